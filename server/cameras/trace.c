/* Viewer traces: the reader and writer of the `fxcache-trace 1` text format (see trace.h and
 * docs/TRACE_FORMAT.md).
 *
 * The reader is line oriented and treats the file as untrusted: it reads at most SRV_TRACE_MAX_LINE bytes
 * per line, checks each line for NUL bytes, control characters and invalid UTF-8 before looking at its
 * content, accepts only plain decimal numbers (no NaN, no infinity, no hex), and stops at the first problem
 * with one line "FILE:LINE: what is wrong". Cameras are kept as read, in double and world coordinates;
 * srv_trace_camera() moves one into the scene's local frame (scene_world_to_local) when it is replayed, so a
 * trace of a scene far from the world origin loses nothing to float rounding.
 *
 * The writer turns local cameras back into world coordinates (local + the scene's origin, in double) and
 * prints each number with as many digits as it needs to read back exactly (at least 9: float-exact for
 * cameras of a scene at the origin), and flushes after every line. */
#include "trace.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Columns of a camera line, in order. */
enum { TRACE_COLUMNS = 8 };
static const char *const trace_column_names[TRACE_COLUMNS] = {"time", "px", "py", "pz",
                                                              "dx",   "dy", "dz", "fov_deg"};

/* One camera line as read: world coordinates, in double. */
typedef struct trace_camera {
    double position[3];  /* world */
    double direction[3]; /* non-zero; position + direction differs from position in double */
    float fov_deg;       /* (0, 180) */
} trace_camera;

struct srv_trace {
    uint32_t count;         /* cameras, >= 1 once read */
    uint32_t capacity;      /* allocated entries of cameras and times */
    trace_camera *cameras;  /* count cameras */
    double *times;          /* count times, seconds, non-decreasing */
    uint32_t width, height; /* the viewer's resolution (version 2 'resolution' line), 0 when not given */
    uint32_t version;       /* the file's format version */
};

struct srv_trace_writer {
    FILE *file;
    double origin[3]; /* the scene's origin: cameras are local to it, lines are world */
    uint32_t count;   /* cameras written */
    double last_time; /* time of the last camera written (valid when count > 0) */
    bool failed;      /* an I/O error happened: close reports it */
    char error[512];  /* the last error, one line */
};

/* ---- shared helpers ---------------------------------------------------------------------------------- */

/* Prints v with the fewest significant digits (9 to 17) that read back to exactly v. */
static void format_double_exact(double v, char *buf, size_t cap)
{
    for (int digits = 9; digits <= 17; digits++) {
        snprintf(buf, cap, "%.*g", digits, v);
        if (strtod(buf, NULL) == v)
            return;
    }
}

/* Copies at most 40 bytes of text into a quotable snippet: printable ASCII kept, anything else '?'. */
static void snippet(const char *text, size_t len, char *out, size_t cap)
{
    size_t limit = cap - 1 < 40 ? cap - 1 : 40;
    size_t n = 0;
    for (; n < len && n < limit; n++) {
        unsigned char c = (unsigned char)text[n];
        out[n] = (c >= 0x20 && c < 0x7f) ? (char)c : '?';
    }
    out[n] = 0;
    if (len > limit && limit >= 3)
        memcpy(out + limit - 3, "...", 4);
}

/* ---- reader ------------------------------------------------------------------------------------------ */

/* What the reader carries from line to line. */
typedef struct trace_reader {
    const char *path;
    FILE *file;
    uint32_t line_number; /* 1-based number of the line being looked at */
    char *err;
    size_t err_cap;
    srv_trace *trace;
} trace_reader;

/* Outcome of reading one line. */
typedef enum line_status { LINE_OK, LINE_END_OF_FILE, LINE_TOO_LONG, LINE_READ_ERROR } line_status;

