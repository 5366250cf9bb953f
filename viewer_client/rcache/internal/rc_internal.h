/* The render cache's private parts: the owner struct, the point store's layout, the camera maths and the stage
 * functions each source file gives the frame driver (rc_render.c). Only the library and white-box tests see it.
 *
 * The point store (2002 3.2, Reinhard 2001 section 3). Points live in one array of records, grouped by list:
 * list i < tile_count holds the points that landed in tile i in the last frame, list tile_count those that
 * landed outside the image (or behind the camera); after the lists come the points inserted since the last frame.
 * A frame projects every record, counts per chunk of the array how many go to each list, and copies each record
 * into the other array at its list's place: a counting sort by tile that is also the migration of points between
 * tile lists. Records are AoS (rc_rec, 16 bytes) because every pass that reads one reads all of it; what a frame
 * computes per record (pixel and depth) is a second array beside it (rc_prj), copied along.
 *
 * Determinism: every parallel pass writes per-chunk, per-tile or per-band outputs, and the serial steps between
 * them combine those in a fixed order, so the result does not depend on which thread ran what. */
#ifndef FXC_VIEW_RC_INTERNAL_H
#define FXC_VIEW_RC_INTERNAL_H

#include "rcache.h"

#include <math.h>
#include <stdint.h>

#define RC_NO_PIXEL UINT32_MAX
#define RC_NO_POINT UINT32_MAX
#define RC_AGE_EVICTED 255u
#define RC_AGE_NO_DROP 256u      /* drop plan: no age is old enough */
#define RC_EMPTY_PT 0xFF000000u  /* a pixel without a point: colour 0, age 255 */
#define RC_NEAR 1.0e-4f          /* points nearer than this (metres along the view axis) are behind */

/* A cached point: position relative to the cache's origin, colour and age (r | g << 8 | b << 16 | age << 24). */
typedef struct rc_rec {
    float x, y, z;
    uint32_t rgba;
} rc_rec;

/* Where a record landed in the current frame: pixel index (RC_NO_PIXEL outside) and view depth (metres along
 * the camera's forward axis). */
typedef struct rc_prj {
    uint32_t pix;
    float depth;
} rc_prj;

static inline uint32_t rc_age(uint32_t rgba)
{
    return rgba >> 24;
}

/* A camera set up for an image: the server's frame (srv_camera_setup) and the projection that inverts
 * srv_camera_ray. rel is the camera position relative to the cache origin, in float, for the hot loops. */
typedef struct rc_view {
    double origin[3];
    float rel[3];
    float forward[3], right[3], up[3];
    float tan_half_x, tan_half_y;
    uint32_t width, height;
    float half_w, half_h; /* width / 2, height / 2 */
    float kx, ky;         /* width / (2 tan_half_x), height / (2 tan_half_y) */
} rc_view;

/* rc_camera.c */
/* Sets up cam for a width x height image. False when the camera is not valid (the server's rules: finite
 * values, direction not zero, field of view in (0, 180)). cache_origin: the origin rel is taken from. */
bool view_rc__view_setup(const view_rc_camera *cam, uint32_t width, uint32_t height, const double cache_origin[3],
                         rc_view *out);
/* The unit direction through image position (px, py): srv_camera_ray's arithmetic, operation for operation. */
void view_rc__view_ray(const rc_view *v, float px, float py, float dir[3]);

/* Projects a point given relative to the cache origin. Returns false when it is behind the camera or outside
 * the image; else the pixel and the view depth. Inline: the hot loops use the same code. */
