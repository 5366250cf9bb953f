/* Ambient occlusion (DESIGN.md "Effects"): cosine-weighted occlusion rays of length ao_radius, accumulated
 * progressively up to the run's maximum per texel (fx_context.ao_samples, default FX_AO_MAX_SAMPLES = 64;
 * frame stage 6 for AO), and the same rays per pixel for the no-cache baseline.
 *
 * Payload, texel t at bytes 4t: uint16 fraction of unoccluded rays (unorm16, little-endian), uint16 count.
 * Every ray is either occluded or not, so the stored mean is U / count for an integer U <= count; unorm16
 * rounds it by at most 1/131070, so U is recovered exactly as round(fraction * count) while that error times
 * the count stays below 1/2, i.e. for counts below 65535 (the maximum is FX_AO_SAMPLES_LIMIT = 4096). Adding samples is
 * therefore exact integer arithmetic: a texel given 16+16+16+16 samples over four frames stores bit for bit
 * what one given 64 at once stores.
 *
 * Sample k of a texel (k counts on from the stored count, so budget splits do not matter) uses two 2D points
 * of an Owen-scrambled Sobol sequence indexed by k, scrambled per texel by hash(seed, key, texel): one places
 * the ray origin inside the texel's footprint (mapped to the surface through the triangle lookup, and kept
 * FX_TEXEL_MARGIN of a texel inside the lookup triangle's edges, so a texel at a crease never samples the
 * wall's plane), the other gives the cosine-weighted direction about the lookup triangle's geometric normal
 * (Duff et al. basis), negated for a block of the island's back (fx_block_job.back: rays leave on the side
 * the viewer sees). The first 16, 32 and 64 samples are each stratified in both, which lowers the error
 * against pure random.
 *
 * The no-cache baseline traces from the visible point itself, after moving it inside the triangle it lies on
 * (fx__locate_point), about the normal of the side the viewer sees: a pixel exactly on a crease would
 * otherwise start every ray on the wall's plane.
 *
 * Rays: origins through scene_offset_ray_origin (along the normal: every AO ray leaves on that side),
 * batched 256 at a time into rtcOccluded1M; a texel's rays are never split across batches. The caller must
 * have called scene_tracing_thread_init() in this thread. */
#include "fx_internal.h"
#include "fxc_hot.h"

#include <string.h>

/* One texel being updated in the current batch. */
typedef struct ao_pending {
    uint8_t *texel_bytes; /* the texel's 4 payload bytes */
    uint32_t unoccluded;  /* rays that escaped, stored samples plus this batch */
    uint32_t count;       /* stored samples */
    uint32_t added;       /* samples traced in this batch */
} ao_pending;

/* A batch of rays in flight; rays[r] belongs to pending[owner[r]]. 64-byte aligned for the stream API. */
typedef struct ao_batch {
    _Alignas(64) struct RTCRay rays[FX_RAY_BATCH];
    uint16_t owner[FX_RAY_BATCH];
    ao_pending pending[FX_RAY_BATCH];
    uint32_t ray_count, pending_count;
} ao_batch;

/* The samples a texel converges at in this run. */
static inline uint32_t ao_max_samples(const fx_context *ctx)
{
    uint32_t max = ctx->ao_samples ? ctx->ao_samples : FX_AO_MAX_SAMPLES;
    return max > FX_AO_SAMPLES_LIMIT ? FX_AO_SAMPLES_LIMIT : max;
}

/* Traces the batch, then writes every pending texel's new mean and count (saturating). */
static void ao_flush(const fx_context *ctx, ao_batch *batch)
{
    uint32_t max = ao_max_samples(ctx);
    fx__occluded(ctx, batch->rays, batch->ray_count);
    for (uint32_t r = 0; r < batch->ray_count; r++)
        batch->pending[batch->owner[r]].unoccluded += batch->rays[r].tfar != -INFINITY;
    for (uint32_t p = 0; p < batch->pending_count; p++) {
        const ao_pending *texel = &batch->pending[p];
        uint32_t total = texel->count + texel->added;
        uint32_t fraction = (uint32_t)lrint((double)texel->unoccluded * 65535.0 / (double)total);
        fx__put_u16(texel->texel_bytes, (uint16_t)(fraction > 65535u ? 65535u : fraction));
        fx__put_u16(texel->texel_bytes + 2, (uint16_t)(total > max ? max : total));
    }
    batch->ray_count = 0;
    batch->pending_count = 0;
}

/* The ray of AO sample `index` leaving a surface point (position, unit normal with basis tangent,
 * bitangent): origin and direction. */
static void ao_ray(const float position[3], const float normal[3], const float tangent[3],
                   const float bitangent[3], uint64_t direction_hash, uint32_t index, float offset_scale,
                   float origin[3], float dir[3])
{
    float xi[2];
    fx__sobol_2d(index, direction_hash, xi);
    fx__cosine_direction(normal, tangent, bitangent, xi, dir);
    scene_offset_ray_origin(position, normal, offset_scale, origin);
}

