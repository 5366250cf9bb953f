/* Tests of JSON scene descriptions (scene/scene_json.c) and the embedded default scene (scene_default.c):
 * valid descriptions load with the right values (the refusals are in test_scene_json_errors.c). Most tests
 * call scene__load_json() on a fresh scene (white box, no islands needed); one loads through scene_load(),
 * the entry point users use. */
#include "test_util.h"

#include "fxt_scene.h"
#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Positions of every vertex of mesh m: the smallest and largest coordinate, in world coordinates (the scene
 * keeps them relative to its origin). */
static void mesh_bounds(const scene *s, uint32_t m, float lo[3], float hi[3])
{
    for (int k = 0; k < 3; k++) {
        lo[k] = INFINITY;
        hi[k] = -INFINITY;
    }
    const scene_mesh *mesh = &s->meshes[m];
    for (uint32_t t = mesh->first_triangle; t < mesh->first_triangle + mesh->triangle_count; t++)
        for (int c = 0; c < 3; c++) {
            const float *p = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + c];
            for (int k = 0; k < 3; k++) {
                lo[k] = fminf(lo[k], (float)(p[k] + s->origin[k]));
                hi[k] = fmaxf(hi[k], (float)(p[k] + s->origin[k]));
            }
        }
}

/* A local position of s in world coordinates, rounded to float for comparisons. */
static void world_of(const scene *s, const float local[3], float out[3])
{
    double world[3];
    scene_local_to_world(s, local, world);
    for (int k = 0; k < 3; k++)
        out[k] = (float)world[k];
}

/* ---- valid descriptions --------------------------------------------------------------------------------- */

/* Every section at once: values arrive in the scene as written (directions normalised). */
static void test_valid_full_description(void **state)
{
    (void)state;
    scene_error err;
    scene *s = fxt_load_json_text(
        "full.json",
        "{\n"
        "  \"version\": 1,\n"
        "  \"comment\": \"everything\",\n"
        "  \"meshes\": [\n"
        "    {\"file\": \"quad.obj\", \"name\": \"ground\",\n"
        "     \"transform\": {\"translate\": [10, 1, -2], \"scale\": 2},\n"
        "     \"material\": {\"diffuse\": [0.2, 0.4, 0.6], \"name\": \"blueish\"}}\n"
        "  ],\n"
        "  \"lights\": [\n"
        "    {\"type\": \"directional\", \"direction\": [0, -2, 0], \"color\": [1, 0.5, 0.25],"
        " \"intensity\": 3},\n"
        "    {\"type\": \"point\", \"position\": [1, 2, 3], \"intensity\": 40}\n"
        "  ],\n"
        "  \"sky\": {\"color\": [0.5, 0.6, 0.7], \"intensity\": 0.25},\n"
        "  \"texel_density\": 50,\n"
        "  \"ao_radius\": 0.3,\n"
        "  \"effects\": {\"shadows\": \"on\", \"ao\": \"off\", \"indirect\": \"auto\"},\n"
        "  \"camera\": {\"position\": [0, 1.5, 5], \"target\": [0, 0, 0], \"fov_deg\": 45}\n"
        "}\n",
        &err);
    if (!s)
        fail_msg("%s", err.msg);
    assert_int_equal(s->mesh_count, 1);
    assert_int_equal(s->triangle_count, 2);
    assert_string_equal(s->meshes[0].name, "ground");
    const scene_material *m = &s->materials[s->meshes[0].material];
    assert_float_equal(m->diffuse[0], 0.2f, 1e-6);
    assert_float_equal(m->diffuse[1], 0.4f, 1e-6);
    assert_float_equal(m->diffuse[2], 0.6f, 1e-6);
    assert_int_equal(m->texture, -1);
    assert_string_equal(m->name, "blueish");
    float lo[3], hi[3];
    mesh_bounds(s, 0, lo, hi);
    assert_float_equal(lo[0], 10.0f, 1e-5);
    assert_float_equal(hi[0], 12.0f, 1e-5);
    assert_float_equal(lo[1], 1.0f, 1e-5);
    assert_float_equal(lo[2], -2.0f, 1e-5);
    assert_float_equal(hi[2], 0.0f, 1e-5);

    assert_int_equal(s->light_count, 2);
    assert_int_equal(s->lights[0].type, SCENE_LIGHT_DIRECTIONAL);
    assert_float_equal(s->lights[0].direction[1], -1.0f, 1e-6);
    assert_float_equal(s->lights[0].color[1], 0.5f, 1e-6);
    assert_float_equal(s->lights[0].intensity, 3.0f, 1e-6);
    assert_int_equal(s->lights[1].type, SCENE_LIGHT_POINT);
    /* The quad spans x 10..12 about 11 m from the world origin, 2 m wide: the scene is rebased onto its
     * centre rounded to a multiple of 2 m, and the point light and camera follow into that frame. */
    assert_float_equal(s->origin[0], 12.0, 0);
    assert_float_equal(s->origin[1], 0.0, 0);
    assert_float_equal(s->origin[2], 0.0, 0); /* -1 / 2 rounds to even: 0 */
    float world[3];
    world_of(s, s->lights[1].position, world);
    assert_float_equal(world[0], 1.0f, 1e-6);
    assert_float_equal(world[2], 3.0f, 1e-6);
    assert_float_equal(s->lights[1].color[0], 1.0f, 1e-6); /* default colour */
    assert_float_equal(s->lights[1].intensity, 40.0f, 1e-6);

    assert_float_equal(s->sky_color[2], 0.7f, 1e-6);
    assert_float_equal(s->sky_intensity, 0.25f, 1e-6);
    assert_false(s->density_auto);
    assert_float_equal(s->texel_density, 50.0f, 1e-6);
    assert_float_equal(s->ao_radius, 0.3f, 1e-6);
    assert_int_equal(s->fx_shadows, SCENE_ON);
    assert_int_equal(s->fx_ao, SCENE_OFF);
    assert_int_equal(s->fx_indirect, SCENE_AUTO);
    assert_true(s->has_camera);
    world_of(s, s->camera_pos, world);
    assert_float_equal(world[1], 1.5f, 1e-6);
    assert_float_equal(world[2], 5.0f, 1e-6);
    world_of(s, s->camera_target, world);
    assert_float_equal(world[0], 0.0f, 1e-6);
    assert_float_equal(s->camera_fov_deg, 45.0f, 1e-6);
    scene_free(s);
}

