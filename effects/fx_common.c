/* What every effect shares: the effect descriptions the frame loop reads (bytes per texel, level bias,
 * filter, policy), the mapping from a point of island UV to the surface (through the triangle lookup), and the
 * direction towards a light. */
#include "fx_internal.h"

#include <string.h>

fx_info fx_describe(uint32_t id, const scene *s)
{
    fx_info info;
    memset(&info, 0, sizeof info);
    info.id = id;
    switch (id) {
    case FX_TRI_LOOKUP:
        info.name = "triangle_lookup";
        info.texel_bytes = 4;
        info.level_bias = 0;
        info.filter = FX_FILTER_POINT;
        info.policy = FX_UPDATE_ONCE;
        break;
    case FX_SHADOW: {
        uint32_t lights = s ? s->light_count : 0;
        info.name = "shadow";
        info.texel_bytes = 2 * (lights > 0 ? lights : 1);
        info.level_bias = 0; /* hard shadow edges are high frequency */
        info.filter = FX_FILTER_BILINEAR;
        info.policy = FX_UPDATE_ONCE;
        break;
    }
    case FX_AO:
        info.name = "ao";
        info.texel_bytes = 4;
        info.level_bias = 1; /* low frequency: one level coarser */
        info.filter = FX_FILTER_BILINEAR;
        info.policy = FX_UPDATE_PROGRESSIVE;
        break;
    default:
        info.name = "unknown";
        break;
    }
    return info;
}

void fx_surface_point(const scene *s, uint32_t island, uint32_t lookup, float island_u, float island_v,
                      float position[3], float normal[3])
{
    FX_ASSERT(island < s->island_count);
    const scene_island *isl = &s->islands[island];
    uint32_t local = lookup & 0xffu;
    FX_ASSERT(local < isl->triangle_count);
    uint32_t tri = s->island_triangles[isl->first + local];
    const float *uv = s->tri_island_uv + 6 * (size_t)tri;

    /* Barycentrics of (island_u, island_v) in double (UVs reach 32768 texels, sub-texel offsets matter). */
    double ax = uv[0], ay = uv[1], bx = uv[2], by = uv[3], cx = uv[4], cy = uv[5];
    double px = island_u, py = island_v;
    double area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
    double w[3];
    if (area != 0 && isfinite(px) && isfinite(py)) {
        w[1] = ((px - ax) * (cy - ay) - (py - ay) * (cx - ax)) / area;
        w[2] = ((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / area;
        w[0] = 1.0 - w[1] - w[2];
    } else {
        /* No usable UV area (never for island triangles) or a bad point: the lookup's own barycentrics. */
        float lu, lv;
        fx_lookup_unpack(lookup, &local, &lu, &lv);
        w[1] = lu;
        w[2] = lv;
        w[0] = 1.0 - lu - lv;
    }
    /* Clamp into the triangle: negative weights to zero, then renormalise. */
    double sum = 0;
    for (int k = 0; k < 3; k++) {
        w[k] = w[k] > 0 ? w[k] : 0.0;
        sum += w[k];
    }
    if (!(sum > 0)) {
        w[0] = w[1] = w[2] = 1.0 / 3.0;
        sum = 1.0;
    }
    const uint32_t *corner = s->indices + 3 * (size_t)tri;
    for (int k = 0; k < 3; k++) {
        double p = 0;
        for (int c = 0; c < 3; c++)
            p += w[c] / sum * (double)s->positions[3 * (size_t)corner[c] + k];
        position[k] = (float)p;
        normal[k] = s->tri_normal[3 * (size_t)tri + k];
    }
}

void fx_light_direction(const scene_light *light, const float pos[3], float dir[3], float *distance)
{
    if (light->type == SCENE_LIGHT_DIRECTIONAL) {
        float len = sqrtf(fx__dot(light->direction, light->direction));
        float inv = len > 0 ? 1.0f / len : 0.0f;
        for (int k = 0; k < 3; k++)
            dir[k] = -light->direction[k] * inv;
        *distance = INFINITY;
        return;
    }
    /* Point light: in double, so a light close to a point far from the origin keeps its direction. */
    double d[3], len2 = 0;
    for (int k = 0; k < 3; k++) {
        d[k] = (double)light->position[k] - (double)pos[k];
        len2 += d[k] * d[k];
    }
    double len = sqrt(len2);
    for (int k = 0; k < 3; k++)
        dir[k] = len > 0 ? (float)(d[k] / len) : 0.0f;
    *distance = (float)len;
}
