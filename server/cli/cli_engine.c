/* What `fxcache sim` and `fxcache serve` share: the options that shape the engine (scene, effects, level
 * bias, pools, ray budget, probes, seed, threads), opening a run (scene, Embree scene, effect choice, loop,
 * report), the per-frame statistics sink, and the summary in JSON and in words. One place, so both front
 * ends accept the same options with the same messages and report the same figures. */
#include "cli.h"
#include "cli_engine.h"

#include "fxc_file.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char srv_cli_engine_usage[] =
    "  --scene PATH         *.json description, a mesh file, or 'default' (the embedded scene; default)\n"
    "  --effects auto|LIST  'auto': what the scene needs; or a comma list of %s (default auto)\n"
    "  --bias EFFECT=L      level bias of an effect in levels, -4..8 (coarser is positive; repeatable;\n"
    "                       default: each effect's own)\n"
    "  --pool-mb MB         block-pool memory for all effects, 1..65536, within the machine's memory\n"
    "                       (default 64; a quarter of it for probes when they run)\n"
    "  --ray-budget R       effect rays per frame, 0..1e12, 0 = unlimited (default 0)\n"
    "  --ao-step S          samples added per texel and update of progressive effects (AO), 1..64\n"
    "                       (default 16)\n"
    "  --ao-samples N       AO samples a texel converges at, 1..4096 (default 64; the no-cache baseline's\n"
    "                       AO rays per pixel)\n"
    "  --shadow-rays N      shadow rays per texel and light, 1, 2, 4, 8 or 16, stratified over the texel\n"
    "                       (default 16; the no-cache baseline's per pixel and light)\n"
    "  --probe-cell M       finest world-grid cell in metres, [1e-8, 1000]; a cell at distance d from a\n"
    "                       viewer is about d/16..d/8 wide, never finer (default: the power of two nearest\n"
    "                       a 64th of the scene's bounding-box diagonal)\n"
    "  --probe-rays N       rays per probe update, 1..4096 (default 144, DDGI's)\n"
    "  --probe-hysteresis H weight of a probe's old irradiance per update, [0, 0.999] (default 0.97):\n"
    "                       the steady state of the change-aware blend, every update's with plain\n"
    "  --probe-blend B      adaptive or plain (default adaptive): adaptive keeps less of the old\n"
    "                       irradiance (down to none) while a probe's total changes, over updates, by\n"
    "                       well more than the update's own noise (a light switched on or off, bounces\n"
    "                       building up), and H where the change is noise; plain: always H\n"
    "  --probe-budget N     probes updated per frame at most, 1..1000000 (default 1024)\n"
    "  --indirect-block N   probes evaluated once per NxN block of pixels, then a depth- and normal-aware\n"
    "                       upsample; 1 = every pixel, 2 or 4 at most (default 4); a viewer uses the\n"
    "                       largest of 1, 2, 4 up to N that is at most a quarter of the narrowest probe\n"
    "                       cell in pixels (60 degrees: 4 from 296 pixels high, 2 from 148); sparse\n"
    "                       viewers always 1\n"
    "  --no-local-table     compose finds probes through the hash table only (for measuring the\n"
    "                       viewers' local lookup tables)\n"
    "  --no-cache           the baseline: every effect per pixel per frame at the converged sample counts\n"
    "  --no-cache-samples S with --no-cache: the baseline's AO, shadow and probe rays per pixel as S times\n"
    "                       the converged counts, S a power of two in [1/64, 16] ('0.25' or '1/4'; default\n"
    "                       1; shadow rays above 16 go in sets of 16, at most 256)\n"
    "  --seed S             random seed, 0..4294967295 (default 1)\n"
    "  --threads T          worker threads, 0..256, 0 = all cores (default 0)\n"
    "  --density D          level-0 texels per metre, [1e-6, 1e6] (default: the scene's, else auto)\n";

