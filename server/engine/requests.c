/* Stage 3, requests: every visible pixel asks, for every cached effect, for the texels its filter reads at
 * that effect's level (the pixel footprint plus the effect's bias), and for the same texels of the effect it
 * depends on (the triangle lookup). The keys come from the effect's cache kind, a run of pixels at a time.
 * Tiles run on the thread pool; each folds neighbouring pixels' requests for the same block in a small
 * direct-mapped buffer before appending them to its thread's list. The lists of all threads then go to the
 * kind's batch request (a sparse viewer: runs of 256 entries of its list instead of tiles), which sorts and merges them, so the cache comes out identical whatever the thread
 * interleaving. Requests of all viewers meet in the same tables: this is where sharing happens. */
#include "engine_internal.h"
#include "fxc_hot.h"

#include <math.h>
#include <stdatomic.h>
#include <string.h>

enum { FOLD_SLOTS = 64 };

/* Folds requests for the same key that arrive close together. */
typedef struct fold_buffer {
    uint64_t keys[FOLD_SLOTS];
    uint64_t masks[FOLD_SLOTS];
} fold_buffer;

typedef struct request_task {
    srv_loop *loop;
    srv_viewer *view;
    uint32_t kind;
    uint32_t effect; /* the one effect whose keys this pass gathers, or SRV_NO_EFFECT for all of the kind */
    uint32_t tiles_x;
    atomic_bool failed; /* a thread ran out of memory: this viewer's requests are dropped this frame */
} request_task;

/* Moves a folded key onto the thread's list: or-ed into the entry of the same key when the list's recent
 * table finds one (neighbouring tiles ask for the same blocks and cells: a probe cell spans tiles), else
 * appended. The batch sorts and ors equal keys' masks anyway, so the merged requests are the same; its sort
 * gets fewer keys (Sponza at 640 x 360: the probes' pass about 20,000 keys for 1,600 distinct cells, the
 * on-surface one 12,900 for 4,100 blocks, without the table). */
static bool fold_flush_slot(srv_loop *loop, fold_buffer *fold, uint32_t slot, srv_request_list *out)
{
    uint64_t key = fold->keys[slot];
    if (key == OSC_KEY_EMPTY)
        return true;
    /* the top bits of another multiplier than fold_add's (whose slot fixes the top 6 bits of its product) */
    uint32_t h = (uint32_t)((key * 0xC2B2AE3D27D4EB4Full) >> 54); /* 10 bits: SRV_REQUEST_RECENT */
    uint32_t at = out->recent[h];
    if (!loop->desc.no_request_recent && at < out->count && out->keys[at] == key) {
        out->masks[at] |= fold->masks[slot];
        fold->keys[slot] = OSC_KEY_EMPTY;
        return true;
    }
    if (out->count == out->capacity && !srv__request_reserve(loop, SRV_MEM_QUEUES, out, out->count + 1))
        return false;
    if (out->count < UINT32_MAX)
        out->recent[h] = (uint32_t)out->count;
    out->keys[out->count] = key;
    out->masks[out->count] = fold->masks[slot];
    out->count++;
    fold->keys[slot] = OSC_KEY_EMPTY;
    return true;
}

static bool fold_add(srv_loop *loop, fold_buffer *fold, uint64_t key, uint64_t mask, srv_request_list *out)
{
    uint32_t slot = (uint32_t)((key * 0x9E3779B97F4A7C15ull) >> 58); /* 6 bits: FOLD_SLOTS */
    if (fold->keys[slot] == key) {
        fold->masks[slot] |= mask;
        return true;
    }
    bool ok = fold_flush_slot(loop, fold, slot, out);
    fold->keys[slot] = key;
    fold->masks[slot] = mask;
    return ok;
}

/* What neighbouring pixels share when they see the same triangle, looked up once. */
typedef struct pixel_memo {
    uint32_t tri, island; /* the last triangle (SRV_MISS: none yet) and its island */
    float uv[6], corner[3][3];
} pixel_memo;

