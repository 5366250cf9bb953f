/* `fxcache report`'s options and plan (report_plan.h). */
#include "report_plan.h"

#include "camgen.h"
#include "cli.h"

#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- options ------------------------------------------------------------------------------------------- */

/* The sweep families, in the order they run (--only picks some). */
static const char *const family_names[] = {"default",     "bias",       "ao_samples",
                                           "shadow_rays", "probe_cell", "probe_rays",
                                           "ray_budget",  "viewers",    "no_cache"};
_Static_assert(sizeof family_names / sizeof family_names[0] == REPORT_FAMILIES, "one name a family");

static const char report_usage[] =
    "usage: fxcache report --out DIR [options]\n"
    "\n"
    "Error against run time: sweeps of the engine's settings on one scene and one set of cameras, each\n"
    "configuration a run of the engine. For every configuration: time per frame (the engine's frame time,\n"
    "as sim's statistics have it, without the sinks stage; mean over the frames after the warm-up, per "
    "frame\n"
    "and per viewer) and the error of its frames against reference images of the same cameras (RMSE and "
    "PSNR\n"
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
    "  --fps F              frames per second of trace time, [0.001, 1000] (default 30)\n"
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
    "                       summary.json, index.html; one report at a time per folder (another run\n"
    "                       writing it is refused, named by its process number)\n"
    "  --only LIST          only these sweeps (comma list of the names above)\n"
    "  --heatmap-max E      the error shown white in the heat maps, linear radiance, [1e-6, 1e6]\n"
    "                       (default 0.1)\n"
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
        for (int k = 0; k < REPORT_FAMILIES; k++)
            if (strcmp(tok, family_names[k]) == 0)
                found = k;
        if (found < 0) {
            fprintf(stderr,
                    "fxcache report: --only: '%s' is not a sweep (default, bias, ao_samples, shadow_rays, "
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

int srv_report_parse_options(int argc, char **argv, report_options *o)
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
        int known = srv_cli_run_option("report", c, optarg, &o->engine, &o->view);
        if (known == 0)
            return 2;
        if (known == 1)
            continue;
        bool ok = true;
        switch (c) {
        case O_WARMUP:
            ok = srv_cli_u32("report", "--warmup", optarg, 0, 99999, &o->warmup);
            o->warmup_set = true;
            break;
        case O_EVERY:
            ok = srv_cli_u32("report", "--every", optarg, 1, 100000, &o->every);
            o->every_set = true;
            break;
        case O_OUT: o->out_dir = srv_cli_dir_arg(optarg); break;
        case O_QUICK: o->quick = true; break;
        case O_QUIET: o->quiet = true; break;
        case O_REFS: ok = parse_power_of_two("--ref-samples", optarg, 0.125, 4, &o->ref_samples); break;
        case O_ONLY: ok = parse_only(optarg, o); break;
        case O_HEATMAX:
            ok = srv_cli_double("report", "--heatmap-max", optarg, 1e-6, 1e6, &o->heatmap_max);
            break;
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
            printf(
                "  -h, --help           this text\n"
                "\n"
                "Progress: a line per configuration on stderr (a status line too on a terminal). SIGINT or\n"
                "SIGTERM: stops after the current frame with every finished configuration written; run the "
                "same\n"
                "command again to resume. Where a 'flip' executable (NVIDIA's FLIP) is on PATH, a FLIP "
                "column\n"
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
        fprintf(stderr,
                "fxcache report: --no-cache is a sweep of the report (no_cache), not a base setting\n");
        return 2;
    }
    if (o->engine.no_cache_samples > 0) {
        fprintf(stderr,
                "fxcache report: --no-cache-samples: the no_cache sweep sets the baseline's samples\n");
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

/* Adds a configuration derived from the base settings; `apply` edits its engine settings. */
static report_config *add_config(report_plan *plan, const report_context *ctx, const char *family,
                                 const char *id, const char *label, uint32_t viewers)
{
    if (plan->count == REPORT_MAX_CONFIGS)
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
    r->bias_shadow = ctx->shadow_index < 0            ? 0
                     : e->bias_set[ctx->shadow_index] ? e->bias[ctx->shadow_index]
                                                      : effects[ctx->shadow_index]->level_bias;
    r->bias_ao = ctx->ao_index < 0            ? 0
                 : e->bias_set[ctx->ao_index] ? e->bias[ctx->ao_index]
                                              : effects[ctx->ao_index]->level_bias;
    r->ao_samples = e->ao_samples ? e->ao_samples : FX_AO_MAX_SAMPLES;
    r->shadow_rays = e->shadow_rays ? e->shadow_rays : FX_SHADOW_RAYS;
    r->probe_rays = e->probe_rays ? e->probe_rays : FX_PROBE_RAYS;
    r->probe_cell = ctx->probes_on ? (e->probe_cell > 0 ? e->probe_cell : ctx->default_cell) : NAN;
    r->ray_budget = e->ray_budget;
    snprintf(
        c->key, sizeof c->key,
        "%s|viewers %u|no_cache %d x%g|bias %d %d|ao %u|shadow %u|probe rays %u cell %g hyst %g budget %u|"
        "ray budget %g|pool %g|ao step %u|density %g|local %d|indirect block %u",
        ctx->run_key, r->viewers, r->no_cache, r->no_cache_samples, r->bias_shadow, r->bias_ao, r->ao_samples,
        r->shadow_rays, r->probe_rays, r->probe_cell, e->probe_hysteresis, e->probe_budget, r->ray_budget,
        e->pool_mb, e->ao_step, e->density, !e->no_local_table, e->indirect_block);
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
void srv_report_build_plan(report_plan *plan, const report_context *ctx)
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
            int32_t base = o->engine.bias_set[effects[k].index]
                               ? o->engine.bias[effects[k].index]
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
