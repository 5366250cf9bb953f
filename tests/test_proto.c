/* Tests of the wire format (proto/proto.c); the payload codecs' are in test_proto_codec.c.
 *
 * Messages: byte order against literal bytes; every sample message (every type, optional parts present and
 * absent, strings empty and at their maximum) round-trips with proto_bound == bytes written and its header
 * and field offsets where docs/PROTOCOL.md puts them; every prefix of every sample, each in its own
 * allocation, is TRUNCATED; an extra byte, undeclared or declared, is TRAILING; header faults have their own
 * codes; one table changes one field's bytes per row and expects RANGE (or TRUNCATED/TRAILING for length
 * fields), another changes one struct field and expects proto_encode to refuse; a bounded mutation loop
 * checks that whatever decodes re-encodes to the same bytes; the committed fuzz corpus decodes, with its
 * payloads. */
#include "test_util.h"

#include "proto.h"

#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- sample messages ------------------------------------------------------------------------------- */

enum {
    S_HELLO_RAW,       /* empty strings */
    S_HELLO_JPEG,      /* name "alice", token "secret-token", strategy "nearest" */
    S_HELLO_ZSTD,      /* every string at its maximum */
    S_WELCOME,         /* name "viewer_07" */
    S_CAMERA,          /* without a predicted pose */
    S_CAMERA_PREDICTED,
    S_FRAME,           /* 4x3 raw colour (36 bytes), no depth */
    S_FRAME_DEPTH,     /* 5 colour bytes, 7 depth bytes (the message does not look inside them) */
    S_STATS_REQUEST,
    S_STATS,
    S_STATS_EMPTY,
    S_ERROR,           /* reason "missing or wrong access token" (29 bytes) */
    S_BYE,             /* reason "client closing" (14 bytes) */
    S_BYE_EMPTY,
    S_SAMPLE_REQUEST,  /* 640x480, pixels (0,0), (639,479), (17,200) */
    S_SAMPLE_REQUEST_EDGE, /* 2x1, count 2 = width*height, pixel (1,0) twice (duplicates are allowed) */
    S_SAMPLES,         /* 4x3, two samples: (3,2) at 2.5 m, (0,0) the sky */
    S_SAMPLES_EMPTY,   /* count 0 */
    SAMPLE_COUNT
};

static const uint8_t frame_color[36] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18,
                                        19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30, 31, 32, 33, 34, 35, 36};
