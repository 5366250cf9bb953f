/* The point passes of a frame: the drop plan, the predicted projection (2002 3.1), projection and tile sort
 * (2002 3.2; the tile lists of Reinhard 2001 section 3), the tiled z-buffer (2002 3.2), the one-pass z-buffer
 * of the 1999 render cache (no_tiling), and ageing with eviction (2002 3.4).
 *
 * Project and tile sort, per chunk of slots (parallel): every live point is projected once, in a loop without
 * branches (vectorised); the chunk counts how many of its points go to each tile. One serial step turns the
 * counts into offsets, tile by tile and chunk by chunk within a tile, and the bucket sort (parallel again)
 * writes each projected point as a 16-byte entry at its offset: tile after tile, the tiles' point lists. The
 * order within a list (chunk, then slot) does not depend on the thread count.
 *
 * The z-buffer then reads one tile's list (parallel over tiles) into buffers of the tile's own (tiles up to
 * 256 on a side): 64 x 64 pixels of depth, winner and colour, 48 KiB contiguous, which stay in cache while the
 * tile's entries stream past, then copied into the image row by row. (Written straight into the image, the
 * tile's 64 rows lie 4 x width bytes apart and fall into a few of L1's sets: cachegrind counted an L1 miss for
 * nearly every z-buffer write.) The nearer view depth wins; between equal depths, the entry first in the
 * list. */
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

static void chunk_range(const view_rc *rc, uint32_t c, uint32_t *begin, uint32_t *end)
{
    *begin = c * rc->chunk_size;
    *end = *begin + rc->chunk_size < rc->slots ? *begin + rc->chunk_size : rc->slots;
}

/* ---- projection without branches ----------------------------------------------------------------------- */

/* The pixel of every slot in [begin, end) for view v (RC_NO_PIXEL for free slots, points behind the camera or
 * outside the image; `local`: row * tile + column within its tile, else the image's index), its view depth,
 * and its list: the tile (two shifts of the pixel's coordinates), or
 * `outside`, or `dead` for a free slot. rc_project's arithmetic; the conversion to integers happens only on
 * coordinates known to be inside. */
FXC_HOT_CLONES static void project_span(const rc_view *v, const float *restrict px, const float *restrict py,
                                        const float *restrict pz, const uint32_t *restrict rgba,
                                        uint32_t *restrict pix, float *restrict dep, uint16_t *restrict dest,
                                        uint32_t begin, uint32_t end, uint32_t shift, uint32_t tiles_x,
                                        bool local, uint16_t outside, uint16_t dead)
{
    const float cx = v->rel[0], cy = v->rel[1], cz = v->rel[2];
    const float fx = v->forward[0], fy = v->forward[1], fz = v->forward[2];
    const float rx = v->right[0], ry = v->right[1], rz = v->right[2];
    const float ux = v->up[0], uy = v->up[1], uz = v->up[2];
    const float hw = v->half_w, hh = v->half_h, kx = v->kx, ky = v->ky;
    const float w = (float)v->width, h = (float)v->height;
    const uint32_t width = v->width, m = (1u << shift) - 1;
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
        pix[i] = inside ? (local ? in_tile : iy * width + ix) : RC_NO_PIXEL;
        dep[i] = zc;
        dest[i] = (uint16_t)(inside ? tile : live ? outside : dead);
    }
}

/* ---- predicted projection (2002 3.1) ------------------------------------------------------------------- */

/* The quarter-resolution pixel of every slot in [begin, end) for view v (RC_NO_PIXEL when none). */
FXC_HOT_CLONES static void predict_span(const rc_view *v, const float *restrict px, const float *restrict py,
                                        const float *restrict pz, const uint32_t *restrict rgba,
                                        uint32_t *restrict low, uint32_t begin, uint32_t end, uint32_t low_w)
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
        low[i - begin] = inside ? iy * low_w + ix : RC_NO_PIXEL;
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
    predict_span(&rc->predicted, rc->px, rc->py, rc->pz, rc->rgba, low, begin, end, rc->low_w);
    /* Without a branch: points that land nowhere mark the byte after the image. */
    uint32_t sink = rc->low_w * rc->low_h;
    for (uint32_t k = 0; k < end - begin; k++)
        occupied[low[k] == RC_NO_PIXEL ? sink : low[k]] = 1;
}

