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
 * never per frame. The display (frames and samples used, the display clock, the render cache's requests) is
 * view_display.c's; the state both share is view_viewer.h's. */
#include "view_viewer.h"

#include "rcache.h"
#include "view_camera.h"

#include <libwebsockets.h>

#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* ---- buffer pools ----------------------------------------------------------------------------------------
 */

/* Sets up a pool of count buffers (none allocated yet). */
bool view__pool_init(buffer_pool *p, uint32_t count)
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
uint32_t view__pool_take(buffer_pool *p, size_t size)
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

void view__pool_give(buffer_pool *p, uint32_t i)
{
    p->free[p->free_count++] = i;
}

void view__pool_free(buffer_pool *p)
{
    for (uint32_t i = 0; i < p->count; i++)
        free(p->bytes ? p->bytes[i] : NULL);
    free(p->bytes);
    free(p->cap);
    free(p->free);
    memset(p, 0, sizeof *p);
}

static void viewer_tick(lws_sorted_usec_list_t *sul);

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
void view__fail(view_viewer *v, const char *fmt, ...)
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

/* The next moment the viewer's timer must wake it: the next camera to generate, the next pending camera not
 * yet due, the next held frame. Due pending cameras wait for the writeable callback instead. */
void view__schedule(view_viewer *v, lws_usec_t now)
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
void view__stop(view_viewer *v, const char *reason)
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
    case VIEWER_DONE: break;
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
    double elapsed = view__scene_s(v, now);
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
    pending_camera cam = {.generated_us = now, .send_us = now + view__latency_us(v)};
    if (v->trace) {
        cam.pose = view_camera_from_trace(v->trace, index, o->fov_deg);
        cam.camera_s = v->trace->times[index] - v->client->trace_origin;
        v->next_generate_us =
            due < v->trace->count ? view__wall_us(v, v->trace->times[due] - v->client->trace_origin) : 0;
    } else {
        cam.pose =
            view_camera_generate(o->camera, &v->welcome, v->index, v->client->count, index, o->fov_deg);
        cam.camera_s = (double)index / v->fps;
        v->next_generate_us = view__wall_us(v, (double)due / v->fps);
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

/* Shows the held messages whose time (received + --latency) is not after `until`: frames count, give their
 * latency and go to the display or the render cache, samples go to the render cache; ends the viewer when it
 * has shown --frames frames or a frame for its trace's last camera. */
void view__show_frames(view_viewer *v, lws_usec_t until)
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
                view__use_samples(v, &msg);
            view__pool_give(&v->held_pool, f.buffer);
            continue;
        }
        v->held_frames--;
        v->stats->frames++;
        v->stats->frame_bytes += f.bytes;
        v->last_shown_us = f.shown_us;
        v->client->progress_frames++;
        bool going = ok && view__use_frame(v, &msg.u.frame, f.camera_s);
        view__pool_give(&v->held_pool, f.buffer);
        if (!going)
            return;
        if (f.camera_us) {
            double ms = (double)(f.shown_us - f.camera_us) / 1000.0 / view__time_scale(v); /* scene ms */
            /* The round trip the prediction uses: smoothed as TCP smooths its RTT (gain 1/8). */
            v->rtt_ms = v->rtt_measured ? v->rtt_ms + (ms - v->rtt_ms) / 8 : ms;
            v->rtt_measured = true;
            if (!view_latency_add(&v->stats->latency, ms)) {
                view__fail(v, "out of memory for latency samples");
                view__stop(v, "client out of memory");
                return;
            }
        }
        if (o->frames && v->stats->frames >= o->frames) {
            v->goal_reached = true;
            view__stop(v, "done: frames shown");
        } else if (v->trace_all_sent && f.sequence >= v->last_sequence) {
            v->goal_reached = true;
            view__stop(v, "done: the trace ended");
        }
    }
}

/* A frame or samples message: its bytes copied and held until received + --latency, when it counts as shown
 * (and is decoded again, used, and its buffer given back). */
