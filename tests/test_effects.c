/* Tests of the effects module (effects/effects.h): triangle lookup, hard shadows, ambient occlusion.
 *
 * Scenes are built by hand through the scene builder (scene__alloc, scene__add_mesh, scene__finalize) and
 * traced with the real Embree scene. Every expected value is analytic:
 *   - lookup: barycentrics of texel centres computed here in double from the island UVs; texels outside
 *     every triangle must take a triangle at the smallest UV distance;
 *   - AO: for a cosine-weighted direction, its component along the floor is uniform in the unit disk, so a
 *     wall at distance d occludes rays of length R with probability seg(d/R)/pi (seg: circular segment
 *     area), and the inside corner of three planes leaves P(x > -a, z > -b) for (x, z) uniform in the disk;
 *     averages over N rays are compared with tolerance AO_SIGMAS * sqrt(p (1 - p) / N), the binomial
 *     standard error (stratified sampling only lowers the variance);
 *   - shadows: a square occluder above a floor under a sun straight down (and a point light above it).
 * Determinism: payloads must be bitwise identical for any batching, job order and per-frame budget split.
 * Robustness: scenes at 1e-4 scale near the origin and at 1e4 scale 1e5 away, with tilted planes, must show
 * no self-intersection (open-plane AO exactly 1, every shadow bit set) and finite points. */
#include "test_util.h"

#include "fxt_scene.h"

#include "effects.h"
#include "fx_internal.h" /* white-box: the sample sequence */
#include "scene.h"
#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Standard errors allowed between a Monte Carlo average and its analytic value. */
#define AO_SIGMAS 5.0
/* One quantization step of a lookup barycentric, plus float rounding. */
#define LOOKUP_STEP (1.0 / 4095.0 + 1e-6)

static const double PI = 3.14159265358979323846;

/* ---- scene building ------------------------------------------------------------------------------ */

/* Adds a point light at (x, y, z). */
static void add_point_light(scene *s, float x, float y, float z)
{
    scene_light light = {
        .type = SCENE_LIGHT_POINT, .position = {x, y, z}, .color = {1, 1, 1}, .intensity = 1};
    scene_error err;
    assert_int_equal(scene__add_light(s, &light, "test lamp", &err), SCENE_OK);
}

/* ---- running an effect over a whole island -------------------------------------------------------- */

/* World position and normal of the centre of texel t of block b. */
static void texel_centre(const scene *s, const fxt_island_run *run, uint32_t b, uint32_t t, float pos[3],
                         float normal[3])
{
    const fx_block_job *job = &run->jobs[b];
    float scale = (float)(1u << run->level);
    float u = ((float)(job->block_x * 8 + (t & 7)) + 0.5f) * scale;
    float v = ((float)(job->block_y * 8 + (t >> 3)) + 0.5f) * scale;
    fx_surface_point(s, run->island, job->lookup[t], u, v, pos, normal);
}

/* ---- triangle lookup ------------------------------------------------------------------------------ */

/* Pack and unpack keep the triangle and the barycentrics within one quantization step, with u + v <= 1. */
static void test_lookup_pack_roundtrip(void **state)
{
    (void)state;
    uint64_t lcg = 12345;
    for (uint32_t i = 0; i < 100000; i++) {
        lcg = lcg * 6364136223846793005ull + 1442695040888963407ull;
        float u = (float)((lcg >> 40) & 0xffffff) / 16777216.0f;
        float v = (float)((lcg >> 16) & 0xffffff) / 16777216.0f;
        if (u + v > 1) {
            u = 1 - u;
            v = 1 - v;
        }
        if (i % 7 == 0)
            v = 1 - u; /* on the far edge: rounding up of both must not push u + v above 1 */
        uint32_t tri = i & 0xff, tri_back;
        float u_back, v_back;
        fx_lookup_unpack(fx_lookup_pack(tri, u, v), &tri_back, &u_back, &v_back);
        assert_int_equal(tri_back, tri);
        assert_true(fabs((double)u_back - u) <= LOOKUP_STEP);
        assert_true(fabs((double)v_back - v) <= LOOKUP_STEP);
        assert_true(u_back + v_back <= 1.0f + 1e-6f);
    }
    /* Saturation: out-of-range and NaN inputs land inside [0, 1]. */
    uint32_t tri;
    float u, v;
    fx_lookup_unpack(fx_lookup_pack(3, -1.0f, 2.0f), &tri, &u, &v);
    assert_true(u == 0.0f && v == 1.0f && tri == 3);
    fx_lookup_unpack(fx_lookup_pack(255, NAN, 0.25f), &tri, &u, &v);
    assert_true(isfinite(u) && u >= 0 && u <= 1 && tri == 255);
}

