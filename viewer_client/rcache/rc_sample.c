/* Sampling: which pixels the client asks the server to render next.
 *
 * Predicted sampling (2002 3.1): every quarter-resolution pixel of the predicted camera that no point landed
 * in is requested (its middle pixel at full resolution); when there are more than half the budget, every n-th
 * in scanline order, evenly spread. The rest of the budget goes to the normal sampling.
 *
 * Normal sampling (1999, slide 19): an error-diffusion dither over the priority image "concentrates pixels in
 * high priority regions" and "maintains good spatial distribution". The image is cut into bands (the tile
 * rows) that are dithered independently, so that threads can share the work and the result does not depend on
 * how many there are. Each band gets a share of the count proportional to its sum of priority + 1 (the + 1
 * lets fresh points be refreshed too, rarely), by largest remainder and at most its pixel count; within the
 * band a serpentine Floyd-Steinberg pass over (priority + 1) * share / band sum chooses pixels where the
 * running value reaches 1/2, the error going 7/16 ahead, 3/16 below behind, 5/16 below, 1/16 below ahead
 * (shares that would leave the band are given to those that stay). Diffusion keeps the band's sum within a
 * rounding of its share; the last few are then trimmed (lowest priority first) or topped up (highest first),
 * so the count is exact. */
#include "rc_internal.h"

#include <string.h>

/* ---- predicted sampling -------------------------------------------------------------------------------- */

void view_rc__predicted_sampling(view_rc *rc)
{
    rc->predicted_count = 0;
    if (!rc->predict)
        return;
    const uint8_t *occupied = rc->workers[0].occupied;
    size_t low = (size_t)rc->low_w * rc->low_h;
    uint64_t empty = 0;
    for (size_t p = 0; p < low; p++)
        empty += !occupied[p];
    uint64_t most = rc->d.sample_budget / 2, take = empty < most ? empty : most;
    if (take == 0)
        return;
    uint64_t j = 0;
    for (size_t p = 0; p < low; p++) {
        if (occupied[p])
            continue;
        if ((j + 1) * take / empty > j * take / empty) {
            uint32_t lx = (uint32_t)(p % rc->low_w), ly = (uint32_t)(p / rc->low_w);
            uint32_t x_end = 4 * lx + 4 < rc->width ? 4 * lx + 4 : rc->width;
            uint32_t y_end = 4 * ly + 4 < rc->height ? 4 * ly + 4 : rc->height;
            view_rc_pixel *out = &rc->predicted_requests[rc->predicted_count++];
            out->x = (uint16_t)((4 * lx + x_end) / 2);
            out->y = (uint16_t)((4 * ly + y_end) / 2);
        }
        j++;
    }
}

/* ---- band quotas --------------------------------------------------------------------------------------- */

void view_rc__band_quotas(const uint64_t *weight, const uint32_t *pixels, uint32_t bands, uint32_t count,
                          uint32_t *quota)
{
    /* Largest remainder over the bands not yet at their pixel count; a band whose share would exceed its
     * pixels is capped and the others share the rest again. Each round caps at least one band or ends. */
    uint8_t capped[VIEW_RC_MAX_TILES];
    uint64_t remainder[VIEW_RC_MAX_TILES];
    memset(capped, 0, bands);
    uint32_t left = count;
    for (;;) {
        uint64_t sum = 0;
        for (uint32_t b = 0; b < bands; b++)
            if (!capped[b])
                sum += weight[b];
        uint32_t given = 0;
        for (uint32_t b = 0; b < bands; b++) {
            if (capped[b])
                continue;
            if (sum == 0) {
                quota[b] = 0;
                remainder[b] = 0;
                continue;
            }
            quota[b] = (uint32_t)((uint64_t)left * weight[b] / sum);
            remainder[b] = (uint64_t)left * weight[b] % sum;
            given += quota[b];
        }
        /* The units left over go to the largest remainders (the lower band first on ties). */
        for (uint32_t extra = left - given; extra > 0; extra--) {
            uint32_t best = bands;
            for (uint32_t b = 0; b < bands; b++)
                if (!capped[b] && remainder[b] != UINT64_MAX &&
                    (best == bands || remainder[b] > remainder[best]))
                    best = b;
            if (best == bands)
                break;
            quota[best]++;
            remainder[best] = UINT64_MAX; /* one extra each at most */
        }
        bool over = false;
        for (uint32_t b = 0; b < bands; b++)
            if (!capped[b] && quota[b] > pixels[b]) {
                quota[b] = pixels[b];
                capped[b] = 1;
                left -= pixels[b];
                over = true;
            }
        if (!over)
            return;
    }
}

