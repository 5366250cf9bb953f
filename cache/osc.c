/* osc.c: the on-surface cache: creation (every allocation, counted), the frame (begin, requests,
 * housekeeping), block pools with their free stacks and adaptive least-recently-used eviction (paper
 * section 3.1.3 and 4.1), statistics and the memory report. See osc.h for the API and the phase order,
 * osc_table.c for the hash table.
 *
 * Frame stamps. Blocks remember stamp = frame + 1 of their last request (0 = never), so frame 0 is an
 * ordinary frame. A block is on its pool's frame list exactly when its stamp equals the current stamp;
 * that list is what begin_frame clears and what stage 4 reads.
 *
 * Eviction. Two paths, both never touching a block requested this frame:
 *   - housekeeping (once per frame): with E the running estimate of new blocks per frame, evict blocks
 *     older than the adaptive age threshold T, then more, least recently used first, until free >= E;
 *     T halves when free < E before eviction and grows by a quarter when free >= 2E;
 *   - immediate (inside a request that finds the pool empty): the least recently used block not
 *     requested this frame, from a candidate list sorted once per frame on first need. When every
 *     resident block was requested this frame the request fails with a counted OSC_ERR_POOL_EXHAUSTED. */
#include "osc_internal.h"

#include <stdarg.h>
#include <string.h>

#define OSC__DEFAULT_MAX_BLOCKS   65536u
#define OSC__DEFAULT_LOAD_PERCENT 75u
#define OSC__DEFAULT_INITIAL_AGE  64u
#define OSC__DEFAULT_MAX_AGE      1024u
#define OSC__MAX_TEXEL_BYTES      1024u
#define OSC__MAX_TOTAL_BLOCKS     (1u << 30) /* keeps the default table capacity within uint32 */
#define OSC__MIN_TABLE_CAPACITY   16u

/* ---- results ------------------------------------------------------------------------------------------ */

/* The text of a result code. */
const char *osc_result_string(osc_result result)
{
    switch (result) {
#define OSC_RESULT_CASE(name, value, text)                                                                   \
    case name: return text;
        OSC_RESULT_LIST(OSC_RESULT_CASE)
#undef OSC_RESULT_CASE
    }
    return "unknown osc result";
}

/* ---- allocation ----------------------------------------------------------------------------------------- */

static void *osc__default_alloc(size_t size, void *user)
{
    (void)user;
    return malloc(size);
}

static void osc__default_free(void *pointer, size_t size, void *user)
{
    (void)size;
    (void)user;
    free(pointer);
}

/* Allocates `count` elements of `element_size` bytes (overflow-checked) and counts them in `bucket` of
 * the cache and, when pool is not NULL, of that pool. NULL on overflow or failure. */
static void *osc__alloc_array(osc_cache *cache, osc__pool *pool, int bucket, size_t count,
                              size_t element_size)
{
    if (count == 0 || element_size == 0 || count > SIZE_MAX / element_size)
        return NULL;
    size_t size = count * element_size;
    void *pointer = cache->allocator.alloc(size, cache->allocator.user);
    if (!pointer)
        return NULL;
    cache->bytes[bucket] += size;
    if (pool)
        pool->bytes[bucket] += size;
    return pointer;
}

static void osc__free_array(const osc_cache *cache, void *pointer, size_t count, size_t element_size)
{
    if (pointer)
        cache->allocator.free(pointer, count * element_size, cache->allocator.user);
}

/* ---- creation ------------------------------------------------------------------------------------------- */

#if defined(__GNUC__) || defined(__clang__)
__attribute__((format(printf, 3, 4)))
#endif
static osc_result
osc__invalid(char *error_text, size_t error_text_cap, const char *format, ...)
{
    if (error_text && error_text_cap > 0) {
        va_list arguments;
        va_start(arguments, format);
        vsnprintf(error_text, error_text_cap, format, arguments);
        va_end(arguments);
    }
    return OSC_ERR_INVALID_DESC;
}

static uint32_t osc__next_power_of_two(uint64_t value)
{
    uint64_t power = 1;
    while (power < value)
        power <<= 1;
    return power > (1ull << 31) ? 0 : (uint32_t)power;
}

