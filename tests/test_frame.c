/* The frame loop (server/frame.h) on the embedded default scene: deduplication across viewers (identical
 * cameras share everything, disjoint cameras nothing), thread-count independence, the ray budget, the
 * steady state of a static view, the cached image against the no-cache baseline, and a pool too small for
 * one frame. */
#include "test_util.h"

#include "camgen.h"
#include "engine.h"
#include "scene.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef fxt_scene_fixture fixture;

static srv_loop_desc base_desc(const fixture *f)
{
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 7, .pool_bytes = 64u << 20};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    return d;
}

/* Two viewers with the same camera request exactly one viewer's texels twice: the sharing ratio is 2. */
static void test_identical_viewers_share_everything(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = base_desc(f);
    srv_viewer_id ids[2];
    srv_loop *loop = fxt_loop(&d, 2, 96, 54, ids);
    srv_camera cams[2];
    cams[0] = cams[1] = srv_camgen_camera(SRV_CAMGEN_IDENTICAL, f->s, 0, 2, 0, 1);
    srv_frame_stats st;
    fxt_frame(loop, ids, 2, cams, &st);
    assert_true(st.unique_texels > 1000);
    assert_int_equal(st.viewer_count, 2);
    assert_int_equal(st.viewers[0].requested_texels, st.viewers[1].requested_texels);
    assert_int_equal(st.requested_texels, 2 * st.unique_texels);
    assert_int_equal(st.viewers[0].requested_texels, st.unique_texels);
    srv_loop_free(loop);
}

/* Two viewers looking at opposite walls share no texel: requested equals unique. */
static void test_disjoint_viewers_share_nothing(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = base_desc(f);
    srv_viewer_id ids[2];
    srv_loop *loop = fxt_loop(&d, 2, 64, 64, ids);
    srv_camera cams[2] = {
        {.position = {0, 2, 0}, .target = {5, 2, 0}, .up = {0, 1, 0}, .fov_deg = 20},
        {.position = {0, 2, 0}, .target = {-5, 2, 0}, .up = {0, 1, 0}, .fov_deg = 20},
    };
    srv_frame_stats st;
    fxt_frame(loop, ids, 2, cams, &st);
    assert_true(st.viewers[0].requested_texels > 100 && st.viewers[1].requested_texels > 100);
    assert_int_equal(st.requested_texels, st.unique_texels);
    srv_loop_free(loop);
}

/* Runs frames of a walking pair of viewers with a ray budget and returns the last images and totals. */
static void run_walk(fixture *f, uint32_t threads, uint8_t **images, uint64_t *unique, uint64_t *rays)
{
    srv_loop_desc d = base_desc(f);
    d.threads = threads;
    d.ray_budget = 40000;
    srv_viewer_id ids[2];
    srv_loop *loop = fxt_loop(&d, 2, 80, 48, ids);
    *unique = *rays = 0;
    for (uint32_t frame = 0; frame < 5; frame++) {
        srv_camera cams[2];
        for (uint32_t v = 0; v < 2; v++)
            cams[v] = srv_camgen_camera(SRV_CAMGEN_WALK, f->s, v, 2, frame * 20, 3);
        srv_frame_stats st;
        fxt_frame(loop, ids, 2, cams, &st);
        *unique += st.unique_texels;
        *rays += st.rays[SCENE_FX_SHADOW] + st.rays[SCENE_FX_AO];
        assert_true(st.rays[SCENE_FX_SHADOW] + st.rays[SCENE_FX_AO] <= d.ray_budget);
    }
    size_t bytes = (size_t)80 * 48 * 3;
    for (uint32_t v = 0; v < 2; v++) {
        images[v] = malloc(bytes);
        memcpy(images[v], srv_viewer_image(loop, ids[v]), bytes);
    }
    srv_loop_free(loop);
}

/* One thread and two threads give identical caches (same unique texels and rays) and identical images. */
static void test_thread_count_independent(void **state)
{
    fixture *f = *state;
    uint8_t *one[2], *two[2];
    uint64_t unique1, rays1, unique2, rays2;
    run_walk(f, 1, one, &unique1, &rays1);
    run_walk(f, 2, two, &unique2, &rays2);
    assert_int_equal(unique1, unique2);
    assert_int_equal(rays1, rays2);
    assert_true(rays1 > 0);
    for (uint32_t v = 0; v < 2; v++) {
        assert_memory_equal(one[v], two[v], (size_t)80 * 48 * 3);
        free(one[v]);
        free(two[v]);
    }
}

