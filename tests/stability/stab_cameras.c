/* Stability suite, cameras (docs/ERROR.md "Stability suite"): fields of view of 0.5 and 170 degrees, a camera
 * whose near plane lies inside a wall, cameras looking straight up and down, a camera 1e6 m away. Each case
 * renders through the whole frame loop (every frame checked by stab_check_loop) and compares every pixel with
 * a closed form: the depth of a plane or a box along the pixel's ray, in double from the camera's own float
 * frame, and the radiance of an open plane. */
#include "stab_util.h"

#include "scene_internal.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const float sun_dir[3] = {0.4f, -0.8f, 0.3f};

/* A loop with shadows and AO (kept views) and one viewer of w x h. */
static srv_loop *plane_loop(scene *s, scene_rt *rt, bool no_cache, uint32_t w, uint32_t h, srv_viewer_id *id)
{
    srv_loop_desc d = {.s = s,
                       .rt = rt,
                       .seed = 4,
                       .keep_views = true,
                       .no_cache = no_cache,
                       .samples_per_update = 64,
                       .threads = 2};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    return fxt_loop(&d, 1, w, h, id);
}

/* Renders the open plane from cam (two frames: every texel converged; or one no-cache) and checks it. */
static stab_plane_result plane_view(scene *s, scene_rt *rt, const srv_camera *cam, bool no_cache)
{
    srv_viewer_id id;
    srv_loop *loop = plane_loop(s, rt, no_cache, 64, 36, &id);
    srv_frame_stats st;
    stab_frames(loop, &id, 1, cam, true, no_cache ? 1 : 2, &st);
    stab_plane_result r = stab_check_open_plane(loop, id, cam, (double)0.3f, 0.7, -0.4, 20.0, 20.0);
    srv_loop_free(loop);
    return r;
}

/* ---- fields of view ------------------------------------------------------------------------------------------ */

/* 0.5 and 170 degrees (and 179.9), looking down at the open plane at 30 degrees: every pixel the plane's depth
 * and closed-form radiance (stab_check_open_plane), or the sky. At 0.5 degrees a pixel covers 1.5 mm of the
 * plane, a 170th of a level-0 texel (the shadow's sub-texel grid is read); at 170 and 179.9 degrees the outer
 * pixels meet the plane at grazing angles, their footprints and levels clamped. */
