/* `fxcache serve`'s network side and frame clock (net.h): libwebsockets on the calling thread, the frame
 * loop on its own thread, one mutex-protected table of viewer records between them. */
#include "net.h"

#include "proto.h"
#include "trace.h"

#include <errno.h>
#include <float.h>
#include <libwebsockets.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

enum {
    FRAGMENT_BYTES = 128 * 1024, /* a frame goes out in WebSocket fragments of at most this size */
    MAX_PENDING_CONNECTIONS = 32 /* connections that have not sent hello yet, beyond max_viewers */
};

/* A viewer record's life: FREE -> JOINING (hello accepted) -> ACTIVE (in the loop, from its first camera's
 * frame) -> LEAVING (its connection is gone; the frame thread takes it out of the loop) -> FREE. */
typedef enum viewer_state { VS_FREE = 0, VS_JOINING, VS_ACTIVE, VS_LEAVING } viewer_state;

typedef struct net_viewer {
    viewer_state state;
    uint32_t index;                 /* join number: the name is viewer_NN */
    char name[PROTO_NAME_MAX + 1];
    proto_hello hello;
    proto_strategy strategy;        /* hello's reference-frame strategy */
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
    uint32_t *req_pixels[2];        /* request order, packed y << 16 | x: [req_pending_index] pending, the
                                       other the one being rendered (max_samples each) */
    int req_pending_index;
    bool req_pending, req_rendering;
    uint32_t req_id[2], req_count[2], req_width[2], req_height[2];
    srv_camera req_camera[2];
    srv_viewer_id sample_id;        /* the sparse engine viewer, 0 until the first request */
    /* The answer outbox: as frames, two buffers (frame thread fills ans_index, network thread takes it). */
    uint8_t *ans[2];                /* count x PROTO_SAMPLE_BYTES */
    int ans_index;
    bool ans_ready;
    uint32_t ans_request, ans_frame, ans_count, ans_width, ans_height;
    srv_camera ans_camera;
    uint64_t requests_dropped;
    /* In the loop (frame thread). */
    srv_viewer_id id;
    uint32_t frame_sequence;        /* the camera sequence of the frame being rendered */
    srv_trace_writer *trace;
    int fail_code;                  /* the frame thread could not add it: the network thread says so */
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
    struct net_session *next;       /* every open session, for the byes at shutdown */
    net_viewer *viewer;             /* after hello */
    uint8_t *rx;                    /* the message being received */
    size_t rx_len, rx_cap;
    bool rx_bad;                    /* refusing the rest of this message */
    uint8_t *tx;                    /* LWS_PRE + the message being sent */
    size_t tx_len, tx_off, tx_cap;
    int tx_encoding_buffer;         /* the outbox buffer encoded into tx, -1 none */
    uint8_t *scratch;               /* encoded payloads */
    size_t scratch_cap;
    bool welcome_pending;
    int error_code;                 /* != 0: send this error, then close */
    char error_reason[PROTO_REASON_MAX + 1];
    bool bye_pending, closing;
    double tokens, tokens_time;     /* the camera-rate bucket */
    double sample_tokens, sample_tokens_time; /* the sample requests' bucket (the same rate) */
    bool counted;                   /* counted among pending (pre-hello) connections */
} net_session;

struct srv_net {
    srv_net_desc d;
    struct lws_context *context;
    int port;
    pthread_mutex_t lock;
    net_viewer viewers[SRV_MAX_VIEWERS];
    net_viewer *by_slot[256];       /* viewer id slot -> record (frame thread) */
    uint32_t next_index;
    net_session *sessions;
    uint32_t pending_connections;
    atomic_bool stopping;           /* the frame thread finished: say bye */
    bool byes_sent;
    double stop_deadline;
    bool clock_started;
    uint32_t frame;
    double origin[3];
    srv_net_totals totals;          /* under lock */
    uint64_t buffer_bytes;          /* under lock */
    double frame_ms;                /* the last frame's time (under lock): predictive's latency */
    fxc_result frame_error;
    char frame_error_text[256];
    volatile sig_atomic_t no_signal; /* the stop flag when the description gives none */
};

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void count_buffers(srv_net *net, int64_t delta)
{
    net->buffer_bytes = (uint64_t)((int64_t)net->buffer_bytes + delta);
    if (net->buffer_bytes > net->totals.buffer_bytes_peak)
        net->totals.buffer_bytes_peak = net->buffer_bytes;
}

/* ---- messages out -------------------------------------------------------------------------------------- */

/* Makes room for a message of `bytes` after LWS_PRE in the session's send buffer. */
static bool tx_reserve(net_session *ss, size_t bytes)
{
    if (bytes > SIZE_MAX - LWS_PRE)
        return false;
    size_t need = LWS_PRE + bytes;
    if (need <= ss->tx_cap)
        return true;
    uint8_t *p = realloc(ss->tx, need);
    if (!p)
        return false;
    ss->tx = p;
    ss->tx_cap = need;
    return true;
}

/* Encodes m into the send buffer (the session must not be sending). */
static bool tx_message(net_session *ss, const proto_msg *m)
{
    size_t bytes = proto_bound(m);
    if (!bytes || !tx_reserve(ss, bytes))
        return false;
    ss->tx_len = proto_encode(m, ss->tx + LWS_PRE, bytes, NULL);
    ss->tx_off = 0;
    return ss->tx_len > 0;
}

/* Queues an error for the session: it is sent as soon as nothing else is going out, then the connection is
 * closed. The first error wins. */
