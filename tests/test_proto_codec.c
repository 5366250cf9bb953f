/* Tests of the payload codecs (proto/proto_codec.c); the wire format's are in test_proto.c.
 *
 * Colour: raw and zstd bit exact; JPEG against a PSNR floor and quality ordering; corrupt payloads refused;
 * encoding from several threads at once gives the same bytes. Depth: binary32 bit exact; binary16 against
 * closed forms, every half value and a half-ulp sweep (and _Float16 where the compiler has it). */
#include "test_util.h"

#include "proto.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zstd.h>

/* ---- codecs: colour ---------------------------------------------------------------------------------- */

/* A w x h image: a smooth gradient, with noise when noisy. */
static uint8_t *make_image(uint32_t w, uint32_t h, bool noisy, uint32_t seed)
{
    uint8_t *rgb = malloc((size_t)w * h * 3);
    assert_non_null(rgb);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            uint8_t *p = rgb + ((size_t)y * w + x) * 3;
            p[0] = (uint8_t)(255 * x / (w > 1 ? w - 1 : 1));
            p[1] = (uint8_t)(255 * y / (h > 1 ? h - 1 : 1));
            p[2] = (uint8_t)(128 + 100 * sin(0.05 * x + 0.03 * y));
            if (noisy)
                for (int c = 0; c < 3; c++)
                    p[c] ^= (uint8_t)(fxt_random(&seed) & 0x1f);
        }
    return rgb;
}

/* Encodes rgb with codec into an allocation of exactly proto_color_bound bytes. */
static uint8_t *color_encode_alloc(uint32_t codec, uint32_t quality, const uint8_t *rgb, uint32_t w,
                                   uint32_t h, size_t *bytes)
{
    size_t bound = proto_color_bound(codec, w, h);
    assert_true(bound > 0);
    uint8_t *out = malloc(bound);
    assert_non_null(out);
    fxc_result result = proto_color_encode(codec, quality, rgb, w, h, out, bound, bytes);
    if (result != FXC_OK)
        fail_msg("%s %ux%u: %s", proto_codec_name(codec), w, h, fxc_strerror(result));
    assert_true(*bytes > 0 && *bytes <= bound);
    return out;
}

/* Decodes into an allocation of exactly w*h*3 bytes; returns it (or NULL, freed, when the decode failed). */
static uint8_t *color_decode_alloc(uint32_t codec, const uint8_t *payload, size_t bytes, uint32_t w,
                                   uint32_t h, fxc_result *result)
{
    uint8_t *rgb = malloc((size_t)w * h * 3);
    assert_non_null(rgb);
    *result = proto_color_decode(codec, payload, bytes, w, h, rgb);
    if (*result != FXC_OK) {
        free(rgb);
        return NULL;
    }
    return rgb;
}

static void test_color_lossless(void **state)
{
    (void)state;
    static const uint32_t sizes[][2] = {{1, 1}, {37, 23}, {640, 360}, {8192, 1}, {1, 300}};
    for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; s++) {
        uint32_t w = sizes[s][0], h = sizes[s][1];
        uint8_t *rgb = make_image(w, h, s % 2 == 1, (uint32_t)s + 1);
        assert_int_equal(proto_color_bound(PROTO_CODEC_RAW, w, h), (size_t)w * h * 3);
        for (uint32_t codec = PROTO_CODEC_RAW; codec <= PROTO_CODEC_ZSTD; codec++) {
            size_t bytes;
            uint8_t *payload = color_encode_alloc(codec, 0, rgb, w, h, &bytes);
            if (codec == PROTO_CODEC_ZSTD) /* the frame names its content size, which the decoder requires */
                assert_true(ZSTD_getFrameContentSize(payload, bytes) == (unsigned long long)w * h * 3);
            fxc_result result;
            uint8_t *back = color_decode_alloc(codec, payload, bytes, w, h, &result);
            assert_int_equal(result, FXC_OK);
            assert_memory_equal(back, rgb, (size_t)w * h * 3);
            free(back);
            free(payload);
        }
        free(rgb);
    }
    /* A flat image compresses: zstd is doing something. */
    uint8_t *flat = calloc((size_t)256 * 256 * 3, 1);
    assert_non_null(flat);
    size_t bytes;
    uint8_t *payload = color_encode_alloc(PROTO_CODEC_ZSTD, 0, flat, 256, 256, &bytes);
    assert_true(bytes < 256 * 256 * 3 / 100);
    free(payload);
    free(flat);
}

