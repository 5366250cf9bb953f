/* The pixel passes of a frame, each parallel over tiles (a tile reads its neighbours' pixels across its border,
 * written by the previous pass, and writes only its own):
 *
 * Depth cull (1999, slide 14: "z-buffering only works within a pixel; find pixels with locally inconsistent
 * depths"). A point that won its pixel may still lie behind a surface whose points are spread apart, showing
 * through the gaps. Here a point is dropped when two opposite neighbours in its 3x3 neighbourhood (left and right,
 * above and below, or the ends of a diagonal) are both nearer than it by more than cull_ratio and agree with each
 * other much better than with it: in disparity (1 / depth, linear across a plane in the image) the pair's spread
 * is less than half its lead over the point, 2 |1/a - 1/b| < 1/max(a, b) - 1/c. That is the mark of a point seen
 * through a surface. Two simpler rules fail on frames the server sends whole: against the neighbourhood's mean depth, the
 * background point beside every silhouette is dropped (a still camera would not show the frame as it was
 * sent); with only "both nearer", a floor seen at a grazing angle (its depth changing by more than cull_ratio
 * from row to row) beside an object drops the floor's points along the object's outline.
 *
 * Interpolation (1999, slides 15 and 18; 2002 3.3, Figure 3): the 3x3 filter with weights 1-2-1 / 2-4-2 /
 * 1-2-1 over the neighbourhood's points (after the cull), rounded to the nearest integer, fills a pixel without
 * a point (and with smooth_all replaces every pixel by that mean). The same pass writes the priority image:
 * a point's age (older first), or for a pixel without one 255 - 16 n, n the points among its 8 neighbours
 * (emptier first, 255 where there is none).
 *
 * Prefilter (2002 3.3): where the 3x3 found no point, the uniform mean of the points in the 7x7 neighbourhood,
 * from running sums whose cost does not depend on the kernel's size (the paper's reference: Smith's moving
 * average); only tiles with such pixels compute it. It does not change the priority (2002 3.3). */
#include "rc_internal.h"

#include <math.h>
#include <string.h>

typedef struct rc_rect {
    uint32_t x0, y0, x1, y1;
} rc_rect;

static rc_rect tile_rect(const view_rc *rc, uint32_t tile)
{
    rc_rect r;
    r.x0 = (tile % rc->tiles_x) * rc->tile_w;
    r.y0 = (tile / rc->tiles_x) * rc->tile_h;
    r.x1 = r.x0 + rc->tile_w < rc->width ? r.x0 + rc->tile_w : rc->width;
    r.y1 = r.y0 + rc->tile_h < rc->height ? r.y0 + rc->tile_h : rc->height;
    return r;
}

/* ---- depth cull ----------------------------------------------------------------------------------------- */

static void cull_task(void *user, uint32_t tile, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    rc_rect r = tile_rect(rc, tile);
    const float *zbuf = rc->zbuf;
    const uint32_t *win = rc->win;
    const rc_rec *rec = rc->rec[rc->built];
    uint32_t *pt = rc->pt;
    float *depth = rc->depth;
    size_t w = rc->width;
    uint32_t h = rc->height, culled = 0;
    bool cull = !rc->d.no_depth_cull;
    float nearer = 1.0f / (1.0f + rc->d.cull_ratio);
    float sky = (float)(0.5 * VIEW_RC_SKY_DISTANCE);
    for (uint32_t y = r.y0; y < r.y1; y++)
        for (uint32_t x = r.x0; x < r.x1; x++) {
            size_t p = y * w + x;
            uint32_t winner = win[p];
            if (winner == RC_NO_POINT) {
                pt[p] = RC_EMPTY_PT;
                depth[p] = NAN;
                continue;
            }
            float z = zbuf[p], t = z * nearer;
            if (cull) {
                /* The eight neighbours' depths (+inf outside the image and where empty: never nearer). */
                float n[8];
                bool l = x > 0, rt = x + 1 < w, u = y > 0, d = y + 1 < h;
                n[0] = l ? zbuf[p - 1] : INFINITY;             /* left */
                n[1] = rt ? zbuf[p + 1] : INFINITY;             /* right: opposite of 0 */
                n[2] = u ? zbuf[p - w] : INFINITY;             /* up */
                n[3] = d ? zbuf[p + w] : INFINITY;             /* down: opposite of 2 */
                n[4] = l && u ? zbuf[p - w - 1] : INFINITY;   /* up left */
                n[5] = rt && d ? zbuf[p + w + 1] : INFINITY;   /* down right: opposite of 4 */
                n[6] = rt && u ? zbuf[p - w + 1] : INFINITY;   /* up right */
                n[7] = l && d ? zbuf[p + w - 1] : INFINITY;   /* down left: opposite of 6 */
                bool behind = false;
                for (int k = 0; k < 8; k += 2) {
                    float lo = n[k] < n[k + 1] ? n[k] : n[k + 1], hi = n[k] < n[k + 1] ? n[k + 1] : n[k];
                    /* Both nearer by the ratio; then 2 (1/lo - 1/hi) < 1/hi - 1/z, multiplied by lo hi z. */
                    behind |= hi < t && 2.0f * (hi - lo) * z < (z - hi) * lo;
                }
                if (behind) {
                    pt[p] = RC_EMPTY_PT;
                    depth[p] = NAN;
                    culled++;
                    continue;
                }
            }
            pt[p] = rec[winner].rgba;
            depth[p] = z >= sky ? INFINITY : z * sqrtf(1.0f + rc->stretch_x2[x] + rc->stretch_y2[y]);
        }
    rc->tile_culled[tile] = culled;
}

