/* The error accumulator of `fxcache report` (DESIGN.md "Error against run time"): a sink of the engine that
 * compares chosen frames of every viewer with a reference image of the same camera, and the on-disk cache
 * of those reference images.
 *
 *   srv_err_rmse / srv_err_psnr   the measures (below: what they are over, and the peak)
 *   srv_refcache_*                reference images, rendered ONCE per (camera, resolution, reference settings)
 *                                 with the reference renderer (server/engine/reference.h) and kept on disk as
 *                                 DIR/KEY.exr (+ _ao.exr, _shadow.exr, .png, .json), so every configuration
 *                                 that replays the same cameras, and a resumed report, reuses them
 *   srv_err_sink_*                the sink: per compared (viewer, frame) the errors, and per frame the time
 *                                 the engine spent without the sinks stage
 *
 * It lives in server/cli/ (not the engine) because it writes files (the reference cache, heat maps) and
 * serves one command; the engine only hands it frames, like the image and statistics sinks of sim.
 *
 * Measures (all in linear radiance, as compose leaves it before the tone map):
 *   RMSE  = sqrt(mean over every pixel and channel of (frame - reference)^2); sky pixels count (their error is
 *           0 in both), so the figure is per image pixel, as the reference's noise estimate is.
 *   PSNR  = 20 log10(1.0 / RMSE) dB: the peak is 1.0 in linear radiance (compose's tone map 1 - exp(-c) takes
 *           1.0 to 0.63 before the sRGB encoding; lit surfaces of the embedded scene are below 1). Over several images, the RMSE is
 *           the root of the mean of their mean squared errors (the images of one report have one size), and
 *           the PSNR is taken from that RMSE.
 *   Per term: the lit fraction of light 0 (sim's _shadow view against the reference's shadow term) and, only
 *           when no effect replaces the sky term (no probes), the AO term (sim's _ao view is the sky's
 *           visibility after every effect: with probes it is 0 wherever they light; ARCHITECTURE.md, the
 *           reference renderer). Both are fractions in [0, 1], RMSE over every pixel. */
#ifndef FXC_SERVER_ERROR_SINK_H
#define FXC_SERVER_ERROR_SINK_H

#include "engine.h"
#include "reference.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* RMSE of a against b over count values; 0 for count 0. */
double srv_err_rmse(const float *a, const float *b, size_t count);

/* The mean squared error of a against b over count values (srv_err_rmse squared). */
double srv_err_mse(const float *a, const float *b, size_t count);

/* PSNR in dB for an RMSE in linear radiance with peak 1.0: 20 log10(1 / rmse); INFINITY for 0. */
double srv_err_psnr(double rmse);

/* ---- the reference cache ------------------------------------------------------------------------------- */

/* One reference image, owned by the cache. ao is NULL when the renderer had no AO term to give, never. */
typedef struct srv_refcache_entry {
    uint64_t key;
    uint32_t width, height;
    float *radiance; /* width*height*3 linear */
    float *ao;       /* width*height: the AO term alone */
    float *shadow;   /* width*height: the lit fraction of light 0 */
    double noise_rmse;
    double render_ms; /* 0 when it was read from disk */
    char path[1024];  /* DIR/KEY (without extension) */
} srv_refcache_entry;

typedef struct srv_refcache srv_refcache;

/* A cache of reference images in folder dir (created if missing) for renderer ref; settings describes
 * everything besides the camera and size that changes a reference (scene, effects, samples, seed, bounces)
 * and goes into every key. NULL on no memory or an unwritable folder (with a line in err). */
srv_refcache *srv_refcache_create(srv_ref *ref, const char *dir, const char *settings, char *err,
                                  size_t err_cap);
void srv_refcache_free(srv_refcache *cache);

/* FNV-1a, 64 bits, over n bytes, continuing from h (SRV_FNV1A_START to begin): the reference cache's keys and
 * report's content fingerprint. */
#define SRV_FNV1A_START 0xcbf29ce484222325ull
uint64_t srv_fnv1a(uint64_t h, const void *data, size_t n);

/* The key of a camera at a size under the cache's settings: FNV-1a 64 of their exact text. */
uint64_t srv_refcache_key(const srv_refcache *cache, const srv_camera *camera, uint32_t width,
                          uint32_t height);

