/* `fxcache report`: error against run time (DESIGN.md "Error against run time"). Sweeps of the engine's
 * settings, each configuration one run of the engine on the same cameras (viewer traces, or a generator's
 * cameras for the largest viewer count, of which a run with fewer viewers takes the first), with the error
 * accumulator (error_sink.h) as one of its sinks: per configuration the time per frame (the engine's frame
 * time without the sinks stage, steady state) and the error of the compared frames against reference images
 * of the same cameras, rendered once and cached on disk under DIR/ref/. Into DIR: configs.csv, frames.csv,
 * plots (gnuplot), heat maps, index.html (report_out.h). A finished configuration leaves DIR/done/ID.json, so
 * an interrupted report, run again with the same options, resumes without redoing it. SIGINT and SIGTERM stop
 * after the current frame (or reference image) with everything finished written. */
#include "camgen.h"
#include "cli_cameras.h"
#include "cli.h"
#include "cli_engine.h"
#include "error_sink.h"
#include "image.h"
#include "reference.h"
#include "report_out.h"
#include "report_plan.h"
#include "trace.h"

#include <errno.h>
#include <getopt.h>
#include <jansson.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

static volatile sig_atomic_t stop_requested = 0;

/* The first signal asks for the end after the current frame; the second ends at once (default action). */
static void on_signal(int sig)
{
    stop_requested = sig;
    signal(sig, SIG_DFL);
}

/* ---- cameras ------------------------------------------------------------------------------------------- */

/* What a configuration's frames lacked, for its line: "" when nothing (the budget's deferrals are the ray
 * and probe budgets at work, said with the count; an exhausted pool is a degraded run, said with its cause). */
static void degraded_text(const srv_rep_row *row, char *out, size_t cap)
{
    size_t used = 0;
    out[0] = 0;
    if (row->pool_exhausted)
        used += (size_t)snprintf(out, cap,
                                 "; DEGRADED: the block pools (--pool-mb) were full %llu times, %llu visible "
                                 "pixels composed without cached data",
                                 (unsigned long long)row->pool_exhausted,
                                 (unsigned long long)row->pixels_missing);
    if (row->texels_deferred && used < cap)
        snprintf(out + used, cap - used, "; %llu texels and cells deferred by the budgets",
                 (unsigned long long)row->texels_deferred);
}

static bool frame_compared(const report_options *o, uint32_t frame)
{
    return frame == o->view.frames - 1 || frame % o->every == 0;
}

/* ---- what a folder's results were made from ---------------------------------------------------------- */

/* A fingerprint of what the results depend on beyond the options and the scene's path: the loaded scene's
 * content (geometry, UVs, vertex colours, materials with their emission, textures, lights, sky, density, AO radius, effect overrides, default
 * camera, origin) and the camera and size of every viewer in every frame (trace files and generators alike).
 * The references and the finished configurations in DIR are keyed by it, so a scene or trace edited in place
 * under the same name makes them again instead of being taken for the one the folder was made from. */
static uint64_t content_fingerprint(const scene *s, const srv_cli_cameras *cams, uint32_t frames)
{
    uint64_t h = SRV_FNV1A_START;
    h = srv_fnv1a(h, &s->vertex_count, sizeof s->vertex_count);
    h = srv_fnv1a(h, s->positions, (size_t)s->vertex_count * 3 * sizeof(float));
    h = srv_fnv1a(h, &s->triangle_count, sizeof s->triangle_count);
    h = srv_fnv1a(h, s->indices, (size_t)s->triangle_count * 3 * sizeof(uint32_t));
    if (s->corner_uv)
        h = srv_fnv1a(h, s->corner_uv, (size_t)s->triangle_count * 6 * sizeof(float));
    if (s->corner_color) /* vertex colours (a scene without them hashes as before) */
        h = srv_fnv1a(h, s->corner_color, (size_t)s->triangle_count * 9 * sizeof(float));
    h = srv_fnv1a(h, s->tri_mesh, (size_t)s->triangle_count * sizeof(uint32_t));
    for (uint32_t m = 0; m < s->mesh_count; m++)
        h = srv_fnv1a(h, &s->meshes[m].material, sizeof s->meshes[m].material);
    for (uint32_t m = 0; m < s->material_count; m++) {
        h = srv_fnv1a(h, s->materials[m].diffuse, sizeof s->materials[m].diffuse);
        h = srv_fnv1a(h, &s->materials[m].texture, sizeof s->materials[m].texture);
        if (scene_material_emits(&s->materials[m])) /* emission (none hashes as before) */
            h = srv_fnv1a(h, s->materials[m].emission, sizeof s->materials[m].emission);
    }
    for (uint32_t t = 0; t < s->texture_count; t++) {
        const scene_texture *tex = &s->textures[t];
        h = srv_fnv1a(h, &tex->width, sizeof tex->width);
        h = srv_fnv1a(h, &tex->height, sizeof tex->height);
        h = srv_fnv1a(h, tex->rgb, (size_t)tex->width * tex->height * 3 * sizeof(float));
    }
    for (uint32_t l = 0; l < s->light_count; l++) {
        const scene_light *light = &s->lights[l];
        int type = (int)light->type;
        h = srv_fnv1a(h, &type, sizeof type);
        h = srv_fnv1a(h, light->direction, sizeof light->direction);
        h = srv_fnv1a(h, light->position, sizeof light->position);
        h = srv_fnv1a(h, light->color, sizeof light->color);
        h = srv_fnv1a(h, &light->intensity, sizeof light->intensity);
    }
    int toggles[3] = {(int)s->fx_shadows, (int)s->fx_ao, (int)s->fx_indirect};
    h = srv_fnv1a(h, s->sky_color, sizeof s->sky_color);
    h = srv_fnv1a(h, &s->sky_intensity, sizeof s->sky_intensity);
    h = srv_fnv1a(h, &s->texel_density, sizeof s->texel_density);
    h = srv_fnv1a(h, &s->ao_radius, sizeof s->ao_radius);
    h = srv_fnv1a(h, toggles, sizeof toggles);
    h = srv_fnv1a(h, s->origin, sizeof s->origin);
    for (uint32_t f = 0; f < frames; f++)
        for (uint32_t v = 0; v < cams->viewers; v++) {
            srv_camera c = {0};
            uint32_t size[2] = {0, 0};
            unsigned char present = srv_cli_cameras_get(cams, s, f, v, &c, &size[0], &size[1]);
            h = srv_fnv1a(h, &present, 1);
            if (present) {
                h = srv_fnv1a(h, c.position, sizeof c.position);
                h = srv_fnv1a(h, c.target, sizeof c.target);
                h = srv_fnv1a(h, c.up, sizeof c.up);
                h = srv_fnv1a(h, &c.fov_deg, sizeof c.fov_deg);
                h = srv_fnv1a(h, size, sizeof size);
            }
        }
    return h;
}

