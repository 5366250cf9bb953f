/* What `fxcache report` writes: rows and markers, the Pareto front, the equal-time comparison, the CSVs, the
 * gnuplot plots and the HTML page (report_out.h). */
#include "report_out.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---- rows ---------------------------------------------------------------------------------------------- */

bool srv_rep_row_add_image(srv_rep_row *row, const srv_rep_image *image)
{
    if (row->image_count == row->image_capacity) {
        size_t cap = row->image_capacity ? row->image_capacity * 2 : 64;
        srv_rep_image *grown =
            cap <= SIZE_MAX / sizeof *grown ? realloc(row->images_list, cap * sizeof *grown) : NULL;
        if (!grown)
            return false;
        row->images_list = grown;
        row->image_capacity = cap;
    }
    row->images_list[row->image_count++] = *image;
    return true;
}

void srv_rep_row_free_images(srv_rep_row *row)
{
    free(row->images_list);
    row->images_list = NULL;
    row->image_count = row->image_capacity = 0;
}

/* A figure as JSON: null for NaN or infinity (JSON has neither). */
static json_t *number(double v)
{
    return isfinite(v) ? json_real(v) : json_null();
}

static double number_of(const json_t *j)
{
    return json_is_number(j) ? json_number_value(j) : NAN;
}

json_t *srv_rep_row_json(const srv_rep_row *r)
{
    json_t *o = json_object();
    json_object_set_new(o, "id", json_string(r->id));
    json_object_set_new(o, "family", json_string(r->family));
    json_object_set_new(o, "label", json_string(r->label));
    json_object_set_new(o, "viewers", json_integer(r->viewers));
    json_object_set_new(o, "no_cache", json_boolean(r->no_cache));
    json_object_set_new(o, "no_cache_samples", number(r->no_cache_samples));
    json_object_set_new(o, "bias_shadow", json_integer(r->bias_shadow));
    json_object_set_new(o, "bias_ao", json_integer(r->bias_ao));
    json_object_set_new(o, "ao_samples", json_integer(r->ao_samples));
    json_object_set_new(o, "shadow_rays", json_integer(r->shadow_rays));
    json_object_set_new(o, "probe_rays", json_integer(r->probe_rays));
    json_object_set_new(o, "probe_cell", number(r->probe_cell));
    json_object_set_new(o, "ray_budget", number(r->ray_budget));
    json_object_set_new(o, "frames_timed", json_integer(r->frames_timed));
    json_object_set_new(o, "images", json_integer(r->images));
    json_object_set_new(o, "ms_per_frame", number(r->ms_per_frame));
    json_object_set_new(o, "ms_per_viewer", number(r->ms_per_viewer));
    json_object_set_new(o, "cpu_ms_per_frame", number(r->cpu_ms_per_frame));
    json_object_set_new(o, "rays_per_frame", number(r->rays_per_frame));
    json_object_set_new(o, "rmse", number(r->rmse));
    json_object_set_new(o, "psnr_db", number(r->psnr_db));
    json_object_set_new(o, "rmse_denoised", number(r->rmse_denoised));
    json_object_set_new(o, "rmse_shadow", number(r->rmse_shadow));
    json_object_set_new(o, "rmse_ao", number(r->rmse_ao));
    json_object_set_new(o, "ref_noise", number(r->ref_noise));
    json_object_set_new(o, "flip_mean", number(r->flip_mean));
    json_object_set_new(o, "run_s", number(r->run_s));
    json_object_set_new(o, "pool_exhausted", json_integer((json_int_t)r->pool_exhausted));
    json_object_set_new(o, "pixels_missing", json_integer((json_int_t)r->pixels_missing));
    json_object_set_new(o, "texels_deferred", json_integer((json_int_t)r->texels_deferred));
    json_object_set_new(o, "heatmap", json_string(r->heatmap));
    json_object_set_new(o, "frame_png", json_string(r->frame_png));
    json_object_set_new(o, "ref_png", json_string(r->ref_png));
    json_t *images = json_array();
    for (size_t i = 0; i < r->image_count; i++) {
        const srv_rep_image *im = &r->images_list[i];
        json_array_append_new(images,
                              json_pack("{s:I,s:s,s:b,s:o,s:o,s:o,s:o}", "frame", (json_int_t)im->frame,
                                        "viewer", im->viewer, "steady", im->steady, "rmse", number(im->rmse),
                                        "psnr_db", number(im->psnr_db), "rmse_shadow",
                                        number(im->rmse_shadow), "rmse_ao", number(im->rmse_ao)));
    }
    json_object_set_new(o, "compared", images);
    return o;
}

static void copy_string(char *out, size_t cap, const json_t *j)
{
    snprintf(out, cap, "%s", json_is_string(j) ? json_string_value(j) : "");
}

