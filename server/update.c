/* Stages 4-6: update queues, resampling, triangle lookup and effect updates.
 *
 * Queues (stage 4): per effect, the blocks requested this frame whose requested texels hold no data, and
 * for progressive effects (AO) those not yet converged. Before anything is traced, a texel of level l >= 1
 * whose four level l-1 texels are resident and final is filled by averaging them (the resampling queue:
 * no rays at all). The ray budget (effect rays per frame, shared by all effects) is then spent in a fixed
 * order: empty shadow texels, empty AO texels, then AO refinement; what does not fit waits for a later
 * frame and is counted as deferred. Costs are upper bounds known before tracing (16 rays per texel and
 * light, the AO step), so which texels run depends only on the queues, never on timing.
 *
 * Triangle lookup (stage 5) fills every requested lookup texel that holds none (no rays; it is itself a
 * cached effect, so a texel is located once). Effect updates (stage 6) run the queued blocks on the pool
 * in chunks; each chunk's ray count is stored per chunk and summed in order. */
#include "frame_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

enum { CHUNK_BLOCKS = 8 };

bool srv__jobs_reserve(srv_job_list *list, size_t n)
{
    size_t cap = srv__grown_capacity(list->capacity, n, 1024);
    if (cap == list->capacity)
        return true;
    if (!srv__realloc((void **)&list->items, cap, sizeof *list->items))
        return false;
    list->capacity = cap;
    return true;
}

/* The lookup key of an effect key: the same block with effect 0. */
static uint64_t lookup_key_of(uint64_t key)
{
    return key & ~((uint64_t)0xF << OSC_KEY_EFFECT_SHIFT);
}

/* AO texels of mask whose sample count is below the maximum. */
static uint64_t ao_unconverged(const void *payload, uint64_t mask)
{
    uint64_t out = 0;
    for (uint64_t m = mask; m; m &= m - 1) {
        uint32_t t = (uint32_t)__builtin_ctzll(m);
        if (fx_ao_count(payload, t) < FX_AO_MAX_SAMPLES)
            out |= (uint64_t)1 << t;
    }
    return out;
}

/* ---- resampling ----------------------------------------------------------------------------------------- */

/* Fills texels of `need` in a block at level >= 1 from four final level-1-finer texels each, when all four
 * are resident; returns the texels filled. */
