/* wsc.c: the world-space cache: WGIs, levels and grid points (pure functions), one osc core per world-space
 * effect (creation, the frame, bricks, statistics, memory) and the per-viewer local lookup table. See
 * wsc.h for the API, the WGI layout and the thread rules; osc.c for the table, pools and eviction this
 * file reuses unchanged (each core is a single-pool osc cache whose pool 0 is the effect's brick pool). */
#include "osc_internal.h"
#include "wsc.h"

#include <stdarg.h>
#include <string.h>

#define WSC__MAX_CELL_BYTES 1024u
#define WSC__MAX_BRICKS     (1u << 30)
#define WSC__XZ_MASK        ((1u << WSC_XZ_BITS) - 1u)
#define WSC__Y_MASK         ((1u << WSC_Y_BITS) - 1u)

/* ---- WGIs ------------------------------------------------------------------------------------------------ */

/* Packs a WGI; refuses (never wraps) anything out of range. */
bool wsc_wgi_pack(uint32_t level, int32_t gx, int32_t gy, int32_t gz, uint64_t *wgi)
{
    if (level > WSC_MAX_LEVEL || gx < WSC_XZ_MIN || gx > WSC_XZ_MAX || gz < WSC_XZ_MIN || gz > WSC_XZ_MAX ||
        gy < WSC_Y_MIN || gy > WSC_Y_MAX)
        return false;
    /* The offsets make every coordinate non-negative, so the stored fields are plain unsigned bits. */
    uint64_t x = (uint64_t)(gx + WSC_XZ_OFFSET), z = (uint64_t)(gz + WSC_XZ_OFFSET);
    uint64_t y = (uint64_t)(gy + WSC_Y_OFFSET);
    *wgi = ((uint64_t)level << WSC_WGI_LEVEL_SHIFT) | (y << WSC_WGI_Y_SHIFT) | (z << WSC_WGI_Z_SHIFT) |
           (x << WSC_WGI_X_SHIFT);
    return true;
}

/* Unpacks a WGI; false for the reserved level 15. */
bool wsc_wgi_unpack(uint64_t wgi, uint32_t *level, int32_t *gx, int32_t *gy, int32_t *gz)
{
    if (wsc_wgi_level(wgi) > WSC_MAX_LEVEL)
        return false;
    if (level)
        *level = wsc_wgi_level(wgi);
    if (gx)
        *gx = (int32_t)((wgi >> WSC_WGI_X_SHIFT) & WSC__XZ_MASK) - WSC_XZ_OFFSET;
    if (gz)
        *gz = (int32_t)((wgi >> WSC_WGI_Z_SHIFT) & WSC__XZ_MASK) - WSC_XZ_OFFSET;
    if (gy)
        *gy = (int32_t)((wgi >> WSC_WGI_Y_SHIFT) & WSC__Y_MASK) - WSC_Y_OFFSET;
    return true;
}

/* ---- levels and grid points ------------------------------------------------------------------------------ */

/* level = max(0, ceil(log2(distance / (16 c0)))), from the binary exponent so it is exact and monotone:
 * with ratio = m * 2^e, m in [0.5, 1), ceil(log2(ratio)) is e - 1 when m == 0.5 (a power of two), else e.
 * Division by the positive constant 16 c0 is monotone under rounding, so the level never decreases. */
uint32_t wsc_level(double distance, double c0)
{
    WSC_ASSERT(isfinite(c0) && c0 > 0.0);
    double ratio = distance / (16.0 * c0);
    if (!(ratio > 1.0)) /* also NaN and negative */
        return 0;
    if (isinf(ratio))
        return WSC_MAX_LEVEL;
    int exponent;
    double mantissa = frexp(ratio, &exponent);
    int level = mantissa == 0.5 ? exponent - 1 : exponent;
    return level > (int)WSC_MAX_LEVEL ? WSC_MAX_LEVEL : (uint32_t)level;
}

/* floor(world / cell) per axis, refused when not finite or out of range. The double comparison happens
 * before the conversion to int32, so the conversion is always defined. */