/* The cache pixel of buffer entry p of a viewer (visible: tri[p] != SRV_MISS). */
FXC_HOT_INLINE void fill_pixel(const scene *s, const srv_viewer *view, size_t p, bool positions,
                               pixel_memo *memo, srv_pixel *px)
{
    uint32_t tri = view->tri[p];
    if (tri != memo->tri) {
        memo->tri = tri;
        memo->island = s->tri_island[tri];
        memcpy(memo->uv, s->tri_island_uv + 6 * (size_t)tri, sizeof memo->uv);
        if (positions) {
            const uint32_t *idx = s->indices + 3 * (size_t)tri;
            for (int c = 0; c < 3; c++)
                memcpy(memo->corner[c], s->positions + 3 * (size_t)idx[c], sizeof memo->corner[c]);
        }
    }
    px->triangle = tri;
    px->island = memo->island | (uint32_t)view->back[p] << 31; /* the side seen: SCENE_ISLAND_BACK */
    px->footprint = view->footprint[p];
    float u = view->bary_u[p], v = view->bary_v[p], w = 1.0f - u - v;
    if (!positions) { /* a kind reads island UVs or positions, never both (needs_position) */
        px->island_u = w * memo->uv[0] + u * memo->uv[2] + v * memo->uv[4];
        px->island_v = w * memo->uv[1] + u * memo->uv[3] + v * memo->uv[5];
    } else {
        for (int k = 0; k < 3; k++)
            px->position[k] = w * memo->corner[0][k] + u * memo->corner[1][k] + v * memo->corner[2][k];
        px->distance = view->depth[p];
    }
}

/* The keys of up to SRV_TILE * SRV_TILE pixels, folded, onto the thread's list. */
FXC_HOT_INLINE void request_pixels(request_task *task, uint32_t thread_index, const srv_pixel *pixels,
                                   uint32_t count)
{
    srv_loop *loop = task->loop;
    const srv_viewer *view = task->view;
    const srv_cache_kind *kind = loop->kinds[task->kind];
    const void *cache = loop->caches[task->kind];
    const uint32_t viewer_slot = (uint32_t)(view - loop->viewers);
    srv_request_list *out = &loop->thread_requests[thread_index];
    fold_buffer fold;
    memset(fold.keys, 0xFF, sizeof fold.keys);
    bool ok = true;
    /* The whole tile in one call, so the kind can skip pixels that repeat one above or beside them. */
    uint64_t keys[SRV_TILE * SRV_TILE * SRV_KEYS_PER_PIXEL], masks[SRV_TILE * SRV_TILE * SRV_KEYS_PER_PIXEL];
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        if (!loop->effect_shading[e] || loop->effect_kind[e] != task->kind ||
            (task->effect != SRV_NO_EFFECT && task->effect != e))
            continue;
        /* Only the effect's own keys: its dependency's are derived after merging (half the keys). */
        uint32_t n = kind->pixel_requests(cache, viewer_slot, pixels, count, e, loop->bias[e], keys, masks);
        for (uint32_t i = 0; i < n; i++)
            ok &= fold_add(loop, &fold, keys[i], masks[i], out);
    }
    for (uint32_t f = 0; f < FOLD_SLOTS; f++)
        ok &= fold_flush_slot(loop, &fold, f, out);
    if (!ok)
        atomic_store(&task->failed, true);
}

/* srv__coarse_mask for one row of a tile, lane j for pixel (x0 + j, y) (vectorised: FXC_HOT_LANES; contiguous
 * loads only, gathers are slow on the machines we measure on): the row's pixels (triangle, face normal, depth,
 * footprint) and, expanded per column, the samples of the row of blocks the row lies in and of the next one
 * (column c holds sample c / B of its row, a miss from sample nx on; a pixel in column j reads its candidates at j and
 * j + B). The same compares and the same float operations as srv__coarse_mask and srv__coarse_match, so the
 * same mask for every visible pixel. */
enum { MASK_COLUMNS = SRV_TILE + 8 }; /* blocks of up to 8 */

