/* The reference renderer (server/engine/reference.h) and `fxcache ref`.
 *
 * Closed forms that can fail: an open plane under a uniform sky (albedo x sky, whichever effects run: the
 * probes carry the sky, so it must not be counted twice), direct light from a sun and a point light against
 * the analytic irradiance per pixel, an occluder's shadow against its analytic projection, and a closed
 * sphere lit from its centre whose indirect light is a geometric series in the albedo (truncated at 1, 2, 3
 * bounces and whole). A second method where no closed form exists: one bounce of the reference against the
 * engine's no-cache baseline on the embedded scene, within their combined noise. Then determinism (seed,
 * thread count), the half-sample noise estimate against the error measured with four times the samples, and
 * the command line: option errors, sim's frame numbers and cameras for traces and generators, and an
 * interrupted run. Small images and few samples keep it quick, also in the sanitizer build. */
#include "test_util.h"

#include "fxt_scene.h"
#include "image.h"
#include "reference.h"
#include "scene_internal.h"
#include "trace.h"

#include <dirent.h>
#include <fcntl.h>
#include <jansson.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

/* ---- helpers ----------------------------------------------------------------------------------------- */

/* The effects named (registry order indices set), and samples per name: {name, samples} pairs, NULL ended. */
static void effects_on(srv_ref_desc *d, const char *const *names, uint32_t count)
{
    uint32_t n = 0;
    const fx_effect *const *registry = fx_registry(&n);
    for (uint32_t i = 0; i < count; i++) {
        int32_t e = fx_find(registry, n, names[i]);
        if (e < 0)
            fail_msg("no effect named %s", names[i]);
        d->effect_on[e] = true;
    }
}

/* Sets the samples of the effect named `name`. */
static void set_samples(srv_ref_desc *d, const char *name, uint32_t samples)
{
    uint32_t n = 0;
    const fx_effect *const *registry = fx_registry(&n);
    int32_t e = fx_find(registry, n, name);
    assert_true(e >= 0);
    d->samples[e] = samples;
}

/* What the scene needs, as `fxcache ref` decides it (every shading effect the scene calls for). */
static void effects_needed(srv_ref_desc *d)
{
    uint32_t n = 0;
    const fx_effect *const *registry = fx_registry(&n);
    bool needed[SRV_MAX_EFFECTS] = {false};
    char why[SRV_MAX_EFFECTS][200];
    fx_needs(registry, n, d->s, needed, why);
    for (uint32_t e = 0; e < n; e++)
        d->effect_on[e] = needed[e] && registry[e]->shade;
}

/* One image with every output, owned by the caller (image_free). */
typedef struct image {
    uint32_t width, height;
    float *radiance, *half[2], *ao, *shadow;
    uint8_t *srgb;
    srv_ref_stats stats;
} ref_image;

static void image_free(ref_image *im)
{
    free(im->radiance);
    free(im->half[0]);
    free(im->half[1]);
    free(im->ao);
    free(im->shadow);
    free(im->srgb);
    memset(im, 0, sizeof *im);
}

/* Renders one image with desc (failing the test on any error). */
static void render(const srv_ref_desc *desc, const srv_camera *cam, uint32_t w, uint32_t h, uint32_t frame,
                   ref_image *im)
{
    memset(im, 0, sizeof *im);
    size_t n = (size_t)w * h;
    im->width = w;
    im->height = h;
    im->radiance = malloc(n * 3 * sizeof(float));
    im->half[0] = malloc(n * 3 * sizeof(float));
    im->half[1] = malloc(n * 3 * sizeof(float));
    im->ao = malloc(n * sizeof(float));
    im->shadow = malloc(n * sizeof(float));
    im->srgb = malloc(n * 3);
    assert_true(im->radiance && im->half[0] && im->half[1] && im->ao && im->shadow && im->srgb);
    srv_ref *ref = NULL;
    char err[256];
    fxc_result r = srv_ref_create(desc, &ref, err, sizeof err);
    if (r != FXC_OK)
        fail_msg("srv_ref_create: %s", err);
    srv_ref_image out = {.radiance = im->radiance,
                         .half = {im->half[0], im->half[1]},
                         .ao = im->ao,
                         .shadow = im->shadow,
                         .srgb = im->srgb};
    assert_int_equal(srv_ref_render(ref, cam, w, h, frame, &out, &im->stats, NULL, NULL), FXC_OK);
    srv_ref_free(ref);
}

/* Mean squared difference of two float arrays. */
static double mse(const float *a, const float *b, size_t n)
{
    double sum = 0;
    for (size_t i = 0; i < n; i++) {
        double d = (double)a[i] - b[i];
        sum += d * d;
    }
    return sum / (double)n;
}

/* The point where the ray from origin along dir meets the plane y = 0 (t > 0), in double. */
static bool hit_ground(const float origin[3], const double dir[3], double p[3])
{
    if (!(dir[1] < 0))
        return false;
    double t = -(double)origin[1] / dir[1];
    for (int k = 0; k < 3; k++)
        p[k] = origin[k] + t * dir[k];
    return true;
}

/* The unnormalised direction of the ray through image position (px, py) (the camera model). */
static void pixel_ray(const srv_camera_frame *f, double px, double py, double dir[3])
{
    double sx = (2.0 * px / f->width - 1.0) * f->tan_half_x,
           sy = (1.0 - 2.0 * py / f->height) * f->tan_half_y;
    for (int k = 0; k < 3; k++)
        dir[k] = f->forward[k] + sx * f->right[k] + sy * f->up[k];
}

/* A flat ground of side `side` metres centred at the origin, facing up, in cells x cells quads. */
static void add_ground(scene *s, double side, uint32_t cells)
{
    fxt_add_quad(s, "ground", (double[3]){-side / 2, 0, -side / 2}, (double[3]){0, 0, side},
                 (double[3]){side, 0, 0}, cells);
}

/* ---- (a) an open plane under a uniform sky ----------------------------------------------------------- */

/* With no lights, an open plane facing up sees only sky: AO is 1 and every path escapes at once, so compose's
 * model gives albedo x sky whether the sky comes in through the sky term (without probes) or through the
 * probes' indirect light that replaces it (with them); counted twice it would be 2 albedo x sky. Pixels that
 * miss are the sky. Every ray escapes, so both halves agree exactly: the noise estimate is 0. */
