/* `fxcache report` and its parts: the error sink against a hand-made image difference (closed-form RMSE,
 * PSNR, shadow error, time without the sinks stage), the Pareto front and the equal-time interpolation on
 * hand-made points, the run-time sample counts the sweeps set (shadow rays per texel, AO samples a texel
 * converges at), the command line's option errors, an interrupted report resumed without redoing finished
 * configurations, and a tiny end-to-end report whose files exist and whose CSV parses. Tiny images and few
 * frames keep it quick, also in the sanitizer build. */
#include "test_util.h"

#include "fxt_scene.h"

#include "error_sink.h"
#include "image.h"
#include "report_out.h"

#include <fcntl.h>
#include <jansson.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static void remove_tree(const char *dir)
{
    char command[1200];
    snprintf(command, sizeof command, "rm -rf '%s'", dir);
    assert_int_equal(system(command), 0);
}

/* ---- the measures and the sink ------------------------------------------------------------------------- */

/* A frame that is its reference plus 0.1 in the red channel everywhere: RMSE = sqrt(0.01 / 3), PSNR =
 * 20 log10(1 / RMSE); a shadow view half at 0.5 where the reference is 1: RMSE sqrt(0.25 / 2). The reference
 * is written on disk under the cache's key, so the sink finds it there and renders nothing. */
static void test_error_sink_closed_form(void **state)
{
    (void)state;
    assert_true(fabs(srv_err_psnr(0.1) - 20.0) < 1e-12);
    assert_true(isinf(srv_err_psnr(0.0)));

    const uint32_t w = 8, h = 4;
    const size_t n = (size_t)w * h;
    float reference[8 * 4 * 3], frame[8 * 4 * 3], ones[8 * 4], shadow_ref[8 * 4], shadow[8 * 4];
    for (size_t p = 0; p < n; p++) {
        for (int c = 0; c < 3; c++)
            reference[3 * p + c] = 0.05f * (float)(p % 7) + 0.1f * (float)c;
        frame[3 * p] = reference[3 * p] + 0.1f;
        frame[3 * p + 1] = reference[3 * p + 1];
        frame[3 * p + 2] = reference[3 * p + 2];
        ones[p] = 1.0f;
        shadow_ref[p] = 1.0f;
        shadow[p] = p < n / 2 ? 0.5f : 1.0f;
    }
    double expected = sqrt(0.01 / 3.0);
    assert_true(fabs(srv_err_rmse(frame, reference, 3 * n) - expected) < 1e-6);

    char dir[1024];
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("sink_refs"));
    remove_tree(dir);
    mkdir(FXC_TEST_TMP, 0755);
    char err[512];
    srv_refcache *cache = srv_refcache_create(NULL, dir, "test settings", err, sizeof err);
    assert_non_null(cache);
    srv_camera camera = {.position = {0, 1, 0}, .target = {0, 1, -1}, .fov_deg = 60};
    uint64_t key = srv_refcache_key(cache, &camera, w, h);
    assert_int_not_equal(key, srv_refcache_key(cache, &camera, w, h + 1)); /* the size is in the key */
    char base[1200], path[1300], msg[512];
    snprintf(base, sizeof base, "%s/%016llx", dir, (unsigned long long)key);
    snprintf(path, sizeof path, "%s.exr", base);
    assert_int_equal(scene_image_write_f32(path, w, h, 3, reference, msg, sizeof msg), 0);
    snprintf(path, sizeof path, "%s_ao.exr", base);
    assert_int_equal(scene_image_write_f32(path, w, h, 1, ones, msg, sizeof msg), 0);
    snprintf(path, sizeof path, "%s_shadow.exr", base);
    assert_int_equal(scene_image_write_f32(path, w, h, 1, shadow_ref, msg, sizeof msg), 0);
    snprintf(path, sizeof path, "%s.json", base);
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    fprintf(f, "{\"width\": %u, \"height\": %u, \"noise_rmse\": 0.01}\n", w, h);
    fclose(f);

    char heatmap[1200];
    snprintf(heatmap, sizeof heatmap, "%s/heat.png", dir);
    srv_err_sink sink;
    srv_err_sink_init(&sink, &(srv_err_sink_desc){.refs = cache,
                                                  .every = 2,
                                                  .last_frame = 5,
                                                  .warmup = 2,
                                                  .compare_shadow = true,
                                                  .heatmap_viewer = "viewer_00",
                                                  .heatmap_path = heatmap});
    srv_sink s = srv_err_sink_sink(&sink);
    const float *views[3] = {ones, shadow, NULL};
    srv_viewer_frame vf = {.name = "viewer_00",
                           .width = w,
                           .height = h,
                           .radiance = frame,
                           .camera = camera,
                           .views = {views[0], views[1], views[2]}};
    for (uint32_t fr = 0; fr < 6; fr++) {
        sink.frame = fr;
        assert_int_equal(s.viewer_frame(s.user, &vf), 0);
        srv_frame_stats st = {.frame = fr, .viewer_count = 1, .frame_ms = 10.0};
        st.time_ms[SRV_STAGE_SINKS] = 4.0;
        st.rays[1] = 100;
        assert_int_equal(s.frame_done(s.user, &st), 0);
    }
    const srv_err_totals *t = &sink.totals;
    assert_int_equal(t->images_all, 4); /* frames 0, 2, 4 and the last, 5 */
    assert_int_equal(t->images, 3);     /* 2, 4, 5 are past the warm-up */
    assert_true(fabs(sqrt(t->mse_sum / t->images) - expected) < 1e-6);
    assert_true(fabs(sqrt(t->mse_shadow_sum / t->images) - sqrt(0.125)) < 1e-6);
    assert_true(fabs(sqrt(t->noise2_sum / t->images) - 0.01) < 1e-12);
    assert_int_equal(t->frames, 4);                 /* frames 2..5 timed */
    assert_true(fabs(t->ms_sum - 4 * 6.0) < 1e-12); /* frame time less the sinks stage */
    assert_int_equal(t->effect_rays, 400);
    assert_int_equal(access(heatmap, R_OK), 0);
    uint32_t rendered = 9, read = 9;
    srv_refcache_counts(cache, &rendered, &read, NULL);
    assert_int_equal(rendered, 0);
    assert_int_equal(read, 1); /* read once, then from memory */
    srv_refcache_free(cache);
}

