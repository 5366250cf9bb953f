/* `fxcache sim`: several viewers in one process with no network, driven through the same engine
 * (engine.h) the networked server uses. Viewers are added with their own resolution; cameras come from a
 * generator or from viewer traces, whose viewers join at their trace's first time and leave after its last
 * (paced by --fps). The run's results go out through sinks: frames and effect views as images (--out), one
 * JSON line of statistics per frame (--stats), trace recording (--record) and the run report, whose totals
 * make the summary (--summary, and in words on stdout). SIGINT and SIGTERM end the run after the current
 * frame, with the summary and every file complete. */
#include "camgen.h"
#include "cli.h"
#include "engine.h"
#include "image.h"
#include "report.h"
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
#include <unistd.h>

enum { MAX_TRACES = SRV_MAX_VIEWERS };

static volatile sig_atomic_t stop_requested = 0;

static void on_signal(int sig)
{
    stop_requested = sig;
}

typedef struct sim_options {
    const char *scene_path;
    uint32_t viewers;
    bool viewers_set;
    uint32_t frames;
    bool frames_set;
    uint32_t width, height;
    bool res_set;
    const char *effects;
    int32_t bias[SRV_MAX_EFFECTS];
    bool bias_set[SRV_MAX_EFFECTS];
    double pool_mb;
    double ray_budget;
    bool no_cache;
    uint32_t seed;
    const char *out_dir;
    uint32_t save_every;
    bool views;
    const char *stats_path;
    const char *summary_path;
    srv_camgen_kind camera;
    bool camera_set;
    const char *traces[MAX_TRACES];
    uint32_t trace_count;
    const char *record_dir;
    uint32_t threads;
    uint32_t ao_step;
    double density;
    double fps;
    bool quiet;
    double probe_cell, probe_hysteresis;
    uint32_t probe_rays, probe_budget;
    bool no_local_table;
} sim_options;

static const char sim_usage[] =
    "usage: fxcache sim [options]\n"
    "\n"
    "Runs several simulated viewers on one scene in one process: per frame, visibility for every viewer,\n"
    "requests deduplicated into the shared caches, effect updates within a ray budget, and a composed\n"
    "image per viewer. Prints a summary in words.\n"
    "\n"
    "  --scene PATH         *.json description, a mesh file, or 'default' (the embedded scene; default)\n"
    "  --viewers N          viewers, 1..64 (default 4, or one per --trace)\n"
    "  --frames F           frames, 1..1000000 (default 30, or until the last trace ends)\n"
    "  --res WxH            resolution per viewer, sides 1..8192 (default 640x360; a version 2 trace's own\n"
    "                       resolution wins for its viewer)\n"
    "  --effects auto|LIST  'auto': what the scene needs; or a comma list of %s (default auto)\n"
    "  --bias EFFECT=L      level bias of an effect in levels, -4..8 (coarser is positive; repeatable;\n"
    "                       default: each effect's own)\n"
    "  --pool-mb MB         block-pool memory for all effects, 1..65536, within the machine's memory\n"
    "                       (default 64; a quarter of it for probes when they run)\n"
    "  --ray-budget R       effect rays per frame, 0 = unlimited (default 0)\n"
    "  --ao-step S          samples added per texel and update of progressive effects (AO), 1..64\n"
    "                       (default 16)\n"
    "  --probe-cell M       finest world-grid cell in metres, [0.001, 1000]; a cell at distance d from a\n"
    "                       viewer is about d/16..d/8 wide, never finer (default: the power of two nearest\n"
    "                       a 64th of the scene's bounding-box diagonal)\n"
    "  --probe-rays N       rays per probe update, 1..4096 (default 144, DDGI's)\n"
    "  --probe-hysteresis H weight of a probe's old irradiance per update, [0, 0.999] (default 0.97)\n"
    "  --probe-budget N     probes updated per frame at most, 1..1000000 (default 1024)\n"
    "  --no-local-table     compose finds probes through the hash table only (for measuring the\n"
    "                       viewers' local lookup tables)\n"
    "  --no-cache           the baseline: every effect per pixel per frame at the converged sample counts\n"
    "  --camera GEN         camera generator when no --trace is given (default room): %s\n"
    "  --trace FILE         a viewer trace (repeat once per viewer; see docs/TRACE_FORMAT.md): the viewer\n"
    "                       joins at its first time and leaves after its last\n"
    "  --fps F              frames per second of trace time when replaying, (0, 1000] (default 30)\n"
    "  --record DIR         write the cameras each viewer was rendered for as DIR/viewer_NN.trace\n"
    "                       (version 2, with the resolution; replay with --trace)\n"
    "  --seed S             random seed, 0..4294967295 (default 1)\n"
    "  --threads T          worker threads, 0 = all cores (default 0)\n"
    "  --density D          level-0 texels per metre, [1e-6, 1e6] (default: the scene's, else auto)\n"
    "  --out DIR            write frames as DIR/frame_FFFF_viewer_VV.png\n"
    "  --save-every K       frames to save: every K-th and the last (default 0: only the last)\n"
    "  --views              with --out: also AO and shadow as linear EXR, and a picture of how many\n"
    "                       viewers requested the blocks each pixel reads (_sharing.png)\n"
    "  --stats FILE         one JSON line of statistics per frame\n"
    "  --summary FILE       one JSON object at the end (time_ms: sums over the run; time_ms_per_frame)\n"
    "  --quiet              no summary in words on stdout\n"
    "  -h, --help           this text\n";

