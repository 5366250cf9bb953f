/* Benchmark of the viewer client's render cache (viewer_client/rcache): the client frame time stage by stage
 * (the 2002 paper's Table 1, which measured 62.1 ms at 512 x 512 on a 1.7 GHz Pentium 4; the target
 * here is at most 4 ms on one core), its scaling to 1024 x 1024 (target: linear in the pixels) and to 2
 * threads (target: at least 1.7 times faster), what each stage switch saves, and what it costs in image
 * quality.
 *
 * Input: a small analytic scene ray cast on the CPU here (a checkered floor, five spheres lit by one
 * directional light, the sky at +inf), standing in for the server. A camera orbits the scene at 7 m, turning
 * `--deg` degrees a frame (default 2) while it looks at the centre. Frame 0 inserts one whole frame (colour
 * and depth, as the server's first frame); from then on every client frame inserts the answers to the
 * previous frame's requests (both kinds, each pixel ray cast exactly at the camera it was asked for, one
 * frame late: the server's answer), then renders with the predicted camera `--lead` frames ahead (default 2).
 * The budget is the default, width * height / 32 samples a frame (8192 at 512 x 512, the paper's "roughly
 * 8000"); capacity the default, width * height points (`--capacity F`: F points a pixel), tiles of 64
 * (`--tile`). The first `--warmup` frames (default 60: the cache fills after 32) are not timed; the next
 * `--frames` (default 100) are, and each repetition reports the median of its frames; tables give the median
 * over `--reps` repetitions (default 5) and their range. A frame's time is the render call plus the inserts
 * before it ("update points"); the ray casting of the answers is the server's and is not counted.
 *
 * Comparisons alternate inside every repetition (1 against 2 threads; default against each switch), so each
 * repetition gives a ratio measured under the same load; the tables report medians of those per-repetition
 * ratios. Image quality: every 10th measured frame is compared with the exact ray-cast image of the same
 * camera (mean absolute error over channels, and the share of pixels off by more than 32 in a channel).
 *
 * Usage: bench_rcache [--res 512] [--reps 5] [--warmup 60] [--frames 100] [--deg 2] [--lead 2] [--tile 64]
 *        [--capacity F] [--pin CPU] [--separate-pixels]
 *        [--only table|scaling|threads|split|split-pixels|fuse|share|direct|bands|switches|quality]
 *        (default: all, in that order; --separate-pixels: the table with the depth cull, interpolation and
 *        prefilter as separate passes, each in its own row, instead of fused). Each table also gives the
 * process CPU time of a frame: on a machine shared with other jobs the wall time includes the time the
 * process waited for a core. */
#define _GNU_SOURCE
#include "rcache.h"

#include <math.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench_util.h"

#define PI 3.14159265358979323846

enum { MAX_REPS = 64 };

/* ---- the scene, ray cast in double --------------------------------------------------------------------- */

typedef struct ball {
    double c[3], r;
    double rgb[3];
} ball;

static const ball balls[] = {
    {{0, 1, 0}, 1.0, {0.85, 0.25, 0.2}},       {{2.5, 0.6, -1}, 0.6, {0.2, 0.7, 0.3}},
    {{-2, 0.8, 1.5}, 0.8, {0.25, 0.35, 0.9}},  {{1.2, 0.4, 2.2}, 0.4, {0.9, 0.8, 0.2}},
    {{-1.5, 1.5, -2.5}, 1.5, {0.7, 0.7, 0.7}},
};
static const double light[3] = {0.48, 0.8, 0.36}; /* unit */

static uint8_t to_byte(double v)
{
    v = v < 0 ? 0 : v > 1 ? 1 : v;
    return (uint8_t)(255 * sqrt(v) + 0.5); /* a rough sRGB */
}

