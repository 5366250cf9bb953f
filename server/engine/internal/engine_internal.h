/* Private to the engine: the loop's state, the cache-kind interface and the stage functions.
 *
 * loop.c owns the loop, its viewers and sinks and runs the stages in order; visibility.c, requests.c,
 * update.c (queues, lookup, effects) and compose.c are the stages; kind_osc.c puts the on-surface cache
 * behind the cache-kind interface (a world-space kind is one more file and one line in kinds.c); report.c
 * is the run report. Stages call the helpers declared here; nothing here calls back into a stage. */
#ifndef FXC_ENGINE_INTERNAL_H
#define FXC_ENGINE_INTERNAL_H

#include "cache.h"
#include "effects.h"
#include "engine.h"
#include "pool.h"

#include <math.h>
#include <stdatomic.h>
#include <string.h>

enum {
    SRV_TILE = 16,          /* visibility and request tiles are 16 x 16 pixels */
    SRV_MISS = 0xFFFFFFFFu, /* no hit */
    SRV_NONE = 0xFFFFFFFFu, /* no block */
    SRV_MAX_SINKS = 8,
    SRV_NO_EFFECT = 0xFFFFFFFFu,
    SRV_KEYS_PER_PIXEL = FX_MAX_TAPS, /* blocks one filtered read of a pixel touches */
    SRV_RUN = FX_RUN_PIXELS,          /* pixels per batched call in requests and compose */
};

/* Memory categories counted by the engine's allocator (srv_memory's viewers and queues). */
typedef enum srv_mem_category { SRV_MEM_VIEWERS = 0, SRV_MEM_QUEUES, SRV_MEM_COUNT } srv_mem_category;

enum { SRV_REQUEST_RECENT = 1024 }; /* srv_request_list.recent: a power of two */

/* A growable (key, mask) list, kept across frames so steady state allocates nothing. Padded to two cache
 * lines, whatever the alignment the allocator gives the array of per-thread lists: the fields of two
 * neighbouring lists (64 bytes each) are then at least 64 bytes apart and never share a cache line. */
typedef struct srv_request_list {
    uint64_t *keys;
    uint64_t *masks;
    uint32_t *blocks; /* block index per key after the batch request */
    size_t count, capacity;
    size_t keys_capacity, masks_capacity, blocks_capacity; /* each array's own (equal unless a grow failed) */
    /* Per-thread lists (requests.c): by a hash of a key, the index of the entry that last took that hash, so
     * that a key another tile of the same pass already appended gets its mask or-ed in instead of a second
     * entry. An index is trusted only if it is below count and its entry holds the key: never reset. */
    uint32_t recent[SRV_REQUEST_RECENT];
    uint8_t padding[64];
} srv_request_list;

/* A visible pixel as the cache kinds see it. */
typedef struct srv_pixel {
    uint32_t triangle;
    uint32_t island;          /* the triangle's island and the side seen: | SCENE_ISLAND_BACK for its back */
    float island_u, island_v; /* level-0 island texels */
    float footprint;          /* log2 of the pixel's footprint in level-0 texels */
    /* Filled only when a cache kind asks for them (needs_position; its request pass then leaves island_u/v
     * unset): the visible point, scene-local, and its distance from the viewer's camera (what world-space
     * levels are chosen by). */
    float position[3];
    float distance;
} srv_pixel;

/* A run's pixels as lanes (structure of arrays over SRV_RUN, lanes past the run 0), what compose's gather
 * of a tile's run has anyway: island UVs, footprint, island and the island's size at level 0
 * (scene_island width and height). Handed to a cache kind's pixel_taps with the pixels, so that it need not
 * copy them out of srv_pixel again for each call. */
typedef struct srv_pixel_lanes {
    float island_u[SRV_RUN], island_v[SRV_RUN], footprint[SRV_RUN];
    uint32_t island[SRV_RUN]; /* with the side bit, as srv_pixel.island */
    uint32_t width0[SRV_RUN], height0[SRV_RUN];
} srv_pixel_lanes;

/* A viewer slot. A sparse viewer's per-pixel buffers are indexed by position in its list, not by y * width
 * + x; the stages visit list entries instead of tiles (visibility, requests, compose). */
