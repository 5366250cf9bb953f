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

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- the server process ----------------------------------------------------------------------------------
 */

typedef struct server {
    pid_t pid;
    int port;
    char out[512], err[512];
} server;

/* Starts `fxcache serve --port 0 ARGS...` with stdout and stderr in files; waits for its address line. */
static void server_start(server *sv, const char *name, const char *const *args)
{
    snprintf(sv->out, sizeof sv->out, "%s", fxt_tmp_path(name));
    strncat(sv->out, ".out", sizeof sv->out - strlen(sv->out) - 1);
    snprintf(sv->err, sizeof sv->err, "%s", fxt_tmp_path(name));
    strncat(sv->err, ".err", sizeof sv->err - strlen(sv->err) - 1);
    const char *argv[64] = {FXC_BIN, "serve", "--port", "0", "--quiet"};
    int n = 5;
    for (int i = 0; args[i] && n < 62; i++)
        argv[n++] = args[i];
    argv[n] = NULL;
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, sv->out, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 2, sv->err, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
    assert_int_equal(posix_spawn(&sv->pid, FXC_BIN, &fa, NULL, (char *const *)argv, environ), 0);
    posix_spawn_file_actions_destroy(&fa);
    sv->port = 0;
    for (double t0 = now_s(); now_s() - t0 < 120 && !sv->port;) {
        FILE *f = fopen(sv->out, "r");
        char line[256];
        while (f && fgets(line, sizeof line, f)) {
            const char *at = strstr(line, "listening on ws://127.0.0.1:");
            if (at)
                sv->port = atoi(at + strlen("listening on ws://127.0.0.1:"));
        }
        if (f)
            fclose(f);
        int status;
        if (!sv->port && waitpid(sv->pid, &status, WNOHANG) == sv->pid)
            fail_msg("fxcache serve exited before listening (see %s)", sv->err);
        if (!sv->port)
            usleep(20000);
    }
    assert_true(sv->port > 0);
}

/* Sends SIGTERM and returns the exit status (fails the test when it does not exit within 60 s). */
static int server_stop(server *sv)
{
    kill(sv->pid, SIGTERM);
    for (double t0 = now_s(); now_s() - t0 < 60;) {
        int status;
        if (waitpid(sv->pid, &status, WNOHANG) == sv->pid)
            return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        usleep(20000);
    }
    kill(sv->pid, SIGKILL);
    fail_msg("fxcache serve did not stop within 60 s of SIGTERM");
    return -1;
}

/* ---- WebSocket by hand ----------------------------------------------------------------------------------
 */

static int tcp_connect(int port)
{
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (fd < 0 || connect(fd, (struct sockaddr *)&a, sizeof a) != 0) {
        if (fd >= 0)
            close(fd);
        return -1;
    }
    int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    return fd;
}

static bool write_all(int fd, const void *data, size_t len)
{
    const uint8_t *p = data;
    while (len) {
        ssize_t n = send(fd, p, len, MSG_NOSIGNAL);
        if (n <= 0)
            return false;
        p += n;
        len -= (size_t)n;
    }
    return true;
}

/* Reads exactly len bytes within timeout seconds. */
static bool read_exact(int fd, void *data, size_t len, double timeout)
{
    uint8_t *p = data;
    double t0 = now_s();
    while (len) {
        struct pollfd pfd = {.fd = fd, .events = POLLIN};
        int left_ms = (int)((timeout - (now_s() - t0)) * 1000);
        if (left_ms <= 0 || poll(&pfd, 1, left_ms) <= 0)
            return false;
        ssize_t n = recv(fd, p, len, 0);
        if (n <= 0)
            return false;
        p += n;
        len -= (size_t)n;
    }
    return true;
}

/* Connects and completes the opening handshake; -1 on failure. */
static int ws_connect(int port)
{
    int fd = tcp_connect(port);
    if (fd < 0)
        return -1;
    static const char request[] =
        "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n";
    char reply[2048];
    size_t len = 0;
    if (!write_all(fd, request, sizeof request - 1))
        goto fail;
    while (len < sizeof reply - 1) {
        if (!read_exact(fd, reply + len, 1, 10))
            goto fail;
        len++;
        reply[len] = 0;
        if (len >= 4 && memcmp(reply + len - 4, "\r\n\r\n", 4) == 0)
            break;
    }
    if (!strstr(reply, " 101 "))
        goto fail;
    return fd;
fail:
    close(fd);
    return -1;
}

