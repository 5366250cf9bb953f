/* The loop: creation (effects resolved, caches per kind, scratch), viewers as handles, sinks, one frame in
 * DESIGN.md's stage order, memory. See engine.h. */
#include "engine_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static const char *const stage_names[SRV_STAGE_COUNT] = {"visibility", "requests", "queues", "lookup",
                                                         "effects",    "compose",  "sinks",  "housekeeping"};

const char *srv_stage_name(srv_stage stage)
{
    return (unsigned)stage < SRV_STAGE_COUNT ? stage_names[stage] : "?";
}

static const char *const drop_names[SRV_DROP_COUNT] = {"nomem_requests", "nomem_updates", "pool_exhausted",
                                                       "table_full", "no_dependency"};

const char *srv_drop_name(srv_drop drop)
{
    return (unsigned)drop < SRV_DROP_COUNT ? drop_names[drop] : "?";
}

double srv__now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* ---- counted allocation ------------------------------------------------------------------------------ */

bool srv__resize(srv_loop *loop, srv_mem_category category, void **array, size_t old_count, size_t new_count,
                 size_t size)
{
    const srv_allocator *a = &loop->desc.allocator;
    if (new_count == 0) {
        if (*array) {
            if (a->free)
                a->free(*array, old_count * size, a->user);
            else
                free(*array);
        }
        *array = NULL;
        atomic_fetch_sub(&loop->mem[category], (uint64_t)old_count * size);
        return true;
    }
    if (size == 0 || new_count > SIZE_MAX / size)
        return false;
    void *p;
    if (a->realloc) {
        p = a->realloc(*array, old_count * size, new_count * size, a->user);
    } else {
        /* Cache-line aligned (glibc's large blocks start 16 bytes into a page): a tile's row of 16 pixels of
         * a per-pixel float array is then one line, not two, for compose's gather. */
        size_t bytes = new_count * size;
        if (bytes > SIZE_MAX - 63)
            return false;
        p = aligned_alloc(64, (bytes + 63) & ~(size_t)63);
        if (p && *array) {
            memcpy(p, *array, (old_count < new_count ? old_count : new_count) * size);
            free(*array);
        }
    }
    if (!p)
        return false;
    *array = p;
    atomic_fetch_add(&loop->mem[category], (uint64_t)new_count * size);
    atomic_fetch_sub(&loop->mem[category], (uint64_t)old_count * size);
    return true;
}

bool srv__grow(srv_loop *loop, srv_mem_category category, void **array, size_t *capacity, size_t n,
               size_t first, size_t size)
{
    if (n <= *capacity)
        return true;
    size_t cap = *capacity ? *capacity : first;
    while (cap < n && cap <= SIZE_MAX / 2)
        cap *= 2;
    if (cap < n)
        cap = n;
    if (!srv__resize(loop, category, array, *capacity, cap, size))
        return false;
    *capacity = cap;
    return true;
}

bool srv__request_reserve(srv_loop *loop, srv_mem_category category, srv_request_list *list, size_t n)
{
    if (n <= list->capacity)
        return true;
    size_t cap = list->capacity ? list->capacity : 4096;
    while (cap < n && cap <= SIZE_MAX / 2)
        cap *= 2;
    if (cap < n)
        cap = n;
    /* Grow the three arrays; on a failure the grown ones keep their larger size (counted) and the list keeps
     * its old capacity, so nothing is lost or miscounted. */
    if (!srv__resize(loop, category, (void **)&list->keys, list->keys_capacity, cap, sizeof *list->keys))
        return false;
    list->keys_capacity = cap;
    if (!srv__resize(loop, category, (void **)&list->masks, list->masks_capacity, cap, sizeof *list->masks))
        return false;
    list->masks_capacity = cap;
    if (!srv__resize(loop, category, (void **)&list->blocks, list->blocks_capacity, cap,
                     sizeof *list->blocks))
        return false;
    list->blocks_capacity = cap;
    list->capacity = cap;
    return true;
}

void srv__request_list_free(srv_loop *loop, srv_mem_category category, srv_request_list *list)
{
    srv__resize(loop, category, (void **)&list->keys, list->keys_capacity, 0, sizeof *list->keys);
    srv__resize(loop, category, (void **)&list->masks, list->masks_capacity, 0, sizeof *list->masks);
    srv__resize(loop, category, (void **)&list->blocks, list->blocks_capacity, 0, sizeof *list->blocks);
    memset(list, 0, sizeof *list);
}

/* ---- creation ------------------------------------------------------------------------------------------ */

