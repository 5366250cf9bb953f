/* The fxcache command line's refusals: every bad input (missing or unsupported files, malformed scenes and
 * traces, out-of-range options, outputs that cannot be written, memory beyond the machine) ends with exit
 * code and exactly one line on stderr naming what and where. Runs the fxcache program of this build. */
#include "fxt_cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---------------------------------------------------------------------------------------------------------
 * Bad input: non-zero exit, one line on stderr naming what is at fault */

static void test_err_missing_file(void **state)
{
    (void)state;
    expect_error(1, "scene-info /nonexistent/fxcache-no-such-scene.obj", "fxcache-no-such-scene.obj", NULL);
}

static void test_err_unsupported_format(void **state)
{
    (void)state;
    char path[1100], args[1300];
    write_file(path, sizeof path, "junk.xyz", "this is not a mesh\n\x01\x02\x03 junk junk\n");
    snprintf(args, sizeof args, "scene-info '%s'", path);
    expect_error(1, args, "junk.xyz", NULL);
}

/* Model inputs that crashed (a segfault in Assimp's pre-transform step), ran out of memory, got a misleading
 * message or printed a second line from inside Assimp: each is refused with exit code 1 and one line naming
 * the file and the problem. The Assimp test models are used where Debian's assimp-testmodels is installed. */
static void test_err_model_inputs(void **state)
{
    (void)state;
    char folder[1100], bsp[1100], models[3][1100];
    tmp_path(folder, sizeof folder, "folder.obj");
    assert_true(mkdir(folder, 0755) == 0 || access(folder, F_OK) == 0);
    write_file(bsp, sizeof bsp, "bare.bsp", "IBSP.");
    static const char *const model_names[3] = {"AC/nosurfaces.ac", "invalid/OutOfMemory.off",
                                               "OpenGEX/empty_camera.ogex"};
    for (int k = 0; k < 3; k++)
        snprintf(models[k], sizeof models[k], "/usr/share/assimp/models/%s", model_names[k]);
    bool have_models = access("/usr/share/assimp/models", R_OK) == 0;
    if (!have_models)
        print_message("SKIP (part): /usr/share/assimp/models is absent (install assimp-testmodels)\n");
    const struct {
        const char *path;
        const char *needle;
        bool assimp_model;
    } cases[] = {
        {folder, "is a directory", false},
        {bsp, "only from inside a .pk3", false},
        {models[0], "no usable triangles in the file (only 7 points and lines)", true},
        {models[1], "declares 353535235358 vertices", true},
        {models[2], "(Assimp also printed: 'nullptr returned by creating DDLNode.')", true},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        if (cases[i].assimp_model && !have_models)
            continue;
        char args[1300];
        snprintf(args, sizeof args, "scene-info '%s'", cases[i].path);
        expect_error(1, args, cases[i].path, cases[i].needle, NULL);
    }
}

static void test_err_malformed_json(void **state)
{
    (void)state;
    char path[1100], args[1300];
    /* The stray comma is on line 2, column 13. */
    write_file(path, sizeof path, "malformed.json", "{\"version\": 1,\n \"meshes\": [,]}\n");
    snprintf(args, sizeof args, "scene-info '%s'", path);
    expect_error(1, args, "malformed.json:2:13", NULL);
}

/* A glTF 2 file whose second triangle uses vertex 9 of 4: Assimp drops that face and says so only in its
 * log; the import now repeats it as a warning, and the scene keeps the one good triangle. The same file with
 * index 2 there has both triangles and no warning. */
