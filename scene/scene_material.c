/* Materials, textures and albedo: adding materials and textures (with their mip chains) while a scene is
 * built, the per-triangle texture density once it is finalized, and sampling a triangle's albedo at a pixel's
 * footprint (compose). Split from scene.c, which builds the geometry. */
#include "image.h"
#include "scene_internal.h"
#include "fxc_hot.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

uint32_t scene__add_material(scene *s, const scene_material *m, scene_error *err)
{
    if (!scene__grow((void **)&s->materials, (size_t)s->material_count + 1, sizeof *s->materials)) {
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

/* The texture already loaded from path (or named so), or -1. */
static int32_t texture_named(const scene *s, const char *path)
{
    for (uint32_t i = 0; i < s->texture_count; i++)
        if (strcmp(s->textures[i].path, path) == 0)
            return (int32_t)i;
    return -1;
}

int32_t scene__add_texture(scene *s, const char *path, scene_error *err)
{
    int32_t known = texture_named(s, path);
    if (known >= 0)
        return known;
    scene_texture tex = {0};
    char msg[384] = "";
    if (scene_image_read_rgb(path, &tex.width, &tex.height, &tex.rgb, msg, sizeof msg) != 0) {
        scene__fail(err, SCENE_ERR_IO, "%s", msg);
        return -1;
    }
    if (msg[0]) /* read, but damaged: it loads (docs/SCENE_FORMAT.md), never silently */
        fprintf(stderr, "fxcache: warning: %s\n", msg);
    return scene__add_texture_rgb(s, path, tex.width, tex.height, tex.rgb, err);
}

int32_t scene__add_texture_memory(scene *s, const char *name, const void *data, size_t len, scene_error *err)
{
    int32_t known = texture_named(s, name);
    if (known >= 0)
        return known;
    scene_texture tex = {0};
    char msg[384] = "";
    if (scene_image_read_rgb_memory(name, data, len, &tex.width, &tex.height, &tex.rgb, msg, sizeof msg) !=
        0) {
        scene__fail(err, SCENE_ERR_IO, "%s", msg);
        return -1;
    }
    if (msg[0]) /* read, but damaged: it loads (docs/SCENE_FORMAT.md), never silently */
        fprintf(stderr, "fxcache: warning: %s\n", msg);
    return scene__add_texture_rgb(s, name, tex.width, tex.height, tex.rgb, err);
}

int32_t scene__add_texture_rgb(scene *s, const char *path, uint32_t width, uint32_t height, float *rgb,
                               scene_error *err)
{
    scene_texture tex = {.width = width, .height = height, .rgb = rgb};
    /* An albedo is a reflectance, 0..1 (as a material's colour is clamped on import): a float texture (EXR, HDR)
     * may hold more, which would reflect more light than arrives (a closed room's indirect light then grows
     * without bound, to FLT_MAX), or less than 0. */
    for (size_t i = 0; i < (size_t)tex.width * tex.height * 3; i++)
        tex.rgb[i] = fminf(fmaxf(tex.rgb[i], 0.0f), 1.0f);
    snprintf(tex.path, sizeof tex.path, "%s", path);
    bool mips_ok = build_mips(&tex);
    if (!mips_ok || !scene__grow((void **)&s->textures, (size_t)s->texture_count + 1, sizeof *s->textures)) {
        for (uint32_t l = 0; l < tex.levels; l++)
            free(tex.mip_rgb[l]);
        scene__fail(err, SCENE_ERR_NOMEM, "out of memory adding texture %s", path);
        return -1;
    }
    s->textures[s->texture_count] = tex;
    return (int32_t)s->texture_count++;
}

/* Per textured triangle, log2 of its texture's texels per metre: sqrt(UV area in texels / world area). */
scene_result scene__compute_texture_lods(scene *s, scene_error *err)
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
        double uv_area = 0.5 *
                         fabs(((double)uv[2] - uv[0]) * ((double)uv[5] - uv[1]) -
                              ((double)uv[4] - uv[0]) * ((double)uv[3] - uv[1])) *
                         (double)tex->width * (double)tex->height;
        double world_area = scene_triangle_area(s, t);
        if (uv_area > 0 && world_area > 0 && isfinite(uv_area))
            s->tri_texture_lod[t] = (float)(0.5 * log2(uv_area / world_area));
    }
    return SCENE_OK;
}

/* Settles the local frame: the origin from the bounds of every staged mesh; the meshes welded and cleaned
 * again from their double positions when the provisional frame (the first mesh's) differs, so the result is
 * that of one pass in the final frame; point lights and the camera moved into the frame. */