/* Writes "PATH:LINE: message" into the reader's error buffer; always returns false for `return fail(...)`. */
static bool fail(trace_reader *r, const char *fmt, ...)
{
    if (!r->err || r->err_cap == 0)
        return false;
    int prefix = snprintf(r->err, r->err_cap, "%s:%u: ", r->path, r->line_number);
    if (prefix < 0 || (size_t)prefix >= r->err_cap)
        return false;
    va_list args;
    va_start(args, fmt);
    vsnprintf(r->err + prefix, r->err_cap - (size_t)prefix, fmt, args);
    va_end(args);
    return false;
}

/* Reads one line (without its '\n', and without a '\r' before it) into buf of SRV_TRACE_MAX_LINE + 2
 * bytes; *len receives its length (the line may contain NUL bytes, checked later). Stops reading as soon
 * as the line is known to be too long. */
static line_status read_line(FILE *file, char *buf, size_t *len)
{
    size_t n = 0;
    int c;
    while ((c = getc(file)) != EOF) {
        if (c == '\n')
            break;
        if (n > SRV_TRACE_MAX_LINE)
            return LINE_TOO_LONG; /* room for one more byte only if it is the '\r' of a CRLF */
        buf[n++] = (char)c;
    }
    if (c == EOF) {
        if (ferror(file))
            return LINE_READ_ERROR;
        if (n == 0)
            return LINE_END_OF_FILE;
    }
    if (n > 0 && buf[n - 1] == '\r')
        n--;
    if (n > SRV_TRACE_MAX_LINE)
        return LINE_TOO_LONG;
    buf[n] = 0;
    *len = n;
    return LINE_OK;
}

/* Checks that a line is text: no NUL, no control characters but tab, and well-formed UTF-8 (no overlong
 * forms, no surrogates, nothing above U+10FFFF). Fills the error and returns false otherwise. */
static bool check_text(trace_reader *r, const char *line, size_t len)
{
    const unsigned char *bytes = (const unsigned char *)line;
    size_t i = 0;
    while (i < len) {
        unsigned char c = bytes[i];
        if (c == 0)
            return fail(r, "NUL byte at column %zu: this is not a text file", i + 1);
        if (c < 0x80) {
            if ((c < 0x20 && c != '\t') || c == 0x7f)
                return fail(r, "control character 0x%02x at column %zu: this is not a text file", c, i + 1);
            i++;
            continue;
        }
        size_t extra;
        uint32_t code_point, minimum;
        if (c >= 0xc2 && c <= 0xdf)
            extra = 1, code_point = c & 0x1fu, minimum = 0x80;
        else if (c >= 0xe0 && c <= 0xef)
            extra = 2, code_point = c & 0x0fu, minimum = 0x800;
        else if (c >= 0xf0 && c <= 0xf4)
            extra = 3, code_point = c & 0x07u, minimum = 0x10000;
        else
            return fail(r, "invalid UTF-8 (byte 0x%02x at column %zu): this is not a text file", c, i + 1);
        for (size_t k = 1; k <= extra; k++) {
            if (i + k >= len)
                return fail(r, "invalid UTF-8 (truncated sequence at column %zu): this is not a text file",
                            i + 1);
            unsigned char continuation = bytes[i + k];
            if ((continuation & 0xc0u) != 0x80u)
                return fail(r, "invalid UTF-8 (byte 0x%02x at column %zu): this is not a text file", c,
                            i + 1);
            code_point = (code_point << 6) | (continuation & 0x3fu);
        }
        if (code_point < minimum || code_point > 0x10ffff || (code_point >= 0xd800 && code_point <= 0xdfff))
            return fail(
                r, "invalid UTF-8 (overlong or out-of-range sequence at column %zu): this is not a text file",
                i + 1);
        i += extra + 1;
    }
    return true;
}

/* True for the separators between fields: space and tab. */
static bool is_separator(char c)
{
    return c == ' ' || c == '\t';
}

/* Splits a line at spaces and tabs: up to max_tokens (start, length) pairs; returns the total number of
 * tokens on the line, which may be more than max_tokens. */
