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
 * This file: update (rays, gather, relocation), commit and the effect's table; fx_probes_hits.c: the hits of
 * the update's rays (shadow rays, the bounce at hits and its memo) and the no-cache estimate; fx_probes_map.c:
 * the maps, their readers and compose's shade.
 *
 * Update of one probe (a job, brick size 1): probe_rays rays in a spherical Fibonacci set, rotated by a
 * uniform random rotation from hash(seed, frame) shared by every probe of the frame (RTXGI rotates a volume's
 * rays once per update the same way; without a frame number, ctx->frame 0, from hash(seed, update count)),
 * from the probe's (relocated) position:
 *   - front-face hit: radiance = albedo x (direct light at the hit, shadow rays to every light, as compose
 *     lights it + E_probes / pi), E_probes the committed probes around the hit at the job's level with the
 *     update's filter (below, "The bounce at hits"), the hit's cell read through ctx->world_cell and kept
 *     per thread for the frame (hit_bounce; through ctx->world_taps per hit when world_cell is NULL, the same
 *     filter); where none contributes, the probes of the 4 coarser levels around the hit, then the updating
 *     probe's own irradiance towards the hit's normal (fx_probes_hits.c, hit_bounce_coarser, own_bounce):
 *     light bounces once more every frame; the albedo is the triangle's mean (below); plus the
 *     emission of an emitting material (scene_material.emission; scenes with emitters only), which is how an
 *     emitter's light reaches the surfaces around it;
 *   - back-face hit: radiance 0, counted, distance shortened to 0.2 t (RTXGI), so the visibility moments see
 *     the wall as near;
 *   - miss: the sky's radiance, distance the maximum.
 * Distances are clamped to 1.5 sqrt(3) cell (RTXGI's maximum). Per texel direction d_t, the new irradiance is
 * pi sum(max(0, d_t.d_i) L_i) / sum(max(0, d_t.d_i)) (the cosine-weighted integral, normalised by the
 * quadrature's own weight sum), and the moments sum(w d) / sum(w), sum(w d^2) / sum(w) with w = max(0,
 * d_t.d_i)^FX_PROBE_DEPTH_POWER. These, the back-face fraction, the off decision and the relocated position
 * go to the job's scratch; commit blends them into the payload: old x k + new x (1 - k), except that the
 * first update after the probe was created or switched on is taken as is. The moments keep k = h =
 * ctx->probe_hysteresis; the irradiance's k comes from the change-aware blend (below), or is h with
 * ctx->probe_plain_blend (plain hysteresis: a step settles as h^k exactly).
 *
 * The change-aware blend. With the bounce read from the probes' previous irradiance, plain hysteresis shrinks
 * the error by h + (1 - h) rho per update: at h = 0.97, 305 frames to 1 % inside a closed sphere of albedo
 * 0.5, 1,533 at 0.9. RTXGI lowers the hysteresis by 0.75 where a texel changes by more than an absolute
 * threshold; here the test is relative and statistical, per probe: each update's relative change of the
 * map's total, m = sum(new - old) / sum(new + old), against the update's own noise, the standard deviation
 * of that total estimated from the even and the odd rays apart (half their estimates' difference: update,
 * total_spread). Commit keeps an exponential mean of m (memory FX_PROBE_DRIFT_MEMORY 0.75) and of the noise's
 * square (FX_PROBE_NOISE_MEMORY 0.9) in the payload (effects.h), and z = |mean| / the mean's standard
 * deviation under noise alone (sqrt(variance (1 - a) / (1 + a))): k = h up to z = FX_PROBE_DRIFT_Z_LOW (4),
 * FX_PROBE_FAST_KEEP (0: the update taken whole) from FX_PROBE_DRIFT_Z_HIGH (7), linear between. A light
 * switched on or off, or bounces still building up, move the total consistently and far beyond the noise: the
 * probe follows at the fastest rate the one-bounce-per-frame iteration allows (rho per update: 7 frames to
 * 1 % at albedo 0.5, 44 at 0.9, tests/test_probes_converge.c); where the estimate only fluctuates, z stays
 * below 4 and the probe keeps h, so it flickers no more than under plain hysteresis (same test: 16 rays per
 * update, where the two halves' estimate of the noise is poorest). Every blend stays a convex mix of old and
 * new, so nothing overshoots that plain hysteresis would not. Per probe, not per texel: a light moving from
 * one side of a probe to the other changes its texels both ways and its total little, and keeps h (what
 * RTXGI's per-texel threshold would catch). A probe that stays dark (sum 0) keeps its state; one switched off
 * or created starts with mean and variance 0 (its first update is taken whole anyway).
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
    for (uint32_t i = 0; i < n;
         i++) { /* selects only: && or a bool mixed into integers stop the vectoriser */
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
    float moments[FX_PROBE_TEXELS][2]; /* new mean distance and squared distance, cells */
    float moment_weight[FX_PROBE_TEXELS];
    float position[3];  /* relocated position for the next update */
    float total_spread; /* half the difference of the even and the odd rays' estimates of the map's total
                           (commit: the update's own noise; INFINITY when a half has no weight) */
    float backface_fraction;
    uint32_t off;
    uint32_t moved_out;  /* FX_PROBE_MOVED_OUT for the payload */
    uint32_t seen_front; /* FX_PROBE_SEEN_FRONT for the payload */
    uint32_t valid;      /* 1 once update wrote it */
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
_Static_assert((int)PROBE_TABLE_RAYS >= (int)PROBE_CHUNK && (int)PROBE_TABLE_RAYS % (int)PROBE_CHUNK == 0,
               "table rows");

typedef struct probe_directions {
    uint64_t h1, h2; /* the hashes the rotation came from, seed included (valid when rays != 0) */
    uint32_t rays;   /* 0: none yet */
    float dir[FX_PROBE_MAX_RAYS][3];
    _Alignas(64) float cosine[PROBE_TABLE_RAYS][FX_PROBE_TEXELS];
    _Alignas(64) float lobe[PROBE_TABLE_RAYS][FX_PROBE_TEXELS];
    float cosine_sum[FX_PROBE_TEXELS], lobe_sum[FX_PROBE_TEXELS]; /* over all rays (table or not) */
    /* Ray i's share of the map's total: sum over texels of cosine[i][t] / cosine_sum[t] (texels with weight);
     * the map's total irradiance (RGB and texels summed) is pi sum_i ray_share[i] (r + g + b)_i. parity_share:
     * the shares' sums over the even and the odd rays (all shares sum to the texels with weight). */
    float ray_share[FX_PROBE_MAX_RAYS], parity_share[2];
} probe_directions;

/* Rows [first, first + n) of the weights into rows [row, row + n) of the table; adds them to the sums when
 * `sum`. Each texel's sum runs in ray order. */
FXC_HOT_CLONES static void direction_weights(probe_directions *restrict pd, uint32_t first, uint32_t n,
                                             uint32_t row, bool sum)
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
            pd->dir[i][k] =
                rotation[3 * k] * fib[0] + rotation[3 * k + 1] * fib[1] + rotation[3 * k + 2] * fib[2];
    }
    memset(pd->cosine_sum, 0, sizeof pd->cosine_sum);
    memset(pd->lobe_sum, 0, sizeof pd->lobe_sum);
    for (uint32_t first = 0; first < rays; first += PROBE_CHUNK) {
        uint32_t n = rays - first < PROBE_CHUNK ? rays - first : PROBE_CHUNK;
        /* Beyond the table only the sums are kept (the rows land in the first chunk's, overwritten). */
        direction_weights(pd, first, n, rays <= PROBE_TABLE_RAYS ? first : 0, true);
    }
    /* The rays' shares of the total (the change-aware blend's noise estimate); beyond the table the rows are
     * computed once more, chunk by chunk. */
    float inverse_sum[FX_PROBE_TEXELS];
    for (uint32_t tx = 0; tx < FX_PROBE_TEXELS; tx++)
        inverse_sum[tx] = pd->cosine_sum[tx] > 0 ? 1.0f / pd->cosine_sum[tx] : 0.0f;
    pd->parity_share[0] = pd->parity_share[1] = 0;
    for (uint32_t first = 0; first < rays; first += PROBE_CHUNK) {
        uint32_t n = rays - first < PROBE_CHUNK ? rays - first : PROBE_CHUNK, row = first;
        if (rays > PROBE_TABLE_RAYS) {
            direction_weights(pd, first, n, 0, false);
            row = 0;
        }
        for (uint32_t r = 0; r < n; r++) {
            float share = 0;
            for (uint32_t tx = 0; tx < FX_PROBE_TEXELS; tx++)
                share += pd->cosine[row + r][tx] * inverse_sum[tx];
            pd->ray_share[first + r] = share;
            pd->parity_share[(first + r) & 1] += share;
        }
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
static _Thread_local probe_scratch thread_scratch;
static _Thread_local probe_directions thread_directions; /* 180 KB: the frame's rays and weights */

FXC_HOT_CLONES uint64_t fx_probes_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count)
{
    const scene *s = ctx->s;
    const uint32_t rays = probe_ray_count(ctx);
    gather_sums sums, *acc = &sums;
    float sky[3];
    for (int k = 0; k < 3; k++)
        sky[k] = s->sky_color[k] * s->sky_intensity;
    struct RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCScene rtc = (RTCScene)scene_rt_handle(ctx->rt);
    _Alignas(64) struct RTCRayHit hits[PROBE_CHUNK];
    float values[PROBE_CHUNK][5]; /* per ray: radiance RGB, distance and its square (cells) */
    probe_scratch *out = &thread_scratch;
    probe_directions *pd = &thread_directions;
    const bool table = rays <= PROBE_TABLE_RAYS;
    uint64_t traced = 0;
    fx__probe_hits_begin(ctx);

    for (uint32_t j = 0; j < count; j++) {
        const fx_block_job *job = &jobs[j];
        FX_ASSERT(job->scratch != NULL && job->cell > 0);
        const uint8_t *payload = job->payload;
        uint32_t flags = get_u32(payload + 16), updates = get_u32(payload + 20) & 0xffffu;
        float cell = job->cell, origin[3], offset[3];
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
        directions_prepare(pd, rays, fx__hash(ctx->seed, rotation_key, 0, 0, FX_STREAM_PROBE_ROTATION),
                           fx__hash(ctx->seed, rotation_key, 1, 0, FX_STREAM_PROBE_ROTATION));
        memset(out, 0, sizeof *out);
        memset(acc, 0, sizeof *acc);
        fx_probe_faces faces = {.closest_front = INFINITY, .closest_back = INFINITY};
        float parity_total[2] = {0, 0}; /* sum of ray_share x (r + g + b) over the even and the odd rays */

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

            /* The hits' radiance (shadow rays, the bounce) and distances, and the faces seen: fx_probes_hits.c. */
            traced += fx__probe_shade_chunk(ctx, job, origin, (const float(*)[3])pd->dir + first, hits, n,
                                            sky, &faces, values);
            /* Into the texels (file comment): the weight rows of these rays, from the table or computed. */
            for (uint32_t r = 0; r < n; r++)
                parity_total[(first + r) & 1] +=
                    pd->ray_share[first + r] * (values[r][0] + values[r][1] + values[r][2]);
            if (!table)
                direction_weights(pd, first, n, 0, false);
            gather_chunk(pd, table ? first : 0, n, (const float(*)[5])values, acc);
        }
        const uint32_t backfaces = faces.backfaces;
        const float closest_front = faces.closest_front, closest_back = faces.closest_back;
        const float *front_dir = faces.front_dir, *back_dir = faces.back_dir;
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

        /* Each half's estimate of the total, pi parity_total[p] x (all shares / its shares); the full update's
         * is about their mean, with the variance of half their difference squared. */
        float shares = pd->parity_share[0] + pd->parity_share[1];
        out->total_spread =
            pd->parity_share[0] > 0 && pd->parity_share[1] > 0
                ? 0.5f * FX_PROBE_PI * shares *
                      (parity_total[0] / pd->parity_share[0] - parity_total[1] / pd->parity_share[1])
                : INFINITY;

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
                next[k] =
                    fminf(fmaxf(next[k] + back_dir[k] * (closest_back + 0.5f * min_front), -limit), limit);
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

/* ---- commit ---------------------------------------------------------------------------------------- */

/* The change-aware blend's state: the mean m of an update's relative change (below) and the variance of m
 * about that mean, as the exponential averages of updates so far. Stored as halves (sign-magnitude, rounded
 * to nearest) in the high 16 bits of the flags word (mean) and of the update-count word (variance). */
typedef struct probe_drift {
    float mean, variance;
} probe_drift;

static float drift_half_to_float(uint32_t bits)
{
    float magnitude = half_bits_to_float(bits & 0x7fffu);
    return (bits & 0x8000u) ? -magnitude : magnitude;
}

static uint32_t drift_float_to_half(float x)
{
    float magnitude = fabsf(x), half_u = 0.5f; /* u = 1/2: nearest (ties down) */
    uint16_t bits;
    halves_stochastic(&magnitude, &half_u, 1, &bits);
    return (uint32_t)bits | (x < 0 && bits != 0 ? 0x8000u : 0u);
}

static probe_drift drift_read(uint32_t flags, uint32_t updates_word)
{
    return (probe_drift){drift_half_to_float(flags >> 16), drift_half_to_float(updates_word >> 16)};
}

/* The next state after an update whose texels changed by d_t = new - old (RGB summed; texels the update
 * gave weight only): m = sum(d_t) / sum(new + old) in [-1, 1] (0 when both are 0), the signed relative change
 * of the probe's total irradiance, and its noise n = spread / sum(new + old), spread the update's own estimate
 * of the standard deviation of its total (update: the even and the odd rays apart); mean <- a mean + (1 - a) m,
 * variance <- b variance + (1 - b) n^2 (a = FX_PROBE_DRIFT_MEMORY, b = FX_PROBE_NOISE_MEMORY). A probe that
 * was and stays dark (sum 0) keeps its state. */
static probe_drift probe_drift_next(probe_drift state, const float *new_irradiance, const float *old_values,
                                    const float *irradiance_weight, float spread)
{
    float change = 0, total = 0;
    for (uint32_t i = 0; i < 3 * FX_PROBE_TEXELS; i++) {
        bool counted = irradiance_weight[i] > 0;
        change += counted ? new_irradiance[i] - old_values[i] : 0.0f;
        total += counted ? new_irradiance[i] + old_values[i] : 0.0f;
    }
    if (!(total > 0 && total <= FLT_MAX && change == change))
        return state; /* all dark (or not finite): nothing to learn from */
    float m = change / total;
    m = m > -1.0f ? (m < 1.0f ? m : 1.0f) : -1.0f;
    float noise = fabsf(spread) / total; /* NaN (infinite spread: a half without rays): 1 below */
    noise = noise < 1.0f ? noise : 1.0f;
    probe_drift next;
    next.mean = FX_PROBE_DRIFT_MEMORY * state.mean + (1.0f - FX_PROBE_DRIFT_MEMORY) * m;
    next.variance = FX_PROBE_NOISE_MEMORY * state.variance + (1.0f - FX_PROBE_NOISE_MEMORY) * noise * noise;
    return next;
}

/* The irradiance's keep weight for steady-state hysteresis h: z = |mean| / (its standard deviation under
 * noise alone, sqrt(variance (1 - a) / (1 + a)) for an average of memory a of independent m); h while z <=
 * FX_PROBE_DRIFT_Z_LOW, FX_PROBE_FAST_KEEP (or h if smaller) from FX_PROBE_DRIFT_Z_HIGH, linear between. */
static float probe_adaptive_keep(float h, probe_drift state)
{
    const float spread = (1.0f - FX_PROBE_DRIFT_MEMORY) / (1.0f + FX_PROBE_DRIFT_MEMORY);
    float noise = sqrtf(state.variance * spread) + 1e-7f, z = fabsf(state.mean) / noise;
    float g = (z - FX_PROBE_DRIFT_Z_LOW) * (1.0f / (FX_PROBE_DRIFT_Z_HIGH - FX_PROBE_DRIFT_Z_LOW));
    g = g > 0 ? (g < 1 ? g : 1.0f) : 0.0f; /* NaN: 0 */
    float fast = FX_PROBE_FAST_KEEP < h ? FX_PROBE_FAST_KEEP : h;
    return h + (fast - h) * g;
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
        uint32_t flags = get_u32(p + 16), updates_word = get_u32(p + 20), updates = updates_word & 0xffffu;
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
        float old_scale = fresh ? 0.0f : get_f32(p + 24), irradiance[IRRADIANCE_HALVES],
              moments[MOMENT_HALVES];
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
        float old_values[IRRADIANCE_HALVES];
        for (uint32_t i = 0; i < IRRADIANCE_HALVES;
             i++) /* payload halves are halves_stochastic's: finite, >= 0 */
            old_values[i] = old_scale * half_bits_to_float(old_irradiance[i]);
        /* The change-aware blend (file comment): the irradiance's keep weight from the drift's coherence. */
        probe_drift drift = {0, 0};
        float keep_irradiance = keep;
        if (!fresh && !ctx->probe_plain_blend) {
            drift = probe_drift_next(drift_read(flags, updates_word), new_irradiance, old_values,
                                     irradiance_weight, in->total_spread);
            keep_irradiance = probe_adaptive_keep(h, drift);
        }
        const float take_irradiance = fresh ? take : 1.0f - keep_irradiance;
        for (uint32_t i = 0; i < IRRADIANCE_HALVES; i++) {
            float old = old_values[i];
            float blended = keep_irradiance * old + take_irradiance * new_irradiance[i];
            float value = irradiance_weight[i] > 0 ? blended : old;
            value = value > 0 ? value : 0.0f;                   /* <= 0, -inf and NaN: 0 */
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
                            (in->seen_front ? FX_PROBE_SEEN_FRONT : 0u) |
                            drift_float_to_half(drift.mean) << 16);
        put_u32(p + 20, (updates < 0xffffu ? updates + 1 : 0xffffu) | drift_float_to_half(drift.variance)
                                                                          << 16);
    }
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

static uint64_t probes_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count,
                              uint32_t samples)
{
    (void)samples;
    return fx_probes_update(ctx, jobs, count);
}

static uint32_t probes_texel_samples(const void *texel)
{
    return get_u32((const uint8_t *)texel + 20) & 0xffffu;
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
