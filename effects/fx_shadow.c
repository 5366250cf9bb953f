/* Hard shadows (DESIGN.md "Effects"): per texel and light, FX_SHADOW_RAYS = 16 occlusion rays from 4 x 4
 * stratified, jittered points of the texel's footprint on the surface, kept as a 16-bit mask (bit i set: ray
 * i reached the light). A run may trace fewer (fx_context.shadow_rays: 1, 2, 4 or 8, strata of 1x1, 2x1, 2x2
 * or 4x2 cells): each ray then sets the bits of the 4 x 4 cells its stratum covers, so the payload, the
 * resampling and compose's reading of the mask stay the same. Frame stage 6 for the shadow effect, and the same rays per pixel for the no-cache
 * baseline.
 *
 * Sample points: sample i lies in stratum (i % 4, i / 4) of the texel's footprint square in level-0 island
 * UV, jittered by hash(seed, key, texel, i); it is mapped to the surface through the texel's triangle lookup
 * and clamped into the lookup triangle shrunk by FX_TEXEL_MARGIN of a texel (border texels sample just inside
 * the nearest triangle's edge, never on the plane of a wall that edge meets: fx_internal.h).
 * The same 16 points serve every light. Facing: a ray whose direction has dot(n, to_light) <= 0 (n the
 * geometric normal, negated for a block of the island's back: fx_block_job.back) is not traced and its bit
 * stays 0; a texel facing away from a light stores 0 with no ray. Origins leave along n, on that side.
 *
 * The no-cache baseline (fx_shadow_eval_point, about the normal of the side the viewer sees, as the
 * reference) jitters over the pixel's footprint instead, which can reach
 * past a crease onto or behind a wall: its points are checked as effects.h describes. Checking only the
 * points that leave the visible triangle keeps the baseline at 16 rays for pixels inside a triangle, which
 * is what it stands for (DESIGN.md "No-cache baseline"); clamping every point into the triangle instead would
 * shrink the footprint to the triangle on fine meshes.
 *
 * Rays: origins through scene_offset_ray_origin, batched 256 at a time into rtcOccluded1M; a (texel, light)
 * group of 16 rays is never split across batches. The caller must have called scene_tracing_thread_init() in
 * the calling thread (flush-to-zero / denormals-are-zero). */
#include "fx_internal.h"
#include "fxc_hot.h"

#include <string.h>

/* Where the result of one batched ray goes. */
typedef struct shadow_ray_target {
    uint32_t job;
    uint32_t payload_offset; /* byte offset of the texel's uint16 for this light */
    uint32_t bits;           /* the mask bits the ray's stratum covers (1 << i with 16 rays) */
} shadow_ray_target;

/* A batch of rays in flight and their targets; the ray array is 64-byte aligned for Embree's stream API. */
typedef struct shadow_batch {
    _Alignas(64) struct RTCRay rays[FX_RAY_BATCH];
    shadow_ray_target targets[FX_RAY_BATCH];
    uint32_t count;
} shadow_batch;

/* Columns of the strata grid of n rays (1, 2, 4, 8, 16): 1, 2, 2, 4, 4; rows are n / columns. */
static inline uint32_t shadow_columns(uint32_t n)
{
    return n >= 8 ? 4u : (n >= 2 ? 2u : 1u);
}

/* Rays of one stratified set: n when it is 1, 2, 4 or 8, else 16. */
static inline uint32_t shadow_set_rays(uint32_t n)
{
    return n == 1 || n == 2 || n == 4 || n == 8 ? n : FX_SHADOW_RAYS;
}

/* The rays per texel and light of a cached run (1, 2, 4, 8 or 16; anything else is taken as 16). */
static inline uint32_t shadow_texel_rays(const fx_context *ctx)
{
    return shadow_set_rays(ctx->shadow_rays);
}

/* The n jitter offsets in [0,1)^2 of the stratified pattern (n of 1, 2, 4, 8, 16: a columns x rows grid of
 * strata, ray i in stratum (i % columns, i / columns)) for hash inputs (seed, key, texel). With 16 rays this is
 * the 4 x 4 pattern whose cell i is mask bit i. */