/* Resolves the effect list: dependencies by name, which effects run and how. */
static fxc_result resolve_effects(srv_loop *loop, char *err, size_t err_cap)
{
    const srv_loop_desc *d = &loop->desc;
    const fx_effect *const *list = d->effects;
    uint32_t count = d->effect_count;
    if (!list)
        list = fx_registry(&count);
    if (count == 0 || count > SRV_MAX_EFFECTS) {
        snprintf(err, err_cap, "frame loop: %u effects (1..%d)", count, SRV_MAX_EFFECTS);
        return FXC_ERR_EFFECTS;
    }
    loop->effect_count = count;
    for (uint32_t e = 0; e < count; e++) {
        const fx_effect *fx = list[e];
        if (!fx || !fx->name || !fx->texel_bytes || !fx->update || !fx->cost ||
            (fx->policy == FX_UPDATE_PROGRESSIVE && (!fx->texel_samples || fx->max_samples == 0)) ||
            fx->cache >= SCENE_CACHE_COUNT) {
            snprintf(err, err_cap,
                     "frame loop: effect %u (%s) lacks a name, texel_bytes, cost or update, or is "
                     "progressive without texel_samples and max_samples",
                     e, fx && fx->name ? fx->name : "?");
            return FXC_ERR_EFFECTS;
        }
        loop->effects[e] = fx;
        loop->effect_kind[e] = fx->cache;
        loop->dependency[e] = SRV_NO_EFFECT;
        if (fx->depends_on) {
            int32_t dep = fx_find(list, count, fx->depends_on);
            if (dep < 0 || (uint32_t)dep == e || list[dep]->depends_on || list[dep]->cache != fx->cache) {
                snprintf(err, err_cap,
                         "frame loop: effect %s depends on '%s', which is not in the list, is itself "
                         "dependent, or lives in another cache",
                         fx->name, fx->depends_on);
                return FXC_ERR_EFFECTS;
            }
            loop->dependency[e] = (uint32_t)dep;
        }
    }
    for (uint32_t e = 0; e < count; e++) {
        loop->effect_on[e] = d->effect_on[e];
        /* An effect that shades nothing runs only for the effects that depend on it. */
        if (!loop->effects[e]->shade && !loop->effects[e]->eval)
            loop->effect_on[e] = false;
    }
    for (uint32_t e = 0; e < count; e++)
        if (loop->effect_on[e] && loop->dependency[e] != SRV_NO_EFFECT && !d->no_cache) {
            loop->effect_on[loop->dependency[e]] = true;
            loop->depended_on[loop->dependency[e]] = true;
        }
    for (uint32_t e = 0; e < count; e++) {
        const fx_effect *fx = loop->effects[e];
        loop->effect_cached[e] = loop->effect_on[e] && !d->no_cache && srv__cache_kind(fx->cache) != NULL;
        loop->effect_shading[e] = loop->effect_cached[e] && fx->shade != NULL;
        loop->bias[e] = d->bias_set[e] ? d->bias[e] : fx->level_bias;
        uint32_t step = d->samples_per_update ? d->samples_per_update : 16;
        uint32_t run = fx->run_samples ? fx->run_samples(&loop->fx) : 0;
        loop->max_samples[e] = fx->policy == FX_UPDATE_PROGRESSIVE && run ? run : fx->max_samples;
        loop->samples[e] = fx->policy == FX_UPDATE_PROGRESSIVE
                               ? (step < loop->max_samples[e] ? step : loop->max_samples[e])
                               : (fx->policy == FX_UPDATE_ONCE ? run : 0);
        if (fx->policy == FX_UPDATE_CONTINUOUS && fx->cache == SCENE_CACHE_WORLD_SPACE)
            loop->samples[e] = loop->desc.probe_rays; /* the rays of one update: what its cost counts */
        if (loop->effect_on[e] && !loop->effect_cached[e] && !d->no_cache) {
            snprintf(err, err_cap, "frame loop: effect %s needs the %s cache, which is not built yet",
                     fx->name, scene_cache_name(fx->cache));
            return FXC_ERR_EFFECTS;
        }
    }
    return FXC_OK;
}

/* Loops created so far in the process: each loop's fx_context.epoch (per-thread memos in the effects tell
 * one loop's frame from another's, even when a loop is freed and the next one reuses its addresses). */
static _Atomic uint64_t loop_epochs;

/* What probes have stored depends on the lights, the sky and the emitting materials: a hash of every field
 * that changes their light (FNV-1a over the fields' bytes), compared at each frame's start so that a light
 * switched or dimmed between frames lets converged probes refresh at once (update.c). Positions and
 * directions are in it too, though the shadow texels do not follow a light that moves. Materials' emission
 * (and the scene's emissive flag) are in it: a lamp switched on or off through its material is a change of
 * light as well (before, the probes kept its old light until their slow refresh). */
static uint64_t light_signature(const scene *s)
{
    uint64_t h = 14695981039346656037u;
    const void *parts[5];
    size_t sizes[5];
    for (uint32_t l = 0; l <= s->light_count; l++) {
        size_t n = 0;
        if (l < s->light_count) {
            const scene_light *light = &s->lights[l];
            parts[n] = &light->type, sizes[n++] = sizeof light->type;
            parts[n] = light->direction, sizes[n++] = sizeof light->direction;
            parts[n] = light->position, sizes[n++] = sizeof light->position;
            parts[n] = light->color, sizes[n++] = sizeof light->color;
            parts[n] = &light->intensity, sizes[n++] = sizeof light->intensity;
        } else {
            parts[n] = s->sky_color, sizes[n++] = sizeof s->sky_color;
            parts[n] = &s->sky_intensity, sizes[n++] = sizeof s->sky_intensity;
            parts[n] = &s->light_count, sizes[n++] = sizeof s->light_count;
        }
        for (size_t k = 0; k < n; k++)
            for (size_t b = 0; b < sizes[k]; b++)
                h = (h ^ ((const unsigned char *)parts[k])[b]) * 1099511628211u;
    }
    h = (h ^ (unsigned char)s->emissive) * 1099511628211u;
    for (uint32_t m = 0; s->emissive && m < s->material_count; m++)
        for (size_t b = 0; b < sizeof s->materials[m].emission; b++)
            h = (h ^ ((const unsigned char *)s->materials[m].emission)[b]) * 1099511628211u;
    return h;
}