static const uint8_t frame_depth[7] = {0xde, 0xad, 0xbe, 0xef, 0x00, 0x01, 0xff};
static const char stats_json[] = "{\"frames\": 10, \"viewers\": [1, 2]}";
/* The request's pixels as bytes: x, y little-endian u16 each. */
static const uint8_t request_pixels[12] = {0, 0, 0, 0, 0x7f, 0x02, 0xdf, 0x01, 17, 0, 200, 0};
/* Four entries, of which the edge sample uses two (an edit may raise its count to 3 without an over-read). */
static const uint8_t edge_pixels[16] = {1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
/* Two samples: (3,2) rgb 10,20,30 depth 2.5 (0x40200000); (0,0) rgb 255,0,128 depth +inf (0x7f800000). */
static const uint8_t samples_bytes[24] = {3, 0, 2, 0, 10, 20, 30, 0, 0x00, 0x00, 0x20, 0x40,
                                          0, 0, 0, 0, 255, 0, 128, 0, 0x00, 0x00, 0x80, 0x7f};

static proto_pose sample_pose(double offset)
{
    proto_pose pose = {{1.5e6 + offset, -2.25, 3.0 / 7.0}, {0.25f, -1.0f, 1e-3f}, 60.0f};
    return pose;
}

/* Sample message i (valid, every field distinct from zero where it may be). */
static proto_msg sample(int i)
{
    proto_msg m;
    memset(&m, 0, sizeof m);
    switch (i) {
    case S_HELLO_RAW:
        m.type = PROTO_HELLO;
        m.u.hello = (proto_hello){.width = 640, .height = 360, .fov_deg = 60.0f, .codec = PROTO_CODEC_RAW};
        break;
    case S_HELLO_JPEG:
        m.type = PROTO_HELLO;
        m.u.hello = (proto_hello){.name = "alice", .width = 1920, .height = 1080, .fov_deg = 75.5f,
                                  .codec = PROTO_CODEC_JPEG, .jpeg_quality = 85, .depth = PROTO_DEPTH_HALF,
                                  .token = "secret-token", .strategy = "nearest"};
        break;
    case S_HELLO_ZSTD:
        m.type = PROTO_HELLO;
        m.u.hello = (proto_hello){.width = PROTO_MAX_SIDE, .height = 1, .fov_deg = 179.9f,
                                  .codec = PROTO_CODEC_ZSTD, .depth = PROTO_DEPTH_FLOAT};
        memset(m.u.hello.name, '~', PROTO_NAME_MAX);
        m.u.hello.name[0] = ' ';
        memset(m.u.hello.token, 'T', PROTO_TOKEN_MAX);
        memset(m.u.hello.strategy, 's', PROTO_STRATEGY_MAX);
        break;
    case S_WELCOME:
        m.type = PROTO_WELCOME;
        m.u.welcome = (proto_welcome){.viewer_id = 7, .name = "viewer_07", .fps = 30.0f,
                                      .bounds_min = {-10.5, 0.0, -1e-9}, .bounds_max = {10.5, 0.0, 4.0},
                                      .camera = sample_pose(0.0), .max_camera_rate = 120};
        break;
    case S_CAMERA:
        m.type = PROTO_CAMERA;
        m.u.camera = (proto_camera){.sequence = 42, .time = 1.25, .pose = sample_pose(1.0)};
        break;
    case S_CAMERA_PREDICTED:
        m.type = PROTO_CAMERA;
        m.u.camera = (proto_camera){.sequence = 0xfffffffeu, .time = -3.5, .pose = sample_pose(2.0),
                                    .has_predicted = true, .predicted_time = 1.3, .predicted = sample_pose(3.0)};
        m.u.camera.predicted.fov_deg = 0.001f;
        break;
    case S_FRAME:
        m.type = PROTO_FRAME;
        m.u.frame = (proto_frame){.frame = 100, .camera_sequence = 42, .camera = sample_pose(4.0), .width = 4,
                                  .height = 3, .codec = PROTO_CODEC_RAW, .depth = PROTO_DEPTH_NONE,
                                  .stats = {1, 2, 3, 4, 5, 16.5f, 0.0f}, .color = frame_color,
                                  .color_bytes = sizeof frame_color};
        break;
    case S_FRAME_DEPTH:
        m.type = PROTO_FRAME;
        m.u.frame = (proto_frame){.frame = 0xffffffffu, .camera_sequence = 0, .camera = sample_pose(5.0),
                                  .width = PROTO_MAX_SIDE, .height = PROTO_MAX_SIDE, .codec = PROTO_CODEC_ZSTD,
                                  .depth = PROTO_DEPTH_HALF,
                                  .stats = {UINT64_MAX, 1ull << 40, 7, 0, 1, 1e3f, 2.5f}, .color = frame_color,
                                  .color_bytes = 5, .depth_data = frame_depth, .depth_bytes = sizeof frame_depth};
        break;
    case S_STATS_REQUEST:
        m.type = PROTO_STATS_REQUEST;
        break;
    case S_STATS:
        m.type = PROTO_STATS;
        m.u.stats = (proto_stats){stats_json, (uint32_t)strlen(stats_json)};
        break;
    case S_STATS_EMPTY:
        m.type = PROTO_STATS;
        break;
    case S_ERROR:
        m.type = PROTO_ERROR;
        m.u.error.code = FXC_ERR_UNAUTHORIZED;
        strcpy(m.u.error.reason, "missing or wrong access token");
        break;
    case S_BYE:
        m.type = PROTO_BYE;
        strcpy(m.u.bye.reason, "client closing");
        break;
    case S_BYE_EMPTY:
        m.type = PROTO_BYE;
        break;
    case S_SAMPLE_REQUEST:
        m.type = PROTO_SAMPLE_REQUEST;
        m.u.sample_request = (proto_sample_request){.request = 0x01020304u, .camera = sample_pose(6.0),
                                                    .width = 640, .height = 480, .count = 3,
                                                    .pixels = request_pixels};
        break;
    case S_SAMPLE_REQUEST_EDGE:
        m.type = PROTO_SAMPLE_REQUEST;
        m.u.sample_request = (proto_sample_request){.request = 0, .camera = sample_pose(7.0), .width = 2,
                                                    .height = 1, .count = 2, .pixels = edge_pixels};
        break;
    case S_SAMPLES:
        m.type = PROTO_SAMPLES;
        m.u.samples = (proto_samples){.request = 77, .frame = 1000, .camera = sample_pose(8.0), .width = 4,
                                      .height = 3, .count = 2, .samples = samples_bytes};
        break;
    case S_SAMPLES_EMPTY:
        m.type = PROTO_SAMPLES;
        m.u.samples = (proto_samples){.request = 0xffffffffu, .frame = 0, .camera = sample_pose(9.0),
                                      .width = PROTO_MAX_SIDE, .height = PROTO_MAX_SIDE};
        break;
    }
    return m;
}

/* Payload bytes of each sample, counted by hand from docs/PROTOCOL.md's tables. */
static const size_t sample_payload_bytes[SAMPLE_COUNT] = {
    [S_HELLO_RAW] = 18,
    [S_HELLO_JPEG] = 18 + 5 + 12 + 7,
    [S_HELLO_ZSTD] = 18 + 31 + 64 + 31,
    [S_WELCOME] = 101 + 9,
    [S_CAMERA] = 53,
    [S_CAMERA_PREDICTED] = 101,
    [S_FRAME] = 114 + 36,
    [S_FRAME_DEPTH] = 114 + 5 + 7,
    [S_STATS_REQUEST] = 0,
    [S_STATS] = 4 + sizeof stats_json - 1,
    [S_STATS_EMPTY] = 4,
    [S_ERROR] = 6 + 29,
    [S_BYE] = 2 + 14,
    [S_BYE_EMPTY] = 2,
    [S_SAMPLE_REQUEST] = 56 + 3 * 4,
    [S_SAMPLE_REQUEST_EDGE] = 56 + 2 * 4,
    [S_SAMPLES] = 60 + 2 * 12,
    [S_SAMPLES_EMPTY] = 60,
};

/* Encodes m into a new allocation of exactly proto_bound(m) bytes (the test fails if it cannot). */
static uint8_t *encode_alloc(const proto_msg *m, size_t *len)
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
static fxc_result decode_copy(const uint8_t *bytes, size_t len, proto_msg *out)
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
static void assert_same_message(const proto_msg *a, const proto_msg *b)
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
    case PROTO_BYE:
        assert_string_equal(a->u.bye.reason, b->u.bye.reason);
        break;
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

/* ---- bytes and names -------------------------------------------------------------------------------- */

static void test_byte_order(void **state)
{
    (void)state;
    uint8_t bytes[8];
    proto_put_u32le(bytes, 0x01020304u);
    static const uint8_t want32[4] = {0x04, 0x03, 0x02, 0x01};
    assert_memory_equal(bytes, want32, 4);
    proto_put_u16le(bytes, 0xa1b2u);
    assert_int_equal(bytes[0], 0xb2);
    assert_int_equal(bytes[1], 0xa1);
    proto_put_u64le(bytes, 0x0102030405060708ull);
    static const uint8_t want64[8] = {8, 7, 6, 5, 4, 3, 2, 1};
    assert_memory_equal(bytes, want64, 8);
    static const uint8_t high[8] = {0xff, 0xfe, 0xfd, 0xfc, 0xfb, 0xfa, 0xf9, 0xf8};
    assert_int_equal(proto_get_u16le(high), 0xfeff);
    assert_int_equal(proto_get_u32le(high), 0xfcfdfeffu);
    assert_true(proto_get_u64le(high) == 0xf8f9fafbfcfdfeffull);
}

static void test_names(void **state)
{
    (void)state;
    static const char *const types[] = {NULL,    "hello", "welcome", "camera", "frame", "stats-request",
                                        "stats", "error", "bye",     "sample-request", "samples"};
    for (uint32_t t = 1; t <= 10; t++)
        assert_string_equal(proto_type_name(t), types[t]);
    assert_string_equal(proto_type_name(0), "unknown");
    assert_string_equal(proto_type_name(11), "unknown");
    assert_string_equal(proto_type_name(0xffffffffu), "unknown");
    assert_string_equal(proto_codec_name(PROTO_CODEC_RAW), "raw");
    assert_string_equal(proto_codec_name(PROTO_CODEC_ZSTD), "zstd");
    assert_string_equal(proto_codec_name(PROTO_CODEC_JPEG), "jpeg");
    assert_string_equal(proto_codec_name(PROTO_CODEC_COUNT), "unknown");
    proto_codec codec = PROTO_CODEC_COUNT;
    assert_true(proto_codec_parse("jpeg", &codec));
    assert_int_equal(codec, PROTO_CODEC_JPEG);
    assert_true(proto_codec_parse("raw", &codec));
    assert_int_equal(codec, PROTO_CODEC_RAW);
    assert_true(proto_codec_parse("zstd", &codec));
    assert_int_equal(codec, PROTO_CODEC_ZSTD);
    static const char *const refused[] = {"JPEG", "", "zstd ", "jpg", "unknown"};
    for (size_t i = 0; i < sizeof refused / sizeof refused[0]; i++) {
        codec = PROTO_CODEC_COUNT;
        assert_false(proto_codec_parse(refused[i], &codec));
        assert_int_equal(codec, PROTO_CODEC_COUNT);
    }
    assert_false(proto_codec_parse(NULL, &codec));

    /* Strategies: "" is basic; names are exact. */
    static const struct {
        const char *text;
        int strategy; /* -1: refused */
    } strategies[] = {{"", PROTO_STRATEGY_BASIC},   {"basic", PROTO_STRATEGY_BASIC},
                      {"fan", PROTO_STRATEGY_FAN},  {"predictive", PROTO_STRATEGY_PREDICTIVE},
                      {"Basic", -1},                {"fan ", -1},
                      {"nearest", -1},              {"predict", -1}};
    for (size_t i = 0; i < sizeof strategies / sizeof strategies[0]; i++) {
        proto_strategy strategy = PROTO_STRATEGY_COUNT;
        bool ok = proto_strategy_parse(strategies[i].text, &strategy);
        assert_int_equal(ok, strategies[i].strategy >= 0);
        assert_int_equal(strategy, ok ? strategies[i].strategy : PROTO_STRATEGY_COUNT);
    }
    assert_false(proto_strategy_parse(NULL, NULL));
    assert_string_equal(proto_strategy_name(PROTO_STRATEGY_BASIC), "basic");
    assert_string_equal(proto_strategy_name(PROTO_STRATEGY_FAN), "fan");
    assert_string_equal(proto_strategy_name(PROTO_STRATEGY_PREDICTIVE), "predictive");
    assert_string_equal(proto_strategy_name(PROTO_STRATEGY_COUNT), "unknown");
}

/* The sample arrays' entries against literal bytes, and back. */
static void test_sample_entries(void **state)
{
    (void)state;
    uint8_t pixels[8];
    memset(pixels, 0xaa, sizeof pixels);
    proto_request_pixel_put(pixels, 1, 0x0102, 0xfffe);
    static const uint8_t want_pixels[8] = {0xaa, 0xaa, 0xaa, 0xaa, 0x02, 0x01, 0xfe, 0xff};
    assert_memory_equal(pixels, want_pixels, sizeof pixels);
    uint16_t x = 0, y = 0;
    proto_request_pixel_get(request_pixels, 1, &x, &y);
    assert_int_equal(x, 639);
    assert_int_equal(y, 479);

    uint8_t samples[24];
    memset(samples, 0xaa, sizeof samples);
    proto_sample s = {3, 2, {10, 20, 30}, 2.5f};
    proto_sample_put(samples, 0, &s);
    s = (proto_sample){0, 0, {255, 0, 128}, INFINITY};
    proto_sample_put(samples, 1, &s);
    assert_memory_equal(samples, samples_bytes, sizeof samples); /* the pad byte is written 0 */
    proto_sample back;
    proto_sample_get(samples_bytes, 0, &back);
    assert_int_equal(back.x, 3);
    assert_int_equal(back.y, 2);
    assert_int_equal(back.rgb[0], 10);
    assert_int_equal(back.rgb[2], 30);
    assert_true(back.depth == 2.5f);
    proto_sample_get(samples_bytes, 1, &back);
    assert_int_equal(back.rgb[0], 255);
    assert_true(isinf(back.depth) && back.depth > 0.0f);
}

/* ---- messages --------------------------------------------------------------------------------------- */

/* Every sample: bound == written == 12 + the hand-counted payload, the header as documented, decode gives
 * back every field, and the frame's payloads point into the buffer. */
static void test_round_trip(void **state)
{
    (void)state;
    for (int i = 0; i < SAMPLE_COUNT; i++) {
        proto_msg m = sample(i);
        size_t len;
        uint8_t *buf = encode_alloc(&m, &len);
        assert_int_equal(len, PROTO_HEADER_BYTES + sample_payload_bytes[i]);
        assert_memory_equal(buf, "FXCP", 4);
        assert_int_equal(buf[4], PROTO_VERSION);
        assert_int_equal(buf[5], 0);
        assert_int_equal(buf[6], m.type);
        assert_int_equal(buf[7], 0);
        assert_int_equal(proto_get_u32le(buf + 8), sample_payload_bytes[i]);
        proto_header h;
        assert_int_equal(proto_decode_header(buf, len, &h), FXC_OK);
        assert_int_equal(h.version, PROTO_VERSION);
        assert_int_equal(h.type, m.type);
        assert_int_equal(h.length, sample_payload_bytes[i]);
        proto_msg back;
        fxc_result result = proto_decode(buf, len, &back);
        if (result != FXC_OK)
            fail_msg("sample %d (%s): %s", i, proto_type_name(m.type), fxc_strerror(result));
        assert_same_message(&m, &back);
        if (m.type == PROTO_FRAME) {
            /* The colour count sits at payload offset 106, the colour bytes right after it. */
            assert_ptr_equal(back.u.frame.color, buf + PROTO_HEADER_BYTES + 110);
            assert_int_equal(proto_get_u32le(buf + PROTO_HEADER_BYTES + 106), m.u.frame.color_bytes);
            if (m.u.frame.depth_bytes)
                assert_ptr_equal(back.u.frame.depth_data, buf + PROTO_HEADER_BYTES + 114 + m.u.frame.color_bytes);
            else
                assert_null(back.u.frame.depth_data);
        }
        if (m.type == PROTO_SAMPLE_REQUEST)
            assert_ptr_equal(back.u.sample_request.pixels, buf + PROTO_HEADER_BYTES + 56);
        if (m.type == PROTO_SAMPLES && m.u.samples.count)
            assert_ptr_equal(back.u.samples.samples, buf + PROTO_HEADER_BYTES + 60);
        if (m.type == PROTO_STATS && m.u.stats.json_bytes)
            assert_ptr_equal(back.u.stats.json, (const char *)buf + PROTO_HEADER_BYTES + 4);
        /* A camera without a predicted pose decodes with the predicted fields zeroed. */
        if (i == S_CAMERA) {
            assert_false(back.u.camera.has_predicted);
            assert_true(back.u.camera.predicted.fov_deg == 0.0f && back.u.camera.predicted_time == 0.0);
        }
        free(buf);
    }
}

/* A few fields at the offsets docs/PROTOCOL.md gives (a second reading of the layout, by hand). */
static void test_documented_offsets(void **state)
{
    (void)state;
    size_t len;
    proto_msg m = sample(S_HELLO_JPEG);
    uint8_t *buf = encode_alloc(&m, &len);
    const uint8_t *p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(p[0], 5);
    assert_memory_equal(p + 1, "alice", 5);
    assert_int_equal(proto_get_u32le(p + 6), 1920);
    assert_int_equal(proto_get_u32le(p + 10), 1080);
    assert_int_equal(proto_get_u32le(p + 14), fxt_bits_from_float(75.5f));
    assert_int_equal(p[18], PROTO_CODEC_JPEG);
    assert_int_equal(p[19], 85);
    assert_int_equal(p[20], 16);
    assert_int_equal(p[21], 12);
    assert_memory_equal(p + 22, "secret-token", 12);
    assert_int_equal(p[34], 7);
    assert_memory_equal(p + 35, "nearest", 7);
    free(buf);

    m = sample(S_WELCOME);
    buf = encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p), 7);
    assert_int_equal(p[4], 9);
    assert_int_equal(proto_get_u32le(p + 14), fxt_bits_from_float(30.0f));
    double bmax0 = 10.5;
    uint64_t bits;
    memcpy(&bits, &bmax0, sizeof bits);
    assert_true(proto_get_u64le(p + 42) == bits);
    assert_int_equal(proto_get_u32le(p + 102), fxt_bits_from_float(60.0f)); /* camera fov */
    assert_int_equal(proto_get_u32le(p + 106), 120);
    free(buf);

    m = sample(S_CAMERA_PREDICTED);
    buf = encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p), 0xfffffffeu);
    assert_int_equal(p[52], 1);
    assert_int_equal(proto_get_u32le(p + 97), fxt_bits_from_float(0.001f));
    free(buf);

    m = sample(S_FRAME_DEPTH);
    buf = encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p + 48), PROTO_MAX_SIDE);
    assert_int_equal(p[56], PROTO_CODEC_ZSTD);
    assert_int_equal(p[57], 16);
    assert_true(proto_get_u64le(p + 58) == UINT64_MAX);
    assert_int_equal(proto_get_u32le(p + 102), fxt_bits_from_float(2.5f));
    assert_int_equal(proto_get_u32le(p + 115), 7);
    free(buf);

    m = sample(S_ERROR);
    buf = encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p), (uint32_t)FXC_ERR_UNAUTHORIZED);
    assert_int_equal(proto_get_u16le(p + 4), 29);
    free(buf);

    m = sample(S_SAMPLE_REQUEST);
    buf = encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p), 0x01020304u);
    assert_int_equal(proto_get_u32le(p + 40), fxt_bits_from_float(60.0f)); /* camera fov */
    assert_int_equal(proto_get_u32le(p + 44), 640);
    assert_int_equal(proto_get_u32le(p + 48), 480);
    assert_int_equal(proto_get_u32le(p + 52), 3);
    assert_int_equal(proto_get_u16le(p + 60), 639);
    assert_int_equal(proto_get_u16le(p + 62), 479);
    free(buf);

    m = sample(S_SAMPLES);
    buf = encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p), 77);
    assert_int_equal(proto_get_u32le(p + 4), 1000);
    assert_int_equal(proto_get_u32le(p + 44), fxt_bits_from_float(60.0f));
    assert_int_equal(proto_get_u32le(p + 48), 4);
    assert_int_equal(proto_get_u32le(p + 52), 3);
    assert_int_equal(proto_get_u32le(p + 56), 2);
    assert_int_equal(p[60 + 12 + 4], 255);
    assert_int_equal(proto_get_u32le(p + 60 + 8), fxt_bits_from_float(2.5f));
    free(buf);
}

