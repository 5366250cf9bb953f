/* The scene library's error reporting, apart from the builder so that the import checks
 * (scene_import_check.c) link alone into their libFuzzer harness (tests/fuzz/fuzz_import_check.c). */
#include "scene_internal.h"

#include <stdio.h>

const char *scene_strerror(scene_result code)
{
    switch (code) {
#define FXC_X(name, value, str)                                                                              \
    case name: return str;
        SCENE_RESULTS(FXC_X)
#undef FXC_X
    }
    return "unknown error";
}

scene_result scene__fail(scene_error *err, scene_result code, const char *fmt, ...)
{
    if (err) {
        va_list ap;
        va_start(ap, fmt);
        err->code = code;
        vsnprintf(err->msg, sizeof err->msg, fmt, ap);
        va_end(ap);
    }
    return code;
}
