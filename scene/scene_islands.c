/* Islands: cuts every mesh of a finished scene into charts of at most 256 triangles, each with its own
 * texture space at the scene's uniform texel density (DESIGN.md, "Islands").
 *
 * Pipeline position: scene__finalize() calls scene__build_islands() after welding and normals. The on-surface
 * cache then addresses texels as (island, x, y); effects find a surface point's texel through
 * tri_island / tri_island_uv.
 *
 * How: edge adjacency comes from OpenMesh's half-edge mesh (topology.h; triangles it refuses are split off
 * and end up alone). Charts grow in the spirit of xatlas: from the lowest-numbered unassigned triangle,
 * breadth-first across edges, within one mesh, while a candidate's normal stays within ISLAND_MIN_COS of
 * the seed's normal. Each chart is projected onto the seed's plane (basis: the seed's longest edge and
 * normal) at texel_density, so a triangle's UV area is d^2 * world area * cos(angle to the seed normal),
 * that is between 0.9 and 1.0 times d^2 * world area. A candidate is refused when its projection would
 * fold (non-positive or badly quantised area), overlap the interior of a chart triangle, or make the chart
 * wider or taller than SCENE_MAX_ISLAND_TEXELS with its border. A finished chart is then turned in its
 * plane to the direction of the convex-hull edge that gives the smallest bounding box (kept only if the
 * exact checks below still pass in the turned frame).
 *
 * Exactness: projected corners are snapped to a grid of 1/256 texel (ISLAND_SUBTEXELS) held in integers,
 * and all fold and overlap predicates are exact integer arithmetic on those snapped corners. The stored
 * float UVs are the same snapped values shifted by a whole number of grid steps (exact in float below 2^24
 * steps), so what was tested is exactly what is stored: no two triangles of an island share interior
 * points, hence no texel centre is covered twice under any consistent tie rule. Snapping moves a corner by
 * at most half a grid step, so a triangle's UV area may differ from its exact projection by about its UV
 * perimeter times 1/512 texel; a seed whose snapped projection has no area is opened by one grid step.
 *
 * Cost: O(triangles) overall with per-chart work bounded by 256 x 256 bounding-box tests; deterministic
 * (no hashing of pointers, no threads, fixed visiting order). */
#include "scene_internal.h"
#include "topology.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* A candidate joins a chart only if dot(its normal, the seed normal) >= this (about 25.8 degrees). */
#define ISLAND_MIN_COS 0.9
/* Grid steps per texel for the snapped projection. 32768 texels * 256 = 2^23 steps fit a float exactly. */
#define ISLAND_SUBTEXELS 256
/* A candidate is refused when snapping changed its projected area by more than this fraction. */
#define ISLAND_MAX_SNAP_AREA_ERROR 0.25
/* Most distinct vertices a chart of 256 triangles can have (each triangle adds at most three). */
#define ISLAND_MAX_VERTICES (3 * SCENE_ISLAND_MAX_TRIANGLES)
/* Candidate queue: the seed's three neighbours plus up to two new ones per accepted triangle, with slack. */
#define ISLAND_QUEUE_CAP (3 * SCENE_ISLAND_MAX_TRIANGLES + 8)

/* A snapped 2D point, in grid steps (1/ISLAND_SUBTEXELS texel) relative to the chart origin. */
typedef struct island_point {
    int64_t u, v;
} island_point;

/* One chart while it grows: its projection frame, its local vertices and triangles. */
typedef struct island_chart {
    double origin[3]; /* world position of the seed's first corner (grid origin) */
    double axis_u[3]; /* unit in-plane axes (u along the seed's longest edge, v = normal x u) */
    double axis_v[3];
    double normal[3];       /* unit seed normal */
    double steps_per_metre; /* texel_density * ISLAND_SUBTEXELS */

    uint32_t vertex_count;
    uint32_t vertex_id[ISLAND_MAX_VERTICES]; /* scene vertex of each local vertex */
    island_point vertex_uv[ISLAND_MAX_VERTICES];

    uint32_t triangle_count;
    uint32_t triangle_id[SCENE_ISLAND_MAX_TRIANGLES];
    uint16_t corner[SCENE_ISLAND_MAX_TRIANGLES][3]; /* local vertex of each corner */
    int64_t box[SCENE_ISLAND_MAX_TRIANGLES][4];     /* umin, vmin, umax, vmax of each triangle */
    int64_t chart_box[4];                           /* of the whole chart */
} island_chart;

