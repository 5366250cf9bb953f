/* The networked server's private parts (net.c: the connections; net_frames.c: the frame thread): the viewer
 * records both threads share under srv_net's lock, the sessions, and the server itself. */
#ifndef FXC_NET_INTERNAL_H
#define FXC_NET_INTERNAL_H

#include "net.h"

#include "proto.h"
#include "trace.h"

#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>
#include <time.h>

struct lws;
struct lws_context;

enum {
    FRAGMENT_BYTES = 128 * 1024, /* a frame goes out in WebSocket fragments of at most this size */
    MAX_PENDING_CONNECTIONS = 32 /* connections that have not sent hello yet, beyond max_viewers */
};

/* A viewer record's life: FREE -> JOINING (hello accepted) -> ACTIVE (in the loop, from its first camera's
 * frame) -> LEAVING (its connection is gone; the frame thread takes it out of the loop) -> FREE. */
typedef enum viewer_state { VS_FREE = 0, VS_JOINING, VS_ACTIVE, VS_LEAVING } viewer_state;

typedef struct net_viewer {
    viewer_state state;
    uint32_t index; /* join number: the name is viewer_NN */
    char name[PROTO_NAME_MAX + 1];
    proto_hello hello;
    proto_strategy strategy; /* hello's reference-frame strategy */
    /* The latest camera (network thread writes, frame thread reads): the one rendered, after the strategy. */
    bool has_camera;
    srv_camera camera;
    uint32_t camera_sequence;
    /* The last camera message (network thread only): predictive extrapolates from it to the next. */
    bool has_previous;
    double previous_time;
    proto_pose previous_pose;
    /* Sample requests (issue 11). The network thread writes the pending one; the frame thread hands it to
     * the viewer's sparse engine viewer (added at its first request), renders it, and stages the answer. */
    uint32_t *req_pixels[2]; /* request order, packed y << 16 | x: [req_pending_index] pending, the
                                       other the one being rendered (max_samples each) */
    int req_pending_index;
    bool req_pending, req_rendering;
    uint32_t req_id[2], req_count[2], req_width[2], req_height[2];
    srv_camera req_camera[2];
    srv_viewer_id sample_id; /* the sparse engine viewer, 0 until the first request */
    /* The answer outbox: as frames, two buffers (frame thread fills ans_index, network thread takes it). */
    uint8_t *ans[2]; /* count x PROTO_SAMPLE_BYTES */
    int ans_index;
    bool ans_ready;
    uint32_t ans_request, ans_frame, ans_count, ans_width, ans_height;
    srv_camera ans_camera;
    uint64_t requests_dropped;
    /* In the loop (frame thread). */
    srv_viewer_id id;
    uint32_t frame_sequence; /* the camera sequence of the frame being rendered */
    srv_trace_writer *trace;
    int fail_code; /* the frame thread could not add it: the network thread says so */
    /* The outbox: one finished frame (frame thread fills buffer out_index, network thread takes it). */
    uint8_t *rgb[2];
    float *depth[2];
    int out_index;
    bool staged, ready;
    uint32_t out_frame, out_sequence;
    srv_camera out_camera;
    srv_viewer_stats out_stats;
    float out_frame_ms;
    uint64_t dropped;
    /* Stats on request: the frame thread writes the JSON text, the network thread sends it. */
    bool stats_requested;
    char *stats_json;
    size_t buffer_bytes;
} net_viewer;

/* Per connection (network thread only; lws allocates and frees it). */
typedef struct net_session {
    struct lws *wsi;
    struct net_session *next; /* every open session, for the byes at shutdown */
    net_viewer *viewer;       /* after hello */
    uint8_t *rx;              /* the message being received */
    size_t rx_len, rx_cap;
    bool rx_bad; /* refusing the rest of this message */
    uint8_t *tx; /* LWS_PRE + the message being sent */
    size_t tx_len, tx_off, tx_cap;
    int tx_encoding_buffer; /* the outbox buffer encoded into tx, -1 none */
    uint8_t *scratch;       /* encoded payloads */
    size_t scratch_cap;
    bool welcome_pending;
    int error_code; /* != 0: send this error, then close */
    char error_reason[PROTO_REASON_MAX + 1];
    bool bye_pending, closing;
    double tokens, tokens_time;               /* the camera-rate bucket */
    double sample_tokens, sample_tokens_time; /* the sample requests' bucket (the same rate) */
    bool counted;                             /* counted among pending (pre-hello) connections */
} net_session;

struct srv_net {
    srv_net_desc d;
    struct lws_context *context;
    int port;
    char address[64]; /* d.bind resolved: the IPv4 address listened on, dotted */
    pthread_mutex_t lock;
    net_viewer viewers[SRV_MAX_VIEWERS];
    net_viewer *by_slot[256]; /* viewer id slot -> record (frame thread) */
    uint32_t next_index;
    net_session *sessions;
    uint32_t pending_connections;
    atomic_bool stopping; /* the frame thread finished: say bye */
    bool byes_sent;
    double stop_deadline;
    bool clock_started;
    uint32_t frame;
    double origin[3];
    srv_net_totals totals; /* under lock */
    uint64_t buffer_bytes; /* under lock */
    double frame_ms;       /* the last frame's time (under lock): predictive's latency */
    fxc_result frame_error;
    char frame_error_text[256];
    volatile sig_atomic_t no_signal; /* the stop flag when the description gives none */
};

static inline double srv__net_now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Adds delta to the server's buffer bytes (under lock) and keeps the peak. */
static inline void srv__net_count_buffers(srv_net *net, int64_t delta)
{
    net->buffer_bytes = (uint64_t)((int64_t)net->buffer_bytes + delta);
    if (net->buffer_bytes > net->totals.buffer_bytes_peak)
        net->totals.buffer_bytes_peak = net->buffer_bytes;
}

/* ---- the frame thread (net_frames.c) ---- */

/* Frees a viewer record's buffers and clears it (FREE), counting its buffers out. */
void srv__net_free_viewer(srv_net *net, net_viewer *v);
/* The engine's sink callbacks: a viewer's finished frame into its outbox; the end of a frame. */
int srv__net_viewer_frame(void *user, const srv_viewer_frame *vf);
int srv__net_frame_done(void *user, const srv_frame_stats *stats);
/* The frame clock: takes joining and leaving viewers, runs the loop at the server's rate, stages answers
 * and statistics, wakes the network thread; sets `stopping` at the end. arg: the srv_net. */
void *srv__net_frame_thread(void *arg);

#endif
