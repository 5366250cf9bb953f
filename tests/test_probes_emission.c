/* Emissive materials (scene_material.emission) against closed forms: the probes, the no-cache estimate and
 * the path-traced reference carry an emitter's light to the surfaces around it, compose shows it on the
 * emitter itself, and the Cornell box loads lit by its own light. Every test here fails when emission is
 * ignored (everything is dark then). */
#include "test_util.h"

#include "camgen.h"
#include "engine.h"
#include "engine_internal.h" /* white-box: the tone map */
#include "fxt_probes.h"
#include "fxt_scene.h"
#include "reference.h"

#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* 14 points on the unit sphere's wall: the 6 axes and the 8 diagonals. */
static void wall_direction(int j, float d[3])
{
    if (j < 6) {
        d[0] = d[1] = d[2] = 0.0f;
        d[j / 2] = j % 2 ? -1.0f : 1.0f;
        return;
    }
    int m = j - 6;
    float c = 1.0f / sqrtf(3.0f);
    d[0] = m & 1 ? -c : c, d[1] = m & 2 ? -c : c, d[2] = m & 4 ? -c : c;
}

/* Inside a closed diffuse sphere whose inside emits Le and reflects rho, the radiance is uniform:
 * L = Le + rho L, so L = Le / (1 - rho) everywhere and the irradiance at the wall is E = pi Le / (1 - rho);
 * compose's indirect term there is E / pi = Le / (1 - rho). With no light and no sky every bit of it comes
 * from the emission the probe rays meet.
 *   - The probes (hysteresis 0.5, 30 frames: the error shrinks by 0.5 + 0.5 rho per frame, to below 2e-4):
 *     within 2 % at every wall point and 1 % on the mean, test_sphere_converges' bounds for the same field.
 *   - The reference (fx_indirect_reference_point, every bounce): rho = 0 gives pi Le from every path (each
 *     meets the wall once), so exact to float rounding; rho = 0.5 within 3 % on the mean of 14 points of 1024
 *     paths (Russian roulette's noise; measured 0.6 % low).
 *   - The no-cache estimate (fx_probe_eval_point) is one bounce of light by design: pi (Le + rho x direct),
 *     here pi Le whatever rho, exactly up to float rounding. */
static void test_sphere_emitter(void **state)
{
    (void)state;
    const float le[3] = {0.8f, 0.4f, 0.2f};
    for (int run = 0; run < 2; run++) {
        const float rho = run == 0 ? 0.0f : 0.5f;
        scene *s = fxt_new_scene();
        s->materials[0].diffuse[0] = s->materials[0].diffuse[1] = s->materials[0].diffuse[2] = rho;
        memcpy(s->materials[0].emission, le, sizeof le);
        fxt_add_sphere(s, 1.0f, 4); /* 5,120 facets */
        scene_rt *rt = fxt_finish_scene(s, 4.0f, 1.0f);
        assert_true(s->emissive);
        assert_int_equal(s->light_count, 0);

        fxt_grid g;
        fxt_grid_init(&g, s, (float[3]){-1.1f, -1.1f, -1.1f}, 0.55f, 5, 5, 5);
        fx_context ctx = fxt_grid_context(s, rt, &g, 0.5f);
        for (int f = 0; f < 30; f++)
            fxt_grid_frame(&g, &ctx);
        fx_context plain = {.s = s, .rt = rt, .seed = 99, .ao_radius = 1, .probe_rays = FX_PROBE_RAYS};
        scene_tracing_thread_init();
        double probe_mean[3] = {0, 0, 0}, probe_worst = 0, ref_mean[3] = {0, 0, 0};
        for (int j = 0; j < 14; j++) {
            float d[3], pos[3], normal[3], indirect[3], ref[3], eval[3];
            wall_direction(j, d);
            for (int k = 0; k < 3; k++)
                pos[k] = 0.99f * d[k], normal[k] = -d[k]; /* inside every facet's plane */
            fxt_grid_shade_at(&g, pos, normal, indirect, NULL);
            uint64_t rays = 0;
            fx_indirect_reference_point(&plain, pos, normal, 1024, (uint64_t)j, ref, &rays);
            fx_probe_eval_point(&plain, pos, normal, (uint64_t)j, eval, &rays);
            for (int k = 0; k < 3; k++) {
                double expected = le[k] / (1.0 - rho); /* E / pi */
                double error = fabs(indirect[k] - expected) / expected;
                probe_worst = fmax(probe_worst, error);
                probe_mean[k] += indirect[k] / 14.0;
                ref_mean[k] += ref[k] / FXT_PI_F / 14.0;
                if (rho == 0.0f)
                    assert_true(fabs(ref[k] / FXT_PI_F - expected) < 1e-5 * expected);
                assert_true(fabs(eval[k] / FXT_PI_F - le[k]) < 1e-5 * le[k]);
            }
        }
        for (int k = 0; k < 3; k++) {
            double expected = le[k] / (1.0 - rho);
            printf("sphere emitter rho=%.1f channel %d: probes mean %.4f, reference mean %.4f, closed form "
                   "%.4f; probes' worst error %.4f\n",
                   (double)rho, k, probe_mean[k], ref_mean[k], expected, probe_worst);
            assert_true(fabs(probe_mean[k] - expected) < 0.01 * expected);
            assert_true(fabs(ref_mean[k] - expected) < 0.03 * expected);
        }
        assert_true(probe_worst < 0.02);
        fxt_grid_free(&g);
        scene_rt_free(rt);
        scene_free(s);
    }
}

