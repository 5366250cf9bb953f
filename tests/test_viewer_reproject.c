/* fxcache-viewer's display clock and render cache (--reproject) against a real `fxcache serve` on the
 * embedded default scene, both programs started as users start them:
 *   - a static camera: every display frame after the first frames equals, pixel for pixel, the last frame the
 *     viewer received before it (the frame's PNG from --out), with and without --reproject. With --reproject
 *     the frame went through depth (binary16 on the wire), its 3-D points and the render cache's projection
 *     back to the same camera; the tolerance is exact colours, as tests/test_rcache.c proves for the cache
 *     alone (depth quantization moves a point along its own ray only, so it lands on its own pixel). These
 *     runs send no sample requests (--sample-budget 0): an answer rendered later may differ from the frame;
 *   - a camera turning in place with 50 ms of simulated latency each way, sample requests on: the server
 *     answers them, and the render cache's displayed frames have at most the empty fraction the closed form
 *     gives for the turn since the newest frame's camera (a pure turn has no parallax: only the strip no
 * frame saw yet can be empty; the samples fill some of it);
 *   - --stats carries the display's and the render cache's figures, consistent with the display's CSV.
 *   - sample requests against a fake server (tests/peer_rc_server.js) that answers them and sends no frames.
 * The program is built only with the wire format's implementation in the tree; until then every test skips.
 */
#include "image.h"
#include "fxt_serve.h"
#include "test_util.h"

#include <fcntl.h>
#include <glob.h>
#include <jansson.h>
#include <math.h>
#include <signal.h>
#include <stdbool.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

#ifdef FXC_VIEWER_BIN
/* The display PNGs a --display-out run has written to dir so far. */
static size_t display_pngs(const char *dir)
{
    char pattern[1024];
    snprintf(pattern, sizeof pattern, "%s/display_*.png", dir);
    glob_t found;
    size_t n = glob(pattern, 0, NULL, &found) == 0 ? found.gl_pathc : 0;
    globfree(&found);
    return n;
}

/* Runs fxcache-viewer with args (NULL-terminated) to its end (at most 300 s); with term_dir, sends SIGTERM
 * once term_pngs display PNGs are in it (or after 120 s), so that a slow start on a loaded machine (the
 * sanitizer build) still gets its frames before the signal. Returns its exit status. */
static int run_viewer_for(const char *const *args, const char *name, const char *term_dir, size_t term_pngs)
{
    const char *argv[48] = {FXC_VIEWER_BIN};
    int n = 1;
    for (; args[n - 1]; n++) {
        assert_true(n < 47);
        argv[n] = args[n - 1];
    }
    argv[n] = NULL;
    char err[512];
    snprintf(err, sizeof err, "%s.viewer.err", fxt_tmp_path(name));
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 2, err, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_t pid;
    assert_int_equal(posix_spawn(&pid, FXC_VIEWER_BIN, &fa, NULL, (char *const *)argv, environ), 0);
    posix_spawn_file_actions_destroy(&fa);
    bool signalled = false;
    for (double t0 = fxt_now_s(); fxt_now_s() - t0 < 300;) {
        if (term_dir && !signalled && (display_pngs(term_dir) >= term_pngs || fxt_now_s() - t0 > 120)) {
            kill(pid, SIGTERM);
            signalled = true;
        }
        int status;
        if (waitpid(pid, &status, WNOHANG) == pid) {
            int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
            if (code != 0) {
                FILE *f = fopen(err, "r");
                char line[512];
                while (f && fgets(line, sizeof line, f))
                    print_message("fxcache-viewer: %s", line);
                if (f)
                    fclose(f);
            }
            return code;
        }
        usleep(20000);
    }
    kill(pid, SIGKILL);
    waitpid(pid, NULL, 0);
    fail_msg("fxcache-viewer did not end within 300 s");
    return -1;
}

static int run_viewer(const char *const *args, const char *name)
{
    return run_viewer_for(args, name, NULL, 0);
}

