/* proto_codec.c: the codecs of a frame's payloads (proto.h, docs/PROTOCOL.md "Codecs"). Colour: raw sRGB,
 * zstd of it, or baseline JPEG 4:2:0 (libturbojpeg). Depth: IEEE binary16 (converted here by hand, so the
 * rounding is the same on every host) or binary32, little-endian, then zstd.
 *
 * The server encodes from several threads at once, so nothing here is shared between calls: each call makes
 * its own zstd context or turbojpeg handle and frees it before returning. Decoders treat the payload as
 * untrusted: they check the size the payload claims against width x height before decompressing, decompress
 * into exactly the caller's buffer, and refuse any payload that does not fill it exactly. */
#include "proto.h"

#include <string.h>
#include <turbojpeg.h>
#include <zstd.h>
#include <zstd_errors.h>

/* zstd level 1: the fastest standard level; a frame stream is encoded 30+ times a second per viewer, and
 * higher levels cost several times the time for a few percent of size on rendered images. */
enum { ZSTD_FRAME_LEVEL = 1 };

/* Values converted per step of the depth encoder (on the stack: no allocation the size of the frame). */
enum { DEPTH_CHUNK_VALUES = 4096 };

static bool sides_ok(uint32_t width, uint32_t height)
{
    return width >= 1 && width <= PROTO_MAX_SIDE && height >= 1 && height <= PROTO_MAX_SIDE;
}

/* The code for a zstd error: the caller's buffer was too small, or the library failed. */
static fxc_result zstd_failure(size_t code)
{
    return ZSTD_getErrorCode(code) == ZSTD_error_dstSize_tooSmall ? FXC_ERR_TOO_LARGE : FXC_ERR_CODEC;
}

/* Decompresses a payload that must be one zstd frame declaring exactly `bytes` of content, into out
 * (`bytes` bytes). Anything else (several frames, trailing bytes, an unknown or different content size, a
 * corrupt block) is FXC_ERR_CODEC. */
static fxc_result zstd_decode_exact(const uint8_t *payload, size_t payload_bytes, uint8_t *out, size_t bytes)
{
    if (!payload || payload_bytes == 0)
        return FXC_ERR_CODEC;
    size_t frame_bytes = ZSTD_findFrameCompressedSize(payload, payload_bytes);
    if (ZSTD_isError(frame_bytes) || frame_bytes != payload_bytes)
        return FXC_ERR_CODEC;
    unsigned long long content = ZSTD_getFrameContentSize(payload, payload_bytes);
    if (content == ZSTD_CONTENTSIZE_UNKNOWN || content == ZSTD_CONTENTSIZE_ERROR || content != bytes)
        return FXC_ERR_CODEC;
    size_t got = ZSTD_decompress(out, bytes, payload, payload_bytes);
    return !ZSTD_isError(got) && got == bytes ? FXC_OK : FXC_ERR_CODEC;
}

/* ---- colour ------------------------------------------------------------------------------------------ */

size_t proto_color_bound(uint32_t codec, uint32_t width, uint32_t height)
{
    if (!sides_ok(width, height))
        return 0;
    size_t raw = (size_t)width * height * 3; /* at most 8192 * 8192 * 3: no overflow */
    switch (codec) {
    case PROTO_CODEC_RAW: return raw;
    case PROTO_CODEC_ZSTD: return ZSTD_compressBound(raw);
    case PROTO_CODEC_JPEG: {
        unsigned long bound = tjBufSize((int)width, (int)height, TJSAMP_420);
        return bound == (unsigned long)-1 ? 0 : (size_t)bound;
    }
    }
    return 0;
}

