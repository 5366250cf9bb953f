/* Helpers shared by the test programs: paths to the shared scenes (skip when absent), scratch files,
 * running the fxcache command line and capturing what it prints. */
#ifndef FXC_TEST_UTIL_H
#define FXC_TEST_UTIL_H

#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <sys/types.h>
#include <cmocka.h>

/* Path of ../shared/scenes/<rel> relative to the repository root, or NULL (with a message printed) when
 * that file is absent: the caller then calls skip(). The returned string is static. */
const char *fxt_shared_scene(const char *rel);

/* Writes text to a scratch file named name in this test's own temporary folder; returns its path (static
 * buffer, valid until the next call). */
const char *fxt_write_file(const char *name, const char *text);

/* The whole file at path in a malloc'd buffer (the caller frees it), its length in *size; fails the test when
 * it cannot be read. */
void *fxt_read_file(const char *path, size_t *size);

/* A scratch path for name in this test's temporary folder (static buffer). */
const char *fxt_tmp_path(const char *name);

/* Runs `fxcache <args>` through the shell, captures stdout and stderr (each truncated to cap-1 bytes, may
 * be NULL) and returns the exit status (or -1 when it did not exit normally). */
int fxt_run_cli(const char *args, char *out, size_t out_cap, char *err, size_t err_cap);

/* fxt_run_cli with the arguments printf-style (at most 3 KB). */
int fxt_run_clif(char *out, size_t out_cap, char *err, size_t err_cap, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));

/* fxt_tmp_path(name) copied into dst (cap bytes; fails the test when it does not fit). */
void fxt_tmp_path_copy(char *dst, size_t cap, const char *name);

/* Waits until the file at path holds at least `lines` newline characters (a growing stats.jsonl), polling
 * every 0.1 s for at most timeout_s seconds; false when it never did. */
bool fxt_wait_for_lines(const char *path, int lines, double timeout_s);

/* Starts argv[0] (a program path) with argv in a child process, its stdout to /dev/null and its stderr to
 * err_path (created or truncated; NULL: /dev/null), signal `reset` (0: none) back to its default first, so
 * that fxt_catches_signal sees the program's own handler and not one inherited. Returns the child's pid. */
pid_t fxt_spawn_quiet(const char *const argv[], int reset, const char *err_path);

/* Whether process pid catches signal sig (its SigCgt mask in /proc): a child's handler is in place. */
bool fxt_catches_signal(pid_t pid, int sig);

/* A small deterministic generator for test data (xorshift32): the next value of *state (never 0 if the seed
 * is not 0), stored back into *state. */
uint32_t fxt_random(uint32_t *state);

/* A float's bits and back (memcpy: no aliasing or union games). */
float fxt_float_from_bits(uint32_t bits);
uint32_t fxt_bits_from_float(float v);

/* A counting allocator for the caches' allocator hooks (osc_allocator): live bytes and allocations, and an
 * optional failure of the n-th allocation. free checks it never frees more than is live. */
typedef struct fxt_counting_allocator {
    size_t live_bytes, live_allocations, total_allocations;
    size_t fail_at; /* 1-based allocation number that fails, 0 = never */
} fxt_counting_allocator;
void *fxt_counting_alloc(size_t size, void *user);
void fxt_counting_free(void *pointer, size_t size, void *user);

/* ---- the engine (server/engine) --------------------------------------------------------------------- */
#include "engine.h"

/* A cmocka fixture holding the embedded default scene and its Embree scene (state: fxt_scene_fixture *). */
typedef struct fxt_scene_fixture {
    scene *s;
    scene_rt *rt;
} fxt_scene_fixture;
int fxt_default_scene_setup(void **state);
int fxt_default_scene_teardown(void **state);

/* Creates a loop (failing the test with the message if it cannot) and adds n viewers of w x h, their ids in
 * ids[0..n). */
srv_loop *fxt_loop(const srv_loop_desc *desc, uint32_t n, uint32_t w, uint32_t h, srv_viewer_id *ids);

/* Sets the cameras of viewers ids[0..n) and runs one frame (failing the test on any error). */
void fxt_frame(srv_loop *loop, const srv_viewer_id *ids, uint32_t n, const srv_camera *cameras,
               srv_frame_stats *stats);

/* The desc fields that turn on effects by name (registry order) for the built-in effects. */
void fxt_effects_on(srv_loop_desc *desc, const char *const *names, uint32_t count);

#endif