/* Barycentric weights (corners 0, 1, 2) of UV point p in triangle uv (6 floats). */
static void barycentrics(const float *uv, double px, double py, double w[3])
{
    double ax = uv[0], ay = uv[1], bx = uv[2], by = uv[3], cx = uv[4], cy = uv[5];
    double area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
    w[1] = ((px - ax) * (cy - ay) - (py - ay) * (cx - ax)) / area;
    w[2] = ((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / area;
    w[0] = 1 - w[1] - w[2];
}

/* Distance from p to segment a-b. */
static double segment_distance(double px, double py, double ax, double ay, double bx, double by)
{
    double ex = bx - ax, ey = by - ay, len2 = ex * ex + ey * ey;
    double t = len2 > 0 ? ((px - ax) * ex + (py - ay) * ey) / len2 : 0;
    t = t < 0 ? 0 : (t > 1 ? 1 : t);
    return hypot(ax + t * ex - px, ay + t * ey - py);
}

/* Distance from p to triangle uv (0 inside). */
static double triangle_distance(const float *uv, double px, double py)
{
    double w[3];
    barycentrics(uv, px, py, w);
    if (w[0] >= 0 && w[1] >= 0 && w[2] >= 0)
        return 0;
    double d = INFINITY;
    for (int k = 0; k < 3; k++) {
        int n = (k + 1) % 3;
        d = fmin(d, segment_distance(px, py, uv[2 * k], uv[2 * k + 1], uv[2 * n], uv[2 * n + 1]));
    }
    return d;
}

/* An L-shaped planar mesh (non-convex: texels in its notch lie outside every triangle): every texel centre
 * strictly inside a triangle gets it with the analytic barycentrics; every other one a nearest triangle. */
static void test_lookup_inside_and_nearest(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    const float positions[] = {0, 0, 0, 3, 0, 0, 3, 0, 1, 1.2f, 0, 1.1f, 1, 0, 3, 0, 0, 3};
    const uint32_t indices[] = {0, 2, 1, 0, 3, 2, 0, 4, 3, 0, 5, 4}; /* normal +y */
    scene_error err;
    assert_int_equal(scene__add_mesh(s, "L", positions, 6, indices, 4, NULL, 0, NULL, &err), SCENE_OK);
    scene_rt *rt = fxt_finish_scene(s, 7.3f, 1.0f);
    uint32_t island = fxt_island_of_mesh(s, 0);
    const scene_island *isl = &s->islands[island];
    assert_int_equal(isl->triangle_count, 4);

    for (uint32_t level = 0; level < 2; level++) {
        fxt_island_run run;
        fxt_island_run_init(&run, s, island, level, FX_TRI_LOOKUP);
        uint32_t inside = 0, outside = 0;
        for (uint32_t b = 0; b < run.block_count; b++)
            for (uint32_t t = 0; t < 64; t++) {
                if (!(run.jobs[b].mask >> t & 1))
                    continue;
                double scale = (double)(1u << level);
                double px = ((double)(run.jobs[b].block_x * 8 + (t & 7)) + 0.5) * scale;
                double py = ((double)(run.jobs[b].block_y * 8 + (t >> 3)) + 0.5) * scale;
                uint32_t local;
                float u, v;
                fx_lookup_unpack(run.lookup[64 * b + t], &local, &u, &v);
                assert_true(local < isl->triangle_count);
                uint32_t strictly_in = UINT32_MAX;
                double nearest = INFINITY;
                bool near_edge = false;
                for (uint32_t j = 0; j < isl->triangle_count; j++) {
                    uint32_t tri = s->island_triangles[isl->first + j];
                    assert_int_equal(s->tri_local[tri], j);
                    double w[3];
                    barycentrics(s->tri_island_uv + 6 * tri, px, py, w);
                    double lowest = fmin(w[0], fmin(w[1], w[2]));
                    if (lowest > 1e-7)
                        strictly_in = j;
                    else if (lowest > -1e-7)
                        near_edge = true;
                    nearest = fmin(nearest, triangle_distance(s->tri_island_uv + 6 * tri, px, py));
                }
                const float *uv = s->tri_island_uv + 6 * s->island_triangles[isl->first + local];
                if (strictly_in != UINT32_MAX) {
                    double w[3];
                    barycentrics(uv, px, py, w);
                    assert_int_equal(local, strictly_in);
                    assert_true(fabs(w[1] - u) <= LOOKUP_STEP && fabs(w[2] - v) <= LOOKUP_STEP);
                    inside++;
                } else if (!near_edge) {
                    /* The chosen triangle is a nearest one, and the stored barycentrics name its closest
                     * point (within the quantization of the barycentrics times the edge lengths). */
                    assert_true(triangle_distance(uv, px, py) <= nearest + 1e-9);
                    double qx = (1 - u - v) * uv[0] + u * uv[2] + v * uv[4];
                    double qy = (1 - u - v) * uv[1] + u * uv[3] + v * uv[5];
                    double edges = hypot(uv[2] - uv[0], uv[3] - uv[1]) + hypot(uv[4] - uv[0], uv[5] - uv[1]);
                    assert_true(fabs(hypot(qx - px, qy - py) - nearest) <= edges * LOOKUP_STEP + 1e-6);
                    outside++;
                }
            }
        /* Not vacuous: both kinds occur (the notch and the border are outside). */
        assert_true(inside > 50u >> (2 * level));
        assert_true(outside > 20u >> (2 * level));
        fxt_island_run_free(&run);
    }
    scene_rt_free(rt);
    scene_free(s);
}

/* fx_surface_point maps a texel centre to the world point with those barycentrics, on the plane. */
static void test_surface_point(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "floor", (double[3]){-2, 0.5, -2}, (double[3]){0, 0, 4}, (double[3]){4, 0, 0}, 3);
    scene_rt *rt = fxt_finish_scene(s, 8.0f, 1.0f);
    fxt_island_run run;
    fxt_island_run_init(&run, s, fxt_island_of_mesh(s, 0), 0, FX_TRI_LOOKUP);
    for (uint32_t b = 0; b < run.block_count; b++)
        for (uint32_t t = 0; t < 64; t++) {
            if (!(run.jobs[b].mask >> t & 1))
                continue;
            float pos[3], normal[3];
            texel_centre(s, &run, b, t, pos, normal);
            /* On the floor (clamped into it, even for border texels) with the floor's normal. */
            assert_true(fabsf(pos[1] - 0.5f) < 1e-6f);
            assert_true(pos[0] >= -2.0f - 1e-5f && pos[0] <= 2.0f + 1e-5f);
            assert_true(pos[2] >= -2.0f - 1e-5f && pos[2] <= 2.0f + 1e-5f);
            assert_true(fabsf(normal[1] - 1.0f) < 1e-6f);
        }
    fxt_island_run_free(&run);
    scene_rt_free(rt);
    scene_free(s);
}

/* The AO sample sequence is stratified for any texel hash: the samples 0..15, 16..31 and 0..63 each put
 * exactly one point in every elementary interval of their size (a (0,m,2)-net: 4x4, 2x8, 8x2, 1x16, 16x1
 * cells for 16 points; 8x8, 4x16, 16x4, 2x32 cells for 64), and every value lies in [0, 1). */
static void test_sample_sequence_stratified(void **state)
{
    (void)state;
    for (uint32_t texel = 0; texel < 200; texel++) {
        uint64_t h = fx__hash(9, 0x1234, texel, 0, FX_STREAM_AO_DIRECTION);
        float points[64][2];
        for (uint32_t i = 0; i < 64; i++) {
            fx__sobol_2d(i, h, points[i]);
            assert_true(points[i][0] >= 0 && points[i][0] < 1 && points[i][1] >= 0 && points[i][1] < 1);
        }
        const uint32_t first[3] = {0, 16, 0}, count[3] = {16, 16, 64};
        for (int run = 0; run < 3; run++) {
            uint32_t m = count[run] == 16 ? 4 : 6;
            for (uint32_t xbits = 0; xbits <= m; xbits++) {
                uint32_t cells_x = 1u << xbits, cells_y = 1u << (m - xbits);
                uint8_t hits[64] = {0};
                for (uint32_t i = first[run]; i < first[run] + count[run]; i++) {
                    uint32_t cx = (uint32_t)(points[i][0] * (float)cells_x);
                    uint32_t cy = (uint32_t)(points[i][1] * (float)cells_y);
                    hits[cy * cells_x + cx]++;
                }
                for (uint32_t c = 0; c < count[run]; c++)
                    assert_int_equal(hits[c], 1);
            }
        }
    }
}

/* ---- ambient occlusion --------------------------------------------------------------------------- */

/* Area of the unit disk beyond the line x = a (0 <= a <= 1). */
static double disk_segment(double a)
{
    return acos(a) - a * sqrt(1 - a * a);
}

/* Probability that (x, z) uniform in the unit disk has x > -a and z > -b (a, b >= 0, a^2 + b^2 < 1). */
static double disk_quadrant_open(double a, double b)
{
    /* disk minus {x < -a} minus {z < -b} plus their overlap {x < -a, z < -b} */
    double top = sqrt(1 - b * b);
    double antiderivative_top = 0.5 * (top * sqrt(1 - top * top) + asin(top));
    double antiderivative_a = 0.5 * (a * sqrt(1 - a * a) + asin(a));
    double overlap = antiderivative_top - antiderivative_a - b * (top - a);
    return (PI - disk_segment(a) - disk_segment(b) + overlap) / PI;
}

/* Mean and expected mean of the AO texels of run selected by `expect` (returns NAN to skip a texel). */
typedef double (*ao_expectation)(const float pos[3], double radius);

/* Runs AO to convergence on run, then compares the mean of selected texels with the analytic mean. */
static void check_ao_against(const scene *s, scene_rt *rt, fxt_island_run *run, float radius,
                             ao_expectation expect, const char *what)
{
    fx_context ctx = {.s = s, .rt = rt, .seed = 7, .ao_radius = radius};
    uint64_t rays = fx_ao_update(&ctx, run->jobs, run->block_count, FX_AO_MAX_SAMPLES);
    assert_int_equal(rays, run->texels * FX_AO_MAX_SAMPLES);
    double measured = 0, expected = 0;
    uint64_t texels = 0;
    for (uint32_t b = 0; b < run->block_count; b++)
        for (uint32_t t = 0; t < 64; t++) {
            if (!(run->jobs[b].mask >> t & 1))
                continue;
            assert_int_equal(fx_ao_count(run->jobs[b].payload, t), FX_AO_MAX_SAMPLES);
            float pos[3], normal[3];
            texel_centre(s, run, b, t, pos, normal);
            double e = expect(pos, radius);
            if (isnan(e))
                continue;
            measured += fx_ao_sample(run->jobs[b].payload, t);
            expected += e;
            texels++;
        }
    assert_true(texels >= 100);
    measured /= (double)texels;
    expected /= (double)texels;
    double n = (double)texels * FX_AO_MAX_SAMPLES;
    double tolerance = AO_SIGMAS * sqrt(expected * (1 - expected) / n);
    printf("  %s: %llu texels, AO %.4f, analytic %.4f, tolerance %.4f\n", what, (unsigned long long)texels,
           measured, expected, tolerance);
    assert_true(fabs(measured - expected) <= tolerance);
}

/* Expected AO on the floor in front of the wall x = 0, for texels 0.05..0.4 m from it and |z| < 1. */
static double expect_wall(const float pos[3], double radius)
{
    if (pos[0] < 0.05f || pos[0] > 0.4f || fabsf(pos[2]) > 1.0f)
        return NAN;
    return 1 - disk_segment(pos[0] / radius) / PI;
}

/* Expected AO on the floor in the corner of the walls x = 0 and z = 0, texels 0.05..0.4 m from both. */
static double expect_corner(const float pos[3], double radius)
{
    if (pos[0] < 0.05f || pos[0] > 0.4f || pos[2] < 0.05f || pos[2] > 0.4f)
        return NAN;
    return disk_quadrant_open(pos[0] / radius, pos[2] / radius);
}

/* AO radius of the wall scene. */
#define WALL_RADIUS 4.0f

/* A floor (x in [0, 3], z in [-3, 3]) in front of a wall x = 0 facing it, 10 m high and 12 m wide: for the
 * texels of expect_wall, every ray of length WALL_RADIUS towards the wall hits it (as an infinite wall). */
static scene *wall_scene(scene_rt **rt)
{
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "floor", (double[3]){0, 0, -3}, (double[3]){0, 0, 6}, (double[3]){3, 0, 0}, 2);
    fxt_add_quad(s, "wall", (double[3]){0, 0, -6}, (double[3]){0, 10, 0}, (double[3]){0, 0, 12},
                 2); /* normal +x */
    *rt = fxt_finish_scene(s, 20.0f, WALL_RADIUS);
    return s;
}