/* Every prefix of every sample, each in its own allocation of exactly that many bytes, is TRUNCATED. */
static void test_every_prefix(void **state)
{
    (void)state;
    for (int i = 0; i < SAMPLE_COUNT; i++) {
        proto_msg m = sample(i);
        size_t len;
        uint8_t *buf = encode_alloc(&m, &len);
        for (size_t prefix = 0; prefix < len; prefix++) {
            proto_msg out;
            fxc_result result = decode_copy(buf, prefix, &out);
            if (result != FXC_ERR_TRUNCATED)
                fail_msg("sample %d, %zu of %zu bytes: %s", i, prefix, len, fxc_strerror(result));
        }
        free(buf);
    }
}

/* One byte more than declared, and a declared length one more than the fields use: both TRAILING. */
static void test_trailing(void **state)
{
    (void)state;
    for (int i = 0; i < SAMPLE_COUNT; i++) {
        proto_msg m = sample(i);
        size_t len;
        uint8_t *buf = encode_alloc(&m, &len);
        uint8_t *longer = malloc(len + 1);
        assert_non_null(longer);
        memcpy(longer, buf, len);
        longer[len] = 0;
        proto_msg out;
        assert_int_equal(decode_copy(longer, len + 1, &out), FXC_ERR_TRAILING);
        proto_put_u32le(longer + 8, proto_get_u32le(longer + 8) + 1);
        assert_int_equal(decode_copy(longer, len + 1, &out), FXC_ERR_TRAILING);
        free(longer);
        free(buf);
    }
}

static void test_header_faults(void **state)
{
    (void)state;
    proto_msg m = sample(S_BYE);
    size_t len;
    uint8_t *buf = encode_alloc(&m, &len);
    proto_msg out;
    for (int k = 0; k < 4; k++) { /* each magic byte */
        buf[k] ^= 0x20;
        assert_int_equal(decode_copy(buf, len, &out), FXC_ERR_BAD_MAGIC);
        assert_int_equal(proto_decode_header(buf, len, NULL), FXC_ERR_BAD_MAGIC);
        buf[k] ^= 0x20;
    }
    static const uint16_t bad_versions[] = {0, PROTO_VERSION + 1, 0xffff};
    for (size_t k = 0; k < sizeof bad_versions / sizeof bad_versions[0]; k++) {
        proto_put_u16le(buf + 4, bad_versions[k]);
        assert_int_equal(decode_copy(buf, len, &out), FXC_ERR_VERSION);
        /* The magic is checked before the version. */
        buf[0] = 'G';
        assert_int_equal(decode_copy(buf, len, &out), FXC_ERR_BAD_MAGIC);
        buf[0] = 'F';
    }
    proto_put_u16le(buf + 4, PROTO_VERSION);
    static const uint16_t bad_types[] = {0, 11, 0x100 | PROTO_BYE, 0xffff};
    for (size_t k = 0; k < sizeof bad_types / sizeof bad_types[0]; k++) {
        proto_put_u16le(buf + 6, bad_types[k]);
        assert_int_equal(decode_copy(buf, len, &out), FXC_ERR_UNKNOWN_TYPE);
    }
    proto_put_u16le(buf + 6, PROTO_BYE);
    assert_int_equal(decode_copy(buf, len, &out), FXC_OK);

    /* The length: above the maximum is TOO_LARGE from the 12 header bytes alone; at it, the header is fine
     * and the message is merely truncated. */
    uint8_t header[PROTO_HEADER_BYTES];
    memcpy(header, buf, sizeof header);
    proto_put_u32le(header + 8, PROTO_MAX_PAYLOAD + 1u);
    assert_int_equal(proto_decode_header(header, sizeof header, NULL), FXC_ERR_TOO_LARGE);
    assert_int_equal(decode_copy(header, sizeof header, &out), FXC_ERR_TOO_LARGE);
    proto_put_u32le(header + 8, 0xffffffffu);
    assert_int_equal(decode_copy(header, sizeof header, &out), FXC_ERR_TOO_LARGE);
    proto_put_u32le(header + 8, PROTO_MAX_PAYLOAD);
    proto_header h;
    assert_int_equal(proto_decode_header(header, sizeof header, &h), FXC_OK);
    assert_int_equal(h.length, PROTO_MAX_PAYLOAD);
    assert_int_equal(decode_copy(header, sizeof header, &out), FXC_ERR_TRUNCATED);
    assert_int_equal(proto_decode_header(header, 11, &h), FXC_ERR_TRUNCATED);
    assert_int_equal(proto_decode(NULL, 0, &out), FXC_ERR_TRUNCATED);
    free(buf);
}

