/* Tests of the island builder (scene/scene_islands.c, scene/topology_openmesh.cpp).
 *
 * Every scene built here goes through check_island_invariants(), which verifies what DESIGN.md promises
 * about islands from the outputs alone, with exact arithmetic where it matters:
 *   - every triangle is in exactly one island, at most 256 per island, all from the island's mesh;
 *   - island sizes fit 12-bit block coordinates (width, height <= 32768 texels, border included);
 *   - every corner UV lies inside the one-texel border [1, width-1] x [1, height-1];
 *   - every projected triangle has positive signed area (no fold, one orientation), exactly;
 *   - no level-0 texel centre is covered by two triangles of one island (texel centres rasterised with a
 *     top-left tie rule, edge functions evaluated exactly in 128-bit integers);
 *   - UV area / world area per island is density^2 times a factor in [ISLAND_TEST_MIN_COS, 1]: the
 *     projection foreshortening the builder allows (normals within acos(0.9) = 25.8 degrees of the
 *     island's projection normal), plus the 1/256-texel snapping of corners, bounded per triangle by its UV
 *     perimeter / 128 texel^2.
 * Real meshes come from Debian (bunny) and ../shared/scenes (skipped with a message when absent); the
 * hand-built meshes exercise non-manifold fans, bow-ties, slivers, size splits, a too-high density, folds
 * (cube), curvature (sphere) and projection overlap (helical ramp). */
#include "test_util.h"

#include "scene.h"
#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The normal bound the builder promises (cos of the largest angle between a triangle and its island). */
#define ISLAND_TEST_MIN_COS 0.9
/* Fixed-point scale for exact UV arithmetic: a float in [1, 32768] is a multiple of 2^-23. */
#define UV_FIXED_SCALE 8388608.0
/* Largest island bounding box (texels) whose coverage bitmap the test allocates. */
#define COVERAGE_MAX_TEXELS ((uint64_t)1 << 28)

__extension__ typedef __int128 exact_int;

/* What check_island_invariants() measured, for assertions specific to a mesh. */
typedef struct island_report {
    uint32_t island_count;
    uint32_t largest_island; /* most triangles in one island */
    uint32_t single_islands; /* islands of one triangle */
    uint32_t widest;         /* largest width or height, texels */
    uint64_t texels_covered; /* texel centres claimed by some triangle */
    double worst_area_ratio; /* smallest (UV area / (density^2 * world area)) over islands with area */
} island_report;

/* A UV coordinate as an exact integer multiple of 2^-23; fails the test if it is not one. */
static int64_t uv_fixed(float value)
{
    double scaled = (double)value * UV_FIXED_SCALE;
    assert_true(scaled == floor(scaled));
    return (int64_t)scaled;
}

/* Exact twice-signed-area of three fixed-point points. */
static exact_int orient_exact(const int64_t a[2], const int64_t b[2], const int64_t c[2])
{
    return (exact_int)(b[0] - a[0]) * (c[1] - a[1]) - (exact_int)(b[1] - a[1]) * (c[0] - a[0]);
}

/* Whether a point exactly on edge a->b (of a counter-clockwise triangle) belongs to the triangle: the
 * top-left rule, i.e. the point nudged by (eps, eps^2) is inside. Consistent for any set of triangles with
 * disjoint interiors, so a texel centre is claimed at most once. */
static bool edge_owns_ties(const int64_t a[2], const int64_t b[2])
{
    int64_t dx = b[0] - a[0], dy = b[1] - a[1];
    return dy < 0 || (dy == 0 && dx > 0);
}

