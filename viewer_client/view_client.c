/* The viewer client's session (view_client.h): the viewers' state machine on libwebsockets.
 *
 * A viewer goes CONNECTING -> HELLO (connected; hello queued, welcome awaited) -> STREAMING (cameras out,
 * frames in) -> CLOSING (bye queued, then the close handshake) -> DONE. A failure anywhere records one line,
 * prints it, and closes that viewer; the session ends when every viewer is DONE.
 *
 * Time is lws_now_usecs() (monotonic, microseconds). Cameras: a generated camera waits in the viewer's
 * pending ring until it is due (generated + --latency), then the writeable callback sends the newest due one
 * (older due ones are skipped: the server renders only the latest). Its sequence number is given when it is
 * sent, and the time it was generated is kept in a ring by sequence, so a frame's echoed sequence gives its
 * latency. Frames: each one taken is decoded at once, then held in a ring until received + --latency, when it
 * counts as shown. Rings are allocated once per viewer (at the welcome, sized from the rates and the delay),
 * never per frame. */
#include "view_client.h"

#include "rcache.h"
#include "view_camera.h"
#include "view_image.h"

#include <libwebsockets.h>

#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

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

/* Sets up a pool of count buffers (none allocated yet). */
static bool pool_init(buffer_pool *p, uint32_t count)
{
    p->bytes = calloc(count, sizeof *p->bytes);
    p->cap = calloc(count, sizeof *p->cap);
    p->free = calloc(count, sizeof *p->free);
    if (!p->bytes || !p->cap || !p->free)
        return false;
    p->count = p->free_count = count;
    for (uint32_t i = 0; i < count; i++)
        p->free[i] = count - 1 - i; /* buffer 0 is taken first */
    return true;
}

/* A free buffer of at least size bytes; UINT32_MAX when none is free or memory ran out. */
static uint32_t pool_take(buffer_pool *p, size_t size)
{
    if (!p->free_count)
        return UINT32_MAX;
    uint32_t i = p->free[p->free_count - 1];
    if (p->cap[i] < size) {
        uint8_t *grown = realloc(p->bytes[i], size);
        if (!grown)
            return UINT32_MAX;
        p->bytes[i] = grown;
        p->cap[i] = size;
    }
    p->free_count--;
    return i;
}

static void pool_give(buffer_pool *p, uint32_t i)
{
    p->free[p->free_count++] = i;
}

static void pool_free(buffer_pool *p)
{
    for (uint32_t i = 0; i < p->count; i++)
        free(p->bytes ? p->bytes[i] : NULL);
    free(p->bytes);
    free(p->cap);
    free(p->free);
    memset(p, 0, sizeof *p);
}

typedef struct view_client view_client;

static void viewer_tick(lws_sorted_usec_list_t *sul);
static void viewer_display_tick(lws_sorted_usec_list_t *sul);

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

/* ---- signals ------------------------------------------------------------------------------------------ */

static volatile sig_atomic_t interrupted;
static struct lws_context *volatile signal_context;

/* Async-signal-safe: a flag, and a wake-up of the service loop (lws_cancel_service writes to a pipe). */
static void on_signal(int signal_number)
{
    (void)signal_number;
    interrupted = 1;
    if (signal_context)
        lws_cancel_service(signal_context);
}

/* ---- messages to the user ------------------------------------------------------------------------------ */

/* Clears a progress line before anything else is printed on stderr. */
static void clear_progress(view_client *c)
{
    if (c->progress_shown) {
        fputs("\r\033[K", stderr);
        c->progress_shown = false;
    }
}

/* Ends a viewer with a failure: one line on stderr and in its statistics (the first failure is kept). */
static void viewer_fail(view_viewer *v, const char *fmt, ...)
{
    if (v->stats->failed)
        return;
    va_list args;
    va_start(args, fmt);
    vsnprintf(v->stats->error, sizeof v->stats->error, fmt, args);
    va_end(args);
    v->stats->failed = true;
    clear_progress(v->client);
    fprintf(stderr, "fxcache-viewer: viewer %u: %s\n", v->index, v->stats->error);
}

/* ---- timing ------------------------------------------------------------------------------------------- */

/* --time-scale: every duration of the session (trace times, camera and display rates, --latency) runs this
 * many times slower on the wall clock; "scene" times are the session's own. */
static double time_scale(const view_viewer *v)
{
    return v->client->options->time_scale;
}

/* The wall-clock moment of scene time t (seconds after the welcome). */
static lws_usec_t wall_us(const view_viewer *v, double t)
{
    return v->welcome_us + (lws_usec_t)ceil(t * 1e6 * time_scale(v));
}

/* Scene seconds after the welcome at wall-clock moment now. */
static double scene_s(const view_viewer *v, lws_usec_t now)
{
    return (double)(now - v->welcome_us) / 1e6 / time_scale(v);
}

static lws_usec_t latency_us(const view_viewer *v)
{
    return (lws_usec_t)llround(v->client->options->latency_ms * 1000.0 * time_scale(v));
}

/* The next moment the viewer's timer must wake it: the next camera to generate, the next pending camera not
 * yet due, the next held frame. Due pending cameras wait for the writeable callback instead. */
static void viewer_schedule(view_viewer *v, lws_usec_t now)
{
    lws_usec_t next = 0;
    if (v->state == VIEWER_STREAMING) {
        if (v->next_generate_us)
            next = v->next_generate_us;
        if (v->pending_count) {
            lws_usec_t send = v->pending[v->pending_head].send_us;
            if (send > now && (!next || send < next))
                next = send;
        }
        if (v->held_count) {
            lws_usec_t shown = v->held[v->held_head].shown_us;
            if (!next || shown < next)
                next = shown;
        }
        if (v->out_count) {
            lws_usec_t send = v->out[v->out_head].send_us;
            if (send > now && (!next || send < next))
                next = send;
        }
    }
    if (!next) {
        lws_sul_cancel(&v->tick);
        return;
    }
    lws_sul_schedule(v->client->context, 0, &v->tick, viewer_tick, next > now ? next - now : 1);
}

/* ---- ending a viewer ---------------------------------------------------------------------------------- */

/* Asks libwebsockets to drop a connection now (without a close handshake). */
static void viewer_kill(view_viewer *v)
{
    if (v->wsi)
        lws_set_timeout(v->wsi, PENDING_TIMEOUT_USER_OK, LWS_TO_KILL_ASYNC);
}

/* Ends a viewer: a bye (when it was welcomed and the connection is up), then the close handshake; a
 * connection still being made is dropped. reason goes into the bye. */
static void viewer_stop(view_viewer *v, const char *reason)
{
    lws_usec_t now = lws_now_usecs();
    switch (v->state) {
    case VIEWER_CONNECTING:
        viewer_kill(v);
        if (!v->wsi)
            v->state = VIEWER_DONE;
        break;
    case VIEWER_HELLO:
    case VIEWER_STREAMING:
        v->state = VIEWER_CLOSING;
        snprintf(v->bye_reason, sizeof v->bye_reason, "%s", reason);
        /* A hello not yet sent needs no bye: the connection just closes. */
        v->bye_pending = !v->hello_pending;
        v->hello_pending = false;
        v->closing_deadline_us = now + CLOSE_GRACE_US;
        lws_sul_cancel(&v->tick);
        lws_sul_cancel(&v->display_tick);
        lws_callback_on_writable(v->wsi);
        break;
    case VIEWER_CLOSING:
    case VIEWER_DONE:
        break;
    }
}

