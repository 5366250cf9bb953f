/* fx_probes_internal.h: what the probe effect's four files share (effects/fx_probes.c: update, commit and
 * the table; effects/fx_probes_hits.c: the update's hits; effects/fx_probes_eval.c: the no-cache estimate;
 * effects/fx_probes_map.c: the octahedral maps, reading payloads, the shading filter and compose's shade).
 * The payload layout and units are described at the top of fx_probes.c. */
#ifndef FXC_FX_PROBES_INTERNAL_H
#define FXC_FX_PROBES_INTERNAL_H

#include "fx_internal.h"

#include <float.h>
#include <string.h>

#define FX_PROBE_PI 3.14159265358979f
/* The cosine power of the moments' lobe: 64 (DDGI's 50, rounded to six squarings). A lobe as wide as an
 * 8 x 8 texel (power 16) mixed a thin wall's distance with the floor's behind it, and the Chebyshev test let
 * 15 % of the lit room through to a floor point beside the wall (tests/test_probes.c); at 64 it is under 1 %.
 * Each texel then rests on about 1.1 rays' weight per update; the hysteresis averages over the rotations. */
#define FX_PROBE_DEPTH_POWER      64
#define FX_PROBE_BACKFACE_OFF     0.25f     /* back-face fraction above which a probe is off (RTXGI) */
#define FX_PROBE_BACKFACE_SHORTEN 0.2f      /* back-face distances are stored shortened (RTXGI) */
#define FX_PROBE_MAX_DISTANCE     2.598076f /* 1.5 sqrt(3): distances are clamped to this many cells */
#define FX_PROBE_MIN_FRONT        0.25f     /* cells: relocation keeps front faces at least this far */
#define FX_PROBE_MAX_OFFSET       0.45f     /* cells, per axis: relocation range */
/* The change-aware blend (fx_probes.c, commit): the memories per update of the drift's mean and of its
 * variance, the z-scores of the mean up to which the irradiance keeps the steady-state hysteresis h and from
 * which it keeps FX_PROBE_FAST_KEEP. */
#define FX_PROBE_DRIFT_MEMORY   0.75f
#define FX_PROBE_NOISE_MEMORY   0.9f
#define FX_PROBE_DRIFT_Z_LOW    4.0f
#define FX_PROBE_DRIFT_Z_HIGH   7.0f
#define FX_PROBE_FAST_KEEP      0.0f
#define FX_PROBE_COARSER_LEVELS 4u /* levels above the update's searched at a hit with no probe (hits) */
#define FX_PROBE_NORMAL_BIAS    0.2f /* cells: the shading point moves this far along its normal for Chebyshev */

enum {
    FX_STREAM_PROBE_ROTATION = 0x5052, /* "PR" */
    FX_STREAM_PROBE_ROUNDING = 0x5051,
    FX_STREAM_PROBE_EVAL = 0x5045,
    PROBE_CHUNK = 128, /* primary rays per intersection stream */
    PROBE_HEADER = 32,
    PROBE_IRRADIANCE = PROBE_HEADER,
    PROBE_MOMENTS = PROBE_IRRADIANCE + FX_PROBE_TEXELS * 6,
};

_Static_assert(PROBE_MOMENTS + FX_PROBE_TEXELS * 4 == FX_PROBE_BYTES, "payload layout");

/* fminf(x, m) for m > 0 (not NaN), inline: NaN and x >= m give m, as fminf does (libm's fminf is a call
 * here: without -ffinite-math-only the compiler does not inline it). */
static inline float min_of(float x, float m)
{
    return x < m ? x : m;
}

/* The rays an update traces per probe (ctx->probe_rays, default FX_PROBE_RAYS, at most FX_PROBE_MAX_RAYS). */
static inline uint32_t probe_ray_count(const fx_context *ctx)
{
    uint32_t n = ctx->probe_rays ? ctx->probe_rays : FX_PROBE_RAYS;
    return n > FX_PROBE_MAX_RAYS ? FX_PROBE_MAX_RAYS : n;
}

/* ---- bytes ---------------------------------------------------------------------------------------------- */

static inline uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static inline void put_u32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

