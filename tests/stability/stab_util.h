/* The stability suite's shared checker and helpers (tests/stability/, docs/ERROR.md "Stability suite").
 *
 * stab_check_loop() is run after every frame of every case: it reads every float a viewer's frame has
 * (linear radiance, depth, sRGB bytes, the kept views), every figure of srv_frame_stats and srv_memory, and
 * every payload texel of every block the caches hold (white-box, through the engine's cache kinds), and fails
 * the test on the first value that is not finite or not consistent with the others. The closed forms and
 * the second methods each case compares against are in the case's own file; what several cases share (a
 * plane's depth along a pixel's ray, the relative RMSE of two images) is here. */
#ifndef FXC_STAB_UTIL_H
#define FXC_STAB_UTIL_H

#include "test_util.h"

#include "camera.h"
#include "engine.h"
#include "fxt_scene.h"

#include <stdbool.h>
#include <stdint.h>

/* What a check looked at, so a case can assert it was not vacuous. */
typedef struct stab_checked {
    uint64_t pixels;                  /* viewer pixels checked (all viewers) */
    uint64_t sky_pixels;              /* of which saw the sky */
    uint64_t view_values;             /* kept-view floats checked */
    uint64_t texels[SRV_MAX_EFFECTS]; /* payload texels (cells) with data checked, per effect */
    uint64_t blocks;                  /* resident blocks walked */
} stab_checked;

/* Checks the loop's state after srv_loop_frame() returned st: every present viewer's frame, the frame's
 * statistics, the memory report and every cache payload. Fails the test (cmocka) at the first finding, naming
 * the viewer, pixel, effect or figure. */
stab_checked stab_check_loop(srv_loop *loop, const srv_frame_stats *st);

/* Sets the cameras of ids[0..n) (one camera for all when `same`), runs `frames` frames and checks each with
 * stab_check_loop(); returns what the last check looked at. st receives the last frame's statistics. */
stab_checked stab_frames(srv_loop *loop, const srv_viewer_id *ids, uint32_t n, const srv_camera *cameras,
                         bool same, uint32_t frames, srv_frame_stats *st);

/* A copy (caller frees) of a viewer's linear radiance, w * h * 3 floats. */
float *stab_copy_radiance(const srv_loop *loop, srv_viewer_id id);

/* The world-space point a pixel's primary ray reaches at `depth`, in double (scene-local). */
void stab_pixel_point(const srv_camera_frame *f, uint32_t x, uint32_t y, float depth, double point[3]);

/* Distance along the pixel's primary ray (as visibility traces it) to the plane y = plane_y, in double;
 * INFINITY when the ray does not reach it. */
double stab_plane_depth(const srv_camera_frame *f, uint32_t x, uint32_t y, double plane_y);

/* Root mean square of (b - a) over n floats, relative to the mean of |a|. */
double stab_relative_rmse(const float *a, const float *b, size_t n);

/* An open square floor y = height, side 2 * half about (cx, cz), cells x cells quads, facing up, grey (0.5). */
void stab_add_floor(scene *s, double cx, double height, double cz, double half, uint32_t cells);

/* Adds a point light at a scene-local position (the scene is still being built: world == local until
 * finalisation; call before fxt_finish_scene). */
void stab_add_point_light(scene *s, float x, float y, float z, float intensity);

/* The sky's radiance (colour x intensity), per channel. */
void stab_sky(const scene *s, float sky[3]);

/* Sets an open-sky, one-sun lighting: sky colour (r, g, b) at `sky_intensity`, and light 0 (a directional
 * light fxt_add_sun made) travelling along dir with `intensity`. */
void stab_set_sun(scene *s, const float dir[3], float intensity);

#endif

/* ---- the bounce scene (stab_light.c, stab_stiffness.c) ------------------------------------------------- */

/* A floor (y = 0.1, x 0.1..4.1, z -5..5, albedo 0.5) lit by a sun straight down (light 0, intensity
 * `intensity`), a black sky, and a wall (x = 0.1, facing +x, y 0.1..5.1) the sun does not reach (it travels
 * along the wall's plane): what lights the wall is the floor's bounce, which only the probes carry. The planes
 * lie off the probe grid's planes (multiples of 0.5 m) so no probe sits on a surface, and reach beyond the
 * camera's view, so no probe behind the wall's edges is requested (those switch off and on again every other
 * update: docs/ERROR.md). */
scene *stab_bounce_scene(float intensity, scene_rt **rt);

/* A camera in the bounce scene looking at the wall across the floor. */
srv_camera stab_bounce_camera(void);

/* The mean radiance (channel 0) of the wall's inner pixels (away from its edges: y 0.5..1.7, |z| < 1.4) and
 * of the floor's (x 1.5..3.5, |z| < 1.4), from a viewer's depth and radiance. */
void stab_bounce_means(const srv_loop *loop, srv_viewer_id id, double *wall, double *floor);

/* A loop over the bounce scene: shadows and probes (64 rays, plain hysteresis h, finest cell 0.5 m), one viewer of
 * 48 x 32 (views kept). */
srv_loop *stab_bounce_loop(scene *s, scene_rt *rt, float h, srv_viewer_id *id);

/* One frame of the bounce scene from stab_bounce_camera() (checked): the wall's and the floor's mean radiance. */
void stab_bounce_frame(srv_loop *loop, srv_viewer_id id, double *wall, double *floor);

/* The wall's steady light: 40 frames at hysteresis 0.5 (the blend's fixed point does not depend on h; the
 * error falls by about 0.5 per frame), then its mean and frame-to-frame spread over `frames` more (the probes'
 * Monte Carlo noise after the blend). */
