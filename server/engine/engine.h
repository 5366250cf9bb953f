/* The engine: DESIGN.md's frame loop as a library that `fxcache sim`, the networked server and the error
 * report drive alike.
 *
 *   srv_loop_create        the effects (a registry list), the caches their kinds need, the thread pool
 *   srv_viewer_add/remove  viewers join and leave at any frame, each with its own resolution and field of
 *                          view; ids carry a generation, so a removed or stale id is refused
 *   srv_viewer_set_camera  the camera a viewer's next frame is rendered for (stage 1)
 *   srv_viewer_set_pixels  a sparse viewer's next frame: a camera, an image size and a list of its pixels;
 *                          only those pixels are traced, request texels and are composed (the render
 *                          cache's sample requests, issue 11)
 *   srv_loop_add_sink      where finished frames go (files, a connection, an error accumulator)
 *   srv_loop_frame         one frame for the viewers present, stages in a fixed order, each timed:
 *                          visibility, requests, queues, lookup, effects, compose, (sinks), housekeeping;
 *                          returns the frame's statistics
 *
 * With no_cache set the same shading is evaluated per pixel with the sample counts the cache converges to
 * (the baseline a renderer without the cache pays), or a power-of-two multiple of them (no_cache_samples). Results are fxc_result codes (common/fxc_result.h). */
#ifndef FXC_ENGINE_H
#define FXC_ENGINE_H

#include "camera.h"
#include "effects.h"
#include "fxc_result.h"
#include "scene.h"

#include <stdbool.h>
#include <stddef.h>
#include <signal.h>
#include <stdint.h>

enum {
    SRV_MAX_VIEWERS = 64, /* viewer slots */
    SRV_MAX_EFFECTS = FX_MAX_EFFECTS,
    SRV_MAX_SIDE = 8192,          /* largest image side */
    SRV_MAX_PIXEL_LIST = 1 << 20, /* most pixels a sparse viewer may list (max_pixels) */
};

/* Stages timed per frame, in the order they run. */
typedef enum srv_stage {
    SRV_STAGE_VISIBILITY = 0,
    SRV_STAGE_REQUESTS,
    SRV_STAGE_QUEUES,
    SRV_STAGE_LOOKUP,
    SRV_STAGE_EFFECTS,
    SRV_STAGE_COMPOSE,
    SRV_STAGE_SINKS,
    SRV_STAGE_HOUSEKEEPING,
    SRV_STAGE_COUNT
} srv_stage;

const char *srv_stage_name(srv_stage stage);

/* Things a frame had to leave out, each counted (never silent). */
typedef enum srv_drop {
    SRV_DROP_NOMEM_REQUESTS = 0, /* a viewer's requests lost: no memory for its request lists */
    SRV_DROP_NOMEM_UPDATES,      /* an effect's updates lost: no memory for its job lists */
    SRV_DROP_POOL_EXHAUSTED,     /* blocks not mapped: the effect's pool was full of this frame's blocks */
    SRV_DROP_TABLE_FULL,         /* blocks not mapped: the cache's table at its maximum load */
    SRV_DROP_NO_DEPENDENCY, /* texels not updated: the block they depend on (triangle lookup) is absent */
    SRV_DROP_COUNT
} srv_drop;

const char *srv_drop_name(srv_drop drop);

/* An allocator for everything the engine allocates outside the caches (viewer buffers, request and job
 * lists), so memory is counted exactly and failures can be injected. NULL members: libc. realloc gets the
 * old size (0 for a new block), free the size. It is called from pool threads too: it must be thread-safe. */
typedef struct srv_allocator {
    void *(*realloc)(void *pointer, size_t old_size, size_t new_size, void *user);
    void (*free)(void *pointer, size_t size, void *user);
    void *user;
} srv_allocator;

