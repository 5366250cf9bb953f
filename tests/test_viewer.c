/* White-box tests of the viewer client's parts that need no network (viewer_client/): the latency figures
 * (median and nearest-rank 95th percentile against values worked out by hand, totals over viewers), the
 * --stats JSON read back with jansson, the camera generators (orbit against its closed form: viewer 0 starts
 * at the default camera, every camera on the circle at the camera's height looking at the centre, viewers
 * spread evenly, one revolution per 240 cameras; static is the default camera), the trace schedule, and the
 * PNG writer against the server's (scene/image_oiio.cpp): the same pixels give the same bytes. The program
 * itself is tested through its entry point in tests/test_viewer_cli.c. */
#include "test_util.h"

#include "image.h"
#include "proto_trace.h"
#include "view_camera.h"
#include "view_image.h"
#include "view_stats.h"

#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define PI 3.14159265358979323846

/* ---- figures ------------------------------------------------------------------------------------------ */

static void test_median_and_percentile(void **state)
{
    (void)state;
    /* 1..20: median (10 + 11) / 2; the 95th percentile's rank is ceil(0.95 * 20) = 19. */
    double twenty[20];
    for (int i = 0; i < 20; i++)
        twenty[i] = 20 - i; /* given unsorted */
    view_sort(twenty, 20);
    for (int i = 0; i < 20; i++)
        assert_true(twenty[i] == i + 1);
    assert_true(view_median(twenty, 20) == 10.5);
    assert_true(view_percentile(twenty, 20, 95) == 19);
    assert_true(view_percentile(twenty, 20, 100) == 20);
    assert_true(view_percentile(twenty, 20, 5) == 1);
    /* Odd counts: the middle value; 95 % of 7 is rank ceil(6.65) = 7. */
    double seven[7] = {1, 2, 3, 100, 101, 102, 1000};
    assert_true(view_median(seven, 7) == 100);
    assert_true(view_percentile(seven, 7, 95) == 1000);
    assert_true(view_percentile(seven, 7, 50) == 100); /* rank ceil(3.5) = 4 */
    /* One value, and none. */
    double one = 42;
    assert_true(view_median(&one, 1) == 42 && view_percentile(&one, 1, 95) == 42);
    assert_true(view_median(NULL, 0) == 0 && view_percentile(NULL, 0, 95) == 0);
    /* 100 values: rank 95 exactly (0.95 * 100 is not whole in binary: the tolerance keeps it 95). */
    double hundred[100];
    for (int i = 0; i < 100; i++)
        hundred[i] = i + 1;
    assert_true(view_percentile(hundred, 100, 95) == 95);
}

/* Two viewers' figures, and their total: frames and bytes add, fps add, latency over all samples. */
static void fill_two_viewers(view_viewer_stats viewers[2])
{
    memset(viewers, 0, 2 * sizeof viewers[0]);
    viewers[0].index = 0;
    snprintf(viewers[0].name, sizeof viewers[0].name, "viewer_01");
    viewers[0].frames = 30;
    viewers[0].seconds = 1.5;
    viewers[0].bytes_received = 31000;
    viewers[0].frame_bytes = 30000;
    viewers[0].decode_errors = 2;
    for (int i = 1; i <= 10; i++)
        assert_true(view_latency_add(&viewers[0].latency, 10.0 * i)); /* 10..100 */
    viewers[1].index = 1;
    snprintf(viewers[1].name, sizeof viewers[1].name, "a \"quoted\"\\name");
    viewers[1].failed = true;
    snprintf(viewers[1].error, sizeof viewers[1].error, "server refused: \x01 bad\ttoken \xe9");
    viewers[1].frames = 10;
    viewers[1].seconds = 2;
    viewers[1].bytes_received = 5000;
    viewers[1].frame_bytes = 4000;
    for (int i = 0; i < 2000; i++) /* past the first allocation: the list grows */
        assert_true(view_latency_add(&viewers[1].latency, 1000));
}

