/* Camera generators: deterministic viewer cameras for `fxcache sim` when no live viewer or trace drives them.
 *
 * Stage 1 of the frame ("cameras") asks srv_camgen_camera() for viewer v's camera at frame f. Every
 * generator is a pure function of (kind, scene bounds and default camera, viewer, viewer count, frame,
 * seed): the same arguments always give the same camera, on every machine, so runs are repeatable. Each
 * stresses the caches differently:
 *   orbit      viewers spread evenly around the scene centre on a circle, each advancing one revolution per
 *              SRV_CAMGEN_ORBIT_PERIOD frames: steady, moderate motion, partial sharing;
 *   walk       viewers staggered evenly along a closed loop through the scene's interior, along its longest
 *              horizontal axis, at eye height, looking ahead: first-person motion, little sharing;
 *   group      viewers on the walk's loop, SRV_CAMGEN_GROUP_SPACING of the loop apart, alternately a little to
 *              the left and right: a tour group walking through the same hall, heavy sharing;
 *   turn       every viewer turning in place at the scene centre, SRV_CAMGEN_TURN_DEGREES_PER_FRAME degrees
 *              per frame, each starting at its own heading: a disocclusion stress test;
 *   room       viewers standing close to the default camera with small offsets, looking at nearby targets
 *              and swaying slowly: heavily overlapping views, high sharing;
 *   static     every viewer at the default camera, moved sideways by a small per-viewer offset (none for
 *              viewer 0), never moving: the cache converges;
 *   identical  every viewer exactly at the default camera: the sharing ratio must equal the viewer count.
 * The default camera is the scene's own (has_camera) or srv_camera_default()'s framing. Every camera has
 * up = +Y and the scene camera's vertical field of view when it has one, else 60 degrees. Every camera is
 * valid: finite, target != position, fov in (0, 180), even for empty or degenerate bounds. */
#ifndef FXC_SERVER_CAMGEN_H
#define FXC_SERVER_CAMGEN_H

#include "camera.h"

#include <stdbool.h>
#include <stdint.h>

/* Frames per orbit revolution (1.5 degrees per frame). */
#define SRV_CAMGEN_ORBIT_PERIOD 240u
/* Frames per lap of the walk loop. */
#define SRV_CAMGEN_WALK_PERIOD 600u
/* Distance between consecutive viewers of the group generator, as a fraction of the walk loop. */
#define SRV_CAMGEN_GROUP_SPACING 0.02

/* Rotation of the turn generator per frame, degrees. */
#define SRV_CAMGEN_TURN_DEGREES_PER_FRAME 30u
/* Frames per sway cycle of the room generator. */
#define SRV_CAMGEN_ROOM_SWAY_PERIOD 240u
/* Vertical field of view, degrees, when the scene has no camera of its own. */
#define SRV_CAMGEN_DEFAULT_FOV_DEG 60.0f

/* The generators, one X-macro table: enum name, command-line name, one-line description. */
#define SRV_CAMGEN_KINDS(X)                                                                                  \
    X(SRV_CAMGEN_ORBIT, "orbit", "viewers spread around the scene centre, circling slowly")                  \
    X(SRV_CAMGEN_WALK, "walk", "viewers staggered along a loop through the scene at eye height")             \
    X(SRV_CAMGEN_GROUP, "group", "viewers walking the same loop together, a few steps apart")                \
    X(SRV_CAMGEN_TURN, "turn", "viewers turning in place at the centre, 30 degrees per frame")               \
    X(SRV_CAMGEN_ROOM, "room", "viewers close together near the default camera, overlapping views")          \
    X(SRV_CAMGEN_STATIC, "static", "viewers at the default camera with small fixed offsets")                 \
    X(SRV_CAMGEN_IDENTICAL, "identical", "every viewer exactly at the default camera")

typedef enum srv_camgen_kind {
#define FXC_X(name, str, description) name,
    SRV_CAMGEN_KINDS(FXC_X)
#undef FXC_X
        SRV_CAMGEN_COUNT
} srv_camgen_kind;

/* Looks up a generator by its command-line name (exact, lower case). Returns false for an unknown name
 * and leaves *out alone. */
bool srv_camgen_parse(const char *name, srv_camgen_kind *out);

/* The command-line name of a generator ("orbit", ...), or "unknown" for a value outside the enum. */
const char *srv_camgen_name(srv_camgen_kind kind);

/* A one-line description of a generator, for --help. */
const char *srv_camgen_description(srv_camgen_kind kind);

/* Every generator name, comma separated, for --help and error messages: "orbit, walk, turn, ...". */
const char *srv_camgen_list(void);

/* Viewer `viewer`'s camera (of viewer_count viewers; 0 is taken as 1) at frame `frame`. seed varies the
 * starting phases and the per-viewer offsets without changing the character of the motion; viewer 0 of
 * `static` sits exactly at the default camera whatever the seed. s must not be NULL; only its bounds and
 * default camera are used. An unknown kind gives the `identical` camera. */
srv_camera srv_camgen_camera(srv_camgen_kind kind, const scene *s, uint32_t viewer, uint32_t viewer_count,
                             uint32_t frame, uint32_t seed);

#endif
