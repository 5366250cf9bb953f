/* Benchmark of building a scene: the stages scene_load() times itself (scene.timings: reading and
 * triangulation, welding and validation, textures, islands) and the Embree BVH build (scene_rt_create),
 * median of N repetitions per scene, with what the islands came out as (count, mean triangles per island,
 * level-0 texels and 8x8 blocks over all islands).
 *
 * The islands are single-threaded; Embree's BVH build uses TBB's threads (all cores unless --pin).
 * Target of the islands issue: Sponza's islands in under 1 s on one core.
 *
 * Usage: bench_scene [-n N (default 5)] [--pin CPU] [SCENE...]
 *   default scenes (relative to the repository root, the working directory when run from there):
 *   ../shared/scenes/sponza/sponza.3ds and ../shared/scenes/dragon/dragon_vrip_res2.ply.gz; a scene file
 *   that is absent is skipped with a message. --pin CPU restricts the whole process (TBB included) to one
 *   core. Prints a markdown table. */
#define _GNU_SOURCE
#include "scene.h"

#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "bench_util.h"

enum { MAX_REPS = 101 };

enum { ST_LOAD = 0, ST_WELD, ST_TEXTURES, ST_ISLANDS, ST_SCENE_LOAD_TOTAL, ST_BVH, ST_COUNT };
static const char *const stage_names[ST_COUNT] = {
    "load", "weld", "textures", "islands", "scene_load total", "BVH build"};

typedef struct row {
    char name[64];
    double median_ms[ST_COUNT], min_ms[ST_COUNT], max_ms[ST_COUNT];
    uint32_t triangles, vertices, islands, meshes;
    uint64_t texels, blocks;
    int reps;
} row;

static int run_scene(const char *path, int reps, row *out)
{
    double samples[ST_COUNT][MAX_REPS];
    memset(out, 0, sizeof *out);
    const char *base = strrchr(path, '/');
    snprintf(out->name, sizeof out->name, "%s", base ? base + 1 : path);
    for (int r = 0; r < reps; r++) {
        scene_error err;
        double t0 = bench_now_ms();
        scene *s = scene_load(path, NULL, &err);
        double t1 = bench_now_ms();
        if (!s) {
            fprintf(stderr, "bench_scene: %s: %s\n", path, err.msg);
            return -1;
        }
        double build_ms = 0;
        scene_rt *rt = scene_rt_create(s, &build_ms, &err);
        if (!rt) {
            fprintf(stderr, "bench_scene: %s: %s\n", path, err.msg);
            scene_free(s);
            return -1;
        }
        samples[ST_LOAD][r] = s->timings.load_ms;
        samples[ST_WELD][r] = s->timings.weld_ms;
        samples[ST_TEXTURES][r] = s->timings.textures_ms;
        samples[ST_ISLANDS][r] = s->timings.islands_ms;
        samples[ST_SCENE_LOAD_TOTAL][r] = t1 - t0;
        samples[ST_BVH][r] = build_ms;
        if (r == 0) {
            out->triangles = s->triangle_count;
            out->vertices = s->vertex_count;
            out->islands = s->island_count;
            out->meshes = s->mesh_count;
            for (uint32_t i = 0; i < s->island_count; i++) {
                uint64_t w = s->islands[i].width, h = s->islands[i].height;
                out->texels += w * h;
                out->blocks += ((w + SCENE_BLOCK_TEXELS - 1) / SCENE_BLOCK_TEXELS) *
                               ((h + SCENE_BLOCK_TEXELS - 1) / SCENE_BLOCK_TEXELS);
            }
        } else if (s->island_count != out->islands) {
            fprintf(stderr, "bench_scene: %s: island count differs between runs (%u, then %u)\n", path,
                    out->islands, s->island_count);
        }
        fprintf(stderr,
                "  %s run %d: load %.1f weld %.1f textures %.1f islands %.1f (scene_load %.1f) BVH %.1f ms\n",
                out->name, r + 1, samples[ST_LOAD][r], samples[ST_WELD][r], samples[ST_TEXTURES][r],
                samples[ST_ISLANDS][r], samples[ST_SCENE_LOAD_TOTAL][r], samples[ST_BVH][r]);
        scene_rt_free(rt);
        scene_free(s);
    }
    for (int st = 0; st < ST_COUNT; st++) {
        out->min_ms[st] = out->max_ms[st] = samples[st][0];
        for (int r = 1; r < reps; r++) {
            if (samples[st][r] < out->min_ms[st])
                out->min_ms[st] = samples[st][r];
            if (samples[st][r] > out->max_ms[st])
                out->max_ms[st] = samples[st][r];
        }
        out->median_ms[st] = bench_quantile(samples[st], reps, 0.5);
    }
    out->reps = reps;
    return 0;
}

