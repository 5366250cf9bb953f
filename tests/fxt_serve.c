/* Helpers for tests that meet `fxcache serve` from outside (test_serve.c, test_serve_samples.c): the real program
 * started on a free port, and WebSocket peers written by hand (RFC 6455 framing, a few lines) because some
 * must send what no well-behaved library would (fxt_serve.h). */
#include "fxt_serve.h"
#include "test_util.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
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

double fxt_now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- the server process ---------------------------------------------------------------------------------- */

/* Starts `fxcache serve --port 0 ARGS...` with stdout and stderr in files; waits for its address line. */
void fxt_server_start(fxt_server *sv, const char *name, const char *const *args)
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
    for (double t0 = fxt_now_s(); fxt_now_s() - t0 < 120 && !sv->port;) {
        sv->port = fxt_listening_port(sv->out);
        int status;
        if (!sv->port && waitpid(sv->pid, &status, WNOHANG) == sv->pid)
            fail_msg("fxcache serve exited before listening (see %s)", sv->err);
        if (!sv->port)
            usleep(20000);
    }
    assert_true(sv->port > 0);
}

int fxt_listening_port(const char *path)
{
    int port = 0;
    FILE *f = fopen(path, "r");
    char line[256];
    while (f && fgets(line, sizeof line, f)) {
        const char *at = strstr(line, "listening on ws://127.0.0.1:");
        if (at)
            port = atoi(at + strlen("listening on ws://127.0.0.1:"));
    }
    if (f)
        fclose(f);
    return port;
}

int fxt_node_peer_start(const char *script, const char *args, const char *out, pid_t *pid)
{
    char cmd[2048];
    if (system("node --version >/dev/null 2>&1") != 0) {
        print_message("node is missing (./install-deps.sh installs it): skipped\n");
        return 0;
    }
    remove(out); /* a port from an earlier run must not be read */
    snprintf(cmd, sizeof cmd, "NODE_PATH=/usr/share/nodejs exec node '%s/tests/%s' %s > '%s' 2>&1",
             FXC_SOURCE_DIR, script, args, out);
    const char *sh[] = {"/bin/sh", "-c", cmd, NULL};
    assert_int_equal(posix_spawn(pid, "/bin/sh", NULL, NULL, (char *const *)sh, environ), 0);
    int port = 0;
    for (double t0 = fxt_now_s(); fxt_now_s() - t0 < 30 && !port;) {
        port = fxt_listening_port(out);
        if (!port && fxt_file_contains(out, "ws module is missing")) {
            waitpid(*pid, NULL, 0);
            print_message("Node's ws module is missing (Debian's node-ws): skipped\n");
            return 0;
        }
        if (!port)
            usleep(20000);
    }
    assert_true(port > 0);
    return port;
}

bool fxt_file_contains(const char *path, const char *text)
{
    bool found = false;
    FILE *f = fopen(path, "r");
    char line[256];
    while (f && !found && fgets(line, sizeof line, f))
        found = strstr(line, text) != NULL;
    if (f)
        fclose(f);
    return found;
}

/* True while the server process runs. */
bool fxt_server_alive(fxt_server *sv)
{
    int status;
    return waitpid(sv->pid, &status, WNOHANG) == 0;
}

/* Sends SIGTERM and returns the exit status (fails the test when it does not exit within 60 s). */
int fxt_server_stop(fxt_server *sv)
{
    kill(sv->pid, SIGTERM);
    for (double t0 = fxt_now_s(); fxt_now_s() - t0 < 60;) {
        int status;
        if (waitpid(sv->pid, &status, WNOHANG) == sv->pid)
            return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        usleep(20000);
    }
    kill(sv->pid, SIGKILL);
    fail_msg("fxcache serve did not stop within 60 s of SIGTERM");
    return -1;
}

/* ---- WebSocket by hand ---------------------------------------------------------------------------------- */

int fxt_tcp_connect(int port)
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

bool fxt_write_all(int fd, const void *data, size_t len)
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
bool fxt_read_exact(int fd, void *data, size_t len, double timeout)
{
    uint8_t *p = data;
    double t0 = fxt_now_s();
    while (len) {
        struct pollfd pfd = {.fd = fd, .events = POLLIN};
        int left_ms = (int)((timeout - (fxt_now_s() - t0)) * 1000);
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
int fxt_ws_connect(int port)
{
    int fd = fxt_tcp_connect(port);
    if (fd < 0)
        return -1;
    static const char request[] =
        "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n";
    char reply[2048];
    size_t len = 0;
    if (!fxt_write_all(fd, request, sizeof request - 1))
        goto fail;
    while (len < sizeof reply - 1) {
        if (!fxt_read_exact(fd, reply + len, 1, 10))
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
bool fxt_ws_send(int fd, const uint8_t *payload, size_t len)
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
    bool ok = fxt_write_all(fd, head, h) && fxt_write_all(fd, masked, len);
    free(masked);
    return ok;
}

bool fxt_ws_send_msg(int fd, const proto_msg *m)
{
    size_t bound = proto_bound(m);
    uint8_t *buf = malloc(bound ? bound : 1);
    size_t n = buf ? proto_encode(m, buf, bound, NULL) : 0;
    bool ok = n > 0 && fxt_ws_send(fd, buf, n);
    free(buf);
    return ok;
}

/* Receives one whole message (fragments joined, control frames skipped) into *out (malloc'd, caller frees).
 * Returns its length, or -1 on close, error or timeout. */
long fxt_ws_recv(int fd, uint8_t **out, double timeout)
{
    uint8_t *msg = NULL;
    size_t len = 0;
    for (;;) {
        uint8_t h[2];
        if (!fxt_read_exact(fd, h, 2, timeout))
            break;
        uint64_t n = h[1] & 0x7f;
        if (n == 126 || n == 127) {
            uint8_t ext[8];
            size_t e = n == 126 ? 2 : 8;
            if (!fxt_read_exact(fd, ext, e, timeout))
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
        if (!fxt_read_exact(fd, msg + len, n, timeout))
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
bool fxt_expect_error(int fd, int code)
{
    for (;;) {
        uint8_t *msg = NULL;
        long n = fxt_ws_recv(fd, &msg, 20);
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

proto_msg fxt_hello_msg(uint32_t width, uint32_t height, uint8_t codec)
{
    proto_msg m = {.type = PROTO_HELLO};
    m.u.hello.width = width;
    m.u.hello.height = height;
    m.u.hello.fov_deg = 60;
    m.u.hello.codec = codec;
    return m;
}

/* Reads the welcome; its default camera is the camera the viewer then sends. */
bool fxt_read_welcome(int fd, proto_welcome *out)
{
    uint8_t *msg = NULL;
    long n = fxt_ws_recv(fd, &msg, 60);
    if (n < 0)
        return false;
    proto_msg m;
    bool ok = proto_decode(msg, (size_t)n, &m) == FXC_OK && m.type == PROTO_WELCOME;
    if (ok)
        *out = m.u.welcome;
    free(msg);
    return ok;
}
