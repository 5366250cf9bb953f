/* bench_stages: the per-pixel stages (requests, compose) against visibility on the same frames, and the
 * whole frame on 2 threads against 1, for a walking viewer (issue: "per-pixel stages at a fraction of the
 * ray cost").
 *
 *   part 1: one loop on 1 thread; per frame after the warm-up, requests / visibility and compose /
 *           visibility (the same frame's stage timers); medians and the 10-90 % spread
 *   part 2: two loops, 1 and 2 threads, same cameras, frames alternating between them (frame f on the
 *           1-thread loop, then frame f on the 2-thread loop); per frame t1 / t2; median and spread.
 *           Both loops do identical work (same cameras, deterministic caches).
 *
 * Usage: bench_stages [--scene PATH (default ../shared/scenes/sponza/sponza.3ds)] [--res WxH (640x360)]
 *                     [--warmup N (10)] [--frames N (30)] [--camera walk|group|orbit (walk)] [--viewers N (1)]
 *                     [--no-scaling (part 1 only, for profiling)]
 */
#include "bench_engine.h"
#include "scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static void print_row(const char *what, const double *values, int n)
{
    printf("| %s | %.3f | %.3f | %.3f |\n", what, bench_quantile(values, n, 0.5),
           bench_quantile(values, n, 0.1), bench_quantile(values, n, 0.9));
}

