/* Tests of the wire format (proto/proto.c); the payload codecs' are in test_proto_codec.c.
 *
 * Messages: byte order against literal bytes; every sample message (every type, optional parts present and
 * absent, strings empty and at their maximum) round-trips with proto_bound == bytes written and its header
 * and field offsets where docs/PROTOCOL.md puts them; every prefix of every sample, each in its own
 * allocation, is TRUNCATED; an extra byte, undeclared or declared, is TRAILING; the committed fuzz corpus
 * decodes, with its payloads. The sample messages are tests/fxt_proto.h's; the faults (headers, fields,
 * encode refusals, mutations) are in test_proto_faults.c. */
#include "test_util.h"

#include "fxt_proto.h"
#include "proto.h"

#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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
    static const char *const types[] = {NULL,    "hello",          "welcome", "camera",
                                        "frame", "stats-request",  "stats",   "error",
                                        "bye",   "sample-request", "samples"};
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
    } strategies[] = {{"", PROTO_STRATEGY_BASIC},
                      {"basic", PROTO_STRATEGY_BASIC},
                      {"fan", PROTO_STRATEGY_FAN},
                      {"predictive", PROTO_STRATEGY_PREDICTIVE},
                      {"Basic", -1},
                      {"fan ", -1},
                      {"nearest", -1},
                      {"predict", -1}};
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
    proto_request_pixel_get(fxt_request_pixels, 1, &x, &y);
    assert_int_equal(x, 639);
    assert_int_equal(y, 479);

    uint8_t samples[24];
    memset(samples, 0xaa, sizeof samples);
    proto_sample s = {3, 2, {10, 20, 30}, 2.5f};
    proto_sample_put(samples, 0, &s);
    s = (proto_sample){0, 0, {255, 0, 128}, INFINITY};
    proto_sample_put(samples, 1, &s);
    assert_memory_equal(samples, fxt_samples_bytes, sizeof samples); /* the pad byte is written 0 */
    proto_sample back;
    proto_sample_get(fxt_samples_bytes, 0, &back);
    assert_int_equal(back.x, 3);
    assert_int_equal(back.y, 2);
    assert_int_equal(back.rgb[0], 10);
    assert_int_equal(back.rgb[2], 30);
    assert_true(back.depth == 2.5f);
    proto_sample_get(fxt_samples_bytes, 1, &back);
    assert_int_equal(back.rgb[0], 255);
    assert_true(isinf(back.depth) && back.depth > 0.0f);
}

/* ---- messages --------------------------------------------------------------------------------------- */

/* Every sample: bound == written == 12 + the hand-counted payload, the header as documented, decode gives
 * back every field, and the frame's payloads point into the buffer. */
