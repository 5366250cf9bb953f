/* The scene builder: the functions every loader (mesh file, JSON description, embedded scene) shares, and
 * the finalisation that turns the appended meshes into a read-only scene with islands.
 *
 * scene__add_mesh() is where untrusted geometry is checked: every coordinate finite (naming mesh and
 * vertex), every index in range, vertices with equal positions welded (so the half-edge mesh sees the real
 * topology), degenerate and duplicate triangles dropped and counted. */
#include "scene_internal.h"
#include "image.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

/* Auto texel density aims at this many level-0 texels over the whole surface (4096 x 4096). */
#define SCENE_AUTO_TEXELS (4096.0 * 4096.0)

static const char *const scene_result_strings[] = {
#define FXC_X(name, str) str,
    SCENE_RESULTS(FXC_X)
#undef FXC_X
};

const char *scene_strerror(scene_result code)
{
    size_t n = sizeof scene_result_strings / sizeof scene_result_strings[0];
    return (size_t)code < n ? scene_result_strings[code] : "unknown error";
}

scene_result scene__fail(scene_error *err, scene_result code, const char *fmt, ...)
{
    if (err) {
        va_list ap;
        va_start(ap, fmt);
        err->code = code;
        vsnprintf(err->msg, sizeof err->msg, fmt, ap);
        va_end(ap);
    }
    return code;
}

double scene__now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

scene *scene__alloc(void)
{
    scene *s = calloc(1, sizeof *s);
    if (!s)
        return NULL;
    s->density_auto = true;
    s->fx_shadows = s->fx_ao = s->fx_indirect = SCENE_AUTO;
    snprintf(s->source, sizeof s->source, "(unnamed)");
    return s;
}

void scene_free(scene *s)
{
    if (!s)
        return;
    free(s->positions);
    free(s->indices);
    free(s->corner_uv);
    free(s->tri_mesh);
    free(s->tri_normal);
    free(s->meshes);
    free(s->materials);
    for (uint32_t i = 0; i < s->texture_count; i++) {
        free(s->textures[i].rgb); /* level 0 (mip_rgb[0], when the chain was built) */
        for (uint32_t l = 1; l < s->textures[i].levels; l++)
            free(s->textures[i].mip_rgb[l]);
    }
    free(s->tri_texture_lod);
    free(s->textures);
    free(s->lights);
    free(s->islands);
    free(s->island_triangles);
    free(s->tri_island);
    free(s->tri_local);
    free(s->tri_island_uv);
    free(s);
}

/* Grows *array to hold count elements of size bytes; false (array untouched) on overflow or no memory. */
static bool grow(void **array, size_t count, size_t size)
{
    if (count != 0 && size > SIZE_MAX / count)
        return false;
    void *p = realloc(*array, count * size);
    if (!p && count)
        return false;
    *array = p;
    return true;
}

uint32_t scene__add_material(scene *s, const scene_material *m, scene_error *err)
{
    if (!grow((void **)&s->materials, (size_t)s->material_count + 1, sizeof *s->materials)) {
        scene__fail(err, SCENE_ERR_NOMEM, "out of memory adding material %s", m->name);
        return UINT32_MAX;
    }
    s->materials[s->material_count] = *m;
    return s->material_count++;
}

/* Builds the mip chain of a texture: each level the 2 x 2 box average of the one above (the last row or
 * column is repeated for odd sizes), down to 1 x 1. False on no memory (levels built so far are kept). */
