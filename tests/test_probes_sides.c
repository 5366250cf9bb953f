/* The probes' light at the back of a single-sided surface (effects/fx_probes_map.c, fx__probes_shade): a pixel
 * that sees a triangle from behind reads only the probes on its own side of the surface's plane. The probes
 * there see that surface's back and are switched off (or moved out through it), so before, DDGI's
 * renormalisation gave the back the whole light of the probes on the other side: a room of inward faces, lit
 * inside, showed its lit interior's light on the outside of its floor and ceiling (the Cornell box seen from
 * outside, ../shared). Expectations are the reference renderer (paths from a back face gather the viewer's
 * side) and its closed forms:
 *   - a room lit by a point light inside, no sky, seen from below its floor: the reference is 0 (nothing
 *     outside gives light); the cached frame must be (almost) 0 too, against the lit floor seen from inside;
 *   - the same room under a sky, seen from above its ceiling: the ceiling's back sees the whole sky, so the
 *     reference is albedo x sky; the cached frame within a stated bound of it. */
#include "test_util.h"

#include "engine_internal.h"
#include "fxt_probes.h"
#include "fxt_scene.h"
#include "reference.h"
#include "scene.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { W = 48, H = 32, FRAMES = 24 };

static const char *const shadow_probes[] = {"shadow", "probes"};

/* A room [0, 4]^3 of inward faces with a point light inside; a white sky of `sky` (0: none). */
static scene *room_scene(float sky, scene_rt **rt)
{
    scene *s = fxt_new_scene();
    fxt_add_box(s, "room", (double[3]){0, 0, 0}, (double[3]){4, 4, 4}, true, 4);
    fxt_add_point_light(s, 2.0f, 3.0f, 2.0f, 8.0f);
    *rt = fxt_finish_scene(s, 16, 1.0f);
    s->sky_color[0] = s->sky_color[1] = s->sky_color[2] = 1.0f;
    s->sky_intensity = sky;
    return s;
}

/* Mean radiance (over channels) of the visible pixels of a radiance image; *visible their count. */
static double mean_visible(const float *radiance, const float *depth, uint32_t *visible)
{
    double sum = 0;
    *visible = 0;
    for (size_t p = 0; p < (size_t)W * H; p++)
        if (isfinite(depth[p])) {
            sum += (double)radiance[3 * p] + radiance[3 * p + 1] + radiance[3 * p + 2];
            (*visible)++;
        }
    return *visible ? sum / (3.0 * *visible) : 0.0;
}

/* A converged cached frame of cam (shadows and probes): its mean visible radiance. */
static double cached_mean(const scene *s, scene_rt *rt, const srv_camera *cam, uint32_t *visible)
{
    srv_loop_desc d = {.s = s, .rt = rt, .seed = 3, .threads = 2};
    fxt_effects_on(&d, shadow_probes, 2);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, W, H, &id);
    srv_frame_stats st;
    for (uint32_t f = 0; f < FRAMES; f++)
        fxt_frame(loop, &id, 1, cam, &st);
    double mean = mean_visible(srv_viewer_radiance(loop, id), srv_viewer_depth(loop, id), visible);
    srv_loop_free(loop);
    return mean;
}

/* The reference's mean radiance of cam, whose every pixel sees the room (shadows and every bounce of the indirect light). */
static double reference_mean(const scene *s, scene_rt *rt, const srv_camera *cam)
{
    uint32_t n = 0;
    const fx_effect *const *registry = fx_registry(&n);
    srv_ref_desc d = {.s = s, .rt = rt, .seed = 5, .threads = 2};
    d.effect_on[fx_find(registry, n, "shadow")] = d.effect_on[fx_find(registry, n, "probes")] = true;
    d.samples[fx_find(registry, n, "shadow")] = 32;
    d.samples[fx_find(registry, n, "probes")] = 64;
    srv_ref *ref = NULL;
    char err[256];
    assert_int_equal(srv_ref_create(&d, &ref, err, sizeof err), FXC_OK);
    float *radiance = malloc(sizeof(float) * 3 * W * H);
    assert_non_null(radiance);
    srv_ref_image out = {.radiance = radiance};
    srv_ref_stats st;
    assert_int_equal(srv_ref_render(ref, cam, W, H, 0, &out, &st, NULL, NULL), FXC_OK);
    assert_int_equal(st.pixels_visible, W * H); /* the cameras see nothing but the room */
    double mean = (st.mean_radiance[0] + st.mean_radiance[1] + st.mean_radiance[2]) / 3.0;
    free(radiance);
    srv_ref_free(ref);
    return mean;
}

/* No sky: the floor's back, from below, is dark in the reference (exactly: no light outside) and must be in
 * the cached frame, against the floor lit inside. Bound: 1 % of the lit floor's mean (measured: 0; before the
 * fix the back showed 0.351 against the lit floor's 0.670, 52 %). */
static void test_floor_back_dark(void **state)
{
    (void)state;
    scene_rt *rt;
    scene *s = room_scene(0.0f, &rt);
    const srv_camera below = {.position = {2.2f, -2.0f, 2.1f}, .target = {2.0f, 0.0f, 2.0f}, .fov_deg = 50};
    const srv_camera inside = {.position = {2.3f, 2.5f, 3.5f}, .target = {2.0f, 0.0f, 2.0f}, .fov_deg = 50};
    uint32_t visible_below, visible_inside;
    double lit = cached_mean(s, rt, &inside, &visible_inside);
    double back = cached_mean(s, rt, &below, &visible_below);
    double reference = reference_mean(s, rt, &below);
    printf("floor from inside %.5f; its back from below: cached %.6f, reference %.6f\n", lit, back,
           reference);
    assert_true(visible_inside == W * H && visible_below == W * H);
    assert_true(lit > 0.01);
    assert_true(reference == 0.0);
    assert_true(back < 0.01 * lit);
    scene_rt_free(rt);
    scene_free(s);
}

/* Under a sky of 0.5, the ceiling's back, seen from above, sees the whole sky and nothing else: the reference
 * is albedo x 0.5 (closed form, checked); the cached frame within 5 % of it (measured: equal to 5
 * digits; before, the ceiling's back showed the room's light from inside: 1.02 against 0.25). */
static void test_ceiling_back_sky(void **state)
{
    (void)state;
    scene_rt *rt;
    scene *s = room_scene(0.5f, &rt);
    const srv_camera above = {.position = {2.2f, 6.0f, 2.1f}, .target = {2.0f, 4.0f, 2.0f}, .fov_deg = 50};
    uint32_t visible;
    double back = cached_mean(s, rt, &above, &visible);
    assert_int_equal(visible, W * H);
    double reference = reference_mean(s, rt, &above);
    double albedo = s->materials[0].diffuse[0];
    printf("ceiling's back from above: cached %.5f, reference %.5f, closed form %.5f\n", back, reference,
           albedo * 0.5);
    assert_true(fabs(reference - albedo * 0.5) < 0.02 * albedo * 0.5);
    assert_true(fabs(back - reference) < 0.05 * reference);
    scene_rt_free(rt);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_floor_back_dark),
        cmocka_unit_test(test_ceiling_back_sky),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
