/* test_osc.c: tests of the on-surface cache (cache/osc*.c; keys and footprints are in test_osc_keys.c): the hash
 * table against a reference model (sorted array) including backward-shift deletion on clustered keys, the radix
 * sort, pools with exhaustion and recovery, adaptive eviction, exact memory accounting through a counting
 * allocator (and allocation failure at every step), and batch determinism across request orders and
 * threads. White-box: reaches the internals through osc_internal.h. */
#include "test_util.h"

#include "cache.h"
#include "osc_internal.h"

#include <pthread.h>
#include <stdlib.h>
#include <string.h>

/* ---- helpers -------------------------------------------------------------------------------------------- */

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

/* A random key shaped like a real one: a few effects, islands from a small set, low levels, small block
 * coordinates. */
static uint64_t random_key(uint64_t *state, uint32_t effects, uint32_t islands)
{
    uint32_t level = rng_below(state, 4);
    uint32_t span = 32u >> level;
    return osc_key_pack(rng_below(state, effects), 1000 + rng_below(state, islands), level,
                        rng_below(state, span), rng_below(state, span));
}

static void shuffle_pairs(uint64_t *keys, uint64_t *masks, size_t count, uint64_t *state)
{
    for (size_t i = count; i > 1; i--) {
        size_t j = rng_next(state) % i;
        uint64_t key = keys[i - 1], mask = masks[i - 1];
        keys[i - 1] = keys[j];
        masks[i - 1] = masks[j];
        keys[j] = key;
        masks[j] = mask;
    }
}

static osc_cache *create_or_fail(const osc_desc *desc)
{
    osc_cache *cache = NULL;
    char message[256];
    osc_result result = osc_create(desc, &cache, message, sizeof message);
    if (result != OSC_OK)
        fail_msg("osc_create: %s: %s", osc_result_string(result), message);
    return cache;
}

/* Checks the cache's internal consistency: table invariant, every resident block's key maps back to it,
 * table count equals the resident blocks, free + resident = capacity, frame lists exact. */
static void check_cache_consistency(const osc_cache *cache)
{
    assert_true(osc__table_check(&cache->table));
    uint32_t resident_total = 0;
    for (uint32_t effect = 0; effect < OSC_MAX_EFFECTS; effect++) {
        const osc__pool *pool = &cache->pools[effect];
        uint32_t resident = 0, on_frame = 0;
        for (uint32_t block = 0; block < pool->capacity; block++) {
            if (pool->keys[block] == OSC_KEY_EMPTY) {
                assert_int_equal(pool->last_stamp[block], 0);
                continue;
            }
            resident++;
            assert_int_equal(osc_key_effect(pool->keys[block]), effect);
            assert_int_equal(osc_find(cache, pool->keys[block]), block);
            if (pool->last_stamp[block] == cache->stamp)
                on_frame++;
        }
        assert_int_equal(resident, pool->in_use);
        assert_int_equal(resident + pool->free_count, pool->capacity);
        assert_int_equal(on_frame, pool->frame_block_count);
        resident_total += resident;
    }
    assert_int_equal(resident_total, cache->table.count);
}

/* ---- sort ----------------------------------------------------------------------------------------------------- */

static int compare_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

static void test_radix_sort(void **state)
{
    (void)state;
    uint64_t rng = 7;
    enum { N = 20000 };
    uint64_t *keys = malloc(N * sizeof *keys), *payload = malloc(N * sizeof *payload);
    uint64_t *expected = malloc(N * sizeof *expected);
    assert_non_null(keys);
    assert_non_null(payload);
    assert_non_null(expected);
    for (int round = 0; round < 6; round++) {
        size_t count = round == 0 ? 0 : round == 1 ? 1 : round == 2 ? 31 : N;
        for (size_t i = 0; i < count; i++) {
            keys[i] = round == 3   ? rng_next(&rng)
                      : round == 4 ? rng_below(&rng, 50)
                                   : random_key(&rng, 3, 40);
            payload[i] = ~keys[i];
            expected[i] = keys[i];
        }
        osc__sort_u64(keys, payload, count);
        qsort(expected, count, sizeof *expected, compare_u64);
        for (size_t i = 0; i < count; i++) {
            assert_true(keys[i] == expected[i]);
            assert_true(payload[i] == ~keys[i]);
        }
    }
    free(keys);
    free(payload);
    free(expected);
}

/* ---- the table against a reference model ------------------------------------------------------------------ */

typedef struct reference_model {
    uint64_t *keys; /* sorted */
    uint32_t *values;
    size_t count;
} reference_model;

static size_t model_lower_bound(const reference_model *model, uint64_t key)
{
    size_t low = 0, high = model->count;
    while (low < high) {
        size_t middle = low + (high - low) / 2;
        if (model->keys[middle] < key)
            low = middle + 1;
        else
            high = middle;
    }
    return low;
}

static uint32_t model_find(const reference_model *model, uint64_t key)
{
    size_t at = model_lower_bound(model, key);
    return at < model->count && model->keys[at] == key ? model->values[at] : OSC_NONE;
}

