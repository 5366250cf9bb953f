/* The pixel passes of a frame, each parallel over bands of rows (a band reads its neighbours' rows across its
 * border, written by the previous pass, and writes only its own):
 *
 * Depth cull (1999, slide 14: "z-buffering only works within a pixel; find pixels with locally inconsistent
 * depths"). A point that won its pixel may still lie behind a surface whose points are spread apart, showing
 * through the gaps. Here a point is dropped when two opposite neighbours in its 3x3 neighbourhood (left and
 * right, above and below, or the ends of a diagonal) are both nearer than it by more than cull_ratio and
 * agree with each other much better than with it: in disparity (1 / depth, linear across a plane in the
 * image) the pair's spread is less than half its lead over the point, 2 |1/a - 1/b| < 1/max(a, b) - 1/c. That
 * is the mark of a point seen through a surface. Two simpler rules fail on frames the server sends whole:
 * against the neighbourhood's mean depth, the background point beside every silhouette is dropped (a still
 * camera would not show the frame as it was sent); with only "both nearer", a floor seen at a grazing angle
 * (its depth changing by more than cull_ratio from row to row) beside an object drops the floor's points
 * along the object's outline. What remains: a strip of background one pixel thin between two nearer surfaces
 * (a floor seen behind the line where a ball touches it) looks exactly like a gap and goes.
 *
 * Interpolation (1999, slides 15 and 18; 2002 3.3, Figure 3): the 3x3 filter with weights 1-2-1 / 2-4-2 /
 * 1-2-1 over the neighbourhood's points (after the cull), rounded to the nearest integer, fills a pixel
 * without a point (and with smooth_all replaces every pixel by that mean). The filter is separable: sums
 * along rows, then along columns, over planes of 16-bit values, in loops the compiler vectorises. The same
 * pass writes the priority image: a point's age (older first), or for a pixel without one 255 - 16 n, n the
 * points among its 8 neighbours (emptier first, 255 where there is none).
 *
 * Prefilter (2002 3.3): where the 3x3 found no point, the uniform mean of the points in the 7x7
 * neighbourhood. It works by tiles (only tiles with pixels to fill do anything): a tile with many such pixels
 * is filtered whole, separated into 7-sums along rows and then down columns over 16-bit planes (the paper
 * uses running sums, whose cost does not depend on the kernel's size: Smith's moving average; vector adds of
 * 7 values are cheaper here); a tile with few sums each one's 49 pixels. Both give the same integers. (By
 * full-width bands, as the other pixel passes, it was slower: 0.6-0.8 against 0.4 ms.) It does not change the
 * priority (2002 3.3). */
#include "rc_internal.h"

#include <math.h>
#include <string.h>

/* The pixel passes work on bands of full rows (the tile rows: tile_size rows each), so that every row is one
 * long stream for the prefetcher (64-pixel rows of a tile were short streams, each starting with a miss). */
static void band_rows(const view_rc *rc, uint32_t band, uint32_t *y0, uint32_t *y1)
{
    *y0 = band << rc->tile_shift;
    *y1 = *y0 + rc->tile < rc->height ? *y0 + rc->tile : rc->height;
}

/* ---- depth cull ---------------------------------------------------------------------------------------- */

/* One opposite pair (a, b) around depth z, threshold t = z / (1 + cull_ratio). */
FXC_HOT_INLINE bool pair_in_front(float a, float b, float z, float t)
{
    float lo = a < b ? a : b, hi = a < b ? b : a;
    return (hi < t) & (2.0f * (hi - lo) * z < (z - hi) * lo);
}

/* Pixels [xa, xb) of a row with a row above (zu) and below (zd), none of them on the image's left or right
 * edge. Writes the shown points and the output depth; returns the pixels culled. nearer = 0 turns the cull
 * off. The nine neighbourhood rows are nine pointers indexed alike, so each is one contiguous vector load. */