/* A small ray budget is respected every frame and defers texels to later frames. */
static void test_ray_budget(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = base_desc(f);
    d.ray_budget = 5000;
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, 96, 54, &id);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    uint64_t deferred = 0;
    for (int frame = 0; frame < 3; frame++) {
        srv_frame_stats st;
        fxt_frame(loop, &id, 1, &cam, &st);
        assert_true(st.rays[SCENE_FX_SHADOW] + st.rays[SCENE_FX_AO] <= 5000);
        deferred += st.texels_deferred[SCENE_FX_SHADOW] + st.texels_deferred[SCENE_FX_AO];
        assert_true(st.pixels_missing > 0); /* not everything fits in 5000 rays */
    }
    assert_true(deferred > 0);
    srv_loop_free(loop);
}

/* A static view converges: after AO reaches 64 samples no effect ray is traced any more. */
static void test_static_view_converges(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = base_desc(f);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, 96, 54, &id);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    srv_frame_stats st;
    uint64_t first = 0;
    for (int frame = 0; frame < 6; frame++) {
        fxt_frame(loop, &id, 1, &cam, &st);
        if (frame == 0)
            first = st.rays[SCENE_FX_SHADOW] + st.rays[SCENE_FX_AO];
    }
    assert_true(first > 0);
    assert_int_equal(st.rays[SCENE_FX_SHADOW] + st.rays[SCENE_FX_AO], 0);
    assert_int_equal(st.pixels_missing, 0);
    srv_loop_free(loop);
}

/* RMSE between two linear radiance images, relative to the reference's mean. */
static double relative_rmse(const float *a, const float *ref, size_t n)
{
    double err = 0, mean = 0;
    for (size_t i = 0; i < n; i++) {
        double diff = (double)a[i] - ref[i];
        err += diff * diff;
        mean += ref[i];
    }
    return sqrt(err / (double)n) / (mean / (double)n);
}

/* The converged cached image against the per-pixel baseline. Stated bounds: relative RMSE of linear radiance
 * below 0.15 and below 3 x the RMSE between two baseline runs with different seeds (the noise of 64 AO
 * samples and 16 shadow rays per pixel); the mean AO agrees within 2 %, the mean lit fraction within 4 %.
 * Measured on this view: 0.113 against a seed-to-seed noise of 0.042, mean AO 0.8635 against 0.8645, mean
 * lit 0.0489 against 0.0473. History: 0.157 (noise 0.049) when crease texels sampled the wall and the
 * baseline leaked light along creases, with means within 2 % (mean lit 0.0482 against a leaking 0.0490);
 * 0.151 once shadow masks were read below the texel; 0.113 after the crease fixes. The remaining excess is
 * the texel resolution: shadows and AO are filtered over texels, not pixels. */
static void test_cached_matches_no_cache(void **state)
{
    fixture *f = *state;
    const uint32_t w = 128, h = 72;
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    srv_loop_desc d = base_desc(f);
    d.bias_set[SCENE_FX_AO] = true; /* full resolution for the comparison */
    d.keep_views = true;
    srv_viewer_id id_c, id_a, id_b;
    srv_loop *cached = fxt_loop(&d, 1, w, h, &id_c);
    srv_frame_stats st;
    for (int frame = 0; frame < 6; frame++)
        fxt_frame(cached, &id_c, 1, &cam, &st);
    d.no_cache = true;
    srv_loop *baseline_a = fxt_loop(&d, 1, w, h, &id_a);
    fxt_frame(baseline_a, &id_a, 1, &cam, &st);
    assert_true(st.rays[SCENE_FX_AO] == 64 * st.pixels_visible);
    d.seed = 12345;
    srv_loop *baseline_b = fxt_loop(&d, 1, w, h, &id_b);
    fxt_frame(baseline_b, &id_b, 1, &cam, &st);
    size_t n = (size_t)w * h * 3;
    double cache_err =
        relative_rmse(srv_viewer_radiance(cached, id_c), srv_viewer_radiance(baseline_a, id_a), n);
    double noise =
        relative_rmse(srv_viewer_radiance(baseline_b, id_b), srv_viewer_radiance(baseline_a, id_a), n);
    print_message("relative RMSE: cached vs no-cache %.4f, no-cache vs no-cache (other seed) %.4f\n",
                  cache_err, noise);
    assert_true(noise > 0.0);
    assert_true(cache_err < 0.15);
    assert_true(cache_err <= 3.0 * noise);
    for (int view = SRV_VIEW_AO; view <= SRV_VIEW_SHADOW; view++) {
        const float *c = srv_viewer_view(cached, id_c, view), *b = srv_viewer_view(baseline_a, id_a, view);
        double mean_c = 0, mean_b = 0;
        for (size_t i = 0; i < (size_t)w * h; i++) {
            mean_c += c[i];
            mean_b += b[i];
        }
        print_message("view %d: mean cached %.4f, mean no-cache %.4f\n", view, mean_c / (w * h),
                      mean_b / (w * h));
        assert_true(fabs(mean_c - mean_b) <= (view == SRV_VIEW_AO ? 0.02 : 0.04) * mean_b);
    }
    srv_loop_free(cached);
    srv_loop_free(baseline_a);
    srv_loop_free(baseline_b);
}