typedef struct srv_viewer {
    uint32_t generation; /* id = generation << 8 | slot; bumped at remove */
    bool present, has_camera, rendered;
    bool sparse; /* desc.max_pixels > 0 */
    srv_viewer_desc desc;
    srv_camera camera;
    srv_camera_frame frame;
    size_t pixels;          /* entries of the per-pixel buffers (width*height, or max_pixels) */
    uint32_t *list;         /* sparse: the distinct listed pixels, y << 16 | x, in srv__run_key order
                                  (max_pixels) */
    uint32_t *list_scratch; /* sparse: the radix sort's other buffer (max_pixels) */
    uint32_t list_count;    /* sparse: entries of list */
    uint32_t *tri;          /* hit triangle per pixel, SRV_MISS for none */
    float *bary_u, *bary_v;
    float *footprint;       /* log2 of the pixel's footprint in level-0 texels (ray differentials) */
    float *depth;           /* distance along the primary ray, INFINITY for none */
    uint8_t *back;          /* 1 where the ray meets its triangle's back (visibility; requests and compose
                               read the island's back, SCENE_ISLAND_BACK), else 0; unset for a miss */
    uint8_t *coarse;        /* whole frames with a coarse effect: per pixel, this frame's srv__coarse_mask
                                  (written by requests, read by compose); NULL otherwise */
    float *samples;         /* whole frames with a coarse effect: the frame's block samples' terms, evaluated
                                  once per frame before compose's tiles (SRV_SAMPLE_VALUES arrays of
                                  sample_capacity entries, sample (i, j) at j * ceil(width / B) + i); NULL
                                  otherwise */
    size_t sample_capacity; /* entries of each array: enough for the smallest block, 2 */
    float *radiance;        /* linear RGB */
    uint8_t *image;         /* sRGB 8-bit RGB */
    float *views[SRV_VIEW_COUNT];
    srv_request_list requests; /* this frame's, merged across threads, before the cache */
    srv_viewer_stats stats;
} srv_viewer;

/* One queued block of an effect for this frame. */
typedef struct srv_job {
    uint32_t block;            /* block index in the effect's pool */
    uint32_t dependency_block; /* the same block of the effect it depends on, or SRV_NONE */
    uint64_t mask;             /* texels to update */
} srv_job;

/* Per effect: this frame's queue scratch and job lists (grown when needed and kept). */
typedef struct srv_effect_queue {
    uint64_t *empty, *refine, *take; /* per frame block: texels without data, to refine, taken */
    uint32_t *dependency;            /* per frame block: its dependency block */
    size_t capacity;
    srv_job *jobs;
    size_t job_count, job_capacity;
    fx_block_job *fx_jobs; /* what the effect's update receives */
    size_t fx_job_capacity;
    uint64_t *chunk_rays; /* rays traced per chunk of jobs */
    size_t chunk_capacity;
    uint8_t *scratch;        /* job_count * the effect's scratch_bytes (world-space updates) */
    size_t scratch_capacity; /* bytes */
    uint64_t *order;         /* continuous refresh: (~age << 32 | frame block), oldest first */
    size_t order_capacity, order_count;
    uint64_t cells_taken; /* continuous effects: cells taken this frame (the probe budget) */
} srv_effect_queue;

typedef struct srv_loop srv_loop;

/* A cache kind: what the stages call for every cache, whatever its layout (DESIGN.md: on-surface,
 * world-space). Blocks are indices into an effect's pool (a world-space brick is a block here). Batched calls
 * take runs of pixels, never one call per texel. `slot` is the viewer a call works for (a kind may keep
 * per-viewer state, such as the world-space cache's local lookup tables). */
