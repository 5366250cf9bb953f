/* Stability suite, light (docs/ERROR.md "Stability suite"): intensities from 1e-8 to 1e8 with the tone map
 * saturating, a sun grazing a surface at 1e-6 rad, lights inside geometry, and a light switched on and off
 * (the step response of direct light and of the probes). Every frame of every case is checked by
 * stab_check_loop (finite, consistent, payloads sound). */
#include "stab_util.h"

#include "camgen.h"
#include "scene_internal.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Renders the plane from a camera looking down at it at 40 degrees, cached (2 frames, every texel converged)
 * or no-cache, and checks every pixel: floor pixels the closed form within STAB_FORMULA_TOLERANCE, lit fraction and
 * AO 1 (or lit 0 facing away) within 2^-22 (a filter's weights sum to 1 within four roundings), sky pixels the
 * sky; returns the floor pixels checked. */
static uint64_t check_plane(scene *s, scene_rt *rt, bool no_cache, bool lit, double *worst)
{
    enum { PW = 64, PH = 36 };
    srv_loop_desc d = {.s = s,
                       .rt = rt,
                       .seed = 3,
                       .keep_views = true,
                       .no_cache = no_cache,
                       .samples_per_update = 64,
                       .threads = 2};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, PW, PH, &id);
    srv_camera cam = {
        .position = {1.0f, 4.3f, 5.0f}, .target = {0.5f, 0.3f, -2.0f}, .up = {0, 1, 0}, .fov_deg = 80};
    srv_frame_stats st;
    stab_frames(loop, &id, 1, &cam, true, no_cache ? 1 : 2, &st);
    double expected[3];
    stab_plane_closed_form(s, expected);
    const float *rad = srv_viewer_radiance(loop, id), *depth = srv_viewer_depth(loop, id);
    const float *ao = srv_viewer_view(loop, id, SRV_VIEW_AO),
                *shadow = srv_viewer_view(loop, id, SRV_VIEW_SHADOW);
    uint64_t floor = 0;
    for (size_t p = 0; p < (size_t)PW * PH; p++) {
        if (!isfinite(depth[p]))
            continue; /* sky: the checker compared it with the sky */
        floor++;
        if (!(fabs(ao[p] - 1.0) <= 0x1p-22 && fabs(shadow[p] - (lit ? 1.0 : 0.0)) <= 0x1p-22))
            fail_msg("pixel %zu: AO %.9g, lit fraction %.9g (expected 1 and %d)", p, (double)ao[p],
                     (double)shadow[p], lit);
        for (int k = 0; k < 3; k++) {
            double error = fabs(rad[3 * p + k] - expected[k]) / expected[k];
            *worst = fmax(*worst, error);
            if (error > STAB_FORMULA_TOLERANCE)
                fail_msg("pixel %zu channel %d: radiance %.9g, closed form %.9g (relative error %.3g)", p, k,
                         (double)rad[3 * p + k], expected[k], error);
        }
    }
    assert_true(floor > (uint64_t)PW * PH / 2);
    srv_loop_free(loop);
    return floor;
}

/* ---- intensities from 1e-8 to 1e8 ------------------------------------------------------------------------ */

/* The open plane under a sun at 30 degrees from the normal and a sky, both at 1e-8 ... 1e8: every floor pixel
 * is the closed form within STAB_FORMULA_TOLERANCE, cached and no-cache; the tone map (1 - e^-x, then sRGB) gives
 * 0 for every byte at 1e-8 (radiance below 2^-20) and 255 at 1e8 (above 20), the checker having compared
 * every byte with the tone map of its radiance. */
