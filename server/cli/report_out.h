/* What `fxcache report` writes (cmd_report.c runs the configurations): one row per configuration and its
 * compared images, kept as DIR/done/ID.json when the configuration finished (so an interrupted report resumes
 * without redoing it), and from those the CSVs, the Pareto front, the equal-time comparison, the gnuplot
 * plots and the HTML page. Everything here is rebuilt from the rows, so writing it again after a resume gives
 * one row per configuration, never a duplicate. */
#ifndef FXC_SERVER_REPORT_OUT_H
#define FXC_SERVER_REPORT_OUT_H

#include <jansson.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

enum { SRV_REP_MAX_VIEWER_COUNTS = 16 }; /* distinct viewer counts the plots and the comparison handle */

/* Whether an executable named name is in a folder of PATH. */
bool srv_rep_on_path(const char *name);

/* One compared image of a configuration (error over frames). */
typedef struct srv_rep_image {
    uint32_t frame;
    char viewer[32];
    bool steady;
    double rmse, psnr_db, rmse_shadow, rmse_ao; /* NAN: not measured */
} srv_rep_image;

/* One configuration: what it sets, and once done what it measured. */
typedef struct srv_rep_row {
    char id[64];     /* file-safe, unique: the marker's and the heat map's name */
    char family[24]; /* the sweep it belongs to: default, bias, ao_samples, shadow_rays, probe_cell,
                        probe_rays, ray_budget, viewers, no_cache */
    char label[96];  /* for people: "ao bias 2", "no cache x1/4" */
    uint32_t viewers;
    bool no_cache;
    double no_cache_samples;      /* the baseline's sample scale (1 when cached) */
    int32_t bias_shadow, bias_ao; /* level bias used */
    uint32_t ao_samples, shadow_rays, probe_rays;
    double probe_cell; /* metres, as used */
    double ray_budget; /* 0: unlimited */
    /* Results (valid when done). */
    bool done;
    uint32_t frames_timed, images;
    double ms_per_frame, ms_per_viewer, cpu_ms_per_frame, rays_per_frame;
    double rmse, psnr_db, rmse_denoised, rmse_shadow, rmse_ao, ref_noise, flip_mean; /* NAN: not measured */
    bool pareto;  /* on the front of its viewer count (computed, not stored) */
    double run_s; /* wall time the configuration took, references excluded */
    /* Degraded frames, counted over all of the configuration's frames (warm-up included): its errors are of
     * these frames, never silently lower for what the pools or the budget left out. */
    uint64_t pool_exhausted;  /* block requests the pools could not take (--pool-mb), on-surface and probes */
    uint64_t pixels_missing;  /* visible pixels composed without cached data */
    uint64_t texels_deferred; /* texels and cells left for a later frame by the ray or probe budget */
    char heatmap[160];        /* relative to the report folder ("" if none) */
    char frame_png[160];      /* the compared frame of viewer 0 the heat map is of */
    char ref_png[160];        /* its reference, display PNG */
    srv_rep_image *images_list;
    size_t image_count, image_capacity;
} srv_rep_row;

/* Appends an image to a row (false on no memory). */
bool srv_rep_row_add_image(srv_rep_row *row, const srv_rep_image *image);
void srv_rep_row_free_images(srv_rep_row *row);

/* The row (settings, results and images) as JSON, and back: the marker's body. from_json fills the results
 * and images of a row whose settings are already set; false when the JSON lacks them. */
json_t *srv_rep_row_json(const srv_rep_row *row);
bool srv_rep_row_from_json(srv_rep_row *row, const json_t *json);

/* Marks on_front[i] for the points (time[i], error[i]) no other point dominates: none has time <= and error
 * <= with one of them strictly less. Points with a NaN are never on it and dominate nothing. */
void srv_rep_pareto(const double *time, const double *error, size_t n, bool *on_front);

/* The error of the curve (time[i], error[i]) at time `at`, interpolated linearly in log(time)-log(error)
 * between the two points around it (the lower envelope: for each time the least error among points not
 * slower). *where: 0 inside the curve's time range, -1 below it, +1 above it (then the nearest point's error
 * is returned: no extrapolation). NAN with fewer than one point. */
double srv_rep_equal_time(const double *time, const double *error, size_t n, double at, int *where);

/* The CSVs, written whole through a temporary file: one row per done configuration (configs.csv), one per
 * compared image (frames.csv). False with a line in err. */
bool srv_rep_write_csv(const char *path, const srv_rep_row *rows, size_t n, char *err, size_t err_cap);
bool srv_rep_write_frames_csv(const char *path, const srv_rep_row *rows, size_t n, char *err, size_t err_cap);

/* The equal-time comparison of one viewer count: the cached configuration `cached` against the no-cache
 * curve of the same viewer count. */
typedef struct srv_rep_equal {
    uint32_t viewers;
    const srv_rep_row *cached;
    double cached_rmse, cached_ms;
    double no_cache_rmse; /* interpolated at cached_ms */
    int where;            /* srv_rep_equal_time's */
    uint32_t no_cache_points;
    double ratio;  /* cached / no cache (NAN when not measured) */
    bool goal_met; /* ratio <= 0.5 */
    /* For the reason when it is not met: */
    double cached_shadow, no_cache_shadow; /* the shadow term's RMSE, the no-cache one at the same time */
    const srv_rep_row *best; /* the cached configuration of this viewer count with the least RMSE */
    double no_cache_at_best; /* the no-cache RMSE at the best one's time */
    int where_best;
} srv_rep_equal;

/* Fills out for the default cached configuration of each viewer count that has a no-cache curve; returns how
 * many (at most cap). */
size_t srv_rep_equal_times(const srv_rep_row *rows, size_t n, srv_rep_equal *out, size_t cap);

/* The plots with gnuplot, if it is on PATH: per viewer count error against time per frame (Pareto front
 * marked) and error over frames, PNG and SVG under dir/plots/; time_label says what the rows' ms_per_frame
 * is. Returns the number of plots made; -1 when gnuplot is missing or failed (a line in err; the data and the
 * script stay for a later run); -2 when a data file or the script cannot be written (a line in err naming
 * the file: a full disk, a read-only folder). */
int srv_rep_plots(const char *dir, const srv_rep_row *rows, size_t n, const char *time_label, char *err,
                  size_t err_cap);

/* What the page says of the run besides the rows. */
typedef struct srv_rep_page {
    const char *title;      /* the scene and cameras */
    const char *command;    /* the command line */
    const char *settings;   /* one paragraph: resolution, frames, warm-up, references */
    bool plots;             /* the plots exist */
    const char *time_label; /* what ms_per_frame is (the plots' and the comparison's time) */
    bool interrupted;
    uint32_t planned; /* configurations planned */
} srv_rep_page;

/* dir/index.html: the headline comparison, the table, the plots, the heat maps and images; relative links
 * only, no script, readable offline. */
bool srv_rep_write_html(const char *dir, const srv_rep_row *rows, size_t n, const srv_rep_page *page,
                        char *err, size_t err_cap);

#endif