bool srv_rep_row_from_json(srv_rep_row *r, const json_t *o)
{
    const json_t *images = json_object_get(o, "compared");
    if (!json_is_object(o) || !json_is_array(images) || !json_is_number(json_object_get(o, "ms_per_frame")) ||
        !json_is_integer(json_object_get(o, "pool_exhausted"))) /* a marker without the counts: redone */
        return false;
    r->pool_exhausted = (uint64_t)json_integer_value(json_object_get(o, "pool_exhausted"));
    r->pixels_missing = (uint64_t)json_integer_value(json_object_get(o, "pixels_missing"));
    r->texels_deferred = (uint64_t)json_integer_value(json_object_get(o, "texels_deferred"));
    r->frames_timed = (uint32_t)json_integer_value(json_object_get(o, "frames_timed"));
    r->images = (uint32_t)json_integer_value(json_object_get(o, "images"));
    r->ms_per_frame = number_of(json_object_get(o, "ms_per_frame"));
    r->ms_per_viewer = number_of(json_object_get(o, "ms_per_viewer"));
    r->cpu_ms_per_frame = number_of(json_object_get(o, "cpu_ms_per_frame"));
    r->rays_per_frame = number_of(json_object_get(o, "rays_per_frame"));
    r->rmse = number_of(json_object_get(o, "rmse"));
    r->psnr_db = number_of(json_object_get(o, "psnr_db"));
    r->rmse_denoised = number_of(json_object_get(o, "rmse_denoised"));
    r->rmse_shadow = number_of(json_object_get(o, "rmse_shadow"));
    r->rmse_ao = number_of(json_object_get(o, "rmse_ao"));
    r->ref_noise = number_of(json_object_get(o, "ref_noise"));
    r->flip_mean = number_of(json_object_get(o, "flip_mean"));
    r->run_s = number_of(json_object_get(o, "run_s"));
    copy_string(r->heatmap, sizeof r->heatmap, json_object_get(o, "heatmap"));
    copy_string(r->frame_png, sizeof r->frame_png, json_object_get(o, "frame_png"));
    copy_string(r->ref_png, sizeof r->ref_png, json_object_get(o, "ref_png"));
    srv_rep_row_free_images(r);
    size_t i;
    const json_t *item;
    json_array_foreach(images, i, item)
    {
        srv_rep_image im = {.frame = (uint32_t)json_integer_value(json_object_get(item, "frame")),
                            .steady = json_is_true(json_object_get(item, "steady")),
                            .rmse = number_of(json_object_get(item, "rmse")),
                            .psnr_db = number_of(json_object_get(item, "psnr_db")),
                            .rmse_shadow = number_of(json_object_get(item, "rmse_shadow")),
                            .rmse_ao = number_of(json_object_get(item, "rmse_ao"))};
        copy_string(im.viewer, sizeof im.viewer, json_object_get(item, "viewer"));
        if (!srv_rep_row_add_image(r, &im))
            return false;
    }
    r->done = true;
    return true;
}

/* ---- Pareto front and equal time ----------------------------------------------------------------------- */

void srv_rep_pareto(const double *time, const double *error, size_t n, bool *on_front)
{
    for (size_t i = 0; i < n; i++) {
        on_front[i] = !isnan(time[i]) && !isnan(error[i]);
        for (size_t j = 0; j < n && on_front[i]; j++) {
            if (j == i || isnan(time[j]) || isnan(error[j]))
                continue;
            bool no_worse = time[j] <= time[i] && error[j] <= error[i];
            bool better = time[j] < time[i] || error[j] < error[i];
            if (no_worse && better)
                on_front[i] = false;
        }
    }
}

typedef struct curve_point {
    double time, error;
} curve_point;

static int compare_time(const void *a, const void *b)
{
    const curve_point *p = a, *q = b;
    return p->time < q->time ? -1 : p->time > q->time ? 1 : (p->error < q->error ? -1 : p->error > q->error);
}

double srv_rep_equal_time(const double *time, const double *error, size_t n, double at, int *where)
{
    *where = 0;
    curve_point *pts = malloc((n ? n : 1) * sizeof *pts);
    if (!pts)
        return NAN;
    size_t m = 0;
    for (size_t i = 0; i < n; i++)
        if (time[i] > 0 && error[i] > 0 && isfinite(time[i]) && isfinite(error[i]))
            pts[m++] = (curve_point){time[i], error[i]};
    if (m == 0) {
        free(pts);
        return NAN;
    }
    qsort(pts, m, sizeof *pts, compare_time);
    /* The lower envelope: a point stays only if it has less error than every faster one. */
    size_t k = 0;
    for (size_t i = 0; i < m; i++)
        if (k == 0 || pts[i].error < pts[k - 1].error)
            pts[k++] = pts[i];
    double result;
    if (at < pts[0].time) {
        *where = -1;
        result = pts[0].error;
    } else if (at >= pts[k - 1].time) {
        *where = at > pts[k - 1].time ? 1 : 0;
        result = pts[k - 1].error;
    } else {
        size_t i = 0;
        while (i + 1 < k && pts[i + 1].time <= at)
            i++;
        double x0 = log(pts[i].time), x1 = log(pts[i + 1].time);
        double y0 = log(pts[i].error), y1 = log(pts[i + 1].error);
        double w = x1 > x0 ? (log(at) - x0) / (x1 - x0) : 0;
        result = exp(y0 + w * (y1 - y0));
    }
    free(pts);
    return result;
}