static inline bool rc_project(const rc_view *v, float x, float y, float z, uint32_t *ix, uint32_t *iy,
                              float *depth)
{
    float vx = x - v->rel[0], vy = y - v->rel[1], vz = z - v->rel[2];
    float zc = vx * v->forward[0] + vy * v->forward[1] + vz * v->forward[2];
    float xc = vx * v->right[0] + vy * v->right[1] + vz * v->right[2];
    float yc = vx * v->up[0] + vy * v->up[1] + vz * v->up[2];
    *depth = zc;
    if (!(zc > RC_NEAR))
        return false;
    float inv = 1.0f / zc;
    float px = v->half_w + v->kx * xc * inv;
    float py = v->half_h - v->ky * yc * inv;
    if (!(px >= 0.0f && px < (float)v->width && py >= 0.0f && py < (float)v->height))
        return false;
    *ix = (uint32_t)px; /* truncation: floor for px >= 0, at most width - 1 for px < width */
    *iy = (uint32_t)py;
    return true;
}

/* rc_pool.c: a pool of threads that run task 0..count-1 of a function, the caller included. */
typedef struct rc_pool rc_pool;
typedef void (*rc_pool_task)(void *user, uint32_t task, uint32_t worker);
rc_pool *view_rc__pool_create(uint32_t threads); /* NULL when threads cannot start */
void view_rc__pool_free(rc_pool *pool);
void view_rc__pool_run(rc_pool *pool, uint32_t count, rc_pool_task task, void *user);

/* Per-thread scratch. */
typedef struct rc_worker {
    uint32_t *box;     /* prefilter: (tile_h + 6) x tile_w x 4 running sums */
    uint8_t *occupied; /* predicted occupancy at quarter resolution, low_w x low_h */
    float *err;        /* dither: two rows of width + 2 errors */
} rc_worker;

/* Per-chunk figures of the passes over the store, added up in chunk order. */
typedef struct rc_chunk_stat {
    uint32_t projected, migrated, evicted, dropped;
    uint64_t dropped_age_sum;
} rc_chunk_stat;

struct view_rc {
    view_rc_desc d; /* resolved */
    uint32_t width, height;
    size_t pixels;
    size_t memory_bytes;
    void *block; /* the one allocation every array below points into */

    /* Tiles (Reinhard 2001; 2002 3.2). */
    uint32_t tile_w, tile_h, tiles_x, tiles_y, tile_count;
    uint32_t list_count;  /* tile_count + 1: the tiles and the outside list */
    uint16_t *col_tile;   /* per column: its tile's column */
    uint32_t *row_tile;   /* per row: tiles_x times its tile's row */

    /* The point store: two arrays, the current one is [cur]. */
    uint32_t slots;       /* capacity + insert_reserve */
    rc_rec *rec[2];
    rc_prj *prj[2];
    int cur;
    int built;            /* the array this frame builds: 1 - cur (tiled) or cur (no_tiling, in place) */
    uint32_t built_count; /* records in it */
    uint32_t chunks_used; /* chunks covering [0, placed + pending) at the frame's start */
    uint16_t *dest;       /* per slot of the current array: the list it goes to this frame (list_count: dropped) */
    uint32_t *list_start; /* list_count + 1 entries: list i is [list_start[i], list_start[i + 1]) */
    uint32_t *next_start; /* the same for the array being built */
    uint32_t placed;      /* records in lists: [0, placed) */
    uint32_t pending;     /* inserted since the last frame: [placed, placed + pending) */

    /* Chunks of the store (fixed-size ranges of slot indices): the unit of the parallel passes over points. */
    uint32_t chunk_size, chunk_max;
    uint32_t *counts;      /* chunk_max x (list_count + 1): records going to each list, then their offsets */
    uint32_t *chunk_hist;  /* chunk_max x 256: ages of live records per chunk of the current array */
    uint32_t *chunk_quota; /* per chunk: records of age drop_age to drop this frame */
    rc_chunk_stat *chunk_stat;
    uint32_t drop_age;     /* this frame's drop plan: drop ages above it and chunk_quota of it (256: none) */

    /* Ageing (2002 3.4). */
    double age_carry, hidden_carry; /* fractional parts carried to the next frame */
    uint32_t step_visible, step_hidden;