/* Validates the description and resolves every default into *resolved (the one place defaults live). */
static osc_result osc__resolve_desc(const osc_desc *desc, osc_desc *resolved, char *error_text,
                                    size_t error_text_cap)
{
    *resolved = *desc;
    uint64_t total_blocks = 0;
    for (unsigned effect = 0; effect < OSC_MAX_EFFECTS; effect++) {
        osc_effect_desc *effect_desc = &resolved->effects[effect];
        if (effect_desc->texel_bytes == 0) {
            if (effect_desc->max_blocks != 0 || effect_desc->convergence || effect_desc->block_texels != 0)
                return osc__invalid(
                    error_text, error_text_cap,
                    "effects[%u]: max_blocks, convergence or block_texels set but texel_bytes is 0", effect);
            continue;
        }
        if (resolved->single_pool && effect != 0)
            return osc__invalid(error_text, error_text_cap,
                                "effects[%u]: a single-pool cache has effects[0] only", effect);
        if (effect_desc->block_texels == 0)
            effect_desc->block_texels = OSC_BLOCK_TEXELS;
        if (effect_desc->block_texels != OSC_BLOCK_TEXELS && effect_desc->block_texels != 1)
            return osc__invalid(error_text, error_text_cap, "effects[%u].block_texels %u is neither 64 nor 1",
                                effect, effect_desc->block_texels);
        if (effect_desc->texel_bytes > OSC__MAX_TEXEL_BYTES)
            return osc__invalid(error_text, error_text_cap, "effects[%u].texel_bytes %u exceeds 1024", effect,
                                effect_desc->texel_bytes);
        if (effect_desc->max_blocks == 0)
            effect_desc->max_blocks = OSC__DEFAULT_MAX_BLOCKS;
        if (effect_desc->max_blocks > OSC__MAX_TOTAL_BLOCKS)
            return osc__invalid(error_text, error_text_cap, "effects[%u].max_blocks %u exceeds 2^30", effect,
                                effect_desc->max_blocks);
        total_blocks += effect_desc->max_blocks;
    }
    if (total_blocks > OSC__MAX_TOTAL_BLOCKS)
        return osc__invalid(error_text, error_text_cap, "sum of max_blocks (%llu blocks) exceeds 2^30",
                            (unsigned long long)total_blocks);
    if (resolved->max_load_percent == 0)
        resolved->max_load_percent = OSC__DEFAULT_LOAD_PERCENT;
    if (resolved->max_load_percent < 10 || resolved->max_load_percent > 95)
        return osc__invalid(error_text, error_text_cap, "max_load_percent %u is outside 10..95",
                            resolved->max_load_percent);
    if (resolved->table_capacity == 0) {
        uint64_t wanted = (total_blocks * 3 + 1) / 2;
        resolved->table_capacity =
            osc__next_power_of_two(wanted < OSC__MIN_TABLE_CAPACITY ? OSC__MIN_TABLE_CAPACITY : wanted);
    } else if ((resolved->table_capacity & (resolved->table_capacity - 1)) != 0 ||
               resolved->table_capacity < OSC__MIN_TABLE_CAPACITY) {
        return osc__invalid(error_text, error_text_cap, "table_capacity %u is not a power of two >= 16",
                            resolved->table_capacity);
    }
    if (resolved->initial_age_frames == 0)
        resolved->initial_age_frames = OSC__DEFAULT_INITIAL_AGE;
    if (resolved->max_age_frames == 0)
        resolved->max_age_frames = OSC__DEFAULT_MAX_AGE;
    if (resolved->initial_age_frames > resolved->max_age_frames)
        return osc__invalid(error_text, error_text_cap, "initial_age_frames %u exceeds max_age_frames %u",
                            resolved->initial_age_frames, resolved->max_age_frames);
    if (!resolved->allocator.alloc != !resolved->allocator.free)
        return osc__invalid(error_text, error_text_cap, "allocator: set both alloc and free, or neither");
    if (!resolved->allocator.alloc) {
        resolved->allocator.alloc = osc__default_alloc;
        resolved->allocator.free = osc__default_free;
    }
    return OSC_OK;
}

