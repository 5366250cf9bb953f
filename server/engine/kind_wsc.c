/* The world-space cache (cache/wsc.h) behind the cache-kind interface: the 8 grid points around each visible
 * point at the level its distance from the camera chooses, bricks per effect, the taps compose and the
 * effects' own reads (fx_context.world_taps) use, and the cache's figures and memory. Everything in the
 * engine that knows the world grid is here.
 *
 * The grid is fixed for the run and anchored at the scene's local frame: positions go to the grid as they
 * are, scene-local (in double). The frame's origin is a whole multiple of a power of two at least the scene's
 * extent (scene.h), and the default finest cell is a power of two below the extent, so these are the cells a
 * grid anchored at the world origin would have; but the grid's range (2^20 cells on each horizontal axis,
 * 2^17 vertically, wsc.h) is measured from the scene, so a scene 1e6 m from the world origin keeps its probes
 * and renders like the same scene at the origin, keys and all (DESIGN.md, numerical robustness; anchored at
 * the world origin, such a scene lay outside the range of every cell of 0.25 to 0.5 m and had no probes at
 * all: tests/stability/stab_scale.c). Points outside the grid's range are refused and counted, never
 * wrapped.
 *
 * Local lookup tables (paper section 3.2.2): compose reads the 8 probes of every pixel, and neighbouring
 * pixels read the same ones, so each viewer has local tables around its camera that answer most reads
 * without hashing; one per viewer and pool thread (a local table belongs to one thread at a time), created
 * at the viewer's first frame and dropped when it leaves. They always agree with the table (wsc.h). */
#include "engine_internal.h"
#include "fxc_hot.h"

#include "wsc.h"

#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Slots per axis and levels of a viewer's local tables: compose reads them only when a pixel enters another
 * cell, so 8^3 slots a level (6 KB) are enough: 97 % of reads hit on Sponza with 4 viewers (16^3: 99.9 %) at
 * an eighth of the memory (docs/BENCHMARKS.md). */
enum { LOCAL_SIDE = 8, LOCAL_LEVELS = 8 };

/* Cells compose looked up this frame, per pool thread, direct-mapped (cell_cache_entry). */
enum { CELL_CACHE = 256 };

/* The cells of one cell's 8 corners that hold data, found once per cell: payload and corner index. */
typedef struct cell_taps {
    uint32_t count;
    const void *texel[8];
    uint8_t corner[8];
    uint32_t first_block; /* the brick of the first corner found, or SRV_NONE */
} cell_taps;

/* A cell compose looked up this frame: within compose the table, the bricks' valid bits and the payloads do
 * not change (every update and commit of the frame ran before it, housekeeping runs after), so the corners
 * found for a cell stay right for the whole stage, for every viewer. Pixels enter a new cell about every 9
 * pixels on Sponza, mostly one they or the run before met: the lookup of 8 corners (brick keys, hashing,
 * valid bits) is then done once per cell and thread instead of once per run. */
typedef struct cell_cache_entry {
    uint64_t cell; /* wsc_wgi_pack of (level, grid point) */
    uint32_t stamp, effect;
    cell_taps taps;
} cell_cache_entry;

typedef struct kind_wsc {
    wsc_cache *wsc;
    const scene *s;
    double c0; /* finest cell, metres */
    double cell_size[WSC_MAX_LEVEL + 1],
        inv_cell_size[WSC_MAX_LEVEL + 1]; /* wsc_cell_size per level, 1 / it */
    uint32_t brick_size[SRV_MAX_EFFECTS];
    uint32_t cell_bytes[SRV_MAX_EFFECTS];
    uint32_t threads;
    bool use_local;
    wsc_local **local;              /* [SRV_MAX_VIEWERS * threads], NULL until first used */
    _Atomic uint64_t refused;       /* this frame, from the request threads */
    _Atomic uint64_t local_lookups; /* this frame, compose */
    _Atomic uint64_t local_hits;
    cell_cache_entry *cell_cache; /* [threads * CELL_CACHE]: compose's cells of this frame, per thread */
    uint32_t stamp;               /* the frame's stamp in cell_cache (bumped at begin_frame; 0: none yet) */
} kind_wsc;

/* The default finest cell: the power of two nearest a 64th of the bounding-box diagonal (a grid that does
 * not move when the scene does); 1/64 m only for a scene without extent. No floor in metres: with one (it was
 * 1/64 m) a scene smaller than a metre, such as the embedded scene at 1e-4, had its whole room in one or a few
 * probe cells, and its indirect light came out flat and too bright instead of the same image at every scale. */
static double default_cell(const scene *s)
{
    double d2 = 0;
    for (int k = 0; k < 3; k++) {
        double e = (double)s->bounds_max[k] - (double)s->bounds_min[k];
        d2 += e > 0 ? e * e : 0;
    }
    double target = sqrt(d2) / 64.0;
    if (!(target > 0) || !isfinite(target))
        return 1.0 / 64.0;
    return ldexp(1.0, (int)lround(log2(target)));
}