    /* What the inserts did since the last frame. */
    uint32_t since_inserted, since_superseded, since_dropped;
    uint64_t since_dropped_age_sum;
    double since_update_ms;

    /* The cache's origin: points are stored as float offsets from it (set by the first insert). */
    bool has_origin;
    double origin[3];

    /* The last frame, for the sparse supersede (its z-buffer and winners stay until the next frame). */
    bool last_valid;
    rc_view last_view;

    /* This frame. */
    rc_view view, predicted;
    bool predict;

    /* Images, width x height. */
    float *zbuf;       /* nearest view depth per pixel */
    uint32_t *win;     /* its record in the current array (RC_NO_POINT: none) */
    uint32_t *pt;      /* after the depth cull: the shown point's rgba, RC_EMPTY_PT when none */
    uint8_t *rgb;      /* output colour */
    float *depth;      /* output depth */
    uint8_t *kind;     /* output pixel kinds */
    uint8_t *priority; /* output priority */
    uint8_t *chosen;   /* dither: chosen pixels */
    float *stretch_x2, *stretch_y2; /* per column / row: the squared image-plane coordinate of the pixel centre */
    uint32_t *tile_need;           /* per tile: pixels the prefilter must fill */
    uint32_t *tile_culled;         /* per tile: pixels the depth cull emptied */
    uint32_t *tile_kind;           /* per tile: pixels by kind (x VIEW_RC_PIXEL_KINDS) */
    uint64_t *tile_weight;         /* per tile: sum of priority + 1 */
    uint64_t *band_weight;         /* per band: sum of priority + 1 */
    uint32_t *band_quota, *band_offset;

    /* Prediction: quarter resolution (2002 3.1). */
    uint32_t low_w, low_h;

    /* Requests. */
    view_rc_pixel *requests;   /* sample_budget entries */
    view_rc_pixel *predicted_requests; /* sample_budget / 2 entries */
    uint32_t request_count, predicted_count;

    uint32_t thread_count;
    rc_worker *workers;
    rc_pool *pool;
};

/* rc_cache.c */
/* Recomputes the age histogram of every chunk from the current array's records. */
void view_rc__recount_ages(view_rc *rc);

/* rc_project.c: the point passes of a frame. */
void view_rc__plan_drops(view_rc *rc);      /* serial: this frame's drop plan from the chunk histograms */
void view_rc__predict_project(view_rc *rc); /* parallel: quarter-resolution occupancy per worker */
void view_rc__project_sort(view_rc *rc);    /* parallel + serial offsets + parallel scatter */
void view_rc__zbuffer(view_rc *rc);         /* parallel over tiles */
void view_rc__project_direct(view_rc *rc);  /* no_tiling: serial projection and z-buffer in cache order */
void view_rc__age(view_rc *rc);             /* parallel over chunks of the new array */

/* rc_image.c: the pixel passes, parallel over tiles. */
void view_rc__depth_cull(view_rc *rc);
void view_rc__interpolate(view_rc *rc);
void view_rc__prefilter(view_rc *rc);

/* rc_sample.c */
void view_rc__predicted_sampling(view_rc *rc); /* serial */
void view_rc__sampling(view_rc *rc);           /* serial quotas, parallel bands */
/* Splits count over bands by weight (largest remainder, each band at most its pixels). */
void view_rc__band_quotas(const uint64_t *weight, const uint32_t *pixels, uint32_t bands, uint32_t count,
                          uint32_t *quota);
/* Dithers one band: rows [y0, y1) of a width-wide priority image; chooses exactly quota pixels (quota at most
 * the band's pixels), marks them in chosen and writes them to out in scanline order. err: 2 * (width + 2)
 * floats. */
void view_rc__dither_band(const uint8_t *priority, uint32_t width, uint32_t y0, uint32_t y1, uint64_t weight,
                          uint32_t quota, uint8_t *chosen, float *err, view_rc_pixel *out);

/* Monotonic clock, milliseconds. */
double view_rc__now_ms(void);

#endif