/* ---- Pareto front, equal time -------------------------------------------------------------------------- */

static void test_pareto_front(void **state)
{
    (void)state;
    /* (1,10) (2,5) (3,6) (4,1) (5,1) (2,5) (NaN) (0.5,20): the front is the fastest, the two equal (2,5)
     * (neither is better), (4,1) and (0.5,20); (3,6) loses to (2,5), (5,1) to (4,1). */
    const double time[] = {1, 2, 3, 4, 5, 2, NAN, 0.5};
    const double error[] = {10, 5, 6, 1, 1, 5, 0.1, 20};
    const bool expected[] = {true, true, false, true, false, true, false, true};
    bool front[8];
    srv_rep_pareto(time, error, 8, front);
    for (int i = 0; i < 8; i++)
        assert_int_equal(front[i], expected[i]);

    /* Equal time, log-log between (10, 0.1) and (40, 0.05): at 20, 0.1 x 0.5^0.5. A slower, worse point is
     * not on the lower envelope and changes nothing. */
    const double t2[] = {40, 10, 30};
    const double e2[] = {0.05, 0.1, 0.2};
    int where = 9;
    assert_true(fabs(srv_rep_equal_time(t2, e2, 3, 20, &where) - 0.1 * sqrt(0.5)) < 1e-12);
    assert_int_equal(where, 0);
    assert_true(fabs(srv_rep_equal_time(t2, e2, 3, 5, &where) - 0.1) < 1e-12);
    assert_int_equal(where, -1);
    assert_true(fabs(srv_rep_equal_time(t2, e2, 3, 80, &where) - 0.05) < 1e-12);
    assert_int_equal(where, 1);
}

/* The plots' data files written to a full disk (each in turn a link to /dev/full): srv_rep_plots fails with
 * a line naming that file (-2, which fails the report as a CSV would); before, their write errors were
 * ignored and the report said it was done. With every file writable the same rows plot (or only miss
 * gnuplot: -1). */
static void test_plot_files_write_errors(void **state)
{
    (void)state;
    char dir[] = "/tmp/fxc_report_full_XXXXXX";
    assert_non_null(mkdtemp(dir));
    srv_rep_row row = {.id = "default",
                       .family = "default",
                       .label = "default",
                       .viewers = 1,
                       .done = true,
                       .ms_per_frame = 2,
                       .rmse = 0.1,
                       .pareto = true};
    srv_rep_image image = {.frame = 3, .viewer = "viewer_00", .steady = true, .rmse = 0.1};
    row.images_list = &image;
    row.image_count = 1;
    char err[1400], plots[1100], path[1200];
    snprintf(plots, sizeof plots, "%s/plots", dir);
    int fine = srv_rep_plots(dir, &row, 1, "ms", err, sizeof err);
    assert_true(fine > 0 || fine == -1);
    static const char *const files[] = {"points_v1.dat", "pareto_v1.dat", "frames_v1.dat", "plots.gp"};
    for (size_t k = 0; k < sizeof files / sizeof files[0]; k++) {
        snprintf(path, sizeof path, "%s/%s", plots, files[k]);
        assert_int_equal(unlink(path), 0);
        assert_int_equal(symlink("/dev/full", path), 0);
        err[0] = 0;
        assert_int_equal(srv_rep_plots(dir, &row, 1, "ms", err, sizeof err), -2);
        assert_non_null(strstr(err, files[k]));
        assert_null(strchr(err, '\n'));
        assert_int_equal(unlink(path), 0);
        FILE *f = fopen(path, "w"); /* back to a plain file for the next one */
        assert_non_null(f);
        fclose(f);
    }
    remove_tree(dir);
}