double srv_probe_cell_default(const scene *s)
{
    return default_cell(s);
}

static fxc_result wsc_kind_create(srv_loop *loop, void **out, char *err, size_t err_cap)
{
    *out = NULL;
    wsc_desc wd = {0};
    bool any = false;
    uint32_t brick_size[SRV_MAX_EFFECTS] = {0}, cell_bytes[SRV_MAX_EFFECTS] = {0}, world_effects = 0;
    for (uint32_t e = 0; e < loop->effect_count; e++)
        world_effects += loop->effect_cached[e] && loop->effect_kind[e] == SCENE_CACHE_WORLD_SPACE;
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        if (!loop->effect_cached[e] || loop->effect_kind[e] != SCENE_CACHE_WORLD_SPACE)
            continue;
        const fx_effect *fx = loop->effects[e];
        brick_size[e] = fx->brick_size ? fx->brick_size : 1;
        cell_bytes[e] = fx->texel_bytes(loop->s);
        uint64_t brick_bytes = (uint64_t)cell_bytes[e] * brick_size[e] * brick_size[e] * brick_size[e];
        /* A quarter of the pool budget for the world-space effects, shared equally (the on-surface pools have
         * the rest), within 64..65536 bricks each. */
        uint64_t bricks = loop->desc.pool_bytes / 4 / world_effects / (brick_bytes ? brick_bytes : 1);
        bricks = bricks < 64 ? 64 : (bricks > 65536 ? 65536 : bricks);
        wd.effects[e] = (wsc_effect_desc){.cell_bytes = cell_bytes[e],
                                          .brick_size = brick_size[e],
                                          .max_bricks = (uint32_t)bricks,
                                          .convergence = true};
        any = true;
    }
    if (!any)
        return FXC_OK; /* no world-space effect runs: nothing is allocated */
    kind_wsc *k = calloc(1, sizeof *k);
    uint32_t threads = srv_pool_threads(loop->pool);
    wsc_local **local = calloc((size_t)SRV_MAX_VIEWERS * threads, sizeof *local);
    cell_cache_entry *cell_cache = calloc((size_t)threads * CELL_CACHE, sizeof *cell_cache);
    if (!k || !local || !cell_cache) {
        free(k);
        free(local);
        free(cell_cache);
        snprintf(err, err_cap, "frame loop: out of memory for the world-space cache");
        return FXC_ERR_NOMEM;
    }
    k->s = loop->s;
    k->c0 = loop->desc.probe_cell > 0 ? (double)loop->desc.probe_cell : default_cell(loop->s);
    for (uint32_t level = 0; level <= WSC_MAX_LEVEL; level++) {
        k->cell_size[level] = wsc_cell_size(level, k->c0);
        k->inv_cell_size[level] = 1.0 / k->cell_size[level];
    }
    memcpy(k->brick_size, brick_size, sizeof brick_size);
    memcpy(k->cell_bytes, cell_bytes, sizeof cell_bytes);
    k->threads = threads;
    k->local = local;
    k->cell_cache = cell_cache;
    k->use_local = !loop->desc.no_local_table;
    char msg[256];
    osc_result r = wsc_create(&wd, &k->wsc, msg, sizeof msg);
    if (r != OSC_OK) {
        snprintf(err, err_cap, "frame loop: cannot create the world-space cache: %s", msg);
        free(cell_cache);
        free(local);
        free(k);
        return (fxc_result)r;
    }
    loop->desc.probe_cell = (float)k->c0; /* what the run used, for its summary */
    *out = k;
    return FXC_OK;
}

static void drop_locals(kind_wsc *k, uint32_t slot)
{
    for (uint32_t t = 0; t < k->threads; t++) {
        wsc_local **l = &k->local[(size_t)slot * k->threads + t];
        if (*l) {
            wsc_local_destroy(*l);
            *l = NULL;
        }
    }
}

static void wsc_kind_destroy(void *cache)
{
    kind_wsc *k = cache;
    if (!k)
        return;
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        drop_locals(k, v);
    wsc_destroy(k->wsc);
    free(k->cell_cache);
    free(k->local);
    free(k);
}

static void wsc_kind_viewer_removed(void *cache, uint32_t slot)
{
    drop_locals(cache, slot);
}

static void wsc_kind_begin_frame(void *cache, uint32_t frame)
{
    kind_wsc *k = cache;
    wsc_begin_frame(k->wsc, frame);
    k->stamp = k->stamp == UINT32_MAX ? 1 : k->stamp + 1; /* forgets compose's cells of the last frame */
    atomic_store_explicit(&k->refused, 0, memory_order_relaxed);
    atomic_store_explicit(&k->local_lookups, 0, memory_order_relaxed);
    atomic_store_explicit(&k->local_hits, 0, memory_order_relaxed);
}

