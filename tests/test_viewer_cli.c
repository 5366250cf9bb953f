/* fxcache-viewer through its real entry point: the program of this build is started as a user starts it
 * (fork and exec, no shell) and judged by its exit status and what it prints.
 *  - every kind of bad option: exit 2, nothing on stdout, exactly one line on stderr naming the option and
 * the value; the same for a bad $FXCACHE_TOKEN, an unreadable or invalid --trace, an --out that is a file;
 *  - --help: exit 0, every option of the table and the defaults;
 *  - no server at the port: exit 1, one line per viewer, the summary, and --stats JSON saying both failed;
 *  - a server that accepts the connection but never answers: --timeout gives up (exit 1), and SIGTERM ends
 * the run cleanly (exit 0, summary, --stats written) without waiting for the timeout. Runs against a real
 * server come with the server (`fxcache serve`). The program is built only once the wire format's
 * implementation is in the tree (viewer_client/CMakeLists.txt); until then every test here skips. */
#include "test_util.h"

#include "fxt_serve.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <jansson.h>
#include <netinet/in.h>
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

/* What one run of the program gave. */
typedef struct viewer_run {
    int status;      /* exit status, or -1 when it did not exit normally */
    char out[16384]; /* stdout (truncated) */
    char err[16384]; /* stderr (truncated) */
    double seconds;  /* how long it ran */
} viewer_run;

/* How to run it. */
typedef struct run_how {
    const char *token_env; /* $FXCACHE_TOKEN for the program (NULL: unset) */
    double signal_after_s; /* send `signal_number` after this long (0: never) */
    int signal_number;
    int ready_fd; /* > 0: and not before this listening socket has a connection waiting (the program
                     is past its start, its signal handlers in place, even on a loaded machine) */
} run_how;

#ifdef FXC_VIEWER_BIN
static double now_seconds(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec / 1e9;
}

static void read_file_into(const char *path, char *buf, size_t cap)
{
    buf[0] = 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        return;
    size_t n = fread(buf, 1, cap - 1, f);
    buf[n] = 0;
    fclose(f);
}
#endif

/* Starts fxcache-viewer with args (NULL-terminated, without the program name), waits for it (at most 60 s,
 * then kills it and fails the test), and fills *r. Skips the test when the program is not built. */
static void run_viewer(const char *const *args, const run_how *how, viewer_run *r)
{
#ifndef FXC_VIEWER_BIN
    (void)args, (void)how, (void)r;
    print_message(
        "SKIP: fxcache-viewer is not built (proto/proto.c and proto/proto_codec.c are not in the tree)\n");
    skip();
#else
    static const run_how plain = {.token_env = NULL};
    if (!how)
        how = &plain;
    char out_path[1024], err_path[1024];
    snprintf(out_path, sizeof out_path, "%s", fxt_tmp_path("viewer_stdout.txt"));
    snprintf(err_path, sizeof err_path, "%s", fxt_tmp_path("viewer_stderr.txt"));
    const char *argv[64];
    int argc = 0;
    argv[argc++] = FXC_VIEWER_BIN;
    for (; args[argc - 1]; argc++) {
        assert_true(argc < 63);
        argv[argc] = args[argc - 1];
    }
    argv[argc] = NULL;
    double start = now_seconds();
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        int in = open("/dev/null", O_RDONLY), out = open(out_path, O_WRONLY | O_CREAT | O_TRUNC, 0644),
            err = open(err_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (in < 0 || out < 0 || err < 0)
            _exit(126);
        dup2(in, 0);
        dup2(out, 1);
        dup2(err, 2);
        if (how->token_env)
            setenv("FXCACHE_TOKEN", how->token_env, 1);
        else
            unsetenv("FXCACHE_TOKEN");
        execv(FXC_VIEWER_BIN, (char *const *)argv);
        _exit(127);
    }
    bool signalled = false;
    int wstatus = 0;
    for (;;) {
        pid_t done = waitpid(pid, &wstatus, WNOHANG);
        assert_true(done >= 0);
        if (done == pid)
            break;
        double elapsed = now_seconds() - start;
        bool ready = true;
        if (how->ready_fd > 0) {
            struct pollfd pfd = {.fd = how->ready_fd, .events = POLLIN};
            ready = poll(&pfd, 1, 0) > 0;
        }
        if (how->signal_after_s > 0 && !signalled && elapsed >= how->signal_after_s && ready) {
            kill(pid, how->signal_number);
            signalled = true;
        }
        if (elapsed > 60) {
            kill(pid, SIGKILL);
            waitpid(pid, &wstatus, 0);
            fail_msg("fxcache-viewer did not end within 60 s");
        }
        struct timespec pause = {0, 10 * 1000 * 1000};
        nanosleep(&pause, NULL);
    }
    r->seconds = now_seconds() - start;
    r->status = WIFEXITED(wstatus) ? WEXITSTATUS(wstatus) : -1;
    read_file_into(out_path, r->out, sizeof r->out);
    read_file_into(err_path, r->err, sizeof r->err);
#endif
}

