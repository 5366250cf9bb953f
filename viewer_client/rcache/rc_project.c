/* The point passes of a frame: the drop plan, the predicted projection (2002 3.1), projection and tile sort
 * (2002 3.2; the tile lists of Reinhard 2001 section 3), the tiled z-buffer (2002 3.2), the one-pass z-buffer
 * of the 1999 render cache (no_tiling), and ageing with eviction (2002 3.4).
 *
 * The predicted projection is computed in the projection pass: each block of 1024 points is projected to the
 * current camera, then to the predicted one while its positions are still in L1 (a pass of its own read the
 * store, 16 bytes a point, from memory a second time).
 *
 * Project and tile sort, per chunk of slots (parallel): every live point is projected once, in a loop without
 * branches (vectorised); the chunk counts how many of its points go to each tile. One serial step turns the
 * counts into offsets, tile by tile, part by part within a tile (a part: the chunks one thread owns) and
 * chunk by chunk within a part, each (tile, part) list starting on a cache line of its own; the bucket sort
 * (parallel again) writes each projected point as a 16-byte entry at its offset. The order within a tile
 * (part, then chunk, then slot: chunk then slot) does not depend on the thread count.
 *
 * Every pass over chunks of slots (predicted projection, projection, sort, ageing) is a static run of the
 * pool (fxc_pool_run_static): thread k takes the same range of chunks in each, so the slots' positions,
 * colours, pixels, depths and lists stay in its core's cache from pass to pass and frame to frame, and the
 * (tile, part) lists mean no line of entries is written by two cores. (With the pool's dynamic hand-out a
 * chunk went to whichever thread asked first, differently in every pass: on 2 threads the point passes got
 * slower than on one.) A thread that has finished its range takes chunks from the end of another's; such a
 * chunk still writes its own part's list, so the result is the same.
 *
 * The z-buffer then reads one tile's list (parallel over tiles) into buffers of the tile's own (tiles up to
 * 256 on a side): 64 x 64 pixels of depth, winner and colour, 48 KiB contiguous, which stay in cache while
 * the tile's entries stream past, then copied into the image row by row. (Written straight into the image,
 * the tile's 64 rows lie 4 x width bytes apart and fall into a few of L1's sets: cachegrind counted an L1
 * miss for nearly every z-buffer write.) The nearer view depth wins; between equal depths, the entry first in
 * the list.
 *
 * Band lists (band_z): the same with bands of full rows for tiles (a band's depth, winner and colour at most
 * 384 KiB, in L2), each band tested straight into the image's rows; on one thread (band_flush) without the
 * sort pass: chunks appended to per-band buffers, flushed into the band's rows when full and at the end. */
#include "rc_internal.h"

#include <math.h>
#include <string.h>

/* ---- drop plan ----------------------------------------------------------------------------------------- */

void view_rc__plan_drops(view_rc *rc)
{
    uint64_t hist[256] = {0}, live = 0;
    for (uint32_t c = 0; c < rc->chunk_count; c++)
        for (uint32_t a = 0; a < 255; a++) {
            hist[a] += rc->chunk_hist[(size_t)c * 256 + a];
            live += rc->chunk_hist[(size_t)c * 256 + a];
        }
    memset(rc->chunk_quota, 0, rc->chunk_count * sizeof(uint32_t));
    rc->drop_age = RC_AGE_NO_DROP;
    if (live <= rc->d.capacity)
        return;
    /* The oldest first (2002 3.4: ageing is set so that a point reaches 128 before it is overwritten). */
    uint64_t drop = live - rc->d.capacity, above = 0;
    int age = 254;
    while (age > 0 && above + hist[age] < drop)
        above += hist[age--];
    rc->drop_age = (uint32_t)age;
    uint64_t take = drop - above; /* points of exactly that age, the first ones in slot order */
    for (uint32_t c = 0; c < rc->chunk_count && take > 0; c++) {
        uint32_t n = rc->chunk_hist[(size_t)c * 256 + (uint32_t)age];
        rc->chunk_quota[c] = n < take ? n : (uint32_t)take;
        take -= rc->chunk_quota[c];
    }
}

/* A pass over every chunk: statically split (each thread on the same chunks in every pass, stealing from the
 * others' ends when done), or, with dynamic_points, handed out by the pool's counter. */
static void run_chunks(view_rc *rc, fxc_pool_task task)
{
    if (rc->d.dynamic_points)
        fxc_pool_run(rc->pool, rc->chunk_count, task, rc);
    else
        fxc_pool_run_static(rc->pool, rc->chunk_count, task, rc, true);
}

static void chunk_range(const view_rc *rc, uint32_t c, uint32_t *begin, uint32_t *end)
{
    *begin = c * rc->chunk_size;
    *end = *begin + rc->chunk_size < rc->slots ? *begin + rc->chunk_size : rc->slots;
}

/* ---- projection without branches ----------------------------------------------------------------------- */

/* The pixel of every slot in [begin, end) for view v (RC_NO_PIXEL for free slots, points behind the camera or
 * outside the image; `local`: row * tile + column within its tile, else band << band_bits | the pixel within
 * its band of 1 << band_shift rows, row * width + column: with band_shift 31, the image's index), its depth,
 * and its list: the tile (two shifts of the pixel's coordinates), or `outside`, or `dead` for a free slot.
 * rc_project's arithmetic; the conversion to integers happens only on coordinates known to be inside. (The
 * slot within the chunk is added to the key by the sort: in this loop it cost 1.2 M instructions a frame.) */