/* The cell of the last pixel: neighbouring pixels lie in the same cell far more often than not, and a point
 * well inside the last cell's box (by a millionth of a cell, so rounding can never put it in another) is in
 * it without the divisions and floors of wsc_corners. Decisions near a face go through wsc_corners, so the
 * cell of a point never depends on which pixel came before it. The boxes are kept in float too, rounded
 * inwards: a pixel's position and distance are floats, so a float inside the float box is inside the double
 * one, and the test per pixel is six float comparisons (the answer is the same as in double). */
typedef struct cell_memo {
    uint32_t level;                   /* UINT32_MAX: none */
    int32_t g[3];                     /* the cell's grid point */
    float inside_lo[3], inside_hi[3]; /* the cell's box a millionth inside, rounded inwards to float */
    double lo[3];                     /* the cell's lower corner */
    double inv_cell;
    /* The last distance's level (before the bias), the distances well inside its range (rounded inwards
     * to float), and the inverse of the range's upper end (for the blend). */
    uint32_t distance_level;
    float distance_lo, distance_hi;
    double inv_top;
} cell_memo;

/* The float nearest x from above (below): (double)float_above(x) >= x. One step of the float's bits towards
 * x when the conversion rounded the other way (not for infinities or NaN: they convert exactly). */
static float float_step(float f, bool up)
{
    uint32_t bits;
    memcpy(&bits, &f, sizeof bits);
    if (f == 0.0f)
        bits = up ? 1u : 0x80000001u; /* the smallest subnormal of the right sign */
    else
        bits = (f > 0.0f) == up ? bits + 1 : bits - 1;
    memcpy(&f, &bits, sizeof f);
    return f;
}

static float float_above(double x)
{
    float f = (float)x;
    return (double)f < x ? float_step(f, true) : f;
}

static float float_below(double x)
{
    float f = (float)x;
    return (double)f > x ? float_step(f, false) : f;
}

/* wsc_level of a distance, remembering the range of distances of the last level (a millionth inside its
 * bounds, so the answer is always wsc_level's). */
static inline uint32_t memo_level(const kind_wsc *k, cell_memo *m, float distance)
{
    if (distance > m->distance_lo && distance < m->distance_hi)
        return m->distance_level;
    uint32_t level = wsc_level((double)distance, k->c0);
    double step = 16.0 * k->c0;
    double lo = level == 0 ? -INFINITY : ldexp(step, (int)level - 1),
           hi = level == WSC_MAX_LEVEL ? INFINITY : ldexp(step, (int)level);
    m->distance_level = level;
    m->distance_lo = level == 0 ? -INFINITY : float_above(lo * (1.0 + 1e-6));
    m->distance_hi = float_below(hi * (1.0 - 1e-6));
    m->inv_top = level == WSC_MAX_LEVEL ? 0.0 : 1.0 / hi;
    if (!(distance == distance)) /* NaN: no range */
        m->distance_lo = m->distance_hi = 0;
    return level;
}

/* Levels blend into each other: over the last quarter of a level's distances (3/4 to 1 of its upper end)
 * the next level's cells fade in, so no seam shows where the level changes; at the boundary a pixel reads
 * the next level alone, as the pixel just beyond it does. A pixel's level (bias included) and the weight
 * of level + 1 in [0, 1]. The sum is taken in 64 bits (a bias of INT32_MAX overflowed it), and a bias that
 * puts the next level below 0 too leaves nothing to blend (both clamp to level 0; it used to blend level 1
 * in: found by tests/stability/stab_caches.c). */
static inline uint32_t pixel_level(const kind_wsc *k, cell_memo *m, const srv_pixel *px, int32_t bias,
                                   float *blend)
{
    double distance = (double)px->distance;
    int64_t l = (int64_t)memo_level(k, m, px->distance) + bias;
    uint32_t level = l < 0 ? 0 : (l > (int64_t)WSC_MAX_LEVEL ? WSC_MAX_LEVEL : (uint32_t)l);
    double b = (distance * m->inv_top - 0.75) * 4.0;
    *blend = level >= WSC_MAX_LEVEL || l + 1 <= 0 || !(b > 0.0) ? 0.0f : (b >= 1.0 ? 1.0f : (float)b);
    return level;
}

/* Whether a point (scene-local, float) lies well inside the memo's cell at `level`. */
static inline bool cell_same(const cell_memo *m, uint32_t level, const float p[3])
{
    return m->level == level && p[0] >= m->inside_lo[0] && p[0] < m->inside_hi[0] &&
           p[1] >= m->inside_lo[1] && p[1] < m->inside_hi[1] && p[2] >= m->inside_lo[2] &&
           p[2] < m->inside_hi[2];
}

/* The cell of a point at a level (memo m); false when the point is outside the grid's range. *same: the
 * memo's cell already was this one. */
static bool cell_enter_slow(const kind_wsc *k, const float p[3], uint32_t level, cell_memo *m, bool *same);

static inline bool cell_enter(const kind_wsc *k, const float p[3], uint32_t level, cell_memo *m, bool *same)
{
    *same = cell_same(m, level, p);
    return *same || cell_enter_slow(k, p, level, m, same);
}