/* An open plane: every ray escapes, so AO is exactly 1 with 64 samples in every texel. */
static void test_ao_open_plane(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "floor", (double[3]){-3, 0, -3}, (double[3]){0, 0, 6}, (double[3]){6, 0, 0}, 4);
    scene_rt *rt = fxt_finish_scene(s, 6.0f, 1.0f);
    fxt_island_run run;
    fxt_island_run_init(&run, s, fxt_island_of_mesh(s, 0), 0, FX_AO);
    fx_context ctx = {.s = s, .rt = rt, .seed = 1, .ao_radius = 1.0f};
    assert_int_equal(fx_ao_update(&ctx, run.jobs, run.block_count, 64), run.texels * 64);
    for (uint32_t b = 0; b < run.block_count; b++)
        for (uint32_t t = 0; t < 64; t++)
            if (run.jobs[b].mask >> t & 1) {
                assert_true(fx_ao_sample(run.jobs[b].payload, t) == 1.0f);
                assert_int_equal(fx_ao_count(run.jobs[b].payload, t), 64);
            }
    /* Converged: a further update traces nothing and changes nothing. */
    assert_int_equal(fx_ao_update(&ctx, run.jobs, run.block_count, 16), 0);
    /* The no-cache baseline at a point of the plane: 64 rays, all free. */
    uint64_t rays = 0;
    assert_true(fx_ao_eval_point(&ctx, (float[3]){0.3f, 0, -0.7f}, (float[3]){0, 1, 0}, 64, 99, &rays) ==
                1.0f);
    assert_int_equal(rays, 64);
    fxt_island_run_free(&run);
    scene_rt_free(rt);
    scene_free(s);
}

