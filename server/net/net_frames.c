/* `fxcache serve`'s frame thread (net_internal.h): the frame clock, viewers in and out of the loop, their
 * frames, sample answers and statistics staged for the network thread (net.c). */
#include "net_internal.h"

#include "trace.h"

#include <float.h>
#include <libwebsockets.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

void srv__net_free_viewer(srv_net *net, net_viewer *v)
{
    for (int k = 0; k < 2; k++) {
        free(v->rgb[k]);
        free(v->depth[k]);
        free(v->req_pixels[k]);
        free(v->ans[k]);
    }
    free(v->stats_json);
    srv__net_count_buffers(net, -(int64_t)v->buffer_bytes);
    memset(v, 0, sizeof *v);
}

int srv__net_viewer_frame(void *user, const srv_viewer_frame *vf)
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

int srv__net_frame_done(void *user, const srv_frame_stats *stats)
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
            snprintf(net->frame_error_text, sizeof net->frame_error_text, "writing %s's trace failed",
                     v->name);
        }
        v->trace = NULL;
        srv__net_free_viewer(net, v);
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
            sample.depth =
                d > 0.0f ? d : FLT_MIN; /* the wire wants > 0 (a hit at the eye, were it possible) */
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
    double left = t - srv__net_now_s();
    if (left <= 0)
        return;
    struct timespec ts = {.tv_sec = (time_t)left, .tv_nsec = (long)((left - floor(left)) * 1e9)};
    nanosleep(&ts, NULL);
}

void *srv__net_frame_thread(void *arg)
{
    srv_net *net = arg;
    double period = 1.0 / net->d.fps, next_tick = srv__net_now_s();
    while (!*net->d.stop && !(net->d.frames && net->frame >= net->d.frames)) {
        take_viewers(net);
        if (net->clock_started) {
            srv_frame_stats st;
            fxc_result r = srv_loop_frame(net->d.loop, &st);
            if (r == FXC_ERR_SHUTDOWN)
                break; /* abandoned at the stop flag, within a tile of the signal: nothing to send */
            if (r != FXC_OK && !net->frame_error) {
                net->frame_error = FXC_ERR_IO; /* a sink could not write: it said why */
                snprintf(net->frame_error_text, sizeof net->frame_error_text,
                         "a frame's output could not be written");
            }
            stage_answers(net, st.frame);
            pthread_mutex_lock(&net->lock);
            net->frame_ms = st.frame_ms;
            pthread_mutex_unlock(&net->lock);
            net->frame++;
            if (net->d.progress)
                fprintf(stderr, "\rframe %u  %u viewers  %.1f ms   ", net->frame, st.viewer_count,
                        st.frame_ms);
        }
        answer_stats(net);
        lws_cancel_service(net->context);
        if (net->frame_error)
            break;
        /* The next tick; a late frame starts the schedule again from now (no bursts to catch up). */
        next_tick += period;
        double t = srv__net_now_s();
        if (next_tick < t)
            next_tick = t;
        while (!*net->d.stop && srv__net_now_s() < next_tick - 1e-4)
            sleep_until(fmin(next_tick, srv__net_now_s() + 0.05));
    }
    if (net->d.progress)
        fputc('\n', stderr);
    atomic_store(&net->stopping, true);
    lws_cancel_service(net->context);
    return NULL;
}
