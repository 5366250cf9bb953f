/* wsc.h: the world-space cache (WSC), after Weinrauch et al. 2023, section 3.2 (notes in
 * shared/papers/weinrauch2023-effect-cache-notes.txt) and DESIGN.md "World-space cache".
 *
 * What it holds. Space is cut by a grid that is fixed in world space: level l (0 = finest) has cubic cells
 * of side cell(l) = c0 * 2^l, where c0 (metres) is the one scene-scale parameter; grid point g = (gx, gy,
 * gz) at level l is the cell [g, g + 1) * cell(l), and the cells of level l + 1 are exactly the unions of
 * 2 x 2 x 2 cells of level l. Cells appear when a viewer asks for them and disappear by eviction; they never
 * move with a camera. An effect stores its data in bricks of n x n x n cells: n = 1 (probes, one probe per
 * grid point) or n = 4 (volumetric data, 64 cells, bit c = (z * 4 + y) * 4 + x of a 64-bit brick mask).
 * A brick is named by a 64-bit world-grid index (WGI, below) and found through a hash table.
 *
 * Built on the on-surface cache's core. Each world-space effect gets one osc core instance (osc.h) of its
 * own, created as a single-pool cache (osc_desc.single_pool: the WGI uses all 64 bits, there is no effect
 * field) with one pool of block_texels 1 (n = 1) or 64 (n = 4). So the table, the pools, the free stacks,
 * the adaptive LRU eviction, the batch sort and merge, the statistics and the memory accounting are the
 * osc's own code, and two effects' tables are independent: the same WGI in two effects names two bricks.
 *
 * The frame, as seen from here (the osc's phase order, per effect):
 *   wsc_begin_frame(c, frame)     clears the requested masks of last frame's bricks
 *   wsc_request_batch             stage 3: map bricks (evicting old ones if a pool is empty), OR masks
 *   wsc_frame_bricks, accessors   stage 4-6: the bricks requested this frame, their masks and payload
 *   wsc_find, wsc_local_lookup    stage 6-7: read-only lookups (see Threads)
 *   wsc_housekeeping(c)           stage 9: adaptive LRU eviction so the next frame finds free bricks
 *
 * Threads. As in osc.h: wsc_find, the const accessors, the pure helpers (wsc_wgi_*, wsc_level,
 * wsc_grid_point, wsc_corners, wsc_brick_of) and wsc_local_lookup may run concurrently while nobody
 * writes to the cache; every other cache call is a writer and runs alone. wsc_local_lookup writes to its
 * own wsc_local only (its slots and counters): one thread per wsc_local at a time, any number of wsc_local
 * objects on as many threads. Requests gathered on several threads go to one wsc_request_batch call, which
 * sorts and merges them first, so the outcome does not depend on the thread interleaving. Refusals counted
 * by the threads are added with wsc_count_refusals on the writer thread.
 *
 * Memory. Everything is allocated in wsc_create() (and wsc_local_create()) through the optional counting
 * allocator and nothing afterwards. wsc_memory() and wsc_local_memory() report every byte. */
#ifndef FXC_WSC_H
#define FXC_WSC_H

#include "osc.h"

/* ---- the world-grid index (WGI) -------------------------------------------------------------------- */

/* Layout, high bits to low bits:   level:4 | y:18 | z:21 | x:21
 *   bits 63..60 level   0..14 (15 is reserved, see below)
 *   bits 59..42 y       vertical (scenes are y-up), stored as gy + 2^17: gy in [-2^17, 2^17 - 1]
 *   bits 41..21 z       horizontal, stored as gz + 2^20:                gz in [-2^20, 2^20 - 1]
 *   bits 20..0  x       horizontal, stored as gx + 2^20:                gx in [-2^20, 2^20 - 1]
 * Reach: at c0 = 0.25 m, level 0 spans +-262 km horizontally (2^20 cells of 0.25 m) and +-32.8 km
 * vertically (2^17 cells); level l reaches 2^l times further (level 14: +-4.3 million km horizontally).
 * Level 15 is reserved: no WGI has it, so UINT64_MAX (level 15, every coordinate all ones), the table's
 * empty marker, is never a valid WGI, and every stored coordinate value of levels 0..14 stays usable.
 * For bricks of n = 4 the coordinates are the brick's own, b = floor(g / 4) (the same ranges, of which
 * only a quarter is reachable): the brick's WGI names its first cell, grid point 4 * b (wsc_brick_first_cell). */