/* Peak signal to noise ratio of b against a, in dB, over n bytes. */
static double psnr(const uint8_t *a, const uint8_t *b, size_t n)
{
    double sum = 0;
    for (size_t i = 0; i < n; i++) {
        double d = (double)a[i] - (double)b[i];
        sum += d * d;
    }
    double mse = sum / (double)n;
    return mse == 0 ? INFINITY : 10.0 * log10(255.0 * 255.0 / mse);
}

static void test_color_jpeg(void **state)
{
    (void)state;
    const uint32_t w = 160, h = 96;
    uint8_t *rgb = make_image(w, h, false, 1);
    double quality_psnr[2];
    size_t quality_bytes[2];
    static const uint32_t qualities[2] = {90, 20};
    for (int q = 0; q < 2; q++) {
        size_t bytes;
        uint8_t *payload = color_encode_alloc(PROTO_CODEC_JPEG, qualities[q], rgb, w, h, &bytes);
        assert_true(payload[0] == 0xff && payload[1] == 0xd8); /* SOI */
        fxc_result result;
        uint8_t *back = color_decode_alloc(PROTO_CODEC_JPEG, payload, bytes, w, h, &result);
        assert_int_equal(result, FXC_OK);
        quality_psnr[q] = psnr(rgb, back, (size_t)w * h * 3);
        quality_bytes[q] = bytes;
        free(back);
        free(payload);
    }
    print_message("jpeg 160x96 gradient: quality 90 %.1f dB (%zu bytes), quality 20 %.1f dB (%zu bytes)\n",
                  quality_psnr[0], quality_bytes[0], quality_psnr[1], quality_bytes[1]);
    assert_true(quality_psnr[0] > 42.0); /* 46.6 dB with libjpeg-turbo 2.1.5 */
    assert_true(quality_psnr[1] < quality_psnr[0] - 3.0);
    assert_true(quality_bytes[1] < quality_bytes[0]);
    /* Sizes that are not multiples of the 16x16 block still decode to the whole image. */
    uint8_t *odd = make_image(17, 9, false, 2);
    size_t bytes;
    uint8_t *payload = color_encode_alloc(PROTO_CODEC_JPEG, 95, odd, 17, 9, &bytes);
    fxc_result result;
    uint8_t *back = color_decode_alloc(PROTO_CODEC_JPEG, payload, bytes, 17, 9, &result);
    assert_int_equal(result, FXC_OK);
    assert_true(psnr(odd, back, 17 * 9 * 3) > 30.0);
    free(back);
    free(payload);
    free(odd);
    free(rgb);
}

/* Payloads that must not decode, each from an exact allocation. */
static void expect_color_codec_error(const char *what, uint32_t codec, const uint8_t *payload, size_t bytes,
                                     uint32_t w, uint32_t h)
{
    uint8_t *copy = malloc(bytes ? bytes : 1);
    assert_non_null(copy);
    if (bytes)
        memcpy(copy, payload, bytes);
    fxc_result result;
    uint8_t *back = color_decode_alloc(codec, bytes ? copy : NULL, bytes, w, h, &result);
    if (result != FXC_ERR_CODEC)
        fail_msg("%s: %s", what, fxc_strerror(result));
    free(back);
    free(copy);
}