/* The names of the effects a user can choose (those that shade), comma-separated. */
static void effect_names(char *out, size_t cap)
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
static bool parse_bias(const char *text, sim_options *o)
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
        effect_names(list, sizeof list);
        if (!eq)
            fprintf(stderr, "fxcache sim: --bias: '%s' is not EFFECT=LEVELS (effects: %s)\n", text ? text : "", list);
        else
            fprintf(stderr, "fxcache sim: --bias: unknown effect '%.*s' (effects: %s)\n", (int)(eq - text), text, list);
        return false;
    }
    double levels;
    if (!srv_cli_double("sim", "--bias", eq + 1, -4, 8, &levels))
        return false;
    if (levels != floor(levels)) {
        fprintf(stderr, "fxcache sim: --bias: '%s' must be a whole number of levels in [-4, 8]\n", eq + 1);
        return false;
    }
    o->bias[fx] = (int32_t)levels;
    o->bias_set[fx] = true;
    return true;
}

/* Checks --effects before anything is loaded: 'auto', or a comma list of known effects with no empty entry. */
static bool effects_list_valid(const char *list)
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
            effect_names(names, sizeof names);
            fprintf(stderr, "fxcache sim: --effects: '%.*s' in '%s' is not an effect (auto, or a comma list of %s)\n",
                    (int)n, p, list, names);
            return false;
        }
        if (!comma)
            return true;
        p = comma + 1;
    }
}

