/* `fxcache sim`: several viewers in one process with no network, driven through the same engine
 * (engine.h) the networked server uses. Viewers are added with their own resolution; cameras come from a
 * generator or from viewer traces, whose viewers join at their trace's first time and leave after its last
 * (paced by --fps). The run's results go out through sinks: frames and effect views as images (--out), one
 * JSON line of statistics per frame (--stats), trace recording (--record) and the run report, whose totals
 * make the summary (--summary, and in words on stdout). SIGINT and SIGTERM end the run within a tile of the
 * current frame (abandoned: srv_loop_set_stop), with the summary and every file of the finished frames. */
#include "camgen.h"
#include "cli_cameras.h"
#include "cli.h"
#include "cli_engine.h"
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

static volatile sig_atomic_t stop_requested = 0;

/* The first signal asks for the end: the frame in progress is abandoned within a tile (srv_loop_set_stop),
 * the files of the finished frames are written; a second ends at once (the default action). */
static void on_signal(int sig)
{
    stop_requested = sig;
    signal(sig, SIG_DFL);
}

typedef struct sim_options {
    srv_cli_engine engine;
    srv_cli_view_options view; /* --viewers, --frames, --res, --camera, --trace, --fps */
    const char *out_dir;
    uint32_t save_every;
    bool views;
    const char *stats_path;
    const char *summary_path;
    const char *record_dir;
    bool quiet;
} sim_options;

static const char sim_usage[] =
    "usage: fxcache sim [options]\n"
    "\n"
    "Runs several simulated viewers on one scene in one process: per frame, visibility for every viewer,\n"
    "requests deduplicated into the shared caches, effect updates within a ray budget, and a composed\n"
    "image per viewer. Prints a summary in words.\n"
    "\n"
    "  --viewers N          viewers, 1..64 (default 4, or one per --trace)\n"
    "  --frames F           frames, 1..1000000 (default 30, or until the last trace ends: traces\n"
    "                       lasting more frames need --frames)\n"
    "  --res WxH            resolution per viewer, sides 1..8192 (default 640x360; a version 2 trace's own\n"
    "                       resolution wins for its viewer unless --res is given)\n"
    "  --camera GEN         camera generator when no --trace is given (default room):\n"
    "                       %s\n"
    "  --trace FILE         a viewer trace (repeat once per viewer; see docs/TRACE_FORMAT.md): the viewer\n"
    "                       joins at its first time and leaves after its last\n"
    "  --fps F              frames per second of trace time when replaying, [0.001, 1000] (default 30)\n"
    "  --record DIR         write the cameras each viewer was rendered for as DIR/viewer_NN.trace\n"
    "                       (version 2, with the resolution; replay with --trace)\n"
    "  --out DIR            write frames as DIR/frame_FFFF_viewer_VV.png\n"
    "  --save-every K       frames to save: every K-th and the last, 0..1000000 (default 0: only the\n"
    "                       last)\n"
    "  --views              with --out: also AO and shadow as linear EXR, and a picture of how many\n"
    "                       viewers requested the blocks each pixel reads (_sharing.png)\n"
    "  --stats FILE         one JSON line of statistics per frame\n"
    "  --summary FILE       one JSON object at the end (time_ms: sums over the run; time_ms_per_frame)\n"
    "  --quiet              no summary in words on stdout\n";

