/* Tests of "what the scene needs" (scene/scene_needs.c): which effects run and which caches exist, for
 * scenes with and without lights, sky, albedo and overrides, and that every decision carries a reason that
 * names its cause. Scenes are built directly with the scene builder (white box, no files, no islands). */
#include "test_util.h"

#include "scene_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* What a test scene holds. */
typedef struct needs_fixture {
    int lights;            /* directional lights to add */
    float light_intensity; /* of each light */
    float light_color;     /* grey level of each light */
    float sky_intensity;   /* 0 = no sky */
    float albedo;          /* grey level of the one material */
    bool textured;         /* the material has a texture (with a black diffuse colour when albedo = 0) */
    float emission;        /* grey level of the material's emission (0: none) */
    scene_toggle shadows, ao, indirect;
} needs_fixture;

/* Builds a one-quad scene as described by f. */
static scene *make_scene(const needs_fixture *f)
{
    scene *s = scene__alloc();
    assert_non_null(s);
    scene_error err = {0};
    if (f->textured) {
        s->textures = calloc(1, sizeof *s->textures);
        assert_non_null(s->textures);
        s->textures[0].width = s->textures[0].height = 1;
        s->textures[0].rgb = calloc(3, sizeof(float));
        assert_non_null(s->textures[0].rgb);
        s->textures[0].rgb[0] = 0.5f;
        s->texture_count = 1;
    }
    scene_material material = {.diffuse = {f->albedo, f->albedo, f->albedo},
                               .texture = f->textured ? 0 : -1,
                               .emission = {f->emission, f->emission, f->emission}};
    uint32_t material_index = scene__add_material(s, &material, &err);
    assert_int_not_equal(material_index, UINT32_MAX);
    static const float positions[] = {0, 0, 0, 1, 0, 0, 1, 0, 1, 0, 0, 1};
    static const uint32_t indices[] = {0, 2, 1, 0, 3, 2};
    assert_int_equal(scene__add_mesh(s, "quad", positions, 4, indices, 2, NULL, material_index, NULL, &err),
                     SCENE_OK);
    for (int i = 0; i < f->lights; i++) {
        scene_light light = {.type = SCENE_LIGHT_DIRECTIONAL,
                             .direction = {0, -1, 0},
                             .color = {f->light_color, f->light_color, f->light_color},
                             .intensity = f->light_intensity};
        assert_int_equal(scene__add_light(s, &light, "test light", &err), SCENE_OK);
    }
    if (f->sky_intensity > 0) {
        s->sky_color[0] = s->sky_color[1] = s->sky_color[2] = 1.0f;
        s->sky_intensity = f->sky_intensity;
    }
    s->fx_shadows = f->shadows;
    s->fx_ao = f->ao;
    s->fx_indirect = f->indirect;
    return s;
}

/* Runs scene_needs() and checks the invariants every result must hold: a reason for everything, the
 * triangle lookup iff an on-surface effect, the caches iff their effects. */
static scene_needs_result needs_of(const scene *s)
{
    scene_needs_result r;
    memset(&r, 0x5a, sizeof r); /* scene_needs must fill every field */
    scene_needs(s, &r);
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
        printf("  %-15s %-3s %s\n", scene_effect_name((scene_effect)fx), r.effect[fx] ? "on" : "off",
               r.effect_reason[fx]);
        assert_true(strlen(r.effect_reason[fx]) > 0);
        assert_true(strlen(r.effect_reason[fx]) < sizeof r.effect_reason[fx]);
    }
    for (int c = 0; c < SCENE_CACHE_COUNT; c++) {
        printf("  %-15s %-3s %s\n", scene_cache_name((scene_cache_kind)c), r.cache[c] ? "on" : "off",
               r.cache_reason[c]);
        assert_true(strlen(r.cache_reason[c]) > 0);
    }
    assert_int_equal(r.effect[SCENE_FX_TRIANGLE_LOOKUP], r.effect[SCENE_FX_SHADOW] || r.effect[SCENE_FX_AO]);
    assert_int_equal(r.cache[SCENE_CACHE_ON_SURFACE], r.effect[SCENE_FX_TRIANGLE_LOOKUP]);
    assert_int_equal(r.cache[SCENE_CACHE_WORLD_SPACE], r.effect[SCENE_FX_PROBES]);
    return r;
}