/* Allocates one pool's arrays; false when an allocation fails (the caller destroys the cache). */
static bool osc__pool_create(osc_cache *cache, osc__pool *pool, const osc_effect_desc *effect_desc,
                             uint32_t initial_age)
{
    uint32_t capacity = effect_desc->max_blocks;
    pool->texel_bytes = effect_desc->texel_bytes;
    pool->capacity = capacity;
    pool->block_texels = effect_desc->block_texels;
    pool->block_bytes = effect_desc->block_texels * effect_desc->texel_bytes;
    pool->age_threshold = initial_age;
    pool->requested = osc__alloc_array(cache, pool, OSC__MEM_BLOCK_META, capacity, sizeof(uint64_t));
    pool->valid = osc__alloc_array(cache, pool, OSC__MEM_BLOCK_META, capacity, sizeof(uint64_t));
    pool->last_stamp = osc__alloc_array(cache, pool, OSC__MEM_BLOCK_META, capacity, sizeof(uint32_t));
    pool->keys = osc__alloc_array(cache, pool, OSC__MEM_BLOCK_META, capacity, sizeof(uint64_t));
    if (effect_desc->convergence)
        pool->convergence = osc__alloc_array(cache, pool, OSC__MEM_BLOCK_META, capacity, sizeof(uint32_t));
    pool->payload = osc__alloc_array(cache, pool, OSC__MEM_PAYLOAD, capacity, pool->block_bytes);
    pool->free_stack = osc__alloc_array(cache, pool, OSC__MEM_LISTS, capacity, sizeof(uint32_t));
    pool->frame_blocks = osc__alloc_array(cache, pool, OSC__MEM_LISTS, capacity, sizeof(uint32_t));
    pool->candidates = osc__alloc_array(cache, pool, OSC__MEM_LISTS, capacity, sizeof(uint64_t));
    if (!pool->requested || !pool->valid || !pool->last_stamp || !pool->keys || !pool->payload ||
        !pool->free_stack || !pool->frame_blocks || !pool->candidates ||
        (effect_desc->convergence && !pool->convergence))
        return false;
    memset(pool->requested, 0, (size_t)capacity * sizeof(uint64_t));
    memset(pool->valid, 0, (size_t)capacity * sizeof(uint64_t));
    memset(pool->last_stamp, 0, (size_t)capacity * sizeof(uint32_t));
    memset(pool->keys, 0xFF, (size_t)capacity * sizeof(uint64_t)); /* OSC_KEY_EMPTY: free */
    if (pool->convergence)
        memset(pool->convergence, 0, (size_t)capacity * sizeof(uint32_t));
    /* Pop order 0, 1, 2, ...: the stack holds capacity-1 at the bottom. */
    for (uint32_t i = 0; i < capacity; i++)
        pool->free_stack[i] = capacity - 1 - i;
    pool->free_count = capacity;
    return true;
}

