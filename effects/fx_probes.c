/* Probes: DDGI-style indirect diffuse light in the world-space cache (DESIGN.md "Effects"; Majercik et al.
 * 2019, "Dynamic Diffuse Global Illumination with Ray-Traced Irradiance Fields", and RTXGI's defaults).
 * Frame stage 6 for world-space jobs (update, then commit after every update of the frame), stage 7 (shade),
 * and the per-pixel estimate of the no-cache baseline (eval).
 *
 * Units. Compose forms radiance = albedo x (E_l cos + sky x sky_visibility + indirect): its bracket is
 * irradiance over pi (a light's `intensity` is its irradiance over pi; the sky term is the sky's radiance L,
 * which is pi L over pi). Payloads store true irradiance E (pi L under a uniform sky) as DDGI does; shade and
 * eval add E / pi to `indirect`, so a white wall under a uniform sky gets from the probes exactly what the
 * sky term gives it. The probe irradiance includes the sky (misses return it), so shade and eval set
 * sky_visibility to 0 for the pixels they light (compose would otherwise count the sky twice) after scaling
 * E by what it held (ambient occlusion's open fraction when AO ran before them, else 1).
 *
 * This file: update, commit, the no-cache estimate and the effect's table; fx_probes_map.c: the maps, their
 * readers and compose's shade.
 *
 * Update of one probe (a job, brick size 1): probe_rays rays in a spherical Fibonacci set, rotated by a
 * uniform random rotation from hash(seed, frame) shared by every probe of the frame (RTXGI rotates a volume's
 * rays once per update the same way; without a frame number, ctx->frame 0, from hash(seed, update count)),
 * from the probe's (relocated) position:
 *   - front-face hit: radiance = albedo x (direct light at the hit, shadow rays to every light, as compose
 *     lights it + E_probes / pi), E_probes the committed probes around the hit at the job's level with the
 *     update's filter (below, "The bounce at hits"), the hit's cell read through ctx->world_cell and kept
 *     per thread for the frame (hit_bounce; through ctx->world_taps per hit when world_cell is NULL, the same
 *     filter): light bounces once more every frame; the albedo is the triangle's mean (below);
 *   - back-face hit: radiance 0, counted, distance shortened to 0.2 t (RTXGI), so the visibility moments see
 *     the wall as near;
 *   - miss: the sky's radiance, distance the maximum.
 * Distances are clamped to 1.5 sqrt(3) cell (RTXGI's maximum). Per texel direction d_t, the new irradiance is
 * pi sum(max(0, d_t.d_i) L_i) / sum(max(0, d_t.d_i)) (the cosine-weighted integral, normalised by the
 * quadrature's own weight sum), and the moments sum(w d) / sum(w), sum(w d^2) / sum(w) with w = max(0,
 * d_t.d_i)^FX_PROBE_DEPTH_POWER. These, the back-face fraction, the off decision and the relocated position
 * go to the job's scratch; commit blends them into the payload: old x h + new x (1 - h), h =
 * ctx->probe_hysteresis, except that the first update after the probe was created or switched on is taken
 * as is. Plain hysteresis (no RTXGI change-threshold or brightness clamp), so a step settles as h^k exactly.
 *
 * Probes inside geometry are switched off (shade and the update filter skip them; the update count is reset):
 * more than FX_PROBE_BACKFACE_OFF (RTXGI's 25 %) of the rays hit back faces, or some back face lies within
 * the cell diagonal sqrt(3) cell and no front face does (none this update, and none in an earlier update from
 * the same position: FX_PROBE_SEEN_FRONT, cleared when the probe moves; geometry is static, so a face once seen
 * is there, and a sliver of front face that only some rotations of the rays find does not switch the probe
 * on and off). A probe just outside a closed room sees only the room's back faces near it, under 25 % of its
 * rays, and would otherwise pass its darkness to the wall points of its cells; RTXGI's classification also
 * switches off probes with no front face in their cell.
 * Relocation, every update, from the same rays (offset = position - grid point, m = FX_PROBE_MIN_FRONT cell):
 *   1. off (the tests above): move through the closest back face, offset += dir_b (t_b + m / 2)
 *      (RTXGI: towards the closest back face, which is the way out of the geometry);
 *   2. else a front face closer than m: move straight away from it by what is missing, offset -= dir_f (m -
 *      t_f) (a probe in a corner walks out of it over a few updates);
 *   3. else: back towards the grid point by min(t_f - m, |offset|) (RTXGI), t_f the closest front face;
 *      not for a probe that once moved out of geometry (FX_PROBE_MOVED_OUT): it holds its place.
 * Each component of the offset is clamped to +-0.45 cell (RTXGI checks per axis too), so a probe never
 * passes half way to its neighbour and the trilinear cell stays right. A move out (1.) that the clamp would
 * stop short of the face (less than m / 8 beyond it along the ray) is not made: the probe stays off where it
 * is, rather than sit on the surface. Both departures from RTXGI keep a probe near the edge of a
 * single-sided surface from cycling: behind the edge it is off, moves out through the face, walks back
 * towards its grid point round the edge (t_f sees no face on that path) and is off again, restarting from
 * one update's rays each time; a probe moved part way sat on the face and was on or off with the rays'
 * rotation (tests/test_probes.c, test_wall_edge_stable).
 *
 * Storage: half floats (the 1024-byte texel limit; floats would take 1,280 bytes for the maps alone). The
 * irradiance is stored relative to a per-probe float scale, so any light intensity keeps 11 bits of
 * precision (DESIGN.md "Numerical robustness": nothing saturates or overflows); moments are in cell units
 * (scale-free: a scene of 1e-4 m keeps them normal halves). Rounding to half is stochastic (probability
 * from a hash): with nearest rounding a 3 % step is below half a unit in the last place within 0.8 % of the
 * target, and the blend would stall there; stochastic rounding keeps the blend's mean exact.
 *
 * Albedo at hits: scene_albedo_mean, the triangle's texture mean (one load; computed when the scene is
 * finalised) times its material's colour, instead of the texture filtered at the ray's footprint (a mip
 * level from log2f, a bilinear fetch). What a texel of the irradiance map integrates is a cosine lobe over
 * many hits, and the light leaving a hit is low-frequency indirect light: the triangle's mean differs from
 * the footprint's mean only where a triangle is larger than a ray's footprint (near hits on big textured
 * triangles), and then by the texture's variation within the triangle. Untextured materials: the same floats
 * as before (diffuse x 1). BENCHMARKS, branch probe-upd, measures the image change against the seed noise.
 *
 * The bounce at hits (hit_weights): DDGI's filter (trilinear x wrap x Chebyshev, renormalised, crushing below
 * 0.2) as compose's shade has it, with two departures for the update only: (1) the Chebyshev test reads the
 * moments of the one octahedral texel the direction from the probe falls in, not the bilinear mix of four
 * (a quarter of the scattered loads and of the texel arithmetic); (2) a plane test: a corner behind the plane
 * of the surface it would light gets weight 0 (it cannot see that side) as long as one corner with a
 * trilinear weight lies in front; when none does, all corners keep their filter weights as before (a surface
 * near a cell face with every corner behind it would otherwise get no bounce at all). The plane test only
 * removes light from behind a surface (what the Chebyshev test let through at its floor of 0.05 and the wrap
 * at 0.2), which is what the thin-wall test measures; the nearest texel coarsens the visibility to the map's
 * 8x8 resolution, which the same test bounds (tests/test_probes.c, unchanged tolerances).
 *
 * Determinism: update reads only committed payloads (its own and world_taps' / world_cell's); all
 * randomness is hashed from (seed, frame or update count) for the rays and (seed, key, texel, update count)
 * for the rounding: any thread split or job order gives the same bytes. The caller must have
 * called scene_tracing_thread_init() in the tracing thread. */
