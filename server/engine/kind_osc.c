/* The on-surface cache (cache/osc.h) behind the cache-kind interface: keys from a pixel's island UV and
 * level (bilinear footprints), filtered taps for compose, the four finer texels for resampling, and the
 * cache's phases, figures and memory. Everything that knows the osc key layout or island sizes in the
 * engine is here. */
#include "engine_internal.h"
#include "fxc_hot.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct kind_osc {
    osc_cache *osc;
    const scene *s;
} kind_osc;

static fxc_result osc_kind_create(srv_loop *loop, void **out, char *err, size_t err_cap)
{
    uint32_t total_texel_bytes = 0;
    uint32_t texel_bytes[SRV_MAX_EFFECTS] = {0};
    for (uint32_t e = 0; e < loop->effect_count; e++)
        if (loop->effect_cached[e] && loop->effect_kind[e] == SCENE_CACHE_ON_SURFACE) {
            texel_bytes[e] = loop->effects[e]->texel_bytes(loop->s);
            total_texel_bytes += texel_bytes[e];
        }
    *out = NULL;
    if (total_texel_bytes == 0)
        return FXC_OK;
    kind_osc *k = calloc(1, sizeof *k);
    if (!k) {
        snprintf(err, err_cap, "frame loop: out of memory for the on-surface cache");
        return FXC_ERR_NOMEM;
    }
    k->s = loop->s;
    /* Every effect gets the same number of blocks: a block of each effect covers the same texels. When a
     * world-space effect runs, it has a quarter of the pool budget (kind_wsc.c) and these pools the rest. */
    bool world = false;
    for (uint32_t e = 0; e < loop->effect_count; e++)
        world |= loop->effect_cached[e] && loop->effect_kind[e] == SCENE_CACHE_WORLD_SPACE;
    uint64_t budget = world ? loop->desc.pool_bytes - loop->desc.pool_bytes / 4 : loop->desc.pool_bytes;
    uint64_t blocks = budget / (64ull * total_texel_bytes);
    if (blocks < 64)
        blocks = 64;
    if (blocks > (1u << 26))
        blocks = 1u << 26;
    osc_desc od = {0};
    for (uint32_t e = 0; e < loop->effect_count; e++)
        if (texel_bytes[e])
            od.effects[e] = (osc_effect_desc){.texel_bytes = texel_bytes[e], .max_blocks = (uint32_t)blocks};
    char msg[256];
    osc_result r = osc_create(&od, &k->osc, msg, sizeof msg);
    if (r != OSC_OK) {
        snprintf(err, err_cap, "frame loop: cannot create the on-surface cache: %s", msg);
        free(k);
        return (fxc_result)r;
    }
    *out = k;
    return FXC_OK;
}

static void osc_kind_destroy(void *cache)
{
    kind_osc *k = cache;
    if (!k)
        return;
    osc_destroy(k->osc);
    free(k);
}

static void osc_kind_begin_frame(void *cache, uint32_t frame)
{
    osc_begin_frame(((kind_osc *)cache)->osc, frame);
}

/* A lane's level (srv__level of l: NaN and l <= 0 give 0, at most 15) and 2^-level, as the per-pixel code
 * computes them. A macro, not a function: a helper is not inlined into FXC_HOT_LANES functions (other
 * options), and the loops must stay free of calls to vectorise. */
#define LANE_LEVEL(l_in, level_out, scale_out)                                                               \
    do {                                                                                                     \
        float l_ = (l_in);                                                                                   \
        float above_ = l_ > 0.0f ? l_ : 0.0f;                                                                \
        float clamped_ = above_ < 15.0f ? above_ : 15.0f;                                                    \
        int32_t level_ = (int32_t)(clamped_ + 0.5f);                                                         \
        level_ = level_ > 15 ? 15 : level_;                                                                  \
        int32_t scale_bits_ = (127 - level_) << 23;                                                          \
        memcpy(&(scale_out), &scale_bits_, sizeof(scale_out));                                               \
        (level_out) = level_;                                                                                \
    } while (0)

/* What the request pass computes per pixel before its dedup and keys, for a run at once over SRV_RUN lanes
 * (vectorised as taps_lanes_fill, the same operations in the same order): the level, the position in texels
 * of that level, whether it lies in [0, 32768)^2 and, there, the stencil corner floor(x - 0.5) + 1. */
typedef struct request_lanes {
    float u[SRV_RUN], v[SRV_RUN], footprint[SRV_RUN]; /* input; lanes past the run are 0 */
    int32_t level[SRV_RUN], inside[SRV_RUN], cx[SRV_RUN], cy[SRV_RUN];
    float x[SRV_RUN], y[SRV_RUN];
} request_lanes;

FXC_HOT_LANES static void request_lanes_fill(request_lanes *L, int32_t bias)
{
    const float fbias = (float)bias;
    for (int i = 0; i < SRV_RUN; i++) {
        int32_t level;
        float scale;
        LANE_LEVEL(L->footprint[i] + fbias, level, scale);
        float x = L->u[i] * scale, y = L->v[i] * scale;
        int32_t inside = (x >= 0.0f) & (y >= 0.0f) & (x < 32768.0f) & (y < 32768.0f); /* also 0 for NaN */
        float xc = inside ? x : 0.0f, yc = inside ? y : 0.0f; /* converted only where it fits */
        L->level[i] = level;
        L->inside[i] = inside;
        L->cx[i] = (int32_t)(xc + 0.5f);
        L->cy[i] = (int32_t)(yc + 0.5f);
        L->x[i] = x, L->y[i] = y;
    }
}

