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

#include <stdbool.h>
#include <stdint.h>

struct json_t;

enum { SRV_CLI_MAX_TRACES = SRV_MAX_VIEWERS };

typedef struct srv_cli_cameras {
    /* Set by the command before srv_cli_cameras_load. */
    srv_camgen_kind generator; /* without traces */
    uint32_t viewers;          /* the generator's viewer count (load sets it to the trace count) */
    uint32_t seed;
    double fps;                /* frames per second of trace time */
    uint32_t width, height;    /* --res */
    bool res_set;              /* --res given: it wins over a trace's own resolution */
    /* Set by srv_cli_cameras_load. */
    srv_trace *traces[SRV_CLI_MAX_TRACES]; /* by viewer; NULL: a generator's viewer */
    const char *trace_paths[SRV_CLI_MAX_TRACES]; /* the paths given (for messages) */
    uint32_t trace_count;
    double start_time, last_time; /* frame 0's time and the last trace's end (0 without traces) */
} srv_cli_cameras;

/* --trace PATH while parsing: appends path to paths (count entries), or prints "fxcache CMD: --trace: at most
 * 64 traces" and returns false. */
bool srv_cli_add_trace(const char *cmd, const char **paths, uint32_t *count, const char *path);

/* --camera GEN while parsing: the generator named gen, or false after "fxcache CMD: --camera: unknown
 * generator 'GEN' (one of: ...)". */
bool srv_cli_camera_option(const char *cmd, const char *gen, srv_camgen_kind *out);

/* The checks every command makes once its options are parsed: one --trace per viewer when --viewers is given
 * too, and not both --camera and --trace. False with a one-line error. */
bool srv_cli_check_cameras(const char *cmd, uint32_t trace_count, bool viewers_set, uint32_t viewers,
                           bool camera_set);

/* Reads the traces (count may be 0: the generator drives every viewer). False with a one-line error naming
 * the file and the problem; what was read is freed by srv_cli_cameras_free either way. */
bool srv_cli_cameras_load(const char *cmd, srv_cli_cameras *c, const char *const *paths, uint32_t count);

/* Checks every trace camera against the loaded scene: each must give a usable camera in the scene's local
 * frame (srv_camera_setup: within SCENE_MAX_CAMERA_REACH of the scene's centre, position and target apart in float).
 * False with "fxcache CMD: PATH: camera N (time T s) ..." naming the first that does not. */
bool srv_cli_cameras_check(const char *cmd, const srv_cli_cameras *c, const scene *s);

/* Frames from start until the last trace ends (1..1000000); 0 without traces. */
uint32_t srv_cli_cameras_frames(const srv_cli_cameras *c);

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
bool srv_cli_cameras_get(const srv_cli_cameras *c, const scene *s, uint32_t frame, uint32_t v, srv_camera *camera,
                         uint32_t *width, uint32_t *height);

void srv_cli_cameras_free(srv_cli_cameras *c);

#endif