/* Creates a cache (see osc.h). */
osc_result osc_create(const osc_desc *desc, osc_cache **out_cache, char *error_text, size_t error_text_cap)
{
    OSC_ASSERT(desc != NULL && out_cache != NULL);
    *out_cache = NULL;
    if (error_text && error_text_cap > 0)
        error_text[0] = '\0';
    osc_desc resolved;
    osc_result result = osc__resolve_desc(desc, &resolved, error_text, error_text_cap);
    if (result != OSC_OK)
        return result;

    osc_cache *cache = resolved.allocator.alloc(sizeof *cache, resolved.allocator.user);
    if (!cache) {
        if (error_text && error_text_cap > 0)
            snprintf(error_text, error_text_cap, "out of memory allocating the cache (%zu bytes)",
                     sizeof *cache);
        return OSC_ERR_OUT_OF_MEMORY;
    }
    memset(cache, 0, sizeof *cache);
    cache->allocator = resolved.allocator;
    cache->bytes[OSC__MEM_STRUCT] = sizeof *cache;
    cache->max_age_frames = resolved.max_age_frames;
    cache->pool_select = resolved.single_pool ? 0u : 0xFu;

    uint32_t table_capacity = resolved.table_capacity;
    uint64_t *table_keys =
        osc__alloc_array(cache, NULL, OSC__MEM_TABLE_KEYS, table_capacity, sizeof(uint64_t));
    uint32_t *table_values =
        osc__alloc_array(cache, NULL, OSC__MEM_TABLE_VALUES, table_capacity, sizeof(uint32_t));
    cache->table.keys = table_keys; /* so osc_destroy frees them even if the next step fails */
    cache->table.values = table_values;
    cache->table.capacity = table_capacity;
    bool ok = table_keys && table_values;
    if (ok) {
        uint32_t max_count = (uint32_t)((uint64_t)table_capacity * resolved.max_load_percent / 100);
        if (max_count == 0)
            max_count = 1;
        osc__table_init(&cache->table, table_keys, table_values, table_capacity, max_count);
    }
    for (unsigned effect = 0; ok && effect < OSC_MAX_EFFECTS; effect++) {
        if (resolved.effects[effect].texel_bytes != 0)
            ok = osc__pool_create(cache, &cache->pools[effect], &resolved.effects[effect],
                                  resolved.initial_age_frames);
    }
    if (!ok) {
        size_t allocated = 0;
        for (int bucket = 0; bucket < OSC__MEM_COUNT; bucket++)
            allocated += cache->bytes[bucket];
        osc_destroy(cache);
        if (error_text && error_text_cap > 0)
            snprintf(error_text, error_text_cap,
                     "out of memory creating the cache (%zu bytes allocated before)", allocated);
        return OSC_ERR_OUT_OF_MEMORY;
    }
    cache->stats.table_capacity = table_capacity;
    *out_cache = cache;
    return OSC_OK;
}

/* Frees every allocation, with the sizes it was made with. */
void osc_destroy(osc_cache *cache)
{
    if (!cache)
        return;
    for (unsigned effect = 0; effect < OSC_MAX_EFFECTS; effect++) {
        osc__pool *pool = &cache->pools[effect];
        size_t capacity = pool->capacity;
        osc__free_array(cache, pool->requested, capacity, sizeof(uint64_t));
        osc__free_array(cache, pool->valid, capacity, sizeof(uint64_t));
        osc__free_array(cache, pool->last_stamp, capacity, sizeof(uint32_t));
        osc__free_array(cache, pool->keys, capacity, sizeof(uint64_t));
        osc__free_array(cache, pool->convergence, capacity, sizeof(uint32_t));
        osc__free_array(cache, pool->payload, capacity, pool->block_bytes);
        osc__free_array(cache, pool->free_stack, capacity, sizeof(uint32_t));
        osc__free_array(cache, pool->frame_blocks, capacity, sizeof(uint32_t));
        osc__free_array(cache, pool->candidates, capacity, sizeof(uint64_t));
    }
    osc__free_array(cache, cache->table.keys, cache->table.capacity, sizeof(uint64_t));
    osc__free_array(cache, cache->table.values, cache->table.capacity, sizeof(uint32_t));
    osc_allocator allocator = cache->allocator;
    allocator.free(cache, sizeof *cache, allocator.user);
}

/* ---- pools ---------------------------------------------------------------------------------------------- */

static osc__pool *osc__pool_of(const osc_cache *cache, uint32_t effect)
{
    OSC_ASSERT(effect < OSC_MAX_EFFECTS);
    return (osc__pool *)&cache->pools[effect];
}

static osc__pool *osc__pool_block(const osc_cache *cache, uint32_t effect, uint32_t block_index)
{
    osc__pool *pool = osc__pool_of(cache, effect);
    OSC_ASSERT(pool->texel_bytes != 0 && block_index < pool->capacity);
    return pool;
}

/* Takes a block off the frame list (only osc_remove frees a block requested this frame; rare, so a
 * linear search that keeps the list's order is fine). */
static void osc__frame_list_drop(osc__pool *pool, uint32_t block_index)
{
    for (uint32_t i = 0; i < pool->frame_block_count; i++) {
        if (pool->frame_blocks[i] == block_index) {
            memmove(&pool->frame_blocks[i], &pool->frame_blocks[i + 1],
                    (size_t)(pool->frame_block_count - i - 1) * sizeof(uint32_t));
            pool->frame_block_count--;
            return;
        }
    }
}