/* A scene whose every image is exact (a light of 1e-38: every radiance 0, every RMSE 0): the equal-time
 * comparison has no no-cache point with an error above 0 and says "not compared"; before, the page and the
 * summary in words printed "nan" for the no-cache error and the ratio. */
static void test_equal_time_all_exact(void **state)
{
    (void)state;
    srv_rep_row rows[2];
    memset(rows, 0, sizeof rows);
    const char *ids[2] = {"default_v1", "no_cache_x1_v1"};
    for (int i = 0; i < 2; i++) {
        snprintf(rows[i].id, sizeof rows[i].id, "%s", ids[i]);
        snprintf(rows[i].family, sizeof rows[i].family, "%s", i ? "no_cache" : "default");
        snprintf(rows[i].label, sizeof rows[i].label, "%s", ids[i]);
        rows[i].viewers = 1;
        rows[i].no_cache = i == 1;
        rows[i].done = true;
        rows[i].ms_per_frame = 5.0 * (i + 1);
        rows[i].rmse = rows[i].rmse_denoised = 0;
        rows[i].psnr_db = rows[i].rmse_shadow = rows[i].rmse_ao = rows[i].ref_noise = rows[i].flip_mean = NAN;
    }
    srv_rep_equal eq[4];
    assert_int_equal(srv_rep_equal_times(rows, 2, eq, 4), 1);
    assert_false(isfinite(eq[0].no_cache_rmse)); /* not measured: no point with an error above 0 */
    char dir[1024], path[1100], err[256];
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("report_exact"));
    mkdir(dir, 0755);
    srv_rep_page page = {
        .title = "exact", .command = "fxcache report", .settings = "", .time_label = "elapsed"};
    assert_true(srv_rep_write_html(dir, rows, 2, &page, err, sizeof err));
    snprintf(path, sizeof path, "%s/index.html", dir);
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    static char html[65536];
    size_t len = fread(html, 1, sizeof html - 1, f);
    html[len] = 0;
    fclose(f);
    assert_null(strstr(html, "nan"));
    assert_non_null(strstr(html, "not compared"));
}

/* ---- run-time sample counts ---------------------------------------------------------------------------- */

/* The same frame with 4 and with 16 shadow rays per texel: the same texels updated, a quarter of the rays
 * (a directional sun: a texel's rays face it alike); AO converging at 16 samples stops tracing after one
 * update of 16, at 64 it goes on. */
static void test_sample_counts(void **state)
{
    fxt_scene_fixture *fx = *state;
    uint32_t count = 0;
    const fx_effect *const *effects = fx_registry(&count);
    int32_t shadow = fx_find(effects, count, "shadow"), ao = fx_find(effects, count, "ao");
    srv_camera camera = {.position = {0, 1.6f, 3}, .target = {0, 1, 0}, .fov_deg = 60};
    uint64_t shadow_rays[2], shadow_texels[2], ao_rays_second[2];
    for (int run = 0; run < 2; run++) {
        srv_loop_desc d = {
            .s = fx->s, .rt = fx->rt, .threads = 2, .shadow_rays = run ? 16 : 4, .ao_samples = run ? 64 : 16};
        const char *names[] = {"shadow", "ao"};
        fxt_effects_on(&d, names, 2);
        srv_viewer_id id;
        srv_loop *loop = fxt_loop(&d, 1, 48, 27, &id);
        srv_frame_stats st;
        fxt_frame(loop, &id, 1, &camera, &st);
        shadow_rays[run] = st.rays[shadow];
        shadow_texels[run] = st.texels_updated[shadow];
        fxt_frame(loop, &id, 1, &camera, &st);
        ao_rays_second[run] = st.rays[ao];
        srv_loop_free(loop);
    }
    assert_true(shadow_texels[0] > 0);
    assert_int_equal(shadow_texels[0], shadow_texels[1]);
    assert_int_equal(shadow_rays[0] * 4, shadow_rays[1]);
    assert_int_equal(ao_rays_second[0], 0); /* converged at 16 after the first frame's 16 */
    assert_true(ao_rays_second[1] > 0);
}