#include "fx_probes_internal.h"
#include "fxc_hot.h"
#include "scene_inline.h"

#include <pthread.h>
#include <stdlib.h>

/* fminf(x, m) for m > 0 (not NaN), inline: NaN and x >= m give m, as fminf does (libm's fminf is a call
 * here: without -ffinite-math-only the compiler does not inline it). */
static inline float min_of(float x, float m)
{
    return x < m ? x : m;
}

/* Values >= 0 to halves, each rounded up with probability equal to its position between the two neighbouring
 * halves (u in [0, 1)), so the rounding is unbiased; saturates at the largest half (65504), never infinity;
 * negative values and NaN become 0 (irradiance and distances are never negative). Written without branches
 * so the AVX2 copy runs 8 at a time (x clamped to [0, 65504] first, NaN to 0; a normal half's bits are the
 * float's shifted, less the exponent biases' difference; below 2^-14 a truncated multiple of 2^-24). The
 * same halves as the scalar version it replaced, checked over 42 million inputs (every half, the midpoints
 * between halves, random floats of every exponent, 0, -0, NaN, infinities). */
FXC_HOT_CLONES static void halves_stochastic(const float *restrict x, const float *restrict u, uint32_t n,
                                             uint16_t *restrict out)
{
    for (uint32_t i = 0; i < n; i++) { /* selects only: && or a bool mixed into integers stop the vectoriser */
        float xi = x[i];
        float v = xi > 0 ? xi : 0.0f;
        v = v < 65504.0f ? v : 65504.0f;
        uint32_t bits;
        memcpy(&bits, &v, sizeof bits);
        uint32_t sub = (uint32_t)(int32_t)(v * 0x1p24f), norm = (bits >> 13) - (112u << 10);
        uint32_t lo = v < 0x1p-14f ? sub : norm;
        float below = half_bits_to_float(lo), above = half_bits_to_float(lo + 1);
        uint32_t up = u[i] * (above - below) < v - below ? 1u : 0u;
        up = below != v ? up : 0u;
        up = lo != 0x7bffu ? up : 0u;
        out[i] = (uint16_t)(lo + up);
    }
}

/* ---- update ---------------------------------------------------------------------------------------- */

/* What update leaves for commit (host floats: scratch never leaves the process). */
typedef struct probe_scratch {
    float irradiance[FX_PROBE_TEXELS][3]; /* new estimate of E per texel */
    float irradiance_weight[FX_PROBE_TEXELS];
    float moments[FX_PROBE_TEXELS][2];    /* new mean distance and squared distance, cells */
    float moment_weight[FX_PROBE_TEXELS];
    float position[3];                    /* relocated position for the next update */
    float backface_fraction;
    uint32_t off;
    uint32_t moved_out;  /* FX_PROBE_MOVED_OUT for the payload */
    uint32_t seen_front; /* FX_PROBE_SEEN_FRONT for the payload */
    uint32_t valid; /* 1 once update wrote it */
} probe_scratch;

/* A uniform random rotation (Shoemake's quaternion from three uniform numbers) as a row-major matrix. */
static void random_rotation(uint64_t h1, uint64_t h2, float m[9])
{
    float u1 = fx__unit_float((uint32_t)h1), u2 = fx__unit_float((uint32_t)(h1 >> 32)),
          u3 = fx__unit_float((uint32_t)h2);
    float s2, c2, s3, c3;
    fx__sincos_turns(u2, &s2, &c2);
    fx__sincos_turns(u3, &s3, &c3);
    float a = sqrtf(1.0f - u1), b = sqrtf(u1);
    float x = a * s2, y = a * c2, z = b * s3, w = b * c3;
    float n = sqrtf(x * x + y * y + z * z + w * w);
    x /= n, y /= n, z /= n, w /= n;
    m[0] = 1 - 2 * (y * y + z * z), m[1] = 2 * (x * y - z * w), m[2] = 2 * (x * z + y * w);
    m[3] = 2 * (x * y + z * w), m[4] = 1 - 2 * (x * x + z * z), m[5] = 2 * (y * z - x * w);
    m[6] = 2 * (x * z - y * w), m[7] = 2 * (y * z + x * w), m[8] = 1 - 2 * (x * x + y * y);
}

static uint32_t ray_count(const fx_context *ctx)
{
    uint32_t n = ctx->probe_rays ? ctx->probe_rays : FX_PROBE_RAYS;
    return n > FX_PROBE_MAX_RAYS ? FX_PROBE_MAX_RAYS : n;
}

/* The shading of a chunk of hits: per primary ray, its radiance once the shadow rays are back. */
typedef struct hit_shading {
    _Alignas(64) struct RTCRay shadow[FX_RAY_BATCH];
    uint16_t owner[FX_RAY_BATCH];
    float light[FX_RAY_BATCH][3];
    uint32_t count;
    float direct[PROBE_CHUNK][3]; /* compose units (irradiance / pi) */
} hit_shading;

FXC_HOT_INLINE void shadow_flush(const fx_context *ctx, hit_shading *hs)
{
    fx__occluded(ctx, hs->shadow, hs->count);
    for (uint32_t r = 0; r < hs->count; r++)
        if (hs->shadow[r].tfar != -INFINITY)
            for (int k = 0; k < 3; k++)
                hs->direct[hs->owner[r]][k] += hs->light[r][k];
    hs->count = 0;
}

/* The directions of the first PROBE_FIXED_LIGHTS lights that are directional, once per update call: they do not
 * depend on the point (fx_light_direction's, the same floats), so the shadow-ray set-up skips the call and
 * its square root and division per hit and light. */
enum { PROBE_FIXED_LIGHTS = 16 };
typedef struct fixed_lights {
    uint32_t directional; /* bit l: light l is directional, its direction in dir[l] */
    float dir[PROBE_FIXED_LIGHTS][3];
} fixed_lights;

static void fixed_lights_init(const scene *s, fixed_lights *fl)
{
    fl->directional = 0;
    static const float anywhere[3] = {0, 0, 0};
    for (uint32_t l = 0; l < s->light_count && l < PROBE_FIXED_LIGHTS; l++) {
        if (s->lights[l].type != SCENE_LIGHT_DIRECTIONAL)
            continue;
        float distance;
        fx_light_direction(&s->lights[l], anywhere, fl->dir[l], &distance);
        fl->directional |= 1u << l;
    }
}