/* A chart vertex in the plane (unsnapped), for the convex hull of rotate_chart(). */
typedef struct island_hull_point {
    double u, v;
    uint32_t local; /* local vertex, breaks ties so the order is total and deterministic */
} island_hull_point;

/* Scratch of one build, sized from the scene, freed at the end. */
typedef struct island_work {
    uint32_t *edge_neighbor; /* triangle_count * 3, from topology.h */
    uint32_t *visit_stamp;   /* triangle_count: 1 + chart that last queued this triangle */
    uint32_t *vertex_stamp;  /* vertex_count: 1 + chart whose local map holds this vertex */
    uint16_t *vertex_local;  /* vertex_count: local vertex index, valid when vertex_stamp matches */
    uint32_t queue[ISLAND_QUEUE_CAP];
    island_chart chart;
    /* Scratch of rotate_chart(): the chart in a rotated frame before it is accepted. */
    double plane_u[ISLAND_MAX_VERTICES], plane_v[ISLAND_MAX_VERTICES]; /* unsnapped, grid steps */
    island_hull_point sorted[ISLAND_MAX_VERTICES];
    island_hull_point hull[2 * ISLAND_MAX_VERTICES + 2];
    island_point rotated_uv[ISLAND_MAX_VERTICES];
    int64_t rotated_box[SCENE_ISLAND_MAX_TRIANGLES][4];
} island_work;

/* The bounding box (min u, min v, max u, max v) of a triangle's three grid points. */
static void triangle_box(const island_point pts[3], int64_t box[4])
{
    box[0] = box[2] = pts[0].u;
    box[1] = box[3] = pts[0].v;
    for (int k = 1; k < 3; k++) {
        box[0] = pts[k].u < box[0] ? pts[k].u : box[0];
        box[1] = pts[k].v < box[1] ? pts[k].v : box[1];
        box[2] = pts[k].u > box[2] ? pts[k].u : box[2];
        box[3] = pts[k].v > box[3] ? pts[k].v : box[3];
    }
}

/* Twice the signed area of (a, b, c) in grid steps squared; exact (|coordinates| <= 2^24). */
static int64_t orient2(island_point a, island_point b, island_point c)
{
    return (b.u - a.u) * (c.v - a.v) - (b.v - a.v) * (c.u - a.u);
}

/* Whether the open interiors of two counter-clockwise triangles intersect. Separating-axis test over the six
 * edges with weak inequalities: a shared edge or vertex separates, touching is not overlapping. Exact. */
static bool triangles_overlap(const island_point a[3], const island_point b[3])
{
    for (int edge = 0; edge < 3; edge++) {
        island_point p = a[edge], q = a[(edge + 1) % 3];
        if (orient2(p, q, b[0]) <= 0 && orient2(p, q, b[1]) <= 0 && orient2(p, q, b[2]) <= 0)
            return false;
    }
    for (int edge = 0; edge < 3; edge++) {
        island_point p = b[edge], q = b[(edge + 1) % 3];
        if (orient2(p, q, a[0]) <= 0 && orient2(p, q, a[1]) <= 0 && orient2(p, q, a[2]) <= 0)
            return false;
    }
    return true;
}

/* Projects scene vertex onto the chart plane, in grid steps, unsnapped. */
static void project_vertex(const scene *s, const island_chart *chart, uint32_t vertex, double *u, double *v)
{
    const float *p = s->positions + 3 * (size_t)vertex;
    double d[3] = {(double)p[0] - chart->origin[0], (double)p[1] - chart->origin[1],
                   (double)p[2] - chart->origin[2]};
    *u = (d[0] * chart->axis_u[0] + d[1] * chart->axis_u[1] + d[2] * chart->axis_u[2]) *
         chart->steps_per_metre;
    *v = (d[0] * chart->axis_v[0] + d[1] * chart->axis_v[1] + d[2] * chart->axis_v[2]) *
         chart->steps_per_metre;
}

/* Level-0 island side in texels (border included) for a chart extent in grid steps. */
static int64_t island_side_texels(int64_t extent_steps)
{
    return (extent_steps + ISLAND_SUBTEXELS - 1) / ISLAND_SUBTEXELS + 2;
}

/* Name of mesh m for messages. */
static const char *mesh_name(const scene *s, uint32_t m)
{
    return (s->meshes && m < s->mesh_count) ? s->meshes[m].name : "(unnamed)";
}