/* cell_enter for a point not well inside the memo's cell (kept out of line: about one pixel in ten). */
static __attribute__((noinline)) bool cell_enter_slow(const kind_wsc *k, const float p[3], uint32_t level,
                                                      cell_memo *m, bool *same)
{
    int32_t g[3];
    /* wsc_corners' cell and range (the far corner g + 1 inside it too), without its 8 weights: wsc_grid_point
     * with the level's cell size from the table (the same double), then the far corner's range. */
    double cell = k->cell_size[level];
    for (int a = 0; a < 3; a++) {
        double q = floor((double)p[a] / cell);
        double lo = a == 1 ? WSC_Y_MIN : WSC_XZ_MIN, hi = a == 1 ? WSC_Y_MAX : WSC_XZ_MAX;
        if (!(q >= lo && q <= hi - 1)) { /* also NaN and inf; hi - 1: the far corner g + 1 within hi */
            m->level = UINT32_MAX;
            return false;
        }
        g[a] = (int32_t)q;
    }
    bool moved = m->level != level || memcmp(m->g, g, sizeof m->g) != 0;
    m->level = level;
    m->inv_cell = k->inv_cell_size[level];
    for (int a = 0; a < 3; a++) {
        m->g[a] = g[a];
        m->lo[a] = (double)g[a] * cell;
        m->inside_lo[a] = float_above(m->lo[a] + 1e-6 * cell);
        m->inside_hi[a] = float_below(m->lo[a] + cell - 1e-6 * cell);
    }
    *same = !moved; /* a point near a face of the same cell */
    return true;
}

/* The position of a point in the memo's cell (each in [0, 1]). */
static inline void cell_position(const cell_memo *m, const float p[3], float t[3])
{
    for (int a = 0; a < 3; a++) {
        float u = (float)(((double)p[a] - m->lo[a]) * m->inv_cell);
        /* [0, 1]; NaN cannot occur (the point is inside the cell). Selects, not fminf(fmaxf(u, 0), 1) (libm
         * calls here): the same floats but the sign of a zero, and a zero weight is left out either way */
        float above = u > 0.0f ? u : 0.0f;
        t[a] = above < 1.0f ? above : 1.0f;
    }
}

/* Corner c (0..7) of the memo's cell: g + (c & 1, c >> 1 & 1, c >> 2 & 1); its trilinear weight from t. */
static void corner_of(const cell_memo *m, int c, int32_t out[3])
{
    out[0] = m->g[0] + (c & 1);
    out[1] = m->g[1] + ((c >> 1) & 1);
    out[2] = m->g[2] + ((c >> 2) & 1);
}

/* Writes the keys of the memo's cell's 8 corners unless a recent pixel wrote them (seen). */
static uint32_t cell_keys(const cell_memo *m, uint32_t brick_size, uint64_t seen[32], uint64_t *keys,
                          uint64_t *masks, uint32_t n, uint32_t *refused)
{
    uint64_t cell;
    if (!wsc_wgi_pack(m->level, m->g[0], m->g[1], m->g[2], &cell)) {
        (*refused)++;
        return n;
    }
    uint32_t s = (uint32_t)((cell * 0x9E3779B97F4A7C15ull) >> 59); /* 5 bits: 32 slots */
    if (seen[s] == cell)
        return n;
    seen[s] = cell;
    uint32_t first = n;
    for (int c = 0; c < 8; c++) {
        int32_t corner[3];
        corner_of(m, c, corner);
        uint64_t wgi, bit;
        if (!wsc_brick_of(corner, m->level, brick_size, &wgi, &bit))
            continue; /* wsc_corners checked the range: not reached */
        uint32_t j = first;
        while (j < n && keys[j] != wgi)
            j++;
        if (j == n) {
            keys[n] = wgi;
            masks[n++] = bit;
        } else {
            masks[j] |= bit;
        }
    }
    return n;
}

FXC_HOT_CLONES static uint32_t wsc_kind_pixel_requests(const void *cache, uint32_t slot,
                                                       const srv_pixel *pixels, uint32_t count,
                                                       uint32_t effect, int32_t bias, uint64_t *keys,
                                                       uint64_t *masks)
{
    (void)slot;
    kind_wsc *k = (kind_wsc *)cache; /* only the atomic refusal counter is written */
    uint32_t n = 0, refused = 0, brick_size = k->brick_size[effect];
    /* Recent cells, direct-mapped: a pixel in a cell already asked for asks for the same 8 grid points. */
    uint64_t seen[32];
    memset(seen, 0xFF, sizeof seen);
    cell_memo memo = {.level = UINT32_MAX},
              next = {.level = UINT32_MAX}; /* the pixel's level, and level + 1 */
    for (uint32_t i = 0; i < count; i++) {
        float blend;
        bool same;
        const float *p = pixels[i].position;
        uint32_t level = pixel_level(k, &memo, &pixels[i], bias, &blend);
        if (!cell_enter(k, p, level, &memo, &same)) {
            refused++;
            continue;
        }
        if (!same)
            n = cell_keys(&memo, brick_size, seen, keys, masks, n, &refused);
        if (blend > 0 && cell_enter(k, p, level + 1, &next, &same) && !same)
            n = cell_keys(&next, brick_size, seen, keys, masks, n, &refused);
    }
    if (refused)
        atomic_fetch_add_explicit(&k->refused, refused, memory_order_relaxed);
    return n;
}

