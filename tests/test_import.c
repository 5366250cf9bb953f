/* Mesh-file import through Assimp (scene/scene_import.c) and the builder's cleaning: glTF 2 with an embedded
 * buffer, ASCII PLY, OBJ with a material and a texture (found case-insensitively), gzip-compressed files,
 * 3DS (Debian's glmark2 horse), points and lines dropped and counted, a missing texture counted, welding,
 * degenerate and duplicate triangles skipped, mirrored transforms keeping the winding. */
#include "test_util.h"

#include "fxt_scene.h"

#include "image.h"
#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

/* Where Debian's assimp-testmodels puts Assimp's own test models. */
#define ASSIMP_MODELS "/usr/share/assimp/models"

/* splitmix64: the mutation test's deterministic random numbers. */
static uint64_t splitmix(uint64_t *state)
{
    uint64_t z = (*state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

/* A glTF 2 file with one triangle in a base64 data-URI buffer. */
static void test_gltf(void **state)
{
    (void)state;
    const char *path = fxt_write_file(
        "tri.gltf",
        "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"name\":\"tri\",\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1}]}],"
        "\"buffers\":[{\"byteLength\":44,\"uri\":\"data:application/octet-stream;base64,"
        "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA=\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":36},"
        "{\"buffer\":0,\"byteOffset\":36,\"byteLength\":6}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\","
        "\"min\":[0,0,0],\"max\":[1,1,0]},{\"bufferView\":1,\"componentType\":5123,\"count\":3,\"type\":"
        "\"SCALAR\"}]}");
    scene *s = fxt_load_ok(path);
    assert_int_equal(s->triangle_count, 1);
    assert_int_equal(s->island_count, 1);
    assert_true(fabsf(s->tri_normal[2] - 1.0f) < 1e-6f); /* counter-clockwise seen from +z */
    assert_int_equal(s->light_count, 1);                 /* a plain mesh file gets a sun and a sky */
    assert_true(s->sky_intensity > 0);
    scene_free(s);
}

/* ASCII PLY, and the same file gzip-compressed: identical scenes. */
static void test_ply_and_gz(void **state)
{
    (void)state;
    const char *ply = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                      "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
                      "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";
    scene *plain = fxt_load_ok(fxt_write_file("quad.ply", ply));
    char gz_path[1024];
    snprintf(gz_path, sizeof gz_path, "%s", fxt_tmp_path("quad.ply.gz"));
    gzFile gz = gzopen(gz_path, "wb");
    assert_non_null(gz);
    assert_int_equal(gzputs(gz, ply), (int)strlen(ply));
    gzclose(gz);
    scene *packed = fxt_load_ok(gz_path);
    assert_int_equal(plain->triangle_count, 2);
    assert_int_equal(packed->triangle_count, 2);
    assert_int_equal(plain->vertex_count, 4);
    assert_memory_equal(plain->positions, packed->positions, sizeof(float) * 3 * 4);
    assert_int_equal(plain->island_count, 1); /* two coplanar triangles sharing an edge: one island */
    scene_free(plain);
    scene_free(packed);
}

/* A gzip file that is not gzip inside, and one that decompresses to junk: one-line errors, no scene. */
static void test_bad_gz(void **state)
{
    (void)state;
    scene_error err = {0};
    assert_null(scene_load(fxt_write_file("junk.obj.gz", "this is not gzip"), NULL, &err));
    assert_int_not_equal(err.code, SCENE_OK);
    assert_null(strchr(err.msg, '\n'));
    assert_non_null(strstr(err.msg, "junk.obj.gz"));
}

/* OBJ with a material whose texture file is named in another case than on disk; points and lines in the
 * file are dropped and counted. */
static void test_obj_texture_and_non_triangles(void **state)
{
    (void)state;
    /* A 2x2 texture written through the same shim the scene reads with. */
    const uint8_t texels[12] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255};
    char msg[256];
    assert_int_equal(scene_image_write_u8(fxt_tmp_path("checker.png"), 2, 2, 3, texels, msg, sizeof msg), 0);
    fxt_write_file("tex.mtl", "newmtl red\nKd 1 1 1\nmap_Kd CHECKER.PNG\n");
    const char *obj = fxt_write_file("tex.obj", "mtllib tex.mtl\nusemtl red\n"
                                                "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                                "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                                "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\nl 1 2\np 3\n");
    scene *s = fxt_load_ok(obj);
    assert_int_equal(s->triangle_count, 2);
    assert_int_equal(s->texture_count, 1);
    assert_int_equal(s->repairs.textures_missing, 0);
    assert_true(s->repairs.non_triangles_dropped >= 2);
    /* Texel (0, 0) at the image's bottom left is blue (row 1 of the file): u = v = 0.25. */
    float rgb[3];
    scene_albedo(s, 0, 0.2f, 0.05f, rgb); /* near uv (0.25, 0.05): the bottom row */
    assert_true(rgb[2] > rgb[0]);
    scene_free(s);
}

/* Texture mip levels: a 64 x 64 checker of single texels on a 1 m quad reads as its average (0.5) for a
 * pixel 1 m wide and as pure black or white for a pixel far smaller than a texel. */
