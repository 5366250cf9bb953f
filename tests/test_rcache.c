/* Tests of the client's render cache (viewer_client/rcache/rcache.h), each against something worked out apart
 * from the code: a ray caster of a small analytic scene written here in double (a floor, a sphere, a wall and
 * the sky), closed-form projections by angles, filter outputs computed by hand, and counts that follow from
 * the stated rules.
 *
 *   - a frame reprojected to its own camera gives back its colours exactly and its depths up to their
 *     quantization (binary16 as on the wire), with 1 and 3 threads and odd sizes;
 *   - a camera turned or moved by a known amount puts each point where the angle-based formula says;
 *   - the depth test keeps the nearer of two points in either insertion order;
 *   - a sideways move shows the disoccluded wall as empty pixels with the highest priority, and the requests
 *     gather there;
 *   - the 3x3 weighted filter, smooth_all, the 7x7 prefilter and its switch on hand-made point patterns;
 *   - the dither places exactly the count asked, spreads it evenly and concentrates it by priority;
 *   - predicted requests fall where the predicted camera sees nothing, at most half the budget;
 *   - ageing steps of 128 k / N with the fraction carried, hidden points twice as fast, eviction at 255 (and
 *     none with no_eviction), a full cache dropping its oldest points at age 128, a colour change ageing the
 *     neighbours, a new frame replacing what it saw;
 *   - descriptions and cameras out of range are refused.
 * The scene is tests/fxt_rcache.h's; test_rcache_walk.c holds the threads, tiles and links checks. */
#include "test_util.h"

#include "fxt_rcache.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void test_desc_defaults_and_refusals(void **state)
{
    (void)state;
    view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = 640, .height = 360});
    view_rc_desc d = view_rc_resolved_desc(rc);
    assert_int_equal(d.capacity, 640 * 360);
    assert_int_equal(d.sample_budget, 640 * 360 / 32);
    assert_int_equal(d.insert_reserve, 4 * (640 * 360 / 32));
    assert_int_equal(d.tile_size, 64);
    assert_int_equal(d.threads, 1);
    assert_true(d.cull_ratio == 0.1f && d.supersede_ratio == 0.02f && d.hidden_age_factor == 2.0f);
    assert_int_equal(d.change_threshold, 32);
    assert_int_equal(d.change_penalty, 64);
    assert_true(view_rc_memory_bytes(rc) > (size_t)d.capacity * 16);
    view_rc_destroy(rc);

    static const struct {
        view_rc_desc d;
        const char *why;
    } bad[] = {
        {{.width = 0, .height = 10}, "no width"},
        {{.width = 10, .height = 0}, "no height"},
        {{.width = VIEW_RC_MAX_SIDE + 1, .height = 10}, "too wide"},
        {{.width = 10, .height = 10, .sample_budget = 101}, "budget above the pixels"},
        {{.width = 10, .height = 10, .threads = VIEW_RC_MAX_THREADS + 1}, "too many threads"},
        {{.width = 10, .height = 10, .cull_ratio = -0.5f}, "negative cull ratio"},
        {{.width = 10, .height = 10, .supersede_ratio = NAN}, "NaN supersede ratio"},
        {{.width = 10, .height = 10, .hidden_age_factor = 0.5f}, "hidden ageing slower"},
        {{.width = 10, .height = 10, .capacity = UINT32_MAX}, "capacity past 32 bits with the reserve"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        view_rc *none = (view_rc *)(uintptr_t)1; /* must be set to NULL */
        if (view_rc_create(&bad[i].d, &none) != FXC_ERR_INVALID || none != NULL)
            fail_msg("accepted: %s", bad[i].why);
    }
    assert_int_equal(view_rc_create(NULL, NULL), FXC_ERR_INVALID);

    /* Cameras: the server's rules. */
    rc = fxt_rc_make(&(view_rc_desc){.width = 16, .height = 16});
    view_rc_frame f;
    static const view_rc_camera cams[] = {
        {.position = {0, 0, 0}, .direction = {0, 0, -1}, .fov_deg = 0},
        {.position = {0, 0, 0}, .direction = {0, 0, -1}, .fov_deg = 180},
        {.position = {0, 0, 0}, .direction = {0, 0, 0}, .fov_deg = 60},
        {.position = {NAN, 0, 0}, .direction = {0, 0, -1}, .fov_deg = 60},
        {.position = {0, 0, 0}, .direction = {INFINITY, 0, -1}, .fov_deg = 60},
    };
    for (size_t i = 0; i < sizeof cams / sizeof cams[0]; i++) {
        assert_int_equal(view_rc_render(rc, &cams[i], NULL, &f), FXC_ERR_CAMERA);
        uint8_t rgb[3] = {1, 2, 3};
        float depth = 1;
        assert_int_equal(view_rc_insert_frame(rc, &cams[i], 1, 1, rgb, &depth), FXC_ERR_CAMERA);
    }
    view_rc_camera good = fxt_rc_look(0, 0, 0, 0, 0, -1, 60);
    assert_int_equal(view_rc_render(rc, &good, &cams[2], &f), FXC_ERR_CAMERA); /* a bad predicted camera */
    assert_int_equal(view_rc_insert_frame(rc, &good, 0, 1, (uint8_t[3]){0}, (float[1]){1}), FXC_ERR_INVALID);
    assert_int_equal(view_rc_insert_frame(rc, &good, 1, 1, NULL, (float[1]){1}), FXC_ERR_INVALID);
    assert_int_equal(view_rc_insert_samples(rc, &good, 16, 16, NULL, 3), FXC_ERR_INVALID);
    view_rc_destroy(rc);
    /* More pixels than the capacity. */
    rc = fxt_rc_make(&(view_rc_desc){.width = 4, .height = 4, .capacity = 8});
    uint8_t rgb[16 * 3] = {0};
    float depth[16];
    for (int i = 0; i < 16; i++)
        depth[i] = 2;
    assert_int_equal(view_rc_insert_frame(rc, &good, 4, 4, rgb, depth), FXC_ERR_RANGE);
    view_rc_destroy(rc);
}

/* ---- reprojection to the frame's own camera ------------------------------------------------------------ */