static uint64_t resample_block(srv_loop *loop, uint32_t fx, uint32_t block, uint64_t need)
{
    osc_key_fields k = osc_key_unpack(osc_block_key(loop->osc, fx, block));
    if (k.level == 0 || need == 0)
        return 0;
    const scene_island *island = &loop->s->islands[k.island_id];
    uint32_t fine_w = osc_level_size(island->width, k.level - 1), fine_h = osc_level_size(island->height, k.level - 1);
    uint32_t texel_bytes = osc_pool_texel_bytes(loop->osc, fx);
    uint32_t lights = loop->s->light_count ? loop->s->light_count : 1;
    uint8_t *payload = osc_block_payload(loop->osc, fx, block);
    /* The up to four finer blocks under this one. */
    uint32_t fine_block[2][2];
    for (uint32_t dy = 0; dy < 2; dy++)
        for (uint32_t dx = 0; dx < 2; dx++) {
            uint32_t bx = 2 * k.block_x + dx, by = 2 * k.block_y + dy;
            fine_block[dy][dx] = OSC_NONE;
            if (bx * 8 < fine_w && by * 8 < fine_h && bx <= OSC_MAX_BLOCK_COORD && by <= OSC_MAX_BLOCK_COORD)
                fine_block[dy][dx] = osc_find(loop->osc, osc_key_pack(fx, k.island_id, k.level - 1, bx, by));
        }
    uint64_t filled = 0;
    for (uint64_t m = need; m; m &= m - 1) {
        uint32_t t = (uint32_t)__builtin_ctzll(m);
        uint32_t tx = k.block_x * 8 + (t & 7), ty = k.block_y * 8 + (t >> 3);
        const uint8_t *child[4];
        bool ok = true;
        for (uint32_t c = 0; c < 4 && ok; c++) {
            uint32_t cx = 2 * tx + (c & 1), cy = 2 * ty + (c >> 1);
            if (cx >= fine_w || cy >= fine_h) {
                ok = false;
                break;
            }
            uint32_t fb = fine_block[(cy / 8) - 2 * k.block_y][(cx / 8) - 2 * k.block_x];
            uint32_t ct = (cy & 7) * 8 + (cx & 7);
            if (fb == OSC_NONE || !(osc_block_valid(loop->osc, fx, fb) >> ct & 1)) {
                ok = false;
                break;
            }
            const uint8_t *cp = osc_block_payload(loop->osc, fx, fb);
            if (fx == FX_AO && fx_ao_count(cp, ct) < FX_AO_MAX_SAMPLES)
                ok = false;
            child[c] = cp + (size_t)ct * texel_bytes;
        }
        if (!ok)
            continue;
        uint8_t *dst = payload + (size_t)t * texel_bytes;
        if (fx == FX_AO) {
            float mean = 0;
            for (int c = 0; c < 4; c++)
                mean += 0.25f * fx_ao_sample(child[c], 0);
            uint32_t value = (uint32_t)lrintf(fminf(fmaxf(mean, 0.0f), 1.0f) * 65535.0f);
            uint16_t words[2] = {(uint16_t)value, (uint16_t)FX_AO_MAX_SAMPLES};
            memcpy(dst, words, sizeof words);
        } else { /* shadow: per light, as many lit rays as the four children have on average */
            for (uint32_t l = 0; l < lights; l++) {
                float mean = 0;
                for (int c = 0; c < 4; c++)
                    mean += 0.25f * fx_shadow_sample(child[c], 0, lights, l);
                uint32_t bits = (uint32_t)lrintf(mean * FX_SHADOW_RAYS);
                uint16_t mask16 = (uint16_t)(bits >= 16 ? 0xFFFFu : ((1u << bits) - 1u));
                memcpy(dst + 2 * l, &mask16, sizeof mask16);
            }
        }
        filled |= (uint64_t)1 << t;
    }
    return filled;
}

/* ---- stage 5: triangle lookup -------------------------------------------------------------------------- */

typedef struct lookup_task {
    srv_loop *loop;
    const uint32_t *blocks;
    uint32_t count;
} lookup_task;

static void lookup_chunk(void *user, uint32_t task_index, uint32_t thread_index)
{
    (void)thread_index;
    lookup_task *task = user;
    osc_cache *osc = task->loop->osc;
    uint32_t end = (task_index + 1) * CHUNK_BLOCKS;
    for (uint32_t i = task_index * CHUNK_BLOCKS; i < end && i < task->count; i++) {
        uint32_t block = task->blocks[i];
        uint64_t need = osc_block_requested(osc, FX_TRI_LOOKUP, block) & ~osc_block_valid(osc, FX_TRI_LOOKUP, block);
        if (!need)
            continue;
        osc_key_fields k = osc_key_unpack(osc_block_key(osc, FX_TRI_LOOKUP, block));
        fx_lookup_update(task->loop->s, k.island_id, k.level, k.block_x, k.block_y, need,
                         osc_block_payload(osc, FX_TRI_LOOKUP, block));
        /* Distinct blocks per task: writing this block's valid mask races with nobody. */
        osc_block_set_valid(osc, FX_TRI_LOOKUP, block, osc_block_valid(osc, FX_TRI_LOOKUP, block) | need);
    }
}

/* ---- stage 6: effects ------------------------------------------------------------------------------------ */

typedef struct effect_task {
    srv_loop *loop;
    uint32_t fx;
    const fx_block_job *jobs;
    uint32_t count;
    uint32_t samples;
    uint64_t *rays; /* per chunk */
} effect_task;

static void effect_chunk(void *user, uint32_t task_index, uint32_t thread_index)
{
    (void)thread_index;
    effect_task *task = user;
    uint32_t first = task_index * CHUNK_BLOCKS;
    uint32_t n = task->count - first < CHUNK_BLOCKS ? task->count - first : CHUNK_BLOCKS;
    if (task->fx == FX_SHADOW)
        task->rays[task_index] = fx_shadow_update(&task->loop->fx, task->jobs + first, n);
    else
        task->rays[task_index] = fx_ao_update(&task->loop->fx, task->jobs + first, n, task->samples);
}