#define WSC_MAX_EFFECTS     16u
#define WSC_MAX_LEVEL       14u
#define WSC_RESERVED_LEVEL  15u
#define WSC_WGI_X_SHIFT     0
#define WSC_WGI_Z_SHIFT     21
#define WSC_WGI_Y_SHIFT     42
#define WSC_WGI_LEVEL_SHIFT 60
#define WSC_XZ_BITS         21
#define WSC_Y_BITS          18
#define WSC_XZ_OFFSET       (1 << 20) /* stored = g + offset */
#define WSC_Y_OFFSET        (1 << 17)
#define WSC_XZ_MIN          (-(1 << 20))
#define WSC_XZ_MAX          ((1 << 20) - 1)
#define WSC_Y_MIN           (-(1 << 17))
#define WSC_Y_MAX           ((1 << 17) - 1)
#define WSC_WGI_EMPTY       UINT64_MAX /* never a valid WGI (level 15) */
#define WSC_NONE            OSC_NONE   /* "no brick" */
#define WSC_FRAME_NEVER     OSC_FRAME_NEVER

/* WSC_ASSERT: programming errors only, on in every build type (as OSC_ASSERT). */
#define WSC_ASSERT(cond) OSC_ASSERT(cond)

/* Packs (level, gx, gy, gz) into *wgi. Returns false, leaving *wgi unchanged, when level > 14 or a
 * coordinate is outside its range above: out-of-range coordinates are refused, never wrapped. */
bool wsc_wgi_pack(uint32_t level, int32_t gx, int32_t gy, int32_t gz, uint64_t *wgi);

/* Unpacks a WGI. Returns false (outputs unchanged) for a level-15 value (e.g. WSC_WGI_EMPTY); every other
 * 64-bit value unpacks. Any of the output pointers may be NULL. */
bool wsc_wgi_unpack(uint64_t wgi, uint32_t *level, int32_t *gx, int32_t *gy, int32_t *gz);

/* The level field of a WGI (no check). */
static inline uint32_t wsc_wgi_level(uint64_t wgi)
{
    return (uint32_t)(wgi >> WSC_WGI_LEVEL_SHIFT);
}

/* ---- levels and grid points ------------------------------------------------------------------------- */

/* The level for a cell at `distance` metres from the viewer, with c0 the level-0 cell size in metres:
 *   level = max(0, ceil(log2(distance / (16 * c0)))), clamped to WSC_MAX_LEVEL.
 * So level 0 is used within 16 level-0 cells of the camera, and at level l >= 1 the distance is 8..16
 * cells of that level: cells are about distance/16 .. distance/8 wide. Never decreases with distance
 * (computed exactly from the binary exponent, no log2 rounding); NaN, negative and zero distances give 0,
 * +inf gives WSC_MAX_LEVEL. Precondition: c0 finite and > 0. */
uint32_t wsc_level(double distance, double c0);

/* The cell size of `level`, metres: c0 * 2^level (exact). */
static inline double wsc_cell_size(uint32_t level, double c0)
{
    return ldexp(c0, (int)level);
}

/* The grid point of the cell holding a WORLD position (double: scene-local position + the scene's origin,
 * so the grid stays fixed in world space whatever the scene's local frame): g = floor(world / cell(level)).
 * Returns false (g unchanged) when a coordinate is not finite or g is outside the WGI's range; callers
 * count those refusals (wsc_count_refusals). Depends on nothing but its arguments (no camera).
 * Precondition: level <= WSC_MAX_LEVEL, c0 finite and > 0. */
bool wsc_grid_point(const double world[3], uint32_t level, double c0, int32_t g[3]);

/* Trilinear interpolation support: the 8 corner grid points of the cell holding `world` at `level` and
 * their weights. Corner i (0..7) is g + (i & 1, (i >> 1) & 1, (i >> 2) & 1) with g = wsc_grid_point();
 * weights are the products of (1 - t) or t per axis, t = world / cell - g in [0, 1), so they sum to 1 and
 * interpolate linear functions exactly (corner 0 takes weight 1 at a grid point). Returns false (outputs
 * unchanged) when wsc_grid_point refuses or when a corner (g + 1) would be outside the range. */
bool wsc_corners(const double world[3], uint32_t level, double c0, int32_t corners[8][3], float weights[8]);

/* ---- bricks ---------------------------------------------------------------------------------------- */