static void model_insert(reference_model *model, uint64_t key, uint32_t value)
{
    size_t at = model_lower_bound(model, key);
    memmove(&model->keys[at + 1], &model->keys[at], (model->count - at) * sizeof(uint64_t));
    memmove(&model->values[at + 1], &model->values[at], (model->count - at) * sizeof(uint32_t));
    model->keys[at] = key;
    model->values[at] = value;
    model->count++;
}

static void model_remove(reference_model *model, uint64_t key)
{
    size_t at = model_lower_bound(model, key);
    assert_true(at < model->count && model->keys[at] == key);
    memmove(&model->keys[at], &model->keys[at + 1], (model->count - at - 1) * sizeof(uint64_t));
    memmove(&model->values[at], &model->values[at + 1], (model->count - at - 1) * sizeof(uint32_t));
    model->count--;
}

static void test_table_reference_model(void **state)
{
    (void)state;
    enum { CAPACITY = 1024, MAX_COUNT = 768, UNIVERSE = 3000, OPERATIONS = 400000 };
    uint64_t *table_keys = malloc(CAPACITY * sizeof(uint64_t));
    uint32_t *table_values = malloc(CAPACITY * sizeof(uint32_t));
    uint64_t *universe = malloc(UNIVERSE * sizeof(uint64_t));
    reference_model model = {malloc(MAX_COUNT * sizeof(uint64_t)), malloc(MAX_COUNT * sizeof(uint32_t)), 0};
    assert_non_null(table_keys);
    assert_non_null(table_values);
    assert_non_null(universe);
    assert_non_null(model.keys);
    assert_non_null(model.values);
    osc__table table;
    osc__table_init(&table, table_keys, table_values, CAPACITY, MAX_COUNT);
    uint64_t rng = 42;
    /* Keys shaped like real ones, plus runs of neighbouring blocks. */
    for (int i = 0; i < UNIVERSE; i++)
        universe[i] = i % 3 == 0 ? osc_key_pack(1, 9, 0, (uint32_t)i % 4096, (uint32_t)i / 4096)
                                 : random_key(&rng, 4, 500);
    uint32_t peak = 0, full_refusals = 0;
    for (int operation = 0; operation < OPERATIONS; operation++) {
        uint64_t key = universe[rng_below(&rng, UNIVERSE)];
        uint32_t choice = rng_below(&rng, 100);
        /* Phases: mostly inserting (drive to max load), then mixed, then mostly deleting. */
        int phase = (operation / 50000) % 4;
        uint32_t insert_share = phase == 0 ? 80 : phase == 3 ? 20 : 50;
        uint32_t expected = model_find(&model, key);
        assert_int_equal(osc__table_find(&table, key), expected);
        if (choice < insert_share) {
            if (expected != OSC_NONE)
                continue;
            uint32_t value = (uint32_t)operation;
            bool inserted = osc__table_insert(&table, key, value);
            if (model.count >= MAX_COUNT) {
                assert_false(inserted);
                full_refusals++;
            } else {
                assert_true(inserted);
                model_insert(&model, key, value);
            }
        } else {
            bool removed = osc__table_remove(&table, key);
            assert_int_equal(removed, expected != OSC_NONE);
            if (removed)
                model_remove(&model, key);
        }
        assert_int_equal(table.count, model.count);
        if (table.count > peak)
            peak = table.count;
        if (operation % 5000 == 0) {
            assert_true(osc__table_check(&table));
            for (size_t i = 0; i < model.count; i++)
                assert_int_equal(osc__table_find(&table, model.keys[i]), model.values[i]);
        }
    }
    assert_int_equal(peak, MAX_COUNT); /* reached 75 % load */
    assert_true(full_refusals > 0);
    assert_true(osc__table_check(&table));
    for (int i = 0; i < UNIVERSE; i++)
        assert_int_equal(osc__table_find(&table, universe[i]), model_find(&model, universe[i]));
    free(table_keys);
    free(table_values);
    free(universe);
    free(model.keys);
    free(model.values);
}

/* Keys that all hash to the same home slots (including the last slots, so runs wrap around): deleting any
 * of them in any order must leave every other one reachable. */
static void test_table_clustered_delete(void **state)
{
    (void)state;
    enum { CAPACITY = 64, PER_HOME = 6 };
    uint64_t table_keys[CAPACITY];
    uint32_t table_values[CAPACITY];
    const uint32_t homes[] = {10, 11, 62, 63};
    uint64_t keys[4 * PER_HOME];
    size_t found = 0;
    for (size_t h = 0; h < 4; h++) {
        size_t have = 0;
        for (uint32_t x = 0; have < PER_HOME; x++) {
            uint64_t key = osc_key_pack(2, 3, 0, x % 4096, x / 4096);
            if (((uint32_t)osc__hash(key) & (CAPACITY - 1)) == homes[h]) {
                keys[found++] = key;
                have++;
            }
        }
    }
    uint64_t rng = 3;
    for (int round = 0; round < 300; round++) {
        osc__table table;
        osc__table_init(&table, table_keys, table_values, CAPACITY, 48);
        /* Insert in a random order, delete a random subset in a random order. */
        uint64_t order[4 * PER_HOME], unused[4 * PER_HOME];
        memcpy(order, keys, sizeof keys);
        shuffle_pairs(order, unused, found, &rng);
        for (size_t i = 0; i < found; i++)
            assert_true(osc__table_insert(&table, order[i], (uint32_t)(order[i] & 0xFFFF)));
        shuffle_pairs(order, unused, found, &rng);
        size_t deleted = rng_below(&rng, (uint32_t)found + 1);
        for (size_t i = 0; i < deleted; i++) {
            assert_true(osc__table_remove(&table, order[i]));
            assert_true(osc__table_check(&table));
            assert_int_equal(osc__table_find(&table, order[i]), OSC_NONE);
            for (size_t j = i + 1; j < found; j++)
                assert_int_equal(osc__table_find(&table, order[j]), (uint32_t)(order[j] & 0xFFFF));
        }
        assert_int_equal(table.count, found - deleted);
    }
}

