/* bench_steady: the steady state against the no-cache baseline over the same frames (DESIGN.md,
 * "Definitions": moving cameras, a stated warm-up). Two loops, cached and --no-cache, get the same cameras;
 * each frame runs on the cached loop and then on the baseline, so both see the same machine load. Per frame
 * after the warm-up: effect rays and frame time of each, and their ratios; then medians and the 10-90 %
 * spread. A static camera is not used: its zero rays are true by construction.
 *
 * Usage: bench_steady [--scene PATH (default ../shared/scenes/sponza/sponza.3ds)] [--res WxH (640x360)]
 *                     [--camera walk|group|... (walk)] [--viewers N (1)] [--warmup N (10)] [--frames N (20)]
 *                     [--threads T (0 = all)]
 */
#include "bench_engine.h"
#include "scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int main(int argc, char **argv)
{
    const char *path = "../shared/scenes/sponza/sponza.3ds";
    uint32_t w = 640, h = 360, warmup = 10, frames = 20, viewers = 1, threads = 0;
    srv_camgen_kind gen = SRV_CAMGEN_WALK;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--scene") && v)
            path = v, i++;
        else if (!strcmp(a, "--res") && v && sscanf(v, "%ux%u", &w, &h) == 2)
            i++;
        else if (!strcmp(a, "--warmup") && v)
            warmup = (uint32_t)atoi(v), i++;
        else if (!strcmp(a, "--frames") && v)
            frames = (uint32_t)atoi(v), i++;
        else if (!strcmp(a, "--viewers") && v)
            viewers = (uint32_t)atoi(v), i++;
        else if (!strcmp(a, "--threads") && v)
            threads = (uint32_t)atoi(v), i++;
        else if (!strcmp(a, "--camera") && v && srv_camgen_parse(v, &gen))
            i++;
        else {
            fprintf(
                stderr,
                "usage: bench_steady [--scene PATH] [--res WxH] [--camera GEN] [--viewers N] [--warmup N] "
                "[--frames N] [--threads T]\n");
            return !strcmp(a, "-h") || !strcmp(a, "--help") ? 0 : 2;
        }
    }
    if (!w || !h || frames < 1 || frames > BENCH_MAX_SAMPLES || viewers < 1 || viewers > SRV_MAX_VIEWERS ||
        gen == SRV_CAMGEN_STATIC || gen == SRV_CAMGEN_IDENTICAL) {
        fprintf(stderr,
                "bench_steady: bad --res, --frames (1..%d) or --viewers, or a camera that does not move\n",
                BENCH_MAX_SAMPLES);
        return 2;
    }
    if (strcmp(path, "default") && access(path, R_OK) != 0) {
        printf("%s not found: using the embedded default scene\n", path);
        path = "default";
    }
    scene_error err;
    scene *s = scene_load(path, NULL, &err);
    scene_rt *rt = s ? scene_rt_create(s, NULL, &err) : NULL;
    if (!rt) {
        fprintf(stderr, "bench_steady: %s\n", err.msg);
        return 1;
    }
    printf("scene %s, %u viewer(s) of %ux%u, camera %s, threads %u (0 = all), %u warm-up frames, then %u "
           "frames; "
           "each frame on the cached loop, then on the no-cache loop\n\n",
           path, viewers, w, h, srv_camgen_name(gen), threads, warmup, frames);
    srv_viewer_id ids_c[SRV_MAX_VIEWERS], ids_n[SRV_MAX_VIEWERS];
    srv_loop *cached = bench_make_loop("bench_steady", s, rt, false, threads, viewers, w, h, ids_c);
    srv_loop *baseline = bench_make_loop("bench_steady", s, rt, true, threads, viewers, w, h, ids_n);
    double ray_ratio[BENCH_MAX_SAMPLES], time_ratio[BENCH_MAX_SAMPLES], ms_c[BENCH_MAX_SAMPLES],
        ms_n[BENCH_MAX_SAMPLES], rays_c[BENCH_MAX_SAMPLES], rays_n[BENCH_MAX_SAMPLES];
    printf("| frame | cached effect rays | no-cache effect rays | rays cached / no-cache | cached ms | "
           "no-cache ms | "
           "time cached / no-cache |\n|---|---|---|---|---|---|---|\n");
    for (uint32_t f = 0; f < warmup + frames; f++) {
        srv_frame_stats sc, sn;
        double tc = bench_run_frame("bench_steady", cached, s, gen, ids_c, viewers, f, &sc);
        double tn = bench_run_frame("bench_steady", baseline, s, gen, ids_n, viewers, f, &sn);
        uint64_t rc = bench_effect_rays(&sc), rn = bench_effect_rays(&sn);
        if (f < warmup)
            continue;
        int i = (int)(f - warmup);
        rays_c[i] = (double)rc;
        rays_n[i] = (double)rn;
        ms_c[i] = tc;
        ms_n[i] = tn;
        ray_ratio[i] = rn ? (double)rc / (double)rn : 0.0;
        time_ratio[i] = tc / tn;
        printf("| %u | %llu | %llu | %.4f | %.1f | %.1f | %.4f |\n", f, (unsigned long long)rc,
               (unsigned long long)rn, ray_ratio[i], tc, tn, time_ratio[i]);
        fflush(stdout);
    }
    int n = (int)frames;
    printf("\n| figure (frames %u..%u) | median | p10 | p90 |\n|---|---|---|---|\n", warmup,
           warmup + frames - 1);
    printf("| cached effect rays per frame | %.0f | %.0f | %.0f |\n", bench_quantile(rays_c, n, 0.5),
           bench_quantile(rays_c, n, 0.1), bench_quantile(rays_c, n, 0.9));
    printf("| no-cache effect rays per frame | %.0f | %.0f | %.0f |\n", bench_quantile(rays_n, n, 0.5),
           bench_quantile(rays_n, n, 0.1), bench_quantile(rays_n, n, 0.9));
    printf("| rays cached / no-cache | %.4f | %.4f | %.4f |\n", bench_quantile(ray_ratio, n, 0.5),
           bench_quantile(ray_ratio, n, 0.1), bench_quantile(ray_ratio, n, 0.9));
    printf("| cached frame ms | %.1f | %.1f | %.1f |\n", bench_quantile(ms_c, n, 0.5),
           bench_quantile(ms_c, n, 0.1), bench_quantile(ms_c, n, 0.9));
    printf("| no-cache frame ms | %.1f | %.1f | %.1f |\n", bench_quantile(ms_n, n, 0.5),
           bench_quantile(ms_n, n, 0.1), bench_quantile(ms_n, n, 0.9));
    printf("| time cached / no-cache | %.4f | %.4f | %.4f |\n", bench_quantile(time_ratio, n, 0.5),
           bench_quantile(time_ratio, n, 0.1), bench_quantile(time_ratio, n, 0.9));
    srv_loop_free(cached);
    srv_loop_free(baseline);
    scene_rt_free(rt);
    scene_free(s);
    return 0;
}
