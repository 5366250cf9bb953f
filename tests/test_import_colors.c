/* Vertex colours as mesh files carry them (scene/scene_import.c, scene_material.c): glTF's COLOR_0 multiplies
 * the base colour (linear, by glTF's specification), a PLY scan's byte colours are sRGB-encoded albedos. Each
 * expectation is a closed form of the file written here: the colours are an affine function of position, so
 * the interpolation over either triangle of the quad is that function at the hit point. Emission as files
 * give it (an emissive texture) and as a program changes it (the frame loop sees it as a change of light). */
#include "test_util.h"

#include "fxt_scene.h"

#include "camera.h"
#include "engine.h"
#include "engine_internal.h" /* white-box: the loop's record of light changes */
#include "image.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* The colour the quad's corners carry: affine in (x, y), so its interpolation is itself. */
static void affine_color(double x, double y, double out[3])
{
    out[0] = 0.2 + 0.3 * x;
    out[1] = 0.9 - 0.4 * y;
    out[2] = 0.5 + 0.2 * x + 0.1 * y;
}

static const double base_color[3] = {0.5, 0.8, 1.0};

/* A unit quad in the xy plane (z = 0) facing +z, corners (0, 0), (1, 0), (1, 1), (0, 1), with COLOR_0 from
 * affine_color and baseColorFactor base_color; textured (the 2 x 1 red | green texture, u = x, v = y) when
 * `textured`; `emissive` (JSON text or NULL) is added to the material. Returns the .gltf path. */
static const char *write_quad_emissive(const char *name, bool textured, const char *emissive)
{
    const uint8_t texels[6] = {255, 0, 0, 0, 255, 0};
    char msg[256];
    assert_int_equal(scene_image_write_u8(fxt_tmp_path("vc_red_green.png"), 2, 1, 3, texels, msg, sizeof msg),
                     0);
    const float positions[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
    float colors[4][3], uv[4][2];
    for (int c = 0; c < 4; c++) {
        double rgb[3];
        affine_color(positions[c][0], positions[c][1], rgb);
        for (int k = 0; k < 3; k++)
            colors[c][k] = (float)rgb[k];
        uv[c][0] = positions[c][0];
        uv[c][1] = positions[c][1];
    }
    const uint16_t indices[6] = {0, 1, 2, 0, 2, 3};
    char bin_name[64];
    snprintf(bin_name, sizeof bin_name, "%s.bin", name);
    FILE *bin = fopen(fxt_tmp_path(bin_name), "wb");
    assert_non_null(bin);
    assert_int_equal(fwrite(positions, sizeof positions, 1, bin), 1);
    assert_int_equal(fwrite(colors, sizeof colors, 1, bin), 1);
    assert_int_equal(fwrite(uv, sizeof uv, 1, bin), 1);
    assert_int_equal(fwrite(indices, sizeof indices, 1, bin), 1);
    fclose(bin);
    static char text[4096];
    snprintf(
        text, sizeof text,
        "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"COLOR_0\":1%s},"
        "\"indices\":3,\"material\":0}]}],"
        "\"materials\":[{%s\"pbrMetallicRoughness\":{\"baseColorFactor\":[%g,%g,%g,1],%s"
        "\"metallicFactor\":0}}],"
        "%s"
        "\"buffers\":[{\"byteLength\":140,\"uri\":\"%s\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":48},"
        "{\"buffer\":0,\"byteOffset\":48,\"byteLength\":48},{\"buffer\":0,\"byteOffset\":96,"
        "\"byteLength\":32},{\"buffer\":0,\"byteOffset\":128,\"byteLength\":12}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\","
        "\"min\":[0,0,0],\"max\":[1,1,0]},{\"bufferView\":1,\"componentType\":5126,\"count\":4,"
        "\"type\":\"VEC3\"},{\"bufferView\":2,\"componentType\":5126,\"count\":4,\"type\":\"VEC2\"},"
        "{\"bufferView\":3,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]}",
        textured || emissive ? ",\"TEXCOORD_0\":2" : "", emissive ? emissive : "", base_color[0],
        base_color[1], base_color[2], textured ? "\"baseColorTexture\":{\"index\":0}," : "",
        textured || emissive ? "\"textures\":[{\"source\":0}],\"images\":[{\"uri\":\"vc_red_green.png\"}],"
                             : "",
        bin_name);
    return fxt_write_file(name, text);
}