/* Configuration; zero fields take the defaults beside them. */
typedef struct srv_loop_desc {
    const scene *s;                  /* required, outlives the loop */
    scene_rt *rt;                    /* required, outlives the loop */
    const fx_effect *const *effects; /* the effect list (default: fx_registry()); index = effect id */
    uint32_t effect_count;           /* entries of effects (<= SRV_MAX_EFFECTS) */
    bool effect_on[SRV_MAX_EFFECTS]; /* which effects run; their dependencies run with them */
    int32_t bias[SRV_MAX_EFFECTS];   /* level bias per effect (used where bias_set) */
    bool bias_set[SRV_MAX_EFFECTS];  /* bias given explicitly (replaces the effect's default) */
    uint64_t pool_bytes;             /* payload pool budget for all effects (default 64 MiB) */
    uint64_t ray_budget;             /* effect rays per frame, 0 = unlimited */
    uint32_t samples_per_update;     /* progressive effects: samples added per texel per update
                                              (default 16, at most the effect's max_samples) */
    bool no_cache;                   /* the per-pixel baseline */
    /* Sample counts (effects.h, fx_context). In a cached run: what a texel converges at; in the no-cache
     * baseline: what each pixel traces, times no_cache_samples. */
    uint32_t ao_samples;    /* AO samples a texel converges at, 1..FX_AO_SAMPLES_LIMIT
                                              (default 64) */
    uint32_t shadow_rays;   /* shadow rays per texel and light: 1, 2, 4, 8 or 16 (default 16) */
    float no_cache_samples; /* no_cache: the baseline's AO rays, shadow rays and probe rays per
                                              pixel as a multiple of ao_samples, shadow_rays and probe_rays, a
                                              power of two in [1/64, 16] (default 1; AO at least 1 ray, shadow
                                              rays 1..256, probe rays 1..4096) */
    uint32_t seed;
    uint32_t threads; /* 0 = all cores */
    bool keep_views;  /* keep per-viewer AO, shadow and sharing images */
    /* World-space effects (probes). */
    float probe_cell;        /* finest cell, metres: the grid's one scene-scale parameter
                                              (default: the power of two nearest a 64th of the
                                              scene's bounding-box diagonal) */
    uint32_t probe_rays;     /* rays per probe update (default 144, DDGI's) */
    float probe_hysteresis;  /* old irradiance's weight in an update, (0, 0.999] (default 0.97,
                                              RTXGI's; a tiny weight such as 1e-9 spells "none", as the
                                              command line's 0 does) */
    bool probe_plain_blend;  /* true: plain hysteresis, probe_hysteresis at every update; false
                                              (the default): the change-aware blend, which keeps less
                                              while an update's changes agree in sign (fx_probes.c) */
    uint32_t probe_budget;   /* cells (probes) updated per frame at most, new ones first, then
                                              the longest unrefreshed (default 1024; shares the ray budget) */
    uint32_t indirect_block; /* low-frequency effects (probes) in whole frames: evaluated once
                                              per block of B x B pixels, then a depth- and normal-aware
                                              upsample; pixels no block sample matches are evaluated
                                              themselves. The largest B: 1 = every pixel (sparse viewers
                                              always), 2 or 4 (default 4); a viewer uses at most a quarter of
                                              the narrowest probe cell in its pixels (640 x 360 at 60
                                              degrees: 4; at 60 degrees, 2 from 148 to 295 pixels high, 1
                                              below) */
    bool no_local_table;     /* benchmarks: compose finds probes through the hash table only,
                                              not the viewers' local lookup tables */
    bool no_lanes;           /* tests: the per-pixel stages' coarse sample choice (requests)
                                              and blend (compose) through their scalar loops only, not the
                                              lanes of whole rows (the same results, byte for byte) */
    bool no_request_recent;  /* tests: every tile's requests appended to its thread's list, none
                                              or-ed into an entry of the same key from an earlier tile (the
                                              same requests after the batch merges them) */
    srv_allocator allocator; /* default: libc */
} srv_loop_desc;

/* A viewer: a handle with a generation counter (slot in the low 8 bits, generation above), 0 is never valid.
 */
typedef struct srv_viewer_id {
    uint32_t id;
} srv_viewer_id;

/* A viewer's shape; zero fields take the defaults beside them. */
typedef struct srv_viewer_desc {
    uint32_t width, height; /* pixels, 1..SRV_MAX_SIDE (default 640 x 360); a sparse viewer's come with each
                               pixel list instead (ignored here) */
    char name[32];          /* for statistics and file names (default "viewer_SLOT") */
    uint32_t max_pixels;    /* 0: a viewer of whole frames. 1..SRV_MAX_PIXEL_LIST: a sparse viewer, whose
                               frames render only the pixels of a list (srv_viewer_set_pixels), at most this
                               many; its buffers hold max_pixels entries (SRV_VIEWER_BYTES_PER_PIXEL each, plus
                               SRV_LIST_BYTES_PER_ENTRY), whatever the image size */
} srv_viewer_desc;