/* Returns a resident block to the free stack (its key already removed from the table). */
static void osc__pool_free_block(osc_cache *cache, osc__pool *pool, uint32_t block_index)
{
    if (pool->last_stamp[block_index] == cache->stamp && cache->stamp != 0)
        osc__frame_list_drop(pool, block_index);
    pool->keys[block_index] = OSC_KEY_EMPTY;
    pool->requested[block_index] = 0;
    pool->last_stamp[block_index] = 0;
    OSC_ASSERT(pool->free_count < pool->capacity);
    pool->free_stack[pool->free_count++] = block_index;
    pool->in_use--;
}

/* Evicts one resident block (see osc_internal.h). */
void osc__pool_evict(osc_cache *cache, osc__pool *pool, uint32_t block_index)
{
    uint64_t key = pool->keys[block_index];
    OSC_ASSERT(key != OSC_KEY_EMPTY);
    OSC_ASSERT(pool->last_stamp[block_index] != cache->stamp); /* never a block requested this frame */
    bool removed = osc__table_remove(&cache->table, key);
    OSC_ASSERT(removed);
    (void)removed;
    osc__pool_free_block(cache, pool, block_index);
    pool->stats.evictions++;
    cache->stats.evictions++;
}

/* Builds the candidate list: resident blocks not requested this frame, oldest first (see header). */
void osc__pool_build_candidates(osc_cache *cache, osc__pool *pool)
{
    uint32_t count = 0;
    for (uint32_t block = 0; block < pool->capacity; block++) {
        if (pool->keys[block] != OSC_KEY_EMPTY && pool->last_stamp[block] != cache->stamp)
            pool->candidates[count++] = (uint64_t)pool->last_stamp[block] << 32 | block;
    }
    osc__sort_u64(pool->candidates, NULL, count);
    pool->candidate_count = count;
    pool->candidate_cursor = 0;
    pool->candidate_stamp = cache->stamp;
}

/* Immediate path: evicts the least recently used block not requested this frame and returns it (now free),
 * or OSC_NONE when every resident block was requested this frame. */
static uint32_t osc__evict_immediate(osc_cache *cache, osc__pool *pool)
{
    if (pool->candidate_stamp != cache->stamp)
        osc__pool_build_candidates(cache, pool);
    while (pool->candidate_cursor < pool->candidate_count) {
        uint32_t block = (uint32_t)pool->candidates[pool->candidate_cursor++];
        /* Skip blocks freed since the list was built and blocks (re)requested this frame. */
        if (pool->keys[block] == OSC_KEY_EMPTY || pool->last_stamp[block] == cache->stamp)
            continue;
        osc__pool_evict(cache, pool, block);
        pool->stats.immediate_evictions++;
        return block;
    }
    return OSC_NONE;
}

/* Maps an absent key to a free block (evicting if needed) and enters it in the table. */
static osc_result osc__map(osc_cache *cache, osc__pool *pool, uint64_t key, uint32_t *block_index)
{
    pool->new_this_frame++;
    if (pool->free_count == 0 && osc__evict_immediate(cache, pool) == OSC_NONE) {
        pool->stats.exhausted++;
        cache->stats.exhausted++;
        return OSC_ERR_POOL_EXHAUSTED;
    }
    uint32_t block = pool->free_stack[pool->free_count - 1];
    if (!osc__table_insert(&cache->table, key, block)) {
        cache->stats.table_full++;
        return OSC_ERR_TABLE_FULL;
    }
    pool->free_count--;
    pool->keys[block] = key;
    pool->requested[block] = 0;
    pool->valid[block] = 0;
    if (pool->convergence)
        pool->convergence[block] = 0;
    memset(pool->payload + (size_t)block * pool->block_bytes, 0, pool->block_bytes);
    pool->in_use++;
    if (pool->in_use > pool->stats.blocks_peak)
        pool->stats.blocks_peak = pool->in_use;
    pool->stats.inserts++;
    cache->stats.inserts++;
    *block_index = block;
    return OSC_OK;
}

/* ---- the frame ------------------------------------------------------------------------------------------ */