/* Starts a chart at seed: frame from the seed's longest edge and geometric normal, corners snapped (and
 * opened by one grid step if snapping flattened it). Fails with SCENE_ERR_RANGE when the seed alone is
 * wider or taller than an island may be at this density. */
static scene_result start_chart(const scene *s, island_work *work, uint32_t chart_index, uint32_t seed,
                                scene_error *err)
{
    island_chart *chart = &work->chart;
    const uint32_t *corner = s->indices + 3 * (size_t)seed;
    double pos[3][3];
    for (int k = 0; k < 3; k++)
        for (int c = 0; c < 3; c++)
            pos[k][c] = s->positions[3 * (size_t)corner[k] + c];

    /* The longest edge becomes the u axis, so thin triangles get tight boxes; when the seed does not fit an
     * island that way (a right triangle's legs may fit where its hypotenuse is 1.41 times too long), the other
     * edges are tried, longer first. Only a seed that fits along none of its edges is refused. */
    int order[3] = {0, 1, 2};
    double edge_len2[3];
    for (int k = 0; k < 3; k++) {
        const double *a = pos[k], *b = pos[(k + 1) % 3];
        edge_len2[k] =
            (b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]);
    }
    for (int i = 1; i < 3; i++) /* by decreasing length, the first of equal ones first (as before) */
        for (int j = i; j > 0 && edge_len2[order[j]] > edge_len2[order[j - 1]]; j--) {
            int t = order[j];
            order[j] = order[j - 1];
            order[j - 1] = t;
        }
    int first = order[0];
    double proj_u[3], proj_v[3], width = 0, height = 0, longest_width = 0, longest_height = 0;
    for (int attempt = 0; attempt < 3; attempt++) {
        first = order[attempt];
        const double *a = pos[first], *b = pos[(first + 1) % 3], *c = pos[(first + 2) % 3];
        double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                       e1[0] * e2[1] - e1[1] * e2[0]};
        double n_len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (!(n_len > 0)) { /* degenerate slipped through: use the stored normal */
            for (int k = 0; k < 3; k++)
                n[k] = s->tri_normal[3 * (size_t)seed + k];
            n_len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            if (!(n_len > 0)) {
                n[0] = n[1] = 0;
                n[2] = n_len = 1;
            }
        }
        for (int k = 0; k < 3; k++)
            chart->normal[k] = n[k] / n_len;
        /* u: the edge made orthogonal to the normal; v = normal x u (corners then run counter-clockwise). */
        double along = e1[0] * chart->normal[0] + e1[1] * chart->normal[1] + e1[2] * chart->normal[2];
        double u_axis[3] = {e1[0] - along * chart->normal[0], e1[1] - along * chart->normal[1],
                            e1[2] - along * chart->normal[2]};
        double u_len = sqrt(u_axis[0] * u_axis[0] + u_axis[1] * u_axis[1] + u_axis[2] * u_axis[2]);
        if (!(u_len > 0)) { /* all corners equal: any axis orthogonal to the normal */
            const double *nn = chart->normal;
            double helper[3] = {fabs(nn[0]) < 0.9 ? 1.0 : 0.0, fabs(nn[0]) < 0.9 ? 0.0 : 1.0, 0.0};
            double h_along = helper[0] * nn[0] + helper[1] * nn[1];
            for (int k = 0; k < 3; k++)
                u_axis[k] = helper[k] - h_along * nn[k];
            u_len = sqrt(u_axis[0] * u_axis[0] + u_axis[1] * u_axis[1] + u_axis[2] * u_axis[2]);
        }
        for (int k = 0; k < 3; k++) {
            chart->axis_u[k] = u_axis[k] / u_len;
            chart->origin[k] = a[k];
        }
        const double *nn = chart->normal, *uu = chart->axis_u;
        chart->axis_v[0] = nn[1] * uu[2] - nn[2] * uu[1];
        chart->axis_v[1] = nn[2] * uu[0] - nn[0] * uu[2];
        chart->axis_v[2] = nn[0] * uu[1] - nn[1] * uu[0];
        chart->steps_per_metre = (double)s->texel_density * ISLAND_SUBTEXELS;

        /* Unsnapped corners in texels, to check the size before anything is converted to integers. */
        double umin = INFINITY, vmin = INFINITY, umax = -INFINITY, vmax = -INFINITY;
        for (int k = 0; k < 3; k++) {
            project_vertex(s, chart, corner[(first + k) % 3], &proj_u[k], &proj_v[k]);
            umin = fmin(umin, proj_u[k]);
            umax = fmax(umax, proj_u[k]);
            vmin = fmin(vmin, proj_v[k]);
            vmax = fmax(vmax, proj_v[k]);
        }
        width = ceil((umax - umin) / ISLAND_SUBTEXELS) + 2;
        height = ceil((vmax - vmin) / ISLAND_SUBTEXELS) + 2;
        if (attempt == 0) {
            longest_width = width;
            longest_height = height;
        }
        if (width <= SCENE_MAX_ISLAND_TEXELS && height <= SCENE_MAX_ISLAND_TEXELS)
            break;
    }
    if (!(width <= SCENE_MAX_ISLAND_TEXELS && height <= SCENE_MAX_ISLAND_TEXELS)) {
        uint32_t mesh = s->tri_mesh[seed];
        uint32_t local = (s->meshes && mesh < s->mesh_count) ? seed - s->meshes[mesh].first_triangle : seed;
        return scene__fail(
            err, SCENE_ERR_RANGE,
            "mesh '%s' triangle %u (scene triangle %u) needs %.0f x %.0f texels at %g texels/m; "
            "an island may be at most %d texels on a side: lower the texel density",
            mesh_name(s, mesh), local, seed, longest_width, longest_height, (double)s->texel_density,
            (int)SCENE_MAX_ISLAND_TEXELS);
    }

    /* Snap: a = origin exactly, b on the u axis, c above it; open a flattened triangle by one step. */
    island_point snapped[3];
    for (int k = 0; k < 3; k++) {
        snapped[k].u = (int64_t)llround(proj_u[k]);
        snapped[k].v = (int64_t)llround(proj_v[k]);
    }
    snapped[0].u = snapped[0].v = 0;
    snapped[1].v = 0;
    if (snapped[1].u < 1)
        snapped[1].u = 1;
    if (snapped[2].v < 1)
        snapped[2].v = 1;

    chart->vertex_count = 0;
    chart->triangle_count = 1;
    chart->triangle_id[0] = seed;
    for (int k = 0; k < 3; k++) {
        uint32_t vertex = corner[(first + k) % 3];
        uint32_t corner_slot = (uint32_t)((first + k) % 3);
        uint16_t local = (uint16_t)chart->vertex_count++;
        chart->vertex_id[local] = vertex;
        chart->vertex_uv[local] = snapped[k];
        chart->corner[0][corner_slot] = local;
        work->vertex_stamp[vertex] = chart_index + 1;
        work->vertex_local[vertex] = local;
    }
    int64_t *box = chart->box[0];
    triangle_box(snapped, box);
    memcpy(chart->chart_box, box, sizeof chart->chart_box);
    return SCENE_OK;
}

