/* Benchmark of the effect updates (effects/effects.h): rays per second of fx_ao_update and fx_shadow_update
 * on one thread, over every level-0 block of every island of a scene, against the Embree ceilings in
 * DEPENDENCIES.md (rtcOccluded1M, 256-ray streams: 19.8 Mrays/s on one thread for AO).
 *
 * The raw baseline traces exactly the rays the update traced: a first, untimed run of each update records its
 * ray streams (fx_context.observe_rays); then five runs alternate the update and the raw rtcOccluded1M replay
 * of those streams, and the figure is the median of the per-run ratios.
 *
 * Usage: bench_effects [scene (default: the embedded scene)] [texel density, texels per metre (default 24)]
 * Prints the scene, the texel count, then Mrays/s per effect and the ratios to the raw replay. */
#include "effects.h"
#include "scene.h"

#include <embree3/rtcore.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

enum { MAX_CAPTURED = 1 << 25 }; /* rays kept for the raw replay (48 bytes each) */

/* The rays an update traced, in the streams it traced them in (fx_context.observe_rays). */
typedef struct captured_rays {
    struct RTCRay *rays;    /* pristine copies */
    uint32_t *stream_sizes; /* rays per rtcOccluded1M call, in order */
    size_t count, streams, capacity, stream_capacity;
    bool truncated;
} captured_rays;

static void capture(void *user, const void *rays, uint32_t count)
{
    captured_rays *c = user;
    if (c->truncated || c->count + count > MAX_CAPTURED) {
        c->truncated = true;
        return;
    }
    if (c->count + count > c->capacity) {
        size_t cap = c->capacity ? 2 * c->capacity : 1u << 16;
        while (cap < c->count + count)
            cap *= 2;
        struct RTCRay *grown = aligned_alloc(64, cap * sizeof *grown);
        if (!grown) {
            c->truncated = true;
            return;
        }
        if (c->rays)
            memcpy(grown, c->rays, c->count * sizeof *grown);
        free(c->rays);
        c->rays = grown;
        c->capacity = cap;
    }
    if (c->streams == c->stream_capacity) {
        size_t cap = c->stream_capacity ? 2 * c->stream_capacity : 1024;
        uint32_t *grown = realloc(c->stream_sizes, cap * sizeof *grown);
        if (!grown) {
            c->truncated = true;
            return;
        }
        c->stream_sizes = grown;
        c->stream_capacity = cap;
    }
    memcpy(c->rays + c->count, rays, count * sizeof(struct RTCRay));
    c->count += count;
    c->stream_sizes[c->streams++] = count;
}

/* Traces the captured rays again, stream by stream as the update did, with nothing else per ray; `work` is a
 * scratch copy (Embree overwrites tfar). Returns milliseconds (the copy is not timed). */
static double raw_replay_ms(scene_rt *rt, const captured_rays *c, struct RTCRay *work)
{
    memcpy(work, c->rays, c->count * sizeof *work);
    struct RTCIntersectContext context;
    double t0 = bench_now_ms();
    size_t first = 0;
    for (size_t k = 0; k < c->streams; k++) {
        rtcInitIntersectContext(&context);
        rtcOccluded1M(scene_rt_handle(rt), &context, work + first, c->stream_sizes[k], sizeof *work);
        first += c->stream_sizes[k];
    }
    return bench_now_ms() - t0;
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
    /* One update of each effect (AO: 4 frames x 16 samples; shadows: once) on fresh payloads. */
    for (int effect = 0; effect < 2; effect++) {
        bool ao = effect == 0;
        captured_rays rays = {0};
        double update_ms[5], raw_ms[5], ratio[5];
        struct RTCRay *work = NULL;
        for (int run = -1; run < 5; run++) {
            /* Run -1 captures the rays (not timed); runs 0..4 alternate the update and its raw replay. */
            ctx.observe_rays = run < 0 ? capture : NULL;
            ctx.observe_user = &rays;
            uint8_t *payload = ao ? ao_payload : shadow_payload;
            uint32_t bytes = ao ? 4 : shadow_bytes;
            memset(payload, 0, (size_t)block_count * 64 * bytes);
            for (uint32_t j = 0; j < block_count; j++) {
                jobs[j].payload = payload + (size_t)64 * bytes * j;
                jobs[j].key = (jobs[j].key & ~(0xfull << 60)) | ((uint64_t)(ao ? FX_AO : FX_SHADOW) << 60);
            }
            double start = bench_now_ms();
            uint64_t traced = 0;
            if (ao)
                for (int frame = 0; frame < 4; frame++)
                    traced += fx_ao_update(&ctx, jobs, block_count, 16);
            else
                traced = fx_shadow_update(&ctx, jobs, block_count);
            double ms = bench_now_ms() - start;
            if (run < 0) {
                if (rays.truncated || rays.count != traced) {
                    fprintf(stderr, "bench_effects: captured %zu of %llu rays (at most %d are kept)\n",
                            rays.count, (unsigned long long)traced, MAX_CAPTURED);
                    return 1;
                }
                work = aligned_alloc(64, (rays.count ? rays.count : 1) * sizeof *work);
                if (!work)
                    return 1;
                continue;
            }
            update_ms[run] = ms;
            raw_ms[run] = raw_replay_ms(rt, &rays, work);
            ratio[run] = raw_ms[run] / update_ms[run]; /* update throughput over raw throughput */
        }
        double n = (double)rays.count;
        printf(
            "%s: %zu rays in %zu streams; update %.2f Mrays/s, raw rtcOccluded1M over the same rays %.2f "
            "Mrays/s "
            "(medians of 5 alternating runs, 1 thread); update / raw throughput %.2f (p10 %.2f, p90 %.2f)\n",
            ao ? "fx_ao_update (4 frames x 16 samples)" : "fx_shadow_update (16 rays per texel and light)",
            rays.count, rays.streams, n / bench_quantile(update_ms, 5, 0.5) * 1e-3,
            n / bench_quantile(raw_ms, 5, 0.5) * 1e-3, bench_quantile(ratio, 5, 0.5),
            bench_quantile(ratio, 5, 0.1), bench_quantile(ratio, 5, 0.9));
        free(work);
        free(rays.rays);
        free(rays.stream_sizes);
    }

    free(jobs);
    free(lookup);
    free(ao_payload);
    free(shadow_payload);
    scene_rt_free(rt);
    scene_free(s);
    return 0;
}
