/* Stability suite, scale (docs/ERROR.md "Stability suite"): the embedded scene and Sponza scaled by 1e-4 and
 * 1e4 about the world origin and translated by 1e6 on every axis, against the same scene at scale 1 at the
 * origin, through the whole frame loop (every frame checked by stab_check_loop).
 *
 * What can differ, and the tolerance for it. Everything the engine derives from the geometry is scale-free:
 * the automatic texel density follows the scale (4096^2 texels over the surface), so islands are the same in
 * texels; the AO radius and the camera are scaled with the scene, and the probes' finest cell is the unit
 * scene's times the scale, so cache keys (island, level, block; grid coordinates) and with them every hashed
 * random number are the same; floats have the same relative precision at any magnitude, and ray origins
 * leave surfaces by a scale-aware offset. What is left is rounding, and its effects are of two kinds:
 *   - a texel whose centre lies on an edge between two triangles of its island (ties the 1/256-texel UV
 *     snapping breaks either way at another scale) takes the other triangle, and its sample points, kept
 *     inside that triangle, cover the other part of its footprint (at coarse levels half a texel of 0.3 m):
 *     a shadow or AO edge moves by up to one texel. The AO and shadow views are therefore compared with the
 *     texel criterion: each pixel within what the unit image itself varies over two pixels (a texel is one to
 *     two pixels at the level the pixel's footprint chooses), plus one shadow ray (1/16);
 *   - a probe ray that grazes an edge flips, and the bounces spread the change to its neighbours: the
 *     probe term differs the way another seed's would, so its bound is the relative RMSE between seeds 7 and
 *     8 at scale 1 (measured in the same run; h = 0.5 and 6 frames, so both have settled to the same level
 *     of noise).
 * A translation keeps the local geometry bit for bit (the scene is rebased onto a whole multiple of a power
 * of two near its centre) and the probe grid is anchored at the local frame: the images must be identical.
 * Measured (printed): AO and lit fraction at 1e-4 within 0.0005 of scale 1; at 1e4 up to 0.27 and 0.50 at
 * edges, all within one texel's shift; the probe term 0.3 to 0.7 of a new seed's difference for the embedded
 * scene, 0.01 for Sponza; translations identical. Against the reference at the variant's own scale (mean
 * absolute difference): the embedded scene AO 0.0260-0.0268, lit fraction 0.0049-0.0061; Sponza AO
 * 0.0670-0.0671, lit 0.0253-0.0254, at every scale and translation. */
#include "stab_util.h"

#include "camgen.h"
#include "reference.h"
#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { W = 96, H = 54, FRAMES = 6, PROBE_RAYS = 64, REF_AO_SAMPLES = 256, REF_SHADOW_SAMPLES = 64 };
#define PROBE_HYSTERESIS 0.5f

/* One render: radiance, the kept AO and shadow views (runs without probes keep them), the visible count. */
typedef struct render_out {
    uint32_t w, h;
    float *radiance; /* w x h x 3 */
    float *views[2]; /* AO and lit fraction, w x h (NULL with probes: they take the sky term over) */
    uint64_t visible;
    float probe_cell;
    /* Runs without probes: the views against the reference renderer (reference.h) at the scene's own scale,
     * same camera and size: mean absolute difference of the AO and the lit-fraction view, and the
     * reference's own standard error of each (its noise estimate). */
    double ref_mae[2], ref_noise[2];
} render_out;

static void render_free(render_out *r)
{
    free(r->radiance);
    free(r->views[0]);
    free(r->views[1]);
    memset(r, 0, sizeof *r);
}

/* The AO and lit-fraction views of `out` against the reference renderer's AO and shadow terms of the same
 * camera on the same scene (shadow and AO on, REF_* samples a pixel): a second method at the scene's own
 * scale. Its mean equal to scale 1's says the cache's error against the truth, which `fxcache report`
 * measures at scale 1, holds at every scale (the comparison with scale 1 alone says only that the images
 * agree). */