/* ---- the command line ---------------------------------------------------------------------------------- */

static void test_cli_option_errors(void **state)
{
    (void)state;
    static const struct {
        const char *args, *needle;
    } cases[] = {
        {"report", "--out DIR is required"},
        {"report --out /tmp/x --frames 4 --warmup 4", "--warmup 4 must be below --frames 4"},
        {"report --out /tmp/x --only bias,nope", "'nope' is not a sweep"},
        {"report --out /tmp/x --ref-samples 3", "not a power of two"},
        {"report --out /tmp/x --ref-samples 1/16", "not a power of two in [0.125, 4]"},
        {"report --out /tmp/x --camera walk --trace a.trace", "--camera and --trace"},
        {"report --out /tmp/x --no-cache", "--no-cache is a sweep"},
        {"report --out /tmp/x --shadow-rays 3", "--shadow-rays: '3' must be 1, 2, 4, 8 or 16"},
        {"report --out /tmp/x --ao-samples 5000", "--ao-samples"},
        {"report --out /tmp/x --frames 1", "--frames"},
        {"report --out /tmp/x --bogus", "unknown option '--bogus'"},
        {"report --out /tmp/x --camera nowhere", "unknown generator 'nowhere'"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char err[2048] = "";
        int rc = fxt_run_cli(cases[i].args, NULL, 0, err, sizeof err);
        if (rc != 2 || !strstr(err, cases[i].needle))
            fail_msg("'%s': exit %d, stderr '%s' (wanted 2 and '%s')", cases[i].args, rc, err,
                     cases[i].needle);
        const char *newline = strchr(err, '\n');
        assert_true(newline && newline[1] == 0); /* one line */
    }
}

/* The CSV's rows as arrays of fields; returns the number of rows (header included). */
static size_t read_csv(const char *path, char rows[][64][48], size_t cap, size_t *fields)
{
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    char line[4096];
    size_t n = 0;
    while (n < cap && fgets(line, sizeof line, f)) {
        line[strcspn(line, "\n")] = 0;
        size_t k = 0;
        for (char *p = line;; k++) {
            char *comma = strchr(p, ',');
            size_t len = comma ? (size_t)(comma - p) : strlen(p);
            assert_true(k < 64 && len < 48);
            memcpy(rows[n][k], p, len);
            rows[n][k][len] = 0;
            if (!comma)
                break;
            p = comma + 1;
        }
        fields[n++] = k + 1;
    }
    fclose(f);
    return n;
}

static char csv[64][64][48];

/* Every row has the header's fields, the configuration names are unique, RMSE and time are positive. */
static size_t check_configs_csv(const char *dir)
{
    char path[1200];
    snprintf(path, sizeof path, "%s/configs.csv", dir);
    size_t fields[64];
    size_t n = read_csv(path, csv, 64, fields);
    assert_true(n >= 2);
    assert_string_equal(csv[0][0], "config");
    int rmse = -1, ms = -1;
    for (size_t k = 0; k < fields[0]; k++) {
        if (strcmp(csv[0][k], "rmse") == 0)
            rmse = (int)k;
        if (strcmp(csv[0][k], "ms_per_frame") == 0)
            ms = (int)k;
    }
    assert_true(rmse >= 0 && ms >= 0);
    for (size_t i = 1; i < n; i++) {
        assert_int_equal(fields[i], fields[0]);
        assert_true(strtod(csv[i][rmse], NULL) > 0);
        assert_true(strtod(csv[i][ms], NULL) > 0);
        for (size_t j = 1; j < i; j++)
            assert_string_not_equal(csv[i][0], csv[j][0]);
    }
    return n - 1;
}

/* A tiny report: every file it promises exists, the CSVs parse, the AO term is measured (no probes). */
static void test_cli_end_to_end(void **state)
{
    (void)state;
    char dir[1024], args[2048], path[1200], err[8192] = "";
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("report_e2e"));
    remove_tree(dir);
    snprintf(args, sizeof args,
             "report --quick --out %s --res 24x14 --frames 4 --warmup 2 --every 2 --viewers 2 --threads 2 "
             "--only default,viewers,no_cache --ref-samples 1/8 --effects shadow,ao",
             dir);
    int rc = fxt_run_cli(args, NULL, 0, err, sizeof err);
    if (rc != 0)
        fail_msg("exit %d: %s", rc, err);
    assert_non_null(strstr(err, "report: [1/")); /* a line per configuration */
    const char *files[] = {"index.html",
                           "configs.csv",
                           "frames.csv",
                           "summary.json",
                           "heatmaps/default_v1.png",
                           "frames/default_v1.png",
                           "done/default_v1.json",
                           "plots/plots.gp"};
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, files[i]);
        if (access(path, R_OK) != 0)
            fail_msg("%s is missing", path);
    }
    if (srv_rep_on_path("gnuplot")) {
        snprintf(path, sizeof path, "%s/plots/error_time_v1.svg", dir);
        assert_int_equal(access(path, R_OK), 0);
    }
    /* default 1 and 2 viewers, no cache at four scales for 1 and for 2 viewers. */
    assert_int_equal(check_configs_csv(dir), 10);
    int ao = -1;
    for (int k = 0; k < 64 && csv[0][k][0]; k++)
        if (strcmp(csv[0][k], "rmse_ao") == 0)
            ao = k;
    assert_true(ao >= 0 && strtod(csv[1][ao], NULL) > 0);
    json_t *summary = json_load_file((snprintf(path, sizeof path, "%s/summary.json", dir), path), 0, NULL);
    assert_non_null(summary);
    assert_int_equal(json_array_size(json_object_get(summary, "equal_time")), 2);
    json_decref(summary);
    /* The page links only inside the folder. */
    snprintf(path, sizeof path, "%s/index.html", dir);
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    char html[65536];
    size_t len = fread(html, 1, sizeof html - 1, f);
    html[len] = 0;
    fclose(f);
    assert_null(strstr(html, "src=\"/"));
    assert_null(strstr(html, "href=\"/"));
    assert_null(strstr(html, "http"));
    assert_non_null(strstr(html, "heatmaps/default_v1.png"));
}