typedef struct mask_row {
    uint32_t tri[SRV_TILE];
    float normal[3][SRV_TILE], depth[SRV_TILE], footprint[SRV_TILE];
    uint32_t sample_tri[2][MASK_COLUMNS];
    uint32_t
        sample_one[2]; /* the triangle of every sample of the row before nx (mask_expand), else SRV_MISS */
    float sample_normal[2][3][MASK_COLUMNS], sample_depth[2][MASK_COLUMNS], sample_footprint[2][MASK_COLUMNS];
} mask_row;

FXC_HOT_INLINE uint32_t coarse_mask_core(const mask_row *in, int32_t block, int32_t nx, int32_t fy,
                                         int32_t two_y, float depth_scale, int32_t *out, uint8_t *bytes,
                                         bool one_triangle)
{
    const int32_t shift = __builtin_ctz((uint32_t)block), low = block - 1;
    int32_t result[SRV_TILE]; /* (stores to a local array, then out) */
    for (int32_t j = 0; j < SRV_TILE; j++) {
        int32_t ix = j >> shift, fx = j & low;
        int32_t two_x = (fx != 0) & (ix + 1 < nx);
        uint32_t tp = in->tri[j];
        float n0 = in->normal[0][j], n1 = in->normal[1][j], n2 = in->normal[2][j];
        float dp = in->depth[j], fp = in->footprint[j];
        int32_t mask = 0;
#pragma GCC unroll 4
        for (int32_t c = 0; c < 4; c++) {
            int32_t rowc = c >> 1, at = j + ((c & 1) ? block : 0);
            int32_t exists = ((c & 1) ? two_x : 1) & ((c & 2) ? two_y : 1);
            uint32_t tr = in->sample_tri[rowc][at];
            float d0 = in->sample_normal[rowc][0][at] - n0, d1 = in->sample_normal[rowc][1][at] - n1,
                  d2 = in->sample_normal[rowc][2][at] - n2;
            int32_t normal_ok = (fabsf(d0) <= 0.05f) & (fabsf(d1) <= 0.05f) & (fabsf(d2) <= 0.05f);
            /* srv__pow2_floor of the larger footprint (clamped to [-60, 60], NaN to -60), from the bits */
            float fr = in->sample_footprint[rowc][at], x = fp > fr ? fp : fr;
            x = x > -60.0f ? (x < 60.0f ? x : 60.0f) : -60.0f;
            int32_t e =
                (int32_t)floorf(x); /* (roundps in the AVX2 copy; floor by hand kept GCC from vectorising) */
            uint32_t bits = (uint32_t)(e + 127) << 23;
            float pow2;
            memcpy(&pow2, &bits, sizeof pow2);
            int32_t dx = (c & 1) ? block - fx : fx, dy = (c & 2) ? block - fy : fy;
            float apart = (float)(dx > dy ? dx : dy);
            float tolerance = pow2 * (apart * 1.0f * depth_scale);
            int32_t depth_ok = fabsf(dp - in->sample_depth[rowc][at]) <= tolerance;
            int32_t match = one_triangle ? 1 : (tr == tp) | ((tr != SRV_MISS) & normal_ok & depth_ok);
            mask |= (exists & match) << c;
        }
        result[j] = ((fx | fy) == 0) ? 1 : mask;
    }
    /* bytes (the row's view->coarse, a whole row): each visible pixel's mask, a miss's byte left as it was */
    uint8_t stored[SRV_TILE];
    for (int32_t j = 0; j < SRV_TILE; j++) {
        int32_t visible = -(int32_t)(in->tri[j] != SRV_MISS); /* all ones or 0 */
        stored[j] = (uint8_t)((result[j] & visible) | ((int32_t)bytes[j] & ~visible));
    }
    /* bit j of the answer: pixel j asks for its own keys, i.e. it is visible and a rep ((fx | fy) == 0: the
     * tile starts on a multiple of the block, srv__coarse_is_rep) or no rep stands in for it */
    uint32_t own = 0;
    for (int32_t j = 0; j < SRV_TILE; j++)
        own |= (uint32_t)((in->tri[j] != SRV_MISS) & ((result[j] == 0) | (((j & low) | fy) == 0))) << j;
    for (int32_t j = 0; j < SRV_TILE; j++) {
        out[j] = result[j];
        bytes[j] = stored[j];
    }
    return own;
}