/* ---- pools, exhaustion, eviction ---------------------------------------------------------------------------- */

static void test_pool_exhaustion_and_recovery(void **state)
{
    (void)state;
    osc_desc desc = {0};
    desc.effects[0].texel_bytes = 4;
    desc.effects[0].max_blocks = 64;
    osc_cache *cache = create_or_fail(&desc);
    uint32_t block;
    osc_begin_frame(cache, 0);
    for (uint32_t i = 0; i < 64; i++) {
        assert_int_equal(osc_request(cache, osc_key_pack(0, 1, 0, i, 0), 1, &block), OSC_OK);
        assert_int_equal(block, i); /* free stack pops 0, 1, 2, ... */
    }
    /* Every block is requested this frame: the 65th key fails, counted, nothing crashes. */
    assert_int_equal(osc_request(cache, osc_key_pack(0, 1, 0, 64, 0), 1, &block), OSC_ERR_POOL_EXHAUSTED);
    assert_int_equal(block, OSC_NONE);
    assert_int_equal(osc_request(cache, osc_key_pack(0, 1, 0, 65, 0), 1, &block), OSC_ERR_POOL_EXHAUSTED);
    /* Existing keys still work. */
    assert_int_equal(osc_request(cache, osc_key_pack(0, 1, 0, 5, 0), 2, &block), OSC_OK);
    assert_int_equal(block, 5);
    assert_true(osc_block_requested(cache, 0, 5) == 3);
    /* A key of an effect without pool. */
    assert_int_equal(osc_request(cache, osc_key_pack(1, 1, 0, 0, 0), 1, &block), OSC_ERR_NO_POOL);
    osc_stats stats;
    osc_stats_get(cache, &stats);
    assert_int_equal(stats.exhausted, 2);
    assert_int_equal(stats.effects[0].exhausted, 2);
    assert_int_equal(stats.effects[0].blocks_resident, 64);
    assert_int_equal(stats.effects[0].new_this_frame, 66);
    check_cache_consistency(cache);
    osc_housekeeping(cache); /* nothing evictable: everything was requested this frame */
    osc_stats_get(cache, &stats);
    assert_int_equal(stats.evictions, 0);
    assert_int_equal(stats.effects[0].expected_new, 66);
    assert_int_equal(stats.effects[0].age_threshold, 32); /* pressure: 64 halved */

    /* Frame 1: keys 0..9 again, then housekeeping frees the least recently used blocks for next frame. */
    osc_begin_frame(cache, 1);
    assert_true(osc_block_requested(cache, 0, 5) == 0); /* cleared by begin_frame */
    for (uint32_t i = 0; i < 10; i++)
        assert_int_equal(osc_request(cache, osc_key_pack(0, 1, 0, i, 0), 1, &block), OSC_OK);
    osc_housekeeping(cache);
    osc_stats_get(cache, &stats);
    /* expected = 66 - ceil(66/8) = 57 (demand 0 this frame); only 54 blocks are evictable. */
    assert_int_equal(stats.effects[0].expected_new, 57);
    assert_int_equal(stats.evictions, 54);
    assert_int_equal(stats.effects[0].blocks_resident, 10);
    check_cache_consistency(cache);
    for (uint32_t i = 0; i < 10; i++)
        assert_int_not_equal(osc_find(cache, osc_key_pack(0, 1, 0, i, 0)), OSC_NONE);
    for (uint32_t i = 10; i < 64; i++)
        assert_int_equal(osc_find(cache, osc_key_pack(0, 1, 0, i, 0)), OSC_NONE);

    /* Frame 2: 54 new keys fit without any immediate eviction; the 55th evicts the oldest block not
     * requested this frame (from frame 1: block 0 first, ties broken by block index). */
    osc_begin_frame(cache, 2);
    for (uint32_t i = 0; i < 54; i++)
        assert_int_equal(osc_request(cache, osc_key_pack(0, 2, 0, i, 0), 1, &block), OSC_OK);
    osc_stats_get(cache, &stats);
    assert_int_equal(stats.effects[0].immediate_evictions, 0);
    assert_int_equal(osc_request(cache, osc_key_pack(0, 2, 0, 54, 0), 1, &block), OSC_OK);
    assert_int_equal(block, 0);
    assert_int_equal(osc_find(cache, osc_key_pack(0, 1, 0, 0, 0)), OSC_NONE);
    osc_stats_get(cache, &stats);
    assert_int_equal(stats.effects[0].immediate_evictions, 1);
    assert_int_equal(stats.exhausted, 2);
    check_cache_consistency(cache);
    /* Fill the rest: 9 more immediate evictions, then exhaustion again. */
    for (uint32_t i = 55; i < 64; i++)
        assert_int_equal(osc_request(cache, osc_key_pack(0, 2, 0, i, 0), 1, &block), OSC_OK);
    assert_int_equal(osc_request(cache, osc_key_pack(0, 2, 0, 64, 0), 1, &block), OSC_ERR_POOL_EXHAUSTED);
    osc_stats_get(cache, &stats);
    assert_int_equal(stats.effects[0].immediate_evictions, 10);
    assert_int_equal(stats.exhausted, 3);
    check_cache_consistency(cache);
    osc_destroy(cache);
}