/* fx__light_arriving, for a directional light with its direction given (distance infinite, no falloff). */
FXC_HOT_INLINE bool light_arriving_fixed(const scene_light *light, const float fixed_dir[3], const float normal[3],
                                         float dir[3], float *distance, float *scale)
{
    memcpy(dir, fixed_dir, 3 * sizeof(float));
    *distance = INFINITY;
    float cosine = fx__dot(normal, dir);
    if (!(cosine > 0))
        return false;
    *scale = light->intensity * cosine * 1.0f; /* fx__light_arriving's falloff 1 */
    return *scale > 0;
}

/* Queues the shadow rays of a front-face hit (origin already offset, unit front normal) for chunk slot i;
 * returns the rays queued. Contributions are compose's: intensity x colour x cos (/ d^2 for point lights).
 * fl: the directional lights' directions (NULL: none given). */
FXC_HOT_INLINE uint32_t queue_shadow_rays(const fx_context *ctx, const fixed_lights *fl, hit_shading *hs,
                                          uint32_t i, const float origin[3], const float normal[3])
{
    const scene *s = ctx->s;
    uint32_t queued = 0;
    for (uint32_t l = 0; l < s->light_count; l++) {
        const scene_light *light = &s->lights[l];
        float dir[3], distance, scale;
        bool fixed = fl && l < PROBE_FIXED_LIGHTS && (fl->directional >> l & 1);
        if (fixed ? !light_arriving_fixed(light, fl->dir[l], normal, dir, &distance, &scale)
                  : !fx__light_arriving(light, origin, normal, dir, &distance, &scale))
            continue;
        if (hs->count == FX_RAY_BATCH)
            shadow_flush(ctx, hs);
        fx__set_ray(&hs->shadow[hs->count], origin, dir, isinf(distance) ? INFINITY : distance * (1.0f - 1e-4f),
                    hs->count);
        hs->owner[hs->count] = (uint16_t)i;
        for (int k = 0; k < 3; k++)
            hs->light[hs->count][k] = min_of(scale * light->color[k], FLT_MAX);
        hs->count++;
        queued++;
    }
    return queued;
}

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
enum { HIT_CELLS_LOG2 = 11, HIT_CELLS = 1 << HIT_CELLS_LOG2, HIT_CELLS_FALLBACK_LOG2 = 8, HIT_CELL_NORMALS = 2 };

