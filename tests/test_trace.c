/* Tests of viewer traces (server/trace.c) and camera generators (server/camgen.c).
 *
 * Traces: a write-read round trip (positions and fov exact, directions equal after normalisation to float
 * precision, times exact), each refusal of the reader as one line naming the file, the line number and
 * the fault, a newer format version refused, the past-the-end rule, the writer's own refusals and its
 * per-line flush, every prefix of a valid file, and a bounded fuzz loop over random and mutated bytes.
 * Generators: valid cameras (finite, target != position, fov in range) for every kind on the default
 * scene, a scene without a camera and degenerate bounds; determinism; distinct viewers (except
 * `identical`); the walk inside the default room; the turn rate; the orbit rate. */
#include "test_util.h"

#include "camera.h"
#include "camgen.h"
#include "scene.h"
#include "trace.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Writes len bytes (may contain NUL) to a scratch file and returns its path (static buffer). */
static const char *write_bytes(const char *name, const void *data, size_t len)
{
    const char *path = fxt_tmp_path(name);
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(data, 1, len, f), len);
    fclose(f);
    return path;
}

/* Reads text as a trace that must be refused; checks the message is one line, begins with
 * "<path>:" and contains each of the given substrings (NULL-terminated list). */
static void expect_refusal(const char *name, const char *text, size_t len, ...)
{
    const char *path = write_bytes(name, text, len);
    char err[512];
    srv_trace *t = srv_trace_read(path, err, sizeof err);
    if (t)
        fail_msg("%s was accepted", name);
    assert_null(strchr(err, '\n'));
    assert_true(strncmp(err, path, strlen(path)) == 0);
    va_list args;
    va_start(args, len);
    const char *needle;
    while ((needle = va_arg(args, const char *)) != NULL)
        if (!strstr(err, needle))
            fail_msg("message for %s lacks '%s': %s", name, needle, err);
    va_end(args);
}

/* The same for a NUL-terminated text. */
#define EXPECT_REFUSAL(name, text, ...)                                                                      \
    expect_refusal(name, text, strlen(text), __VA_ARGS__, (const char *)NULL)

/* Reads text that must be accepted and returns the trace. */
static srv_trace *expect_accept(const char *name, const char *text, size_t len)
{
    const char *path = write_bytes(name, text, len);
    char err[512];
    srv_trace *t = srv_trace_read(path, err, sizeof err);
    if (!t)
        fail_msg("%s was refused: %s", name, err);
    return t;
}

/* The unit view direction of a camera, in double. */
static void unit_direction(const srv_camera *cam, double out[3])
{
    double length = 0;
    for (int k = 0; k < 3; k++) {
        out[k] = (double)cam->target[k] - (double)cam->position[k];
        length += out[k] * out[k];
    }
    length = sqrt(length);
    assert_true(length > 0);
    for (int k = 0; k < 3; k++)
        out[k] /= length;
}

/* Asserts that a camera is usable: finite, target != position, fov in (0, 180). */
static void assert_valid_camera(const srv_camera *cam)
{
    for (int k = 0; k < 3; k++) {
        assert_true(isfinite(cam->position[k]));
        assert_true(isfinite(cam->target[k]));
        assert_true(isfinite(cam->up[k]));
    }
    assert_true(cam->position[0] != cam->target[0] || cam->position[1] != cam->target[1] ||
                cam->position[2] != cam->target[2]);
    assert_true(cam->fov_deg > 0 && cam->fov_deg < 180);
}

/* True when two cameras are bit-for-bit the same in position, target and fov. */
static bool same_camera(const srv_camera *a, const srv_camera *b)
{
    return memcmp(a->position, b->position, sizeof a->position) == 0 &&
           memcmp(a->target, b->target, sizeof a->target) == 0 && a->fov_deg == b->fov_deg;
}

/* A float in [lo, hi) from the generator. */
static float random_float(uint32_t *state, float lo, float hi)
{
    return lo + (hi - lo) * (float)(fxt_random(state) >> 8) / 16777216.0f;
}

/* ---- traces ------------------------------------------------------------------------------------------ */

/* Writes cameras over a wide range of magnitudes, reads them back and compares. */
static void test_round_trip(void **state)
{
    (void)state;
    enum { CAMERA_COUNT = 500 };
    srv_camera written[CAMERA_COUNT];
    double times[CAMERA_COUNT];
    uint32_t rng = 12345;
    double time = 0.0;
    for (int i = 0; i < CAMERA_COUNT; i++) {
        float scale = powf(10.0f, (float)(i % 9) - 4.0f); /* 1e-4 .. 1e4 */
        float offset = (i % 7 == 0) ? 1.0e4f : 0.0f;      /* far from the origin sometimes */
        if (offset > 0 && scale < 0.1f)
            scale = 0.1f; /* a float at 1e4 resolves 0.001: smaller steps would make target == position */
        srv_camera cam = {.up = {0, 1, 0}};
        for (int k = 0; k < 3; k++) {
            cam.position[k] = offset + scale * random_float(&rng, -10, 10);
            cam.target[k] = cam.position[k] + scale * random_float(&rng, -3, 3);
        }
        cam.target[0] = cam.position[0] + scale; /* never degenerate */
        cam.fov_deg = random_float(&rng, 0.5f, 179.5f);
        time += (i % 5 == 0) ? 0.0 : 1.0 / 30.0 + 1e-7 * i; /* repeated times are allowed */
        written[i] = cam;
        times[i] = time;
    }
    const char *path = fxt_tmp_path("round_trip.trace");
    char err[512];
    srv_trace_writer *w = srv_trace_writer_open(path, NULL, err, sizeof err);
    assert_non_null(w);
    for (int i = 0; i < CAMERA_COUNT; i++)
        if (srv_trace_writer_add(w, times[i], &written[i]) != 0)
            fail_msg("camera %d: %s", i, srv_trace_writer_error(w));
    assert_int_equal(srv_trace_writer_count(w), CAMERA_COUNT);
    assert_int_equal(srv_trace_writer_close(w), 0);

    srv_trace *t = srv_trace_read(path, err, sizeof err);
    if (!t)
        fail_msg("%s", err);
    assert_int_equal(srv_trace_count(t), CAMERA_COUNT);
    for (uint32_t i = 0; i < CAMERA_COUNT; i++) {
        srv_camera cam = srv_trace_camera(t, NULL, i);
        assert_valid_camera(&cam);
        assert_true(memcmp(cam.position, written[i].position, sizeof cam.position) == 0);
        assert_true(cam.fov_deg == written[i].fov_deg);
        assert_true(srv_trace_time(t, i) == times[i]);
        assert_true(cam.up[0] == 0 && cam.up[1] == 1 && cam.up[2] == 0);
        double read_dir[3], written_dir[3];
        unit_direction(&cam, read_dir);
        unit_direction(&written[i], written_dir);
        for (int k = 0; k < 3; k++)
            if (fabs(read_dir[k] - written_dir[k]) > 1e-6)
                fail_msg("camera %u: direction %d %.9g != %.9g", i, k, read_dir[k], written_dir[k]);
        /* The target itself comes back to within a float ulp or two of the direction's length. */
        for (int k = 0; k < 3; k++) {
            double slack = 4e-7 * (fabs((double)written[i].target[k] - written[i].position[k]) +
                                   fabs((double)written[i].position[k]));
            assert_true(fabs((double)cam.target[k] - written[i].target[k]) <= slack);
        }
    }
    srv_trace_free(t);
}

