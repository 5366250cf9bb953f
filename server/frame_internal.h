/* Private to the frame loop: the loop's state and the stage functions (frame.c orchestrates; visibility.c,
 * requests.c, update.c and compose.c are the stages). */
#ifndef FXC_SERVER_FRAME_INTERNAL_H
#define FXC_SERVER_FRAME_INTERNAL_H

#include "cache.h"
#include "effects.h"
#include "frame.h"
#include "pool.h"

enum {
    SRV_TILE = 16,                /* visibility and request tiles are 16 x 16 pixels */
    SRV_MISS = 0xFFFFFFFFu,       /* no hit */
};

/* A growable (key, mask) list, kept across frames so steady state allocates nothing. */
typedef struct srv_request_list {
    uint64_t *keys, *masks;
    uint32_t *blocks; /* block index per key after the batch request */
    size_t count, capacity;
} srv_request_list;

/* What one viewer's pixels saw (stage 2) and got (stage 7). */
typedef struct srv_viewer {
    srv_camera_frame frame;
    uint32_t *tri;      /* hit triangle per pixel, SRV_MISS for none */
    float *bary_u, *bary_v;
    float *footprint;   /* log2 of the pixel's footprint in level-0 texels (ray differentials) */
    float *radiance;    /* linear RGB */
    uint8_t *image;     /* sRGB 8-bit RGB */
    float *views[SRV_VIEW_COUNT];
    srv_request_list requests; /* this frame's, merged across threads, before the cache */
} srv_viewer;

/* One queued block of an effect for this frame. */
typedef struct srv_job {
    uint32_t block;        /* block index in the effect's pool */
    uint32_t lookup_block; /* the lookup block with the same island, level and position */
    uint64_t mask;         /* texels to trace */
} srv_job;

typedef struct srv_job_list {
    srv_job *items;
    size_t count, capacity;
} srv_job_list;

struct srv_loop {
    srv_loop_desc desc;
    const scene *s;
    scene_rt *rt;
    srv_pool *pool;
    osc_cache *osc;
    fx_context fx;
    fx_info info[SCENE_FX_COUNT];
    int32_t bias[SCENE_FX_COUNT];
    bool cached_effect[SCENE_FX_COUNT]; /* shading effects that go through the cache (shadow, AO) */
    uint32_t frame_number;
    srv_viewer viewers[SRV_MAX_VIEWERS];
    srv_request_list *thread_requests; /* one per pool thread */
    srv_job_list jobs[SCENE_FX_COUNT];
    fx_block_job *fx_jobs;             /* scratch handed to the effects */
    size_t fx_jobs_capacity;
    uint64_t *viewer_bits[SCENE_FX_COUNT]; /* per block: which viewers requested it (keep_views only) */
    /* Per-frame scratch of the update stage, grown when needed and kept (no allocation in steady state). */
    uint64_t *queue_empty, *queue_refine;  /* per frame block: empty texels, texels to refine */
    uint32_t *queue_lookups;               /* per frame block: its lookup block */
    size_t queue_capacity;
    uint64_t *chunk_rays;                  /* rays traced per chunk of jobs */
    size_t chunk_capacity;
    srv_frame_stats *stats;                /* the frame being filled */
};

/* Monotonic clock, milliseconds. */
double srv__now_ms(void);

/* The capacity a growable array of `capacity` entries needs for n entries: doubled from `first` until it
 * holds n (capacity itself when it already does). */
size_t srv__grown_capacity(size_t capacity, size_t n, size_t first);

/* Reallocates *array to count elements of size bytes, checking the size for overflow; false (array
 * untouched) on failure. */
bool srv__realloc(void **array, size_t count, size_t size);

/* Grows a list to hold at least n entries; false on no memory. */
bool srv__request_reserve(srv_request_list *list, size_t n);
bool srv__jobs_reserve(srv_job_list *list, size_t n);

/* Stage 2: visibility of one viewer into its buffers. */
void srv__visibility(srv_loop *loop, uint32_t viewer);

/* Stage 3: requests of one viewer into the cache; returns the viewer's requested texels (deduplicated
 * within the viewer, shading effects only). */
uint64_t srv__requests(srv_loop *loop, uint32_t viewer);

/* Stages 4-6: queues within the ray budget, resampling, triangle lookup, effect updates. */
void srv__update(srv_loop *loop);

/* Stage 7: compose one viewer (cached, or per-pixel in no-cache mode). */
void srv__compose(srv_loop *loop, uint32_t viewer);

/* The effect level of a pixel: round(footprint + bias), clamped to [0, 15]. */
static inline uint32_t srv__level(float footprint_log2, int32_t bias)
{
    float l = footprint_log2 + (float)bias;
    if (!(l > 0.0f))
        return 0;
    if (l >= 15.0f)
        return 15;
    return (uint32_t)(l + 0.5f) > 15 ? 15 : (uint32_t)(l + 0.5f);
}

/* The island-local UV (level-0 texels) of a hit. */
static inline void srv__island_uv(const scene *s, uint32_t tri, float u, float v, float *tu, float *tv)
{
    const float *uv = s->tri_island_uv + 6 * (size_t)tri;
    float w = 1.0f - u - v;
    *tu = w * uv[0] + u * uv[2] + v * uv[4];
    *tv = w * uv[1] + u * uv[3] + v * uv[5];
}

/* The world position and unit normal of a hit. */
void srv__hit_point(const scene *s, uint32_t tri, float u, float v, float pos[3], float normal[3]);

#endif