static const char *write_colored_quad(const char *name, bool textured)
{
    return write_quad_emissive(name, textured, NULL);
}

/* The hit point (local frame) of triangle t at barycentrics (u, v) of corners 1 and 2. */
static void point_at(const scene *s, uint32_t t, float u, float v, double out[3])
{
    const float *p0 = s->positions + 3 * (size_t)s->indices[3 * (size_t)t];
    const float *p1 = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 1];
    const float *p2 = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 2];
    for (int k = 0; k < 3; k++)
        out[k] = (1.0 - u - v) * p0[k] + u * (double)p1[k] + v * (double)p2[k] + s->origin[k];
}

/* scene_albedo at several barycentrics of both triangles is base colour x affine_color at the point, and the
 * triangle mean (the probes' albedo) is it at the centroid. */
static void test_gltf_color_multiplies_base(void **state)
{
    (void)state;
    scene *s = fxt_load_ok(write_colored_quad("vc.gltf", false));
    assert_non_null(s->corner_color);
    assert_int_equal(s->triangle_count, 2);
    const float bary[5][2] = {{0, 0}, {1, 0}, {0, 1}, {0.2f, 0.7f}, {0.55f, 0.15f}};
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        for (int i = 0; i < 5; i++) {
            double p[3], c[3];
            point_at(s, t, bary[i][0], bary[i][1], p);
            affine_color(p[0], p[1], c);
            float rgb[3];
            scene_albedo(s, t, bary[i][0], bary[i][1], rgb);
            for (int k = 0; k < 3; k++)
                if (!(fabs(rgb[k] - base_color[k] * c[k]) < 1e-5))
                    fail_msg("triangle %u at (%g, %g) channel %d: %.6f, expected %.6f", t, (double)bary[i][0],
                             (double)bary[i][1], k, (double)rgb[k], base_color[k] * c[k]);
        }
        double p[3], c[3];
        point_at(s, t, 1.0f / 3, 1.0f / 3, p);
        affine_color(p[0], p[1], c);
        float mean[3];
        scene_albedo_mean(s, t, mean);
        for (int k = 0; k < 3; k++)
            assert_true(fabs(mean[k] - base_color[k] * c[k]) < 1e-5);
    }
    scene_free(s);
}

/* Compose's pixels (the engine's radiance, no effects, one sun straight onto the quad, no sky): albedo x E,
 * where the albedo is base colour x affine_color at the point the pixel's ray hits (found here with
 * srv_camera_ray and one closest-hit query). */
static void test_compose_pixels_interpolate(void **state)
{
    (void)state;
    write_colored_quad("vc_compose.gltf", false);
    scene_error err = {0};
    scene *s = fxt_load_json_text(
        "vc_compose.json",
        "{\"version\":1,\"meshes\":[{\"file\":\"vc_compose.gltf\"}],"
        "\"lights\":[{\"type\":\"directional\",\"direction\":[0,0,-1],\"color\":[1,1,1],\"intensity\":2}],"
        "\"effects\":{\"shadows\":\"off\",\"ao\":\"off\",\"indirect\":\"off\"}}",
        &err);
    if (!s)
        fail_msg("%s", err.msg);
    assert_non_null(s->corner_color);
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    assert_non_null(rt);
    enum { W = 32, H = 32 };
    srv_camera cam = {.position = {0.5f, 0.5f, 1.5f}, .target = {0.5f, 0.5f, 0}, .fov_deg = 40};
    for (int k = 0; k < 3; k++) {
        cam.position[k] -= (float)s->origin[k];
        cam.target[k] -= (float)s->origin[k];
    }
    srv_loop_desc d = {.s = s, .rt = rt, .seed = 1, .no_cache = 1};
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, W, H, &id);
    srv_frame_stats st;
    fxt_frame(loop, &id, 1, &cam, &st);
    const float *radiance = srv_viewer_radiance(loop, id);
    srv_camera_frame f;
    assert_true(srv_camera_setup(&cam, W, H, &f));
    uint32_t checked = 0;
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            float dir[3], u, v, t;
            uint32_t tri;
            srv_camera_ray(&f, (float)x + 0.5f, (float)y + 0.5f, dir);
            if (!scene_rt_intersect1(rt, cam.position, dir, INFINITY, &tri, &u, &v, &t))
                continue;
            double p[3], c[3];
            for (int k = 0; k < 3; k++)
                p[k] = cam.position[k] + (double)t * dir[k] + s->origin[k];
            affine_color(p[0], p[1], c);
            const float *px = radiance + 3 * ((size_t)y * W + x);
            for (int k = 0; k < 3; k++)
                if (!(fabs(px[k] - 2.0 * base_color[k] * c[k]) < 1e-4))
                    fail_msg("pixel (%u, %u) channel %d: %.6f, expected 2 x %.4f x %.4f = %.6f", x, y, k,
                             (double)px[k], base_color[k], c[k], 2.0 * base_color[k] * c[k]);
            checked++;
        }
    assert_true(checked > W * H / 2);
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
}