FXC_HOT_CLONES static uint32_t cull_span(const float *zu, const float *zc, const float *zd,
                                         const uint32_t *restrict pre, uint32_t *restrict pt,
                                         float *restrict depth, const float *restrict sx2, float sy2,
                                         float nearer, float sky, uint32_t xa, uint32_t xb)
{
    const float *restrict l = zc + xa - 1, *restrict c = zc + xa, *restrict r = zc + xa + 1;
    const float *restrict ul = zu + xa - 1, *restrict u = zu + xa, *restrict ur = zu + xa + 1;
    const float *restrict dl = zd + xa - 1, *restrict d = zd + xa, *restrict dr = zd + xa + 1;
    pre += xa, pt += xa, depth += xa, sx2 += xa;
    size_t n = xb - xa;
    uint32_t culled = 0;
    for (size_t x = 0; x < n; x++) {
        float z = c[x], t = z * nearer;
        bool behind = pair_in_front(l[x], r[x], z, t) | pair_in_front(u[x], d[x], z, t) |
                      pair_in_front(ul[x], dr[x], z, t) | pair_in_front(ur[x], dl[x], z, t);
        uint32_t v = pre[x];
        uint32_t occupied = v != RC_EMPTY_PT, cull = behind & occupied, mask = 0u - cull;
        pt[x] = (v & ~mask) | (RC_EMPTY_PT & mask); /* (a select the vectoriser takes) */
        float root = sqrtf(1.0f + sx2[x] + sy2), dist = z * root;
        float shown = z >= sky ? INFINITY : dist;
        depth[x] = occupied & !cull ? shown : NAN;
        culled += cull;
    }
    return culled;
}

/* The same for one pixel anywhere (the image's border rows and columns): neighbours outside are +inf. Writes
 * pixel x of the output rows pt_row and depth_row. */
static uint32_t cull_pixel(const view_rc *rc, uint32_t x, uint32_t y, uint32_t *pt_row, float *depth_row,
                           float nearer, float sky)
{
    size_t w = rc->width, p = y * w + x;
    uint32_t h = rc->height;
    const float *zbuf = rc->zbuf;
    bool l = x > 0, r = x + 1 < w, u = y > 0, d = y + 1 < h;
    float z = zbuf[p], t = z * nearer;
    bool behind =
        pair_in_front(l ? zbuf[p - 1] : INFINITY, r ? zbuf[p + 1] : INFINITY, z, t) |
        pair_in_front(u ? zbuf[p - w] : INFINITY, d ? zbuf[p + w] : INFINITY, z, t) |
        pair_in_front(l && u ? zbuf[p - w - 1] : INFINITY, r && d ? zbuf[p + w + 1] : INFINITY, z, t) |
        pair_in_front(r && u ? zbuf[p - w + 1] : INFINITY, l && d ? zbuf[p + w - 1] : INFINITY, z, t);
    uint32_t v = rc->pre[p];
    bool occupied = v != RC_EMPTY_PT, cull = behind & occupied;
    pt_row[x] = cull ? RC_EMPTY_PT : v;
    float depth = z >= sky ? INFINITY : z * sqrtf(1.0f + rc->stretch_x2[x] + rc->stretch_y2[y]);
    depth_row[x] = occupied && !cull ? depth : NAN;
    return cull;
}

/* Row y of the depth cull into the output rows pt_row and depth_row (the image's rows, or a halo row of a
 * band's scratch); returns the pixels culled. It reads only the z-buffer and the winners' colours, which the
 * z-buffer pass has finished for the whole image, so any row can be culled at any time, and twice alike. */
static uint32_t cull_row(const view_rc *rc, uint32_t y, uint32_t *pt_row, float *depth_row)
{
    size_t w = rc->width;
    uint32_t h = rc->height, culled = 0;
    float nearer = rc->d.no_depth_cull ? 0.0f : 1.0f / (1.0f + rc->d.cull_ratio);
    float sky = (float)(0.5 * VIEW_RC_SKY_DISTANCE);
    if (y == 0 || y + 1 >= h || w < 3) {
        for (uint32_t x = 0; x < w; x++)
            culled += cull_pixel(rc, x, y, pt_row, depth_row, nearer, sky);
        return culled;
    }
    size_t row = y * w;
    culled += cull_pixel(rc, 0, y, pt_row, depth_row, nearer, sky);
    culled += cull_span(rc->zbuf + row - w, rc->zbuf + row, rc->zbuf + row + w, rc->pre + row, pt_row,
                        depth_row, rc->stretch_x2, rc->stretch_y2[y], nearer, sky, 1, (uint32_t)w - 1);
    culled += cull_pixel(rc, (uint32_t)w - 1, y, pt_row, depth_row, nearer, sky);
    return culled;
}

/* Where each of n pixels marks: its shown point's slot, or `sink` when it shows none (vectorised). */
FXC_HOT_INLINE void mark_targets(const uint32_t *restrict pt, const uint32_t *restrict win, uint32_t sink,
                                 uint32_t *restrict at, uint32_t n)
{
    for (uint32_t x = 0; x < n; x++) {
        uint32_t shown = win[x]; /* read unconditionally: a plain vector load, not a masked one */
        at[x] = pt[x] == RC_EMPTY_PT ? sink : shown;
    }
}

