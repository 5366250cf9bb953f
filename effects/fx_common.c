/* What every effect shares: the mapping from a point of island UV to the surface (through the triangle
 * lookup), and the direction towards a light. The effects' own descriptions are their tables (effects.h). */
#include "fx_internal.h"

#include <string.h>

void fx__surface_map_init(const scene *s, uint32_t island, uint32_t lookup, fx__surface_map *map)
{
    FX_ASSERT(island < s->island_count);
    const scene_island *isl = &s->islands[island];
    uint32_t local = lookup & 0xffu;
    FX_ASSERT(local < isl->triangle_count);
    uint32_t tri = s->island_triangles[isl->first + local];
    const float *uv = s->tri_island_uv + 6 * (size_t)tri;
    const uint32_t *corner = s->indices + 3 * (size_t)tri;
    const float *p0 = s->positions + 3 * (size_t)corner[0], *p1 = s->positions + 3 * (size_t)corner[1],
                *p2 = s->positions + 3 * (size_t)corner[2];
    for (int k = 0; k < 3; k++) {
        map->origin[k] = p0[k];
        map->edge1[k] = (double)p1[k] - p0[k];
        map->edge2[k] = (double)p2[k] - p0[k];
        map->normal[k] = s->tri_normal[3 * (size_t)tri + k];
    }
    /* Barycentrics as an affine function of UV (in double: UVs reach 32768 texels, sub-texel offsets matter).
     */
    double ax = uv[0], ay = uv[1], e1u = (double)uv[2] - ax, e1v = (double)uv[3] - ay;
    double e2u = (double)uv[4] - ax, e2v = (double)uv[5] - ay;
    double area = e1u * e2v - e1v * e2u;
    map->uv_origin[0] = ax;
    map->uv_origin[1] = ay;
    if (area != 0) {
        map->to_w1[0] = e2v / area;
        map->to_w1[1] = -e2u / area;
        map->to_w2[0] = -e1v / area;
        map->to_w2[1] = e1u / area;
        map->fallback[0] = map->fallback[1] = 0;
    } else {
        /* No UV area (never for island triangles): every point takes the lookup's own barycentrics. */
        float lu, lv;
        fx_lookup_unpack(lookup, &local, &lu, &lv);
        map->to_w1[0] = map->to_w1[1] = map->to_w2[0] = map->to_w2[1] = 0;
        map->fallback[0] = lu;
        map->fallback[1] = lv;
    }
}

void fx__surface_map_eval(const fx__surface_map *map, float island_u, float island_v, float position[3])
{
    double du = (double)island_u - map->uv_origin[0], dv = (double)island_v - map->uv_origin[1];
    double w1 = map->fallback[0] + du * map->to_w1[0] + dv * map->to_w1[1];
    double w2 = map->fallback[1] + du * map->to_w2[0] + dv * map->to_w2[1];
    double w0 = 1.0 - w1 - w2;
    if (!(w0 >= 0 && w1 >= 0 && w2 >= 0)) {
        /* Outside (or NaN): clamp negative weights to zero and renormalise; the centroid if nothing is left.
         */
        w0 = w0 > 0 ? w0 : 0.0;
        w1 = w1 > 0 ? w1 : 0.0;
        w2 = w2 > 0 ? w2 : 0.0;
        double sum = w0 + w1 + w2;
        if (sum > 0) {
            w1 /= sum;
            w2 /= sum;
        } else {
            w1 = w2 = 1.0 / 3.0;
        }
    }
    for (int k = 0; k < 3; k++)
        position[k] = (float)(map->origin[k] + w1 * map->edge1[k] + w2 * map->edge2[k]);
}

void fx_surface_point(const scene *s, uint32_t island, uint32_t lookup, float island_u, float island_v,
                      float position[3], float normal[3])
{
    fx__surface_map map;
    fx__surface_map_init(s, island, lookup, &map);
    fx__surface_map_eval(&map, island_u, island_v, position);
    for (int k = 0; k < 3; k++)
        normal[k] = map.normal[k];
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