/* Tries to add triangle candidate to the chart; returns whether it was added. Refusals: normal outside the
 * bound, a corner too far away, folded or badly snapped projection, chart too large, interior overlap. */
static bool try_add_triangle(const scene *s, island_work *work, uint32_t chart_index, uint32_t candidate)
{
    island_chart *chart = &work->chart;
    const float *cn = s->tri_normal + 3 * (size_t)candidate;
    double facing = cn[0] * chart->normal[0] + cn[1] * chart->normal[1] + cn[2] * chart->normal[2];
    if (!(facing >= ISLAND_MIN_COS))
        return false;

    const uint32_t *corner = s->indices + 3 * (size_t)candidate;
    const double limit = (double)SCENE_MAX_ISLAND_TEXELS * ISLAND_SUBTEXELS;
    island_point pts[3];
    double exact_u[3], exact_v[3];
    bool is_new[3];
    for (int k = 0; k < 3; k++) {
        uint32_t vertex = corner[k];
        project_vertex(s, chart, vertex, &exact_u[k], &exact_v[k]);
        is_new[k] = work->vertex_stamp[vertex] != chart_index + 1;
        if (!is_new[k]) {
            pts[k] = chart->vertex_uv[work->vertex_local[vertex]];
            continue;
        }
        /* The origin is in the chart, so a corner this far away could never fit. */
        if (!(fabs(exact_u[k]) < limit && fabs(exact_v[k]) < limit))
            return false;
        pts[k].u = (int64_t)llround(exact_u[k]);
        pts[k].v = (int64_t)llround(exact_v[k]);
    }

    /* Fold and snapping: positive area, and close to the exact projection's. */
    int64_t area2 = orient2(pts[0], pts[1], pts[2]);
    double exact_area2 = (exact_u[1] - exact_u[0]) * (exact_v[2] - exact_v[0]) -
                         (exact_v[1] - exact_v[0]) * (exact_u[2] - exact_u[0]);
    if (area2 <= 0 || !(exact_area2 > 0) ||
        !(fabs((double)area2 - exact_area2) <= ISLAND_MAX_SNAP_AREA_ERROR * exact_area2))
        return false;

    /* Size of the chart with this triangle. */
    int64_t box[4] = {pts[0].u, pts[0].v, pts[0].u, pts[0].v};
    for (int k = 1; k < 3; k++) {
        box[0] = pts[k].u < box[0] ? pts[k].u : box[0];
        box[1] = pts[k].v < box[1] ? pts[k].v : box[1];
        box[2] = pts[k].u > box[2] ? pts[k].u : box[2];
        box[3] = pts[k].v > box[3] ? pts[k].v : box[3];
    }
    int64_t grown[4] = {box[0] < chart->chart_box[0] ? box[0] : chart->chart_box[0],
                        box[1] < chart->chart_box[1] ? box[1] : chart->chart_box[1],
                        box[2] > chart->chart_box[2] ? box[2] : chart->chart_box[2],
                        box[3] > chart->chart_box[3] ? box[3] : chart->chart_box[3]};
    if (island_side_texels(grown[2] - grown[0]) > SCENE_MAX_ISLAND_TEXELS ||
        island_side_texels(grown[3] - grown[1]) > SCENE_MAX_ISLAND_TEXELS)
        return false;

    /* Interior overlap with every chart triangle whose box overlaps this one's with positive area. */
    for (uint32_t other = 0; other < chart->triangle_count; other++) {
        const int64_t *ob = chart->box[other];
        if (ob[0] >= box[2] || ob[2] <= box[0] || ob[1] >= box[3] || ob[3] <= box[1])
            continue;
        island_point other_pts[3];
        for (int k = 0; k < 3; k++)
            other_pts[k] = chart->vertex_uv[chart->corner[other][k]];
        if (triangles_overlap(pts, other_pts))
            return false;
    }

    /* Accept. */
    uint32_t slot = chart->triangle_count++;
    chart->triangle_id[slot] = candidate;
    for (int k = 0; k < 3; k++) {
        uint32_t vertex = corner[k];
        if (is_new[k]) {
            uint16_t local = (uint16_t)chart->vertex_count++;
            chart->vertex_id[local] = vertex;
            chart->vertex_uv[local] = pts[k];
            work->vertex_stamp[vertex] = chart_index + 1;
            work->vertex_local[vertex] = local;
        }
        chart->corner[slot][k] = work->vertex_local[vertex];
    }
    memcpy(chart->box[slot], box, sizeof box);
    memcpy(chart->chart_box, grown, sizeof grown);
    return true;
}

