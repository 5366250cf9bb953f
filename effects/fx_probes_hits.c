/* The probe update's hits (effects/fx_probes.c's update calls fx__probe_shade_chunk once per chunk of rays
 * after rtcIntersect1M): the radiance leaving each front-face hit (shadow rays to the lights, the committed
 * probes around the hit through a per-thread memo of cells, in three passes over the chunk's hits), the
 * back faces and misses, each ray's distance. The shadow-ray queue is fx_probes_shading.h's, shared with the
 * no-cache estimate (fx_probes_eval.c). A front face of an emitting material adds its emission to what leaves
 * it (its light reaches the surfaces around it through the probes; only when the scene has emitters). The
 * rules (units, the bounce filter's departures, determinism) are in the comment at the top of fx_probes.c;
 * this file is apart so its hot inline code still inlines into its one entry point's AVX2 copy. */
#include "fx_probes_internal.h"
#include "fx_probes_shading.h"
#include "fxc_hot.h"
#include "scene_inline.h"

#include <pthread.h>
#include <stdlib.h>

static _Thread_local hit_shading thread_hit_shading; /* the update's, within one call */

/* ---- the bounce at hits: the committed probes around a hit, per cell ------------------------------------
 * The shading filter of fx__probe_filter_memo (trilinear x wrap x Chebyshev, renormalised) at a hit, with the
 * cell's 8 corners found once per frame and thread instead of once per hit: hits of neighbouring probes land
 * in the same cells again and again. A cell keeps its corners' payloads, which of them hold data and are on,
 * their positions and cells (the header read once), and the corners' irradiance towards the last
 * HIT_CELL_NORMALS normals asked (hits of one wall share one; exact: the same sums fx_probe_irradiance takes).
 * Per hit only the trilinear weights, the wrap and the Chebyshev weight (its moments towards the hit) are
 * left. The entries hold pointers into the cache: they are kept while ctx->epoch and ctx->frame stay the same
 * (payloads do not change within a frame's updates), else only within one update call.
 *
 * The memo: HIT_CELLS entries of 448 bytes (0.9 MB a thread; with the batch's marks and arrays, hit_memo,
 * 0.96 MB), direct-mapped, two normals a cell. On Sponza
 * (bench_probes --part rays, 5 frames; BENCHMARKS, branch probe-upd2) one normal a cell recomputed the corners'
 * irradiance 107,443 times; more entries cut the fills (106,118 with 2,048 entries, 47,132 with 16,384,
 * 39,015 with 65,536: about the distinct cells) but not the time: with 16,384 entries (11 MB) the entries'
 * first loads missed the caches, and perf put more time there than the fills had taken (the fills' 8 hash
 * lookups are about 0.5 % of the run's samples). On the heap (with more normals or entries it would not fit
 * in thread-local storage: static TLS beyond a few hundred KB makes pthread_create fail), allocated at a
 * thread's first update and freed when the thread ends (a pthread key's destructor); if that fails, a small
 * thread-local table serves: more fills, the same numbers. */
enum {
    HIT_CELLS_LOG2 = 11,
    HIT_CELLS = 1 << HIT_CELLS_LOG2,
    HIT_CELLS_FALLBACK_LOG2 = 8,
    HIT_CELL_NORMALS = 2
};

typedef struct hit_cell {
    uint64_t generation; /* the thread's generation it was filled in (0: empty) */
    float centre[3];     /* the cell's centre as the update computed it (compared bit for bit) */
    uint16_t level, effect;
    /* HIT_COARSE_KNOWN | j once hit_coarse_level has looked: the first level above `level` (j = 1 ..
     * FX_PROBE_COARSER_LEVELS) with an active corner in a cell overlapping this one, 0 none; 0 before */
    uint32_t coarse;
    uint32_t active; /* bit c: corner c holds a probe with data, not off */
    const uint8_t *texel[8];
    float position[8][3], cell[8];
    /* e[s] holds the active corners' irradiance towards normal[s] (compared bit for bit) when bit s of
     * normal_set is set; a new normal replaces slot normal_next (round robin: the oldest) */
    uint32_t normal_set, normal_next;
    float normal[HIT_CELL_NORMALS][3];
    float e[HIT_CELL_NORMALS][8][3];
} hit_cell;
_Static_assert(sizeof(hit_cell) % 64 == 0, "hit_cell: whole cache lines (hit_memo aligns them)");

/* The bounce of a chunk's front-face hits together (world_cell with the heap memo; batch_locate,
 * hits_bounce_prepare, hits_radiance). One hit at a time, each hit waited on its memo entry's first load,
 * then on its 8 corners' moment words, each depending on the one before (BENCHMARKS, probe-upd4's perf).
 * Here a chunk's front-face hits go through three passes, so those loads are issued for many hits before any
 * is waited on: (1) in the shadow-ray set-up loop, the cell, the memo entry's address and a prefetch of the
 * entry (and of the triangle's albedo loads); (2) before the shadow rays are traced (their tracing covers
 * the prefetches), in hit order, the tag compare and the fill, the normal's slot (computed when new), the
 * trilinear weights, hit_weights' first half and a prefetch of the active corners' moment words; (3) after
 * them, hit_weights' second half (the moments), the sum, and the hit's radiance. Every float is computed by
 * the same operations as one hit at a time (hit_bounce): the passes only move them in time. What pass 3
 * reads of an entry (corners, active, cells, the slot's irradiance) must still be what pass 2 saw: when a
 * later hit's fill would replace an entry, or its new normal a slot, that a hit waiting for pass 3 uses,
 * pass 3 runs first for the hits waiting (`pending` marks, per batch, the entries and slots in use). */
