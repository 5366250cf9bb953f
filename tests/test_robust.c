/* Numerical robustness of the whole frame (DESIGN.md "Numerical robustness"): the embedded scene at 1e-4 and
 * 1e4 scale, far from the origin, gives the same AO and shadows as at scale 1 within a stated bound; cameras
 * with extreme fields of view and lights of extreme intensity give finite output. */
#include "test_util.h"

#include "camgen.h"
#include "engine.h"
#include "fxt_scene.h"
#include "scene_internal.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct frame_result {
    double mean_ao, mean_shadow;
    uint64_t visible;
    bool finite;
} frame_result;

/* Runs 5 frames of one static viewer and returns the means of the AO and shadow views of the last one. */
static frame_result run_view(scene *s, float fov_override)
{
    scene_error err = {0};
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    assert_non_null(rt);
    const uint32_t w = 96, h = 54;
    srv_loop_desc d = {.s = s, .rt = rt, .seed = 3, .pool_bytes = 32u << 20, .keep_views = true};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, w, h, &id);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, s, 0, 1, 0, 1);
    if (fov_override > 0)
        cam.fov_deg = fov_override;
    srv_frame_stats st;
    for (int frame = 0; frame < 5; frame++)
        fxt_frame(loop, &id, 1, &cam, &st);
    frame_result r = {.visible = st.pixels_visible, .finite = true};
    const float *ao = srv_viewer_view(loop, id, SRV_VIEW_AO),
                *shadow = srv_viewer_view(loop, id, SRV_VIEW_SHADOW);
    const float *rad = srv_viewer_radiance(loop, id);
    for (size_t i = 0; i < (size_t)w * h; i++) {
        r.mean_ao += ao[i];
        r.mean_shadow += shadow[i];
        r.finite &= isfinite(ao[i]) && isfinite(shadow[i]);
    }
    for (size_t i = 0; i < (size_t)w * h * 3; i++)
        r.finite &= isfinite(rad[i]) && rad[i] >= 0 && rad[i] <= FLT_MAX;
    r.mean_ao /= (double)w * h;
    r.mean_shadow /= (double)w * h;
    srv_loop_free(loop);
    scene_rt_free(rt);
    return r;
}

/* The same view at scale 1, 1e-4 near the origin and 1e4 at 1e5 from it: finite, and the mean AO and lit
 * fraction within 0.01 of scale 1 (measured: AO 0.0017 lower; lit fraction equal at 1e-4, 0.0002 lower at
 * 1e4, which is now kept relative to a local origin; the difference is the sample noise of a different float
 * layout; test_origin.c compares a scene at 1e6 image by image). Before the ray offset scaled with the scene,
 * the 1e-4 scene lost 0.6 % of its lit fraction to origins lifted by 1.5 % of the scene's size. */
static void test_scales_agree(void **state)
{
    (void)state;
    scene *unit = fxt_transformed_default(1.0f, 0.0f, 1.0f);
    frame_result ref = run_view(unit, 0);
    scene_free(unit);
    assert_true(ref.finite);
    assert_true(ref.visible > 1000);
    const float scales[2][2] = {{1e-4f, 0.0f}, {1e4f, 1e5f}};
    for (int i = 0; i < 2; i++) {
        scene *s = fxt_transformed_default(scales[i][0], scales[i][1], 1.0f);
        frame_result r = run_view(s, 0);
        scene_free(s);
        print_message("scale %g offset %g: AO %.4f (scale 1: %.4f), lit %.4f (scale 1: %.4f), visible %llu\n",
                      (double)scales[i][0], (double)scales[i][1], r.mean_ao, ref.mean_ao, r.mean_shadow,
                      ref.mean_shadow, (unsigned long long)r.visible);
        assert_true(r.finite);
        assert_true(fabs(r.mean_ao - ref.mean_ao) < 0.01);
        assert_true(fabs(r.mean_shadow - ref.mean_shadow) < 0.01);
        assert_true(llabs((long long)r.visible - (long long)ref.visible) < (long long)ref.visible / 50);
    }
}