/* Bytes srv_viewer_add allocates per pixel: triangle, barycentric u and v, footprint, depth (4 each), the
 * side seen (1), linear radiance (12), sRGB image (3); and the three kept views with keep_views (4 each).
 * For memory checks before anything is created; tests/test_engine.c checks them against the counted
 * allocations. */
#define SRV_VIEWER_BYTES_PER_PIXEL 36u
#define SRV_VIEWS_BYTES_PER_PIXEL  12u
/* A sparse viewer's list and its sorting scratch, per entry (4 each). */
#define SRV_LIST_BYTES_PER_ENTRY 8u

/* One viewer's figures in a frame. */
typedef struct srv_viewer_stats {
    srv_viewer_id id;
    uint32_t width, height;
    uint64_t requested_texels; /* deduplicated within the viewer, shading effects */
    uint64_t requested_cells;  /* world-space cells (probes), deduplicated within the viewer */
    uint64_t pixels_visible;
    uint64_t pixels_missing;  /* visible pixels composed without cached data */
    uint64_t pixels_rendered; /* primary rays: width*height, or a sparse viewer's distinct listed pixels */
    bool sparse;              /* a sparse viewer (a client's sample requests), not a whole-frame viewer */
} srv_viewer_stats;

/* The world-space cache's figures in a frame (all zero when no world-space effect runs). Requested and
 * unique cells follow DESIGN.md's definitions for texels: per viewer the set of (effect, cell) it asks for,
 * summed over viewers, against the size of their union. */
typedef struct srv_world_stats {
    uint64_t requested_cells;
    uint64_t unique_cells;
    uint64_t entries;        /* keys in its tables (one per resident brick) */
    uint64_t table_capacity; /* slots of its tables */
    uint64_t bricks_resident;
    uint64_t bytes;         /* every byte it allocated, local lookup tables included */
    uint64_t refusals;      /* this frame: points outside the grid's range, refused (never wrapped) */
    uint64_t local_lookups; /* this frame: compose's reads through the viewers' local lookup tables */
    uint64_t local_hits;    /* of which answered without the hash table */
    uint64_t
        exhausted; /* cumulative: brick requests its pools could not take (in the frame's exhausted too) */
} srv_world_stats;

/* One frame's figures. */
typedef struct srv_frame_stats {
    uint32_t frame;
    uint32_t viewer_count;                     /* viewers rendered this frame */
    srv_viewer_stats viewers[SRV_MAX_VIEWERS]; /* [0, viewer_count), in slot order */
    uint64_t requested_texels;                 /* sum over viewers, shading effects */
    uint64_t unique_texels;                    /* after deduplication across viewers */
    uint64_t rays[SRV_MAX_EFFECTS];            /* effect rays traced this frame */
    uint64_t visibility_rays;
    uint64_t texels_updated[SRV_MAX_EFFECTS];   /* texels written (traced or resampled) */
    uint64_t texels_resampled[SRV_MAX_EFFECTS]; /* of which filled from a finer level */
    uint64_t texels_deferred[SRV_MAX_EFFECTS];  /* requested but left for later by the ray budget */
    uint64_t blocks_resident[SRV_MAX_EFFECTS];
    uint64_t pixels_visible;
    uint64_t pixels_missing;
    uint64_t drops[SRV_DROP_COUNT];       /* this frame */
    uint64_t evictions, exhausted;        /* cumulative cache counters */
    uint32_t table_count, table_capacity; /* keys in the on-surface table, and its slots */
    srv_world_stats world;
    double time_ms[SRV_STAGE_COUNT];
    double frame_ms;
} srv_frame_stats;

/* Bytes actually allocated, by structure and effect. */
typedef struct srv_memory {
    uint64_t table;                           /* hash table keys and values, the cache object */
    uint64_t pools_reserved[SRV_MAX_EFFECTS]; /* payload pools, whole (allocated) */
    uint64_t pools_in_use[SRV_MAX_EFFECTS];   /* part of them held by resident blocks */
    uint64_t block_meta[SRV_MAX_EFFECTS];     /* masks, frames, keys, lists, viewer bits */
    uint64_t viewers;                         /* per-viewer buffers (pixels, images, request lists) */
    uint64_t queues;                          /* update queues, job lists, per-thread scratch */
    uint64_t world_local;                     /* the world-space cache's local lookup tables (per viewer) */
    uint64_t total;                           /* everything above (reserved pools counted whole) */
} srv_memory;

/* What a sink receives for each viewer after compose (sparse viewers excepted: their pixels are read with
 * srv_viewer_pixels and the accessors below). Pointers are valid during the call only. */
