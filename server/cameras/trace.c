/* Viewer traces: the file reader and the writer of the `fxcache-trace` text format (see trace.h and
 * docs/TRACE_FORMAT.md).
 *
 * The text itself is parsed by proto_trace_parse() (proto/proto_trace.c), which the viewer client shares:
 * this file reads the file into memory (at most PROTO_TRACE_MAX_FILE_BYTES) and hands the bytes over. The
 * cameras are kept as read, in double and world coordinates; srv_trace_camera() moves one into the scene's
 * local frame (scene_world_to_local) when it is replayed, so a trace of a scene far from the world origin
 * loses nothing to float rounding.
 *
 * The writer turns local cameras back into world coordinates (local + the scene's origin, in double) and
 * prints each number with as many digits as it needs to read back exactly (proto_trace_format_number: at
 * least 9, float-exact for cameras of a scene at the origin), and flushes after every line. */
#include "trace.h"

#include "proto_trace.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The format's limits are the parser's: trace.h keeps its own names for them. */
_Static_assert(SRV_TRACE_VERSION == PROTO_TRACE_VERSION, "trace.h and proto_trace.h name different versions");
_Static_assert(SRV_TRACE_MAX_SIDE == PROTO_TRACE_MAX_SIDE, "trace.h and proto_trace.h name different sides");
_Static_assert(SRV_TRACE_MAX_LINE == PROTO_TRACE_MAX_LINE, "trace.h and proto_trace.h name different lines");

struct srv_trace {
    proto_trace parsed; /* the cameras as read (world coordinates, double), their times, the resolution */
};

struct srv_trace_writer {
    FILE *file;
    double origin[3]; /* the scene's origin: cameras are local to it, lines are world */
    uint32_t count;   /* cameras written */
    double last_time; /* time of the last camera written (valid when count > 0) */
    bool failed;      /* an I/O error happened: close reports it */
    char error[512];  /* the last error, one line */
};

/* ---- reader ------------------------------------------------------------------------------------------ */

/* Reads a whole file of at most PROTO_TRACE_MAX_FILE_BYTES into a malloc'd buffer (*text, *len; the caller
 * frees it). Returns false with one line in err on failure: "PATH: cannot open: ...", "PATH:LINE: read
 * error: ..." (the line the read stopped in), or the file being too large. */
static bool read_whole_file(const char *path, char **text, size_t *len, char *err, size_t cap)
{
    *text = NULL;
    *len = 0;
    FILE *file = fopen(path, "rb");
    if (!file) {
        if (err && cap > 0)
            snprintf(err, cap, "%s: cannot open: %s", path, strerror(errno));
        return false;
    }
    size_t size = 0, capacity = 0;
    char *buf = NULL;
    bool ok = true;
    for (;;) {
        if (size == capacity) {
            if (capacity > PROTO_TRACE_MAX_FILE_BYTES) {
                if (err && cap > 0)
                    snprintf(err, cap, "%s: larger than %u MiB: too large for a trace file", path,
                             PROTO_TRACE_MAX_FILE_BYTES >> 20);
                ok = false;
                break;
            }
            /* One byte over the limit tells a file of exactly the limit from a larger one. */
            size_t grown = capacity ? capacity * 2 : 65536;
            if (grown > (size_t)PROTO_TRACE_MAX_FILE_BYTES + 1)
                grown = (size_t)PROTO_TRACE_MAX_FILE_BYTES + 1;
            char *bigger = realloc(buf, grown);
            if (!bigger) {
                if (err && cap > 0)
                    snprintf(err, cap, "%s: out of memory", path);
                ok = false;
                break;
            }
            buf = bigger;
            capacity = grown;
        }
        size_t got = fread(buf + size, 1, capacity - size, file);
        size += got;
        if (size < capacity) { /* a short read: the end of the file, or an error */
            if (ferror(file)) {
                int saved = errno;
                uint32_t line = 1;
                for (size_t i = 0; i < size; i++)
                    line += buf[i] == '\n';
                if (err && cap > 0)
                    snprintf(err, cap, "%s:%u: read error: %s", path, line, strerror(saved));
                ok = false;
            }
            break;
        }
    }
    fclose(file);
    if (!ok) {
        free(buf);
        return false;
    }
    *text = buf;
    *len = size;
    return true;
}

