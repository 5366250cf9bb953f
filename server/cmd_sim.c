/* `fxcache sim`: several viewers in one process with no network, driven through the same frame loop
 * (frame.h) the networked server uses. Cameras come from a generator or from viewer traces; the run writes
 * one JSON line of statistics per frame (--stats), a summary object at the end (--summary) and in words on
 * stdout, chosen frames as PNG (--out), and optionally each effect's own image. SIGINT and SIGTERM end the
 * run after the current frame, with the summary and every file complete. */
#include "camgen.h"
#include "cli.h"
#include "frame.h"
#include "image.h"
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
    const char *effects;
    int32_t bias[SCENE_FX_COUNT];
    bool bias_set[SCENE_FX_COUNT];
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
    bool quiet;
} sim_options;

static const char sim_usage[] =
    "usage: fxcache sim [options]\n"
    "\n"
    "Runs several simulated viewers on one scene in one process: per frame, visibility for every viewer,\n"
    "requests deduplicated into one shared on-surface cache, effect updates (hard shadows, ambient\n"
    "occlusion) within a ray budget, and a composed image per viewer. Prints a summary in words.\n"
    "\n"
    "  --scene PATH         *.json description, a mesh file, or 'default' (the embedded scene; default)\n"
    "  --viewers N          viewers, 1..64 (default 4, or one per --trace)\n"
    "  --frames F           frames, 1..1000000 (default 30, or the longest trace)\n"
    "  --res WxH            resolution per viewer, sides 1..8192 (default 640x360)\n"
    "  --effects auto|LIST  'auto': what the scene needs; or a comma list of shadow,ao (default auto)\n"
    "  --bias EFFECT=L      level bias of shadow or ao in levels, -4..8 (coarser is positive; repeatable;\n"
    "                       defaults: shadow 0, ao 1)\n"
    "  --pool-mb MB         block-pool memory for all effects, 1..65536 (default 64)\n"
    "  --ray-budget R       effect rays per frame, 0 = unlimited (default 0)\n"
    "  --ao-step S          AO samples added per texel and update, 1..64 (default 16)\n"
    "  --no-cache           the baseline: every effect per pixel per frame at the converged sample counts\n"
    "  --camera GEN         camera generator when no --trace is given (default room): %s\n"
    "  --trace FILE         a viewer trace (repeat once per viewer; see docs/TRACE_FORMAT.md)\n"
    "  --record DIR         write the cameras used as traces DIR/viewer_NN.trace (replay with --trace)\n"
    "  --seed S             random seed, 0..4294967295 (default 1)\n"
    "  --threads T          worker threads, 0 = all cores (default 0)\n"
    "  --density D          level-0 texels per metre, [1e-6, 1e6] (default: the scene's, else auto)\n"
    "  --out DIR            write frames as DIR/frame_FFFF_viewer_VV.png\n"
    "  --save-every K       frames to save: every K-th and the last (default 0: only the last)\n"
    "  --views              with --out: also AO and shadow as linear EXR, and a picture of how many\n"
    "                       viewers requested each pixel's AO block (_sharing.png)\n"
    "  --stats FILE         one JSON line of statistics per frame\n"
    "  --summary FILE       one JSON object at the end (time_ms: sums over the run; time_ms_per_frame)\n"
    "  --quiet              no summary in words on stdout\n"
    "  -h, --help           this text\n";