/* Starts a frame: clears last frame's requested masks (only the blocks on the frame lists). */
void osc_begin_frame(osc_cache *cache, uint32_t frame)
{
    OSC_ASSERT(frame < UINT32_MAX);
    OSC_ASSERT(cache->stamp == 0 || frame + 1 > cache->stamp);
    for (unsigned effect = 0; effect < OSC_MAX_EFFECTS; effect++) {
        osc__pool *pool = &cache->pools[effect];
        for (uint32_t i = 0; i < pool->frame_block_count; i++)
            pool->requested[pool->frame_blocks[i]] = 0;
        pool->frame_block_count = 0;
        pool->new_this_frame = 0;
    }
    cache->stamp = frame + 1;
    cache->stats.frame = frame;
}

/* Requests texels of one block (see osc.h). */
osc_result osc_request(osc_cache *cache, uint64_t key, uint64_t texel_mask, uint32_t *block_index)
{
    OSC_ASSERT(cache->stamp != 0); /* osc_begin_frame first */
    OSC_ASSERT(key != OSC_KEY_EMPTY);
    *block_index = OSC_NONE;
    osc__pool *pool = osc__pool_of_key(cache, key);
    if (pool->texel_bytes == 0)
        return OSC_ERR_NO_POOL;
    pool->stats.requests++;
    cache->stats.lookups++;
    uint32_t block;
    uint32_t slot = osc__table_find_slot(&cache->table, key);
    if (slot != OSC_NONE) {
        cache->stats.hits++;
        block = cache->table.values[slot];
    } else {
        osc_result result = osc__map(cache, pool, key, &block);
        if (result != OSC_OK)
            return result;
    }
    if (pool->last_stamp[block] != cache->stamp) {
        pool->last_stamp[block] = cache->stamp;
        pool->frame_blocks[pool->frame_block_count++] = block;
    }
    pool->requested[block] |= texel_mask;
    *block_index = block;
    return OSC_OK;
}

/* Sorts, merges and requests a batch (see osc.h). */
osc_result osc_request_batch(osc_cache *cache, uint64_t *keys, uint64_t *masks, size_t count,
                             size_t *unique_count, uint32_t *block_indices)
{
    OSC_ASSERT((keys && masks) || count == 0);
    osc__sort_u64(keys, masks, count);
    size_t unique = 0;
    for (size_t i = 0; i < count; i++) {
        if (unique > 0 && keys[unique - 1] == keys[i]) {
            masks[unique - 1] |= masks[i];
        } else {
            keys[unique] = keys[i];
            masks[unique] = masks[i];
            unique++;
        }
    }
    osc_result first_failure = OSC_OK;
    for (size_t i = 0; i < unique; i++) {
        uint32_t block;
        osc_result result = osc_request(cache, keys[i], masks[i], &block);
        if (block_indices)
            block_indices[i] = block;
        if (result != OSC_OK && first_failure == OSC_OK)
            first_failure = result;
    }
    if (unique_count)
        *unique_count = unique;
    return first_failure;
}

/* Read-only lookup. */
uint32_t osc_find(const osc_cache *cache, uint64_t key)
{
    if (key == OSC_KEY_EMPTY)
        return OSC_NONE;
    return osc__table_find(&cache->table, key);
}

/* Read-only batched lookup. */
void osc_find_batch(const osc_cache *cache, const uint64_t *keys, size_t count, uint32_t *block_indices)
{
    osc__table_find_batch(&cache->table, keys, count, block_indices);
}

/* Read-only batched lookup of blocks' valid masks and payloads (osc.h). */
void osc_find_payloads(const osc_cache *cache, uint32_t effect, const uint64_t *keys, size_t count,
                       uint64_t *valid, const void **payload)
{
    enum { GROUP = 16 };
    const osc__pool *pool = osc__pool_of(cache, effect);
    OSC_ASSERT(pool->texel_bytes != 0);
    uint32_t blocks[GROUP];
    for (size_t base = 0; base < count; base += GROUP) {
        size_t group = count - base < GROUP ? count - base : GROUP;
        osc__table_find_batch(&cache->table, keys + base, group, blocks);
        for (size_t i = 0; i < group; i++) {
            uint32_t b = blocks[i];
            if (b == OSC_NONE) {
                valid[base + i] = 0;
                payload[base + i] = NULL;
                continue;
            }
            OSC_ASSERT(b < pool->capacity);
            valid[base + i] = pool->valid[b];
            payload[base + i] = pool->payload + (size_t)b * pool->block_bytes;
        }
    }
}

