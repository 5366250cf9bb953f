/* The cameras of a run, shared by sim, ref and report (cli_cameras.h). */
#include "cli_cameras.h"
#include "cli.h"

#include <jansson.h>

#include <math.h>
#include <stdio.h>

srv_cli_view_options srv_cli_view_defaults(void)
{
    return (srv_cli_view_options){.viewers = 4,
                                  .frames = 30,
                                  .width = 640,
                                  .height = 360,
                                  .camera = SRV_CAMGEN_ROOM,
                                  .fps = 30,
                                  .frames_min = 1,
                                  .frames_max = 1000000};
}

int srv_cli_view_option(const char *cmd, int code, const char *arg, srv_cli_view_options *v)
{
    switch (code) {
    case SRV_CLI_O_VIEWERS:
        v->viewers_set = true;
        return srv_cli_u32(cmd, "--viewers", arg, 1, SRV_MAX_VIEWERS, &v->viewers);
    case SRV_CLI_O_FRAMES:
        v->frames_set = true;
        return srv_cli_u32(cmd, "--frames", arg, v->frames_min, v->frames_max, &v->frames);
    case SRV_CLI_O_RES:
        v->res_set = true;
        return srv_cli_resolution(cmd, "--res", arg, SRV_MAX_SIDE, &v->width, &v->height);
    case SRV_CLI_O_CAMERA:
        v->camera_set = true;
        if (srv_camgen_parse(arg, &v->camera))
            return 1;
        fprintf(stderr, "fxcache %s: --camera: unknown generator '%s' (one of: %s)\n", cmd, arg,
                srv_camgen_list());
        return 0;
    case SRV_CLI_O_TRACE:
        if (v->trace_count == SRV_CLI_MAX_TRACES) {
            fprintf(stderr, "fxcache %s: --trace: at most %d traces\n", cmd, SRV_CLI_MAX_TRACES);
            return 0;
        }
        v->traces[v->trace_count++] = arg;
        return 1;
    case SRV_CLI_O_FPS: return srv_cli_double(cmd, "--fps", arg, 0.001, 1000, &v->fps);
    default: return -1;
    }
}

bool srv_cli_view_check(const char *cmd, const srv_cli_view_options *v)
{
    if (v->trace_count && v->viewers_set && v->viewers != v->trace_count) {
        fprintf(stderr, "fxcache %s: --viewers %u but %u traces: give one --trace per viewer\n", cmd,
                v->viewers, v->trace_count);
        return false;
    }
    if (v->trace_count && v->camera_set) {
        fprintf(stderr, "fxcache %s: --camera and --trace both choose the cameras: give one of them\n", cmd);
        return false;
    }
    return true;
}

bool srv_cli_cameras_load(const char *cmd, srv_cli_cameras *c, const srv_cli_view_options *v, uint32_t seed)
{
    *c = (srv_cli_cameras){.generator = v->camera,
                           .viewers = v->viewers,
                           .seed = seed,
                           .fps = v->fps,
                           .width = v->width,
                           .height = v->height,
                           .res_set = v->res_set};
    const char *const *paths = v->traces;
    uint32_t count = v->trace_count;
    if (!count)
        return true;
    char err[512];
    double first = INFINITY, last = -INFINITY;
    for (uint32_t i = 0; i < count && i < SRV_CLI_MAX_TRACES; i++) {
        c->traces[i] = srv_trace_read(paths[i], err, sizeof err);
        if (!c->traces[i]) {
            fprintf(stderr, "fxcache %s: %s\n", cmd, err);
            return false;
        }
        c->trace_paths[i] = paths[i];
        c->trace_count = i + 1;
        first = fmin(first, srv_trace_first_time(c->traces[i]));
        last = fmax(last, srv_trace_last_time(c->traces[i]));
    }
    c->viewers = c->trace_count;
    c->start_time = first;
    c->last_time = last;
    return true;
}

bool srv_cli_cameras_check(const char *cmd, const srv_cli_cameras *c, const scene *s)
{
    for (uint32_t v = 0; v < c->trace_count; v++) {
        const srv_trace *t = c->traces[v];
        for (uint32_t i = 0; t && i < srv_trace_count(t); i++) {
            srv_camera cam = srv_trace_camera(t, s, i);
            srv_camera_frame frame;
            if (srv_camera_setup(&cam, 1, 1, &frame))
                continue;
            double reach = 0;
            for (int k = 0; k < 3; k++)
                reach = fmax(reach, fmax(fabs((double)cam.position[k]), fabs((double)cam.target[k])));
            if (!(reach <= SCENE_MAX_CAMERA_REACH))
                fprintf(
                    stderr,
                    "fxcache %s: %s: camera %u (time %.9g s) lies %.3g m from the scene's centre; cameras "
                    "may be at most %.0e m from it\n",
                    cmd, c->trace_paths[v], i + 1, srv_trace_time(t, i), reach, SCENE_MAX_CAMERA_REACH);
            else
                fprintf(stderr,
                        "fxcache %s: %s: camera %u (time %.9g s): its position and target coincide in the "
                        "scene's float coordinates (move the target farther away)\n",
                        cmd, c->trace_paths[v], i + 1, srv_trace_time(t, i));
            return false;
        }
    }
    return true;
}

