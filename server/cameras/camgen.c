/* Camera generators: see camgen.h for what each one does and why.
 *
 * Geometry choices, all relative to the scene's axis-aligned bounding box so that they hold at any scale:
 *   - The box is sanitised first (scene_box): non-finite or inverted bounds become a 2 m cube at the origin;
 *     each half extent is at least 5 % of the largest one, so flat scenes (a single plane) still give
 *     cameras above the surface rather than in it.
 *   - orbit: if the scene camera stands inside the box, the scene is an interior: the circle has radius
 *     0.6 x the smaller horizontal half extent, at the camera's height (2.4 m and 2 m in the default room).
 *     If the camera is outside, the circle goes through the camera's horizontal distance from the centre, at
 *     its height. Without a camera, radius 1.5 x the horizontal half diagonal, at half the box's half
 *     diagonal above the centre. Viewers look at the box centre.
 *   - walk: a stadium-shaped loop (two straight lanes joined by half circles) in the horizontal plane:
 *     lanes along the longest horizontal axis at +-R across from the centre, R = a quarter of the cross
 *     extent; the loop ends 10 % of the cross extent short of the box on the long axis. Eye height is a
 *     quarter of the box height above the floor. Viewers are spread evenly along the loop and look at the
 *     point R further along it, a little below eye height. In the default room (10 x 4 x 8 m) the lanes
 *     run at z = -2 and z = +2, x within [-4.2, 4.2], at y = 1 m: clear of the walls, the boxes and the
 *     sphere.
 *   - turn: at the box centre, looking horizontally, viewer v starting at heading 360 v / N degrees.
 *   - room / static / identical: around the default camera (the scene's, else srv_camera_default()), with
 *     offsets proportional to its distance to its target: room moves each viewer up to 8 % of it sideways
 *     and its target up to 12 %, plus a 2 % sway; static translates camera and target together by 3 %.
 * Arithmetic is in double and rounded once to float; frame numbers are reduced modulo each period first so
 * that frame 4e9 is as exact as frame 4. */
#include "camgen.h"

#include <math.h>
#include <string.h>

#define CAMGEN_PI 3.14159265358979323846

/* The sanitised bounding box of a scene: centre and half extents, metres. */
typedef struct scene_box {
    double center[3];
    double half[3]; /* each > 0 */
    double largest; /* largest half extent */
} scene_box;

static const char *const camgen_names[SRV_CAMGEN_COUNT] = {
#define FXC_X(name, str, description) str,
    SRV_CAMGEN_KINDS(FXC_X)
#undef FXC_X
};

static const char *const camgen_descriptions[SRV_CAMGEN_COUNT] = {
#define FXC_X(name, str, description) description,
    SRV_CAMGEN_KINDS(FXC_X)
#undef FXC_X
};

bool srv_camgen_parse(const char *name, srv_camgen_kind *out)
{
    if (!name)
        return false;
    for (int kind = 0; kind < SRV_CAMGEN_COUNT; kind++)
        if (strcmp(name, camgen_names[kind]) == 0) {
            *out = (srv_camgen_kind)kind;
            return true;
        }
    return false;
}

const char *srv_camgen_name(srv_camgen_kind kind)
{
    return (unsigned)kind < SRV_CAMGEN_COUNT ? camgen_names[kind] : "unknown";
}

const char *srv_camgen_description(srv_camgen_kind kind)
{
    return (unsigned)kind < SRV_CAMGEN_COUNT ? camgen_descriptions[kind] : "unknown generator";
}

const char *srv_camgen_list(void)
{
    return "orbit, walk, group, turn, room, static, identical";
}