size_t srv_rep_equal_times(const srv_rep_row *rows, size_t n, srv_rep_equal *out, size_t cap)
{
    size_t count = 0;
    for (size_t i = 0; i < n && count < cap; i++) {
        const srv_rep_row *c = &rows[i];
        bool is_default =
            strcmp(c->family, "default") == 0 || (strcmp(c->family, "viewers") == 0 && !c->no_cache);
        if (!c->done || c->no_cache || !is_default)
            continue;
        double t[64], e[64], es[64];
        size_t m = 0;
        const srv_rep_row *best = NULL;
        for (size_t j = 0; j < n; j++) {
            if (!rows[j].done || rows[j].viewers != c->viewers)
                continue;
            if (!rows[j].no_cache && (!best || rows[j].rmse < best->rmse))
                best = &rows[j];
            if (rows[j].no_cache && m < 64) {
                t[m] = rows[j].ms_per_frame;
                e[m] = rows[j].rmse;
                es[m] = rows[j].rmse_shadow;
                m++;
            }
        }
        if (m == 0)
            continue;
        srv_rep_equal *q = &out[count++];
        memset(q, 0, sizeof *q);
        q->viewers = c->viewers;
        q->cached = c;
        q->cached_rmse = c->rmse;
        q->cached_ms = c->ms_per_frame;
        q->no_cache_points = (uint32_t)m;
        q->no_cache_rmse = srv_rep_equal_time(t, e, m, c->ms_per_frame, &q->where);
        q->ratio = q->no_cache_rmse > 0 ? c->rmse / q->no_cache_rmse : NAN;
        q->goal_met = q->ratio <= 0.5;
        int ignored;
        q->cached_shadow = c->rmse_shadow;
        q->no_cache_shadow = srv_rep_equal_time(t, es, m, c->ms_per_frame, &ignored);
        q->best = best;
        q->no_cache_at_best = best ? srv_rep_equal_time(t, e, m, best->ms_per_frame, &q->where_best) : NAN;
    }
    return count;
}

/* ---- CSV ----------------------------------------------------------------------------------------------- */

/* A figure in a CSV cell: empty for NaN. */
static void cell(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, ",%.6g", v);
    else
        fputs(",", f);
}

static bool finish_file(FILE *f, const char *tmp, const char *path, char *err, size_t err_cap)
{
    bool ok = !ferror(f);
    ok = fclose(f) == 0 && ok;
    if (ok && rename(tmp, path) != 0)
        ok = false;
    if (!ok)
        snprintf(err, err_cap, "cannot write %s: %s", path, strerror(errno ? errno : EIO));
    return ok;
}

bool srv_rep_write_csv(const char *path, const srv_rep_row *rows, size_t n, char *err, size_t err_cap)
{
    char tmp[1100];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f) {
        snprintf(err, err_cap, "cannot write %s: %s", tmp, strerror(errno));
        return false;
    }
    fputs("config,family,mode,viewers,bias_shadow,bias_ao,ao_samples,shadow_rays,probe_rays,probe_cell_m,"
          "ray_budget,no_cache_samples,frames_timed,images,ms_per_frame,ms_per_viewer,cpu_ms_per_frame,"
          "effect_rays_per_frame,rmse,psnr_db,rmse_denoised,rmse_shadow,rmse_ao,ref_noise,pareto,flip_mean,"
          "pool_exhausted,pixels_missing,texels_deferred\n",
          f);
    for (size_t i = 0; i < n; i++) {
        const srv_rep_row *r = &rows[i];
        if (!r->done)
            continue;
        fprintf(f, "%s,%s,%s,%u,%d,%d,%u,%u,%u", r->id, r->family, r->no_cache ? "no-cache" : "cached",
                r->viewers, r->bias_shadow, r->bias_ao, r->ao_samples, r->shadow_rays, r->probe_rays);
        cell(f, r->probe_cell);
        cell(f, r->ray_budget);
        cell(f, r->no_cache ? r->no_cache_samples : NAN);
        fprintf(f, ",%u,%u", r->frames_timed, r->images);
        cell(f, r->ms_per_frame);
        cell(f, r->ms_per_viewer);
        cell(f, r->cpu_ms_per_frame);
        cell(f, r->rays_per_frame);
        cell(f, r->rmse);
        cell(f, r->psnr_db);
        cell(f, r->rmse_denoised);
        cell(f, r->rmse_shadow);
        cell(f, r->rmse_ao);
        cell(f, r->ref_noise);
        fprintf(f, ",%d", r->pareto ? 1 : 0);
        cell(f, r->flip_mean);
        fprintf(f, ",%llu,%llu,%llu\n", (unsigned long long)r->pool_exhausted,
                (unsigned long long)r->pixels_missing, (unsigned long long)r->texels_deferred);
    }
    return finish_file(f, tmp, path, err, err_cap);
}