/* Sends one binary message as a masked client frame. */
static bool ws_send(int fd, const uint8_t *payload, size_t len)
{
    uint8_t head[14];
    size_t h = 0;
    head[h++] = 0x82;
    if (len < 126) {
        head[h++] = (uint8_t)(0x80 | len);
    } else if (len < 65536) {
        head[h++] = 0x80 | 126;
        head[h++] = (uint8_t)(len >> 8);
        head[h++] = (uint8_t)len;
    } else {
        head[h++] = 0x80 | 127;
        for (int k = 7; k >= 0; k--)
            head[h++] = (uint8_t)((uint64_t)len >> (8 * k));
    }
    static const uint8_t mask[4] = {0x12, 0x34, 0x56, 0x78};
    memcpy(head + h, mask, 4);
    h += 4;
    uint8_t *masked = malloc(len ? len : 1);
    for (size_t i = 0; i < len; i++)
        masked[i] = payload[i] ^ mask[i & 3];
    bool ok = write_all(fd, head, h) && write_all(fd, masked, len);
    free(masked);
    return ok;
}

static bool ws_send_msg(int fd, const proto_msg *m)
{
    size_t bound = proto_bound(m);
    uint8_t *buf = malloc(bound ? bound : 1);
    size_t n = buf ? proto_encode(m, buf, bound, NULL) : 0;
    bool ok = n > 0 && ws_send(fd, buf, n);
    free(buf);
    return ok;
}

/* Receives one whole message (fragments joined, control frames skipped) into *out (malloc'd, caller frees).
 * Returns its length, or -1 on close, error or timeout. */
static long ws_recv(int fd, uint8_t **out, double timeout)
{
    uint8_t *msg = NULL;
    size_t len = 0;
    for (;;) {
        uint8_t h[2];
        if (!read_exact(fd, h, 2, timeout))
            break;
        uint64_t n = h[1] & 0x7f;
        if (n == 126 || n == 127) {
            uint8_t ext[8];
            size_t e = n == 126 ? 2 : 8;
            if (!read_exact(fd, ext, e, timeout))
                break;
            n = 0;
            for (size_t k = 0; k < e; k++)
                n = n << 8 | ext[k];
        }
        int opcode = h[0] & 0x0f;
        if (n > (64u << 20))
            break;
        uint8_t *p = realloc(msg, len + n + 1);
        if (!p)
            break;
        msg = p;
        if (!read_exact(fd, msg + len, n, timeout))
            break;
        if (opcode == 8)
            break; /* close */
        if (opcode >= 8)
            continue; /* ping, pong */
        len += n;
        if (h[0] & 0x80) {
            *out = msg;
            return (long)len;
        }
    }
    free(msg);
    return -1;
}

/* Waits for the server's error message and the close: true when one came with this code (0: any code). */
static bool expect_error(int fd, int code)
{
    for (;;) {
        uint8_t *msg = NULL;
        long n = ws_recv(fd, &msg, 20);
        if (n < 0)
            return false;
        proto_msg m;
        fxc_result r = proto_decode(msg, (size_t)n, &m);
        free(msg);
        if (r != FXC_OK)
            return false;
        if (m.type == PROTO_ERROR) {
            if (code && m.u.error.code != code)
                print_message("error %d (%s), expected %d\n", m.u.error.code, m.u.error.reason, code);
            return !code || m.u.error.code == code;
        }
    }
}

static proto_msg hello_msg(uint32_t width, uint32_t height, uint8_t codec)
{
    proto_msg m = {.type = PROTO_HELLO};
    m.u.hello.width = width;
    m.u.hello.height = height;
    m.u.hello.fov_deg = 60;
    m.u.hello.codec = codec;
    return m;
}

/* Reads the welcome; its default camera is the camera the viewer then sends. */
static bool read_welcome(int fd, proto_welcome *out)
{
    uint8_t *msg = NULL;
    long n = ws_recv(fd, &msg, 60);
    if (n < 0)
        return false;
    proto_msg m;
    bool ok = proto_decode(msg, (size_t)n, &m) == FXC_OK && m.type == PROTO_WELCOME;
    if (ok)
        *out = m.u.welcome;
    free(msg);
    return ok;
}

/* ---- the render cache's peer -----------------------------------------------------------------------------
 */

/* Receives messages until one of type `type` arrives (others are skipped, frames kept in *frame_out when
 * given); returns its bytes (caller frees) and fills *m, or NULL on close or timeout. */