static bool build_mips(scene_texture *tex)
{
    tex->mip_rgb[0] = tex->rgb;
    tex->mip_width[0] = tex->width;
    tex->mip_height[0] = tex->height;
    tex->levels = 1;
    while (tex->levels < SCENE_TEXTURE_MAX_LEVELS) {
        uint32_t l = tex->levels;
        uint32_t pw = tex->mip_width[l - 1], ph = tex->mip_height[l - 1];
        if (pw == 1 && ph == 1)
            break;
        uint32_t w = (pw + 1) / 2, h = (ph + 1) / 2;
        float *dst = malloc(sizeof(float) * 3 * (size_t)w * h);
        if (!dst)
            return false;
        const float *src = tex->mip_rgb[l - 1];
        for (uint32_t y = 0; y < h; y++)
            for (uint32_t x = 0; x < w; x++) {
                uint32_t x0 = 2 * x, y0 = 2 * y;
                uint32_t x1 = x0 + 1 < pw ? x0 + 1 : x0, y1 = y0 + 1 < ph ? y0 + 1 : y0;
                for (int k = 0; k < 3; k++)
                    dst[3 * ((size_t)y * w + x) + k] =
                        0.25f * (src[3 * ((size_t)y0 * pw + x0) + k] + src[3 * ((size_t)y0 * pw + x1) + k] +
                                 src[3 * ((size_t)y1 * pw + x0) + k] + src[3 * ((size_t)y1 * pw + x1) + k]);
            }
        tex->mip_rgb[l] = dst;
        tex->mip_width[l] = w;
        tex->mip_height[l] = h;
        tex->levels++;
    }
    return true;
}

int32_t scene__add_texture(scene *s, const char *path, scene_error *err)
{
    for (uint32_t i = 0; i < s->texture_count; i++)
        if (strcmp(s->textures[i].path, path) == 0)
            return (int32_t)i;
    scene_texture tex = {0};
    char msg[384];
    if (scene_image_read_rgb(path, &tex.width, &tex.height, &tex.rgb, msg, sizeof msg) != 0) {
        scene__fail(err, SCENE_ERR_IO, "%s", msg);
        return -1;
    }
    snprintf(tex.path, sizeof tex.path, "%s", path);
    bool mips_ok = build_mips(&tex);
    if (!mips_ok || !grow((void **)&s->textures, (size_t)s->texture_count + 1, sizeof *s->textures)) {
        for (uint32_t l = 0; l < tex.levels; l++)
            free(tex.mip_rgb[l]);
        scene__fail(err, SCENE_ERR_NOMEM, "out of memory adding texture %s", path);
        return -1;
    }
    s->textures[s->texture_count] = tex;
    return (int32_t)s->texture_count++;
}

static bool finite3(const float v[3])
{
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

scene_result scene__add_light(scene *s, const scene_light *l, const char *where, scene_error *err)
{
    scene_light light = *l;
    if (!finite3(light.color) || !isfinite(light.intensity))
        return scene__fail(err, SCENE_ERR_INVALID, "%s: light colour and intensity must be finite", where);
    if (light.intensity < 0 || light.color[0] < 0 || light.color[1] < 0 || light.color[2] < 0)
        return scene__fail(err, SCENE_ERR_RANGE, "%s: light colour and intensity must be >= 0", where);
    if (light.type == SCENE_LIGHT_DIRECTIONAL) {
        if (!finite3(light.direction))
            return scene__fail(err, SCENE_ERR_INVALID, "%s: light direction must be finite", where);
        double len = sqrt((double)light.direction[0] * light.direction[0] +
                          (double)light.direction[1] * light.direction[1] +
                          (double)light.direction[2] * light.direction[2]);
        if (!(len > 1e-20))
            return scene__fail(err, SCENE_ERR_INVALID, "%s: light direction must not be zero", where);
        for (int k = 0; k < 3; k++)
            light.direction[k] = (float)(light.direction[k] / len);
    } else if (!finite3(light.position)) {
        return scene__fail(err, SCENE_ERR_INVALID, "%s: light position must be finite", where);
    }
    if (!grow((void **)&s->lights, (size_t)s->light_count + 1, sizeof *s->lights))
        return scene__fail(err, SCENE_ERR_NOMEM, "out of memory adding a light");
    s->lights[s->light_count++] = light;
    return SCENE_OK;
}

void scene__add_default_lighting(scene *s)
{
    scene_light sun = {.type = SCENE_LIGHT_DIRECTIONAL,
                       .direction = {-0.35f, -0.85f, -0.4f},
                       .color = {1.0f, 0.95f, 0.85f},
                       .intensity = 3.0f};
    scene__add_light(s, &sun, "default sun", NULL);
    s->sky_color[0] = 0.55f;
    s->sky_color[1] = 0.7f;
    s->sky_color[2] = 1.0f;
    s->sky_intensity = 0.6f;
}

/* ---- welding and cleaning ----------------------------------------------------------------------------- */

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
    if (v[0] > v[1]) { t = v[0]; v[0] = v[1]; v[1] = t; }
    if (v[1] > v[2]) { t = v[1]; v[1] = v[2]; v[2] = t; }
    if (v[0] > v[1]) { t = v[0]; v[0] = v[1]; v[1] = t; }
}

