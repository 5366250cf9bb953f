/* The error of fxcache-viewer's displayed frames against the true view (issue 11's latency benchmark,
 * bench/rc_latency.sh): reads a --display-out folder (display_NNNNN_NAME.png and display_NAME.csv) and a
 * folder of the server's own renders of the same cameras (`fxcache sim --trace DIR/display_NAME.trace --fps F
 * --out TRUTH --save-every 1`: frame_NNNN_viewer_00.png is display frame NNNN), and prints, over the display
 * frames at or after --from seconds that show something received (a frame shown, or with --reproject any
 * point): frames, RMSE (sRGB, 0..255: the 8-bit values, so what the viewer shows), its median and 95th
 * percentile over frames, the mean fraction of empty pixels (from the CSV), and the RMSE over the pixels that
 * show something (not pure black, the render cache's colour for empty pixels: Sponza has almost none of its
 * own), with the mean age of the newest frame's camera at each display frame. RMSE of a frame is over its
 * pixels and channels; the figure is the root of the mean of the frames' squared errors (so every pixel
 * weighs the same).
 *
 *   bench_display_error DISPLAY_DIR TRUTH_DIR [--from SECONDS] [--label TEXT]
 */
#include "image.h"

#include <glob.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Linear [0, 1] back to its 8-bit sRGB value (scene_image_read_rgb decoded it with the sRGB curve; this is
 * its inverse, rounded, so the original byte comes back). */
static double to_srgb8(float linear)
{
    double v = linear <= 0.0031308 ? 12.92 * linear : 1.055 * pow(linear, 1 / 2.4) - 0.055;
    return floor(v * 255 + 0.5);
}

static int compare_doubles(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: bench_display_error DISPLAY_DIR TRUTH_DIR [--from SECONDS] [--label TEXT]\n");
        return 2;
    }
    const char *display = argv[1], *truth = argv[2], *label = "";
    double from = 0;
    for (int i = 3; i + 1 < argc; i += 2) {
        if (strcmp(argv[i], "--from") == 0)
            from = atof(argv[i + 1]);
        else if (strcmp(argv[i], "--label") == 0)
            label = argv[i + 1];
    }
    char pattern[4096];
    snprintf(pattern, sizeof pattern, "%s/display_*.csv", display);
    glob_t found;
    if (glob(pattern, 0, NULL, &found) != 0 || found.gl_pathc != 1) {
        fprintf(stderr, "bench_display_error: %s: expected one file\n", pattern);
        return 1;
    }
    char csv[4096], name[256];
    snprintf(csv, sizeof csv, "%s", found.gl_pathv[0]);
    globfree(&found);
    const char *base = strrchr(csv, '/') + 1 + strlen("display_");
    snprintf(name, sizeof name, "%.*s", (int)(strlen(base) - strlen(".csv")), base);
    FILE *f = fopen(csv, "r");
    if (!f) {
        fprintf(stderr, "bench_display_error: %s: cannot open\n", csv);
        return 1;
    }
    char line[1024];
    if (!fgets(line, sizeof line, f)) {
        fclose(f);
        return 1;
    }
    size_t cap = 1024, n = 0;
    double *errors = malloc(cap * sizeof *errors);
    double squared_sum = 0, empty_sum = 0, lag_sum = 0, shown_sum = 0, shown_pixels = 0;
    size_t lag_count = 0;
    while (fgets(line, sizeof line, f)) {
        long index, frame, kinds[4];
        double time_s, frame_camera_s, empty;
        if (sscanf(line, "%ld,%lf,%ld,%lf,%lf,%ld,%ld,%ld,%ld", &index, &time_s, &frame, &frame_camera_s,
                   &empty, &kinds[0], &kinds[1], &kinds[2], &kinds[3]) != 9) {
            fprintf(stderr, "bench_display_error: %s: a line does not read: %s", csv, line);
            return 1;
        }
        if (time_s < from || frame < 0)
            continue;
        char a[4096], b[4096], msg[512];
        snprintf(a, sizeof a, "%s/display_%05ld_%s.png", display, index, name);
        snprintf(b, sizeof b, "%s/frame_%04ld_viewer_00.png", truth, index);
        uint32_t wa, ha, wb, hb;
        float *ia = NULL, *ib = NULL;
        if (scene_image_read_rgb(a, &wa, &ha, &ia, msg, sizeof msg) != 0 ||
            scene_image_read_rgb(b, &wb, &hb, &ib, msg, sizeof msg) != 0 || wa != wb || ha != hb) {
            fprintf(stderr, "bench_display_error: %s against %s: %s\n", a, b, msg);
            free(ia);
            free(ib);
            continue; /* the truth ended earlier (the viewer ran a little longer): counted as missing */
        }
        double sum = 0;
        for (size_t p = 0; p < (size_t)wa * ha; p++) {
            double pixel = 0;
            for (int c = 0; c < 3; c++) {
                double d = to_srgb8(ia[3 * p + c]) - to_srgb8(ib[3 * p + c]);
                pixel += d * d;
            }
            sum += pixel;
            if (ia[3 * p] > 0 || ia[3 * p + 1] > 0 || ia[3 * p + 2] > 0) {
                shown_sum += pixel;
                shown_pixels++;
            }
        }
        free(ia);
        free(ib);
        double mse = sum / ((double)wa * ha * 3);
        if (n == cap) {
            cap *= 2;
            errors = realloc(errors, cap * sizeof *errors);
        }
        errors[n++] = sqrt(mse);
        squared_sum += mse;
        empty_sum += empty;
        if (frame_camera_s == frame_camera_s) { /* not NaN */
            lag_sum += time_s - frame_camera_s;
            lag_count++;
        }
    }
    fclose(f);
    if (!n) {
        fprintf(stderr, "bench_display_error: no display frame to compare\n");
        return 1;
    }
    qsort(errors, n, sizeof *errors, compare_doubles);
    size_t p95 = (size_t)ceil(0.95 * (double)n);
    printf(
        "%s\tframes %zu\trmse %.2f\tmedian %.2f\tp95 %.2f\tempty %.4f\trmse shown %.2f\tcamera age %.0f ms\n",
        label, n, sqrt(squared_sum / (double)n),
        n % 2 ? errors[n / 2] : (errors[n / 2 - 1] + errors[n / 2]) / 2, errors[p95 - 1],
        empty_sum / (double)n, shown_pixels ? sqrt(shown_sum / (3 * shown_pixels)) : NAN,
        lag_count ? 1000 * lag_sum / (double)lag_count : NAN);
    free(errors);
    return 0;
}