FXC_HOT_CLONES static void project_span(const rc_view *v, const float *restrict px, const float *restrict py,
                                        const float *restrict pz, const uint32_t *restrict rgba,
                                        uint32_t *restrict key, float *restrict dep, uint16_t *restrict dest,
                                        uint32_t begin, uint32_t end, uint32_t shift, uint32_t tiles_x,
                                        bool local, uint32_t band_shift, uint32_t band_bits, uint16_t outside,
                                        uint16_t dead)
{
    const float cx = v->rel[0], cy = v->rel[1], cz = v->rel[2];
    const float fx = v->forward[0], fy = v->forward[1], fz = v->forward[2];
    const float rx = v->right[0], ry = v->right[1], rz = v->right[2];
    const float ux = v->up[0], uy = v->up[1], uz = v->up[2];
    const float hw = v->half_w, hh = v->half_h, kx = v->kx, ky = v->ky;
    const float w = (float)v->width, h = (float)v->height;
    const uint32_t width = v->width, m = (1u << shift) - 1, band_mask = (1u << band_shift) - 1;
    for (uint32_t i = begin; i < end; i++) {
        float vx = px[i] - cx, vy = py[i] - cy, vz = pz[i] - cz;
        float zc = vx * fx + vy * fy + vz * fz;
        float xc = vx * rx + vy * ry + vz * rz;
        float yc = vx * ux + vy * uy + vz * uz;
        float inv = 1.0f / zc;
        float sx = hw + kx * xc * inv;
        float sy = hh - ky * yc * inv;
        bool live = (rgba[i] >> 24) != RC_AGE_DEAD;
        bool inside = live & (zc > RC_NEAR) & (sx >= 0.0f) & (sx < w) & (sy >= 0.0f) & (sy < h);
        uint32_t ix = (uint32_t)(int32_t)(inside ? sx : 0.0f);
        uint32_t iy = (uint32_t)(int32_t)(inside ? sy : 0.0f);
        uint32_t tile = (iy >> shift) * tiles_x + (ix >> shift);
        uint32_t in_tile = ((iy & m) << shift) | (ix & m);
        uint32_t in_band = ((iy >> band_shift) << band_bits) | ((iy & band_mask) * width + ix);
        key[i] = inside ? (local ? in_tile : in_band) : RC_NO_PIXEL;
        dep[i] = zc;
        dest[i] = (uint16_t)(inside ? tile : live ? outside : dead);
    }
}

/* ---- predicted projection (2002 3.1) ------------------------------------------------------------------- */

/* The quarter-resolution pixel of every slot in [begin, end) for view v (`none` when none: the byte after the
 * occupancy image, so the marking loop is a load and a store a point). */
FXC_HOT_CLONES static void predict_span(const rc_view *v, const float *restrict px, const float *restrict py,
                                        const float *restrict pz, const uint32_t *restrict rgba,
                                        uint32_t *restrict low, uint32_t begin, uint32_t end, uint32_t low_w,
                                        uint32_t none)
{
    const float cx = v->rel[0], cy = v->rel[1], cz = v->rel[2];
    const float fx = v->forward[0], fy = v->forward[1], fz = v->forward[2];
    const float rx = v->right[0], ry = v->right[1], rz = v->right[2];
    const float ux = v->up[0], uy = v->up[1], uz = v->up[2];
    const float hw = v->half_w, hh = v->half_h, kx = v->kx, ky = v->ky;
    const float w = (float)v->width, h = (float)v->height;
    for (uint32_t i = begin; i < end; i++) {
        float vx = px[i] - cx, vy = py[i] - cy, vz = pz[i] - cz;
        float zc = vx * fx + vy * fy + vz * fz;
        float xc = vx * rx + vy * ry + vz * rz;
        float yc = vx * ux + vy * uy + vz * uz;
        float inv = 1.0f / zc;
        float sx = hw + kx * xc * inv;
        float sy = hh - ky * yc * inv;
        bool live = (rgba[i] >> 24) != RC_AGE_DEAD;
        bool inside = live & (zc > RC_NEAR) & (sx >= 0.0f) & (sx < w) & (sy >= 0.0f) & (sy < h);
        uint32_t ix = (uint32_t)(int32_t)(inside ? sx : 0.0f) >> 2;
        uint32_t iy = (uint32_t)(int32_t)(inside ? sy : 0.0f) >> 2;
        low[i - begin] = inside ? iy * low_w + ix : none;
    }
}

/* No z-buffer and a quarter of the resolution in each direction: only whether any point lands in a pixel. */
static void predict_task(void *user, uint32_t c, uint32_t worker)
{
    view_rc *rc = user;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint32_t *low = rc->workers[worker].low;
    uint8_t *occupied = rc->workers[worker].occupied;
    /* Without a branch: points that land nowhere mark the byte after the image. */
    uint32_t sink = rc->low_w * rc->low_h;
    predict_span(&rc->predicted, rc->px, rc->py, rc->pz, rc->rgba, low, begin, end, rc->low_w, sink);
    for (uint32_t k = 0; k < end - begin; k++)
        occupied[low[k]] = 1;
}

void view_rc__predict_clear(view_rc *rc)
{
    size_t low = (size_t)rc->low_w * rc->low_h;
    for (uint32_t t = 0; t < rc->thread_count; t++)
        memset(rc->workers[t].occupied, 0, low);
}

void view_rc__predict_combine(view_rc *rc)
{
    size_t low = (size_t)rc->low_w * rc->low_h;
    uint8_t *all = rc->workers[0].occupied;
    for (uint32_t t = 1; t < rc->thread_count; t++) {
        const uint8_t *mine = rc->workers[t].occupied;
        for (size_t p = 0; p < low; p++)
            all[p] |= mine[p];
    }
}