/* Queues the unassigned, not yet considered neighbours of triangle t within its mesh. */
static void queue_neighbors(const scene *s, island_work *work, uint32_t chart_index, uint32_t t,
                            uint32_t *queue_end)
{
    for (int edge = 0; edge < 3; edge++) {
        uint32_t across = work->edge_neighbor[3 * (size_t)t + edge];
        if (across == SCENE_TOPO_NO_NEIGHBOR || across >= s->triangle_count)
            continue;
        if (s->tri_island[across] != UINT32_MAX || work->visit_stamp[across] == chart_index + 1)
            continue;
        if (s->tri_mesh[across] != s->tri_mesh[t])
            continue;
        if (*queue_end >= ISLAND_QUEUE_CAP) /* cannot happen with the cap above; stay safe */
            return;
        work->visit_stamp[across] = chart_index + 1;
        work->queue[(*queue_end)++] = across;
    }
}

/* Orders hull points by u, then v, then local index. */
static int hull_point_compare(const void *a, const void *b)
{
    const island_hull_point *p = a, *q = b;
    if (p->u != q->u)
        return p->u < q->u ? -1 : 1;
    if (p->v != q->v)
        return p->v < q->v ? -1 : 1;
    return p->local < q->local ? -1 : p->local > q->local;
}

/* Cross product of (b - a) and (c - a) for hull points. */
static double hull_cross(const island_hull_point *a, const island_hull_point *b, const island_hull_point *c)
{
    return (b->u - a->u) * (c->v - a->v) - (b->v - a->v) * (c->u - a->u);
}

/* Texel area (border included) of the chart's bounding box when its frame is turned so that u runs along
 * (cos_a, sin_a) of the current frame; only hull points are needed. */
