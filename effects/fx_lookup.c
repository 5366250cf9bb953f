/* Triangle lookup: which island triangle each texel centre lies in, and where (DESIGN.md "Effects"). It is
 * the first effect of every block (frame stage 5): shadows and AO map their sample points through it.
 *
 * Inside test: exact. Island UVs are multiples of 1/256 texel below 32768 (scene_islands.c) and texel
 * centres are multiples of 1/2, so every edge function below is computed exactly in double (products of
 * integers below 2^23 times 2^-16). Points on a shared edge go to exactly one triangle by the top-left rule
 * (the one the island tests use), so the result never depends on the order the triangles are visited.
 * Texel centres inside no triangle (the island border, gaps) take the triangle whose closest point in UV is
 * nearest (ties: the lower island-local index) and the barycentrics of that closest point (conservative).
 *
 * Cost: per block, the triangles whose UV bounding box touches the block are gathered once; texels are tested
 * against those only, and only texels inside none of them scan every triangle of the island (<= 256). */
#include "fx_internal.h"

#include <string.h>

/* Quantization steps of a barycentric coordinate (12 bits). */
#define FX_LOOKUP_STEPS 4095.0f

/* One island triangle prepared for tests: corners in counter-clockwise order (swapped when stored clockwise).
 */
typedef struct lookup_triangle {
    double corner[3][2];
    double twice_area; /* > 0 for a usable triangle */
    bool swapped;      /* corners 1 and 2 were swapped to make it counter-clockwise */
    uint32_t local;    /* index inside the island */
} lookup_triangle;

uint32_t fx_lookup_pack(uint32_t tri_local, float u, float v)
{
    FX_ASSERT(tri_local < SCENE_ISLAND_MAX_TRIANGLES);
    /* NaN and out-of-range inputs saturate into [0, 1] (fmaxf/fminf return the number for a NaN input). */
    float cu = fminf(fmaxf(u, 0.0f), 1.0f), cv = fminf(fmaxf(v, 0.0f), 1.0f);
    float su = cu * FX_LOOKUP_STEPS, sv = cv * FX_LOOKUP_STEPS;
    uint32_t qu = (uint32_t)lrintf(su), qv = (uint32_t)lrintf(sv);
    if (qu + qv > 4095u) {
        /* Both rounded up past the edge u + v = 1: take back the step from the one rounded up more. */
        if ((float)qu - su >= (float)qv - sv)
            qu--;
        else
            qv--;
    }
    return tri_local | (qu << 8) | (qv << 20);
}

void fx_lookup_unpack(uint32_t texel, uint32_t *tri_local, float *u, float *v)
{
    *tri_local = texel & 0xffu;
    *u = (float)((texel >> 8) & 0xfffu) * (1.0f / FX_LOOKUP_STEPS);
    *v = (float)(texel >> 20) * (1.0f / FX_LOOKUP_STEPS);
}

/* Twice the signed area of (a, b, p): positive when p is left of a->b. */
static double edge_function(const double a[2], const double b[2], double px, double py)
{
    return (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0]);
}

/* Whether points exactly on edge a->b of a counter-clockwise triangle belong to it: the top-left rule. */
static bool edge_owns_ties(const double a[2], const double b[2])
{
    double dx = b[0] - a[0], dy = b[1] - a[1];
    return dy < 0 || (dy == 0 && dx > 0);
}

/* Prepares island triangle `local` of island for the tests. */
static void prepare_triangle(const scene *s, const scene_island *island, uint32_t local, lookup_triangle *out)
{
    uint32_t tri = s->island_triangles[island->first + local];
    const float *uv = s->tri_island_uv + 6 * (size_t)tri;
    for (int k = 0; k < 3; k++) {
        out->corner[k][0] = uv[2 * k];
        out->corner[k][1] = uv[2 * k + 1];
    }
    out->local = local;
    out->twice_area = edge_function(out->corner[0], out->corner[1], out->corner[2][0], out->corner[2][1]);
    out->swapped = out->twice_area < 0;
    if (out->swapped) {
        double keep[2] = {out->corner[1][0], out->corner[1][1]};
        memcpy(out->corner[1], out->corner[2], sizeof keep);
        memcpy(out->corner[2], keep, sizeof keep);
        out->twice_area = -out->twice_area;
    }
}

/* Exact inside test with the top-left tie rule; on success the barycentrics of corners 1 and 2 (as stored).
 */
static bool triangle_contains(const lookup_triangle *t, double px, double py, float *u, float *v)
{
    if (!(t->twice_area > 0))
        return false;
    double w[3]; /* w[k]: edge function of the edge opposite corner k */
    for (int k = 0; k < 3; k++) {
        const double *a = t->corner[(k + 1) % 3], *b = t->corner[(k + 2) % 3];
        w[k] = edge_function(a, b, px, py);
        if (w[k] < 0 || (w[k] == 0 && !edge_owns_ties(a, b)))
            return false;
    }
    double bu = w[1] / t->twice_area, bv = w[2] / t->twice_area;
    *u = (float)(t->swapped ? bv : bu);
    *v = (float)(t->swapped ? bu : bv);
    return true;
}

/* Squared UV distance from p to the triangle's boundary and the barycentrics (as stored) of the closest
 * boundary point. Used only for points inside no triangle, so the boundary holds the closest point. */
