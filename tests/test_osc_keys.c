/* test_osc_keys.c: the on-surface cache's keys (exact bit positions, round trip), result strings, level sizes
 * and the texel masks of point, bilinear and trilinear footprints at block corners, edges and island borders
 * (cache/osc.h, cache/osc_footprint.c). The table, pools and memory are in test_osc.c. */
#include "test_util.h"

#include "cache.h"
#include "osc_internal.h"

#include <stdlib.h>
#include <string.h>

static uint64_t rng_next(uint64_t *state)
{
    /* splitmix64 */
    uint64_t z = (*state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static uint32_t rng_below(uint64_t *state, uint32_t bound)
{
    return (uint32_t)(rng_next(state) % bound);
}

/* ---- keys -------------------------------------------------------------------------------------------------- */

static void test_key_bit_positions(void **state)
{
    (void)state;
    assert_true(osc_key_pack(0xF, 0, 0, 0, 0) == 0xF000000000000000ull);
    assert_true(osc_key_pack(0, 0xFFFFFFFFu, 0, 0, 0) == 0x0FFFFFFFF0000000ull);
    assert_true(osc_key_pack(0, 0, 0xF, 0, 0) == 0x000000000F000000ull);
    assert_true(osc_key_pack(0, 0, 0, 0, 0xFFF) == 0x0000000000FFF000ull); /* block_y: bits 12-23 */
    assert_true(osc_key_pack(0, 0, 0, 0xFFF, 0) == 0x0000000000000FFFull); /* block_x: bits 0-11 */
    assert_true(osc_key_pack(0, 1, 0, 0, 0) == 1ull << 28);
    assert_true(osc_key_pack(1, 0, 0, 0, 0) == 1ull << 60);
    assert_true(osc_key_pack(0, 0, 1, 0, 0) == 1ull << 24);
    assert_true(osc_key_pack(0, 0, 0, 0, 1) == 1ull << 12);
    assert_true(osc_key_pack(0, 0, 0, 1, 0) == 1ull);
    assert_true(osc_key_pack(0xA, 0x12345678u, 0x5, 0xBCD, 0x9EF) == 0xA1234567859EFBCDull);
    assert_int_equal(osc_key_effect(0xA1234567859EFBCDull), 0xA);
    /* The largest valid key is one below the reserved empty marker's neighbourhood. */
    assert_true(osc_key_pack(0xF, 0xFFFFFFFFu, 0xF, 0xFFE, 0xFFF) == OSC_KEY_EMPTY - 1);
}

static void test_key_round_trip(void **state)
{
    (void)state;
    uint64_t rng = 1;
    for (int i = 0; i < 100000; i++) {
        uint32_t effect = rng_below(&rng, 16), island = (uint32_t)rng_next(&rng), level = rng_below(&rng, 15);
        uint32_t block_x = rng_below(&rng, 4096), block_y = rng_below(&rng, 4096);
        uint64_t key = osc_key_pack(effect, island, level, block_x, block_y);
        osc_key_fields fields = osc_key_unpack(key);
        assert_int_equal(fields.effect, effect);
        assert_int_equal(fields.island_id, island);
        assert_int_equal(fields.level, level);
        assert_int_equal(fields.block_x, block_x);
        assert_int_equal(fields.block_y, block_y);
        assert_int_equal(osc_key_effect(key), effect);
    }
}

static void test_result_strings(void **state)
{
    (void)state;
    assert_string_equal(osc_result_string(OSC_OK), "ok");
    assert_string_equal(osc_result_string(OSC_ERR_POOL_EXHAUSTED),
                        "every block of the effect's pool is requested this frame");
    assert_string_equal(osc_result_string((osc_result)-99), "unknown osc result");
    assert_int_equal(OSC_ERR_NOT_FOUND, -6);
}

/* ---- footprints ---------------------------------------------------------------------------------------------- */

static uint64_t bit(uint32_t x, uint32_t y)
{
    return 1ull << (y * 8 + x);
}

static void expect_block(const osc_footprint *footprint, uint32_t index, const osc_island_extent *island,
                         uint32_t level, uint32_t block_x, uint32_t block_y, uint64_t mask)
{
    assert_true(index < footprint->count);
    assert_true(footprint->keys[index] ==
                osc_key_pack(island->effect, island->island_id, level, block_x, block_y));
    assert_true(footprint->texel_masks[index] == mask);
}

static void test_level_size(void **state)
{
    (void)state;
    assert_int_equal(osc_level_size(100, 0), 100);
    assert_int_equal(osc_level_size(100, 2), 25);
    assert_int_equal(osc_level_size(101, 2), 26);
    assert_int_equal(osc_level_size(1, 5), 1);
    assert_int_equal(osc_level_size(32768, 15), 1);
    assert_int_equal(osc_level_size(32768, 12), 8);
}

static void test_footprint_point(void **state)
{
    (void)state;
    osc_island_extent island = {.effect = 2, .island_id = 77, .width0 = 100, .height0 = 50};
    osc_footprint footprint;
    osc_footprint_point(&island, 0, 8.0f, 0.0f, &footprint); /* texel (8,0): first texel of block (1,0) */
    assert_int_equal(footprint.count, 1);
    expect_block(&footprint, 0, &island, 0, 1, 0, bit(0, 0));
    osc_footprint_point(&island, 0, 7.99f, 7.99f, &footprint); /* last texel of block (0,0) */
    expect_block(&footprint, 0, &island, 0, 0, 0, bit(7, 7));
    osc_footprint_point(&island, 0, 100.5f, -3.0f, &footprint); /* outside: clamped to texel (99, 0) */
    assert_int_equal(footprint.count, 1);
    expect_block(&footprint, 0, &island, 0, 12, 0, bit(3, 0));
    osc_footprint_point(&island, 0, 0.0f / 0.0f, 49.99f, &footprint); /* NaN -> 0; y=49 */
    expect_block(&footprint, 0, &island, 0, 0, 6, bit(0, 1));
    /* Level 2: 25 x 13 texels. */
    osc_footprint_point(&island, 2, 30.0f, 12.5f, &footprint);
    expect_block(&footprint, 0, &island, 2, 3, 1, bit(0, 4));
}

static void test_footprint_bilinear(void **state)
{
    (void)state;
    osc_island_extent island = {.effect = 1, .island_id = 5, .width0 = 64, .height0 = 64};
    osc_footprint footprint;
    /* Interior of a block: one block, 2 x 2 texels (3..4, 4..5). */
    osc_footprint_bilinear(&island, 0, 3.75f, 4.75f, &footprint);
    assert_int_equal(footprint.count, 1);
    expect_block(&footprint, 0, &island, 0, 0, 0, bit(3, 4) | bit(4, 4) | bit(3, 5) | bit(4, 5));
    /* Exactly on a texel centre: the zero-weight texels are included (conservative, like hardware). */
    osc_footprint_bilinear(&island, 0, 3.5f, 3.5f, &footprint);
    assert_int_equal(footprint.count, 1);
    expect_block(&footprint, 0, &island, 0, 0, 0, bit(3, 3) | bit(4, 3) | bit(3, 4) | bit(4, 4));
    /* A block corner: four blocks, one texel each. */
    osc_footprint_bilinear(&island, 0, 8.0f, 8.0f, &footprint);
    assert_int_equal(footprint.count, 4);
    expect_block(&footprint, 0, &island, 0, 0, 0, bit(7, 7));
    expect_block(&footprint, 1, &island, 0, 1, 0, bit(0, 7));
    expect_block(&footprint, 2, &island, 0, 0, 1, bit(7, 0));
    expect_block(&footprint, 3, &island, 0, 1, 1, bit(0, 0));
    /* A vertical block edge: two blocks, two texels each. */
    osc_footprint_bilinear(&island, 0, 8.0f, 4.75f, &footprint);
    assert_int_equal(footprint.count, 2);
    expect_block(&footprint, 0, &island, 0, 0, 0, bit(7, 4) | bit(7, 5));
    expect_block(&footprint, 1, &island, 0, 1, 0, bit(0, 4) | bit(0, 5));
    /* A horizontal block edge. */
    osc_footprint_bilinear(&island, 0, 20.75f, 24.2f, &footprint);
    assert_int_equal(footprint.count, 2);
    expect_block(&footprint, 0, &island, 0, 2, 2, bit(4, 7) | bit(5, 7));
    expect_block(&footprint, 1, &island, 0, 2, 3, bit(4, 0) | bit(5, 0));

    /* Island borders: 20 x 20 texels. Near the origin the stencil clamps to texel (0,0). */
    osc_island_extent small = {.effect = 1, .island_id = 6, .width0 = 20, .height0 = 20};
    osc_footprint_bilinear(&small, 0, 0.2f, 0.2f, &footprint);
    assert_int_equal(footprint.count, 1);
    expect_block(&footprint, 0, &small, 0, 0, 0, bit(0, 0));
    /* Near the far corner: texel (19,19) only, block (2,2). */
    osc_footprint_bilinear(&small, 0, 19.9f, 19.9f, &footprint);
    assert_int_equal(footprint.count, 1);
    expect_block(&footprint, 0, &small, 0, 2, 2, bit(3, 3));
    /* Far outside: the same clamped texel. */
    osc_footprint_bilinear(&small, 0, 1e9f, 1e9f, &footprint);
    assert_int_equal(footprint.count, 1);
    expect_block(&footprint, 0, &small, 0, 2, 2, bit(3, 3));
    /* An island whose last column is the first of a block: 9 x 9, stencil clamped to column 8. */
    osc_island_extent nine = {.effect = 0, .island_id = 9, .width0 = 9, .height0 = 9};
    osc_footprint_bilinear(&nine, 0, 8.6f, 4.75f, &footprint);
    assert_int_equal(footprint.count, 1);
    expect_block(&footprint, 0, &nine, 0, 1, 0, bit(0, 4) | bit(0, 5));
    /* Border at a coarse level: 100 x 100 at level 3 is 13 x 13. */
    osc_island_extent hundred = {.effect = 3, .island_id = 100, .width0 = 100, .height0 = 100};
    osc_footprint_bilinear(&hundred, 3, 12.9f, 12.9f, &footprint);
    assert_int_equal(footprint.count, 1);
    expect_block(&footprint, 0, &hundred, 3, 1, 1, bit(4, 4));
}

/* The inlined bilinear keys of the request stage against osc_footprint_bilinear(): the same blocks, masks and
 * order for random islands, levels and points, also outside the island and at texel centres. */
static void test_bilinear_keys_match(void **state)
{
    (void)state;
    uint64_t rng = 0x9e3779b97f4a7c15ull;
    for (int i = 0; i < 200000; i++) {
        rng = rng * 6364136223846793005ull + 1442695040888963407ull;
        uint32_t r = (uint32_t)(rng >> 32);
        osc_island_extent island = {.effect = r & 15u,
                                    .island_id = (uint32_t)(rng >> 7) & 0xFFFFFFu,
                                    .width0 = 1 + (r >> 4) % (i % 3 == 0 ? 40 : OSC_MAX_ISLAND_SIZE),
                                    .height0 = 1 + (r >> 12) % (i % 5 == 0 ? 17 : OSC_MAX_ISLAND_SIZE)};
        uint32_t level = (r >> 24) % 16;
        rng = rng * 6364136223846793005ull + 1442695040888963407ull;
        float w = (float)osc_level_size(island.width0, level),
              h = (float)osc_level_size(island.height0, level);
        float x = ((float)(rng >> 40) / 16777216.0f) * (w + 4.0f) - 2.0f;
        float y = ((float)((rng >> 16) & 0xFFFFFFu) / 16777216.0f) * (h + 4.0f) - 2.0f;
        if (i % 7 == 0)
            x = floorf(x) + 0.5f; /* exactly on a texel centre */
        osc_footprint fp;
        osc_footprint_bilinear(&island, level, x, y, &fp);
        uint64_t keys[4], masks[4];
        uint32_t n = osc_bilinear_keys(island.effect, island.island_id, island.width0, island.height0, level,
                                       x, y, keys, masks);
        assert_int_equal(n, fp.count);
        for (uint32_t k = 0; k < n; k++) {
            assert_int_equal(keys[k], fp.keys[k]);
            assert_int_equal(masks[k], fp.texel_masks[k]);
        }
    }
}

static void test_footprint_trilinear(void **state)
{
    (void)state;
    osc_island_extent island = {.effect = 4, .island_id = 12, .width0 = 64, .height0 = 64};
    osc_footprint footprint;
    /* A block corner at both levels: 8 blocks. Level 0 at (16,16), level 1 at (8,8). */
    osc_footprint_trilinear(&island, 0, 16.0f, 16.0f, &footprint);
    assert_int_equal(footprint.count, 8);
    expect_block(&footprint, 0, &island, 0, 1, 1, bit(7, 7));
    expect_block(&footprint, 1, &island, 0, 2, 1, bit(0, 7));
    expect_block(&footprint, 2, &island, 0, 1, 2, bit(7, 0));
    expect_block(&footprint, 3, &island, 0, 2, 2, bit(0, 0));
    expect_block(&footprint, 4, &island, 1, 0, 0, bit(7, 7));
    expect_block(&footprint, 5, &island, 1, 1, 0, bit(0, 7));
    expect_block(&footprint, 6, &island, 1, 0, 1, bit(7, 0));
    expect_block(&footprint, 7, &island, 1, 1, 1, bit(0, 0));
    /* Interior: one block per level. Level 1 coordinate (2.375, 2.375): texels 1..2. */
    osc_footprint_trilinear(&island, 0, 4.75f, 4.75f, &footprint);
    assert_int_equal(footprint.count, 2);
    expect_block(&footprint, 0, &island, 0, 0, 0, bit(4, 4) | bit(5, 4) | bit(4, 5) | bit(5, 5));
    expect_block(&footprint, 1, &island, 1, 0, 0, bit(1, 1) | bit(2, 1) | bit(1, 2) | bit(2, 2));
    /* A 2 x 2 island: level 0 uses all four texels, level 1 is a single texel. */
    osc_island_extent tiny = {.effect = 4, .island_id = 13, .width0 = 2, .height0 = 2};
    osc_footprint_trilinear(&tiny, 0, 1.0f, 1.0f, &footprint);
    assert_int_equal(footprint.count, 2);
    expect_block(&footprint, 0, &tiny, 0, 0, 0, bit(0, 0) | bit(1, 0) | bit(0, 1) | bit(1, 1));
    expect_block(&footprint, 1, &tiny, 1, 0, 0, bit(0, 0));
    /* The coarser level clamps at the island border while the finer one does not: 40 x 40 at level 2
     * is 10 x 10, at level 3 it is 5 x 5. At (9.9, 4.0) level 2: texels 9 (clamped) and 3..4;
     * level 3 at (4.95, 2.0): texels 4 (clamped), 1..2. */
    osc_island_extent forty = {.effect = 4, .island_id = 14, .width0 = 40, .height0 = 40};
    osc_footprint_trilinear(&forty, 2, 9.9f, 4.0f, &footprint);
    assert_int_equal(footprint.count, 2);
    expect_block(&footprint, 0, &forty, 2, 1, 0, bit(1, 3) | bit(1, 4));
    expect_block(&footprint, 1, &forty, 3, 0, 0, bit(4, 1) | bit(4, 2));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_key_bit_positions),   cmocka_unit_test(test_key_round_trip),
        cmocka_unit_test(test_result_strings),      cmocka_unit_test(test_level_size),
        cmocka_unit_test(test_footprint_point),     cmocka_unit_test(test_footprint_bilinear),
        cmocka_unit_test(test_footprint_trilinear), cmocka_unit_test(test_bilinear_keys_match),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