/* The points shown in row y: visible for the ageing (no branch: a pixel without one marks the byte after the
 * last slot), in this thread's marks. The targets are computed in vectors a stretch at a time, so the scalar
 * loop is a load and a store a pixel (it was 13 instructions a pixel, the select and the mask in it).
 * Marking entries instead (tile-local writes) and reading them back through each slot's entry in the ageing
 * was slower: 0.8 against 0.3 ms for the ageing, the cull unchanged. */
FXC_HOT_CLONES static void mark_row(const view_rc *rc, uint32_t y, uint32_t worker)
{
    uint32_t w = rc->width;
    const uint32_t *pt = rc->pt + (size_t)y * w, *win = rc->win + (size_t)y * w;
    uint8_t *mark = rc->mark + worker * rc->mark_stride;
    uint32_t at[256];
    for (uint32_t x0 = 0; x0 < w; x0 += 256) {
        uint32_t n = w - x0 < 256 ? w - x0 : 256;
        mark_targets(pt + x0, win + x0, rc->slots, at, n);
        for (uint32_t k = 0; k < n; k++)
            mark[at[k]] = 1;
    }
}

/* ---- bands --------------------------------------------------------------------------------------------- */

/* One band of rows [y0, y1) going through the pixel passes. Fused (the default), one task takes its band
 * through the cull, the interpolation and the prefilter, row by row where it can (each row culled just
 * before the interpolation reads it, so the shown points are read back from L1, not from memory), and the
 * rows its filters read across its borders (one above and below for the 3x3, three for the 7x7) are culled
 * again into scratch of its own: the band never waits for its neighbours, one pool run and barrier instead of
 * three. The cull of a row reads only the finished z-buffer, so a halo row's points are exactly those its own
 * band writes. Separate (separate_pixel_passes), each pass is a run over all bands and reads its neighbours'
 * rows from the image, which the previous pass finished. */
typedef struct rc_band {
    view_rc *rc;
    uint32_t y0, y1;
    bool fused;
    uint32_t *halo;    /* fused: rows y0 - 3 .. y0 - 1 as halo rows 0..2, y1 .. y1 + 2 as 3..5 */
    float *halo_depth; /* a row the halo rows' depths go to (not used) */
    uint8_t halo_done; /* bit k: halo row k culled */
} rc_band;

/* The band's view of the shown points' row y (inside the image). */
static const uint32_t *band_pt(const rc_band *b, uint32_t y)
{
    if (!b->fused || (y >= b->y0 && y < b->y1))
        return b->rc->pt + (size_t)y * b->rc->width;
    uint32_t k = y < b->y0 ? 3 - (b->y0 - y) : 3 + (y - b->y1);
    return b->halo + (size_t)k * b->rc->width;
}

/* Fused: culls the halo rows within `reach` rows of the band (those inside the image, once each). */
static void band_halo(rc_band *b, uint32_t reach)
{
    if (!b->fused)
        return;
    for (uint32_t k = 0; k < 6; k++) {
        uint32_t d = k < 3 ? 3 - k : k - 2; /* distance from the band */
        if (d > reach || (b->halo_done >> k & 1))
            continue;
        int64_t y = k < 3 ? (int64_t)b->y0 - d : (int64_t)b->y1 + d - 1;
        if (y < 0 || y >= b->rc->height)
            continue;
        cull_row(b->rc, (uint32_t)y, b->halo + (size_t)k * b->rc->width, b->halo_depth);
        b->halo_done |= (uint8_t)(1u << k);
    }
}

static rc_band band_of(view_rc *rc, uint32_t band, uint32_t worker, bool fused)
{
    rc_band b = {.rc = rc, .fused = fused};
    band_rows(rc, band, &b.y0, &b.y1);
    b.halo = rc->workers[worker].halo;
    b.halo_depth = (float *)(b.halo + 6 * (size_t)rc->width);
    return b;
}

/* Separate: the band's rows culled and marked. */
static void cull_task(void *user, uint32_t band, uint32_t worker)
{
    view_rc *rc = user;
    uint32_t y0, y1, culled = 0;
    band_rows(rc, band, &y0, &y1);
    size_t w = rc->width;
    for (uint32_t y = y0; y < y1; y++)
        culled += cull_row(rc, y, rc->pt + y * w, rc->depth + y * w);
    for (uint32_t y = y0; y < y1; y++)
        mark_row(rc, y, worker);
    rc->band_culled[band] = culled;
}

static void set_stretch(view_rc *rc)
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
}

void view_rc__depth_cull(view_rc *rc)
{
    set_stretch(rc);
    rc_run_pixels(rc->pool, rc->d.dynamic_pixels, rc->tiles_y, cull_task, rc);
}

/* ---- interpolation and priority ----------------------------------------------------------------------- */

