/* The render cache's owner struct and its point store: creation with every default resolved in one place, the
 * one allocation everything lives in, and the two ways points come in (a whole frame, or sparse samples).
 *
 * Points come in at the end of the store (the insert list, placed by the next frame's tile sort) after the
 * points they replace were marked evicted:
 *   - a frame replaces every cached point it saw: one pass projects all points into the frame's camera and
 *     evicts those that are not behind the frame's depth at their pixel by more than supersede_ratio (the new
 *     frame is the truth for everything it shows; an old point of the same surface would otherwise fight the new
 *     one in the z-buffer at nearly the same depth, and show stale colour half the time);
 *   - a sample replaces the point the last frame showed at its place (found through the last frame's winners,
 *     so it costs nothing per cached point), and when the colours differ the neighbours' points age faster:
 *     their shading has probably changed too (1999 slide 21, "color change heuristic"; 2002 3.4).
 * When the store has no room for the points coming in, it is compacted on the spot: evicted points go, then the
 * oldest (the frame's tile sort drops the oldest down to capacity anyway; this is the rare case of more inserts
 * between two frames than insert_reserve). */
#include "rc_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

double view_rc__now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

const char *view_rc_stage_name(int stage)
{
    static const char *const names[] = {
#define VIEW_RC_STAGE_NAME(name, text) text,
        VIEW_RC_STAGES(VIEW_RC_STAGE_NAME)
#undef VIEW_RC_STAGE_NAME
    };
    return stage >= 0 && stage < VIEW_RC_STAGE_COUNT ? names[stage] : "unknown";
}

/* ---- creation ---------------------------------------------------------------------------------------- */

/* Fills the defaults into d; false when a field is out of range. */
static bool resolve_desc(view_rc_desc *d)
{
    if (d->width == 0 || d->height == 0 || d->width > VIEW_RC_MAX_SIDE || d->height > VIEW_RC_MAX_SIDE)
        return false;
    uint64_t pixels = (uint64_t)d->width * d->height;
    if (d->sample_budget == 0)
        d->sample_budget = pixels / 32 > 0 ? (uint32_t)(pixels / 32) : 1;
    if (d->sample_budget > pixels)
        return false;
    if (d->capacity == 0)
        d->capacity = (uint32_t)(2 * pixels);
    if (d->insert_reserve == 0)
        d->insert_reserve = 4 * d->sample_budget;
    if ((uint64_t)d->capacity + d->insert_reserve > UINT32_MAX - 1)
        return false;
    if (d->tile_size == 0)
        d->tile_size = 64;
    if (d->tile_size > VIEW_RC_MAX_SIDE)
        d->tile_size = VIEW_RC_MAX_SIDE;
    if (d->threads == 0)
        d->threads = 1;
    if (d->threads > VIEW_RC_MAX_THREADS)
        return false;
    if (d->cull_ratio == 0)
        d->cull_ratio = 0.1f;
    if (d->supersede_ratio == 0)
        d->supersede_ratio = 0.02f;
    if (d->hidden_age_factor == 0)
        d->hidden_age_factor = 2.0f;
    if (!(d->cull_ratio > 0 && d->cull_ratio < 1e6f) || !(d->supersede_ratio > 0 && d->supersede_ratio < 1e6f) ||
        !(d->hidden_age_factor >= 1 && d->hidden_age_factor <= 256))
        return false;
    if (d->change_threshold == 0)
        d->change_threshold = 32;
    if (d->change_penalty == 0)
        d->change_penalty = 64;
    return true;
}

/* Lays arrays out in one block: offsets aligned to 64 bytes, overflow checked. */
typedef struct rc_layout {
    size_t bytes;
    bool overflow;
} rc_layout;

static size_t take(rc_layout *l, size_t count, size_t size)
{
    size_t at = (l->bytes + 63) & ~(size_t)63;
    if (at < l->bytes || (size != 0 && count > (SIZE_MAX - at) / size)) {
        l->overflow = true;
        return 0;
    }
    l->bytes = at + count * size;
    return at;
}

