/* Writes the seed corpus of fuzz_proto: one valid message of every type, a hello for every colour codec,
 * a camera with and without its predicted pose, and a frame for every colour codec x depth codec pair with
 * real payloads of a small image, a sample request and its answer. Usage: make_corpus_proto DIR (the files are overwritten). */
#include "proto.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { W = 8, H = 6 };

/* Encodes m and writes it to dir/name; exits on any failure. */
static void write_message(const char *dir, const char *name, const proto_msg *m)
{
    static uint8_t buf[1 << 16];
    fxc_result result = FXC_OK;
    size_t len = proto_encode(m, buf, sizeof buf, &result);
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = len ? fopen(path, "wb") : NULL;
    if (!f || fwrite(buf, 1, len, f) != len || fclose(f) != 0) {
        fprintf(stderr, "make_corpus_proto: %s: %s\n", path, len ? "cannot write" : fxc_strerror(result));
        exit(1);
    }
}

static proto_pose pose(void)
{
    proto_pose p = {{-4.2, 2.0, 3.4}, {6.7f, -1.6f, -3.2f}, 60.0f};
    return p;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: make_corpus_proto DIR\n");
        return 2;
    }
    const char *dir = argv[1];
    proto_msg m;
    for (uint32_t codec = 0; codec < PROTO_CODEC_COUNT; codec++) {
        memset(&m, 0, sizeof m);
        m.type = PROTO_HELLO;
        m.u.hello = (proto_hello){.name = "alice",
                                  .width = 640,
                                  .height = 360,
                                  .fov_deg = 60.0f,
                                  .codec = (uint8_t)codec,
                                  .jpeg_quality = codec == PROTO_CODEC_JPEG ? 85 : 0,
                                  .depth = (uint8_t)(codec * 16),
                                  .token = "secret",
                                  .strategy = ""};
        char name[64];
        snprintf(name, sizeof name, "hello-%s", proto_codec_name(codec));
        write_message(dir, name, &m);
    }
    memset(&m, 0, sizeof m);
    m.type = PROTO_WELCOME;
    m.u.welcome = (proto_welcome){.viewer_id = 1,
                                  .name = "viewer_01",
                                  .fps = 30.0f,
                                  .bounds_min = {-5, 0, -5},
                                  .bounds_max = {5, 3, 5},
                                  .camera = pose(),
                                  .max_camera_rate = 120};
    write_message(dir, "welcome", &m);
    memset(&m, 0, sizeof m);
    m.type = PROTO_CAMERA;
    m.u.camera = (proto_camera){.sequence = 1, .time = 0.5, .pose = pose()};
    write_message(dir, "camera", &m);
    m.u.camera.has_predicted = true;
    m.u.camera.predicted_time = 0.55;
    m.u.camera.predicted = pose();
    write_message(dir, "camera-predicted", &m);

    /* A small image with a gradient, and depths with a sky (+infinity) corner. */
    uint8_t rgb[W * H * 3];
    float depth[W * H];
    for (int i = 0; i < W * H; i++) {
        rgb[3 * i] = (uint8_t)(i * 5);
        rgb[3 * i + 1] = (uint8_t)(255 - i * 3);
        rgb[3 * i + 2] = (uint8_t)(i % W * 30);
        depth[i] = i == 0 ? INFINITY : 0.5f + 0.25f * (float)i;
    }
    static uint8_t color[1 << 14], depth_bytes[1 << 14];
    static const uint32_t depths[3] = {PROTO_DEPTH_NONE, PROTO_DEPTH_HALF, PROTO_DEPTH_FLOAT};
    for (uint32_t codec = 0; codec < PROTO_CODEC_COUNT; codec++)
        for (int d = 0; d < 3; d++) {
            size_t color_size = 0, depth_size = 0;
            if (proto_color_encode(codec, 80, rgb, W, H, color, sizeof color, &color_size) != FXC_OK ||
                (depths[d] != PROTO_DEPTH_NONE &&
                 proto_depth_encode(depths[d], depth, W, H, depth_bytes, sizeof depth_bytes, &depth_size) !=
                     FXC_OK)) {
                fprintf(stderr, "make_corpus_proto: cannot encode the payloads\n");
                return 1;
            }
            memset(&m, 0, sizeof m);
            m.type = PROTO_FRAME;
            m.u.frame = (proto_frame){.frame = 7,
                                      .camera_sequence = 1,
                                      .camera = pose(),
                                      .width = W,
                                      .height = H,
                                      .codec = (uint8_t)codec,
                                      .depth = (uint8_t)depths[d],
                                      .stats = {100, 10, W * H, 3, 0, 16.7f, 0.4f},
                                      .color = color,
                                      .color_bytes = (uint32_t)color_size,
                                      .depth_data = depth_size ? depth_bytes : NULL,
                                      .depth_bytes = (uint32_t)depth_size};
            char name[64];
            snprintf(name, sizeof name, "frame-%s-%s", proto_codec_name(codec),
                     depths[d] == PROTO_DEPTH_NONE   ? "nodepth"
                     : depths[d] == PROTO_DEPTH_HALF ? "half"
                                                     : "float");
            write_message(dir, name, &m);
        }
    memset(&m, 0, sizeof m);
    m.type = PROTO_STATS_REQUEST;
    write_message(dir, "stats-request", &m);
    static const char json[] = "{\"frames\": 120, \"viewers\": 2, \"hit_rate\": 0.97}";
    m.type = PROTO_STATS;
    m.u.stats = (proto_stats){json, (uint32_t)strlen(json)};
    write_message(dir, "stats", &m);
    memset(&m, 0, sizeof m);
    m.type = PROTO_ERROR;
    m.u.error.code = FXC_ERR_PROTOCOL;
    strcpy(m.u.error.reason, "camera before hello");
    write_message(dir, "error", &m);
    memset(&m, 0, sizeof m);
    m.type = PROTO_BYE;
    strcpy(m.u.bye.reason, "client closing");
    write_message(dir, "bye", &m);

    /* A sample request for a few pixels of the W x H image, and its answer (colour and depth of the image
     * above at those pixels, the first one the sky). */
    static const uint16_t wanted[5][2] = {{0, 0}, {W - 1, H - 1}, {3, 2}, {3, 2}, {0, H - 1}};
    uint8_t pixels[5 * PROTO_REQUEST_PIXEL_BYTES], samples[5 * PROTO_SAMPLE_BYTES];
    for (uint32_t i = 0; i < 5; i++) {
        proto_request_pixel_put(pixels, i, wanted[i][0], wanted[i][1]);
        uint32_t at = wanted[i][1] * W + wanted[i][0];
        proto_sample s = {
            wanted[i][0], wanted[i][1], {rgb[3 * at], rgb[3 * at + 1], rgb[3 * at + 2]}, depth[at]};
        proto_sample_put(samples, i, &s);
    }
    memset(&m, 0, sizeof m);
    m.type = PROTO_SAMPLE_REQUEST;
    m.u.sample_request = (proto_sample_request){
        .request = 3, .camera = pose(), .width = W, .height = H, .count = 5, .pixels = pixels};
    write_message(dir, "sample-request", &m);
    memset(&m, 0, sizeof m);
    m.type = PROTO_SAMPLES;
    m.u.samples = (proto_samples){
        .request = 3, .frame = 8, .camera = pose(), .width = W, .height = H, .count = 5, .samples = samples};
    write_message(dir, "samples", &m);
    return 0;
}