fxc_result proto_color_encode(uint32_t codec, uint32_t quality, const uint8_t *rgb, uint32_t width,
                              uint32_t height, uint8_t *out, size_t cap, size_t *out_bytes)
{
    if (codec >= PROTO_CODEC_COUNT || !sides_ok(width, height) || !rgb || !out || !out_bytes)
        return FXC_ERR_INVALID;
    if (codec == PROTO_CODEC_JPEG && (quality < 1 || quality > 100))
        return FXC_ERR_INVALID;
    *out_bytes = 0;
    size_t raw = (size_t)width * height * 3;
    switch (codec) {
    case PROTO_CODEC_RAW:
        if (cap < raw)
            return FXC_ERR_TOO_LARGE;
        memcpy(out, rgb, raw);
        *out_bytes = raw;
        return FXC_OK;
    case PROTO_CODEC_ZSTD: {
        size_t got = ZSTD_compress(out, cap, rgb, raw, ZSTD_FRAME_LEVEL);
        if (ZSTD_isError(got))
            return zstd_failure(got);
        *out_bytes = got;
        return FXC_OK;
    }
    default: {
        /* With TJFLAG_NOREALLOC turbojpeg takes the buffer to be tjBufSize() long whatever we say, so a
         * smaller buffer must be refused here rather than overrun there. */
        if (cap < proto_color_bound(codec, width, height))
            return FXC_ERR_TOO_LARGE;
        tjhandle jpeg = tjInitCompress();
        if (!jpeg)
            return FXC_ERR_CODEC;
        unsigned char *dst = out;
        unsigned long size = (unsigned long)cap;
        /* The default (accurate) DCT: with SIMD it costs about what the fast one does, and the fast one loses
         * accuracy at the high qualities a viewer asks for. */
        int failed = tjCompress2(jpeg, rgb, (int)width, 0, (int)height, TJPF_RGB, &dst, &size, TJSAMP_420,
                                 (int)quality, TJFLAG_NOREALLOC);
        tjDestroy(jpeg);
        if (failed || dst != out || size > cap)
            return FXC_ERR_CODEC;
        *out_bytes = size;
        return FXC_OK;
    }
    }
}

fxc_result proto_color_decode(uint32_t codec, const uint8_t *payload, size_t payload_bytes, uint32_t width,
                              uint32_t height, uint8_t *rgb)
{
    if (codec >= PROTO_CODEC_COUNT || !sides_ok(width, height) || !rgb)
        return FXC_ERR_INVALID;
    size_t raw = (size_t)width * height * 3;
    switch (codec) {
    case PROTO_CODEC_RAW:
        if (!payload || payload_bytes != raw)
            return FXC_ERR_CODEC;
        memcpy(rgb, payload, raw);
        return FXC_OK;
    case PROTO_CODEC_ZSTD: return zstd_decode_exact(payload, payload_bytes, rgb, raw);
    default: {
        if (!payload || payload_bytes == 0)
            return FXC_ERR_CODEC;
        tjhandle jpeg = tjInitDecompress();
        if (!jpeg)
            return FXC_ERR_CODEC;
        int jpeg_width = 0, jpeg_height = 0, subsampling = 0, colorspace = 0;
        fxc_result result = FXC_ERR_CODEC;
        /* The header's size must be ours before any pixel is written: turbojpeg would otherwise scale, or
         * write a larger image past the end of rgb. Stop on warnings (corrupt data) and limit progressive
         * scans, so a hostile payload costs neither a half-decoded image nor unbounded time. */
        if (tjDecompressHeader3(jpeg, payload, (unsigned long)payload_bytes, &jpeg_width, &jpeg_height,
                                &subsampling, &colorspace) == 0 &&
            jpeg_width == (int)width && jpeg_height == (int)height &&
            tjDecompress2(jpeg, payload, (unsigned long)payload_bytes, rgb, (int)width, 0, (int)height,
                          TJPF_RGB, TJFLAG_STOPONWARNING | TJFLAG_LIMITSCANS) == 0)
            result = FXC_OK;
        tjDestroy(jpeg);
        return result;
    }
    }
}

/* ---- depth: binary16 ----------------------------------------------------------------------------------- */