static void check_own_camera(uint32_t threads, bool half, bool cull)
{
    const uint32_t w = 97, h = 61;
    view_rc_camera cam = fxt_rc_look(1.3, 0.7, 2.2, 0.2, -0.4, -5, 55);
    uint8_t *rgb = malloc((size_t)w * h * 3);
    float *depth = malloc((size_t)w * h * sizeof(float));
    fxt_rc_render_scene(&cam, w, h, true, true, rgb, depth);
    if (half)
        for (size_t p = 0; p < (size_t)w * h; p++)
            depth[p] = fxt_rc_to_half(depth[p]);
    view_rc *rc = fxt_rc_make(&(view_rc_desc){
        .width = w, .height = h, .tile_size = 16, .threads = threads, .no_depth_cull = !cull});
    assert_int_equal(view_rc_insert_frame(rc, &cam, w, h, rgb, depth), FXC_OK);
    view_rc_frame f;
    fxt_rc_render(rc, &cam, NULL, &f);
    assert_memory_equal(f.rgb, rgb, (size_t)w * h * 3);
    size_t sky = 0;
    for (size_t p = 0; p < (size_t)w * h; p++) {
        assert_int_equal(f.kind[p], VIEW_RC_POINT);
        if (isinf(depth[p])) {
            assert_true(isinf(f.depth[p]));
            sky++;
        } else if (fabsf(f.depth[p] - depth[p]) > 2e-5f * depth[p]) {
            fail_msg("pixel %zu: depth %.7g, sent %.7g", p, f.depth[p], depth[p]);
        }
    }
    assert_true(sky > 0 && sky < (size_t)w * h / 2); /* the scene has sky, floor, sphere and wall */
    assert_int_equal(f.stats.pixels[VIEW_RC_POINT], w * h);
    assert_int_equal(f.stats.culled, 0);
    assert_int_equal(f.stats.points, w * h);
    assert_int_equal(f.stats.projected, w * h);
    assert_int_equal(f.request_count, view_rc_resolved_desc(rc).sample_budget);
    view_rc_destroy(rc);
    free(rgb);
    free(depth);
}

static void test_reprojection_own_camera(void **state)
{
    (void)state;
    check_own_camera(1, false, true);
    check_own_camera(1, true, true);
    check_own_camera(3, true, true);
    /* With the sphere resting on the floor, the floor shows in slivers one pixel thin behind the contact,
     * which the depth cull (a 3x3 heuristic) cannot tell from a gap in the sphere: exact without the cull. */
    fxt_rc_floor_y = -1.0;
    check_own_camera(1, true, false);
    check_own_camera(2, false, false);
    fxt_rc_floor_y = -1.5;
}

/* ---- closed-form motion -------------------------------------------------------------------------------- */

/* Points on the middle row of a camera at the origin looking down -z (the row's rays have y = 0 exactly: the
 * height is odd), then the camera turned by yaw a about +y or moved by (tx, ty, 0): a point at (X, 0, -Z)
 * seen under azimuth atan(X / Z) from -z appears at column W/2 (1 + tan(azimuth - a) / tan_half_x) after the
 * turn, and at column W/2 (1 + (X - tx) / (Z tan_half_x)), row H/2 (1 + ty / (Z tan_half_y)) after the move.
 */
static void test_closed_form_motion(void **state)
{
    (void)state;
    const uint32_t w = 101, h = 61;
    const float fov = 50;
    const double thy = tan(fov * FXT_RC_PI / 360.0), thx = thy * w / h;
    view_rc_camera c0 = fxt_rc_look(0, 0, 0, 0, 0, -1, fov);
    const uint32_t columns[] = {8, 23, 37, 50, 61, 77, 94};
    const float dist[] = {3.0f, 4.5f, 6.0f, 7.5f, 9.0f, 10.5f, 12.0f};
    enum { N = sizeof columns / sizeof columns[0] };
    view_rc_sample samples[N];
    double X[N], Z[N];
    for (int i = 0; i < N; i++) {
        samples[i] = (view_rc_sample){.x = (uint16_t)columns[i], .y = (h - 1) / 2, .depth = dist[i]};
        samples[i].rgb[0] = (uint8_t)(30 * i + 10), samples[i].rgb[1] = 200,
        samples[i].rgb[2] = (uint8_t)(7 * i);
        double sx = (2.0 * (columns[i] + 0.5) / w - 1.0) * thx;
        Z[i] = dist[i] / sqrt(1 + sx * sx);
        X[i] = sx * Z[i];
    }
    struct {
        double yaw_deg, tx, ty;
    } moves[] = {{0, 0, 0},   {4, 0, 0},       {-7.5, 0, 0},   {12, 0, 0},
                 {0, 0.6, 0}, {0, -1.1, 0.35}, {0, 0.25, -0.5}};
    for (size_t m = 0; m < sizeof moves / sizeof moves[0]; m++) {
        view_rc *rc =
            fxt_rc_make(&(view_rc_desc){.width = w, .height = h, .tile_size = 32, .no_prefilter = true});
        assert_int_equal(view_rc_insert_samples(rc, &c0, w, h, samples, N), FXC_OK);
        double a = moves[m].yaw_deg * FXT_RC_PI / 180;
        view_rc_camera c1 = {.position = {moves[m].tx, moves[m].ty, 0},
                             .direction = {(float)sin(a), 0, (float)-cos(a)},
                             .fov_deg = fov};
        view_rc_frame f;
        fxt_rc_render(rc, &c1, NULL, &f);
        uint32_t expected_points = 0;
        for (int i = 0; i < N; i++) {
            double px, py;
            if (a != 0) {
                px = w / 2.0 * (1 + tan(atan2(X[i], Z[i]) - a) / thx);
                py = h / 2.0;
            } else {
                px = w / 2.0 * (1 + (X[i] - moves[m].tx) / (Z[i] * thx));
                py = h / 2.0 * (1 + moves[m].ty / (Z[i] * thy));
            }
            if (px < 0 || px >= w || py < 0 || py >= h)
                continue;
            /* Only positions clear of a pixel border: the float store may move a point by 1e-4 pixels. */
            if (fabs(px - floor(px) - 0.5) > 0.45 || (a == 0 && fabs(py - floor(py) - 0.5) > 0.45))
                continue;
            size_t p = (size_t)floor(py) * w + (size_t)floor(px);
            if (f.kind[p] != VIEW_RC_POINT || memcmp(f.rgb + 3 * p, samples[i].rgb, 3) != 0)
                fail_msg("move %zu, point %d: expected at (%.3f, %.3f), kind %d there", m, i, px, py,
                         f.kind[p]);
            expected_points++;
        }
        assert_true(expected_points >= 4);
        assert_true(f.stats.pixels[VIEW_RC_POINT] <= N);
        view_rc_destroy(rc);
    }
}

/* ---- the depth test ------------------------------------------------------------------------------------ */