bool srv_rep_write_frames_csv(const char *path, const srv_rep_row *rows, size_t n, char *err, size_t err_cap)
{
    char tmp[1100];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f) {
        snprintf(err, err_cap, "cannot write %s: %s", tmp, strerror(errno));
        return false;
    }
    fputs("config,viewers,frame,viewer,steady,rmse,psnr_db,rmse_shadow,rmse_ao\n", f);
    for (size_t i = 0; i < n; i++) {
        const srv_rep_row *r = &rows[i];
        if (!r->done)
            continue;
        for (size_t k = 0; k < r->image_count; k++) {
            const srv_rep_image *im = &r->images_list[k];
            fprintf(f, "%s,%u,%u,%s,%d", r->id, r->viewers, im->frame, im->viewer, im->steady ? 1 : 0);
            cell(f, im->rmse);
            cell(f, im->psnr_db);
            cell(f, im->rmse_shadow);
            cell(f, im->rmse_ao);
            fputc('\n', f);
        }
    }
    return finish_file(f, tmp, path, err, err_cap);
}

/* ---- plots --------------------------------------------------------------------------------------------- */

static const char *const families[] = {"default",    "bias",       "ao_samples", "shadow_rays", "probe_cell",
                                       "probe_rays", "ray_budget", "viewers",    "no_cache"};
enum { FAMILY_COUNT = sizeof families / sizeof families[0] };

bool srv_rep_on_path(const char *name)
{
    const char *path = getenv("PATH");
    if (!path)
        return false;
    char dir[1024], file[1200];
    for (const char *p = path; *p;) {
        const char *colon = strchr(p, ':');
        size_t len = colon ? (size_t)(colon - p) : strlen(p);
        if (len > 0 && len < sizeof dir) {
            memcpy(dir, p, len);
            dir[len] = 0;
            snprintf(file, sizeof file, "%s/%s", dir, name);
            if (access(file, X_OK) == 0)
                return true;
        }
        if (!colon)
            break;
        p = colon + 1;
    }
    return false;
}

/* The viewer counts among the done rows, ascending (at most cap). */
static size_t viewer_counts(const srv_rep_row *rows, size_t n, uint32_t *out, size_t cap)
{
    size_t m = 0;
    for (size_t i = 0; i < n; i++) {
        if (!rows[i].done)
            continue;
        bool seen = false;
        for (size_t k = 0; k < m; k++)
            seen |= out[k] == rows[i].viewers;
        if (!seen && m < cap)
            out[m++] = rows[i].viewers;
    }
    for (size_t a = 1; a < m; a++)
        for (size_t b = a; b > 0 && out[b - 1] > out[b]; b--) {
            uint32_t t = out[b];
            out[b] = out[b - 1];
            out[b - 1] = t;
        }
    return m;
}

static int compare_points(const void *a, const void *b)
{
    const double *p = a, *q = b;
    return p[0] < q[0] ? -1 : p[0] > q[0];
}

/* Opens a plot data file; NULL after a line in err naming it. */
static FILE *open_data(const char *path, char *err, size_t err_cap)
{
    FILE *f = fopen(path, "w");
    if (!f)
        snprintf(err, err_cap, "cannot write %s: %s", path, strerror(errno));
    return f;
}

/* Closes a plot data file; false after a line in err naming it when a write or the close failed (a full
 * disk shows only here: fprintf buffers). */
static bool close_data(FILE *f, const char *path, char *err, size_t err_cap)
{
    errno = 0;
    bool ok = !ferror(f);
    ok = fclose(f) == 0 && ok;
    if (!ok)
        snprintf(err, err_cap, "cannot write %s: %s", path, strerror(errno ? errno : EIO));
    return ok;
}

/* Writes the data files and the script for one viewer count; returns the number of plots it draws, or -1
 * after a line in err when a data file cannot be written. */
