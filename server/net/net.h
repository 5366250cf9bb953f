/* The networked front end (DESIGN.md stage 8, `fxcache serve`): a libwebsockets server that drives the same
 * engine as `fxcache sim`, with one more sink.
 *
 * Two threads. The calling thread runs the network event loop (libwebsockets is not thread-safe: every lws
 * call but lws_cancel_service() happens there): connections, hello/welcome, cameras, stats requests,
 * encoding and sending frames, errors and byes. The frame thread runs the frame clock at --fps: at each tick
 * it takes the viewers that left out of the loop and the new ones (with their first camera) in, gives every
 * viewer its latest camera, runs srv_loop_frame(), and hands each viewer's finished frame to its connection.
 * The two meet in one mutex-protected table of viewer records; the frame thread wakes the network loop with
 * lws_cancel_service().
 *
 * Latest frame wins: a record holds one finished frame waiting to be sent; a newer one replaces it and the
 * replaced one is counted as dropped. Frames are encoded on the network thread when they are sent, so a
 * dropped frame costs only its copy.
 *
 * Reference-frame strategies (hello's strategy, docs/PROTOCOL.md): the network thread turns each camera
 * message into the camera to render: the reported one (basic), with tan(fov/2) times SRV_FAN_TAN_FACTOR (fan),
 * or the predicted pose / a linear extrapolation (predictive). Frames, traces and the frame message carry the
 * camera rendered.
 *
 * Sample requests (the client render cache's, issue 11): each viewer that sends one gets a second, sparse
 * engine viewer (srv_viewer_set_pixels) of --max-samples entries, added at its first request. The latest
 * request is rendered in the next frame through the shared caches; the answer (one sample per requested
 * entry, in the request's order) waits in an outbox like frames, the newest winning. A session without
 * sample requests renders and sends exactly what it did before.
 *
 * The frame clock starts (frame 0) at the first tick at which some viewer has a camera, and from then on runs
 * a frame at every tick, also with no viewer present, as `fxcache sim` does on a trace's clock. Frame f has
 * time f / fps seconds: the time --record writes, so `fxcache sim --trace DIR/viewer_*.trace --fps F` replays
 * the session frame by frame with the same joins and leaves. */
#ifndef FXC_SERVER_NET_H
#define FXC_SERVER_NET_H

#include "engine.h"
#include "proto.h"
#include "report.h"

#include <signal.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* The fan strategy's widening: tan(fov/2) multiplied by this (Baxter's wider reference frame at the same pixel
 * count), the result capped at SRV_FAN_MAX_FOV degrees. */
#define SRV_FAN_TAN_FACTOR 1.5
#define SRV_FAN_MAX_FOV    170.0

/* The camera rendered for a camera message under a strategy: basic the reported pose; fan that pose widened;
 * predictive the message's predicted pose when it has one, else the reported pose extrapolated linearly from
 * the previous message (previous may be NULL) by latency_s seconds of client time. World coordinates. A
 * helper of the network thread, public for tests. */
proto_pose srv_net_strategy_pose(uint32_t strategy, const proto_camera *c, const proto_pose *previous,
                                 double previous_time, double latency_s);

/* Bytes the network side holds per pixel of a viewer's resolution: two outboxes of colour and depth (3 + 4
 * each), the encoding scratch and the send buffer (the codecs' bounds: at most about 3 + 4 each, rounded
 * up); and per entry of a sample request: two request lists (4 each), two answer outboxes and the send
 * buffer (12 each). With the engine's SRV_VIEWER_BYTES_PER_PIXEL, what a viewer at the limits can take. */
#define SRV_NET_BYTES_PER_PIXEL  32u
#define SRV_NET_BYTES_PER_SAMPLE 44u