static fxc_result wsc_kind_request_batch(void *cache, uint32_t slot, uint32_t effect, uint64_t *keys,
                                         uint64_t *masks, size_t count, size_t *unique, uint32_t *blocks,
                                         uint64_t *pool_exhausted, uint64_t *table_full)
{
    (void)slot;
    kind_wsc *k = cache;
    wsc_stats before, after;
    wsc_stats_get(k->wsc, &before);
    osc_result r = wsc_request_batch(k->wsc, effect, keys, masks, count, unique, blocks);
    wsc_stats_get(k->wsc, &after);
    *pool_exhausted += after.effects[effect].exhausted - before.effects[effect].exhausted;
    *table_full += after.effects[effect].table_full - before.effects[effect].table_full;
    return (fxc_result)r;
}

static const uint32_t *wsc_kind_frame_blocks(void *cache, uint32_t effect, uint32_t *count)
{
    return wsc_frame_bricks(((kind_wsc *)cache)->wsc, effect, count);
}

static uint64_t wsc_kind_block_key(const void *cache, uint32_t effect, uint32_t block)
{
    return wsc_brick_key(((const kind_wsc *)cache)->wsc, effect, block);
}

static uint64_t wsc_kind_block_requested(const void *cache, uint32_t effect, uint32_t block)
{
    return wsc_brick_requested(((const kind_wsc *)cache)->wsc, effect, block);
}

static uint64_t wsc_kind_block_valid(const void *cache, uint32_t effect, uint32_t block)
{
    return wsc_brick_valid(((const kind_wsc *)cache)->wsc, effect, block);
}

static void wsc_kind_block_set_valid(void *cache, uint32_t effect, uint32_t block, uint64_t valid)
{
    wsc_brick_set_valid(((kind_wsc *)cache)->wsc, effect, block, valid);
}

static void *wsc_kind_block_payload(void *cache, uint32_t effect, uint32_t block)
{
    return wsc_brick_payload(((kind_wsc *)cache)->wsc, effect, block);
}

static uint32_t *wsc_kind_block_word(void *cache, uint32_t effect, uint32_t block)
{
    return wsc_brick_convergence(((kind_wsc *)cache)->wsc, effect, block);
}

static uint32_t wsc_kind_find(const void *cache, uint32_t effect, uint64_t key)
{
    return wsc_find(((const kind_wsc *)cache)->wsc, effect, key);
}

static void wsc_kind_job_location(const void *cache, uint32_t effect, uint64_t key, fx_block_job *job)
{
    const kind_wsc *k = cache;
    uint32_t level = 0;
    int32_t first[3] = {0, 0, 0};
    bool ok = wsc_brick_first_cell(key, k->brick_size[effect], &level, first);
    WSC_ASSERT(ok);
    double cell = wsc_cell_size(level, k->c0);
    job->key = key;
    job->level = level;
    job->cell = (float)cell;
    for (int a = 0; a < 3; a++)
        job->origin[a] = (float)((double)first[a] * cell);
}

/* Looks the memo's cell's corners up (through `local` when not NULL, else the hash table). */
static void find_cell_taps(kind_wsc *k, wsc_local *local, uint32_t effect, const cell_memo *m, cell_taps *out)
{
    uint32_t brick_size = k->brick_size[effect], cell_bytes = k->cell_bytes[effect];
    out->count = 0;
    out->first_block = SRV_NONE;
    for (int c = 0; c < 8; c++) {
        int32_t corner[3];
        corner_of(m, c, corner);
        uint64_t wgi, bit;
        if (!wsc_brick_of(corner, m->level, brick_size, &wgi, &bit))
            continue;
        uint32_t brick = local ? wsc_local_lookup(local, k->wsc, effect, wgi) : wsc_find(k->wsc, effect, wgi);
        if (brick == WSC_NONE)
            continue;
        if (out->first_block == SRV_NONE)
            out->first_block = brick;
        if (!(wsc_brick_valid(k->wsc, effect, brick) & bit))
            continue;
        uint32_t index = (uint32_t)__builtin_ctzll(bit);
        out->texel[out->count] =
            (const uint8_t *)wsc_brick_payload(k->wsc, effect, brick) + (size_t)index * cell_bytes;
        out->corner[out->count++] = (uint8_t)c;
    }
}