static void test_color_corrupt(void **state)
{
    (void)state;
    const uint32_t w = 24, h = 16;
    uint8_t *rgb = make_image(w, h, true, 3);
    size_t zstd_bytes, jpeg_bytes;
    uint8_t *zstd = color_encode_alloc(PROTO_CODEC_ZSTD, 0, rgb, w, h, &zstd_bytes);
    uint8_t *jpeg = color_encode_alloc(PROTO_CODEC_JPEG, 80, rgb, w, h, &jpeg_bytes);

    expect_color_codec_error("raw one byte short", PROTO_CODEC_RAW, rgb, w * h * 3 - 1, w, h);
    expect_color_codec_error("raw one byte long", PROTO_CODEC_RAW, rgb, w * h * 3, w, h - 1);
    expect_color_codec_error("raw for a taller image", PROTO_CODEC_RAW, rgb, w * h * 3, w, h + 1);
    expect_color_codec_error("empty zstd", PROTO_CODEC_ZSTD, zstd, 0, w, h);
    expect_color_codec_error("empty jpeg", PROTO_CODEC_JPEG, jpeg, 0, w, h);
    for (size_t cut = 1; cut < zstd_bytes; cut++)
        expect_color_codec_error("truncated zstd", PROTO_CODEC_ZSTD, zstd, cut, w, h);
    for (size_t cut = 1; cut < jpeg_bytes; cut += 7)
        expect_color_codec_error("truncated jpeg", PROTO_CODEC_JPEG, jpeg, cut, w, h);
    expect_color_codec_error("zstd of a smaller image", PROTO_CODEC_ZSTD, zstd, zstd_bytes, w, h + 1);
    expect_color_codec_error("zstd of a larger image", PROTO_CODEC_ZSTD, zstd, zstd_bytes, w - 1, h);
    expect_color_codec_error("jpeg of another width", PROTO_CODEC_JPEG, jpeg, jpeg_bytes, w + 8, h);
    expect_color_codec_error("jpeg of another height", PROTO_CODEC_JPEG, jpeg, jpeg_bytes, w, h / 2);
    expect_color_codec_error("jpeg as zstd", PROTO_CODEC_ZSTD, jpeg, jpeg_bytes, w, h);
    expect_color_codec_error("zstd as jpeg", PROTO_CODEC_JPEG, zstd, zstd_bytes, w, h);

    /* A zstd payload with a byte after the frame, and two frames whose contents add up to the image. */
    uint8_t *longer = malloc(zstd_bytes + 1);
    assert_non_null(longer);
    memcpy(longer, zstd, zstd_bytes);
    longer[zstd_bytes] = 0;
    expect_color_codec_error("zstd with a trailing byte", PROTO_CODEC_ZSTD, longer, zstd_bytes + 1, w, h);
    free(longer);
    size_t half = (size_t)w * h * 3 / 2, cap = 2 * ZSTD_compressBound((size_t)w * h * 3);
    uint8_t *two = malloc(cap);
    assert_non_null(two);
    size_t first = ZSTD_compress(two, cap, rgb, half, 1);
    assert_false(ZSTD_isError(first));
    size_t second = ZSTD_compress(two + first, cap - first, rgb + half, half, 1);
    assert_false(ZSTD_isError(second));
    expect_color_codec_error("two zstd frames", PROTO_CODEC_ZSTD, two, first + second, w, h);
    /* The whole image in the first frame, then an empty second frame: the content adds up, still refused. */
    first = ZSTD_compress(two, cap, rgb, (size_t)w * h * 3, 1);
    assert_false(ZSTD_isError(first));
    second = ZSTD_compress(two + first, cap - first, rgb, 0, 1);
    assert_false(ZSTD_isError(second));
    expect_color_codec_error("zstd and an empty frame", PROTO_CODEC_ZSTD, two, first + second, w, h);
    /* One frame of the right content but without its size in the header. */
    ZSTD_CCtx *cctx = ZSTD_createCCtx();
    assert_non_null(cctx);
    assert_false(ZSTD_isError(ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 0)));
    size_t unsized = ZSTD_compress2(cctx, two, cap, rgb, (size_t)w * h * 3);
    assert_false(ZSTD_isError(unsized));
    ZSTD_freeCCtx(cctx);
    assert_true(ZSTD_getFrameContentSize(two, unsized) == ZSTD_CONTENTSIZE_UNKNOWN);
    expect_color_codec_error("zstd without a content size", PROTO_CODEC_ZSTD, two, unsized, w, h);
    free(two);

    /* Flipped bytes inside the zstd blocks or the JPEG's entropy-coded data. */
    uint32_t rng = 99;
    for (int trial = 0; trial < 300; trial++) {
        uint8_t *copy = malloc(jpeg_bytes);
        assert_non_null(copy);
        memcpy(copy, jpeg, jpeg_bytes);
        copy[fxt_random(&rng) % jpeg_bytes] ^= (uint8_t)(1 + fxt_random(&rng) % 255);
        fxc_result result;
        uint8_t *back = color_decode_alloc(PROTO_CODEC_JPEG, copy, jpeg_bytes, w, h, &result);
        /* Some flips land in the image data and decode to another image; either outcome is allowed. */
        assert_true(result == FXC_OK || result == FXC_ERR_CODEC);
        free(back);
        free(copy);
    }
    /* Random bytes. */
    for (int trial = 0; trial < 200; trial++) {
        size_t bytes = 1 + fxt_random(&rng) % 600;
        uint8_t *noise = malloc(bytes);
        assert_non_null(noise);
        for (size_t i = 0; i < bytes; i++)
            noise[i] = (uint8_t)fxt_random(&rng);
        if (trial % 2) { /* sometimes behind a plausible magic */
            static const uint8_t zstd_magic[4] = {0x28, 0xb5, 0x2f, 0xfd},
                                 jpeg_magic[4] = {0xff, 0xd8, 0xff, 0xdb};
            memcpy(noise, trial % 4 == 1 ? zstd_magic : jpeg_magic, bytes < 4 ? bytes : 4);
        }
        expect_color_codec_error("random zstd", PROTO_CODEC_ZSTD, noise, bytes, w, h);
        expect_color_codec_error("random jpeg", PROTO_CODEC_JPEG, noise, bytes, w, h);
        free(noise);
    }
    /* Arguments. */
    uint8_t pixel[3];
    assert_int_equal(proto_color_decode(PROTO_CODEC_COUNT, zstd, zstd_bytes, w, h, rgb), FXC_ERR_INVALID);
    assert_int_equal(proto_color_decode(PROTO_CODEC_ZSTD, zstd, zstd_bytes, 0, h, rgb), FXC_ERR_INVALID);
    assert_int_equal(proto_color_decode(PROTO_CODEC_ZSTD, zstd, zstd_bytes, w, 8193, rgb), FXC_ERR_INVALID);
    assert_int_equal(proto_color_decode(PROTO_CODEC_RAW, pixel, 3, 1, 1, NULL), FXC_ERR_INVALID);
    free(jpeg);
    free(zstd);
    free(rgb);
}