fxc_result view_rc_create(const view_rc_desc *desc, view_rc **out)
{
    if (!out)
        return FXC_ERR_INVALID;
    *out = NULL;
    view_rc_desc d = desc ? *desc : (view_rc_desc){0};
    if (!resolve_desc(&d))
        return FXC_ERR_INVALID;
    view_rc *rc = calloc(1, sizeof *rc);
    if (!rc)
        return FXC_ERR_NOMEM;
    rc->d = d;
    rc->width = d.width;
    rc->height = d.height;
    rc->pixels = (size_t)d.width * d.height;
    rc->thread_count = d.threads;

    /* Tiles: square, grown until there are at most VIEW_RC_MAX_TILES (the per-chunk counts are chunks x lists). */
    uint32_t side = d.tile_size;
    for (;;) {
        uint32_t tx = (d.width + side - 1) / side, ty = (d.height + side - 1) / side;
        if ((uint64_t)tx * ty <= VIEW_RC_MAX_TILES) {
            rc->tiles_x = tx;
            rc->tiles_y = ty;
            break;
        }
        side *= 2;
    }
    rc->tile_w = side < d.width ? side : d.width;
    rc->tile_h = side < d.height ? side : d.height;
    rc->tiles_x = (d.width + rc->tile_w - 1) / rc->tile_w;
    rc->tiles_y = (d.height + rc->tile_h - 1) / rc->tile_h;
    rc->tile_count = rc->tiles_x * rc->tiles_y;
    rc->list_count = rc->tile_count + 1;
    rc->slots = d.capacity + d.insert_reserve;
    rc->chunk_size = rc->slots / 128 + 1;
    if (rc->chunk_size < 4096)
        rc->chunk_size = 4096;
    rc->chunk_max = (rc->slots + rc->chunk_size - 1) / rc->chunk_size;
    rc->low_w = (d.width + 3) / 4;
    rc->low_h = (d.height + 3) / 4;

    rc_layout l = {0};
    size_t o_col_tile = take(&l, d.width, sizeof(uint16_t));
    size_t o_row_tile = take(&l, d.height, sizeof(uint32_t));
    size_t o_rec[2], o_prj[2];
    for (int k = 0; k < 2; k++) {
        o_rec[k] = take(&l, rc->slots, sizeof(rc_rec));
        o_prj[k] = take(&l, rc->slots, sizeof(rc_prj));
    }
    size_t o_dest = take(&l, rc->slots, sizeof(uint16_t));
    size_t o_list_start = take(&l, rc->list_count + 1, sizeof(uint32_t));
    size_t o_next_start = take(&l, rc->list_count + 1, sizeof(uint32_t));
    size_t o_counts = take(&l, (size_t)rc->chunk_max * (rc->list_count + 1), sizeof(uint32_t));
    size_t o_chunk_hist = take(&l, (size_t)rc->chunk_max * 256, sizeof(uint32_t));
    size_t o_chunk_quota = take(&l, rc->chunk_max, sizeof(uint32_t));
    size_t o_chunk_stat = take(&l, rc->chunk_max, sizeof(rc_chunk_stat));
    size_t o_zbuf = take(&l, rc->pixels, sizeof(float));
    size_t o_win = take(&l, rc->pixels, sizeof(uint32_t));
    size_t o_pt = take(&l, rc->pixels, sizeof(uint32_t));
    size_t o_rgb = take(&l, rc->pixels, 3);
    size_t o_depth = take(&l, rc->pixels, sizeof(float));
    size_t o_kind = take(&l, rc->pixels, 1);
    size_t o_priority = take(&l, rc->pixels, 1);
    size_t o_chosen = take(&l, rc->pixels, 1);
    size_t o_stretch_x2 = take(&l, d.width, sizeof(float));
    size_t o_stretch_y2 = take(&l, d.height, sizeof(float));
    size_t o_tile_need = take(&l, rc->tile_count, sizeof(uint32_t));
    size_t o_tile_culled = take(&l, rc->tile_count, sizeof(uint32_t));
    size_t o_tile_kind = take(&l, (size_t)rc->tile_count * VIEW_RC_PIXEL_KINDS, sizeof(uint32_t));
    size_t o_tile_weight = take(&l, rc->tile_count, sizeof(uint64_t));
    size_t o_band_weight = take(&l, rc->tiles_y, sizeof(uint64_t));
    size_t o_band_quota = take(&l, rc->tiles_y, sizeof(uint32_t));
    size_t o_band_offset = take(&l, rc->tiles_y, sizeof(uint32_t));
    size_t o_requests = take(&l, d.sample_budget, sizeof(view_rc_pixel));
    size_t o_predicted = take(&l, d.sample_budget / 2 + 1, sizeof(view_rc_pixel));
    size_t o_workers = take(&l, d.threads, sizeof(rc_worker));
    size_t o_box[VIEW_RC_MAX_THREADS], o_occupied[VIEW_RC_MAX_THREADS], o_err[VIEW_RC_MAX_THREADS];
    for (uint32_t t = 0; t < d.threads; t++) {
        o_box[t] = take(&l, (size_t)(rc->tile_h + 6) * rc->tile_w * 4, sizeof(uint32_t));
        o_occupied[t] = take(&l, (size_t)rc->low_w * rc->low_h, 1);
        o_err[t] = take(&l, 2 * ((size_t)d.width + 2), sizeof(float));
    }
    if (l.overflow) {
        free(rc);
        return FXC_ERR_INVALID;
    }
    char *block = aligned_alloc(64, (l.bytes + 63) & ~(size_t)63);
    if (!block) {
        free(rc);
        return FXC_ERR_NOMEM;
    }
    rc->block = block;
    rc->memory_bytes = l.bytes + sizeof *rc;
    rc->col_tile = (uint16_t *)(block + o_col_tile);
    rc->row_tile = (uint32_t *)(block + o_row_tile);
    for (int k = 0; k < 2; k++) {
        rc->rec[k] = (rc_rec *)(block + o_rec[k]);
        rc->prj[k] = (rc_prj *)(block + o_prj[k]);
    }
    rc->dest = (uint16_t *)(block + o_dest);
    rc->list_start = (uint32_t *)(block + o_list_start);
    rc->next_start = (uint32_t *)(block + o_next_start);
    rc->counts = (uint32_t *)(block + o_counts);
    rc->chunk_hist = (uint32_t *)(block + o_chunk_hist);
    rc->chunk_quota = (uint32_t *)(block + o_chunk_quota);
    rc->chunk_stat = (rc_chunk_stat *)(block + o_chunk_stat);
    rc->zbuf = (float *)(block + o_zbuf);
    rc->win = (uint32_t *)(block + o_win);
    rc->pt = (uint32_t *)(block + o_pt);
    rc->rgb = (uint8_t *)(block + o_rgb);
    rc->depth = (float *)(block + o_depth);
    rc->kind = (uint8_t *)(block + o_kind);
    rc->priority = (uint8_t *)(block + o_priority);
    rc->chosen = (uint8_t *)(block + o_chosen);
    rc->stretch_x2 = (float *)(block + o_stretch_x2);
    rc->stretch_y2 = (float *)(block + o_stretch_y2);
    rc->tile_need = (uint32_t *)(block + o_tile_need);
    rc->tile_culled = (uint32_t *)(block + o_tile_culled);
    rc->tile_kind = (uint32_t *)(block + o_tile_kind);
    rc->tile_weight = (uint64_t *)(block + o_tile_weight);
    rc->band_weight = (uint64_t *)(block + o_band_weight);
    rc->band_quota = (uint32_t *)(block + o_band_quota);
    rc->band_offset = (uint32_t *)(block + o_band_offset);
    rc->requests = (view_rc_pixel *)(block + o_requests);
    rc->predicted_requests = (view_rc_pixel *)(block + o_predicted);
    rc->workers = (rc_worker *)(block + o_workers);
    for (uint32_t t = 0; t < d.threads; t++) {
        rc->workers[t].box = (uint32_t *)(block + o_box[t]);
        rc->workers[t].occupied = (uint8_t *)(block + o_occupied[t]);
        rc->workers[t].err = (float *)(block + o_err[t]);
    }

    for (uint32_t x = 0; x < d.width; x++)
        rc->col_tile[x] = (uint16_t)(x / rc->tile_w);
    for (uint32_t y = 0; y < d.height; y++)
        rc->row_tile[y] = (y / rc->tile_h) * rc->tiles_x;
    memset(rc->list_start, 0, (rc->list_count + 1) * sizeof(uint32_t));
    memset(rc->chunk_hist, 0, (size_t)rc->chunk_max * 256 * sizeof(uint32_t));
    memset(rc->win, 0xFF, rc->pixels * sizeof(uint32_t));
    for (size_t p = 0; p < rc->pixels; p++)
        rc->pt[p] = RC_EMPTY_PT;
    rc->drop_age = RC_AGE_NO_DROP;

    rc->pool = view_rc__pool_create(d.threads);
    if (!rc->pool) {
        free(block);
        free(rc);
        return FXC_ERR_THREADS;
    }
    *out = rc;
    return FXC_OK;
}