static void test_age_threshold_eviction(void **state)
{
    (void)state;
    osc_desc desc = {0};
    desc.effects[3].texel_bytes = 2;
    desc.effects[3].max_blocks = 1000;
    desc.initial_age_frames = 4;
    desc.max_age_frames = 8;
    osc_cache *cache = create_or_fail(&desc);
    uint32_t block;
    uint64_t old_key = osc_key_pack(3, 1, 0, 0, 0);
    osc_begin_frame(cache, 10);
    assert_int_equal(osc_request(cache, old_key, 1, &block), OSC_OK);
    assert_int_equal(osc_block_last_frame(cache, 3, block), 10);
    osc_housekeeping(cache);
    uint32_t evicted_at = 0;
    for (uint32_t frame = 11; frame < 30 && evicted_at == 0; frame++) {
        osc_begin_frame(cache, frame);
        /* A block requested every frame is never evicted. */
        assert_int_equal(osc_request(cache, osc_key_pack(3, 2, 0, 0, 0), 1, &block), OSC_OK);
        osc_housekeeping(cache);
        if (osc_find(cache, old_key) == OSC_NONE)
            evicted_at = frame;
    }
    /* Plenty of free blocks: the threshold only grows (4 -> 6 -> 8, capped), so the block survives ages
     * 1..4 and goes once its age exceeds the threshold, at the latest after 8 frames. */
    assert_true(evicted_at > 14 && evicted_at <= 19);
    osc_stats stats;
    osc_stats_get(cache, &stats);
    assert_int_equal(stats.effects[3].age_threshold, 8);
    assert_int_equal(stats.effects[3].blocks_resident, 1);
    assert_int_equal(osc_block_last_frame(cache, 3, 0), OSC_FRAME_NEVER); /* block 0 freed */
    assert_true(osc_block_key(cache, 3, 0) == OSC_KEY_EMPTY);
    check_cache_consistency(cache);
    osc_destroy(cache);
}

/* Random frames against a small pool: consistency after every frame; blocks requested this frame are
 * never evicted within it; every failure is exhaustion of a pool whose blocks are all requested. */
static void test_cache_random_frames(void **state)
{
    (void)state;
    osc_desc desc = {0};
    desc.effects[0].texel_bytes = 2;
    desc.effects[0].max_blocks = 300;
    desc.effects[1].texel_bytes = 4;
    desc.effects[1].max_blocks = 200;
    desc.effects[1].convergence = true;
    desc.table_capacity = 512; /* 500 blocks: the table reaches its 75 % limit (384) first */
    osc_cache *cache = create_or_fail(&desc);
    uint64_t rng = 99;
    uint64_t frame_keys[400];
    uint32_t frame_blocks_seen[400];
    uint64_t table_full_before = 0;
    for (uint32_t frame = 0; frame < 300; frame++) {
        osc_begin_frame(cache, frame);
        uint32_t requests = 50 + rng_below(&rng, 350);
        uint32_t islands = 20 + (frame % 50) * 3;
        for (uint32_t i = 0; i < requests; i++) {
            uint64_t key = random_key(&rng, 2, islands);
            uint32_t block;
            osc_result result = osc_request(cache, key, 1ull << rng_below(&rng, 64), &block);
            if (result == OSC_OK) {
                frame_keys[i] = key;
                frame_blocks_seen[i] = block;
                uint32_t *convergence = osc_block_convergence(cache, osc_key_effect(key), block);
                assert_true((convergence != NULL) == (osc_key_effect(key) == 1));
                if (convergence)
                    (*convergence)++;
            } else {
                frame_keys[i] = OSC_KEY_EMPTY;
                assert_true(result == OSC_ERR_POOL_EXHAUSTED || result == OSC_ERR_TABLE_FULL);
                if (result == OSC_ERR_POOL_EXHAUSTED) {
                    const osc__pool *pool = &cache->pools[osc_key_effect(key)];
                    assert_int_equal(pool->frame_block_count, pool->capacity);
                } else {
                    assert_int_equal(cache->table.count, cache->table.max_count);
                }
            }
        }
        /* Everything mapped this frame is still where it was mapped. */
        for (uint32_t i = 0; i < requests; i++) {
            if (frame_keys[i] == OSC_KEY_EMPTY)
                continue;
            assert_int_equal(osc_find(cache, frame_keys[i]), frame_blocks_seen[i]);
            assert_int_equal(osc_block_last_frame(cache, osc_key_effect(frame_keys[i]), frame_blocks_seen[i]),
                             frame);
        }
        check_cache_consistency(cache);
        osc_housekeeping(cache);
        check_cache_consistency(cache);
        osc_stats stats;
        osc_stats_get(cache, &stats);
        assert_true(stats.table_count <= 384);
        table_full_before = stats.table_full;
    }
    osc_stats stats;
    osc_stats_get(cache, &stats);
    assert_true(stats.evictions > 0);
    assert_true(stats.effects[0].immediate_evictions > 0 || stats.effects[1].immediate_evictions > 0);
    assert_true(table_full_before > 0);
    osc_destroy(cache);
}