/* 16-bit values per worker for an image `width` wide: three rows of row sums (red, green, blue, weight,
 * count), one row of four planes (red, green, blue, occupied: width + 2 each), three output rows of bytes. */
size_t view_rc__interp_scratch(uint32_t width)
{
    size_t w = width;
    return 3 * 5 * w + 4 * (w + 2) + 2 * w;
}

/* A row of points as planes: red, green, blue (0 where empty) and occupied. */
FXC_HOT_CLONES static void unpack_span(const uint32_t *restrict src, uint16_t *restrict r,
                                       uint16_t *restrict g, uint16_t *restrict b, uint16_t *restrict o,
                                       uint32_t n)
{
    for (size_t x = 0; x < n; x++) {
        uint32_t v = src[x];
        r[x] = (uint16_t)(v & 0xFF);
        g[x] = (uint16_t)((v >> 8) & 0xFF);
        b[x] = (uint16_t)((v >> 16) & 0xFF);
        o[x] = v != RC_EMPTY_PT;
    }
}

/* Row sums: weighted 1-2-1 of each plane, and the plain count of occupied pixels. */
FXC_HOT_CLONES static void row_sums(const uint16_t *restrict r, const uint16_t *restrict g,
                                    const uint16_t *restrict b, const uint16_t *restrict o,
                                    uint16_t *restrict hr, uint16_t *restrict hg, uint16_t *restrict hb,
                                    uint16_t *restrict hw, uint16_t *restrict hn, uint32_t n)
{
    for (size_t x = 0; x < n; x++) {
        hr[x] = (uint16_t)(r[x] + 2 * r[x + 1] + r[x + 2]);
        hg[x] = (uint16_t)(g[x] + 2 * g[x + 1] + g[x + 2]);
        hb[x] = (uint16_t)(b[x] + 2 * b[x + 1] + b[x + 2]);
        hw[x] = (uint16_t)(o[x] + 2 * o[x + 1] + o[x + 2]);
        hn[x] = (uint16_t)(o[x] + o[x + 1] + o[x + 2]);
    }
}

/* Three planes of a row into rgb triples. */
FXC_HOT_CLONES static void interleave(const uint8_t *restrict r, const uint8_t *restrict g,
                                      const uint8_t *restrict b, uint8_t *restrict rgb, uint32_t n)
{
    for (size_t x = 0; x < n; x++) {
        rgb[3 * x] = r[x];
        rgb[3 * x + 1] = g[x];
        rgb[3 * x + 2] = b[x];
    }
}

/* One output row: the column sums of three rows of row sums (up, here, down: five planes each, `plane`
 * apart), the choice of colour, kind and priority (`own`: the row's shown points). */
FXC_HOT_CLONES static uint64_t
finish_row(const uint16_t *restrict up, const uint16_t *restrict here, const uint16_t *restrict down,
           size_t plane, const uint32_t *restrict own, uint8_t *restrict out_r, uint8_t *restrict out_g,
           uint8_t *restrict out_b, uint8_t *restrict kind, uint8_t *restrict priority, uint32_t n,
           bool smooth_all, const uint8_t clear[3], uint32_t kinds[VIEW_RC_PIXEL_KINDS])
{
    uint32_t weight = 0; /* at most 256 x VIEW_RC_MAX_SIDE a row: 32-bit lanes in the vector loop */
    uint32_t points = 0, interp = 0, empty = 0;
    const uint32_t clear_r = clear[0], clear_g = clear[1], clear_b = clear[2],
                   keep_own = smooth_all ? 0u : 1u;
    for (size_t x = 0; x < n; x++) {
        uint32_t sr = up[x] + 2u * here[x] + down[x];
        uint32_t sg = up[x + plane] + 2u * here[x + plane] + down[x + plane];
        uint32_t sb = up[x + 2 * plane] + 2u * here[x + 2 * plane] + down[x + 2 * plane];
        uint32_t sw = up[x + 3 * plane] + 2u * here[x + 3 * plane] + down[x + 3 * plane];
        uint32_t v = own[x];
        uint32_t has = v != RC_EMPTY_PT, keep = has & keep_own, filled = sw > 0;
        uint32_t count = up[x + 4 * plane] + here[x + 4 * plane] + down[x + 4 * plane] - has; /* not itself */
        /* Rounded division by 1..16: exact through the float reciprocal (an error below 1/64 either way). */
        float inv = 1.0f / (float)(sw | !filled);
        uint32_t half = sw / 2;
        uint32_t qr = (uint32_t)(int32_t)((float)(sr + half) * inv + (1.0f / 64));
        uint32_t qg = (uint32_t)(int32_t)((float)(sg + half) * inv + (1.0f / 64));
        uint32_t qb = (uint32_t)(int32_t)((float)(sb + half) * inv + (1.0f / 64));
        uint32_t mk = 0u - keep, mf = 0u - filled; /* masks: the selects the vectoriser takes */
        uint32_t fr = (qr & mf) | (clear_r & ~mf), fg = (qg & mf) | (clear_g & ~mf),
                 fb = (qb & mf) | (clear_b & ~mf);
        out_r[x] = (uint8_t)(((v & 0xFF) & mk) | (fr & ~mk));
        out_g[x] = (uint8_t)((((v >> 8) & 0xFF) & mk) | (fg & ~mk));
        out_b[x] = (uint8_t)((((v >> 16) & 0xFF) & mk) | (fb & ~mk));
        uint32_t k = has ? VIEW_RC_POINT : filled ? VIEW_RC_INTERP : VIEW_RC_EMPTY;
        kind[x] = (uint8_t)k;
        uint32_t mh = 0u - has, prio = ((v >> 24) & mh) | ((255 - 16 * count) & ~mh);
        priority[x] = (uint8_t)prio;
        weight += prio + 1;
        points += has;
        interp += (has ^ 1) & filled;
        empty += (has ^ 1) & (filled ^ 1);
    }
    kinds[VIEW_RC_POINT] += points;
    kinds[VIEW_RC_INTERP] += interp;
    kinds[VIEW_RC_EMPTY] += empty;
    return weight;
}