void view_rc_destroy(view_rc *rc)
{
    if (!rc)
        return;
    view_rc__pool_free(rc->pool);
    free(rc->block);
    free(rc);
}

view_rc_desc view_rc_resolved_desc(const view_rc *rc)
{
    return rc->d;
}

size_t view_rc_memory_bytes(const view_rc *rc)
{
    return rc->memory_bytes;
}

/* ---- the store --------------------------------------------------------------------------------------- */

void view_rc__recount_ages(view_rc *rc)
{
    const rc_rec *rec = rc->rec[rc->cur];
    uint32_t end = rc->placed + rc->pending;
    memset(rc->chunk_hist, 0, (size_t)rc->chunk_max * 256 * sizeof(uint32_t));
    for (uint32_t i = 0; i < end; i++) {
        uint32_t age = rc_age(rec[i].rgba);
        if (age != RC_AGE_EVICTED)
            rc->chunk_hist[(size_t)(i / rc->chunk_size) * 256 + age]++;
    }
}

/* Changes record i's age (and its chunk's histogram). */
static void set_age(view_rc *rc, uint32_t i, uint32_t age)
{
    rc_rec *r = &rc->rec[rc->cur][i];
    uint32_t old = rc_age(r->rgba);
    uint32_t *hist = rc->chunk_hist + (size_t)(i / rc->chunk_size) * 256;
    if (old != RC_AGE_EVICTED)
        hist[old]--;
    if (age != RC_AGE_EVICTED)
        hist[age]++;
    r->rgba = (r->rgba & 0x00FFFFFFu) | (age << 24);
}

