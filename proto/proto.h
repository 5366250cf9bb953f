/* proto: the wire format between `fxcache serve` and its viewer clients (DESIGN.md stage 8). No I/O: it turns
 * messages into bytes and bytes into messages, and frame payloads into pixels and back. Both sides link it;
 * it depends on nothing of ours but common/fxc_result.h (and on zstd and libturbojpeg for the codecs).
 *
 * A message is one WebSocket binary message: a 12-byte header, then the payload. Every field is written byte
 * by byte in little-endian order (never a struct copied onto the wire), so the format is host independent:
 *
 *     offset 0   magic    4 bytes  'F' 'X' 'C' 'P'
 *     offset 4   version  u16      PROTO_VERSION; a decoder refuses newer versions
 *     offset 6   type     u16      proto_type
 *     offset 8   length   u32      payload bytes that follow the header (exactly: no more, no fewer)
 *
 * Floats are IEEE-754 binary32/binary64 bit patterns (u32/u64). Strings are a u8 or u16 length, then that
 * many bytes, no terminator; names, tokens and reasons must be printable ASCII. docs/PROTOCOL.md gives every
 * message's payload field by field.
 *
 * Decoders are safe on untrusted bytes: they never read outside [buf, buf + len), never assert on content,
 * and return a distinct code for each way a message can be wrong (below). A decoded message's byte fields
 * (payloads, JSON text) point into the caller's buffer: they are valid while it is. */
#ifndef FXC_PROTO_H
#define FXC_PROTO_H

#include "fxc_result.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define PROTO_MAGIC0       'F'
#define PROTO_MAGIC1       'X'
#define PROTO_MAGIC2       'C'
#define PROTO_MAGIC3       'P'
#define PROTO_VERSION      1u
#define PROTO_HEADER_BYTES 12u

enum {
    PROTO_NAME_MAX = 31,         /* viewer name bytes */
    PROTO_TOKEN_MAX = 64,        /* access token bytes */
    PROTO_STRATEGY_MAX = 31,     /* reference strategy name bytes */
    PROTO_REASON_MAX = 200,      /* error and bye reason bytes */
    PROTO_MAX_SIDE = 8192,       /* largest width or height a message may name */
    PROTO_MAX_PAYLOAD = 1u << 30 /* largest payload length a header may declare (1 GiB) */
};
enum { PROTO_MAX_SAMPLES = 1 << 20 }; /* pixels in one request or answer */

/* Message types. Values are fixed on the wire; new types get new numbers. */
#define PROTO_TYPES(X)                                                                                       \
    X(PROTO_HELLO, 1, "hello")     /* client -> server: who, what size, which codec */                       \
    X(PROTO_WELCOME, 2, "welcome") /* server -> client: accepted; the scene's frame of reference */          \
    X(PROTO_CAMERA, 3, "camera")   /* client -> server: the viewer's latest camera */                        \
    X(PROTO_FRAME, 4, "frame")     /* server -> client: a composed frame */                                  \
    X(PROTO_STATS_REQUEST, 5, "stats-request") /* client -> server: send the run report's figures */         \
    X(PROTO_STATS, 6, "stats")                 /* server -> client: the run report as JSON text */           \
    X(PROTO_ERROR, 7, "error")                 /* either way: a code from fxc_result.h and a reason */       \
    X(PROTO_BYE, 8, "bye")                     /* either way: closing, with a reason */                      \
    X(PROTO_SAMPLE_REQUEST, 9,                                                                               \
      "sample-request")             /* client -> server: pixels of a camera's image to render */             \
    X(PROTO_SAMPLES, 10, "samples") /* server -> client: those pixels, rendered */

typedef enum proto_type {
#define PROTO_TYPE_ENUM(name, value, text) name = value,
    PROTO_TYPES(PROTO_TYPE_ENUM)
#undef PROTO_TYPE_ENUM
} proto_type;

/* The name of a message type ("unknown" outside the table). */
const char *proto_type_name(uint32_t type);

/* Colour codecs (hello's wanted codec, frame's codec). */
typedef enum proto_codec {
    PROTO_CODEC_RAW = 0,  /* width*height*3 bytes of sRGB, top row first */
    PROTO_CODEC_ZSTD = 1, /* zstd of the raw bytes: lossless (the default) */
    PROTO_CODEC_JPEG = 2, /* baseline JPEG (libturbojpeg), 4:2:0, quality 1..100: lossy */
    PROTO_CODEC_COUNT
} proto_codec;

