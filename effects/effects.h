/* effects: what is computed into the on-surface cache, one small interface per effect (DESIGN.md
 * "Effects"): triangle lookup (itself cached, used by every other effect), hard shadows and ambient
 * occlusion. Each effect names its cache, its bytes per texel, its default level bias, its filter and its
 * update policy; updates work on batches of queued blocks (never a function pointer per texel), and the
 * sample functions decode one texel for compositing. The same rays, evaluated per pixel instead of per
 * texel, give the no-cache baseline (fx_*_eval_point).
 *
 * Effect ids are the on-surface cache key's effect field and equal scene_effect's numbering.
 * Determinism: every random number comes from a hash of (seed, block key, texel, sample index), never from
 * a per-thread state, so any thread split gives identical results. */
#ifndef FXC_EFFECTS_H
#define FXC_EFFECTS_H

#include "scene.h"

#include <float.h>
#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

enum {
    FX_TRI_LOOKUP = SCENE_FX_TRIANGLE_LOOKUP, /* 0 */
    FX_SHADOW = SCENE_FX_SHADOW,              /* 1 */
    FX_AO = SCENE_FX_AO,                      /* 2 */
    FX_PROBES = SCENE_FX_PROBES,              /* 3: the effect id world_taps is called with for probes */
    FX_SHADOW_RAYS = 16,                      /* rays per texel and light (default; fx_context.shadow_rays) */
    FX_AO_MAX_SAMPLES = 64,                   /* AO converges here (default; fx_context.ao_samples) */
    FX_AO_SAMPLES_LIMIT = 4096,               /* most AO samples a texel may converge at: the payload's uint16
                                                 count holds it, and its unorm16 mean still gives back the exact
                                                 number of unoccluded rays (count < 65535) */
    FX_SHADOW_TEXEL_RAYS_MAX = 16,            /* most shadow rays per texel and light: one bit per cell of the
                                                 texel's 4 x 4 mask */
    FX_SHADOW_POINT_RAYS_MAX = 256,           /* most shadow rays per pixel and light in the no-cache baseline
                                                 (sets of 16 above 16) */
};

typedef enum fx_filter { FX_FILTER_POINT = 0, FX_FILTER_BILINEAR, FX_FILTER_TRILINEAR } fx_filter;
typedef enum fx_policy { FX_UPDATE_ONCE = 0, FX_UPDATE_PROGRESSIVE, FX_UPDATE_CONTINUOUS } fx_policy;

/* ---- triangle lookup -------------------------------------------------------------------------------- */

/* A lookup texel, 32 bits: bits 0..7 the triangle's index inside its island, bits 8..19 and 20..31 the
 * barycentrics (u, v) of corners 1 and 2 quantized to 12 bits (u + v <= 1). Texel centres outside every
 * triangle of the island take the nearest triangle and the barycentrics of the closest point on it. */
uint32_t fx_lookup_pack(uint32_t tri_local, float u, float v);
void fx_lookup_unpack(uint32_t texel, uint32_t *tri_local, float *u, float *v);

/* Fills texels[y*8+x] for every set bit of mask in block (block_x, block_y) of island at level: the texel
 * centre ((block_x*8 + x + 0.5) * 2^level, ...) in level-0 island UV is located in the island's triangles. */
void fx_lookup_update(const scene *s, uint32_t island, uint32_t level, uint32_t block_x, uint32_t block_y,
                      uint64_t mask, uint32_t texels[64]);

/* ---- updates over queued blocks ------------------------------------------------------------------------ */

struct fx_taps;