/* Marks the texel centres of triangle uv (6 floats) in the island bitmap; fails on a centre already set. */
static uint64_t rasterise_triangle(const float *uv, uint32_t width, uint32_t height, uint8_t *bitmap,
                                   uint32_t island, uint32_t triangle)
{
    int64_t p[3][2];
    for (int k = 0; k < 3; k++) {
        p[k][0] = uv_fixed(uv[2 * k]);
        p[k][1] = uv_fixed(uv[2 * k + 1]);
    }
    float umin = fminf(uv[0], fminf(uv[2], uv[4])), umax = fmaxf(uv[0], fmaxf(uv[2], uv[4]));
    float vmin = fminf(uv[1], fminf(uv[3], uv[5])), vmax = fmaxf(uv[1], fmaxf(uv[3], uv[5]));
    int64_t x0 = (int64_t)floorf(umin - 0.5f), x1 = (int64_t)ceilf(umax), y0 = (int64_t)floorf(vmin - 0.5f),
            y1 = (int64_t)ceilf(vmax);
    if (x0 < 0)
        x0 = 0;
    if (y0 < 0)
        y0 = 0;
    if (x1 > (int64_t)width - 1)
        x1 = (int64_t)width - 1;
    if (y1 > (int64_t)height - 1)
        y1 = (int64_t)height - 1;
    bool owns[3];
    for (int e = 0; e < 3; e++)
        owns[e] = edge_owns_ties(p[e], p[(e + 1) % 3]);
    const int64_t half = (int64_t)(UV_FIXED_SCALE / 2), step = (int64_t)UV_FIXED_SCALE;
    uint64_t claimed = 0;
    for (int64_t y = y0; y <= y1; y++) {
        int64_t centre[2] = {x0 * step + half, y * step + half};
        exact_int edge_value[3];
        for (int e = 0; e < 3; e++)
            edge_value[e] = orient_exact(p[e], p[(e + 1) % 3], centre);
        for (int64_t x = x0; x <= x1; x++) {
            bool inside = true;
            for (int e = 0; e < 3; e++)
                inside = inside && (edge_value[e] > 0 || (edge_value[e] == 0 && owns[e]));
            if (inside) {
                uint64_t bit = (uint64_t)y * width + (uint64_t)x;
                if (bitmap[bit >> 3] & (1u << (bit & 7)))
                    fail_msg("island %u: texel (%lld, %lld) covered twice (second: triangle %u)", island,
                             (long long)x, (long long)y, triangle);
                bitmap[bit >> 3] |= (uint8_t)(1u << (bit & 7));
                claimed++;
            }
            /* One texel to the right: each edge function changes by -(dy) * step. */
            for (int e = 0; e < 3; e++)
                edge_value[e] -= (exact_int)(p[(e + 1) % 3][1] - p[e][1]) * step;
        }
    }
    return claimed;
}