typedef struct srv_cache_kind {
    const char *name;
    scene_cache_kind kind;
    bool keys_carry_effect; /* the key names its effect (key_effect, rekey); otherwise requests are batched
                               per effect and the effect is passed alongside */
    bool needs_position;    /* pixels must carry position and distance (srv_pixel) */
    bool lanes_suffice;     /* pixel_taps given lanes reads only them: the caller may leave pixels unset */
    /* Creates the cache for the loop's effects of this kind that run (loop->effect_cached, pool budget
     * loop->desc.pool_bytes shared by bytes per texel). *cache NULL: nothing of this kind runs. */
    fxc_result (*create)(srv_loop *loop, void **cache, char *err, size_t err_cap);
    void (*destroy)(void *cache);
    void (*begin_frame)(void *cache, uint32_t frame);
    /* Stage 3: writes the keys and masks the filtered reads of `count` pixels touch for `effect` at level
     * footprint + bias, at most SRV_KEYS_PER_PIXEL per pixel (a pixel that repeats a recent one may write
     * none). Returns how many were written. The dependency's keys are derived later, from the merged ones.
     * Called from several threads at once. */
    uint32_t (*pixel_requests)(const void *cache, uint32_t slot, const srv_pixel *pixels, uint32_t count,
                               uint32_t effect, int32_t bias, uint64_t *keys, uint64_t *masks);
    uint32_t (*key_effect)(uint64_t key);             /* keys_carry_effect only */
    uint64_t (*rekey)(uint64_t key, uint32_t effect); /* the same block's key for another effect */
    /* Sorts, merges and requests one viewer's keys (of `effect` when keys do not carry it). */
    fxc_result (*request_batch)(void *cache, uint32_t slot, uint32_t effect, uint64_t *keys, uint64_t *masks,
                                size_t count, size_t *unique, uint32_t *blocks, uint64_t *pool_exhausted,
                                uint64_t *table_full);
    const uint32_t *(*frame_blocks)(void *cache, uint32_t effect, uint32_t *count);
    uint64_t (*block_key)(const void *cache, uint32_t effect, uint32_t block);
    uint64_t (*block_requested)(const void *cache, uint32_t effect, uint32_t block);
    uint64_t (*block_valid)(const void *cache, uint32_t effect, uint32_t block);
    void (*block_set_valid)(void *cache, uint32_t effect, uint32_t block, uint64_t valid);
    void *(*block_payload)(void *cache, uint32_t effect, uint32_t block);
    /* Per-block word (world-space: the frame of the block's last update, for continuous refresh), or NULL. */
    uint32_t *(*block_word)(void *cache, uint32_t effect, uint32_t block);
    uint32_t (*find)(const void *cache, uint32_t effect, uint64_t key);
    /* Fills the location fields of an fx_block_job (key, island, level, block_x, block_y; world-space:
     * origin and cell) from a key. */
    void (*job_location)(const void *cache, uint32_t effect, uint64_t key, fx_block_job *job);
    /* Resampling: for every texel of `need` in block, the four finer texels holding data (finer[t][0..3]);
     * returns the texels whose four are all there. NULL: the kind does not resample. */
    uint64_t (*finer_texels)(void *cache, uint32_t effect, uint32_t block, uint64_t need,
                             const void *finer[64][4]);
    /* Stage 7: the filtered taps of `count` pixels for each of `effect_count` effects of this kind (at most
     * SRV_MAX_EFFECTS), all at level footprint + bias: taps[j][i] for pixel i and effects[j]; blocks (may be
     * NULL, and so may each blocks[j]) receives the block of each pixel's first tap or SRV_NONE. Each effect's
     * taps are those of a call for it alone; a kind computes what they share (level, footprint, weights)
     * once per pixel. Called from several threads at once; `thread` is the calling pool thread (per-thread
     * state of a kind, such as local lookup tables). Returns how many of the count x effect_count taps have
     * count 0 (no data), so that a caller can skip looking for them when there are none. lanes (may be NULL):
     * the same pixels' island UVs, footprints, islands and island sizes as lanes, equal to the pixels'
     * (a kind may read either; a kind with lanes_suffice reads only the lanes when it gets them, and the
     * pixels passed with lanes may then be unset). */
    uint32_t (*pixel_taps)(const void *cache, uint32_t slot, uint32_t thread, const srv_pixel *pixels,
                           const srv_pixel_lanes *lanes, uint32_t count, uint32_t effect_count,
                           const uint32_t *effects, int32_t bias, fx_taps *const *taps,
                           uint32_t *const *blocks);
    uint32_t (*pool_capacity)(const void *cache, uint32_t effect);
    /* Stage 9 and figures. */
    void (*housekeeping)(void *cache);
    void (*frame_figures)(const void *cache, srv_frame_stats *stats);
    void (*memory)(const void *cache, srv_memory *out); /* adds its bytes */
    /* A viewer left: drop whatever the kind keeps for its slot (may be NULL). */
    void (*viewer_removed)(void *cache, uint32_t slot);
} srv_cache_kind;