static int plot_files(const char *plots, FILE *gp, const srv_rep_row *rows, size_t n, uint32_t viewers,
                      const char *time_label, char *err, size_t err_cap)
{
    char path[1200];
    snprintf(path, sizeof path, "%s/points_v%u.dat", plots, viewers);
    FILE *f = open_data(path, err, err_cap);
    if (!f)
        return -1;
    bool used[FAMILY_COUNT] = {false};
    int blocks = 0, block_of[FAMILY_COUNT];
    for (int k = 0; k < FAMILY_COUNT; k++) {
        block_of[k] = -1;
        bool any = false;
        for (size_t i = 0; i < n; i++)
            if (rows[i].done && rows[i].viewers == viewers && strcmp(rows[i].family, families[k]) == 0 &&
                isfinite(rows[i].rmse) && rows[i].ms_per_frame > 0) {
                if (!any && blocks)
                    fputs("\n\n", f);
                any = true;
                char label[96]; /* the plot is of one viewer count: without ", N viewers" */
                snprintf(label, sizeof label, "%s", rows[i].label);
                char *comma = strrchr(label, ',');
                if (comma && strstr(comma, "viewer"))
                    *comma = 0;
                fprintf(f, "%.6g %.6g \"%s\"\n", rows[i].ms_per_frame, rows[i].rmse, label);
            }
        if (any) {
            used[k] = true;
            block_of[k] = blocks++;
        }
    }
    if (!close_data(f, path, err, err_cap))
        return -1;
    if (!blocks)
        return 0;
    /* The Pareto front, by time. */
    snprintf(path, sizeof path, "%s/pareto_v%u.dat", plots, viewers);
    f = open_data(path, err, err_cap);
    if (!f)
        return -1;
    double(*front)[2] = malloc((n ? n : 1) * sizeof *front);
    size_t m = 0;
    for (size_t i = 0; front && i < n; i++)
        if (rows[i].done && rows[i].viewers == viewers && rows[i].pareto) {
            front[m][0] = rows[i].ms_per_frame;
            front[m][1] = rows[i].rmse;
            m++;
        }
    if (front)
        qsort(front, m, sizeof *front, compare_points);
    for (size_t i = 0; i < m; i++)
        fprintf(f, "%.6g %.6g\n", front[i][0], front[i][1]);
    free(front);
    if (!close_data(f, path, err, err_cap))
        return -1;

    static const int point_type[FAMILY_COUNT] = {7, 5, 9, 11, 13, 15, 4, 6, 2};
    for (int term = 0; term < 2; term++) {
        if (term == 0)
            fprintf(gp,
                    "set terminal pngcairo size 960,640 noenhanced font 'sans,10'\nset output "
                    "'error_time_v%u.png'\n",
                    viewers);
        else
            fprintf(
                gp,
                "set terminal svg size 960,640 noenhanced font 'sans,10'\nset output 'error_time_v%u.svg'\n",
                viewers);
        fprintf(
            gp,
            "set title 'RMSE against time per frame, %u viewer%s (front: no configuration is both faster and "
            "more exact)'\n"
            "set logscale xy\nset grid\nset key outside right top\n"
            "set xlabel 'time per frame, ms (%s)'\n"
            "set ylabel 'RMSE against the reference, linear radiance'\n",
            viewers, viewers == 1 ? "" : "s", time_label);
        fprintf(gp, "plot 'pareto_v%u.dat' using 1:2 with lines lw 2 lc rgb '#888888' title 'Pareto front'",
                viewers);
        for (int k = 0; k < FAMILY_COUNT; k++)
            if (used[k])
                fprintf(gp, ", \\\n  'points_v%u.dat' index %d using 1:2 with points pt %d ps 1.3 title '%s'",
                        viewers, block_of[k], point_type[k], families[k]);
        fprintf(
            gp,
            ", \\\n  'points_v%u.dat' using 1:2:3 with labels font ',7' offset char 0.6,0.6 left notitle\n",
            viewers);
        fputs("unset logscale\n", gp);
    }

    /* Error over frames: the default, viewers and no-cache configurations, mean over viewers per frame. */
    snprintf(path, sizeof path, "%s/frames_v%u.dat", plots, viewers);
    f = open_data(path, err, err_cap);
    if (!f)
        return -1;
    int series = 0;
    char titles[32][96];
    for (size_t i = 0; i < n && series < 32; i++) {
        const srv_rep_row *r = &rows[i];
        if (!r->done || r->viewers != viewers ||
            !(strcmp(r->family, "default") == 0 || strcmp(r->family, "viewers") == 0 ||
              strcmp(r->family, "no_cache") == 0))
            continue;
        if (series)
            fputs("\n\n", f);
        for (size_t k = 0; k < r->image_count;) {
            uint32_t frame = r->images_list[k].frame;
            double sum = 0;
            uint32_t count = 0;
            for (; k < r->image_count && r->images_list[k].frame == frame; k++) {
                sum += r->images_list[k].rmse * r->images_list[k].rmse;
                count++;
            }
            fprintf(f, "%u %.6g\n", frame, sqrt(sum / count));
        }
        snprintf(titles[series], sizeof titles[series], "%s", r->label);
        series++;
    }
    if (!close_data(f, path, err, err_cap))
        return -1;
    if (!series)
        return 1;
    for (int term = 0; term < 2; term++) {
        if (term == 0)
            fprintf(gp,
                    "set terminal pngcairo size 960,480 noenhanced font 'sans,10'\nset output "
                    "'error_frames_v%u.png'\n",
                    viewers);
        else
            fprintf(gp,
                    "set terminal svg size 960,480 noenhanced font 'sans,10'\nset output "
                    "'error_frames_v%u.svg'\n",
                    viewers);
        fprintf(gp,
                "set title 'RMSE over frames (moving cameras), %u viewer%s'\nset logscale y\nset grid\n"
                "set key outside right top\nset xlabel 'frame'\nset ylabel 'RMSE, linear radiance'\nplot ",
                viewers, viewers == 1 ? "" : "s");
        for (int s = 0; s < series; s++)
            fprintf(gp, "%s'frames_v%u.dat' index %d using 1:2 with linespoints title '%s'",
                    s ? ", \\\n  " : "", viewers, s, titles[s]);
        fputs("\nunset logscale\n", gp);
    }
    return 2;
}