typedef struct hit_batch {
    uint32_t count;
    uint16_t ray[PROBE_CHUNK];
    uint32_t slot[PROBE_CHUNK], front[PROBE_CHUNK];
    hit_cell *entry[PROBE_CHUNK]; /* NULL: no bounce (out of range; after pass 2 also no active corner) */
    double t[PROBE_CHUNK][3];
    float centre[PROBE_CHUNK][3];
    float tap[PROBE_CHUNK][8], weight[PROBE_CHUNK][8], distance[PROBE_CHUNK][8];
    int32_t texel[PROBE_CHUNK][8];
    float bounce[PROBE_CHUNK][3]; /* pass 3's E of the probes around the hit */
    bool found[PROBE_CHUNK];      /* pass 3: some probe around the hit contributed (else own_bounce) */
    bool located[PROBE_CHUNK];    /* pass 1: hit_locate gave the hit's cell (centre) */
    uint32_t done;                /* pass 3 ran for hits [0, done) */
} hit_batch;

/* The heap memo of a thread: the entries, per entry the last batch that uses it (<< HIT_CELL_NORMALS) and the
 * slots it uses, and the batch. */
typedef struct hit_memo {
    _Alignas(64) hit_cell cells[HIT_CELLS]; /* 448 bytes each: 7 cache lines, not 8, from a line's start */
    uint64_t pending[HIT_CELLS];
    uint64_t batch_id;
    hit_batch batch;
} hit_memo;

/* Whether update shades a chunk's front-face hits in passes (the default) or one at a time (the tests
 * compare the two, bit for bit). */
bool fx__probe_hits_batched = true;
uint32_t fx__probe_memo_log2 = HIT_CELLS_LOG2;

static _Thread_local hit_cell thread_hit_fallback[1 << HIT_CELLS_FALLBACK_LOG2]; /* 115 KB */
static _Thread_local hit_memo *thread_hit_memo; /* NULL with the fallback: hits one at a time */
static _Thread_local hit_cell *thread_hit_cells;
static _Thread_local uint32_t thread_hit_shift; /* 64 - log2(entries) */
static _Thread_local uint64_t thread_hit_generation, thread_hit_epoch;
static _Thread_local uint32_t thread_hit_frame;
static pthread_key_t hit_cells_key;
static pthread_once_t hit_cells_once = PTHREAD_ONCE_INIT;
static bool hit_cells_key_ok;

static void hit_cells_free(void *p)
{
    free(p);
}

static void hit_cells_key_create(void)
{
    hit_cells_key_ok = pthread_key_create(&hit_cells_key, hit_cells_free) == 0;
}

/* The thread's table: the heap one (zeroed: generation 0, empty; aligned to a cache line), else the fallback. */
static void hit_cells_table(void)
{
    if (thread_hit_cells)
        return;
    pthread_once(&hit_cells_once, hit_cells_key_create);
    hit_memo *table = hit_cells_key_ok ? aligned_alloc(_Alignof(hit_memo), sizeof *table) : NULL;
    if (table)
        memset(table, 0, sizeof *table);
    if (table && pthread_setspecific(hit_cells_key, table) == 0) {
        thread_hit_memo = table;
        thread_hit_cells = table->cells;
        uint32_t log2 = fx__probe_memo_log2 >= 1 && fx__probe_memo_log2 <= HIT_CELLS_LOG2
                            ? fx__probe_memo_log2
                            : HIT_CELLS_LOG2;
        thread_hit_shift = 64 - log2;
    } else {
        free(table);
        thread_hit_cells = thread_hit_fallback;
        thread_hit_shift = 64 - HIT_CELLS_FALLBACK_LOG2;
    }
}

/* At the start of an update call: keep the cells while the loop and frame are the same, else forget them. */
static void hit_cells_begin(const fx_context *ctx)
{
    hit_cells_table();
    if (ctx->epoch && ctx->frame && ctx->epoch == thread_hit_epoch && ctx->frame == thread_hit_frame)
        return;
    thread_hit_generation++;
    thread_hit_epoch = ctx->epoch;
    thread_hit_frame = ctx->frame;
}

/* The memo entry of the cell around `centre` (its direct-mapped slot; not checked). */
FXC_HOT_INLINE hit_cell *hit_cell_entry(uint32_t effect, uint32_t level, const float centre[3])
{
    uint32_t bits[3];
    memcpy(bits, centre, sizeof bits);
    uint64_t h = (uint64_t)bits[0] * 0x9E3779B97F4A7C15ull ^ (uint64_t)bits[1] * 0xC2B2AE3D27D4EB4Full ^
                 (uint64_t)bits[2] * 0x165667B19E3779F9ull ^ ((uint64_t)level << 40) ^
                 ((uint64_t)effect << 48);
    h ^= h >> 31;
    h *= 0xD6E8FEB86659FD93ull;
    return &thread_hit_cells[h >> thread_hit_shift];
}

/* Whether entry e holds the cell around `centre` in this generation. */
FXC_HOT_INLINE bool hit_cell_holds(const hit_cell *e, uint32_t effect, uint32_t level, const float centre[3])
{
    return e->generation == thread_hit_generation && memcmp(e->centre, centre, sizeof e->centre) == 0 &&
           e->level == level && e->effect == effect;
}

