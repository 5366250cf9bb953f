/* Damaged texture files: a truncated JPEG, which OpenImageIO returns whole (libjpeg fills what is missing with
 * grey) with the error left only in geterror(), loads with one warning line naming the file; before, it loaded
 * silently. Checked on the shim (scene_image_read_rgb: 0 with the warning in msg; "" for the whole file) and
 * through the command line (`fxcache scene-info` on a JSON scene whose texture is the truncated file: it
 * loads, and stderr is that one line). A truncated PNG, which the reader refuses, fails the load with one
 * line. docs/SCENE_FORMAT.md, "Material". */
#include "test_util.h"

#include "image.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* A 64 x 64 gradient written as path (JPEG or PNG by the name), then cut to `keep` of its bytes (0: whole). */
static void write_image(const char *path, double keep)
{
    enum { SIDE = 64 };
    static uint8_t pixels[SIDE * SIDE * 3];
    for (int i = 0; i < SIDE * SIDE; i++) {
        pixels[3 * i] = (uint8_t)(i % SIDE * 4);
        pixels[3 * i + 1] = (uint8_t)(i / SIDE * 4);
        pixels[3 * i + 2] = (uint8_t)((i * 7) & 0xFF);
    }
    char msg[512];
    if (scene_image_write_u8(path, SIDE, SIDE, 3, pixels, msg, sizeof msg) != 0)
        fail_msg("%s", msg);
    if (keep > 0) {
        struct stat st;
        assert_int_equal(stat(path, &st), 0);
        assert_int_equal(truncate(path, (off_t)(st.st_size * keep)), 0);
    }
}

static size_t count_lines(const char *text)
{
    size_t n = 0;
    for (; *text; text++)
        n += *text == '\n';
    return n;
}

static void test_truncated_jpeg_shim(void **state)
{
    (void)state;
    char whole[1100], cut[1100], msg[512];
    fxt_tmp_path_copy(whole, sizeof whole, "whole.jpg");
    fxt_tmp_path_copy(cut, sizeof cut, "cut.jpg");
    write_image(whole, 0);
    write_image(cut, 0.5);
    uint32_t w = 0, h = 0;
    float *rgb = NULL;
    strcpy(msg, "stale");
    assert_int_equal(scene_image_read_rgb(whole, &w, &h, &rgb, msg, sizeof msg), 0);
    assert_string_equal(msg, "");
    free(rgb);
    rgb = NULL;
    assert_int_equal(scene_image_read_rgb(cut, &w, &h, &rgb, msg, sizeof msg), 0);
    assert_non_null(rgb);
    assert_int_equal(w, 64);
    assert_int_equal(h, 64);
    assert_non_null(strstr(msg, cut));
    assert_non_null(strstr(msg, "truncated"));
    assert_null(strchr(msg, '\n'));
    free(rgb);
}

/* The JSON scene: a textured quad (OBJ with UVs) and a light; its texture named by the caller. */
static void write_scene(const char *json, const char *obj, const char *texture)
{
    FILE *f = fopen(obj, "w");
    assert_non_null(f);
    fputs("v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 1 0\n"
          "f 1/1/1 3/3/1 2/2/1\nf 1/1/1 4/4/1 3/3/1\n",
          f);
    fclose(f);
    f = fopen(json, "w");
    assert_non_null(f);
    fprintf(f,
            "{\"version\": 1, \"meshes\": [{\"file\": \"%s\", \"material\": {\"texture\": \"%s\"}}],\n"
            " \"lights\": [{\"type\": \"directional\", \"direction\": [0, -1, 0], \"intensity\": 1}]}\n",
            obj, texture);
    fclose(f);
}