static void shadow_jitter(uint32_t seed, uint64_t key, uint32_t texel, uint32_t n,
                          float offsets[FX_SHADOW_RAYS][2])
{
    uint32_t columns = shadow_columns(n), rows = n / columns;
    float cell_x = 1.0f / (float)columns, cell_y = 1.0f / (float)rows; /* 0.25f exactly for 4 */
    for (uint32_t i = 0; i < n; i++) {
        uint64_t h = fx__hash(seed, key, texel, i, FX_STREAM_SHADOW_JITTER);
        offsets[i][0] = ((float)(i % columns) + fx__unit_float((uint32_t)h)) * cell_x;
        offsets[i][1] = ((float)(i / columns) + fx__unit_float((uint32_t)(h >> 32))) * cell_y;
    }
}

/* The bits of the 4 x 4 mask (bit y * 4 + x) that stratum i of n rays covers. */
static uint32_t shadow_stratum_bits(uint32_t i, uint32_t n)
{
    uint32_t columns = shadow_columns(n), rows = n / columns;
    uint32_t width = 4 / columns, height = 4 / rows, x0 = (i % columns) * width, y0 = (i / columns) * height;
    uint32_t bits = 0;
    for (uint32_t y = y0; y < y0 + height; y++)
        for (uint32_t x = x0; x < x0 + width; x++)
            bits |= 1u << (y * 4 + x);
    return bits;
}

/* Direction and ray length from an origin towards a light; false when the light is behind the surface. */
static bool shadow_ray_towards(const scene_light *light, const float origin[3], const float normal[3],
                               float dir[3], float *tfar)
{
    float distance;
    fx_light_direction(light, origin, dir, &distance);
    if (!(fx__dot(normal, dir) > 0))
        return false;
    /* Point lights: stop just short of the light so geometry behind it never counts. */
    *tfar = isinf(distance) ? INFINITY : distance * (1.0f - 1e-4f);
    return true;
}

/* Traces the batch and sets the bit of every ray that reached its light. */
static void shadow_flush(const fx_context *ctx, const fx_block_job *jobs, shadow_batch *batch)
{
    fx__occluded(ctx, batch->rays, batch->count);
    for (uint32_t r = 0; r < batch->count; r++) {
        if (batch->rays[r].tfar == -INFINITY)
            continue;
        const shadow_ray_target *target = &batch->targets[r];
        uint8_t *slot = (uint8_t *)jobs[target->job].payload + target->payload_offset;
        fx__put_u16(slot, (uint16_t)(fx__get_u16(slot) | target->bits));
    }
    batch->count = 0;
}

uint64_t fx_shadow_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count)
{
    const scene *s = ctx->s;
    uint32_t light_count = s->light_count;
    if (light_count == 0 || count == 0)
        return 0;
    shadow_batch batch;
    batch.count = 0;
    uint64_t rays_traced = 0;
    uint32_t n = shadow_texel_rays(ctx);
    uint32_t stratum_bits[FX_SHADOW_RAYS];
    for (uint32_t i = 0; i < n; i++)
        stratum_bits[i] = shadow_stratum_bits(i, n);

    for (uint32_t j = 0; j < count; j++) {
        const fx_block_job *job = &jobs[j];
        for (uint64_t bits = job->mask; bits != 0; bits &= bits - 1) {
            uint32_t texel = (uint32_t)__builtin_ctzll(bits);
            float offsets[FX_SHADOW_RAYS][2], origins[FX_SHADOW_RAYS][3];
            shadow_jitter(ctx->seed, job->key, texel, n, offsets);
            fx__surface_map map;
            fx__surface_map_init(s, job->island, job->lookup[texel], fx__texel_margin(s, job->level), &map);
            float normal[3]; /* of the block's side: a back block's is negated */
            fx__side_normal(map.normal, job->back, normal);
            for (uint32_t i = 0; i < n; i++) {
                float u, v, position[3];
                fx__texel_uv(job->level, job->block_x, job->block_y, texel, offsets[i][0], offsets[i][1], &u,
                             &v);
                fx__surface_map_eval(&map, u, v, position);
                scene_offset_ray_origin(position, normal, s->ray_offset_scale, origins[i]);
            }
            for (uint32_t l = 0; l < light_count; l++) {
                uint32_t offset = (texel * light_count + l) * 2u;
                fx__put_u16((uint8_t *)job->payload + offset, 0);
                if (batch.count + n > FX_RAY_BATCH)
                    shadow_flush(ctx, jobs, &batch);
                for (uint32_t i = 0; i < n; i++) {
                    float dir[3], tfar;
                    if (!shadow_ray_towards(&s->lights[l], origins[i], normal, dir, &tfar))
                        continue;
                    fx__set_ray(&batch.rays[batch.count], origins[i], dir, tfar, batch.count);
                    batch.targets[batch.count] =
                        (shadow_ray_target){.job = j, .payload_offset = offset, .bits = stratum_bits[i]};
                    batch.count++;
                    rays_traced++;
                }
            }
        }
    }
    shadow_flush(ctx, jobs, &batch);
    return rays_traced;
}