bool wsc_grid_point(const double world[3], uint32_t level, double c0, int32_t g[3])
{
    WSC_ASSERT(level <= WSC_MAX_LEVEL && isfinite(c0) && c0 > 0.0);
    double cell = wsc_cell_size(level, c0);
    double q[3];
    for (int axis = 0; axis < 3; axis++) {
        q[axis] = floor(world[axis] / cell);
        double lo = axis == 1 ? WSC_Y_MIN : WSC_XZ_MIN, hi = axis == 1 ? WSC_Y_MAX : WSC_XZ_MAX;
        if (!(q[axis] >= lo && q[axis] <= hi)) /* also NaN and inf */
            return false;
    }
    for (int axis = 0; axis < 3; axis++)
        g[axis] = (int32_t)q[axis];
    return true;
}

/* The 8 corners of the cell holding `world` and their trilinear weights (see wsc.h). */
bool wsc_corners(const double world[3], uint32_t level, double c0, int32_t corners[8][3], float weights[8])
{
    int32_t g[3];
    if (!wsc_grid_point(world, level, c0, g))
        return false;
    if (g[0] >= WSC_XZ_MAX || g[2] >= WSC_XZ_MAX || g[1] >= WSC_Y_MAX)
        return false; /* the far corner g + 1 would leave the range */
    double cell = wsc_cell_size(level, c0);
    double t[3];
    for (int axis = 0; axis < 3; axis++) {
        t[axis] = world[axis] / cell - (double)g[axis];
        /* world / cell was floored to g, so t is in [0, 1); the clamp guards the last ulp only. */
        t[axis] = t[axis] < 0.0 ? 0.0 : (t[axis] > 1.0 ? 1.0 : t[axis]);
    }
    for (int corner = 0; corner < 8; corner++) {
        double weight = 1.0;
        for (int axis = 0; axis < 3; axis++) {
            int step = (corner >> axis) & 1;
            corners[corner][axis] = g[axis] + step;
            weight *= step ? t[axis] : 1.0 - t[axis];
        }
        weights[corner] = (float)weight;
    }
    return true;
}

/* ---- bricks ------------------------------------------------------------------------------------------------ */

/* floor(value / 4) without relying on the implementation-defined right shift of negative values. */
static int32_t wsc__floor_div4(int32_t value)
{
    return value >= 0 ? value / 4 : -((-value + 3) / 4);
}

/* The brick of a grid point and the cell's bit in its mask. */
bool wsc_brick_of(const int32_t g[3], uint32_t level, uint32_t brick_size, uint64_t *wgi, uint64_t *bit)
{
    WSC_ASSERT(brick_size == 1 || brick_size == 4);
    if (brick_size == 1) {
        if (!wsc_wgi_pack(level, g[0], g[1], g[2], wgi))
            return false;
        *bit = 1;
        return true;
    }
    /* Range first: the brick coordinates of an out-of-range point could still pack. */
    if (g[0] < WSC_XZ_MIN || g[0] > WSC_XZ_MAX || g[2] < WSC_XZ_MIN || g[2] > WSC_XZ_MAX ||
        g[1] < WSC_Y_MIN || g[1] > WSC_Y_MAX)
        return false;
    int32_t b[3];
    uint32_t local[3];
    for (int axis = 0; axis < 3; axis++) {
        b[axis] = wsc__floor_div4(g[axis]);
        local[axis] = (uint32_t)(g[axis] - 4 * b[axis]);
    }
    if (!wsc_wgi_pack(level, b[0], b[1], b[2], wgi))
        return false;
    *bit = (uint64_t)1 << ((local[2] * 4u + local[1]) * 4u + local[0]);
    return true;
}

/* The first cell of a brick. */
bool wsc_brick_first_cell(uint64_t wgi, uint32_t brick_size, uint32_t *level, int32_t first[3])
{
    WSC_ASSERT(brick_size == 1 || brick_size == 4);
    int32_t b[3];
    if (!wsc_wgi_unpack(wgi, level, &b[0], &b[1], &b[2]))
        return false;
    for (int axis = 0; axis < 3; axis++)
        first[axis] = b[axis] * (int32_t)brick_size;
    return true;
}

/* ---- the cache ------------------------------------------------------------------------------------------- */

struct wsc_cache {
    osc_allocator allocator;
    osc_cache *cores[WSC_MAX_EFFECTS];        /* NULL: effect absent */
    wsc_effect_desc effects[WSC_MAX_EFFECTS]; /* resolved */
    uint64_t refusals[WSC_MAX_EFFECTS];
    uint32_t frame;
};