static void session_fail(srv_net *net, net_session *ss, fxc_result code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static void session_fail(srv_net *net, net_session *ss, fxc_result code, const char *fmt, ...)
{
    if (ss->error_code || ss->closing)
        return;
    ss->error_code = code;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(ss->error_reason, sizeof ss->error_reason, fmt, ap);
    va_end(ap);
    /* Printable ASCII only on the wire. */
    for (char *c = ss->error_reason; *c; c++)
        if (*c < 0x20 || *c > 0x7e)
            *c = '?';
    pthread_mutex_lock(&net->lock);
    net->totals.refused++;
    if (-code >= 0 && -code < 32)
        net->totals.refused_by_code[-code]++;
    pthread_mutex_unlock(&net->lock);
    lws_callback_on_writable(ss->wsi);
}

/* The world-space pose of a local camera. */
static proto_pose pose_of(const srv_net *net, const srv_camera *cam)
{
    proto_pose pose = {.fov_deg = cam->fov_deg};
    for (int k = 0; k < 3; k++) {
        pose.position[k] = (double)cam->position[k] + net->origin[k];
        pose.direction[k] = cam->target[k] - cam->position[k];
    }
    return pose;
}

/* Takes the viewer's ready frame (if any) and encodes it into the send buffer. */
static bool take_frame(srv_net *net, net_session *ss)
{
    net_viewer *v = ss->viewer;
    pthread_mutex_lock(&net->lock);
    if (!v->ready) {
        pthread_mutex_unlock(&net->lock);
        return false;
    }
    int buffer = v->out_index;
    v->out_index ^= 1;
    v->ready = false;
    proto_msg m = {.type = PROTO_FRAME};
    proto_frame *f = &m.u.frame;
    f->frame = v->out_frame;
    f->camera_sequence = v->out_sequence;
    f->camera = pose_of(net, &v->out_camera);
    f->width = v->hello.width;
    f->height = v->hello.height;
    f->codec = v->hello.codec;
    f->depth = v->hello.depth;
    f->stats = (proto_frame_stats){.requested_texels = v->out_stats.requested_texels,
                                   .requested_cells = v->out_stats.requested_cells,
                                   .pixels_visible = v->out_stats.pixels_visible,
                                   .pixels_missing = v->out_stats.pixels_missing,
                                   .frames_dropped = v->dropped,
                                   .frame_ms = v->out_frame_ms};
    pthread_mutex_unlock(&net->lock);

    /* Encoding reads buffer `buffer`, which the frame thread no longer writes (it writes the other one). */
    double t0 = now_s();
    uint32_t w = f->width, h = f->height;
    size_t color_cap = proto_color_bound(f->codec, w, h);
    size_t depth_cap = proto_depth_bound(f->depth, w, h);
    if (color_cap + depth_cap > ss->scratch_cap) {
        uint8_t *p = realloc(ss->scratch, color_cap + depth_cap);
        if (!p)
            return false;
        ss->scratch = p;
        ss->scratch_cap = color_cap + depth_cap;
    }
    size_t color_bytes = 0, depth_bytes = 0;
    uint32_t quality = f->codec == PROTO_CODEC_JPEG ? v->hello.jpeg_quality : 0;
    if (proto_color_encode(f->codec, quality, v->rgb[buffer], w, h, ss->scratch, color_cap, &color_bytes) != FXC_OK)
        return false;
    if (f->depth != PROTO_DEPTH_NONE &&
        proto_depth_encode(f->depth, v->depth[buffer], w, h, ss->scratch + color_cap, depth_cap, &depth_bytes) !=
            FXC_OK)
        return false;
    f->color = ss->scratch;
    f->color_bytes = (uint32_t)color_bytes;
    f->depth_data = depth_bytes ? ss->scratch + color_cap : NULL;
    f->depth_bytes = (uint32_t)depth_bytes;
    f->stats.encode_ms = (float)((now_s() - t0) * 1e3);
    if (!tx_message(ss, &m))
        return false;
    pthread_mutex_lock(&net->lock);
    net->totals.frames_sent++;
    net->totals.bytes_sent += ss->tx_len;
    net->totals.encode_ms += f->stats.encode_ms;
    pthread_mutex_unlock(&net->lock);
    return true;
}

/* Takes the viewer's ready sample answer (if any) and encodes it into the send buffer. */
static bool take_answer(srv_net *net, net_session *ss)
{
    net_viewer *v = ss->viewer;
    pthread_mutex_lock(&net->lock);
    if (!v->ans_ready) {
        pthread_mutex_unlock(&net->lock);
        return false;
    }
    int buffer = v->ans_index;
    v->ans_index ^= 1;
    v->ans_ready = false;
    proto_msg m = {.type = PROTO_SAMPLES};
    proto_samples *a = &m.u.samples;
    a->request = v->ans_request;
    a->frame = v->ans_frame;
    a->camera = pose_of(net, &v->ans_camera);
    a->width = v->ans_width;
    a->height = v->ans_height;
    a->count = v->ans_count;
    a->samples = v->ans[buffer]; /* the frame thread now writes the other buffer */
    pthread_mutex_unlock(&net->lock);
    if (!tx_message(ss, &m))
        return false;
    pthread_mutex_lock(&net->lock);
    net->totals.samples_sent++;
    net->totals.samples_pixels += a->count;
    net->totals.bytes_sent += ss->tx_len;
    pthread_mutex_unlock(&net->lock);
    return true;
}

/* Writes the next fragment of the message in the send buffer. Returns -1 to close the connection. */
static int send_fragment(net_session *ss)
{
    size_t left = ss->tx_len - ss->tx_off;
    size_t chunk = left < FRAGMENT_BYTES ? left : FRAGMENT_BYTES;
    int flags = lws_write_ws_flags(LWS_WRITE_BINARY, ss->tx_off == 0, chunk == left);
    /* lws writes the fragment's framing into the LWS_PRE bytes before it: for a later fragment those are bytes
     * of the message already sent (or already copied by lws), so they may be overwritten. */
    uint8_t *start = ss->tx + LWS_PRE + ss->tx_off;
    if (lws_write(ss->wsi, start, chunk, (enum lws_write_protocol)flags) < 0)
        return -1;
    ss->tx_off += chunk;
    if (ss->tx_off < ss->tx_len)
        lws_callback_on_writable(ss->wsi);
    return 0;
}

/* LWS_CALLBACK_SERVER_WRITEABLE: finish the message going out, else the most urgent one waiting. */
static int on_writeable(srv_net *net, net_session *ss)
{
    if (ss->tx_off < ss->tx_len)
        return send_fragment(ss);
    ss->tx_len = ss->tx_off = 0;
    proto_msg m = {0};
    if (ss->error_code) {
        m.type = PROTO_ERROR;
        m.u.error.code = ss->error_code;
        snprintf(m.u.error.reason, sizeof m.u.error.reason, "%s", ss->error_reason);
        if (tx_message(ss, &m))
            lws_write(ss->wsi, ss->tx + LWS_PRE, ss->tx_len, LWS_WRITE_BINARY);
        ss->closing = true;
        lws_close_reason(ss->wsi, LWS_CLOSE_STATUS_POLICY_VIOLATION, (unsigned char *)ss->error_reason,
                         strlen(ss->error_reason) > 120 ? 120 : strlen(ss->error_reason));
        return -1;
    }
    if (ss->bye_pending) {
        m.type = PROTO_BYE;
        snprintf(m.u.bye.reason, sizeof m.u.bye.reason, "the server is shutting down");
        if (tx_message(ss, &m))
            lws_write(ss->wsi, ss->tx + LWS_PRE, ss->tx_len, LWS_WRITE_BINARY);
        ss->closing = true;
        lws_close_reason(ss->wsi, LWS_CLOSE_STATUS_GOINGAWAY, (unsigned char *)"bye", 3);
        return -1;
    }
    if (!ss->viewer)
        return 0;
    net_viewer *v = ss->viewer;
    if (ss->welcome_pending) {
        ss->welcome_pending = false;
        m.type = PROTO_WELCOME;
        proto_welcome *wl = &m.u.welcome;
        wl->viewer_id = v->index + 1;
        snprintf(wl->name, sizeof wl->name, "%s", v->name);
        wl->fps = (float)net->d.fps;
        for (int k = 0; k < 3; k++) {
            wl->bounds_min[k] = (double)net->d.s->bounds_min[k] + net->origin[k];
            wl->bounds_max[k] = (double)net->d.s->bounds_max[k] + net->origin[k];
            if (!(wl->bounds_min[k] <= wl->bounds_max[k]))
                wl->bounds_min[k] = wl->bounds_max[k] = net->origin[k]; /* an empty scene */
        }
        srv_camera cam = srv_camera_default(net->d.s);
        wl->camera = pose_of(net, &cam);
        wl->max_camera_rate = net->d.camera_rate;
        if (!tx_message(ss, &m))
            return -1;
        return send_fragment(ss);
    }
    pthread_mutex_lock(&net->lock);
    char *json = v->stats_json;
    v->stats_json = NULL;
    int fail = v->fail_code;
    pthread_mutex_unlock(&net->lock);
    if (fail) {
        session_fail(net, ss, fail, "the server could not add this viewer (or its sample viewer): %s",
                     fxc_strerror(fail));
        return 0;
    }
    if (json) {
        m.type = PROTO_STATS;
        m.u.stats.json = json;
        m.u.stats.json_bytes = (uint32_t)strlen(json);
        bool ok = tx_message(ss, &m);
        free(json);
        if (!ok)
            return -1;
        return send_fragment(ss);
    }
    if (take_answer(net, ss)) {
        lws_callback_on_writable(ss->wsi); /* a frame may be waiting too */
        return send_fragment(ss);
    }
    if (take_frame(net, ss))
        return send_fragment(ss);
    return 0;
}

/* ---- messages in --------------------------------------------------------------------------------------- */

static bool printable_token_equal(const char *a, const char *b)
{
    /* Compares every byte whatever the first difference (no timing hint about the token). */
    size_t la = strlen(a), lb = strlen(b);
    unsigned diff = (unsigned)(la ^ lb);
    for (size_t i = 0; i < la; i++)
        diff |= (unsigned)(unsigned char)a[i] ^ (unsigned)(unsigned char)(i < lb ? b[i] : 0);
    return diff == 0;
}

static void on_hello(srv_net *net, net_session *ss, const proto_hello *h)
{
    if (ss->viewer) {
        session_fail(net, ss, FXC_ERR_PROTOCOL, "a second hello on the same connection");
        return;
    }
    if (net->d.token && net->d.token[0] && !printable_token_equal(h->token, net->d.token)) {
        session_fail(net, ss, FXC_ERR_UNAUTHORIZED, "hello without the server's access token");
        return;
    }
    proto_strategy strategy;
    if (!proto_strategy_parse(h->strategy, &strategy)) {
        session_fail(net, ss, FXC_ERR_RANGE, "unknown strategy '%s' (basic, fan or predictive)", h->strategy);
        return;
    }
    if (h->width > net->d.max_width || h->height > net->d.max_height) {
        session_fail(net, ss, FXC_ERR_LIMIT, "resolution %ux%u is above the server's limit %ux%u", h->width, h->height,
                     net->d.max_width, net->d.max_height);
        return;
    }
    size_t pixels = (size_t)h->width * h->height;
    size_t bytes = 2 * pixels * 3 + (h->depth ? 2 * pixels * sizeof(float) : 0);
    pthread_mutex_lock(&net->lock);
    uint32_t present = 0;
    net_viewer *v = NULL;
    for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++) {
        if (net->viewers[i].state != VS_FREE)
            present++;
        else if (!v)
            v = &net->viewers[i];
    }
    if (present >= net->d.max_viewers || !v) {
        pthread_mutex_unlock(&net->lock);
        session_fail(net, ss, FXC_ERR_LIMIT, "the server is full (%u viewers)", net->d.max_viewers);
        return;
    }
    memset(v, 0, sizeof *v);
    for (int k = 0; k < 2; k++) {
        v->rgb[k] = malloc(pixels * 3);
        v->depth[k] = h->depth ? malloc(pixels * sizeof(float)) : NULL;
    }
    if (!v->rgb[0] || !v->rgb[1] || (h->depth && (!v->depth[0] || !v->depth[1]))) {
        for (int k = 0; k < 2; k++) {
            free(v->rgb[k]);
            free(v->depth[k]);
        }
        memset(v, 0, sizeof *v);
        pthread_mutex_unlock(&net->lock);
        session_fail(net, ss, FXC_ERR_NOMEM, "no memory for a %ux%u viewer", h->width, h->height);
        return;
    }
    v->buffer_bytes = bytes;
    count_buffers(net, (int64_t)bytes);
    v->state = VS_JOINING;
    v->hello = *h;
    v->strategy = strategy;
    v->index = net->next_index++;
    snprintf(v->name, sizeof v->name, "viewer_%02u", v->index);
    net->totals.viewers_joined++;
    pthread_mutex_unlock(&net->lock);
    ss->viewer = v;
    if (ss->counted) {
        net->pending_connections--;
        ss->counted = false;
    }
    lws_set_timeout(ss->wsi, NO_PENDING_TIMEOUT, 0);
    ss->welcome_pending = true;
    ss->tokens = ss->sample_tokens = net->d.camera_rate;
    ss->tokens_time = ss->sample_tokens_time = now_s();
    lws_callback_on_writable(ss->wsi);
}