/* A textured quad with colours: scene_albedo_run over runs of hits on one triangle (long enough for its lanes)
 * gives what scene_albedo_filtered gives per hit, which is texture x base colour x colour (the texel read
 * through the same function without colours times affine_color). */
static void test_textured_run_matches_single(void **state)
{
    (void)state;
    scene *s = fxt_load_ok(write_colored_quad("vc_tex.gltf", true));
    assert_non_null(s->corner_color);
    assert_int_equal(s->texture_count, 1);
    enum { N = 40 };
    uint32_t tri[N];
    float u[N], v[N], footprint[N], run[N][3];
    for (int i = 0; i < N; i++) {
        tri[i] = i < 25 ? 0 : 1; /* a stretch of 25 (lanes) then 15 */
        u[i] = 0.05f + 0.02f * (float)(i % 20);
        v[i] = 0.5f - 0.015f * (float)(i % 20);
        footprint[i] = -6.0f + 0.1f * (float)(i % 7);
    }
    scene_albedo_run(s, tri, u, v, footprint, N, run);
    float *saved = s->corner_color;
    for (int i = 0; i < N; i++) {
        float one[3], plain[3];
        scene_albedo_filtered(s, tri[i], u[i], v[i], footprint[i], one);
        assert_memory_equal(one, run[i], sizeof one);
        s->corner_color = NULL; /* the same hit without colours */
        scene_albedo_filtered(s, tri[i], u[i], v[i], footprint[i], plain);
        s->corner_color = saved;
        double p[3], c[3];
        point_at(s, tri[i], u[i], v[i], p);
        affine_color(p[0], p[1], c);
        for (int k = 0; k < 3; k++)
            assert_true(fabs(one[k] - plain[k] * c[k]) < 1e-5);
    }
    scene_free(s);
}

/* An ASCII PLY triangle with byte colours: sRGB-decoded at the corners (128 -> 0.2158605), times the
 * material Assimp gives; an OBJ without colours in the same scene gets none (white), and a scene of it alone
 * holds no colour table at all. */