static void test_fov_0_5_and_170_deg(void **state)
{
    (void)state;
    scene_rt *rt;
    scene *s = stab_open_plane(sun_dir, 2.0f, 1.0f, &rt);
    const float fovs[] = {0.5f, 170.0f, 179.9f};
    for (size_t i = 0; i < sizeof fovs / sizeof fovs[0]; i++)
        for (int no_cache = 0; no_cache < 2; no_cache++) {
            srv_camera cam = {.position = {0.2f, 3.3f, 1.9f},
                              .target = {0.2f, 0.3f, -3.296f},
                              .up = {0, 1, 0},
                              .fov_deg = fovs[i]};
            stab_plane_result r = plane_view(s, rt, &cam, no_cache);
            print_message(
                "fov %g%s: %llu plane pixels, %llu sky; worst depth error %.2f of its bound, radiance "
                "%.2e\n",
                (double)fovs[i], no_cache ? " (no cache)" : "", (unsigned long long)r.plane_pixels,
                (unsigned long long)r.sky_pixels, r.worst_depth, r.worst_radiance);
            assert_true(r.plane_pixels > 500);
            assert_true(fovs[i] < 10 || r.sky_pixels > 50);
        }
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- the near plane inside a wall ----------------------------------------------------------------------- */

/* Distance from o along unit d to the boundary of the box [lo, hi] that contains o (where the ray leaves). */
static double box_exit(const double o[3], const double d[3], const double lo[3], const double hi[3])
{
    double t = INFINITY;
    for (int k = 0; k < 3; k++) {
        if (d[k] > 0)
            t = fmin(t, (hi[k] - o[k]) / d[k]);
        else if (d[k] < 0)
            t = fmin(t, (lo[k] - o[k]) / d[k]);
    }
    return t;
}

/* A camera inside a solid wall 0.4 m thick (a box with outward faces) standing on the plane, looking along
 * it: every pixel meets the wall's inside at the distance where its ray leaves the box, within 2^-20 relative
 * (float rounding as for the plane, at incidences above 5 degrees here), and every value is finite (a back
 * face is lit as the front; ARCHITECTURE.md). A camera exactly on the plane, looking level: the rays going
 * down start on the surface they meet (depth 0, a footprint of 0); those going up see the sky or, as tnear is
 * 0, meet the plane at their own origin (depth 0): either, but finite. A camera 1 mm above it: the plane's
 * depths and closed form. */
static void test_near_plane_inside_wall(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    stab_add_floor(s, 0.7, 0.3, -0.4, 20.0, 4);
    const double lo[3] = {-2.0, 0.3, -0.2}, hi[3] = {2.0, 2.3, 0.2};
    fxt_add_box(s, "wall", lo, hi, false, 2);
    fxt_add_sun(s, sun_dir[0], sun_dir[1], sun_dir[2]);
    stab_set_sun(s, sun_dir, 2.0f);
    s->sky_color[0] = 0.2f, s->sky_color[1] = 0.3f, s->sky_color[2] = 0.4f;
    s->sky_intensity = 1.0f;
    scene_rt *rt = fxt_finish_scene(s, 4.0f, 1.0f);

    /* Inside the wall. */
    for (int no_cache = 0; no_cache < 2; no_cache++) {
        srv_viewer_id id;
        srv_loop *loop = plane_loop(s, rt, no_cache, 48, 32, &id);
        srv_camera cam = {
            .position = {-1.7f, 1.1f, 0.05f}, .target = {2.0f, 1.2f, -0.01f}, .up = {0, 1, 0}, .fov_deg = 80};
        srv_frame_stats st;
        stab_frames(loop, &id, 1, &cam, true, 2, &st);
        srv_camera_frame f;
        assert_true(srv_camera_setup(&cam, 48, 32, &f));
        const float *depth = srv_viewer_depth(loop, id);
        double worst = 0;
        for (uint32_t y = 0; y < 32; y++)
            for (uint32_t x = 0; x < 48; x++) {
                double q[3], o[3] = {f.origin[0], f.origin[1], f.origin[2]}, d[3];
                stab_pixel_point(&f, x, y, 1.0f, q);
                for (int k = 0; k < 3; k++)
                    d[k] = q[k] - o[k];
                double t = box_exit(o, d, lo, hi), error = fabs(depth[(size_t)y * 48 + x] - t) / t;
                worst = fmax(worst, error);
                if (!(error <= 0x1p-20))
                    fail_msg("inside the wall, pixel (%u, %u): depth %.9g, the box's %.9g", x, y,
                             (double)depth[(size_t)y * 48 + x], t);
            }
        assert_int_equal(st.pixels_visible, 48 * 32);
        print_message(
            "camera inside the wall%s: every pixel meets the wall's inside, worst relative depth error "
            "%.2e\n",
            no_cache ? " (no cache)" : "", worst);
        srv_loop_free(loop);
    }

    scene_rt_free(rt);
    scene_free(s);

    /* On the open plane, and 1 mm above it, looking level. */
    s = stab_open_plane(sun_dir, 2.0f, 1.0f, &rt);
    for (int above = 0; above < 2; above++)
        for (int no_cache = 0; no_cache < 2; no_cache++) {
            srv_viewer_id id;
            srv_loop *loop = plane_loop(s, rt, no_cache, 48, 32, &id);
            float y0 = above ? 0.301f : 0.3f;
            srv_camera cam = {
                .position = {0.7f, y0, 3.0f}, .target = {0.7f, y0, 9.0f}, .up = {0, 1, 0}, .fov_deg = 60};
            srv_frame_stats st;
            stab_frames(loop, &id, 1, &cam, true, 2, &st);
            srv_camera_frame f;
            assert_true(srv_camera_setup(&cam, 48, 32, &f));
            const float *depth = srv_viewer_depth(loop, id);
            uint64_t down = 0;
            if (above) {
                stab_plane_result r =
                    stab_check_open_plane(loop, id, &cam, (double)0.3f, 0.7, -0.4, 20.0, 20.0);
                down = r.plane_pixels;
                assert_true(r.sky_pixels > 0);
            } else {
                for (uint32_t y = 0; y < 32; y++)
                    for (uint32_t x = 0; x < 48; x++) {
                        double q[3];
                        stab_pixel_point(&f, x, y, 1.0f, q);
                        float dv = depth[(size_t)y * 48 + x];
                        if (q[1] < f.origin[1]) { /* going down from the surface itself */
                            if (!(dv <= 1e-6f || dv == INFINITY))
                                fail_msg("on the plane, pixel (%u, %u) going down: depth %g", x, y,
                                         (double)dv);
                            down += dv <= 1e-6f;
                        } else if (!(dv <= 1e-6f || dv == INFINITY)) {
                            /* Going up, the ray may meet the plane at its own origin (t = 0, tnear is 0): a
                             * camera exactly on a surface sees it at its feet, or the sky. */
                            fail_msg("on the plane, pixel (%u, %u) going up: depth %g", x, y, (double)dv);
                        }
                    }
            }
            print_message("camera %s the plane%s: %llu pixels meet it\n", above ? "1 mm above" : "on",
                          no_cache ? " (no cache)" : "", (unsigned long long)down);
            assert_true(down > 0);
            srv_loop_free(loop);
        }
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- straight up and down ----------------------------------------------------------------------------------- */

/* The camera's frame (srv_camera_setup) for a camera looking along the world's up hint, exactly or within a
 * rounding error: forward, right and up unit length within 2^-20 and orthogonal within 2^-20 (what the image
 * plane needs to be a plane). */
static void check_frame(const srv_camera *cam)
{
    srv_camera_frame f;
    assert_true(srv_camera_setup(cam, 48, 48, &f));
    const float *v[3] = {f.forward, f.right, f.up};
    for (int i = 0; i < 3; i++) {
        double len = sqrt((double)v[i][0] * v[i][0] + (double)v[i][1] * v[i][1] + (double)v[i][2] * v[i][2]);
        if (!(fabs(len - 1) <= 0x1p-20))
            fail_msg("camera looking along (%g, %g, %g): frame vector %d has length %g",
                     (double)(cam->target[0] - cam->position[0]), (double)(cam->target[1] - cam->position[1]),
                     (double)(cam->target[2] - cam->position[2]), i, len);
        for (int j = 0; j < i; j++) {
            double dot = (double)v[i][0] * v[j][0] + (double)v[i][1] * v[j][1] + (double)v[i][2] * v[j][2];
            if (!(fabs(dot) <= 0x1p-20))
                fail_msg("camera frame vectors %d and %d: dot %g", i, j, dot);
        }
    }
}

/* Looking straight down at the open plane from 2 m (the up hint (0, 1, 0) along the view), and within 1e-20
 * and 1e-30 of straight down (a frame built from a cross product of about 1e-30: its length underflows a
 * float): an orthonormal frame, and every pixel the plane's depth and closed form. Looking straight up (and
 * as nearly): every pixel the sky. */
static void test_straight_up_and_down(void **state)
{
    (void)state;
    scene_rt *rt;
    scene *s = stab_open_plane(sun_dir, 2.0f, 1.0f, &rt);
    const float offsets[] = {0.0f, 1e-20f, 1e-30f};
    for (size_t i = 0; i < sizeof offsets / sizeof offsets[0]; i++)
        for (int up = 0; up < 2; up++) {
            srv_camera cam = {.position = {0, 2.3f, 0},
                              .target = {offsets[i], up ? 4.3f : 0.3f, 0},
                              .up = {0, 1, 0},
                              .fov_deg = 90};
            check_frame(&cam);
            srv_viewer_id id;
            srv_loop *loop = plane_loop(s, rt, false, 48, 48, &id);
            srv_frame_stats st;
            stab_frames(loop, &id, 1, &cam, true, 2, &st);
            stab_plane_result r = stab_check_open_plane(loop, id, &cam, (double)0.3f, 0.7, -0.4, 20.0, 20.0);
            print_message("looking straight %s (target off by %g): %llu plane pixels, %llu sky\n",
                          up ? "up" : "down", (double)offsets[i], (unsigned long long)r.plane_pixels,
                          (unsigned long long)r.sky_pixels);
            if (up)
                assert_int_equal(r.sky_pixels, 48 * 48);
            else
                assert_int_equal(r.plane_pixels, 48 * 48);
            srv_loop_free(loop);
        }
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- a camera 1e6 m away ------------------------------------------------------------------------------------- */

/* A sun 37 degrees above the horizon, for long shadows. */
static const float low_sun[3] = {0.6f, -0.6f, 0.5f};

/* A box 6 m tall on the open plane seen from 1e6 m away at 30 degrees of elevation, through a field of view
 * of 0.0012 degrees that frames 21 m (192 x 108 pixels of 0.2 m, 0.4 m on the plane): every plane pixel at the
 * plane's depth (float positions 1e6 away are 0.06 m apart; the bound is 1e-6 relative, 1 m, while a
 * pixel's ray error of about 1e-7 rad moves it 0.1 m), the exact shadow and AO 1 away from the box
 * (stab_check_box_on_plane). Probes from there (the world grid's coarsest level) are checked by the checker. */
static void test_camera_1e6_away(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    stab_add_floor(s, 0.7, 0.3, -0.4, 20.0, 8);
    const double lo[3] = {-2.0, (double)0.3f, -2.0}, hi[3] = {2.0, 6.3, 2.0};
    fxt_add_box(s, "box", lo, hi, false, 2);
    fxt_add_sun(s, low_sun[0], low_sun[1], low_sun[2]);
    stab_set_sun(s, low_sun, 2.0f);
    s->sky_color[0] = 0.2f, s->sky_color[1] = 0.3f, s->sky_color[2] = 0.4f;
    s->sky_intensity = 1.0f;
    const float density = 8.0f, ao_radius = 1.0f;
    scene_rt *rt = fxt_finish_scene(s, density, ao_radius);
    enum { FW = 192, FH = 108 };
    srv_camera cam = {.position = {0.25f, 5e5f, 866025.4f},
                      .target = {2.0f, 0.3f, 2.0f},
                      .up = {0, 1, 0},
                      .fov_deg = 0.0012f};
    for (int no_cache = 0; no_cache < 2; no_cache++) {
        srv_loop_desc d = {.s = s,
                           .rt = rt,
                           .seed = 4,
                           .keep_views = true,
                           .no_cache = no_cache,
                           .samples_per_update = 64,
                           .threads = 2};
        fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
        srv_viewer_id id;
        srv_loop *loop = fxt_loop(&d, 1, FW, FH, &id);
        srv_frame_stats st;
        stab_frames(loop, &id, 1, &cam, true, no_cache ? 1 : 2, &st);
        stab_box_result r =
            stab_check_box_on_plane(loop, id, &cam, (double)0.3f, lo, hi, true, density, ao_radius, 1e-6);
        print_message(
            "camera 1e6 away%s: %u plane pixels (worst relative depth error %.2e), %u away from shadow "
            "edges of which %u in the shadow, all exact; AO exactly 1 at %u open ones\n",
            no_cache ? " (no cache)" : "", r.plane_pixels, r.worst_depth, r.lit_checked, r.dark, r.open);
        assert_true(r.plane_pixels > FW * FH / 2 && r.lit_checked > r.plane_pixels / 2 && r.dark > 20 &&
                    r.open > 100);
        srv_loop_free(loop);
    }
    /* The probes from there: the coarsest grid level, every frame checked. */
    srv_loop_desc d = {.s = s, .rt = rt, .seed = 4, .threads = 2, .probe_rays = 32};
    fxt_effects_on(&d, (const char *const[]){"probes"}, 1);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, FW, FH, &id);
    srv_frame_stats st;
    stab_checked c = stab_frames(loop, &id, 1, &cam, true, 3, &st);
    print_message("camera 1e6 away, probes: %llu cells, %llu refused\n",
                  (unsigned long long)c.texels[SCENE_FX_PROBES], (unsigned long long)st.world.refusals);
    assert_true(c.texels[SCENE_FX_PROBES] > 0);
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_fov_0_5_and_170_deg),
        cmocka_unit_test(test_near_plane_inside_wall),
        cmocka_unit_test(test_straight_up_and_down),
        cmocka_unit_test(test_camera_1e6_away),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