/* Whether any of 64 points is live and at least drop_age old (vectorised). */
FXC_HOT_CLONES static bool any_candidate(const uint32_t *restrict rgba, uint32_t drop_age)
{
    uint32_t any = 0;
    for (uint32_t k = 0; k < 64; k++) {
        uint32_t age = rgba[k] >> 24;
        any |= (uint32_t)(age >= drop_age) & (uint32_t)(age != RC_AGE_DEAD);
    }
    return any != 0;
}

/* ---- project and tile sort ----------------------------------------------------------------------------- */

/* Live points of exactly `age` among n (vectorised). */
FXC_HOT_CLONES static uint32_t count_age(const uint32_t *restrict rgba, uint32_t n, uint32_t age)
{
    uint32_t same = 0;
    for (uint32_t k = 0; k < n; k++)
        same += (rgba[k] >> 24) == age; /* age < 255: a free slot never matches */
    return same;
}

/* Drops every live point at least drop_age old among n, without branches (vectorised): the slot is freed and
 * leaves this frame's lists (and no_tiling's image: its key RC_NO_PIXEL). */
FXC_HOT_CLONES static void drop_block(uint32_t *restrict rgba, uint32_t *restrict key,
                                      uint16_t *restrict dest, uint32_t n, uint32_t drop_age, uint16_t dead,
                                      rc_chunk_stat *stat)
{
    uint32_t dropped = 0, age_sum = 0;
    for (uint32_t k = 0; k < n; k++) {
        uint32_t v = rgba[k], age = v >> 24;
        uint32_t drop = (age != RC_AGE_DEAD) & (age >= drop_age), mask = 0u - drop;
        dropped += drop;
        age_sum += age & mask;
        rgba[k] = v | (0xFF000000u & mask);
        key[k] = key[k] | mask; /* RC_NO_PIXEL is all ones */
        dest[k] = (uint16_t)((dest[k] & ~mask) | (dead & mask));
    }
    stat->dropped += dropped;
    stat->dropped_age_sum += age_sum;
}

/* Migrations (a projected or outside point whose list changed; new points not counted), and the lists
 * remembered for the next frame. */
FXC_HOT_CLONES static uint32_t migrate_span(const uint16_t *restrict dest, uint16_t *restrict tile_of,
                                            uint32_t begin, uint32_t end, uint16_t dead, uint16_t fresh)
{
    uint32_t migrated = 0;
    for (uint32_t i = begin; i < end; i++) {
        uint16_t d = dest[i], t = tile_of[i];
        migrated += (d != dead) & (t != fresh) & (t != d);
        tile_of[i] = d;
    }
    return migrated;
}

/* One thread's z-buffer straight into the image (direct_z): a chunk's n projected points (key, dep and rgba
 * indexed from its first slot, `first`) in slot order, each tested against its pixel (the nearer depth wins;
 * between equal depths the first, as in the tile lists, which hold a tile's points in slot order too).
 * Returns the points projected.
 *
 * The image's depths, winners and colours (3 MiB at 512 x 512) do not stay in L2, and the points land at
 * random in them, so a test a point in one loop waited for its depth's miss, then for the stores' lines
 * (perf: 45 % of that loop's samples on the compare). So in blocks of RC_ZBLOCK points (128: a block's three
 * lines a point fit in L1), three steps: the depth held at every projected point's pixel read without a
 * branch (vectorised: the loads, independent, overlap their misses) and the points nearer than it listed as
 * candidates; the candidates' winner and colour lines fetched for writing; then the candidates tested in slot
 * order against the z-buffer as it is now (the lines in cache). The depths only fall, so a point that was not
 * nearer then is not nearer now: the same winners as one test a point in slot order. */
#define RC_ZBLOCK 128u

FXC_HOT_CLONES static uint32_t zbuffer_candidates(const uint32_t *restrict key, const float *restrict dep,
                                                  uint32_t n, const float *restrict zbuf,
                                                  uint16_t *restrict list, uint32_t *restrict projected)
{
    /* Flags first, in a loop without a branch (no pixel reads pixel 0 and is not flagged), then the list. */
    uint8_t flag[RC_ZBLOCK];
    uint32_t shown = 0;
    for (uint32_t k = 0; k < n; k++) {
        uint32_t p = key[k];
        uint32_t valid = p != RC_NO_PIXEL;
        float held = zbuf[p & (0u - valid)];
        flag[k] = (uint8_t)(valid & (dep[k] < held));
        shown += valid;
    }
    uint32_t count = 0;
    for (uint32_t k = 0; k < n; k++) {
        list[count] = (uint16_t)k;
        count += flag[k];
    }
    *projected += shown;
    return count;
}

static uint32_t zbuffer_span(const uint32_t *restrict key, const float *restrict dep,
                             const uint32_t *restrict rgba, uint32_t first, uint32_t n, float *restrict zbuf,
                             uint32_t *restrict win, uint32_t *restrict pre)
{
    uint32_t projected = 0;
    uint16_t list[RC_ZBLOCK];
    for (uint32_t b0 = 0; b0 < n; b0 += RC_ZBLOCK) {
        uint32_t m = n - b0 < RC_ZBLOCK ? n - b0 : RC_ZBLOCK;
        uint32_t count = zbuffer_candidates(key + b0, dep + b0, m, zbuf, list, &projected);
        for (uint32_t j = 0; j < count; j++) {
            uint32_t p = key[b0 + list[j]];
            __builtin_prefetch(&win[p], 1);
            __builtin_prefetch(&pre[p], 1);
        }
        for (uint32_t j = 0; j < count; j++) {
            uint32_t k = b0 + list[j], p = key[k];
            float z = dep[k];
            if (z < zbuf[p]) {
                zbuf[p] = z;
                win[p] = first + k;
                pre[p] = rgba[k];
            }
        }
    }
    return projected;
}

