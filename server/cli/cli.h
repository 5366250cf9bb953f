/* Shared pieces of the fxcache command line: value parsing with ranges (every refusal names the option,
 * the value and the allowed range), and loading the scene a subcommand names. */
#ifndef FXC_SERVER_CLI_H
#define FXC_SERVER_CLI_H

#include "scene.h"

#include <stdbool.h>
#include <stdint.h>

/* Parses a finite double in [min, max]; on failure prints "fxcache CMD: OPTION: ..." and returns false. */
bool srv_cli_double(const char *cmd, const char *option, const char *text, double min, double max,
                    double *out);

/* Parses an unsigned integer in [min, max]; on failure prints a one-line error and returns false. */
bool srv_cli_u32(const char *cmd, const char *option, const char *text, uint32_t min, uint32_t max,
                 uint32_t *out);

/* Parses "WxH" with each side in [1, max_side]. */
bool srv_cli_resolution(const char *cmd, const char *option, const char *text, uint32_t max_side,
                        uint32_t *width, uint32_t *height);

/* Parses "x,y,z" (three finite numbers, |each| <= 1e30), in double: world positions far from the origin
 * keep their precision until scene_world_to_local(). */
bool srv_cli_vec3(const char *cmd, const char *option, const char *text, double out[3]);

/* The machine's physical memory in bytes (sysconf(_SC_PHYS_PAGES) times the page size), 0 if unknown. */
uint64_t srv_cli_physical_memory(void);

/* The error for getopt_long's ':' (a missing value) or '?' (an unknown option), c being what it returned;
 * prints one line and returns the exit status 2. The option string must start with ':'. */
int srv_cli_getopt_error(const char *cmd, int c, char **argv);
/* False, after one line naming the first, if arguments remain after the options (the scene is given with
 * --scene). */
bool srv_cli_no_operands(const char *cmd, int argc, char **argv);
/* Checks, before anything is loaded, that the block pools (pool_mb MiB; 0 when no cache runs) and the
 * per-pixel buffers of `viewers` viewers with `pixels` pixels in all (SRV_VIEWER_BYTES_PER_PIXEL each, and
 * SRV_VIEWS_BYTES_PER_PIXEL more with views) fit in physical memory; otherwise prints one line with both figures and the
 * machine's ("fxcache CMD: ... need N MiB ..., more than this machine's M MiB of physical memory") and
 * returns false. Always true when the physical memory is unknown. */
bool srv_cli_check_memory(const char *cmd, double pool_mb, uint32_t viewers, uint64_t pixels, bool views);
/* How many of `wanted` viewers of per_viewer bytes each fit in `physical` bytes beside `fixed` bytes (0 when
 * not one does). */
uint32_t srv_cli_viewers_that_fit(uint64_t physical, uint64_t fixed, uint64_t per_viewer, uint32_t wanted);

/* Reports a run ended by signal sig (SIGINT, SIGTERM) before it did its work, with one line
 * "fxcache CMD: interrupted by SIGTERM WHEN", and returns the exit code a shell gives such a run: 128 + sig
 * (130 for SIGINT, 143 for SIGTERM). */
int srv_cli_interrupted(const char *cmd, int sig, const char *when);

/* A directory argument without its trailing slashes ("out/" -> "out", "/" stays): the paths built from it
 * read "out/index.html", not "out//index.html". Returns dir, changed in place (an argv string). */
char *srv_cli_dir_arg(char *dir);

/* Creates the folder path, or accepts it if it exists as a folder (not as a file: every image of a run
 * would fail to be written after the run); false with "fxcache CMD: cannot create folder PATH: why". */
bool srv_cli_make_dir(const char *cmd, const char *path);

/* Takes the output folder for this run: an exclusive lock (flock) on DIR/.fxcache.lock, held until the
 * process ends or srv_cli_unlock_dir(), so two runs writing one folder at once (report, ref) cannot mix
 * their files. Returns the lock's descriptor, or -1 after one line: "fxcache CMD: DIR is in use by another
 * fxcache run (process N); wait for it to end or use another --out", or why the lock could not be taken. */
int srv_cli_lock_dir(const char *cmd, const char *dir);

/* Gives the lock back (fd -1: nothing to do). */
void srv_cli_unlock_dir(int fd);

/* Whether an output file named by option (--stats, --summary) can be written, checked before the scene
 * loads: not a directory, its folder exists and is writable. Prints "fxcache CMD: cannot write PATH (OPTION):
 * why" and returns false otherwise (the file itself is opened later, when the run needs it). */
bool srv_cli_output_file_ok(const char *cmd, const char *option, const char *path);

/* Whether two output files (--stats and --summary) are different files: the same path, the same existing
 * file (also through a link) or the same name in the same folder is refused with "fxcache CMD: OPTION_A and
 * OPTION_B name the same file" (the summary overwrote the statistics without a word). True when either is
 * NULL. */
bool srv_cli_output_files_differ(const char *cmd, const char *option_a, const char *a, const char *option_b,
                                 const char *b);

/* Loads the scene at path ("default" or NULL: the embedded scene); prints the error on failure, and the
 * scene's precision warning (if any) as "fxcache CMD: warning: ..." on stderr. */
scene *srv_cli_load_scene(const char *cmd, const char *path, float texel_density);

/* The subcommands (each parses its own options and returns the process exit code). */
int srv_cmd_scene_info(int argc, char **argv);
int srv_cmd_render(int argc, char **argv);
int srv_cmd_sim(int argc, char **argv);
int srv_cmd_serve(int argc, char **argv);
int srv_cmd_ref(int argc, char **argv);
int srv_cmd_report(int argc, char **argv);

#endif