static double rotated_box_texels(const island_hull_point *hull, uint32_t hull_count, double cos_a,
                                 double sin_a)
{
    double umin = INFINITY, umax = -INFINITY, vmin = INFINITY, vmax = -INFINITY;
    for (uint32_t i = 0; i < hull_count; i++) {
        double u = hull[i].u * cos_a + hull[i].v * sin_a, v = -hull[i].u * sin_a + hull[i].v * cos_a;
        umin = fmin(umin, u);
        umax = fmax(umax, u);
        vmin = fmin(vmin, v);
        vmax = fmax(vmax, v);
    }
    return (ceil((umax - umin) / ISLAND_SUBTEXELS) + 2) * (ceil((vmax - vmin) / ISLAND_SUBTEXELS) + 2);
}

/* Turns a finished chart in its plane for a tighter bounding box: tries the direction of every convex hull
 * edge (the minimum-area rectangle has a side on one), and if the best saves at least 3 % of the texels,
 * re-snaps every corner in the turned frame and re-runs the exact checks (positive area, snapping error,
 * size, no interior overlap). If any fails the chart keeps its first frame, which passed them already. */
static void rotate_chart(const scene *s, island_work *work)
{
    island_chart *chart = &work->chart;
    uint32_t count = chart->vertex_count;
    for (uint32_t i = 0; i < count; i++) {
        project_vertex(s, chart, chart->vertex_id[i], &work->plane_u[i], &work->plane_v[i]);
        work->sorted[i].u = work->plane_u[i];
        work->sorted[i].v = work->plane_v[i];
        work->sorted[i].local = i;
    }
    qsort(work->sorted, count, sizeof work->sorted[0], hull_point_compare);
    /* Andrew's monotone chain: lower then upper hull, counter-clockwise. */
    uint32_t hull_count = 0;
    for (uint32_t i = 0; i < count; i++) {
        while (hull_count >= 2 &&
               hull_cross(&work->hull[hull_count - 2], &work->hull[hull_count - 1], &work->sorted[i]) <= 0)
            hull_count--;
        work->hull[hull_count++] = work->sorted[i];
    }
    for (uint32_t i = count - 1, lower = hull_count + 1; i-- > 0;) {
        while (hull_count >= lower &&
               hull_cross(&work->hull[hull_count - 2], &work->hull[hull_count - 1], &work->sorted[i]) <= 0)
            hull_count--;
        work->hull[hull_count++] = work->sorted[i];
    }
    if (hull_count > 1)
        hull_count--; /* the last point repeats the first */

    double current = (double)island_side_texels(chart->chart_box[2] - chart->chart_box[0]) *
                     (double)island_side_texels(chart->chart_box[3] - chart->chart_box[1]);
    double best = current, best_cos = 1, best_sin = 0;
    for (uint32_t i = 0; i < hull_count; i++) {
        const island_hull_point *a = &work->hull[i], *b = &work->hull[(i + 1) % hull_count];
        double du = b->u - a->u, dv = b->v - a->v, len = sqrt(du * du + dv * dv);
        if (!(len > 0))
            continue;
        double texels = rotated_box_texels(work->hull, hull_count, du / len, dv / len);
        if (texels < best) {
            best = texels;
            best_cos = du / len;
            best_sin = dv / len;
        }
    }
    if (!(best <= 0.97 * current))
        return;

    /* Re-snap in the turned frame and re-check everything exactly. */
    for (uint32_t i = 0; i < count; i++) {
        double u = work->plane_u[i] * best_cos + work->plane_v[i] * best_sin;
        double v = -work->plane_u[i] * best_sin + work->plane_v[i] * best_cos;
        work->plane_u[i] = u;
        work->plane_v[i] = v;
        work->rotated_uv[i].u = (int64_t)llround(u);
        work->rotated_uv[i].v = (int64_t)llround(v);
    }
    int64_t chart_box[4] = {INT64_MAX, INT64_MAX, INT64_MIN, INT64_MIN};
    for (uint32_t t = 0; t < chart->triangle_count; t++) {
        island_point pts[3];
        for (int k = 0; k < 3; k++)
            pts[k] = work->rotated_uv[chart->corner[t][k]];
        const uint16_t *c = chart->corner[t];
        double exact_area2 =
            (work->plane_u[c[1]] - work->plane_u[c[0]]) * (work->plane_v[c[2]] - work->plane_v[c[0]]) -
            (work->plane_v[c[1]] - work->plane_v[c[0]]) * (work->plane_u[c[2]] - work->plane_u[c[0]]);
        int64_t area2 = orient2(pts[0], pts[1], pts[2]);
        if (area2 <= 0 || !(exact_area2 > 0) ||
            !(fabs((double)area2 - exact_area2) <= ISLAND_MAX_SNAP_AREA_ERROR * exact_area2))
            return;
        int64_t *box = work->rotated_box[t];
        triangle_box(pts, box);
        chart_box[0] = box[0] < chart_box[0] ? box[0] : chart_box[0];
        chart_box[1] = box[1] < chart_box[1] ? box[1] : chart_box[1];
        chart_box[2] = box[2] > chart_box[2] ? box[2] : chart_box[2];
        chart_box[3] = box[3] > chart_box[3] ? box[3] : chart_box[3];
    }
    if (island_side_texels(chart_box[2] - chart_box[0]) > SCENE_MAX_ISLAND_TEXELS ||
        island_side_texels(chart_box[3] - chart_box[1]) > SCENE_MAX_ISLAND_TEXELS)
        return;
    for (uint32_t t = 1; t < chart->triangle_count; t++) {
        const int64_t *box = work->rotated_box[t];
        island_point pts[3];
        for (int k = 0; k < 3; k++)
            pts[k] = work->rotated_uv[chart->corner[t][k]];
        for (uint32_t other = 0; other < t; other++) {
            const int64_t *ob = work->rotated_box[other];
            if (ob[0] >= box[2] || ob[2] <= box[0] || ob[1] >= box[3] || ob[3] <= box[1])
                continue;
            island_point other_pts[3];
            for (int k = 0; k < 3; k++)
                other_pts[k] = work->rotated_uv[chart->corner[other][k]];
            if (triangles_overlap(pts, other_pts))
                return;
        }
    }

    /* Accept the turned frame. */
    double axis_u[3], axis_v[3];
    for (int k = 0; k < 3; k++) {
        axis_u[k] = chart->axis_u[k] * best_cos + chart->axis_v[k] * best_sin;
        axis_v[k] = -chart->axis_u[k] * best_sin + chart->axis_v[k] * best_cos;
    }
    memcpy(chart->axis_u, axis_u, sizeof axis_u);
    memcpy(chart->axis_v, axis_v, sizeof axis_v);
    memcpy(chart->vertex_uv, work->rotated_uv, sizeof(island_point) * count);
    memcpy(chart->box, work->rotated_box, sizeof(chart->box[0]) * chart->triangle_count);
    memcpy(chart->chart_box, chart_box, sizeof chart_box);
}