/* The brick holding grid point g at `level`, for bricks of brick_size n (1 or 4), and the cell's bit in a
 * brick mask: n = 1: the WGI of g, bit 1 (bit 0); n = 4: the WGI of b = floor(g / 4) (per axis, also for
 * negative g) and bit 1 << ((lz * 4 + ly) * 4 + lx) with l = g - 4 * b in 0..3. Returns false (outputs
 * unchanged) when g is out of range or level > WSC_MAX_LEVEL. */
bool wsc_brick_of(const int32_t g[3], uint32_t level, uint32_t brick_size, uint64_t *wgi, uint64_t *bit);

/* The grid point of a brick's first (lowest) cell and its level: 4 * b for n = 4, the WGI's own point
 * for n = 1. Cell c of the brick (bit c) is first + (c % n, (c / n) % n, c / (n * n)). False for a
 * level-15 WGI. */
bool wsc_brick_first_cell(uint64_t wgi, uint32_t brick_size, uint32_t *level, int32_t first[3]);

/* ---- creation ---------------------------------------------------------------------------------------- */

/* One world-space effect. All-zero: absent (nothing allocated). */
typedef struct wsc_effect_desc {
    uint32_t cell_bytes; /* payload bytes per cell, 1..1024 (0 = effect absent) */
    uint32_t brick_size; /* cells per brick side: 1 (probes) or 4 (volumetric; 64 cells) (default 1) */
    uint32_t max_bricks; /* pool capacity in bricks (default 65536) */
    bool convergence;    /* keep one uint32 convergence word per brick (default false) */
} wsc_effect_desc;

/* The cache's configuration; zero fields take the defaults written beside them. Table capacity, load and
 * ageing apply to every effect's core (see osc_desc for their meaning and defaults). */
typedef struct wsc_desc {
    wsc_effect_desc effects[WSC_MAX_EFFECTS]; /* indexed by world-space effect index 0..15 */
    uint32_t max_load_percent;                /* 10..95 (default 75) */
    uint32_t initial_age_frames;              /* frames (default 64) */
    uint32_t max_age_frames;                  /* frames (default 1024) */
    osc_allocator allocator;                  /* default: malloc / free; every allocation goes through it */
} wsc_desc;

typedef struct wsc_cache wsc_cache;

/* Creates the cache: one osc core per present effect (table at 150 % of its bricks, pool, lists), all
 * allocated now. On failure returns OSC_ERR_INVALID_DESC or OSC_ERR_OUT_OF_MEMORY, *out_cache = NULL and,
 * when error_text is not NULL, a message naming the field at fault. */
osc_result wsc_create(const wsc_desc *desc, wsc_cache **out_cache, char *error_text, size_t error_text_cap);

/* Frees everything (NULL allowed). */
void wsc_destroy(wsc_cache *cache);

/* ---- the frame ---------------------------------------------------------------------------------------- */

/* Starts frame `frame` for every effect (osc_begin_frame's precondition: increasing frame numbers). */
void wsc_begin_frame(wsc_cache *cache, uint32_t frame);

/* Requests cells of bricks of one effect, as osc_request_batch: sorts wgis[] in place (masks[] moving
 * along), merges duplicates (OR of masks), maps the unique WGIs in ascending order; wgis[0..*unique_count)
 * are then the unique WGIs and bricks[i] (room for `count`, or NULL) the brick of wgis[i] or WSC_NONE.
 * Masks: bit 0 only for brick_size 1, any of 64 bits for brick_size 4 (wsc_brick_of gives them).
 * Preconditions (asserted): the effect is present, every WGI has a level <= 14. Returns OSC_OK, or the
 * first failure in WGI order (OSC_ERR_POOL_EXHAUSTED, OSC_ERR_TABLE_FULL), counted in the stats. */
osc_result wsc_request_batch(wsc_cache *cache, uint32_t effect, uint64_t *wgis, uint64_t *masks, size_t count,
                             size_t *unique_count, uint32_t *bricks);

/* Adds `count` refused positions (wsc_grid_point / wsc_corners / wsc_brick_of returned false) to the
 * effect's refusal counter: callers count on their threads and add here on the writer thread. */
void wsc_count_refusals(wsc_cache *cache, uint32_t effect, uint64_t count);

/* The brick of a WGI, or WSC_NONE (absent effect, level-15 value or not resident). Read-only, not counted. */
uint32_t wsc_find(const wsc_cache *cache, uint32_t effect, uint64_t wgi);