const struct option srv_cli_engine_options[] = {
    {"scene", required_argument, NULL, SRV_CLI_O_SCENE},
    {"effects", required_argument, NULL, SRV_CLI_O_EFFECTS},
    {"bias", required_argument, NULL, SRV_CLI_O_BIAS},
    {"pool-mb", required_argument, NULL, SRV_CLI_O_POOL},
    {"ray-budget", required_argument, NULL, SRV_CLI_O_BUDGET},
    {"ao-step", required_argument, NULL, SRV_CLI_O_AOSTEP},
    {"probe-cell", required_argument, NULL, SRV_CLI_O_PCELL},
    {"probe-rays", required_argument, NULL, SRV_CLI_O_PRAYS},
    {"probe-hysteresis", required_argument, NULL, SRV_CLI_O_PHYST},
    {"probe-blend", required_argument, NULL, SRV_CLI_O_PBLEND},
    {"probe-budget", required_argument, NULL, SRV_CLI_O_PBUDGET},
    {"indirect-block", required_argument, NULL, SRV_CLI_O_IBLOCK},
    {"no-local-table", no_argument, NULL, SRV_CLI_O_NOLOCAL},
    {"no-cache", no_argument, NULL, SRV_CLI_O_NOCACHE},
    {"seed", required_argument, NULL, SRV_CLI_O_SEED},
    {"threads", required_argument, NULL, SRV_CLI_O_THREADS},
    {"density", required_argument, NULL, SRV_CLI_O_DENSITY},
    {"ao-samples", required_argument, NULL, SRV_CLI_O_AOSAMPLES},
    {"shadow-rays", required_argument, NULL, SRV_CLI_O_SHADOWRAYS},
    {"no-cache-samples", required_argument, NULL, SRV_CLI_O_NCSAMPLES},
};
const size_t srv_cli_engine_option_count = sizeof srv_cli_engine_options / sizeof srv_cli_engine_options[0];

void srv_cli_engine_defaults(srv_cli_engine *e)
{
    *e = (srv_cli_engine){.pool_mb = 64, .seed = 1};
}

void srv_cli_merge_options(const struct option *own, size_t n_own, struct option *out, size_t cap)
{
    size_t n = 0;
    for (size_t i = 0; i < n_own && n + 1 < cap; i++)
        out[n++] = own[i];
    for (size_t i = 0; i < srv_cli_engine_option_count && n + 1 < cap; i++)
        out[n++] = srv_cli_engine_options[i];
    out[n] = (struct option){NULL, 0, NULL, 0};
    optind = 1;
    opterr = 0;
}

void srv_cli_effect_names(char *out, size_t cap)
{
    uint32_t count = 0;
    const fx_effect *const *effects = fx_registry(&count);
    out[0] = 0;
    for (uint32_t i = 0; i < count; i++) {
        if (!effects[i]->shade)
            continue;
        size_t used = strlen(out);
        snprintf(out + used, cap - used, "%s%s", used ? "," : "", effects[i]->name);
    }
}

/* Parses --bias EFFECT=LEVELS against the effect registry. */
static bool parse_bias(const char *cmd, const char *text, srv_cli_engine *e)
{
    uint32_t count = 0;
    const fx_effect *const *effects = fx_registry(&count);
    const char *eq = text ? strchr(text, '=') : NULL;
    char name[64] = "";
    if (eq && (size_t)(eq - text) < sizeof name)
        memcpy(name, text, (size_t)(eq - text));
    int32_t fx = eq ? fx_find(effects, count, name) : -1;
    if (fx >= 0 && !effects[fx]->shade)
        fx = -1; /* the lookup has no level of its own */
    if (fx < 0) {
        char list[256];
        srv_cli_effect_names(list, sizeof list);
        if (!eq)
            fprintf(stderr, "fxcache %s: --bias: '%s' is not EFFECT=LEVELS (effects: %s)\n", cmd,
                    text ? text : "", list);
        else
            fprintf(stderr, "fxcache %s: --bias: unknown effect '%.*s' (effects: %s)\n", cmd,
                    (int)(eq - text), text, list);
        return false;
    }
    double levels;
    if (!srv_cli_double(cmd, "--bias", eq + 1, -4, 8, &levels))
        return false;
    if (levels != floor(levels)) {
        fprintf(stderr, "fxcache %s: --bias: '%s' must be a whole number of levels in [-4, 8]\n", cmd,
                eq + 1);
        return false;
    }
    e->bias[fx] = (int32_t)levels;
    e->bias_set[fx] = true;
    return true;
}