uint64_t fx_ao_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count, uint32_t samples)
{
    FX_ASSERT(ctx->ao_radius > 0);
    if (count == 0 || samples == 0)
        return 0;
    ao_batch batch;
    batch.ray_count = batch.pending_count = 0;
    uint64_t rays_traced = 0;
    uint32_t max = ao_max_samples(ctx);

    for (uint32_t j = 0; j < count; j++) {
        const fx_block_job *job = &jobs[j];
        float margin = fx__texel_margin(ctx->s, job->level);
        for (uint64_t bits = job->mask; bits != 0; bits &= bits - 1) {
            uint32_t texel = (uint32_t)__builtin_ctzll(bits);
            uint8_t *texel_bytes = (uint8_t *)job->payload + 4u * texel;
            uint32_t stored = fx__get_u16(texel_bytes + 2);
            if (stored >= max)
                continue; /* converged (a larger stored count saturates here too) */
            uint32_t add = max - stored;
            add = samples < add ? samples : add;
            add = add < FX_RAY_BATCH ? add
                                     : FX_RAY_BATCH; /* a texel's rays fit one batch; the rest next time */
            /* Recover the exact number of unoccluded rays from the stored mean. */
            long unoccluded = stored ? lrint((double)fx__get_u16(texel_bytes) * stored / 65535.0) : 0;
            if (unoccluded > (long)stored)
                unoccluded = (long)stored;

            if (batch.ray_count + add > FX_RAY_BATCH)
                ao_flush(ctx, &batch);
            uint32_t owner = batch.pending_count++;
            batch.pending[owner] = (ao_pending){.texel_bytes = texel_bytes,
                                                .unoccluded = (uint32_t)unoccluded,
                                                .count = stored,
                                                .added = add};

            uint64_t origin_hash = fx__hash(ctx->seed, job->key, texel, 0, FX_STREAM_AO_ORIGIN);
            uint64_t direction_hash = fx__hash(ctx->seed, job->key, texel, 0, FX_STREAM_AO_DIRECTION);
            fx__surface_map map;
            fx__surface_map_init(ctx->s, job->island, job->lookup[texel], margin, &map);
            float normal[3], tangent[3], bitangent[3]; /* of the block's side: a back block's is negated */
            fx__side_normal(map.normal, job->back, normal);
            fx__onb(normal, tangent, bitangent);
            for (uint32_t k = stored; k < stored + add; k++) {
                float jitter[2], u, v, position[3], origin[3], dir[3];
                fx__sobol_2d(k, origin_hash, jitter);
                fx__texel_uv(job->level, job->block_x, job->block_y, texel, jitter[0], jitter[1], &u, &v);
                fx__surface_map_eval(&map, u, v, position);
                ao_ray(position, normal, tangent, bitangent, direction_hash, k, ctx->s->ray_offset_scale,
                       origin, dir);
                fx__set_ray(&batch.rays[batch.ray_count], origin, dir, ctx->ao_radius, batch.ray_count);
                batch.owner[batch.ray_count++] = (uint16_t)owner;
            }
            rays_traced += add;
        }
    }
    ao_flush(ctx, &batch);
    return rays_traced;
}

float fx_ao_sample(const void *payload, uint32_t texel)
{
    FX_ASSERT(texel < 64);
    return (float)fx__get_u16((const uint8_t *)payload + 4u * texel) / 65535.0f; /* 65535 -> 1 exactly */
}

uint32_t fx_ao_count(const void *payload, uint32_t texel)
{
    FX_ASSERT(texel < 64);
    return fx__get_u16((const uint8_t *)payload + 4u * texel + 2);
}

float fx_ao_eval_point(const fx_context *ctx, const float pos[3], const float normal[3], uint32_t samples,
                       uint64_t pixel_id, uint64_t *rays)
{
    FX_ASSERT(ctx->ao_radius > 0);
    if (rays)
        *rays = samples;
    if (samples == 0)
        return 1.0f; /* nothing known to occlude */
    _Alignas(64) struct RTCRay batch[FX_RAY_BATCH];
    uint64_t direction_hash = fx__hash(ctx->seed, pixel_id, 0, 0, FX_STREAM_AO_DIRECTION);
    /* A point exactly on a crease lies on the wall's plane too: move it inside its own triangle first. */
    fx__surface_map map;
    float point[3];
    fx__locate_point(ctx, pos, normal, 0.0f, &map, point);
    float tangent[3], bitangent[3];
    fx__onb(normal, tangent, bitangent);
    uint32_t unoccluded = 0;
    for (uint32_t first = 0; first < samples; first += FX_RAY_BATCH) {
        uint32_t n = samples - first < FX_RAY_BATCH ? samples - first : FX_RAY_BATCH;
        for (uint32_t r = 0; r < n; r++) {
            float origin[3], dir[3];
            ao_ray(point, normal, tangent, bitangent, direction_hash, first + r, ctx->s->ray_offset_scale,
                   origin, dir);
            fx__set_ray(&batch[r], origin, dir, ctx->ao_radius, r);
        }
        fx__occluded(ctx, batch, n);
        for (uint32_t r = 0; r < n; r++)
            unoccluded += batch[r].tfar != -INFINITY;
    }
    return (float)((double)unoccluded / (double)samples);
}