static void test_ply_colors_srgb(void **state)
{
    (void)state;
    fxt_write_file("vc.ply",
                   "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                   "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                   "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                   "0 0 0 255 128 0\n1 0 0 0 255 128\n0 1 0 128 0 255\n3 0 1 2\n");
    const char *quad = fxt_write_quad();
    scene *alone = fxt_load_ok(quad);
    assert_null(alone->corner_color);
    scene_free(alone);
    static char out[8192], cli_err[8192], path[1024]; /* scene-info says which has them */
    snprintf(path, sizeof path, "%s", quad);          /* fxt_run_clif reuses the scratch path's buffer */
    assert_int_equal(fxt_run_clif(out, sizeof out, cli_err, sizeof cli_err, "scene-info '%s'", path), 0);
    assert_null(strstr(out, "vertex colours"));
    snprintf(path, sizeof path, "%s", fxt_tmp_path("vc.ply"));
    assert_int_equal(fxt_run_clif(out, sizeof out, cli_err, sizeof cli_err, "scene-info '%s'", path), 0);
    assert_non_null(strstr(out, "textures 0, vertex colours)"));
    scene_error err = {0};
    scene *s = fxt_load_json_text(
        "vc_ply.json", "{\"version\":1,\"meshes\":[{\"file\":\"vc.ply\"},{\"file\":\"quad.obj\"}]}", &err);
    if (!s)
        fail_msg("%s", err.msg);
    assert_non_null(s->corner_color);
    const double half = 0.21586050011389923;                                  /* sRGB 128/255 decoded */
    const double expected[3][3] = {{1, half, 0}, {0, 1, half}, {half, 0, 1}}; /* by vertex, as in the file */
    uint32_t ply_triangles = 0;
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        const scene_material *m = &s->materials[s->meshes[s->tri_mesh[t]].material];
        bool from_ply = strstr(s->meshes[s->tri_mesh[t]].name, "quad") == NULL;
        for (int corner = 0; corner < 3; corner++) {
            float rgb[3];
            scene_albedo(s, t, corner == 1 ? 1.0f : 0.0f, corner == 2 ? 1.0f : 0.0f, rgb);
            const float *p = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + corner];
            int vertex = p[0] > 0.5f ? 1 : (p[1] > 0.5f ? 2 : 0);
            for (int k = 0; k < 3; k++) {
                double want = m->diffuse[k] * (from_ply ? expected[vertex][k] : 1.0);
                if (!(fabs(rgb[k] - want) < 1e-5))
                    fail_msg("%s triangle %u corner %d channel %d: %.6f, expected %.6f",
                             from_ply ? "PLY" : "OBJ", t, corner, k, (double)rgb[k], want);
            }
        }
        ply_triangles += from_ply;
    }
    assert_int_equal(ply_triangles, 1);
    scene_free(s);
}

/* glTF's emissive texture times emissiveFactor [2, 2, 2]: the red | green texture's mean (0.5, 0.5, 0) makes
 * the material's uniform emission (1, 1, 0), the texture is not kept for it, and kept when it is also the
 * base colour's; without the texture the factor alone (2, 2, 2). Before, the texture was not read: (2, 2, 2)
 * in each case. */
static void test_emissive_texture_mean(void **state)
{
    (void)state;
    const char *emissive = "\"emissiveFactor\":[2,2,2],\"emissiveTexture\":{\"index\":0},";
    const float want[3] = {1, 1, 0};
    for (int textured = 0; textured < 2; textured++) {
        scene *s = fxt_load_ok(write_quad_emissive("emissive.gltf", textured, emissive));
        assert_int_equal(s->texture_count, (uint32_t)textured);
        const scene_material *m = &s->materials[s->meshes[0].material];
        for (int k = 0; k < 3; k++)
            if (!(fabsf(m->emission[k] - want[k]) < 1e-6f))
                fail_msg("textured %d: emission %g %g %g", textured, (double)m->emission[0],
                         (double)m->emission[1], (double)m->emission[2]);
        assert_true(s->emissive);
        scene_free(s);
    }
    scene *s = fxt_load_ok(write_quad_emissive("emissive_plain.gltf", false, "\"emissiveFactor\":[2,2,2],"));
    const scene_material *m = &s->materials[s->meshes[0].material];
    assert_true(m->emission[0] == 2 && m->emission[1] == 2 && m->emission[2] == 2);
    scene_free(s);
}

/* A change of a material's emission between frames is a change of light (srv_loop_frame's light signature):
 * the loop marks it, so converged probes refresh at once, as for a light dimmed. Before, emission was not in
 * the signature: the probes kept the lamp's old light until their slow refresh. */
