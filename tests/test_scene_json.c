/* Tests of JSON scene descriptions (scene/scene_json.c) and the embedded default scene (scene_default.c).
 *
 * Valid descriptions load with the right values; every error case has its own test asserting both the
 * result code and that the one-line message names what is wrong and where (line:column for malformed JSON,
 * the JSON path and field for content errors, the mesh and vertex for bad coordinates in a mesh file).
 * Most tests call scene__load_json() on a fresh scene (white box, no islands needed); one loads through
 * scene_load(), the entry point users use. */
#include "test_util.h"

#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* A unit quad in the XZ plane facing up (+y), two triangles. */
static const char quad_obj[] = "o quad\n"
                               "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\n"
                               "f 1 3 2\nf 1 4 3\n";

/* Writes quad.obj into the scratch folder, where the JSON files of these tests refer to it. */
static const char *write_quad(void)
{
    return fxt_write_file("quad.obj", quad_obj);
}

/* Writes text as a JSON file name next to quad.obj, loads it into a fresh scene and finalises it; returns
 * the scene on success (caller frees) or NULL with err filled. */
static scene *load_json_text(const char *name, const char *text, scene_error *err)
{
    write_quad();
    const char *path = fxt_write_file(name, text);
    char path_copy[1024];
    snprintf(path_copy, sizeof path_copy, "%s", path);
    scene *s = scene__alloc();
    assert_non_null(s);
    snprintf(s->source, sizeof s->source, "%s", path_copy); /* as scene_load() names it */
    memset(err, 0, sizeof *err);
    scene_result r = scene__load_json(s, path_copy, err);
    if (r == SCENE_OK) /* settles the local frame: positions, lights and camera relative to s->origin */
        r = scene__finalize(s, NULL, err);
    if (r != SCENE_OK) {
        assert_int_equal(err->code, r);
        scene_free(s);
        return NULL;
    }
    return s;
}