/* The floor in front of one tall, wide wall: about half the cosine-weighted hemisphere is blocked. */
static void test_ao_wall(void **state)
{
    (void)state;
    scene_rt *rt;
    scene *s = wall_scene(&rt);
    fxt_island_run run;
    fxt_island_run_init(&run, s, fxt_island_of_mesh(s, 0), 0, FX_AO);
    check_ao_against(s, rt, &run, WALL_RADIUS, expect_wall, "wall (about 0.5)");
    fxt_island_run_free(&run);
    scene_rt_free(rt);
    scene_free(s);
}

/* Builds the inside corner of three perpendicular planes: the floor y = 0 (x, z in [0, 1]) and the walls
 * x = 0 and z = 0 (4 x 4 m, beyond the reach of rays of length radius <= 3) facing into the corner. */
static scene *corner_scene(scene_rt **rt, float density, float radius)
{
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "floor", (double[3]){0, 0, 0}, (double[3]){0, 0, 1}, (double[3]){1, 0, 0}, 2);
    fxt_add_quad(s, "wall_x", (double[3]){0, 0, 0}, (double[3]){0, 4, 0}, (double[3]){0, 0, 4}, 2); /* +x */
    fxt_add_quad(s, "wall_z", (double[3]){0, 0, 0}, (double[3]){4, 0, 0}, (double[3]){0, 4, 0}, 2); /* +z */
    *rt = fxt_finish_scene(s, density, radius);
    return s;
}

/* The floor of an inside corner: about a quarter of the hemisphere is open. */
static void test_ao_corner(void **state)
{
    (void)state;
    scene_rt *rt;
    scene *s = corner_scene(&rt, 80.0f, 2.0f);
    fxt_island_run run;
    fxt_island_run_init(&run, s, fxt_island_of_mesh(s, 0), 0, FX_AO);
    check_ao_against(s, rt, &run, 2.0f, expect_corner, "corner (about 0.25)");

    /* The no-cache baseline at one corner point, averaged over many pixels, agrees with the analytic value.
     */
    fx_context ctx = {.s = s, .rt = rt, .seed = 3, .ao_radius = 2.0f};
    double sum = 0;
    const uint32_t pixels = 400;
    for (uint32_t p = 0; p < pixels; p++) {
        uint64_t rays;
        sum += fx_ao_eval_point(&ctx, (float[3]){0.2f, 0, 0.1f}, (float[3]){0, 1, 0}, 64, p, &rays);
        assert_int_equal(rays, 64);
    }
    double expected = disk_quadrant_open(0.1, 0.05), mean = sum / pixels;
    double tolerance = AO_SIGMAS * sqrt(expected * (1 - expected) / (pixels * 64.0));
    assert_true(fabs(mean - expected) <= tolerance);
    fxt_island_run_free(&run);
    scene_rt_free(rt);
    scene_free(s);
}

/* AO payloads do not depend on the budget split (64, 16 x 4, 7 x 10, 1 x 64), the job order, or the
 * batching (one call for all blocks or one per block); another seed gives other payloads. */
static void test_ao_deterministic_budget_split(void **state)
{
    (void)state;
    scene_rt *rt;
    scene *s = corner_scene(&rt, 30.0f, 1.0f);
    uint32_t island = fxt_island_of_mesh(s, 0);
    fx_context ctx = {.s = s, .rt = rt, .seed = 11, .ao_radius = 1.0f};
    fxt_island_run once, split16, split7, single, reversed, other_seed;
    fxt_island_run *runs[] = {&once, &split16, &split7, &single, &reversed, &other_seed};
    for (int r = 0; r < 6; r++)
        fxt_island_run_init(runs[r], s, island, 0, FX_AO);
    size_t bytes = (size_t)once.block_count * 64 * once.texel_bytes;

    fx_ao_update(&ctx, once.jobs, once.block_count, 64);
    for (int frame = 0; frame < 4; frame++)
        fx_ao_update(&ctx, split16.jobs, split16.block_count, 16);
    uint64_t rays7 = 0;
    for (int frame = 0; frame < 10; frame++)
        rays7 += fx_ao_update(&ctx, split7.jobs, split7.block_count, 7);
    assert_int_equal(rays7, once.texels * 64);
    for (int frame = 0; frame < 64; frame++)
        for (uint32_t b = 0; b < single.block_count; b++)
            fx_ao_update(&ctx, &single.jobs[b], 1, 1);
    /* Reversed job order, in calls of three blocks, two frames of 32. */
    fx_block_job *backwards = calloc(reversed.block_count, sizeof *backwards);
    assert_non_null(backwards);
    for (uint32_t b = 0; b < reversed.block_count; b++)
        backwards[b] = reversed.jobs[reversed.block_count - 1 - b];
    for (int frame = 0; frame < 2; frame++)
        for (uint32_t b = 0; b < reversed.block_count; b += 3)
            fx_ao_update(&ctx, backwards + b, reversed.block_count - b < 3 ? reversed.block_count - b : 3,
                         32);
    free(backwards);

    assert_memory_equal(once.payload, split16.payload, bytes);
    assert_memory_equal(once.payload, split7.payload, bytes);
    assert_memory_equal(once.payload, single.payload, bytes);
    assert_memory_equal(once.payload, reversed.payload, bytes);

    /* Not trivially equal: the corner has partly occluded texels, and another seed changes some of them. */
    fx_context other = ctx;
    other.seed = 12;
    fx_ao_update(&other, other_seed.jobs, other_seed.block_count, 64);
    assert_memory_not_equal(once.payload, other_seed.payload, bytes);
    for (int r = 0; r < 6; r++)
        fxt_island_run_free(runs[r]);
    scene_rt_free(rt);
    scene_free(s);
}

/* Stratification: with 16 samples the error of partly occluded texels is well below plain Monte Carlo's. */
static void test_ao_stratified_error(void **state)
{
    (void)state;
    scene_rt *rt;
    scene *s = wall_scene(&rt);
    fxt_island_run run;
    fxt_island_run_init(&run, s, fxt_island_of_mesh(s, 0), 0, FX_AO);
    fx_context ctx = {.s = s, .rt = rt, .seed = 5, .ao_radius = WALL_RADIUS};
    fx_ao_update(&ctx, run.jobs, run.block_count, 16);
    double squared_error = 0, binomial_variance = 0;
    uint64_t texels = 0;
    for (uint32_t b = 0; b < run.block_count; b++)
        for (uint32_t t = 0; t < 64; t++) {
            if (!(run.jobs[b].mask >> t & 1))
                continue;
            float pos[3], normal[3];
            texel_centre(s, &run, b, t, pos, normal);
            double e = expect_wall(pos, WALL_RADIUS);
            if (isnan(e))
                continue;
            double d = fx_ao_sample(run.jobs[b].payload, t) - e;
            squared_error += d * d;
            binomial_variance += e * (1 - e) / 16;
            texels++;
        }
    printf("  16-sample RMSE %.4f vs independent-sample standard error %.4f\n", sqrt(squared_error / texels),
           sqrt(binomial_variance / texels));
    /* Plain Monte Carlo would give mean squared error = binomial variance; demand half of it or less. */
    assert_true(squared_error < 0.5 * binomial_variance);
    fxt_island_run_free(&run);
    scene_rt_free(rt);
    scene_free(s);
}