void view_rc__predict_project(view_rc *rc)
{
    size_t low = (size_t)rc->low_w * rc->low_h;
    for (uint32_t t = 0; t < rc->thread_count; t++)
        memset(rc->workers[t].occupied, 0, low);
    fxc_pool_run(rc->pool, rc->chunk_count, predict_task, rc);
    uint8_t *all = rc->workers[0].occupied;
    for (uint32_t t = 1; t < rc->thread_count; t++) {
        const uint8_t *mine = rc->workers[t].occupied;
        for (size_t p = 0; p < low; p++)
            all[p] |= mine[p];
    }
}

/* ---- the drop plan applied (before the projection) ------------------------------------------------------ */

/* Whether any of 64 points is live and at least drop_age old (vectorised). */
FXC_HOT_CLONES static bool any_candidate(const uint32_t *restrict rgba, uint32_t drop_age)
{
    uint32_t any = 0;
    for (uint32_t k = 0; k < 64; k++) {
        uint32_t age = rgba[k] >> 24;
        any |= (age >= drop_age) & (age != RC_AGE_DEAD);
    }
    return any != 0;
}

/* Points older than drop_age, and the chunk's quota of that age, in slot order. */
static void drop_task(void *user, uint32_t c, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    rc_chunk_stat stat = {0};
    uint32_t quota = rc->chunk_quota[c], drop_age = rc->drop_age;
    for (uint32_t i = begin; i < end; i++) {
        /* Most blocks of 64 hold no candidate (the drops are the oldest few): one test without branches. */
        if ((i & 63) == 0 && i + 64 <= end && !any_candidate(rc->rgba + i, drop_age)) {
            i += 63;
            continue;
        }
        uint32_t age = rc_age(rc->rgba[i]);
        if (age == RC_AGE_DEAD || age < drop_age || (age == drop_age && quota == 0))
            continue;
        if (age == drop_age)
            quota--;
        stat.dropped++;
        stat.dropped_age_sum += age;
        rc->rgba[i] = (rc->rgba[i] & 0x00FFFFFFu) | (RC_AGE_DEAD << 24);
    }
    rc->chunk_stat[c] = stat;
}

void view_rc__drop(view_rc *rc)
{
    if (rc->drop_age == RC_AGE_NO_DROP) {
        memset(rc->chunk_stat, 0, rc->chunk_count * sizeof(rc_chunk_stat));
        return;
    }
    fxc_pool_run(rc->pool, rc->chunk_count, drop_task, rc);
}

/* ---- project and tile sort ----------------------------------------------------------------------------- */

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

static void project_task(void *user, uint32_t c, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint16_t outside = rc->list_outside, dead = rc->list_dead;
    /* The tiled z-buffer in its own buffers takes the pixel within the tile; the 1999 one, the image's. */
    bool local = rc->local_z && !rc->d.no_tiling;
    project_span(&rc->view, rc->px, rc->py, rc->pz, rc->rgba, rc->pix, rc->dep, rc->dest, begin, end,
                 rc->tile_shift, rc->tiles_x, local, outside, dead);
    rc_chunk_stat stat = {0};
    stat.dropped = rc->chunk_stat[c].dropped; /* the drop pass's (view_rc__drop) */
    stat.dropped_age_sum = rc->chunk_stat[c].dropped_age_sum;
    stat.migrated = migrate_span(rc->dest, rc->tile_of, begin, end, dead, rc->list_new);
    /* Counts per list, in four interleaved sets (consecutive points mostly go to the same tile). */
    uint32_t lists = rc->tile_count + 2;
    uint32_t *count = rc->counts + (size_t)c * lists;
    memset(count, 0, lists * sizeof(uint32_t));
    uint32_t part[3][VIEW_RC_MAX_TILES + 2];
    for (int k = 0; k < 3; k++)
        memset(part[k], 0, lists * sizeof(uint32_t));
    const uint16_t *dest = rc->dest;
    uint32_t i = begin;
    for (; i + 4 <= end; i += 4) {
        count[dest[i]]++;
        part[0][dest[i + 1]]++;
        part[1][dest[i + 2]]++;
        part[2][dest[i + 3]]++;
    }
    for (; i < end; i++)
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
    (void)worker;
    view_rc *rc = user;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint32_t *offset = rc->counts + (size_t)c * (rc->tile_count + 2);
    const uint16_t *dest = rc->dest;
    const uint32_t *pix = rc->pix, *rgba = rc->rgba;
    const float *dep = rc->dep;
    rc_entry *entries = rc->entries;
    uint32_t tiles = rc->tile_count;
    /* Without a branch (slots are in no order once points come and go): points that land outside, and free
     * slots, go to the entry after the last, whose cursor does not move. */
    offset[tiles] = offset[tiles + 1] = rc->slots;
    for (uint32_t i = begin; i < end; i++) {
        uint32_t d = dest[i], o = offset[d];
        offset[d] = o + (d < tiles);
        rc_entry *e = &entries[o];
        e->pix = pix[i];
        e->depth = dep[i];
        e->rgba = rgba[i];
        e->slot = i;
    }
}