/* A pixel that sees the front of an emitter of albedo 0 shows exactly its emission: albedo x (anything) is 0
 * and compose adds Le, so the radiance is Le bit for bit and the image byte is the tone map's of Le; a pixel
 * that sees the back of the same material shows 0 (emission is one-sided, as the probes see it). Cached and
 * no-cache, with the probes running, and in the reference renderer. */
static void test_pixel_shows_emission(void **state)
{
    (void)state;
    const float le[3] = {0.3f, 1.7f, 12.0f};
    scene *s = fxt_new_scene();
    memset(s->materials[0].diffuse, 0, sizeof s->materials[0].diffuse);
    memcpy(s->materials[0].emission, le, sizeof le);
    /* x in [-1, 1] facing +z (towards the camera), x in [3, 5] facing -z (away from it) */
    fxt_add_quad(s, "front", (double[3]){-1, -1, 0}, (double[3]){2, 0, 0}, (double[3]){0, 2, 0}, 4);
    fxt_add_quad(s, "back", (double[3]){3, -1, 0}, (double[3]){0, 2, 0}, (double[3]){2, 0, 0}, 4);
    scene_rt *rt = fxt_finish_scene(s, 8.0f, 1.0f);
    assert_true(s->emissive);
    /* 90 degrees vertical, 64 x 32: 16 m wide at distance 4, x in [-6, 10]; x = 0 at column 24, x = 4 at 40 */
    srv_camera cam = {.position = {2, 0, 4}, .target = {2, 0, 0}, .fov_deg = 90};
    for (int no_cache = 0; no_cache < 2; no_cache++) {
        srv_loop_desc d = {.s = s, .rt = rt, .seed = 3, .no_cache = no_cache};
        fxt_effects_on(&d, (const char *const[]){"probes"}, 1);
        srv_viewer_id id;
        srv_loop *loop = fxt_loop(&d, 1, 64, 32, &id);
        srv_frame_stats st;
        for (int f = 0; f < 3; f++)
            fxt_frame(loop, &id, 1, &cam, &st);
        const float *radiance = srv_viewer_radiance(loop, id);
        const uint8_t *image = srv_viewer_image(loop, id);
        size_t front = (size_t)16 * 64 + 24, back = (size_t)16 * 64 + 40;
        for (int k = 0; k < 3; k++) {
            assert_true(radiance[3 * front + k] == le[k]);
            assert_int_equal(image[3 * front + k], srv__tone_map(le[k]));
            assert_true(radiance[3 * back + k] == 0.0f);
            assert_int_equal(image[3 * back + k], 0);
        }
        srv_loop_free(loop);
    }
    /* The reference renderer (fxcache ref): the camera ray's first hit, the same. */
    srv_ref_desc rd = {.s = s, .rt = rt, .seed = 3, .threads = 1};
    uint32_t count = 0;
    const fx_effect *const *registry = fx_registry(&count);
    rd.effect_on[fx_find(registry, count, "probes")] = true;
    rd.samples[fx_find(registry, count, "probes")] = 16;
    srv_ref *ref = NULL;
    char err[256];
    assert_int_equal(srv_ref_create(&rd, &ref, err, sizeof err), FXC_OK);
    float *radiance = calloc((size_t)64 * 32 * 3, sizeof(float));
    uint8_t *srgb = calloc((size_t)64 * 32 * 3, 1);
    srv_ref_image out = {.radiance = radiance, .srgb = srgb};
    assert_int_equal(srv_ref_render(ref, &cam, 64, 32, 0, &out, NULL, NULL, NULL), FXC_OK);
    size_t front = (size_t)16 * 64 + 24, back = (size_t)16 * 64 + 40;
    for (int k = 0; k < 3; k++) {
        assert_true(radiance[3 * front + k] == le[k]);
        assert_int_equal(srgb[3 * front + k], srv__tone_map(le[k]));
        assert_true(radiance[3 * back + k] == 0.0f);
    }
    free(radiance);
    free(srgb);
    srv_ref_free(ref);
    scene_rt_free(rt);
    scene_free(s);
}