static int parse_options(int argc, char **argv, sim_options *o)
{
    enum { O_OUT = SRV_CLI_O_COMMAND, O_SAVE, O_VIEWS, O_STATS, O_SUMMARY, O_RECORD, O_QUIET };
    static const struct option own[] = {
        SRV_CLI_VIEW_OPTIONS,
        {"out", required_argument, NULL, O_OUT},
        {"save-every", required_argument, NULL, O_SAVE},
        {"views", no_argument, NULL, O_VIEWS},
        {"stats", required_argument, NULL, O_STATS},
        {"summary", required_argument, NULL, O_SUMMARY},
        {"record", required_argument, NULL, O_RECORD},
        {"quiet", no_argument, NULL, O_QUIET},
        {"help", no_argument, NULL, 'h'},
    };
    struct option options[sizeof own / sizeof own[0] + 32];
    srv_cli_merge_options(own, sizeof own / sizeof own[0], options, sizeof options / sizeof options[0]);
    for (int c; (c = getopt_long(argc, argv, ":h", options, NULL)) != -1;) {
        int known = srv_cli_run_option("sim", c, optarg, &o->engine, &o->view);
        if (known == 0)
            return 2;
        if (known == 1)
            continue;
        bool ok = true;
        switch (c) {
        case O_OUT: o->out_dir = srv_cli_dir_arg(optarg); break;
        case O_SAVE: ok = srv_cli_u32("sim", "--save-every", optarg, 0, 1000000, &o->save_every); break;
        case O_VIEWS: o->views = true; break;
        case O_STATS: o->stats_path = optarg; break;
        case O_SUMMARY: o->summary_path = optarg; break;
        case O_RECORD: o->record_dir = srv_cli_dir_arg(optarg); break;
        case O_QUIET: o->quiet = true; break;
        case 'h': {
            char names[256];
            srv_cli_effect_names(names, sizeof names);
            printf(sim_usage, srv_camgen_list());
            printf(srv_cli_engine_usage, names);
            printf(
                "  -h, --help           this text\n"
                "\n"
                "SIGINT or SIGTERM during the scene's load: one line, nothing written, exit 128 + signal;\n"
                "during the frames: the current frame is abandoned within a tile (about 0.1 s), then\n"
                "the statistics and traces of the finished frames, the last finished frame's images\n"
                "(unless the signal came during the next frame's compose: a note says so) and the\n"
                "summary (interrupted: true) are written; a second signal ends the run at once.\n"
                "Exit status: 0 done or interrupted during the frames, 1 a failure (scene, trace, writing\n"
                "files), 2 bad options or a run larger than the machine's memory.\n");
            return 0;
        }
        default: return srv_cli_getopt_error("sim", c, argv);
        }
        if (!ok)
            return 2;
    }
    if (!srv_cli_no_operands("sim", argc, argv))
        return 2;
    if (!srv_cli_view_check("sim", &o->view))
        return 2;
    if (o->views && !o->out_dir) {
        fprintf(stderr, "fxcache sim: --views needs --out DIR\n");
        return 2;
    }
    return -1;
}

static bool make_dir(const char *path)
{
    return srv_cli_make_dir("sim", path);
}

/* ---- sinks ----------------------------------------------------------------------------------------------- */