/* One line of the display's CSV (--display-out). */
typedef struct display_row {
    long index, frame;
    double time_s, frame_camera_s, empty_fraction;
    long kinds[4]; /* empty, point, interpolated, prefiltered */
} display_row;

/* Reads the one DIR/display_NAME.csv of a run (NAME, the server's name for the viewer, into name). Returns
 * the rows (malloc'd). */
static display_row *read_display_csv(const char *dir, size_t *count, char name[64])
{
    char path[1024], line[512], pattern[1024];
    snprintf(pattern, sizeof pattern, "%s/display_*.csv", dir);
    glob_t found;
    if (glob(pattern, 0, NULL, &found) != 0 || found.gl_pathc != 1)
        fail_msg("%s: expected one file", pattern);
    snprintf(path, sizeof path, "%s", found.gl_pathv[0]);
    globfree(&found);
    const char *base = strrchr(path, '/') + 1 + strlen("display_");
    snprintf(name, 64, "%.*s", (int)(strlen(base) - strlen(".csv")), base);
    FILE *f = fopen(path, "r");
    if (!f)
        fail_msg("%s: cannot open", path);
    assert_non_null(fgets(line, sizeof line, f));
    assert_non_null(strstr(
        line, "display,time_s,frame,frame_camera_s,empty_fraction,empty,point,interpolated,prefiltered"));
    size_t n = 0, cap = 64;
    display_row *rows = malloc(cap * sizeof *rows);
    assert_non_null(rows);
    while (fgets(line, sizeof line, f)) {
        if (n == cap) {
            cap *= 2;
            rows = realloc(rows, cap * sizeof *rows);
            assert_non_null(rows);
        }
        display_row *r = &rows[n];
        if (sscanf(line, "%ld,%lf,%ld,%lf,%lf,%ld,%ld,%ld,%ld", &r->index, &r->time_s, &r->frame,
                   &r->frame_camera_s, &r->empty_fraction, &r->kinds[0], &r->kinds[1], &r->kinds[2],
                   &r->kinds[3]) != 9)
            fail_msg("%s: line %zu does not read: %s", path, n + 2, line);
        n++;
    }
    fclose(f);
    *count = n;
    return rows;
}

/* Pixels that differ between two images of the same size (the test fails when a file does not read). */
static long pixels_differing(const char *a, const char *b, uint32_t *pixels)
{
    uint32_t wa, ha, wb, hb;
    float *ia = NULL, *ib = NULL;
    char msg[512];
    if (scene_image_read_rgb(a, &wa, &ha, &ia, msg, sizeof msg) != 0)
        fail_msg("%s", msg);
    if (scene_image_read_rgb(b, &wb, &hb, &ib, msg, sizeof msg) != 0)
        fail_msg("%s", msg);
    assert_true(wa == wb && ha == hb);
    long differ = 0;
    for (size_t p = 0; p < (size_t)wa * ha; p++)
        differ += ia[3 * p] != ib[3 * p] || ia[3 * p + 1] != ib[3 * p + 1] || ia[3 * p + 2] != ib[3 * p + 2];
    free(ia);
    free(ib);
    *pixels = wa * ha;
    return differ;
}

static void remove_tree(const char *dir)
{
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    assert_int_equal(system(cmd), 0);
}
#endif

