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

/* Up to RC_DITHER_LANES (8) bands run through the error diffusion together, one lane each: the bands are
 * independent, and their chains of error (each pixel's value waits for the error of the pixel before) overlap
 * in the processor. The lanes' errors are interleaved, err[x * 8 + k] for lane k, so one row of
 * Floyd-Steinberg takes the eight lanes' pixel x in two 4-wide vectors: the arithmetic of eight pixels in a
 * few vector instructions (it was four lanes of scalar code, about 2.6 ns a pixel). The choices come out as a
 * byte of eight bits per pixel (bit k: lane k), spread into the lanes' rows afterwards. The floats are those
 * of the plain loop per pixel (the same operations in the same order, -ffp-contract=off), so the choices do
 * not depend on which lanes run together.
 *
 * Seam rule (the bands' edges): no error crosses a band's edge. At a row's ends, the shares that would leave
 * the band go to those that stay in proportion (first pixel of a row 7 + 5 + 1 = 13, last 3 + 5 = 8); a
 * band's last row passes everything ahead (nothing goes below). Each band gets its count from the band
 * quotas, so the count is exact whatever the seams do to the pattern near them. */

/* One row of the lanes: errors in `here` (read), into `below` (written), width * 8 each; lane k reads line[k]
 * (its priorities) with scale[k]; bit k of bits[x] is lane k's choice. Not a band's last row. */
typedef struct rc_lanes {
    const uint8_t *line[RC_DITHER_LANES];
    float scale[RC_DITHER_LANES];
} rc_lanes;

#if defined(__SSE2__)
#include <emmintrin.h>

/* Pixel x of the eight lanes as two vectors: (line + 1) * scale + (here + ahead), the choice, the error e. */
#define RC_PICK8(x)                                                                                          \
    __m128i la = _mm_setr_epi32(l->line[0][x], l->line[1][x], l->line[2][x], l->line[3][x]);                 \
    __m128i lb = _mm_setr_epi32(l->line[4][x], l->line[5][x], l->line[6][x], l->line[7][x]);                 \
    __m128 va = _mm_add_ps(_mm_mul_ps(_mm_cvtepi32_ps(_mm_add_epi32(la, one_i)), scale_a),                   \
                           _mm_add_ps(_mm_loadu_ps(here + 8 * (size_t)(x)), ahead_a));                       \
    __m128 vb = _mm_add_ps(_mm_mul_ps(_mm_cvtepi32_ps(_mm_add_epi32(lb, one_i)), scale_b),                   \
                           _mm_add_ps(_mm_loadu_ps(here + 8 * (size_t)(x) + 4), ahead_b));                   \
    __m128 ca = _mm_cmpge_ps(va, half), cb = _mm_cmpge_ps(vb, half);                                         \
    bits[x] = (uint8_t)(_mm_movemask_ps(ca) | _mm_movemask_ps(cb) << 4);                                     \
    __m128 ea = _mm_sub_ps(va, _mm_and_ps(ca, one)), eb = _mm_sub_ps(vb, _mm_and_ps(cb, one));
#define RC_SPLAT(v) _mm_set1_ps(v)

