/* What every effect shares: the mapping from a point of island UV to the surface (through the triangle
 * lookup, kept inside the triangle by a margin: fx_internal.h "surface points"), locating the triangle of a
 * visible point for the no-cache baseline, and the direction towards a light. The effects' own descriptions
 * are their tables (effects.h). */
#include "fx_internal.h"

#include <string.h>

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

/* ---- locating a visible point's triangle (the no-cache baseline) ---------------------------------- */

/* What the point query looks for and what it found. */
typedef struct locate_query {
    const scene *s;
    double point[3];
    float normal[3];
    uint32_t best_tri; /* UINT32_MAX: none yet */
    double best_d2;    /* squared distance to it */
    /* The same for triangles facing against the normal: a point seen from behind its triangle (the normal
     * passed is the side the viewer sees), taken only when no triangle faces along it. */
    uint32_t back_tri;
    double back_d2;
} locate_query;

/* Squared distance from p to triangle (a, b, c), in double (Ericson, Real-Time Collision Detection 5.1.5). */
static double triangle_distance2(const double p[3], const float *a, const float *b, const float *c)
{
    double ab[3], ac[3], ap[3];
    for (int k = 0; k < 3; k++) {
        ab[k] = (double)b[k] - a[k];
        ac[k] = (double)c[k] - a[k];
        ap[k] = p[k] - a[k];
    }
#define FX_DOT3(x, y) ((x)[0] * (y)[0] + (x)[1] * (y)[1] + (x)[2] * (y)[2])
    double d1 = FX_DOT3(ab, ap), d2 = FX_DOT3(ac, ap), v, w;
    if (d1 <= 0 && d2 <= 0) {
        v = w = 0; /* corner a */
    } else {
        double bp[3], cp[3];
        for (int k = 0; k < 3; k++) {
            bp[k] = p[k] - b[k];
            cp[k] = p[k] - c[k];
        }
        double d3 = FX_DOT3(ab, bp), d4 = FX_DOT3(ac, bp), d5 = FX_DOT3(ab, cp), d6 = FX_DOT3(ac, cp);
        double vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
        if (d3 >= 0 && d4 <= d3) {
            v = 1, w = 0; /* corner b */
        } else if (d6 >= 0 && d5 <= d6) {
            v = 0, w = 1; /* corner c */
        } else if (vc <= 0 && d1 >= 0 && d3 <= 0) {
            v = d1 / (d1 - d3), w = 0; /* edge ab */
        } else if (vb <= 0 && d2 >= 0 && d6 <= 0) {
            v = 0, w = d2 / (d2 - d6); /* edge ac */
        } else if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
            w = (d4 - d3) / ((d4 - d3) + (d5 - d6)); /* edge bc */
            v = 1 - w;
        } else {
            double denom = 1.0 / (va + vb + vc); /* inside */
            v = vb * denom;
            w = vc * denom;
        }
    }
#undef FX_DOT3
    double d2sum = 0;
    for (int k = 0; k < 3; k++) {
        double q = a[k] + v * ab[k] + w * ac[k] - p[k];
        d2sum += q * q;
    }
    return d2sum;
}

/* Embree's point-query callback: keeps the nearest triangle facing along the query's normal, and apart the
 * nearest facing against it (ties: the lower index, so the answer does not depend on the traversal order).
 * The radius is never shrunk. */
static bool locate_callback(struct RTCPointQueryFunctionArguments *args)
{
    locate_query *q = args->userPtr;
    uint32_t tri = args->primID;
    const scene *s = q->s;
    if (tri >= s->triangle_count)
        return false;
    float facing = fx__dot(s->tri_normal + 3 * (size_t)tri, q->normal);
    bool along = facing > 0.906f;
    if (!along && !(facing < -0.906f))
        return false; /* more than 25 degrees off: another surface (the wall at a crease) */
    const uint32_t *corner = s->indices + 3 * (size_t)tri;
    double d2 =
        triangle_distance2(q->point, s->positions + 3 * (size_t)corner[0],
                           s->positions + 3 * (size_t)corner[1], s->positions + 3 * (size_t)corner[2]);
    double radius = args->query->radius;
    uint32_t *best_tri = along ? &q->best_tri : &q->back_tri;
    double *best_d2 = along ? &q->best_d2 : &q->back_d2;
    if (d2 <= radius * radius && (d2 < *best_d2 || (d2 == *best_d2 && tri < *best_tri))) {
        *best_d2 = d2;
        *best_tri = tri;
    }
    return false;
}

bool fx__locate_point(const fx_context *ctx, const float pos[3], const float normal[3], float margin,
                      fx__surface_map *map, float settled[3])
{
    const scene *s = ctx->s;
    float reach = fx__robust_distance(pos, s->ray_offset_scale);
    locate_query q = {
        .s = s, .best_tri = UINT32_MAX, .best_d2 = INFINITY, .back_tri = UINT32_MAX, .back_d2 = INFINITY};
    for (int k = 0; k < 3; k++) {
        q.point[k] = pos[k];
        q.normal[k] = normal[k];
        settled[k] = pos[k];
    }
    _Alignas(16) struct RTCPointQuery query = {
        .x = pos[0], .y = pos[1], .z = pos[2], .time = 0, .radius = reach};
    _Alignas(16) struct RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    rtcPointQuery((RTCScene)scene_rt_handle(ctx->rt), &query, &context, locate_callback, &q);
    /* A triangle facing against the normal wins when it is nearer: the point seen from behind its own triangle
     * (normal the side the viewer sees) lies on it, and a neighbour facing along the normal (a mesh with one
     * triangle wound the other way: the Stanford dragon's) can lie under it; moved into that neighbour, the
     * point's rays all met the triangle it was on (black pixels in the reference). On a tie, along. */
    if (q.best_tri == UINT32_MAX || q.back_d2 < q.best_d2)
        q.best_tri = q.back_tri; /* (nothing facing either way: none) */
    if (q.best_tri == UINT32_MAX)
        return false;
    fx__triangle_map_init(s, q.best_tri, fmaxf(margin, reach), map);
    double w1, w2;
    fx__surface_map_bary(map, pos, &w1, &w2);
    fx__surface_map_eval_bary(map, w1, w2, settled);
    return true;
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