/* Checks --effects before anything is loaded: 'auto', or a comma list of known effects with no empty entry. */
static bool effects_list_valid(const char *cmd, const char *list)
{
    if (strcmp(list, "auto") == 0)
        return true;
    uint32_t count = 0;
    const fx_effect *const *effects = fx_registry(&count);
    const char *p = list;
    for (;;) {
        const char *comma = strchr(p, ',');
        size_t n = comma ? (size_t)(comma - p) : strlen(p);
        char name[64] = "";
        if (n < sizeof name)
            memcpy(name, p, n);
        int32_t fx = fx_find(effects, count, name);
        if (fx < 0 || !effects[fx]->shade) {
            char names[256];
            srv_cli_effect_names(names, sizeof names);
            fprintf(stderr,
                    "fxcache %s: --effects: '%.*s' in '%s' is not an effect (auto, or a comma list of %s)\n",
                    cmd, (int)n, p, list, names);
            return false;
        }
        if (!comma)
            return true;
        p = comma + 1;
    }
}

/* Parses --shadow-rays: 1, 2, 4, 8 or 16 (the texel's 16-bit mask has one bit per cell of its 4 x 4 grid). */
static bool parse_shadow_rays(const char *cmd, const char *arg, srv_cli_engine *e)
{
    uint32_t n;
    if (!srv_cli_u32(cmd, "--shadow-rays", arg, 1, FX_SHADOW_TEXEL_RAYS_MAX, &n))
        return false;
    if (n & (n - 1)) {
        fprintf(stderr,
                "fxcache %s: --shadow-rays: '%s' must be 1, 2, 4, 8 or 16 (strata of the texel's 4x4 "
                "shadow mask)\n",
                cmd, arg);
        return false;
    }
    e->shadow_rays = n;
    return true;
}

/* Parses --indirect-block: 1, 2 or 4 (srv_loop_desc.indirect_block). */
static bool parse_indirect_block(const char *cmd, const char *arg, srv_cli_engine *e)
{
    uint32_t n;
    if (!srv_cli_u32(cmd, "--indirect-block", arg, 1, 4, &n))
        return false;
    if (n == 3) {
        fprintf(stderr, "fxcache %s: --indirect-block: '%s' must be 1, 2 or 4 (pixels per side of a block)\n",
                cmd, arg);
        return false;
    }
    e->indirect_block = n;
    return true;
}

/* Parses --no-cache-samples: a power of two in [1/64, 16], as a decimal or as 1/N. */
static bool parse_no_cache_samples(const char *cmd, const char *arg, srv_cli_engine *e)
{
    double value = 0;
    const char *slash = arg ? strchr(arg, '/') : NULL;
    if (slash && strncmp(arg, "1/", 2) == 0) {
        uint32_t divisor;
        if (!srv_cli_u32(cmd, "--no-cache-samples", slash + 1, 1, 64, &divisor))
            return false;
        value = 1.0 / divisor;
    } else if (!srv_cli_double(cmd, "--no-cache-samples", arg, 1.0 / 64, 16, &value)) {
        return false;
    }
    int exponent;
    if (frexp(value, &exponent) != 0.5) {
        fprintf(stderr, "fxcache %s: --no-cache-samples: '%s' is not a power of two in [1/64, 16]\n", cmd,
                arg);
        return false;
    }
    e->no_cache_samples = value;
    return true;
}

bool srv_cli_engine_check(const char *cmd, const srv_cli_engine *e)
{
    if (e->no_cache_samples > 0 && !e->no_cache) {
        fprintf(stderr, "fxcache %s: --no-cache-samples scales the no-cache baseline: it needs --no-cache\n",
                cmd);
        return false;
    }
    return true;
}