/* The four texels (x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1) of a width x height level with
 * wrap-around addressing, for x0 in [-1, width - 1] and y0 in [-1, height - 1]: inside the image (most
 * lookups) directly, else wrapped around. */
FXC_HOT_INLINE void texel_corners(const float *texels, int64_t w, int64_t h, int64_t x0, int64_t y0,
                                  const float **p00, const float **p10, const float **p01, const float **p11)
{
    if (x0 >= 0 && x0 + 1 < w && y0 >= 0 && y0 + 1 < h) {
        *p00 = texels + 3 * ((size_t)y0 * (size_t)w + (size_t)x0);
        *p10 = *p00 + 3;
        *p01 = *p00 + 3 * (size_t)w;
        *p11 = *p01 + 3;
        return;
    }
    int64_t column[2], row[2];
    bool column_bad[2], row_bad[2];
    for (int d = 0; d < 2; d++) {
        int64_t xi = x0 + d, yi = y0 + d;
        column[d] = xi < 0 ? xi + w : (xi >= w ? xi - w : xi);
        row[d] = yi < 0 ? yi + h : (yi >= h ? yi - h : yi);
        column_bad[d] = column[d] < 0 || column[d] >= w;
        row_bad[d] = row[d] < 0 || row[d] >= h;
    }
    const float *corner[2][2];
    for (int dy = 0; dy < 2; dy++)
        for (int dx = 0; dx < 2; dx++) {
            size_t xi = (size_t)column[dx], yi = (size_t)row[dy];
            if (column_bad[dx] || row_bad[dy]) /* only for a u or v so large floorf lost precision */
                xi = 0, yi = 0;
            corner[dy][dx] = texels + 3 * (yi * (size_t)w + xi);
        }
    *p00 = corner[0][0], *p10 = corner[0][1], *p01 = corner[1][0], *p11 = corner[1][1];
}

/* Bilinear lookup in mip level `level` of a texture with wrap-around addressing; (u, v) with v = 0 at the
 * bottom of the image. */
FXC_HOT_INLINE void texture_sample(const scene_texture *tex, uint32_t level, float u, float v, float out[3])
{
    /* Level 0 straight from rgb: a texture filled by hand may have no mip chain. */
    const float *texels = level ? tex->mip_rgb[level] : tex->rgb;
    uint32_t width = level ? tex->mip_width[level] : tex->width,
             height = level ? tex->mip_height[level] : tex->height;
    if (!isfinite(u) || !isfinite(v)) {
        u = 0;
        v = 0;
    }
    float x = (u - floorf(u)) * (float)width - 0.5f;
    float y = (1.0f - (v - floorf(v))) * (float)height - 0.5f;
    float fx = floorf(x), fy = floorf(y);
    float ax = x - fx, ay = y - fy;
    /* x lies in [-0.5, width - 0.5], so x0 + dx lies in [-1, width]: one wrap step, no division. */
    const float *p00, *p10, *p01, *p11;
    texel_corners(texels, width, height, (int64_t)fx, (int64_t)fy, &p00, &p10, &p01, &p11);
    float wx0 = 1 - ax, wx1 = ax, wy0 = 1 - ay, wy1 = ay;
    float w00 = wx0 * wy0, w10 = wx1 * wy0, w01 = wx0 * wy1, w11 = wx1 * wy1;
    /* Summed from 0 in the order (0, 0), (1, 0), (0, 1), (1, 1), written out: a loop over the three channels
     * stayed a loop at -O2. */
    out[0] = 0.0f + w00 * p00[0] + w10 * p10[0] + w01 * p01[0] + w11 * p11[0];
    out[1] = 0.0f + w00 * p00[1] + w10 * p10[1] + w01 * p01[1] + w11 * p11[1];
    out[2] = 0.0f + w00 * p00[2] + w10 * p10[2] + w01 * p01[2] + w11 * p11[2];
}