void stab_bounce_steady(scene *s, scene_rt *rt, uint32_t frames, double *mean, double *spread);

/* The update counts of the probes switched on and requested this frame in the loop's world-space cache, by key
 * (white-box). */
typedef struct stab_probe_counts {
    uint32_t count;
    uint64_t key[8192];
    uint32_t updates[8192];
} stab_probe_counts;
void stab_probe_snapshot(srv_loop *loop, stab_probe_counts *out);

/* The fewest and most updates since `then` of the probes on both then and now and not restarted since (a
 * probe switched off and on again starts its count afresh); returns how many such probes there are. */
uint32_t stab_probe_updates_since(srv_loop *loop, const stab_probe_counts *then, uint32_t *least,
                                  uint32_t *most);

/* ---- an open plane (stab_light.c, stab_cameras.c, stab_geometry.c) --------------------------------------- */

/* Float rounding of compose's formula, albedo x (E cos + sky): the light direction's normalisation (one
 * rounding per component, so cos is within 2^-23 relative) and six products and sums, each within 2^-24
 * relative: 2^-19 (1.9e-6) relative bounds them all with room. */
#define STAB_FORMULA_TOLERANCE 0x1p-19

/* An open floor (y = 0.3, 40 m wide, about (0.7, -0.4), albedo 0.5), a sun along dir with `intensity`, a sky
 * (0.2, 0.3, 0.4) x sky_intensity; finalised at 4 texels per metre, AO radius 1 m. */
scene *stab_open_plane(const float dir[3], float intensity, float sky_intensity, scene_rt **rt);

/* The closed form of a floor facing +y under s's light 0 (a sun) and sky, with nothing above it: every shadow
 * and AO ray escapes, so radiance = albedo 0.5 x (E max(0, cos) + sky), per channel. */
void stab_plane_closed_form(const scene *s, double out[3]);

/* What stab_check_open_plane found. */
typedef struct stab_plane_result {
    uint64_t plane_pixels, sky_pixels;
    double worst_depth;    /* largest depth error over its bound */
    double worst_radiance; /* largest relative radiance error */
} stab_plane_result;

/* Checks every pixel of viewer id (rendered from cam) over the floor stab_open_plane makes (or any floor
 * y = plane_y, |x - cx| <= half_x, |z - cz| <= half_z, with nothing above it), with shadows and AO: a pixel whose ray
 * reaches the floor more than 1e-4 of its distance inside the border must hit it at the depth along the ray
 * (computed in double from the camera's float frame) within its rounding bound, 2^-20 (1 + tan_x + tan_y) /
 * |d_y| relative (the direction's float rounding, 2^-23 per component of a sum of terms up to 1 + tan_x + tan_y,
 * amplified by 1 / |d_y| at grazing incidence; 8 x for Embree's own arithmetic), with the closed-form radiance
 * within STAB_FORMULA_TOLERANCE and (when kept) AO and lit fraction 1 (lit 0 when the sun is below the
 * horizon) within 2^-22: every texel holds exactly 1 (or 0), and a filter's weights sum to 1 within four
 * roundings; a ray that misses it by as much sees the sky. Fails the test at the first finding. */
stab_plane_result stab_check_open_plane(const srv_loop *loop, srv_viewer_id id, const srv_camera *cam,
                                        double plane_y, double cx, double cz, double half_x, double half_z);

/* ---- a box over a plane (stab_cameras.c, stab_geometry.c) ----------------------------------------------- */

/* Whether the ray from p against the light's direction dir (towards the sun) meets the box [lo, hi]. */
bool stab_box_shadows(const double p[3], const float dir[3], const double lo[3], const double hi[3]);

/* What stab_check_box_on_plane found. */
typedef struct stab_box_result {
    uint32_t plane_pixels; /* pixels at the plane's depth (within depth_tolerance relative) */
    uint32_t lit_checked;  /* of which away from the shadow's edge (lit fraction checked) */
    uint32_t dark;         /* of which in the shadow */
    uint32_t open;         /* plane pixels beyond the AO radius plus the band from the box (AO checked) */
    double worst_depth;    /* relative */
} stab_box_result;

/* Checks the kept views of viewer id (rendered from cam, shadows and AO) over a plane y = plane_y with one
 * box [lo, hi] on or over it, lit by a sun travelling along sun (s's light 0), at texel density `density` with
 * an AO radius ao_radius: plane pixels (the box hides the plane elsewhere) must lie at the plane's depth
 * within depth_tolerance (relative); their lit fraction is 1 where the sun's ray misses the box and 0 where it
 * meets it (or where the point lies under the box, when `under_is_dark`: the plane runs on under a box that
 * stands on it, and a texel reaching under it is partly dark, ARCHITECTURE.md's departure), within 2^-22,
 * except within a band of 2 texels of the level the pixel reads plus its footprint around the shadow's
 * edge: a pixel's level is round(log2 footprint), so its texel is at most 1.42 footprints (or one level-0
 * texel), a filtered read reaches a texel to either side; AO is 1 within 2^-22 beyond the AO radius plus
 * twice that band (AO reads one level coarser) from the box's footprint. Fails at the first finding. */
stab_box_result stab_check_box_on_plane(const srv_loop *loop, srv_viewer_id id, const srv_camera *cam,
                                        double plane_y, const double lo[3], const double hi[3],
                                        bool under_is_dark, float density, float ao_radius,
                                        double depth_tolerance);