/* binary32 bits -> binary16 bits, rounded to nearest, ties to even. Above the largest half (65504) values
 * round to +-infinity from 65520 on (the midpoint to 2^16); below 2^-14 the result is subnormal; NaN stays a
 * (quiet) NaN with its sign. */
static uint16_t half_from_float_bits(uint32_t bits)
{
    uint16_t sign = (uint16_t)((bits >> 16) & 0x8000u);
    uint32_t magnitude = bits & 0x7fffffffu;
    if (magnitude >= 0x7f800000u) /* infinity or NaN */
        return magnitude == 0x7f800000u ? (uint16_t)(sign | 0x7c00u)
                                        : (uint16_t)(sign | 0x7e00u | ((magnitude >> 13) & 0x3ffu));
    if (magnitude >= 0x477ff000u) /* >= 65520 */
        return (uint16_t)(sign | 0x7c00u);
    if (magnitude >= 0x38800000u) { /* >= 2^-14: a normal half */
        uint32_t rebiased = magnitude - ((127u - 15u) << 23);
        /* Round the 13 dropped bits to nearest even; a carry moves into the exponent, as it should. */
        rebiased += 0x0fffu + ((rebiased >> 13) & 1u);
        return (uint16_t)(sign | (rebiased >> 13));
    }
    /* Subnormal half: m = round(value / 2^-24) with value = full * 2^(exponent - 150). */
    uint32_t exponent = magnitude >> 23;
    if (exponent < 102) /* value < 2^-25: rounds to zero (and float subnormals are far below) */
        return sign;
    uint32_t full = (magnitude & 0x7fffffu) | 0x800000u;
    uint32_t shift = 126u - exponent; /* 14..24 */
    uint32_t m = full >> shift;
    uint32_t rest = full & ((1u << shift) - 1u);
    uint32_t half_way = 1u << (shift - 1u);
    if (rest > half_way || (rest == half_way && (m & 1u)))
        m++; /* m may become 1024: the smallest normal, which is the right answer */
    return (uint16_t)(sign | m);
}

/* binary16 bits -> binary32 bits (exact: every half is a float). */
static uint32_t float_bits_from_half(uint16_t half)
{
    uint32_t sign = (uint32_t)(half & 0x8000u) << 16;
    uint32_t exponent = (half >> 10) & 0x1fu;
    uint32_t mantissa = half & 0x3ffu;
    if (exponent == 31)
        return sign | 0x7f800000u | (mantissa << 13);
    if (exponent != 0)
        return sign | ((exponent + 127u - 15u) << 23) | (mantissa << 13);
    if (mantissa == 0)
        return sign;
    /* Subnormal: normalise the mantissa (value = mantissa * 2^-24). */
    uint32_t shift = 0;
    while (!(mantissa & 0x400u)) {
        mantissa <<= 1;
        shift++;
    }
    return sign | ((127u - 15u + 1u - shift) << 23) | ((mantissa & 0x3ffu) << 13);
}

/* ---- depth ------------------------------------------------------------------------------------------- */

/* Bytes per depth value, 0 for NONE or an unknown depth codec. */
static size_t depth_value_bytes(uint32_t depth)
{
    return depth == PROTO_DEPTH_HALF ? 2 : depth == PROTO_DEPTH_FLOAT ? 4 : 0;
}

size_t proto_depth_bound(uint32_t depth, uint32_t width, uint32_t height)
{
    size_t value_bytes = depth_value_bytes(depth);
    if (!value_bytes || !sides_ok(width, height))
        return 0;
    return ZSTD_compressBound((size_t)width * height * value_bytes);
}

/* Writes values[0..count) as little-endian binary16 or binary32 into bytes. */
static void depth_to_bytes(size_t value_bytes, const float *values, size_t count, uint8_t *bytes)
{
    for (size_t i = 0; i < count; i++) {
        uint32_t bits;
        memcpy(&bits, &values[i], sizeof bits);
        if (value_bytes == 2)
            proto_put_u16le(bytes + 2 * i, half_from_float_bits(bits));
        else
            proto_put_u32le(bytes + 4 * i, bits);
    }
}