/* ---- files --------------------------------------------------------------------------------------------- */

/* Loads a configuration's marker if it exists and was made with the same key. */
static bool load_marker(const char *dir, report_config *c)
{
    char path[1400];
    snprintf(path, sizeof path, "%s/done/%s.json", dir, c->row.id);
    json_error_t jerr;
    json_t *marker = json_load_file(path, 0, &jerr);
    if (!marker)
        return false;
    const char *key = json_string_value(json_object_get(marker, "key"));
    bool ok =
        key && strcmp(key, c->key) == 0 && srv_rep_row_from_json(&c->row, json_object_get(marker, "row"));
    json_decref(marker);
    if (!ok) {
        c->row.done = false;
        srv_rep_row_free_images(&c->row);
    }
    return ok;
}

static bool write_marker(const char *dir, const report_config *c)
{
    char path[1400], tmp[1420];
    snprintf(path, sizeof path, "%s/done/%s.json", dir, c->row.id);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    json_t *marker = json_pack("{s:s,s:o}", "key", c->key, "row", srv_rep_row_json(&c->row));
    bool ok = marker && json_dump_file(marker, tmp, JSON_INDENT(1) | JSON_PRESERVE_ORDER) == 0 &&
              rename(tmp, path) == 0;
    json_decref(marker);
    if (!ok)
        fprintf(stderr, "fxcache report: cannot write %s: %s\n", path, strerror(errno));
    return ok;
}

/* FLIP (NVIDIA's, the flip-evaluator package's 'flip' program) of a frame against its reference: the mean it
 * prints, or NAN when it is not installed or says nothing we can read. Nothing else depends on it. */
static double flip_mean(const char *dir, const srv_rep_row *r)
{
    if (!r->frame_png[0] || !r->ref_png[0] || !srv_rep_on_path("flip"))
        return NAN;
    char command[1400];
    snprintf(command, sizeof command, "cd '%s' && flip -r '%s' -t '%s' 2>&1", dir, r->ref_png, r->frame_png);
    FILE *p = popen(command, "r");
    if (!p)
        return NAN;
    double mean = NAN;
    char line[512];
    while (fgets(line, sizeof line, p)) {
        const char *at = strstr(line, "Mean");
        if (!at)
            at = strstr(line, "mean");
        const char *colon = at ? strchr(at, ':') : NULL;
        if (colon && isnan(mean))
            mean = strtod(colon + 1, NULL);
    }
    pclose(p);
    return mean;
}

/* ---- running one configuration ------------------------------------------------------------------------- */

/* Writes viewer_00's frame at the last frame as the configuration's picture (inside the sinks stage). */
typedef struct picture_sink {
    const srv_err_sink *clock;
    uint32_t last_frame;
    char path[1400];
    bool written;
} picture_sink;

static int picture_frame(void *user, const srv_viewer_frame *vf)
{
    picture_sink *p = user;
    if (p->clock->frame != p->last_frame || strcmp(vf->name, "viewer_00") != 0)
        return 0;
    char msg[512];
    if (scene_image_write_u8(p->path, vf->width, vf->height, 3, vf->srgb, msg, sizeof msg) != 0) {
        fprintf(stderr, "fxcache report: %s\n", msg);
        return -1;
    }
    p->written = true;
    return 0;
}