static void against_reference(render_out *out, scene *s, scene_rt *rt, const srv_camera *cam)
{
    uint32_t n = 0;
    const fx_effect *const *registry = fx_registry(&n);
    srv_ref_desc d = {.s = s, .rt = rt, .effects = registry, .effect_count = n, .seed = 11, .threads = 2};
    int32_t ao = fx_find(registry, n, "ao"), shadow = fx_find(registry, n, "shadow");
    assert_true(ao >= 0 && shadow >= 0);
    d.effect_on[ao] = d.effect_on[shadow] = true;
    d.samples[ao] = REF_AO_SAMPLES;
    d.samples[shadow] = REF_SHADOW_SAMPLES;
    srv_ref *ref = NULL;
    char err[256];
    if (srv_ref_create(&d, &ref, err, sizeof err) != FXC_OK)
        fail_msg("srv_ref_create: %s", err);
    size_t pixels = (size_t)out->w * out->h;
    float *radiance = malloc(pixels * 3 * sizeof(float)),
          *terms[2] = {malloc(pixels * sizeof(float)), malloc(pixels * sizeof(float))};
    assert_true(radiance && terms[0] && terms[1]);
    srv_ref_image im = {.radiance = radiance, .ao = terms[0], .shadow = terms[1]};
    srv_ref_stats st;
    assert_int_equal(srv_ref_render(ref, cam, out->w, out->h, 0, &im, &st, NULL, NULL), FXC_OK);
    out->ref_noise[0] = st.noise_ao;
    out->ref_noise[1] = st.noise_shadow;
    for (int v = 0; v < 2; v++) {
        double sum = 0;
        for (size_t i = 0; i < pixels; i++)
            sum += fabs((double)out->views[v][i] - terms[v][i]);
        out->ref_mae[v] = sum / (double)pixels;
        free(terms[v]);
    }
    free(radiance);
    srv_ref_free(ref);
}

/* Renders s from its own camera for FRAMES frames (every frame checked) with shadows and AO, and probes when
 * probe_cell > 0 (that finest cell, metres). */
static render_out render(scene *s, bool probes, float probe_cell, uint32_t seed, uint32_t w, uint32_t h)
{
    scene_error err = {0};
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    assert_non_null(rt);
    srv_loop_desc d = {.s = s,
                       .rt = rt,
                       .seed = seed,
                       .pool_bytes = 48u << 20,
                       .probe_cell = probe_cell,
                       .keep_views = !probes,
                       .threads = 2,
                       .probe_rays = PROBE_RAYS,
                       .probe_hysteresis = PROBE_HYSTERESIS};
    if (probes)
        fxt_effects_on(&d, (const char *const[]){"probes"}, 1);
    else
        fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, w, h, &id);
    srv_camera cam = srv_camera_default(s);
    srv_frame_stats st;
    stab_checked c = stab_frames(loop, &id, 1, &cam, true, FRAMES, &st);
    assert_true(probes ? c.texels[SCENE_FX_PROBES] > 0
                       : c.texels[SCENE_FX_AO] > 0 && c.texels[SCENE_FX_SHADOW] > 0);
    render_out out = {.w = w,
                      .h = h,
                      .radiance = stab_copy_radiance(loop, id),
                      .visible = st.pixels_visible,
                      .probe_cell = srv_loop_probe_cell(loop)};
    for (int v = 0; !probes && v < 2; v++) {
        out.views[v] = malloc((size_t)w * h * sizeof(float));
        assert_non_null(out.views[v]);
        memcpy(out.views[v], srv_viewer_view(loop, id, v == 0 ? SRV_VIEW_AO : SRV_VIEW_SHADOW),
               (size_t)w * h * sizeof(float));
    }
    if (!probes)
        against_reference(&out, s, rt, &cam);
    srv_loop_free(loop);
    scene_rt_free(rt);
    return out;
}

/* The texel criterion: each pixel of view b within one texel's shift of view a. A pixel's level is chosen so
 * that a texel is about one pixel (two for AO, one level coarser), so a texel that samples another part of
 * its footprint, or an edge a rounding error moves into the next texel, can change a pixel by as much as a's
 * own change within two pixels; beyond that, by one shadow ray (1/16; one AO ray is 1/64). Returns the pixels
 * beyond it (and prints the worst). */