/* Fixed-point AO saturates: a count beyond 64 in a payload is treated as converged, never wraps. */
static void test_ao_saturation(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "floor", (double[3]){-1, 0, -1}, (double[3]){0, 0, 2}, (double[3]){2, 0, 0}, 1);
    scene_rt *rt = fxt_finish_scene(s, 4.0f, 1.0f);
    fxt_island_run run;
    fxt_island_run_init(&run, s, fxt_island_of_mesh(s, 0), 0, FX_AO);
    memset(run.payload, 0xff, (size_t)run.block_count * 64 * 4); /* count 65535 everywhere */
    fx_context ctx = {.s = s, .rt = rt, .seed = 1, .ao_radius = 1.0f};
    assert_int_equal(fx_ao_update(&ctx, run.jobs, run.block_count, 64), 0);
    /* 60 stored samples, all free: 4 more at most. */
    memset(run.payload, 0, (size_t)run.block_count * 64 * 4);
    for (uint32_t t = 0; t < 64; t++) {
        run.payload[4 * t] = 0xff;
        run.payload[4 * t + 1] = 0xff;
        run.payload[4 * t + 2] = 60;
    }
    uint64_t rays = fx_ao_update(&ctx, run.jobs, 1, 64);
    assert_int_equal(rays, 4 * (uint64_t)__builtin_popcountll(run.jobs[0].mask));
    for (uint32_t t = 0; t < 64; t++)
        if (run.jobs[0].mask >> t & 1) {
            assert_int_equal(fx_ao_count(run.payload, t), 64);
            assert_true(fx_ao_sample(run.payload, t) == 1.0f);
        }
    fxt_island_run_free(&run);
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- shadows --------------------------------------------------------------------------------------- */

/* A floor, a 2 x 2 m square occluder 1 m above it facing down, a sun straight down and a point light 3 m up:
 * texels fully under the occluder are dark for both, texels well outside fully lit; the occluder's own
 * texels face away from both lights: 0 with no ray traced. */
static void test_shadow_occluder(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "floor", (double[3]){-4, 0, -4}, (double[3]){0, 0, 8}, (double[3]){8, 0, 0}, 2);
    fxt_add_quad(s, "occluder", (double[3]){-1, 1, -1}, (double[3]){2, 0, 0}, (double[3]){0, 0, 2},
                 1); /* -y */
    fxt_add_sun(s, 0, -1, 0);
    add_point_light(s, 0, 3, 0);
    scene_rt *rt = fxt_finish_scene(s, 8.0f, 1.0f);
    assert_int_equal(fx_effect_shadow.texel_bytes(s), 4);
    fx_context ctx = {.s = s, .rt = rt, .seed = 2, .ao_radius = 1.0f};

    fxt_island_run floor_run;
    fxt_island_run_init(&floor_run, s, fxt_island_of_mesh(s, 0), 0, FX_SHADOW);
    memset(floor_run.payload, 0xa5, (size_t)floor_run.block_count * 64 * floor_run.texel_bytes);
    assert_int_equal(fx_shadow_update(&ctx, floor_run.jobs, floor_run.block_count),
                     floor_run.texels * FX_SHADOW_RAYS * 2);
    uint32_t dark[2] = {0, 0}, lit[2] = {0, 0};
    /* Half a texel diagonal, plus slack: texel footprints reach this far from their centres. */
    const float reach = 0.75f / 8.0f;
    for (uint32_t b = 0; b < floor_run.block_count; b++)
        for (uint32_t t = 0; t < 64; t++) {
            if (!(floor_run.jobs[b].mask >> t & 1))
                continue;
            float pos[3], normal[3];
            texel_centre(s, &floor_run, b, t, pos, normal);
            float extent = fmaxf(fabsf(pos[0]), fabsf(pos[2]));
            const uint8_t *texel = (const uint8_t *)floor_run.jobs[b].payload + 4 * t;
            uint16_t sun_mask = (uint16_t)(texel[0] | texel[1] << 8);
            uint16_t lamp_mask = (uint16_t)(texel[2] | texel[3] << 8);
            /* Sun: shadow exactly under the occluder. Lamp at 3 m: the umbra reaches 1.5 m. */
            if (extent < 1.0f - reach) {
                assert_int_equal(sun_mask, 0);
                dark[0]++;
            } else if (extent > 1.0f + reach) {
                assert_int_equal(sun_mask, 0xffff);
                assert_true(fx_shadow_sample(floor_run.jobs[b].payload, t, 2, 0) == 1.0f);
                lit[0]++;
            }
            if (extent < 1.5f - reach) {
                assert_int_equal(lamp_mask, 0);
                dark[1]++;
            } else if (extent > 1.5f + reach) {
                assert_int_equal(lamp_mask, 0xffff);
                lit[1]++;
            }
        }
    for (int l = 0; l < 2; l++)
        assert_true(dark[l] > 100 && lit[l] > 1000);

    fxt_island_run occluder_run;
    fxt_island_run_init(&occluder_run, s, fxt_island_of_mesh(s, 1), 0, FX_SHADOW);
    memset(occluder_run.payload, 0xff, (size_t)occluder_run.block_count * 64 * occluder_run.texel_bytes);
    assert_int_equal(fx_shadow_update(&ctx, occluder_run.jobs, occluder_run.block_count), 0);
    for (uint32_t b = 0; b < occluder_run.block_count; b++)
        for (uint32_t t = 0; t < 64; t++)
            if (occluder_run.jobs[b].mask >> t & 1)
                for (uint32_t l = 0; l < 2; l++)
                    assert_true(fx_shadow_sample(occluder_run.jobs[b].payload, t, 2, l) == 0.0f);

    /* The no-cache baseline: under the occluder, in the open, and facing away. */
    float dpdx[3] = {0.01f, 0, 0}, dpdy[3] = {0, 0, 0.01f}, up[3] = {0, 1, 0}, down[3] = {0, -1, 0};
    uint64_t rays;
    assert_true(fx_shadow_eval_point(&ctx, (float[3]){0.2f, 0, -0.3f}, up, dpdx, dpdy, 0, 5, &rays) == 0.0f);
    assert_int_equal(rays, 16);
    assert_true(fx_shadow_eval_point(&ctx, (float[3]){3, 0, 2}, up, dpdx, dpdy, 0, 6, &rays) == 1.0f);
    assert_int_equal(rays, 16);
    assert_true(fx_shadow_eval_point(&ctx, (float[3]){3, 0, 2}, up, dpdx, dpdy, 1, 6, &rays) == 1.0f);
    assert_true(fx_shadow_eval_point(&ctx, (float[3]){0, 1, 0}, down, dpdx, dpdy, 0, 7, &rays) == 0.0f);
    assert_int_equal(rays, 0);

    /* Determinism: reversed job order in single-block calls gives the same bytes. */
    fxt_island_run again;
    fxt_island_run_init(&again, s, fxt_island_of_mesh(s, 0), 0, FX_SHADOW);
    memset(again.payload, 0xa5,
           (size_t)again.block_count * 64 * again.texel_bytes); /* texels outside masks */
    for (uint32_t b = again.block_count; b-- > 0;)
        fx_shadow_update(&ctx, &again.jobs[b], 1);
    assert_memory_equal(again.payload, floor_run.payload, (size_t)again.block_count * 64 * again.texel_bytes);
    fxt_island_run_free(&again);
    fxt_island_run_free(&floor_run);
    fxt_island_run_free(&occluder_run);
    scene_rt_free(rt);
    scene_free(s);
}