static uint32_t osc_kind_pixel_requests(const void *cache, uint32_t slot, const srv_pixel *pixels,
                                        uint32_t count, uint32_t effect, int32_t bias, uint64_t *keys,
                                        uint64_t *masks)
{
    (void)slot;
    const kind_osc *k = cache;
    const scene_island *islands = k->s->islands;
    uint32_t n = 0;
    /* Recent pixels' island, level and stencil corner, direct-mapped: a pixel with the same ones as one of
     * them asks for exactly the same texels (neighbouring pixels, beside and above, often do: a texel of a
     * coarser level spans several pixels), so it is skipped. */
    enum { SEEN = 64 };
    uint64_t seen[SEEN];
    memset(seen, 0xFF, sizeof seen);
    uint32_t memo_island = UINT32_MAX, width0 = 0, height0 = 0; /* the last island's size */
    request_lanes L;
    for (uint32_t first = 0; first < count; first += SRV_RUN) {
        uint32_t lanes = count - first < SRV_RUN ? count - first : SRV_RUN, i = 0;
        for (; i < lanes; i++) {
            L.u[i] = pixels[first + i].island_u;
            L.v[i] = pixels[first + i].island_v;
            L.footprint[i] = pixels[first + i].footprint;
        }
        for (; i < SRV_RUN; i++)
            L.u[i] = L.v[i] = L.footprint[i] = 0.0f;
        request_lanes_fill(&L, bias);
        for (i = 0; i < lanes; i++) {
            const srv_pixel *px = &pixels[first + i];
            uint32_t level = (uint32_t)L.level[i];
            if (L.inside[i]) {
                /* floor(x - 0.5) + 1, 16 bits each: level 4, island 28 bits (the id rotated left by one:
                 * its index, then its side bit; islands of index 2^27 and beyond are not deduped) */
                uint64_t cx = (uint64_t)L.cx[i], cy = (uint64_t)L.cy[i];
                uint32_t island = px->island << 1 | px->island >> 31;
                uint64_t signature = (uint64_t)island << 36 | (uint64_t)level << 32 | cy << 16 | cx;
                uint32_t seen_slot = (uint32_t)((signature * 0x9E3779B97F4A7C15ull) >> 58); /* 6 bits: SEEN */
                if (island < (1u << 28)) {
                    if (seen[seen_slot] == signature)
                        continue;
                    seen[seen_slot] = signature;
                }
            }
            if (px->island != memo_island) {
                memo_island = px->island;
                width0 = islands[memo_island & SCENE_ISLAND_INDEX].width;
                height0 = islands[memo_island & SCENE_ISLAND_INDEX].height;
            }
            n += osc_bilinear_keys(effect, px->island, width0, height0, level, L.x[i], L.y[i], keys + n,
                                   masks + n);
        }
    }
    return n;
}

static uint32_t osc_kind_key_effect(uint64_t key)
{
    return osc_key_effect(key);
}

static uint64_t osc_kind_rekey(uint64_t key, uint32_t effect)
{
    return (key & ~((uint64_t)0xF << OSC_KEY_EFFECT_SHIFT)) | ((uint64_t)effect << OSC_KEY_EFFECT_SHIFT);
}

static fxc_result osc_kind_request_batch(void *cache, uint32_t slot, uint32_t effect, uint64_t *keys,
                                         uint64_t *masks, size_t count, size_t *unique, uint32_t *blocks,
                                         uint64_t *pool_exhausted, uint64_t *table_full)
{
    (void)slot, (void)effect; /* every viewer and effect meet in one table; keys carry their effect */
    kind_osc *k = cache;
    osc_stats before;
    osc_stats_get(k->osc, &before);
    osc_result r = osc_request_batch(k->osc, keys, masks, count, unique, blocks);
    osc_stats after;
    osc_stats_get(k->osc, &after);
    *pool_exhausted += after.exhausted - before.exhausted;
    *table_full += after.table_full - before.table_full;
    return (fxc_result)r;
}

static const uint32_t *osc_kind_frame_blocks(void *cache, uint32_t effect, uint32_t *count)
{
    return osc_frame_blocks(((kind_osc *)cache)->osc, effect, count);
}

static uint64_t osc_kind_block_key(const void *cache, uint32_t effect, uint32_t block)
{
    return osc_block_key(((const kind_osc *)cache)->osc, effect, block);
}

static uint64_t osc_kind_block_requested(const void *cache, uint32_t effect, uint32_t block)
{
    return osc_block_requested(((const kind_osc *)cache)->osc, effect, block);
}

static uint64_t osc_kind_block_valid(const void *cache, uint32_t effect, uint32_t block)
{
    return osc_block_valid(((const kind_osc *)cache)->osc, effect, block);
}

static void osc_kind_block_set_valid(void *cache, uint32_t effect, uint32_t block, uint64_t valid)
{
    osc_block_set_valid(((kind_osc *)cache)->osc, effect, block, valid);
}

static void *osc_kind_block_payload(void *cache, uint32_t effect, uint32_t block)
{
    return osc_block_payload(((kind_osc *)cache)->osc, effect, block);
}

static uint32_t osc_kind_find(const void *cache, uint32_t effect, uint64_t key)
{
    (void)effect;
    return osc_find(((const kind_osc *)cache)->osc, key);
}

static void osc_kind_job_location(const void *cache, uint32_t effect, uint64_t key, fx_block_job *job)
{
    (void)cache, (void)effect;
    osc_key_fields f = osc_key_unpack(key);
    job->key = key;
    job->island = f.island_id & SCENE_ISLAND_INDEX;
    job->back = (f.island_id & SCENE_ISLAND_BACK) != 0;
    job->level = f.level;
    job->block_x = f.block_x;
    job->block_y = f.block_y;
}