/* The connection is gone: the viewer's figures are final. */
static void viewer_closed(view_viewer *v)
{
    v->wsi = NULL;
    v->state = VIEWER_DONE;
    lws_sul_cancel(&v->tick);
    lws_sul_cancel(&v->display_tick);
    if (v->last_shown_us > v->welcome_us && v->welcome_us)
        v->stats->seconds = (double)(v->last_shown_us - v->welcome_us) / 1e6;
}

/* ---- cameras ------------------------------------------------------------------------------------------ */

/* Generates the camera due now, if one is (only the newest when several are: a stalled loop does not
 * burst), and queues it for sending at generated + --latency. */
static void viewer_generate(view_viewer *v, lws_usec_t now)
{
    const view_options *o = v->client->options;
    if (!v->next_generate_us || now < v->next_generate_us)
        return;
    double elapsed = scene_s(v, now);
    uint32_t due;
    if (v->trace) {
        due = view_trace_due(v->trace, v->client->trace_origin, elapsed);
    } else {
        double count = floor(elapsed * v->fps) + 1;
        due = count > 4e9 ? 4000000000u : (uint32_t)count;
    }
    if (due <= v->generated)
        due = v->generated + 1; /* the timer fired a hair early by the float clock: this one is due */
    uint32_t index = due - 1;
    v->stats->cameras_skipped += index - v->generated;
    v->generated = due;
    pending_camera cam = {.generated_us = now, .send_us = now + latency_us(v)};
    if (v->trace) {
        cam.pose = view_camera_from_trace(v->trace, index, o->fov_deg);
        cam.camera_s = v->trace->times[index] - v->client->trace_origin;
        v->next_generate_us =
            due < v->trace->count ? wall_us(v, v->trace->times[due] - v->client->trace_origin) : 0;
    } else {
        cam.pose =
            view_camera_generate(o->camera, &v->welcome, v->index, v->client->count, index, o->fov_deg);
        cam.camera_s = (double)index / v->fps;
        v->next_generate_us = wall_us(v, (double)due / v->fps);
    }
    if (v->pending_count == v->pending_capacity) { /* the oldest waiting camera gives way */
        v->pending_head = (v->pending_head + 1) % v->pending_capacity;
        v->pending_count--;
        v->stats->cameras_skipped++;
    }
    v->pending[(v->pending_head + v->pending_count) % v->pending_capacity] = cam;
    v->pending_count++;
}

/* True when the oldest pending camera is due to be sent. */
static bool camera_due(const view_viewer *v, lws_usec_t now)
{
    return v->pending_count && v->pending[v->pending_head].send_us <= now;
}

/* ---- frames ------------------------------------------------------------------------------------------- */

/* A file name part from the server's name for the viewer: letters, digits, '-', '_' and '.' kept, anything
 * else '_' (a name is printable ASCII but may hold '/'). */
static void file_name_part(const char *name, char *out, size_t cap)
{
    size_t n = 0;
    for (; name[n] && n + 1 < cap; n++) {
        char ch = name[n];
        bool keep = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') ||
                    ch == '-' || ch == '_' || ch == '.';
        out[n] = keep ? ch : '_';
    }
    out[n] = 0;
}

/* Makes room for w x h pixels of colour (and depth): grows the buffers only when a frame is larger than any
 * before. */
static bool viewer_pixels(view_viewer *v, uint32_t width, uint32_t height, bool depth)
{
    size_t pixels = (size_t)width * height; /* both <= PROTO_MAX_SIDE: no overflow */
    if (pixels * 3 > v->rgb_cap) {
        uint8_t *grown = realloc(v->rgb, pixels * 3);
        if (!grown)
            return false;
        v->rgb = grown;
        v->rgb_cap = pixels * 3;
    }
    if (depth && pixels > v->depth_cap) {
        float *grown = realloc(v->depth, pixels * sizeof *grown);
        if (!grown)
            return false;
        v->depth = grown;
        v->depth_cap = pixels;
    }
    return true;
}

static view_rc_camera rc_camera(const proto_pose *pose)
{
    view_rc_camera cam;
    for (int k = 0; k < 3; k++) {
        cam.position[k] = pose->position[k];
        cam.direction[k] = pose->direction[k];
    }
    cam.fov_deg = pose->fov_deg;
    return cam;
}

/* A frame whose time has come: decoded (a payload that does not decode is counted, not fatal), written with
 * --out, then inserted into the render cache (--reproject) or kept as the display's image. Returns false when
 * the viewer had to stop. */
static bool viewer_use_frame(view_viewer *v, const proto_frame *frame, double camera_s)
{
    const view_options *o = v->client->options;
    bool with_depth = frame->depth != PROTO_DEPTH_NONE;
    if (!viewer_pixels(v, frame->width, frame->height, with_depth)) {
        viewer_fail(v, "out of memory for a %ux%u frame", frame->width, frame->height);
        viewer_stop(v, "client out of memory");
        return false;
    }
    bool decoded = proto_color_decode(frame->codec, frame->color, frame->color_bytes, frame->width,
                                      frame->height, v->rgb) == FXC_OK;
    if (decoded && with_depth)
        decoded = proto_depth_decode(frame->depth, frame->depth_data, frame->depth_bytes, frame->width,
                                     frame->height, v->depth) == FXC_OK;
    if (!decoded) {
        v->stats->decode_errors++;
        return true;
    }
    if (o->out_dir) {
        char path[4096], msg[512];
        snprintf(path, sizeof path, "%s/frame_%04u_%s.png", o->out_dir, frame->frame, v->file_name);
        if (view_image_write_png(path, frame->width, frame->height, v->rgb, msg, sizeof msg) != 0) {
            viewer_fail(v, "cannot write the frame: %s", msg);
            viewer_stop(v, "client cannot write frames");
            return false;
        }
    }
    view_display_stats *d = &v->stats->display;
    if (v->rc) {
        view_rc_camera cam = rc_camera(&frame->camera);
        if (!with_depth ||
            view_rc_insert_frame(v->rc, &cam, frame->width, frame->height, v->rgb, v->depth) != FXC_OK) {
            d->insert_errors++;
            return true;
        }
        d->frames_inserted++;
    } else {
        if (frame->width != v->width || frame->height != v->height) {
            d->insert_errors++; /* not the size asked for: it cannot be the display's image */
            return true;
        }
        memcpy(v->display_rgb, v->rgb, (size_t)frame->width * frame->height * 3);
        v->display_has_frame = true;
    }
    v->display_frame = frame->frame;
    v->display_frame_camera_s = camera_s;
    return true;
}

static void viewer_use_samples(view_viewer *v, const proto_msg *msg);

/* Shows the held messages whose time (received + --latency) is not after `until`: frames count, give their
 * latency and go to the display or the render cache, samples go to the render cache; ends the viewer when it
 * has shown --frames frames or a frame for its trace's last camera. */