static void test_warn_assimp_dropped_faces(void **state)
{
    (void)state;
    /* indices 0 1 2 1 3 9 (u16), then the corners (0,0,0) (1,0,0) (0,1,0) (1,1,0) */
    const char *gltf_head =
        "{\"asset\": {\"version\": \"2.0\"}, \"scene\": 0, \"scenes\": [{\"nodes\": [0]}], \"nodes\": "
        "[{\"mesh\": "
        "0}], \"meshes\": [{\"primitives\": [{\"attributes\": {\"POSITION\": 1}, \"indices\": 0}]}], "
        "\"buffers\": [{\"byteLength\": 60, \"uri\": \"data:application/octet-stream;base64,AAABAAIAAQADAA";
    const char *gltf_tail =
        "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAACAPwAAgD8AAAAA\"}], \"bufferViews\": "
        "[{\"buffer\": "
        "0, \"byteOffset\": 0, \"byteLength\": 12}, {\"buffer\": 0, \"byteOffset\": 12, \"byteLength\": "
        "48}], \"accessors\": [{\"bufferView\": 0, \"componentType\": 5123, \"count\": 6, \"type\": "
        "\"SCALAR\"}, {\"bufferView\": 1, \"componentType\": 5126, \"count\": 4, \"type\": \"VEC3\", "
        "\"min\": [0, 0, 0], \"max\": [1, 1, 0]}]}\n";
    char text[2048], path[1100];
    for (int bad = 0; bad < 2; bad++) {
        snprintf(text, sizeof text, "%s%s%s", gltf_head, bad ? "kA" : "IA", gltf_tail);
        write_file(path, sizeof path, bad ? "dropped.gltf" : "whole.gltf", text);
        assert_int_equal(run("scene-info '%s' --json", path), 0);
        json_t *root = parse_json_text(out_buf);
        assert_int_equal(json_integer_value(json_object_get(root, "triangles")), bad ? 1 : 2);
        json_decref(root);
        if (bad)
            assert_contains(err_buf,
                            "dropped.gltf: Assimp dropped geometry while reading it: 'Some faces had "
                            "out-of-range indices. Those faces were dropped.'");
        else if (strstr(err_buf, "dropped geometry"))
            fail_msg("a whole file warned: %s", err_buf);
    }
}