/* Writes the finished chart as island chart_index: its triangles, their slots and the final UVs (snapped
 * points shifted so the chart starts one texel in, then divided by the grid: exact in float). */
static void emit_chart(scene *s, island_work *work, uint32_t chart_index, uint32_t first_slot)
{
    const island_chart *chart = &work->chart;
    scene_island *island = &s->islands[chart_index];
    island->first = first_slot;
    island->triangle_count = chart->triangle_count;
    island->width = (uint32_t)island_side_texels(chart->chart_box[2] - chart->chart_box[0]);
    island->height = (uint32_t)island_side_texels(chart->chart_box[3] - chart->chart_box[1]);
    island->mesh = s->tri_mesh[chart->triangle_id[0]];
    for (uint32_t slot = 0; slot < chart->triangle_count; slot++) {
        uint32_t t = chart->triangle_id[slot];
        s->island_triangles[first_slot + slot] = t;
        s->tri_island[t] = chart_index;
        s->tri_local[t] = (uint8_t)slot;
        for (int k = 0; k < 3; k++) {
            island_point p = chart->vertex_uv[chart->corner[slot][k]];
            s->tri_island_uv[6 * (size_t)t + 2 * k] =
                (float)(p.u - chart->chart_box[0] + ISLAND_SUBTEXELS) / (float)ISLAND_SUBTEXELS;
            s->tri_island_uv[6 * (size_t)t + 2 * k + 1] =
                (float)(p.v - chart->chart_box[1] + ISLAND_SUBTEXELS) / (float)ISLAND_SUBTEXELS;
        }
    }
}

/* Frees the scratch of one build. */
static void free_work(island_work *work)
{
    if (!work)
        return;
    free(work->edge_neighbor);
    free(work->visit_stamp);
    free(work->vertex_stamp);
    free(work->vertex_local);
    free(work);
}

