/* Stability suite, geometry (docs/ERROR.md "Stability suite"): slivers with aspect ratios of 1e6, zero-area
 * and duplicate triangles, a non-manifold edge, T-junctions, single-sided geometry seen from behind, and
 * islands at and beyond the 12-bit block limit. Each case builds its mesh by hand, checks what the builder
 * repaired (counted, never silent), renders it through the whole frame loop (every frame checked by
 * stab_check_loop) and compares every pixel with a closed form: an open plane's depth and radiance, the exact
 * shadow of a box, the AO beside a wall. */
#include "stab_util.h"

#include "engine_internal.h"
#include "scene_internal.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const float sun_dir[3] = {0.4f, -0.8f, 0.3f};
#define PLANE_Y 0.3f

/* Adds a mesh of nv positions (x, z pairs on the plane y = PLANE_Y when `flat`, else xyz triples) and nt
 * triangles, each turned to face +y when `flat`. */
static void add_mesh(scene *s, const char *name, const float *coords, uint32_t nv, const uint32_t *idx,
                     uint32_t nt, bool flat)
{
    float *p = malloc(sizeof(float) * 3 * nv);
    uint32_t *t = malloc(sizeof(uint32_t) * 3 * nt);
    assert_true(p && t);
    for (uint32_t v = 0; v < nv; v++) {
        if (flat) {
            p[3 * v] = coords[2 * v];
            p[3 * v + 1] = PLANE_Y;
            p[3 * v + 2] = coords[2 * v + 1];
        } else {
            memcpy(p + 3 * v, coords + 3 * v, 3 * sizeof(float));
        }
    }
    memcpy(t, idx, sizeof(uint32_t) * 3 * nt);
    for (uint32_t i = 0; flat && i < nt; i++) {
        const float *a = p + 3 * t[3 * i], *b = p + 3 * t[3 * i + 1], *c = p + 3 * t[3 * i + 2];
        /* y of (b - a) x (c - a) for points in the xz plane: dz1 dx2 - dx1 dz2 */
        double ny =
            ((double)b[2] - a[2]) * ((double)c[0] - a[0]) - ((double)b[0] - a[0]) * ((double)c[2] - a[2]);
        if (ny < 0) {
            uint32_t swap = t[3 * i + 1];
            t[3 * i + 1] = t[3 * i + 2];
            t[3 * i + 2] = swap;
        }
    }
    scene_error err = {0};
    if (scene__add_mesh(s, name, p, nv, t, nt, NULL, 0, NULL, &err) != SCENE_OK)
        fail_msg("%s: %s", name, err.msg);
    free(p);
    free(t);
}

/* The sun and sky every case uses. */
static void light(scene *s)
{
    fxt_add_sun(s, sun_dir[0], sun_dir[1], sun_dir[2]);
    stab_set_sun(s, sun_dir, 2.0f);
    s->sky_color[0] = 0.2f, s->sky_color[1] = 0.3f, s->sky_color[2] = 0.4f;
    s->sky_intensity = 1.0f;
}

/* A loop with shadows and AO (views kept), every texel converged in one update. */
static srv_loop *views_loop(scene *s, scene_rt *rt, bool no_cache, uint32_t w, uint32_t h, srv_viewer_id *id)
{
    srv_loop_desc d = {.s = s,
                       .rt = rt,
                       .seed = 6,
                       .keep_views = true,
                       .no_cache = no_cache,
                       .samples_per_update = 64,
                       .threads = 2};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    return fxt_loop(&d, 1, w, h, id);
}

/* Renders the floor (y = PLANE_Y, |x - cx| <= half_x, |z - cz| <= half_z, nothing above it) from every camera, cached and
 * no-cache, and checks every pixel against the open plane's depth and closed form. Returns plane pixels. */
