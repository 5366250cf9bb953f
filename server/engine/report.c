/* The run report (report.h): totals over a run's frames and their JSON form. */
#include "report.h"

#include <stdlib.h>
#include <string.h>

struct srv_report {
    const srv_loop *loop;
    srv_report_totals totals;
    srv_memory last;
    uint32_t seen_generation[SRV_MAX_VIEWERS]; /* the id last seen per slot, to count distinct viewers */
};

srv_report *srv_report_create(const srv_loop *loop)
{
    srv_report *r = calloc(1, sizeof *r);
    if (r)
        r->loop = loop;
    return r;
}

void srv_report_free(srv_report *report)
{
    free(report);
}

void srv_report_add(srv_report *r, const srv_frame_stats *st, const srv_memory *mem)
{
    srv_report_totals *t = &r->totals;
    t->frames++;
    uint32_t whole = 0;
    for (uint32_t i = 0; i < st->viewer_count; i++) {
        bool sparse = st->viewers[i].sparse;
        whole += !sparse;
        t->sample_viewer_frames += sparse;
        uint32_t id = st->viewers[i].id.id, slot = id & 0xFFu;
        if (slot < SRV_MAX_VIEWERS && r->seen_generation[slot] != id) {
            r->seen_generation[slot] = id;
            if (sparse)
                t->sample_viewers_seen++;
            else
                t->viewers_seen++;
        }
    }
    t->viewer_frames += whole;
    if (whole > t->max_viewers)
        t->max_viewers = whole;
    t->requested += st->requested_texels;
    t->unique += st->unique_texels;
    t->visibility_rays += st->visibility_rays;
    t->pixels_visible += st->pixels_visible;
    t->pixels_missing += st->pixels_missing;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++) {
        t->rays[e] += st->rays[e];
        t->texels_updated[e] += st->texels_updated[e];
        t->resampled[e] += st->texels_resampled[e];
        t->deferred[e] += st->texels_deferred[e];
    }
    for (uint32_t d = 0; d < SRV_DROP_COUNT; d++)
        t->drops[d] += st->drops[d];
    t->exhausted = st->exhausted;
    t->world_requested += st->world.requested_cells;
    t->world_unique += st->world.unique_cells;
    t->world_refusals += st->world.refusals;
    t->world_local_lookups += st->world.local_lookups;
    t->world_local_hits += st->world.local_hits;
    t->world_last = st->world;
    for (uint32_t s = 0; s < SRV_STAGE_COUNT; s++)
        t->time_ms[s] += st->time_ms[s];
    t->frame_ms += st->frame_ms;
    if (mem) {
        if (mem->total > t->peak.total)
            t->peak = *mem;
        t->final = *mem;
        r->last = *mem;
    }
}

static int report_frame_done(void *user, const srv_frame_stats *stats)
{
    srv_report *r = user;
    srv_memory mem;
    srv_loop_memory(r->loop, &mem);
    srv_report_add(r, stats, &mem);
    return 0;
}

srv_sink srv_report_sink(srv_report *report)
{
    return (srv_sink){.frame_done = report_frame_done, .user = report};
}

const srv_report_totals *srv_report_get_totals(const srv_report *report)
{
    return &report->totals;
}

const srv_memory *srv_report_last_memory(const srv_report *report)
{
    return &report->last;
}

/* ---- JSON ------------------------------------------------------------------------------------------------ */

/* An object of one figure per cached effect (those that run through a cache, lookup included when asked). */
static json_t *per_effect(const srv_loop *loop, const uint64_t *values, bool with_lookup)
{
    json_t *o = json_object();
    for (uint32_t e = 0; e < srv_loop_effect_count(loop); e++)
        if (srv_loop_effect_on(loop, e) && (with_lookup || srv_loop_effect(loop, e)->shade))
            json_object_set_new(o, srv_loop_effect(loop, e)->name, json_integer((json_int_t)values[e]));
    return o;
}

static json_t *rays_json(const srv_loop *loop, const uint64_t *rays, uint64_t visibility)
{
    json_t *o = json_object();
    json_object_set_new(o, "visibility", json_integer((json_int_t)visibility));
    uint64_t total = 0;
    for (uint32_t e = 0; e < srv_loop_effect_count(loop); e++) {
        if (srv_loop_effect_on(loop, e) && srv_loop_effect(loop, e)->shade)
            json_object_set_new(o, srv_loop_effect(loop, e)->name, json_integer((json_int_t)rays[e]));
        total += rays[e];
    }
    json_object_set_new(o, "effects_total", json_integer((json_int_t)total));
    return o;
}