/* Checks every island invariant listed at the top of this file; returns what it measured. */
static island_report check_island_invariants(const scene *s)
{
    island_report report = {0};
    report.worst_area_ratio = INFINITY;
    uint32_t n = s->triangle_count;
    assert_true(s->island_count >= 1 || n == 0);
    assert_non_null(s->islands);
    assert_non_null(s->island_triangles);
    assert_non_null(s->tri_island);
    assert_non_null(s->tri_local);
    assert_non_null(s->tri_island_uv);
    uint8_t *seen = calloc(n ? n : 1, 1);
    assert_non_null(seen);
    uint8_t *bitmap = NULL;
    size_t bitmap_bytes = 0;
    double density2 = (double)s->texel_density * s->texel_density;
    uint64_t total = 0;
    report.island_count = s->island_count;

    for (uint32_t i = 0; i < s->island_count; i++) {
        const scene_island *island = &s->islands[i];
        assert_true(island->triangle_count >= 1 && island->triangle_count <= SCENE_ISLAND_MAX_TRIANGLES);
        assert_true((uint64_t)island->first + island->triangle_count <= n);
        assert_true(island->width >= 3 && island->height >= 3);
        assert_true(island->width <= SCENE_MAX_ISLAND_TEXELS && island->height <= SCENE_MAX_ISLAND_TEXELS);
        assert_true((island->width + SCENE_BLOCK_TEXELS - 1) / SCENE_BLOCK_TEXELS <= SCENE_MAX_BLOCKS);
        assert_true((island->height + SCENE_BLOCK_TEXELS - 1) / SCENE_BLOCK_TEXELS <= SCENE_MAX_BLOCKS);
        if (s->mesh_count)
            assert_true(island->mesh < s->mesh_count);
        total += island->triangle_count;
        if (island->triangle_count > report.largest_island)
            report.largest_island = island->triangle_count;
        if (island->triangle_count == 1)
            report.single_islands++;
        if (island->width > report.widest)
            report.widest = island->width;
        if (island->height > report.widest)
            report.widest = island->height;

        uint64_t box_texels = (uint64_t)island->width * island->height;
        bool rasterise = box_texels <= COVERAGE_MAX_TEXELS;
        if (rasterise) {
            size_t need = (size_t)((box_texels + 7) / 8);
            if (need > bitmap_bytes) {
                free(bitmap);
                bitmap = malloc(need);
                assert_non_null(bitmap);
                bitmap_bytes = need;
            }
            memset(bitmap, 0, need);
        } else {
            printf("note: island %u (%u x %u texels) too large for the coverage check\n", i, island->width,
                   island->height);
        }

        double uv_area = 0, area = 0, slack = 0;
        for (uint32_t slot = 0; slot < island->triangle_count; slot++) {
            uint32_t t = s->island_triangles[island->first + slot];
            assert_true(t < n);
            if (seen[t])
                fail_msg("triangle %u appears in two islands", t);
            seen[t] = 1;
            assert_int_equal(s->tri_island[t], i);
            assert_int_equal(s->tri_local[t], slot);
            assert_int_equal(s->tri_mesh[t], island->mesh);
            const float *uv = s->tri_island_uv + 6 * (size_t)t;
            for (int k = 0; k < 3; k++) {
                if (!(uv[2 * k] >= 1.0f && uv[2 * k] <= (float)island->width - 1.0f &&
                      uv[2 * k + 1] >= 1.0f && uv[2 * k + 1] <= (float)island->height - 1.0f))
                    fail_msg("island %u (%u x %u): triangle %u corner %d at (%g, %g) is outside the border",
                             i, island->width, island->height, t, k, (double)uv[2 * k],
                             (double)uv[2 * k + 1]);
            }
            int64_t p[3][2];
            for (int k = 0; k < 3; k++) {
                p[k][0] = uv_fixed(uv[2 * k]);
                p[k][1] = uv_fixed(uv[2 * k + 1]);
            }
            if (!(orient_exact(p[0], p[1], p[2]) > 0))
                fail_msg("island %u: triangle %u is folded or flat in UV", i, t);
            double tri_uv_area = 0.5 * (((double)uv[2] - uv[0]) * ((double)uv[5] - uv[1]) -
                                        ((double)uv[3] - uv[1]) * ((double)uv[4] - uv[0]));
            double perimeter = 0;
            for (int k = 0; k < 3; k++) {
                double du = (double)uv[2 * ((k + 1) % 3)] - uv[2 * k];
                double dv = (double)uv[2 * ((k + 1) % 3) + 1] - uv[2 * k + 1];
                perimeter += sqrt(du * du + dv * dv);
            }
            uv_area += tri_uv_area;
            area += scene_triangle_area(s, t);
            slack += perimeter / 128.0;
            if (rasterise)
                report.texels_covered += rasterise_triangle(uv, island->width, island->height, bitmap, i, t);
        }
        double expected = density2 * area;
        if (!(uv_area >= ISLAND_TEST_MIN_COS * expected * (1 - 1e-5) - slack &&
              uv_area <= expected * (1 + 1e-5) + slack))
            fail_msg(
                "island %u: UV area %.6g texels^2 for world area %.6g m^2 at density %g (expected %.6g..%.6g "
                "+- %.3g)",
                i, uv_area, area, (double)s->texel_density, ISLAND_TEST_MIN_COS * expected, expected, slack);
        if (expected > 100 * slack && uv_area / expected < report.worst_area_ratio)
            report.worst_area_ratio = uv_area / expected;
    }
    assert_int_equal(total, n);
    for (uint32_t t = 0; t < n; t++)
        if (!seen[t])
            fail_msg("triangle %u is in no island", t);
    free(seen);
    free(bitmap);
    return report;
}

/* Prints a one-line summary of a scene's islands. */
static void print_report(const char *what, const scene *s, const island_report *r)
{
    printf("%s: %u triangles -> %u islands (largest %u triangles, %u single, widest %u texels), density %g, "
           "%llu texels covered, worst area ratio %.4f, %llu split off, islands %.1f ms\n",
           what, s->triangle_count, r->island_count, r->largest_island, r->single_islands, r->widest,
           (double)s->texel_density, (unsigned long long)r->texels_covered, r->worst_area_ratio,
           (unsigned long long)s->repairs.nonmanifold_split, s->timings.islands_ms);
}

/* ---- hand-built scenes ----------------------------------------------------------------------------- */

/* A scene filled by hand (no welding, no filtering), one mesh, islands built at the given density.
 * Returns the scene; *rc receives the result of scene__build_islands, err its message. */