static void find_cell_cached(kind_wsc *k, wsc_local *local, cell_cache_entry *cache, uint32_t effect,
                             const cell_memo *m, cell_taps *out)
{
    uint64_t cell;
    if (!cache || k->stamp == 0 || !wsc_wgi_pack(m->level, m->g[0], m->g[1], m->g[2], &cell)) {
        find_cell_taps(k, local, effect, m, out);
        return;
    }
    cell_cache_entry *e = &cache[((cell ^ effect) * 0x9E3779B97F4A7C15ull) >> 56]; /* 8 bits: CELL_CACHE */
    if (e->stamp != k->stamp || e->cell != cell || e->effect != effect) {
        find_cell_taps(k, local, effect, m, &e->taps);
        e->stamp = k->stamp;
        e->cell = cell;
        e->effect = effect;
    }
    *out = e->taps;
}

/* Appends a point's taps from its cell's: trilinear weights times `scale` (not renormalised), corners of zero
 * weight left out. A point strictly inside a cell with all 8 corners (the usual case) appends the 8 in two
 * copies. Zero weights must stay out, not only because they add nothing: shade groups pixels by their list of
 * taps, and a point on a face of the cell (a wall on a grid plane) joining the group of the points inside
 * would move the group's mean position and so its Chebyshev weights (measured: up to 3 % on the embedded
 * scene's walls). */
static inline void add_taps(const cell_taps *ct, const float t[3], float scale, fx_taps *out)
{
    float wz0 = (1.0f - t[2]) * scale, wz1 = t[2] * scale;
    float wxy[4] = {(1.0f - t[0]) * (1.0f - t[1]), t[0] * (1.0f - t[1]), (1.0f - t[0]) * t[1], t[0] * t[1]};
    float w[8];
    for (int c = 0; c < 4; c++) {
        w[c] = wxy[c] * wz0;
        w[c + 4] = wxy[c] * wz1;
    }
    uint32_t n = out->count;
    /* All 8 above 0: their smallest is (the weights are products of factors in [0, 1] and a finite scale,
     * never NaN; a product may still underflow to 0, so the products are tested). Rounding a product of
     * factors >= 0 is monotonic in each factor, so the smallest of the 8 rounded products is the rounded
     * product of the smallest factors: wxy's smallest is x's times y's, w's that times the smaller wz
     * (the same float as the smallest of w, without comparing all 8). */
    float x_least = t[0] < 1.0f - t[0] ? t[0] : 1.0f - t[0],
          y_least = t[1] < 1.0f - t[1] ? t[1] : 1.0f - t[1];
    float least = x_least * y_least * (wz0 < wz1 ? wz0 : wz1);
    if (ct->count == 8 && least > 0) {
        memcpy(out->texel + n, ct->texel, sizeof ct->texel);
        memcpy(out->weight + n, w, sizeof w);
        out->count = n + 8;
        return;
    }
    for (uint32_t i = 0; i < ct->count; i++) { /* at_x, at_y: on-surface taps only (effects.h) */
        out->texel[n] = ct->texel[i];
        out->weight[n] = w[ct->corner[i]];
        n += out->weight[n] > 0; /* written, then overwritten when 0: no branch */
    }
    out->count = n;
}

uint32_t srv__wsc_world_taps(const void *user, uint32_t effect, const float position[3], uint32_t level,
                             fx_taps *taps)
{
    kind_wsc *k = (kind_wsc *)user; /* read-only: the table and payloads are only read here */
    taps->count = 0;
    if (effect >= SRV_MAX_EFFECTS || !k->brick_size[effect] || level > WSC_MAX_LEVEL)
        return 0;
    double world[3] = {(double)position[0], (double)position[1], (double)position[2]};
    int32_t corners[8][3];
    float weights[8];
    if (!wsc_corners(world, level, k->c0, corners, weights))
        return 0;
    cell_memo m = {.level = level};
    memcpy(m.g, corners[0], sizeof m.g);
    cell_taps ct;
    find_cell_taps(k, NULL, effect, &m, &ct);
    taps->footprint_log2 = 0;
    for (uint32_t i = 0; i < ct.count; i++) {
        float w = weights[ct.corner[i]];
        if (!(w > 0))
            continue;
        taps->texel[taps->count] = ct.texel[i];
        taps->weight[taps->count] = w;
        taps->at_x[taps->count] = taps->at_y[taps->count] = 0;
        taps->count++;
    }
    return taps->count;
}

bool srv__wsc_world_cell(const void *user, uint32_t effect, uint32_t level, const float centre[3],
                         const void *texel[8])
{
    kind_wsc *k = (kind_wsc *)user; /* read-only, as srv__wsc_world_taps */
    for (int c = 0; c < 8; c++)
        texel[c] = NULL;
    if (effect >= SRV_MAX_EFFECTS || !k->brick_size[effect] || level > WSC_MAX_LEVEL)
        return false;
    double world[3] = {(double)centre[0], (double)centre[1], (double)centre[2]};
    int32_t g[3];
    /* wsc_corners' range: g and the far corner g + 1 inside the grid */
    if (!wsc_grid_point(world, level, k->c0, g) || g[0] >= WSC_XZ_MAX || g[2] >= WSC_XZ_MAX ||
        g[1] >= WSC_Y_MAX)
        return false;
    if (k->brick_size[effect] == 1) /* probes: the 8 corners in one batched lookup, the same texels */
        return wsc_cell_corners(k->wsc, effect, level, g, texel);
    cell_memo m = {.level = level};
    memcpy(m.g, g, sizeof m.g);
    cell_taps ct;
    find_cell_taps(k, NULL, effect, &m, &ct);
    for (uint32_t i = 0; i < ct.count; i++)
        texel[ct.corner[i]] = ct.texel[i];
    return true;
}

