/* libFuzzer harness of the JSON scene reader (scene/scene_json.c, docs/SCENE_FORMAT.md): the input is written as
 * a .json file and loaded with scene_load(), as `fxcache --scene FILE.json` does. The reader (built here by
 * clang, with coverage) must refuse with one message or load, never crash, hang or allocate beyond what the
 * input justifies. Meshes it names resolve beside it, in a private folder that holds one small triangle
 * (tri.obj) and one small texture (tex.png), so seeds can reach the mesh, transform and material paths. The
 * rest of the scene library (builder, import, islands) is linked from the normal build, uninstrumented. */
#include "scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static char folder[64], path[96];

/* The private folder goes at exit (libFuzzer exits through exit() at the end of a run). */
static void remove_folder(void)
{
    char file[128];
    snprintf(file, sizeof file, "%s/tri.obj", folder);
    unlink(file);
    unlink(path);
    rmdir(folder);
}

static void make_folder(void)
{
    snprintf(folder, sizeof folder, "/tmp/fxc_fuzz_json_XXXXXX");
    if (!mkdtemp(folder))
        abort();
    char file[128];
    snprintf(file, sizeof file, "%s/tri.obj", folder);
    FILE *f = fopen(file, "w");
    if (!f)
        abort();
    fputs("v 0 0 0\nv 1 0 0\nv 0 0 1\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 3/3 2/2\n", f);
    fclose(f);
    snprintf(path, sizeof path, "%s/scene.json", folder);
    atexit(remove_folder);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!folder[0])
        make_folder();
    FILE *f = fopen(path, "wb");
    if (!f)
        abort();
    fwrite(data, 1, size, f);
    fclose(f);
    scene_error err = {0};
    scene *s = scene_load(path, NULL, &err);
    if (!s && !err.msg[0] && err.code == SCENE_OK)
        abort(); /* a refusal always says why */
    scene_free(s);
    return 0;
}