/* Shared, read-only state of an update. */
typedef struct fx_context {
    const scene *s;
    scene_rt *rt;
    uint32_t seed;   /* run seed */
    float ao_radius; /* metres (> 0) */
    /* Optional: called with every stream of occlusion rays (an array of `count` Embree RTCRay, 64-byte
     * aligned) just before it is traced, from the tracing thread; benchmarks use it to replay exactly the
     * rays an update traced. NULL: nothing is called. */
    void (*observe_rays)(void *user, const void *rays, uint32_t count);
    /* The same for streams of intersection rays (RTCRayHit, before tracing); NULL: nothing is called. */
    void (*observe_hits)(void *user, const void *rayhits, uint32_t count);
    void *observe_user;
    /* World-space effects (probes). The filtered read of `effect` at a scene-local position on grid `level`:
     * the resident cells (probes) at the corners of the level's cell around it that hold committed data,
     * trilinear weights (not renormalised over missing corners; fx_taps.count 0: none). Reads only what the
     * last commit wrote, so it is safe from any thread during updates and the result does not depend on
     * the order updates run in. NULL: the loop has no world-space cache. */
    uint32_t (*world_taps)(const void *user, uint32_t effect, const float position[3], uint32_t level,
                           struct fx_taps *taps);
    /* Optional, beside world_taps (NULL: update hits use world_taps): the committed texels of the 8 corners
     * of the cell of `level` around `centre` (the caller passes a cell's centre, well inside it; corner c at
     * the cell's lowest grid point + cell size x (c & 1, c >> 1 & 1, c >> 2 & 1)), NULL where a corner holds
     * none. False (all NULL) outside the grid's range. The same contract as world_taps otherwise: committed
     * data only, read-only, any thread. Probe updates keep what it returns per thread for the frame (see
     * epoch), so a cell's 8 corners are looked up once, not once per ray that hits it. */
    bool (*world_cell)(const void *user, uint32_t effect, uint32_t level, const float centre[3],
                       const void *texel[8]);
    const void *world_user;
    uint64_t epoch;      /* unique per loop within the process (0: unknown). With frame it names the payloads'
                       state: memos that keep pointers into the cache are kept only while both are the same */
    uint32_t probe_rays; /* rays per probe update (default 144, DDGI's) */
    uint32_t frame;      /* the frame being run, + 1 (0: unknown). Cache payloads change only between
                               frames, so what is derived from them can be kept within one frame. */
    float probe_hysteresis; /* weight of the old irradiance in a probe update's blend (default 0.97, RTXGI's);
                             the change-aware blend's steady state */
    bool probe_plain_blend; /* true: plain hysteresis, probe_hysteresis at every update (false, the default:
                               the change-aware blend, fx_probes.c) */
    uint32_t reference_bounces; /* the reference's path tracing (fx_indirect_reference_point): bounces at most
                                   (0: until Russian roulette ends the path) */
    /* Run-time sample counts (0: the default). In a cached run they are what a texel converges at; in the
     * no-cache baseline they are the counts each pixel traces (srv_loop_desc.no_cache_samples scales them). */
    uint32_t ao_samples;  /* AO rays a texel converges at, 1..FX_AO_SAMPLES_LIMIT; the baseline's AO rays per
                             pixel (default FX_AO_MAX_SAMPLES) */
    uint32_t shadow_rays; /* shadow rays per texel and light: 1, 2, 4, 8 or 16 (strata of 1x1, 2x1, 2x2, 4x2,
                             4x4 cells of the texel, each ray setting the mask bits of its stratum); the
                             baseline's per pixel and light: those, or a multiple of 16 up to
                             FX_SHADOW_POINT_RAYS_MAX in sets of 16 (default FX_SHADOW_RAYS) */
} fx_context;