/* The effect tables and the registry (the key's effect field is the registry index). */
static void test_describe(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    uint32_t count = 0;
    const fx_effect *const *registry = fx_registry(&count);
    assert_int_equal(count, 4);
    assert_ptr_equal(registry[FX_TRI_LOOKUP], &fx_effect_triangle_lookup);
    assert_ptr_equal(registry[FX_SHADOW], &fx_effect_shadow);
    assert_ptr_equal(registry[FX_AO], &fx_effect_ao);
    const fx_effect *lookup = registry[FX_TRI_LOOKUP], *shadow = registry[FX_SHADOW], *ao = registry[FX_AO];
    assert_string_equal(lookup->name, "triangle_lookup");
    assert_int_equal(lookup->texel_bytes(s), 4);
    assert_int_equal(lookup->policy, FX_UPDATE_ONCE);
    assert_int_equal(lookup->filter, FX_FILTER_POINT);
    assert_null(lookup->shade); /* it shades nothing: it serves the others */
    assert_string_equal(shadow->name, "shadow");
    assert_string_equal(shadow->depends_on, "triangle_lookup");
    assert_int_equal(shadow->texel_bytes(s), 2); /* no light yet: at least 2 */
    fxt_add_sun(s, 0, -1, 0);
    fxt_add_sun(s, 1, -1, 0);
    add_point_light(s, 0, 2, 0);
    assert_int_equal(shadow->texel_bytes(s), 6);
    assert_int_equal(shadow->cost(s, 0), 3 * FX_SHADOW_RAYS);
    assert_string_equal(ao->name, "ao");
    assert_int_equal(ao->texel_bytes(s), 4);
    assert_int_equal(ao->level_bias, 1);
    assert_int_equal(ao->policy, FX_UPDATE_PROGRESSIVE);
    assert_int_equal(ao->max_samples, FX_AO_MAX_SAMPLES);
    assert_int_equal(ao->cost(s, 16), 16);
    /* Names and aliases resolve to registry indices; unknown names do not. */
    assert_int_equal(fx_find(registry, count, "shadows"), FX_SHADOW);
    assert_int_equal(fx_find(registry, count, "ao"), FX_AO);
    assert_int_equal(fx_find(registry, count, "probes"), FX_PROBES);
    assert_int_equal(fx_find(registry, count, "indirect"), FX_PROBES);
    assert_int_equal(fx_find(registry, count, "volumes"), -1);
    const fx_effect *probes = registry[FX_PROBES];
    assert_ptr_equal(probes, &fx_effect_probes);
    assert_int_equal(probes->cache, SCENE_CACHE_WORLD_SPACE);
    assert_int_equal(probes->brick_size, 1);
    assert_int_equal(probes->policy, FX_UPDATE_CONTINUOUS);
    assert_int_equal(probes->texel_bytes(s), FX_PROBE_BYTES);
    assert_true(probes->texel_bytes(s) <= 1024);
    assert_int_equal(probes->cost(s, 0), FX_PROBE_RAYS * 4); /* three lights: a shadow ray each per hit */
    assert_non_null(probes->commit);
    assert_non_null(probes->scratch_bytes);
    /* Light directions: the sun's reversed travel direction; a point light's unit direction and distance. */
    float dir[3], distance;
    fx_light_direction(&s->lights[0], (float[3]){5, 5, 5}, dir, &distance);
    assert_true(dir[1] == 1.0f && isinf(distance));
    fx_light_direction(&s->lights[2], (float[3]){3, 2, 4}, dir, &distance);
    assert_true(fabsf(distance - 5.0f) < 1e-5f && fabsf(dir[0] + 0.6f) < 1e-6f &&
                fabsf(dir[2] + 0.8f) < 1e-6f);
    scene_free(s);
}

/* ---- robustness ------------------------------------------------------------------------------------ */

/* A horizontal and a tilted open plane at `scale` metres around `offset`: AO exactly 1, every shadow bit set
 * for a sun the planes face, and finite surface points. */
