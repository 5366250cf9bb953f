/* The bounce at a probe ray's hit where no probe of the update's level is (effects/fx_probes_hits.c,
 * hit_bounce_coarser, then own_bounce): the probes of the coarser levels around the hit first. The scene: a
 * closed room [-2, 2] x [0, 4] x [-2, 2] of inward faces (albedo 0.5, no sky) with a point light 0.6 m above
 * the middle of its floor, which lights a bright patch under it. Fine probes (cell 0.5, level 0) fill only the
 * room's lowest metre, as a viewer looking down at the floor would request them; the ceiling and the upper
 * walls lie in level-0 cells with no probe. A coarse grid (cell 1, level 1, on the world cache's grid
 * anchored at the origin) fills the room, as a viewer's farther requests do.
 *
 * Before, an update ray of a fine probe that reached the ceiling took the probe's own irradiance towards the
 * ceiling's normal (down): the lit patch just below the probe, far brighter than what the ceiling 4 m up
 * receives. The fake bright ceiling lit the floor a second time: the floor's indirect light under the light
 * came out far above the reference. Now the ceiling's hits read the coarse probes near it. Checked against
 * the reference renderer (fx_indirect_reference_point, every bounce) at floor points around the patch, both
 * ways (the coarse grid resident, and not: then the own irradiance is all there is, the old rule, which the
 * test shows is further: +58 % on the mean, +141 % under the light), and the run with the coarse grid within
 * 12 % of the reference on the mean (measured +9.3 %), 15 % at every point. */
#include "test_util.h"

#include "fxt_probes.h"
#include "fxt_scene.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { FRAMES = 30, POINTS = 5, PATHS = 16384 };

static const float floor_points[POINTS][3] = {
    {0.0f, 0.0f, 0.0f}, {0.6f, 0.0f, 0.1f}, {-0.4f, 0.0f, -0.7f}, {1.2f, 0.0f, -1.1f}, {-1.3f, 0.0f, 1.4f}};

/* The floor's indirect irradiance at floor_points from the fine grid after FRAMES frames, the coarse grid
 * resident (read by the fine probes' update hits) or not; the mean of relative errors against ref. */
static double run(const scene *s, scene_rt *rt, bool coarse_resident, const double ref[POINTS], double *worst)
{
    fxt_grid fine, coarse;
    fxt_grid_init(&fine, s, (float[3]){-1.75f, 0.25f, -1.75f}, 0.5f, 8, 2, 8);
    fxt_grid_init(&coarse, s, (float[3]){-1.0f, 1.0f, -1.0f}, 1.0f, 3, 3, 3);
    coarse.level = 1;
    for (uint32_t i = 0; i < coarse.count; i++)
        coarse.jobs[i].level = 1;
    fine.coarser = coarse_resident ? &coarse : NULL;
    fx_context ctx = fxt_grid_context(s, rt, &fine, 0.5f);
    fx_context coarse_ctx = fxt_grid_context(s, rt, &coarse, 0.5f);
    for (int f = 0; f < FRAMES; f++) {
        fxt_grid_frame(&fine, &ctx);
        fxt_grid_frame(&coarse, &coarse_ctx);
    }
    const float up[3] = {0, 1, 0};
    double sum = 0;
    *worst = 0;
    for (int i = 0; i < POINTS; i++) {
        float indirect[3];
        fxt_grid_shade_at(&fine, floor_points[i], up, indirect, NULL);
        double e = (double)indirect[0] * M_PI, error = (e - ref[i]) / ref[i];
        printf("  floor (%.1f, %.1f): probes %.4f, reference %.4f (%+.1f %%)\n", (double)floor_points[i][0],
               (double)floor_points[i][2], e, ref[i], 100 * error);
        sum += error;
        *worst = fmax(*worst, fabs(error));
    }
    fxt_grid_free(&fine);
    fxt_grid_free(&coarse);
    return sum / POINTS;
}

static void test_ceiling_without_fine_probes(void **state)
{
    (void)state;
    scene *s = fxt_new_scene(); /* albedo 0.5, no sky */
    fxt_add_box(s, "room", (double[3]){-2, 0, -2}, (double[3]){2, 4, 2}, true, 8);
    fxt_add_point_light(s, 0.0f, 0.6f, 0.0f, 1.0f);
    scene_rt *rt = fxt_finish_scene(s, 16.0f, 1.0f);
    fx_context every = {.s = s, .rt = rt, .seed = 9, .ao_radius = 1, .reference_bounces = 0};
    double ref[POINTS];
    const float up[3] = {0, 1, 0};
    for (int i = 0; i < POINTS; i++) {
        float e[3];
        uint64_t rays = 0;
        fx_indirect_reference_point(&every, floor_points[i], up, PATHS, (uint64_t)i + 1, e, &rays);
        ref[i] = e[0];
    }
    double worst_own, worst_coarse;
    printf("the fine probes alone (own irradiance at the ceiling's hits):\n");
    double own = run(s, rt, false, ref, &worst_own);
    printf("the coarse probes resident:\n");
    double coarse = run(s, rt, true, ref, &worst_coarse);
    printf("mean relative error: own %+.4f (worst %.4f), coarser levels %+.4f (worst %.4f)\n", own, worst_own,
           coarse, worst_coarse);
    assert_true(fabs(coarse) < 0.12); /* measured +0.093 */
    assert_true(worst_coarse < 0.15); /* measured 0.103 */
    assert_true(fabs(coarse) < fabs(own));
    scene_rt_free(rt);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ceiling_without_fine_probes),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
