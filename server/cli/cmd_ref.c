/* `fxcache ref`: reference images for measuring the error of cached frames (DESIGN.md "Error against run
 * time"). The cameras are those `fxcache sim` renders with the same options (a generator with the same seed,
 * or viewer traces on sim's clock), named by sim's frame numbers; each image goes through the reference
 * renderer (server/engine/reference.h) and out as linear EXR, display PNG and a record in DIR/ref.json
 * (rewritten after every image, so whatever is done is on disk). SIGINT and SIGTERM end the run after the
 * current image. */
#include "camgen.h"
#include "cli_cameras.h"
#include "cli.h"
#include "cli_engine.h"
#include "image.h"
#include "reference.h"
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

/* The first signal asks for the end after the current image; the second ends at once (default action). */
static void on_signal(int sig)
{
    stop_requested = sig;
    signal(sig, SIG_DFL);
}

/* The sample options and the effects they set (by name: the table says what a sample is). */
enum { SAMPLE_AO = 0, SAMPLE_SHADOW, SAMPLE_PATHS, SAMPLE_OPTIONS };
static const struct {
    const char *option, *effect;
    uint32_t max;
} sample_options[SAMPLE_OPTIONS] = {
    {"--ao-samples", "ao", 1048576},
    {"--shadow-rays", "shadow", 65536},
    {"--paths", "probes", 65536},
};

typedef struct ref_options {
    srv_cli_engine engine;     /* --scene, --effects, --seed, --threads */
    srv_cli_view_options view; /* --viewers, --frames, --res, --camera, --trace, --fps */
    const char *out_dir;
    uint32_t every;
    bool views, quiet;
    uint32_t samples[SAMPLE_OPTIONS]; /* 0: the effect's default */
    uint32_t max_bounces;
} ref_options;

static const char ref_usage[] =
    "usage: fxcache ref --out DIR [options]\n"
    "\n"
    "Renders reference images for measuring the error of cached frames: compose's shading model (albedo;\n"
    "lights with their shadows over the pixel's footprint; the sky with ambient occlusion; the probes'\n"
    "indirect light, which carries the sky and emitting materials' light; a visible emitter's own emission)\n"
    "with every term computed per pixel, no cache, enough samples to be converged. Each pixel is rendered\n"
    "as two halves with independent samples; the image is their mean,\n"
    "and its noise, RMSE(half 0 - half 1) / 2, is the standard error of its pixels (RMS over the image),\n"
    "printed and recorded for every image.\n"
    "\n"
    "Cameras: the frames 'fxcache sim' renders with the same options, named by sim's frame numbers.\n"
    "  --trace FILE         a viewer trace (repeat once per viewer, as in sim): frame f is at time\n"
    "                       start + f / fps (start: the earliest first time of the traces); a viewer is in\n"
    "                       the frames from its first time to its last, with the last camera line not\n"
    "                       after the frame's time\n"
    "  --fps F              frames per second of trace time, [0.001, 1000] (default 30)\n"
    "  --camera GEN         camera generator when no --trace is given (default room):\n"
    "                       %s\n"
    "  --viewers N          viewers of the generator, 1..64 (default 4)\n"
    "  --frames F           frames, 1..1000000 (default 30, or until the last trace ends: traces\n"
    "                       lasting more frames need --frames)\n"
    "  --every K            render frames 0, K, 2K, ... and the last: what 'sim --out DIR --save-every K'\n"
    "                       saves, 0..1000000 (default 0: only the last frame)\n"
    "  --res WxH            resolution, sides 1..8192 (default 640x360; a version 2 trace's own resolution\n"
    "                       wins for its viewer unless --res is given, as in sim)\n"
    "Samples per pixel (each half takes half of them):\n"
    "  --ao-samples N       ambient-occlusion rays, even, 2..1048576 (default 1024)\n"
    "  --shadow-rays N      shadow rays per light, jittered over the pixel's footprint in sets of 16\n"
    "                       stratified rays: a multiple of 32, 32..65536 (default 256)\n"
    "  --paths N            indirect-light paths (next-event estimation of the lights at every vertex, the\n"
    "                       sky where a path escapes, Russian roulette), even, 2..65536 (default 256)\n"
    "  --max-bounces B      path vertices at most, 0..256 (default 0: Russian roulette ends the paths;\n"
    "                       1: one bounce, as 'sim --no-cache' estimates indirect light)\n"
    "Output:\n"
    "  --out DIR            frame_FFFF_viewer_VV.exr (linear RGB float), frame_FFFF_viewer_VV.png (display:\n"
    "                       sim's tone map and sRGB), and ref.json (the options; per image its time, rays,\n"
    "                       noise and mean radiance), rewritten after every image; one run at a time\n"
    "                       per folder (another run writing it is refused)\n"
    "  --views              also the AO term and the lit fraction of light 0 as _ao.exr and _shadow.exr\n"
    "                       (as 'sim --views')\n"
    "  --quiet              no line per image on stdout\n"
    "As in sim:\n"
    "  --scene PATH         *.json description, a mesh file, or 'default' (the embedded scene; default)\n"
    "  --effects auto|LIST  'auto': what the scene needs; or a comma list of %s (default auto): the\n"
    "                       terms in the image, as the cached frames have them\n"
    "  --seed S             random seed, 0..4294967295 (default 1): the generators' cameras (sim's) and\n"
    "                       the samples\n"
    "  --threads T          worker threads, 0..256, 0 = all cores (default 0); the images do not depend\n"
    "                       on it\n"
    "  -h, --help           this text\n"
    "\n"
    "Progress goes to stderr when it is a terminal. SIGINT or SIGTERM: the current image is finished and\n"
    "written, ref.json says interrupted, exit 0; a second signal ends at once.\n"
    "Exit status: 0 done, 1 a failure (scene, trace, writing files), 2 bad options.\n";

