/* Cameras: the server's pinhole model (server/cameras/camera.h, srv_camera_setup and srv_camera_ray), rebuilt
 * from a wire pose (position, direction with +Y up, vertical field of view) with the same float operations,
 * so that projecting a point the server's ray produced lands it back on the pixel the ray went through. The
 * client may not link server code: this copies the arithmetic, not the file. */
#include "rc_internal.h"

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

bool view_rc__view_setup(const view_rc_camera *cam, uint32_t width, uint32_t height,
                         const double cache_origin[3], rc_view *out)
{
    memset(out, 0, sizeof *out);
    if (width == 0 || height == 0 || !(cam->fov_deg > 0 && cam->fov_deg < 180))
        return false;
    const float up_hint[3] = {0, 1, 0};
    for (int k = 0; k < 3; k++) {
        if (!isfinite(cam->position[k]) || !isfinite(cam->direction[k]))
            return false;
        out->origin[k] = cam->position[k];
        out->rel[k] = (float)(cam->position[k] - cache_origin[k]);
        out->forward[k] = cam->direction[k];
    }
    float len = sqrtf(out->forward[0] * out->forward[0] + out->forward[1] * out->forward[1] +
                      out->forward[2] * out->forward[2]);
    if (!(len > 0) || !isfinite(len))
        return false;
    normalize3(out->forward);
    cross3(out->forward, up_hint, out->right);
    if (out->right[0] == 0 && out->right[1] == 0 && out->right[2] == 0) {
        /* Looking straight along the up hint: any perpendicular will do (the server's choice). */
        float alt[3] = {1, 0, 0};
        if (fabsf(out->forward[0]) > 0.9f)
            alt[0] = 0, alt[2] = 1;
        cross3(out->forward, alt, out->right);
    }
    normalize3(out->right);
    cross3(out->right, out->forward, out->up);
    out->tan_half_y = tanf(cam->fov_deg * (float)M_PI / 360.0f);
    out->tan_half_x = out->tan_half_y * (float)width / (float)height;
    out->width = width;
    out->height = height;
    /* The inverse of srv_camera_ray: sx = (2 px / width - 1) tan_half_x, so px = width / 2 + sx width /
     * (2 tan_half_x), with sx = x_cam / z_cam; y is flipped. */
    out->half_w = 0.5f * (float)width;
    out->half_h = 0.5f * (float)height;
    out->kx = (float)width / (2.0f * out->tan_half_x);
    out->ky = (float)height / (2.0f * out->tan_half_y);
    return true;
}
