/* proto.c: the messages of the wire format (proto.h, docs/PROTOCOL.md): the header, every message type's
 * encoder, bound and decoder, and the byte helpers. The codecs of frame payloads are in proto_codec.c.
 *
 * One validation function per message type serves both directions: proto_encode refuses what proto_decode
 * would refuse, so a message this library writes always reads back. Decoding reads the payload in field
 * order through a cursor whose first fault sticks (TRUNCATED when a field runs past the end; RANGE for a
 * string longer than its maximum, a non-printable byte or a flag other than 0/1, since those decide the
 * layout), then checks that no byte is left (TRAILING), then runs the same validation as the encoder. */
#include "proto.h"

#include <assert.h>
#include <math.h>
#include <string.h>

/* Bytes of a pose on the wire: 3 f64 position, 3 f32 direction, f32 fov. */
enum { POSE_BYTES = 3 * 8 + 3 * 4 + 4 };
/* Fixed parts of the sample messages: request, pose, width, height, count (and the answer's frame). */
enum { SAMPLE_REQUEST_FIXED = 4 + POSE_BYTES + 4 + 4 + 4, SAMPLES_FIXED = 4 + 4 + POSE_BYTES + 4 + 4 + 4 };

/* ---- bytes ------------------------------------------------------------------------------------------- */