/* Bits set per byte value: a 16-bit mask's popcount in two table reads, the same on every x86-64 (the
 * baseline build has no POPCNT instruction, and __builtin_popcount is a library call there). */
#define FX_B2(n) n, n + 1, n + 1, n + 2
#define FX_B4(n) FX_B2(n), FX_B2(n + 1), FX_B2(n + 1), FX_B2(n + 2)
#define FX_B6(n) FX_B4(n), FX_B4(n + 1), FX_B4(n + 1), FX_B4(n + 2)
static const uint8_t bits_in_byte[256] = {FX_B6(0), FX_B6(1), FX_B6(1), FX_B6(2)};
#undef FX_B2
#undef FX_B4
#undef FX_B6

static inline uint32_t popcount16(uint32_t v)
{
    return (uint32_t)bits_in_byte[v & 0xFF] + bits_in_byte[(v >> 8) & 0xFF];
}

/* The lit fraction of a texel's mask: rays that reached the light over rays traced. */
static inline float lit_fraction(uint32_t mask)
{
    return (float)popcount16(mask) * (1.0f / FX_SHADOW_RAYS);
}

/* lit_fraction inside the cloned shade: __builtin_popcount is one POPCNT in the x86-64-v3 copy (the one this
 * machine runs) and libgcc's table code in the baseline copy; the same count either way. */
static inline __attribute__((always_inline)) float lit_fraction_hot(uint32_t mask)
{
    return (float)__builtin_popcount(mask) * (1.0f / FX_SHADOW_RAYS);
}

float fx_shadow_sample(const void *payload, uint32_t texel, uint32_t light_count, uint32_t light)
{
    FX_ASSERT(texel < 64 && light < light_count);
    uint16_t mask = fx__get_u16((const uint8_t *)payload + ((size_t)texel * light_count + light) * 2u);
    return lit_fraction(mask);
}