/* Without "lights" and "sky" a description has none: no defaults are added. */
static void test_valid_no_lights_no_sky(void **state)
{
    (void)state;
    scene_error err;
    scene *s =
        fxt_load_json_text("bare.json", "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}]}", &err);
    if (!s)
        fail_msg("%s", err.msg);
    assert_int_equal(s->light_count, 0);
    assert_float_equal(s->sky_intensity, 0.0f, 0);
    assert_float_equal(s->sky_color[0], 0.0f, 0);
    assert_true(s->density_auto);
    assert_false(s->has_camera);
    assert_int_equal(s->fx_shadows, SCENE_AUTO);
    scene_free(s);
}

/* Rotation order and the two matrix forms: the same placement three ways. */
static void test_valid_transforms(void **state)
{
    (void)state;
    scene_error err;
    /* Rx(90) maps (x, y, z) to (x, -z, y): the quad (z 0..1, y = 0) then spans y -1..0 at z = 0, and the
     * translation moves it to z = 5. The matrix forms below write the same transform out. */
    scene *s = fxt_load_json_text(
        "xforms.json",
        "{\"version\": 1, \"meshes\": [\n"
        " {\"file\": \"quad.obj\", \"transform\": {\"rotate_deg\": [90, 0, 0],"
        " \"translate\": [0, 0, 5]}},\n"
        " {\"file\": \"quad.obj\", \"transform\": {\"matrix\": [1,0,0,0, 0,0,-1,0,"
        " 0,1,0,5, 0,0,0,1]}},\n"
        " {\"file\": \"quad.obj\", \"transform\": [1,0,0,0, 0,0,-1,0, 0,1,0,5, 0,0,0,1]},\n"
        " {\"file\": \"quad.obj\", \"transform\": {\"scale\": [2, 1, 3]}}\n"
        "]}",
        &err);
    if (!s)
        fail_msg("%s", err.msg);
    assert_int_equal(s->mesh_count, 4);
    for (uint32_t m = 0; m < 3; m++) {
        float lo[3], hi[3];
        mesh_bounds(s, m, lo, hi);
        assert_float_equal(lo[0], 0.0f, 1e-5);
        assert_float_equal(hi[0], 1.0f, 1e-5);
        assert_float_equal(lo[1], -1.0f, 1e-5);
        assert_float_equal(hi[1], 0.0f, 1e-5);
        assert_float_equal(lo[2], 5.0f, 1e-5);
        assert_float_equal(hi[2], 5.0f, 1e-5);
    }
    float lo[3], hi[3];
    mesh_bounds(s, 3, lo, hi);
    assert_float_equal(hi[0], 2.0f, 1e-6);
    assert_float_equal(hi[2], 3.0f, 1e-6);
    scene_free(s);
}