static void viewer_take_message(view_viewer *v, const proto_msg *msg, lws_usec_t now)
{
    const view_options *o = v->client->options;
    held_frame held = {.shown_us = now + view__latency_us(v),
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
        view__show_frames(v, now);
        if (v->state != VIEWER_STREAMING)
            return;
    }
    held.buffer = view__pool_take(&v->held_pool, v->rx_len);
    if (held.buffer == UINT32_MAX) {
        view__fail(v, "out of memory for a message of %zu bytes", v->rx_len);
        view__stop(v, "client out of memory");
        return;
    }
    memcpy(v->held_pool.bytes[held.buffer], v->rx, v->rx_len);
    v->held[(v->held_head + v->held_count) % v->held_capacity] = held;
    v->held_count++;
    v->held_frames += msg->type == PROTO_FRAME;
    if (!view__latency_us(v))
        view__show_frames(v, now);
    else
        view__schedule(v, now); /* the timer may be set for later than this message's moment */
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
    return v->pending && v->held && v->out && view__pool_init(&v->held_pool, v->held_capacity) &&
           view__pool_init(&v->out_pool, v->out_capacity);
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
        view__fail(v, "the welcome names %g frames a second", welcome->fps);
        view__stop(v, "bad welcome");
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
        view__fail(v, "out of memory");
        view__stop(v, "client out of memory");
        return;
    }
    if (!view__display_setup(v)) {
        view__stop(v, "client cannot display");
        return;
    }
    v->state = VIEWER_STREAMING;
    v->next_generate_us = now;
    if (v->trace) /* the first line is due at its time after the traces' common origin */
        v->next_generate_us = view__wall_us(v, v->trace->times[0] - c->trace_origin);
    viewer_generate(v, now);
    if (camera_due(v, now))
        lws_callback_on_writable(v->wsi);
    view__schedule(v, now);
    view__display(v, now); /* display frame 0, at the welcome */
}

/* ---- messages from the server ------------------------------------------------------------------------- */