int srv_cli_engine_option(const char *cmd, int code, const char *arg, srv_cli_engine *e)
{
    switch (code) {
    case SRV_CLI_O_SCENE: e->scene_path = arg; return 1;
    case SRV_CLI_O_EFFECTS: e->effects = arg; return effects_list_valid(cmd, arg);
    case SRV_CLI_O_BIAS: return parse_bias(cmd, arg, e);
    case SRV_CLI_O_POOL: return srv_cli_double(cmd, "--pool-mb", arg, 1, 65536, &e->pool_mb);
    case SRV_CLI_O_BUDGET: return srv_cli_double(cmd, "--ray-budget", arg, 0, 1e12, &e->ray_budget);
    case SRV_CLI_O_AOSTEP: return srv_cli_u32(cmd, "--ao-step", arg, 1, 64, &e->ao_step);
    /* down to about a 64th of the smallest scene fxcache loads (SCENE_MIN_EXTENT, 1e-6 m) */
    case SRV_CLI_O_PCELL: return srv_cli_double(cmd, "--probe-cell", arg, 1e-8, 1000, &e->probe_cell);
    case SRV_CLI_O_PRAYS: return srv_cli_u32(cmd, "--probe-rays", arg, 1, 4096, &e->probe_rays);
    case SRV_CLI_O_PHYST:
        if (!srv_cli_double(cmd, "--probe-hysteresis", arg, 0, 0.999, &e->probe_hysteresis))
            return 0;
        if (e->probe_hysteresis == 0)
            e->probe_hysteresis = 1e-9; /* 0 means "default" in the loop's description */
        return 1;
    case SRV_CLI_O_PBLEND:
        if (strcmp(arg, "adaptive") == 0 || strcmp(arg, "plain") == 0) {
            e->probe_plain_blend = strcmp(arg, "plain") == 0;
            return 1;
        }
        fprintf(stderr, "fxcache %s: --probe-blend '%s': expected adaptive or plain\n", cmd, arg);
        return 0;
    case SRV_CLI_O_PBUDGET: return srv_cli_u32(cmd, "--probe-budget", arg, 1, 1000000, &e->probe_budget);
    case SRV_CLI_O_IBLOCK: return parse_indirect_block(cmd, arg, e);
    case SRV_CLI_O_NOLOCAL: e->no_local_table = true; return 1;
    case SRV_CLI_O_NOCACHE: e->no_cache = true; return 1;
    case SRV_CLI_O_SEED: return srv_cli_u32(cmd, "--seed", arg, 0, UINT32_MAX, &e->seed);
    case SRV_CLI_O_THREADS: return srv_cli_u32(cmd, "--threads", arg, 0, 256, &e->threads);
    case SRV_CLI_O_DENSITY: return srv_cli_double(cmd, "--density", arg, 1e-6, 1e6, &e->density);
    case SRV_CLI_O_AOSAMPLES:
        return srv_cli_u32(cmd, "--ao-samples", arg, 1, FX_AO_SAMPLES_LIMIT, &e->ao_samples);
    case SRV_CLI_O_SHADOWRAYS: return parse_shadow_rays(cmd, arg, e);
    case SRV_CLI_O_NCSAMPLES: return parse_no_cache_samples(cmd, arg, e);
    default: return -1;
    }
}

