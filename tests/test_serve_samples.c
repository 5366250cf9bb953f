/* `fxcache serve`'s answers to the client render cache (issue 11), from outside: the real program on a free
 * port, a peer speaking WebSocket and the wire format through proto/ (the helpers below are test_serve.c's,
 * copied so that file stays as it was).
 *
 *   - sample requests: the answer echoes the request and its camera and holds one sample per requested
 *     entry in the request's order (duplicates included); on a static camera each sample equals the same
 *     pixel of the frame the server rendered in the same frame (colour and binary32 depth, bit for bit,
 *     shadow and AO); a request over --max-samples (by its count, or by its size from the header), for an
 *     image over --max-res, a flood, or before hello is refused with an error; a request larger than
 *     --max-message but within --max-samples is answered;
 *   - strategies: fan's frames carry a vertical fov of 2 atan(1.5 tan(fov/2)) (closed form), the same
 *     position and direction; predictive renders the camera message's predicted pose when it has one, and
 *     otherwise a pose extrapolated along the motion by between one frame period and a second; an unknown
 *     strategy is refused; --record writes the camera rendered (fan's widened fov). */
#include "proto.h"
#include "fxt_serve.h"
#include "test_util.h"

#include <arpa/inet.h>
#include <errno.h>
#include <jansson.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

/* ---- the render cache's peer -----------------------------------------------------------------------------
 */

/* Receives messages until one of type `type` arrives (others are skipped, frames kept in *frame_out when
 * given); returns its bytes (caller frees) and fills *m, or NULL on close or timeout. */
static uint8_t *recv_type(int fd, uint32_t type, proto_msg *m)
{
    for (int i = 0; i < 1000; i++) {
        uint8_t *msg = NULL;
        long n = fxt_ws_recv(fd, &msg, 60);
        if (n < 0)
            return NULL;
        if (proto_decode(msg, (size_t)n, m) == FXC_OK && m->type == type)
            return msg;
        if (m->type == PROTO_ERROR)
            print_message("error %d: %s\n", m->u.error.code, m->u.error.reason);
        free(msg);
    }
    return NULL;
}

static proto_msg request_msg(uint32_t request, const proto_pose *camera, uint32_t width, uint32_t height,
                             const uint8_t *pixels, uint32_t count)
{
    proto_msg m = {.type = PROTO_SAMPLE_REQUEST};
    m.u.sample_request = (proto_sample_request){.request = request,
                                                .camera = *camera,
                                                .width = width,
                                                .height = height,
                                                .count = count,
                                                .pixels = pixels};
    return m;
}

enum { W = 64, H = 36, LIST = 300, KEEP = 32 };

/* A decoded frame (its number, colour and depth) and the answer rendered in the same server frame. */
typedef struct kept_frame {
    uint32_t frame, answer_frame;
    uint8_t rgb[W * H * 3];
    float depth[W * H];
    uint8_t samples[LIST * PROTO_SAMPLE_BYTES];
    bool compared;
} kept_frame;

/* Compares an answer's samples with the frame of the same server frame, once both arrived. */
static bool compare_kept(kept_frame *k)
{
    if (k->compared || k->frame != k->answer_frame || k->frame == UINT32_MAX)
        return false;
    for (uint32_t e = 0; e < LIST; e++) {
        proto_sample s;
        proto_sample_get(k->samples, e, &s);
        size_t p = (size_t)s.y * W + s.x;
        if (memcmp(s.rgb, k->rgb + 3 * p, 3) != 0 || memcmp(&s.depth, &k->depth[p], 4) != 0)
            fail_msg("frame %u pixel (%u, %u): sample %u %u %u depth %g, frame %u %u %u depth %g", k->frame,
                     s.x, s.y, s.rgb[0], s.rgb[1], s.rgb[2], (double)s.depth, k->rgb[3 * p],
                     k->rgb[3 * p + 1], k->rgb[3 * p + 2], (double)k->depth[p]);
    }
    k->compared = true;
    return true;
}

