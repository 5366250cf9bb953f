/* Benchmark of the visibility pass (server/visibility.c, stage 2 of the frame loop) against raw Embree
 * packet rays on the same scene, camera, tiling and thread pool, in the same process.
 *
 *   visibility  srv_loop_frame() with every effect off (only visibility and compose run); the figure is the
 *               loop's own time_ms[SRV_STAGE_VISIBILITY]
 *   raw         the same primary rays (camera directions precomputed once, outside the timing) through
 *               rtcIntersect16 in 4x4 packets, 16x16 tiles on an srv_pool of the same size; per pixel only
 *               the hit (triangle, u, v, t) is stored
 *   raw+gen     as raw, with the directions generated in the loop by srv_camera_ray() (what the pass does)
 *
 * The variants alternate inside every repetition, so each repetition gives a ratio measured under the same
 * load; the table reports medians of the times and of the per-repetition ratios.
 *
 * Usage: bench_visibility [--scene PATH (default ../shared/scenes/sponza/sponza.3ds, else the embedded
 *        scene)] [--width 1280] [--height 720] [--reps 9] [--threads 1,2] [--only vis|raw]
 *        [--pos x,y,z] [--target x,y,z] [--fov 60]
 * The default camera (Sponza, y up): position -12,2,0 looking at 5,5,0; for the embedded scene its own
 * default camera. --only runs just one variant in a loop (for profiling with perf or callgrind). */
#define _GNU_SOURCE
#include "camera.h"
#include "engine.h"
#include "pool.h"
#include "scene.h"

#include <embree3/rtcore.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "bench_util.h"

enum { TILE = 16, MAX_REPS = 201 };

/* The raw baseline's state: the frame, precomputed directions (x, y, z planes) and the hit buffers. */
typedef struct raw_job {
    RTCScene rtc;
    const srv_camera_frame *f;
    const float *dir[3]; /* width*height each */
    bool generate;       /* generate directions in the loop instead of reading them */
    uint32_t tiles_x;
    uint32_t *tri;
    float *u, *v, *t;
} raw_job;

static void raw_tile(void *user, uint32_t task_index, uint32_t thread_index)
{
    (void)thread_index;
    raw_job *job = user;
    const srv_camera_frame *f = job->f;
    uint32_t tile_x = (task_index % job->tiles_x) * TILE, tile_y = (task_index / job->tiles_x) * TILE;
    _Alignas(64) struct RTCRayHit16 packet;
    _Alignas(64) int valid[16];
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (uint32_t py = tile_y; py < tile_y + TILE && py < f->height; py += 4)
        for (uint32_t px = tile_x; px < tile_x + TILE && px < f->width; px += 4) {
            for (int i = 0; i < 16; i++) {
                uint32_t x = px + (uint32_t)(i & 3), y = py + (uint32_t)(i >> 2);
                bool inside = x < f->width && y < f->height;
                valid[i] = inside ? -1 : 0;
                float d[3] = {0, 0, 1};
                if (inside) {
                    if (job->generate) {
                        srv_camera_ray(f, (float)x + 0.5f, (float)y + 0.5f, d);
                    } else {
                        size_t p = (size_t)y * f->width + x;
                        d[0] = job->dir[0][p], d[1] = job->dir[1][p], d[2] = job->dir[2][p];
                    }
                }
                packet.ray.org_x[i] = f->origin[0];
                packet.ray.org_y[i] = f->origin[1];
                packet.ray.org_z[i] = f->origin[2];
                packet.ray.dir_x[i] = d[0];
                packet.ray.dir_y[i] = d[1];
                packet.ray.dir_z[i] = d[2];
                packet.ray.tnear[i] = 0.0f;
                packet.ray.tfar[i] = INFINITY;
                packet.ray.time[i] = 0.0f;
                packet.ray.mask[i] = 0xFFFFFFFFu;
                packet.ray.id[i] = 0;
                packet.ray.flags[i] = 0;
                packet.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
                packet.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
            }
            rtcIntersect16(valid, job->rtc, &ctx, &packet);
            for (int i = 0; i < 16; i++) {
                uint32_t x = px + (uint32_t)(i & 3), y = py + (uint32_t)(i >> 2);
                if (!valid[i])
                    continue;
                size_t p = (size_t)y * f->width + x;
                bool hit = packet.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
                job->tri[p] = hit ? packet.hit.primID[i] : 0xFFFFFFFFu;
                job->u[p] = packet.hit.u[i];
                job->v[p] = packet.hit.v[i];
                job->t[p] = packet.ray.tfar[i];
            }
        }
}

static bool parse3(const char *s, float out[3])
{
    return sscanf(s, "%f,%f,%f", &out[0], &out[1], &out[2]) == 3;
}

