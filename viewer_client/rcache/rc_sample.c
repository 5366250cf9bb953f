/* Sampling: which pixels the client asks the server to render next.
 *
 * Predicted sampling (2002 3.1): every quarter-resolution pixel of the predicted camera that no point landed in
 * is requested (its middle pixel at full resolution); when there are more than half the budget, every n-th in
 * scanline order, evenly spread. The rest of the budget goes to the normal sampling.
 *
 * Normal sampling (1999, slide 19): an error-diffusion dither over the priority image "concentrates pixels in
 * high priority regions" and "maintains good spatial distribution". The image is cut into bands (the tile rows)
 * that are dithered independently, so that threads can share the work and the result does not depend on how
 * many there are. Each band gets a share of the count proportional to its sum of priority + 1 (the + 1 lets
 * fresh points be refreshed too, rarely), by largest remainder and at most its pixel count; within the band a
 * serpentine Floyd-Steinberg pass over (priority + 1) * share / band sum chooses pixels where the running value
 * reaches 1/2, the error going 7/16 ahead, 3/16 below behind, 5/16 below, 1/16 below ahead (shares that would
 * leave the band are given to those that stay). Diffusion keeps the band's sum within a rounding of its share;
 * the last few are then trimmed (lowest priority first) or topped up (highest first), so the count is exact. */
#include "rc_internal.h"

#include <string.h>

/* ---- predicted sampling --------------------------------------------------------------------------------- */

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

/* ---- band quotas ---------------------------------------------------------------------------------------- */

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
                if (!capped[b] && remainder[b] != UINT64_MAX && (best == bands || remainder[b] > remainder[best]))
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

/* ---- one band's dither ------------------------------------------------------------------------------------- */

void view_rc__dither_band(const uint8_t *priority, uint32_t width, uint32_t y0, uint32_t y1, uint64_t weight,
                          uint32_t quota, uint8_t *chosen, float *err, view_rc_pixel *out)
{
    size_t first = (size_t)y0 * width, end = (size_t)y1 * width;
    memset(chosen + first, 0, end - first);
    if (quota == 0)
        return;
    float scale = (float)((double)quota / (double)weight);
    float *here = err, *below = err + width + 2;
    memset(here, 0, (width + 2) * sizeof(float));
    uint64_t picked = 0;
    for (uint32_t y = y0; y < y1; y++) {
        memset(below, 0, (width + 2) * sizeof(float));
        bool last_row = y + 1 == y1, forward = ((y - y0) & 1) == 0;
        const uint8_t *line = priority + (size_t)y * width;
        uint8_t *mark = chosen + (size_t)y * width;
        for (uint32_t k = 0; k < width; k++) {
            uint32_t x = forward ? k : width - 1 - k;
            float value = (float)(line[x] + 1) * scale + here[x];
            if (value >= 0.5f) {
                mark[x] = 1;
                picked++;
                value -= 1.0f;
            }
            bool ahead = k + 1 < width, behind = k > 0;
            uint32_t xa = forward ? x + 1 : x - 1, xb = forward ? x - 1 : x + 1;
            if (last_row) {
                if (ahead)
                    here[xa] += value;
                continue;
            }
            float total = 5.0f + (ahead ? 8.0f : 0.0f) + (behind ? 3.0f : 0.0f);
            float unit = value / total;
            if (ahead) {
                here[xa] += 7.0f * unit;
                below[xa] += 1.0f * unit;
            }
            if (behind)
                below[xb] += 3.0f * unit;
            below[x] += 5.0f * unit;
        }
        float *swap = here;
        here = below;
        below = swap;
    }
    /* Exactly quota: top up by highest priority, or trim by lowest, in scanline order within a priority. */
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
    uint32_t written = 0;
    for (size_t p = first; p < end && written < quota; p++)
        if (chosen[p]) {
            out[written].x = (uint16_t)(p % width);
            out[written].y = (uint16_t)(p / width);
            written++;
        }
}

/* ---- the frame's sampling ---------------------------------------------------------------------------------- */

static void dither_task(void *user, uint32_t band, uint32_t worker)
{
    view_rc *rc = user;
    uint32_t y0 = band * rc->tile_h, y1 = y0 + rc->tile_h < rc->height ? y0 + rc->tile_h : rc->height;
    view_rc__dither_band(rc->priority, rc->width, y0, y1, rc->band_weight[band], rc->band_quota[band], rc->chosen,
                         rc->workers[worker].err, rc->requests + rc->band_offset[band]);
}

void view_rc__sampling(view_rc *rc)
{
    uint32_t pixels[VIEW_RC_MAX_TILES];
    for (uint32_t b = 0; b < rc->tiles_y; b++) {
        uint64_t sum = 0;
        for (uint32_t t = 0; t < rc->tiles_x; t++)
            sum += rc->tile_weight[b * rc->tiles_x + t];
        rc->band_weight[b] = sum;
        uint32_t y0 = b * rc->tile_h, y1 = y0 + rc->tile_h < rc->height ? y0 + rc->tile_h : rc->height;
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
    view_rc__pool_run(rc->pool, rc->tiles_y, dither_task, rc);
}

/* ---- the dither on its own ------------------------------------------------------------------------------- */

size_t view_rc_dither_scratch_bytes(uint32_t width, uint32_t height)
{
    return (size_t)width * height + 2 * ((size_t)width + 2) * sizeof(float) + 16;
}

fxc_result view_rc_dither(const uint8_t *priority, uint32_t width, uint32_t height, uint32_t band_height,
                          uint32_t count, view_rc_pixel *out, void *scratch, size_t scratch_bytes)
{
    if (!priority || !scratch || (!out && count > 0) || width == 0 || height == 0 || width > VIEW_RC_MAX_SIDE ||
        height > VIEW_RC_MAX_SIDE || (uint64_t)count > (uint64_t)width * height ||
        scratch_bytes < view_rc_dither_scratch_bytes(width, height))
        return FXC_ERR_INVALID;
    if (band_height == 0 || band_height > height)
        band_height = height;
    uint32_t bands = (height + band_height - 1) / band_height;
    if (bands > VIEW_RC_MAX_TILES)
        return FXC_ERR_INVALID;
    uint8_t *chosen = scratch;
    /* The error rows after the mask, float-aligned. */
    uintptr_t at = ((uintptr_t)(chosen + (size_t)width * height) + 15) & ~(uintptr_t)15;
    float *err = (float *)at;
    uint64_t weight[VIEW_RC_MAX_TILES];
    uint32_t pixels[VIEW_RC_MAX_TILES], quota[VIEW_RC_MAX_TILES];
    for (uint32_t b = 0; b < bands; b++) {
        uint32_t y0 = b * band_height, y1 = y0 + band_height < height ? y0 + band_height : height;
        weight[b] = 0;
        for (size_t p = (size_t)y0 * width; p < (size_t)y1 * width; p++)
            weight[b] += priority[p] + 1u;
        pixels[b] = (y1 - y0) * width;
    }
    view_rc__band_quotas(weight, pixels, bands, count, quota);
    uint32_t run = 0;
    for (uint32_t b = 0; b < bands; b++) {
        uint32_t y0 = b * band_height, y1 = y0 + band_height < height ? y0 + band_height : height;
        view_rc__dither_band(priority, width, y0, y1, weight[b], quota[b], chosen, err, out + run);
        run += quota[b];
    }
    return FXC_OK;
}