/* Depth codecs: none, or zstd of width*height little-endian values, IEEE binary16 or binary32, of the distance
 * along the primary ray in metres (+infinity for the sky). */
typedef enum proto_depth {
    PROTO_DEPTH_NONE = 0,
    PROTO_DEPTH_HALF = 16,
    PROTO_DEPTH_FLOAT = 32,
} proto_depth;

const char *proto_codec_name(uint32_t codec);
/* Parses "raw", "zstd", "jpeg" (false for anything else). */
bool proto_codec_parse(const char *text, proto_codec *out);

/* A camera on the wire: world coordinates in double (a scene far from the origin keeps its precision), a view
 * direction (non-zero, need not be unit; up is +Y, as in viewer traces) and the vertical field of view. */
typedef struct proto_pose {
    double position[3]; /* metres, world coordinates, finite */
    float direction[3]; /* finite, not all zero */
    float fov_deg;      /* (0, 180) */
} proto_pose;

typedef struct proto_hello {
    char name[PROTO_NAME_MAX + 1];   /* 0..31 printable bytes, NUL-terminated here ("" = server names it) */
    uint32_t width, height;          /* 1..PROTO_MAX_SIDE */
    float fov_deg;                   /* (0, 180) */
    uint8_t codec;                   /* proto_codec */
    uint8_t jpeg_quality;            /* 1..100 with PROTO_CODEC_JPEG, else 0 */
    uint8_t depth;                   /* proto_depth */
    char token[PROTO_TOKEN_MAX + 1]; /* optional access token ("" = none) */
    char strategy[PROTO_STRATEGY_MAX + 1]; /* reference strategy (proto_strategy_parse; "" = basic). Any
                                               printable text decodes: the server refuses names it does not
                                               know (docs/PROTOCOL.md, "Session rules") */
} proto_hello;

/* Baxter's reference-frame strategies, named in hello's strategy field: which camera the server renders the
 * viewer's frames for. basic: the reported camera; fan: the reported camera with a wider field of view at
 * the same pixel count; predictive: the camera message's predicted pose (or an extrapolation). */
typedef enum proto_strategy {
    PROTO_STRATEGY_BASIC = 0,
    PROTO_STRATEGY_FAN = 1,
    PROTO_STRATEGY_PREDICTIVE = 2,
    PROTO_STRATEGY_COUNT
} proto_strategy;

/* "basic", "fan", "predictive" ("unknown" outside the table). */
const char *proto_strategy_name(uint32_t strategy);
/* Parses a hello's strategy: "" and "basic" are basic, "fan", "predictive"; false for anything else
 * (*out untouched). */
bool proto_strategy_parse(const char *text, proto_strategy *out);

typedef struct proto_welcome {
    uint32_t viewer_id; /* the server's id for this viewer (nonzero) */
    char name[PROTO_NAME_MAX +
              1];         /* the server's name for it ("viewer_NN", 1..31 printable bytes): its frames,
                                      statistics and trace */
    float fps;            /* the server's target frames per second, > 0 */
    double bounds_min[3]; /* the scene's bounding box, world coordinates (min <= max, finite) */
    double bounds_max[3];
    proto_pose camera;        /* the scene's default camera */
    uint32_t max_camera_rate; /* camera messages per second the server accepts before it disconnects */
} proto_welcome;

typedef struct proto_camera {
    uint32_t sequence; /* the client's number for this camera (echoed in the frames rendered for it) */
    double time;       /* the client's clock, seconds, finite */
    proto_pose pose;
    bool has_predicted; /* an optional predicted pose (the predictive strategy renders it) */
    double predicted_time;
    proto_pose predicted;
} proto_camera;

/* The server's per-viewer figures for one frame. */
typedef struct proto_frame_stats {
    uint64_t requested_texels; /* deduplicated within the viewer */
    uint64_t requested_cells;  /* world-space cells (probes) */
    uint64_t pixels_visible;
    uint64_t pixels_missing; /* visible pixels composed without cached data */
    uint64_t frames_dropped; /* this viewer's frames replaced by a newer one before they were sent, so far */
    float frame_ms;          /* the server's whole frame, all viewers (finite, >= 0) */
    float encode_ms;         /* encoding this message (finite, >= 0) */
} proto_frame_stats;