static int parse_options(int argc, char **argv, sim_options *o)
{
    enum { O_SCENE = 256, O_VIEWERS, O_FRAMES, O_RES, O_EFFECTS, O_BIAS, O_POOL, O_BUDGET, O_NOCACHE, O_SEED,
           O_OUT, O_SAVE, O_VIEWS, O_STATS, O_SUMMARY, O_CAMERA, O_TRACE, O_RECORD, O_THREADS, O_AOSTEP,
           O_DENSITY, O_QUIET, O_FPS, O_PCELL, O_PRAYS, O_PHYST, O_PBUDGET, O_NOLOCAL };
    static const struct option options[] = {
        {"scene", required_argument, NULL, O_SCENE},     {"viewers", required_argument, NULL, O_VIEWERS},
        {"frames", required_argument, NULL, O_FRAMES},   {"res", required_argument, NULL, O_RES},
        {"effects", required_argument, NULL, O_EFFECTS}, {"bias", required_argument, NULL, O_BIAS},
        {"pool-mb", required_argument, NULL, O_POOL},    {"ray-budget", required_argument, NULL, O_BUDGET},
        {"no-cache", no_argument, NULL, O_NOCACHE},      {"seed", required_argument, NULL, O_SEED},
        {"out", required_argument, NULL, O_OUT},         {"save-every", required_argument, NULL, O_SAVE},
        {"views", no_argument, NULL, O_VIEWS},           {"stats", required_argument, NULL, O_STATS},
        {"summary", required_argument, NULL, O_SUMMARY}, {"camera", required_argument, NULL, O_CAMERA},
        {"trace", required_argument, NULL, O_TRACE},     {"record", required_argument, NULL, O_RECORD},
        {"threads", required_argument, NULL, O_THREADS}, {"ao-step", required_argument, NULL, O_AOSTEP},
        {"density", required_argument, NULL, O_DENSITY}, {"quiet", no_argument, NULL, O_QUIET},
        {"fps", required_argument, NULL, O_FPS},         {"help", no_argument, NULL, 'h'},
        {"probe-cell", required_argument, NULL, O_PCELL}, {"probe-rays", required_argument, NULL, O_PRAYS},
        {"probe-hysteresis", required_argument, NULL, O_PHYST},
        {"probe-budget", required_argument, NULL, O_PBUDGET}, {"no-local-table", no_argument, NULL, O_NOLOCAL},
        {NULL, 0, NULL, 0},
    };
    optind = 1;
    opterr = 0;
    for (int c; (c = getopt_long(argc, argv, ":h", options, NULL)) != -1;) {
        bool ok = true;
        switch (c) {
        case O_SCENE: o->scene_path = optarg; break;
        case O_VIEWERS: ok = srv_cli_u32("sim", "--viewers", optarg, 1, SRV_MAX_VIEWERS, &o->viewers); o->viewers_set = true; break;
        case O_FRAMES: ok = srv_cli_u32("sim", "--frames", optarg, 1, 1000000, &o->frames); o->frames_set = true; break;
        case O_RES: ok = srv_cli_resolution("sim", "--res", optarg, SRV_MAX_SIDE, &o->width, &o->height); o->res_set = true; break;
        case O_EFFECTS:
            o->effects = optarg;
            ok = effects_list_valid(optarg);
            break;
        case O_BIAS: ok = parse_bias(optarg, o); break;
        case O_POOL: ok = srv_cli_double("sim", "--pool-mb", optarg, 1, 65536, &o->pool_mb); break;
        case O_BUDGET: ok = srv_cli_double("sim", "--ray-budget", optarg, 0, 1e12, &o->ray_budget); break;
        case O_NOCACHE: o->no_cache = true; break;
        case O_SEED: ok = srv_cli_u32("sim", "--seed", optarg, 0, UINT32_MAX, &o->seed); break;
        case O_OUT: o->out_dir = optarg; break;
        case O_SAVE: ok = srv_cli_u32("sim", "--save-every", optarg, 0, 1000000, &o->save_every); break;
        case O_VIEWS: o->views = true; break;
        case O_STATS: o->stats_path = optarg; break;
        case O_SUMMARY: o->summary_path = optarg; break;
        case O_CAMERA:
            o->camera_set = true;
            if (!srv_camgen_parse(optarg, &o->camera)) {
                fprintf(stderr, "fxcache sim: --camera: unknown generator '%s' (one of: %s)\n", optarg, srv_camgen_list());
                ok = false;
            }
            break;
        case O_TRACE:
            if (o->trace_count == MAX_TRACES) {
                fprintf(stderr, "fxcache sim: --trace: at most %d traces\n", MAX_TRACES);
                ok = false;
            } else {
                o->traces[o->trace_count++] = optarg;
            }
            break;
        case O_RECORD: o->record_dir = optarg; break;
        case O_THREADS: ok = srv_cli_u32("sim", "--threads", optarg, 0, 256, &o->threads); break;
        case O_AOSTEP: ok = srv_cli_u32("sim", "--ao-step", optarg, 1, 64, &o->ao_step); break;
        case O_DENSITY: ok = srv_cli_double("sim", "--density", optarg, 1e-6, 1e6, &o->density); break;
        case O_QUIET: o->quiet = true; break;
        case O_FPS: ok = srv_cli_double("sim", "--fps", optarg, 0.001, 1000, &o->fps); break;
        case O_PCELL: ok = srv_cli_double("sim", "--probe-cell", optarg, 0.001, 1000, &o->probe_cell); break;
        case O_PRAYS: ok = srv_cli_u32("sim", "--probe-rays", optarg, 1, 4096, &o->probe_rays); break;
        case O_PHYST:
            ok = srv_cli_double("sim", "--probe-hysteresis", optarg, 0, 0.999, &o->probe_hysteresis);
            if (ok && o->probe_hysteresis == 0)
                o->probe_hysteresis = 1e-9; /* 0 means "default" in the loop's description */
            break;
        case O_PBUDGET: ok = srv_cli_u32("sim", "--probe-budget", optarg, 1, 1000000, &o->probe_budget); break;
        case O_NOLOCAL: o->no_local_table = true; break;
        case 'h': {
            char names[256];
            effect_names(names, sizeof names);
            printf(sim_usage, names, srv_camgen_list());
            return 0;
        }
        case ':': fprintf(stderr, "fxcache sim: %s needs a value\n", argv[optind - 1]); return 2;
        default: fprintf(stderr, "fxcache sim: unknown option '%s' (try --help)\n", argv[optind - 1]); return 2;
        }
        if (!ok)
            return 2;
    }
    if (optind < argc) {
        fprintf(stderr, "fxcache sim: unexpected argument '%s' (the scene is given with --scene)\n", argv[optind]);
        return 2;
    }
    if (o->trace_count && o->viewers_set && o->viewers != o->trace_count) {
        fprintf(stderr, "fxcache sim: --viewers %u but %u traces: give one --trace per viewer\n", o->viewers,
                o->trace_count);
        return 2;
    }
    if (o->save_every && !o->out_dir) {
        fprintf(stderr, "fxcache sim: --save-every needs --out DIR\n");
        return 2;
    }
    if (o->trace_count && o->camera_set) {
        fprintf(stderr, "fxcache sim: --camera and --trace both choose the cameras: give one of them\n");
        return 2;
    }
    if (o->views && !o->out_dir) {
        fprintf(stderr, "fxcache sim: --views needs --out DIR\n");
        return 2;
    }
    return -1;
}