/* The ages of all live records, summed over chunks. Returns the live count. */
static uint64_t total_ages(const view_rc *rc, uint64_t hist[256])
{
    memset(hist, 0, 256 * sizeof(uint64_t));
    uint64_t live = 0;
    for (uint32_t c = 0; c < rc->chunk_max; c++)
        for (uint32_t a = 0; a < 255; a++) {
            hist[a] += rc->chunk_hist[(size_t)c * 256 + a];
            live += rc->chunk_hist[(size_t)c * 256 + a];
        }
    return live;
}

/* The oldest `drop` live records: all of age above *age_out and *take_out of age *age_out (drop > 0, at most
 * the live count). */
static void oldest(const uint64_t hist[256], uint64_t drop, uint32_t *age_out, uint64_t *take_out)
{
    uint64_t above = 0;
    for (int a = 254; a >= 0; a--) {
        if (above + hist[a] >= drop) {
            *age_out = (uint32_t)a;
            *take_out = drop - above;
            return;
        }
        above += hist[a];
    }
    *age_out = 0;
    *take_out = hist[0];
}

/* Compacts the store in place so that `incoming` more records fit: evicted records go, then the oldest. The
 * lists keep their order; the last frame's winners no longer point at the right records. */
static void make_room(view_rc *rc, uint32_t incoming)
{
    uint64_t hist[256];
    uint64_t live = total_ages(rc, hist);
    uint64_t drop = live + incoming > rc->slots ? live + incoming - rc->slots : 0;
    uint32_t drop_age = RC_AGE_NO_DROP;
    uint64_t take = 0;
    if (drop > 0)
        oldest(hist, drop, &drop_age, &take);
    rc_rec *rec = rc->rec[rc->cur];
    uint32_t write = 0;
    /* Lists 0..list_count-1, then the insert list as one more. */
    for (uint32_t list = 0; list <= rc->list_count; list++) {
        uint32_t begin = list < rc->list_count ? rc->list_start[list] : rc->placed;
        uint32_t end = list < rc->list_count ? rc->list_start[list + 1] : rc->placed + rc->pending;
        if (list < rc->list_count)
            rc->list_start[list] = write;
        else
            rc->placed = write;
        for (uint32_t i = begin; i < end; i++) {
            uint32_t age = rc_age(rec[i].rgba);
            if (age == RC_AGE_EVICTED)
                continue;
            if (age > drop_age || (age == drop_age && take > 0)) {
                if (age == drop_age)
                    take--;
                rc->since_dropped++;
                rc->since_dropped_age_sum += age;
                continue;
            }
            rec[write++] = rec[i];
        }
    }
    rc->list_start[rc->list_count] = rc->placed;
    rc->pending = write - rc->placed;
    rc->last_valid = false;
    view_rc__recount_ages(rc);
}