static size_t split_tokens(const char *line, size_t len, const char **starts, size_t *lengths,
                           size_t max_tokens)
{
    size_t count = 0, i = 0;
    while (i < len) {
        while (i < len && is_separator(line[i]))
            i++;
        if (i >= len)
            break;
        size_t begin = i;
        while (i < len && !is_separator(line[i]))
            i++;
        if (count < max_tokens) {
            starts[count] = line + begin;
            lengths[count] = i - begin;
        }
        count++;
    }
    return count;
}

/* True when a token spells NaN or infinity in a form strtod would accept ("nan", "-inf", "Infinity"). */
static bool token_is_nan_or_inf(const char *token, size_t len)
{
    if (len > 0 && (token[0] == '+' || token[0] == '-'))
        token++, len--;
    if (len == 0)
        return false;
    char first = token[0];
    return first == 'n' || first == 'N' || first == 'i' || first == 'I';
}

/* Parses a token as a finite decimal number. Accepts only digits, sign, '.', and an exponent; reports the
 * column by name on failure. */
static bool parse_number(trace_reader *r, const char *token, size_t len, int column, double *out)
{
    char quoted[48];
    snippet(token, len, quoted, sizeof quoted);
    const char *name = trace_column_names[column];
    if (token_is_nan_or_inf(token, len))
        return fail(r, "%s is '%s': numbers must be finite (no NaN or infinity)", name, quoted);
    if (len > 64)
        return fail(r, "%s '%s' is not a number (too long)", name, quoted);
    bool has_digit = false;
    for (size_t i = 0; i < len; i++) {
        char c = token[i];
        if (c >= '0' && c <= '9')
            has_digit = true;
        else if (c != '+' && c != '-' && c != '.' && c != 'e' && c != 'E')
            return fail(r, "%s '%s' is not a number", name, quoted);
    }
    if (!has_digit)
        return fail(r, "%s '%s' is not a number", name, quoted);
    char copy[72];
    memcpy(copy, token, len);
    copy[len] = 0;
    char *end = NULL;
    errno = 0;
    double value = strtod(copy, &end);
    if (end != copy + len)
        return fail(r, "%s '%s' is not a number", name, quoted);
    if (!isfinite(value))
        return fail(r, "%s '%s' is not finite (too large)", name, quoted);
    *out = value;
    return true;
}

/* Parses and checks the header line: the magic word and a version this build reads. */
static bool parse_header(trace_reader *r, const char *line, size_t len)
{
    static const char bom[] = "\xef\xbb\xbf";
    if (len >= 3 && memcmp(line, bom, 3) == 0)
        line += 3, len -= 3; /* a UTF-8 byte-order mark, as some editors write */
    const char *starts[3];
    size_t lengths[3];
    size_t count = split_tokens(line, len, starts, lengths, 3);
    size_t magic_len = strlen(SRV_TRACE_MAGIC);
    char quoted[48];
    snippet(line, len, quoted, sizeof quoted);
    if (count == 0 || lengths[0] != magic_len || memcmp(starts[0], SRV_TRACE_MAGIC, magic_len) != 0)
        return fail(r, "missing header: the first line must be '%s %d', got '%s'", SRV_TRACE_MAGIC,
                    SRV_TRACE_VERSION, quoted);
    if (count < 2)
        return fail(r, "malformed header '%s': no version after '%s'", quoted, SRV_TRACE_MAGIC);
    if (count > 2)
        return fail(r, "malformed header '%s': trailing text after the version", quoted);
    uint64_t version = 0; /* saturates: any huge number is still "newer" */
    for (size_t i = 0; i < lengths[1]; i++) {
        char c = starts[1][i];
        if (c < '0' || c > '9')
            return fail(r, "malformed header '%s': the version is not a whole number", quoted);
        if (version < 1000000000u)
            version = version * 10 + (uint64_t)(c - '0');
    }
    char version_text[48];
    snippet(starts[1], lengths[1], version_text, sizeof version_text);
    if (version > SRV_TRACE_VERSION)
        return fail(r, "trace format version %s is newer than this fxcache reads (version %d)", version_text,
                    SRV_TRACE_VERSION);
    if (version < 1)
        return fail(r, "trace format version %s is not supported (this fxcache reads version %d)",
                    version_text, SRV_TRACE_VERSION);
    r->trace->version = (uint32_t)version;
    return true;
}