/* A static camera: display frames equal the last frame received, with and without the render cache. */
static void test_static_camera(void **state)
{
    (void)state;
#ifndef FXC_VIEWER_BIN
    print_message("SKIP: fxcache-viewer is not built\n");
    skip();
#else
    fxt_server server;
    fxt_server_start(&server, "static", (const char *const[]){"--fps", "30", NULL});
    int port = server.port;
    char url[64];
    snprintf(url, sizeof url, "ws://127.0.0.1:%d", port);
    for (int reproject = 0; reproject < 2; reproject++) {
        char out[512], display[512], stats[512];
        snprintf(out, sizeof out, "%s_%d", fxt_tmp_path("static_frames"), reproject);
        snprintf(display, sizeof display, "%s_%d", fxt_tmp_path("static_display"), reproject);
        snprintf(stats, sizeof stats, "%s_%d.json", fxt_tmp_path("static_stats"), reproject);
        remove_tree(out);
        remove_tree(display);
        const char *args[] = {
            "--connect", url, "--camera", "static", "--res", "96x54", "--frames", "45", "--out", out,
            "--quiet", "--display-out", display, "--stats", stats, "--timeout", "120",
            /* the render cache, without sample requests; the list ends here without --reproject */
            reproject ? "--reproject" : NULL, "--sample-budget", "0", NULL};
        assert_int_equal(run_viewer(args, "static"), 0);
        size_t count;
        char name[64];
        display_row *rows = read_display_csv(display, &count, name);
        /* Display frames from the 10th frame received on (the server's caches fill during the first ones; the
         * comparison holds for every frame, the wait only lets frames differ from one another). */
        int compared = 0;
        long differ = 0;
        uint32_t pixels = 0;
        for (size_t i = 0; i < count; i++) {
            /* The first display frame of each frame received (a slow server, as under the sanitizer, shows
             * one frame on many display frames: they are the same image). */
            if (rows[i].frame < 10 || (i > 0 && rows[i - 1].frame == rows[i].frame))
                continue;
            char shown[1024], received[1024];
            snprintf(shown, sizeof shown, "%s/display_%05ld_%s.png", display, rows[i].index, name);
            snprintf(received, sizeof received, "%s/frame_%04ld_%s.png", out, rows[i].frame, name);
            differ += pixels_differing(shown, received, &pixels);
            compared++;
            assert_true(rows[i].empty_fraction == 0);
            if (reproject) /* every pixel shows a point of the frame, none filtered */
                assert_int_equal(rows[i].kinds[1], (long)pixels);
        }
        print_message("%s: %d display frames compared with the frame received before them: %ld of %ld pixels "
                      "differ\n",
                      reproject ? "--reproject" : "last frame", compared, differ, (long)compared * pixels);
        assert_true(compared >= 20);
        assert_int_equal(differ, 0);
        /* Display times are k / 30 s. */
        for (size_t i = 0; i < count; i++)
            assert_true(fabs(rows[i].time_s - (double)rows[i].index / 30.0) < 1e-9);
        free(rows);

        json_error_t error;
        json_t *root = json_load_file(stats, 0, &error);
        if (!root)
            fail_msg("%s:%d: %s", stats, error.line, error.text);
        json_t *v = json_array_get(json_object_get(root, "viewers"), 0);
        json_t *d = json_object_get(v, "display"), *rc = json_object_get(v, "render_cache");
        assert_true(json_integer_value(json_object_get(d, "frames")) +
                        json_integer_value(json_object_get(d, "skipped")) >=
                    (json_int_t)count);
        if (reproject) {
            assert_true(json_is_object(rc));
            /* Every frame shown went into the cache; none was refused. */
            assert_int_equal(json_integer_value(json_object_get(rc, "frames_inserted")),
                             json_integer_value(json_object_get(v, "frames")));
            assert_int_equal(json_integer_value(json_object_get(rc, "insert_errors")), 0);
            assert_true(json_integer_value(json_object_get(rc, "points")) > 0);
            assert_true(json_integer_value(json_object_get(rc, "points")) <= 96 * 54);
        } else {
            assert_true(json_is_null(rc));
        }
        json_decref(root);
    }
    assert_int_equal(fxt_server_stop(&server), 0);
#endif
}

/* Pixels of a pinhole image (horizontal field of view hfov) that a frame of the same camera turned by lag
 * radians no longer covers: the columns at angles from hfov / 2 - lag to hfov / 2, as a fraction. */