/* The reference image for camera at width x height: from memory, else from disk, else rendered (and written,
 * the .json last, so an interrupted write is rendered again). *rendered (may be NULL) says whether it was
 * rendered now. NULL on failure with a line in err. The entry lives as long as the cache. */
const srv_refcache_entry *srv_refcache_get(srv_refcache *cache, const srv_camera *camera, uint32_t width,
                                           uint32_t height, bool *rendered, char *err, size_t err_cap);

/* Images rendered and read from disk so far, and the processor time of the renders (ms). */
void srv_refcache_counts(const srv_refcache *cache, uint32_t *rendered, uint32_t *read, double *render_ms);

/* ---- the sink ------------------------------------------------------------------------------------------ */

/* One compared image. */
typedef struct srv_err_image {
    uint32_t frame;     /* the caller's frame number (srv_err_sink.frame) */
    const char *viewer; /* the viewer's name */
    bool steady;        /* frame >= warmup: in the configuration's figures */
    double rmse, psnr_db;
    double rmse_shadow; /* NAN: no light */
    double rmse_ao;     /* NAN: not comparable (probes replace the sky term) or no AO */
    double ref_noise;   /* the reference's noise estimate (its RMSE against the converged image) */
} srv_err_image;

typedef struct srv_err_sink_desc {
    srv_refcache *refs; /* required */
    uint32_t every;     /* frames compared: f % every == 0 (0: none of those), and last_frame */
    uint32_t last_frame;
    uint32_t warmup;            /* frames before this one are compared but not in the totals */
    bool compare_shadow;        /* the frames carry the shadow view (keep_views) and the scene has a light */
    bool compare_ao;            /* the AO view is the AO term (no effect replaces the sky) */
    const char *heatmap_viewer; /* the viewer whose last compared frame gets a heat map (NULL: none) */
    const char *heatmap_path;   /* PNG: per pixel |frame - reference|, mean over channels */
    float heatmap_max;          /* the error shown white (default 0.1) */
    /* Called for every compared image (may be NULL), from the thread running the frame. */
    void (*on_image)(void *user, const srv_err_image *image);
    void *user;
} srv_err_sink_desc;

/* What the sink summed over the steady-state frames. */
typedef struct srv_err_totals {
    uint32_t images; /* compared images, steady state */
    double mse_sum;  /* sum of their mean squared errors */
    double mse_shadow_sum, mse_ao_sum;
    double noise2_sum;      /* sum of the references' noise squared */
    uint32_t frames;        /* steady-state frames timed */
    double ms_sum;          /* sum over them of frame_ms minus the sinks stage */
    double cpu_ms_sum;      /* process CPU time of those frames minus what the sink itself used
                                        (filled by the caller through srv_err_sink_add_cpu) */
    uint64_t viewer_frames; /* sum over them of the viewers rendered */
    uint64_t effect_rays;   /* sum over them of every effect's rays */
    uint32_t images_all;    /* compared images, warm-up included */
    char error[512];        /* the first failure (reference or heat map), "" if none */
} srv_err_totals;

typedef struct srv_err_sink {
    srv_err_sink_desc desc;
    uint32_t frame; /* the caller's frame number of the frame about to run (set before srv_loop_frame):
                           what is compared, timed and named uses it, not the loop's own count, so a run may
                           skip frames (the no-cache baseline keeps no state between frames) */
    srv_err_totals totals;
    double sink_cpu_ms; /* process CPU time spent inside this frame's viewer_frame calls */
} srv_err_sink;

/* Sets up a sink (no allocation); srv_err_sink_sink gives the srv_sink to register. */
void srv_err_sink_init(srv_err_sink *sink, const srv_err_sink_desc *desc);
srv_sink srv_err_sink_sink(srv_err_sink *sink);

/* The caller measured a frame's process CPU time around srv_loop_frame: adds it, less what the sink used,
 * for a steady-state frame. Call after srv_loop_frame. */
void srv_err_sink_add_cpu(srv_err_sink *sink, uint32_t frame, double frame_cpu_ms);

/* The process's CPU time in ms (all threads). */
double srv_err_cpu_ms(void);

/* Writes a heat map PNG of per-pixel |a - b| (mean over the 3 channels), `max` shown white, through a
 * black-red-yellow-white ramp. 0, or -1 with msg. */
int srv_err_heatmap(const char *path, const float *a, const float *b, uint32_t width, uint32_t height,
                    float max, char *msg, size_t msg_cap);

#endif