/* Fields of view of 0.5 and 179.5 degrees: finite output, no failure. */
static void test_extreme_fov(void **state)
{
    (void)state;
    scene *s = fxt_transformed_default(1.0f, 0.0f, 1.0f);
    frame_result narrow = run_view(s, 0.5f);
    frame_result wide = run_view(s, 179.5f);
    assert_true(narrow.finite && wide.finite);
    assert_true(narrow.visible > 0 && wide.visible > 0);
    scene_free(s);
}

/* Lights and sky at 1e30 and 1e-30 times their intensity: the radiance saturates, never infinite or NaN. */
static void test_extreme_intensity(void **state)
{
    (void)state;
    const float factors[2] = {1e30f, 1e-30f};
    for (int i = 0; i < 2; i++) {
        scene *s = fxt_transformed_default(1.0f, 0.0f, factors[i]);
        frame_result r = run_view(s, 0);
        assert_true(r.finite);
        scene_free(s);
    }
}

/* ---- a point light at every scale against its closed form ---------------------------------------------- */

/* An open ground of side 8 s (albedo 0.5) and a lamp s above it of intensity s^2 (colour (1, 0.5, 0.25)), no
 * sky: compose's radiance is albedo I cos / d^2, the same at every scale s. Checked per pixel against the
 * point where the pixel's ray meets the plane, in double, with shadows on (every ray reaches the lamp) and
 * nothing else. Relative error at most 1e-3: the visible point is rebuilt from a float depth (about 1e-6
 * relative at the pixel) and the camera's float frame. Before, 1 / d^2 was floored at d = 0.1 mm, so at
 * s = 1e-5 every pixel came out 1e4 .. 1e5 times too dark. Returns the worst relative error. */
static double point_light_worst_error(double scale)
{
    scene *s = fxt_new_scene();
    const double side = 8 * scale;
    fxt_add_quad(s, "ground", (double[3]){-side / 2, 0, -side / 2}, (double[3]){0, 0, side},
                 (double[3]){side, 0, 0}, 4);
    const double lamp[3] = {0.2 * scale, scale, -0.1 * scale}, intensity = scale * scale;
    const double colour[3] = {1, 0.5, 0.25};
    scene_light light = {.type = SCENE_LIGHT_POINT,
                         .position = {(float)lamp[0], (float)lamp[1], (float)lamp[2]},
                         .color = {1, 0.5f, 0.25f},
                         .intensity = (float)intensity};
    scene_error err = {0};
    assert_int_equal(scene__add_light_world(s, &light, lamp, "test lamp", &err), SCENE_OK);
    scene_rt *rt = fxt_finish_scene(s, (float)fmin(16 / scale, 1e6), (float)scale);
    const uint32_t w = 48, h = 27;
    srv_loop_desc d = {.s = s, .rt = rt, .seed = 3, .pool_bytes = 16u << 20};
    fxt_effects_on(&d, (const char *const[]){"shadow"}, 1);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, w, h, &id);
    srv_camera cam = {.position = {0, (float)(2 * scale), (float)(0.5 * scale)}, .fov_deg = 40};
    srv_frame_stats st;
    for (int frame = 0; frame < 4; frame++)
        fxt_frame(loop, &id, 1, &cam, &st);
    srv_camera_frame f;
    assert_true(srv_camera_setup(&cam, w, h, &f));
    const float *rad = srv_viewer_radiance(loop, id);
    double worst = 0;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            double sx = (2.0 * (x + 0.5) / w - 1.0) * f.tan_half_x,
                   sy = (1.0 - 2.0 * (y + 0.5) / h) * f.tan_half_y;
            double dir[3], p[3], to_lamp[3], d2 = 0;
            for (int k = 0; k < 3; k++)
                dir[k] = f.forward[k] + sx * f.right[k] + sy * f.up[k];
            assert_true(dir[1] < 0); /* every pixel sees the ground */
            double t = -(double)cam.position[1] / dir[1];
            for (int k = 0; k < 3; k++) {
                p[k] = cam.position[k] + t * dir[k];
                to_lamp[k] = lamp[k] - p[k];
                d2 += to_lamp[k] * to_lamp[k];
            }
            if (fabs(p[0]) > side / 2 || fabs(p[2]) > side / 2)
                fail_msg("pixel (%u, %u) misses the ground", x, y);
            for (int k = 0; k < 3; k++) {
                double expected = 0.5 * intensity * (to_lamp[1] / sqrt(d2)) / d2 * colour[k];
                double got = rad[3 * ((size_t)y * w + x) + k];
                worst = fmax(worst, fabs(got - expected) / expected);
            }
        }
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
    return worst;
}

