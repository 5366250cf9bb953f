/* The frame loop: creation (the cache and every buffer sized once), one frame in DESIGN.md's stage order,
 * statistics and memory. See frame.h. */
#include "frame_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static const char *const stage_names[SRV_STAGE_COUNT] = {"visibility", "requests", "queues", "lookup",
                                                         "effects", "compose", "housekeeping"};

const char *srv_stage_name(srv_stage stage)
{
    return (unsigned)stage < SRV_STAGE_COUNT ? stage_names[stage] : "?";
}

double srv__now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

size_t srv__grown_capacity(size_t capacity, size_t n, size_t first)
{
    if (n <= capacity)
        return capacity;
    size_t cap = capacity ? capacity : first;
    while (cap < n && cap <= SIZE_MAX / 2)
        cap *= 2;
    return cap < n ? n : cap;
}

bool srv__realloc(void **array, size_t count, size_t size)
{
    if (count == 0 || size > SIZE_MAX / count)
        return false;
    void *p = realloc(*array, count * size);
    if (!p)
        return false;
    *array = p;
    return true;
}

srv_loop *srv_loop_create(const srv_loop_desc *desc, char *err, size_t err_cap)
{
    if (!desc->s || !desc->rt || desc->viewer_count < 1 || desc->viewer_count > SRV_MAX_VIEWERS) {
        snprintf(err, err_cap, "frame loop: a scene, its Embree scene and 1..%d viewers are required",
                 SRV_MAX_VIEWERS);
        return NULL;
    }
    srv_loop *loop = calloc(1, sizeof *loop);
    if (!loop) {
        snprintf(err, err_cap, "frame loop: out of memory");
        return NULL;
    }
    loop->desc = *desc;
    srv_loop_desc *d = &loop->desc;
    if (!d->width || !d->height)
        d->width = 640, d->height = 360;
    if (!d->pool_bytes)
        d->pool_bytes = (uint64_t)64 << 20;
    if (!d->ao_samples_per_frame)
        d->ao_samples_per_frame = 16;
    if (d->ao_samples_per_frame > FX_AO_MAX_SAMPLES)
        d->ao_samples_per_frame = FX_AO_MAX_SAMPLES;
    loop->s = d->s;
    loop->rt = d->rt;
    loop->fx = (fx_context){.s = d->s, .rt = d->rt, .seed = d->seed, .ao_radius = d->s->ao_radius};
    d->effect_on[SCENE_FX_PROBES] = false; /* not implemented yet: the world-space cache is a later issue */
    d->effect_on[SCENE_FX_TRIANGLE_LOOKUP] = d->effect_on[SCENE_FX_SHADOW] || d->effect_on[SCENE_FX_AO];
    if (d->s->light_count == 0)
        d->effect_on[SCENE_FX_SHADOW] = false;

    uint32_t total_texel_bytes = 0;
    for (uint32_t fx = 0; fx <= FX_AO; fx++) {
        loop->info[fx] = fx_describe(fx, d->s);
        loop->bias[fx] = d->bias_set[fx] ? d->bias[fx] : loop->info[fx].level_bias;
        loop->cached_effect[fx] = fx != FX_TRI_LOOKUP && d->effect_on[fx] && !d->no_cache;
        if (d->effect_on[fx] && !d->no_cache)
            total_texel_bytes += loop->info[fx].texel_bytes;
    }
    loop->pool = srv_pool_create(d->threads);
    if (!loop->pool) {
        snprintf(err, err_cap, "frame loop: cannot start threads");
        srv_loop_free(loop);
        return NULL;
    }
    if (total_texel_bytes > 0) {
        /* Every effect gets the same number of blocks: a block of each effect covers the same texels. */
        uint64_t blocks = d->pool_bytes / (64ull * total_texel_bytes);
        if (blocks < 64)
            blocks = 64;
        if (blocks > (1u << 26))
            blocks = 1u << 26;
        osc_desc od = {0};
        for (uint32_t fx = 0; fx <= FX_AO; fx++)
            if (d->effect_on[fx])
                od.effects[fx] = (osc_effect_desc){.texel_bytes = loop->info[fx].texel_bytes,
                                                   .max_blocks = (uint32_t)blocks};
        char msg[256];
        if (osc_create(&od, &loop->osc, msg, sizeof msg) != OSC_OK) {
            snprintf(err, err_cap, "frame loop: cannot create the on-surface cache: %s", msg);
            srv_loop_free(loop);
            return NULL;
        }
        if (d->keep_views)
            for (uint32_t fx = FX_SHADOW; fx <= FX_AO; fx++)
                if (loop->cached_effect[fx]) {
                    loop->viewer_bits[fx] = calloc(blocks, sizeof(uint64_t));
                    if (!loop->viewer_bits[fx]) {
                        snprintf(err, err_cap, "frame loop: out of memory");
                        srv_loop_free(loop);
                        return NULL;
                    }
                }
    }
    uint32_t threads = srv_pool_threads(loop->pool);
    loop->thread_requests = calloc(threads, sizeof *loop->thread_requests);
    size_t pixels = (size_t)d->width * d->height;
    bool ok = loop->thread_requests != NULL;
    for (uint32_t v = 0; ok && v < d->viewer_count; v++) {
        srv_viewer *view = &loop->viewers[v];
        view->tri = malloc(pixels * sizeof *view->tri);
        view->bary_u = malloc(pixels * sizeof(float));
        view->bary_v = malloc(pixels * sizeof(float));
        view->footprint = malloc(pixels * sizeof(float));
        view->radiance = malloc(pixels * 3 * sizeof(float));
        view->image = malloc(pixels * 3);
        ok = view->tri && view->bary_u && view->bary_v && view->footprint && view->radiance && view->image;
        if (d->keep_views)
            for (int w = 0; w < SRV_VIEW_COUNT; w++)
                ok = ok && (view->views[w] = calloc(pixels, sizeof(float))) != NULL;
    }
    if (!ok) {
        snprintf(err, err_cap, "frame loop: out of memory for %u viewers of %ux%u", d->viewer_count, d->width,
                 d->height);
        srv_loop_free(loop);
        return NULL;
    }
    return loop;
}