/* Parses --bias EFFECT=LEVELS. */
static bool parse_bias(const char *text, sim_options *o)
{
    const char *eq = text ? strchr(text, '=') : NULL;
    if (!eq) {
        fprintf(stderr, "fxcache sim: --bias: '%s' is not EFFECT=LEVELS (effects: shadow, ao)\n", text ? text : "");
        return false;
    }
    size_t n = (size_t)(eq - text);
    int fx = -1;
    if (n == 6 && strncmp(text, "shadow", 6) == 0)
        fx = SCENE_FX_SHADOW;
    else if (n == 2 && strncmp(text, "ao", 2) == 0)
        fx = SCENE_FX_AO;
    if (fx < 0) {
        fprintf(stderr, "fxcache sim: --bias: unknown effect '%.*s' (effects: shadow, ao)\n", (int)n, text);
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
    const char *p = list;
    for (;;) {
        const char *comma = strchr(p, ',');
        size_t n = comma ? (size_t)(comma - p) : strlen(p);
        bool known = (n == 6 && strncmp(p, "shadow", 6) == 0) || (n == 7 && strncmp(p, "shadows", 7) == 0) ||
                     (n == 2 && strncmp(p, "ao", 2) == 0);
        if (!known) {
            fprintf(stderr, "fxcache sim: --effects: '%.*s' in '%s' is not an effect (auto, or a comma list of shadow,ao)\n",
                    (int)n, p, list);
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
           O_DENSITY, O_QUIET };
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
        {"help", no_argument, NULL, 'h'},                {NULL, 0, NULL, 0},
    };
    optind = 1;
    opterr = 0;
    for (int c; (c = getopt_long(argc, argv, ":h", options, NULL)) != -1;) {
        bool ok = true;
        switch (c) {
        case O_SCENE: o->scene_path = optarg; break;
        case O_VIEWERS: ok = srv_cli_u32("sim", "--viewers", optarg, 1, SRV_MAX_VIEWERS, &o->viewers); o->viewers_set = true; break;
        case O_FRAMES: ok = srv_cli_u32("sim", "--frames", optarg, 1, 1000000, &o->frames); o->frames_set = true; break;
        case O_RES: ok = srv_cli_resolution("sim", "--res", optarg, 8192, &o->width, &o->height); break;
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
        case 'h': printf(sim_usage, srv_camgen_list()); return 0;
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

/* Decides which effects run: the scene's needs, narrowed by --effects; fills reasons for the summary. */
static bool choose_effects(const scene *s, const char *list, bool effect_on[SCENE_FX_COUNT],
                           char reasons[SCENE_FX_COUNT][200])
{
    scene_needs_result needs;
    scene_needs(s, &needs);
    bool wanted[SCENE_FX_COUNT] = {false};
    bool automatic = !list || strcmp(list, "auto") == 0;
    if (!automatic) {
        char buf[256];
        snprintf(buf, sizeof buf, "%s", list);
        for (char *save = NULL, *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
            if (strcmp(tok, "shadow") == 0 || strcmp(tok, "shadows") == 0)
                wanted[SCENE_FX_SHADOW] = true;
            else if (strcmp(tok, "ao") == 0)
                wanted[SCENE_FX_AO] = true;
            else {
                fprintf(stderr, "fxcache sim: --effects: unknown effect '%s' (auto, or a list of shadow,ao)\n", tok);
                return false;
            }
        }
    }
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
        effect_on[fx] = false;
        if (fx == SCENE_FX_TRIANGLE_LOOKUP)
            continue;
        if (fx == SCENE_FX_PROBES) {
            snprintf(reasons[fx], 200, "%s; but probes are not implemented yet (the world-space cache is a later "
                                       "issue)",
                     needs.effect_reason[fx]);
            continue;
        }
        if (!needs.effect[fx]) {
            snprintf(reasons[fx], 200, "%s", needs.effect_reason[fx]);
            continue;
        }
        if (!automatic && !wanted[fx]) {
            snprintf(reasons[fx], 200, "not in --effects %s", list);
            continue;
        }
        effect_on[fx] = true;
        snprintf(reasons[fx], 200, "%s", needs.effect_reason[fx]);
    }
    effect_on[SCENE_FX_TRIANGLE_LOOKUP] = effect_on[SCENE_FX_SHADOW] || effect_on[SCENE_FX_AO];
    snprintf(reasons[SCENE_FX_TRIANGLE_LOOKUP], 200, "%s",
             effect_on[SCENE_FX_TRIANGLE_LOOKUP] ? "needed by the on-surface effects" : "no on-surface effect runs");
    return true;
}

static bool make_dir(const char *path)
{
    if (mkdir(path, 0755) == 0 || errno == EEXIST)
        return true;
    fprintf(stderr, "fxcache sim: cannot create folder %s: %s\n", path, strerror(errno));
    return false;
}

/* Cumulative figures over the run. */
typedef struct sim_totals {
    uint64_t requested, unique, visibility_rays, pixels_visible, pixels_missing;
    uint64_t rays[SCENE_FX_COUNT], texels_updated[SCENE_FX_COUNT], resampled[SCENE_FX_COUNT],
        deferred[SCENE_FX_COUNT];
    double time_ms[SRV_STAGE_COUNT], frame_ms;
    srv_memory peak;
    uint32_t frames;
    uint64_t exhausted; /* cumulative failed requests (pool exhausted), from the cache */
} sim_totals;

static json_t *memory_json(const srv_memory *m)
{
    json_t *per_effect = json_object();
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
        if (!m->pools_reserved[fx] && !m->block_meta[fx])
            continue;
        json_object_set_new(per_effect, scene_effect_name((scene_effect)fx),
                            json_pack("{s:I,s:I,s:I}", "pool_reserved", (json_int_t)m->pools_reserved[fx],
                                      "pool_in_use", (json_int_t)m->pools_in_use[fx], "block_meta",
                                      (json_int_t)m->block_meta[fx]));
    }
    return json_pack("{s:I,s:I,s:I,s:o,s:I}", "table", (json_int_t)m->table, "viewers", (json_int_t)m->viewers,
                     "queues", (json_int_t)m->queues, "effects", per_effect, "total", (json_int_t)m->total);
}

static json_t *rays_json(const uint64_t rays[SCENE_FX_COUNT], uint64_t visibility)
{
    return json_pack("{s:I,s:I,s:I,s:I}", "visibility", (json_int_t)visibility, "shadow",
                     (json_int_t)rays[SCENE_FX_SHADOW], "ao", (json_int_t)rays[SCENE_FX_AO], "effects_total",
                     (json_int_t)(rays[SCENE_FX_SHADOW] + rays[SCENE_FX_AO]));
}

static json_t *stage_json(const double time_ms[SRV_STAGE_COUNT], double frame_ms)
{
    json_t *o = json_object();
    for (int st = 0; st < SRV_STAGE_COUNT; st++)
        json_object_set_new(o, srv_stage_name((srv_stage)st), json_real(time_ms[st]));
    json_object_set_new(o, "frame", json_real(frame_ms));
    return o;
}

static json_t *frame_json(const srv_frame_stats *st, uint32_t viewers, const srv_memory *mem)
{
    json_t *per_viewer = json_array();
    for (uint32_t v = 0; v < viewers; v++)
        json_array_append_new(per_viewer, json_integer((json_int_t)st->viewer_requested[v]));
    json_t *o = json_object();
    json_object_set_new(o, "frame", json_integer(st->frame));
    json_object_set_new(o, "requested_texels", json_integer((json_int_t)st->requested_texels));
    json_object_set_new(o, "viewer_requested_texels", per_viewer);
    json_object_set_new(o, "unique_texels", json_integer((json_int_t)st->unique_texels));
    json_object_set_new(o, "sharing_ratio", st->unique_texels
                                                ? json_real((double)st->requested_texels / (double)st->unique_texels)
                                                : json_null());
    json_object_set_new(o, "rays", rays_json(st->rays, st->visibility_rays));
    json_object_set_new(o, "texels_updated", json_pack("{s:I,s:I}", "shadow", (json_int_t)st->texels_updated[SCENE_FX_SHADOW],
                                                       "ao", (json_int_t)st->texels_updated[SCENE_FX_AO]));
    json_object_set_new(o, "texels_resampled", json_pack("{s:I,s:I}", "shadow", (json_int_t)st->texels_resampled[SCENE_FX_SHADOW],
                                                         "ao", (json_int_t)st->texels_resampled[SCENE_FX_AO]));
    json_object_set_new(o, "texels_deferred", json_pack("{s:I,s:I}", "shadow", (json_int_t)st->texels_deferred[SCENE_FX_SHADOW],
                                                        "ao", (json_int_t)st->texels_deferred[SCENE_FX_AO]));
    json_object_set_new(o, "blocks_resident",
                        json_pack("{s:I,s:I,s:I}", "triangle_lookup", (json_int_t)st->blocks_resident[0], "shadow",
                                  (json_int_t)st->blocks_resident[SCENE_FX_SHADOW], "ao",
                                  (json_int_t)st->blocks_resident[SCENE_FX_AO]));
    json_object_set_new(o, "pixels_visible", json_integer((json_int_t)st->pixels_visible));
    json_object_set_new(o, "pixels_missing", json_integer((json_int_t)st->pixels_missing));
    json_object_set_new(o, "table_load",
                        json_real(st->table_capacity ? (double)st->table_count / st->table_capacity : 0.0));
    json_object_set_new(o, "evictions", json_integer((json_int_t)st->evictions));
    json_object_set_new(o, "pool_exhausted", json_integer((json_int_t)st->exhausted));
    json_object_set_new(o, "memory_bytes", memory_json(mem));
    json_object_set_new(o, "time_ms", stage_json(st->time_ms, st->frame_ms));
    return o;
}

/* Writes one viewer's frame (and its effect views) under the output folder. */
static bool save_frame(const sim_options *o, const srv_loop *loop, uint32_t frame, uint32_t viewer)
{
    char path[1024], msg[512];
    snprintf(path, sizeof path, "%s/frame_%04u_viewer_%02u.png", o->out_dir, frame, viewer);
    if (scene_image_write_u8(path, o->width, o->height, 3, srv_loop_image(loop, viewer), msg, sizeof msg) != 0) {
        fprintf(stderr, "fxcache sim: %s\n", msg);
        return false;
    }
    if (!o->views)
        return true;
    static const char *const names[SRV_VIEW_COUNT] = {"ao", "shadow", "sharing"};
    for (int w = 0; w < SRV_VIEW_COUNT; w++) {
        const float *img = srv_loop_view(loop, viewer, w);
        if (!img)
            continue;
        int rc;
        if (w == SRV_VIEW_SHARING) {
            /* Grey levels: black = nobody (sky, or no data), then brighter for each more viewer. */
            size_t n = (size_t)o->width * o->height;
            uint8_t *grey = malloc(n);
            if (!grey)
                return false;
            for (size_t i = 0; i < n; i++)
                grey[i] = (uint8_t)(img[i] <= 0 ? 0 : 40 + (215.0f * img[i]) / (float)o->viewers);
            snprintf(path, sizeof path, "%s/frame_%04u_viewer_%02u_sharing.png", o->out_dir, frame, viewer);
            rc = scene_image_write_u8(path, o->width, o->height, 1, grey, msg, sizeof msg);
            free(grey);
        } else {
            snprintf(path, sizeof path, "%s/frame_%04u_viewer_%02u_%s.exr", o->out_dir, frame, viewer, names[w]);
            rc = scene_image_write_f32(path, o->width, o->height, 1, img, msg, sizeof msg);
        }
        if (rc != 0) {
            fprintf(stderr, "fxcache sim: %s\n", msg);
            return false;
        }
    }
    return true;
}

static void add_memory_peak(srv_memory *peak, const srv_memory *m)
{
    if (m->total > peak->total)
        *peak = *m;
}

int srv_cmd_sim(int argc, char **argv)
{
    sim_options o = {.viewers = 4, .frames = 30, .width = 640, .height = 360, .seed = 1, .pool_mb = 64,
                     .camera = SRV_CAMGEN_ROOM};
    int rc = parse_options(argc, argv, &o);
    if (rc >= 0)
        return rc;
    uint32_t viewer_count = o.trace_count ? o.trace_count : o.viewers;
    if (!srv_cli_check_memory("sim", o.no_cache ? 0 : o.pool_mb, viewer_count, o.width, o.height, o.views))
        return 2;
    signal(SIGINT, on_signal); /* from here on: a signal during the load ends the run after it */
    signal(SIGTERM, on_signal);
    srv_trace *traces[MAX_TRACES] = {0};
    srv_trace_writer *records[SRV_MAX_VIEWERS] = {0};
    scene *s = NULL;
    scene_rt *rt = NULL;
    srv_loop *loop = NULL;
    FILE *stats_file = NULL;
    srv_camera *cameras = NULL;
    int exit_code = 1;
    char err[512];

    if (o.trace_count) {
        o.viewers = o.trace_count;
        uint32_t longest = 0;
        for (uint32_t i = 0; i < o.trace_count; i++) {
            traces[i] = srv_trace_read(o.traces[i], err, sizeof err);
            if (!traces[i]) {
                fprintf(stderr, "fxcache sim: %s\n", err);
                goto done;
            }
            longest = srv_trace_count(traces[i]) > longest ? srv_trace_count(traces[i]) : longest;
        }
        if (!o.frames_set)
            o.frames = longest;
    }
    s = srv_cli_load_scene("sim", o.scene_path, (float)o.density);
    if (stop_requested)
        exit_code = srv_cli_interrupted("sim", stop_requested, "while loading the scene");
    if (!s || stop_requested)
        goto done;
    scene_error serr = {0};
    double bvh_ms = 0;
    rt = scene_rt_create(s, &bvh_ms, &serr);
    if (!rt) {
        fprintf(stderr, "fxcache sim: %s\n", serr.msg);
        goto done;
    }
    char reasons[SCENE_FX_COUNT][200];
    srv_loop_desc desc = {.s = s, .rt = rt, .viewer_count = o.viewers, .width = o.width, .height = o.height,
                          .pool_bytes = (uint64_t)(o.pool_mb * 1048576.0), .ray_budget = (uint64_t)o.ray_budget,
                          .ao_samples_per_frame = o.ao_step, .no_cache = o.no_cache, .seed = o.seed,
                          .threads = o.threads, .keep_views = o.views};
    if (!choose_effects(s, o.effects, desc.effect_on, reasons)) {
        exit_code = 2;
        goto done;
    }
    memcpy(desc.bias, o.bias, sizeof desc.bias);
    memcpy(desc.bias_set, o.bias_set, sizeof desc.bias_set);
    loop = srv_loop_create(&desc, err, sizeof err);
    if (!loop) {
        fprintf(stderr, "fxcache sim: %s\n", err);
        goto done;
    }
    if (o.out_dir && !make_dir(o.out_dir))
        goto done;
    if (o.record_dir) {
        if (!make_dir(o.record_dir))
            goto done;
        for (uint32_t v = 0; v < o.viewers; v++) {
            char path[1024];
            snprintf(path, sizeof path, "%s/viewer_%02u.trace", o.record_dir, v);
            records[v] = srv_trace_writer_open(path, err, sizeof err);
            if (!records[v]) {
                fprintf(stderr, "fxcache sim: %s\n", err);
                goto done;
            }
        }
    }
    if (o.stats_path && !(stats_file = fopen(o.stats_path, "w"))) {
        fprintf(stderr, "fxcache sim: cannot write %s: %s\n", o.stats_path, strerror(errno));
        goto done;
    }
    cameras = calloc(o.viewers, sizeof *cameras);
    if (!cameras)
        goto done;
    bool progress = isatty(STDERR_FILENO);
    sim_totals tot = {0};
    srv_memory mem = {0};
    uint32_t frame = 0;
    for (; frame < o.frames && !stop_requested; frame++) {
        for (uint32_t v = 0; v < o.viewers; v++) {
            cameras[v] = traces[v] ? srv_trace_camera(traces[v], frame)
                                   : srv_camgen_camera(o.camera, s, v, o.viewers, frame, o.seed);
            if (records[v] && srv_trace_writer_add(records[v], traces[v] ? srv_trace_time(traces[v], frame) : frame / 30.0,
                                                   &cameras[v]) != 0) {
                fprintf(stderr, "fxcache sim: %s\n", srv_trace_writer_error(records[v]));
                goto done;
            }
        }
        srv_frame_stats st;
        if (!srv_loop_frame(loop, cameras, &st, err, sizeof err)) {
            fprintf(stderr, "fxcache sim: frame %u: %s\n", frame, err);
            goto done;
        }
        srv_loop_memory(loop, &mem);
        add_memory_peak(&tot.peak, &mem);
        tot.requested += st.requested_texels;
        tot.unique += st.unique_texels;
        tot.visibility_rays += st.visibility_rays;
        tot.pixels_visible += st.pixels_visible;
        tot.pixels_missing += st.pixels_missing;
        for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
            tot.rays[fx] += st.rays[fx];
            tot.texels_updated[fx] += st.texels_updated[fx];
            tot.resampled[fx] += st.texels_resampled[fx];
            tot.deferred[fx] += st.texels_deferred[fx];
        }
        for (int stg = 0; stg < SRV_STAGE_COUNT; stg++)
            tot.time_ms[stg] += st.time_ms[stg];
        tot.frame_ms += st.frame_ms;
        tot.frames++;
        tot.exhausted = st.exhausted;
        if (stats_file) {
            json_t *line = frame_json(&st, o.viewers, &mem);
            json_dumpf(line, stats_file, JSON_COMPACT | JSON_PRESERVE_ORDER);
            fputc('\n', stats_file);
            fflush(stats_file);
            json_decref(line);
        }
        bool last = frame + 1 == o.frames;
        if (o.out_dir && (last || (o.save_every && frame % o.save_every == 0)))
            for (uint32_t v = 0; v < o.viewers; v++)
                if (!save_frame(&o, loop, frame, v))
                    goto done;
        if (progress)
            fprintf(stderr, "\rframe %u/%u  %.1f ms  sharing %.2f  effect rays %llu   ", frame + 1, o.frames, st.frame_ms,
                    st.unique_texels ? (double)st.requested_texels / (double)st.unique_texels : 0.0,
                    (unsigned long long)(st.rays[SCENE_FX_SHADOW] + st.rays[SCENE_FX_AO]));
    }
    if (progress)
        fputc('\n', stderr);
    if (tot.exhausted > 0)
        fprintf(stderr, "fxcache sim: warning: the block pools (--pool-mb %g) were too small for the requests of one "
                        "frame %llu times; the run went on degraded (%llu visible pixels composed without cached "
                        "data)\n",
                o.pool_mb, (unsigned long long)tot.exhausted, (unsigned long long)tot.pixels_missing);
    if (stop_requested && o.out_dir && frame > 0)
        for (uint32_t v = 0; v < o.viewers; v++)
            save_frame(&o, loop, frame - 1, v);

    /* The summary. */
    json_t *sum = json_object();
    json_object_set_new(sum, "scene", json_string(s->source));
    json_object_set_new(sum, "viewers", json_integer(o.viewers));
    json_object_set_new(sum, "frames", json_integer(tot.frames));
    json_object_set_new(sum, "frames_requested", json_integer(o.frames));
    json_object_set_new(sum, "interrupted", json_boolean(stop_requested));
    char res[32];
    snprintf(res, sizeof res, "%ux%u", o.width, o.height);
    json_object_set_new(sum, "resolution", json_string(res));
    json_object_set_new(sum, "no_cache", json_boolean(o.no_cache));
    json_object_set_new(sum, "camera", json_string(o.trace_count ? "trace" : srv_camgen_name(o.camera)));
    json_object_set_new(sum, "seed", json_integer(o.seed));
    json_object_set_new(sum, "pool_mb", json_real(o.pool_mb));
    json_object_set_new(sum, "ray_budget", json_integer((json_int_t)o.ray_budget));
    json_t *effects = json_object(), *left_out = json_object(), *bias = json_object();
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
        const char *name = scene_effect_name((scene_effect)fx);
        json_object_set_new(desc.effect_on[fx] ? effects : left_out, name, json_string(reasons[fx]));
        if (desc.effect_on[fx] && fx != SCENE_FX_TRIANGLE_LOOKUP)
            json_object_set_new(bias, name, json_integer(srv_loop_bias(loop, (scene_effect)fx)));
    }
    json_object_set_new(sum, "effects", effects);
    json_object_set_new(sum, "left_out", left_out);
    json_object_set_new(sum, "level_bias", bias);
    json_object_set_new(sum, "requested_texels", json_integer((json_int_t)tot.requested));
    json_object_set_new(sum, "unique_texels", json_integer((json_int_t)tot.unique));
    /* No cache, or nothing visible: nothing is requested, so there is no ratio (null, not 0). */
    json_object_set_new(sum, "sharing_ratio",
                        tot.unique ? json_real((double)tot.requested / (double)tot.unique) : json_null());
    json_object_set_new(sum, "rays", rays_json(tot.rays, tot.visibility_rays));
    json_object_set_new(sum, "texels_updated", json_pack("{s:I,s:I}", "shadow", (json_int_t)tot.texels_updated[SCENE_FX_SHADOW],
                                                         "ao", (json_int_t)tot.texels_updated[SCENE_FX_AO]));
    json_object_set_new(sum, "texels_resampled", json_pack("{s:I,s:I}", "shadow", (json_int_t)tot.resampled[SCENE_FX_SHADOW],
                                                           "ao", (json_int_t)tot.resampled[SCENE_FX_AO]));
    json_object_set_new(sum, "texels_deferred", json_pack("{s:I,s:I}", "shadow", (json_int_t)tot.deferred[SCENE_FX_SHADOW],
                                                          "ao", (json_int_t)tot.deferred[SCENE_FX_AO]));
    json_object_set_new(sum, "pixels_visible", json_integer((json_int_t)tot.pixels_visible));
    json_object_set_new(sum, "pixels_missing", json_integer((json_int_t)tot.pixels_missing));
    json_object_set_new(sum, "pool_exhausted", json_integer((json_int_t)tot.exhausted));
    json_object_set_new(sum, "memory_bytes", json_pack("{s:o,s:o}", "peak", memory_json(&tot.peak), "final", memory_json(&mem)));
    json_object_set_new(sum, "time_ms", stage_json(tot.time_ms, tot.frame_ms)); /* sums over the run */
    double per_frame[SRV_STAGE_COUNT];
    for (int stg = 0; stg < SRV_STAGE_COUNT; stg++)
        per_frame[stg] = tot.frames ? tot.time_ms[stg] / tot.frames : 0.0;
    json_object_set_new(sum, "time_ms_per_frame", stage_json(per_frame, tot.frames ? tot.frame_ms / tot.frames : 0.0));
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
    if (!o.quiet) {
        uint64_t effect_rays = tot.rays[SCENE_FX_SHADOW] + tot.rays[SCENE_FX_AO];
        printf("%u viewers, %u frames of %ux%u on %s%s%s\n", o.viewers, tot.frames, o.width, o.height, s->source,
               o.no_cache ? " (no cache)" : "", stop_requested ? " (interrupted)" : "");
        printf("effects:   ");
        for (int fx = SCENE_FX_SHADOW; fx < SCENE_FX_COUNT; fx++)
            printf(" %s %s;", scene_effect_name((scene_effect)fx), desc.effect_on[fx] ? "on" : "off");
        printf("\n");
        for (int fx = SCENE_FX_SHADOW; fx < SCENE_FX_COUNT; fx++)
            if (!desc.effect_on[fx])
                printf("  left out %s: %s\n", scene_effect_name((scene_effect)fx), reasons[fx]);
        if (o.no_cache)
            printf("texels:     none (no cache: every pixel traces its own rays)\n");
        else if (!tot.unique)
            printf("texels:     none requested (no viewer saw a surface)\n");
        else
            printf("texels:     %llu requested, %llu unique: sharing ratio %.2f\n", (unsigned long long)tot.requested,
                   (unsigned long long)tot.unique, (double)tot.requested / (double)tot.unique);
        printf("rays:       %llu visibility, %llu shadow, %llu AO (%.0f effect rays per frame)\n",
               (unsigned long long)tot.visibility_rays, (unsigned long long)tot.rays[SCENE_FX_SHADOW],
               (unsigned long long)tot.rays[SCENE_FX_AO], tot.frames ? (double)effect_rays / tot.frames : 0.0);
        printf("memory:     %.1f MiB peak, %.1f MiB final (pools in use %.1f MiB)\n", tot.peak.total / 1048576.0,
               mem.total / 1048576.0,
               (mem.pools_in_use[0] + mem.pools_in_use[1] + mem.pools_in_use[2]) / 1048576.0);
        printf("time:       %.1f ms per frame (", tot.frames ? tot.frame_ms / tot.frames : 0.0);
        for (int stg = 0; stg < SRV_STAGE_COUNT; stg++)
            printf("%s%s %.1f", stg ? ", " : "", srv_stage_name((srv_stage)stg),
                   tot.frames ? tot.time_ms[stg] / tot.frames : 0.0);
        printf(")\n");
        if (tot.pixels_missing)
            printf("note:       %llu of %llu visible pixels were composed before their texels held data\n",
                   (unsigned long long)tot.pixels_missing, (unsigned long long)tot.pixels_visible);
    }
    exit_code = 0;
done:
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        if (records[v] && srv_trace_writer_close(records[v]) != 0 && exit_code == 0) {
            fprintf(stderr, "fxcache sim: writing a trace failed\n");
            exit_code = 1;
        }
    for (uint32_t i = 0; i < MAX_TRACES; i++)
        srv_trace_free(traces[i]);
    if (stats_file)
        fclose(stats_file);
    free(cameras);
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
    return exit_code;
}