/* "auto" density, a file in a subfolder (paths relative to the JSON file), an empty lights list. */
static void test_valid_auto_density_and_subfolder(void **state)
{
    (void)state;
    fxt_write_quad();
    char folder[1100];
    snprintf(folder, sizeof folder, "%s", fxt_tmp_path("sub"));
    char command[1200];
    snprintf(command, sizeof command, "mkdir -p '%s'", folder);
    assert_int_equal(system(command), 0);
    fxt_write_file("sub/quad2.obj", fxt_quad_obj);
    scene_error err;
    scene *s = fxt_load_json_text("sub/auto.json",
                                  "{\"version\": 1, \"texel_density\": \"auto\", \"lights\": [],"
                                  " \"meshes\": [{\"file\": \"quad2.obj\"}, {\"file\": \"../quad.obj\"}]}",
                                  &err);
    if (!s)
        fail_msg("%s", err.msg);
    assert_true(s->density_auto);
    assert_int_equal(s->mesh_count, 2);
    assert_int_equal(s->light_count, 0);
    scene_free(s);
}

/* {"builtin": "default"} brings the default scene's geometry but not its lights, sky or camera. */
static void test_valid_builtin_default(void **state)
{
    (void)state;
    scene_error err;
    scene *s = fxt_load_json_text(
        "builtin.json",
        "{\"version\": 1, \"meshes\": [{\"builtin\": \"default\"}, {\"file\": \"quad.obj\"}],"
        " \"lights\": [{\"type\": \"point\", \"position\": [0, 2, 0], \"intensity\": 5}]}",
        &err);
    if (!s)
        fail_msg("%s", err.msg);
    assert_true(s->mesh_count >= 5);
    assert_true(s->triangle_count > 1000);
    assert_int_equal(s->light_count, 1);
    assert_int_equal(s->lights[0].type, SCENE_LIGHT_POINT);
    assert_float_equal(s->sky_intensity, 0.0f, 0);
    assert_false(s->has_camera);
    scene_free(s);
}

/* The whole way users go: scene_load() on a .json path, through finalisation (islands). */
static void test_valid_through_scene_load(void **state)
{
    (void)state;
    fxt_write_quad();
    const char *path = fxt_write_file("load.json", "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}],"
                                                   " \"sky\": {\"intensity\": 1}, \"texel_density\": 64}");
    char path_copy[1024];
    snprintf(path_copy, sizeof path_copy, "%s", path);
    scene_error err = {0};
    scene *s = scene_load(path_copy, NULL, &err);
    if (!s)
        fail_msg("scene_load: %s", err.msg);
    assert_int_equal(s->triangle_count, 2);
    assert_float_equal(s->texel_density, 64.0f, 1e-6);
    assert_true(s->island_count >= 1);
    assert_float_equal(s->tri_normal[1], 1.0f, 1e-6); /* the quad faces up */
    scene_free(s);
}

/* ---- the embedded default scene ------------------------------------------------------------------------ */

/* Size, materials, sun, sky, camera, and normals: room surfaces face into the room, objects face out. */
static void test_default_scene_content(void **state)
{
    (void)state;
    scene *s = scene__alloc();
    assert_non_null(s);
    scene_error err = {0};
    if (scene__build_default(s, &err) != SCENE_OK)
        fail_msg("%s", err.msg);
    printf("  default scene: %u triangles, %u meshes, %u materials\n", s->triangle_count, s->mesh_count,
           s->material_count);
    assert_true(s->triangle_count >= 1000 && s->triangle_count <= 3000);
    assert_true(s->material_count >= 3);
    assert_int_equal(s->light_count, 1);
    assert_int_equal(s->lights[0].type, SCENE_LIGHT_DIRECTIONAL);
    assert_true(s->lights[0].direction[1] < 0); /* the sun shines down */
    assert_true(s->sky_intensity > 0);
    assert_true(s->has_camera);
    const float room_lo[3] = {-5, 0, -4}, room_hi[3] = {5, 4, 4};
    for (int k = 0; k < 3; k++) /* inside the room */
        assert_true(s->camera_pos[k] > room_lo[k] && s->camera_pos[k] < room_hi[k]);
    assert_int_equal(s->repairs.degenerate_skipped, 0);
    assert_int_equal(s->repairs.duplicate_skipped, 0);

    const float room_center[3] = {0, 2, 0};
    for (uint32_t m = 0; m < s->mesh_count; m++) {
        const scene_mesh *mesh = &s->meshes[m];
        bool room = strcmp(mesh->name, "floor") == 0 || strcmp(mesh->name, "walls") == 0 ||
                    strncmp(mesh->name, "ceiling", 7) == 0;
        float lo[3], hi[3], center[3];
        mesh_bounds(s, m, lo, hi);
        for (int k = 0; k < 3; k++)
            center[k] = room ? room_center[k] : 0.5f * (lo[k] + hi[k]);
        for (uint32_t t = mesh->first_triangle; t < mesh->first_triangle + mesh->triangle_count; t++) {
            const float *a = s->positions + 3 * (size_t)s->indices[3 * (size_t)t];
            const float *b = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 1];
            const float *c = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 2];
            float e1[3], e2[3], n[3], centroid[3];
            for (int k = 0; k < 3; k++) {
                e1[k] = b[k] - a[k];
                e2[k] = c[k] - a[k];
                centroid[k] = (a[k] + b[k] + c[k]) / 3.0f;
            }
            n[0] = e1[1] * e2[2] - e1[2] * e2[1];
            n[1] = e1[2] * e2[0] - e1[0] * e2[2];
            n[2] = e1[0] * e2[1] - e1[1] * e2[0];
            float to_center = 0;
            for (int k = 0; k < 3; k++)
                to_center += n[k] * (center[k] - centroid[k]);
            if (room ? !(to_center > 0) : !(to_center < 0))
                fail_msg("mesh '%s' triangle %u faces the wrong way", mesh->name, t);
        }
    }
    scene_free(s);
}