static const double PI = 3.14159265358979323846;

proto_pose srv_net_strategy_pose(uint32_t strategy, const proto_camera *c, const proto_pose *previous,
                                 double previous_time, double latency_s)
{
    proto_pose pose = c->pose;
    if (strategy == PROTO_STRATEGY_FAN) {
        double widened = 360.0 / PI * atan(SRV_FAN_TAN_FACTOR * tan((double)pose.fov_deg * PI / 360.0));
        pose.fov_deg = (float)fmin(widened, SRV_FAN_MAX_FOV);
    } else if (strategy == PROTO_STRATEGY_PREDICTIVE) {
        if (c->has_predicted)
            return c->predicted;
        double dt = previous ? c->time - previous_time : 0.0;
        if (!(dt > 0.0)) /* no earlier camera, or no time between them: nothing to extrapolate from */
            return pose;
        double ahead = latency_s / dt;
        /* Unit directions, so that a client that changes a direction's length does not look like a turn. */
        double len0 = 0, len1 = 0, moved[3], turned[3], len = 0;
        for (int k = 0; k < 3; k++) {
            len0 += (double)previous->direction[k] * previous->direction[k];
            len1 += (double)pose.direction[k] * pose.direction[k];
        }
        len0 = sqrt(len0);
        len1 = sqrt(len1);
        for (int k = 0; k < 3; k++) {
            moved[k] = pose.position[k] + (pose.position[k] - previous->position[k]) * ahead;
            double d1 = pose.direction[k] / len1;
            turned[k] = d1 + (d1 - previous->direction[k] / len0) * ahead;
            len += turned[k] * turned[k];
        }
        bool ok = len > 1e-12 && isfinite(len);
        for (int k = 0; k < 3; k++)
            ok = ok && isfinite(moved[k]);
        if (!ok)
            return pose;
        for (int k = 0; k < 3; k++) {
            pose.position[k] = moved[k];
            pose.direction[k] = (float)(turned[k] / sqrt(len));
        }
    }
    return pose;
}

