/* bench_sparse: what a sample request (a sparse viewer's list, issue 11) adds to a frame, against what a second
 * whole-frame viewer adds. Three loops run the same moving camera, frame by frame, alternated in one run:
 *   A: one viewer of W x H;
 *   B: the same viewer plus a sparse viewer listing N random pixels of the same camera's image;
 *   C: the same viewer plus a second whole-frame viewer with the same camera.
 * Per frame it takes the ratios B/A and C/A of the frame's process CPU time (all threads: on a shared, loaded
 * machine wall time mostly measures preemption) and of the effect rays; it prints their
 * medians and 10th/90th percentiles, and the primary rays. The sparse viewer's pixels come from the same
 * frame's camera as the whole frame's, as a client's render cache asks for its current view.
 *
 * Usage: bench_sparse [--scene PATH (default: the embedded scene)] [--res WxH (640x360)] [--pixels N (4096)]
 *                     [--frames N (40)] [--warmup N (10)] [--threads T (1)] */
#include "bench_engine.h"

#include <string.h>
#include <time.h>

/* CPU time of the whole process (every pool thread), ms. */
static double cpu_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

int main(int argc, char **argv)
{
    const char *scene_path = NULL;
    uint32_t w = 640, h = 360, pixels = 4096, frames = 40, warmup = 10, threads = 1;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--scene"))
            scene_path = argv[i + 1];
        else if (!strcmp(argv[i], "--res"))
            sscanf(argv[i + 1], "%ux%u", &w, &h);
        else if (!strcmp(argv[i], "--pixels"))
            pixels = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--frames"))
            frames = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--warmup"))
            warmup = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--threads"))
            threads = (uint32_t)atoi(argv[i + 1]);
    }
    if (!w || !h || w > SRV_MAX_SIDE || h > SRV_MAX_SIDE || !pixels || pixels > SRV_MAX_PIXEL_LIST ||
        !frames || frames > 100000) {
        fprintf(stderr,
                "usage: bench_sparse [--scene PATH] [--res WxH] [--pixels N] [--frames N] [--warmup N] "
                "[--threads T]\n");
        return 2;
    }
    scene_error err = {0};
    scene *s = scene_path ? scene_load(scene_path, NULL, &err) : scene_create_default(NULL, &err);
    scene_rt *rt = s ? scene_rt_create(s, NULL, &err) : NULL;
    if (!rt) {
        fprintf(stderr, "bench_sparse: %s\n", err.msg);
        return 1;
    }
    srv_viewer_id a[1], b[1], c[2], sparse;
    srv_loop *loop_a = bench_make_loop("bench_sparse", s, rt, false, threads, 1, w, h, a);
    srv_loop *loop_b = bench_make_loop("bench_sparse", s, rt, false, threads, 1, w, h, b);
    srv_loop *loop_c = bench_make_loop("bench_sparse", s, rt, false, threads, 2, w, h, c);
    if (srv_viewer_add(loop_b, &(srv_viewer_desc){.max_pixels = pixels}, &sparse) != FXC_OK) {
        fprintf(stderr, "bench_sparse: cannot add the sparse viewer\n");
        return 1;
    }
    uint32_t *list = malloc(pixels * sizeof *list);
    double *ratio_ms_b = malloc(frames * sizeof(double)), *ratio_ms_c = malloc(frames * sizeof(double));
    double *ratio_rays_b = malloc(frames * sizeof(double)), *ratio_rays_c = malloc(frames * sizeof(double));
    if (!list || !ratio_ms_b || !ratio_ms_c || !ratio_rays_b || !ratio_rays_c)
        return 1;
    uint32_t rng = 12345, n = 0;
    uint64_t primary_b = 0, primary_a = 0;
    for (uint32_t f = 0; f < warmup + frames; f++) {
        srv_camera cam = srv_camgen_camera(SRV_CAMGEN_ORBIT, s, 0, 1, f, 1);
        for (uint32_t i = 0; i < pixels; i++) {
            rng = rng * 1664525u + 1013904223u;
            uint32_t x = (rng >> 4) % w;
            rng = rng * 1664525u + 1013904223u;
            list[i] = SRV_PIXEL_XY(x, (rng >> 4) % h);
        }
        srv_frame_stats sa, sb, sc;
        srv_viewer_set_camera(loop_a, a[0], &cam);
        double t = cpu_ms();
        srv_loop_frame(loop_a, &sa);
        double ms_a = cpu_ms() - t;
        srv_viewer_set_camera(loop_b, b[0], &cam);
        t = cpu_ms();
        if (srv_viewer_set_pixels(loop_b, sparse, &cam, w, h, list, pixels, NULL) != FXC_OK) {
            fprintf(stderr, "bench_sparse: the pixel list was refused\n");
            return 1;
        }
        srv_loop_frame(loop_b, &sb);
        double ms_b = cpu_ms() - t;
        srv_viewer_set_camera(loop_c, c[0], &cam);
        srv_viewer_set_camera(loop_c, c[1], &cam);
        t = cpu_ms();
        srv_loop_frame(loop_c, &sc);
        double ms_c = cpu_ms() - t;
        if (f < warmup)
            continue;
        uint64_t ra = bench_effect_rays(&sa), rb = bench_effect_rays(&sb), rc = bench_effect_rays(&sc);
        ratio_ms_b[n] = ms_b / ms_a;
        ratio_ms_c[n] = ms_c / ms_a;
        ratio_rays_b[n] = ra ? (double)rb / (double)ra : 1.0;
        ratio_rays_c[n] = ra ? (double)rc / (double)ra : 1.0;
        primary_a += sa.visibility_rays;
        primary_b += sb.visibility_rays;
        n++;
    }
    printf(
        "bench_sparse: %s, %ux%u, a sample request of %u random pixels, %u frames (after %u), orbit camera\n",
        scene_path ? scene_path : "the embedded scene", w, h, pixels, n, warmup);
    printf("| per frame, against one viewer alone | median | p10 | p90 |\n|---|---|---|---|\n");
    printf("| CPU time, + the sample request | %.3f | %.3f | %.3f |\n", bench_quantile(ratio_ms_b, n, 0.5),
           bench_quantile(ratio_ms_b, n, 0.1), bench_quantile(ratio_ms_b, n, 0.9));
    printf("| CPU time, + a second whole viewer | %.3f | %.3f | %.3f |\n", bench_quantile(ratio_ms_c, n, 0.5),
           bench_quantile(ratio_ms_c, n, 0.1), bench_quantile(ratio_ms_c, n, 0.9));
    printf("| effect rays, + the sample request | %.3f | %.3f | %.3f |\n",
           bench_quantile(ratio_rays_b, n, 0.5), bench_quantile(ratio_rays_b, n, 0.1),
           bench_quantile(ratio_rays_b, n, 0.9));
    printf("| effect rays, + a second whole viewer | %.3f | %.3f | %.3f |\n",
           bench_quantile(ratio_rays_c, n, 0.5), bench_quantile(ratio_rays_c, n, 0.1),
           bench_quantile(ratio_rays_c, n, 0.9));
    printf("primary rays per frame: one viewer %.0f, with the sample request %.0f (distinct listed pixels "
           "added)\n",
           (double)primary_a / n, (double)primary_b / n);
    free(list);
    free(ratio_ms_b);
    free(ratio_ms_c);
    free(ratio_rays_b);
    free(ratio_rays_c);
    srv_loop_free(loop_a);
    srv_loop_free(loop_b);
    srv_loop_free(loop_c);
    scene_rt_free(rt);
    scene_free(s);
    return 0;
}