static void test_sample_answers(void **state)
{
    (void)state;
    fxt_server sv;
    char summary_path[512];
    snprintf(summary_path, sizeof summary_path, "%s", fxt_tmp_path("samples_summary.json"));
    const char *args[] = {
        "--fps", "20",        "--effects",  "shadow,ao", "--max-samples", "1000", "--max-message",
        "1024",  "--summary", summary_path, NULL};
    fxt_server_start(&sv, "samples", args);
    int fd = fxt_ws_connect(sv.port);
    assert_true(fd >= 0);
    /* Before hello: refused. */
    uint8_t pixels[LIST * 4];
    uint32_t rng = 12345;
    for (uint32_t i = 0; i < LIST; i++) {
        rng = rng * 1664525u + 1013904223u;
        uint16_t x = (uint16_t)((rng >> 8) % W), y = (uint16_t)((rng >> 20) % H);
        if (i == 7)
            x = 0, y = 0;
        if (i == 8) /* a duplicate */
            x = 0, y = 0;
        proto_request_pixel_put(pixels, i, x, y);
    }
    proto_pose pose = {{0, 1, 0}, {0, 0, -1}, 60};
    proto_msg early = request_msg(1, &pose, W, H, pixels, 10);
    assert_true(fxt_ws_send_msg(fd, &early));
    assert_true(fxt_expect_error(fd, FXC_ERR_PROTOCOL));
    close(fd);

    fd = fxt_ws_connect(sv.port);
    proto_msg hello = fxt_hello_msg(W, H, PROTO_CODEC_RAW);
    hello.u.hello.depth = PROTO_DEPTH_FLOAT;
    assert_true(fxt_ws_send_msg(fd, &hello));
    proto_welcome w;
    assert_true(fxt_read_welcome(fd, &w));
    pose = w.camera;
    pose.fov_deg = 60;
    proto_msg cam = {.type = PROTO_CAMERA};
    cam.u.camera.pose = pose;
    assert_true(fxt_ws_send_msg(fd, &cam));
    static kept_frame kept[KEEP];
    for (int k = 0; k < KEEP; k++)
        kept[k].frame = kept[k].answer_frame = UINT32_MAX;
    uint32_t answers = 0, compared = 0, next_request = 100;
    proto_msg req = request_msg(next_request, &pose, W, H, pixels, LIST); /* 4 kB: over --max-message 1024 */
    assert_true(fxt_ws_send_msg(fd, &req));
    for (int i = 0; i < 400 && compared < 6; i++) {
        uint8_t *msg = NULL;
        long n = fxt_ws_recv(fd, &msg, 60);
        assert_true(n > 0);
        proto_msg m;
        assert_int_equal(proto_decode(msg, (size_t)n, &m), FXC_OK);
        if (m.type == PROTO_FRAME) {
            const proto_frame *fr = &m.u.frame;
            kept_frame *k = &kept[fr->frame % KEEP];
            if (k->answer_frame != fr->frame)
                k->compared = false;
            k->frame = fr->frame;
            assert_int_equal(proto_color_decode(fr->codec, fr->color, fr->color_bytes, W, H, k->rgb), FXC_OK);
            assert_int_equal(proto_depth_decode(fr->depth, fr->depth_data, fr->depth_bytes, W, H, k->depth),
                             FXC_OK);
            compared += answers >= 4 && compare_kept(k);
        } else if (m.type == PROTO_SAMPLES) {
            const proto_samples *a = &m.u.samples;
            answers++;
            assert_int_equal(a->request, next_request);
            assert_int_equal(a->width, W);
            assert_int_equal(a->height, H);
            assert_int_equal(a->count, LIST);
            assert_true(fabs(a->camera.position[0] - pose.position[0]) < 1e-4);
            assert_true(fabs(a->camera.fov_deg - pose.fov_deg) < 1e-4f);
            for (uint32_t e = 0; e < LIST; e++) { /* the request's order, duplicates answered */
                proto_sample s;
                uint16_t x, y;
                proto_sample_get(a->samples, e, &s);
                proto_request_pixel_get(pixels, e, &x, &y);
                assert_int_equal(s.x, x);
                assert_int_equal(s.y, y);
            }
            /* From the fourth answer on (the caches converged for a static camera), against the frame of the
             * same server frame once both arrived (frames may be replaced by newer ones). */
            kept_frame *k = &kept[a->frame % KEEP];
            if (k->frame != a->frame)
                k->compared = false;
            k->answer_frame = a->frame;
            memcpy(k->samples, a->samples, sizeof k->samples);
            compared += answers >= 4 && compare_kept(k);
            req.u.sample_request.request = ++next_request;
            assert_true(fxt_ws_send_msg(fd, &req));
            assert_true(fxt_ws_send_msg(fd, &cam));
        }
        free(msg);
    }
    assert_true(compared >= 6);
    print_message("%u answers, %u compared with the frame of the same server frame\n", answers, compared);
    /* Over --max-samples: here its message is also over the sample requests' size limit (12 + 56 + 4 x 1000
     * bytes), so it is refused from its header alone (test_strategies' server reaches the count check). */
    static uint8_t many[1001 * 4];
    proto_msg over = request_msg(1, &pose, W, H, many, 1001);
    assert_true(fxt_ws_send_msg(fd, &over));
    assert_true(fxt_expect_error(fd, FXC_ERR_TOO_LARGE));
    close(fd);
    /* An image over --max-res (default 3840x2160). */
    fd = fxt_ws_connect(sv.port);
    assert_true(fxt_ws_send_msg(fd, &hello));
    assert_true(fxt_read_welcome(fd, &w));
    proto_msg huge = request_msg(1, &pose, 4000, H, pixels, 10);
    assert_true(fxt_ws_send_msg(fd, &huge));
    assert_true(fxt_expect_error(fd, FXC_ERR_LIMIT));
    close(fd);
    /* A flood: over the bucket of --camera-rate (240) requests. */
    fd = fxt_ws_connect(sv.port);
    assert_true(fxt_ws_send_msg(fd, &hello));
    assert_true(fxt_read_welcome(fd, &w));
    proto_msg small = request_msg(1, &pose, W, H, pixels, 4);
    bool sent = true;
    for (int i = 0; i < 400 && sent; i++)
        sent = fxt_ws_send_msg(fd, &small);
    assert_true(fxt_expect_error(fd, FXC_ERR_LIMIT));
    close(fd);
    assert_int_equal(fxt_server_stop(&sv), 0);
    /* The summary counts them: every answer received was a request received and an answer sent. */
    json_error_t jerr;
    json_t *sum = json_load_file(summary_path, 0, &jerr);
    assert_non_null(sum);
    json_t *serve = json_object_get(sum, "serve");
    json_int_t requests = json_integer_value(json_object_get(serve, "sample_requests"));
    json_int_t answers_sent = json_integer_value(json_object_get(serve, "samples_sent"));
    json_int_t sent_pixels = json_integer_value(json_object_get(serve, "samples_pixels"));
    print_message("summary: %lld sample requests, %lld answers sent (%lld samples)\n", (long long)requests,
                  (long long)answers_sent, (long long)sent_pixels);
    assert_true(requests >= answers && answers_sent >= answers && answers_sent <= requests);
    assert_true(sent_pixels >= (json_int_t)answers * LIST);
    json_decref(sum);
}