FXC_HOT_LANES static uint32_t coarse_mask_lanes(const mask_row *in, int32_t block, int32_t nx, int32_t fy,
                                                int32_t two_y, float depth_scale, int32_t *out,
                                                uint8_t *bytes)
{
    return coarse_mask_core(in, block, nx, fy, two_y, depth_scale, out, bytes, false);
}

/* coarse_mask_lanes for a row whose pixels and every candidate that can exist (samples of the row's block
 * rows before nx; the second row only when two_y) lie on one triangle (row_one_triangle): every candidate
 * that exists matches on its triangle (tr == tp), so the normals, depths and footprints are not read (the
 * same mask: the match is an or with tr == tp). */
FXC_HOT_LANES static uint32_t coarse_mask_one_triangle(const mask_row *in, int32_t block, int32_t nx,
                                                       int32_t fy, int32_t two_y, int32_t *out,
                                                       uint8_t *bytes)
{
    return coarse_mask_core(in, block, nx, fy, two_y, 0.0f, out, bytes, true);
}

/* Whether a row's 16 pixels (in->tri) and the candidates they can take (the samples before nx of the
 * expanded sample rows, the second only when two_y: in->sample_one) all lie on one triangle, not a miss;
 * *pixels_one: whether the pixels do (a miss included). */
static bool row_one_triangle(const mask_row *in, bool two_y, bool *pixels_one)
{
    uint32_t t = in->tri[0];
    uint32_t differ = 0;
    for (uint32_t j = 0; j < SRV_TILE; j++)
        differ |= in->tri[j] ^ t;
    *pixels_one = differ == 0;
    return differ == 0 && t != SRV_MISS && in->sample_one[0] == t && (!two_y || in->sample_one[1] == t);
}

/* Row `sample_row` of a tile's samples (buffer index of its first) expanded per column into in's row `to`;
 * block is a constant in each copy (mask_expand): B stores of one value. Columns past the last sample are
 * never taken (their candidates do not exist) and hold a miss. */
FXC_HOT_INLINE void mask_expand_of(const scene *s, const srv_viewer *view, size_t sample_row, uint32_t nx,
                                   uint32_t block, mask_row *in, int to)
{
    static const float none[3] = {0, 0, 0};
    uint32_t one = view->tri[sample_row]; /* (sample 0 exists: nx >= 1) */
    for (uint32_t i = 0; i < MASK_COLUMNS / block; i++) {
        size_t r = sample_row + (size_t)i * block;
        uint32_t tri = i < nx ? view->tri[r] : SRV_MISS;
        one = i < nx && tri != one ? SRV_MISS : one;
        const float *n = tri != SRV_MISS ? s->tri_normal + 3 * (size_t)tri : none;
        float depth = i < nx ? view->depth[r] : 0.0f, footprint = i < nx ? view->footprint[r] : 0.0f;
        float n0 = n[0], n1 = n[1], n2 = n[2];
        for (uint32_t f = 0; f < block; f++) {
            uint32_t c = i * block + f;
            in->sample_tri[to][c] = tri;
            in->sample_normal[to][0][c] = n0;
            in->sample_normal[to][1][c] = n1;
            in->sample_normal[to][2][c] = n2;
            in->sample_depth[to][c] = depth;
            in->sample_footprint[to][c] = footprint;
        }
    }
    in->sample_one[to] = one;
}

static void mask_expand(const scene *s, const srv_viewer *view, size_t sample_row, uint32_t nx,
                        uint32_t block, mask_row *in, int to)
{
    if (block == 4)
        mask_expand_of(s, view, sample_row, nx, 4, in, to);
    else if (block == 2)
        mask_expand_of(s, view, sample_row, nx, 2, in, to);
    else
        mask_expand_of(s, view, sample_row, nx, 8, in, to);
}