/* The documented example, comments, blank lines, tabs, CRLF line ends, a byte-order mark, UTF-8 in
 * comments, a missing final newline, and a comment of exactly the longest line length are all accepted. */
static void test_accepts_documented_forms(void **state)
{
    (void)state;
    const char *example = "fxcache-trace 1\n"
                          "# recorded by fxcache; up is +Y\n"
                          "0      -4.2 2 3.4   6.7 -1.6 -3.2   60\n"
                          "0.0333 -4.1 2 3.4   6.7 -1.6 -3.2   60\n"
                          "\n"
                          "# a comment between cameras\n"
                          "\t0.0667\t-4.0 2 3.4 6.7 -1.6 -3.2 55.5   \n"
                          "0.0667 -4.0 2 3.4 6.7 -1.6 -3.2 1e1";
    srv_trace *t = expect_accept("example.trace", example, strlen(example));
    assert_int_equal(srv_trace_count(t), 4);
    srv_camera cam = srv_trace_camera(t, NULL, 2);
    assert_true(cam.position[0] == -4.0f && cam.fov_deg == 55.5f);
    assert_true(fabsf(cam.target[0] - 2.7f) < 1e-6f && fabsf(cam.target[2] - 0.2f) < 1e-6f);
    assert_true(srv_trace_camera(t, NULL, 3).fov_deg == 10.0f);
    srv_trace_free(t);

    const char *crlf = "\xef\xbb\xbf"
                       "fxcache-trace 1\r\n# caf\xc3\xa9 \xe2\x98\x95\r\n1 0 0 0 0 0 -1 90\r\n";
    t = expect_accept("crlf.trace", crlf, strlen(crlf));
    assert_int_equal(srv_trace_count(t), 1);
    srv_trace_free(t);

    /* A comment of exactly SRV_TRACE_MAX_LINE bytes, with LF and with CRLF. */
    for (int crlf_end = 0; crlf_end < 2; crlf_end++) {
        const char *header = "fxcache-trace 1\n", *camera = "0 0 0 0 1 0 0 45    \n";
        size_t header_len = strlen(header), camera_len = strlen(camera);
        size_t long_len = header_len + SRV_TRACE_MAX_LINE + (size_t)crlf_end + 1 + camera_len;
        char *long_ok = malloc(long_len);
        assert_non_null(long_ok);
        char *at = long_ok;
        memcpy(at, header, header_len);
        at += header_len;
        memset(at, 'x', SRV_TRACE_MAX_LINE);
        at[0] = '#';
        at += SRV_TRACE_MAX_LINE;
        if (crlf_end)
            *at++ = '\r';
        *at++ = '\n';
        memcpy(at, camera, camera_len);
        assert_true(at + camera_len == long_ok + long_len);
        t = expect_accept("longest.trace", long_ok, long_len);
        assert_int_equal(srv_trace_count(t), 1);
        srv_trace_free(t);
        free(long_ok);
    }
}

