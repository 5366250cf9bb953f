/* osc_internal.h: private structures of the on-surface cache, shared by cache/osc*.c and by white-box
 * tests and benchmarks (tests/test_osc.c, bench/bench_osc.c). Not part of the public API.
 *
 *   osc__table   the open-addressing hash table (osc_table.c): keys and values in separate arrays so that
 *                probing reads keys only; linear probing, backward-shift deletion, bounded loops.
 *   osc__pool    one effect's block pool (osc.c): structure-of-arrays block metadata, payload, free stack,
 *                this frame's block list and the eviction candidate list.
 *   osc__sort_u64  in-place radix sort used by batches and by eviction (osc_sort.c). */
#ifndef FXC_OSC_INTERNAL_H
#define FXC_OSC_INTERNAL_H

#include "osc.h"

/* ---- hash table ------------------------------------------------------------------------------------- */

typedef struct osc__table {
    uint64_t *keys;     /* [capacity], OSC_KEY_EMPTY marks a free slot */
    uint32_t *values;   /* [capacity], block index of keys[i] */
    uint32_t capacity;  /* power of two */
    uint32_t mask;      /* capacity - 1 */
    uint32_t count;     /* keys stored */
    uint32_t max_count; /* inserts beyond this count are refused (max load) */
} osc__table;

/* The 64-bit mixer (murmur3's fmix64 finalizer): every key bit affects every hash bit, so structured keys
 * (neighbouring blocks differ in their low bits only) spread over the table. */
static inline uint64_t osc__hash(uint64_t key)
{
    key ^= key >> 33;
    key *= 0xff51afd7ed558ccdull;
    key ^= key >> 33;
    key *= 0xc4ceb9fe1a85ec53ull;
    key ^= key >> 33;
    return key;
}

/* Initializes a table over caller-owned arrays (capacity a power of two >= 16, max_count < capacity) and
 * marks every slot empty. */
void osc__table_init(osc__table *table, uint64_t *keys, uint32_t *values, uint32_t capacity,
                     uint32_t max_count);

/* The slot holding key, or OSC_NONE. Precondition: key != OSC_KEY_EMPTY.
 * Plain linear probing, one slot per step: measured faster here than reading 4-slot windows without
 * branches and than Robin Hood ordering with early miss exit (bench/bench_osc.c; both tried). */
static inline uint32_t osc__table_find_slot(const osc__table *table, uint64_t key)
{
    const uint64_t *keys = table->keys;
    uint32_t mask = table->mask;
    uint32_t slot = (uint32_t)osc__hash(key) & mask;
    /* Bounded: the table is never full (max_count < capacity), so an empty slot ends every probe; the
     * bound only guards against a corrupted table. */
    for (uint32_t step = 0; step <= mask; step++) {
        uint64_t stored = keys[slot];
        if (stored == key)
            return slot;
        if (stored == OSC_KEY_EMPTY)
            return OSC_NONE;
        slot = (slot + 1) & mask;
    }
    return OSC_NONE;
}

/* The value stored for key, or OSC_NONE. */
static inline uint32_t osc__table_find(const osc__table *table, uint64_t key)
{
    uint32_t slot = osc__table_find_slot(table, key);
    return slot == OSC_NONE ? OSC_NONE : table->values[slot];
}

/* Finds `count` keys with prefetching: values_out[i] = value of keys[i] or OSC_NONE. */
void osc__table_find_batch(const osc__table *table, const uint64_t *keys, size_t count, uint32_t *values_out);

/* Inserts a key known to be absent. Returns false (and changes nothing) at maximum load. */
bool osc__table_insert(osc__table *table, uint64_t key, uint32_t value);

/* Removes the key in `slot` by backward shift: later keys of the same probe run move back so that every
 * remaining key stays reachable from its home slot without tombstones. */
void osc__table_remove_slot(osc__table *table, uint32_t slot);

/* Removes key; false when absent. */
bool osc__table_remove(osc__table *table, uint64_t key);

/* Checks the table invariant (every key reachable from its home slot, count matches): for tests. */
bool osc__table_check(const osc__table *table);