static void viewer_show_frames(view_viewer *v, lws_usec_t until)
{
    const view_options *o = v->client->options;
    while (v->held_count && v->held[v->held_head].shown_us <= until && v->state == VIEWER_STREAMING) {
        held_frame f = v->held[v->held_head];
        v->held_head = (v->held_head + 1) % v->held_capacity;
        v->held_count--;
        proto_msg msg;
        /* It decoded when it arrived: the same bytes decode again. */
        bool ok = proto_decode(v->held_pool.bytes[f.buffer], f.bytes, &msg) == FXC_OK;
        if (f.type != PROTO_FRAME) { /* the samples answering a request */
            if (ok)
                viewer_use_samples(v, &msg);
            pool_give(&v->held_pool, f.buffer);
            continue;
        }
        v->held_frames--;
        v->stats->frames++;
        v->stats->frame_bytes += f.bytes;
        v->last_shown_us = f.shown_us;
        v->client->progress_frames++;
        bool going = ok && viewer_use_frame(v, &msg.u.frame, f.camera_s);
        pool_give(&v->held_pool, f.buffer);
        if (!going)
            return;
        if (f.camera_us) {
            double ms = (double)(f.shown_us - f.camera_us) / 1000.0 / time_scale(v); /* scene ms */
            /* The round trip the prediction uses: smoothed as TCP smooths its RTT (gain 1/8). */
            v->rtt_ms = v->rtt_measured ? v->rtt_ms + (ms - v->rtt_ms) / 8 : ms;
            v->rtt_measured = true;
            if (!view_latency_add(&v->stats->latency, ms)) {
                viewer_fail(v, "out of memory for latency samples");
                viewer_stop(v, "client out of memory");
                return;
            }
        }
        if (o->frames && v->stats->frames >= o->frames) {
            v->goal_reached = true;
            viewer_stop(v, "done: frames shown");
        } else if (v->trace_all_sent && f.sequence >= v->last_sequence) {
            v->goal_reached = true;
            viewer_stop(v, "done: the trace ended");
        }
    }
}

/* A frame or samples message: its bytes copied and held until received + --latency, when it counts as shown
 * (and is decoded again, used, and its buffer given back). */
static void viewer_take_message(view_viewer *v, const proto_msg *msg, lws_usec_t now)
{
    const view_options *o = v->client->options;
    held_frame held = {.shown_us = now + latency_us(v),
                       .bytes = v->rx_len > UINT32_MAX ? UINT32_MAX : (uint32_t)v->rx_len,
                       .type = msg->type};
    if (msg->type == PROTO_FRAME) {
        const proto_frame *frame = &msg->u.frame;
        v->last_frame_rx_us = now;
        if (o->frames && v->stats->frames + v->held_frames >= o->frames)
            return; /* enough frames are on their way to being shown */
        held.sequence = frame->camera_sequence;
        /* Latency once per camera: the first frame for it, or for a newer one; only for cameras really sent.
         */
        uint32_t seq = frame->camera_sequence;
        bool known = seq < v->next_sequence && v->next_sequence - seq <= SENT_RING;
        held.camera_s = known ? v->sent_camera_s[seq % SENT_RING] : NAN;
        if (seq < v->next_sequence && seq >= v->latency_next_sequence &&
            v->next_sequence - seq <= SENT_RING) {
            held.camera_us = v->sent_generated_us[seq % SENT_RING];
            v->latency_next_sequence = seq + 1;
        }
    }
    if (v->held_count == v->held_capacity) { /* full: the oldest held message is shown a little early */
        v->held[v->held_head].shown_us = now;
        viewer_show_frames(v, now);
        if (v->state != VIEWER_STREAMING)
            return;
    }
    held.buffer = pool_take(&v->held_pool, v->rx_len);
    if (held.buffer == UINT32_MAX) {
        viewer_fail(v, "out of memory for a message of %zu bytes", v->rx_len);
        viewer_stop(v, "client out of memory");
        return;
    }
    memcpy(v->held_pool.bytes[held.buffer], v->rx, v->rx_len);
    v->held[(v->held_head + v->held_count) % v->held_capacity] = held;
    v->held_count++;
    v->held_frames += msg->type == PROTO_FRAME;
    if (!latency_us(v))
        viewer_show_frames(v, now);
    else
        viewer_schedule(v, now); /* the timer may be set for later than this message's moment */
}

/* ---- the display clock -------------------------------------------------------------------------------- */

/* The viewer's camera `elapsed` seconds after its welcome: its trace's cameras interpolated, or the generator
 * at a fractional index (between the cameras it sends). */
static proto_pose viewer_camera_at(const view_viewer *v, double elapsed)
{
    const view_options *o = v->client->options;
    if (v->trace)
        return view_camera_trace_at(v->trace, v->client->trace_origin, elapsed, o->fov_deg);
    return view_camera_generate_at(o->camera, &v->welcome, v->index, v->client->count, elapsed * v->fps,
                                   o->fov_deg);
}

/* The round trip the prediction assumes: measured (camera generated to its first frame shown, smoothed), else
 * until the first measurement both --latency delays and a frame of the server's clock. */
static double viewer_rtt_ms(const view_viewer *v)
{
    if (v->rtt_measured)
        return v->rtt_ms;
    return 2.0 * v->client->options->latency_ms + 1000.0 / (v->welcome.fps * time_scale(v));
}

static void viewer_send_requests(view_viewer *v, const view_rc_frame *frame, const proto_pose *camera,
                                 const proto_pose *predicted, lws_usec_t now);

/* Writes a display frame's PNG, its camera's trace line and its figures' CSV line (--display-out). */
static bool viewer_display_out(view_viewer *v, uint64_t index, double time_s, const proto_pose *cam,
                               const uint8_t *rgb, const view_rc_frame *frame, double empty)
{
    const view_options *o = v->client->options;
    char path[4096], msg[512];
    snprintf(path, sizeof path, "%s/display_%05llu_%s.png", o->display_out, (unsigned long long)index,
             v->file_name);
    if (view_image_write_png(path, v->width, v->height, rgb, msg, sizeof msg) != 0) {
        viewer_fail(v, "cannot write the display frame: %s", msg);
        return false;
    }
    fprintf(v->display_trace, "%.17g %.17g %.17g %.17g %.9g %.9g %.9g %.9g\n", time_s, cam->position[0],
            cam->position[1], cam->position[2], (double)cam->direction[0], (double)cam->direction[1],
            (double)cam->direction[2], (double)cam->fov_deg);
    uint32_t kinds[VIEW_RC_PIXEL_KINDS] = {0};
    if (frame)
        memcpy(kinds, frame->stats.pixels, sizeof kinds);
    fprintf(v->display_csv, "%llu,%.9f,%lld,%.9f,%.6f,%u,%u,%u,%u,%u,%u,%u,%.4f\n", (unsigned long long)index,
            time_s, (long long)v->display_frame, v->display_frame_camera_s, empty, kinds[VIEW_RC_EMPTY],
            kinds[VIEW_RC_POINT], kinds[VIEW_RC_INTERP], kinds[VIEW_RC_PREFILTER],
            frame ? frame->stats.points : 0, frame ? frame->request_count : 0,
            frame ? frame->predicted_count : 0, frame ? frame->stats.total_ms : 0.0);
    if (ferror(v->display_trace) || ferror(v->display_csv)) {
        viewer_fail(v, "cannot write the display's trace or figures in %s", o->display_out);
        return false;
    }
    return true;
}

/* One display frame: the messages due by its time shown, the camera at its time, the render cache's frame
 * (and its requests sent) or the last frame received, its figures, --display-out. Display frame k is at
 * welcome + k / --display-fps; a clock that fell behind skips to the newest due frame. */