static uint64_t osc_kind_finer_texels(void *cache, uint32_t effect, uint32_t block, uint64_t need,
                                      const void *finer[64][4])
{
    kind_osc *k = cache;
    osc_key_fields key = osc_key_unpack(osc_block_key(k->osc, effect, block));
    if (key.level == 0 || need == 0)
        return 0;
    const scene_island *island = &k->s->islands[key.island_id & SCENE_ISLAND_INDEX]; /* either side */
    uint32_t fine_w = osc_level_size(island->width, key.level - 1);
    uint32_t fine_h = osc_level_size(island->height, key.level - 1);
    uint32_t texel_bytes = osc_pool_texel_bytes(k->osc, effect);
    /* The up to four finer blocks under this one, looked up once. */
    uint32_t fine_block[2][2];
    uint64_t fine_valid[2][2] = {{0, 0}, {0, 0}};
    const uint8_t *fine_payload[2][2] = {{NULL, NULL}, {NULL, NULL}};
    for (uint32_t dy = 0; dy < 2; dy++)
        for (uint32_t dx = 0; dx < 2; dx++) {
            uint32_t bx = 2 * key.block_x + dx, by = 2 * key.block_y + dy;
            fine_block[dy][dx] = OSC_NONE;
            if (bx * 8 < fine_w && by * 8 < fine_h && bx <= OSC_MAX_BLOCK_COORD && by <= OSC_MAX_BLOCK_COORD)
                fine_block[dy][dx] =
                    osc_find(k->osc, osc_key_pack(effect, key.island_id, key.level - 1, bx, by));
            if (fine_block[dy][dx] != OSC_NONE) {
                fine_valid[dy][dx] = osc_block_valid(k->osc, effect, fine_block[dy][dx]);
                fine_payload[dy][dx] = osc_block_payload(k->osc, effect, fine_block[dy][dx]);
            }
        }
    uint64_t found = 0;
    for (uint64_t m = need; m; m &= m - 1) {
        uint32_t t = (uint32_t)__builtin_ctzll(m);
        uint32_t tx = key.block_x * 8 + (t & 7), ty = key.block_y * 8 + (t >> 3);
        bool ok = true;
        for (uint32_t c = 0; c < 4 && ok; c++) {
            uint32_t cx = 2 * tx + (c & 1), cy = 2 * ty + (c >> 1);
            if (cx >= fine_w || cy >= fine_h) {
                ok = false;
                break;
            }
            uint32_t by = (cy / 8) - 2 * key.block_y, bx = (cx / 8) - 2 * key.block_x;
            uint32_t ct = (cy & 7) * 8 + (cx & 7);
            if (fine_block[by][bx] == OSC_NONE || !(fine_valid[by][bx] >> ct & 1)) {
                ok = false;
                break;
            }
            finer[t][c] = fine_payload[by][bx] + (size_t)ct * texel_bytes;
        }
        if (ok)
            found |= (uint64_t)1 << t;
    }
    return found;
}

/* The blocks one call of osc_kind_pixel_taps has read, direct-mapped by key: neighbouring pixels of a run
 * read the same two to four blocks, so most taps find theirs here with one compare instead of a probe of the
 * table. A block found is constant within compose, so how often an entry is replaced changes nothing. */
enum { TAP_MEMO = 16 };
typedef struct tap_memo {
    uint64_t key[TAP_MEMO];
    uint32_t block[TAP_MEMO];
    uint64_t valid[TAP_MEMO];
    const uint8_t *payload[TAP_MEMO];
} tap_memo;

/* The memo slot holding key (looked up in the cache when it is not there yet). */
FXC_HOT_INLINE uint32_t memo_lookup(const osc_cache *osc, tap_memo *memo, uint32_t effect, uint64_t key)
{
    uint32_t m = (uint32_t)((key * 0x9E3779B97F4A7C15ull) >> 60); /* 4 bits: TAP_MEMO */
    if (memo->key[m] == key)
        return m;
    memo->key[m] = key;
    memo->block[m] = osc_find(osc, key);
    memo->valid[m] = 0;
    memo->payload[m] = NULL;
    if (memo->block[m] != OSC_NONE) {
        memo->valid[m] = osc_block_valid(osc, effect, memo->block[m]);
        memo->payload[m] = osc_block_payload((osc_cache *)osc, effect, memo->block[m]);
    }
    return m;
}

/* The taps of the common case: four texels of one block, all holding data, weights above 0 (renormalised),
 * in the order (x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1). */
FXC_HOT_INLINE void four_taps(fx_taps *out, const uint8_t *const texel[4], float w00, float w10, float w01,
                              float w11, float x, float y, long tx0, long tx1, long ty0, long ty1)
{
    out->texel[0] = texel[0];
    out->texel[1] = texel[1];
    out->texel[2] = texel[2];
    out->texel[3] = texel[3];
    float total = w00 + w10 + w01 + w11;
    float inv = 1.0f / total;
    out->weight[0] = w00 * inv;
    out->weight[1] = w10 * inv;
    out->weight[2] = w01 * inv;
    out->weight[3] = w11 * inv;
    float at_x0 = x + 0.5f - (float)tx0, at_x1 = x + 0.5f - (float)tx1;
    float at_y0 = y + 0.5f - (float)ty0, at_y1 = y + 0.5f - (float)ty1;
    out->at_x[0] = at_x0, out->at_x[1] = at_x1, out->at_x[2] = at_x0, out->at_x[3] = at_x1;
    out->at_y[0] = at_y0, out->at_y[1] = at_y0, out->at_y[2] = at_y1, out->at_y[3] = at_y1;
    out->count = 4;
}

/* The per-pixel arithmetic of the taps for a whole run at once, in structure of arrays over SRV_RUN lanes (a
 * fixed trip count, so GCC vectorises the loop: 8 pixels per instruction in the x86-64-v3 copy). The same IEEE
 * operations in the same order as one pixel at a time: the level as srv__level() gives it, 2^-level built
 * from its exponent bits (the table's values exactly), the bilinear weights renormalised with one reciprocal,
 * and the taps' positions for the usual case (columns and rows not clamped: there (float)x0 is floor(x)).
 * Computed from a srv_pixel_lanes (the pixels' island UVs, footprints, islands and island sizes; lanes past
 * the run are 0): the caller's, or a copy of the pixels' values when it has none. */