typedef struct srv_viewer_frame {
    srv_viewer_id id;
    const char *name;
    uint32_t frame;
    uint32_t width, height;
    const uint8_t *srgb;   /* width*height*3, sRGB 8-bit, top row first */
    const float *radiance; /* width*height*3, linear */
    const float *depth;    /* width*height, distance along the primary ray, INFINITY for the sky */
    srv_camera camera;     /* the camera it was rendered for */
    const srv_viewer_stats *stats;
    const float *views[3]; /* with keep_views: AO, lit fraction of light 0, sharing; else NULL */
} srv_viewer_frame;

enum { SRV_VIEW_AO = 0, SRV_VIEW_SHADOW, SRV_VIEW_SHARING, SRV_VIEW_COUNT };

/* A sink: called for every viewer's frame, then once with the frame's statistics. Returning non-zero from
 * either stops nothing but is counted and reported by srv_loop_frame (a sink that cannot write). */
typedef struct srv_sink {
    int (*viewer_frame)(void *user, const srv_viewer_frame *frame);
    int (*frame_done)(void *user, const srv_frame_stats *stats);
    void *user;
} srv_sink;

typedef struct srv_loop srv_loop;

/* Creates a loop with no viewers. Returns FXC_OK and *out, or a code with a one-line message in err. */
fxc_result srv_loop_create(const srv_loop_desc *desc, srv_loop **out, char *err, size_t err_cap);
void srv_loop_free(srv_loop *loop);

/* Adds a viewer: its buffers are allocated (and counted) here. FXC_ERR_NO_SLOT when all slots are taken,
 * FXC_ERR_INVALID for a bad size, FXC_ERR_NOMEM. It has no camera until srv_viewer_set_camera. */
fxc_result srv_viewer_add(srv_loop *loop, const srv_viewer_desc *desc, srv_viewer_id *out);

/* Removes a viewer and frees its buffers; its id (and every older id of its slot) is refused afterwards. */
fxc_result srv_viewer_remove(srv_loop *loop, srv_viewer_id id);

/* Sets the camera the viewer's next frames are rendered for. FXC_ERR_CAMERA for a degenerate camera,
 * FXC_ERR_STALE_ID for a removed viewer, FXC_ERR_INVALID for a sparse viewer (srv_viewer_set_pixels). */
fxc_result srv_viewer_set_camera(srv_loop *loop, srv_viewer_id id, const srv_camera *camera);

/* A sparse viewer's next frame (desc.max_pixels > 0): the pixels of the width x height image camera sees,
 * each packed as y << 16 | x (SRV_PIXEL_XY), in any order. The list is copied, sorted in a whole frame's
 * compose order (16 x 16 tiles in row order, 4-row runs inside each, rows inside each run) and
 * deduplicated: a pixel listed twice is traced once (*unique, may be NULL, receives the distinct count).
 * Listed pixels of one whole-frame run are composed together, so an effect that shades a run's pixels
 * jointly (the probes) sees the same neighbours when the whole run is listed.
 * The next srv_loop_frame renders exactly those pixels through the shared caches: visibility traces one
 * primary ray each, requests and compose visit only them (cost proportional to the list, not the image);
 * then the list is spent, and the viewer renders nothing more until the next call. Results, until then:
 * srv_viewer_pixels (the sorted distinct list) and srv_viewer_image / radiance / depth / view, indexed by
 * position in that list (srv_viewer_pixel_index). A list replaces one not yet rendered.
 * FXC_ERR_STALE_ID; FXC_ERR_INVALID (not a sparse viewer, a NULL list, sides outside 1..SRV_MAX_SIDE);
 * FXC_ERR_RANGE (count 0 or above max_pixels, or an entry outside the image: nothing is changed);
 * FXC_ERR_CAMERA. */
fxc_result srv_viewer_set_pixels(srv_loop *loop, srv_viewer_id id, const srv_camera *camera, uint32_t width,
                                 uint32_t height, const uint32_t *pixels, uint32_t count, uint32_t *unique);
#define SRV_PIXEL_XY(x, y) ((uint32_t)(y) << 16 | (uint32_t)(x))

/* A sparse viewer's last rendered list (distinct, in that compose order), *count entries; NULL for a stale id,
 * a whole-frame viewer, or before its first frame. */
const uint32_t *srv_viewer_pixels(const srv_loop *loop, srv_viewer_id id, uint32_t *count);
/* The position of pixel (x, y) in that list (binary search), or UINT32_MAX when it is not listed. */
uint32_t srv_viewer_pixel_index(const srv_loop *loop, srv_viewer_id id, uint32_t x, uint32_t y);