/* Counts the lines of text (each ending in '\n'); a last line without one counts too. */
static int line_count(const char *text)
{
    int lines = 0;
    for (const char *c = text; *c; c++)
        lines += *c == '\n';
    size_t len = strlen(text);
    return lines + (len > 0 && text[len - 1] != '\n');
}

/* Each refusal: the arguments, and what its one line must contain (besides the program name). */
static void test_bad_options(void **state)
{
    (void)state;
    static const struct {
        const char *args[8];
        const char *expected;
    } cases[] = {
        {{"--viewers", "0"}, "--viewers 0: must be a whole number in 1..64"},
        {{"--viewers", "65"}, "--viewers 65:"},
        {{"--viewers", "1.5"}, "--viewers 1.5:"},
        {{"--viewers=-2"}, "--viewers -2:"},
        {{"--frames", "-3"}, "--frames -3:"},
        {{"--frames", "ten"}, "--frames ten:"},
        {{"--connect", "http://127.0.0.1:7681"}, "--connect http://127.0.0.1:7681: the scheme must be ws://"},
        {{"--connect", "wss://example.org:443"}, "--connect wss://example.org:443:"},
        {{"--connect", "127.0.0.1:7681"}, "--connect 127.0.0.1:7681: expected ws://HOST:PORT"},
        {{"--connect", "ws://127.0.0.1"}, "--connect ws://127.0.0.1: no port"},
        {{"--connect", "ws://127.0.0.1:0"}, "--connect ws://127.0.0.1:0: the port must be"},
        {{"--connect", "ws://127.0.0.1:65536"}, "--connect ws://127.0.0.1:65536: the port must be"},
        {{"--connect", "ws://127.0.0.1:76a"}, "--connect ws://127.0.0.1:76a: the port must be"},
        {{"--connect", "ws://:7681"}, "--connect ws://:7681: no host"},
        {{"--connect", "ws://a b:7681"}, "--connect ws://a b:7681: the host"},
        {{"--connect", "ws://[::1:7681"}, "--connect ws://[::1:7681: an IPv6 address needs its closing ']'"},
        {{"--res", "640"}, "--res 640: expected WIDTHxHEIGHT"},
        {{"--res", "640x0"}, "--res 640x0:"},
        {{"--res", "8193x10"}, "--res 8193x10:"},
        {{"--fov", "0"}, "--fov 0: must be a number of degrees strictly between 0 and 180"},
        {{"--fov", "180"}, "--fov 180:"},
        {{"--fov", "nan"}, "--fov nan:"},
        {{"--fps", "0"}, "--fps 0:"},
        {{"--fps", "1001"}, "--fps 1001:"},
        {{"--fps", "inf"}, "--fps inf:"},
        {{"--codec", "png"}, "--codec png: must be raw, zstd or jpeg"},
        {{"--codec", "jpeg", "--quality", "101"}, "--quality 101: must be a whole number in 1..100"},
        {{"--quality", "50"}, "--quality 50: only --codec jpeg has a quality"},
        {{"--depth", "24"}, "--depth 24: must be none, 16 or 32"},
        {{"--latency", "10001"}, "--latency 10001:"},
        {{"--timeout", "0"}, "--timeout 0:"},
        {{"--timeout", "-1"}, "--timeout -1:"},
        {{"--camera", "spiral"}, "--camera spiral: must be orbit or static"},
        {{"--name", "a-name-of-thirty-letters-long0"},
         "--name a-name-of-thirty-letters-long0: must be 1..29"},
        {{"--viewers", "11", "--name", "a-name-of-29-letters-is-long0"},
         "--name a-name-of-29-letters-is-long0: the name "
         "a-name-of-29-letters-is-long0_10 is longer"},
        {{"--name", ""}, "--name :"},
        {{"--token", "0123456789012345678901234567890123456789012345678901234567890123456789"}, "--token:"},
        {{"--bogus"}, "--bogus: unknown option"},
        {{"stray"}, "stray: unexpected argument"},
        {{"--trace"}, "--trace: needs a value"},
        {{"--quiet=yes"}, "--quiet=yes: takes no value"},
        {{"--trace", "a.trace", "--camera", "static"}, "--camera static: the cameras come from --trace"},
        {{"--trace", "a.trace", "--fps", "30"},
         "--fps 30: cameras from --trace are sent at the trace's own times"},
        {{"--viewers", "3", "--trace", "a.trace", "--trace", "b.trace"}, "--viewers 3: 2 traces given"},
        /* The display clock and the render cache. */
        {{"--display-fps", "0"}, "--display-fps 0: must be a number above 0, at most 1000"},
        {{"--display-fps", "1000.5"}, "--display-fps 1000.5:"},
        {{"--display-out", ""}, "--display-out '': needs a folder"},
        {{"--reproject", "--rc-threads", "0"}, "--rc-threads 0: must be a whole number in 1..64"},
        {{"--reproject", "--rc-threads", "65"}, "--rc-threads 65:"},
        {{"--reproject", "--sample-budget", "-1"}, "--sample-budget -1: must be a whole number of pixels"},
        {{"--reproject", "--res", "64x32", "--sample-budget", "2049"},
         "--sample-budget 2049: more than the 64x32 image's 2048 pixels"},
        {{"--strategy", "ahead"}, "--strategy ahead: must be basic, fan or predictive"},
        {{"--strategy", "fan"}, "--strategy fan: only with --reproject"},
        {{"--no-prefilter"}, "--no-prefilter: only with --reproject"},
        {{"--no-prediction"}, "--no-prediction: only with --reproject"},
        {{"--no-eviction"}, "--no-eviction: only with --reproject"},
        {{"--no-tiling"}, "--no-tiling: only with --reproject"},
        {{"--sample-budget", "10"}, "--sample-budget: only with --reproject"},
        {{"--rc-threads", "2"}, "--rc-threads 2: only with --reproject"},
        {{"--reproject", "--depth", "none"}, "--depth none: --reproject needs depth"},
        {{"--reproject=yes"}, "--reproject=yes: takes no value"},
        {{"--time-scale", "0.5"}, "--time-scale 0.5: must be a number from 1 to 1000"},
        {{"--time-scale", "1001"}, "--time-scale 1001:"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        viewer_run r;
        run_viewer(cases[i].args, NULL, &r);
        char expected[512];
        snprintf(expected, sizeof expected, "fxcache-viewer: %s", cases[i].expected);
        if (r.status != 2 || strncmp(r.err, expected, strlen(expected)) != 0 || line_count(r.err) != 1 ||
            r.out[0])
            fail_msg(
                "case %zu (%s ...): exit %d, stdout '%s', stderr '%s'; expected exit 2 and one line starting "
                "'%s'",
                i, cases[i].args[0], r.status, r.out, r.err, expected);
    }

    /* $FXCACHE_TOKEN is checked as --token is, and named. */
    const char *none[] = {NULL};
    run_how bad_token = {.token_env = "tab\there"};
    viewer_run r;
    run_viewer(none, &bad_token, &r);
    assert_int_equal(r.status, 2);
    assert_int_equal(line_count(r.err), 1);
    assert_non_null(strstr(r.err, "fxcache-viewer: FXCACHE_TOKEN: the token must be"));
}

/* Files named by options are checked before any connection: a trace that does not read, an --out that is a
 * file. */
static void test_bad_files(void **state)
{
    (void)state;
    char bad_trace[1024], good_trace[1024], plain_file[1024];
    snprintf(bad_trace, sizeof bad_trace, "%s",
             fxt_write_file("bad.trace", "fxcache-trace 2\n# one camera\n0 0 0 0 1 0 0 0\n"));
    snprintf(good_trace, sizeof good_trace, "%s",
             fxt_write_file("good.trace", "fxcache-trace 1\n0 0 1 0 0 0 -1 60\n"));
    snprintf(plain_file, sizeof plain_file, "%s", fxt_write_file("not_a_folder", "x"));
    viewer_run r;
    char expected[2048];

    const char *trace_args[] = {"--trace", good_trace, "--trace", bad_trace, NULL};
    run_viewer(trace_args, NULL, &r);
    snprintf(expected, sizeof expected, "fxcache-viewer: --trace: %s:3: fov_deg 0 is outside (0, 180)\n",
             bad_trace);
    assert_int_equal(r.status, 2);
    assert_string_equal(r.err, expected);

    const char *missing_args[] = {"--trace", "/nonexistent/walk.trace", NULL};
    run_viewer(missing_args, NULL, &r);
    assert_int_equal(r.status, 2);
    assert_string_equal(r.err,
                        "fxcache-viewer: --trace: /nonexistent/walk.trace: cannot open: No such file or "
                        "directory\n");

    const char *out_args[] = {"--trace", good_trace, "--out", plain_file, NULL};
    run_viewer(out_args, NULL, &r);
    snprintf(expected, sizeof expected, "fxcache-viewer: --out %s: cannot create the folder:", plain_file);
    assert_int_equal(r.status, 2);
    assert_int_equal(line_count(r.err), 1);
    assert_true(strncmp(r.err, expected, strlen(expected)) == 0);
}

/* --help lists every option and the defaults, on stdout, and exits 0. */
static void test_help(void **state)
{
    (void)state;
    const char *args[] = {"--viewers", "3", "--help", NULL};
    viewer_run r;
    run_viewer(args, NULL, &r);
    assert_int_equal(r.status, 0);
    assert_string_equal(r.err, "");
    static const char *const mentions[] = {
        "--connect ws://HOST:PORT",
        "--viewers N",
        "--frames N",
        "--trace FILE",
        "--camera orbit|static",
        "--fps F",
        "--res WxH",
        "--fov DEG",
        "--codec raw|zstd|jpeg",
        "--quality Q",
        "--depth none|16|32",
        "--token T",
        "FXCACHE_TOKEN",
        "--name PREFIX",
        "--out DIR",
        "frame_FFFF_NAME.png",
        "--latency MS",
        "--stats FILE",
        "--timeout S",
        "--quiet",
        "--display-fps F",
        "default 30",
        "--display-out DIR",
        "display_NNNNN_NAME.png",
        "--reproject",
        "--no-prediction",
        "--no-prefilter",
        "--no-eviction",
        "--no-tiling",
        "--rc-threads N",
        "--sample-budget N",
        "--strategy basic|fan|predictive",
        "--time-scale S",
        "--help",
        "ws://127.0.0.1:7681",
        "640x360",
        "default zstd",
        "default 85",
        "1..64",
        "240 cameras",
        "SIGINT",
        "Exit status",
    };
    for (size_t i = 0; i < sizeof mentions / sizeof mentions[0]; i++)
        if (!strstr(r.out, mentions[i]))
            fail_msg("--help does not mention '%s'", mentions[i]);
}

/* A local port nobody listens on: bound, then closed. */
static uint16_t closed_port(void)
{
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    assert_true(fd >= 0);
    struct sockaddr_in address = {.sin_family = AF_INET, .sin_port = 0};
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    assert_int_equal(bind(fd, (struct sockaddr *)&address, sizeof address), 0);
    socklen_t len = sizeof address;
    assert_int_equal(getsockname(fd, (struct sockaddr *)&address, &len), 0);
    close(fd);
    return ntohs(address.sin_port);
}

/* A local port that accepts connections (the kernel completes them) but never answers: the WebSocket
 * handshake waits forever. Returns the listening socket; *port its port. */
static int silent_listener(uint16_t *port)
{
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    assert_true(fd >= 0);
    struct sockaddr_in address = {.sin_family = AF_INET, .sin_port = 0};
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    assert_int_equal(bind(fd, (struct sockaddr *)&address, sizeof address), 0);
    assert_int_equal(listen(fd, 16), 0);
    socklen_t len = sizeof address;
    assert_int_equal(getsockname(fd, (struct sockaddr *)&address, &len), 0);
    *port = ntohs(address.sin_port);
    return fd;
}

/* Accepts and closes every connection waiting on a listener (those of an earlier run). */
static void drain(int listener)
{
    for (;;) {
        struct pollfd pfd = {.fd = listener, .events = POLLIN};
        if (poll(&pfd, 1, 0) <= 0)
            return;
        int fd = accept(listener, NULL, NULL);
        if (fd < 0)
            return;
        close(fd);
    }
}

/* Reads the --stats file and checks the number of viewers and failures. */
static json_t *load_stats(const char *path, size_t viewers, int failed)
{
    json_error_t error;
    json_t *root = json_load_file(path, 0, &error);
    if (!root)
        fail_msg("%s:%d: %s", path, error.line, error.text);
    assert_int_equal(json_array_size(json_object_get(root, "viewers")), viewers);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(root, "total"), "failed")), failed);
    return root;
}

