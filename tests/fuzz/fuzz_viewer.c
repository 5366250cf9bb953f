/* libFuzzer harness of the viewer's side of the wire (CONVENTIONS.md 10): what fxcache-viewer does with the
 * bytes a server sends when it reprojects (view_display.c). A frame of at most 2^16 pixels is decoded into
 * buffers of exactly its size and inserted into a render cache (view_rc_insert_frame), a samples answer is
 * converted and inserted (view_rc_insert_samples), then the cache renders a frame for a fixed camera; all of
 * it must refuse with a code or succeed, never crash, hang or read past a buffer. The seeds are the wire
 * format's (corpus_proto). */
#include "proto.h"
#include "rcache.h"

#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static view_rc_camera camera_of(const proto_pose *pose)
{
    view_rc_camera cam;
    for (int k = 0; k < 3; k++) {
        cam.position[k] = pose->position[k];
        cam.direction[k] = pose->direction[k];
    }
    cam.fov_deg = pose->fov_deg;
    return cam;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    proto_msg m;
    if (proto_decode(data, size, &m) != FXC_OK || (m.type != PROTO_FRAME && m.type != PROTO_SAMPLES))
        return 0;
    view_rc *rc = NULL;
    view_rc_desc desc = {.width = 32, .height = 24, .threads = 1};
    if (view_rc_create(&desc, &rc) != FXC_OK)
        abort(); /* a valid description */
    if (m.type == PROTO_FRAME && (uint64_t)m.u.frame.width * m.u.frame.height <= (1u << 16)) {
        const proto_frame *f = &m.u.frame;
        size_t pixels = (size_t)f->width * f->height;
        uint8_t *rgb = malloc(pixels * 3);
        float *depth = malloc(pixels * sizeof(float));
        if (rgb && depth &&
            proto_color_decode(f->codec, f->color, f->color_bytes, f->width, f->height, rgb) == FXC_OK &&
            f->depth != PROTO_DEPTH_NONE &&
            proto_depth_decode(f->depth, f->depth_data, f->depth_bytes, f->width, f->height, depth) ==
                FXC_OK) {
            view_rc_camera cam = camera_of(&f->camera);
            view_rc_insert_frame(rc, &cam, f->width, f->height, rgb, depth);
        }
        free(depth);
        free(rgb);
    } else if (m.type == PROTO_SAMPLES) {
        const proto_samples *a = &m.u.samples;
        view_rc_sample *samples = malloc(((size_t)a->count + 1) * sizeof *samples);
        if (samples) {
            for (uint32_t i = 0; i < a->count; i++) {
                proto_sample s;
                proto_sample_get(a->samples, i, &s);
                samples[i] = (view_rc_sample){.x = s.x, .y = s.y, .depth = s.depth};
                memcpy(samples[i].rgb, s.rgb, 3);
            }
            view_rc_camera cam = camera_of(&a->camera);
            view_rc_insert_samples(rc, &cam, a->width, a->height, samples, a->count);
        }
        free(samples);
    }
    view_rc_camera eye = {.position = {0, 1, 4}, .direction = {0, 0, -1}, .fov_deg = 60};
    view_rc_frame out;
    view_rc_render(rc, &eye, &eye, &out);
    view_rc_destroy(rc);
    return 0;
}
