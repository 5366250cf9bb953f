/* Welding and cleaning one mesh into the scene (scene__commit_mesh): positions from double to the local frame,
 * every coordinate checked finite, vertices with equal positions welded (so the half-edge mesh sees the real
 * topology), degenerate and duplicate triangles dropped and counted. scene.c stages the meshes and calls this
 * once the frame is known, and again when finalisation moves the frame. */
#include "scene_internal.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The spacing of floats at magnitude x (the unit in the last place), in double. */
double scene__float_spacing(double x)
{
    if (!(x >= FLT_MIN))
        return ldexp(1.0, -149); /* subnormal floats are this far apart */
    return ldexp(1.0, ilogb(x) - 23);
}

static _Thread_local const float *weld_positions;

/* Orders vertex indices by position (x, then y, then z), so equal positions end up adjacent. */
static int weld_compare(const void *a, const void *b)
{
    const float *pa = weld_positions + 3 * (size_t)(*(const uint32_t *)a);
    const float *pb = weld_positions + 3 * (size_t)(*(const uint32_t *)b);
    for (int k = 0; k < 3; k++) {
        if (pa[k] < pb[k])
            return -1;
        if (pa[k] > pb[k])
            return 1;
    }
    uint32_t ia = *(const uint32_t *)a, ib = *(const uint32_t *)b;
    return (ia > ib) - (ia < ib);
}

typedef struct tri_key {
    uint32_t v[3];  /* sorted welded vertex indices */
    uint32_t index; /* triangle in the mesh */
} tri_key;

/* Orders triangles by their sorted vertex triple, then by input order (so the first copy survives). */
static int tri_key_compare(const void *a, const void *b)
{
    const tri_key *ta = a, *tb = b;
    for (int k = 0; k < 3; k++)
        if (ta->v[k] != tb->v[k])
            return ta->v[k] < tb->v[k] ? -1 : 1;
    return (ta->index > tb->index) - (ta->index < tb->index);
}

static void sort3(uint32_t v[3])
{
    uint32_t t;
    if (v[0] > v[1]) {
        t = v[0];
        v[0] = v[1];
        v[1] = t;
    }
    if (v[1] > v[2]) {
        t = v[1];
        v[1] = v[2];
        v[2] = t;
    }
    if (v[0] > v[1]) {
        t = v[0];
        v[0] = v[1];
        v[1] = t;
    }
}

void scene__precision_lost(const scene_repairs *r, uint64_t before, char *out, size_t cap)
{
    uint64_t n = r->precision_skipped - before;
    if (n)
        snprintf(out, cap,
                 "; %llu of the degenerate ones have an area but collapse at float precision %.4g m "
                 "from the local origin, where floats are %.3g m apart",
                 (unsigned long long)n, r->precision_reach, scene__float_spacing(r->precision_reach));
    else if (cap)
        out[0] = 0;
}

/* Whether triangle (a, b, c) is too thin to carry a normal, judged in double. */
static bool triangle_degenerate_d(const double a[3], const double b[3], const double c[3])
{
    double e1[3], e2[3], e3[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = b[k] - a[k];
        e2[k] = c[k] - a[k];
        e3[k] = c[k] - b[k];
    }
    double cx = e1[1] * e2[2] - e1[2] * e2[1];
    double cy = e1[2] * e2[0] - e1[0] * e2[2];
    double cz = e1[0] * e2[1] - e1[1] * e2[0];
    double area2 = sqrt(cx * cx + cy * cy + cz * cz);
    double l1 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2];
    double l2 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2];
    double l3 = e3[0] * e3[0] + e3[1] * e3[1] + e3[2] * e3[2];
    double longest2 = fmax(l1, fmax(l2, l3));
    /* The sine of the smallest angle scaled: below 1e-9 the float normal is noise. */
    return !(area2 > 1e-9 * longest2) || !(longest2 > 0);
}

/* The same for float corners. */
static bool triangle_degenerate(const float *a, const float *b, const float *c)
{
    double p[3][3];
    for (int k = 0; k < 3; k++) {
        p[0][k] = a[k];
        p[1][k] = b[k];
        p[2][k] = c[k];
    }
    return triangle_degenerate_d(p[0], p[1], p[2]);
}

/* Whether the triangle with these corners (world positions, double) keeps its shape when moved by -origin in
 * double: a triangle degenerate only once rounded to float lies too far from the frame's origin for its size.
 * Its farthest corner from the origin goes into *reach. */