static void test_depth_test_keeps_nearer(void **state)
{
    (void)state;
    const uint32_t w = 32, h = 32;
    view_rc_camera cam = fxt_rc_look(0.5, 1, 3, 0, 0.5, -4, 60);
    view_rc_sample near_s = {.x = 13, .y = 20, .rgb = {250, 10, 10}, .depth = 3.0f};
    view_rc_sample far_s = {.x = 13, .y = 20, .rgb = {10, 10, 250}, .depth = 7.0f};
    for (int order = 0; order < 2; order++) {
        view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w, .height = h});
        /* Two batches without a frame between them: nothing replaces anything, the z-buffer decides. */
        assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, order ? &far_s : &near_s, 1), FXC_OK);
        assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, order ? &near_s : &far_s, 1), FXC_OK);
        assert_int_equal(view_rc_point_count(rc), 2);
        view_rc_frame f;
        fxt_rc_render(rc, &cam, NULL, &f);
        size_t p = 20 * w + 13;
        assert_int_equal(f.kind[p], VIEW_RC_POINT);
        assert_memory_equal(f.rgb + 3 * p, near_s.rgb, 3);
        assert_true(fabsf(f.depth[p] - 3.0f) < 1e-5f);
        assert_int_equal(f.stats.pixels[VIEW_RC_POINT], 1);
        /* A frame later, from another place, the nearer one still wins where both land. */
        view_rc_camera moved = fxt_rc_look(1.0, 1, 3, 0.5, 0.5, -4, 60);
        fxt_rc_render(rc, &moved, NULL, &f);
        assert_int_equal(f.stats.points, 2);
        assert_int_equal(f.stats.pixels[VIEW_RC_POINT], 2); /* different parallax: both show */
        view_rc_destroy(rc);
    }
    /* A whole far frame, then a near object's samples: the near colours show. */
    view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w, .height = h, .capacity = 2 * w * h});
    uint8_t rgb[32 * 32 * 3];
    float depth[32 * 32];
    for (int p = 0; p < 32 * 32; p++) {
        rgb[3 * p] = 1, rgb[3 * p + 1] = 2, rgb[3 * p + 2] = 3;
        depth[p] = 9.0f;
    }
    assert_int_equal(view_rc_insert_frame(rc, &cam, w, h, rgb, depth), FXC_OK);
    view_rc_sample s[4];
    for (int i = 0; i < 4; i++)
        s[i] = (view_rc_sample){
            .x = (uint16_t)(4 + 6 * i), .y = 9, .rgb = {200, 100, (uint8_t)i}, .depth = 2.5f};
    assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, s, 4), FXC_OK);
    view_rc_frame f;
    fxt_rc_render(rc, &cam, NULL, &f);
    for (int i = 0; i < 4; i++)
        assert_memory_equal(f.rgb + 3 * (9 * w + 4 + 6 * i), s[i].rgb, 3);
    assert_int_equal(f.stats.points, 32 * 32 + 4);
    view_rc_destroy(rc);
}

/* ---- disocclusion -------------------------------------------------------------------------------------- */

static void test_disocclusion_empty_and_first(void **state)
{
    (void)state;
    const uint32_t w = 96, h = 64;
    view_rc_camera c0 = fxt_rc_look(0, 0, 0, 0, 0, -1, 50);
    uint8_t *rgb = malloc(w * h * 3);
    float *depth = malloc(w * h * sizeof(float));
    fxt_rc_render_scene(&c0, w, h, true, false, rgb, depth); /* sphere before the wall, no floor */
    view_rc *rc =
        fxt_rc_make(&(view_rc_desc){.width = w, .height = h, .tile_size = 16, .capacity = 2 * w * h});
    assert_int_equal(view_rc_insert_frame(rc, &c0, w, h, rgb, depth), FXC_OK);
    view_rc_frame f;
    fxt_rc_render(rc, &c0, NULL, &f);
    view_rc_camera c1 = fxt_rc_look(1.5, 0, 0, 1.5, 0, -1, 50); /* 1.5 m to the right */
    fxt_rc_render(rc, &c1, NULL, &f);

    /* Disoccluded: pixels of c1 that see the wall where c0's view of that wall point was blocked by the
     * sphere. */
    uint8_t *dis = calloc(w * h, 1);
    uint32_t dis_count = 0;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            double d[3];
            fxt_rc_pixel_ray(&c1, w, h, x, y, d);
            fxt_rc_hit hit = fxt_rc_cast(c1.position, d, true, false);
            if (!(hit.t < INFINITY) || fxt_rc_sphere_t(c1.position, d, fxt_rc_sphere_centre, 1.0) == hit.t)
                continue;
            double q[3], to[3], len = 0;
            for (int k = 0; k < 3; k++) {
                q[k] = c1.position[k] + hit.t * d[k];
                to[k] = q[k] - c0.position[k];
                len += to[k] * to[k];
            }
            len = sqrt(len);
            for (int k = 0; k < 3; k++)
                to[k] /= len;
            if (fxt_rc_sphere_t(c0.position, to, fxt_rc_sphere_centre, 1.0) < len) {
                dis[y * w + x] = 1;
                dis_count++;
            }
        }
    assert_true(dis_count > 100);
    /* Chebyshev distance of each disoccluded pixel to the nearest pixel that is not (up to 5). */
    uint32_t inner2 = 0, inner3 = 0, inner5 = 0, inner5_empty = 0;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            if (!dis[y * w + x])
                continue;
            int dist = 6;
            for (int dy = -5; dy <= 5; dy++)
                for (int dx = -5; dx <= 5; dx++) {
                    int nx = (int)x + dx, ny = (int)y + dy;
                    int cheb = abs(dx) > abs(dy) ? abs(dx) : abs(dy);
                    if (nx >= 0 && ny >= 0 && nx < (int)w && ny < (int)h && !dis[ny * w + nx] && cheb < dist)
                        dist = cheb;
                }
            size_t p = y * w + x;
            if (dist >= 2) {
                inner2++;
                assert_int_not_equal(f.kind[p], VIEW_RC_POINT);
            }
            if (dist >= 3) {
                inner3++;
                assert_int_equal(f.priority[p], 255);
            }
            if (dist >= 5) { /* no point within the 7x7 reach: points lie at distance 1 at most */
                inner5++;
                inner5_empty += f.kind[p] == VIEW_RC_EMPTY;
            }
        }
    assert_true(inner3 > 20);
    assert_true(inner5 > 0);
    assert_int_equal(inner5_empty, inner5);
    /* Every pixel that shows a point has a lower priority than the disocclusion's inside. */
    uint32_t requests_in = 0;
    for (size_t p = 0; p < (size_t)w * h; p++)
        if (f.kind[p] == VIEW_RC_POINT)
            assert_true(f.priority[p] < 255);
    for (uint32_t i = 0; i < f.request_count; i++)
        requests_in += dis[f.requests[i].y * w + f.requests[i].x];
    /* Priority 255 against 64 for the points (a frame of w h points in a cache of 2 w h ages by 64): the
     * region's share of requests is well above its area's. */
    double share = (double)requests_in / f.request_count, area = (double)dis_count / (w * h);
    assert_true(share > 2.0 * area);
    view_rc_destroy(rc);
    free(dis);
    free(rgb);
    free(depth);
}