static void test_color_encode_errors(void **state)
{
    (void)state;
    const uint32_t w = 32, h = 16;
    uint8_t *rgb = make_image(w, h, true, 4);
    uint8_t out[8192];
    size_t bytes = 12345;
    assert_int_equal(proto_color_encode(PROTO_CODEC_COUNT, 0, rgb, w, h, out, sizeof out, &bytes),
                     FXC_ERR_INVALID);
    assert_int_equal(proto_color_encode(PROTO_CODEC_JPEG, 0, rgb, w, h, out, sizeof out, &bytes),
                     FXC_ERR_INVALID);
    assert_int_equal(proto_color_encode(PROTO_CODEC_JPEG, 101, rgb, w, h, out, sizeof out, &bytes),
                     FXC_ERR_INVALID);
    assert_int_equal(proto_color_encode(PROTO_CODEC_RAW, 0, rgb, 0, h, out, sizeof out, &bytes),
                     FXC_ERR_INVALID);
    assert_int_equal(proto_color_encode(PROTO_CODEC_RAW, 0, rgb, w, 8193, out, sizeof out, &bytes),
                     FXC_ERR_INVALID);
    assert_int_equal(proto_color_encode(PROTO_CODEC_RAW, 0, NULL, w, h, out, sizeof out, &bytes),
                     FXC_ERR_INVALID);
    /* Quality is ignored by the lossless codecs. */
    assert_int_equal(proto_color_encode(PROTO_CODEC_ZSTD, 0, rgb, w, h, out, sizeof out, &bytes), FXC_OK);
    assert_int_equal(proto_color_encode(PROTO_CODEC_RAW, 500, rgb, w, h, out, sizeof out, &bytes), FXC_OK);
    /* Too small a buffer, each one exact so a write past it is seen. */
    size_t raw = (size_t)w * h * 3, jpeg_bound = proto_color_bound(PROTO_CODEC_JPEG, w, h);
    const struct {
        uint32_t codec;
        size_t cap;
    } small[] = {{PROTO_CODEC_RAW, raw - 1},
                 {PROTO_CODEC_ZSTD, 16},
                 {PROTO_CODEC_ZSTD, 1},
                 {PROTO_CODEC_JPEG, jpeg_bound - 1}};
    for (size_t i = 0; i < sizeof small / sizeof small[0]; i++) {
        uint8_t *buf = malloc(small[i].cap);
        assert_non_null(buf);
        assert_int_equal(proto_color_encode(small[i].codec, 50, rgb, w, h, buf, small[i].cap, &bytes),
                         FXC_ERR_TOO_LARGE);
        free(buf);
    }
    /* Bounds. */
    assert_int_equal(proto_color_bound(PROTO_CODEC_COUNT, w, h), 0);
    assert_int_equal(proto_color_bound(PROTO_CODEC_RAW, 8193, 1), 0);
    assert_int_equal(proto_color_bound(PROTO_CODEC_ZSTD, 1, 0), 0);
    assert_true(proto_color_bound(PROTO_CODEC_ZSTD, w, h) >= raw);
    assert_true(proto_color_bound(PROTO_CODEC_JPEG, PROTO_MAX_SIDE, PROTO_MAX_SIDE) >=
                (size_t)PROTO_MAX_SIDE * PROTO_MAX_SIDE);
    free(rgb);
}