static uint32_t beyond_one_texel(const float *a, const float *b, uint32_t w, uint32_t h, const char *what)
{
    uint32_t beyond = 0;
    double worst = 0;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t p = (size_t)y * w + x;
            double reach = 0;
            for (int dy = -2; dy <= 2; dy++)
                for (int dx = -2; dx <= 2; dx++) {
                    int qx = (int)x + dx, qy = (int)y + dy;
                    if (qx >= 0 && qy >= 0 && qx < (int)w && qy < (int)h)
                        reach = fmax(reach, fabs((double)a[(size_t)qy * w + (size_t)qx] - a[p]));
                }
            double excess = fabs((double)b[p] - a[p]) - reach - 1.0 / 16.0;
            if (excess > 1e-6) {
                if (beyond++ < 3)
                    print_message(
                        "  %s pixel (%u, %u): %.4f against %.4f, its neighbourhood varies by %.4f\n", what, x,
                        y, (double)b[p], (double)a[p], reach);
            }
            worst = fmax(worst, fabs((double)b[p] - a[p]));
        }
    print_message("  %s: largest difference %.4f, %u pixels beyond one texel's shift\n", what, worst, beyond);
    return beyond;
}

/* The references of one scene: at scale 1 without probes (views), with probes, and with probes and another
 * seed (the Monte Carlo noise floor of the probes). */
typedef struct reference {
    render_out plain, probes, other_seed;
} reference;

static void reference_make(reference *r, scene *unit, float probe_cell, uint32_t w, uint32_t h)
{
    r->plain = render(unit, false, 0, 7, w, h);
    r->probes = render(unit, true, probe_cell, 7, w / 2, h / 2);
    r->other_seed = render(unit, true, probe_cell, 8, w / 2, h / 2);
}

static void reference_free(reference *r)
{
    render_free(&r->plain);
    render_free(&r->probes);
    render_free(&r->other_seed);
}

/* The variant (scaled by `scale` about the world origin, then translated) against the unit scene:
 *   - translated only (scale 1): bit for bit the same images (the local frame and the grid make every key,
 *     position and ray the same);
 *   - scaled: the AO and shadow views within one texel's shift (beyond_one_texel), the same visible pixels
 *     within 0.5 % (silhouette pixels whose primary ray grazes an edge), and the radiance with probes no
 *     further from the unit's than another seed's is: relative RMSE at most 1.5 x that of seed 8 against
 *     seed 7 (rounding flips single probe rays where they graze an edge, and bounces spread the change, as a
 *     new seed would; 1.5 allows for the spread of an RMSE over a few hundred correlated probes);
 *   - either way, a second method at the variant's own scale: the mean absolute difference of its AO and lit
 *     views from the reference renderer's terms (against_reference) within a quarter of the unit scene's own
 *     plus twice the two references' standard errors. A texel's shift moves single pixels' errors and leaves
 *     the mean nearly alone (measured: within 0.0012 of scale 1's). */
static void check_variant(const reference *ref, scene *variant, double scale, const char *what)
{
    uint32_t w = ref->plain.w, h = ref->plain.h;
    size_t n = (size_t)w * h * 3;
    assert_string_equal(variant->precision_warning, "");
    render_out plain = render(variant, false, 0, 7, w, h);
    render_out probes = render(variant, true, (float)(ref->probes.probe_cell * scale), 7, w / 2, h / 2);
    size_t n_probes = (size_t)(w / 2) * (h / 2) * 3;
    double noise = stab_relative_rmse(ref->probes.radiance, ref->other_seed.radiance, n_probes);
    double rmse = stab_relative_rmse(ref->probes.radiance, probes.radiance, n_probes);
    double rmse_plain = stab_relative_rmse(ref->plain.radiance, plain.radiance, n);
    print_message(
        "%s: origin (%.17g, %.17g, %.17g); relative RMSE without probes %.2e, with probes %.2e (another "
        "seed at scale 1: %.2e); visible %llu (scale 1: %llu)\n",
        what, variant->origin[0], variant->origin[1], variant->origin[2], rmse_plain, rmse, noise,
        (unsigned long long)plain.visible, (unsigned long long)ref->plain.visible);
    print_message(
        "  against the reference at its own scale: AO %.4f (scale 1: %.4f), lit fraction %.4f (scale 1: "
        "%.4f); the references' standard errors %.4f, %.4f\n",
        plain.ref_mae[0], ref->plain.ref_mae[0], plain.ref_mae[1], ref->plain.ref_mae[1], plain.ref_noise[0],
        plain.ref_noise[1]);
    if (scale == 1.0) {
        assert_memory_equal(ref->plain.radiance, plain.radiance, n * sizeof(float));
        assert_memory_equal(ref->probes.radiance, probes.radiance, n_probes * sizeof(float));
    } else {
        assert_int_equal(beyond_one_texel(ref->plain.views[0], plain.views[0], w, h, "AO"), 0);
        assert_int_equal(beyond_one_texel(ref->plain.views[1], plain.views[1], w, h, "lit fraction"), 0);
        assert_true(llabs((long long)plain.visible - (long long)ref->plain.visible) * 200 <=
                    (long long)ref->plain.visible);
        assert_true(rmse <= noise);
    }
    for (int v = 0; v < 2; v++) {
        double allowed = 0.25 * ref->plain.ref_mae[v] + 2.0 * (plain.ref_noise[v] + ref->plain.ref_noise[v]);
        if (fabs(plain.ref_mae[v] - ref->plain.ref_mae[v]) > allowed)
            fail_msg("%s: %s against the reference at its own scale %.4f, at scale 1 %.4f (allowed +-%.4f)",
                     what, v == 0 ? "AO" : "lit fraction", plain.ref_mae[v], ref->plain.ref_mae[v], allowed);
    }
    render_free(&plain);
    render_free(&probes);
}