/* Every refusal names the file and the line, and says what is wrong. */
static void test_refusals(void **state)
{
    (void)state;
    EXPECT_REFUSAL("walk.trace",
                   "fxcache-trace 1\n# c\n0 0 0 0 1 0 0 60\n1 0 0 0 1 0 0 60\n\n# c\n2 0 0 0 1\n",
                   "walk.trace:7: expected 8 numbers", "got 5");
    EXPECT_REFUSAL("fov0.trace", "fxcache-trace 1\n#\n0 0 0 0 1 0 0 0\n",
                   "fov0.trace:3: fov_deg 0 is outside (0, 180)");
    EXPECT_REFUSAL("fov180.trace", "fxcache-trace 1\n0 0 0 0 1 0 0 180\n",
                   "fov180.trace:2: fov_deg 180 is outside");
    EXPECT_REFUSAL("fovneg.trace", "fxcache-trace 1\n0 0 0 0 1 0 0 -5\n", ":2: fov_deg -5 is outside");
    EXPECT_REFUSAL("time.trace",
                   "fxcache-trace 1\n0 0 0 0 1 0 0 60\n0.5 0 0 0 1 0 0 60\n1 0 0 0 1 0 0 60\n"
                   "1 0 0 0 1 0 0 60\n#\n#\n2.0 0 0 0 1 0 0 60\n1.5 0 0 0 1 0 0 60\n",
                   "time.trace:9: time 1.5 is before the previous line's 2");
    EXPECT_REFUSAL("nan.trace", "fxcache-trace 1\n0 0 nan 0 1 0 0 60\n", "nan.trace:2:", "py", "finite");
    EXPECT_REFUSAL("inf.trace", "fxcache-trace 1\n0 0 0 0 1 0 0 60\n0 0 0 0 -inf 0 0 60\n",
                   "inf.trace:3:", "dx", "finite");
    EXPECT_REFUSAL("infinity.trace", "fxcache-trace 1\nInfinity 0 0 0 1 0 0 60\n", ":2: time", "finite");
    EXPECT_REFUSAL("huge.trace", "fxcache-trace 1\n0 1e999 0 0 1 0 0 60\n", ":2: px '1e999' is not finite");
    EXPECT_REFUSAL("float.trace", "fxcache-trace 1\n0 1e300 0 0 1 0 0 60\n",
                   ":2: px 1e+300 is outside the range");
    EXPECT_REFUSAL("trailing.trace", "fxcache-trace 1\n0 0 0 0 1 0 0 60 abc\n", ":2: expected 8 numbers",
                   "got 9", "trailing text 'abc'");
    EXPECT_REFUSAL("inline_comment.trace", "fxcache-trace 1\n0 0 0 0 1 0 0 60 # look\n",
                   ":2:", "trailing text '# look'");
    EXPECT_REFUSAL("junk_number.trace", "fxcache-trace 1\n0 0 0 0 1.5abc 0 0 60\n",
                   ":2: dx '1.5abc' is not a number");
    EXPECT_REFUSAL("hex.trace", "fxcache-trace 1\n0 0x10 0 0 1 0 0 60\n", ":2: px '0x10' is not a number");
    EXPECT_REFUSAL("comma.trace", "fxcache-trace 1\n0 0,5 0 0 1 0 0 60\n", ":2: px '0,5' is not a number");
    EXPECT_REFUSAL("sign.trace", "fxcache-trace 1\n0 - 0 0 1 0 0 60\n", ":2: px '-' is not a number");
    EXPECT_REFUSAL("zero_dir.trace", "fxcache-trace 1\n0 1 2 3 0 0 0 60\n",
                   ":2: direction (0, 0, 0) is zero");
    /* Positions are kept in double (a scene's local frame holds them more precisely than a float at these
     * world coordinates): 1e-11 is below half a double's spacing at 1e6, 1e-9 is not (test_origin.c). */
    EXPECT_REFUSAL("tiny_dir.trace", "fxcache-trace 1\n0 1e6 0 0 1e-11 0 0 60\n",
                   ":2:", "rounds to the position");
    EXPECT_REFUSAL("no_header.trace", "0 0 0 0 1 0 0 60\n", "no_header.trace:1: missing header",
                   "fxcache-trace 2");
    EXPECT_REFUSAL("wrong_magic.trace", "fxcache-trase 1\n0 0 0 0 1 0 0 60\n", ":1: missing header");
    EXPECT_REFUSAL("empty.trace", "", "empty.trace:1: empty file");
    EXPECT_REFUSAL("no_cameras.trace", "fxcache-trace 1\n# only\n# comments\n\n",
                   "no_cameras.trace:4: no cameras");
    EXPECT_REFUSAL("header_only.trace", "fxcache-trace 1", "header_only.trace:1: no cameras");
    EXPECT_REFUSAL("newer.trace", "fxcache-trace 3\n0 0 0 0 1 0 0 60 0\n",
                   "newer.trace:1: trace format version 3 is newer", "version 2");
    /* Version 2's resolution line: only in version 2, before the cameras, once, two sides in 1..8192. */
    EXPECT_REFUSAL("res_v1.trace", "fxcache-trace 1\nresolution 64 36\n0 0 0 0 1 0 0 60\n",
                   ":2:", "needs format version 2");
    EXPECT_REFUSAL("res_late.trace", "fxcache-trace 2\n0 0 0 0 1 0 0 60\nresolution 64 36\n",
                   ":3:", "before the first camera");
    EXPECT_REFUSAL("res_twice.trace",
                   "fxcache-trace 2\nresolution 64 36\nresolution 64 36\n0 0 0 0 1 0 0 60\n",
                   ":3:", "second 'resolution'");
    EXPECT_REFUSAL("res_zero.trace", "fxcache-trace 2\nresolution 0 36\n0 0 0 0 1 0 0 60\n",
                   ":2:", "width 0 is outside 1..8192");
    EXPECT_REFUSAL("res_big.trace", "fxcache-trace 2\nresolution 64 8193\n0 0 0 0 1 0 0 60\n",
                   ":2:", "height 8193");
    EXPECT_REFUSAL("res_words.trace", "fxcache-trace 2\nresolution 64\n0 0 0 0 1 0 0 60\n",
                   ":2:", "resolution WIDTH HEIGHT");
    EXPECT_REFUSAL("res_text.trace", "fxcache-trace 2\nresolution 64 3x6\n0 0 0 0 1 0 0 60\n",
                   ":2:", "not a whole number");
    EXPECT_REFUSAL("much_newer.trace", "fxcache-trace 99999999999999999999\n", ":1: trace format version",
                   "is newer");
    EXPECT_REFUSAL("version0.trace", "fxcache-trace 0\n", ":1: trace format version 0 is not supported");
    EXPECT_REFUSAL("no_version.trace", "fxcache-trace\n", ":1: malformed header", "no version");
    EXPECT_REFUSAL("bad_version.trace", "fxcache-trace 1.0\n", ":1: malformed header", "not a whole number");
    EXPECT_REFUSAL("header_tail.trace", "fxcache-trace 1 x\n", ":1: malformed header", "trailing text");
    EXPECT_REFUSAL("control.trace", "fxcache-trace 1\n0 0 0 0 1 0 0 60\x01\n", ":2: control character 0x01");
    expect_refusal("nul.trace", "fxcache-trace 1\n0 0 0\0 0 1 0 0 60\n", 34, ":2: NUL byte at column 6",
                   (const char *)NULL);
    EXPECT_REFUSAL("latin1.trace", "fxcache-trace 1\n# caf\xe9\n0 0 0 0 1 0 0 60\n", ":2: invalid UTF-8");
    EXPECT_REFUSAL("overlong.trace", "fxcache-trace 1\n# \xc0\xaf\n", ":2: invalid UTF-8");
    EXPECT_REFUSAL("surrogate.trace", "fxcache-trace 1\n# \xed\xa0\x80\n", ":2: invalid UTF-8");
    EXPECT_REFUSAL("cut_utf8.trace", "fxcache-trace 1\n# \xe2\x98", ":2: invalid UTF-8 (truncated");
    EXPECT_REFUSAL("binary.trace",
                   "\x7f"
                   "ELF\x02\x01\x01\n",
                   "binary.trace:1: control character 0x7f");

    /* A line one byte over the limit. */
    const char *start = "fxcache-trace 1\n0 0 0 0 1 0 0 60    \n";
    size_t start_len = strlen(start), len = start_len + SRV_TRACE_MAX_LINE + 2;
    char *text = malloc(len);
    assert_non_null(text);
    memcpy(text, start, start_len);
    memset(text + start_len, '#', SRV_TRACE_MAX_LINE + 1);
    text[len - 1] = '\n';
    expect_refusal("long.trace", text, len, "long.trace:3: line longer than 4096 bytes", (const char *)NULL);
    free(text);

    char err[512];
    assert_null(srv_trace_read(fxt_tmp_path("does_not_exist.trace"), err, sizeof err));
    assert_non_null(strstr(err, "does_not_exist.trace: cannot open"));
    assert_null(srv_trace_read(FXC_TEST_TMP, err, sizeof err)); /* a directory */
    assert_non_null(strstr(err, FXC_TEST_TMP));
    assert_null(strchr(err, '\n'));
    /* A tiny or absent error buffer is allowed. */
    const char *bad = fxt_write_file("small_err.trace", "nonsense\n");
    assert_null(srv_trace_read(bad, err, 4));
    assert_int_equal(strlen(err), 3);
    assert_null(srv_trace_read(bad, NULL, 0));
}

