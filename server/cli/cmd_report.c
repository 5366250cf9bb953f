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

enum { MAX_CONFIGS = 96 };

static volatile sig_atomic_t stop_requested = 0;

/* The first signal asks for the end after the current frame; the second ends at once (default action). */
static void on_signal(int sig)
{
    stop_requested = sig;
    signal(sig, SIG_DFL);
}

/* The sweep families, in the order they run (--only picks some). */
static const char *const family_names[] = {"default",    "bias",       "ao_samples", "shadow_rays", "probe_cell",
                                           "probe_rays", "ray_budget", "viewers",    "no_cache"};
enum { FAMILIES = sizeof family_names / sizeof family_names[0] };

typedef struct report_options {
    srv_cli_engine engine; /* the base settings every configuration starts from */
    srv_cli_view_options view; /* --viewers, --frames, --res, --camera, --trace, --fps */
    uint32_t warmup, every;
    bool warmup_set, every_set;
    const char *out_dir;
    bool quick, quiet;
    double ref_samples; /* scale of the reference's default samples (0: 1, or 1/4 with --quick) */
    bool only[FAMILIES];
    bool only_set;
    double heatmap_max;
    bool time_cpu; /* plots, front and comparison on process CPU time instead of the elapsed frame time */
} report_options;

static const char report_usage[] =
    "usage: fxcache report --out DIR [options]\n"
    "\n"
    "Error against run time: sweeps of the engine's settings on one scene and one set of cameras, each\n"
    "configuration a run of the engine. For every configuration: time per frame (the engine's frame time,\n"
    "as sim's statistics have it, without the sinks stage; mean over the frames after the warm-up, per frame\n"
    "and per viewer) and the error of its frames against reference images of the same cameras (RMSE and PSNR\n"
    "in linear radiance with peak 1.0, the shadow term, and the AO term where no probes replace the sky).\n"
    "\n"
    "Sweeps (from the base settings given with the engine options below; one viewer unless said):\n"
    "  default      the base settings, the cached renderer\n"
    "  bias         level bias 0..3 of shadow and of ao (each apart)\n"
    "  ao_samples   AO samples a texel converges at: 16, 64, 256\n"
    "  shadow_rays  shadow rays per texel and light: 1, 4, 16\n"
    "  probe_cell   probe spacing: half and twice the default finest cell\n"
    "  probe_rays   rays per probe update: 36, 144, 576\n"
    "  ray_budget   effect rays per frame: 25000, 100000\n"
    "  viewers      the base settings with 2, 4, 8 viewers (the same cameras: the first N viewers)\n"
    "  no_cache     the no-cache baseline at sample scales 1/64, 1/16, 1/4, 1, 4 with one viewer and\n"
    "               1/64, 1/16, 1/4, 1 with the most viewers: the curve the equal-time comparison reads\n"
    "--quick keeps fewer points (bias 2, AO 16 and 256, shadow rays 4, no probe cell, probe rays 36,\n"
    "budget 25000, the viewer counts 1 and the most, no cache at 1/64, 1/16, 1/4 and 1).\n"
    "\n"
    "Cameras (as sim):\n"
    "  --trace FILE         a viewer trace (repeat once per viewer); frame f at time start + f / fps\n"
    "  --fps F              frames per second of trace time, (0, 1000] (default 30)\n"
    "  --camera GEN         generator when no --trace is given (default group):\n"
    "                       %s\n"
    "  --viewers N          the most viewers, 1..64 (default 8, or the number of traces): the generator's\n"
    "                       cameras are those of N viewers, and fewer viewers take the first ones\n"
    "Frames:\n"
    "  --frames F           frames per configuration, 2..100000 (default 60; --quick 30)\n"
    "  --warmup W           frames before the steady state, 0..F-1 (default 10, DESIGN.md's; F/2 when F\n"
    "                       is 10 or less): compared and in frames.csv, not in the configuration's\n"
    "                       figures\n"
    "  --every K            compare frames 0, K, 2K, ... and the last, 1..100000 (default 10; --quick 6);\n"
    "                       the no-cache baseline keeps nothing between frames and renders only those\n"
    "  --res WxH            resolution, sides 1..8192 (default 320x180; --quick 160x90; a version 2\n"
    "                       trace's own resolution wins unless --res is given)\n"
    "References (DIR/ref/, rendered once per camera and resolution, reused by every configuration and a\n"
    "resumed report; their time is in no configuration's):\n"
    "  --ref-samples S      the reference renderer's samples (AO 1024, shadow 256 per light, 256 paths)\n"
    "                       times S, a power of two in [1/8, 4] ('1/4' or '0.25'; default 1; --quick 1/4)\n"
    "Output:\n"
    "  --out DIR            required: configs.csv, frames.csv, plots/, heatmaps/, frames/, ref/, done/,\n"
    "                       summary.json, index.html\n"
    "  --only LIST          only these sweeps (comma list of the names above)\n"
    "  --heatmap-max E      the error shown white in the heat maps, linear radiance (default 0.1)\n"
    "  --time elapsed|cpu   the time the plots, the Pareto front and the equal-time comparison use:\n"
    "                       'elapsed', the engine's frame time less the sinks stage (default), or 'cpu',\n"
    "                       the process CPU time of the frame less the sink's (steadier on a busy machine);\n"
    "                       the CSV has both. A rerun on a finished folder only rewrites the outputs\n"
    "  --quick              the short report (under 5 minutes on the embedded scene here)\n"
    "  --quiet              no summary on stdout\n"
    "Engine options (the base settings; --effects also sets the reference's terms; --no-cache and\n"
    "--no-cache-samples are refused: the no_cache sweep sets them):\n";

