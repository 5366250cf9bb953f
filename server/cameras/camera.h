/* Pinhole cameras: where a viewer stands and looks, and the primary ray through each pixel. */
#ifndef FXC_SERVER_CAMERA_H
#define FXC_SERVER_CAMERA_H

#include "scene.h"

#include <math.h>

typedef struct srv_camera {
    float position[3];
    float target[3];
    float up[3];   /* world up hint (default 0,1,0 when zero) */
    float fov_deg; /* vertical field of view, degrees, (0, 180) */
} srv_camera;

/* A camera's orthonormal frame and image-plane scale, precomputed once per frame. */
typedef struct srv_camera_frame {
    float origin[3];
    float forward[3], right[3], up[3];
    float tan_half_y, tan_half_x; /* image-plane half extents at distance 1 */
    uint32_t width, height;
} srv_camera_frame;

/* Precomputes the frame for an image of width x height pixels. Returns false when the camera is
 * degenerate (position equals target, non-finite values, field of view outside (0, 180)) or its position or
 * target lies farther than SCENE_MAX_CAMERA_REACH from the scene's local origin (rays from there overflow:
 * Embree refuses them). */
bool srv_camera_setup(const srv_camera *cam, uint32_t width, uint32_t height, srv_camera_frame *out);

/* The unit direction of the ray through image position (px, py) (pixel centres at +0.5, y down). Inline:
 * it runs once per pixel in visibility and compose. */
static inline void srv_camera_ray(const srv_camera_frame *f, float px, float py, float dir[3])
{
    float sx = (2.0f * px / (float)f->width - 1.0f) * f->tan_half_x;
    float sy = (1.0f - 2.0f * py / (float)f->height) * f->tan_half_y;
    float len2 = 0;
    for (int k = 0; k < 3; k++) {
        dir[k] = f->forward[k] + sx * f->right[k] + sy * f->up[k];
        len2 += dir[k] * dir[k];
    }
    float inv = 1.0f / sqrtf(len2);
    for (int k = 0; k < 3; k++)
        dir[k] *= inv;
}

/* A camera that frames the whole scene: the scene's own camera when it has one, else one looking at the
 * centre of the bounding box from above and in front. */
srv_camera srv_camera_default(const scene *s);

#endif