static json_t *stage_json(const double time_ms[SRV_STAGE_COUNT], double frame_ms, double divide)
{
    json_t *o = json_object();
    for (int s = 0; s < SRV_STAGE_COUNT; s++)
        json_object_set_new(o, srv_stage_name((srv_stage)s),
                            json_real(divide > 0 ? time_ms[s] / divide : 0.0));
    json_object_set_new(o, "frame", json_real(divide > 0 ? frame_ms / divide : 0.0));
    return o;
}

static json_t *drops_json(const uint64_t drops[SRV_DROP_COUNT])
{
    json_t *o = json_object();
    for (int d = 0; d < SRV_DROP_COUNT; d++)
        json_object_set_new(o, srv_drop_name((srv_drop)d), json_integer((json_int_t)drops[d]));
    return o;
}

json_t *srv_report_memory_json(const srv_report *report, const srv_memory *m)
{
    const srv_loop *loop = report->loop;
    json_t *effects = json_object();
    for (uint32_t e = 0; e < srv_loop_effect_count(loop); e++) {
        if (!m->pools_reserved[e] && !m->block_meta[e])
            continue;
        json_object_set_new(effects, srv_loop_effect(loop, e)->name,
                            json_pack("{s:I,s:I,s:I}", "pool_reserved", (json_int_t)m->pools_reserved[e],
                                      "pool_in_use", (json_int_t)m->pools_in_use[e], "block_meta",
                                      (json_int_t)m->block_meta[e]));
    }
    return json_pack("{s:I,s:I,s:I,s:I,s:o,s:I}", "table", (json_int_t)m->table, "viewers",
                     (json_int_t)m->viewers, "queues", (json_int_t)m->queues, "world_local_tables",
                     (json_int_t)m->world_local, "effects", effects, "total", (json_int_t)m->total);
}

/* The world-space cache's figures: cells (probes) requested and unique, their sharing ratio (the texels'
 * definition), the table, the bricks, the bytes, refusals and the local lookup tables' hit rate. */
static json_t *world_json(uint64_t requested, uint64_t unique, const srv_world_stats *w, uint64_t refusals,
                          uint64_t lookups, uint64_t hits)
{
    json_t *o = json_object();
    json_object_set_new(o, "requested_cells", json_integer((json_int_t)requested));
    json_object_set_new(o, "unique_cells", json_integer((json_int_t)unique));
    json_object_set_new(o, "sharing_ratio",
                        unique ? json_real((double)requested / (double)unique) : json_null());
    json_object_set_new(o, "entries", json_integer((json_int_t)w->entries));
    json_object_set_new(o, "bricks", json_integer((json_int_t)w->bricks_resident));
    json_object_set_new(o, "bytes", json_integer((json_int_t)w->bytes));
    json_object_set_new(o, "table_load",
                        json_real(w->table_capacity ? (double)w->entries / (double)w->table_capacity : 0.0));
    json_object_set_new(o, "refusals", json_integer((json_int_t)refusals));
    json_object_set_new(o, "local_table_lookups", json_integer((json_int_t)lookups));
    json_object_set_new(o, "local_table_hit_rate",
                        lookups ? json_real((double)hits / (double)lookups) : json_null());
    return o;
}