/* Decides which effects run: the registry's needs, narrowed by --effects; reasons for the summary. Needs
 * of the scene that no registered effect serves (the scene_needs list) are reported as left out. */
static bool choose_effects(const scene *s, const char *list, bool effect_on[SRV_MAX_EFFECTS],
                           char reasons[SRV_MAX_EFFECTS][200], json_t *left_out_extra)
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
                fprintf(stderr, "fxcache sim: --effects: unknown effect '%s'\n", tok);
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
    /* What the scene would need beyond the registry (probes until the world-space cache exists). */
    scene_needs_result needs;
    scene_needs(s, &needs);
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
        const char *name = scene_effect_name((scene_effect)fx);
        if (fx_find(effects, count, name) >= 0)
            continue;
        char reason[320];
        if (needs.effect[fx])
            snprintf(reason, sizeof reason, "%s; but %s is not implemented yet (no effect of that name is registered)",
                     needs.effect_reason[fx], name);
        else
            snprintf(reason, sizeof reason, "%s", needs.effect_reason[fx]);
        json_object_set_new(left_out_extra, name, json_string(reason));
    }
    return true;
}

static bool make_dir(const char *path)
{
    if (mkdir(path, 0755) == 0 || errno == EEXIST)
        return true;
    fprintf(stderr, "fxcache sim: cannot create folder %s: %s\n", path, strerror(errno));
    return false;
}

/* ---- sinks ----------------------------------------------------------------------------------------------- */

/* Images: the chosen frames of every viewer, as PNG (and the effect views with --views). */
typedef struct image_sink {
    const sim_options *o;
    uint32_t last_frame; /* the run's last frame (always saved) */
    bool force;          /* save whatever frame comes (after an interruption) */
} image_sink;

static bool save_viewer_frame(const sim_options *o, const srv_viewer_frame *vf, uint32_t viewers)
{
    char path[1024], msg[512];
    snprintf(path, sizeof path, "%s/frame_%04u_%s.png", o->out_dir, vf->frame, vf->name);
    if (scene_image_write_u8(path, vf->width, vf->height, 3, vf->srgb, msg, sizeof msg) != 0) {
        fprintf(stderr, "fxcache sim: %s\n", msg);
        return false;
    }
    if (!o->views)
        return true;
    static const char *const names[SRV_VIEW_COUNT] = {"ao", "shadow", "sharing"};
    for (int w = 0; w < SRV_VIEW_COUNT; w++) {
        const float *img = vf->views[w];
        if (!img)
            continue;
        int rc;
        if (w == SRV_VIEW_SHARING) {
            /* Grey levels: black = nobody (sky, or no data), then brighter for each more viewer. */
            size_t n = (size_t)vf->width * vf->height;
            uint8_t *grey = malloc(n);
            if (!grey)
                return false;
            for (size_t i = 0; i < n; i++)
                grey[i] = (uint8_t)(img[i] <= 0 ? 0 : fminf(255.0f, 40 + (215.0f * img[i]) / (float)viewers));
            snprintf(path, sizeof path, "%s/frame_%04u_%s_sharing.png", o->out_dir, vf->frame, vf->name);
            rc = scene_image_write_u8(path, vf->width, vf->height, 1, grey, msg, sizeof msg);
            free(grey);
        } else {
            snprintf(path, sizeof path, "%s/frame_%04u_%s_%s.exr", o->out_dir, vf->frame, vf->name, names[w]);
            rc = scene_image_write_f32(path, vf->width, vf->height, 1, img, msg, sizeof msg);
        }
        if (rc != 0) {
            fprintf(stderr, "fxcache sim: %s\n", msg);
            return false;
        }
    }
    return true;
}

static int image_sink_frame(void *user, const srv_viewer_frame *vf)
{
    image_sink *sink = user;
    const sim_options *o = sink->o;
    bool chosen = sink->force || vf->frame == sink->last_frame || (o->save_every && vf->frame % o->save_every == 0);
    if (!chosen || stop_requested) /* an interrupted run saves its last frame afterwards */
        return 0;
    return save_viewer_frame(o, vf, o->viewers) ? 0 : -1;
}

/* Statistics: one JSON line per frame, flushed at once so that a crash loses no finished frame. */
typedef struct stats_sink {
    FILE *file;
    const srv_loop *loop;
    const srv_report *report; /* for the names and the memory JSON */
} stats_sink;

