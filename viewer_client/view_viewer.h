/* The viewer client's state, shared by its session (view_client.c: the state machine on libwebsockets, the
 * cameras, the messages) and its display (view_display.c: the display clock, the render cache and its sample
 * requests). Nothing outside viewer_client/ includes this. */
#ifndef VIEW_VIEWER_H
#define VIEW_VIEWER_H

#include "view_client.h"

#include "rcache.h"

#include <libwebsockets.h>

#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

enum {
    RC_CAPACITY_FRAMES = 4,     /* the render cache keeps this many whole frames' worth of points (below) */
    REQUEST_MAX_PIXELS = 65536, /* pixels in one sample request: a server's default --max-samples */
    SENT_RING = 4096,           /* sequences whose send time is remembered (older frames get no latency) */
    TX_BYTES = 1024,            /* the largest message a viewer sends (hello, camera, bye), without LWS_PRE */
    RX_CHUNK = 65536,           /* libwebsockets' receive buffer per read */
    HOUSEKEEPING_US = 100000,   /* the housekeeping timer's period */
    CLOSE_GRACE_US = 2000000,   /* a closing viewer is cut off after this long */
};

typedef enum viewer_state {
    VIEWER_CONNECTING,
    VIEWER_HELLO,
    VIEWER_STREAMING,
    VIEWER_CLOSING,
    VIEWER_DONE
} viewer_state;

/* A camera generated and waiting to be sent. */
typedef struct pending_camera {
    lws_usec_t generated_us; /* when it was generated (latency counts from here) */
    double camera_s;         /* the camera's own time after the welcome: its trace line's, or index / fps */
    lws_usec_t send_us;      /* generated + --latency */
    proto_pose pose;
} pending_camera;

/* A message received (a frame, or the samples answering a request) and held until it counts as shown: its
 * bytes are copied into a buffer of the viewer's pool and decoded again when it is shown. */
typedef struct held_frame {
    lws_usec_t shown_us;  /* received + --latency */
    lws_usec_t camera_us; /* when its camera was generated; 0 = no latency sample for this frame */
    double camera_s;      /* its camera's own time (pending_camera.camera_s); NaN when not known */
    uint32_t sequence;    /* the camera sequence it echoes */
    uint32_t bytes;       /* its message's size */
    uint32_t type;        /* PROTO_FRAME, or the samples answering a sample request */
    uint32_t buffer;      /* its bytes: a buffer of the viewer's held pool */
} held_frame;

/* A message waiting to be sent (a sample request held for --latency): encoded behind LWS_PRE bytes of
 * headroom in a buffer of the viewer's out pool. */
typedef struct queued_message {
    lws_usec_t send_us;
    uint32_t buffer;
    uint32_t bytes; /* without LWS_PRE */
    uint32_t pixels;
} queued_message;

/* Byte buffers that grow and are reused through a LIFO free list (CONVENTIONS.md 5): only as many are ever
 * allocated as are in use at once, and each grows only when a message is larger than any before it. */
typedef struct buffer_pool {
    uint8_t **bytes;
    size_t *cap;
    uint32_t *free; /* stack of free indices */
    uint32_t count, free_count;
} buffer_pool;

typedef struct view_client view_client;