/* Frees the island arrays of s and clears them. */
static void clear_islands(scene *s)
{
    free(s->islands);
    free(s->island_triangles);
    free(s->tri_island);
    free(s->tri_local);
    free(s->tri_island_uv);
    s->islands = NULL;
    s->island_triangles = NULL;
    s->tri_island = NULL;
    s->tri_local = NULL;
    s->tri_island_uv = NULL;
    s->island_count = 0;
}

/* Builds the islands of s: see the top of this file. On failure s has no islands and err says why. */
scene_result scene__build_islands(scene *s, scene_error *err)
{
    clear_islands(s);
    s->repairs.nonmanifold_split = 0;
    uint32_t triangle_count = s->triangle_count;
    if (triangle_count == 0)
        return SCENE_OK;
    if (!s->positions || !s->indices || !s->tri_normal || !s->tri_mesh)
        return scene__fail(err, SCENE_ERR_INVALID,
                           "islands: the scene has no triangles, normals or meshes set");
    if (!(s->texel_density > 0) || !isfinite(s->texel_density))
        return scene__fail(err, SCENE_ERR_RANGE, "islands: texel density %g must be a finite number > 0",
                           (double)s->texel_density);

    size_t n = triangle_count;
    island_work *work = calloc(1, sizeof *work);
    if (work) {
        work->edge_neighbor = malloc(sizeof(uint32_t) * 3 * n);
        work->visit_stamp = calloc(n, sizeof(uint32_t));
        work->vertex_stamp = calloc(s->vertex_count ? s->vertex_count : 1, sizeof(uint32_t));
        work->vertex_local = calloc(s->vertex_count ? s->vertex_count : 1, sizeof(uint16_t));
    }
    s->islands = malloc(sizeof(scene_island) * n);
    s->island_triangles = malloc(sizeof(uint32_t) * n);
    s->tri_island = malloc(sizeof(uint32_t) * n);
    s->tri_local = malloc(n);
    s->tri_island_uv = malloc(sizeof(float) * 6 * n);
    if (!work || !work->edge_neighbor || !work->visit_stamp || !work->vertex_stamp || !work->vertex_local ||
        !s->islands || !s->island_triangles || !s->tri_island || !s->tri_local || !s->tri_island_uv) {
        free_work(work);
        clear_islands(s);
        return scene__fail(err, SCENE_ERR_NOMEM, "islands: out of memory for %u triangles", triangle_count);
    }

    char topo_msg[256];
    uint32_t split = 0;
    scene_topo_result topo =
        scene_topo_edge_neighbors(s->positions, s->vertex_count, s->indices, triangle_count,
                                  work->edge_neighbor, &split, topo_msg, sizeof topo_msg);
    if (topo != SCENE_TOPO_OK) {
        free_work(work);
        clear_islands(s);
        return scene__fail(err, topo == SCENE_TOPO_ERR_NOMEM ? SCENE_ERR_NOMEM : SCENE_ERR_INVALID, "%s: %s",
                           s->source[0] ? s->source : "scene", topo_msg);
    }
    s->repairs.nonmanifold_split = split;

    for (size_t t = 0; t < n; t++)
        s->tri_island[t] = UINT32_MAX;

    uint32_t chart_count = 0, slots_used = 0;
    for (uint32_t seed = 0; seed < triangle_count; seed++) {
        if (s->tri_island[seed] != UINT32_MAX)
            continue;
        uint32_t chart_index = chart_count;
        scene_result rc = start_chart(s, work, chart_index, seed, err);
        if (rc != SCENE_OK) {
            free_work(work);
            clear_islands(s);
            return rc;
        }
        work->visit_stamp[seed] = chart_index + 1;
        /* Breadth-first growth; a refused candidate stays refused for this chart (it could only get worse).
         */
        uint32_t queue_begin = 0, queue_end = 0;
        queue_neighbors(s, work, chart_index, seed, &queue_end);
        while (queue_begin < queue_end && work->chart.triangle_count < SCENE_ISLAND_MAX_TRIANGLES) {
            uint32_t candidate = work->queue[queue_begin++];
            if (try_add_triangle(s, work, chart_index, candidate))
                queue_neighbors(s, work, chart_index, candidate, &queue_end);
        }
        rotate_chart(s, work);
        emit_chart(s, work, chart_index, slots_used);
        slots_used += work->chart.triangle_count;
        chart_count++;
    }
    free_work(work);

    s->island_count = chart_count;
    scene_island *shrunk = realloc(s->islands, sizeof(scene_island) * chart_count);
    if (shrunk)
        s->islands = shrunk;
    return SCENE_OK;
}