static int stats_sink_done(void *user, const srv_frame_stats *st)
{
    stats_sink *sink = user;
    srv_memory mem;
    srv_loop_memory(sink->loop, &mem);
    json_t *line = srv_report_frame_json(sink->report, st, &mem);
    int rc = json_dumpf(line, sink->file, JSON_COMPACT | JSON_PRESERVE_ORDER);
    json_decref(line);
    if (rc != 0 || fputc('\n', sink->file) == EOF || fflush(sink->file) != 0) {
        fprintf(stderr, "fxcache sim: writing %s failed: %s\n", "the statistics", strerror(errno));
        return -1;
    }
    return 0;
}

/* Recording: the camera each viewer was rendered for, at the frame's time. */
typedef struct record_sink {
    srv_trace_writer *writers[SRV_MAX_VIEWERS]; /* by the sim's viewer index */
    const uint32_t *index_of_slot;              /* viewer slot -> the sim's viewer index */
    double fps, start_time;
} record_sink;

static int record_sink_frame(void *user, const srv_viewer_frame *vf)
{
    record_sink *sink = user;
    uint32_t index = sink->index_of_slot[vf->id.id & 0xFFu];
    srv_trace_writer *w = index < SRV_MAX_VIEWERS ? sink->writers[index] : NULL;
    if (!w)
        return 0;
    if (srv_trace_writer_add(w, sink->start_time + vf->frame / sink->fps, &vf->camera) != 0) {
        fprintf(stderr, "fxcache sim: %s\n", srv_trace_writer_error(w));
        return -1;
    }
    return 0;
}

/* ---- the summary ----------------------------------------------------------------------------------------- */

