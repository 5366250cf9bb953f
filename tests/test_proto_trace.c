/* Tests of the in-memory viewer-trace parser (proto/proto_trace.c), beyond what tests/test_trace.c checks
 * through the server's file reader:
 *  - the messages of docs/TRACE_FORMAT.md's "Errors" section, word for word (the documentation is the
 *    expectation, not the code's own format strings);
 *  - the numbers come out as written: the exact doubles of the text, the resolution, the version;
 *  - text that is not NUL-terminated: every prefix of a valid trace in an allocation of exactly its length,
 *    so the sanitizer build sees any read past the end;
 *  - lengths, not terminators: a NUL inside the text is refused at its column, text after len is not read;
 *  - argument errors and result codes; release;
 *  - proto_trace_format_number() against numbers whose shortest exact spelling is known;
 *  - the server's file layer (srv_trace_read) hands the parser the whole file: a trace far larger than its
 *    first read buffer gives the same cameras as the parser on the same bytes, and a file over the size
 *    limit is refused with one line. */
#include "test_util.h"

#include "proto_trace.h"
#include "trace.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* A heap copy of len bytes with nothing after them (no terminator), so reads past the end are caught. */
static char *exact_copy(const char *text, size_t len)
{
    char *copy = malloc(len ? len : 1);
    assert_non_null(copy);
    if (len)
        memcpy(copy, text, len);
    return copy;
}

/* Parses len bytes of text from an exact-size allocation. */
static fxc_result parse(const char *text, size_t len, const char *name, proto_trace *out, char *err,
                        size_t cap)
{
    char *copy = exact_copy(text, len);
    fxc_result result = proto_trace_parse(copy, len, name, out, err, cap);
    free(copy);
    return result;
}