/* Columns [xa, xb) of row y of the shown points (as the band sees them) as row sums into `sums` (five planes,
 * `plane` apart); zeros for a row outside the image. The row sums at [xa, xb) read the pixels xa - 1 .. xb,
 * so only those are unpacked into `unpacked` (four planes of width + 2, pixel x at x + 1; the image's edges
 * read the zeros at both ends). */
static void interp_row(const rc_band *band, int64_t y, uint16_t *sums, size_t plane, uint16_t *unpacked,
                       uint32_t xa, uint32_t xb)
{
    uint32_t w = band->rc->width;
    size_t s = (size_t)w + 2;
    if (y < 0 || y >= band->rc->height) {
        for (int k = 0; k < 5; k++)
            memset(sums + k * plane + xa, 0, (xb - xa) * sizeof(uint16_t));
        return;
    }
    uint16_t *r = unpacked, *g = r + s, *b = g + s, *occupied = b + s;
    r[0] = g[0] = b[0] = occupied[0] = 0;
    r[s - 1] = g[s - 1] = b[s - 1] = occupied[s - 1] = 0;
    uint32_t lo = xa > 0 ? xa - 1 : 0, hi = xb < w ? xb + 1 : w; /* the pixels the sums read */
    unpack_span(band_pt(band, (uint32_t)y) + lo, r + 1 + lo, g + 1 + lo, b + 1 + lo, occupied + 1 + lo,
                hi - lo);
    row_sums(r + xa, g + xa, b + xa, occupied + xa, sums + xa, sums + plane + xa, sums + 2 * plane + xa,
             sums + 3 * plane + xa, sums + 4 * plane + xa, xb - xa);
}

/* Fused: the band's rows are culled RC_CULL_ROWS at a time, just before the interpolation reaches them, and
 * their shown points marked at once (the batch's rows still in L1): the cull's rows (three of depth, the
 * colours, the outputs) and the interpolation's (row sums, planes) do not fit in L1 together, so each runs
 * over a batch alone. Row by row, the interpolation's rows left L1 between rows (D1 misses 76.4 -> 91.5 M in
 * 80 frames, the marks' random stores most of it). */
enum { RC_CULL_ROWS = 8 };

/* Fused: makes sure row y is culled (the band's own rows a batch at a time into the image, with their marks;
 * the row below the band into the halo). */
static void fused_cull(rc_band *b, uint32_t y, uint32_t worker, uint32_t *culled_to, uint32_t *culled)
{
    if (!b->fused || y >= b->rc->height || y < *culled_to)
        return;
    if (y >= b->y1) {
        band_halo(b, 1);
        return;
    }
    view_rc *rc = b->rc;
    size_t w = rc->width;
    uint32_t end = y + RC_CULL_ROWS < b->y1 ? y + RC_CULL_ROWS : b->y1;
    for (uint32_t r = y; r < end; r++)
        *culled += cull_row(rc, r, rc->pt + r * w, rc->depth + r * w);
    for (uint32_t r = y; r < end; r++)
        mark_row(rc, r, worker);
    *culled_to = end;
}