/* Asserts that text mentions fragment. */
static void assert_mentions(const char *text, const char *fragment)
{
    if (!strstr(text, fragment))
        fail_msg("reason '%s' does not mention '%s'", text, fragment);
}

/* Emission is energy for the probes: an emitter alone runs them (no shadow, no AO, each saying the emitter
 * lights the scene), not when every albedo is black (nothing bounces; the emitter still shows), and beside a
 * sky both are named. */
static void test_needs_emission(void **state)
{
    (void)state;
    needs_fixture f = {.albedo = 0.7f, .emission = 2.0f};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_true(r.effect[SCENE_FX_PROBES]);
    assert_mentions(r.effect_reason[SCENE_FX_PROBES], "light from 1 emitting mesh bounces");
    assert_false(r.effect[SCENE_FX_SHADOW]);
    assert_mentions(r.effect_reason[SCENE_FX_SHADOW], "1 emitting mesh light it through the probes");
    assert_false(r.effect[SCENE_FX_AO]);
    scene_free(s);

    f = (needs_fixture){.albedo = 0.0f, .emission = 2.0f};
    s = make_scene(&f);
    r = needs_of(s);
    assert_false(r.effect[SCENE_FX_PROBES]);
    assert_mentions(r.effect_reason[SCENE_FX_PROBES], "every material is black");
    scene_free(s);

    f = (needs_fixture){.albedo = 0.7f, .emission = 2.0f, .sky_intensity = 1.0f};
    s = make_scene(&f);
    r = needs_of(s);
    assert_true(r.effect[SCENE_FX_PROBES]);
    assert_mentions(r.effect_reason[SCENE_FX_PROBES], "the sky and 1 emitting mesh");
    assert_true(r.effect[SCENE_FX_AO]);
    scene_free(s);
}

/* No lights and no sky: nothing runs, and each reason says what is missing. */
static void test_needs_nothing(void **state)
{
    (void)state;
    needs_fixture f = {.albedo = 0.7f};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_false(r.effect[SCENE_FX_SHADOW]);
    assert_false(r.effect[SCENE_FX_AO]);
    assert_false(r.effect[SCENE_FX_PROBES]);
    assert_false(r.effect[SCENE_FX_TRIANGLE_LOOKUP]);
    assert_false(r.cache[SCENE_CACHE_ON_SURFACE]);
    assert_false(r.cache[SCENE_CACHE_WORLD_SPACE]);
    assert_mentions(r.effect_reason[SCENE_FX_SHADOW], "no lights");
    assert_mentions(r.effect_reason[SCENE_FX_AO], "no sky");
    assert_mentions(r.effect_reason[SCENE_FX_PROBES], "nothing lights");
    assert_mentions(r.effect_reason[SCENE_FX_TRIANGLE_LOOKUP], "no on-surface effect");
    assert_mentions(r.cache_reason[SCENE_CACHE_WORLD_SPACE], "probes");
    scene_free(s);
}

/* A light and no sky: shadows and probes, no AO. */
static void test_needs_light_only(void **state)
{
    (void)state;
    needs_fixture f = {.lights = 1, .light_intensity = 2, .light_color = 1, .albedo = 0.5f};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_true(r.effect[SCENE_FX_SHADOW]);
    assert_false(r.effect[SCENE_FX_AO]);
    assert_true(r.effect[SCENE_FX_PROBES]);
    assert_true(r.effect[SCENE_FX_TRIANGLE_LOOKUP]);
    assert_true(r.cache[SCENE_CACHE_ON_SURFACE]);
    assert_true(r.cache[SCENE_CACHE_WORLD_SPACE]);
    assert_mentions(r.effect_reason[SCENE_FX_SHADOW], "1 of 1 lights");
    assert_mentions(r.effect_reason[SCENE_FX_AO], "no sky");
    assert_mentions(r.effect_reason[SCENE_FX_TRIANGLE_LOOKUP], "shadow");
    assert_mentions(r.cache_reason[SCENE_CACHE_ON_SURFACE], "shadow");
    scene_free(s);
}

