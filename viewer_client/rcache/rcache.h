/* clang-format off */
/* rcache: the viewer client's render cache (Walter, Drettakis and Parker 1999; Walter, Drettakis and
 * Greenberg 2002; parallel tiles after Reinhard, Shirley and Hansen 2001). The client keeps the colour and
 * depth samples the server sends as coloured 3-D points in a cache of fixed size, and every client frame it
 * reprojects them to its own, newer camera: a good image at the client's frame rate while the server's frames
 * are still on the way, and a list of pixels the server should render next (a sample request).
 *
 * One client frame (view_rc_render), stage by stage (the 2002 paper's Table 1 and Figure 1):
 *   update points       samples inserted since the previous frame (view_rc_insert_frame / _samples)
 *   predicted proj.     the points projected to a predicted camera at quarter resolution, no z-buffer
 *                       (2002 3.1)
 *   predicted sampling  empty quarter-resolution pixels requested, up to half the budget (2002 3.1)
 *   project, tile sort  every point projected to the current camera and put in the list of the tile it lands
 *                       in: a counting sort by tile (2002 3.2) that is also the migration of points between
 *                       the tiles' point lists (Reinhard 2001 section 3)
 *   z-buffer tiles      each tile's list depth-tested into that tile only (cache-sized, 2002 3.2)
 *   depth cull          points with nearer points on two opposite sides, agreeing with each other, dropped
 *                       (1999, slide 14)
 *   interpolate         the 3x3 weighted filter (1-2-1 / 2-4-2 / 1-2-1) where a pixel has no point, and the
 *                       priority image: older points and emptier neighbourhoods first (1999, slides 15-18)
 *   prefilter           the 7x7 uniform filter, only where the 3x3 found no point (2002 3.3, Figure 3)
 *   sampling            an error-diffusion dither over the priority image picks the rest of the budget
 *                       (1999, slide 19)
 *   age and evict       every point aged so that it reaches 128 before it is overwritten on average, faster
 *                       when not visible; a new sample whose colour differs ages its neighbours; 255 evicts
 *                       (2002 3.4)
 * Every stage but two short serial steps runs on several threads (Reinhard 2001: tiles for the z-buffer,
 * chunks of the point store, bands of rows for the pixel passes); the result does not depend on the thread
 * count.
 *
 * It links nothing but libc, libm and pthreads: no proto, no scene, no server code. Cameras are the wire's
 * (proto_pose: world position in double, a view direction with +Y up, vertical field of view); the pinhole
 * model is the server's (server/cameras/camera.h: pixel centres at +0.5, y down), inverted exactly, so a
 * frame reprojected to its own camera lands every point on its own pixel.
 *
 * Everything is allocated in view_rc_create(); nothing is allocated per frame. A view_rc is used by one
 * thread at a time (its own worker threads are internal). */
/* clang-format on */
#ifndef FXC_VIEW_RCACHE_H
#define FXC_VIEW_RCACHE_H

#include "fxc_result.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

enum {
    VIEW_RC_MAX_SIDE = 8192,  /* largest image width or height */
    VIEW_RC_MAX_THREADS = 64, /* worker threads, the caller included */
    VIEW_RC_MAX_TILES = 1024, /* the tile side grows until the image has at most this many tiles */
};

/* Distance, metres, at which a sky sample (depth +inf) is kept as a point: it then moves with the camera's
 * rotation and, to within 1e-6 rad per metre the camera travels, not with its translation. */
#define VIEW_RC_SKY_DISTANCE 1.0e6

/* A camera, as on the wire (proto_pose): world position, view direction (non-zero, need not be unit; up is
 * +Y) and vertical field of view. */
typedef struct view_rc_camera {
    double position[3]; /* metres, world coordinates, finite */
    float direction[3]; /* finite, not all zero */
    float fov_deg;      /* vertical field of view, degrees, (0, 180) */
} view_rc_camera;