int main(int argc, char **argv)
{
    const char *path = "../shared/scenes/sponza/sponza.3ds";
    uint32_t w = 640, h = 360, warmup = 10, frames = 30, viewers = 1;
    srv_camgen_kind gen = SRV_CAMGEN_WALK;
    bool scaling = true;
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
        else if (!strcmp(a, "--camera") && v && srv_camgen_parse(v, &gen))
            i++;
        else if (!strcmp(a, "--no-scaling"))
            scaling = false;
        else {
            fprintf(stderr,
                    "usage: bench_stages [--scene PATH] [--res WxH] [--warmup N] [--frames N] [--camera GEN] "
                    "[--viewers N] [--no-scaling]\n");
            return !strcmp(a, "-h") || !strcmp(a, "--help") ? 0 : 2;
        }
    }
    if (!w || !h || frames < 1 || frames > BENCH_MAX_SAMPLES || viewers < 1 || viewers > SRV_MAX_VIEWERS) {
        fprintf(stderr, "bench_stages: bad --res, --frames (1..%d) or --viewers\n", BENCH_MAX_SAMPLES);
        return 2;
    }
    if (strcmp(path, "default") && access(path, R_OK) != 0) {
        printf("%s not found: using the embedded default scene\n", path);
        path = "default";
    }
    scene_error err;
    scene *s = scene_load(path, NULL, &err);
    if (!s) {
        fprintf(stderr, "bench_stages: %s\n", err.msg);
        return 1;
    }
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    if (!rt) {
        fprintf(stderr, "bench_stages: %s\n", err.msg);
        return 1;
    }
    printf("scene %s (%u triangles), %u viewer(s) of %ux%u, camera %s, %u warm-up frames then %u measured\n",
           path, s->triangle_count, viewers, w, h, srv_camgen_name(gen), warmup, frames);

    /* Part 1: stage ratios on one thread. */
    srv_viewer_id ids[SRV_MAX_VIEWERS];
    srv_loop *one = bench_make_loop("bench_stages", s, rt, false, 1, viewers, w, h, ids);
    double vis[BENCH_MAX_SAMPLES], req_ratio[BENCH_MAX_SAMPLES], comp_ratio[BENCH_MAX_SAMPLES],
        req[BENCH_MAX_SAMPLES], comp[BENCH_MAX_SAMPLES], frame_ms[BENCH_MAX_SAMPLES];
    srv_frame_stats st;
    for (uint32_t f = 0; f < warmup + frames; f++) {
        bench_run_frame("bench_stages", one, s, gen, ids, viewers, f, &st);
        if (f < warmup)
            continue;
        int i = (int)(f - warmup);
        vis[i] = st.time_ms[SRV_STAGE_VISIBILITY];
        req[i] = st.time_ms[SRV_STAGE_REQUESTS];
        comp[i] = st.time_ms[SRV_STAGE_COMPOSE];
        frame_ms[i] = st.frame_ms;
        req_ratio[i] = req[i] / vis[i];
        comp_ratio[i] = comp[i] / vis[i];
    }
    srv_loop_free(one);
    printf("\n1 thread, per frame (ms and ratios to the same frame's visibility):\n\n"
           "| figure | median | p10 | p90 |\n|---|---|---|---|\n");
    print_row("visibility ms", vis, (int)frames);
    print_row("requests ms", req, (int)frames);
    print_row("compose ms", comp, (int)frames);
    print_row("frame ms", frame_ms, (int)frames);
    print_row("requests / visibility", req_ratio, (int)frames);
    print_row("compose / visibility", comp_ratio, (int)frames);

    /* Part 2: 1 thread against 2, alternating frame by frame. */
    if (!scaling) {
        scene_rt_free(rt);
        scene_free(s);
        return 0;
    }
    srv_viewer_id ids1[SRV_MAX_VIEWERS], ids2[SRV_MAX_VIEWERS];
    srv_loop *l1 = bench_make_loop("bench_stages", s, rt, false, 1, viewers, w, h, ids1),
             *l2 = bench_make_loop("bench_stages", s, rt, false, 2, viewers, w, h, ids2);
    double speedup[BENCH_MAX_SAMPLES], t1s[BENCH_MAX_SAMPLES], t2s[BENCH_MAX_SAMPLES];
    static double stage1[SRV_STAGE_COUNT][BENCH_MAX_SAMPLES], stage2[SRV_STAGE_COUNT][BENCH_MAX_SAMPLES];
    for (uint32_t f = 0; f < warmup + frames; f++) {
        srv_frame_stats s1, s2;
        double t1 = bench_run_frame("bench_stages", l1, s, gen, ids1, viewers, f, &s1);
        double t2 = bench_run_frame("bench_stages", l2, s, gen, ids2, viewers, f, &s2);
        if (s1.requested_texels != s2.requested_texels || bench_effect_rays(&s1) != bench_effect_rays(&s2)) {
            fprintf(stderr, "bench_stages: the two loops did different work in frame %u\n", f);
            return 1;
        }
        if (f < warmup)
            continue;
        int i = (int)(f - warmup);
        t1s[i] = t1;
        t2s[i] = t2;
        speedup[i] = t1 / t2;
        for (int k = 0; k < SRV_STAGE_COUNT; k++) {
            stage1[k][i] = s1.time_ms[k];
            stage2[k][i] = s2.time_ms[k];
        }
    }
    printf("\nwhole frame, 1 thread against 2 threads (frames alternating between the two loops):\n\n"
           "| figure | median | p10 | p90 |\n|---|---|---|---|\n");
    print_row("1 thread ms", t1s, (int)frames);
    print_row("2 threads ms", t2s, (int)frames);
    print_row("speed-up (1 thread / 2 threads)", speedup, (int)frames);
    /* Where the second thread helps and where it does not: each stage's median on both loops (the stages'
     * own timers, so their sum is less than the frame by what lies between them). */
    printf("\nper stage, the same frames (median ms; speed-up of the medians):\n\n"
           "| stage | 1 thread | 2 threads | speed-up |\n|---|---|---|---|\n");
    for (int k = 0; k < SRV_STAGE_COUNT; k++) {
        double m1 = bench_quantile(stage1[k], (int)frames, 0.5),
               m2 = bench_quantile(stage2[k], (int)frames, 0.5);
        printf("| %s | %.3f | %.3f | %.2f |\n", srv_stage_name((srv_stage)k), m1, m2, m2 > 0 ? m1 / m2 : 0.0);
    }
    srv_loop_free(l1);
    srv_loop_free(l2);
    scene_rt_free(rt);
    scene_free(s);
    return 0;
}