static void test_remove_and_frame_list(void **state)
{
    (void)state;
    osc_desc desc = {0};
    desc.effects[5].texel_bytes = 2;
    desc.effects[5].max_blocks = 8;
    osc_cache *cache = create_or_fail(&desc);
    uint32_t block, count;
    osc_begin_frame(cache, 0);
    for (uint32_t i = 0; i < 4; i++)
        assert_int_equal(osc_request(cache, osc_key_pack(5, 0, 0, i, 0), 1u << i, &block), OSC_OK);
    assert_int_equal(osc_remove(cache, osc_key_pack(5, 0, 0, 1, 0)), OSC_OK);
    assert_int_equal(osc_remove(cache, osc_key_pack(5, 0, 0, 1, 0)), OSC_ERR_NOT_FOUND);
    const uint32_t *blocks = osc_frame_blocks(cache, 5, &count);
    assert_int_equal(count, 3);
    assert_int_equal(blocks[0], 0);
    assert_int_equal(blocks[1], 2);
    assert_int_equal(blocks[2], 3);
    /* The freed block is reused (stack) and appears once on the frame list. */
    assert_int_equal(osc_request(cache, osc_key_pack(5, 0, 0, 9, 0), 0x80, &block), OSC_OK);
    assert_int_equal(block, 1);
    assert_true(osc_block_requested(cache, 5, 1) == 0x80);
    blocks = osc_frame_blocks(cache, 5, &count);
    assert_int_equal(count, 4);
    assert_int_equal(blocks[3], 1);
    /* Payload and valid mask. */
    assert_int_equal(osc_pool_texel_bytes(cache, 5), 2);
    uint8_t *payload = osc_block_payload(cache, 5, 1);
    for (int i = 0; i < 128; i++)
        assert_int_equal(payload[i], 0);
    payload[127] = 9;
    osc_block_set_valid(cache, 5, 1, 0x8000000000000000ull);
    assert_true(osc_block_valid(cache, 5, 1) == 0x8000000000000000ull);
    assert_true(osc_block_key(cache, 5, 1) == osc_key_pack(5, 0, 0, 9, 0));
    assert_null(osc_block_convergence(cache, 5, 1));
    check_cache_consistency(cache);
    osc_begin_frame(cache, 1);
    osc_frame_blocks(cache, 5, &count);
    assert_int_equal(count, 0);
    for (uint32_t b = 0; b < 8; b++)
        assert_true(osc_block_requested(cache, 5, b) == 0);
    assert_true(osc_block_valid(cache, 5, 1) == 0x8000000000000000ull); /* data survives frames */
    osc_destroy(cache);
}

/* ---- memory accounting -------------------------------------------------------------------------------------- */

