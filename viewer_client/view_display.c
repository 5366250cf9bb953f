/* The viewer client's display (view_viewer.h): frames and samples used as they are shown, the display clock
 * (a frame every 1 / --display-fps: the last frame received, or the render cache's frame at the display's
 * camera with --reproject), the render cache's sample requests held for --latency, and --display-out. */
#include "view_viewer.h"

#include "view_camera.h"
#include "view_image.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- frames and samples shown ------------------------------------------------------------------------- */

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
bool view__use_frame(view_viewer *v, const proto_frame *frame, double camera_s)
{
    const view_options *o = v->client->options;
    bool with_depth = frame->depth != PROTO_DEPTH_NONE;
    if (!viewer_pixels(v, frame->width, frame->height, with_depth)) {
        view__fail(v, "out of memory for a %ux%u frame", frame->width, frame->height);
        view__stop(v, "client out of memory");
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
            view__fail(v, "cannot write the frame: %s", msg);
            view__stop(v, "client cannot write frames");
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
double view__rtt_ms(const view_viewer *v)
{
    if (v->rtt_measured)
        return v->rtt_ms;
    return 2.0 * v->client->options->latency_ms + 1000.0 / (v->welcome.fps * view__time_scale(v));
}

static void viewer_display_tick(lws_sorted_usec_list_t *sul);
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
        view__fail(v, "cannot write the display frame: %s", msg);
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
        view__fail(v, "cannot write the display's trace or figures in %s", o->display_out);
        return false;
    }
    return true;
}

/* One display frame: the messages due by its time shown, the camera at its time, the render cache's frame
 * (and its requests sent) or the last frame received, its figures, --display-out. Display frame k is at
 * welcome + k / --display-fps; a clock that fell behind skips to the newest due frame. */
void view__display(view_viewer *v, lws_usec_t now)
{
    const view_options *o = v->client->options;
    view_display_stats *d = &v->stats->display;
    double fps = o->display_fps;
    uint64_t due = (uint64_t)floor(view__scene_s(v, now) * fps);
    if (due > v->display_index) {
        d->skipped += due - v->display_index;
        v->display_index = due;
    }
    uint64_t index = v->display_index;
    double time_s = (double)index / fps;
    lws_usec_t at = view__wall_us(v, time_s);
    view__show_frames(v, at);
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
                                              time_s + view__rtt_ms(v) / 1000.0);
            ahead = rc_camera(&predicted);
        }
        fxc_result r = view_rc_render(v->rc, &current, predict ? &ahead : NULL, &frame);
        if (r != FXC_OK) {
            view__fail(v, "the render cache cannot render display frame %llu: %s", (unsigned long long)index,
                       fxc_strerror(r));
            view__stop(v, "client render cache failed");
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
        d->rtt_ms = view__rtt_ms(v);
        viewer_send_requests(v, &frame, &cam, &predicted, now);
        if (v->state != VIEWER_STREAMING)
            return;
    }
    d->frames++;
    d->empty_fraction_sum += empty;
    if (o->display_out && !viewer_display_out(v, index, time_s, &cam, rgb, shown, empty)) {
        view__stop(v, "client cannot write display frames");
        return;
    }
    v->display_previous = cam;
    v->display_previous_s = time_s;
    v->display_has_previous = true;
    v->display_index = index + 1;
    lws_usec_t next = view__wall_us(v, (double)v->display_index / fps);
    lws_sul_schedule(v->client->context, 0, &v->display_tick, viewer_display_tick,
                     next > now ? next - now : 1);
}

/* ---- sample requests ---------------------------------------------------------------------------------- */

/* True when the oldest queued sample request is due to be sent. */
bool view__request_due(const view_viewer *v, lws_usec_t now)
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
    double gap_us = 0.9e6 / v->welcome.fps; /* a welcome's fps of 1e-30: saturated, not wrapped below zero */
    lws_usec_t interval = (lws_usec_t)(gap_us < 1e15 ? gap_us : 1e15);
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
    uint32_t buffer = bytes ? view__pool_take(&v->out_pool, LWS_PRE + bytes) : UINT32_MAX;
    fxc_result r = FXC_ERR_NOMEM;
    if (buffer == UINT32_MAX || proto_encode(&m, v->out_pool.bytes[buffer] + LWS_PRE,
                                             v->out_pool.cap[buffer] - LWS_PRE, &r) != bytes) {
        view__fail(v, "cannot make a sample request of %u pixels: %s", count, fxc_strerror(r));
        view__stop(v, "client cannot make sample requests");
        return;
    }
    v->next_request++;
    v->last_request_us = now;
    d->requests_dropped += all - count;
    v->out[(v->out_head + v->out_count) % v->out_capacity] = (queued_message){
        .send_us = now + view__latency_us(v), .buffer = buffer, .bytes = (uint32_t)bytes, .pixels = count};
    v->out_count++;
    if (view__request_due(v, now))
        lws_callback_on_writable(v->wsi);
    else
        view__schedule(v, now);
}

/* Sends the oldest queued sample request. Returns 0, or -1 (after recording the failure). */
int view__send_request(view_viewer *v)
{
    queued_message q = v->out[v->out_head];
    v->out_head = (v->out_head + 1) % v->out_capacity;
    v->out_count--;
    int written = lws_write(v->wsi, v->out_pool.bytes[q.buffer] + LWS_PRE, q.bytes, LWS_WRITE_BINARY);
    view__pool_give(&v->out_pool, q.buffer);
    if (written < (int)q.bytes) {
        view__fail(v, "the connection broke while sending a sample-request message");
        return -1;
    }
    v->stats->display.request_messages++;
    v->stats->display.request_pixels += q.pixels;
    return 0;
}

/* A samples message shown: its samples inserted into the render cache with the camera the server says it
 * rendered them for. */
void view__use_samples(view_viewer *v, const proto_msg *msg)
{
    const proto_samples *answer = &msg->u.samples;
    view_display_stats *d = &v->stats->display;
    if (answer->request >= v->next_request) { /* an answer to a request never sent: refused, counted */
        d->insert_errors++;
        return;
    }
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
        view__display(v, lws_now_usecs());
}

/* ---- the display's set-up ------------------------------------------------------------------------------ */

/* The display's buffers, the render cache (--reproject), the --display-out files. false after recording the
 * failure. */
bool view__display_setup(view_viewer *v)
{
    const view_options *o = v->client->options;
    v->display_frame = -1;
    v->display_frame_camera_s = NAN;
    v->stats->display.fps = o->display_fps;
    v->stats->display.reproject = o->reproject;
    v->display_rgb = calloc((size_t)v->width * v->height, 3);
    if (!v->display_rgb) {
        view__fail(v, "out of memory for a %ux%u display", v->width, v->height);
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
            view__fail(v, "out of memory");
            return false;
        }
        fxc_result r = view_rc_create(&desc, &v->rc);
        if (r != FXC_OK) {
            view__fail(v, "cannot create a %ux%u render cache: %s", v->width, v->height, fxc_strerror(r));
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
            view__fail(v, "cannot create %s: %s", path, strerror(errno));
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