/* fx_shadow_eval_point with n rays (1, 2, 4, 8 or 16) in n strata of the footprint. */
static float shadow_eval_rays(const fx_context *ctx, const float pos[3], const float normal[3],
                              const float dpdx[3], const float dpdy[3], uint32_t light, uint64_t pixel_id,
                              uint32_t n, uint64_t *rays)
{
    FX_ASSERT(light < ctx->s->light_count && n >= 1 && n <= FX_SHADOW_RAYS);
    const scene *s = ctx->s;
    const scene_light *lamp = &s->lights[light];
    float offsets[FX_SHADOW_RAYS][2];
    shadow_jitter(ctx->seed, pixel_id, 0, n, offsets);

    /* The centre: the visible point moved inside its triangle (a pixel on a crease lies on the wall too). */
    fx__surface_map map;
    float centre[3], centre_origin[3];
    bool located = fx__locate_point(ctx, pos, normal, 0.0f, &map, centre);
    scene_offset_ray_origin(centre, normal, s->ray_offset_scale, centre_origin);
    float reach = fx__robust_distance(centre, s->ray_offset_scale);

    /* Jittered points over the footprint. Those inside the triangle (with its margin) are on the visible
     * surface; any other may lie on or behind another surface (past a crease): it is kept only when a ray
     * from the centre reaches it, and a little beyond, without meeting anything; otherwise it is clamped into
     * the triangle (the centre itself when the triangle is unknown). */
    float points[FX_SHADOW_RAYS][3];
    _Alignas(64) struct RTCRay batch[FX_SHADOW_RAYS];
    uint32_t checks = 0;
    for (uint32_t i = 0; i < n; i++) {
        float a = offsets[i][0] - 0.5f, b = offsets[i][1] - 0.5f, origin[3], dir[3], tfar;
        for (int k = 0; k < 3; k++)
            points[i][k] = centre[k] + a * dpdx[k] + b * dpdy[k];
        double w1 = 0, w2 = 0;
        if (located) {
            fx__surface_map_bary(&map, points[i], &w1, &w2);
            if (fx__inside_margin(&map, w1, w2))
                continue;
        }
        scene_offset_ray_origin(points[i], normal, s->ray_offset_scale, origin);
        if (!shadow_ray_towards(lamp, origin, normal, dir, &tfar))
            continue; /* untraced below anyway */
        float step[3];
        double length2 = 0;
        for (int k = 0; k < 3; k++) {
            step[k] = origin[k] - centre_origin[k];
            length2 += (double)step[k] * step[k];
        }
        float length = (float)sqrt(length2);
        if (!(length > 0))
            continue;
        for (int k = 0; k < 3; k++)
            step[k] /= length;
        fx__set_ray(&batch[checks++], centre_origin, step, length + reach, i);
    }
    fx__occluded(ctx, batch, checks);
    for (uint32_t r = 0; r < checks; r++) {
        if (batch[r].tfar != -INFINITY)
            continue;
        float *point = points[batch[r].id];
        if (located) {
            double w1, w2;
            fx__surface_map_bary(&map, point, &w1, &w2);
            fx__surface_map_eval_bary(&map, w1, w2, point);
        } else {
            for (int k = 0; k < 3; k++)
                point[k] = centre[k];
        }
    }

    uint32_t traced = 0;
    for (uint32_t i = 0; i < n; i++) {
        float origin[3], dir[3], tfar;
        scene_offset_ray_origin(points[i], normal, s->ray_offset_scale, origin);
        if (shadow_ray_towards(lamp, origin, normal, dir, &tfar))
            fx__set_ray(&batch[traced++], origin, dir, tfar, i);
    }
    fx__occluded(ctx, batch, traced);
    uint32_t lit = 0;
    for (uint32_t r = 0; r < traced; r++)
        lit += batch[r].tfar != -INFINITY;
    if (rays)
        *rays = checks + traced;
    return (float)lit * (1.0f / (float)n); /* 1/16 exactly as before for 16 */
}

float fx_shadow_eval_point(const fx_context *ctx, const float pos[3], const float normal[3],
                           const float dpdx[3], const float dpdy[3], uint32_t light, uint64_t pixel_id,
                           uint64_t *rays)
{
    return shadow_eval_rays(ctx, pos, normal, dpdx, dpdy, light, pixel_id, FX_SHADOW_RAYS, rays);
}

/* The identity of shadow ray set `set` of a pixel: set 0 is the pixel's own (so 16 rays are exactly
 * fx_shadow_eval_point's), the others independent. */
static inline uint64_t shadow_set_id(uint64_t pixel_id, uint32_t set)
{
    return set == 0 ? pixel_id : fx__mix64(pixel_id ^ ((uint64_t)(set + 1) * 0x9e3779b97f4a7c15ull));
}

/* ---- the effect table ------------------------------------------------------------------------------- */

static uint32_t shadow_texel_bytes(const scene *s)
{
    return 2u * (s && s->light_count > 0 ? s->light_count : 1u);
}

static bool shadow_needs(const scene *s, char *why, size_t why_cap)
{
    return fx__scene_needs(s, SCENE_FX_SHADOW, why, why_cap);
}

/* `samples`: the run's rays per texel and light (run_samples; 0: FX_SHADOW_RAYS). */
static uint64_t shadow_cost(const scene *s, uint32_t samples)
{
    return (uint64_t)(samples ? samples : FX_SHADOW_RAYS) * (s->light_count ? s->light_count : 1u);
}

/* The run's rays per texel and light (--shadow-rays). */
static uint32_t shadow_run_samples(const fx_context *ctx)
{
    return shadow_texel_rays(ctx);
}

static uint64_t shadow_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count,
                              uint32_t samples)
{
    (void)samples;
    return fx_shadow_update(ctx, jobs, count);
}

/* The coarse texel's 4 x 4 cells from its four finer texels: each finer texel covers 2 x 2 coarse cells, and
 * a coarse cell is lit when at least two of the four finer cells under it are (per light). The mask stays a
 * map of where inside the texel the light reaches, so compose can still place edges inside it. */