/* The band of a key (band << bits | pixel within the band): RC_NO_PIXEL, and anything past the last band,
 * go to list `bands`, the sink. */
#define RC_BAND_OF(k) ((k) >> bits < bands ? (k) >> bits : bands)

/* Band lists: a chunk's n keys counted by band (key >> bits; RC_NO_PIXEL and anything past the last band in
 * list `bands`, the sink), in four interleaved sets (consecutive points mostly go to one band). */
static void count_bands(const uint32_t *restrict key, uint32_t n, uint32_t bits, uint32_t bands,
                        uint32_t *restrict count)
{
    uint32_t part[4][VIEW_RC_MAX_TILES + 2];
    for (int k = 0; k < 4; k++)
        memset(part[k], 0, (bands + 1) * sizeof(uint32_t));
    uint32_t i = 0;
    for (; i + 4 <= n; i += 4) {
        part[0][RC_BAND_OF(key[i])]++;
        part[1][RC_BAND_OF(key[i + 1])]++;
        part[2][RC_BAND_OF(key[i + 2])]++;
        part[3][RC_BAND_OF(key[i + 3])]++;
    }
    for (; i < n; i++)
        part[0][RC_BAND_OF(key[i])]++;
    for (uint32_t b = 0; b <= bands; b++)
        count[b] = part[0][b] + part[1][b] + part[2][b] + part[3][b];
}

/* band_flush: chunk c's entries [from, to) of band b's buffer noted as a segment (none when empty). */
static void note_segment(view_rc *rc, uint32_t b, uint32_t c, uint32_t from, uint32_t to)
{
    if (to == from)
        return;
    uint32_t *seg = rc->zband_seg + (size_t)b * 2 * rc->chunk_count + 2 * rc->zband_nseg[b]++;
    seg[0] = c;
    seg[1] = to;
}

/* The depth, winner and colour of n pixels cleared (vectorised). */
FXC_HOT_CLONES static void clear_z(float *restrict zb, uint32_t *restrict wb, uint32_t *restrict cb, size_t n)
{
    for (size_t p = 0; p < n; p++) {
        zb[p] = INFINITY;
        wb[p] = RC_NO_POINT;
        cb[p] = RC_EMPTY_PT;
    }
}

/* band_flush: band `band`'s buffer depth-tested into its rows of the image, segment by segment (the chunks in
 * order, each chunk's entries in slot order), then emptied. The rows are cleared at the band's first flush of
 * the frame. */
static void flush_band(view_rc *rc, uint32_t band)
{
    size_t first = (size_t)band * rc->zband_rows * rc->width;
    size_t last = (size_t)(band + 1) * rc->zband_rows * rc->width;
    last = last < rc->pixels ? last : rc->pixels;
    float *restrict zb = rc->zbuf + first;
    uint32_t *restrict wb = rc->win + first, *restrict cb = rc->pre + first;
    if (!rc->zband_clear[band]) {
        clear_z(zb, wb, cb, last - first);
        rc->zband_clear[band] = 1;
    }
    const rc_entry *entries = rc->entries;
    const uint32_t *rgba = rc->rgba;
    uint32_t bits = rc->zband_bits, mask = (1u << bits) - 1, at = band * rc->zband_cap;
    const uint32_t *seg = rc->zband_seg + (size_t)band * 2 * rc->chunk_count;
    for (uint32_t s = 0; s < rc->zband_nseg[band]; s++) {
        uint32_t base = seg[2 * s] << rc->chunk_shift, end = band * rc->zband_cap + seg[2 * s + 1];
        for (; at < end; at++) {
            uint32_t k = entries[at].key, p = k & mask, slot = base + (k >> bits);
            float z = entries[at].depth;
            if (z < zb[p]) {
                zb[p] = z;
                wb[p] = slot;
                cb[p] = rgba[slot];
            }
        }
    }
    rc->zband_fill[band] = 0;
    rc->zband_nseg[band] = 0;
}

/* band_flush: chunk c's n keys and depths (in L1) appended to their bands' buffers in slot order; a band whose
 * buffer is full is flushed first (its part of this chunk noted as a segment before). Returns the points
 * projected. (A counting pass per chunk before the appends, to flush before the chunk instead, cost more.) */
static uint32_t append_bands(view_rc *rc, uint32_t c, const uint32_t *restrict key, const float *restrict dep,
                             uint32_t n)
{
    uint32_t bands = rc->zband_count, bits = rc->zband_bits, mask = (1u << bits) - 1, cap = rc->zband_cap;
    uint32_t fill[VIEW_RC_MAX_TILES + 1], start[VIEW_RC_MAX_TILES + 1];
    memcpy(fill, rc->zband_fill, bands * sizeof(uint32_t));
    memcpy(start, rc->zband_fill, bands * sizeof(uint32_t));
    fill[bands] = start[bands] = 0; /* the sink (outside, behind, free or dropped): it never moves */
    rc_entry *entries = rc->entries;
    uint32_t projected = 0;
    for (uint32_t i = 0; i < n; i++) {
        uint32_t k = key[i], b = RC_BAND_OF(k);
        if (fill[b] == cap) { /* rare: the band's buffer is full (the sink's fill stays 0) */
            rc->zband_fill[b] = cap;
            note_segment(rc, b, c, start[b], cap);
            flush_band(rc, b);
            fill[b] = start[b] = 0;
        }
        uint32_t o = b * cap + fill[b];
        fill[b] += b < bands;
        projected += b < bands;
        entries[o].key = (k & mask) | i << bits;
        entries[o].depth = dep[i];
    }
    for (uint32_t b = 0; b < bands; b++) {
        rc->zband_fill[b] = fill[b];
        note_segment(rc, b, c, start[b], fill[b]);
    }
    return projected;
}

