/* The point passes of a frame: the drop plan, the predicted projection (2002 3.1), projection and tile sort
 * with migration between tile lists (2002 3.2; Reinhard 2001 section 3), the tiled z-buffer (2002 3.2), the
 * one-pass projection and z-buffer of the 1999 render cache (no_tiling), and ageing with eviction (2002 3.4).
 *
 * Project and tile sort, per chunk of the store (parallel): every record is projected once; the chunk counts
 * how many of its records go to each list (the tile they landed in, the outside list, or dropped). Then one
 * serial step turns the counts into offsets, list by list and chunk by chunk within a list, and the scatter
 * (parallel again) copies each record with its pixel and depth to its offset in the other array. A point that
 * landed in another tile than the list it came from has migrated. The new array is ordered by list, then by the
 * chunk the record came from, then by its place in that chunk: the same whatever the thread count.
 *
 * The z-buffer then reads one tile's list (parallel over tiles) into that tile's part of the image: about
 * 64 x 64 pixels of depth and winner, 32 KiB, resident in cache while the tile's points stream past. The nearer
 * view depth wins; between equal depths, the record placed first (lower index). */
#include "rc_internal.h"

#include <math.h>
#include <string.h>

/* ---- drop plan ----------------------------------------------------------------------------------------- */

void view_rc__plan_drops(view_rc *rc)
{
    uint64_t hist[256] = {0}, live = 0;
    for (uint32_t c = 0; c < rc->chunk_max; c++)
        for (uint32_t a = 0; a < 255; a++) {
            hist[a] += rc->chunk_hist[(size_t)c * 256 + a];
            live += rc->chunk_hist[(size_t)c * 256 + a];
        }
    memset(rc->chunk_quota, 0, rc->chunk_max * sizeof(uint32_t));
    rc->drop_age = RC_AGE_NO_DROP;
    if (live <= rc->d.capacity)
        return;
    /* The oldest first (2002 3.4: ageing is set so that a point reaches 128 before it is overwritten). */
    uint64_t drop = live - rc->d.capacity, above = 0;
    int age = 254;
    while (age > 0 && above + hist[age] < drop)
        above += hist[age--];
    rc->drop_age = (uint32_t)age;
    uint64_t take = drop - above; /* records of exactly that age, the first ones in store order */
    for (uint32_t c = 0; c < rc->chunk_max && take > 0; c++) {
        uint32_t n = rc->chunk_hist[(size_t)c * 256 + (uint32_t)age];
        rc->chunk_quota[c] = n < take ? n : (uint32_t)take;
        take -= rc->chunk_quota[c];
    }
}

/* Whether record age `age` goes in this frame's plan; *quota counts down the chunk's share of drop_age. */
static inline bool dropped(uint32_t age, uint32_t drop_age, uint32_t *quota)
{
    if (age == RC_AGE_EVICTED || age > drop_age)
        return true;
    if (age == drop_age && *quota > 0) {
        (*quota)--;
        return true;
    }
    return false;
}

static void chunk_range(const view_rc *rc, uint32_t c, uint32_t *begin, uint32_t *end)
{
    uint32_t total = rc->placed + rc->pending;
    *begin = c * rc->chunk_size;
    *end = *begin + rc->chunk_size < total ? *begin + rc->chunk_size : total;
    if (*begin > *end)
        *begin = *end;
}

/* ---- predicted projection (2002 3.1) ------------------------------------------------------------------- */

/* No z-buffer and a quarter of the resolution in each direction: only whether any point lands in a pixel. */
static void predict_task(void *user, uint32_t c, uint32_t worker)
{
    view_rc *rc = user;
    const rc_view *v = &rc->predicted;
    const rc_rec *rec = rc->rec[rc->cur];
    uint8_t *occupied = rc->workers[worker].occupied;
    uint32_t begin, end, low_w = rc->low_w;
    chunk_range(rc, c, &begin, &end);
    for (uint32_t i = begin; i < end; i++) {
        if (rc_age(rec[i].rgba) == RC_AGE_EVICTED)
            continue;
        uint32_t x, y;
        float zc;
        if (rc_project(v, rec[i].x, rec[i].y, rec[i].z, &x, &y, &zc))
            occupied[(y >> 2) * low_w + (x >> 2)] = 1;
    }
}

void view_rc__predict_project(view_rc *rc)
{
    size_t low = (size_t)rc->low_w * rc->low_h;
    for (uint32_t t = 0; t < rc->thread_count; t++)
        memset(rc->workers[t].occupied, 0, low);
    view_rc__pool_run(rc->pool, rc->chunks_used, predict_task, rc);
    uint8_t *all = rc->workers[0].occupied;
    for (uint32_t t = 1; t < rc->thread_count; t++) {
        const uint8_t *mine = rc->workers[t].occupied;
        for (size_t p = 0; p < low; p++)
            all[p] |= mine[p];
    }
}