/* Twice the area of triangle (a, b, c), in double, and whether it is too thin to carry a normal. */
static bool triangle_degenerate(const float *a, const float *b, const float *c)
{
    double e1[3], e2[3], e3[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = (double)b[k] - a[k];
        e2[k] = (double)c[k] - a[k];
        e3[k] = (double)c[k] - b[k];
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

scene_result scene__add_mesh(scene *s, const char *name, const float *positions, uint32_t vertex_count,
                             const uint32_t *indices, uint32_t triangle_count, const float *uv,
                             uint32_t material, const float *xform, scene_error *err)
{
    if (material >= s->material_count)
        return scene__fail(err, SCENE_ERR_INVALID, "mesh '%s': material %u out of range (%u materials)",
                           name, material, s->material_count);
    for (uint32_t v = 0; v < vertex_count; v++) {
        const float *p = positions + 3 * (size_t)v;
        if (!finite3(p))
            return scene__fail(err, SCENE_ERR_INVALID,
                               "mesh '%s': vertex %u has a non-finite coordinate (%g, %g, %g)", name, v,
                               (double)p[0], (double)p[1], (double)p[2]);
    }
    for (size_t i = 0; i < 3 * (size_t)triangle_count; i++)
        if (indices[i] >= vertex_count)
            return scene__fail(err, SCENE_ERR_INVALID,
                               "mesh '%s': triangle %zu uses vertex %u, but the mesh has %u vertices", name,
                               i / 3, indices[i], vertex_count);
    if (triangle_count == 0)
        return SCENE_OK;

    double t0 = scene__now_ms();
    scene_result rc = SCENE_ERR_NOMEM;
    float *world = malloc(sizeof(float) * 3 * (size_t)vertex_count);
    uint32_t *order = malloc(sizeof(uint32_t) * (size_t)vertex_count);
    uint32_t *remap = malloc(sizeof(uint32_t) * (size_t)vertex_count);
    tri_key *keys = malloc(sizeof(tri_key) * (size_t)triangle_count);
    uint8_t *keep = calloc(triangle_count, 1);
    if (!world || !order || !remap || !keys || !keep)
        goto done;

    /* Transform; adding 0.0f turns -0 into +0 so the two weld together. */
    for (uint32_t v = 0; v < vertex_count; v++) {
        const float *p = positions + 3 * (size_t)v;
        float *w = world + 3 * (size_t)v;
        if (xform) {
            for (int r = 0; r < 3; r++)
                w[r] = (float)((double)xform[4 * r] * p[0] + (double)xform[4 * r + 1] * p[1] +
                               (double)xform[4 * r + 2] * p[2] + xform[4 * r + 3]);
        } else {
            w[0] = p[0], w[1] = p[1], w[2] = p[2];
        }
        for (int k = 0; k < 3; k++)
            w[k] += 0.0f;
        if (!finite3(w)) {
            rc = scene__fail(err, SCENE_ERR_INVALID,
                             "mesh '%s': vertex %u is not finite after the mesh transform", name, v);
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

    /* Degenerate and duplicate triangles. */
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
    if ((uint64_t)s->vertex_count + unique > UINT32_MAX / 4 ||
        (uint64_t)s->triangle_count + kept > UINT32_MAX / 8) {
        rc = scene__fail(err, SCENE_ERR_RANGE, "mesh '%s': the scene would exceed %u triangles", name,
                         UINT32_MAX / 8);
        goto done;
    }

    uint32_t base_vertex = s->vertex_count, base_tri = s->triangle_count;
    size_t nv = (size_t)base_vertex + unique, nt = (size_t)base_tri + kept;
    if (!grow((void **)&s->positions, nv * 3, sizeof(float)) ||
        !grow((void **)&s->indices, nt * 3, sizeof(uint32_t)) ||
        !grow((void **)&s->corner_uv, nt * 6, sizeof(float)) ||
        !grow((void **)&s->tri_mesh, nt, sizeof(uint32_t)) ||
        !grow((void **)&s->meshes, (size_t)s->mesh_count + 1, sizeof(scene_mesh)))
        goto done;
    for (uint32_t v = 0; v < vertex_count; v++)
        memcpy(s->positions + 3 * ((size_t)base_vertex + remap[v]), world + 3 * (size_t)v, 3 * sizeof(float));
    /* A mirroring transform (negative determinant) would turn every triangle inside out: swap two corners. */
    bool mirrored = false;
    if (xform) {
        double det = (double)xform[0] * ((double)xform[5] * xform[10] - (double)xform[6] * xform[9]) -
                     (double)xform[1] * ((double)xform[4] * xform[10] - (double)xform[6] * xform[8]) +
                     (double)xform[2] * ((double)xform[4] * xform[9] - (double)xform[5] * xform[8]);
        mirrored = det < 0;
    }
    uint32_t out = base_tri;
    for (uint32_t t = 0; t < triangle_count; t++) {
        if (!keep[t])
            continue;
        for (int corner = 0; corner < 3; corner++) {
            int c = mirrored && corner > 0 ? 3 - corner : corner;
            uint32_t src = indices[3 * (size_t)t + corner];
            s->indices[3 * (size_t)out + c] = base_vertex + remap[src];
            float u = 0, w = 0;
            if (uv && isfinite(uv[2 * (size_t)src]) && isfinite(uv[2 * (size_t)src + 1])) {
                u = uv[2 * (size_t)src];
                w = uv[2 * (size_t)src + 1];
            }
            s->corner_uv[6 * (size_t)out + 2 * c] = u;
            s->corner_uv[6 * (size_t)out + 2 * c + 1] = w;
        }
        s->tri_mesh[out] = s->mesh_count;
        out++;
    }
    scene_mesh *m = &s->meshes[s->mesh_count++];
    memset(m, 0, sizeof *m);
    snprintf(m->name, sizeof m->name, "%s", name);
    m->first_triangle = base_tri;
    m->triangle_count = kept;
    m->material = material;
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

/* ---- finalisation ------------------------------------------------------------------------------------- */

double scene_surface_area(const scene *s)
{
    double area = 0;
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        const float *a = s->positions + 3 * (size_t)s->indices[3 * (size_t)t];
        const float *b = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 1];
        const float *c = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 2];
        double e1[3], e2[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = (double)b[k] - a[k];
            e2[k] = (double)c[k] - a[k];
        }
        double cx = e1[1] * e2[2] - e1[2] * e2[1];
        double cy = e1[2] * e2[0] - e1[0] * e2[2];
        double cz = e1[0] * e2[1] - e1[1] * e2[0];
        area += 0.5 * sqrt(cx * cx + cy * cy + cz * cz);
    }
    return area;
}

/* Unit geometric normals (counter-clockwise corners seen from the front) and the bounding box. */
static scene_result compute_normals_and_bounds(scene *s, scene_error *err)
{
    free(s->tri_normal);
    s->tri_normal = malloc(sizeof(float) * 3 * (size_t)s->triangle_count);
    if (!s->tri_normal)
        return scene__fail(err, SCENE_ERR_NOMEM, "out of memory computing normals");
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        const float *a = s->positions + 3 * (size_t)s->indices[3 * (size_t)t];
        const float *b = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 1];
        const float *c = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 2];
        double e1[3], e2[3], n[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = (double)b[k] - a[k];
            e2[k] = (double)c[k] - a[k];
        }
        n[0] = e1[1] * e2[2] - e1[2] * e2[1];
        n[1] = e1[2] * e2[0] - e1[0] * e2[2];
        n[2] = e1[0] * e2[1] - e1[1] * e2[0];
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int k = 0; k < 3; k++)
            s->tri_normal[3 * (size_t)t + k] = len > 0 ? (float)(n[k] / len) : (k == 2 ? 1.0f : 0.0f);
    }
    for (int k = 0; k < 3; k++) {
        s->bounds_min[k] = INFINITY;
        s->bounds_max[k] = -INFINITY;
    }
    for (uint32_t v = 0; v < s->vertex_count; v++)
        for (int k = 0; k < 3; k++) {
            float x = s->positions[3 * (size_t)v + k];
            s->bounds_min[k] = fminf(s->bounds_min[k], x);
            s->bounds_max[k] = fmaxf(s->bounds_max[k], x);
        }
    double diag2 = 0;
    for (int k = 0; k < 3; k++)
        diag2 += ((double)s->bounds_max[k] - s->bounds_min[k]) * ((double)s->bounds_max[k] - s->bounds_min[k]);
    s->ray_offset_scale = (float)fmin(1.0, fmax(sqrt(diag2), 1e-30));
    return SCENE_OK;
}