/* Version 2: "resolution W H" before the first camera, at most once; sides 1..SRV_TRACE_MAX_SIDE. */
static bool parse_resolution_line(trace_reader *r, const char *line, size_t len)
{
    const char *starts[4];
    size_t lengths[4];
    size_t count = split_tokens(line, len, starts, lengths, 4);
    if (r->trace->version < 2)
        return fail(r, "a 'resolution' line needs format version 2 (the header says 1)");
    if (r->trace->count > 0)
        return fail(r, "the 'resolution' line must come before the first camera");
    if (r->trace->width)
        return fail(r, "a second 'resolution' line");
    if (count != 3)
        return fail(r, "expected 'resolution WIDTH HEIGHT', got %zu words", count);
    uint32_t side[2];
    for (int i = 0; i < 2; i++) {
        uint64_t v = 0;
        for (size_t k = 0; k < lengths[i + 1]; k++) {
            char c = starts[i + 1][k];
            if (c < '0' || c > '9')
                return fail(r, "resolution: '%.*s' is not a whole number", (int)(lengths[i + 1] < 32 ? lengths[i + 1] : 32),
                            starts[i + 1]);
            if (v < 1000000000u)
                v = v * 10 + (uint64_t)(c - '0');
        }
        if (v < 1 || v > SRV_TRACE_MAX_SIDE)
            return fail(r, "resolution: %s %llu is outside 1..%d", i ? "height" : "width", (unsigned long long)v,
                        SRV_TRACE_MAX_SIDE);
        side[i] = (uint32_t)v;
    }
    r->trace->width = side[0];
    r->trace->height = side[1];
    return true;
}

/* Appends a camera and its time to the trace, growing it with overflow-checked doubling. */
static bool append_camera(trace_reader *r, double time, const trace_camera *cam)
{
    srv_trace *t = r->trace;
    if (t->count == t->capacity) {
        if (t->capacity >= UINT32_MAX / 2)
            return fail(r, "too many cameras (at most %u)", UINT32_MAX / 2);
        uint32_t capacity = t->capacity ? t->capacity * 2 : 256;
#if SIZE_MAX < UINT64_MAX /* only a 32-bit size_t can overflow here */
        if (SIZE_MAX / sizeof(trace_camera) < capacity)
            return fail(r, "too many cameras for this machine's memory");
#endif
        trace_camera *cameras = realloc(t->cameras, (size_t)capacity * sizeof *cameras);
        if (!cameras)
            return fail(r, "out of memory after %u cameras", t->count);
        t->cameras = cameras;
        double *times = realloc(t->times, (size_t)capacity * sizeof *times);
        if (!times)
            return fail(r, "out of memory after %u cameras", t->count);
        t->times = times;
        t->capacity = capacity;
    }
    t->cameras[t->count] = *cam;
    t->times[t->count] = time;
    t->count++;
    return true;
}

