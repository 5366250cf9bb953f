/* scene_inline.h: scene helpers that hot loops inline (so they are compiled into each FXC_HOT_CLONES copy
 * and cost no call per ray); the out-of-line functions of scene.h run the same code. */
#ifndef FXC_SCENE_INLINE_H
#define FXC_SCENE_INLINE_H

#include "scene.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

/* scene_offset_ray_origin (scene.h; scene_rt.c calls this). */
static inline void scene_offset_ray_origin_inline(const float p[3], const float n[3], float scale,
                                                  float out[3])
{
    /* Waechter and Binder: near the origin a tiny fixed offset (float spacing is fine there); elsewhere an
     * offset of int_scale * n units in the last place, which scales with the magnitude of p. Their near-zero
     * constants are for a scene of unit size: a scene of 1 mm would be lifted by 1.5 % of its size. */
    if (!(scale > 0) || scale > 1.0f)
        scale = 1.0f;
    const float origin = scale / 32.0f, float_scale = scale / 65536.0f, int_scale = 256.0f;
    for (int k = 0; k < 3; k++) {
        int32_t offset = (int32_t)(int_scale * n[k]);
        int32_t bits; /* the float's bits as int32 and back, through memcpy */
        memcpy(&bits, &p[k], sizeof bits);
        bits += p[k] < 0 ? -offset : offset;
        float moved;
        memcpy(&moved, &bits, sizeof moved);
        out[k] = fabsf(p[k]) < origin ? p[k] + float_scale * n[k] : moved;
    }
}

#endif
