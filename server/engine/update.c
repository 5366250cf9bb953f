/* Stages 4-6: update queues (with resampling), the lookup stage, the effect updates. Nothing here names an
 * effect: every decision comes from the effect's table (effects.h) and the cache's kind.
 *
 * Queues (stage 4): per cached effect, the blocks requested this frame whose requested texels hold no data,
 * and for progressive effects those not yet converged. Before anything is traced, a texel of level l >= 1
 * whose four level l-1 texels hold final data is filled from them (the resampling queue: no rays). The ray
 * budget (effect rays per frame, shared by all effects) is then spent in a fixed order: every effect's empty
 * texels in registry order, then every progressive effect's refinement; what does not fit waits for a later
 * frame and is counted as deferred. Costs are upper bounds known before tracing (the effect's cost
 * callback), so which texels run depends only on the queues, never on timing. A texel whose dependency block
 * (the triangle lookup) could not be mapped is counted as dropped.
 *
 * Lookup (stage 5) runs the jobs of the effects others depend on, so that the effect updates (stage 6) find
 * their lookup texels. Both run the queued blocks on the pool in chunks; each chunk's ray count is stored per
 * chunk and summed in order, and valid masks are set after the chunks, on one thread. */
#include "engine_internal.h"

#include <stdlib.h>
#include <string.h>

enum { CHUNK_BLOCKS = 8 };

/* Grows an effect's per-block queue arrays to n blocks. */
static bool queue_reserve(srv_loop *loop, srv_effect_queue *q, size_t n)
{
    if (n <= q->capacity)
        return true;
    size_t cap = q->capacity ? q->capacity : 1024;
    while (cap < n)
        cap *= 2;
    /* Each array keeps its own size until all four have grown; only then does the capacity change. */
    size_t old = q->capacity;
    void *arrays[4] = {q->empty, q->refine, q->take, q->dependency};
    size_t sizes[4] = {sizeof *q->empty, sizeof *q->refine, sizeof *q->take, sizeof *q->dependency};
    for (int i = 0; i < 4; i++)
        if (!srv__resize(loop, SRV_MEM_QUEUES, &arrays[i], old, cap, sizes[i])) {
            /* Undo the ones already grown so every array has `old` entries again. */
            for (int j = 0; j < i; j++)
                srv__resize(loop, SRV_MEM_QUEUES, &arrays[j], cap, old ? old : 0, sizes[j]);
            q->empty = arrays[0], q->refine = arrays[1], q->take = arrays[2], q->dependency = arrays[3];
            return false;
        }
    q->empty = arrays[0], q->refine = arrays[1], q->take = arrays[2], q->dependency = arrays[3];
    q->capacity = cap;
    return true;
}

/* Texels of mask whose sample count is below the run's maximum for the effect. */
static uint64_t unconverged(const fx_effect *e, uint32_t max_samples, const uint8_t *payload,
                            uint32_t texel_bytes, uint64_t mask)
{
    uint64_t out = 0;
    for (uint64_t m = mask; m; m &= m - 1) {
        uint32_t t = (uint32_t)__builtin_ctzll(m);
        if (e->texel_samples(payload + (size_t)t * texel_bytes) < max_samples)
            out |= (uint64_t)1 << t;
    }
    return out;
}

/* Fills texels of `need` from four final finer texels each; returns the texels filled. */
static uint64_t resample_block(srv_loop *loop, uint32_t e, uint32_t block, uint64_t need,
                               uint32_t texel_bytes)
{
    const fx_effect *fx = loop->effects[e];
    const srv_cache_kind *kind = loop->kinds[loop->effect_kind[e]];
    void *cache = loop->caches[loop->effect_kind[e]];
    const void *finer[64][4];
    uint64_t found = kind->finer_texels(cache, e, block, need, finer);
    uint8_t *payload = kind->block_payload(cache, e, block);
    uint64_t filled = 0;
    for (uint64_t m = found; m; m &= m - 1) {
        uint32_t t = (uint32_t)__builtin_ctzll(m);
        bool final = true;
        if (fx->texel_samples)
            for (int c = 0; c < 4; c++)
                final &= fx->texel_samples(finer[t][c]) >= loop->max_samples[e];
        if (!final)
            continue;
        fx->resample(&loop->fx, finer[t], payload + (size_t)t * texel_bytes);
        filled |= (uint64_t)1 << t;
    }
    return filled;
}

/* Takes texels of masks[i] into take[i] within the remaining budget (cost per texel); what does not fit is
 * counted as deferred, texels without their dependency block as dropped. */