/* No server: each viewer fails with one line of its own, the run exits 1 with its summary and statistics. */
static void test_no_server(void **state)
{
    (void)state;
    char url[64], stats[1024];
    snprintf(url, sizeof url, "ws://127.0.0.1:%u", closed_port());
    snprintf(stats, sizeof stats, "%s", fxt_tmp_path("no_server.json"));
    const char *args[] = {"--connect", url, "--viewers", "2", "--stats", stats, NULL};
    viewer_run r;
    run_viewer(args, NULL, &r);
    assert_int_equal(r.status, 1);
    assert_int_equal(line_count(r.err), 2);
    for (int i = 0; i < 2; i++) {
        char expected[128];
        snprintf(expected, sizeof expected, "fxcache-viewer: viewer %d: cannot connect to %s", i, url);
        if (!strstr(r.err, expected))
            fail_msg("stderr lacks '%s': %s", expected, r.err);
    }
    assert_non_null(strstr(r.out, "2 viewers on ws://127.0.0.1:"));
    assert_non_null(strstr(r.out, "2 failed"));
    json_t *root = load_stats(stats, 2, 2);
    json_t *first = json_array_get(json_object_get(root, "viewers"), 0);
    assert_true(json_is_true(json_object_get(first, "failed")));
    assert_non_null(strstr(json_string_value(json_object_get(first, "error")), "cannot connect"));
    json_decref(root);

    /* --quiet: the same failures, no summary. */
    const char *quiet_args[] = {"--connect", url, "--quiet", NULL};
    run_viewer(quiet_args, NULL, &r);
    assert_int_equal(r.status, 1);
    assert_string_equal(r.out, "");
    assert_int_equal(line_count(r.err), 1);
}

