/* Shared test helpers (named fxt_util.c so the test_*.c glob does not take it for a test): see test_util.h. */
#include "test_util.h"

#include <fcntl.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

const char *fxt_shared_scene(const char *rel)
{
    static char path[1024];
    snprintf(path, sizeof path, "%s/../shared/scenes/%s", FXC_SOURCE_DIR, rel);
    if (access(path, R_OK) != 0) {
        printf("SKIP: %s is absent (the shared scenes are not beside this clone)\n", path);
        return NULL;
    }
    return path;
}

uint32_t fxt_random(uint32_t *state)
{
    uint32_t x = *state;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    return *state = x;
}

float fxt_float_from_bits(uint32_t bits)
{
    float v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

uint32_t fxt_bits_from_float(float v)
{
    uint32_t bits;
    memcpy(&bits, &v, sizeof bits);
    return bits;
}

const char *fxt_tmp_path(const char *name)
{
    static char path[1024];
    mkdir(FXC_TEST_TMP, 0755);
    snprintf(path, sizeof path, "%s/%s", FXC_TEST_TMP, name);
    return path;
}

const char *fxt_write_file(const char *name, const char *text)
{
    const char *path = fxt_tmp_path(name);
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    fputs(text, f);
    fclose(f);
    return path;
}

void *fxt_read_file(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        fail_msg("cannot open %s", path);
    assert_int_equal(fseek(f, 0, SEEK_END), 0);
    long len = ftell(f);
    assert_true(len >= 0);
    rewind(f);
    unsigned char *bytes = malloc(len > 0 ? (size_t)len : 1);
    assert_non_null(bytes);
    assert_int_equal(fread(bytes, 1, (size_t)len, f), (size_t)len);
    fclose(f);
    *size = (size_t)len;
    return bytes;
}

static void slurp(const char *path, char *buf, size_t cap)
{
    if (!buf || cap == 0)
        return;
    buf[0] = 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        return;
    size_t n = fread(buf, 1, cap - 1, f);
    buf[n] = 0;
    fclose(f);
}

int fxt_run_cli(const char *args, char *out, size_t out_cap, char *err, size_t err_cap)
{
    char out_path[1100], err_path[1100], cmd[4096];
    snprintf(out_path, sizeof out_path, "%s", fxt_tmp_path("cli_stdout.txt"));
    snprintf(err_path, sizeof err_path, "%s", fxt_tmp_path("cli_stderr.txt"));
    snprintf(cmd, sizeof cmd, "'%s' %s >'%s' 2>'%s' </dev/null", FXC_BIN, args, out_path, err_path);
    int status = system(cmd);
    slurp(out_path, out, out_cap);
    slurp(err_path, err, err_cap);
    if (status == -1 || !WIFEXITED(status))
        return -1;
    return WEXITSTATUS(status);
}

srv_loop *fxt_loop(const srv_loop_desc *desc, uint32_t n, uint32_t w, uint32_t h, srv_viewer_id *ids)
{
    char err[256];
    srv_loop *loop = NULL;
    fxc_result r = srv_loop_create(desc, &loop, err, sizeof err);
    if (r != FXC_OK)
        fail_msg("srv_loop_create: %s (%s)", err, fxc_strerror(r));
    for (uint32_t v = 0; v < n; v++) {
        srv_viewer_desc vd = {.width = w, .height = h};
        r = srv_viewer_add(loop, &vd, &ids[v]);
        if (r != FXC_OK)
            fail_msg("srv_viewer_add: %s", fxc_strerror(r));
    }
    return loop;
}

void fxt_frame(srv_loop *loop, const srv_viewer_id *ids, uint32_t n, const srv_camera *cameras,
               srv_frame_stats *stats)
{
    for (uint32_t v = 0; v < n; v++) {
        fxc_result r = srv_viewer_set_camera(loop, ids[v], &cameras[v]);
        if (r != FXC_OK)
            fail_msg("srv_viewer_set_camera: %s", fxc_strerror(r));
    }
    fxc_result r = srv_loop_frame(loop, stats);
    if (r != FXC_OK)
        fail_msg("srv_loop_frame: %s", fxc_strerror(r));
}

void fxt_effects_on(srv_loop_desc *desc, const char *const *names, uint32_t count)
{
    uint32_t n = 0;
    const fx_effect *const *registry = fx_registry(&n);
    for (uint32_t i = 0; i < count; i++) {
        int32_t e = fx_find(registry, n, names[i]);
        if (e < 0)
            fail_msg("no effect named %s", names[i]);
        desc->effect_on[e] = true;
    }
}

int fxt_default_scene_setup(void **state)
{
    fxt_scene_fixture *f = calloc(1, sizeof *f);
    assert_non_null(f);
    scene_error err = {0};
    f->s = scene_create_default(NULL, &err);
    assert_non_null(f->s);
    f->rt = scene_rt_create(f->s, NULL, &err);
    assert_non_null(f->rt);
    *state = f;
    return 0;
}

int fxt_default_scene_teardown(void **state)
{
    fxt_scene_fixture *f = *state;
    scene_rt_free(f->rt);
    scene_free(f->s);
    free(f);
    return 0;
}

void *fxt_counting_alloc(size_t size, void *user)
{
    fxt_counting_allocator *counter = user;
    counter->total_allocations++;
    if (counter->fail_at != 0 && counter->total_allocations == counter->fail_at)
        return NULL;
    void *pointer = malloc(size);
    if (pointer) {
        counter->live_bytes += size;
        counter->live_allocations++;
    }
    return pointer;
}

void fxt_counting_free(void *pointer, size_t size, void *user)
{
    fxt_counting_allocator *counter = user;
    assert_true(counter->live_bytes >= size);
    counter->live_bytes -= size;
    counter->live_allocations--;
    free(pointer);
}

/* Whether process pid catches signal sig (its SigCgt mask in /proc). */
pid_t fxt_spawn_quiet(const char *const argv[], int reset, const char *err_path)
{
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        if (reset)
            signal(reset, SIG_DFL);
        int devnull = open("/dev/null", O_WRONLY);
        int errfd = err_path ? open(err_path, O_WRONLY | O_CREAT | O_TRUNC, 0644) : devnull;
        dup2(devnull, STDOUT_FILENO);
        dup2(errfd, STDERR_FILENO);
        execv(argv[0], (char *const *)argv);
        _exit(127);
    }
    return pid;
}