static void viewer_display(view_viewer *v, lws_usec_t now)
{
    const view_options *o = v->client->options;
    view_display_stats *d = &v->stats->display;
    double fps = o->display_fps;
    uint64_t due = (uint64_t)floor(scene_s(v, now) * fps);
    if (due > v->display_index) {
        d->skipped += due - v->display_index;
        v->display_index = due;
    }
    uint64_t index = v->display_index;
    double time_s = (double)index / fps;
    lws_usec_t at = wall_us(v, time_s);
    viewer_show_frames(v, at);
    if (v->state != VIEWER_STREAMING)
        return;
    proto_pose cam = viewer_camera_at(v, time_s);
    const uint8_t *rgb = v->display_rgb;
    double pixels = (double)v->width * v->height, empty = v->display_has_frame ? 0 : 1;
    view_rc_frame frame, *shown = NULL;
    if (v->rc) {
        view_rc_camera current = rc_camera(&cam), ahead;
        proto_pose predicted = cam;
        bool predict = !o->no_prediction && v->display_has_previous;
        if (predict) {
            predicted = view_pose_extrapolate(&v->display_previous, v->display_previous_s, &cam, time_s,
                                              time_s + viewer_rtt_ms(v) / 1000.0);
            ahead = rc_camera(&predicted);
        }
        fxc_result r = view_rc_render(v->rc, &current, predict ? &ahead : NULL, &frame);
        if (r != FXC_OK) {
            viewer_fail(v, "the render cache cannot render display frame %llu: %s", (unsigned long long)index,
                        fxc_strerror(r));
            viewer_stop(v, "client render cache failed");
            return;
        }
        shown = &frame;
        rgb = frame.rgb;
        empty = frame.stats.pixels[VIEW_RC_EMPTY] / pixels;
        for (int k = 0; k < VIEW_RC_PIXEL_KINDS; k++)
            d->kind_fraction_sum[k] += frame.stats.pixels[k] / pixels;
        d->points_sum += frame.stats.points;
        d->points_last = frame.stats.points;
        for (int k = 0; k < VIEW_RC_STAGE_COUNT; k++)
            d->stage_ms_sum[k] += frame.stats.stage_ms[k];
        d->total_ms_sum += frame.stats.total_ms;
        if (frame.stats.total_ms > d->total_ms_max)
            d->total_ms_max = frame.stats.total_ms;
        d->rtt_ms = viewer_rtt_ms(v);
        viewer_send_requests(v, &frame, &cam, &predicted, now);
        if (v->state != VIEWER_STREAMING)
            return;
    }
    d->frames++;
    d->empty_fraction_sum += empty;
    if (o->display_out && !viewer_display_out(v, index, time_s, &cam, rgb, shown, empty)) {
        viewer_stop(v, "client cannot write display frames");
        return;
    }
    v->display_previous = cam;
    v->display_previous_s = time_s;
    v->display_has_previous = true;
    v->display_index = index + 1;
    lws_usec_t next = wall_us(v, (double)v->display_index / fps);
    lws_sul_schedule(v->client->context, 0, &v->display_tick, viewer_display_tick,
                     next > now ? next - now : 1);
}

/* ---- sample requests ---------------------------------------------------------------------------------- */

/* True when the oldest queued sample request is due to be sent. */
static bool request_due(const view_viewer *v, lws_usec_t now)
{
    return v->out_count && v->out[v->out_head].send_us <= now;
}

/* The render cache's requests of a display frame, as one sample-request message held for --latency (as
 * cameras are). The server renders only the latest request in each frame of its clock (docs/PROTOCOL.md,
 * session rule 9), so a viewer makes at most one request a display frame and none sooner than 0.9 of the
 * server's frame interval after the previous one; the current camera's requests and the predicted camera's
 * take turns (odd display frames the predicted ones) when both have some. At most REQUEST_MAX_PIXELS pixels.
 * What is not sent is counted. */
static void viewer_send_requests(view_viewer *v, const view_rc_frame *frame, const proto_pose *camera,
                                 const proto_pose *predicted, lws_usec_t now)
{
    view_display_stats *d = &v->stats->display;
    uint32_t all = frame->request_count + frame->predicted_count;
    bool use_predicted = frame->predicted_count && (!frame->request_count || (v->display_index & 1));
    const view_rc_pixel *pixels = use_predicted ? frame->predicted_requests : frame->requests;
    uint32_t count = use_predicted ? frame->predicted_count : frame->request_count;
    lws_usec_t interval = (lws_usec_t)(0.9e6 / v->welcome.fps);
    bool wanted = v->client->options->sample_budget > 0 || !v->client->options->sample_budget_given;
    if (!count || !wanted || (v->last_request_us && now - v->last_request_us < interval) ||
        v->out_count == v->out_capacity) {
        d->requests_dropped += all;
        return;
    }
    if (count > REQUEST_MAX_PIXELS)
        count = REQUEST_MAX_PIXELS;
    proto_msg m = {.type = PROTO_SAMPLE_REQUEST};
    proto_sample_request *q = &m.u.sample_request;
    q->request = v->next_request;
    q->camera = use_predicted ? *predicted : *camera;
    q->width = v->width;
    q->height = v->height;
    q->count = count;
    for (uint32_t i = 0; i < count; i++)
        proto_request_pixel_put(v->request_pixels, i, pixels[i].x, pixels[i].y);
    q->pixels = v->request_pixels;
    size_t bytes = proto_bound(&m);
    uint32_t buffer = bytes ? pool_take(&v->out_pool, LWS_PRE + bytes) : UINT32_MAX;
    fxc_result r = FXC_ERR_NOMEM;
    if (buffer == UINT32_MAX || proto_encode(&m, v->out_pool.bytes[buffer] + LWS_PRE,
                                             v->out_pool.cap[buffer] - LWS_PRE, &r) != bytes) {
        viewer_fail(v, "cannot make a sample request of %u pixels: %s", count, fxc_strerror(r));
        viewer_stop(v, "client cannot make sample requests");
        return;
    }
    v->next_request++;
    v->last_request_us = now;
    d->requests_dropped += all - count;
    v->out[(v->out_head + v->out_count) % v->out_capacity] = (queued_message){
        .send_us = now + latency_us(v), .buffer = buffer, .bytes = (uint32_t)bytes, .pixels = count};
    v->out_count++;
    if (request_due(v, now))
        lws_callback_on_writable(v->wsi);
    else
        viewer_schedule(v, now);
}

/* Sends the oldest queued sample request. Returns 0, or -1 (after recording the failure). */
static int viewer_send_request(view_viewer *v)
{
    queued_message q = v->out[v->out_head];
    v->out_head = (v->out_head + 1) % v->out_capacity;
    v->out_count--;
    int written = lws_write(v->wsi, v->out_pool.bytes[q.buffer] + LWS_PRE, q.bytes, LWS_WRITE_BINARY);
    pool_give(&v->out_pool, q.buffer);
    if (written < (int)q.bytes) {
        viewer_fail(v, "the connection broke while sending a sample-request message");
        return -1;
    }
    v->stats->display.request_messages++;
    v->stats->display.request_pixels += q.pixels;
    return 0;
}

/* A samples message shown: its samples inserted into the render cache with the camera the server says it
 * rendered them for. */