/* Decides which effects run (cli_engine.h). */
bool srv_cli_choose_effects(const char *cmd, const scene *s, const char *list,
                            bool effect_on[SRV_MAX_EFFECTS], char reasons[SRV_MAX_EFFECTS][200],
                            json_t *left_out_extra)
{
    uint32_t count = 0;
    const fx_effect *const *effects = fx_registry(&count);
    bool needed[SRV_MAX_EFFECTS] = {false};
    fx_needs(effects, count, s, needed, reasons);
    bool automatic = !list || strcmp(list, "auto") == 0;
    bool wanted[SRV_MAX_EFFECTS] = {false};
    if (!automatic) {
        char buf[256];
        snprintf(buf, sizeof buf, "%s", list);
        for (char *save = NULL, *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
            int32_t fx = fx_find(effects, count, tok);
            if (fx < 0) {
                fprintf(stderr, "fxcache %s: --effects: unknown effect '%s'\n", cmd, tok);
                return false;
            }
            wanted[fx] = true;
        }
    }
    for (uint32_t e = 0; e < count; e++) {
        effect_on[e] = false;
        if (!effects[e]->shade)
            continue; /* runs for the effects that depend on it */
        if (!needed[e])
            continue;
        if (!automatic && !wanted[e]) {
            snprintf(reasons[e], 200, "not in --effects %s", list);
            continue;
        }
        effect_on[e] = true;
    }
    /* What the scene would need beyond the registry. */
    scene_needs_result needs;
    scene_needs(s, &needs);
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
        const char *name = scene_effect_name((scene_effect)fx);
        if (fx_find(effects, count, name) >= 0)
            continue;
        char reason[320];
        if (needs.effect[fx])
            snprintf(reason, sizeof reason,
                     "%s; but %s is not implemented yet (no effect of that name is registered)",
                     needs.effect_reason[fx], name);
        else
            snprintf(reason, sizeof reason, "%s", needs.effect_reason[fx]);
        json_object_set_new(left_out_extra, name, json_string(reason));
    }
    return true;
}

srv_loop_desc srv_cli_loop_desc(const srv_cli_engine *e, const scene *s, scene_rt *rt, bool keep_views)
{
    srv_loop_desc desc = {.s = s,
                          .rt = rt,
                          .pool_bytes = (uint64_t)(e->pool_mb * 1048576.0),
                          .ray_budget = (uint64_t)e->ray_budget,
                          .samples_per_update = e->ao_step,
                          .no_cache = e->no_cache,
                          .seed = e->seed,
                          .threads = e->threads,
                          .keep_views = keep_views,
                          .probe_cell = (float)e->probe_cell,
                          .probe_rays = e->probe_rays,
                          .probe_hysteresis = (float)e->probe_hysteresis,
                          .probe_plain_blend = e->probe_plain_blend,
                          .probe_budget = e->probe_budget,
                          .indirect_block = e->indirect_block,
                          .no_local_table = e->no_local_table,
                          .ao_samples = e->ao_samples,
                          .shadow_rays = e->shadow_rays,
                          .no_cache_samples = (float)e->no_cache_samples};
    memcpy(desc.bias, e->bias, sizeof desc.bias);
    memcpy(desc.bias_set, e->bias_set, sizeof desc.bias_set);
    return desc;
}

int srv_cli_run_open(const char *cmd, const srv_cli_engine *e, bool keep_views, srv_cli_run *run,
                     volatile sig_atomic_t *stop)
{
    memset(run, 0, sizeof *run);
    run->cmd = cmd;
    run->left_out_extra = json_object();
    if (!srv_cli_engine_check(cmd, e))
        return 2;
    run->s = srv_cli_load_scene(cmd, e->scene_path, (float)e->density);
    if (stop && *stop)
        return srv_cli_interrupted(cmd, *stop, "while loading the scene");
    if (!run->s)
        return 1;
    scene_error serr = {0};
    run->rt = scene_rt_create(run->s, &run->bvh_ms, &serr);
    if (!run->rt) {
        fprintf(stderr, "fxcache %s: %s\n", cmd, serr.msg);
        return 1;
    }
    srv_loop_desc desc = srv_cli_loop_desc(e, run->s, run->rt, keep_views);
    if (!srv_cli_choose_effects(cmd, run->s, e->effects, desc.effect_on, run->reasons, run->left_out_extra))
        return 2;
    char err[512];
    if (srv_loop_create(&desc, &run->loop, err, sizeof err) != FXC_OK) {
        fprintf(stderr, "fxcache %s: %s\n", cmd, err);
        return 1;
    }
    run->report = srv_report_create(run->loop);
    if (!run->report) {
        fprintf(stderr, "fxcache %s: out of memory\n", cmd);
        return 1;
    }
    run->report_sink = srv_report_sink(run->report);
    srv_loop_add_sink(run->loop, &run->report_sink);
    return -1;
}

