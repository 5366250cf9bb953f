/* The run report: a run's totals, fed by the loop's per-frame statistics, so that every front end (sim,
 * the server, the error report) reports the same figures the same way.
 *
 *   srv_report_create(loop)     a report for one loop's run (the loop names the effects)
 *   srv_report_sink(report)     a sink that adds every finished frame (with the loop's memory then)
 *   srv_report_add(...)         or add frames by hand
 *   srv_report_get_totals()       the sums, peaks and counts
 *   srv_report_frame_json()     one frame's statistics as a JSON object (the --stats lines)
 *   srv_report_json()           the totals as a JSON object (the body of a summary)
 *
 * Definitions (DESIGN.md, "Definitions"): requested and unique texels are summed over frames; the sharing
 * ratio is requested / unique, null when nothing was requested; memory is what the allocators counted,
 * peak (by total) and final. */
#ifndef FXC_REPORT_H
#define FXC_REPORT_H

#include "engine.h"

#include <jansson.h>

typedef struct srv_report_totals {
    uint32_t frames;
    uint64_t viewer_frames; /* sum over frames of the viewers rendered */
    uint32_t viewers_seen;  /* distinct viewer ids */
    uint32_t max_viewers;   /* most viewers in one frame */
    /* The three above count whole-frame viewers; sparse viewers (the server's answers to a client's sample
     * requests, one per client that asks) are counted apart. Both kinds' requests are in the sharing. */
    uint64_t sample_viewer_frames;
    uint32_t sample_viewers_seen;
    uint64_t requested, unique, visibility_rays, pixels_visible, pixels_missing;
    uint64_t rays[SRV_MAX_EFFECTS], texels_updated[SRV_MAX_EFFECTS], resampled[SRV_MAX_EFFECTS],
        deferred[SRV_MAX_EFFECTS];
    uint64_t drops[SRV_DROP_COUNT];
    uint64_t exhausted; /* cumulative failed block requests (pool exhausted), from the caches */
    /* The world-space cache (zero when it is left out): cells requested and unique, summed over frames;
     * refusals and local-table reads summed; the last frame's table and bricks. */
    uint64_t world_requested, world_unique, world_refusals, world_local_lookups, world_local_hits;
    srv_world_stats world_last;
    double time_ms[SRV_STAGE_COUNT], frame_ms;
    srv_memory peak, final;
} srv_report_totals;

typedef struct srv_report srv_report;

/* A report for a run of loop (the loop must outlive it). NULL on no memory. */
srv_report *srv_report_create(const srv_loop *loop);
void srv_report_free(srv_report *report);

/* Adds one frame's statistics and the memory after it. */
void srv_report_add(srv_report *report, const srv_frame_stats *stats, const srv_memory *memory);

/* A sink whose frame_done adds the frame with the loop's memory at that moment. */
srv_sink srv_report_sink(srv_report *report);

const srv_report_totals *srv_report_get_totals(const srv_report *report);

/* The memory of the last frame added (zero before any). */
const srv_memory *srv_report_last_memory(const srv_report *report);

/* JSON: one frame (with its memory), the totals; new references owned by the caller. */
json_t *srv_report_frame_json(const srv_report *report, const srv_frame_stats *stats,
                              const srv_memory *memory);
json_t *srv_report_json(const srv_report *report);

/* The memory as JSON (per structure, per effect). */
json_t *srv_report_memory_json(const srv_report *report, const srv_memory *memory);

#endif