static double triangle_closest(const lookup_triangle *t, double px, double py, float *u, float *v)
{
    double best = INFINITY, weight[3] = {1.0, 0.0, 0.0};
    for (int k = 0; k < 3; k++) {
        const double *a = t->corner[k], *b = t->corner[(k + 1) % 3];
        double ex = b[0] - a[0], ey = b[1] - a[1], len2 = ex * ex + ey * ey;
        double param = len2 > 0 ? ((px - a[0]) * ex + (py - a[1]) * ey) / len2 : 0.0;
        param = fmin(fmax(param, 0.0), 1.0);
        double dx = a[0] + param * ex - px, dy = a[1] + param * ey - py, d2 = dx * dx + dy * dy;
        if (d2 < best) {
            best = d2;
            weight[0] = weight[1] = weight[2] = 0.0;
            weight[k] = 1.0 - param;
            weight[(k + 1) % 3] = param;
        }
    }
    *u = (float)(t->swapped ? weight[2] : weight[1]);
    *v = (float)(t->swapped ? weight[1] : weight[2]);
    return best;
}

void fx_lookup_update(const scene *s, uint32_t island, uint32_t level, uint32_t block_x, uint32_t block_y,
                      uint64_t mask, uint32_t texels[64])
{
    FX_ASSERT(island < s->island_count && level < 16);
    if (mask == 0)
        return;
    const scene_island *isl = &s->islands[island];
    FX_ASSERT(isl->triangle_count >= 1 && isl->triangle_count <= SCENE_ISLAND_MAX_TRIANGLES);

    /* The texel centres of the block span this box (level-0 UV); gather the triangles touching it. */
    double scale = (double)(1u << level);
    double box_min_u = ((double)block_x * SCENE_BLOCK_TEXELS + 0.5) * scale;
    double box_min_v = ((double)block_y * SCENE_BLOCK_TEXELS + 0.5) * scale;
    double box_max_u = box_min_u + 7.0 * scale, box_max_v = box_min_v + 7.0 * scale;
    lookup_triangle candidates[SCENE_ISLAND_MAX_TRIANGLES];
    uint32_t candidate_count = 0;
    for (uint32_t local = 0; local < isl->triangle_count; local++) {
        lookup_triangle *t = &candidates[candidate_count];
        prepare_triangle(s, isl, local, t);
        double umin = fmin(t->corner[0][0], fmin(t->corner[1][0], t->corner[2][0]));
        double umax = fmax(t->corner[0][0], fmax(t->corner[1][0], t->corner[2][0]));
        double vmin = fmin(t->corner[0][1], fmin(t->corner[1][1], t->corner[2][1]));
        double vmax = fmax(t->corner[0][1], fmax(t->corner[1][1], t->corner[2][1]));
        if (umax >= box_min_u && umin <= box_max_u && vmax >= box_min_v && vmin <= box_max_v)
            candidate_count++;
    }

    for (uint64_t bits = mask; bits != 0; bits &= bits - 1) {
        uint32_t texel = (uint32_t)__builtin_ctzll(bits);
        double px = ((double)(block_x * SCENE_BLOCK_TEXELS + (texel & 7u)) + 0.5) * scale;
        double py = ((double)(block_y * SCENE_BLOCK_TEXELS + (texel >> 3)) + 0.5) * scale;
        float u = 0, v = 0;
        bool found = false;
        for (uint32_t c = 0; c < candidate_count && !found; c++) {
            if (triangle_contains(&candidates[c], px, py, &u, &v)) {
                texels[texel] = fx_lookup_pack(candidates[c].local, u, v);
                found = true;
            }
        }
        if (found)
            continue;
        /* Outside every triangle: the nearest one over the whole island (lowest index on ties). */
        double best = INFINITY;
        uint32_t best_local = 0;
        float best_u = 0, best_v = 0;
        for (uint32_t local = 0; local < isl->triangle_count; local++) {
            lookup_triangle t;
            prepare_triangle(s, isl, local, &t);
            double d2 = triangle_closest(&t, px, py, &u, &v);
            if (d2 < best) {
                best = d2;
                best_local = local;
                best_u = u;
                best_v = v;
            }
        }
        texels[texel] = fx_lookup_pack(best_local, best_u, best_v);
    }
}

/* ---- the effect table ------------------------------------------------------------------------------- */

static uint32_t lookup_texel_bytes(const scene *s)
{
    (void)s;
    return 4;
}

static uint64_t lookup_cost(const scene *s, uint32_t samples)
{
    (void)s, (void)samples;
    return 0; /* no rays */
}

static uint64_t lookup_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count,
                              uint32_t samples)
{
    (void)samples;
    for (uint32_t j = 0; j < count; j++)
        fx_lookup_update(ctx->s, jobs[j].island, jobs[j].level, jobs[j].block_x, jobs[j].block_y,
                         jobs[j].mask, jobs[j].payload);
    return 0;
}

/* The triangle lookup: located once per texel, read by every on-surface effect's update. It shades nothing
 * and decides nothing itself: it runs when an effect that depends on it runs. */
const fx_effect fx_effect_triangle_lookup = {
    .name = "triangle_lookup",
    .cache = SCENE_CACHE_ON_SURFACE,
    .level_bias = 0,
    .filter = FX_FILTER_POINT,
    .policy = FX_UPDATE_ONCE,
    .texel_bytes = lookup_texel_bytes,
    .cost = lookup_cost,
    .update = lookup_update,
};