/* scene_albedo_sample's body, inlined into the run. */
FXC_HOT_INLINE void albedo_sample(const scene_albedo_triangle *t, float u, float v, float footprint_log2,
                                  float out_rgb[3])
{
    if (!t->texture) {
        memcpy(out_rgb, t->diffuse, 3 * sizeof(float));
        return;
    }
    const float *uv = t->uv;
    float w0 = 1 - u - v;
    float tu = w0 * uv[0] + u * uv[2] + v * uv[4];
    float tv = w0 * uv[1] + u * uv[3] + v * uv[5];
    const scene_texture *tex = t->texture;
    float level = footprint_log2 + t->lod;
    uint32_t mip = 0;
    if (level > 0.5f && tex->levels > 1)
        mip = level >= (float)(tex->levels - 1) ? tex->levels - 1 : (uint32_t)(level + 0.5f);
    float texel[3];
    texture_sample(tex, mip, tu, tv, texel);
    out_rgb[0] = texel[0] * t->diffuse[0];
    out_rgb[1] = texel[1] * t->diffuse[1];
    out_rgb[2] = texel[2] * t->diffuse[2];
}

/* Multiplies out_rgb by the vertex colour at barycentrics (u, v) of corners 1 and 2 of a triangle whose corner
 * colours are color[0..8]. */
static inline void apply_vertex_color(const float color[9], float u, float v, float out_rgb[3])
{
    float w0 = 1 - u - v;
    for (int k = 0; k < 3; k++)
        out_rgb[k] *= w0 * color[k] + u * color[3 + k] + v * color[6 + k];
}

void scene_albedo(const scene *s, uint32_t tri, float u, float v, float out_rgb[3])
{
    scene_albedo_filtered(s, tri, u, v, -1000.0f, out_rgb);
}

void scene_albedo_prepare(const scene *s, uint32_t tri, scene_albedo_triangle *out)
{
    const scene_material *m = &s->materials[s->meshes[s->tri_mesh[tri]].material];
    memcpy(out->diffuse, m->diffuse, sizeof out->diffuse);
    out->texture = NULL;
    out->color = s->corner_color ? s->corner_color + 9 * (size_t)tri : NULL;
    if (m->texture < 0 || (uint32_t)m->texture >= s->texture_count)
        return;
    out->texture = &s->textures[m->texture];
    memcpy(out->uv, s->corner_uv + 6 * (size_t)tri, sizeof out->uv);
    out->lod = s->tri_texture_lod ? s->tri_texture_lod[tri] : -1000.0f;
}

void scene_albedo_sample(const scene_albedo_triangle *t, float u, float v, float footprint_log2,
                         float out_rgb[3])
{
    albedo_sample(t, u, v, footprint_log2, out_rgb);
    if (t->color)
        apply_vertex_color(t->color, u, v, out_rgb);
}

/* The mip level albedo_sample reads for footprint_log2 on triangle t (textured). */
FXC_HOT_INLINE uint32_t albedo_mip(const scene_albedo_triangle *t, float footprint_log2)
{
    const scene_texture *tex = t->texture;
    float level = footprint_log2 + t->lod;
    uint32_t mip = 0;
    if (level > 0.5f && tex->levels > 1)
        mip = level >= (float)(tex->levels - 1) ? tex->levels - 1 : (uint32_t)(level + 0.5f);
    return mip;
}

/* Hits of one textured triangle per lanes call, and lanes per chunk (one AVX2 vector of floats). */
enum { ALBEDO_LANES = 64, ALBEDO_CHUNK = 8 };
/* The shortest stretch that goes through the lanes: their set-up (about 280 instructions: the call, the
 * copies, the constants) against about 65 saved per hit (callgrind, Sponza). */
enum { ALBEDO_MIN_STRETCH = 5 };

/* The per-hit arithmetic of albedo_sample for a stretch of hits on one textured triangle, in structure of
 * arrays: the same IEEE operations in the same order, so each lane's mip level, corner texel and bilinear
 * weights are what albedo_sample computes for that hit. The triangle's constants (corner UVs, lod, the
 * texture's level count) and the level's size are filled once for the stretch, the hits' (u, v, footprint)
 * are copied in as they lie; a lane whose own level differs from the stretch's (mip_ok 0) is sampled alone. */
typedef struct albedo_lanes {
    float uv[6], lod, top, width, height; /* top: the last level as a float (0 for one level) */
    int32_t levels, mip;                  /* the stretch's level */
    float u[ALBEDO_LANES], v[ALBEDO_LANES], footprint[ALBEDO_LANES];
    int32_t mip_ok[ALBEDO_LANES], x0[ALBEDO_LANES], y0[ALBEDO_LANES];
    float w00[ALBEDO_LANES], w10[ALBEDO_LANES], w01[ALBEDO_LANES], w11[ALBEDO_LANES];
} albedo_lanes;

