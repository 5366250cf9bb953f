/* The wire format tests' sample messages (fxt_proto.h). */
#include "fxt_proto.h"

#include "test_util.h"

#include <stdlib.h>
#include <string.h>

static const uint8_t frame_color[36] = {1,  2,  3,  4,  5,  6,  7,  8,  9,  10, 11, 12,
                                        13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24,
                                        25, 26, 27, 28, 29, 30, 31, 32, 33, 34, 35, 36};
static const uint8_t frame_depth[7] = {0xde, 0xad, 0xbe, 0xef, 0x00, 0x01, 0xff};
/* The request's pixels as bytes: x, y little-endian u16 each. */
const uint8_t fxt_request_pixels[12] = {0, 0, 0, 0, 0x7f, 0x02, 0xdf, 0x01, 17, 0, 200, 0};
/* Four entries, of which the edge sample uses two (an edit may raise its count to 3 without an over-read). */
static const uint8_t edge_pixels[16] = {1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
/* Two samples: (3,2) rgb 10,20,30 depth 2.5 (0x40200000); (0,0) rgb 255,0,128 depth +inf (0x7f800000). */
const uint8_t fxt_samples_bytes[24] = {3, 0, 2, 0, 10,  20, 30,  0, 0x00, 0x00, 0x20, 0x40,
                                       0, 0, 0, 0, 255, 0,  128, 0, 0x00, 0x00, 0x80, 0x7f};

static proto_pose sample_pose(double offset)
{
    proto_pose pose = {{1.5e6 + offset, -2.25, 3.0 / 7.0}, {0.25f, -1.0f, 1e-3f}, 60.0f};
    return pose;
}

/* Sample message i (valid, every field distinct from zero where it may be). */
proto_msg fxt_proto_sample(int i)
{
    proto_msg m;
    memset(&m, 0, sizeof m);
    switch (i) {
    case FXT_S_HELLO_RAW:
        m.type = PROTO_HELLO;
        m.u.hello = (proto_hello){.width = 640, .height = 360, .fov_deg = 60.0f, .codec = PROTO_CODEC_RAW};
        break;
    case FXT_S_HELLO_JPEG:
        m.type = PROTO_HELLO;
        m.u.hello = (proto_hello){.name = "alice",
                                  .width = 1920,
                                  .height = 1080,
                                  .fov_deg = 75.5f,
                                  .codec = PROTO_CODEC_JPEG,
                                  .jpeg_quality = 85,
                                  .depth = PROTO_DEPTH_HALF,
                                  .token = "secret-token",
                                  .strategy = "nearest"};
        break;
    case FXT_S_HELLO_ZSTD:
        m.type = PROTO_HELLO;
        m.u.hello = (proto_hello){.width = PROTO_MAX_SIDE,
                                  .height = 1,
                                  .fov_deg = 179.9f,
                                  .codec = PROTO_CODEC_ZSTD,
                                  .depth = PROTO_DEPTH_FLOAT};
        memset(m.u.hello.name, '~', PROTO_NAME_MAX);
        m.u.hello.name[0] = ' ';
        memset(m.u.hello.token, 'T', PROTO_TOKEN_MAX);
        memset(m.u.hello.strategy, 's', PROTO_STRATEGY_MAX);
        break;
    case FXT_S_WELCOME:
        m.type = PROTO_WELCOME;
        m.u.welcome = (proto_welcome){.viewer_id = 7,
                                      .name = "viewer_07",
                                      .fps = 30.0f,
                                      .bounds_min = {-10.5, 0.0, -1e-9},
                                      .bounds_max = {10.5, 0.0, 4.0},
                                      .camera = sample_pose(0.0),
                                      .max_camera_rate = 120};
        break;
    case FXT_S_CAMERA:
        m.type = PROTO_CAMERA;
        m.u.camera = (proto_camera){.sequence = 42, .time = 1.25, .pose = sample_pose(1.0)};
        break;
    case FXT_S_CAMERA_PREDICTED:
        m.type = PROTO_CAMERA;
        m.u.camera = (proto_camera){.sequence = 0xfffffffeu,
                                    .time = -3.5,
                                    .pose = sample_pose(2.0),
                                    .has_predicted = true,
                                    .predicted_time = 1.3,
                                    .predicted = sample_pose(3.0)};
        m.u.camera.predicted.fov_deg = 0.001f;
        break;
    case FXT_S_FRAME:
        m.type = PROTO_FRAME;
        m.u.frame = (proto_frame){.frame = 100,
                                  .camera_sequence = 42,
                                  .camera = sample_pose(4.0),
                                  .width = 4,
                                  .height = 3,
                                  .codec = PROTO_CODEC_RAW,
                                  .depth = PROTO_DEPTH_NONE,
                                  .stats = {1, 2, 3, 4, 5, 16.5f, 0.0f},
                                  .color = frame_color,
                                  .color_bytes = sizeof frame_color};
        break;
    case FXT_S_FRAME_DEPTH:
        m.type = PROTO_FRAME;
        m.u.frame = (proto_frame){.frame = 0xffffffffu,
                                  .camera_sequence = 0,
                                  .camera = sample_pose(5.0),
                                  .width = PROTO_MAX_SIDE,
                                  .height = PROTO_MAX_SIDE,
                                  .codec = PROTO_CODEC_ZSTD,
                                  .depth = PROTO_DEPTH_HALF,
                                  .stats = {UINT64_MAX, 1ull << 40, 7, 0, 1, 1e3f, 2.5f},
                                  .color = frame_color,
                                  .color_bytes = 5,
                                  .depth_data = frame_depth,
                                  .depth_bytes = sizeof frame_depth};
        break;
    case FXT_S_STATS_REQUEST: m.type = PROTO_STATS_REQUEST; break;
    case FXT_S_STATS:
        m.type = PROTO_STATS;
        m.u.stats = (proto_stats){FXT_STATS_JSON, (uint32_t)strlen(FXT_STATS_JSON)};
        break;
    case FXT_S_STATS_EMPTY: m.type = PROTO_STATS; break;
    case FXT_S_ERROR:
        m.type = PROTO_ERROR;
        m.u.error.code = FXC_ERR_UNAUTHORIZED;
        strcpy(m.u.error.reason, "missing or wrong access token");
        break;
    case FXT_S_BYE:
        m.type = PROTO_BYE;
        strcpy(m.u.bye.reason, "client closing");
        break;
    case FXT_S_BYE_EMPTY: m.type = PROTO_BYE; break;
    case FXT_S_SAMPLE_REQUEST:
        m.type = PROTO_SAMPLE_REQUEST;
        m.u.sample_request = (proto_sample_request){.request = 0x01020304u,
                                                    .camera = sample_pose(6.0),
                                                    .width = 640,
                                                    .height = 480,
                                                    .count = 3,
                                                    .pixels = fxt_request_pixels};
        break;
    case FXT_S_SAMPLE_REQUEST_EDGE:
        m.type = PROTO_SAMPLE_REQUEST;
        m.u.sample_request = (proto_sample_request){.request = 0,
                                                    .camera = sample_pose(7.0),
                                                    .width = 2,
                                                    .height = 1,
                                                    .count = 2,
                                                    .pixels = edge_pixels};
        break;
    case FXT_S_SAMPLES:
        m.type = PROTO_SAMPLES;
        m.u.samples = (proto_samples){.request = 77,
                                      .frame = 1000,
                                      .camera = sample_pose(8.0),
                                      .width = 4,
                                      .height = 3,
                                      .count = 2,
                                      .samples = fxt_samples_bytes};
        break;
    case FXT_S_SAMPLES_EMPTY:
        m.type = PROTO_SAMPLES;
        m.u.samples = (proto_samples){.request = 0xffffffffu,
                                      .frame = 0,
                                      .camera = sample_pose(9.0),
                                      .width = PROTO_MAX_SIDE,
                                      .height = PROTO_MAX_SIDE};
        break;
    }
    return m;
}

/* Payload bytes of each sample, counted by hand from docs/PROTOCOL.md's tables. */
const size_t fxt_sample_payload_bytes[FXT_SAMPLE_COUNT] = {
    [FXT_S_HELLO_RAW] = 18,
    [FXT_S_HELLO_JPEG] = 18 + 5 + 12 + 7,
    [FXT_S_HELLO_ZSTD] = 18 + 31 + 64 + 31,
    [FXT_S_WELCOME] = 101 + 9,
    [FXT_S_CAMERA] = 53,
    [FXT_S_CAMERA_PREDICTED] = 101,
    [FXT_S_FRAME] = 114 + 36,
    [FXT_S_FRAME_DEPTH] = 114 + 5 + 7,
    [FXT_S_STATS_REQUEST] = 0,
    [FXT_S_STATS] = 4 + sizeof FXT_STATS_JSON - 1,
    [FXT_S_STATS_EMPTY] = 4,
    [FXT_S_ERROR] = 6 + 29,
    [FXT_S_BYE] = 2 + 14,
    [FXT_S_BYE_EMPTY] = 2,
    [FXT_S_SAMPLE_REQUEST] = 56 + 3 * 4,
    [FXT_S_SAMPLE_REQUEST_EDGE] = 56 + 2 * 4,
    [FXT_S_SAMPLES] = 60 + 2 * 12,
    [FXT_S_SAMPLES_EMPTY] = 60,
};

/* Encodes m into a new allocation of exactly proto_bound(m) bytes (the test fails if it cannot). */
uint8_t *fxt_encode_alloc(const proto_msg *m, size_t *len)
{
    size_t bound = proto_bound(m);
    assert_true(bound >= PROTO_HEADER_BYTES);
    uint8_t *buf = malloc(bound);
    assert_non_null(buf);
    fxc_result result = FXC_ERR_INVALID;
    *len = proto_encode(m, buf, bound, &result);
    assert_int_equal(result, FXC_OK);
    assert_int_equal(*len, bound);
    return buf;
}

/* Decodes a copy of bytes in an allocation of exactly len bytes, so the sanitizer sees any over-read. */
fxc_result fxt_decode_copy(const uint8_t *bytes, size_t len, proto_msg *out)
{
    uint8_t *copy = malloc(len ? len : 1);
    assert_non_null(copy);
    if (len)
        memcpy(copy, bytes, len);
    fxc_result result = proto_decode(len ? copy : NULL, len, out);
    free(copy);
    return result;
}

static bool same_pose(const proto_pose *a, const proto_pose *b)
{
    return memcmp(a->position, b->position, sizeof a->position) == 0 &&
           memcmp(a->direction, b->direction, sizeof a->direction) == 0 &&
           fxt_bits_from_float(a->fov_deg) == fxt_bits_from_float(b->fov_deg);
}

/* Field by field equality of two messages (floats bit for bit, payloads by content). */
void fxt_assert_same_message(const proto_msg *a, const proto_msg *b)
{
    assert_int_equal(a->type, b->type);
    switch (a->type) {
    case PROTO_HELLO: {
        const proto_hello *x = &a->u.hello, *y = &b->u.hello;
        assert_string_equal(x->name, y->name);
        assert_int_equal(x->width, y->width);
        assert_int_equal(x->height, y->height);
        assert_int_equal(fxt_bits_from_float(x->fov_deg), fxt_bits_from_float(y->fov_deg));
        assert_int_equal(x->codec, y->codec);
        assert_int_equal(x->jpeg_quality, y->jpeg_quality);
        assert_int_equal(x->depth, y->depth);
        assert_string_equal(x->token, y->token);
        assert_string_equal(x->strategy, y->strategy);
        break;
    }
    case PROTO_WELCOME: {
        const proto_welcome *x = &a->u.welcome, *y = &b->u.welcome;
        assert_int_equal(x->viewer_id, y->viewer_id);
        assert_string_equal(x->name, y->name);
        assert_int_equal(fxt_bits_from_float(x->fps), fxt_bits_from_float(y->fps));
        assert_memory_equal(x->bounds_min, y->bounds_min, sizeof x->bounds_min);
        assert_memory_equal(x->bounds_max, y->bounds_max, sizeof x->bounds_max);
        assert_true(same_pose(&x->camera, &y->camera));
        assert_int_equal(x->max_camera_rate, y->max_camera_rate);
        break;
    }
    case PROTO_CAMERA: {
        const proto_camera *x = &a->u.camera, *y = &b->u.camera;
        assert_int_equal(x->sequence, y->sequence);
        assert_memory_equal(&x->time, &y->time, sizeof x->time);
        assert_true(same_pose(&x->pose, &y->pose));
        assert_int_equal(x->has_predicted, y->has_predicted);
        if (x->has_predicted) {
            assert_memory_equal(&x->predicted_time, &y->predicted_time, sizeof x->predicted_time);
            assert_true(same_pose(&x->predicted, &y->predicted));
        }
        break;
    }
    case PROTO_FRAME: {
        const proto_frame *x = &a->u.frame, *y = &b->u.frame;
        assert_int_equal(x->frame, y->frame);
        assert_int_equal(x->camera_sequence, y->camera_sequence);
        assert_true(same_pose(&x->camera, &y->camera));
        assert_int_equal(x->width, y->width);
        assert_int_equal(x->height, y->height);
        assert_int_equal(x->codec, y->codec);
        assert_int_equal(x->depth, y->depth);
        assert_true(x->stats.requested_texels == y->stats.requested_texels);
        assert_true(x->stats.requested_cells == y->stats.requested_cells);
        assert_true(x->stats.pixels_visible == y->stats.pixels_visible);
        assert_true(x->stats.pixels_missing == y->stats.pixels_missing);
        assert_true(x->stats.frames_dropped == y->stats.frames_dropped);
        assert_int_equal(fxt_bits_from_float(x->stats.frame_ms), fxt_bits_from_float(y->stats.frame_ms));
        assert_int_equal(fxt_bits_from_float(x->stats.encode_ms), fxt_bits_from_float(y->stats.encode_ms));
        assert_int_equal(x->color_bytes, y->color_bytes);
        assert_memory_equal(x->color, y->color, x->color_bytes);
        assert_int_equal(x->depth_bytes, y->depth_bytes);
        if (x->depth_bytes)
            assert_memory_equal(x->depth_data, y->depth_data, x->depth_bytes);
        break;
    }
    case PROTO_STATS:
        assert_int_equal(a->u.stats.json_bytes, b->u.stats.json_bytes);
        if (a->u.stats.json_bytes)
            assert_memory_equal(a->u.stats.json, b->u.stats.json, a->u.stats.json_bytes);
        break;
    case PROTO_ERROR:
        assert_int_equal(a->u.error.code, b->u.error.code);
        assert_string_equal(a->u.error.reason, b->u.error.reason);
        break;
    case PROTO_BYE: assert_string_equal(a->u.bye.reason, b->u.bye.reason); break;
    case PROTO_SAMPLE_REQUEST: {
        const proto_sample_request *x = &a->u.sample_request, *y = &b->u.sample_request;
        assert_int_equal(x->request, y->request);
        assert_true(same_pose(&x->camera, &y->camera));
        assert_int_equal(x->width, y->width);
        assert_int_equal(x->height, y->height);
        assert_int_equal(x->count, y->count);
        assert_memory_equal(x->pixels, y->pixels, (size_t)x->count * 4);
        break;
    }
    case PROTO_SAMPLES: {
        const proto_samples *x = &a->u.samples, *y = &b->u.samples;
        assert_int_equal(x->request, y->request);
        assert_int_equal(x->frame, y->frame);
        assert_true(same_pose(&x->camera, &y->camera));
        assert_int_equal(x->width, y->width);
        assert_int_equal(x->height, y->height);
        assert_int_equal(x->count, y->count);
        if (x->count)
            assert_memory_equal(x->samples, y->samples, (size_t)x->count * 12);
        else
            assert_null(y->samples);
        break;
    }
    }
}