typedef struct proto_frame {
    uint32_t frame;           /* the server's frame number */
    uint32_t camera_sequence; /* the sequence of the camera message it was rendered for */
    proto_pose camera;        /* the camera it was rendered for */
    uint32_t width, height;   /* 1..PROTO_MAX_SIDE */
    uint8_t codec;            /* proto_codec */
    uint8_t depth;            /* proto_depth */
    proto_frame_stats stats;
    const uint8_t *color; /* encoded colour payload (into the message buffer when decoded) */
    uint32_t color_bytes;
    const uint8_t *depth_data; /* encoded depth payload, NULL/0 with PROTO_DEPTH_NONE */
    uint32_t depth_bytes;
} proto_frame;

typedef struct proto_stats {
    const char *json; /* UTF-8 JSON text, not NUL-terminated */
    uint32_t json_bytes;
} proto_stats;

typedef struct proto_error {
    int32_t code;                      /* an fxc_result code (negative) */
    char reason[PROTO_REASON_MAX + 1]; /* 0..200 printable bytes, NUL-terminated here */
} proto_error;

typedef struct proto_bye {
    char reason[PROTO_REASON_MAX + 1];
} proto_bye;

/* A request for some pixels of one camera's image (the client's render cache asks for the pixels it needs
 * most). The server answers with a samples message for the same request number. */
typedef struct proto_sample_request {
    uint32_t request;       /* the client's number for it (echoed in the answer) */
    proto_pose camera;      /* the camera whose image the pixels belong to */
    uint32_t width, height; /* that image's size, 1..PROTO_MAX_SIDE */
    uint32_t count;         /* 1..min(width*height, PROTO_MAX_SAMPLES) */
    const uint8_t *pixels;  /* count x (u16 x, u16 y), little-endian, x < width, y < height (points into
                                the message buffer when decoded); duplicates are allowed here */
} proto_sample_request;

/* One rendered pixel, as proto_sample_get reads it. */
typedef struct proto_sample {
    uint16_t x, y;  /* pixel of the request's image, x < width, y < height */
    uint8_t rgb[3]; /* sRGB, as in a frame */
    float depth;    /* metres along the primary ray, +infinity for the sky; > 0, not NaN */
} proto_sample;

typedef struct proto_samples {
    uint32_t request; /* the request answered */
    uint32_t frame;   /* the server frame that rendered them */
    proto_pose camera;
    uint32_t width, height;
    uint32_t count;         /* 0..PROTO_MAX_SAMPLES */
    const uint8_t *samples; /* count x PROTO_SAMPLE_BYTES: u16 x, u16 y, u8 r, g, b, u8 0, f32 depth
                                (metres along the primary ray, +inf for the sky) */
} proto_samples;

#define PROTO_REQUEST_PIXEL_BYTES 4u
#define PROTO_SAMPLE_BYTES        12u

/* Writes / reads entry i of a sample request's pixel array (4 bytes each). No range checks: the caller
 * sized the array (count x PROTO_REQUEST_PIXEL_BYTES). */
void proto_request_pixel_put(uint8_t *pixels, uint32_t i, uint16_t x, uint16_t y);
void proto_request_pixel_get(const uint8_t *pixels, uint32_t i, uint16_t *x, uint16_t *y);
/* Writes / reads entry i of a samples array (PROTO_SAMPLE_BYTES each; the pad byte is written 0). */
void proto_sample_put(uint8_t *samples, uint32_t i, const proto_sample *s);
void proto_sample_get(const uint8_t *samples, uint32_t i, proto_sample *s);

/* Any message: the type says which member is valid (stats-request has none). */
typedef struct proto_msg {
    uint32_t type; /* proto_type */
    union {
        proto_hello hello;
        proto_welcome welcome;
        proto_camera camera;
        proto_frame frame;
        proto_stats stats;
        proto_error error;
        proto_bye bye;
        proto_sample_request sample_request;
        proto_samples samples;
    } u;
} proto_msg;

/* A header as read from bytes. */
typedef struct proto_header {
    uint32_t version, type, length;
} proto_header;