/* A sky and no light: AO and probes, no shadows. */
static void test_needs_sky_only(void **state)
{
    (void)state;
    needs_fixture f = {.sky_intensity = 0.8f, .albedo = 0.5f};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_false(r.effect[SCENE_FX_SHADOW]);
    assert_true(r.effect[SCENE_FX_AO]);
    assert_true(r.effect[SCENE_FX_PROBES]);
    assert_true(r.effect[SCENE_FX_TRIANGLE_LOOKUP]);
    assert_mentions(r.effect_reason[SCENE_FX_SHADOW], "no lights");
    assert_mentions(r.effect_reason[SCENE_FX_AO], "sky");
    assert_mentions(r.effect_reason[SCENE_FX_TRIANGLE_LOOKUP], "ao");
    scene_free(s);
}

/* Lights and sky: everything runs. */
static void test_needs_everything(void **state)
{
    (void)state;
    needs_fixture f = {
        .lights = 2, .light_intensity = 1, .light_color = 1, .sky_intensity = 1, .albedo = 0.5f};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++)
        assert_true(r.effect[fx]);
    assert_true(r.cache[SCENE_CACHE_ON_SURFACE]);
    assert_true(r.cache[SCENE_CACHE_WORLD_SPACE]);
    assert_mentions(r.effect_reason[SCENE_FX_SHADOW], "2 of 2 lights");
    assert_mentions(r.cache_reason[SCENE_CACHE_ON_SURFACE], "ao");
    scene_free(s);
}

/* Lights with zero intensity, or a black colour, carry no energy: no shadows. */
static void test_needs_dark_lights(void **state)
{
    (void)state;
    needs_fixture zero = {.lights = 1, .light_intensity = 0, .light_color = 1, .albedo = 0.5f};
    scene *s = make_scene(&zero);
    scene_needs_result r = needs_of(s);
    assert_false(r.effect[SCENE_FX_SHADOW]);
    assert_false(r.effect[SCENE_FX_PROBES]);
    assert_mentions(r.effect_reason[SCENE_FX_SHADOW], "none of the 1 lights");
    scene_free(s);

    needs_fixture black = {.lights = 3, .light_intensity = 5, .light_color = 0, .albedo = 0.5f};
    s = make_scene(&black);
    r = needs_of(s);
    assert_false(r.effect[SCENE_FX_SHADOW]);
    assert_mentions(r.effect_reason[SCENE_FX_SHADOW], "black");
    scene_free(s);
}

/* A sky with a black colour gives no ambient light: no AO. */
static void test_needs_black_sky(void **state)
{
    (void)state;
    needs_fixture f = {.albedo = 0.5f};
    scene *s = make_scene(&f);
    s->sky_intensity = 2.0f; /* colour stays black */
    scene_needs_result r = needs_of(s);
    assert_false(r.effect[SCENE_FX_AO]);
    assert_mentions(r.effect_reason[SCENE_FX_AO], "dark");
    scene_free(s);
}

/* Black materials: light and sky, but nothing bounces, so no probes and no world-space cache. */
static void test_needs_black_materials(void **state)
{
    (void)state;
    needs_fixture f = {.lights = 1, .light_intensity = 1, .light_color = 1, .sky_intensity = 1, .albedo = 0};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_true(r.effect[SCENE_FX_SHADOW]);
    assert_true(r.effect[SCENE_FX_AO]);
    assert_false(r.effect[SCENE_FX_PROBES]);
    assert_false(r.cache[SCENE_CACHE_WORLD_SPACE]);
    assert_mentions(r.effect_reason[SCENE_FX_PROBES], "black");
    assert_mentions(r.cache_reason[SCENE_CACHE_WORLD_SPACE], "no world-space effect");
    scene_free(s);
}