/* Distance along the unit ray and colour; +inf for the sky. */
static float cast(const double o[3], const double d[3], uint8_t rgb[3])
{
    double best = INFINITY;
    int hit = -1;
    for (int b = 0; b < (int)(sizeof balls / sizeof balls[0]); b++) {
        double oc[3] = {o[0] - balls[b].c[0], o[1] - balls[b].c[1], o[2] - balls[b].c[2]};
        double bb = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
        double cc = oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - balls[b].r * balls[b].r;
        double disc = bb * bb - cc;
        if (disc < 0)
            continue;
        double t = -bb - sqrt(disc);
        if (t > 1e-6 && t < best)
            best = t, hit = b;
    }
    double tf = d[1] < 0 ? -o[1] / d[1] : INFINITY;
    if (hit >= 0 && best <= tf) {
        double n[3];
        for (int k = 0; k < 3; k++)
            n[k] = (o[k] + best * d[k] - balls[hit].c[k]) / balls[hit].r;
        double lambert = n[0] * light[0] + n[1] * light[1] + n[2] * light[2];
        double shade = 0.15 + 0.85 * (lambert > 0 ? lambert : 0);
        for (int k = 0; k < 3; k++)
            rgb[k] = to_byte(balls[hit].rgb[k] * shade);
        return (float)best;
    }
    if (tf < INFINITY) {
        double x = o[0] + tf * d[0], z = o[2] + tf * d[2];
        bool dark = ((int)floor(x) + (int)floor(z)) & 1;
        double fade = 1.0 / (1.0 + 0.01 * tf);
        for (int k = 0; k < 3; k++)
            rgb[k] = to_byte((dark ? 0.15 : 0.75) * fade + 0.05 * k);
        return (float)tf;
    }
    double up = d[1] > 0 ? d[1] : 0;
    rgb[0] = to_byte(0.35 + 0.2 * (1 - up)), rgb[1] = to_byte(0.5 + 0.2 * (1 - up)), rgb[2] = to_byte(0.85);
    return INFINITY;
}

/* The server's pinhole model (server/cameras/camera.h) in double. */
typedef struct frame_cam {
    view_rc_camera cam;
    double o[3], f[3], r[3], u[3], thx, thy;
    uint32_t w, h;
} frame_cam;

static frame_cam setup(view_rc_camera cam, uint32_t w, uint32_t h)
{
    frame_cam c = {.cam = cam, .w = w, .h = h};
    double len = 0;
    for (int k = 0; k < 3; k++) {
        c.o[k] = cam.position[k];
        c.f[k] = cam.direction[k];
        len += c.f[k] * c.f[k];
    }
    for (int k = 0; k < 3; k++)
        c.f[k] /= sqrt(len);
    double rl = sqrt(c.f[2] * c.f[2] + c.f[0] * c.f[0]);
    c.r[0] = -c.f[2] / rl, c.r[1] = 0, c.r[2] = c.f[0] / rl;
    c.u[0] = c.r[1] * c.f[2] - c.r[2] * c.f[1];
    c.u[1] = c.r[2] * c.f[0] - c.r[0] * c.f[2];
    c.u[2] = c.r[0] * c.f[1] - c.r[1] * c.f[0];
    c.thy = tan(cam.fov_deg * PI / 360.0);
    c.thx = c.thy * w / h;
    return c;
}

static float cast_pixel(const frame_cam *c, uint32_t x, uint32_t y, uint8_t rgb[3])
{
    double sx = (2.0 * (x + 0.5) / c->w - 1.0) * c->thx, sy = (1.0 - 2.0 * (y + 0.5) / c->h) * c->thy;
    double d[3], len = 0;
    for (int k = 0; k < 3; k++) {
        d[k] = c->f[k] + sx * c->r[k] + sy * c->u[k];
        len += d[k] * d[k];
    }
    for (int k = 0; k < 3; k++)
        d[k] /= sqrt(len);
    return cast(c->o, d, rgb);
}

/* The orbit: radius 7 m, height 2 m, looking at (0, 0.8, 0); deg degrees a frame. */
static view_rc_camera orbit(double frame, double deg)
{
    double a = frame * deg * PI / 180;
    view_rc_camera c = {.position = {7 * sin(a), 2.0, 7 * cos(a)}, .fov_deg = 60};
    c.direction[0] = (float)(0 - c.position[0]);
    c.direction[1] = (float)(0.8 - c.position[1]);
    c.direction[2] = (float)(0 - c.position[2]);
    return c;
}

/* ---- one run of the sequence --------------------------------------------------------------------------- */

typedef struct bench_opts {
    uint32_t res, tile;
    double capacity; /* points per pixel (0: the default) */
    int reps, warmup, frames, lead;
    double deg;
    bool separate; /* --separate-pixels: the table with the pixel passes separate (each stage timed alone) */
} bench_opts;

