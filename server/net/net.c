/* `fxcache serve`'s network side and frame clock (net.h): libwebsockets on the calling thread, the frame
 * loop on its own thread (net_frames.c), one mutex-protected table of viewer records between them
 * (net_internal.h). */
#include "net_internal.h"
#include "net_samples.h"

#include "proto.h"
#include "trace.h"

#include <arpa/inet.h>
#include <errno.h>
#include <libwebsockets.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

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
    double t0 = srv__net_now_s();
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
    if (proto_color_encode(f->codec, quality, v->rgb[buffer], w, h, ss->scratch, color_cap, &color_bytes) !=
        FXC_OK)
        return false;
    if (f->depth != PROTO_DEPTH_NONE &&
        proto_depth_encode(f->depth, v->depth[buffer], w, h, ss->scratch + color_cap, depth_cap,
                           &depth_bytes) != FXC_OK)
        return false;
    f->color = ss->scratch;
    f->color_bytes = (uint32_t)color_bytes;
    f->depth_data = depth_bytes ? ss->scratch + color_cap : NULL;
    f->depth_bytes = (uint32_t)depth_bytes;
    f->stats.encode_ms = (float)((srv__net_now_s() - t0) * 1e3);
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
        session_fail(net, ss, FXC_ERR_LIMIT, "resolution %ux%u is above the server's limit %ux%u", h->width,
                     h->height, net->d.max_width, net->d.max_height);
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
    srv__net_count_buffers(net, (int64_t)bytes);
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
    ss->tokens_time = ss->sample_tokens_time = srv__net_now_s();
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
    double t = srv__net_now_s();
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
    proto_pose rendered_pose = srv_net_strategy_pose(
        v->strategy, c, v->has_previous ? &v->previous_pose : NULL, v->previous_time, latency);
    double rendered_direction[3] = {rendered_pose.direction[0], rendered_pose.direction[1],
                                    rendered_pose.direction[2]};
    srv_camera rendered =
        srv_trace_camera_world(net->d.s, rendered_pose.position, rendered_direction, rendered_pose.fov_deg);
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
    double t = srv__net_now_s();
    ss->sample_tokens = fmin((double)net->d.camera_rate,
                             ss->sample_tokens + (t - ss->sample_tokens_time) * net->d.camera_rate);
    ss->sample_tokens_time = t;
    if (ss->sample_tokens < 1) {
        session_fail(net, ss, FXC_ERR_LIMIT, "more than %u sample requests per second", net->d.camera_rate);
        return;
    }
    ss->sample_tokens -= 1;
    srv_sample_limits limits = {net->d.max_samples, net->d.max_width, net->d.max_height};
    srv_camera cam;
    char why[200];
    fxc_result checked = srv_sample_request_check(net->d.s, &limits, q, &cam, why, sizeof why);
    if (checked != FXC_OK) {
        session_fail(net, ss, checked, "%s", why);
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
        srv__net_count_buffers(net, (int64_t)bytes);
    }
    if (v->req_pending) { /* the newest request wins */
        v->requests_dropped++;
        net->totals.sample_requests_dropped++;
    }
    int b = v->req_pending_index;
    srv_sample_request_pixels(q, v->req_pixels[b]);
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
        session_fail(net, ss, FXC_ERR_PROTOCOL, "a %s message is not for the server",
                     proto_type_name(m.type));
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
            session_fail(net, ss, FXC_ERR_TOO_LARGE,
                         "a message of %u bytes is over the server's limit of %zu", h.length, limit);
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
        net->stop_deadline = srv__net_now_s() + 1.0;
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
        bool work =
            ss->viewer->ready || ss->viewer->ans_ready || ss->viewer->stats_json || ss->viewer->fail_code;
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
    case LWS_CALLBACK_RECEIVE: on_receive(net, ss, in, len); return 0;
    case LWS_CALLBACK_SERVER_WRITEABLE:
        if (ss->closing)
            return -1;
        return on_writeable(net, ss);
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE: ss->closing = true; return 0;
    case LWS_CALLBACK_CLOSED: session_close(net, ss); return 0;
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED:
        if (net)
            on_wake(net);
        return 0;
    default: return lws_callback_http_dummy(wsi, reason, user, in, len);
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

/* ---- the server ---------------------------------------------------------------------------------------- */

/* Binds fd to addr as libwebsockets binds its listening socket (SO_REUSEADDR), to find out before it
 * whether it can: false with errno set. */
static bool bind_socket(int fd, const struct sockaddr_in *addr)
{
    int one = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    return bind(fd, (const struct sockaddr *)addr, sizeof *addr) == 0;
}

