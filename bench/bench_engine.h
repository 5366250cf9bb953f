/* What the engine benchmarks share: a loop with the effects the scene needs and some viewers, and one frame of
 * generated cameras, timed. Header-only like bench_util.h; benchmarks exit with a message on any failure. */
#ifndef FXC_BENCH_ENGINE_H
#define FXC_BENCH_ENGINE_H

#include "bench_util.h"
#include "camgen.h"
#include "engine.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A loop with description d running what the scene needs except the effect named skip (NULL: none), with
 * `viewers` viewers of w x h whose ids go to ids. */
static inline srv_loop *bench_make_loop_desc(const char *who, srv_loop_desc d, const char *skip,
                                             uint32_t viewers, uint32_t w, uint32_t h, srv_viewer_id *ids)
{
    uint32_t count = 0;
    const fx_effect *const *registry = fx_registry(&count);
    bool needed[SRV_MAX_EFFECTS];
    char why[SRV_MAX_EFFECTS][200];
    fx_needs(registry, count, d.s, needed, why);
    for (uint32_t e = 0; e < count; e++)
        d.effect_on[e] = needed[e] && registry[e]->shade && !(skip && !strcmp(skip, registry[e]->name));
    srv_loop *loop = NULL;
    char err[256];
    if (srv_loop_create(&d, &loop, err, sizeof err) != FXC_OK) {
        fprintf(stderr, "%s: %s\n", who, err);
        exit(1);
    }
    for (uint32_t v = 0; v < viewers; v++)
        if (srv_viewer_add(loop, &(srv_viewer_desc){.width = w, .height = h}, &ids[v]) != FXC_OK) {
            fprintf(stderr, "%s: cannot add a viewer\n", who);
            exit(1);
        }
    return loop;
}

/* The same with the default description, without probes: the figures of bench_stages and bench_steady are
 * the on-surface effects' (docs/BENCHMARKS.md); bench_probes measures what probes add. */
static inline srv_loop *bench_make_loop(const char *who, scene *s, scene_rt *rt, bool no_cache,
                                        uint32_t threads, uint32_t viewers, uint32_t w, uint32_t h,
                                        srv_viewer_id *ids)
{
    srv_loop_desc d = {.s = s, .rt = rt, .threads = threads, .seed = 1, .no_cache = no_cache};
    return bench_make_loop_desc(who, d, "probes", viewers, w, h, ids);
}

/* Frame `frame` of generator gen for every viewer; returns its wall time in ms and fills *st. */
static inline double bench_run_frame(const char *who, srv_loop *loop, const scene *s, srv_camgen_kind gen,
                                     const srv_viewer_id *ids, uint32_t viewers, uint32_t frame,
                                     srv_frame_stats *st)
{
    for (uint32_t v = 0; v < viewers; v++) {
        srv_camera cam = srv_camgen_camera(gen, s, v, viewers, frame, 1);
        srv_viewer_set_camera(loop, ids[v], &cam);
    }
    double t = bench_now_ms();
    if (srv_loop_frame(loop, st) != FXC_OK) {
        fprintf(stderr, "%s: frame %u failed\n", who, frame);
        exit(1);
    }
    return bench_now_ms() - t;
}

/* The effect rays of a frame, summed over effects. */
static inline uint64_t bench_effect_rays(const srv_frame_stats *st)
{
    uint64_t rays = 0;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++)
        rays += st->rays[e];
    return rays;
}

#endif