static scene *hand_scene(const float *positions, uint32_t vertex_count, const uint32_t *indices,
                         uint32_t triangle_count, float density, scene_result *rc, scene_error *err)
{
    scene *s = calloc(1, sizeof *s);
    assert_non_null(s);
    snprintf(s->source, sizeof s->source, "(test)");
    s->vertex_count = vertex_count;
    s->triangle_count = triangle_count;
    s->positions = malloc(sizeof(float) * 3 * vertex_count);
    s->indices = malloc(sizeof(uint32_t) * 3 * triangle_count);
    s->tri_mesh = calloc(triangle_count, sizeof(uint32_t));
    s->tri_normal = malloc(sizeof(float) * 3 * triangle_count);
    s->meshes = calloc(1, sizeof(scene_mesh));
    assert_true(s->positions && s->indices && s->tri_mesh && s->tri_normal && s->meshes);
    memcpy(s->positions, positions, sizeof(float) * 3 * vertex_count);
    memcpy(s->indices, indices, sizeof(uint32_t) * 3 * triangle_count);
    s->mesh_count = 1;
    snprintf(s->meshes[0].name, sizeof s->meshes[0].name, "hand");
    s->meshes[0].triangle_count = triangle_count;
    for (uint32_t t = 0; t < triangle_count; t++) {
        const float *a = positions + 3 * (size_t)indices[3 * t],
                    *b = positions + 3 * (size_t)indices[3 * t + 1],
                    *c = positions + 3 * (size_t)indices[3 * t + 2];
        double e1[3], e2[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = (double)b[k] - a[k];
            e2[k] = (double)c[k] - a[k];
        }
        double nx = e1[1] * e2[2] - e1[2] * e2[1], ny = e1[2] * e2[0] - e1[0] * e2[2],
               nz = e1[0] * e2[1] - e1[1] * e2[0];
        double len = sqrt(nx * nx + ny * ny + nz * nz);
        float *out = s->tri_normal + 3 * (size_t)t;
        out[0] = len > 0 ? (float)(nx / len) : 0.0f;
        out[1] = len > 0 ? (float)(ny / len) : 0.0f;
        out[2] = len > 0 ? (float)(nz / len) : 1.0f;
    }
    s->texel_density = density;
    double t0 = scene__now_ms();
    *rc = scene__build_islands(s, err);
    s->timings.islands_ms = scene__now_ms() - t0;
    return s;
}

/* Three and four triangles on one edge: OpenMesh refuses the extra ones, which become islands alone. */
static void test_nonmanifold_fan(void **state)
{
    (void)state;
    static const float p[] = {0, 0, 0, 1, 0, 0, 0.5f, 1, 0, 0.5f, -1, 0, 0.5f, 0, 1, 0.5f, 0, -1};
    static const uint32_t idx[] = {0, 1, 2, 1, 0, 3, 0, 1, 4, 1, 0, 5};
    scene_error err = {0};
    scene_result rc;
    scene *s = hand_scene(p, 6, idx, 4, 20.0f, &rc, &err);
    assert_int_equal(rc, SCENE_OK);
    island_report r = check_island_invariants(s);
    print_report("non-manifold fan", s, &r);
    assert_int_equal(s->repairs.nonmanifold_split, 2);
    assert_int_equal(s->islands[s->tri_island[2]].triangle_count, 1);
    assert_int_equal(s->islands[s->tri_island[3]].triangle_count, 1);
    /* The two accepted triangles are coplanar and share edge 0-1: one island. */
    assert_int_equal(s->tri_island[0], s->tri_island[1]);
    assert_int_equal(r.island_count, 3);
    scene_free(s);
}

/* The same fan through the builder users use: scene__alloc, scene__add_mesh, scene__finalize. */
static void test_nonmanifold_fan_through_builder(void **state)
{
    (void)state;
    static const float p[] = {0, 0, 0, 1, 0, 0, 0.5f, 1, 0, 0.5f, -1, 0, 0.5f, 0, 1, 0.5f, 0, -1};
    static const uint32_t idx[] = {0, 1, 2, 1, 0, 3, 0, 1, 4, 1, 0, 5};
    scene_error err = {0};
    scene *s = scene__alloc();
    assert_non_null(s);
    scene_material material = {.diffuse = {0.5f, 0.5f, 0.5f}, .texture = -1, .name = "grey"};
    scene__add_material(s, &material, &err);
    assert_int_equal(scene__add_mesh(s, "fan", p, 6, idx, 4, NULL, 0, NULL, &err), SCENE_OK);
    scene_load_desc desc = {.texel_density = 20.0f};
    scene_result rc = scene__finalize(s, &desc, &err);
    if (rc != SCENE_OK)
        fail_msg("finalize: %s", err.msg);
    island_report r = check_island_invariants(s);
    print_report("non-manifold fan (builder)", s, &r);
    assert_int_equal(s->repairs.nonmanifold_split, 2);
    scene_free(s);
}