/* A well-mixed 32-bit hash of (seed, viewer, salt) (the murmur3 finaliser over a combined word). */
static uint32_t camgen_hash(uint32_t seed, uint32_t viewer, uint32_t salt)
{
    uint32_t h = seed * 0x9e3779b9u ^ viewer * 0x85ebca6bu ^ salt * 0xc2b2ae35u ^ 0x27d4eb2fu;
    h ^= h >> 16;
    h *= 0x85ebca6bu;
    h ^= h >> 13;
    h *= 0xc2b2ae35u;
    h ^= h >> 16;
    return h;
}

/* The hash as a double in [0, 1). */
static double camgen_unit(uint32_t seed, uint32_t viewer, uint32_t salt)
{
    return (double)camgen_hash(seed, viewer, salt) / 4294967296.0;
}

/* The scene's bounding box, made safe to build cameras from (see the comment at the top of the file). */
static scene_box camgen_box(const scene *s)
{
    scene_box box;
    bool usable = true;
    for (int k = 0; k < 3; k++)
        if (!isfinite(s->bounds_min[k]) || !isfinite(s->bounds_max[k]) || s->bounds_min[k] > s->bounds_max[k])
            usable = false;
    box.largest = 0;
    for (int k = 0; k < 3; k++) {
        box.center[k] = usable ? 0.5 * ((double)s->bounds_min[k] + (double)s->bounds_max[k]) : 0;
        box.half[k] = usable ? 0.5 * ((double)s->bounds_max[k] - (double)s->bounds_min[k]) : 1;
        if (box.half[k] > box.largest)
            box.largest = box.half[k];
    }
    if (!(box.largest > 0)) /* a single point: a 2 m cube around it */
        box.largest = 1;
    for (int k = 0; k < 3; k++)
        if (box.half[k] < 0.05 * box.largest)
            box.half[k] = 0.05 * box.largest;
    return box;
}

/* The vertical field of view every generated camera uses: the scene camera's, else the default. */
static float camgen_fov(const scene *s)
{
    if (s->has_camera && s->camera_fov_deg > 0 && s->camera_fov_deg < 180)
        return s->camera_fov_deg;
    return SRV_CAMGEN_DEFAULT_FOV_DEG;
}

/* A camera from double-precision position and target, guaranteed valid: non-finite values fall back to
 * the box centre, and a target that rounds onto the position is pushed along -Z by a representable step. */
static srv_camera camgen_make(const double position[3], const double target[3], float fov_deg,
                              const scene_box *box)
{
    srv_camera cam = {.up = {0, 1, 0}, .fov_deg = fov_deg};
    bool finite = true;
    for (int k = 0; k < 3; k++) {
        cam.position[k] = (float)position[k];
        cam.target[k] = (float)target[k];
        if (!isfinite(cam.position[k]) || !isfinite(cam.target[k]))
            finite = false;
    }
    if (!finite)
        for (int k = 0; k < 3; k++) {
            cam.position[k] = (float)box->center[k];
            cam.target[k] = (float)box->center[k];
        }
    if (cam.position[0] == cam.target[0] && cam.position[1] == cam.target[1] &&
        cam.position[2] == cam.target[2]) {
        float step = fmaxf(1.0f, fabsf(cam.position[2]) * 1e-3f);
        cam.target[2] = cam.position[2] - step;
        if (!isfinite(cam.target[2]) || cam.target[2] == cam.position[2])
            cam.target[2] = cam.position[2] > 0 ? 0 : 1; /* at the float limit: look towards the origin */
    }
    return cam;
}

/* The default camera as doubles: position, target and the distance between them (> 0). */
static double camgen_default(const scene *s, const scene_box *box, double position[3], double target[3])
{
    srv_camera base = srv_camera_default(s);
    double distance_squared = 0;
    bool finite = true;
    for (int k = 0; k < 3; k++) {
        position[k] = base.position[k];
        target[k] = base.target[k];
        if (!isfinite(position[k]) || !isfinite(target[k]))
            finite = false;
    }
    if (!finite) /* a scene with broken bounds and no camera: look at the box from +Z */
        for (int k = 0; k < 3; k++) {
            target[k] = box->center[k];
            position[k] = box->center[k] + (k == 2 ? 3 * box->largest : 0);
        }
    for (int k = 0; k < 3; k++)
        distance_squared += (target[k] - position[k]) * (target[k] - position[k]);
    double distance = sqrt(distance_squared);
    return distance > 0 ? distance : box->largest;
}