/* Several threads encoding and decoding at once get the bytes one thread gets alone. */
typedef struct codec_job {
    const uint8_t *rgb;
    const uint8_t *want_jpeg, *want_zstd;
    size_t want_jpeg_bytes, want_zstd_bytes;
    int failures;
} codec_job;

enum { THREAD_W = 96, THREAD_H = 64 };

static void *codec_thread(void *arg)
{
    codec_job *job = arg;
    size_t cap = proto_color_bound(PROTO_CODEC_JPEG, THREAD_W, THREAD_H);
    size_t zcap = proto_color_bound(PROTO_CODEC_ZSTD, THREAD_W, THREAD_H);
    if (zcap > cap)
        cap = zcap;
    uint8_t *out = malloc(cap), *back = malloc((size_t)THREAD_W * THREAD_H * 3);
    for (int round = 0; out && back && round < 40; round++) {
        size_t bytes;
        if (proto_color_encode(PROTO_CODEC_JPEG, 75, job->rgb, THREAD_W, THREAD_H, out, cap, &bytes) !=
                FXC_OK ||
            bytes != job->want_jpeg_bytes || memcmp(out, job->want_jpeg, bytes) != 0 ||
            proto_color_decode(PROTO_CODEC_JPEG, out, bytes, THREAD_W, THREAD_H, back) != FXC_OK)
            job->failures++;
        if (proto_color_encode(PROTO_CODEC_ZSTD, 0, job->rgb, THREAD_W, THREAD_H, out, cap, &bytes) !=
                FXC_OK ||
            bytes != job->want_zstd_bytes || memcmp(out, job->want_zstd, bytes) != 0 ||
            proto_color_decode(PROTO_CODEC_ZSTD, out, bytes, THREAD_W, THREAD_H, back) != FXC_OK ||
            memcmp(back, job->rgb, (size_t)THREAD_W * THREAD_H * 3) != 0)
            job->failures++;
    }
    if (!out || !back)
        job->failures++;
    free(out);
    free(back);
    return NULL;
}

static void test_codec_threads(void **state)
{
    (void)state;
    uint8_t *rgb = make_image(THREAD_W, THREAD_H, true, 5);
    size_t jpeg_bytes, zstd_bytes;
    uint8_t *jpeg = color_encode_alloc(PROTO_CODEC_JPEG, 75, rgb, THREAD_W, THREAD_H, &jpeg_bytes);
    uint8_t *zstd = color_encode_alloc(PROTO_CODEC_ZSTD, 0, rgb, THREAD_W, THREAD_H, &zstd_bytes);
    enum { THREADS = 4 };
    pthread_t threads[THREADS];
    codec_job jobs[THREADS];
    for (int t = 0; t < THREADS; t++) {
        jobs[t] = (codec_job){rgb, jpeg, zstd, jpeg_bytes, zstd_bytes, 0};
        assert_int_equal(pthread_create(&threads[t], NULL, codec_thread, &jobs[t]), 0);
    }
    for (int t = 0; t < THREADS; t++) {
        pthread_join(threads[t], NULL);
        assert_int_equal(jobs[t].failures, 0);
    }
    free(zstd);
    free(jpeg);
    free(rgb);
}

/* ---- codecs: depth ----------------------------------------------------------------------------------- */

/* Encodes count = w*h depths and decodes them again (exact allocations); returns the decoded values. */
static float *depth_round_trip(uint32_t depth, const float *values, uint32_t w, uint32_t h)
{
    size_t bound = proto_depth_bound(depth, w, h);
    assert_true(bound > 0);
    uint8_t *payload = malloc(bound);
    float *back = malloc((size_t)w * h * sizeof(float));
    assert_non_null(payload);
    assert_non_null(back);
    size_t bytes = 0;
    fxc_result result = proto_depth_encode(depth, values, w, h, payload, bound, &bytes);
    if (result != FXC_OK)
        fail_msg("depth %u %ux%u: %s", depth, w, h, fxc_strerror(result));
    assert_true(bytes > 0 && bytes <= bound);
    assert_true(ZSTD_getFrameContentSize(payload, bytes) == (unsigned long long)w * h * (depth / 8));
    uint8_t *exact = malloc(bytes);
    assert_non_null(exact);
    memcpy(exact, payload, bytes);
    assert_int_equal(proto_depth_decode(depth, exact, bytes, w, h, back), FXC_OK);
    free(exact);
    free(payload);
    return back;
}