static double uncovered_fraction(double hfov, double lag)
{
    double edge = tan(hfov / 2);
    return lag >= hfov / 2 ? 0.5 + (tan(lag - hfov / 2) / edge) / 2
                           : (edge - tan(hfov / 2 - lag)) / (2 * edge);
}

/* A camera turning in place at 20 degrees a second with 50 ms of latency each way, the session at half speed
 * (--time-scale 2, the server at 15 frames a second: times in the display's CSV are the session's): the
 * render cache shows every frame's points turned to the display's camera, so only the strip the newest frame
 * never saw is empty. A pure turn has no parallax, so each display frame's empty fraction is bounded by the
 * closed form of that strip for its lag (the turn from the newest frame's camera, its time from the CSV, to
 * the display's camera), plus one column for the pixel grid. The filters fill up to three pixels into the
 * strip, so the bound is not tight. */
static void test_turning_camera(void **state)
{
    (void)state;
#ifndef FXC_VIEWER_BIN
    print_message("SKIP: fxcache-viewer is not built\n");
    skip();
#else
    /* At (0, 1.6, 0), the middle of the default scene's room, 1/30 s a line for 6 s. */
    const double rate = 20 * 3.14159265358979323846 / 180;
    char *text = malloc(65536);
    assert_non_null(text);
    size_t at = (size_t)snprintf(text, 65536, "fxcache-trace 1\n");
    for (int i = 0; i <= 180; i++) {
        double t = i / 30.0, yaw = rate * t;
        at +=
            (size_t)snprintf(text + at, 65536 - at, "%.9f 0 1.6 0 %.9f 0 %.9f 60\n", t, sin(yaw), -cos(yaw));
    }
    char trace[512];
    snprintf(trace, sizeof trace, "%s", fxt_write_file("turn.trace", text));
    free(text);
    fxt_server server;
    fxt_server_start(&server, "turning",
                     (const char *const[]){"--fps", "15", NULL}); /* 30 a second of the session's time */
    int port = server.port;
    char url[64], display[512], stats[512];
    snprintf(url, sizeof url, "ws://127.0.0.1:%d", port);
    snprintf(display, sizeof display, "%s", fxt_tmp_path("turning_display"));
    snprintf(stats, sizeof stats, "%s", fxt_tmp_path("turning_stats.json"));
    remove_tree(display);
    const char *args[] = {
        "--connect", url,       "--trace",      trace,     "--res", "96x54",         "--latency",
        "50",        "--quiet", "--reproject",  "--stats", stats,   "--display-out", display,
        "--timeout", "120",     "--time-scale", "2",       NULL};
    assert_int_equal(run_viewer(args, "turning"), 0);
    assert_int_equal(fxt_server_stop(&server), 0);
    json_error_t error;
    json_t *root = json_load_file(stats, 0, &error);
    if (!root)
        fail_msg("%s:%d: %s", stats, error.line, error.text);
    json_t *v = json_array_get(json_object_get(root, "viewers"), 0);
    json_t *rc = json_object_get(v, "render_cache");
    /* The prediction's round trip: at least both delays. */
    assert_true(json_real_value(json_object_get(rc, "rtt_ms")) >= 100);
    /* Sample requests went out and the server answered some (it renders the latest request a frame), and
     * every answer was inserted. */
    json_int_t sent = json_integer_value(json_object_get(rc, "requests_sent"));
    json_int_t answered = json_integer_value(json_object_get(rc, "requests_answered"));
    print_message("sample requests: %lld sent, %lld answered with %lld samples\n", (long long)sent,
                  (long long)answered,
                  (long long)json_integer_value(json_object_get(rc, "samples_received")));
    assert_true(sent >= 30 && answered >= 5 && answered <= sent);
    assert_true(json_integer_value(json_object_get(rc, "samples_received")) >= answered);
    assert_int_equal(json_integer_value(json_object_get(rc, "insert_errors")), 0);
    json_decref(root);
    double hfov = 2 * atan(tan(30 * 3.14159265358979323846 / 180) * 96 / 54);
    size_t count;
    char name[64];
    display_row *rows = read_display_csv(display, &count, name);
    /* From the 10th frame received on (the first frames come while the server's caches fill). */
    double empty = 0, worst_lag = 0, bound_sum = 0;
    int frames = 0;
    for (size_t i = 0; i < count; i++) {
        if (rows[i].frame < 10)
            continue;
        long total = rows[i].kinds[0] + rows[i].kinds[1] + rows[i].kinds[2] + rows[i].kinds[3];
        assert_int_equal(total, 96 * 54);
        assert_true(fabs(rows[i].empty_fraction - (double)rows[i].kinds[0] / total) < 1e-6);
        double lag = rows[i].time_s - rows[i].frame_camera_s;
        assert_true(lag >= -1e-9); /* a frame's camera is never ahead of the display */
        double bound = uncovered_fraction(hfov, rate * lag) + 1.0 / 96;
        if (rows[i].empty_fraction > bound)
            fail_msg("display frame %ld: %.4f of the pixels empty, more than %.4f for a lag of %.0f ms",
                     rows[i].index, rows[i].empty_fraction, bound, lag * 1000);
        empty += rows[i].empty_fraction;
        bound_sum += bound;
        worst_lag = fmax(worst_lag, lag);
        frames++;
    }
    free(rows);
    print_message(
        "turning 20 deg/s, 50 ms each way: %d display frames, empty pixels %.4f on average (the strips "
        "of their lags %.4f; lag at most %.0f ms)\n",
        frames, frames ? empty / frames : 0, frames ? bound_sum / frames : 0, worst_lag * 1000);
    assert_true(frames >= 60);
    /* Not vacuous: the turn uncovers a strip the received frames alone do not cover (the bound above has
     * teeth). How much of it stays empty depends on how fast the answers to the sample requests come back:
     * on an idle machine they fill all of it (measured 0.0000 empty against a strip of 0.065), on a loaded
     * one about a quarter stays empty (0.016 against 0.083). */
    assert_true(bound_sum / frames > 0.02);
#endif
}