void view_rc__depth_cull(view_rc *rc)
{
    /* The squared image-plane coordinates of the pixel centres (srv_camera_ray's sx, sy). */
    const rc_view *v = &rc->view;
    for (uint32_t x = 0; x < rc->width; x++) {
        float sx = (2.0f * ((float)x + 0.5f) / (float)v->width - 1.0f) * v->tan_half_x;
        rc->stretch_x2[x] = sx * sx;
    }
    for (uint32_t y = 0; y < rc->height; y++) {
        float sy = (1.0f - 2.0f * ((float)y + 0.5f) / (float)v->height) * v->tan_half_y;
        rc->stretch_y2[y] = sy * sy;
    }
    view_rc__pool_run(rc->pool, rc->tile_count, cull_task, rc);
}

/* ---- interpolation and priority ----------------------------------------------------------------------- */

static void interpolate_task(void *user, uint32_t tile, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    rc_rect r = tile_rect(rc, tile);
    const uint32_t *pt = rc->pt;
    uint8_t *rgb = rc->rgb, *kind = rc->kind, *priority = rc->priority;
    size_t w = rc->width;
    uint32_t h = rc->height;
    bool smooth_all = rc->d.smooth_all, prefilter = !rc->d.no_prefilter;
    const uint8_t *clear = rc->d.clear_rgb;
    uint32_t kinds[VIEW_RC_PIXEL_KINDS] = {0};
    uint64_t weight = 0;
    for (uint32_t y = r.y0; y < r.y1; y++)
        for (uint32_t x = r.x0; x < r.x1; x++) {
            size_t p = y * w + x;
            uint32_t own = pt[p];
            bool has_point = own != RC_EMPTY_PT;
            uint8_t *out = rgb + 3 * p;
            if (has_point && !smooth_all) {
                out[0] = (uint8_t)own, out[1] = (uint8_t)(own >> 8), out[2] = (uint8_t)(own >> 16);
                kind[p] = VIEW_RC_POINT;
                priority[p] = (uint8_t)rc_age(own);
                kinds[VIEW_RC_POINT]++;
                weight += rc_age(own) + 1;
                continue;
            }
            /* 1-2-1 / 2-4-2 / 1-2-1 over the neighbourhood's points. */
            uint32_t sum[3] = {0, 0, 0}, total = 0, neighbours = 0;
            for (int dy = -1; dy <= 1; dy++) {
                if ((dy < 0 && y == 0) || (dy > 0 && y + 1 >= h))
                    continue;
                for (int dx = -1; dx <= 1; dx++) {
                    if ((dx < 0 && x == 0) || (dx > 0 && x + 1 >= w))
                        continue;
                    uint32_t v = pt[(size_t)((int64_t)p + dy * (int64_t)w + dx)];
                    if (v == RC_EMPTY_PT)
                        continue;
                    uint32_t k = (uint32_t)((dx ? 1 : 2) * (dy ? 1 : 2));
                    sum[0] += k * (v & 0xFF);
                    sum[1] += k * ((v >> 8) & 0xFF);
                    sum[2] += k * ((v >> 16) & 0xFF);
                    total += k;
                    neighbours += dx || dy;
                }
            }
            uint32_t prio = has_point ? rc_age(own) : 255 - 16 * neighbours;
            priority[p] = (uint8_t)prio;
            weight += prio + 1;
            if (total > 0) {
                for (int c = 0; c < 3; c++)
                    out[c] = (uint8_t)((sum[c] + total / 2) / total);
                kind[p] = has_point ? VIEW_RC_POINT : VIEW_RC_INTERP;
            } else {
                out[0] = clear[0], out[1] = clear[1], out[2] = clear[2];
                kind[p] = VIEW_RC_EMPTY;
            }
            kinds[kind[p]]++;
        }
    memcpy(rc->tile_kind + (size_t)tile * VIEW_RC_PIXEL_KINDS, kinds, sizeof kinds);
    rc->tile_need[tile] = prefilter ? kinds[VIEW_RC_EMPTY] : 0;
    rc->tile_weight[tile] = weight;
}