static void test_memory_accounting(void **state)
{
    (void)state;
    fxt_counting_allocator counter = {0};
    osc_desc desc = {0};
    desc.effects[0].texel_bytes = 2;
    desc.effects[0].max_blocks = 100;
    desc.effects[3].texel_bytes = 4;
    desc.effects[3].max_blocks = 50;
    desc.effects[3].convergence = true;
    desc.allocator = (osc_allocator){fxt_counting_alloc, fxt_counting_free, &counter};
    osc_cache *cache = create_or_fail(&desc);
    osc_memory_report report;
    osc_memory(cache, &report);
    assert_int_equal(report.total_bytes, counter.live_bytes);
    /* 150 blocks -> 150 % = 225 -> 256 slots. */
    assert_int_equal(report.table_key_bytes, 256 * 8);
    assert_int_equal(report.table_value_bytes, 256 * 4);
    assert_int_equal(report.cache_struct_bytes, sizeof(osc_cache));
    assert_int_equal(report.effects[0].block_meta_bytes, 100 * (8 + 8 + 4 + 8));
    assert_int_equal(report.effects[0].payload_reserved_bytes, 100 * 64 * 2);
    assert_int_equal(report.effects[0].list_bytes, 100 * (4 + 4 + 8));
    assert_int_equal(report.effects[3].block_meta_bytes, 50 * (8 + 8 + 4 + 8 + 4));
    assert_int_equal(report.effects[3].payload_reserved_bytes, 50 * 64 * 4);
    assert_int_equal(report.effects[3].list_bytes, 50 * (4 + 4 + 8));
    assert_int_equal(report.effects[1].total_bytes, 0);
    assert_int_equal(report.payload_in_use_bytes, 0);
    size_t per_effect_sum = 0;
    for (int e = 0; e < 16; e++)
        per_effect_sum += report.effects[e].total_bytes;
    assert_int_equal(report.total_bytes, per_effect_sum + report.cache_struct_bytes + report.table_key_bytes +
                                             report.table_value_bytes);
    /* No allocation during frames; in-use payload follows resident blocks. */
    size_t allocations = counter.total_allocations;
    uint32_t block;
    osc_begin_frame(cache, 0);
    for (uint32_t i = 0; i < 30; i++)
        assert_int_equal(osc_request(cache, osc_key_pack(0, 4, 0, i, 0), 1, &block), OSC_OK);
    for (uint32_t i = 0; i < 7; i++)
        assert_int_equal(osc_request(cache, osc_key_pack(3, 4, 0, i, 0), 1, &block), OSC_OK);
    osc_housekeeping(cache);
    assert_int_equal(counter.total_allocations, allocations);
    osc_memory(cache, &report);
    assert_int_equal(report.effects[0].payload_in_use_bytes, 30 * 128);
    assert_int_equal(report.effects[3].payload_in_use_bytes, 7 * 256);
    assert_int_equal(report.payload_in_use_bytes, 30 * 128 + 7 * 256);
    assert_int_equal(report.total_bytes, counter.live_bytes);
    osc_destroy(cache);
    assert_int_equal(counter.live_bytes, 0);
    assert_int_equal(counter.live_allocations, 0);

    /* Allocation failure at every step: a clean error, nothing leaked. */
    for (size_t fail_at = 1; fail_at <= allocations; fail_at++) {
        fxt_counting_allocator failing = {.fail_at = fail_at};
        desc.allocator.user = &failing;
        osc_cache *broken = (osc_cache *)&failing;
        char message[200];
        assert_int_equal(osc_create(&desc, &broken, message, sizeof message), OSC_ERR_OUT_OF_MEMORY);
        assert_null(broken);
        assert_non_null(strstr(message, "out of memory"));
        assert_int_equal(failing.live_bytes, 0);
        assert_int_equal(failing.live_allocations, 0);
    }
}

static void test_desc_validation(void **state)
{
    (void)state;
    char message[200];
    osc_cache *cache;
    osc_desc desc = {0};
    desc.effects[2].texel_bytes = 2000;
    assert_int_equal(osc_create(&desc, &cache, message, sizeof message), OSC_ERR_INVALID_DESC);
    assert_null(cache);
    assert_non_null(strstr(message, "effects[2].texel_bytes 2000"));
    desc = (osc_desc){0};
    desc.effects[0].texel_bytes = 4;
    desc.table_capacity = 1000;
    assert_int_equal(osc_create(&desc, &cache, message, sizeof message), OSC_ERR_INVALID_DESC);
    assert_non_null(strstr(message, "table_capacity 1000"));
    desc.table_capacity = 0;
    desc.max_load_percent = 99;
    assert_int_equal(osc_create(&desc, &cache, message, sizeof message), OSC_ERR_INVALID_DESC);
    assert_non_null(strstr(message, "max_load_percent 99"));
    desc.max_load_percent = 0;
    desc.effects[1].max_blocks = 5; /* without texel_bytes */
    assert_int_equal(osc_create(&desc, &cache, message, sizeof message), OSC_ERR_INVALID_DESC);
    assert_non_null(strstr(message, "effects[1]"));
    /* Defaults: 65536 blocks, 131072 slots (150 % = 98304, rounded up). */
    desc.effects[1].max_blocks = 0;
    assert_int_equal(osc_create(&desc, &cache, NULL, 0), OSC_OK);
    assert_int_equal(osc_pool_capacity(cache, 0), 65536);
    assert_int_equal(osc_pool_capacity(cache, 1), 0);
    osc_stats stats;
    osc_stats_get(cache, &stats);
    assert_int_equal(stats.table_capacity, 131072);
    assert_int_equal(stats.effects[0].age_threshold, 64);
    assert_int_equal(cache->table.max_count, 98304);
    osc_destroy(cache);
}

/* ---- batch determinism -------------------------------------------------------------------------------------- */

enum { BATCH_FRAMES = 12, BATCH_REQUESTS = 6000, BATCH_THREADS = 4 };

static osc_cache *create_batch_cache(void)
{
    osc_desc desc = {0};
    desc.effects[0].texel_bytes = 2;
    desc.effects[0].max_blocks = 700;
    desc.effects[1].texel_bytes = 4;
    desc.effects[1].max_blocks = 400;
    desc.effects[2].texel_bytes = 2;
    desc.effects[2].max_blocks = 150; /* small enough to exhaust in some frames */
    return create_or_fail(&desc);
}