static void test_err_nan_vertex(void **state)
{
    (void)state;
    char path[1100], args[1300];
    write_file(path, sizeof path, "nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    snprintf(args, sizeof args, "scene-info '%s'", path);
    expect_error(1, args, "vertex 0", "non-finite", NULL);
}

/* Every scene error names the file (docs/SCENE_FORMAT.md "Errors"); a NaN in a mesh file given directly must
 * say which file, as it does when the same mesh comes through a JSON scene. */
static void test_err_nan_vertex_names_file(void **state)
{
    (void)state;
    char path[1100], args[1300];
    write_file(path, sizeof path, "nan2.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n");
    snprintf(args, sizeof args, "scene-info '%s'", path);
    expect_error(1, args, "vertex 1", "nan2.obj", NULL);
}

static void test_err_density(void **state)
{
    (void)state;
    expect_error(2, "scene-info --density 0", "--density", "'0'", NULL);
    expect_error(2, "scene-info --density abc", "--density", "'abc'", NULL);
    expect_error(2, "render --density -1", "--density", "'-1'", NULL);
}

static void test_err_res(void **state)
{
    (void)state;
    expect_error(2, "render --res 0x10", "--res", "'0x10'", NULL);
    expect_error(2, "render --res 100000x10", "--res", "'100000x10'", NULL);
    expect_error(2, "sim --res 64x", "--res", "'64x'", NULL);
    expect_error(2, "sim --res 8193x8", "--res", "'8193x8'", NULL);
    expect_error(2, "sim --res '64x 36'", "--res", "'64x 36'", NULL); /* sscanf's %llu skipped the space */
    expect_error(2, "sim --res 64x+36", "--res", "'64x+36'", NULL);
    expect_error(2, "render --res 64x36x", "--res", "'64x36x'", NULL);
    expect_error(2, "sim --probe-rays 0", "--probe-rays", "'0'", NULL);
    expect_error(2, "sim --probe-cell -1", "--probe-cell", "'-1'", NULL);
    expect_error(2, "sim --probe-cell nan", "--probe-cell", "'nan'", NULL);
    expect_error(2, "sim --probe-cell 1e-9", "--probe-cell", "'1e-9'", NULL);
    expect_error(2, "sim --probe-hysteresis 1", "--probe-hysteresis", "'1'", NULL);
    expect_error(2, "sim --probe-blend fast", "--probe-blend", "'fast'", "adaptive or plain", NULL);
    expect_error(2, "sim --probe-budget 0", "--probe-budget", "'0'", NULL);
    expect_error(2, "sim --indirect-block 0", "--indirect-block", "'0'", NULL);
    expect_error(2, "sim --indirect-block 3", "--indirect-block", "'3'", "1, 2 or 4", NULL);
    expect_error(2, "sim --indirect-block 8", "--indirect-block", "'8'", NULL);
    expect_error(2, "serve --indirect-block x", "--indirect-block", "'x'", NULL);
}

static void test_err_fov(void **state)
{
    (void)state;
    expect_error(2, "render --fov 0", "--fov", "'0'", NULL);
    expect_error(2, "render --fov 180", "--fov", "'180'", NULL);
}

static void test_err_viewers(void **state)
{
    (void)state;
    expect_error(2, "sim --viewers 0", "--viewers", "'0'", NULL);
    expect_error(2, "sim --viewers 65", "--viewers", "'65'", NULL);
    expect_error(2, "sim --viewers", "--viewers", NULL);
}

static void test_err_frames(void **state)
{
    (void)state;
    expect_error(2, "sim --frames 0", "--frames", "'0'", NULL);
}

static void test_err_bias(void **state)
{
    (void)state;
    expect_error(2, "sim --bias foo=1", "--bias", "foo", NULL);
    expect_error(2, "sim --bias ao=99", "--bias", "99", NULL);
    expect_error(2, "sim --bias shadow=-5", "--bias", "-5", NULL);
}

static void test_err_effects(void **state)
{
    (void)state;
    expect_error(2, "sim --effects bogus", "--effects", "bogus", NULL);
    expect_error(2, "sim --effects shadow,bogus", "--effects", "bogus", NULL);
}

static void test_err_camera(void **state)
{
    (void)state;
    expect_error(2, "sim --camera nowhere", "--camera", "nowhere", NULL);
}

static void test_err_views_without_out(void **state)
{
    (void)state;
    expect_error(2, "sim --views --res 8x8 --frames 1", "--views", "--out", NULL);
}

static void test_err_unknown_option(void **state)
{
    (void)state;
    expect_error(2, "sim --bogus-option", "--bogus-option", NULL);
    expect_error(2, "render --bogus-option", "--bogus-option", NULL);
    expect_error(2, "scene-info --bogus-option", "--bogus-option", NULL);
}

static void test_err_trace_bad_line(void **state)
{
    (void)state;
    char path[1100], args[1300];
    write_file(path, sizeof path, "short.trace", "fxcache-trace 1\n0 1 2 3 4\n");
    snprintf(args, sizeof args, "sim --trace '%s' --res 8x8 --quiet", path);
    expect_error(1, args, "short.trace:2:", "8 numbers", NULL);
}

static void test_err_trace_newer_version(void **state)
{
    (void)state;
    char path[1100], args[1300];
    write_file(path, sizeof path, "newer.trace", "fxcache-trace 99\n0 0 1 0 0 0 -1 60\n");
    snprintf(args, sizeof args, "sim --trace '%s' --res 8x8 --quiet", path);
    expect_error(1, args, "newer.trace:1:", "99", NULL);
}

/* A trace camera 1e30 m out (valid as a trace: the format has no scene) is refused against the scene, naming
 * the file and the camera, by every command that replays traces; it aborted inside Embree before (its rays
 * overflowed). The second camera of a trace that starts fine is named as such. */
static void test_err_trace_camera_beyond_reach(void **state)
{
    (void)state;
    char path[1100], out[1100], args[2400];
    write_file(path, sizeof path, "far.trace",
               "fxcache-trace 1\n0 0 1 3 0 0 -1 60\n0.5 1e30 2 3 -1e29 0 0 60\n");
    tmp_path(out, sizeof out, "far_out");
    const char *cmds[] = {"sim", "ref", "report"};
    for (int i = 0; i < 3; i++) {
        snprintf(args, sizeof args, "%s --trace '%s' --res 8x8 --quiet --out '%s'", cmds[i], path, out);
        if (i == 0)
            snprintf(args, sizeof args, "sim --trace '%s' --res 8x8 --quiet", path);
        expect_error(1, args, "far.trace: camera 2", "1e+30 m", "1e+13", NULL);
    }
}

/* Traces lasting more frames than a run may have (1e9 s at 30 fps) are refused when --frames is not given,
 * naming the trace; they were cut at 1,000,000 frames without a word (a run of hours replaying a fraction of
 * the trace). With --frames the first frames are rendered as asked. */
static void test_err_traces_too_long(void **state)
{
    (void)state;
    char path[1100], out[1100], args[2400];
    write_file(path, sizeof path, "long.trace", "fxcache-trace 1\n0 0 1 3 0 0 -1 60\n1e9 0 1 3 0 0 -1 60\n");
    tmp_path(out, sizeof out, "long_out");
    const char *cmds[] = {"sim", "ref"};
    for (int i = 0; i < 2; i++) {
        snprintf(args, sizeof args, "%s --trace '%s' --res 8x8 --quiet --out '%s'", cmds[i], path, out);
        expect_error(2, args, "long.trace ends 1e+09 s after the traces' start", "3e+10 frames at 30 fps",
                     "--frames N", NULL);
    }
    snprintf(args, sizeof args, "sim --trace '%s' --res 8x8 --quiet --frames 2 --threads 1", path);
    assert_int_equal(run("%s", args), 0);
}

static void test_err_traces_and_viewers_disagree(void **state)
{
    (void)state;
    char path[1100], args[1300];
    write_file(path, sizeof path, "one.trace", "fxcache-trace 1\n0 0 1 3 0 0 -1 60\n");
    snprintf(args, sizeof args, "sim --trace '%s' --viewers 2 --res 8x8 --quiet", path);
    expect_error(2, args, "--viewers", NULL);
}

/* The machine's physical memory in MiB as /proc/meminfo tells it (MemTotal), a second source beside the
 * sysconf() figure fxcache prints; 0 when unreadable. */
static unsigned long long meminfo_total_mib(void)
{
    FILE *f = fopen("/proc/meminfo", "r");
    if (!f)
        return 0;
    char line[256];
    unsigned long long kib = 0;
    while (fgets(line, sizeof line, f))
        if (sscanf(line, "MemTotal: %llu kB", &kib) == 1)
            break;
    fclose(f);
    return kib / 1024;
}

/* Memory options beyond the machine's physical memory are refused before anything is loaded or allocated,
 * with the figures: --pool-mb 65536 and 64 viewers of 8192x8192 (140 GiB of per-pixel buffers) were accepted
 * and tried to allocate them. A case is skipped on a machine that has the memory. */
/* An output file that cannot be written is refused before the scene loads: one line naming the path and
 * the option, exit 1; a --summary inside --out's folder (created by the run) is fine. */
static void test_err_output_paths_checked_first(void **state)
{
    (void)state;
    char dir[1100], args[2400], summary[1200];
    tmp_path(dir, sizeof dir, "no_such_folder_for_stats");
    snprintf(args, sizeof args, "sim --frames 1 --res 8x8 --viewers 1 --quiet --stats '%s/s.jsonl'", dir);
    expect_error(1, args, "--stats", "its folder does not exist", NULL);
    tmp_path(dir, sizeof dir, "");
    snprintf(args, sizeof args, "serve --summary '%s' --port 0", dir);
    expect_error(1, args, "--summary", "is a directory", NULL);
    tmp_path(dir, sizeof dir, "paths_out");
    snprintf(summary, sizeof summary, "%s/inside/summary.json", dir);
    snprintf(args, sizeof args,
             "sim --frames 1 --res 8x8 --viewers 1 --quiet --out '%s/inside/' --summary '%s'", dir, summary);
    mkdir(dir, 0755);
    assert_int_equal(run("%s", args), 0);
    assert_int_equal(access(summary, F_OK), 0);
    /* --stats and --summary naming one file (the summary overwrote the statistics without a word): the same
     * path, the same name spelt through another path to its folder (not there yet), an existing file. */
    snprintf(args, sizeof args,
             "sim --frames 1 --res 8x8 --viewers 1 --quiet --stats '%s/same.json' --summary '%s/./same.json'",
             dir, dir);
    expect_error(1, args, "--stats and --summary name the same file", NULL);
    snprintf(args, sizeof args, "serve --port 0 --stats '%s' --summary '%s'", summary, summary);
    expect_error(1, args, "--stats and --summary name the same file", NULL);
    snprintf(args, sizeof args,
             "sim --frames 1 --res 8x8 --viewers 1 --quiet --stats '%s' --summary '%s/./%s'", summary, dir,
             "inside/summary.json");
    expect_error(1, args, "--stats and --summary name the same file", NULL);
}

/* An output folder that exists as a file is refused before the run, in one line: sim ran the whole run and
 * then failed on every image (a line each); the others the same way. */
static void test_err_output_folder_is_a_file(void **state)
{
    (void)state;
    char path[1100], args[2400];
    write_file(path, sizeof path, "a_file", "not a folder\n");
    const char *cmds[] = {"sim --frames 1 --res 8x8 --viewers 1 --quiet --out",
                          "sim --frames 1 --res 8x8 --viewers 1 --quiet --record",
                          "ref --frames 1 --res 8x8 --viewers 1 --quiet --out",
                          "report --quick --only default --quiet --out", "serve --port 0 --record"};
    for (size_t i = 0; i < sizeof cmds / sizeof cmds[0]; i++) {
        snprintf(args, sizeof args, "%s '%s'", cmds[i], path);
        expect_error(1, args, "cannot create folder", "a_file: a file of that name is in the way", NULL);
    }
}

static void test_err_memory_beyond_physical(void **state)
{
    (void)state;
    unsigned long long total_mib = meminfo_total_mib();
    if (total_mib == 0) {
        print_message("SKIP: /proc/meminfo is unreadable\n");
        skip();
    }
    char out_dir[1024], views_args[1400], total[64];
    tmp_path(out_dir, sizeof out_dir, "memory_views_out");
    snprintf(views_args, sizeof views_args, "sim --viewers 64 --res 8192x8192 --views --out '%s' --quiet",
             out_dir);
    snprintf(total, sizeof total, "this machine's %llu MiB of physical memory", total_mib);
    const struct {
        const char *args;
        unsigned long long at_least_mib; /* a lower bound of what the options need (skip above it) */
        const char *needle;
    } cases[] = {
        {"sim --pool-mb 65536 --quiet", 65536, "block pools (65536 MiB)"},
        {"sim --viewers 64 --res 8192x8192 --quiet", 64ull * 8192 * 8192 * 36 / 1048576,
         "64 viewers, 4294967296 pixels (147456 MiB)"},
        {views_args, 64ull * 8192 * 8192 * 48 / 1048576, "64 viewers, 4294967296 pixels (196608 MiB)"},
        {"sim --no-cache --pool-mb 65536 --viewers 64 --res 8192x8192 --quiet",
         64ull * 8192 * 8192 * 36 / 1048576, "block pools (0 MiB)"},
    };
    unsigned checked = 0;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        if (total_mib >= cases[i].at_least_mib) {
            print_message("SKIP: '%s' fits in this machine's %llu MiB\n", cases[i].args, total_mib);
            continue;
        }
        expect_error(2, cases[i].args, cases[i].needle, total, "lower --pool-mb", NULL);
        checked++;
    }
    if (checked == 0)
        skip();
    assert_int_equal(access(out_dir, F_OK), -1); /* refused before --out was created */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_err_missing_file),
        cmocka_unit_test(test_warn_assimp_dropped_faces),
        cmocka_unit_test(test_err_unsupported_format),
        cmocka_unit_test(test_err_model_inputs),
        cmocka_unit_test(test_err_malformed_json),
        cmocka_unit_test(test_err_nan_vertex),
        cmocka_unit_test(test_err_nan_vertex_names_file),
        cmocka_unit_test(test_err_density),
        cmocka_unit_test(test_err_res),
        cmocka_unit_test(test_err_fov),
        cmocka_unit_test(test_err_viewers),
        cmocka_unit_test(test_err_frames),
        cmocka_unit_test(test_err_bias),
        cmocka_unit_test(test_err_effects),
        cmocka_unit_test(test_err_camera),
        cmocka_unit_test(test_err_views_without_out),
        cmocka_unit_test(test_err_unknown_option),
        cmocka_unit_test(test_err_trace_bad_line),
        cmocka_unit_test(test_err_trace_newer_version),
        cmocka_unit_test(test_err_trace_camera_beyond_reach),
        cmocka_unit_test(test_err_traces_too_long),
        cmocka_unit_test(test_err_traces_and_viewers_disagree),
        cmocka_unit_test(test_err_memory_beyond_physical),
        cmocka_unit_test(test_err_output_paths_checked_first),
        cmocka_unit_test(test_err_output_folder_is_a_file),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