/* The interpolation's columns at a time: its rows (three of row sums in five planes, the four unpacked planes,
 * the three output planes: 41 bytes a pixel of width) for 256 columns take 10 KiB of L1, where whole rows of
 * 1024 (with three rows of occupancy then, 47 bytes a pixel) took 49 KiB, the whole L1 of a core with 48 KiB.
 * Every output pixel depends only on its neighbourhood, so the strips give the same image as whole rows. */
enum { RC_INTERP_STRIP = 256 };

/* Rows of a band, each from the row sums of the rows above, itself and below (three kept, one new a row).
 * The rows go in groups (those the culled batch allows: each output row needs the row below culled), each
 * group in strips of columns: a strip's three rows of row sums stay in the ring (indexed by the row) from one
 * group to the next. */
static void band_interpolate(view_rc *rc, rc_band *b, uint32_t band, uint32_t worker)
{
    uint32_t y0 = b->y0, y1 = b->y1, culled = 0, culled_to = y0;
    uint32_t w = rc->width;
    size_t plane = w, s = (size_t)w + 2;
    uint16_t *scratch = rc->workers[worker].planes;
    uint16_t *sums[3] = {scratch, scratch + 5 * plane, scratch + 10 * plane};
    uint16_t *unpacked = scratch + 15 * plane;
    uint8_t *out_r = (uint8_t *)(unpacked + 4 * s), *out_g = out_r + w, *out_b = out_g + w;
    if (b->fused && y0 > 0)
        band_halo(b, 1);
    fused_cull(b, y0, worker, &culled_to, &culled);
    uint32_t kinds[VIEW_RC_PIXEL_KINDS] = {0};
    uint64_t weight = 0;
    for (uint32_t ya = y0; ya < y1;) {
        uint32_t yb; /* output rows [ya, yb) in this group */
        if (b->fused) {
            fused_cull(b, ya + 1, worker, &culled_to, &culled);
            yb = culled_to >= y1 ? y1 : culled_to - 1;
            if (yb == y1)
                fused_cull(b, y1, worker, &culled_to, &culled); /* the halo row below the band */
        } else {
            yb = ya + RC_CULL_ROWS < y1 ? ya + RC_CULL_ROWS : y1;
        }
        for (uint32_t xa = 0; xa < w; xa += RC_INTERP_STRIP) {
            uint32_t xb = w - xa > RC_INTERP_STRIP ? xa + RC_INTERP_STRIP : w, n = xb - xa;
            if (ya == y0) {
                interp_row(b, (int64_t)y0 - 1, sums[(y0 + 2) % 3], plane, unpacked, xa, xb);
                interp_row(b, y0, sums[y0 % 3], plane, unpacked, xa, xb);
            }
            for (uint32_t y = ya; y < yb; y++) {
                interp_row(b, (int64_t)y + 1, sums[(y + 1) % 3], plane, unpacked, xa, xb);
                size_t p = (size_t)y * w + xa;
                uint32_t before = kinds[VIEW_RC_EMPTY];
                weight += finish_row(sums[(y + 2) % 3] + xa, sums[y % 3] + xa, sums[(y + 1) % 3] + xa, plane,
                                     rc->pt + p, out_r + xa, out_g + xa, out_b + xa, rc->kind + p,
                                     rc->priority + p, n, rc->d.smooth_all, rc->d.clear_rgb, kinds);
                uint32_t need = kinds[VIEW_RC_EMPTY] - before;
                rc->row_need[y] = xa == 0 ? need : rc->row_need[y] + need;
                interleave(out_r + xa, out_g + xa, out_b + xa, rc->rgb + 3 * p, n);
            }
        }
        ya = yb;
    }
    if (b->fused)
        rc->band_culled[band] = culled;
    memcpy(rc->band_kind + (size_t)band * VIEW_RC_PIXEL_KINDS, kinds, sizeof kinds);
    rc->band_need[band] = rc->d.no_prefilter ? 0 : kinds[VIEW_RC_EMPTY];
    rc->band_weight[band] = weight;
}

static void interpolate_task(void *user, uint32_t band, uint32_t worker)
{
    view_rc *rc = user;
    rc_band b = band_of(rc, band, worker, false);
    band_interpolate(rc, &b, band, worker);
}

void view_rc__interpolate(view_rc *rc)
{
    rc_run_pixels(rc->pool, rc->d.dynamic_pixels, rc->tiles_y, interpolate_task, rc);
}

typedef struct rc_rect {
    uint32_t x0, y0, x1, y1;
} rc_rect;

