/* `fxcache serve` from outside, as users and hostile peers meet it: the real program is started on a free
 * port, and peers connect over loopback.
 *
 *   - a WebSocket peer not written here (Node's ws, tests/peer_ws.js, with zstd decoded by the zstd tool);
 *   - misbehaving clients (garbage bytes, a garbage message, an absurd hello, a camera flood, a camera 1e30 m
 *     out, a client that never reads, a disconnect in the middle of a frame, 200 connect/disconnect cycles)
 *     while two good viewers measure their frame rate: the server stays up, refuses each rule-breaker with an
 *     error message, and the good viewers' rate stays within 20 % of their rate before;
 *   - limits and the token: a hello over the resolution limit, beyond the viewer limit, without the token.
 * The misbehaving peers speak WebSocket by hand (RFC 6455 framing, a few lines) because they must send what
 * no well-behaved library would. Under the sanitizer build the server runs instrumented and must exit 0 on
 * SIGTERM (a leak or an error makes it exit non-zero). */
#include "cli.h"
#include "proto.h"
#include "fxt_serve.h"
#include "test_util.h"

#include <arpa/inet.h>
#include <jansson.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <spawn.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

static proto_msg camera_msg(const proto_welcome *w, uint32_t sequence)
{
    proto_msg m = {.type = PROTO_CAMERA};
    m.u.camera.sequence = sequence;
    m.u.camera.pose = w->camera;
    m.u.camera.pose.position[0] += 0.01 * (sequence % 50); /* moving: the cache keeps working */
    return m;
}

/* ---- a good viewer, in a thread: frames received with their times ---------------------------------------- */

typedef struct good_viewer {
    int port;
    atomic_bool stop;
    double times[20000];
    atomic_int frames;
    bool failed;
    pthread_t thread;
} good_viewer;

static void *good_viewer_run(void *arg)
{
    good_viewer *g = arg;
    int fd = fxt_ws_connect(g->port);
    proto_welcome w;
    proto_msg hello = fxt_hello_msg(64, 36, PROTO_CODEC_ZSTD);
    if (fd < 0 || !fxt_ws_send_msg(fd, &hello) || !fxt_read_welcome(fd, &w)) {
        g->failed = true;
        if (fd >= 0)
            close(fd);
        return NULL;
    }
    uint32_t sequence = 0;
    double next_camera = 0;
    uint8_t rgb[64 * 36 * 3];
    while (!atomic_load(&g->stop)) {
        if (fxt_now_s() >= next_camera) {
            proto_msg cam = camera_msg(&w, sequence++);
            if (!fxt_ws_send_msg(fd, &cam)) {
                g->failed = true;
                break;
            }
            next_camera = fxt_now_s() + 1.0 / 30;
        }
        uint8_t *msg = NULL;
        struct pollfd pfd = {.fd = fd, .events = POLLIN};
        if (poll(&pfd, 1, 10) <= 0)
            continue;
        long n = fxt_ws_recv(fd, &msg, 10);
        proto_msg m;
        if (n < 0 || proto_decode(msg, (size_t)n, &m) != FXC_OK || m.type != PROTO_FRAME ||
            proto_color_decode(m.u.frame.codec, m.u.frame.color, m.u.frame.color_bytes, 64, 36, rgb) !=
                FXC_OK) {
            free(msg);
            g->failed = true;
            break;
        }
        free(msg);
        int k = atomic_load(&g->frames);
        if (k < 20000) {
            g->times[k] = fxt_now_s();
            atomic_store(&g->frames, k + 1);
        }
    }
    close(fd);
    return NULL;
}

/* Frames per second a viewer received in [t0, t1). */
static double rate_in(const good_viewer *g, double t0, double t1)
{
    int count = 0, n = atomic_load((atomic_int *)&g->frames);
    for (int i = 0; i < n; i++)
        count += g->times[i] >= t0 && g->times[i] < t1;
    return count / (t1 - t0);
}

/* ---- misbehaving peers ----------------------------------------------------------------------------------- */

typedef struct misbehaviour_result {
    bool garbage_refused, bad_message_refused, absurd_hello_refused, flood_refused, text_refused, far_refused;
    int cycles_done;
} misbehaviour_result;