/* Images: the chosen frames of every viewer, as PNG (and the effect views with --views). */
typedef struct image_sink {
    const sim_options *o;
    uint32_t last_frame; /* the run's last frame (always saved) */
    bool force;          /* save whatever frame comes (after an interruption) */
    bool failed;         /* a write failed and said so: the frame's other viewers write nothing more */
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
    bool chosen =
        sink->force || vf->frame == sink->last_frame || (o->save_every && vf->frame % o->save_every == 0);
    if (sink->failed)
        return -1; /* one line for the run (the loop still hands over the frame's other viewers) */
    if (!chosen || stop_requested) /* an interrupted run saves its last frame afterwards */
        return 0;
    sink->failed = !save_viewer_frame(o, vf, o->view.viewers);
    return sink->failed ? -1 : 0;
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

/* ---- the run ----------------------------------------------------------------------------------------------- */

int srv_cmd_sim(int argc, char **argv)
{
    sim_options o = {.view = srv_cli_view_defaults()};
    srv_cli_engine_defaults(&o.engine);
    int rc = parse_options(argc, argv, &o);
    if (rc >= 0)
        return rc;
    srv_cli_cameras cams = {0};
    record_sink recorder = {.fps = o.view.fps};
    uint32_t index_of_slot[SRV_MAX_VIEWERS];
    srv_viewer_id ids[SRV_MAX_VIEWERS] = {{0}};
    bool joined[SRV_MAX_VIEWERS] = {false}, left[SRV_MAX_VIEWERS] = {false};
    srv_cli_run run = {0};
    srv_cli_stats stats = {0};
    int exit_code = 1;
    char err[512];
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        index_of_slot[v] = UINT32_MAX;

    /* Traces: each viewer joins at its first time and leaves after its last, on one clock at --fps. */
    if (!srv_cli_cameras_load("sim", &cams, &o.view, o.engine.seed))
        goto done;
    if (o.view.trace_count) {
        o.view.viewers = o.view.trace_count;
        if (!o.view.frames_set &&
            !srv_cli_cameras_frames_fit("sim", &cams, o.view.frames_max, &o.view.frames)) {
            exit_code = 2;
            goto done;
        }
    }
    recorder.start_time = cams.start_time;
    /* Memory: the pools and every viewer's buffers (at its trace's resolution, if it records one) within the
     * machine's physical memory, before anything is loaded. */
    uint64_t pixels = 0;
    for (uint32_t v = 0; v < o.view.viewers; v++) {
        uint32_t w, h;
        srv_cli_cameras_size(&cams, v, &w, &h);
        pixels += (uint64_t)w * h;
    }
    if (!srv_cli_check_memory("sim", o.engine.no_cache ? 0 : o.engine.pool_mb, o.view.viewers, pixels,
                              o.views)) {
        exit_code = 2;
        goto done;
    }
    /* Output folders (after the memory check: a refused run creates none; a --summary or --stats path may
     * lie in them), then the files' folders: a path that cannot be written is found before the scene loads. */
    if ((o.out_dir && !make_dir(o.out_dir)) || (o.record_dir && !make_dir(o.record_dir)))
        goto done;
    if ((o.stats_path && !srv_cli_output_file_ok("sim", "--stats", o.stats_path)) ||
        (o.summary_path && !srv_cli_output_file_ok("sim", "--summary", o.summary_path)) ||
        !srv_cli_output_files_differ("sim", "--stats", o.stats_path, "--summary", o.summary_path))
        goto done;
    signal(SIGINT, on_signal); /* from here on: a signal during the load ends the run after it */
    signal(SIGTERM, on_signal);
    exit_code = srv_cli_run_open("sim", &o.engine, o.views, &run, &stop_requested);
    if (exit_code >= 0)
        goto done;
    exit_code = 1;
    const scene *s = run.s;
    if (!srv_cli_cameras_check("sim", &cams, s))
        goto done;
    srv_loop *loop = run.loop;
    srv_loop_set_stop(loop, &stop_requested); /* a signal ends a long frame within a tile */
    fxc_result r;
    image_sink images = {.o = &o, .last_frame = o.view.frames - 1};
    if (o.out_dir)
        srv_loop_add_sink(loop, &(srv_sink){.viewer_frame = image_sink_frame, .user = &images});
    if (o.stats_path && !srv_cli_stats_open(&stats, &run, o.stats_path))
        goto done;
    if (o.record_dir) {
        recorder.index_of_slot = index_of_slot;
        srv_loop_add_sink(loop, &(srv_sink){.viewer_frame = record_sink_frame, .user = &recorder});
    }

    bool progress = isatty(STDERR_FILENO);
    uint32_t frame = 0;
    for (; frame < o.view.frames && !stop_requested; frame++) {
        /* Stage 1: viewers join and leave, then every present viewer gets its camera. */
        for (uint32_t v = 0; v < o.view.viewers; v++) {
            bool traced = cams.traces[v] != NULL, present = srv_cli_cameras_present(&cams, v, frame);
            if (traced && !present && joined[v] && !left[v]) {
                srv_viewer_remove(loop, ids[v]);
                left[v] = true;
                continue;
            }
            if (!present || left[v])
                continue;
            if (!joined[v]) {
                srv_viewer_desc vd = {0};
                srv_cli_cameras_size(&cams, v, &vd.width, &vd.height);
                uint32_t tw, th;
                if (traced && o.view.res_set && srv_trace_resolution(cams.traces[v], &tw, &th) &&
                    (tw != o.view.width || th != o.view.height))
                    fprintf(stderr,
                            "fxcache sim: note: %s records %ux%u; --res %ux%u is used for its viewer\n",
                            o.view.traces[v], tw, th, o.view.width, o.view.height);
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
                    recorder.writers[v] =
                        srv_trace_writer_open_sized(path, s, vd.width, vd.height, err, sizeof err);
                    if (!recorder.writers[v]) {
                        fprintf(stderr, "fxcache sim: %s\n", err);
                        goto done;
                    }
                }
            }
            srv_camera cam;
            uint32_t w, h;
            srv_cli_cameras_get(&cams, s, frame, v, &cam, &w, &h);
            r = srv_viewer_set_camera(loop, ids[v], &cam);
            if (r != FXC_OK) {
                fprintf(stderr, "fxcache sim: frame %u, viewer %u: %s\n", frame, v, fxc_strerror(r));
                goto done;
            }
        }
        srv_frame_stats st;
        r = srv_loop_frame(loop, &st);
        if (r == FXC_ERR_SHUTDOWN)
            break; /* a signal: the frame was abandoned within a tile (not counted, no sink saw it) */
        if (r != FXC_OK)
            goto done; /* a sink could not write: it said why */
        if (progress)
            fprintf(stderr, "\rframe %u/%u  %u viewers  %.1f ms  sharing %.2f   ", frame + 1, o.view.frames,
                    st.viewer_count, st.frame_ms,
                    st.unique_texels ? (double)st.requested_texels / (double)st.unique_texels : 0.0);
    }
    if (progress)
        fputc('\n', stderr);
    srv_cli_warn_exhausted(&run, &o.engine);
    if (stop_requested && o.out_dir && frame > 0) {
        /* Interrupted: the last finished frame of every viewer still present (gone when the signal came
         * during the next frame's compose: then one line says so). */
        srv_viewer_id present[SRV_MAX_VIEWERS];
        uint32_t n = srv_loop_viewers(loop, present, SRV_MAX_VIEWERS), lost = 0;
        for (uint32_t i = 0; i < n; i++) {
            uint32_t w = 0, h = 0;
            srv_viewer_size(loop, present[i], &w, &h);
            uint32_t v = index_of_slot[present[i].id & 0xFFu];
            char name[32];
            snprintf(name, sizeof name, "viewer_%02u", v);
            srv_viewer_frame vf = {.id = present[i],
                                   .name = name,
                                   .frame = frame - 1,
                                   .width = w,
                                   .height = h,
                                   .srgb = srv_viewer_image(loop, present[i])};
            for (int k = 0; k < SRV_VIEW_COUNT; k++)
                vf.views[k] = srv_viewer_view(loop, present[i], k);
            lost += !vf.srgb;
            if (vf.srgb && !save_viewer_frame(&o, &vf, o.view.viewers)) {
                images.failed = true; /* it said why; the summary is still written, the exit code is 1 */
                break;
            }
        }
        if (lost)
            fprintf(stderr,
                    "fxcache sim: note: interrupted during frame %u's compose: frame %u's images of %u "
                    "viewer%s were partly overwritten and are not saved\n",
                    frame, frame - 1, lost, lost == 1 ? "" : "s");
    }

    /* The summary: the run's options, then the report's totals. */
    json_t *sum = srv_cli_summary_json(&run, &o.engine);
    json_object_set_new(sum, "viewers", json_integer(o.view.viewers));
    json_object_set_new(sum, "frames_requested", json_integer(o.view.frames));
    json_object_set_new(sum, "interrupted", json_boolean(stop_requested));
    srv_cli_cameras_summary_resolution(&cams, o.view.viewers, sum);
    json_object_set_new(sum, "camera",
                        json_string(o.view.trace_count ? "trace" : srv_camgen_name(o.view.camera)));
    if (o.view.trace_count)
        json_object_set_new(sum, "fps", json_real(o.view.fps));
    bool written = !o.summary_path || srv_cli_write_json("sim", o.summary_path, sum);
    json_decref(sum);
    if (!written)
        goto done;
    if (!o.quiet)
        srv_cli_print_summary(&run, o.engine.no_cache, stop_requested);
    exit_code = images.failed ? 1 : 0;
done:
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        if (recorder.writers[v] && srv_trace_writer_close(recorder.writers[v]) != 0 && exit_code == 0) {
            fprintf(stderr, "fxcache sim: writing a trace failed\n");
            exit_code = 1;
        }
    srv_cli_cameras_free(&cams);
    if (!srv_cli_stats_close(&stats) && exit_code == 0)
        exit_code = 1;
    srv_cli_run_close(&run);
    return exit_code;
}
