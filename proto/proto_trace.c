/* The viewer-trace text format parsed from memory (proto_trace.h, docs/TRACE_FORMAT.md).
 *
 * Line oriented, for untrusted text: each line (at most PROTO_TRACE_MAX_LINE bytes without its line end) is
 * checked for NUL bytes, control characters and invalid UTF-8 before its content is looked at; numbers are
 * plain decimals only (no NaN, no infinity, no hex); the first problem ends the parse with one line
 * "FILE:LINE: what is wrong". Cameras are kept as read, in double and world coordinates, so a trace of a
 * scene far from the world origin loses nothing to float rounding (the server moves them into its scene's
 * local frame when it replays them, server/cameras/trace.c).
 *
 * The messages are those the server's file reader gave before the parser moved here, word for word: users
 * and tests quote them. */
#include "proto_trace.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void proto_trace_format_number(double v, char *buf, size_t cap)
{
    for (int digits = 9; digits <= 17; digits++) {
        snprintf(buf, cap, "%.*g", digits, v);
        if (strtod(buf, NULL) == v)
            return;
    }
}

/* Columns of a camera line, in order. */
enum { TRACE_COLUMNS = 8 };
static const char *const trace_column_names[TRACE_COLUMNS] = {"time", "px", "py", "pz",
                                                              "dx",   "dy", "dz", "fov_deg"};

/* ---- shared helpers ---------------------------------------------------------------------------------- */

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
    const char *path;     /* the file name messages begin with */
    uint32_t line_number; /* 1-based number of the line being looked at */
    char *err;
    size_t err_cap;
    bool out_of_memory; /* the failure was memory, not the text (FXC_ERR_NOMEM) */
    uint32_t capacity;  /* allocated entries of trace->cameras and trace->times */
    proto_trace *trace;
} trace_reader;

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

/* The same for memory running out, which is not the text's fault (FXC_ERR_NOMEM). */
static bool fail_out_of_memory(trace_reader *r, uint32_t cameras)
{
    r->out_of_memory = true;
    return fail(r, "out of memory after %u cameras", cameras);
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
    size_t magic_len = strlen(PROTO_TRACE_MAGIC);
    char quoted[48];
    snippet(line, len, quoted, sizeof quoted);
    if (count == 0 || lengths[0] != magic_len || memcmp(starts[0], PROTO_TRACE_MAGIC, magic_len) != 0)
        return fail(r, "missing header: the first line must be '%s %d', got '%s'", PROTO_TRACE_MAGIC,
                    PROTO_TRACE_VERSION, quoted);
    if (count < 2)
        return fail(r, "malformed header '%s': no version after '%s'", quoted, PROTO_TRACE_MAGIC);
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
    if (version > PROTO_TRACE_VERSION)
        return fail(r, "trace format version %s is newer than this fxcache reads (version %d)", version_text,
                    PROTO_TRACE_VERSION);
    if (version < 1)
        return fail(r, "trace format version %s is not supported (this fxcache reads version %d)",
                    version_text, PROTO_TRACE_VERSION);
    r->trace->version = (uint32_t)version;
    return true;
}

/* Version 2: "resolution W H" before the first camera, at most once; sides 1..PROTO_TRACE_MAX_SIDE. */
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
                return fail(r, "resolution: '%.*s' is not a whole number",
                            (int)(lengths[i + 1] < 32 ? lengths[i + 1] : 32), starts[i + 1]);
            if (v < 1000000000u)
                v = v * 10 + (uint64_t)(c - '0');
        }
        if (v < 1 || v > PROTO_TRACE_MAX_SIDE)
            return fail(r, "resolution: %s %llu is outside 1..%d", i ? "height" : "width",
                        (unsigned long long)v, PROTO_TRACE_MAX_SIDE);
        side[i] = (uint32_t)v;
    }
    r->trace->width = side[0];
    r->trace->height = side[1];
    return true;
}

