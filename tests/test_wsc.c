/* test_wsc.c: tests of the world-space cache (cache/wsc.c) and of the two generalisations of the osc core it
 * is built on (pools of 1-element blocks, single-pool caches whose keys use all 64 bits): WGI packing
 * against the documented bit layout with both ends of every axis at every level and refusal one beyond
 * (never a wrap, never UINT64_MAX); the level formula against its closed form and monotone over a dense
 * sweep; grid points against integer references and nested across levels (a static grid); trilinear
 * corners reproducing positions; 4 x 4 x 4 bricks next to probes in one cache; the per-viewer local
 * lookup table against the table under moving cameras with evictions and re-maps; exact memory accounting
 * through a counting allocator with failure at every allocation; refusal counting; description errors.
 * White-box where it needs to be: reaches the osc core's internals through osc_internal.h. */
#include "test_util.h"

#include "cache.h"
#include "osc_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- helpers ----------------------------------------------------------------------------------------------- */

static uint64_t rng_next(uint64_t *state)
{
    uint64_t z = (*state += 0x9e3779b97f4a7c15ull); /* splitmix64 */
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static double rng_unit(uint64_t *state)
{
    return (double)(rng_next(state) >> 11) / 9007199254740992.0; /* [0, 1) */
}

static int32_t rng_range(uint64_t *state, int32_t lo, int32_t hi) /* [lo, hi] */
{
    return lo + (int32_t)(rng_next(state) % (uint64_t)(hi - lo + 1));
}

static wsc_cache *create_or_fail(const wsc_desc *desc)
{
    wsc_cache *cache = NULL;
    char message[256];
    osc_result result = wsc_create(desc, &cache, message, sizeof message);
    if (result != OSC_OK)
        fail_msg("wsc_create: %s: %s", osc_result_string(result), message);
    return cache;
}

/* The cache the brick tests share: effect 0 probe-like (1 x 1 x 1, 16 bytes per cell), effect 3 a test-only
 * volumetric effect (4 x 4 x 4, 4 bytes per cell). */
static wsc_desc two_effect_desc(uint32_t probe_bricks, uint32_t volume_bricks)
{
    wsc_desc desc = {0};
    desc.effects[0] = (wsc_effect_desc){.cell_bytes = 16, .brick_size = 1, .max_bricks = probe_bricks};
    desc.effects[3] = (wsc_effect_desc){.cell_bytes = 4, .brick_size = 4, .max_bricks = volume_bricks};
    return desc;
}

/* floor(a / b) by a second method (double floor) for the brick references. */
static int32_t floor_div(int32_t a, int32_t b)
{
    return (int32_t)floor((double)a / (double)b);
}

/* ---- WGIs ---------------------------------------------------------------------------------------------------- */

static void test_wgi_layout_and_round_trip(void **state)
{
    (void)state;
    uint64_t wgi = 0;
    /* The documented bit positions: the lowest coordinates are stored as 0, one step up sets one bit. */
    assert_true(wsc_wgi_pack(0, WSC_XZ_MIN, WSC_Y_MIN, WSC_XZ_MIN, &wgi));
    assert_true(wgi == 0);
    assert_true(wsc_wgi_pack(0, WSC_XZ_MIN + 1, WSC_Y_MIN, WSC_XZ_MIN, &wgi) && wgi == 1ull << 0);
    assert_true(wsc_wgi_pack(0, WSC_XZ_MIN, WSC_Y_MIN, WSC_XZ_MIN + 1, &wgi) && wgi == 1ull << 21);
    assert_true(wsc_wgi_pack(0, WSC_XZ_MIN, WSC_Y_MIN + 1, WSC_XZ_MIN, &wgi) && wgi == 1ull << 42);
    assert_true(wsc_wgi_pack(1, WSC_XZ_MIN, WSC_Y_MIN, WSC_XZ_MIN, &wgi) && wgi == 1ull << 60);
    /* The origin: each offset is one bit at the top of its field. */
    assert_true(wsc_wgi_pack(0, 0, 0, 0, &wgi) && wgi == ((1ull << 20) | (1ull << 41) | (1ull << 59)));
    /* The highest valid WGI: level 14 and every coordinate at its top; not UINT64_MAX. */
    assert_true(wsc_wgi_pack(WSC_MAX_LEVEL, WSC_XZ_MAX, WSC_Y_MAX, WSC_XZ_MAX, &wgi));
    assert_true(wgi == (UINT64_MAX >> 4 | 14ull << 60));
    assert_true(wgi != UINT64_MAX);

    /* Both ends and their neighbours on every axis, at every level, plus random values; round trip. */
    const int32_t xz_values[] = {WSC_XZ_MIN, WSC_XZ_MIN + 1, -1, 0, 1, WSC_XZ_MAX - 1, WSC_XZ_MAX};
    const int32_t y_values[] = {WSC_Y_MIN, WSC_Y_MIN + 1, -1, 0, 1, WSC_Y_MAX - 1, WSC_Y_MAX};
    uint64_t rng = 11;
    for (uint32_t level = 0; level <= WSC_MAX_LEVEL; level++) {
        for (int i = 0; i < 7 * 7 * 7 + 500; i++) {
            int32_t gx, gy, gz;
            if (i < 343) {
                gx = xz_values[i % 7], gy = y_values[(i / 7) % 7], gz = xz_values[i / 49];
            } else {
                gx = rng_range(&rng, WSC_XZ_MIN, WSC_XZ_MAX), gy = rng_range(&rng, WSC_Y_MIN, WSC_Y_MAX);
                gz = rng_range(&rng, WSC_XZ_MIN, WSC_XZ_MAX);
            }
            assert_true(wsc_wgi_pack(level, gx, gy, gz, &wgi));
            assert_true(wgi != UINT64_MAX);
            assert_int_equal(wsc_wgi_level(wgi), level);
            uint32_t out_level = 99;
            int32_t ox = 0, oy = 0, oz = 0;
            assert_true(wsc_wgi_unpack(wgi, &out_level, &ox, &oy, &oz));
            assert_true(out_level == level && ox == gx && oy == gy && oz == gz);
        }
    }
    /* Level 15 is reserved: never packed, never unpacked (so UINT64_MAX is no WGI). */
    assert_false(wsc_wgi_pack(15, 0, 0, 0, &wgi));
    assert_false(wsc_wgi_unpack(UINT64_MAX, NULL, NULL, NULL, NULL));
    assert_false(wsc_wgi_unpack(15ull << 60, NULL, NULL, NULL, NULL));
}

/* One beyond each end of each axis is refused at every level and leaves the output alone (no wrap). */
static void test_wgi_refusals(void **state)
{
    (void)state;
    static const struct {
        int32_t gx, gy, gz;
    } beyond[] = {
        {WSC_XZ_MIN - 1, 0, 0}, {WSC_XZ_MAX + 1, 0, 0}, {0, WSC_Y_MIN - 1, 0}, {0, WSC_Y_MAX + 1, 0},
        {0, 0, WSC_XZ_MIN - 1}, {0, 0, WSC_XZ_MAX + 1}, {INT32_MIN, 0, 0},     {0, INT32_MAX, 0},
    };
    for (uint32_t level = 0; level <= 16; level++) {
        for (size_t i = 0; i < sizeof beyond / sizeof beyond[0]; i++) {
            uint64_t wgi = 12345;
            assert_false(wsc_wgi_pack(level, beyond[i].gx, beyond[i].gy, beyond[i].gz, &wgi));
            assert_true(wgi == 12345);
            int32_t g[3] = {beyond[i].gx, beyond[i].gy, beyond[i].gz};
            uint64_t bit = 77;
            assert_false(wsc_brick_of(g, level < 15 ? level : 0, 4, &wgi, &bit));
            assert_false(wsc_brick_of(g, level < 15 ? level : 0, 1, &wgi, &bit));
            assert_true(wgi == 12345 && bit == 77);
        }
    }
}

/* ---- levels and the grid -------------------------------------------------------------------------------- */

static void test_level_formula(void **state)
{
    (void)state;
    const double c0 = 0.25;
    /* Closed form at the boundaries: level l covers (16 c0 2^(l-1), 16 c0 2^l]. */
    static const struct {
        double distance;
        uint32_t level;
    } expected[] = {{0.0, 0},
                    {4.0, 0},
                    {4.000000000000001, 1},
                    {8.0, 1},
                    {8.000000000000002, 2},
                    {4096.0, 10},
                    {1e300, WSC_MAX_LEVEL},
                    {INFINITY, WSC_MAX_LEVEL},
                    {NAN, 0},
                    {-5.0, 0},
                    {-INFINITY, 0},
                    {5e-324, 0}};
    for (size_t i = 0; i < sizeof expected / sizeof expected[0]; i++)
        assert_int_equal(wsc_level(expected[i].distance, c0), expected[i].level);
    /* Random distances: 8 < distance / cell <= 16 for levels 1..13 (cells distance/16..distance/8 wide). */
    uint64_t rng = 3;
    for (int i = 0; i < 20000; i++) {
        double distance = ldexp(1.0 + rng_unit(&rng), rng_range(&rng, -10, 20));
        uint32_t level = wsc_level(distance, c0);
        double cells = distance / wsc_cell_size(level, c0);
        if (level == 0)
            assert_true(cells <= 16.0);
        else if (level < WSC_MAX_LEVEL)
            assert_true(cells > 8.0 && cells <= 16.0);
    }
    /* Dense sweep, multiplicative steps from tiny to huge, then inf: never decreasing. */
    const double scales[] = {0.25, 1e-3, 7.0, 1e6};
    for (size_t s = 0; s < 4; s++) {
        uint32_t previous = wsc_level(-1.0, scales[s]);
        uint32_t seen_max = previous;
        for (double distance = 1e-300; distance < 1e300; distance *= 1.0 + 1.0 / 64.0) {
            uint32_t level = wsc_level(distance, scales[s]);
            assert_true(level >= previous);
            previous = level;
            seen_max = level;
            /* Around every exact boundary, one ulp either side. */
            double below = nextafter(distance, 0.0), above = nextafter(distance, INFINITY);
            assert_true(wsc_level(below, scales[s]) <= level && level <= wsc_level(above, scales[s]));
        }
        assert_int_equal(seen_max, WSC_MAX_LEVEL);
        assert_true(wsc_level(INFINITY, scales[s]) >= previous);
    }
}

/* Grid points against an integer reference, nested across levels (static grid), refused beyond range, and
 * the refusals counted by the cache's stats. */
static void test_grid_static_and_refusals(void **state)
{
    (void)state;
    const double c0 = 0.25;
    uint64_t rng = 5;
    for (int i = 0; i < 20000; i++) {
        uint32_t level = (uint32_t)rng_range(&rng, 0, WSC_MAX_LEVEL);
        double cell = wsc_cell_size(level, c0);
        assert_true(cell == c0 * (double)(1u << level));
        /* A point strictly inside cell k (fractions away from the faces) has grid point k. */
        int32_t k[3] = {rng_range(&rng, -100000, 100000), rng_range(&rng, -30000, 30000),
                        rng_range(&rng, -100000, 100000)};
        double world[3];
        for (int a = 0; a < 3; a++)
            world[a] = ((double)k[a] + 0.01 + 0.98 * rng_unit(&rng)) * cell;
        int32_t g[3];
        assert_true(wsc_grid_point(world, level, c0, g));
        assert_memory_equal(g, k, sizeof g);
        /* Static and nested: at level + 1 the point lies in the parent cell floor(k / 2), whatever camera
         * chose the level (the function takes none). */
        if (level < WSC_MAX_LEVEL) {
            int32_t parent[3];
            assert_true(wsc_grid_point(world, level + 1, c0, parent));
            for (int a = 0; a < 3; a++)
                assert_int_equal(parent[a], floor_div(k[a], 2));
        }
    }
    /* Far from the scene origin (world = local + origin): still exact. */
    double far[3] = {200000.0 + 0.3, -32000.0 + 0.1, -250000.0 + 0.2};
    int32_t g[3];
    assert_true(wsc_grid_point(far, 0, c0, g));
    assert_true(g[0] == 800001 && g[1] == -128000 && g[2] == -1000000);

    /* Range ends: the last cell inside is accepted, the next refused, per axis and level; non-finite
     * coordinates refused. Count the refusals into a cache and read them back. */
    wsc_desc desc = two_effect_desc(16, 16);
    wsc_cache *cache = create_or_fail(&desc);
    uint64_t refused[2] = {0, 0};
    for (uint32_t level = 0; level <= WSC_MAX_LEVEL; level++) {
        double cell = wsc_cell_size(level, c0);
        for (int axis = 0; axis < 3; axis++) {
            double lo = axis == 1 ? WSC_Y_MIN : WSC_XZ_MIN, hi = axis == 1 ? WSC_Y_MAX : WSC_XZ_MAX;
            double inside[2] = {lo * cell, (hi + 0.5) * cell},
                   outside[2] = {(lo - 0.5) * cell, (hi + 1.0) * cell};
            for (int end = 0; end < 2; end++) {
                double p[3] = {0.5, 0.5, 0.5};
                p[axis] = inside[end];
                int32_t out[3] = {7, 7, 7};
                assert_true(wsc_grid_point(p, level, c0, out));
                assert_int_equal(out[axis], end ? (int32_t)hi : (int32_t)lo);
                p[axis] = outside[end];
                out[0] = out[1] = out[2] = 7;
                bool ok = wsc_grid_point(p, level, c0, out);
                assert_false(ok);
                assert_true(out[0] == 7 && out[1] == 7 && out[2] == 7);
                refused[level & 1] += !ok;
            }
        }
    }
    const double bad[] = {NAN, INFINITY, -INFINITY, 1e300};
    for (int i = 0; i < 4; i++) {
        double p[3] = {1.0, bad[i], 1.0};
        refused[0] += !wsc_grid_point(p, 0, c0, g);
    }
    wsc_count_refusals(cache, 0, refused[0]);
    wsc_count_refusals(cache, 3, refused[1]);
    wsc_stats stats;
    wsc_stats_get(cache, &stats);
    /* 15 levels x 3 axes x 2 ends: 8 even levels -> 48 (+4 non-finite), 7 odd levels -> 42. */
    assert_int_equal(stats.effects[0].refusals, 52);
    assert_int_equal(stats.effects[3].refusals, 42);
    assert_int_equal(stats.refusals, 94);
    wsc_destroy(cache);
}

/* The 8 corners and weights: weights sum to 1, interpolate the position itself (a linear function)
 * exactly, give weight 1 to corner 0 at a grid point, and refuse the last cell of the range. */
static void test_corners(void **state)
{
    (void)state;
    const double c0 = 0.5;
    uint64_t rng = 9;
    int32_t corners[8][3];
    float weights[8];
    for (int i = 0; i < 5000; i++) {
        uint32_t level = (uint32_t)rng_range(&rng, 0, 6);
        double cell = wsc_cell_size(level, c0);
        double world[3] = {(rng_unit(&rng) - 0.5) * 2000.0, (rng_unit(&rng) - 0.5) * 300.0,
                           (rng_unit(&rng) - 0.5) * 2000.0};
        assert_true(wsc_corners(world, level, c0, corners, weights));
        int32_t g[3];
        assert_true(wsc_grid_point(world, level, c0, g));
        double sum = 0.0, interpolated[3] = {0.0, 0.0, 0.0};
        for (int c = 0; c < 8; c++) {
            assert_true(weights[c] >= 0.0f);
            sum += weights[c];
            for (int a = 0; a < 3; a++) {
                assert_int_equal(corners[c][a], g[a] + ((c >> a) & 1));
                interpolated[a] += weights[c] * (double)(corners[c][a] - g[a]); /* in cells, from g */
            }
        }
        assert_true(fabs(sum - 1.0) < 1e-6);
        for (int a = 0; a < 3; a++)
            assert_true(fabs(interpolated[a] - (world[a] / cell - g[a])) < 1e-6);
    }
    double on_point[3] = {3.0 * c0, -2.0 * c0, 5.0 * c0};
    assert_true(wsc_corners(on_point, 0, c0, corners, weights));
    assert_true(weights[0] == 1.0f);
    assert_int_equal(corners[0][0], 3);
    assert_int_equal(corners[7][1], -1);
    double last[3] = {(WSC_XZ_MAX + 0.5) * c0, 0.0, 0.0};
    assert_false(wsc_corners(last, 0, c0, corners, weights));
    last[0] = (WSC_XZ_MAX - 0.5) * c0;
    assert_true(wsc_corners(last, 0, c0, corners, weights));
    assert_int_equal(corners[1][0], WSC_XZ_MAX);
}

/* ---- bricks ------------------------------------------------------------------------------------------------ */

/* A test-only 4 x 4 x 4 effect next to a probe-like 1 x 1 x 1 effect in one cache: cells map to the right
 * brick and bit, payloads have the right size and are distinct, the two tables are independent. */
static void test_bricks_4x4x4_next_to_probes(void **state)
{
    (void)state;
    enum { POINTS = 3000 };
    wsc_desc desc = two_effect_desc(4096, 4096);
    wsc_cache *cache = create_or_fail(&desc);
    assert_int_equal(wsc_brick_bytes(cache, 0), 16);
    assert_int_equal(wsc_brick_bytes(cache, 3), 64 * 4);
    assert_int_equal(wsc_brick_size(cache, 3), 4);
    assert_int_equal(wsc_brick_size(cache, 1), 0);

    static int32_t points[POINTS][4]; /* gx, gy, gz, level */
    static uint64_t probe_wgis[POINTS], probe_masks[POINTS], brick_wgis[POINTS], brick_masks[POINTS];
    static uint64_t ref_wgis[POINTS], ref_masks[POINTS];
    size_t ref_count = 0;
    uint64_t rng = 21;
    for (int i = 0; i < POINTS; i++) {
        int32_t g[3] = {rng_range(&rng, -20, 20), rng_range(&rng, -9, 9), rng_range(&rng, -20, 20)};
        uint32_t level = (uint32_t)rng_range(&rng, 0, 2);
        memcpy(points[i], g, sizeof g);
        points[i][3] = (int32_t)level;
        assert_true(wsc_brick_of(g, level, 1, &probe_wgis[i], &probe_masks[i]));
        assert_true(probe_masks[i] == 1);
        assert_true(wsc_brick_of(g, level, 4, &brick_wgis[i], &brick_masks[i]));
        /* Reference: brick b = floor(g / 4) by double floor, cell l = g - 4b, bit (lz * 4 + ly) * 4 + lx. */
        int32_t b[3], l[3];
        for (int a = 0; a < 3; a++) {
            b[a] = floor_div(g[a], 4);
            l[a] = g[a] - 4 * b[a];
        }
        uint64_t expected_wgi;
        assert_true(wsc_wgi_pack(level, b[0], b[1], b[2], &expected_wgi));
        assert_true(brick_wgis[i] == expected_wgi);
        assert_true(brick_masks[i] == 1ull << ((l[2] * 4 + l[1]) * 4 + l[0]));
        int32_t first[3];
        uint32_t first_level;
        assert_true(wsc_brick_first_cell(brick_wgis[i], 4, &first_level, first));
        assert_int_equal(first_level, level);
        for (int a = 0; a < 3; a++)
            assert_true(g[a] - first[a] >= 0 && g[a] - first[a] < 4);
        /* Reference requested mask per brick (linear search: small). */
        size_t r = 0;
        while (r < ref_count && ref_wgis[r] != expected_wgi)
            r++;
        if (r == ref_count) {
            ref_wgis[ref_count] = expected_wgi;
            ref_masks[ref_count++] = 0;
        }
        ref_masks[r] |= brick_masks[i];
    }
    wsc_begin_frame(cache, 0);
    size_t unique_probes, unique_bricks;
    static uint32_t bricks[POINTS];
    assert_int_equal(wsc_request_batch(cache, 0, probe_wgis, probe_masks, POINTS, &unique_probes, bricks),
                     OSC_OK);
    assert_int_equal(wsc_request_batch(cache, 3, brick_wgis, brick_masks, POINTS, &unique_bricks, bricks),
                     OSC_OK);
    assert_int_equal(unique_bricks, ref_count);
    for (size_t r = 0; r < ref_count; r++) {
        uint32_t brick = wsc_find(cache, 3, ref_wgis[r]);
        assert_int_not_equal(brick, WSC_NONE);
        assert_true(wsc_brick_requested(cache, 3, brick) == ref_masks[r]);
        assert_true(wsc_brick_key(cache, 3, brick) == ref_wgis[r]);
        /* The whole payload is writable (the sanitizer build checks the bounds). */
        memset(wsc_brick_payload(cache, 3, brick), (int)(r & 0xFF), 64 * 4);
    }
    uint32_t frame_count;
    wsc_frame_bricks(cache, 3, &frame_count);
    assert_int_equal(frame_count, ref_count);
    wsc_stats stats;
    wsc_stats_get(cache, &stats);
    assert_int_equal(stats.effects[0].entries, unique_probes);
    assert_int_equal(stats.effects[3].entries, ref_count);
    assert_int_equal(stats.effects[3].bricks_resident, ref_count);
    assert_int_equal(stats.effects[1].entries, 0);

    /* The same WGI in both effects names two bricks with separate payloads. */
    uint64_t shared_wgi;
    assert_true(wsc_wgi_pack(0, 1, 1, 1, &shared_wgi));
    uint64_t wgi_a = shared_wgi, wgi_b = shared_wgi, mask_a = 1, mask_b = 1ull << 63;
    uint32_t brick_a, brick_b;
    assert_int_equal(wsc_request_batch(cache, 0, &wgi_a, &mask_a, 1, NULL, &brick_a), OSC_OK);
    assert_int_equal(wsc_request_batch(cache, 3, &wgi_b, &mask_b, 1, NULL, &brick_b), OSC_OK);
    unsigned char *payload_a = wsc_brick_payload(cache, 0, brick_a),
                  *payload_b = wsc_brick_payload(cache, 3, brick_b);
    assert_true(payload_a + 16 <= payload_b || payload_b + 256 <= payload_a);
    memset(payload_a, 0xAA, 16);
    memset(payload_b, 0x55, 256);
    assert_int_equal(payload_a[15], 0xAA);
    assert_int_equal(payload_b[0], 0x55);
    assert_true(wsc_brick_requested(cache, 0, brick_a) == 1);
    assert_true((wsc_brick_requested(cache, 3, brick_b) & (1ull << 63)) != 0);
    wsc_destroy(cache);
}

/* ---- the local lookup table ------------------------------------------------------------------------------ */

/* Random camera motion, requests around the camera, small pools (evictions inside requests and in
 * housekeeping, so WGIs are evicted and re-mapped to other bricks): every local lookup, of fresh and of old
 * WGIs, returns exactly what wsc_find returns, and that brick's key is the WGI. */
static void test_local_agrees_with_table(void **state)
{
    (void)state;
    enum { FRAMES = 80, POINTS = 300, HISTORY = 4096 };
    const double c0 = 0.25;
    wsc_desc desc = two_effect_desc(600, 24);
    desc.initial_age_frames = 2;
    desc.max_age_frames = 6;
    wsc_cache *cache = create_or_fail(&desc);
    wsc_local *locals[2];
    wsc_local_desc small = {.side = 4, .levels = 3}; /* small: collisions, and levels >= 3 bypass */
    assert_int_equal(wsc_local_create(&small, cache, &locals[0], NULL, 0), OSC_OK);
    assert_int_equal(wsc_local_create(NULL, cache, &locals[1], NULL, 0), OSC_OK);
    static uint64_t wgis[2][POINTS * 8], masks[2][POINTS * 8], history[HISTORY];
    size_t history_count = 0;
    uint64_t rng = 77, lookups = 0;
    double camera[3] = {1000.0, 20.0, -3000.0};
    const uint32_t effects[2] = {0, 3};

    for (uint32_t frame = 0; frame < FRAMES; frame++) {
        for (int a = 0; a < 3; a++) /* a walk, with an occasional jump back and forth */
            camera[a] += (rng_unit(&rng) - 0.5) * (frame % 17 == 0 ? 60.0 : 3.0);
        wsc_begin_frame(cache, frame);
        for (int half = 0; half < 2; half++) { /* two request batches: lookups in between see evictions */
            size_t count[2] = {0, 0};
            for (int p = 0; p < POINTS / 2; p++) {
                double distance = ldexp(rng_unit(&rng), rng_range(&rng, 0, 7));
                double world[3];
                for (int a = 0; a < 3; a++)
                    world[a] = camera[a] + (rng_unit(&rng) - 0.5) * 2.0 * distance;
                uint32_t level = wsc_level(distance, c0);
                int32_t corners[8][3];
                float weights[8];
                assert_true(wsc_corners(world, level, c0, corners, weights));
                for (int c = 0; c < 8; c++) {
                    for (int e = 0; e < 2; e++) {
                        assert_true(wsc_brick_of(corners[c], level, e ? 4 : 1, &wgis[e][count[e]],
                                                 &masks[e][count[e]]));
                        if (e == 0 && history_count < HISTORY)
                            history[history_count++] = wgis[e][count[e]];
                        else if (e == 0)
                            history[rng_next(&rng) % HISTORY] = wgis[e][count[e]];
                        count[e]++;
                    }
                }
            }
            for (int e = 0; e < 2; e++) {
                /* Exhaustion is allowed (small pools); a failed WGI is simply absent. */
                osc_result result =
                    wsc_request_batch(cache, effects[e], wgis[e], masks[e], count[e], NULL, NULL);
                assert_true(result == OSC_OK || result == OSC_ERR_POOL_EXHAUSTED);
            }
            /* Lookups: this batch's WGIs (unique, sorted) and old ones from the history, through both
             * local tables, several times so slots get reused. */
            for (int round = 0; round < 2; round++) {
                for (int e = 0; e < 2; e++) {
                    for (size_t i = 0; i < count[e] / 2; i++) {
                        uint64_t wgi = (i & 1) ? history[rng_next(&rng) % history_count] : wgis[e][i];
                        uint32_t expected = wsc_find(cache, effects[e], wgi);
                        for (int l = 0; l < 2; l++) {
                            assert_int_equal(wsc_local_lookup(locals[l], cache, effects[e], wgi), expected);
                            lookups++;
                        }
                        if (expected != WSC_NONE)
                            assert_true(wsc_brick_key(cache, effects[e], expected) == wgi);
                    }
                }
            }
        }
        wsc_housekeeping(cache);
        for (size_t i = 0; i < 200; i++) { /* after housekeeping's evictions */
            uint64_t wgi = history[rng_next(&rng) % history_count];
            for (int l = 0; l < 2; l++) {
                assert_int_equal(wsc_local_lookup(locals[l], cache, 0, wgi), wsc_find(cache, 0, wgi));
                lookups++;
            }
        }
    }
    wsc_stats stats;
    wsc_stats_get(cache, &stats);
    assert_true(stats.effects[0].evictions > 1000 && stats.effects[3].evictions > 0); /* the test churned */
    wsc_local_stats local_stats[2];
    uint64_t total = 0;
    for (int l = 0; l < 2; l++) {
        wsc_local_stats_get(locals[l], &local_stats[l]);
        total += local_stats[l].hits + local_stats[l].misses + local_stats[l].bypasses;
        assert_true(local_stats[l].hits > 0 && local_stats[l].misses > 0);
        assert_true(local_stats[l].stale > 0); /* the trust check did reject slots */
        print_message("local table %d: %llu hits, %llu misses (%llu stale), %llu bypasses, %zu bytes\n", l,
                      (unsigned long long)local_stats[l].hits, (unsigned long long)local_stats[l].misses,
                      (unsigned long long)local_stats[l].stale, (unsigned long long)local_stats[l].bypasses,
                      local_stats[l].bytes);
    }
    assert_true(local_stats[0].bypasses > 0);
    assert_int_equal(local_stats[1].bypasses, 0);
    assert_int_equal(total, lookups);
    /* Absent effects and non-WGIs: nothing, as wsc_find. */
    assert_int_equal(wsc_local_lookup(locals[1], cache, 5, 0), WSC_NONE);
    assert_int_equal(wsc_local_lookup(locals[1], cache, 0, UINT64_MAX), WSC_NONE);
    wsc_local_destroy(locals[0]);
    wsc_local_destroy(locals[1]);
    wsc_destroy(cache);
}

/* wsc_cell_corners (one pack, one batched lookup) against the per-corner path (wsc_brick_of, wsc_find,
 * wsc_brick_valid, wsc_brick_payload) over random cells around a random set of resident probes, some with data
 * (valid) and some without; its refusals: the far corner out of range, brick size 4, an absent effect. */
static void test_cell_corners_match_find(void **state)
{
    (void)state;
    enum { PROBES = 400, CELLS = 4000 };
    wsc_desc desc = two_effect_desc(PROBES, 4);
    wsc_cache *cache = create_or_fail(&desc);
    uint64_t rng = 1234;
    static uint64_t wgis[PROBES], masks[PROBES];
    static uint32_t bricks[PROBES];
    const int32_t lo[3] = {-6, -3, 1000}, span = 8; /* a small box: most cells have resident corners */
    const uint32_t level = 2;
    wsc_begin_frame(cache, 0);
    for (int i = 0; i < PROBES; i++) {
        int32_t g[3];
        for (int a = 0; a < 3; a++)
            g[a] = lo[a] + rng_range(&rng, 0, span);
        assert_true(wsc_brick_of(g, level, 1, &wgis[i], &masks[i]));
    }
    size_t unique = 0;
    assert_int_equal(wsc_request_batch(cache, 0, wgis, masks, PROBES, &unique, bricks), OSC_OK);
    for (int i = 0; i < PROBES; i++) /* about two thirds with data */
        if (rng_next(&rng) % 3)
            wsc_brick_set_valid(cache, 0, bricks[i], 1);
    uint32_t seen_valid = 0, seen_invalid = 0, seen_absent = 0;
    for (int i = 0; i < CELLS; i++) {
        int32_t g[3];
        for (int a = 0; a < 3; a++)
            g[a] = lo[a] - 1 + rng_range(&rng, 0, span + 1);
        const void *payload[8];
        assert_true(wsc_cell_corners(cache, 0, level, g, payload));
        for (int c = 0; c < 8; c++) {
            int32_t corner[3] = {g[0] + (c & 1), g[1] + (c >> 1 & 1), g[2] + (c >> 2 & 1)};
            uint64_t wgi, bit;
            assert_true(wsc_brick_of(corner, level, 1, &wgi, &bit));
            uint32_t brick = wsc_find(cache, 0, wgi);
            const void *expected = NULL;
            if (brick == WSC_NONE)
                seen_absent++;
            else if (!(wsc_brick_valid(cache, 0, brick) & bit))
                seen_invalid++;
            else {
                expected = wsc_brick_payload(cache, 0, brick);
                seen_valid++;
            }
            assert_ptr_equal(payload[c], expected);
        }
    }
    assert_true(seen_valid > 0 && seen_invalid > 0 && seen_absent > 0);
    /* Refusals: every payload NULL. */
    const int32_t edges[3][3] = {{WSC_XZ_MAX, 0, 0}, {0, WSC_Y_MAX, 0}, {0, 0, WSC_XZ_MAX}};
    for (int e = 0; e < 3; e++) {
        const void *payload[8] = {cache, cache, cache, cache, cache, cache, cache, cache};
        assert_false(wsc_cell_corners(cache, 0, level, edges[e], payload));
        for (int c = 0; c < 8; c++)
            assert_null(payload[c]);
    }
    const void *payload[8];
    int32_t at_lo[3] = {WSC_XZ_MIN, WSC_Y_MIN, WSC_XZ_MIN}, below[3] = {WSC_XZ_MIN - 1, 0, 0};
    assert_true(wsc_cell_corners(cache, 0, level, at_lo, payload));
    assert_false(wsc_cell_corners(cache, 0, level, below, payload));
    assert_false(wsc_cell_corners(cache, 0, WSC_MAX_LEVEL + 1, lo, payload));
    assert_false(wsc_cell_corners(cache, 3, level, lo, payload)); /* 4 x 4 x 4 bricks */
    assert_false(wsc_cell_corners(cache, 5, level, lo, payload)); /* absent */
    for (int c = 0; c < 8; c++)
        assert_null(payload[c]);
    wsc_destroy(cache);
}

/* ---- memory, descriptions, the generalised core ------------------------------------------------------------ */

static void test_memory_accounting(void **state)
{
    (void)state;
    fxt_counting_allocator counter = {0};
    wsc_desc desc = two_effect_desc(100, 40);
    desc.effects[3].convergence = true;
    desc.allocator = (osc_allocator){fxt_counting_alloc, fxt_counting_free, &counter};
    wsc_cache *cache = create_or_fail(&desc);
    wsc_memory_report report;
    wsc_memory(cache, &report);
    assert_int_equal(report.total_bytes, counter.live_bytes);
    /* Closed forms: 100 bricks -> 150 -> 256 slots; 40 -> 60 -> 64 slots. */
    assert_int_equal(report.effects[0].table_key_bytes, 256 * 8);
    assert_int_equal(report.effects[3].table_key_bytes, 64 * 8);
    assert_int_equal(report.effects[0].payload_reserved_bytes, 100 * 16);
    assert_int_equal(report.effects[3].payload_reserved_bytes, 40 * 64 * 4);
    assert_int_equal(report.effects[3].block_meta_bytes, 40 * (8 + 8 + 4 + 8 + 4));
    assert_int_equal(report.core_struct_bytes, 2 * sizeof(osc_cache));
    wsc_stats stats;
    wsc_stats_get(cache, &stats);
    assert_int_equal(stats.effects[0].bytes + stats.effects[3].bytes + report.cache_struct_bytes,
                     counter.live_bytes);

    size_t before_local = counter.live_bytes;
    wsc_local_desc local_desc = {.side = 8, .levels = 5, .allocator = desc.allocator};
    wsc_local *local;
    assert_int_equal(wsc_local_create(&local_desc, cache, &local, NULL, 0), OSC_OK);
    wsc_local_stats local_stats;
    wsc_local_stats_get(local, &local_stats);
    assert_int_equal(local_stats.bytes, counter.live_bytes - before_local);
    assert_true(local_stats.bytes > 2u * 5 * 8 * 8 * 8 * 12 &&
                local_stats.bytes < 2u * 5 * 8 * 8 * 8 * 12 + 4096);

    /* No allocation during frames; payload in use follows resident bricks. */
    size_t allocations = counter.total_allocations;
    wsc_begin_frame(cache, 0);
    uint64_t wgis[10], masks[10];
    for (int i = 0; i < 10; i++) {
        assert_true(wsc_wgi_pack(0, i, 0, 0, &wgis[i]));
        masks[i] = 1;
    }
    assert_int_equal(wsc_request_batch(cache, 3, wgis, masks, 10, NULL, NULL), OSC_OK);
    for (int i = 0; i < 10; i++)
        wsc_local_lookup(local, cache, 3, wgis[i]);
    wsc_housekeeping(cache);
    assert_int_equal(counter.total_allocations, allocations);
    wsc_memory(cache, &report);
    assert_int_equal(report.payload_in_use_bytes, 10 * 256);
    wsc_local_destroy(local);
    assert_int_equal(counter.live_bytes, before_local);
    wsc_destroy(cache);
    assert_int_equal(counter.live_bytes, 0);
    assert_int_equal(counter.live_allocations, 0);

    /* Allocation failure at every step of both creations: a clean error, nothing leaked. */
    for (size_t fail_at = 1;; fail_at++) {
        fxt_counting_allocator failing = {.fail_at = fail_at};
        desc.allocator.user = &failing;
        local_desc.allocator.user = &failing;
        char message[200];
        wsc_cache *made = NULL;
        osc_result result = wsc_create(&desc, &made, message, sizeof message);
        if (result == OSC_OK) {
            wsc_local *made_local = NULL;
            result = wsc_local_create(&local_desc, made, &made_local, message, sizeof message);
            wsc_local_destroy(made_local);
            wsc_destroy(made);
            assert_int_equal(failing.live_bytes, 0);
            if (result == OSC_OK)
                break; /* past the last allocation */
        }
        assert_int_equal(result, OSC_ERR_OUT_OF_MEMORY);
        assert_non_null(strstr(message, "out of memory"));
        assert_int_equal(failing.live_bytes, 0);
        assert_int_equal(failing.live_allocations, 0);
    }
}

static void test_desc_validation(void **state)
{
    (void)state;
    static const struct {
        uint32_t effect, cell_bytes, brick_size, max_bricks, load;
        const char *message;
    } cases[] = {
        {2, 0, 4, 0, 0, "effects[2]: brick_size"},       {1, 2000, 1, 0, 0, "effects[1].cell_bytes 2000"},
        {4, 4, 2, 0, 0, "effects[4].brick_size 2"},      {4, 4, 8, 0, 0, "effects[4].brick_size 8"},
        {0, 4, 1, 1u << 31, 0, "effects[0].max_bricks"}, {7, 4, 1, 0, 99, "effects[7]: max_load_percent 99"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        wsc_desc desc = {0};
        desc.effects[cases[i].effect] =
            (wsc_effect_desc){cases[i].cell_bytes, cases[i].brick_size, cases[i].max_bricks, false};
        desc.max_load_percent = cases[i].load;
        wsc_cache *cache = (wsc_cache *)&desc;
        char message[256];
        assert_int_equal(wsc_create(&desc, &cache, message, sizeof message), OSC_ERR_INVALID_DESC);
        assert_null(cache);
        if (!strstr(message, cases[i].message))
            fail_msg("case %zu: \"%s\" lacks \"%s\"", i, message, cases[i].message);
    }
    /* Defaults: brick size 1, 65536 bricks; an empty description is a cache with no effects. */
    wsc_desc desc = {0};
    desc.effects[2].cell_bytes = 8;
    wsc_cache *cache = create_or_fail(&desc);
    assert_int_equal(wsc_brick_size(cache, 2), 1);
    assert_int_equal(wsc_capacity(cache, 2), 65536);
    wsc_stats stats;
    wsc_stats_get(cache, &stats);
    assert_int_equal(stats.effects[2].table_capacity, 131072);
    wsc_local *local;
    wsc_local_desc bad_local = {.side = 12};
    char message[128];
    assert_int_equal(wsc_local_create(&bad_local, cache, &local, message, sizeof message),
                     OSC_ERR_INVALID_DESC);
    assert_null(local);
    assert_non_null(strstr(message, "side 12"));
    wsc_destroy(cache);
}

/* The osc core's two generalisations, directly: a single-pool cache sends keys with any top bits to pool 0,
 * and pools of 1-element blocks have payloads of texel_bytes. */
static void test_osc_core_generalised(void **state)
{
    (void)state;
    osc_desc desc = {0};
    desc.single_pool = true;
    desc.effects[0] = (osc_effect_desc){.texel_bytes = 12, .max_blocks = 8, .block_texels = 1};
    osc_cache *cache;
    assert_int_equal(osc_create(&desc, &cache, NULL, 0), OSC_OK);
    osc_begin_frame(cache, 0);
    uint32_t blocks[9];
    for (uint64_t i = 0; i < 8; i++) /* top nibbles 0, 2, 4, ..., 14 and 15 for the last: all pool 0 */
        assert_int_equal(osc_request(cache, (i == 7 ? 0xFull : 2 * i) << 60 | i, 1, &blocks[i]), OSC_OK);
    assert_int_equal(osc_request(cache, 0x5ull << 60, 1, &blocks[8]),
                     OSC_ERR_POOL_EXHAUSTED); /* shared pool */
    assert_int_equal(cache->pools[0].in_use, 8);
    for (int i = 1; i < 16; i++)
        assert_int_equal(cache->pools[i].capacity, 0);
    assert_int_equal((unsigned char *)osc_block_payload(cache, 0, 1) -
                         (unsigned char *)osc_block_payload(cache, 0, 0),
                     12);
    assert_int_equal(osc_pool_block_texels(cache, 0), 1);
    osc_memory_report report;
    osc_memory(cache, &report);
    assert_int_equal(report.payload_reserved_bytes, 8 * 12);
    assert_int_equal(osc_remove(cache, 0xFull << 60 | 7), OSC_OK);
    assert_int_equal(osc_find(cache, 0xFull << 60 | 7), OSC_NONE);
    osc_destroy(cache);

    /* Without single_pool, block_texels 1 on one effect: that effect's keys, by their top bits, get
     * 1-element blocks; others keep 64. */
    desc = (osc_desc){0};
    desc.effects[5] = (osc_effect_desc){.texel_bytes = 4, .max_blocks = 4, .block_texels = 1};
    desc.effects[6] = (osc_effect_desc){.texel_bytes = 4, .max_blocks = 4};
    assert_int_equal(osc_create(&desc, &cache, NULL, 0), OSC_OK);
    assert_int_equal(osc_pool_block_texels(cache, 5), 1);
    assert_int_equal(osc_pool_block_texels(cache, 6), 64);
    osc_memory(cache, &report);
    assert_int_equal(report.effects[5].payload_reserved_bytes, 4 * 4);
    assert_int_equal(report.effects[6].payload_reserved_bytes, 4 * 64 * 4);
    osc_begin_frame(cache, 0);
    assert_int_equal(osc_request(cache, osc_key_pack(5, 1, 0, 0, 0), 1, &blocks[0]), OSC_OK);
    assert_int_equal(cache->pools[5].in_use, 1);
    osc_destroy(cache);

    /* Refused descriptions. */
    char message[200];
    desc = (osc_desc){0};
    desc.single_pool = true;
    desc.effects[0].texel_bytes = 4;
    desc.effects[1].texel_bytes = 4;
    assert_int_equal(osc_create(&desc, &cache, message, sizeof message), OSC_ERR_INVALID_DESC);
    assert_non_null(strstr(message, "single-pool"));
    desc = (osc_desc){0};
    desc.effects[2] = (osc_effect_desc){.texel_bytes = 4, .block_texels = 8};
    assert_int_equal(osc_create(&desc, &cache, message, sizeof message), OSC_ERR_INVALID_DESC);
    assert_non_null(strstr(message, "effects[2].block_texels 8"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_wgi_layout_and_round_trip),
        cmocka_unit_test(test_wgi_refusals),
        cmocka_unit_test(test_level_formula),
        cmocka_unit_test(test_grid_static_and_refusals),
        cmocka_unit_test(test_corners),
        cmocka_unit_test(test_bricks_4x4x4_next_to_probes),
        cmocka_unit_test(test_local_agrees_with_table),
        cmocka_unit_test(test_cell_corners_match_find),
        cmocka_unit_test(test_memory_accounting),
        cmocka_unit_test(test_desc_validation),
        cmocka_unit_test(test_osc_core_generalised),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