/* Frame i is camera line i; past the end the last camera holds. */
static void test_frame_past_end(void **state)
{
    (void)state;
    const char *text = "fxcache-trace 1\n0 1 0 0 1 0 0 60\n0.5 2 0 0 1 0 0 60\n1 3 0 0 0 0 1 70\n";
    srv_trace *t = expect_accept("three.trace", text, strlen(text));
    assert_int_equal(srv_trace_count(t), 3);
    for (uint32_t frame = 0; frame < 3; frame++)
        assert_true(srv_trace_camera(t, NULL, frame).position[0] == (float)(frame + 1));
    const uint32_t past[] = {3, 4, 1000, UINT32_MAX};
    for (size_t i = 0; i < sizeof past / sizeof past[0]; i++) {
        srv_camera cam = srv_trace_camera(t, NULL, past[i]);
        assert_true(cam.position[0] == 3.0f && cam.target[2] == 1.0f && cam.fov_deg == 70.0f);
        assert_true(srv_trace_time(t, past[i]) == 1.0);
    }
    srv_trace_free(t);
    srv_trace_free(NULL);
}

/* Directions the format accepts but far below a float's precision at 1 m: (1e-30, 0, 0) moves the target off a
 * position at x = 0, and a subnormal 1e-40 off one at z = 0. Each replays as a usable camera looking exactly
 * along its direction (the closed form: the unit vector of the direction). Before, the float squares of the
 * difference underflowed and srv_camera_setup refused the camera ("position and target coincide"), so
 * `sim --trace` refused a valid trace. */
static void test_tiny_directions(void **state)
{
    (void)state;
    static const struct {
        const char *line;
        float forward[3];
    } cases[] = {
        {"0 0 1.6 3 1e-30 0 0 60\n", {1, 0, 0}},
        {"0 0.5 1.6 0 0 0 -1e-40 60\n", {0, 0, -1}},
        {"0 0 1.6 3 3e-31 0 -4e-31 60\n", {0.6f, 0, -0.8f}},
        {"0 0 1.6 3 0 0 -1 60\n", {0, 0, -1}}, /* an ordinary one, the same way */
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char text[256];
        snprintf(text, sizeof text, "fxcache-trace 1\n%s", cases[i].line);
        srv_trace *t = expect_accept("tiny.trace", text, strlen(text));
        srv_camera cam = srv_trace_camera(t, NULL, 0);
        srv_camera_frame f;
        if (!srv_camera_setup(&cam, 64, 36, &f))
            fail_msg("'%s' is refused as a camera", cases[i].line);
        for (int k = 0; k < 3; k++)
            assert_true(fabsf(f.forward[k] - cases[i].forward[k]) < 1e-6f);
        srv_trace_free(t);
    }
}

/* The writer refuses cameras the reader would refuse, writes nothing for them, and flushes every line. */
/* Version 2: the writer records the resolution, the reader returns it; version 1 files have none; cameras
 * by time take the last line not after the time. */