static uint64_t check_flat(scene *s, scene_rt *rt, const srv_camera *cams, uint32_t n, double cx, double cz,
                           double half_x, double half_z, const char *what)
{
    uint64_t pixels = 0;
    for (uint32_t c = 0; c < n; c++)
        for (int no_cache = 0; no_cache < 2; no_cache++) {
            srv_viewer_id id;
            srv_loop *loop = views_loop(s, rt, no_cache, 64, 36, &id);
            srv_frame_stats st;
            stab_frames(loop, &id, 1, &cams[c], true, no_cache ? 1 : 2, &st);
            stab_plane_result r =
                stab_check_open_plane(loop, id, &cams[c], (double)PLANE_Y, cx, cz, half_x, half_z);
            print_message(
                "%s, camera %u%s: %llu plane pixels (closed form within %.2e, depth within %.2f of its "
                "bound), %llu sky\n",
                what, c, no_cache ? " (no cache)" : "", (unsigned long long)r.plane_pixels, r.worst_radiance,
                r.worst_depth, (unsigned long long)r.sky_pixels);
            assert_true(r.plane_pixels > 64 * 36 / 8);
            pixels += r.plane_pixels;
            srv_loop_free(loop);
        }
    return pixels;
}

/* ---- slivers ---------------------------------------------------------------------------------------------- */

/* An 8 m square floor cut into a fan around a point E 8e-6 m inside its edge AB: the triangle A E B is 8 m long
 * and 8e-6 m high (aspect 1e6), and E's fan towards the edge CD has ten needles 8e-6 m wide at their far end,
 * 8.9 m away (angles of 9e-7 rad). The builder keeps them all (the degenerate test is a sine below 1e-9); the
 * slivers end up in islands of their own, far below a texel. Every pixel, from above and grazing along AB, is
 * the open plane's depth (no crack between needles) and closed-form radiance, AO and lit fraction 1 (no
 * sample point of a sliver texel off the plane, no shadow acne). */
