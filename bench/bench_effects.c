/* Benchmark of the effect updates (effects/effects.h): rays per second of fx_ao_update and fx_shadow_update
 * on one thread, over every level-0 block of every island of a scene, against the Embree ceilings in
 * DEPENDENCIES.md (rtcOccluded1M, 256-ray streams: 19.8 Mrays/s on one thread for AO).
 *
 * Usage: bench_effects [scene (default: the embedded scene)] [texel density, texels per metre (default 24)]
 * Prints the scene, the texel count, then Mrays/s per effect (median of 5 runs). */
#include "effects.h"
#include "scene.h"

#include <embree3/rtcore.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

enum { RAW_RAYS = 1 << 20, RAW_BATCH = 256 };

/* A uniform float in [0, 1) from a 64-bit hash of (a, b). */
static float hash_unit(uint64_t a, uint64_t b)
{
    uint64_t z = a * 0x9e3779b97f4a7c15ull + b * 0xbf58476d1ce4e5b9ull + 0x94d049bb133111ebull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    z ^= z >> 31;
    return (float)(z >> 40) * (1.0f / 16777216.0f);
}

/* The raw baseline: the first RAW_RAYS AO rays of the same texels (64 cosine-weighted rays per texel centre,
 * length ao_radius, robust origins) built once, then traced through rtcOccluded1M in 256-ray streams with
 * nothing else per ray. Returns Mrays/s of the best of 5 runs. */
static double raw_ao_rate(const scene *s, scene_rt *rt, const fx_block_job *jobs, uint32_t block_count)
{
    struct RTCRay *rays = aligned_alloc(64, sizeof(struct RTCRay) * RAW_RAYS);
    if (!rays)
        return 0;
    uint32_t n = 0;
    for (uint32_t j = 0; j < block_count && n < RAW_RAYS; j++)
        for (uint64_t m = jobs[j].mask; m && n < RAW_RAYS; m &= m - 1) {
            uint32_t t = (uint32_t)__builtin_ctzll(m);
            float p[3], normal[3], origin[3];
            fx_surface_point(s, jobs[j].island, jobs[j].lookup[t], (float)(jobs[j].block_x * 8 + (t & 7)) + 0.5f,
                             (float)(jobs[j].block_y * 8 + (t >> 3)) + 0.5f, p, normal);
            scene_offset_ray_origin(p, normal, s->ray_offset_scale, origin);
            float tangent[3] = {1, 0, 0};
            if (fabsf(normal[0]) > 0.9f)
                tangent[0] = 0, tangent[1] = 1;
            float bitangent[3] = {normal[1] * tangent[2] - normal[2] * tangent[1],
                                  normal[2] * tangent[0] - normal[0] * tangent[2],
                                  normal[0] * tangent[1] - normal[1] * tangent[0]};
            float len = sqrtf(bitangent[0] * bitangent[0] + bitangent[1] * bitangent[1] + bitangent[2] * bitangent[2]);
            for (int k = 0; k < 3; k++)
                bitangent[k] /= len;
            for (int k = 0; k < 3; k++)
                tangent[k] = bitangent[(k + 1) % 3] * normal[(k + 2) % 3] - bitangent[(k + 2) % 3] * normal[(k + 1) % 3];
            for (uint32_t r = 0; r < 64 && n < RAW_RAYS; r++, n++) {
                float u1 = hash_unit((uint64_t)j * 64 + t, 2 * r), u2 = hash_unit((uint64_t)j * 64 + t, 2 * r + 1);
                float radius = sqrtf(u1), phi = 6.2831853f * u2;
                float x = radius * cosf(phi), y = radius * sinf(phi), z = sqrtf(fmaxf(0.0f, 1.0f - u1));
                struct RTCRay *ray = &rays[n];
                memset(ray, 0, sizeof *ray);
                ray->org_x = origin[0], ray->org_y = origin[1], ray->org_z = origin[2];
                ray->dir_x = x * tangent[0] + y * bitangent[0] + z * normal[0];
                ray->dir_y = x * tangent[1] + y * bitangent[1] + z * normal[1];
                ray->dir_z = x * tangent[2] + y * bitangent[2] + z * normal[2];
                ray->tnear = 0.0f;
                ray->tfar = s->ao_radius;
                ray->mask = 0xFFFFFFFFu;
            }
        }
    _Alignas(64) struct RTCRay batch[RAW_BATCH];
    struct RTCIntersectContext ctx;
    double best = 0;
    for (int run = 0; run < 5; run++) {
        double t0 = (bench_now_ms() * 1e-3);
        for (uint32_t first = 0; first < n; first += RAW_BATCH) {
            uint32_t count = n - first < RAW_BATCH ? n - first : RAW_BATCH;
            memcpy(batch, rays + first, count * sizeof *batch);
            rtcInitIntersectContext(&ctx);
            rtcOccluded1M(scene_rt_handle(rt), &ctx, batch, count, sizeof *batch);
        }
        double rate = (double)n / ((bench_now_ms() * 1e-3) - t0) * 1e-6;
        best = rate > best ? rate : best;
    }
    free(rays);
    return best;
}