int main(int argc, char **argv)
{
    const char *path = NULL, *only = NULL;
    uint32_t width = 1280, height = 720;
    int reps = 9;
    uint32_t thread_list[8] = {1, 2};
    int thread_count_n = 2;
    float pos[3] = {-12, 2, 0}, target[3] = {5, 5, 0}, fov = 60;
    bool camera_given = false;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *next = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--scene") && next)
            path = argv[++i];
        else if (!strcmp(a, "--width") && next)
            width = (uint32_t)atoi(argv[++i]);
        else if (!strcmp(a, "--height") && next)
            height = (uint32_t)atoi(argv[++i]);
        else if (!strcmp(a, "--reps") && next)
            reps = atoi(argv[++i]);
        else if (!strcmp(a, "--only") && next)
            only = argv[++i];
        else if (!strcmp(a, "--fov") && next)
            fov = (float)atof(argv[++i]);
        else if (!strcmp(a, "--pos") && next && parse3(argv[i + 1], pos))
            i++, camera_given = true;
        else if (!strcmp(a, "--target") && next && parse3(argv[i + 1], target))
            i++, camera_given = true;
        else if (!strcmp(a, "--threads") && next) {
            thread_count_n = 0;
            char *s = argv[++i];
            for (char *tok = strtok(s, ","); tok && thread_count_n < 8; tok = strtok(NULL, ","))
                thread_list[thread_count_n++] = (uint32_t)atoi(tok);
        } else {
            fprintf(
                stderr,
                "usage: bench_visibility [--scene PATH] [--width W] [--height H] [--reps N] [--threads 1,2] "
                "[--only vis|raw] [--pos x,y,z] [--target x,y,z] [--fov deg]\n");
            return !strcmp(a, "-h") || !strcmp(a, "--help") ? 0 : 2;
        }
    }
    if (reps < 1 || reps > MAX_REPS || !width || !height) {
        fprintf(stderr, "bench_visibility: bad --reps, --width or --height\n");
        return 2;
    }
    if (!path)
        path = "../shared/scenes/sponza/sponza.3ds";
    if (strcmp(path, "default") && access(path, R_OK) != 0) {
        printf("%s not found: using the embedded default scene with its default camera\n", path);
        path = "default";
    }
    scene_error err;
    double t0 = bench_now_ms();
    scene *s = scene_load(path, NULL, &err);
    if (!s) {
        fprintf(stderr, "bench_visibility: %s\n", err.msg);
        return 1;
    }
    double build_ms = 0;
    scene_rt *rt = scene_rt_create(s, &build_ms, &err);
    if (!rt) {
        fprintf(stderr, "bench_visibility: %s\n", err.msg);
        return 1;
    }
    srv_camera cam = {.position = {pos[0], pos[1], pos[2]},
                      .target = {target[0], target[1], target[2]},
                      .up = {0, 1, 0},
                      .fov_deg = fov};
    if (!strcmp(path, "default") && !camera_given)
        cam = srv_camera_default(s);
    srv_camera_frame f;
    if (!srv_camera_setup(&cam, width, height, &f)) {
        fprintf(stderr, "bench_visibility: invalid camera\n");
        return 1;
    }
    size_t pixels = (size_t)width * height;
    printf("scene %s: %u triangles, loaded and built in %.0f ms; camera (%g,%g,%g) -> (%g,%g,%g), fov %g; "
           "%ux%u, 1 viewer, %d repetitions\n",
           path, s->triangle_count, bench_now_ms() - t0, cam.position[0], cam.position[1], cam.position[2],
           cam.target[0], cam.target[1], cam.target[2], cam.fov_deg, width, height, reps);

    /* Precomputed directions and the raw hit buffers. */
    float *dir[3];
    for (int k = 0; k < 3; k++)
        dir[k] = malloc(sizeof(float) * pixels);
    uint32_t *tri = malloc(sizeof(uint32_t) * pixels);
    float *u = malloc(sizeof(float) * pixels), *v = malloc(sizeof(float) * pixels),
          *t = malloc(sizeof(float) * pixels);
    if (!dir[0] || !dir[1] || !dir[2] || !tri || !u || !v || !t) {
        fprintf(stderr, "bench_visibility: out of memory\n");
        return 1;
    }
    for (uint32_t y = 0; y < height; y++)
        for (uint32_t x = 0; x < width; x++) {
            float d[3];
            srv_camera_ray(&f, (float)x + 0.5f, (float)y + 0.5f, d);
            size_t p = (size_t)y * width + x;
            dir[0][p] = d[0], dir[1][p] = d[1], dir[2][p] = d[2];
        }
    uint32_t tiles_x = (width + TILE - 1) / TILE, tiles = tiles_x * ((height + TILE - 1) / TILE);

    printf("\n| threads | visibility ms | visibility Mrays/s | raw ms | raw Mrays/s | raw+gen ms | raw+gen "
           "Mrays/s "
           "| visibility / raw | visibility / raw+gen | best of runs: vis / raw / raw+gen ms | compose ms "
           "| hit pixels (vis / raw) |\n"
           "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int ti = 0; ti < thread_count_n; ti++) {
        uint32_t threads = thread_list[ti];
        srv_loop_desc desc = {.s = s, .rt = rt, .threads = threads};
        char msg[256];
        srv_loop *loop = NULL;
        srv_viewer_id viewer = {0};
        if (srv_loop_create(&desc, &loop, msg, sizeof msg) == FXC_OK &&
            (srv_viewer_add(loop, &(srv_viewer_desc){.width = width, .height = height}, &viewer) != FXC_OK ||
             srv_viewer_set_camera(loop, viewer, &cam) != FXC_OK)) {
            snprintf(msg, sizeof msg, "cannot add the viewer");
            srv_loop_free(loop);
            loop = NULL;
        }
        srv_pool *pool = srv_pool_create(threads);
        if (!loop || !pool) {
            fprintf(stderr, "bench_visibility: %s\n", loop ? "cannot start the pool" : msg);
            return 1;
        }
        raw_job job = {.rtc = scene_rt_handle(rt),
                       .f = &f,
                       .dir = {dir[0], dir[1], dir[2]},
                       .tiles_x = tiles_x,
                       .tri = tri,
                       .u = u,
                       .v = v,
                       .t = t};
        double vis_ms[MAX_REPS], raw_ms[MAX_REPS], gen_ms[MAX_REPS], compose_ms[MAX_REPS];
        double ratio_raw[MAX_REPS], ratio_gen[MAX_REPS];
        uint64_t vis_hits = 0, raw_hits = 0;
        srv_frame_stats st;
        /* Warm-up: one of each (page faults, caches). */
        if (!only || !strcmp(only, "vis"))
            srv_loop_frame(loop, &st);
        if (!only || !strcmp(only, "raw"))
            srv_pool_run(pool, tiles, raw_tile, &job);
        for (int r = 0; r < reps; r++) {
            vis_ms[r] = raw_ms[r] = gen_ms[r] = compose_ms[r] = NAN;
            if (!only || !strcmp(only, "vis")) {
                if (srv_loop_frame(loop, &st) != FXC_OK) {
                    fprintf(stderr, "bench_visibility: frame failed\n");
                    return 1;
                }
                vis_ms[r] = st.time_ms[SRV_STAGE_VISIBILITY];
                compose_ms[r] = st.time_ms[SRV_STAGE_COMPOSE];
                vis_hits = st.pixels_visible;
            }
            if (!only || !strcmp(only, "raw")) {
                job.generate = false;
                double a = bench_now_ms();
                srv_pool_run(pool, tiles, raw_tile, &job);
                raw_ms[r] = bench_now_ms() - a;
            }
            if (!only) {
                job.generate = true;
                double a = bench_now_ms();
                srv_pool_run(pool, tiles, raw_tile, &job);
                gen_ms[r] = bench_now_ms() - a;
            }
            ratio_raw[r] = raw_ms[r] / vis_ms[r]; /* visibility throughput / raw throughput */
            ratio_gen[r] = gen_ms[r] / vis_ms[r];
        }
        raw_hits = 0;
        for (size_t p = 0; p < pixels; p++)
            raw_hits += tri[p] != 0xFFFFFFFFu;
        double mv = bench_quantile(vis_ms, reps, 0.5), mr = bench_quantile(raw_ms, reps, 0.5),
               mg = bench_quantile(gen_ms, reps, 0.5);
        printf("| %u | %.2f | %.1f | %.2f | %.1f | %.2f | %.1f | %.2f | %.2f | %.1f / %.1f / %.1f | %.2f | "
               "%llu / %llu |\n",
               threads, mv, (double)pixels / mv / 1e3, mr, (double)pixels / mr / 1e3, mg,
               (double)pixels / mg / 1e3, bench_quantile(ratio_raw, reps, 0.5),
               bench_quantile(ratio_gen, reps, 0.5), bench_quantile(vis_ms, reps, 0.0),
               bench_quantile(raw_ms, reps, 0.0), bench_quantile(gen_ms, reps, 0.0),
               bench_quantile(compose_ms, reps, 0.5), (unsigned long long)vis_hits,
               (unsigned long long)raw_hits);
        fflush(stdout);
        srv_pool_free(pool);
        srv_loop_free(loop);
    }
    printf("\nMrays/s = %ux%u primary rays / median time; ratios are medians of per-repetition ratios "
           "(throughput of visibility over that of the raw loop).\n",
           width, height);
    for (int k = 0; k < 3; k++)
        free(dir[k]);
    free(tri), free(u), free(v), free(t);
    scene_rt_free(rt);
    scene_free(s);
    return 0;
}