static void on_camera(srv_net *net, net_session *ss, const proto_camera *c)
{
    if (!ss->viewer) {
        session_fail(net, ss, FXC_ERR_PROTOCOL, "a camera before hello");
        return;
    }
    /* The rate: a bucket of one second's worth of cameras, refilled continuously. */
    double t = now_s();
    ss->tokens = fmin((double)net->d.camera_rate, ss->tokens + (t - ss->tokens_time) * net->d.camera_rate);
    ss->tokens_time = t;
    if (ss->tokens < 1) {
        session_fail(net, ss, FXC_ERR_LIMIT, "more than %u camera messages per second", net->d.camera_rate);
        return;
    }
    ss->tokens -= 1;
    double direction[3] = {c->pose.direction[0], c->pose.direction[1], c->pose.direction[2]};
    srv_camera cam = srv_trace_camera_world(net->d.s, c->pose.position, direction, c->pose.fov_deg);
    srv_camera_frame check;
    if (!srv_camera_setup(&cam, ss->viewer->hello.width, ss->viewer->hello.height, &check)) {
        session_fail(net, ss, FXC_ERR_CAMERA, "camera %u: %s", c->sequence, fxc_strerror(FXC_ERR_CAMERA));
        return;
    }
    net_viewer *v = ss->viewer;
    pthread_mutex_lock(&net->lock);
    /* Predictive's latency: from a camera's arrival to its frame, at most a tick's wait plus the last frame's
     * time (at most a second). */
    double latency = fmin(1.0, 1.0 / net->d.fps + 1e-3 * net->frame_ms);
    pthread_mutex_unlock(&net->lock);
    proto_pose rendered_pose = srv_net_strategy_pose(v->strategy, c, v->has_previous ? &v->previous_pose : NULL,
                                                     v->previous_time, latency);
    double rendered_direction[3] = {rendered_pose.direction[0], rendered_pose.direction[1], rendered_pose.direction[2]};
    srv_camera rendered = srv_trace_camera_world(net->d.s, rendered_pose.position, rendered_direction,
                                                 rendered_pose.fov_deg);
    if (!srv_camera_setup(&rendered, v->hello.width, v->hello.height, &check))
        rendered = cam; /* a prediction the renderer cannot use: the reported camera */
    v->has_previous = true;
    v->previous_pose = c->pose;
    v->previous_time = c->time;
    pthread_mutex_lock(&net->lock);
    v->camera = rendered;
    v->camera_sequence = c->sequence;
    v->has_camera = true;
    net->totals.cameras_received++;
    pthread_mutex_unlock(&net->lock);
}

/* A sample request: checked against the limits, converted into the viewer's pending list (replacing one not
 * yet rendered), rendered by the frame thread at its next frame. */