/* Sample requests against a fake server (tests/peer_rc_server.js, Node's ws, the wire format written by
 * hand): it sends no frames and answers every sample-request at once with each pixel red at 4 m. A static
 * camera fills its display from the answers alone: every request arrives well formed with the viewer's
 * camera, both sides count the same requests, every answer but those in flight at the end is inserted, and
 * the last display frame is all the answers' red, no pixel empty. */
static void test_sample_requests(void **state)
{
    (void)state;
#ifndef FXC_VIEWER_BIN
    print_message("SKIP: fxcache-viewer is not built\n");
    skip();
#else
    char report[512], out[512], display[512], stats[512];
    snprintf(report, sizeof report, "%s", fxt_tmp_path("fake_report.json"));
    snprintf(out, sizeof out, "%s", fxt_tmp_path("fake.out"));
    snprintf(display, sizeof display, "%s", fxt_tmp_path("fake_display"));
    snprintf(stats, sizeof stats, "%s", fxt_tmp_path("fake_stats.json"));
    remove_tree(display);
    remove(report);
    char quoted[600];
    snprintf(quoted, sizeof quoted, "'%s'", report);
    pid_t fake;
    int port = fxt_node_peer_start("peer_rc_server.js", quoted, out, &fake);
    if (!port) {
        skip(); /* fxt_node_peer_start said why */
    }
    char url[64];
    snprintf(url, sizeof url, "ws://127.0.0.1:%d", port);
    const char *args[] = {
        "--connect", url,       "--camera",    "static",        "--res", "64x36",   "--latency",
        "20",        "--quiet", "--reproject", "--display-out", display, "--stats", stats,
        "--timeout", "60",      NULL};
    assert_int_equal(run_viewer_for(args, "fake", display, 60),
                     0); /* about 2 s at 30 display frames a second */
    int status = 0;
    for (double t0 = fxt_now_s(); fxt_now_s() - t0 < 30;) {
        if (waitpid(fake, &status, WNOHANG) == fake)
            break;
        usleep(20000);
    }
    json_error_t error;
    json_t *fake_report = json_load_file(report, 0, &error);
    if (!fake_report)
        fail_msg("%s: %s (the fake server did not finish: see %s)", report, error.text, out);
    json_t *errors = json_object_get(fake_report, "errors");
    for (size_t i = 0; i < json_array_size(errors); i++)
        print_message("fake server: %s\n", json_string_value(json_array_get(errors, i)));
    assert_int_equal(json_array_size(errors), 0);
    json_int_t requests = json_integer_value(json_object_get(fake_report, "requests"));
    json_int_t pixels = json_integer_value(json_object_get(fake_report, "pixels"));
    /* Every request is for the static camera (the welcome's): the current one, or the predicted one, which
     * for a camera at rest is the same. */
    json_t *cameras = json_object_get(fake_report, "cameras");
    const double expected[7] = {0, 1.6, 3, 0, 0, -1, 60};
    for (size_t i = 0; i < json_array_size(cameras); i++)
        for (int k = 0; k < 7; k++)
            assert_true(fabs(json_number_value(json_array_get(json_array_get(cameras, i), k)) - expected[k]) <
                        1e-6);

    json_t *root = json_load_file(stats, 0, &error);
    if (!root)
        fail_msg("%s:%d: %s", stats, error.line, error.text);
    json_t *rc = json_object_get(json_array_get(json_object_get(root, "viewers"), 0), "render_cache");
    json_int_t sent = json_integer_value(json_object_get(rc, "requests_sent"));
    json_int_t answered = json_integer_value(json_object_get(rc, "requests_answered"));
    json_int_t received = json_integer_value(json_object_get(rc, "samples_received"));
    print_message(
        "fake server: %lld requests of %lld pixels; the viewer sent %lld, inserted %lld answers of %lld "
        "samples\n",
        (long long)requests, (long long)pixels, (long long)sent, (long long)answered, (long long)received);
    assert_true(requests >= 20);
    assert_int_equal(sent, requests);
    assert_int_equal(json_integer_value(json_object_get(rc, "request_pixels")), pixels);
    assert_true(answered <= requests && answered >= requests - 3);  /* answers in flight when it stopped */
    assert_true(received <= pixels && received >= pixels - 3 * 72); /* 72: the budget, 64 * 36 / 32 */
    assert_int_equal(json_integer_value(json_object_get(rc, "insert_errors")), 0);
    json_decref(root);
    json_decref(fake_report);

    size_t count;
    char name[64];
    display_row *rows = read_display_csv(display, &count, name);
    assert_string_equal(name, "fake_00");
    assert_true(count > 10);
    display_row last = rows[count - 1];
    free(rows);
    assert_true(last.empty_fraction == 0);
    assert_true(last.kinds[1] > 64 * 36 / 2); /* most pixels show a sample of their own */
    char path[1024], msg[256];
    snprintf(path, sizeof path, "%s/display_%05ld_fake_00.png", display, last.index);
    uint32_t w, h;
    float *rgb = NULL;
    if (scene_image_read_rgb(path, &w, &h, &rgb, msg, sizeof msg) != 0)
        fail_msg("%s", msg);
    for (size_t p = 0; p < (size_t)w * h; p++)
        assert_true(rgb[3 * p] == rgb[0] && rgb[3 * p + 1] == rgb[1] && rgb[3 * p + 2] == rgb[2]);
    assert_true(rgb[0] > 20 * rgb[1] && rgb[1] == rgb[2]); /* sRGB (200, 30, 30), read as linear */
    free(rgb);
#endif
}

int main(void)
{
    signal(SIGPIPE, SIG_IGN);
    mkdir(FXC_TEST_TMP, 0755);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_static_camera),
        cmocka_unit_test(test_turning_camera),
        cmocka_unit_test(test_sample_requests),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