/* The lanes of the first chunks * ALBEDO_CHUNK hits (vectorised: FXC_HOT_LANES, a fixed trip count per chunk). */
FXC_HOT_LANES static void albedo_lanes_fill(albedo_lanes *L, uint32_t chunks)
{
    const float uv0 = L->uv[0], uv1 = L->uv[1], uv2 = L->uv[2], uv3 = L->uv[3], uv4 = L->uv[4],
                uv5 = L->uv[5];
    const float lod = L->lod, top = L->top, width = L->width, height = L->height;
    const int32_t levels = L->levels, mip = L->mip;
    for (int c = 0; c < (int)chunks; c++) {
        for (int j = 0; j < ALBEDO_CHUNK; j++) {
            int i = c * ALBEDO_CHUNK + j;
            float u = L->u[i], v = L->v[i];
            float w0 = 1 - u - v;
            float tu = w0 * uv0 + u * uv2 + v * uv4;
            float tv = w0 * uv1 + u * uv3 + v * uv5;
            /* albedo_mip: 0, the last level, or the level rounded (converted only where it fits) */
            float level = L->footprint[i] + lod;
            int32_t last = (levels > 1) & (level >= top);
            int32_t middle = (levels > 1) & (level > 0.5f) & (level < top);
            float rounded = middle ? level + 0.5f : 0.0f;
            int32_t own = last ? levels - 1 : (int32_t)rounded;
            L->mip_ok[i] = own == mip;
            /* texture_sample: a non-finite u or v reads (0, 0) */
            int32_t finite = (fabsf(tu) <= FLT_MAX) & (fabsf(tv) <= FLT_MAX);
            tu = finite ? tu : 0.0f;
            tv = finite ? tv : 0.0f;
            float x = (tu - floorf(tu)) * width - 0.5f;
            float y = (1.0f - (tv - floorf(tv))) * height - 0.5f;
            float fx = floorf(x), fy = floorf(y);
            float ax = x - fx, ay = y - fy;
            L->x0[i] = (int32_t)fx; /* in [-1, width - 1]: x lies in [-0.5, width - 0.5] */
            L->y0[i] = (int32_t)fy;
            float wx0 = 1 - ax, wx1 = ax, wy0 = 1 - ay, wy1 = ay;
            L->w00[i] = wx0 * wy0;
            L->w10[i] = wx1 * wy0;
            L->w01[i] = wx0 * wy1;
            L->w11[i] = wx1 * wy1;
        }
    }
}

/* Hits first..end-1 (at most ALBEDO_LANES), all on textured triangle t: the level of the first hit's
 * footprint for the stretch, the lanes, then per hit the four texels and the filter (albedo_sample alone for
 * a hit at another level). */
FXC_HOT_INLINE void albedo_stretch(const scene_albedo_triangle *t, albedo_lanes *L, const float *u,
                                   const float *v, const float *footprint_log2, uint32_t first, uint32_t end,
                                   float (*out_rgb)[3])
{
    const scene_texture *tex = t->texture;
    uint32_t n = end - first, mip = albedo_mip(t, footprint_log2[first]);
    const float *texels = mip ? tex->mip_rgb[mip] : tex->rgb;
    uint32_t width = mip ? tex->mip_width[mip] : tex->width,
             height = mip ? tex->mip_height[mip] : tex->height;
    memcpy(L->uv, t->uv, sizeof L->uv);
    L->lod = t->lod;
    L->levels = (int32_t)tex->levels;
    L->top = tex->levels > 1 ? (float)(tex->levels - 1) : 0.0f;
    L->mip = (int32_t)mip;
    L->width = (float)width;
    L->height = (float)height;
    memcpy(L->u, u + first, n * sizeof(float));
    memcpy(L->v, v + first, n * sizeof(float));
    memcpy(L->footprint, footprint_log2 + first, n * sizeof(float));
    uint32_t chunks = (n + ALBEDO_CHUNK - 1) / ALBEDO_CHUNK;
    for (uint32_t i = n; i < chunks * ALBEDO_CHUNK; i++) /* defined values in the last chunk's spare lanes */
        L->u[i] = L->v[i] = L->footprint[i] = 0.0f;
    albedo_lanes_fill(L, chunks);
    const float d0 = t->diffuse[0], d1 = t->diffuse[1], d2 = t->diffuse[2];
    for (uint32_t i = 0; i < n; i++) {
        float *out = out_rgb[first + i];
        if (!L->mip_ok[i]) {
            albedo_sample(t, u[first + i], v[first + i], footprint_log2[first + i], out);
            continue;
        }
        const float *p00, *p10, *p01, *p11;
        texel_corners(texels, width, height, L->x0[i], L->y0[i], &p00, &p10, &p01, &p11);
        float w00 = L->w00[i], w10 = L->w10[i], w01 = L->w01[i], w11 = L->w11[i];
        float r = 0.0f + w00 * p00[0] + w10 * p10[0] + w01 * p01[0] + w11 * p11[0];
        float g = 0.0f + w00 * p00[1] + w10 * p10[1] + w01 * p01[1] + w11 * p11[1];
        float b = 0.0f + w00 * p00[2] + w10 * p10[2] + w01 * p01[2] + w11 * p11[2];
        out[0] = r * d0;
        out[1] = g * d1;
        out[2] = b * d2;
    }
}