/* Creation parameters. All-zero fields mean the default given beside each. */
typedef struct view_rc_desc {
    uint32_t width, height;  /* the client's image, pixels, 1..VIEW_RC_MAX_SIDE (required) */
    uint32_t capacity;       /* points the cache keeps after a frame (default width * height, about the 2002
                                paper's 7 MB of points at 512 x 512) */
    uint32_t sample_budget;  /* sample requests per frame, both kinds (default width * height / 32, at least
                                1; at most width * height) */
    uint32_t insert_reserve; /* points that can wait for the next frame beyond capacity before an insert has
                                to make room on the spot (default 4 * sample_budget) */
    uint32_t tile_size; /* tile side, pixels (default 64; rounded up to a power of two, grown until the image
                           has at most VIEW_RC_MAX_TILES tiles); also the height of the pixel passes' bands */
    uint32_t threads;   /* threads for a frame, the caller included (default 1, at most 64) */
    float cull_ratio;   /* depth cull: a point is dropped when points nearer by more than this fraction of
                           its depth lie on two opposite sides of it and agree with each other
                           (default 0.1) */
    float supersede_ratio;    /* a new sample replaces the cached point its camera saw at its pixel unless
                                 that point lies farther than the sample by more than this fraction
                                 (default 0.02) */
    float hidden_age_factor;  /* points not visible in a frame age this many times faster (default 2, >= 1) */
    uint8_t change_threshold; /* a new sample whose colour differs from the point it replaces by more than
                                 this (any channel, 0..255) ages that pixel's neighbours (default 32) */
    uint8_t change_penalty;   /* ... by this much (default 64) */
    uint8_t clear_rgb[3];     /* colour of pixels neither filter could fill (default black) */
    bool smooth_all;          /* false (default): a pixel that shows a point shows its colour, the 3x3 filter
                                 only fills pixels without one; true: the 3x3 weighted mean everywhere, as the
                                 1999 paper's "interpolation / smoothing" */
    /* Stage switches (off = false, the default, means the stage runs), to measure what each one does: */
    bool no_prediction; /* no predicted projection or predicted requests */
    bool no_prefilter;  /* no 7x7 prefilter */
    bool no_eviction;   /* ages stop at 254; points go only to make room */
    bool no_tiling;     /* no tile sort: the z-buffer takes the points in cache order straight into the whole
                           image, on one thread (the 1999 render cache); the other stages are unchanged */
    bool no_depth_cull; /* no depth cull */
    /* Not a stage switch: the same image either way. */
    bool dynamic_points; /* the passes over the point store handed out to threads dynamically (as before they
                            ran on a static split, each thread on the same chunks in every pass), to measure
                            what the split does (bench_rcache --only split) */
    bool dynamic_pixels; /* the passes over the image (z-buffer tiles, depth cull, interpolation, prefilter,
                            dither) handed out dynamically (as before they ran statically, thread k on the
                            same k-th range of rows in each), to measure the split (bench_rcache --only
                            split-pixels) */
    bool separate_pixel_passes; /* the depth cull, interpolation and prefilter as three passes over the
                                   whole image, each timed in its own stage (as before they ran fused, one
                                   band of rows through all three while its rows are in cache, timed
                                   together as VIEW_RC_STAGE_PIXELS), to measure the fusion
                                   (bench_rcache --only fuse) */
    bool separate_sample_age;   /* the dither and the ageing as two pool runs on 2+ threads, each timed in its
                                   own stage (by default they share one run there, timed as
                                   VIEW_RC_STAGE_SAMPLE_AGE), to measure it (bench_rcache --only share) */
    bool tiled_one_thread;      /* the tile sort and the tiled z-buffer on one thread too (by default one
                                   thread projects each chunk of points straight into the image's z-buffer
                                   in slot order, timed in "project and tile sort"; the tiles serve the
                                   threads), to measure it (bench_rcache --only direct) */
    bool band_lists; /* the points bucket-sorted into bands of full rows (as many rows as keep a band's
                        depth, winner and colour within 384 KiB, in L2) instead of tiles, each band
                        depth-tested straight into the image's rows; on one thread without a sort pass
                        (each chunk appended to per-band buffers, 8 bytes a pixel in all, flushed when
                        full), on 2+ threads through the tile sort's counting and offsets (thread k on
                        the k-th range of bands). The same image. Off by default: on an idle machine not
                        faster than the direct z-buffer on one thread (slower at 512, -3 % to +1 % at
                        1024) and slower than the tiles on 2 (docs/BENCHMARKS.md, rc-seven and the lead's
                        idle run; bench_rcache --only bands) */
} view_rc_desc;

typedef struct view_rc view_rc;

/* What a pixel of a rendered frame shows. */
typedef enum view_rc_pixel_kind {
    VIEW_RC_EMPTY = 0,     /* nothing near: desc.clear_rgb */
    VIEW_RC_POINT = 1,     /* a cached point projected here (after z-buffer and depth cull) */
    VIEW_RC_INTERP = 2,    /* no point here; the 3x3 weighted mean of the neighbours' points */
    VIEW_RC_PREFILTER = 3, /* no point within 3x3; the 7x7 uniform mean */
    VIEW_RC_PIXEL_KINDS = 4
} view_rc_pixel_kind;