static void test_figures(void **state)
{
    (void)state;
    view_viewer_stats viewers[2];
    fill_two_viewers(viewers);
    view_figures one, total;
    assert_true(view_figures_of(&viewers[0], 1, &one));
    assert_int_equal(one.frames, 30);
    assert_true(one.fps == 20.0);
    assert_true(one.latency_median == 55.0); /* (50 + 60) / 2 */
    assert_true(one.latency_p95 == 100.0);   /* rank ceil(9.5) = 10 */
    assert_true(one.bytes_per_frame == 1000.0);
    assert_int_equal(one.latency_samples, 10);
    assert_true(view_figures_of(viewers, 2, &total));
    assert_int_equal(total.frames, 40);
    assert_true(total.fps == 25.0); /* 20 + 5 */
    assert_int_equal(total.bytes_received, 36000);
    assert_true(total.bytes_per_frame == 850.0); /* 34000 / 40 */
    assert_int_equal(total.decode_errors, 2);
    assert_int_equal(total.latency_samples, 2010);
    assert_true(total.latency_median == 1000 && total.latency_p95 == 1000);

    /* The summary names each viewer, its figures, and the failure. */
    const char *path = fxt_tmp_path("summary.txt");
    FILE *f = fopen(path, "w+");
    assert_non_null(f);
    view_stats_print_summary(f, viewers, 2, "ws://127.0.0.1:7681", 3.0);
    rewind(f);
    char text[4096] = "";
    size_t n = fread(text, 1, sizeof text - 1, f);
    text[n] = 0;
    fclose(f);
    assert_non_null(strstr(text, "2 viewers on ws://127.0.0.1:7681 for 3.0 s, 1 failed"));
    assert_non_null(
        strstr(text, "viewer 0 (viewer_01): 30 frames, 20.0 fps, latency median 55.0 ms, 95th percentile "
                     "100.0 ms, 0.03 MB received, 1000 bytes a frame, 2 frames did not decode"));
    assert_non_null(strstr(text, "failed: server refused"));
    assert_non_null(strstr(text, "total: 40 frames, 25.0 fps"));
    for (int i = 0; i < 2; i++)
        view_latency_free(&viewers[i].latency);
}

/* The --stats JSON, read back with jansson: valid JSON whatever bytes a name or reason holds, and the
 * figures. */