static void print_summary(const sim_options *o, const scene *s, const srv_loop *loop, const srv_report *report,
                          const char reasons[SRV_MAX_EFFECTS][200], const json_t *left_out_extra)
{
    const srv_report_totals *t = srv_report_get_totals(report);
    uint64_t effect_rays = 0, pools_in_use = 0;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++) {
        effect_rays += t->rays[e];
        pools_in_use += t->final.pools_in_use[e];
    }
    printf("%u viewer%s (%llu viewer-frames), %u frames on %s%s%s\n", t->viewers_seen, t->viewers_seen == 1 ? "" : "s",
           (unsigned long long)t->viewer_frames, t->frames, s->source, o->no_cache ? " (no cache)" : "",
           stop_requested ? " (interrupted)" : "");
    printf("effects:   ");
    for (uint32_t e = 0; e < srv_loop_effect_count(loop); e++)
        if (srv_loop_effect(loop, e)->shade)
            printf(" %s %s;", srv_loop_effect(loop, e)->name, srv_loop_effect_on(loop, e) ? "on" : "off");
    printf("\n");
    for (uint32_t e = 0; e < srv_loop_effect_count(loop); e++)
        if (srv_loop_effect(loop, e)->shade && !srv_loop_effect_on(loop, e))
            printf("  left out %s: %s\n", srv_loop_effect(loop, e)->name, reasons[e]);
    const char *extra_name;
    const json_t *extra_reason;
    json_object_foreach((json_t *)left_out_extra, extra_name, extra_reason)
        printf("  left out %s: %s\n", extra_name, json_string_value(extra_reason));
    if (o->no_cache)
        printf("texels:     none (no cache: every pixel traces its own rays)\n");
    else if (!t->unique)
        printf("texels:     none requested (no viewer saw a surface)\n");
    else
        printf("texels:     %llu requested, %llu unique: sharing ratio %.2f\n", (unsigned long long)t->requested,
               (unsigned long long)t->unique, (double)t->requested / (double)t->unique);
    if (srv_loop_probe_cell(loop) > 0) {
        printf("probes:     %llu requested, %llu unique: sharing ratio %.2f; finest cell %g m\n",
               (unsigned long long)t->world_requested, (unsigned long long)t->world_unique,
               t->world_unique ? (double)t->world_requested / (double)t->world_unique : 0.0,
               (double)srv_loop_probe_cell(loop));
        printf("world:      %llu bricks, %.1f MiB, table load %.2f, %llu points refused, local tables answered "
               "%.1f %% of reads\n",
               (unsigned long long)t->world_last.bricks_resident, t->world_last.bytes / 1048576.0,
               t->world_last.table_capacity ? (double)t->world_last.entries / (double)t->world_last.table_capacity : 0.0,
               (unsigned long long)t->world_refusals,
               t->world_local_lookups ? 100.0 * (double)t->world_local_hits / (double)t->world_local_lookups : 0.0);
    } else if (!o->no_cache) {
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
        printf("%s%s %.1f", stg ? ", " : "", srv_stage_name((srv_stage)stg), t->frames ? t->time_ms[stg] / t->frames : 0.0);
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

/* ---- the run ----------------------------------------------------------------------------------------------- */

int srv_cmd_sim(int argc, char **argv)
{
    sim_options o = {.viewers = 4, .frames = 30, .width = 640, .height = 360, .seed = 1, .pool_mb = 64,
                     .camera = SRV_CAMGEN_ROOM, .fps = 30};
    int rc = parse_options(argc, argv, &o);
    if (rc >= 0)
        return rc;
    srv_trace *traces[MAX_TRACES] = {0};
    record_sink recorder = {.fps = o.fps};
    uint32_t index_of_slot[SRV_MAX_VIEWERS];
    srv_viewer_id ids[SRV_MAX_VIEWERS] = {{0}};
    bool joined[SRV_MAX_VIEWERS] = {false}, left[SRV_MAX_VIEWERS] = {false};
    scene *s = NULL;
    scene_rt *rt = NULL;
    srv_loop *loop = NULL;
    srv_report *report = NULL;
    stats_sink stats = {0};
    json_t *left_out_extra = json_object();
    int exit_code = 1;
    char err[512];
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        index_of_slot[v] = UINT32_MAX;

    /* Traces: each viewer joins at its first time and leaves after its last, on one clock at --fps. */
    double start_time = 0;
    if (o.trace_count) {
        o.viewers = o.trace_count;
        double first = INFINITY, last = -INFINITY;
        for (uint32_t i = 0; i < o.trace_count; i++) {
            traces[i] = srv_trace_read(o.traces[i], err, sizeof err);
            if (!traces[i]) {
                fprintf(stderr, "fxcache sim: %s\n", err);
                goto done;
            }
            first = fmin(first, srv_trace_first_time(traces[i]));
            last = fmax(last, srv_trace_last_time(traces[i]));
        }
        start_time = first;
        if (!o.frames_set) {
            double span = (last - first) * o.fps;
            o.frames = span < 1e6 ? (uint32_t)floor(span + 1e-6) + 1 : 1000000;
        }
    }
    recorder.start_time = start_time;
    /* Memory: the pools and every viewer's buffers (at its trace's resolution, if it records one) within the
     * machine's physical memory, before anything is loaded. */
    uint64_t pixels = 0;
    for (uint32_t v = 0; v < o.viewers; v++) {
        uint32_t w = o.width, h = o.height;
        if (traces[v] && !o.res_set)
            srv_trace_resolution(traces[v], &w, &h);
        pixels += (uint64_t)w * h;
    }
    if (!srv_cli_check_memory("sim", o.no_cache ? 0 : o.pool_mb, o.viewers, pixels, o.views)) {
        exit_code = 2;
        goto done;
    }
    signal(SIGINT, on_signal); /* from here on: a signal during the load ends the run after it */
    signal(SIGTERM, on_signal);
    s = srv_cli_load_scene("sim", o.scene_path, (float)o.density);
    if (stop_requested) {
        exit_code = srv_cli_interrupted("sim", stop_requested, "while loading the scene");
        goto done;
    }
    if (!s)
        goto done;
    scene_error serr = {0};
    double bvh_ms = 0;
    rt = scene_rt_create(s, &bvh_ms, &serr);
    if (!rt) {
        fprintf(stderr, "fxcache sim: %s\n", serr.msg);
        goto done;
    }
    char reasons[SRV_MAX_EFFECTS][200];
    srv_loop_desc desc = {.s = s, .rt = rt, .pool_bytes = (uint64_t)(o.pool_mb * 1048576.0),
                          .ray_budget = (uint64_t)o.ray_budget, .samples_per_update = o.ao_step,
                          .no_cache = o.no_cache, .seed = o.seed, .threads = o.threads, .keep_views = o.views,
                          .probe_cell = (float)o.probe_cell, .probe_rays = o.probe_rays,
                          .probe_hysteresis = (float)o.probe_hysteresis, .probe_budget = o.probe_budget,
                          .no_local_table = o.no_local_table};
    if (!choose_effects(s, o.effects, desc.effect_on, reasons, left_out_extra)) {
        exit_code = 2;
        goto done;
    }
    memcpy(desc.bias, o.bias, sizeof desc.bias);
    memcpy(desc.bias_set, o.bias_set, sizeof desc.bias_set);
    fxc_result r = srv_loop_create(&desc, &loop, err, sizeof err);
    if (r != FXC_OK) {
        fprintf(stderr, "fxcache sim: %s\n", err);
        goto done;
    }
    report = srv_report_create(loop);
    if (!report) {
        fprintf(stderr, "fxcache sim: out of memory\n");
        goto done;
    }
    if (o.out_dir && !make_dir(o.out_dir))
        goto done;
    image_sink images = {.o = &o, .last_frame = o.frames - 1};
    if (o.out_dir)
        srv_loop_add_sink(loop, &(srv_sink){.viewer_frame = image_sink_frame, .user = &images});
    if (o.stats_path) {
        stats = (stats_sink){.file = fopen(o.stats_path, "w"), .loop = loop, .report = report};
        if (!stats.file) {
            fprintf(stderr, "fxcache sim: cannot write %s: %s\n", o.stats_path, strerror(errno));
            goto done;
        }
        srv_loop_add_sink(loop, &(srv_sink){.frame_done = stats_sink_done, .user = &stats});
    }
    if (o.record_dir) {
        if (!make_dir(o.record_dir))
            goto done;
        recorder.index_of_slot = index_of_slot;
        srv_loop_add_sink(loop, &(srv_sink){.viewer_frame = record_sink_frame, .user = &recorder});
    }
    srv_sink report_sink = srv_report_sink(report);
    srv_loop_add_sink(loop, &report_sink);

    bool progress = isatty(STDERR_FILENO);
    uint32_t frame = 0;
    for (; frame < o.frames && !stop_requested; frame++) {
        double now = start_time + frame / o.fps;
        /* Stage 1: viewers join and leave, then every present viewer gets its camera. */
        for (uint32_t v = 0; v < o.viewers; v++) {
            bool present = !traces[v] || (srv_trace_first_time(traces[v]) <= now + SRV_TRACE_TIME_EPSILON &&
                                          now <= srv_trace_last_time(traces[v]) + SRV_TRACE_TIME_EPSILON);
            if (traces[v] && !present && joined[v] && !left[v]) {
                srv_viewer_remove(loop, ids[v]);
                left[v] = true;
                continue;
            }
            if (!present || left[v])
                continue;
            if (!joined[v]) {
                srv_viewer_desc vd = {.width = o.width, .height = o.height};
                if (traces[v] && !o.res_set)
                    srv_trace_resolution(traces[v], &vd.width, &vd.height);
                else if (traces[v] && srv_trace_resolution(traces[v], &vd.width, &vd.height) &&
                         (vd.width != o.width || vd.height != o.height))
                    fprintf(stderr, "fxcache sim: note: %s records %ux%u; that is used for its viewer, not --res\n",
                            o.traces[v], vd.width, vd.height);
                snprintf(vd.name, sizeof vd.name, "viewer_%02u", v);
                r = srv_viewer_add(loop, &vd, &ids[v]);
                if (r != FXC_OK) {
                    fprintf(stderr, "fxcache sim: viewer %u: %s\n", v, fxc_strerror(r));
                    goto done;
                }
                joined[v] = true;
                index_of_slot[ids[v].id & 0xFFu] = v;
                if (o.record_dir) {
                    char path[1024];
                    snprintf(path, sizeof path, "%s/viewer_%02u.trace", o.record_dir, v);
                    recorder.writers[v] = srv_trace_writer_open_sized(path, s, vd.width, vd.height, err, sizeof err);
                    if (!recorder.writers[v]) {
                        fprintf(stderr, "fxcache sim: %s\n", err);
                        goto done;
                    }
                }
            }
            srv_camera cam = traces[v] ? srv_trace_camera_at(traces[v], s, now)
                                       : srv_camgen_camera(o.camera, s, v, o.viewers, frame, o.seed);
            r = srv_viewer_set_camera(loop, ids[v], &cam);
            if (r != FXC_OK) {
                fprintf(stderr, "fxcache sim: frame %u, viewer %u: %s\n", frame, v, fxc_strerror(r));
                goto done;
            }
        }
        srv_frame_stats st;
        if (srv_loop_frame(loop, &st) != FXC_OK)
            goto done; /* a sink could not write: it said why */
        if (progress)
            fprintf(stderr, "\rframe %u/%u  %u viewers  %.1f ms  sharing %.2f   ", frame + 1, o.frames, st.viewer_count,
                    st.frame_ms, st.unique_texels ? (double)st.requested_texels / (double)st.unique_texels : 0.0);
    }
    if (progress)
        fputc('\n', stderr);
    const srv_report_totals *tot = srv_report_get_totals(report);
    if (tot->exhausted > 0)
        fprintf(stderr, "fxcache sim: warning: the block pools (--pool-mb %g) were too small for the requests of one "
                        "frame %llu times; the run went on degraded (%llu visible pixels composed without cached "
                        "data)\n",
                o.pool_mb, (unsigned long long)tot->exhausted, (unsigned long long)tot->pixels_missing);
    if (stop_requested && o.out_dir && frame > 0) {
        /* Interrupted: the last finished frame of every viewer still present. */
        srv_viewer_id present[SRV_MAX_VIEWERS];
        uint32_t n = srv_loop_viewers(loop, present, SRV_MAX_VIEWERS);
        for (uint32_t i = 0; i < n; i++) {
            uint32_t w = 0, h = 0;
            srv_viewer_size(loop, present[i], &w, &h);
            uint32_t v = index_of_slot[present[i].id & 0xFFu];
            char name[32];
            snprintf(name, sizeof name, "viewer_%02u", v);
            srv_viewer_frame vf = {.id = present[i], .name = name, .frame = frame - 1, .width = w, .height = h,
                                   .srgb = srv_viewer_image(loop, present[i])};
            for (int k = 0; k < SRV_VIEW_COUNT; k++)
                vf.views[k] = srv_viewer_view(loop, present[i], k);
            if (vf.srgb)
                save_viewer_frame(&o, &vf, o.viewers);
        }
    }

    /* The summary: the run's options, then the report's totals. */
    json_t *sum = json_object();
    json_object_set_new(sum, "scene", json_string(s->source));
    json_object_set_new(sum, "precision_warning",
                        s->precision_warning[0] ? json_string(s->precision_warning) : json_null());
    json_object_set_new(sum, "viewers", json_integer(o.viewers));
    json_object_set_new(sum, "frames_requested", json_integer(o.frames));
    json_object_set_new(sum, "interrupted", json_boolean(stop_requested));
    char res[32];
    snprintf(res, sizeof res, "%ux%u", o.width, o.height);
    json_object_set_new(sum, "resolution", json_string(res));
    json_object_set_new(sum, "no_cache", json_boolean(o.no_cache));
    json_object_set_new(sum, "camera", json_string(o.trace_count ? "trace" : srv_camgen_name(o.camera)));
    if (o.trace_count)
        json_object_set_new(sum, "fps", json_real(o.fps));
    json_object_set_new(sum, "seed", json_integer(o.seed));
    json_object_set_new(sum, "pool_mb", json_real(o.pool_mb));
    json_object_set_new(sum, "ray_budget", json_integer((json_int_t)o.ray_budget));
    if (srv_loop_probe_cell(loop) > 0)
        json_object_set_new(sum, "probes",
                            json_pack("{s:f,s:I,s:f,s:I,s:b}", "cell_m", (double)srv_loop_probe_cell(loop), "rays",
                                      (json_int_t)srv_loop_desc_of(loop)->probe_rays, "hysteresis",
                                      (double)srv_loop_desc_of(loop)->probe_hysteresis, "budget",
                                      (json_int_t)srv_loop_desc_of(loop)->probe_budget, "local_tables",
                                      !o.no_local_table));
    else
        json_object_set_new(sum, "world_space_cache",
                            json_string(o.no_cache ? "none: no cache at all (--no-cache)"
                                                   : "not created: no effect that runs lives in it (nothing allocated)"));
    json_t *effects = json_object(), *left_out = json_object(), *bias = json_object();
    for (uint32_t e = 0; e < srv_loop_effect_count(loop); e++) {
        const char *name = srv_loop_effect(loop, e)->name;
        bool on = srv_loop_effect_on(loop, e);
        json_object_set_new(on ? effects : left_out, name, json_string(reasons[e]));
        if (on && srv_loop_effect(loop, e)->shade)
            json_object_set_new(bias, name, json_integer(srv_loop_bias(loop, e)));
    }
    json_object_update(left_out, left_out_extra);
    json_object_set_new(sum, "effects", effects);
    json_object_set_new(sum, "left_out", left_out);
    json_object_set_new(sum, "level_bias", bias);
    json_t *totals = srv_report_json(report);
    json_object_update(sum, totals);
    json_decref(totals);
    json_object_set_new(sum, "bvh_build_ms", json_real(bvh_ms));
    if (o.summary_path) {
        FILE *sf = fopen(o.summary_path, "w");
        bool written = sf && json_dumpf(sum, sf, JSON_INDENT(2) | JSON_PRESERVE_ORDER) == 0;
        int saved = errno;
        if (sf && fclose(sf) != 0)
            written = false;
        if (!written) {
            fprintf(stderr, "fxcache sim: cannot write %s: %s\n", o.summary_path, strerror(saved ? saved : EIO));
            json_decref(sum);
            goto done;
        }
    }
    json_decref(sum);
    if (!o.quiet)
        print_summary(&o, s, loop, report, (const char(*)[200])reasons, left_out_extra);
    exit_code = 0;
done:
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        if (recorder.writers[v] && srv_trace_writer_close(recorder.writers[v]) != 0 && exit_code == 0) {
            fprintf(stderr, "fxcache sim: writing a trace failed\n");
            exit_code = 1;
        }
    for (uint32_t i = 0; i < MAX_TRACES; i++)
        srv_trace_free(traces[i]);
    if (stats.file && fclose(stats.file) != 0 && exit_code == 0) {
        fprintf(stderr, "fxcache sim: writing %s failed: %s\n", o.stats_path, strerror(errno));
        exit_code = 1;
    }
    json_decref(left_out_extra);
    srv_report_free(report);
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
    return exit_code;
}