static void request_tile(void *user, uint32_t task_index, uint32_t thread_index)
{
    request_task *task = user;
    const srv_viewer *view = task->view;
    const bool positions = task->loop->kinds[task->kind]->needs_position;
    uint32_t width = view->frame.width, height = view->frame.height;
    uint32_t x0 = (task_index % task->tiles_x) * SRV_TILE, y0 = (task_index / task->tiles_x) * SRV_TILE;
    srv_pixel pixels[SRV_TILE * SRV_TILE];
    uint32_t count = 0;
    pixel_memo memo = {.tri = SRV_MISS};
    const srv_loop *loop = task->loop;
    uint32_t block = task->effect != SRV_NO_EFFECT && task->effect == loop->coarse_effect
                         ? srv__coarse_block(loop, view)
                         : 1;
    if (block > 1) {
        /* Evaluated per block in compose: the reps, and the pixels no rep stands in for. The sample choice is
         * made here, once, and kept for compose (view->coarse; engine_internal.h, srv__coarse_mask). */
        srv_coarse_grid g;
        srv__coarse_grid(block, x0, y0, width, height, &g);
        uint8_t *coarse = view->coarse;
        const scene *sc = loop->s;
        uint32_t lanes = width - x0 < SRV_TILE ? width - x0 : SRV_TILE, expanded = UINT32_MAX;
        mask_row in;
        int32_t row_mask[SRV_TILE];
        uint8_t bytes_row[SRV_TILE];
        for (uint32_t y = y0; y < y0 + SRV_TILE && y < height; y++) {
            uint32_t ly = y - y0, iy = ly >> g.shift, fy = ly & (g.block - 1);
            size_t row = (size_t)y * width + x0;
            if (iy != expanded) {
                size_t sample_row = (size_t)(y0 + (iy << g.shift)) * width + x0;
                mask_expand(sc, view, sample_row, g.nx, g.block, &in, 0);
                mask_expand(sc, view, iy + 1 < g.ny ? sample_row + (size_t)g.block * width : sample_row, g.nx,
                            g.block, &in, 1);
                expanded = iy;
            }
            static const float none[3] = {0, 0, 0}; /* a miss's lanes: not used */
            uint32_t memo_tri = SRV_MISS;
            const float *n = none;
            bool two_y = fy != 0 && iy + 1 < g.ny, pixels_one = false;
            if (lanes == SRV_TILE && !loop->desc.no_lanes) { /* a whole row: copies */
                memcpy(in.tri, view->tri + row, sizeof in.tri);
                if (row_one_triangle(&in, two_y, &pixels_one)) { /* the common case: no other input read */
                    memcpy(bytes_row, coarse + row, sizeof bytes_row);
                    uint32_t own = coarse_mask_one_triangle(&in, (int32_t)g.block, (int32_t)g.nx, (int32_t)fy,
                                                            (int32_t)two_y, row_mask, bytes_row);
                    memcpy(coarse + row, bytes_row, sizeof bytes_row);
                    for (; own; own &= own - 1) { /* in column order */
                        uint32_t j = (uint32_t)__builtin_ctz(own);
                        fill_pixel(loop->s, view, row + j, positions, &memo, &pixels[count++]);
                    }
                    continue;
                }
                memcpy(in.depth, view->depth + row, sizeof in.depth);
                memcpy(in.footprint, view->footprint + row, sizeof in.footprint);
            } else {
                for (uint32_t j = 0; j < SRV_TILE; j++) {
                    size_t p =
                        row + (j < lanes ? j : 0); /* lanes past the frame's edge: lane 0's pixel, not used */
                    in.tri[j] = view->tri[p];
                    in.depth[j] = view->depth[p];
                    in.footprint[j] = view->footprint[p];
                }
            }
            if (pixels_one) { /* one triangle (or all misses): its normal in every lane */
                n = in.tri[0] != SRV_MISS ? sc->tri_normal + 3 * (size_t)in.tri[0] : none;
                for (int k = 0; k < 3; k++) {
                    float nk = n[k];
                    for (uint32_t j = 0; j < SRV_TILE; j++)
                        in.normal[k][j] = nk;
                }
            } else {
                for (uint32_t j = 0; j < SRV_TILE; j++) {
                    uint32_t tri = in.tri[j];
                    if (tri != memo_tri) {
                        memo_tri = tri;
                        n = tri != SRV_MISS ? sc->tri_normal + 3 * (size_t)tri : none;
                    }
                    for (int k = 0; k < 3; k++)
                        in.normal[k][j] = n[k];
                }
            }
            uint8_t bytes[SRV_TILE] = {0};
            if (lanes == SRV_TILE)
                memcpy(bytes, coarse + row, sizeof bytes);
            uint32_t own = coarse_mask_lanes(&in, (int32_t)g.block, (int32_t)g.nx, (int32_t)fy,
                                             (int32_t)two_y, loop->coarse_depth_scale, row_mask, bytes);
            if (lanes == SRV_TILE && !loop->desc.no_lanes) {
                memcpy(coarse + row, bytes, sizeof bytes);
                for (; own; own &= own - 1) { /* in column order */
                    uint32_t j = (uint32_t)__builtin_ctz(own);
                    fill_pixel(loop->s, view, row + j, positions, &memo, &pixels[count++]);
                }
            } else {
                for (uint32_t j = 0; j < lanes; j++) {
                    size_t p = row + j;
                    if (view->tri[p] == SRV_MISS)
                        continue;
                    int32_t mask = row_mask[j];
                    coarse[p] = (uint8_t)mask;
                    if (mask == 0 || srv__coarse_is_rep(g.block, x0 + j, y))
                        fill_pixel(loop->s, view, p, positions, &memo, &pixels[count++]);
                }
            }
        }
        request_pixels(task, thread_index, pixels, count);
        return;
    }
    for (uint32_t y = y0; y < y0 + SRV_TILE && y < height; y++)
        for (uint32_t x = x0; x < x0 + SRV_TILE && x < width; x++) {
            size_t p = (size_t)y * width + x;
            if (view->tri[p] != SRV_MISS)
                fill_pixel(task->loop->s, view, p, positions, &memo, &pixels[count++]);
        }
    request_pixels(task, thread_index, pixels, count);
}

