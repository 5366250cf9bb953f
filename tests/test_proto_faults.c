/* Tests of the wire format (proto/proto.c) against malformed input, with tests/fxt_proto.h's sample messages:
 * header faults have their own codes; one table changes one field's bytes per row and expects RANGE (or
 * TRUNCATED/TRAILING for length fields), another changes one struct field and expects proto_encode to refuse;
 * every buffer shorter than the bound is refused; a bounded mutation loop checks that whatever decodes
 * re-encodes to the same bytes. The round trips, offsets, prefixes and the fuzz corpus are in test_proto.c.
 */
#include "test_util.h"

#include "fxt_proto.h"
#include "proto.h"

#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void test_header_faults(void **state)
{
    (void)state;
    proto_msg m = fxt_proto_sample(FXT_S_BYE);
    size_t len;
    uint8_t *buf = fxt_encode_alloc(&m, &len);
    proto_msg out;
    for (int k = 0; k < 4; k++) { /* each magic byte */
        buf[k] ^= 0x20;
        assert_int_equal(fxt_decode_copy(buf, len, &out), FXC_ERR_BAD_MAGIC);
        assert_int_equal(proto_decode_header(buf, len, NULL), FXC_ERR_BAD_MAGIC);
        buf[k] ^= 0x20;
    }
    static const uint16_t bad_versions[] = {0, PROTO_VERSION + 1, 0xffff};
    for (size_t k = 0; k < sizeof bad_versions / sizeof bad_versions[0]; k++) {
        proto_put_u16le(buf + 4, bad_versions[k]);
        assert_int_equal(fxt_decode_copy(buf, len, &out), FXC_ERR_VERSION);
        /* The magic is checked before the version. */
        buf[0] = 'G';
        assert_int_equal(fxt_decode_copy(buf, len, &out), FXC_ERR_BAD_MAGIC);
        buf[0] = 'F';
    }
    proto_put_u16le(buf + 4, PROTO_VERSION);
    static const uint16_t bad_types[] = {0, 11, 0x100 | PROTO_BYE, 0xffff};
    for (size_t k = 0; k < sizeof bad_types / sizeof bad_types[0]; k++) {
        proto_put_u16le(buf + 6, bad_types[k]);
        assert_int_equal(fxt_decode_copy(buf, len, &out), FXC_ERR_UNKNOWN_TYPE);
    }
    proto_put_u16le(buf + 6, PROTO_BYE);
    assert_int_equal(fxt_decode_copy(buf, len, &out), FXC_OK);

    /* The length: above the maximum is TOO_LARGE from the 12 header bytes alone; at it, the header is fine
     * and the message is merely truncated. */
    uint8_t header[PROTO_HEADER_BYTES];
    memcpy(header, buf, sizeof header);
    proto_put_u32le(header + 8, PROTO_MAX_PAYLOAD + 1u);
    assert_int_equal(proto_decode_header(header, sizeof header, NULL), FXC_ERR_TOO_LARGE);
    assert_int_equal(fxt_decode_copy(header, sizeof header, &out), FXC_ERR_TOO_LARGE);
    proto_put_u32le(header + 8, 0xffffffffu);
    assert_int_equal(fxt_decode_copy(header, sizeof header, &out), FXC_ERR_TOO_LARGE);
    proto_put_u32le(header + 8, PROTO_MAX_PAYLOAD);
    proto_header h;
    assert_int_equal(proto_decode_header(header, sizeof header, &h), FXC_OK);
    assert_int_equal(h.length, PROTO_MAX_PAYLOAD);
    assert_int_equal(fxt_decode_copy(header, sizeof header, &out), FXC_ERR_TRUNCATED);
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

#define F32_NAN     0x7fc00000u
#define F32_INF     0x7f800000u
#define F32_NEG_INF 0xff800000u
#define F32_ZERO    0x00000000u
#define F32_NEG_ONE 0xbf800000u
#define F32_180     0x43340000u
#define F64_NAN     0x7ff8000000000000ull
#define F64_INF     0x7ff0000000000000ull
#define F64_NEG_INF 0xfff0000000000000ull
#define F64_ONE     0x3ff0000000000000ull

/* Payload offsets of the samples' fields (docs/PROTOCOL.md), with their string lengths in. */
enum {
    /* hello "alice"/"secret-token"/"nearest"; FXT_S_HELLO_RAW has empty strings: width at 1 */
    HJ_NAME = 0,
    HJ_WIDTH = 6,
    HJ_HEIGHT = 10,
    HJ_FOV = 14,
    HJ_CODEC = 18,
    HJ_QUALITY = 19,
    HJ_DEPTH = 20,
    HJ_TOKEN = 21,
    HJ_STRATEGY = 34,
    HR_QUALITY = 14,
    HR_TOKEN = 16,
    HR_STRATEGY = 17,
    /* welcome "viewer_07" */
    W_ID = 0,
    W_NAME = 4,
    W_FPS = 14,
    W_MIN = 18,
    W_MAX = 42,
    W_POS = 66,
    W_DIR = 90,
    W_FOV = 102,
    /* camera (FXT_S_CAMERA_PREDICTED for the predicted part) */
    C_TIME = 4,
    C_POS = 12,
    C_DIR = 36,
    C_FOV = 48,
    C_FLAG = 52,
    C_PTIME = 53,
    C_PPOS = 61,
    C_PDIR = 85,
    C_PFOV = 97,
    /* frame */
    F_POS = 8,
    F_DIR = 32,
    F_FOV = 44,
    F_WIDTH = 48,
    F_HEIGHT = 52,
    F_CODEC = 56,
    F_DEPTH = 57,
    F_FRAME_MS = 98,
    F_ENCODE_MS = 102,
    F_COLOR_BYTES = 106,
    F_COLOR = 110,
    /* error and bye */
    E_CODE = 0,
    E_REASON = 4,
    B_REASON = 0,
    /* sample request and samples */
    SR_FOV = 40,
    SR_DIR = 28,
    SR_WIDTH = 44,
    SR_HEIGHT = 48,
    SR_COUNT = 52,
    SR_PIXELS = 56,
    SA_POS = 8,
    SA_FOV = 44,
    SA_WIDTH = 48,
    SA_HEIGHT = 52,
    SA_COUNT = 56,
    SA_SAMPLES = 60,
};

static const byte_edit byte_edits[] = {
    /* hello */
    {"hello name longer than 31", FXT_S_HELLO_JPEG, HJ_NAME, 1, 1, 32, FXC_ERR_RANGE},
    {"hello name control byte", FXT_S_HELLO_JPEG, HJ_NAME + 3, 1, 1, 0x01, FXC_ERR_RANGE},
    {"hello name DEL byte", FXT_S_HELLO_JPEG, HJ_NAME + 1, 1, 1, 0x7f, FXC_ERR_RANGE},
    {"hello name non-ASCII byte", FXT_S_HELLO_JPEG, HJ_NAME + 5, 1, 1, 0xc3, FXC_ERR_RANGE},
    {"hello name NUL byte", FXT_S_HELLO_JPEG, HJ_NAME + 2, 1, 1, 0x00, FXC_ERR_RANGE},
    {"hello width 0", FXT_S_HELLO_JPEG, HJ_WIDTH, 4, 4, 0, FXC_ERR_RANGE},
    {"hello width 8193", FXT_S_HELLO_JPEG, HJ_WIDTH, 4, 4, 8193, FXC_ERR_RANGE},
    {"hello height 0", FXT_S_HELLO_JPEG, HJ_HEIGHT, 4, 4, 0, FXC_ERR_RANGE},
    {"hello height 2^32-1", FXT_S_HELLO_JPEG, HJ_HEIGHT, 4, 4, 0xffffffffu, FXC_ERR_RANGE},
    {"hello fov 0", FXT_S_HELLO_JPEG, HJ_FOV, 4, 4, F32_ZERO, FXC_ERR_RANGE},
    {"hello fov 180", FXT_S_HELLO_JPEG, HJ_FOV, 4, 4, F32_180, FXC_ERR_RANGE},
    {"hello fov NaN", FXT_S_HELLO_JPEG, HJ_FOV, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"hello fov -inf", FXT_S_HELLO_JPEG, HJ_FOV, 4, 4, F32_NEG_INF, FXC_ERR_RANGE},
    {"hello codec 3", FXT_S_HELLO_JPEG, HJ_CODEC, 1, 1, PROTO_CODEC_COUNT, FXC_ERR_RANGE},
    {"hello codec 255", FXT_S_HELLO_JPEG, HJ_CODEC, 1, 1, 255, FXC_ERR_RANGE},
    {"hello jpeg quality 0", FXT_S_HELLO_JPEG, HJ_QUALITY, 1, 1, 0, FXC_ERR_RANGE},
    {"hello jpeg quality 101", FXT_S_HELLO_JPEG, HJ_QUALITY, 1, 1, 101, FXC_ERR_RANGE},
    {"hello raw with a quality", FXT_S_HELLO_RAW, HR_QUALITY, 1, 1, 50, FXC_ERR_RANGE},
    {"hello quality kept, codec raw", FXT_S_HELLO_JPEG, HJ_CODEC, 1, 1, PROTO_CODEC_RAW, FXC_ERR_RANGE},
    {"hello depth 1", FXT_S_HELLO_JPEG, HJ_DEPTH, 1, 1, 1, FXC_ERR_RANGE},
    {"hello depth 8", FXT_S_HELLO_JPEG, HJ_DEPTH, 1, 1, 8, FXC_ERR_RANGE},
    {"hello depth 33", FXT_S_HELLO_JPEG, HJ_DEPTH, 1, 1, 33, FXC_ERR_RANGE},
    {"hello token longer than 64", FXT_S_HELLO_JPEG, HJ_TOKEN, 1, 1, 65, FXC_ERR_RANGE},
    {"hello token tab", FXT_S_HELLO_JPEG, HJ_TOKEN + 1, 1, 1, '\t', FXC_ERR_RANGE},
    {"hello strategy longer than 31", FXT_S_HELLO_JPEG, HJ_STRATEGY, 1, 1, 32, FXC_ERR_RANGE},
    {"hello strategy newline", FXT_S_HELLO_JPEG, HJ_STRATEGY + 7, 1, 1, '\n', FXC_ERR_RANGE},
    {"hello token longer than the payload", FXT_S_HELLO_RAW, HR_TOKEN, 1, 1, 2, FXC_ERR_TRUNCATED},
    {"hello strategy shorter than its bytes", FXT_S_HELLO_JPEG, HJ_STRATEGY, 1, 1, 6, FXC_ERR_TRAILING},
    /* welcome */
    {"welcome viewer id 0", FXT_S_WELCOME, W_ID, 4, 4, 0, FXC_ERR_RANGE},
    {"welcome empty name", FXT_S_WELCOME, W_NAME, 10, 1, 0, FXC_ERR_RANGE},
    {"welcome name longer than 31", FXT_S_WELCOME, W_NAME, 1, 1, 32, FXC_ERR_RANGE},
    {"welcome name escape byte", FXT_S_WELCOME, W_NAME + 1, 1, 1, 0x1b, FXC_ERR_RANGE},
    {"welcome fps 0", FXT_S_WELCOME, W_FPS, 4, 4, F32_ZERO, FXC_ERR_RANGE},
    {"welcome fps -1", FXT_S_WELCOME, W_FPS, 4, 4, F32_NEG_ONE, FXC_ERR_RANGE},
    {"welcome fps NaN", FXT_S_WELCOME, W_FPS, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"welcome fps inf", FXT_S_WELCOME, W_FPS, 4, 4, F32_INF, FXC_ERR_RANGE},
    {"welcome bounds min x NaN", FXT_S_WELCOME, W_MIN, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"welcome bounds min z -inf", FXT_S_WELCOME, W_MIN + 16, 8, 8, F64_NEG_INF, FXC_ERR_RANGE},
    {"welcome bounds max z inf", FXT_S_WELCOME, W_MAX + 16, 8, 8, F64_INF, FXC_ERR_RANGE},
    {"welcome bounds min y > max y", FXT_S_WELCOME, W_MIN + 8, 8, 8, F64_ONE, FXC_ERR_RANGE},
    {"welcome camera position NaN", FXT_S_WELCOME, W_POS + 8, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"welcome camera direction zero", FXT_S_WELCOME, W_DIR, 12, 12, 0, FXC_ERR_RANGE},
    {"welcome camera direction inf", FXT_S_WELCOME, W_DIR + 4, 4, 4, F32_INF, FXC_ERR_RANGE},
    {"welcome camera fov 180", FXT_S_WELCOME, W_FOV, 4, 4, F32_180, FXC_ERR_RANGE},
    /* camera */
    {"camera time NaN", FXT_S_CAMERA, C_TIME, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"camera time inf", FXT_S_CAMERA, C_TIME, 8, 8, F64_INF, FXC_ERR_RANGE},
    {"camera position -inf", FXT_S_CAMERA, C_POS + 16, 8, 8, F64_NEG_INF, FXC_ERR_RANGE},
    {"camera direction zero", FXT_S_CAMERA, C_DIR, 12, 12, 0, FXC_ERR_RANGE},
    {"camera direction -0, 0, 0", FXT_S_CAMERA, C_DIR, 12, 12, 0x80000000u, FXC_ERR_RANGE},
    {"camera direction NaN", FXT_S_CAMERA, C_DIR + 8, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"camera fov NaN", FXT_S_CAMERA, C_FOV, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"camera fov -1", FXT_S_CAMERA, C_FOV, 4, 4, F32_NEG_ONE, FXC_ERR_RANGE},
    {"camera flag 2", FXT_S_CAMERA, C_FLAG, 1, 1, 2, FXC_ERR_RANGE},
    {"camera flag 255", FXT_S_CAMERA_PREDICTED, C_FLAG, 1, 1, 255, FXC_ERR_RANGE},
    {"camera flag 1 without the predicted part", FXT_S_CAMERA, C_FLAG, 1, 1, 1, FXC_ERR_TRUNCATED},
    {"camera flag 0 with the predicted part", FXT_S_CAMERA_PREDICTED, C_FLAG, 1, 1, 0, FXC_ERR_TRAILING},
    {"camera predicted time NaN", FXT_S_CAMERA_PREDICTED, C_PTIME, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"camera predicted position inf", FXT_S_CAMERA_PREDICTED, C_PPOS, 8, 8, F64_INF, FXC_ERR_RANGE},
    {"camera predicted direction zero", FXT_S_CAMERA_PREDICTED, C_PDIR, 12, 12, 0, FXC_ERR_RANGE},
    {"camera predicted fov 180", FXT_S_CAMERA_PREDICTED, C_PFOV, 4, 4, F32_180, FXC_ERR_RANGE},
    /* frame */
    {"frame position NaN", FXT_S_FRAME, F_POS, 8, 8, F64_NAN, FXC_ERR_RANGE},
    {"frame direction zero", FXT_S_FRAME, F_DIR, 12, 12, 0, FXC_ERR_RANGE},
    {"frame fov 0", FXT_S_FRAME, F_FOV, 4, 4, F32_ZERO, FXC_ERR_RANGE},
    {"frame width 0", FXT_S_FRAME, F_WIDTH, 4, 4, 0, FXC_ERR_RANGE},
    {"frame width 8193", FXT_S_FRAME, F_WIDTH, 4, 4, 8193, FXC_ERR_RANGE},
    {"frame height 0", FXT_S_FRAME, F_HEIGHT, 4, 4, 0, FXC_ERR_RANGE},
    {"frame height 8193", FXT_S_FRAME_DEPTH, F_HEIGHT, 4, 4, 8193, FXC_ERR_RANGE},
    {"frame codec 3", FXT_S_FRAME, F_CODEC, 1, 1, 3, FXC_ERR_RANGE},
    {"frame depth 1", FXT_S_FRAME_DEPTH, F_DEPTH, 1, 1, 1, FXC_ERR_RANGE},
    {"frame depth 64", FXT_S_FRAME_DEPTH, F_DEPTH, 1, 1, 64, FXC_ERR_RANGE},
    {"frame depth none with depth bytes", FXT_S_FRAME_DEPTH, F_DEPTH, 1, 1, PROTO_DEPTH_NONE, FXC_ERR_RANGE},
    {"frame depth half without depth bytes", FXT_S_FRAME, F_DEPTH, 1, 1, PROTO_DEPTH_HALF, FXC_ERR_RANGE},
    {"frame depth float without depth bytes", FXT_S_FRAME, F_DEPTH, 1, 1, PROTO_DEPTH_FLOAT, FXC_ERR_RANGE},
    {"frame frame_ms NaN", FXT_S_FRAME, F_FRAME_MS, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"frame frame_ms -1", FXT_S_FRAME, F_FRAME_MS, 4, 4, F32_NEG_ONE, FXC_ERR_RANGE},
    {"frame encode_ms inf", FXT_S_FRAME, F_ENCODE_MS, 4, 4, F32_INF, FXC_ERR_RANGE},
    {"frame no colour bytes", FXT_S_FRAME, F_COLOR_BYTES, 4 + 36, 4, 0, FXC_ERR_RANGE},
    {"frame colour runs past the end", FXT_S_FRAME, F_COLOR_BYTES, 4, 4, 41, FXC_ERR_TRUNCATED},
    {"frame colour count 2^32-1", FXT_S_FRAME, F_COLOR_BYTES, 4, 4, 0xffffffffu, FXC_ERR_TRUNCATED},
    {"frame depth runs past the end", FXT_S_FRAME_DEPTH, F_COLOR + 5, 4, 4, 8, FXC_ERR_TRUNCATED},
    {"frame depth count short", FXT_S_FRAME_DEPTH, F_COLOR + 5, 4, 4, 6, FXC_ERR_TRAILING},
    /* stats */
    {"stats text runs past the end", FXT_S_STATS, 0, 4, 4, sizeof FXT_STATS_JSON, FXC_ERR_TRUNCATED},
    {"stats text shorter than its bytes", FXT_S_STATS, 0, 4, 4, 3, FXC_ERR_TRAILING},
    /* error and bye */
    {"error code 0", FXT_S_ERROR, E_CODE, 4, 4, 0, FXC_ERR_RANGE},
    {"error code 1", FXT_S_ERROR, E_CODE, 4, 4, 1, FXC_ERR_RANGE},
    {"error code INT32_MAX", FXT_S_ERROR, E_CODE, 4, 4, 0x7fffffffu, FXC_ERR_RANGE},
    {"error reason longer than 200", FXT_S_ERROR, E_REASON, 2, 2, 201, FXC_ERR_RANGE},
    {"error reason 65535 bytes", FXT_S_ERROR, E_REASON, 2, 2, 0xffff, FXC_ERR_RANGE},
    {"error reason newline", FXT_S_ERROR, E_REASON + 2 + 28, 1, 1, '\n', FXC_ERR_RANGE},
    {"error reason runs past the end", FXT_S_ERROR, E_REASON, 2, 2, 30, FXC_ERR_TRUNCATED},
    {"bye reason longer than 200", FXT_S_BYE, B_REASON, 2, 2, 201, FXC_ERR_RANGE},
    {"bye reason NUL", FXT_S_BYE, B_REASON + 2 + 6, 1, 1, 0, FXC_ERR_RANGE},
    {"bye reason 0xff", FXT_S_BYE, B_REASON + 2, 1, 1, 0xff, FXC_ERR_RANGE},
    {"bye reason shorter than its bytes", FXT_S_BYE, B_REASON, 2, 2, 13, FXC_ERR_TRAILING},
    /* sample request */
    {"request camera fov NaN", FXT_S_SAMPLE_REQUEST, SR_FOV, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"request camera direction zero", FXT_S_SAMPLE_REQUEST, SR_DIR, 12, 12, 0, FXC_ERR_RANGE},
    {"request width 0", FXT_S_SAMPLE_REQUEST, SR_WIDTH, 4, 4, 0, FXC_ERR_RANGE},
    {"request width 8193", FXT_S_SAMPLE_REQUEST, SR_WIDTH, 4, 4, 8193, FXC_ERR_RANGE},
    {"request height 0", FXT_S_SAMPLE_REQUEST, SR_HEIGHT, 4, 4, 0, FXC_ERR_RANGE},
    {"request count 0, no pixels", FXT_S_SAMPLE_REQUEST, SR_COUNT, 4 + 12, 4, 0, FXC_ERR_RANGE},
    {"request count above width*height", FXT_S_SAMPLE_REQUEST_EDGE, SR_COUNT, 4, 8, 3, FXC_ERR_RANGE},
    {"request count above 2^20", FXT_S_SAMPLE_REQUEST, SR_COUNT, 4, 4, PROTO_MAX_SAMPLES + 1, FXC_ERR_RANGE},
    {"request count 2^32-1", FXT_S_SAMPLE_REQUEST, SR_COUNT, 4, 4, 0xffffffffu, FXC_ERR_RANGE},
    {"request count 2^20 runs past the end", FXT_S_SAMPLE_REQUEST, SR_COUNT, 4, 4, PROTO_MAX_SAMPLES,
     FXC_ERR_TRUNCATED},
    {"request count 4 runs past the end", FXT_S_SAMPLE_REQUEST, SR_COUNT, 4, 4, 4, FXC_ERR_TRUNCATED},
    {"request count one short", FXT_S_SAMPLE_REQUEST, SR_COUNT, 4, 4, 2, FXC_ERR_TRAILING},
    {"request pixel x = width", FXT_S_SAMPLE_REQUEST, SR_PIXELS + 4, 2, 2, 640, FXC_ERR_RANGE},
    {"request pixel y = height", FXT_S_SAMPLE_REQUEST, SR_PIXELS + 6, 2, 2, 480, FXC_ERR_RANGE},
    {"request pixel x 0xffff", FXT_S_SAMPLE_REQUEST, SR_PIXELS + 8, 2, 2, 0xffff, FXC_ERR_RANGE},
    {"request pixel y 1 of height 1", FXT_S_SAMPLE_REQUEST_EDGE, SR_PIXELS + 2, 2, 2, 1, FXC_ERR_RANGE},
    /* samples */
    {"samples position inf", FXT_S_SAMPLES, SA_POS, 8, 8, F64_INF, FXC_ERR_RANGE},
    {"samples camera fov 180", FXT_S_SAMPLES, SA_FOV, 4, 4, F32_180, FXC_ERR_RANGE},
    {"samples width 0", FXT_S_SAMPLES, SA_WIDTH, 4, 4, 0, FXC_ERR_RANGE},
    {"samples height 8193", FXT_S_SAMPLES_EMPTY, SA_HEIGHT, 4, 4, 8193, FXC_ERR_RANGE},
    {"samples count above 2^20", FXT_S_SAMPLES_EMPTY, SA_COUNT, 4, 4, PROTO_MAX_SAMPLES + 1, FXC_ERR_RANGE},
    {"samples count runs past the end", FXT_S_SAMPLES, SA_COUNT, 4, 4, 3, FXC_ERR_TRUNCATED},
    {"samples count one short", FXT_S_SAMPLES, SA_COUNT, 4, 4, 1, FXC_ERR_TRAILING},
    {"samples x = width", FXT_S_SAMPLES, SA_SAMPLES, 2, 2, 4, FXC_ERR_RANGE},
    {"samples y = height", FXT_S_SAMPLES, SA_SAMPLES + 2, 2, 2, 3, FXC_ERR_RANGE},
    {"samples pad byte 1", FXT_S_SAMPLES, SA_SAMPLES + 7, 1, 1, 1, FXC_ERR_RANGE},
    {"samples second pad byte 0x80", FXT_S_SAMPLES, SA_SAMPLES + 12 + 7, 1, 1, 0x80, FXC_ERR_RANGE},
    {"samples depth NaN", FXT_S_SAMPLES, SA_SAMPLES + 8, 4, 4, F32_NAN, FXC_ERR_RANGE},
    {"samples depth 0", FXT_S_SAMPLES, SA_SAMPLES + 8, 4, 4, F32_ZERO, FXC_ERR_RANGE},
    {"samples depth -0", FXT_S_SAMPLES, SA_SAMPLES + 8, 4, 4, 0x80000000u, FXC_ERR_RANGE},
    {"samples depth -1", FXT_S_SAMPLES, SA_SAMPLES + 8, 4, 4, F32_NEG_ONE, FXC_ERR_RANGE},
    {"samples depth -inf", FXT_S_SAMPLES, SA_SAMPLES + 12 + 8, 4, 4, F32_NEG_INF, FXC_ERR_RANGE},
    /* controls: edits that stay valid, so the table's offsets are known to hit the right fields */
    {"control: request pixel x = width - 1", FXT_S_SAMPLE_REQUEST, SR_PIXELS + 4, 2, 2, 639, FXC_OK},
    {"control: request count 1", FXT_S_SAMPLE_REQUEST, SR_COUNT, 4 + 12, 8, 1, FXC_OK},
    {"control: samples depth smallest subnormal", FXT_S_SAMPLES, SA_SAMPLES + 8, 4, 4, 1, FXC_OK},
    {"control: samples depth 1e38", FXT_S_SAMPLES, SA_SAMPLES + 12 + 8, 4, 4, 0x7e967699u, FXC_OK},
    {"control: hello width 8192", FXT_S_HELLO_JPEG, HJ_WIDTH, 4, 4, 8192, FXC_OK},
    {"control: hello jpeg quality 100", FXT_S_HELLO_JPEG, HJ_QUALITY, 1, 1, 100, FXC_OK},
    {"control: hello depth 32", FXT_S_HELLO_JPEG, HJ_DEPTH, 1, 1, 32, FXC_OK},
    {"control: welcome fps 1", FXT_S_WELCOME, W_FPS, 4, 4, 0x3f800000u, FXC_OK},
    {"control: welcome bounds min y = -1", FXT_S_WELCOME, W_MIN + 8, 8, 8, 0xbff0000000000000ull, FXC_OK},
    {"control: camera direction y only", FXT_S_CAMERA, C_DIR, 12, 12, 0x3f80000000000000ull, FXC_OK},
    {"control: frame depth float", FXT_S_FRAME_DEPTH, F_DEPTH, 1, 1, PROTO_DEPTH_FLOAT, FXC_OK},
    {"control: frame frame_ms -0", FXT_S_FRAME, F_FRAME_MS, 4, 4, 0x80000000u, FXC_OK},
    {"control: error code INT32_MIN", FXT_S_ERROR, E_CODE, 4, 4, 0x80000000u, FXC_OK},
    {"control: bye reason shortened", FXT_S_BYE, B_REASON, 2 + 14, 2, 0, FXC_OK},
};

/* Each row of byte_edits applied to its sample, decoded from an exact allocation. */
static void test_field_faults(void **state)
{
    (void)state;
    for (size_t row = 0; row < sizeof byte_edits / sizeof byte_edits[0]; row++) {
        const byte_edit *e = &byte_edits[row];
        proto_msg m = fxt_proto_sample(e->sample);
        size_t len;
        uint8_t *buf = fxt_encode_alloc(&m, &len);
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
        fxc_result result = fxt_decode_copy(edited, edited_len, &out);
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
typedef enum edit_kind {
    EDIT_U8,
    EDIT_U32,
    EDIT_I32,
    EDIT_F32,
    EDIT_F64,
    EDIT_TEXT,
    EDIT_FILL,
    EDIT_ZERO
} edit_kind;
typedef struct struct_edit {
    const char *what;
    int sample;
    size_t offset; /* offsetof(proto_msg, ...) */
    edit_kind kind;
    size_t size; /* bytes for EDIT_FILL and EDIT_ZERO */
    double number;
    const char *text;
    fxc_result expect;
} struct_edit;

#define AT(field) offsetof(proto_msg, field)

static const struct_edit struct_edits[] = {
    {"type 0", FXT_S_BYE, AT(type), EDIT_U32, 0, 0, NULL, FXC_ERR_INVALID},
    {"type 11", FXT_S_BYE, AT(type), EDIT_U32, 0, 11, NULL, FXC_ERR_INVALID},
    {"hello name control byte", FXT_S_HELLO_JPEG, AT(u.hello.name), EDIT_TEXT, 0, 0, "a\x02", FXC_ERR_RANGE},
    {"hello name unterminated", FXT_S_HELLO_JPEG, AT(u.hello.name), EDIT_FILL, PROTO_NAME_MAX + 1, 0, NULL,
     FXC_ERR_RANGE},
    {"hello name non-ASCII", FXT_S_HELLO_JPEG, AT(u.hello.name), EDIT_TEXT, 0, 0, "caf\xc3\xa9",
     FXC_ERR_RANGE},
    {"hello width 0", FXT_S_HELLO_JPEG, AT(u.hello.width), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"hello width 8193", FXT_S_HELLO_JPEG, AT(u.hello.width), EDIT_U32, 0, 8193, NULL, FXC_ERR_RANGE},
    {"hello height 0", FXT_S_HELLO_JPEG, AT(u.hello.height), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"hello fov 0", FXT_S_HELLO_JPEG, AT(u.hello.fov_deg), EDIT_F32, 0, 0, NULL, FXC_ERR_RANGE},
    {"hello fov 180", FXT_S_HELLO_JPEG, AT(u.hello.fov_deg), EDIT_F32, 0, 180, NULL, FXC_ERR_RANGE},
    {"hello fov NaN", FXT_S_HELLO_JPEG, AT(u.hello.fov_deg), EDIT_F32, 0, NAN, NULL, FXC_ERR_RANGE},
    {"hello codec 3", FXT_S_HELLO_RAW, AT(u.hello.codec), EDIT_U8, 0, 3, NULL, FXC_ERR_RANGE},
    {"hello jpeg quality 0", FXT_S_HELLO_JPEG, AT(u.hello.jpeg_quality), EDIT_U8, 0, 0, NULL, FXC_ERR_RANGE},
    {"hello jpeg quality 101", FXT_S_HELLO_JPEG, AT(u.hello.jpeg_quality), EDIT_U8, 0, 101, NULL,
     FXC_ERR_RANGE},
    {"hello zstd with a quality", FXT_S_HELLO_ZSTD, AT(u.hello.jpeg_quality), EDIT_U8, 0, 90, NULL,
     FXC_ERR_RANGE},
    {"hello depth 8", FXT_S_HELLO_JPEG, AT(u.hello.depth), EDIT_U8, 0, 8, NULL, FXC_ERR_RANGE},
    {"hello token unterminated", FXT_S_HELLO_JPEG, AT(u.hello.token), EDIT_FILL, PROTO_TOKEN_MAX + 1, 0, NULL,
     FXC_ERR_RANGE},
    {"hello strategy tab", FXT_S_HELLO_JPEG, AT(u.hello.strategy), EDIT_TEXT, 0, 0, "a\tb", FXC_ERR_RANGE},
    {"welcome viewer id 0", FXT_S_WELCOME, AT(u.welcome.viewer_id), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"welcome empty name", FXT_S_WELCOME, AT(u.welcome.name), EDIT_TEXT, 0, 0, "", FXC_ERR_RANGE},
    {"welcome fps 0", FXT_S_WELCOME, AT(u.welcome.fps), EDIT_F32, 0, 0, NULL, FXC_ERR_RANGE},
    {"welcome fps inf", FXT_S_WELCOME, AT(u.welcome.fps), EDIT_F32, 0, INFINITY, NULL, FXC_ERR_RANGE},
    {"welcome fps NaN", FXT_S_WELCOME, AT(u.welcome.fps), EDIT_F32, 0, NAN, NULL, FXC_ERR_RANGE},
    {"welcome bounds min x NaN", FXT_S_WELCOME, AT(u.welcome.bounds_min[0]), EDIT_F64, 0, NAN, NULL,
     FXC_ERR_RANGE},
    {"welcome bounds max y > min y fails", FXT_S_WELCOME, AT(u.welcome.bounds_max[1]), EDIT_F64, 0, -1, NULL,
     FXC_ERR_RANGE},
    {"welcome camera fov 180", FXT_S_WELCOME, AT(u.welcome.camera.fov_deg), EDIT_F32, 0, 180, NULL,
     FXC_ERR_RANGE},
    {"welcome camera direction zero", FXT_S_WELCOME, AT(u.welcome.camera.direction), EDIT_ZERO, 12, 0, NULL,
     FXC_ERR_RANGE},
    {"camera time inf", FXT_S_CAMERA, AT(u.camera.time), EDIT_F64, 0, -INFINITY, NULL, FXC_ERR_RANGE},
    {"camera position NaN", FXT_S_CAMERA, AT(u.camera.pose.position[2]), EDIT_F64, 0, NAN, NULL,
     FXC_ERR_RANGE},
    {"camera direction inf", FXT_S_CAMERA, AT(u.camera.pose.direction[0]), EDIT_F32, 0, INFINITY, NULL,
     FXC_ERR_RANGE},
    {"camera predicted time NaN", FXT_S_CAMERA_PREDICTED, AT(u.camera.predicted_time), EDIT_F64, 0, NAN, NULL,
     FXC_ERR_RANGE},
    {"camera predicted direction zero", FXT_S_CAMERA_PREDICTED, AT(u.camera.predicted.direction), EDIT_ZERO,
     12, 0, NULL, FXC_ERR_RANGE},
    {"camera predicted ignored without flag", FXT_S_CAMERA, AT(u.camera.predicted_time), EDIT_F64, 0, NAN,
     NULL, FXC_OK},
    {"frame width 8193", FXT_S_FRAME, AT(u.frame.width), EDIT_U32, 0, 8193, NULL, FXC_ERR_RANGE},
    {"frame height 0", FXT_S_FRAME, AT(u.frame.height), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"frame codec 3", FXT_S_FRAME, AT(u.frame.codec), EDIT_U8, 0, 3, NULL, FXC_ERR_RANGE},
    {"frame depth 8", FXT_S_FRAME_DEPTH, AT(u.frame.depth), EDIT_U8, 0, 8, NULL, FXC_ERR_RANGE},
    {"frame depth none with depth bytes", FXT_S_FRAME_DEPTH, AT(u.frame.depth), EDIT_U8, 0, 0, NULL,
     FXC_ERR_RANGE},
    {"frame depth half without bytes", FXT_S_FRAME, AT(u.frame.depth), EDIT_U8, 0, 16, NULL, FXC_ERR_RANGE},
    {"frame no colour", FXT_S_FRAME, AT(u.frame.color_bytes), EDIT_U32, 0, 0, NULL, FXC_ERR_RANGE},
    {"frame frame_ms NaN", FXT_S_FRAME, AT(u.frame.stats.frame_ms), EDIT_F32, 0, NAN, NULL, FXC_ERR_RANGE},
    {"frame encode_ms -1", FXT_S_FRAME, AT(u.frame.stats.encode_ms), EDIT_F32, 0, -1, NULL, FXC_ERR_RANGE},
    {"frame camera fov NaN", FXT_S_FRAME, AT(u.frame.camera.fov_deg), EDIT_F32, 0, NAN, NULL, FXC_ERR_RANGE},
    {"frame colour NULL", FXT_S_FRAME, AT(u.frame.color), EDIT_ZERO, sizeof(void *), 0, NULL,
     FXC_ERR_INVALID},
    {"frame depth NULL", FXT_S_FRAME_DEPTH, AT(u.frame.depth_data), EDIT_ZERO, sizeof(void *), 0, NULL,
     FXC_ERR_INVALID},
    {"frame colour over 1 GiB", FXT_S_FRAME, AT(u.frame.color_bytes), EDIT_U32, 0, PROTO_MAX_PAYLOAD, NULL,
     FXC_ERR_TOO_LARGE},
    {"stats text NULL", FXT_S_STATS, AT(u.stats.json), EDIT_ZERO, sizeof(void *), 0, NULL, FXC_ERR_INVALID},
    {"stats text 4 GiB", FXT_S_STATS, AT(u.stats.json_bytes), EDIT_U32, 0, 4294967295.0, NULL,
     FXC_ERR_TOO_LARGE},
    {"error code 0", FXT_S_ERROR, AT(u.error.code), EDIT_I32, 0, 0, NULL, FXC_ERR_RANGE},
    {"error code 5", FXT_S_ERROR, AT(u.error.code), EDIT_I32, 0, 5, NULL, FXC_ERR_RANGE},
    {"error reason newline", FXT_S_ERROR, AT(u.error.reason), EDIT_TEXT, 0, 0, "line\n", FXC_ERR_RANGE},
    {"error reason unterminated", FXT_S_ERROR, AT(u.error.reason), EDIT_FILL, PROTO_REASON_MAX + 1, 0, NULL,
     FXC_ERR_RANGE},
    {"bye reason DEL", FXT_S_BYE, AT(u.bye.reason), EDIT_TEXT, 0, 0, "\x7f", FXC_ERR_RANGE},
    {"request pixels NULL", FXT_S_SAMPLE_REQUEST, AT(u.sample_request.pixels), EDIT_ZERO, sizeof(void *), 0,
     NULL, FXC_ERR_INVALID},
    {"request count 0", FXT_S_SAMPLE_REQUEST, AT(u.sample_request.count), EDIT_U32, 0, 0, NULL,
     FXC_ERR_RANGE},
    {"request count above width*height", FXT_S_SAMPLE_REQUEST_EDGE, AT(u.sample_request.count), EDIT_U32, 0,
     3, NULL, FXC_ERR_RANGE},
    {"request count above 2^20", FXT_S_SAMPLE_REQUEST, AT(u.sample_request.count), EDIT_U32, 0,
     PROTO_MAX_SAMPLES + 1, NULL, FXC_ERR_RANGE},
    {"request width 2^16", FXT_S_SAMPLE_REQUEST, AT(u.sample_request.width), EDIT_U32, 0, 65536, NULL,
     FXC_ERR_RANGE},
    {"request height 1 (pixel y 479)", FXT_S_SAMPLE_REQUEST, AT(u.sample_request.height), EDIT_U32, 0, 1,
     NULL, FXC_ERR_RANGE},
    {"request camera fov 0", FXT_S_SAMPLE_REQUEST, AT(u.sample_request.camera.fov_deg), EDIT_F32, 0, 0, NULL,
     FXC_ERR_RANGE},
    {"samples NULL with a count", FXT_S_SAMPLES, AT(u.samples.samples), EDIT_ZERO, sizeof(void *), 0, NULL,
     FXC_ERR_INVALID},
    {"samples width 3 (x 3)", FXT_S_SAMPLES, AT(u.samples.width), EDIT_U32, 0, 3, NULL, FXC_ERR_RANGE},
    {"samples count above 2^20", FXT_S_SAMPLES_EMPTY, AT(u.samples.count), EDIT_U32, 0, PROTO_MAX_SAMPLES + 1,
     NULL, FXC_ERR_RANGE},
    {"control: samples NULL without a count", FXT_S_SAMPLES_EMPTY, AT(u.samples.samples), EDIT_ZERO,
     sizeof(void *), 0, NULL, FXC_OK},
    {"control: request width 8192", FXT_S_SAMPLE_REQUEST, AT(u.sample_request.width), EDIT_U32, 0, 8192, NULL,
     FXC_OK},
    {"control: bye reason of 200", FXT_S_BYE, AT(u.bye.reason), EDIT_FILL, PROTO_REASON_MAX, 0, NULL, FXC_OK},
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
    case EDIT_F64: memcpy(at, &e->number, sizeof e->number); break;
    case EDIT_TEXT: memcpy(at, e->text, strlen(e->text) + 1); break;
    case EDIT_FILL: memset(at, 'a', e->size); break;
    case EDIT_ZERO: memset(at, 0, e->size); break;
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
        proto_msg m = fxt_proto_sample(e->sample);
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
    proto_msg bad = fxt_proto_sample(FXT_S_ERROR);
    bad.u.error.code = 0;
    assert_int_equal(proto_encode(&bad, buf, sizeof buf, NULL), 0);
}

/* A buffer one byte short (an exact allocation, so a write past it is seen), or none, is TOO_LARGE. */
static void test_encode_capacity(void **state)
{
    (void)state;
    for (int i = 0; i < FXT_SAMPLE_COUNT; i++) {
        proto_msg m = fxt_proto_sample(i);
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
        proto_msg m = fxt_proto_sample(iteration % FXT_SAMPLE_COUNT);
        size_t len;
        uint8_t *buf = fxt_encode_alloc(&m, &len);
        int edits = 1 + (int)(fxt_random(&rng) % 3);
        for (int e = 0; e < edits; e++) {
            size_t at = fxt_random(&rng) % len;
            switch (fxt_random(&rng) % 4) {
            case 0: buf[at] = (uint8_t)fxt_random(&rng); break;
            case 1: buf[at] ^= (uint8_t)(1u << (fxt_random(&rng) % 8)); break;
            case 2: buf[at] = (uint8_t)(buf[at] + 1); break;
            default:
                len = at > PROTO_HEADER_BYTES ? at : len; /* cut */
                break;
            }
        }
        if (fxt_random(&rng) % 2) /* keep the header's length consistent, so payload faults are reached */
            proto_put_u32le(buf + 8, (uint32_t)(len - PROTO_HEADER_BYTES));
        proto_msg out;
        fxc_result result = fxt_decode_copy(buf, len, &out);
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
        case FXC_ERR_RANGE: break;
        default: fail_msg("unexpected %s", fxc_strerror(result));
        }
        free(buf);
    }
    assert_true(decoded > 1000); /* the loop reaches valid messages too, not only refusals */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_header_faults),   cmocka_unit_test(test_field_faults),
        cmocka_unit_test(test_encode_refusals), cmocka_unit_test(test_encode_capacity),
        cmocka_unit_test(test_mutations),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