static void viewer_use_samples(view_viewer *v, const proto_msg *msg)
{
    const proto_samples *answer = &msg->u.samples;
    view_display_stats *d = &v->stats->display;
    if (answer->count > v->samples_cap) {
        view_rc_sample *grown = realloc(v->samples, (size_t)answer->count * sizeof *grown);
        if (!grown) {
            d->insert_errors++;
            return;
        }
        v->samples = grown;
        v->samples_cap = answer->count;
    }
    for (uint32_t i = 0; i < answer->count; i++) {
        proto_sample sample;
        proto_sample_get(answer->samples, i, &sample);
        v->samples[i] = (view_rc_sample){.x = sample.x, .y = sample.y, .depth = sample.depth};
        memcpy(v->samples[i].rgb, sample.rgb, 3);
    }
    view_rc_camera cam = rc_camera(&answer->camera);
    if (view_rc_insert_samples(v->rc, &cam, answer->width, answer->height, v->samples, answer->count) !=
        FXC_OK) {
        d->insert_errors++;
        return;
    }
    d->answers++;
    d->samples_received += answer->count;
}

static void viewer_display_tick(lws_sorted_usec_list_t *sul)
{
    view_viewer *v = lws_container_of(sul, view_viewer, display_tick);
    if (v->state == VIEWER_STREAMING)
        viewer_display(v, lws_now_usecs());
}

/* ---- the welcome -------------------------------------------------------------------------------------- */

/* Allocates the rings once, from the rates and the delay: cameras pending during --latency, frames held
 * during it (at twice the server's fps, and at least 64), with answers to sample requests (two requests a
 * display frame, each answered once); requests waiting during --latency. Buffers are allocated as they are
 * first needed (pool_take). */
static bool viewer_rings(view_viewer *v)
{
    const view_options *o = v->client->options;
    double delay_s = o->latency_ms / 1000.0 * o->time_scale; /* wall seconds; the rates below are scene
                                                                 rates, at least the wall ones */
    double camera_rate = v->trace ? 1000.0 : v->fps; /* a trace's lines may be dense: --fps's upper bound */
    double requests = o->reproject ? o->display_fps : 0; /* at most one sample request a display frame */
    double pending = ceil(camera_rate * delay_s) + 4,
           held = ceil((2 * v->welcome.fps + requests) * delay_s) + 64;
    double out = ceil(requests * delay_s) + 8;
    v->pending_capacity = pending > 65536 ? 65536 : (uint32_t)pending;
    v->held_capacity = held > 65536 ? 65536 : (uint32_t)held;
    v->out_capacity = out > 65536 ? 65536 : (uint32_t)out;
    v->pending = calloc(v->pending_capacity, sizeof *v->pending);
    v->held = calloc(v->held_capacity, sizeof *v->held);
    v->out = calloc(v->out_capacity, sizeof *v->out);
    return v->pending && v->held && v->out && pool_init(&v->held_pool, v->held_capacity) &&
           pool_init(&v->out_pool, v->out_capacity);
}

/* The display's buffers, the render cache (--reproject), the --display-out files. false after recording the
 * failure. */
static bool viewer_display_setup(view_viewer *v)
{
    const view_options *o = v->client->options;
    v->display_frame = -1;
    v->display_frame_camera_s = NAN;
    v->stats->display.fps = o->display_fps;
    v->stats->display.reproject = o->reproject;
    v->display_rgb = calloc((size_t)v->width * v->height, 3);
    if (!v->display_rgb) {
        viewer_fail(v, "out of memory for a %ux%u display", v->width, v->height);
        return false;
    }
    if (o->reproject) {
        view_rc_desc desc = {
            .width = v->width,
            .height = v->height,
            .threads = o->rc_threads,
            .no_prediction = o->no_prediction,
            .no_prefilter = o->no_prefilter,
            .no_eviction = o->no_eviction,
            .no_tiling = o->no_tiling,
        };
        /* The cache ages every point by 128 k / capacity per frame (k points inserted since the last one),
         * and hidden points twice as fast: with room for one frame, each whole frame inserted would age every
         * point by 128 and evict the hidden ones at once (two frames arriving between display frames: all of
         * them). Room for several frames lets a point live through about that many frames inserted. */
        uint32_t pixels = v->width * v->height;
        desc.capacity = pixels * RC_CAPACITY_FRAMES; /* <= 4 * 8192^2 < 2^32 */
        if (o->sample_budget_given && o->sample_budget > 0)
            desc.sample_budget = o->sample_budget < pixels ? o->sample_budget : pixels;
        v->request_pixels = malloc((size_t)REQUEST_MAX_PIXELS * PROTO_REQUEST_PIXEL_BYTES);
        if (!v->request_pixels) {
            viewer_fail(v, "out of memory");
            return false;
        }
        fxc_result r = view_rc_create(&desc, &v->rc);
        if (r != FXC_OK) {
            viewer_fail(v, "cannot create a %ux%u render cache: %s", v->width, v->height, fxc_strerror(r));
            return false;
        }
    }
    if (o->display_out) {
        char path[4096];
        snprintf(path, sizeof path, "%s/display_%s.trace", o->display_out, v->file_name);
        v->display_trace = fopen(path, "w");
        snprintf(path, sizeof path, "%s/display_%s.csv", o->display_out, v->file_name);
        v->display_csv = fopen(path, "w");
        if (!v->display_trace || !v->display_csv) {
            viewer_fail(v, "cannot create %s: %s", path, strerror(errno));
            return false;
        }
        fprintf(v->display_trace,
                "fxcache-trace 2\n# the display frames' cameras of fxcache-viewer's viewer %u (%s), at their "
                "display times\nresolution %u %u\n",
                v->index, v->welcome.name, v->width, v->height);
        fprintf(
            v->display_csv,
            "display,time_s,frame,frame_camera_s,empty_fraction,empty,point,interpolated,prefiltered,points,"
            "requests,predicted_requests,rc_ms\n");
    }
    return true;
}

/* The welcome: the viewer's name, the scene's frame of reference, the rates. Cameras start now. */
static void viewer_welcomed(view_viewer *v, const proto_welcome *welcome, lws_usec_t now)
{
    view_client *c = v->client;
    const view_options *o = c->options;
    v->welcome = *welcome;
    snprintf(v->stats->name, sizeof v->stats->name, "%s", welcome->name);
    v->welcome_us = now;
    /* --fps, else the server's own rate, at most 1000 a second (--fps's bound) even when the server names
     * more. */
    v->fps = o->fps > 0 ? o->fps : welcome->fps * o->time_scale > 1000 ? 1000 : welcome->fps * o->time_scale;
    if (!(v->fps > 0)) { /* the decoder refuses this; a camera clock cannot run on it */
        viewer_fail(v, "the welcome names %g frames a second", welcome->fps);
        viewer_stop(v, "bad welcome");
        return;
    }
    if (!v->trace && welcome->max_camera_rate && v->fps / o->time_scale > welcome->max_camera_rate) {
        if (!c->rate_warned && !o->quiet) {
            clear_progress(c);
            fprintf(stderr,
                    "fxcache-viewer: %g cameras a second is above the server's limit of %u: sending %u a "
                    "second\n",
                    v->fps, welcome->max_camera_rate, welcome->max_camera_rate);
        }
        c->rate_warned = true;
        v->fps = welcome->max_camera_rate * o->time_scale;
    }
    file_name_part(welcome->name, v->file_name, sizeof v->file_name);
    if (!viewer_rings(v)) {
        viewer_fail(v, "out of memory");
        viewer_stop(v, "client out of memory");
        return;
    }
    if (!viewer_display_setup(v)) {
        viewer_stop(v, "client cannot display");
        return;
    }
    v->state = VIEWER_STREAMING;
    v->next_generate_us = now;
    if (v->trace) /* the first line is due at its time after the traces' common origin */
        v->next_generate_us = wall_us(v, v->trace->times[0] - c->trace_origin);
    viewer_generate(v, now);
    if (camera_due(v, now))
        lws_callback_on_writable(v->wsi);
    viewer_schedule(v, now);
    viewer_display(v, now); /* display frame 0, at the welcome */
}