typedef struct run_result {
    double stage_ms[VIEW_RC_STAGE_COUNT]; /* medians over the measured frames */
    double frame_ms;                      /* median of render + inserts */
    double points, migrated, projected, culled, dropped, evicted, predicted, empty; /* medians */
    double interp, prefiltered;                                                     /* medians */
    double cpu_ms;                    /* median of the frame's process CPU time (render + inserts) */
    double mean_abs_error, bad_share; /* quality (when asked) */
} run_result;

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median_of(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* Process CPU time, milliseconds: on a machine other jobs share, what the frame cost apart from waiting. */
static double cpu_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* The server's answer to requests of camera c: each pixel ray cast. */
static uint32_t cast_answers(const frame_cam *c, const view_rc_pixel *px, uint32_t n, view_rc_sample *buf)
{
    for (uint32_t i = 0; i < n; i++) {
        buf[i].x = px[i].x;
        buf[i].y = px[i].y;
        buf[i].depth = cast_pixel(c, px[i].x, px[i].y, buf[i].rgb);
    }
    return n;
}

static void insert(view_rc *rc, const frame_cam *c, const view_rc_sample *buf, uint32_t n)
{
    if (view_rc_insert_samples(rc, &c->cam, c->w, c->h, buf, n) != FXC_OK) {
        fprintf(stderr, "bench_rcache: insert_samples failed\n");
        exit(1);
    }
}

static void run(const bench_opts *o, uint32_t res, const view_rc_desc *switches, uint32_t threads,
                bool quality, run_result *out)
{
    view_rc_desc d = *switches;
    d.width = d.height = res;
    d.tile_size = o->tile;
    d.capacity = (uint32_t)(o->capacity * res * res);
    d.threads = threads;
    view_rc *rc = NULL;
    if (view_rc_create(&d, &rc) != FXC_OK) {
        fprintf(stderr, "bench_rcache: cannot create the cache\n");
        exit(1);
    }
    size_t pixels = (size_t)res * res;
    uint8_t *rgb = malloc(pixels * 3);
    float *depth = malloc(pixels * sizeof(float));
    view_rc_pixel *req = malloc(sizeof *req * pixels), *pred = malloc(sizeof *pred * pixels);
    view_rc_sample *buf = malloc(sizeof *buf * 2 * pixels);
    int total = o->warmup + o->frames;
    double *series[VIEW_RC_STAGE_COUNT + 12];
    for (int s = 0; s < VIEW_RC_STAGE_COUNT + 12; s++)
        series[s] = calloc((size_t)o->frames, sizeof(double));
    double err_sum = 0, bad_sum = 0;
    int quality_frames = 0;

    frame_cam first = setup(orbit(0, o->deg), res, res);
    for (uint32_t y = 0; y < res; y++)
        for (uint32_t x = 0; x < res; x++)
            depth[(size_t)y * res + x] = cast_pixel(&first, x, y, rgb + 3 * ((size_t)y * res + x));
    view_rc_insert_frame(rc, &first.cam, res, res, rgb, depth);
    uint32_t nreq = 0, npred = 0;
    frame_cam prev = first, prev_pred = first;
    for (int f = 0; f < total; f++) {
        frame_cam cam = setup(orbit(f, o->deg), res, res);
        frame_cam predicted = setup(orbit(f + o->lead, o->deg), res, res);
        /* The server's answers, ray cast before the clock starts; then inserted and rendered. */
        uint32_t nreq_cast = cast_answers(&prev, req, nreq, buf);
        uint32_t npred_cast = cast_answers(&prev_pred, pred, npred, buf + nreq_cast);
        double cpu0 = cpu_ms();
        insert(rc, &prev, buf, nreq_cast);
        insert(rc, &prev_pred, buf + nreq_cast, npred_cast);
        view_rc_frame fr;
        if (view_rc_render(rc, &cam.cam, &predicted.cam, &fr) != FXC_OK) {
            fprintf(stderr, "bench_rcache: render failed\n");
            exit(1);
        }
        double cpu = cpu_ms() - cpu0;
        if (f >= o->warmup) {
            int i = f - o->warmup;
            for (int s = 0; s < VIEW_RC_STAGE_COUNT; s++)
                series[s][i] = fr.stats.stage_ms[s];
            series[VIEW_RC_STAGE_COUNT][i] = fr.stats.total_ms + fr.stats.stage_ms[VIEW_RC_STAGE_UPDATE];
            series[VIEW_RC_STAGE_COUNT + 1][i] = fr.stats.points;
            series[VIEW_RC_STAGE_COUNT + 2][i] = fr.stats.migrated;
            series[VIEW_RC_STAGE_COUNT + 3][i] = fr.stats.projected;
            series[VIEW_RC_STAGE_COUNT + 4][i] = fr.stats.culled;
            series[VIEW_RC_STAGE_COUNT + 5][i] = fr.stats.dropped;
            series[VIEW_RC_STAGE_COUNT + 6][i] = fr.stats.evicted;
            series[VIEW_RC_STAGE_COUNT + 7][i] = fr.predicted_count;
            series[VIEW_RC_STAGE_COUNT + 8][i] = fr.stats.pixels[VIEW_RC_EMPTY];
            series[VIEW_RC_STAGE_COUNT + 9][i] = fr.stats.pixels[VIEW_RC_INTERP];
            series[VIEW_RC_STAGE_COUNT + 10][i] = fr.stats.pixels[VIEW_RC_PREFILTER];
            series[VIEW_RC_STAGE_COUNT + 11][i] = cpu;
            if (quality && i % 10 == 0) {
                double err = 0;
                size_t bad = 0;
                for (uint32_t y = 0; y < res; y++)
                    for (uint32_t x = 0; x < res; x++) {
                        uint8_t truth[3];
                        cast_pixel(&cam, x, y, truth);
                        const uint8_t *got = fr.rgb + 3 * ((size_t)y * res + x);
                        int worst = 0;
                        for (int k = 0; k < 3; k++) {
                            int diff = abs((int)got[k] - (int)truth[k]);
                            err += diff;
                            worst = diff > worst ? diff : worst;
                        }
                        bad += worst > 32;
                    }
                err_sum += err / (3.0 * pixels);
                bad_sum += (double)bad / pixels;
                quality_frames++;
            }
        }
        memcpy(req, fr.requests, fr.request_count * sizeof *req);
        memcpy(pred, fr.predicted_requests, fr.predicted_count * sizeof *pred);
        nreq = fr.request_count;
        npred = fr.predicted_count;
        prev = cam;
        prev_pred = predicted;
    }
    for (int s = 0; s < VIEW_RC_STAGE_COUNT; s++)
        out->stage_ms[s] = median_of(series[s], o->frames);
    out->frame_ms = median_of(series[VIEW_RC_STAGE_COUNT], o->frames);
    double *figs[] = {&out->points,  &out->migrated,    &out->projected, &out->culled,
                      &out->dropped, &out->evicted,     &out->predicted, &out->empty,
                      &out->interp,  &out->prefiltered, &out->cpu_ms};
    for (int k = 0; k < 11; k++)
        *figs[k] = median_of(series[VIEW_RC_STAGE_COUNT + 1 + k], o->frames);
    out->mean_abs_error = quality_frames ? err_sum / quality_frames : 0;
    out->bad_share = quality_frames ? bad_sum / quality_frames : 0;
    for (int s = 0; s < VIEW_RC_STAGE_COUNT + 12; s++)
        free(series[s]);
    free(rgb);
    free(depth);
    free(req);
    free(pred);
    free(buf);
    view_rc_destroy(rc);
}

/* ---- sections ------------------------------------------------------------------------------------------ */

static void range_of(const double *v, int n, double *lo, double *mid, double *hi)
{
    *lo = bench_quantile(v, n, 0);
    *mid = bench_quantile(v, n, 0.5);
    *hi = bench_quantile(v, n, 1);
}

static void section_table(const bench_opts *o, uint32_t res)
{
    double per[VIEW_RC_STAGE_COUNT][MAX_REPS], frame[MAX_REPS], sums[MAX_REPS], cpu[MAX_REPS];
    run_result last = {0};
    for (int r = 0; r < o->reps; r++) {
        run(o, res, &(view_rc_desc){.separate_pixel_passes = o->separate}, 1, false, &last);
        sums[r] = 0;
        for (int s = 0; s < VIEW_RC_STAGE_COUNT; s++) {
            per[s][r] = last.stage_ms[s];
            sums[r] += last.stage_ms[s];
        }
        frame[r] = last.frame_ms;
        cpu[r] = last.cpu_ms;
    }
    double lo, mid, hi, sum_mid;
    range_of(sums, o->reps, &lo, &sum_mid, &hi);
    printf("\n%ux%u, 1 thread: median of %d repetitions (each the median of %d frames after %d of warm-up)\n",
           res, res, o->reps, o->frames, o->warmup);
    printf("| stage | ms | range | %% of the sum |\n|---|---|---|---|\n");
    for (int s = 0; s < VIEW_RC_STAGE_COUNT; s++) {
        range_of(per[s], o->reps, &lo, &mid, &hi);
        printf("| %s | %.3f | %.3f-%.3f | %.1f |\n", view_rc_stage_name(s), mid, lo, hi, 100 * mid / sum_mid);
    }
    range_of(sums, o->reps, &lo, &mid, &hi);
    printf("| **sum of the stage medians** | **%.3f** | %.3f-%.3f | |\n", mid, lo, hi);
    range_of(cpu, o->reps, &lo, &mid, &hi);
    printf("| frame, process CPU time | %.3f | %.3f-%.3f | |\n", mid, lo, hi);
    range_of(frame, o->reps, &lo, &mid, &hi);
    printf("| frame, wall (median of per-frame totals) | %.3f | %.3f-%.3f | |\n", mid, lo, hi);
    printf(
        "per frame (last repetition, medians): %.0f points, %.0f projected, %.0f migrated, %.0f culled, "
        "%.0f dropped, %.0f evicted, %.0f predicted requests; pixels: %.0f interpolated, %.0f prefiltered, "
        "%.0f empty\n",
        last.points, last.projected, last.migrated, last.culled, last.dropped, last.evicted, last.predicted,
        last.interp, last.prefiltered, last.empty);
}

/* The sum of a run's stage medians: each stage is short, so its median over the frames leaves out the frames
 * in which the process waited for a core; the sum is the frame as it runs when it has one. */
static double stage_sum(const run_result *r)
{
    double sum = 0;
    for (int s = 0; s < VIEW_RC_STAGE_COUNT; s++)
        sum += r->stage_ms[s];
    return sum;
}

static void section_scaling(const bench_opts *o)
{
    /* 512 and 1024 alternate inside each repetition; the ratios are per pixel (1.0 = linear). */
    double wall[2][MAX_REPS], sums[2][MAX_REPS], cpu[2][MAX_REPS], ratio[3][MAX_REPS];
    for (int r = 0; r < o->reps; r++) {
        run_result a, b;
        run(o, 512, &(view_rc_desc){0}, 1, false, &a);
        run(o, 1024, &(view_rc_desc){0}, 1, false, &b);
        wall[0][r] = a.frame_ms, wall[1][r] = b.frame_ms;
        sums[0][r] = stage_sum(&a), sums[1][r] = stage_sum(&b);
        cpu[0][r] = a.cpu_ms, cpu[1][r] = b.cpu_ms;
        ratio[0][r] = b.frame_ms / (4 * a.frame_ms);
        ratio[1][r] = sums[1][r] / (4 * sums[0][r]);
        ratio[2][r] = b.cpu_ms / (4 * a.cpu_ms);
    }
    double lo, mid, hi;
    printf("\nscaling, 1 thread, %d repetitions alternating 512x512 and 1024x1024\n", o->reps);
    printf("| figure | 512x512 ms | 1024x1024 ms | 1024 / (4 x 512), median (range) |\n|---|---|---|---|\n");
    const char *names[3] = {"frame, wall (median of per-frame totals)", "sum of the stage medians",
                            "frame, process CPU time"};
    double(*series[3])[MAX_REPS] = {wall, sums, cpu};
    for (int k = 0; k < 3; k++) {
        range_of(ratio[k], o->reps, &lo, &mid, &hi);
        printf("| %s | %.3f | %.3f | %.3f (%.3f-%.3f) |\n", names[k],
               bench_quantile(series[k][0], o->reps, 0.5), bench_quantile(series[k][1], o->reps, 0.5), mid,
               lo, hi);
    }
}

/* Two configurations of one run (a: a_threads, b: b_threads), alternating per repetition: the per-stage
 * medians, each side's frame, the sums and both sides' process CPU time, and the per-repetition ratio a / b.
 * The labels name the sides ("1 thread", "dynamic") and the ratio ("speed-up (per-repetition ratio 1 thread /
 * 2 threads)" for frames, "speed-up" for the sums). */
typedef struct ab_labels {
    const char *title, *a, *b, *ratio_frames, *ratio_sums;
} ab_labels;

static void section_ab(const bench_opts *o, view_rc_desc da, int a_threads, view_rc_desc db, int b_threads,
                       const ab_labels *l)
{
    double ta[MAX_REPS], tb[MAX_REPS], ratio[MAX_REPS], sum_a[MAX_REPS], sum_b[MAX_REPS], sum_ratio[MAX_REPS],
        cpu_a[MAX_REPS], cpu_b[MAX_REPS];
    double sa[VIEW_RC_STAGE_COUNT][MAX_REPS], sb[VIEW_RC_STAGE_COUNT][MAX_REPS];
    for (int r = 0; r < o->reps; r++) {
        run_result a, b;
        run(o, o->res, &da, a_threads, false, &a);
        run(o, o->res, &db, b_threads, false, &b);
        ta[r] = a.frame_ms, tb[r] = b.frame_ms;
        ratio[r] = a.frame_ms / b.frame_ms;
        sum_a[r] = stage_sum(&a), sum_b[r] = stage_sum(&b);
        sum_ratio[r] = sum_a[r] / sum_b[r];
        cpu_a[r] = a.cpu_ms, cpu_b[r] = b.cpu_ms;
        for (int s = 0; s < VIEW_RC_STAGE_COUNT; s++)
            sa[s][r] = a.stage_ms[s], sb[s][r] = b.stage_ms[s];
    }
    double lo, mid, hi;
    printf("\n%ux%u, %s, %d repetitions alternating\n", o->res, o->res, l->title, o->reps);
    printf("| stage | %s ms | %s ms |\n|---|---|---|\n", l->a, l->b);
    for (int s = 0; s < VIEW_RC_STAGE_COUNT; s++)
        printf("| %s | %.3f | %.3f |\n", view_rc_stage_name(s), bench_quantile(sa[s], o->reps, 0.5),
               bench_quantile(sb[s], o->reps, 0.5));
    range_of(ta, o->reps, &lo, &mid, &hi);
    printf("| frame, %s | %.3f (%.3f-%.3f) | |\n", l->a, mid, lo, hi);
    range_of(tb, o->reps, &lo, &mid, &hi);
    printf("| frame, %s | | %.3f (%.3f-%.3f) |\n", l->b, mid, lo, hi);
    printf("| sum of the stage medians | %.3f | %.3f |\n", bench_quantile(sum_a, o->reps, 0.5),
           bench_quantile(sum_b, o->reps, 0.5));
    /* All threads' CPU time, the pool's spinning between stages included: above 1 thread's by the work that
     * sharing adds (lines moving between the cores) and the spinning. */
    printf("| frame, process CPU time (all threads) | %.3f | %.3f |\n", bench_quantile(cpu_a, o->reps, 0.5),
           bench_quantile(cpu_b, o->reps, 0.5));
    range_of(ratio, o->reps, &lo, &mid, &hi);
    printf("%s, frames: median %.3f, range %.3f-%.3f\n", l->ratio_frames, mid, lo, hi);
    range_of(sum_ratio, o->reps, &lo, &mid, &hi);
    printf("%s, sums of the stage medians: median %.3f, range %.3f-%.3f\n", l->ratio_sums, mid, lo, hi);
}

static void section_threads(const bench_opts *o)
{
    section_ab(o, (view_rc_desc){0}, 1, (view_rc_desc){0}, 2,
               &(ab_labels){"1 against 2 threads", "1 thread", "2 threads",
                            "speed-up (per-repetition ratio 1 thread / 2 threads)", "speed-up"});
}

/* The pixel passes as three runs over the image (view_rc_desc.separate_pixel_passes, each stage timed alone)
 * against fused by bands (the default), on 1 and then on 2 threads, alternating. */
static void section_fuse(const bench_opts *o)
{
    for (int threads = 1; threads <= 2; threads++)
        section_ab(o, (view_rc_desc){.separate_pixel_passes = true}, threads, (view_rc_desc){0}, threads,
                   &(ab_labels){threads == 1 ? "1 thread, pixel passes separate against fused"
                                             : "2 threads, pixel passes separate against fused",
                                "separate", "fused", "separate / fused (per-repetition ratio)",
                                "separate / fused"});
}

/* The static split of the point passes against the dynamic hand-out (view_rc_desc.dynamic_points), both on 2
 * threads, alternating: what keeping each chunk on one core does. */
static void section_split(const bench_opts *o)
{
    section_ab(o, (view_rc_desc){.dynamic_points = true}, 2, (view_rc_desc){0}, 2,
               &(ab_labels){"2 threads, point passes dynamic against static", "dynamic", "static",
                            "dynamic / static (per-repetition ratio)", "dynamic / static"});
}

/* The same for the passes over the image (view_rc_desc.dynamic_pixels: z-buffer tiles, depth cull,
 * interpolation, prefilter, dither), the point passes static in both. */
static void section_split_pixels(const bench_opts *o)
{
    section_ab(o, (view_rc_desc){.dynamic_pixels = true}, 2, (view_rc_desc){0}, 2,
               &(ab_labels){"2 threads, pixel passes dynamic against static", "dynamic", "static",
                            "dynamic / static (per-repetition ratio)", "dynamic / static"});
}

/* The dither and the ageing as two pool runs (view_rc_desc.separate_sample_age) against one shared run (the
 * default on 2+ threads), both on 2 threads, alternating. */
static void section_share(const bench_opts *o)
{
    section_ab(o, (view_rc_desc){.separate_sample_age = true}, 2, (view_rc_desc){0}, 2,
               &(ab_labels){"2 threads, dither and ageing in two runs against one", "two runs", "one run",
                            "two runs / one run (per-repetition ratio)", "two runs / one run"});
}

/* One thread through the tile lists (view_rc_desc.tiled_one_thread) against each chunk projected straight
 * into the image's z-buffer (the default), alternating: what the direct
 * z-buffer does. */
static void section_direct(const bench_opts *o)
{
    section_ab(o, (view_rc_desc){.tiled_one_thread = true}, 1, (view_rc_desc){0}, 1,
               &(ab_labels){"1 thread, z-buffer through the tiles against straight into the image", "tiled",
                            "direct", "tiled / direct (per-repetition ratio)", "tiled / direct"});
}

/* The band lists (view_rc_desc.band_lists: the points bucket-sorted by bands of full rows, each band's
 * z-buffer in L2) against the path without them (the default), on 1 thread (the direct z-buffer) and then
 * on 2 (the tiles), alternating. */
static void section_bands(const bench_opts *o)
{
    for (int threads = 1; threads <= 2; threads++)
        section_ab(o, (view_rc_desc){0}, threads, (view_rc_desc){.band_lists = true}, threads,
                   &(ab_labels){threads == 1 ? "1 thread, z-buffer direct against band lists"
                                             : "2 threads, z-buffer through the tiles against band lists",
                                threads == 1 ? "direct" : "tiles", "bands",
                                "without / with bands (per-repetition ratio)", "without / with bands"});
}

typedef struct variant {
    const char *name;
    view_rc_desc d;
} variant;

static const variant variants[] = {
    {"no_prediction", {.no_prediction = true}}, {"no_prefilter", {.no_prefilter = true}},
    {"no_eviction", {.no_eviction = true}},     {"no_tiling", {.no_tiling = true}},
    {"no_depth_cull", {.no_depth_cull = true}},
};

static void section_switches(const bench_opts *o)
{
    printf("\n%ux%u, 1 thread, each switch against the default, %d repetitions alternating\n", o->res, o->res,
           o->reps);
    printf("| switch | default frame ms | switched frame ms | switched / default (range) | stages that "
           "change |\n");
    printf("|---|---|---|---|---|\n");
    for (size_t v = 0; v < sizeof variants / sizeof variants[0]; v++) {
        double a_ms[MAX_REPS], b_ms[MAX_REPS], ratio[MAX_REPS];
        double a_stage[VIEW_RC_STAGE_COUNT][MAX_REPS], b_stage[VIEW_RC_STAGE_COUNT][MAX_REPS];
        for (int r = 0; r < o->reps; r++) {
            run_result a, b;
            run(o, o->res, &(view_rc_desc){0}, 1, false, &a);
            run(o, o->res, &variants[v].d, 1, false, &b);
            a_ms[r] = a.frame_ms;
            b_ms[r] = b.frame_ms;
            ratio[r] = b.frame_ms / a.frame_ms;
            for (int s = 0; s < VIEW_RC_STAGE_COUNT; s++)
                a_stage[s][r] = a.stage_ms[s], b_stage[s][r] = b.stage_ms[s];
        }
        /* The two stages whose medians moved most. */
        int most[2] = {0, 0};
        double moved[2] = {0, 0};
        for (int st = 0; st < VIEW_RC_STAGE_COUNT; st++) {
            double delta =
                bench_quantile(b_stage[st], o->reps, 0.5) - bench_quantile(a_stage[st], o->reps, 0.5);
            if (fabs(delta) > fabs(moved[0])) {
                moved[1] = moved[0], most[1] = most[0];
                moved[0] = delta, most[0] = st;
            } else if (fabs(delta) > fabs(moved[1])) {
                moved[1] = delta, most[1] = st;
            }
        }
        double lo, mid, hi;
        range_of(ratio, o->reps, &lo, &mid, &hi);
        printf("| %s | %.3f | %.3f | %.3f (%.3f-%.3f) | %s %+.3f ms, %s %+.3f ms |\n", variants[v].name,
               bench_quantile(a_ms, o->reps, 0.5), bench_quantile(b_ms, o->reps, 0.5), mid, lo, hi,
               view_rc_stage_name(most[0]), moved[0], view_rc_stage_name(most[1]), moved[1]);
    }
}

static void section_quality(const bench_opts *o)
{
    printf("\n%ux%u, image against the exact ray-cast image of the same camera, every 10th measured frame "
           "(deterministic: one run each)\n",
           o->res, o->res);
    printf("| variant | mean abs error (0-255) | pixels off by > 32 | empty pixels | predicted requests |\n");
    printf("|---|---|---|---|---|\n");
    run_result a;
    run(o, o->res, &(view_rc_desc){0}, 1, true, &a);
    printf("| default | %.2f | %.2f %% | %.0f | %.0f |\n", a.mean_abs_error, 100 * a.bad_share, a.empty,
           a.predicted);
    for (size_t v = 0; v < sizeof variants / sizeof variants[0]; v++) {
        if (variants[v].d.no_tiling)
            continue; /* the same image as the default up to ties */
        run(o, o->res, &variants[v].d, 1, true, &a);
        printf("| %s | %.2f | %.2f %% | %.0f | %.0f |\n", variants[v].name, a.mean_abs_error,
               100 * a.bad_share, a.empty, a.predicted);
    }
}

int main(int argc, char **argv)
{
    bench_opts o = {.res = 512, .tile = 64, .reps = 5, .warmup = 60, .frames = 100, .lead = 2, .deg = 2};
    const char *only = NULL;
    int pin = -1;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *next = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--res") && next)
            o.res = (uint32_t)atoi(argv[++i]);
        else if (!strcmp(a, "--capacity") && next)
            o.capacity = atof(argv[++i]);
        else if (!strcmp(a, "--tile") && next)
            o.tile = (uint32_t)atoi(argv[++i]);
        else if (!strcmp(a, "--reps") && next)
            o.reps = atoi(argv[++i]);
        else if (!strcmp(a, "--warmup") && next)
            o.warmup = atoi(argv[++i]);
        else if (!strcmp(a, "--frames") && next)
            o.frames = atoi(argv[++i]);
        else if (!strcmp(a, "--deg") && next)
            o.deg = atof(argv[++i]);
        else if (!strcmp(a, "--lead") && next)
            o.lead = atoi(argv[++i]);
        else if (!strcmp(a, "--pin") && next)
            pin = atoi(argv[++i]);
        else if (!strcmp(a, "--only") && next)
            only = argv[++i];
        else if (!strcmp(a, "--separate-pixels"))
            o.separate = true;
        else {
            fprintf(stderr,
                    "usage: bench_rcache [--res 512] [--reps 5] [--warmup 60] [--frames 100] [--deg 2] "
                    "[--lead 2] [--tile 64] [--capacity F] [--pin CPU] [--separate-pixels] "
                    "[--only "
                    "table|scaling|threads|split|split-pixels|fuse|share|direct|bands|switches|quality]\n");
            return !strcmp(a, "-h") || !strcmp(a, "--help") ? 0 : 2;
        }
    }
    if (o.reps < 1 || o.reps > MAX_REPS || o.frames < 1 || o.warmup < 0 || o.res < 16 || o.res > 4096) {
        fprintf(stderr, "bench_rcache: bad --reps (1..%d), --frames, --warmup or --res (16..4096)\n",
                MAX_REPS);
        return 2;
    }
    if (pin >= 0) {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET(pin, &set);
        if (sched_setaffinity(0, sizeof set, &set) != 0)
            perror("bench_rcache: sched_setaffinity");
    }
    printf("bench_rcache: %ux%u, orbit %.1f deg/frame, prediction %d frames ahead, %d warm-up + %d measured "
           "frames, "
           "%d repetitions%s\n",
           o.res, o.res, o.deg, o.lead, o.warmup, o.frames, o.reps, pin >= 0 ? ", pinned" : "");
    if (!only || !strcmp(only, "table"))
        section_table(&o, o.res);
    if (!only || !strcmp(only, "scaling"))
        section_scaling(&o);
    if (!only || !strcmp(only, "threads"))
        section_threads(&o);
    if (!only || !strcmp(only, "split"))
        section_split(&o);
    if (!only || !strcmp(only, "split-pixels"))
        section_split_pixels(&o);
    if (!only || !strcmp(only, "fuse"))
        section_fuse(&o);
    if (!only || !strcmp(only, "share"))
        section_share(&o);
    if (!only || !strcmp(only, "direct"))
        section_direct(&o);
    if (!only || !strcmp(only, "bands"))
        section_bands(&o);
    if (!only || !strcmp(only, "switches"))
        section_switches(&o);
    if (!only || !strcmp(only, "quality"))
        section_quality(&o);
    return 0;
}