/* Sunlight falls through the ceiling opening onto the floor, and the ceiling shades the rest of the room. */
static void test_default_scene_sun_patch(void **state)
{
    (void)state;
    scene *s = scene__alloc();
    assert_non_null(s);
    scene_error err = {0};
    if (scene__build_default(s, &err) != SCENE_OK)
        fail_msg("%s", err.msg);
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    if (!rt)
        fail_msg("%s", err.msg);
    const float *sun = s->lights[0].direction;
    const float towards_sun[3] = {-sun[0], -sun[1], -sun[2]};
    const float lit[3] = {3.5f, 0.001f, -0.5f}, shaded[3] = {-3.0f, 0.001f, 2.0f};
    uint32_t tri;
    float u, v, t;
    assert_false(scene_rt_intersect1(rt, lit, towards_sun, 1e30f, &tri, &u, &v, &t));
    assert_true(scene_rt_intersect1(rt, shaded, towards_sun, 1e30f, &tri, &u, &v, &t));
    scene_rt_free(rt);
    scene_free(s);
}

/* The default scene through scene_load("default"): finalised, with islands, and its camera kept. */
static void test_default_scene_through_scene_load(void **state)
{
    (void)state;
    scene_error err = {0};
    scene *s = scene_load("default", NULL, &err);
    if (!s)
        fail_msg("scene_load(default): %s", err.msg);
    assert_true(s->island_count > 0);
    assert_true(s->has_camera);
    assert_int_equal(s->repairs.nonmanifold_split, 0);
    assert_float_equal(s->ao_radius, 1.0f, 1e-6);
    scene_free(s);
}

/* ---- the command line ------------------------------------------------------------------------------ */

/* `fxcache scene-info` on a bad description fails and prints the one-line message with the JSON path. */
static void test_cli_reports_json_error(void **state)
{
    (void)state;
    fxt_write_quad();
    const char *path =
        fxt_write_file("cli_bad.json", "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}],"
                                       " \"lights\": [{\"type\": \"point\", \"position\": [0,1,0],"
                                       " \"intensity\": -1}]}");
    char args[1200], out[4096], errors[4096];
    snprintf(args, sizeof args, "scene-info '%s'", path);
    int status = fxt_run_cli(args, out, sizeof out, errors, sizeof errors);
    printf("  exit %d, stderr: %s", status, errors);
    assert_int_not_equal(status, 0);
    assert_non_null(strstr(errors, "cli_bad.json"));
    assert_non_null(strstr(errors, "lights[0].intensity"));
}

/* `fxcache scene-info` on a description without lights says why there are no shadows. */
static void test_cli_scene_info_without_lights(void **state)
{
    (void)state;
    fxt_write_quad();
    const char *path =
        fxt_write_file("cli_ok.json", "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}],"
                                      " \"sky\": {\"intensity\": 1}}");
    char args[1200], out[8192], errors[4096];
    snprintf(args, sizeof args, "scene-info '%s'", path);
    int status = fxt_run_cli(args, out, sizeof out, errors, sizeof errors);
    if (status != 0)
        fail_msg("exit %d: %s", status, errors);
    assert_non_null(strstr(out, "the scene has no lights"));
    assert_non_null(strstr(out, "the sky gives ambient light"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_valid_full_description),
        cmocka_unit_test(test_valid_no_lights_no_sky),
        cmocka_unit_test(test_valid_transforms),
        cmocka_unit_test(test_valid_auto_density_and_subfolder),
        cmocka_unit_test(test_valid_builtin_default),
        cmocka_unit_test(test_valid_through_scene_load),
        cmocka_unit_test(test_default_scene_content),
        cmocka_unit_test(test_default_scene_sun_patch),
        cmocka_unit_test(test_default_scene_through_scene_load),
        cmocka_unit_test(test_cli_reports_json_error),
        cmocka_unit_test(test_cli_scene_info_without_lights),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