FXC_HOT_INLINE void wsc_kind_pixel_taps_one(const void *cache, uint32_t slot, uint32_t thread,
                                            const srv_pixel *pixels, uint32_t count, uint32_t effect,
                                            int32_t bias, fx_taps *taps, uint32_t *blocks)
{
    kind_wsc *k = (kind_wsc *)cache; /* writes only this (viewer, thread)'s local table and counters */
    wsc_local *local = NULL;
    if (k->use_local && thread < k->threads) {
        wsc_local **slot_local = &k->local[(size_t)slot * k->threads + thread];
        if (!*slot_local) {
            wsc_local_desc ld = {.side = LOCAL_SIDE, .levels = LOCAL_LEVELS};
            char msg[128];
            if (wsc_local_create(&ld, k->wsc, slot_local, msg, sizeof msg) != OSC_OK)
                *slot_local = NULL; /* no memory: the table answers alone */
        }
        local = *slot_local;
    }
    wsc_local_stats before = {0}, after = {0};
    if (local)
        wsc_local_stats_get(local, &before);
    cell_cache_entry *cells =
        k->cell_cache && thread < k->threads ? k->cell_cache + (size_t)thread * CELL_CACHE : NULL;
    /* The pixel's cell: the last CELL_SLOTS cells entered and their taps, each kept until it is the oldest
     * (a run of block samples, or of pixels along rows, goes back and forth between a few cells; each cell's
     * taps are what find_cell_cached gives it, so which slot answers changes nothing). `levels` only holds
     * the distances' level range (pixel_level). */
    enum { CELL_SLOTS = 4 };
    cell_memo levels = {.level = UINT32_MAX}, slot_memo[CELL_SLOTS], next = {.level = UINT32_MAX};
    cell_taps slot_ct[CELL_SLOTS], next_ct = {.count = 0, .first_block = SRV_NONE};
    for (uint32_t c = 0; c < CELL_SLOTS; c++) {
        slot_memo[c].level = UINT32_MAX;
        slot_ct[c].count = 0;
        slot_ct[c].first_block = SRV_NONE;
    }
    uint32_t at = 0, oldest = 0;
    for (uint32_t i = 0; i < count; i++) {
        float t[3], blend;
        bool same;
        const float *p = pixels[i].position;
        uint32_t level = pixel_level(k, &levels, &pixels[i], bias, &blend);
        taps[i].count = 0;
        taps[i].footprint_log2 = 0;
        if (!cell_same(&slot_memo[at], level, p)) {
            uint32_t c = 0;
            while (c < CELL_SLOTS && !cell_same(&slot_memo[c], level, p))
                c++;
            if (c < CELL_SLOTS) {
                at = c;
            } else {
                at = oldest;
                oldest = (oldest + 1) % CELL_SLOTS;
                if (!cell_enter_slow(k, p, level, &slot_memo[at], &same)) {
                    if (blocks)
                        blocks[i] = SRV_NONE;
                    continue;
                }
                if (!same)
                    find_cell_cached(k, local, cells, effect, &slot_memo[at], &slot_ct[at]);
            }
        }
        const cell_memo *memo = &slot_memo[at];
        const cell_taps *ct = &slot_ct[at];
        cell_position(memo, p, t);
        add_taps(ct, t, 1.0f - blend, &taps[i]);
        if (blocks)
            blocks[i] = ct->first_block;
        if (blend > 0 && cell_enter(k, p, level + 1, &next, &same)) {
            if (!same)
                find_cell_cached(k, local, cells, effect, &next, &next_ct);
            cell_position(&next, p, t);
            add_taps(&next_ct, t, blend, &taps[i]);
        }
    }
    if (local) {
        wsc_local_stats_get(local, &after);
        uint64_t hits = after.hits - before.hits;
        uint64_t lookups = hits + (after.misses - before.misses) + (after.bypasses - before.bypasses);
        atomic_fetch_add_explicit(&k->local_lookups, lookups, memory_order_relaxed);
        atomic_fetch_add_explicit(&k->local_hits, hits, memory_order_relaxed);
    }
}

static uint32_t wsc_kind_pool_capacity(const void *cache, uint32_t effect)
{
    return wsc_capacity(((const kind_wsc *)cache)->wsc, effect);
}

static void wsc_kind_housekeeping(void *cache)
{
    kind_wsc *k = cache;
    uint64_t refused = atomic_load_explicit(&k->refused, memory_order_relaxed);
    if (refused) { /* counted against the first world-space effect: a point is refused for all alike */
        for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++)
            if (k->brick_size[e]) {
                wsc_count_refusals(k->wsc, e, refused);
                break;
            }
    }
    wsc_housekeeping(k->wsc);
}