static void *wsc__default_alloc(size_t size, void *user)
{
    (void)user;
    return malloc(size);
}

static void wsc__default_free(void *pointer, size_t size, void *user)
{
    (void)size;
    (void)user;
    free(pointer);
}

#if defined(__GNUC__) || defined(__clang__)
__attribute__((format(printf, 4, 5)))
#endif
static osc_result
wsc__fail(osc_result result, char *error_text, size_t error_text_cap, const char *format, ...)
{
    if (error_text && error_text_cap > 0) {
        va_list arguments;
        va_start(arguments, format);
        vsnprintf(error_text, error_text_cap, format, arguments);
        va_end(arguments);
    }
    return result;
}

/* Resolves an allocator: both callbacks or neither (then malloc / free). */
static bool wsc__resolve_allocator(const osc_allocator *in, osc_allocator *out)
{
    if (!in->alloc != !in->free)
        return false;
    *out = *in;
    if (!out->alloc) {
        out->alloc = wsc__default_alloc;
        out->free = wsc__default_free;
    }
    return true;
}

/* Validates the description and resolves the effects' defaults (the one place they live). */
static osc_result wsc__resolve_desc(const wsc_desc *desc, wsc_desc *resolved, char *error_text, size_t cap)
{
    *resolved = *desc;
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++) {
        wsc_effect_desc *fx = &resolved->effects[effect];
        if (fx->cell_bytes == 0) {
            if (fx->brick_size != 0 || fx->max_bricks != 0 || fx->convergence)
                return wsc__fail(OSC_ERR_INVALID_DESC, error_text, cap,
                                 "effects[%u]: brick_size, max_bricks or convergence set but cell_bytes is 0",
                                 effect);
            continue;
        }
        if (fx->cell_bytes > WSC__MAX_CELL_BYTES)
            return wsc__fail(OSC_ERR_INVALID_DESC, error_text, cap, "effects[%u].cell_bytes %u exceeds 1024",
                             effect, fx->cell_bytes);
        if (fx->brick_size == 0)
            fx->brick_size = 1;
        if (fx->brick_size != 1 && fx->brick_size != 4)
            return wsc__fail(OSC_ERR_INVALID_DESC, error_text, cap,
                             "effects[%u].brick_size %u is neither 1 nor 4", effect, fx->brick_size);
        if (fx->max_bricks > WSC__MAX_BRICKS)
            return wsc__fail(OSC_ERR_INVALID_DESC, error_text, cap, "effects[%u].max_bricks %u exceeds 2^30",
                             effect, fx->max_bricks);
    }
    if (!wsc__resolve_allocator(&desc->allocator, &resolved->allocator))
        return wsc__fail(OSC_ERR_INVALID_DESC, error_text, cap,
                         "allocator: set both alloc and free, or neither");
    return OSC_OK;
}

/* Creates the cache and one single-pool osc core per present effect. */
osc_result wsc_create(const wsc_desc *desc, wsc_cache **out_cache, char *error_text, size_t error_text_cap)
{
    WSC_ASSERT(desc != NULL && out_cache != NULL);
    *out_cache = NULL;
    if (error_text && error_text_cap > 0)
        error_text[0] = '\0';
    wsc_desc resolved;
    osc_result result = wsc__resolve_desc(desc, &resolved, error_text, error_text_cap);
    if (result != OSC_OK)
        return result;
    wsc_cache *cache = resolved.allocator.alloc(sizeof *cache, resolved.allocator.user);
    if (!cache)
        return wsc__fail(OSC_ERR_OUT_OF_MEMORY, error_text, error_text_cap,
                         "out of memory allocating the world-space cache (%zu bytes)", sizeof *cache);
    memset(cache, 0, sizeof *cache);
    cache->allocator = resolved.allocator;
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++) {
        const wsc_effect_desc *fx = &resolved.effects[effect];
        cache->effects[effect] = *fx;
        if (fx->cell_bytes == 0)
            continue;
        osc_desc core = {0};
        core.single_pool = true; /* the WGI uses all 64 bits */
        core.effects[0].texel_bytes = fx->cell_bytes;
        core.effects[0].max_blocks = fx->max_bricks;
        core.effects[0].convergence = fx->convergence;
        core.effects[0].block_texels = fx->brick_size * fx->brick_size * fx->brick_size; /* 1 or 64 */
        core.max_load_percent = resolved.max_load_percent;
        core.initial_age_frames = resolved.initial_age_frames;
        core.max_age_frames = resolved.max_age_frames;
        core.allocator = resolved.allocator;
        char core_error[160];
        result = osc_create(&core, &cache->cores[effect], core_error, sizeof core_error);
        if (result != OSC_OK) {
            wsc_destroy(cache);
            return wsc__fail(result, error_text, error_text_cap, "effects[%u]: %s", effect, core_error);
        }
    }
    *out_cache = cache;
    return OSC_OK;
}

