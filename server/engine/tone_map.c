/* The tone map of compose: linear radiance to an sRGB byte, (1 - e^-c) followed by the sRGB encoding, through
 * tables built once (srv__tone_map_init), equal for every float to its definition with expf
 * (srv__tone_map_reference; tests/test_engine.c compares them). Rows go 8 floats at a time through AVX2's
 * gathers where the CPU has them. Declared in engine_internal.h. */
#include "engine_internal.h"
#include "fxc_hot.h"

#include <math.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The tone map's rows with AVX2 gathers (tone_map_avx2) where the compiler and the CPU have them. */
#if defined(__x86_64__) && defined(__GNUC__) && defined(__linux__) && !defined(FXC_NO_CLONES)
#include <immintrin.h>
#define TONE_MAP_AVX2 1
#else
#define TONE_MAP_AVX2 0
#endif
static bool tone_use_avx2; /* set once with the table */

enum { TONE_LUT_SIZE = 4096 };

/* The tone map (1 - e^-c) followed by the sRGB encoding, tabulated over the tone-mapped value in [0, 1]:
 * two transcendental calls per channel and pixel were most of compose's time. */
static uint8_t tone_lut[TONE_LUT_SIZE];

/* A check of a table's premise at start-up: a programming error if it fails, in every build type. */
#define FX_CHECK(cond)                                                                                       \
    do {                                                                                                     \
        if (!(cond)) {                                                                                       \
            fprintf(stderr, "%s:%d: compose: check failed: %s\n", __FILE__, __LINE__, #cond);                \
            abort();                                                                                         \
        }                                                                                                    \
    } while (0)
/* The tone map without expf: a table indexed by the top bits of the float (its exponent and 8 bits of
 * mantissa), so each cell spans 1/256 of an octave of radiance. Within a cell the byte changes at most once
 * (checked when the table is built): the cell holds its first byte and the radiance where the next begins. */
enum {
    TONE_EXP_LO = 107, /* 2^-20: below it every byte is 0 (checked) */
    TONE_EXP_HI = 132, /* 2^5 = 32: from 20 on every byte is 255 */
    TONE_CELLS = (TONE_EXP_HI - TONE_EXP_LO) << 8,
};
static uint8_t tone_cell_byte[TONE_CELLS];
static int32_t tone_cell_byte32[TONE_CELLS]; /* the same, 32 bits wide for the lanes' gathers */
static float tone_cell_next[TONE_CELLS];
static pthread_once_t tone_lut_once = PTHREAD_ONCE_INIT;

/* Linear radiance to an sRGB byte through the tone map, with expf: the definition. */
static uint8_t tone_map_reference(float c)
{
    if (!(c > 0))
        return 0;
    float mapped = c < 20.0f ? 1.0f - expf(-c) : 1.0f;
    return tone_lut[(int)(mapped * (TONE_LUT_SIZE - 1) + 0.5f)];
}

static float float_of_bits(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

static void tone_lut_init(void)
{
    for (int i = 0; i < TONE_LUT_SIZE; i++) {
        float c = (float)i / (TONE_LUT_SIZE - 1);
        float e = c <= 0.0031308f ? 12.92f * c : 1.055f * powf(c, 1.0f / 2.4f) - 0.055f;
        tone_lut[i] = (uint8_t)(e * 255.0f + 0.5f);
    }
    FX_CHECK(tone_map_reference(float_of_bits((uint32_t)TONE_EXP_LO << 23)) == 0);
    FX_CHECK(tone_map_reference(20.0f) == 255);
    for (uint32_t cell = 0; cell < TONE_CELLS; cell++) {
        uint32_t first = ((uint32_t)TONE_EXP_LO << 23) + (cell << 15), last = first + (1u << 15) - 1;
        uint8_t lo_byte = tone_map_reference(float_of_bits(first)),
                hi_byte = tone_map_reference(float_of_bits(last));
        FX_CHECK(hi_byte - lo_byte <= 1); /* one change at most: the table's premise */
        tone_cell_byte[cell] = lo_byte;
        tone_cell_byte32[cell] = lo_byte;
        tone_cell_next[cell] = INFINITY;
        if (hi_byte == lo_byte)
            continue;
        uint32_t lo = first, hi = last; /* byte(lo) = lo_byte, byte(hi) = lo_byte + 1 */
        while (hi - lo > 1) {
            uint32_t mid = lo + (hi - lo) / 2;
            if (tone_map_reference(float_of_bits(mid)) > lo_byte)
                hi = mid;
            else
                lo = mid;
        }
        tone_cell_next[cell] = float_of_bits(hi);
    }
#if TONE_MAP_AVX2
    tone_use_avx2 = __builtin_cpu_supports("avx2");
#endif
}

/* Linear radiance to an sRGB byte, equal to tone_map_reference() for every float (tests/test_engine.c). */
static inline uint8_t tone_map_srgb8(float c)
{
    if (!(c >= 0x1p-20f)) /* also NaN and every c <= 0 */
        return 0;
    if (c >= 20.0f)
        return 255;
    uint32_t bits;
    memcpy(&bits, &c, sizeof bits);
    uint32_t cell = (bits >> 15) - ((uint32_t)TONE_EXP_LO << 8);
    return (uint8_t)(tone_cell_byte[cell] + (c >= tone_cell_next[cell]));
}

/* tone_map_srgb8 of n consecutive floats (the channels of a row of a run's pixels), one call per row instead of
 * one inlined call per channel; the same bytes (tests/test_engine.c). Written for lanes (FXC_HOT_LANES), but
 * GCC 12 leaves it scalar: at -O2 its cheap cost model refuses a loop of variable length, and a fixed-length
 * version (48 lanes, branch-free) vectorised with emulated gathers (element inserts and extracts, no vgather
 * under the generic tuning), longer than the scalar loop, so it was not kept. */
FXC_HOT_LANES static void tone_map_lanes(const float *radiance, uint8_t *image, uint32_t n)
{
    for (uint32_t j = 0; j < n; j++) {
        float c = radiance[j];
        uint32_t bits;
        memcpy(&bits, &c, sizeof bits);
        int low = !(c >= 0x1p-20f), high = c >= 20.0f; /* low: also NaN and every c <= 0 */
        uint32_t cell = (low | high) ? 0 : (bits >> 15) - ((uint32_t)TONE_EXP_LO << 8);
        int32_t byte = tone_cell_byte32[cell] + (c >= tone_cell_next[cell]);
        image[j] = (uint8_t)(low ? 0 : (high ? 255 : byte));
    }
}

/* The tone map with AVX2's gathers, 8 floats at a time, where the CPU has them: the same bytes as
 * tone_map_lanes (the same cell, the same table entries and the same compares; srv__tone_map_lanes takes this
 * path in tests/test_engine.c on such a CPU). GCC does not emit these gathers itself under the generic tuning
 * (it emulates them with element inserts), so they are written with intrinsics. The tail goes through
 * tone_map_lanes. */
#if TONE_MAP_AVX2
__attribute__((target("avx2"))) static void tone_map_avx2(const float *radiance, uint8_t *image, uint32_t n)
{
    const __m256 lowest = _mm256_set1_ps(0x1p-20f), highest = _mm256_set1_ps(20.0f);
    const __m256i first_cell = _mm256_set1_epi32(TONE_EXP_LO << 8), all_ones = _mm256_set1_epi32(255);
    uint32_t j = 0;
    for (; j + 8 <= n; j += 8) {
        __m256 c = _mm256_loadu_ps(radiance + j);
        __m256i low = _mm256_castps_si256(_mm256_cmp_ps(c, lowest, _CMP_NGE_UQ)); /* !(c >= 2^-20), NaN too */
        __m256i high = _mm256_castps_si256(_mm256_cmp_ps(c, highest, _CMP_GE_OQ));
        __m256i outside = _mm256_or_si256(low, high);
        __m256i cell = _mm256_sub_epi32(_mm256_srli_epi32(_mm256_castps_si256(c), 15), first_cell);
        cell = _mm256_andnot_si256(outside, cell); /* cell 0 outside, as in tone_map_lanes */
        __m256i byte = _mm256_i32gather_epi32(tone_cell_byte32, cell, 4);
        __m256 next = _mm256_i32gather_ps(tone_cell_next, cell, 4);
        byte = _mm256_sub_epi32(byte, _mm256_castps_si256(_mm256_cmp_ps(c, next, _CMP_GE_OQ))); /* + 1 */
        byte = _mm256_or_si256(_mm256_andnot_si256(outside, byte), _mm256_and_si256(high, all_ones));
        __m256i words = _mm256_packus_epi32(byte, byte);   /* per 128-bit half: its 4 values, twice */
        __m256i bytes = _mm256_packus_epi16(words, words); /* the same as bytes */
        uint32_t lo4 = (uint32_t)_mm_cvtsi128_si32(_mm256_castsi256_si128(bytes));
        uint32_t hi4 = (uint32_t)_mm_cvtsi128_si32(_mm256_extracti128_si256(bytes, 1));
        memcpy(image + j, &lo4, 4);
        memcpy(image + j + 4, &hi4, 4);
    }
    if (j < n)
        tone_map_lanes(radiance + j, image + j, n - j);
}
#endif

/* A row of n floats to bytes: tone_map_avx2 where the CPU has AVX2, else tone_map_lanes. */
static inline void tone_map_row(const float *radiance, uint8_t *image, uint32_t n)
{
#if TONE_MAP_AVX2
    if (tone_use_avx2) {
        tone_map_avx2(radiance, image, n);
        return;
    }
#endif
    tone_map_lanes(radiance, image, n);
}

uint8_t srv__tone_map(float c)
{
    pthread_once(&tone_lut_once, tone_lut_init);
    return tone_map_srgb8(c);
}

void srv__tone_map_lanes(const float *radiance, uint8_t *image, uint32_t n)
{
    pthread_once(&tone_lut_once, tone_lut_init);
    tone_map_row(radiance, image, n);
}

uint8_t srv__tone_map_reference(float c)
{
    pthread_once(&tone_lut_once, tone_lut_init);
    return tone_map_reference(c);
}

void srv__tone_map_init(void)
{
    pthread_once(&tone_lut_once, tone_lut_init);
}

void srv__tone_map_row(const float *radiance, uint8_t *image, uint32_t n)
{
    tone_map_row(radiance, image, n);
}