/* Parses a power of two given as a decimal or as 1/N, within [lo, hi]. */
static bool parse_power_of_two(const char *option, const char *arg, double lo, double hi, double *out)
{
    double value;
    if (strncmp(arg, "1/", 2) == 0) {
        uint32_t divisor;
        if (!srv_cli_u32("report", option, arg + 2, 1, 1u << 20, &divisor))
            return false;
        value = 1.0 / divisor;
    } else if (!srv_cli_double("report", option, arg, lo, hi, &value)) {
        return false;
    }
    int exponent;
    if (frexp(value, &exponent) != 0.5 || value < lo || value > hi) {
        fprintf(stderr, "fxcache report: %s: '%s' is not a power of two in [%g, %g]\n", option, arg, lo, hi);
        return false;
    }
    *out = value;
    return true;
}

static bool parse_only(const char *arg, report_options *o)
{
    char buf[512];
    snprintf(buf, sizeof buf, "%s", arg);
    bool any = false;
    for (char *save = NULL, *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        int found = -1;
        for (int k = 0; k < FAMILIES; k++)
            if (strcmp(tok, family_names[k]) == 0)
                found = k;
        if (found < 0) {
            fprintf(stderr, "fxcache report: --only: '%s' is not a sweep (default, bias, ao_samples, shadow_rays, "
                            "probe_cell, probe_rays, ray_budget, viewers, no_cache)\n",
                    tok);
            return false;
        }
        o->only[found] = true;
        any = true;
    }
    if (!any) {
        fprintf(stderr, "fxcache report: --only: no sweep named\n");
        return false;
    }
    o->only_set = true;
    return true;
}