static void test_round_trip(void **state)
{
    (void)state;
    for (int i = 0; i < FXT_SAMPLE_COUNT; i++) {
        proto_msg m = fxt_proto_sample(i);
        size_t len;
        uint8_t *buf = fxt_encode_alloc(&m, &len);
        assert_int_equal(len, PROTO_HEADER_BYTES + fxt_sample_payload_bytes[i]);
        assert_memory_equal(buf, "FXCP", 4);
        assert_int_equal(buf[4], PROTO_VERSION);
        assert_int_equal(buf[5], 0);
        assert_int_equal(buf[6], m.type);
        assert_int_equal(buf[7], 0);
        assert_int_equal(proto_get_u32le(buf + 8), fxt_sample_payload_bytes[i]);
        proto_header h;
        assert_int_equal(proto_decode_header(buf, len, &h), FXC_OK);
        assert_int_equal(h.version, PROTO_VERSION);
        assert_int_equal(h.type, m.type);
        assert_int_equal(h.length, fxt_sample_payload_bytes[i]);
        proto_msg back;
        fxc_result result = proto_decode(buf, len, &back);
        if (result != FXC_OK)
            fail_msg("sample %d (%s): %s", i, proto_type_name(m.type), fxc_strerror(result));
        fxt_assert_same_message(&m, &back);
        if (m.type == PROTO_FRAME) {
            /* The colour count sits at payload offset 106, the colour bytes right after it. */
            assert_ptr_equal(back.u.frame.color, buf + PROTO_HEADER_BYTES + 110);
            assert_int_equal(proto_get_u32le(buf + PROTO_HEADER_BYTES + 106), m.u.frame.color_bytes);
            if (m.u.frame.depth_bytes)
                assert_ptr_equal(back.u.frame.depth_data,
                                 buf + PROTO_HEADER_BYTES + 114 + m.u.frame.color_bytes);
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
        if (i == FXT_S_CAMERA) {
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
    proto_msg m = fxt_proto_sample(FXT_S_HELLO_JPEG);
    uint8_t *buf = fxt_encode_alloc(&m, &len);
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

    m = fxt_proto_sample(FXT_S_WELCOME);
    buf = fxt_encode_alloc(&m, &len);
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

    m = fxt_proto_sample(FXT_S_CAMERA_PREDICTED);
    buf = fxt_encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p), 0xfffffffeu);
    assert_int_equal(p[52], 1);
    assert_int_equal(proto_get_u32le(p + 97), fxt_bits_from_float(0.001f));
    free(buf);

    m = fxt_proto_sample(FXT_S_FRAME_DEPTH);
    buf = fxt_encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p + 48), PROTO_MAX_SIDE);
    assert_int_equal(p[56], PROTO_CODEC_ZSTD);
    assert_int_equal(p[57], 16);
    assert_true(proto_get_u64le(p + 58) == UINT64_MAX);
    assert_int_equal(proto_get_u32le(p + 102), fxt_bits_from_float(2.5f));
    assert_int_equal(proto_get_u32le(p + 115), 7);
    free(buf);

    m = fxt_proto_sample(FXT_S_ERROR);
    buf = fxt_encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p), (uint32_t)FXC_ERR_UNAUTHORIZED);
    assert_int_equal(proto_get_u16le(p + 4), 29);
    free(buf);

    m = fxt_proto_sample(FXT_S_SAMPLE_REQUEST);
    buf = fxt_encode_alloc(&m, &len);
    p = buf + PROTO_HEADER_BYTES;
    assert_int_equal(proto_get_u32le(p), 0x01020304u);
    assert_int_equal(proto_get_u32le(p + 40), fxt_bits_from_float(60.0f)); /* camera fov */
    assert_int_equal(proto_get_u32le(p + 44), 640);
    assert_int_equal(proto_get_u32le(p + 48), 480);
    assert_int_equal(proto_get_u32le(p + 52), 3);
    assert_int_equal(proto_get_u16le(p + 60), 639);
    assert_int_equal(proto_get_u16le(p + 62), 479);
    free(buf);

    m = fxt_proto_sample(FXT_S_SAMPLES);
    buf = fxt_encode_alloc(&m, &len);
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
    for (int i = 0; i < FXT_SAMPLE_COUNT; i++) {
        proto_msg m = fxt_proto_sample(i);
        size_t len;
        uint8_t *buf = fxt_encode_alloc(&m, &len);
        for (size_t prefix = 0; prefix < len; prefix++) {
            proto_msg out;
            fxc_result result = fxt_decode_copy(buf, prefix, &out);
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
    for (int i = 0; i < FXT_SAMPLE_COUNT; i++) {
        proto_msg m = fxt_proto_sample(i);
        size_t len;
        uint8_t *buf = fxt_encode_alloc(&m, &len);
        uint8_t *longer = malloc(len + 1);
        assert_non_null(longer);
        memcpy(longer, buf, len);
        longer[len] = 0;
        proto_msg out;
        assert_int_equal(fxt_decode_copy(longer, len + 1, &out), FXC_ERR_TRAILING);
        proto_put_u32le(longer + 8, proto_get_u32le(longer + 8) + 1);
        assert_int_equal(fxt_decode_copy(longer, len + 1, &out), FXC_ERR_TRAILING);
        free(longer);
        free(buf);
    }
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
        fxc_result result = fxt_decode_copy(buf, len, &m);
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
            if (proto_color_decode(fr->codec, fr->color, fr->color_bytes, fr->width, fr->height, rgb) !=
                FXC_OK)
                fail_msg("%s: the colour does not decode", name);
            if (fr->depth != PROTO_DEPTH_NONE &&
                proto_depth_decode(fr->depth, fr->depth_data, fr->depth_bytes, fr->width, fr->height,
                                   depth) != FXC_OK)
                fail_msg("%s: the depth does not decode", name);
            free(depth);
            free(rgb);
        }
    }
    closedir(dir);
    assert_true(seeds >= 8);
    assert_int_equal(types_seen, 0x7feu); /* types 1..10 */
    assert_int_equal(codecs_seen, 0x7u);  /* raw, zstd, jpeg */
    assert_int_equal(depths_seen, 0x7u);  /* none, half, float */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_byte_order),         cmocka_unit_test(test_names),
        cmocka_unit_test(test_sample_entries),     cmocka_unit_test(test_round_trip),
        cmocka_unit_test(test_documented_offsets), cmocka_unit_test(test_every_prefix),
        cmocka_unit_test(test_trailing),           cmocka_unit_test(test_corpus),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