/* The form factor from a floor point to the rectangle [x0, x1] x [z0, z1] of a parallel plane at height h
 * above it (coordinates relative to the point), in closed form: corner rectangles (one corner straight above
 * the point, sides a, b) have F = (a' atan(b / sqrt(1 + a^2)) + b' atan(a / sqrt(1 + b^2))) / (2 pi) with
 * a = side / h, a' = a / sqrt(1 + a^2); any rectangle is their signed sum. */
static double corner_factor(double x, double z, double h)
{
    double a = fabs(x) / h, b = fabs(z) / h;
    double f =
        (a / sqrt(1 + a * a) * atan(b / sqrt(1 + a * a)) + b / sqrt(1 + b * b) * atan(a / sqrt(1 + b * b))) /
        (2 * M_PI);
    return (x < 0) == (z < 0) ? f : -f;
}

static double rectangle_factor(double x0, double x1, double z0, double z1, double h)
{
    return corner_factor(x1, z1, h) - corner_factor(x0, z1, h) - corner_factor(x1, z0, h) +
           corner_factor(x0, z0, h);
}

/* The Cornell box (../shared): one emitting material ('light', Ke 17 12 4 on a 0.47 x 0.38 m quad), no
 * default sun and sky, the probes run because of the emitter and say so; a floor point clear of both boxes
 * (and of their shadow) gets the light's irradiance: the reference's first bounce matches the closed form of a
 * parallel rectangle (E = pi Le F) within 5 % (65,536 Sobol-stratified paths, about 1 % of which meet the
 * light; measured 0.4 %), and so does the no-cache estimate, one bounce by design (4,096 rays; measured 1.1 %);
 * every bounce gives more, and the probes (cells of 0.25 m, 20 frames) are within 10 % of the reference's
 * every bounce (measured 2 to 4.5 %). */