/* A pixel of a camera's image (the request the client sends; x < width, y < height). */
typedef struct view_rc_pixel {
    uint16_t x, y;
} view_rc_pixel;

/* A sample the server rendered: pixel (x, y) of some camera's width x height image, its sRGB colour and its
 * depth (distance along the primary ray through the pixel centre, metres; +inf for the sky). */
typedef struct view_rc_sample {
    uint16_t x, y;
    uint8_t rgb[3];
    float depth;
} view_rc_sample;

/* The stages of a frame, in the order they run, with the 2002 paper's names. */
#define VIEW_RC_STAGES(X)                                                                                    \
    X(VIEW_RC_STAGE_UPDATE, "update points") /* inserts since the previous frame */                          \
    X(VIEW_RC_STAGE_PREDICT_PROJECT, "predicted projection")                                                 \
    X(VIEW_RC_STAGE_PREDICT_SAMPLE, "predicted sampling")                                                    \
    X(VIEW_RC_STAGE_PROJECT_SORT,                                                                            \
      "project and tile sort") /* no_tiling: projection only; one thread: with   \
                                                            * the z-buffer (not tiled_one_thread) */                           \
    X(VIEW_RC_STAGE_ZBUFFER, "z-buffer tiles")                                                               \
    X(VIEW_RC_STAGE_PIXELS, "cull + interpolate + prefilter (fused)") /* the next three, by bands */         \
    X(VIEW_RC_STAGE_DEPTH_CULL, "depth cull")                                                                \
    X(VIEW_RC_STAGE_INTERPOLATE, "interpolate / smooth") /* and the priority image */                        \
    X(VIEW_RC_STAGE_PREFILTER, "prefilter")                                                                  \
    X(VIEW_RC_STAGE_SAMPLE, "sampling")                                                                      \
    X(VIEW_RC_STAGE_AGE, "age and evict")                                                                    \
    X(VIEW_RC_STAGE_SAMPLE_AGE, "sampling + age (one run)") /* 2+ threads: both above in one pool run */

typedef enum view_rc_stage {
#define VIEW_RC_STAGE_ENUM(name, text) name,
    VIEW_RC_STAGES(VIEW_RC_STAGE_ENUM)
#undef VIEW_RC_STAGE_ENUM
        VIEW_RC_STAGE_COUNT
} view_rc_stage;

/* The name of a stage ("unknown" outside the table). */
const char *view_rc_stage_name(int stage);

/* A frame's figures. "Since the previous frame" counts what the inserts did between the two renders. */
typedef struct view_rc_stats {
    uint32_t points;     /* live points after the frame */
    uint32_t inserted;   /* points inserted since the previous frame */
    uint32_t superseded; /* cached points replaced by a new sample of their place, since the previous frame */
    uint32_t dropped;    /* points dropped to keep the cache within capacity (oldest first) */
    uint64_t dropped_age_sum; /* the sum of their ages */
    uint32_t evicted;         /* points that reached age 255 in this frame */
    uint32_t projected;       /* points that landed in the image */
    uint32_t migrated;        /* points that moved to another tile's list (new points not counted) */
    uint32_t culled;          /* pixels whose point the depth cull removed */
    uint32_t pixels[VIEW_RC_PIXEL_KINDS]; /* pixels by kind */
    uint32_t age_step;                    /* the age added to visible points in this frame */
    uint32_t hidden_age_step;             /* ... and to points not visible */
    double stage_ms[VIEW_RC_STAGE_COUNT]; /* wall time of each stage (update: of the inserts since the
                                             previous frame), milliseconds */
    double total_ms;                      /* the whole view_rc_render call */
} view_rc_stats;

/* A rendered frame. The arrays belong to the cache and stay valid until the next view_rc_render,
 * view_rc_insert_* or view_rc_destroy. Images are width x height, top row first. */
typedef struct view_rc_frame {
    uint32_t width, height;
    const uint8_t *rgb;      /* 3 bytes per pixel, sRGB8 */
    const float *depth;      /* POINT pixels: distance along the ray through the pixel centre to the plane of
                                the point (metres; +inf for sky points); NaN elsewhere */
    const uint8_t *kind;     /* view_rc_pixel_kind */
    const uint8_t *priority; /* 0..255: a point's age, or 255 - 16 * (points among the 8 neighbours) */
    const view_rc_pixel
        *requests; /* pixels of the current camera to render, in scanline order within bands */
    uint32_t request_count;
    const view_rc_pixel *predicted_requests; /* pixels of the predicted camera to render */
    uint32_t predicted_count;
    view_rc_stats stats;
} view_rc_frame;