/* Two fans touching in one vertex (a bow-tie), plus a second pair whose projections overlap. */
static void test_bowtie(void **state)
{
    (void)state;
    static const float p[] = {
        0,  0,    0,                                       /* 0: the shared vertex */
        1,  0,    0,     1,  1,    0,     0,    1,  0,     /* 1..3: first fan */
        -1, 0,    0,     -1, -1,   0,     0,    -1, 0,     /* 4..6: second fan, opposite quadrant */
        1,  0.2f, 0.05f, 1,  1.2f, 0.05f, 0.2f, 1,  0.05f, /* 7..9: a third fan over the first one */
    };
    static const uint32_t idx[] = {0, 1, 2, 0, 2, 3, 0, 4, 5, 0, 5, 6, 0, 7, 8, 0, 8, 9};
    scene_error err = {0};
    scene_result rc;
    scene *s = hand_scene(p, 10, idx, 6, 50.0f, &rc, &err);
    assert_int_equal(rc, SCENE_OK);
    island_report r = check_island_invariants(s);
    print_report("bow-tie", s, &r);
    /* The three fans are not edge-connected: three islands of two triangles. */
    assert_int_equal(r.island_count, 3);
    assert_int_equal(r.largest_island, 2);
    scene_free(s);
}

/* Needle triangles, a collinear (zero-area) triangle and one with a repeated corner: no crash, valid
 * islands; slivers too thin for the 1/256-texel grid end up alone. */
static void test_slivers(void **state)
{
    (void)state;
    enum { NEEDLES = 20 };
    float p[3 * (NEEDLES + 2 + 6)];
    uint32_t idx[3 * (NEEDLES + 2 + 4)];
    uint32_t v = 0, t = 0;
    p[3 * v] = 0, p[3 * v + 1] = 0, p[3 * v + 2] = 0, v++;
    for (int k = 0; k <= NEEDLES; k++, v++) {
        p[3 * v] = 1.0f;
        p[3 * v + 1] = (float)k * 1e-6f;
        p[3 * v + 2] = 0;
    }
    for (uint32_t k = 0; k < NEEDLES; k++, t++) {
        idx[3 * t] = 0;
        idx[3 * t + 1] = 1 + k;
        idx[3 * t + 2] = 2 + k;
    }
    /* Two ordinary triangles next to the needles, sharing the first needle's long edge. */
    uint32_t base = v;
    static const float quad[] = {0, -1, 0, 1, -1, 0};
    memcpy(p + 3 * v, quad, sizeof quad);
    v += 2;
    idx[3 * t] = 0, idx[3 * t + 1] = base, idx[3 * t + 2] = 1, t++;
    idx[3 * t] = base, idx[3 * t + 1] = base + 1, idx[3 * t + 2] = 1, t++;
    /* Collinear triangle and a repeated corner (should have been filtered; must not crash). */
    static const float line[] = {5, 0, 0, 6, 0, 0, 7, 0, 0, 5, 1, 0};
    memcpy(p + 3 * v, line, sizeof line);
    idx[3 * t] = v, idx[3 * t + 1] = v + 1, idx[3 * t + 2] = v + 2, t++;
    idx[3 * t] = v, idx[3 * t + 1] = v, idx[3 * t + 2] = v + 3, t++;
    v += 4;

    scene_error err = {0};
    scene_result rc;
    scene *s = hand_scene(p, v, idx, t, 100.0f, &rc, &err);
    if (rc != SCENE_OK)
        fail_msg("%s", err.msg);
    island_report r = check_island_invariants(s);
    print_report("slivers", s, &r);
    /* Each needle is 1e-4 texel wide at this density: below the grid, so each stands alone (the first one
     * seeds the chart the two ordinary triangles join, across its long edge). */
    for (uint32_t k = 1; k < NEEDLES; k++)
        assert_int_equal(s->islands[s->tri_island[k]].triangle_count, 1);
    assert_int_equal(s->tri_island[NEEDLES], s->tri_island[NEEDLES + 1]);
    assert_true(s->repairs.nonmanifold_split >= 1); /* the repeated corner */
    scene_free(s);
}