static void test_cornell_box(void **state)
{
    (void)state;
    const char *path = fxt_shared_scene("cornell-box/CornellBox-Original.obj");
    if (!path) {
        print_message("SKIP: the Cornell box (../shared/scenes/cornell-box) is absent\n");
        skip();
    }
    scene_error err = {0};
    scene *s = scene_load(path, NULL, &err);
    assert_non_null(s);
    assert_true(s->emissive);
    assert_int_equal(s->light_count, 0);
    assert_true(s->sky_intensity == 0.0f);
    uint32_t emitting = 0;
    double power[3];
    scene_emission_power(s, &emitting, power);
    assert_int_equal(emitting, 1);
    const double area = 0.47 * 0.38, le[3] = {17, 12, 4};
    for (int k = 0; k < 3; k++)
        assert_true(fabs(power[k] - M_PI * le[k] * area) < 1e-4 * power[k]);

    scene_needs_result needs;
    scene_needs(s, &needs);
    assert_true(needs.effect[SCENE_FX_PROBES]);
    assert_false(needs.effect[SCENE_FX_SHADOW]);
    assert_false(needs.effect[SCENE_FX_AO]);
    assert_non_null(strstr(needs.effect_reason[SCENE_FX_PROBES], "1 emitting mesh"));

    /* What sim says, in words and in its summary: the emitter lights the scene. */
    char cmd[1400], out[8192];
    snprintf(cmd, sizeof cmd, "sim --scene %s --viewers 1 --frames 2 --res 32x24 --threads 1 --summary %s",
             path, fxt_tmp_path("cornell_summary.json"));
    assert_int_equal(fxt_run_cli(cmd, out, sizeof out, NULL, 0), 0);
    assert_non_null(strstr(out, "left out shadow: the scene has no lights: its 1 emitting mesh light it"));
    json_error_t json_err;
    json_t *summary = json_load_file(fxt_tmp_path("cornell_summary.json"), 0, &json_err);
    assert_non_null(summary);
    const char *probes = json_string_value(json_object_get(json_object_get(summary, "effects"), "probes"));
    assert_non_null(probes);
    assert_non_null(strstr(probes, "light from 1 emitting mesh bounces"));
    json_decref(summary);

    scene_error rt_err = {0};
    scene_rt *rt = scene_rt_create(s, NULL, &rt_err);
    assert_non_null(rt);
    scene_tracing_thread_init();
    const float point[3] = {-0.5f, 0.0f, 0.6f}, up[3] = {0, 1, 0};
    /* the light: x in [-0.24, 0.23], z in [-0.22, 0.16] at y = 1.98 */
    double factor =
        rectangle_factor(-0.24 - point[0], 0.23 - point[0], -0.22 - point[2], 0.16 - point[2], 1.98);
    fx_context one = {
        .s = s, .rt = rt, .seed = 5, .ao_radius = 1, .reference_bounces = 1, .probe_rays = 4096};
    fx_context all = one;
    all.reference_bounces = 0;
    float direct[3], every[3], eval[3];
    uint64_t rays = 0;
    fx_indirect_reference_point(&one, point, up, 65536, 1, direct, &rays);
    fx_indirect_reference_point(&all, point, up, 65536, 1, every, &rays);
    fx_probe_eval_point(&all, point, up, 1, eval, &rays);

    fxt_grid g; /* probes every 0.25 m over the box */
    fxt_grid_init(&g, s, (float[3]){-1.125f, -0.125f, -1.125f}, 0.25f, 10, 10, 10);
    fx_context ctx = fxt_grid_context(s, rt, &g, 0.5f);
    for (int f = 0; f < 20; f++)
        fxt_grid_frame(&g, &ctx);
    float indirect[3];
    fxt_grid_shade_at(&g, point, up, indirect, NULL);
    for (int k = 0; k < 3; k++) {
        double expected = M_PI * le[k] * factor;
        printf("cornell box channel %d: E first bounce %.4f (closed form %.4f), every bounce %.4f, no-cache "
               "%.4f, probes %.4f\n",
               k, (double)direct[k], expected, (double)every[k], (double)eval[k],
               (double)(indirect[k] * FXT_PI_F));
        assert_true(fabs(direct[k] - expected) < 0.05 * expected);
        assert_true(fabs(eval[k] - expected) < 0.05 * expected);
        assert_true(every[k] > direct[k]);
        assert_true(fabs(indirect[k] * FXT_PI_F - every[k]) < 0.1 * every[k]);
    }
    fxt_grid_free(&g);
    scene_rt_free(rt);
    scene_free(s);
}