/* ---- filters on hand-made patterns --------------------------------------------------------------------- */

/* Samples at chosen pixels of a camera, all 5 m away along their rays, rendered with the same camera. */
static view_rc_frame filter_frame(view_rc **rc_out, const view_rc_desc *d, const view_rc_sample *s,
                                  uint32_t n)
{
    view_rc *rc = fxt_rc_make(d);
    view_rc_camera cam = fxt_rc_look(0, 0, 0, 0, 0, -1, 60);
    assert_int_equal(view_rc_insert_samples(rc, &cam, d->width, d->height, s, n), FXC_OK);
    view_rc_frame f;
    fxt_rc_render(rc, &cam, NULL, &f);
    *rc_out = rc;
    return f;
}

static void expect_pixel(const view_rc_frame *f, uint32_t x, uint32_t y, int kind, int r, int g, int b)
{
    size_t p = (size_t)y * f->width + x;
    if (f->kind[p] != kind || f->rgb[3 * p] != r || f->rgb[3 * p + 1] != g || f->rgb[3 * p + 2] != b)
        fail_msg("pixel (%u, %u): kind %d rgb %d %d %d, expected kind %d rgb %d %d %d", x, y, f->kind[p],
                 f->rgb[3 * p], f->rgb[3 * p + 1], f->rgb[3 * p + 2], kind, r, g, b);
}

static void test_filters_by_hand(void **state)
{
    (void)state;
    const view_rc_sample s[] = {
        {.x = 10, .y = 10, .rgb = {200, 0, 0}, .depth = 5},
        {.x = 12, .y = 10, .rgb = {0, 100, 50}, .depth = 5},
        {.x = 11, .y = 11, .rgb = {30, 60, 90}, .depth = 5},
        {.x = 25, .y = 22, .rgb = {90, 180, 30}, .depth = 5},
        {.x = 28, .y = 22, .rgb = {10, 20, 250}, .depth = 5},
    };
    view_rc_desc d = {.width = 40, .height = 36, .tile_size = 8, .clear_rgb = {1, 2, 3}};
    view_rc *rc;
    view_rc_frame f = filter_frame(&rc, &d, s, 5);
    /* Points show their own colours. */
    expect_pixel(&f, 10, 10, VIEW_RC_POINT, 200, 0, 0);
    expect_pixel(&f, 12, 10, VIEW_RC_POINT, 0, 100, 50);
    /* (11, 10): left (200,0,0) weight 2, right (0,100,50) weight 2, below (30,60,90) weight 2; total 6:
     * red (400 + 60 + 3) / 6 = 77, green (200 + 120 + 3) / 6 = 53, blue (100 + 180 + 3) / 6 = 47. */
    expect_pixel(&f, 11, 10, VIEW_RC_INTERP, 77, 53, 47);
    /* (10, 11): above (200,0,0) weight 2, right (30,60,90) weight 2; total 4:
     * (400 + 60 + 2) / 4 = 115, (0 + 120 + 2) / 4 = 30, (0 + 180 + 2) / 4 = 45. */
    expect_pixel(&f, 10, 11, VIEW_RC_INTERP, 115, 30, 45);
    /* (11, 9): two corners, weight 1 each: (200 + 0 + 1) / 2 = 100, (0 + 100 + 1) / 2 = 50, (0 + 50 + 1) / 2
     * = 25. */
    expect_pixel(&f, 11, 9, VIEW_RC_INTERP, 100, 50, 25);
    /* (12, 12): one corner (30,60,90): itself. */
    expect_pixel(&f, 12, 12, VIEW_RC_INTERP, 30, 60, 90);
    /* The prefilter: (25, 25) has no point within 3x3; its 7x7 holds (25,22) and (28,22):
     * ((90 + 10 + 1) / 2, (180 + 20 + 1) / 2, (30 + 250 + 1) / 2) = (50, 100, 140). */
    expect_pixel(&f, 25, 25, VIEW_RC_PREFILTER, 50, 100, 140);
    /* (22, 25): 7x7 holds only (25, 22). */
    expect_pixel(&f, 22, 25, VIEW_RC_PREFILTER, 90, 180, 30);
    /* (25, 26): nothing within 3 rows: clear colour. */
    expect_pixel(&f, 25, 26, VIEW_RC_EMPTY, 1, 2, 3);
    expect_pixel(&f, 0, 35, VIEW_RC_EMPTY, 1, 2, 3);
    /* Priority: points are new (age 0); empty pixels 255 - 16 per neighbouring point. */
    assert_int_equal(f.priority[10 * 40 + 10], 0);
    assert_int_equal(f.priority[10 * 40 + 11], 255 - 3 * 16);
    assert_int_equal(f.priority[9 * 40 + 11], 255 - 2 * 16);
    assert_int_equal(f.priority[25 * 40 + 25], 255);
    assert_int_equal(f.stats.pixels[VIEW_RC_POINT], 5);
    view_rc_destroy(rc);

    /* Without the prefilter, (25, 25) is empty. */
    d.no_prefilter = true;
    f = filter_frame(&rc, &d, s, 5);
    expect_pixel(&f, 25, 25, VIEW_RC_EMPTY, 1, 2, 3);
    expect_pixel(&f, 11, 10, VIEW_RC_INTERP, 77, 53, 47);
    assert_int_equal(f.stats.pixels[VIEW_RC_PREFILTER], 0);
    view_rc_destroy(rc);

    /* smooth_all: a point's pixel is the weighted mean too. (10, 10): itself weight 4, (11, 11) weight 1:
     * (800 + 30 + 2) / 5 = 166, (0 + 60 + 2) / 5 = 12, (0 + 90 + 2) / 5 = 18. */
    d.no_prefilter = false;
    d.smooth_all = true;
    f = filter_frame(&rc, &d, s, 5);
    expect_pixel(&f, 10, 10, VIEW_RC_POINT, 166, 12, 18);
    expect_pixel(&f, 11, 10, VIEW_RC_INTERP, 77, 53, 47);
    view_rc_destroy(rc);
}