static void request_list_free(srv_request_list *list)
{
    free(list->keys);
    free(list->masks);
    free(list->blocks);
}

void srv_loop_free(srv_loop *loop)
{
    if (!loop)
        return;
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++) {
        srv_viewer *view = &loop->viewers[v];
        free(view->tri);
        free(view->bary_u);
        free(view->bary_v);
        free(view->footprint);
        free(view->radiance);
        free(view->image);
        for (int w = 0; w < SRV_VIEW_COUNT; w++)
            free(view->views[w]);
        request_list_free(&view->requests);
    }
    if (loop->thread_requests && loop->pool)
        for (uint32_t t = 0; t < srv_pool_threads(loop->pool); t++)
            request_list_free(&loop->thread_requests[t]);
    free(loop->thread_requests);
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
        free(loop->jobs[fx].items);
        free(loop->viewer_bits[fx]);
    }
    free(loop->fx_jobs);
    free(loop->queue_empty);
    free(loop->queue_refine);
    free(loop->queue_lookups);
    free(loop->chunk_rays);
    osc_destroy(loop->osc);
    srv_pool_free(loop->pool);
    free(loop);
}

bool srv_loop_frame(srv_loop *loop, const srv_camera *cameras, srv_frame_stats *stats, char *err, size_t err_cap)
{
    const srv_loop_desc *d = &loop->desc;
    for (uint32_t v = 0; v < d->viewer_count; v++)
        if (!srv_camera_setup(&cameras[v], d->width, d->height, &loop->viewers[v].frame)) {
            snprintf(err, err_cap, "viewer %u: invalid camera (position equals target, non-finite, or field of "
                                   "view outside (0, 180))",
                     v);
            return false;
        }
    memset(stats, 0, sizeof *stats);
    stats->frame = loop->frame_number;
    loop->stats = stats;
    double frame_start = srv__now_ms();

    double t = srv__now_ms();
    for (uint32_t v = 0; v < d->viewer_count; v++)
        srv__visibility(loop, v);
    stats->time_ms[SRV_STAGE_VISIBILITY] = srv__now_ms() - t;
    for (uint32_t v = 0; v < d->viewer_count; v++) {
        const srv_viewer *view = &loop->viewers[v];
        size_t pixels = (size_t)d->width * d->height;
        stats->visibility_rays += pixels;
        for (size_t p = 0; p < pixels; p++)
            stats->pixels_visible += view->tri[p] != SRV_MISS;
    }

    if (loop->osc) {
        t = srv__now_ms();
        osc_begin_frame(loop->osc, loop->frame_number);
        for (int fx = 0; fx < SCENE_FX_COUNT; fx++)
            if (loop->viewer_bits[fx])
                memset(loop->viewer_bits[fx], 0, sizeof(uint64_t) * osc_pool_capacity(loop->osc, (uint32_t)fx));
        for (uint32_t v = 0; v < d->viewer_count; v++) {
            stats->viewer_requested[v] = srv__requests(loop, v);
            stats->requested_texels += stats->viewer_requested[v];
        }
        for (uint32_t fx = FX_SHADOW; fx <= FX_AO; fx++) {
            if (!loop->cached_effect[fx])
                continue;
            uint32_t n = 0;
            const uint32_t *blocks = osc_frame_blocks(loop->osc, fx, &n);
            for (uint32_t i = 0; i < n; i++)
                stats->unique_texels += (uint64_t)__builtin_popcountll(osc_block_requested(loop->osc, fx, blocks[i]));
        }
        stats->time_ms[SRV_STAGE_REQUESTS] = srv__now_ms() - t;
        srv__update(loop);
    }

    t = srv__now_ms();
    for (uint32_t v = 0; v < d->viewer_count; v++)
        srv__compose(loop, v);
    stats->time_ms[SRV_STAGE_COMPOSE] = srv__now_ms() - t;

    if (loop->osc) {
        t = srv__now_ms();
        osc_housekeeping(loop->osc);
        osc_stats os;
        osc_stats_get(loop->osc, &os);
        for (uint32_t fx = 0; fx <= FX_AO; fx++)
            stats->blocks_resident[fx] = os.effects[fx].blocks_resident;
        stats->evictions = os.evictions;
        stats->table_count = os.table_count;
        stats->table_capacity = os.table_capacity;
        stats->exhausted = os.exhausted;
        stats->time_ms[SRV_STAGE_HOUSEKEEPING] = srv__now_ms() - t;
    }
    stats->frame_ms = srv__now_ms() - frame_start;
    loop->stats = NULL;
    loop->frame_number++;
    return true;
}