static void test_point_light_every_scale(void **state)
{
    (void)state;
    const double scales[] = {1e-5, 1, 1e4};
    for (size_t i = 0; i < sizeof scales / sizeof scales[0]; i++) {
        double worst = point_light_worst_error(scales[i]);
        print_message("scale %g: worst relative error of the lamp's term %.3g\n", scales[i], worst);
        if (!(worst < 1e-3))
            fail_msg("scale %g: worst relative error %.3g", scales[i], worst);
    }
}

/* ---- a sun at grazing angles ------------------------------------------------------------------------- */

/* An open ground (8 x 8 m) under a sun `elevation_deg` above its plane, shadows on: nothing occludes it, so
 * every pixel's lit fraction is 1 and its radiance albedo x sin(elevation) (closed form), down to 0.01 degree,
 * where a shadow ray runs 5,700 m along the ground per metre it rises (no self-shadowing from the ray's
 * origin offset). At the horizon and below the ground faces away: radiance 0, never negative or NaN.
 * Returns the smallest lit fraction and the worst relative error of the radiance (0 when nothing is lit). */
static void grazing_sun(double elevation_deg, double *least_lit, double *worst)
{
    scene *s = fxt_new_scene(); /* albedo 0.5 */
    fxt_add_quad(s, "ground", (double[3]){-4, 0, -4}, (double[3]){0, 0, 8}, (double[3]){8, 0, 0}, 4);
    double e = elevation_deg * M_PI / 180.0;
    fxt_add_sun(s, (float)cos(e), (float)-sin(e), 0.3f * (float)cos(e));
    scene_rt *rt = fxt_finish_scene(s, 16, 1);
    const uint32_t w = 48, h = 27;
    srv_loop_desc d = {.s = s, .rt = rt, .seed = 3, .pool_bytes = 16u << 20, .keep_views = true};
    fxt_effects_on(&d, (const char *const[]){"shadow"}, 1);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, w, h, &id);
    srv_camera cam = {.position = {0, 2, 0.5f}, .fov_deg = 40};
    srv_frame_stats st;
    for (int frame = 0; frame < 4; frame++)
        fxt_frame(loop, &id, 1, &cam, &st);
    const float *rad = srv_viewer_radiance(loop, id), *lit = srv_viewer_view(loop, id, SRV_VIEW_SHADOW);
    /* the irradiance of a unit sun at this elevation: the normalised direction's -y */
    double len = sqrt(cos(e) * cos(e) * 1.09 + sin(e) * sin(e)), irradiance = fmax(0.0, sin(e) / len);
    *least_lit = 1;
    *worst = 0;
    for (size_t i = 0; i < (size_t)w * h; i++) {
        *least_lit = fmin(*least_lit, lit[i]);
        for (int k = 0; k < 3; k++) {
            double got = rad[3 * i + k], expected = 0.5 * (double)(float)irradiance;
            assert_true(isfinite(got) && got >= 0);
            *worst = fmax(*worst, expected > 0 ? fabs(got - expected) / expected : got);
        }
    }
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
}

static void test_grazing_sun(void **state)
{
    (void)state;
    const double elevations[] = {30, 1, 0.1, 0.01, 0, -0.01};
    for (size_t i = 0; i < sizeof elevations / sizeof elevations[0]; i++) {
        double least_lit, worst;
        grazing_sun(elevations[i], &least_lit, &worst);
        print_message("sun %g degrees up: least lit fraction %.4f, worst radiance error %.3g\n",
                      elevations[i], least_lit, worst);
        if (elevations[i] > 0) {
            assert_true(least_lit == 1.0);
            assert_true(worst < 1e-3);
        } else {
            assert_true(worst == 0);
        }
    }
}

/* ---- a lamp inside a closed box, and one on the ground ---------------------------------------------------- */

/* The image-plane offsets of pixel column x and row y (the camera model, pixel centres at +0.5). */
static double sx_of(const srv_camera_frame *f, uint32_t x, uint32_t w)
{
    return (2.0 * (x + 0.5) / w - 1.0) * f->tan_half_x;
}

