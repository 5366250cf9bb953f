/* The frame loop: DESIGN.md's stages 2-7 and 9 for a set of viewers, as one library function so that the
 * simulation (`fxcache sim`) and the networked server drive exactly the same code.
 *
 *   srv_loop_create   the caches, pools and per-viewer buffers, sized once
 *   srv_loop_frame    one frame for every viewer's camera: visibility, requests (deduplicated across
 *                     viewers in one on-surface cache), update queues within the ray budget, triangle
 *                     lookup, effect updates, compose, housekeeping; fills the frame's statistics
 *   srv_loop_image    a viewer's composed frame (sRGB 8-bit RGB)
 *
 * With no_cache set the same shading is evaluated per pixel with the sample counts the cache converges to
 * (the baseline a renderer without the cache pays). */
#ifndef FXC_SERVER_FRAME_H
#define FXC_SERVER_FRAME_H

#include "camera.h"
#include "scene.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

enum { SRV_MAX_VIEWERS = 64 };

/* Stages timed per frame. */
typedef enum srv_stage {
    SRV_STAGE_VISIBILITY = 0,
    SRV_STAGE_REQUESTS,
    SRV_STAGE_QUEUES,
    SRV_STAGE_LOOKUP,
    SRV_STAGE_EFFECTS,
    SRV_STAGE_COMPOSE,
    SRV_STAGE_HOUSEKEEPING,
    SRV_STAGE_COUNT
} srv_stage;

const char *srv_stage_name(srv_stage stage);

/* Configuration; zero fields take the defaults beside them. */
typedef struct srv_loop_desc {
    const scene *s;                       /* required, outlives the loop */
    scene_rt *rt;                         /* required, outlives the loop */
    uint32_t viewer_count;                /* 1..SRV_MAX_VIEWERS */
    uint32_t width, height;               /* per viewer (default 640x360) */
    bool effect_on[SCENE_FX_COUNT];       /* which effects run (probes are not implemented yet) */
    int32_t bias[SCENE_FX_COUNT];         /* level bias per effect, added to the effect's default */
    bool bias_set[SCENE_FX_COUNT];        /* bias given explicitly (replaces the default) */
    uint64_t pool_bytes;                  /* payload pool budget for all effects (default 64 MiB) */
    uint64_t ray_budget;                  /* effect rays per frame, 0 = unlimited */
    uint32_t ao_samples_per_frame;        /* AO samples added per texel per update (default 16) */
    bool no_cache;                        /* the per-pixel baseline */
    uint32_t seed;
    uint32_t threads;                     /* 0 = all cores */
    bool keep_views;                      /* keep per-viewer AO, shadow and sharing images */
} srv_loop_desc;

/* One frame's figures (cumulative ones are summed by the caller). */
typedef struct srv_frame_stats {
    uint32_t frame;
    uint64_t requested_texels;                    /* sum over viewers, shading effects (shadow, AO) */
    uint64_t viewer_requested[SRV_MAX_VIEWERS];   /* per viewer */
    uint64_t unique_texels;                       /* after deduplication across viewers */
    uint64_t rays[SCENE_FX_COUNT];                /* effect rays traced this frame */
    uint64_t visibility_rays;
    uint64_t texels_updated[SCENE_FX_COUNT];      /* texels written (traced or resampled) */
    uint64_t texels_resampled[SCENE_FX_COUNT];    /* of which filled from a finer level */
    uint64_t texels_deferred[SCENE_FX_COUNT];     /* requested but left for later by the ray budget */
    uint64_t blocks_resident[SCENE_FX_COUNT];
    uint64_t pixels_visible;
    uint64_t pixels_missing;                      /* visible pixels composed without cached data */
    uint64_t evictions, exhausted;                /* cumulative cache counters */
    uint32_t table_count, table_capacity;         /* keys in the on-surface table, and its slots */
    double time_ms[SRV_STAGE_COUNT];
    double frame_ms;
} srv_frame_stats;

/* Bytes actually allocated, by structure and effect. */
typedef struct srv_memory {
    uint64_t table;                          /* hash table keys and values */
    uint64_t pools_reserved[SCENE_FX_COUNT]; /* payload pools, whole (allocated) */
    uint64_t pools_in_use[SCENE_FX_COUNT];   /* part of them held by resident blocks */
    uint64_t block_meta[SCENE_FX_COUNT];     /* masks, frames, keys, lists */
    uint64_t viewers;                        /* visibility buffers, images, request buffers */
    uint64_t queues;                         /* update queues and job lists */
    uint64_t total;                          /* everything above (reserved pools counted whole) */
} srv_memory;

typedef struct srv_loop srv_loop;

/* Creates a loop; NULL with a one-line message in err on failure. */
srv_loop *srv_loop_create(const srv_loop_desc *desc, char *err, size_t err_cap);
void srv_loop_free(srv_loop *loop);

/* Runs one frame for cameras[0..viewer_count). Returns false (with a message) only for invalid cameras. */
bool srv_loop_frame(srv_loop *loop, const srv_camera *cameras, srv_frame_stats *stats, char *err,
                    size_t err_cap);

/* The composed frame of a viewer: width*height*3 bytes, sRGB, top row first. */
const uint8_t *srv_loop_image(const srv_loop *loop, uint32_t viewer);

/* Linear per-viewer images kept with keep_views: AO (1 channel), lit fraction of light 0 (1 channel), and
 * how many viewers requested the AO block each pixel reads (1 channel). NULL when not kept. */
const float *srv_loop_view(const srv_loop *loop, uint32_t viewer, int which);
enum { SRV_VIEW_AO = 0, SRV_VIEW_SHADOW, SRV_VIEW_SHARING, SRV_VIEW_COUNT };

/* Current memory, and the effective level bias per effect. */
void srv_loop_memory(const srv_loop *loop, srv_memory *out);
int32_t srv_loop_bias(const srv_loop *loop, scene_effect fx);

/* The linear radiance of a viewer's last frame (width*height*3), before tone mapping: for error
 * measurements against a reference. */
const float *srv_loop_radiance(const srv_loop *loop, uint32_t viewer);

#endif