/* Parses one camera line: exactly 8 finite numbers, checked one by one, then appended. */
static bool parse_camera_line(trace_reader *r, const char *line, size_t len)
{
    const char *starts[TRACE_COLUMNS + 1];
    size_t lengths[TRACE_COLUMNS + 1];
    size_t count = split_tokens(line, len, starts, lengths, TRACE_COLUMNS + 1);
    if (count < TRACE_COLUMNS)
        return fail(r, "expected %d numbers (time px py pz dx dy dz fov_deg), got %zu", TRACE_COLUMNS, count);
    if (count > TRACE_COLUMNS) {
        char quoted[48];
        snippet(starts[TRACE_COLUMNS], (size_t)(line + len - starts[TRACE_COLUMNS]), quoted, sizeof quoted);
        return fail(r, "expected %d numbers (time px py pz dx dy dz fov_deg), got %zu: trailing text '%s'",
                    TRACE_COLUMNS, count, quoted);
    }
    double values[TRACE_COLUMNS];
    for (int column = 0; column < TRACE_COLUMNS; column++)
        if (!parse_number(r, starts[column], lengths[column], column, &values[column]))
            return false;
    char text[2][32];
    for (int column = 1; column < TRACE_COLUMNS; column++)
        if (fabs(values[column]) > FLT_MAX) {
            format_double_exact(values[column], text[0], sizeof text[0]);
            return fail(r, "%s %s is outside the range of a float", trace_column_names[column], text[0]);
        }
    double time = values[0], fov_deg = values[7];
    const double *position = values + 1, *direction = values + 4;
    srv_trace *t = r->trace;
    if (t->count > 0 && time < t->times[t->count - 1]) {
        format_double_exact(time, text[0], sizeof text[0]);
        format_double_exact(t->times[t->count - 1], text[1], sizeof text[1]);
        return fail(r, "time %s is before the previous line's %s (times must not decrease)", text[0],
                    text[1]);
    }
    if (!(fov_deg > 0 && fov_deg < 180)) {
        format_double_exact(fov_deg, text[0], sizeof text[0]);
        return fail(r, "fov_deg %s is outside (0, 180)", text[0]);
    }
    if (direction[0] == 0 && direction[1] == 0 && direction[2] == 0)
        return fail(r, "direction (0, 0, 0) is zero: a camera must look somewhere");
    /* Checked in double, as kept: the scene's local frame may hold the camera more precisely than a float
     * at these world coordinates could (srv_trace_camera). */
    trace_camera cam = {.fov_deg = (float)fov_deg};
    bool target_differs = false;
    for (int k = 0; k < 3; k++) {
        cam.position[k] = position[k];
        cam.direction[k] = direction[k];
        if (!(fabs(position[k] + direction[k]) <= FLT_MAX))
            return fail(r, "position + direction is outside the range of a float");
        if (position[k] + direction[k] != position[k])
            target_differs = true;
    }
    if (!target_differs)
        return fail(r,
                    "direction is too small for this position: position + direction rounds to the position");
    if (!(cam.fov_deg > 0 && cam.fov_deg < 180))
        return fail(r, "fov_deg rounds to 0 or 180 as a float");
    return append_camera(r, time, &cam);
}

/* Reads every line of an open trace file; returns false with the error filled at the first problem. */
static bool read_all_lines(trace_reader *r)
{
    char *buf = malloc(SRV_TRACE_MAX_LINE + 2); /* on the heap so that threads and the stack stay small */
    if (!buf)
        return fail(r, "out of memory");
    bool ok = true, header_seen = false;
    for (;;) {
        if (r->line_number == UINT32_MAX) {
            ok = fail(r, "too many lines");
            break;
        }
        r->line_number++;
        size_t len = 0;
        line_status status = read_line(r->file, buf, &len);
        if (status == LINE_END_OF_FILE) {
            r->line_number--;
            if (!header_seen) {
                r->line_number = 1;
                ok = fail(r, "empty file: expected the header '%s %d'", SRV_TRACE_MAGIC, SRV_TRACE_VERSION);
            } else if (r->trace->count == 0) {
                ok = fail(r, "no cameras: a trace needs at least one camera line after the header");
            }
            break;
        }
        if (status == LINE_TOO_LONG) {
            ok = fail(r, "line longer than %d bytes: this is not a trace file", SRV_TRACE_MAX_LINE);
            break;
        }
        if (status == LINE_READ_ERROR) {
            ok = fail(r, "read error: %s", strerror(errno));
            break;
        }
        if (!check_text(r, buf, len)) {
            ok = false;
            break;
        }
        if (!header_seen) {
            if (!(ok = parse_header(r, buf, len)))
                break;
            header_seen = true;
            continue;
        }
        size_t first = 0;
        while (first < len && is_separator(buf[first]))
            first++;
        if (first == len || buf[first] == '#')
            continue; /* blank line or comment */
        if (len - first >= 10 && memcmp(buf + first, "resolution", 10) == 0) {
            if (!(ok = parse_resolution_line(r, buf, len)))
                break;
            continue;
        }
        if (!(ok = parse_camera_line(r, buf, len)))
            break;
    }
    free(buf);
    return ok;
}