/* A texture counts as non-zero albedo even when the diffuse colour is black. */
static void test_needs_texture_counts_as_albedo(void **state)
{
    (void)state;
    needs_fixture f = {.lights = 1, .light_intensity = 1, .light_color = 1, .albedo = 0, .textured = true};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_true(r.effect[SCENE_FX_PROBES]);
    assert_true(r.cache[SCENE_CACHE_WORLD_SPACE]);
    scene_free(s);
}

/* "off" wins over content: a lit scene with every effect switched off runs nothing. */
static void test_needs_off_wins(void **state)
{
    (void)state;
    needs_fixture f = {.lights = 1,
                       .light_intensity = 1,
                       .light_color = 1,
                       .sky_intensity = 1,
                       .albedo = 0.5f,
                       .shadows = SCENE_OFF,
                       .ao = SCENE_OFF,
                       .indirect = SCENE_OFF};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_false(r.effect[SCENE_FX_SHADOW]);
    assert_false(r.effect[SCENE_FX_AO]);
    assert_false(r.effect[SCENE_FX_PROBES]);
    assert_false(r.effect[SCENE_FX_TRIANGLE_LOOKUP]);
    assert_false(r.cache[SCENE_CACHE_ON_SURFACE]);
    assert_false(r.cache[SCENE_CACHE_WORLD_SPACE]);
    assert_string_equal(r.effect_reason[SCENE_FX_SHADOW], "switched off in the scene description");
    assert_string_equal(r.effect_reason[SCENE_FX_AO], "switched off in the scene description");
    assert_string_equal(r.effect_reason[SCENE_FX_PROBES], "switched off in the scene description");
    scene_free(s);
}

/* Only indirect switched off: shadows and AO stay, the world-space cache goes. */
static void test_needs_indirect_off(void **state)
{
    (void)state;
    needs_fixture f = {.lights = 1,
                       .light_intensity = 1,
                       .light_color = 1,
                       .sky_intensity = 1,
                       .albedo = 0.5f,
                       .indirect = SCENE_OFF};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_true(r.effect[SCENE_FX_SHADOW]);
    assert_true(r.effect[SCENE_FX_AO]);
    assert_false(r.effect[SCENE_FX_PROBES]);
    assert_true(r.cache[SCENE_CACHE_ON_SURFACE]);
    assert_false(r.cache[SCENE_CACHE_WORLD_SPACE]);
    assert_mentions(r.effect_reason[SCENE_FX_PROBES], "switched off");
    scene_free(s);
}

/* "on" forces effects that have nothing to work with, and the reason warns. */
static void test_needs_on_forces_with_warning(void **state)
{
    (void)state;
    needs_fixture f = {.albedo = 0, .shadows = SCENE_ON, .ao = SCENE_ON, .indirect = SCENE_ON};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_true(r.effect[SCENE_FX_SHADOW]);
    assert_true(r.effect[SCENE_FX_AO]);
    assert_true(r.effect[SCENE_FX_PROBES]);
    assert_true(r.cache[SCENE_CACHE_ON_SURFACE]);
    assert_true(r.cache[SCENE_CACHE_WORLD_SPACE]);
    for (int fx = SCENE_FX_SHADOW; fx < SCENE_FX_COUNT; fx++) {
        assert_mentions(r.effect_reason[fx], "forced on");
        assert_mentions(r.effect_reason[fx], "warning");
    }
    scene_free(s);
}