static void on_sample_request(srv_net *net, net_session *ss, const proto_sample_request *q)
{
    net_viewer *v = ss->viewer;
    if (!v) {
        session_fail(net, ss, FXC_ERR_PROTOCOL, "a sample request before hello");
        return;
    }
    double t = now_s();
    ss->sample_tokens =
        fmin((double)net->d.camera_rate, ss->sample_tokens + (t - ss->sample_tokens_time) * net->d.camera_rate);
    ss->sample_tokens_time = t;
    if (ss->sample_tokens < 1) {
        session_fail(net, ss, FXC_ERR_LIMIT, "more than %u sample requests per second", net->d.camera_rate);
        return;
    }
    ss->sample_tokens -= 1;
    if (q->count > net->d.max_samples) {
        session_fail(net, ss, FXC_ERR_LIMIT, "sample request %u: %u pixels, over the server's limit of %u",
                     q->request, q->count, net->d.max_samples);
        return;
    }
    if (q->width > net->d.max_width || q->height > net->d.max_height) {
        session_fail(net, ss, FXC_ERR_LIMIT, "sample request %u: image %ux%u is above the server's limit %ux%u",
                     q->request, q->width, q->height, net->d.max_width, net->d.max_height);
        return;
    }
    double direction[3] = {q->camera.direction[0], q->camera.direction[1], q->camera.direction[2]};
    srv_camera cam = srv_trace_camera_world(net->d.s, q->camera.position, direction, q->camera.fov_deg);
    srv_camera_frame check;
    if (!srv_camera_setup(&cam, q->width, q->height, &check)) {
        session_fail(net, ss, FXC_ERR_CAMERA, "sample request %u: %s", q->request, fxc_strerror(FXC_ERR_CAMERA));
        return;
    }
    pthread_mutex_lock(&net->lock);
    net->totals.sample_requests++;
    if (!v->req_pixels[0]) { /* the first request: its buffers (counted) */
        size_t n = net->d.max_samples;
        for (int k = 0; k < 2; k++) {
            v->req_pixels[k] = malloc(n * sizeof *v->req_pixels[k]);
            v->ans[k] = malloc(n * PROTO_SAMPLE_BYTES);
        }
        if (!v->req_pixels[0] || !v->req_pixels[1] || !v->ans[0] || !v->ans[1]) {
            for (int k = 0; k < 2; k++) {
                free(v->req_pixels[k]);
                free(v->ans[k]);
                v->req_pixels[k] = NULL;
                v->ans[k] = NULL;
            }
            pthread_mutex_unlock(&net->lock);
            session_fail(net, ss, FXC_ERR_NOMEM, "no memory for sample requests");
            return;
        }
        size_t bytes = 2 * n * (sizeof *v->req_pixels[0] + PROTO_SAMPLE_BYTES);
        v->buffer_bytes += bytes;
        count_buffers(net, (int64_t)bytes);
    }
    if (v->req_pending) { /* the newest request wins */
        v->requests_dropped++;
        net->totals.sample_requests_dropped++;
    }
    int b = v->req_pending_index;
    for (uint32_t i = 0; i < q->count; i++) {
        uint16_t x, y;
        proto_request_pixel_get(q->pixels, i, &x, &y);
        v->req_pixels[b][i] = SRV_PIXEL_XY(x, y);
    }
    v->req_id[b] = q->request;
    v->req_count[b] = q->count;
    v->req_width[b] = q->width;
    v->req_height[b] = q->height;
    v->req_camera[b] = cam;
    v->req_pending = true;
    pthread_mutex_unlock(&net->lock);
}

/* One whole message from a client. */
static void on_message(srv_net *net, net_session *ss, const uint8_t *bytes, size_t len)
{
    proto_msg m;
    fxc_result r = proto_decode(bytes, len, &m);
    if (r != FXC_OK) {
        session_fail(net, ss, r, "message of %zu bytes refused: %s", len, fxc_strerror(r));
        return;
    }
    switch (m.type) {
    case PROTO_HELLO: on_hello(net, ss, &m.u.hello); break;
    case PROTO_CAMERA: on_camera(net, ss, &m.u.camera); break;
    case PROTO_SAMPLE_REQUEST: on_sample_request(net, ss, &m.u.sample_request); break;
    case PROTO_STATS_REQUEST:
        if (!ss->viewer) {
            session_fail(net, ss, FXC_ERR_PROTOCOL, "a stats request before hello");
            return;
        }
        pthread_mutex_lock(&net->lock);
        ss->viewer->stats_requested = true;
        pthread_mutex_unlock(&net->lock);
        break;
    case PROTO_BYE:
        ss->closing = true;
        lws_close_reason(ss->wsi, LWS_CLOSE_STATUS_NORMAL, (unsigned char *)"bye", 3);
        lws_set_timeout(ss->wsi, PENDING_TIMEOUT_CLOSE_SEND, LWS_TO_KILL_ASYNC);
        break;
    default:
        session_fail(net, ss, FXC_ERR_PROTOCOL, "a %s message is not for the server", proto_type_name(m.type));
        break;
    }
}

/* The largest message the session may be receiving: a sample request's own limit once its header says
 * that is what it is; before the header, the larger of the two. */
static size_t message_limit(const srv_net *net, const net_session *ss)
{
    size_t samples = PROTO_HEADER_BYTES + 56 + (size_t)PROTO_REQUEST_PIXEL_BYTES * net->d.max_samples;
    size_t larger = samples > net->d.max_message ? samples : net->d.max_message;
    if (ss->rx_len < PROTO_HEADER_BYTES)
        return larger;
    return proto_get_u16le(ss->rx + 6) == PROTO_SAMPLE_REQUEST ? larger : net->d.max_message;
}

static void on_receive(srv_net *net, net_session *ss, const uint8_t *in, size_t len)
{
    if (ss->closing || ss->error_code)
        return;
    if (!lws_frame_is_binary(ss->wsi)) {
        session_fail(net, ss, FXC_ERR_PROTOCOL, "a text message (messages are binary)");
        return;
    }
    size_t limit = message_limit(net, ss);
    if (len > limit - ss->rx_len) {
        session_fail(net, ss, FXC_ERR_TOO_LARGE, "a message over the server's limit of %zu bytes", limit);
        return;
    }
    if (ss->rx_len + len > ss->rx_cap) {
        size_t cap = ss->rx_cap ? ss->rx_cap : 256;
        while (cap < ss->rx_len + len)
            cap *= 2;
        if (cap > limit)
            cap = limit;
        uint8_t *p = realloc(ss->rx, cap);
        if (!p) {
            session_fail(net, ss, FXC_ERR_NOMEM, "no memory for a message");
            return;
        }
        ss->rx = p;
        ss->rx_cap = cap;
    }
    memcpy(ss->rx + ss->rx_len, in, len);
    ss->rx_len += len;
    /* Refuse what the header already shows to be wrong before the rest arrives. */
    if (ss->rx_len >= PROTO_HEADER_BYTES) {
        proto_header h;
        fxc_result r = proto_decode_header(ss->rx, ss->rx_len, &h);
        if (r != FXC_OK) {
            session_fail(net, ss, r, "message refused: %s", fxc_strerror(r));
            return;
        }
        limit = message_limit(net, ss);
        if (h.length > limit - PROTO_HEADER_BYTES) {
            session_fail(net, ss, FXC_ERR_TOO_LARGE, "a message of %u bytes is over the server's limit of %zu",
                         h.length, limit);
            return;
        }
    }
    if (!lws_is_final_fragment(ss->wsi) || lws_remaining_packet_payload(ss->wsi))
        return;
    on_message(net, ss, ss->rx, ss->rx_len);
    ss->rx_len = 0;
}

/* ---- the lws callback ---------------------------------------------------------------------------------- */