/* One queued block. payload and lookup point into the cache; the effect writes payload texels of mask. */
typedef struct fx_block_job {
    uint64_t key;                             /* the block's cache key (seeds the random numbers) */
    uint32_t island, level, block_x, block_y; /* island: its index in scene.islands (no side bit) */
    uint64_t mask;                            /* texels to update */
    const uint32_t *lookup; /* the block's 64 triangle-lookup texels (valid for every texel of mask) */
    void *payload;          /* 64 * texel_bytes (on-surface); brick_size^3 * texel_bytes (world-space) */
    /* World-space effects: the brick's first cell's grid point (its lowest corner) in scene-local metres,
     * the cell size of its level (level in `level`), and the job's scratch (the effect's scratch_bytes,
     * kept from update to commit within the frame; NULL when the effect asks for none). Cell c of the
     * brick (bit c of mask, c = (z * n + y) * n + x for brick size n) is the grid point origin + cell *
     * (x, y, z). */
    float origin[3];
    float cell;
    void *scratch;
    uint32_t effect; /* the effect's index in the loop's list (what ctx->world_taps takes) */
    /* On-surface: the block is of the island's back (its key's island field has SCENE_ISLAND_BACK): the
     * surface seen from behind its winding, so an effect's rays leave along the negated geometric normal.
     * (Last, in the struct's tail padding: a job is no larger for it.) */
    bool back;
} fx_block_job;

/* Hard shadows: for each texel of mask and each light, ctx->shadow_rays (default FX_SHADOW_RAYS) rays from
 * stratified jittered points
 * of the texel's footprint on the surface (kept a sixteenth of a texel inside the lookup triangle's edges,
 * so a texel at a crease never samples the wall's plane) towards the light; bit i set = ray i reached the
 * light. Stored
 * as uint16 per light: texel t, light l at payload bytes ((t * light_count) + l) * 2. Texels facing away
 * from a light store 0 for it without tracing. Call from any thread; uses Embree's stream API.
 * Returns the number of rays traced. */
uint64_t fx_shadow_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count);

/* The lit fraction (0..1) of one shadow texel for light l. */
float fx_shadow_sample(const void *payload, uint32_t texel, uint32_t light_count, uint32_t light);

/* Ambient occlusion: adds `samples` cosine-weighted rays of length ao_radius to each texel of mask (never
 * past ctx->ao_samples in all, default FX_AO_MAX_SAMPLES; at most FX_RAY_BATCH = 256 per texel and call),
 * keeping a running mean. Texel t: uint16 unoccluded fraction (unorm16)
 * then uint16 sample count, at payload bytes t * 4. Returns the number of rays traced. */
uint64_t fx_ao_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count, uint32_t samples);

/* AO texel decoding: unoccluded fraction (0..1) and sample count. */
float fx_ao_sample(const void *payload, uint32_t texel);
uint32_t fx_ao_count(const void *payload, uint32_t texel);

/* The world position and unit geometric normal of a point of island UV (level-0 texel units), found with
 * the triangle lookup texel `lookup` of the texel it lies in: barycentrics relative to that triangle,
 * clamped into it. */
void fx_surface_point(const scene *s, uint32_t island, uint32_t lookup, float island_u, float island_v,
                      float position[3], float normal[3]);

/* ---- the no-cache baseline: the same rays per pixel ------------------------------------------------- */

/* Lit fraction of light l at a visible point: FX_SHADOW_RAYS rays from pos + a*dpdx + b*dpdy for
 * stratified jittered (a, b) in [-0.5, 0.5]^2 (the pixel's footprint), seeded by (seed, pixel_id). pos is
 * first moved a rounding-safe distance inside the triangle it lies on (found by its position and normal), so
 * a pixel on a crease does not start on the wall; a jittered point outside that triangle is kept only if a
 * ray from pos reaches it past every surface, and is otherwise clamped into the triangle, so no ray starts on
 * or behind another surface. Returns the fraction; *rays receives the rays traced, those checks included
 * (0 when facing away). */
float fx_shadow_eval_point(const fx_context *ctx, const float pos[3], const float normal[3],
                           const float dpdx[3], const float dpdy[3], uint32_t light, uint64_t pixel_id,
                           uint64_t *rays);

/* AO at a visible point with `samples` cosine-weighted rays, seeded by (seed, pixel_id), from pos moved a
 * rounding-safe distance inside the triangle it lies on (a pixel exactly on a crease reads the AO beside it,
 * not 0). */
float fx_ao_eval_point(const fx_context *ctx, const float pos[3], const float normal[3], uint32_t samples,
                       uint64_t pixel_id, uint64_t *rays);