static void shadow_resample(const fx_context *ctx, const void *const finer[4], void *texel)
{
    uint32_t lights = ctx->s->light_count ? ctx->s->light_count : 1u;
    for (uint32_t l = 0; l < lights; l++) {
        uint32_t mask = 0;
        for (uint32_t c = 0; c < 4; c++) { /* finer texel c sits at (c & 1, c >> 1) of the coarse one */
            uint32_t child = fx__get_u16((const uint8_t *)finer[c] + 2u * l);
            for (uint32_t qy = 0; qy < 2; qy++)
                for (uint32_t qx = 0; qx < 2; qx++) {
                    /* The 2 x 2 finer cells under coarse cell (qx, qy) of this quarter. */
                    uint32_t bits = (child >> ((2 * qy) * 4 + 2 * qx)) & 3u;
                    bits |= ((child >> ((2 * qy + 1) * 4 + 2 * qx)) & 3u) << 2;
                    if (popcount16(bits) >= 2)
                        mask |= 1u << ((2 * (c >> 1) + qy) * 4 + 2 * (c & 1) + qx);
                }
        }
        fx__put_u16((uint8_t *)texel + 2u * l, (uint16_t)mask);
    }
}

/* The tap whose texel lies (ox, oy) texels from tap `from`'s texel, or -1. */
static inline int shadow_tap_at(const fx_taps *taps, int from, int ox, int oy)
{
    for (uint32_t t = 0; t < taps->count; t++)
        if (fabsf(taps->at_x[from] - (float)ox - taps->at_x[t]) < 0.5f &&
            fabsf(taps->at_y[from] - (float)oy - taps->at_y[t]) < 0.5f)
            return (int)t;
    return -1;
}

/* For shadow_shade's fine path: the tap whose texel holds the pixel (the one with the largest weight if none
 * does exactly), the first of the four fine cells around the pixel (cx0, cy0, in cells of that texel) and
 * their bilinear weights, cell c at (c & 1, c >> 1) from the first. */
static inline __attribute__((always_inline)) void
shadow_fine_cells(const fx_taps *taps, int *home_out, float *cx0_out, float *cy0_out, float cell_weight[4])
{
    int home = 0;
    for (uint32_t t = 0; t < taps->count; t++) {
        if (taps->at_x[t] >= 0 && taps->at_x[t] < 1 && taps->at_y[t] >= 0 && taps->at_y[t] < 1) {
            home = (int)t;
            break;
        }
        if (taps->weight[t] > taps->weight[home])
            home = (int)t;
    }
    float fx = taps->at_x[home] * 4.0f - 0.5f, fy = taps->at_y[home] * 4.0f - 0.5f;
    float cx0 = floorf(fx), cy0 = floorf(fy);
    float wx = fx - cx0, wy = fy - cy0;
    /* Written out (a loop of four stayed a loop at -O2). */
    cell_weight[0] = (1 - wx) * (1 - wy);
    cell_weight[1] = wx * (1 - wy);
    cell_weight[2] = (1 - wx) * wy;
    cell_weight[3] = wx * wy;
    *home_out = home, *cx0_out = cx0, *cy0_out = cy0;
}

/* Each light's visibility at the pixel. Bit i of a texel's mask is the ray from cell (i & 3, i >> 2) of its
 * 4 x 4 stratified cells, so the masks of the taps form a sample grid four times finer than the texels.
 * A pixel much smaller than a texel (the finest level, seen from close) reads that grid bilinearly at its
 * own position, which places shadow edges inside texels (DESIGN.md, "Hard shadows") without more rays; a
 * cell whose texel holds no data takes the nearest cell of the pixel's own texel. A pixel as large as a
 * texel reads the texels' lit fractions bilinearly instead (a point sample of the fine grid would alias);
 * in between, the two are blended by the pixel's size in texels. The renormalised weights sum to 1 only to
 * within rounding: a fraction is clamped to 1 (a visibility, never a gain; found by tests/stability). */