/* FXC_OK when id names a present viewer. */
fxc_result srv_viewer_check(const srv_loop *loop, srv_viewer_id id);

/* The present viewers in slot order: writes up to cap ids, returns how many there are. */
uint32_t srv_loop_viewers(const srv_loop *loop, srv_viewer_id *ids, uint32_t cap);

/* A viewer's last frame: sRGB image, linear radiance, depth, or a kept view; NULL for a stale id or before
 * its first frame. *width / *height (may be NULL) receive its size. A sparse viewer's arrays hold one entry
 * per listed pixel (srv_viewer_pixels), and its size is its last list's image. */
const uint8_t *srv_viewer_image(const srv_loop *loop, srv_viewer_id id);
const float *srv_viewer_radiance(const srv_loop *loop, srv_viewer_id id);
const float *srv_viewer_depth(const srv_loop *loop, srv_viewer_id id);
const float *srv_viewer_view(const srv_loop *loop, srv_viewer_id id, int which);
fxc_result srv_viewer_size(const srv_loop *loop, srv_viewer_id id, uint32_t *width, uint32_t *height);

/* Registers a sink (at most 8). The loop keeps the struct by value; user must outlive the loop. */
fxc_result srv_loop_add_sink(srv_loop *loop, const srv_sink *sink);

/* Runs one frame for every present viewer that has a camera, fills *stats (returned, never stashed).
 * Returns FXC_OK; a sink's failure is returned as FXC_ERR_IO after the whole frame ran; FXC_ERR_SHUTDOWN for
 * a frame abandoned at a stop (srv_loop_set_stop). */
fxc_result srv_loop_frame(srv_loop *loop, srv_frame_stats *stats);

/* A stop flag the frames watch (NULL: none; the flag must outlive the loop): once it is non-zero, a frame in
 * progress ends within one task of the thread pool (a 16 x 16 tile, a chunk of blocks) instead of after its
 * last stage (a frame of several 4K viewers takes seconds), and is abandoned: srv_loop_frame returns
 * FXC_ERR_SHUTDOWN without calling the sinks, counting the frame or advancing the frame number. The caches
 * may then hold blocks marked valid that were not computed, so the loop renders no more frames (every later
 * srv_loop_frame returns FXC_ERR_SHUTDOWN at once); what it counted so far (the run report, memory) stays
 * readable. The viewers' images, radiance and views stay the last finished frame's when the frame was
 * abandoned before compose, and are gone (NULL) when compose had started; depth is gone either way. The
 * queues stage (serial) watches the flag too, every few thousand blocks. For SIGTERM in `serve` and `sim`:
 * the summary is written a tile after the signal, not a frame after. */
void srv_loop_set_stop(srv_loop *loop, const volatile sig_atomic_t *stop);

/* The effect list, the effects that run, their effective level bias. */
uint32_t srv_loop_effect_count(const srv_loop *loop);
const fx_effect *srv_loop_effect(const srv_loop *loop, uint32_t index);
bool srv_loop_effect_on(const srv_loop *loop, uint32_t index);
int32_t srv_loop_bias(const srv_loop *loop, uint32_t index);
/* Whether an effect is a shading effect that goes through a cache this run (counted in requested texels). */
bool srv_loop_effect_cached(const srv_loop *loop, uint32_t index);

/* Benchmarks: every ray stream the effect updates trace is shown to these first (fx_context's observe_rays
 * and observe_hits; NULL: none), from the tracing thread. */
void srv_loop_set_observer(srv_loop *loop, void (*occlusion)(void *user, const void *rays, uint32_t count),
                           void (*hits)(void *user, const void *rayhits, uint32_t count), void *user);

/* The finest world-grid cell a loop on scene s uses when probe_cell is 0 (the power of two nearest a 64th of
 * the bounding-box diagonal; 1/64 m for a scene without extent), metres. */
double srv_probe_cell_default(const scene *s);

/* The finest world-grid cell the run uses, metres; 0 when no world-space cache exists. */
float srv_loop_probe_cell(const srv_loop *loop);

/* The loop's description with its defaults resolved. */
const srv_loop_desc *srv_loop_desc_of(const srv_loop *loop);

/* Current memory (exact: every byte went through a counting allocator). */
void srv_loop_memory(const srv_loop *loop, srv_memory *out);

#endif