void proto_put_u16le(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

void proto_put_u32le(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

void proto_put_u64le(uint8_t *p, uint64_t v)
{
    proto_put_u32le(p, (uint32_t)v);
    proto_put_u32le(p + 4, (uint32_t)(v >> 32));
}

uint16_t proto_get_u16le(const uint8_t *p)
{
    return (uint16_t)(p[0] | (uint16_t)p[1] << 8);
}

uint32_t proto_get_u32le(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

uint64_t proto_get_u64le(const uint8_t *p)
{
    return (uint64_t)proto_get_u32le(p) | (uint64_t)proto_get_u32le(p + 4) << 32;
}

static float f32_from_bits(uint32_t bits)
{
    float v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

static uint32_t bits_from_f32(float v)
{
    uint32_t bits;
    memcpy(&bits, &v, sizeof bits);
    return bits;
}

/* ---- sample arrays ------------------------------------------------------------------------------------ */

void proto_request_pixel_put(uint8_t *pixels, uint32_t i, uint16_t x, uint16_t y)
{
    uint8_t *p = pixels + (size_t)i * PROTO_REQUEST_PIXEL_BYTES;
    proto_put_u16le(p, x);
    proto_put_u16le(p + 2, y);
}

void proto_request_pixel_get(const uint8_t *pixels, uint32_t i, uint16_t *x, uint16_t *y)
{
    const uint8_t *p = pixels + (size_t)i * PROTO_REQUEST_PIXEL_BYTES;
    *x = proto_get_u16le(p);
    *y = proto_get_u16le(p + 2);
}

void proto_sample_put(uint8_t *samples, uint32_t i, const proto_sample *s)
{
    uint8_t *p = samples + (size_t)i * PROTO_SAMPLE_BYTES;
    proto_put_u16le(p, s->x);
    proto_put_u16le(p + 2, s->y);
    p[4] = s->rgb[0];
    p[5] = s->rgb[1];
    p[6] = s->rgb[2];
    p[7] = 0;
    proto_put_u32le(p + 8, bits_from_f32(s->depth));
}

void proto_sample_get(const uint8_t *samples, uint32_t i, proto_sample *s)
{
    const uint8_t *p = samples + (size_t)i * PROTO_SAMPLE_BYTES;
    s->x = proto_get_u16le(p);
    s->y = proto_get_u16le(p + 2);
    s->rgb[0] = p[4];
    s->rgb[1] = p[5];
    s->rgb[2] = p[6];
    s->depth = f32_from_bits(proto_get_u32le(p + 8));
}

/* ---- names ------------------------------------------------------------------------------------------- */

const char *proto_type_name(uint32_t type)
{
    switch (type) {
#define PROTO_TYPE_CASE(name, value, text)                                                                   \
    case value: return text;
        PROTO_TYPES(PROTO_TYPE_CASE)
#undef PROTO_TYPE_CASE
    }
    return "unknown";
}

/* True for the types of the table. */
static bool type_known(uint32_t type)
{
    switch (type) {
#define PROTO_TYPE_KNOWN(name, value, text) case value:
        PROTO_TYPES(PROTO_TYPE_KNOWN)
#undef PROTO_TYPE_KNOWN
        return true;
    }
    return false;
}

static const char *const codec_names[PROTO_CODEC_COUNT] = {"raw", "zstd", "jpeg"};

const char *proto_codec_name(uint32_t codec)
{
    return codec < PROTO_CODEC_COUNT ? codec_names[codec] : "unknown";
}

bool proto_codec_parse(const char *text, proto_codec *out)
{
    for (uint32_t codec = 0; text && codec < PROTO_CODEC_COUNT; codec++)
        if (strcmp(text, codec_names[codec]) == 0) {
            if (out)
                *out = (proto_codec)codec;
            return true;
        }
    return false;
}

static const char *const strategy_names[PROTO_STRATEGY_COUNT] = {"basic", "fan", "predictive"};

const char *proto_strategy_name(uint32_t strategy)
{
    return strategy < PROTO_STRATEGY_COUNT ? strategy_names[strategy] : "unknown";
}

bool proto_strategy_parse(const char *text, proto_strategy *out)
{
    if (!text)
        return false;
    for (uint32_t strategy = 0; strategy < PROTO_STRATEGY_COUNT; strategy++)
        if (strcmp(text, strategy_names[strategy]) == 0 || (strategy == PROTO_STRATEGY_BASIC && !text[0])) {
            if (out)
                *out = (proto_strategy)strategy;
            return true;
        }
    return false;
}

/* ---- validation (shared by encoder and decoder) ----------------------------------------------------- */

/* Printable ASCII, space included: names, tokens and reasons end up in file names, logs and terminals. */
static bool printable(uint8_t c)
{
    return c >= 0x20 && c <= 0x7e;
}

/* Checks a NUL-terminated string held in a char[max + 1] field: at most max bytes, all printable. Sets
 * *len to its length. */
static fxc_result check_text(const char *text, size_t max, size_t *len)
{
    const char *end = memchr(text, 0, max + 1);
    if (!end)
        return FXC_ERR_RANGE;
    *len = (size_t)(end - text);
    for (size_t i = 0; i < *len; i++)
        if (!printable((uint8_t)text[i]))
            return FXC_ERR_RANGE;
    return FXC_OK;
}

static bool side_ok(uint32_t side)
{
    return side >= 1 && side <= PROTO_MAX_SIDE;
}

/* (0, 180): false for NaN too. */
static bool fov_ok(float fov_deg)
{
    return fov_deg > 0.0f && fov_deg < 180.0f;
}

static bool depth_ok(uint32_t depth)
{
    return depth == PROTO_DEPTH_NONE || depth == PROTO_DEPTH_HALF || depth == PROTO_DEPTH_FLOAT;
}

static fxc_result check_pose(const proto_pose *pose)
{
    for (int k = 0; k < 3; k++)
        if (!isfinite(pose->position[k]) || !isfinite(pose->direction[k]))
            return FXC_ERR_RANGE;
    if (pose->direction[0] == 0.0f && pose->direction[1] == 0.0f && pose->direction[2] == 0.0f)
        return FXC_ERR_RANGE;
    return fov_ok(pose->fov_deg) ? FXC_OK : FXC_ERR_RANGE;
}

static fxc_result check_hello(const proto_hello *h)
{
    size_t len;
    if (check_text(h->name, PROTO_NAME_MAX, &len) || check_text(h->token, PROTO_TOKEN_MAX, &len) ||
        check_text(h->strategy, PROTO_STRATEGY_MAX, &len))
        return FXC_ERR_RANGE;
    if (!side_ok(h->width) || !side_ok(h->height) || !fov_ok(h->fov_deg) || h->codec >= PROTO_CODEC_COUNT ||
        !depth_ok(h->depth))
        return FXC_ERR_RANGE;
    /* The quality belongs to JPEG alone: a nonzero quality with a lossless codec is a confused client. */
    bool quality_ok =
        h->codec == PROTO_CODEC_JPEG ? h->jpeg_quality >= 1 && h->jpeg_quality <= 100 : h->jpeg_quality == 0;
    return quality_ok ? FXC_OK : FXC_ERR_RANGE;
}

static fxc_result check_welcome(const proto_welcome *w)
{
    size_t len;
    if (w->viewer_id == 0 || check_text(w->name, PROTO_NAME_MAX, &len) || len == 0)
        return FXC_ERR_RANGE;
    if (!(w->fps > 0.0f) || !isfinite(w->fps))
        return FXC_ERR_RANGE;
    for (int k = 0; k < 3; k++)
        if (!isfinite(w->bounds_min[k]) || !isfinite(w->bounds_max[k]) || w->bounds_min[k] > w->bounds_max[k])
            return FXC_ERR_RANGE;
    return check_pose(&w->camera);
}

static fxc_result check_camera(const proto_camera *c)
{
    if (!isfinite(c->time) || check_pose(&c->pose))
        return FXC_ERR_RANGE;
    if (c->has_predicted && (!isfinite(c->predicted_time) || check_pose(&c->predicted)))
        return FXC_ERR_RANGE;
    return FXC_OK;
}

/* A frame time in milliseconds: finite and not negative. */
static bool ms_ok(float ms)
{
    return isfinite(ms) && ms >= 0.0f;
}

static fxc_result check_frame(const proto_frame *f)
{
    if (check_pose(&f->camera) || !side_ok(f->width) || !side_ok(f->height) ||
        f->codec >= PROTO_CODEC_COUNT || !depth_ok(f->depth))
        return FXC_ERR_RANGE;
    if (!ms_ok(f->stats.frame_ms) || !ms_ok(f->stats.encode_ms))
        return FXC_ERR_RANGE;
    /* Every frame has colour; depth is there exactly when the frame says which depth codec it used. */
    if (f->color_bytes == 0 || (f->depth == PROTO_DEPTH_NONE) != (f->depth_bytes == 0))
        return FXC_ERR_RANGE;
    return FXC_OK;
}

/* A sample request: the image, the count within 1..min(w*h, PROTO_MAX_SAMPLES), every pixel inside the
 * image (O(count): the pixels are the message). NULL pixels with a count are the caller's error. */
static fxc_result check_sample_request(const proto_sample_request *q)
{
    if (check_pose(&q->camera) || !side_ok(q->width) || !side_ok(q->height))
        return FXC_ERR_RANGE;
    uint64_t image = (uint64_t)q->width * q->height;
    if (q->count == 0 || q->count > PROTO_MAX_SAMPLES || q->count > image)
        return FXC_ERR_RANGE;
    if (!q->pixels)
        return FXC_ERR_INVALID;
    for (uint32_t i = 0; i < q->count; i++) {
        uint16_t x, y;
        proto_request_pixel_get(q->pixels, i, &x, &y);
        if (x >= q->width || y >= q->height)
            return FXC_ERR_RANGE;
    }
    return FXC_OK;
}

/* An answer: the image, at most PROTO_MAX_SAMPLES samples, each inside the image, its pad byte 0 and its
 * depth > 0 and not NaN (+infinity is the sky). */
static fxc_result check_samples(const proto_samples *a)
{
    if (check_pose(&a->camera) || !side_ok(a->width) || !side_ok(a->height) || a->count > PROTO_MAX_SAMPLES)
        return FXC_ERR_RANGE;
    if (a->count && !a->samples)
        return FXC_ERR_INVALID;
    for (uint32_t i = 0; i < a->count; i++) {
        proto_sample s;
        proto_sample_get(a->samples, i, &s);
        if (s.x >= a->width || s.y >= a->height || a->samples[(size_t)i * PROTO_SAMPLE_BYTES + 7] != 0 ||
            !(s.depth > 0.0f))
            return FXC_ERR_RANGE;
    }
    return FXC_OK;
}

static fxc_result check_reason(const char *reason)
{
    size_t len;
    return check_text(reason, PROTO_REASON_MAX, &len);
}

/* Validates m and computes its payload size (64-bit: a frame's two u32 payload sizes cannot overflow it). */
static fxc_result payload_size(const proto_msg *m, uint64_t *size)
{
    size_t a, b, c;
    fxc_result r = FXC_OK;
    switch (m->type) {
    case PROTO_HELLO:
        if ((r = check_hello(&m->u.hello)))
            return r;
        check_text(m->u.hello.name, PROTO_NAME_MAX, &a);
        check_text(m->u.hello.token, PROTO_TOKEN_MAX, &b);
        check_text(m->u.hello.strategy, PROTO_STRATEGY_MAX, &c);
        *size = 1 + a + 4 + 4 + 4 + 1 + 1 + 1 + 1 + b + 1 + c;
        break;
    case PROTO_WELCOME:
        if ((r = check_welcome(&m->u.welcome)))
            return r;
        check_text(m->u.welcome.name, PROTO_NAME_MAX, &a);
        *size = 4 + 1 + a + 4 + 3 * 8 + 3 * 8 + POSE_BYTES + 4;
        break;
    case PROTO_CAMERA:
        if ((r = check_camera(&m->u.camera)))
            return r;
        *size = 4 + 8 + POSE_BYTES + 1 + (m->u.camera.has_predicted ? 8 + POSE_BYTES : 0);
        break;
    case PROTO_FRAME:
        if ((r = check_frame(&m->u.frame)))
            return r;
        if (!m->u.frame.color || (m->u.frame.depth_bytes && !m->u.frame.depth_data))
            return FXC_ERR_INVALID;
        *size = 4 + 4 + POSE_BYTES + 4 + 4 + 1 + 1 + 5 * 8 + 4 + 4 + 4 + (uint64_t)m->u.frame.color_bytes +
                4 + (uint64_t)m->u.frame.depth_bytes;
        break;
    case PROTO_STATS_REQUEST: *size = 0; break;
    case PROTO_STATS:
        if (m->u.stats.json_bytes && !m->u.stats.json)
            return FXC_ERR_INVALID;
        *size = 4 + (uint64_t)m->u.stats.json_bytes;
        break;
    case PROTO_ERROR:
        if (m->u.error.code >= 0 || check_reason(m->u.error.reason))
            return FXC_ERR_RANGE;
        *size = 4 + 2 + strlen(m->u.error.reason);
        break;
    case PROTO_BYE:
        if (check_reason(m->u.bye.reason))
            return FXC_ERR_RANGE;
        *size = 2 + strlen(m->u.bye.reason);
        break;
    case PROTO_SAMPLE_REQUEST:
        if ((r = check_sample_request(&m->u.sample_request)))
            return r;
        *size = SAMPLE_REQUEST_FIXED + (uint64_t)m->u.sample_request.count * PROTO_REQUEST_PIXEL_BYTES;
        break;
    case PROTO_SAMPLES:
        if ((r = check_samples(&m->u.samples)))
            return r;
        *size = SAMPLES_FIXED + (uint64_t)m->u.samples.count * PROTO_SAMPLE_BYTES;
        break;
    default: return FXC_ERR_INVALID;
    }
    return *size > PROTO_MAX_PAYLOAD ? FXC_ERR_TOO_LARGE : FXC_OK;
}

/* ---- encoding ---------------------------------------------------------------------------------------- */

/* A write cursor: the size was computed and checked against the capacity before any write. */
typedef struct writer {
    uint8_t *at;
} writer;

static void put_u8(writer *w, uint8_t v)
{
    *w->at++ = v;
}

static void put_u16(writer *w, uint16_t v)
{
    proto_put_u16le(w->at, v);
    w->at += 2;
}

static void put_u32(writer *w, uint32_t v)
{
    proto_put_u32le(w->at, v);
    w->at += 4;
}

static void put_u64(writer *w, uint64_t v)
{
    proto_put_u64le(w->at, v);
    w->at += 8;
}

static void put_f32(writer *w, float v)
{
    put_u32(w, bits_from_f32(v));
}

static void put_f64(writer *w, double v)
{
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits);
    put_u64(w, bits);
}

static void put_bytes(writer *w, const void *bytes, size_t len)
{
    if (len)
        memcpy(w->at, bytes, len);
    w->at += len;
}

/* A name or token: u8 length, then the bytes (validated: at most 255). */
static void put_text8(writer *w, const char *text)
{
    size_t len = strlen(text);
    put_u8(w, (uint8_t)len);
    put_bytes(w, text, len);
}

/* A reason: u16 length, then the bytes. */
static void put_text16(writer *w, const char *text)
{
    size_t len = strlen(text);
    put_u16(w, (uint16_t)len);
    put_bytes(w, text, len);
}

static void put_pose(writer *w, const proto_pose *pose)
{
    for (int k = 0; k < 3; k++)
        put_f64(w, pose->position[k]);
    for (int k = 0; k < 3; k++)
        put_f32(w, pose->direction[k]);
    put_f32(w, pose->fov_deg);
}

static void put_payload(writer *w, const proto_msg *m)
{
    switch (m->type) {
    case PROTO_HELLO: {
        const proto_hello *h = &m->u.hello;
        put_text8(w, h->name);
        put_u32(w, h->width);
        put_u32(w, h->height);
        put_f32(w, h->fov_deg);
        put_u8(w, h->codec);
        put_u8(w, h->jpeg_quality);
        put_u8(w, h->depth);
        put_text8(w, h->token);
        put_text8(w, h->strategy);
        break;
    }
    case PROTO_WELCOME: {
        const proto_welcome *wel = &m->u.welcome;
        put_u32(w, wel->viewer_id);
        put_text8(w, wel->name);
        put_f32(w, wel->fps);
        for (int k = 0; k < 3; k++)
            put_f64(w, wel->bounds_min[k]);
        for (int k = 0; k < 3; k++)
            put_f64(w, wel->bounds_max[k]);
        put_pose(w, &wel->camera);
        put_u32(w, wel->max_camera_rate);
        break;
    }
    case PROTO_CAMERA: {
        const proto_camera *c = &m->u.camera;
        put_u32(w, c->sequence);
        put_f64(w, c->time);
        put_pose(w, &c->pose);
        put_u8(w, c->has_predicted ? 1 : 0);
        if (c->has_predicted) {
            put_f64(w, c->predicted_time);
            put_pose(w, &c->predicted);
        }
        break;
    }
    case PROTO_FRAME: {
        const proto_frame *f = &m->u.frame;
        put_u32(w, f->frame);
        put_u32(w, f->camera_sequence);
        put_pose(w, &f->camera);
        put_u32(w, f->width);
        put_u32(w, f->height);
        put_u8(w, f->codec);
        put_u8(w, f->depth);
        put_u64(w, f->stats.requested_texels);
        put_u64(w, f->stats.requested_cells);
        put_u64(w, f->stats.pixels_visible);
        put_u64(w, f->stats.pixels_missing);
        put_u64(w, f->stats.frames_dropped);
        put_f32(w, f->stats.frame_ms);
        put_f32(w, f->stats.encode_ms);
        put_u32(w, f->color_bytes);
        put_bytes(w, f->color, f->color_bytes);
        put_u32(w, f->depth_bytes);
        put_bytes(w, f->depth_data, f->depth_bytes);
        break;
    }
    case PROTO_STATS_REQUEST: break;
    case PROTO_STATS:
        put_u32(w, m->u.stats.json_bytes);
        put_bytes(w, m->u.stats.json, m->u.stats.json_bytes);
        break;
    case PROTO_ERROR:
        put_u32(w, (uint32_t)m->u.error.code);
        put_text16(w, m->u.error.reason);
        break;
    case PROTO_BYE: put_text16(w, m->u.bye.reason); break;
    case PROTO_SAMPLE_REQUEST: {
        const proto_sample_request *q = &m->u.sample_request;
        put_u32(w, q->request);
        put_pose(w, &q->camera);
        put_u32(w, q->width);
        put_u32(w, q->height);
        put_u32(w, q->count);
        put_bytes(w, q->pixels, (size_t)q->count * PROTO_REQUEST_PIXEL_BYTES);
        break;
    }
    case PROTO_SAMPLES: {
        const proto_samples *a = &m->u.samples;
        put_u32(w, a->request);
        put_u32(w, a->frame);
        put_pose(w, &a->camera);
        put_u32(w, a->width);
        put_u32(w, a->height);
        put_u32(w, a->count);
        put_bytes(w, a->samples, (size_t)a->count * PROTO_SAMPLE_BYTES);
        break;
    }
    }
}

size_t proto_bound(const proto_msg *m)
{
    uint64_t payload;
    if (!m || payload_size(m, &payload) != FXC_OK)
        return 0;
    return PROTO_HEADER_BYTES + (size_t)payload;
}

size_t proto_encode(const proto_msg *m, uint8_t *buf, size_t cap, fxc_result *result)
{
    fxc_result unused;
    if (!result)
        result = &unused;
    uint64_t payload = 0;
    *result = m ? payload_size(m, &payload) : FXC_ERR_INVALID;
    if (*result != FXC_OK)
        return 0;
    if (!buf || cap < PROTO_HEADER_BYTES || payload > cap - PROTO_HEADER_BYTES) {
        *result = FXC_ERR_TOO_LARGE;
        return 0;
    }
    writer w = {buf};
    put_u8(&w, PROTO_MAGIC0);
    put_u8(&w, PROTO_MAGIC1);
    put_u8(&w, PROTO_MAGIC2);
    put_u8(&w, PROTO_MAGIC3);
    put_u16(&w, PROTO_VERSION);
    put_u16(&w, (uint16_t)m->type);
    put_u32(&w, (uint32_t)payload);
    put_payload(&w, m);
    size_t written = (size_t)(w.at - buf);
    assert(written == PROTO_HEADER_BYTES + payload);
    return written;
}

/* ---- decoding ---------------------------------------------------------------------------------------- */

fxc_result proto_decode_header(const uint8_t *buf, size_t len, proto_header *out)
{
    if (!buf || len < PROTO_HEADER_BYTES)
        return FXC_ERR_TRUNCATED;
    if (buf[0] != PROTO_MAGIC0 || buf[1] != PROTO_MAGIC1 || buf[2] != PROTO_MAGIC2 || buf[3] != PROTO_MAGIC3)
        return FXC_ERR_BAD_MAGIC;
    proto_header h = {proto_get_u16le(buf + 4), proto_get_u16le(buf + 6), proto_get_u32le(buf + 8)};
    if (h.version == 0 || h.version > PROTO_VERSION)
        return FXC_ERR_VERSION;
    if (!type_known(h.type))
        return FXC_ERR_UNKNOWN_TYPE;
    if (h.length > PROTO_MAX_PAYLOAD)
        return FXC_ERR_TOO_LARGE;
    if (out)
        *out = h;
    return FXC_OK;
}

/* A read cursor over the payload; the first fault sticks and later reads return zeros. */
typedef struct reader {
    const uint8_t *at;
    size_t left;
    fxc_result fault;
} reader;

/* The next n bytes, or NULL (and FXC_ERR_TRUNCATED) when fewer are left. */
static const uint8_t *take(reader *r, size_t n)
{
    if (r->fault)
        return NULL;
    if (n > r->left) {
        r->fault = FXC_ERR_TRUNCATED;
        return NULL;
    }
    const uint8_t *p = r->at;
    r->at += n;
    r->left -= n;
    return p;
}

static uint8_t get_u8(reader *r)
{
    const uint8_t *p = take(r, 1);
    return p ? p[0] : 0;
}

static uint16_t get_u16(reader *r)
{
    const uint8_t *p = take(r, 2);
    return p ? proto_get_u16le(p) : 0;
}

static uint32_t get_u32(reader *r)
{
    const uint8_t *p = take(r, 4);
    return p ? proto_get_u32le(p) : 0;
}

static uint64_t get_u64(reader *r)
{
    const uint8_t *p = take(r, 8);
    return p ? proto_get_u64le(p) : 0;
}

static float get_f32(reader *r)
{
    return f32_from_bits(get_u32(r));
}

static double get_f64(reader *r)
{
    uint64_t bits = get_u64(r);
    double v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

/* A string of len bytes into out (max + 1 bytes, NUL-terminated): RANGE when longer than max or when a byte
 * is not printable (a NUL inside would silently shorten it). */
static void get_text(reader *r, size_t len, size_t max, char *out)
{
    if (!r->fault && len > max) {
        r->fault = FXC_ERR_RANGE;
        return;
    }
    const uint8_t *p = take(r, len);
    if (!p)
        return;
    for (size_t i = 0; i < len; i++)
        if (!printable(p[i])) {
            r->fault = FXC_ERR_RANGE;
            return;
        }
    memcpy(out, p, len);
    out[len] = 0;
}

static void get_text8(reader *r, size_t max, char *out)
{
    size_t len = get_u8(r);
    get_text(r, len, max, out);
}

static void get_text16(reader *r, size_t max, char *out)
{
    size_t len = get_u16(r);
    get_text(r, len, max, out);
}

/* An optional part's flag: 0 or 1, anything else is RANGE (it decides whether more fields follow). */
static bool get_flag(reader *r)
{
    uint8_t flag = get_u8(r);
    if (!r->fault && flag > 1)
        r->fault = FXC_ERR_RANGE;
    return flag == 1;
}

static void get_pose(reader *r, proto_pose *pose)
{
    for (int k = 0; k < 3; k++)
        pose->position[k] = get_f64(r);
    for (int k = 0; k < 3; k++)
        pose->direction[k] = get_f32(r);
    pose->fov_deg = get_f32(r);
}

/* A u32 byte count, then a pointer to that many bytes of the payload (NULL when the count is 0). */
static const uint8_t *get_blob(reader *r, uint32_t *bytes)
{
    *bytes = get_u32(r);
    const uint8_t *p = take(r, *bytes);
    return *bytes ? p : NULL;
}

/* A sample count, then a pointer to count entries of entry_bytes each: a count above PROTO_MAX_SAMPLES is
 * RANGE as it is read (it decides the layout, and the product cannot overflow below it). */
static const uint8_t *get_entries(reader *r, uint32_t *count, size_t entry_bytes)
{
    *count = get_u32(r);
    if (!r->fault && *count > PROTO_MAX_SAMPLES) {
        r->fault = FXC_ERR_RANGE;
        return NULL;
    }
    const uint8_t *p = take(r, (size_t)*count * entry_bytes);
    return *count ? p : NULL;
}

/* An i32 from its two's complement bits, without the implementation-defined conversion of large values. */
static int32_t int32_from_bits(uint32_t bits)
{
    return bits <= INT32_MAX ? (int32_t)bits : -(int32_t)(~bits) - 1;
}

/* Reads the payload of type into m; validation comes after. */
static void get_payload(reader *r, proto_msg *m)
{
    switch (m->type) {
    case PROTO_HELLO: {
        proto_hello *h = &m->u.hello;
        get_text8(r, PROTO_NAME_MAX, h->name);
        h->width = get_u32(r);
        h->height = get_u32(r);
        h->fov_deg = get_f32(r);
        h->codec = get_u8(r);
        h->jpeg_quality = get_u8(r);
        h->depth = get_u8(r);
        get_text8(r, PROTO_TOKEN_MAX, h->token);
        get_text8(r, PROTO_STRATEGY_MAX, h->strategy);
        break;
    }
    case PROTO_WELCOME: {
        proto_welcome *w = &m->u.welcome;
        w->viewer_id = get_u32(r);
        get_text8(r, PROTO_NAME_MAX, w->name);
        w->fps = get_f32(r);
        for (int k = 0; k < 3; k++)
            w->bounds_min[k] = get_f64(r);
        for (int k = 0; k < 3; k++)
            w->bounds_max[k] = get_f64(r);
        get_pose(r, &w->camera);
        w->max_camera_rate = get_u32(r);
        break;
    }
    case PROTO_CAMERA: {
        proto_camera *c = &m->u.camera;
        c->sequence = get_u32(r);
        c->time = get_f64(r);
        get_pose(r, &c->pose);
        c->has_predicted = get_flag(r);
        if (c->has_predicted) {
            c->predicted_time = get_f64(r);
            get_pose(r, &c->predicted);
        }
        break;
    }
    case PROTO_FRAME: {
        proto_frame *f = &m->u.frame;
        f->frame = get_u32(r);
        f->camera_sequence = get_u32(r);
        get_pose(r, &f->camera);
        f->width = get_u32(r);
        f->height = get_u32(r);
        f->codec = get_u8(r);
        f->depth = get_u8(r);
        f->stats.requested_texels = get_u64(r);
        f->stats.requested_cells = get_u64(r);
        f->stats.pixels_visible = get_u64(r);
        f->stats.pixels_missing = get_u64(r);
        f->stats.frames_dropped = get_u64(r);
        f->stats.frame_ms = get_f32(r);
        f->stats.encode_ms = get_f32(r);
        f->color = get_blob(r, &f->color_bytes);
        f->depth_data = get_blob(r, &f->depth_bytes);
        break;
    }
    case PROTO_STATS_REQUEST: break;
    case PROTO_STATS: m->u.stats.json = (const char *)get_blob(r, &m->u.stats.json_bytes); break;
    case PROTO_ERROR:
        m->u.error.code = int32_from_bits(get_u32(r));
        get_text16(r, PROTO_REASON_MAX, m->u.error.reason);
        break;
    case PROTO_BYE: get_text16(r, PROTO_REASON_MAX, m->u.bye.reason); break;
    case PROTO_SAMPLE_REQUEST: {
        proto_sample_request *q = &m->u.sample_request;
        q->request = get_u32(r);
        get_pose(r, &q->camera);
        q->width = get_u32(r);
        q->height = get_u32(r);
        q->pixels = get_entries(r, &q->count, PROTO_REQUEST_PIXEL_BYTES);
        break;
    }
    case PROTO_SAMPLES: {
        proto_samples *a = &m->u.samples;
        a->request = get_u32(r);
        a->frame = get_u32(r);
        get_pose(r, &a->camera);
        a->width = get_u32(r);
        a->height = get_u32(r);
        a->samples = get_entries(r, &a->count, PROTO_SAMPLE_BYTES);
        break;
    }
    }
}

fxc_result proto_decode(const uint8_t *buf, size_t len, proto_msg *out)
{
    if (!out)
        return FXC_ERR_INVALID;
    memset(out, 0, sizeof *out);
    proto_header h;
    fxc_result result = proto_decode_header(buf, len, &h);
    if (result != FXC_OK)
        return result;
    size_t available = len - PROTO_HEADER_BYTES;
    if (h.length > available)
        return FXC_ERR_TRUNCATED;
    if (h.length < available)
        return FXC_ERR_TRAILING;
    out->type = h.type;
    reader r = {buf + PROTO_HEADER_BYTES, h.length, FXC_OK};
    get_payload(&r, out);
    if (r.fault == FXC_OK && r.left > 0)
        r.fault = FXC_ERR_TRAILING;
    if (r.fault == FXC_OK) {
        uint64_t size;
        r.fault = payload_size(out, &size);
    }
    if (r.fault != FXC_OK) {
        memset(out, 0, sizeof *out);
        return r.fault;
    }
    return FXC_OK;
}
