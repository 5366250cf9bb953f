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

/* Ends a stage: the time since *t added to *stage_ms (stats start at zero, so a stage timed in two parts
 * adds up), and *t moved to now (one clock read a stage). */
static void lap(double *t, double *stage_ms)
{
    double now = view_rc__now_ms();
    *stage_ms += now - *t;
    *t = now;
}

static uint32_t whole_step(double *carry, double step)
{
    *carry += step;
    double whole = floor(*carry);
    *carry -= whole;
    return whole > 255 ? 255 : (uint32_t)whole;
}

/* ---- the dither and the ageing in one pool run ------------------------------------------------------- */

/* They are independent (the dither reads the priority image and writes the requests; the ageing reads and
 * writes the points' ages, the marks and each chunk's histogram and free slots), so on 2+ threads they share
 * one run, one barrier less a frame, and the dither takes its bands RC_DITHER_LANES at a time, as on one
 * thread: eight lanes of the vector loop cost about what four do, so one thread dithers all eight bands of a
 * 512 x 512 image (0.33 ms on the idle machine, against 0.26 ms for four on each of two threads) while the
 * other ages the points. Tasks: thread t's static range (fxc_pool_static_begin) starts with its dither groups
 * (groups t, t + T, ...) and goes on with chunks in order, so thread t ages about the chunks it owns in the
 * other passes over the store; with stealing, a thread that is done takes chunks from the others' ends. On
 * one thread (or with separate_sample_age, or the dynamic hand-out) they run apart, each timed in its row.
 * Which thread runs a task changes nothing (each writes its own outputs). */
static uint32_t dither_groups(const view_rc *rc)
{
    return (rc->tiles_y + RC_DITHER_LANES - 1) / RC_DITHER_LANES;
}

static uint32_t sample_age_tasks(const view_rc *rc)
{
    return dither_groups(rc) + rc->chunk_count;
}

/* Dither groups in thread t's range: groups t, t + T, ... */
static uint32_t groups_of(uint32_t groups, uint32_t threads, uint32_t t)
{
    return t < groups ? (groups - t + threads - 1) / threads : 0;
}

static bool sample_age_together(const view_rc *rc)
{
    if (rc->thread_count < 2 || rc->d.separate_sample_age || rc->d.dynamic_points || rc->d.dynamic_pixels)
        return false;
    /* Every thread's range must hold its dither groups (not so for tiny images on many threads). */
    uint32_t threads = rc->thread_count, groups = dither_groups(rc), count = sample_age_tasks(rc);
    for (uint32_t t = 0; t < threads; t++)
        if (fxc_pool_static_begin(count, threads, t + 1) - fxc_pool_static_begin(count, threads, t) <
            groups_of(groups, threads, t))
            return false;
    return true;
}

static void sample_age_task(void *user, uint32_t task, uint32_t worker)
{
    view_rc *rc = user;
    uint32_t threads = rc->thread_count, groups = dither_groups(rc), count = sample_age_tasks(rc);
    uint32_t t = (uint32_t)((uint64_t)task * threads / count); /* the range holding task: t or just above */
    while (t + 1 < threads && fxc_pool_static_begin(count, threads, t + 1) <= task)
        t++;
    while (fxc_pool_static_begin(count, threads, t) > task)
        t--;
    uint32_t at = task - fxc_pool_static_begin(count, threads, t);
    uint32_t mine = groups_of(groups, threads, t);
    if (at < mine) {
        view_rc__dither_group(rc, t + threads * at, RC_DITHER_LANES, worker);
        return;
    }
    uint32_t before = (groups / threads) * t + (groups % threads < t ? groups % threads : t);
    view_rc__age_chunk(rc, task - before - mine);
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
    double t = view_rc__now_ms();
    if (rc->predict) {
        view_rc__predict_clear(rc);
        lap(&t, &stats.stage_ms[VIEW_RC_STAGE_PREDICT_PROJECT]);
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
    lap(&t, &stats.stage_ms[VIEW_RC_STAGE_PROJECT_SORT]);
    if (rc->predict) {
        view_rc__predict_combine(rc);
        lap(&t, &stats.stage_ms[VIEW_RC_STAGE_PREDICT_PROJECT]);
    }

    if (rc->d.no_tiling)
        view_rc__zbuffer_direct(rc);
    else
        view_rc__zbuffer(rc);
    lap(&t, &stats.stage_ms[VIEW_RC_STAGE_ZBUFFER]);

    if (rc->d.separate_pixel_passes) {
        view_rc__depth_cull(rc);
        lap(&t, &stats.stage_ms[VIEW_RC_STAGE_DEPTH_CULL]);

        view_rc__interpolate(rc);
        lap(&t, &stats.stage_ms[VIEW_RC_STAGE_INTERPOLATE]);

        if (!rc->d.no_prefilter) {
            view_rc__prefilter(rc);
            lap(&t, &stats.stage_ms[VIEW_RC_STAGE_PREFILTER]);
        }
    } else {
        /* The 2002 paper's depth cull, interpolate and prefilter, one band of rows at a time: one row. */
        view_rc__pixels(rc);
        lap(&t, &stats.stage_ms[VIEW_RC_STAGE_PIXELS]);
    }

    view_rc__predicted_sampling(rc);
    lap(&t, &stats.stage_ms[VIEW_RC_STAGE_PREDICT_SAMPLE]);

    view_rc__sampling_quotas(rc);
    if (sample_age_together(rc)) {
        /* The dither and the ageing share one pool run (their own rows keep the serial steps around it). */
        lap(&t, &stats.stage_ms[VIEW_RC_STAGE_SAMPLE]);
        fxc_pool_run_static(rc->pool, sample_age_tasks(rc), sample_age_task, rc, true);
        lap(&t, &stats.stage_ms[VIEW_RC_STAGE_SAMPLE_AGE]);
        view_rc__free_stack(rc);
    } else {
        view_rc__sampling(rc);
        lap(&t, &stats.stage_ms[VIEW_RC_STAGE_SAMPLE]);
        view_rc__age(rc);
    }
    for (uint32_t c = 0; c < rc->chunk_count; c++)
        stats.evicted += rc->chunk_stat[c].evicted;
    lap(&t, &stats.stage_ms[VIEW_RC_STAGE_AGE]);

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
