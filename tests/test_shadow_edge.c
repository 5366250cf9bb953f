/* Shadow edges at the finest level: a square occluder 1 m above a floor under a sun straight overhead casts
 * a square shadow; a camera between them looks down with pixels far smaller than a texel. For the occluder's
 * edges at 0, 22.5 and 45 degrees to the floor island's texel grid, the 10-90 % width of the lit fraction
 * across the edge (from the pixels' distance to the exact shadow boundary, binned) must be at most one
 * texel, without more than the 16 rays per texel. The per-pixel baseline's width is printed beside it. */
#include "test_util.h"

#include "engine.h"
#include "scene.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { RES = 256 };
static const float density = 16.0f; /* texels per metre: a texel is 6.25 cm */
static const double centre[2] = {0.3, 0.2};

/* Writes the scene: a 4 m floor (+y) and, if angle >= 0, a 1 m square occluder at y = 1 whose edges make
 * `angle` degrees with the world direction u_dir (x, z); the sun shines straight down. */
static scene *edge_scene(double angle_deg, const double u_dir[2])
{
    char obj[2048], json[1024];
    int n = snprintf(obj, sizeof obj,
                     "v -2 0 -2\nv -2 0 2\nv 2 0 2\nv 2 0 -2\n"
                     "f 1 2 3\nf 1 3 4\n");
    if (angle_deg >= 0) {
        double a = angle_deg * M_PI / 180.0;
        /* Edge directions: u_dir rotated by a, and its perpendicular. */
        double e1[2] = {u_dir[0] * cos(a) - u_dir[1] * sin(a), u_dir[0] * sin(a) + u_dir[1] * cos(a)};
        double e2[2] = {-e1[1], e1[0]};
        for (int c = 0; c < 4; c++) {
            double s1 = (c == 1 || c == 2) ? 0.5 : -0.5, s2 = (c >= 2) ? 0.5 : -0.5;
            n += snprintf(obj + n, sizeof obj - (size_t)n, "v %.9f 1 %.9f\n",
                          centre[0] + s1 * e1[0] + s2 * e2[0], centre[1] + s1 * e1[1] + s2 * e2[1]);
        }
        n += snprintf(obj + n, sizeof obj - (size_t)n, "f 5 6 7\nf 5 7 8\n");
    }
    assert_true(n > 0 && (size_t)n < sizeof obj);
    fxt_write_file("edge.obj", obj);
    snprintf(json, sizeof json,
             "{\"version\": 1, \"meshes\": [{\"file\": \"edge.obj\"}],\n"
             " \"lights\": [{\"type\": \"directional\", \"direction\": [0, -1, 0]}],\n"
             " \"texel_density\": %g, \"effects\": {\"ao\": \"off\"}}\n",
             (double)density);
    scene_error err = {0};
    scene *s = scene_load(fxt_write_file("edge.json", json), NULL, &err);
    if (!s)
        fail_msg("edge scene: %s", err.msg);
    return s;
}

/* The world (x, z) direction of the floor island's +u texel axis. */
static void floor_u_axis(const scene *s, double u_dir[2])
{
    uint32_t tri = 0; /* the floor's first triangle */
    const float *uv = s->tri_island_uv + 6 * (size_t)tri;
    const uint32_t *idx = s->indices + 3 * (size_t)tri;
    const float *p0 = s->positions + 3 * (size_t)idx[0], *p1 = s->positions + 3 * (size_t)idx[1],
                *p2 = s->positions + 3 * (size_t)idx[2];
    /* Solve [du1 du2; dv1 dv2] [a; b] = [1; 0] for the world step (a e1 + b e2) that moves u by one. */
    double du1 = uv[2] - uv[0], dv1 = uv[3] - uv[1], du2 = uv[4] - uv[0], dv2 = uv[5] - uv[1];
    double det = du1 * dv2 - du2 * dv1;
    assert_true(fabs(det) > 0);
    double a = dv2 / det, b = -dv1 / det;
    double x = a * (p1[0] - p0[0]) + b * (p2[0] - p0[0]), z = a * (p1[2] - p0[2]) + b * (p2[2] - p0[2]);
    double len = sqrt(x * x + z * z);
    u_dir[0] = x / len;
    u_dir[1] = z / len;
}