/* Fills entry e with the cell around `centre` (its corners through world_cell). */
FXC_HOT_INLINE void hit_cell_fill(const fx_context *ctx, hit_cell *e, uint32_t effect, uint32_t level,
                                  const float centre[3])
{
    const void *texel[8];
    if (!ctx->world_cell(ctx->world_user, effect, level, centre, texel))
        memset(texel, 0, sizeof texel);
    e->generation = thread_hit_generation;
    memcpy(e->centre, centre, sizeof e->centre);
    e->level = (uint16_t)level;
    e->effect = (uint16_t)effect;
    e->coarse = 0;
    e->active = 0;
    e->normal_set = 0;
    e->normal_next = 0;
    for (int c = 0; c < 8; c++) {
        const uint8_t *p = texel[c];
        e->texel[c] = p;
        if (!p)
            continue;
        uint32_t flags = get_u32(p + 16);
        if (!(flags & FX_PROBE_HAS_DATA) || (flags & FX_PROBE_OFF))
            continue;
        e->active |= 1u << c;
        for (int k = 0; k < 3; k++)
            e->position[c][k] = get_f32(p + 4 * k);
        e->cell[c] = get_f32(p + 12);
    }
}

/* The cell around `centre` (a cell's centre: the same cell gives the same bits from any probe of a grid
 * whose coordinates are exact in float, as powers-of-two cells are; otherwise a cell may take two entries). */
FXC_HOT_INLINE hit_cell *hit_cell_find(const fx_context *ctx, uint32_t effect, uint32_t level,
                                       const float centre[3])
{
    hit_cell *e = hit_cell_entry(effect, level, centre);
    if (!hit_cell_holds(e, effect, level, centre))
        hit_cell_fill(ctx, e, effect, level, centre);
    return e;
}

/* probe_weight (fx_probes_map.c) with visibility for the 8 corners of a cell at once, times the trilinear
 * weights `tap` (0 for corners that are missing, off or without data), with two departures (file comment,
 * "The bounce at hits"): the moments are read from the one texel of the octahedral map the direction falls in
 * (nearest, not bilinear: one load per corner instead of four), and a corner behind the plane of the hit's
 * surface gets weight 0 when some corner lies in front of it (plane_mask: the corners in front, with a
 * trilinear weight). Written lane by lane without branches, so the AVX2 copy runs the 8 corners as one
 * vector. */
/* Its first half: per corner the wrap weight, the distance to the biased point, the texel the direction
 * falls in; returns the corners in front of the plane with a trilinear weight (`front`). */
FXC_HOT_INLINE uint32_t hit_weights_geometry(const hit_cell *restrict e, const float position[3],
                                             const float normal[3], const float tap[8], int32_t texel[8],
                                             float weight[8], float distance[8])
{
    const float px = position[0], py = position[1], pz = position[2];
    const float nx = normal[0], ny = normal[1], nz = normal[2];
    float cell[8], along[8];
    for (int c = 0; c < 8; c++) {
        cell[c] = e->cell[c];
        const float *probe = e->position[c];
        float tx = probe[0] - px, ty = probe[1] - py, tz = probe[2] - pz;
        float bx = probe[0] - (px + nx * FX_PROBE_NORMAL_BIAS * cell[c]);
        float by = probe[1] - (py + ny * FX_PROBE_NORMAL_BIAS * cell[c]);
        float bz = probe[2] - (pz + nz * FX_PROBE_NORMAL_BIAS * cell[c]);
        float len2 = tx * tx + ty * ty + tz * tz, biased_len2 = bx * bx + by * by + bz * bz;
        float len = sqrtf(len2);
        along[c] = tx * nx + ty * ny + tz * nz;
        float wrap = len > 0 ? (along[c] / len + 1.0f) * 0.5f : 1.0f;
        weight[c] = wrap * wrap + 0.2f;
        float d = sqrtf(biased_len2);
        distance[c] = d;
        /* fx_probe_oct_encode of the direction from the probe to the biased point */
        float safe = d > 0 ? d : 1.0f;
        float x = -bx / safe, y = -by / safe, z = -bz / safe;
        float l1 = fabsf(x) + fabsf(y) + fabsf(z);
        float ox = l1 > 0 ? x / (l1 > 0 ? l1 : 1.0f) : 0.0f, oy = l1 > 0 ? y / (l1 > 0 ? l1 : 1.0f) : 0.0f;
        float fold_x = (1.0f - fabsf(oy)) * (ox >= 0 ? 1.0f : -1.0f),
              fold_y = (1.0f - fabsf(ox)) * (oy >= 0 ? 1.0f : -1.0f);
        float u = z < 0 ? fold_x : ox, v = z < 0 ? fold_y : oy;
        /* the texel the direction falls in (u, v in [-1, 1]: texel (u + 1) x 4, clamped at the edge) */
        int32_t ix = (int32_t)((u + 1.0f) * 4.0f), iy = (int32_t)((v + 1.0f) * 4.0f);
        ix = ix < 0 ? 0 : (ix > 7 ? 7 : ix);
        iy = iy < 0 ? 0 : (iy > 7 ? 7 : iy);
        texel[c] = iy * FX_PROBE_MAP + ix;
    }
    uint32_t front = 0; /* corners in front of the surface's plane with a trilinear weight */
    for (int c = 0; c < 8; c++)
        front |= ((e->active >> c & 1) && along[c] >= 0 && tap[c] > 0 ? 1u : 0u) << c;
    return front;
}

static const uint8_t zero_payload[FX_PROBE_BYTES]; /* read in place of missing corners, never used */

/* The texel's moment word of corner c (the zero payload's for corners without data). */
FXC_HOT_INLINE const uint8_t *hit_moment_address(const hit_cell *restrict e, int c, int32_t texel)
{
    const uint8_t *p = (e->active >> c & 1) ? e->texel[c] : zero_payload;
    return p + PROBE_MOMENTS + 4 * texel;
}