fxc_result proto_depth_encode(uint32_t depth, const float *values, uint32_t width, uint32_t height,
                              uint8_t *out, size_t cap, size_t *out_bytes)
{
    size_t value_bytes = depth_value_bytes(depth);
    if (!value_bytes || !sides_ok(width, height) || !values || !out || !out_bytes)
        return FXC_ERR_INVALID;
    *out_bytes = 0;
    size_t count = (size_t)width * height;
    ZSTD_CCtx *zstd = ZSTD_createCCtx();
    if (!zstd)
        return FXC_ERR_CODEC;
    /* Streamed in chunks converted on the stack; the pledged size puts the content size in the frame header,
     * which the decoder requires. */
    size_t status = ZSTD_CCtx_setParameter(zstd, ZSTD_c_compressionLevel, ZSTD_FRAME_LEVEL);
    if (!ZSTD_isError(status))
        status = ZSTD_CCtx_setPledgedSrcSize(zstd, (unsigned long long)(count * value_bytes));
    fxc_result result = ZSTD_isError(status) ? FXC_ERR_CODEC : FXC_OK;
    ZSTD_outBuffer output = {out, cap, 0};
    uint8_t chunk[DEPTH_CHUNK_VALUES * 4];
    for (size_t first = 0; result == FXC_OK && first < count; first += DEPTH_CHUNK_VALUES) {
        size_t n = count - first < DEPTH_CHUNK_VALUES ? count - first : DEPTH_CHUNK_VALUES;
        bool last = first + n == count;
        depth_to_bytes(value_bytes, values + first, n, chunk);
        ZSTD_inBuffer input = {chunk, n * value_bytes, 0};
        for (;;) {
            size_t before_in = input.pos, before_out = output.pos;
            size_t remaining =
                ZSTD_compressStream2(zstd, &output, &input, last ? ZSTD_e_end : ZSTD_e_continue);
            if (ZSTD_isError(remaining)) {
                result = zstd_failure(remaining);
                break;
            }
            bool done = last ? remaining == 0 : input.pos == input.size;
            if (done)
                break;
            /* No room left to make progress: the caller's buffer is too small. */
            if (output.pos == output.size || (input.pos == before_in && output.pos == before_out)) {
                result = FXC_ERR_TOO_LARGE;
                break;
            }
        }
    }
    ZSTD_freeCCtx(zstd);
    if (result == FXC_OK)
        *out_bytes = output.pos;
    return result;
}

fxc_result proto_depth_decode(uint32_t depth, const uint8_t *payload, size_t payload_bytes, uint32_t width,
                              uint32_t height, float *values)
{
    size_t value_bytes = depth_value_bytes(depth);
    if (!value_bytes || !sides_ok(width, height) || !values)
        return FXC_ERR_INVALID;
    size_t count = (size_t)width * height;
    size_t bytes = count * value_bytes;
    /* Decompress into the end of the caller's float buffer, then widen forwards in place: value i is read
     * from byte 4 * count - bytes + value_bytes * i, at or after where it is written (4 * i), and the write
     * ends before value i + 1 is read, so no unread byte is overwritten. */
    uint8_t *base = (uint8_t *)values;
    uint8_t *packed = base + (count * 4 - bytes);
    fxc_result result = zstd_decode_exact(payload, payload_bytes, packed, bytes);
    if (result != FXC_OK)
        return result;
    for (size_t i = 0; i < count; i++) {
        uint32_t bits = value_bytes == 2 ? float_bits_from_half(proto_get_u16le(packed + 2 * i))
                                         : proto_get_u32le(packed + 4 * i);
        memcpy(base + 4 * i, &bits, sizeof bits);
    }
    return FXC_OK;
}