static void test_texture_mip_levels(void **state)
{
    (void)state;
    uint8_t checker[64 * 64 * 3];
    for (int y = 0; y < 64; y++)
        for (int x = 0; x < 64; x++)
            memset(checker + 3 * (y * 64 + x), (x + y) & 1 ? 255 : 0, 3);
    char msg[256];
    assert_int_equal(scene_image_write_u8(fxt_tmp_path("checker64.png"), 64, 64, 3, checker, msg, sizeof msg),
                     0);
    fxt_write_file("mip.mtl", "newmtl c\nKd 1 1 1\nmap_Kd checker64.png\n");
    const char *obj =
        fxt_write_file("mip.obj", "mtllib mip.mtl\nusemtl c\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                  "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n");
    scene *s = fxt_load_ok(obj);
    assert_int_equal(s->texture_count, 1);
    assert_int_equal(s->textures[0].levels, 7);               /* 64, 32, ..., 1 */
    assert_true(fabsf(s->tri_texture_lod[0] - 6.0f) < 1e-4f); /* 64 texels per metre */
    float rgb[3];
    scene_albedo_filtered(s, 0, 0.3f, 0.2f, 0.0f, rgb); /* a 1 m pixel: the 1 x 1 level */
    assert_true(fabsf(rgb[0] - 0.5f) < 0.01f);
    scene_albedo_filtered(s, 0, 0.3f, 0.2f, -4.0f, rgb); /* 1/16 m: the 4 x 4 level, still the average */
    assert_true(fabsf(rgb[0] - 0.5f) < 0.01f);
    /* Far below a texel, at a texel centre: level 0, pure black or white. */
    float u = (10.5f / 64.0f) - (3.5f / 64.0f),
          v = 3.5f / 64.0f; /* texture uv (10.5, 3.5)/64 on triangle 0 */
    scene_albedo_filtered(s, 0, u, v, -12.0f, rgb);
    assert_true(rgb[0] < 0.01f || rgb[0] > 0.99f);
    scene_free(s);
}

/* A float texture (EXR) with texels 2, -1, 0.25 and NaN: albedo is a reflectance, so they load as 1, 0, 0.25 and
 * 0 (the reader's NaN rule), as a material colour is clamped; before, 2 was kept, and inside a closed room of
 * it the probes' indirect light grew without bound. */
static void test_float_texture_albedo_clamped(void **state)
{
    (void)state;
    const float texels[4 * 3] = {2, 2, 2, -1, -1, -1, 0.25f, 0.25f, 0.25f, NAN, 0.5f, 0.5f};
    char msg[256];
    assert_int_equal(scene_image_write_f32(fxt_tmp_path("hdr2x2.exr"), 2, 2, 3, texels, msg, sizeof msg), 0);
    fxt_write_file("hdr.mtl", "newmtl h\nKd 1 1 1\nmap_Kd hdr2x2.exr\n");
    const char *obj =
        fxt_write_file("hdr.obj", "mtllib hdr.mtl\nusemtl h\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                  "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n");
    scene *s = fxt_load_ok(obj);
    assert_int_equal(s->texture_count, 1);
    const float expected[4 * 3] = {1, 1, 1, 0, 0, 0, 0.25f, 0.25f, 0.25f, 0, 0.5f, 0.5f};
    for (int i = 0; i < 12; i++)
        assert_true(s->textures[0].rgb[i] == expected[i]);
    for (uint32_t l = 0; l < s->textures[0].levels; l++) /* every mip level within 0..1 */
        for (uint32_t i = 0; i < s->textures[0].mip_width[l] * s->textures[0].mip_height[l] * 3; i++)
            assert_true(s->textures[0].mip_rgb[l][i] >= 0 && s->textures[0].mip_rgb[l][i] <= 1);
    scene_free(s);
}

/* The albedo of a run of hits (scene_albedo_run: stretches of one triangle in lanes) equals each hit's
 * scene_albedo_filtered bit for bit: a 64 x 64 texture of random texels (7 mip levels) on a quad and an
 * untextured triangle, hits in stretches of 1 to 150 on one triangle (longer than a lanes call), footprints
 * from far below a texel to above the whole texture (levels changing inside a stretch), UVs inside, beyond
 * the texture (wrapped) and not finite. */
static void test_albedo_run_equals_filtered(void **state)
{
    (void)state;
    enum { SIDE = 64, HITS = 4096 };
    static uint8_t noise[SIDE * SIDE * 3];
    uint64_t rng = 777;
    for (int i = 0; i < SIDE * SIDE * 3; i++) {
        rng = rng * 6364136223846793005ull + 1442695040888963407ull;
        noise[i] = (uint8_t)(rng >> 56);
    }
    char msg[256];
    assert_int_equal(scene_image_write_u8(fxt_tmp_path("noise64.png"), SIDE, SIDE, 3, noise, msg, sizeof msg),
                     0);
    fxt_write_file("run.mtl", "newmtl t\nKd 0.9 0.7 0.5\nmap_Kd noise64.png\nnewmtl plain\nKd 0.3 0.6 0.2\n");
    const char *obj =
        fxt_write_file("run.obj", "mtllib run.mtl\nusemtl t\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                  "v 3 0 0\nv 4 0 0\nv 3 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                  "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\nusemtl plain\nf 5 6 7\n");
    scene *s = fxt_load_ok(obj);
    assert_int_equal(s->texture_count, 1);
    assert_int_equal(s->textures[0].levels, 7);
    static uint32_t tri[HITS];
    static float u[HITS], v[HITS], footprint[HITS], run[HITS][3];
    uint32_t n = 0, textured = 0;
    while (n < HITS) {
        rng = rng * 6364136223846793005ull + 1442695040888963407ull;
        uint32_t length = 1 + (uint32_t)(rng >> 33) % 150, t = (uint32_t)(rng >> 20) % 3;
        float level_base = (float)((rng >> 40) % 20) - 14.0f; /* -14 .. 5: a stretch's footprint */
        for (uint32_t i = 0; i < length && n < HITS; i++, n++) {
            rng = rng * 6364136223846793005ull + 1442695040888963407ull;
            tri[n] = t;
            u[n] = (float)((double)(rng >> 11) * 0x1p-53 * 3.0 - 1.0);
            rng = rng * 6364136223846793005ull + 1442695040888963407ull;
            v[n] = (float)((double)(rng >> 11) * 0x1p-53 * 3.0 - 1.0);
            footprint[n] =
                level_base + (float)((double)(rng >> 40) * 0x1p-24 * 1.5); /* a level or two apart */
            if (rng % 97 == 0)
                u[n] = rng % 2 ? NAN : INFINITY;
            textured += t < 2;
        }
    }
    for (uint32_t count = 1; count <= 200; count += 67) /* calls of several lengths over the same hits */
        for (uint32_t first = 0; first < HITS; first += count) {
            uint32_t c = HITS - first < count ? HITS - first : count;
            scene_albedo_run(s, tri + first, u + first, v + first, footprint + first, c, run + first);
        }
    for (uint32_t i = 0; i < HITS; i++) {
        float expected[3];
        scene_albedo_filtered(s, tri[i], u[i], v[i], footprint[i], expected);
        if (memcmp(expected, run[i], sizeof expected) != 0)
            fail_msg(
                "hit %u (triangle %u, uv %.9g %.9g, footprint %.9g): %.9g %.9g %.9g, expected %.9g %.9g %.9g",
                i, tri[i], (double)u[i], (double)v[i], (double)footprint[i], (double)run[i][0],
                (double)run[i][1], (double)run[i][2], (double)expected[0], (double)expected[1],
                (double)expected[2]);
    }
    assert_true(textured > HITS / 2);
    scene_free(s);
}

/* Bilinear texture lookup with wrap-around, against the same lookup in double: a 5 x 3 texture of distinct
 * texels, read at level 0 at random texture coordinates (negative, beyond 1, and on the texels next to each
 * edge, where the lookup wraps) and at every texel centre (the texel itself). */
static void test_texture_bilinear_wrap(void **state)
{
    (void)state;
    enum { W = 5, H = 3 };
    float texels[W * H * 3];
    for (int i = 0; i < W * H * 3; i++)
        texels[i] = (float)((i * 37) % 101) / 100.0f;
    scene_texture tex = {.width = W, .height = H, .rgb = texels, .levels = 1};
    tex.mip_rgb[0] = texels;
    tex.mip_width[0] = W;
    tex.mip_height[0] = H;
    /* One triangle whose texture coordinates equal its barycentrics (u, v): uv = (0,0), (1,0), (0,1). */
    scene_albedo_triangle tri = {.texture = &tex, .diffuse = {1, 1, 1}, .uv = {0, 0, 1, 0, 0, 1}, .lod = 0};
    uint64_t rng = 12345;
    int edge = 0;
    for (int n = 0; n < 20000; n++) {
        rng = rng * 6364136223846793005ull + 1442695040888963407ull;
        float u = (float)((double)(rng >> 11) * 0x1p-53 * 4.0 - 2.0);
        rng = rng * 6364136223846793005ull + 1442695040888963407ull;
        float v = (float)((double)(rng >> 11) * 0x1p-53 * 4.0 - 2.0);
        if (n < W * H) /* texel centres first */
            u = ((float)(n % W) + 0.5f) / W, v = 1.0f - ((float)(n / W) + 0.5f) / H;
        float rgb[3];
        scene_albedo_sample(&tri, u, v, -1000.0f, rgb); /* the finest level */
        double fu = (double)u - floor((double)u), fv = (double)v - floor((double)v);
        double x = fu * W - 0.5, y = (1.0 - fv) * H - 0.5, x0 = floor(x), y0 = floor(y);
        double ax = x - x0, ay = y - y0;
        edge += x0 < 0 || x0 + 1 >= W || y0 < 0 || y0 + 1 >= H;
        for (int k = 0; k < 3; k++) {
            double expected = 0;
            for (int c = 0; c < 4; c++) {
                int xi = ((int)x0 + (c & 1) + W) % W, yi = ((int)y0 + (c >> 1) + H) % H;
                expected +=
                    ((c & 1) ? ax : 1 - ax) * ((c >> 1) ? ay : 1 - ay) * texels[3 * (yi * W + xi) + k];
            }
            if (n < W * H)
                expected = texels[3 * n + k];
            if (fabs(rgb[k] - expected) > 2e-6)
                fail_msg("uv (%.9g, %.9g) channel %d: %.9g, expected %.9g", (double)u, (double)v, k,
                         (double)rgb[k], expected);
        }
    }
    assert_true(edge > 5000); /* the wrapped path was taken, as well as the inside one */
}

/* A texture that is not there: the material keeps its colour, the miss is counted, the load succeeds. */
static void test_missing_texture_counted(void **state)
{
    (void)state;
    fxt_write_file("gone.mtl", "newmtl m\nKd 0.5 0.5 0.5\nmap_Kd nowhere.png\n");
    const char *obj =
        fxt_write_file("gone.obj", "mtllib gone.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    scene *s = fxt_load_ok(obj);
    assert_int_equal(s->repairs.textures_missing, 1);
    assert_int_equal(s->texture_count, 0);
    float rgb[3];
    scene_albedo(s, 0, 0.3f, 0.3f, rgb);
    assert_true(fabsf(rgb[0] - 0.5f) < 1e-6f);
    scene_free(s);
}

#ifdef __SANITIZE_ADDRESS__
/* The sanitizer build unwinds every allocation's stack in full: the fast unwinder stops in libstdc++, so
 * lsan.supp's entry for OpenImageIO's leak on a truncated PNG (test_damaged_png_one_line) could not match. */
const char *__asan_default_options(void);
const char *__asan_default_options(void)
{
    return "fast_unwind_on_malloc=0";
}
#endif

/* A damaged PNG texture gives one warning line and nothing else on stderr (file descriptor 2, where libpng's
 * own handler wrote "libpng error: IDA[AB]: invalid chunk type" as a second line, and where OpenImageIO's
 * message for a truncated PNG spread over three lines); the material keeps its colour. */
static void test_damaged_png_one_line(void **state)
{
    (void)state;
    uint8_t pixels[4 * 4 * 3];
    memset(pixels, 200, sizeof pixels);
    char msg[256];
    const char *good = fxt_tmp_path("good.png");
    assert_int_equal(scene_image_write_u8(good, 4, 4, 3, pixels, msg, sizeof msg), 0);
    uint8_t bytes[4096];
    FILE *f = fopen(good, "rb");
    assert_non_null(f);
    size_t len = fread(bytes, 1, sizeof bytes, f);
    fclose(f);
    uint8_t *idat = NULL;
    for (size_t i = 0; i + 4 <= len && !idat; i++)
        if (memcmp(bytes + i, "IDAT", 4) == 0)
            idat = bytes + i;
    assert_non_null(idat);
    static const char *const names[2] = {"bad_chunk.png", "cut.png"};
    for (int k = 0; k < 2; k++) {
        char mtl[128], obj[256], err_path[1024];
        snprintf(mtl, sizeof mtl, "newmtl m\nKd 0.5 0.5 0.5\nmap_Kd %s\n", names[k]);
        fxt_write_file(k ? "cut.mtl" : "bad_chunk.mtl", mtl);
        snprintf(obj, sizeof obj,
                 "mtllib %s\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n",
                 k ? "cut.mtl" : "bad_chunk.mtl");
        char obj_path[1024]; /* fxt_tmp_path's buffer is reused below */
        snprintf(obj_path, sizeof obj_path, "%s", fxt_write_file(k ? "cut.obj" : "bad_chunk.obj", obj));
        f = fopen(fxt_tmp_path(names[k]), "wb");
        assert_non_null(f);
        if (k == 0) { /* the chunk type IDAT becomes IDAB */
            idat[3] = 'B';
            fwrite(bytes, 1, len, f);
            idat[3] = 'T';
        } else { /* cut inside the image data */
            fwrite(bytes, 1, (size_t)(idat - bytes) + 10, f);
        }
        fclose(f);
        /* stderr into a file while the scene loads */
        snprintf(err_path, sizeof err_path, "%s", fxt_tmp_path("png_stderr.txt"));
        fflush(stderr);
        int saved = dup(2);
        FILE *capture = fopen(err_path, "w+");
        assert_non_null(capture);
        assert_true(dup2(fileno(capture), 2) >= 0);
        scene *s = fxt_load_ok(obj_path);
        fflush(stderr);
        dup2(saved, 2);
        close(saved);
        char text[2048] = {0};
        rewind(capture);
        size_t n = fread(text, 1, sizeof text - 1, capture);
        fclose(capture);
        text[n] = 0;
        unsigned lines = 0;
        for (size_t i = 0; i < n; i++)
            lines += text[i] == '\n';
        print_message("%s: %s", names[k], text);
        if (lines != 1 || !strstr(text, names[k]) || !strstr(text, "(using its colour)"))
            fail_msg("%s: expected one warning line naming it, got %u lines: %s", names[k], lines, text);
        assert_int_equal(s->texture_count, 0);
        float rgb[3];
        scene_albedo(s, 0, 0.3f, 0.3f, rgb);
        assert_true(fabsf(rgb[0] - 0.5f) < 1e-6f);
        scene_free(s);
    }
}

/* Welding, degenerate and duplicate triangles through the builder. */
static void test_builder_cleaning(void **state)
{
    (void)state;
    scene_error err = {0};
    scene *s = scene__alloc();
    scene_material grey = {.diffuse = {0.5f, 0.5f, 0.5f}, .texture = -1};
    assert_int_equal(scene__add_material(s, &grey, &err), 0);
    /* Six vertices, two pairs of equal positions (-0 and +0 weld too); a duplicate, a repeated-vertex and a
     * zero-area triangle. */
    const float positions[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 0, 0, -0.0f, 1, 0, 2, 0, 0};
    const uint32_t indices[] = {0, 1, 2, 3, 4, 0, 0, 1, 2, 0, 0, 1, 0, 1, 5};
    assert_int_equal(scene__add_mesh(s, "m", positions, 6, indices, 5, NULL, 0, NULL, &err), SCENE_OK);
    assert_int_equal(s->repairs.vertices_welded, 2);
    assert_int_equal(s->repairs.duplicate_skipped, 2); /* 0 1 2 again, and 3 4 0 = 1 2 0 after welding */
    assert_int_equal(s->repairs.degenerate_skipped, 2);
    assert_int_equal(s->triangle_count, 1);
    assert_int_equal(scene__finalize(s, NULL, &err), SCENE_OK);
    scene_free(s);
}

/* A mirroring transform keeps the triangles facing the same way relative to the surface: the normal of the
 * mirrored triangle is the mirrored normal, not its opposite. */
static void test_mirrored_transform_keeps_winding(void **state)
{
    (void)state;
    scene_error err = {0};
    scene *s = scene__alloc();
    scene_material grey = {.diffuse = {0.5f, 0.5f, 0.5f}, .texture = -1};
    scene__add_material(s, &grey, &err);
    const float positions[] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const uint32_t indices[] = {0, 1, 2};
    const double mirror_z[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1};
    const double mirror_x[16] = {-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    assert_int_equal(scene__add_mesh(s, "z", positions, 3, indices, 1, NULL, 0, mirror_z, &err), SCENE_OK);
    assert_int_equal(scene__add_mesh(s, "x", positions, 3, indices, 1, NULL, 0, mirror_x, &err), SCENE_OK);
    assert_int_equal(scene__finalize(s, NULL, &err), SCENE_OK);
    assert_true(s->tri_normal[2] < -0.99f); /* +z normal mirrored in z: -z */
    assert_true(s->tri_normal[5] > 0.99f);  /* mirrored in x: the z normal stays +z */
    scene_free(s);
}

/* PLY files that made Assimp 5.2.5 loop forever (a damaged end_header line), or that it cannot read (a
 * header line that is no PLY keyword, where the vertex element should be; an element with no count), or that
 * abort its triangulation (a face with no vertex): refused with a one-line error, quickly. */
static void test_damaged_ply_refused(void **state)
{
    (void)state;
    static const char *const files[] = {
        /* end_header damaged */
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nen-1d_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 "
        "2\n",
        /* a header line that is no PLY keyword: Assimp skips it, and then finds no vertex element */
        "ply\nformat ascii 1.0\nelnanement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n0 0 0\n1 0 0\n0 1 0\n",
        /* an element without its count */
        "ply\nformat ascii 1.0\nelement ver\nproperty float x\nend_header\n0\n",
        /* an element count larger than the file */
        "ply\nformat ascii 1.0\nelement vertex 99999999\nproperty float x\nproperty float y\nproperty float "
        "z\n"
        "end_header\n0 0 0\n",
        /* a face with no data: Assimp's triangulation asserts */
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0/3 0 1 2\n",
    };
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        char name[32];
        snprintf(name, sizeof name, "damaged%zu.ply", i);
        scene_error err = {0};
        assert_null(scene_load(fxt_write_file(name, files[i]), NULL, &err));
        assert_int_equal(err.code, SCENE_ERR_FORMAT);
        assert_non_null(strstr(err.msg, name));
        assert_null(strchr(err.msg, '\n'));
    }
}

/* Loads `rounds` mutations of the seed files (round r mutates seed r % kinds, written under names[r % kinds])
 * from a fixed random sequence, so every run sees the same inputs: each either loads or fails with a
 * one-line error naming the file; never a crash, a hang or a sanitizer report. Counts both outcomes. */
static void mutation_run(const char *const *seeds, const char *const *names, int kinds, int rounds,
                         uint64_t rng, unsigned *loaded, unsigned *refused)
{
    static const char *const inserts[] = {"99999999",  "-1",         "1e39", "nan",
                                          "f 1 2 9\n", "4294967295", "\"",   "]"};
    static const char alphabet[] = "0123456789-. \nfvn/e+x\"{}[],:";
    char buf[2048];
    for (int round = 0; round < rounds; round++) {
        int kind = round % kinds;
        size_t len = strlen(seeds[kind]);
        memcpy(buf, seeds[kind], len + 1);
        int edits = 1 + (int)(splitmix(&rng) % 5);
        for (int e = 0; e < edits && len > 0; e++) {
            size_t pos = (size_t)(splitmix(&rng) % len);
            uint64_t what = splitmix(&rng) % 10;
            if (what < 5) {
                buf[pos] = alphabet[splitmix(&rng) % (sizeof alphabet - 1)];
            } else if (what < 7) {
                size_t cut = 1 + (size_t)(splitmix(&rng) % 5);
                cut = cut > len - pos ? len - pos : cut;
                memmove(buf + pos, buf + pos + cut, len - pos - cut + 1);
                len -= cut;
            } else {
                const char *ins = inserts[splitmix(&rng) % (sizeof inserts / sizeof inserts[0])];
                size_t n = strlen(ins);
                if (len + n + 1 > sizeof buf)
                    continue;
                memmove(buf + pos + n, buf + pos, len - pos + 1);
                memcpy(buf + pos, ins, n);
                len += n;
            }
        }
        scene_error err = {0};
        scene *s = scene_load(fxt_write_file(names[kind], buf), NULL, &err);
        if (s) {
            (*loaded)++;
            assert_true(s->triangle_count > 0);
            scene_free(s);
        } else {
            (*refused)++;
            assert_int_not_equal(err.code, SCENE_OK);
            if (!strstr(err.msg, names[kind]) || strchr(err.msg, '\n'))
                fail_msg("round %d: not one line naming %s: '%s'", round, names[kind], err.msg);
        }
    }
}

/* A bounded mutation run (fixed seed, so every run sees the same 240 inputs): damaged OBJ, PLY and glTF files
 * either load or fail with a one-line error naming the file; never a crash, a hang or a sanitizer report.
 * The mutations are the kind that found Assimp's PLY loop and triangulation abort. */
static void test_mutated_files(void **state)
{
    (void)state;
    static const char *const seeds[3] = {
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 1\nf 1/1 2/2 3/1\nf 1 3 4\n",
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1}]}],"
        "\"buffers\":[{\"byteLength\":44,\"uri\":\"data:application/octet-stream;base64,"
        "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA=\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36},{\"buffer\":0,\"byteOffset\":36,\"byteLength\":6}]"
        ","
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\","
        "\"min\":[0,0,0],\"max\":[1,1,0]},{\"bufferView\":1,\"componentType\":5123,\"count\":3,\"type\":"
        "\"SCALAR\"}]}",
    };
    static const char *const names[3] = {"mutated.obj", "mutated.ply", "mutated.gltf"};
    unsigned loaded = 0, refused = 0;
    mutation_run(seeds, names, 3, 240, 20261123, &loaded, &refused);
    print_message("mutated files: %u loaded, %u refused\n", loaded, refused);
    assert_true(loaded > 0 && refused > 0);
}