/* Runs a job list of one effect on the pool and marks the texels valid; returns rays traced. */
static uint64_t run_jobs(srv_loop *loop, uint32_t fx, const srv_job_list *list, uint32_t samples)
{
    if (list->count == 0)
        return 0;
    if (list->count > loop->fx_jobs_capacity) {
        if (!srv__realloc((void **)&loop->fx_jobs, list->count, sizeof *loop->fx_jobs))
            return 0;
        loop->fx_jobs_capacity = list->count;
    }
    for (size_t i = 0; i < list->count; i++) {
        const srv_job *job = &list->items[i];
        uint64_t key = osc_block_key(loop->osc, fx, job->block);
        osc_key_fields k = osc_key_unpack(key);
        loop->fx_jobs[i] = (fx_block_job){.key = key, .island = k.island_id, .level = k.level,
                                          .block_x = k.block_x, .block_y = k.block_y, .mask = job->mask,
                                          .lookup = osc_block_payload(loop->osc, FX_TRI_LOOKUP, job->lookup_block),
                                          .payload = osc_block_payload(loop->osc, fx, job->block)};
    }
    uint32_t chunks = (uint32_t)((list->count + CHUNK_BLOCKS - 1) / CHUNK_BLOCKS);
    if (chunks > loop->chunk_capacity) {
        if (!srv__realloc((void **)&loop->chunk_rays, chunks, sizeof *loop->chunk_rays))
            return 0;
        loop->chunk_capacity = chunks;
    }
    uint64_t *rays = loop->chunk_rays;
    effect_task task = {.loop = loop, .fx = fx, .jobs = loop->fx_jobs, .count = (uint32_t)list->count,
                        .samples = samples, .rays = rays};
    srv_pool_run(loop->pool, chunks, effect_chunk, &task);
    uint64_t total = 0;
    for (uint32_t c = 0; c < chunks; c++)
        total += rays[c];
    for (size_t i = 0; i < list->count; i++) {
        const srv_job *job = &list->items[i];
        osc_block_set_valid(loop->osc, fx, job->block, osc_block_valid(loop->osc, fx, job->block) | job->mask);
    }
    return total;
}

/* Appends jobs for the texels of `masks` to list within the remaining budget (cost per texel); texels
 * that do not fit are counted as deferred. */
static void queue_within_budget(srv_loop *loop, uint32_t fx, srv_job_list *list, const uint32_t *blocks,
                                const uint64_t *masks, const uint32_t *lookups, uint32_t count,
                                uint64_t cost_per_texel, uint64_t *budget_left)
{
    srv_frame_stats *st = loop->stats;
    list->count = 0;
    if (!srv__jobs_reserve(list, count ? count : 1))
        return;
    bool unlimited = loop->desc.ray_budget == 0;
    for (uint32_t i = 0; i < count; i++) {
        uint64_t mask = masks[i];
        if (!mask || lookups[i] == OSC_NONE)
            continue;
        if (!unlimited) {
            uint64_t texels = (uint64_t)__builtin_popcountll(mask);
            uint64_t affordable = cost_per_texel ? *budget_left / cost_per_texel : texels;
            if (affordable < texels) {
                uint64_t trimmed = 0;
                for (uint64_t m = mask, n = 0; m && n < affordable; m &= m - 1, n++)
                    trimmed |= m & (~m + 1);
                st->texels_deferred[fx] += texels - affordable;
                mask = trimmed;
                texels = affordable;
            }
            *budget_left -= texels * cost_per_texel;
            if (!mask)
                continue;
        }
        list->items[list->count++] = (srv_job){.block = blocks[i], .lookup_block = lookups[i], .mask = mask};
        st->texels_updated[fx] += (uint64_t)__builtin_popcountll(mask);
    }
}

