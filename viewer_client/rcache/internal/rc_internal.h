/* The render cache's private parts: the owner struct, the point store's layout, the camera maths and the
 * stage functions each source file gives the frame driver (rc_render.c). Only the library and white-box tests
 * see it.
 *
 * The point store is structure-of-arrays over fixed slots (capacity + insert_reserve of them): position (x,
 * y, z as float offsets from the cache's origin), colour and age packed in one word (r | g << 8 | b << 16 |
 * age << 24, age 255 = a free slot), and what a frame computes per slot (pixel, view depth, destination
 * list). A slot keeps its point until the point is evicted or dropped; new points take free slots from a
 * stack rebuilt every frame. Each pass that streams over the points touches only the arrays it needs
 * (CONVENTIONS 6: the projection reads 16 bytes a point, ageing 5).
 *
 * Tile lists (2002 3.2, Reinhard 2001 section 3): every frame the projected points are bucket-sorted by tile
 * (counting sort, per chunk of slots) into one array of 16-byte entries, tile after tile and within a tile by
 * part (the chunks one thread owns in the static split): each tile's point list for this frame. A point that
 * lands in another tile than in the last frame moves to that tile's list (tile_of[] remembers the list; the
 * move is counted as a migration). The z-buffer then reads one tile's list into that tile's part of the
 * image, which stays in cache.
 *
 * Determinism: every parallel pass writes per-chunk, per-tile or per-band outputs, and the serial steps
 * between them combine those in a fixed order, so the result does not depend on which thread ran what. Hot
 * loops are written without branches so the compiler vectorises them (FXC_HOT_CLONES adds an AVX2 copy); with
 * -ffp-contract=off every copy computes the same floats. */
#ifndef FXC_VIEW_RC_INTERNAL_H
#define FXC_VIEW_RC_INTERNAL_H

#include "fxc_pool.h"
#include "fxc_hot.h"
#include "rcache.h"

#include <math.h>
#include <stdint.h>

#define RC_NO_PIXEL    UINT32_MAX
#define RC_NO_POINT    UINT32_MAX
#define RC_AGE_DEAD    255u        /* a free slot (an evicted or dropped point) */
#define RC_AGE_NO_DROP 255u        /* drop plan: no age is old enough */
#define RC_EMPTY_PT    0xFF000000u /* a pixel without a point: colour 0, age 255 */
#define RC_NEAR        1.0e-4f     /* points nearer than this (metres along the view axis) are behind */
#define RC_LOCAL_TILE  256u        /* the largest tile side the z-buffer works on in its own buffers */

static inline uint32_t rc_age(uint32_t rgba)
{
    return rgba >> 24;
}

/* A projected point in its tile's list: 8 bytes. The key packs the pixel within the tile (row * tile +
 * column, pix_bits of them) and the slot within its chunk above it: the z-buffer reads a tile's list chunk by
 * chunk (each chunk's range of it is known from the sort's offsets), so the slot is the chunk's first plus
 * that. The colour is not in the entry: the z-buffer reads a winner's from the store. (Entries
 * of 16 bytes, pixel, depth, colour and slot, made the sort write and the z-buffer read twice the bytes.) */
typedef struct rc_entry {
    uint32_t key; /* (slot - chunk's first) << pix_bits | pixel within the tile */
    float depth;  /* view depth, metres along the camera's forward axis */
} rc_entry;
#define RC_ENTRY_LINE 8u /* entries in a cache line: every (tile, part) list starts on a line of its own */

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
bool view_rc__view_setup(const view_rc_camera *cam, uint32_t width, uint32_t height,
                         const double cache_origin[3], rc_view *out);

/* Projects a point given relative to the cache origin. Returns false when it is behind the camera or outside
 * the image; else the pixel and the view depth. The hot loops use the same arithmetic without branches. */