/* Frees the cores, then the object. */
void wsc_destroy(wsc_cache *cache)
{
    if (!cache)
        return;
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++)
        osc_destroy(cache->cores[effect]);
    osc_allocator allocator = cache->allocator;
    allocator.free(cache, sizeof *cache, allocator.user);
}

/* The core of a present effect (asserted). */
static osc_cache *wsc__core(const wsc_cache *cache, uint32_t effect)
{
    WSC_ASSERT(effect < WSC_MAX_EFFECTS && cache->cores[effect] != NULL);
    return cache->cores[effect];
}

/* ---- the frame ------------------------------------------------------------------------------------------- */

/* Starts a frame in every core. */
void wsc_begin_frame(wsc_cache *cache, uint32_t frame)
{
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++) {
        if (cache->cores[effect])
            osc_begin_frame(cache->cores[effect], frame);
    }
    cache->frame = frame;
}

/* Sorted, merged batch of one effect (osc_request_batch on its core). */
osc_result wsc_request_batch(wsc_cache *cache, uint32_t effect, uint64_t *wgis, uint64_t *masks, size_t count,
                             size_t *unique_count, uint32_t *bricks)
{
    osc_cache *core = wsc__core(cache, effect);
    /* Programming errors the core cannot see: a level-15 key other than the empty marker would be stored
     * as if valid, and a 1 x 1 x 1 brick has one cell (bit 0). */
    uint64_t allowed = cache->effects[effect].brick_size == 1 ? 1u : UINT64_MAX;
    for (size_t i = 0; i < count; i++)
        WSC_ASSERT(wsc_wgi_level(wgis[i]) <= WSC_MAX_LEVEL && (masks[i] & ~allowed) == 0);
    return osc_request_batch(core, wgis, masks, count, unique_count, bricks);
}

/* Adds refused positions to the effect's counter. */
void wsc_count_refusals(wsc_cache *cache, uint32_t effect, uint64_t count)
{
    WSC_ASSERT(effect < WSC_MAX_EFFECTS);
    cache->refusals[effect] += count;
}

/* Read-only lookup. */
uint32_t wsc_find(const wsc_cache *cache, uint32_t effect, uint64_t wgi)
{
    WSC_ASSERT(effect < WSC_MAX_EFFECTS);
    if (!cache->cores[effect] || wsc_wgi_level(wgi) > WSC_MAX_LEVEL)
        return WSC_NONE;
    return osc_find(cache->cores[effect], wgi);
}

/* A cell's 8 corners in one batched lookup (wsc.h). */
bool wsc_cell_corners(const wsc_cache *cache, uint32_t effect, uint32_t level, const int32_t g[3],
                      const void *payload[8])
{
    for (int c = 0; c < 8; c++)
        payload[c] = NULL;
    uint64_t base;
    if (effect >= WSC_MAX_EFFECTS || !cache->cores[effect] || cache->effects[effect].brick_size != 1 ||
        g[0] >= WSC_XZ_MAX || g[2] >= WSC_XZ_MAX || g[1] >= WSC_Y_MAX ||
        !wsc_wgi_pack(level, g[0], g[1], g[2], &base))
        return false;
    /* g + 1 stays in range on every axis, so each field of base has room for the + 1 (no carry). */
    const uint64_t dx = (uint64_t)1 << WSC_WGI_X_SHIFT, dy = (uint64_t)1 << WSC_WGI_Y_SHIFT,
                   dz = (uint64_t)1 << WSC_WGI_Z_SHIFT;
    uint64_t valid[8], keys[8] = {base,      base + dx,      base + dy,      base + dx + dy,
                                  base + dz, base + dx + dz, base + dy + dz, base + dx + dy + dz};
    osc_find_payloads(cache->cores[effect], 0, keys, 8, valid, payload);
    for (int c = 0; c < 8; c++)
        payload[c] = (valid[c] & 1) ? payload[c] : NULL;
    return true;
}