static double sy_of(const srv_camera_frame *f, uint32_t y, uint32_t h)
{
    return (1.0 - 2.0 * (y + 0.5) / h) * f->tan_half_y;
}

/* The largest radiance on an open ground (8 x 8 m, no sky) lit only by a point lamp at `lamp`, with a closed
 * solid box (faces out) [-0.5, 0.5] x [0.2, 1.2] x [-0.5, 0.5] when `box`; shadows and probes on. */
static double lamp_ground_max(const float lamp[3], bool box)
{
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "ground", (double[3]){-4, 0, -4}, (double[3]){0, 0, 8}, (double[3]){8, 0, 0}, 4);
    if (box)
        fxt_add_box(s, "box", (double[3]){-0.5, 0.2, -0.5}, (double[3]){0.5, 1.2, 0.5}, false, 2);
    scene_light light = {.type = SCENE_LIGHT_POINT,
                         .position = {lamp[0], lamp[1], lamp[2]},
                         .color = {1, 1, 1},
                         .intensity = 1};
    scene_error err = {0};
    assert_int_equal(scene__add_light(s, &light, "test lamp", &err), SCENE_OK);
    scene_rt *rt = fxt_finish_scene(s, 16, 1);
    const uint32_t w = 48, h = 27;
    srv_loop_desc d = {.s = s, .rt = rt, .seed = 3, .pool_bytes = 32u << 20};
    fxt_effects_on(&d, (const char *const[]){"shadow", "probes"}, 2);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, w, h, &id);
    srv_camera cam = {.position = {0, 2, 2.5f}, .target = {0, 0, 0}, .fov_deg = 60};
    srv_frame_stats st;
    for (int frame = 0; frame < 6; frame++)
        fxt_frame(loop, &id, 1, &cam, &st);
    const float *rad = srv_viewer_radiance(loop, id), *depth = srv_viewer_depth(loop, id);
    srv_camera_frame f;
    assert_true(srv_camera_setup(&cam, w, h, &f));
    double largest = 0;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            for (int k = 0; k < 3; k++)
                assert_true(isfinite(rad[3 * i + k]) && rad[3 * i + k] >= 0);
            /* the ground's pixels: the ray meets y = 0 at the distance the pixel's depth holds */
            double dir[3], dir_len = 0;
            for (int k = 0; k < 3; k++) {
                dir[k] = f.forward[k] + sx_of(&f, x, w) * f.right[k] + sy_of(&f, y, h) * f.up[k];
                dir_len += dir[k] * dir[k];
            }
            double ground = dir[1] < 0 ? -2.0 / dir[1] * sqrt(dir_len) : INFINITY;
            if (!(fabs(depth[i] - ground) < 1e-3 * ground))
                continue;
            largest = fmax(largest, fmax(rad[3 * i], fmax(rad[3 * i + 1], rad[3 * i + 2])));
        }
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
    return largest;
}

/* A lamp inside a closed solid box lights nothing outside (the ground is black: no shadow ray and no probe
 * ray leaks through the box), the same lamp with no box lights the ground (the test can fail), and a lamp
 * exactly on the ground (cos 0 at every ground point) lights none of it: 0, not NaN or 1/0. */
static void test_lamp_inside_box_and_on_ground(void **state)
{
    (void)state;
    double open = lamp_ground_max((const float[3]){0, 0.7f, 0}, false),
           boxed = lamp_ground_max((const float[3]){0, 0.7f, 0}, true),
           on = lamp_ground_max((const float[3]){0.3f, 0, 0.2f}, false);
    print_message(
        "ground's brightest pixel: lamp in the open %.4g, inside the box %.4g, on the ground %.4g\n", open,
        boxed, on);
    assert_true(open > 0.1);
    assert_true(boxed == 0);
    assert_true(on == 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_scales_agree),      cmocka_unit_test(test_extreme_fov),
        cmocka_unit_test(test_extreme_intensity), cmocka_unit_test(test_point_light_every_scale),
        cmocka_unit_test(test_grazing_sun),       cmocka_unit_test(test_lamp_inside_box_and_on_ground),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