FXC_HOT_CLONES static void diffuse_rows(const rc_lanes *l, const float *restrict here, float *restrict below,
                                        uint8_t *restrict bits, uint32_t width, bool forward)
{
    const __m128i one_i = _mm_set1_epi32(1);
    const __m128 one = RC_SPLAT(1.0f), half = RC_SPLAT(0.5f), a7 = RC_SPLAT(7.0f / 16),
                 b3 = RC_SPLAT(3.0f / 16), b5 = RC_SPLAT(5.0f / 16), b1 = RC_SPLAT(1.0f / 16);
    const __m128 scale_a = _mm_loadu_ps(l->scale), scale_b = _mm_loadu_ps(l->scale + 4);
    __m128 ahead_a = _mm_setzero_ps(), ahead_b = ahead_a, near_a = ahead_a, near_b = ahead_a, far_a = ahead_a,
           far_b = ahead_a;
    if (width == 1) {
        RC_PICK8(0)
        _mm_storeu_ps(below, ea); /* only below is left */
        _mm_storeu_ps(below + 4, eb);
        return;
    }
    uint32_t first = forward ? 0 : width - 1, last = forward ? width - 1 : 0;
    {
        /* First: no pixel behind, 7 + 5 + 1 = 13. */
        RC_PICK8(first)
        ahead_a = _mm_mul_ps(ea, RC_SPLAT(7.0f / 13)), ahead_b = _mm_mul_ps(eb, RC_SPLAT(7.0f / 13));
        near_a = _mm_mul_ps(ea, RC_SPLAT(5.0f / 13)), near_b = _mm_mul_ps(eb, RC_SPLAT(5.0f / 13));
        far_a = _mm_mul_ps(ea, RC_SPLAT(1.0f / 13)), far_b = _mm_mul_ps(eb, RC_SPLAT(1.0f / 13));
    }
    /* Interior pixel x, moving by step: below[x - step] is final with 3/16 of e; below[x] gets 5/16 (after
     * 1/16 from the pixel before), below[x + step] starts with 1/16. */
#define RC_STEP8(x, step)                                                                                    \
    {                                                                                                        \
        RC_PICK8(x)                                                                                          \
        float *b = below + 8 * (size_t)((x) - (step));                                                       \
        _mm_storeu_ps(b, _mm_add_ps(near_a, _mm_mul_ps(ea, b3)));                                            \
        _mm_storeu_ps(b + 4, _mm_add_ps(near_b, _mm_mul_ps(eb, b3)));                                        \
        near_a = _mm_add_ps(far_a, _mm_mul_ps(ea, b5)), near_b = _mm_add_ps(far_b, _mm_mul_ps(eb, b5));      \
        far_a = _mm_mul_ps(ea, b1), far_b = _mm_mul_ps(eb, b1);                                              \
        ahead_a = _mm_mul_ps(ea, a7), ahead_b = _mm_mul_ps(eb, a7);                                          \
    }
    if (forward)
        for (uint32_t x = 1; x + 1 < width; x++)
            RC_STEP8(x, 1)
    else
        for (uint32_t x = width - 2; x > 0; x--)
            RC_STEP8(x, -1)
#undef RC_STEP8
            {
                /* Last: nothing ahead, 3 + 5 = 8. */
                RC_PICK8(last)
                int32_t back = forward ? -1 : 1;
                float *b = below + 8 * (size_t)((int64_t)last + back), *c = below + 8 * (size_t)last;
                _mm_storeu_ps(b, _mm_add_ps(near_a, _mm_mul_ps(ea, RC_SPLAT(3.0f / 8))));
                _mm_storeu_ps(b + 4, _mm_add_ps(near_b, _mm_mul_ps(eb, RC_SPLAT(3.0f / 8))));
                _mm_storeu_ps(c, _mm_add_ps(far_a, _mm_mul_ps(ea, RC_SPLAT(5.0f / 8))));
                _mm_storeu_ps(c + 4, _mm_add_ps(far_b, _mm_mul_ps(eb, RC_SPLAT(5.0f / 8))));
            }
}
#undef RC_PICK8
#undef RC_SPLAT
#else
/* Without SSE2: the same arithmetic lane by lane. */
static void diffuse_rows(const rc_lanes *l, const float *restrict here, float *restrict below,
                         uint8_t *restrict bits, uint32_t width, bool forward)
{
    memset(bits, 0, width);
    for (uint32_t k = 0; k < RC_DITHER_LANES; k++) {
        const uint8_t *line = l->line[k];
        float scale = l->scale[k], ahead = 0, near = 0, far = 0;
        for (uint32_t i = 0; i < width; i++) {
            uint32_t x = forward ? i : width - 1 - i;
            float value = (float)(line[x] + 1) * scale + (here[8 * (size_t)x + k] + ahead);
            uint32_t chosen = value >= 0.5f;
            bits[x] |= (uint8_t)(chosen << k);
            float e = value - (chosen ? 1.0f : 0.0f);
            if (width == 1) {
                below[k] = e;
            } else if (i == 0) {
                ahead = e * (7.0f / 13), near = e * (5.0f / 13), far = e * (1.0f / 13);
            } else if (i + 1 < width) {
                below[8 * (size_t)(forward ? x - 1 : x + 1) + k] = near + e * (3.0f / 16);
                near = far + e * (5.0f / 16);
                far = e * (1.0f / 16);
                ahead = e * (7.0f / 16);
            } else {
                below[8 * (size_t)(forward ? x - 1 : x + 1) + k] = near + e * (3.0f / 8);
                below[8 * (size_t)x + k] = far + e * (5.0f / 8);
            }
        }
    }
}
#endif

/* Lane k's choices from the row's bits into its row of `chosen`; returns how many. */
FXC_HOT_CLONES static uint32_t spread_bits(const uint8_t *restrict bits, uint32_t k, uint8_t *restrict mark,
                                           uint32_t width)
{
    uint32_t picked = 0;
    for (size_t x = 0; x < width; x++) {
        uint8_t c = (uint8_t)((bits[x] >> k) & 1u);
        mark[x] = c;
        picked += c;
    }
    return picked;
}