static void test_sliver_aspect_1e6(void **state)
{
    (void)state;
    enum { NEEDLES = 10 };
    float xz[2 * (5 + NEEDLES)] = {-4, -4, 4, -4, 4, 4, -4, 4, 0, -4 + 8e-6f}; /* A B C D E */
    for (uint32_t i = 0; i < NEEDLES; i++) {
        xz[10 + 2 * i] = 4.0f - 8e-6f * (float)(i + 1);
        xz[11 + 2 * i] = 4.0f;
    }
    uint32_t idx[3 * (5 + NEEDLES)], t = 0;
    const uint32_t A = 0, B = 1, C = 2, D = 3, E = 4;
    const uint32_t fixed[5][3] = {{A, E, B}, {B, E, C}, {C, E, 5}, {5 + NEEDLES - 1, E, D}, {D, E, A}};
    for (int i = 0; i < 5; i++, t++)
        memcpy(idx + 3 * t, fixed[i], sizeof fixed[i]);
    for (uint32_t i = 0; i + 1 < NEEDLES; i++, t++) {
        idx[3 * t] = 5 + i;
        idx[3 * t + 1] = E;
        idx[3 * t + 2] = 5 + i + 1;
    }
    scene *s = fxt_new_scene();
    add_mesh(s, "fan", xz, 5 + NEEDLES, idx, t, true);
    light(s);
    scene_rt *rt = fxt_finish_scene(s, 16.0f, 1.0f);
    print_message("slivers: %u triangles kept of %u, %llu degenerate, %u islands\n", s->triangle_count, t,
                  (unsigned long long)s->repairs.degenerate_skipped, s->island_count);
    assert_int_equal(s->triangle_count, t);
    assert_int_equal(s->repairs.degenerate_skipped, 0);
    const srv_camera cams[2] = {
        {.position = {0.5f, 6.0f, 3.0f}, .target = {0.0f, 0.3f, -0.5f}, .up = {0, 1, 0}, .fov_deg = 70},
        /* low along AB, looking at the sliver and at E */
        {.position = {-3.0f, 0.4f, -3.5f}, .target = {1.0f, 0.3f, -3.99f}, .up = {0, 1, 0}, .fov_deg = 40},
    };
    check_flat(s, rt, cams, 2, 0, 0, 4, 4, "slivers");
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- zero-area and duplicate triangles ------------------------------------------------------------------------ */

/* A floor of two triangles plus a collinear triangle, one with a repeated corner, an exact duplicate, the same
 * triangle with its corners rotated, and one reversed (the same three vertices facing down, after its
 * original): the builder drops 2 as degenerate and 3 as duplicates (the first of each set of three vertices
 * wins, so the floor still faces up; a kept reversed twin would be a coplanar surface facing down, its AO and
 * shadows computed for the wrong side). The image is the open plane's. */
static void test_zero_area_and_duplicates(void **state)
{
    (void)state;
    const float xz[] = {-4, -4, 4, -4, 4, 4, -4, 4, 0, -4};
    scene *s = fxt_new_scene();
    float p[3 * 5];
    for (int v = 0; v < 5; v++) {
        p[3 * v] = xz[2 * v];
        p[3 * v + 1] = PLANE_Y;
        p[3 * v + 2] = xz[2 * v + 1];
    }
    /* Facing +y: (0, 3, 2) and (0, 2, 1) (edge_a along +z, edge_b along +x: z x x = +y). */
    const uint32_t idx[] = {0, 3, 2, 0, 2, 1, /* the floor */
                            0, 4, 1,          /* collinear: A, the midpoint of AB, B */
                            0, 0, 2,          /* a repeated corner */
                            0, 3, 2,          /* an exact duplicate */
                            3, 2, 0,          /* the same, corners rotated */
                            0, 1, 2};         /* the second triangle reversed (faces down) */
    scene_error err = {0};
    assert_int_equal(scene__add_mesh(s, "floor and extras", p, 5, idx, 7, NULL, 0, NULL, &err), SCENE_OK);
    light(s);
    scene_rt *rt = fxt_finish_scene(s, 16.0f, 1.0f);
    print_message("degenerate %llu, duplicate %llu, %u triangles kept\n",
                  (unsigned long long)s->repairs.degenerate_skipped,
                  (unsigned long long)s->repairs.duplicate_skipped, s->triangle_count);
    assert_int_equal(s->repairs.degenerate_skipped, 2);
    assert_int_equal(s->repairs.duplicate_skipped, 3);
    assert_int_equal(s->triangle_count, 2);
    for (uint32_t t = 0; t < s->triangle_count; t++)
        assert_true(s->tri_normal[3 * t + 1] == 1.0f);
    const srv_camera cams[1] = {
        {.position = {0.5f, 6.0f, 3.0f}, .target = {0.0f, 0.3f, -0.5f}, .up = {0, 1, 0}, .fov_deg = 70}};
    check_flat(s, rt, cams, 1, 0, 0, 4, 4, "zero-area and duplicates");
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- a non-manifold edge ------------------------------------------------------------------------------------- */

/* One mesh: a floor on both sides of the line x = 0 and a wall 5 m tall standing on that line, facing +x, all
 * three sharing the edge from (0, 0.3, -4) to (0, 0.3, 4): three triangles on one edge (non-manifold), which
 * the topology splits off and counts. Lit by a sun from -x (the wall's shadow on the floor is a strip 1 m
 * wide). On the floor in front of it:
 *   - the lit fraction is the exact shadow of the wall (stab_check_box_on_plane, the wall a box of no
 *     thickness) away from the shadow's edge;
 *   - AO is the closed form beside an infinite wall, fxt_disk_open(d, inf, inf, R) (the wall reaches beyond R
 *     in height and, where checked, |z| < 4 - R, along), compared as the mean over bins of 0.1 R in d: the
 *     bound is 4 standard errors of the bin's mean, 0.5 / sqrt(64 n) for n texels of 64 samples (no-cache:
 *     n pixels; cached: a quarter of its pixels, AO reading one level coarser than the pixel), plus for the
 *     cached read the closed form's slope (at most 2 / (pi R)) times half the texel, which bilinear filtering
 *     of texel means may shift it by. */
static void test_non_manifold_edge(void **state)
{
    (void)state;
    const double R = 1.0, half = 4.0;
    const float p[] = {-4, PLANE_Y, -4, 0, PLANE_Y, -4, 0, PLANE_Y, 4, -4, PLANE_Y, 4, /* left floor */
                       4,  PLANE_Y, -4, 4, PLANE_Y, 4,                                 /* right floor */
                       0,  5.3f,    -4, 0, 5.3f,    4};                                /* wall top */
    /* Each quad's first triangle has the shared edge 1-2 as an edge. Left floor: (0, 2, 1), (0, 3, 2) face up
     * (z x x); right floor: (4, 1, 2), (4, 2, 5); wall facing +x: (6, 1, 2)?, (6, 2, 7) (y x z = +x). */
    const uint32_t idx[] = {0, 2, 1, 0, 3, 2, 4, 1, 2, 4, 2, 5, 6, 2, 1, 6, 7, 2};
    scene *s = fxt_new_scene();
    scene_error err = {0};
    assert_int_equal(scene__add_mesh(s, "floor and wall", p, 8, idx, 6, NULL, 0, NULL, &err), SCENE_OK);
    const float sun[3] = {0.2f, -1.0f, 0.1f};
    fxt_add_sun(s, sun[0], sun[1], sun[2]);
    stab_set_sun(s, sun, 2.0f);
    s->sky_color[0] = s->sky_color[1] = s->sky_color[2] = 1.0f;
    s->sky_intensity = 1.0f;
    const float density = 32.0f;
    scene_rt *rt = fxt_finish_scene(s, density, (float)R);
    print_message("non-manifold: %llu triangles split off, %u islands\n",
                  (unsigned long long)s->repairs.nonmanifold_split, s->island_count);
    assert_true(s->repairs.nonmanifold_split >= 1);
    for (uint32_t t = 0; t < s->triangle_count; t++) { /* floors up, the wall towards +x */
        const float *n = s->tri_normal + 3 * t;
        assert_true(n[1] == 1.0f || n[0] == 1.0f);
    }
    srv_camera cam = {
        .position = {2.6f, 2.0f, 0.0f}, .target = {0.4f, 0.3f, 0.0f}, .up = {0, 1, 0}, .fov_deg = 70};
    const double lo[3] = {0, (double)PLANE_Y, -half}, hi[3] = {0, 5.3, half};
    enum { NW = 96, NH = 64, BINS = 10 };
    for (int no_cache = 0; no_cache < 2; no_cache++) {
        srv_viewer_id id;
        srv_loop *loop = views_loop(s, rt, no_cache, NW, NH, &id);
        srv_frame_stats st;
        stab_frames(loop, &id, 1, &cam, true, no_cache ? 1 : 2, &st);
        stab_box_result r =
            stab_check_box_on_plane(loop, id, &cam, (double)PLANE_Y, lo, hi, false, density, (float)R, 1e-5);
        assert_true(r.lit_checked > 1000 && r.dark > 100);
        /* AO against the closed form, by distance from the wall. */
        srv_camera_frame f;
        assert_true(srv_camera_setup(&cam, NW, NH, &f));
        const float *depth = srv_viewer_depth(loop, id), *ao = srv_viewer_view(loop, id, SRV_VIEW_AO);
        double measured[BINS] = {0}, closed[BINS] = {0}, slack[BINS] = {0};
        uint32_t count[BINS] = {0};
        for (uint32_t y = 0; y < NH; y++)
            for (uint32_t x = 0; x < NW; x++) {
                size_t px = (size_t)y * NW + x;
                double t = stab_plane_depth(&f, x, y, (double)PLANE_Y), q[3];
                if (!(fabs(depth[px] - t) <= 1e-5 * t))
                    continue;
                stab_pixel_point(&f, x, y, (float)t, q);
                int bin = (int)floor(q[0] / (0.1 * R));
                if (bin < 0 || bin >= BINS || fabs(q[2]) > half - R - 0.2)
                    continue;
                double footprint = t * 2.0 * f.tan_half_y / NH / fabs((q[1] - f.origin[1]) / t);
                double texel = fmax(2.84 * footprint, 1.0 / density); /* AO: one level coarser */
                measured[bin] += ao[px];
                closed[bin] += fxt_disk_open(q[0], INFINITY, INFINITY, R);
                slack[bin] += no_cache ? 0.0 : 2.0 / (M_PI * R) * texel / 2;
                count[bin]++;
            }
        double worst = 0;
        for (int b = 0; b < BINS; b++) {
            assert_true(count[b] >= 16);
            double n = no_cache ? count[b] : fmax(1.0, count[b] / 4.0);
            double bound = 4 * 0.5 / sqrt(64 * n) + slack[b] / count[b];
            double error = fabs(measured[b] - closed[b]) / count[b];
            worst = fmax(worst, error / bound);
            if (error > bound)
                fail_msg(
                    "non-manifold%s: AO at %.1f..%.1f R from the wall %.4f, closed form %.4f (bound %.4f, %u "
                    "pixels)",
                    no_cache ? " (no cache)" : "", 0.1 * b, 0.1 * (b + 1), measured[b] / count[b],
                    closed[b] / count[b], bound, count[b]);
        }
        print_message(
            "non-manifold%s: %u pixels' shadows exact (%u dark); AO in 10 bins within %.2f of its bound "
            "(at the wall %.4f, closed form %.4f)\n",
            no_cache ? " (no cache)" : "", r.lit_checked, r.dark, worst, measured[0] / count[0],
            closed[0] / count[0]);
        srv_loop_free(loop);
    }
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- T-junctions ------------------------------------------------------------------------------------------- */

/* A floor whose left half is one quad and right half two, so the right half's middle corner (0, 0.3, 0) lies on
 * the left quad's edge (a T-junction), and a second T where a fan of three triangles meets the right quads'
 * shared edge at two points. Seen from above and grazing along the junction line: every pixel meets the
 * plane (no crack where the edges do not share vertices) at the plane's depth, with the closed form. */
static void test_t_junction(void **state)
{
    (void)state;
    const float xz[] = {-4, -4, 0, -4, 0, 4, -4, 4, /* left quad: 0 1 2 3 */
                        0,  0,  4, -4, 4, 0, 4,  4, /* right: T corner 4, then 5 6 7 */
                        2,  0,  1, 0};              /* two more points on the edge 4-6: 8 (2, 0), 9 (1, 0) */
    const uint32_t idx[] = {0, 1, 2, 0, 2, 3,       /* left quad */
                            1, 5, 6, 1, 6, 4,       /* right lower: 1 5 6 4, cut at 4-6 by the fan below */
                            4, 9, 2, 9, 8, 2,
                            8, 6, 7, 8, 7, 2}; /* right upper: a fan whose corners 9, 8 lie on 4-6 */
    scene *s = fxt_new_scene();
    add_mesh(s, "t-junctions", xz, 10, idx, 8, true);
    light(s);
    scene_rt *rt = fxt_finish_scene(s, 16.0f, 1.0f);
    print_message("T-junctions: %u triangles, %llu degenerate, %llu duplicate, %llu split\n",
                  s->triangle_count, (unsigned long long)s->repairs.degenerate_skipped,
                  (unsigned long long)s->repairs.duplicate_skipped,
                  (unsigned long long)s->repairs.nonmanifold_split);
    assert_int_equal(s->triangle_count, 8);
    const srv_camera cams[3] = {
        {.position = {0.5f, 6.0f, 3.0f}, .target = {0.0f, 0.3f, -0.5f}, .up = {0, 1, 0}, .fov_deg = 70},
        /* low along the line x = 0 */
        {.position = {0.0f, 0.35f, -3.9f}, .target = {0.0f, 0.15f, 0.0f}, .up = {0, 1, 0}, .fov_deg = 30},
        /* low along the line z = 0 */
        {.position = {-3.9f, 0.33f, 0.0f}, .target = {0.0f, 0.15f, 0.0f}, .up = {0, 1, 0}, .fov_deg = 30},
    };
    check_flat(s, rt, cams, 3, 0, 0, 4, 4, "T-junctions");
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- single-sided geometry seen from behind ------------------------------------------------------------------ */

/* One floor quad facing up, seen from below. With the sun above, the face the camera sees is turned away from
 * it (no direct light) and its sky is open: every pixel is exactly albedo x sky, at the plane's depth. With
 * the sun below, the face the camera sees is lit and open: albedo x (E cos + sky), read from the back's own
 * cached shadows (ARCHITECTURE.md "Both sides of a surface"; before branch two-side the back read the
 * front's visibility, 0 for a sun behind it, and the value was albedo x sky). The case asserts the value lies
 * between the two (bounded by the direct term) and that it is the exact one for the sun's side. */
static void test_single_sided_from_behind(void **state)
{
    (void)state;
    for (int below = 0; below < 2; below++) {
        scene *s = fxt_new_scene();
        stab_add_floor(s, 0.0, (double)PLANE_Y, 0.0, 4.0, 2);
        const float sun[3] = {0.3f, below ? 0.9f : -0.9f, 0.2f};
        fxt_add_sun(s, sun[0], sun[1], sun[2]);
        stab_set_sun(s, sun, 2.0f);
        s->sky_color[0] = 0.2f, s->sky_color[1] = 0.3f, s->sky_color[2] = 0.4f;
        s->sky_intensity = 1.0f;
        scene_rt *rt = fxt_finish_scene(s, 16.0f, 1.0f);
        srv_camera cam = {
            .position = {0.4f, -2.2f, 0.6f}, .target = {0.0f, 0.3f, 0.0f}, .up = {0, 1, 0}, .fov_deg = 70};
        for (int no_cache = 0; no_cache < 2; no_cache++) {
            srv_viewer_id id;
            srv_loop *loop = views_loop(s, rt, no_cache, 64, 36, &id);
            srv_frame_stats st;
            stab_frames(loop, &id, 1, &cam, true, no_cache ? 1 : 2, &st);
            srv_camera_frame f;
            assert_true(srv_camera_setup(&cam, 64, 36, &f));
            const float *rad = srv_viewer_radiance(loop, id), *depth = srv_viewer_depth(loop, id);
            double cosine = (double)s->lights[0].direction[1]; /* towards the sun, against the normal -y */
            uint32_t plane = 0;
            for (uint32_t y = 0; y < 36; y++)
                for (uint32_t x = 0; x < 64; x++) {
                    size_t px = (size_t)y * 64 + x;
                    double t = stab_plane_depth(&f, x, y, (double)PLANE_Y), q[3];
                    stab_pixel_point(&f, x, y, (float)t, q);
                    if (!isfinite(t) || fmax(fabs(q[0]), fabs(q[2])) > 4.0 - 1e-3)
                        continue;
                    if (!(fabs(depth[px] - t) <= 1e-5 * t))
                        fail_msg("from behind, pixel (%u, %u): depth %g, the plane's %g", x, y,
                                 (double)depth[px], t);
                    plane++;
                    for (int k = 0; k < 3; k++) {
                        double sky = 0.5 * s->sky_color[k] * s->sky_intensity;
                        double lit =
                            sky + 0.5 * s->lights[0].intensity * s->lights[0].color[k] * fmax(cosine, 0.0);
                        double v = rad[3 * px + k];
                        if (!(v >= sky * (1 - STAB_FORMULA_TOLERANCE) &&
                              v <= lit * (1 + STAB_FORMULA_TOLERANCE)))
                            fail_msg("from behind, pixel (%u, %u): radiance %g outside [%g, %g]", x, y, v,
                                     sky, lit);
                        double exact = below ? lit : sky; /* the face seen lit by a sun on its side */
                        if (!(fabs(v - exact) <= STAB_FORMULA_TOLERANCE * exact))
                            fail_msg("from behind, sun %s, pixel (%u, %u): radiance %.9g, expected %.9g",
                                     below ? "below" : "above", x, y, v, exact);
                    }
                }
            print_message("seen from behind, sun %s%s: %u pixels, all albedo x %s\n",
                          below ? "below" : "above", no_cache ? " (no cache)" : "", plane,
                          below ? "(E cos + sky): the back's own shadows" : "sky");
            assert_true(plane > 64 * 36 / 2);
            srv_loop_free(loop);
        }
        scene_rt_free(rt);
        scene_free(s);
    }
}

/* ---- islands at the 12-bit block limit ------------------------------------------------------------------------ */

/* A floor of one quad 32.766 m wide at 1000 texels per metre: two triangles whose island is 32768 x 32768
 * texels with its border, the largest the 12-bit block coordinates hold (blocks 0..4095). Its right triangles
 * need 46,341 texels along their hypotenuse: they fit turned to their legs (scene_islands.c tries every
 * edge). A box 1 cm wide floats 5 mm over the floor near the island's far corner (blocks 4095), and a camera
 * 2.5 cm above looks at its shadow with pixels of 0.8 mm, so the texels read are level 0 at blocks up to 4095:
 * the exact shadow and AO 1 away from the box (stab_check_box_on_plane), and the checker finds every resident
 * block inside its island (a coordinate wrapped past 4095 would not be). One millimetre wider (32.767 m) the
 * floor needs 32769 texels along its legs too: SCENE_ERR_RANGE, naming the mesh and the density. A floor
 * 40 m x 1 m of 40 quads at the same density is split into islands of at most 32768 texels, and is the open
 * plane's closed form across their seam. */
static void test_island_at_12bit_limit(void **state)
{
    (void)state;
    const float density = 1000.0f;
    /* One millimetre too wide: refused. */
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "too wide", (const double[3]){-16.3835, (double)PLANE_Y, -16.3835},
                 (const double[3]){0, 0, 32.767}, (const double[3]){32.767, 0, 0}, 1);
    scene_error err = {0};
    scene_load_desc desc = {.texel_density = density};
    assert_int_equal(scene__finalize(s, &desc, &err), SCENE_ERR_RANGE);
    print_message("32.767 m at %g texels/m: %s\n", (double)density, err.msg);
    assert_non_null(strstr(err.msg, "'too wide'"));
    assert_non_null(strstr(err.msg, "1000 texels/m"));
    scene_free(s);

    /* At the limit. The far corner: the floor's corner at the island's largest UV (found on a first build of
     * the floor alone), and from it `inward` along both axes. */
    const double side = 32.766, corner = -16.383;
    double far[3] = {0, 0, 0};
    {
        scene *probe = fxt_new_scene();
        fxt_add_quad(probe, "floor", (const double[3]){corner, (double)PLANE_Y, corner},
                     (const double[3]){0, 0, side}, (const double[3]){side, 0, 0}, 1);
        scene_rt *probe_rt = fxt_finish_scene(probe, density, 0.002f);
        print_message("32.766 m at %g texels/m: %u island(s), the first %u x %u texels\n", (double)density,
                      probe->island_count, probe->islands[0].width, probe->islands[0].height);
        assert_int_equal(probe->island_count, 1);
        assert_int_equal(probe->islands[0].width, 32768);
        assert_int_equal(probe->islands[0].height, 32768);
        bool found = false;
        for (uint32_t t = 0; t < probe->triangle_count && !found; t++)
            for (int c = 0; c < 3 && !found; c++) {
                const float *uv = probe->tri_island_uv + 6 * (size_t)t + 2 * c;
                if (uv[0] > 32760 && uv[1] > 32760) {
                    for (int k = 0; k < 3; k++)
                        far[k] = probe->positions[3 * (size_t)probe->indices[3 * (size_t)t + c] + k];
                    found = true;
                }
            }
        assert_true(found);
        scene_rt_free(probe_rt);
        scene_free(probe);
    }
    const double in_x = far[0] > 0 ? -1 : 1, in_z = far[2] > 0 ? -1 : 1;
    /* A box 10 mm wide, 2 to 10 mm over the floor, 9 to 19 mm inside the corner; a sun travelling outwards at
     * 35 degrees of elevation lays its shadow over the last 8 texels (block 4095) of both axes. */
    const double bc[2] = {far[0] + in_x * 0.014, far[2] + in_z * 0.014};
    const double lo[3] = {bc[0] - 0.005, (double)PLANE_Y + 0.002, bc[1] - 0.005},
                 hi[3] = {bc[0] + 0.005, (double)PLANE_Y + 0.010, bc[1] + 0.005};
    s = fxt_new_scene();
    fxt_add_quad(s, "floor", (const double[3]){corner, (double)PLANE_Y, corner},
                 (const double[3]){0, 0, side}, (const double[3]){side, 0, 0}, 1);
    fxt_add_box(s, "box", lo, hi, false, 1);
    const float out_sun[3] = {(float)-in_x, -1.0f, (float)-in_z};
    fxt_add_sun(s, out_sun[0], out_sun[1], out_sun[2]);
    stab_set_sun(s, out_sun, 2.0f);
    s->sky_color[0] = s->sky_color[1] = s->sky_color[2] = 1.0f;
    s->sky_intensity = 1.0f;
    const float ao_radius = 0.002f;
    scene_rt *rt = fxt_finish_scene(s, density, ao_radius);
    srv_camera cam = {
        .position = {(float)(far[0] + in_x * 0.010), PLANE_Y + 0.02f, (float)(far[2] + in_z * 0.010)},
        .target = {(float)(far[0] + in_x * 0.004), PLANE_Y, (float)(far[2] + in_z * 0.004)},
        .up = {0, 1, 0},
        .fov_deg = 40};
    for (int no_cache = 0; no_cache < 2; no_cache++) {
        srv_viewer_id id;
        srv_loop *loop = views_loop(s, rt, no_cache, 128, 96, &id);
        srv_frame_stats st;
        stab_checked c = stab_frames(loop, &id, 1, &cam, true, no_cache ? 1 : 2, &st);
        stab_box_result r =
            stab_check_box_on_plane(loop, id, &cam, (double)PLANE_Y, lo, hi, false, density, ao_radius, 1e-5);
        /* The largest level-0 block coordinate resident (the checker found every block inside its island). */
        uint32_t largest = 0;
        const srv_cache_kind *kind = loop->kinds[SCENE_CACHE_ON_SURFACE];
        for (uint32_t b = 0;
             !no_cache && b < kind->pool_capacity(loop->caches[SCENE_CACHE_ON_SURFACE], SCENE_FX_SHADOW);
             b++) {
            uint64_t key = kind->block_key(loop->caches[SCENE_CACHE_ON_SURFACE], SCENE_FX_SHADOW, b);
            if (key == UINT64_MAX || ((key >> 24) & 0xf) != 0)
                continue;
            uint32_t bx = (uint32_t)key & 0xfff, by = (uint32_t)(key >> 12) & 0xfff;
            largest = bx > largest ? bx : largest;
            largest = by > largest ? by : largest;
        }
        print_message(
            "far corner%s: %u plane pixels, %u shadows exact (%u dark), AO 1 at %u; level-0 blocks up "
            "to %u (%llu blocks checked)\n",
            no_cache ? " (no cache)" : "", r.plane_pixels, r.lit_checked, r.dark, r.open, largest,
            (unsigned long long)c.blocks);
        assert_true(r.lit_checked > 300 && r.dark > 20 && r.open > 100);
        assert_true(no_cache || largest == 4095);
        srv_loop_free(loop);
    }
    scene_rt_free(rt);
    scene_free(s);

    /* Split: 40 m x 1 m of 40 quads. */
    s = fxt_new_scene();
    fxt_add_quad(s, "strip", (const double[3]){-20, (double)PLANE_Y, -0.5}, (const double[3]){0, 0, 1},
                 (const double[3]){40, 0, 0}, 8);
    light(s);
    rt = fxt_finish_scene(s, density, 0.05f);
    uint32_t widest = 0;
    for (uint32_t i = 0; i < s->island_count; i++) {
        widest = s->islands[i].width > widest ? s->islands[i].width : widest;
        widest = s->islands[i].height > widest ? s->islands[i].height : widest;
        assert_true(s->islands[i].width <= SCENE_MAX_ISLAND_TEXELS &&
                    s->islands[i].height <= SCENE_MAX_ISLAND_TEXELS);
    }
    print_message("40 m strip at %g texels/m: %u islands, the longest side %u texels\n", (double)density,
                  s->island_count, widest);
    assert_true(s->island_count >= 2);
    /* The seam: the x where the island of the triangle at x changes, found along the strip. */
    double seam = NAN;
    uint32_t last = UINT32_MAX;
    for (double x = -19.99; x < 20 && isnan(seam); x += 0.01) {
        uint32_t tri;
        float u, v, t;
        assert_true(scene_rt_intersect1(rt, (const float[3]){(float)x, 1.0f, 0.1f},
                                        (const float[3]){0, -1, 0}, INFINITY, &tri, &u, &v, &t));
        if (last != UINT32_MAX && s->tri_island[tri] != last)
            seam = x;
        last = s->tri_island[tri];
    }
    assert_false(isnan(seam));
    srv_camera cams[1] = {{.position = {(float)seam - 0.05f, PLANE_Y + 0.06f, 0.02f},
                           .target = {(float)seam + 0.02f, PLANE_Y, 0.0f},
                           .up = {0, 1, 0},
                           .fov_deg = 60}};
    check_flat(s, rt, cams, 1, 0, 0, 20, 0.5, "across the seam of two islands");
    scene_rt_free(rt);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sliver_aspect_1e6),        cmocka_unit_test(test_zero_area_and_duplicates),
        cmocka_unit_test(test_non_manifold_edge),        cmocka_unit_test(test_t_junction),
        cmocka_unit_test(test_single_sided_from_behind), cmocka_unit_test(test_island_at_12bit_limit),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