int srv_rep_plots(const char *dir, const srv_rep_row *rows, size_t n, const char *time_label, char *err,
                  size_t err_cap)
{
    char plots[1100], path[1200];
    snprintf(plots, sizeof plots, "%s/plots", dir);
    if (mkdir(plots, 0755) != 0 && errno != EEXIST) {
        snprintf(err, err_cap, "cannot create folder %s: %s", plots, strerror(errno));
        return -1;
    }
    snprintf(path, sizeof path, "%s/plots.gp", plots);
    FILE *gp = fopen(path, "w");
    if (!gp) {
        snprintf(err, err_cap, "cannot write %s: %s", path, strerror(errno));
        return -1;
    }
    fputs("# Written by fxcache report; run it inside this folder: gnuplot plots.gp\n", gp);
    uint32_t counts[SRV_REP_MAX_VIEWER_COUNTS];
    size_t m = viewer_counts(rows, n, counts, SRV_REP_MAX_VIEWER_COUNTS);
    int made = 0;
    for (size_t k = 0; k < m; k++) {
        int drawn = plot_files(plots, gp, rows, n, counts[k], time_label, err, err_cap);
        if (drawn < 0) {
            fclose(gp);
            return -2;
        }
        made += drawn;
    }
    if (!close_data(gp, path, err, err_cap))
        return -2;
    if (!srv_rep_on_path("gnuplot")) {
        snprintf(err, err_cap,
                 "gnuplot is not on PATH (install-deps.sh installs gnuplot-nox): the data and the "
                 "script are in %s",
                 plots);
        return -1;
    }
    char command[2600];
    snprintf(command, sizeof command, "cd '%s' && gnuplot plots.gp 2> plots.log", plots);
    int rc = system(command);
    if (rc != 0) {
        snprintf(err, err_cap, "gnuplot failed (exit %d): see %s/plots.log", rc, plots);
        return -1;
    }
    return made * 2;
}

/* ---- HTML ---------------------------------------------------------------------------------------------- */

/* Text with &, <, > and " escaped. */
static void html_text(FILE *f, const char *s)
{
    for (; *s; s++) {
        switch (*s) {
        case '&': fputs("&amp;", f); break;
        case '<': fputs("&lt;", f); break;
        case '>': fputs("&gt;", f); break;
        case '"': fputs("&quot;", f); break;
        default: fputc(*s, f);
        }
    }
}

static void html_number(FILE *f, const char *format, double v)
{
    if (isfinite(v))
        fprintf(f, format, v);
    else
        fputs("&ndash;", f);
}

static bool file_exists(const char *dir, const char *rel)
{
    char path[1400];
    snprintf(path, sizeof path, "%s/%s", dir, rel);
    return rel[0] && access(path, R_OK) == 0;
}