static void test_version2_resolution_and_time(void **state)
{
    (void)state;
    const char *path = fxt_tmp_path("sized.trace");
    char err[512];
    srv_trace_writer *w = srv_trace_writer_open_sized(path, NULL, 320, 180, err, sizeof err);
    assert_non_null(w);
    srv_camera a = {.position = {0, 1, 0}, .target = {0, 1, -1}, .fov_deg = 60};
    srv_camera b = {.position = {2, 1, 0}, .target = {2, 1, -1}, .fov_deg = 50};
    assert_int_equal(srv_trace_writer_add(w, 0.5, &a), 0);
    assert_int_equal(srv_trace_writer_add(w, 1.5, &b), 0);
    assert_int_equal(srv_trace_writer_close(w), 0);
    FILE *f = fopen(path, "rb");
    char head[32] = "";
    assert_non_null(fgets(head, sizeof head, f));
    fclose(f);
    assert_string_equal(head, "fxcache-trace 2\n");
    srv_trace *t = srv_trace_read(path, err, sizeof err);
    if (!t)
        fail_msg("%s", err);
    uint32_t width = 0, height = 0;
    assert_true(srv_trace_resolution(t, &width, &height));
    assert_int_equal(width, 320);
    assert_int_equal(height, 180);
    assert_true(srv_trace_first_time(t) == 0.5 && srv_trace_last_time(t) == 1.5);
    assert_true(srv_trace_camera_at(t, NULL, 0.0).position[0] == 0.0f); /* before the start: the first */
    assert_true(srv_trace_camera_at(t, NULL, 1.4999).position[0] == 0.0f);
    assert_true(srv_trace_camera_at(t, NULL, 1.5).position[0] == 2.0f);  /* exactly at a line's time */
    assert_true(srv_trace_camera_at(t, NULL, 99.0).position[0] == 2.0f); /* past the end: the last */
    srv_trace_free(t);
    /* Without a resolution the writer keeps version 1, which older readers read. */
    w = srv_trace_writer_open(path, NULL, err, sizeof err);
    assert_int_equal(srv_trace_writer_add(w, 0, &a), 0);
    assert_int_equal(srv_trace_writer_close(w), 0);
    t = srv_trace_read(path, err, sizeof err);
    assert_non_null(t);
    assert_false(srv_trace_resolution(t, &width, &height));
    srv_trace_free(t);
    f = fopen(path, "rb");
    assert_non_null(fgets(head, sizeof head, f));
    fclose(f);
    assert_string_equal(head, "fxcache-trace 1\n");
}

static void test_writer(void **state)
{
    (void)state;
    const char *path = fxt_tmp_path("writer.trace");
    char err[512];
    srv_trace_writer *w = srv_trace_writer_open(path, NULL, err, sizeof err);
    assert_non_null(w);
    srv_camera good = {.position = {1, 2, 3}, .target = {1, 2, 2}, .fov_deg = 45};
    assert_int_equal(srv_trace_writer_add(w, 1.0, &good), 0);
    assert_string_equal(srv_trace_writer_error(w), "");

    /* Flushed: a reader sees the camera before the writer is closed. */
    srv_trace *t = srv_trace_read(path, err, sizeof err);
    if (!t)
        fail_msg("%s", err);
    assert_int_equal(srv_trace_count(t), 1);
    srv_trace_free(t);

    srv_camera same = good;
    memcpy(same.target, same.position, sizeof same.target);
    assert_int_equal(srv_trace_writer_add(w, 2.0, &same), -1);
    assert_non_null(strstr(srv_trace_writer_error(w), "position equals target"));
    srv_camera nan_cam = good;
    nan_cam.position[1] = NAN;
    assert_int_equal(srv_trace_writer_add(w, 2.0, &nan_cam), -1);
    srv_camera bad_fov = good;
    bad_fov.fov_deg = 180;
    assert_int_equal(srv_trace_writer_add(w, 2.0, &bad_fov), -1);
    assert_non_null(strstr(srv_trace_writer_error(w), "fov_deg 180"));
    assert_int_equal(srv_trace_writer_add(w, 0.5, &good), -1);
    assert_non_null(strstr(srv_trace_writer_error(w), "before the previous"));
    assert_int_equal(srv_trace_writer_add(w, INFINITY, &good), -1);
    assert_int_equal(srv_trace_writer_add(w, 1.0, &good), 0); /* equal times are fine */
    assert_int_equal(srv_trace_writer_count(w), 2);
    assert_int_equal(srv_trace_writer_close(w), 0);
    assert_int_equal(srv_trace_writer_close(NULL), 0);

    t = srv_trace_read(path, err, sizeof err);
    if (!t)
        fail_msg("%s", err);
    assert_int_equal(srv_trace_count(t), 2);
    srv_trace_free(t);

    assert_null(srv_trace_writer_open(fxt_tmp_path("no/such/folder/x.trace"), NULL, err, sizeof err));
    assert_non_null(strstr(err, "cannot create"));
}

/* Every prefix of a valid trace, each in its own allocation-sized file, is read or refused cleanly. */
static void test_every_prefix(void **state)
{
    (void)state;
    const char *text = "fxcache-trace 1\n# comment \xc3\xa9\n0 -4.2 2 3.4 6.7 -1.6 -3.2 60\n"
                       "0.033 -4.1 2 3.4 6.7 -1.6 -3.2 60\n";
    size_t len = strlen(text);
    for (size_t prefix = 0; prefix <= len; prefix++) {
        char err[512] = "";
        const char *path = write_bytes("prefix.trace", text, prefix);
        srv_trace *t = srv_trace_read(path, err, sizeof err);
        if (t) {
            assert_true(srv_trace_count(t) >= 1);
            srv_camera cam = srv_trace_camera(t, NULL, srv_trace_count(t) - 1);
            assert_valid_camera(&cam);
            srv_trace_free(t);
        } else {
            assert_true(strlen(err) > 0);
            assert_null(strchr(err, '\n'));
        }
    }
}

/* Random bytes and random mutations of a valid trace: the reader never crashes, and either accepts
 * valid cameras or refuses with one line. Bounded: a fixed number of iterations with a fixed seed. */