/* Checks a sample count against its effect's granule: each half takes half, in whole sets. */
static bool samples_valid(uint32_t option, uint32_t value)
{
    uint32_t count = 0;
    const fx_effect *const *effects = fx_registry(&count);
    int32_t e = fx_find(effects, count, sample_options[option].effect);
    uint32_t granule = e >= 0 && effects[e]->reference_granule ? effects[e]->reference_granule : 1;
    if (value % (2 * granule) == 0)
        return true;
    if (granule == 1)
        fprintf(stderr, "fxcache ref: %s: '%u' is odd: each of the two halves takes half\n",
                sample_options[option].option, value);
    else
        fprintf(stderr,
                "fxcache ref: %s: '%u' is not a multiple of %u: each of the two halves takes whole sets "
                "of %u\n",
                sample_options[option].option, value, 2 * granule, granule);
    return false;
}

static int parse_options(int argc, char **argv, ref_options *o)
{
    enum { O_OUT = SRV_CLI_O_COMMAND, O_EVERY, O_VIEWS, O_QUIET, O_AO, O_SHADOW, O_PATHS, O_BOUNCES };
    static const struct option own[] = {
        SRV_CLI_VIEW_OPTIONS,
        {"out", required_argument, NULL, O_OUT},
        {"every", required_argument, NULL, O_EVERY},
        {"views", no_argument, NULL, O_VIEWS},
        {"quiet", no_argument, NULL, O_QUIET},
        {"ao-samples", required_argument, NULL, O_AO},
        {"shadow-rays", required_argument, NULL, O_SHADOW},
        {"paths", required_argument, NULL, O_PATHS},
        {"max-bounces", required_argument, NULL, O_BOUNCES},
        {"help", no_argument, NULL, 'h'},
    };
    /* Of the engine's options, those that mean something here. */
    static const int shared[] = {SRV_CLI_O_SCENE, SRV_CLI_O_EFFECTS, SRV_CLI_O_SEED, SRV_CLI_O_THREADS};
    struct option options[sizeof own / sizeof own[0] + sizeof shared / sizeof shared[0] + 1];
    size_t n = sizeof own / sizeof own[0];
    memcpy(options, own, sizeof own);
    for (size_t i = 0; i < srv_cli_engine_option_count; i++)
        for (size_t j = 0; j < sizeof shared / sizeof shared[0]; j++)
            if (srv_cli_engine_options[i].val == shared[j])
                options[n++] = srv_cli_engine_options[i];
    options[n] = (struct option){NULL, 0, NULL, 0};
    optind = 1;
    opterr = 0;
    for (int c; (c = getopt_long(argc, argv, ":h", options, NULL)) != -1;) {
        int known = srv_cli_run_option("ref", c, optarg, &o->engine, &o->view);
        if (known == 0)
            return 2;
        if (known == 1)
            continue;
        bool ok = true;
        switch (c) {
        case O_OUT: o->out_dir = srv_cli_dir_arg(optarg); break;
        case O_EVERY: ok = srv_cli_u32("ref", "--every", optarg, 0, 1000000, &o->every); break;
        case O_VIEWS: o->views = true; break;
        case O_QUIET: o->quiet = true; break;
        case O_AO:
        case O_SHADOW:
        case O_PATHS: {
            uint32_t which = c == O_AO ? SAMPLE_AO : c == O_SHADOW ? SAMPLE_SHADOW : SAMPLE_PATHS;
            ok = srv_cli_u32("ref", sample_options[which].option, optarg, which == SAMPLE_SHADOW ? 32 : 2,
                             sample_options[which].max, &o->samples[which]) &&
                 samples_valid(which, o->samples[which]);
            break;
        }
        case O_BOUNCES:
            ok = srv_cli_u32("ref", "--max-bounces", optarg, 0, FX_PATH_MAX_VERTICES, &o->max_bounces);
            break;
        case 'h': {
            char names[256];
            srv_cli_effect_names(names, sizeof names);
            printf(ref_usage, srv_camgen_list(), names);
            return 0;
        }
        default: return srv_cli_getopt_error("ref", c, argv);
        }
        if (!ok)
            return 2;
    }
    if (!srv_cli_no_operands("ref", argc, argv))
        return 2;
    if (!o->out_dir) {
        fprintf(stderr, "fxcache ref: --out DIR is required (where the images and ref.json go)\n");
        return 2;
    }
    if (!srv_cli_view_check("ref", &o->view))
        return 2;
    return -1;
}