json_t *srv_report_frame_json(const srv_report *report, const srv_frame_stats *st, const srv_memory *mem)
{
    const srv_loop *loop = report->loop;
    json_t *viewers = json_array();
    for (uint32_t i = 0; i < st->viewer_count; i++) {
        const srv_viewer_stats *v = &st->viewers[i];
        json_array_append_new(
            viewers, json_pack("{s:I,s:I,s:I,s:I,s:I,s:I,s:I,s:b}", "id", (json_int_t)v->id.id, "slot",
                               (json_int_t)(v->id.id & 0xFFu), "width", (json_int_t)v->width, "height",
                               (json_int_t)v->height, "requested_texels", (json_int_t)v->requested_texels,
                               "requested_cells", (json_int_t)v->requested_cells, "pixels_missing",
                               (json_int_t)v->pixels_missing, "sparse", (int)v->sparse));
    }
    json_t *o = json_object();
    json_object_set_new(o, "frame", json_integer(st->frame));
    json_object_set_new(o, "viewers", viewers);
    json_object_set_new(o, "requested_texels", json_integer((json_int_t)st->requested_texels));
    json_object_set_new(o, "unique_texels", json_integer((json_int_t)st->unique_texels));
    json_object_set_new(o, "sharing_ratio",
                        st->unique_texels
                            ? json_real((double)st->requested_texels / (double)st->unique_texels)
                            : json_null());
    json_object_set_new(o, "rays", rays_json(loop, st->rays, st->visibility_rays));
    json_object_set_new(o, "texels_updated", per_effect(loop, st->texels_updated, false));
    json_object_set_new(o, "texels_resampled", per_effect(loop, st->texels_resampled, false));
    json_object_set_new(o, "texels_deferred", per_effect(loop, st->texels_deferred, false));
    json_object_set_new(o, "blocks_resident", per_effect(loop, st->blocks_resident, true));
    json_object_set_new(o, "pixels_visible", json_integer((json_int_t)st->pixels_visible));
    json_object_set_new(o, "pixels_missing", json_integer((json_int_t)st->pixels_missing));
    json_object_set_new(o, "drops", drops_json(st->drops));
    json_object_set_new(o, "table_load",
                        json_real(st->table_capacity ? (double)st->table_count / st->table_capacity : 0.0));
    json_object_set_new(o, "evictions", json_integer((json_int_t)st->evictions));
    json_object_set_new(o, "pool_exhausted", json_integer((json_int_t)st->exhausted));
    if (st->world.table_capacity)
        json_object_set_new(o, "world_space",
                            world_json(st->world.requested_cells, st->world.unique_cells, &st->world,
                                       st->world.refusals, st->world.local_lookups, st->world.local_hits));
    if (mem)
        json_object_set_new(o, "memory_bytes", srv_report_memory_json(report, mem));
    json_object_set_new(o, "time_ms", stage_json(st->time_ms, st->frame_ms, 1.0));
    return o;
}

json_t *srv_report_json(const srv_report *report)
{
    const srv_loop *loop = report->loop;
    const srv_report_totals *t = &report->totals;
    json_t *o = json_object();
    json_object_set_new(o, "frames", json_integer(t->frames));
    json_object_set_new(o, "viewer_frames", json_integer((json_int_t)t->viewer_frames));
    json_object_set_new(o, "viewers_seen", json_integer(t->viewers_seen));
    json_object_set_new(o, "max_viewers", json_integer(t->max_viewers));
    json_object_set_new(o, "sample_viewers_seen", json_integer(t->sample_viewers_seen));
    json_object_set_new(o, "sample_viewer_frames", json_integer((json_int_t)t->sample_viewer_frames));
    json_object_set_new(o, "requested_texels", json_integer((json_int_t)t->requested));
    json_object_set_new(o, "unique_texels", json_integer((json_int_t)t->unique));
    /* No cache, or nothing visible: nothing is requested, so there is no ratio (null, not 0). */
    json_object_set_new(o, "sharing_ratio",
                        t->unique ? json_real((double)t->requested / (double)t->unique) : json_null());
    json_object_set_new(o, "rays", rays_json(loop, t->rays, t->visibility_rays));
    json_object_set_new(o, "texels_updated", per_effect(loop, t->texels_updated, false));
    json_object_set_new(o, "texels_resampled", per_effect(loop, t->resampled, false));
    json_object_set_new(o, "texels_deferred", per_effect(loop, t->deferred, false));
    json_object_set_new(o, "pixels_visible", json_integer((json_int_t)t->pixels_visible));
    json_object_set_new(o, "pixels_missing", json_integer((json_int_t)t->pixels_missing));
    json_object_set_new(o, "pool_exhausted", json_integer((json_int_t)t->exhausted));
    json_object_set_new(o, "drops", drops_json(t->drops));
    if (t->world_last.table_capacity)
        json_object_set_new(o, "world_space",
                            world_json(t->world_requested, t->world_unique, &t->world_last, t->world_refusals,
                                       t->world_local_lookups, t->world_local_hits));
    json_object_set_new(o, "memory_bytes",
                        json_pack("{s:o,s:o}", "peak", srv_report_memory_json(report, &t->peak), "final",
                                  srv_report_memory_json(report, &t->final)));
    json_object_set_new(o, "time_ms", stage_json(t->time_ms, t->frame_ms, 1.0)); /* sums over the run */
    json_object_set_new(o, "time_ms_per_frame", stage_json(t->time_ms, t->frame_ms, (double)t->frames));
    return o;
}