/* Eviction in every core. */
void wsc_housekeeping(wsc_cache *cache)
{
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++) {
        if (cache->cores[effect])
            osc_housekeeping(cache->cores[effect]);
    }
}

/* ---- bricks ------------------------------------------------------------------------------------------------ */

/* This frame's bricks of one effect. */
const uint32_t *wsc_frame_bricks(wsc_cache *cache, uint32_t effect, uint32_t *count)
{
    WSC_ASSERT(effect < WSC_MAX_EFFECTS);
    if (!cache->cores[effect]) {
        *count = 0;
        return NULL;
    }
    return osc_frame_blocks(cache->cores[effect], 0, count);
}

uint64_t wsc_brick_key(const wsc_cache *cache, uint32_t effect, uint32_t brick)
{
    return osc_block_key(wsc__core(cache, effect), 0, brick);
}

uint64_t wsc_brick_requested(const wsc_cache *cache, uint32_t effect, uint32_t brick)
{
    return osc_block_requested(wsc__core(cache, effect), 0, brick);
}

uint64_t wsc_brick_valid(const wsc_cache *cache, uint32_t effect, uint32_t brick)
{
    return osc_block_valid(wsc__core(cache, effect), 0, brick);
}

uint32_t wsc_brick_last_frame(const wsc_cache *cache, uint32_t effect, uint32_t brick)
{
    return osc_block_last_frame(wsc__core(cache, effect), 0, brick);
}

void wsc_brick_set_valid(wsc_cache *cache, uint32_t effect, uint32_t brick, uint64_t valid_mask)
{
    osc_block_set_valid(wsc__core(cache, effect), 0, brick, valid_mask);
}

void *wsc_brick_payload(wsc_cache *cache, uint32_t effect, uint32_t brick)
{
    return osc_block_payload(wsc__core(cache, effect), 0, brick);
}

uint32_t *wsc_brick_convergence(wsc_cache *cache, uint32_t effect, uint32_t brick)
{
    return osc_block_convergence(wsc__core(cache, effect), 0, brick);
}

uint32_t wsc_brick_size(const wsc_cache *cache, uint32_t effect)
{
    WSC_ASSERT(effect < WSC_MAX_EFFECTS);
    return cache->cores[effect] ? cache->effects[effect].brick_size : 0;
}

uint32_t wsc_cell_bytes(const wsc_cache *cache, uint32_t effect)
{
    WSC_ASSERT(effect < WSC_MAX_EFFECTS);
    return cache->effects[effect].cell_bytes;
}

uint32_t wsc_brick_bytes(const wsc_cache *cache, uint32_t effect)
{
    WSC_ASSERT(effect < WSC_MAX_EFFECTS);
    return cache->cores[effect] ? cache->cores[effect]->pools[0].block_bytes : 0;
}

uint32_t wsc_capacity(const wsc_cache *cache, uint32_t effect)
{
    WSC_ASSERT(effect < WSC_MAX_EFFECTS);
    return cache->cores[effect] ? osc_pool_capacity(cache->cores[effect], 0) : 0;
}

/* ---- statistics and memory ------------------------------------------------------------------------------ */

/* Per-effect figures from each core's own statistics and memory report. */
void wsc_stats_get(const wsc_cache *cache, wsc_stats *out)
{
    memset(out, 0, sizeof *out);
    out->frame = cache->frame;
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++) {
        out->refusals += cache->refusals[effect];
        const osc_cache *core = cache->cores[effect];
        wsc_effect_stats *fx = &out->effects[effect];
        fx->refusals = cache->refusals[effect];
        if (!core)
            continue;
        osc_stats core_stats;
        osc_stats_get(core, &core_stats);
        osc_memory_report memory;
        osc_memory(core, &memory);
        const osc_effect_stats *pool = &core_stats.effects[0];
        fx->brick_size = cache->effects[effect].brick_size;
        fx->entries = core_stats.table_count;
        fx->table_capacity = core_stats.table_capacity;
        fx->table_load = (float)core_stats.table_count / (float)core_stats.table_capacity;
        fx->bricks_resident = pool->blocks_resident;
        fx->bricks_peak = pool->blocks_peak;
        fx->bricks_this_frame = pool->blocks_this_frame;
        fx->bytes = memory.total_bytes;
        fx->requests = pool->requests;
        fx->inserts = pool->inserts;
        fx->evictions = pool->evictions;
        fx->exhausted = pool->exhausted;
        fx->table_full = core_stats.table_full;
    }
}