static void test_open_plane_under_sky(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    const float albedo[3] = {0.8f, 0.5f, 0.2f}, sky[3] = {0.3f * 2, 0.6f * 2, 0.9f * 2};
    memcpy(s->materials[0].diffuse, albedo, sizeof albedo);
    s->sky_color[0] = 0.3f, s->sky_color[1] = 0.6f, s->sky_color[2] = 0.9f;
    s->sky_intensity = 2.0f;
    add_ground(s, 200, 8);
    scene_rt *rt = fxt_finish_scene(s, 4, 1.0f);
    srv_camera cam = {.position = {0, 2, 0}, .target = {0, 1.2f, -5}, .fov_deg = 60};
    static const char *const all[] = {"shadow", "ao", "probes"}, *const ao_only[] = {"ao"};
    struct {
        const char *const *names;
        uint32_t count;
        bool needed;
    } cases[] = {{NULL, 0, true}, {ao_only, 1, false}, {NULL, 0, false}, {all, 3, false}};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        srv_ref_desc d = {.s = s, .rt = rt, .seed = 3, .threads = 2};
        if (cases[c].needed)
            effects_needed(&d);
        else
            effects_on(&d, cases[c].names, cases[c].count);
        set_samples(&d, "ao", 64);
        set_samples(&d, "shadow", 32);
        set_samples(&d, "probes", 32);
        ref_image im;
        render(&d, &cam, 48, 27, 0, &im);
        uint32_t ground = 0, skyward = 0;
        for (uint32_t y = 0; y < im.height; y++)
            for (uint32_t x = 0; x < im.width; x++) {
                size_t p = (size_t)y * im.width + x;
                srv_camera_frame f;
                assert_true(srv_camera_setup(&cam, im.width, im.height, &f));
                double dir[3], at[3];
                pixel_ray(&f, x + 0.5, y + 0.5, dir);
                bool on_ground = hit_ground(cam.position, dir, at) && fabs(at[0]) < 99 && fabs(at[2]) < 99;
                ground += on_ground;
                skyward += !on_ground;
                for (int k = 0; k < 3; k++) {
                    double expected = on_ground ? (double)albedo[k] * sky[k] : sky[k];
                    if (fabs(im.radiance[3 * p + k] - expected) > 1e-5 * expected)
                        fail_msg("case %zu pixel (%u, %u) channel %d: %.7g, expected %.7g", c, x, y, k,
                                 (double)im.radiance[3 * p + k], expected);
                }
                assert_true(im.ao[p] == 1.0f && im.shadow[p] == 1.0f);
            }
        assert_true(ground > 100 && skyward > 100);
        assert_true(im.stats.noise_rmse == 0.0);
        image_free(&im);
    }
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- (b) direct light against the analytic irradiance ------------------------------------------------ */

/* A sun and a point light over an open ground, no sky: compose's bracket is E_sun cos + I cos / d^2 at the
 * pixel centre, every shadow ray reaches its light, and no path brings anything back (a black sky, nothing
 * above). Checked per pixel against the point where the pixel's ray meets the plane, in double. */
static void test_direct_light_analytic(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    const float albedo = 0.6f;
    for (int k = 0; k < 3; k++)
        s->materials[0].diffuse[k] = albedo;
    add_ground(s, 40, 8);
    fxt_add_sun(s, 0.3f, -1.0f, 0.2f); /* intensity 1, white */
    scene_error err;
    scene_light lamp = {
        .type = SCENE_LIGHT_POINT, .position = {1, 3, -1}, .color = {1, 0.5f, 0.25f}, .intensity = 5};
    assert_int_equal(scene__add_light(s, &lamp, "test lamp", &err), SCENE_OK);
    scene_rt *rt = fxt_finish_scene(s, 4, 1.0f);
    srv_ref_desc d = {.s = s, .rt = rt, .seed = 5, .threads = 2};
    effects_needed(&d);
    uint32_t n = 0;
    const fx_effect *const *registry = fx_registry(&n);
    assert_true(d.effect_on[fx_find(registry, n, "shadow")] && d.effect_on[fx_find(registry, n, "probes")]);
    set_samples(&d, "shadow", 64);
    set_samples(&d, "probes", 16);
    srv_camera cam = {.position = {0, 3, 2.5f}, .target = {0, 0, 0}, .fov_deg = 60};
    ref_image im;
    render(&d, &cam, 40, 24, 0, &im);
    srv_camera_frame f;
    assert_true(srv_camera_setup(&cam, im.width, im.height, &f));
    double sun[3] = {-0.3, 1.0, -0.2}, len = sqrt(0.3 * 0.3 + 1 + 0.2 * 0.2);
    double worst = 0;
    for (uint32_t y = 0; y < im.height; y++)
        for (uint32_t x = 0; x < im.width; x++) {
            double dir[3], p[3];
            pixel_ray(&f, x + 0.5, y + 0.5, dir);
            assert_true(hit_ground(cam.position, dir, p));
            double to_lamp[3] = {1 - p[0], 3 - p[1], -1 - p[2]};
            double d2 = to_lamp[0] * to_lamp[0] + to_lamp[1] * to_lamp[1] + to_lamp[2] * to_lamp[2];
            double lamp_cos = to_lamp[1] / sqrt(d2), sun_cos = sun[1] / len;
            const double colour[3] = {1, 0.5, 0.25};
            for (int k = 0; k < 3; k++) {
                double expected = albedo * (sun_cos + 5.0 * lamp_cos / d2 * colour[k]);
                double got = im.radiance[3 * ((size_t)y * im.width + x) + k];
                worst = fmax(worst, fabs(got - expected) / expected);
            }
        }
    if (worst > 1e-4)
        fail_msg("worst relative error of the direct term %.3g", worst);
    assert_true(im.stats.noise_rmse == 0.0);
    image_free(&im);
    scene_rt_free(rt);
    scene_free(s);
}

/* A sun and a sky at 3e38 (colour x intensity just under FLT_MAX): radiance saturates at FLT_MAX, and the
 * noise, a sum of squared half differences, stays finite (saturated) instead of infinite; before, the
 * image's record in ref.json could not be written (JSON has no infinity) and `fxcache report` stopped. */