static void test_intensity_closed_form(void **state)
{
    (void)state;
    const float dir[3] = {0.5f, -0.8660254f, 0.0f};
    const float factors[] = {1e-8f, 1e-4f, 1.0f, 1e4f, 1e8f};
    for (size_t i = 0; i < sizeof factors / sizeof factors[0]; i++) {
        scene_rt *rt;
        scene *s = stab_open_plane(dir, 2.0f * factors[i], factors[i], &rt);
        double worst = 0;
        for (int no_cache = 0; no_cache < 2; no_cache++)
            check_plane(s, rt, no_cache, true, &worst);
        /* The image at the extremes, through the same loop once more. */
        srv_loop_desc d = {.s = s, .rt = rt, .seed = 3, .threads = 2};
        fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
        srv_viewer_id id;
        srv_loop *loop = fxt_loop(&d, 1, 32, 18, &id);
        srv_camera cam = {
            .position = {1.0f, 4.3f, 5.0f}, .target = {0.5f, 0.3f, -2.0f}, .up = {0, 1, 0}, .fov_deg = 80};
        srv_frame_stats st;
        stab_frames(loop, &id, 1, &cam, true, 1, &st);
        const uint8_t *srgb = srv_viewer_image(loop, id);
        uint32_t zero = 0, full = 0;
        for (size_t b = 0; b < 32 * 18 * 3; b++) {
            zero += srgb[b] == 0;
            full += srgb[b] == 255;
        }
        print_message("intensity x %g: worst relative error %.2e (bound %.2e); bytes 0: %u, 255: %u of %u\n",
                      (double)factors[i], worst, STAB_FORMULA_TOLERANCE, zero, full, 32 * 18 * 3);
        if (factors[i] <= 1e-8f)
            assert_int_equal(zero, 32 * 18 * 3);
        if (factors[i] >= 1e8f)
            assert_int_equal(full, 32 * 18 * 3);
        srv_loop_free(loop);
        scene_rt_free(rt);
        scene_free(s);
    }
}

/* Light transport is linear in the lights: the embedded scene with every effect (shadows, AO, probes), its
 * sun and sky multiplied by k, gives k times the image at k = 1. For k a power of two every product and sum
 * of the pipeline scales exactly in binary floating point, including the probes' per-probe irradiance scale
 * and its reciprocal (the half-float maps hold the same bits), so the bound is 0: bit for bit k times the
 * radiance, cached and no-cache, from 2^-27 (7.5e-9) to 2^27 (1.3e8). */
static void test_intensity_linear(void **state)
{
    (void)state;
    enum { LW = 48, LH = 27, FRAMES = 3 };
    const int exponents[] = {0, -27, -13, 13, 27};
    float *reference[2] = {NULL, NULL};
    for (size_t i = 0; i < sizeof exponents / sizeof exponents[0]; i++) {
        float k = ldexpf(1.0f, exponents[i]);
        scene *s = fxt_transformed_default(1.0, 0.0, k);
        scene_error err = {0};
        scene_rt *rt = scene_rt_create(s, NULL, &err);
        assert_non_null(rt);
        for (int no_cache = 0; no_cache < 2; no_cache++) {
            srv_loop_desc d = {
                .s = s, .rt = rt, .seed = 5, .no_cache = no_cache, .threads = 2, .probe_rays = 64};
            fxt_effects_on(&d, (const char *const[]){"shadow", "ao", "probes"}, 3);
            srv_viewer_id id;
            srv_loop *loop = fxt_loop(&d, 1, LW, LH, &id);
            srv_camera cam = srv_camera_default(s);
            srv_frame_stats st;
            stab_frames(loop, &id, 1, &cam, true, no_cache ? 1 : FRAMES, &st);
            float *rad = stab_copy_radiance(loop, id);
            if (i == 0) {
                reference[no_cache] = rad;
            } else {
                uint32_t differ = 0;
                for (size_t c = 0; c < (size_t)LW * LH * 3; c++)
                    differ += rad[c] != reference[no_cache][c] * k;
                print_message("lights x 2^%d%s: %u of %u values differ from 2^%d x the image at 1\n",
                              exponents[i], no_cache ? " (no cache)" : "", differ, LW * LH * 3, exponents[i]);
                assert_int_equal(differ, 0);
                free(rad);
            }
            srv_loop_free(loop);
        }
        scene_rt_free(rt);
        scene_free(s);
    }
    free(reference[0]);
    free(reference[1]);
}

/* ---- grazing light ---------------------------------------------------------------------------------------- */

/* A sun 1e-6 rad above the open plane's horizon, at intensity 1e6 so that its light (1e6 x sin 1e-6 = 1) is
 * comparable to the sky's: every floor pixel lit, lit fraction exactly 1 (no shadow acne: shadow rays leave
 * along the plane from origins lifted off it by the scale-aware offset), AO 1, the radiance the closed form
 * within STAB_FORMULA_TOLERANCE, cached and no-cache. The same sun 1e-6 rad below the horizon: lit fraction exactly
 * 0, the radiance the sky's share alone. */