void srv_cli_run_close(srv_cli_run *run)
{
    json_decref(run->left_out_extra);
    srv_report_free(run->report);
    srv_loop_free(run->loop);
    scene_rt_free(run->rt);
    scene_free(run->s);
    memset(run, 0, sizeof *run);
}

/* ---- statistics per frame ------------------------------------------------------------------------------ */

static int stats_sink_done(void *user, const srv_frame_stats *st)
{
    srv_cli_stats *sink = user;
    srv_memory mem;
    srv_loop_memory(sink->run->loop, &mem);
    json_t *line = srv_report_frame_json(sink->run->report, st, &mem);
    int rc = json_dumpf(line, sink->file, JSON_COMPACT | JSON_PRESERVE_ORDER);
    json_decref(line);
    if (rc != 0 || fputc('\n', sink->file) == EOF || fflush(sink->file) != 0) {
        fprintf(stderr, "fxcache %s: writing %s failed: %s\n", sink->run->cmd, sink->path, strerror(errno));
        return -1;
    }
    return 0;
}

bool srv_cli_stats_open(srv_cli_stats *stats, srv_cli_run *run, const char *path)
{
    *stats = (srv_cli_stats){.file = fopen(path, "w"), .run = run, .path = path};
    if (!stats->file) {
        fprintf(stderr, "fxcache %s: cannot write %s: %s\n", run->cmd, path, strerror(errno));
        return false;
    }
    srv_loop_add_sink(run->loop, &(srv_sink){.frame_done = stats_sink_done, .user = stats});
    return true;
}

bool srv_cli_stats_close(srv_cli_stats *stats)
{
    if (!stats->file)
        return true;
    bool ok = fclose(stats->file) == 0;
    if (!ok)
        fprintf(stderr, "fxcache %s: writing %s failed: %s\n", stats->run ? stats->run->cmd : "", stats->path,
                strerror(errno));
    stats->file = NULL;
    return ok;
}

/* ---- the summary --------------------------------------------------------------------------------------- */

json_t *srv_cli_summary_json(const srv_cli_run *run, const srv_cli_engine *e)
{
    const srv_loop *loop = run->loop;
    json_t *sum = json_object();
    json_object_set_new(sum, "scene", json_string(run->s->source));
    json_object_set_new(sum, "precision_warning",
                        run->s->precision_warning[0] ? json_string(run->s->precision_warning) : json_null());
    json_object_set_new(sum, "no_cache", json_boolean(e->no_cache));
    json_object_set_new(sum, "seed", json_integer(e->seed));
    json_object_set_new(sum, "pool_mb", json_real(e->pool_mb));
    json_object_set_new(sum, "ray_budget", json_integer((json_int_t)e->ray_budget));
    const srv_loop_desc *resolved = srv_loop_desc_of(loop);
    json_object_set_new(sum, "ao_samples", json_integer(resolved->ao_samples));
    json_object_set_new(sum, "shadow_rays", json_integer(resolved->shadow_rays));
    if (e->no_cache)
        json_object_set_new(sum, "no_cache_samples", json_real(resolved->no_cache_samples));
    if (srv_loop_probe_cell(loop) > 0)
        json_object_set_new(sum, "probes",
                            json_pack("{s:f,s:I,s:f,s:s,s:I,s:I,s:b}", "cell_m",
                                      (double)srv_loop_probe_cell(loop), "rays",
                                      (json_int_t)srv_loop_desc_of(loop)->probe_rays, "hysteresis",
                                      (double)srv_loop_desc_of(loop)->probe_hysteresis, "blend",
                                      srv_loop_desc_of(loop)->probe_plain_blend ? "plain" : "adaptive",
                                      "budget", (json_int_t)srv_loop_desc_of(loop)->probe_budget,
                                      "indirect_block", (json_int_t)srv_loop_desc_of(loop)->indirect_block,
                                      "local_tables", !e->no_local_table));
    else
        json_object_set_new(
            sum, "world_space_cache",
            json_string(e->no_cache ? "none: no cache at all (--no-cache)"
                                    : "not created: no effect that runs lives in it (nothing allocated)"));
    json_t *effects = json_object(), *left_out = json_object(), *bias = json_object();
    for (uint32_t i = 0; i < srv_loop_effect_count(loop); i++) {
        const char *name = srv_loop_effect(loop, i)->name;
        bool on = srv_loop_effect_on(loop, i);
        json_object_set_new(on ? effects : left_out, name, json_string(run->reasons[i]));
        if (on && srv_loop_effect(loop, i)->shade)
            json_object_set_new(bias, name, json_integer(srv_loop_bias(loop, i)));
    }
    json_object_update(left_out, run->left_out_extra);
    json_object_set_new(sum, "effects", effects);
    json_object_set_new(sum, "left_out", left_out);
    json_object_set_new(sum, "level_bias", bias);
    json_t *totals = srv_report_json(run->report);
    json_object_update(sum, totals);
    json_decref(totals);
    json_object_set_new(sum, "bvh_build_ms", json_real(run->bvh_ms));
    return sum;
}