/* ---- one band's dither --------------------------------------------------------------------------------- */

/* Pixel x's value plus the error it received; chooses it when that reaches 1/2 (no branch: the choice is as
 * likely as not) and returns what is left to pass on. */
FXC_HOT_INLINE float pick(const uint8_t *line, uint8_t *mark, const float *here, uint32_t x, float scale,
                          uint32_t *picked)
{
    float value = (float)(line[x] + 1) * scale + here[x];
    uint32_t chosen = value >= 0.5f;
    mark[x] = (uint8_t)chosen;
    *picked += chosen;
    return value - (float)chosen;
}

/* One band's row being diffused. */
typedef struct rc_lane {
    const uint8_t *line; /* the row's priorities */
    uint8_t *mark;       /* the row's choices */
    float *here, *below; /* errors into this row (read) and into the next (written), width + 2 each */
    float scale;         /* (priority + 1) * scale sums to the band's quota */
    uint32_t picked;
} rc_lane;

/* One row of Floyd-Steinberg in four bands at once (the bands are independent: their chains of error
 * interleave in the processor; eight at once was slower, 1.1 against 0.7 ms: the lanes' state no longer fits
 * in registers), left to right (forward) or right to left: 7/16 of the error ahead, 3/16 below behind, 5/16
 * below, 1/16 below ahead; at the row's ends the shares that would leave the band go to the others in
 * proportion. Not a band's last row (diffuse_last_row). The error ahead and the three errors below that are
 * not final yet stay in registers (the additions happen in the same order as into memory, so the floats are
 * those of the plain loop); each lane's state is local, out of reach of the byte stores of the choices. */
#define RC_LANE_VARS(k)                                                                                      \
    const uint8_t *line##k = lanes[k].line;                                                                  \
    uint8_t *mark##k = lanes[k].mark;                                                                        \
    const float *here##k = lanes[k].here;                                                                    \
    float *below##k = lanes[k].below;                                                                        \
    float scale##k = lanes[k].scale, ahead##k = 0, near##k = 0, far##k = 0;                                  \
    uint32_t picked##k = 0;
/* Pixel x of lane k: its value and choice; e is what it passes on. */
#define RC_LANE_PICK(k, x)                                                                                   \
    float value##k = (float)(line##k[x] + 1) * scale##k + (here##k[x] + ahead##k);                           \
    uint32_t chosen##k = value##k >= 0.5f;                                                                   \
    mark##k[x] = (uint8_t)chosen##k;                                                                         \
    picked##k += chosen##k;                                                                                  \
    float e##k = value##k - (value##k >= 0.5f ? 1.0f : 0.0f); /* a compare and a mask: no int-to-float */
/* Interior pixel x, moving by step (+1 or -1): below[x - step] is final with 3/16 of e; below[x] gets 5/16
 * (after 1/16 from the pixel before), below[x + step] starts with 1/16. */
#define RC_LANE_STEP(k, x, step)                                                                             \
    {                                                                                                        \
        RC_LANE_PICK(k, x)                                                                                   \
        below##k[(x) - (step)] = near##k + e##k * b3;                                                        \
        near##k = far##k + e##k * b5;                                                                        \
        far##k = e##k * b1;                                                                                  \
        ahead##k = e##k * a7;                                                                                \
    }
#define RC_LANES(macro, ...)                                                                                 \
    macro(0, __VA_ARGS__) macro(1, __VA_ARGS__) macro(2, __VA_ARGS__) macro(3, __VA_ARGS__)
#define RC_EACH(macro) macro(0) macro(1) macro(2) macro(3)