static void test_emission_change_is_light_change(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    s->materials[0].emission[0] = s->materials[0].emission[1] = s->materials[0].emission[2] = 1.0f;
    fxt_add_quad(s, "lamp", (double[3]){-1, -1, 0}, (double[3]){2, 0, 0}, (double[3]){0, 2, 0}, 4);
    fxt_add_quad(s, "floor", (double[3]){-3, -2, 3}, (double[3]){6, 0, 0}, (double[3]){0, 0, -6}, 4);
    scene_rt *rt = fxt_finish_scene(s, 8.0f, 1.0f);
    assert_true(s->emissive);
    srv_camera cam = {.position = {0, 0, 4}, .target = {0, 0, 0}, .fov_deg = 60};
    srv_loop_desc d = {.s = s, .rt = rt, .seed = 3};
    fxt_effects_on(&d, (const char *const[]){"probes"}, 1);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, 32, 16, &id);
    srv_frame_stats st;
    fxt_frame(loop, &id, 1, &cam, &st);
    fxt_frame(loop, &id, 1, &cam, &st);
    assert_false(loop->light_changed);   /* nothing changed since the loop was made */
    s->materials[0].emission[1] = 0.25f; /* dimmed */
    scene_emission_refresh(s);
    uint32_t frame = loop->frame_number;
    fxt_frame(loop, &id, 1, &cam, &st);
    assert_true(loop->light_changed);
    assert_int_equal(loop->light_change_frame, frame);
    memset(s->materials[0].emission, 0, sizeof s->materials[0].emission); /* switched off */
    scene_emission_refresh(s);
    assert_false(s->emissive);
    frame = loop->frame_number;
    fxt_frame(loop, &id, 1, &cam, &st);
    assert_int_equal(loop->light_change_frame, frame);
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
}

/* The weight of the texel centred at 0.75 (against the one at 0.25) in a bilinear, repeated lookup of a
 * 2-texel side at coordinate fraction f. */
static double right_weight(double f)
{
    double d = fabs(f - 0.75);
    return 1.0 - 2.0 * fmin(d, 1.0 - d);
}

/* glTF's KHR_texture_transform (offset [0.3, -0.2], rotation 0.4, scale [1.7, 0.6]) on a unit quad whose
 * texture coordinates are its (x, y), reading a 2 x 2 texture (top row red, green; bottom row blue, black):
 * at every point the texel weights of uv' = offset + R (scale x uv), R = [cos sin; -sin cos] (the rotation
 * Khronos's TextureTransformTest asset shows as right), glTF's v pointing down the image. Before, the
 * transform was not applied. */