/* ---- messages from the server ------------------------------------------------------------------------- */

/* One whole message. Returns -1 when the connection must close now (garbage, refusal, the server's bye). */
static int viewer_message(view_viewer *v, lws_usec_t now)
{
    proto_msg msg;
    fxc_result r = proto_decode(v->rx, v->rx_len, &msg);
    if (r != FXC_OK) {
        viewer_fail(v, "a message from the server does not decode: %s (%zu bytes)", fxc_strerror(r),
                    v->rx_len);
        return -1;
    }
    switch (msg.type) {
    case PROTO_WELCOME:
        if (v->state != VIEWER_HELLO)
            break;
        viewer_welcomed(v, &msg.u.welcome, now);
        return 0;
    case PROTO_FRAME:
        if (v->state == VIEWER_CLOSING)
            return 0; /* frames still in flight after our bye */
        if (v->state != VIEWER_STREAMING)
            break;
        viewer_take_message(v, &msg, now);
        return 0;
    case PROTO_SAMPLES:
        if (v->state == VIEWER_CLOSING)
            return 0; /* answers still in flight after our bye */
        if (v->state != VIEWER_STREAMING || !v->rc)
            break; /* never asked for */
        viewer_take_message(v, &msg, now);
        return 0;
    case PROTO_STATS:
        return 0; /* not asked for; harmless */
    case PROTO_ERROR:
        if (v->state == VIEWER_HELLO)
            viewer_fail(v, "server refused: %s (%s)", msg.u.error.reason, fxc_strerror(msg.u.error.code));
        else if (v->state != VIEWER_CLOSING || !v->goal_reached)
            viewer_fail(v, "server error: %s (%s)", msg.u.error.reason, fxc_strerror(msg.u.error.code));
        v->state = VIEWER_CLOSING;
        return -1;
    case PROTO_BYE:
        if (!v->goal_reached && v->state != VIEWER_CLOSING && (v->client->options->frames || v->trace))
            viewer_fail(v, "the server said bye before the viewer was done: %s", msg.u.bye.reason);
        else if (!v->client->options->quiet && v->state != VIEWER_CLOSING) {
            clear_progress(v->client);
            fprintf(stderr, "fxcache-viewer: viewer %u: the server said bye: %s\n", v->index,
                    msg.u.bye.reason);
        }
        v->goal_reached = true;
        v->state = VIEWER_CLOSING;
        return -1;
    default:
        break;
    }
    viewer_fail(v, "the server sent a %s message, which a viewer does not expect %s",
                proto_type_name(msg.type), v->state == VIEWER_HELLO ? "before its welcome" : "now");
    return -1;
}

/* Part of a message: collected until its last fragment. The header is checked as soon as it is in, so an
 * oversize or foreign message is refused before it arrives whole. */
static int viewer_receive(view_viewer *v, const void *in, size_t len, lws_usec_t now)
{
    struct lws *wsi = v->wsi;
    v->stats->bytes_received += len;
    if (!v->rx_in_message) { /* a new message (tracked here: the fragments of one may come in many parts) */
        v->rx_in_message = true;
        v->rx_len = 0;
        v->rx_header_checked = false;
        v->rx_binary = lws_frame_is_binary(wsi) != 0;
    }
    if (!v->rx_binary) {
        viewer_fail(v, "the server sent a text message (the protocol is binary)");
        return -1;
    }
    if (len > v->rx_limit - v->rx_len) {
        viewer_fail(v, "a message from the server is larger than %zu bytes", v->rx_limit);
        return -1;
    }
    if (v->rx_len + len > v->rx_cap) {
        size_t capacity = v->rx_cap ? v->rx_cap : RX_CHUNK;
        while (capacity < v->rx_len + len)
            capacity = capacity > v->rx_limit / 2 ? v->rx_limit : capacity * 2;
        uint8_t *grown = realloc(v->rx, capacity);
        if (!grown) {
            viewer_fail(v, "out of memory for a message of %zu bytes", v->rx_len + len);
            return -1;
        }
        v->rx = grown;
        v->rx_cap = capacity;
    }
    memcpy(v->rx + v->rx_len, in, len);
    v->rx_len += len;
    if (!v->rx_header_checked && v->rx_len >= PROTO_HEADER_BYTES) {
        proto_header header;
        fxc_result r = proto_decode_header(v->rx, v->rx_len, &header);
        if (r != FXC_OK) {
            viewer_fail(v, "a message from the server does not decode: %s", fxc_strerror(r));
            return -1;
        }
        if (header.length > v->rx_limit - PROTO_HEADER_BYTES) {
            viewer_fail(v, "the server announced a message of %u bytes, more than %zu", header.length,
                        v->rx_limit);
            return -1;
        }
        v->rx_header_checked = true;
    }
    if (!lws_is_final_fragment(wsi) || lws_remaining_packet_payload(wsi))
        return 0;
    v->rx_in_message = false;
    return viewer_message(v, now);
}

/* ---- messages to the server --------------------------------------------------------------------------- */

/* Encodes m behind LWS_PRE and writes it. Returns 0, or -1 (after recording the failure). */
static int viewer_send(view_viewer *v, const proto_msg *m)
{
    fxc_result r = FXC_OK;
    size_t n = proto_encode(m, v->tx + LWS_PRE, TX_BYTES, &r);
    if (!n) {
        viewer_fail(v, "cannot encode a %s message: %s", proto_type_name(m->type), fxc_strerror(r));
        return -1;
    }
    if (lws_write(v->wsi, v->tx + LWS_PRE, n, LWS_WRITE_BINARY) < (int)n) {
        viewer_fail(v, "the connection broke while sending a %s message", proto_type_name(m->type));
        return -1;
    }
    return 0;
}

/* The hello: who, what size, which codec. */
static int viewer_send_hello(view_viewer *v)
{
    const view_options *o = v->client->options;
    proto_msg m = {.type = PROTO_HELLO};
    proto_hello *h = &m.u.hello;
    if (o->name_prefix[0])
        snprintf(h->name, sizeof h->name, "%s_%u", o->name_prefix, v->index);
    h->width = v->width;
    h->height = v->height;
    /* The hello needs a field of view before the welcome names the scene's: --fov, the trace's first, or 60.
     */
    h->fov_deg = o->fov_deg > 0 ? o->fov_deg : v->trace ? v->trace->cameras[0].fov_deg : 60.0f;
    h->codec = o->codec;
    h->jpeg_quality = o->codec == PROTO_CODEC_JPEG ? o->quality : 0;
    h->depth = o->depth;
    snprintf(h->token, sizeof h->token, "%s", o->token);
    snprintf(h->strategy, sizeof h->strategy, "%s", proto_strategy_name(o->strategy));
    return viewer_send(v, &m);
}