static void session_close(srv_net *net, net_session *ss)
{
    for (net_session **p = &net->sessions; *p; p = &(*p)->next)
        if (*p == ss) {
            *p = ss->next;
            break;
        }
    if (ss->counted)
        net->pending_connections--;
    if (ss->viewer) {
        pthread_mutex_lock(&net->lock);
        ss->viewer->state = VS_LEAVING; /* the frame thread takes it out of the loop and frees it */
        pthread_mutex_unlock(&net->lock);
    }
    free(ss->rx);
    free(ss->tx);
    free(ss->scratch);
    memset(ss, 0, sizeof *ss);
}

static void on_wake(srv_net *net)
{
    if (atomic_load(&net->stopping) && !net->byes_sent) {
        net->byes_sent = true;
        net->stop_deadline = now_s() + 1.0;
        for (net_session *ss = net->sessions; ss; ss = ss->next) {
            ss->bye_pending = true;
            lws_callback_on_writable(ss->wsi);
        }
        return;
    }
    /* Frames, stats and failures ready: ask to write. */
    for (net_session *ss = net->sessions; ss; ss = ss->next) {
        if (!ss->viewer)
            continue;
        pthread_mutex_lock(&net->lock);
        bool work = ss->viewer->ready || ss->viewer->ans_ready || ss->viewer->stats_json || ss->viewer->fail_code;
        pthread_mutex_unlock(&net->lock);
        if (work)
            lws_callback_on_writable(ss->wsi);
    }
}

static int net_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len)
{
    struct lws_context *context = lws_get_context(wsi);
    srv_net *net = context ? lws_context_user(context) : NULL;
    net_session *ss = user;
    switch (reason) {
    case LWS_CALLBACK_ESTABLISHED:
        memset(ss, 0, sizeof *ss);
        ss->wsi = wsi;
        ss->next = net->sessions;
        net->sessions = ss;
        pthread_mutex_lock(&net->lock);
        net->totals.connections++;
        pthread_mutex_unlock(&net->lock);
        if (atomic_load(&net->stopping)) {
            session_fail(net, ss, FXC_ERR_SHUTDOWN, "the server is shutting down");
            return 0;
        }
        ss->counted = true;
        net->pending_connections++;
        if (net->pending_connections > net->d.max_viewers + MAX_PENDING_CONNECTIONS) {
            session_fail(net, ss, FXC_ERR_LIMIT, "too many connections waiting for hello");
            return 0;
        }
        lws_set_timeout(wsi, PENDING_TIMEOUT_USER_OK, (int)net->d.hello_timeout_s);
        return 0;
    case LWS_CALLBACK_RECEIVE:
        on_receive(net, ss, in, len);
        return 0;
    case LWS_CALLBACK_SERVER_WRITEABLE:
        if (ss->closing)
            return -1;
        return on_writeable(net, ss);
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE:
        ss->closing = true;
        return 0;
    case LWS_CALLBACK_CLOSED:
        session_close(net, ss);
        return 0;
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED:
        if (net)
            on_wake(net);
        return 0;
    default:
        return lws_callback_http_dummy(wsi, reason, user, in, len);
    }
}

static const struct lws_protocols net_protocols[] = {
    {"fxcache", net_callback, sizeof(net_session), 4096, 0, NULL, FRAGMENT_BYTES},
    {NULL, NULL, 0, 0, 0, NULL, 0},
};

static void lws_log_line(int level, const char *line)
{
    (void)level;
    fprintf(stderr, "fxcache serve: libwebsockets: %s", line);
}

/* ---- the frame thread ---------------------------------------------------------------------------------- */

static void free_viewer(srv_net *net, net_viewer *v)
{
    for (int k = 0; k < 2; k++) {
        free(v->rgb[k]);
        free(v->depth[k]);
        free(v->req_pixels[k]);
        free(v->ans[k]);
    }
    free(v->stats_json);
    count_buffers(net, -(int64_t)v->buffer_bytes);
    memset(v, 0, sizeof *v);
}

static int net_viewer_frame(void *user, const srv_viewer_frame *vf)
{
    srv_net *net = user;
    net_viewer *v = net->by_slot[vf->id.id & 0xFFu];
    if (!v)
        return 0;
    int rc = 0;
    if (v->trace && srv_trace_writer_add(v->trace, vf->frame / net->d.fps, &vf->camera) != 0) {
        fprintf(stderr, "fxcache serve: %s: %s\n", v->name, srv_trace_writer_error(v->trace));
        rc = -1;
    }
    size_t pixels = (size_t)vf->width * vf->height;
    pthread_mutex_lock(&net->lock);
    if (v->ready) { /* the previous frame was never taken: the newest wins */
        v->ready = false;
        v->dropped++;
        net->totals.frames_dropped++;
    }
    int b = v->out_index;
    memcpy(v->rgb[b], vf->srgb, pixels * 3);
    if (v->depth[b])
        memcpy(v->depth[b], vf->depth, pixels * sizeof(float));
    v->out_frame = vf->frame;
    v->out_sequence = v->frame_sequence;
    v->out_camera = vf->camera;
    v->out_stats = *vf->stats;
    v->staged = true;
    pthread_mutex_unlock(&net->lock);
    return rc;
}

static int net_frame_done(void *user, const srv_frame_stats *stats)
{
    srv_net *net = user;
    pthread_mutex_lock(&net->lock);
    for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++) {
        net_viewer *v = &net->viewers[i];
        if (v->staged) {
            v->staged = false;
            v->ready = true;
            v->out_frame_ms = (float)stats->frame_ms;
        }
    }
    pthread_mutex_unlock(&net->lock);
    return 0;
}

/* Hands a viewer's pending sample request to its sparse engine viewer (added at the first request) for the
 * next frame. Under the lock. */