fxc_result srv_loop_create(const srv_loop_desc *desc, srv_loop **out, char *err, size_t err_cap)
{
    *out = NULL;
    if (!desc || !desc->s || !desc->rt) {
        snprintf(err, err_cap, "frame loop: a scene and its Embree scene are required");
        return FXC_ERR_INVALID;
    }
    const srv_allocator *a = &desc->allocator;
    srv_loop *loop = a->realloc ? a->realloc(NULL, 0, sizeof *loop, a->user) : malloc(sizeof *loop);
    if (!loop) {
        snprintf(err, err_cap, "frame loop: out of memory");
        return FXC_ERR_NOMEM;
    }
    memset(loop, 0, sizeof *loop);
    loop->desc = *desc;
    atomic_store(&loop->mem[SRV_MEM_QUEUES], sizeof *loop);
    loop->s = desc->s;
    loop->rt = desc->rt;
    if (!loop->desc.pool_bytes)
        loop->desc.pool_bytes = (uint64_t)64 << 20;
    if (!loop->desc.probe_rays)
        loop->desc.probe_rays = 144;
    if (loop->desc.probe_hysteresis == 0.0f)
        loop->desc.probe_hysteresis = 0.97f;
    if (!loop->desc.probe_budget)
        loop->desc.probe_budget = 1024;
    if (!loop->desc.ao_samples)
        loop->desc.ao_samples = FX_AO_MAX_SAMPLES;
    if (!loop->desc.shadow_rays)
        loop->desc.shadow_rays = FX_SHADOW_RAYS;
    if (!loop->desc.indirect_block)
        loop->desc.indirect_block = 4;
    if (loop->desc.indirect_block != 1 && loop->desc.indirect_block != 2 && loop->desc.indirect_block != 4) {
        snprintf(err, err_cap, "frame loop: the indirect block must be 1, 2 or 4 pixels");
        srv_loop_free(loop);
        return FXC_ERR_INVALID;
    }
    if (!(loop->desc.no_cache_samples > 0))
        loop->desc.no_cache_samples = 1.0f;
    /* The probes' commit clamps its weight to 0.999 (fx_probes.c): a larger one, a negative one or NaN was
     * taken without a word (clamped, or replaced by the default); now each is refused, as the command line
     * refuses them (found by tests/stability/stab_stiffness.c). */
    if (loop->desc.probe_rays > 1u << 16 ||
        !(loop->desc.probe_hysteresis > 0.0f && loop->desc.probe_hysteresis <= 0.999f) ||
        !(loop->desc.probe_cell >= 0.0f && loop->desc.probe_cell <= 1e6f)) {
        snprintf(err, err_cap,
                 "frame loop: probe rays must be 1..65536, hysteresis in (0, 0.999], the cell 0..1e6 m");
        srv_loop_free(loop);
        return FXC_ERR_INVALID;
    }
    uint32_t shadow_rays = loop->desc.shadow_rays;
    int scale_exponent = 0;
    float scale_mantissa = frexpf(loop->desc.no_cache_samples, &scale_exponent);
    if (loop->desc.ao_samples > FX_AO_SAMPLES_LIMIT || shadow_rays > FX_SHADOW_TEXEL_RAYS_MAX ||
        (shadow_rays & (shadow_rays - 1)) != 0 || scale_mantissa != 0.5f || scale_exponent < -5 ||
        scale_exponent > 5) {
        snprintf(err, err_cap,
                 "frame loop: AO samples must be 1..%d, shadow rays 1, 2, 4, 8 or 16, the no-cache "
                 "sample scale a power of two in [1/64, 16]",
                 FX_AO_SAMPLES_LIMIT);
        srv_loop_free(loop);
        return FXC_ERR_INVALID;
    }
    loop->fx = (fx_context){.s = desc->s,
                            .rt = desc->rt,
                            .seed = desc->seed,
                            .ao_radius = desc->s->ao_radius,
                            .probe_rays = loop->desc.probe_rays,
                            .probe_hysteresis = loop->desc.probe_hysteresis,
                            .probe_plain_blend = loop->desc.probe_plain_blend,
                            .ao_samples = loop->desc.ao_samples,
                            .shadow_rays = shadow_rays,
                            .epoch = atomic_fetch_add(&loop_epochs, 1) + 1};
    /* After a change of the lights, converged probes refresh every frame until the old light's weight in
     * them, h^k after k blended updates, is below 1 % (7 frames at h = 0.5, 152 at the default 0.97). */
    loop->light_signature = light_signature(desc->s);
    loop->light_settle_frames = (uint32_t)ceil(log(0.01) / log((double)loop->desc.probe_hysteresis));
    if (loop->desc.no_cache) { /* the baseline's counts per pixel: the converged ones, scaled */
        double scale = loop->desc.no_cache_samples;
        double ao = fmax(1.0, floor(loop->desc.ao_samples * scale + 0.5));
        double shadow = fmin(fmax(1.0, shadow_rays * scale), FX_SHADOW_POINT_RAYS_MAX);
        double probe = fmin(fmax(1.0, floor(loop->desc.probe_rays * scale + 0.5)), FX_PROBE_MAX_RAYS);
        loop->fx.ao_samples = (uint32_t)ao;
        loop->fx.shadow_rays = (uint32_t)shadow;
        loop->fx.probe_rays = (uint32_t)probe;
    }
    fxc_result r = resolve_effects(loop, err, err_cap);
    if (r != FXC_OK) {
        srv_loop_free(loop);
        return r;
    }
    loop->pool = srv_pool_create(desc->threads);
    if (!loop->pool) {
        snprintf(err, err_cap, "frame loop: cannot start threads");
        srv_loop_free(loop);
        return FXC_ERR_THREADS;
    }
    for (uint32_t k = 0; k < SCENE_CACHE_COUNT; k++) {
        const srv_cache_kind *kind = srv__cache_kind((scene_cache_kind)k);
        if (!kind)
            continue;
        void *cache = NULL;
        r = kind->create(loop, &cache, err, err_cap);
        if (r != FXC_OK) {
            srv_loop_free(loop);
            return r;
        }
        if (cache) {
            loop->kinds[k] = kind;
            loop->caches[k] = cache;
        }
        if (cache && k == SCENE_CACHE_WORLD_SPACE) {
            loop->fx.world_taps = srv__wsc_world_taps;
            loop->fx.world_cell = srv__wsc_world_cell;
            loop->fx.world_user = cache;
        }
    }
    /* The effect whole frames evaluate per block (engine_internal.h, srv__coarse_mask): the first shading,
     * low-frequency one of a kind that batches per effect and reads positions (the world-space kind). */
    loop->coarse_effect = SRV_NO_EFFECT;
    loop->coarse_depth_scale = 3.0f / loop->s->texel_density;
    for (uint32_t e = 0; e < loop->effect_count && loop->desc.indirect_block > 1; e++) {
        const srv_cache_kind *kind = loop->kinds[loop->effect_kind[e]];
        if (loop->effect_shading[e] && loop->effects[e]->low_frequency && kind && !kind->keys_carry_effect &&
            kind->needs_position) {
            loop->coarse_effect = e;
            break;
        }
    }
    uint32_t threads = srv_pool_threads(loop->pool);
    bool ok = srv__resize(loop, SRV_MEM_QUEUES, (void **)&loop->thread_requests, 0, threads,
                          sizeof *loop->thread_requests);
    if (ok)
        memset(loop->thread_requests, 0, threads * sizeof *loop->thread_requests);
    for (uint32_t e = 0; ok && e < loop->effect_count; e++) {
        if (!desc->keep_views || !loop->effect_shading[e])
            continue;
        uint32_t k = loop->effect_kind[e];
        size_t blocks = loop->kinds[k]->pool_capacity(loop->caches[k], e);
        ok = srv__resize(loop, SRV_MEM_QUEUES, (void **)&loop->viewer_bits[e], 0, blocks, sizeof(uint64_t));
    }
    loop->compose_scratch_bytes = srv__compose_scratch_bytes(loop);
    ok = ok &&
         srv__resize(loop, SRV_MEM_QUEUES, &loop->compose_scratch, 0, threads, loop->compose_scratch_bytes);
    if (!ok) {
        snprintf(err, err_cap, "frame loop: out of memory");
        srv_loop_free(loop);
        return FXC_ERR_NOMEM;
    }
    *out = loop;
    return FXC_OK;
}