static void take_within_budget(srv_loop *loop, uint32_t e, srv_effect_queue *q, uint32_t count,
                               const uint64_t *masks, uint64_t cost, uint64_t *budget_left,
                               srv_frame_stats *st)
{
    bool unlimited = loop->desc.ray_budget == 0;
    bool needs_dependency = loop->dependency[e] != SRV_NO_EFFECT;
    for (uint32_t i = 0; i < count; i++) {
        uint64_t mask = masks[i];
        if (!mask)
            continue;
        uint64_t texels = (uint64_t)__builtin_popcountll(mask);
        if (needs_dependency && q->dependency[i] == SRV_NONE) {
            st->drops[SRV_DROP_NO_DEPENDENCY] += texels;
            continue;
        }
        if (!unlimited && cost > 0) {
            uint64_t affordable = *budget_left / cost;
            if (affordable < texels) {
                uint64_t trimmed = 0;
                for (uint64_t m = mask, n = 0; m && n < affordable; m &= m - 1, n++)
                    trimmed |= m & (~m + 1);
                st->texels_deferred[e] += texels - affordable;
                mask = trimmed;
                texels = affordable;
            }
            *budget_left -= texels * cost;
        }
        q->take[i] |= mask;
    }
}

/* Continuous effects (probes) keep being updated while they are requested: their light changes as their
 * neighbours' does (the bounces) and when lights change. Each frame at most desc.probe_budget cells of
 * such an effect update (sharing the ray budget): first the requested cells that hold no data yet, then
 * the ones whose last update is oldest; a cell the effect calls converged (texel_samples >= max_samples,
 * max_samples > 0) waits at least CONVERGED_REFRESH frames between updates, except for light_settle_frames
 * frames after the lights or the sky changed (loop.c). The order is a sort on (age,
 * frame-list position), so it depends only on the cache's state, never on timing or threads. */
enum { CONVERGED_REFRESH = 8 };

static int compare_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

static void continuous_order(srv_loop *loop, uint32_t e, srv_effect_queue *q, const uint32_t *blocks,
                             uint32_t count)
{
    const fx_effect *fx = loop->effects[e];
    const srv_cache_kind *kind = loop->kinds[loop->effect_kind[e]];
    void *cache = loop->caches[loop->effect_kind[e]];
    uint32_t texel_bytes = fx->texel_bytes(loop->s);
    q->order_count = 0;
    if (!srv__grow(loop, SRV_MEM_QUEUES, (void **)&q->order, &q->order_capacity, count ? count : 1, 1024,
                   sizeof *q->order))
        return; /* no refresh this frame: only cells without data are taken */
    uint32_t stamp = loop->frame_number + 1;
    /* Shortly after the lights changed, what a converged probe holds is out of date: no refresh waits. */
    bool settling =
        loop->light_changed && loop->frame_number - loop->light_change_frame < loop->light_settle_frames;
    for (uint32_t i = 0; i < count; i++) {
        uint64_t have = q->refine[i] =
            kind->block_requested(cache, e, blocks[i]) & kind->block_valid(cache, e, blocks[i]);
        if (!have)
            continue;
        uint32_t *word = kind->block_word ? kind->block_word(cache, e, blocks[i]) : NULL;
        uint32_t age = word && *word ? stamp - *word : UINT32_MAX / 2;
        if (!settling && fx->texel_samples && loop->max_samples[e] > 0 && age < CONVERGED_REFRESH) {
            const uint8_t *payload = kind->block_payload(cache, e, blocks[i]);
            bool converged = true;
            for (uint64_t m = have; m && converged; m &= m - 1)
                converged = fx->texel_samples(payload + (size_t)__builtin_ctzll(m) * texel_bytes) >=
                            loop->max_samples[e];
            if (converged)
                continue;
        }
        /* Oldest first; ties in frame-list order. */
        q->order[q->order_count++] = (uint64_t)(UINT32_MAX - age) << 32 | i;
    }
    qsort(q->order, q->order_count, sizeof *q->order, compare_u64);
}

/* Round 0 (refresh = false): cells without data, in frame-list order; round 2: the refresh order. Both
 * within the cell budget and the ray budget. */
static void take_continuous(srv_loop *loop, uint32_t e, srv_effect_queue *q, uint32_t count, bool refresh,
                            uint64_t cost, uint64_t *budget_left, srv_frame_stats *st)
{
    bool unlimited = loop->desc.ray_budget == 0;
    uint32_t n = refresh ? (uint32_t)q->order_count : count;
    for (uint32_t j = 0; j < n; j++) {
        uint32_t i = refresh ? (uint32_t)q->order[j] : j;
        uint64_t mask = refresh ? q->refine[i] : q->empty[i];
        if (!mask)
            continue;
        uint64_t cells = (uint64_t)__builtin_popcountll(mask);
        bool fits =
            q->cells_taken + cells <= loop->desc.probe_budget && (unlimited || *budget_left >= cells * cost);
        if (!fits) {
            if (!refresh)
                st->texels_deferred[e] +=
                    cells; /* a refresh that waits is not a deferral: the cell has data */
            continue;
        }
        q->cells_taken += cells;
        if (!unlimited)
            *budget_left -= cells * cost;
        q->take[i] |= mask;
    }
}