static void test_truncated_textures_cli(void **state)
{
    (void)state;
    char json[1100], obj[1100], jpg[1100], png[1100], args[4096], out[8192], err[4096];
    fxt_tmp_path_copy(json, sizeof json, "textured.json");
    fxt_tmp_path_copy(obj, sizeof obj, "quad.obj");
    fxt_tmp_path_copy(jpg, sizeof jpg, "cut_texture.jpg");
    fxt_tmp_path_copy(png, sizeof png, "cut_texture.png");

    /* A truncated JPEG: loads, one warning line naming the file. */
    write_image(jpg, 0.5);
    write_scene(json, obj, jpg);
    snprintf(args, sizeof args, "scene-info '%s'", json);
    err[0] = 0;
    assert_int_equal(fxt_run_cli(args, out, sizeof out, err, sizeof err), 0);
    assert_int_equal(count_lines(err), 1);
    assert_non_null(strstr(err, "warning"));
    assert_non_null(strstr(err, jpg));

    /* The whole JPEG: nothing on stderr. */
    write_image(jpg, 0);
    err[0] = 0;
    assert_int_equal(fxt_run_cli(args, out, sizeof out, err, sizeof err), 0);
    assert_string_equal(err, "");

    /* A truncated PNG: refused with one line naming the file. In the sanitizer build the child must unwind
     * allocations in full for lsan.supp's entry for OpenImageIO's leak on it to match (test_import.c), and
     * not list the suppressions it used on stderr. */
    write_image(png, 0.5);
    write_scene(json, obj, png);
    const char *asan = getenv("ASAN_OPTIONS");
    char options[512];
    snprintf(options, sizeof options, "%s%sfast_unwind_on_malloc=0", asan ? asan : "",
             asan && asan[0] ? ":" : "");
    setenv("ASAN_OPTIONS", options, 1);
    const char *lsan = getenv("LSAN_OPTIONS"); /* and without its list of the suppressions used */
    snprintf(options, sizeof options, "%s%sprint_suppressions=0", lsan ? lsan : "",
             lsan && lsan[0] ? ":" : "");
    setenv("LSAN_OPTIONS", options, 1);
    err[0] = 0;
    assert_int_equal(fxt_run_cli(args, out, sizeof out, err, sizeof err), 1);
    assert_int_equal(count_lines(err), 1);
    assert_non_null(strstr(err, png));
}

/* A model whose materials share one missing texture warns once for it (and once for another); every
 * material still counts in the repairs. It warned once per material (Assimp's MDC spider: 19 lines, one
 * texture 12 times). */
static void test_shared_missing_texture_once(void **state)
{
    (void)state;
    char obj[1100], mtl[1100], out[8192], err[4096];
    fxt_tmp_path_copy(obj, sizeof obj, "shared.obj");
    fxt_tmp_path_copy(mtl, sizeof mtl, "shared.mtl");
    FILE *f = fopen(mtl, "w");
    assert_non_null(f);
    fputs("newmtl a\nKd 1 0 0\nmap_Kd gone.png\nnewmtl b\nKd 0 1 0\nmap_Kd gone.png\n"
          "newmtl c\nKd 0 0 1\nmap_Kd other.png\n",
          f);
    fclose(f);
    f = fopen(obj, "w");
    assert_non_null(f);
    fputs("mtllib shared.mtl\nv 0 0 0\nv 1 0 0\nv 0 0 1\nv 1 0 1\nv 2 0 0\nv 2 0 1\nvt 0 0\n"
          "usemtl a\nf 1/1 3/1 2/1\nusemtl b\nf 2/1 3/1 4/1\nusemtl c\nf 2/1 4/1 5/1\n",
          f);
    fclose(f);
    err[0] = 0;
    assert_int_equal(fxt_run_clif(out, sizeof out, err, sizeof err, "scene-info '%s'", obj), 0);
    assert_int_equal(count_lines(err), 2);
    assert_non_null(strstr(err, "gone.png"));
    assert_non_null(strstr(err, "other.png"));
    assert_non_null(strstr(out, "3 textures missing"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_truncated_jpeg_shim),
        cmocka_unit_test(test_truncated_textures_cli),
        cmocka_unit_test(test_shared_missing_texture_once),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