static void test_stats_json(void **state)
{
    (void)state;
    view_viewer_stats viewers[2];
    fill_two_viewers(viewers);
    char path[1024], err[256];
    snprintf(path, sizeof path, "%s", fxt_tmp_path("stats.json"));
    assert_int_equal(view_stats_write_json(path, viewers, 2, "ws://[::1]:7681", 3.0, err, sizeof err), 0);
    json_error_t error;
    json_t *root = json_load_file(path, 0, &error);
    if (!root)
        fail_msg("%s:%d: %s", path, error.line, error.text);
    json_t *list = json_object_get(root, "viewers");
    assert_int_equal(json_array_size(list), 2);
    json_t *v0 = json_array_get(list, 0), *v1 = json_array_get(list, 1),
           *total = json_object_get(root, "total");
    assert_string_equal(json_string_value(json_object_get(root, "server")), "ws://[::1]:7681");
    assert_string_equal(json_string_value(json_object_get(v0, "name")), "viewer_01");
    assert_true(json_is_null(json_object_get(v0, "error")));
    assert_int_equal(json_integer_value(json_object_get(v0, "frames")), 30);
    assert_true(json_real_value(json_object_get(v0, "fps")) == 20.0);
    json_t *latency = json_object_get(v0, "latency_ms");
    assert_true(json_real_value(json_object_get(latency, "median")) == 55.0);
    assert_true(json_real_value(json_object_get(latency, "p95")) == 100.0);
    assert_int_equal(json_integer_value(json_object_get(v0, "decode_errors")), 2);
    assert_true(json_real_value(json_object_get(v0, "bytes_per_frame")) == 1000.0);
    assert_string_equal(json_string_value(json_object_get(v1, "name")), "a \"quoted\"\\name");
    assert_true(json_is_true(json_object_get(v1, "failed")));
    assert_string_equal(json_string_value(json_object_get(v1, "error")), "server refused: \x01 bad\ttoken ?");
    assert_int_equal(json_integer_value(json_object_get(total, "frames")), 40);
    assert_int_equal(json_integer_value(json_object_get(total, "failed")), 1);
    assert_int_equal(json_integer_value(json_object_get(total, "bytes_received")), 36000);
    json_decref(root);

    /* The display and the render cache's figures: means over display frames. */
    view_viewer_stats rc = {.index = 0};
    rc.display = (view_display_stats){.frames = 4,
                                      .skipped = 1,
                                      .fps = 30,
                                      .empty_fraction_sum = 0.5,
                                      .reproject = true,
                                      .points_sum = 400,
                                      .points_last = 120,
                                      .request_messages = 8,
                                      .request_pixels = 800,
                                      .answers = 6,
                                      .samples_received = 600,
                                      .frames_inserted = 3,
                                      .total_ms_sum = 10,
                                      .total_ms_max = 4,
                                      .rtt_ms = 75};
    rc.display.kind_fraction_sum[VIEW_RC_EMPTY] = 0.5;
    rc.display.kind_fraction_sum[VIEW_RC_POINT] = 3.0;
    rc.display.stage_ms_sum[VIEW_RC_STAGE_ZBUFFER] = 2;
    assert_int_equal(view_stats_write_json(path, &rc, 1, "ws://h:1", 1, err, sizeof err), 0);
    root = json_load_file(path, 0, &error);
    if (!root)
        fail_msg("%s:%d: %s", path, error.line, error.text);
    json_t *v = json_array_get(json_object_get(root, "viewers"), 0);
    json_t *display = json_object_get(v, "display"), *cache = json_object_get(v, "render_cache");
    assert_int_equal(json_integer_value(json_object_get(display, "frames")), 4);
    assert_int_equal(json_integer_value(json_object_get(display, "skipped")), 1);
    assert_true(json_real_value(json_object_get(display, "empty_fraction")) == 0.125);
    json_t *fractions = json_object_get(cache, "pixel_fractions");
    assert_true(json_real_value(json_object_get(fractions, "empty")) == 0.125);
    assert_true(json_real_value(json_object_get(fractions, "point")) == 0.75);
    assert_int_equal(json_integer_value(json_object_get(cache, "points")), 120);
    assert_true(json_real_value(json_object_get(cache, "points_mean")) == 100);
    assert_int_equal(json_integer_value(json_object_get(cache, "requests_sent")), 8);
    assert_int_equal(json_integer_value(json_object_get(cache, "requests_answered")), 6);
    assert_int_equal(json_integer_value(json_object_get(cache, "samples_received")), 600);
    assert_true(json_real_value(json_object_get(json_object_get(cache, "stage_ms"), "z-buffer tiles")) ==
                0.5);
    assert_true(json_real_value(json_object_get(json_object_get(cache, "total_ms"), "mean")) == 2.5);
    assert_true(json_real_value(json_object_get(cache, "rtt_ms")) == 75);
    json_decref(root);

    /* No latency samples: null, not 0; no render cache: null. */
    view_viewer_stats empty = {.index = 0};
    assert_int_equal(view_stats_write_json(path, &empty, 1, "ws://h:1", 0, err, sizeof err), 0);
    root = json_load_file(path, 0, &error);
    assert_non_null(root);
    assert_true(json_is_null(json_object_get(
        json_object_get(json_array_get(json_object_get(root, "viewers"), 0), "latency_ms"), "median")));
    assert_true(
        json_is_null(json_object_get(json_array_get(json_object_get(root, "viewers"), 0), "render_cache")));
    json_decref(root);
    /* A file that cannot be created: one line. */
    assert_int_equal(view_stats_write_json(fxt_tmp_path("no/such/folder/s.json"), &empty, 1, "ws://h:1", 0,
                                           err, sizeof err),
                     -1);
    assert_non_null(strstr(err, "cannot create"));
    assert_null(strchr(err, '\n'));
    for (int i = 0; i < 2; i++)
        view_latency_free(&viewers[i].latency);
}

/* ---- cameras ------------------------------------------------------------------------------------------ */

