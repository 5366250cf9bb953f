/* Pinhole cameras: see camera.h. */
#include "camera.h"

#include "fxc_camera.h"

#include <float.h>
#include <math.h>
#include <string.h>

bool srv_camera_setup(const srv_camera *cam, uint32_t width, uint32_t height, srv_camera_frame *out)
{
    memset(out, 0, sizeof *out);
    if (width == 0 || height == 0 || !(cam->fov_deg > 0 && cam->fov_deg < 180))
        return false;
    float toward[3];
    for (int k = 0; k < 3; k++) {
        if (!isfinite(cam->position[k]) || !isfinite(cam->target[k]) ||
            !(fabsf(cam->position[k]) <= SCENE_MAX_CAMERA_REACH) ||
            !(fabsf(cam->target[k]) <= SCENE_MAX_CAMERA_REACH))
            return false;
        out->origin[k] = cam->position[k];
        toward[k] = cam->target[k] - cam->position[k];
    }
    if (!fxc_camera_basis(toward, cam->up, out->forward, out->right, out->up))
        return false;
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
    fxc_camera_normalize3(offset);
    for (int k = 0; k < 3; k++)
        cam.position[k] = cam.target[k] + offset[k] * diag * 1.1f;
    return cam;
}
