/* Private to the effects module: what the effect files (fx_lookup.c, fx_shadow.c, fx_ao.c) share.
 *
 * - FX_ASSERT: programming errors, on in every build type (tests run RelWithDebInfo).
 * - Stateless random numbers: a 64-bit mix of (seed, key, texel, sample index, stream tag), so any split of
 *   the work over threads, batches or frames gives the same numbers (effects.h, "Determinism").
 * - Owen-scrambled Sobol points (Burley 2020, "Practical Hash-based Owen Scrambling"): stratified 2D points
 *   indexed by sample index, so the first 16, 32, 64 samples of a texel are each well stratified.
 * - Small vector helpers, the branchless orthonormal basis of Duff et al. 2017, little-endian payload access.
 * - The ray batch: 64-byte aligned RTCRay arrays for rtcOccluded1M (DEPENDENCIES.md: 256-ray streams are
 *   the fastest for occlusion here). */
#ifndef FXC_FX_INTERNAL_H
#define FXC_FX_INTERNAL_H

#include "effects.h"

#include <embree3/rtcore.h>

#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

/* Programming errors only (bad arguments from our own code); never on a per-ray path. */
#define FX_ASSERT(cond)                                                                                      \
    do {                                                                                                     \
        if (!(cond)) {                                                                                       \
            fprintf(stderr, "%s:%d: effects assertion failed: %s\n", __FILE__, __LINE__, #cond);             \
            abort();                                                                                         \
        }                                                                                                    \
    } while (0)

enum {
    FX_RAY_BATCH = 256, /* rays per rtcOccluded1M call */
};

/* Stream tags: keep the random numbers of different uses independent of each other. */
enum {
    FX_STREAM_SHADOW_JITTER = 0x5348, /* "SH" */
    FX_STREAM_AO_DIRECTION = 0x4144,  /* "AD" */
    FX_STREAM_AO_ORIGIN = 0x414f,     /* "AO" */
};

/* ---- random numbers ------------------------------------------------------------------------------- */

/* A 64-bit finaliser (the splitmix64 / Stafford "mix13" constants): every input bit affects every output bit.
 */
static inline uint64_t fx__mix64(uint64_t x)
{
    x ^= x >> 30;
    x *= 0xbf58476d1ce4e5b9ull;
    x ^= x >> 27;
    x *= 0x94d049bb133111ebull;
    x ^= x >> 31;
    return x;
}

/* The hash of (seed, key, texel, index, stream): chained mixing, so permuting the arguments changes it. */
static inline uint64_t fx__hash(uint32_t seed, uint64_t key, uint32_t texel, uint32_t index, uint32_t stream)
{
    uint64_t h = fx__mix64((uint64_t)seed ^ ((uint64_t)stream << 32) ^ 0x9e3779b97f4a7c15ull);
    h = fx__mix64(h ^ key);
    h = fx__mix64(h ^ (((uint64_t)texel << 32) | index));
    return h;
}

/* A uniform float in [0, 1) from the top 24 bits of a 32-bit value (exactly representable, never 1). */
static inline float fx__unit_float(uint32_t bits)
{
    return (float)(bits >> 8) * (1.0f / 16777216.0f);
}

/* Reverses the bit order of a 32-bit value. */
static inline uint32_t fx__reverse_bits(uint32_t x)
{
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
    x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
    return (x >> 16) | (x << 16);
}

/* The Laine-Karras permutation: each bit is flipped depending only on the bits below it. */
static inline uint32_t fx__laine_karras(uint32_t x, uint32_t seed)
{
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

/* Nested uniform (Owen) scrambling of a 32-bit fraction: the Laine-Karras permutation on the reversed bits;
 * each bit is flipped depending only on the bits above it, so aligned intervals map to aligned intervals. */
static inline uint32_t fx__owen_scramble(uint32_t x, uint32_t seed)
{
    return fx__reverse_bits(fx__laine_karras(fx__reverse_bits(x), seed));
}

/* Sobol dimension 1 before bit reversal: its generator is Pascal's matrix mod 2, and by Lucas' theorem
 * output bit m is the XOR of index bits k that are supersets of m (k & m == m): a superset transform over
 * the five bits of a bit position, in five shift-and-mask steps (checked against the direction-number loop).
 */
static inline uint32_t fx__sobol1_reversed(uint32_t index)
{
    index ^= (index >> 1) & 0x55555555u;
    index ^= (index >> 2) & 0x33333333u;
    index ^= (index >> 4) & 0x0f0f0f0fu;
    index ^= (index >> 8) & 0x00ff00ffu;
    index ^= (index >> 16) & 0x0000ffffu;
    return index;
}

/* Sample `index` of a 2D Owen-scrambled, index-shuffled Sobol sequence (dimensions 0 and 1, a (0,2)-sequence)
 * for scramble hash `h`: every aligned run of 2^m indices (the first 16, the next 16, the first 64) is a
 * (0,m,2)-net, i.e. stratified in every elementary interval. Output in [0, 1)^2.
 * Sobol dimension 0 is reverse_bits(index), dimension 1 is reverse_bits(fx__sobol1_reversed(index)), and the
 * Owen scramble reverses, permutes and reverses again, so the reversals cancel: no loop over bits at all. */
static inline void fx__sobol_2d(uint32_t index, uint64_t h, float out[2])
{
    uint32_t shuffled = fx__owen_scramble(index, (uint32_t)(h >> 40) | 1u);
    uint32_t x = fx__reverse_bits(fx__laine_karras(shuffled, (uint32_t)h));
    uint32_t y = fx__reverse_bits(fx__laine_karras(fx__sobol1_reversed(shuffled), (uint32_t)(h >> 32)));
    out[0] = fx__unit_float(x);
    out[1] = fx__unit_float(y);
}

/* ---- vectors -------------------------------------------------------------------------------------- */

/* Dot product of two 3-vectors. */
static inline float fx__dot(const float a[3], const float b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* Direct light arriving at a point with this normal from one light: its direction and distance (as
 * fx_light_direction) and the unshadowed irradiance scale intensity x cos x falloff (1/d^2 for a point light).
 * False when it arrives from behind or with no energy; the probe update and the path tracer both use it. */
static inline bool fx__light_arriving(const scene_light *light, const float origin[3], const float normal[3],
                                      float dir[3], float *distance, float *scale)
{
    fx_light_direction(light, origin, dir, distance);
    float cosine = fx__dot(normal, dir);
    if (!(cosine > 0))
        return false;
    float falloff = light->type == SCENE_LIGHT_POINT ? fx_point_falloff(*distance) : 1.0f;
    *scale = fminf(light->intensity * cosine * falloff, FLT_MAX); /* x a black channel: 0, never NaN */
    return *scale > 0;
}

/* The normal of one side of a surface: n, or -n for its back (a block of a twin island, fx_block_job.back). */
static inline void fx__side_normal(const float n[3], bool back, float out[3])
{
    for (int k = 0; k < 3; k++)
        out[k] = back ? -n[k] : n[k];
}

/* An orthonormal basis (t, b) around unit n, branchless and continuous except at n.z = 0 sign flips
 * (Duff et al. 2017, "Building an Orthonormal Basis, Revisited"). */
static inline void fx__onb(const float n[3], float t[3], float b[3])
{
    float sign = copysignf(1.0f, n[2]);
    float a = -1.0f / (sign + n[2]);
    float c = n[0] * n[1] * a;
    t[0] = 1.0f + sign * n[0] * n[0] * a;
    t[1] = sign * c;
    t[2] = -sign * n[0];
    b[0] = c;
    b[1] = sign + n[1] * n[1] * a;
    b[2] = -n[1];
}

/* A cosine-weighted direction about unit n (with basis t, b) from a point of [0,1)^2 (Malley's method). */
/* sin and cos of 2 pi `turns` for turns in [0, 1): quadrant reduction and Taylor polynomials on [0, pi/2),
 * absolute error below 4e-6 (ample for a ray direction); libm's sincosf was 18 % of the AO update's time. */
static inline void fx__sincos_turns(float turns, float *sine, float *cosine)
{
    float quarter = turns * 4.0f;
    int quadrant = (int)quarter;
    float x = (quarter - (float)quadrant) * 1.57079632679489662f;
    float x2 = x * x;
    float s = x * (1.0f + x2 * (-1.0f / 6 + x2 * (1.0f / 120 + x2 * (-1.0f / 5040 + x2 * (1.0f / 362880)))));
    float c =
        1.0f + x2 * (-0.5f + x2 * (1.0f / 24 + x2 * (-1.0f / 720 + x2 * (1.0f / 40320 - x2 / 3628800))));
    switch (quadrant & 3) {
    case 0: *sine = s, *cosine = c; break;
    case 1: *sine = c, *cosine = -s; break;
    case 2: *sine = -s, *cosine = -c; break;
    default: *sine = -c, *cosine = s; break;
    }
}

static inline void fx__cosine_direction(const float n[3], const float t[3], const float b[3],
                                        const float xi[2], float dir[3])
{
    float r = sqrtf(xi[0]);
    float sine, cosine;
    fx__sincos_turns(xi[1], &sine, &cosine);
    float x = r * cosine, y = r * sine, z = sqrtf(fmaxf(0.0f, 1.0f - xi[0]));
    for (int k = 0; k < 3; k++)
        dir[k] = x * t[k] + y * b[k] + z * n[k];
}

/* ---- surface points -------------------------------------------------------------------------------- */

/* Why sample points are pulled inside their triangle (DESIGN.md "Effects": a texel's points stay on its own
 * surface). Where a floor meets a wall, the floor triangle's edge lies on the wall's plane. A point on that
 * edge, offset along the floor's normal, is still on the wall's plane (or, after rounding, behind it): every
 * ray from it with tnear = 0 meets the wall at t = 0, whatever its direction (AO 0, a dark line), or passes
 * behind it (light leaking into a closed room). So every sample point is kept `margin` metres inside each
 * edge of its triangle: more than the Waechter-Binder offset can move it sideways and the rounding of a
 * position (fx__robust_distance), and for texels a small fraction of the texel (FX_TEXEL_MARGIN), so the
 * wall is met at t > 0 by the rays that reach it and by no other. */

/* The fraction of a texel's side by which its sample points stay inside their triangle's edges. Small
 * against the texel (AO near a wall of radius R changes by about 2 margin / (pi R); a shadow mask's stratum
 * is 1/4 of the side), large against rounding. */
#define FX_TEXEL_MARGIN (1.0f / 16.0f)

/* A distance (metres) beyond every sideways move of scene_offset_ray_origin at p and the rounding of p:
 * twice its largest offset, 2 * 256 ulps of p's largest coordinate (at most |x| 2^-14), or near zero twice
 * its fixed offset (scale 2^-15). */
static inline float fx__robust_distance(const float p[3], float scale)
{
    if (!(scale > 0) || scale > 1.0f)
        scale = 1.0f;
    float largest = fmaxf(fabsf(p[0]), fmaxf(fabsf(p[1]), fabsf(p[2])));
    return largest * 0x1p-14f + scale * 0x1p-15f;
}

/* The map from level-0 island UV (or barycentrics) to the surface of one triangle, set up once per texel so
 * that each sample point costs a few multiply-adds (fx_surface_point is init + eval). Points are clamped into
 * the triangle shrunk by `margin` metres on every side: barycentric weight k at least min_weight[k]. */
typedef struct fx__surface_map {
    double uv_origin[2];                  /* corner 0 in island UV */
    double to_w1[2], to_w2[2];            /* barycentrics of corners 1 and 2 per UV unit */
    double fallback[2];                   /* constant barycentrics for a triangle without UV area */
    double origin[3], edge1[3], edge2[3]; /* world corner 0 and edges to corners 1 and 2, metres */
    double dual1[3], dual2[3];            /* world offset from corner 0 -> barycentrics 1 and 2 (in plane) */
    double min_weight[3];                 /* barycentric margins of corners 0, 1, 2 (0: plain clamp) */
    float normal[3];                      /* unit geometric normal */
} fx__surface_map;

/* Sets up the map of scene triangle tri (world part only: no UV), with its points kept margin metres (raised
 * to fx__robust_distance of its corners when positive; 0: clamped onto the triangle, edges included)
 * inside its edges. A triangle too small for the margin maps every point to its incentre. */
void fx__triangle_map_init(const scene *s, uint32_t tri, float margin, fx__surface_map *map);

/* Sets up the map of the triangle named by lookup texel `lookup` in island, with margin as above. */
void fx__surface_map_init(const scene *s, uint32_t island, uint32_t lookup, float margin,
                          fx__surface_map *map);

/* The margin (metres) for the sample points of a texel at level: FX_TEXEL_MARGIN of its side. */
static inline float fx__texel_margin(const scene *s, uint32_t level)
{
    return FX_TEXEL_MARGIN * (float)(1u << level) / s->texel_density;
}

/* Whether barycentrics (w1, w2) (w0 = 1 - w1 - w2) lie in the map's shrunk triangle. */
static inline bool fx__inside_margin(const fx__surface_map *map, double w1, double w2)
{
    return 1.0 - w1 - w2 >= map->min_weight[0] && w1 >= map->min_weight[1] && w2 >= map->min_weight[2];
}

/* The world position of barycentrics (w1, w2), clamped into the shrunk triangle first (weights below their
 * margins raised onto it, the rest renormalised). */
void fx__surface_map_eval_bary(const fx__surface_map *map, double w1, double w2, float position[3]);

/* The world position of an island UV point: its barycentrics, clamped as fx__surface_map_eval_bary does. */
void fx__surface_map_eval(const fx__surface_map *map, float island_u, float island_v, float position[3]);

/* The barycentrics (w1, w2) of world point p projected onto the map's plane. */
static inline void fx__surface_map_bary(const fx__surface_map *map, const float p[3], double *w1, double *w2)
{
    double d[3];
    for (int k = 0; k < 3; k++)
        d[k] = (double)p[k] - map->origin[k];
    *w1 = d[0] * map->dual1[0] + d[1] * map->dual1[1] + d[2] * map->dual1[2];
    *w2 = d[0] * map->dual2[0] + d[1] * map->dual2[1] + d[2] * map->dual2[2];
}

/* For the no-cache baseline, which knows a visible point and its normal but not its triangle: finds the
 * triangle facing along normal (within 25 degrees) nearest to pos, within fx__robust_distance of it
 * (Embree's point query); when none does, or one facing against it (within 25 degrees: a point seen from
 * behind its triangle, normal the side the viewer sees) is strictly nearer, that one; and sets map up for it with points kept
 * margin metres inside (raised as in fx__triangle_map_init), then `settled` = pos clamped into that shrunk
 * triangle. Returns false, with settled = pos, when no such triangle is that near (a point off every
 * surface). */
bool fx__locate_point(const fx_context *ctx, const float pos[3], const float normal[3], float margin,
                      fx__surface_map *map, float settled[3]);

/* ---- the registry ------------------------------------------------------------------------------- */

/* The scene's own decision (scene_needs) for one of its effects, with the reason copied into why. */
bool fx__scene_needs(const scene *s, scene_effect which, char *why, size_t why_cap);

/* fminf(x, 1.0f) without a libm call (GCC keeps fminf a call without -ffinite-math-only): x below 1, else
 * 1, also 1 for NaN as fminf gives. Compose clamps every filtered visibility with it. */
static inline float fx__min1(float x)
{
    return x < 1.0f ? x : 1.0f;
}

/* A unorm16 as a float, n / 65535 rounded to float, as the double product n * (1 / 65535) rounded once to
 * float: the same float for every n (all 65536 checked, tests/test_effects.c), with a multiply where the
 * division was the slowest step of AO shading. */
static inline float fx__unorm16(uint32_t n)
{
    return (float)((double)n * (1.0 / 65535.0));
}

/* ---- payload bytes (little-endian, host independent) --------------------------------------------- */

/* Reads a little-endian uint16 at p. */
static inline uint16_t fx__get_u16(const void *p)
{
    const uint8_t *bytes = p;
    return (uint16_t)(bytes[0] | (bytes[1] << 8));
}

/* Writes a little-endian uint16 at p. */
static inline void fx__put_u16(void *p, uint16_t value)
{
    uint8_t *bytes = p;
    bytes[0] = (uint8_t)(value & 0xffu);
    bytes[1] = (uint8_t)(value >> 8);
}

/* ---- rays ------------------------------------------------------------------------------------------ */

/* Fills an occlusion ray: tnear 0, mask all, flags 0, time 0. */
static inline void fx__set_ray(struct RTCRay *ray, const float org[3], const float dir[3], float tfar,
                               uint32_t id)
{
    ray->org_x = org[0];
    ray->org_y = org[1];
    ray->org_z = org[2];
    ray->tnear = 0.0f;
    ray->dir_x = dir[0];
    ray->dir_y = dir[1];
    ray->dir_z = dir[2];
    ray->time = 0.0f;
    ray->tfar = tfar;
    ray->mask = 0xFFFFFFFFu;
    ray->id = id;
    ray->flags = 0;
}

/* Traces count occlusion rays as one stream; afterwards ray i is occluded iff its tfar is -INFINITY. */
static inline void fx__occluded(const fx_context *ctx, struct RTCRay *rays, uint32_t count)
{
    if (count == 0)
        return;
    if (ctx->observe_rays) /* benchmarks replay exactly these rays against raw Embree */
        ctx->observe_rays(ctx->observe_user, rays, count);
    struct RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    rtcOccluded1M((RTCScene)scene_rt_handle(ctx->rt), &context, rays, count, sizeof(struct RTCRay));
}

/* Level-0 island UV of a point inside texel (block_x*8 + x, block_y*8 + y) of level at offsets (jx, jy) in
 * [0, 1] of the texel. */
static inline void fx__texel_uv(uint32_t level, uint32_t block_x, uint32_t block_y, uint32_t texel, float jx,
                                float jy, float *u, float *v)
{
    float scale = (float)(1u << level);
    *u = ((float)(block_x * SCENE_BLOCK_TEXELS + (texel & 7u)) + jx) * scale;
    *v = ((float)(block_y * SCENE_BLOCK_TEXELS + (texel >> 3)) + jy) * scale;
}

#endif
