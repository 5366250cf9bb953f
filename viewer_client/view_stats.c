/* The viewer client's figures: latency percentiles, the summary in words and the --stats JSON (view_stats.h).
 * The JSON is written by hand (writing needs no library; nothing here parses JSON); strings are escaped and
 * bytes outside printable ASCII become '?', so the file is valid JSON whatever a server put in a reason. */
#include "view_stats.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

bool view_latency_add(view_latency *l, double ms)
{
    if (l->count == l->capacity) {
        size_t capacity = l->capacity ? l->capacity * 2 : 1024;
        if (capacity > SIZE_MAX / sizeof *l->samples_ms)
            return false;
        double *grown = realloc(l->samples_ms, capacity * sizeof *grown);
        if (!grown)
            return false;
        l->samples_ms = grown;
        l->capacity = capacity;
    }
    l->samples_ms[l->count++] = ms;
    return true;
}

void view_latency_free(view_latency *l)
{
    free(l->samples_ms);
    memset(l, 0, sizeof *l);
}

static int compare_doubles(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

void view_sort(double *values, size_t n)
{
    if (n > 1)
        qsort(values, n, sizeof *values, compare_doubles);
}

double view_median(const double *sorted, size_t n)
{
    if (n == 0)
        return 0;
    return n % 2 ? sorted[n / 2] : (sorted[n / 2 - 1] + sorted[n / 2]) / 2;
}

double view_percentile(const double *sorted, size_t n, double p)
{
    if (n == 0)
        return 0;
    /* Nearest rank: ceil(p/100 * n), 1-based, with a tolerance so that 95 % of 20 values is the 19th even
     * where 0.95 * 20 rounds to a hair above 19. */
    double exact = p / 100.0 * (double)n;
    size_t rank = (size_t)exact;
    if ((double)rank < exact - 1e-9)
        rank++;
    if (rank < 1)
        rank = 1;
    if (rank > n)
        rank = n;
    return sorted[rank - 1];
}

bool view_figures_of(const view_viewer_stats *viewers, uint32_t n, view_figures *out)
{
    memset(out, 0, sizeof *out);
    size_t samples = 0;
    for (uint32_t i = 0; i < n; i++) {
        const view_viewer_stats *v = &viewers[i];
        out->frames += v->frames;
        out->decode_errors += v->decode_errors;
        out->bytes_received += v->bytes_received;
        out->frame_bytes += v->frame_bytes;
        if (v->seconds > 0)
            out->fps += (double)v->frames / v->seconds;
        samples += v->latency.count;
    }
    out->latency_samples = samples;
    out->bytes_per_frame = out->frames ? (double)out->frame_bytes / (double)out->frames : 0;
    if (samples == 0)
        return true;
    double *all = malloc(samples * sizeof *all);
    if (!all)
        return false;
    size_t at = 0;
    for (uint32_t i = 0; i < n; i++) {
        if (viewers[i].latency.count)
            memcpy(all + at, viewers[i].latency.samples_ms, viewers[i].latency.count * sizeof *all);
        at += viewers[i].latency.count;
    }
    view_sort(all, samples);
    out->latency_median = view_median(all, samples);
    out->latency_p95 = view_percentile(all, samples, 95);
    free(all);
    return true;
}

/* One summary line's figures in words. */
static void print_figures(FILE *out, const view_figures *f)
{
    fprintf(out, "%llu frames, %.1f fps", (unsigned long long)f->frames, f->fps);
    if (f->latency_samples)
        fprintf(out, ", latency median %.1f ms, 95th percentile %.1f ms", f->latency_median, f->latency_p95);
    else
        fprintf(out, ", no latency measured");
    fprintf(out, ", %.2f MB received, %.0f bytes a frame", (double)f->bytes_received / 1e6,
            f->bytes_per_frame);
    if (f->decode_errors)
        fprintf(out, ", %llu frames did not decode", (unsigned long long)f->decode_errors);
}

void view_stats_print_summary(FILE *out, const view_viewer_stats *viewers, uint32_t n, const char *url,
                              double seconds)
{
    uint32_t failed = 0;
    for (uint32_t i = 0; i < n; i++)
        failed += viewers[i].failed;
    fprintf(out, "fxcache-viewer: %u viewer%s on %s for %.1f s", n, n == 1 ? "" : "s", url, seconds);
    if (failed)
        fprintf(out, ", %u failed", failed);
    fprintf(out, "\n");
    for (uint32_t i = 0; i < n; i++) {
        const view_viewer_stats *v = &viewers[i];
        view_figures f;
        fprintf(out, "  viewer %u%s%s%s: ", v->index, v->name[0] ? " (" : "", v->name, v->name[0] ? ")" : "");
        if (!view_figures_of(v, 1, &f)) {
            fprintf(out, "out of memory\n");
            continue;
        }
        print_figures(out, &f);
        if (v->display.frames)
            fprintf(out, ", %llu display frames (%.1f %% of pixels empty)",
                    (unsigned long long)v->display.frames,
                    100.0 * v->display.empty_fraction_sum / (double)v->display.frames);
        if (v->failed)
            fprintf(out, "; failed: %s", v->error);
        fprintf(out, "\n");
    }
    view_figures total;
    if (n > 1 && view_figures_of(viewers, n, &total)) {
        fprintf(out, "  total: ");
        print_figures(out, &total);
        fprintf(out, "\n");
    }
}

/* Writes text as a JSON string: quotes, backslashes and control characters escaped, bytes outside printable
 * ASCII as '?'. */
static void json_string(FILE *f, const char *text)
{
    fputc('"', f);
    for (const unsigned char *c = (const unsigned char *)text; *c; c++) {
        if (*c == '"' || *c == '\\')
            fprintf(f, "\\%c", *c);
        else if (*c < 0x20)
            fprintf(f, "\\u%04x", *c);
        else if (*c >= 0x7f)
            fputc('?', f);
        else
            fputc(*c, f);
    }
    fputc('"', f);
}

/* The figures shared by a viewer's object and the total (members only, the caller writes the braces). */
static void json_figures(FILE *f, const view_figures *fig, const char *indent)
{
    fprintf(f, "%s\"frames\": %llu,\n", indent, (unsigned long long)fig->frames);
    fprintf(f, "%s\"fps\": %.3f,\n", indent, fig->fps);
    if (fig->latency_samples)
        fprintf(f, "%s\"latency_ms\": {\"median\": %.3f, \"p95\": %.3f, \"samples\": %llu},\n", indent,
                fig->latency_median, fig->latency_p95, (unsigned long long)fig->latency_samples);
    else
        fprintf(f, "%s\"latency_ms\": {\"median\": null, \"p95\": null, \"samples\": 0},\n", indent);
    fprintf(f, "%s\"bytes_received\": %llu,\n", indent, (unsigned long long)fig->bytes_received);
    fprintf(f, "%s\"bytes_per_frame\": %.1f,\n", indent, fig->bytes_per_frame);
    fprintf(f, "%s\"decode_errors\": %llu", indent, (unsigned long long)fig->decode_errors);
}

/* A viewer's display and render cache figures (members "display" and "render_cache", no trailing comma). */
static void json_display(FILE *f, const view_display_stats *d)
{
    double frames = d->frames ? (double)d->frames : 1;
    fprintf(f,
            "      \"display\": {\"frames\": %llu, \"skipped\": %llu, \"fps\": %.3f, \"empty_fraction\": "
            "%.6f},\n",
            (unsigned long long)d->frames, (unsigned long long)d->skipped, d->fps,
            d->empty_fraction_sum / frames);
    if (!d->reproject) {
        fprintf(f, "      \"render_cache\": null");
        return;
    }
    static const char *const kinds[VIEW_RC_PIXEL_KINDS] = {"empty", "point", "interpolated", "prefiltered"};
    fprintf(f, "      \"render_cache\": {\n        \"pixel_fractions\": {");
    for (int k = 0; k < VIEW_RC_PIXEL_KINDS; k++)
        fprintf(f, "%s\"%s\": %.6f", k ? ", " : "", kinds[k], d->kind_fraction_sum[k] / frames);
    fprintf(f, "},\n        \"points\": %u, \"points_mean\": %.1f,\n", d->points_last,
            (double)d->points_sum / frames);
    fprintf(f,
            "        \"requests_sent\": %llu, \"request_pixels\": %llu, \"request_pixels_not_sent\": %llu,\n"
            "        \"requests_answered\": %llu, \"samples_received\": %llu,\n"
            "        \"frames_inserted\": %llu, \"insert_errors\": %llu, \"rtt_ms\": %.3f,\n",
            (unsigned long long)d->request_messages, (unsigned long long)d->request_pixels,
            (unsigned long long)d->requests_dropped, (unsigned long long)d->answers,
            (unsigned long long)d->samples_received, (unsigned long long)d->frames_inserted,
            (unsigned long long)d->insert_errors, d->rtt_ms);
    fprintf(f, "        \"stage_ms\": {");
    for (int k = 0; k < VIEW_RC_STAGE_COUNT; k++) {
        fprintf(f, "%s", k ? ", " : "");
        json_string(f, view_rc_stage_name(k));
        fprintf(f, ": %.4f", d->stage_ms_sum[k] / frames);
    }
    fprintf(f, "},\n        \"total_ms\": {\"mean\": %.4f, \"max\": %.4f}\n      }", d->total_ms_sum / frames,
            d->total_ms_max);
}

int view_stats_write_json(const char *path, const view_viewer_stats *viewers, uint32_t n, const char *url,
                          double seconds, char *err, size_t cap)
{
    FILE *f = fopen(path, "wb");
    if (!f) {
        snprintf(err, cap, "%s: cannot create: %s", path, strerror(errno));
        return -1;
    }
    uint32_t failed = 0;
    for (uint32_t i = 0; i < n; i++)
        failed += viewers[i].failed;
    fprintf(f, "{\n  \"server\": ");
    json_string(f, url);
    fprintf(f, ",\n  \"seconds\": %.3f,\n  \"viewers\": [\n", seconds);
    bool ok = true;
    for (uint32_t i = 0; i < n; i++) {
        const view_viewer_stats *v = &viewers[i];
        view_figures fig;
        ok = ok && view_figures_of(v, 1, &fig);
        if (!ok)
            break;
        fprintf(f, "    {\n      \"index\": %u,\n      \"name\": ", v->index);
        json_string(f, v->name);
        fprintf(f, ",\n      \"failed\": %s,\n      \"error\": ", v->failed ? "true" : "false");
        if (v->failed)
            json_string(f, v->error);
        else
            fprintf(f, "null");
        fprintf(f, ",\n");
        json_figures(f, &fig, "      ");
        fprintf(
            f,
            ",\n      \"cameras_sent\": %llu,\n      \"cameras_skipped\": %llu,\n      \"seconds\": %.3f,\n",
            (unsigned long long)v->cameras_sent, (unsigned long long)v->cameras_skipped, v->seconds);
        json_display(f, &v->display);
        fprintf(f, "\n    }%s\n", i + 1 < n ? "," : "");
    }
    view_figures total;
    ok = ok && view_figures_of(viewers, n, &total);
    if (ok) {
        fprintf(f, "  ],\n  \"total\": {\n    \"viewers\": %u,\n    \"failed\": %u,\n", n, failed);
        json_figures(f, &total, "    ");
        fprintf(f, "\n  }\n}\n");
    }
    if (!ok) {
        fclose(f);
        snprintf(err, cap, "%s: out of memory", path);
        return -1;
    }
    bool write_failed = ferror(f) != 0;
    if (fclose(f) != 0)
        write_failed = true;
    if (write_failed) {
        snprintf(err, cap, "%s: cannot write: %s", path, strerror(errno));
        return -1;
    }
    return 0;
}