/* Its second half: the moments' Chebyshev weight times the trilinear weight, the plane test. */
FXC_HOT_INLINE void hit_weights_finish(const hit_cell *restrict e, const float tap[8], const int32_t texel[8],
                                       const float weight[8], const float distance[8], uint32_t front,
                                       float out[8])
{
    uint32_t word[8]; /* the texel's two moments: mean distance (low half), mean squared distance */
    float cell[8];
    for (int c = 0; c < 8; c++) {
        cell[c] = e->cell[c];
        word[c] = get_u32(hit_moment_address(e, c, texel[c]));
    }
    for (int c = 0; c < 8; c++) {
        float m1 = half_bits_to_float(word[c] & 0xffffu), m2 = half_bits_to_float(word[c] >> 16);
        float w = probe_visibility_weight(weight[c], m1 * cell[c], m2 * cell[c] * cell[c], distance[c]);
        uint32_t keep = front ? (front >> c & 1) : (e->active >> c & 1);
        out[c] = keep ? w * tap[c] : 0.0f;
    }
}

FXC_HOT_INLINE void hit_weights(const hit_cell *restrict e, const float position[3], const float normal[3],
                                const float tap[8], float out[8])
{
    int32_t texel[8];
    float weight[8], distance[8];
    uint32_t front = hit_weights_geometry(e, position, normal, tap, texel, weight, distance);
    hit_weights_finish(e, tap, texel, weight, distance, front, out);
}

/* 1 / cell when multiplying by it rounds as dividing by cell does, else 0 (hit_locate then divides). A
 * power-of-two cell (the grid's: the finest cell is one and levels double it) has an exact inverse: three
 * divisions fewer per hit. Once per job. */
static inline double cell_inverse(float cell)
{
    uint32_t cell_bits;
    memcpy(&cell_bits, &cell, sizeof cell_bits);
    const bool exact_inverse = (cell_bits & 0x7fffffu) == 0 && cell > 0x1p-100f && cell < 0x1p100f;
    return exact_inverse ? 1.0 / (double)cell : 0.0;
}

/* The cell around a hit on the grid of `grid_point` (any grid point of the level, e.g. the job's) and `cell`
 * (metres): its centre and the position in it, t in [0, 1] per axis; false when it lies beyond the range. */
FXC_HOT_INLINE bool hit_locate(const float grid_point[3], float cell, double inverse, const float position[3],
                               float centre[3], double t[3])
{
    for (int k = 0; k < 3;
         k++) { /* the cell and the position in it (wsc_corners' rule, from the grid point) */
        double delta = (double)position[k] - (double)grid_point[k];
        double q = inverse != 0.0 ? delta * inverse : delta / (double)cell, f = floor(q);
        if (!(fabs(f) < 1e9))
            return false;
        centre[k] = (float)((double)grid_point[k] + (f + 0.5) * (double)cell);
        /* in [0, 1] without a clamp: q is finite, f <= q < f + 1, and rounding q - f keeps it between 0 and 1 */
        t[k] = q - f;
    }
    return true;
}

/* The 8 corners' trilinear weights at position t in the cell. */
FXC_HOT_INLINE void hit_taps(const double t[3], float tap[8])
{
    double wx[2] = {1.0 - t[0], t[0]}, wy[2] = {1.0 - t[1], t[1]}, wz[2] = {1.0 - t[2], t[2]};
    /* ((1 x wx) x wy) x wz in double, as before: 1 x wx is exact; the 4 products wx x wy once, not twice,
     * then times wz[0] and wz[1] as two 4-wide loops */
    double wxy[4] = {wx[0] * wy[0], wx[1] * wy[0], wx[0] * wy[1], wx[1] * wy[1]};
    for (int c = 0; c < 4; c++)
        tap[c] = (float)(wxy[c] * wz[0]);
    for (int c = 0; c < 4; c++)
        tap[c + 4] = (float)(wxy[c] * wz[1]);
}

/* The slot holding e's corners' irradiance towards `normal` (bit for bit), or HIT_CELL_NORMALS. */
FXC_HOT_INLINE uint32_t cell_normal_find(const hit_cell *e, const float normal[3])
{
    for (uint32_t n = 0; n < HIT_CELL_NORMALS; n++)
        if ((e->normal_set >> n & 1) && memcmp(e->normal[n], normal, sizeof e->normal[n]) == 0)
            return n;
    return HIT_CELL_NORMALS;
}

/* The active corners' irradiance towards a new normal into the next slot (round robin); returns the slot. */
FXC_HOT_INLINE uint32_t cell_normal_compute(hit_cell *e, const float normal[3])
{
    uint32_t slot = e->normal_next;
    e->normal_next = (slot + 1) % HIT_CELL_NORMALS;
    uint32_t texel[4];
    float w[4];
    fx__probe_oct_bilinear(normal, texel, w);
    for (int c = 0; c < 8; c++) {
        if (!(e->active >> c & 1))
            continue;
        const uint8_t *p = e->texel[c];
        float scale = get_f32(p + 24), r = 0, g = 0, b = 0;
        for (int i = 0; i < 4;
             i++) { /* the texel's three halves, written out: the same sums in the same order */
            const uint8_t *q = p + PROBE_IRRADIANCE + 6 * texel[i];
            r += w[i] * half_bits_to_float(fx__get_u16(q));
            g += w[i] * half_bits_to_float(fx__get_u16(q + 2));
            b += w[i] * half_bits_to_float(fx__get_u16(q + 4));
        }
        e->e[slot][c][0] = r * scale;
        e->e[slot][c][1] = g * scale;
        e->e[slot][c][2] = b * scale;
    }
    memcpy(e->normal[slot], normal, sizeof e->normal[slot]);
    e->normal_set |= 1u << slot;
    return slot;
}

/* The renormalised sum of the corners' irradiance in `slot` with the filter weights: false when none
 * contributes (out untouched). */