/* Reads and checks a header from the first len bytes of buf: FXC_ERR_TRUNCATED when len < 12,
 * FXC_ERR_BAD_MAGIC, FXC_ERR_VERSION (version 0 or newer than PROTO_VERSION), FXC_ERR_UNKNOWN_TYPE,
 * FXC_ERR_TOO_LARGE (length above PROTO_MAX_PAYLOAD). Does not look at the payload. A server can call it on a
 * message's first bytes to refuse an oversize message before it arrives whole. */
fxc_result proto_decode_header(const uint8_t *buf, size_t len, proto_header *out);

/* Bytes proto_encode needs for m (header included); 0 when m cannot be encoded (a field out of range or a
 * payload too large: proto_encode says which). */
size_t proto_bound(const proto_msg *m);

/* Encodes m into buf (cap bytes). Returns the bytes written (exactly proto_bound(m)), or 0 when m is invalid
 * or cap is too small; then *result (may be NULL) says why: FXC_ERR_RANGE (a field out of range, or a string
 * not printable, a pixel outside its image), FXC_ERR_INVALID (unknown type, or a NULL payload pointer with
 * a nonzero count),
 * FXC_ERR_TOO_LARGE (cap too small or a payload too large). */
size_t proto_encode(const proto_msg *m, uint8_t *buf, size_t cap, fxc_result *result);

/* Decodes exactly one whole message of len bytes. Returns FXC_OK and *out, or: the header's codes above;
 * FXC_ERR_TRUNCATED (fewer bytes than the header declares, or a payload field that runs past its end);
 * FXC_ERR_TRAILING (more bytes than declared, or payload bytes left after the last field); FXC_ERR_RANGE (a
 * field outside its documented range, a non-printable string, a non-finite float). Byte fields of *out point
 * into buf. */
fxc_result proto_decode(const uint8_t *buf, size_t len, proto_msg *out);

/* ---- codecs ---------------------------------------------------------------------------------------------- */

/* Largest colour payload for codec at width x height (0 for an unknown codec or sides out of range). */
size_t proto_color_bound(uint32_t codec, uint32_t width, uint32_t height);

/* Encodes width*height*3 bytes of sRGB (top row first) into out (cap bytes). quality: 1..100 for JPEG,
 * ignored otherwise. Returns FXC_OK and *out_bytes, FXC_ERR_INVALID (unknown codec, bad quality or sides),
 * FXC_ERR_TOO_LARGE (cap too small; for JPEG cap must be at least proto_color_bound), FXC_ERR_CODEC (the codec
 * library failed). Thread-safe (no state is shared between calls). */
fxc_result proto_color_encode(uint32_t codec, uint32_t quality, const uint8_t *rgb, uint32_t width,
                              uint32_t height, uint8_t *out, size_t cap, size_t *out_bytes);

/* Decodes a colour payload into rgb (width*height*3 bytes). FXC_ERR_CODEC when the payload is not a valid
 * encoding, or decodes to a different size than width x height; FXC_ERR_INVALID for an unknown codec. Safe on
 * untrusted payloads. */
fxc_result proto_color_decode(uint32_t codec, const uint8_t *payload, size_t payload_bytes, uint32_t width,
                              uint32_t height, uint8_t *rgb);

/* Largest depth payload (0 for PROTO_DEPTH_NONE or an unknown depth codec). */
size_t proto_depth_bound(uint32_t depth, uint32_t width, uint32_t height);

/* Encodes width*height depths (metres, +infinity for the sky) as binary16 (rounded to nearest even; above
 * 65504 becomes +infinity) or binary32, then zstd. Same results as proto_color_encode. */
fxc_result proto_depth_encode(uint32_t depth, const float *values, uint32_t width, uint32_t height,
                              uint8_t *out, size_t cap, size_t *out_bytes);

/* Decodes a depth payload into width*height floats. FXC_ERR_CODEC as proto_color_decode. */
fxc_result proto_depth_decode(uint32_t depth, const uint8_t *payload, size_t payload_bytes, uint32_t width,
                              uint32_t height, float *values);

/* ---- bytes, one function each way (used by the encoders and decoders; public for tests and tools) -------- */

void proto_put_u16le(uint8_t *p, uint16_t v);
void proto_put_u32le(uint8_t *p, uint32_t v);
void proto_put_u64le(uint8_t *p, uint64_t v);
uint16_t proto_get_u16le(const uint8_t *p);
uint32_t proto_get_u32le(const uint8_t *p);
uint64_t proto_get_u64le(const uint8_t *p);

#endif