typedef struct view_viewer {
    view_client *client;
    uint32_t index;
    struct lws *wsi; /* NULL when there is no connection */
    viewer_state state;
    lws_sorted_usec_list_t tick; /* the viewer's one timer */
    const proto_trace *trace;    /* NULL: the generator */
    uint32_t width, height;      /* asked for in the hello */
    lws_usec_t started_us;       /* the connection attempt began */
    lws_usec_t welcome_us;       /* the welcome arrived: cameras' clock starts */
    proto_welcome welcome;
    double fps; /* cameras per second (generator) */

    /* cameras */
    bool hello_pending, bye_pending, bye_sent;
    char bye_reason[PROTO_REASON_MAX + 1];
    lws_usec_t closing_deadline_us;
    uint32_t generated;          /* cameras due so far (generator index, or trace lines) */
    lws_usec_t next_generate_us; /* when the next is due; 0 = no more (trace ended) */
    pending_camera *pending;     /* ring of pending_capacity */
    uint32_t pending_capacity, pending_head, pending_count;
    uint32_t next_sequence;                  /* the next camera's sequence */
    lws_usec_t sent_generated_us[SENT_RING]; /* by sequence % SENT_RING */
    double sent_camera_s[SENT_RING];         /* ... and the camera's own time */
    lws_usec_t first_camera_us;              /* the first camera went out (0: none yet) */
    bool trace_all_sent;                     /* every trace line has been sent */
    uint32_t last_sequence;         /* the sequence of the trace's last camera (valid with trace_all_sent) */
    uint32_t latency_next_sequence; /* frames echoing a sequence below this add no latency sample */

    proto_pose last_sent_pose; /* the previous camera sent, and when it was generated (prediction) */
    lws_usec_t last_sent_generated_us;
    double rtt_ms; /* round trip: a camera generated to its first frame shown, smoothed (prediction) */
    bool rtt_measured;

    /* frames and samples, held for --latency */
    held_frame *held; /* ring of held_capacity */
    uint32_t held_capacity, held_head, held_count;
    uint32_t held_frames; /* frame messages among them */
    buffer_pool held_pool;
    lws_usec_t last_frame_rx_us; /* the last frame message arrived */
    lws_usec_t last_shown_us;
    uint8_t *rx; /* the message being received */
    size_t rx_len, rx_cap, rx_limit;
    bool rx_in_message; /* part of a message has arrived; the rest is to come */
    bool rx_binary, rx_header_checked;
    uint8_t *rgb; /* decoded colour, rgb_cap bytes */
    size_t rgb_cap;
    float *depth; /* decoded depth, depth_cap floats */
    size_t depth_cap;
    uint8_t tx[LWS_PRE + TX_BYTES];

    /* the display clock */
    lws_sorted_usec_list_t display_tick;
    uint64_t display_index; /* the next display frame */
    uint8_t *display_rgb;   /* the last frame shown (without --reproject), width x height */
    bool display_has_frame;
    int64_t display_frame;         /* the server's number of the last frame shown (-1: none) */
    double display_frame_camera_s; /* its camera's own time (NaN: not known) */
    proto_pose display_previous;   /* the previous display frame's camera (prediction) */
    double display_previous_s;
    bool display_has_previous;
    FILE *display_trace, *display_csv;  /* --display-out */
    char file_name[PROTO_NAME_MAX + 1]; /* the welcome's name, as a file name part */

    /* the render cache (--reproject) and its sample requests */
    view_rc *rc;
    view_rc_sample *samples; /* a samples message converted for view_rc_insert_samples */
    uint32_t samples_cap;
    uint32_t next_request;      /* the next sample request's number */
    lws_usec_t last_request_us; /* the last sample request was made (0: none yet) */
    uint8_t *request_pixels;    /* REQUEST_MAX_PIXELS entries of proto_request_pixel_put */
    queued_message *out;        /* ring of out_capacity: requests waiting for --latency */
    uint32_t out_capacity, out_head, out_count;
    buffer_pool out_pool;

    bool goal_reached; /* ended by its own rule (frames, trace end, interrupt): a bye from the
                          server after that is no failure */
    view_viewer_stats *stats;
} view_viewer;

struct view_client {
    const view_options *options;
    const proto_trace *traces;
    double trace_origin; /* the earliest first time of all traces */
    struct lws_context *context;
    view_viewer *viewers;
    uint32_t count;
    lws_usec_t start_us;
    lws_sorted_usec_list_t housekeeping;
    bool stopping; /* every viewer was told to end (a signal) */
    bool rate_warned;
    bool progress;       /* progress goes to stderr (a terminal, not --quiet) */
    bool progress_shown; /* a progress line is on the terminal now */
    lws_usec_t progress_us;
    uint64_t progress_frames;
};

/* ---- view_client.c ------------------------------------------------------------------------------------ */

/* Sets up a pool of count buffers (none allocated yet). */
bool view__pool_init(buffer_pool *p, uint32_t count);