/* A welcome with bounds [-5, 5] x [0, 4] x [-4, 4] and a default camera at (3, 1.6, 4) looking down -Z. */
static proto_welcome room_welcome(void)
{
    proto_welcome w = {.viewer_id = 1, .fps = 30, .max_camera_rate = 120};
    const double lo[3] = {-5, 0, -4}, hi[3] = {5, 4, 4};
    for (int k = 0; k < 3; k++) {
        w.bounds_min[k] = lo[k];
        w.bounds_max[k] = hi[k];
    }
    w.camera.position[0] = 3;
    w.camera.position[1] = 1.6;
    w.camera.position[2] = 4;
    w.camera.direction[2] = -1;
    w.camera.fov_deg = 55;
    return w;
}

static void test_orbit(void **state)
{
    (void)state;
    proto_welcome w = room_welcome();
    const double centre[3] = {0, 2, 0}, radius = 5.0, start = atan2(4.0, 3.0); /* |(3, 4)| = 5 */
    for (uint32_t viewers = 1; viewers <= 5; viewers += 2)
        for (uint32_t viewer = 0; viewer < viewers; viewer++)
            for (uint32_t index = 0; index < 600; index += 7) {
                proto_pose pose = view_camera_generate(VIEW_CAMERA_ORBIT, &w, viewer, viewers, index, 0);
                double angle = start + 2 * PI * ((double)viewer / viewers + (double)(index % 240) / 240.0);
                assert_true(fabs(pose.position[0] - radius * cos(angle)) < 1e-9);
                assert_true(fabs(pose.position[2] - radius * sin(angle)) < 1e-9);
                assert_true(pose.position[1] == 1.6); /* the default camera's height */
                /* Looks at the centre: direction = centre - position (to float precision). */
                for (int k = 0; k < 3; k++)
                    assert_true(fabs(pose.direction[k] - (centre[k] - pose.position[k])) < 1e-5);
                assert_true(pose.fov_deg == 55.0f);
            }
    /* Viewer 0's first camera is the default camera's position; a revolution later it is there again. */
    proto_pose first = view_camera_generate(VIEW_CAMERA_ORBIT, &w, 0, 4, 0, 0);
    proto_pose again = view_camera_generate(VIEW_CAMERA_ORBIT, &w, 0, 4, 240, 0);
    assert_true(fabs(first.position[0] - 3) < 1e-12 && fabs(first.position[2] - 4) < 1e-12);
    assert_true(memcmp(&first, &again, sizeof first) == 0);
    /* Four viewers a quarter turn apart: viewer 2 opposite viewer 0. */
    proto_pose opposite = view_camera_generate(VIEW_CAMERA_ORBIT, &w, 2, 4, 0, 0);
    assert_true(fabs(opposite.position[0] + 3) < 1e-12 && fabs(opposite.position[2] + 4) < 1e-12);
    /* --fov replaces the camera's. */
    assert_true(view_camera_generate(VIEW_CAMERA_ORBIT, &w, 0, 1, 0, 70.5f).fov_deg == 70.5f);

    /* A default camera right above the centre: the orbit takes half the horizontal diagonal, from angle 0. */
    w.camera.position[0] = 0;
    w.camera.position[2] = 0;
    proto_pose above = view_camera_generate(VIEW_CAMERA_ORBIT, &w, 0, 1, 0, 0);
    double half_diagonal = 0.5 * hypot(10, 8);
    assert_true(fabs(above.position[0] - half_diagonal) < 1e-12 && fabs(above.position[2]) < 1e-12);
    assert_true(above.direction[0] < 0);

    /* Far from the origin, in double: a scene at 1e6 keeps centimetres. */
    proto_welcome far = room_welcome();
    for (int k = 0; k < 3; k++) {
        far.bounds_min[k] += 1e6;
        far.bounds_max[k] += 1e6;
        far.camera.position[k] += 1e6;
    }
    proto_pose moved = view_camera_generate(VIEW_CAMERA_ORBIT, &far, 0, 1, 0, 0);
    assert_true(fabs(moved.position[0] - (1e6 + 3)) < 1e-6 && fabs(moved.position[1] - (1e6 + 1.6)) < 1e-6);
}