/* A quad in an OBJ file whose material (in its MTL) has the emissive colour ke ("0 0 0": none). */
static const char *write_quad_obj(const char *name, const char *ke)
{
    char mtl_name[64], mtl[160], obj[400];
    snprintf(mtl_name, sizeof mtl_name, "%s.mtl", name);
    snprintf(mtl, sizeof mtl, "newmtl glow\nKd 0.5 0.5 0.5\nKe %s\n", ke);
    fxt_write_file(mtl_name, mtl);
    snprintf(obj, sizeof obj,
             "mtllib %s\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nusemtl glow\nf 1 4 3\nf 1 3 2\n", mtl_name);
    char obj_name[64];
    snprintf(obj_name, sizeof obj_name, "%s.obj", name);
    return fxt_write_file(obj_name, obj);
}

/* Emission from files: an OBJ's Ke through Assimp (the file is then lit by it alone: no default sun and sky;
 * without Ke it keeps them), a JSON material's "emission" (read and validated: >= 0, finite as a float, three
 * numbers). */
static void test_emission_from_files(void **state)
{
    (void)state;
    scene_error err = {0};
    scene *s = scene_load(write_quad_obj("glow", "2 3 4"), NULL, &err);
    if (!s)
        fail_msg("%s", err.msg);
    const scene_material *m = &s->materials[s->meshes[0].material];
    assert_true(m->emission[0] == 2.0f && m->emission[1] == 3.0f && m->emission[2] == 4.0f);
    assert_true(s->emissive);
    assert_int_equal(s->light_count, 0);
    assert_true(s->sky_intensity == 0.0f);
    scene_free(s);

    s = scene_load(write_quad_obj("dark", "0 0 0"), NULL, &err);
    if (!s)
        fail_msg("%s", err.msg);
    assert_false(s->emissive);
    assert_int_equal(s->light_count, 1); /* the default sun */
    assert_true(s->sky_intensity > 0.0f);
    scene_free(s);

    write_quad_obj("plain", "0 0 0");
    s = scene_load(fxt_write_file("emit.json", "{\"version\": 1, \"meshes\": [{\"file\": \"plain.obj\", "
                                               "\"material\": {\"diffuse\": [0.25, 0.25, 0.25], "
                                               "\"emission\": [1, 2.5, 1e30]}}]}"),
                   NULL, &err);
    if (!s)
        fail_msg("%s", err.msg);
    m = &s->materials[s->meshes[0].material];
    assert_true(m->emission[0] == 1.0f && m->emission[1] == 2.5f && m->emission[2] == 1e30f);
    assert_true(s->emissive);
    assert_int_equal(s->light_count, 0); /* a description says exactly which lights it has */
    scene_needs_result needs;
    scene_needs(s, &needs);
    assert_true(needs.effect[SCENE_FX_PROBES]);
    scene_free(s);

    static const struct {
        const char *emission;
        scene_result code;
        const char *text;
    } bad[] = {
        {"[-1, 0, 0]", SCENE_ERR_INVALID, "meshes[0].material.emission: components must be radiances >= 0"},
        {"[0, 1e39, 0]", SCENE_ERR_INVALID, "meshes[0].material.emission[1]: must be a finite number"},
        {"[1, 2]", SCENE_ERR_JSON, "meshes[0].material.emission"},
        {"\"bright\"", SCENE_ERR_JSON, "meshes[0].material.emission"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char json[256];
        snprintf(
            json, sizeof json,
            "{\"version\": 1, \"meshes\": [{\"file\": \"plain.obj\", \"material\": {\"emission\": %s}}]}",
            bad[i].emission);
        memset(&err, 0, sizeof err);
        s = scene_load(fxt_write_file("bad.json", json), NULL, &err);
        assert_null(s);
        if (err.code != bad[i].code || !strstr(err.msg, bad[i].text))
            fail_msg("emission %s: code %d, '%s'", bad[i].emission, (int)err.code, err.msg);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sphere_emitter),
        cmocka_unit_test(test_pixel_shows_emission),
        cmocka_unit_test(test_cornell_box),
        cmocka_unit_test(test_emission_from_files),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
