/* The reference renderer (DESIGN.md "Error against run time"): compose's shading model, every term computed
 * per pixel with no cache and enough samples to be converged, for measuring the error of cached frames.
 *
 *   srv_ref_create   the scene, the effects whose terms are in the image, samples per effect, seed, threads
 *   srv_ref_render   one camera at width x height: linear radiance, optionally the two half-sample images,
 *                    the AO and shadow terms alone and the display image; the image's rays, noise estimate
 *                    and mean radiance
 *
 * Shading model (server/engine/compose.c): one primary ray through each pixel centre, exactly the engine's
 * visibility pass (the same packets, so the same surface at every pixel), a miss is the sky, and a visible
 * point gets
 *     radiance = albedo x (sum over lights of E_l x cos x visibility_l + sky x sky_visibility + indirect)
 * with the albedo filtered over the pixel's footprint and the cosine and distance taken at the pixel centre,
 * as compose does. Each effect that runs contributes its term through its table's `reference` callback
 * (effects.h), in registry order, with compose's rules: shadows multiply each light's visibility (rays over
 * the pixel's footprint), AO multiplies the sky's, the probes' indirect light carries the sky and so replaces
 * the sky term, scaled by what AO left. Every term is taken on the side of the surface the viewer sees.
 *
 * Noise: every pixel is rendered twice, each half with half of every effect's samples and its own random
 * numbers; the image is the mean of the two halves, so RMSE(half 0 - half 1) / 2 estimates the standard error
 * of the image (the RMS over pixels of each pixel's standard deviation), the noise the reference adds to an
 * error measured against it.
 *
 * Determinism: every random number is a hash of (seed, frame, pixel, half, sample), every output is written
 * per pixel and the image's sums are taken in pixel order afterwards, so an image is bit-identical for any
 * thread count. */
#ifndef FXC_REFERENCE_H
#define FXC_REFERENCE_H

#include "camera.h"
#include "effects.h"
#include "engine.h"
#include "fxc_result.h"
#include "scene.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* Configuration; zero fields take the defaults beside them. */
typedef struct srv_ref_desc {
    const scene *s;                    /* required, outlives the renderer */
    scene_rt *rt;                      /* required, outlives the renderer */
    const fx_effect *const *effects;   /* the effect list (default: fx_registry()); index = effect id */
    uint32_t effect_count;             /* entries of effects (<= SRV_MAX_EFFECTS) */
    bool effect_on[SRV_MAX_EFFECTS];   /* whose terms are in the image (what the frames it is compared with
                                              ran); an effect that shades must have a reference estimator */
    uint32_t samples[SRV_MAX_EFFECTS]; /* per pixel, in the effect's reference_unit (default its
                                              reference_samples); a multiple of twice its reference_granule,
                                              as each half takes half */
    uint32_t seed;
    uint32_t threads;     /* 0 = all cores */
    uint32_t max_bounces; /* indirect paths: vertices at most (0: until Russian roulette
                                              ends them; 1: one bounce, what the no-cache baseline traces) */
} srv_ref_desc;

typedef struct srv_ref srv_ref;

/* Bytes srv_ref_render keeps per pixel of the largest image so far (triangle, barycentrics, depth, footprint,
 * three noise terms), besides the caller's outputs: for memory checks before anything is created. */
#define SRV_REF_BYTES_PER_PIXEL 32u

/* Creates a renderer. Returns FXC_OK and *out, or FXC_ERR_INVALID / FXC_ERR_EFFECTS (an effect that shades
 * without a reference estimator, samples that do not split into two halves of whole sets) / FXC_ERR_NOMEM /
 * FXC_ERR_THREADS with one line in err. */
fxc_result srv_ref_create(const srv_ref_desc *desc, srv_ref **out, char *err, size_t err_cap);
void srv_ref_free(srv_ref *ref);

/* The description with its defaults resolved (samples of every effect that runs filled in). */
const srv_ref_desc *srv_ref_desc_of(const srv_ref *ref);

/* Where an image goes, top row first; NULL members are not produced. */
typedef struct srv_ref_image {
    float *radiance; /* required: width*height*3 linear RGB, the mean of the two halves */
    float *half[2];  /* width*height*3 each: the half-sample images */
    float *ao;       /* width*height: the ambient-occlusion term alone, as sim's _ao view means it: the sky's
                         visibility the effects leave, before the probes replace the sky term (1 for the sky
                         and without AO) */
    float *shadow;   /* width*height: the lit fraction of light 0 (1 for the sky and without lights), as sim's
                         _shadow view */
    uint8_t *srgb;   /* width*height*3: the display image through compose's tone map and sRGB encoding (what
                         sim writes as PNG) */
} srv_ref_image;

/* One image's figures. */
typedef struct srv_ref_stats {
    uint64_t pixels, pixels_visible;
    uint64_t primary_rays;          /* one per pixel */
    uint64_t rays[SRV_MAX_EFFECTS]; /* per effect, both halves */
    uint64_t rays_total;            /* primary and every effect's */
    double noise_rmse;              /* RMSE(half 0 - half 1) / 2 over every pixel and channel: the
                                            standard error of `radiance` */
    double noise_rmse_visible;      /* the same over the pixels that see a surface */
    double noise_ao, noise_shadow;  /* the same for the AO and shadow terms, every pixel */
    double mean_radiance[3];        /* over every pixel */
    double render_ms;
} srv_ref_stats;

/* Progress: pixels done of the image's total. Called from the thread that called srv_ref_render only. */
typedef void (*srv_ref_progress)(void *user, uint64_t done, uint64_t total);

/* Renders one camera at width x height (1..SRV_MAX_SIDE each) into *out; `frame` only seeds the random
 * numbers (the same camera at another frame gets independent noise). progress may be NULL. Returns FXC_OK,
 * FXC_ERR_CAMERA for a degenerate camera, FXC_ERR_INVALID for a bad size or no radiance output,
 * FXC_ERR_NOMEM. */
fxc_result srv_ref_render(srv_ref *ref, const srv_camera *camera, uint32_t width, uint32_t height,
                          uint32_t frame, const srv_ref_image *out, srv_ref_stats *stats,
                          srv_ref_progress progress, void *user);

#endif