/* orbit: a circle around the box centre, one revolution per SRV_CAMGEN_ORBIT_PERIOD frames. */
static srv_camera camgen_orbit(const scene *s, const scene_box *box, uint32_t viewer, uint32_t viewer_count,
                               uint32_t frame, uint32_t seed)
{
    double radius, height;
    if (s->has_camera && isfinite(s->camera_pos[0]) && isfinite(s->camera_pos[1]) &&
        isfinite(s->camera_pos[2])) {
        bool inside = true;
        for (int k = 0; k < 3; k++)
            if (fabs(s->camera_pos[k] - box->center[k]) > box->half[k])
                inside = false;
        height = s->camera_pos[1];
        if (inside) {
            radius = 0.6 * fmin(box->half[0], box->half[2]);
        } else {
            double dx = s->camera_pos[0] - box->center[0], dz = s->camera_pos[2] - box->center[2];
            radius = fmax(sqrt(dx * dx + dz * dz), 0.5 * hypot(box->half[0], box->half[2]));
        }
    } else {
        double horizontal = hypot(box->half[0], box->half[2]);
        radius = 1.5 * horizontal;
        height = box->center[1] + 0.5 * sqrt(horizontal * horizontal + box->half[1] * box->half[1]);
    }
    double turns = (double)viewer / viewer_count +
                   (double)(frame % SRV_CAMGEN_ORBIT_PERIOD) / SRV_CAMGEN_ORBIT_PERIOD +
                   camgen_unit(seed, 0, 1);
    double angle = 2 * CAMGEN_PI * turns;
    double position[3] = {box->center[0] + radius * cos(angle), height, box->center[2] + radius * sin(angle)};
    return camgen_make(position, box->center, camgen_fov(s), box);
}

/* The stadium loop of the walk: lanes at +-radius across, straights of half length straight_half along.
 * Maps an arc length (any value, wrapped) to (along, across) relative to the box centre. */
static void camgen_stadium_point(double straight_half, double radius, double arc, double *along,
                                 double *across)
{
    double straight = 2 * straight_half, bend = CAMGEN_PI * radius;
    double loop = 2 * straight + 2 * bend;
    arc = fmod(arc, loop);
    if (arc < 0)
        arc += loop;
    if (arc < straight) { /* lane at -radius, walking towards +along */
        *along = -straight_half + arc;
        *across = -radius;
    } else if (arc < straight + bend) { /* half circle at the +along end, from -radius to +radius */
        double theta = -0.5 * CAMGEN_PI + (arc - straight) / radius;
        *along = straight_half + radius * cos(theta);
        *across = radius * sin(theta);
    } else if (arc < 2 * straight + bend) { /* lane at +radius, walking towards -along */
        *along = straight_half - (arc - straight - bend);
        *across = radius;
    } else { /* half circle at the -along end, from +radius back to -radius */
        double theta = 0.5 * CAMGEN_PI + (arc - 2 * straight - bend) / radius;
        *along = -straight_half + radius * cos(theta);
        *across = radius * sin(theta);
    }
}

/* walk: staggered viewers on the stadium loop at eye height, looking ahead along it. group: the same loop,
 * viewers SRV_CAMGEN_GROUP_SPACING of it apart and alternately shifted across by a tenth of the lane radius. */