/* Configuration; zero fields take the defaults beside them. */
typedef struct srv_net_desc {
    srv_loop *loop;       /* required: the engine (the frame thread drives it) */
    srv_report *report;   /* required: the run report (stats requests read it, on the frame thread) */
    const scene *s;       /* required: world <-> local, the welcome's bounds and default camera */
    const char *bind;     /* address to listen on (default 127.0.0.1) */
    int port;             /* TCP port, 0 = any free port (srv_net_port tells which); -1 = default 7681 */
    const char *token;    /* the access token hello must carry (NULL or "": none) */
    double fps;           /* target frames per second (default 30) */
    uint32_t max_viewers; /* viewers at once (default 16, at most SRV_MAX_VIEWERS) */
    uint32_t max_width, max_height; /* largest resolution a viewer may ask for (default 3840 x 2160) */
    uint32_t max_message;           /* largest message a client may send, bytes (default 65536) */
    uint32_t camera_rate;     /* camera messages per second per viewer (default 240; a burst of one second's
                                   worth is allowed); sample requests have a bucket of their own at this rate */
    uint32_t max_samples;     /* pixels one sample request may ask for (default 65536, at most
                                   PROTO_MAX_SAMPLES); its message may be 56 + 4 x max_samples bytes whatever
                                   max_message says */
    uint32_t hello_timeout_s; /* seconds a connection may take to send hello (default 10) */
    const char *record_dir;   /* write every viewer's rendered cameras as DIR/NAME.trace (NULL: none) */
    uint32_t frames;          /* stop after this many frames of the clock (0: until stopped) */
    volatile sig_atomic_t *stop; /* set non-zero (by a signal handler) to stop cleanly */
    bool progress;               /* a status line on stderr (a terminal) */
} srv_net_desc;

/* Totals of a run (network side). */
typedef struct srv_net_totals {
    uint64_t connections;         /* WebSocket connections accepted */
    uint64_t viewers_joined;      /* hellos accepted */
    uint64_t refused;             /* connections closed with an error message */
    uint64_t refused_by_code[32]; /* by -code (fxc_result), for codes up to 31 */
    uint64_t frames_sent, frames_dropped, bytes_sent;
    uint64_t cameras_received;
    uint64_t sample_requests; /* sample requests received */
    uint64_t
        sample_requests_dropped; /* replaced by a newer one before being rendered, or answered but replaced
                                         before being sent */
    uint64_t samples_sent;       /* answers sent */
    uint64_t samples_pixels;     /* samples in the answers sent */
    double encode_ms;            /* time spent encoding frames */
    uint32_t frames;             /* frames of the clock */
    uint64_t buffer_bytes_peak;  /* per-viewer frame and message buffers, at most at once */
} srv_net_totals;

typedef struct srv_net srv_net;

/* Resolves a --bind address to the IPv4 address the server listens on, in dotted form in numeric (at least
 * 16 bytes): an IPv4 address or a host name with one (localhost), which must be an address of this machine;
 * *loopback says whether it is in 127.0.0.0/8. The listening socket is IPv4 only, so an IPv6 address is
 * refused (libwebsockets listened on every IPv4 interface for "::1", and on none for a name it could not
 * find, while the server said it was listening). False with one line in err. */
bool srv_net_resolve_bind(const char *bind, char *numeric, size_t numeric_cap, bool *loopback, char *err,
                          size_t err_cap);

/* Creates the server and starts listening. Returns FXC_OK and *out, or a code with one line in err (an
 * address that cannot be bound, say). Frames are not produced before srv_net_run. */
fxc_result srv_net_create(const srv_net_desc *desc, srv_net **out, char *err, size_t err_cap);

/* The TCP port the server listens on. */
int srv_net_port(const srv_net *net);

/* The IPv4 address the server listens on, dotted (srv_net_resolve_bind of desc->bind). */
const char *srv_net_address(const srv_net *net);

/* Runs until *desc->stop is set or desc->frames frames were made; then says bye on every connection, waits
 * up to a second for them to close, and closes every trace file. FXC_OK, or FXC_ERR_THREADS / FXC_ERR_IO
 * (a trace could not be written) with one line in err. */
fxc_result srv_net_run(srv_net *net, char *err, size_t err_cap);

void srv_net_get_totals(const srv_net *net, srv_net_totals *out);

/* Frees everything (closes any connection still open). NULL is allowed. */
void srv_net_free(srv_net *net);

#endif
