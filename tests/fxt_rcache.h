/* A small analytic scene for the render cache's tests (tests/test_rcache*.c), ray cast in double apart from
 * the code under test: a checkered floor y = fxt_rc_floor_y (-1.5 unless a test lowers the sphere onto it), a
 * sphere of radius 1 at fxt_rc_sphere_centre (shaded by its normal), a striped wall z = -12 up to y = 3, and
 * the sky beyond. Also the server's pinhole model in double, binary16 rounding as on the wire, and two
 * asserting wrappers of the library's calls. */
#ifndef FXT_RCACHE_H
#define FXT_RCACHE_H

#include "rcache.h"

#include <stdbool.h>
#include <stdint.h>

#define FXT_RC_PI 3.14159265358979323846

/* A ray's hit: the distance along the unit ray (+inf for the sky) and the colour. */
typedef struct fxt_rc_hit {
    double t;
    uint8_t rgb[3];
} fxt_rc_hit;

extern const double fxt_rc_sphere_centre[3];
extern double fxt_rc_floor_y;

/* The distance along the unit ray d from o to the sphere (c, r), +inf when it misses or is behind. */
double fxt_rc_sphere_t(const double o[3], const double d[3], const double c[3], double r);
fxt_rc_hit fxt_rc_cast(const double o[3], const double d[3], bool with_sphere, bool with_floor);
view_rc_camera fxt_rc_look(double px, double py, double pz, double tx, double ty, double tz, float fov);
/* The unit ray through pixel (x + 0.5, y + 0.5) of cam's w x h image, the server's pinhole model in double.
 */
void fxt_rc_pixel_ray(const view_rc_camera *cam, uint32_t w, uint32_t h, uint32_t x, uint32_t y, double d[3]);
/* A frame of the scene: colours (rgb, 3 a pixel) and distances along the rays. */
void fxt_rc_render_scene(const view_rc_camera *cam, uint32_t w, uint32_t h, bool with_sphere, bool with_floor,
                         uint8_t *rgb, float *depth);
/* Round to IEEE binary16 (nearest, ties to even), as a PROTO_DEPTH_HALF frame carries it. */
float fxt_rc_to_half(float v);
/* view_rc_create and view_rc_render, asserting success. */
view_rc *fxt_rc_make(const view_rc_desc *d);
void fxt_rc_render(view_rc *rc, const view_rc_camera *cam, const view_rc_camera *predicted, view_rc_frame *f);

#endif