/* The 3x3 filter on an image wider than the interpolation's column strips (256 columns), with points on both
 * sides of the strips' seams (255 | 256, 511 | 512, ...) and at random: every pixel against the filter
 * computed here directly from the points (kind, colour, and the priority of pixels without a point). */
static void check_wide_interpolation(uint32_t w, uint32_t h)
{
    uint8_t *has = calloc((size_t)w * h, 1);
    uint8_t *col = calloc((size_t)w * h * 3, 1);
    view_rc_sample *s = calloc((size_t)w * h, sizeof *s);
    uint32_t n = 0, seed = 12345;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            seed = seed * 1664525u + 1013904223u;
            bool seam = (x % 256 == 255 || (x % 256 == 0 && x > 0 && y % 2 == 0)) && y % 3 == 0;
            if (!seam && (seed >> 24) >= 70)
                continue;
            size_t p = (size_t)y * w + x;
            has[p] = 1;
            for (int k = 0; k < 3; k++)
                col[3 * p + k] = (uint8_t)((x * 7 + y * 13 + (uint32_t)k * 101) & 0xFF);
            s[n] = (view_rc_sample){.x = x, .y = y, .depth = 5};
            memcpy(s[n].rgb, col + 3 * p, 3);
            n++;
        }
    view_rc_desc d = {.width = w,
                      .height = h,
                      .tile_size = 8,
                      .no_prefilter = true,
                      .no_depth_cull = true,
                      .clear_rgb = {1, 2, 3}};
    view_rc *rc;
    view_rc_frame f = filter_frame(&rc, &d, s, n);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t p = (size_t)y * w + x;
            if (has[p]) {
                expect_pixel(&f, x, y, VIEW_RC_POINT, col[3 * p], col[3 * p + 1], col[3 * p + 2]);
                continue;
            }
            uint32_t sum[3] = {0}, weight = 0, count = 0;
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) {
                    int64_t nx = (int64_t)x + dx, ny = (int64_t)y + dy;
                    if (nx < 0 || ny < 0 || nx >= w || ny >= h || !has[ny * w + nx])
                        continue;
                    uint32_t wt = (uint32_t)((2 - abs(dx)) * (2 - abs(dy)));
                    for (int k = 0; k < 3; k++)
                        sum[k] += wt * col[3 * (ny * w + nx) + k];
                    weight += wt;
                    count++;
                }
            if (weight == 0)
                expect_pixel(&f, x, y, VIEW_RC_EMPTY, 1, 2, 3);
            else
                expect_pixel(&f, x, y, VIEW_RC_INTERP, (int)((sum[0] + weight / 2) / weight),
                             (int)((sum[1] + weight / 2) / weight), (int)((sum[2] + weight / 2) / weight));
            assert_int_equal(f.priority[p], 255 - 16 * count);
        }
    view_rc_destroy(rc);
    free(s);
    free(col);
    free(has);
}

static void test_interpolation_wide_by_closed_form(void **state)
{
    (void)state;
    check_wide_interpolation(600, 24);  /* three strips */
    check_wide_interpolation(5000, 20); /* twenty strips */
}

/* ---- the dither ---------------------------------------------------------------------------------------- */

static void check_distinct(const view_rc_pixel *px, uint32_t n, uint32_t w, uint32_t h)
{
    uint8_t *seen = calloc((size_t)w * h, 1);
    for (uint32_t i = 0; i < n; i++) {
        assert_true(px[i].x < w && px[i].y < h);
        size_t p = (size_t)px[i].y * w + px[i].x;
        assert_int_equal(seen[p], 0);
        seen[p] = 1;
    }
    free(seen);
}

/* Left half of the image priority 200, right half 10. */
static void fill_halves(uint8_t *prio, uint32_t w, uint32_t h)
{
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++)
            prio[y * w + x] = x < w / 2 ? 200 : 10;
}

/* Dithers 300 samples over prio in bands of `band` rows (0: one band) and returns how many fell in the left
 * half, after checking they are distinct pixels. */
static uint32_t dither_left(const uint8_t *prio, uint32_t w, uint32_t h, uint32_t band, view_rc_pixel *out,
                            void *scratch, size_t scratch_bytes)
{
    assert_int_equal(view_rc_dither(prio, w, h, band, 300, out, scratch, scratch_bytes), FXC_OK);
    check_distinct(out, 300, w, h);
    uint32_t left = 0;
    for (int i = 0; i < 300; i++)
        left += out[i].x < w / 2;
    return left;
}

