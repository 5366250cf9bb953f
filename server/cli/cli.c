/* Shared command-line helpers: see cli.h. */
#include "cli.h"

#include "engine.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

bool srv_cli_double(const char *cmd, const char *option, const char *text, double min, double max,
                    double *out)
{
    char *end = NULL;
    errno = 0;
    double v = text ? strtod(text, &end) : NAN;
    if (!text || end == text || *end != 0 || errno == ERANGE || !isfinite(v) || v < min || v > max) {
        fprintf(stderr, "fxcache %s: %s: '%s' is not a number in [%g, %g]\n", cmd, option, text ? text : "",
                min, max);
        return false;
    }
    *out = v;
    return true;
}

bool srv_cli_u32(const char *cmd, const char *option, const char *text, uint32_t min, uint32_t max,
                 uint32_t *out)
{
    char *end = NULL;
    errno = 0;
    unsigned long long v = 0;
    bool ok = text && text[0] >= '0' && text[0] <= '9';
    if (ok) {
        v = strtoull(text, &end, 10);
        ok = end != text && *end == 0 && errno != ERANGE && v >= min && v <= max;
    }
    if (!ok) {
        fprintf(stderr, "fxcache %s: %s: '%s' is not a whole number in [%u, %u]\n", cmd, option,
                text ? text : "", min, max);
        return false;
    }
    *out = (uint32_t)v;
    return true;
}

bool srv_cli_resolution(const char *cmd, const char *option, const char *text, uint32_t max_side,
                        uint32_t *width, uint32_t *height)
{
    unsigned long long w = 0, h = 0;
    char tail = 0;
    /* Digits, one 'x', digits: sscanf's %llu alone would also take "64x 36", "64x+36" (and "64x-1" wrapped). */
    size_t digits = text ? strspn(text, "0123456789") : 0;
    bool shape = digits > 0 && text[digits] == 'x' && strspn(text + digits + 1, "0123456789") > 0 &&
                 text[digits + 1 + strspn(text + digits + 1, "0123456789")] == 0;
    if (!shape || sscanf(text, "%llux%llu%c", &w, &h, &tail) != 2 || w < 1 || h < 1 || w > max_side ||
        h > max_side) {
        fprintf(stderr, "fxcache %s: %s: '%s' is not WIDTHxHEIGHT with each side in [1, %u]\n", cmd, option,
                text ? text : "", max_side);
        return false;
    }
    *width = (uint32_t)w;
    *height = (uint32_t)h;
    return true;
}

bool srv_cli_vec3(const char *cmd, const char *option, const char *text, double out[3])
{
    double v[3];
    int used = 0;
    if (!text || sscanf(text, "%lf,%lf,%lf%n", &v[0], &v[1], &v[2], &used) != 3 || text[used] != 0 ||
        !isfinite(v[0]) || !isfinite(v[1]) || !isfinite(v[2]) || fabs(v[0]) > 1e30 || fabs(v[1]) > 1e30 ||
        fabs(v[2]) > 1e30) {
        fprintf(stderr, "fxcache %s: %s: '%s' is not three finite numbers x,y,z (|each| <= 1e30)\n", cmd,
                option, text ? text : "");
        return false;
    }
    for (int k = 0; k < 3; k++)
        out[k] = v[k];
    return true;
}

uint64_t srv_cli_physical_memory(void)
{
    long pages = sysconf(_SC_PHYS_PAGES), page_size = sysconf(_SC_PAGESIZE);
    if (pages <= 0 || page_size <= 0)
        return 0;
    return (uint64_t)pages * (uint64_t)page_size;
}

bool srv_cli_check_memory(const char *cmd, double pool_mb, uint32_t viewers, uint64_t pixels, bool views)
{
    uint64_t physical = srv_cli_physical_memory();
    if (physical == 0)
        return true;
    /* At most 64 viewers of 8192 x 8192 at 47 bytes and a 64 GiB pool: no overflow in 64 bits. */
    uint64_t per_pixel = SRV_VIEWER_BYTES_PER_PIXEL + (views ? SRV_VIEWS_BYTES_PER_PIXEL : 0);
    uint64_t buffers = pixels * per_pixel;
    uint64_t pools = pool_mb > 0 ? (uint64_t)(pool_mb * 1048576.0) : 0;
    if (pools + buffers <= physical)
        return true;
    fprintf(stderr,
            "fxcache %s: the block pools (%.0f MiB) and the per-pixel buffers of %u viewers, %llu pixels "
            "(%.0f MiB) "
            "need %.0f MiB, more than this machine's %llu MiB of physical memory: lower --pool-mb, --viewers "
            "or --res\n",
            cmd, pools / 1048576.0, viewers, (unsigned long long)pixels, buffers / 1048576.0,
            (pools + buffers) / 1048576.0, (unsigned long long)(physical >> 20));
    return false;
}

uint32_t srv_cli_viewers_that_fit(uint64_t physical, uint64_t fixed, uint64_t per_viewer, uint32_t wanted)
{
    if (fixed >= physical)
        return 0;
    if (per_viewer == 0)
        return wanted;
    uint64_t fit = (physical - fixed) / per_viewer;
    return fit < wanted ? (uint32_t)fit : wanted;
}

int srv_cli_interrupted(const char *cmd, int sig, const char *when)
{
    const char *name = sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "a signal";
    fprintf(stderr, "fxcache %s: interrupted by %s %s\n", cmd, name, when);
    return 128 + sig;
}

scene *srv_cli_load_scene(const char *cmd, const char *path, float texel_density)
{
    scene_load_desc desc = {.texel_density = texel_density};
    scene_error err = {0};
    scene *s = scene_load(path, &desc, &err);
    if (!s)
        fprintf(stderr, "fxcache %s: %s\n", cmd, err.msg[0] ? err.msg : scene_strerror(err.code));
    else if (s->precision_warning[0]) /* the scene loads, but it must not render silently wrong */
        fprintf(stderr, "fxcache %s: warning: %s\n", cmd, s->precision_warning);
    return s;
}