/* The cache kinds by scene_cache_kind (NULL: not built yet). */
const srv_cache_kind *srv__cache_kind(scene_cache_kind kind);

struct srv_loop {
    srv_loop_desc desc;
    const scene *s;
    scene_rt *rt;
    srv_pool *pool;
    bool abandoned; /* a frame was abandoned at the stop flag (srv_loop_set_stop): no more frames */
    fx_context fx;
    /* Effects. */
    uint32_t effect_count;
    const fx_effect *effects[SRV_MAX_EFFECTS];
    uint32_t dependency[SRV_MAX_EFFECTS]; /* index of the effect it depends on, or SRV_NO_EFFECT */
    bool effect_on[SRV_MAX_EFFECTS];      /* runs (in either mode) */
    bool effect_cached[SRV_MAX_EFFECTS];  /* goes through a cache this run (on, cache mode) */
    bool effect_shading[SRV_MAX_EFFECTS]; /* cached and shades (counted in requested texels) */
    bool depended_on[SRV_MAX_EFFECTS];    /* an effect that runs depends on it: updated in the lookup stage */
    int32_t bias[SRV_MAX_EFFECTS];
    uint32_t samples[SRV_MAX_EFFECTS];     /* samples per update handed to the effect */
    uint32_t max_samples[SRV_MAX_EFFECTS]; /* progressive: the samples a texel converges at this run (the
                                               effect's run_samples, else its max_samples) */
    /* Caches, one per kind that an effect needs. */
    const srv_cache_kind *kinds[SCENE_CACHE_COUNT];
    void *caches[SCENE_CACHE_COUNT];
    uint32_t effect_kind[SRV_MAX_EFFECTS]; /* scene_cache_kind of each effect */
    /* Viewers and sinks. */
    uint32_t frame_number;
    /* The lights and sky as the last frame saw them (srv__light_signature), the frame they last changed on
     * and for how many frames after a change converged probes refresh every frame (update.c). */
    uint64_t light_signature;
    uint32_t light_change_frame, light_settle_frames;
    bool light_changed;
    srv_viewer viewers[SRV_MAX_VIEWERS];
    srv_sink sinks[SRV_MAX_SINKS];
    uint32_t sink_count;
    /* Scratch kept across frames. */
    srv_request_list *thread_requests; /* one per pool thread */
    srv_effect_queue queues[SRV_MAX_EFFECTS];
    uint64_t *viewer_bits[SRV_MAX_EFFECTS]; /* per block: which viewer slots requested it (keep_views) */
    uint32_t coarse_effect;       /* the low-frequency effect whole frames evaluate once per block of
                                               desc.indirect_block pixels (compose, requests), or SRV_NO_EFFECT */
    float coarse_depth_scale;     /* the coarse match's depth tolerance per pixel apart and per metre
                                               of footprint: 3 / texel_density (srv__coarse_match) */
    void *compose_scratch;        /* per thread: runs of pixels (compose.c) */
    size_t compose_scratch_bytes; /* per thread */
    /* Memory counted by category through desc.allocator (request lists grow on pool threads). */
    _Atomic uint64_t mem[SRV_MEM_COUNT];
};

/* Monotonic clock, milliseconds. */
double srv__now_ms(void);

/* Allocation through the loop's allocator, counted in category: (re)allocates *array from old_count to
 * new_count elements of size bytes (overflow-checked); false and *array untouched on failure. new_count 0
 * frees. */
bool srv__resize(srv_loop *loop, srv_mem_category category, void **array, size_t old_count, size_t new_count,
                 size_t size);

/* Grows *array (capacity *capacity elements) to hold n, doubling from `first`; false on no memory. */
bool srv__grow(srv_loop *loop, srv_mem_category category, void **array, size_t *capacity, size_t n,
               size_t first, size_t size);