static void test_grazing_1e_6_rad(void **state)
{
    (void)state;
    for (int below = 0; below < 2; below++) {
        double e = below ? -1e-6 : 1e-6;
        const float dir[3] = {(float)cos(e), (float)-sin(e), 0.0f};
        scene_rt *rt;
        scene *s = stab_open_plane(dir, 1e6f, 1.0f, &rt);
        double worst = 0;
        uint64_t pixels = 0;
        for (int no_cache = 0; no_cache < 2; no_cache++)
            pixels += check_plane(s, rt, no_cache, !below, &worst);
        double expected[3];
        stab_plane_closed_form(s, expected);
        print_message(
            "sun %g rad %s the horizon: %llu floor pixels, radiance %.6f (direct share %.3f), worst "
            "relative error %.2e\n",
            fabs(e), below ? "below" : "above", (unsigned long long)pixels, expected[0],
            below ? 0.0 : 0.5 * s->lights[0].intensity * -(double)s->lights[0].direction[1] / expected[0],
            worst);
        scene_rt_free(rt);
        scene_free(s);
    }
}

/* ---- lights inside geometry ------------------------------------------------------------------------------- */

enum { IW = 64, IH = 36 };

/* Renders the scene of test_light_inside_geometry; returns the radiance and (may be NULL) the depth. */
static float *render_inside(scene *s, scene_rt *rt, bool no_cache, bool probes, float **depth)
{
    srv_loop_desc d = {.s = s,
                       .rt = rt,
                       .seed = 9,
                       .no_cache = no_cache,
                       .threads = 2,
                       .probe_rays = 64,
                       .probe_hysteresis = 0.5f};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao", "probes"}, probes ? 3 : 2);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, IW, IH, &id);
    srv_camera cam = {
        .position = {3.5f, 2.5f, 3.0f}, .target = {0.0f, 0.6f, 0.0f}, .up = {0, 1, 0}, .fov_deg = 70};
    srv_frame_stats st;
    stab_frames(loop, &id, 1, &cam, true, no_cache ? 1 : 4, &st);
    float *rad = stab_copy_radiance(loop, id);
    if (depth) {
        *depth = malloc((size_t)IW * IH * sizeof(float));
        assert_non_null(*depth);
        memcpy(*depth, srv_viewer_depth(loop, id), (size_t)IW * IH * sizeof(float));
    }
    srv_loop_free(loop);
    return rad;
}

/* The scene of test_light_inside_geometry with `extra` point lights of 1e8 (0: none, 1: inside the box and
 * the wall, 2: on the floor's plane). */
static scene *inside_scene(int extra, scene_rt **rt)
{
    scene *s = fxt_new_scene();
    stab_add_floor(s, 0.0, 0.0, 0.0, 4.0, 4);
    fxt_add_box(s, "box", (const double[3]){-0.5, 0.3, -0.5}, (const double[3]){0.5, 1.3, 0.5}, false, 2);
    fxt_add_box(s, "wall", (const double[3]){-2.0, 0.05, -1.51}, (const double[3]){2.0, 1.5, -1.49}, false,
                2);
    fxt_add_sun(s, 0.3f, -1.0f, -0.4f);
    if (extra == 1) {
        stab_add_point_light(s, 0.1f, 0.8f, -0.05f, 1e8f); /* inside the box */
        stab_add_point_light(s, 0.3f, 0.7f, -1.5f, 1e8f);  /* inside the wall, 2 cm thick */
    } else if (extra == 2) {
        stab_add_point_light(s, 1.7f, 0.0f, 2.2f, 1e8f); /* on the floor's plane */
    }
    s->sky_color[0] = 0.5f, s->sky_color[1] = 0.6f, s->sky_color[2] = 0.9f;
    s->sky_intensity = 0.8f;
    *rt = fxt_finish_scene(s, 16.0f, 0.6f);
    return s;
}

/* Point lights of 1e8 inside a solid box floating over a floor and inside a wall 2 cm thick (floating 5 cm
 * over the floor: a wall standing on a floor lets light through the floor texels under it, a departure
 * ARCHITECTURE.md documents) can light nothing: their shadow rays meet the geometry around them, so the image
 * is the image without them, bit for bit, cached and no-cache, with shadows, AO and probes (the probes'
 * shadow rays too). A light of 1e8 makes any leaked ray show: one of 16 shadow rays of one texel would add
 * 0.5 x 1e8 / 16 / d^2. A light of 1e8 exactly on the floor's plane lights the box and the wall above it, but
 * no point of the floor, which it meets edge-on (cos 0): every floor pixel's direct light is as without it,
 * bit for bit (shadows and AO; with probes the floor rightly gets the light the box bounces). */