/* Appends a record for the point at distance `dist` along dir from the view's origin. */
static void append_point(view_rc *rc, const rc_view *v, const float dir[3], float dist, const uint8_t rgb[3])
{
    uint32_t i = rc->placed + rc->pending++;
    double d = isinf(dist) ? VIEW_RC_SKY_DISTANCE : (double)dist;
    rc_rec *r = &rc->rec[rc->cur][i];
    r->x = (float)(v->origin[0] + d * (double)dir[0] - rc->origin[0]);
    r->y = (float)(v->origin[1] + d * (double)dir[1] - rc->origin[1]);
    r->z = (float)(v->origin[2] + d * (double)dir[2] - rc->origin[2]);
    r->rgba = (uint32_t)rgb[0] | (uint32_t)rgb[1] << 8 | (uint32_t)rgb[2] << 16;
    rc->chunk_hist[(size_t)(i / rc->chunk_size) * 256]++;
}

static bool depth_usable(float depth)
{
    return depth > 0; /* false for NaN and <= 0; +inf is the sky */
}

/* Sets up an insert's camera (and the cache's origin at the first insert). */
static fxc_result insert_view(view_rc *rc, const view_rc_camera *cam, uint32_t width, uint32_t height, rc_view *v)
{
    if (!cam || width == 0 || height == 0 || width > VIEW_RC_MAX_SIDE || height > VIEW_RC_MAX_SIDE)
        return FXC_ERR_INVALID;
    double origin[3] = {cam->position[0], cam->position[1], cam->position[2]};
    if (!view_rc__view_setup(cam, width, height, rc->has_origin ? rc->origin : origin, v))
        return FXC_ERR_CAMERA;
    if (!rc->has_origin) {
        memcpy(rc->origin, origin, sizeof origin);
        rc->has_origin = true;
    }
    return FXC_OK;
}

fxc_result view_rc_insert_frame(view_rc *rc, const view_rc_camera *cam, uint32_t width, uint32_t height,
                                const uint8_t *rgb, const float *depth)
{
    if (!rc || !rgb || !depth)
        return FXC_ERR_INVALID;
    double t0 = view_rc__now_ms();
    rc_view v;
    fxc_result result = insert_view(rc, cam, width, height, &v);
    if (result != FXC_OK)
        return result;
    size_t pixels = (size_t)width * height;
    uint64_t incoming = 0;
    for (size_t p = 0; p < pixels; p++)
        incoming += depth_usable(depth[p]);
    if (incoming > rc->d.capacity)
        return FXC_ERR_RANGE;

    /* Every cached point the frame saw goes: it is not behind the frame's surface at its pixel. */
    rc_rec *rec = rc->rec[rc->cur];
    float keep = 1.0f + rc->d.supersede_ratio;
    uint32_t end = rc->placed + rc->pending;
    for (uint32_t i = 0; i < end; i++) {
        if (rc_age(rec[i].rgba) == RC_AGE_EVICTED)
            continue;
        uint32_t x, y;
        float zc;
        if (!rc_project(&v, rec[i].x, rec[i].y, rec[i].z, &x, &y, &zc))
            continue;
        float d = depth[(size_t)y * width + x];
        if (!depth_usable(d))
            continue;
        float dx = rec[i].x - v.rel[0], dy = rec[i].y - v.rel[1], dz = rec[i].z - v.rel[2];
        float limit = d * keep;
        if (isinf(d) || dx * dx + dy * dy + dz * dz < limit * limit) {
            set_age(rc, i, RC_AGE_EVICTED);
            rc->since_superseded++;
        }
    }
    if ((uint64_t)rc->placed + rc->pending + incoming > rc->slots)
        make_room(rc, (uint32_t)incoming);

    for (uint32_t y = 0; y < height; y++)
        for (uint32_t x = 0; x < width; x++) {
            size_t p = (size_t)y * width + x;
            if (!depth_usable(depth[p]))
                continue;
            float dir[3];
            view_rc__view_ray(&v, (float)x + 0.5f, (float)y + 0.5f, dir);
            append_point(rc, &v, dir, depth[p], rgb + 3 * p);
        }
    rc->since_inserted += (uint32_t)incoming;
    rc->since_update_ms += view_rc__now_ms() - t0;
    return FXC_OK;
}