static srv_camera camgen_walk(const scene *s, const scene_box *box, uint32_t viewer, uint32_t viewer_count,
                              uint32_t frame, uint32_t seed, bool group)
{
    int along_axis = box->half[0] >= box->half[2] ? 0 : 2, across_axis = 2 - along_axis;
    double half_along = box->half[along_axis], half_across = box->half[across_axis];
    double radius = 0.5 * half_across; /* a quarter of the cross extent */
    double straight_half =
        half_along - 0.2 * half_across - radius; /* >= 0.3 half_across since along >= across */
    double loop = 4 * straight_half + 2 * CAMGEN_PI * radius;
    double eye =
        box->center[1] - box->half[1] + 0.5 * box->half[1]; /* a quarter of the height above the floor */
    double spacing = group ? SRV_CAMGEN_GROUP_SPACING : 1.0 / viewer_count;
    double phase = -(double)viewer * spacing +
                   (double)(frame % SRV_CAMGEN_WALK_PERIOD) / SRV_CAMGEN_WALK_PERIOD +
                   camgen_unit(seed, 0, 2);
    double arc = loop * phase;
    double along, across, ahead_along, ahead_across;
    camgen_stadium_point(straight_half, radius, arc, &along, &across);
    camgen_stadium_point(straight_half, radius, arc + radius, &ahead_along, &ahead_across);
    double position[3], target[3];
    position[along_axis] = box->center[along_axis] + along;
    position[across_axis] = box->center[across_axis] + across;
    if (group && viewer > 0) /* side by side, not in single file */
        position[across_axis] += (viewer % 2 ? 0.1 : -0.1) * radius;
    position[1] = eye;
    target[along_axis] = box->center[along_axis] + ahead_along;
    target[across_axis] = box->center[across_axis] + ahead_across;
    target[1] = eye - 0.15 * radius; /* about 8 degrees down: the floor ahead is in view */
    return camgen_make(position, target, camgen_fov(s), box);
}

/* turn: at the box centre, heading 360 v / N degrees plus SRV_CAMGEN_TURN_DEGREES_PER_FRAME per frame. */
static srv_camera camgen_turn(const scene *s, const scene_box *box, uint32_t viewer, uint32_t viewer_count,
                              uint32_t frame, uint32_t seed)
{
    uint32_t steps_per_turn = 360u / SRV_CAMGEN_TURN_DEGREES_PER_FRAME;
    double degrees = 360.0 * viewer / viewer_count + 360.0 * camgen_unit(seed, 0, 3) +
                     (double)(frame % steps_per_turn) * SRV_CAMGEN_TURN_DEGREES_PER_FRAME;
    double angle = degrees * CAMGEN_PI / 180.0;
    double reach = 0.5 * box->largest;
    double target[3] = {box->center[0] + reach * cos(angle), box->center[1],
                        box->center[2] + reach * sin(angle)};
    return camgen_make(box->center, target, camgen_fov(s), box);
}

/* A deterministic point in the unit disk (horizontal) or ball, from the hash; salt picks the stream. */
static void camgen_random_offset(uint32_t seed, uint32_t viewer, uint32_t salt, bool vertical, double out[3])
{
    double azimuth = 2 * CAMGEN_PI * camgen_unit(seed, viewer, salt);
    double elevation = vertical ? asin(2 * camgen_unit(seed, viewer, salt + 1) - 1) : 0;
    double length =
        vertical ? cbrt(camgen_unit(seed, viewer, salt + 2)) : sqrt(camgen_unit(seed, viewer, salt + 2));
    out[0] = length * cos(elevation) * cos(azimuth);
    out[1] = length * sin(elevation);
    out[2] = length * cos(elevation) * sin(azimuth);
}

/* room: near the default camera with small offsets, looking at nearby targets, swaying slowly. */
/* When the default camera stands inside the scene's box (an interior), keeps a moved position inside too:
 * each coordinate stays within the box shrunk by a margin no larger than the default camera's own distance
 * to that face (so the default camera itself is never moved) and no larger than 5 % of the half extent. */