/* One whole message. Returns -1 when the connection must close now (garbage, refusal, the server's bye). */
static int viewer_message(view_viewer *v, lws_usec_t now)
{
    proto_msg msg;
    fxc_result r = proto_decode(v->rx, v->rx_len, &msg);
    if (r != FXC_OK) {
        view__fail(v, "a message from the server does not decode: %s (%zu bytes)", fxc_strerror(r),
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
    case PROTO_STATS: return 0; /* not asked for; harmless */
    case PROTO_ERROR:
        if (v->state == VIEWER_HELLO)
            view__fail(v, "server refused: %s (%s)", msg.u.error.reason, fxc_strerror(msg.u.error.code));
        else if (v->state != VIEWER_CLOSING || !v->goal_reached)
            view__fail(v, "server error: %s (%s)", msg.u.error.reason, fxc_strerror(msg.u.error.code));
        v->state = VIEWER_CLOSING;
        return -1;
    case PROTO_BYE:
        if (!v->goal_reached && v->state != VIEWER_CLOSING && (v->client->options->frames || v->trace))
            view__fail(v, "the server said bye before the viewer was done: %s", msg.u.bye.reason);
        else if (!v->client->options->quiet && v->state != VIEWER_CLOSING) {
            clear_progress(v->client);
            fprintf(stderr, "fxcache-viewer: viewer %u: the server said bye: %s\n", v->index,
                    msg.u.bye.reason);
        }
        v->goal_reached = true;
        v->state = VIEWER_CLOSING;
        return -1;
    default: break;
    }
    view__fail(v, "the server sent a %s message, which a viewer does not expect %s",
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
        view__fail(v, "the server sent a text message (the protocol is binary)");
        return -1;
    }
    if (len > v->rx_limit - v->rx_len) {
        view__fail(v, "a message from the server is larger than %zu bytes", v->rx_limit);
        return -1;
    }
    if (v->rx_len + len > v->rx_cap) {
        size_t capacity = v->rx_cap ? v->rx_cap : RX_CHUNK;
        while (capacity < v->rx_len + len)
            capacity = capacity > v->rx_limit / 2 ? v->rx_limit : capacity * 2;
        uint8_t *grown = realloc(v->rx, capacity);
        if (!grown) {
            view__fail(v, "out of memory for a message of %zu bytes", v->rx_len + len);
            return -1;
        }
        v->rx = grown;
        v->rx_cap = capacity;
    }
    if (len) /* an empty message arrives as len 0, possibly before any buffer exists (rx NULL) */
        memcpy(v->rx + v->rx_len, in, len);
    v->rx_len += len;
    if (!v->rx_header_checked && v->rx_len >= PROTO_HEADER_BYTES) {
        proto_header header;
        fxc_result r = proto_decode_header(v->rx, v->rx_len, &header);
        if (r != FXC_OK) {
            view__fail(v, "a message from the server does not decode: %s", fxc_strerror(r));
            return -1;
        }
        if (header.length > v->rx_limit - PROTO_HEADER_BYTES) {
            view__fail(v, "the server announced a message of %u bytes, more than %zu", header.length,
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
        view__fail(v, "cannot encode a %s message: %s", proto_type_name(m->type), fxc_strerror(r));
        return -1;
    }
    if (lws_write(v->wsi, v->tx + LWS_PRE, n, LWS_WRITE_BINARY) < (int)n) {
        view__fail(v, "the connection broke while sending a %s message", proto_type_name(m->type));
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
    m.u.camera.time = (double)(cam.generated_us - v->client->start_us) / 1e6 / view__time_scale(v);
    m.u.camera.pose = cam.pose;
    if (v->client->options->strategy == PROTO_STRATEGY_PREDICTIVE) {
        /* Where the camera will be when the frame rendered for it is shown: extrapolated from the previous
         * camera sent by the measured round trip. */
        double rtt_s = view__rtt_ms(v) / 1000.0;
        m.u.camera.has_predicted = true;
        m.u.camera.predicted_time = m.u.camera.time + rtt_s;
        m.u.camera.predicted =
            v->last_sent_generated_us
                ? view_pose_extrapolate(&v->last_sent_pose,
                                        (double)(v->last_sent_generated_us - v->client->start_us) / 1e6 /
                                            view__time_scale(v),
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
    } else if (v->state == VIEWER_STREAMING && view__request_due(v, now)) {
        if (view__send_request(v) != 0)
            return -1;
    }
    if (v->state == VIEWER_STREAMING) {
        if (camera_due(v, now) || view__request_due(v, now))
            lws_callback_on_writable(v->wsi);
        view__schedule(v, now);
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
    view__show_frames(v, now);
    if (v->state != VIEWER_STREAMING)
        return;
    viewer_generate(v, now);
    if (camera_due(v, now) || view__request_due(v, now))
        lws_callback_on_writable(v->wsi);
    view__schedule(v, now);
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
            view__fail(v, "cannot connect to %s: %s", o->url, in ? (const char *)in : "connection failed");
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
            view__fail(v, "the server closed the connection (close code %u)", code);
        }
        return 0;
    case LWS_CALLBACK_CLIENT_CLOSED:
        if (v->state != VIEWER_CLOSING && !v->goal_reached)
            view__fail(v, "the server closed the connection");
        viewer_closed(v);
        return 0;
    case LWS_CALLBACK_WSI_DESTROY:
        if (v->wsi == wsi || v->state != VIEWER_DONE) {
            if (v->state != VIEWER_DONE && v->state != VIEWER_CLOSING && !v->goal_reached)
                view__fail(v, "the connection ended");
            viewer_closed(v);
        }
        return 0;
    default: return 0;
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
            view__fail(v, "cannot connect to %s", o->url);
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
                view__fail(v, "%s within %g s",
                           v->state == VIEWER_CONNECTING ? "no connection" : "no welcome",
                           c->options->timeout_s);
                if (v->state == VIEWER_HELLO)
                    view__stop(v, "no welcome");
                else
                    viewer_kill(v);
            }
            break;
        case VIEWER_STREAMING: {
            lws_usec_t since =
                v->last_frame_rx_us > v->first_camera_us ? v->last_frame_rx_us : v->first_camera_us;
            if (v->first_camera_us && now - since > limit) {
                view__fail(v, "no frame for %g s", c->options->timeout_s);
                view__stop(v, "no frames");
            }
            break;
        }
        case VIEWER_CLOSING:
            if (now > v->closing_deadline_us)
                viewer_kill(v);
            break;
        case VIEWER_DONE: break;
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
                view__stop(&c.viewers[i], "interrupted");
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
        /* Frames whose payload did not decode were counted and skipped; the run still did not end well, so
         * a script can tell from the exit status. */
        if (v->stats->decode_errors)
            view__fail(v, "%llu of %llu frames did not decode", (unsigned long long)v->stats->decode_errors,
                       (unsigned long long)v->stats->frames);
        free(v->pending);
        free(v->held);
        free(v->rx);
        free(v->rgb);
        free(v->depth);
        free(v->out);
        view__pool_free(&v->held_pool);
        view__pool_free(&v->out_pool);
        free(v->display_rgb);
        free(v->samples);
        free(v->request_pixels);
        view_rc_destroy(v->rc);
        if (v->display_trace && fclose(v->display_trace) != 0)
            view__fail(v, "cannot write the display's trace");
        if (v->display_csv && fclose(v->display_csv) != 0)
            view__fail(v, "cannot write the display's figures");
    }
    free(c.viewers);
    return 0;
}