static void test_fuzz(void **state)
{
    (void)state;
    const char *valid = "fxcache-trace 1\n# c\n0 -4.2 2 3.4 6.7 -1.6 -3.2 60\n0.5 1 2 3 0 0 1 90\n"
                        "1e0 1e-3 -2e3 3.5 -1 1e-2 0.5 120\n";
    size_t valid_len = strlen(valid);
    static const char alphabet[] = "0123456789 .-+eE\n\t#nanif\r\x00\xff\xc3\xa9x";
    uint32_t rng = 0xdecafbadu;
    unsigned accepted = 0;
    for (int iteration = 0; iteration < 3000; iteration++) {
        char buf[512];
        size_t len;
        int mode = iteration % 3;
        if (mode == 0) { /* raw random bytes, sometimes after a valid header */
            len = fxt_random(&rng) % sizeof buf;
            for (size_t i = 0; i < len; i++)
                buf[i] = (char)fxt_random(&rng);
            if (fxt_random(&rng) & 1 && len > 16)
                memcpy(buf, "fxcache-trace 1\n", 16);
        } else if (mode == 1) { /* text from a number-like alphabet after a header */
            len = 16 + fxt_random(&rng) % (sizeof buf - 16);
            memcpy(buf, "fxcache-trace 1\n", 16);
            for (size_t i = 16; i < len; i++)
                buf[i] = alphabet[fxt_random(&rng) % (sizeof alphabet - 1)];
        } else { /* a valid trace with a few bytes changed, inserted or cut */
            len = valid_len;
            memcpy(buf, valid, len);
            int edits = 1 + (int)(fxt_random(&rng) % 4);
            for (int e = 0; e < edits; e++) {
                size_t at = fxt_random(&rng) % len;
                char c = (fxt_random(&rng) & 1) ? alphabet[fxt_random(&rng) % (sizeof alphabet - 1)]
                                                : (char)fxt_random(&rng);
                switch (fxt_random(&rng) % 3) {
                case 0: buf[at] = c; break;
                case 1:
                    if (len < sizeof buf) {
                        memmove(buf + at + 1, buf + at, len - at);
                        buf[at] = c;
                        len++;
                    }
                    break;
                default:
                    memmove(buf + at, buf + at + 1, len - at - 1);
                    len--;
                    break;
                }
            }
        }
        const char *path = write_bytes("fuzz.trace", buf, len);
        char err[256] = "";
        srv_trace *t = srv_trace_read(path, err, sizeof err);
        if (t) {
            accepted++;
            for (uint32_t i = 0; i <= srv_trace_count(t); i++) {
                srv_camera cam = srv_trace_camera(t, NULL, i);
                assert_valid_camera(&cam);
            }
            srv_trace_free(t);
        } else {
            assert_true(strlen(err) > 0);
            assert_null(strchr(err, '\n'));
        }
    }
    assert_true(accepted > 0); /* some mutations (in comments, of digits) stay valid */
}

/* ---- generators -------------------------------------------------------------------------------------- */

/* The scenes every generator is tried on: the default scene, it without a camera, flat, degenerate and
 * broken bounds, and a small far-away object. */
typedef struct generator_scenes {
    scene *room;
    scene plain[5];
    int plain_count;
} generator_scenes;

/* Builds the test scenes; the plain ones are zeroed structs with only bounds and camera set. */
static void make_scenes(generator_scenes *g)
{
    scene_error error;
    g->room = scene_create_default(NULL, &error);
    if (!g->room)
        fail_msg("default scene: %s", error.msg);
    memset(g->plain, 0, sizeof g->plain);
    scene *no_camera = &g->plain[0];
    memcpy(no_camera->bounds_min, g->room->bounds_min, sizeof no_camera->bounds_min);
    memcpy(no_camera->bounds_max, g->room->bounds_max, sizeof no_camera->bounds_max);
    scene *flat = &g->plain[1];
    const float flat_min[3] = {-10, 0, -10}, flat_max[3] = {10, 0, 10};
    memcpy(flat->bounds_min, flat_min, sizeof flat_min);
    memcpy(flat->bounds_max, flat_max, sizeof flat_max);
    scene *point = &g->plain[2]; /* all bounds zero */
    (void)point;
    scene *broken = &g->plain[3];
    broken->bounds_min[0] = NAN;
    broken->bounds_max[1] = INFINITY;
    scene *far_object = &g->plain[4];
    const float far_min[3] = {1.0e4f, 1.0e4f, 1.0e4f},
                far_max[3] = {1.0e4f + 1e-3f, 1.0e4f + 1e-3f, 1.0e4f + 1e-3f};
    memcpy(far_object->bounds_min, far_min, sizeof far_min);
    memcpy(far_object->bounds_max, far_max, sizeof far_max);
    far_object->has_camera = true;
    const float far_cam[3] = {1.0e4f + 0.01f, 1.0e4f, 1.0e4f}, far_target[3] = {1.0e4f, 1.0e4f, 1.0e4f};
    memcpy(far_object->camera_pos, far_cam, sizeof far_cam);
    memcpy(far_object->camera_target, far_target, sizeof far_target);
    far_object->camera_fov_deg = 20;
    g->plain_count = 5;
}

/* Names parse back to their kinds; unknown names are refused; the list names them all. */
static void test_camgen_names(void **state)
{
    (void)state;
    for (int kind = 0; kind < SRV_CAMGEN_COUNT; kind++) {
        srv_camgen_kind parsed = SRV_CAMGEN_COUNT;
        assert_true(srv_camgen_parse(srv_camgen_name((srv_camgen_kind)kind), &parsed));
        assert_int_equal(parsed, kind);
        assert_non_null(strstr(srv_camgen_list(), srv_camgen_name((srv_camgen_kind)kind)));
        assert_true(strlen(srv_camgen_description((srv_camgen_kind)kind)) > 0);
    }
    srv_camgen_kind untouched = SRV_CAMGEN_WALK;
    assert_false(srv_camgen_parse("Orbit", &untouched));
    assert_false(srv_camgen_parse("", &untouched));
    assert_false(srv_camgen_parse(NULL, &untouched));
    assert_int_equal(untouched, SRV_CAMGEN_WALK);
    assert_string_equal(srv_camgen_name(SRV_CAMGEN_COUNT), "unknown");
}

