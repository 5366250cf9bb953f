/* What every effect shares: the effect descriptions the frame loop reads (bytes per texel, level bias,
 * filter, policy), the mapping from a point of island UV to the surface (through the triangle lookup, kept
 * inside the triangle by a margin: fx_internal.h "surface points"), and the direction towards a light. */
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

/* Fills the world part of map for scene triangle tri: corners, edges, the dual vectors that give barycentrics
 * of a point in its plane, the normal, and the barycentric margins that keep points `margin` metres inside
 * every edge (raised to the robust distance of its corners when positive). */
void fx__triangle_map_init(const scene *s, uint32_t tri, float margin, fx__surface_map *map)
{
    FX_ASSERT(tri < s->triangle_count);
    const uint32_t *corner = s->indices + 3 * (size_t)tri;
    const float *p0 = s->positions + 3 * (size_t)corner[0], *p1 = s->positions + 3 * (size_t)corner[1],
                *p2 = s->positions + 3 * (size_t)corner[2];
    double e11 = 0, e12 = 0, e22 = 0;
    for (int k = 0; k < 3; k++) {
        map->origin[k] = p0[k];
        map->edge1[k] = (double)p1[k] - p0[k];
        map->edge2[k] = (double)p2[k] - p0[k];
        map->normal[k] = s->tri_normal[3 * (size_t)tri + k];
        e11 += map->edge1[k] * map->edge1[k];
        e12 += map->edge1[k] * map->edge2[k];
        e22 += map->edge2[k] * map->edge2[k];
    }
    /* Gram determinant = (twice the area)^2; the builder drops triangles without area. */
    double gram = e11 * e22 - e12 * e12;
    for (int k = 0; k < 3; k++) {
        map->dual1[k] = gram > 0 ? (e22 * map->edge1[k] - e12 * map->edge2[k]) / gram : 0.0;
        map->dual2[k] = gram > 0 ? (e11 * map->edge2[k] - e12 * map->edge1[k]) / gram : 0.0;
    }
    map->min_weight[0] = map->min_weight[1] = map->min_weight[2] = 0.0;
    if (margin > 0) {
        margin = fmaxf(margin, fmaxf(fx__robust_distance(p0, s->ray_offset_scale),
                                     fmaxf(fx__robust_distance(p1, s->ray_offset_scale),
                                           fx__robust_distance(p2, s->ray_offset_scale))));
        /* Weight k is the distance from the edge opposite corner k over corner k's altitude, 2 area / |edge|.
         */
        double twice_area = sqrt(gram > 0 ? gram : 0.0);
        double opposite[3] = {0, sqrt(e22), sqrt(e11)};
        double e21 = 0;
        for (int k = 0; k < 3; k++)
            e21 += (map->edge2[k] - map->edge1[k]) * (map->edge2[k] - map->edge1[k]);
        opposite[0] = sqrt(e21);
        double sum = 0;
        for (int k = 0; k < 3; k++) {
            map->min_weight[k] = twice_area > 0 ? (double)margin * opposite[k] / twice_area : 1.0;
            sum += map->min_weight[k];
        }
        /* Too small for the margin: the shrunk triangle is its incentre (weights in proportion to the edges
         * opposite the corners), where every point goes. */
        if (!(sum < 1.0))
            for (int k = 0; k < 3; k++)
                map->min_weight[k] /= sum;
    }
}

void fx__surface_map_init(const scene *s, uint32_t island, uint32_t lookup, float margin,
                          fx__surface_map *map)
{
    FX_ASSERT(island < s->island_count);
    const scene_island *isl = &s->islands[island];
    uint32_t local = lookup & 0xffu;
    FX_ASSERT(local < isl->triangle_count);
    uint32_t tri = s->island_triangles[isl->first + local];
    fx__triangle_map_init(s, tri, margin, map);
    const float *uv = s->tri_island_uv + 6 * (size_t)tri;
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

void fx__surface_map_eval_bary(const fx__surface_map *map, double w1, double w2, float position[3])
{
    double w0 = 1.0 - w1 - w2;
    const double *m = map->min_weight;
    if (!(w0 >= m[0] && w1 >= m[1] && w2 >= m[2])) {
        /* Outside the shrunk triangle (or NaN): in its own barycentrics (it is the triangle scaled by
         * `inner` towards the margins' point), clamp negative weights to zero and renormalise, the centre if
         * nothing is left; then back. With zero margins this is the plain clamp into the triangle. */
        double inner = 1.0 - (m[0] + m[1] + m[2]);
        double a0 = 1.0 / 3.0, a1 = 1.0 / 3.0, a2 = 1.0 / 3.0;
        if (inner > 0) {
            a0 = (w0 - m[0]) / inner;
            a1 = (w1 - m[1]) / inner;
            a2 = (w2 - m[2]) / inner;
            a0 = a0 > 0 ? a0 : 0.0;
            a1 = a1 > 0 ? a1 : 0.0;
            a2 = a2 > 0 ? a2 : 0.0;
            double sum = a0 + a1 + a2;
            if (sum > 0) {
                a1 /= sum;
                a2 /= sum;
            } else {
                a1 = a2 = 1.0 / 3.0;
            }
        } else {
            inner = 0; /* the margins' point (the incentre) only */
        }
        w1 = m[1] + inner * a1;
        w2 = m[2] + inner * a2;
    }
    for (int k = 0; k < 3; k++)
        position[k] = (float)(map->origin[k] + w1 * map->edge1[k] + w2 * map->edge2[k]);
}

void fx__surface_map_eval(const fx__surface_map *map, float island_u, float island_v, float position[3])
{
    double du = (double)island_u - map->uv_origin[0], dv = (double)island_v - map->uv_origin[1];
    double w1 = map->fallback[0] + du * map->to_w1[0] + dv * map->to_w1[1];
    double w2 = map->fallback[1] + du * map->to_w2[0] + dv * map->to_w2[1];
    fx__surface_map_eval_bary(map, w1, w2, position);
}

void fx_surface_point(const scene *s, uint32_t island, uint32_t lookup, float island_u, float island_v,
                      float position[3], float normal[3])
{
    fx__surface_map map;
    fx__surface_map_init(s, island, lookup, 0.0f, &map);
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