/* A pool far too small for one frame's requests runs degraded (evictions, missing pixels), never fails. */
static void test_tiny_pool_degrades(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = base_desc(f);
    d.pool_bytes = 1; /* the minimum of 64 blocks per effect */
    srv_viewer_id ids[2];
    srv_loop *loop = fxt_loop(&d, 2, 160, 90, ids);
    srv_frame_stats st;
    for (uint32_t frame = 0; frame < 3; frame++) {
        srv_camera cams[2];
        for (uint32_t v = 0; v < 2; v++)
            cams[v] = srv_camgen_camera(SRV_CAMGEN_ORBIT, f->s, v, 2, frame * 10, 1);
        fxt_frame(loop, ids, 2, cams, &st);
    }
    assert_true(st.exhausted > 0 || st.evictions > 0);
    assert_true(st.pixels_missing > 0);
    assert_true(st.blocks_resident[SCENE_FX_AO] <= 64);
    srv_loop_free(loop);
}

/* A camera that sees nothing: no requests, no rays, a sky-coloured image. */
static void test_viewer_sees_nothing(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = base_desc(f);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, 32, 32, &id);
    srv_camera cam = {.position = {0, 100, 0}, .target = {0, 200, 0}, .up = {1, 0, 0}, .fov_deg = 30};
    srv_frame_stats st;
    fxt_frame(loop, &id, 1, &cam, &st);
    assert_int_equal(st.pixels_visible, 0);
    assert_int_equal(st.unique_texels, 0);
    assert_int_equal(st.rays[SCENE_FX_SHADOW] + st.rays[SCENE_FX_AO], 0);
    srv_loop_free(loop);
}

/* Memory reported by the loop covers the cache's own exact total and grows with resident blocks only. */
static void test_memory_report(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = base_desc(f);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, 64, 36, &id);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    srv_frame_stats st;
    fxt_frame(loop, &id, 1, &cam, &st);
    srv_memory m;
    srv_loop_memory(loop, &m);
    assert_true(m.pools_reserved[SCENE_FX_AO] >= 64u * 4u * st.blocks_resident[SCENE_FX_AO]);
    assert_int_equal(m.pools_in_use[SCENE_FX_AO], 64u * 4u * st.blocks_resident[SCENE_FX_AO]);
    assert_true(m.total >=
                m.table + m.viewers + m.pools_reserved[SCENE_FX_AO] + m.pools_reserved[SCENE_FX_SHADOW]);
    srv_loop_free(loop);
}

/* A test run with the embedded default scene as its state. */
#define SCENE_TEST(test)                                                                                     \
    cmocka_unit_test_setup_teardown(test, fxt_default_scene_setup, fxt_default_scene_teardown)

int main(void)
{
    const struct CMUnitTest tests[] = {
        SCENE_TEST(test_identical_viewers_share_everything),
        SCENE_TEST(test_disjoint_viewers_share_nothing),
        SCENE_TEST(test_thread_count_independent),
        SCENE_TEST(test_ray_budget),
        SCENE_TEST(test_static_view_converges),
        SCENE_TEST(test_cached_matches_no_cache),
        SCENE_TEST(test_tiny_pool_degrades),
        SCENE_TEST(test_viewer_sees_nothing),
        SCENE_TEST(test_memory_report),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