static void *never_reader(void *arg)
{
    /* Joins with a big raw frame, sends one camera, and then never reads: its socket buffers fill. */
    int *port = arg;
    int fd = fxt_ws_connect(*port);
    if (fd < 0)
        return (void *)(intptr_t)-1;
    int small = 4096;
    setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
    proto_msg hello = fxt_hello_msg(160, 90, PROTO_CODEC_RAW);
    fxt_ws_send_msg(fd, &hello);
    usleep(200000);
    proto_msg cam = {.type = PROTO_CAMERA};
    cam.u.camera.pose = (proto_pose){.position = {4.3, 2.2, 3.5}, .direction = {-1, -0.3, -1}, .fov_deg = 60};
    fxt_ws_send_msg(fd, &cam);
    return (void *)(intptr_t)fd;
}

static void misbehave(int port, misbehaviour_result *r)
{
    /* Garbage before any handshake. */
    int fd = fxt_tcp_connect(port);
    if (fd >= 0) {
        uint8_t junk[4096];
        for (size_t i = 0; i < sizeof junk; i++)
            junk[i] = (uint8_t)(i * 2654435761u >> 13);
        fxt_write_all(fd, junk, sizeof junk);
        close(fd);
    }
    /* A garbage message after the handshake. */
    fd = fxt_ws_connect(port);
    if (fd >= 0) {
        uint8_t junk[300];
        for (size_t i = 0; i < sizeof junk; i++)
            junk[i] = (uint8_t)(i * 40503u >> 3);
        fxt_ws_send(fd, junk, sizeof junk);
        r->bad_message_refused = fxt_expect_error(fd, FXC_ERR_BAD_MAGIC);
        close(fd);
    }
    r->garbage_refused = true; /* the raw garbage has no answer to check: the server must simply survive */
    /* A hello with an absurd resolution: out of the format's range, so the bytes are written by hand. */
    fd = fxt_ws_connect(port);
    if (fd >= 0) {
        proto_msg hello = fxt_hello_msg(64, 36, PROTO_CODEC_ZSTD);
        uint8_t buf[256];
        size_t n = proto_encode(&hello, buf, sizeof buf, NULL);
        proto_put_u32le(buf + PROTO_HEADER_BYTES + 1,
                        1000000); /* width, after the empty name's length byte */
        fxt_ws_send(fd, buf, n);
        r->absurd_hello_refused = fxt_expect_error(fd, FXC_ERR_RANGE);
        close(fd);
    }
    /* A text message. */
    fd = fxt_ws_connect(port);
    if (fd >= 0) {
        uint8_t frame[] = {0x81, 0x80 | 5, 0, 0, 0, 0, 'h', 'e', 'l', 'l', 'o'};
        fxt_write_all(fd, frame, sizeof frame);
        r->text_refused = fxt_expect_error(fd, FXC_ERR_PROTOCOL);
        close(fd);
    }
    /* A flood of cameras. */
    fd = fxt_ws_connect(port);
    if (fd >= 0) {
        proto_msg hello = fxt_hello_msg(32, 18, PROTO_CODEC_ZSTD);
        proto_welcome w;
        if (fxt_ws_send_msg(fd, &hello) && fxt_read_welcome(fd, &w)) {
            for (uint32_t i = 0; i < 2000; i++) {
                proto_msg cam = camera_msg(&w, i);
                if (!fxt_ws_send_msg(fd, &cam))
                    break;
            }
            r->flood_refused = fxt_expect_error(fd, FXC_ERR_LIMIT);
        }
        close(fd);
    }
    /* A camera 1e30 m out, looking back: finite, so the format carries it, but its rays overflow (it aborted
     * the whole server inside Embree); refused as an invalid camera, that session closed. */
    fd = fxt_ws_connect(port);
    if (fd >= 0) {
        proto_msg hello = fxt_hello_msg(32, 18, PROTO_CODEC_ZSTD);
        proto_welcome w;
        if (fxt_ws_send_msg(fd, &hello) && fxt_read_welcome(fd, &w)) {
            proto_msg cam = {.type = PROTO_CAMERA};
            cam.u.camera.pose =
                (proto_pose){.position = {1e30, 2, 3}, .direction = {-1e29, 0, 0}, .fov_deg = 60};
            fxt_ws_send_msg(fd, &cam);
            r->far_refused = fxt_expect_error(fd, FXC_ERR_CAMERA);
        }
        close(fd);
    }
    /* A disconnect in the middle of a frame: join, ask for frames, read a few bytes of one, reset. */
    fd = fxt_ws_connect(port);
    if (fd >= 0) {
        proto_msg hello = fxt_hello_msg(96, 54, PROTO_CODEC_RAW);
        proto_welcome w;
        if (fxt_ws_send_msg(fd, &hello) && fxt_read_welcome(fd, &w)) {
            proto_msg cam = camera_msg(&w, 0);
            fxt_ws_send_msg(fd, &cam);
            uint8_t part[100];
            fxt_read_exact(fd, part, sizeof part, 20);
        }
        struct linger lg = {1, 0}; /* close with a reset */
        setsockopt(fd, SOL_SOCKET, SO_LINGER, &lg, sizeof lg);
        close(fd);
    }
    /* 200 connect/disconnect cycles, every other one with a hello. */
    for (int i = 0; i < 200; i++) {
        fd = fxt_ws_connect(port);
        if (fd < 0)
            continue;
        if (i % 2) {
            proto_msg hello = fxt_hello_msg(32, 18, PROTO_CODEC_ZSTD);
            fxt_ws_send_msg(fd, &hello);
        }
        close(fd);
        r->cycles_done++;
    }
}

