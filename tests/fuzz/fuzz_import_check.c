/* libFuzzer harness of the checks fxcache runs on a mesh file before Assimp reads it
 * (scene/scene_import_check.c: PLY, OFF, STL, ASE, X, MD5 counts and indices against the file size). Every
 * check runs on every input, from a buffer of exactly the input's size (the checks are given a length, not
 * a terminated string), so the sanitizers see any read past it; a check may accept or refuse, never crash,
 * hang or allocate beyond what the input's size justifies. */
#include "scene_internal.h"

#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const char *const formats[] = {"ply", "off", "stl", "ase", "x", "md5mesh"};
    if (size == 0) /* the importer refuses an empty file before any check */
        return 0;
    char *buf = malloc(size);
    if (!buf)
        return 0;
    memcpy(buf, data, size);
    for (size_t i = 0; i < sizeof formats / sizeof formats[0]; i++) {
        const scene_import_format *f = scene__import_format_of(formats[i]);
        scene_error err = {0};
        if (!f || !f->check)
            abort(); /* the list above names formats that have a check */
        f->check("fuzz", buf, size, &err);
    }
    free(buf);
    return 0;
}