static void test_depth_float_exact(void **state)
{
    (void)state;
    const uint32_t w = 300, h = 70; /* more values than one encoder chunk */
    float *values = malloc((size_t)w * h * sizeof(float));
    assert_non_null(values);
    uint32_t rng = 7;
    for (size_t i = 0; i < (size_t)w * h; i++)
        values[i] = fxt_float_from_bits(fxt_random(&rng));
    values[0] = INFINITY;
    values[1] = 0.0f;
    values[2] = -0.0f;
    values[3] = fxt_float_from_bits(1); /* smallest subnormal */
    values[4] = 1e30f;
    values[5] = fxt_float_from_bits(0x7fc01234u); /* a NaN with a payload: the bits travel as they are */
    float *back = depth_round_trip(PROTO_DEPTH_FLOAT, values, w, h);
    assert_memory_equal(back, values, (size_t)w * h * sizeof(float));
    free(back);
    free(values);
}

/* binary16 through the codec against values worked out by hand. */
static void test_depth_half_closed_forms(void **state)
{
    (void)state;
    const float ulp_sub = 5.9604644775390625e-8f; /* 2^-24, the smallest subnormal half */
    const struct {
        float in, out;
    } cases[] = {
        {1.0f, 1.0f},
        {-2.0f, -2.0f},
        {65504.0f, 65504.0f}, /* the largest half */
        {65519.0f, 65504.0f}, /* below the midpoint to 2^16 */
        {65520.0f, INFINITY}, /* the midpoint: ties to even, which is 2^16: overflow */
        {1e6f, INFINITY},
        {-65520.0f, -INFINITY},
        {INFINITY, INFINITY},
        {-INFINITY, -INFINITY},
        {1e-8f, 0.0f},                          /* 0.168 of the smallest subnormal */
        {ulp_sub, ulp_sub},                     /* 2^-24 exact */
        {ulp_sub / 2, 0.0f},                    /* 2^-25: a tie, to the even 0 */
        {ulp_sub * 0.75f, ulp_sub},             /* above the tie */
        {ulp_sub * 1.5f, 2 * ulp_sub},          /* tie between 1 and 2 ulps: to the even 2 */
        {ulp_sub * 2.5f, 2 * ulp_sub},          /* tie between 2 and 3: to the even 2 */
        {ulp_sub * 1023.0f, ulp_sub * 1023.0f}, /* the largest subnormal */
        {ulp_sub * 1023.5f, 6.103515625e-5f},   /* tie to the even 1024 = 2^-14, the smallest normal */
        {6.103515625e-5f, 6.103515625e-5f},
        {1.0f + 0x1p-11f, 1.0f},               /* tie between 1 and 1 + 2^-10: to the even 1 */
        {1.0f + 3 * 0x1p-11f, 1.0f + 0x1p-9f}, /* tie between 1 + 2^-10 and 1 + 2^-9: to the even one */
        {1.0f + 0x1p-11f + 0x1p-20f, 1.0f + 0x1p-10f}, /* just above the tie */
        {1.0f / 3.0f, 0.333251953125f},                /* 0x3555 */
        {0.1f, 0.0999755859375f},                      /* 0x2e66 */
        {2049.0f, 2048.0f}, /* the spacing is 2 from 2048: a tie, to the even 2048 */
        {2051.0f, 2052.0f}, /* a tie, to the even 2052 */
        {0.0f, 0.0f},
        {fxt_float_from_bits(1), 0.0f}, /* a float subnormal */
    };
    enum { COUNT = sizeof cases / sizeof cases[0] };
    float in[COUNT + 4];
    for (int i = 0; i < COUNT; i++)
        in[i] = cases[i].in;
    in[COUNT] = -0.0f;
    in[COUNT + 1] = NAN;
    in[COUNT + 2] = -1e-9f;                           /* rounds to -0 */
    in[COUNT + 3] = fxt_float_from_bits(0xff800001u); /* a NaN whose payload lies only in the dropped bits */
    float *back = depth_round_trip(PROTO_DEPTH_HALF, in, COUNT + 4, 1);
    for (int i = 0; i < COUNT; i++)
        if (fxt_bits_from_float(back[i]) != fxt_bits_from_float(cases[i].out))
            fail_msg("half(%.10g) = %.10g, expected %.10g", cases[i].in, back[i], cases[i].out);
    assert_int_equal(fxt_bits_from_float(back[COUNT]), 0x80000000u);
    assert_true(isnan(back[COUNT + 1]));
    assert_int_equal(fxt_bits_from_float(back[COUNT + 2]), 0x80000000u);
    assert_true(isnan(back[COUNT + 3]) && signbit(back[COUNT + 3]));
    free(back);
}