/* The frame camera the server renders for one camera message under a strategy (from the second frame on, so
 * that the message was taken). */
static proto_pose frame_camera(int fd, const proto_msg *cam)
{
    proto_msg m;
    assert_true(fxt_ws_send_msg(fd, cam));
    proto_pose last = {0};
    for (int i = 0; i < 3; i++) {
        uint8_t *msg = recv_type(fd, PROTO_FRAME, &m);
        assert_non_null(msg);
        last = m.u.frame.camera;
        free(msg);
    }
    return last;
}

static void unit(const float d[3], double out[3])
{
    double len = sqrt((double)d[0] * d[0] + (double)d[1] * d[1] + (double)d[2] * d[2]);
    for (int k = 0; k < 3; k++)
        out[k] = d[k] / len;
}

static void assert_same_direction(const float a[3], const float b[3])
{
    double ua[3], ub[3];
    unit(a, ua);
    unit(b, ub);
    for (int k = 0; k < 3; k++)
        if (fabs(ua[k] - ub[k]) > 1e-5)
            fail_msg("direction %g %g %g, expected %g %g %g", ua[0], ua[1], ua[2], ub[0], ub[1], ub[2]);
}

/* Strategies (and the sample count limit, which needs a server whose --max-message lets the message in). */
static void test_strategies(void **state)
{
    (void)state;
    fxt_server sv;
    char record_dir[512];
    snprintf(record_dir, sizeof record_dir, "%s", fxt_tmp_path("strategies_rec"));
    const char *args[] = {"--fps", "20",       "--effects", "shadow,ao", "--max-samples",
                          "1000",  "--record", record_dir,  NULL};
    fxt_server_start(&sv, "strategies", args);
    /* A request over --max-samples whose message is within --max-message (65536): refused by its count. */
    int over_fd = fxt_ws_connect(sv.port);
    proto_msg plain = fxt_hello_msg(W, H, PROTO_CODEC_ZSTD);
    assert_true(fxt_ws_send_msg(over_fd, &plain));
    proto_welcome over_welcome;
    assert_true(fxt_read_welcome(over_fd, &over_welcome));
    static uint8_t many[1001 * 4];
    proto_msg over = request_msg(1, &over_welcome.camera, W, H, many, 1001);
    assert_true(fxt_ws_send_msg(over_fd, &over));
    assert_true(fxt_expect_error(over_fd, FXC_ERR_LIMIT));
    close(over_fd);
    /* Unknown: refused before welcome. */
    int fd = fxt_ws_connect(sv.port);
    proto_msg hello = fxt_hello_msg(W, H, PROTO_CODEC_ZSTD);
    snprintf(hello.u.hello.strategy, sizeof hello.u.hello.strategy, "nearest");
    assert_true(fxt_ws_send_msg(fd, &hello));
    assert_true(fxt_expect_error(fd, FXC_ERR_RANGE));
    close(fd);
    static const char *const strategies[] = {"", "basic", "fan"};
    for (int s = 0; s < 3; s++) {
        fd = fxt_ws_connect(sv.port);
        snprintf(hello.u.hello.strategy, sizeof hello.u.hello.strategy, "%s", strategies[s]);
        assert_true(fxt_ws_send_msg(fd, &hello));
        proto_welcome w;
        assert_true(fxt_read_welcome(fd, &w));
        for (int f = 0; f < 2; f++) {
            float fov = f == 0 ? 60.0f : 90.0f;
            proto_msg cam = {.type = PROTO_CAMERA};
            cam.u.camera.pose = w.camera;
            cam.u.camera.pose.fov_deg = fov;
            proto_pose got = frame_camera(fd, &cam);
            double want = s < 2 ? fov : 360.0 / M_PI * atan(1.5 * tan(fov * M_PI / 360.0));
            if (fabs(got.fov_deg - want) > 1e-3)
                fail_msg("strategy '%s', fov %g: frame fov %g, expected %g", strategies[s], (double)fov,
                         (double)got.fov_deg, want);
            for (int k = 0; k < 3; k++)
                assert_true(fabs(got.position[k] - w.camera.position[k]) < 1e-4);
            assert_same_direction(got.direction, w.camera.direction);
        }
        close(fd);
    }
    /* Predictive with a predicted pose: that pose is rendered. */
    fd = fxt_ws_connect(sv.port);
    snprintf(hello.u.hello.strategy, sizeof hello.u.hello.strategy, "predictive");
    assert_true(fxt_ws_send_msg(fd, &hello));
    proto_welcome w;
    assert_true(fxt_read_welcome(fd, &w));
    proto_msg cam = {.type = PROTO_CAMERA};
    cam.u.camera.pose = w.camera;
    cam.u.camera.time = 1.0;
    cam.u.camera.has_predicted = true;
    cam.u.camera.predicted_time = 1.1;
    cam.u.camera.predicted = w.camera;
    cam.u.camera.predicted.position[0] += 0.5;
    cam.u.camera.predicted.direction[0] += 0.3f;
    cam.u.camera.predicted.fov_deg = 50;
    proto_pose got = frame_camera(fd, &cam);
    for (int k = 0; k < 3; k++)
        assert_true(fabs(got.position[k] - cam.u.camera.predicted.position[k]) < 1e-4);
    assert_same_direction(got.direction, cam.u.camera.predicted.direction);
    assert_true(fabs(got.fov_deg - 50.0f) < 1e-4f);
    /* Without one: extrapolated from the last two messages. 0.1 s of client time apart, 0.2 m along x: at
     * 2 m/s and a latency between a frame period (0.05 s at 20 fps) and a second, 0.1..2 m ahead of the
     * latest position along x, nowhere else. */
    cam.u.camera.has_predicted = false;
    cam.u.camera.time = 2.0;
    assert_true(fxt_ws_send_msg(fd, &cam));
    cam.u.camera.time = 2.1;
    cam.u.camera.pose.position[0] += 0.2;
    got = frame_camera(fd, &cam);
    double ahead = got.position[0] - cam.u.camera.pose.position[0];
    print_message("predictive: %.3f m ahead along the motion\n", ahead);
    assert_true(ahead >= 0.1 - 1e-4 && ahead <= 2.0 + 1e-4);
    assert_true(fabs(got.position[1] - cam.u.camera.pose.position[1]) < 1e-4);
    assert_true(fabs(got.position[2] - cam.u.camera.pose.position[2]) < 1e-4);
    assert_same_direction(got.direction, w.camera.direction);
    close(fd);
    assert_int_equal(fxt_server_stop(&sv), 0);
    /* --record writes the camera rendered: the fan viewer (viewer_03: viewer_00 never sent a camera, then "",
     * basic, fan) ends with the widened fov of its 90-degree camera. */
    char path[600], line[512];
    snprintf(path, sizeof path, "%s/viewer_03.trace", record_dir);
    FILE *trace = fopen(path, "r");
    assert_non_null(trace);
    double last_fov = 0;
    while (fgets(line, sizeof line, trace)) {
        double v[8];
        if (sscanf(line, "%lf %lf %lf %lf %lf %lf %lf %lf", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5], &v[6],
                   &v[7]) == 8)
            last_fov = v[7];
    }
    fclose(trace);
    double want = 360.0 / M_PI * atan(1.5 * tan(90.0 * M_PI / 360.0));
    if (fabs(last_fov - want) > 1e-3)
        fail_msg("%s: last fov %g, expected %g", path, last_fov, want);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sample_answers),
        cmocka_unit_test(test_strategies),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