FXC_HOT_CLONES static void diffuse_rows(rc_lane *lanes, uint32_t width, bool forward)
{
    const float a7 = 7.0f / 16, b3 = 3.0f / 16, b5 = 5.0f / 16, b1 = 1.0f / 16;
    RC_EACH(RC_LANE_VARS)
    if (width == 1) {
#define RC_ONLY(k)                                                                                           \
    {                                                                                                        \
        RC_LANE_PICK(k, 0)                                                                                   \
        below##k[0] = e##k; /* only below is left */                                                         \
    }
        RC_EACH(RC_ONLY)
#undef RC_ONLY
    } else if (forward) {
        /* First: no pixel behind, 7 + 5 + 1 = 13. */
#define RC_FIRST(k)                                                                                          \
    {                                                                                                        \
        RC_LANE_PICK(k, 0)                                                                                   \
        ahead##k = e##k * (7.0f / 13), near##k = e##k * (5.0f / 13), far##k = e##k * (1.0f / 13);            \
    }
        RC_EACH(RC_FIRST)
#undef RC_FIRST
        for (uint32_t x = 1; x + 1 < width; x++) {
            RC_LANES(RC_LANE_STEP, x, 1)
        }
        /* Last: nothing ahead, 3 + 5 = 8. */
#define RC_LAST(k)                                                                                           \
    {                                                                                                        \
        RC_LANE_PICK(k, width - 1)                                                                           \
        below##k[width - 2] = near##k + e##k * (3.0f / 8);                                                   \
        below##k[width - 1] = far##k + e##k * (5.0f / 8);                                                    \
    }
        RC_EACH(RC_LAST)
#undef RC_LAST
    } else {
#define RC_FIRST(k)                                                                                          \
    {                                                                                                        \
        RC_LANE_PICK(k, width - 1)                                                                           \
        ahead##k = e##k * (7.0f / 13), near##k = e##k * (5.0f / 13), far##k = e##k * (1.0f / 13);            \
    }
        RC_EACH(RC_FIRST)
#undef RC_FIRST
        for (uint32_t x = width - 2; x > 0; x--) {
            RC_LANES(RC_LANE_STEP, x, -1)
        }
#define RC_LAST(k)                                                                                           \
    {                                                                                                        \
        RC_LANE_PICK(k, 0)                                                                                   \
        below##k[1] = near##k + e##k * (3.0f / 8);                                                           \
        below##k[0] = far##k + e##k * (5.0f / 8);                                                            \
    }
        RC_EACH(RC_LAST)
#undef RC_LAST
    }
#define RC_SAVE(k) lanes[k].picked += picked##k;
    RC_EACH(RC_SAVE)
#undef RC_SAVE
}

/* A band's last row: everything goes ahead (nothing may leave the band). */
static void diffuse_last_row(rc_lane *l, uint32_t width, bool forward)
{
    if (forward)
        for (uint32_t x = 0; x < width; x++) {
            float e = pick(l->line, l->mark, l->here, x, l->scale, &l->picked);
            if (x + 1 < width)
                l->here[x + 1] += e;
        }
    else
        for (uint32_t x = width; x-- > 0;) {
            float e = pick(l->line, l->mark, l->here, x, l->scale, &l->picked);
            if (x > 0)
                l->here[x - 1] += e;
        }
}

/* Exactly quota in rows [y0, y1): tops up by highest priority, or trims by lowest (in scanline order within a
 * priority), then lists the chosen pixels in scanline order. */
static void settle_band(const uint8_t *priority, uint32_t width, uint32_t y0, uint32_t y1, uint64_t picked,
                        uint32_t quota, uint8_t *chosen, view_rc_pixel *out)
{
    size_t first = (size_t)y0 * width, end = (size_t)y1 * width;
    if (picked != quota) {
        bool add = picked < quota;
        uint64_t need = add ? quota - picked : picked - quota;
        uint32_t hist[256] = {0};
        for (size_t p = first; p < end; p++)
            if (chosen[p] != add)
                hist[priority[p]]++;
        /* The priority level where the need runs out, and how many of that level. */
        uint64_t beyond = 0;
        int level = add ? 255 : 0;
        for (;;) {
            if (beyond + hist[level] >= need)
                break;
            beyond += hist[level];
            level += add ? -1 : 1;
        }
        uint64_t at_level = need - beyond;
        for (size_t p = first; p < end; p++) {
            if (chosen[p] == add)
                continue;
            int prio = priority[p];
            bool flip = add ? prio > level : prio < level;
            if (!flip && prio == level && at_level > 0) {
                flip = true;
                at_level--;
            }
            if (flip)
                chosen[p] = add;
        }
    }
    /* The chosen pixels in scanline order (a few in a hundred), row by row so that no pixel index is divided
     * by the width (a division per chosen pixel held a fifth of this function's perf samples), eight bytes at
     * a time: the chosen ones among them found by their lowest set bits (a choice is 0 or 1 a byte). */
    uint32_t written = 0;
    for (uint32_t y = y0; y < y1 && written < quota; y++) {
        const uint8_t *row = chosen + (size_t)y * width;
        uint32_t x = 0;
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
        for (; x + 8 <= width; x += 8) {
            uint64_t eight;
            memcpy(&eight, row + x, 8);
            for (; eight != 0 && written < quota; eight &= eight - 1) {
                out[written].x = (uint16_t)(x + ((uint32_t)__builtin_ctzll(eight) >> 3));
                out[written].y = (uint16_t)y;
                written++;
            }
        }
#endif
        for (; x < width && written < quota; x++)
            if (row[x]) {
                out[written].x = (uint16_t)x;
                out[written].y = (uint16_t)y;
                written++;
            }
    }
}