/* The 8 corners of the cell whose lowest corner is grid point g at `level`, for an effect of brick size 1:
 * payload[c] is the brick of corner g + (c & 1, c >> 1 & 1, c >> 2 & 1) when it is resident and its cell
 * holds data (valid bit 0), else NULL; the same as wsc_brick_of, wsc_find, wsc_brick_valid and
 * wsc_brick_payload per corner, with the 8 WGIs from one pack and one batched lookup. False (all NULL) when
 * the effect is absent or not of brick size 1, or a corner is out of range. Read-only, not counted. */
bool wsc_cell_corners(const wsc_cache *cache, uint32_t effect, uint32_t level, const int32_t g[3],
                      const void *payload[8]);

/* Stage 9: adaptive LRU eviction of every effect's pool (osc_housekeeping). */
void wsc_housekeeping(wsc_cache *cache);

/* ---- bricks ------------------------------------------------------------------------------------------- */

/* The bricks of `effect` requested this frame, in first-request order; the array is owned by the cache
 * and valid until the next request or frame. An absent effect gives count 0. */
const uint32_t *wsc_frame_bricks(wsc_cache *cache, uint32_t effect, uint32_t *count);

/* Per-brick accessors. Precondition (asserted): the effect is present and brick < its max_bricks. */
uint64_t wsc_brick_key(const wsc_cache *cache, uint32_t effect, uint32_t brick); /* WGI, EMPTY if free */
uint64_t wsc_brick_requested(const wsc_cache *cache, uint32_t effect, uint32_t brick); /* cells, this frame */
uint64_t wsc_brick_valid(const wsc_cache *cache, uint32_t effect, uint32_t brick);     /* cells with data */
uint32_t wsc_brick_last_frame(const wsc_cache *cache, uint32_t effect, uint32_t brick); /* or NEVER */
void wsc_brick_set_valid(wsc_cache *cache, uint32_t effect, uint32_t brick, uint64_t valid_mask);

/* The brick's payload: brick_size^3 cells of cell_bytes, cell c (bit c) at byte c * cell_bytes. Zeroed
 * when the brick is mapped; owned by the cache. */
void *wsc_brick_payload(wsc_cache *cache, uint32_t effect, uint32_t brick);

/* The brick's convergence word (zeroed when mapped), or NULL when the effect keeps none. */
uint32_t *wsc_brick_convergence(wsc_cache *cache, uint32_t effect, uint32_t brick);

/* Shape of an effect (all 0 when absent): brick side, bytes per cell, payload bytes per brick
 * (brick_size^3 * cell_bytes), pool capacity in bricks. */
uint32_t wsc_brick_size(const wsc_cache *cache, uint32_t effect);
uint32_t wsc_cell_bytes(const wsc_cache *cache, uint32_t effect);
uint32_t wsc_brick_bytes(const wsc_cache *cache, uint32_t effect);
uint32_t wsc_capacity(const wsc_cache *cache, uint32_t effect);

/* ---- statistics and memory ------------------------------------------------------------------------------ */

/* Per-effect figures (cumulative since creation unless said otherwise). */
typedef struct wsc_effect_stats {
    uint32_t brick_size;      /* 0: effect absent (every other field 0) */
    uint32_t entries;         /* WGIs in the effect's table now */
    uint32_t table_capacity;  /* slots */
    float table_load;         /* entries / table_capacity */
    uint32_t bricks_resident; /* now (equals entries) */
    uint32_t bricks_peak;
    uint32_t bricks_this_frame; /* bricks requested in the current frame */
    size_t bytes;               /* every byte allocated for the effect (its osc core), as wsc_memory */
    uint64_t requests;          /* unique WGIs requested (batches merge duplicates first) */
    uint64_t refusals;          /* positions refused as out of range (wsc_count_refusals) */
    uint64_t inserts;           /* bricks mapped */
    uint64_t evictions;         /* bricks evicted (housekeeping and immediate) */
    uint64_t exhausted;         /* requests failed: every brick requested this frame */
    uint64_t table_full;        /* requests failed: table at maximum load */
} wsc_effect_stats;

typedef struct wsc_stats {
    uint32_t frame;
    uint64_t refusals; /* sum over effects */
    wsc_effect_stats effects[WSC_MAX_EFFECTS];
} wsc_stats;

/* Fills *out. */
void wsc_stats_get(const wsc_cache *cache, wsc_stats *out);

