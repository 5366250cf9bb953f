/* One client frame: the stages in their fixed order (the 2002 paper's Figure 1), each timed, and what they
 * leave behind for the inserts until the next frame (the winners, the z-buffer and the camera, for the sparse
 * supersede).
 *
 * Ageing (2002 3.4): "this increment is chosen based on the number of new points added to the cache such that
 * on average a point should reach the age of 128 before being overwritten". With k points inserted since the
 * previous frame into a cache of capacity N, N / k frames pass before the oldest points must make room, so a
 * frame adds 128 k / N (the fraction carried to the next frame, so that the steps add up exactly); points no
 * pixel shows add hidden_age_factor times as much. */
#include "rc_internal.h"

#include <math.h>
#include <string.h>

static uint32_t whole_step(double *carry, double step)
{
    *carry += step;
    double whole = floor(*carry);
    *carry -= whole;
    return whole > 255 ? 255 : (uint32_t)whole;
}

fxc_result view_rc_render(view_rc *rc, const view_rc_camera *cam, const view_rc_camera *predicted,
                          view_rc_frame *out)
{
    if (!rc || !cam || !out)
        return FXC_ERR_INVALID;
    double t_start = view_rc__now_ms();
    if (!rc->has_origin) {
        memcpy(rc->origin, cam->position, sizeof rc->origin);
        rc->has_origin = true;
    }
    if (!view_rc__view_setup(cam, rc->width, rc->height, rc->origin, &rc->view))
        return FXC_ERR_CAMERA;
    rc->predict = predicted && !rc->d.no_prediction;
    if (rc->predict && !view_rc__view_setup(predicted, rc->width, rc->height, rc->origin, &rc->predicted))
        return FXC_ERR_CAMERA;

    view_rc_stats stats = {0};
    stats.inserted = rc->since_inserted;
    stats.superseded = rc->since_superseded;
    stats.dropped = rc->since_dropped;
    stats.dropped_age_sum = rc->since_dropped_age_sum;
    stats.stage_ms[VIEW_RC_STAGE_UPDATE] = rc->since_update_ms;

    double base = 128.0 * (double)rc->since_inserted / (double)rc->d.capacity;
    rc->step_visible = whole_step(&rc->age_carry, base);
    rc->step_hidden = whole_step(&rc->hidden_carry, base * rc->d.hidden_age_factor);
    stats.age_step = rc->step_visible;
    stats.hidden_age_step = rc->step_hidden;

    view_rc__plan_drops(rc);

    /* The predicted projection runs inside the projection pass, chunk by chunk (rc_project.c): its row of the
     * stage table keeps only the clearing and combining of the occupancy images, and "project and tile sort"
     * holds both projections (the 2002 paper's predicted projection and its projection and tile sort). */
    double t = view_rc__now_ms(), t_next;
    if (rc->predict) {
        view_rc__predict_clear(rc);
        t_next = view_rc__now_ms();
        stats.stage_ms[VIEW_RC_STAGE_PREDICT_PROJECT] = t_next - t;
        t = t_next;
    }

    if (rc->d.no_tiling)
        view_rc__project_direct(rc);
    else
        view_rc__project_sort(rc);
    for (uint32_t c = 0; c < rc->chunk_count; c++) {
        stats.projected += rc->chunk_stat[c].projected;
        stats.migrated += rc->chunk_stat[c].migrated;
        stats.dropped += rc->chunk_stat[c].dropped;
        stats.dropped_age_sum += rc->chunk_stat[c].dropped_age_sum;
    }
    t_next = view_rc__now_ms();
    stats.stage_ms[VIEW_RC_STAGE_PROJECT_SORT] = t_next - t;
    t = t_next;
    if (rc->predict) {
        view_rc__predict_combine(rc);
        t_next = view_rc__now_ms();
        stats.stage_ms[VIEW_RC_STAGE_PREDICT_PROJECT] += t_next - t;
        t = t_next;
    }

    if (rc->d.no_tiling)
        view_rc__zbuffer_direct(rc);
    else
        view_rc__zbuffer(rc);
    t_next = view_rc__now_ms();
    stats.stage_ms[VIEW_RC_STAGE_ZBUFFER] = t_next - t;
    t = t_next;

    if (rc->d.separate_pixel_passes) {
        view_rc__depth_cull(rc);
        t_next = view_rc__now_ms();
        stats.stage_ms[VIEW_RC_STAGE_DEPTH_CULL] = t_next - t;
        t = t_next;

        view_rc__interpolate(rc);
        t_next = view_rc__now_ms();
        stats.stage_ms[VIEW_RC_STAGE_INTERPOLATE] = t_next - t;
        t = t_next;

        if (!rc->d.no_prefilter) {
            view_rc__prefilter(rc);
            t_next = view_rc__now_ms();
            stats.stage_ms[VIEW_RC_STAGE_PREFILTER] = t_next - t;
            t = t_next;
        }
    } else {
        /* The 2002 paper's depth cull, interpolate and prefilter, one band of rows at a time: one row. */
        view_rc__pixels(rc);
        t_next = view_rc__now_ms();
        stats.stage_ms[VIEW_RC_STAGE_PIXELS] = t_next - t;
        t = t_next;
    }

    view_rc__predicted_sampling(rc);
    t_next = view_rc__now_ms();
    stats.stage_ms[VIEW_RC_STAGE_PREDICT_SAMPLE] = t_next - t;
    t = t_next;

    view_rc__sampling(rc);
    t_next = view_rc__now_ms();
    stats.stage_ms[VIEW_RC_STAGE_SAMPLE] = t_next - t;
    t = t_next;

    view_rc__age(rc);
    for (uint32_t c = 0; c < rc->chunk_count; c++)
        stats.evicted += rc->chunk_stat[c].evicted;
    t_next = view_rc__now_ms();
    stats.stage_ms[VIEW_RC_STAGE_AGE] = t_next - t;

    rc->last_view = rc->view;
    rc->last_valid = true;

    for (uint32_t band = 0; band < rc->tiles_y; band++) {
        stats.culled += rc->band_culled[band];
        for (int k = 0; k < VIEW_RC_PIXEL_KINDS; k++)
            stats.pixels[k] += rc->band_kind[(size_t)band * VIEW_RC_PIXEL_KINDS + k];
    }
    stats.points = 0;
    for (uint32_t c = 0; c < rc->chunk_count; c++)
        for (uint32_t a = 0; a < 255; a++)
            stats.points += rc->chunk_hist[(size_t)c * 256 + a];
    rc->since_inserted = rc->since_superseded = rc->since_dropped = 0;
    rc->since_dropped_age_sum = 0;
    rc->since_update_ms = 0;

    memset(out, 0, sizeof *out);
    out->width = rc->width;
    out->height = rc->height;
    out->rgb = rc->rgb;
    out->depth = rc->depth;
    out->kind = rc->kind;
    out->priority = rc->priority;
    out->requests = rc->requests;
    out->request_count = rc->request_count;
    out->predicted_requests = rc->predicted_requests;
    out->predicted_count = rc->predicted_count;
    stats.total_ms = view_rc__now_ms() - t_start;
    out->stats = stats;
    return FXC_OK;
}