static void test_saturated_noise_finite(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    add_ground(s, 40, 8);
    fxt_add_quad(s, "roof", (double[3]){-1, 1, -1}, (double[3]){2, 0, 0}, (double[3]){0, 0, 2}, 1);
    fxt_add_sun(s, 0.3f, -1.0f, 0.2f);
    s->lights[0].intensity = 3e38f;
    s->sky_intensity = 3e38f;
    scene_rt *rt = fxt_finish_scene(s, 4, 1.0f);
    srv_ref_desc d = {.s = s, .rt = rt, .seed = 5, .threads = 2};
    effects_needed(&d);
    set_samples(&d, "shadow", 32);
    set_samples(&d, "ao", 16);
    set_samples(&d, "probes", 4);
    srv_camera cam = {.position = {0, 3, 2.5f}, .target = {0, 0, 0}, .fov_deg = 60};
    ref_image im;
    render(&d, &cam, 24, 14, 0, &im);
    for (size_t i = 0; i < (size_t)im.width * im.height * 3; i++)
        assert_true(isfinite(im.radiance[i]) && im.radiance[i] >= 0);
    print_message("noise %g (visible %g), mean radiance %g\n", im.stats.noise_rmse,
                  im.stats.noise_rmse_visible, im.stats.mean_radiance[0]);
    assert_true(isfinite(im.stats.noise_rmse) && isfinite(im.stats.noise_rmse_visible));
    assert_true(isfinite(im.stats.mean_radiance[0]) && im.stats.mean_radiance[0] > 1e37);
    image_free(&im);
    scene_rt_free(rt);
    scene_free(s);
}

/* A square occluder above the ground under the sun: a pixel whose footprint (with a pixel's margin) lies
 * inside the occluder's projection along the sun is black (no sky, and paths from below meet the occluder's
 * back face, which is dark), one wholly outside it gets the analytic sun term, one across its edge is in
 * between; the shadow view says the same with 0 and 1. */