static inline float get_f32(const uint8_t *p)
{
    uint32_t bits = get_u32(p);
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

static inline void put_f32(uint8_t *p, float f)
{
    uint32_t bits;
    memcpy(&bits, &f, sizeof bits);
    put_u32(p, bits);
}

/* A half float (IEEE binary16) to float: every half, subnormals included (no infinities are ever written). */
static inline float half_to_float(uint16_t h)
{
    uint32_t exponent = (h >> 10) & 0x1fu, mantissa = h & 0x3ffu, sign = (uint32_t)(h & 0x8000u) << 16;
    uint32_t bits;
    if (exponent - 1u < 30u) { /* normal: rebias the exponent (15 -> 127) and widen the mantissa, exact */
        bits = sign | ((exponent + 112u) << 23) | (mantissa << 13);
    } else if (exponent == 0) {
        float value = (float)mantissa * 0x1p-24f; /* subnormal, exact */
        memcpy(&bits, &value, sizeof bits);
        bits |= sign;
    } else {
        bits = sign | 0x7f800000u | (mantissa << 13); /* infinity or NaN */
    }
    float value;
    memcpy(&value, &bits, sizeof value);
    return value;
}

/* A half (finite, >= 0: moments and stored irradiance) to float, exactly, subnormals included, in selects so
 * loops over it vectorise: a normal half's exponent rebiased (15 -> 127) in its bits, a subnormal one as its
 * mantissa times 2^-24 (a normal float). For those halves the same float as half_to_float, also on threads
 * with denormals-are-zero (the pool's, scene_tracing_thread_init): the shorter form that shifts the bits into
 * a float and multiplies by 2^112 makes a subnormal float of a subnormal half, which such a thread reads as
 * 0 (test_half_bits_daz). */
static inline float half_bits_to_float(uint32_t h)
{
    uint32_t magnitude = h & 0x7fffu, normal_bits = (magnitude << 13) + (112u << 23);
    float normal;
    memcpy(&normal, &normal_bits, sizeof normal);
    float subnormal = (float)(int32_t)(magnitude & 0x3ffu) * 0x1p-24f;
    return magnitude >> 10 == 0 ? subnormal : normal;
}

/* DDGI's weight of a probe seen from a point at `distance` (metres; 0: no visibility test): the direction
 * weight times Chebyshev's bound from the moments towards the point (mean, mean2 in metres), cubed and at least
 * 0.05; at least 1e-6; and below 0.2 crushed (times w^2 / 0.2^2) so light leaking through a wall fades quickly.
 * In selects, so loops over lanes vectorise; the same operations as fx_probes_map.c's probe_weight, the scalar
 * form the tests compare against. */
static inline float probe_visibility_weight(float weight, float mean, float mean2, float distance)
{
    float variance = fabsf(mean2 - mean * mean), excess = distance - mean;
    float chebyshev = variance / (variance + excess * excess);
    chebyshev = distance > mean ? chebyshev * chebyshev * chebyshev : 1.0f;
    chebyshev = chebyshev > 0.05f ? chebyshev : 0.05f; /* fmaxf(0.05f, chebyshev), NaN included */
    float w = distance > 0 ? weight * chebyshev : weight;
    w = w > 1e-6f ? w : 1e-6f;
    return w < 0.2f ? w * (w * w / (0.2f * 0.2f)) : w;
}

/* The four texels of direction dir in the 8 x 8 map and their bilinear weights (DDGI's border wrap). */
void fx__probe_oct_bilinear(const float dir[3], uint32_t texel[4], float weight[4]);

/* The 64 texels' directions (their octahedral centres). */
void fx__probe_texel_dirs(float dirs[FX_PROBE_TEXELS][3]);

/* The shading filter (DDGI's weights, renormalised; false when no probe contributes), each probe's irradiance towards the normal from a per-thread memo of the frame (ctx may be
 * NULL: no memo). committed: read after this frame's commits (compose) or before them (update hits). */
bool fx__probe_filter_memo(const fx_context *ctx, bool committed, const fx_taps *taps,
                           const float position[3], const float normal[3], float out_rgb[3]);

/* Whether the update shades a chunk's front-face hits in passes, with the directional lights' directions
 * once per call (true, the default), or one at a time with fx__light_arriving per hit (the tests set it false
 * to compare the two bit for bit; not to be changed while updates run). */
extern bool fx__probe_hits_batched;
/* log2 of the entries a thread's hit memo uses (1 to 11, the default 11), read when a thread allocates it
 * (its first update): the tests make it small so that entries are replaced within a chunk. */
extern uint32_t fx__probe_memo_log2;

/* What an update's rays saw of the faces they hit, per probe (update's relocation and off test). */
typedef struct fx_probe_faces {
    uint32_t backfaces;                /* rays that hit a back face */
    float closest_front, closest_back; /* metres; INFINITY: none */
    float front_dir[3], back_dir[3];   /* the rays' directions to them */
} fx_probe_faces;

/* fx_probes_hits.c. Once per update call, in the tracing thread, before fx__probe_shade_chunk: the call's
 * lights and the thread's hit memo. */
void fx__probe_hits_begin(const fx_context *ctx);
/* The chunk's n rays from `origin` in directions dirs[0..n-1] of probe `job`, after rtcIntersect1M (hits):
 * values[r] = radiance RGB (front faces: albedo x (direct + the probes' bounce / pi); back faces 0; misses
 * `sky`), the distance in cells (clamped; back faces shortened) and its square; faces updated. Returns the
 * shadow rays traced. */
uint64_t fx__probe_shade_chunk(const fx_context *ctx, const fx_block_job *job, const float origin[3],
                               const float (*dirs)[3], const struct RTCRayHit *hits, uint32_t n,
                               const float sky[3], fx_probe_faces *faces, float (*values)[5]);

/* The probes' term of a run of pixels (fx_effect.shade). */
void fx__probes_shade(const fx_context *ctx, const fx_shade_run *run);

#endif