/* The 10-90 % width (texels) of the lit fraction against the signed distance to the shadow's boundary. */
static double edge_width(bool no_cache, double angle_deg)
{
    scene *probe = edge_scene(-1, NULL);
    double u_dir[2];
    floor_u_axis(probe, u_dir);
    scene_free(probe);
    scene *s = edge_scene(angle_deg, u_dir);
    scene_error err = {0};
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    assert_non_null(rt);
    srv_loop_desc d = {.s = s, .rt = rt, .seed = 3, .keep_views = true, .no_cache = no_cache};
    fxt_effects_on(&d, (const char *const[]){"shadow"}, 1);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, RES, RES, &id);
    srv_camera cam = {.position = {(float)centre[0], 0.9f, (float)centre[1]},
                      .target = {(float)centre[0], 0.0f, (float)centre[1]},
                      .up = {0, 0, -1},
                      .fov_deg = 100};
    srv_frame_stats st;
    fxt_frame(loop, &id, 1, &cam, &st);
    assert_int_equal(st.pixels_missing, 0);
    const float *lit = srv_viewer_view(loop, id, SRV_VIEW_SHADOW), *depth = srv_viewer_depth(loop, id);
    srv_camera_frame cf;
    assert_true(srv_camera_setup(&cam, RES, RES, &cf));
    /* Bins of 0.1 texel from -3 to +3 texels of signed distance (negative: inside the shadow). */
    enum { BINS = 60 };
    double sum[BINS] = {0}, count[BINS] = {0};
    double a = angle_deg * M_PI / 180.0;
    double e1[2] = {u_dir[0] * cos(a) - u_dir[1] * sin(a), u_dir[0] * sin(a) + u_dir[1] * cos(a)};
    double e2[2] = {-e1[1], e1[0]};
    for (uint32_t y = 0; y < RES; y++)
        for (uint32_t x = 0; x < RES; x++) {
            size_t p = (size_t)y * RES + x;
            if (!isfinite(depth[p]))
                continue;
            float dir[3];
            srv_camera_ray(&cf, (float)x + 0.5f, (float)y + 0.5f, dir);
            double px = cam.position[0] + depth[p] * dir[0] - centre[0];
            double pz = cam.position[2] + depth[p] * dir[2] - centre[1];
            double la = fabs(px * e1[0] + pz * e1[1]), lb = fabs(px * e2[0] + pz * e2[1]);
            double along = fmin(la, lb), across = fmax(la, lb);
            if (along > 0.35) /* away from the corners */
                continue;
            double texels = (across - 0.5) * density;
            int bin = (int)floor((texels + 3.0) / 0.1);
            if (bin < 0 || bin >= BINS)
                continue;
            sum[bin] += lit[p];
            count[bin] += 1;
        }
    double d10 = NAN, d90 = NAN, previous = 0.0;
    for (int b = 0; b < BINS; b++) {
        if (count[b] < 4)
            continue;
        double mean = sum[b] / count[b], at = -3.0 + (b + 0.5) * 0.1;
        if (isnan(d10) && mean >= 0.1)
            d10 = at - 0.1 * (mean - 0.1) / fmax(mean - previous, 1e-9);
        if (isnan(d90) && mean >= 0.9)
            d90 = at - 0.1 * (mean - 0.9) / fmax(mean - previous, 1e-9);
        previous = mean;
    }
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
    assert_false(isnan(d10) || isnan(d90));
    return d90 - d10;
}

static void test_shadow_edge_width(void **state)
{
    (void)state;
    const double angles[3] = {0.0, 22.5, 45.0};
    for (int i = 0; i < 3; i++) {
        double cached = edge_width(false, angles[i]);
        double baseline = edge_width(true, angles[i]);
        print_message("edge at %4.1f deg: 10-90 %% width %.2f texels cached, %.2f per pixel (no cache)\n",
                      angles[i], cached, baseline);
        assert_true(cached <= 1.0);
        assert_true(cached > 0.0);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_shadow_edge_width),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