static rc_rect tile_rect(const view_rc *rc, uint32_t tile)
{
    rc_rect r;
    r.x0 = (tile % rc->tiles_x) << rc->tile_shift;
    r.y0 = (tile / rc->tiles_x) << rc->tile_shift;
    r.x1 = r.x0 + rc->tile < rc->width ? r.x0 + rc->tile : rc->width;
    r.y1 = r.y0 + rc->tile < rc->height ? r.y0 + rc->tile : rc->height;
    return r;
}

/* ---- prefilter ----------------------------------------------------------------------------------------- */

static void fill_from(uint8_t *rgb, const uint32_t acc[4])
{
    for (int c = 0; c < 3; c++)
        rgb[c] = (uint8_t)((acc[c] + acc[3] / 2) / acc[3]);
}

/* Pixels of kind VIEW_RC_EMPTY among n (vectorised). */
FXC_HOT_CLONES static uint32_t count_empty(const uint8_t *restrict kind, uint32_t n)
{
    uint32_t empty = 0;
    for (uint32_t x = 0; x < n; x++)
        empty += kind[x] == VIEW_RC_EMPTY;
    return empty;
}

/* Tiles with few pixels to fill: each one's 7x7 window summed directly. */
static uint32_t prefilter_direct(view_rc *rc, const rc_band *b, rc_rect r)
{
    uint32_t w = rc->width, h = rc->height, filled = 0;
    for (uint32_t y = r.y0; y < r.y1; y++) {
        if (rc->row_need[y] == 0 || count_empty(rc->kind + (size_t)y * w + r.x0, r.x1 - r.x0) == 0)
            continue; /* no pixel of the tile's row to fill */
        for (uint32_t x = r.x0; x < r.x1; x++) {
            size_t p = (size_t)y * w + x;
            if (rc->kind[p] != VIEW_RC_EMPTY)
                continue;
            uint32_t acc[4] = {0, 0, 0, 0};
            uint32_t ya = y >= 3 ? y - 3 : 0, yb = y + 4 < h ? y + 4 : h;
            uint32_t xa = x >= 3 ? x - 3 : 0, xb = x + 4 < w ? x + 4 : w;
            for (uint32_t yy = ya; yy < yb; yy++) {
                const uint32_t *row = band_pt(b, yy);
                for (uint32_t xx = xa; xx < xb; xx++) {
                    uint32_t v = row[xx];
                    if (v == RC_EMPTY_PT)
                        continue;
                    acc[0] += v & 0xFF, acc[1] += (v >> 8) & 0xFF, acc[2] += (v >> 16) & 0xFF;
                    acc[3]++;
                }
            }
            if (acc[3] > 0) {
                fill_from(rc->rgb + 3 * p, acc);
                rc->kind[p] = VIEW_RC_PREFILTER;
                filled++;
            }
        }
    }
    return filled;
}

/* 16-bit values of a worker's prefilter scratch for tiles of side `tile`: four planes (red, green, blue,
 * occupied) of the tile and a three-pixel border, their 7-sums along the rows, and one row of 7-sums down the
 * columns. */
size_t view_rc__prefilter_scratch(uint32_t tile)
{
    size_t s = (size_t)tile + 6;
    return 4 * s * s + 4 * s * tile + 4 * (size_t)tile;
}

/* Sums of 7 consecutive values, n of them (src holds n + 6). */
FXC_HOT_CLONES static void sums7(const uint16_t *restrict src, uint16_t *restrict out, uint32_t n)
{
    for (size_t x = 0; x < n; x++)
        out[x] =
            (uint16_t)(src[x] + src[x + 1] + src[x + 2] + src[x + 3] + src[x + 4] + src[x + 5] + src[x + 6]);
}

/* Sums of the same column over 7 rows `stride` apart, n columns. */
FXC_HOT_CLONES static void sums7_down(const uint16_t *restrict src, size_t stride, uint16_t *restrict out,
                                      uint32_t n)
{
    for (size_t x = 0; x < n; x++)
        out[x] = (uint16_t)(src[x] + src[x + stride] + src[x + 2 * stride] + src[x + 3 * stride] +
                            src[x + 4 * stride] + src[x + 5 * stride] + src[x + 6 * stride]);
}

/* Tiles with many: the box filter separated, rows then columns, on 16-bit planes (the loops vectorise; the
 * largest sum, 49 x 255, fits). */