/* A pool too small for the frames' requests (--pool-mb 1 with the probes' fine cells): the configuration's
 * line says DEGRADED with the counts, configs.csv and summary.json carry them; its error is not passed off as
 * the cache's. The same report with the default pool says nothing of the kind and counts 0. */
static void test_cli_exhausted_pool_counted(void **state)
{
    (void)state;
    for (int small = 1; small >= 0; small--) {
        char dir[1024], args[2048], path[1200], err[8192] = "";
        snprintf(dir, sizeof dir, "%s", fxt_tmp_path(small ? "report_pool1" : "report_pool64"));
        remove_tree(dir);
        snprintf(
            args, sizeof args,
            "report --quick --out %s --res 48x27 --frames 3 --warmup 1 --every 1 --viewers 1 --threads 2 "
            "--only default --ref-samples 1/8 --effects probes --probe-cell 0.02 --pool-mb %d --quiet",
            dir, small ? 1 : 64);
        int rc = fxt_run_cli(args, NULL, 0, err, sizeof err);
        if (rc != 0)
            fail_msg("exit %d: %s", rc, err);
        print_message("%s\n", err);
        assert_true((strstr(err, "DEGRADED: the block pools (--pool-mb) were full ") != NULL) == small);
        assert_int_equal(check_configs_csv(dir), 1);
        int exhausted = -1;
        for (int k = 0; k < 64 && csv[0][k][0]; k++)
            if (strcmp(csv[0][k], "pool_exhausted") == 0)
                exhausted = k;
        assert_true(exhausted >= 0);
        assert_true((strtod(csv[1][exhausted], NULL) > 0) == small);
        json_t *summary =
            json_load_file((snprintf(path, sizeof path, "%s/summary.json", dir), path), 0, NULL);
        assert_non_null(summary);
        json_t *degraded = json_object_get(summary, "degraded");
        assert_int_equal(json_array_size(degraded), small ? 1 : 0);
        if (small)
            assert_true(json_integer_value(json_object_get(json_array_get(degraded, 0), "pool_exhausted")) >
                        0);
        json_decref(summary);
    }
}

/* SIGTERM once the first configuration is done: exit 0 with everything finished written; the rerun skips the
 * finished configuration (its marker untouched), runs the rest, and the CSV has each once. */
