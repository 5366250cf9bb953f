/* osc.h: the on-surface cache (OSC), after Weinrauch et al. 2023, section 3.1 (notes in
 * shared/papers/weinrauch2023-effect-cache-notes.txt) and DESIGN.md "On-surface cache".
 *
 * What it holds. Every island has its own texture space; at level l (0 = finest) it is
 * ceil(size0 / 2^l) texels wide and high. Texture space is cut into 8 x 8 texel blocks. A block is named by
 * a 64-bit key  effect:4 | island:32 | level:4 | block_y:12 | block_x:12  (high bits to low bits), and one
 * open-addressing hash table for all effects maps a key to the index of a block in that effect's pool.
 * The engine names the back of an island (its triangles seen against their winding) by the island id with
 * its top bit set (SCENE_ISLAND_BACK, scene.h): a twin island with its own blocks, created only when a
 * viewer sees that side. The cache treats it as any other island id.
 * Per block the pool keeps (structure of arrays): the texels requested this frame (64-bit mask, bit
 * y*8+x), the texels that hold data (valid mask), the frame it was last requested, its key, an optional
 * 32-bit convergence word and the payload: 64 texels of `texel_bytes` bytes each, defined by the effect.
 *
 * The frame, as seen from here (fixed phase order):
 *   osc_begin_frame(c, frame)    clears the requested masks of last frame's blocks
 *   osc_request / _batch         stage 3: map blocks (evicting old ones if a pool is empty), OR masks
 *   osc_frame_blocks, accessors  stage 4-6: the blocks requested this frame, their masks and payload
 *   osc_find                     stage 7: read-only lookups, safe from several threads at once
 *   osc_housekeeping(c)          stage 9: adaptive LRU eviction so the next frame finds free blocks
 *
 * Threads. Only osc_find, osc_find_batch and the const accessors may run concurrently (with each other,
 * never with a writer). Requests from several threads are gathered into per-thread (key, mask) buffers and
 * handed to osc_request_batch() on one thread: it sorts by key and merges duplicates first, so the
 * resulting table, block assignment and statistics are identical whatever the thread interleaving.
 *
 * Memory. Everything is allocated in osc_create() (through an optional counting allocator) and nothing
 * afterwards: no allocation per request, per block or per frame. osc_memory() reports every byte. */
#ifndef FXC_OSC_H
#define FXC_OSC_H

#include "fxc_result.h"

#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

/* ---- programming errors ------------------------------------------------------------------------- */

/* OSC_ASSERT stays on in every build type (tests run RelWithDebInfo, where assert() is compiled out);
 * it is used for programming errors only (bad arguments from our own code), never on hot probe loops. */
