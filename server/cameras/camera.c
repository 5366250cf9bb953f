/* Pinhole cameras: see camera.h. */
#include "camera.h"

#include <float.h>
#include <math.h>
#include <string.h>

static void normalize3(float v[3])
{
    float len = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (len > 0)
        for (int k = 0; k < 3; k++)
            v[k] /= len;
}

static void cross3(const float a[3], const float b[3], float out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

bool srv_camera_setup(const srv_camera *cam, uint32_t width, uint32_t height, srv_camera_frame *out)
{
    memset(out, 0, sizeof *out);
    if (width == 0 || height == 0 || !(cam->fov_deg > 0 && cam->fov_deg < 180))
        return false;
    float up_hint[3] = {cam->up[0], cam->up[1], cam->up[2]};
    if (up_hint[0] == 0 && up_hint[1] == 0 && up_hint[2] == 0)
        up_hint[1] = 1;
    for (int k = 0; k < 3; k++) {
        if (!isfinite(cam->position[k]) || !isfinite(cam->target[k]) || !isfinite(up_hint[k]) ||
            !(fabsf(cam->position[k]) <= SCENE_MAX_CAMERA_REACH) ||
            !(fabsf(cam->target[k]) <= SCENE_MAX_CAMERA_REACH))
            return false;
        out->origin[k] = cam->position[k];
        out->forward[k] = cam->target[k] - cam->position[k];
    }
    float len2 = out->forward[0] * out->forward[0] + out->forward[1] * out->forward[1] +
                 out->forward[2] * out->forward[2];
    if (!(len2 >= FLT_MIN)) {
        /* A target within about 1e-19 of the position (a trace's direction of 1e-30 is valid, docs/TRACE_FORMAT.md):
         * the float squares underflow to zero or lose their precision, and the camera was refused as if position
         * and target coincided. Any non-zero difference is a direction: normalised in double. */
        double length =
            sqrt((double)out->forward[0] * out->forward[0] + (double)out->forward[1] * out->forward[1] +
                 (double)out->forward[2] * out->forward[2]);
        if (!(length > 0))
            return false;
        for (int k = 0; k < 3; k++)
            out->forward[k] = (float)(out->forward[k] / length);
    } else {
        normalize3(out->forward);
    }
    /* right = forward x up hint, normalised in double: looking within a tiny angle of the up hint (a target
     * 1e-30 m beside the point straight below) the product is tiny, its squared length underflows a float (or
     * is flushed to zero in a tracing thread), and right stayed unnormalised: the image plane collapsed onto
     * the forward direction, every pixel the same ray (found by tests/stability/stab_cameras.c). Within
     * 1e-6 rad of the up hint any perpendicular will do. */
    double hint_length = sqrt((double)up_hint[0] * up_hint[0] + (double)up_hint[1] * up_hint[1] +
                              (double)up_hint[2] * up_hint[2]);
    double right[3] = {(double)out->forward[1] * up_hint[2] - (double)out->forward[2] * up_hint[1],
                       (double)out->forward[2] * up_hint[0] - (double)out->forward[0] * up_hint[2],
                       (double)out->forward[0] * up_hint[1] - (double)out->forward[1] * up_hint[0]};
    double right_length = sqrt(right[0] * right[0] + right[1] * right[1] + right[2] * right[2]);
    if (!(hint_length > 0) || !(right_length > 1e-6 * hint_length)) {
        /* Looking along the up hint: any perpendicular will do. */
        float alt[3] = {1, 0, 0};
        if (fabsf(out->forward[0]) > 0.9f)
            alt[0] = 0, alt[2] = 1;
        cross3(out->forward, alt, out->right);
        normalize3(out->right);
    } else {
        for (int k = 0; k < 3; k++)
            out->right[k] = (float)(right[k] / right_length);
    }
    cross3(out->right, out->forward, out->up);
    out->tan_half_y = tanf(cam->fov_deg * (float)M_PI / 360.0f);
    out->tan_half_x = out->tan_half_y * (float)width / (float)height;
    out->width = width;
    out->height = height;
    return true;
}

srv_camera srv_camera_default(const scene *s)
{
    srv_camera cam = {.up = {0, 1, 0}, .fov_deg = 60};
    if (s->has_camera) {
        memcpy(cam.position, s->camera_pos, sizeof cam.position);
        memcpy(cam.target, s->camera_target, sizeof cam.target);
        cam.fov_deg = s->camera_fov_deg > 0 && s->camera_fov_deg < 180 ? s->camera_fov_deg : 60;
        return cam;
    }
    float diag = 0;
    for (int k = 0; k < 3; k++) {
        float e = s->bounds_max[k] - s->bounds_min[k];
        diag += e * e;
        cam.target[k] = 0.5f * (s->bounds_min[k] + s->bounds_max[k]);
    }
    diag = sqrtf(diag);
    float offset[3] = {0.35f, 0.45f, 0.85f};
    normalize3(offset);
    for (int k = 0; k < 3; k++)
        cam.position[k] = cam.target[k] + offset[k] * diag * 1.1f;
    return cam;
}