int main(int argc, char **argv)
{
    const char *path = argc > 1 ? argv[1] : "default";
    scene_load_desc desc = {.texel_density = argc > 2 ? (float)atof(argv[2]) : 24.0f};
    scene_error err;
    scene *s = scene_load(path, &desc, &err);
    if (!s) {
        fprintf(stderr, "bench_effects: %s\n", err.msg);
        return 1;
    }
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    if (!rt) {
        fprintf(stderr, "bench_effects: %s\n", err.msg);
        return 1;
    }
    scene_tracing_thread_init();

    /* Every level-0 block of every island, with its lookup. */
    uint32_t block_count = 0;
    for (uint32_t i = 0; i < s->island_count; i++)
        block_count += ((s->islands[i].width + 7) / 8) * ((s->islands[i].height + 7) / 8);
    fx_block_job *jobs = calloc(block_count, sizeof *jobs);
    uint32_t *lookup = calloc((size_t)block_count * 64, sizeof *lookup);
    uint32_t shadow_bytes = fx_effect_shadow.texel_bytes(s);
    uint8_t *ao_payload = calloc((size_t)block_count * 64, 4);
    uint8_t *shadow_payload = calloc((size_t)block_count * 64, shadow_bytes);
    if (!jobs || !lookup || !ao_payload || !shadow_payload) {
        fprintf(stderr, "bench_effects: out of memory\n");
        return 1;
    }
    uint64_t texels = 0;
    double t0 = (bench_now_ms() * 1e-3);
    uint32_t b = 0;
    for (uint32_t i = 0; i < s->island_count; i++) {
        uint32_t width = s->islands[i].width, height = s->islands[i].height;
        for (uint32_t by = 0; by < (height + 7) / 8; by++)
            for (uint32_t bx = 0; bx < (width + 7) / 8; bx++, b++) {
                uint64_t mask = 0;
                for (uint32_t t = 0; t < 64; t++)
                    if (bx * 8 + (t & 7) < width && by * 8 + (t >> 3) < height)
                        mask |= 1ull << t;
                fx_lookup_update(s, i, 0, bx, by, mask, lookup + 64 * (size_t)b);
                jobs[b] = (fx_block_job){.key = ((uint64_t)i << 28) | ((uint64_t)by << 12) | bx,
                                         .island = i,
                                         .block_x = bx,
                                         .block_y = by,
                                         .mask = mask,
                                         .lookup = lookup + 64 * (size_t)b};
                texels += (uint64_t)__builtin_popcountll(mask);
            }
    }
    double lookup_seconds = (bench_now_ms() * 1e-3) - t0;
    printf("scene %s: %u triangles, %u islands, %u blocks, %llu texels; lookup %.1f Mtexels/s\n", s->source,
           s->triangle_count, s->island_count, block_count, (unsigned long long)texels,
           (double)texels / lookup_seconds * 1e-6);

    fx_context ctx = {.s = s, .rt = rt, .seed = 1, .ao_radius = s->ao_radius};
    double ao_rates[5], shadow_rates[5];
    for (int run = 0; run < 5; run++) {
        memset(ao_payload, 0, (size_t)block_count * 64 * 4);
        for (uint32_t j = 0; j < block_count; j++) {
            jobs[j].payload = ao_payload + (size_t)64 * 4 * j;
            jobs[j].key = (jobs[j].key & ~(0xfull << 60)) | ((uint64_t)FX_AO << 60);
        }
        t0 = (bench_now_ms() * 1e-3);
        uint64_t rays = 0;
        for (int frame = 0; frame < 4; frame++)
            rays += fx_ao_update(&ctx, jobs, block_count, 16);
        ao_rates[run] = (double)rays / ((bench_now_ms() * 1e-3) - t0) * 1e-6;

        for (uint32_t j = 0; j < block_count; j++) {
            jobs[j].payload = shadow_payload + (size_t)64 * shadow_bytes * j;
            jobs[j].key = (jobs[j].key & ~(0xfull << 60)) | ((uint64_t)FX_SHADOW << 60);
        }
        t0 = (bench_now_ms() * 1e-3);
        rays = fx_shadow_update(&ctx, jobs, block_count);
        shadow_rates[run] = (double)rays / ((bench_now_ms() * 1e-3) - t0) * 1e-6;
    }

    double raw = raw_ao_rate(s, rt, jobs, block_count);
    printf("raw rtcOccluded1M over the first %d AO rays of the same texels (256-ray streams, best of 5): %.2f "
           "Mrays/s; fx_ao_update (best of 5) / raw = %.2f\n",
           RAW_RAYS, raw, raw > 0 ? bench_quantile(ao_rates, 5, 1.0) / raw : 0.0);
    printf("fx_ao_update (4 frames x 16 samples, radius %.3g m): %.2f Mrays/s (median of 5, 1 thread)\n",
           (double)s->ao_radius, bench_quantile(ao_rates, 5, 0.5));
    printf("fx_shadow_update (%u lights x 16 rays): %.2f Mrays/s (median of 5, 1 thread)\n", s->light_count,
           bench_quantile(shadow_rates, 5, 0.5));

    free(jobs);
    free(lookup);
    free(ao_payload);
    free(shadow_payload);
    scene_rt_free(rt);
    scene_free(s);
    return 0;
}