void view_rc__dither_bands(const uint8_t *priority, uint32_t width, const uint32_t *y0, const uint32_t *y1,
                           const uint64_t *weight, const uint32_t *quota, uint32_t bands, uint8_t *chosen,
                           float *err, uint8_t *spare, view_rc_pixel *const *out)
{
    rc_lane lanes[RC_DITHER_LANES];
    uint32_t rows = 0;
    for (uint32_t k = 0; k < bands; k++) {
        memset(chosen + (size_t)y0[k] * width, 0, (size_t)(y1[k] - y0[k]) * width);
        lanes[k].here = err + (size_t)k * 2 * (width + 2);
        lanes[k].below = lanes[k].here + width + 2;
        memset(lanes[k].here, 0, (width + 2) * sizeof(float));
        lanes[k].scale = (float)((double)quota[k] / (double)weight[k]);
        lanes[k].picked = 0;
        rows = y1[k] - y0[k] > rows ? y1[k] - y0[k] : rows;
    }
    /* Spare lanes (fewer bands, or bands done) run on the spare rows after the real ones: line 0 of band 0
     * read again, choices into `spare`. */
    float *spare_err = err + (size_t)RC_DITHER_LANES * 2 * (width + 2);
    for (uint32_t j = 0; j < rows; j++) {
        bool forward = (j & 1) == 0;
        rc_lane run[RC_DITHER_LANES];
        uint32_t n = 0, index[RC_DITHER_LANES];
        for (uint32_t k = 0; k < bands; k++) {
            if (quota[k] == 0 || j >= y1[k] - y0[k])
                continue;
            lanes[k].line = priority + (size_t)(y0[k] + j) * width;
            lanes[k].mark = chosen + (size_t)(y0[k] + j) * width;
            if (j + 1 == y1[k] - y0[k]) {
                diffuse_last_row(&lanes[k], width, forward);
                continue;
            }
            index[n] = k;
            run[n++] = lanes[k];
        }
        if (n == 0)
            continue;
        for (uint32_t m = n; m < RC_DITHER_LANES; m++) {
            run[m] = run[0];
            run[m].here = spare_err + (m - n) * 2 * (size_t)(width + 2);
            run[m].below = run[m].here + width + 2;
            run[m].mark = spare;
        }
        for (uint32_t m = 0; m < RC_DITHER_LANES; m++)
            run[m].picked = 0;
        diffuse_rows(run, width, forward);
        for (uint32_t m = 0; m < n; m++) {
            rc_lane *l = &lanes[index[m]];
            l->picked += run[m].picked;
            l->here = run[m].below; /* the next row's incoming errors */
            l->below = run[m].here;
        }
    }
    for (uint32_t k = 0; k < bands; k++)
        if (quota[k] > 0)
            settle_band(priority, width, y0[k], y1[k], lanes[k].picked, quota[k], chosen, out[k]);
}

/* ---- the frame's sampling ------------------------------------------------------------------------------ */