static void test_shadow_analytic(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    add_ground(s, 40, 8);
    /* The occluder at height 1.5, x and z in [-0.5, 0.5], facing up (from below it is a back face). */
    fxt_add_quad(s, "occluder", (double[3]){-0.5, 1.5, -0.5}, (double[3]){0, 0, 1}, (double[3]){1, 0, 0}, 1);
    fxt_add_sun(s, 0.4f, -1.0f, 0.3f);
    scene_rt *rt = fxt_finish_scene(s, 8, 1.0f);
    srv_ref_desc d = {.s = s, .rt = rt, .seed = 9, .threads = 2};
    effects_needed(&d);
    set_samples(&d, "shadow", 64);
    set_samples(&d, "probes", 16);
    /* Below the occluder, looking down: it is never in view (every ray goes down from under it). */
    srv_camera cam = {.position = {0.6f, 1.3f, 2.2f}, .target = {0.6f, 0, 0.45f}, .fov_deg = 50};
    ref_image im;
    render(&d, &cam, 64, 36, 0, &im);
    srv_camera_frame f;
    assert_true(srv_camera_setup(&cam, im.width, im.height, &f));
    /* The shadow: the square moved along the sun by 1.5 / 1 of its horizontal components. */
    const double sx0 = -0.5 + 0.6, sx1 = 0.5 + 0.6, sz0 = -0.5 + 0.45, sz1 = 0.5 + 0.45;
    const double sun_term = 0.5 * (1.0 / sqrt(0.4 * 0.4 + 1 + 0.3 * 0.3)); /* albedo 0.5 x cos */
    uint32_t dark = 0, lit = 0, edge = 0;
    for (uint32_t y = 0; y < im.height; y++)
        for (uint32_t x = 0; x < im.width; x++) {
            size_t p = (size_t)y * im.width + x;
            double dir[3], at[3];
            pixel_ray(&f, x + 0.5, y + 0.5, dir);
            /* Pixels that see the occluder are not about the ground. */
            double t_occ = (1.5 - cam.position[1]) / dir[1], ox = cam.position[0] + t_occ * dir[0],
                   oz = cam.position[2] + t_occ * dir[2];
            if (t_occ > 0 && ox >= -0.5 && ox <= 0.5 && oz >= -0.5 && oz <= 0.5)
                continue;
            assert_true(hit_ground(cam.position, dir, at));
            int inside = 0, outside = 0;
            for (int c = 0; c < 4; c++) { /* the pixel grown by one pixel on every side */
                double corner[3];
                pixel_ray(&f, x + ((c & 1) ? 2.0 : -1.0), y + ((c & 2) ? 2.0 : -1.0), dir);
                assert_true(hit_ground(cam.position, dir, corner));
                bool in = corner[0] > sx0 && corner[0] < sx1 && corner[2] > sz0 && corner[2] < sz1;
                inside += in;
                outside += !in;
            }
            /* Wholly outside when all corners lie beyond one edge of the square. */
            bool beyond = false;
            for (int side = 0; side < 4 && !beyond; side++) {
                bool all = true;
                for (int c = 0; c < 4; c++) {
                    double corner[3];
                    pixel_ray(&f, x + ((c & 1) ? 2.0 : -1.0), y + ((c & 2) ? 2.0 : -1.0), dir);
                    hit_ground(cam.position, dir, corner);
                    double v = side == 0   ? sx0 - corner[0]
                               : side == 1 ? corner[0] - sx1
                               : side == 2 ? sz0 - corner[2]
                                           : corner[2] - sz1;
                    all = all && v > 0;
                }
                beyond = all;
            }
            const float *rad = im.radiance + 3 * p;
            if (inside == 4) {
                dark++;
                assert_true(rad[0] == 0.0f && rad[1] == 0.0f && rad[2] == 0.0f && im.shadow[p] == 0.0f);
            } else if (beyond) {
                lit++;
                for (int k = 0; k < 3; k++)
                    if (fabs(rad[k] - sun_term) > 1e-4 * sun_term)
                        fail_msg("lit pixel (%u, %u): %.6g, expected %.6g", x, y, (double)rad[k], sun_term);
                assert_true(im.shadow[p] == 1.0f);
            } else {
                edge++;
                assert_true(rad[0] >= 0.0f && rad[0] <= sun_term * (1 + 1e-4));
            }
            (void)outside;
        }
    print_message("shadow: %u pixels in it, %u lit, %u across its edge\n", dark, lit, edge);
    if (dark < 20 || lit < 20 || edge < 5)
        fail_msg("the view should hold shadow, light and the edge: %u dark, %u lit, %u across", dark, lit,
                 edge);
    image_free(&im);
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- (c) the path tracer: a closed sphere lit from its centre ---------------------------------------- */

/* Inside a closed sphere of radius R and albedo rho with a point light of intensity I at its centre, the
 * direct light is the same everywhere (compose's bracket: I / R^2, cos 1), so the radiance is uniform and
 * each bounce multiplies it by rho: a pixel sees rho (I / R^2) (1 + rho + ... + rho^B) with B bounces, and
 * rho (I / R^2) / (1 - rho) with all of them. The sphere is 48 x 24 facets (their planes within 0.3 % of R:
 * the tolerance's fixed part), no sky (AO is left out). */
static void test_closed_sphere_series(void **state)
{
    (void)state;
    const double radius = 2.0, rho = 0.7, intensity = 3.0;
    enum { SEGMENTS = 48, RINGS = 24 };
    scene *s = fxt_new_scene();
    for (int k = 0; k < 3; k++)
        s->materials[0].diffuse[k] = (float)rho;
    uint32_t vertex_count = 2 + (RINGS - 1) * SEGMENTS, triangle_count = 2 * SEGMENTS * (RINGS - 1);
    float *positions = malloc(sizeof(float) * 3 * vertex_count);
    uint32_t *indices = malloc(sizeof(uint32_t) * 3 * triangle_count);
    assert_true(positions && indices);
    positions[0] = 0, positions[1] = (float)radius, positions[2] = 0;  /* north pole */
    positions[3] = 0, positions[4] = (float)-radius, positions[5] = 0; /* south pole */
    for (uint32_t j = 1; j < RINGS; j++)
        for (uint32_t i = 0; i < SEGMENTS; i++) {
            double theta = M_PI * j / RINGS, phi = 2 * M_PI * i / SEGMENTS;
            float *p = positions + 3 * (2 + (j - 1) * SEGMENTS + i);
            p[0] = (float)(radius * sin(theta) * cos(phi));
            p[1] = (float)(radius * cos(theta));
            p[2] = (float)(radius * sin(theta) * sin(phi));
        }
    uint32_t t = 0;
#define RING_VERTEX(j, i) (2 + ((j)-1) * SEGMENTS + ((i) % SEGMENTS))
    for (uint32_t i = 0; i < SEGMENTS; i++) {
        uint32_t tris[2][3] = {{0, RING_VERTEX(1, i), RING_VERTEX(1, i + 1)},
                               {1, RING_VERTEX(RINGS - 1, i + 1), RING_VERTEX(RINGS - 1, i)}};
        memcpy(indices + 3 * t, tris, sizeof tris);
        t += 2;
        for (uint32_t j = 1; j + 1 < RINGS; j++) {
            uint32_t quad[6] = {RING_VERTEX(j, i), RING_VERTEX(j + 1, i),     RING_VERTEX(j + 1, i + 1),
                                RING_VERTEX(j, i), RING_VERTEX(j + 1, i + 1), RING_VERTEX(j, i + 1)};
            memcpy(indices + 3 * t, quad, sizeof quad);
            t += 2;
        }
    }
#undef RING_VERTEX
    assert_int_equal(t, triangle_count);
    /* Turn every triangle to face the centre. */
    for (uint32_t k = 0; k < triangle_count; k++) {
        const float *a = positions + 3 * indices[3 * k], *b = positions + 3 * indices[3 * k + 1],
                    *c = positions + 3 * indices[3 * k + 2];
        double e1[3], e2[3], centroid = 0;
        for (int q = 0; q < 3; q++) {
            e1[q] = (double)b[q] - a[q];
            e2[q] = (double)c[q] - a[q];
        }
        double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                       e1[0] * e2[1] - e1[1] * e2[0]};
        for (int q = 0; q < 3; q++)
            centroid += n[q] * ((double)a[q] + b[q] + c[q]);
        if (centroid > 0) {
            uint32_t swap = indices[3 * k + 1];
            indices[3 * k + 1] = indices[3 * k + 2];
            indices[3 * k + 2] = swap;
        }
    }
    scene_error err;
    assert_int_equal(
        scene__add_mesh(s, "sphere", positions, vertex_count, indices, triangle_count, NULL, 0, NULL, &err),
        SCENE_OK);
    free(positions);
    free(indices);
    scene_light lamp = {
        .type = SCENE_LIGHT_POINT, .position = {0, 0, 0}, .color = {1, 1, 1}, .intensity = (float)intensity};
    assert_int_equal(scene__add_light(s, &lamp, "centre", &err), SCENE_OK);
    scene_rt *rt = fxt_finish_scene(s, 8, 0.5f);
    for (uint32_t k = 0; k < s->triangle_count; k++) { /* the precondition: every normal faces the centre */
        const float *n = s->tri_normal + 3 * (size_t)k, *a = s->positions + 3 * (size_t)s->indices[3 * k];
        assert_true(n[0] * a[0] + n[1] * a[1] + n[2] * a[2] < 0);
    }
    const double direct = rho * intensity / (radius * radius);
    srv_camera cam = {.position = {0.6f, 0.3f, 0.4f}, .target = {-1, -0.2f, -1}, .fov_deg = 60};
    const uint32_t bounces[] = {1, 2, 3, 0};
    for (size_t b = 0; b < sizeof bounces / sizeof bounces[0]; b++) {
        srv_ref_desc d = {.s = s, .rt = rt, .seed = 11, .threads = 2, .max_bounces = bounces[b]};
        effects_needed(&d);
        uint32_t n = 0;
        const fx_effect *const *registry = fx_registry(&n);
        assert_false(d.effect_on[fx_find(registry, n, "ao")]); /* no sky */
        set_samples(&d, "shadow", 32);
        set_samples(&d, "probes", 64);
        ref_image im;
        render(&d, &cam, 32, 24, 0, &im);
        double expected = 0, term = direct;
        for (uint32_t k = 0; bounces[b] == 0 ? k < 200 : k <= bounces[b]; k++, term *= rho)
            expected += term;
        double mean = (im.stats.mean_radiance[0] + im.stats.mean_radiance[1] + im.stats.mean_radiance[2]) / 3;
        double standard_error = im.stats.noise_rmse / sqrt((double)im.stats.pixels);
        double tolerance = 0.006 * expected + 4 * standard_error;
        print_message("closed sphere, %u bounces (0: all): mean radiance %.5f, series %.5f, tolerance %.5f\n",
                      bounces[b], mean, expected, tolerance);
        if (fabs(mean - expected) > tolerance)
            fail_msg("%u bounces: mean radiance %.5f, the series gives %.5f (tolerance %.5f, noise %.5f)",
                     bounces[b], mean, expected, tolerance, im.stats.noise_rmse);
        assert_int_equal(im.stats.pixels_visible, im.stats.pixels);
        image_free(&im);
    }
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- (c) a second method: one bounce against the engine's no-cache baseline --------------------------- */

/* On the embedded scene, the reference with its paths cut after one bounce estimates what the no-cache
 * baseline estimates per pixel (AO with 64 rays, 16 shadow rays over the footprint, one bounce of
 * probe_rays rays with shadow rays at the hits): the same expectation, so their mean squared difference is
 * their two variances and no more. The baseline's variance comes from two seeds of it, the reference's
 * from its halves. A bias of a fifth of the noise per pixel would show. */
static void test_one_bounce_matches_no_cache(void **state)
{
    fxt_scene_fixture *fx = *state;
    const uint32_t w = 64, h = 36;
    const size_t n = (size_t)w * h * 3;
    srv_camera cam = srv_camera_default(fx->s);
    float *baseline[2];
    for (int run = 0; run < 2; run++) {
        srv_loop_desc d = {.s = fx->s,
                           .rt = fx->rt,
                           .seed = 21 + (uint32_t)run,
                           .threads = 2,
                           .no_cache = true,
                           .probe_rays = 1024};
        static const char *const names[] = {"shadow", "ao", "probes"};
        fxt_effects_on(&d, names, 3);
        srv_viewer_id id;
        srv_loop *loop = fxt_loop(&d, 1, w, h, &id);
        srv_frame_stats st;
        fxt_frame(loop, &id, 1, &cam, &st);
        baseline[run] = malloc(n * sizeof(float));
        assert_non_null(baseline[run]);
        memcpy(baseline[run], srv_viewer_radiance(loop, id), n * sizeof(float));
        srv_loop_free(loop);
    }
    srv_ref_desc d = {.s = fx->s, .rt = fx->rt, .seed = 7, .threads = 2, .max_bounces = 1};
    effects_needed(&d);
    set_samples(&d, "ao", 256);
    set_samples(&d, "shadow", 64);
    set_samples(&d, "probes", 512);
    ref_image im;
    render(&d, &cam, w, h, 0, &im);
    double baseline_variance = mse(baseline[0], baseline[1], n) / 2;
    double reference_variance = im.stats.noise_rmse * im.stats.noise_rmse;
    double measured = mse(im.radiance, baseline[0], n), expected = baseline_variance + reference_variance;
    double mean_ref = 0, mean_base = 0;
    for (size_t i = 0; i < n; i++) {
        mean_ref += im.radiance[i];
        mean_base += baseline[0][i];
    }
    mean_ref /= (double)n;
    mean_base /= (double)n;
    print_message(
        "one bounce: MSE against the baseline %.4g, their variances %.4g + %.4g; means %.5f, %.5f\n",
        measured, baseline_variance, reference_variance, mean_ref, mean_base);
    assert_true(measured > 0.8 * expected && measured < 1.25 * expected);
    assert_true(fabs(mean_ref - mean_base) < 4 * sqrt(expected / (double)(w * h)));
    free(baseline[0]);
    free(baseline[1]);
    image_free(&im);
}

/* ---- (d) determinism --------------------------------------------------------------------------------- */

/* The same seed gives the same bytes in every output, for one thread and two; another seed or another frame
 * gives other noise. */
static void test_deterministic(void **state)
{
    fxt_scene_fixture *fx = *state;
    srv_camera cam = srv_camera_default(fx->s);
    ref_image im[5];
    for (int i = 0; i < 5; i++) {
        srv_ref_desc d = {.s = fx->s, .rt = fx->rt, .seed = i == 3 ? 43 : 42, .threads = i == 1 ? 1 : 2};
        effects_needed(&d);
        set_samples(&d, "ao", 32);
        set_samples(&d, "shadow", 32);
        set_samples(&d, "probes", 8);
        render(&d, &cam, 37, 21, i == 4 ? 1 : 0, &im[i]); /* a size that is no multiple of a tile */
    }
    size_t n = (size_t)37 * 21;
    for (int i = 1; i <= 2; i++) {
        assert_memory_equal(im[0].radiance, im[i].radiance, n * 3 * sizeof(float));
        assert_memory_equal(im[0].half[0], im[i].half[0], n * 3 * sizeof(float));
        assert_memory_equal(im[0].half[1], im[i].half[1], n * 3 * sizeof(float));
        assert_memory_equal(im[0].ao, im[i].ao, n * sizeof(float));
        assert_memory_equal(im[0].shadow, im[i].shadow, n * sizeof(float));
        assert_memory_equal(im[0].srgb, im[i].srgb, n * 3);
        assert_true(im[0].stats.noise_rmse == im[i].stats.noise_rmse);
        assert_true(im[0].stats.rays_total == im[i].stats.rays_total);
    }
    assert_true(mse(im[0].radiance, im[3].radiance, n * 3) > 0);
    assert_true(mse(im[0].radiance, im[4].radiance, n * 3) > 0);
    /* The image is the mean of its halves, and the display image compose's tone map of it. */
    for (size_t i = 0; i < n * 3; i++)
        assert_true(im[0].radiance[i] == 0.5f * im[0].half[0][i] + 0.5f * im[0].half[1][i]);
    for (int i = 0; i < 5; i++)
        image_free(&im[i]);
}

/* ---- (e) the noise estimate ---------------------------------------------------------------------------- */

/* The half-sample estimate of an image's noise against its actual error, measured against a render with four
 * times the samples and another seed (whose own noise, from its halves, is taken out of the difference):
 * within a factor 1.5. */
static void test_noise_estimate(void **state)
{
    fxt_scene_fixture *fx = *state;
    srv_camera cam = srv_camera_default(fx->s);
    ref_image im[2];
    for (int i = 0; i < 2; i++) {
        uint32_t scale = i ? 4 : 1;
        srv_ref_desc d = {.s = fx->s, .rt = fx->rt, .seed = i ? 77 : 76, .threads = 2};
        effects_needed(&d);
        set_samples(&d, "ao", 32 * scale);
        set_samples(&d, "shadow", 32 * scale);
        set_samples(&d, "probes", 16 * scale);
        render(&d, &cam, 64, 36, 0, &im[i]);
    }
    size_t n = (size_t)64 * 36 * 3;
    double estimated = im[0].stats.noise_rmse;
    double actual2 = mse(im[0].radiance, im[1].radiance, n) - im[1].stats.noise_rmse * im[1].stats.noise_rmse;
    assert_true(actual2 > 0);
    double ratio = estimated / sqrt(actual2);
    print_message("noise: estimated %.5f, measured %.5f (ratio %.3f); 4x samples: estimated %.5f\n",
                  estimated, sqrt(actual2), ratio, im[1].stats.noise_rmse);
    assert_true(ratio > 1 / 1.5 && ratio < 1.5);
    /* Four times the samples: about half the noise. */
    assert_true(im[1].stats.noise_rmse < 0.7 * estimated && im[1].stats.noise_rmse > 0.35 * estimated);
    image_free(&im[0]);
    image_free(&im[1]);
}

/* ---- the library's refusals ---------------------------------------------------------------------------- */

static uint64_t no_reference_eval(const fx_context *ctx, const fx_point *point, fx_shade_point *out)
{
    (void)ctx, (void)point, (void)out;
    return 0;
}

/* Samples that do not split into two halves of whole sets, an effect that shades without a reference
 * estimator, a degenerate camera, a bad size. */
static void test_refusals(void **state)
{
    fxt_scene_fixture *fx = *state;
    srv_ref *ref = NULL;
    char err[256];
    srv_ref_desc d = {.s = fx->s, .rt = fx->rt, .threads = 1};
    effects_needed(&d);
    set_samples(&d, "shadow", 48);
    assert_int_equal(srv_ref_create(&d, &ref, err, sizeof err), FXC_ERR_INVALID);
    assert_non_null(strstr(err, "shadow"));
    set_samples(&d, "shadow", 0);
    set_samples(&d, "ao", 5);
    assert_int_equal(srv_ref_create(&d, &ref, err, sizeof err), FXC_ERR_INVALID);
    assert_non_null(strstr(err, "ao"));
    fx_effect plain = {.name = "plain", .eval = no_reference_eval};
    const fx_effect *list[] = {&plain};
    srv_ref_desc own = {.s = fx->s, .rt = fx->rt, .effects = list, .effect_count = 1, .effect_on = {true}};
    assert_int_equal(srv_ref_create(&own, &ref, err, sizeof err), FXC_ERR_EFFECTS);
    assert_non_null(strstr(err, "plain"));
    srv_ref_desc good = {.s = fx->s, .rt = fx->rt, .threads = 1};
    assert_int_equal(srv_ref_create(&good, &ref, err, sizeof err), FXC_OK);
    float pixel[3];
    srv_ref_image out = {.radiance = pixel};
    srv_camera degenerate = {.position = {1, 1, 1}, .target = {1, 1, 1}, .fov_deg = 60};
    assert_int_equal(srv_ref_render(ref, &degenerate, 1, 1, 0, &out, NULL, NULL, NULL), FXC_ERR_CAMERA);
    srv_camera cam = srv_camera_default(fx->s);
    assert_int_equal(srv_ref_render(ref, &cam, 0, 1, 0, &out, NULL, NULL, NULL), FXC_ERR_INVALID);
    assert_int_equal(srv_ref_render(ref, &cam, 1, 1, 0, &(srv_ref_image){0}, NULL, NULL, NULL),
                     FXC_ERR_INVALID);
    srv_ref_free(ref);
}

/* ---- (f) the command line ------------------------------------------------------------------------------ */

static char out_buf[1 << 16], err_buf[1 << 14];

/* A scratch path copied out of fxt_tmp_path's static buffer. */
static void tmp_path(char *dst, size_t cap, const char *name)
{
    int n = snprintf(dst, cap, "%s", fxt_tmp_path(name));
    assert_true(n > 0 && (size_t)n < cap);
}

/* Bad options: exit 2 and one line on stderr naming the option (and the value where there is one). */
static void test_cli_option_errors(void **state)
{
    (void)state;
    char dir[1024];
    tmp_path(dir, sizeof dir, "errors_out");
    static const struct {
        const char *args, *needle1, *needle2;
    } cases[] = {
        {"--ao-samples 3", "--ao-samples", "'3'"},
        {"--ao-samples 0", "--ao-samples", "'0'"},
        {"--shadow-rays 48", "--shadow-rays", "'48'"},
        {"--paths abc", "--paths", "'abc'"},
        {"--max-bounces 300", "--max-bounces", "'300'"},
        {"--res 0x10", "--res", "'0x10'"},
        {"--camera nope", "--camera", "'nope'"},
        {"--every -1", "--every", "'-1'"},
        {"--fps 0", "--fps", "'0'"},
        {"--threads x", "--threads", "'x'"},
        {"--effects nope", "--effects", "'nope'"},
        {"--bias ao=1", "unknown option", "--bias"},
        {"--trace a.trace --camera walk", "--camera", "--trace"},
        {"--trace a.trace --viewers 2", "--viewers 2", "1 traces"},
        {"extra", "unexpected argument", "'extra'"},
        {"--paths", "--paths", "needs a value"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char args[2048];
        snprintf(args, sizeof args, "ref --out '%s' %s", dir, cases[i].args);
        int rc = fxt_run_cli(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf);
        size_t len = strlen(err_buf);
        if (rc != 2 || len < 2 || err_buf[len - 1] != '\n' || memchr(err_buf, '\n', len - 1) ||
            !strstr(err_buf, cases[i].needle1) || !strstr(err_buf, cases[i].needle2) ||
            strncmp(err_buf, "fxcache ref: ", 13) != 0)
            fail_msg("fxcache %s: exit %d, stderr '%s' (expected exit 2 and one line with %s and %s)", args,
                     rc, err_buf, cases[i].needle1, cases[i].needle2);
    }
    /* --out is required. */
    assert_int_equal(fxt_run_cli("ref --ao-samples 4", out_buf, sizeof out_buf, err_buf, sizeof err_buf), 2);
    assert_non_null(strstr(err_buf, "--out"));
    /* A trace that cannot be read is a failure of the run (exit 1, the file named), as in sim. */
    char args[2048];
    snprintf(args, sizeof args, "ref --out '%s' --trace '%s'", dir, fxt_tmp_path("absent.trace"));
    assert_int_equal(fxt_run_cli(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 1);
    assert_non_null(strstr(err_buf, "absent.trace"));
    /* --help tells the options and exits 0. */
    assert_int_equal(fxt_run_cli("ref --help", out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    static const char *const documented[] = {
        "--trace",   "--every",      "--fps",         "--camera",  "--viewers",     "--frames",
        "--res",     "--ao-samples", "--shadow-rays", "--paths",   "--max-bounces", "--seed",
        "--threads", "--out",        "--views",       "--effects", "--scene"};
    for (size_t i = 0; i < sizeof documented / sizeof documented[0]; i++)
        assert_non_null(strstr(out_buf, documented[i]));
}

static json_t *load_json(const char *path)
{
    json_error_t error;
    json_t *root = json_load_file(path, 0, &error);
    if (!root)
        fail_msg("%s: %s", path, error.text);
    return root;
}

/* Removes the files of a folder (not its subfolders), so a test starts from nothing. */
static void clear_dir(const char *dir)
{
    DIR *d = opendir(dir);
    if (!d)
        return;
    for (struct dirent *e; (e = readdir(d)) != NULL;) {
        char path[1400];
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        if (e->d_name[0] != '.')
            remove(path);
    }
    closedir(d);
}

/* The PNG names in a folder, sorted, joined by spaces. */
static void png_names(const char *dir, char *out, size_t cap)
{
    char names[64][64];
    uint32_t count = 0;
    DIR *d = opendir(dir);
    assert_non_null(d);
    for (struct dirent *e; (e = readdir(d)) != NULL;) {
        size_t len = strlen(e->d_name);
        if (len > 4 && strcmp(e->d_name + len - 4, ".png") == 0 && count < 64)
            snprintf(names[count++], sizeof names[0], "%s", e->d_name);
    }
    closedir(d);
    qsort(names, count, sizeof names[0], (int (*)(const void *, const void *))strcmp);
    out[0] = 0;
    for (uint32_t i = 0; i < count; i++) {
        strncat(out, names[i], cap - strlen(out) - 1);
        strncat(out, " ", cap - strlen(out) - 1);
    }
}

/* Traces: ref renders the frames `sim --trace ... --save-every K` saves, under the same names, each at sim's
 * time start + f / fps, with the trace's camera of that time; ref.json records what was done. */
static void test_cli_trace_frames_match_sim(void **state)
{
    (void)state;
    char a[1024], b[1024], sim_dir[1024], ref_dir[1024], args[4096];
    /* Viewer 0 from t = 0.5 to 1.4, ten cameras; viewer 1 from 0.8 to 1.1. */
    char text[4096] = "fxcache-trace 2\nresolution 24 14\n";
    for (int i = 0; i < 10; i++)
        snprintf(text + strlen(text), sizeof text - strlen(text), "%.1f %.2f 2 3 -1 -0.4 -1 60\n",
                 0.5 + 0.1 * i, 4.0 - 0.1 * i);
    snprintf(a, sizeof a, "%s", fxt_write_file("a.trace", text));
    snprintf(text, sizeof text, "fxcache-trace 1\n0.8 -3 2 2 1 -0.3 -1 50\n1.1 -2.5 2 2 1 -0.3 -1 50\n");
    snprintf(b, sizeof b, "%s", fxt_write_file("b.trace", text));
    tmp_path(sim_dir, sizeof sim_dir, "trace_sim");
    tmp_path(ref_dir, sizeof ref_dir, "trace_ref");
    clear_dir(sim_dir);
    clear_dir(ref_dir);
    snprintf(args, sizeof args,
             "sim --trace '%s' --trace '%s' --fps 10 --save-every 3 --res 16x9 --out '%s' --quiet", a, b,
             sim_dir);
    assert_int_equal(fxt_run_cli(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    snprintf(args, sizeof args,
             "ref --trace '%s' --trace '%s' --fps 10 --every 3 --res 16x9 --ao-samples 4 --shadow-rays 32 "
             "--paths 2 --out '%s' --quiet",
             a, b, ref_dir);
    assert_int_equal(fxt_run_cli(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    char sim_names[4096], ref_names[4096];
    png_names(sim_dir, sim_names, sizeof sim_names);
    png_names(ref_dir, ref_names, sizeof ref_names);
    assert_string_equal(sim_names, ref_names);
    assert_string_equal(ref_names,
                        "frame_0000_viewer_00.png frame_0003_viewer_00.png frame_0003_viewer_01.png "
                        "frame_0006_viewer_00.png frame_0006_viewer_01.png frame_0009_viewer_00.png ");
    /* The same resolution rule as ref: --res wins over the trace's own 24 x 14 (cli_cameras.c). */
    char png[1100], msg[256];
    snprintf(png, sizeof png, "%s/frame_0000_viewer_00.png", sim_dir);
    uint32_t pw = 0, ph = 0;
    float *pixels = NULL;
    assert_int_equal(scene_image_read_rgb(png, &pw, &ph, &pixels, msg, sizeof msg), 0);
    free(pixels);
    assert_int_equal(pw, 16);
    assert_int_equal(ph, 9);
    char record[1100];
    snprintf(record, sizeof record, "%s/ref.json", ref_dir);
    json_t *root = load_json(record);
    json_t *images = json_object_get(root, "images");
    assert_int_equal(json_array_size(images), 6);
    assert_int_equal(json_integer_value(json_object_get(root, "images_planned")), 6);
    assert_true(json_is_false(json_object_get(root, "interrupted")));
    size_t i;
    json_t *image;
    json_array_foreach(images, i, image)
    {
        json_int_t frame = json_integer_value(json_object_get(image, "frame"));
        double time = json_real_value(json_object_get(image, "time_s"));
        assert_true(fabs(time - (0.5 + frame / 10.0)) < 1e-9);
        /* Viewer 0's camera is its trace line of that time: x = 4.0 - 0.1 line, line = frame. */
        if (json_integer_value(json_object_get(image, "viewer")) == 0) {
            double x = json_real_value(
                json_array_get(json_object_get(json_object_get(image, "camera"), "position"), 0));
            assert_true(fabs(x - (4.0 - 0.1 * (double)frame)) < 1e-6);
            assert_int_equal(json_integer_value(json_object_get(image, "width")), 16); /* --res wins */
        }
        assert_true(json_integer_value(json_object_get(json_object_get(image, "rays"), "total")) > 0);
        assert_true(json_real_value(json_object_get(image, "noise_rmse")) >= 0);
        assert_true(json_is_array(json_object_get(image, "mean_radiance")));
    }
    json_decref(root);
}

/* Generators: the same cameras as sim with the same seed (checked against what sim --record writes), and
 * --views writes the AO and shadow terms. */
static void test_cli_generator_cameras_match_sim(void **state)
{
    (void)state;
    char rec_dir[1024], ref_dir[1024], args[4096], path[1200];
    tmp_path(rec_dir, sizeof rec_dir, "gen_record");
    tmp_path(ref_dir, sizeof ref_dir, "gen_ref");
    clear_dir(rec_dir);
    clear_dir(ref_dir);
    snprintf(args, sizeof args,
             "sim --camera walk --viewers 2 --frames 5 --seed 9 --res 8x6 --record '%s' --quiet", rec_dir);
    assert_int_equal(fxt_run_cli(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    snprintf(args, sizeof args,
             "ref --camera walk --viewers 2 --frames 5 --every 2 --seed 9 --res 16x9 --ao-samples 4 "
             "--shadow-rays 32 --paths 2 --views --threads 1 --out '%s'",
             ref_dir);
    assert_int_equal(fxt_run_cli(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    assert_non_null(strstr(out_buf, "frame 0004 viewer 01"));
    snprintf(path, sizeof path, "%s/ref.json", ref_dir);
    json_t *root = load_json(path);
    json_t *images = json_object_get(root, "images");
    assert_int_equal(json_array_size(images), 6); /* frames 0, 2, 4 x 2 viewers */
    scene_error serr;
    scene *s = scene_create_default(NULL, &serr);
    assert_non_null(s);
    size_t i;
    json_t *image;
    json_array_foreach(images, i, image)
    {
        uint32_t frame = (uint32_t)json_integer_value(json_object_get(image, "frame"));
        uint32_t viewer = (uint32_t)json_integer_value(json_object_get(image, "viewer"));
        snprintf(path, sizeof path, "%s/viewer_%02u.trace", rec_dir, viewer);
        char err[256];
        srv_trace *t = srv_trace_read(path, err, sizeof err);
        assert_non_null(t);
        srv_camera expected = srv_trace_camera(t, s, frame);
        json_t *camera = json_object_get(image, "camera");
        for (int k = 0; k < 3; k++) {
            double pos = json_real_value(json_array_get(json_object_get(camera, "position"), (size_t)k));
            assert_true(fabs(pos - expected.position[k]) < 1e-5);
        }
        srv_trace_free(t);
        static const char *const files[] = {".exr", ".png", "_ao.exr", "_shadow.exr"};
        for (size_t f = 0; f < 4; f++) {
            snprintf(path, sizeof path, "%s/frame_%04u_viewer_%02u%s", ref_dir, frame, viewer, files[f]);
            assert_int_equal(access(path, R_OK), 0);
        }
    }
    scene_free(s);
    json_t *samples = json_object_get(root, "samples");
    assert_int_equal(json_integer_value(json_object_get(json_object_get(samples, "ao"), "per_pixel")), 4);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(samples, "probes"), "per_pixel")), 2);
    json_decref(root);
}

/* SIGTERM during a long run: the image being rendered is finished and written, ref.json lists exactly the
 * images on disk and says interrupted, and the exit status is 0. */
static void test_cli_interrupted(void **state)
{
    (void)state;
    char dir[1024], record[1100];
    tmp_path(dir, sizeof dir, "int_ref");
    snprintf(record, sizeof record, "%s/ref.json", dir);
    clear_dir(dir);
    const char *argv[] = {FXC_BIN,        "ref",    "--camera",      "orbit", "--viewers", "1",
                          "--frames",     "100000", "--every",       "1",     "--res",     "24x14",
                          "--ao-samples", "8",      "--shadow-rays", "32",    "--paths",   "4",
                          "--threads",    "1",      "--out",         dir,     NULL};
    pid_t pid = fxt_spawn_quiet(argv, 0, NULL);
    /* Wait (at most 60 s) until two images are on record, then ask it to stop. */
    size_t recorded = 0;
    for (int tries = 0; tries < 600 && recorded < 2; tries++) {
        json_t *root = json_load_file(record, 0, NULL);
        recorded = root ? json_array_size(json_object_get(root, "images")) : 0;
        json_decref(root);
        struct timespec pause = {0, 100 * 1000 * 1000};
        nanosleep(&pause, NULL);
    }
    assert_true(recorded >= 2);
    assert_int_equal(kill(pid, SIGTERM), 0);
    int status = 0;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFEXITED(status));
    assert_int_equal(WEXITSTATUS(status), 0);
    json_t *root = load_json(record);
    assert_true(json_is_true(json_object_get(root, "interrupted")));
    size_t images = json_array_size(json_object_get(root, "images"));
    assert_true(images >= recorded && images < 100000);
    char path[1200];
    for (size_t f = 0; f < images; f++) {
        snprintf(path, sizeof path, "%s/frame_%04zu_viewer_00.exr", dir, f);
        assert_int_equal(access(path, R_OK), 0);
    }
    snprintf(path, sizeof path, "%s/frame_%04zu_viewer_00.png", dir, images);
    assert_int_not_equal(access(path, R_OK), 0);
    json_decref(root);
}

#define SCENE_TEST(fn)                                                                                       \
    cmocka_unit_test_setup_teardown(fn, fxt_default_scene_setup, fxt_default_scene_teardown)

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_open_plane_under_sky),
        cmocka_unit_test(test_direct_light_analytic),
        cmocka_unit_test(test_saturated_noise_finite),
        cmocka_unit_test(test_shadow_analytic),
        cmocka_unit_test(test_closed_sphere_series),
        SCENE_TEST(test_one_bounce_matches_no_cache),
        SCENE_TEST(test_deterministic),
        SCENE_TEST(test_noise_estimate),
        SCENE_TEST(test_refusals),
        cmocka_unit_test(test_cli_option_errors),
        cmocka_unit_test(test_cli_trace_frames_match_sim),
        cmocka_unit_test(test_cli_generator_cameras_match_sim),
        cmocka_unit_test(test_cli_interrupted),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