/* One edit of an encoded sample: replace old_size payload bytes at offset by new_size bytes holding value
 * (little-endian, zeros beyond 8 bytes), fix the header's length, and expect a code. */
typedef struct byte_edit {
    const char *what;
    int sample;
    size_t offset, old_size, new_size;
    uint64_t value;
    fxc_result expect;
} byte_edit;

#define F32_NAN 0x7fc00000u
#define F32_INF 0x7f800000u
#define F32_NEG_INF 0xff800000u
#define F32_ZERO 0x00000000u
#define F32_NEG_ONE 0xbf800000u
#define F32_180 0x43340000u
#define F64_NAN 0x7ff8000000000000ull
#define F64_INF 0x7ff0000000000000ull
#define F64_NEG_INF 0xfff0000000000000ull
#define F64_ONE 0x3ff0000000000000ull

/* Payload offsets of the samples' fields (docs/PROTOCOL.md), with their string lengths in. */
enum {
    /* hello "alice"/"secret-token"/"nearest"; S_HELLO_RAW has empty strings: width at 1 */
    HJ_NAME = 0, HJ_WIDTH = 6, HJ_HEIGHT = 10, HJ_FOV = 14, HJ_CODEC = 18, HJ_QUALITY = 19, HJ_DEPTH = 20,
    HJ_TOKEN = 21, HJ_STRATEGY = 34, HR_QUALITY = 14, HR_TOKEN = 16, HR_STRATEGY = 17,
    /* welcome "viewer_07" */
    W_ID = 0, W_NAME = 4, W_FPS = 14, W_MIN = 18, W_MAX = 42, W_POS = 66, W_DIR = 90, W_FOV = 102,
    /* camera (S_CAMERA_PREDICTED for the predicted part) */
    C_TIME = 4, C_POS = 12, C_DIR = 36, C_FOV = 48, C_FLAG = 52, C_PTIME = 53, C_PPOS = 61, C_PDIR = 85,
    C_PFOV = 97,
    /* frame */
    F_POS = 8, F_DIR = 32, F_FOV = 44, F_WIDTH = 48, F_HEIGHT = 52, F_CODEC = 56, F_DEPTH = 57, F_FRAME_MS = 98,
    F_ENCODE_MS = 102, F_COLOR_BYTES = 106, F_COLOR = 110,
    /* error and bye */
    E_CODE = 0, E_REASON = 4, B_REASON = 0,
    /* sample request and samples */
    SR_FOV = 40, SR_DIR = 28, SR_WIDTH = 44, SR_HEIGHT = 48, SR_COUNT = 52, SR_PIXELS = 56,
    SA_POS = 8, SA_FOV = 44, SA_WIDTH = 48, SA_HEIGHT = 52, SA_COUNT = 56, SA_SAMPLES = 60,
};