/* The direction towards light l from pos and the distance to it (INFINITY for directional lights). */
void fx_light_direction(const scene_light *light, const float pos[3], float dir[3], float *distance);

/* A point light's falloff 1 / d^2 at distance d (metres), exact at every scale: d^2 is kept from its smallest
 * normal float on (d about 1e-19 m; 1 / d^2 then stays finite, at most 8.5e37). A fixed floor of 1e-8 m^2
 * (d = 0.1 mm) before cut a lamp's light 10,000 times 10 um from a scene 0.1 mm across. */
static inline float fx_point_falloff(float distance)
{
    float d2 = distance * distance;
    return 1.0f / (d2 > FLT_MIN ? d2 : FLT_MIN);
}

/* ---- probes (indirect diffuse, DDGI-style; fx_probes.c) -------------------------------------------- */

/* One probe's payload, FX_PROBE_BYTES, little-endian, written byte by byte:
 *   0  float32 x3  position, scene-local metres (the grid point plus its relocation offset)
 *  12  float32     cell size of its level, metres (shade has no other way to know it)
 *  16  uint32      flags (low 16 bits): FX_PROBE_HAS_DATA (committed at least once), FX_PROBE_OFF (inside
 *                  geometry), FX_PROBE_MOVED_OUT (relocated out of geometry once: it no longer returns to its
 *                  grid point), FX_PROBE_SEEN_FRONT (some update saw a front face within reach from this
 *                  position); high 16 bits: the change-aware blend's drift mean, a half (0 when fresh, off
 *                  or under plain hysteresis)
 *  20  uint32      low 16 bits: blended updates since it was created or last switched on, at most 65535
 *                  (0: the next takes its value fully; texel_samples returns it); high 16 bits: the drift's
 *                  variance, a half
 *  24  float32     irradiance scale: the largest irradiance component of the map (0: all zero)
 *  28  float32     fraction of back-face hits of the last update
 *  32  64 x 3 half irradiance / scale, RGB, texel t = y * 8 + x of the 8 x 8 octahedral map
 * 416  64 x 2 half visibility moments: mean distance / cell, mean (distance / cell)^2
 * Irradiance is E = integral of radiance x cos over the hemisphere about the texel's direction (a uniform
 * sky of radiance L gives pi L); shade hands compose E / pi, which is what compose's bracket holds. */
enum {
    FX_PROBE_BYTES = 672,
    FX_PROBE_MAP = 8, /* octahedral map side, texels */
    FX_PROBE_TEXELS = 64,
    FX_PROBE_RAYS = 144,      /* default rays per update (DDGI's) */
    FX_PROBE_MAX_RAYS = 4096, /* probe_rays is clamped to this */
    FX_PROBE_HAS_DATA = 1u,
    FX_PROBE_OFF = 2u,
    FX_PROBE_MOVED_OUT = 4u,
    FX_PROBE_SEEN_FRONT = 8u,
};
#define FX_PROBE_HYSTERESIS 0.97f /* default weight of the old value in a blend (RTXGI's) */

/* The octahedral map (DDGI's convention): unit dir -> uv in [-1, 1]^2, z >= 0 inside the diamond |u|+|v| <= 1,
 * z < 0 folded outside it; and back (any uv in [-1, 1]^2 to a unit direction). Texel (x, y) covers
 * uv in [x/4 - 1, (x+1)/4 - 1] x [y/4 - 1, (y+1)/4 - 1]. */
void fx_probe_oct_encode(const float dir[3], float uv[2]);
void fx_probe_oct_decode(const float uv[2], float dir[3]);

/* Point i of the n-point spherical Fibonacci set (unrotated), a unit vector. */
void fx_probe_fibonacci(uint32_t i, uint32_t n, float dir[3]);

/* A probe payload's header, decoded. */
typedef struct fx_probe_info {
    float position[3], cell;
    uint32_t flags, updates; /* flags: the low 16 bits of the word (FX_PROBE_*) */
    float backface_fraction;
    float drift_mean, drift_variance; /* the change-aware blend's state (fx_probes.c, commit) */
} fx_probe_info;
void fx_probe_info_read(const void *payload, fx_probe_info *out);