/* A strip 200 m long at 500 texels/m (100,000 texels) must be cut into islands of at most 32768 texels. */
static void test_long_strip_split_for_size(void **state)
{
    (void)state;
    enum { QUADS = 100 };
    float p[3 * 2 * (QUADS + 1)];
    uint32_t idx[3 * 2 * QUADS];
    for (int k = 0; k <= QUADS; k++) {
        float x = 2.0f * (float)k;
        float *a = p + 6 * k;
        a[0] = x, a[1] = 0, a[2] = 0;
        a[3] = x, a[4] = 0.1f, a[5] = 0;
    }
    for (uint32_t k = 0; k < QUADS; k++) {
        uint32_t *q = idx + 6 * k;
        uint32_t b0 = 2 * k, t0 = 2 * k + 1, b1 = 2 * k + 2, t1 = 2 * k + 3;
        q[0] = b0, q[1] = b1, q[2] = t1;
        q[3] = b0, q[4] = t1, q[5] = t0;
    }
    scene_error err = {0};
    scene_result rc;
    scene *s = hand_scene(p, 2 * (QUADS + 1), idx, 2 * QUADS, 500.0f, &rc, &err);
    if (rc != SCENE_OK)
        fail_msg("%s", err.msg);
    island_report r = check_island_invariants(s);
    print_report("long strip", s, &r);
    assert_true(r.island_count >= 4);
    assert_true(r.widest > SCENE_MAX_ISLAND_TEXELS / 2); /* split for size, not into crumbs */
    scene_free(s);
}

/* A 1 m triangle at 40,000 texels/m cannot fit one island: SCENE_ERR_RANGE naming mesh, triangle, density. */
static void test_density_too_high(void **state)
{
    (void)state;
    static const float p[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0.01f, 0.01f, 0, 0.02f, 0.01f, 0};
    static const uint32_t idx[] = {0, 3, 4, 0, 1, 2};
    scene_error err = {0};
    scene_result rc;
    scene *s = hand_scene(p, 5, idx, 2, 40000.0f, &rc, &err);
    assert_int_equal(rc, SCENE_ERR_RANGE);
    assert_int_equal(err.code, SCENE_ERR_RANGE);
    printf("expected failure: %s\n", err.msg);
    assert_non_null(strstr(err.msg, "'hand'"));
    assert_non_null(strstr(err.msg, "triangle 1"));
    assert_non_null(strstr(err.msg, "40000"));
    assert_null(strchr(err.msg, '\n'));
    assert_int_equal(s->island_count, 0);
    assert_null(s->islands);
    /* The same mesh at a density that fits works. */
    s->texel_density = 20000.0f;
    assert_int_equal(scene__build_islands(s, &err), SCENE_OK);
    check_island_invariants(s);
    scene_free(s);
}

/* A closed unit cube: every edge between faces is a 90-degree fold, so exactly one island per face. */
static void test_cube(void **state)
{
    (void)state;
    static const float p[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1};
    static const uint32_t idx[] = {
        0, 2, 1, 0, 3, 2, /* z = 0, facing -z */
        4, 5, 6, 4, 6, 7, /* z = 1 */
        0, 1, 5, 0, 5, 4, /* y = 0 */
        3, 7, 6, 3, 6, 2, /* y = 1 */
        0, 4, 7, 0, 7, 3, /* x = 0 */
        1, 2, 6, 1, 6, 5, /* x = 1 */
    };
    scene_error err = {0};
    scene_result rc;
    scene *s = hand_scene(p, 8, idx, 12, 64.0f, &rc, &err);
    assert_int_equal(rc, SCENE_OK);
    island_report r = check_island_invariants(s);
    print_report("cube", s, &r);
    assert_int_equal(r.island_count, 6);
    assert_int_equal(s->repairs.nonmanifold_split, 0);
    for (uint32_t i = 0; i < 6; i++) {
        assert_int_equal(s->islands[i].triangle_count, 2);
        /* 64 texels + border, snapping may add one. */
        assert_true(s->islands[i].width >= 66 && s->islands[i].width <= 67);
        assert_true(s->islands[i].height >= 66 && s->islands[i].height <= 67);
    }
    /* Each face covers 64 x 64 texel centres exactly once. */
    assert_int_equal(r.texels_covered, 6 * 64 * 64);
    scene_free(s);
}