static int parse_options(int argc, char **argv, report_options *o)
{
    enum {
        O_WARMUP = SRV_CLI_O_COMMAND,
        O_EVERY,
        O_OUT,
        O_QUICK,
        O_QUIET,
        O_REFS,
        O_ONLY,
        O_HEATMAX,
        O_TIME
    };
    static const struct option own[] = {
        SRV_CLI_VIEW_OPTIONS,
        {"warmup", required_argument, NULL, O_WARMUP},
        {"every", required_argument, NULL, O_EVERY},
        {"out", required_argument, NULL, O_OUT},
        {"quick", no_argument, NULL, O_QUICK},
        {"quiet", no_argument, NULL, O_QUIET},
        {"ref-samples", required_argument, NULL, O_REFS},
        {"only", required_argument, NULL, O_ONLY},
        {"heatmap-max", required_argument, NULL, O_HEATMAX},
        {"time", required_argument, NULL, O_TIME},
        {"help", no_argument, NULL, 'h'},
    };
    struct option options[sizeof own / sizeof own[0] + 40];
    srv_cli_merge_options(own, sizeof own / sizeof own[0], options, sizeof options / sizeof options[0]);
    for (int c; (c = getopt_long(argc, argv, ":h", options, NULL)) != -1;) {
        int known = srv_cli_engine_option("report", c, optarg, &o->engine);
        if (known < 0)
            known = srv_cli_view_option("report", c, optarg, &o->view);
        if (known == 0)
            return 2;
        if (known == 1)
            continue;
        bool ok = true;
        switch (c) {
        case O_WARMUP: ok = srv_cli_u32("report", "--warmup", optarg, 0, 99999, &o->warmup); o->warmup_set = true; break;
        case O_EVERY:
            ok = srv_cli_u32("report", "--every", optarg, 1, 100000, &o->every);
            o->every_set = true;
            break;
        case O_OUT: o->out_dir = srv_cli_dir_arg(optarg); break;
        case O_QUICK: o->quick = true; break;
        case O_QUIET: o->quiet = true; break;
        case O_REFS: ok = parse_power_of_two("--ref-samples", optarg, 0.125, 4, &o->ref_samples); break;
        case O_ONLY: ok = parse_only(optarg, o); break;
        case O_HEATMAX: ok = srv_cli_double("report", "--heatmap-max", optarg, 1e-6, 1e6, &o->heatmap_max); break;
        case O_TIME:
            o->time_cpu = strcmp(optarg, "cpu") == 0;
            if (!o->time_cpu && strcmp(optarg, "elapsed") != 0) {
                fprintf(stderr, "fxcache report: --time: '%s' is not elapsed or cpu\n", optarg);
                ok = false;
            }
            break;
        case 'h': {
            char names[256];
            srv_cli_effect_names(names, sizeof names);
            printf(report_usage, srv_camgen_list());
            printf(srv_cli_engine_usage, names);
            printf("  -h, --help           this text\n"
                   "\n"
                   "Progress: a line per configuration on stderr (a status line too on a terminal). SIGINT or\n"
                   "SIGTERM: stops after the current frame with every finished configuration written; run the same\n"
                   "command again to resume. Where a 'flip' executable (NVIDIA's FLIP) is on PATH, a FLIP column\n"
                   "is added. Exit status: 0 done or interrupted, 1 a failure, 2 bad options.\n");
            return 0;
        }
        default: return srv_cli_getopt_error("report", c, argv);
        }
        if (!ok)
            return 2;
    }
    if (!srv_cli_no_operands("report", argc, argv))
        return 2;
    if (!o->out_dir) {
        fprintf(stderr, "fxcache report: --out DIR is required (where the report goes)\n");
        return 2;
    }
    if (!srv_cli_view_check("report", &o->view))
        return 2;
    if (o->engine.no_cache) {
        fprintf(stderr, "fxcache report: --no-cache is a sweep of the report (no_cache), not a base setting\n");
        return 2;
    }
    if (o->engine.no_cache_samples > 0) {
        fprintf(stderr, "fxcache report: --no-cache-samples: the no_cache sweep sets the baseline's samples\n");
        return 2;
    }
    /* --quick's defaults, where the option was not given. */
    if (!o->view.frames_set)
        o->view.frames = o->quick ? 30 : 60;
    if (!o->every_set)
        o->every = o->quick ? 6 : 10;
    if (!o->view.res_set && o->quick)
        o->view.width = 160, o->view.height = 90;
    if (!(o->ref_samples > 0))
        o->ref_samples = o->quick ? 0.25 : 1.0;
    if (!o->warmup_set)
        o->warmup = o->view.frames > 10 ? 10 : o->view.frames / 2;
    if (o->warmup >= o->view.frames) {
        fprintf(stderr, "fxcache report: --warmup %u must be below --frames %u\n", o->warmup, o->view.frames);
        return 2;
    }
    if (o->view.trace_count)
        o->view.viewers = o->view.trace_count;
    return -1;
}

/* ---- configurations ------------------------------------------------------------------------------------ */

/* One configuration: its row and the engine settings it runs with. */
typedef struct report_config {
    srv_rep_row row;
    srv_cli_engine engine;
    char key[1400]; /* everything that decides its results: a marker with another key is redone */
} report_config;

typedef struct report_plan {
    report_config configs[MAX_CONFIGS];
    size_t count;
} report_plan;

typedef struct report_context {
    const report_options *o;
    const scene *s;
    int32_t shadow_index, ao_index; /* in the registry, -1 when absent or not running */
    bool probes_on;
    double default_cell;
    char run_key[900]; /* what every configuration shares */
} report_context;