static void dither_task(void *user, uint32_t group, uint32_t worker)
{
    view_rc *rc = user;
    uint32_t first = group * RC_DITHER_LANES, bands = rc->tiles_y - first;
    bands = bands < RC_DITHER_LANES ? bands : RC_DITHER_LANES;
    uint32_t y0[RC_DITHER_LANES], y1[RC_DITHER_LANES];
    view_rc_pixel *out[RC_DITHER_LANES];
    for (uint32_t k = 0; k < bands; k++) {
        uint32_t b = first + k;
        y0[k] = b * rc->tile;
        y1[k] = y0[k] + rc->tile < rc->height ? y0[k] + rc->tile : rc->height;
        out[k] = rc->requests + rc->band_offset[b];
    }
    view_rc__dither_bands(rc->priority, rc->width, y0, y1, rc->band_weight + first, rc->band_quota + first,
                          bands, rc->chosen, rc->workers[worker].err, rc->workers[worker].spare, out);
}

void view_rc__sampling(view_rc *rc)
{
    uint32_t pixels[VIEW_RC_MAX_TILES];
    for (uint32_t b = 0; b < rc->tiles_y; b++) {
        uint32_t y0 = b * rc->tile, y1 = y0 + rc->tile < rc->height ? y0 + rc->tile : rc->height;
        pixels[b] = (y1 - y0) * rc->width;
    }
    uint32_t count = rc->d.sample_budget - rc->predicted_count;
    view_rc__band_quotas(rc->band_weight, pixels, rc->tiles_y, count, rc->band_quota);
    uint32_t run = 0;
    for (uint32_t b = 0; b < rc->tiles_y; b++) {
        rc->band_offset[b] = run;
        run += rc->band_quota[b];
    }
    rc->request_count = run;
    rc_run_pixels(rc->pool, rc->d.dynamic_pixels, (rc->tiles_y + RC_DITHER_LANES - 1) / RC_DITHER_LANES,
                  dither_task, rc);
}

/* ---- the dither on its own ----------------------------------------------------------------------------- */

size_t view_rc_dither_scratch_bytes(uint32_t width, uint32_t height)
{
    return (size_t)width * height + (size_t)width +
           2 * RC_DITHER_LANES * 2 * ((size_t)width + 2) * sizeof(float) + 16;
}

fxc_result view_rc_dither(const uint8_t *priority, uint32_t width, uint32_t height, uint32_t band_height,
                          uint32_t count, view_rc_pixel *out, void *scratch, size_t scratch_bytes)
{
    if (!priority || !scratch || (!out && count > 0) || width == 0 || height == 0 ||
        width > VIEW_RC_MAX_SIDE || height > VIEW_RC_MAX_SIDE || (uint64_t)count > (uint64_t)width * height ||
        scratch_bytes < view_rc_dither_scratch_bytes(width, height))
        return FXC_ERR_INVALID;
    if (band_height == 0 || band_height > height)
        band_height = height;
    uint32_t bands = (height + band_height - 1) / band_height;
    if (bands > VIEW_RC_MAX_TILES)
        return FXC_ERR_INVALID;
    uint8_t *chosen = scratch, *spare = chosen + (size_t)width * height;
    /* The error rows after the mask and the spare row, float-aligned. */
    uintptr_t at = ((uintptr_t)(spare + width) + 15) & ~(uintptr_t)15;
    float *err = (float *)at;
    uint64_t weight[VIEW_RC_MAX_TILES];
    uint32_t pixels[VIEW_RC_MAX_TILES], quota[VIEW_RC_MAX_TILES], y0[VIEW_RC_MAX_TILES],
        y1[VIEW_RC_MAX_TILES];
    view_rc_pixel *outs[VIEW_RC_MAX_TILES];
    uint32_t run = 0;
    for (uint32_t b = 0; b < bands; b++) {
        y0[b] = b * band_height;
        y1[b] = y0[b] + band_height < height ? y0[b] + band_height : height;
        weight[b] = 0;
        for (size_t p = (size_t)y0[b] * width; p < (size_t)y1[b] * width; p++)
            weight[b] += priority[p] + 1u;
        pixels[b] = (y1[b] - y0[b]) * width;
    }
    view_rc__band_quotas(weight, pixels, bands, count, quota);
    for (uint32_t b = 0; b < bands; b++) {
        outs[b] = out + run;
        run += quota[b];
    }
    for (uint32_t b = 0; b < bands; b += RC_DITHER_LANES) {
        uint32_t n = bands - b < RC_DITHER_LANES ? bands - b : RC_DITHER_LANES;
        view_rc__dither_bands(priority, width, y0 + b, y1 + b, weight + b, quota + b, n, chosen, err, spare,
                              outs + b);
    }
    return FXC_OK;
}