/* Per stretch of hits on one triangle: its material looked up once; a textured one's per-hit arithmetic in
 * lanes over the stretch (albedo_stretch: no per-hit fill of triangle data, which made a lanes version over
 * the whole run slower), the texel reads and the filter per hit. */
FXC_HOT_CLONES void scene_albedo_run(const scene *s, const uint32_t *tri, const float *u, const float *v,
                                     const float *footprint_log2, uint32_t count, float (*out_rgb)[3])
{
    scene_albedo_triangle t;
    albedo_lanes L;
    for (uint32_t first = 0, end; first < count; first = end) {
        uint32_t limit = count - first < ALBEDO_LANES ? count : first + ALBEDO_LANES;
        for (end = first + 1; end < limit && tri[end] == tri[first];)
            end++;
        scene_albedo_prepare(s, tri[first], &t);
        if (!t.texture) {
            for (uint32_t i = first; i < end; i++)
                memcpy(out_rgb[i], t.diffuse, sizeof out_rgb[i]);
        } else if (end - first < ALBEDO_MIN_STRETCH) { /* the lanes' set-up costs more than they save */
            for (uint32_t i = first; i < end; i++)
                albedo_sample(&t, u[i], v[i], footprint_log2[i], out_rgb[i]);
        } else {
            albedo_stretch(&t, &L, u, v, footprint_log2, first, end, out_rgb);
        }
        if (t.color) /* vertex colours (a scene without them: one test per stretch) */
            for (uint32_t i = first; i < end; i++)
                apply_vertex_color(t.color, u[i], v[i], out_rgb[i]);
    }
}

void scene_albedo_filtered(const scene *s, uint32_t tri, float u, float v, float footprint_log2,
                           float out_rgb[3])
{
    scene_albedo_triangle t;
    scene_albedo_prepare(s, tri, &t);
    scene_albedo_sample(&t, u, v, footprint_log2, out_rgb);
}

/* The mip level whose texels are as large as the triangle: half the log2 of its UV area in texels (level 0
 * texels), rounded, within the chain. */
static uint32_t mean_level(const scene_texture *tex, const float uv[6])
{
    double uv_area = 0.5 *
                     fabs(((double)uv[2] - uv[0]) * ((double)uv[5] - uv[1]) -
                          ((double)uv[4] - uv[0]) * ((double)uv[3] - uv[1])) *
                     (double)tex->width * (double)tex->height;
    if (tex->levels <= 1 || !(uv_area > 1.0))
        return 0;
    double level = 0.5 * log2(uv_area);
    if (!(level < (double)(tex->levels - 1)))
        return tex->levels - 1;
    return (uint32_t)(level + 0.5);
}

scene_result scene__compute_texture_means(scene *s, scene_error *err)
{
    free(s->tri_texture_mean);
    s->tri_texture_mean = malloc(sizeof(float) * 3 * (size_t)s->triangle_count);
    if (!s->tri_texture_mean)
        return scene__fail(err, SCENE_ERR_NOMEM, "out of memory computing texture means");
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        const scene_material *m = &s->materials[s->meshes[s->tri_mesh[t]].material];
        float *out = s->tri_texture_mean + 3 * (size_t)t;
        out[0] = out[1] = out[2] = 1.0f;
        if (m->texture >= 0 && (uint32_t)m->texture < s->texture_count) {
            const scene_texture *tex = &s->textures[m->texture];
            const float *uv = s->corner_uv + 6 * (size_t)t;
            float cu = (uv[0] + uv[2] + uv[4]) * (1.0f / 3.0f), cv = (uv[1] + uv[3] + uv[5]) * (1.0f / 3.0f);
            texture_sample(tex, mean_level(tex, uv), cu, cv, out);
        }
        if (s->corner_color)
            apply_vertex_color(s->corner_color + 9 * (size_t)t, 1.0f / 3.0f, 1.0f / 3.0f, out);
    }
    return SCENE_OK;
}

