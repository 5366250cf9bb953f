/* The viewer client's camera generators and trace schedule (view_camera.h). Arithmetic in double, rounded
 * once to the wire's float direction; the orbit's camera index is reduced modulo the period first, so camera
 * 4e9 is as exact as camera 4. */
#include "view_camera.h"

#include <math.h>
#include <string.h>

#define VIEW_PI 3.14159265358979323846

static const char *const camera_kind_names[VIEW_CAMERA_KIND_COUNT] = {"orbit", "static"};

const char *view_camera_kind_name(uint32_t kind)
{
    return kind < VIEW_CAMERA_KIND_COUNT ? camera_kind_names[kind] : "unknown";
}

bool view_camera_kind_parse(const char *text, view_camera_kind *out)
{
    for (uint32_t kind = 0; kind < VIEW_CAMERA_KIND_COUNT; kind++)
        if (strcmp(text, camera_kind_names[kind]) == 0) {
            *out = (view_camera_kind)kind;
            return true;
        }
    return false;
}

/* The orbit: see view_camera.h. */
static proto_pose camera_orbit(const proto_welcome *w, uint32_t viewer, uint32_t viewers, uint32_t index)
{
    double centre[3];
    for (int k = 0; k < 3; k++)
        centre[k] = 0.5 * (w->bounds_min[k] + w->bounds_max[k]);
    const double *eye = w->camera.position;
    double dx = eye[0] - centre[0], dz = eye[2] - centre[2];
    double radius = hypot(dx, dz), start = atan2(dz, dx);
    double half_diagonal =
        0.5 * hypot(w->bounds_max[0] - w->bounds_min[0], w->bounds_max[2] - w->bounds_min[2]);
    if (!(radius > 1e-6 * fmax(half_diagonal, 1.0))) {
        radius = half_diagonal > 0 ? half_diagonal : 1.0;
        start = 0;
    }
    double turns = (double)viewer / (double)(viewers ? viewers : 1) +
                   (double)(index % VIEW_ORBIT_PERIOD) / (double)VIEW_ORBIT_PERIOD;
    double angle = start + 2 * VIEW_PI * turns;
    proto_pose pose = {.fov_deg = w->camera.fov_deg};
    pose.position[0] = centre[0] + radius * cos(angle);
    pose.position[1] = eye[1];
    pose.position[2] = centre[2] + radius * sin(angle);
    for (int k = 0; k < 3; k++)
        pose.direction[k] = (float)(centre[k] - pose.position[k]);
    return pose;
}

proto_pose view_camera_generate(view_camera_kind kind, const proto_welcome *welcome, uint32_t viewer,
                                uint32_t viewers, uint32_t index, float fov_deg)
{
    proto_pose pose =
        kind == VIEW_CAMERA_ORBIT ? camera_orbit(welcome, viewer, viewers, index) : welcome->camera;
    if (fov_deg > 0)
        pose.fov_deg = fov_deg;
    return pose;
}

proto_pose view_camera_from_trace(const proto_trace *t, uint32_t index, float fov_deg)
{
    const proto_trace_camera *c = &t->cameras[index];
    proto_pose pose = {.fov_deg = fov_deg > 0 ? fov_deg : c->fov_deg};
    for (int k = 0; k < 3; k++) {
        pose.position[k] = c->position[k];
        pose.direction[k] = (float)c->direction[k];
    }
    /* The trace's direction is a double and need only move the position in double; a float can round a tiny
     * component to zero. Only its direction matters: scale it up, keeping it (no squares, which underflow).
     */
    if (pose.direction[0] == 0 && pose.direction[1] == 0 && pose.direction[2] == 0) {
        double largest = fmax(fabs(c->direction[0]), fmax(fabs(c->direction[1]), fabs(c->direction[2])));
        for (int k = 0; k < 3; k++)
            pose.direction[k] = (float)(c->direction[k] / largest); /* the largest component becomes +-1 */
    }
    return pose;
}

uint32_t view_trace_due(const proto_trace *t, double origin, double elapsed)
{
    /* The first line whose time is after origin + elapsed (times do not decrease): binary search. */
    uint32_t lo = 0, hi = t->count;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (t->times[mid] - origin <= elapsed + 1e-9)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}