bool srv_rep_write_html(const char *dir, const srv_rep_row *rows, size_t n, const srv_rep_page *page,
                        char *err, size_t err_cap)
{
    char path[1100], tmp[1120];
    snprintf(path, sizeof path, "%s/index.html", dir);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f) {
        snprintf(err, err_cap, "cannot write %s: %s", tmp, strerror(errno));
        return false;
    }
    size_t done = 0;
    for (size_t i = 0; i < n; i++)
        done += rows[i].done;
    fputs("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>fxcache report</title>\n"
          "<style>body{font-family:sans-serif;max-width:1200px;margin:1em auto;padding:0 1em}"
          "table{border-collapse:collapse;font-size:85%}td,th{border:1px solid #ccc;padding:2px "
          "6px;text-align:right}"
          "td:first-child,th:first-child,td:nth-child(2){text-align:left}tr.front{background:#eef7ee}"
          "figure{display:inline-block;margin:4px;text-align:center;font-size:80%}img{image-rendering:"
          "pixelated}"
          ".met{color:#060}.unmet{color:#a00}</style></head><body>\n<h1>fxcache report</h1>\n<p>",
          f);
    html_text(f, page->title ? page->title : "");
    fputs("</p>\n<p>", f);
    html_text(f, page->settings ? page->settings : "");
    fprintf(f, "</p>\n<p>%zu of %u configurations done%s.</p>\n", done, page->planned,
            page->interrupted
                ? " (interrupted: rerun the same command to finish; finished configurations are kept)"
                : "");
    if (page->command) {
        fputs("<pre>", f);
        html_text(f, page->command);
        fputs("</pre>\n", f);
    }

    fputs(
        "<h2>Equal-time comparison</h2>\n<p>At equal server time per frame, the RMSE of the cached renderer "
        "(default settings) against the no-cache renderer, whose error at that time is interpolated along "
        "its "
        "curve over sample counts (log-log, its lower envelope). The goal: cached error at most half the "
        "no-cache error.</p>\n<ul>\n",
        f);
    srv_rep_equal eq[SRV_REP_MAX_VIEWER_COUNTS];
    size_t m = srv_rep_equal_times(rows, n, eq, SRV_REP_MAX_VIEWER_COUNTS);
    if (m == 0)
        fputs("<li>Not measured: it needs a done default cached configuration and no-cache configurations of "
              "the same "
              "viewer count.</li>\n",
              f);
    for (size_t k = 0; k < m; k++) {
        if (!isfinite(
                eq[k].no_cache_rmse)) { /* every no-cache error 0 (or none finite): nothing to compare */
            fprintf(f,
                    "<li>%u viewer%s: cached RMSE %.4g at %.1f ms per frame; not compared: no no-cache point "
                    "has an "
                    "error above 0.</li>\n",
                    eq[k].viewers, eq[k].viewers == 1 ? "" : "s", eq[k].cached_rmse, eq[k].cached_ms);
            continue;
        }
        fprintf(
            f,
            "<li class=\"%s\">%u viewer%s: cached RMSE %.4g at %.1f ms per frame; no cache at that time %.4g "
            "(%u no-cache points%s): ratio %.2f, goal %s.</li>\n",
            eq[k].goal_met ? "met" : "unmet", eq[k].viewers, eq[k].viewers == 1 ? "" : "s", eq[k].cached_rmse,
            eq[k].cached_ms, eq[k].no_cache_rmse, eq[k].no_cache_points,
            eq[k].where < 0
                ? "; the cache is faster than the fastest no-cache point, compared with that point"
            : eq[k].where > 0
                ? "; the cache is slower than the slowest no-cache point, compared with that point"
                : "",
            eq[k].ratio, eq[k].goal_met ? "met" : "NOT met");
        if (eq[k].goal_met || !eq[k].best)
            continue;
        /* Why not: is there a cached setting that would meet it, and where does the error sit? */
        const srv_rep_row *b = eq[k].best;
        bool best_meets = b->rmse <= 0.5 * eq[k].no_cache_at_best;
        fprintf(f, "<li>Why: the most exact cached configuration of %u viewer%s, ", eq[k].viewers,
                eq[k].viewers == 1 ? "" : "s");
        html_text(f, b->label);
        fprintf(f,
                ", has RMSE %.4g at %.1f ms per frame, against %.4g for no cache at that time (ratio %.2f). ",
                b->rmse, b->ms_per_frame, eq[k].no_cache_at_best, b->rmse / eq[k].no_cache_at_best);
        if (best_meets && b != eq[k].cached)
            fprintf(f,
                    "That setting meets the goal: the default misses it by its time, not by its error (%.0f "
                    "effect rays per frame against %.0f). ",
                    eq[k].cached->rays_per_frame, b->rays_per_frame);
        else if (!best_meets)
            fputs(
                "No swept setting brings the cached error under half: the cached error is a floor the sample "
                "counts do not move, not noise. ",
                f);
        if (isfinite(eq[k].cached_shadow) && isfinite(eq[k].no_cache_shadow))
            fprintf(f,
                    "The shadow term (lit fraction of light 0) has RMSE %.4g cached against %.4g without the "
                    "cache "
                    "at equal time.",
                    eq[k].cached_shadow, eq[k].no_cache_shadow);
        fputs("</li>\n", f);
    }
    fputs("</ul>\n", f);

    fputs("<h2>Error against time per frame</h2>\n<p>Time per frame here: ", f);
    html_text(f, page->time_label ? page->time_label : "");
    fputs(
        "; mean over the steady-state frames, on a shared, noisy machine. The CSV has both the engine's "
        "elapsed frame time (the statistics sim writes, without the sinks stage, so the comparison with the "
        "reference is not counted) and the process CPU time of the frame less the sink's. Points on the "
        "Pareto front are no slower and no less exact than any other of their viewer count.</p>\n",
        f);
    uint32_t counts[SRV_REP_MAX_VIEWER_COUNTS];
    size_t vc = viewer_counts(rows, n, counts, SRV_REP_MAX_VIEWER_COUNTS);
    for (size_t k = 0; k < vc; k++) {
        char rel[64];
        snprintf(rel, sizeof rel, "plots/error_time_v%u.png", counts[k]);
        if (page->plots && file_exists(dir, rel))
            fprintf(f,
                    "<p><a href=\"plots/error_time_v%u.svg\"><img src=\"%s\" alt=\"error against time, %u "
                    "viewer(s)\" "
                    "width=\"960\"></a></p>\n",
                    counts[k], rel, counts[k]);
        snprintf(rel, sizeof rel, "plots/error_frames_v%u.png", counts[k]);
        if (page->plots && file_exists(dir, rel))
            fprintf(f,
                    "<p><a href=\"plots/error_frames_v%u.svg\"><img src=\"%s\" alt=\"error over frames, %u "
                    "viewer(s)\" "
                    "width=\"960\"></a></p>\n",
                    counts[k], rel, counts[k]);
    }
    if (!page->plots)
        fputs("<p>No plots: gnuplot was not available (the data and script are under plots/).</p>\n", f);

    fputs(
        "<h2>Configurations</h2>\n<p>The same as <a href=\"configs.csv\">configs.csv</a>; error over frames "
        "per "
        "image in <a href=\"frames.csv\">frames.csv</a>. RMSE and PSNR in linear radiance (peak 1.0), over "
        "every "
        "pixel; <i>denoised</i> removes the reference's own noise in quadrature (sqrt(RMSE&sup2; &minus; "
        "noise&sup2;)); shadow: the lit fraction of light 0; AO only where no probes replace the sky "
        "term.</p>\n"
        "<table><tr><th>configuration</th><th>family</th><th>viewers</th><th>ms/frame (the time "
        "above)</th><th>ms/viewer</th>"
        "<th>CPU ms/frame</th><th>effect rays/frame</th><th>RMSE</th><th>PSNR dB</th><th>RMSE denoised</th>"
        "<th>shadow RMSE</th><th>AO RMSE</th><th>ref noise</th><th>FLIP</th></tr>\n",
        f);
    for (size_t i = 0; i < n; i++) {
        const srv_rep_row *r = &rows[i];
        if (!r->done)
            continue;
        fprintf(f, "<tr%s><td>", r->pareto ? " class=\"front\"" : "");
        html_text(f, r->label);
        fprintf(f, "</td><td>%s</td><td>%u</td><td>", r->family, r->viewers);
        const struct {
            const char *format;
            double value;
        } cells[] = {{"%.1f", r->ms_per_frame},   {"%.1f", r->ms_per_viewer}, {"%.1f", r->cpu_ms_per_frame},
                     {"%.0f", r->rays_per_frame}, {"%.4g", r->rmse},          {"%.2f", r->psnr_db},
                     {"%.4g", r->rmse_denoised},  {"%.4g", r->rmse_shadow},   {"%.4g", r->rmse_ao},
                     {"%.3g", r->ref_noise},      {"%.4f", r->flip_mean}};
        for (size_t k = 0; k < sizeof cells / sizeof cells[0]; k++) {
            if (k)
                fputs("</td><td>", f);
            html_number(f, cells[k].format, cells[k].value);
        }
        fputs("</td></tr>\n", f);
    }
    fputs("</table>\n<p>Highlighted rows are on the Pareto front of their viewer count.</p>\n", f);

    fputs("<h2>Error heat maps</h2>\n<p>Per pixel |frame &minus; reference| (mean over the channels, linear "
          "radiance) of viewer 0's last compared frame; black is 0, white 0.1 or more (black, red, yellow, "
          "white). Beside the first: the frame and its reference.</p>\n",
          f);
    bool first = true;
    for (size_t i = 0; i < n; i++) {
        const srv_rep_row *r = &rows[i];
        if (!r->done || !file_exists(dir, r->heatmap))
            continue;
        if (first && file_exists(dir, r->frame_png) && file_exists(dir, r->ref_png)) {
            fprintf(f,
                    "<figure><img src=\"%s\" width=\"320\" alt=\"frame\"><figcaption>frame: ", r->frame_png);
            html_text(f, r->label);
            fprintf(
                f,
                "</figcaption></figure><figure><img src=\"%s\" width=\"320\" alt=\"reference\"><figcaption>"
                "reference</figcaption></figure><br>\n",
                r->ref_png);
        }
        first = false;
        fprintf(f, "<figure><img src=\"%s\" width=\"240\" alt=\"heat map\"><figcaption>", r->heatmap);
        html_text(f, r->label);
        fputs("</figcaption></figure>\n", f);
    }
    fputs("</body></html>\n", f);
    return finish_file(f, tmp, path, err, err_cap);
}