static uint8_t *recv_type(int fd, uint32_t type, proto_msg *m)
{
    for (int i = 0; i < 1000; i++) {
        uint8_t *msg = NULL;
        long n = ws_recv(fd, &msg, 60);
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
    server sv;
    char summary_path[512];
    snprintf(summary_path, sizeof summary_path, "%s", fxt_tmp_path("samples_summary.json"));
    const char *args[] = {
        "--fps", "20",        "--effects",  "shadow,ao", "--max-samples", "1000", "--max-message",
        "1024",  "--summary", summary_path, NULL};
    server_start(&sv, "samples", args);
    int fd = ws_connect(sv.port);
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
    assert_true(ws_send_msg(fd, &early));
    assert_true(expect_error(fd, FXC_ERR_PROTOCOL));
    close(fd);

    fd = ws_connect(sv.port);
    proto_msg hello = hello_msg(W, H, PROTO_CODEC_RAW);
    hello.u.hello.depth = PROTO_DEPTH_FLOAT;
    assert_true(ws_send_msg(fd, &hello));
    proto_welcome w;
    assert_true(read_welcome(fd, &w));
    pose = w.camera;
    pose.fov_deg = 60;
    proto_msg cam = {.type = PROTO_CAMERA};
    cam.u.camera.pose = pose;
    assert_true(ws_send_msg(fd, &cam));
    static kept_frame kept[KEEP];
    for (int k = 0; k < KEEP; k++)
        kept[k].frame = kept[k].answer_frame = UINT32_MAX;
    uint32_t answers = 0, compared = 0, next_request = 100;
    proto_msg req = request_msg(next_request, &pose, W, H, pixels, LIST); /* 4 kB: over --max-message 1024 */
    assert_true(ws_send_msg(fd, &req));
    for (int i = 0; i < 400 && compared < 6; i++) {
        uint8_t *msg = NULL;
        long n = ws_recv(fd, &msg, 60);
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
            assert_true(ws_send_msg(fd, &req));
            assert_true(ws_send_msg(fd, &cam));
        }
        free(msg);
    }
    assert_true(compared >= 6);
    print_message("%u answers, %u compared with the frame of the same server frame\n", answers, compared);
    /* Over --max-samples: here its message is also over the sample requests' size limit (12 + 56 + 4 x 1000
     * bytes), so it is refused from its header alone (test_strategies' server reaches the count check). */
    static uint8_t many[1001 * 4];
    proto_msg over = request_msg(1, &pose, W, H, many, 1001);
    assert_true(ws_send_msg(fd, &over));
    assert_true(expect_error(fd, FXC_ERR_TOO_LARGE));
    close(fd);
    /* An image over --max-res (default 3840x2160). */
    fd = ws_connect(sv.port);
    assert_true(ws_send_msg(fd, &hello));
    assert_true(read_welcome(fd, &w));
    proto_msg huge = request_msg(1, &pose, 4000, H, pixels, 10);
    assert_true(ws_send_msg(fd, &huge));
    assert_true(expect_error(fd, FXC_ERR_LIMIT));
    close(fd);
    /* A flood: over the bucket of --camera-rate (240) requests. */
    fd = ws_connect(sv.port);
    assert_true(ws_send_msg(fd, &hello));
    assert_true(read_welcome(fd, &w));
    proto_msg small = request_msg(1, &pose, W, H, pixels, 4);
    bool sent = true;
    for (int i = 0; i < 400 && sent; i++)
        sent = ws_send_msg(fd, &small);
    assert_true(expect_error(fd, FXC_ERR_LIMIT));
    close(fd);
    assert_int_equal(server_stop(&sv), 0);
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
    assert_true(ws_send_msg(fd, cam));
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
    server sv;
    char record_dir[512];
    snprintf(record_dir, sizeof record_dir, "%s", fxt_tmp_path("strategies_rec"));
    const char *args[] = {"--fps", "20",       "--effects", "shadow,ao", "--max-samples",
                          "1000",  "--record", record_dir,  NULL};
    server_start(&sv, "strategies", args);
    /* A request over --max-samples whose message is within --max-message (65536): refused by its count. */
    int over_fd = ws_connect(sv.port);
    proto_msg plain = hello_msg(W, H, PROTO_CODEC_ZSTD);
    assert_true(ws_send_msg(over_fd, &plain));
    proto_welcome over_welcome;
    assert_true(read_welcome(over_fd, &over_welcome));
    static uint8_t many[1001 * 4];
    proto_msg over = request_msg(1, &over_welcome.camera, W, H, many, 1001);
    assert_true(ws_send_msg(over_fd, &over));
    assert_true(expect_error(over_fd, FXC_ERR_LIMIT));
    close(over_fd);
    /* Unknown: refused before welcome. */
    int fd = ws_connect(sv.port);
    proto_msg hello = hello_msg(W, H, PROTO_CODEC_ZSTD);
    snprintf(hello.u.hello.strategy, sizeof hello.u.hello.strategy, "nearest");
    assert_true(ws_send_msg(fd, &hello));
    assert_true(expect_error(fd, FXC_ERR_RANGE));
    close(fd);
    static const char *const strategies[] = {"", "basic", "fan"};
    for (int s = 0; s < 3; s++) {
        fd = ws_connect(sv.port);
        snprintf(hello.u.hello.strategy, sizeof hello.u.hello.strategy, "%s", strategies[s]);
        assert_true(ws_send_msg(fd, &hello));
        proto_welcome w;
        assert_true(read_welcome(fd, &w));
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
    fd = ws_connect(sv.port);
    snprintf(hello.u.hello.strategy, sizeof hello.u.hello.strategy, "predictive");
    assert_true(ws_send_msg(fd, &hello));
    proto_welcome w;
    assert_true(read_welcome(fd, &w));
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
    assert_true(ws_send_msg(fd, &cam));
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
    assert_int_equal(server_stop(&sv), 0);
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