static const byte_edit byte_edits[] = {
    /* hello */
    {"hello name longer than 31", S_HELLO_JPEG, HJ_NAME, 1, 1, 32, FXC_ERR_RANGE},
    {"hello name control byte", S_HELLO_JPEG, HJ_NAME + 3, 1, 1, 0x01, FXC_ERR_RANGE},
    {"hello name DEL byte", S_HELLO_JPEG, HJ_NAME + 1, 1, 1, 0x7f, FXC_ERR_RANGE},
    {"hello name non-ASCII byte", S_HELLO_JPEG, HJ_NAME + 5, 1, 1, 0xc3, FXC_ERR_RANGE},
    {"hello name NUL byte", S_HELLO_JPEG, HJ_NAME + 2, 1, 1, 0x00, FXC_ERR_RANGE},
    {"hello width 0", S_HELLO_JPEG, HJ_WIDTH, 4, 4, 0, FXC_ERR_RANGE},
    {"hello width 8193", S_HELLO_JPEG, HJ_WIDTH, 4, 4, 8193, FXC_ERR_RANGE},
    {"hello height 0", S_HELLO_JPEG, HJ_HEIGHT, 4, 4, 0, FXC_ERR_RANGE},
    {"hello height 2^32-1", S_HELLO_JPEG, HJ_HEIGHT, 4, 4, 0xffffffffu, FXC_ERR_RANGE},
    {"hello fov 0", S_HELLO_JPEG, HJ_FOV, 4, 4, F32_ZERO, FXC_ERR_RANGE},
    {"hello fov 180", S_HELLO_JPEG, HJ_FOV, 4, 4, F32_180, FXC_ERR_RANGE},
    {"hello fov NaN", S_HELLO_JPEG, HJ_FOV, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"hello fov -inf", S_HELLO_JPEG, HJ_FOV, 4, 4, F32_NEG_INF, FXC_ERR_RANGE},
    {"hello codec 3", S_HELLO_JPEG, HJ_CODEC, 1, 1, PROTO_CODEC_COUNT, FXC_ERR_RANGE},
    {"hello codec 255", S_HELLO_JPEG, HJ_CODEC, 1, 1, 255, FXC_ERR_RANGE},
    {"hello jpeg quality 0", S_HELLO_JPEG, HJ_QUALITY, 1, 1, 0, FXC_ERR_RANGE},
    {"hello jpeg quality 101", S_HELLO_JPEG, HJ_QUALITY, 1, 1, 101, FXC_ERR_RANGE},
    {"hello raw with a quality", S_HELLO_RAW, HR_QUALITY, 1, 1, 50, FXC_ERR_RANGE},
    {"hello quality kept, codec raw", S_HELLO_JPEG, HJ_CODEC, 1, 1, PROTO_CODEC_RAW, FXC_ERR_RANGE},
    {"hello depth 1", S_HELLO_JPEG, HJ_DEPTH, 1, 1, 1, FXC_ERR_RANGE},
    {"hello depth 8", S_HELLO_JPEG, HJ_DEPTH, 1, 1, 8, FXC_ERR_RANGE},
    {"hello depth 33", S_HELLO_JPEG, HJ_DEPTH, 1, 1, 33, FXC_ERR_RANGE},
    {"hello token longer than 64", S_HELLO_JPEG, HJ_TOKEN, 1, 1, 65, FXC_ERR_RANGE},
    {"hello token tab", S_HELLO_JPEG, HJ_TOKEN + 1, 1, 1, '\t', FXC_ERR_RANGE},
    {"hello strategy longer than 31", S_HELLO_JPEG, HJ_STRATEGY, 1, 1, 32, FXC_ERR_RANGE},
    {"hello strategy newline", S_HELLO_JPEG, HJ_STRATEGY + 7, 1, 1, '\n', FXC_ERR_RANGE},
    {"hello token longer than the payload", S_HELLO_RAW, HR_TOKEN, 1, 1, 2, FXC_ERR_TRUNCATED},
    {"hello strategy shorter than its bytes", S_HELLO_JPEG, HJ_STRATEGY, 1, 1, 6, FXC_ERR_TRAILING},
    /* welcome */
    {"welcome viewer id 0", S_WELCOME, W_ID, 4, 4, 0, FXC_ERR_RANGE},
    {"welcome empty name", S_WELCOME, W_NAME, 10, 1, 0, FXC_ERR_RANGE},
    {"welcome name longer than 31", S_WELCOME, W_NAME, 1, 1, 32, FXC_ERR_RANGE},
    {"welcome name escape byte", S_WELCOME, W_NAME + 1, 1, 1, 0x1b, FXC_ERR_RANGE},
    {"welcome fps 0", S_WELCOME, W_FPS, 4, 4, F32_ZERO, FXC_ERR_RANGE},
    {"welcome fps -1", S_WELCOME, W_FPS, 4, 4, F32_NEG_ONE, FXC_ERR_RANGE},
    {"welcome fps NaN", S_WELCOME, W_FPS, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"welcome fps inf", S_WELCOME, W_FPS, 4, 4, F32_INF, FXC_ERR_RANGE},
    {"welcome bounds min x NaN", S_WELCOME, W_MIN, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"welcome bounds min z -inf", S_WELCOME, W_MIN + 16, 8, 8, F64_NEG_INF, FXC_ERR_RANGE},
    {"welcome bounds max z inf", S_WELCOME, W_MAX + 16, 8, 8, F64_INF, FXC_ERR_RANGE},
    {"welcome bounds min y > max y", S_WELCOME, W_MIN + 8, 8, 8, F64_ONE, FXC_ERR_RANGE},
    {"welcome camera position NaN", S_WELCOME, W_POS + 8, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"welcome camera direction zero", S_WELCOME, W_DIR, 12, 12, 0, FXC_ERR_RANGE},
    {"welcome camera direction inf", S_WELCOME, W_DIR + 4, 4, 4, F32_INF, FXC_ERR_RANGE},
    {"welcome camera fov 180", S_WELCOME, W_FOV, 4, 4, F32_180, FXC_ERR_RANGE},
    /* camera */
    {"camera time NaN", S_CAMERA, C_TIME, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"camera time inf", S_CAMERA, C_TIME, 8, 8, F64_INF, FXC_ERR_RANGE},
    {"camera position -inf", S_CAMERA, C_POS + 16, 8, 8, F64_NEG_INF, FXC_ERR_RANGE},
    {"camera direction zero", S_CAMERA, C_DIR, 12, 12, 0, FXC_ERR_RANGE},
    {"camera direction -0, 0, 0", S_CAMERA, C_DIR, 12, 12, 0x80000000u, FXC_ERR_RANGE},
    {"camera direction NaN", S_CAMERA, C_DIR + 8, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"camera fov NaN", S_CAMERA, C_FOV, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"camera fov -1", S_CAMERA, C_FOV, 4, 4, F32_NEG_ONE, FXC_ERR_RANGE},
    {"camera flag 2", S_CAMERA, C_FLAG, 1, 1, 2, FXC_ERR_RANGE},
    {"camera flag 255", S_CAMERA_PREDICTED, C_FLAG, 1, 1, 255, FXC_ERR_RANGE},
    {"camera flag 1 without the predicted part", S_CAMERA, C_FLAG, 1, 1, 1, FXC_ERR_TRUNCATED},
    {"camera flag 0 with the predicted part", S_CAMERA_PREDICTED, C_FLAG, 1, 1, 0, FXC_ERR_TRAILING},
    {"camera predicted time NaN", S_CAMERA_PREDICTED, C_PTIME, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"camera predicted position inf", S_CAMERA_PREDICTED, C_PPOS, 8, 8, F64_INF, FXC_ERR_RANGE},
    {"camera predicted direction zero", S_CAMERA_PREDICTED, C_PDIR, 12, 12, 0, FXC_ERR_RANGE},
    {"camera predicted fov 180", S_CAMERA_PREDICTED, C_PFOV, 4, 4, F32_180, FXC_ERR_RANGE},
    /* frame */
    {"frame position NaN", S_FRAME, F_POS, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"frame direction zero", S_FRAME, F_DIR, 12, 12, 0, FXC_ERR_RANGE},
    {"frame fov 0", S_FRAME, F_FOV, 4, 4, F32_ZERO, FXC_ERR_RANGE},
    {"frame width 0", S_FRAME, F_WIDTH, 4, 4, 0, FXC_ERR_RANGE},
    {"frame width 8193", S_FRAME, F_WIDTH, 4, 4, 8193, FXC_ERR_RANGE},
    {"frame height 0", S_FRAME, F_HEIGHT, 4, 4, 0, FXC_ERR_RANGE},
    {"frame height 8193", S_FRAME_DEPTH, F_HEIGHT, 4, 4, 8193, FXC_ERR_RANGE},
    {"frame codec 3", S_FRAME, F_CODEC, 1, 1, 3, FXC_ERR_RANGE},
    {"frame depth 1", S_FRAME_DEPTH, F_DEPTH, 1, 1, 1, FXC_ERR_RANGE},
    {"frame depth 64", S_FRAME_DEPTH, F_DEPTH, 1, 1, 64, FXC_ERR_RANGE},
    {"frame depth none with depth bytes", S_FRAME_DEPTH, F_DEPTH, 1, 1, PROTO_DEPTH_NONE, FXC_ERR_RANGE},
    {"frame depth half without depth bytes", S_FRAME, F_DEPTH, 1, 1, PROTO_DEPTH_HALF, FXC_ERR_RANGE},
    {"frame depth float without depth bytes", S_FRAME, F_DEPTH, 1, 1, PROTO_DEPTH_FLOAT, FXC_ERR_RANGE},
    {"frame frame_ms NaN", S_FRAME, F_FRAME_MS, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"frame frame_ms -1", S_FRAME, F_FRAME_MS, 4, 4, F32_NEG_ONE, FXC_ERR_RANGE},
    {"frame encode_ms inf", S_FRAME, F_ENCODE_MS, 4, 4, F32_INF, FXC_ERR_RANGE},
    {"frame no colour bytes", S_FRAME, F_COLOR_BYTES, 4 + 36, 4, 0, FXC_ERR_RANGE},
    {"frame colour runs past the end", S_FRAME, F_COLOR_BYTES, 4, 4, 41, FXC_ERR_TRUNCATED},
    {"frame colour count 2^32-1", S_FRAME, F_COLOR_BYTES, 4, 4, 0xffffffffu, FXC_ERR_TRUNCATED},
    {"frame depth runs past the end", S_FRAME_DEPTH, F_COLOR + 5, 4, 4, 8, FXC_ERR_TRUNCATED},
    {"frame depth count short", S_FRAME_DEPTH, F_COLOR + 5, 4, 4, 6, FXC_ERR_TRAILING},
    /* stats */
    {"stats text runs past the end", S_STATS, 0, 4, 4, sizeof stats_json, FXC_ERR_TRUNCATED},
    {"stats text shorter than its bytes", S_STATS, 0, 4, 4, 3, FXC_ERR_TRAILING},
    /* error and bye */
    {"error code 0", S_ERROR, E_CODE, 4, 4, 0, FXC_ERR_RANGE},
    {"error code 1", S_ERROR, E_CODE, 4, 4, 1, FXC_ERR_RANGE},
    {"error code INT32_MAX", S_ERROR, E_CODE, 4, 4, 0x7fffffffu, FXC_ERR_RANGE},
    {"error reason longer than 200", S_ERROR, E_REASON, 2, 2, 201, FXC_ERR_RANGE},
    {"error reason 65535 bytes", S_ERROR, E_REASON, 2, 2, 0xffff, FXC_ERR_RANGE},
    {"error reason newline", S_ERROR, E_REASON + 2 + 28, 1, 1, '\n', FXC_ERR_RANGE},
    {"error reason runs past the end", S_ERROR, E_REASON, 2, 2, 30, FXC_ERR_TRUNCATED},
    {"bye reason longer than 200", S_BYE, B_REASON, 2, 2, 201, FXC_ERR_RANGE},
    {"bye reason NUL", S_BYE, B_REASON + 2 + 6, 1, 1, 0, FXC_ERR_RANGE},
    {"bye reason 0xff", S_BYE, B_REASON + 2, 1, 1, 0xff, FXC_ERR_RANGE},
    {"bye reason shorter than its bytes", S_BYE, B_REASON, 2, 2, 13, FXC_ERR_TRAILING},
    /* sample request */
    {"request camera fov NaN", S_SAMPLE_REQUEST, SR_FOV, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"request camera direction zero", S_SAMPLE_REQUEST, SR_DIR, 12, 12, 0, FXC_ERR_RANGE},
    {"request width 0", S_SAMPLE_REQUEST, SR_WIDTH, 4, 4, 0, FXC_ERR_RANGE},
    {"request width 8193", S_SAMPLE_REQUEST, SR_WIDTH, 4, 4, 8193, FXC_ERR_RANGE},
    {"request height 0", S_SAMPLE_REQUEST, SR_HEIGHT, 4, 4, 0, FXC_ERR_RANGE},
    {"request count 0, no pixels", S_SAMPLE_REQUEST, SR_COUNT, 4 + 12, 4, 0, FXC_ERR_RANGE},
    {"request count above width*height", S_SAMPLE_REQUEST_EDGE, SR_COUNT, 4, 8, 3, FXC_ERR_RANGE},
    {"request count above 2^20", S_SAMPLE_REQUEST, SR_COUNT, 4, 4, PROTO_MAX_SAMPLES + 1, FXC_ERR_RANGE},
    {"request count 2^32-1", S_SAMPLE_REQUEST, SR_COUNT, 4, 4, 0xffffffffu, FXC_ERR_RANGE},
    {"request count 2^20 runs past the end", S_SAMPLE_REQUEST, SR_COUNT, 4, 4, PROTO_MAX_SAMPLES, FXC_ERR_TRUNCATED},
    {"request count 4 runs past the end", S_SAMPLE_REQUEST, SR_COUNT, 4, 4, 4, FXC_ERR_TRUNCATED},
    {"request count one short", S_SAMPLE_REQUEST, SR_COUNT, 4, 4, 2, FXC_ERR_TRAILING},
    {"request pixel x = width", S_SAMPLE_REQUEST, SR_PIXELS + 4, 2, 2, 640, FXC_ERR_RANGE},
    {"request pixel y = height", S_SAMPLE_REQUEST, SR_PIXELS + 6, 2, 2, 480, FXC_ERR_RANGE},
    {"request pixel x 0xffff", S_SAMPLE_REQUEST, SR_PIXELS + 8, 2, 2, 0xffff, FXC_ERR_RANGE},
    {"request pixel y 1 of height 1", S_SAMPLE_REQUEST_EDGE, SR_PIXELS + 2, 2, 2, 1, FXC_ERR_RANGE},
    /* samples */
    {"samples position inf", S_SAMPLES, SA_POS, 8, 8, F64_INF, FXC_ERR_RANGE},
    {"samples camera fov 180", S_SAMPLES, SA_FOV, 4, 4, F32_180, FXC_ERR_RANGE},
    {"samples width 0", S_SAMPLES, SA_WIDTH, 4, 4, 0, FXC_ERR_RANGE},
    {"samples height 8193", S_SAMPLES_EMPTY, SA_HEIGHT, 4, 4, 8193, FXC_ERR_RANGE},
    {"samples count above 2^20", S_SAMPLES_EMPTY, SA_COUNT, 4, 4, PROTO_MAX_SAMPLES + 1, FXC_ERR_RANGE},
    {"samples count runs past the end", S_SAMPLES, SA_COUNT, 4, 4, 3, FXC_ERR_TRUNCATED},
    {"samples count one short", S_SAMPLES, SA_COUNT, 4, 4, 1, FXC_ERR_TRAILING},
    {"samples x = width", S_SAMPLES, SA_SAMPLES, 2, 2, 4, FXC_ERR_RANGE},
    {"samples y = height", S_SAMPLES, SA_SAMPLES + 2, 2, 2, 3, FXC_ERR_RANGE},
    {"samples pad byte 1", S_SAMPLES, SA_SAMPLES + 7, 1, 1, 1, FXC_ERR_RANGE},
    {"samples second pad byte 0x80", S_SAMPLES, SA_SAMPLES + 12 + 7, 1, 1, 0x80, FXC_ERR_RANGE},
    {"samples depth NaN", S_SAMPLES, SA_SAMPLES + 8, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"samples depth 0", S_SAMPLES, SA_SAMPLES + 8, 4, 4, F32_ZERO, FXC_ERR_RANGE},
    {"samples depth -0", S_SAMPLES, SA_SAMPLES + 8, 4, 4, 0x80000000u, FXC_ERR_RANGE},
    {"samples depth -1", S_SAMPLES, SA_SAMPLES + 8, 4, 4, F32_NEG_ONE, FXC_ERR_RANGE},
    {"samples depth -inf", S_SAMPLES, SA_SAMPLES + 12 + 8, 4, 4, F32_NEG_INF, FXC_ERR_RANGE},
    /* controls: edits that stay valid, so the table's offsets are known to hit the right fields */
    {"control: request pixel x = width - 1", S_SAMPLE_REQUEST, SR_PIXELS + 4, 2, 2, 639, FXC_OK},
    {"control: request count 1", S_SAMPLE_REQUEST, SR_COUNT, 4 + 12, 8, 1, FXC_OK},
    {"control: samples depth smallest subnormal", S_SAMPLES, SA_SAMPLES + 8, 4, 4, 1, FXC_OK},
    {"control: samples depth 1e38", S_SAMPLES, SA_SAMPLES + 12 + 8, 4, 4, 0x7e967699u, FXC_OK},
    {"control: hello width 8192", S_HELLO_JPEG, HJ_WIDTH, 4, 4, 8192, FXC_OK},
    {"control: hello jpeg quality 100", S_HELLO_JPEG, HJ_QUALITY, 1, 1, 100, FXC_OK},
    {"control: hello depth 32", S_HELLO_JPEG, HJ_DEPTH, 1, 1, 32, FXC_OK},
    {"control: welcome fps 1", S_WELCOME, W_FPS, 4, 4, 0x3f800000u, FXC_OK},
    {"control: welcome bounds min y = -1", S_WELCOME, W_MIN + 8, 8, 8, 0xbff0000000000000ull, FXC_OK},
    {"control: camera direction y only", S_CAMERA, C_DIR, 12, 12, 0x3f80000000000000ull, FXC_OK},
    {"control: frame depth float", S_FRAME_DEPTH, F_DEPTH, 1, 1, PROTO_DEPTH_FLOAT, FXC_OK},
    {"control: frame frame_ms -0", S_FRAME, F_FRAME_MS, 4, 4, 0x80000000u, FXC_OK},
    {"control: error code INT32_MIN", S_ERROR, E_CODE, 4, 4, 0x80000000u, FXC_OK},
    {"control: bye reason shortened", S_BYE, B_REASON, 2 + 14, 2, 0, FXC_OK},
};