static void take_request(srv_net *net, net_viewer *v)
{
    int b = v->req_pending_index;
    v->req_pending = false;
    if (!v->sample_id.id) {
        srv_viewer_desc vd = {.max_pixels = net->d.max_samples};
        snprintf(vd.name, sizeof vd.name, "%.20s.samples", v->name);
        fxc_result r = srv_viewer_add(net->d.loop, &vd, &v->sample_id);
        if (r != FXC_OK) {
            v->sample_id.id = 0;
            v->fail_code = r == FXC_ERR_NO_SLOT ? FXC_ERR_LIMIT : r;
            return;
        }
    }
    /* Checked when it arrived (sizes, pixels, camera): a refusal here would be a bug, and drops the request. */
    if (srv_viewer_set_pixels(net->d.loop, v->sample_id, &v->req_camera[b], v->req_width[b], v->req_height[b],
                              v->req_pixels[b], v->req_count[b], NULL) != FXC_OK)
        return;
    v->req_rendering = true;
    v->req_pending_index ^= 1; /* the network thread writes the next request into the other buffer */
}

/* Stage 1 for the network's viewers: leaves, joins (in join order, as a replay adds them), cameras. */
static void take_viewers(srv_net *net)
{
    pthread_mutex_lock(&net->lock);
    for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++) {
        net_viewer *v = &net->viewers[i];
        if (v->state != VS_LEAVING)
            continue;
        if (v->id.id) {
            srv_viewer_remove(net->d.loop, v->id);
            net->by_slot[v->id.id & 0xFFu] = NULL;
        }
        if (v->sample_id.id)
            srv_viewer_remove(net->d.loop, v->sample_id);
        if (v->trace && srv_trace_writer_close(v->trace) != 0 && !net->frame_error) {
            net->frame_error = FXC_ERR_IO;
            snprintf(net->frame_error_text, sizeof net->frame_error_text, "writing %s's trace failed", v->name);
        }
        v->trace = NULL;
        free_viewer(net, v);
    }
    for (;;) {
        net_viewer *next = NULL;
        for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++) {
            net_viewer *v = &net->viewers[i];
            if (v->state == VS_JOINING && v->has_camera && !v->fail_code && (!next || v->index < next->index))
                next = v;
        }
        if (!next)
            break;
        srv_viewer_desc vd = {.width = next->hello.width, .height = next->hello.height};
        snprintf(vd.name, sizeof vd.name, "%s", next->name);
        fxc_result r = srv_viewer_add(net->d.loop, &vd, &next->id);
        if (r != FXC_OK) {
            next->fail_code = r;
            continue;
        }
        next->state = VS_ACTIVE;
        net->by_slot[next->id.id & 0xFFu] = next;
        if (net->d.record_dir) {
            char path[1024], err[512];
            snprintf(path, sizeof path, "%s/%s.trace", net->d.record_dir, next->name);
            next->trace = srv_trace_writer_open_sized(path, net->d.s, vd.width, vd.height, err, sizeof err);
            if (!next->trace && !net->frame_error) {
                net->frame_error = FXC_ERR_IO;
                snprintf(net->frame_error_text, sizeof net->frame_error_text, "%s", err);
            }
        }
    }
    for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++) {
        net_viewer *v = &net->viewers[i];
        if (v->state != VS_ACTIVE)
            continue;
        srv_viewer_set_camera(net->d.loop, v->id, &v->camera); /* checked when it arrived */
        v->frame_sequence = v->camera_sequence;
        net->clock_started = true;
        if (v->req_pending)
            take_request(net, v);
    }
    pthread_mutex_unlock(&net->lock);
}

/* After a frame: each rendered request's answer, one sample per requested entry in the request's order, into
 * the viewer's answer outbox (a newer answer replaces one not yet sent). Under the lock. */
static void stage_answers(srv_net *net, uint32_t frame)
{
    pthread_mutex_lock(&net->lock);
    for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++) {
        net_viewer *v = &net->viewers[i];
        if (v->state != VS_ACTIVE || !v->req_rendering)
            continue;
        v->req_rendering = false;
        int r = v->req_pending_index ^ 1; /* the request rendered */
        const uint8_t *image = srv_viewer_image(net->d.loop, v->sample_id);
        const float *depth = srv_viewer_depth(net->d.loop, v->sample_id);
        if (!image || !depth)
            continue;
        if (v->ans_ready) {
            v->requests_dropped++;
            net->totals.sample_requests_dropped++;
        }
        uint8_t *out = v->ans[v->ans_index];
        for (uint32_t k = 0; k < v->req_count[r]; k++) {
            uint32_t xy = v->req_pixels[r][k];
            proto_sample sample = {.x = (uint16_t)(xy & 0xFFFFu), .y = (uint16_t)(xy >> 16)};
            uint32_t at = srv_viewer_pixel_index(net->d.loop, v->sample_id, sample.x, sample.y);
            float d = INFINITY;
            if (at != UINT32_MAX) { /* always: every requested pixel was listed */
                memcpy(sample.rgb, image + 3 * (size_t)at, 3);
                d = depth[at];
            }
            sample.depth = d > 0.0f ? d : FLT_MIN; /* the wire wants > 0 (a hit at the eye, were it possible) */
            proto_sample_put(out, k, &sample);
        }
        v->ans_request = v->req_id[r];
        v->ans_frame = frame;
        v->ans_count = v->req_count[r];
        v->ans_width = v->req_width[r];
        v->ans_height = v->req_height[r];
        v->ans_camera = v->req_camera[r];
        v->ans_ready = true;
    }
    pthread_mutex_unlock(&net->lock);
}

/* Answers stats requests with the run report as JSON text. */
static void answer_stats(srv_net *net)
{
    bool wanted = false;
    pthread_mutex_lock(&net->lock);
    for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++)
        wanted |= net->viewers[i].state != VS_FREE && net->viewers[i].stats_requested;
    pthread_mutex_unlock(&net->lock);
    if (!wanted)
        return;
    json_t *report = srv_report_json(net->d.report);
    char *text = report ? json_dumps(report, JSON_COMPACT | JSON_PRESERVE_ORDER) : NULL;
    json_decref(report);
    pthread_mutex_lock(&net->lock);
    for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++) {
        net_viewer *v = &net->viewers[i];
        if (v->state == VS_FREE || !v->stats_requested || !text)
            continue;
        v->stats_requested = false;
        free(v->stats_json);
        v->stats_json = strdup(text);
    }
    pthread_mutex_unlock(&net->lock);
    free(text);
}

static void sleep_until(double t)
{
    double left = t - now_s();
    if (left <= 0)
        return;
    struct timespec ts = {.tv_sec = (time_t)left, .tv_nsec = (long)((left - floor(left)) * 1e9)};
    nanosleep(&ts, NULL);
}

