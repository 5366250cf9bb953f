/* Where the viewer client's simulated viewers look: the cameras it sends, from a generator or a trace.
 *
 * Generators work from the welcome message alone (the scene's bounds and default camera, world coordinates):
 *   orbit   a circle around the bounds' centre at the default camera's height and horizontal distance from
 *           the centre, looking at the centre; viewer v of N starts v/N of a turn further round, viewer 0 at
 *           the default camera; one revolution per VIEW_ORBIT_PERIOD cameras. A default camera above the
 *           centre (no horizontal distance) orbits at half the bounds' horizontal diagonal.
 *   static  the default camera, for every viewer and every camera.
 * Traces (proto_trace.h) give their own cameras at their own times; view_trace_due() says how many of a
 * trace's lines are due after some seconds. Pure functions, no network: tests/test_viewer.c checks them. */
#ifndef FXC_VIEW_CAMERA_H
#define FXC_VIEW_CAMERA_H

#include "proto.h"
#include "proto_trace.h"

#include <stdbool.h>
#include <stdint.h>

/* Cameras of one orbit revolution. */
#define VIEW_ORBIT_PERIOD 240u

typedef enum view_camera_kind {
    VIEW_CAMERA_ORBIT,
    VIEW_CAMERA_STATIC,
    VIEW_CAMERA_KIND_COUNT
} view_camera_kind;

/* The kind's name ("unknown" outside the table). */
const char *view_camera_kind_name(uint32_t kind);
/* Parses "orbit" or "static"; false for anything else. */
bool view_camera_kind_parse(const char *text, view_camera_kind *out);

/* Camera number `index` (from 0) of viewer `viewer` of `viewers` (1 or more) from the welcome's bounds and
 * default camera. fov_deg in (0, 180), or 0 for the default camera's. The pose is valid for the wire: finite,
 * a non-zero direction. */
proto_pose view_camera_generate(view_camera_kind kind, const proto_welcome *welcome, uint32_t viewer,
                                uint32_t viewers, uint32_t index, float fov_deg);

/* The same at a fractional camera index (the camera between two generated ones: a display clock's camera);
 * a whole index gives exactly view_camera_generate's camera. */
proto_pose view_camera_generate_at(view_camera_kind kind, const proto_welcome *welcome, uint32_t viewer,
                                   uint32_t viewers, double index, float fov_deg);

/* Line `index` (< t->count) of a trace as a wire pose; fov_deg 0 keeps the trace's field of view. */
proto_pose view_camera_from_trace(const proto_trace *t, uint32_t index, float fov_deg);

/* How many of a trace's lines are due `elapsed` seconds after the start, when time `origin` of the trace is
 * the start: the lines whose time - origin is not after elapsed (with the server's 1e-9 s slack). */
uint32_t view_trace_due(const proto_trace *t, double origin, double elapsed);

/* A trace's camera at `elapsed` seconds after the start (time `origin` of the trace is the start): between
 * two lines, position, unit direction (renormalised) and fov mixed linearly by time; before the first line
 * the first, after the last the last. At a line's own time, that line exactly (as view_camera_from_trace). */
proto_pose view_camera_trace_at(const proto_trace *t, double origin, double elapsed, float fov_deg);

/* The camera at target_s extrapolated from two earlier ones (previous at previous_s < current at current_s):
 * position and fov linearly, the direction by its yaw (about +Y, the short way) and pitch linearly (a
 * steady turn is extrapolated exactly; pitch kept within 0.057 degrees of vertical). Returns current when
 * the times do not increase. */
proto_pose view_pose_extrapolate(const proto_pose *previous, double previous_s, const proto_pose *current,
                                 double current_s, double target_s);

#endif
