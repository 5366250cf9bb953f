/* The wire format tests' sample messages (tests/test_proto*.c): one valid message of every type, with its
 * optional parts present and absent and its strings empty and at their maximum, the payload bytes each takes
 * by docs/PROTOCOL.md's tables, and helpers that encode and decode them in allocations of exactly their size
 * (so the sanitizer sees any over-read). */
#ifndef FXT_PROTO_H
#define FXT_PROTO_H

#include "proto.h"

#include <stddef.h>
#include <stdint.h>

typedef enum fxt_sample {
    FXT_S_HELLO_RAW,  /* empty strings */
    FXT_S_HELLO_JPEG, /* name "alice", token "secret-token", strategy "nearest" */
    FXT_S_HELLO_ZSTD, /* every string at its maximum */
    FXT_S_WELCOME,    /* name "viewer_07" */
    FXT_S_CAMERA,     /* without a predicted pose */
    FXT_S_CAMERA_PREDICTED,
    FXT_S_FRAME,       /* 4x3 raw colour (36 bytes), no depth */
    FXT_S_FRAME_DEPTH, /* 5 colour bytes, 7 depth bytes (the message does not look inside them) */
    FXT_S_STATS_REQUEST,
    FXT_S_STATS,
    FXT_S_STATS_EMPTY,
    FXT_S_ERROR, /* reason "missing or wrong access token" (29 bytes) */
    FXT_S_BYE,   /* reason "client closing" (14 bytes) */
    FXT_S_BYE_EMPTY,
    FXT_S_SAMPLE_REQUEST,      /* 640x480, pixels (0,0), (639,479), (17,200) */
    FXT_S_SAMPLE_REQUEST_EDGE, /* 2x1, count 2 = width*height, pixel (1,0) twice (duplicates are allowed) */
    FXT_S_SAMPLES,             /* 4x3, two samples: (3,2) at 2.5 m, (0,0) the sky */
    FXT_S_SAMPLES_EMPTY,       /* count 0 */
    FXT_SAMPLE_COUNT
} fxt_sample;

/* The sample stats message's JSON text (a literal, so sizeof gives its length + 1). */
#define FXT_STATS_JSON "{\"frames\": 10, \"viewers\": [1, 2]}"

/* The request's pixels as bytes: x, y little-endian u16 each. */
extern const uint8_t fxt_request_pixels[12];
/* Two samples: (3,2) rgb 10,20,30 depth 2.5 (0x40200000); (0,0) rgb 255,0,128 depth +inf (0x7f800000). */
extern const uint8_t fxt_samples_bytes[24];
/* Payload bytes of each sample, counted by hand from docs/PROTOCOL.md's tables. */
extern const size_t fxt_sample_payload_bytes[FXT_SAMPLE_COUNT];

/* Sample message i (valid, every field distinct from zero where it may be). */
proto_msg fxt_proto_sample(int i);
/* Encodes m into a new allocation of exactly proto_bound(m) bytes (the test fails if it cannot). */
uint8_t *fxt_encode_alloc(const proto_msg *m, size_t *len);
/* Decodes a copy of bytes in an allocation of exactly len bytes, so the sanitizer sees any over-read. */
fxc_result fxt_decode_copy(const uint8_t *bytes, size_t len, proto_msg *out);
/* Field by field equality of two messages (floats bit for bit, payloads by content). */
void fxt_assert_same_message(const proto_msg *a, const proto_msg *b);

#endif