static void test_misbehaving_clients(void **state)
{
    (void)state;
    fxt_server sv;
    /* A frame rate the server keeps with room to spare (cheap effects), so that a slowdown would be the
     * network's doing, not the extra viewers' rendering. */
    const char *args[] = {"--fps", "10", "--effects", "shadow", "--max-viewers", "8", NULL};
    fxt_server_start(&sv, "abuse", args);
    good_viewer *good = calloc(2, sizeof *good);
    for (int i = 0; i < 2; i++) {
        good[i].port = sv.port;
        pthread_create(&good[i].thread, NULL, good_viewer_run, &good[i]);
    }
    /* Warm-up, then the rate without misbehaviour. */
    sleep(2);
    double a0 = fxt_now_s();
    sleep(3);
    double a1 = fxt_now_s();
    pthread_t never;
    int port = sv.port;
    pthread_create(&never, NULL, never_reader, &port);
    misbehaviour_result r = {0};
    double b0 = fxt_now_s();
    misbehave(sv.port, &r);
    void *never_fd;
    pthread_join(never, &never_fd);
    double spent = fxt_now_s() - b0;
    if (spent < 3)
        usleep((useconds_t)((3 - spent) * 1e6));
    double b1 = fxt_now_s();
    assert_true(fxt_server_alive(&sv));
    for (int i = 0; i < 2; i++) {
        atomic_store(&good[i].stop, true);
        pthread_join(good[i].thread, NULL);
    }
    for (int i = 0; i < 2; i++) {
        double before = rate_in(&good[i], a0, a1), during = rate_in(&good[i], b0, b1);
        print_message("good viewer %d: %.1f frames/s before, %.1f while misbehaving peers ran (%.1f s)\n", i,
                      before, during, b1 - b0);
        assert_false(good[i].failed);
        assert_true(before > 5);
        assert_true(during >= 0.8 * before);
    }
    assert_true(r.bad_message_refused);
    assert_true(r.absurd_hello_refused);
    assert_true(r.text_refused);
    assert_true(r.flood_refused);
    assert_true(r.far_refused);
    assert_int_equal(r.cycles_done, 200);
    if ((intptr_t)never_fd >= 0)
        close((int)(intptr_t)never_fd);
    assert_int_equal(fxt_server_stop(&sv), 0);
    free(good);
}