static void *frame_thread(void *arg)
{
    srv_net *net = arg;
    double period = 1.0 / net->d.fps, next_tick = now_s();
    while (!*net->d.stop && !(net->d.frames && net->frame >= net->d.frames)) {
        take_viewers(net);
        if (net->clock_started) {
            srv_frame_stats st;
            if (srv_loop_frame(net->d.loop, &st) != FXC_OK && !net->frame_error) {
                net->frame_error = FXC_ERR_IO; /* a sink could not write: it said why */
                snprintf(net->frame_error_text, sizeof net->frame_error_text, "a frame's output could not be written");
            }
            stage_answers(net, st.frame);
            pthread_mutex_lock(&net->lock);
            net->frame_ms = st.frame_ms;
            pthread_mutex_unlock(&net->lock);
            net->frame++;
            if (net->d.progress)
                fprintf(stderr, "\rframe %u  %u viewers  %.1f ms   ", net->frame, st.viewer_count, st.frame_ms);
        }
        answer_stats(net);
        lws_cancel_service(net->context);
        if (net->frame_error)
            break;
        /* The next tick; a late frame starts the schedule again from now (no bursts to catch up). */
        next_tick += period;
        double t = now_s();
        if (next_tick < t)
            next_tick = t;
        while (!*net->d.stop && now_s() < next_tick - 1e-4)
            sleep_until(fmin(next_tick, now_s() + 0.05));
    }
    if (net->d.progress)
        fputc('\n', stderr);
    atomic_store(&net->stopping, true);
    lws_cancel_service(net->context);
    return NULL;
}

/* ---- the server ---------------------------------------------------------------------------------------- */

fxc_result srv_net_create(const srv_net_desc *desc, srv_net **out, char *err, size_t err_cap)
{
    *out = NULL;
    srv_net *net = calloc(1, sizeof *net);
    if (!net) {
        snprintf(err, err_cap, "out of memory");
        return FXC_ERR_NOMEM;
    }
    net->d = *desc;
    if (!net->d.stop)
        net->d.stop = &net->no_signal;
    if (!net->d.bind)
        net->d.bind = "127.0.0.1";
    if (net->d.port < 0)
        net->d.port = 7681;
    if (!(net->d.fps > 0))
        net->d.fps = 30;
    if (!net->d.max_viewers || net->d.max_viewers > SRV_MAX_VIEWERS)
        net->d.max_viewers = net->d.max_viewers ? SRV_MAX_VIEWERS : 16;
    if (!net->d.max_width)
        net->d.max_width = 3840;
    if (!net->d.max_height)
        net->d.max_height = 2160;
    if (!net->d.max_message)
        net->d.max_message = 65536;
    if (net->d.max_message < 1024)
        net->d.max_message = 1024;
    if (!net->d.camera_rate)
        net->d.camera_rate = 240;
    if (!net->d.max_samples)
        net->d.max_samples = 65536;
    if (net->d.max_samples > PROTO_MAX_SAMPLES)
        net->d.max_samples = PROTO_MAX_SAMPLES;
    if (!net->d.hello_timeout_s)
        net->d.hello_timeout_s = 10;
    for (int k = 0; k < 3; k++)
        net->origin[k] = desc->s->origin[k];
    pthread_mutex_init(&net->lock, NULL);
    lws_set_log_level(LLL_ERR, lws_log_line);
    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    info.port = net->d.port;
    info.iface = net->d.bind;
    info.protocols = net_protocols;
    info.user = net;
    info.options = LWS_SERVER_OPTION_DISABLE_IPV6;
    info.gid = -1;
    info.uid = -1;
    net->context = lws_create_context(&info);
    if (!net->context) {
        snprintf(err, err_cap, "cannot listen on %s:%d (in use, or not an address of this machine)", net->d.bind,
                 net->d.port);
        srv_net_free(net);
        return FXC_ERR_IO;
    }
    struct lws_vhost *vhost = lws_get_vhost_by_name(net->context, "default");
    net->port = vhost ? lws_get_vhost_listen_port(vhost) : net->d.port;
    srv_sink sink = {.viewer_frame = net_viewer_frame, .frame_done = net_frame_done, .user = net};
    srv_loop_add_sink(net->d.loop, &sink);
    *out = net;
    return FXC_OK;
}

int srv_net_port(const srv_net *net)
{
    return net->port;
}

fxc_result srv_net_run(srv_net *net, char *err, size_t err_cap)
{
    pthread_t thread;
    if (pthread_create(&thread, NULL, frame_thread, net) != 0) {
        snprintf(err, err_cap, "cannot start the frame thread");
        return FXC_ERR_THREADS;
    }
    for (;;) {
        if (lws_service(net->context, 0) < 0)
            break;
        if (net->byes_sent && (!net->sessions || now_s() > net->stop_deadline))
            break;
    }
    pthread_join(thread, NULL);
    /* Close what is left, then flush the traces of the viewers still present. */
    lws_context_destroy(net->context);
    net->context = NULL;
    pthread_mutex_lock(&net->lock);
    for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++) {
        net_viewer *v = &net->viewers[i];
        if (v->trace && srv_trace_writer_close(v->trace) != 0 && !net->frame_error) {
            net->frame_error = FXC_ERR_IO;
            snprintf(net->frame_error_text, sizeof net->frame_error_text, "writing %s's trace failed", v->name);
        }
        v->trace = NULL;
    }
    net->totals.frames = net->frame;
    pthread_mutex_unlock(&net->lock);
    if (net->frame_error) {
        snprintf(err, err_cap, "%s", net->frame_error_text);
        return net->frame_error;
    }
    return FXC_OK;
}

void srv_net_get_totals(const srv_net *net, srv_net_totals *out)
{
    pthread_mutex_lock((pthread_mutex_t *)&net->lock);
    *out = net->totals;
    pthread_mutex_unlock((pthread_mutex_t *)&net->lock);
}

void srv_net_free(srv_net *net)
{
    if (!net)
        return;
    if (net->context)
        lws_context_destroy(net->context);
    for (uint32_t i = 0; i < SRV_MAX_VIEWERS; i++) {
        net_viewer *v = &net->viewers[i];
        if (v->trace)
            srv_trace_writer_close(v->trace);
        if (v->state != VS_FREE)
            free_viewer(net, v);
    }
    pthread_mutex_destroy(&net->lock);
    free(net);
}