/* Per textured triangle, log2 of its texture's texels per metre: sqrt(UV area in texels / world area). */
static scene_result compute_texture_lods(scene *s, scene_error *err)
{
    free(s->tri_texture_lod);
    s->tri_texture_lod = malloc(sizeof(float) * (size_t)s->triangle_count);
    if (!s->tri_texture_lod)
        return scene__fail(err, SCENE_ERR_NOMEM, "out of memory computing texture levels");
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        const scene_material *m = &s->materials[s->meshes[s->tri_mesh[t]].material];
        s->tri_texture_lod[t] = -1000.0f;
        if (m->texture < 0 || (uint32_t)m->texture >= s->texture_count)
            continue;
        const scene_texture *tex = &s->textures[m->texture];
        const float *uv = s->corner_uv + 6 * (size_t)t;
        double uv_area = 0.5 * fabs(((double)uv[2] - uv[0]) * ((double)uv[5] - uv[1]) -
                                    ((double)uv[4] - uv[0]) * ((double)uv[3] - uv[1])) *
                         (double)tex->width * (double)tex->height;
        const float *a = s->positions + 3 * (size_t)s->indices[3 * (size_t)t];
        const float *b = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 1];
        const float *c = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 2];
        double e1[3], e2[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = (double)b[k] - a[k];
            e2[k] = (double)c[k] - a[k];
        }
        double cx = e1[1] * e2[2] - e1[2] * e2[1], cy = e1[2] * e2[0] - e1[0] * e2[2], cz = e1[0] * e2[1] - e1[1] * e2[0];
        double world_area = 0.5 * sqrt(cx * cx + cy * cy + cz * cz);
        if (uv_area > 0 && world_area > 0 && isfinite(uv_area))
            s->tri_texture_lod[t] = (float)(0.5 * log2(uv_area / world_area));
    }
    return SCENE_OK;
}