/* The queues stage is serial (373 ms a frame for 4 x 3840x2160 viewers, BENCHMARKS.md robust-five): it looks
 * at the stop flag (srv_loop_set_stop) every this many blocks of an effect (a power of two). */
enum { QUEUE_STOP_BLOCKS = 4096 };

void srv__queues(srv_loop *loop, srv_frame_stats *st)
{
    uint32_t counts[SRV_MAX_EFFECTS] = {0};
    const uint32_t *blocks[SRV_MAX_EFFECTS] = {NULL};
    uint32_t texel_bytes[SRV_MAX_EFFECTS] = {0};
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        srv_effect_queue *q = &loop->queues[e];
        q->job_count = 0;
        q->cells_taken = 0;
        if (!loop->effect_cached[e])
            continue;
        const fx_effect *fx = loop->effects[e];
        const srv_cache_kind *kind = loop->kinds[loop->effect_kind[e]];
        void *cache = loop->caches[loop->effect_kind[e]];
        uint32_t n = 0;
        blocks[e] = kind->frame_blocks(cache, e, &n);
        texel_bytes[e] = fx->texel_bytes(loop->s);
        if (!queue_reserve(loop, q, n)) {
            st->drops[SRV_DROP_NOMEM_UPDATES]++; /* nothing of this effect is updated this frame */
            continue;
        }
        counts[e] = n;
        uint32_t dep = loop->dependency[e];
        for (uint32_t i = 0; i < n; i++) {
            if ((i & (QUEUE_STOP_BLOCKS - 1)) == 0 && srv_pool_stopped(loop->pool))
                goto stopped;
            uint32_t b = blocks[e][i];
            uint64_t requested = kind->block_requested(cache, e, b), valid = kind->block_valid(cache, e, b);
            uint64_t need = requested & ~valid;
            if (need && fx->resample && kind->finer_texels) {
                uint64_t filled = resample_block(loop, e, b, need, texel_bytes[e]);
                if (filled) {
                    kind->block_set_valid(cache, e, b, valid | filled);
                    st->texels_resampled[e] += (uint64_t)__builtin_popcountll(filled);
                    st->texels_updated[e] += (uint64_t)__builtin_popcountll(filled);
                    need &= ~filled;
                    valid |= filled;
                }
            }
            q->empty[i] = need;
            q->refine[i] = fx->policy == FX_UPDATE_PROGRESSIVE
                               ? unconverged(fx, loop->max_samples[e], kind->block_payload(cache, e, b),
                                             texel_bytes[e], requested & valid)
                               : 0;
            q->dependency[i] = dep == SRV_NO_EFFECT
                                   ? SRV_NONE
                                   : kind->find(cache, dep, kind->rekey(kind->block_key(cache, e, b), dep));
            q->take[i] = 0;
        }
    }
    /* The budget: empty texels of every effect in registry order, then refinement, then the refresh of
     * continuous effects. */
    uint64_t budget_left = loop->desc.ray_budget;
    for (uint32_t round = 0; round < 3; round++)
        for (uint32_t e = 0; e < loop->effect_count; e++) {
            if (srv_pool_stopped(loop->pool))
                goto stopped;
            const fx_effect *fx = loop->effects[e];
            if (!counts[e] || (round == 1 && fx->policy != FX_UPDATE_PROGRESSIVE) ||
                (round == 2 && fx->policy != FX_UPDATE_CONTINUOUS))
                continue;
            srv_effect_queue *q = &loop->queues[e];
            uint64_t cost = fx->cost(loop->s, loop->samples[e]);
            if (fx->policy == FX_UPDATE_CONTINUOUS) {
                if (round == 0)
                    continuous_order(loop, e, q, blocks[e], counts[e]);
                take_continuous(loop, e, q, counts[e], round == 2, cost, &budget_left, st);
                continue;
            }
            take_within_budget(loop, e, q, counts[e], round == 0 ? q->empty : q->refine, cost, &budget_left,
                               st);
        }
    /* One job per block with texels taken. */
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        srv_effect_queue *q = &loop->queues[e];
        if (!counts[e])
            continue;
        uint32_t jobs = 0;
        for (uint32_t i = 0; i < counts[e]; i++)
            jobs += q->take[i] != 0;
        if (!srv__grow(loop, SRV_MEM_QUEUES, (void **)&q->jobs, &q->job_capacity, jobs ? jobs : 1, 1024,
                       sizeof *q->jobs)) {
            st->drops[SRV_DROP_NOMEM_UPDATES]++;
            continue;
        }
        for (uint32_t i = 0; i < counts[e]; i++)
            if (q->take[i])
                q->jobs[q->job_count++] = (srv_job){
                    .block = blocks[e][i], .dependency_block = q->dependency[i], .mask = q->take[i]};
    }
    return;