static void viewer_free_buffers(srv_loop *loop, srv_viewer *view)
{
    size_t n = view->pixels;
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->tri, n, 0, sizeof *view->tri);
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->bary_u, n, 0, sizeof(float));
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->bary_v, n, 0, sizeof(float));
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->footprint, n, 0, sizeof(float));
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->depth, n, 0, sizeof(float));
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->back, n, 0, 1);
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->coarse, view->coarse ? n : 0, 0, 1);
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->samples,
                view->samples ? SRV_SAMPLE_VALUES * view->sample_capacity : 0, 0, sizeof(float));
    view->sample_capacity = 0;
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->radiance, 3 * n, 0, sizeof(float));
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->image, 3 * n, 0, 1);
    for (int w = 0; w < SRV_VIEW_COUNT; w++)
        srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->views[w], view->views[w] ? n : 0, 0,
                    sizeof(float));
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->list, view->list ? n : 0, 0, sizeof *view->list);
    srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->list_scratch, view->list_scratch ? n : 0, 0,
                sizeof *view->list_scratch);
    srv__request_list_free(loop, SRV_MEM_VIEWERS, &view->requests);
}

void srv_loop_free(srv_loop *loop)
{
    if (!loop)
        return;
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        if (loop->viewers[v].present)
            viewer_free_buffers(loop, &loop->viewers[v]);
    uint32_t threads = loop->pool ? srv_pool_threads(loop->pool) : 0;
    if (loop->thread_requests) {
        for (uint32_t t = 0; t < threads; t++)
            srv__request_list_free(loop, SRV_MEM_QUEUES, &loop->thread_requests[t]);
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&loop->thread_requests, threads, 0,
                    sizeof *loop->thread_requests);
    }
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++) {
        srv_effect_queue *q = &loop->queues[e];
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&q->empty, q->capacity, 0, sizeof *q->empty);
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&q->refine, q->capacity, 0, sizeof *q->refine);
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&q->take, q->capacity, 0, sizeof *q->take);
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&q->dependency, q->capacity, 0, sizeof *q->dependency);
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&q->jobs, q->job_capacity, 0, sizeof *q->jobs);
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&q->fx_jobs, q->fx_job_capacity, 0, sizeof *q->fx_jobs);
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&q->chunk_rays, q->chunk_capacity, 0,
                    sizeof *q->chunk_rays);
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&q->scratch, q->scratch_capacity, 0, 1);
        srv__resize(loop, SRV_MEM_QUEUES, (void **)&q->order, q->order_capacity, 0, sizeof *q->order);
        if (loop->viewer_bits[e]) {
            uint32_t k = loop->effect_kind[e];
            size_t blocks = loop->kinds[k]->pool_capacity(loop->caches[k], e);
            srv__resize(loop, SRV_MEM_QUEUES, (void **)&loop->viewer_bits[e], blocks, 0, sizeof(uint64_t));
        }
    }
    if (loop->compose_scratch)
        srv__resize(loop, SRV_MEM_QUEUES, &loop->compose_scratch, threads, 0, loop->compose_scratch_bytes);
    for (uint32_t k = 0; k < SCENE_CACHE_COUNT; k++)
        if (loop->kinds[k])
            loop->kinds[k]->destroy(loop->caches[k]);
    srv_pool_free(loop->pool);
    srv_allocator a = loop->desc.allocator;
    if (a.free)
        a.free(loop, sizeof *loop, a.user);
    else
        free(loop);
}