FXC_HOT_INLINE bool rc_project(const rc_view *v, float x, float y, float z, uint32_t *ix, uint32_t *iy,
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

/* The frame's threads: common/fxc_pool.h, a pool that runs task 0..count-1 of a function, the caller included
 * (Reinhard 2001 section 3: tiles processed by several threads). Each pass is a count of tasks (chunks of the
 * point store, tiles or bands); every task writes only its own outputs, so which thread ran it does not
 * change the result. */
typedef fxc_pool rc_pool;

/* A pass over the image: tiles (row-major) or bands of rows, `count` of them in row order. Run statically
 * (thread k takes the k-th contiguous range, and steals from the others' ends when done), so on 2 threads
 * the top half of the image stays on the caller's core from the z-buffer through the dither; with
 * dynamic_pixels, handed out by the pool's counter. Which thread runs a task never changes its output. */
static inline void rc_run_pixels(fxc_pool *pool, bool dynamic, uint32_t count, fxc_pool_task task, void *user)
{
    if (dynamic)
        fxc_pool_run(pool, count, task, user);
    else
        fxc_pool_run_static(pool, count, task, user, true);
}

/* Per-thread scratch. */
typedef struct rc_worker {
    uint8_t *occupied; /* predicted occupancy at quarter resolution, low_w x low_h */
    uint32_t *low;     /* predicted projection: quarter-resolution pixel per slot of a chunk */
    float *err;        /* dither: two rows of RC_DITHER_LANES x (width + 2) errors, the lanes interleaved */
    uint8_t *spare;    /* dither: a row of choices, a bit per lane */
    uint16_t *planes;  /* interpolation: view_rc__interp_scratch(width) values */
    uint16_t *box;     /* prefilter: view_rc__prefilter_scratch(tile side) values */
    uint32_t *halo;    /* fused pixel passes: six rows of shown points around a band, then a row of depths */
    float *zt;         /* z-buffer: one tile's depths, tile x tile, row after row (local_z only) */
    uint32_t *wt;      /* ... the slot that won each pixel (RC_NO_POINT: none) */
    uint32_t *ct;      /* ... and its rgba (RC_EMPTY_PT: none) */
} rc_worker;

/* Points being inserted, a batch at a time (rc_cache.c): their positions computed in one loop without
 * branches, then the slots taken one by one. */
enum { RC_BATCH = 256 };
typedef struct rc_batch {
    uint32_t n;
    float px[RC_BATCH], py[RC_BATCH], dist[RC_BATCH]; /* image position, distance along the ray (inf: sky) */
    const uint8_t *rgb[RC_BATCH];
    float x[RC_BATCH], y[RC_BATCH], z[RC_BATCH]; /* out: position relative to the cache origin */
    uint32_t last_pix[RC_BATCH];                 /* out: pixel in the last frame (RC_NO_PIXEL: none) */
    float last_depth[RC_BATCH];                  /* out: view depth there */
} rc_batch;

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

    /* Tiles: square, a power of two on a side (the tile of a pixel is two shifts). */
    uint32_t tile, tile_shift, tiles_x, tiles_y, tile_count;
    uint32_t pix_bits; /* 2 tile_shift: an entry key's bits of the pixel; + chunk_shift at most 32 */
    uint16_t list_outside, list_dead, list_new; /* tile_count, + 1, + 2: the other values of dest / tile_of */
    /* The z-buffer works in buffers of its own (tiles up to RC_LOCAL_TILE on a side): the tile's depths,
     * winners and colours contiguous (48 KiB at tiles of 64), instead of 64 rows of the image 4 * width bytes
     * apart (which all fall in a few of L1's sets), then copied out row by row. */
    bool local_z;
    /* One thread (and not tiled_one_thread or no_tiling): no tile lists; each chunk, once projected, goes
     * straight into the image's z-buffer in slot order (the same winners as the lists, which hold a tile's
     * points in slot order too: the nearer depth, then the first). */
    bool direct_z;
    /* band_lists: the lists are bands of zband_rows full rows (a power of two; zband_count of them) instead
     * of tiles: a point's key is its band << zband_bits | its pixel within the band (row * width + column),
     * the entry's the pixel within the band and the slot within its chunk above it; the z-buffer tests a
     * band's lists straight into the image's rows (384 KiB at most of depth, winner and colour: in L2). The
     * points' tiles (dest, tile_of, the migrations) stay the tiles'. */
    bool band_z;
    uint32_t zband_rows, zband_shift, zband_count, zband_bits;
    /* band_z on one thread (band_flush): no sort pass. Each chunk, once projected (its keys in L1, as
     * direct_z), is appended band by band to a buffer of zband_cap entries per band (band b's at b *
     * zband_cap: the pixel within the band and the slot within the chunk above it), and the chunk's count
     * noted as a segment of that buffer (chunk, end); a band whose buffer the next chunk would overflow is
     * first flushed: its segments depth-tested in order into its rows of the image (cleared at its first
     * flush). The last flush of every band ends the pass. Slot order throughout: the same winners. */
    bool band_flush;
    uint32_t zband_cap;    /* entries a band's buffer holds (at least a chunk) */
    uint32_t *zband_fill;  /* per band: entries in its buffer */
    uint32_t *zband_nseg;  /* per band: segments in its buffer */
    uint32_t *zband_seg;   /* per band: chunk_count x (chunk, end) */
    uint8_t *zband_clear;  /* per band: its rows cleared this frame */
    uint32_t list_count;   /* the lists the sort fills: tile_count, or zband_count with band_z */
    uint32_t count_stride; /* counts per chunk: list_count + 2 (the tiles' outside and dead lists, or the
                            * bands' one sink) */

    /* The point store (structure of arrays over slots). */
    uint32_t slots; /* capacity + insert_reserve */
    float *px, *py, *pz;
    uint32_t *rgba;
    uint16_t *tile_of;    /* the list a point was in last frame (list_new: inserted since) */
    uint32_t *key;        /* this frame, per slot: its entry's key, which the sort copies into its tile's list
                           * (with no_tiling: the image's pixel index, RC_NO_PIXEL outside) */
    float *dep;           /* this frame: view depth */
    uint16_t *dest;       /* this frame: tile, list_outside or list_dead */
    uint8_t *mark;        /* this frame: shown in a pixel, one array per thread, mark_stride bytes apart (each
                           * slots + 1: the last is a sink). The depth cull's thread w writes only array w (no
                           * line written by two cores at once); the ageing ORs them over its chunks. */
    size_t mark_stride;   /* slots + 1, rounded up to 64 */
    uint32_t *free_slots; /* stack of free slots: the next insert takes free_slots[free_count - 1] */
    uint32_t free_count;
    uint32_t
        *chunk_free; /* per chunk: free slots the ageing pass listed (in free_list at chunk * chunk_size) */
    uint32_t *free_list; /* slots: per chunk, its free slots in descending order */

    /* Chunks of slots: the unit of the parallel passes over points. */
    uint32_t chunk_size, chunk_shift, chunk_count; /* chunk_size = 1 << chunk_shift (pix_bits + chunk_shift
                                                    * <= 32, so an entry's key holds both) */
    uint32_t *counts;      /* chunk_count x count_stride: points going to each list, then offsets */
    uint32_t *chunk_hist;  /* chunk_count x 256: ages of the live points per chunk */
    uint32_t *chunk_quota; /* per chunk: points of age drop_age to drop this frame */
    rc_chunk_stat *chunk_stat;
    uint32_t drop_age; /* this frame's drop plan: drop ages above it and chunk_quota of it (255: none) */

    /* The tile lists of this frame, one per tile and part. The passes over chunks run statically split
     * (fxc_pool_run_static): part p is the chunks thread p runs, [fxc_pool_static_begin(chunk_count, parts,
     * p), the same for p + 1). Tile t's entries from part p are [list_start[t * parts + p], list_end[...]),
     * in chunk then slot order (chunk c's: up to counts[c * (tile_count + 2) + t] after the sort); every such
     * list starts on a cache line of its own (entries padded to RC_ENTRY_LINE, 64 bytes), so no line of
     * entries is written by two threads. The z-buffer reads a tile's parts in part order: chunk order, the
     * same with any thread count. */
    rc_entry *entries;    /* entry_sink + RC_ENTRY_LINE x parts entries, 64-byte aligned */
    uint32_t parts;       /* the pool's threads */
    uint32_t entry_sink;  /* the sort writes points outside the image and free slots to entry_sink + 8 x its
                           * thread: a line per thread, so no two threads write one entry */
    uint32_t *list_start; /* list_count x parts */
    uint32_t *list_end;   /* list_count x parts */

    /* Ageing (2002 3.4). */
    double age_carry, hidden_carry; /* fractional parts carried to the next frame */
    uint32_t step_visible, step_hidden;

    /* What the inserts did since the last frame. */
    uint32_t since_inserted, since_superseded, since_dropped;
    uint64_t since_dropped_age_sum;
    double since_update_ms;

    /* The cache's origin: points are stored as float offsets from it (set by the first insert or frame). */
    bool has_origin;
    double origin[3];

    /* The last frame, for the sparse supersede (its z-buffer and winners stay until the next frame). */
    bool last_valid;
    rc_view last_view;

    /* This frame. */
    rc_view view, predicted;
    bool predict;

    /* Images, width x height. */
    float *zbuf;       /* nearest view depth per pixel (+inf: none) */
    uint32_t *win;     /* its slot (RC_NO_POINT: none) */
    uint32_t *pre;     /* its rgba before the depth cull (RC_EMPTY_PT: none) */
    uint32_t *pt;      /* after the depth cull: the shown point's rgba, RC_EMPTY_PT when none */
    uint8_t *rgb;      /* output colour */
    float *depth;      /* output depth */
    uint8_t *kind;     /* output pixel kinds */
    uint8_t *priority; /* output priority */
    uint8_t *chosen;   /* dither: chosen pixels */
    float *stretch_x2,
        *stretch_y2;       /* per column / row: the squared image-plane coordinate of the pixel centre */
    uint32_t *row_need;    /* per row: pixels the prefilter must fill */
    uint32_t *band_need;   /* per band (tiles_y of them, tile_size rows each): pixels to fill */
    uint32_t *band_culled; /* per band: pixels the depth cull emptied */
    uint32_t *band_kind;   /* per band: pixels by kind (x VIEW_RC_PIXEL_KINDS) */
    uint64_t *band_weight; /* per band: sum of priority + 1 */
    uint32_t *band_quota, *band_offset;

    /* Prediction: quarter resolution (2002 3.1). */
    uint32_t low_w, low_h;

    /* Requests. */
    view_rc_pixel *requests;           /* sample_budget entries */
    view_rc_pixel *predicted_requests; /* sample_budget / 2 entries */
    uint32_t request_count, predicted_count;

    uint32_t thread_count;
    rc_worker *workers;
    rc_pool *pool;

    rc_batch batch; /* the inserts' points, a batch at a time */
};