void view_rc__interpolate(view_rc *rc)
{
    view_rc__pool_run(rc->pool, rc->tile_count, interpolate_task, rc);
}

/* ---- prefilter -------------------------------------------------------------------------------------------- */

static void prefilter_task(void *user, uint32_t tile, uint32_t worker)
{
    view_rc *rc = user;
    if (rc->tile_need[tile] == 0)
        return;
    rc_rect r = tile_rect(rc, tile);
    const uint32_t *pt = rc->pt;
    uint8_t *rgb = rc->rgb, *kind = rc->kind;
    uint32_t w = rc->width, h = rc->height, tw = r.x1 - r.x0;
    uint32_t row_lo = r.y0 >= 3 ? r.y0 - 3 : 0, row_hi = r.y1 + 3 < h ? r.y1 + 3 : h;
    uint32_t *box = rc->workers[worker].box; /* per row of [row_lo, row_hi), per column: r, g, b, count */
    /* Horizontal sums over [x - 3, x + 3], sliding along each row. */
    for (uint32_t y = row_lo; y < row_hi; y++) {
        const uint32_t *line = pt + (size_t)y * w;
        uint32_t acc[4] = {0, 0, 0, 0};
        uint32_t lo = r.x0 >= 3 ? r.x0 - 3 : 0, hi = r.x0 + 4 < w ? r.x0 + 4 : w;
        for (uint32_t x = lo; x < hi; x++)
            if (line[x] != RC_EMPTY_PT) {
                acc[0] += line[x] & 0xFF, acc[1] += (line[x] >> 8) & 0xFF, acc[2] += (line[x] >> 16) & 0xFF;
                acc[3]++;
            }
        uint32_t *out = box + (size_t)(y - row_lo) * tw * 4;
        for (uint32_t x = r.x0; x < r.x1; x++) {
            memcpy(out + (x - r.x0) * 4, acc, sizeof acc);
            if (x >= 3 && line[x - 3] != RC_EMPTY_PT) {
                uint32_t v = line[x - 3];
                acc[0] -= v & 0xFF, acc[1] -= (v >> 8) & 0xFF, acc[2] -= (v >> 16) & 0xFF;
                acc[3]--;
            }
            if (x + 4 < w && line[x + 4] != RC_EMPTY_PT) {
                uint32_t v = line[x + 4];
                acc[0] += v & 0xFF, acc[1] += (v >> 8) & 0xFF, acc[2] += (v >> 16) & 0xFF;
                acc[3]++;
            }
        }
    }
    /* Vertical sums over [y - 3, y + 3], sliding down each column; only the empty pixels read them. */
    uint32_t filled = 0;
    for (uint32_t x = r.x0; x < r.x1; x++) {
        uint32_t acc[4] = {0, 0, 0, 0};
        const uint32_t *column = box + (x - r.x0) * 4;
        size_t stride = (size_t)tw * 4;
        uint32_t lo = r.y0 >= 3 ? r.y0 - 3 : 0, hi = r.y0 + 4 < h ? r.y0 + 4 : h;
        for (uint32_t y = lo; y < hi; y++)
            for (int c = 0; c < 4; c++)
                acc[c] += column[(y - row_lo) * stride + c];
        for (uint32_t y = r.y0; y < r.y1; y++) {
            size_t p = (size_t)y * w + x;
            if (kind[p] == VIEW_RC_EMPTY && acc[3] > 0) {
                for (int c = 0; c < 3; c++)
                    rgb[3 * p + c] = (uint8_t)((acc[c] + acc[3] / 2) / acc[3]);
                kind[p] = VIEW_RC_PREFILTER;
                filled++;
            }
            if (y >= 3 && y - 3 >= row_lo)
                for (int c = 0; c < 4; c++)
                    acc[c] -= column[(y - 3 - row_lo) * stride + c];
            if (y + 4 < row_hi)
                for (int c = 0; c < 4; c++)
                    acc[c] += column[(y + 4 - row_lo) * stride + c];
        }
    }
    rc->tile_kind[(size_t)tile * VIEW_RC_PIXEL_KINDS + VIEW_RC_EMPTY] -= filled;
    rc->tile_kind[(size_t)tile * VIEW_RC_PIXEL_KINDS + VIEW_RC_PREFILTER] += filled;
}

void view_rc__prefilter(view_rc *rc)
{
    view_rc__pool_run(rc->pool, rc->tile_count, prefilter_task, rc);
}