static void test_cli_resume(void **state)
{
    (void)state;
    char dir[1024], marker[1200], path[1200];
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("report_resume"));
    remove_tree(dir);
    snprintf(marker, sizeof marker, "%s/done/default_v1.json", dir);
    const char *argv[] = {FXC_BIN,         "report", "--out",     dir, "--res",   "24x14",
                          "--frames",      "40",     "--warmup",  "2", "--every", "13",
                          "--viewers",     "2",      "--threads", "1", "--only",  "default,viewers",
                          "--ref-samples", "1/8",    "--quiet",   NULL};
    pid_t pid = fxt_spawn_quiet(argv, 0, NULL);
    bool seen = false;
    for (int tries = 0; tries < 1200 && !seen; tries++) { /* at most 120 s */
        seen = access(marker, R_OK) == 0;
        struct timespec pause = {0, 100 * 1000 * 1000};
        nanosleep(&pause, NULL);
    }
    assert_true(seen);
    assert_int_equal(kill(pid, SIGTERM), 0);
    int status = 0;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFEXITED(status));
    assert_int_equal(WEXITSTATUS(status), 0);
    snprintf(path, sizeof path, "%s/done/default_v2.json", dir);
    if (access(path, R_OK) == 0)
        skip(); /* the second configuration finished before the signal arrived: nothing left to resume */
    assert_int_equal(check_configs_csv(dir), 1);
    struct stat before;
    assert_int_equal(stat(marker, &before), 0);

    char args[2048], err[8192] = "";
    snprintf(args, sizeof args,
             "report --out %s --res 24x14 --frames 40 --warmup 2 --every 13 --viewers 2 --threads 1 --only "
             "default,viewers --ref-samples 1/8 --quiet",
             dir);
    int rc = fxt_run_cli(args, NULL, 0, err, sizeof err);
    if (rc != 0)
        fail_msg("rerun: exit %d: %s", rc, err);
    assert_non_null(strstr(err, "default_v1: done earlier"));
    assert_non_null(strstr(err, "references: 0 rendered")); /* every reference came from ref/ */
    struct stat after;
    assert_int_equal(stat(marker, &after), 0);
    assert_int_equal(before.st_mtim.tv_sec, after.st_mtim.tv_sec);
    assert_int_equal(before.st_mtim.tv_nsec, after.st_mtim.tv_nsec);
    assert_int_equal(before.st_ino, after.st_ino);
    assert_int_equal(check_configs_csv(dir), 2);
}

/* Runs a small report of the scene and trace below into dir with extra options; returns its stderr in err. */
static void run_small_report(const char *dir, const char *scene_path, const char *trace_path,
                             const char *extra, char *err, size_t err_cap)
{
    char args[3072];
    snprintf(
        args, sizeof args,
        "report --out %s --scene %s --trace %s --res 16x9 --frames 3 --warmup 1 --every 2 --threads 1 --only "
        "default --ref-samples 1/8 --effects shadow %s",
        dir, scene_path, trace_path, extra);
    err[0] = 0;
    int rc = fxt_run_cli(args, NULL, 0, err, err_cap);
    if (rc != 0)
        fail_msg("exit %d: %s", rc, err);
}

/* A folder is reused only for what it was made from: run again unchanged, the configuration is done earlier
 * and every reference read; with the scene file edited in place (another sun), the trace edited in place
 * (another camera) or another --indirect-block, neither the configuration nor (for the edits) the references
 * are taken from the folder. Before, the scene and traces counted by their paths and --indirect-block not at
 * all, so each of the three silently reported the old results. The same for a material's emission edited
 * alone. */