/* A misbehaving server (tests/peer_bad_server.js, Node's ws, the wire format written by hand): for each way it
 * misbehaves the viewer either ends with exactly one line naming what went wrong (exit 1, --quiet) or goes on
 * to its frames (exit 0), within seconds, and never with a sanitizer's report. The empty message was a
 * memcpy from a NULL buffer (UBSan: "null pointer passed as argument 1") before its first message. */
static void test_misbehaving_server(void **state)
{
    (void)state;
#ifndef FXC_VIEWER_BIN
    print_message("SKIP: fxcache-viewer is not built\n");
    skip();
#else
    static const struct {
        const char *mode;
        int status;
        const char *says; /* in the one line (status 1) */
    } cases[] = {
        {"empty", 1, "does not decode: message truncated (0 bytes)"},
        {"text", 1, "sent a text message"},
        {"wrong_type", 1, "unknown message type"},
        {"len_more", 1, "message truncated"},
        {"len_less", 1, "trailing bytes"},
        {"frame_first", 1, "before its welcome"},
        {"welcome_twice", 1, "does not expect now"},
        {"nan_camera", 1, "value out of range"},
        {"stall", 1, "no frame for 1 s"},
        {"unasked", 0, NULL},
        {"slow_clock", 1, "no frame for 1 s"}, /* was "server error: a flood" */
        {"tiny_fps", 1, "no frame for 1 s"},
        {"bad_payload", 1, "3 of 3 frames did not decode"}, /* was exit 0 */
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char out[512];
        snprintf(out, sizeof out, "%s", fxt_tmp_path("bad_server.out"));
        pid_t fake;
        int port = fxt_node_peer_start("peer_bad_server.js", cases[i].mode, out, &fake);
        if (!port) {
            skip(); /* fxt_node_peer_start said why */
        }
        char url[64];
        snprintf(url, sizeof url, "ws://127.0.0.1:%d", port);
        const char *args[] = {"--connect", url, "--res",     "16x9", "--codec", "raw",
                              "--frames",  "3", "--timeout", "1",    "--quiet", NULL};
        char stats[1024];
        snprintf(stats, sizeof stats, "%s", fxt_tmp_path("bad_server.json"));
        remove(stats);
        const char *reproject_args[] = {"--connect", url,           "--res",   "16x9",      "--codec",
                                        "raw",       "--frames",    "3",       "--timeout", "1",
                                        "--quiet",   "--reproject", "--stats", stats,       NULL};
        const char *slow_args[] = {"--connect", url,      "--res",         "16x9", "--codec", "raw",
                                   "--frames",  "2",      "--timeout",     "1",    "--quiet", "--reproject",
                                   "--fps",     "1e-300", "--display-fps", "100",  NULL};
        viewer_run r;
        bool slow = strcmp(cases[i].mode, "slow_clock") == 0 || strcmp(cases[i].mode, "tiny_fps") == 0;
        if (slow && strcmp(cases[i].mode, "tiny_fps") == 0)
            slow_args[12] = NULL; /* the welcome's fps, not --fps */
        run_viewer(slow                                    ? slow_args
                   : strcmp(cases[i].mode, "unasked") == 0 ? reproject_args
                                                           : args,
                   NULL, &r);
        kill(fake, SIGTERM);
        waitpid(fake, NULL, 0);
        print_message("%-13s exit %d in %.1f s: %s", cases[i].mode, r.status, r.seconds,
                      r.err[0] ? r.err : "\n");
        if (strstr(r.err, "runtime error") || strstr(r.err, "AddressSanitizer"))
            fail_msg("%s: a sanitizer's report: %s", cases[i].mode, r.err);
        if (r.status != cases[i].status)
            fail_msg("%s: exit %d, expected %d: %s", cases[i].mode, r.status, cases[i].status, r.err);
        assert_true(r.seconds < 20);
        if (cases[i].status == 1) {
            assert_int_equal(line_count(r.err), 1);
            if (!strstr(r.err, "fxcache-viewer: viewer 0: ") || !strstr(r.err, cases[i].says))
                fail_msg("%s: stderr lacks '%s': %s", cases[i].mode, cases[i].says, r.err);
        } else {
            assert_string_equal(r.err, "");
        }
        if (strcmp(cases[i].mode, "unasked") == 0) {
            /* The answers to a request never sent are refused and counted, not inserted or counted as answers. */
            json_t *root = load_stats(stats, 1, 0);
            json_t *rc = json_object_get(json_array_get(json_object_get(root, "viewers"), 0), "render_cache");
            assert_int_equal(json_integer_value(json_object_get(rc, "requests_answered")), 0);
            assert_int_equal(json_integer_value(json_object_get(rc, "samples_received")), 0);
            assert_true(json_integer_value(json_object_get(rc, "insert_errors")) >= 1);
            json_decref(root);
        }
    }
#endif
}

