/* Helpers for tests that meet `fxcache serve` from outside (fxt_serve.c): the server process on a free port,
 * and a WebSocket peer by hand speaking the wire format through proto/. They fail the calling test (cmocka)
 * where a step cannot go on. */
#ifndef FXC_TEST_SERVE_H
#define FXC_TEST_SERVE_H

#include "proto.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

typedef struct fxt_server {
    pid_t pid;
    int port;
    char out[512], err[512];
} fxt_server;

/* Seconds on the monotonic clock. */
double fxt_now_s(void);

/* Starts `fxcache serve --port 0 ARGS...` with stdout and stderr in files; waits for its address line. */
void fxt_server_start(fxt_server *sv, const char *name, const char *const *args);

/* The port of the last "listening on ws://127.0.0.1:PORT" line in the file at path; 0 when none (yet). */
int fxt_listening_port(const char *path);

/* True when a line of the file at path contains text (false when the file is absent). */
bool fxt_file_contains(const char *path, const char *text);

/* Starts a WebSocket peer written by someone else, `node tests/SCRIPT ARGS` (ARGS as the shell reads them) with
 * its output in the file at out, and waits up to 30 s for its "listening on ws://127.0.0.1:PORT" line. Returns
 * the port with *pid the peer's; 0 when node or its ws module is missing (said in a message: the caller
 * skips). Fails the test when no port comes. */
int fxt_node_peer_start(const char *script, const char *args, const char *out, pid_t *pid);

/* True while the server process runs. */
bool fxt_server_alive(fxt_server *sv);

/* Sends SIGTERM and returns the exit status (fails the test when it does not exit within 60 s). */
int fxt_server_stop(fxt_server *sv);

/* A TCP connection to 127.0.0.1:port; -1 on failure. */
int fxt_tcp_connect(int port);

/* Writes all of data (false on an error or a closed peer). */
bool fxt_write_all(int fd, const void *data, size_t len);

/* Reads exactly len bytes within timeout seconds. */
bool fxt_read_exact(int fd, void *data, size_t len, double timeout);

/* Connects and completes the opening handshake; -1 on failure. */
int fxt_ws_connect(int port);

/* Sends one binary message as a masked client frame. */
bool fxt_ws_send(int fd, const uint8_t *payload, size_t len);

/* Encodes m (proto_encode) and sends it as one binary message. */
bool fxt_ws_send_msg(int fd, const proto_msg *m);

/* Receives one whole message (fragments joined, control frames skipped) into *out (malloc'd, caller frees).
 * Returns its length, or -1 on close, error or timeout. */
long fxt_ws_recv(int fd, uint8_t **out, double timeout);

/* Waits for the server's error message and the close: true when one came with this code (0: any code). */
bool fxt_expect_error(int fd, int code);

/* A hello of that size and codec (fov 60, no name, token or strategy). */
proto_msg fxt_hello_msg(uint32_t width, uint32_t height, uint8_t codec);

/* Reads the welcome; its default camera is the camera the viewer then sends. */
bool fxt_read_welcome(int fd, proto_welcome *out);

#endif