void scene_albedo_mean(const scene *s, uint32_t tri, float out_rgb[3])
{
    const scene_material *m = &s->materials[s->meshes[s->tri_mesh[tri]].material];
    if (s->tri_texture_mean) {
        const float *mean = s->tri_texture_mean + 3 * (size_t)tri;
        out_rgb[0] = m->diffuse[0] * mean[0];
        out_rgb[1] = m->diffuse[1] * mean[1];
        out_rgb[2] = m->diffuse[2] * mean[2];
        return;
    }
    float mean[3] = {1.0f, 1.0f, 1.0f}; /* what scene__compute_texture_means stores */
    if (m->texture >= 0 && (uint32_t)m->texture < s->texture_count) {
        const scene_texture *tex = &s->textures[m->texture];
        const float *uv = s->corner_uv + 6 * (size_t)tri;
        texture_sample(tex, mean_level(tex, uv), (uv[0] + uv[2] + uv[4]) * (1.0f / 3.0f),
                       (uv[1] + uv[3] + uv[5]) * (1.0f / 3.0f), mean);
    }
    if (s->corner_color)
        apply_vertex_color(s->corner_color + 9 * (size_t)tri, 1.0f / 3.0f, 1.0f / 3.0f, mean);
    for (int k = 0; k < 3; k++)
        out_rgb[k] = m->diffuse[k] * mean[k];
}

/* ---- emission ----------------------------------------------------------------------------------------- */

bool scene_material_emits(const scene_material *m)
{
    return m->emission[0] > 0.0f || m->emission[1] > 0.0f || m->emission[2] > 0.0f;
}

void scene_emission_refresh(scene *s)
{
    s->emissive = false;
    for (uint32_t i = 0; i < s->mesh_count; i++)
        if (s->meshes[i].triangle_count > 0 && s->meshes[i].material < s->material_count)
            s->emissive |= scene_material_emits(&s->materials[s->meshes[i].material]);
}

void scene_emission_power(const scene *s, uint32_t *emitting_materials, double power_rgb[3])
{
    uint32_t count = 0;
    power_rgb[0] = power_rgb[1] = power_rgb[2] = 0.0;
    for (uint32_t m = 0; m < s->material_count; m++) {
        const scene_material *material = &s->materials[m];
        if (!scene_material_emits(material))
            continue;
        double area = 0.0;
        bool used = false;
        for (uint32_t i = 0; i < s->mesh_count; i++) {
            const scene_mesh *mesh = &s->meshes[i];
            if (mesh->material != m || mesh->triangle_count == 0)
                continue;
            used = true;
            for (uint32_t t = mesh->first_triangle; t < mesh->first_triangle + mesh->triangle_count; t++)
                area += scene_triangle_area(s, t);
        }
        if (!used)
            continue;
        count++;
        for (int k = 0; k < 3; k++) /* a Lambertian emitter's exitance is pi x its radiance */
            power_rgb[k] += 3.14159265358979323846 * (double)material->emission[k] * area;
    }
    *emitting_materials = count;
}

double scene_emission_area_fraction(const scene *s)
{
    double all = 0.0, emitting = 0.0;
    for (uint32_t i = 0; i < s->mesh_count; i++) {
        const scene_mesh *mesh = &s->meshes[i];
        bool emits =
            mesh->material < s->material_count && scene_material_emits(&s->materials[mesh->material]);
        for (uint32_t t = mesh->first_triangle; t < mesh->first_triangle + mesh->triangle_count; t++) {
            double area = scene_triangle_area(s, t);
            all += area;
            if (emits)
                emitting += area;
        }
    }
    return all > 0.0 ? emitting / all : 0.0;
}

void scene_emission_add(const scene *s, uint32_t tri, const float view_normal[3], float out_rgb[3])
{
    const float *n = s->tri_normal + 3 * (size_t)tri;
    if (!(view_normal[0] * n[0] + view_normal[1] * n[1] + view_normal[2] * n[2] > 0.0f))
        return;
    const scene_material *m = &s->materials[s->meshes[s->tri_mesh[tri]].material];
    for (int k = 0; k < 3; k++) {
        float sum = out_rgb[k] + m->emission[k];
        out_rgb[k] = sum <= FLT_MAX ? sum : FLT_MAX;
    }
}
