/* Stage 3, requests: every visible pixel asks, for every cached effect, for the texels its bilinear filter
 * reads at that effect's level (the pixel footprint plus the effect's bias), and for the triangle lookup of
 * the same texels. Tiles run on the thread pool; each folds neighbouring pixels' requests for the same
 * block in a small direct-mapped buffer before appending them to its thread's list. The lists of all
 * threads then go to osc_request_batch(), which sorts and merges them, so the cache comes out identical
 * whatever the thread interleaving. Requests of all viewers meet in the same table: this is where sharing
 * happens. */
#include "frame_internal.h"

#include <stdlib.h>
#include <string.h>

enum { FOLD_SLOTS = 64 };

bool srv__request_reserve(srv_request_list *list, size_t n)
{
    size_t cap = srv__grown_capacity(list->capacity, n, 4096);
    if (cap == list->capacity)
        return true;
    if (!srv__realloc((void **)&list->keys, cap, sizeof *list->keys) ||
        !srv__realloc((void **)&list->masks, cap, sizeof *list->masks) ||
        !srv__realloc((void **)&list->blocks, cap, sizeof *list->blocks))
        return false;
    list->capacity = cap;
    return true;
}

/* Folds requests for the same key that arrive close together. */
typedef struct fold_buffer {
    uint64_t keys[FOLD_SLOTS];
    uint64_t masks[FOLD_SLOTS];
} fold_buffer;

static void fold_flush_slot(fold_buffer *fold, uint32_t slot, srv_request_list *out, bool *ok)
{
    if (fold->keys[slot] == OSC_KEY_EMPTY)
        return;
    if (!srv__request_reserve(out, out->count + 1)) {
        *ok = false;
        return;
    }
    out->keys[out->count] = fold->keys[slot];
    out->masks[out->count] = fold->masks[slot];
    out->count++;
    fold->keys[slot] = OSC_KEY_EMPTY;
}

static void fold_add(fold_buffer *fold, uint64_t key, uint64_t mask, srv_request_list *out, bool *ok)
{
    uint64_t h = key * 0x9E3779B97F4A7C15ull;
    uint32_t slot = (uint32_t)(h >> 58); /* 6 bits: FOLD_SLOTS */
    if (fold->keys[slot] == key) {
        fold->masks[slot] |= mask;
        return;
    }
    fold_flush_slot(fold, slot, out, ok);
    fold->keys[slot] = key;
    fold->masks[slot] = mask;
}

typedef struct request_task {
    srv_loop *loop;
    uint32_t viewer;
    uint32_t tiles_x;
    bool ok;
} request_task;

static void request_tile(void *user, uint32_t task_index, uint32_t thread_index)
{
    request_task *task = user;
    srv_loop *loop = task->loop;
    const scene *s = loop->s;
    srv_viewer *view = &loop->viewers[task->viewer];
    srv_request_list *out = &loop->thread_requests[thread_index];
    uint32_t width = view->frame.width, height = view->frame.height;
    uint32_t x0 = (task_index % task->tiles_x) * SRV_TILE, y0 = (task_index / task->tiles_x) * SRV_TILE;
    fold_buffer fold;
    memset(fold.keys, 0xFF, sizeof fold.keys);
    bool ok = true;
    for (uint32_t y = y0; y < y0 + SRV_TILE && y < height; y++)
        for (uint32_t x = x0; x < x0 + SRV_TILE && x < width; x++) {
            size_t p = (size_t)y * width + x;
            uint32_t tri = view->tri[p];
            if (tri == SRV_MISS)
                continue;
            uint32_t island = s->tri_island[tri];
            float tu, tv;
            srv__island_uv(s, tri, view->bary_u[p], view->bary_v[p], &tu, &tv);
            for (uint32_t fx = 0; fx < SCENE_FX_COUNT; fx++) {
                if (!loop->cached_effect[fx])
                    continue;
                uint32_t level = srv__level(view->footprint[p], loop->bias[fx]);
                float scale = 1.0f / (float)(1u << level);
                osc_island_extent extent = {.effect = fx, .island_id = island,
                                            .width0 = s->islands[island].width,
                                            .height0 = s->islands[island].height};
                osc_footprint fp;
                osc_footprint_bilinear(&extent, level, tu * scale, tv * scale, &fp);
                for (uint32_t i = 0; i < fp.count; i++) {
                    fold_add(&fold, fp.keys[i], fp.texel_masks[i], out, &ok);
                    /* The same texels' triangle lookup: the key with effect 0. */
                    uint64_t lookup_key = fp.keys[i] & ~((uint64_t)0xF << OSC_KEY_EFFECT_SHIFT);
                    fold_add(&fold, lookup_key, fp.texel_masks[i], out, &ok);
                }
            }
        }
    for (uint32_t slot = 0; slot < FOLD_SLOTS; slot++)
        fold_flush_slot(&fold, slot, out, &ok);
    if (!ok)
        task->ok = false; /* benign race: only ever set to false */
}

uint64_t srv__requests(srv_loop *loop, uint32_t viewer)
{
    srv_viewer *view = &loop->viewers[viewer];
    uint32_t threads = srv_pool_threads(loop->pool);
    for (uint32_t t = 0; t < threads; t++)
        loop->thread_requests[t].count = 0;
    request_task task = {.loop = loop, .viewer = viewer, .ok = true,
                         .tiles_x = (view->frame.width + SRV_TILE - 1) / SRV_TILE};
    uint32_t tiles_y = (view->frame.height + SRV_TILE - 1) / SRV_TILE;
    srv_pool_run(loop->pool, task.tiles_x * tiles_y, request_tile, &task);

    /* Gather the threads' lists (order does not matter: the batch sorts). */
    size_t total = 0;
    for (uint32_t t = 0; t < threads; t++)
        total += loop->thread_requests[t].count;
    srv_request_list *merged = &view->requests;
    merged->count = 0;
    if (!task.ok || !srv__request_reserve(merged, total ? total : 1))
        return 0; /* out of memory: the frame goes on without this viewer's requests */
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
    osc_request_batch(loop->osc, merged->keys, merged->masks, merged->count, &unique, blocks);
    merged->count = unique;

    uint64_t requested = 0;
    for (size_t i = 0; i < unique; i++) {
        uint32_t fx = osc_key_effect(merged->keys[i]);
        if (fx == FX_TRI_LOOKUP)
            continue;
        requested += (uint64_t)__builtin_popcountll(merged->masks[i]);
        if (blocks[i] != OSC_NONE && loop->viewer_bits[fx])
            loop->viewer_bits[fx][blocks[i]] |= (uint64_t)1 << viewer;
    }
    return requested;
}