static bool triangle_fine_in_double(const double *world, const uint32_t *tri, const double origin[3],
                                    double *reach)
{
    double p[3][3];
    for (int c = 0; c < 3; c++)
        for (int k = 0; k < 3; k++) {
            p[c][k] = world[3 * (size_t)tri[c] + k] - origin[k];
            *reach = fmax(*reach, fabs(p[c][k]));
        }
    return !triangle_degenerate_d(p[0], p[1], p[2]);
}

/* Welds, cleans and appends one staged mesh, its positions moved into the frame with the given origin:
 * (float)(world - origin), subtracted in double. *mesh_index receives its index in s->meshes, or UINT32_MAX
 * when no triangle was left. */
scene_result scene__commit_mesh(scene *s, const scene__staged_mesh *m, const double origin[3],
                                const char *name, uint32_t *mesh_index, scene_error *err)
{
    uint32_t vertex_count = m->vertex_count, triangle_count = m->triangle_count;
    const uint32_t *indices = m->indices;
    *mesh_index = UINT32_MAX;
    double t0 = scene__now_ms();
    scene_result rc = SCENE_ERR_NOMEM;
    float *world = malloc(sizeof(float) * 3 * (size_t)vertex_count);
    uint32_t *order = malloc(sizeof(uint32_t) * (size_t)vertex_count);
    uint32_t *remap = malloc(sizeof(uint32_t) * (size_t)vertex_count);
    tri_key *keys = malloc(sizeof(tri_key) * (size_t)triangle_count);
    uint8_t *keep = calloc(triangle_count, 1);
    if (!world || !order || !remap || !keys || !keep)
        goto done;

    /* Into the frame, in double, rounded once; adding 0.0f turns -0 into +0 so the two weld together. */
    for (uint32_t v = 0; v < vertex_count; v++) {
        const double *p = m->world + 3 * (size_t)v;
        float *w = world + 3 * (size_t)v;
        for (int k = 0; k < 3; k++)
            w[k] = (float)(p[k] - origin[k]) + 0.0f;
        if (!scene__finite3(w)) {
            rc = scene__fail(err, SCENE_ERR_INVALID,
                             "mesh '%s': vertex %u is not finite after the mesh transform (%g, %g, %g)", name,
                             v, p[0], p[1], p[2]);
            goto done;
        }
        order[v] = v;
    }

    /* Weld equal positions: sort, then the first of each run of equal positions keeps its slot. */
    weld_positions = world;
    qsort(order, vertex_count, sizeof *order, weld_compare);
    uint32_t unique = 0;
    for (uint32_t i = 0; i < vertex_count; i++) {
        const float *p = world + 3 * (size_t)order[i];
        if (i > 0) {
            const float *q = world + 3 * (size_t)order[i - 1];
            if (p[0] == q[0] && p[1] == q[1] && p[2] == q[2]) {
                remap[order[i]] = remap[order[i - 1]];
                continue;
            }
        }
        remap[order[i]] = unique++;
    }
    s->repairs.vertices_welded += vertex_count - unique;

    /* Degenerate and duplicate triangles, judged on the float positions in this frame. */
    uint32_t kept = 0;
    for (uint32_t t = 0; t < triangle_count; t++) {
        const uint32_t *tri = indices + 3 * (size_t)t;
        keys[t].v[0] = remap[tri[0]];
        keys[t].v[1] = remap[tri[1]];
        keys[t].v[2] = remap[tri[2]];
        keys[t].index = t;
        sort3(keys[t].v);
        bool degenerate = keys[t].v[0] == keys[t].v[1] || keys[t].v[1] == keys[t].v[2] ||
                          triangle_degenerate(world + 3 * (size_t)tri[0], world + 3 * (size_t)tri[1],
                                              world + 3 * (size_t)tri[2]);
        if (degenerate) {
            s->repairs.degenerate_skipped++;
            double reach = 0;
            if (triangle_fine_in_double(m->world, tri, origin, &reach)) {
                s->repairs.precision_skipped++;
                s->repairs.precision_reach = fmax(s->repairs.precision_reach, reach);
            }
            keys[t].v[0] = keys[t].v[1] = keys[t].v[2] = UINT32_MAX;
        }
    }
    qsort(keys, triangle_count, sizeof *keys, tri_key_compare);
    for (uint32_t i = 0; i < triangle_count; i++) {
        if (keys[i].v[0] == UINT32_MAX)
            continue;
        if (i > 0 && memcmp(keys[i].v, keys[i - 1].v, sizeof keys[i].v) == 0) {
            s->repairs.duplicate_skipped++;
            continue;
        }
        keep[keys[i].index] = 1;
        kept++;
    }
    if (kept == 0) {
        rc = SCENE_OK; /* nothing left of this mesh: counted above, not an error by itself */
        goto done;
    }
    _Static_assert(UINT32_MAX / 8 < SCENE_ISLAND_BACK, "island ids keep their top bit for the side");
    if ((uint64_t)s->vertex_count + unique > UINT32_MAX / 4 ||
        (uint64_t)s->triangle_count + kept > UINT32_MAX / 8) {
        rc = scene__fail(err, SCENE_ERR_RANGE, "mesh '%s': the scene would exceed %u triangles", name,
                         UINT32_MAX / 8);
        goto done;
    }

    uint32_t base_vertex = s->vertex_count, base_tri = s->triangle_count;
    size_t nv = (size_t)base_vertex + unique, nt = (size_t)base_tri + kept;
    if (!scene__grow((void **)&s->positions, nv * 3, sizeof(float)) ||
        !scene__grow((void **)&s->indices, nt * 3, sizeof(uint32_t)) ||
        !scene__grow((void **)&s->corner_uv, nt * 6, sizeof(float)) ||
        !scene__grow((void **)&s->tri_mesh, nt, sizeof(uint32_t)) ||
        !scene__grow((void **)&s->meshes, (size_t)s->mesh_count + 1, sizeof(scene_mesh)))
        goto done;
    /* Vertex colours: the scene's table from the first mesh that has them on (white before it). */
    bool had_colors = s->corner_color != NULL;
    if ((m->color || had_colors) && !scene__grow((void **)&s->corner_color, nt * 9, sizeof(float)))
        goto done;
    for (size_t i = 0; m->color && !had_colors && i < (size_t)base_tri * 9; i++)
        s->corner_color[i] = 1.0f;
    for (uint32_t v = 0; v < vertex_count; v++)
        memcpy(s->positions + 3 * ((size_t)base_vertex + remap[v]), world + 3 * (size_t)v, 3 * sizeof(float));
    uint32_t out = base_tri;
    for (uint32_t t = 0; t < triangle_count; t++) {
        if (!keep[t])
            continue;
        for (int corner = 0; corner < 3; corner++) {
            /* A mirroring transform would turn every triangle inside out: swap two corners. */
            int c = m->mirrored && corner > 0 ? 3 - corner : corner;
            uint32_t src = indices[3 * (size_t)t + corner];
            s->indices[3 * (size_t)out + c] = base_vertex + remap[src];
            float u = 0, w = 0;
            if (m->uv && isfinite(m->uv[2 * (size_t)src]) && isfinite(m->uv[2 * (size_t)src + 1])) {
                u = m->uv[2 * (size_t)src];
                w = m->uv[2 * (size_t)src + 1];
            }
            s->corner_uv[6 * (size_t)out + 2 * c] = u;
            s->corner_uv[6 * (size_t)out + 2 * c + 1] = w;
            for (int k = 0; s->corner_color && k < 3; k++)
                s->corner_color[9 * (size_t)out + 3 * c + k] =
                    m->color ? m->color[3 * (size_t)src + k] : 1.0f;
        }
        s->tri_mesh[out] = s->mesh_count;
        out++;
    }
    scene_mesh *mesh = &s->meshes[s->mesh_count];
    memset(mesh, 0, sizeof *mesh);
    snprintf(mesh->name, sizeof mesh->name, "%s", name);
    mesh->first_triangle = base_tri;
    mesh->triangle_count = kept;
    mesh->material = m->material;
    *mesh_index = s->mesh_count++;
    s->vertex_count = (uint32_t)nv;
    s->triangle_count = (uint32_t)nt;
    rc = SCENE_OK;
done:
    if (rc == SCENE_ERR_NOMEM)
        scene__fail(err, rc, "mesh '%s': out of memory", name);
    s->timings.weld_ms += scene__now_ms() - t0;
    free(world);
    free(order);
    free(remap);
    free(keys);
    free(keep);
    return rc;
}