const uint8_t *srv_loop_image(const srv_loop *loop, uint32_t viewer)
{
    return viewer < loop->desc.viewer_count ? loop->viewers[viewer].image : NULL;
}

const float *srv_loop_radiance(const srv_loop *loop, uint32_t viewer)
{
    return viewer < loop->desc.viewer_count ? loop->viewers[viewer].radiance : NULL;
}

const float *srv_loop_view(const srv_loop *loop, uint32_t viewer, int which)
{
    if (viewer >= loop->desc.viewer_count || which < 0 || which >= SRV_VIEW_COUNT)
        return NULL;
    return loop->viewers[viewer].views[which];
}

int32_t srv_loop_bias(const srv_loop *loop, scene_effect fx)
{
    return (unsigned)fx < SCENE_FX_COUNT ? loop->bias[fx] : 0;
}

void srv_loop_memory(const srv_loop *loop, srv_memory *out)
{
    memset(out, 0, sizeof *out);
    const srv_loop_desc *d = &loop->desc;
    uint64_t cache_total = 0; /* exact: every byte of the cache went through its allocator */
    if (loop->osc) {
        osc_memory_report m;
        osc_memory(loop->osc, &m);
        cache_total = m.total_bytes;
        out->table = m.table_key_bytes + m.table_value_bytes + m.cache_struct_bytes;
        for (int fx = 0; fx < SCENE_FX_COUNT && fx < (int)OSC_MAX_EFFECTS; fx++) {
            out->pools_reserved[fx] = m.effects[fx].payload_reserved_bytes;
            out->pools_in_use[fx] = m.effects[fx].payload_in_use_bytes;
            out->block_meta[fx] = m.effects[fx].block_meta_bytes + m.effects[fx].list_bytes;
            if (loop->viewer_bits[fx]) {
                uint64_t bits = sizeof(uint64_t) * osc_pool_capacity(loop->osc, (uint32_t)fx);
                out->block_meta[fx] += bits;
                cache_total += bits;
            }
        }
    }
    size_t pixels = (size_t)d->width * d->height;
    size_t per_viewer = pixels * (sizeof(uint32_t) + 3 * sizeof(float) + 3 * sizeof(float) + 3);
    if (d->keep_views)
        per_viewer += pixels * SRV_VIEW_COUNT * sizeof(float);
    out->viewers = (uint64_t)per_viewer * d->viewer_count;
    for (uint32_t v = 0; v < d->viewer_count; v++)
        out->viewers += loop->viewers[v].requests.capacity * (2 * sizeof(uint64_t) + sizeof(uint32_t));
    if (loop->thread_requests)
        for (uint32_t t = 0; t < srv_pool_threads(loop->pool); t++)
            out->viewers += loop->thread_requests[t].capacity * (2 * sizeof(uint64_t) + sizeof(uint32_t));
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++)
        out->queues += loop->jobs[fx].capacity * sizeof(srv_job);
    out->queues += loop->fx_jobs_capacity * sizeof(fx_block_job);
    out->queues += loop->queue_capacity * (2 * sizeof(uint64_t) + sizeof(uint32_t)) +
                   loop->chunk_capacity * sizeof(uint64_t);
    out->total = cache_total + out->viewers + out->queues;
}