/* Ages the point the last frame showed at pixel q by penalty (evicted at 255, unless eviction is off). */
static void penalise(view_rc *rc, uint32_t q)
{
    uint32_t w = rc->win[q];
    if (rc->pt[q] == RC_EMPTY_PT || w == RC_NO_POINT)
        return;
    uint32_t age = rc_age(rc->rec[rc->cur][w].rgba);
    if (age == RC_AGE_EVICTED)
        return;
    age += rc->d.change_penalty;
    uint32_t top = rc->d.no_eviction ? 254 : 255;
    set_age(rc, w, age > top ? top : age);
}

fxc_result view_rc_insert_samples(view_rc *rc, const view_rc_camera *cam, uint32_t width, uint32_t height,
                                  const view_rc_sample *samples, uint32_t count)
{
    if (!rc || (!samples && count > 0))
        return FXC_ERR_INVALID;
    double t0 = view_rc__now_ms();
    rc_view v;
    fxc_result result = insert_view(rc, cam, width, height, &v);
    if (result != FXC_OK)
        return result;
    uint32_t incoming = 0;
    for (uint32_t s = 0; s < count; s++)
        incoming += samples[s].x < width && samples[s].y < height && depth_usable(samples[s].depth);
    if (incoming > rc->d.capacity)
        return FXC_ERR_RANGE;
    if ((uint64_t)rc->placed + rc->pending + incoming > rc->slots)
        make_room(rc, incoming);

    const rc_view *last = &rc->last_view;
    float keep = 1.0f + rc->d.supersede_ratio;
    for (uint32_t s = 0; s < count; s++) {
        const view_rc_sample *sample = &samples[s];
        if (!(sample->x < width && sample->y < height && depth_usable(sample->depth)))
            continue;
        float dir[3];
        view_rc__view_ray(&v, (float)sample->x + 0.5f, (float)sample->y + 0.5f, dir);
        append_point(rc, &v, dir, sample->depth, sample->rgb);
        const rc_rec *r = &rc->rec[rc->cur][rc->placed + rc->pending - 1];
        uint32_t qx, qy;
        float zc;
        if (!rc->last_valid || !rc_project(last, r->x, r->y, r->z, &qx, &qy, &zc))
            continue;
        /* The point the last frame showed there, unless it lies well behind the new sample. */
        uint32_t q = qy * last->width + qx, w = rc->win[q];
        if (rc->pt[q] == RC_EMPTY_PT || w == RC_NO_POINT)
            continue;
        uint32_t old = rc->rec[rc->cur][w].rgba;
        if (rc_age(old) == RC_AGE_EVICTED || !(rc->zbuf[q] < zc * keep))
            continue;
        int change = 0;
        for (int k = 0; k < 3; k++) {
            int diff = abs((int)((old >> (8 * k)) & 0xFF) - (int)sample->rgb[k]);
            change = diff > change ? diff : change;
        }
        if (change > rc->d.change_threshold)
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) {
                    int64_t nx = (int64_t)qx + dx, ny = (int64_t)qy + dy;
                    if ((dx || dy) && nx >= 0 && ny >= 0 && nx < last->width && ny < last->height)
                        penalise(rc, (uint32_t)ny * last->width + (uint32_t)nx);
                }
        set_age(rc, w, RC_AGE_EVICTED);
        rc->since_superseded++;
    }
    rc->since_inserted += incoming;
    rc->since_update_ms += view_rc__now_ms() - t0;
    return FXC_OK;
}

uint32_t view_rc_point_count(const view_rc *rc)
{
    uint64_t hist[256];
    return (uint32_t)total_ages(rc, hist);
}

uint32_t view_rc_points(const view_rc *rc, uint32_t first, uint32_t count, view_rc_point *out)
{
    const rc_rec *rec = rc->rec[rc->cur];
    uint32_t end = rc->placed + rc->pending, seen = 0, copied = 0;
    for (uint32_t i = 0; i < end && copied < count; i++) {
        uint32_t rgba = rec[i].rgba;
        if (rc_age(rgba) == RC_AGE_EVICTED)
            continue;
        if (seen++ < first)
            continue;
        view_rc_point *p = &out[copied++];
        p->position[0] = rc->origin[0] + (double)rec[i].x;
        p->position[1] = rc->origin[1] + (double)rec[i].y;
        p->position[2] = rc->origin[2] + (double)rec[i].z;
        p->rgb[0] = (uint8_t)rgba;
        p->rgb[1] = (uint8_t)(rgba >> 8);
        p->rgb[2] = (uint8_t)(rgba >> 16);
        p->age = (uint8_t)rc_age(rgba);
    }
    return copied;
}