/* Each example message of docs/TRACE_FORMAT.md, "Errors", from a text that gives it. */
static void test_documented_messages(void **state)
{
    (void)state;
    static const struct {
        const char *text;
        size_t len; /* 0: strlen(text) */
        const char *message;
    } cases[] = {
        {"0 0 0 0 1 0 0 60\n", 0,
         "walk.trace:1: missing header: the first line must be 'fxcache-trace 2', got '0 0 0 0 1 0 0 60'"},
        {"fxcache-trace 3\n0 0 0 0 1 0 0 60\n", 0,
         "walk.trace:1: trace format version 3 is newer than this fxcache reads (version 2)"},
        {"", 0, "walk.trace:1: empty file: expected the header 'fxcache-trace 2'"},
        {"fxcache-trace 1\nresolution 64 36\n0 0 0 0 1 0 0 60\n", 0,
         "walk.trace:2: a 'resolution' line needs format version 2 (the header says 1)"},
        {"fxcache-trace 2\n# a\n\n0 0 0 0 1 0 0 60\nresolution 64 36\n", 0,
         "walk.trace:5: the 'resolution' line must come before the first camera"},
        {"fxcache-trace 2\n# only\n# comments\n\n", 0,
         "walk.trace:4: no cameras: a trace needs at least one camera line after the header"},
        {"fxcache-trace 2\n#\n#\n#\n#\n#\n0 0 0 0 1\n", 0,
         "walk.trace:7: expected 8 numbers (time px py pz dx dy dz fov_deg), got 5"},
        {"fxcache-trace 2\n#\n#\n#\n#\n#\n0 0 0 0 1 0 0 60 abc\n", 0,
         "walk.trace:7: expected 8 numbers (time px py pz dx dy dz fov_deg), got 9: trailing text 'abc'"},
        {"fxcache-trace 2\n#\n0 0 0 0 1 0 0 0\n", 0, "walk.trace:3: fov_deg 0 is outside (0, 180)"},
        {"fxcache-trace 2\n0 0 0 0 1 0 0 60\n1 0 0 0 1 0 0 60\n#\n#\n#\n#\n2 0 0 0 1 0 0 60\n1.5 0 0 0 1 0 0 "
         "60\n",
         0, "walk.trace:9: time 1.5 is before the previous line's 2 (times must not decrease)"},
        {"fxcache-trace 2\n0 0 nan 0 1 0 0 60\n", 0,
         "walk.trace:2: py is 'nan': numbers must be finite (no NaN or infinity)"},
        {"fxcache-trace 2\n0 1e999 0 0 1 0 0 60\n", 0, "walk.trace:2: px '1e999' is not finite (too large)"},
        {"fxcache-trace 2\n0 0 0 0 1.5abc 0 0 60\n", 0, "walk.trace:2: dx '1.5abc' is not a number"},
        {"fxcache-trace 2\n0 1 2 3 0 0 0 60\n", 0,
         "walk.trace:2: direction (0, 0, 0) is zero: a camera must look somewhere"},
        {"fxcache-trace 2\n0 0 0\0 0 1 0 0 60\n", 34,
         "walk.trace:2: NUL byte at column 6: this is not a text file"},
        {"fxcache-trace 2\n# caf\xe9 au lait\n0 0 0 0 1 0 0 60\n", 0,
         "walk.trace:2: invalid UTF-8 (byte 0xe9 at column 6): this is not a text file"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        size_t len = cases[i].len ? cases[i].len : strlen(cases[i].text);
        proto_trace t;
        char err[512];
        fxc_result result = parse(cases[i].text, len, "walk.trace", &t, err, sizeof err);
        if (result != FXC_ERR_FORMAT)
            fail_msg("case %zu: result %d (%s), expected a format error", i, result, fxc_strerror(result));
        if (strcmp(err, cases[i].message) != 0)
            fail_msg("case %zu:\n got      %s\n expected %s", i, err, cases[i].message);
        assert_int_equal(t.count, 0); /* nothing partial */
        assert_null(t.cameras);
        assert_null(t.times);
    }

    /* The line too long (documented as line 3): a comment of PROTO_TRACE_MAX_LINE + 1 bytes. */
    const char *start = "fxcache-trace 2\n0 0 0 0 1 0 0 60\n";
    size_t start_len = strlen(start), len = start_len + PROTO_TRACE_MAX_LINE + 1;
    char *text = malloc(len);
    assert_non_null(text);
    memcpy(text, start, start_len);
    memset(text + start_len, '#', PROTO_TRACE_MAX_LINE + 1); /* no line end: the text just stops */
    proto_trace t;
    char err[512];
    assert_int_equal(parse(text, len, "walk.trace", &t, err, sizeof err), FXC_ERR_FORMAT);
    assert_string_equal(err, "walk.trace:3: line longer than 4096 bytes: this is not a trace file");
    /* One byte shorter is a comment, and the camera before it counts. */
    assert_int_equal(parse(text, len - 1, "walk.trace", &t, err, sizeof err), FXC_OK);
    assert_int_equal(t.count, 1);
    proto_trace_release(&t);
    free(text);

    /* Without a file name the messages say "(trace)". */
    assert_int_equal(parse("", 0, NULL, &t, err, sizeof err), FXC_ERR_FORMAT);
    assert_string_equal(err, "(trace):1: empty file: expected the header 'fxcache-trace 2'");
}

/* The numbers come out exactly as the text spells them (strtod of the token), with the header's version and
 * the resolution line. */
static void test_values(void **state)
{
    (void)state;
    const char *text = "\xef\xbb\xbf"
                       "fxcache-trace 2\r\n"
                       "# world coordinates far from the origin\r\n"
                       "resolution 320 8192\r\n"
                       "0.1\t1000004.3 -2.5e-3 7   0.1 -0.2 1e-9  59.9\r\n"
                       "0.1 -1e6 0 .5 -3 0 4 1e-3\r\n"
                       "   \t \r\n"
                       "1e2 3 2 1 0 1 0 179.99";
    proto_trace t;
    char err[256];
    assert_int_equal(parse(text, strlen(text), "v.trace", &t, err, sizeof err), FXC_OK);
    assert_int_equal(t.version, 2);
    assert_int_equal(t.width, 320);
    assert_int_equal(t.height, 8192);
    assert_int_equal(t.count, 3);
    static const double expected[3][8] = {
        {0.1, 1000004.3, -2.5e-3, 7, 0.1, -0.2, 1e-9, 59.9},
        {0.1, -1e6, 0, 0.5, -3, 0, 4, 1e-3},
        {100, 3, 2, 1, 0, 1, 0, 179.99},
    };
    for (uint32_t i = 0; i < 3; i++) {
        assert_true(t.times[i] == expected[i][0]);
        for (int k = 0; k < 3; k++) {
            assert_true(t.cameras[i].position[k] == expected[i][1 + k]);
            assert_true(t.cameras[i].direction[k] == expected[i][4 + k]);
        }
        assert_true(t.cameras[i].fov_deg == (float)expected[i][7]);
    }
    proto_trace_release(&t);
    assert_int_equal(t.count, 0);
    assert_null(t.cameras);
    proto_trace_release(&t); /* twice is harmless */
    proto_trace_release(NULL);

    /* Version 1 has no resolution. */
    const char *v1 = "fxcache-trace 1\n5 0 0 0 0 0 -1 90\n";
    assert_int_equal(parse(v1, strlen(v1), "v1.trace", &t, err, sizeof err), FXC_OK);
    assert_int_equal(t.version, 1);
    assert_int_equal(t.width, 0);
    assert_int_equal(t.height, 0);
    assert_true(t.times[0] == 5.0);
    proto_trace_release(&t);
}

/* Every prefix of a valid trace, each in an allocation of exactly its length: accepted with the cameras whose
 * lines are whole (a last line without its line end counts), or refused with one line. */
static void test_every_prefix(void **state)
{
    (void)state;
    const char *text = "fxcache-trace 2\r\n# caf\xc3\xa9\nresolution 64 36\n0 -4.2 2 3.4 6.7 -1.6 -3.2 60\n"
                       "0.033 -4.1 2 3.4 6.7 -1.6 -3.2 60\r\n";
    size_t len = strlen(text);
    /* Where each camera line's last digit ends: a prefix through it holds that camera. */
    const char *first_end = strstr(text, "-3.2 60\n") + strlen("-3.2 60");
    const char *second_end = strstr(text, "-3.2 60\r\n") + strlen("-3.2 60");
    unsigned accepted = 0;
    for (size_t prefix = 0; prefix <= len; prefix++) {
        proto_trace t;
        char err[512] = "";
        fxc_result result = parse(text, prefix, "prefix.trace", &t, err, sizeof err);
        uint32_t expected = 0; /* camera lines whole in this prefix */
        if (prefix >= (size_t)(first_end - text))
            expected = prefix >= (size_t)(second_end - text) ? 2 : 1;
        if (result == FXC_OK) {
            /* The whole camera lines, perhaps one more cut short that still reads ("6" of "60"). */
            accepted++;
            assert_true(t.count == expected || t.count == expected + 1);
            assert_int_equal(t.width, 64);
            proto_trace_release(&t);
        } else {
            /* Refused only before the first camera is whole, or at the cut second camera line. */
            assert_true(expected == 0 || (expected == 1 && strstr(err, "prefix.trace:5:")));
            assert_int_equal(result, FXC_ERR_FORMAT);
            assert_true(strncmp(err, "prefix.trace:", 13) == 0);
            assert_null(strchr(err, '\n'));
        }
    }
    assert_true(accepted >= 2);
}

/* The length is the text's end, not a NUL: text after len is never looked at, a NUL before it is refused. */
static void test_length_not_terminator(void **state)
{
    (void)state;
    const char *text = "fxcache-trace 1\n0 0 0 0 1 0 0 60\nthis line is not part of the trace";
    size_t len = strlen("fxcache-trace 1\n0 0 0 0 1 0 0 60\n");
    proto_trace t;
    char err[256];
    assert_int_equal(parse(text, len, "a.trace", &t, err, sizeof err), FXC_OK);
    assert_int_equal(t.count, 1);
    proto_trace_release(&t);

    const char with_nul[] = "fxcache-trace 1\n0 0 0 0 1 0 0 60\n\0\n";
    assert_int_equal(parse(with_nul, sizeof with_nul - 1, "b.trace", &t, err, sizeof err), FXC_ERR_FORMAT);
    assert_string_equal(err, "b.trace:3: NUL byte at column 1: this is not a text file");
}

/* Arguments a caller can get wrong, and error buffers of any size. */
static void test_arguments(void **state)
{
    (void)state;
    proto_trace t;
    char err[128];
    assert_int_equal(proto_trace_parse("fxcache-trace 1\n", 16, "x.trace", NULL, err, sizeof err),
                     FXC_ERR_INVALID);
    assert_non_null(strstr(err, "x.trace"));
    assert_int_equal(proto_trace_parse(NULL, 3, "x.trace", &t, err, sizeof err), FXC_ERR_INVALID);
    /* No text at all is an empty file. */
    assert_int_equal(proto_trace_parse(NULL, 0, "x.trace", &t, err, sizeof err), FXC_ERR_FORMAT);
    assert_string_equal(err, "x.trace:1: empty file: expected the header 'fxcache-trace 2'");
    /* A tiny error buffer gets a truncated message; none at all is allowed. */
    assert_int_equal(parse("nonsense", 8, "x.trace", &t, err, 5), FXC_ERR_FORMAT);
    assert_string_equal(err, "x.tr");
    assert_int_equal(parse("nonsense", 8, "x.trace", &t, NULL, 0), FXC_ERR_FORMAT);
    /* A success clears an earlier message. */
    assert_int_equal(parse("fxcache-trace 1\n0 0 0 0 1 0 0 60", 32, "x.trace", &t, err, sizeof err), FXC_OK);
    assert_string_equal(err, "");
    proto_trace_release(&t);
}

/* The shortest spelling with 9 to 17 significant digits that reads back to the same double (expectations
 * from Python's printf and float(), a second implementation). */
static void test_format_number(void **state)
{
    (void)state;
    static const struct {
        double value;
        const char *text;
    } cases[] = {
        {0, "0"},
        {0.1, "0.1"}, /* %.9g drops trailing zeros */
        {-4.2, "-4.2"},
        {1000004.3, "1000004.3"},
        {1.0 / 3.0, "0.3333333333333333"},  /* 16 digits */
        {0.1 + 0.2, "0.30000000000000004"}, /* 17 */
        {1e300, "1e+300"},
        {1234567891.0, "1234567891"}, /* %.9g would print 1.23456789e+09, which is another number */
        {5e-324, "4.94065646e-324"},  /* the smallest subnormal: 9 digits read back */
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char buf[32];
        proto_trace_format_number(cases[i].value, buf, sizeof buf);
        if (strcmp(buf, cases[i].text) != 0)
            fail_msg("case %zu: got %s, expected %s", i, buf, cases[i].text);
    }
}

/* ---- the server's file layer ------------------------------------------------------------------------- */

/* Writes len bytes to a scratch file; returns its path (static buffer). */
static const char *write_bytes(const char *name, const void *data, size_t len)
{
    const char *path = fxt_tmp_path(name);
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(data, 1, len, f), len);
    fclose(f);
    return path;
}