typedef struct hit_cell {
    uint64_t generation; /* the thread's generation it was filled in (0: empty) */
    float centre[3];     /* the cell's centre as the update computed it (compared bit for bit) */
    uint32_t level, effect;
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
        uint32_t log2 = fx__probe_memo_log2 >= 1 && fx__probe_memo_log2 <= HIT_CELLS_LOG2 ? fx__probe_memo_log2
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
                 (uint64_t)bits[2] * 0x165667B19E3779F9ull ^ ((uint64_t)level << 40) ^ ((uint64_t)effect << 48);
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
    e->level = level;
    e->effect = effect;
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
FXC_HOT_INLINE hit_cell *hit_cell_find(const fx_context *ctx, uint32_t effect, uint32_t level, const float centre[3])
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
        float fold_x = (1.0f - fabsf(oy)) * (ox >= 0 ? 1.0f : -1.0f), fold_y = (1.0f - fabsf(ox)) * (oy >= 0 ? 1.0f : -1.0f);
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
                                       const float weight[8], const float distance[8], uint32_t front, float out[8])
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
    for (int k = 0; k < 3; k++) { /* the cell and the position in it (wsc_corners' rule, from the grid point) */
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
        for (int i = 0; i < 4; i++) { /* the texel's three halves, written out: the same sums in the same order */
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
FXC_HOT_INLINE bool cell_filter(hit_cell *e, const float tap[8], const float position[3], const float normal[3],
                                float out[3])
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
FXC_HOT_INLINE bool hit_bounce(const fx_context *ctx, uint32_t effect, uint32_t level, const float grid_point[3],
                               float cell, double inverse, const float position[3], const float normal[3],
                               float out[3])
{
    out[0] = out[1] = out[2] = 0;
    float centre[3];
    double t[3];
    if (!hit_locate(grid_point, cell, inverse, position, centre, t))
        return false;
    hit_cell *e = hit_cell_find(ctx, effect, level, centre);
    if (!e->active)
        return false;
    float tap[8];
    hit_taps(t, tap);
    return cell_filter(e, tap, position, normal, out);
}

/* hit_bounce's filter from taps (ctx->world_taps, when world_cell is NULL): the taps as the corners of a
 * cell (up to 8; an update's taps are one level's 8 corners), then the same cell_filter. */
static void taps_bounce(const fx_taps *taps, const float position[3], const float normal[3], float out[3])
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
    if (e.active)
        cell_filter(&e, tap, position, normal, out);
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
    if (ctx->world_cell) {
        hit_bounce(ctx, effect, level, job->origin, job->cell, inverse, position, normal, bounce);
    } else if (ctx->world_taps) {
        fx_taps taps;
        memset(&taps, 0, sizeof taps);
        ctx->world_taps(ctx->world_user, effect, position, level, &taps);
        if (taps.count > 0)
            taps_bounce(&taps, position, normal, bounce);
    }
    for (int k = 0; k < 3; k++)
        out[k] = albedo[k] * (direct[k] + bounce[k] * (1.0f / FX_PROBE_PI));
}

/* Pass 1 of the batched bounce (the comment at hit_batch): chunk hit r at `position` joins the batch, its
 * cell located and its memo entry prefetched. */
FXC_HOT_INLINE void batch_locate(hit_batch *restrict hb, const fx_block_job *job, double inverse,
                                 const float position[3], uint32_t r)
{
    uint32_t i = hb->count++;
    hb->ray[i] = (uint16_t)r;
    hb->entry[i] = NULL;
    if (!hit_locate(job->origin, job->cell, inverse, position, hb->centre[i], hb->t[i]))
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
        if (e) {
            float weight[8];
            hit_weights_finish(e, hb->tap[i], hb->texel[i], hb->weight[i], hb->distance[i], hb->front[i], weight);
            cell_sum(e, hb->slot[i], weight, bounce);
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
            if (*pending >> HIT_CELL_NORMALS == batch) { /* a waiting hit reads this entry: finish those first */
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
            if (*pending >> HIT_CELL_NORMALS == batch && (*pending >> e->normal_next & 1)) { /* the slot is read */
                batch_bounce(hb, done, i);
                done = i;
                batch = ++memo->batch_id;
            }
            slot = cell_normal_compute(e, normal);
        }
        *pending = (*pending >> HIT_CELL_NORMALS == batch ? *pending : batch << HIT_CELL_NORMALS) | (1u << slot);
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
FXC_HOT_INLINE void hits_radiance(const fx_context *ctx, hit_batch *restrict hb, const struct RTCRayHit *hits,
                                  const hit_shading *hs, float (*values)[5])
{
    batch_bounce(hb, hb->done, hb->count);
    for (uint32_t i = 0; i < hb->count; i++) {
        uint32_t r = hb->ray[i];
        float albedo[3];
        scene_albedo_mean(ctx->s, hits[r].hit.primID, albedo); /* the triangle's mean (file comment) */
        for (int k = 0; k < 3; k++)
            values[r][k] = albedo[k] * (hs->direct[r][k] + hb->bounce[i][k] * (1.0f / FX_PROBE_PI));
    }
    hb->count = 0;
}

/* The gather's sums per texel, structure of arrays (update). */
typedef struct gather_sums {
    float r[FX_PROBE_TEXELS], g[FX_PROBE_TEXELS], b[FX_PROBE_TEXELS], w[FX_PROBE_TEXELS];
    float m1[FX_PROBE_TEXELS], m2[FX_PROBE_TEXELS], mw[FX_PROBE_TEXELS];
} gather_sums;

/* The rays of an update and their weights in the 64 texels. One rotation serves every probe updated in a
 * frame (RTXGI rotates its whole volume's rays once per update the same way): the directions, each ray's
 * cosine weight max(0, d_t.d_i) and moment lobe weight max(0, d_t.d_i)^FX_PROBE_DEPTH_POWER in every texel,
 * and their sums over the rays, are then computed once per frame and thread instead of once per probe; the
 * gather is left with the weighted sums of the probe's radiance and distances. Up to PROBE_TABLE_RAYS rays
 * the weights are kept for the frame; beyond that (probe_rays above the default) each chunk's rows are
 * computed again per probe into the first rows of the table, the same numbers. */
enum { PROBE_TABLE_RAYS = 256 };
_Static_assert((int)PROBE_TABLE_RAYS >= (int)PROBE_CHUNK && (int)PROBE_TABLE_RAYS % (int)PROBE_CHUNK == 0, "table rows");

typedef struct probe_directions {
    uint64_t h1, h2; /* the hashes the rotation came from, seed included (valid when rays != 0) */
    uint32_t rays;         /* 0: none yet */
    float dir[FX_PROBE_MAX_RAYS][3];
    _Alignas(64) float cosine[PROBE_TABLE_RAYS][FX_PROBE_TEXELS];
    _Alignas(64) float lobe[PROBE_TABLE_RAYS][FX_PROBE_TEXELS];
    float cosine_sum[FX_PROBE_TEXELS], lobe_sum[FX_PROBE_TEXELS]; /* over all rays (table or not) */
} probe_directions;

/* Rows [first, first + n) of the weights into rows [row, row + n) of the table; adds them to the sums when
 * `sum`. Each texel's sum runs in ray order. */
FXC_HOT_CLONES static void direction_weights(probe_directions *restrict pd, uint32_t first, uint32_t n, uint32_t row,
                                             bool sum)
{
    float dirs[FX_PROBE_TEXELS][3], dir_x[FX_PROBE_TEXELS], dir_y[FX_PROBE_TEXELS], dir_z[FX_PROBE_TEXELS];
    fx__probe_texel_dirs(dirs);
    for (uint32_t tx = 0; tx < FX_PROBE_TEXELS; tx++)
        dir_x[tx] = dirs[tx][0], dir_y[tx] = dirs[tx][1], dir_z[tx] = dirs[tx][2];
    for (uint32_t r = 0; r < n; r++) {
        float rx = pd->dir[first + r][0], ry = pd->dir[first + r][1], rz = pd->dir[first + r][2];
        float *restrict cosine = pd->cosine[row + r], *restrict lobe = pd->lobe[row + r];
        for (uint32_t tx = 0; tx < FX_PROBE_TEXELS; tx++) {
            float c = dir_x[tx] * rx + dir_y[tx] * ry + dir_z[tx] * rz;
            /* max(c, 0) on the bits (negative floats have the sign bit: cleared to +0), so it vectorises */
            uint32_t bits;
            memcpy(&bits, &c, sizeof bits);
            bits &= (bits >> 31) - 1u; /* sign set: mask 0; clear: all ones */
            memcpy(&c, &bits, sizeof c);
            float c2 = c * c, c4 = c2 * c2, c8 = c4 * c4, c16 = c8 * c8, c32 = c16 * c16; /* c^64 below */
            cosine[tx] = c;
            lobe[tx] = c32 * c32;
        }
        if (sum)
            for (uint32_t tx = 0; tx < FX_PROBE_TEXELS; tx++) {
                pd->cosine_sum[tx] += cosine[tx];
                pd->lobe_sum[tx] += lobe[tx];
            }
    }
}

/* The frame's rays for `rays` rays per probe (the rotation from the hashes h1, h2 of the seed and the rotation
 * key), unless the table holds them. The table is kept per thread: it is keyed by the hashes, not the rotation
 * key alone, so a loop with another seed on the same thread (the stability suite's seed pairs, the tests)
 * never reads another seed's rays. */
static void directions_prepare(probe_directions *pd, uint32_t rays, uint64_t h1, uint64_t h2)
{
    if (pd->rays == rays && pd->h1 == h1 && pd->h2 == h2)
        return;
    float rotation[9];
    random_rotation(h1, h2, rotation);
    for (uint32_t i = 0; i < rays; i++) {
        float fib[3];
        fx_probe_fibonacci(i, rays, fib);
        for (int k = 0; k < 3; k++)
            pd->dir[i][k] = rotation[3 * k] * fib[0] + rotation[3 * k + 1] * fib[1] + rotation[3 * k + 2] * fib[2];
    }
    memset(pd->cosine_sum, 0, sizeof pd->cosine_sum);
    memset(pd->lobe_sum, 0, sizeof pd->lobe_sum);
    for (uint32_t first = 0; first < rays; first += PROBE_CHUNK) {
        uint32_t n = rays - first < PROBE_CHUNK ? rays - first : PROBE_CHUNK;
        /* Beyond the table only the sums are kept (the rows land in the first chunk's, overwritten). */
        direction_weights(pd, first, n, rays <= PROBE_TABLE_RAYS ? first : 0, true);
    }
    pd->rays = rays;
    pd->h1 = h1;
    pd->h2 = h2;
}

/* The weighted sums of a chunk of n rays (radiance RGB, distance and squared distance in cells, per ray)
 * into the texels: every ray adds its weight row times its values, in ray order. With GCC's vector types the
 * texels go in blocks of 16, the rays inside: a block's five sums (10 AVX2 registers) stay in registers over
 * the chunk's rays instead of being loaded and stored once per ray (64 texels x 5 sums do not fit the 16
 * registers; written as plain arrays GCC keeps them on the stack). The same products and sums in the same
 * order per texel: the same floats. */
#if defined(__GNUC__)
typedef float gather_v8 __attribute__((vector_size(32)));

/* A vector of 8 floats from p (any alignment); a macro: a function returning an AVX vector changes the ABI. */
#define GATHER_LOAD(v, p) memcpy(&(v), (p), sizeof(v))

FXC_HOT_CLONES static void gather_chunk(const probe_directions *restrict pd, uint32_t row, uint32_t n,
                                        const float (*restrict values)[5], gather_sums *restrict acc)
{
    for (uint32_t t0 = 0; t0 < FX_PROBE_TEXELS; t0 += 16) {
        gather_v8 r0, r1, g0, g1, b0, b1, m0, m1, q0, q1;
        GATHER_LOAD(r0, acc->r + t0), GATHER_LOAD(r1, acc->r + t0 + 8);
        GATHER_LOAD(g0, acc->g + t0), GATHER_LOAD(g1, acc->g + t0 + 8);
        GATHER_LOAD(b0, acc->b + t0), GATHER_LOAD(b1, acc->b + t0 + 8);
        GATHER_LOAD(m0, acc->m1 + t0), GATHER_LOAD(m1, acc->m1 + t0 + 8);
        GATHER_LOAD(q0, acc->m2 + t0), GATHER_LOAD(q1, acc->m2 + t0 + 8);
        for (uint32_t ray = 0; ray < n; ray++) {
            const float *cosine = pd->cosine[row + ray] + t0, *lobe = pd->lobe[row + ray] + t0;
            const float *v = values[ray];
            gather_v8 c0, c1, w0, w1;
            GATHER_LOAD(c0, cosine), GATHER_LOAD(c1, cosine + 8);
            r0 += c0 * v[0], r1 += c1 * v[0];
            g0 += c0 * v[1], g1 += c1 * v[1];
            b0 += c0 * v[2], b1 += c1 * v[2];
            GATHER_LOAD(w0, lobe), GATHER_LOAD(w1, lobe + 8);
            m0 += w0 * v[3], m1 += w1 * v[3];
            q0 += w0 * v[4], q1 += w1 * v[4];
        }
        memcpy(acc->r + t0, &r0, sizeof r0), memcpy(acc->r + t0 + 8, &r1, sizeof r1);
        memcpy(acc->g + t0, &g0, sizeof g0), memcpy(acc->g + t0 + 8, &g1, sizeof g1);
        memcpy(acc->b + t0, &b0, sizeof b0), memcpy(acc->b + t0 + 8, &b1, sizeof b1);
        memcpy(acc->m1 + t0, &m0, sizeof m0), memcpy(acc->m1 + t0 + 8, &m1, sizeof m1);
        memcpy(acc->m2 + t0, &q0, sizeof q0), memcpy(acc->m2 + t0 + 8, &q1, sizeof q1);
    }
}
#else
static void gather_chunk(const probe_directions *restrict pd, uint32_t row, uint32_t n,
                         const float (*restrict values)[5], gather_sums *restrict acc)
{
    for (uint32_t r = 0; r < n; r++) {
        const float *restrict cosine = pd->cosine[row + r], *restrict lobe = pd->lobe[row + r];
        float lr = values[r][0], lg = values[r][1], lb = values[r][2], d = values[r][3], dd = values[r][4];
        for (uint32_t tx = 0; tx < FX_PROBE_TEXELS; tx++) {
            float c = cosine[tx], w = lobe[tx];
            acc->r[tx] += c * lr;
            acc->g[tx] += c * lg;
            acc->b[tx] += c * lb;
            acc->m1[tx] += w * d;
            acc->m2[tx] += w * dd;
        }
    }
}
#endif
_Static_assert(FX_PROBE_TEXELS % 16 == 0, "gather blocks");

/* Per-thread working memory of update, commit and eval (each uses it within one call only). */
static _Thread_local hit_shading thread_hit_shading;
static _Thread_local probe_scratch thread_scratch;
static _Thread_local probe_directions thread_directions; /* 180 KB: the frame's rays and weights */

FXC_HOT_CLONES uint64_t fx_probes_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count)
{
    const scene *s = ctx->s;
    const uint32_t rays = ray_count(ctx);
    gather_sums sums, *acc = &sums;
    float sky[3];
    for (int k = 0; k < 3; k++)
        sky[k] = s->sky_color[k] * s->sky_intensity;
    struct RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCScene rtc = (RTCScene)scene_rt_handle(ctx->rt);
    _Alignas(64) struct RTCRayHit hits[PROBE_CHUNK];
    float values[PROBE_CHUNK][5]; /* per ray: radiance RGB, distance and its square (cells) */
    hit_shading *hs = &thread_hit_shading; /* 20 KB: off the (pool thread) stack, never allocated */
    probe_scratch *out = &thread_scratch;
    probe_directions *pd = &thread_directions;
    const bool table = rays <= PROBE_TABLE_RAYS;
    uint64_t traced = 0;
    fixed_lights lights;
    fixed_lights_init(s, &lights);
    if (ctx->world_cell)
        hit_cells_begin(ctx);
    /* The front-face hits' bounce in passes (hit_batch) with the heap memo, else one at a time. */
    hit_memo *memo = ctx->world_cell && fx__probe_hits_batched ? thread_hit_memo : NULL;
    const bool batch = memo != NULL;
    if (memo)
        memo->batch.count = 0;

    for (uint32_t j = 0; j < count; j++) {
        const fx_block_job *job = &jobs[j];
        FX_ASSERT(job->scratch != NULL && job->cell > 0);
        const uint8_t *payload = job->payload;
        uint32_t flags = get_u32(payload + 16), updates = get_u32(payload + 20);
        float cell = job->cell, origin[3], offset[3];
        const double inverse = cell_inverse(cell);
        for (int k = 0; k < 3; k++) {
            origin[k] = (flags & FX_PROBE_HAS_DATA) ? get_f32(payload + 4 * k) : job->origin[k];
            offset[k] = origin[k] - job->origin[k];
            if (!isfinite(offset[k]) || fabsf(offset[k]) > FX_PROBE_MAX_OFFSET * cell * 1.001f) {
                origin[k] = job->origin[k]; /* a stale or foreign payload: start from the grid point */
                offset[k] = 0;
            }
        }
        /* The frame's rotation (every probe of the frame shares it); without a frame number (ctx->frame 0),
         * one per update count, so successive updates of a probe still turn. */
        uint64_t rotation_key = ctx->frame ? ((uint64_t)1 << 63) | ctx->frame : updates;
        directions_prepare(pd, rays,
                           fx__hash(ctx->seed, rotation_key, 0, 0, FX_STREAM_PROBE_ROTATION),
                           fx__hash(ctx->seed, rotation_key, 1, 0, FX_STREAM_PROBE_ROTATION));
        memset(out, 0, sizeof *out);
        memset(acc, 0, sizeof *acc);
        uint32_t backfaces = 0;
        float closest_front = INFINITY, closest_back = INFINITY, front_dir[3] = {0, 0, 0}, back_dir[3] = {0, 0, 0};
        const float max_distance = FX_PROBE_MAX_DISTANCE * cell;

        for (uint32_t first = 0; first < rays; first += PROBE_CHUNK) {
            uint32_t n = rays - first < PROBE_CHUNK ? rays - first : PROBE_CHUNK;
            for (uint32_t r = 0; r < n; r++) {
                struct RTCRayHit *rh = &hits[r];
                fx__set_ray(&rh->ray, origin, pd->dir[first + r], INFINITY, r);
                rh->hit.geomID = RTC_INVALID_GEOMETRY_ID;
                rh->hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
            }
            if (ctx->observe_hits) /* benchmarks replay exactly these rays against raw Embree */
                ctx->observe_hits(ctx->observe_user, hits, n);
            rtcIntersect1M(rtc, &context, hits, n, sizeof(struct RTCRayHit));
            traced += n;

            /* Shadow rays of the front-face hits. */
            hs->count = 0;
            float hit_pos[PROBE_CHUNK][3];
            for (uint32_t r = 0; r < n; r++) {
                hs->direct[r][0] = hs->direct[r][1] = hs->direct[r][2] = 0;
                const struct RTCRayHit *rh = &hits[r];
                if (rh->hit.geomID == RTC_INVALID_GEOMETRY_ID || rh->hit.primID >= s->triangle_count)
                    continue;
                const float *normal = s->tri_normal + 3 * (size_t)rh->hit.primID;
                const float *dir = pd->dir[first + r];
                if (!(fx__dot(dir, normal) < 0))
                    continue; /* back face */
                float p[3];
                for (int k = 0; k < 3; k++)
                    p[k] = origin[k] + rh->ray.tfar * dir[k];
                scene_offset_ray_origin_inline(p, normal, s->ray_offset_scale, hit_pos[r]);
                traced += queue_shadow_rays(ctx, batch ? &lights : NULL, hs, r, hit_pos[r], normal);
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
                const float *dir = pd->dir[first + r];
                float radiance[3], distance;
                if (rh->hit.geomID == RTC_INVALID_GEOMETRY_ID || rh->hit.primID >= s->triangle_count) {
                    memcpy(radiance, sky, sizeof radiance);
                    distance = max_distance;
                } else {
                    const float *normal = s->tri_normal + 3 * (size_t)rh->hit.primID;
                    float t = rh->ray.tfar;
                    if (!(fx__dot(dir, normal) < 0)) {
                        backfaces++;
                        radiance[0] = radiance[1] = radiance[2] = 0;
                        distance = FX_PROBE_BACKFACE_SHORTEN * t;
                        if (t < closest_back) {
                            closest_back = t;
                            memcpy(back_dir, dir, sizeof back_dir);
                        }
                    } else {
                        if (batch) { /* radiance from hits_radiance below */
                            radiance[0] = radiance[1] = radiance[2] = 0;
                        } else {
                            hit_radiance(ctx, job, inverse, rh->hit.primID, rh->hit.u, rh->hit.v, t, hit_pos[r],
                                         normal, hs->direct[r], radiance);
                        }
                        distance = t;
                        if (t < closest_front) {
                            closest_front = t;
                            memcpy(front_dir, dir, sizeof front_dir);
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
                hits_radiance(ctx, &memo->batch, hits, hs, values);
            /* Into the texels (file comment): the weight rows of these rays, from the table or computed. */
            if (!table)
                direction_weights(pd, first, n, 0, false);
            gather_chunk(pd, table ? first : 0, n, (const float(*)[5])values, acc);
        }
        for (uint32_t tx = 0; tx < FX_PROBE_TEXELS; tx++) {
            out->irradiance[tx][0] = acc->r[tx];
            out->irradiance[tx][1] = acc->g[tx];
            out->irradiance[tx][2] = acc->b[tx];
            out->irradiance_weight[tx] = pd->cosine_sum[tx];
            out->moments[tx][0] = acc->m1[tx];
            out->moments[tx][1] = acc->m2[tx];
            out->moment_weight[tx] = pd->lobe_sum[tx];
        }
        for (uint32_t tx = 0; tx < FX_PROBE_TEXELS; tx++) {
            if (out->irradiance_weight[tx] > 0)
                for (int k = 0; k < 3; k++)
                    out->irradiance[tx][k] =
                        min_of(FX_PROBE_PI * out->irradiance[tx][k] / out->irradiance_weight[tx], FLT_MAX);
            if (out->moment_weight[tx] > 0) {
                out->moments[tx][0] /= out->moment_weight[tx];
                out->moments[tx][1] /= out->moment_weight[tx];
            }
        }

        /* Off and relocation (file comment). */
        out->backface_fraction = (float)backfaces / (float)rays;
        /* Inside: too many back faces, or back faces within reach of its cells (the cell diagonal) and no
         * front face there: every surface it could light is seen from behind (outside a closed room). */
        float reach = 1.7320508f * cell;
        bool seen_front = closest_front <= reach || (flags & FX_PROBE_SEEN_FRONT);
        out->off = out->backface_fraction > FX_PROBE_BACKFACE_OFF || (closest_back <= reach && !seen_front);
        float min_front = FX_PROBE_MIN_FRONT * cell, limit = FX_PROBE_MAX_OFFSET * cell, next[3];
        memcpy(next, offset, sizeof next);
        out->moved_out = (flags & FX_PROBE_MOVED_OUT) ? 1u : 0u;
        if (out->off && isfinite(closest_back)) {
            float moved = 0;
            for (int k = 0; k < 3; k++) {
                next[k] = fminf(fmaxf(next[k] + back_dir[k] * (closest_back + 0.5f * min_front), -limit), limit);
                moved += (next[k] - offset[k]) * back_dir[k];
            }
            /* Through the face only if the clamp leaves it at least a quarter of the margin beyond it; else it
             * stays where it is, off (moved part way it would sit on the surface, on and off at random). */
            if (moved >= closest_back + 0.25f * min_front)
                out->moved_out = 1;
            else
                memcpy(next, offset, sizeof next);
        } else if (closest_front < min_front) {
            for (int k = 0; k < 3; k++)
                next[k] -= front_dir[k] * (min_front - closest_front);
        } else if (!out->moved_out) {
            float length = sqrtf(fx__dot(offset, offset));
            float back = fminf(closest_front - min_front, length);
            if (length > 0 && back > 0)
                for (int k = 0; k < 3; k++)
                    next[k] -= offset[k] / length * back;
        }
        bool moved = false;
        for (int k = 0; k < 3; k++) {
            next[k] = fminf(fmaxf(next[k], -limit), limit);
            out->position[k] = job->origin[k] + next[k];
            moved |= out->position[k] != origin[k];
        }
        out->seen_front = seen_front && !moved;
        out->valid = 1;
        memcpy(job->scratch, out, sizeof *out);
    }

    return traced;
}

FXC_HOT_CLONES void fx_probes_commit(const fx_context *ctx, const fx_block_job *jobs, uint32_t count)
{
    float h = ctx->probe_hysteresis;
    if (h == 0.0f)
        h = FX_PROBE_HYSTERESIS;
    h = isnan(h) ? FX_PROBE_HYSTERESIS : fminf(fmaxf(h, 0.0f), 0.999f);
    probe_scratch *in = &thread_scratch;
    for (uint32_t j = 0; j < count; j++) {
        const fx_block_job *job = &jobs[j];
        FX_ASSERT(job->scratch != NULL);
        memcpy(in, job->scratch, sizeof *in);
        if (!in->valid)
            continue;
        uint8_t *p = job->payload;
        uint32_t flags = get_u32(p + 16), updates = get_u32(p + 20);
        bool fresh = !(flags & FX_PROBE_HAS_DATA) || updates == 0;
        for (int k = 0; k < 3; k++)
            put_f32(p + 4 * k, in->position[k]);
        put_f32(p + 12, job->cell);
        put_f32(p + 28, in->backface_fraction);
        if (in->off) { /* the maps stay as they were; the next update after it is on again starts afresh */
            if (!(flags & FX_PROBE_HAS_DATA))
                put_f32(p + 24, 0.0f);
            put_u32(p + 16, FX_PROBE_HAS_DATA | FX_PROBE_OFF | (in->moved_out ? FX_PROBE_MOVED_OUT : 0u) |
                                (in->seen_front ? FX_PROBE_SEEN_FRONT : 0u));
            put_u32(p + 20, 0);
            continue;
        }
        /* Flat loops over the 192 irradiance halves and the 128 moment halves (texel t's component k at
         * 3t + k and 2t + k, as in the payload: byte 2 x (3t + k), 2 x (2t + k)), written with selects so
         * the AVX2 copy runs them 8 wide; per half the same operations in the same order as one texel at a
         * time, and the maximum (exact in any order: no NaN, no -0) in 8 partial maxima. */
        enum { IRRADIANCE_HALVES = 3 * FX_PROBE_TEXELS, MOMENT_HALVES = 2 * FX_PROBE_TEXELS };
        float old_scale = fresh ? 0.0f : get_f32(p + 24), irradiance[IRRADIANCE_HALVES], moments[MOMENT_HALVES];
        float irradiance_weight[IRRADIANCE_HALVES], moment_weight[MOMENT_HALVES];
        for (uint32_t t = 0; t < FX_PROBE_TEXELS; t++) {
            for (int k = 0; k < 3; k++)
                irradiance_weight[3 * t + k] = in->irradiance_weight[t];
            for (int k = 0; k < 2; k++)
                moment_weight[2 * t + k] = in->moment_weight[t];
        }
        const float *new_irradiance = &in->irradiance[0][0], *new_moments = &in->moments[0][0];
        /* keep x old + take x new: h x old + (1 - h) x new as before, or 0 + new when fresh (old is 0 then: the
         * same value, a new -0 becoming +0, which the clamp below and halves_stochastic turn into 0 anyway) */
        const float keep = fresh ? 0.0f : h, take = fresh ? 1.0f : 1.0f - h;
        const float old_factor = fresh ? 0.0f : 1.0f, initial_factor = fresh ? 1.0f : 0.0f;
        uint16_t old_irradiance[IRRADIANCE_HALVES], old_moments[MOMENT_HALVES]; /* the payload's, read once */
        for (uint32_t i = 0; i < IRRADIANCE_HALVES; i++)
            old_irradiance[i] = fx__get_u16(p + PROBE_IRRADIANCE + 2 * i);
        for (uint32_t i = 0; i < MOMENT_HALVES; i++)
            old_moments[i] = fx__get_u16(p + PROBE_MOMENTS + 2 * i);
        for (uint32_t i = 0; i < IRRADIANCE_HALVES; i++) {
            /* payload halves are halves_stochastic's: finite and >= 0 */
            float old = old_scale * half_bits_to_float(old_irradiance[i]);
            float blended = keep * old + take * new_irradiance[i];
            float value = irradiance_weight[i] > 0 ? blended : old;
            value = value > 0 ? value : 0.0f;                 /* <= 0, -inf and NaN: 0 */
            irradiance[i] = value <= FLT_MAX ? value : FLT_MAX; /* +inf: the largest float */
        }
        float partial[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        for (uint32_t i = 0; i < IRRADIANCE_HALVES; i += 8)
            for (uint32_t l = 0; l < 8; l++)
                partial[l] = irradiance[i + l] > partial[l] ? irradiance[i + l] : partial[l];
        float scale = 0;
        for (uint32_t l = 0; l < 8; l++)
            scale = partial[l] > scale ? partial[l] : scale;
        for (uint32_t i = 0; i < MOMENT_HALVES; i++) {
            /* fresh: old 0 and the unseen texels' start (FX_PROBE_MAX_DISTANCE, its square); else old (x 1, + 0) */
            float old = old_factor * half_bits_to_float(old_moments[i]);
            float blended = keep * old + take * new_moments[i];
            float initial = (i & 1) ? FX_PROBE_MAX_DISTANCE * FX_PROBE_MAX_DISTANCE : FX_PROBE_MAX_DISTANCE;
            moments[i] = moment_weight[i] > 0 ? blended : old + initial_factor * initial;
        }
        put_f32(p + 24, scale);
        float inv = scale > 0 ? 1.0f / scale : 0.0f;
        /* Per texel one hash, 12 bits of it per half (RGB, then the two moments), as halves_stochastic's u. */
        float relative[IRRADIANCE_HALVES], u_irradiance[IRRADIANCE_HALVES], u_moments[MOMENT_HALVES];
        uint16_t halves_irradiance[IRRADIANCE_HALVES], halves_moments[MOMENT_HALVES];
        for (uint32_t t = 0; t < FX_PROBE_TEXELS; t++) {
            uint64_t bits = fx__hash(ctx->seed, job->key, t, updates, FX_STREAM_PROBE_ROUNDING);
            u_irradiance[3 * t + 0] = (float)(uint32_t)(bits & 0xfffu) * (1.0f / 4096.0f);
            u_irradiance[3 * t + 1] = (float)(uint32_t)((bits >> 12) & 0xfffu) * (1.0f / 4096.0f);
            u_irradiance[3 * t + 2] = (float)(uint32_t)((bits >> 24) & 0xfffu) * (1.0f / 4096.0f);
            u_moments[2 * t + 0] = (float)(uint32_t)((bits >> 36) & 0xfffu) * (1.0f / 4096.0f);
            u_moments[2 * t + 1] = (float)(uint32_t)((bits >> 48) & 0xfffu) * (1.0f / 4096.0f);
        }
        for (uint32_t i = 0; i < IRRADIANCE_HALVES; i++)
            relative[i] = min_of(irradiance[i] * inv, 1.0f);
        halves_stochastic(relative, u_irradiance, IRRADIANCE_HALVES, halves_irradiance);
        halves_stochastic(moments, u_moments, MOMENT_HALVES, halves_moments);
        for (uint32_t i = 0; i < IRRADIANCE_HALVES; i++)
            fx__put_u16(p + PROBE_IRRADIANCE + 2 * i, halves_irradiance[i]);
        for (uint32_t i = 0; i < MOMENT_HALVES; i++)
            fx__put_u16(p + PROBE_MOMENTS + 2 * i, halves_moments[i]);
        put_u32(p + 16, FX_PROBE_HAS_DATA | (in->moved_out ? FX_PROBE_MOVED_OUT : 0u) |
                            (in->seen_front ? FX_PROBE_SEEN_FRONT : 0u));
        put_u32(p + 20, updates < UINT32_MAX ? updates + 1 : UINT32_MAX);
    }
}

/* ---- the no-cache baseline --------------------------------------------------------------------------- */

void fx_probe_eval_point(const fx_context *ctx, const float pos[3], const float normal[3], uint64_t pixel_id,
                         float out_rgb[3], uint64_t *rays)
{
    const scene *s = ctx->s;
    const uint32_t n_rays = ray_count(ctx);
    float sky[3];
    for (int k = 0; k < 3; k++)
        sky[k] = s->sky_color[k] * s->sky_intensity;
    fx__surface_map map;
    float point[3], origin[3], tangent[3], bitangent[3];
    fx__locate_point(ctx, pos, normal, 0.0f, &map, point); /* off a crease's wall */
    scene_offset_ray_origin(point, normal, s->ray_offset_scale, origin);
    fx__onb(normal, tangent, bitangent);
    uint64_t direction_hash = fx__hash(ctx->seed, pixel_id, 0, 0, FX_STREAM_PROBE_EVAL);
    struct RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCScene rtc = (RTCScene)scene_rt_handle(ctx->rt);
    _Alignas(64) struct RTCRayHit hits[PROBE_CHUNK];
    hit_shading *hs = &thread_hit_shading;
    double sum[3] = {0, 0, 0};
    uint64_t traced = 0;
    for (uint32_t first = 0; first < n_rays; first += PROBE_CHUNK) {
        uint32_t n = n_rays - first < PROBE_CHUNK ? n_rays - first : PROBE_CHUNK;
        for (uint32_t r = 0; r < n; r++) {
            float xi[2], dir[3];
            fx__sobol_2d(first + r, direction_hash, xi);
            fx__cosine_direction(normal, tangent, bitangent, xi, dir);
            fx__set_ray(&hits[r].ray, origin, dir, INFINITY, r);
            hits[r].hit.geomID = RTC_INVALID_GEOMETRY_ID;
            hits[r].hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        }
        if (ctx->observe_hits)
            ctx->observe_hits(ctx->observe_user, hits, n);
        rtcIntersect1M(rtc, &context, hits, n, sizeof(struct RTCRayHit));
        traced += n;
        hs->count = 0;
        float hit_pos[PROBE_CHUNK][3];
        bool front[PROBE_CHUNK];
        for (uint32_t r = 0; r < n; r++) {
            hs->direct[r][0] = hs->direct[r][1] = hs->direct[r][2] = 0;
            front[r] = false;
            if (hits[r].hit.geomID == RTC_INVALID_GEOMETRY_ID || hits[r].hit.primID >= s->triangle_count) {
                for (int k = 0; k < 3; k++)
                    sum[k] += sky[k];
                continue;
            }
            const float *n_hit = s->tri_normal + 3 * (size_t)hits[r].hit.primID;
            float dir[3] = {hits[r].ray.dir_x, hits[r].ray.dir_y, hits[r].ray.dir_z};
            if (!(fx__dot(dir, n_hit) < 0))
                continue; /* back face: no light, as for the probes */
            front[r] = true;
            float p[3];
            for (int k = 0; k < 3; k++)
                p[k] = origin[k] + hits[r].ray.tfar * dir[k];
            scene_offset_ray_origin(p, n_hit, s->ray_offset_scale, hit_pos[r]);
            traced += queue_shadow_rays(ctx, NULL, hs, r, hit_pos[r], n_hit);
        }
        shadow_flush(ctx, hs);
        for (uint32_t r = 0; r < n; r++) {
            if (!front[r])
                continue;
            float albedo[3];
            scene_albedo_filtered(s, hits[r].hit.primID, hits[r].hit.u, hits[r].hit.v,
                                  log2f(fmaxf(hits[r].ray.tfar * 0.3f, 1e-30f)), albedo);
            for (int k = 0; k < 3; k++)
                sum[k] += (double)albedo[k] * hs->direct[r][k];
        }
    }
    /* Cosine-weighted sampling: E = pi x the mean radiance. */
    for (int k = 0; k < 3; k++)
        out_rgb[k] = (float)fmin(FX_PROBE_PI * sum[k] / (double)n_rays, FLT_MAX);
    if (rays)
        *rays = traced;
}

/* ---- the effect table ------------------------------------------------------------------------------- */

static uint32_t probes_texel_bytes(const scene *s)
{
    (void)s;
    return FX_PROBE_BYTES;
}

static bool probes_needs(const scene *s, char *why, size_t why_cap)
{
    return fx__scene_needs(s, SCENE_FX_PROBES, why, why_cap);
}

/* Rays of one probe update: `samples` rays when the caller passes probe_rays there, else the default; each
 * may hit a front face and send one shadow ray per light. */
static uint64_t probes_cost(const scene *s, uint32_t samples)
{
    uint64_t rays = samples ? (samples > FX_PROBE_MAX_RAYS ? FX_PROBE_MAX_RAYS : samples) : FX_PROBE_RAYS;
    return rays * (1u + (uint64_t)s->light_count);
}

static uint64_t probes_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count, uint32_t samples)
{
    (void)samples;
    return fx_probes_update(ctx, jobs, count);
}

static uint32_t probes_texel_samples(const void *texel)
{
    return get_u32((const uint8_t *)texel + 20);
}

static uint32_t probes_scratch_bytes(const scene *s)
{
    (void)s;
    return (uint32_t)sizeof(probe_scratch);
}

static void probes_commit(const fx_context *ctx, const fx_block_job *jobs, uint32_t count)
{
    fx_probes_commit(ctx, jobs, count);
}

static uint64_t probes_eval(const fx_context *ctx, const fx_point *point, fx_shade_point *out)
{
    uint64_t rays = 0;
    float e[3];
    fx_probe_eval_point(ctx, point->position, point->view_normal, point->pixel_id, e, &rays);
    float open = *out->sky_visibility * (1.0f / FX_PROBE_PI);
    for (int k = 0; k < 3; k++)
        out->indirect[k] += e[k] * open;
    if (out->sky_open)
        *out->sky_open = *out->sky_visibility;
    *out->sky_visibility = 0.0f;
    return rays;
}

/* The reference: the same term with E from path tracing (every bounce, not one) instead of one bounce of
 * probe_rays rays; the probes' rule for the sky (E carries it, scaled by what AO left) is the same. */
static uint64_t probes_reference(const fx_context *ctx, const fx_point *point, uint32_t samples,
                                 fx_shade_point *out)
{
    uint64_t rays = 0;
    float e[3];
    fx_indirect_reference_point(ctx, point->position, point->view_normal, samples, point->pixel_id, e, &rays);
    float open = *out->sky_visibility;
    for (int k = 0; k < 3; k++)
        out->indirect[k] += fminf(e[k] * open * (1.0f / FX_PROBE_PI), FLT_MAX);
    if (out->sky_open)
        *out->sky_open = open;
    *out->sky_visibility = 0.0f;
    return rays;
}

/* Probes: DDGI-style irradiance and visibility per grid point, updated continuously with hysteresis. */
const fx_effect fx_effect_probes = {
    .name = "probes",
    .alias = "indirect",
    .cache = SCENE_CACHE_WORLD_SPACE,
    .level_bias = 0,
    .filter = FX_FILTER_TRILINEAR,
    .policy = FX_UPDATE_CONTINUOUS,
    /* Converged after 64 blended updates (the first value's weight 0.97^63 = 0.15 by then): the engine then
     * refreshes the probe only every few frames, spending the budget on younger ones. */
    .max_samples = 64,
    .texel_bytes = probes_texel_bytes,
    .needs = probes_needs,
    .cost = probes_cost,
    .update = probes_update,
    .texel_samples = probes_texel_samples,
    .brick_size = 1,
    .scratch_bytes = probes_scratch_bytes,
    .commit = probes_commit,
    .shade = fx__probes_shade,
    .low_frequency = true,
    .eval = probes_eval,
    .reference = probes_reference,
    .reference_samples = 256, /* paths per pixel: see docs/ARCHITECTURE.md, "The reference renderer" */
    .reference_unit = "paths",
};