/* ---- the cameras: sim's frames --------------------------------------------------------------------------- */

/* Whether frame f is one to render: sim --save-every's choice. */
static bool frame_chosen(const ref_options *o, uint32_t frame)
{
    return frame == o->view.frames - 1 || (o->every && frame % o->every == 0);
}

/* ---- output -------------------------------------------------------------------------------------------- */

/* Writes ref.json whole through a temporary file and a rename, so a reader never sees half of it. */
static bool write_record(const ref_options *o, const json_t *root)
{
    char path[1024], tmp[1040];
    snprintf(path, sizeof path, "%s/ref.json", o->out_dir);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    if (!srv_cli_write_json("ref", tmp, root))
        return false;
    if (rename(tmp, path) != 0) {
        fprintf(stderr, "fxcache ref: cannot write %s: %s\n", path, strerror(errno));
        return false;
    }
    return true;
}

/* A camera in world coordinates, as a trace line holds it. */
static json_t *camera_json(const scene *s, const srv_camera *cam)
{
    double position[3];
    scene_local_to_world(s, cam->position, position);
    json_t *dir = json_array(), *pos = json_array();
    for (int k = 0; k < 3; k++) {
        json_array_append_new(pos, json_real(position[k]));
        json_array_append_new(dir, json_real((double)cam->target[k] - (double)cam->position[k]));
    }
    return json_pack("{s:o,s:o,s:f}", "position", pos, "direction", dir, "fov_deg", (double)cam->fov_deg);
}

/* The image buffers, grown to the largest image. */
typedef struct ref_buffers {
    size_t pixels;
    float *radiance, *ao, *shadow;
    uint8_t *srgb;
} ref_buffers;

static bool buffers_reserve(ref_buffers *b, size_t pixels, bool views)
{
    if (pixels <= b->pixels)
        return true;
    free(b->radiance);
    free(b->ao);
    free(b->shadow);
    free(b->srgb);
    memset(b, 0, sizeof *b);
    b->radiance = malloc(pixels * 3 * sizeof(float));
    b->srgb = malloc(pixels * 3);
    if (views) {
        b->ao = malloc(pixels * sizeof(float));
        b->shadow = malloc(pixels * sizeof(float));
    }
    if (!b->radiance || !b->srgb || (views && (!b->ao || !b->shadow)))
        return false;
    b->pixels = pixels;
    return true;
}

static void buffers_free(ref_buffers *b)
{
    free(b->radiance);
    free(b->ao);
    free(b->shadow);
    free(b->srgb);
    memset(b, 0, sizeof *b);
}