FXC_HOT_CLONES static void shadow_shade(const fx_context *ctx, const fx_shade_run *run)
{
    (void)ctx;
    uint32_t lights = run->light_count;
    for (uint32_t i = 0; i < run->count; i++) {
        const fx_taps *taps = &run->taps[i];
        if (taps->count == 0)
            continue;
        float *visibility = run->light_visibility + (size_t)i * lights;
        if (taps->footprint_log2 >= 0.0f) { /* as large as a texel: the texels' lit fractions */
            for (uint32_t l = 0; l < lights; l++) {
                float lit = 0;
                if (taps->count == 4) { /* most pixels: the loop below written out (same sum, same order) */
                    const size_t at = 2u * l;
                    uint32_t m0 = fx__get_u16((const uint8_t *)taps->texel[0] + at);
                    uint32_t m1 = fx__get_u16((const uint8_t *)taps->texel[1] + at);
                    uint32_t m2 = fx__get_u16((const uint8_t *)taps->texel[2] + at);
                    uint32_t m3 = fx__get_u16((const uint8_t *)taps->texel[3] + at);
                    if ((m0 | m1 | m2 | m3) == 0) /* wholly shadowed: each lit fraction is 0.0f exactly */
                        lit = lit + taps->weight[0] * 0.0f + taps->weight[1] * 0.0f + taps->weight[2] * 0.0f +
                              taps->weight[3] * 0.0f;
                    else
                        lit = lit + taps->weight[0] * lit_fraction_hot(m0) +
                              taps->weight[1] * lit_fraction_hot(m1) +
                              taps->weight[2] * lit_fraction_hot(m2) + taps->weight[3] * lit_fraction_hot(m3);
                } else {
                    for (uint32_t t = 0; t < taps->count; t++)
                        lit += taps->weight[t] *
                               lit_fraction_hot(fx__get_u16((const uint8_t *)taps->texel[t] + 2u * l));
                }
                visibility[l] *= fx__min1(lit);
            }
            continue;
        }
        if (taps->count == 4 && lights != 0 && taps->footprint_log2 == taps->footprint_log2) {
            /* Four taps wholly shadowed for every light (most shadowed pixels): each light's fine sum is 0
             * and its texel average the weights times 0 in the loop's order, 0 for finite weights, which the
             * loop below takes as fine = average = 0; so each visibility is multiplied by fx__min1(0), the
             * loop's own step, without its set-up. Otherwise (a lit cell, a weight not finite) the loop. */
            float average = 0.0f + taps->weight[0] * 0.0f + taps->weight[1] * 0.0f + taps->weight[2] * 0.0f +
                            taps->weight[3] * 0.0f;
            /* The first light outside the loops (one light is the usual scene: GCC's vectorised loops cost
             * more to enter than one light's work). */
            uint32_t any_lit = (uint32_t)fx__get_u16(taps->texel[0]) | fx__get_u16(taps->texel[1]) |
                               fx__get_u16(taps->texel[2]) | fx__get_u16(taps->texel[3]);
            for (uint32_t l = 1; l < lights; l++)
                any_lit |= fx__get_u16((const uint8_t *)taps->texel[0] + 2u * l) |
                           fx__get_u16((const uint8_t *)taps->texel[1] + 2u * l) |
                           fx__get_u16((const uint8_t *)taps->texel[2] + 2u * l) |
                           fx__get_u16((const uint8_t *)taps->texel[3] + 2u * l);
            if (any_lit == 0 && average == 0.0f) {
                visibility[0] *= fx__min1(0.0f);
                for (uint32_t l = 1; l < lights; l++)
                    visibility[l] *= fx__min1(0.0f);
                continue;
            }
        }
        /* The tap whose texel holds the pixel and the four fine cells around the pixel with their bilinear
         * weights: found only for a light where some tap's mask has a lit cell (shadow_fine_cells); under
         * wholly shadowed texels (a common case) the fine sum is 0 whatever the cells. */
        bool weights_found = false;
        int home = 0;
        float cx0 = 0.0f, cy0 = 0.0f, cell_weight[4] = {0.0f, 0.0f, 0.0f, 0.0f};
        /* Which texel and bit each cell reads, found only for a light whose taps' masks differ (below). */
        bool cells_found = false;
        const uint8_t *cell_texel[4];
        uint32_t cell_bit[4];
        /* The weight of the texel average: the pixel's size, < 1. Found only for a light where it changes the
         * result: where the average equals the fine sum (both 0 under a wholly shadowed texel, most shadowed
         * pixels) fine + coarse x (average - fine) is the fine sum for every finite coarse, and coarse =
         * 2^footprint_log2 is finite unless footprint_log2 is NaN (then it is found, as before). */
        float coarse = 0.0f;
        bool coarse_found = false;
        if (taps->footprint_log2 != taps->footprint_log2) {
            coarse = exp2f(taps->footprint_log2);
            coarse_found = true;
        }
        for (uint32_t l = 0; l < lights; l++) {
            float fine = 0, average = 0;
            uint32_t any_lit = 0, all_lit = 0xFFFFu;
            if (taps->count == 4) { /* most pixels: the loops below written out (the same sums, same order) */
                const size_t at = 2u * l;
                uint32_t m0 = fx__get_u16((const uint8_t *)taps->texel[0] + at);
                uint32_t m1 = fx__get_u16((const uint8_t *)taps->texel[1] + at);
                uint32_t m2 = fx__get_u16((const uint8_t *)taps->texel[2] + at);
                uint32_t m3 = fx__get_u16((const uint8_t *)taps->texel[3] + at);
                any_lit = m0 | m1 | m2 | m3;
                all_lit = m0 & m1 & m2 & m3;
                if (any_lit == 0) { /* wholly shadowed (the common case here): the lit fractions are 0 */
                    average = average + taps->weight[0] * 0.0f + taps->weight[1] * 0.0f +
                              taps->weight[2] * 0.0f + taps->weight[3] * 0.0f;
                    if (average == 0.0f && !coarse_found) { /* fine is 0: the shortcut below, at once */
                        visibility[l] *= fx__min1(fine);
                        continue;
                    }
                } else {
                    average = average + taps->weight[0] * lit_fraction_hot(m0) +
                              taps->weight[1] * lit_fraction_hot(m1) +
                              taps->weight[2] * lit_fraction_hot(m2) + taps->weight[3] * lit_fraction_hot(m3);
                }
            } else {
                for (uint32_t t = 0; t < taps->count; t++) {
                    uint32_t mask = fx__get_u16((const uint8_t *)taps->texel[t] + 2u * l);
                    any_lit |= mask;
                    all_lit &= mask;
                }
                /* The texel average: under wholly shadowed texels (every mask 0, the common case here)
                 * each lit fraction is 0, so the same sum without the popcounts. */
                if (any_lit == 0) {
                    for (uint32_t t = 0; t < taps->count; t++)
                        average += taps->weight[t] * 0.0f;
                } else {
                    for (uint32_t t = 0; t < taps->count; t++)
                        average += taps->weight[t] *
                                   lit_fraction_hot(fx__get_u16((const uint8_t *)taps->texel[t] + 2u * l));
                }
            }
            /* Every cell reads a bit of some tap's mask: when the taps' masks are all 0 or all 0xFFFF (most
             * texels: wholly shadowed or wholly lit), every bit read is 0, or 1, and the sum below is the sum
             * of the cell weights times 0 or 1, the same floats without finding the cells. */
            if (any_lit != 0 && !weights_found) {
                weights_found = true;
                shadow_fine_cells(taps, &home, &cx0, &cy0, cell_weight);
            }
            if (all_lit == 0xFFFFu) {
                fine = fine + cell_weight[0] * 1.0f + cell_weight[1] * 1.0f + cell_weight[2] * 1.0f +
                       cell_weight[3] * 1.0f;
            } else if (any_lit != 0) {
                if (!cells_found) {
                    cells_found = true;
                    for (int c = 0; c < 4; c++) {
                        int cx = (int)cx0 + (c & 1), cy = (int)cy0 + (c >> 1);
                        int ox = cx < 0 ? -1 : (cx > 3 ? 1 : 0), oy = cy < 0 ? -1 : (cy > 3 ? 1 : 0);
                        int t = (ox || oy) ? shadow_tap_at(taps, home, ox, oy) : home;
                        if (t < 0) { /* no data there: the nearest cell of the pixel's own texel */
                            t = home;
                            ox = oy = 0;
                            cx = cx < 0 ? 0 : (cx > 3 ? 3 : cx);
                            cy = cy < 0 ? 0 : (cy > 3 ? 3 : cy);
                        }
                        cell_texel[c] = taps->texel[t];
                        cell_bit[c] = (uint32_t)((cy - 4 * oy) * 4 + (cx - 4 * ox));
                    }
                }
                for (int c = 0; c < 4; c++) {
                    uint32_t mask = fx__get_u16(cell_texel[c] + 2u * l);
                    fine += cell_weight[c] * (float)((mask >> cell_bit[c]) & 1u);
                }
            }
            if (average == fine && fine - fine == 0.0f && !coarse_found) { /* fine finite */
                visibility[l] *= fx__min1(fine);
                continue;
            }
            if (!coarse_found) {
                coarse = exp2f(taps->footprint_log2);
                coarse_found = true;
            }
            if (!(coarse > 0))
                average = 0;
            visibility[l] *= fx__min1(fine + coarse * (average - fine));
        }
    }
}