/* ---- the embedded scene ---------------------------------------------------------------------------------- */

static int default_setup(void **state)
{
    reference *r = calloc(1, sizeof *r);
    assert_non_null(r);
    scene *unit = fxt_transformed_default(1.0, 0.0, 1.0f);
    reference_make(r, unit, 0.5f, W, H);
    scene_free(unit);
    *state = r;
    return 0;
}

static int default_teardown(void **state)
{
    reference_free(*state);
    free(*state);
    return 0;
}

static void check_default(const reference *ref, double scale, double offset)
{
    scene *s = fxt_transformed_default(scale, offset, 1.0f);
    char what[128];
    snprintf(what, sizeof what, "default scene, scale %g, moved by %g", scale, offset);
    check_variant(ref, s, scale, what);
    scene_free(s);
}

static void test_default_scaled_1e_4(void **state)
{
    check_default(*state, 1e-4, 0.0);
}

static void test_default_scaled_1e4(void **state)
{
    check_default(*state, 1e4, 0.0);
}

static void test_default_translated_1e6(void **state)
{
    check_default(*state, 1.0, 1e6);
}

/* The default finest probe cell (probe_cell 0) follows the scale: it is a power of two within a factor
 * sqrt(2) of a 64th of the bounding-box diagonal at every scale (a closed form), and the embedded scene at
 * 2^-14 (a power of two, so its default cell is exactly the unit scene's times the scale) renders with its
 * default cell no further from the unit scene's own default-cell image than another seed is. Before, the
 * default had a floor of 1/64 m: at 2^-14 (a room 1.6 mm long) the whole scene sat in one or two cells and
 * its indirect light came out flat and too bright. */
static void test_default_probe_cell_follows_scale(void **state)
{
    const reference *ref = *state;
    static const double scales[] = {1.0, 0x1p-14, 1e-4, 1e-6, 1e4};
    for (size_t i = 0; i < sizeof scales / sizeof scales[0]; i++) {
        scene *s = fxt_transformed_default(scales[i], 0.0, 1.0f);
        double d2 = 0;
        for (int k = 0; k < 3; k++) {
            double e = (double)s->bounds_max[k] - (double)s->bounds_min[k];
            d2 += e * e;
        }
        double cell = srv_probe_cell_default(s), ratio = cell / (sqrt(d2) / 64.0);
        int exponent;
        print_message("scale %g: default probe cell %g m, %.3f x a 64th of the diagonal\n", scales[i], cell,
                      ratio);
        assert_true(frexp(cell, &exponent) == 0.5);
        assert_true(ratio >= 1.0 / sqrt(2.0) - 1e-12 && ratio <= sqrt(2.0) + 1e-12);
        scene_free(s);
    }
    uint32_t w = ref->plain.w / 2, h = ref->plain.h / 2;
    size_t n = (size_t)w * h * 3;
    scene *unit = fxt_transformed_default(1.0, 0.0, 1.0f),
          *small = fxt_transformed_default(0x1p-14, 0.0, 1.0f);
    render_out a = render(unit, true, 0, 7, w, h), b = render(unit, true, 0, 8, w, h);
    render_out c = render(small, true, 0, 7, w, h);
    double noise = stab_relative_rmse(a.radiance, b.radiance, n),
           rmse = stab_relative_rmse(a.radiance, c.radiance, n);
    print_message("default cell %g m at scale 1, %g m at 2^-14; relative RMSE %.2e (another seed: %.2e)\n",
                  (double)a.probe_cell, (double)c.probe_cell, rmse, noise);
    assert_true(c.probe_cell == a.probe_cell * 0x1p-14f);
    assert_true(rmse <= noise);
    render_free(&a);
    render_free(&b);
    render_free(&c);
    scene_free(unit);
    scene_free(small);
}