static void test_gltf_texture_transform(void **state)
{
    (void)state;
    const uint8_t texels[12] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 0, 0, 0};
    char msg[256];
    assert_int_equal(scene_image_write_u8(fxt_tmp_path("kt_2x2.png"), 2, 2, 3, texels, msg, sizeof msg), 0);
    const float positions[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
    const float uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    const uint16_t indices[6] = {0, 1, 2, 0, 2, 3};
    FILE *bin = fopen(fxt_tmp_path("kt.bin"), "wb");
    assert_non_null(bin);
    assert_int_equal(fwrite(positions, sizeof positions, 1, bin), 1);
    assert_int_equal(fwrite(uv, sizeof uv, 1, bin), 1);
    assert_int_equal(fwrite(indices, sizeof indices, 1, bin), 1);
    fclose(bin);
    const double offset[2] = {0.3, -0.2}, rotation = 0.4, scale[2] = {1.7, 0.6};
    static char text[4096];
    snprintf(text, sizeof text,
             "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_texture_transform\"],\"scene\":0,"
             "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],\"meshes\":[{\"primitives\":[{"
             "\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1},\"indices\":2,\"material\":0}]}],"
             "\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorTexture\":{\"index\":0,\"extensions\":{"
             "\"KHR_texture_transform\":{\"offset\":[%g,%g],\"rotation\":%g,\"scale\":[%g,%g]}}},"
             "\"metallicFactor\":0}}],\"textures\":[{\"source\":0}],\"images\":[{\"uri\":\"kt_2x2.png\"}],"
             "\"buffers\":[{\"byteLength\":92,\"uri\":\"kt.bin\"}],"
             "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":48},{\"buffer\":0,"
             "\"byteOffset\":48,\"byteLength\":32},{\"buffer\":0,\"byteOffset\":80,\"byteLength\":12}],"
             "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\","
             "\"min\":[0,0,0],\"max\":[1,1,0]},{\"bufferView\":1,\"componentType\":5126,\"count\":4,"
             "\"type\":\"VEC2\"},{\"bufferView\":2,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]}",
             offset[0], offset[1], rotation, scale[0], scale[1]);
    scene *s = fxt_load_ok(fxt_write_file("kt.gltf", text));
    assert_int_equal(s->texture_count, 1);
    const float bary[5][2] = {{0.1f, 0.1f}, {0.6f, 0.3f}, {0.2f, 0.7f}, {0.33f, 0.33f}, {0.05f, 0.8f}};
    double c = cos(rotation), sn = sin(rotation);
    for (uint32_t t = 0; t < s->triangle_count; t++)
        for (int i = 0; i < 5; i++) {
            double p[3];
            point_at(s, t, bary[i][0], bary[i][1], p);
            double u = offset[0] + c * scale[0] * p[0] + sn * scale[1] * p[1];
            double v_down = offset[1] - sn * scale[0] * p[0] + c * scale[1] * p[1];
            double v = 1.0 - v_down; /* up the image, as fxcache reads */
            double gu = right_weight(u - floor(u)), gv = right_weight(v - floor(v)); /* gv: the top row's */
            const double want[3] = {gv * (1 - gu), gv * gu, (1 - gv) * (1 - gu)};
            float rgb[3];
            scene_albedo(s, t, bary[i][0], bary[i][1], rgb);
            for (int k = 0; k < 3; k++)
                if (!(fabs(rgb[k] - want[k]) < 1e-4))
                    fail_msg("point (%.3f, %.3f) uv' (%.4f, %.4f): (%g, %g, %g), expected (%g, %g, %g)", p[0],
                             p[1], u, v, (double)rgb[0], (double)rgb[1], (double)rgb[2], want[0], want[1],
                             want[2]);
        }
    scene_free(s);
}

/* A texture named by a path from the author's machine ("D:\\work\\proj\\tex\\red.png" in an OBJ's MTL) is found
 * as its last folder and file name beside the model's folder (proj/model/quad.obj reads proj/tex/red.png),
 * as Assimp's FBX spider names ..\\OBJ\\ textures; before, it was missing and the material kept its colour. */
static void test_texture_from_another_machine(void **state)
{
    (void)state;
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("proj"));
    mkdir(dir, 0755);
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("proj/model"));
    mkdir(dir, 0755);
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("proj/tex"));
    mkdir(dir, 0755);
    const uint8_t red[3] = {255, 0, 0};
    char msg[256];
    assert_int_equal(scene_image_write_u8(fxt_tmp_path("proj/tex/red.png"), 1, 1, 3, red, msg, sizeof msg),
                     0);
    fxt_write_file("proj/model/quad.mtl", "newmtl m\nKd 1 1 1\nmap_Kd D:\\work\\proj\\tex\\red.png\n");
    const char *path =
        fxt_write_file("proj/model/quad.obj", "mtllib quad.mtl\nv 0 0 0\nv 1 0 0\nv 1 0 -1\nv 0 0 -1\n"
                                              "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl m\n"
                                              "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n");
    scene *s = fxt_load_ok(path);
    assert_int_equal(s->repairs.textures_missing, 0);
    assert_int_equal(s->texture_count, 1);
    float rgb[3];
    scene_albedo(s, 0, 0.3f, 0.3f, rgb);
    assert_true(rgb[0] == 1.0f && rgb[1] == 0.0f && rgb[2] == 0.0f);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_gltf_color_multiplies_base),
        cmocka_unit_test(test_compose_pixels_interpolate),
        cmocka_unit_test(test_textured_run_matches_single),
        cmocka_unit_test(test_ply_colors_srgb),
        cmocka_unit_test(test_emissive_texture_mean),
        cmocka_unit_test(test_gltf_texture_transform),
        cmocka_unit_test(test_texture_from_another_machine),
        cmocka_unit_test(test_emission_change_is_light_change),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