typedef struct taps_lanes {
    int32_t level[SRV_RUN], positive[SRV_RUN]; /* positive: all four weights > 0 */
    float x[SRV_RUN], y[SRV_RUN], fx0[SRV_RUN], fy0[SRV_RUN], ax[SRV_RUN], ay[SRV_RUN];
    /* The usual case's values in the order fx_taps holds them, per lane, so that a pixel copies them with a
     * few wide moves: the renormalised weights (for positive lanes), at_x and at_y of the four taps. */
    float weight[SRV_RUN][4];
    float at_x[SRV_RUN][4], at_y[SRV_RUN][4];
    float footprint_log2[SRV_RUN];
    /* floor(x), floor(y) where the usual case may apply (all four weights > 0, both in [0, 2^24)), else -1:
     * one unsigned compare per axis against the island's size then decides whether the columns and rows
     * lie inside it. */
    int32_t fast_x0[SRV_RUN], fast_y0[SRV_RUN];
    /* Whether the pixel is the usual case up to the blocks' contents (fast_x0 above, columns and rows inside the island at its level, the island's size
     * there below 2^24), whether its four texels straddle a block edge (x0 mod 8 or y0 mod 8 is 7), the
     * corner texel's block key without the effect field and the corner texel's index in that block. */
    int32_t fast[SRV_RUN], straddle[SRV_RUN], cell[SRV_RUN];
    uint64_t key[SRV_RUN];
} taps_lanes;

/* A pixel's four taps' weights, positions and footprint as the lanes computed them (its texels are the
 * caller's). */
static inline void taps_from_lanes(fx_taps *out, const taps_lanes *L, size_t i)
{
    memcpy(out->weight, L->weight[i], sizeof L->weight[i]);
    memcpy(out->at_x, L->at_x[i], sizeof L->at_x[i]);
    memcpy(out->at_y, L->at_y[i], sizeof L->at_y[i]);
    out->footprint_log2 = L->footprint_log2[i];
    out->count = 4;
}

FXC_HOT_LANES static void taps_lanes_fill(taps_lanes *restrict L, const srv_pixel_lanes *restrict in,
                                          int32_t bias)
{
    const float fbias = (float)bias;
    for (int i = 0; i < SRV_RUN; i++) {
        int32_t level;
        float scale;
        LANE_LEVEL(in->footprint[i] + fbias, level, scale);
        float x = in->island_u[i] * scale - 0.5f, y = in->island_v[i] * scale - 0.5f;
        float fx0 = floorf(x), fy0 = floorf(y);
        float ax = x - fx0, ay = y - fy0;
        float wx0 = 1 - ax, wy0 = 1 - ay;
        float w00 = wx0 * wy0, w10 = ax * wy0, w01 = wx0 * ay, w11 = ax * ay;
        float total = w00 + w10 + w01 + w11;
        float inv = 1.0f / total;
        L->level[i] = level;
        L->positive[i] = (w00 > 0) & (w10 > 0) & (w01 > 0) & (w11 > 0);
        L->x[i] = x, L->y[i] = y, L->fx0[i] = fx0, L->fy0[i] = fy0, L->ax[i] = ax, L->ay[i] = ay;
        L->weight[i][0] = w00 * inv;
        L->weight[i][1] = w10 * inv;
        L->weight[i][2] = w01 * inv;
        L->weight[i][3] = w11 * inv;
        float at_x0 = x + 0.5f - fx0, at_x1 = x + 0.5f - (fx0 + 1.0f);
        float at_y0 = y + 0.5f - fy0, at_y1 = y + 0.5f - (fy0 + 1.0f);
        L->at_x[i][0] = at_x0, L->at_x[i][1] = at_x1, L->at_x[i][2] = at_x0, L->at_x[i][3] = at_x1;
        L->at_y[i][0] = at_y0, L->at_y[i][1] = at_y0, L->at_y[i][2] = at_y1, L->at_y[i][3] = at_y1;
        L->footprint_log2[i] = in->footprint[i] - (float)level;
        int32_t fast =
            L->positive[i] & (fx0 >= 0.0f) & (fy0 >= 0.0f) & (fx0 < 16777216.0f) & (fy0 < 16777216.0f);
        float fxc = fast ? fx0 : -1.0f, fyc = fast ? fy0 : -1.0f; /* converted only where it fits */
        L->fast_x0[i] = (int32_t)fxc;
        L->fast_y0[i] = (int32_t)fyc;
    }
}

/* After taps_lanes_fill: fast, cell and key (in loops of their own, which GCC vectorises). */
FXC_HOT_LANES static void taps_lanes_fast(taps_lanes *restrict L, const srv_pixel_lanes *restrict in)
{
    for (int i = 0; i < SRV_RUN; i++) {
        int32_t x0 = L->fast_x0[i], y0 = L->fast_y0[i], level = L->level[i];
        int32_t round = (1 << level) - 1;
        int32_t w = (int32_t)((in->width0[i] + (uint32_t)round) >> level);
        int32_t h = (int32_t)((in->height0[i] + (uint32_t)round) >> level);
        int32_t small = (w > 0) & (h > 0) & (w < (1 << 24)) & (h < (1 << 24));
        L->fast[i] = (x0 >= 0) & small & (x0 + 1 < w) & (y0 + 1 < h);
        L->straddle[i] = ((x0 & 7) == 7) | ((y0 & 7) == 7);
        L->cell[i] = (y0 & 7) * 8 + (x0 & 7);
    }
    for (int i = 0; i < SRV_RUN; i++)
        L->key[i] = ((uint64_t)in->island[i] << OSC_KEY_ISLAND_SHIFT) |
                    ((uint64_t)(uint32_t)L->level[i] << OSC_KEY_LEVEL_SHIFT) |
                    ((uint64_t)(uint32_t)(L->fast_y0[i] >> 3) << OSC_KEY_BLOCK_Y_SHIFT) |
                    ((uint64_t)(uint32_t)(L->fast_x0[i] >> 3) << OSC_KEY_BLOCK_X_SHIFT);
}

/* One effect's lookup state across the pixels of a call: its memo of blocks, the island and level of the
 * previous pixel (their size and key fields), and the four texels of the last pixel that took the common
 * path (its corner texel and block). */