static void test_cli_folder_of_other_content(void **state)
{
    (void)state;
    static const char scene_a[] =
        "{\"version\": 1, \"meshes\": [{\"builtin\": \"default\"}], \"lights\": "
        "[{\"type\": \"directional\", \"direction\": [-0.3, -1, -0.2], \"intensity\": 3}]}";
    static const char scene_b[] =
        "{\"version\": 1, \"meshes\": [{\"builtin\": \"default\"}], \"lights\": "
        "[{\"type\": \"directional\", \"direction\": [-0.3, -1, -0.2], \"intensity\": 1}]}";
    static const char trace_a[] = "fxcache-trace 1\n0 0 1.6 3 0 -0.2 -1 60\n0.05 0.1 1.6 3 0 -0.2 -1 60\n"
                                  "0.1 0.1 1.6 3 0 -0.2 -1 60\n";
    static const char trace_b[] = "fxcache-trace 1\n0 0 1.6 3 0 -0.2 -1 60\n0.05 0.2 1.6 3 0 -0.2 -1 60\n"
                                  "0.1 0.2 1.6 3 0 -0.2 -1 60\n";
    char dir[1024], scene_path[1024], trace_path[1024], err[8192];
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("report_other_content"));
    remove_tree(dir);
    snprintf(scene_path, sizeof scene_path, "%s", fxt_write_file("report_scene.json", scene_a));
    snprintf(trace_path, sizeof trace_path, "%s", fxt_write_file("report_walk.trace", trace_a));

    run_small_report(dir, scene_path, trace_path, "", err, sizeof err);
    if (strstr(err, "default_v1: done earlier") || strstr(err, "RMSE nan"))
        fail_msg("the first run: %s", err);
    run_small_report(dir, scene_path, trace_path, "", err, sizeof err);
    if (!strstr(err, "default_v1: done earlier"))
        fail_msg("the same again: %s", err);

    fxt_write_file("report_scene.json", scene_b);
    run_small_report(dir, scene_path, trace_path, "", err, sizeof err);
    if (strstr(err, "default_v1: done earlier") || !strstr(err, "references: 2 rendered"))
        fail_msg("the scene edited in place: %s", err);

    fxt_write_file("report_walk.trace", trace_b);
    run_small_report(dir, scene_path, trace_path, "", err, sizeof err);
    if (strstr(err, "default_v1: done earlier") || !strstr(err, "references: 2 rendered"))
        fail_msg("the trace edited in place: %s", err);

    run_small_report(dir, scene_path, trace_path, "--indirect-block 1", err, sizeof err);
    if (strstr(err, "default_v1: done earlier") || !strstr(err, "references: 0 rendered"))
        fail_msg("another --indirect-block: %s", err);

    /* Only a material's emission edited (a lamp brightened): before, emission was not in the fingerprint. */
    fxt_write_quad();
    static const char lamp[] =
        "{\"version\": 1, \"meshes\": [{\"builtin\": \"default\"}, {\"file\": \"quad.obj\", "
        "\"transform\": {\"translate\": [0, 0.5, 0]}, \"material\": {\"emission\": [%d, %d, %d]}}], "
        "\"lights\": [{\"type\": \"directional\", \"direction\": [-0.3, -1, -0.2], "
        "\"intensity\": 1}]}";
    char text[512];
    snprintf(text, sizeof text, lamp, 1, 1, 1);
    fxt_write_file("report_scene.json", text);
    run_small_report(dir, scene_path, trace_path, "--indirect-block 1", err, sizeof err);
    snprintf(text, sizeof text, lamp, 2, 2, 2);
    fxt_write_file("report_scene.json", text);
    run_small_report(dir, scene_path, trace_path, "--indirect-block 1", err, sizeof err);
    if (strstr(err, "default_v1: done earlier") || !strstr(err, "references: 2 rendered"))
        fail_msg("the emission edited in place: %s", err);
}

/* A trace that ends before the first compared frame after the warm-up: the configuration has no error to give.
 * Its line says so, and every error column of configs.csv is empty; before, the line printed "RMSE nan, PSNR
 * inf dB" and rmse_denoised was 0 (fmax(0, NaN)), an exact match where nothing was compared. PSNR of no
 * error is no PSNR (NaN), of a zero error infinite. */
static void test_cli_trace_ends_before_compared_frames(void **state)
{
    (void)state;
    assert_true(isnan(srv_err_psnr(NAN)));
    assert_true(isinf(srv_err_psnr(0.0)));
    assert_true(fabs(srv_err_psnr(0.1) - 20.0) < 1e-12);
    static const char trace[] = "fxcache-trace 1\n0 0 1.6 3 0 -0.2 -1 60\n0.05 0.1 1.6 3 0 -0.2 -1 60\n";
    char dir[1024], trace_path[1024], args[3072], err[8192] = "";
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("report_short_trace"));
    remove_tree(dir);
    snprintf(trace_path, sizeof trace_path, "%s", fxt_write_file("report_short.trace", trace));
    /* frames at 0, 1/30 and 2/30 s: the viewer has left at frame 2, the only compared frame after warm-up 1 */
    snprintf(
        args, sizeof args,
        "report --out %s --trace %s --res 16x9 --frames 3 --warmup 1 --every 2 --threads 1 --only default "
        "--ref-samples 1/8 --effects shadow",
        dir, trace_path);
    int rc = fxt_run_cli(args, NULL, 0, err, sizeof err);
    if (rc != 0)
        fail_msg("exit %d: %s", rc, err);
    if (strstr(err, "nan") || strstr(err, " inf") || !strstr(err, "no frame after the warm-up was compared"))
        fail_msg("%s", err);
    char path[1200];
    size_t fields[64];
    snprintf(path, sizeof path, "%s/configs.csv", dir);
    assert_int_equal(read_csv(path, csv, 64, fields), 2);
    for (size_t k = 0; k < fields[0]; k++)
        if (strncmp(csv[0][k], "rmse", 4) == 0 || strcmp(csv[0][k], "psnr_db") == 0)
            if (csv[1][k][0])
                fail_msg("configs.csv: %s is '%s' with no frame compared", csv[0][k], csv[1][k]);

    /* A trace of one camera: gone before the warm-up ends, so no timed frame has a viewer; its line said
     * "nan per viewer". */
    snprintf(trace_path, sizeof trace_path, "%s",
             fxt_write_file("report_one.trace", "fxcache-trace 1\n0 0 1.6 3 0 -0.2 -1 60\n"));
    remove_tree(dir);
    snprintf(
        args, sizeof args,
        "report --out %s --trace %s --res 16x9 --frames 3 --warmup 1 --every 2 --threads 1 --only default "
        "--ref-samples 1/8 --effects shadow",
        dir, trace_path);
    err[0] = 0;
    rc = fxt_run_cli(args, NULL, 0, err, sizeof err);
    if (rc != 0 || strstr(err, "nan") || !strstr(err, "(no viewer present, CPU"))
        fail_msg("one camera: exit %d: %s", rc, err);
}