srv_trace *srv_trace_read(const char *path, char *err, size_t cap)
{
    if (err && cap > 0)
        err[0] = 0;
    if (!path) {
        if (err && cap > 0)
            snprintf(err, cap, "(null): no trace file given");
        return NULL;
    }
    char *text;
    size_t len;
    if (!read_whole_file(path, &text, &len, err, cap))
        return NULL;
    srv_trace *t = calloc(1, sizeof *t);
    if (!t) {
        if (err && cap > 0)
            snprintf(err, cap, "%s: out of memory", path);
        free(text);
        return NULL;
    }
    fxc_result result = proto_trace_parse(text, len, path, &t->parsed, err, cap);
    free(text);
    if (result != FXC_OK) {
        free(t);
        return NULL;
    }
    return t;
}

uint32_t srv_trace_count(const srv_trace *t)
{
    return t ? t->parsed.count : 0;
}

srv_camera srv_trace_camera_world(const scene *s, const double position[3], const double direction[3],
                                  float fov_deg)
{
    srv_camera cam = {.up = {0, 1, 0}, .fov_deg = fov_deg};
    if (s) {
        scene_world_to_local(s, position, cam.position);
    } else {
        for (int k = 0; k < 3; k++)
            cam.position[k] = (float)position[k];
    }
    /* The target from the rounded position, so a recorded camera reads back exactly. */
    double length =
        sqrt(direction[0] * direction[0] + direction[1] * direction[1] + direction[2] * direction[2]);
    double off2 = 0; /* squared distance between the direction and the one the float target gives */
    for (int k = 0; k < 3; k++) {
        cam.target[k] = (float)((double)cam.position[k] + direction[k]);
        double realized = (double)cam.target[k] - (double)cam.position[k];
        off2 += (realized - direction[k]) * (realized - direction[k]);
    }
    if (!(sqrt(off2) <= 1e-4 * length)) {
        /* A direction below the float spacing at this position, wholly (the target rounds onto the position)
         * or in part (a component rounds away: (3e-31, 0, -4e-31) at z = 3 looked along +x): the same
         * direction, one position-length long (the view does not depend on the target's distance). A recorded
         * camera's direction is a difference of floats and never comes here. */
        double reach = 1.0;
        for (int k = 0; k < 3; k++)
            reach = fmax(reach, fabs((double)cam.position[k]));
        for (int k = 0; k < 3; k++)
            cam.target[k] = (float)((double)cam.position[k] + direction[k] / length * reach);
    }
    return cam;
}

/* Camera line `index` in the local frame of scene s (NULL: as given). */
static srv_camera trace_camera_local(const srv_trace *t, const scene *s, uint32_t index)
{
    const proto_trace_camera *c = &t->parsed.cameras[index];
    double direction[3] = {c->direction[0], c->direction[1], c->direction[2]};
    return srv_trace_camera_world(s, c->position, direction, c->fov_deg);
}

srv_camera srv_trace_camera(const srv_trace *t, const scene *s, uint32_t frame)
{
    return trace_camera_local(t, s, frame < t->parsed.count ? frame : t->parsed.count - 1);
}

double srv_trace_time(const srv_trace *t, uint32_t frame)
{
    uint32_t index = frame < t->parsed.count ? frame : t->parsed.count - 1;
    return t->parsed.times[index];
}

bool srv_trace_resolution(const srv_trace *t, uint32_t *width, uint32_t *height)
{
    if (!t->parsed.width)
        return false;
    *width = t->parsed.width;
    *height = t->parsed.height;
    return true;
}

double srv_trace_first_time(const srv_trace *t)
{
    return t->parsed.times[0];
}

double srv_trace_last_time(const srv_trace *t)
{
    return t->parsed.times[t->parsed.count - 1];
}

srv_camera srv_trace_camera_at(const srv_trace *t, const scene *s, double time)
{
    /* The last line whose time is not after `time` (binary search; times do not decrease). */
    uint32_t lo = 0, hi = t->parsed.count;
    while (hi - lo > 1) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (t->parsed.times[mid] <= time + SRV_TRACE_TIME_EPSILON)
            lo = mid;
        else
            hi = mid;
    }
    return trace_camera_local(t, s, lo);
}

void srv_trace_free(srv_trace *t)
{
    if (!t)
        return;
    proto_trace_release(&t->parsed);
    free(t);
}

/* ---- writer ------------------------------------------------------------------------------------------ */

srv_trace_writer *srv_trace_writer_open(const char *path, const scene *s, char *err, size_t cap)
{
    return srv_trace_writer_open_sized(path, s, 0, 0, err, cap);
}