/* Limits and the token: each refusal is an error message with its code, then the close. */
static void test_limits_and_token(void **state)
{
    (void)state;
    fxt_server sv;
    const char *args[] = {"--fps",   "10",      "--max-viewers", "2", "--max-res",
                          "320x240", "--token", "s3cret",        NULL};
    fxt_server_start(&sv, "limits", args);
    /* No token, a wrong token. */
    int fd = fxt_ws_connect(sv.port);
    proto_msg hello = fxt_hello_msg(64, 36, PROTO_CODEC_ZSTD);
    assert_true(fxt_ws_send_msg(fd, &hello));
    assert_true(fxt_expect_error(fd, FXC_ERR_UNAUTHORIZED));
    close(fd);
    fd = fxt_ws_connect(sv.port);
    snprintf(hello.u.hello.token, sizeof hello.u.hello.token, "s3cres");
    assert_true(fxt_ws_send_msg(fd, &hello));
    assert_true(fxt_expect_error(fd, FXC_ERR_UNAUTHORIZED));
    close(fd);
    /* Over the resolution limit. */
    snprintf(hello.u.hello.token, sizeof hello.u.hello.token, "s3cret");
    fd = fxt_ws_connect(sv.port);
    proto_msg big = hello;
    big.u.hello.width = 640;
    assert_true(fxt_ws_send_msg(fd, &big));
    assert_true(fxt_expect_error(fd, FXC_ERR_LIMIT));
    close(fd);
    /* Two viewers fit, the third does not. */
    int keep[2];
    proto_welcome w;
    for (int i = 0; i < 2; i++) {
        keep[i] = fxt_ws_connect(sv.port);
        assert_true(fxt_ws_send_msg(keep[i], &hello));
        assert_true(fxt_read_welcome(keep[i], &w));
        assert_string_equal(w.name, i == 0 ? "viewer_00" : "viewer_01");
    }
    fd = fxt_ws_connect(sv.port);
    assert_true(fxt_ws_send_msg(fd, &hello));
    assert_true(fxt_expect_error(fd, FXC_ERR_LIMIT));
    close(fd);
    /* A camera before hello, and a frame message (not for the server). */
    fd = fxt_ws_connect(sv.port);
    proto_msg cam = camera_msg(&w, 0);
    assert_true(fxt_ws_send_msg(fd, &cam));
    assert_true(fxt_expect_error(fd, FXC_ERR_PROTOCOL));
    close(fd);
    /* The joined viewers still get frames. */
    for (int i = 0; i < 2; i++) {
        assert_true(fxt_ws_send_msg(keep[i], &cam));
        uint8_t *msg = NULL;
        long n = fxt_ws_recv(keep[i], &msg, 60);
        proto_msg m;
        assert_true(n > 0);
        assert_int_equal(proto_decode(msg, (size_t)n, &m), FXC_OK);
        assert_int_equal(m.type, PROTO_FRAME);
        assert_int_equal(m.u.frame.width, 64);
        free(msg);
    }
    /* Stats on request: the run report as JSON text. */
    proto_msg request = {.type = PROTO_STATS_REQUEST};
    assert_true(fxt_ws_send_msg(keep[0], &request));
    bool stats = false;
    for (int i = 0; i < 200 && !stats; i++) {
        uint8_t *msg = NULL;
        long n = fxt_ws_recv(keep[0], &msg, 60);
        proto_msg m;
        assert_true(n > 0);
        assert_int_equal(proto_decode(msg, (size_t)n, &m), FXC_OK);
        if (m.type == PROTO_STATS) {
            char *text = strndup(m.u.stats.json, m.u.stats.json_bytes);
            assert_non_null(strstr(text, "\"frames\""));
            assert_non_null(strstr(text, "\"sharing_ratio\""));
            free(text);
            stats = true;
        }
        free(msg);
    }
    assert_true(stats);
    /* SIGTERM: each gets bye. */
    kill(sv.pid, SIGTERM);
    for (int i = 0; i < 2; i++) {
        bool bye = false;
        for (;;) {
            uint8_t *msg = NULL;
            long n = fxt_ws_recv(keep[i], &msg, 30);
            proto_msg m;
            if (n < 0)
                break;
            if (proto_decode(msg, (size_t)n, &m) == FXC_OK && m.type == PROTO_BYE)
                bye = true;
            free(msg);
        }
        assert_true(bye);
        close(keep[i]);
    }
    assert_int_equal(fxt_server_stop(&sv), 0);
}