/* "on" for an effect that would run anyway: forced, no warning. */
static void test_needs_on_without_warning(void **state)
{
    (void)state;
    needs_fixture f = {
        .lights = 1, .light_intensity = 1, .light_color = 1, .albedo = 0.5f, .shadows = SCENE_ON};
    scene *s = make_scene(&f);
    scene_needs_result r = needs_of(s);
    assert_true(r.effect[SCENE_FX_SHADOW]);
    assert_mentions(r.effect_reason[SCENE_FX_SHADOW], "forced on");
    assert_null(strstr(r.effect_reason[SCENE_FX_SHADOW], "warning"));
    scene_free(s);
}

/* The embedded default scene needs everything. */
static void test_needs_default_scene(void **state)
{
    (void)state;
    scene *s = scene__alloc();
    assert_non_null(s);
    scene_error err = {0};
    if (scene__build_default(s, &err) != SCENE_OK)
        fail_msg("%s", err.msg);
    scene_needs_result r = needs_of(s);
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++)
        assert_true(r.effect[fx]);
    assert_true(r.cache[SCENE_CACHE_ON_SURFACE]);
    assert_true(r.cache[SCENE_CACHE_WORLD_SPACE]);
    scene_free(s);
}

/* Overrides from a JSON description reach scene_needs(). */
static void test_needs_from_json(void **state)
{
    (void)state;
    fxt_write_file("quad.obj", "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 3 2\nf 1 4 3\n");
    const char *path = fxt_write_file("needs.json", "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}],"
                                                    " \"sky\": {\"intensity\": 1},"
                                                    " \"effects\": {\"ao\": \"off\", \"shadows\": \"on\"}}");
    char path_copy[1024];
    snprintf(path_copy, sizeof path_copy, "%s", path);
    scene *s = scene__alloc();
    assert_non_null(s);
    scene_error err = {0};
    if (scene__load_json(s, path_copy, &err) != SCENE_OK)
        fail_msg("%s", err.msg);
    scene_needs_result r = needs_of(s);
    assert_true(r.effect[SCENE_FX_SHADOW]);
    assert_mentions(r.effect_reason[SCENE_FX_SHADOW], "warning"); /* forced, but the scene has no light */
    assert_false(r.effect[SCENE_FX_AO]);
    assert_mentions(r.effect_reason[SCENE_FX_AO], "switched off");
    assert_true(r.effect[SCENE_FX_PROBES]); /* the sky lights a grey quad */
    scene_free(s);
}

/* The short names, and "?" out of range. */
static void test_needs_names(void **state)
{
    (void)state;
    assert_string_equal(scene_effect_name(SCENE_FX_TRIANGLE_LOOKUP), "triangle_lookup");
    assert_string_equal(scene_effect_name(SCENE_FX_SHADOW), "shadow");
    assert_string_equal(scene_effect_name(SCENE_FX_AO), "ao");
    assert_string_equal(scene_effect_name(SCENE_FX_PROBES), "probes");
    assert_string_equal(scene_effect_name(SCENE_FX_COUNT), "?");
    assert_string_equal(scene_cache_name(SCENE_CACHE_ON_SURFACE), "on_surface");
    assert_string_equal(scene_cache_name(SCENE_CACHE_WORLD_SPACE), "world_space");
    assert_string_equal(scene_cache_name(SCENE_CACHE_COUNT), "?");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_needs_nothing),
        cmocka_unit_test(test_needs_emission),
        cmocka_unit_test(test_needs_light_only),
        cmocka_unit_test(test_needs_sky_only),
        cmocka_unit_test(test_needs_everything),
        cmocka_unit_test(test_needs_dark_lights),
        cmocka_unit_test(test_needs_black_sky),
        cmocka_unit_test(test_needs_black_materials),
        cmocka_unit_test(test_needs_texture_counts_as_albedo),
        cmocka_unit_test(test_needs_off_wins),
        cmocka_unit_test(test_needs_indirect_off),
        cmocka_unit_test(test_needs_on_forces_with_warning),
        cmocka_unit_test(test_needs_on_without_warning),
        cmocka_unit_test(test_needs_default_scene),
        cmocka_unit_test(test_needs_from_json),
        cmocka_unit_test(test_needs_names),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