static void test_dither(void **state)
{
    (void)state;
    const uint32_t w = 64, h = 48;
    uint8_t prio[64 * 48];
    size_t scratch_bytes = view_rc_dither_scratch_bytes(w, h);
    void *scratch = malloc(scratch_bytes);
    view_rc_pixel *out = malloc(sizeof(view_rc_pixel) * w * h);
    /* Left half 200, right half 10: weights 201 and 11, so 300 * 201 / 212 = 284.4 on the left. */
    fill_halves(prio, w, h);
    for (uint32_t band = 0; band <= 16; band += 16) {
        uint32_t left = dither_left(prio, w, h, band, out, scratch, scratch_bytes);
        assert_true(left >= 281 && left <= 288);
    }
    /* Uniform priority: every 8x8 block gets its share, 400 * 64 / 3072 = 8.3, within 2. */
    memset(prio, 77, sizeof prio);
    assert_int_equal(view_rc_dither(prio, w, h, 16, 400, out, scratch, scratch_bytes), FXC_OK);
    check_distinct(out, 400, w, h);
    uint32_t block[8][6] = {{0}};
    for (int i = 0; i < 400; i++)
        block[out[i].x / 8][out[i].y / 8]++;
    for (int bx = 0; bx < 8; bx++)
        for (int by = 0; by < 6; by++)
            assert_true(block[bx][by] >= 6 && block[bx][by] <= 11);
    /* Exact counts whatever the pattern: none, one, a spike that wants more than its pixels, all pixels. */
    for (size_t p = 0; p < sizeof prio; p++)
        prio[p] = (uint8_t)((p * 7919) % 13 == 0 ? 255 : 0);
    const uint32_t counts[] = {0, 1, 17, 1000, 2999, w * h};
    for (size_t i = 0; i < sizeof counts / sizeof counts[0]; i++) {
        assert_int_equal(view_rc_dither(prio, w, h, 16, counts[i], out, scratch, scratch_bytes), FXC_OK);
        check_distinct(out, counts[i], w, h);
    }
    /* With 200 of 3072 and the 255-pixels a thirteenth of the image (236 of them): weight 256 against 1, so
     * nearly all go there. */
    assert_int_equal(view_rc_dither(prio, w, h, 0, 200, out, scratch, scratch_bytes), FXC_OK);
    uint32_t hot = 0;
    for (int i = 0; i < 200; i++)
        hot += prio[out[i].y * w + out[i].x] == 255;
    assert_true(hot >= 190);
    /* Many bands (12 of 4 rows; 10 of 5 rows, the last 3): more than one group of lanes, and spare lanes.
     * Every row has the same weights, so each band gets 300 in proportion to its rows, 201 / 212 of it on the
     * left: 284.4 in all, each band within a rounding of its own share. */
    fill_halves(prio, w, h);
    for (uint32_t band = 4; band <= 5; band++) {
        uint32_t left = dither_left(prio, w, h, band, out, scratch, scratch_bytes);
        assert_true(left >= 272 && left <= 296);
    }
    /* The seam rule keeps bands independent: each band of a 12-band run, dithered alone with the count it got
     * there, chooses the same pixels (in the run one lane of eight, alone one beside spare lanes). */
    for (size_t p = 0; p < sizeof prio; p++)
        prio[p] = (uint8_t)((p * 7919) % 251);
    assert_int_equal(view_rc_dither(prio, w, h, 4, 500, out, scratch, scratch_bytes), FXC_OK);
    view_rc_pixel alone[64 * 4];
    uint32_t at = 0;
    for (uint32_t band = 0; band < h / 4; band++) {
        uint32_t n = 0;
        while (at + n < 500 && out[at + n].y / 4 == band)
            n++;
        assert_true(n > 0);
        void *scratch2 = malloc(view_rc_dither_scratch_bytes(w, 4));
        assert_int_equal(view_rc_dither(prio + (size_t)band * 4 * w, w, 4, 0, n, alone, scratch2,
                                        view_rc_dither_scratch_bytes(w, 4)),
                         FXC_OK);
        free(scratch2);
        for (uint32_t i = 0; i < n; i++) {
            assert_int_equal(alone[i].x, out[at + i].x);
            assert_int_equal(alone[i].y + band * 4, out[at + i].y);
        }
        at += n;
    }
    assert_int_equal(at, 500);
    /* Refusals. */
    assert_int_equal(view_rc_dither(prio, w, h, 0, w * h + 1, out, scratch, scratch_bytes), FXC_ERR_INVALID);
    assert_int_equal(view_rc_dither(prio, w, h, 0, 10, out, scratch, scratch_bytes - 1), FXC_ERR_INVALID);
    free(scratch);
    free(out);
}

/* ---- prediction ---------------------------------------------------------------------------------------- */

static void test_predicted_requests(void **state)
{
    (void)state;
    const uint32_t w = 128, h = 96;
    view_rc_camera c0 = fxt_rc_look(0, 0, 0, 0, 0, -1, 60);
    uint8_t *rgb = malloc(w * h * 3);
    float *depth = malloc(w * h * sizeof(float));
    fxt_rc_render_scene(&c0, w, h, true, true, rgb, depth);
    for (int budget_case = 0; budget_case < 2; budget_case++) {
        uint32_t budget = budget_case ? 64 : 2000;
        view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w, .height = h, .sample_budget = budget});
        assert_int_equal(view_rc_insert_frame(rc, &c0, w, h, rgb, depth), FXC_OK);
        /* Turned 25 degrees to the right: beyond c0's frustum nothing is cached. */
        view_rc_camera turned = {
            .position = {0, 0, 0},
            .direction = {(float)sin(25 * FXT_RC_PI / 180), 0, (float)-cos(25 * FXT_RC_PI / 180)},
            .fov_deg = 60};
        view_rc_frame f;
        fxt_rc_render(rc, &c0, &turned, &f);
        /* Where a ray of `turned` through image-plane point (sx, sy) meets c0's image plane: c0 sees along
         * -z, `turned` along (sin a, 0, -cos a) with right (cos a, 0, sin a), so the ray's c0 coordinates are
         * x = sin a + sx cos a, y = sy, depth = cos a - sx sin a. Outside c0's frustum when |x| / depth or
         * |y| / depth exceeds c0's tangents: nothing is cached there. */
        double a = 25 * FXT_RC_PI / 180, thy = tan(30 * FXT_RC_PI / 180), thx = thy * w / h;
        uint32_t surely_empty = 0;
        for (uint32_t ly = 0; ly < h / 4; ly++)
            for (uint32_t lx = 0; lx < w / 4; lx++) {
                bool all_out = true; /* all four corners of the 4 x 4 block, a pixel beyond c0's edge */
                for (int corner = 0; corner < 4; corner++) {
                    double sx = (2.0 * (4 * lx + (corner & 1) * 4) / w - 1.0) * thx;
                    double sy = (1.0 - 2.0 * (4 * ly + (corner >> 1) * 4) / h) * thy;
                    double depth0 = cos(a) - sx * sin(a), x0 = sin(a) + sx * cos(a);
                    all_out &= depth0 > 0 &&
                               (x0 / depth0 > thx * (1 + 2.0 / w) || fabs(sy) / depth0 > thy * (1 + 2.0 / h));
                }
                surely_empty += all_out;
            }
        assert_true(surely_empty > 100);
        uint32_t half = budget / 2;
        assert_true(f.predicted_count >= (surely_empty < half ? surely_empty : half));
        assert_true(f.predicted_count <= half);
        if (budget == 64)
            assert_int_equal(f.predicted_count, 32);
        assert_int_equal(f.predicted_count + f.request_count, budget);
        for (uint32_t i = 0; i < f.predicted_count; i++) {
            /* Each requested pixel lies outside c0's frustum, or within the 2.5 pixels of a block's reach. */
            double sx = (2.0 * (f.predicted_requests[i].x + 0.5) / w - 1.0) * thx;
            double sy = (1.0 - 2.0 * (f.predicted_requests[i].y + 0.5) / h) * thy;
            double depth0 = cos(a) - sx * sin(a), x0 = sin(a) + sx * cos(a);
            assert_true(x0 / depth0 > thx * (1 - 5.0 / w) || fabs(sy) / depth0 > thy * (1 - 5.0 / h));
        }
        check_distinct(f.predicted_requests, f.predicted_count, w, h);
        check_distinct(f.requests, f.request_count, w, h);
        view_rc_destroy(rc);
        /* Switched off: no predicted requests, the whole budget to the dither. */
        rc = fxt_rc_make(
            &(view_rc_desc){.width = w, .height = h, .sample_budget = budget, .no_prediction = true});
        assert_int_equal(view_rc_insert_frame(rc, &c0, w, h, rgb, depth), FXC_OK);
        fxt_rc_render(rc, &c0, &turned, &f);
        assert_int_equal(f.predicted_count, 0);
        assert_int_equal(f.request_count, budget);
        view_rc_destroy(rc);
    }
    free(rgb);
    free(depth);
}