/* The same for the formats whose declared counts and indices are checked before Assimp reads them (OFF,
 * text .x, ASE, MD5 mesh): the checks read untrusted bytes, and what they let through must not crash
 * Assimp either. */
static void test_mutated_counted_formats(void **state)
{
    (void)state;
    static const char *const seeds[4] = {
        "OFF\n# a comment\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n",
        "xof 0302txt 0064\nMesh m {\n4;\n0;0;0;,\n1;0;0;,\n1;1;0;,\n0;1;0;;\n2;\n3;0,1,2;,\n3;0,2,3;;\n"
        "MeshNormals {\n1;\n0;0;1;;\n2;\n3;0,0,0;,\n3;0,0,0;;\n}\n}\n",
        "*3DSMAX_ASCIIEXPORT 200\n*GEOMOBJECT {\n*NODE_NAME \"a\"\n*MESH {\n*MESH_NUMVERTEX "
        "3\n*MESH_NUMFACES 1\n"
        "*MESH_VERTEX_LIST {\n*MESH_VERTEX 0 0 0 0\n*MESH_VERTEX 1 1 0 0\n*MESH_VERTEX 2 0 1 0\n}\n"
        "*MESH_FACE_LIST {\n*MESH_FACE 0: A: 0 B: 1 C: 2\n}\n}\n}\n",
        "MD5Version 10\ncommandline \"\"\n\nnumJoints 1\nnumMeshes 1\n\njoints {\n\"root\" -1 ( 0 0 0 ) ( 0 "
        "0 0 )\n}\n"
        "\nmesh {\nshader \"m\"\nnumverts 3\nvert 0 ( 0 0 ) 0 1\nvert 1 ( 1 0 ) 1 1\nvert 2 ( 0 1 ) 2 "
        "1\nnumtris 1\n"
        "tri 0 0 2 1\nnumweights 3\nweight 0 0 1 ( 0 0 0 )\nweight 1 0 1 ( 1 0 0 )\nweight 2 0 1 ( 0 1 0 "
        ")\n}\n",
    };
    static const char *const names[4] = {"mutated.off", "mutated.x", "mutated.ase", "mutated.md5mesh"};
    unsigned loaded = 0, refused = 0;
    mutation_run(seeds, names, 4, 320, 20261128, &loaded, &refused);
    print_message("mutated files: %u loaded, %u refused\n", loaded, refused);
    assert_true(loaded > 0 && refused > 0);
}