/* A free buffer of at least size bytes; UINT32_MAX when none is free or memory ran out. */
uint32_t view__pool_take(buffer_pool *p, size_t size);

void view__pool_give(buffer_pool *p, uint32_t i);

void view__pool_free(buffer_pool *p);

/* Ends a viewer with a failure: one line on stderr and in its statistics (the first failure is kept). */
void view__fail(view_viewer *v, const char *fmt, ...);

/* The next moment the viewer's timer must wake it: the next camera to generate, the next pending camera not
 * yet due, the next held frame. Due pending cameras wait for the writeable callback instead. */
void view__schedule(view_viewer *v, lws_usec_t now);

/* Ends a viewer: a bye (when it was welcomed and the connection is up), then the close handshake; a
 * connection still being made is dropped. reason goes into the bye. */
void view__stop(view_viewer *v, const char *reason);

/* Shows the held messages whose time (received + --latency) is not after `until`: frames count, give their
 * latency and go to the display or the render cache, samples go to the render cache; ends the viewer when it
 * has shown --frames frames or a frame for its trace's last camera. */
void view__show_frames(view_viewer *v, lws_usec_t until);

/* ---- view_display.c ----------------------------------------------------------------------------------- */

/* A frame whose time has come: decoded (a payload that does not decode is counted, not fatal), written with
 * --out, then inserted into the render cache (--reproject) or kept as the display's image. Returns false when
 * the viewer had to stop. */
bool view__use_frame(view_viewer *v, const proto_frame *frame, double camera_s);

/* The round trip the prediction assumes: measured (camera generated to its first frame shown, smoothed), else
 * until the first measurement both --latency delays and a frame of the server's clock. */
double view__rtt_ms(const view_viewer *v);

/* One display frame: the messages due by its time shown, the camera at its time, the render cache's frame
 * (and its requests sent) or the last frame received, its figures, --display-out. Display frame k is at
 * welcome + k / --display-fps; a clock that fell behind skips to the newest due frame. */
void view__display(view_viewer *v, lws_usec_t now);

/* True when the oldest queued sample request is due to be sent. */
bool view__request_due(const view_viewer *v, lws_usec_t now);

/* Sends the oldest queued sample request. Returns 0, or -1 (after recording the failure). */
int view__send_request(view_viewer *v);

/* A samples message shown: its samples inserted into the render cache with the camera the server says it
 * rendered them for. */
void view__use_samples(view_viewer *v, const proto_msg *msg);

/* The display's buffers, the render cache (--reproject), the --display-out files. false after recording the
 * failure. */
bool view__display_setup(view_viewer *v);

/* ---- timing ------------------------------------------------------------------------------------------- */

/* --time-scale: every duration of the session (trace times, camera and display rates, --latency) runs this
 * many times slower on the wall clock; "scene" times are the session's own. */
static inline double view__time_scale(const view_viewer *v)
{
    return v->client->options->time_scale;
}

/* The wall-clock moment of scene time t (seconds after the welcome). */
static inline lws_usec_t view__wall_us(const view_viewer *v, double t)
{
    /* Saturated at 1e15 us (31 years, a moment no run reaches): a clock of --fps 1e-300, or a welcome's fps of
     * 1e-30, puts its next camera 1e300 s away, and that converted to int64 wrapped into the past, so cameras
     * went out as fast as the loop ran. */
    double us = ceil(t * 1e6 * view__time_scale(v));
    us = us < 1e15 ? (us > -1e15 ? us : -1e15) : 1e15;
    return v->welcome_us + (lws_usec_t)us;
}

/* Scene seconds after the welcome at wall-clock moment now. */
static inline double view__scene_s(const view_viewer *v, lws_usec_t now)
{
    return (double)(now - v->welcome_us) / 1e6 / view__time_scale(v);
}

/* --latency in wall-clock microseconds. */
static inline lws_usec_t view__latency_us(const view_viewer *v)
{
    return (lws_usec_t)llround(v->client->options->latency_ms * 1000.0 * view__time_scale(v));
}

#endif