int main(int argc, char **argv)
{
    setvbuf(stdout, NULL, _IOLBF, 0);
    int reps = 5, pin = -1;
    const char *paths[64];
    int path_count = 0;
    for (int i = 1; i < argc; i++) {
        if ((!strcmp(argv[i], "-n") || !strcmp(argv[i], "--reps")) && i + 1 < argc) {
            reps = atoi(argv[++i]);
        } else if (!strcmp(argv[i], "--pin") && i + 1 < argc) {
            pin = atoi(argv[++i]);
        } else if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
            printf("usage: bench_scene [-n N (default 5)] [--pin CPU] [SCENE...]\n");
            return 0;
        } else if (path_count < 64) {
            paths[path_count++] = argv[i];
        }
    }
    if (reps < 1 || reps > MAX_REPS) {
        fprintf(stderr, "bench_scene: -n must be 1..%d\n", MAX_REPS);
        return 2;
    }
    if (path_count == 0) {
        paths[path_count++] = "../shared/scenes/sponza/sponza.3ds";
        paths[path_count++] = "../shared/scenes/dragon/dragon_vrip_res2.ply.gz";
    }
    if (pin >= 0) {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET(pin, &set);
        if (sched_setaffinity(0, sizeof set, &set) != 0) {
            perror("bench_scene: sched_setaffinity");
            return 2;
        }
    }
    printf("bench_scene: %d repetitions per scene, %s, %ld online cores\n\n", reps,
           pin >= 0 ? "whole process pinned to one core (BVH build single-core)"
                    : "not pinned (islands single-threaded, Embree BVH build on TBB's threads)",
           sysconf(_SC_NPROCESSORS_ONLN));
    row rows[64];
    int row_count = 0;
    for (int i = 0; i < path_count; i++) {
        if (access(paths[i], R_OK) != 0) {
            printf("skipped %s: not found (run from the repository root, or give the path)\n", paths[i]);
            continue;
        }
        fprintf(stderr, "%s\n", paths[i]);
        if (run_scene(paths[i], reps, &rows[row_count]) == 0)
            row_count++;
    }
    if (row_count == 0)
        return 1;
    printf("\nMedian of %d runs, milliseconds (min-max in brackets):\n\n", reps);
    printf("| scene | triangles | vertices | meshes |");
    for (int st = 0; st < ST_COUNT; st++)
        printf(" %s ms |", stage_names[st]);
    printf(" islands | mean tris/island | level-0 texels | level-0 blocks |\n|---|---|---|---|");
    for (int st = 0; st < ST_COUNT; st++)
        printf("---|");
    printf("---|---|---|---|\n");
    for (int i = 0; i < row_count; i++) {
        const row *r = &rows[i];
        printf("| %s | %u | %u | %u |", r->name, r->triangles, r->vertices, r->meshes);
        for (int st = 0; st < ST_COUNT; st++)
            printf(" %.1f (%.1f-%.1f) |", r->median_ms[st], r->min_ms[st], r->max_ms[st]);
        printf(" %u | %.1f | %llu | %llu |\n", r->islands,
               r->islands ? (double)r->triangles / r->islands : 0.0, (unsigned long long)r->texels,
               (unsigned long long)r->blocks);
    }
    return 0;
}