/* A band's last row, lane k of the interleaved errors: everything goes ahead (nothing may leave the band). */
static uint32_t diffuse_last_row(const uint8_t *line, uint8_t *mark, float *here, uint32_t k, float scale,
                                 uint32_t width, bool forward)
{
    uint32_t picked = 0;
    for (uint32_t i = 0; i < width; i++) {
        uint32_t x = forward ? i : width - 1 - i;
        float value = (float)(line[x] + 1) * scale + here[8 * (size_t)x + k];
        uint32_t chosen = value >= 0.5f;
        mark[x] = (uint8_t)chosen;
        picked += chosen;
        float e = value - (float)chosen;
        if (i + 1 < width)
            here[8 * (size_t)(forward ? x + 1 : x - 1) + k] += e;
    }
    return picked;
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
                           float *err, uint8_t *bits, view_rc_pixel *const *out)
{
    float *here = err, *below = err + (size_t)RC_DITHER_LANES * (width + 2);
    memset(here, 0, (size_t)RC_DITHER_LANES * width * sizeof(float));
    rc_lanes lanes;
    uint32_t picked[RC_DITHER_LANES] = {0}, rows = 0;
    for (uint32_t k = 0; k < RC_DITHER_LANES; k++) {
        /* Spare lanes (fewer bands, a band without a quota, or one done) read the first row with scale 0;
         * their choices are not spread and their errors not read. */
        lanes.line[k] = priority;
        lanes.scale[k] = 0.0f;
        if (k >= bands)
            continue;
        memset(chosen + (size_t)y0[k] * width, 0, (size_t)(y1[k] - y0[k]) * width);
        if (quota[k] > 0)
            lanes.scale[k] = (float)((double)quota[k] / (double)weight[k]);
        rows = y1[k] - y0[k] > rows ? y1[k] - y0[k] : rows;
    }
    float scale[RC_DITHER_LANES];
    memcpy(scale, lanes.scale, sizeof scale);
    for (uint32_t j = 0; j < rows; j++) {
        bool forward = (j & 1) == 0, live[RC_DITHER_LANES], any = false;
        /* Lanes on their last row go ahead alone (scalar); the rest together. */
        for (uint32_t k = 0; k < RC_DITHER_LANES; k++) {
            live[k] = k < bands && quota[k] > 0 && j < y1[k] - y0[k];
            if (live[k] && j + 1 == y1[k] - y0[k]) {
                picked[k] +=
                    diffuse_last_row(priority + (size_t)(y0[k] + j) * width,
                                     chosen + (size_t)(y0[k] + j) * width, here, k, scale[k], width, forward);
                live[k] = false;
            }
            lanes.line[k] = live[k] ? priority + (size_t)(y0[k] + j) * width : priority;
            lanes.scale[k] = live[k] ? scale[k] : 0.0f;
            any |= live[k];
        }
        if (!any)
            continue;
        diffuse_rows(&lanes, here, below, bits, width, forward);
        for (uint32_t k = 0; k < RC_DITHER_LANES; k++)
            if (live[k])
                picked[k] += spread_bits(bits, k, chosen + (size_t)(y0[k] + j) * width, width);
        float *t = here;
        here = below; /* the next row's incoming errors */
        below = t;
    }
    for (uint32_t k = 0; k < bands; k++)
        if (quota[k] > 0)
            settle_band(priority, width, y0[k], y1[k], picked[k], quota[k], chosen, out[k]);
}

/* ---- the frame's sampling ------------------------------------------------------------------------------ */

/* Bands per dither task: up to RC_DITHER_LANES, fewer when that leaves a thread without a task (8 bands on 2
 * threads: two tasks of 4). Which bands run together does not change a choice. */
static uint32_t dither_group(const view_rc *rc)
{
    uint32_t group = (rc->tiles_y + rc->thread_count - 1) / rc->thread_count;
    return group < 1 ? 1 : group > RC_DITHER_LANES ? RC_DITHER_LANES : group;
}

void view_rc__dither_group(view_rc *rc, uint32_t task, uint32_t group, uint32_t worker)
{
    uint32_t first = task * group, bands = rc->tiles_y - first;
    bands = bands < group ? bands : group;
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

static void dither_task(void *user, uint32_t task, uint32_t worker)
{
    view_rc *rc = user;
    view_rc__dither_group(rc, task, dither_group(rc), worker);
}

void view_rc__sampling_quotas(view_rc *rc)
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
}

void view_rc__sampling(view_rc *rc)
{
    uint32_t group = dither_group(rc);
    rc_run_pixels(rc->pool, rc->d.dynamic_pixels, (rc->tiles_y + group - 1) / group, dither_task, rc);
}

/* ---- the dither on its own ----------------------------------------------------------------------------- */

size_t view_rc_dither_scratch_bytes(uint32_t width, uint32_t height)
{
    return (size_t)width * height + (size_t)width +
           2 * RC_DITHER_LANES * ((size_t)width + 2) * sizeof(float) + 16;
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