static void test_light_inside_geometry(void **state)
{
    (void)state;
    /* images[0, 1]: without and with the lights inside, every effect; [2, 3]: without and with the light on
     * the plane, shadows and AO. */
    float *images[4][2], *depth = NULL;
    for (int i = 0; i < 4; i++) {
        scene_rt *rt;
        scene *s = inside_scene(i == 1 ? 1 : (i == 3 ? 2 : 0), &rt);
        for (int no_cache = 0; no_cache < 2; no_cache++)
            images[i][no_cache] =
                render_inside(s, rt, no_cache, i < 2, i == 0 && no_cache == 0 ? &depth : NULL);
        scene_rt_free(rt);
        scene_free(s);
    }
    srv_camera cam = {
        .position = {3.5f, 2.5f, 3.0f}, .target = {0.0f, 0.6f, 0.0f}, .up = {0, 1, 0}, .fov_deg = 70};
    srv_camera_frame f;
    assert_true(srv_camera_setup(&cam, IW, IH, &f));
    for (int no_cache = 0; no_cache < 2; no_cache++) {
        uint32_t differ = 0, floor_differ = 0, floor_pixels = 0, lit_elsewhere = 0;
        for (uint32_t p = 0; p < IW * IH; p++) {
            double q[3];
            bool on_floor =
                isfinite(depth[p]) && (stab_pixel_point(&f, p % IW, p / IW, depth[p], q), fabs(q[1]) < 1e-3);
            floor_pixels += on_floor;
            for (int k = 0; k < 3; k++) {
                size_t c = 3 * (size_t)p + (size_t)k;
                differ += images[0][no_cache][c] != images[1][no_cache][c];
                floor_differ += on_floor && images[2][no_cache][c] != images[3][no_cache][c];
                lit_elsewhere += !on_floor && images[3][no_cache][c] > images[2][no_cache][c];
            }
        }
        print_message(
            "lights of 1e8 inside geometry%s: %u values differ from the image without them; a light on "
            "the floor's plane: %u of %u floor pixels' values differ, %u values elsewhere brighter\n",
            no_cache ? " (no cache)" : "", differ, floor_differ, 3 * floor_pixels, lit_elsewhere);
        assert_int_equal(differ, 0);
        assert_int_equal(floor_differ, 0);
        assert_true(floor_pixels > IW * IH / 4);
        assert_true(lit_elsewhere > 0); /* not vacuous: the light on the plane does light the box */
        for (int i = 0; i < 4; i++)
            free(images[i][no_cache]);
    }
    free(depth);
}

/* ---- a light switched on and off ------------------------------------------------------------------------ */

/* A sun switched on and off over the bounce scene. Direct light has no memory: the floor's radiance is
 * albedo x E (+ its small bounce) in the very frame the sun goes on, and falls to its bounce alone in the
 * frame it goes off. The wall's light comes through the probes: with hysteresis h = 0.5 each update blends
 * half of the new estimate, so after k updates the wall holds V (1 - h^k) going on (from probes holding 0)
 * and V h^k going off, V the steady value. The engine updates a probe every frame until it has 64 blended
 * updates (converged), then every 8 frames (update.c), except for ceil(ln 0.01 / ln h) = 7 frames after the
 * lights change, when converged probes refresh every frame too: so the wall is within 5 % of V 5 updates after
 * the switch (0.5^5 = 3 %), 5 frames going on from fresh probes and going off from converged ones (before
 * the lights were watched, 40 frames going off), and converged probes are back to one refresh in 8 frames
 * once the 7 frames are over. Checked every frame against the closed form at the probes' own update count k (read from their
 * payloads; every probe of the view runs on the same schedule), within 4 % of V plus 4 x the steady
 * frame-to-frame spread (the probes' noise), and no overshoot beyond the same bound. */