/* Each row of byte_edits applied to its sample, decoded from an exact allocation. */
static void test_field_faults(void **state)
{
    (void)state;
    for (size_t row = 0; row < sizeof byte_edits / sizeof byte_edits[0]; row++) {
        const byte_edit *e = &byte_edits[row];
        proto_msg m = sample(e->sample);
        size_t len;
        uint8_t *buf = encode_alloc(&m, &len);
        size_t at = PROTO_HEADER_BYTES + e->offset;
        assert_true(at + e->old_size <= len);
        size_t edited_len = len - e->old_size + e->new_size;
        uint8_t *edited = malloc(edited_len);
        assert_non_null(edited);
        memcpy(edited, buf, at);
        for (size_t k = 0; k < e->new_size; k++)
            edited[at + k] = k < 8 ? (uint8_t)(e->value >> (8 * k)) : 0;
        memcpy(edited + at + e->new_size, buf + at + e->old_size, len - at - e->old_size);
        proto_put_u32le(edited + 8, (uint32_t)(edited_len - PROTO_HEADER_BYTES));
        proto_msg out;
        fxc_result result = decode_copy(edited, edited_len, &out);
        if (result != e->expect)
            fail_msg("%s: %s, expected %s", e->what, fxc_strerror(result), fxc_strerror(e->expect));
        if (result != FXC_OK) { /* a refused message leaves nothing half-decoded behind */
            proto_msg zero;
            memset(&zero, 0, sizeof zero);
            assert_memory_equal(&out, &zero, sizeof out);
        }
        free(edited);
        free(buf);
    }
}

/* One change to a valid message's struct, and what proto_encode must say. */
typedef enum edit_kind { EDIT_U8, EDIT_U32, EDIT_I32, EDIT_F32, EDIT_F64, EDIT_TEXT, EDIT_FILL, EDIT_ZERO } edit_kind;
typedef struct struct_edit {
    const char *what;
    int sample;
    size_t offset; /* offsetof(proto_msg, ...) */
    edit_kind kind;
    size_t size;   /* bytes for EDIT_FILL and EDIT_ZERO */
    double number;
    const char *text;
    fxc_result expect;
} struct_edit;

#define AT(field) offsetof(proto_msg, field)

