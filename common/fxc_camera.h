/* The pinhole camera's orthonormal basis, shared by the server (server/cameras/camera.c, srv_camera_setup)
 * and the client's render cache (viewer_client/rcache/rc_camera.c), which may not link server code. Both must
 * build the same basis from the same pose, bit for bit: the client projects the points the server's rays
 * produced back to the pixels those rays went through. Before this header each kept a copy of the
 * arithmetic, and the copies had drifted apart (the server's right vector normalised in double, the client's
 * in float). Header-only: libm only. */
#ifndef FXC_CAMERA_H
#define FXC_CAMERA_H

#include <float.h>
#include <math.h>
#include <stdbool.h>

static inline void fxc_camera_normalize3(float v[3])
{
    float len = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (len > 0)
        for (int k = 0; k < 3; k++)
            v[k] /= len;
}

static inline void fxc_camera_cross3(const float a[3], const float b[3], float out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* forward, right and up (orthonormal, right = forward x up hint, up = right x forward) from a viewing
 * direction `toward` of any non-zero length and an up hint (all zero: +Y). False when toward is zero or not
 * finite, or the hint is not finite. */
static inline bool fxc_camera_basis(const float toward[3], const float up_hint_in[3], float forward[3],
                                    float right[3], float up[3])
{
    float up_hint[3] = {up_hint_in[0], up_hint_in[1], up_hint_in[2]};
    if (up_hint[0] == 0 && up_hint[1] == 0 && up_hint[2] == 0)
        up_hint[1] = 1;
    for (int k = 0; k < 3; k++) {
        if (!isfinite(toward[k]) || !isfinite(up_hint[k]))
            return false;
        forward[k] = toward[k];
    }
    float len2 = forward[0] * forward[0] + forward[1] * forward[1] + forward[2] * forward[2];
    if (!(len2 >= FLT_MIN) || !isfinite(len2)) {
        /* A direction within about 1e-19 of zero (a trace's direction of 1e-30 is valid,
         * docs/TRACE_FORMAT.md), or one whose square overflows: the float squares underflow or overflow, so
         * it is normalised in double. */
        double length = sqrt((double)forward[0] * forward[0] + (double)forward[1] * forward[1] +
                             (double)forward[2] * forward[2]);
        if (!(length > 0) || !isfinite(length))
            return false;
        for (int k = 0; k < 3; k++)
            forward[k] = (float)(forward[k] / length);
    } else {
        fxc_camera_normalize3(forward);
    }
    /* right = forward x up hint, normalised in double: looking within a tiny angle of the up hint (a target
     * 1e-30 m beside the point straight below) the product is tiny, its squared length underflows a float
     * (or is flushed to zero in a tracing thread), and right stayed unnormalised: the image plane collapsed
     * onto the forward direction, every pixel the same ray (found by tests/stability/stab_cameras.c). Within
     * 1e-6 rad of the up hint any perpendicular will do. */
    double hint_length = sqrt((double)up_hint[0] * up_hint[0] + (double)up_hint[1] * up_hint[1] +
                              (double)up_hint[2] * up_hint[2]);
    double r[3] = {(double)forward[1] * up_hint[2] - (double)forward[2] * up_hint[1],
                   (double)forward[2] * up_hint[0] - (double)forward[0] * up_hint[2],
                   (double)forward[0] * up_hint[1] - (double)forward[1] * up_hint[0]};
    double r_length = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    if (!(hint_length > 0) || !(r_length > 1e-6 * hint_length)) {
        float alt[3] = {1, 0, 0};
        if (fabsf(forward[0]) > 0.9f)
            alt[0] = 0, alt[2] = 1;
        fxc_camera_cross3(forward, alt, right);
        fxc_camera_normalize3(right);
    } else {
        for (int k = 0; k < 3; k++)
            right[k] = (float)(r[k] / r_length);
    }
    fxc_camera_cross3(right, forward, up);
    return true;
}

#endif
