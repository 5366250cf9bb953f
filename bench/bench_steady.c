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
#include "bench_util.h"
#include "camgen.h"
#include "engine.h"
#include "scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static srv_loop *make_loop(scene *s, scene_rt *rt, bool no_cache, uint32_t threads, uint32_t viewers, uint32_t w,
                           uint32_t h, srv_viewer_id *ids)
{
    srv_loop_desc d = {.s = s, .rt = rt, .threads = threads, .seed = 1, .no_cache = no_cache};
    uint32_t count = 0;
    const fx_effect *const *registry = fx_registry(&count);
    bool needed[SRV_MAX_EFFECTS];
    char why[SRV_MAX_EFFECTS][200];
    fx_needs(registry, count, s, needed, why);
    for (uint32_t e = 0; e < count; e++)
        d.effect_on[e] = needed[e] && registry[e]->shade;
    srv_loop *loop = NULL;
    char err[256];
    if (srv_loop_create(&d, &loop, err, sizeof err) != FXC_OK) {
        fprintf(stderr, "bench_steady: %s\n", err);
        exit(1);
    }
    for (uint32_t v = 0; v < viewers; v++)
        if (srv_viewer_add(loop, &(srv_viewer_desc){.width = w, .height = h}, &ids[v]) != FXC_OK) {
            fprintf(stderr, "bench_steady: cannot add a viewer\n");
            exit(1);
        }
    return loop;
}

/* Runs one frame; returns its wall time (ms) and the effect rays. */
static double run_frame(srv_loop *loop, const scene *s, srv_camgen_kind gen, const srv_viewer_id *ids,
                        uint32_t viewers, uint32_t frame, uint64_t *rays)
{
    for (uint32_t v = 0; v < viewers; v++) {
        srv_camera cam = srv_camgen_camera(gen, s, v, viewers, frame, 1);
        srv_viewer_set_camera(loop, ids[v], &cam);
    }
    srv_frame_stats st;
    double t = bench_now_ms();
    if (srv_loop_frame(loop, &st) != FXC_OK) {
        fprintf(stderr, "bench_steady: frame failed\n");
        exit(1);
    }
    t = bench_now_ms() - t;
    *rays = 0;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++)
        *rays += st.rays[e];
    return t;
}

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
            fprintf(stderr, "usage: bench_steady [--scene PATH] [--res WxH] [--camera GEN] [--viewers N] [--warmup N] "
                            "[--frames N] [--threads T]\n");
            return !strcmp(a, "-h") || !strcmp(a, "--help") ? 0 : 2;
        }
    }
    if (!w || !h || frames < 1 || frames > BENCH_MAX_SAMPLES || viewers < 1 || viewers > SRV_MAX_VIEWERS ||
        gen == SRV_CAMGEN_STATIC || gen == SRV_CAMGEN_IDENTICAL) {
        fprintf(stderr, "bench_steady: bad --res, --frames (1..%d) or --viewers, or a camera that does not move\n",
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
    printf("scene %s, %u viewer(s) of %ux%u, camera %s, threads %u (0 = all), %u warm-up frames, then %u frames; "
           "each frame on the cached loop, then on the no-cache loop\n\n",
           path, viewers, w, h, srv_camgen_name(gen), threads, warmup, frames);
    srv_viewer_id ids_c[SRV_MAX_VIEWERS], ids_n[SRV_MAX_VIEWERS];
    srv_loop *cached = make_loop(s, rt, false, threads, viewers, w, h, ids_c);
    srv_loop *baseline = make_loop(s, rt, true, threads, viewers, w, h, ids_n);
    double ray_ratio[BENCH_MAX_SAMPLES], time_ratio[BENCH_MAX_SAMPLES], ms_c[BENCH_MAX_SAMPLES],
        ms_n[BENCH_MAX_SAMPLES], rays_c[BENCH_MAX_SAMPLES], rays_n[BENCH_MAX_SAMPLES];
    printf("| frame | cached effect rays | no-cache effect rays | rays cached / no-cache | cached ms | no-cache ms | "
           "time cached / no-cache |\n|---|---|---|---|---|---|---|\n");
    for (uint32_t f = 0; f < warmup + frames; f++) {
        uint64_t rc, rn;
        double tc = run_frame(cached, s, gen, ids_c, viewers, f, &rc);
        double tn = run_frame(baseline, s, gen, ids_n, viewers, f, &rn);
        if (f < warmup)
            continue;
        int i = (int)(f - warmup);
        rays_c[i] = (double)rc;
        rays_n[i] = (double)rn;
        ms_c[i] = tc;
        ms_n[i] = tn;
        ray_ratio[i] = rn ? (double)rc / (double)rn : 0.0;
        time_ratio[i] = tc / tn;
        printf("| %u | %llu | %llu | %.4f | %.1f | %.1f | %.4f |\n", f, (unsigned long long)rc, (unsigned long long)rn,
               ray_ratio[i], tc, tn, time_ratio[i]);
        fflush(stdout);
    }
    int n = (int)frames;
    printf("\n| figure (frames %u..%u) | median | p10 | p90 |\n|---|---|---|---|\n", warmup, warmup + frames - 1);
    printf("| cached effect rays per frame | %.0f | %.0f | %.0f |\n", bench_quantile(rays_c, n, 0.5),
           bench_quantile(rays_c, n, 0.1), bench_quantile(rays_c, n, 0.9));
    printf("| no-cache effect rays per frame | %.0f | %.0f | %.0f |\n", bench_quantile(rays_n, n, 0.5),
           bench_quantile(rays_n, n, 0.1), bench_quantile(rays_n, n, 0.9));
    printf("| rays cached / no-cache | %.4f | %.4f | %.4f |\n", bench_quantile(ray_ratio, n, 0.5),
           bench_quantile(ray_ratio, n, 0.1), bench_quantile(ray_ratio, n, 0.9));
    printf("| cached frame ms | %.1f | %.1f | %.1f |\n", bench_quantile(ms_c, n, 0.5), bench_quantile(ms_c, n, 0.1),
           bench_quantile(ms_c, n, 0.9));
    printf("| no-cache frame ms | %.1f | %.1f | %.1f |\n", bench_quantile(ms_n, n, 0.5), bench_quantile(ms_n, n, 0.1),
           bench_quantile(ms_n, n, 0.9));
    printf("| time cached / no-cache | %.4f | %.4f | %.4f |\n", bench_quantile(time_ratio, n, 0.5),
           bench_quantile(time_ratio, n, 0.1), bench_quantile(time_ratio, n, 0.9));
    srv_loop_free(cached);
    srv_loop_free(baseline);
    scene_rt_free(rt);
    scene_free(s);
    return 0;
}