static const struct_edit struct_edits[] = {
    {"type 0", S_BYE, AT(type), EDIT_U32, 0, 0, NULL, FXC_ERR_INVALID},
    {"type 11", S_BYE, AT(type), EDIT_U32, 0, 11, NULL, FXC_ERR_INVALID},
    {"hello name control byte", S_HELLO_JPEG, AT(u.hello.name), EDIT_TEXT, 0, 0, "a\x02", FXC_ERR_RANGE},
    {"hello name unterminated", S_HELLO_JPEG, AT(u.hello.name), EDIT_FILL, PROTO_NAME_MAX + 1, 0, NULL, FXC_ERR_RANGE},
    {"hello name non-ASCII", S_HELLO_JPEG, AT(u.hello.name), EDIT_TEXT, 0, 0, "caf\xc3\xa9", FXC_ERR_RANGE},
    {"hello width 0", S_HELLO_JPEG, AT(u.hello.width), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"hello width 8193", S_HELLO_JPEG, AT(u.hello.width), EDIT_U32, 0, 8193, NULL, FXC_ERR_RANGE},
    {"hello height 0", S_HELLO_JPEG, AT(u.hello.height), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"hello fov 0", S_HELLO_JPEG, AT(u.hello.fov_deg), EDIT_F32, 0, 0, NULL, FXC_ERR_RANGE},
    {"hello fov 180", S_HELLO_JPEG, AT(u.hello.fov_deg), EDIT_F32, 0, 180, NULL, FXC_ERR_RANGE},
    {"hello fov NaN", S_HELLO_JPEG, AT(u.hello.fov_deg), EDIT_F32, 0, NAN, NULL, FXC_ERR_RANGE},
    {"hello codec 3", S_HELLO_RAW, AT(u.hello.codec), EDIT_U8, 0, 3, NULL, FXC_ERR_RANGE},
    {"hello jpeg quality 0", S_HELLO_JPEG, AT(u.hello.jpeg_quality), EDIT_U8, 0, 0, NULL, FXC_ERR_RANGE},
    {"hello jpeg quality 101", S_HELLO_JPEG, AT(u.hello.jpeg_quality), EDIT_U8, 0, 101, NULL, FXC_ERR_RANGE},
    {"hello zstd with a quality", S_HELLO_ZSTD, AT(u.hello.jpeg_quality), EDIT_U8, 0, 90, NULL, FXC_ERR_RANGE},
    {"hello depth 8", S_HELLO_JPEG, AT(u.hello.depth), EDIT_U8, 0, 8, NULL, FXC_ERR_RANGE},
    {"hello token unterminated", S_HELLO_JPEG, AT(u.hello.token), EDIT_FILL, PROTO_TOKEN_MAX + 1, 0, NULL, FXC_ERR_RANGE},
    {"hello strategy tab", S_HELLO_JPEG, AT(u.hello.strategy), EDIT_TEXT, 0, 0, "a\tb", FXC_ERR_RANGE},
    {"welcome viewer id 0", S_WELCOME, AT(u.welcome.viewer_id), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"welcome empty name", S_WELCOME, AT(u.welcome.name), EDIT_TEXT, 0, 0, "", FXC_ERR_RANGE},
    {"welcome fps 0", S_WELCOME, AT(u.welcome.fps), EDIT_F32, 0, 0, NULL, FXC_ERR_RANGE},
    {"welcome fps inf", S_WELCOME, AT(u.welcome.fps), EDIT_F32, 0, INFINITY, NULL, FXC_ERR_RANGE},
    {"welcome fps NaN", S_WELCOME, AT(u.welcome.fps), EDIT_F32, 0, NAN, NULL, FXC_ERR_RANGE},
    {"welcome bounds min x NaN", S_WELCOME, AT(u.welcome.bounds_min[0]), EDIT_F64, 0, NAN, NULL, FXC_ERR_RANGE},
    {"welcome bounds max y > min y fails", S_WELCOME, AT(u.welcome.bounds_max[1]), EDIT_F64, 0, -1, NULL, FXC_ERR_RANGE},
    {"welcome camera fov 180", S_WELCOME, AT(u.welcome.camera.fov_deg), EDIT_F32, 0, 180, NULL, FXC_ERR_RANGE},
    {"welcome camera direction zero", S_WELCOME, AT(u.welcome.camera.direction), EDIT_ZERO, 12, 0, NULL, FXC_ERR_RANGE},
    {"camera time inf", S_CAMERA, AT(u.camera.time), EDIT_F64, 0, -INFINITY, NULL, FXC_ERR_RANGE},
    {"camera position NaN", S_CAMERA, AT(u.camera.pose.position[2]), EDIT_F64, 0, NAN, NULL, FXC_ERR_RANGE},
    {"camera direction inf", S_CAMERA, AT(u.camera.pose.direction[0]), EDIT_F32, 0, INFINITY, NULL, FXC_ERR_RANGE},
    {"camera predicted time NaN", S_CAMERA_PREDICTED, AT(u.camera.predicted_time), EDIT_F64, 0, NAN, NULL, FXC_ERR_RANGE},
    {"camera predicted direction zero", S_CAMERA_PREDICTED, AT(u.camera.predicted.direction), EDIT_ZERO, 12, 0, NULL, FXC_ERR_RANGE},
    {"camera predicted ignored without flag", S_CAMERA, AT(u.camera.predicted_time), EDIT_F64, 0, NAN, NULL, FXC_OK},
    {"frame width 8193", S_FRAME, AT(u.frame.width), EDIT_U32, 0, 8193, NULL, FXC_ERR_RANGE},
    {"frame height 0", S_FRAME, AT(u.frame.height), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"frame codec 3", S_FRAME, AT(u.frame.codec), EDIT_U8, 0, 3, NULL, FXC_ERR_RANGE},
    {"frame depth 8", S_FRAME_DEPTH, AT(u.frame.depth), EDIT_U8, 0, 8, NULL, FXC_ERR_RANGE},
    {"frame depth none with depth bytes", S_FRAME_DEPTH, AT(u.frame.depth), EDIT_U8, 0, 0, NULL, FXC_ERR_RANGE},
    {"frame depth half without bytes", S_FRAME, AT(u.frame.depth), EDIT_U8, 0, 16, NULL, FXC_ERR_RANGE},
    {"frame no colour", S_FRAME, AT(u.frame.color_bytes), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"frame frame_ms NaN", S_FRAME, AT(u.frame.stats.frame_ms), EDIT_F32, 0, NAN, NULL, FXC_ERR_RANGE},
    {"frame encode_ms -1", S_FRAME, AT(u.frame.stats.encode_ms), EDIT_F32, 0, -1, NULL, FXC_ERR_RANGE},
    {"frame camera fov NaN", S_FRAME, AT(u.frame.camera.fov_deg), EDIT_F32, 0, NAN, NULL, FXC_ERR_RANGE},
    {"frame colour NULL", S_FRAME, AT(u.frame.color), EDIT_ZERO, sizeof(void *), 0, NULL, FXC_ERR_INVALID},
    {"frame depth NULL", S_FRAME_DEPTH, AT(u.frame.depth_data), EDIT_ZERO, sizeof(void *), 0, NULL, FXC_ERR_INVALID},
    {"frame colour over 1 GiB", S_FRAME, AT(u.frame.color_bytes), EDIT_U32, 0, PROTO_MAX_PAYLOAD, NULL, FXC_ERR_TOO_LARGE},
    {"stats text NULL", S_STATS, AT(u.stats.json), EDIT_ZERO, sizeof(void *), 0, NULL, FXC_ERR_INVALID},
    {"stats text 4 GiB", S_STATS, AT(u.stats.json_bytes), EDIT_U32, 0, 4294967295.0, NULL, FXC_ERR_TOO_LARGE},
    {"error code 0", S_ERROR, AT(u.error.code), EDIT_I32, 0, 0, NULL, FXC_ERR_RANGE},
    {"error code 5", S_ERROR, AT(u.error.code), EDIT_I32, 0, 5, NULL, FXC_ERR_RANGE},
    {"error reason newline", S_ERROR, AT(u.error.reason), EDIT_TEXT, 0, 0, "line\n", FXC_ERR_RANGE},
    {"error reason unterminated", S_ERROR, AT(u.error.reason), EDIT_FILL, PROTO_REASON_MAX + 1, 0, NULL, FXC_ERR_RANGE},
    {"bye reason DEL", S_BYE, AT(u.bye.reason), EDIT_TEXT, 0, 0, "\x7f", FXC_ERR_RANGE},
    {"request pixels NULL", S_SAMPLE_REQUEST, AT(u.sample_request.pixels), EDIT_ZERO, sizeof(void *), 0, NULL, FXC_ERR_INVALID},
    {"request count 0", S_SAMPLE_REQUEST, AT(u.sample_request.count), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"request count above width*height", S_SAMPLE_REQUEST_EDGE, AT(u.sample_request.count), EDIT_U32, 0, 3, NULL, FXC_ERR_RANGE},
    {"request count above 2^20", S_SAMPLE_REQUEST, AT(u.sample_request.count), EDIT_U32, 0, PROTO_MAX_SAMPLES + 1, NULL, FXC_ERR_RANGE},
    {"request width 2^16", S_SAMPLE_REQUEST, AT(u.sample_request.width), EDIT_U32, 0, 65536, NULL, FXC_ERR_RANGE},
    {"request height 1 (pixel y 479)", S_SAMPLE_REQUEST, AT(u.sample_request.height), EDIT_U32, 0, 1, NULL, FXC_ERR_RANGE},
    {"request camera fov 0", S_SAMPLE_REQUEST, AT(u.sample_request.camera.fov_deg), EDIT_F32, 0, 0, NULL, FXC_ERR_RANGE},
    {"samples NULL with a count", S_SAMPLES, AT(u.samples.samples), EDIT_ZERO, sizeof(void *), 0, NULL, FXC_ERR_INVALID},
    {"samples width 3 (x 3)", S_SAMPLES, AT(u.samples.width), EDIT_U32, 0, 3, NULL, FXC_ERR_RANGE},
    {"samples count above 2^20", S_SAMPLES_EMPTY, AT(u.samples.count), EDIT_U32, 0, PROTO_MAX_SAMPLES + 1, NULL, FXC_ERR_RANGE},
    {"control: samples NULL without a count", S_SAMPLES_EMPTY, AT(u.samples.samples), EDIT_ZERO, sizeof(void *), 0, NULL, FXC_OK},
    {"control: request width 8192", S_SAMPLE_REQUEST, AT(u.sample_request.width), EDIT_U32, 0, 8192, NULL, FXC_OK},
    {"control: bye reason of 200", S_BYE, AT(u.bye.reason), EDIT_FILL, PROTO_REASON_MAX, 0, NULL, FXC_OK},
};

static void apply_struct_edit(const struct_edit *e, proto_msg *m)
{
    uint8_t *at = (uint8_t *)m + e->offset;
    switch (e->kind) {
    case EDIT_U8: {
        uint8_t v = (uint8_t)e->number;
        memcpy(at, &v, sizeof v);
        break;
    }
    case EDIT_U32: {
        uint32_t v = (uint32_t)e->number;
        memcpy(at, &v, sizeof v);
        break;
    }
    case EDIT_I32: {
        int32_t v = (int32_t)e->number;
        memcpy(at, &v, sizeof v);
        break;
    }
    case EDIT_F32: {
        float v = (float)e->number;
        memcpy(at, &v, sizeof v);
        break;
    }
    case EDIT_F64:
        memcpy(at, &e->number, sizeof e->number);
        break;
    case EDIT_TEXT:
        memcpy(at, e->text, strlen(e->text) + 1);
        break;
    case EDIT_FILL:
        memset(at, 'a', e->size);
        break;
    case EDIT_ZERO:
        memset(at, 0, e->size);
        break;
    }
}