static void test_light_switched_on_and_off(void **state)
{
    (void)state;
    const float intensity = 2.0f, h = 0.5f;
    scene_rt *rt;
    scene *s = stab_bounce_scene(intensity, &rt);
    double V, spread;
    stab_bounce_steady(s, rt, 10, &V, &spread);
    double bound = 0.04 * V + 4 * spread;
    print_message("bounce scene: the wall's steady radiance %.5f, frame-to-frame spread %.5f, bound %.5f\n",
                  V, spread, bound);
    assert_true(V > 0.01);

    srv_viewer_id id;
    srv_loop *loop = stab_bounce_loop(s, rt, h, &id);
    stab_probe_counts *then = malloc(sizeof *then);
    assert_non_null(then);
    double wall, floor, worst = 0, peak = 0;
    s->lights[0].intensity = 0.0f; /* three dark frames: every probe holds 0 */
    for (int f = 0; f < 3; f++)
        stab_bounce_frame(loop, id, &wall, &floor);
    assert_true(wall == 0.0 && floor == 0.0);
    stab_probe_snapshot(loop, then);
    s->lights[0].intensity = intensity;
    int settled_on = -1;
    uint32_t least = 0, most = 0;
    for (int k = 1; k <= 70; k++) {
        stab_bounce_frame(loop, id, &wall, &floor);
        assert_true(stab_probe_updates_since(loop, then, &least, &most) > then->count / 2);
        /* The probes around a wall pixel have had `least` to `most` updates since the switch. */
        double low = V * (1.0 - pow(h, (double)least)), high = V * (1.0 - pow(h, (double)most));
        worst = fmax(worst, fmax(low - wall, wall - high));
        peak = fmax(peak, wall);
        if (k == 1) /* direct light at once: the floor is albedo x E (0.5 x 2) plus a bounce under 10 % */
            assert_true(floor >= 0.5 * intensity * (1 - 1e-6) && floor <= 0.5 * intensity * 1.1);
        if (settled_on < 0 && fabs(wall - V) <= 0.05 * V)
            settled_on = k;
    }
    print_message(
        "on: within 5 %% of the steady value after %d frames; worst deviation outside V (1 - h^k) for "
        "the probes' k %.5f (bound %.5f), peak %.5f (V + bound %.5f); probes at %u..%u updates\n",
        settled_on, worst, bound, peak, V + bound, least, most);
    assert_true(worst <= bound);
    assert_true(peak <= V + bound);
    assert_true(settled_on > 0 && settled_on <= 5);
    s->lights[0].intensity = 0.0f;
    stab_probe_snapshot(loop, then);
    for (uint32_t i = 0; i < then->count; i++) /* converged: the refresh every 8 frames is what runs next */
        assert_true(then->updates[i] >= 64);
    double start = wall;
    int settled_off = -1;
    worst = 0;
    stab_probe_counts *late = malloc(sizeof *late);
    assert_non_null(late);
    for (int k = 1; k <= 48; k++) {
        if (k == 33) /* long after the 7 frames: converged probes wait for their refresh again */
            stab_probe_snapshot(loop, late);
        stab_bounce_frame(loop, id, &wall, &floor);
        assert_true(stab_probe_updates_since(loop, then, &least, &most) > then->count / 2);
        double low = start * pow(h, (double)most), high = start * pow(h, (double)least);
        worst = fmax(worst, fmax(low - wall, wall - high));
        assert_true(wall >= 0 && wall <= start + bound); /* no overshoot either way */
        if (k == 1)
            assert_true(floor < 0.5 * intensity * 0.1); /* the direct light gone at once */
        if (settled_off < 0 && wall <= 0.05 * V)
            settled_off = k;
    }
    print_message(
        "off: within 5 %% of V of 0 after %d frames (probes at %u..%u updates); worst deviation outside "
        "V h^k %.5f\n",
        settled_off, least, most, worst);
    assert_true(worst <= bound);
    assert_true(settled_off > 0 && settled_off <= 5);
    uint32_t late_least, late_most;
    assert_true(stab_probe_updates_since(loop, late, &late_least, &late_most) > late->count / 2);
    print_message("off, frames 33 to 48: each probe refreshed %u..%u times\n", late_least, late_most);
    assert_true(late_least >= 1 && late_most <= 2); /* every 8 frames: 2 in 16, not 16 */
    free(late);
    free(then);
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_intensity_closed_form),     cmocka_unit_test(test_intensity_linear),
        cmocka_unit_test(test_grazing_1e_6_rad),          cmocka_unit_test(test_light_inside_geometry),
        cmocka_unit_test(test_light_switched_on_and_off),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