FXC_HOT_INLINE bool cell_sum(const hit_cell *e, uint32_t slot, const float weight[8], float out[3])
{
    float sum[3] = {0, 0, 0}, total = 0;
    for (int c = 0; c < 8; c++) {
        if (!(weight[c] > 0)) /* off, missing, or a trilinear weight of 0 */
            continue;
        for (int k = 0; k < 3; k++)
            sum[k] += weight[c] * e->e[slot][c][k];
        total += weight[c];
    }
    if (!(total > 0))
        return false;
    for (int k = 0; k < 3; k++)
        out[k] = min_of(sum[k] / total, FLT_MAX);
    return true;
}

/* The filter over a cell's corners with trilinear weights `tap`: E of the probes around the hit, or false
 * (out untouched: 0) when none contributes. */
FXC_HOT_INLINE bool cell_filter(hit_cell *e, const float tap[8], const float position[3],
                                const float normal[3], float out[3])
{
    uint32_t slot = cell_normal_find(e, normal);
    if (slot == HIT_CELL_NORMALS)
        slot = cell_normal_compute(e, normal);
    float weight[8];
    hit_weights(e, position, normal, tap, weight);
    return cell_sum(e, slot, weight, out);
}

/* The filter at a hit (one hit at a time: the path of the tests' comparison and of fx__probe_hits_batched
 * false): E of the probes around it, or false (and 0) when none contributes. */
FXC_HOT_INLINE bool hit_bounce_at(const fx_context *ctx, uint32_t effect, uint32_t level,
                                  const float grid_point[3], float cell, double inverse,
                                  const float position[3], const float normal[3], float out[3],
                                  float centre[3], bool *located)
{
    out[0] = out[1] = out[2] = 0;
    double t[3];
    *located = hit_locate(grid_point, cell, inverse, position, centre, t);
    if (!*located)
        return false;
    hit_cell *e = hit_cell_find(ctx, effect, level, centre);
    if (!e->active)
        return false;
    float tap[8];
    hit_taps(t, tap);
    return cell_filter(e, tap, position, normal, out);
}

/* hit_bounce_at without its cell. */
FXC_HOT_INLINE bool hit_bounce(const fx_context *ctx, uint32_t effect, uint32_t level,
                               const float grid_point[3], float cell, double inverse, const float position[3],
                               const float normal[3], float out[3])
{
    float centre[3];
    bool located;
    return hit_bounce_at(ctx, effect, level, grid_point, cell, inverse, position, normal, out, centre,
                         &located);
}

/* The bounce at a hit no probe of the update's level contributes to: the committed probes of the coarser
 * levels around it, level + 1 .. level + FX_PROBE_COARSER_LEVELS (the world cache's grid is anchored at the
 * scene-local origin and its cell doubles per level, wsc.h: cells of level l + 1 are unions of 2 x 2 x 2
 * cells of level l), with the same filter (trilinear x wrap x Chebyshev with each probe's own cell x plane
 * test); the first level whose probes contribute. False (out 0) when none does. A viewer requests coarser
 * levels for what it sees far away, so a hit off every viewer's screen near the probe (behind the viewers,
 * a ceiling) often still finds them; before, such a hit took own_bounce (below) at once.
 *
 * Most such hits find no probe at any level (on Sponza's bench, searching the four levels per hit cost 8 %
 * of the update's speed): the first level with an active corner is looked up once per cell of the update's
 * level and kept in its memo entry (hit_cell.coarse, hit_coarse_level); the filter then runs from that
 * level on, per hit. `centre`: the hit's cell at the update's level (hit_locate's). */
enum { HIT_COARSE_KNOWN = 0x100u };
static const float hit_anchor[3] = {0, 0, 0};

/* The first coarser level (1 .. FX_PROBE_COARSER_LEVELS above `level`) with an active corner in a cell that
 * overlaps the cell of `level` around `centre`, 0 when none; kept in that cell's memo entry. The levels below
 * it hold no probe around any hit of the cell, so skipping them changes nothing. */
FXC_HOT_INLINE uint32_t hit_coarse_level(const fx_context *ctx, uint32_t effect, uint32_t level, float cell,
                                         const float centre[3])
{
    hit_cell *e = hit_cell_find(ctx, effect, level, centre);
    if (e->coarse & HIT_COARSE_KNOWN)
        return e->coarse & 0xffu;
    uint32_t first = 0;
    for (uint32_t j = 1; j <= FX_PROBE_COARSER_LEVELS && !first; j++) {
        float coarse = ldexpf(cell, (int)j);
        if (!(coarse < FLT_MAX))
            break;
        double inverse = cell_inverse(coarse);
        /* the coarse cells around 8 points just inside the cell's corners: every coarse cell the cell
         * overlaps (one on the world cache's nested grid: its lowest and highest points fall in the same;
         * up to 8 where the grids are not nested, as in some tests' grids) */
        float low[3], high[3], low_centre[3], high_centre[3];
        double t[3];
        for (int k = 0; k < 3; k++) {
            low[k] = centre[k] - 0.49f * cell;
            high[k] = centre[k] + 0.49f * cell;
        }
        if (!hit_locate(hit_anchor, coarse, inverse, low, low_centre, t) ||
            !hit_locate(hit_anchor, coarse, inverse, high, high_centre, t))
            break;
        if (memcmp(low_centre, high_centre, sizeof low_centre) == 0) { /* one coarse cell (nested grids) */
            first = hit_cell_find(ctx, effect, level + j, low_centre)->active ? j : 0;
            continue;
        }
        for (uint32_t c = 0; c < 8 && !first; c++) {
            float point[3], coarse_centre[3];
            for (int k = 0; k < 3; k++)
                point[k] = c >> k & 1 ? high[k] : low[k];
            if (hit_locate(hit_anchor, coarse, inverse, point, coarse_centre, t) &&
                hit_cell_find(ctx, effect, level + j, coarse_centre)->active)
                first = j;
        }
    }
    /* the coarse cells' fills may have replaced e */
    if (hit_cell_holds(e, effect, level, centre))
        e->coarse = HIT_COARSE_KNOWN | first;
    return first;
}