/* Each row of struct_edits: proto_bound is 0 and proto_encode writes nothing and says why; the controls
 * encode and decode. */
static void test_encode_refusals(void **state)
{
    (void)state;
    uint8_t buf[2048];
    for (size_t row = 0; row < sizeof struct_edits / sizeof struct_edits[0]; row++) {
        const struct_edit *e = &struct_edits[row];
        proto_msg m = sample(e->sample);
        apply_struct_edit(e, &m);
        fxc_result result = FXC_OK;
        memset(buf, 0xaa, sizeof buf);
        size_t written = proto_encode(&m, buf, sizeof buf, &result);
        if (result != e->expect)
            fail_msg("%s: %s, expected %s", e->what, fxc_strerror(result), fxc_strerror(e->expect));
        if (e->expect != FXC_OK) {
            assert_int_equal(written, 0);
            assert_int_equal(proto_bound(&m), 0);
            assert_int_equal(buf[0], 0xaa);
        } else {
            proto_msg out;
            assert_int_equal(written, proto_bound(&m));
            assert_int_equal(proto_decode(buf, written, &out), FXC_OK);
        }
    }
    /* A NULL message, a NULL result pointer. */
    fxc_result result = FXC_OK;
    assert_int_equal(proto_encode(NULL, buf, sizeof buf, &result), 0);
    assert_int_equal(result, FXC_ERR_INVALID);
    assert_int_equal(proto_bound(NULL), 0);
    proto_msg bad = sample(S_ERROR);
    bad.u.error.code = 0;
    assert_int_equal(proto_encode(&bad, buf, sizeof buf, NULL), 0);
}

/* A buffer one byte short (an exact allocation, so a write past it is seen), or none, is TOO_LARGE. */
static void test_encode_capacity(void **state)
{
    (void)state;
    for (int i = 0; i < SAMPLE_COUNT; i++) {
        proto_msg m = sample(i);
        size_t bound = proto_bound(&m);
        for (size_t cap = 0; cap < bound; cap += (cap < PROTO_HEADER_BYTES + 2 || cap + 2 >= bound) ? 1 : 7) {
            uint8_t *buf = malloc(cap ? cap : 1);
            assert_non_null(buf);
            fxc_result result = FXC_OK;
            assert_int_equal(proto_encode(&m, buf, cap, &result), 0);
            assert_int_equal(result, FXC_ERR_TOO_LARGE);
            free(buf);
        }
        fxc_result result = FXC_OK;
        assert_int_equal(proto_encode(&m, NULL, 0, &result), 0);
        assert_int_equal(result, FXC_ERR_TOO_LARGE);
    }
}

/* Random edits of valid messages: every result is one of the decoder's codes, and whatever decodes encodes
 * back to exactly the same bytes (the encoding is canonical). */
static void test_mutations(void **state)
{
    (void)state;
    uint32_t rng = 0x5eed1234u;
    unsigned decoded = 0;
    uint8_t again[4096];
    for (int iteration = 0; iteration < 40000; iteration++) {
        proto_msg m = sample(iteration % SAMPLE_COUNT);
        size_t len;
        uint8_t *buf = encode_alloc(&m, &len);
        int edits = 1 + (int)(fxt_random(&rng) % 3);
        for (int e = 0; e < edits; e++) {
            size_t at = fxt_random(&rng) % len;
            switch (fxt_random(&rng) % 4) {
            case 0:
                buf[at] = (uint8_t)fxt_random(&rng);
                break;
            case 1:
                buf[at] ^= (uint8_t)(1u << (fxt_random(&rng) % 8));
                break;
            case 2:
                buf[at] = (uint8_t)(buf[at] + 1);
                break;
            default:
                len = at > PROTO_HEADER_BYTES ? at : len; /* cut */
                break;
            }
        }
        if (fxt_random(&rng) % 2) /* keep the header's length consistent, so payload faults are reached */
            proto_put_u32le(buf + 8, (uint32_t)(len - PROTO_HEADER_BYTES));
        proto_msg out;
        fxc_result result = decode_copy(buf, len, &out);
        switch (result) {
        case FXC_OK: {
            decoded++;
            /* The copy is gone, so decode again from buf (payload pointers must point into a live buffer). */
            assert_int_equal(proto_decode(buf, len, &out), FXC_OK);
            fxc_result encoded = FXC_ERR_INVALID;
            size_t n = proto_encode(&out, again, sizeof again, &encoded);
            assert_int_equal(encoded, FXC_OK);
            assert_int_equal(n, len);
            assert_memory_equal(again, buf, len);
            break;
        }
        case FXC_ERR_TRUNCATED:
        case FXC_ERR_TRAILING:
        case FXC_ERR_BAD_MAGIC:
        case FXC_ERR_VERSION:
        case FXC_ERR_TOO_LARGE:
        case FXC_ERR_UNKNOWN_TYPE:
        case FXC_ERR_RANGE:
            break;
        default:
            fail_msg("unexpected %s", fxc_strerror(result));
        }
        free(buf);
    }
    assert_true(decoded > 1000); /* the loop reaches valid messages too, not only refusals */
}

/* ---- the fuzz corpus --------------------------------------------------------------------------------- */

/* Every seed of tests/fuzz/corpus_proto (crash-* and leak-* files aside: those are inputs the fuzzer once
 * found, kept to be refused) decodes, with its payloads; together they cover every type, codec and depth. */
static void test_corpus(void **state)
{
    (void)state;
    const char *dir_path = FXC_SOURCE_DIR "/tests/fuzz/corpus_proto";
    DIR *dir = opendir(dir_path);
    if (!dir)
        fail_msg("cannot open %s", dir_path);
    unsigned types_seen = 0, codecs_seen = 0, depths_seen = 0, seeds = 0;
    struct dirent *entry;
    while ((entry = readdir(dir)) != NULL) {
        const char *name = entry->d_name;
        if (name[0] == '.' || strcmp(name, "README.md") == 0)
            continue;
        char path[1024];
        snprintf(path, sizeof path, "%s/%s", dir_path, name);
        FILE *f = fopen(path, "rb");
        assert_non_null(f);
        static uint8_t buf[1 << 16];
        size_t len = fread(buf, 1, sizeof buf, f);
        fclose(f);
        assert_true(len < sizeof buf);
        proto_msg m;
        fxc_result result = decode_copy(buf, len, &m);
        if (strncmp(name, "crash-", 6) == 0 || strncmp(name, "leak-", 5) == 0)
            continue; /* found by the fuzzer: it must merely not crash, which decoding it just showed */
        if (result != FXC_OK)
            fail_msg("%s: %s", name, fxc_strerror(result));
        seeds++;
        assert_int_equal(proto_decode(buf, len, &m), FXC_OK);
        types_seen |= 1u << m.type;
        if (m.type == PROTO_FRAME) {
            const proto_frame *fr = &m.u.frame;
            codecs_seen |= 1u << fr->codec;
            depths_seen |= 1u << (fr->depth / 16);
            uint8_t *rgb = malloc((size_t)fr->width * fr->height * 3);
            float *depth = malloc((size_t)fr->width * fr->height * sizeof(float));
            assert_non_null(rgb);
            assert_non_null(depth);
            if (proto_color_decode(fr->codec, fr->color, fr->color_bytes, fr->width, fr->height, rgb) != FXC_OK)
                fail_msg("%s: the colour does not decode", name);
            if (fr->depth != PROTO_DEPTH_NONE &&
                proto_depth_decode(fr->depth, fr->depth_data, fr->depth_bytes, fr->width, fr->height, depth) != FXC_OK)
                fail_msg("%s: the depth does not decode", name);
            free(depth);
            free(rgb);
        }
    }
    closedir(dir);
    assert_true(seeds >= 8);
    assert_int_equal(types_seen, 0x7feu);  /* types 1..10 */
    assert_int_equal(codecs_seen, 0x7u);   /* raw, zstd, jpeg */
    assert_int_equal(depths_seen, 0x7u);   /* none, half, float */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_byte_order),
        cmocka_unit_test(test_names),
        cmocka_unit_test(test_sample_entries),
        cmocka_unit_test(test_round_trip),
        cmocka_unit_test(test_documented_offsets),
        cmocka_unit_test(test_every_prefix),
        cmocka_unit_test(test_trailing),
        cmocka_unit_test(test_header_faults),
        cmocka_unit_test(test_field_faults),
        cmocka_unit_test(test_encode_refusals),
        cmocka_unit_test(test_encode_capacity),
        cmocka_unit_test(test_mutations),
        cmocka_unit_test(test_corpus),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