static void check_open_planes_at_scale(double scale, double offset)
{
    scene *s = fxt_new_scene();
    double o = offset;
    fxt_add_quad(s, "flat", (double[3]){o - 5 * scale, o, o - 5 * scale}, (double[3]){0, 0, 10 * scale},
                 (double[3]){10 * scale, 0, 0}, 3);
    /* Tilted about two axes, above and beside the flat one (out of its sun rays and AO radius). */
    fxt_add_quad(s, "tilted", (double[3]){o + 30 * scale, o + 20 * scale, o - 2 * scale},
                 (double[3]){1 * scale, 3 * scale, 7 * scale}, (double[3]){6 * scale, 1 * scale, -1 * scale},
                 3);
    fxt_add_sun(s, 0.2f, -1.0f, 0.1f);
    scene_rt *rt = fxt_finish_scene(s, (float)(6.0 / scale), (float)(2.0 * scale));
    fx_context ctx = {.s = s, .rt = rt, .seed = 4, .ao_radius = (float)(2.0 * scale)};
    for (uint32_t mesh = 0; mesh < 2; mesh++) {
        fxt_island_run ao, shadow;
        uint32_t island = fxt_island_of_mesh(s, mesh);
        fxt_island_run_init(&ao, s, island, 0, FX_AO);
        fxt_island_run_init(&shadow, s, island, 0, FX_SHADOW);
        fx_ao_update(&ctx, ao.jobs, ao.block_count, 64);
        uint64_t shadow_rays = fx_shadow_update(&ctx, shadow.jobs, shadow.block_count);
        assert_int_equal(shadow_rays, shadow.texels * 16);
        for (uint32_t b = 0; b < ao.block_count; b++)
            for (uint32_t t = 0; t < 64; t++) {
                if (!(ao.jobs[b].mask >> t & 1))
                    continue;
                float pos[3], normal[3];
                texel_centre(s, &ao, b, t, pos, normal);
                assert_true(isfinite(pos[0]) && isfinite(pos[1]) && isfinite(pos[2]));
                assert_true(fx_ao_sample(ao.jobs[b].payload, t) == 1.0f);
                assert_true(fx_shadow_sample(shadow.jobs[b].payload, t, 1, 0) == 1.0f);
            }
        fxt_island_run_free(&ao);
        fxt_island_run_free(&shadow);
    }
    scene_rt_free(rt);
    scene_free(s);
}

/* Tiny geometry near the origin. */
static void test_robust_small_scale(void **state)
{
    (void)state;
    check_open_planes_at_scale(1e-4, 0.0);
}

/* Huge geometry far from the origin. */
static void test_robust_large_scale_far(void **state)
{
    (void)state;
    check_open_planes_at_scale(1e4, 1e5);
}

/* ---- shadow shading: the fast path for uniform masks against the definition ---------------------------- */