/* Appends a camera and its time to the trace, growing it with overflow-checked doubling. */
static bool append_camera(trace_reader *r, double time, const proto_trace_camera *cam)
{
    proto_trace *t = r->trace;
    if (t->count == r->capacity) {
        if (r->capacity >= UINT32_MAX / 2)
            return fail(r, "too many cameras (at most %u)", UINT32_MAX / 2);
        uint32_t capacity = r->capacity ? r->capacity * 2 : 256;
#if SIZE_MAX < UINT64_MAX /* only a 32-bit size_t can overflow here */
        if (SIZE_MAX / sizeof(proto_trace_camera) < capacity)
            return fail(r, "too many cameras for this machine's memory");
#endif
        proto_trace_camera *cameras = realloc(t->cameras, (size_t)capacity * sizeof *cameras);
        if (!cameras)
            return fail_out_of_memory(r, t->count);
        t->cameras = cameras;
        double *times = realloc(t->times, (size_t)capacity * sizeof *times);
        if (!times)
            return fail_out_of_memory(r, t->count);
        t->times = times;
        r->capacity = capacity;
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
            proto_trace_format_number(values[column], text[0], sizeof text[0]);
            return fail(r, "%s %s is outside the range of a float", trace_column_names[column], text[0]);
        }
    double time = values[0], fov_deg = values[7];
    const double *position = values + 1, *direction = values + 4;
    proto_trace *t = r->trace;
    if (t->count > 0 && time < t->times[t->count - 1]) {
        proto_trace_format_number(time, text[0], sizeof text[0]);
        proto_trace_format_number(t->times[t->count - 1], text[1], sizeof text[1]);
        return fail(r, "time %s is before the previous line's %s (times must not decrease)", text[0],
                    text[1]);
    }
    if (!(fov_deg > 0 && fov_deg < 180)) {
        proto_trace_format_number(fov_deg, text[0], sizeof text[0]);
        return fail(r, "fov_deg %s is outside (0, 180)", text[0]);
    }
    if (direction[0] == 0 && direction[1] == 0 && direction[2] == 0)
        return fail(r, "direction (0, 0, 0) is zero: a camera must look somewhere");
    /* Checked in double, as kept: the scene's local frame may hold the camera more precisely than a float
     * at these world coordinates could (srv_trace_camera). */
    proto_trace_camera cam = {.fov_deg = (float)fov_deg};
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

/* Finds the line that starts at text[*pos]: its start and length without the '\n' and without one '\r' before
 * it, and moves *pos past its line end. Returns false at the end of the text. A last line without a line end
 * is a line; nothing after a final '\n' is not. */
static bool next_line(const char *text, size_t len, size_t *pos, const char **line, size_t *line_len)
{
    if (*pos >= len)
        return false;
    const char *start = text + *pos;
    const char *newline = memchr(start, '\n', len - *pos);
    size_t n = newline ? (size_t)(newline - start) : len - *pos;
    *pos += n + (newline ? 1 : 0);
    if (n > 0 && start[n - 1] == '\r')
        n--;
    *line = start;
    *line_len = n;
    return true;
}

/* Parses every line; returns false with the error filled at the first problem. */
static bool parse_all_lines(trace_reader *r, const char *text, size_t len)
{
    bool header_seen = false;
    size_t pos = 0;
    for (;;) {
        if (r->line_number == UINT32_MAX)
            return fail(r, "too many lines");
        r->line_number++;
        const char *line;
        size_t line_len;
        if (!next_line(text, len, &pos, &line, &line_len)) {
            r->line_number--;
            if (!header_seen) {
                r->line_number = 1;
                return fail(r, "empty file: expected the header '%s %d'", PROTO_TRACE_MAGIC,
                            PROTO_TRACE_VERSION);
            }
            if (r->trace->count == 0)
                return fail(r, "no cameras: a trace needs at least one camera line after the header");
            return true;
        }
        if (line_len > PROTO_TRACE_MAX_LINE)
            return fail(r, "line longer than %d bytes: this is not a trace file", PROTO_TRACE_MAX_LINE);
        if (!check_text(r, line, line_len))
            return false;
        if (!header_seen) {
            if (!parse_header(r, line, line_len))
                return false;
            header_seen = true;
            continue;
        }
        size_t first = 0;
        while (first < line_len && is_separator(line[first]))
            first++;
        if (first == line_len || line[first] == '#')
            continue; /* blank line or comment */
        if (line_len - first >= 10 && memcmp(line + first, "resolution", 10) == 0) {
            if (!parse_resolution_line(r, line, line_len))
                return false;
            continue;
        }
        if (!parse_camera_line(r, line, line_len))
            return false;
    }
}

fxc_result proto_trace_parse(const char *text, size_t len, const char *file_name, proto_trace *out, char *err,
                             size_t cap)
{
    if (err && cap > 0)
        err[0] = 0;
    if (!out || (!text && len > 0)) {
        if (err && cap > 0)
            snprintf(err, cap, "%s: no trace text given", file_name ? file_name : "(trace)");
        return FXC_ERR_INVALID;
    }
    memset(out, 0, sizeof *out);
    trace_reader reader = {
        .path = file_name ? file_name : "(trace)", .err = err, .err_cap = cap, .trace = out};
    if (parse_all_lines(&reader, text ? text : "", len))
        return FXC_OK;
    proto_trace_release(out);
    return reader.out_of_memory ? FXC_ERR_NOMEM : FXC_ERR_FORMAT;
}

void proto_trace_release(proto_trace *t)
{
    if (!t)
        return;
    free(t->cameras);
    free(t->times);
    memset(t, 0, sizeof *t);
}