/* Unmaps a key. */
osc_result osc_remove(osc_cache *cache, uint64_t key)
{
    if (key == OSC_KEY_EMPTY)
        return OSC_ERR_NOT_FOUND;
    cache->stats.lookups++;
    uint32_t slot = osc__table_find_slot(&cache->table, key);
    if (slot == OSC_NONE)
        return OSC_ERR_NOT_FOUND;
    cache->stats.hits++;
    osc__pool *pool = osc__pool_of_key(cache, key);
    uint32_t block = cache->table.values[slot];
    osc__table_remove_slot(&cache->table, slot);
    osc__pool_free_block(cache, pool, block);
    pool->stats.removals++;
    return OSC_OK;
}

/* Adaptive LRU eviction for one pool (see osc.h, osc_housekeeping). */
static void osc__pool_housekeeping(osc_cache *cache, osc__pool *pool)
{
    /* Running estimate of new blocks per frame: follows a rise at once, decays by 1/8 per frame. */
    uint32_t demand = pool->new_this_frame;
    if (demand >= pool->expected_new)
        pool->expected_new = demand;
    else
        pool->expected_new -= (pool->expected_new - demand + 7) / 8;
    uint32_t expected = pool->expected_new;
    uint32_t free_before = pool->free_count;

    osc__pool_build_candidates(cache, pool);
    while (pool->candidate_cursor < pool->candidate_count) {
        uint64_t entry = pool->candidates[pool->candidate_cursor];
        uint32_t age = cache->stamp - (uint32_t)(entry >> 32); /* >= 1: this frame's blocks are excluded */
        if (age <= pool->age_threshold && pool->free_count >= expected)
            break; /* oldest first: every later candidate is younger */
        osc__pool_evict(cache, pool, (uint32_t)entry);
        pool->candidate_cursor++;
    }
    /* Adapt the threshold to the ratio free / expected seen this frame. */
    if (free_before < expected) {
        pool->age_threshold = pool->age_threshold / 2 > 1 ? pool->age_threshold / 2 : 1;
    } else if ((uint64_t)free_before >= 2ull * expected) {
        uint32_t grown = pool->age_threshold + pool->age_threshold / 4 + 1;
        pool->age_threshold = grown < cache->max_age_frames ? grown : cache->max_age_frames;
    }
    pool->candidate_stamp = 0; /* the list no longer matches the pool; rebuilt on the next need */
}

/* Stage 9: eviction and statistics for every pool. */
void osc_housekeeping(osc_cache *cache)
{
    OSC_ASSERT(cache->stamp != 0);
    for (unsigned effect = 0; effect < OSC_MAX_EFFECTS; effect++) {
        if (cache->pools[effect].texel_bytes != 0)
            osc__pool_housekeeping(cache, &cache->pools[effect]);
    }
}

/* ---- blocks --------------------------------------------------------------------------------------------- */

/* This frame's blocks of one effect. */
const uint32_t *osc_frame_blocks(osc_cache *cache, uint32_t effect, uint32_t *count)
{
    osc__pool *pool = osc__pool_of(cache, effect);
    *count = pool->frame_block_count;
    return pool->frame_blocks;
}

/* The key of a block (OSC_KEY_EMPTY when free). */
uint64_t osc_block_key(const osc_cache *cache, uint32_t effect, uint32_t block_index)
{
    return osc__pool_block(cache, effect, block_index)->keys[block_index];
}

/* Texels requested this frame. */
uint64_t osc_block_requested(const osc_cache *cache, uint32_t effect, uint32_t block_index)
{
    return osc__pool_block(cache, effect, block_index)->requested[block_index];
}

/* Texels holding data. */
uint64_t osc_block_valid(const osc_cache *cache, uint32_t effect, uint32_t block_index)
{
    return osc__pool_block(cache, effect, block_index)->valid[block_index];
}

/* The frame a block was last requested in, or OSC_FRAME_NEVER. */
uint32_t osc_block_last_frame(const osc_cache *cache, uint32_t effect, uint32_t block_index)
{
    uint32_t stamp = osc__pool_block(cache, effect, block_index)->last_stamp[block_index];
    return stamp == 0 ? OSC_FRAME_NEVER : stamp - 1;
}