/* Grows a request list to hold at least n entries; false on no memory. */
bool srv__request_reserve(srv_loop *loop, srv_mem_category category, srv_request_list *list, size_t n);
void srv__request_list_free(srv_loop *loop, srv_mem_category category, srv_request_list *list);

/* A sparse viewer's list order: the compose run a pixel (packed y << 16 | x) belongs to in a whole frame of
 * tiles_x tiles per row (16 x 16 tiles in row order, runs of SRV_RUN / SRV_TILE = 4 rows inside), shifted
 * left by 6, then its place in that run. Listed pixels of one whole-frame run are then consecutive, and
 * compose shades them together, as a whole frame does (effects that shade a run's pixels jointly, such as
 * the probes, then see the same neighbours). Below 2^26 for sides up to 8192. */
_Static_assert(SRV_RUN == 4 * SRV_TILE, "a compose run is 4 rows of a tile");
static inline uint32_t srv__run_key(uint32_t xy, uint32_t tiles_x)
{
    uint32_t x = xy & 0xFFFFu, y = xy >> 16;
    uint32_t run = ((y / SRV_TILE) * tiles_x + x / SRV_TILE) * (SRV_TILE / 4) + (y % SRV_TILE) / 4;
    return run << 6 | (y % 4) << 4 | (x % SRV_TILE);
}

/* The packed pixel of a run key (the inverse of srv__run_key). */
static inline uint32_t srv__run_key_pixel(uint32_t key, uint32_t tiles_x)
{
    uint32_t run = key >> 6, tile = run / (SRV_TILE / 4), band = run % (SRV_TILE / 4);
    uint32_t x = (tile % tiles_x) * SRV_TILE + (key & 15u),
             y = (tile / tiles_x) * SRV_TILE + band * 4 + ((key >> 4) & 3u);
    return y << 16 | x;
}

/* Coarse evaluation of a low-frequency effect (srv_loop_desc.indirect_block = B > 1; whole frames only, a
 * sparse viewer's pixels have no neighbours and are evaluated one by one). The pixels (B i, B j) of the
 * frame are the block samples ("reps"): compose evaluates the effect there. A tile uses its own reps and
 * those of the next column and row of reps (its right and lower neighbours' first ones: (16 / B + 1)^2 at
 * most), so interpolation runs across tile borders without a seam. Every other pixel takes the up to 4 reps
 * around it (bilinear weights, at least 1/16 each) whose surface matches its own (joint bilateral), or, when
 * none matches, is evaluated itself, and requests then ask for its own keys. The match reads only what
 * visibility wrote (triangle, depth, footprint) and the scene's face normals; requests decide it once per
 * frame and pixel and keep it for compose (one byte a pixel, view->coarse), so the pixels compose evaluates
 * itself are exactly those whose keys requests asked for. Compose evaluates every sample of the frame once,
 * before its tiles, into the viewer's sample image (srv_viewer.samples); the tiles blend from it.
 * srv__coarse_mask and srv__coarse_weights below are the definitions: requests compute the mask a tile row
 * at a time in lanes (requests.c, coarse_mask_lanes) and compose the weights likewise (compose.c, blend_row),
 * with the same operations. */

/* The frame-wide sample image (srv_viewer.samples): per sample its indirect term (3 arrays, sky visibility 1
 * in), the sky visibility shade left, the sharing count for the stats view, and 1 where it is visible and has
 * taps (else 0, and finite zeros everywhere: the blend multiplies them by 0). */
enum {
    SRV_SAMPLE_R,
    SRV_SAMPLE_G,
    SRV_SAMPLE_B,
    SRV_SAMPLE_SKY,
    SRV_SAMPLE_SHARING,
    SRV_SAMPLE_OK,
    SRV_SAMPLE_VALUES
};

/* Samples per row of a frame `width` pixels wide at block B (the pixels 0, B, 2 B, ...). */
static inline uint32_t srv__sample_stride(uint32_t width, uint32_t block)
{
    return (width + block - 1) / block;
}

typedef struct srv_coarse_grid {
    uint32_t block, shift; /* B = 1 << shift */
    uint32_t x0, y0;       /* the tile's first pixel (a multiple of B: tiles are 16-aligned) */
    uint32_t nx, ny; /* reps per row and column the tile uses (its own and the next, within the frame) */
    float inv_block; /* 1 / B */
} srv_coarse_grid;