void srv__update(srv_loop *loop)
{
    osc_cache *osc = loop->osc;
    srv_frame_stats *st = loop->stats;

    /* Stage 4: queues, with resampling before anything is traced. */
    uint32_t n_shadow = 0, n_ao = 0;
    const uint32_t *shadow_blocks = loop->cached_effect[FX_SHADOW] ? osc_frame_blocks(osc, FX_SHADOW, &n_shadow) : NULL;
    const uint32_t *ao_blocks = loop->cached_effect[FX_AO] ? osc_frame_blocks(osc, FX_AO, &n_ao) : NULL;
    uint32_t n_max = n_shadow > n_ao ? n_shadow : n_ao;
    if (n_max > loop->queue_capacity) {
        if (!srv__realloc((void **)&loop->queue_empty, n_max, sizeof *loop->queue_empty) ||
            !srv__realloc((void **)&loop->queue_refine, n_max, sizeof *loop->queue_refine) ||
            !srv__realloc((void **)&loop->queue_lookups, n_max, sizeof *loop->queue_lookups))
            return; /* out of memory: nothing is updated this frame, compose falls back */
        loop->queue_capacity = n_max;
    }
    uint64_t *empty = loop->queue_empty, *refine = loop->queue_refine;
    uint32_t *lookups = loop->queue_lookups;
    uint64_t budget_left = loop->desc.ray_budget;

    /* Stage 5 first in time: lookups are needed by every queued texel, and cost no rays. */
    double tl = srv__now_ms();
    uint32_t n_lookup = 0;
    const uint32_t *lookup_blocks = osc_frame_blocks(osc, FX_TRI_LOOKUP, &n_lookup);
    lookup_task lt = {.loop = loop, .blocks = lookup_blocks, .count = n_lookup};
    srv_pool_run(loop->pool, (n_lookup + CHUNK_BLOCKS - 1) / CHUNK_BLOCKS, lookup_chunk, &lt);
    st->time_ms[SRV_STAGE_LOOKUP] += srv__now_ms() - tl;

    uint32_t lights = loop->s->light_count;
    for (uint32_t pass = 0; pass < 2; pass++) {
        uint32_t fx = pass == 0 ? FX_SHADOW : FX_AO;
        const uint32_t *blocks = pass == 0 ? shadow_blocks : ao_blocks;
        uint32_t n = pass == 0 ? n_shadow : n_ao;
        double tq = srv__now_ms();
        for (uint32_t i = 0; i < n; i++) {
            uint32_t b = blocks[i];
            uint64_t requested = osc_block_requested(osc, fx, b), valid = osc_block_valid(osc, fx, b);
            uint64_t need = requested & ~valid;
            uint64_t filled = resample_block(loop, fx, b, need);
            if (filled) {
                osc_block_set_valid(osc, fx, b, valid | filled);
                st->texels_resampled[fx] += (uint64_t)__builtin_popcountll(filled);
                st->texels_updated[fx] += (uint64_t)__builtin_popcountll(filled);
                need &= ~filled;
                valid |= filled;
            }
            empty[i] = need;
            refine[i] = fx == FX_AO ? ao_unconverged(osc_block_payload(osc, fx, b), requested & valid) : 0;
            lookups[i] = osc_find(osc, lookup_key_of(osc_block_key(osc, fx, b)));
        }
        /* Shadows: empty texels only (computed once). AO: empty texels, then refinement of the rest. */
        uint32_t rounds = fx == FX_SHADOW ? 1 : 2;
        uint32_t samples = fx == FX_SHADOW ? 0 : loop->desc.ao_samples_per_frame;
        uint64_t cost = fx == FX_SHADOW ? (uint64_t)FX_SHADOW_RAYS * (lights ? lights : 1) : samples;
        for (uint32_t round = 0; round < rounds; round++) {
            queue_within_budget(loop, fx, &loop->jobs[fx], blocks, round == 0 ? empty : refine, lookups, n,
                                cost, &budget_left);
            st->time_ms[SRV_STAGE_QUEUES] += srv__now_ms() - tq;
            double te = srv__now_ms();
            st->rays[fx] += run_jobs(loop, fx, &loop->jobs[fx], samples);
            st->time_ms[SRV_STAGE_EFFECTS] += srv__now_ms() - te;
            tq = srv__now_ms();
        }
    }
}