/* A probe's irradiance E (true units: pi L under a uniform sky L) in direction dir, bilinear in its map. */
void fx_probe_irradiance(const void *payload, const float dir[3], float out_rgb[3]);

/* Traces every job's probe and leaves the new estimates in the job's scratch; reads payloads only (its own
 * and, through ctx->world_taps, its neighbours' committed ones). Returns the rays traced. */
uint64_t fx_probes_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count);

/* Blends every job's scratch into its payload: the moments with hysteresis ctx->probe_hysteresis, the
 * irradiance with the change-aware blend (fx_probes.c; plain hysteresis when ctx->probe_plain_blend). */
void fx_probes_commit(const fx_context *ctx, const fx_block_job *jobs, uint32_t count);

/* The no-cache estimate at a visible point: probe_rays cosine-weighted rays, hits lit directly (shadow rays),
 * the sky on misses, one bounce. Writes E (true units) to out_rgb; *rays receives the rays traced. */
void fx_probe_eval_point(const fx_context *ctx, const float pos[3], const float normal[3], uint64_t pixel_id,
                         float out_rgb[3], uint64_t *rays);

/* ---- the reference renderer: the same terms per pixel, converged (server/engine/reference.h) ---------- */

/* Indirect diffuse light at a visible point by path tracing, what the probes approximate (fx_paths.c):
 * `paths` paths leave the point (moved inside its triangle off a crease, as the baseline's) in
 * cosine-weighted directions about `normal` (an Owen-scrambled Sobol set, scrambled by hash(seed, stream));
 * a path that misses returns the sky, one that meets a back face ends dark (the probes' rule), and at every
 * front-face vertex it gathers direct light by next-event estimation (a shadow ray per light, lit as compose
 * lights a point: intensity x colour x cos, / d^2 for point lights), times the albedo of every vertex so far;
 * then it continues in a cosine-weighted direction, with Russian roulette from the second vertex on
 * (survival probability the largest component of the path's throughput, at most 0.95) and at most
 * ctx->reference_bounces vertices (0: no limit but FX_PATH_MAX_VERTICES). Writes E (true units, pi L under a
 * uniform sky L, as fx_probe_eval_point) to out_rgb; *rays receives the rays traced (paths and shadow rays). */
enum { FX_PATH_MAX_VERTICES = 256 };
void fx_indirect_reference_point(const fx_context *ctx, const float pos[3], const float normal[3],
                                 uint32_t paths, uint64_t stream, float out_rgb[3], uint64_t *rays);

/* ---- effects as plug-ins: one table of data and callbacks per effect ---------------------------------- */

enum {
    FX_MAX_EFFECTS = 16, /* the on-surface key's 4-bit effect field */
    FX_RUN_PIXELS = 64,  /* compose hands an effect at most this many pixels per shade call */
    FX_MAX_TAPS = 16,    /* texels one filtered read touches (trilinear: 8; world-space cells blended
                             across two levels: 16) */
};

/* The texels one filtered read of a pixel touches, restricted to texels holding data, weights summing to 1
 * (count 0: no data yet; the effect then leaves its term untouched). at_x, at_y: where the pixel lies
 * relative to each tap's texel, in that texel's units (0..1 inside it), for sub-texel use of the data. */
typedef struct fx_taps {
    const void *texel[FX_MAX_TAPS];
    float weight[FX_MAX_TAPS];
    float at_x[FX_MAX_TAPS], at_y[FX_MAX_TAPS]; /* on-surface taps only; unset for world-space ones */
    float footprint_log2; /* log2 of the pixel's size in texels of the level read (about 0 unless the level
                             is clamped at 0: then negative, the pixel smaller than a texel) */
    uint32_t count;
} fx_taps;

