/* The cameras of a run, as `fxcache sim`, `ref` and `report` share them (cli_cameras.c): one viewer trace per
 * viewer on one clock, or a camera generator. With traces, frame f is at time start + f / fps, start being the
 * earliest first time of the traces; a viewer is present from its trace's first time to its last (sim adds it
 * then and removes it after), and renders at the resolution its trace records unless --res was given. Without
 * traces every viewer is present in every frame with the generator's camera. One place, so a reference or a
 * report renders exactly the cameras sim renders for the same options. */
#ifndef FXC_SERVER_CLI_CAMERAS_H
#define FXC_SERVER_CLI_CAMERAS_H

#include "camgen.h"
#include "engine.h"
#include "trace.h"

#include <getopt.h>
#include <stdbool.h>
#include <stdint.h>

struct json_t;

enum { SRV_CLI_MAX_TRACES = SRV_MAX_VIEWERS };

typedef struct srv_cli_cameras {
    /* Set by srv_cli_cameras_load from the options. */
    srv_camgen_kind generator; /* without traces */
    uint32_t viewers;          /* the generator's viewer count (load sets it to the trace count) */
    uint32_t seed;
    double fps;             /* frames per second of trace time */
    uint32_t width, height; /* --res */
    bool res_set;           /* --res given: it wins over a trace's own resolution */
    /* Read by srv_cli_cameras_load. */
    srv_trace *traces[SRV_CLI_MAX_TRACES];       /* by viewer; NULL: a generator's viewer */
    const char *trace_paths[SRV_CLI_MAX_TRACES]; /* the paths given (for messages) */
    uint32_t trace_count;
    double start_time, last_time; /* frame 0's time and the last trace's end (0 without traces) */
} srv_cli_cameras;

/* The camera options `sim`, `ref` and `report` take alike: --viewers, --frames, --res, --camera, --trace and
 * --fps, as parsed (defaults set by the command before parsing). */
typedef struct srv_cli_view_options {
    uint32_t viewers, frames, width, height;
    bool viewers_set, frames_set, res_set, camera_set;
    srv_camgen_kind camera;
    const char *traces[SRV_CLI_MAX_TRACES]; /* the --trace paths, in order */
    uint32_t trace_count;
    double fps;
    uint32_t frames_min, frames_max; /* --frames' range (the command's) */
} srv_cli_view_options;

/* The defaults sim and ref share, so that a reference renders the cameras sim renders for the same options:
 * 4 viewers, 30 frames at 640 x 360, the room generator, 30 frames per second of trace time, --frames
 * 1..1000000. */
srv_cli_view_options srv_cli_view_defaults(void);

/* getopt_long codes of those options: after the engine's (256 on), before a command's own (320 on). */
enum {
    SRV_CLI_O_VIEWERS = 300,
    SRV_CLI_O_FRAMES,
    SRV_CLI_O_RES,
    SRV_CLI_O_CAMERA,
    SRV_CLI_O_TRACE,
    SRV_CLI_O_FPS
};

/* Their getopt_long entries, to put in a command's own list. */
#define SRV_CLI_VIEW_OPTIONS                                                                                 \
    {"viewers", required_argument, NULL, SRV_CLI_O_VIEWERS},                                                 \
        {"frames", required_argument, NULL, SRV_CLI_O_FRAMES},                                               \
        {"res", required_argument, NULL, SRV_CLI_O_RES},                                                     \
        {"camera", required_argument, NULL, SRV_CLI_O_CAMERA},                                               \
        {"trace", required_argument, NULL, SRV_CLI_O_TRACE},                                                 \
    {                                                                                                        \
        "fps", required_argument, NULL, SRV_CLI_O_FPS                                                        \
    }

/* Handles one getopt_long result: 1 when it was one of the camera options and valid, 0 when it was one and
 * invalid (a one-line error "fxcache CMD: OPTION: ..." was printed), -1 when it is not one of them. */
int srv_cli_view_option(const char *cmd, int code, const char *arg, srv_cli_view_options *v);

/* The checks once the options are parsed: one --trace per viewer when --viewers is given too, and not both
 * --camera and --trace. False with a one-line error. */
bool srv_cli_view_check(const char *cmd, const srv_cli_view_options *v);

/* Sets c from the parsed options (the generator, its viewer count and seed, --fps, --res) and reads the
 * traces (there may be none: the generator drives every viewer). False with a one-line error naming the file
 * and the problem; what was read is freed by srv_cli_cameras_free either way. */
bool srv_cli_cameras_load(const char *cmd, srv_cli_cameras *c, const srv_cli_view_options *v, uint32_t seed);

/* Checks every trace camera against the loaded scene: each must give a usable camera in the scene's local
 * frame (srv_camera_setup: within SCENE_MAX_CAMERA_REACH of the scene's centre, position and target apart in float).
 * False with "fxcache CMD: PATH: camera N (time T s) ..." naming the first that does not. */
bool srv_cli_cameras_check(const char *cmd, const srv_cli_cameras *c, const scene *s);

/* Frames from start until the last trace ends (1..1000000); 0 without traces. */
uint32_t srv_cli_cameras_frames(const srv_cli_cameras *c);

/* The same count in *frames, checked: traces lasting more than max_frames frames at the run's fps (a trace
 * over 1e9 s at 30 fps) are refused with "fxcache CMD: the traces last ..." on stderr and false, instead of
 * being cut at the limit without a word. True (any count) without traces. */
bool srv_cli_cameras_frames_fit(const char *cmd, const srv_cli_cameras *c, uint32_t max_frames,
                                uint32_t *frames);

/* Frame f's time on the run's clock. */
double srv_cli_cameras_time(const srv_cli_cameras *c, uint32_t frame);

/* Whether viewer v is present in frame f (always, for a generator's viewer). */
bool srv_cli_cameras_present(const srv_cli_cameras *c, uint32_t v, uint32_t frame);

/* Viewer v's resolution: its trace's own unless --res was given or the trace records none. */
void srv_cli_cameras_size(const srv_cli_cameras *c, uint32_t v, uint32_t *width, uint32_t *height);

/* Sets the run's resolution in a summary object: "resolution", "WxH" when every one of the viewers renders at
 * it, else "mixed" (traces of other resolutions), and "resolutions", each viewer's "WxH". */
void srv_cli_cameras_summary_resolution(const srv_cli_cameras *c, uint32_t viewers, struct json_t *obj);

/* Viewer v's camera (scene-local) and resolution in frame f; false when it is not present then. */
bool srv_cli_cameras_get(const srv_cli_cameras *c, const scene *s, uint32_t frame, uint32_t v,
                         srv_camera *camera, uint32_t *width, uint32_t *height);

void srv_cli_cameras_free(srv_cli_cameras *c);

#endif