/* Every byte the cache allocated: the wsc object itself plus each effect's osc core by structure (table
 * keys and values, brick metadata, payload reserved and in use, lists; see osc_memory_report, where
 * cache_struct_bytes is the core object). total_bytes equals the bytes that went through the allocator. */
typedef struct wsc_memory_report {
    size_t cache_struct_bytes; /* the wsc_cache object */
    size_t table_key_bytes;    /* sums over effects */
    size_t table_value_bytes;
    size_t block_meta_bytes;
    size_t payload_reserved_bytes;
    size_t payload_in_use_bytes; /* part of payload_reserved_bytes */
    size_t list_bytes;
    size_t core_struct_bytes; /* the osc core objects */
    size_t total_bytes;
    osc_memory_report effects[WSC_MAX_EFFECTS]; /* per effect; its total_bytes is the effect's all */
} wsc_memory_report;

/* Fills *out. */
void wsc_memory(const wsc_cache *cache, wsc_memory_report *out);

/* ---- the per-viewer local lookup table (paper section 3.2.2) --------------------------------------------- */

/* Neighbouring pixels of one viewer look up the same few WGIs again and again (the 8 probes around each
 * shading point). A wsc_local keeps, per effect and per level, a dense side^3 array of slots addressed
 * toroidally by the WGI's coordinates modulo side (stored coordinates; the offsets are multiples of any
 * side, so this is the signed coordinate modulo side): the side^3 block of WGIs around the camera maps to
 * distinct slots, and as the camera moves, slots are simply overwritten by the WGIs now around it. No
 * camera position is needed. Each slot holds a WGI and its brick. A lookup hashes only on a miss.
 *
 * It always agrees with the table: a slot's brick is returned only when the slot's WGI is the one asked
 * for AND the pool's key array still holds that WGI for that brick (one O(1) read). Pool keys are set when
 * a brick is mapped and cleared when it is evicted or removed, and the table maps a WGI to at most one
 * brick, so an evicted or re-mapped brick can never be returned for the old WGI. Negative results (not
 * resident) are not kept: they could turn positive without the slot noticing. */
typedef struct wsc_local_desc {
    uint32_t side;   /* slots per axis per level, a power of two 2..64 (default 16: 4096 slots) */
    uint32_t levels; /* levels 0..levels-1 get slots; coarser WGIs go to the table directly, counted as
                         bypasses (1..15, default 15: every level) */
    osc_allocator allocator; /* default: malloc / free */
} wsc_local_desc;

typedef struct wsc_local wsc_local;

/* Counters of one local table (cumulative). hit rate = hits / (hits + misses + bypasses). */
typedef struct wsc_local_stats {
    uint64_t hits;     /* answered from a slot, no hashing */
    uint64_t misses;   /* went to the table (slot empty, another WGI, or stale) */
    uint64_t stale;    /* of the misses: the slot held the WGI but its brick no longer did (evicted or
                          re-mapped since); the check that keeps the table honest */
    uint64_t bypasses; /* level >= levels: straight to the table */
    size_t bytes;      /* allocated for this local table (slots and the object) */
} wsc_local_stats;

/* Creates a local table for `cache`: slots for every effect present in the cache, levels x side^3 each
 * (12 bytes per slot: WGI and brick), all allocated now; desc may be NULL (defaults). Returns OSC_OK,
 * OSC_ERR_INVALID_DESC or OSC_ERR_OUT_OF_MEMORY (*out_local NULL). The local table is tied to this cache
 * and must be destroyed before it. */
osc_result wsc_local_create(const wsc_local_desc *desc, const wsc_cache *cache, wsc_local **out_local,
                            char *error_text, size_t error_text_cap);

/* Frees it (NULL allowed). */
void wsc_local_destroy(wsc_local *local);

/* The brick of `wgi` in `effect`, or WSC_NONE: exactly what wsc_find(cache, effect, wgi) returns, from a
 * slot when it can, else from the table (then the slot is filled). Writes only to `local`: one thread per
 * local table, concurrently with other readers of the cache, never with a writer. */
uint32_t wsc_local_lookup(wsc_local *local, const wsc_cache *cache, uint32_t effect, uint64_t wgi);

/* Forgets every slot (e.g. after the viewer jumps far; never needed for correctness). */
void wsc_local_clear(wsc_local *local);

/* Fills *out. */
void wsc_local_stats_get(const wsc_local *local, wsc_local_stats *out);

#endif