/* Replaces a block's valid mask. */
void osc_block_set_valid(osc_cache *cache, uint32_t effect, uint32_t block_index, uint64_t valid_mask)
{
    osc__pool_block(cache, effect, block_index)->valid[block_index] = valid_mask;
}

/* A block's payload. */
void *osc_block_payload(osc_cache *cache, uint32_t effect, uint32_t block_index)
{
    osc__pool *pool = osc__pool_block(cache, effect, block_index);
    return pool->payload + (size_t)block_index * pool->block_bytes;
}

/* A block's convergence word, or NULL. */
uint32_t *osc_block_convergence(osc_cache *cache, uint32_t effect, uint32_t block_index)
{
    osc__pool *pool = osc__pool_block(cache, effect, block_index);
    return pool->convergence ? &pool->convergence[block_index] : NULL;
}

/* Pool capacity in blocks (0 when absent). */
uint32_t osc_pool_capacity(const osc_cache *cache, uint32_t effect)
{
    return osc__pool_of(cache, effect)->capacity;
}

/* Bytes per texel (0 when absent). */
uint32_t osc_pool_texel_bytes(const osc_cache *cache, uint32_t effect)
{
    return osc__pool_of(cache, effect)->texel_bytes;
}

/* Elements per block (0 when absent). */
uint32_t osc_pool_block_texels(const osc_cache *cache, uint32_t effect)
{
    return osc__pool_of(cache, effect)->block_texels;
}

/* ---- statistics and memory ------------------------------------------------------------------------------- */

/* Copies the counters, filling in the live per-pool values. */
void osc_stats_get(const osc_cache *cache, osc_stats *out)
{
    *out = cache->stats;
    out->table_count = cache->table.count;
    out->table_capacity = cache->table.capacity;
    for (unsigned effect = 0; effect < OSC_MAX_EFFECTS; effect++) {
        const osc__pool *pool = &cache->pools[effect];
        osc_effect_stats *effect_stats = &out->effects[effect];
        *effect_stats = pool->stats;
        effect_stats->blocks_resident = pool->in_use;
        effect_stats->blocks_this_frame = pool->frame_block_count;
        effect_stats->new_this_frame = pool->new_this_frame;
        effect_stats->expected_new = pool->expected_new;
        effect_stats->age_threshold = pool->age_threshold;
    }
}

/* Fills the memory report from the byte counts kept at allocation. */
void osc_memory(const osc_cache *cache, osc_memory_report *out)
{
    memset(out, 0, sizeof *out);
    out->cache_struct_bytes = cache->bytes[OSC__MEM_STRUCT];
    out->table_key_bytes = cache->bytes[OSC__MEM_TABLE_KEYS];
    out->table_value_bytes = cache->bytes[OSC__MEM_TABLE_VALUES];
    out->block_meta_bytes = cache->bytes[OSC__MEM_BLOCK_META];
    out->payload_reserved_bytes = cache->bytes[OSC__MEM_PAYLOAD];
    out->list_bytes = cache->bytes[OSC__MEM_LISTS];
    for (unsigned effect = 0; effect < OSC_MAX_EFFECTS; effect++) {
        const osc__pool *pool = &cache->pools[effect];
        osc_effect_memory *effect_memory = &out->effects[effect];
        effect_memory->block_meta_bytes = pool->bytes[OSC__MEM_BLOCK_META];
        effect_memory->payload_reserved_bytes = pool->bytes[OSC__MEM_PAYLOAD];
        effect_memory->payload_in_use_bytes = (size_t)pool->in_use * pool->block_bytes;
        effect_memory->list_bytes = pool->bytes[OSC__MEM_LISTS];
        effect_memory->total_bytes = effect_memory->block_meta_bytes + effect_memory->payload_reserved_bytes +
                                     effect_memory->list_bytes;
        out->payload_in_use_bytes += effect_memory->payload_in_use_bytes;
    }
    out->total_bytes = out->cache_struct_bytes + out->table_key_bytes + out->table_value_bytes +
                       out->block_meta_bytes + out->payload_reserved_bytes + out->list_bytes;
}