/* A UV sphere (poles, curvature in every direction). */
static void test_sphere(void **state)
{
    (void)state;
    enum { SEGMENTS = 48, RINGS = 24 };
    uint32_t vertex_count = (RINGS + 1) * SEGMENTS;
    float *p = malloc(sizeof(float) * 3 * vertex_count);
    uint32_t *idx = malloc(sizeof(uint32_t) * 6 * RINGS * SEGMENTS);
    assert_true(p && idx);
    for (uint32_t ring = 0; ring <= RINGS; ring++)
        for (uint32_t seg = 0; seg < SEGMENTS; seg++) {
            double theta = M_PI * ring / RINGS, phi = 2 * M_PI * seg / SEGMENTS;
            float *out = p + 3 * (ring * SEGMENTS + seg);
            out[0] = (float)(sin(theta) * cos(phi));
            out[1] = (float)(sin(theta) * sin(phi));
            out[2] = (float)cos(theta);
        }
    /* Pole rings are collapsed to one vertex each so the sphere is closed. */
    uint32_t t = 0;
    for (uint32_t ring = 0; ring < RINGS; ring++)
        for (uint32_t seg = 0; seg < SEGMENTS; seg++) {
            uint32_t next = (seg + 1) % SEGMENTS;
            uint32_t a = ring * SEGMENTS + seg, b = ring * SEGMENTS + next;
            uint32_t c = (ring + 1) * SEGMENTS + seg, d = (ring + 1) * SEGMENTS + next;
            if (ring == 0)
                a = b = 0;
            if (ring == RINGS - 1)
                c = d = RINGS * SEGMENTS;
            /* outward: (a, c, d) and (a, d, b) are counter-clockwise seen from outside */
            if (ring != 0) {
                idx[3 * t] = a, idx[3 * t + 1] = c, idx[3 * t + 2] = b, t++;
            }
            if (ring != RINGS - 1) {
                idx[3 * t] = b, idx[3 * t + 1] = c, idx[3 * t + 2] = d, t++;
            }
        }
    scene_error err = {0};
    scene_result rc;
    scene *s = hand_scene(p, vertex_count, idx, t, 200.0f, &rc, &err);
    if (rc != SCENE_OK)
        fail_msg("%s", err.msg);
    island_report r = check_island_invariants(s);
    print_report("sphere", s, &r);
    assert_int_equal(s->repairs.nonmanifold_split, 0);
    assert_true(r.island_count >= 6 && r.island_count <= t / 8);
    free(p);
    free(idx);
    scene_free(s);
}

/* A helical ramp (three turns, rising 0.1 m per turn): almost flat, so the normal bound never stops the
 * growth; only the overlap test keeps a turn from landing on the next one in projection. */
static void test_helix_ramp_overlap(void **state)
{
    (void)state;
    enum { PER_TURN = 64, TURNS = 3, STEPS = PER_TURN * TURNS };
    float p[3 * 2 * (STEPS + 1)];
    uint32_t idx[3 * 2 * STEPS];
    for (int k = 0; k <= STEPS; k++) {
        double angle = 2 * M_PI * k / PER_TURN, z = 0.1 * k / PER_TURN;
        float *inner = p + 6 * k, *outer = inner + 3;
        inner[0] = (float)cos(angle), inner[1] = (float)sin(angle), inner[2] = (float)z;
        outer[0] = (float)(2 * cos(angle)), outer[1] = (float)(2 * sin(angle)), outer[2] = (float)z;
    }
    for (uint32_t k = 0; k < STEPS; k++) {
        uint32_t i0 = 2 * k, o0 = 2 * k + 1, i1 = 2 * k + 2, o1 = 2 * k + 3;
        uint32_t *q = idx + 6 * k;
        q[0] = i0, q[1] = o0, q[2] = o1; /* counter-clockwise seen from +z */
        q[3] = i0, q[4] = o1, q[5] = i1;
    }
    scene_error err = {0};
    scene_result rc;
    scene *s = hand_scene(p, 2 * (STEPS + 1), idx, 2 * STEPS, 100.0f, &rc, &err);
    if (rc != SCENE_OK)
        fail_msg("%s", err.msg);
    island_report r = check_island_invariants(s);
    print_report("helix ramp", s, &r);
    /* 384 triangles, 128 per turn, no island can hold more than one turn. */
    assert_true(r.island_count >= 3);
    assert_true(r.largest_island <= 2 * PER_TURN);
    assert_true(r.largest_island >= PER_TURN); /* it does grow around most of a turn */
    scene_free(s);
}