/* The value of half bits by the formula of IEEE 754 (not the codec's bit manipulation). */
static double half_value(uint16_t bits)
{
    int exponent = (bits >> 10) & 31, mantissa = bits & 1023;
    double sign = (bits & 0x8000) ? -1.0 : 1.0;
    if (exponent == 31)
        return mantissa ? NAN : sign * INFINITY;
    if (exponent == 0)
        return sign * ldexp(mantissa, -24);
    return sign * ldexp(1024 + mantissa, exponent - 25);
}

/* Every one of the 65536 halves survives float -> half -> float exactly (NaNs stay NaN). */
static void test_depth_half_every_value(void **state)
{
    (void)state;
    float *values = malloc(65536 * sizeof(float));
    assert_non_null(values);
    for (uint32_t bits = 0; bits < 65536; bits++)
        values[bits] = (float)half_value((uint16_t)bits);
    float *back = depth_round_trip(PROTO_DEPTH_HALF, values, 8192, 8);
    for (uint32_t bits = 0; bits < 65536; bits++) {
        if (isnan(values[bits]))
            assert_true(isnan(back[bits]));
        else if (fxt_bits_from_float(back[bits]) != fxt_bits_from_float(values[bits]))
            fail_msg("half 0x%04x: %.10g came back as %.10g", bits, values[bits], back[bits]);
    }
    free(back);
    free(values);
}

/* A sweep over [2^-26, 65504]: the error is at most half an ulp of binary16 at that value, and a tie goes to
 * an even mantissa; with _Float16 available, the result equals the compiler's conversion too. */
static void test_depth_half_sweep(void **state)
{
    (void)state;
    const uint32_t w = 8192, h = 40;
    size_t count = (size_t)w * h;
    float *values = malloc(count * sizeof(float));
    assert_non_null(values);
    uint32_t rng = 11;
    double lo = log(0x1p-26), hi = log(65504.0);
    for (size_t i = 0; i < count; i++) {
        double t = (double)i / (double)(count - 1);
        float v = (float)exp(lo + (hi - lo) * t);
        if (i % 3 == 1) /* and a random float of the same binade */
            v = fxt_float_from_bits((fxt_bits_from_float(v) & 0xff800000u) | (fxt_random(&rng) & 0x7fffffu));
        if (v > 65504.0f)
            v = 65504.0f;
        values[i] = (i % 2) ? -v : v;
    }
    float *back = depth_round_trip(PROTO_DEPTH_HALF, values, w, h);
    double worst = 0;
    for (size_t i = 0; i < count; i++) {
        double x = fabs((double)values[i]), y = fabs((double)back[i]);
        assert_true(!signbit(values[i]) == !signbit(back[i]));
        int exponent;
        frexp(x, &exponent); /* x = f * 2^exponent, f in [0.5, 1) */
        int e = exponent - 1 < -14 ? -14 : exponent - 1;
        double ulp = ldexp(1.0, e - 10);
        double error = fabs(y - x) / ulp;
        if (error > worst)
            worst = error;
        if (error > 0.5)
            fail_msg("half(%.10g) = %.10g: %.4f ulp", values[i], back[i], error);
        if (error == 0.5) { /* a tie: the mantissa of the result is even */
            double units = y / ulp;
            assert_true(fmod(units, 2.0) == 0.0);
        }
#ifdef __FLT16_MAX__
        _Float16 reference = (_Float16)values[i];
        if (fxt_bits_from_float((float)reference) != fxt_bits_from_float(back[i]))
            fail_msg("half(%.10g) = %.10g, _Float16 says %.10g", values[i], back[i],
                     (double)(float)reference);
#endif
    }
    print_message("binary16 sweep: %zu values, worst error %.4f ulp\n", count, worst);
    assert_true(worst > 0.49); /* the sweep does reach near-ties */
    free(back);
    free(values);
}