/* A sparse viewer: SRV_TILE * SRV_TILE consecutive entries of its (row-sorted) list per task. */
static void request_list_task(void *user, uint32_t task_index, uint32_t thread_index)
{
    request_task *task = user;
    const srv_viewer *view = task->view;
    const bool positions = task->loop->kinds[task->kind]->needs_position;
    size_t first = (size_t)task_index * SRV_TILE * SRV_TILE, end = first + SRV_TILE * SRV_TILE;
    if (end > view->list_count)
        end = view->list_count;
    srv_pixel pixels[SRV_TILE * SRV_TILE];
    uint32_t count = 0;
    pixel_memo memo = {.tri = SRV_MISS};
    for (size_t p = first; p < end; p++)
        if (view->tri[p] != SRV_MISS)
            fill_pixel(task->loop->s, view, p, positions, &memo, &pixels[count++]);
    request_pixels(task, thread_index, pixels, count);
}

/* One pass of one viewer over one kind (and one effect when the kind's keys do not name it): gather on the
 * pool, merge, batch-request, then the dependency's keys. Returns the requested texels (or cells). */
static uint64_t request_pass(srv_loop *loop, uint32_t slot, uint32_t k, uint32_t effect, srv_frame_stats *st)
{
    srv_viewer *view = &loop->viewers[slot];
    const srv_cache_kind *kind = loop->kinds[k];
    uint32_t threads = srv_pool_threads(loop->pool);
    uint64_t requested = 0;
    for (uint32_t t = 0; t < threads; t++)
        loop->thread_requests[t].count = 0;
    request_task task = {.loop = loop,
                         .view = view,
                         .kind = k,
                         .effect = effect,
                         .tiles_x = (view->frame.width + SRV_TILE - 1) / SRV_TILE};
    atomic_init(&task.failed, false);
    uint32_t tiles_y = (view->frame.height + SRV_TILE - 1) / SRV_TILE;
    if (view->sparse)
        srv_pool_run(loop->pool, (view->list_count + SRV_TILE * SRV_TILE - 1) / (SRV_TILE * SRV_TILE),
                     request_list_task, &task);
    else
        srv_pool_run(loop->pool, task.tiles_x * tiles_y, request_tile, &task);

    /* Gather the threads' lists (order does not matter: the batch sorts). */
    size_t total = 0;
    for (uint32_t t = 0; t < threads; t++)
        total += loop->thread_requests[t].count;
    srv_request_list *merged = &view->requests;
    merged->count = 0;
    if (atomic_load(&task.failed) ||
        !srv__request_reserve(loop, SRV_MEM_VIEWERS, merged, total ? total : 1)) {
        st->drops[SRV_DROP_NOMEM_REQUESTS]++; /* the frame goes on without this viewer's requests */
        return 0;
    }
    for (uint32_t t = 0; t < threads; t++) {
        const srv_request_list *list = &loop->thread_requests[t];
        if (list->count == 0)
            continue;
        memcpy(merged->keys + merged->count, list->keys, list->count * sizeof *list->keys);
        memcpy(merged->masks + merged->count, list->masks, list->count * sizeof *list->masks);
        merged->count += list->count;
    }
    size_t unique = 0;
    uint32_t *blocks = merged->blocks;
    kind->request_batch(loop->caches[k], slot, effect, merged->keys, merged->masks, merged->count, &unique,
                        blocks, &st->drops[SRV_DROP_POOL_EXHAUSTED], &st->drops[SRV_DROP_TABLE_FULL]);
    merged->count = unique;
    size_t dependent = 0;
    for (size_t i = 0; i < unique; i++) {
        uint32_t e = effect != SRV_NO_EFFECT ? effect : kind->key_effect(merged->keys[i]);
        if (e >= loop->effect_count || !loop->effect_shading[e])
            continue;
        requested += (uint64_t)__builtin_popcountll(merged->masks[i]);
        if (blocks[i] != SRV_NONE && loop->viewer_bits[e])
            loop->viewer_bits[e][blocks[i]] |= (uint64_t)1 << slot;
        dependent += loop->dependency[e] != SRV_NO_EFFECT;
    }
    /* The same texels of the effects they depend on (the triangle lookup), from the merged keys: appended
     * after them and requested as a second batch. Only kinds whose keys name their effect have dependencies. */
    if (!dependent || !kind->rekey)
        return requested;
    if (!srv__request_reserve(loop, SRV_MEM_VIEWERS, merged, unique + dependent)) {
        st->drops[SRV_DROP_NOMEM_REQUESTS]++;
        return requested;
    }
    size_t n = unique;
    for (size_t i = 0; i < unique; i++) {
        uint32_t e = kind->key_effect(merged->keys[i]);
        if (e < loop->effect_count && loop->effect_shading[e] && loop->dependency[e] != SRV_NO_EFFECT) {
            merged->keys[n] = kind->rekey(merged->keys[i], loop->dependency[e]);
            merged->masks[n++] = merged->masks[i];
        }
    }
    size_t dep_unique = 0;
    kind->request_batch(loop->caches[k], slot, SRV_NO_EFFECT, merged->keys + unique, merged->masks + unique,
                        n - unique, &dep_unique, merged->blocks + unique, &st->drops[SRV_DROP_POOL_EXHAUSTED],
                        &st->drops[SRV_DROP_TABLE_FULL]);
    merged->count = unique + dep_unique;
    return requested;
}

void srv__requests(srv_loop *loop, uint32_t slot, srv_frame_stats *st, uint64_t requested[SCENE_CACHE_COUNT])
{
    for (uint32_t k = 0; k < SCENE_CACHE_COUNT; k++) {
        requested[k] = 0;
        const srv_cache_kind *kind = loop->kinds[k];
        if (!kind)
            continue;
        if (kind->keys_carry_effect) {
            requested[k] += request_pass(loop, slot, k, SRV_NO_EFFECT, st);
            continue;
        }
        for (uint32_t e = 0; e < loop->effect_count; e++)
            if (loop->effect_shading[e] && loop->effect_kind[e] == k)
                requested[k] += request_pass(loop, slot, k, e, st);
    }
}