bool fxt_catches_signal(pid_t pid, int sig)
{
    char path[64], line[256];
    snprintf(path, sizeof path, "/proc/%d/status", (int)pid);
    FILE *f = fopen(path, "r");
    if (!f)
        return false;
    unsigned long long mask = 0;
    bool found = false;
    while (!found && fgets(line, sizeof line, f))
        found = sscanf(line, "SigCgt: %llx", &mask) == 1;
    fclose(f);
    return found && (mask >> (sig - 1)) & 1;
}

int fxt_run_clif(char *out, size_t out_cap, char *err, size_t err_cap, const char *fmt, ...)
{
    char args[3072];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(args, sizeof args, fmt, ap);
    va_end(ap);
    assert_true(n > 0 && (size_t)n < sizeof args);
    return fxt_run_cli(args, out, out_cap, err, err_cap);
}

void fxt_tmp_path_copy(char *dst, size_t cap, const char *name)
{
    int n = snprintf(dst, cap, "%s", fxt_tmp_path(name));
    assert_true(n > 0 && (size_t)n < cap);
}

bool fxt_wait_for_lines(const char *path, int lines, double timeout_s)
{
    for (double waited = 0; waited <= timeout_s; waited += 0.1) {
        FILE *f = fopen(path, "r");
        int count = 0;
        if (f) {
            for (int c; (c = fgetc(f)) != EOF;)
                count += c == '\n';
            fclose(f);
        }
        if (count >= lines)
            return true;
        struct timespec pause = {0, 100 * 1000 * 1000};
        nanosleep(&pause, NULL);
    }
    return false;
}