static void test_depth_errors(void **state)
{
    (void)state;
    const uint32_t w = 40, h = 30;
    float values[40 * 30];
    uint32_t rng = 5;
    for (size_t i = 0; i < w * h; i++)
        values[i] = (float)(fxt_random(&rng) % 100000) / 100.0f;
    for (uint32_t depth = PROTO_DEPTH_HALF; depth <= PROTO_DEPTH_FLOAT; depth += 16) {
        size_t bound = proto_depth_bound(depth, w, h);
        assert_true(bound >= w * h * (depth / 8));
        uint8_t *payload = malloc(bound);
        assert_non_null(payload);
        size_t bytes;
        assert_int_equal(proto_depth_encode(depth, values, w, h, payload, bound, &bytes), FXC_OK);
        float *back = malloc((size_t)w * (h + 1) * sizeof(float)); /* room for the wrong sizes tried below */
        assert_non_null(back);
        for (size_t cut = 1; cut < bytes; cut += 3) {
            uint8_t *copy = malloc(cut);
            assert_non_null(copy);
            memcpy(copy, payload, cut);
            assert_int_equal(proto_depth_decode(depth, copy, cut, w, h, back), FXC_ERR_CODEC);
            free(copy);
        }
        assert_int_equal(proto_depth_decode(depth, payload, bytes, w, h + 1, back), FXC_ERR_CODEC);
        assert_int_equal(proto_depth_decode(depth, payload, bytes, w / 2, h, back), FXC_ERR_CODEC);
        /* Read as the other depth codec: the content size is twice or half what it claims. */
        assert_int_equal(proto_depth_decode(depth ^ 48, payload, bytes, w, h, back), FXC_ERR_CODEC);
        assert_int_equal(proto_depth_decode(depth, NULL, 0, w, h, back), FXC_ERR_CODEC);
        for (int trial = 0; trial < 100; trial++) {
            for (size_t i = 4; i < bytes; i++)
                payload[i] = (uint8_t)fxt_random(&rng);
            assert_int_equal(proto_depth_decode(depth, payload, bytes, w, h, back), FXC_ERR_CODEC);
        }
        /* Too small a buffer. */
        uint8_t small[16];
        assert_int_equal(proto_depth_encode(depth, values, w, h, small, sizeof small, &bytes),
                         FXC_ERR_TOO_LARGE);
        free(back);
        free(payload);
    }
    /* Incompressible values still fit in the bound (exact allocation). */
    const uint32_t big_w = 512, big_h = 300;
    float *noise = malloc((size_t)big_w * big_h * sizeof(float));
    assert_non_null(noise);
    for (size_t i = 0; i < (size_t)big_w * big_h; i++)
        noise[i] = fxt_float_from_bits(fxt_random(&rng) & 0x7f7fffffu);
    for (uint32_t depth = PROTO_DEPTH_HALF; depth <= PROTO_DEPTH_FLOAT; depth += 16) {
        float *back = depth_round_trip(depth, noise, big_w, big_h);
        if (depth == PROTO_DEPTH_FLOAT)
            assert_memory_equal(back, noise, (size_t)big_w * big_h * sizeof(float));
        free(back);
    }
    free(noise);
    /* Arguments. */
    uint8_t out[64];
    size_t bytes;
    float one = 1.0f;
    assert_int_equal(proto_depth_bound(PROTO_DEPTH_NONE, w, h), 0);
    assert_int_equal(proto_depth_bound(8, w, h), 0);
    assert_int_equal(proto_depth_bound(PROTO_DEPTH_HALF, 0, h), 0);
    assert_int_equal(proto_depth_encode(PROTO_DEPTH_NONE, &one, 1, 1, out, sizeof out, &bytes),
                     FXC_ERR_INVALID);
    assert_int_equal(proto_depth_encode(PROTO_DEPTH_HALF, &one, 8193, 1, out, sizeof out, &bytes),
                     FXC_ERR_INVALID);
    assert_int_equal(proto_depth_decode(PROTO_DEPTH_NONE, out, 10, 1, 1, &one), FXC_ERR_INVALID);
    assert_int_equal(proto_depth_decode(17, out, 10, 1, 1, &one), FXC_ERR_INVALID);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_color_lossless),          cmocka_unit_test(test_color_jpeg),
        cmocka_unit_test(test_color_corrupt),           cmocka_unit_test(test_color_encode_errors),
        cmocka_unit_test(test_codec_threads),           cmocka_unit_test(test_depth_float_exact),
        cmocka_unit_test(test_depth_half_closed_forms), cmocka_unit_test(test_depth_half_every_value),
        cmocka_unit_test(test_depth_half_sweep),        cmocka_unit_test(test_depth_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