/* Adds a configuration derived from the base settings; `apply` edits its engine settings. */
static report_config *add_config(report_plan *plan, const report_context *ctx, const char *family, const char *id,
                                 const char *label, uint32_t viewers)
{
    if (plan->count == MAX_CONFIGS)
        return NULL;
    report_config *c = &plan->configs[plan->count++];
    memset(c, 0, sizeof *c);
    c->engine = ctx->o->engine;
    snprintf(c->row.family, sizeof c->row.family, "%s", family);
    snprintf(c->row.id, sizeof c->row.id, "%s_v%u", id, viewers);
    snprintf(c->row.label, sizeof c->row.label, "%s, %u viewer%s", label, viewers, viewers == 1 ? "" : "s");
    c->row.viewers = viewers;
    return c;
}

/* Fills a configuration's row settings from its engine settings, and its key. */
static void finish_config(report_config *c, const report_context *ctx)
{
    srv_rep_row *r = &c->row;
    const srv_cli_engine *e = &c->engine;
    uint32_t count = 0;
    const fx_effect *const *effects = fx_registry(&count);
    r->no_cache = e->no_cache;
    r->no_cache_samples = e->no_cache ? (e->no_cache_samples > 0 ? e->no_cache_samples : 1.0) : 1.0;
    r->bias_shadow = ctx->shadow_index < 0 ? 0
                     : e->bias_set[ctx->shadow_index] ? e->bias[ctx->shadow_index]
                                                      : effects[ctx->shadow_index]->level_bias;
    r->bias_ao = ctx->ao_index < 0 ? 0 : e->bias_set[ctx->ao_index] ? e->bias[ctx->ao_index] : effects[ctx->ao_index]->level_bias;
    r->ao_samples = e->ao_samples ? e->ao_samples : FX_AO_MAX_SAMPLES;
    r->shadow_rays = e->shadow_rays ? e->shadow_rays : FX_SHADOW_RAYS;
    r->probe_rays = e->probe_rays ? e->probe_rays : FX_PROBE_RAYS;
    r->probe_cell = ctx->probes_on ? (e->probe_cell > 0 ? e->probe_cell : ctx->default_cell) : NAN;
    r->ray_budget = e->ray_budget;
    snprintf(c->key, sizeof c->key,
             "%s|viewers %u|no_cache %d x%g|bias %d %d|ao %u|shadow %u|probe rays %u cell %g hyst %g budget %u|"
             "ray budget %g|pool %g|ao step %u|density %g|local %d",
             ctx->run_key, r->viewers, r->no_cache, r->no_cache_samples, r->bias_shadow, r->bias_ao, r->ao_samples,
             r->shadow_rays, r->probe_rays, r->probe_cell, e->probe_hysteresis, e->probe_budget, r->ray_budget,
             e->pool_mb, e->ao_step, e->density, !e->no_local_table);
}

/* The viewer counts of the viewers sweep: 1, 2, 4, 8 up to the most, and the most. */
static uint32_t viewer_steps(uint32_t most, bool quick, uint32_t out[8])
{
    uint32_t n = 0;
    if (quick) {
        out[n++] = 1;
        if (most > 1)
            out[n++] = most;
        return n;
    }
    for (uint32_t v = 1; v <= most && v <= 8; v *= 2)
        out[n++] = v;
    if (out[n - 1] != most)
        out[n++] = most;
    return n;
}