/* The wsc object plus every core's report. */
void wsc_memory(const wsc_cache *cache, wsc_memory_report *out)
{
    memset(out, 0, sizeof *out);
    out->cache_struct_bytes = sizeof *cache;
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++) {
        if (!cache->cores[effect])
            continue;
        osc_memory_report *core = &out->effects[effect];
        osc_memory(cache->cores[effect], core);
        out->table_key_bytes += core->table_key_bytes;
        out->table_value_bytes += core->table_value_bytes;
        out->block_meta_bytes += core->block_meta_bytes;
        out->payload_reserved_bytes += core->payload_reserved_bytes;
        out->payload_in_use_bytes += core->payload_in_use_bytes;
        out->list_bytes += core->list_bytes;
        out->core_struct_bytes += core->cache_struct_bytes;
    }
    out->total_bytes = out->cache_struct_bytes + out->core_struct_bytes + out->table_key_bytes +
                       out->table_value_bytes + out->block_meta_bytes + out->payload_reserved_bytes +
                       out->list_bytes;
}

/* ---- the local lookup table ------------------------------------------------------------------------------ */

#define WSC__LOCAL_DEFAULT_SIDE 16u
#define WSC__LOCAL_MAX_SIDE     64u /* divides both coordinate offsets, so stored & mask is the signed modulo */

struct wsc_local {
    osc_allocator allocator;
    const wsc_cache *cache;
    uint32_t side, side_mask, levels;
    size_t slots_per_effect;                    /* levels * side^3 */
    uint64_t *slot_wgis[WSC_MAX_EFFECTS];       /* [slots_per_effect], WSC_WGI_EMPTY = unused; NULL: absent */
    uint32_t *slot_bricks[WSC_MAX_EFFECTS];     /* [slots_per_effect] */
    const uint64_t *pool_keys[WSC_MAX_EFFECTS]; /* the core's pool key array: the O(1) trust check */
    wsc_local_stats stats;                      /* bytes kept up to date at creation */
};

/* Frees a local table's arrays and the object. */
void wsc_local_destroy(wsc_local *local)
{
    if (!local)
        return;
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++) {
        if (local->slot_wgis[effect])
            local->allocator.free(local->slot_wgis[effect], local->slots_per_effect * sizeof(uint64_t),
                                  local->allocator.user);
        if (local->slot_bricks[effect])
            local->allocator.free(local->slot_bricks[effect], local->slots_per_effect * sizeof(uint32_t),
                                  local->allocator.user);
    }
    osc_allocator allocator = local->allocator;
    allocator.free(local, sizeof *local, allocator.user);
}