/* ---- Sponza -------------------------------------------------------------------------------------------- */

enum { SW = 64, SH = 36 };

/* Sponza through a scene description: scaled by `scale` about the origin, then moved by `offset` on every
 * axis, with a sun, a sky, an AO radius and a camera in the nave transformed alike. */
static scene *sponza_at(const char *path, double scale, double offset)
{
    char text[4096];
    const double pos[3] = {-11.0, 3.0, 0.4}, target[3] = {9.0, 4.5, -0.6};
    snprintf(
        text, sizeof text,
        "{\"version\": 1, \"meshes\": [{\"file\": \"%s\", \"transform\": {\"scale\": %.17g, \"translate\": "
        "[%.17g, %.17g, %.17g]}}],\n"
        " \"lights\": [{\"type\": \"directional\", \"direction\": [-0.3, -1, -0.2], \"intensity\": 2}],\n"
        " \"sky\": {\"color\": [0.5, 0.6, 1], \"intensity\": 0.6}, \"ao_radius\": %.17g,\n"
        " \"camera\": {\"position\": [%.17g, %.17g, %.17g], \"target\": [%.17g, %.17g, %.17g], \"fov_deg\": "
        "70}}",
        path, scale, offset, offset, offset, 2.0 * scale, pos[0] * scale + offset, pos[1] * scale + offset,
        pos[2] * scale + offset, target[0] * scale + offset, target[1] * scale + offset,
        target[2] * scale + offset);
    scene_error err = {0};
    scene *s = scene_load(fxt_write_file("sponza.json", text), NULL, &err);
    if (!s)
        fail_msg("sponza at scale %g offset %g: %s", scale, offset, err.msg);
    return s;
}

/* Sponza's path and references (a group fixture: a load takes most of a second); NULL when it is absent. */
typedef struct sponza_fixture {
    char path[1024];
    reference ref;
} sponza_fixture;

static int sponza_setup(void **state)
{
    const char *found = fxt_shared_scene("sponza/sponza.3ds");
    if (!found) {
        *state = NULL;
        return 0;
    }
    sponza_fixture *f = calloc(1, sizeof *f);
    assert_non_null(f);
    snprintf(f->path, sizeof f->path, "%s", found);
    scene *unit = sponza_at(f->path, 1.0, 0.0);
    reference_make(&f->ref, unit, 1.0f, SW, SH);
    scene_free(unit);
    *state = f;
    return 0;
}

static int sponza_teardown(void **state)
{
    sponza_fixture *f = *state;
    if (f)
        reference_free(&f->ref);
    free(f);
    return 0;
}

static void check_sponza(void **state, double scale, double offset)
{
    sponza_fixture *f = *state;
    if (!f)
        skip();
    scene *s = sponza_at(f->path, scale, offset);
    char what[128];
    snprintf(what, sizeof what, "Sponza, scale %g, moved by %g (%u triangles)", scale, offset,
             s->triangle_count);
    check_variant(&f->ref, s, scale, what);
    scene_free(s);
}

static void test_sponza_scaled_1e_4(void **state)
{
    check_sponza(state, 1e-4, 0.0);
}

static void test_sponza_scaled_1e4(void **state)
{
    check_sponza(state, 1e4, 0.0);
}

static void test_sponza_translated_1e6(void **state)
{
    check_sponza(state, 1.0, 1e6);
}

int main(void)
{
    const struct CMUnitTest default_tests[] = {
        cmocka_unit_test(test_default_scaled_1e_4),
        cmocka_unit_test(test_default_scaled_1e4),
        cmocka_unit_test(test_default_translated_1e6),
        cmocka_unit_test(test_default_probe_cell_follows_scale),
    };
    const struct CMUnitTest sponza_tests[] = {
        cmocka_unit_test(test_sponza_scaled_1e_4),
        cmocka_unit_test(test_sponza_scaled_1e4),
        cmocka_unit_test(test_sponza_translated_1e6),
    };
    int failed = cmocka_run_group_tests_name("scale: the embedded scene", default_tests, default_setup,
                                             default_teardown);
    failed += cmocka_run_group_tests_name("scale: Sponza", sponza_tests, sponza_setup, sponza_teardown);
    return failed;
}