/* A server that never answers: --timeout gives up on every viewer; SIGTERM ends the wait at once, cleanly. */
static void test_timeout_and_signal(void **state)
{
    (void)state;
    uint16_t port;
    int listener = silent_listener(&port);
    char url[64], stats[1024];
    snprintf(url, sizeof url, "ws://127.0.0.1:%u", port);
    snprintf(stats, sizeof stats, "%s", fxt_tmp_path("timeout.json"));

    const char *timeout_args[] = {"--connect", url, "--viewers", "3", "--timeout", "0.5", NULL};
    viewer_run r;
    run_viewer(timeout_args, NULL, &r);
    assert_int_equal(r.status, 1);
    assert_int_equal(line_count(r.err), 3);
    assert_non_null(strstr(r.err, "fxcache-viewer: viewer 2: no connection within 0.5 s"));
    assert_true(r.seconds < 20);

    /* SIGTERM long before the (default 60 s) timeout: exit 0, the summary, the statistics, no failure. */
    const char *signal_args[] = {"--connect", url, "--viewers", "2", "--stats", stats, NULL};
    drain(listener);
    run_how term = {.signal_after_s = 1.0, .signal_number = SIGTERM, .ready_fd = listener};
    run_viewer(signal_args, &term, &r);
    if (r.status != 0)
        fail_msg("exit %d after SIGTERM; stderr: %s", r.status, r.err);
    assert_true(r.seconds < 8);
    assert_string_equal(r.err, "");
    assert_non_null(strstr(r.out, "2 viewers on ws://127.0.0.1:"));
    json_decref(load_stats(stats, 2, 0));

    /* SIGINT the same. */
    drain(listener);
    run_how interrupt = {.signal_after_s = 1.0, .signal_number = SIGINT, .ready_fd = listener};
    run_viewer(signal_args, &interrupt, &r);
    assert_int_equal(r.status, 0);
    close(listener);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_bad_options),
        cmocka_unit_test(test_bad_files),
        cmocka_unit_test(test_help),
        cmocka_unit_test(test_no_server),
        cmocka_unit_test(test_timeout_and_signal),
        cmocka_unit_test(test_misbehaving_server),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