void view_rc__project_sort(view_rc *rc)
{
    fxc_pool_run(rc->pool, rc->chunk_count, project_task, rc);
    /* Offsets: tile by tile, chunk by chunk. */
    uint32_t lists = rc->tile_count + 2, run = 0;
    for (uint32_t t = 0; t < rc->tile_count; t++) {
        rc->tile_start[t] = run;
        for (uint32_t c = 0; c < rc->chunk_count; c++) {
            uint32_t *slot = rc->counts + (size_t)c * lists + t;
            uint32_t n = *slot;
            *slot = run;
            run += n;
        }
    }
    rc->tile_start[rc->tile_count] = run;
    fxc_pool_run(rc->pool, rc->chunk_count, sort_task, rc);
}

/* ---- z-buffer tiles (2002 3.2) ------------------------------------------------------------------------- */

static void zbuffer_task(void *user, uint32_t tile, uint32_t worker)
{
    view_rc *rc = user;
    size_t w = rc->width;
    uint32_t x0 = (tile % rc->tiles_x) << rc->tile_shift, y0 = (tile / rc->tiles_x) << rc->tile_shift;
    uint32_t x1 = x0 + rc->tile < rc->width ? x0 + rc->tile : rc->width;
    uint32_t y1 = y0 + rc->tile < rc->height ? y0 + rc->tile : rc->height;
    float *zbuf = rc->zbuf;
    uint32_t *win = rc->win, *pre = rc->pre;
    const rc_entry *entries = rc->entries;
    uint32_t first = rc->tile_start[tile], last = rc->tile_start[tile + 1];
    /* Depth and entry of the nearest; between equal depths, the first in the list. Tried and slower in
     * bench_rcache: the same without the branch (2.2 against 1.9 ms), and 64-bit keys of depth and entry (one
     * load, minimum and store a point; entries split in 8 bytes for the test and 8 for the winners: 1.6
     * against 1.2 ms, and the sort 0.3 ms slower). */
    if (rc->local_z) {
        /* In the tile's own buffers (contiguous: 48 KiB for a tile of 64, no set conflicts in L1 or L2),
         * then copied out row by row (vectorised copies). */
        uint32_t side = rc->tile, n = side * side;
        float *restrict zt = rc->workers[worker].zt;
        uint32_t *restrict wt = rc->workers[worker].wt, *restrict ct = rc->workers[worker].ct;
        for (uint32_t k = 0; k < n; k++) {
            zt[k] = INFINITY;
            wt[k] = RC_NO_POINT;
            ct[k] = RC_EMPTY_PT;
        }
        for (uint32_t e = first; e < last; e++) {
            uint32_t p = entries[e].pix;
            float z = entries[e].depth;
            if (z < zt[p]) {
                zt[p] = z;
                wt[p] = entries[e].slot;
                ct[p] = entries[e].rgba;
            }
        }
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
    for (uint32_t e = first; e < last; e++) {
        uint32_t p = entries[e].pix;
        float z = entries[e].depth, old = zbuf[p];
        if (z < old) {
            zbuf[p] = z;
            win[p] = entries[e].slot;
            pre[p] = entries[e].rgba;
        }
    }
}

void view_rc__zbuffer(view_rc *rc)
{
    fxc_pool_run(rc->pool, rc->tile_count, zbuffer_task, rc);
}

/* ---- the 1999 render cache: one z-buffer in slot order ------------------------------------------------- */

/* The projection as above (without the sort), then every point straight into the whole image in slot order,
 * one thread: about 2 MiB of depth and winners at 512 x 512, touched at random, which the 2002 paper's tiles
 * avoid. */
void view_rc__project_direct(view_rc *rc)
{
    fxc_pool_run(rc->pool, rc->chunk_count, project_task, rc);
}

void view_rc__zbuffer_direct(view_rc *rc)
{
    float *zbuf = rc->zbuf;
    uint32_t *win = rc->win;
    for (size_t p = 0; p < rc->pixels; p++) {
        zbuf[p] = INFINITY;
        win[p] = RC_NO_POINT;
    }
    const uint32_t *pix = rc->pix;
    const float *dep = rc->dep;
    for (uint32_t i = 0; i < rc->slots; i++) {
        uint32_t p = pix[i];
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

static void age_task(void *user, uint32_t c, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint32_t top = rc->d.no_eviction ? 254 : 255;
    rc->chunk_stat[c].evicted =
        age_span(rc->rgba, rc->mark, begin, end, rc->step_visible, rc->step_hidden, top);
    /* The chunk's age histogram and its free slots, in descending order. */
    uint32_t *hist = rc->chunk_hist + (size_t)c * 256,
             *free_list = rc->free_list + (size_t)c * rc->chunk_size;
    memset(hist, 0, 256 * sizeof(uint32_t));
    uint32_t n = 0;
    for (uint32_t i = end; i-- > begin;) {
        uint32_t age = rc_age(rc->rgba[i]);
        if (age == RC_AGE_DEAD)
            free_list[n++] = i;
        else
            hist[age]++;
    }
    rc->chunk_free[c] = n;
}

void view_rc__age(view_rc *rc)
{
    fxc_pool_run(rc->pool, rc->chunk_count, age_task, rc);
    /* The free stack: chunks from the last to the first, so that the lowest free slot is on top. */
    rc->free_count = 0;
    for (uint32_t c = rc->chunk_count; c-- > 0;) {
        memcpy(rc->free_slots + rc->free_count, rc->free_list + (size_t)c * rc->chunk_size,
               rc->chunk_free[c] * sizeof(uint32_t));
        rc->free_count += rc->chunk_free[c];
    }
}

/* ---- the fused path: each tile projects its own points into its z-buffer (Reinhard 2001) ---------------- */

/* Task k's slots: tile k's home range, or (k >= tile_count) a chunk of the rest. */
static void task_range(const view_rc *rc, uint32_t k, uint32_t *begin, uint32_t *end)
{
    uint32_t tiles = rc->tile_count;
    if (k < tiles) {
        *begin = rc->home_start[k];
        *end = rc->home_start[k + 1];
        return;
    }
    uint32_t rest = rc->home_start[tiles];
    *begin = rest + (k - tiles) * rc->chunk_size;
    *end = *begin + rc->chunk_size < rc->slots ? *begin + rc->chunk_size : rc->slots;
}

/* Tile k (or a chunk of the rest): its slots projected a block at a time (project_span, vectorised), the
 * points that land in the tile depth-tested at once into the worker's tile buffers while the block is in L1,
 * the others counted per destination list (their dest stays; the home points' dest becomes list_outside, so
 * that the hand-over below skips them), and the buffers copied into the image. Home points come in slot
 * order and win ties by the strict test, the same rule as the sorted lists: nearest, then lowest slot. */
static void fused_task(void *user, uint32_t k, uint32_t worker)
{
    view_rc *rc = user;
    uint32_t begin, end;
    task_range(rc, k, &begin, &end);
    uint32_t tiles = rc->tile_count, lists = tiles + 2;
    uint16_t outside = rc->list_outside, dead = rc->list_dead;
    uint32_t *count = rc->task_counts + (size_t)k * lists;
    memset(count, 0, lists * sizeof(uint32_t));
    rc_chunk_stat stat = {0};
    uint32_t own = k < tiles ? k : UINT32_MAX, side = rc->tile, n = side * side, home = 0, away = 0;
    uint32_t *restrict away_slot = rc->free_list + begin; /* the migrants' slots, for the hand-over */
    (void)worker;
    size_t at = own != UINT32_MAX ? (size_t)own * n : 0;
    float *restrict zt = rc->ztile + at;
    uint32_t *restrict wt = rc->wtile + at, *restrict ct = rc->ctile + at;
    if (own != UINT32_MAX)
        for (uint32_t q = 0; q < n; q++) {
            zt[q] = INFINITY;
            wt[q] = RC_NO_POINT;
            ct[q] = RC_EMPTY_PT;
        }
    uint32_t *restrict pix = rc->pix;
    float *restrict dep = rc->dep;
    uint16_t *restrict dest = rc->dest;
    const uint32_t *restrict rgba = rc->rgba;
    for (uint32_t b0 = begin; b0 < end; b0 += RC_BLOCK) {
        uint32_t b1 = end - b0 > RC_BLOCK ? b0 + RC_BLOCK : end;
        project_span(&rc->view, rc->px, rc->py, rc->pz, rc->rgba, pix, dep, dest, b0, b1, rc->tile_shift,
                     rc->tiles_x, true, outside, dead);
        stat.migrated += migrate_span(dest, rc->tile_of, b0, b1, dead, rc->list_new);
        for (uint32_t i = b0; i < b1; i++) {
            uint32_t d = dest[i];
            if (d == own) {
                uint32_t p = pix[i];
                float z = dep[i];
                if (z < zt[p]) {
                    zt[p] = z;
                    wt[p] = i;
                    ct[p] = rgba[i];
                }
                dest[i] = outside;
                home++;
            } else {
                count[d]++;
                away_slot[away] = i; /* kept only when it landed in a tile */
                away += d < tiles;
            }
        }
    }
    stat.projected = home + away;
    stat.away = away;
    rc->task_stat[k] = stat;
}

/* The migrants of task k (their slots listed by fused_task in free_list, which only the ageing uses) written
 * as entries into their new tiles' lists: the sort of the sorted path, for these points only. */
static void handover_task(void *user, uint32_t k, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    uint32_t away = rc->task_stat[k].away;
    if (away == 0)
        return;
    uint32_t begin, end;
    task_range(rc, k, &begin, &end);
    uint32_t *offset = rc->task_counts + (size_t)k * (rc->tile_count + 2);
    const uint32_t *away_slot = rc->free_list + begin;
    const uint16_t *dest = rc->dest;
    const uint32_t *pix = rc->pix, *rgba = rc->rgba;
    const float *dep = rc->dep;
    rc_entry *entries = rc->entries;
    for (uint32_t j = 0; j < away; j++) {
        uint32_t i = away_slot[j];
        rc_entry *e = &entries[offset[dest[i]]++];
        e->pix = pix[i];
        e->depth = dep[i];
        e->rgba = rgba[i];
        e->slot = i;
    }
}

void view_rc__project_fused(view_rc *rc)
{
    uint32_t tiles = rc->tile_count, rest = rc->slots - rc->home_start[tiles];
    rc->task_count = tiles + (rest + rc->chunk_size - 1) / rc->chunk_size;
    fxc_pool_run(rc->pool, rc->task_count, fused_task, rc);
    /* Offsets of the migrants: tile by tile, task by task within a tile. */
    uint32_t lists = tiles + 2, run = 0;
    for (uint32_t t = 0; t < tiles; t++) {
        rc->tile_start[t] = run;
        for (uint32_t k = 0; k < rc->task_count; k++) {
            uint32_t *slot = rc->task_counts + (size_t)k * lists + t;
            uint32_t n = *slot;
            *slot = run;
            run += n;
        }
    }
    rc->tile_start[tiles] = run;
    rc->frame_migrants = run;
    fxc_pool_run(rc->pool, rc->task_count, handover_task, rc);
    /* The frame's figures: the drop pass's per chunk, the projection's on chunk 0 (added up in order). */
    for (uint32_t k = 0; k < rc->task_count; k++) {
        rc->chunk_stat[0].projected += rc->task_stat[k].projected;
        rc->chunk_stat[0].migrated += rc->task_stat[k].migrated;
    }
}

/* Tile t's migrants into the tile's buffers (contiguous, like the home pass's): the nearest wins, between
 * equal depths the lowest slot, as in the home pass; then the tile copied into the image row by row. */
static void migrant_task(void *user, uint32_t tile, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    uint32_t side = rc->tile;
    size_t n = (size_t)side * side;
    float *restrict zt = rc->ztile + tile * n;
    uint32_t *restrict wt = rc->wtile + tile * n, *restrict ct = rc->ctile + tile * n;
    const rc_entry *entries = rc->entries;
    for (uint32_t e = rc->tile_start[tile], last = rc->tile_start[tile + 1]; e < last; e++) {
        uint32_t p = entries[e].pix;
        float z = entries[e].depth, old = zt[p];
        uint32_t slot = entries[e].slot;
        if (z < old || (z == old && slot < wt[p])) {
            zt[p] = z;
            wt[p] = slot;
            ct[p] = entries[e].rgba;
        }
    }
    size_t w = rc->width;
    uint32_t x0 = (tile % rc->tiles_x) << rc->tile_shift, y0 = (tile / rc->tiles_x) << rc->tile_shift;
    uint32_t x1 = x0 + side < rc->width ? x0 + side : rc->width;
    uint32_t y1 = y0 + side < rc->height ? y0 + side : rc->height;
    for (uint32_t y = y0; y < y1; y++) {
        size_t at = (size_t)(y - y0) * side;
        memcpy(rc->zbuf + y * w + x0, zt + at, (x1 - x0) * sizeof(float));
        memcpy(rc->win + y * w + x0, wt + at, (x1 - x0) * sizeof(uint32_t));
        memcpy(rc->pre + y * w + x0, ct + at, (x1 - x0) * sizeof(uint32_t));
    }
}

void view_rc__zbuffer_migrants(view_rc *rc)
{
    fxc_pool_run(rc->pool, rc->tile_count, migrant_task, rc);
}

/* ---- the fused path's re-sort ------------------------------------------------------------------------- */

bool view_rc__resort_due(const view_rc *rc)
{
    uint32_t projected = 0;
    for (uint32_t k = 0; k < rc->task_count; k++)
        projected += rc->task_stat[k].projected;
    return (float)rc->frame_migrants > RC_RESORT_FRACTION * (float)projected;
}

/* Per chunk of slots: how many go to each list (this frame's tile, outside, free), from tile_of (which the
 * projection set to this frame's list for every slot). */
static void resort_count_task(void *user, uint32_t c, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint32_t lists = rc->tile_count + 2;
    uint32_t *count = rc->counts + (size_t)c * lists;
    memset(count, 0, lists * sizeof(uint32_t));
    for (uint32_t i = begin; i < end; i++)
        count[rc->tile_of[i]]++;
}

/* Per chunk: every slot copied to its place in the second store (stable: chunk, then slot order), and its new
 * number in pix (for the winners). */
static void resort_move_task(void *user, uint32_t c, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    uint32_t *offset = rc->counts + (size_t)c * (rc->tile_count + 2);
    for (uint32_t i = begin; i < end; i++) {
        uint32_t d = rc->tile_of[i], o = offset[d]++;
        rc->px2[o] = rc->px[i];
        rc->py2[o] = rc->py[i];
        rc->pz2[o] = rc->pz[i];
        rc->rgba2[o] = rc->rgba[i];
        rc->tile_of2[o] = (uint16_t)d;
        rc->mark2[o] = rc->mark[i];
        rc->pix[i] = o;
    }
}

/* Per band of rows: the winners renamed (the inserts until the next frame find points through them). */
static void resort_winners_task(void *user, uint32_t band, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    size_t y0 = (size_t)band << rc->tile_shift, y1 = y0 + rc->tile < rc->height ? y0 + rc->tile : rc->height;
    const uint32_t *renamed = rc->pix;
    for (size_t p = y0 * rc->width; p < y1 * rc->width; p++) {
        uint32_t s = rc->win[p];
        rc->win[p] = s == RC_NO_POINT ? s : renamed[s];
    }
}

#define RC_SWAP(type, a, b)                                                                                  \
    do {                                                                                                     \
        type swap_ = (a);                                                                                    \
        (a) = (b);                                                                                           \
        (b) = swap_;                                                                                         \
    } while (0)

void view_rc__resort(view_rc *rc)
{
    fxc_pool_run(rc->pool, rc->chunk_count, resort_count_task, rc);
    /* Offsets: list by list (tiles, then outside, then the free slots), chunk by chunk. */
    uint32_t lists = rc->tile_count + 2, run = 0;
    for (uint32_t l = 0; l < lists; l++) {
        if (l <= rc->tile_count)
            rc->home_start[l] = run;
        for (uint32_t c = 0; c < rc->chunk_count; c++) {
            uint32_t *slot = rc->counts + (size_t)c * lists + l;
            uint32_t n = *slot;
            *slot = run;
            run += n;
        }
    }
    fxc_pool_run(rc->pool, rc->chunk_count, resort_move_task, rc);
    fxc_pool_run(rc->pool, rc->tiles_y, resort_winners_task, rc);
    RC_SWAP(float *, rc->px, rc->px2);
    RC_SWAP(float *, rc->py, rc->py2);
    RC_SWAP(float *, rc->pz, rc->pz2);
    RC_SWAP(uint32_t *, rc->rgba, rc->rgba2);
    RC_SWAP(uint16_t *, rc->tile_of, rc->tile_of2);
    RC_SWAP(uint8_t *, rc->mark, rc->mark2);
}