typedef struct taps_state {
    const osc_cache *osc;
    const scene_island *islands;
    size_t texel_bytes;
    uint32_t effect;
    uint64_t effect_field;
    uint32_t memo_island, memo_level;
    long w, h;
    uint64_t base;
    /* The usual case's bounds: w - 1 and h - 1 when the island's size at this level is below 2^24 (a column
     * or row is exact in a float), else 0 (never the usual case). */
    uint32_t fast_w, fast_h;
    uint32_t last_slot; /* the memo slot of the previous pixel's first block */
    bool reuse;
    long reuse_x0, reuse_y0;
    const uint8_t *reuse_texel[4];
    uint32_t reuse_block;
    tap_memo memo;
} taps_state;

/* Remembers the four texels (rows row0/row1, columns col0/col1, as offsets within the block) of one block's
 * payload for the pixel whose footprint corner is (x0, y0): the next pixel with the same corner reuses them. */
static inline void reuse_block_texels(taps_state *st, const uint8_t *payload, uint32_t block,
                                      size_t texel_bytes, uint32_t row0, uint32_t row1, uint32_t col0,
                                      uint32_t col1, long x0, long y0)
{
    st->reuse_texel[0] = payload + (row0 + col0) * texel_bytes;
    st->reuse_texel[1] = payload + (row0 + col1) * texel_bytes;
    st->reuse_texel[2] = payload + (row1 + col0) * texel_bytes;
    st->reuse_texel[3] = payload + (row1 + col1) * texel_bytes;
    st->reuse = true, st->reuse_x0 = x0, st->reuse_y0 = y0, st->reuse_block = block;
}

/* A new island or level: its size at the level and the keys' fields. */
FXC_HOT_INLINE void taps_state_island(taps_state *st, uint32_t island, uint32_t level)
{
    st->memo_island = island;
    st->memo_level = level;
    const scene_island *is = &st->islands[island & SCENE_ISLAND_INDEX]; /* either side's */
    st->w = (long)((is->width + (1u << level) - 1u) >> level);
    st->h = (long)((is->height + (1u << level) - 1u) >> level);
    bool small = st->w > 0 && st->h > 0 && st->w < (1l << 24) && st->h < (1l << 24);
    st->fast_w = small ? (uint32_t)st->w - 1u : 0u;
    st->fast_h = small ? (uint32_t)st->h - 1u : 0u;
    st->base = st->effect_field | ((uint64_t)island << OSC_KEY_ISLAND_SHIFT) |
               ((uint64_t)level << OSC_KEY_LEVEL_SHIFT);
    st->reuse = false;
}

/* Pixel i's taps when the usual case's quick paths (taps_of_effect) did not give them: columns or rows
 * clamped at the island's edge, a weight 0, a footprint straddling a block edge, texels without data. The
 * island and level of st are the pixel's. */