scene_result scene__finalize(scene *s, const scene_load_desc *desc, scene_error *err)
{
    if (s->triangle_count == 0)
        return scene__fail(err, SCENE_ERR_EMPTY, "%s: the scene has no triangles (%llu degenerate, %llu "
                                                  "duplicate skipped)",
                           s->source, (unsigned long long)s->repairs.degenerate_skipped,
                           (unsigned long long)s->repairs.duplicate_skipped);
    double t0 = scene__now_ms();
    scene_result rc = compute_normals_and_bounds(s, err);
    if (rc != SCENE_OK)
        return rc;
    if (desc && desc->texel_density != 0) {
        if (!(desc->texel_density >= 1e-6f) || !(desc->texel_density <= 1e6f))
            return scene__fail(err, SCENE_ERR_RANGE, "texel density %g is outside [1e-6, 1e6] texels per metre",
                               (double)desc->texel_density);
        s->texel_density = desc->texel_density;
        s->density_auto = false;
    }
    if (s->density_auto || !(s->texel_density > 0)) {
        double area = scene_surface_area(s);
        s->texel_density = area > 0 ? (float)sqrt(SCENE_AUTO_TEXELS / area) : 1.0f;
        s->density_auto = true;
    }
    if (!(s->ao_radius > 0)) {
        double dx = s->bounds_max[0] - s->bounds_min[0], dy = s->bounds_max[1] - s->bounds_min[1],
               dz = s->bounds_max[2] - s->bounds_min[2];
        s->ao_radius = (float)(0.1 * sqrt(dx * dx + dy * dy + dz * dz));
        if (!(s->ao_radius > 0))
            s->ao_radius = 1.0f;
    }
    rc = compute_texture_lods(s, err);
    if (rc != SCENE_OK)
        return rc;
    s->timings.weld_ms += scene__now_ms() - t0;
    t0 = scene__now_ms();
    rc = scene__build_islands(s, err);
    s->timings.islands_ms = scene__now_ms() - t0;
    return rc;
}