/* The baseline: ctx->shadow_rays per light (default 16) over the pixel's footprint; up to 16 in one stratified
 * set, more in sets of 16 (as the reference), each set with its own jitter. */
static uint64_t shadow_eval(const fx_context *ctx, const fx_point *point, fx_shade_point *out)
{
    uint32_t n = ctx->shadow_rays ? ctx->shadow_rays : FX_SHADOW_RAYS;
    if (n > FX_SHADOW_POINT_RAYS_MAX)
        n = FX_SHADOW_POINT_RAYS_MAX;
    uint32_t per_set = n > FX_SHADOW_RAYS ? FX_SHADOW_RAYS : shadow_set_rays(n);
    uint32_t sets = n > FX_SHADOW_RAYS ? n / FX_SHADOW_RAYS : 1;
    uint64_t rays = 0;
    for (uint32_t l = 0; l < ctx->s->light_count; l++) {
        float lit = 0;
        for (uint32_t set = 0; set < sets; set++) {
            uint64_t r = 0;
            lit += shadow_eval_rays(ctx, point->position, point->view_normal, point->dpdx, point->dpdy, l,
                                    shadow_set_id(point->pixel_id, set), per_set, &r);
            rays += r;
        }
        out->light_visibility[l] *= sets == 1 ? lit : lit / (float)sets;
    }
    return rays;
}

