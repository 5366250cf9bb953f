/* Tests of JSON scene descriptions (scene/scene_json.c) that must be refused: malformed JSON, wrong structure,
 * values out of range, mesh files with bad coordinates. Each asserts the result code and that the one-line
 * message names what is wrong and where (line:column for malformed JSON, the JSON path and field for content
 * errors, the mesh and vertex for bad coordinates in a mesh file). The valid descriptions are in
 * test_scene_json.c. */
#include "test_util.h"

#include "fxt_scene.h"
#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Loads text (expected to fail) and asserts the code and that the message holds every given fragment. */
static void expect_error(const char *name, const char *text, scene_result code, const char *fragment1,
                         const char *fragment2)
{
    scene_error err;
    scene *s = fxt_load_json_text(name, text, &err);
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
        fxt_load_json_text("product_fits.json",
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
        scene *s = fxt_load_json_text("density_end.json", texts[i], &err);
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
    scene *s = fxt_load_json_text("small.json",
                                  "{\"version\": 1, \"meshes\": [{\"builtin\": \"default\", \"transform\": "
                                  "{\"scale\": 1e-7}}]}",
                                  &err);
    if (!s)
        fail_msg("a scene 1e-6 m across is refused: %s", err.msg);
    scene_free(s);
}

/* Transforms that collapse every triangle: a translate of 1e38 m (even doubles are 1.7e22 m apart there) and
 * a scale of [1e20, 1e-20, 1] (slivers 1e21 m long). Both said only "no triangles (1246 degenerate
 * skipped)", as if the file were empty; the message now names the cause. */
static void test_error_transform_collapses_everything(void **state)
{
    (void)state;
    expect_error("far_away.json",
                 "{\"version\": 1, \"meshes\": [{\"builtin\": \"default\", \"transform\": {\"translate\": "
                 "[1e38, 1e38, -1e38]}}]}",
                 SCENE_ERR_EMPTY, "no triangles", "where even doubles are");
    expect_error("stretched.json",
                 "{\"version\": 1, \"meshes\": [{\"builtin\": \"default\", \"transform\": {\"scale\": "
                 "[1e20, 1e-20, 1]}}]}",
                 SCENE_ERR_EMPTY, "no triangles", "the meshes span");
}

/* A UTF-8 byte-order mark before the JSON is skipped (it was refused: "'[' or '{' expected"); one anywhere
 * else is still malformed JSON. */
static void test_byte_order_mark(void **state)
{
    (void)state;
    scene_error err;
    scene *s = fxt_load_json_text(
        "bom.json", "\xef\xbb\xbf{\"version\": 1, \"meshes\": [{\"file\": \"quad.obj\"}]}", &err);
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
    scene *s =
        fxt_load_json_text("nan.json", "{\"version\": 1, \"meshes\": [{\"file\": \"nan.obj\"}]}", &err);
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
        scene *sc = fxt_load_json_text("reach_fine.json", fine[i], &err);
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
        fxt_load_json_text("mixed.json",
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
        cmocka_unit_test(test_error_beyond_reach),
        cmocka_unit_test(test_precision_collapse_named),
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
        cmocka_unit_test(test_error_transform_collapses_everything),
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