static void project_task(void *user, uint32_t c, uint32_t worker)
{
    view_rc *rc = user;
    /* The predicted projection first, over the same chunk (before this frame's drops, as a pass of its own
     * was): the projection below then reads the chunk's positions from L2, 64 KiB, not from memory. */
    if (rc->predict)
        predict_task(user, c, worker);
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint32_t n = end - begin;
    uint16_t outside = rc->list_outside, dead = rc->list_dead;
    /* The chunk's keys, depths and lists, indexed from its first slot: in the store's arrays at the chunk
     * (the sort reads them later), or with direct_z (used only here) in their first chunk_size entries,
     * which every chunk reuses while they are in L1 (a frame's 10 bytes a slot not written out to memory). */
    size_t at = rc->direct_z || rc->band_flush ? 0 : begin;
    uint32_t *key = rc->key + at;
    float *dep = rc->dep + at;
    uint16_t *dest = rc->dest + at;
    uint32_t *rgba = rc->rgba + begin;
    /* The tiled z-buffer takes the pixel within the tile; band_z the band and the pixel within it; the 1999
     * one and direct_z, the image's. */
    bool band_z = rc->band_z;
    project_span(&rc->view, rc->px + begin, rc->py + begin, rc->pz + begin, rgba, key, dep, dest, 0, n,
                 rc->tile_shift, rc->tiles_x, !rc->d.no_tiling && !rc->direct_z && !band_z,
                 band_z ? rc->zband_shift : 31, band_z ? rc->zband_bits : 0, outside, dead);
    rc_chunk_stat stat = {0};
    /* The drop plan: points older than drop_age, and the chunk's quota of that age, in slot order. A block of
     * 64 slots without a candidate is skipped after one test; a block whose points of drop_age all fit in
     * what is left of the quota drops without branches (drop_block); only the block where the quota runs out
     * goes slot by slot. */
    if (rc->drop_age != RC_AGE_NO_DROP) {
        uint32_t quota = rc->chunk_quota[c], drop_age = rc->drop_age;
        for (uint32_t b0 = 0; b0 < n; b0 += 64) {
            uint32_t b1 = n - b0 >= 64 ? b0 + 64 : n;
            if (b1 - b0 == 64 && !any_candidate(rgba + b0, drop_age))
                continue;
            uint32_t same = count_age(rgba + b0, b1 - b0, drop_age);
            if (same <= quota) {
                quota -= same;
                drop_block(rgba + b0, key + b0, dest + b0, b1 - b0, drop_age, dead, &stat);
                continue;
            }
            for (uint32_t i = b0; i < b1; i++) {
                uint32_t age = rc_age(rgba[i]);
                if (age == RC_AGE_DEAD || age < drop_age || (age == drop_age && quota == 0))
                    continue;
                if (age == drop_age)
                    quota--;
                stat.dropped++;
                stat.dropped_age_sum += age;
                rgba[i] = (rgba[i] & 0x00FFFFFFu) | (RC_AGE_DEAD << 24);
                key[i] = RC_NO_PIXEL;
                dest[i] = dead;
            }
        }
    }
    stat.migrated = migrate_span(dest, rc->tile_of + begin, 0, n, dead, rc->list_new);
    if (rc->direct_z) {
        stat.projected = zbuffer_span(key, dep, rgba, begin, n, rc->zbuf, rc->win, rc->pre);
        rc->chunk_stat[c] = stat;
        return;
    }
    uint32_t lists = rc->count_stride;
    uint32_t *count = rc->counts + (size_t)c * lists;
    if (rc->band_flush) {
        stat.projected = append_bands(rc, c, key, dep, n);
        rc->chunk_stat[c] = stat;
        return;
    }
    if (band_z) {
        count_bands(key, n, rc->zband_bits, rc->zband_count, count);
        stat.projected = 0;
        for (uint32_t b = 0; b < rc->zband_count; b++)
            stat.projected += count[b];
        rc->chunk_stat[c] = stat;
        return;
    }
    /* Counts per list, in four interleaved sets (consecutive points mostly go to the same tile). */
    memset(count, 0, lists * sizeof(uint32_t));
    uint32_t part[3][VIEW_RC_MAX_TILES + 2];
    for (int k = 0; k < 3; k++)
        memset(part[k], 0, lists * sizeof(uint32_t));
    uint32_t i = 0;
    for (; i + 4 <= n; i += 4) {
        count[dest[i]]++;
        part[0][dest[i + 1]]++;
        part[1][dest[i + 2]]++;
        part[2][dest[i + 3]]++;
    }
    for (; i < n; i++)
        count[dest[i]]++;
    for (uint32_t l = 0; l < lists; l++)
        count[l] += part[0][l] + part[1][l] + part[2][l];
    stat.projected = 0;
    for (uint32_t t = 0; t < rc->tile_count; t++)
        stat.projected += count[t];
    rc->chunk_stat[c] = stat;
}