/* ---- sorting ------------------------------------------------------------------------------------------ */

/* Sorts keys[0..count) ascending in place (MSD radix sort, 8-bit digits, insertion sort for small
 * ranges); when payload is not NULL its entries move with their keys. Not stable: equal keys may come out
 * with their payloads in any order (callers merge them with a commutative operation). No allocation;
 * recursion depth at most 8. */
void osc__sort_u64(uint64_t *keys, uint64_t *payload, size_t count);

/* ---- pools and the cache -------------------------------------------------------------------------- */

/* Memory accounting buckets. */
enum {
    OSC__MEM_STRUCT,
    OSC__MEM_TABLE_KEYS,
    OSC__MEM_TABLE_VALUES,
    OSC__MEM_BLOCK_META,
    OSC__MEM_PAYLOAD,
    OSC__MEM_LISTS,
    OSC__MEM_COUNT
};

typedef struct osc__pool {
    uint32_t texel_bytes;  /* 0: no pool */
    uint32_t capacity;     /* blocks */
    uint32_t block_texels; /* elements per block: 64 (8 x 8 texels, 4 x 4 x 4 cells) or 1 */
    uint32_t block_bytes;  /* block_texels * texel_bytes */
    uint32_t in_use;       /* resident blocks */
    /* Block metadata, structure of arrays, [capacity] each. */
    uint64_t *requested;   /* texels requested this frame */
    uint64_t *valid;       /* texels holding data */
    uint32_t *last_stamp;  /* frame + 1 of the last request, 0 = never */
    uint64_t *keys;        /* the block's key, OSC_KEY_EMPTY when free */
    uint32_t *convergence; /* optional, NULL when the effect keeps none */
    uint8_t *payload;      /* capacity * block_bytes */
    /* Lists. */
    uint32_t *free_stack; /* [capacity]; free_stack[0..free_count) */
    uint32_t free_count;
    uint32_t *frame_blocks; /* [capacity]; blocks first requested this frame, in order */
    uint32_t frame_block_count;
    uint64_t *candidates; /* [capacity]; (last_stamp << 32 | block), oldest first */
    uint32_t candidate_count;
    uint32_t candidate_cursor;
    uint32_t candidate_stamp; /* frame stamp the candidate list was built in, 0 = stale */
    /* Adaptive eviction state. */
    uint32_t new_this_frame; /* blocks asked to be mapped this frame (mapped or failed) */
    uint32_t expected_new;   /* running estimate of new blocks per frame */
    uint32_t age_threshold;  /* frames */
    /* Statistics. */
    osc_effect_stats stats;
    size_t bytes[OSC__MEM_COUNT]; /* bytes allocated for this pool, by bucket */
} osc__pool;

struct osc_cache {
    osc_allocator allocator;
    osc__table table;
    osc__pool pools[OSC_MAX_EFFECTS];
    uint32_t pool_select; /* ANDed with the key's top 4 bits to pick the pool: 0xF, or 0 for a
                                single-pool cache (osc__pool_of_key) */
    uint32_t stamp;       /* current frame + 1; 0 before the first osc_begin_frame */
    uint32_t max_age_frames;
    osc_stats stats;              /* whole-cache counters (effects[] filled on osc_stats_get) */
    size_t bytes[OSC__MEM_COUNT]; /* bytes allocated, by bucket, whole cache */
};

/* The pool a key belongs to: its top 4 bits, masked to 0 in a single-pool cache. A mask rather than a
 * branch keeps the default request path as it was (one more AND with a field of the same cache line). */
static inline osc__pool *osc__pool_of_key(osc_cache *cache, uint64_t key)
{
    return &cache->pools[(uint32_t)(key >> OSC_KEY_EFFECT_SHIFT) & cache->pool_select];
}

/* Builds the pool's eviction candidate list for the current stamp: resident blocks not requested this
 * frame, least recently requested first (ties by block index). */
void osc__pool_build_candidates(osc_cache *cache, osc__pool *pool);

/* Evicts one block: removes its key from the table and pushes it on the free stack. */
void osc__pool_evict(osc_cache *cache, osc__pool *pool, uint32_t block_index);

#endif