static void assert_caches_identical(const osc_cache *a, const osc_cache *b)
{
    assert_int_equal(a->table.count, b->table.count);
    assert_memory_equal(a->table.keys, b->table.keys, a->table.capacity * sizeof(uint64_t));
    assert_memory_equal(a->table.values, b->table.values, a->table.capacity * sizeof(uint32_t));
    for (int effect = 0; effect < 3; effect++) {
        const osc__pool *pa = &a->pools[effect], *pb = &b->pools[effect];
        uint32_t n = pa->capacity;
        assert_memory_equal(pa->keys, pb->keys, n * sizeof(uint64_t));
        assert_memory_equal(pa->requested, pb->requested, n * sizeof(uint64_t));
        assert_memory_equal(pa->last_stamp, pb->last_stamp, n * sizeof(uint32_t));
        assert_int_equal(pa->frame_block_count, pb->frame_block_count);
        assert_memory_equal(pa->frame_blocks, pb->frame_blocks, pa->frame_block_count * sizeof(uint32_t));
        assert_int_equal(pa->free_count, pb->free_count);
        assert_memory_equal(pa->free_stack, pb->free_stack, pa->free_count * sizeof(uint32_t));
        assert_int_equal(pa->age_threshold, pb->age_threshold);
        assert_int_equal(pa->expected_new, pb->expected_new);
        assert_int_equal(pa->stats.evictions, pb->stats.evictions);
        assert_int_equal(pa->stats.immediate_evictions, pb->stats.immediate_evictions);
        assert_int_equal(pa->stats.exhausted, pb->stats.exhausted);
        assert_int_equal(pa->stats.inserts, pb->stats.inserts);
    }
    assert_int_equal(a->stats.lookups, b->stats.lookups);
    assert_int_equal(a->stats.hits, b->stats.hits);
}

typedef struct thread_job {
    const uint64_t *keys;
    const uint64_t *masks;
    size_t count;
    uint32_t thread;
    uint32_t threads;
    uint64_t *out_keys; /* this thread's own buffer */
    uint64_t *out_masks;
    size_t out_count;
} thread_job;

/* A "visibility" worker: takes every threads-th request (like one tile of pixels) into its own buffer. */
static void *gather_requests(void *argument)
{
    thread_job *job = argument;
    job->out_count = 0;
    for (size_t i = job->thread; i < job->count; i += job->threads) {
        job->out_keys[job->out_count] = job->keys[i];
        job->out_masks[job->out_count] = job->masks[i];
        job->out_count++;
    }
    return NULL;
}