/* ---- project and tile sort ----------------------------------------------------------------------------- */

static void project_task(void *user, uint32_t c, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    const rc_view *v = &rc->view;
    rc_rec *rec = rc->rec[rc->cur];
    rc_prj *prj = rc->prj[rc->cur];
    uint16_t *dest = rc->dest;
    const uint16_t *col_tile = rc->col_tile;
    const uint32_t *row_tile = rc->row_tile;
    uint32_t lists = rc->list_count, outside = lists - 1, drop = lists;
    uint32_t *count = rc->counts + (size_t)c * (lists + 1);
    memset(count, 0, (lists + 1) * sizeof(uint32_t));
    rc_chunk_stat stat = {0};
    uint32_t quota = rc->chunk_quota[c], drop_age = rc->drop_age, width = rc->width;
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);

    /* The list the chunk starts in (the insert list counts as `lists`: its points have not migrated). */
    uint32_t list = 0;
    if (begin >= rc->placed) {
        list = lists;
    } else {
        uint32_t lo = 0, hi = lists - 1; /* the last list whose start is <= begin */
        while (lo < hi) {
            uint32_t mid = (lo + hi + 1) / 2;
            if (rc->list_start[mid] <= begin)
                lo = mid;
            else
                hi = mid - 1;
        }
        list = lo;
    }
    uint32_t i = begin;
    while (i < end) {
        uint32_t list_end = list < lists ? rc->list_start[list + 1] : rc->placed + rc->pending;
        if (list_end > end)
            list_end = end;
        for (; i < list_end; i++) {
            uint32_t age = rc_age(rec[i].rgba);
            if (dropped(age, drop_age, &quota)) {
                if (age != RC_AGE_EVICTED) {
                    stat.dropped++;
                    stat.dropped_age_sum += age;
                }
                dest[i] = (uint16_t)drop;
                count[drop]++;
                continue;
            }
            uint32_t x, y, to = outside, pix = RC_NO_PIXEL;
            float zc;
            if (rc_project(v, rec[i].x, rec[i].y, rec[i].z, &x, &y, &zc)) {
                pix = y * width + x;
                to = row_tile[y] + col_tile[x];
                stat.projected++;
            }
            prj[i].pix = pix;
            prj[i].depth = zc;
            dest[i] = (uint16_t)to;
            count[to]++;
            stat.migrated += list < lists && to != list;
        }
        list++;
    }
    rc->chunk_stat[c] = stat;
}

static void scatter_task(void *user, uint32_t c, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    const rc_rec *from = rc->rec[rc->cur];
    const rc_prj *from_prj = rc->prj[rc->cur];
    rc_rec *to = rc->rec[rc->built];
    rc_prj *to_prj = rc->prj[rc->built];
    const uint16_t *dest = rc->dest;
    uint32_t lists = rc->list_count;
    uint32_t *offset = rc->counts + (size_t)c * (lists + 1);
    uint32_t begin, end;
    chunk_range(rc, c, &begin, &end);
    for (uint32_t i = begin; i < end; i++) {
        uint32_t d = dest[i];
        if (d == lists)
            continue;
        uint32_t o = offset[d]++;
        to[o] = from[i];
        to_prj[o] = from_prj[i];
    }
}

void view_rc__project_sort(view_rc *rc)
{
    rc->built = 1 - rc->cur;
    view_rc__pool_run(rc->pool, rc->chunks_used, project_task, rc);
    /* Offsets: list by list, chunk by chunk. */
    uint32_t lists = rc->list_count, run = 0;
    for (uint32_t l = 0; l < lists; l++) {
        rc->next_start[l] = run;
        for (uint32_t c = 0; c < rc->chunks_used; c++) {
            uint32_t *slot = rc->counts + (size_t)c * (lists + 1) + l;
            uint32_t n = *slot;
            *slot = run;
            run += n;
        }
    }
    rc->next_start[lists] = run;
    rc->built_count = run;
    view_rc__pool_run(rc->pool, rc->chunks_used, scatter_task, rc);
}

/* ---- z-buffer tiles (2002 3.2) --------------------------------------------------------------------------- */

static void zbuffer_task(void *user, uint32_t tile, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    uint32_t x0 = (tile % rc->tiles_x) * rc->tile_w, y0 = (tile / rc->tiles_x) * rc->tile_h;
    uint32_t x1 = x0 + rc->tile_w < rc->width ? x0 + rc->tile_w : rc->width;
    uint32_t y1 = y0 + rc->tile_h < rc->height ? y0 + rc->tile_h : rc->height;
    float *zbuf = rc->zbuf;
    uint32_t *win = rc->win;
    for (uint32_t y = y0; y < y1; y++)
        for (uint32_t x = x0; x < x1; x++) {
            zbuf[(size_t)y * rc->width + x] = INFINITY;
            win[(size_t)y * rc->width + x] = RC_NO_POINT;
        }
    const rc_prj *prj = rc->prj[rc->built];
    for (uint32_t r = rc->next_start[tile], end = rc->next_start[tile + 1]; r < end; r++) {
        uint32_t p = prj[r].pix;
        float z = prj[r].depth;
        if (z < zbuf[p]) {
            zbuf[p] = z;
            win[p] = r;
        }
    }
}