/* rc_cache.c */
/* Recomputes the age histogram of every chunk. */
void view_rc__recount_ages(view_rc *rc);

/* rc_project.c: the point passes of a frame. */
void view_rc__plan_drops(view_rc *rc);      /* serial: this frame's drop plan from the chunk histograms */
void view_rc__predict_clear(view_rc *rc);   /* the workers' quarter-resolution occupancy cleared */
void view_rc__predict_combine(view_rc *rc); /* ... and ORed into worker 0's (the projection fills them) */
void view_rc__project_sort(view_rc *rc); /* parallel projections (predicted, if predict, and current) + serial
                                          * offsets + parallel bucket sort */
void view_rc__zbuffer(view_rc *rc);      /* parallel over tiles */
void view_rc__project_direct(view_rc *rc); /* no_tiling: the projection without the sort (parallel) */
void view_rc__zbuffer_direct(view_rc *rc); /* no_tiling: one z-buffer pass in slot order (serial) */
void view_rc__age(view_rc *rc);            /* parallel over chunks, then the free stack (serial) */
void view_rc__age_chunk(view_rc *rc, uint32_t chunk); /* one chunk of view_rc__age's parallel part */
void view_rc__free_stack(view_rc *rc);                /* ... and its serial part */

/* rc_image.c: the pixel passes, parallel over bands of rows: fused (view_rc__pixels: each band through the
 * cull, the interpolation and the prefilter in one task) or, with separate_pixel_passes, one run each. */