bool srv_cli_write_json(const char *cmd, const char *path, const json_t *value)
{
    errno = 0;
    FILE *file = fopen(path, "w");
    bool written =
        file && json_dumpf(value, file, JSON_INDENT(2) | JSON_PRESERVE_ORDER) == 0 && fflush(file) == 0;
    int saved = errno;
    if (file && fclose(file) != 0 && written) {
        written = false;
        saved = errno;
    }
    if (!written) {
        /* a summary that is there is whole: a partial one (a full disk) is removed */
        if (file)
            fxc_remove_partial(path);
        fprintf(stderr, "fxcache %s: cannot write %s: %s\n", cmd, path, strerror(saved ? saved : EIO));
    }
    return written;
}

void srv_cli_warn_exhausted(const srv_cli_run *run, const srv_cli_engine *e)
{
    const srv_report_totals *t = srv_report_get_totals(run->report);
    if (t->exhausted == 0)
        return;
    char world[320] = "";
    double cell = (double)srv_loop_probe_cell(run->loop);
    if (t->world_last.exhausted > 0 && cell > 0)
        snprintf(world, sizeof world,
                 ", %llu of them in the probes' world-space pool at a finest cell of %g m (this scene's "
                 "default %g m; raise --probe-cell or --pool-mb)",
                 (unsigned long long)t->world_last.exhausted, cell, srv_probe_cell_default(run->s));
    fprintf(
        stderr,
        "fxcache %s: warning: the block pools (--pool-mb %g) were too small for the requests of one frame "
        "%llu times%s; the run went on degraded (%llu visible pixels composed without cached data)\n",
        run->cmd, e->pool_mb, (unsigned long long)t->exhausted, world, (unsigned long long)t->pixels_missing);
}