/* One input of the table-driven tests below: a file written by the test (or named in Assimp's models), and
 * what loading it must give. */
typedef struct input_case {
    const char *name;   /* file name in the test's folder, or a path under ASSIMP_MODELS */
    const char *bytes;  /* the file's content (NULL: an Assimp model, or a directory when dir is set) */
    size_t len;         /* bytes in content; 0: strlen */
    bool dir;           /* make a directory of that name instead of a file */
    scene_result code;  /* SCENE_OK: must load */
    const char *needle; /* must be in the error message (when code is not SCENE_OK) */
    uint32_t triangles; /* when it loads: exactly this many triangles (0: any number above 0) */
} input_case;

/* Loads one case and checks the outcome: the load's code, and for a refusal one line naming the file and
 * containing the needle. */
static void check_input_case(const input_case *c, const char *path)
{
    scene_error err = {0};
    scene *s = scene_load(path, NULL, &err);
    if (c->code == SCENE_OK) {
        if (!s)
            fail_msg("%s: expected to load, got: %s", c->name, err.msg);
        if (c->triangles)
            assert_int_equal(s->triangle_count, c->triangles);
        assert_true(s->triangle_count > 0);
        scene_free(s);
        return;
    }
    if (s) {
        scene_free(s);
        fail_msg("%s: expected a refusal containing '%s', but it loaded", c->name, c->needle);
    }
    if (err.code != c->code || !strstr(err.msg, c->needle) || !strstr(err.msg, c->name) ||
        strchr(err.msg, '\n'))
        fail_msg("%s: expected code %d and one line naming the file with '%s'; got code %d: '%s'", c->name,
                 (int)c->code, c->needle, (int)err.code, err.msg);
}