static void test_static_and_kinds(void **state)
{
    (void)state;
    proto_welcome w = room_welcome();
    for (uint32_t index = 0; index < 500; index += 61) {
        proto_pose pose = view_camera_generate(VIEW_CAMERA_STATIC, &w, index % 3, 3, index, 0);
        assert_true(memcmp(&pose, &w.camera, sizeof pose) == 0);
    }
    assert_true(view_camera_generate(VIEW_CAMERA_STATIC, &w, 0, 1, 0, 30).fov_deg == 30.0f);
    view_camera_kind kind;
    assert_true(view_camera_kind_parse("orbit", &kind) && kind == VIEW_CAMERA_ORBIT);
    assert_true(view_camera_kind_parse("static", &kind) && kind == VIEW_CAMERA_STATIC);
    assert_false(view_camera_kind_parse("Orbit", &kind));
    assert_false(view_camera_kind_parse("", &kind));
    assert_string_equal(view_camera_kind_name(VIEW_CAMERA_STATIC), "static");
    assert_string_equal(view_camera_kind_name(VIEW_CAMERA_KIND_COUNT), "unknown");
}

/* Which trace lines are due after some seconds, and trace lines as wire poses. */
static void test_trace_schedule(void **state)
{
    (void)state;
    const char *text =
        "fxcache-trace 2\nresolution 64 36\n"
        "10 0 0 0 0 0 -1 60\n10.5 1 0 0 0 0 -1 60\n10.5 2 0 0 0 0 -1 60\n12 0 0 0 1e-50 0 0 45\n";
    proto_trace t;
    char err[256];
    assert_int_equal(proto_trace_parse(text, strlen(text), "s.trace", &t, err, sizeof err), FXC_OK);
    static const struct {
        double origin, elapsed;
        uint32_t due;
    } cases[] = {
        {10, -0.1, 0}, {10, 0, 1},   {10, 0.4999, 1}, {10, 0.5, 3}, {10, 1.99, 3},
        {10, 2, 4},    {10, 100, 4}, {9, 1, 1},       {9, 0.9, 0},  {10, 0.5 - 1e-10, 3}, /* the 1e-9 slack */
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        if (view_trace_due(&t, cases[i].origin, cases[i].elapsed) != cases[i].due)
            fail_msg("case %zu: %u due, expected %u", i,
                     view_trace_due(&t, cases[i].origin, cases[i].elapsed), cases[i].due);
    proto_pose pose = view_camera_from_trace(&t, 1, 0);
    assert_true(pose.position[0] == 1 && pose.direction[2] == -1.0f && pose.fov_deg == 60.0f);
    assert_true(view_camera_from_trace(&t, 1, 33).fov_deg == 33.0f);
    /* A direction below float range is kept as a direction, not rounded to zero. */
    pose = view_camera_from_trace(&t, 3, 0);
    assert_true(pose.direction[0] == 1.0f && pose.direction[1] == 0 && pose.direction[2] == 0);
    assert_true(pose.fov_deg == 45.0f);
    proto_trace_release(&t);
}

/* The display clock's cameras: the orbit between two generated cameras, a trace between two lines. */
static void test_display_cameras(void **state)
{
    (void)state;
    proto_welcome w = room_welcome();
    const double start = atan2(4.0, 3.0);
    for (uint32_t index = 0; index < 500; index += 13) {
        /* A whole index is the generated camera, bit for bit; a fractional one lies on the circle at its
         * angle (closed form), between its neighbours. */
        proto_pose whole = view_camera_generate(VIEW_CAMERA_ORBIT, &w, 1, 3, index, 0);
        proto_pose at = view_camera_generate_at(VIEW_CAMERA_ORBIT, &w, 1, 3, (double)(index % 240), 0);
        assert_true(memcmp(&whole, &at, sizeof at) == 0);
        double fractional = index + 0.37;
        at = view_camera_generate_at(VIEW_CAMERA_ORBIT, &w, 1, 3, fractional, 0);
        double angle = start + 2 * PI * (1.0 / 3 + fmod(fractional, 240) / 240.0);
        assert_true(fabs(at.position[0] - 5 * cos(angle)) < 1e-9 &&
                    fabs(at.position[2] - 5 * sin(angle)) < 1e-9);
    }
    /* A trace: at a line's time that line; between two lines mixed linearly; before the first the first,
     * after the last the last. Line 1 to 2 turns 90 degrees (-z to +x) and moves 2 m in 1 s. */
    const char *text = "fxcache-trace 1\n5 0 0 0 0 0 -1 60\n6 0 0 0 0 0 -3 60\n7 2 0 0 5 0 0 40\n";
    proto_trace t;
    char err[256];
    assert_int_equal(proto_trace_parse(text, strlen(text), "d.trace", &t, err, sizeof err), FXC_OK);
    proto_pose p = view_camera_trace_at(&t, 5, 1, 0), line = view_camera_from_trace(&t, 1, 0);
    assert_true(memcmp(&p, &line, sizeof p) == 0);
    p = view_camera_trace_at(&t, 5, -3, 0);
    assert_true(p.position[0] == 0 && p.direction[2] == -1.0f);
    p = view_camera_trace_at(&t, 5, 9, 0);
    assert_true(p.position[0] == 2 && p.direction[0] == 5.0f && p.fov_deg == 40.0f);
    p = view_camera_trace_at(&t, 5, 1.5, 0); /* half way: (1, 0, 0), direction (0.5, 0, -0.5) normalised */
    assert_true(fabs(p.position[0] - 1) < 1e-12);
    assert_true(fabs(p.direction[0] - sqrt(0.5)) < 1e-6 && fabs(p.direction[2] + sqrt(0.5)) < 1e-6);
    assert_true(fabs(p.fov_deg - 50) < 1e-5);
    assert_true(view_camera_trace_at(&t, 5, 1.25, 33).fov_deg == 33.0f);
    proto_trace_release(&t);
}

/* Extrapolation: a steady turn at a steady pitch and a straight move are extrapolated exactly (closed form),
 * also across yaw +-180 degrees; times that do not increase give the current camera. */
static void test_extrapolate(void **state)
{
    (void)state;
    static const struct {
        double yaw0, yaw1, pitch0, pitch1; /* degrees */
    } cases[] = {{0, 10, 0, 0}, {170, -175, 5, 10}, {-120, -150, -20, -30}, {45, 45, 0, 0}};
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        proto_pose a = {.position = {1, 2, 3}, .fov_deg = 60}, b = {.position = {1.5, 2, 2}, .fov_deg = 60};
        double r = PI / 180;
        double y0 = cases[i].yaw0 * r, y1 = cases[i].yaw1 * r, p0 = cases[i].pitch0 * r,
               p1 = cases[i].pitch1 * r;
        a.direction[0] = (float)(cos(p0) * sin(y0)), a.direction[1] = (float)sin(p0);
        a.direction[2] = (float)(-cos(p0) * cos(y0));
        b.direction[0] = (float)(2 * cos(p1) * sin(y1)), b.direction[1] = (float)(2 * sin(p1)); /* not unit */
        b.direction[2] = (float)(-2 * cos(p1) * cos(y1));
        /* previous at 10 s, current at 10.1 s, target 10.35 s: 2.5 steps on. */
        proto_pose e = view_pose_extrapolate(&a, 10, &b, 10.1, 10.35);
        double turn = remainder(y1 - y0, 2 * PI), yaw = y1 + 2.5 * turn, pitch = p1 + 2.5 * (p1 - p0);
        double expected[3] = {cos(pitch) * sin(yaw), sin(pitch), -cos(pitch) * cos(yaw)};
        for (int k = 0; k < 3; k++)
            if (fabs(e.direction[k] - expected[k]) > 1e-5)
                fail_msg("case %zu: direction[%d] %g, expected %g", i, k, e.direction[k], expected[k]);
        assert_true(fabs(e.position[0] - 2.75) < 1e-12 && fabs(e.position[2] - -0.5) < 1e-12);
        assert_true(e.position[1] == 2 && e.fov_deg == 60.0f);
        proto_pose same = view_pose_extrapolate(&a, 10.1, &b, 10.1, 11);
        assert_true(memcmp(&same, &b, sizeof b) == 0);
    }
}