static void camgen_keep_inside(const scene_box *box, const double home[3], double position[3])
{
    for (int k = 0; k < 3; k++)
        if (!(fabs(home[k] - box->center[k]) < box->half[k]))
            return; /* outside: an exterior view, nothing to keep it in */
    for (int k = 0; k < 3; k++) {
        double lo = box->center[k] - box->half[k], hi = box->center[k] + box->half[k];
        double margin = fmin(0.05 * box->half[k], fmin(home[k] - lo, hi - home[k]));
        position[k] = fmin(fmax(position[k], lo + margin), hi - margin);
    }
}

static srv_camera camgen_room(const scene *s, const scene_box *box, uint32_t viewer, uint32_t frame,
                              uint32_t seed)
{
    double position[3], target[3];
    double distance = camgen_default(s, box, position, target);
    double stand[3], look[3];
    camgen_random_offset(seed, viewer, 10, false, stand);
    camgen_random_offset(seed, viewer, 20, true, look);
    double sway_phase = 2 * CAMGEN_PI *
                        ((double)(frame % SRV_CAMGEN_ROOM_SWAY_PERIOD) / SRV_CAMGEN_ROOM_SWAY_PERIOD +
                         camgen_unit(seed, viewer, 30));
    double sway[3] = {cos(sway_phase), 0.5 * sin(2 * sway_phase), sin(sway_phase)};
    double home[3] = {position[0], position[1], position[2]};
    for (int k = 0; k < 3; k++) {
        position[k] += distance * (0.08 * stand[k] + 0.02 * sway[k]);
        target[k] += distance * (0.12 * look[k] + 0.02 * sway[k]);
    }
    camgen_keep_inside(box, home, position);
    return camgen_make(position, target, camgen_fov(s), box);
}

/* static and identical: the default camera, translated by 3 % of its distance for viewers > 0 of static. */
static srv_camera camgen_static(const scene *s, const scene_box *box, uint32_t viewer, uint32_t seed,
                                bool identical)
{
    double position[3], target[3];
    double distance = camgen_default(s, box, position, target);
    double home[3] = {position[0], position[1], position[2]};
    if (!identical && viewer > 0) {
        /* A direction on the unit sphere from the hash; the length is fixed so no viewer coincides with 0. */
        double azimuth = 2 * CAMGEN_PI * camgen_unit(seed, viewer, 40);
        double elevation = asin(2 * camgen_unit(seed, viewer, 41) - 1);
        double offset[3] = {cos(elevation) * cos(azimuth), sin(elevation), cos(elevation) * sin(azimuth)};
        for (int k = 0; k < 3; k++) {
            position[k] += 0.03 * distance * offset[k];
            target[k] += 0.03 * distance * offset[k];
        }
        camgen_keep_inside(box, home, position);
    }
    return camgen_make(position, target, camgen_fov(s), box);
}

srv_camera srv_camgen_camera(srv_camgen_kind kind, const scene *s, uint32_t viewer, uint32_t viewer_count,
                             uint32_t frame, uint32_t seed)
{
    scene_box box = camgen_box(s);
    if (viewer_count == 0)
        viewer_count = 1;
    switch (kind) {
    case SRV_CAMGEN_ORBIT: return camgen_orbit(s, &box, viewer, viewer_count, frame, seed);
    case SRV_CAMGEN_WALK: return camgen_walk(s, &box, viewer, viewer_count, frame, seed, false);
    case SRV_CAMGEN_GROUP: return camgen_walk(s, &box, viewer, viewer_count, frame, seed, true);
    case SRV_CAMGEN_TURN: return camgen_turn(s, &box, viewer, viewer_count, frame, seed);
    case SRV_CAMGEN_ROOM: return camgen_room(s, &box, viewer, frame, seed);
    case SRV_CAMGEN_STATIC: return camgen_static(s, &box, viewer, seed, false);
    case SRV_CAMGEN_IDENTICAL:
    default: return camgen_static(s, &box, viewer, seed, true);
    }
}