bool srv_net_resolve_bind(const char *bind, char *numeric, size_t numeric_cap, bool *loopback, char *err,
                          size_t err_cap)
{
    struct in6_addr v6;
    if (inet_pton(AF_INET6, bind, &v6) == 1) {
        snprintf(err, err_cap,
                 "--bind %s: IPv6 addresses are not supported (the server listens on IPv4 only; for loopback "
                 "use 127.0.0.1)",
                 bind);
        return false;
    }
    struct addrinfo hints = {.ai_family = AF_INET, .ai_socktype = SOCK_STREAM}, *found = NULL;
    int rc = getaddrinfo(bind, NULL, &hints, &found);
    if (rc != 0 || !found) {
        snprintf(err, err_cap, "--bind %s: not an IPv4 address or a host name with one (%s)", bind,
                 rc ? gai_strerror(rc) : "no address");
        return false;
    }
    struct sockaddr_in addr;
    memcpy(&addr, found->ai_addr, sizeof addr);
    freeaddrinfo(found);
    addr.sin_port = 0;
    if (!inet_ntop(AF_INET, &addr.sin_addr, numeric, (socklen_t)numeric_cap)) {
        snprintf(err, err_cap, "--bind %s: address does not fit", bind);
        return false;
    }
    *loopback = (ntohl(addr.sin_addr.s_addr) >> 24) == 127;
    /* libwebsockets would report a missing address in its log and go on without a listening socket */
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) {
        snprintf(err, err_cap, "--bind %s: cannot make a socket: %s", bind, strerror(errno));
        return false;
    }
    bool bound = bind_socket(fd, &addr);
    int bind_errno = errno;
    close(fd);
    if (!bound) {
        snprintf(err, err_cap, "--bind %s (%s): %s", bind, numeric,
                 bind_errno == EADDRNOTAVAIL ? "not an address of this machine" : strerror(bind_errno));
        return false;
    }
    return true;
}

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
    bool loopback;
    if (!srv_net_resolve_bind(net->d.bind, net->address, sizeof net->address, &loopback, err, err_cap)) {
        srv_net_free(net);
        return FXC_ERR_RANGE;
    }
    if (net->d.port > 0) {
        /* a port in use, found here, is one line instead of libwebsockets' three log lines and ours */
        struct sockaddr_in addr = {.sin_family = AF_INET, .sin_port = htons((uint16_t)net->d.port)};
        inet_pton(AF_INET, net->address, &addr.sin_addr);
        int fd = socket(AF_INET, SOCK_STREAM, 0);
        bool bound = fd >= 0 && bind_socket(fd, &addr);
        int bind_errno = errno;
        if (fd >= 0)
            close(fd);
        if (!bound) {
            snprintf(err, err_cap, "cannot listen on %s:%d: %s", net->address, net->d.port,
                     bind_errno == EADDRINUSE ? "the port is in use" : strerror(bind_errno));
            srv_net_free(net);
            return FXC_ERR_IO;
        }
    }
    lws_set_log_level(LLL_ERR, lws_log_line);
    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    info.port = net->d.port;
    info.iface = net->address;
    info.protocols = net_protocols;
    info.user = net;
    info.options = LWS_SERVER_OPTION_DISABLE_IPV6;
    info.gid = -1;
    info.uid = -1;
    net->context = lws_create_context(&info);
    if (!net->context) {
        snprintf(err, err_cap, "cannot listen on %s:%d (in use, or not an address of this machine)",
                 net->address, net->d.port);
        srv_net_free(net);
        return FXC_ERR_IO;
    }
    struct lws_vhost *vhost = lws_get_vhost_by_name(net->context, "default");
    net->port = vhost ? lws_get_vhost_listen_port(vhost) : net->d.port;
    srv_sink sink = {.viewer_frame = srv__net_viewer_frame, .frame_done = srv__net_frame_done, .user = net};
    srv_loop_add_sink(net->d.loop, &sink);
    *out = net;
    return FXC_OK;
}

int srv_net_port(const srv_net *net)
{
    return net->port;
}

const char *srv_net_address(const srv_net *net)
{
    return net->address;
}

fxc_result srv_net_run(srv_net *net, char *err, size_t err_cap)
{
    pthread_t thread;
    if (pthread_create(&thread, NULL, srv__net_frame_thread, net) != 0) {
        snprintf(err, err_cap, "cannot start the frame thread");
        return FXC_ERR_THREADS;
    }
    for (;;) {
        if (lws_service(net->context, 0) < 0)
            break;
        if (net->byes_sent && (!net->sessions || srv__net_now_s() > net->stop_deadline))
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
            snprintf(net->frame_error_text, sizeof net->frame_error_text, "writing %s's trace failed",
                     v->name);
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
            srv__net_free_viewer(net, v);
    }
    pthread_mutex_destroy(&net->lock);
    free(net);
}