static void sort_task(void *user, uint32_t c, uint32_t worker)
{
    view_rc *rc = user;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint32_t *offset = rc->counts + (size_t)c * rc->count_stride;
    const uint16_t *dest = rc->dest;
    const uint32_t *key = rc->key;
    const float *dep = rc->dep;
    rc_entry *entries = rc->entries;
    uint32_t tiles = rc->tile_count, bits = rc->pix_bits;
    /* Without a branch (slots are in no order once points come and go): points that land outside, and free
     * slots, go to this thread's sink entry after the lists, whose cursor does not move. (One sink for all
     * threads was a data race, written by every thread: the thread sanitizer saw it.) */
    offset[tiles] = offset[tiles + 1] = rc->entry_sink + RC_ENTRY_LINE * worker;
    for (uint32_t i = begin; i < end; i++) {
        uint32_t d = dest[i], o = offset[d];
        offset[d] = o + (d < tiles);
        entries[o].key = key[i] | (i - begin) << bits; /* the slot within the chunk above the pixel */
        entries[o].depth = dep[i];
    }
}

/* Band lists: the chunk's projected points written to their bands' lists in slot order, each entry the pixel
 * within the band and the slot within the chunk above it; the rest to this thread's sink. */
static void sort_bands_task(void *user, uint32_t c, uint32_t worker)
{
    view_rc *rc = user;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint32_t bands = rc->zband_count, bits = rc->zband_bits, mask = (1u << bits) - 1;
    uint32_t *offset = rc->counts + (size_t)c * rc->count_stride;
    const uint32_t *key = rc->key;
    const float *dep = rc->dep;
    rc_entry *entries = rc->entries;
    offset[bands] = rc->entry_sink + RC_ENTRY_LINE * worker;
    for (uint32_t i = begin; i < end; i++) {
        uint32_t k = key[i], b = RC_BAND_OF(k), o = offset[b];
        offset[b] = o + (b < bands);
        entries[o].key = (k & mask) | (i - begin) << bits;
        entries[o].depth = dep[i];
    }
}
#undef RC_BAND_OF

void view_rc__project_sort(view_rc *rc)
{
    if (rc->band_flush) {
        /* One thread, band lists: every chunk in slot order projected and appended to the bands' buffers,
         * then every band's last flush (a band no point reached is only cleared). */
        memset(rc->zband_fill, 0, rc->zband_count * sizeof(uint32_t));
        memset(rc->zband_nseg, 0, rc->zband_count * sizeof(uint32_t));
        memset(rc->zband_clear, 0, rc->zband_count);
        for (uint32_t c = 0; c < rc->chunk_count; c++)
            project_task(rc, c, 0);
        for (uint32_t b = 0; b < rc->zband_count; b++)
            flush_band(rc, b);
        return;
    }
    if (rc->direct_z) {
        /* One thread: the image's z-buffer cleared, then every chunk in slot order projected into it. */
        for (size_t p = 0; p < rc->pixels; p++) {
            rc->zbuf[p] = INFINITY;
            rc->win[p] = RC_NO_POINT;
            rc->pre[p] = RC_EMPTY_PT;
        }
        for (uint32_t c = 0; c < rc->chunk_count; c++)
            project_task(rc, c, 0);
        return;
    }
    run_chunks(rc, project_task);
    /* Offsets: list by list (tile or band), part by part (each list on a line of its own), chunk by chunk. */
    uint32_t lists = rc->count_stride, run = 0, parts = rc->parts;
    for (uint32_t t = 0; t < rc->list_count; t++)
        for (uint32_t p = 0; p < parts; p++) {
            run = (run + RC_ENTRY_LINE - 1) & ~(RC_ENTRY_LINE - 1);
            rc->list_start[t * parts + p] = run;
            uint32_t c1 = fxc_pool_static_begin(rc->chunk_count, parts, p + 1);
            for (uint32_t c = fxc_pool_static_begin(rc->chunk_count, parts, p); c < c1; c++) {
                uint32_t *slot = rc->counts + (size_t)c * lists + t;
                uint32_t n = *slot;
                *slot = run;
                run += n;
            }
            rc->list_end[t * parts + p] = run;
        }
    run_chunks(rc, rc->band_z ? sort_bands_task : sort_task);
}

/* ---- z-buffer tiles (2002 3.2) ------------------------------------------------------------------------- */

/* The chunk-by-chunk walk of one tile's list, entry by entry: test(p, depth, slot) for each, in list order
 * (part, then chunk, then slot). */
#define RC_FOR_TILE_ENTRIES(rc, tile, bits, test)                                                            \
    do {                                                                                                     \
        const rc_entry *entries_ = (rc)->entries;                                                            \
        uint32_t parts_ = (rc)->parts, lists_ = (rc)->count_stride, bits_ = (bits);                          \
        uint32_t mask_ = (1u << bits_) - 1;                                                                  \
        for (uint32_t part_ = 0; part_ < parts_; part_++) {                                                  \
            uint32_t e_ = (rc)->list_start[(size_t)(tile)*parts_ + part_];                                   \
            uint32_t c1_ = fxc_pool_static_begin((rc)->chunk_count, parts_, part_ + 1);                      \
            for (uint32_t c_ = fxc_pool_static_begin((rc)->chunk_count, parts_, part_); c_ < c1_; c_++) {    \
                uint32_t end_ = (rc)->counts[(size_t)c_ * lists_ + (tile)], base_ = c_ << (rc)->chunk_shift; \
                for (; e_ < end_; e_++) {                                                                    \
                    uint32_t key_ = entries_[e_].key;                                                        \
                    test(key_ &mask_, entries_[e_].depth, base_ + (key_ >> bits_));                          \
                }                                                                                            \
            }                                                                                                \
        }                                                                                                    \
    } while (0)

