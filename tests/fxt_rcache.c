/* The render cache tests' analytic scene (fxt_rcache.h). */
#include "fxt_rcache.h"

#include "test_util.h"

#include <math.h>
#include <string.h>

double fxt_rc_sphere_t(const double o[3], const double d[3], const double c[3], double r)
{
    double oc[3] = {o[0] - c[0], o[1] - c[1], o[2] - c[2]};
    double b = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
    double cc = oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - r * r;
    double disc = b * b - cc;
    if (disc < 0)
        return INFINITY;
    double t = -b - sqrt(disc);
    return t > 1e-9 ? t : INFINITY;
}

const double fxt_rc_sphere_centre[3] = {0, 0, -5};
double fxt_rc_floor_y = -1.5;

fxt_rc_hit fxt_rc_cast(const double o[3], const double d[3], bool with_sphere, bool with_floor)
{
    fxt_rc_hit h = {INFINITY, {100, 150, 220}};
    double ts = with_sphere ? fxt_rc_sphere_t(o, d, fxt_rc_sphere_centre, 1.0) : INFINITY;
    double tf = with_floor && d[1] < 0 ? (fxt_rc_floor_y - o[1]) / d[1] : INFINITY;
    double tw = d[2] < 0 ? (-12.0 - o[2]) / d[2] : INFINITY;
    if (tw < INFINITY && o[1] + tw * d[1] > 3)
        tw = INFINITY;
    if (ts < h.t && ts <= tf && ts <= tw) {
        h.t = ts;
        double n[3];
        for (int k = 0; k < 3; k++)
            n[k] = o[k] + ts * d[k] - fxt_rc_sphere_centre[k];
        h.rgb[0] = (uint8_t)(127.5 + 127 * n[0]);
        h.rgb[1] = (uint8_t)(127.5 + 127 * n[1]);
        h.rgb[2] = (uint8_t)(127.5 + 127 * n[2]);
    } else if (tf < h.t && tf <= tw) {
        h.t = tf;
        double x = o[0] + tf * d[0], z = o[2] + tf * d[2];
        bool dark = ((int)floor(x) + (int)floor(z)) & 1;
        h.rgb[0] = dark ? 40 : 210, h.rgb[1] = dark ? 50 : 200, h.rgb[2] = dark ? 60 : 190;
    } else if (tw < h.t) {
        h.t = tw;
        double y = o[1] + tw * d[1];
        bool band = ((int)floor(2 * y + 100)) & 1;
        h.rgb[0] = band ? 180 : 90, h.rgb[1] = band ? 60 : 120, h.rgb[2] = 30;
    }
    return h;
}

view_rc_camera fxt_rc_look(double px, double py, double pz, double tx, double ty, double tz, float fov)
{
    view_rc_camera c = {.position = {px, py, pz},
                        .direction = {(float)(tx - px), (float)(ty - py), (float)(tz - pz)},
                        .fov_deg = fov};
    return c;
}

/* The unit ray through pixel (x + 0.5, y + 0.5) of cam's w x h image, the server's pinhole model in double.
 */
void fxt_rc_pixel_ray(const view_rc_camera *cam, uint32_t w, uint32_t h, uint32_t x, uint32_t y, double d[3])
{
    double f[3] = {cam->direction[0], cam->direction[1], cam->direction[2]};
    double fl = sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    for (int k = 0; k < 3; k++)
        f[k] /= fl;
    double r[3] = {-f[2], 0, f[0]}; /* f x (0, 1, 0) */
    double rl = sqrt(r[0] * r[0] + r[2] * r[2]);
    r[0] /= rl, r[2] /= rl;
    double u[3] = {r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]};
    double thy = tan(cam->fov_deg * FXT_RC_PI / 360.0), thx = thy * w / h;
    double sx = (2.0 * (x + 0.5) / w - 1.0) * thx, sy = (1.0 - 2.0 * (y + 0.5) / h) * thy;
    double len = 0;
    for (int k = 0; k < 3; k++) {
        d[k] = f[k] + sx * r[k] + sy * u[k];
        len += d[k] * d[k];
    }
    for (int k = 0; k < 3; k++)
        d[k] /= sqrt(len);
}

/* A frame of the scene: colours and distances along the rays. */
void fxt_rc_render_scene(const view_rc_camera *cam, uint32_t w, uint32_t h, bool with_sphere, bool with_floor,
                         uint8_t *rgb, float *depth)
{
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            double d[3];
            fxt_rc_pixel_ray(cam, w, h, x, y, d);
            fxt_rc_hit hit = fxt_rc_cast(cam->position, d, with_sphere, with_floor);
            size_t p = (size_t)y * w + x;
            memcpy(rgb + 3 * p, hit.rgb, 3);
            depth[p] = (float)hit.t;
        }
}

/* Round to IEEE binary16 (nearest, ties to even), as a PROTO_DEPTH_HALF frame carries it. */
float fxt_rc_to_half(float v)
{
    if (!isfinite(v) || v == 0)
        return v;
    int e;
    double m = frexp(v, &e); /* v = m 2^e, 0.5 <= |m| < 1: 11 significant bits */
    double scaled = m * 2048.0;
    double rounded = nearbyint(scaled);
    return (float)ldexp(rounded / 2048.0, e);
}

view_rc *fxt_rc_make(const view_rc_desc *d)
{
    view_rc *rc = NULL;
    assert_int_equal(view_rc_create(d, &rc), FXC_OK);
    assert_non_null(rc);
    return rc;
}

void fxt_rc_render(view_rc *rc, const view_rc_camera *cam, const view_rc_camera *predicted, view_rc_frame *f)
{
    assert_int_equal(view_rc_render(rc, cam, predicted, f), FXC_OK);
}

/* ---- descriptions and cameras -------------------------------------------------------------------------- */