srv_trace *srv_trace_read(const char *path, char *err, size_t cap)
{
    if (err && cap > 0)
        err[0] = 0;
    trace_reader reader = {.path = path ? path : "(null)", .err = err, .err_cap = cap};
    if (!path) {
        if (err && cap > 0)
            snprintf(err, cap, "(null): no trace file given");
        return NULL;
    }
    reader.file = fopen(path, "rb");
    if (!reader.file) {
        if (err && cap > 0)
            snprintf(err, cap, "%s: cannot open: %s", path, strerror(errno));
        return NULL;
    }
    reader.trace = calloc(1, sizeof *reader.trace);
    bool ok = reader.trace != NULL;
    if (!ok && err && cap > 0)
        snprintf(err, cap, "%s: out of memory", path);
    if (ok)
        ok = read_all_lines(&reader);
    fclose(reader.file);
    if (!ok) {
        srv_trace_free(reader.trace);
        return NULL;
    }
    return reader.trace;
}

uint32_t srv_trace_count(const srv_trace *t)
{
    return t ? t->count : 0;
}

srv_camera srv_trace_camera_world(const scene *s, const double position[3], const double direction[3], float fov_deg)
{
    srv_camera cam = {.up = {0, 1, 0}, .fov_deg = fov_deg};
    if (s) {
        scene_world_to_local(s, position, cam.position);
    } else {
        for (int k = 0; k < 3; k++)
            cam.position[k] = (float)position[k];
    }
    /* The target from the rounded position, so a recorded camera reads back exactly. */
    bool target_differs = false;
    for (int k = 0; k < 3; k++) {
        cam.target[k] = (float)((double)cam.position[k] + direction[k]);
        target_differs |= cam.target[k] != cam.position[k];
    }
    if (!target_differs) {
        /* A direction below the float spacing at this position: the same direction, one position-length
         * long (the view does not depend on the target's distance). */
        double length = sqrt(direction[0] * direction[0] + direction[1] * direction[1] +
                             direction[2] * direction[2]);
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
    const trace_camera *c = &t->cameras[index];
    double direction[3] = {c->direction[0], c->direction[1], c->direction[2]};
    return srv_trace_camera_world(s, c->position, direction, c->fov_deg);
}

srv_camera srv_trace_camera(const srv_trace *t, const scene *s, uint32_t frame)
{
    return trace_camera_local(t, s, frame < t->count ? frame : t->count - 1);
}

double srv_trace_time(const srv_trace *t, uint32_t frame)
{
    uint32_t index = frame < t->count ? frame : t->count - 1;
    return t->times[index];
}

bool srv_trace_resolution(const srv_trace *t, uint32_t *width, uint32_t *height)
{
    if (!t->width)
        return false;
    *width = t->width;
    *height = t->height;
    return true;
}

double srv_trace_first_time(const srv_trace *t)
{
    return t->times[0];
}

double srv_trace_last_time(const srv_trace *t)
{
    return t->times[t->count - 1];
}

srv_camera srv_trace_camera_at(const srv_trace *t, const scene *s, double time)
{
    /* The last line whose time is not after `time` (binary search; times do not decrease). */
    uint32_t lo = 0, hi = t->count;
    while (hi - lo > 1) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (t->times[mid] <= time + SRV_TRACE_TIME_EPSILON)
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
    free(t->cameras);
    free(t->times);
    free(t);
}

/* ---- writer ------------------------------------------------------------------------------------------ */

srv_trace_writer *srv_trace_writer_open(const char *path, const scene *s, char *err, size_t cap)
{
    return srv_trace_writer_open_sized(path, s, 0, 0, err, cap);
}

srv_trace_writer *srv_trace_writer_open_sized(const char *path, const scene *s, uint32_t width, uint32_t height,
                                              char *err, size_t cap)
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
    int written = fprintf(w->file,
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
    format_double_exact(time, time_text, sizeof time_text);
    for (int k = 0; k < 3; k++)
        format_double_exact((double)cam->position[k] + w->origin[k], position_text[k], sizeof position_text[k]);
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
