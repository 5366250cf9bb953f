/* libFuzzer harness of the viewer trace parser (proto/proto_trace.c, shared by `fxcache sim --trace` and the
 * viewer client): proto_trace_parse on the input, from a buffer of exactly its size. A trace that parses
 * must hold what proto_trace.h promises (at least one camera, finite non-decreasing times, finite
 * positions, a non-zero direction, a field of view in (0, 180), a resolution within the limit); one that
 * does not must leave *out empty and give a one-line message. */
#include "proto_trace.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char *text = malloc(size ? size : 1);
    if (!text)
        return 0;
    memcpy(text, data, size);
    proto_trace t;
    char err[512] = "";
    fxc_result rc = proto_trace_parse(text, size, "fuzz.trace", &t, err, sizeof err);
    free(text);
    if (rc != FXC_OK) {
        if (t.count != 0 || t.cameras || t.times || err[0] == '\0' || strchr(err, '\n'))
            abort();
        return 0;
    }
    if (t.count == 0 || t.width > PROTO_TRACE_MAX_SIDE || t.height > PROTO_TRACE_MAX_SIDE ||
        (t.version != 1 && t.version != 2))
        abort();
    for (uint32_t i = 0; i < t.count; i++) {
        const proto_trace_camera *c = &t.cameras[i];
        if (!isfinite(t.times[i]) || (i > 0 && t.times[i] < t.times[i - 1]))
            abort();
        if (!(c->fov_deg > 0.0f && c->fov_deg < 180.0f))
            abort();
        if (c->direction[0] == 0.0 && c->direction[1] == 0.0 && c->direction[2] == 0.0)
            abort();
        for (int k = 0; k < 3; k++)
            if (!isfinite(c->position[k]) || !isfinite(c->direction[k]))
                abort();
    }
    proto_trace_release(&t);
    return 0;
}