/* A trace of 20000 cameras (about 700 KB, several times the reader's first buffer): srv_trace_read() and the
 * parser on the same bytes agree on every camera and time; the same text cut in the middle of a camera line
 * deep in the file is refused at that line by both, with the same message. */
static void test_file_reader_hands_over_every_byte(void **state)
{
    (void)state;
    const uint32_t count = 20000;
    size_t cap = 64 + (size_t)count * 48, len = 0;
    char *text = malloc(cap);
    assert_non_null(text);
    len += (size_t)snprintf(text + len, cap - len, "fxcache-trace 2\nresolution 96 54\n");
    for (uint32_t i = 0; i < count; i++)
        len += (size_t)snprintf(text + len, cap - len, "%u.5 %u -2 3 0 0 -1 %u\n", i, i % 1000, 1 + i % 170);
    const char *path = write_bytes("big.trace", text, len);
    char err[512];
    srv_trace *t = srv_trace_read(path, err, sizeof err);
    if (!t)
        fail_msg("%s", err);
    proto_trace parsed;
    assert_int_equal(proto_trace_parse(text, len, path, &parsed, err, sizeof err), FXC_OK);
    assert_int_equal(srv_trace_count(t), count);
    assert_int_equal(parsed.count, count);
    uint32_t width = 0, height = 0;
    assert_true(srv_trace_resolution(t, &width, &height));
    assert_int_equal(width, 96);
    assert_int_equal(height, 54);
    for (uint32_t i = 0; i < count; i++) {
        assert_true(srv_trace_time(t, i) == i + 0.5);
        assert_true(parsed.times[i] == i + 0.5);
        srv_camera cam = srv_trace_camera(t, NULL, i);
        assert_true(cam.position[0] == (float)(i % 1000) &&
                    cam.position[0] == (float)parsed.cameras[i].position[0]);
        assert_true(cam.fov_deg == (float)(1 + i % 170) && cam.fov_deg == parsed.cameras[i].fov_deg);
    }
    srv_trace_free(t);
    proto_trace_release(&parsed);

    /* Cut in the middle of camera line 15002 (line 15004 of the file, past the first buffers). */
    size_t cut = 0;
    for (uint32_t line = 0; line < 15003; line++)
        cut = (size_t)(strchr(text + cut, '\n') - text) + 1;
    cut += 3; /* "15002.5 ..." cut after "150" */
    path = write_bytes("cut.trace", text, cut);
    char file_err[512];
    assert_null(srv_trace_read(path, file_err, sizeof file_err));
    assert_int_equal(proto_trace_parse(text, cut, path, &parsed, err, sizeof err), FXC_ERR_FORMAT);
    assert_string_equal(file_err, err);
    assert_non_null(strstr(err, ":15004: expected 8 numbers (time px py pz dx dy dz fov_deg), got 1"));
    free(text);
}

/* A file over PROTO_TRACE_MAX_FILE_BYTES (a sparse file: no disk space used) is refused with one line that
 * names it, not parsed. */
static void test_file_size_limit(void **state)
{
    (void)state;
    const char *path = write_bytes("huge.trace", "fxcache-trace 1\n", 16);
    assert_int_equal(truncate(path, (off_t)PROTO_TRACE_MAX_FILE_BYTES + 1), 0);
    char err[512];
    assert_null(srv_trace_read(path, err, sizeof err));
    char expected[1200];
    snprintf(expected, sizeof expected, "%s: larger than 256 MiB: too large for a trace file", path);
    assert_string_equal(err, expected);
    unlink(path);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_documented_messages),
        cmocka_unit_test(test_values),
        cmocka_unit_test(test_every_prefix),
        cmocka_unit_test(test_length_not_terminator),
        cmocka_unit_test(test_arguments),
        cmocka_unit_test(test_format_number),
        cmocka_unit_test(test_file_reader_hands_over_every_byte),
        cmocka_unit_test(test_file_size_limit),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
