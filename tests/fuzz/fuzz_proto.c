/* libFuzzer harness of the wire format (CONVENTIONS.md 10): proto_decode on the input; a message that decodes
 * must encode back to the same bytes; a frame of at most 2^20 pixels also has its colour and depth payloads
 * decoded into buffers of exactly the size they claim, so the sanitizers see any write past them. */
#include "proto.h"

#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    proto_msg m;
    if (proto_decode(data, size, &m) != FXC_OK)
        return 0;
    uint8_t *again = malloc(size);
    if (!again || proto_encode(&m, again, size, NULL) != size || memcmp(again, data, size) != 0)
        abort(); /* the encoding is canonical: what decodes, re-encodes to the same bytes */
    free(again);
    if (m.type != PROTO_FRAME || (uint64_t)m.u.frame.width * m.u.frame.height > (1u << 20))
        return 0;
    const proto_frame *f = &m.u.frame;
    size_t pixels = (size_t)f->width * f->height;
    uint8_t *rgb = malloc(pixels * 3);
    float *depth = malloc(pixels * sizeof(float));
    if (rgb && depth) {
        proto_color_decode(f->codec, f->color, f->color_bytes, f->width, f->height, rgb);
        if (f->depth != PROTO_DEPTH_NONE)
            proto_depth_decode(f->depth, f->depth_data, f->depth_bytes, f->width, f->height, depth);
    }
    free(depth);
    free(rgb);
    return 0;
}