/* A visible point as compose sees it (for the no-cache evaluation and for world-space effects). */
typedef struct fx_point {
    float position[3];    /* world (scene-local) position */
    float normal[3];      /* unit geometric normal of the hit triangle (its front side) */
    float view_normal[3]; /* the same normal turned to the side the viewer sees (what light reaches) */
    float dpdx[3],
        dpdy[3];       /* the pixel's footprint on the surface: offsets to the next pixel right and down */
    uint32_t triangle; /* scene triangle */
    float u, v;        /* barycentrics of corners 1 and 2 */
    uint64_t pixel_id; /* seeds the no-cache random numbers */
} fx_point;

/* The shading terms of a run of pixels that compose combines as
 *     radiance = albedo * (sum over lights l of E_l * cos_l * light_visibility[l] + sky * sky_visibility
 *                          + indirect)
 * Compose starts every pixel unshadowed (1), unoccluded (1) and with no indirect light (0); each effect's
 * shade multiplies the visibility it knows and adds the light it brings. The arrays hold `count` pixels. */
typedef struct fx_shade_run {
    uint32_t count;          /* pixels in the run, <= FX_RUN_PIXELS */
    uint32_t light_count;    /* the scene's lights */
    const fx_taps *taps;     /* per pixel: this effect's filtered texels (cached mode) */
    const fx_point *points;  /* per pixel: the visible point; may be NULL when no shading cache
                                     kind needs positions (compose gathers points for readers only) */
    float *light_visibility; /* count * light_count, pixel-major */
    float *sky_visibility;   /* count */
    float *indirect;         /* count * 3, linear RGB irradiance */
} fx_shade_run;

/* The terms of one pixel in no-cache mode (same meaning as fx_shade_run's, one pixel). */
typedef struct fx_shade_point {
    float *light_visibility; /* light_count */
    float *sky_visibility;
    float *indirect; /* 3 */
    /* Optional (NULL: not asked). An effect that replaces the sky term by light that carries the sky (the
     * probes: sky_visibility becomes 0) writes here the sky visibility it found and scaled its light by (what
     * ambient occlusion left): the ambient-occlusion term a picture of it shows. */
    float *sky_open;
} fx_shade_point;

/* An effect: what the frame loop, the needs decision, the command line and the statistics know of it.
 * Adding an effect is one new file defining one of these and one line in the registry (fx_registry.c);
 * a program may also hand the loop its own list (tests do). Callbacks a kind of effect has no use for are
 * NULL. Every callback is called from any thread with distinct blocks or pixels and must be deterministic
 * (random numbers from hashes of seed, key, texel and sample index). */