/* A binary PLY of a unit quad (4 float vertices, 2 faces as uchar-counted int lists, then an element 'extra'
 * of one short and one double) in either byte order: the last `cut` bytes left off, and the second face's
 * last index set to `last_index`. Returns its length. */
static size_t binary_ply(char *buf, size_t cap, bool big, size_t cut, int32_t last_index)
{
    size_t at = (size_t)snprintf(buf, cap,
                                 "ply\nformat %s 1.0\nelement vertex 4\nproperty float x\nproperty float "
                                 "y\nproperty float z\nelement face 2\nproperty list uchar int "
                                 "vertex_indices\nelement extra 1\nproperty short s\nproperty float64 "
                                 "d\nend_header\n",
                                 big ? "binary_big_endian" : "binary_little_endian");
    const float corners[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
    const int32_t faces[2][3] = {{0, 1, 2}, {0, 2, last_index}};
    uint8_t body[128];
    size_t n = 0;
    /* each value as bytes in the file's order */
#define PUT(value, bytes)                                                                                    \
    do {                                                                                                     \
        uint64_t bits_ = (value);                                                                            \
        for (int k_ = 0; k_ < (bytes); k_++)                                                                 \
            body[n++] = (uint8_t)(bits_ >> (8 * (big ? (bytes)-1 - k_ : k_)));                               \
    } while (0)
    for (int v = 0; v < 4; v++)
        for (int k = 0; k < 3; k++) {
            uint32_t bits;
            memcpy(&bits, &corners[v][k], 4);
            PUT(bits, 4);
        }
    for (int f = 0; f < 2; f++) {
        PUT(3, 1);
        for (int k = 0; k < 3; k++)
            PUT((uint32_t)faces[f][k], 4);
    }
    PUT(7, 2);
    double d = 0.5;
    uint64_t dbits;
    memcpy(&dbits, &d, 8);
    PUT(dbits, 8);
#undef PUT
    assert_true(at + n <= cap && cut <= n);
    memcpy(buf + at, body, n - cut);
    return at + n - cut;
}

/* A binary STL of count facets declared, with facets_written facets of data after the header. */
static size_t binary_stl(char *buf, size_t cap, uint32_t declared, uint32_t facets_written)
{
    size_t len = 84 + 50 * (size_t)facets_written;
    assert_true(len <= cap);
    memset(buf, 0, len);
    memcpy(buf, "binary STL written by test_import", 33);
    for (int k = 0; k < 4; k++)
        buf[80 + k] = (char)(declared >> (8 * k));
    const float tri[12] = {0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0}; /* normal, then three corners */
    for (uint32_t f = 0; f < facets_written; f++)
        memcpy(buf + 84 + 50 * (size_t)f, tri, sizeof tri); /* little-endian floats on this machine */
    return len;
}

/* Declared counts are checked against the file size before Assimp reads them (Assimp allocates from the
 * header alone: 3.5 billion OFF vertices for a 40-byte file); the indices of ASE, MD5 and .x files Assimp
 * uses unchecked are checked (each case below crashed it); honest files still load; Quake 3 maps, which
 * Assimp 5.2.5 cannot give usable triangles for, and a directory named like a model are refused with what is
 * wrong; Assimp's own message is kept to one line, and an error found after the import (a triangle too
 * long for an island) names the file too. */
static void test_inputs_refused_or_read(void **state)
{
    (void)state;
    static char stl_wrapped[200], stl_one[200];
    /* 2^31 + 1 facets: 50 * count + 84 wraps in 32 bits to the 134 bytes of the file, which makes Assimp take
     * the file for binary STL. */
    size_t stl_wrapped_len = binary_stl(stl_wrapped, sizeof stl_wrapped, 2147483649u, 1);
    size_t stl_one_len = binary_stl(stl_one, sizeof stl_one, 1, 1);
    const char *tri_off_tail = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    char off_huge_vertices[128], off_huge_faces[128], off_no_keyword[128], coff[128], off_ok[128];
    snprintf(off_huge_vertices, sizeof off_huge_vertices, "OFF\n3500000000 1 0\n%s", tri_off_tail);
    snprintf(off_huge_faces, sizeof off_huge_faces, "OFF\n# a comment\n3 4000000000 0\n%s", tri_off_tail);
    snprintf(off_no_keyword, sizeof off_no_keyword, "3 99999999 0\n%s", tri_off_tail);
    snprintf(coff, sizeof coff, "COFF 99999999 1 0\n%s", tri_off_tail);
    snprintf(off_ok, sizeof off_ok, "OFF\n3 1 0\n%s", tri_off_tail);
    /* Faces Assimp's OFF reader (5.2.5) would drop or change without a word: a decagon (it drops faces of
     * more than 9 corners), index 7 of 3 vertices (clamped to vertex 2: the file loaded as a triangle it
     * does not have), a missing or negative index (read as vertex 0), a line too long for its buffer (it
     * writes a byte past it and reads the rest as the next line). A nonagon with comments, blank lines and
     * CRLF line ends is read: 9 corners make 7 triangles. */
    static char off_decagon[512], off_nonagon[512], off_long[6000];
    snprintf(off_decagon, sizeof off_decagon, "OFF\n11 2 0\n");
    size_t at = (size_t)snprintf(off_nonagon, sizeof off_nonagon, "OFF 9 1 0\r\n# nine corners\r\n");
    for (int k = 0; k < 10; k++) {
        double a = 2 * M_PI * k / 10, b = 2 * M_PI * k / 9;
        size_t used = strlen(off_decagon);
        snprintf(off_decagon + used, sizeof off_decagon - used, "%.6f %.6f 0\n", cos(a), sin(a));
        if (k < 9)
            at += (size_t)snprintf(off_nonagon + at, sizeof off_nonagon - at, "%.6f %.6f 0\r\n\r\n", cos(b),
                                   sin(b));
    }
    size_t used = strlen(off_decagon);
    snprintf(off_decagon + used, sizeof off_decagon - used, "0 0 1\n10 0 1 2 3 4 5 6 7 8 9\n3 0 1 10\n");
    snprintf(off_nonagon + at, sizeof off_nonagon - at, "9 0 1 2 3 4 5 6 7 8  \r\n");
    at = (size_t)snprintf(off_long, sizeof off_long, "OFF\n3 1 0\n0 0 0");
    memset(off_long + at, ' ', 5000);
    snprintf(off_long + at + 5000, sizeof off_long - at - 5000, "\n1 0 0\n0 1 0\n3 0 1 2\n");
    /* PLY bodies that disagree with their headers: Assimp 5.2.5 read a short vertex line as zeros, ignored
     * extra values and lines, loaded a file missing a face (as a copy) and called a truncated binary body or
     * an index out of range "Validation failed: mIndices[2] is out of range". The same quad in ASCII (CRLF,
     * blank lines, an element after the faces) and in both binary byte orders loads as 2 triangles. */
    static char ply_le[512], ply_be[512], ply_le_cut[512], ply_be_cut[512], ply_le_range[512],
        ply_be_neg[512];
    size_t ply_le_len = binary_ply(ply_le, sizeof ply_le, false, 0, 3);
    size_t ply_be_len = binary_ply(ply_be, sizeof ply_be, true, 0, 3);
    size_t ply_le_cut_len = binary_ply(ply_le_cut, sizeof ply_le_cut, false, 1, 3);
    size_t ply_be_cut_len = binary_ply(ply_be_cut, sizeof ply_be_cut, true, 20, 3);
    size_t ply_le_range_len = binary_ply(ply_le_range, sizeof ply_le_range, false, 0, 4);
    size_t ply_be_neg_len = binary_ply(ply_be_neg, sizeof ply_be_neg, true, 0, -1);
#define PLY_QUAD_HEAD                                                                                        \
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"        \
    "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
    const char *ply_crlf =
        "ply\r\nformat ascii 1.0\r\nelement vertex 4\r\nproperty float x\r\nproperty float "
        "y\r\nproperty float z\r\nelement face 2\r\nproperty list uchar int vertex_indices\r\n"
        "element extra 1\r\nproperty list int float f\r\nend_header\r\n0 0 0\r\n1 0 0\r\n"
        "1 1 0\r\n 0 1e0 -0\r\n3 0 1 2\r\n3   0 2 +3 \r\n2 0.5 -7\r\n\r\n\r\n";
    const char *ply_head = "ply\nformat ascii 1.0\n";
    const char *ply_body = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                           "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                           "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    char ply_blender[512], ply_comment_small[512], ply_comment_huge[512], ply_comment_vertex[512];
    snprintf(ply_blender, sizeof ply_blender,
             "%sCreated by Blender3D 247 - www.blender.org, source file: \n%s", ply_head, ply_body);
    snprintf(ply_comment_small, sizeof ply_comment_small,
             "%scomment 2023 scan, obj_info below\nobj_info x\n%s", ply_head, ply_body);
    snprintf(ply_comment_huge, sizeof ply_comment_huge, "%scomment 4000000000 points\n%s", ply_head,
             ply_body);
    snprintf(ply_comment_vertex, sizeof ply_comment_vertex, "%scomment vertex 99999999\n%s", ply_head,
             ply_body);
    /* text .x: a mesh of two triangles with normals */
    const char *x_head = "xof 0302txt 0064\nMesh m {\n4;\n0;0;0;,\n1;0;0;,\n1;1;0;,\n0;1;0;;\n";
    const char *x_faces = "2;\n3;0,1,2;,\n3;0,2,3;;\n";
    char x_ok[512], x_huge[512], x_negative[512], x_normal[512];
    snprintf(x_ok, sizeof x_ok, "%s%sMeshNormals {\n1;\n0;0;1;;\n2;\n3;0,0,0;,\n3;0,0,0;;\n}\n}\n", x_head,
             x_faces);
    snprintf(x_huge, sizeof x_huge,
             "xof 0302txt 0064\nMesh m {\n300000000;\n0;0;0;,\n1;0;0;,\n0;1;0;;\n1;\n3;0,1,2;;\n}\n");
    snprintf(x_negative, sizeof x_negative, "%s-12;\n3;0,1,2;,\n3;0,2,3;;\n}\n", x_head);
    snprintf(x_normal, sizeof x_normal, "%s%sMeshNormals {\n1;\n0;0;1;;\n2;\n3;0,-10,0;,\n3;0,0,0;;\n}\n}\n",
             x_head, x_faces);
    /* ASE: one triangle */
    const char *ase_head = "*3DSMAX_ASCIIEXPORT 200\n*GEOMOBJECT {\n*NODE_NAME \"a\"\n*MESH {\n";
    const char *ase_vertices =
        "*MESH_NUMVERTEX 3\n*MESH_VERTEX_LIST {\n*MESH_VERTEX 0 0 0 0\n*MESH_VERTEX 1 1 0 0\n"
        "*MESH_VERTEX 2 0 1 0\n}\n";
    char ase_ok[512], ase_huge[512], ase_no_face_line[512], ase_no_vertices[512], ase_corner[512],
        ase_half_face[512];
    snprintf(ase_ok, sizeof ase_ok,
             "%s%s*MESH_NUMFACES 1\n*MESH_FACE_LIST {\n*MESH_FACE 0: A: 0 B: 1 C: 2\n}\n}\n}\n", ase_head,
             ase_vertices);
    snprintf(ase_huge, sizeof ase_huge, "%s*MESH_NUMVERTEX 300000000\n}\n}\n", ase_head);
    snprintf(ase_no_face_line, sizeof ase_no_face_line,
             "%s%s*MESH_NUMFACES 2\n*MESH_FACE_LIST {\n"
             "*MESH_FACE 0: A: 0 B: 1 C: 2\n}\n}\n}\n",
             ase_head, ase_vertices);
    snprintf(ase_no_vertices, sizeof ase_no_vertices,
             "%s*MESH_NUMFACES 1\n*MESH_FACE_LIST {\n"
             "*MESH_FACE 0: A: 0 B: 1 C: 2\n}\n}\n}\n",
             ase_head);
    snprintf(ase_corner, sizeof ase_corner,
             "%s%s*MESH_NUMFACES 1\n*MESH_FACE_LIST {\n"
             "*MESH_FACE 0: A: 0 B: 1 C: 159999999\n}\n}\n}\n",
             ase_head, ase_vertices);
    snprintf(ase_half_face, sizeof ase_half_face,
             "%s%s*MESH_NUMFACES 1\n*MESH_FACE_LIST {\n"
             "*MESH_FACE 0: A: 0 B: 1 C:\n}\n}\n}\n",
             ase_head, ase_vertices);
    /* MD5 mesh: one joint, one triangle, one weight per vertex */
    const char *md5_head = "MD5Version 10\ncommandline \"\"\n\nnumJoints 1\nnumMeshes 1\n\n"
                           "joints {\n\"root\" -1 ( 0 0 0 ) ( 0 0 0 )\n}\n\nmesh {\nshader \"m\"\n";
    const char *md5_tri = "numtris 1\ntri 0 0 2 1\n";
    const char *md5_weights =
        "numweights 3\nweight 0 0 1 ( 0 0 0 )\nweight 1 0 1 ( 1 0 0 )\nweight 2 0 1 ( 0 1 0 )\n";
    const char *md5_verts = "numverts 3\nvert 0 ( 0 0 ) 0 1\nvert 1 ( 1 0 ) 1 1\nvert 2 ( 0 1 ) 2 1\n";
    char md5_ok[1024], md5_missing[1024], md5_joint[1024], md5_weight_range[1024], md5_unused[1024],
        md5_quote[1024], md5_no_joints[1024];
    snprintf(md5_ok, sizeof md5_ok, "%s%s%s%s}\n", md5_head, md5_verts, md5_tri, md5_weights);
    snprintf(md5_missing, sizeof md5_missing,
             "%snumverts 40\nvert 0 ( 0 0 ) 0 1\nvert 1 ( 1 0 ) 1 1\n"
             "vert 2 ( 0 1 ) 2 1\n%s%s}\n",
             md5_head, md5_tri, md5_weights);
    snprintf(md5_joint, sizeof md5_joint,
             "%s%s%snumweights 3\nweight 0 0 1 ( 0 0 0 )\nweight 1 0 1 ( 1 0 0 )\n"
             "weight 2 7 1 ( 0 1 0 )\n}\n",
             md5_head, md5_verts, md5_tri);
    snprintf(md5_weight_range, sizeof md5_weight_range,
             "%snumverts 3\nvert 0 ( 0 0 ) 0 1\nvert 1 ( 1 0 ) 1 1\n"
             "vert 2 ( 0 1 ) 2 9\n%s%s}\n",
             md5_head, md5_tri, md5_weights);
    snprintf(md5_unused, sizeof md5_unused,
             "%snumverts 4\nvert 0 ( 0 0 ) 0 1\nvert 1 ( 1 0 ) 1 1\n"
             "vert 2 ( 0 1 ) 2 1\nvert 3 ( 0 1 ) 2 1\nnumtris 2\ntri 0 0 2 1\ntri 1 0 0 0\n%s}\n",
             md5_head, md5_weights);
    snprintf(md5_quote, sizeof md5_quote, "%s%s%s}\n",
             "MD5Version 10\ncommandline \"\"\n\nnumJoints 1\nnumMeshes 1\n"
             "\njoints {\n\"root\" -1 ( 0 0 0 ) ( 0 0 0 )\n}\n\nmesh {\nshader \"m\n",
             md5_verts, md5_tri);
    /* "joints {" right under "numMeshes 1": Assimp reads the block as part of the numMeshes section */
    snprintf(md5_no_joints, sizeof md5_no_joints,
             "MD5Version 10\n\nnumMeshes 1\njoints {\n\"root\" -1 ( 0 0 0 ) "
             "( 0 0 0 )\n}\n\nmesh {\nshader \"m\"\n%s%s%s}\n",
             md5_verts, md5_tri, md5_weights);
    const input_case cases[] = {
        {"honest.x", x_ok, 0, false, SCENE_OK, NULL, 2},
        {"huge.x", x_huge, 0, false, SCENE_ERR_FORMAT, ":3: declares 300000000 vertices (Mesh)", 0},
        {"negative.x", x_negative, 0, false, SCENE_ERR_FORMAT, "declares -12 faces (Mesh)", 0},
        {"normal.x", x_normal, 0, false, SCENE_ERR_FORMAT, "uses normal -10, but it has 1 normals", 0},
        {"format.x", "xof 03024\nMe 0064\n", 0, false, SCENE_ERR_FORMAT, "Unsupported x-file format '4 Me'",
         0},
        /* a sliver 1000 m long: the auto density is lowered so that it fits an island (it was refused at its
         * own auto density with "lower the texel density"); at a density given for it, it is refused */
        {"sliver.obj", "v 0 0 0\nv 1000 0 0\nv 0 0.001 0\nf 1 2 3\n", 0, false, SCENE_OK, NULL, 1},
        {"sliver.json", "{\"version\": 1, \"meshes\": [{\"file\": \"sliver.obj\"}], \"texel_density\": 100}",
         0, false, SCENE_ERR_RANGE, "an island may be at most", 0},
        {"honest.ase", ase_ok, 0, false, SCENE_OK, NULL, 1},
        {"huge.ase", ase_huge, 0, false, SCENE_ERR_FORMAT, "declares 300000000 items (*MESH_NUMVERTEX)", 0},
        {"no_face_line.ase", ase_no_face_line, 0, false, SCENE_ERR_FORMAT,
         "no *MESH_FACE line for face 1 of its 2", 0},
        {"no_vertices.ase", ase_no_vertices, 0, false, SCENE_ERR_FORMAT, "has 1 faces but no vertices", 0},
        {"corner.ase", ase_corner, 0, false, SCENE_ERR_FORMAT,
         "a *MESH_FACE line uses a vertex beyond its list", 0},
        {"half_face.ase", ase_half_face, 0, false, SCENE_ERR_FORMAT, ":13: a *MESH_FACE line that is not", 0},
        {"honest.md5mesh", md5_ok, 0, false, SCENE_OK, NULL, 1},
        {"missing.md5mesh", md5_missing, 0, false, SCENE_ERR_FORMAT, "no vert line for index 3 of its 40", 0},
        {"joint.md5mesh", md5_joint, 0, false, SCENE_ERR_FORMAT,
         "weight 2 uses joint 7, but Assimp finds 1 joints", 0},
        {"no_joints.md5mesh", md5_no_joints, 0, false, SCENE_ERR_FORMAT,
         "uses joint 0, but Assimp finds 0 joints", 0},
        {"weights.md5mesh", md5_weight_range, 0, false, SCENE_ERR_FORMAT,
         "vert 2 uses 9 weights from weight 2", 0},
        {"unused.md5mesh", md5_unused, 0, false, SCENE_ERR_FORMAT, "vert 3 is used by no triangle", 0},
        {"quote.md5mesh", md5_quote, 0, false, SCENE_ERR_FORMAT,
         ":12: a quotation mark not closed on its line", 0},
        {"huge_vertices.off", off_huge_vertices, 0, false, SCENE_ERR_FORMAT, "declares 3500000000 vertices",
         0},
        {"huge_faces.off", off_huge_faces, 0, false, SCENE_ERR_FORMAT, ":3: declares 4000000000 faces", 0},
        {"no_keyword.off", off_no_keyword, 0, false, SCENE_ERR_FORMAT, "declares 99999999 faces", 0},
        {"coff.off", coff, 0, false, SCENE_ERR_FORMAT, "declares 99999999 vertices", 0},
        {"honest.off", off_ok, 0, false, SCENE_OK, NULL, 1},
        {"nonagon.off", off_nonagon, 0, false, SCENE_OK, NULL, 7},
        {"decagon.off", off_decagon, 0, false, SCENE_ERR_FORMAT, ":14: face 0 has 10 corners", 0},
        {"range.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", 0, false, SCENE_ERR_FORMAT,
         ":6: face 0 uses vertex 7, but the file declares 3 vertices", 0},
        {"short_face.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n4 1 2 3\n", 0, false,
         SCENE_ERR_FORMAT, ":8: face 1: corner 3 of 4 is missing", 0},
        {"negative_index.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", 0, false, SCENE_ERR_FORMAT,
         "corner 1 of 3 is missing or not a vertex index", 0},
        {"no_count.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n", 0, false, SCENE_ERR_FORMAT,
         "face 0 does not start with its corner count", 0},
        {"long_line.off", off_long, 0, false, SCENE_ERR_FORMAT, ":3: a line of 5005 bytes", 0},
        {"wrapped.stl", stl_wrapped, stl_wrapped_len, false, SCENE_ERR_FORMAT, "declares 2147483649 facets",
         0},
        {"one.stl", stl_one, stl_one_len, false, SCENE_OK, NULL, 1},
        {"quad_crlf.ply", ply_crlf, 0, false, SCENE_OK, NULL, 2},
        {"quad_le.ply", ply_le, ply_le_len, false, SCENE_OK, NULL, 2},
        {"quad_be.ply", ply_be, ply_be_len, false, SCENE_OK, NULL, 2},
        {"blank_line.ply", PLY_QUAD_HEAD "\n0 0 0\n1 0 0\n\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", 0, false,
         SCENE_OK, NULL, 2},
        {"two_blank_lines.ply", PLY_QUAD_HEAD "0 0 0\n1 0 0\n\n\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", 0, false,
         SCENE_ERR_FORMAT, ":13: a blank line where item 2 of element 'vertex' should be", 0},
        {"crlf_blank_line.ply",
         PLY_QUAD_HEAD "0 0 0\r\n1 0 0\r\n\r\n1 1 0\r\n0 1 0\r\n3 0 1 2\r\n3 0 2 3\r\n", 0, false,
         SCENE_ERR_FORMAT, ":12: a blank line where item 2 of element 'vertex' should be", 0},
        {"short_vertex.ply", PLY_QUAD_HEAD "0 0 0\n1 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", 0, false,
         SCENE_ERR_FORMAT, ":11: element 'vertex' item 1 has 2 values, the header declares 3", 0},
        {"long_vertex.ply", PLY_QUAD_HEAD "0 0 0 7\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", 0, false,
         SCENE_ERR_FORMAT, ":10: element 'vertex' item 0 has 4 values, the header declares 3", 0},
        {"word.ply", PLY_QUAD_HEAD "0 0 0\n1 abc 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", 0, false,
         SCENE_ERR_FORMAT, ":11: 'abc' is not a number (element 'vertex' item 1, property 'y')", 0},
        {"fraction_index.ply", PLY_QUAD_HEAD "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 2.5\n", 0, false,
         SCENE_ERR_FORMAT, ":15: '2.5' is not a whole number", 0},
        {"index_range.ply", PLY_QUAD_HEAD "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 4\n", 0, false,
         SCENE_ERR_FORMAT, ":15: face 1 uses vertex 4, but the file declares 4 vertices", 0},
        {"short_face.ply", PLY_QUAD_HEAD "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2\n", 0, false,
         SCENE_ERR_FORMAT, ":15: element 'face' item 1 has 3 values, the header declares 4", 0},
        {"no_length.ply", PLY_QUAD_HEAD "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n-3 0 2 3\n", 0, false,
         SCENE_ERR_FORMAT, ":15: '-3' is not a list length", 0},
        {"missing_face.ply", PLY_QUAD_HEAD "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n", 0, false,
         SCENE_ERR_FORMAT, "the body ends before item 1 of the 2 of element 'face'", 0},
        {"extra_face.ply", PLY_QUAD_HEAD "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n3 0 1 3\n", 0, false,
         SCENE_ERR_FORMAT, ":16: data after the last item the header declares", 0},
        {"cut_le.ply", ply_le_cut, ply_le_cut_len, false, SCENE_ERR_FORMAT,
         "truncated: the binary body ends (after 83 bytes) inside item 0 of the 1 of element 'extra'", 0},
        {"cut_be.ply", ply_be_cut, ply_be_cut_len, false, SCENE_ERR_FORMAT,
         "truncated: the binary body ends (after 64 bytes) inside item 1 of the 2 of element 'face'", 0},
        {"range_le.ply", ply_le_range, ply_le_range_len, false, SCENE_ERR_FORMAT,
         "face 1 uses vertex 4, but the file declares 4 vertices", 0},
        {"negative_be.ply", ply_be_neg, ply_be_neg_len, false, SCENE_ERR_FORMAT,
         "face 1 uses vertex -1, but the file declares 4 vertices", 0},
        {"blender247.ply", ply_blender, 0, false, SCENE_OK, NULL, 1},
        {"comment_small.ply", ply_comment_small, 0, false, SCENE_OK, NULL, 1},
        {"comment_huge.ply", ply_comment_huge, 0, false, SCENE_ERR_FORMAT, ":3: Assimp reads this comment",
         0},
        {"comment_vertex.ply", ply_comment_vertex, 0, false, SCENE_ERR_FORMAT, "declaring 99999999 items", 0},
        {"map.bsp", "IBSP\x2e", 5, false, SCENE_ERR_FORMAT, "only from inside a .pk3", 0},
        {"maps.pk3", "PK\x03\x04", 4, false, SCENE_ERR_FORMAT, "vertex indices unset", 0},
        {"folder.obj", NULL, 0, true, SCENE_ERR_IO, "is a directory", 0},
        {"comment_only.obj", "# nothing but comments here\nmtllib none.mtl\n", 0, false, SCENE_ERR_EMPTY,
         "Assimp read no meshes from it", 0},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const input_case *c = &cases[i];
        char path[1024];
        snprintf(path, sizeof path, "%s", fxt_tmp_path(c->name));
        if (c->dir) {
            assert_true(mkdir(path, 0755) == 0 || access(path, F_OK) == 0);
        } else {
            FILE *f = fopen(path, "wb");
            assert_non_null(f);
            size_t len = c->len ? c->len : strlen(c->bytes);
            assert_int_equal(fwrite(c->bytes, 1, len, f), len);
            fclose(f);
        }
        check_input_case(c, path);
    }
}

/* Assimp's own test models that crashed, ran out of memory or were refused wrongly: an AC3D file of lines
 * only (a segfault in Assimp's pre-transform step), an OFF header claiming 353535235358 vertices (8 GB and
 * growing), a Blender 2.47 PLY with a bare text line in its header (refused by fxcache's header check). */
static void test_assimp_models(void **state)
{
    (void)state;
    if (access(ASSIMP_MODELS, R_OK) != 0) {
        print_message("SKIP: %s is absent (install assimp-testmodels)\n", ASSIMP_MODELS);
        skip();
    }
    static const input_case cases[] = {
        {"AC/nosurfaces.ac", NULL, 0, false, SCENE_ERR_EMPTY, "only 7 points and lines", 0},
        {"M3D/cube_normals.m3d", NULL, 0, false, SCENE_ERR_EMPTY, "Assimp read no meshes from it", 0},
        {"invalid/OutOfMemory.off", NULL, 0, false, SCENE_ERR_FORMAT, "declares 353535235358 vertices", 0},
        {"PLY/Wuson.ply", NULL, 0, false, SCENE_OK, NULL, 0},
        {"OFF/Cube.off", NULL, 0, false, SCENE_OK, NULL, 12},
        {"OFF/invalid.off", NULL, 0, false, SCENE_ERR_FORMAT, ":6: face 0 has 0 corners", 0},
        {"OpenGEX/empty_camera.ogex", NULL, 0, false, SCENE_ERR_FORMAT, "Assimp also printed: 'nullptr", 0},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char path[1024];
        snprintf(path, sizeof path, "%s/%s", ASSIMP_MODELS, cases[i].name);
        check_input_case(&cases[i], path);
    }
}

/* 3DS through Assimp: the horse Debian's glmark2-data ships. */
static void test_3ds_horse(void **state)
{
    (void)state;
    const char *path = "/usr/share/glmark2/models/horse.3ds";
    FILE *f = fopen(path, "rb");
    if (!f) {
        print_message("SKIP: %s is absent (install glmark2-data)\n", path);
        skip();
    }
    fclose(f);
    scene *s = fxt_load_ok(path);
    assert_true(s->triangle_count > 1000);
    assert_true(s->island_count > 0);
    for (uint32_t i = 0; i < s->island_count; i++)
        assert_true(s->islands[i].triangle_count <= SCENE_ISLAND_MAX_TRIANGLES);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_gltf),
        cmocka_unit_test(test_ply_and_gz),
        cmocka_unit_test(test_bad_gz),
        cmocka_unit_test(test_obj_texture_and_non_triangles),
        cmocka_unit_test(test_texture_mip_levels),
        cmocka_unit_test(test_float_texture_albedo_clamped),
        cmocka_unit_test(test_texture_bilinear_wrap),
        cmocka_unit_test(test_albedo_run_equals_filtered),
        cmocka_unit_test(test_missing_texture_counted),
        cmocka_unit_test(test_damaged_png_one_line),
        cmocka_unit_test(test_builder_cleaning),
        cmocka_unit_test(test_mirrored_transform_keeps_winding),
        cmocka_unit_test(test_damaged_ply_refused),
        cmocka_unit_test(test_mutated_files),
        cmocka_unit_test(test_mutated_counted_formats),
        cmocka_unit_test(test_3ds_horse),
        cmocka_unit_test(test_inputs_refused_or_read),
        cmocka_unit_test(test_assimp_models),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