static inline void srv__coarse_grid(uint32_t block, uint32_t x0, uint32_t y0, uint32_t width, uint32_t height,
                                    srv_coarse_grid *g)
{
    g->block = block;
    g->shift = (uint32_t)__builtin_ctz(block);
    g->inv_block = 1.0f / (float)block;
    g->x0 = x0;
    g->y0 = y0;
    uint32_t most = SRV_TILE / block + 1;
    g->nx = (width - x0 + block - 1) / block;
    g->ny = (height - y0 + block - 1) / block;
    g->nx = g->nx < most ? g->nx : most;
    g->ny = g->ny < most ? g->ny : most;
}

/* The block a viewer's whole frame uses: the largest power of two up to desc.indirect_block that is at most
 * a quarter of the narrowest probe cell in its pixels; 1 (every pixel) for a sparse viewer or without a
 * coarse effect. Cells are at least d / 16 wide at distance d (wsc_level), a pixel 2 d tan_half_y / height:
 * the narrowest cell spans height / (32 tan_half_y) pixels (640 x 360 at 60 degrees: 19.5, so 4; 64 x 36:
 * 1.9, so 1). Within a block the probes' trilinear field then changes by at most a quarter of a cell. */
static inline uint32_t srv__coarse_block(const srv_loop *loop, const srv_viewer *v)
{
    if (loop->coarse_effect == SRV_NO_EFFECT || v->sparse)
        return 1;
    float cell_pixels = (float)v->frame.height / (32.0f * v->frame.tan_half_y);
    uint32_t block = loop->desc.indirect_block;
    while (block > 1 && 4.0f * (float)block > cell_pixels)
        block /= 2;
    return block;
}