void view_rc__zbuffer(view_rc *rc)
{
    view_rc__pool_run(rc->pool, rc->tile_count, zbuffer_task, rc);
}

/* ---- the 1999 render cache: projection and z-buffer in one pass --------------------------------------- */

/* In cache order, straight into the whole image (about 2 MiB of depth and winners at 512 x 512: the random
 * access the 2002 paper's tiles avoid), one thread; the store is compacted in place. */
void view_rc__project_direct(view_rc *rc)
{
    rc->built = rc->cur;
    const rc_view *v = &rc->view;
    rc_rec *rec = rc->rec[rc->cur];
    rc_prj *prj = rc->prj[rc->cur];
    float *zbuf = rc->zbuf;
    uint32_t *win = rc->win;
    for (size_t p = 0; p < rc->pixels; p++) {
        zbuf[p] = INFINITY;
        win[p] = RC_NO_POINT;
    }
    uint32_t total = rc->placed + rc->pending, write = 0, width = rc->width, drop_age = rc->drop_age;
    for (uint32_t c = 0; c < rc->chunks_used; c++) {
        rc_chunk_stat stat = {0};
        uint32_t quota = rc->chunk_quota[c];
        uint32_t begin = c * rc->chunk_size, end = begin + rc->chunk_size < total ? begin + rc->chunk_size : total;
        for (uint32_t i = begin; i < end; i++) {
            uint32_t age = rc_age(rec[i].rgba);
            if (dropped(age, drop_age, &quota)) {
                if (age != RC_AGE_EVICTED) {
                    stat.dropped++;
                    stat.dropped_age_sum += age;
                }
                continue;
            }
            uint32_t x, y, pix = RC_NO_PIXEL;
            float zc;
            if (rc_project(v, rec[i].x, rec[i].y, rec[i].z, &x, &y, &zc)) {
                pix = y * width + x;
                stat.projected++;
                if (zc < zbuf[pix]) {
                    zbuf[pix] = zc;
                    win[pix] = write;
                }
            }
            rec[write] = rec[i];
            prj[write].pix = pix;
            prj[write].depth = zc;
            write++;
        }
        rc->chunk_stat[c] = stat;
    }
    /* One list holds everything. */
    rc->next_start[0] = 0;
    for (uint32_t l = 1; l <= rc->list_count; l++)
        rc->next_start[l] = write;
    rc->built_count = write;
}

/* ---- ageing and eviction (2002 3.4) -------------------------------------------------------------------- */

/* Every point ages by the frame's step, faster when no pixel shows it (off screen, behind a nearer point, or
 * removed by the depth cull); 255 evicts (the next frame drops it). Recounts the chunk's age histogram. */
static void age_task(void *user, uint32_t c, uint32_t worker)
{
    (void)worker;
    view_rc *rc = user;
    rc_rec *rec = rc->rec[rc->built];
    const rc_prj *prj = rc->prj[rc->built];
    const uint32_t *win = rc->win, *pt = rc->pt;
    uint32_t *hist = rc->chunk_hist + (size_t)c * 256;
    memset(hist, 0, 256 * sizeof(uint32_t));
    uint32_t begin = c * rc->chunk_size;
    uint32_t end = begin + rc->chunk_size < rc->built_count ? begin + rc->chunk_size : rc->built_count;
    uint32_t step_visible = rc->step_visible, step_hidden = rc->step_hidden;
    uint32_t top = rc->d.no_eviction ? 254 : 255, evicted = 0;
    for (uint32_t r = begin; r < end; r++) {
        uint32_t rgba = rec[r].rgba, pix = prj[r].pix;
        bool visible = pix != RC_NO_PIXEL && win[pix] == r && pt[pix] != RC_EMPTY_PT;
        uint32_t age = rc_age(rgba) + (visible ? step_visible : step_hidden);
        if (age >= top) {
            age = top;
            evicted += top == RC_AGE_EVICTED;
        }
        if (age != RC_AGE_EVICTED)
            hist[age]++;
        rec[r].rgba = (rgba & 0x00FFFFFFu) | (age << 24);
    }
    rc->chunk_stat[c].evicted = evicted;
}

void view_rc__age(view_rc *rc)
{
    uint32_t chunks = (rc->built_count + rc->chunk_size - 1) / rc->chunk_size;
    for (uint32_t c = chunks; c < rc->chunk_max; c++) {
        memset(rc->chunk_hist + (size_t)c * 256, 0, 256 * sizeof(uint32_t));
        rc->chunk_stat[c].evicted = 0;
    }
    view_rc__pool_run(rc->pool, chunks, age_task, rc);
}