/* Every generator on every test scene: valid, deterministic, distinct viewers (but `identical`). */
static void test_camgen_valid_deterministic_distinct(void **state)
{
    (void)state;
    generator_scenes g;
    make_scenes(&g);
    const scene *scenes[6] = {g.room};
    for (int i = 0; i < g.plain_count; i++)
        scenes[1 + i] = &g.plain[i];
    const uint32_t frames[] = {0, 1, 2, 7, 119, 240, 599, 1000, 123456, UINT32_MAX};
    const uint32_t viewer_counts[] = {1, 2, 4, 16};
    for (int si = 0; si < 1 + g.plain_count; si++)
        for (int kind = 0; kind < SRV_CAMGEN_COUNT; kind++)
            for (size_t ci = 0; ci < sizeof viewer_counts / sizeof viewer_counts[0]; ci++)
                for (size_t fi = 0; fi < sizeof frames / sizeof frames[0]; fi++)
                    for (uint32_t seed = 0; seed < 3; seed++) {
                        uint32_t count = viewer_counts[ci];
                        srv_camera cams[16];
                        for (uint32_t v = 0; v < count; v++) {
                            cams[v] = srv_camgen_camera((srv_camgen_kind)kind, scenes[si], v, count,
                                                        frames[fi], seed);
                            assert_valid_camera(&cams[v]);
                            srv_camera again = srv_camgen_camera((srv_camgen_kind)kind, scenes[si], v, count,
                                                                 frames[fi], seed);
                            assert_true(same_camera(&cams[v], &again));
                            if (scenes[si]->has_camera)
                                assert_true(cams[v].fov_deg == scenes[si]->camera_fov_deg);
                            else
                                assert_true(cams[v].fov_deg == SRV_CAMGEN_DEFAULT_FOV_DEG);
                        }
                        if (si >= 3)
                            continue; /* point, broken bounds, a millimetre object at 1e4 (below float
                                         resolution): valid cameras are all that is promised */
                        for (uint32_t a = 0; a < count; a++)
                            for (uint32_t b = a + 1; b < count; b++) {
                                bool same = same_camera(&cams[a], &cams[b]);
                                if (kind == SRV_CAMGEN_IDENTICAL ? !same : same)
                                    fail_msg("%s on scene %d: viewers %u and %u of %u at frame %u seed %u %s",
                                             srv_camgen_name((srv_camgen_kind)kind), si, a, b, count,
                                             frames[fi], seed, same ? "coincide" : "differ");
                            }
                    }
    /* static: viewer 0 is exactly the default camera, whatever the seed and frame; nothing moves. */
    srv_camera base = srv_camera_default(g.room);
    for (uint32_t seed = 0; seed < 5; seed++) {
        srv_camera first = srv_camgen_camera(SRV_CAMGEN_STATIC, g.room, 0, 4, seed * 77, seed);
        assert_true(same_camera(&first, &base));
        srv_camera later = srv_camgen_camera(SRV_CAMGEN_STATIC, g.room, 3, 4, 1000, seed);
        srv_camera earlier = srv_camgen_camera(SRV_CAMGEN_STATIC, g.room, 3, 4, 0, seed);
        assert_true(same_camera(&later, &earlier));
        /* The offset is small: a few percent of the viewing distance, view direction unchanged. */
        double base_dir[3], dir[3];
        unit_direction(&base, base_dir);
        unit_direction(&later, dir);
        for (int k = 0; k < 3; k++)
            assert_true(fabs(base_dir[k] - dir[k]) < 1e-5);
    }
    /* room: views overlap heavily: every viewer looks within 20 degrees of the default direction. */
    double base_dir[3];
    unit_direction(&base, base_dir);
    for (uint32_t v = 0; v < 16; v++)
        for (uint32_t frame = 0; frame < 240; frame += 17) {
            srv_camera cam = srv_camgen_camera(SRV_CAMGEN_ROOM, g.room, v, 16, frame, 9);
            double dir[3];
            unit_direction(&cam, dir);
            double cosine = dir[0] * base_dir[0] + dir[1] * base_dir[1] + dir[2] * base_dir[2];
            assert_true(cosine > cos(20.0 * M_PI / 180.0));
        }
    scene_free(g.room);
}

/* walk: every viewer stays inside the default room's bounds, a quarter of its height above the floor,
 * and moves a little each frame. */
static void test_camgen_walk_inside_room(void **state)
{
    (void)state;
    scene_error error;
    scene *room = scene_create_default(NULL, &error);
    assert_non_null(room);
    for (uint32_t viewers = 1; viewers <= 8; viewers *= 2)
        for (uint32_t v = 0; v < viewers; v++)
            for (uint32_t frame = 0; frame <= SRV_CAMGEN_WALK_PERIOD; frame++) {
                srv_camera cam = srv_camgen_camera(SRV_CAMGEN_WALK, room, v, viewers, frame, 0);
                for (int k = 0; k < 3; k++) {
                    assert_true(cam.position[k] > room->bounds_min[k] &&
                                cam.position[k] < room->bounds_max[k]);
                    assert_true(cam.target[k] > room->bounds_min[k] && cam.target[k] < room->bounds_max[k]);
                }
                float eye = room->bounds_min[1] + 0.25f * (room->bounds_max[1] - room->bounds_min[1]);
                assert_true(fabsf(cam.position[1] - eye) < 1e-5f);
                /* Clear of the walls by at least half a metre. */
                assert_true(cam.position[0] > room->bounds_min[0] + 0.5f &&
                            cam.position[0] < room->bounds_max[0] - 0.5f);
                assert_true(cam.position[2] > room->bounds_min[2] + 0.5f &&
                            cam.position[2] < room->bounds_max[2] - 0.5f);
                srv_camera next = srv_camgen_camera(SRV_CAMGEN_WALK, room, v, viewers, frame + 1, 0);
                double step = 0;
                for (int k = 0; k < 3; k++)
                    step += ((double)next.position[k] - cam.position[k]) *
                            ((double)next.position[k] - cam.position[k]);
                step = sqrt(step);
                assert_true(step > 0.005 && step < 0.1); /* metres per frame: a walking pace at 30 fps */
            }
    scene_free(room);
}