static void taps_pixel_rest(taps_state *st, const taps_lanes *L, const srv_pixel_lanes *P, uint32_t i,
                            fx_taps *out, uint32_t *blocks)
{
    const osc_cache *osc = st->osc;
    const size_t texel_bytes = st->texel_bytes;
    const uint32_t effect = st->effect;
    tap_memo *memo = &st->memo;
    const uint32_t island = P->island[i];
    if (island != st->memo_island || (uint32_t)L->level[i] != st->memo_level)
        taps_state_island(st, island, (uint32_t)L->level[i]);
    const long w = st->w, h = st->h;
    const uint64_t base = st->base;
    uint32_t level = st->memo_level;
    float x = L->x[i], y = L->y[i], ax = L->ax[i], ay = L->ay[i];
    long x0 = (long)L->fx0[i], y0 = (long)L->fy0[i];
    uint32_t fast_x0 = (uint32_t)L->fast_x0[i], fast_y0 = (uint32_t)L->fast_y0[i];
    bool found = false;
    if (fast_x0 < st->fast_w && fast_y0 < st->fast_h) {
        /* The usual case, columns and rows inside the island, no weight 0. When the four texels lie in one
         * block and hold data, the taps are the lanes' values: what the paths below give, value for value. */
        found = st->reuse && x0 == st->reuse_x0 && y0 == st->reuse_y0;
        if (!found && (x0 & 7) != 7 && (y0 & 7) != 7) {
            uint64_t key0 = base | ((uint64_t)(y0 >> 3) << OSC_KEY_BLOCK_Y_SHIFT) |
                            ((uint64_t)(x0 >> 3) << OSC_KEY_BLOCK_X_SHIFT);
            if (memo->key[st->last_slot] != key0)
                st->last_slot = memo_lookup(osc, memo, effect, key0);
            uint32_t m0 = st->last_slot;
            uint32_t row0 = ((uint32_t)y0 & 7) * 8, row1 = row0 + 8;
            uint32_t col0 = (uint32_t)x0 & 7, col1 = col0 + 1;
            uint64_t need = (uint64_t)3 << (row0 + col0) | (uint64_t)3 << (row1 + col0);
            if (memo->block[m0] != OSC_NONE && (memo->valid[m0] & need) == need) {
                reuse_block_texels(st, memo->payload[m0], memo->block[m0], texel_bytes, row0, row1, col0,
                                   col1, x0, y0);
                found = true;
            }
        }
    }
    if (found) {
        memcpy(out->texel, st->reuse_texel, sizeof st->reuse_texel);
        taps_from_lanes(out, L, i);
        if (blocks)
            blocks[i] = st->reuse_block;
        return;
    }
    if (fast_x0 < st->fast_w && fast_y0 < st->fast_h && !((x0 & 7) != 7 && (y0 & 7) != 7)) {
        /* The usual case, the footprint straddling a block edge: each tap's block from the memo. When all
         * four texels hold data the general path below keeps all four taps, in this order, with the lanes'
         * weights and positions (its total starts from 0 + w00 = w00). */
        const uint8_t *texel[4];
        uint32_t block0 = OSC_NONE;
        bool all = true;
#pragma GCC unroll 4
        for (int t = 0; t < 4 && all; t++) {
            long xi = x0 + (t & 1), yi = y0 + (t >> 1);
            uint32_t m = memo_lookup(osc, memo, effect,
                                     base | ((uint64_t)(yi >> 3) << OSC_KEY_BLOCK_Y_SHIFT) |
                                         ((uint64_t)(xi >> 3) << OSC_KEY_BLOCK_X_SHIFT));
            uint32_t tx = ((uint32_t)yi & 7) * 8 + ((uint32_t)xi & 7);
            all = memo->block[m] != OSC_NONE && (memo->valid[m] >> tx & 1);
            if (all) {
                texel[t] = memo->payload[m] + tx * texel_bytes;
                block0 = t == 0 ? memo->block[m] : block0;
            }
        }
        if (all) {
            for (int t = 0; t < 4; t++)
                st->reuse_texel[t] = texel[t];
            st->reuse = true, st->reuse_x0 = x0, st->reuse_y0 = y0, st->reuse_block = block0;
            memcpy(out->texel, st->reuse_texel, sizeof st->reuse_texel);
            taps_from_lanes(out, L, i);
            if (blocks)
                blocks[i] = block0;
            return;
        }
    }
    /* The two columns and rows, clamped to the island (one test each for the usual case, inside it), in
     * scalars: arrays indexed by the tap are built only for the general path below. */
    long tx0 = x0, tx1 = x0 + 1, ty0 = y0, ty1 = y0 + 1;
    if (!(x0 >= 0 && x0 + 1 < w)) {
        tx0 = tx0 < 0 ? 0 : (tx0 >= w ? w - 1 : tx0);
        tx1 = tx1 < 0 ? 0 : (tx1 >= w ? w - 1 : tx1);
    }
    if (!(y0 >= 0 && y0 + 1 < h)) {
        ty0 = ty0 < 0 ? 0 : (ty0 >= h ? h - 1 : ty0);
        ty1 = ty1 < 0 ? 0 : (ty1 >= h ? h - 1 : ty1);
    }
    float wx0 = 1 - ax, wx1 = ax, wy0 = 1 - ay, wy1 = ay;
    out->footprint_log2 = P->footprint[i] - (float)level;
    float w00 = wx0 * wy0, w10 = wx1 * wy0, w01 = wx0 * wy1, w11 = wx1 * wy1;
    bool positive = w00 > 0 && w10 > 0 && w01 > 0 && w11 > 0;
    if (st->reuse && x0 == st->reuse_x0 && y0 == st->reuse_y0 && positive) {
        /* The previous pixel's four texels (same island, level and corner texel, and it took the common
         * path below): the same block, texels and data, known without the key and the memo. */
        four_taps(out, st->reuse_texel, w00, w10, w01, w11, x, y, tx0, tx1, ty0, ty1);
        if (blocks)
            blocks[i] = st->reuse_block;
        return;
    }
    st->reuse = false;
    uint32_t tap_memo_slot[4];
    uint64_t key0 = base | ((uint64_t)(ty0 >> 3) << OSC_KEY_BLOCK_Y_SHIFT) |
                    ((uint64_t)(tx0 >> 3) << OSC_KEY_BLOCK_X_SHIFT);
    if (memo->key[st->last_slot] != key0) /* the slot may since hold another block */
        st->last_slot = memo_lookup(osc, memo, effect, key0);
    tap_memo_slot[0] = st->last_slot;
    bool same_x = (tx0 >> 3) == (tx1 >> 3), same_y = (ty0 >> 3) == (ty1 >> 3);
    uint32_t m0 = tap_memo_slot[0];
    if (same_x && same_y && memo->block[m0] != OSC_NONE) {
        /* The common case, straight-line: four texels of one block, all holding data, no weight 0. What
         * the general path below gives for it, operation for operation. */
        uint32_t row0 = ((uint32_t)ty0 & 7) * 8, row1 = ((uint32_t)ty1 & 7) * 8;
        uint32_t col0 = (uint32_t)tx0 & 7, col1 = (uint32_t)tx1 & 7;
        uint64_t need = (uint64_t)1 << (row0 + col0) | (uint64_t)1 << (row0 + col1) |
                        (uint64_t)1 << (row1 + col0) | (uint64_t)1 << (row1 + col1);
        if ((memo->valid[m0] & need) == need && positive) {
            reuse_block_texels(st, memo->payload[m0], memo->block[m0], texel_bytes, row0, row1, col0, col1,
                               x0, y0);
            four_taps(out, st->reuse_texel, w00, w10, w01, w11, x, y, tx0, tx1, ty0, ty1);
            if (blocks)
                blocks[i] = st->reuse_block;
            return;
        }
    }
    const long tx[2] = {tx0, tx1}, ty[2] = {ty0, ty1};
    const float wx[2] = {wx0, wx1}, wy[2] = {wy0, wy1};
#pragma GCC unroll 4
    for (int t = 1; t < 4; t++) {
        long xi = tx[t & 1], yi = ty[t >> 1];
        bool same = ((t & 1) == 0 || same_x) && ((t >> 1) == 0 || same_y);
        tap_memo_slot[t] = same ? tap_memo_slot[0]
                                : memo_lookup(osc, memo, effect,
                                              base | ((uint64_t)(yi >> 3) << OSC_KEY_BLOCK_Y_SHIFT) |
                                                  ((uint64_t)(xi >> 3) << OSC_KEY_BLOCK_X_SHIFT));
    }
    float total = 0;
    uint32_t n = 0;
    uint32_t first_block = SRV_NONE;
#pragma GCC unroll 4
    for (int t = 0; t < 4; t++) {
        uint32_t m = tap_memo_slot[t];
        if (memo->block[m] == OSC_NONE)
            continue;
        if (first_block == SRV_NONE)
            first_block = memo->block[m];
        long xi = tx[t & 1], yi = ty[t >> 1];
        uint32_t texel = ((uint32_t)yi & 7) * 8 + ((uint32_t)xi & 7);
        float weight = wx[t & 1] * wy[t >> 1];
        /* Written always, kept only when the texel holds data and the weight is not 0 (no branch). */
        bool keep = (memo->valid[m] >> texel & 1) && !(weight <= 0);
        out->texel[n] = memo->payload[m] + texel * texel_bytes;
        out->weight[n] = weight;
        out->at_x[n] = x + 0.5f - (float)xi;
        out->at_y[n] = y + 0.5f - (float)yi;
        total += keep ? weight : 0.0f;
        n += keep;
    }
    out->count = n;
    if (blocks)
        blocks[i] = first_block;
    float inv = n ? 1.0f / total : 0.0f;
    for (uint32_t t = 0; t < n; t++)
        out->weight[t] *= inv;
}