/* The reference: `samples` rays per light over the pixel's footprint, in sets of FX_SHADOW_RAYS jittered in
 * 4 x 4 strata as the baseline's (each set checked at creases the same way), each set with its own jitter. */
static uint64_t shadow_reference(const fx_context *ctx, const fx_point *point, uint32_t samples,
                                 fx_shade_point *out)
{
    FX_ASSERT(samples >= FX_SHADOW_RAYS && samples % FX_SHADOW_RAYS == 0);
    uint32_t sets = samples / FX_SHADOW_RAYS;
    uint64_t rays = 0;
    for (uint32_t l = 0; l < ctx->s->light_count; l++) {
        double lit = 0;
        for (uint32_t set = 0; set < sets; set++) {
            uint64_t r = 0;
            uint64_t set_id = fx__mix64(point->pixel_id ^ ((uint64_t)(set + 1) * 0x9e3779b97f4a7c15ull));
            lit += fx_shadow_eval_point(ctx, point->position, point->view_normal, point->dpdx, point->dpdy, l,
                                        set_id, &r);
            rays += r;
        }
        out->light_visibility[l] *= (float)(lit / sets);
    }
    return rays;
}

/* Hard shadows: 16 rays per texel and light (the run's shadow_rays), computed once. */
const fx_effect fx_effect_shadow = {
    .name = "shadow",
    .alias = "shadows",
    .cache = SCENE_CACHE_ON_SURFACE,
    .level_bias = 0, /* hard shadow edges are high frequency */
    .filter = FX_FILTER_BILINEAR,
    .policy = FX_UPDATE_ONCE,
    .depends_on = "triangle_lookup",
    .texel_bytes = shadow_texel_bytes,
    .needs = shadow_needs,
    .cost = shadow_cost,
    .run_samples = shadow_run_samples,
    .update = shadow_update,
    .resample = shadow_resample,
    .shade = shadow_shade,
    .eval = shadow_eval,
    .reference = shadow_reference,
    .reference_samples = 256, /* 16 times the cache's 16 per texel */
    .reference_granule = FX_SHADOW_RAYS,
    .reference_unit = "rays per light",
};