/* ---- viewers ------------------------------------------------------------------------------------------- */

static srv_viewer *viewer_of(const srv_loop *loop, srv_viewer_id id)
{
    uint32_t slot = id.id & 0xFFu, generation = id.id >> 8;
    if (slot >= SRV_MAX_VIEWERS)
        return NULL;
    srv_viewer *view = (srv_viewer *)&loop->viewers[slot];
    return view->present && view->generation == generation ? view : NULL;
}

fxc_result srv_viewer_check(const srv_loop *loop, srv_viewer_id id)
{
    return viewer_of(loop, id) ? FXC_OK : FXC_ERR_STALE_ID;
}

fxc_result srv_viewer_add(srv_loop *loop, const srv_viewer_desc *desc, srv_viewer_id *out)
{
    out->id = 0;
    srv_viewer_desc d = desc ? *desc : (srv_viewer_desc){0};
    if (d.max_pixels > SRV_MAX_PIXEL_LIST)
        return FXC_ERR_INVALID;
    if (d.max_pixels) /* a sparse viewer: each list brings its image size */
        d.width = d.height = 1;
    if (!d.width && !d.height)
        d.width = 640, d.height = 360;
    if (d.width < 1 || d.height < 1 || d.width > SRV_MAX_SIDE || d.height > SRV_MAX_SIDE)
        return FXC_ERR_INVALID;
    uint32_t slot = 0;
    while (slot < SRV_MAX_VIEWERS && loop->viewers[slot].present)
        slot++;
    if (slot == SRV_MAX_VIEWERS)
        return FXC_ERR_NO_SLOT;
    srv_viewer *view = &loop->viewers[slot];
    uint32_t generation = view->generation + 1;
    if (generation >= (1u << 24))
        generation = 1; /* wraps after 16 million re-uses of one slot */
    memset(view, 0, sizeof *view);
    view->generation = generation;
    view->desc = d;
    if (!view->desc.name[0])
        snprintf(view->desc.name, sizeof view->desc.name, "viewer_%02u", slot);
    view->sparse = d.max_pixels > 0;
    size_t n = view->sparse ? d.max_pixels : (size_t)d.width * d.height;
    bool ok = srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->tri, 0, n, sizeof *view->tri);
    view->pixels = n; /* from here on viewer_free_buffers frees what was allocated */
    ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->bary_u, 0, n, sizeof(float));
    ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->bary_v, 0, n, sizeof(float));
    ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->footprint, 0, n, sizeof(float));
    ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->depth, 0, n, sizeof(float));
    ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->back, 0, n, 1);
    if (!view->sparse && loop->coarse_effect != SRV_NO_EFFECT) { /* requests' sample choice for compose */
        ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->coarse, 0, n, 1);
        /* the frame-wide sample image, sized for the smallest block (2) */
        size_t samples = (size_t)srv__sample_stride(d.width, 2) * srv__sample_stride(d.height, 2);
        ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->samples, 0, SRV_SAMPLE_VALUES * samples,
                               sizeof(float));
        if (ok)
            view->sample_capacity = samples;
    }
    ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->radiance, 0, 3 * n, sizeof(float));
    ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->image, 0, 3 * n, 1);
    if (view->sparse) {
        ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->list, 0, n, sizeof *view->list);
        ok = ok && srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->list_scratch, 0, n,
                               sizeof *view->list_scratch);
    }
    for (int w = 0; ok && loop->desc.keep_views && w < SRV_VIEW_COUNT; w++) {
        ok = srv__resize(loop, SRV_MEM_VIEWERS, (void **)&view->views[w], 0, n, sizeof(float));
        if (ok)
            memset(view->views[w], 0, n * sizeof(float));
    }
    if (!ok) {
        viewer_free_buffers(loop, view);
        view->present = false;
        return FXC_ERR_NOMEM;
    }
    view->present = true;
    out->id = generation << 8 | slot;
    return FXC_OK;
}

fxc_result srv_viewer_remove(srv_loop *loop, srv_viewer_id id)
{
    srv_viewer *view = viewer_of(loop, id);
    if (!view)
        return FXC_ERR_STALE_ID;
    viewer_free_buffers(loop, view);
    for (uint32_t k = 0; k < SCENE_CACHE_COUNT; k++)
        if (loop->kinds[k] && loop->kinds[k]->viewer_removed)
            loop->kinds[k]->viewer_removed(loop->caches[k], (uint32_t)(view - loop->viewers));
    uint32_t generation = view->generation;
    memset(view, 0, sizeof *view);
    view->generation = generation; /* the next add bumps it: this id stays refused */
    return FXC_OK;
}