/* Allocates slot arrays for every present effect of the cache. */
osc_result wsc_local_create(const wsc_local_desc *desc, const wsc_cache *cache, wsc_local **out_local,
                            char *error_text, size_t error_text_cap)
{
    WSC_ASSERT(cache != NULL && out_local != NULL);
    *out_local = NULL;
    if (error_text && error_text_cap > 0)
        error_text[0] = '\0';
    wsc_local_desc resolved = desc ? *desc : (wsc_local_desc){0};
    if (resolved.side == 0)
        resolved.side = WSC__LOCAL_DEFAULT_SIDE;
    if (resolved.levels == 0)
        resolved.levels = WSC_MAX_LEVEL + 1;
    if (resolved.side < 2 || resolved.side > WSC__LOCAL_MAX_SIDE ||
        (resolved.side & (resolved.side - 1)) != 0)
        return wsc__fail(OSC_ERR_INVALID_DESC, error_text, error_text_cap,
                         "side %u is not a power of two in 2..64", resolved.side);
    if (resolved.levels > WSC_MAX_LEVEL + 1)
        return wsc__fail(OSC_ERR_INVALID_DESC, error_text, error_text_cap, "levels %u exceeds 15",
                         resolved.levels);
    osc_allocator allocator;
    if (!wsc__resolve_allocator(&resolved.allocator, &allocator))
        return wsc__fail(OSC_ERR_INVALID_DESC, error_text, error_text_cap,
                         "allocator: set both alloc and free, or neither");
    wsc_local *local = allocator.alloc(sizeof *local, allocator.user);
    if (!local)
        return wsc__fail(OSC_ERR_OUT_OF_MEMORY, error_text, error_text_cap,
                         "out of memory allocating a local table");
    memset(local, 0, sizeof *local);
    local->allocator = allocator;
    local->cache = cache;
    local->side = resolved.side;
    local->side_mask = resolved.side - 1;
    local->levels = resolved.levels;
    local->slots_per_effect = (size_t)resolved.levels * resolved.side * resolved.side * resolved.side;
    local->stats.bytes = sizeof *local;
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++) {
        if (!cache->cores[effect])
            continue;
        size_t wgi_bytes = local->slots_per_effect * sizeof(uint64_t);
        size_t brick_bytes = local->slots_per_effect * sizeof(uint32_t);
        local->slot_wgis[effect] = allocator.alloc(wgi_bytes, allocator.user);
        if (local->slot_wgis[effect])
            local->stats.bytes += wgi_bytes;
        local->slot_bricks[effect] = allocator.alloc(brick_bytes, allocator.user);
        if (local->slot_bricks[effect])
            local->stats.bytes += brick_bytes;
        if (!local->slot_wgis[effect] || !local->slot_bricks[effect]) {
            size_t allocated = local->stats.bytes;
            wsc_local_destroy(local);
            return wsc__fail(OSC_ERR_OUT_OF_MEMORY, error_text, error_text_cap,
                             "out of memory creating a local table (%zu bytes allocated before)", allocated);
        }
        local->pool_keys[effect] = cache->cores[effect]->pools[0].keys;
    }
    wsc_local_clear(local);
    *out_local = local;
    return OSC_OK;
}

/* Marks every slot unused. */
void wsc_local_clear(wsc_local *local)
{
    for (unsigned effect = 0; effect < WSC_MAX_EFFECTS; effect++) {
        if (local->slot_wgis[effect]) {
            memset(local->slot_wgis[effect], 0xFF, local->slots_per_effect * sizeof(uint64_t));   /* EMPTY */
            memset(local->slot_bricks[effect], 0xFF, local->slots_per_effect * sizeof(uint32_t)); /* NONE */
        }
    }
}

/* A slot, then (on a miss) the table. The slot's brick is trusted only when the pool still holds the WGI
 * for it (see wsc.h), so this returns exactly what wsc_find returns. */
uint32_t wsc_local_lookup(wsc_local *local, const wsc_cache *cache, uint32_t effect, uint64_t wgi)
{
    WSC_ASSERT(local->cache == cache && effect < WSC_MAX_EFFECTS);
    uint64_t *slot_wgis = local->slot_wgis[effect];
    uint32_t level = wsc_wgi_level(wgi);
    if (!slot_wgis || level > WSC_MAX_LEVEL)
        return WSC_NONE; /* absent effect or not a WGI: wsc_find says the same */
    if (level >= local->levels) {
        local->stats.bypasses++;
        return osc_find(cache->cores[effect], wgi);
    }
    uint32_t m = local->side_mask, side = local->side;
    uint32_t x = (uint32_t)(wgi >> WSC_WGI_X_SHIFT) & m, z = (uint32_t)(wgi >> WSC_WGI_Z_SHIFT) & m;
    uint32_t y = (uint32_t)(wgi >> WSC_WGI_Y_SHIFT) & m;
    size_t slot = (((size_t)level * side + y) * side + z) * side + x;
    if (slot_wgis[slot] == wgi) {
        uint32_t brick = local->slot_bricks[effect][slot];
        if (local->pool_keys[effect][brick] == wgi) {
            local->stats.hits++;
            return brick;
        }
        local->stats.stale++; /* evicted or re-mapped since the slot was filled */
    }
    local->stats.misses++;
    uint32_t brick = osc_find(cache->cores[effect], wgi);
    if (brick != WSC_NONE) {
        slot_wgis[slot] = wgi;
        local->slot_bricks[effect][slot] = brick;
    }
    return brick;
}

/* Copies the counters. */
void wsc_local_stats_get(const wsc_local *local, wsc_local_stats *out)
{
    *out = local->stats;
}