/* The angle between two cameras' view directions, degrees. */
static double angle_between(const srv_camera *a, const srv_camera *b)
{
    double da[3], db[3];
    unit_direction(a, da);
    unit_direction(b, db);
    double cosine = da[0] * db[0] + da[1] * db[1] + da[2] * db[2];
    cosine = cosine > 1 ? 1 : (cosine < -1 ? -1 : cosine);
    return acos(cosine) * 180.0 / M_PI;
}

/* turn: in place, 30 degrees per frame, about the vertical axis; orbit: 1.5 degrees per frame around the
 * centre. */
static void test_camgen_rates(void **state)
{
    (void)state;
    scene_error error;
    scene *room = scene_create_default(NULL, &error);
    assert_non_null(room);
    for (uint32_t v = 0; v < 3; v++)
        for (uint32_t frame = 0; frame < 30; frame++) {
            srv_camera a = srv_camgen_camera(SRV_CAMGEN_TURN, room, v, 3, frame, 4);
            srv_camera b = srv_camgen_camera(SRV_CAMGEN_TURN, room, v, 3, frame + 1, 4);
            assert_true(memcmp(a.position, b.position, sizeof a.position) == 0);
            assert_true(fabs(angle_between(&a, &b) - SRV_CAMGEN_TURN_DEGREES_PER_FRAME) < 1e-3);
            /* Counter-clockwise seen from above is not promised, but the rotation is about +Y. */
            assert_true(fabsf((a.target[1] - a.position[1]) - (b.target[1] - b.position[1])) < 1e-6f);
        }
    /* orbit: consecutive positions subtend 360 / period degrees at the centre. */
    double center[3];
    for (int k = 0; k < 3; k++)
        center[k] = 0.5 * ((double)room->bounds_min[k] + room->bounds_max[k]);
    for (uint32_t frame = 0; frame < 10; frame++) {
        srv_camera a = srv_camgen_camera(SRV_CAMGEN_ORBIT, room, 1, 4, frame, 0);
        srv_camera b = srv_camgen_camera(SRV_CAMGEN_ORBIT, room, 1, 4, frame + 1, 0);
        double angle_a = atan2(a.position[2] - center[2], a.position[0] - center[0]);
        double angle_b = atan2(b.position[2] - center[2], b.position[0] - center[0]);
        double delta = fmod((angle_b - angle_a) * 180.0 / M_PI + 720.0, 360.0);
        assert_true(fabs(delta - 360.0 / SRV_CAMGEN_ORBIT_PERIOD) < 1e-3);
        /* Interior scene: the orbit stays inside the room. */
        for (int k = 0; k < 3; k++)
            assert_true(a.position[k] > room->bounds_min[k] && a.position[k] < room->bounds_max[k]);
    }
    scene_free(room);
}

/* Generated cameras survive a trace round trip: what the sim records, it can replay. */
static void test_camgen_trace_round_trip(void **state)
{
    (void)state;
    scene_error error;
    scene *room = scene_create_default(NULL, &error);
    assert_non_null(room);
    const char *path = fxt_tmp_path("generated.trace");
    char err[512];
    srv_trace_writer *w = srv_trace_writer_open(path, NULL, err, sizeof err);
    assert_non_null(w);
    for (uint32_t frame = 0; frame < 100; frame++) {
        srv_camera cam =
            srv_camgen_camera((srv_camgen_kind)(frame % SRV_CAMGEN_COUNT), room, frame % 3, 3, frame, 1);
        assert_int_equal(srv_trace_writer_add(w, frame / 30.0, &cam), 0);
    }
    assert_int_equal(srv_trace_writer_close(w), 0);
    srv_trace *t = srv_trace_read(path, err, sizeof err);
    if (!t)
        fail_msg("%s", err);
    for (uint32_t frame = 0; frame < 100; frame++) {
        srv_camera cam =
            srv_camgen_camera((srv_camgen_kind)(frame % SRV_CAMGEN_COUNT), room, frame % 3, 3, frame, 1);
        srv_camera back = srv_trace_camera(t, NULL, frame);
        assert_true(memcmp(cam.position, back.position, sizeof cam.position) == 0);
        assert_true(angle_between(&cam, &back) < 1e-3);
        assert_true(srv_trace_time(t, frame) == frame / 30.0);
    }
    srv_trace_free(t);
    scene_free(room);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip),
        cmocka_unit_test(test_accepts_documented_forms),
        cmocka_unit_test(test_refusals),
        cmocka_unit_test(test_version2_resolution_and_time),
        cmocka_unit_test(test_frame_past_end),
        cmocka_unit_test(test_tiny_directions),
        cmocka_unit_test(test_writer),
        cmocka_unit_test(test_every_prefix),
        cmocka_unit_test(test_fuzz),
        cmocka_unit_test(test_camgen_names),
        cmocka_unit_test(test_camgen_valid_deterministic_distinct),
        cmocka_unit_test(test_camgen_walk_inside_room),
        cmocka_unit_test(test_camgen_rates),
        cmocka_unit_test(test_camgen_trace_round_trip),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