/* ---- real scenes ------------------------------------------------------------------------------------ */

/* Loads path (or the default scene for NULL) at the file's or auto density, checks the islands. */
static void check_file(const char *label, const char *path)
{
    scene_error err = {0};
    scene *s = path ? scene_load(path, NULL, &err) : scene_create_default(NULL, &err);
    if (!s)
        fail_msg("%s: %s", label, err.msg);
    island_report r = check_island_invariants(s);
    print_report(label, s, &r);
    scene_free(s);
}

static void test_default_scene(void **state)
{
    (void)state;
    check_file("default scene", NULL);
}

static void test_bunny(void **state)
{
    (void)state;
    const char *path = "/usr/share/glmark2/models/bunny.obj";
    FILE *f = fopen(path, "rb");
    if (!f) {
        printf("SKIP: %s is absent (Debian package glmark2-data)\n", path);
        skip();
    }
    fclose(f);
    check_file("bunny", path);
}

/* The same scene twice gives the same islands, byte for byte. */
static void test_deterministic(void **state)
{
    (void)state;
    const char *path = "/usr/share/glmark2/models/bunny.obj";
    FILE *f = fopen(path, "rb");
    if (!f) {
        printf("SKIP: %s is absent (Debian package glmark2-data)\n", path);
        skip();
    }
    fclose(f);
    scene_error err = {0};
    scene *s = scene_load(path, NULL, &err);
    if (!s)
        fail_msg("%s", err.msg);
    uint32_t n = s->triangle_count, count = s->island_count;
    scene_island *islands = malloc(sizeof(scene_island) * count);
    float *uv = malloc(sizeof(float) * 6 * n);
    uint32_t *order = malloc(sizeof(uint32_t) * n);
    assert_true(islands && uv && order);
    memcpy(islands, s->islands, sizeof(scene_island) * count);
    memcpy(uv, s->tri_island_uv, sizeof(float) * 6 * n);
    memcpy(order, s->island_triangles, sizeof(uint32_t) * n);
    assert_int_equal(scene__build_islands(s, &err), SCENE_OK);
    assert_int_equal(s->island_count, count);
    assert_memory_equal(islands, s->islands, sizeof(scene_island) * count);
    assert_memory_equal(uv, s->tri_island_uv, sizeof(float) * 6 * n);
    assert_memory_equal(order, s->island_triangles, sizeof(uint32_t) * n);
    free(islands);
    free(uv);
    free(order);
    scene_free(s);
}

static void test_sponza(void **state)
{
    (void)state;
    const char *path = fxt_shared_scene("sponza/sponza.3ds");
    if (!path)
        skip();
    check_file("sponza", path);
}

static void test_cornell_box(void **state)
{
    (void)state;
    const char *path = fxt_shared_scene("cornell-box/CornellBox-Original.obj");
    if (!path)
        skip();
    check_file("cornell box", path);
}

static void test_dragon(void **state)
{
    (void)state;
    const char *path = fxt_shared_scene("dragon/dragon_vrip_res2.ply.gz");
    if (!path)
        skip();
    check_file("dragon (res2)", path);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_nonmanifold_fan),
        cmocka_unit_test(test_nonmanifold_fan_through_builder),
        cmocka_unit_test(test_bowtie),
        cmocka_unit_test(test_slivers),
        cmocka_unit_test(test_long_strip_split_for_size),
        cmocka_unit_test(test_density_too_high),
        cmocka_unit_test(test_cube),
        cmocka_unit_test(test_sphere),
        cmocka_unit_test(test_helix_ramp_overlap),
        cmocka_unit_test(test_default_scene),
        cmocka_unit_test(test_bunny),
        cmocka_unit_test(test_deterministic),
        cmocka_unit_test(test_cornell_box),
        cmocka_unit_test(test_sponza),
        cmocka_unit_test(test_dragon),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