static void test_batch_determinism(void **state)
{
    (void)state;
    osc_cache *reference = create_batch_cache(); /* single thread, generated order */
    osc_cache *shuffled = create_batch_cache();  /* single thread, shuffled order */
    osc_cache *threaded = create_batch_cache();  /* per-thread buffers, concatenated in reverse order */
    uint64_t *keys = malloc(BATCH_REQUESTS * sizeof(uint64_t)),
             *masks = malloc(BATCH_REQUESTS * sizeof(uint64_t));
    uint64_t *work_keys = malloc(BATCH_REQUESTS * sizeof(uint64_t));
    uint64_t *work_masks = malloc(BATCH_REQUESTS * sizeof(uint64_t));
    uint64_t *thread_keys = malloc(BATCH_REQUESTS * sizeof(uint64_t));
    uint64_t *thread_masks = malloc(BATCH_REQUESTS * sizeof(uint64_t));
    uint32_t *blocks_reference = malloc(BATCH_REQUESTS * sizeof(uint32_t));
    uint32_t *blocks_other = malloc(BATCH_REQUESTS * sizeof(uint32_t));
    assert_true(keys && masks && work_keys && work_masks && thread_keys && thread_masks && blocks_reference &&
                blocks_other);
    uint64_t rng = 2024, shuffle_rng = 77;
    for (uint32_t frame = 0; frame < BATCH_FRAMES; frame++) {
        for (size_t i = 0; i < BATCH_REQUESTS; i++) {
            keys[i] = random_key(&rng, 3, 40 + frame * 10); /* many duplicates, drifting islands */
            masks[i] = 1ull << rng_below(&rng, 64);
        }
        osc_begin_frame(reference, frame);
        osc_begin_frame(shuffled, frame);
        osc_begin_frame(threaded, frame);

        memcpy(work_keys, keys, BATCH_REQUESTS * sizeof(uint64_t));
        memcpy(work_masks, masks, BATCH_REQUESTS * sizeof(uint64_t));
        size_t unique_reference;
        osc_result result_reference = osc_request_batch(reference, work_keys, work_masks, BATCH_REQUESTS,
                                                        &unique_reference, blocks_reference);
        for (size_t i = 1; i < unique_reference; i++)
            assert_true(work_keys[i - 1] < work_keys[i]);

        memcpy(work_keys, keys, BATCH_REQUESTS * sizeof(uint64_t));
        memcpy(work_masks, masks, BATCH_REQUESTS * sizeof(uint64_t));
        shuffle_pairs(work_keys, work_masks, BATCH_REQUESTS, &shuffle_rng);
        size_t unique_other;
        osc_result result_other =
            osc_request_batch(shuffled, work_keys, work_masks, BATCH_REQUESTS, &unique_other, blocks_other);
        assert_int_equal(result_other, result_reference);
        assert_int_equal(unique_other, unique_reference);
        assert_memory_equal(blocks_other, blocks_reference, unique_reference * sizeof(uint32_t));

        /* Threads gather into their own buffers; concatenated in reverse thread order. */
        pthread_t threads[BATCH_THREADS];
        thread_job jobs[BATCH_THREADS];
        size_t offset = 0;
        for (uint32_t t = 0; t < BATCH_THREADS; t++) {
            size_t share = (BATCH_REQUESTS + BATCH_THREADS - 1) / BATCH_THREADS;
            jobs[t] = (thread_job){keys,
                                   masks,
                                   BATCH_REQUESTS,
                                   t,
                                   BATCH_THREADS,
                                   thread_keys + t * share,
                                   thread_masks + t * share,
                                   0};
            assert_int_equal(pthread_create(&threads[t], NULL, gather_requests, &jobs[t]), 0);
        }
        for (uint32_t t = 0; t < BATCH_THREADS; t++)
            assert_int_equal(pthread_join(threads[t], NULL), 0);
        for (uint32_t t = BATCH_THREADS; t-- > 0;) {
            memcpy(work_keys + offset, jobs[t].out_keys, jobs[t].out_count * sizeof(uint64_t));
            memcpy(work_masks + offset, jobs[t].out_masks, jobs[t].out_count * sizeof(uint64_t));
            offset += jobs[t].out_count;
        }
        assert_int_equal(offset, BATCH_REQUESTS);
        result_other =
            osc_request_batch(threaded, work_keys, work_masks, offset, &unique_other, blocks_other);
        assert_int_equal(result_other, result_reference);
        assert_int_equal(unique_other, unique_reference);
        assert_memory_equal(blocks_other, blocks_reference, unique_reference * sizeof(uint32_t));

        assert_caches_identical(reference, shuffled);
        assert_caches_identical(reference, threaded);
        check_cache_consistency(reference);
        osc_housekeeping(reference);
        osc_housekeeping(shuffled);
        osc_housekeeping(threaded);
        assert_caches_identical(reference, shuffled);
        assert_caches_identical(reference, threaded);
    }
    osc_stats stats;
    osc_stats_get(reference, &stats);
    assert_true(stats.evictions > 0); /* the test exercised eviction ... */
    assert_true(stats.exhausted > 0); /* ... and exhaustion */
    free(keys);
    free(masks);
    free(work_keys);
    free(work_masks);
    free(thread_keys);
    free(thread_masks);
    free(blocks_reference);
    free(blocks_other);
    osc_destroy(reference);
    osc_destroy(shuffled);
    osc_destroy(threaded);
}

/* Batch merging: duplicate keys OR their masks; the result equals individual requests. */
static void test_batch_merge(void **state)
{
    (void)state;
    osc_desc desc = {0};
    desc.effects[0].texel_bytes = 2;
    desc.effects[0].max_blocks = 16;
    osc_cache *cache = create_or_fail(&desc);
    osc_begin_frame(cache, 0);
    uint64_t key_a = osc_key_pack(0, 1, 0, 3, 0), key_b = osc_key_pack(0, 1, 0, 1, 0);
    uint64_t keys[5] = {key_a, key_b, key_a, key_a, key_b};
    uint64_t masks[5] = {1, 2, 4, 8, 16};
    uint32_t blocks[5];
    size_t unique;
    assert_int_equal(osc_request_batch(cache, keys, masks, 5, &unique, blocks), OSC_OK);
    assert_int_equal(unique, 2);
    assert_true(keys[0] == key_b && keys[1] == key_a);
    assert_true(masks[0] == 18 && masks[1] == 13);
    assert_int_equal(blocks[0], 0); /* allocation in key order */
    assert_int_equal(blocks[1], 1);
    assert_true(osc_block_requested(cache, 0, 1) == 13);
    uint32_t found[3];
    uint64_t probe[3] = {key_a, key_b, osc_key_pack(0, 1, 0, 2, 0)};
    osc_find_batch(cache, probe, 3, found);
    assert_int_equal(found[0], 1);
    assert_int_equal(found[1], 0);
    assert_int_equal(found[2], OSC_NONE);
    assert_int_equal(osc_request_batch(cache, NULL, NULL, 0, &unique, NULL), OSC_OK);
    assert_int_equal(unique, 0);
    osc_destroy(cache);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_radix_sort),
        cmocka_unit_test(test_table_reference_model),
        cmocka_unit_test(test_table_clustered_delete),
        cmocka_unit_test(test_pool_exhaustion_and_recovery),
        cmocka_unit_test(test_age_threshold_eviction),
        cmocka_unit_test(test_cache_random_frames),
        cmocka_unit_test(test_remove_and_frame_list),
        cmocka_unit_test(test_memory_accounting),
        cmocka_unit_test(test_desc_validation),
        cmocka_unit_test(test_batch_merge),
        cmocka_unit_test(test_batch_determinism),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