/* A cached point, for inspection (view_rc_points). */
typedef struct view_rc_point {
    double position[3]; /* world coordinates, metres (sky points at VIEW_RC_SKY_DISTANCE from their camera) */
    uint8_t rgb[3];
    uint8_t age; /* 0..254 */
} view_rc_point;

/* Creates a cache for width x height client frames. Returns FXC_OK and *out, or FXC_ERR_INVALID (a size or a
 * parameter out of range: out NULL, sizes 0 or above VIEW_RC_MAX_SIDE, threads above 64, a ratio negative or
 * not finite, hidden_age_factor below 1, a budget above width * height, a capacity whose arrays would not fit
 * in size_t), FXC_ERR_NOMEM or FXC_ERR_THREADS. */
fxc_result view_rc_create(const view_rc_desc *desc, view_rc **out);

/* Frees everything (NULL is ignored). */
void view_rc_destroy(view_rc *rc);

/* The description with every default filled in. */
view_rc_desc view_rc_resolved_desc(const view_rc *rc);

/* Bytes allocated by view_rc_create (the whole cache: points, images, threads' scratch). */
size_t view_rc_memory_bytes(const view_rc *rc);

/* Inserts a whole frame the server rendered with camera cam: width x height pixels of rgb (3 bytes each) and
 * depth (metres along the primary ray, +inf for the sky; NaN or <= 0 skips the pixel). Every cached point the
 * frame saw (projected into one of its pixels, not behind that pixel's depth by more than supersede_ratio) is
 * replaced. The new points show from the next view_rc_render on. When the free slots run short, the oldest
 * points make room on the spot. Returns FXC_OK, FXC_ERR_INVALID (NULL arrays, a size of 0 or above
 * VIEW_RC_MAX_SIDE), FXC_ERR_CAMERA (cam not valid) or FXC_ERR_RANGE (more pixels than the capacity). */
fxc_result view_rc_insert_frame(view_rc *rc, const view_rc_camera *cam, uint32_t width, uint32_t height,
                                const uint8_t *rgb, const float *depth);

/* Inserts count samples of camera cam's width x height image (an answer to a request). A sample replaces the
 * point the previous frame showed at its place when that point is not behind it by more than supersede_ratio
 * (nothing is replaced before the first frame, nor after a whole frame or room made on the spot since the
 * last frame: the last frame's winners may be gone), and when its colour differs by more than
 * change_threshold the neighbours of that place age by change_penalty. Samples outside the image or with a
 * depth that is NaN or <= 0 are skipped. Returns FXC_OK, FXC_ERR_INVALID, FXC_ERR_CAMERA or FXC_ERR_RANGE
 * (more samples than the capacity). */
fxc_result view_rc_insert_samples(view_rc *rc, const view_rc_camera *cam, uint32_t width, uint32_t height,
                                  const view_rc_sample *samples, uint32_t count);

/* Renders one client frame for camera cam. predicted (may be NULL: no prediction this frame) is where the
 * camera is expected to be when the requested samples come back; predicted requests are pixels of that
 * camera. *out receives the frame (arrays owned by the cache). Returns FXC_OK, FXC_ERR_INVALID or
 * FXC_ERR_CAMERA. */
fxc_result view_rc_render(view_rc *rc, const view_rc_camera *cam, const view_rc_camera *predicted,
                          view_rc_frame *out);

/* Live points (placed and waiting to be placed). */
uint32_t view_rc_point_count(const view_rc *rc);

/* Copies up to count live points starting at the first-th (store order, which changes every frame) into out;
 * returns how many were copied. */
uint32_t view_rc_points(const view_rc *rc, uint32_t first, uint32_t count, view_rc_point *out);

/* The error-diffusion dither on its own, as view_rc_render uses it: chooses exactly count pixels of a
 * width x height priority image (count at most width * height), denser where priority + 1 is larger,
 * processed in independent bands of band_height rows (0: one band) whose shares of count are proportional to
 * their priority, each band a serpentine Floyd-Steinberg pass over priority + 1 scaled to its share, then
 * trimmed or topped up by priority to its exact share. Writes the pixels to out (count entries, scanline
 * order within each band, bands top to bottom). scratch must hold view_rc_dither_scratch_bytes(width, height)
 * bytes. Returns FXC_OK or FXC_ERR_INVALID. */
fxc_result view_rc_dither(const uint8_t *priority, uint32_t width, uint32_t height, uint32_t band_height,
                          uint32_t count, view_rc_pixel *out, void *scratch, size_t scratch_bytes);
size_t view_rc_dither_scratch_bytes(uint32_t width, uint32_t height);

#endif