srv_trace_writer *srv_trace_writer_open_sized(const char *path, const scene *s, uint32_t width,
                                              uint32_t height, char *err, size_t cap)
{
    if (err && cap > 0)
        err[0] = 0;
    if (!path) {
        if (err && cap > 0)
            snprintf(err, cap, "(null): no trace file given");
        return NULL;
    }
    srv_trace_writer *w = calloc(1, sizeof *w);
    if (!w) {
        if (err && cap > 0)
            snprintf(err, cap, "%s: out of memory", path);
        return NULL;
    }
    if (s)
        memcpy(w->origin, s->origin, sizeof w->origin);
    w->file = fopen(path, "wb");
    if (!w->file) {
        if (err && cap > 0)
            snprintf(err, cap, "%s: cannot create: %s", path, strerror(errno));
        free(w);
        return NULL;
    }
    bool sized = width >= 1 && height >= 1 && width <= SRV_TRACE_MAX_SIDE && height <= SRV_TRACE_MAX_SIDE;
    /* Version 1 when there is no resolution to record, so version-1 readers keep reading such files. */
    int written =
        fprintf(w->file,
                "%s %d\n# columns: time px py pz dx dy dz fov_deg (seconds, position, view direction, "
                "vertical fov in degrees; up is +Y)\n",
                SRV_TRACE_MAGIC, sized ? 2 : 1);
    if (written >= 0 && sized)
        written = fprintf(w->file, "resolution %u %u\n", width, height);
    if (written < 0 || fflush(w->file) != 0) {
        if (err && cap > 0)
            snprintf(err, cap, "%s: cannot write: %s", path, strerror(errno));
        fclose(w->file);
        free(w);
        return NULL;
    }
    return w;
}

int srv_trace_writer_add(srv_trace_writer *w, double time, const srv_camera *cam)
{
    w->error[0] = 0;
    if (w->failed) {
        snprintf(w->error, sizeof w->error, "an earlier write failed");
        return -2;
    }
    if (!isfinite(time)) {
        snprintf(w->error, sizeof w->error, "camera %u: time is not finite", w->count);
        return -1;
    }
    if (w->count > 0 && time < w->last_time) {
        snprintf(w->error, sizeof w->error, "camera %u: time %.9g is before the previous camera's %.9g",
                 w->count, time, w->last_time);
        return -1;
    }
    if (w->count == UINT32_MAX / 2) {
        snprintf(w->error, sizeof w->error, "too many cameras (at most %u)", UINT32_MAX / 2);
        return -1;
    }
    double direction[3];
    bool nonzero = false;
    for (int k = 0; k < 3; k++) {
        if (!isfinite(cam->position[k]) || !isfinite(cam->target[k])) {
            snprintf(w->error, sizeof w->error, "camera %u: position or target is not finite", w->count);
            return -1;
        }
        direction[k] = (double)cam->target[k] - (double)cam->position[k];
        if (direction[k] != 0)
            nonzero = true;
    }
    if (!nonzero) {
        snprintf(w->error, sizeof w->error, "camera %u: position equals target", w->count);
        return -1;
    }
    if (!(cam->fov_deg > 0 && cam->fov_deg < 180)) {
        snprintf(w->error, sizeof w->error, "camera %u: fov_deg %.9g is outside (0, 180)", w->count,
                 (double)cam->fov_deg);
        return -1;
    }
    /* World = local + origin (as scene_local_to_world), printed so that it reads back exactly. */
    char time_text[32], position_text[3][32];
    proto_trace_format_number(time, time_text, sizeof time_text);
    for (int k = 0; k < 3; k++)
        proto_trace_format_number((double)cam->position[k] + w->origin[k], position_text[k],
                                  sizeof position_text[k]);
    if (fprintf(w->file, "%s %s %s %s %.9g %.9g %.9g %.9g\n", time_text, position_text[0], position_text[1],
                position_text[2], direction[0], direction[1], direction[2], (double)cam->fov_deg) < 0 ||
        fflush(w->file) != 0) {
        w->failed = true;
        snprintf(w->error, sizeof w->error, "cannot write: %s", strerror(errno));
        return -2;
    }
    w->last_time = time;
    w->count++;
    return 0;
}

const char *srv_trace_writer_error(const srv_trace_writer *w)
{
    return w->error;
}

uint32_t srv_trace_writer_count(const srv_trace_writer *w)
{
    return w->count;
}

int srv_trace_writer_close(srv_trace_writer *w)
{
    if (!w)
        return 0;
    bool failed = w->failed;
    if (fflush(w->file) != 0)
        failed = true;
    if (fclose(w->file) != 0)
        failed = true;
    free(w);
    return failed ? -2 : 0;
}