/* ---- loading ------------------------------------------------------------------------------------------ */

static bool ends_with(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    if (m > n)
        return false;
    for (size_t i = 0; i < m; i++) {
        char a = s[n - m + i], b = suffix[i];
        if (a >= 'A' && a <= 'Z')
            a = (char)(a - 'A' + 'a');
        if (a != b)
            return false;
    }
    return true;
}

scene_result scene__check_file(const char *path, scene_error *err)
{
    struct stat st;
    if (stat(path, &st) != 0)
        return scene__fail(err, SCENE_ERR_IO, "%s: cannot read: %s", path, strerror(errno));
    if (S_ISDIR(st.st_mode))
        return scene__fail(err, SCENE_ERR_IO, "%s: is a directory, not a file", path);
    if (!S_ISREG(st.st_mode))
        return scene__fail(err, SCENE_ERR_IO, "%s: not a regular file (a %s)", path,
                           S_ISFIFO(st.st_mode)   ? "FIFO"
                           : S_ISSOCK(st.st_mode) ? "socket"
                                                  : "device");
    FILE *probe = fopen(path, "rb");
    if (!probe)
        return scene__fail(err, SCENE_ERR_IO, "%s: cannot read: %s", path, strerror(errno));
    fclose(probe);
    return SCENE_OK;
}

scene *scene_create_default(const scene_load_desc *desc, scene_error *err)
{
    return scene_load(NULL, desc, err);
}

scene *scene_load(const char *path, const scene_load_desc *desc, scene_error *err)
{
    scene *s = scene__alloc();
    if (!s) {
        scene__fail(err, SCENE_ERR_NOMEM, "out of memory");
        return NULL;
    }
    double t0 = scene__now_ms();
    scene_result rc;
    if (!path || strcmp(path, "default") == 0) {
        snprintf(s->source, sizeof s->source, "(embedded default scene)");
        rc = scene__build_default(s, err);
    } else if (ends_with(path, ".json")) {
        snprintf(s->source, sizeof s->source, "%s", path);
        rc = scene__check_file(path, err);
        if (rc == SCENE_OK)
            rc = scene__load_json(s, path, err);
    } else {
        snprintf(s->source, sizeof s->source, "%s", path);
        rc = scene__import_file(s, path, NULL, NULL, err);
        if (rc == SCENE_OK)
            scene__add_default_lighting(s);
    }
    s->timings.load_ms = scene__now_ms() - t0 - s->timings.weld_ms - s->timings.textures_ms;
    if (rc == SCENE_OK)
        rc = scene__finalize(s, desc, err);
    if (rc != SCENE_OK && path && strcmp(path, "default") != 0 && err && !strstr(err->msg, path)) {
        /* name the file when the message does not (a mesh's vertex, a triangle too wide for an island) */
        char inner[sizeof err->msg];
        snprintf(inner, sizeof inner, "%s", err->msg);
        scene__fail(err, rc, "%s: %s", path, inner);
    }
    if (rc != SCENE_OK) {
        scene_free(s);
        return NULL;
    }
    return s;
}