uint32_t srv_cli_cameras_frames(const srv_cli_cameras *c)
{
    if (!c->trace_count)
        return 0;
    double span = (c->last_time - c->start_time) * c->fps;
    return span < 1e6 ? (uint32_t)floor(span + 1e-6) + 1 : 1000000;
}

bool srv_cli_cameras_frames_fit(const char *cmd, const srv_cli_cameras *c, uint32_t max_frames,
                                uint32_t *frames)
{
    *frames = srv_cli_cameras_frames(c);
    double span = (c->last_time - c->start_time) * c->fps; /* inf for times 1e308 apart: refused as well */
    if (!c->trace_count || (span < 1e6 && *frames <= max_frames))
        return true;
    uint32_t longest = 0; /* the trace that ends last */
    for (uint32_t i = 1; i < c->trace_count; i++)
        if (srv_trace_last_time(c->traces[i]) > srv_trace_last_time(c->traces[longest]))
            longest = i;
    fprintf(
        stderr,
        "fxcache %s: %s ends %.6g s after the traces' start: %.6g frames at %g fps, more than the %u a run "
        "may have; give --frames N (at most %u) to render the first N, or a lower --fps\n",
        cmd, c->trace_paths[longest], c->last_time - c->start_time, floor(span + 1e-6) + 1, c->fps,
        max_frames, max_frames);
    return false;
}

double srv_cli_cameras_time(const srv_cli_cameras *c, uint32_t frame)
{
    return c->start_time + frame / c->fps;
}

bool srv_cli_cameras_present(const srv_cli_cameras *c, uint32_t v, uint32_t frame)
{
    const srv_trace *t = v < SRV_CLI_MAX_TRACES ? c->traces[v] : NULL;
    if (!t)
        return true;
    double now = srv_cli_cameras_time(c, frame);
    return srv_trace_first_time(t) <= now + SRV_TRACE_TIME_EPSILON &&
           now <= srv_trace_last_time(t) + SRV_TRACE_TIME_EPSILON;
}

void srv_cli_cameras_size(const srv_cli_cameras *c, uint32_t v, uint32_t *width, uint32_t *height)
{
    *width = c->width;
    *height = c->height;
    const srv_trace *t = v < SRV_CLI_MAX_TRACES ? c->traces[v] : NULL;
    if (t && !c->res_set)
        srv_trace_resolution(t, width, height);
}

void srv_cli_cameras_summary_resolution(const srv_cli_cameras *c, uint32_t viewers, json_t *obj)
{
    json_t *list = json_array();
    char res[32] = "";
    bool same = true;
    uint32_t w0 = 0, h0 = 0;
    for (uint32_t v = 0; v < viewers; v++) {
        uint32_t w, h;
        srv_cli_cameras_size(c, v, &w, &h);
        if (v == 0)
            w0 = w, h0 = h;
        same = same && w == w0 && h == h0;
        snprintf(res, sizeof res, "%ux%u", w, h);
        json_array_append_new(list, json_string(res));
    }
    if (viewers == 0)
        snprintf(res, sizeof res, "%ux%u", c->width, c->height);
    else if (same)
        snprintf(res, sizeof res, "%ux%u", w0, h0);
    json_object_set_new(obj, "resolution", json_string(same ? res : "mixed"));
    json_object_set_new(obj, "resolutions", list);
}

bool srv_cli_cameras_get(const srv_cli_cameras *c, const scene *s, uint32_t frame, uint32_t v,
                         srv_camera *camera, uint32_t *width, uint32_t *height)
{
    srv_cli_cameras_size(c, v, width, height);
    const srv_trace *t = v < SRV_CLI_MAX_TRACES ? c->traces[v] : NULL;
    if (!t) {
        *camera = srv_camgen_camera(c->generator, s, v, c->viewers, frame, c->seed);
        return true;
    }
    if (!srv_cli_cameras_present(c, v, frame))
        return false; /* not joined yet, or left: sim renders nothing for it then */
    *camera = srv_trace_camera_at(t, s, srv_cli_cameras_time(c, frame));
    return true;
}

void srv_cli_cameras_free(srv_cli_cameras *c)
{
    for (uint32_t i = 0; i < SRV_CLI_MAX_TRACES; i++) {
        srv_trace_free(c->traces[i]);
        c->traces[i] = NULL;
    }
    c->trace_count = 0;
}
