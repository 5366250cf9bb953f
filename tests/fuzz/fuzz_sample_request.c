/* libFuzzer harness of the server's side of a sample request (CONVENTIONS.md 10): what `fxcache serve` does
 * with the bytes a client sends to ask for pixels (server/net/net.c, on_sample_request, take_request and
 * stage_answers). The input is decoded (proto_decode); a sample request is checked against the server's
 * default limits and converted (net_samples.c, as the network thread does), handed to a sparse viewer of a
 * loop on the embedded scene (srv_viewer_set_pixels, as the frame thread does) and rendered with shadows, AO
 * and probes; then every requested pixel must have its answer in the rendered list (the answer's staging
 * reads it with srv_viewer_pixel_index), and the answer must encode. One loop serves every input, as one
 * server serves every request. Decoding and the checks are built here by clang (coverage, sanitizers); the
 * engine comes from the normal build, uninstrumented. */
#include "engine.h"
#include "effects.h"
#include "net_samples.h"
#include "proto.h"
#include "scene.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* serve's defaults: --max-samples 65536, --max-res 3840x2160. */
static const srv_sample_limits limits = {.max_samples = 65536, .max_width = 3840, .max_height = 2160};

static scene *world;
static scene_rt *rt;
static srv_loop *loop;
static srv_viewer_id sparse;
static uint32_t *pixels; /* the network thread's copy of a request */
static uint8_t *answer;  /* the answer's samples */
static uint8_t *message; /* the encoded answer */
static size_t message_cap;

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    scene_error err;
    world = scene_create_default(NULL, &err);
    rt = world ? scene_rt_create(world, NULL, &err) : NULL;
    if (!rt)
        abort();
    srv_loop_desc d = {.s = world, .rt = rt, .threads = 1, .seed = 1};
    uint32_t n = 0;
    const fx_effect *const *registry = fx_registry(&n);
    const char *const names[] = {"shadow", "ao", "probes"};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        int32_t e = fx_find(registry, n, names[i]);
        if (e < 0)
            abort();
        d.effect_on[e] = true;
    }
    char why[256];
    if (srv_loop_create(&d, &loop, why, sizeof why) != FXC_OK ||
        srv_viewer_add(loop, &(srv_viewer_desc){.max_pixels = limits.max_samples}, &sparse) != FXC_OK)
        abort();
    pixels = malloc(limits.max_samples * sizeof *pixels);
    answer = malloc((size_t)limits.max_samples * PROTO_SAMPLE_BYTES);
    message_cap = PROTO_HEADER_BYTES + 256 + (size_t)limits.max_samples * PROTO_SAMPLE_BYTES;
    message = malloc(message_cap);
    if (!pixels || !answer || !message)
        abort();
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    proto_msg m;
    if (proto_decode(data, size, &m) != FXC_OK || m.type != PROTO_SAMPLE_REQUEST)
        return 0;
    const proto_sample_request *q = &m.u.sample_request;
    srv_camera camera;
    char why[256];
    why[0] = 0;
    fxc_result r = srv_sample_request_check(world, &limits, q, &camera, why, sizeof why);
    if (r != FXC_OK) {
        if (!why[0] || strchr(why, '\n'))
            abort(); /* a refusal says why, in one line */
        return 0;
    }
    srv_sample_request_pixels(q, pixels);
    /* Checked: the engine must take it (take_request calls a refusal here a bug). */
    if (srv_viewer_set_pixels(loop, sparse, &camera, q->width, q->height, pixels, q->count, NULL) != FXC_OK)
        abort();
    srv_frame_stats st;
    if (srv_loop_frame(loop, &st) != FXC_OK)
        abort();
    const uint8_t *image = srv_viewer_image(loop, sparse);
    const float *depth = srv_viewer_depth(loop, sparse);
    if (!image || !depth)
        abort();
    for (uint32_t k = 0; k < q->count; k++) {
        uint32_t x = pixels[k] & 0xFFFFu, y = pixels[k] >> 16;
        uint32_t at = srv_viewer_pixel_index(loop, sparse, x, y);
        if (at == UINT32_MAX)
            abort(); /* every requested pixel was rendered */
        /* As stage_answers: the wire wants a depth > 0. */
        proto_sample sample = {
            .x = (uint16_t)x, .y = (uint16_t)y, .depth = depth[at] > 0.0f ? depth[at] : FLT_MIN};
        memcpy(sample.rgb, image + 3 * (size_t)at, 3);
        proto_sample_put(answer, k, &sample);
    }
    proto_msg a = {.type = PROTO_SAMPLES};
    a.u.samples = (proto_samples){.request = q->request,
                                  .camera = q->camera,
                                  .width = q->width,
                                  .height = q->height,
                                  .count = q->count,
                                  .samples = answer};
    fxc_result encoded = FXC_OK;
    if (proto_encode(&a, message, message_cap, &encoded) == 0 || encoded != FXC_OK)
        abort(); /* the answer to a request the server took is a valid message */
    return 0;
}
