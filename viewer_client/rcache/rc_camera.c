/* Cameras: the server's pinhole model (server/cameras/camera.h, srv_camera_setup and srv_camera_ray), rebuilt
 * from a wire pose (position, direction with +Y up, vertical field of view) with the same float operations,
 * so that projecting a point the server's ray produced lands it back on the pixel the ray went through. The
 * client may not link server code: the basis is common/fxc_camera.h's, which the server uses too. */
#include "rc_internal.h"

#include "fxc_camera.h"

#include <math.h>
#include <string.h>

bool view_rc__view_setup(const view_rc_camera *cam, uint32_t width, uint32_t height,
                         const double cache_origin[3], rc_view *out)
{
    memset(out, 0, sizeof *out);
    if (width == 0 || height == 0 || !(cam->fov_deg > 0 && cam->fov_deg < 180))
        return false;
    const float up_hint[3] = {0, 1, 0};
    float toward[3];
    for (int k = 0; k < 3; k++) {
        if (!isfinite(cam->position[k]))
            return false;
        out->origin[k] = cam->position[k];
        out->rel[k] = (float)(cam->position[k] - cache_origin[k]);
        toward[k] = cam->direction[k];
    }
    if (!fxc_camera_basis(toward, up_hint, out->forward, out->right, out->up))
        return false;
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