/* The newest due camera (older due ones are skipped), with the next sequence number. */
static int viewer_send_camera(view_viewer *v, lws_usec_t now)
{
    while (v->pending_count > 1 && v->pending[(v->pending_head + 1) % v->pending_capacity].send_us <= now) {
        v->pending_head = (v->pending_head + 1) % v->pending_capacity;
        v->pending_count--;
        v->stats->cameras_skipped++;
    }
    pending_camera cam = v->pending[v->pending_head];
    v->pending_head = (v->pending_head + 1) % v->pending_capacity;
    v->pending_count--;
    proto_msg m = {.type = PROTO_CAMERA};
    m.u.camera.sequence = v->next_sequence;
    m.u.camera.time = (double)(cam.generated_us - v->client->start_us) / 1e6 / time_scale(v);
    m.u.camera.pose = cam.pose;
    if (v->client->options->strategy == PROTO_STRATEGY_PREDICTIVE) {
        /* Where the camera will be when the frame rendered for it is shown: extrapolated from the previous
         * camera sent by the measured round trip. */
        double rtt_s = viewer_rtt_ms(v) / 1000.0;
        m.u.camera.has_predicted = true;
        m.u.camera.predicted_time = m.u.camera.time + rtt_s;
        m.u.camera.predicted =
            v->last_sent_generated_us
                ? view_pose_extrapolate(&v->last_sent_pose,
                                        (double)(v->last_sent_generated_us - v->client->start_us) / 1e6 /
                                            time_scale(v),
                                        &cam.pose, m.u.camera.time, m.u.camera.predicted_time)
                : cam.pose;
    }
    if (viewer_send(v, &m) != 0)
        return -1;
    v->last_sent_pose = cam.pose;
    v->last_sent_generated_us = cam.generated_us;
    v->sent_generated_us[v->next_sequence % SENT_RING] = cam.generated_us;
    v->sent_camera_s[v->next_sequence % SENT_RING] = cam.camera_s;
    if (v->trace && !v->next_generate_us && !v->pending_count) {
        v->trace_all_sent = true;
        v->last_sequence = v->next_sequence;
    }
    v->next_sequence++;
    v->stats->cameras_sent++;
    if (!v->first_camera_us)
        v->first_camera_us = now;
    return 0;
}

/* The writeable callback: one message per call, in order of need (hello, bye then close, due camera). */
static int viewer_writeable(view_viewer *v, lws_usec_t now)
{
    if (v->hello_pending) {
        v->hello_pending = false;
        return viewer_send_hello(v);
    }
    if (v->state == VIEWER_CLOSING) {
        if (v->bye_pending) {
            v->bye_pending = false;
            v->bye_sent = true;
            proto_msg m = {.type = PROTO_BYE};
            snprintf(m.u.bye.reason, sizeof m.u.bye.reason, "%s", v->bye_reason);
            if (viewer_send(v, &m) != 0)
                return -1;
            lws_callback_on_writable(v->wsi); /* the close comes once the bye is out */
            return 0;
        }
        lws_close_reason(v->wsi, LWS_CLOSE_STATUS_NORMAL, (unsigned char *)"bye", 3);
        return -1;
    }
    if (v->state == VIEWER_STREAMING && camera_due(v, now)) {
        if (viewer_send_camera(v, now) != 0)
            return -1;
    } else if (v->state == VIEWER_STREAMING && request_due(v, now)) {
        if (viewer_send_request(v) != 0)
            return -1;
    }
    if (v->state == VIEWER_STREAMING) {
        if (camera_due(v, now) || request_due(v, now))
            lws_callback_on_writable(v->wsi);
        viewer_schedule(v, now);
    }
    return 0;
}

/* ---- libwebsockets ------------------------------------------------------------------------------------ */

static void viewer_tick(lws_sorted_usec_list_t *sul)
{
    view_viewer *v = lws_container_of(sul, view_viewer, tick);
    lws_usec_t now = lws_now_usecs();
    if (v->state != VIEWER_STREAMING)
        return;
    viewer_show_frames(v, now);
    if (v->state != VIEWER_STREAMING)
        return;
    viewer_generate(v, now);
    if (camera_due(v, now) || request_due(v, now))
        lws_callback_on_writable(v->wsi);
    viewer_schedule(v, now);
}

static int viewer_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in,
                           size_t len)
{
    view_viewer *v = user;
    if (!v)
        return 0;
    lws_usec_t now = lws_now_usecs();
    const view_options *o = v->client->options;
    switch (reason) {
    case LWS_CALLBACK_CLIENT_CONNECTION_ERROR:
        if (v->state != VIEWER_DONE && !v->goal_reached)
            viewer_fail(v, "cannot connect to %s: %s", o->url, in ? (const char *)in : "connection failed");
        viewer_closed(v);
        return 0;
    case LWS_CALLBACK_CLIENT_ESTABLISHED:
        v->wsi = wsi;
        if (v->state != VIEWER_CONNECTING || v->goal_reached || v->stats->failed)
            return -1; /* given up on while the connection was being made */
        v->state = VIEWER_HELLO;
        v->hello_pending = true;
        lws_callback_on_writable(wsi);
        return 0;
    case LWS_CALLBACK_CLIENT_RECEIVE:
        if (v->state == VIEWER_DONE)
            return -1;
        return viewer_receive(v, in, len, now);
    case LWS_CALLBACK_CLIENT_WRITEABLE:
        if (v->state == VIEWER_DONE)
            return -1;
        return viewer_writeable(v, now);
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE:
        if (v->state != VIEWER_CLOSING && !v->goal_reached) {
            unsigned code =
                len >= 2 ? ((unsigned)((const uint8_t *)in)[0] << 8) | ((const uint8_t *)in)[1] : 0;
            viewer_fail(v, "the server closed the connection (close code %u)", code);
        }
        return 0;
    case LWS_CALLBACK_CLIENT_CLOSED:
        if (v->state != VIEWER_CLOSING && !v->goal_reached)
            viewer_fail(v, "the server closed the connection");
        viewer_closed(v);
        return 0;
    case LWS_CALLBACK_WSI_DESTROY:
        if (v->wsi == wsi || v->state != VIEWER_DONE) {
            if (v->state != VIEWER_DONE && v->state != VIEWER_CLOSING && !v->goal_reached)
                viewer_fail(v, "the connection ended");
            viewer_closed(v);
        }
        return 0;
    default:
        return 0;
    }
}

static const struct lws_protocols protocols[] = {
    {"fxcache-viewer", viewer_callback, 0, RX_CHUNK, 0, NULL, 0},
    {NULL, NULL, 0, 0, 0, NULL, 0},
};

/* ---- the session -------------------------------------------------------------------------------------- */

/* Starts a viewer's connection. */
static void viewer_connect(view_viewer *v)
{
    const view_options *o = v->client->options;
    struct lws_client_connect_info info;
    memset(&info, 0, sizeof info);
    info.context = v->client->context;
    info.address = o->host;
    info.port = o->port;
    info.path = o->path;
    info.host = o->host;
    info.origin = o->host;
    /* No Sec-WebSocket-Protocol: a server binds such a connection to its default protocol. The callbacks are
     * bound to ours by name. */
    info.protocol = NULL;
    info.local_protocol_name = protocols[0].name;
    info.userdata = v;
    info.pwsi = &v->wsi;
    v->started_us = lws_now_usecs();
    v->state = VIEWER_CONNECTING;
    if (!lws_client_connect_via_info(&info)) {
        if (!v->stats->failed)
            viewer_fail(v, "cannot connect to %s", o->url);
        viewer_closed(v);
    }
}

