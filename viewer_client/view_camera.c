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
static proto_pose camera_orbit(const proto_welcome *w, uint32_t viewer, uint32_t viewers, double index)
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
                   fmod(index, (double)VIEW_ORBIT_PERIOD) / (double)VIEW_ORBIT_PERIOD;
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
    /* index % period first: a whole number below 2^53, so fmod in camera_orbit gives it back exactly. */
    return view_camera_generate_at(kind, welcome, viewer, viewers, (double)(index % VIEW_ORBIT_PERIOD),
                                   fov_deg);
}

proto_pose view_camera_generate_at(view_camera_kind kind, const proto_welcome *welcome, uint32_t viewer,
                                   uint32_t viewers, double index, float fov_deg)
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

proto_pose view_camera_trace_at(const proto_trace *t, double origin, double elapsed, float fov_deg)
{
    uint32_t due = view_trace_due(t, origin, elapsed);
    if (due == 0)
        return view_camera_from_trace(t, 0, fov_deg);
    if (due >= t->count)
        return view_camera_from_trace(t, t->count - 1, fov_deg);
    proto_pose a = view_camera_from_trace(t, due - 1, fov_deg), b = view_camera_from_trace(t, due, fov_deg);
    double span = t->times[due] - t->times[due - 1];
    double w = span > 0 ? (elapsed + origin - t->times[due - 1]) / span : 0;
    w = w < 0 ? 0 : w > 1 ? 1 : w;
    if (w == 0)
        return a;
    /* Directions as unit vectors (trace directions need not be unit), then mixed and renormalised. */
    double na = 0, nb = 0, mixed[3], n = 0;
    for (int k = 0; k < 3; k++) {
        na += (double)a.direction[k] * a.direction[k];
        nb += (double)b.direction[k] * b.direction[k];
    }
    na = sqrt(na), nb = sqrt(nb);
    for (int k = 0; k < 3; k++) {
        mixed[k] = (1 - w) * a.direction[k] / na + w * b.direction[k] / nb;
        n += mixed[k] * mixed[k];
    }
    proto_pose pose = a;
    for (int k = 0; k < 3; k++) {
        pose.position[k] = (1 - w) * a.position[k] + w * b.position[k];
        if (n > 1e-12) /* opposite directions half way: keep the earlier one */
            pose.direction[k] = (float)(mixed[k] / sqrt(n));
    }
    pose.fov_deg = (float)((1 - w) * a.fov_deg + w * b.fov_deg);
    return pose;
}

/* Yaw (about +Y, radians, atan2(x, -z): 0 looks along -z) and pitch (radians above the horizon) of d. */
static void yaw_pitch(const float d[3], double *yaw, double *pitch)
{
    double horizontal = hypot((double)d[0], (double)d[2]);
    *yaw = atan2((double)d[0], -(double)d[2]);
    *pitch = atan2((double)d[1], horizontal);
}

proto_pose view_pose_extrapolate(const proto_pose *previous, double previous_s, const proto_pose *current,
                                 double current_s, double target_s)
{
    proto_pose out = *current;
    double span = current_s - previous_s;
    if (!(span > 0) || !(target_s > current_s))
        return out;
    double f = (target_s - current_s) / span;
    for (int k = 0; k < 3; k++)
        out.position[k] = current->position[k] + f * (current->position[k] - previous->position[k]);
    double yaw0, pitch0, yaw1, pitch1;
    yaw_pitch(previous->direction, &yaw0, &pitch0);
    yaw_pitch(current->direction, &yaw1, &pitch1);
    double turn = yaw1 - yaw0; /* the short way round */
    if (turn > VIEW_PI)
        turn -= 2 * VIEW_PI;
    else if (turn < -VIEW_PI)
        turn += 2 * VIEW_PI;
    double yaw = yaw1 + f * turn, pitch = pitch1 + f * (pitch1 - pitch0);
    double limit = 0.5 * VIEW_PI - 1e-3; /* never straight up or down, nor over the top */
    pitch = pitch > limit ? limit : pitch < -limit ? -limit : pitch;
    out.direction[0] = (float)(cos(pitch) * sin(yaw));
    out.direction[1] = (float)sin(pitch);
    out.direction[2] = (float)(-cos(pitch) * cos(yaw));
    double fov = current->fov_deg + f * (current->fov_deg - previous->fov_deg);
    out.fov_deg = (float)(fov < 1 ? 1 : fov > 170 ? 170 : fov);
    return out;
}