/* The usual case's four texels when they straddle a block edge (x0, y0 inside the island, key the corner
 * texel's block with the effect field): each tap's block from the memo; false when a block is absent or a
 * texel holds no data. *block receives the first tap's block. (Looking up only the two or four distinct
 * blocks, with branches, was more instructions.) */
static bool taps_straddle(taps_state *st, int32_t x0, int32_t y0, uint64_t key, const uint8_t *texel[4],
                          uint32_t *block)
{
    const uint64_t base =
        key & ~(((uint64_t)0xFFF << OSC_KEY_BLOCK_Y_SHIFT) | ((uint64_t)0xFFF << OSC_KEY_BLOCK_X_SHIFT));
#pragma GCC unroll 4
    for (int t = 0; t < 4; t++) { /* unrolled: each tap's offsets and the t == 0 test are constants */
        uint32_t xi = (uint32_t)x0 + (uint32_t)(t & 1), yi = (uint32_t)y0 + (uint32_t)(t >> 1);
        uint32_t m = memo_lookup(st->osc, &st->memo, st->effect,
                                 base | ((uint64_t)(yi >> 3) << OSC_KEY_BLOCK_Y_SHIFT) |
                                     ((uint64_t)(xi >> 3) << OSC_KEY_BLOCK_X_SHIFT));
        uint32_t tx = (yi & 7) * 8 + (xi & 7);
        if (st->memo.block[m] == OSC_NONE || !(st->memo.valid[m] >> tx & 1))
            return false;
        texel[t] = st->memo.payload[m] + tx * st->texel_bytes;
        if (t == 0)
            *block = st->memo.block[m];
    }
    return true;
}

/* One effect's taps of a run from the lanes (taps_lanes_fill at the call's bias): per pixel the bilinear taps
 * at its level, in the order (x0, y0), (x0 + 1, y0), (x0, y0 + 1),
 * (x0 + 1, y0 + 1) with texels clamped to the island, leaving out taps whose block is absent, whose texel
 * holds no data or whose weight is 0; the weights renormalised. The four texels lie in one block unless the
 * footprint straddles a block edge, so the block of a tap is looked up only where its block coordinates
 * differ from the first tap's.
 *
 * The usual case (columns and rows inside the island, no weight 0, the four texels holding data; in one
 * block or, through taps_straddle, straddling a block edge) is this loop's, decided by the lanes up to the
 * blocks' contents (taps_lanes_fast), with the few variables it needs in locals: the previous pixel's key,
 * corner texel and four texels (a pixel with the same ones gets the same taps without the memo). Its taps are
 * the lanes' values, what the general path of taps_pixel_rest gives, value for value. Every other pixel goes
 * through taps_pixel_rest, the general loop body with its state in a struct, not inlined: in one function
 * with the usual case, their state together outnumbered the registers and the usual case ran from the stack. */
FXC_HOT_INLINE uint32_t taps_of_effect(const kind_osc *k, const taps_lanes *L, const srv_pixel_lanes *P,
                                       uint32_t count, uint32_t effect, fx_taps *taps, uint32_t *blocks)
{
    uint32_t empty = 0; /* taps with count 0: only the general path gives them */
    taps_state st;
    st.osc = k->osc;
    st.islands = k->s->islands;
    st.texel_bytes = osc_pool_texel_bytes(st.osc, effect);
    st.effect = effect;
    st.effect_field = (uint64_t)effect << OSC_KEY_EFFECT_SHIFT;
    memset(st.memo.key, 0xFF, sizeof st.memo.key); /* no key has every bit set (effect field 15) */
    st.memo_island = st.memo_level = UINT32_MAX;
    st.w = st.h = 0;
    st.base = 0;
    st.fast_w = st.fast_h = 0;
    st.last_slot = 0;
    st.reuse = false;
    st.reuse_x0 = st.reuse_y0 = 0;
    for (int t = 0; t < 4; t++)
        st.reuse_texel[t] = NULL;
    st.reuse_block = 0;
    const osc_cache *osc = st.osc;
    const size_t texel_bytes = st.texel_bytes;
    const uint64_t effect_field = st.effect_field;
    /* The usual case's last block and corner texel (its key with the effect field, UINT64_MAX: none). */
    uint64_t reuse_key = UINT64_MAX;
    int32_t reuse_cell = -1;
    const uint8_t *t0 = NULL, *t1 = NULL, *t2 = NULL, *t3 = NULL; /* its four texels */
    uint32_t reuse_block = 0, last_slot = 0;
    for (uint32_t i = 0; i < count; i++) {
        fx_taps *out = &taps[i];
        if (L->fast[i]) {
            uint64_t key = L->key[i] | effect_field;
            int32_t cell = L->cell[i];
            if (key != reuse_key || cell != reuse_cell) {
                if (!L->straddle[i]) {
                    if (st.memo.key[last_slot] != key)
                        last_slot = memo_lookup(osc, &st.memo, effect, key);
                    uint32_t m0 = last_slot;
                    uint64_t need = (uint64_t)3 << cell | (uint64_t)3 << (cell + 8);
                    if (!(st.memo.block[m0] != OSC_NONE && (st.memo.valid[m0] & need) == need))
                        goto rest;
                    /* The texels (x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1) of the block. */
                    const uint8_t *corner = st.memo.payload[m0] + (size_t)cell * texel_bytes;
                    t0 = corner, t1 = corner + texel_bytes, t2 = corner + 8 * texel_bytes;
                    t3 = corner + 9 * texel_bytes;
                    reuse_block = st.memo.block[m0];
                } else {
                    const uint8_t *t[4];
                    if (!taps_straddle(&st, L->fast_x0[i], L->fast_y0[i], key, t, &reuse_block))
                        goto rest;
                    t0 = t[0], t1 = t[1], t2 = t[2], t3 = t[3];
                }
                reuse_key = key, reuse_cell = cell;
            }
            out->texel[0] = t0;
            out->texel[1] = t1;
            out->texel[2] = t2;
            out->texel[3] = t3;
            taps_from_lanes(out, L, i);
            if (blocks)
                blocks[i] = reuse_block;
            continue;
        }
    rest:
        st.last_slot = last_slot;
        taps_pixel_rest(&st, L, P, i, out, blocks);
        last_slot = st.last_slot;
        empty += out->count == 0;
    }
    return empty;
}