/* Prints one progress line on stderr (a terminal only): viewers streaming, frames, frames a second. */
static void show_progress(view_client *c, lws_usec_t now)
{
    if (!c->progress || now - c->progress_us < 1000000)
        return;
    uint32_t streaming = 0;
    uint64_t frames = 0;
    for (uint32_t i = 0; i < c->count; i++) {
        streaming += c->viewers[i].state == VIEWER_STREAMING;
        frames += c->viewers[i].stats->frames;
    }
    double seconds = (double)(now - c->progress_us) / 1e6;
    fprintf(stderr, "\r\033[Kfxcache-viewer: %u of %u viewers streaming, %llu frames, %.1f frames a second",
            streaming, c->count, (unsigned long long)frames, (double)c->progress_frames / seconds);
    c->progress_shown = true;
    c->progress_us = now;
    c->progress_frames = 0;
}

/* The housekeeping timer: timeouts, and the progress line. */
static void housekeeping(lws_sorted_usec_list_t *sul)
{
    view_client *c = lws_container_of(sul, view_client, housekeeping);
    lws_usec_t now = lws_now_usecs(), limit = (lws_usec_t)(c->options->timeout_s * 1e6);
    for (uint32_t i = 0; i < c->count; i++) {
        view_viewer *v = &c->viewers[i];
        switch (v->state) {
        case VIEWER_CONNECTING:
        case VIEWER_HELLO:
            if (now - v->started_us > limit) {
                viewer_fail(v, "%s within %g s",
                            v->state == VIEWER_CONNECTING ? "no connection" : "no welcome",
                            c->options->timeout_s);
                if (v->state == VIEWER_HELLO)
                    viewer_stop(v, "no welcome");
                else
                    viewer_kill(v);
            }
            break;
        case VIEWER_STREAMING: {
            lws_usec_t since =
                v->last_frame_rx_us > v->first_camera_us ? v->last_frame_rx_us : v->first_camera_us;
            if (v->first_camera_us && now - since > limit) {
                viewer_fail(v, "no frame for %g s", c->options->timeout_s);
                viewer_stop(v, "no frames");
            }
            break;
        }
        case VIEWER_CLOSING:
            if (now > v->closing_deadline_us)
                viewer_kill(v);
            break;
        case VIEWER_DONE:
            break;
        }
    }
    show_progress(c, now);
    lws_sul_schedule(c->context, 0, &c->housekeeping, housekeeping, HOUSEKEEPING_US);
}

/* Sets up the viewers' fixed parts: trace, size, receive limit. */
static void viewers_init(view_client *c, view_viewer_stats *stats)
{
    const view_options *o = c->options;
    c->trace_origin = 0;
    for (uint32_t t = 0; t < o->trace_count; t++)
        if (t == 0 || c->traces[t].times[0] < c->trace_origin)
            c->trace_origin = c->traces[t].times[0];
    for (uint32_t i = 0; i < c->count; i++) {
        view_viewer *v = &c->viewers[i];
        v->client = c;
        v->index = i;
        v->stats = &stats[i];
        memset(v->stats, 0, sizeof *v->stats);
        v->stats->index = i;
        v->trace = o->trace_count ? &c->traces[o->trace_count == 1 ? 0 : i] : NULL;
        v->width = o->width;
        v->height = o->height;
        if (v->trace && v->trace->width && !o->res_given) {
            v->width = v->trace->width;
            v->height = v->trace->height;
        }
        /* A frame's message: colour (raw is the largest a sane server sends; JPEG's worst case is about
         * twice that), depth as 32-bit floats, headers; at least 1 MiB. */
        size_t pixels = (size_t)v->width * v->height;
        v->rx_limit = (size_t)1 << 20;
        if (v->rx_limit < pixels * 12 + 65536)
            v->rx_limit = pixels * 12 + 65536;
    }
}

int view_client_run(const view_options *o, const proto_trace *traces, view_viewer_stats *stats,
                    double *seconds, char *err, size_t cap)
{
    view_client c = {.options = o, .traces = traces, .count = o->viewers};
    c.progress = !o->quiet && isatty(STDERR_FILENO);
    c.viewers = calloc(c.count, sizeof *c.viewers);
    if (!c.viewers) {
        snprintf(err, cap, "out of memory");
        return -1;
    }
    viewers_init(&c, stats);

    lws_set_log_level(0, NULL); /* failures are reported per viewer, in one line each */
    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    info.port = CONTEXT_PORT_NO_LISTEN;
    info.protocols = protocols;
    info.gid = -1;
    info.uid = -1;
    info.fd_limit_per_thread = 1024;
    c.context = lws_create_context(&info);
    if (!c.context) {
        snprintf(err, cap, "cannot start libwebsockets");
        free(c.viewers);
        return -1;
    }

    interrupted = 0;
    signal_context = c.context;
    struct sigaction action, old_int, old_term;
    memset(&action, 0, sizeof action);
    action.sa_handler = on_signal;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, &old_int);
    sigaction(SIGTERM, &action, &old_term);

    c.start_us = lws_now_usecs();
    c.progress_us = c.start_us; /* the first progress line after a second */
    for (uint32_t i = 0; i < c.count; i++)
        viewer_connect(&c.viewers[i]);
    lws_sul_schedule(c.context, 0, &c.housekeeping, housekeeping, HOUSEKEEPING_US);

    for (;;) {
        if (interrupted && !c.stopping) {
            c.stopping = true;
            for (uint32_t i = 0; i < c.count; i++) {
                c.viewers[i].goal_reached = true;
                viewer_stop(&c.viewers[i], "interrupted");
            }
        }
        uint32_t done = 0;
        for (uint32_t i = 0; i < c.count; i++)
            done += c.viewers[i].state == VIEWER_DONE;
        if (done == c.count)
            break;
        if (lws_service(c.context, 0) < 0)
            break;
    }
    *seconds = (double)(lws_now_usecs() - c.start_us) / 1e6;
    clear_progress(&c);
    lws_sul_cancel(&c.housekeeping);
    signal_context = NULL;
    lws_context_destroy(c.context);
    sigaction(SIGINT, &old_int, NULL);
    sigaction(SIGTERM, &old_term, NULL);
    for (uint32_t i = 0; i < c.count; i++) {
        view_viewer *v = &c.viewers[i];
        if (v->state != VIEWER_DONE)
            viewer_closed(v);
        free(v->pending);
        free(v->held);
        free(v->rx);
        free(v->rgb);
        free(v->depth);
        free(v->out);
        pool_free(&v->held_pool);
        pool_free(&v->out_pool);
        free(v->display_rgb);
        free(v->samples);
        free(v->request_pixels);
        view_rc_destroy(v->rc);
        if (v->display_trace && fclose(v->display_trace) != 0)
            viewer_fail(v, "cannot write the display's trace");
        if (v->display_csv && fclose(v->display_csv) != 0)
            viewer_fail(v, "cannot write the display's figures");
    }
    free(c.viewers);
    return 0;
}