typedef struct fx_effect {
    const char *name;       /* "shadow": command line, statistics, summaries */
    const char *alias;      /* another accepted spelling on the command line ("shadows"), or NULL */
    scene_cache_kind cache; /* where it lives: SCENE_CACHE_ON_SURFACE or SCENE_CACHE_WORLD_SPACE */
    int32_t level_bias;     /* default level bias (coarser is positive) */
    fx_filter filter;       /* how compose reads it */
    fx_policy policy;       /* once, progressive to max_samples, continuous */
    uint32_t max_samples;   /* progressive: samples at which a texel is converged */
    const char *depends_on; /* the effect (by name) whose texels of the same block every update needs
                                     (every on-surface effect: "triangle_lookup"), or NULL */

    /* Payload bytes per texel for scene s (> 0, <= 1024). */
    uint32_t (*texel_bytes)(const scene *s);
    /* Whether scene s needs the effect, with a reason a person can read. NULL: needed exactly when an
     * effect that depends on it runs (the triangle lookup). */
    bool (*needs)(const scene *s, char *why, size_t why_cap);
    /* Upper bound of the rays one update of one texel traces (the ray budget is spent with it before
     * anything is traced); `samples` is the progressive step. */
    uint64_t (*cost)(const scene *s, uint32_t samples);
    /* Updates the texels of every job's mask; returns the rays traced. */
    uint64_t (*update)(const fx_context *ctx, const fx_block_job *jobs, uint32_t count, uint32_t samples);
    /* Progressive effects: the samples a texel holds (converged at max_samples). NULL: a texel with data
     * is final. */
    uint32_t (*texel_samples)(const void *texel);
    /* The run's own sample count, from the context (fx_context.ao_samples, shadow_rays): for a progressive
     * effect the samples a texel converges at (it replaces max_samples for the run); for an effect updated
     * once the samples per texel its cost and update are handed. NULL: max_samples, and 0 for an effect
     * updated once. */
    uint32_t (*run_samples)(const fx_context *ctx);
    /* Writes one texel at level l >= 1 from its four final texels of level l - 1 (resampling queue).
     * NULL: no resampling. */
    void (*resample)(const fx_context *ctx, const void *const finer[4], void *texel);
    /* World-space effects: cells per brick side (1: probes; 4: volumetric data, 64 cells, one bit each in
     * a brick mask). On-surface effects: 0 (their blocks are 8 x 8 texels). */
    uint32_t brick_size;
    /* Scratch bytes one queued job needs between update and commit (NULL: none). */
    uint32_t (*scratch_bytes)(const scene *s);
    /* Called after every update of the frame has run, with the same jobs: makes what update gathered
     * visible (a world-space update reads its neighbours' committed values through ctx->world_taps, so it
     * must not change them itself). NULL: update writes the payload directly. */
    void (*commit)(const fx_context *ctx, const fx_block_job *jobs, uint32_t count);
    /* Compose: multiplies or adds this effect's term for a run of pixels from their taps. NULL: the
     * effect shades nothing itself (the triangle lookup). */
    void (*shade)(const fx_context *ctx, const fx_shade_run *run);
    /* The term is low-frequency (indirect light): compose may evaluate shade once per block of pixels of a
     * whole frame and upsample it (srv_loop_desc.indirect_block). Such a shade must only add to `indirect`
     * and scale `sky_visibility`, both linearly in the sky_visibility it is given, and read neither
     * light_visibility nor light_count (it is called with NULL and 0). World-space effects only. */
    bool low_frequency;
    /* The no-cache baseline: the same term evaluated at one visible point with the sample counts the cache
     * converges to; returns the rays traced. */
    uint64_t (*eval)(const fx_context *ctx, const fx_point *point, fx_shade_point *out);
    /* The reference renderer: the same term as eval, converged. `samples` of the effect's own kind (AO rays,
     * shadow rays per light, indirect paths: a multiple of reference_granule) at one visible point, every
     * random number hashed from (ctx->seed, point->pixel_id), so calls with different pixel_ids are
     * independent estimates. Terms are taken on the side the viewer sees (point->view_normal). Returns the
     * rays traced. NULL: the effect has no reference estimator (the reference renderer refuses to run it). */
    uint64_t (*reference)(const fx_context *ctx, const fx_point *point, uint32_t samples,
                          fx_shade_point *out);
    uint32_t reference_samples; /* the reference's default samples per pixel */
    uint32_t reference_granule; /* samples come in sets of this many (0: 1) */
    const char *reference_unit; /* what a sample is, for messages and --help: "rays", "rays per light", ... */
} fx_effect;

/* The built-in effects in registry order (the on-surface key's effect field is the index):
 * triangle_lookup, shadow, ao, probes. *count receives the number. */
const fx_effect *const *fx_registry(uint32_t *count);

/* The index of the effect named `name` (or its alias) in effects[0..count), or -1. */
int32_t fx_find(const fx_effect *const *effects, uint32_t count, const char *name);

/* Which of effects[0..count) scene s needs, with a reason for each (why[i], why_cap bytes each): an
 * effect with a needs callback decides for itself; one without is needed exactly when a needed effect
 * depends on it. */
void fx_needs(const fx_effect *const *effects, uint32_t count, const scene *s, bool *needed,
              char (*why)[200]);

/* The built-in tables (each defined beside its effect's code). */
extern const fx_effect fx_effect_triangle_lookup, fx_effect_shadow, fx_effect_ao, fx_effect_probes;

#ifdef __cplusplus
}
#endif
#endif