/* splitmix64, and a uniform double in [0, 1) from it. */
static uint64_t shade_rng_next(uint64_t *state)
{
    uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static double shade_rng_unit(uint64_t *state)
{
    return (double)(shade_rng_next(state) >> 11) * 0x1p-53;
}

/* The tap whose texel lies (ox, oy) texels from tap `from`'s, or -1 (the definition's search). */
static int ref_tap_at(const fx_taps *taps, int from, int ox, int oy)
{
    for (uint32_t t = 0; t < taps->count; t++)
        if (fabsf(taps->at_x[from] - (float)ox - taps->at_x[t]) < 0.5f &&
            fabsf(taps->at_y[from] - (float)oy - taps->at_y[t]) < 0.5f)
            return (int)t;
    return -1;
}

static float ref_lit_fraction(uint32_t mask)
{
    return (float)__builtin_popcount(mask & 0xFFFFu) * (1.0f / FX_SHADOW_RAYS);
}

/* The shadow shading of one pixel and light as DESIGN.md defines it, every cell looked up: the reference the
 * shade callback (which skips the lookup when the taps' masks are uniform) must equal bit for bit. */
static float ref_shadow_visibility(const fx_taps *taps, uint32_t lights, uint32_t l)
{
    float lit_average = 0;
    for (uint32_t t = 0; t < taps->count; t++)
        lit_average +=
            taps->weight[t] * ref_lit_fraction(fx__get_u16((const uint8_t *)taps->texel[t] + 2u * l));
    (void)lights;
    if (taps->footprint_log2 >= 0.0f)
        return fminf(lit_average, 1.0f);
    int home = 0;
    for (uint32_t t = 0; t < taps->count; t++) {
        if (taps->at_x[t] >= 0 && taps->at_x[t] < 1 && taps->at_y[t] >= 0 && taps->at_y[t] < 1) {
            home = (int)t;
            break;
        }
        if (taps->weight[t] > taps->weight[home])
            home = (int)t;
    }
    float fx = taps->at_x[home] * 4.0f - 0.5f, fy = taps->at_y[home] * 4.0f - 0.5f;
    float cx0 = floorf(fx), cy0 = floorf(fy);
    float wx = fx - cx0, wy = fy - cy0;
    float fine = 0;
    for (int c = 0; c < 4; c++) {
        int cx = (int)cx0 + (c & 1), cy = (int)cy0 + (c >> 1);
        int ox = cx < 0 ? -1 : (cx > 3 ? 1 : 0), oy = cy < 0 ? -1 : (cy > 3 ? 1 : 0);
        int t = (ox || oy) ? ref_tap_at(taps, home, ox, oy) : home;
        if (t < 0) {
            t = home;
            ox = oy = 0;
            cx = cx < 0 ? 0 : (cx > 3 ? 3 : cx);
            cy = cy < 0 ? 0 : (cy > 3 ? 3 : cy);
        }
        uint32_t mask = fx__get_u16((const uint8_t *)taps->texel[t] + 2u * l);
        uint32_t bit = (uint32_t)((cy - 4 * oy) * 4 + (cx - 4 * ox));
        fine += (((c & 1) ? wx : 1 - wx) * ((c >> 1) ? wy : 1 - wy)) * (float)((mask >> bit) & 1u);
    }
    float coarse = exp2f(taps->footprint_log2);
    float average = coarse > 0 ? lit_average : 0.0f;
    return fminf(fine + coarse * (average - fine), 1.0f);
}

/* Random pixels over random masks (a third of them all lit, a third all shadowed, the rest random, per tap
 * and light; a tenth of the pixels all shadowed for every tap and light; taps dropped at random as texels
 * without data are; a fiftieth of the footprints NaN): the shade callback gives the reference's floats
 * exactly, through both its paths and its four-tap shortcuts. */
static void test_shadow_shade_uniform_masks(void **state)
{
    (void)state;
    enum { PIXELS = 64, LIGHTS = 2, ROUNDS = 400 };
    uint64_t rng = 0x243F6A8885A308D3ull;
    uint8_t payload[PIXELS][4][2 * LIGHTS];
    fx_taps taps[PIXELS];
    float visibility[PIXELS * LIGHTS], sky[PIXELS], indirect[PIXELS * 3];
    uint32_t uniform = 0, mixed = 0, four_dark = 0, all_dark = 0, coarse_dark = 0;
    for (int round = 0; round < ROUNDS; round++) {
        const int lights = 1 + round % LIGHTS; /* one light (the usual scene) and two */
        for (int i = 0; i < PIXELS; i++) {
            fx_taps *tp = &taps[i];
            float px = (float)shade_rng_unit(&rng) * 3.0f + 0.5f,
                  py = (float)shade_rng_unit(&rng) * 3.0f + 0.5f;
            float x = px - 0.5f, y = py - 0.5f, ax = x - floorf(x), ay = y - floorf(y);
            float tx0 = floorf(x), ty0 = floorf(y), total = 0;
            tp->count = 0;
            bool dark = shade_rng_unit(&rng) < 0.1; /* every tap wholly shadowed for every light */
            for (int t = 0; t < 4; t++) {
                float weight = ((t & 1) ? ax : 1 - ax) * ((t >> 1) ? ay : 1 - ay);
                if (shade_rng_unit(&rng) < 0.15 || !(weight > 0))
                    continue; /* no data there */
                uint32_t n = tp->count++;
                for (int l = 0; l < lights; l++) {
                    double pick = shade_rng_unit(&rng);
                    uint32_t mask =
                        pick < 0.33 ? 0xFFFFu
                                    : (pick < 0.66 ? 0u : (uint32_t)(shade_rng_next(&rng) >> 20) & 0xFFFFu);
                    mask = dark ? 0u : mask;
                    payload[i][n][2 * l] = (uint8_t)(mask & 0xFF);
                    payload[i][n][2 * l + 1] = (uint8_t)(mask >> 8);
                }
                tp->texel[n] = payload[i][n];
                tp->weight[n] = weight;
                tp->at_x[n] = px - (tx0 + (float)(t & 1));
                tp->at_y[n] = py - (ty0 + (float)(t >> 1));
                total += weight;
            }
            for (uint32_t t = 0; t < tp->count; t++)
                tp->weight[t] *= 1.0f / total;
            tp->footprint_log2 = (float)shade_rng_unit(&rng) * 4.0f - 3.5f;
            if (shade_rng_unit(&rng) < 0.02)
                tp->footprint_log2 = NAN; /* the blend's weight not a number: the definition's exp2f */
            all_dark += tp->count == 4 && tp->footprint_log2 < 0 && dark;
            coarse_dark += tp->count == 4 && tp->footprint_log2 >= 0 && dark;
            for (int l = 0; l < lights; l++) {
                visibility[i * lights + l] = 1.0f;
                uint32_t any = 0, all = 0xFFFFu;
                for (uint32_t t = 0; t < tp->count; t++) {
                    any |= fx__get_u16(payload[i][t] + 2 * l);
                    all &= fx__get_u16(payload[i][t] + 2 * l);
                }
                if (tp->count && tp->footprint_log2 < 0)
                    (any == 0 || all == 0xFFFFu) ? uniform++ : mixed++;
                four_dark += tp->count == 4 && tp->footprint_log2 < 0 && any == 0;
            }
        }
        fx_shade_run run = {.count = PIXELS,
                            .light_count = (uint32_t)lights,
                            .taps = taps,
                            .light_visibility = visibility,
                            .sky_visibility = sky,
                            .indirect = indirect};
        fx_effect_shadow.shade(NULL, &run);
        for (int i = 0; i < PIXELS; i++)
            for (uint32_t l = 0; l < (uint32_t)lights; l++) {
                float expected = taps[i].count ? ref_shadow_visibility(&taps[i], (uint32_t)lights, l) : 1.0f;
                float got = visibility[i * lights + (int)l];
                if (memcmp(&expected, &got, sizeof got) != 0)
                    fail_msg("round %d pixel %d light %u: %.9g, the definition %.9g", round, i, l,
                             (double)got, (double)expected);
            }
    }
    assert_true(uniform > 1000 && mixed > 1000);                        /* both paths taken many times */
    assert_true(four_dark > 100 && all_dark > 500 && coarse_dark > 50); /* the wholly shadowed shortcuts */
}

/* AO shading reads a texel's fraction with a multiply: the same float as fx_ao_sample (a division) for
 * every stored value, and the shade callback gives the weighted sum of fx_ao_sample's, clamped to 1. */
static void test_ao_fraction_every_value(void **state)
{
    (void)state;
    for (uint32_t n = 0; n <= 65535; n++) {
        uint8_t texel[4] = {(uint8_t)(n & 0xFF), (uint8_t)(n >> 8), 64, 0};
        float a = fx__unorm16(n), b = fx_ao_sample(texel, 0);
        if (memcmp(&a, &b, sizeof a) != 0)
            fail_msg("%u: %.9g against fx_ao_sample's %.9g", n, (double)a, (double)b);
    }
    uint8_t payload[4][4];
    const uint16_t values[4] = {65535, 12345, 40000, 1};
    fx_taps taps = {.count = 4, .weight = {0.1f, 0.2f, 0.3f, 0.4f}};
    for (int t = 0; t < 4; t++) {
        payload[t][0] = (uint8_t)(values[t] & 0xFF), payload[t][1] = (uint8_t)(values[t] >> 8);
        taps.texel[t] = payload[t];
    }
    float sky = 0.5f, expected = 0;
    for (int t = 0; t < 4; t++)
        expected += taps.weight[t] * fx_ao_sample(payload[t], 0);
    fx_shade_run run = {.count = 1, .taps = &taps, .sky_visibility = &sky};
    fx_effect_ao.shade(NULL, &run);
    assert_true(sky == 0.5f * expected);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_lookup_pack_roundtrip),
        cmocka_unit_test(test_lookup_inside_and_nearest),
        cmocka_unit_test(test_surface_point),
        cmocka_unit_test(test_describe),
        cmocka_unit_test(test_sample_sequence_stratified),
        cmocka_unit_test(test_ao_open_plane),
        cmocka_unit_test(test_ao_wall),
        cmocka_unit_test(test_ao_corner),
        cmocka_unit_test(test_ao_deterministic_budget_split),
        cmocka_unit_test(test_ao_stratified_error),
        cmocka_unit_test(test_ao_saturation),
        cmocka_unit_test(test_shadow_occluder),
        cmocka_unit_test(test_shadow_shade_uniform_masks),
        cmocka_unit_test(test_ao_fraction_every_value),
        cmocka_unit_test(test_robust_small_scale),
        cmocka_unit_test(test_robust_large_scale_far),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