/* 2^floor(x), x clamped to [-60, 60], from the bits (no libm: the same in every clone). */
static inline float srv__pow2_floor(float x)
{
    x = x > -60.0f ? (x < 60.0f ? x : 60.0f) : -60.0f; /* also NaN -> -60 */
    int e = (int)floorf(x);
    uint32_t bits = (uint32_t)(e + 127) << 23;
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

/* Whether rep pixel r may stand in for visible pixel p, `apart` pixels away (the larger axis): the same
 * triangle, or a face normal within 0.05 per component (3 degrees) and a depth difference within
 * 3 x apart x the larger footprint (metres, rounded down to a power of two: 1.5 to 3 times what a plane
 * gives between pixels that far apart), both scaled by strictness. No sum of products: nothing to contract. */
static inline bool srv__coarse_match(const scene *s, const srv_viewer *v, float depth_scale, size_t p,
                                     size_t r, float apart, float strictness)
{
    uint32_t tr = v->tri[r], tp = v->tri[p];
    if (tr == tp)
        return true;
    if (tr == SRV_MISS)
        return false;
    const float *nr = s->tri_normal + 3 * (size_t)tr, *np = s->tri_normal + 3 * (size_t)tp;
    float limit = 0.05f * strictness;
    if (!(fabsf(nr[0] - np[0]) <= limit && fabsf(nr[1] - np[1]) <= limit && fabsf(nr[2] - np[2]) <= limit))
        return false;
    float footprint = v->footprint[p] > v->footprint[r] ? v->footprint[p] : v->footprint[r];
    float tolerance = srv__pow2_floor(footprint) * (apart * strictness * depth_scale);
    return fabsf(v->depth[p] - v->depth[r]) <= tolerance;
}

/* Whether frame pixel (x, y) is a rep. */
static inline bool srv__coarse_is_rep(uint32_t block, uint32_t x, uint32_t y)
{
    return (x | y) % block == 0;
}

/* The reps that may stand in for visible pixel (x, y) of the tile of grid g (frame coordinates), as a mask:
 * bit c for candidate c (0: the rep of the pixel's block, 1: the next to the right, 2: the next below, 3: the
 * diagonal one) when it exists in the frame and matches (srv__coarse_match, strictness 1); a rep: bit 0
 * alone; 0: the pixel is evaluated itself. Requests decide it once per frame and keep it in view->coarse for
 * compose (srv__coarse_weights), so what compose evaluates itself is exactly what requests asked keys for.
 * Reps on the pixel's own triangle are the common case and need no test beyond that. */
static inline uint32_t srv__coarse_mask(const scene *s, const srv_viewer *v, float depth_scale,
                                        const srv_coarse_grid *g, uint32_t x, uint32_t y)
{
    uint32_t lx = x - g->x0, ly = y - g->y0, low = g->block - 1;
    uint32_t ix = lx >> g->shift, iy = ly >> g->shift, fx = lx & low, fy = ly & low;
    if (!(fx | fy))
        return 1;
    bool two_x = fx && ix + 1 < g->nx, two_y = fy && iy + 1 < g->ny;
    size_t width = v->frame.width, p = (size_t)y * width + x;
    size_t r0 = (size_t)(g->y0 + (iy << g->shift)) * width + g->x0 + (ix << g->shift);
    const size_t pixel_of[4] = {r0, r0 + g->block, r0 + g->block * width, r0 + g->block * width + g->block};
    const uint32_t exists = 1u | (two_x ? 2u : 0u) | (two_y ? 4u : 0u) | (two_x && two_y ? 8u : 0u);
    uint32_t tp = v->tri[p], mask = 0;
    for (uint32_t c = 0; c < 4; c++) {
        if (!(exists >> c & 1))
            continue;
        size_t r = pixel_of[c];
        if (v->tri[r] != tp) {
            uint32_t dx = (c & 1) ? g->block - fx : fx, dy = (c & 2) ? g->block - fy : fy;
            if (!srv__coarse_match(s, v, depth_scale, p, r, (float)(dx > dy ? dx : dy), 1.0f))
                continue;
        }
        mask |= 1u << c;
    }
    return mask;
}

/* The bilinear weights of the 4 candidate reps of pixel (x, y) (srv__coarse_mask's order; at least 1 / B^2
 * for a candidate that exists, 0 along an axis the frame has no second rep for) and the first candidate's
 * index (j * nx + i, relative to the tile's first rep; the others are +1, +nx, +nx+1). */
static inline uint32_t srv__coarse_weights(const srv_coarse_grid *g, uint32_t x, uint32_t y, float weight[4])
{
    uint32_t lx = x - g->x0, ly = y - g->y0, low = g->block - 1;
    uint32_t ix = lx >> g->shift, iy = ly >> g->shift, fx = lx & low, fy = ly & low;
    bool two_x = fx && ix + 1 < g->nx, two_y = fy && iy + 1 < g->ny;
    float wx = two_x ? (float)fx * g->inv_block : 0.0f, wy = two_y ? (float)fy * g->inv_block : 0.0f;
    weight[0] = (1.0f - wx) * (1.0f - wy);
    weight[1] = wx * (1.0f - wy);
    weight[2] = (1.0f - wx) * wy;
    weight[3] = wx * wy;
    return iy * g->nx + ix;
}

/* Pixels a viewer's frame visits: width*height, or a sparse viewer's list. */
static inline size_t srv__viewer_pixel_count(const srv_viewer *view)
{
    return view->sparse ? view->list_count : (size_t)view->frame.width * view->frame.height;
}

/* Stage 2: visibility of one viewer into its buffers. */
void srv__visibility(srv_loop *loop, srv_viewer *view);

/* The primary rays of one SRV_TILE x SRV_TILE tile of frame f whose top-left pixel is (tile_x, tile_y), in
 * 4 x 4 packets: per pixel of the tile (index y * width + x) the triangle (SRV_MISS for none), barycentrics,
 * depth (INFINITY for none), footprint (log2 of level-0 texels) and, when back is not NULL, whether the ray
 * meets the triangle's back (1; compose's facing test: the geometric normal's dot with the pixel's ray on the
 * image plane > 0). What srv__visibility writes into a viewer's buffers; the reference renderer uses it so
 * it sees the same surface at every pixel. */
void srv__visibility_tile(const scene *s, scene_rt *rt, const srv_camera_frame *f, uint32_t tile_x,
                          uint32_t tile_y, uint32_t *tri, float *bary_u, float *bary_v, float *depth,
                          float *footprint, uint8_t *back);

/* The primary rays of up to 16 listed pixels (packed y << 16 | x of frame f), one packet: what
 * srv__visibility_tile computes for those pixels, written at their list positions first..first+count-1. */
void srv__visibility_list(const scene *s, scene_rt *rt, const srv_camera_frame *f, const uint32_t *list,
                          uint32_t first, uint32_t count, uint32_t *tri, float *bary_u, float *bary_v,
                          float *depth, float *footprint, uint8_t *back);

/* Differentials of the hit position at distance t along unit ray dir on the plane of normal n: the offsets
 * to where the rays through the next pixel right (dpdx) and down (dpdy) meet that plane (grazing: at most 64
 * t). The pixel's footprint the no-cache baseline jitters shadow rays over. */
void srv__pixel_differentials(const srv_camera_frame *f, const float dir[3], float t, const float n[3],
                              float dpdx[3], float dpdy[3]);

/* Stage 3: requests of one viewer into the caches; fills the viewer's requested texels and cells
 * (deduplicated within the viewer, shading effects only, per cache kind) and counts drops in st. */
void srv__requests(srv_loop *loop, uint32_t slot, srv_frame_stats *st, uint64_t requested[SCENE_CACHE_COUNT]);

/* Stage 4: queues of every cached effect within the ray budget, resampling first. */
void srv__queues(srv_loop *loop, srv_frame_stats *st);

/* Stages 5 and 6: runs the queued jobs of the effects others depend on (lookup = true) or of the rest. */
void srv__updates(srv_loop *loop, bool lookup, srv_frame_stats *st);

/* Stage 7: compose one viewer (cached, or per-pixel in no-cache mode). */
void srv__compose(srv_loop *loop, uint32_t slot, srv_frame_stats *st);

/* The tone map of compose (linear radiance to an sRGB byte) and its definition with expf; equal for every
 * float (white-box tests compare them). */
uint8_t srv__tone_map(float c);
uint8_t srv__tone_map_reference(float c);
/* The tone map of n consecutive floats into n bytes as compose's rows take it (in lanes): srv__tone_map of each. */
void srv__tone_map_lanes(const float *radiance, uint8_t *image, uint32_t n);
/* The same without building the tables: for compose, which calls srv__tone_map_init once per viewer first. */
void srv__tone_map_init(void);
void srv__tone_map_row(const float *radiance, uint8_t *image, uint32_t n);

/* Per-thread compose scratch size for this loop (bytes), known at creation. */
size_t srv__compose_scratch_bytes(const srv_loop *loop);

/* The effect level of a pixel: round(footprint + bias), clamped to [0, 15]. */
static inline uint32_t srv__level(float footprint_log2, int32_t bias)
{
    float l = footprint_log2 + (float)bias;
    if (!(l > 0.0f))
        return 0;
    if (l >= 15.0f)
        return 15;
    return (uint32_t)(l + 0.5f) > 15 ? 15 : (uint32_t)(l + 0.5f);
}

/* The island-local UV (level-0 texels) of a hit. */
static inline void srv__island_uv(const scene *s, uint32_t tri, float u, float v, float *tu, float *tv)
{
    const float *uv = s->tri_island_uv + 6 * (size_t)tri;
    float w = 1.0f - u - v;
    *tu = w * uv[0] + u * uv[2] + v * uv[4];
    *tv = w * uv[1] + u * uv[3] + v * uv[5];
}

/* The world position and unit normal of a hit. */
void srv__hit_point(const scene *s, uint32_t tri, float u, float v, float pos[3], float normal[3]);

/* The on-surface kind (kind_osc.c) and the world-space kind (kind_wsc.c). */
extern const srv_cache_kind srv__kind_osc, srv__kind_wsc;

/* The world-space kind's read for effects (fx_context.world_taps; user: the kind's cache). */
/* The same kind's whole-cell read (fx_context.world_cell). */
bool srv__wsc_world_cell(const void *user, uint32_t effect, uint32_t level, const float centre[3],
                         const void *texel[8]);
uint32_t srv__wsc_world_taps(const void *user, uint32_t effect, const float position[3], uint32_t level,
                             fx_taps *taps);

#endif