static void zbuffer_task(void *user, uint32_t tile, uint32_t worker)
{
    view_rc *rc = user;
    size_t w = rc->width;
    uint32_t x0 = (tile % rc->tiles_x) << rc->tile_shift, y0 = (tile / rc->tiles_x) << rc->tile_shift;
    uint32_t x1 = x0 + rc->tile < rc->width ? x0 + rc->tile : rc->width;
    uint32_t y1 = y0 + rc->tile < rc->height ? y0 + rc->tile : rc->height;
    float *zbuf = rc->zbuf;
    uint32_t *win = rc->win, *pre = rc->pre;
    /* Depth and slot of the nearest; between equal depths, the first in the list. Tried and slower in
     * bench_rcache: the same without the branch (2.2 against 1.9 ms), and 64-bit keys of depth and entry (one
     * load, minimum and store a point; entries split in 8 bytes for the test and 8 for the winners: 1.6
     * against 1.2 ms, and the sort 0.3 ms slower). */
    if (rc->local_z) {
        /* In the tile's own buffers (contiguous: 48 KiB for a tile of 64, no set conflicts in L1 or L2),
         * then copied out row by row (vectorised copies). A winner's colour is read from the store when it
         * wins (reading every pixel's winner's colour at the copy-out instead cost 2.5 M instructions a
         * frame at 512 x 512, a gather the compiler does not vectorise). */
        uint32_t side = rc->tile, n = side * side;
        float *restrict zt = rc->workers[worker].zt;
        uint32_t *restrict wt = rc->workers[worker].wt, *restrict ct = rc->workers[worker].ct;
        const uint32_t *rgba = rc->rgba;
        for (uint32_t k = 0; k < n; k++) {
            zt[k] = INFINITY;
            wt[k] = RC_NO_POINT;
            ct[k] = RC_EMPTY_PT;
        }
#define RC_TEST_LOCAL(p, z, slot)                                                                            \
    if ((z) < zt[p]) {                                                                                       \
        zt[p] = (z);                                                                                         \
        wt[p] = (slot);                                                                                      \
        ct[p] = rgba[slot];                                                                                  \
    }
        RC_FOR_TILE_ENTRIES(rc, tile, rc->pix_bits, RC_TEST_LOCAL);
#undef RC_TEST_LOCAL
        for (uint32_t y = y0; y < y1; y++) {
            size_t at = (size_t)(y - y0) * side;
            memcpy(zbuf + y * w + x0, zt + at, (x1 - x0) * sizeof(float));
            memcpy(win + y * w + x0, wt + at, (x1 - x0) * sizeof(uint32_t));
            memcpy(pre + y * w + x0, ct + at, (x1 - x0) * sizeof(uint32_t));
        }
        return;
    }
    for (uint32_t y = y0; y < y1; y++)
        for (uint32_t x = x0; x < x1; x++) {
            zbuf[y * w + x] = INFINITY;
            win[y * w + x] = RC_NO_POINT;
            pre[y * w + x] = RC_EMPTY_PT;
        }
    /* Tiles above RC_LOCAL_TILE: straight into the image (the pixel within the tile turned into the image's).
     */
    uint32_t shift = rc->tile_shift, m = rc->tile - 1;
    size_t origin = (size_t)y0 * w + x0;
#define RC_TEST_IMAGE(p_tile, z, slot)                                                                       \
    {                                                                                                        \
        size_t p = origin + ((p_tile) >> shift) * w + ((p_tile)&m);                                          \
        if ((z) < zbuf[p]) {                                                                                 \
            zbuf[p] = (z);                                                                                   \
            win[p] = (slot);                                                                                 \
            pre[p] = rc->rgba[slot];                                                                         \
        }                                                                                                    \
    }
    RC_FOR_TILE_ENTRIES(rc, tile, rc->pix_bits, RC_TEST_IMAGE);
#undef RC_TEST_IMAGE
}

/* Band lists: one band's rows of the image cleared, then its lists tested straight into them in list order
 * (part, chunk, slot: slot order), the nearer depth winning, between equal depths the first; a winner's
 * colour read from the store when it wins. The band's rows are contiguous, at most 384 KiB of depth, winner
 * and colour: they stay in L2 while the band's entries stream past. */
static void zbuffer_band_task(void *user, uint32_t band, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    size_t first = (size_t)band * rc->zband_rows * rc->width;
    size_t last = (size_t)(band + 1) * rc->zband_rows * rc->width;
    last = last < rc->pixels ? last : rc->pixels;
    float *restrict zb = rc->zbuf + first;
    uint32_t *restrict wb = rc->win + first, *restrict cb = rc->pre + first;
    const uint32_t *rgba = rc->rgba;
    for (size_t p = 0; p < last - first; p++) {
        zb[p] = INFINITY;
        wb[p] = RC_NO_POINT;
        cb[p] = RC_EMPTY_PT;
    }
#define RC_TEST_BAND(p, z, slot)                                                                             \
    if ((z) < zb[p]) {                                                                                       \
        zb[p] = (z);                                                                                         \
        wb[p] = (slot);                                                                                      \
        cb[p] = rgba[slot];                                                                                  \
    }
    RC_FOR_TILE_ENTRIES(rc, band, rc->zband_bits, RC_TEST_BAND);
#undef RC_TEST_BAND
}

void view_rc__zbuffer(view_rc *rc)
{
    if (rc->direct_z || rc->band_flush)
        return; /* done in the projection */
    if (rc->band_z)
        rc_run_pixels(rc->pool, rc->d.dynamic_pixels, rc->zband_count, zbuffer_band_task, rc);
    else
        rc_run_pixels(rc->pool, rc->d.dynamic_pixels, rc->tile_count, zbuffer_task, rc);
}

/* ---- the 1999 render cache: one z-buffer in slot order ------------------------------------------------- */