size_t view_rc__interp_scratch(uint32_t width);   /* 16-bit values of a worker's interpolation scratch */
size_t view_rc__prefilter_scratch(uint32_t tile); /* ... and prefilter scratch (tiles of that side) */
void view_rc__pixels(view_rc *rc);
void view_rc__depth_cull(view_rc *rc);
void view_rc__interpolate(view_rc *rc);
void view_rc__prefilter(view_rc *rc);

/* rc_sample.c */
void view_rc__predicted_sampling(view_rc *rc); /* serial */
void view_rc__sampling_quotas(view_rc *rc);    /* serial: each band's share of the budget */
void view_rc__sampling(view_rc *rc);           /* parallel: the bands dithered, in groups */
/* Dithers bands [task * group, task * group + group) (group at most RC_DITHER_LANES) with worker's scratch.
 */
void view_rc__dither_group(view_rc *rc, uint32_t task, uint32_t group, uint32_t worker);
/* Splits count over bands by weight (largest remainder, each band at most its pixels). */
void view_rc__band_quotas(const uint64_t *weight, const uint32_t *pixels, uint32_t bands, uint32_t count,
                          uint32_t *quota);
/* Dithers up to RC_DITHER_LANES bands at once (each independent, the same result as alone or with others):
 * band k is rows [y0[k], y1[k]) of a width-wide priority image, gets exactly quota[k] pixels (at most its
 * pixels), marked in chosen and written to out[k] in scanline order. err: 2 * RC_DITHER_LANES * (width + 2)
 * floats; spare: width bytes. */
#define RC_DITHER_LANES 8
void view_rc__dither_bands(const uint8_t *priority, uint32_t width, const uint32_t *y0, const uint32_t *y1,
                           const uint64_t *weight, const uint32_t *quota, uint32_t bands, uint8_t *chosen,
                           float *err, uint8_t *spare, view_rc_pixel *const *out);

/* Monotonic clock, milliseconds. */
double view_rc__now_ms(void);

#endif