fxc_result srv_viewer_set_camera(srv_loop *loop, srv_viewer_id id, const srv_camera *camera)
{
    srv_viewer *view = viewer_of(loop, id);
    if (!view)
        return FXC_ERR_STALE_ID;
    if (view->sparse)
        return FXC_ERR_INVALID;
    srv_camera_frame frame;
    if (!camera || !srv_camera_setup(camera, view->desc.width, view->desc.height, &frame))
        return FXC_ERR_CAMERA;
    view->camera = *camera;
    view->frame = frame;
    view->has_camera = true;
    return FXC_OK;
}

/* Sorts n keys (below 2^32) in place, least significant byte first (four counting
 * passes, O(n), no comparison sort), through scratch; passes whose byte is the same for every entry are
 * skipped. */
static void sort_pixels(uint32_t *keys, uint32_t *scratch, uint32_t n)
{
    uint32_t *from = keys, *to = scratch;
    for (uint32_t shift = 0; shift < 32; shift += 8) {
        uint32_t counts[256] = {0};
        for (uint32_t i = 0; i < n; i++)
            counts[(from[i] >> shift) & 0xFFu]++;
        if (counts[(from[0] >> shift) & 0xFFu] == n)
            continue;
        uint32_t sum = 0;
        for (uint32_t b = 0; b < 256; b++) {
            uint32_t c = counts[b];
            counts[b] = sum;
            sum += c;
        }
        for (uint32_t i = 0; i < n; i++)
            to[counts[(from[i] >> shift) & 0xFFu]++] = from[i];
        uint32_t *swap = from;
        from = to;
        to = swap;
    }
    if (from != keys)
        memcpy(keys, from, (size_t)n * sizeof *keys);
}

fxc_result srv_viewer_set_pixels(srv_loop *loop, srv_viewer_id id, const srv_camera *camera, uint32_t width,
                                 uint32_t height, const uint32_t *pixels, uint32_t count, uint32_t *unique)
{
    srv_viewer *view = viewer_of(loop, id);
    if (!view)
        return FXC_ERR_STALE_ID;
    if (!view->sparse || !pixels || width < 1 || height < 1 || width > SRV_MAX_SIDE || height > SRV_MAX_SIDE)
        return FXC_ERR_INVALID;
    if (count == 0 || count > view->desc.max_pixels)
        return FXC_ERR_RANGE;
    for (uint32_t i = 0; i < count; i++)
        if ((pixels[i] & 0xFFFFu) >= width || (pixels[i] >> 16) >= height)
            return FXC_ERR_RANGE;
    srv_camera_frame frame;
    if (!camera || !srv_camera_setup(camera, width, height, &frame))
        return FXC_ERR_CAMERA;
    uint32_t tiles_x = (width + SRV_TILE - 1) / SRV_TILE;
    for (uint32_t i = 0; i < count; i++)
        view->list[i] = srv__run_key(pixels[i], tiles_x);
    sort_pixels(view->list, view->list_scratch, count);
    uint32_t distinct = 1;
    for (uint32_t i = 1; i < count; i++)
        if (view->list[i] != view->list[distinct - 1])
            view->list[distinct++] = view->list[i];
    for (uint32_t i = 0; i < distinct; i++)
        view->list[i] = srv__run_key_pixel(view->list[i], tiles_x);
    view->list_count = distinct;
    view->desc.width = width;
    view->desc.height = height;
    view->camera = *camera;
    view->frame = frame;
    view->has_camera = true;
    view->rendered = false; /* the buffers now belong to this list */
    if (unique)
        *unique = distinct;
    return FXC_OK;
}

const uint32_t *srv_viewer_pixels(const srv_loop *loop, srv_viewer_id id, uint32_t *count)
{
    const srv_viewer *view = viewer_of(loop, id);
    if (!view || !view->sparse || !view->rendered) {
        if (count)
            *count = 0;
        return NULL;
    }
    if (count)
        *count = view->list_count;
    return view->list;
}

uint32_t srv_viewer_pixel_index(const srv_loop *loop, srv_viewer_id id, uint32_t x, uint32_t y)
{
    uint32_t count;
    const uint32_t *list = srv_viewer_pixels(loop, id, &count);
    if (!list)
        return UINT32_MAX;
    const srv_camera_frame *f = &viewer_of(loop, id)->frame;
    if (x >= f->width || y >= f->height)
        return UINT32_MAX;
    uint32_t tiles_x = (f->width + SRV_TILE - 1) / SRV_TILE;
    uint32_t want = SRV_PIXEL_XY(x, y), want_key = srv__run_key(want, tiles_x), lo = 0, hi = count;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (srv__run_key(list[mid], tiles_x) < want_key)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < count && list[lo] == want ? lo : UINT32_MAX;
}

uint32_t srv_loop_viewers(const srv_loop *loop, srv_viewer_id *ids, uint32_t cap)
{
    uint32_t n = 0;
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        if (loop->viewers[v].present) {
            if (ids && n < cap)
                ids[n] = (srv_viewer_id){loop->viewers[v].generation << 8 | v};
            n++;
        }
    return n;
}

const uint8_t *srv_viewer_image(const srv_loop *loop, srv_viewer_id id)
{
    const srv_viewer *view = viewer_of(loop, id);
    return view && view->rendered ? view->image : NULL;
}

const float *srv_viewer_radiance(const srv_loop *loop, srv_viewer_id id)
{
    const srv_viewer *view = viewer_of(loop, id);
    return view && view->rendered ? view->radiance : NULL;
}

const float *srv_viewer_depth(const srv_loop *loop, srv_viewer_id id)
{
    const srv_viewer *view = viewer_of(loop, id);
    /* An abandoned frame's visibility may have rewritten part of it (the image is still the last frame's). */
    return view && view->rendered && !loop->abandoned ? view->depth : NULL;
}