static size_t locals_bytes(const kind_wsc *k)
{
    size_t bytes = (size_t)SRV_MAX_VIEWERS * k->threads * sizeof *k->local +
                   (size_t)k->threads * CELL_CACHE * sizeof *k->cell_cache;
    for (size_t i = 0; i < (size_t)SRV_MAX_VIEWERS * k->threads; i++)
        if (k->local[i]) {
            wsc_local_stats ls;
            wsc_local_stats_get(k->local[i], &ls);
            bytes += ls.bytes;
        }
    return bytes;
}

static void wsc_kind_frame_figures(const void *cache, srv_frame_stats *st)
{
    const kind_wsc *k = cache;
    wsc_stats ws;
    wsc_stats_get(k->wsc, &ws);
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++) {
        const wsc_effect_stats *es = &ws.effects[e];
        if (!es->brick_size)
            continue;
        st->blocks_resident[e] += es->bricks_resident;
        st->world.entries += es->entries;
        st->world.table_capacity += es->table_capacity;
        st->world.bricks_resident += es->bricks_resident;
        st->evictions += es->evictions;
        st->exhausted += es->exhausted;
        st->world.exhausted += es->exhausted;
    }
    wsc_memory_report m;
    wsc_memory(k->wsc, &m);
    st->world.bytes = m.total_bytes + sizeof *k + locals_bytes(k);
    st->world.refusals = atomic_load_explicit(&((kind_wsc *)k)->refused, memory_order_relaxed);
    st->world.local_lookups = atomic_load_explicit(&((kind_wsc *)k)->local_lookups, memory_order_relaxed);
    st->world.local_hits = atomic_load_explicit(&((kind_wsc *)k)->local_hits, memory_order_relaxed);
}

static void wsc_kind_memory(const void *cache, srv_memory *out)
{
    const kind_wsc *k = cache;
    wsc_memory_report m;
    wsc_memory(k->wsc, &m);
    size_t local = locals_bytes(k);
    out->table +=
        m.table_key_bytes + m.table_value_bytes + m.cache_struct_bytes + m.core_struct_bytes + sizeof *k;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++) {
        out->pools_reserved[e] += m.effects[e].payload_reserved_bytes;
        out->pools_in_use[e] += m.effects[e].payload_in_use_bytes;
        out->block_meta[e] += m.effects[e].block_meta_bytes + m.effects[e].list_bytes;
    }
    out->world_local += local;
    out->total += m.total_bytes + sizeof *k + local;
}

/* The interface's several effects: one after the other (their lookups share nothing); an AVX2 copy
 * (FXC_HOT_CLONES: the per-pixel level, cell and weights inlined; no contraction, so the same floats). The
 * lanes are not used: this kind reads the pixels' positions. */
FXC_HOT_CLONES static uint32_t wsc_kind_pixel_taps(const void *cache, uint32_t slot, uint32_t thread,
                                                   const srv_pixel *pixels, const srv_pixel_lanes *lanes,
                                                   uint32_t count, uint32_t effect_count,
                                                   const uint32_t *effects, int32_t bias,
                                                   fx_taps *const *taps, uint32_t *const *blocks)
{
    (void)lanes;
    uint32_t empty = 0;
    for (uint32_t j = 0; j < effect_count; j++) {
        wsc_kind_pixel_taps_one(cache, slot, thread, pixels, count, effects[j], bias, taps[j],
                                blocks ? blocks[j] : NULL);
        for (uint32_t i = 0; i < count; i++)
            empty += taps[j][i].count == 0;
    }
    return empty;
}

const srv_cache_kind srv__kind_wsc = {
    .name = "world_space",
    .kind = SCENE_CACHE_WORLD_SPACE,
    .keys_carry_effect = false,
    .needs_position = true,
    .create = wsc_kind_create,
    .destroy = wsc_kind_destroy,
    .begin_frame = wsc_kind_begin_frame,
    .pixel_requests = wsc_kind_pixel_requests,
    .key_effect = NULL,
    .rekey = NULL,
    .request_batch = wsc_kind_request_batch,
    .frame_blocks = wsc_kind_frame_blocks,
    .block_key = wsc_kind_block_key,
    .block_requested = wsc_kind_block_requested,
    .block_valid = wsc_kind_block_valid,
    .block_set_valid = wsc_kind_block_set_valid,
    .block_payload = wsc_kind_block_payload,
    .block_word = wsc_kind_block_word,
    .find = wsc_kind_find,
    .job_location = wsc_kind_job_location,
    .finer_texels = NULL,
    .pixel_taps = wsc_kind_pixel_taps,
    .pool_capacity = wsc_kind_pool_capacity,
    .housekeeping = wsc_kind_housekeeping,
    .frame_figures = wsc_kind_frame_figures,
    .memory = wsc_kind_memory,
    .viewer_removed = wsc_kind_viewer_removed,
};