/* Builds the plan: every sweep the options ask for, in family order. */
static void build_plan(report_plan *plan, const report_context *ctx)
{
    const report_options *o = ctx->o;
    bool quick = o->quick;
    char id[64], label[96];
    report_config *c;
#define WANT(k) (!o->only_set || o->only[k])
    if (WANT(0))
        add_config(plan, ctx, "default", "default", "default", 1);
    if (WANT(1)) {
        static const int32_t levels_quick[] = {2}, levels[] = {0, 1, 2, 3};
        const int32_t *list = quick ? levels_quick : levels;
        size_t count = quick ? 1 : 4;
        const struct {
            int32_t index;
            const char *name;
        } effects[2] = {{ctx->shadow_index, "shadow"}, {ctx->ao_index, "ao"}};
        for (int k = 0; k < 2; k++) {
            if (effects[k].index < 0)
                continue;
            uint32_t registered = 0;
            int32_t base = o->engine.bias_set[effects[k].index] ? o->engine.bias[effects[k].index]
                                                                 : fx_registry(&registered)[effects[k].index]->level_bias;
            for (size_t i = 0; i < count; i++) {
                if (list[i] == base)
                    continue; /* that is the default configuration */
                snprintf(id, sizeof id, "bias_%s_%d", effects[k].name, list[i]);
                snprintf(label, sizeof label, "%s bias %d", effects[k].name, list[i]);
                if ((c = add_config(plan, ctx, "bias", id, label, 1))) {
                    c->engine.bias[effects[k].index] = list[i];
                    c->engine.bias_set[effects[k].index] = true;
                }
            }
        }
    }
    if (WANT(2) && ctx->ao_index >= 0) {
        static const uint32_t counts[] = {16, 256};
        for (size_t i = 0; i < 2; i++) {
            snprintf(id, sizeof id, "ao_samples_%u", counts[i]);
            snprintf(label, sizeof label, "AO %u samples", counts[i]);
            if ((c = add_config(plan, ctx, "ao_samples", id, label, 1)))
                c->engine.ao_samples = counts[i];
        }
    }
    if (WANT(3) && ctx->shadow_index >= 0) {
        static const uint32_t counts[] = {4, 1};
        for (size_t i = 0; i < (quick ? 1u : 2u); i++) {
            snprintf(id, sizeof id, "shadow_rays_%u", counts[i]);
            snprintf(label, sizeof label, "%u shadow rays", counts[i]);
            if ((c = add_config(plan, ctx, "shadow_rays", id, label, 1)))
                c->engine.shadow_rays = counts[i];
        }
    }
    if (WANT(4) && ctx->probes_on && !quick) {
        static const double factors[] = {0.5, 2.0};
        for (size_t i = 0; i < 2; i++) {
            snprintf(id, sizeof id, "probe_cell_x%g", factors[i]);
            snprintf(label, sizeof label, "probe cell %g m", ctx->default_cell * factors[i]);
            if ((c = add_config(plan, ctx, "probe_cell", id, label, 1)))
                c->engine.probe_cell = ctx->default_cell * factors[i];
        }
    }
    if (WANT(5) && ctx->probes_on) {
        static const uint32_t counts[] = {36, 576};
        for (size_t i = 0; i < (quick ? 1u : 2u); i++) {
            snprintf(id, sizeof id, "probe_rays_%u", counts[i]);
            snprintf(label, sizeof label, "%u rays per probe", counts[i]);
            if ((c = add_config(plan, ctx, "probe_rays", id, label, 1)))
                c->engine.probe_rays = counts[i];
        }
    }
    if (WANT(6)) {
        static const double budgets[] = {25000, 100000};
        for (size_t i = 0; i < (quick ? 1u : 2u); i++) {
            snprintf(id, sizeof id, "ray_budget_%.0f", budgets[i]);
            snprintf(label, sizeof label, "ray budget %.0f", budgets[i]);
            if ((c = add_config(plan, ctx, "ray_budget", id, label, 1)))
                c->engine.ray_budget = budgets[i];
        }
    }
    uint32_t steps[8];
    uint32_t nsteps = viewer_steps(o->view.viewers, quick, steps);
    if (WANT(7))
        for (uint32_t i = 0; i < nsteps; i++)
            if (steps[i] > 1)
                add_config(plan, ctx, "viewers", "default", "default", steps[i]);
    if (WANT(8)) {
        static const double scales[] = {1.0 / 64, 1.0 / 16, 0.25, 1, 4};
        for (uint32_t v = 0; v < 2; v++) {
            uint32_t viewers = v == 0 ? 1 : o->view.viewers;
            if (v == 1 && viewers == 1)
                break;
            size_t count = (quick || v == 1) ? 4 : 5;
            for (size_t i = 0; i < count; i++) {
                char scale[16];
                if (scales[i] < 1)
                    snprintf(scale, sizeof scale, "1/%g", 1 / scales[i]);
                else
                    snprintf(scale, sizeof scale, "%g", scales[i]);
                snprintf(id, sizeof id, "no_cache_x%g", scales[i]);
                snprintf(label, sizeof label, "no cache x%s", scale);
                if ((c = add_config(plan, ctx, "no_cache", id, label, viewers))) {
                    c->engine.no_cache = true;
                    c->engine.no_cache_samples = scales[i];
                }
            }
        }
    }
#undef WANT
    for (size_t i = 0; i < plan->count; i++)
        finish_config(&plan->configs[i], ctx);
}

/* ---- cameras ------------------------------------------------------------------------------------------- */