FXC_HOT_INLINE bool hit_bounce_coarser(const fx_context *ctx, uint32_t effect, uint32_t level, float cell,
                                       const float centre[3], const float position[3], const float normal[3],
                                       float out[3])
{
    uint32_t first = hit_coarse_level(ctx, effect, level, cell, centre);
    for (uint32_t j = first; j && j <= FX_PROBE_COARSER_LEVELS; j++) {
        float coarse = ldexpf(cell, (int)j);
        if (!(coarse < FLT_MAX))
            break;
        if (hit_bounce(ctx, effect, level + j, hit_anchor, coarse, cell_inverse(coarse), position, normal,
                       out))
            return true;
    }
    out[0] = out[1] = out[2] = 0;
    return false;
}

/* The same through ctx->world_taps (world_cell NULL): taps_bounce at level + 1 .. level +
 * FX_PROBE_COARSER_LEVELS. */
static bool taps_bounce(const fx_taps *taps, const float position[3], const float normal[3], float out[3]);
static bool taps_bounce_coarser(const fx_context *ctx, uint32_t effect, uint32_t level,
                                const float position[3], const float normal[3], float out[3])
{
    for (uint32_t j = 1; j <= FX_PROBE_COARSER_LEVELS; j++) {
        fx_taps taps;
        memset(&taps, 0, sizeof taps);
        ctx->world_taps(ctx->world_user, effect, position, level + j, &taps);
        if (taps.count > 0 && taps_bounce(&taps, position, normal, out))
            return true;
    }
    out[0] = out[1] = out[2] = 0;
    return false;
}

/* The bounce at a hit no probe around contributes to (its cell holds no probe: no viewer requested it; or
 * every corner is off): the updating probe's own committed irradiance towards the hit's normal, 0 while it
 * has none or is off. The ray reached the hit, so the two see the same side of every wall; in a closed
 * uniform enclosure the irradiance is the same everywhere and this is exact. Before, such a hit reflected
 * no indirect light: inside a closed sphere of albedo 0.5 seen by one viewer, the light that went round
 * behind it was lost and the wall converged to 0.80 of its closed form E0 / (1 - rho), at albedo 0.99 to
 * 0.024 (tests/test_world.c, test_closed_sphere_one_viewer). */
FXC_HOT_INLINE void own_bounce(const fx_block_job *job, const float normal[3], float out[3])
{
    const uint8_t *p = job->payload;
    uint32_t flags = get_u32(p + 16);
    if (!(flags & FX_PROBE_HAS_DATA) || (flags & FX_PROBE_OFF)) {
        out[0] = out[1] = out[2] = 0;
        return;
    }
    fx_probe_irradiance(p, normal, out);
}

/* hit_bounce's filter from taps (ctx->world_taps, when world_cell is NULL): the taps as the corners of a
 * cell (up to 8; an update's taps are one level's 8 corners), then the same cell_filter. */