const float *srv_viewer_view(const srv_loop *loop, srv_viewer_id id, int which)
{
    const srv_viewer *view = viewer_of(loop, id);
    if (!view || !view->rendered || which < 0 || which >= SRV_VIEW_COUNT)
        return NULL;
    return view->views[which];
}

fxc_result srv_viewer_size(const srv_loop *loop, srv_viewer_id id, uint32_t *width, uint32_t *height)
{
    const srv_viewer *view = viewer_of(loop, id);
    if (!view)
        return FXC_ERR_STALE_ID;
    if (width)
        *width = view->desc.width;
    if (height)
        *height = view->desc.height;
    return FXC_OK;
}

fxc_result srv_loop_add_sink(srv_loop *loop, const srv_sink *sink)
{
    if (!sink || loop->sink_count == SRV_MAX_SINKS)
        return FXC_ERR_INVALID;
    loop->sinks[loop->sink_count++] = *sink;
    return FXC_OK;
}

/* ---- the frame ----------------------------------------------------------------------------------------- */

void srv_loop_set_stop(srv_loop *loop, const volatile sig_atomic_t *stop)
{
    srv_pool_set_stop(loop->pool, stop);
}

/* True (and the loop marked) when the stop flag is set: the frame in progress is abandoned. Checked after
 * every stage that runs on the pool, before anything reads what its skipped tasks did not write. */
static bool abandon(srv_loop *loop)
{
    if (srv_pool_stopped(loop->pool))
        loop->abandoned = true;
    return loop->abandoned;
}

fxc_result srv_loop_frame(srv_loop *loop, srv_frame_stats *st)
{
    memset(st, 0, sizeof *st);
    st->frame = loop->frame_number;
    if (abandon(loop))
        return FXC_ERR_SHUTDOWN;
    double frame_start = srv__now_ms();
    uint64_t lights = light_signature(loop->s);
    if (lights != loop->light_signature) {
        loop->light_signature = lights;
        loop->light_change_frame = loop->frame_number;
        loop->light_changed = true;
    }
    uint32_t slots[SRV_MAX_VIEWERS], active = 0;
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        if (loop->viewers[v].present && loop->viewers[v].has_camera)
            slots[active++] = v;
    st->viewer_count = active;

    loop->fx.frame = loop->frame_number + 1;

    /* Stage 2: visibility. */
    double t = srv__now_ms();
    for (uint32_t i = 0; i < active; i++)
        srv__visibility(loop, &loop->viewers[slots[i]]);
    st->time_ms[SRV_STAGE_VISIBILITY] = srv__now_ms() - t;
    if (abandon(loop))
        return FXC_ERR_SHUTDOWN;
    for (uint32_t i = 0; i < active; i++) {
        srv_viewer *view = &loop->viewers[slots[i]];
        memset(&view->stats, 0, sizeof view->stats);
        view->stats.id = (srv_viewer_id){view->generation << 8 | slots[i]};
        view->stats.width = view->desc.width;
        view->stats.height = view->desc.height;
        size_t pixels = srv__viewer_pixel_count(view);
        for (size_t p = 0; p < pixels; p++)
            view->stats.pixels_visible += view->tri[p] != SRV_MISS;
        view->stats.pixels_rendered = pixels;
        view->stats.sparse = view->sparse;
        st->visibility_rays += pixels;
        st->pixels_visible += view->stats.pixels_visible;
    }

    /* Stage 3: requests from every viewer into the shared caches. */
    t = srv__now_ms();
    for (uint32_t k = 0; k < SCENE_CACHE_COUNT; k++)
        if (loop->kinds[k])
            loop->kinds[k]->begin_frame(loop->caches[k], loop->frame_number);
    for (uint32_t e = 0; e < loop->effect_count; e++)
        if (loop->viewer_bits[e]) {
            uint32_t k = loop->effect_kind[e];
            memset(loop->viewer_bits[e], 0,
                   sizeof(uint64_t) * loop->kinds[k]->pool_capacity(loop->caches[k], e));
        }
    for (uint32_t i = 0; i < active; i++) {
        srv_viewer *view = &loop->viewers[slots[i]];
        uint64_t requested[SCENE_CACHE_COUNT];
        srv__requests(loop, slots[i], st, requested);
        view->stats.requested_texels = requested[SCENE_CACHE_ON_SURFACE];
        view->stats.requested_cells = requested[SCENE_CACHE_WORLD_SPACE];
        st->requested_texels += view->stats.requested_texels;
        st->world.requested_cells += view->stats.requested_cells;
    }
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        if (!loop->effect_shading[e])
            continue;
        uint32_t k = loop->effect_kind[e], n = 0;
        const uint32_t *blocks = loop->kinds[k]->frame_blocks(loop->caches[k], e, &n);
        uint64_t unique = 0;
        for (uint32_t b = 0; b < n; b++)
            unique += (uint64_t)__builtin_popcountll(
                loop->kinds[k]->block_requested(loop->caches[k], e, blocks[b]));
        if (k == SCENE_CACHE_WORLD_SPACE)
            st->world.unique_cells += unique;
        else
            st->unique_texels += unique;
    }
    st->time_ms[SRV_STAGE_REQUESTS] = srv__now_ms() - t;
    if (abandon(loop))
        return FXC_ERR_SHUTDOWN;

    /* Stages 4-6: queues for every effect, then the lookup, then every effect's updates. */
    t = srv__now_ms();
    srv__queues(loop, st);
    st->time_ms[SRV_STAGE_QUEUES] = srv__now_ms() - t;
    if (abandon(loop)) /* the queues may have stopped part-way: no update reads them */
        return FXC_ERR_SHUTDOWN;
    t = srv__now_ms();
    srv__updates(loop, true, st);
    st->time_ms[SRV_STAGE_LOOKUP] = srv__now_ms() - t;
    t = srv__now_ms();
    srv__updates(loop, false, st);
    st->time_ms[SRV_STAGE_EFFECTS] = srv__now_ms() - t;
    if (abandon(loop))
        return FXC_ERR_SHUTDOWN;

    /* Stage 7: compose. */
    t = srv__now_ms();
    for (uint32_t i = 0; i < active; i++)
        srv__compose(loop, slots[i], st);
    st->time_ms[SRV_STAGE_COMPOSE] = srv__now_ms() - t;
    if (abandon(loop)) {
        /* Some images, radiance and views were written by this frame, some by the last, some in part: none
         * is a frame any more. Before compose they are still the last frame's. */
        for (uint32_t i = 0; i < active; i++)
            loop->viewers[slots[i]].rendered = false;
        return FXC_ERR_SHUTDOWN;
    }
    for (uint32_t i = 0; i < active; i++) {
        srv_viewer *view = &loop->viewers[slots[i]];
        view->rendered = true;
        if (view->sparse)
            view->has_camera = false; /* its list is spent: nothing more until the next one */
        st->viewers[i] = view->stats;
        st->pixels_missing += view->stats.pixels_missing;
    }

    /* Stage 8: the sinks get every viewer's frame. */
    t = srv__now_ms();
    uint32_t sink_failures = 0;
    for (uint32_t s = 0; s < loop->sink_count; s++) {
        if (!loop->sinks[s].viewer_frame)
            continue;
        for (uint32_t i = 0; i < active; i++) {
            srv_viewer *view = &loop->viewers[slots[i]];
            if (view->sparse)
                continue; /* no whole image: read with srv_viewer_pixels */
            srv_viewer_frame vf = {.id = st->viewers[i].id,
                                   .name = view->desc.name,
                                   .frame = st->frame,
                                   .width = view->desc.width,
                                   .height = view->desc.height,
                                   .srgb = view->image,
                                   .radiance = view->radiance,
                                   .depth = view->depth,
                                   .camera = view->camera,
                                   .stats = &st->viewers[i]};
            for (int w = 0; w < SRV_VIEW_COUNT; w++)
                vf.views[w] = view->views[w];
            sink_failures += loop->sinks[s].viewer_frame(loop->sinks[s].user, &vf) != 0;
        }
    }
    st->time_ms[SRV_STAGE_SINKS] = srv__now_ms() - t;

    /* Stage 9: housekeeping and the caches' figures. */
    t = srv__now_ms();
    for (uint32_t k = 0; k < SCENE_CACHE_COUNT; k++)
        if (loop->kinds[k]) {
            loop->kinds[k]->housekeeping(loop->caches[k]);
            loop->kinds[k]->frame_figures(loop->caches[k], st);
        }
    st->time_ms[SRV_STAGE_HOUSEKEEPING] = srv__now_ms() - t;
    st->frame_ms = srv__now_ms() - frame_start;
    loop->frame_number++;
    for (uint32_t s = 0; s < loop->sink_count; s++)
        if (loop->sinks[s].frame_done)
            sink_failures += loop->sinks[s].frame_done(loop->sinks[s].user, st) != 0;
    return sink_failures ? FXC_ERR_IO : FXC_OK;
}