int srv_cli_getopt_error(const char *cmd, int c, char **argv)
{
    if (c == ':')
        fprintf(stderr, "fxcache %s: %s needs a value\n", cmd, argv[optind - 1]);
    else
        fprintf(stderr, "fxcache %s: unknown option '%s' (try --help)\n", cmd, argv[optind - 1]);
    return 2;
}

bool srv_cli_no_operands(const char *cmd, int argc, char **argv)
{
    if (optind >= argc)
        return true;
    fprintf(stderr, "fxcache %s: unexpected argument '%s' (the scene is given with --scene)\n", cmd,
            argv[optind]);
    return false;
}

char *srv_cli_dir_arg(char *dir)
{
    size_t n = strlen(dir);
    while (n > 1 && dir[n - 1] == '/')
        dir[--n] = '\0';
    return dir;
}

bool srv_cli_make_dir(const char *cmd, const char *path)
{
    struct stat st;
    if (mkdir(path, 0755) == 0)
        return true;
    int mkdir_errno = errno;
    if (mkdir_errno == EEXIST && stat(path, &st) == 0 && S_ISDIR(st.st_mode))
        return true;
    fprintf(stderr, "fxcache %s: cannot create folder %s: %s\n", cmd, path,
            mkdir_errno == EEXIST ? "a file of that name is in the way" : strerror(mkdir_errno));
    return false;
}

int srv_cli_lock_dir(const char *cmd, const char *dir)
{
    char path[4096];
    if ((size_t)snprintf(path, sizeof path, "%s/.fxcache.lock", dir) >= sizeof path) {
        fprintf(stderr, "fxcache %s: %s: the path is too long\n", cmd, dir);
        return -1;
    }
    int fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) {
        fprintf(stderr, "fxcache %s: cannot create %s: %s\n", cmd, path, strerror(errno));
        return -1;
    }
    if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
        int why = errno;
        char holder[32] = "";
        ssize_t n = read(fd, holder, sizeof holder - 1);
        holder[n > 0 ? n : 0] = 0;
        holder[strcspn(holder, "\n")] = 0;
        close(fd);
        if (why == EWOULDBLOCK)
            fprintf(stderr,
                    "fxcache %s: %s is in use by another fxcache run (process %s); wait for it to end or use "
                    "another --out\n",
                    cmd, dir, holder[0] ? holder : "unknown");
        else
            fprintf(stderr, "fxcache %s: cannot lock %s: %s\n", cmd, path, strerror(why));
        return -1;
    }
    char pid[32];
    int len = snprintf(pid, sizeof pid, "%ld\n", (long)getpid());
    bool noted = ftruncate(fd, 0) == 0 && pwrite(fd, pid, (size_t)len, 0) == len;
    (void)noted; /* the process number is only the refusal's figure */
    return fd;
}

void srv_cli_unlock_dir(int fd)
{
    if (fd >= 0)
        close(fd);
}

bool srv_cli_output_file_ok(const char *cmd, const char *option, const char *path)
{
    struct stat st;
    const char *why = NULL;
    if (!*path)
        why = "empty path";
    else if (stat(path, &st) == 0 && S_ISDIR(st.st_mode))
        why = "is a directory";
    else {
        char folder[4096];
        const char *slash = strrchr(path, '/');
        size_t n = slash ? (size_t)(slash - path) : 0;
        if (n >= sizeof folder)
            why = "path too long";
        else {
            if (!slash)
                strcpy(folder, ".");
            else if (n == 0)
                strcpy(folder, "/");
            else {
                memcpy(folder, path, n);
                folder[n] = '\0';
            }
            if (stat(folder, &st) != 0 || !S_ISDIR(st.st_mode))
                why = "its folder does not exist";
            else if (access(folder, W_OK | X_OK) != 0)
                why = strerror(errno);
        }
    }
    if (why)
        fprintf(stderr, "fxcache %s: cannot write %s (%s): %s\n", cmd, path, option, why);
    return why == NULL;
}

/* The device and inode of path's folder ("." without a slash); false when it cannot be stat'ed. */
static bool folder_id(const char *path, struct stat *st)
{
    char folder[4096];
    const char *slash = strrchr(path, '/');
    if (!slash)
        return stat(".", st) == 0;
    size_t n = (size_t)(slash - path);
    if (n == 0)
        return stat("/", st) == 0;
    if (n >= sizeof folder)
        return false;
    memcpy(folder, path, n);
    folder[n] = '\0';
    return stat(folder, st) == 0;
}

bool srv_cli_output_files_differ(const char *cmd, const char *option_a, const char *a, const char *option_b,
                                 const char *b)
{
    if (!a || !b)
        return true;
    struct stat sa, sb;
    bool same = strcmp(a, b) == 0;
    if (!same && stat(a, &sa) == 0 && stat(b, &sb) == 0)
        same = sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino; /* also through links */
    else if (!same) {
        /* not both there yet: the same name in the same folder, however the folder is spelt */
        const char *name_a = strrchr(a, '/'), *name_b = strrchr(b, '/');
        name_a = name_a ? name_a + 1 : a;
        name_b = name_b ? name_b + 1 : b;
        same = strcmp(name_a, name_b) == 0 && folder_id(a, &sa) && folder_id(b, &sb) &&
               sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
    }
    if (same)
        fprintf(stderr, "fxcache %s: %s and %s name the same file (%s): one would overwrite the other\n", cmd,
                option_a, option_b, a);
    return !same;
}