/* The kind interface's taps: the lanes once for all the call's effects (they share the bias, so the level,
 * weights and positions), then each effect's lookups as above (its own memo, in a loop of its own: state
 * shared across effects in one loop was slower, kept in memory instead of registers). */
FXC_HOT_CLONES static uint32_t osc_kind_pixel_taps(const void *cache, uint32_t slot, uint32_t thread,
                                                   const srv_pixel *pixels, const srv_pixel_lanes *lanes,
                                                   uint32_t count, uint32_t effect_count,
                                                   const uint32_t *effects, int32_t bias,
                                                   fx_taps *const *taps, uint32_t *const *blocks)
{
    (void)slot, (void)thread;
    const kind_osc *k = cache;
    taps_lanes L;
    srv_pixel_lanes copy;
    if (!lanes) { /* the pixels' values into lanes of our own */
        uint32_t i = 0;
        const scene_island *islands = k->s->islands;
        for (; i < count; i++) {
            copy.island_u[i] = pixels[i].island_u;
            copy.island_v[i] = pixels[i].island_v;
            copy.footprint[i] = pixels[i].footprint;
            uint32_t island = pixels[i].island;
            copy.island[i] = island;
            copy.width0[i] = islands[island & SCENE_ISLAND_INDEX].width;
            copy.height0[i] = islands[island & SCENE_ISLAND_INDEX].height;
        }
        for (; i < SRV_RUN; i++) {
            copy.island_u[i] = copy.island_v[i] = copy.footprint[i] = 0.0f;
            copy.island[i] = copy.width0[i] = copy.height0[i] = 0;
        }
        lanes = &copy;
    }
    taps_lanes_fill(&L, lanes, bias);
    taps_lanes_fast(&L, lanes);
    uint32_t empty = 0;
    for (uint32_t j = 0; j < effect_count; j++)
        empty += taps_of_effect(k, &L, lanes, count, effects[j], taps[j], blocks ? blocks[j] : NULL);
    return empty;
}

static uint32_t osc_kind_pool_capacity(const void *cache, uint32_t effect)
{
    return osc_pool_capacity(((const kind_osc *)cache)->osc, effect);
}

static void osc_kind_housekeeping(void *cache)
{
    osc_housekeeping(((kind_osc *)cache)->osc);
}

static void osc_kind_frame_figures(const void *cache, srv_frame_stats *st)
{
    osc_stats os;
    osc_stats_get(((const kind_osc *)cache)->osc, &os);
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS && e < OSC_MAX_EFFECTS; e++)
        st->blocks_resident[e] += os.effects[e].blocks_resident;
    st->evictions += os.evictions;
    st->exhausted += os.exhausted;
    st->table_count += os.table_count;
    st->table_capacity += os.table_capacity;
}

static void osc_kind_memory(const void *cache, srv_memory *out)
{
    const kind_osc *k = cache;
    osc_memory_report m;
    osc_memory(k->osc, &m);
    out->table += m.table_key_bytes + m.table_value_bytes + m.cache_struct_bytes + sizeof *k;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS && e < OSC_MAX_EFFECTS; e++) {
        out->pools_reserved[e] += m.effects[e].payload_reserved_bytes;
        out->pools_in_use[e] += m.effects[e].payload_in_use_bytes;
        out->block_meta[e] += m.effects[e].block_meta_bytes + m.effects[e].list_bytes;
    }
    out->total += m.total_bytes + sizeof *k;
}

const srv_cache_kind srv__kind_osc = {
    .name = "on_surface",
    .kind = SCENE_CACHE_ON_SURFACE,
    .keys_carry_effect = true,
    .needs_position = false,
    .lanes_suffice = true,
    .create = osc_kind_create,
    .destroy = osc_kind_destroy,
    .begin_frame = osc_kind_begin_frame,
    .pixel_requests = osc_kind_pixel_requests,
    .key_effect = osc_kind_key_effect,
    .rekey = osc_kind_rekey,
    .request_batch = osc_kind_request_batch,
    .frame_blocks = osc_kind_frame_blocks,
    .block_key = osc_kind_block_key,
    .block_requested = osc_kind_block_requested,
    .block_valid = osc_kind_block_valid,
    .block_set_valid = osc_kind_block_set_valid,
    .block_payload = osc_kind_block_payload,
    .find = osc_kind_find,
    .job_location = osc_kind_job_location,
    .finer_texels = osc_kind_finer_texels,
    .pixel_taps = osc_kind_pixel_taps,
    .pool_capacity = osc_kind_pool_capacity,
    .housekeeping = osc_kind_housekeeping,
    .frame_figures = osc_kind_frame_figures,
    .memory = osc_kind_memory,
};