static bool taps_bounce(const fx_taps *taps, const float position[3], const float normal[3], float out[3])
{
    hit_cell e;
    memset(&e, 0, sizeof e);
    float tap[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    uint32_t n = taps->count < 8 ? taps->count : 8;
    for (uint32_t c = 0; c < n; c++) {
        const uint8_t *p = taps->texel[c];
        e.texel[c] = p;
        if (!p || !(taps->weight[c] > 0))
            continue;
        uint32_t flags = get_u32(p + 16);
        if (!(flags & FX_PROBE_HAS_DATA) || (flags & FX_PROBE_OFF))
            continue;
        e.active |= 1u << c;
        for (int k = 0; k < 3; k++)
            e.position[c][k] = get_f32(p + 4 * k);
        e.cell[c] = get_f32(p + 12);
        tap[c] = taps->weight[c];
    }
    return e.active && cell_filter(&e, tap, position, normal, out);
}

/* Radiance leaving a front-face hit, given its direct light (compose units) and the probes around it. */
FXC_HOT_INLINE void hit_radiance(const fx_context *ctx, const fx_block_job *job, double inverse, uint32_t tri,
                                 float u, float v, float t, const float position[3], const float normal[3],
                                 const float direct[3], float out[3])
{
    float albedo[3], bounce[3] = {0, 0, 0};
    /* The triangle's mean albedo (one load; file comment, "Albedo at hits"). */
    (void)u, (void)v, (void)t;
    scene_albedo_mean(ctx->s, tri, albedo);
    uint32_t effect = job->effect, level = job->level;
    bool found = false;
    if (ctx->world_cell) {
        float centre[3];
        bool located;
        found =
            hit_bounce_at(ctx, effect, level, job->origin, job->cell, inverse, position, normal, bounce,
                          centre, &located) ||
            (located && hit_bounce_coarser(ctx, effect, level, job->cell, centre, position, normal, bounce));
    } else if (ctx->world_taps) {
        fx_taps taps;
        memset(&taps, 0, sizeof taps);
        ctx->world_taps(ctx->world_user, effect, position, level, &taps);
        found = (taps.count > 0 && taps_bounce(&taps, position, normal, bounce)) ||
                taps_bounce_coarser(ctx, effect, level, position, normal, bounce);
    }
    if (!found)
        own_bounce(job, normal, bounce);
    for (int k = 0; k < 3; k++)
        out[k] = albedo[k] * (direct[k] + bounce[k] * (1.0f / FX_PROBE_PI));
    if (ctx->s->emissive) /* a front face: its own emission (one material lookup) */
        scene_emission_add(ctx->s, tri, normal, out);
}

/* Pass 1 of the batched bounce (the comment at hit_batch): chunk hit r at `position` joins the batch, its
 * cell located and its memo entry prefetched. */
FXC_HOT_INLINE void batch_locate(hit_batch *restrict hb, const fx_block_job *job, double inverse,
                                 const float position[3], uint32_t r)
{
    uint32_t i = hb->count++;
    hb->ray[i] = (uint16_t)r;
    hb->entry[i] = NULL;
    hb->located[i] = hit_locate(job->origin, job->cell, inverse, position, hb->centre[i], hb->t[i]);
    if (!hb->located[i])
        return;
    hit_cell *e = hit_cell_entry(job->effect, job->level, hb->centre[i]);
    hb->entry[i] = e;
#if defined(__GNUC__)
    for (size_t line = 0; line < sizeof *e; line += 64)
        __builtin_prefetch((const char *)e + line);
#endif
}

/* The loads of scene_albedo_mean(s, tri) that miss (the triangle's mesh index and texture mean), prefetched
 * in pass 1 for pass 3. */
FXC_HOT_INLINE void albedo_prefetch(const scene *s, uint32_t tri)
{
#if defined(__GNUC__)
    __builtin_prefetch(s->tri_mesh + tri);
    if (s->tri_texture_mean)
        __builtin_prefetch(s->tri_texture_mean + 3 * (size_t)tri);
#else
    (void)s, (void)tri;
#endif
}

/* Pass 3's bounce for batch hits [from, to): the moments' half of hit_weights and the sum (0 when none). */
FXC_HOT_INLINE void batch_bounce(hit_batch *restrict hb, uint32_t from, uint32_t to)
{
    for (uint32_t i = from; i < to; i++) {
        float *bounce = hb->bounce[i];
        bounce[0] = bounce[1] = bounce[2] = 0;
        const hit_cell *e = hb->entry[i];
        hb->found[i] = false;
        if (e) {
            float weight[8];
            hit_weights_finish(e, hb->tap[i], hb->texel[i], hb->weight[i], hb->distance[i], hb->front[i],
                               weight);
            hb->found[i] = cell_sum(e, hb->slot[i], weight, bounce);
        }
    }
}

/* Pass 2 of the batched bounce over the chunk's front-face hits (batch_locate's), in hit order, before the
 * shadow rays are traced (their tracing covers the moment words' prefetch); pass 3 runs for the hits waiting
 * when a later hit would replace what they read. */
FXC_HOT_INLINE void hits_bounce_prepare(const fx_context *ctx, const fx_block_job *job, hit_memo *memo,
                                        const struct RTCRayHit *hits, const float (*hit_pos)[3])
{
    hit_batch *restrict hb = &memo->batch;
    const scene *s = ctx->s;
    const uint32_t effect = job->effect, level = job->level;
    uint64_t batch = ++memo->batch_id;
    uint32_t done = 0;
    for (uint32_t i = 0; i < hb->count; i++) {
        hit_cell *e = hb->entry[i];
        if (!e)
            continue;
        uint64_t *pending = &memo->pending[e - memo->cells];
        if (!hit_cell_holds(e, effect, level, hb->centre[i])) {
            if (*pending >> HIT_CELL_NORMALS ==
                batch) { /* a waiting hit reads this entry: finish those first */
                batch_bounce(hb, done, i);
                done = i;
                batch = ++memo->batch_id;
            }
            hit_cell_fill(ctx, e, effect, level, hb->centre[i]);
        }
        if (!e->active) {
            hb->entry[i] = NULL;
            continue;
        }
        uint32_t r = hb->ray[i];
        const float *normal = s->tri_normal + 3 * (size_t)hits[r].hit.primID;
        uint32_t slot = cell_normal_find(e, normal);
        if (slot == HIT_CELL_NORMALS) {
            if (*pending >> HIT_CELL_NORMALS == batch &&
                (*pending >> e->normal_next & 1)) { /* the slot is read */
                batch_bounce(hb, done, i);
                done = i;
                batch = ++memo->batch_id;
            }
            slot = cell_normal_compute(e, normal);
        }
        *pending =
            (*pending >> HIT_CELL_NORMALS == batch ? *pending : batch << HIT_CELL_NORMALS) | (1u << slot);
        hb->slot[i] = slot;
        hit_taps(hb->t[i], hb->tap[i]);
        hb->front[i] = hit_weights_geometry(e, hit_pos[r], normal, hb->tap[i], hb->texel[i], hb->weight[i],
                                            hb->distance[i]);
#if defined(__GNUC__)
        for (uint32_t m = e->active; m; m &= m - 1) { /* the others read the zero payload, always cached */
            int c = __builtin_ctz(m);
            __builtin_prefetch(e->texel[c] + PROBE_MOMENTS + 4 * hb->texel[i][c]);
        }
#endif
    }
    hb->done = done;
}

/* Pass 3 for the hits left, then every batch hit's radiance (direct light back) into values[r][0..2]. */
FXC_HOT_INLINE void hits_radiance(const fx_context *ctx, const fx_block_job *job, hit_batch *restrict hb,
                                  const struct RTCRayHit *hits, const float (*hit_pos)[3],
                                  const hit_shading *hs, float (*values)[5])
{
    batch_bounce(hb, hb->done, hb->count);
    const scene *s = ctx->s;
    for (uint32_t i = 0; i < hb->count; i++) {
        uint32_t r = hb->ray[i];
        if (hb->found[i])
            continue;
        /* After pass 3 of every hit: the coarser levels' fills may replace entries the batch has read. */
        const float *normal = s->tri_normal + 3 * (size_t)hits[r].hit.primID;
        if (!hb->located[i] || !hit_bounce_coarser(ctx, job->effect, job->level, job->cell, hb->centre[i],
                                                   hit_pos[r], normal, hb->bounce[i]))
            own_bounce(job, normal, hb->bounce[i]);
    }
    for (uint32_t i = 0; i < hb->count; i++) {
        uint32_t r = hb->ray[i];
        float albedo[3];
        scene_albedo_mean(s, hits[r].hit.primID, albedo); /* the triangle's mean (file comment) */
        for (int k = 0; k < 3; k++)
            values[r][k] = albedo[k] * (hs->direct[r][k] + hb->bounce[i][k] * (1.0f / FX_PROBE_PI));
    }
    if (s->emissive) /* front faces: their own emission (one material lookup each) */
        for (uint32_t i = 0; i < hb->count; i++) {
            uint32_t tri = hits[hb->ray[i]].hit.primID;
            scene_emission_add(s, tri, s->tri_normal + 3 * (size_t)tri, values[hb->ray[i]]);
        }
    hb->count = 0;
}

/* Per update call (fx__probe_hits_begin): the directional lights' directions and the thread's heap memo when
 * the bounce runs in passes (NULL: one hit at a time). */
static _Thread_local fixed_lights thread_lights;
static _Thread_local hit_memo *thread_batch_memo;

void fx__probe_hits_begin(const fx_context *ctx)
{
    fixed_lights_init(ctx->s, &thread_lights);
    if (ctx->world_cell)
        hit_cells_begin(ctx);
    /* The front-face hits' bounce in passes (hit_batch) with the heap memo, else one at a time. */
    thread_batch_memo = ctx->world_cell && fx__probe_hits_batched ? thread_hit_memo : NULL;
    if (thread_batch_memo)
        thread_batch_memo->batch.count = 0;
}

FXC_HOT_CLONES uint64_t fx__probe_shade_chunk(const fx_context *ctx, const fx_block_job *job,
                                              const float origin[3], const float (*dirs)[3],
                                              const struct RTCRayHit *hits, uint32_t n, const float sky[3],
                                              fx_probe_faces *faces, float (*values)[5])
{
    const scene *s = ctx->s;
    hit_shading *hs = &thread_hit_shading; /* 20 KB: off the (pool thread) stack, never allocated */
    hit_memo *memo = thread_batch_memo;
    const bool batch = memo != NULL;
    const fixed_lights *lights = &thread_lights;
    const float cell = job->cell, max_distance = FX_PROBE_MAX_DISTANCE * cell;
    const double inverse = cell_inverse(cell);
    uint64_t traced = 0;

    /* Shadow rays of the front-face hits. */
    hs->count = 0;
    float hit_pos[PROBE_CHUNK][3];
    for (uint32_t r = 0; r < n; r++) {
        hs->direct[r][0] = hs->direct[r][1] = hs->direct[r][2] = 0;
        const struct RTCRayHit *rh = &hits[r];
        if (rh->hit.geomID == RTC_INVALID_GEOMETRY_ID || rh->hit.primID >= s->triangle_count)
            continue;
        const float *normal = s->tri_normal + 3 * (size_t)rh->hit.primID;
        const float *dir = dirs[r];
        if (!(fx__dot(dir, normal) < 0))
            continue; /* back face */
        float p[3];
        for (int k = 0; k < 3; k++)
            p[k] = origin[k] + rh->ray.tfar * dir[k];
        scene_offset_ray_origin_inline(p, normal, s->ray_offset_scale, hit_pos[r]);
        traced += queue_shadow_rays(ctx, batch ? lights : NULL, hs, r, hit_pos[r], normal);
        if (batch) { /* passes 1 and 2 of the bounce (hit_batch), before the shadow rays are traced */
            batch_locate(&memo->batch, job, inverse, hit_pos[r], r);
            albedo_prefetch(s, rh->hit.primID);
        }
    }
    if (batch)
        hits_bounce_prepare(ctx, job, memo, hits, (const float(*)[3])hit_pos);
    shadow_flush(ctx, hs);

    /* Radiance and distance of every ray. */
    for (uint32_t r = 0; r < n; r++) {
        const struct RTCRayHit *rh = &hits[r];
        const float *dir = dirs[r];
        float radiance[3], distance;
        if (rh->hit.geomID == RTC_INVALID_GEOMETRY_ID || rh->hit.primID >= s->triangle_count) {
            memcpy(radiance, sky, sizeof radiance);
            distance = max_distance;
        } else {
            const float *normal = s->tri_normal + 3 * (size_t)rh->hit.primID;
            float t = rh->ray.tfar;
            if (!(fx__dot(dir, normal) < 0)) {
                faces->backfaces++;
                radiance[0] = radiance[1] = radiance[2] = 0;
                distance = FX_PROBE_BACKFACE_SHORTEN * t;
                if (t < faces->closest_back) {
                    faces->closest_back = t;
                    memcpy(faces->back_dir, dir, sizeof faces->back_dir);
                }
            } else {
                if (batch) { /* radiance from hits_radiance below */
                    radiance[0] = radiance[1] = radiance[2] = 0;
                } else {
                    hit_radiance(ctx, job, inverse, rh->hit.primID, rh->hit.u, rh->hit.v, t, hit_pos[r],
                                 normal, hs->direct[r], radiance);
                }
                distance = t;
                if (t < faces->closest_front) {
                    faces->closest_front = t;
                    memcpy(faces->front_dir, dir, sizeof faces->front_dir);
                }
            }
            distance = min_of(distance, max_distance);
        }
        float d = distance / cell;
        values[r][0] = radiance[0];
        values[r][1] = radiance[1];
        values[r][2] = radiance[2];
        values[r][3] = d;
        values[r][4] = d * d;
    }
    if (batch)
        hits_radiance(ctx, job, &memo->batch, hits, (const float(*)[3])hit_pos, hs, values);
    return traced;
}