/* ---- effects and memory ------------------------------------------------------------------------------ */

uint32_t srv_loop_effect_count(const srv_loop *loop)
{
    return loop->effect_count;
}

const fx_effect *srv_loop_effect(const srv_loop *loop, uint32_t index)
{
    return index < loop->effect_count ? loop->effects[index] : NULL;
}

bool srv_loop_effect_on(const srv_loop *loop, uint32_t index)
{
    return index < loop->effect_count && loop->effect_on[index];
}

bool srv_loop_effect_cached(const srv_loop *loop, uint32_t index)
{
    return index < loop->effect_count && loop->effect_shading[index];
}

int32_t srv_loop_bias(const srv_loop *loop, uint32_t index)
{
    return index < loop->effect_count ? loop->bias[index] : 0;
}

void srv_loop_set_observer(srv_loop *loop, void (*occlusion)(void *user, const void *rays, uint32_t count),
                           void (*hits)(void *user, const void *rayhits, uint32_t count), void *user)
{
    loop->fx.observe_rays = occlusion;
    loop->fx.observe_hits = hits;
    loop->fx.observe_user = user;
}

float srv_loop_probe_cell(const srv_loop *loop)
{
    return loop->kinds[SCENE_CACHE_WORLD_SPACE] ? loop->desc.probe_cell : 0.0f;
}

const srv_loop_desc *srv_loop_desc_of(const srv_loop *loop)
{
    return &loop->desc;
}

void srv_loop_memory(const srv_loop *loop, srv_memory *out)
{
    memset(out, 0, sizeof *out);
    for (uint32_t k = 0; k < SCENE_CACHE_COUNT; k++)
        if (loop->kinds[k])
            loop->kinds[k]->memory(loop->caches[k], out);
    out->viewers = atomic_load(&loop->mem[SRV_MEM_VIEWERS]);
    out->queues = atomic_load(&loop->mem[SRV_MEM_QUEUES]);
    out->total += out->viewers + out->queues;
}