static uint32_t prefilter_planes(view_rc *rc, const rc_band *b, rc_rect r, uint16_t *scratch)
{
    uint32_t w = rc->width, h = rc->height, tw = r.x1 - r.x0, th = r.y1 - r.y0, filled = 0;
    uint32_t s = tw + 6;
    size_t plane = (size_t)s * (th + 6), rows = (size_t)(th + 6) * tw;
    uint16_t *planes = scratch, *hsum = planes + 4 * plane, *vsum = hsum + 4 * rows;
    for (uint32_t j = 0; j < th + 6; j++) {
        int64_t y = (int64_t)r.y0 + j - 3;
        size_t q = (size_t)j * s;
        for (int c = 0; c < 4; c++)
            memset(planes + c * plane + q, 0, s * sizeof(uint16_t));
        if (y < 0 || y >= h)
            continue;
        /* Columns x0 - 3 .. x1 + 2, those inside the image. */
        int64_t xa = (int64_t)r.x0 - 3 < 0 ? 0 : (int64_t)r.x0 - 3, xb = r.x1 + 3 < w ? r.x1 + 3 : w;
        size_t i0 = (size_t)(xa - ((int64_t)r.x0 - 3));
        unpack_span(band_pt(b, (uint32_t)y) + xa, planes + q + i0, planes + plane + q + i0,
                    planes + 2 * plane + q + i0, planes + 3 * plane + q + i0, (uint32_t)(xb - xa));
    }
    for (int c = 0; c < 4; c++)
        for (uint32_t j = 0; j < th + 6; j++)
            sums7(planes + c * plane + (size_t)j * s, hsum + c * rows + (size_t)j * tw, tw);
    for (uint32_t j = 0; j < th; j++) {
        size_t p = (size_t)(r.y0 + j) * w + r.x0;
        if (rc->row_need[r.y0 + j] == 0 || count_empty(rc->kind + p, tw) == 0)
            continue; /* no pixel of the tile's row to fill */
        for (int c = 0; c < 4; c++)
            sums7_down(hsum + c * rows + (size_t)j * tw, tw, vsum + (size_t)c * tw, tw);
        for (uint32_t x = 0; x < tw; x++) {
            uint32_t count = vsum[3 * (size_t)tw + x];
            if (rc->kind[p + x] != VIEW_RC_EMPTY || count == 0)
                continue;
            uint32_t acc[4] = {vsum[x], vsum[(size_t)tw + x], vsum[2 * (size_t)tw + x], count};
            fill_from(rc->rgb + 3 * (p + x), acc);
            rc->kind[p + x] = VIEW_RC_PREFILTER;
            filled++;
        }
    }
    return filled;
}

/* The band's tiles that have pixels to fill (fused: once the halo's three rows each side are culled). */
static void band_prefilter(view_rc *rc, rc_band *b, uint32_t band, uint32_t worker)
{
    if (rc->band_need[band] == 0)
        return;
    uint32_t filled = 0;
    for (uint32_t tile = band * rc->tiles_x; tile < (band + 1) * rc->tiles_x; tile++) {
        rc_rect r = tile_rect(rc, tile);
        uint32_t need = 0;
        for (uint32_t y = r.y0; y < r.y1; y++)
            if (rc->row_need[y] > 0)
                need += count_empty(rc->kind + (size_t)y * rc->width + r.x0, r.x1 - r.x0);
        if (need == 0)
            continue;
        band_halo(b, 3);
        /* 49 reads a pixel, against the planes' few vector operations per pixel of the tile (about 25 pixels
         * to fill in a 64 x 64 tile cost as much either way). */
        uint64_t tile_pixels = (uint64_t)(r.x1 - r.x0) * (r.y1 - r.y0);
        filled += (uint64_t)need * 49 * 4 < tile_pixels * 1
                      ? prefilter_direct(rc, b, r)
                      : prefilter_planes(rc, b, r, rc->workers[worker].box);
    }
    uint32_t *kinds = rc->band_kind + (size_t)band * VIEW_RC_PIXEL_KINDS;
    kinds[VIEW_RC_EMPTY] -= filled;
    kinds[VIEW_RC_PREFILTER] += filled;
}

static void prefilter_task(void *user, uint32_t band, uint32_t worker)
{
    view_rc *rc = user;
    rc_band b = band_of(rc, band, worker, false);
    band_prefilter(rc, &b, band, worker);
}

void view_rc__prefilter(view_rc *rc)
{
    rc_run_pixels(rc->pool, rc->d.dynamic_pixels, rc->tiles_y, prefilter_task, rc);
}

/* ---- the three fused ------------------------------------------------------------------------------------
 */

static void pixels_task(void *user, uint32_t band, uint32_t worker)
{
    view_rc *rc = user;
    rc_band b = band_of(rc, band, worker, true);
    band_interpolate(rc, &b, band, worker);
    if (!rc->d.no_prefilter)
        band_prefilter(rc, &b, band, worker);
}

void view_rc__pixels(view_rc *rc)
{
    set_stretch(rc);
    rc_run_pixels(rc->pool, rc->d.dynamic_pixels, rc->tiles_y, pixels_task, rc);
}