/* ---- ageing and eviction ------------------------------------------------------------------------------- */

/* The age of the cached point with colour (r, g, b), or -1. */
static int age_of(const view_rc *rc, uint8_t r, uint8_t g, uint8_t b)
{
    uint32_t n = view_rc_point_count(rc);
    view_rc_point *pts = malloc(sizeof *pts * (n + 1));
    uint32_t got = view_rc_points(rc, 0, n, pts);
    int age = -1;
    for (uint32_t i = 0; i < got; i++)
        if (pts[i].rgb[0] == r && pts[i].rgb[1] == g && pts[i].rgb[2] == b)
            age = pts[i].age;
    free(pts);
    return age;
}

/* 48 samples a frame into a cache of 4096 points: steps of 128 * 48 / 4096 = 1.5, carried: 1, 2, 1, 2, ... so
 * after F frames a visible point is floor(1.5 F) old and a hidden one floor(3 F); the hidden one reaches 255
 * at frame 85 and is evicted; with no_eviction it stays at 254. */
static void test_ageing_and_eviction(void **state)
{
    (void)state;
    const uint32_t w = 64, h = 64;
    for (int no_eviction = 0; no_eviction < 2; no_eviction++) {
        view_rc *rc = fxt_rc_make(
            &(view_rc_desc){.width = w, .height = h, .capacity = 4096, .no_eviction = no_eviction});
        view_rc_camera cam = fxt_rc_look(0, 0, 0, 0, 0, -1, 60), back = fxt_rc_look(0, 0, 0, 0, 0, 1, 60);
        /* One point in view (colour 1, 2, 3) and one behind the camera (4, 5, 6). */
        view_rc_sample seen = {.x = 0, .y = 0, .rgb = {1, 2, 3}, .depth = 4};
        view_rc_sample hidden = {.x = 30, .y = 30, .rgb = {4, 5, 6}, .depth = 4};
        assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, &seen, 1), FXC_OK);
        assert_int_equal(view_rc_insert_samples(rc, &back, w, h, &hidden, 1), FXC_OK);
        uint32_t next_pixel = 1; /* fresh pixels for the filler samples, never the same twice */
        view_rc_frame f;
        fxt_rc_render(rc, &cam, NULL, &f); /* frame 0 inserted 2: its step is 0 */
        assert_int_equal(age_of(rc, 1, 2, 3), 0);
        for (int frame = 1; frame <= 85;
             frame++) { /* 85 * 48 + 2 points: within the capacity and the image */
            view_rc_sample fill[48];
            for (int i = 0; i < 48; i++) {
                uint32_t p = next_pixel++;
                fill[i] = (view_rc_sample){.x = (uint16_t)(p % w),
                                           .y = (uint16_t)(p / w),
                                           .depth = 6,
                                           .rgb = {200, (uint8_t)(p & 0xFF), (uint8_t)(p >> 8)}};
            }
            assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, fill, 48), FXC_OK);
            fxt_rc_render(rc, &cam, NULL, &f);
            assert_int_equal(f.stats.age_step, (uint32_t)(floor(1.5 * frame) - floor(1.5 * (frame - 1))));
            assert_int_equal(f.stats.hidden_age_step, 3);
            assert_int_equal(age_of(rc, 1, 2, 3), (int)floor(1.5 * frame));
            int hidden_age = age_of(rc, 4, 5, 6);
            if (no_eviction)
                assert_int_equal(hidden_age, 3 * frame < 254 ? 3 * frame : 254);
            else if (frame < 85)
                assert_int_equal(hidden_age, 3 * frame);
            else
                assert_int_equal(hidden_age, -1);
            if (!no_eviction)
                assert_int_equal(f.stats.evicted, frame == 85 ? 1 : 0);
            assert_int_equal(f.stats.dropped, 0);
        }
        view_rc_destroy(rc);
    }
}

/* A full cache drops its oldest points; with k = 256 new points a frame in a cache of N = 4096 the step is
 * 128 * 256 / 4096 = 8, and the points dropped at frame f are those of frame f - 16, aged 16 * 8 = 128: the
 * paper's "on average a point should reach the age of 128 before being overwritten". */
static void test_full_cache_drops_oldest_at_128(void **state)
{
    (void)state;
    const uint32_t w = 128, h = 128;
    view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w, .height = h, .capacity = 4096});
    view_rc_camera cam = fxt_rc_look(0, 0, 0, 0, 0, -1, 60);
    uint64_t dropped = 0, dropped_age = 0;
    for (uint32_t frame = 0; frame < 48; frame++) {
        view_rc_sample s[256];
        for (uint32_t i = 0; i < 256; i++) {
            uint32_t p = frame * 256 + i; /* never the same pixel twice */
            s[i] = (view_rc_sample){
                .x = (uint16_t)(p % w), .y = (uint16_t)(p / w), .depth = 5, .rgb = {(uint8_t)frame, 9, 9}};
        }
        assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, s, 256), FXC_OK);
        view_rc_frame f;
        fxt_rc_render(rc, &cam, NULL, &f);
        assert_int_equal(f.stats.age_step, 8);
        assert_int_equal(f.stats.dropped, frame >= 16 ? 256 : 0);
        assert_true(f.stats.points <= 4096);
        dropped += f.stats.dropped;
        dropped_age += f.stats.dropped_age_sum;
        if (frame >= 16)
            assert_int_equal(f.stats.dropped_age_sum, 256 * 128);
    }
    assert_int_equal(dropped, 32 * 256);
    assert_int_equal(dropped_age / dropped, 128);
    /* The oldest batch left is frame 32's. */
    assert_int_equal(age_of(rc, 31, 9, 9), -1);
    assert_true(age_of(rc, 32, 9, 9) >= 0);
    view_rc_destroy(rc);
}

/* When only some points of the oldest age must go, the first ones in slot order go: 4096 points inserted
 * together into an empty cache of 4096 take slots 0..4095 and age alike (all visible, 128 after a frame); 100
 * more then drop exactly the first 100 of them (a block of 64 dropped whole, then 36 of the next one by one,
 * the rest of that block kept). */