/* ---- images ------------------------------------------------------------------------------------------- */

/* The client's PNG and the server's PNG of the same pixels are the same bytes, and read back as those pixels.
 */
static void test_png_same_as_server(void **state)
{
    (void)state;
    const uint32_t width = 67, height = 31;
    uint8_t *rgb = malloc((size_t)width * height * 3);
    assert_non_null(rgb);
    uint32_t seed = 12345;
    for (size_t i = 0; i < (size_t)width * height * 3; i++) {
        seed = seed * 1664525u + 1013904223u;
        rgb[i] = (uint8_t)(i % 7 == 0 ? seed >> 24 : (i / 3) % 251);
    }
    char client_path[1024], server_path[1024], msg[512];
    snprintf(client_path, sizeof client_path, "%s", fxt_tmp_path("client.png"));
    snprintf(server_path, sizeof server_path, "%s", fxt_tmp_path("server.png"));
    assert_int_equal(view_image_write_png(client_path, width, height, rgb, msg, sizeof msg), 0);
    assert_int_equal(scene_image_write_u8(server_path, width, height, 3, rgb, msg, sizeof msg), 0);
    size_t client_len, server_len;
    uint8_t *client = fxt_read_file(client_path, &client_len),
            *server = fxt_read_file(server_path, &server_len);
    assert_int_equal(client_len, server_len);
    assert_memory_equal(client, server, client_len);
    assert_memory_equal(client, "\x89PNG\r\n\x1a\n", 8);
    /* Read back (as linear floats from sRGB): pixel values survive. */
    uint32_t w2, h2;
    float *back;
    assert_int_equal(scene_image_read_rgb(client_path, &w2, &h2, &back, msg, sizeof msg), 0);
    assert_int_equal(w2, width);
    assert_int_equal(h2, height);
    for (size_t i = 0; i < (size_t)width * height * 3; i += 97) {
        double c = rgb[i] / 255.0, linear = c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
        assert_true(fabs(back[i] - linear) < 1e-4);
    }
    free(back);
    free(client);
    free(server);
    /* A folder that does not exist: -1 and one line naming the file. */
    assert_int_equal(view_image_write_png(fxt_tmp_path("no/such/x.png"), width, height, rgb, msg, sizeof msg),
                     -1);
    assert_non_null(strstr(msg, "no/such/x.png"));
    assert_null(strchr(msg, '\n'));
    /* A full disk (a file name linked to /dev/full, where every write fails with ENOSPC): both writers say so
     * in one line, and leave no file. OpenImageIO's PNG writer does not check its writes: both returned 0. */
    if (access("/dev/full", W_OK) == 0)
        for (int k = 0; k < 2; k++) {
            char full_path[1024];
            snprintf(full_path, sizeof full_path, "%s",
                     fxt_tmp_path(k ? "full_server.png" : "full_client.png"));
            remove(full_path);
            assert_int_equal(symlink("/dev/full", full_path), 0);
            int rc = k ? scene_image_write_u8(full_path, width, height, 3, rgb, msg, sizeof msg)
                       : view_image_write_png(full_path, width, height, rgb, msg, sizeof msg);
            if (rc != -1 || !strstr(msg, "No space left on device") || !strstr(msg, full_path))
                fail_msg("%s writer on a full disk: %d, '%s'", k ? "server" : "client", rc, msg);
            assert_null(strchr(msg, '\n'));
            assert_int_equal(access(full_path, F_OK), -1);
            remove(full_path);
        }
    else
        print_message("/dev/full is absent: the full-disk case is skipped\n");
    free(rgb);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_median_and_percentile),
        cmocka_unit_test(test_figures),
        cmocka_unit_test(test_stats_json),
        cmocka_unit_test(test_orbit),
        cmocka_unit_test(test_static_and_kinds),
        cmocka_unit_test(test_trace_schedule),
        cmocka_unit_test(test_display_cameras),
        cmocka_unit_test(test_extrapolate),
        cmocka_unit_test(test_png_same_as_server),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