void srv_cli_print_summary(const srv_cli_run *run, bool no_cache, bool interrupted)
{
    const srv_loop *loop = run->loop;
    const srv_report_totals *t = srv_report_get_totals(run->report);
    uint64_t effect_rays = 0, pools_in_use = 0;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++) {
        effect_rays += t->rays[e];
        pools_in_use += t->final.pools_in_use[e];
    }
    printf("%u viewer%s (%llu viewer-frames), %u frames on %s%s%s\n", t->viewers_seen,
           t->viewers_seen == 1 ? "" : "s", (unsigned long long)t->viewer_frames, t->frames, run->s->source,
           no_cache ? " (no cache)" : "", interrupted ? " (interrupted)" : "");
    if (t->sample_viewers_seen)
        printf("           and %u sample viewer%s (clients' sample requests, %llu viewer-frames; their "
               "texels count in "
               "the sharing)\n",
               t->sample_viewers_seen, t->sample_viewers_seen == 1 ? "" : "s",
               (unsigned long long)t->sample_viewer_frames);
    printf("effects:   ");
    for (uint32_t e = 0; e < srv_loop_effect_count(loop); e++)
        if (srv_loop_effect(loop, e)->shade)
            printf(" %s %s;", srv_loop_effect(loop, e)->name, srv_loop_effect_on(loop, e) ? "on" : "off");
    printf("\n");
    for (uint32_t e = 0; e < srv_loop_effect_count(loop); e++)
        if (srv_loop_effect(loop, e)->shade && !srv_loop_effect_on(loop, e))
            printf("  left out %s: %s\n", srv_loop_effect(loop, e)->name, run->reasons[e]);
    const char *extra_name;
    const json_t *extra_reason;
    json_object_foreach(run->left_out_extra, extra_name, extra_reason)
        printf("  left out %s: %s\n", extra_name, json_string_value(extra_reason));
    if (no_cache)
        printf("texels:     none (no cache: every pixel traces its own rays)\n");
    else if (!t->unique)
        printf("texels:     none requested (no viewer saw a surface)\n");
    else
        printf("texels:     %llu requested, %llu unique: sharing ratio %.2f\n",
               (unsigned long long)t->requested, (unsigned long long)t->unique,
               (double)t->requested / (double)t->unique);
    if (srv_loop_probe_cell(loop) > 0) {
        printf("probes:     %llu requested, %llu unique: sharing ratio %.2f; finest cell %g m\n",
               (unsigned long long)t->world_requested, (unsigned long long)t->world_unique,
               t->world_unique ? (double)t->world_requested / (double)t->world_unique : 0.0,
               (double)srv_loop_probe_cell(loop));
        printf(
            "world:      %llu bricks, %.1f MiB, table load %.2f, %llu points refused, local tables answered "
            "%.1f %% of reads\n",
            (unsigned long long)t->world_last.bricks_resident, t->world_last.bytes / 1048576.0,
            t->world_last.table_capacity
                ? (double)t->world_last.entries / (double)t->world_last.table_capacity
                : 0.0,
            (unsigned long long)t->world_refusals,
            t->world_local_lookups ? 100.0 * (double)t->world_local_hits / (double)t->world_local_lookups
                                   : 0.0);
    } else if (!no_cache) {
        printf("world:      no world-space cache (no effect that runs lives in it: nothing allocated)\n");
    }
    printf("rays:       %llu visibility", (unsigned long long)t->visibility_rays);
    for (uint32_t e = 0; e < srv_loop_effect_count(loop); e++)
        if (srv_loop_effect_on(loop, e) && srv_loop_effect(loop, e)->shade)
            printf(", %llu %s", (unsigned long long)t->rays[e], srv_loop_effect(loop, e)->name);
    printf(" (%.0f effect rays per frame)\n", t->frames ? (double)effect_rays / t->frames : 0.0);
    printf("memory:     %.1f MiB peak, %.1f MiB final (pools in use %.1f MiB)\n", t->peak.total / 1048576.0,
           t->final.total / 1048576.0, pools_in_use / 1048576.0);
    printf("time:       %.1f ms per frame (", t->frames ? t->frame_ms / t->frames : 0.0);
    for (int stg = 0; stg < SRV_STAGE_COUNT; stg++)
        printf("%s%s %.1f", stg ? ", " : "", srv_stage_name((srv_stage)stg),
               t->frames ? t->time_ms[stg] / t->frames : 0.0);
    printf(")\n");
    uint64_t drops = 0;
    for (int d = 0; d < SRV_DROP_COUNT; d++)
        drops += t->drops[d];
    if (drops) {
        printf("dropped:   ");
        for (int d = 0; d < SRV_DROP_COUNT; d++)
            if (t->drops[d])
                printf(" %s %llu;", srv_drop_name((srv_drop)d), (unsigned long long)t->drops[d]);
        printf("\n");
    }
    if (t->pixels_missing)
        printf("note:       %llu of %llu visible pixels were composed before their texels held data\n",
               (unsigned long long)t->pixels_missing, (unsigned long long)t->pixels_visible);
}

int srv_cli_run_option(const char *cmd, int code, const char *arg, srv_cli_engine *e, srv_cli_view_options *v)
{
    int known = srv_cli_engine_option(cmd, code, arg, e);
    return known < 0 ? srv_cli_view_option(cmd, code, arg, v) : known;
}