static void test_drops_first_in_slot_order(void **state)
{
    (void)state;
    const uint32_t w = 128, h = 128, n = 4096, more = 100;
    view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w, .height = h, .capacity = n});
    view_rc_camera cam = fxt_rc_look(0, 0, 0, 0, 0, -1, 60);
    view_rc_sample *s = malloc(sizeof *s * n);
    for (uint32_t p = 0; p < n; p++)
        s[p] = (view_rc_sample){.x = (uint16_t)(p % w),
                                .y = (uint16_t)(p / w),
                                .depth = 5,
                                .rgb = {(uint8_t)(p & 255), (uint8_t)(p >> 8), 1}};
    assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, s, n), FXC_OK);
    view_rc_frame f;
    fxt_rc_render(rc, &cam, NULL, &f);
    assert_int_equal(f.stats.points, n);
    for (uint32_t i = 0; i < more; i++)
        s[i] = (view_rc_sample){.x = (uint16_t)((n + i) % w),
                                .y = (uint16_t)((n + i) / w),
                                .depth = 5,
                                .rgb = {(uint8_t)i, 0, 2}};
    assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, s, more), FXC_OK);
    fxt_rc_render(rc, &cam, NULL, &f);
    assert_int_equal(f.stats.dropped, more);
    assert_int_equal(f.stats.dropped_age_sum, (uint64_t)more * 128);
    uint32_t count = view_rc_point_count(rc);
    assert_int_equal(count, n);
    view_rc_point *pts = malloc(sizeof *pts * count);
    assert_int_equal(view_rc_points(rc, 0, count, pts), count);
    uint8_t *present = calloc(n, 1);
    uint32_t fresh = 0;
    for (uint32_t i = 0; i < count; i++)
        if (pts[i].rgb[2] == 1)
            present[pts[i].rgb[0] | (uint32_t)pts[i].rgb[1] << 8] = 1;
        else
            fresh++;
    assert_int_equal(fresh, more);
    for (uint32_t p = 0; p < n; p++)
        assert_int_equal(present[p], p >= more);
    free(present);
    free(pts);
    free(s);
    view_rc_destroy(rc);
}

/* A sample whose colour differs from the point it replaces ages that pixel's 8 neighbours by the penalty; a
 * similar one does not. */
static void test_colour_change_penalty(void **state)
{
    (void)state;
    const uint32_t w = 32, h = 32;
    view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w, .height = h, .capacity = 2048});
    view_rc_camera cam = fxt_rc_look(0, 0, 0, 0, 0, -1, 60);
    uint8_t rgb[32 * 32 * 3];
    float depth[32 * 32];
    memset(rgb, 128, sizeof rgb);
    for (int p = 0; p < 32 * 32; p++)
        depth[p] = 5;
    assert_int_equal(view_rc_insert_frame(rc, &cam, w, h, rgb, depth), FXC_OK);
    view_rc_frame f;
    fxt_rc_render(rc, &cam, NULL, &f); /* 1024 new in 2048: step 64 */
    assert_int_equal(f.stats.age_step, 64);
    view_rc_sample changed = {.x = 16, .y = 16, .rgb = {255, 0, 0}, .depth = 5};
    view_rc_sample similar = {.x = 5, .y = 5, .rgb = {150, 110, 128}, .depth = 5.05f};
    assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, &changed, 1), FXC_OK);
    assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, &similar, 1), FXC_OK);
    fxt_rc_render(rc, &cam, NULL, &f); /* 2 new in 2048: step 0 (0.125, carried) */
    assert_int_equal(f.stats.superseded, 2);
    assert_int_equal(f.stats.points, 1024);
    expect_pixel(&f, 16, 16, VIEW_RC_POINT, 255, 0, 0);
    expect_pixel(&f, 5, 5, VIEW_RC_POINT, 150, 110, 128);
    assert_int_equal(f.priority[16 * w + 16], 0);
    assert_int_equal(f.priority[5 * w + 5], 0);
    for (int dy = -1; dy <= 1; dy++)
        for (int dx = -1; dx <= 1; dx++) {
            if (dx || dy) {
                assert_int_equal(f.priority[(16 + dy) * w + 16 + dx], 128);
                assert_int_equal(f.priority[(5 + dy) * w + 5 + dx], 64);
            }
        }
    assert_int_equal(f.priority[0], 64);
    view_rc_destroy(rc);
}

/* A frame replaces what it saw: the same view twice holds one frame's points, showing the second's colours.
 */
static void test_frame_replaces_what_it_saw(void **state)
{
    (void)state;
    const uint32_t w = 48, h = 40;
    view_rc_camera cam = fxt_rc_look(0.3, 0.5, 1, 0, 0, -5, 60);
    uint8_t *rgb = malloc(w * h * 3);
    float *depth = malloc(w * h * sizeof(float));
    fxt_rc_render_scene(&cam, w, h, true, true, rgb, depth);
    view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w, .height = h});
    assert_int_equal(view_rc_insert_frame(rc, &cam, w, h, rgb, depth), FXC_OK);
    view_rc_frame f;
    fxt_rc_render(rc, &cam, NULL, &f);
    for (size_t i = 0; i < (size_t)w * h * 3; i++)
        rgb[i] = (uint8_t)(255 - rgb[i]);
    assert_int_equal(view_rc_insert_frame(rc, &cam, w, h, rgb, depth), FXC_OK);
    assert_int_equal(view_rc_point_count(rc), w * h);
    fxt_rc_render(rc, &cam, NULL, &f);
    assert_int_equal(f.stats.superseded, w * h);
    assert_memory_equal(f.rgb, rgb, (size_t)w * h * 3);
    view_rc_destroy(rc);
    free(rgb);
    free(depth);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_desc_defaults_and_refusals),
        cmocka_unit_test(test_reprojection_own_camera),
        cmocka_unit_test(test_closed_form_motion),
        cmocka_unit_test(test_depth_test_keeps_nearer),
        cmocka_unit_test(test_disocclusion_empty_and_first),
        cmocka_unit_test(test_filters_by_hand),
        cmocka_unit_test(test_interpolation_wide_by_closed_form),
        cmocka_unit_test(test_dither),
        cmocka_unit_test(test_predicted_requests),
        cmocka_unit_test(test_ageing_and_eviction),
        cmocka_unit_test(test_full_cache_drops_oldest_at_128),
        cmocka_unit_test(test_drops_first_in_slot_order),
        cmocka_unit_test(test_colour_change_penalty),
        cmocka_unit_test(test_frame_replaces_what_it_saw),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