static bool frame_compared(const report_options *o, uint32_t frame)
{
    return frame == o->view.frames - 1 || frame % o->every == 0;
}

/* ---- files --------------------------------------------------------------------------------------------- */

static bool make_dir(const char *path)
{
    if (mkdir(path, 0755) == 0 || errno == EEXIST)
        return true;
    fprintf(stderr, "fxcache report: cannot create folder %s: %s\n", path, strerror(errno));
    return false;
}

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
    bool ok = key && strcmp(key, c->key) == 0 && srv_rep_row_from_json(&c->row, json_object_get(marker, "row"));
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
    bool ok = marker && json_dump_file(marker, tmp, JSON_INDENT(1) | JSON_PRESERVE_ORDER) == 0 && rename(tmp, path) == 0;
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
    srv_rep_image image = {.frame = im->frame, .steady = im->steady, .rmse = im->rmse, .psnr_db = im->psnr_db,
                           .rmse_shadow = im->rmse_shadow, .rmse_ao = im->rmse_ao};
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
    double start = now_s();
    srv_loop_desc desc = {.s = ctx->s, .rt = rt, .pool_bytes = (uint64_t)(e->pool_mb * 1048576.0),
                          .ray_budget = (uint64_t)e->ray_budget, .samples_per_update = e->ao_step,
                          .no_cache = e->no_cache, .seed = e->seed, .threads = e->threads, .keep_views = true,
                          .probe_cell = (float)e->probe_cell, .probe_rays = e->probe_rays,
                          .probe_hysteresis = (float)e->probe_hysteresis, .probe_budget = e->probe_budget,
                          .indirect_block = e->indirect_block, .no_local_table = e->no_local_table, .ao_samples = e->ao_samples,
                          .shadow_rays = e->shadow_rays, .no_cache_samples = (float)e->no_cache_samples};
    memcpy(desc.effect_on, effect_on, sizeof desc.effect_on);
    memcpy(desc.bias, e->bias, sizeof desc.bias);
    memcpy(desc.bias_set, e->bias_set, sizeof desc.bias_set);
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
                fprintf(stderr, "fxcache report: %s: frame %u, viewer %u: a degenerate camera\n", row->id, frame, v);
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
        double mse = t->images ? t->mse_sum / t->images : NAN, noise2 = t->images ? t->noise2_sum / t->images : NAN;
        row->rmse = sqrt(mse);
        row->psnr_db = srv_err_psnr(row->rmse);
        row->rmse_denoised = sqrt(fmax(0.0, mse - noise2));
        row->rmse_shadow = t->images && errors.desc.compare_shadow ? sqrt(t->mse_shadow_sum / t->images) : NAN;
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
            rows[i].ms_per_viewer = rows[i].ms_per_frame > 0
                                        ? rows[i].cpu_ms_per_frame * rows[i].ms_per_viewer / rows[i].ms_per_frame
                                        : NAN;
            rows[i].ms_per_frame = rows[i].cpu_ms_per_frame;
        }
    }
    const char *time_label = o->time_cpu ? "process CPU time of the frame, less the sink"
                                         : "engine elapsed frame time, sinks stage excluded";
    /* The Pareto front per viewer count. */
    double t[MAX_CONFIGS], e[MAX_CONFIGS];
    bool front[MAX_CONFIGS];
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
        if (plots < 0)
            fprintf(stderr, "fxcache report: warning: no plots: %s\n", err);
        *plots_made = plots > 0;
    }
    srv_rep_page page = {.title = title, .command = command, .settings = settings, .time_label = time_label,
                         .plots = plots_made && *plots_made, .interrupted = interrupted, .planned = (uint32_t)n};
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
            list, json_pack("{s:I,s:s,s:f,s:f,s:o,s:I,s:s,s:o,s:b}", "viewers", (json_int_t)eq[k].viewers, "cached",
                            eq[k].cached->id, "cached_rmse", eq[k].cached_rmse, "cached_ms_per_frame", eq[k].cached_ms,
                            "no_cache_rmse_at_equal_time",
                            isfinite(eq[k].no_cache_rmse) ? json_real(eq[k].no_cache_rmse) : json_null(),
                            "no_cache_points", (json_int_t)eq[k].no_cache_points, "within_no_cache_range",
                            eq[k].where < 0 ? "below (cache faster than every no-cache point)"
                            : eq[k].where > 0 ? "above (cache slower than every no-cache point)"
                                              : "yes",
                            "ratio", isfinite(eq[k].ratio) ? json_real(eq[k].ratio) : json_null(), "goal_met",
                            eq[k].goal_met));
    for (size_t k = 0; k < m; k++) {
        json_t *item = json_array_get(list, k);
        json_object_set_new(item, "cached_rmse_shadow", isfinite(eq[k].cached_shadow) ? json_real(eq[k].cached_shadow) : json_null());
        json_object_set_new(item, "no_cache_rmse_shadow_at_equal_time",
                            isfinite(eq[k].no_cache_shadow) ? json_real(eq[k].no_cache_shadow) : json_null());
        if (eq[k].best)
            json_object_set_new(item, "most_exact_cached",
                                json_pack("{s:s,s:f,s:f,s:o}", "config", eq[k].best->id, "rmse", eq[k].best->rmse,
                                          "ms_per_frame", eq[k].best->ms_per_frame, "no_cache_rmse_at_equal_time",
                                          isfinite(eq[k].no_cache_at_best) ? json_real(eq[k].no_cache_at_best)
                                                                           : json_null()));
    }
    json_object_set_new(sum, "goal", json_string("cached RMSE at most half the no-cache RMSE at equal time per frame"));
    json_object_set_new(sum, "equal_time", list);
    json_object_set_new(sum, "interrupted", json_boolean(interrupted));
    json_object_set_new(sum, "time", json_string(time_label));
    snprintf(path, sizeof path, "%s/summary.json", o->out_dir);
    if (ok && !srv_cli_write_json("report", path, sum))
        ok = false;
    json_decref(sum);
    if (ok && plots_made && !o->quiet && !interrupted) { /* the final write only */
        for (size_t k = 0; k < m; k++)
            printf("equal time, %u viewer%s: cached RMSE %.4g at %.1f ms/frame, no cache %.4g: ratio %.2f, goal (<= "
                   "0.5) %s%s\n",
                   eq[k].viewers, eq[k].viewers == 1 ? "" : "s", eq[k].cached_rmse, eq[k].cached_ms,
                   eq[k].no_cache_rmse, eq[k].ratio, eq[k].goal_met ? "met" : "NOT met",
                   eq[k].where < 0   ? " (cache faster than every no-cache point: compared with the fastest)"
                   : eq[k].where > 0 ? " (cache slower than every no-cache point: compared with the slowest)"
                                     : "");
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
    int rc = parse_options(argc, argv, &o);
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
            snprintf(effects_text + used, sizeof effects_text - used, "%s%s", used ? "," : "", effects[e]->name);
            snprintf(samples_text + used2, sizeof samples_text - used2, "%s%s %u %s", used2 ? ", " : "",
                     effects[e]->name, rdesc.samples[e], effects[e]->reference_unit ? effects[e]->reference_unit : "");
        }
    if (srv_ref_create(&rdesc, &ref, err, sizeof err) != FXC_OK) {
        fprintf(stderr, "fxcache report: %s\n", err);
        goto done;
    }
    if (!make_dir(o.out_dir))
        goto done;
    char sub[1400];
    const char *subdirs[] = {"done", "heatmaps", "frames", "plots"};
    for (size_t i = 0; i < sizeof subdirs / sizeof subdirs[0]; i++) {
        snprintf(sub, sizeof sub, "%s/%s", o.out_dir, subdirs[i]);
        if (!make_dir(sub))
            goto done;
    }
    char ref_settings[1024];
    snprintf(ref_settings, sizeof ref_settings, "scene %s|effects %s|samples %s|seed %u", s->source, effects_text,
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
    build_plan(plan, &ctx);
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
            fprintf(stderr, "report: [%zu/%zu] %s: done earlier (%s/done/%s.json)\n", i + 1, plan->count, c->row.id,
                    o.out_dir, c->row.id);
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
        fprintf(stderr, "report: [%zu/%zu] %s: %.1f ms/frame (%.1f per viewer, CPU %.1f), RMSE %.4g, PSNR %.2f dB, "
                        "shadow %.3g%s (%.1f s)\n",
                i + 1, plan->count, row->id, row->ms_per_frame, row->ms_per_viewer, row->cpu_ms_per_frame, row->rmse,
                row->psnr_db, row->rmse_shadow, ao_text, row->run_s);
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
        fprintf(stderr, "fxcache report: interrupted by %s: %zu of %zu configurations done and written; run the same "
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
    return exit_code;
}
