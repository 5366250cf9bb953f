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

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

enum {
    FX_TRI_LOOKUP = SCENE_FX_TRIANGLE_LOOKUP, /* 0 */
    FX_SHADOW = SCENE_FX_SHADOW,              /* 1 */
    FX_AO = SCENE_FX_AO,                      /* 2 */
    FX_SHADOW_RAYS = 16,                      /* rays per texel and light */
    FX_AO_MAX_SAMPLES = 64,                   /* AO converges here */
};

typedef enum fx_filter { FX_FILTER_POINT = 0, FX_FILTER_BILINEAR, FX_FILTER_TRILINEAR } fx_filter;
typedef enum fx_policy { FX_UPDATE_ONCE = 0, FX_UPDATE_PROGRESSIVE, FX_UPDATE_CONTINUOUS } fx_policy;

/* What the frame loop needs to know of an effect. */
typedef struct fx_info {
    const char *name;        /* "triangle_lookup", "shadow", "ao" */
    uint32_t id;             /* FX_* */
    uint32_t texel_bytes;    /* for this scene (shadow: 2 per light) */
    int32_t level_bias;      /* default bias in levels (coarser is positive) */
    fx_filter filter;        /* how compositing reads it */
    fx_policy policy;        /* once (shadow, lookup), progressive until converged (AO) */
} fx_info;

/* The description of effect id for scene s (texel_bytes depends on the light count). */
fx_info fx_describe(uint32_t id, const scene *s);

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

/* Shared, read-only state of an update. */
typedef struct fx_context {
    const scene *s;
    scene_rt *rt;
    uint32_t seed;   /* run seed */
    float ao_radius; /* metres (> 0) */
} fx_context;

/* One queued block. payload and lookup point into the cache; the effect writes payload texels of mask. */
typedef struct fx_block_job {
    uint64_t key;           /* the block's cache key (seeds the random numbers) */
    uint32_t island, level, block_x, block_y;
    uint64_t mask;          /* texels to update */
    const uint32_t *lookup; /* the block's 64 triangle-lookup texels (valid for every texel of mask) */
    void *payload;          /* 64 * texel_bytes */
} fx_block_job;

/* Hard shadows: for each texel of mask and each light, FX_SHADOW_RAYS rays from stratified jittered points
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
 * past FX_AO_MAX_SAMPLES in all), keeping a running mean. Texel t: uint16 unoccluded fraction (unorm16)
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
float fx_shadow_eval_point(const fx_context *ctx, const float pos[3], const float normal[3], const float dpdx[3],
                           const float dpdy[3], uint32_t light, uint64_t pixel_id, uint64_t *rays);

/* AO at a visible point with `samples` cosine-weighted rays, seeded by (seed, pixel_id), from pos moved a
 * rounding-safe distance inside the triangle it lies on (a pixel exactly on a crease reads the AO beside it,
 * not 0). */
float fx_ao_eval_point(const fx_context *ctx, const float pos[3], const float normal[3], uint32_t samples,
                       uint64_t pixel_id, uint64_t *rays);

/* The direction towards light l from pos and the distance to it (INFINITY for directional lights). */
void fx_light_direction(const scene_light *light, const float pos[3], float dir[3], float *distance);

#ifdef __cplusplus
}
#endif
#endif
