/* The shading of a probe ray's front-face hit by direct light: the shadow rays to the lights, queued per chunk
 * and traced in streams (fx__occluded), shared by the probe update (fx_probes_hits.c) and the no-cache
 * estimate (fx_probes_eval.c). Inline, so each caller's hot copy keeps it. */
#ifndef FXC_EFFECTS_PROBES_SHADING_H
#define FXC_EFFECTS_PROBES_SHADING_H

#include "fx_probes_internal.h"
#include "fxc_hot.h"

#include <math.h>
#include <string.h>

/* The shading of a chunk of hits: per primary ray, its radiance once the shadow rays are back. */
typedef struct hit_shading {
    _Alignas(64) struct RTCRay shadow[FX_RAY_BATCH];
    uint16_t owner[FX_RAY_BATCH];
    float light[FX_RAY_BATCH][3];
    uint32_t count;
    float direct[PROBE_CHUNK][3]; /* compose units (irradiance / pi) */
} hit_shading;

FXC_HOT_INLINE void shadow_flush(const fx_context *ctx, hit_shading *hs)
{
    fx__occluded(ctx, hs->shadow, hs->count);
    for (uint32_t r = 0; r < hs->count; r++)
        if (hs->shadow[r].tfar != -INFINITY)
            for (int k = 0; k < 3; k++)
                hs->direct[hs->owner[r]][k] += hs->light[r][k];
    hs->count = 0;
}

/* The directions of the first PROBE_FIXED_LIGHTS lights that are directional, once per update call: they do not
 * depend on the point (fx_light_direction's, the same floats), so the shadow-ray set-up skips the call and
 * its square root and division per hit and light. */
enum { PROBE_FIXED_LIGHTS = 16 };
typedef struct fixed_lights {
    uint32_t directional; /* bit l: light l is directional, its direction in dir[l] */
    float dir[PROBE_FIXED_LIGHTS][3];
} fixed_lights;

static inline void fixed_lights_init(const scene *s, fixed_lights *fl)
{
    fl->directional = 0;
    static const float anywhere[3] = {0, 0, 0};
    for (uint32_t l = 0; l < s->light_count && l < PROBE_FIXED_LIGHTS; l++) {
        if (s->lights[l].type != SCENE_LIGHT_DIRECTIONAL)
            continue;
        float distance;
        fx_light_direction(&s->lights[l], anywhere, fl->dir[l], &distance);
        fl->directional |= 1u << l;
    }
}

/* fx__light_arriving, for a directional light with its direction given (distance infinite, no falloff). */
FXC_HOT_INLINE bool light_arriving_fixed(const scene_light *light, const float fixed_dir[3],
                                         const float normal[3], float dir[3], float *distance, float *scale)
{
    memcpy(dir, fixed_dir, 3 * sizeof(float));
    *distance = INFINITY;
    float cosine = fx__dot(normal, dir);
    if (!(cosine > 0))
        return false;
    *scale = light->intensity * cosine * 1.0f; /* fx__light_arriving's falloff 1 */
    return *scale > 0;
}

/* Queues the shadow rays of a front-face hit (origin already offset, unit front normal) for chunk slot i;
 * returns the rays queued. Contributions are compose's: intensity x colour x cos (/ d^2 for point lights).
 * fl: the directional lights' directions (NULL: none given). */
FXC_HOT_INLINE uint32_t queue_shadow_rays(const fx_context *ctx, const fixed_lights *fl, hit_shading *hs,
                                          uint32_t i, const float origin[3], const float normal[3])
{
    const scene *s = ctx->s;
    uint32_t queued = 0;
    for (uint32_t l = 0; l < s->light_count; l++) {
        const scene_light *light = &s->lights[l];
        float dir[3], distance, scale;
        bool fixed = fl && l < PROBE_FIXED_LIGHTS && (fl->directional >> l & 1);
        if (fixed ? !light_arriving_fixed(light, fl->dir[l], normal, dir, &distance, &scale)
                  : !fx__light_arriving(light, origin, normal, dir, &distance, &scale))
            continue;
        if (hs->count == FX_RAY_BATCH)
            shadow_flush(ctx, hs);
        fx__set_ray(&hs->shadow[hs->count], origin, dir,
                    isinf(distance) ? INFINITY : distance * (1.0f - 1e-4f), hs->count);
        hs->owner[hs->count] = (uint16_t)i;
        for (int k = 0; k < 3; k++)
            hs->light[hs->count][k] = min_of(scale * light->color[k], FLT_MAX);
        hs->count++;
        queued++;
    }
    return queued;
}

#endif