/* ---- the effect table ------------------------------------------------------------------------------- */

static uint32_t ao_texel_bytes(const scene *s)
{
    (void)s;
    return 4;
}

static bool ao_needs(const scene *s, char *why, size_t why_cap)
{
    return fx__scene_needs(s, SCENE_FX_AO, why, why_cap);
}

static uint64_t ao_cost(const scene *s, uint32_t samples)
{
    (void)s;
    return samples;
}

static uint64_t ao_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count, uint32_t samples)
{
    return fx_ao_update(ctx, jobs, count, samples);
}

static uint32_t ao_texel_samples(const void *texel)
{
    return fx_ao_count(texel, 0);
}

/* The run's convergence count (--ao-samples). */
static uint32_t ao_run_samples(const fx_context *ctx)
{
    return ao_max_samples(ctx);
}

/* The mean of four converged finer texels, itself converged. */
static void ao_resample(const fx_context *ctx, const void *const finer[4], void *texel)
{
    float mean = 0;
    for (int c = 0; c < 4; c++)
        mean += 0.25f * fx_ao_sample(finer[c], 0);
    fx__put_u16(texel, (uint16_t)lrintf(fminf(fmaxf(mean, 0.0f), 1.0f) * 65535.0f));
    fx__put_u16((uint8_t *)texel + 2, (uint16_t)ao_max_samples(ctx));
}

/* The sky's visibility: the filtered unoccluded fraction. The renormalised weights sum to 1 only to within
 * rounding, so four texels of 1 can give 1 + 2^-23: the fraction is clamped to 1 (a visibility, never a
 * gain; found by tests/stability). */
FXC_HOT_CLONES static void ao_shade(const fx_context *ctx, const fx_shade_run *run)
{
    (void)ctx;
    for (uint32_t i = 0; i < run->count; i++) {
        const fx_taps *taps = &run->taps[i];
        if (taps->count == 0)
            continue;
        float ao = 0;
        if (taps->count ==
            4) { /* most pixels: the loop below written out (the same sum, in the same order) */
            ao = ao + taps->weight[0] * fx__unorm16(fx__get_u16(taps->texel[0])) +
                 taps->weight[1] * fx__unorm16(fx__get_u16(taps->texel[1])) +
                 taps->weight[2] * fx__unorm16(fx__get_u16(taps->texel[2])) +
                 taps->weight[3] * fx__unorm16(fx__get_u16(taps->texel[3]));
        } else {
            for (uint32_t t = 0; t < taps->count; t++)
                ao += taps->weight[t] * fx__unorm16(fx__get_u16(taps->texel[t])); /* fx_ao_sample(texel, 0) */
        }
        run->sky_visibility[i] *= fx__min1(ao);
    }
}

/* The baseline: the run's samples from the side the viewer sees, as the cache's texels of that side. */
static uint64_t ao_eval(const fx_context *ctx, const fx_point *point, fx_shade_point *out)
{
    uint64_t rays = 0;
    *out->sky_visibility *= fx_ao_eval_point(ctx, point->position, point->view_normal, ao_max_samples(ctx),
                                             point->pixel_id, &rays);
    return rays;
}

/* The reference: `samples` rays from the side the viewer sees, one Sobol set scrambled by the pixel id. */
static uint64_t ao_reference(const fx_context *ctx, const fx_point *point, uint32_t samples,
                             fx_shade_point *out)
{
    uint64_t rays = 0;
    *out->sky_visibility *=
        fx_ao_eval_point(ctx, point->position, point->view_normal, samples, point->pixel_id, &rays);
    return rays;
}

/* Ambient occlusion: progressive to 64 cosine-weighted samples per texel (the run's ao_samples), one level
 * coarser by default. */
const fx_effect fx_effect_ao = {
    .name = "ao",
    .cache = SCENE_CACHE_ON_SURFACE,
    .level_bias = 1, /* low frequency: one level coarser */
    .filter = FX_FILTER_BILINEAR,
    .policy = FX_UPDATE_PROGRESSIVE,
    .max_samples = FX_AO_MAX_SAMPLES,
    .depends_on = "triangle_lookup",
    .texel_bytes = ao_texel_bytes,
    .needs = ao_needs,
    .cost = ao_cost,
    .update = ao_update,
    .texel_samples = ao_texel_samples,
    .run_samples = ao_run_samples,
    .resample = ao_resample,
    .shade = ao_shade,
    .eval = ao_eval,
    .reference = ao_reference,
    .reference_samples = 1024, /* 16 times the cache's 64: the noise is a quarter of the cached texel's */
    .reference_unit = "rays",
};