/* Progress on stderr (a terminal only). */
typedef struct progress_line {
    uint32_t image, images, frame, viewer;
} progress_line;

static void show_progress(void *user, uint64_t done, uint64_t total)
{
    const progress_line *line = user;
    fprintf(stderr, "\rref: image %u/%u (frame %04u viewer %02u): %3.0f %%   ", line->image, line->images,
            line->frame, line->viewer, total ? 100.0 * (double)done / (double)total : 100.0);
}

/* ---- the run ------------------------------------------------------------------------------------------- */

int srv_cmd_ref(int argc, char **argv)
{
    ref_options o = {.view = srv_cli_view_defaults()};
    srv_cli_engine_defaults(&o.engine);
    int rc = parse_options(argc, argv, &o);
    if (rc >= 0)
        return rc;
    srv_cli_cameras cams = {0};
    scene *s = NULL;
    scene_rt *rt = NULL;
    srv_ref *ref = NULL;
    json_t *root = NULL, *left_out_extra = json_object();
    ref_buffers buffers = {0};
    int exit_code = 1;
    int lock = -1; /* the output folder's lock (srv_cli_lock_dir) */
    char err[512];

    /* Traces: sim's clock starts at the earliest first time; frames until the last trace ends. */
    if (!srv_cli_cameras_load("ref", &cams, &o.view, o.engine.seed))
        goto done;
    if (o.view.trace_count) {
        o.view.viewers = o.view.trace_count;
        if (!o.view.frames_set &&
            !srv_cli_cameras_frames_fit("ref", &cams, o.view.frames_max, &o.view.frames)) {
            exit_code = 2;
            goto done;
        }
    }
    /* Memory: the largest image's buffers within the machine's physical memory, before anything is loaded. */
    uint64_t largest = (uint64_t)o.view.width * o.view.height;
    for (uint32_t v = 0; v < o.view.trace_count; v++) {
        uint32_t w, h;
        srv_cli_cameras_size(&cams, v, &w, &h);
        if ((uint64_t)w * h > largest)
            largest = (uint64_t)w * h;
    }
    uint64_t per_pixel = SRV_REF_BYTES_PER_PIXEL + 12 + 3 + (o.views ? 8 : 0);
    uint64_t physical = srv_cli_physical_memory();
    if (physical && largest * per_pixel > physical) {
        fprintf(stderr,
                "fxcache ref: an image of %llu pixels needs %.0f MiB, more than this machine's %llu MiB of "
                "physical memory: lower --res\n",
                (unsigned long long)largest, (double)(largest * per_pixel) / 1048576.0,
                (unsigned long long)(physical >> 20));
        exit_code = 2;
        goto done;
    }
    signal(SIGINT, on_signal); /* from here on: a signal during the load ends the run after it */
    signal(SIGTERM, on_signal);
    s = srv_cli_load_scene("ref", o.engine.scene_path, 0.0f);
    if (stop_requested) {
        exit_code = srv_cli_interrupted("ref", stop_requested, "while loading the scene");
        goto done;
    }
    if (!s || !srv_cli_cameras_check("ref", &cams, s))
        goto done;
    scene_error serr = {0};
    rt = scene_rt_create(s, NULL, &serr);
    if (!rt) {
        fprintf(stderr, "fxcache ref: %s\n", serr.msg);
        goto done;
    }
    srv_ref_desc desc = {
        .s = s, .rt = rt, .seed = o.engine.seed, .threads = o.engine.threads, .max_bounces = o.max_bounces};
    char reasons[SRV_MAX_EFFECTS][200];
    if (!srv_cli_choose_effects("ref", s, o.engine.effects, desc.effect_on, reasons, left_out_extra)) {
        exit_code = 2;
        goto done;
    }
    uint32_t effect_count = 0;
    const fx_effect *const *effects = fx_registry(&effect_count);
    for (uint32_t i = 0; i < SAMPLE_OPTIONS; i++) {
        int32_t e = fx_find(effects, effect_count, sample_options[i].effect);
        if (e >= 0)
            desc.samples[e] = o.samples[i];
    }
    if (srv_ref_create(&desc, &ref, err, sizeof err) != FXC_OK) {
        fprintf(stderr, "fxcache ref: %s\n", err);
        goto done;
    }
    const srv_ref_desc *resolved = srv_ref_desc_of(ref);
    if (!srv_cli_make_dir("ref", o.out_dir) || (lock = srv_cli_lock_dir("ref", o.out_dir)) < 0)
        goto done;

    /* ref.json: the options, then one record per image. */
    root = json_object();
    json_object_set_new(root, "scene", json_string(s->source));
    json_object_set_new(root, "seed", json_integer(o.engine.seed));
    json_object_set_new(root, "threads", json_integer(o.engine.threads));
    json_object_set_new(root, "cameras",
                        json_string(o.view.trace_count ? "trace" : srv_camgen_name(o.view.camera)));
    json_t *trace_list = json_array();
    for (uint32_t i = 0; i < o.view.trace_count; i++)
        json_array_append_new(trace_list, json_string(o.view.traces[i]));
    json_object_set_new(root, "traces", trace_list);
    json_object_set_new(root, "viewers", json_integer(o.view.viewers));
    json_object_set_new(root, "frames", json_integer(o.view.frames));
    json_object_set_new(root, "every", json_integer(o.every));
    json_object_set_new(root, "fps", json_real(o.view.fps));
    json_object_set_new(root, "start_time_s", json_real(cams.start_time));
    srv_cli_cameras_summary_resolution(&cams, o.view.viewers, root);
    json_t *on = json_object(), *off = json_object(), *samples = json_object();
    for (uint32_t e = 0; e < effect_count; e++) {
        if (!effects[e]->shade)
            continue;
        json_object_set_new(desc.effect_on[e] ? on : off, effects[e]->name, json_string(reasons[e]));
        if (resolved->samples[e])
            json_object_set_new(
                samples, effects[e]->name,
                json_pack("{s:I,s:s}", "per_pixel", (json_int_t)resolved->samples[e], "unit",
                          effects[e]->reference_unit ? effects[e]->reference_unit : "samples"));
    }
    json_object_update(off, left_out_extra);
    json_object_set_new(root, "effects", on);
    json_object_set_new(root, "left_out", off);
    json_object_set_new(root, "samples", samples);
    json_object_set_new(root, "max_bounces", json_integer(o.max_bounces));
    json_object_set_new(
        root, "noise_definition",
        json_string("RMSE(half 0 - half 1) / 2 in linear radiance over every pixel and channel: "
                    "each half has half of every effect's samples and independent random "
                    "numbers and the image is their mean, so this is the standard error of "
                    "its pixels (RMS over the image); noise_rmse_visible is the same over "
                    "the pixels that see a surface"));
    json_object_set_new(root, "interrupted", json_false());
    json_t *images = json_array();
    json_object_set_new(root, "images", images);

    /* The images: sim's chosen frames, every viewer present in them. */
    uint32_t planned = 0;
    for (uint32_t f = 0; f < o.view.frames; f++)
        if (frame_chosen(&o, f))
            for (uint32_t v = 0; v < o.view.viewers; v++) {
                srv_camera cam;
                uint32_t w, h;
                planned += srv_cli_cameras_get(&cams, s, f, v, &cam, &w, &h);
            }
    json_object_set_new(root, "images_planned", json_integer(planned));
    if (!write_record(&o, root))
        goto done;
    bool progress = isatty(STDERR_FILENO);
    uint32_t done_images = 0;
    for (uint32_t f = 0; f < o.view.frames && !stop_requested; f++) {
        if (!frame_chosen(&o, f))
            continue;
        for (uint32_t v = 0; v < o.view.viewers && !stop_requested; v++) {
            srv_camera cam;
            uint32_t w, h;
            if (!srv_cli_cameras_get(&cams, s, f, v, &cam, &w, &h))
                continue;
            if (!buffers_reserve(&buffers, (size_t)w * h, o.views)) {
                fprintf(stderr, "fxcache ref: out of memory for a %ux%u image\n", w, h);
                goto done;
            }
            srv_ref_image out = {.radiance = buffers.radiance,
                                 .srgb = buffers.srgb,
                                 .ao = buffers.ao,
                                 .shadow = buffers.shadow};
            progress_line line = {.image = done_images + 1, .images = planned, .frame = f, .viewer = v};
            srv_ref_stats st;
            fxc_result r =
                srv_ref_render(ref, &cam, w, h, f, &out, &st, progress ? show_progress : NULL, &line);
            if (progress)
                fputc('\n', stderr);
            if (r != FXC_OK) {
                fprintf(stderr, "fxcache ref: frame %u, viewer %u: %s\n", f, v, fxc_strerror(r));
                goto done;
            }
            char base[1024], path[1100], msg[512];
            snprintf(base, sizeof base, "%s/frame_%04u_viewer_%02u", o.out_dir, f, v);
            snprintf(path, sizeof path, "%s.exr", base);
            bool written = scene_image_write_f32(path, w, h, 3, buffers.radiance, msg, sizeof msg) == 0;
            snprintf(path, sizeof path, "%s.png", base);
            written = written && scene_image_write_u8(path, w, h, 3, buffers.srgb, msg, sizeof msg) == 0;
            if (written && o.views) {
                snprintf(path, sizeof path, "%s_ao.exr", base);
                written = scene_image_write_f32(path, w, h, 1, buffers.ao, msg, sizeof msg) == 0;
                snprintf(path, sizeof path, "%s_shadow.exr", base);
                written =
                    written && scene_image_write_f32(path, w, h, 1, buffers.shadow, msg, sizeof msg) == 0;
            }
            if (!written) {
                fprintf(stderr, "fxcache ref: %s\n", msg);
                goto done;
            }
            json_t *rays = json_object();
            json_object_set_new(rays, "primary", json_integer((json_int_t)st.primary_rays));
            for (uint32_t e = 0; e < effect_count; e++)
                if (resolved->samples[e])
                    json_object_set_new(rays, effects[e]->name, json_integer((json_int_t)st.rays[e]));
            json_object_set_new(rays, "total", json_integer((json_int_t)st.rays_total));
            const char *name = strrchr(base, '/') + 1;
            json_t *image = json_pack(
                "{s:I,s:I,s:f,s:I,s:I,s:o,s:s+,s:s+,s:f,s:o,s:f,s:f,s:f,s:f,s:[f,f,f],s:I}", "frame",
                (json_int_t)f, "viewer", (json_int_t)v, "time_s", srv_cli_cameras_time(&cams, f), "width",
                (json_int_t)w, "height", (json_int_t)h, "camera", camera_json(s, &cam), "exr", name, ".exr",
                "png", name, ".png", "render_ms", st.render_ms, "rays", rays, "noise_rmse", st.noise_rmse,
                "noise_rmse_visible", st.noise_rmse_visible, "noise_ao", st.noise_ao, "noise_shadow",
                st.noise_shadow, "mean_radiance", st.mean_radiance[0], st.mean_radiance[1],
                st.mean_radiance[2], "pixels_visible", (json_int_t)st.pixels_visible);
            if (!image) { /* json_pack refuses a non-finite real: never drop the record silently */
                fprintf(stderr, "fxcache ref: frame %u, viewer %u: a statistic of the image is not finite\n",
                        f, v);
                goto done;
            }
            json_array_append_new(images, image);
            done_images++;
            if (!write_record(&o, root))
                goto done;
            if (!o.quiet)
                printf(
                    "frame %04u viewer %02u: %ux%u in %.1f s, %.1f M rays, noise %.3g (visible pixels %.3g), "
                    "mean radiance %.4g %.4g %.4g\n",
                    f, v, w, h, st.render_ms / 1000.0, (double)st.rays_total / 1e6, st.noise_rmse,
                    st.noise_rmse_visible, st.mean_radiance[0], st.mean_radiance[1], st.mean_radiance[2]);
            fflush(stdout);
        }
    }
    if (stop_requested) {
        json_object_set_new(root, "interrupted", json_true());
        if (!write_record(&o, root))
            goto done;
        fprintf(stderr, "fxcache ref: interrupted by %s: %u of %u images written\n",
                stop_requested == SIGINT ? "SIGINT" : "SIGTERM", done_images, planned);
    }
    exit_code = 0;
done:
    buffers_free(&buffers);
    json_decref(root);
    json_decref(left_out_extra);
    srv_ref_free(ref);
    scene_rt_free(rt);
    scene_free(s);
    srv_cli_cameras_free(&cams);
    srv_cli_unlock_dir(lock);
    return exit_code;
}