stopped: /* the frame is abandoned (srv_loop_frame checks the flag next): no effect has jobs */
    for (uint32_t e = 0; e < loop->effect_count; e++)
        loop->queues[e].job_count = 0;
}

typedef struct effect_task {
    srv_loop *loop;
    const fx_effect *effect;
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
    task->rays[task_index] = task->effect->update(&task->loop->fx, task->jobs + first, n, task->samples);
}

static void commit_chunk(void *user, uint32_t task_index, uint32_t thread_index)
{
    (void)thread_index;
    effect_task *task = user;
    uint32_t first = task_index * CHUNK_BLOCKS;
    uint32_t n = task->count - first < CHUNK_BLOCKS ? task->count - first : CHUNK_BLOCKS;
    task->effect->commit(&task->loop->fx, task->jobs + first, n);
}

void srv__updates(srv_loop *loop, bool lookup, srv_frame_stats *st)
{
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        srv_effect_queue *q = &loop->queues[e];
        if (!loop->effect_cached[e] || loop->depended_on[e] != lookup || q->job_count == 0)
            continue;
        const srv_cache_kind *kind = loop->kinds[loop->effect_kind[e]];
        void *cache = loop->caches[loop->effect_kind[e]];
        uint32_t dep = loop->dependency[e];
        const fx_effect *fx = loop->effects[e];
        size_t count = q->job_count;
        uint32_t chunks = (uint32_t)((count + CHUNK_BLOCKS - 1) / CHUNK_BLOCKS);
        size_t scratch_bytes = fx->scratch_bytes ? fx->scratch_bytes(loop->s) : 0;
        if (!srv__grow(loop, SRV_MEM_QUEUES, (void **)&q->fx_jobs, &q->fx_job_capacity, count, 1024,
                       sizeof *q->fx_jobs) ||
            !srv__grow(loop, SRV_MEM_QUEUES, (void **)&q->chunk_rays, &q->chunk_capacity, chunks, 128,
                       sizeof *q->chunk_rays) ||
            (scratch_bytes && !srv__grow(loop, SRV_MEM_QUEUES, (void **)&q->scratch, &q->scratch_capacity,
                                         count * scratch_bytes, 65536, 1))) {
            st->drops[SRV_DROP_NOMEM_UPDATES]++;
            continue;
        }
        for (size_t i = 0; i < count; i++) {
            const srv_job *job = &q->jobs[i];
            fx_block_job *fj = &q->fx_jobs[i];
            memset(fj, 0, sizeof *fj);
            kind->job_location(cache, e, kind->block_key(cache, e, job->block), fj);
            fj->mask = job->mask;
            fj->scratch = scratch_bytes ? q->scratch + i * scratch_bytes : NULL;
            fj->effect = e;
            fj->lookup = dep == SRV_NO_EFFECT ? NULL : kind->block_payload(cache, dep, job->dependency_block);
            fj->payload = kind->block_payload(cache, e, job->block);
        }
        effect_task task = {.loop = loop,
                            .effect = loop->effects[e],
                            .jobs = q->fx_jobs,
                            .count = (uint32_t)count,
                            .samples = loop->samples[e],
                            .rays = q->chunk_rays};
        srv_pool_run(loop->pool, chunks, effect_chunk, &task);
        for (uint32_t c = 0; c < chunks; c++)
            st->rays[e] += q->chunk_rays[c];
        /* Every update has read what the last commit left; only now may the results become visible. */
        if (fx->commit)
            srv_pool_run(loop->pool, chunks, commit_chunk, &task);
        for (size_t i = 0; i < count; i++) {
            const srv_job *job = &q->jobs[i];
            kind->block_set_valid(cache, e, job->block, kind->block_valid(cache, e, job->block) | job->mask);
            uint32_t *word = kind->block_word ? kind->block_word(cache, e, job->block) : NULL;
            if (word)
                *word = loop->frame_number + 1; /* the frame of its last update, + 1 (0: never) */
            st->texels_updated[e] += (uint64_t)__builtin_popcountll(job->mask);
        }
    }
}