/* Loads text (expected to fail) and asserts the code and that the message holds every given fragment. */
static void expect_error(const char *name, const char *text, scene_result code, const char *fragment1,
                         const char *fragment2)
{
    scene_error err;
    scene *s = load_json_text(name, text, &err);
    if (s) {
        scene_free(s);
        fail_msg("%s loaded, expected %s", name, scene_strerror(code));
    }
    printf("  %s -> [%s] %s\n", name, scene_strerror(err.code), err.msg);
    assert_int_equal(err.code, code);
    assert_non_null(strstr(err.msg, name));
    if (fragment1 && !strstr(err.msg, fragment1))
        fail_msg("message '%s' does not mention '%s'", err.msg, fragment1);
    if (fragment2 && !strstr(err.msg, fragment2))
        fail_msg("message '%s' does not mention '%s'", err.msg, fragment2);
    assert_null(strchr(err.msg, '\n'));
}

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
    scene *s =
        load_json_text("full.json",
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
    scene *s = load_json_text("bare.json", "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}]}", &err);
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
    scene *s =
        load_json_text("xforms.json",
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
    write_quad();
    char folder[1100];
    snprintf(folder, sizeof folder, "%s", fxt_tmp_path("sub"));
    char command[1200];
    snprintf(command, sizeof command, "mkdir -p '%s'", folder);
    assert_int_equal(system(command), 0);
    fxt_write_file("sub/quad2.obj", quad_obj);
    scene_error err;
    scene *s = load_json_text("sub/auto.json",
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
    scene *s =
        load_json_text("builtin.json",
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
    write_quad();
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
    write_quad();
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
    write_quad();
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

/* ---- malformed JSON --------------------------------------------------------------------------------- */

/* A trailing comma: the message carries the line and column of the fault. */
static void test_error_syntax_line_column(void **state)
{
    (void)state;
    expect_error("syntax.json",
                 "{\n"
                 "  \"version\": 1,\n"
                 "  \"meshes\": [\n"
                 "    {\"file\": \"quad.obj\",}\n"
                 "  ]\n"
                 "}\n",
                 SCENE_ERR_JSON, "syntax.json:4:", NULL);
}

/* A key given twice is refused (JSON_REJECT_DUPLICATES), with line and column. */
static void test_error_duplicate_key(void **state)
{
    (void)state;
    expect_error("dup.json", "{\"version\": 1,\n \"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_JSON, "dup.json:2:", "duplicate");
}

/* A number beyond double range is a parse error, with line and column. */
static void test_error_number_overflow(void **state)
{
    (void)state;
    expect_error("overflow.json",
                 "{\"version\": 1,\n\n \"ao_radius\": 1e400, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_JSON, "overflow.json:3:", NULL);
}

/* The top level must be an object. */
static void test_error_top_level_not_object(void **state)
{
    (void)state;
    expect_error("array.json", "[1, 2, 3]", SCENE_ERR_JSON, "top level", "array");
}

/* The JSON file itself is missing. */
static void test_error_missing_json_file(void **state)
{
    (void)state;
    scene *s = scene__alloc();
    assert_non_null(s);
    scene_error err = {0};
    assert_int_equal(scene__load_json(s, fxt_tmp_path("no_such_scene.json"), &err), SCENE_ERR_IO);
    assert_non_null(strstr(err.msg, "no_such_scene.json"));
    scene_free(s);
}

/* ---- structure: unknown fields, wrong types, missing fields, versions ---------------------------------- */

/* An unknown top-level field is named. */
static void test_error_unknown_top_field(void **state)
{
    (void)state;
    expect_error("unknown_top.json",
                 "{\"version\": 1, \"lightz\": [], \"meshes\": [{\"file\": \"quad.obj\"}]}", SCENE_ERR_JSON,
                 "'lightz'", "top level");
}

/* An unknown field whose name holds a newline still gives a one-line message. */
static void test_error_unknown_field_with_newline(void **state)
{
    (void)state;
    expect_error("newline_key.json",
                 "{\"version\": 1, \"bad\\nkey\": 1, \"meshes\": [{\"file\": \"quad.obj\"}]}", SCENE_ERR_JSON,
                 "'bad?key'", NULL);
}

/* An unknown field inside a light is named with the light's path. */
static void test_error_unknown_light_field(void **state)
{
    (void)state;
    expect_error("unknown_light.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": ["
                 "{\"type\": \"point\", \"position\": [0,1,0]},"
                 "{\"type\": \"point\", \"position\": [0,1,0], \"colour\": [1,1,1]}]}",
                 SCENE_ERR_JSON, "lights[1]", "'colour'");
}

/* An unknown field inside a mesh transform is named with its path. */
static void test_error_unknown_transform_field(void **state)
{
    (void)state;
    expect_error(
        "unknown_xform.json",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"transform\": {\"rotate\": [0,0,0]}}]}",
        SCENE_ERR_JSON, "meshes[0].transform", "'rotate'");
}

/* A string where a number belongs. */
static void test_error_wrong_type_intensity(void **state)
{
    (void)state;
    expect_error("type_intensity.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}],"
                 " \"sky\": {\"intensity\": \"bright\"}}",
                 SCENE_ERR_JSON, "sky.intensity", "must be a number");
}

/* A colour of the wrong length. */
static void test_error_wrong_length_color(void **state)
{
    (void)state;
    expect_error("type_color.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}],"
                 " \"lights\": [{\"type\": \"directional\", \"direction\": [0,-1,0], \"color\": [1, 1]}]}",
                 SCENE_ERR_JSON, "lights[0].color", "3 numbers");
}

/* "meshes" must be an array. */
static void test_error_meshes_not_array(void **state)
{
    (void)state;
    expect_error("meshes_object.json", "{\"version\": 1, \"meshes\": {\"file\": \"quad.obj\"}}",
                 SCENE_ERR_JSON, "meshes", "must be an array");
}

/* "version" is required. */
static void test_error_missing_version(void **state)
{
    (void)state;
    expect_error("no_version.json", "{\"meshes\": [{\"file\": \"quad.obj\"}]}", SCENE_ERR_JSON, "'version'",
                 NULL);
}

/* "meshes" is required. */
static void test_error_missing_meshes(void **state)
{
    (void)state;
    expect_error("no_meshes.json", "{\"version\": 1}", SCENE_ERR_JSON, "'meshes'", NULL);
}

/* A mesh entry needs "file". */
static void test_error_missing_file(void **state)
{
    (void)state;
    expect_error("no_file.json", "{\"version\": 1, \"meshes\": [{\"name\": \"lost\"}]}", SCENE_ERR_JSON,
                 "meshes[0]", "'file'");
}

/* A light needs "type"; a directional light needs "direction". */
static void test_error_missing_light_fields(void **state)
{
    (void)state;
    expect_error("no_type.json", "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": [{}]}",
                 SCENE_ERR_JSON, "lights[0]", "'type'");
    expect_error(
        "no_direction.json",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": [{\"type\": \"directional\"}]}",
        SCENE_ERR_JSON, "lights[0]", "'direction'");
}

/* A point light with a direction is a mistake worth naming. */
static void test_error_point_light_with_direction(void **state)
{
    (void)state;
    expect_error("point_dir.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": ["
                 "{\"type\": \"point\", \"position\": [0,1,0], \"direction\": [0,-1,0]}]}",
                 SCENE_ERR_JSON, "lights[0]", "'direction'");
}

/* An unknown light type. */
static void test_error_unknown_light_type(void **state)
{
    (void)state;
    expect_error(
        "spot.json",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": [{\"type\": \"spot\"}]}",
        SCENE_ERR_INVALID, "lights[0].type", "'spot'");
}

/* A newer version is refused with both numbers. */
static void test_error_newer_version(void **state)
{
    (void)state;
    expect_error("v2.json", "{\"version\": 2, \"meshes\": [{\"file\": \"quad.obj\"}]}", SCENE_ERR_FORMAT,
                 "version: 2 is newer", "(1)");
}

/* A version written as a real number is refused with both types named. */
static void test_error_version_not_integer(void **state)
{
    (void)state;
    expect_error("v1real.json", "{\"version\": 1.5, \"meshes\": [{\"file\": \"quad.obj\"}]}", SCENE_ERR_JSON,
                 "version", "must be an integer, not a real number");
}

/* ---- values ------------------------------------------------------------------------------------------- */

/* A negative intensity. */
static void test_error_negative_intensity(void **state)
{
    (void)state;
    expect_error("negative.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": ["
                 "{\"type\": \"point\", \"position\": [0,1,0]},"
                 "{\"type\": \"directional\", \"direction\": [0,-1,0], \"intensity\": -2}]}",
                 SCENE_ERR_INVALID, "lights[1].intensity: must be a finite number >= 0", NULL);
}

/* A number that is finite as a double but infinite as a float. */
static void test_error_float_overflow(void **state)
{
    (void)state;
    expect_error("float_overflow.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": ["
                 "{\"type\": \"directional\", \"direction\": [0,-1,0], \"intensity\": 1e39}]}",
                 SCENE_ERR_INVALID, "lights[0].intensity", "finite");
}

/* Colour and intensity each a float but their product not (1e30 x 1e30): refused, for a light and for the sky;
 * the product just below FLT_MAX loads. Before, compose multiplied them into infinity, and a shadowed
 * pixel's 0 x inf made NaN, written out as black. */
static void test_error_light_product_overflow(void **state)
{
    (void)state;
    expect_error(
        "light_product.json",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": ["
        "{\"type\": \"point\", \"position\": [0,1,0], \"color\": [1, 1e30, 0], \"intensity\": 1e30}]}",
        SCENE_ERR_INVALID, "lights[0]: light colour x intensity must fit a float", "1e+60");
    expect_error("sky_product.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], "
                 "\"sky\": {\"color\": [1e20, 1, 1], \"intensity\": 1e20}}",
                 SCENE_ERR_INVALID, "sky: color x intensity must fit a float", "1e+40");
    scene_error err;
    scene *s =
        load_json_text("product_fits.json",
                       "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": ["
                       "{\"type\": \"directional\", \"direction\": [0,-1,0], \"color\": [1e19, 1, 1], "
                       "\"intensity\": 3e19}], \"sky\": {\"color\": [3e19, 0, 1], \"intensity\": 1e19}}",
                       &err);
    assert_non_null(s);
    assert_int_equal(s->light_count, 1);
    assert_true(s->sky_intensity == 1e19f);
    scene_free(s);
}

/* A zero light direction. */
static void test_error_zero_direction(void **state)
{
    (void)state;
    expect_error("zero_dir.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"lights\": ["
                 "{\"type\": \"directional\", \"direction\": [0, 0, 0]}]}",
                 SCENE_ERR_INVALID, "lights[0].direction", "zero");
}

/* A negative sky colour component. */
static void test_error_negative_sky_color(void **state)
{
    (void)state;
    expect_error(
        "sky_color.json",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}], \"sky\": {\"color\": [0.5, -0.1, 1]}}",
        SCENE_ERR_INVALID, "sky.color", ">= 0");
}

/* Texel density 0, negative and absurdly large: refused with the allowed range. */
static void test_error_density_range(void **state)
{
    (void)state;
    expect_error("density0.json",
                 "{\"version\": 1, \"texel_density\": 0, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_RANGE, "texel_density", "allowed");
    expect_error("density_neg.json",
                 "{\"version\": 1, \"texel_density\": -5, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_RANGE, "texel_density", "allowed");
    expect_error("density_huge.json",
                 "{\"version\": 1, \"texel_density\": 1e12, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_RANGE, "texel_density", "allowed");
    /* just outside the ends, as doubles that stay outside once rounded to float */
    expect_error("density_low.json",
                 "{\"version\": 1, \"texel_density\": 9.9e-7, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_RANGE, "texel_density", "allowed");
    expect_error("density_high.json",
                 "{\"version\": 1, \"texel_density\": 1.0001e6, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_RANGE, "texel_density", "allowed");
}

/* The documented ends of the range, 1e-6 and 1e6, are accepted (1e-6 was refused: the double bound is larger
 * than the float the value becomes). */
static void test_density_range_ends(void **state)
{
    (void)state;
    /* a 1 mm quad: 1000 texels on a side at 1e6, within an island's limit */
    fxt_write_file("mm_quad.obj", "v 0 0 0\nv 0.001 0 0\nv 0.001 0 0.001\nv 0 0 0.001\nf 1 3 2\nf 1 4 3\n");
    static const char *const texts[2] = {
        "{\"version\": 1, \"texel_density\": 1e-6, \"meshes\": [{\"file\": \"mm_quad.obj\"}]}",
        "{\"version\": 1, \"texel_density\": 1e6, \"meshes\": [{\"file\": \"mm_quad.obj\"}]}"};
    static const float expected[2] = {1e-6f, 1e6f};
    for (int i = 0; i < 2; i++) {
        scene_error err;
        scene *s = load_json_text("density_end.json", texts[i], &err);
        if (!s)
            fail_msg("texel_density %g refused: %s", (double)expected[i], err.msg);
        assert_false(s->density_auto);
        assert_true(s->texel_density == expected[i]);
        scene_free(s);
    }
}

/* The smallest scene: the embedded room (10 m long) scaled by 1e-8 spans 1e-7 m and is refused with the bound
 * and the remedy; at 1e-7 it spans 1e-6 m and loads (it used to load at any scale and render dark blotches and
 * holes below about 1e-11 m, and be refused camera by camera at 1e-20). */
static void test_error_scene_too_small(void **state)
{
    (void)state;
    expect_error(
        "tiny.json",
        "{\"version\": 1, \"meshes\": [{\"builtin\": \"default\", \"transform\": {\"scale\": 1e-8}}]}",
        SCENE_ERR_RANGE, "spans only 1e-07 m", "scale the scene up");
    scene_error err;
    scene *s = load_json_text("small.json",
                              "{\"version\": 1, \"meshes\": [{\"builtin\": \"default\", \"transform\": "
                              "{\"scale\": 1e-7}}]}",
                              &err);
    if (!s)
        fail_msg("a scene 1e-6 m across is refused: %s", err.msg);
    scene_free(s);
}

/* A UTF-8 byte-order mark before the JSON is skipped (it was refused: "'[' or '{' expected"); one anywhere
 * else is still malformed JSON. */
static void test_byte_order_mark(void **state)
{
    (void)state;
    scene_error err;
    scene *s = load_json_text("bom.json",
                              "\xef\xbb\xbf{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}]}", &err);
    if (!s)
        fail_msg("a byte-order mark is refused: %s", err.msg);
    assert_int_equal(s->triangle_count, 2);
    scene_free(s);
    expect_error("bom_twice.json",
                 "\xef\xbb\xbf\xef\xbb\xbf{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_JSON, "bom_twice.json:1:", NULL);
}

/* A texel density word other than "auto". */
static void test_error_density_word(void **state)
{
    (void)state;
    expect_error("density_word.json",
                 "{\"version\": 1, \"texel_density\": \"high\", \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_INVALID, "texel_density", "\"auto\"");
}

/* An override that is not auto, on or off. */
static void test_error_bad_override(void **state)
{
    (void)state;
    expect_error("override.json",
                 "{\"version\": 1, \"effects\": {\"ao\": \"maybe\"}, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_INVALID, "effects.ao", "\"maybe\"");
    expect_error("override_bool.json",
                 "{\"version\": 1, \"effects\": {\"shadows\": true}, \"meshes\": [{\"file\": \"quad.obj\"}]}",
                 SCENE_ERR_JSON, "effects.shadows", "boolean");
}

/* A camera field of view outside (0, 180). */
static void test_error_camera_fov(void **state)
{
    (void)state;
    expect_error(
        "fov.json",
        "{\"version\": 1, \"camera\": {\"position\": [0,0,1], \"target\": [0,0,0], \"fov_deg\": 180},"
        " \"meshes\": [{\"file\": \"quad.obj\"}]}",
        SCENE_ERR_INVALID, "camera.fov_deg", "180");
}

/* A zero scale, a non-affine matrix and a singular matrix. */
static void test_error_bad_transforms(void **state)
{
    (void)state;
    expect_error(
        "scale0.json",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"transform\": {\"scale\": [1, 0, 1]}}]}",
        SCENE_ERR_INVALID, "meshes[0].transform.scale", "zero");
    expect_error("projective.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"transform\": {\"matrix\":"
                 " [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,1,0]}}]}",
                 SCENE_ERR_INVALID, "meshes[0].transform.matrix", "affine");
    expect_error("singular.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"transform\":"
                 " [1,0,0,0, 2,0,0,0, 0,0,1,0, 0,0,0,1]}]}",
                 SCENE_ERR_INVALID, "meshes[0].transform", "singular");
    expect_error("matrix_and_scale.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"transform\":"
                 " {\"scale\": 2, \"matrix\": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}}]}",
                 SCENE_ERR_JSON, "meshes[0].transform", "cannot be combined");
}

/* An albedo above 1. */
static void test_error_albedo_above_one(void **state)
{
    (void)state;
    expect_error(
        "albedo.json",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"material\": {\"diffuse\": [1.5, 0, 0]}}]}",
        SCENE_ERR_INVALID, "meshes[0].material.diffuse", "0..1");
}

/* An unknown builtin scene. */
static void test_error_unknown_builtin(void **state)
{
    (void)state;
    expect_error("builtin_bad.json", "{\"version\": 1, \"meshes\": [{\"builtin\": \"sponza\"}]}",
                 SCENE_ERR_INVALID, "meshes[0].builtin", "'sponza'");
}

/* An empty meshes list. */
static void test_error_empty_meshes(void **state)
{
    (void)state;
    expect_error("empty.json", "{\"version\": 1, \"meshes\": []}", SCENE_ERR_EMPTY, "meshes", "empty");
}

/* ---- mesh files ------------------------------------------------------------------------------------------ */

/* A mesh file that does not exist: named, with the entry. */
static void test_error_missing_mesh_file(void **state)
{
    (void)state;
    expect_error("missing_mesh.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}, {\"file\": \"not_here.obj\"}]}",
                 SCENE_ERR_IO, "meshes[1]", "not_here.obj");
}

/* A file Assimp cannot read. */
static void test_error_unsupported_format(void **state)
{
    (void)state;
    fxt_write_file("notes.xyz", "this is not a mesh\n");
    expect_error("unsupported.json", "{\"version\": 1, \"meshes\": [{\"file\": \"notes.xyz\"}]}",
                 SCENE_ERR_FORMAT, "meshes[0]", "notes.xyz");
}

/* Assimp's OBJ reader turns the token "nan" into a NaN coordinate: refused, naming mesh and vertex. */
static void test_error_obj_nan(void **state)
{
    (void)state;
    fxt_write_file("nan.obj", "o nanmesh\nv 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
    expect_error("nan.json", "{\"version\": 1, \"meshes\": [{\"file\": \"nan.obj\"}]}", SCENE_ERR_INVALID,
                 "nanmesh", "vertex 2");
    scene_error err;
    scene *s = load_json_text("nan.json", "{\"version\": 1, \"meshes\": [{\"file\": \"nan.obj\"}]}", &err);
    assert_null(s);
    assert_non_null(strstr(err.msg, "nan.obj"));
    assert_non_null(strstr(err.msg, "meshes[0]"));
}

/* The token "inf" likewise. */
static void test_error_obj_inf(void **state)
{
    (void)state;
    fxt_write_file("inf.obj", "o infmesh\nv 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n");
    expect_error("inf.json", "{\"version\": 1, \"meshes\": [{\"file\": \"inf.obj\"}]}", SCENE_ERR_INVALID,
                 "infmesh", "vertex 1");
}

/* A coordinate too large for a float (1e39) becomes infinite: refused like inf. */
static void test_error_obj_float_overflow(void **state)
{
    (void)state;
    fxt_write_file("huge.obj", "o hugemesh\nv 0 0 0\nv 1 0 0\nv 0 1e39 0\nf 1 2 3\n");
    expect_error("huge.json", "{\"version\": 1, \"meshes\": [{\"file\": \"huge.obj\"}]}", SCENE_ERR_INVALID,
                 "hugemesh", "vertex 2");
}

/* A transform that pushes finite coordinates past float range. */
static void test_error_transform_overflow(void **state)
{
    (void)state;
    expect_error("xform_overflow.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"transform\": {\"scale\": 3e38, "
                 "\"translate\": [3e38, 0, 0]}}]}",
                 SCENE_ERR_INVALID, "meshes[0]", "vertex");
}

/* SCENE_MAX_REACH (1e12 m from the local centre; cameras SCENE_MAX_CAMERA_REACH, 1e13 m) bounds the scene's
 * extent, not where it lies. Two quads 2e13 m apart (the far one scaled up: unscaled, float spacing there makes
 * it degenerate, refused as such), a point light 3e12 m out or the camera 5e13 m out are refused by name (they
 * crashed inside Embree: squared distances overflowed and rays became invalid); the same quad alone at 2e13 m
 * from the world origin loads (its local frame is centred on it), and so do a quad 1,000 km wide 1e11 m beside
 * another and a light 1e11 m out. */
static void test_error_beyond_reach(void **state)
{
    (void)state;
    expect_error("reach_geometry.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"},"
                 " {\"file\": \"quad.obj\", \"transform\": {\"scale\": 1e12, \"translate\": [2e13, 0, 0]}}]}",
                 SCENE_ERR_RANGE, "geometry spans", "1e+12");
    expect_error("reach_light.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}],"
                 " \"lights\": [{\"type\": \"point\", \"position\": [0, -3e12, 0], \"intensity\": 1}]}",
                 SCENE_ERR_RANGE, "lights[0] (point)", "directional");
    expect_error("reach_camera.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}],"
                 " \"camera\": {\"position\": [0, 0, 5e13], \"target\": [0, 0, 0]}}",
                 SCENE_ERR_RANGE, "camera lies", "1e+13");
    const char *fine[] = {
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"transform\": {\"translate\": [2e13, 0, "
        "-2e13]}}],"
        " \"camera\": {\"position\": [2e13, 0, -1.99e13], \"target\": [2e13, 0, -2e13]}}",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"},"
        " {\"file\": \"quad.obj\", \"transform\": {\"scale\": 1e6, \"translate\": [1e11, 0, 0]}}],"
        " \"lights\": [{\"type\": \"point\", \"position\": [0, 1e11, 0], \"intensity\": 1e22}]}",
    };
    for (size_t i = 0; i < sizeof fine / sizeof fine[0]; i++) {
        scene_error err;
        scene *sc = load_json_text("reach_fine.json", fine[i], &err);
        if (!sc)
            fail_msg("description %zu: %s", i, err.msg);
        scene_free(sc);
    }
}

/* Triangles that have an area but collapse when rounded to float far from the local origin are named as
 * such: a mesh of nothing else is refused saying so, a scene that keeps other triangles loads with the count
 * and a precision warning (before, both read as plain "degenerate"). */
static void test_precision_collapse_named(void **state)
{
    (void)state;
    fxt_write_file("unit_tri.obj", "o t\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    expect_error("collapse.json",
                 "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"transform\": {\"scale\": 1000}},"
                 " {\"file\": \"unit_tri.obj\", \"transform\": {\"translate\": [1e9, 0, 0]}}]}",
                 SCENE_ERR_EMPTY, "unit_tri.obj", "collapse at float precision");
    /* One triangle of 1e5 m and one of 1 m, 1e9 m out: floats are 64 m apart there. */
    fxt_write_file("mixed_tri.obj", "o m\nv 0 0 0\nv 100000 0 0\nv 0 0 100000\nv 5 0 5\nv 6 0 5\nv 5 0 6\n"
                                    "f 1 3 2\nf 4 6 5\n");
    scene_error err;
    scene *sc =
        load_json_text("mixed.json",
                       "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"},"
                       " {\"file\": \"mixed_tri.obj\", \"transform\": {\"translate\": [1e9, 0, 0]}}]}",
                       &err);
    if (!sc)
        fail_msg("%s", err.msg);
    assert_int_equal(sc->repairs.precision_skipped, 1);
    assert_true(sc->repairs.degenerate_skipped >= 1);
    assert_true(sc->repairs.precision_reach > 4e8 && sc->repairs.precision_reach < 1.1e9);
    assert_non_null(strstr(sc->precision_warning, "collapse at float precision"));
    scene_free(sc);
}

/* A face index past the vertex list: Assimp's OBJ reader refuses the file. */
static void test_error_obj_index_out_of_range(void **state)
{
    (void)state;
    fxt_write_file("oor.obj", "o oor\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n");
    expect_error("oor.json", "{\"version\": 1, \"meshes\": [{\"file\": \"oor.obj\"}]}", SCENE_ERR_FORMAT,
                 "oor.obj", "out of range");
}

/* A mesh file whose every triangle is degenerate has no usable triangle. */
static void test_error_obj_only_degenerate(void **state)
{
    (void)state;
    fxt_write_file("flat.obj", "o flat\nv 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
    expect_error("flat.json", "{\"version\": 1, \"meshes\": [{\"file\": \"flat.obj\"}]}", SCENE_ERR_EMPTY,
                 "meshes[0]", "flat.obj");
}

/* A texture that cannot be read. */
static void test_error_missing_texture(void **state)
{
    (void)state;
    expect_error(
        "texture.json",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"material\": {\"texture\": \"nope.png\"}}]}",
        SCENE_ERR_IO, "meshes[0]", "nope.png");
}

/* A texture whose header declares more than the machine's memory (a 69-byte PNG of 65536 x 65536 RGBA
 * pixels: 64 GiB as floats) is refused with the figures before anything is allocated; it said
 * "std::bad_alloc", or tried the allocation (a sanitizer build aborts on it). Skipped on a machine with the
 * memory. */
static void test_error_texture_beyond_memory(void **state)
{
    (void)state;
    double memory = (double)sysconf(_SC_PHYS_PAGES) * (double)sysconf(_SC_PAGESIZE);
    if (memory >= 64.0 * (1u << 30)) {
        print_message("SKIP: this machine has %.0f GiB of memory\n", memory / (1u << 30));
        skip();
    }
    static const unsigned char png[69] =
        "\x89\x50\x4e\x47\x0d\x0a\x1a\x0a\x00\x00\x00\x0d\x49\x48\x44\x52\x00\x01\x00\x00\x00\x01\x00\x00"
        "\x08\x06\x00\x00\x00\x6c\x84\x30\xe3\x00\x00\x00\x0c\x49\x44\x41\x54\x78\x9c\x63\x60\xa0\x0c\x00"
        "\x00\x00\x40\x00\x01\xb7\x34\x7c\xef\x00\x00\x00\x00\x49\x45\x4e\x44\xae\x42\x60\x82";
    FILE *f = fopen(fxt_tmp_path("vast.png"), "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(png, 1, sizeof png, f), sizeof png);
    fclose(f);
    expect_error(
        "vast_texture.json",
        "{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\", \"material\": {\"texture\": \"vast.png\"}}]}",
        SCENE_ERR_IO, "65536 x 65536 pixels of 4 channels need 64 GiB as floats", "of memory");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_valid_full_description),
        cmocka_unit_test(test_error_beyond_reach),
        cmocka_unit_test(test_precision_collapse_named),
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
        cmocka_unit_test(test_error_syntax_line_column),
        cmocka_unit_test(test_error_duplicate_key),
        cmocka_unit_test(test_error_number_overflow),
        cmocka_unit_test(test_error_top_level_not_object),
        cmocka_unit_test(test_error_missing_json_file),
        cmocka_unit_test(test_error_unknown_top_field),
        cmocka_unit_test(test_error_unknown_field_with_newline),
        cmocka_unit_test(test_error_unknown_light_field),
        cmocka_unit_test(test_error_unknown_transform_field),
        cmocka_unit_test(test_error_wrong_type_intensity),
        cmocka_unit_test(test_error_wrong_length_color),
        cmocka_unit_test(test_error_meshes_not_array),
        cmocka_unit_test(test_error_missing_version),
        cmocka_unit_test(test_error_missing_meshes),
        cmocka_unit_test(test_error_missing_file),
        cmocka_unit_test(test_error_missing_light_fields),
        cmocka_unit_test(test_error_point_light_with_direction),
        cmocka_unit_test(test_error_unknown_light_type),
        cmocka_unit_test(test_error_newer_version),
        cmocka_unit_test(test_error_version_not_integer),
        cmocka_unit_test(test_error_negative_intensity),
        cmocka_unit_test(test_error_float_overflow),
        cmocka_unit_test(test_error_light_product_overflow),
        cmocka_unit_test(test_error_zero_direction),
        cmocka_unit_test(test_error_negative_sky_color),
        cmocka_unit_test(test_error_density_range),
        cmocka_unit_test(test_density_range_ends),
        cmocka_unit_test(test_byte_order_mark),
        cmocka_unit_test(test_error_scene_too_small),
        cmocka_unit_test(test_error_density_word),
        cmocka_unit_test(test_error_bad_override),
        cmocka_unit_test(test_error_camera_fov),
        cmocka_unit_test(test_error_bad_transforms),
        cmocka_unit_test(test_error_albedo_above_one),
        cmocka_unit_test(test_error_unknown_builtin),
        cmocka_unit_test(test_error_empty_meshes),
        cmocka_unit_test(test_error_missing_mesh_file),
        cmocka_unit_test(test_error_unsupported_format),
        cmocka_unit_test(test_error_obj_nan),
        cmocka_unit_test(test_error_obj_inf),
        cmocka_unit_test(test_error_obj_float_overflow),
        cmocka_unit_test(test_error_transform_overflow),
        cmocka_unit_test(test_error_obj_index_out_of_range),
        cmocka_unit_test(test_error_obj_only_degenerate),
        cmocka_unit_test(test_error_missing_texture),
        cmocka_unit_test(test_error_texture_beyond_memory),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