#define OSC_ASSERT(cond)                                                                                     \
    do {                                                                                                     \
        if (!(cond)) {                                                                                       \
            fprintf(stderr, "%s:%d: osc assertion failed: %s\n", __FILE__, __LINE__, #cond);                 \
            abort();                                                                                         \
        }                                                                                                    \
    } while (0)

/* ---- constants ------------------------------------------------------------------------------------ */

#define OSC_MAX_EFFECTS     16u        /* effect field is 4 bits */
#define OSC_MAX_LEVEL       15u        /* level field is 4 bits */
#define OSC_MAX_BLOCK_COORD 4095u      /* block_x, block_y are 12 bits */
#define OSC_BLOCK_SIZE      8u         /* texels per block side */
#define OSC_BLOCK_TEXELS    64u        /* texels per block (one bit each in a texel mask) */
#define OSC_MAX_ISLAND_SIZE 32768u     /* level-0 island size limit in texels: 4096 blocks of 8 */
#define OSC_NONE            UINT32_MAX /* "no block" */
#define OSC_FRAME_NEVER     UINT32_MAX /* osc_block_last_frame() of a block never requested */

/* The one key value that is never a valid key: effect 15, island 0xffffffff, level 15, block (4095, 4095).
 * It cannot name a real block because an island at level 15 is one texel, i.e. only block (0, 0). The
 * table uses it to mark empty slots; a block's key reads OSC_KEY_EMPTY while the block is free. */
#define OSC_KEY_EMPTY UINT64_MAX

/* ---- keys ----------------------------------------------------------------------------------------- */

#define OSC_KEY_EFFECT_SHIFT  60
#define OSC_KEY_ISLAND_SHIFT  28
#define OSC_KEY_LEVEL_SHIFT   24
#define OSC_KEY_BLOCK_Y_SHIFT 12
#define OSC_KEY_BLOCK_X_SHIFT 0

/* The fields of a key, unpacked. */
typedef struct osc_key_fields {
    uint32_t effect;    /* 0..15 */
    uint32_t island_id; /* any 32-bit island index */
    uint32_t level;     /* 0..15, 0 = finest */
    uint32_t block_x;   /* 0..4095, in blocks of 8 texels at `level` */
    uint32_t block_y;   /* 0..4095 */
} osc_key_fields;

/* Packs the fields of a block name into a key. Out-of-range fields are programming errors (asserted);
 * the reserved value OSC_KEY_EMPTY is asserted against too. */
static inline uint64_t osc_key_pack(uint32_t effect, uint32_t island_id, uint32_t level, uint32_t block_x,
                                    uint32_t block_y)
{
    OSC_ASSERT(effect < OSC_MAX_EFFECTS);
    OSC_ASSERT(level <= OSC_MAX_LEVEL);
    OSC_ASSERT(block_x <= OSC_MAX_BLOCK_COORD);
    OSC_ASSERT(block_y <= OSC_MAX_BLOCK_COORD);
    uint64_t key = ((uint64_t)effect << OSC_KEY_EFFECT_SHIFT) |
                   ((uint64_t)island_id << OSC_KEY_ISLAND_SHIFT) | ((uint64_t)level << OSC_KEY_LEVEL_SHIFT) |
                   ((uint64_t)block_y << OSC_KEY_BLOCK_Y_SHIFT) |
                   ((uint64_t)block_x << OSC_KEY_BLOCK_X_SHIFT);
    OSC_ASSERT(key != OSC_KEY_EMPTY);
    return key;
}

/* The effect of a key (top 4 bits): selects the block pool. */
static inline uint32_t osc_key_effect(uint64_t key)
{
    return (uint32_t)(key >> OSC_KEY_EFFECT_SHIFT);
}

/* Unpacks every field of a key (any 64-bit value unpacks; nothing to assert). */
static inline osc_key_fields osc_key_unpack(uint64_t key)
{
    osc_key_fields fields;
    fields.effect = (uint32_t)(key >> OSC_KEY_EFFECT_SHIFT) & 0xFu;
    fields.island_id = (uint32_t)(key >> OSC_KEY_ISLAND_SHIFT);
    fields.level = (uint32_t)(key >> OSC_KEY_LEVEL_SHIFT) & 0xFu;
    fields.block_y = (uint32_t)(key >> OSC_KEY_BLOCK_Y_SHIFT) & 0xFFFu;
    fields.block_x = (uint32_t)(key >> OSC_KEY_BLOCK_X_SHIFT) & 0xFFFu;
    return fields;
}

/* ---- texel footprints ----------------------------------------------------------------------------- */

/* Texel coordinate convention (every footprint function): coordinates are floats in texel units of the
 * level they are given for, island-local; texel (i, j) covers [i, i+1) x [j, j+1) and its centre is
 * (i + 0.5, j + 0.5). A coordinate at level l maps to level l+1 by halving it. The island's size at level
 * l is ceil(size0 / 2^l) texels per axis (DESIGN.md "Definitions"). Coordinates outside the island (and
 * NaN) are clamped to its border texels, so every footprint names existing texels only.
 *
 *   point:     the texel containing (x, y)                                   -> 1 block
 *   bilinear:  texels floor(x - 0.5) .. +1 per axis (the 2 x 2 stencil, including texels whose weight is
 *              zero when (x, y) sits exactly on a centre; duplicates at the border collapse) -> up to 4 blocks
 *   trilinear: bilinear at level l with (x, y), and at level l+1 with (x/2, y/2)         -> up to 8 blocks
 * Results go to a caller-provided osc_footprint (no allocation): `count` entries of key and texel mask,
 * in a fixed order (level l before l+1; within a level, the order blocks are first met in the stencil
 * order (x0,y0) (x1,y0) (x0,y1) (x1,y1)), each key once. */
#define OSC_FOOTPRINT_MAX 8u

/* One island as the footprint helpers need it. */
typedef struct osc_island_extent {
    uint32_t effect;    /* 0..15: the effect field of the produced keys */
    uint32_t island_id; /* island index (key field) */
    uint32_t width0;    /* island width at level 0, texels, 1..32768 */
    uint32_t height0;   /* island height at level 0, texels, 1..32768 */
} osc_island_extent;

/* Blocks touched by one filtered lookup: keys and texel masks, `count` <= OSC_FOOTPRINT_MAX. */
typedef struct osc_footprint {
    uint32_t count;
    uint64_t keys[OSC_FOOTPRINT_MAX];
    uint64_t texel_masks[OSC_FOOTPRINT_MAX];
} osc_footprint;

/* The island's size in texels at `level`: ceil(size0 / 2^level), at least 1. */
static inline uint32_t osc_level_size(uint32_t size0, uint32_t level)
{
    OSC_ASSERT(size0 >= 1 && size0 <= OSC_MAX_ISLAND_SIZE && level <= OSC_MAX_LEVEL);
    return (size0 + (1u << level) - 1u) >> level;
}

/* The bit of texel (x, y) in its block's texel mask (x, y are texel coordinates at any level). */
static inline uint64_t osc_texel_bit(uint32_t texel_x, uint32_t texel_y)
{
    return (uint64_t)1 << ((texel_y & 7u) * 8u + (texel_x & 7u));
}

/* Point filtering at `level`: fills *out with 1 block. Precondition: level <= 15, island size valid. */
void osc_footprint_point(const osc_island_extent *island, uint32_t level, float x, float y,
                         osc_footprint *out);

/* Bilinear filtering at `level`: fills *out with 1..4 blocks. Same preconditions. */
void osc_footprint_bilinear(const osc_island_extent *island, uint32_t level, float x, float y,
                            osc_footprint *out);

/* Trilinear filtering between `level` and level+1 (x, y given at `level`): fills *out with 2..8 blocks.
 * Precondition: level < 15. */
void osc_footprint_trilinear(const osc_island_extent *island, uint32_t level, float x, float y,
                             osc_footprint *out);

/* The bilinear footprint for the hot per-pixel paths (requests): the same blocks, masks and order as
 * osc_footprint_bilinear() for the same arguments, without its argument checks and inlined. Precondition
 * (the caller's, unchecked): effect < 16, level <= 15, 1 <= width0, height0 <= OSC_MAX_ISLAND_SIZE.
 * Writes 1..4 (key, mask) pairs and returns how many. */
static inline uint32_t osc_bilinear_keys(uint32_t effect, uint32_t island_id, uint32_t width0,
                                         uint32_t height0, uint32_t level, float x, float y, uint64_t keys[4],
                                         uint64_t masks[4])
{
    uint32_t width = (width0 + (1u << level) - 1u) >> level, height = (height0 + (1u << level) - 1u) >> level;
    float fx = x - 0.5f, fy = y - 0.5f;
    int32_t x0 = !(fx >= -1.0f) ? -1 : (fx > (float)width ? (int32_t)width : (int32_t)floorf(fx));
    int32_t y0 = !(fy >= -1.0f) ? -1 : (fy > (float)height ? (int32_t)height : (int32_t)floorf(fy));
    uint32_t tx[2], ty[2];
    for (int i = 0; i < 2; i++) {
        int32_t cx = x0 + i, cy = y0 + i;
        tx[i] = cx < 0 ? 0 : ((uint32_t)cx >= width ? width - 1 : (uint32_t)cx);
        ty[i] = cy < 0 ? 0 : ((uint32_t)cy >= height ? height - 1 : (uint32_t)cy);
    }
    uint64_t base = ((uint64_t)effect << OSC_KEY_EFFECT_SHIFT) |
                    ((uint64_t)island_id << OSC_KEY_ISLAND_SHIFT) | ((uint64_t)level << OSC_KEY_LEVEL_SHIFT);
    if ((tx[0] >> 3) == (tx[1] >> 3) && (ty[0] >> 3) == (ty[1] >> 3)) { /* the usual case: one block */
        keys[0] = base | ((uint64_t)(ty[0] >> 3) << OSC_KEY_BLOCK_Y_SHIFT) |
                  ((uint64_t)(tx[0] >> 3) << OSC_KEY_BLOCK_X_SHIFT);
        masks[0] = ((uint64_t)1 << ((ty[0] & 7u) * 8u + (tx[0] & 7u))) |
                   ((uint64_t)1 << ((ty[0] & 7u) * 8u + (tx[1] & 7u))) |
                   ((uint64_t)1 << ((ty[1] & 7u) * 8u + (tx[0] & 7u))) |
                   ((uint64_t)1 << ((ty[1] & 7u) * 8u + (tx[1] & 7u)));
        return 1;
    }
    uint32_t count = 0;
    for (int i = 0; i < 4; i++) { /* (x0,y0) (x1,y0) (x0,y1) (x1,y1), as osc_footprint_bilinear */
        uint32_t px = tx[i & 1], py = ty[i >> 1];
        uint64_t key = base | ((uint64_t)(py >> 3) << OSC_KEY_BLOCK_Y_SHIFT) |
                       ((uint64_t)(px >> 3) << OSC_KEY_BLOCK_X_SHIFT);
        uint64_t bit = (uint64_t)1 << ((py & 7u) * 8u + (px & 7u));
        uint32_t j = 0;
        while (j < count && keys[j] != key)
            j++;
        if (j == count) {
            keys[count] = key;
            masks[count++] = bit;
        } else {
            masks[j] |= bit;
        }
    }
    return count;
}

/* ---- results -------------------------------------------------------------------------------------- */

/* The cache's result codes: its own names and texts, the shared values of common/fxc_result.h (name, value,
 * text). Run-time failures only (pool exhausted is a
 * normal, counted event the caller degrades on); programming errors are asserted instead. */
#define OSC_RESULT_LIST(X)                                                                                   \
    X(OSC_OK, FXC_OK, "ok")                                                                                  \
    X(OSC_ERR_INVALID_DESC, FXC_ERR_INVALID, "invalid cache description")                                    \
    X(OSC_ERR_OUT_OF_MEMORY, FXC_ERR_NOMEM, "out of memory while creating the cache")                        \
    X(OSC_ERR_NO_POOL, FXC_ERR_NO_POOL,                                                                      \
      "the key's effect has no block pool (texel_bytes 0 in the description)")                               \
    X(OSC_ERR_POOL_EXHAUSTED, FXC_ERR_POOL_EXHAUSTED,                                                        \
      "every block of the effect's pool is requested this frame")                                            \
    X(OSC_ERR_TABLE_FULL, FXC_ERR_TABLE_FULL, "the hash table is at its maximum load")                       \
    X(OSC_ERR_NOT_FOUND, FXC_ERR_NOT_FOUND, "the key is not resident")

typedef enum osc_result {
#define OSC_RESULT_ENUM(name, value, text) name = value,
    OSC_RESULT_LIST(OSC_RESULT_ENUM)
#undef OSC_RESULT_ENUM
} osc_result;

/* The text of a result code (static string; "unknown osc result" for values outside the table). */
const char *osc_result_string(osc_result result);

/* ---- creation ------------------------------------------------------------------------------------- */

/* Optional allocator: every allocation of the cache goes through it, once, in osc_create(). free gets the
 * size that was allocated, so a counting allocator needs no header. */
typedef struct osc_allocator {
    void *(*alloc)(size_t size, void *user);              /* NULL: malloc */
    void (*free)(void *pointer, size_t size, void *user); /* NULL: free */
    void *user;
} osc_allocator;

/* One effect's block pool. All-zero: the effect is absent (no pool, nothing allocated).
 * block_texels exists so the world-space cache (wsc.h) can reuse this core for 1 x 1 x 1 bricks: a block
 * of 1 element has a payload of texel_bytes and uses bit 0 of its masks only (the caller keeps the other
 * bits zero). A block of 64 elements is an 8 x 8 texel block here and a 4 x 4 x 4 brick in the wsc. */
typedef struct osc_effect_desc {
    uint32_t texel_bytes;  /* payload bytes per texel, 1..1024 (0 = effect absent; e.g. 2 shadow, 4 AO) */
    uint32_t max_blocks;   /* pool capacity in 8x8 blocks (default 65536 when texel_bytes > 0) */
    bool convergence;      /* keep one uint32 convergence word per block (default false) */
    uint32_t block_texels; /* elements per block: 64 or 1 (default 64, the 8 x 8 texel block) */
} osc_effect_desc;

/* The cache's configuration; all-zero fields take the defaults written beside them. */
typedef struct osc_desc {
    osc_effect_desc effects[OSC_MAX_EFFECTS]; /* indexed by the key's effect field */
    uint32_t table_capacity;     /* slots, a power of two (default: 150 % of all pools' blocks, rounded up
                                     to a power of two, at least 16) */
    uint32_t max_load_percent;   /* inserts beyond this load fail with OSC_ERR_TABLE_FULL, 10..95
                                     (default 75) */
    uint32_t initial_age_frames; /* starting adaptive age threshold, frames (default 64) */
    uint32_t max_age_frames;     /* a block not requested for more frames than this is evicted even when
                                     memory is free, and the adaptive threshold never exceeds it, frames
                                     (default 1024) */
    osc_allocator allocator;     /* default: malloc / free */
    bool single_pool;            /* keys carry no effect field: every key, all 64 bits of it, goes to
                                     pool 0 and only effects[0] may be present (the world-space cache's
                                     WGIs); OSC_KEY_EMPTY stays reserved (default false: the top 4 bits
                                     select the pool) */
} osc_desc;

typedef struct osc_cache osc_cache;

/* Creates a cache: validates the description, resolves defaults and allocates every table, pool and list
 * up front. On success *out_cache owns all of it (free with osc_destroy). On failure returns
 * OSC_ERR_INVALID_DESC or OSC_ERR_OUT_OF_MEMORY, sets *out_cache to NULL and, when error_text is not
 * NULL, writes a message naming the field at fault (truncated to error_text_cap). */
osc_result osc_create(const osc_desc *desc, osc_cache **out_cache, char *error_text, size_t error_text_cap);

/* Frees everything the cache allocated (through its allocator). NULL is allowed. */
void osc_destroy(osc_cache *cache);

/* ---- the frame -------------------------------------------------------------------------------------- */

/* Starts frame `frame`: clears the requested masks of the blocks requested last frame (only those) and
 * empties the list of this frame's blocks. Precondition: frame < UINT32_MAX and greater than the previous
 * frame number (the first frame may be 0). Must be called before the first request. */
void osc_begin_frame(osc_cache *cache, uint32_t frame);

/* Requests texels of one block: finds the key's block or maps an empty one (evicting the least recently
 * used block of that effect not requested this frame if the pool is empty), ORs texel_mask into its
 * requested mask and stamps it with the current frame. Returns OSC_OK with *block_index set, or a counted
 * failure (OSC_ERR_POOL_EXHAUSTED, OSC_ERR_TABLE_FULL, OSC_ERR_NO_POOL) with *block_index = OSC_NONE: the
 * caller degrades (for example uses a coarser level or skips the effect for that pixel).
 * A block index stays valid until the next osc_begin_frame for blocks requested this frame; any other
 * block may be evicted by a later request or by housekeeping. Not thread-safe (see osc_request_batch). */
osc_result osc_request(osc_cache *cache, uint64_t key, uint64_t texel_mask, uint32_t *block_index);

/* Requests many (key, mask) pairs deterministically: sorts the arrays in place by key (in-place radix
 * sort, no allocation), merges duplicate keys (OR of their masks) and requests the unique keys in
 * ascending key order. On return keys[0..*unique_count) are the unique keys, masks[] their merged masks,
 * and, if block_indices is not NULL (room for `count` entries), block_indices[i] is the block of keys[i]
 * or OSC_NONE. The outcome depends only on the multiset of pairs, never on their order, so per-thread
 * buffers concatenated in any order give identical results. Returns OSC_OK when every key was mapped,
 * else the failure of the first key (in key order) that was not. */
osc_result osc_request_batch(osc_cache *cache, uint64_t *keys, uint64_t *masks, size_t count,
                             size_t *unique_count, uint32_t *block_indices);

/* Looks a key up without changing anything: its block index, or OSC_NONE. Read-only and not counted, so
 * several threads may call it at once while nobody writes. */
uint32_t osc_find(const osc_cache *cache, uint64_t key);

/* osc_find for `count` keys at once, with software prefetching (faster on large tables). */
void osc_find_batch(const osc_cache *cache, const uint64_t *keys, size_t count, uint32_t *block_indices);

/* osc_find_batch, then per key its block's valid mask and payload in `effect`'s pool (osc_block_valid,
 * osc_block_payload), or 0 and NULL when absent: a whole neighbourhood read in one call. Read-only and not
 * counted, as osc_find. Precondition (asserted): the effect has a pool. */
void osc_find_payloads(const osc_cache *cache, uint32_t effect, const uint64_t *keys, size_t count,
                       uint64_t *valid, const void **payload);

/* Unmaps a key and returns its block to its pool's free list. OSC_ERR_NOT_FOUND when absent. */
osc_result osc_remove(osc_cache *cache, uint64_t key);

/* Stage 9, once per frame after the frame's requests: per pool, updates the running estimate of new
 * blocks per frame, evicts blocks older than the adaptive age threshold and then, least recently used
 * first, as many more as needed so the free blocks cover the expected new requests (never a block
 * requested this frame), and adapts the threshold to the ratio of free blocks to expected requests:
 * halved under pressure (free < expected), grown by a quarter when free >= 2 x expected, kept within
 * [1, max_age_frames]. No allocation; O(pool capacity). */
void osc_housekeeping(osc_cache *cache);

/* ---- blocks ------------------------------------------------------------------------------------------ */

/* The blocks of `effect` requested this frame, in first-request order (stage 4's input): returns the
 * array (owned by the cache, valid until the next request, remove or frame) and sets *count. */
const uint32_t *osc_frame_blocks(osc_cache *cache, uint32_t effect, uint32_t *count);

/* Per-block accessors. Precondition: the effect has a pool and block_index < its capacity. */
uint64_t osc_block_key(const osc_cache *cache, uint32_t effect, uint32_t block_index); /* EMPTY if free */
uint64_t osc_block_requested(const osc_cache *cache, uint32_t effect, uint32_t block_index);  /* this frame */
uint64_t osc_block_valid(const osc_cache *cache, uint32_t effect, uint32_t block_index);      /* hold data */
uint32_t osc_block_last_frame(const osc_cache *cache, uint32_t effect, uint32_t block_index); /* or NEVER */

/* Replaces a block's valid mask (the effect calls it after writing texels of the payload). */
void osc_block_set_valid(osc_cache *cache, uint32_t effect, uint32_t block_index, uint64_t valid_mask);

/* The block's payload: 64 texels of texel_bytes bytes, texel (x, y) at byte (y*8+x)*texel_bytes (a pool
 * of block_texels 1: one element of texel_bytes bytes). Owned by the cache; zeroed when the block is
 * mapped. */
void *osc_block_payload(osc_cache *cache, uint32_t effect, uint32_t block_index);

/* The block's convergence word (zeroed when mapped), or NULL when the pool has none. */
uint32_t *osc_block_convergence(osc_cache *cache, uint32_t effect, uint32_t block_index);

/* Pool shape: capacity in blocks, bytes per texel and elements per block (all 0 for an absent effect). */
uint32_t osc_pool_capacity(const osc_cache *cache, uint32_t effect);
uint32_t osc_pool_texel_bytes(const osc_cache *cache, uint32_t effect);
uint32_t osc_pool_block_texels(const osc_cache *cache, uint32_t effect);

/* ---- statistics and memory -------------------------------------------------------------------------- */

/* Per-effect counters (cumulative since creation unless said otherwise). */
typedef struct osc_effect_stats {
    uint64_t requests;            /* osc_request calls (batch: unique keys) for this effect */
    uint64_t inserts;             /* blocks mapped */
    uint64_t evictions;           /* blocks evicted, housekeeping and immediate */
    uint64_t immediate_evictions; /* of which evicted inside a request because the pool was empty */
    uint64_t removals;            /* osc_remove */
    uint64_t exhausted;           /* requests failed with OSC_ERR_POOL_EXHAUSTED */
    uint32_t blocks_resident;     /* now */
    uint32_t blocks_peak;         /* highest blocks_resident seen */
    uint32_t blocks_this_frame;   /* blocks requested in the current frame */
    uint32_t new_this_frame;      /* blocks the current frame asked to map (mapped or failed) */
    uint32_t expected_new;        /* running estimate of new blocks per frame (eviction target) */
    uint32_t age_threshold;       /* current adaptive age threshold, frames */
} osc_effect_stats;

/* Whole-cache counters. */
typedef struct osc_stats {
    uint64_t lookups;        /* table lookups by request, batch and remove (osc_find is not counted) */
    uint64_t hits;           /* of which found */
    uint64_t inserts;        /* sum over effects */
    uint64_t evictions;      /* sum over effects */
    uint64_t exhausted;      /* sum over effects */
    uint64_t table_full;     /* inserts refused at maximum load */
    uint32_t table_count;    /* keys in the table now */
    uint32_t table_capacity; /* slots */
    uint32_t frame;          /* current frame number */
    osc_effect_stats effects[OSC_MAX_EFFECTS];
} osc_stats;

/* Copies the statistics into *out. */
void osc_stats_get(const osc_cache *cache, osc_stats *out);

/* Bytes allocated for one effect, by structure. */
typedef struct osc_effect_memory {
    size_t block_meta_bytes;       /* requested, valid, last frame, key and convergence arrays */
    size_t payload_reserved_bytes; /* the whole payload pool (allocated) */
    size_t payload_in_use_bytes;   /* the part held by resident blocks (not an extra allocation) */
    size_t list_bytes;             /* free stack, this frame's block list, eviction candidates */
    size_t total_bytes;            /* block_meta + payload_reserved + list */
} osc_effect_memory;

/* Every byte the cache allocated, by structure and by effect; total_bytes equals the bytes that went
 * through the allocator. Reserved pool capacity is reported apart from what resident blocks use. */
typedef struct osc_memory_report {
    size_t cache_struct_bytes;     /* the osc_cache object itself */
    size_t table_key_bytes;        /* hash table keys */
    size_t table_value_bytes;      /* hash table values (block indices) */
    size_t block_meta_bytes;       /* sum over effects */
    size_t payload_reserved_bytes; /* sum over effects */
    size_t payload_in_use_bytes;   /* sum over effects (part of payload_reserved_bytes) */
    size_t list_bytes;             /* sum over effects */
    size_t total_bytes;            /* everything allocated */
    osc_effect_memory effects[OSC_MAX_EFFECTS];
} osc_memory_report;

/* Fills *out with the memory report. */
void osc_memory(const osc_cache *cache, osc_memory_report *out);

#endif