/* Collects the compared images into the row. */
static void on_image(void *user, const srv_err_image *im)
{
    srv_rep_row *row = user;
    srv_rep_image image = {.frame = im->frame,
                           .steady = im->steady,
                           .rmse = im->rmse,
                           .psnr_db = im->psnr_db,
                           .rmse_shadow = im->rmse_shadow,
                           .rmse_ao = im->rmse_ao};
    snprintf(image.viewer, sizeof image.viewer, "%s", im->viewer);
    srv_rep_row_add_image(row, &image);
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Runs configuration c: 1 finished, 0 interrupted, -1 failed (a line was printed). */
static int run_config(report_config *c, const report_context *ctx, const srv_cli_cameras *cams, scene_rt *rt,
                      const bool effect_on[SRV_MAX_EFFECTS], srv_refcache *refs, bool progress, size_t index,
                      size_t total)
{
    const report_options *o = ctx->o;
    const srv_cli_engine *e = &c->engine;
    srv_rep_row *row = &c->row;
    srv_rep_row_free_images(row);
    row->pool_exhausted = row->pixels_missing = row->texels_deferred = 0;
    double start = now_s();
    srv_loop_desc desc = srv_cli_loop_desc(e, ctx->s, rt, true);
    memcpy(desc.effect_on, effect_on, sizeof desc.effect_on);
    char err[512];
    srv_loop *loop = NULL;
    if (srv_loop_create(&desc, &loop, err, sizeof err) != FXC_OK) {
        fprintf(stderr, "fxcache report: %s: %s\n", row->id, err);
        return -1;
    }
    snprintf(row->heatmap, sizeof row->heatmap, "heatmaps/%s.png", row->id);
    snprintf(row->frame_png, sizeof row->frame_png, "frames/%s.png", row->id);
    char heatmap_path[1400];
    snprintf(heatmap_path, sizeof heatmap_path, "%s/%s", o->out_dir, row->heatmap);
    srv_err_sink errors;
    srv_err_sink_init(
        &errors, &(srv_err_sink_desc){.refs = refs,
                                      .every = o->every,
                                      .last_frame = o->view.frames - 1,
                                      .warmup = o->warmup,
                                      .compare_shadow = ctx->shadow_index >= 0 && ctx->s->light_count > 0,
                                      .compare_ao = ctx->ao_index >= 0 && !ctx->probes_on,
                                      .heatmap_viewer = "viewer_00",
                                      .heatmap_path = heatmap_path,
                                      .heatmap_max = (float)o->heatmap_max,
                                      .on_image = on_image,
                                      .user = row});
    picture_sink picture = {.clock = &errors, .last_frame = o->view.frames - 1};
    snprintf(picture.path, sizeof picture.path, "%s/%s", o->out_dir, row->frame_png);
    srv_sink err_sink = srv_err_sink_sink(&errors);
    srv_loop_add_sink(loop, &err_sink);
    srv_loop_add_sink(loop, &(srv_sink){.viewer_frame = picture_frame, .user = &picture});

    srv_viewer_id ids[SRV_MAX_VIEWERS] = {{0}};
    bool joined[SRV_MAX_VIEWERS] = {false}, left[SRV_MAX_VIEWERS] = {false};
    int result = 1;
    uint32_t frame = 0;
    srv_camera last_camera0 = {0};
    uint32_t last_w = 0, last_h = 0;
    bool have_last = false;
    for (; frame < o->view.frames; frame++) {
        if (stop_requested) {
            result = 0;
            break;
        }
        if (e->no_cache && !frame_compared(o, frame))
            continue; /* no state between frames: only the compared ones are rendered */
        for (uint32_t v = 0; v < row->viewers; v++) {
            srv_camera cam;
            uint32_t w, h;
            bool present = srv_cli_cameras_get(cams, ctx->s, frame, v, &cam, &w, &h);
            if (!present && joined[v] && !left[v]) {
                srv_viewer_remove(loop, ids[v]);
                left[v] = true;
            }
            if (!present || left[v])
                continue;
            if (!joined[v]) {
                srv_viewer_desc vd = {.width = w, .height = h};
                snprintf(vd.name, sizeof vd.name, "viewer_%02u", v);
                if (srv_viewer_add(loop, &vd, &ids[v]) != FXC_OK) {
                    fprintf(stderr, "fxcache report: %s: viewer %u could not be added\n", row->id, v);
                    result = -1;
                    goto done;
                }
                joined[v] = true;
            }
            if (srv_viewer_set_camera(loop, ids[v], &cam) != FXC_OK) {
                fprintf(stderr, "fxcache report: %s: frame %u, viewer %u: a degenerate camera\n", row->id,
                        frame, v);
                result = -1;
                goto done;
            }
            if (v == 0 && frame == o->view.frames - 1) {
                last_camera0 = cam;
                last_w = w;
                last_h = h;
                have_last = true;
            }
        }
        errors.frame = frame;
        srv_frame_stats st;
        double cpu = srv_err_cpu_ms();
        fxc_result r = srv_loop_frame(loop, &st);
        srv_err_sink_add_cpu(&errors, frame, srv_err_cpu_ms() - cpu);
        if (r != FXC_OK) {
            fprintf(stderr, "fxcache report: %s: frame %u: %s\n", row->id, frame,
                    errors.totals.error[0] ? errors.totals.error : "a sink could not write");
            result = -1;
            goto done;
        }
        row->pool_exhausted = st.exhausted; /* cumulative (the probes' pool in it) */
        row->pixels_missing += st.pixels_missing;
        for (uint32_t k = 0; k < SRV_MAX_EFFECTS; k++)
            row->texels_deferred += st.texels_deferred[k];
        if (progress)
            fprintf(stderr, "\r  [%zu/%zu] %s: frame %u/%u, %.1f ms   ", index + 1, total, row->id, frame + 1,
                    o->view.frames, st.frame_ms - st.time_ms[SRV_STAGE_SINKS]);
    }
    if (progress)
        fputs("\r\033[K", stderr);
    if (result == 1) {
        const srv_err_totals *t = &errors.totals;
        row->frames_timed = t->frames;
        row->images = t->images;
        row->ms_per_frame = t->frames ? t->ms_sum / t->frames : NAN;
        row->ms_per_viewer = t->viewer_frames ? t->ms_sum / (double)t->viewer_frames : NAN;
        row->cpu_ms_per_frame = t->frames ? t->cpu_ms_sum / t->frames : NAN;
        row->rays_per_frame = t->frames ? (double)t->effect_rays / t->frames : NAN;
        double mse = t->images ? t->mse_sum / t->images : NAN,
               noise2 = t->images ? t->noise2_sum / t->images : NAN;
        row->rmse = sqrt(mse);
        row->psnr_db = srv_err_psnr(row->rmse);
        row->rmse_denoised = t->images ? sqrt(fmax(0.0, mse - noise2)) : NAN; /* fmax(0, NaN) would say 0 */
        row->rmse_shadow =
            t->images && errors.desc.compare_shadow ? sqrt(t->mse_shadow_sum / t->images) : NAN;
        row->rmse_ao = t->images && errors.desc.compare_ao ? sqrt(t->mse_ao_sum / t->images) : NAN;
        row->ref_noise = sqrt(noise2);
        if (have_last)
            snprintf(row->ref_png, sizeof row->ref_png, "ref/%016llx.png",
                     (unsigned long long)srv_refcache_key(refs, &last_camera0, last_w, last_h));
        if (!picture.written)
            row->frame_png[0] = row->heatmap[0] = 0;
        row->flip_mean = flip_mean(o->out_dir, row);
        row->run_s = now_s() - start;
        row->done = true;
    }
done:
    srv_loop_free(loop);
    return result;
}

/* Renders (or finds on disk) every reference image the plan needs, before any configuration runs, so their
 * time is apart from the configurations'. Returns false on a failure or an interruption. */
static bool prepare_references(const report_context *ctx, const srv_cli_cameras *cams, srv_refcache *refs,
                               uint32_t viewers, bool progress)
{
    const report_options *o = ctx->o;
    uint32_t planned = 0, done = 0;
    for (uint32_t f = 0; f < o->view.frames; f++)
        if (frame_compared(o, f))
            for (uint32_t v = 0; v < viewers; v++) {
                srv_camera cam;
                uint32_t w, h;
                planned += srv_cli_cameras_get(cams, ctx->s, f, v, &cam, &w, &h);
            }
    double start = now_s();
    for (uint32_t f = 0; f < o->view.frames; f++) {
        if (!frame_compared(o, f))
            continue;
        for (uint32_t v = 0; v < viewers; v++) {
            if (stop_requested)
                return false;
            srv_camera cam;
            uint32_t w, h;
            if (!srv_cli_cameras_get(cams, ctx->s, f, v, &cam, &w, &h))
                continue;
            char err[512];
            bool rendered = false;
            if (!srv_refcache_get(refs, &cam, w, h, &rendered, err, sizeof err)) {
                fprintf(stderr, "fxcache report: %s\n", err);
                return false;
            }
            done++;
            if (progress)
                fprintf(stderr, "\r  references %u/%u (frame %u, viewer %u)   ", done, planned, f, v);
        }
    }
    if (progress)
        fputs("\r\033[K", stderr);
    uint32_t rendered = 0, read = 0;
    double render_ms = 0;
    srv_refcache_counts(refs, &rendered, &read, &render_ms);
    fprintf(stderr, "report: references: %u rendered (%.1f s of rendering), %u read from %s/ref, in %.1f s\n",
            rendered, render_ms / 1000.0, read, o->out_dir, now_s() - start);
    return true;
}

/* Writes the CSVs, plots, HTML and summary from the plan's rows. */
static bool write_outputs(report_plan *plan, const report_options *o, const char *title, const char *command,
                          const char *settings, bool interrupted, bool *plots_made)
{
    size_t n = plan->count;
    srv_rep_row *rows = malloc((n ? n : 1) * sizeof *rows);
    if (!rows)
        return false;
    for (size_t i = 0; i < n; i++) {
        rows[i] = plan->configs[i].row;
        if (o->time_cpu && rows[i].done) { /* the chosen time in ms_per_frame, for everything below the CSV */
            rows[i].ms_per_viewer =
                rows[i].ms_per_frame > 0
                    ? rows[i].cpu_ms_per_frame * rows[i].ms_per_viewer / rows[i].ms_per_frame
                    : NAN;
            rows[i].ms_per_frame = rows[i].cpu_ms_per_frame;
        }
    }
    const char *time_label = o->time_cpu ? "process CPU time of the frame, less the sink"
                                         : "engine elapsed frame time, sinks stage excluded";
    /* The Pareto front per viewer count. */
    double t[REPORT_MAX_CONFIGS], e[REPORT_MAX_CONFIGS];
    bool front[REPORT_MAX_CONFIGS];
    for (size_t i = 0; i < n; i++) {
        for (size_t j = 0; j < n; j++) {
            bool same = rows[j].done && rows[j].viewers == rows[i].viewers;
            t[j] = same ? rows[j].ms_per_frame : NAN;
            e[j] = same ? rows[j].rmse : NAN;
        }
        srv_rep_pareto(t, e, n, front);
        rows[i].pareto = rows[i].done && front[i];
    }
    for (size_t i = 0; i < n; i++)
        plan->configs[i].row.pareto = rows[i].pareto;
    char path[1400], err[1400];
    bool ok = true;
    snprintf(path, sizeof path, "%s/configs.csv", o->out_dir);
    srv_rep_row *measured = malloc((n ? n : 1) * sizeof *measured); /* both times as measured */
    if (!measured) {
        free(rows);
        return false;
    }
    for (size_t i = 0; i < n; i++) {
        measured[i] = plan->configs[i].row;
        measured[i].pareto = rows[i].pareto;
    }
    bool csv_ok = srv_rep_write_csv(path, measured, n, err, sizeof err);
    free(measured);
    if (!csv_ok) {
        fprintf(stderr, "fxcache report: %s\n", err);
        ok = false;
    }
    snprintf(path, sizeof path, "%s/frames.csv", o->out_dir);
    if (ok && !srv_rep_write_frames_csv(path, rows, n, err, sizeof err)) {
        fprintf(stderr, "fxcache report: %s\n", err);
        ok = false;
    }
    if (ok && plots_made) {
        int plots = srv_rep_plots(o->out_dir, rows, n, time_label, err, sizeof err);
        if (plots == -2) { /* a file that cannot be written fails the report, as the CSVs do */
            fprintf(stderr, "fxcache report: %s\n", err);
            ok = false;
        } else if (plots < 0) {
            fprintf(stderr, "fxcache report: warning: no plots: %s\n", err);
        }
        *plots_made = plots > 0;
    }
    srv_rep_page page = {.title = title,
                         .command = command,
                         .settings = settings,
                         .time_label = time_label,
                         .plots = plots_made && *plots_made,
                         .interrupted = interrupted,
                         .planned = (uint32_t)n};
    if (ok && !srv_rep_write_html(o->out_dir, rows, n, &page, err, sizeof err)) {
        fprintf(stderr, "fxcache report: %s\n", err);
        ok = false;
    }
    /* summary.json: the equal-time comparison. */
    srv_rep_equal eq[SRV_REP_MAX_VIEWER_COUNTS];
    size_t m = srv_rep_equal_times(rows, n, eq, SRV_REP_MAX_VIEWER_COUNTS);
    json_t *sum = json_object(), *list = json_array();
    for (size_t k = 0; k < m; k++)
        json_array_append_new(
            list, json_pack("{s:I,s:s,s:f,s:f,s:o,s:I,s:s,s:o,s:b}", "viewers", (json_int_t)eq[k].viewers,
                            "cached", eq[k].cached->id, "cached_rmse", eq[k].cached_rmse,
                            "cached_ms_per_frame", eq[k].cached_ms, "no_cache_rmse_at_equal_time",
                            isfinite(eq[k].no_cache_rmse) ? json_real(eq[k].no_cache_rmse) : json_null(),
                            "no_cache_points", (json_int_t)eq[k].no_cache_points, "within_no_cache_range",
                            eq[k].where < 0   ? "below (cache faster than every no-cache point)"
                            : eq[k].where > 0 ? "above (cache slower than every no-cache point)"
                                              : "yes",
                            "ratio", isfinite(eq[k].ratio) ? json_real(eq[k].ratio) : json_null(), "goal_met",
                            eq[k].goal_met));
    for (size_t k = 0; k < m; k++) {
        json_t *item = json_array_get(list, k);
        json_object_set_new(item, "cached_rmse_shadow",
                            isfinite(eq[k].cached_shadow) ? json_real(eq[k].cached_shadow) : json_null());
        json_object_set_new(item, "no_cache_rmse_shadow_at_equal_time",
                            isfinite(eq[k].no_cache_shadow) ? json_real(eq[k].no_cache_shadow) : json_null());
        if (eq[k].best)
            json_object_set_new(item, "most_exact_cached",
                                json_pack("{s:s,s:f,s:f,s:o}", "config", eq[k].best->id, "rmse",
                                          eq[k].best->rmse, "ms_per_frame", eq[k].best->ms_per_frame,
                                          "no_cache_rmse_at_equal_time",
                                          isfinite(eq[k].no_cache_at_best) ? json_real(eq[k].no_cache_at_best)
                                                                           : json_null()));
    }
    json_object_set_new(sum, "goal",
                        json_string("cached RMSE at most half the no-cache RMSE at equal time per frame"));
    json_object_set_new(sum, "equal_time", list);
    /* The configurations whose pools ran out: their errors are of degraded frames (counted, not hidden). */
    json_t *degraded = json_array();
    for (size_t i = 0; i < n; i++)
        if (rows[i].done && rows[i].pool_exhausted)
            json_array_append_new(degraded, json_pack("{s:s,s:I,s:I}", "config", rows[i].id, "pool_exhausted",
                                                      (json_int_t)rows[i].pool_exhausted, "pixels_missing",
                                                      (json_int_t)rows[i].pixels_missing));
    size_t degraded_count = json_array_size(degraded);
    json_object_set_new(sum, "degraded", degraded);
    json_object_set_new(sum, "interrupted", json_boolean(interrupted));
    json_object_set_new(sum, "time", json_string(time_label));
    snprintf(path, sizeof path, "%s/summary.json", o->out_dir);
    if (ok && !srv_cli_write_json("report", path, sum))
        ok = false;
    json_decref(sum);
    if (ok && plots_made && !o->quiet && !interrupted) { /* the final write only */
        for (size_t k = 0; k < m; k++)
            if (!isfinite(eq[k].no_cache_rmse))
                printf(
                    "equal time, %u viewer%s: cached RMSE %.4g at %.1f ms/frame, not compared: no no-cache "
                    "point has an error above 0\n",
                    eq[k].viewers, eq[k].viewers == 1 ? "" : "s", eq[k].cached_rmse, eq[k].cached_ms);
            else
                printf(
                    "equal time, %u viewer%s: cached RMSE %.4g at %.1f ms/frame, no cache %.4g: ratio %.2f, "
                    "goal (<= "
                    "0.5) %s%s\n",
                    eq[k].viewers, eq[k].viewers == 1 ? "" : "s", eq[k].cached_rmse, eq[k].cached_ms,
                    eq[k].no_cache_rmse, eq[k].ratio, eq[k].goal_met ? "met" : "NOT met",
                    eq[k].where < 0   ? " (cache faster than every no-cache point: compared with the fastest)"
                    : eq[k].where > 0 ? " (cache slower than every no-cache point: compared with the slowest)"
                                      : "");
        if (degraded_count)
            printf("degraded: %zu configuration%s ran out of block pool (--pool-mb): their errors are of "
                   "frames with pixels composed without cached data (summary.json \"degraded\")\n",
                   degraded_count, degraded_count == 1 ? "" : "s");
        printf("report: %s/index.html\n", o->out_dir);
    }
    free(rows);
    return ok;
}

/* ---- the command --------------------------------------------------------------------------------------- */

int srv_cmd_report(int argc, char **argv)
{
    report_options o = {.view = {.viewers = 8,
                                 .width = 320,
                                 .height = 180,
                                 .camera = SRV_CAMGEN_GROUP,
                                 .fps = 30,
                                 .frames_min = 2,
                                 .frames_max = 100000}};
    srv_cli_engine_defaults(&o.engine);
    int rc = srv_report_parse_options(argc, argv, &o);
    if (rc >= 0)
        return rc;
    double started = now_s();
    srv_cli_cameras cams = {0};
    scene *s = NULL;
    scene_rt *rt = NULL;
    srv_ref *ref = NULL;
    srv_refcache *refs = NULL;
    report_plan *plan = calloc(1, sizeof *plan);
    json_t *left_out_extra = json_object();
    int exit_code = 1;
    int lock = -1; /* the output folder's lock (srv_cli_lock_dir) */
    char err[512];
    if (!plan) {
        fprintf(stderr, "fxcache report: out of memory\n");
        goto done;
    }
    if (!srv_cli_cameras_load("report", &cams, &o.view, o.engine.seed))
        goto done;
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    s = srv_cli_load_scene("report", o.engine.scene_path, (float)o.engine.density);
    if (stop_requested) {
        exit_code = srv_cli_interrupted("report", stop_requested, "while loading the scene");
        goto done;
    }
    if (!s || !srv_cli_cameras_check("report", &cams, s))
        goto done;
    scene_error serr = {0};
    rt = scene_rt_create(s, NULL, &serr);
    if (!rt) {
        fprintf(stderr, "fxcache report: %s\n", serr.msg);
        goto done;
    }
    bool effect_on[SRV_MAX_EFFECTS] = {false};
    char reasons[SRV_MAX_EFFECTS][200];
    if (!srv_cli_choose_effects("report", s, o.engine.effects, effect_on, reasons, left_out_extra)) {
        exit_code = 2;
        goto done;
    }
    uint32_t effect_count = 0;
    const fx_effect *const *effects = fx_registry(&effect_count);
    report_context ctx = {.o = &o, .s = s, .default_cell = srv_probe_cell_default(s)};
    ctx.shadow_index = fx_find(effects, effect_count, "shadow");
    ctx.ao_index = fx_find(effects, effect_count, "ao");
    int32_t probes = fx_find(effects, effect_count, "probes");
    if (ctx.shadow_index >= 0 && !effect_on[ctx.shadow_index])
        ctx.shadow_index = -1;
    if (ctx.ao_index >= 0 && !effect_on[ctx.ao_index])
        ctx.ao_index = -1;
    ctx.probes_on = probes >= 0 && effect_on[probes];

    /* The reference renderer: the same terms as the frames, its samples scaled by --ref-samples. */
    srv_ref_desc rdesc = {.s = s, .rt = rt, .seed = o.engine.seed, .threads = o.engine.threads};
    memcpy(rdesc.effect_on, effect_on, sizeof rdesc.effect_on);
    char effects_text[256] = "", samples_text[256] = "";
    for (uint32_t e = 0; e < effect_count; e++)
        if (effect_on[e] && effects[e]->reference) {
            rdesc.samples[e] = (uint32_t)lround(effects[e]->reference_samples * o.ref_samples);
            size_t used = strlen(effects_text), used2 = strlen(samples_text);
            snprintf(effects_text + used, sizeof effects_text - used, "%s%s", used ? "," : "",
                     effects[e]->name);
            snprintf(samples_text + used2, sizeof samples_text - used2, "%s%s %u %s", used2 ? ", " : "",
                     effects[e]->name, rdesc.samples[e],
                     effects[e]->reference_unit ? effects[e]->reference_unit : "");
        }
    if (srv_ref_create(&rdesc, &ref, err, sizeof err) != FXC_OK) {
        fprintf(stderr, "fxcache report: %s\n", err);
        goto done;
    }
    if (!srv_cli_make_dir("report", o.out_dir) || (lock = srv_cli_lock_dir("report", o.out_dir)) < 0)
        goto done;
    char sub[1400];
    const char *subdirs[] = {"done", "heatmaps", "frames", "plots"};
    for (size_t i = 0; i < sizeof subdirs / sizeof subdirs[0]; i++) {
        snprintf(sub, sizeof sub, "%s/%s", o.out_dir, subdirs[i]);
        if (!srv_cli_make_dir("report", sub))
            goto done;
    }
    char ref_settings[1024];
    snprintf(ref_settings, sizeof ref_settings, "scene %s content %016llx|effects %s|samples %s|seed %u",
             s->source, (unsigned long long)content_fingerprint(s, &cams, o.view.frames), effects_text,
             samples_text, o.engine.seed);
    snprintf(sub, sizeof sub, "%s/ref", o.out_dir);
    refs = srv_refcache_create(ref, sub, ref_settings, err, sizeof err);
    if (!refs) {
        fprintf(stderr, "fxcache report: %s\n", err);
        goto done;
    }

    /* The plan, and what earlier runs finished. */
    char cameras_text[600] = "";
    if (o.view.trace_count) {
        for (uint32_t i = 0; i < o.view.trace_count; i++) {
            size_t used = strlen(cameras_text);
            snprintf(cameras_text + used, sizeof cameras_text - used, "%s%s", i ? "," : "traces ",
                     o.view.traces[i]);
        }
    } else {
        snprintf(cameras_text, sizeof cameras_text, "%s, %u viewers", srv_camgen_name(o.view.camera),
                 o.view.viewers);
    }
    snprintf(ctx.run_key, sizeof ctx.run_key, "%s|%s|%ux%u|frames %u warmup %u every %u|fps %g|cameras %s",
             ref_settings, o.quick ? "quick" : "full", o.view.width, o.view.height, o.view.frames, o.warmup,
             o.every, o.view.fps, cameras_text);
    srv_report_build_plan(plan, &ctx);
    uint32_t most_viewers = 1;
    size_t pending = 0;
    for (size_t i = 0; i < plan->count; i++) {
        if (load_marker(o.out_dir, &plan->configs[i]))
            continue;
        pending++;
        if (plan->configs[i].row.viewers > most_viewers)
            most_viewers = plan->configs[i].row.viewers;
    }
    bool progress = isatty(STDERR_FILENO);
    fprintf(stderr,
            "report: %zu configurations on %s (%s), %ux%u, %u frames (warm-up %u, every %u compared); %zu "
            "done earlier, %zu to run\n",
            plan->count, s->source, cameras_text, o.view.width, o.view.height, o.view.frames, o.warmup,
            o.every, plan->count - pending, pending);
    bool interrupted = false;
    if (pending && !prepare_references(&ctx, &cams, refs, most_viewers, progress)) {
        if (!stop_requested)
            goto done;
        interrupted = true;
    }
    for (size_t i = 0; i < plan->count && !interrupted; i++) {
        report_config *c = &plan->configs[i];
        if (c->row.done) {
            fprintf(stderr, "report: [%zu/%zu] %s: done earlier (%s/done/%s.json)\n", i + 1, plan->count,
                    c->row.id, o.out_dir, c->row.id);
            continue;
        }
        int r = run_config(c, &ctx, &cams, rt, effect_on, refs, progress, i, plan->count);
        if (r < 0)
            goto done;
        if (r == 0) {
            interrupted = true;
            break;
        }
        if (!write_marker(o.out_dir, c))
            goto done;
        const srv_rep_row *row = &c->row;
        char ao_text[48] = "";
        if (isfinite(row->rmse_ao))
            snprintf(ao_text, sizeof ao_text, ", AO %.3g", row->rmse_ao);
        char per_viewer[48] = "no viewer present"; /* after the warm-up (a trace ended before it) */
        if (isfinite(row->ms_per_viewer))
            snprintf(per_viewer, sizeof per_viewer, "%.1f per viewer", row->ms_per_viewer);
        char degraded[200] = "";
        degraded_text(row, degraded, sizeof degraded);
        if (row->images ==
            0) /* every viewer had left (traces shorter than --frames) before a compared frame */
            fprintf(stderr,
                    "report: [%zu/%zu] %s: %.1f ms/frame (%s, CPU %.1f), no error: no frame "
                    "after the warm-up was compared with a viewer present (the traces end before it; lower "
                    "--frames or --warmup)%s (%.1f s)\n",
                    i + 1, plan->count, row->id, row->ms_per_frame, per_viewer, row->cpu_ms_per_frame,
                    degraded, row->run_s);
        else
            fprintf(stderr,
                    "report: [%zu/%zu] %s: %.1f ms/frame (%s, CPU %.1f), RMSE %.4g, PSNR %.2f dB, "
                    "shadow %.3g%s%s (%.1f s)\n",
                    i + 1, plan->count, row->id, row->ms_per_frame, per_viewer, row->cpu_ms_per_frame,
                    row->rmse, row->psnr_db, row->rmse_shadow, ao_text, degraded, row->run_s);
        if (!write_outputs(plan, &o, NULL, NULL, NULL, false, NULL)) /* the CSVs after every configuration */
            goto done;
    }

    /* Everything from the rows: CSVs, plots, page, summary. */
    char title[1200], settings[1600], command[4096] = "fxcache";
    snprintf(title, sizeof title, "Scene %s; cameras %s; effects %s.", s->source, cameras_text, effects_text);
    snprintf(
        settings, sizeof settings,
        "%ux%u pixels, %u frames per configuration, the first %u the warm-up (compared, not in the figures), "
        "frames 0, %u, %u, ... and the last compared. References: %s, seed %u, rendered once per camera "
        "under "
        "ref/. Threads: %u (0: all cores). %s",
        o.view.width, o.view.height, o.view.frames, o.warmup, o.every, 2 * o.every, samples_text,
        o.engine.seed, o.engine.threads,
        ctx.probes_on ? "AO error is not reported: the probes replace the sky term, so the "
                        "frames' AO view is not the AO term."
                      : "");
    for (int i = 0; i < argc; i++) { /* argv[0] is "report" */
        size_t used = strlen(command);
        snprintf(command + used, sizeof command - used, " %s", argv[i]);
    }
    interrupted = interrupted || stop_requested;
    bool plots = true;
    if (!write_outputs(plan, &o, title, command, settings, interrupted, &plots))
        goto done;
    if (interrupted) {
        size_t finished = 0;
        for (size_t i = 0; i < plan->count; i++)
            finished += plan->configs[i].row.done;
        fprintf(stderr,
                "fxcache report: interrupted by %s: %zu of %zu configurations done and written; run the same "
                "command again to resume\n",
                stop_requested == SIGINT ? "SIGINT" : "SIGTERM", finished, plan->count);
    } else {
        fprintf(stderr, "report: done in %.1f s\n", now_s() - started);
    }
    exit_code = 0;
done:
    if (plan)
        for (size_t i = 0; i < plan->count; i++)
            srv_rep_row_free_images(&plan->configs[i].row);
    free(plan);
    srv_refcache_free(refs);
    srv_ref_free(ref);
    scene_rt_free(rt);
    scene_free(s);
    json_decref(left_out_extra);
    srv_cli_cameras_free(&cams);
    srv_cli_unlock_dir(lock);
    return exit_code;
}
