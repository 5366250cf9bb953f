/* Benchmark of the effect updates (effects/effects.h): rays per second of fx_ao_update and fx_shadow_update
 * on one thread, over every level-0 block of every island of a scene, against the Embree ceilings in
 * DEPENDENCIES.md (rtcOccluded1M, 256-ray streams: 19.8 Mrays/s on one thread for AO).
 *
 * Usage: bench_effects [scene (default: the embedded scene)] [texel density, texels per metre (default 24)]
 * Prints the scene, the texel count, then Mrays/s per effect (median of 5 runs). */
#include "effects.h"
#include "scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* Monotonic clock, seconds. */
static double now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Sorts five doubles in place (insertion sort) for the median. */
static void sort_small(double *values, int count)
{
    for (int i = 1; i < count; i++)
        for (int j = i; j > 0 && values[j - 1] > values[j]; j--) {
            double keep = values[j];
            values[j] = values[j - 1];
            values[j - 1] = keep;
        }
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
    uint32_t shadow_bytes = fx_describe(FX_SHADOW, s).texel_bytes;
    uint8_t *ao_payload = calloc((size_t)block_count * 64, 4);
    uint8_t *shadow_payload = calloc((size_t)block_count * 64, shadow_bytes);
    if (!jobs || !lookup || !ao_payload || !shadow_payload) {
        fprintf(stderr, "bench_effects: out of memory\n");
        return 1;
    }
    uint64_t texels = 0;
    double t0 = now_seconds();
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
    double lookup_seconds = now_seconds() - t0;
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
        t0 = now_seconds();
        uint64_t rays = 0;
        for (int frame = 0; frame < 4; frame++)
            rays += fx_ao_update(&ctx, jobs, block_count, 16);
        ao_rates[run] = (double)rays / (now_seconds() - t0) * 1e-6;

        for (uint32_t j = 0; j < block_count; j++) {
            jobs[j].payload = shadow_payload + (size_t)64 * shadow_bytes * j;
            jobs[j].key = (jobs[j].key & ~(0xfull << 60)) | ((uint64_t)FX_SHADOW << 60);
        }
        t0 = now_seconds();
        rays = fx_shadow_update(&ctx, jobs, block_count);
        shadow_rates[run] = (double)rays / (now_seconds() - t0) * 1e-6;
    }
    sort_small(ao_rates, 5);
    sort_small(shadow_rates, 5);
    printf("fx_ao_update (4 frames x 16 samples, radius %.3g m): %.2f Mrays/s (median of 5, 1 thread)\n",
           (double)s->ao_radius, ao_rates[2]);
    printf("fx_shadow_update (%u lights x 16 rays): %.2f Mrays/s (median of 5, 1 thread)\n", s->light_count,
           shadow_rates[2]);

    free(jobs);
    free(lookup);
    free(ao_payload);
    free(shadow_payload);
    scene_rt_free(rt);
    scene_free(s);
    return 0;
}