/* A token is required beyond loopback; bad option values are refused with one line. */
static void test_options(void **state)
{
    (void)state;
    char err[1024];
    assert_int_equal(fxt_run_cli("serve --bind 0.0.0.0", NULL, 0, err, sizeof err), 2);
    assert_non_null(strstr(err, "--token"));
    static const char *const bad[][2] = {
        {"serve --port 70000", "--port"},
        {"serve --fps 0", "--fps"},
        {"serve --max-viewers 65", "--max-viewers"},
        {"serve --max-res 0x10", "--max-res"},
        {"serve --max-message 10", "--max-message"},
        {"serve --camera-rate 0", "--camera-rate"},
        {"serve --token ''", "--token"},
        {"serve --bogus", "--bogus"},
        {"serve --bias ao=99", "--bias"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        err[0] = 0;
        int rc = fxt_run_cli(bad[i][0], NULL, 0, err, sizeof err);
        if (rc != 2 || !strstr(err, bad[i][1]))
            fail_msg("'%s' gave %d: %s", bad[i][0], rc, err);
    }
    char out[8192];
    assert_int_equal(fxt_run_cli("serve --help", out, sizeof out, NULL, 0), 0);
    assert_non_null(strstr(out, "--record"));

    /* Memory at the limits: 64 viewers at 8192x8192 (36 + 32 bytes a pixel: 4.3 GiB each, 292 GiB) were
     * accepted at start-up and would have failed only as viewers joined; now refused with the figures. The
     * defaults are lowered to the viewers that fit instead: the count that fits, by hand. */
    if (srv_cli_physical_memory() < (200ull << 30)) {
        err[0] = 0;
        assert_int_equal(fxt_run_cli("serve --max-viewers 64 --max-res 8192x8192 --max-samples 1048576", NULL,
                                     0, err, sizeof err),
                         2);
        assert_non_null(strstr(err, "physical memory"));
        assert_non_null(strstr(err, "8192x8192"));
        assert_true(strchr(err, '\n') == strrchr(err, '\n')); /* one line */
    }
    assert_int_equal(srv_cli_viewers_that_fit(1000, 100, 300, 16), 3);
    assert_int_equal(srv_cli_viewers_that_fit(1000, 100, 300, 2), 2);
    assert_int_equal(srv_cli_viewers_that_fit(1000, 800, 300, 16), 0);
    assert_int_equal(srv_cli_viewers_that_fit(1000, 1000, 300, 16), 0);
    assert_int_equal(srv_cli_viewers_that_fit(1000, 0, 0, 5), 5);
}

/* SIGTERM during a long frame (one viewer at 3840x2160 on one thread: many seconds a frame here): the frame
 * is abandoned within a tile, so the server ends with its summary written (interrupted, no frame counted)
 * within a few seconds of the signal, most of it the second it gives the viewer to close. Before, it
 * finished the frame first. */
static void test_sigterm_mid_frame(void **state)
{
    (void)state;
    char summary[1100];
    fxt_tmp_path_copy(summary, sizeof summary, "sigterm_summary.json");
    unlink(summary);
    fxt_server sv;
    const char *args[] = {"--threads", "1", "--fps", "1", "--summary", summary, NULL};
    fxt_server_start(&sv, "sigterm", args);
    int fd = fxt_ws_connect(sv.port);
    assert_true(fd >= 0);
    proto_msg hello = fxt_hello_msg(3840, 2160, PROTO_CODEC_RAW);
    assert_true(fxt_ws_send_msg(fd, &hello));
    proto_welcome w;
    assert_true(fxt_read_welcome(fd, &w));
    proto_msg cam = camera_msg(&w, 0);
    assert_true(fxt_ws_send_msg(fd, &cam));
    usleep(1500000); /* the first frame is under way (a tick at most 1 s after the camera) */
    double t0 = fxt_now_s();
    int status = fxt_server_stop(&sv);
    double took = fxt_now_s() - t0;
    close(fd);
    print_message("stopped %.2f s after SIGTERM in a 3840x2160 frame\n", took);
    assert_int_equal(status, 0);
    assert_true(took < 5.0);
    size_t size = 0;
    char *text = fxt_read_file(summary, &size);
    json_error_t error;
    json_t *sum = json_loadb(text, size, 0, &error);
    free(text);
    assert_non_null(sum);
    assert_true(json_is_true(json_object_get(sum, "interrupted")));
    json_decref(sum);
}

/* --bind resolves to an IPv4 address of this machine or is refused with one line: "::1" made
 * libwebsockets listen on every IPv4 interface (0.0.0.0), with no token since it counted as loopback; a name
 * it could not find ("localhost", a misspelling) left the server without a listening socket while it said
 * "listening on"; a port in use printed four lines. "localhost" now listens on 127.0.0.1. */
static void test_bind_addresses(void **state)
{
    (void)state;
    char err[1024];
    static const char *const bad[][2] = {
        {"serve --bind ::1", "--bind ::1: IPv6 addresses are not supported"},
        {"serve --bind no-such-host.invalid --token t", "not an IPv4 address or a host name with one"},
        {"serve --bind 999.1.1.1 --token t", "not an IPv4 address"},
        {"serve --bind 192.0.2.1 --token t",
         "not an address of this machine"}, /* TEST-NET-1: bound, never sent to */
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        err[0] = 0;
        int rc = fxt_run_cli(bad[i][0], NULL, 0, err, sizeof err);
        if (rc != 2 || !strstr(err, bad[i][1]) || strchr(err, '\n') != strrchr(err, '\n'))
            fail_msg("'%s' gave %d: %s", bad[i][0], rc, err);
    }
    /* a port in use: one line */
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in addr = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    socklen_t len = sizeof addr;
    assert_int_equal(bind(fd, (struct sockaddr *)&addr, sizeof addr), 0);
    assert_int_equal(listen(fd, 1), 0);
    assert_int_equal(getsockname(fd, (struct sockaddr *)&addr, &len), 0);
    char args[128];
    snprintf(args, sizeof args, "serve --port %d", ntohs(addr.sin_port));
    err[0] = 0;
    assert_int_equal(fxt_run_cli(args, NULL, 0, err, sizeof err), 1);
    close(fd);
    if (!strstr(err, "the port is in use") || strchr(err, '\n') != strrchr(err, '\n'))
        fail_msg("'%s': %s", args, err);
    /* localhost: listens on 127.0.0.1 and says so */
    fxt_server sv;
    fxt_server_start(&sv, "bind_localhost", (const char *const[]){"--bind", "localhost", NULL});
    int client = fxt_tcp_connect(sv.port);
    assert_true(client >= 0);
    close(client);
    assert_int_equal(fxt_server_stop(&sv), 0);
}

/* Node's ws client, with zstd decoded by the zstd tool. */
static void test_node_peer(void **state)
{
    (void)state;
    if (system("node --version >/dev/null 2>&1") != 0 || system("zstd --version >/dev/null 2>&1") != 0) {
        print_message("node or zstd is missing (./install-deps.sh installs them): skipped\n");
        skip();
    }
    fxt_server sv;
    const char *args[] = {"--fps", "30", NULL};
    fxt_server_start(&sv, "node", args);
    char cmd[1024];
    snprintf(cmd, sizeof cmd,
             "NODE_PATH=/usr/share/nodejs node '%s/tests/peer_ws.js' ws://127.0.0.1:%d 15 96 54",
             FXC_SOURCE_DIR, sv.port);
    int rc = system(cmd);
    int code = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
    if (code == 77) {
        fxt_server_stop(&sv);
        print_message("Node's ws module is missing (Debian's node-ws): skipped\n");
        skip();
    }
    assert_int_equal(code, 0);
    assert_true(fxt_server_alive(&sv));
    assert_int_equal(fxt_server_stop(&sv), 0);
}

/* Counts the PNG files in a folder. */
static int count_png(const char *dir)
{
    char cmd[1024];
    snprintf(cmd, sizeof cmd, "ls '%s' 2>/dev/null | grep -c '\\.png$'", dir);
    FILE *p = popen(cmd, "r");
    int n = 0;
    if (p && fscanf(p, "%d", &n) != 1)
        n = 0;
    if (p)
        pclose(p);
    return n;
}

/* End to end: 4 fxcache-viewers (zstd, lossless) until SIGTERM stops the fxt_server; then `fxcache sim` replays
 * the traces the server recorded, and every frame a viewer received is the same PNG, byte for byte, as the
 * one sim writes for that frame and viewer. The statistics have one line per frame of the clock. */
static void test_replay_bit_identical(void **state)
{
    (void)state;
#ifndef FXC_VIEWER_BIN
    print_message("fxcache-viewer is not built: skipped\n");
    skip();
#else
    char rec[512], client[512], simdir[512], stats[512], summary[512];
    snprintf(rec, sizeof rec, "%s", fxt_tmp_path("replay_rec"));
    snprintf(client, sizeof client, "%s", fxt_tmp_path("replay_client"));
    snprintf(simdir, sizeof simdir, "%s", fxt_tmp_path("replay_sim"));
    snprintf(stats, sizeof stats, "%s", fxt_tmp_path("replay_stats.jsonl"));
    snprintf(summary, sizeof summary, "%s", fxt_tmp_path("replay_summary.json"));
    char clean[2048];
    snprintf(clean, sizeof clean, "rm -rf '%s' '%s' '%s'", rec, client, simdir);
    assert_int_equal(system(clean), 0);
    fxt_server sv;
    const char *args[] = {"--fps", "30", "--record", rec, "--stats", stats, "--summary", summary, NULL};
    fxt_server_start(&sv, "replay", args);
    char url[64];
    snprintf(url, sizeof url, "ws://127.0.0.1:%d", sv.port);
    const char *argv[] = {FXC_VIEWER_BIN, "--connect", url,       "--viewers", "4",   "--res", "96x54",
                          "--out",        client,      "--quiet", "--timeout", "120", NULL};
    pid_t viewer;
    assert_int_equal(posix_spawn(&viewer, FXC_VIEWER_BIN, NULL, NULL, (char *const *)argv, environ), 0);
    /* Until every viewer has about 20 frames, then SIGTERM in the middle of the session. */
    for (double t0 = fxt_now_s(); count_png(client) < 80 && fxt_now_s() - t0 < 300;)
        usleep(50000);
    assert_true(count_png(client) >= 80);
    assert_int_equal(fxt_server_stop(&sv), 0);
    int status = 0;
    assert_int_equal(waitpid(viewer, &status, 0), viewer);
    assert_true(WIFEXITED(status));
    assert_int_equal(WEXITSTATUS(status), 0); /* the viewers got bye and ended well */
    char cmd[4096];
    snprintf(cmd, sizeof cmd,
             "sim --trace '%s/viewer_00.trace' --trace '%s/viewer_01.trace' --trace '%s/viewer_02.trace' "
             "--trace '%s/viewer_03.trace' --fps 30 --out '%s' --save-every 1 --quiet",
             rec, rec, rec, rec, simdir);
    char err[2048] = "";
    int rc = fxt_run_cli(cmd, NULL, 0, err, sizeof err);
    if (rc != 0)
        fail_msg("sim replay: %d: %s", rc, err);
    /* Every received frame against sim's. */
    snprintf(cmd, sizeof cmd, "cd '%s' && ls *.png", client);
    FILE *list = popen(cmd, "r");
    char name[256];
    int compared = 0, differ = 0;
    while (list && fgets(name, sizeof name, list)) {
        name[strcspn(name, "\n")] = 0;
        snprintf(cmd, sizeof cmd, "cmp -s '%s/%s' '%s/%s'", client, name, simdir, name);
        compared++;
        if (system(cmd) != 0) {
            if (differ++ < 5)
                print_message("differs from sim's: %s\n", name);
        }
    }
    if (list)
        pclose(list);
    print_message("%d frames received, each compared with sim's replay: %d differ\n", compared, differ);
    assert_true(compared >= 80);
    assert_int_equal(differ, 0);
    /* The statistics: one complete line per frame of the clock, as many as the summary counts. */
    FILE *f = fopen(stats, "r");
    assert_non_null(f);
    int lines = 0, c, last = '\n';
    while ((c = fgetc(f)) != EOF) {
        lines += c == '\n';
        last = c;
    }
    fclose(f);
    assert_int_equal(last, '\n');
    json_error_t jerr;
    json_t *sum = json_load_file(summary, 0, &jerr);
    assert_non_null(sum);
    assert_int_equal(json_integer_value(json_object_get(sum, "frames")), lines);
    assert_true(json_is_true(json_object_get(sum, "interrupted")));
    json_t *serve = json_object_get(sum, "serve");
    assert_int_equal(json_integer_value(json_object_get(serve, "viewers_joined")), 4);
    json_decref(sum);
#endif
}

int main(void)
{
    signal(SIGPIPE, SIG_IGN);
    mkdir(FXC_TEST_TMP, 0755);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_options),
        cmocka_unit_test(test_sigterm_mid_frame),
        cmocka_unit_test(test_bind_addresses),
        cmocka_unit_test(test_node_peer),
        cmocka_unit_test(test_limits_and_token),
        cmocka_unit_test(test_replay_bit_identical),
        cmocka_unit_test(test_misbehaving_clients),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