/* ---- materials ---------------------------------------------------------------------------------------- */

/* Bilinear lookup in mip level `level` of a texture with wrap-around addressing; (u, v) with v = 0 at the
 * bottom of the image. */
static void texture_sample(const scene_texture *tex, uint32_t level, float u, float v, float out[3])
{
    /* Level 0 straight from rgb: a texture filled by hand may have no mip chain. */
    const float *texels = level ? tex->mip_rgb[level] : tex->rgb;
    uint32_t width = level ? tex->mip_width[level] : tex->width, height = level ? tex->mip_height[level] : tex->height;
    if (!isfinite(u) || !isfinite(v)) {
        u = 0;
        v = 0;
    }
    float x = (u - floorf(u)) * (float)width - 0.5f;
    float y = (1.0f - (v - floorf(v))) * (float)height - 0.5f;
    float fx = floorf(x), fy = floorf(y);
    float ax = x - fx, ay = y - fy;
    /* x lies in [-0.5, width - 0.5], so x0 + dx lies in [-1, width]: one wrap step, no division. */
    int64_t x0 = (int64_t)fx, y0 = (int64_t)fy;
    int64_t w = width, h = height;
    for (int k = 0; k < 3; k++)
        out[k] = 0;
    for (int dy = 0; dy < 2; dy++)
        for (int dx = 0; dx < 2; dx++) {
            int64_t xi = x0 + dx, yi = y0 + dy;
            xi = xi < 0 ? xi + w : (xi >= w ? xi - w : xi);
            yi = yi < 0 ? yi + h : (yi >= h ? yi - h : yi);
            if (xi < 0 || xi >= w || yi < 0 || yi >= h) /* only for a u or v so large floorf lost precision */
                xi = 0, yi = 0;
            float weight = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay);
            const float *p = texels + 3 * ((size_t)yi * (size_t)w + (size_t)xi);
            for (int k = 0; k < 3; k++)
                out[k] += weight * p[k];
        }
}

void scene_albedo(const scene *s, uint32_t tri, float u, float v, float out_rgb[3])
{
    scene_albedo_filtered(s, tri, u, v, -1000.0f, out_rgb);
}

void scene_albedo_filtered(const scene *s, uint32_t tri, float u, float v, float footprint_log2,
                           float out_rgb[3])
{
    const scene_material *m = &s->materials[s->meshes[s->tri_mesh[tri]].material];
    if (m->texture < 0 || (uint32_t)m->texture >= s->texture_count) {
        memcpy(out_rgb, m->diffuse, 3 * sizeof(float));
        return;
    }
    const float *uv = s->corner_uv + 6 * (size_t)tri;
    float w0 = 1 - u - v;
    float tu = w0 * uv[0] + u * uv[2] + v * uv[4];
    float tv = w0 * uv[1] + u * uv[3] + v * uv[5];
    const scene_texture *tex = &s->textures[m->texture];
    float level = footprint_log2 + (s->tri_texture_lod ? s->tri_texture_lod[tri] : -1000.0f);
    uint32_t mip = 0;
    if (level > 0.5f && tex->levels > 1)
        mip = level >= (float)(tex->levels - 1) ? tex->levels - 1 : (uint32_t)(level + 0.5f);
    float texel[3];
    texture_sample(tex, mip, tu, tv, texel);
    for (int k = 0; k < 3; k++)
        out_rgb[k] = texel[k] * m->diffuse[k];
}