/* The projection as above (without the sort), then every point straight into the whole image in slot order,
 * one thread: about 2 MiB of depth and winners at 512 x 512, touched at random, which the 2002 paper's tiles
 * avoid. */
void view_rc__project_direct(view_rc *rc)
{
    run_chunks(rc, project_task);
}

void view_rc__zbuffer_direct(view_rc *rc)
{
    float *zbuf = rc->zbuf;
    uint32_t *win = rc->win;
    for (size_t p = 0; p < rc->pixels; p++) {
        zbuf[p] = INFINITY;
        win[p] = RC_NO_POINT;
    }
    const uint32_t *key = rc->key;
    const float *dep = rc->dep;
    for (uint32_t i = 0; i < rc->slots; i++) {
        uint32_t p = key[i];
        if (p != RC_NO_PIXEL && dep[i] < zbuf[p]) {
            zbuf[p] = dep[i];
            win[p] = i;
        }
    }
    for (size_t p = 0; p < rc->pixels; p++)
        rc->pre[p] = win[p] == RC_NO_POINT ? RC_EMPTY_PT : rc->rgba[win[p]];
}

/* ---- ageing and eviction (2002 3.4) -------------------------------------------------------------------- */

/* Every live point ages by the frame's step, faster when no pixel shows it (off screen, behind a nearer
 * point, or removed by the depth cull: the cull marked the points shown); 255 evicts. Returns the points
 * evicted. */
FXC_HOT_CLONES static uint32_t age_span(uint32_t *restrict rgba, uint8_t *restrict mark, uint32_t begin,
                                        uint32_t end, uint32_t step_visible, uint32_t step_hidden,
                                        uint32_t top)
{
    uint32_t evicted = 0;
    for (uint32_t i = begin; i < end; i++) {
        uint32_t v = rgba[i], age = v >> 24;
        uint32_t live = age != RC_AGE_DEAD;
        uint32_t aged = age + (mark[i] ? step_visible : step_hidden);
        aged = aged > top ? top : aged;
        evicted += live & (aged == RC_AGE_DEAD);
        rgba[i] = live ? (v & 0x00FFFFFFu) | (aged << 24) : v;
        mark[i] = 0;
    }
    return evicted;
}

/* The marks of threads 1.. ORed into thread 0's array over [begin, end), and cleared. */
FXC_HOT_CLONES static void gather_marks(uint8_t *restrict mark, uint8_t *restrict other, uint32_t begin,
                                        uint32_t end)
{
    for (uint32_t i = begin; i < end; i++) {
        mark[i] |= other[i];
        other[i] = 0;
    }
}

void view_rc__age_chunk(view_rc *rc, uint32_t c)
{
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint32_t top = rc->d.no_eviction ? 254 : 255;
    for (uint32_t t = 1; t < rc->parts; t++)
        gather_marks(rc->mark, rc->mark + t * rc->mark_stride, begin, end);
    rc->chunk_stat[c].evicted =
        age_span(rc->rgba, rc->mark, begin, end, rc->step_visible, rc->step_hidden, top);
    /* The chunk's age histogram and its free slots, in descending order. Neighbouring slots mostly hold
     * points of one age (inserted in the same frame), so with one histogram every increment waited for the
     * last one's store to the same counter (perf: the increment held 72 % of the pass's samples); four
     * histograms, slot i going to i mod 4, make four independent chains. Free slots (age 255) are counted in
     * bin 255 and listed without a branch. */
    uint32_t *hist = rc->chunk_hist + (size_t)c * 256,
             *free_list = rc->free_list + (size_t)c * rc->chunk_size;
    uint32_t h[4][256];
    memset(h, 0, sizeof h);
    const uint32_t *rgba = rc->rgba;
    uint32_t n = 0, i = end;
    while (i > begin && (i - begin) % 4 != 0) {
        i--;
        h[0][rc_age(rgba[i])]++;
        free_list[n] = i;
        n += rc_age(rgba[i]) == RC_AGE_DEAD;
    }
    for (; i > begin; i -= 4) {
        uint32_t a3 = rc_age(rgba[i - 1]), a2 = rc_age(rgba[i - 2]), a1 = rc_age(rgba[i - 3]),
                 a0 = rc_age(rgba[i - 4]);
        h[3][a3]++;
        h[2][a2]++;
        h[1][a1]++;
        h[0][a0]++;
        free_list[n] = i - 1;
        n += a3 == RC_AGE_DEAD;
        free_list[n] = i - 2;
        n += a2 == RC_AGE_DEAD;
        free_list[n] = i - 3;
        n += a1 == RC_AGE_DEAD;
        free_list[n] = i - 4;
        n += a0 == RC_AGE_DEAD;
    }
    for (uint32_t a = 0; a < 255; a++)
        hist[a] = h[0][a] + h[1][a] + h[2][a] + h[3][a];
    hist[255] = 0;
    rc->chunk_free[c] = n;
}

static void age_task(void *user, uint32_t c, uint32_t worker)
{
    (void)worker;
    view_rc__age_chunk(user, c);
}

void view_rc__age(view_rc *rc)
{
    run_chunks(rc, age_task);
    view_rc__free_stack(rc);
}

void view_rc__free_stack(view_rc *rc)
{
    /* The free stack: chunks from the last to the first, so that the lowest free slot is on top. */
    rc->free_count = 0;
    for (uint32_t c = rc->chunk_count; c-- > 0;) {
        memcpy(rc->free_slots + rc->free_count, rc->free_list + (size_t)c * rc->chunk_size,
               rc->chunk_free[c] * sizeof(uint32_t));
        rc->free_count += rc->chunk_free[c];
    }
}