/* Two runs writing one folder at once: while another process holds DIR/.fxcache.lock (here, a child of the
 * test that took it with flock), report and ref refuse the folder with one line naming the holder, and write
 * nothing into it; once it is given back, report runs. Before, the two wrote the same CSVs and markers. */
static void test_cli_folder_in_use(void **state)
{
    (void)state;
    char dir[1024], lock_path[1200], err[8192], args[3072];
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("report_in_use"));
    remove_tree(dir);
    assert_int_equal(mkdir(dir, 0755), 0);
    snprintf(lock_path, sizeof lock_path, "%s/.fxcache.lock", dir);
    int ready[2];
    assert_int_equal(pipe(ready), 0);
    pid_t holder = fork();
    assert_true(holder >= 0);
    if (holder == 0) { /* takes the lock as another run would, says so, and waits to be ended */
        int fd = open(lock_path, O_RDWR | O_CREAT, 0644);
        if (fd < 0 || flock(fd, LOCK_EX) != 0 || dprintf(fd, "%ld\n", (long)getpid()) < 0)
            _exit(1);
        if (write(ready[1], "x", 1) != 1)
            _exit(1);
        pause();
        _exit(0);
    }
    char byte;
    assert_int_equal(read(ready[0], &byte, 1), 1);
    char holder_text[64];
    snprintf(holder_text, sizeof holder_text, "is in use by another fxcache run (process %ld)", (long)holder);
    static const char *const commands[2] = {
        "report --out %s --res 16x9 --frames 3 --warmup 1 --every 2 --threads 1 --only default --ref-samples "
        "1/8 --effects shadow --viewers 1",
        "ref --out %s --res 8x8 --frames 1 --ao-samples 2 --shadow-rays 32 --paths 2 --threads 1 --quiet"};
    for (int k = 0; k < 2; k++) {
        snprintf(args, sizeof args, commands[k], dir);
        err[0] = 0;
        int rc = fxt_run_cli(args, NULL, 0, err, sizeof err);
        if (rc != 1 || !strstr(err, holder_text) || strchr(err, '\n') != err + strlen(err) - 1)
            fail_msg("%s with the folder in use: exit %d, '%s'", k ? "ref" : "report", rc, err);
    }
    char path[1200];
    snprintf(path, sizeof path, "%s/configs.csv", dir);
    assert_int_equal(access(path, F_OK), -1);
    snprintf(path, sizeof path, "%s/ref.json", dir);
    assert_int_equal(access(path, F_OK), -1);
    kill(holder, SIGTERM);
    waitpid(holder, NULL, 0);
    close(ready[0]);
    close(ready[1]);
    snprintf(args, sizeof args, commands[0], dir);
    int rc = fxt_run_cli(args, NULL, 0, err, sizeof err);
    if (rc != 0)
        fail_msg("report after the lock was given back: exit %d, '%s'", rc, err);
}

#define SCENE_TEST(fn)                                                                                       \
    cmocka_unit_test_setup_teardown(fn, fxt_default_scene_setup, fxt_default_scene_teardown)

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_error_sink_closed_form),
        cmocka_unit_test(test_pareto_front),
        cmocka_unit_test(test_plot_files_write_errors),
        cmocka_unit_test(test_equal_time_all_exact),
        SCENE_TEST(test_sample_counts),
        cmocka_unit_test(test_cli_option_errors),
        cmocka_unit_test(test_cli_end_to_end),
        cmocka_unit_test(test_cli_exhausted_pool_counted),
        cmocka_unit_test(test_cli_resume),
        cmocka_unit_test(test_cli_folder_of_other_content),
        cmocka_unit_test(test_cli_trace_ends_before_compared_frames),
        cmocka_unit_test(test_cli_folder_in_use),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
