/* Mesh-file import through Assimp's C API: OBJ, 3DS, PLY, glTF 2 and whatever else Assimp reads.
 * A ".gz" file is decompressed with zlib first and handed to Assimp from memory with the inner extension
 * as the format hint. Meshes are triangulated by Assimp and pre-transformed to world space (or, when some
 * node places a mesh through a mirroring transform, placed node by node here: import_node()); points and
 * lines are dropped and counted; every mesh then goes through scene__add_mesh(), which checks, welds and
 * cleans it. Diffuse colours, emissive colours (times the emissive intensity) and diffuse textures (read
 * with OpenImageIO, relative to the model file, with a case-insensitive fallback since many old models name
 * "KAMEN.JPG" for kamen.jpg) become materials. */
#include "scene_internal.h"
#include "cerr_capture.h"
#include "scene_import_nodes.h"

#include <assimp/cimport.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>
#include <zlib.h>

/* Largest decompressed .gz model accepted (bytes): Assimp takes the length as unsigned int. */
#define IMPORT_MAX_GZ_BYTES ((size_t)1 << 31)

/* Reads a gzip file completely into a malloc'd buffer. */
static scene_result read_gz(const char *path, char **out, size_t *out_len, scene_error *err)
{
    gzFile gz = gzopen(path, "rb");
    if (!gz)
        return scene__fail(err, SCENE_ERR_IO, "%s: cannot open: %s", path, strerror(errno ? errno : EIO));
    size_t cap = 1 << 20, len = 0;
    char *buf = malloc(cap);
    scene_result rc = SCENE_OK;
    while (buf) {
        if (len == cap) {
            if (cap >= IMPORT_MAX_GZ_BYTES) {
                rc = scene__fail(err, SCENE_ERR_RANGE, "%s: decompresses to more than %zu bytes", path,
                                 IMPORT_MAX_GZ_BYTES);
                break;
            }
            char *bigger = realloc(buf, cap * 2);
            if (!bigger) {
                rc = scene__fail(err, SCENE_ERR_NOMEM, "%s: out of memory decompressing", path);
                break;
            }
            buf = bigger;
            cap *= 2;
        }
        int n = gzread(gz, buf + len, (unsigned)(cap - len));
        if (n < 0) {
            int zerr = 0;
            const char *zmsg = gzerror(gz, &zerr);
            rc = scene__fail(err, SCENE_ERR_FORMAT, "%s: corrupt gzip data: %s", path, zmsg);
            break;
        }
        if (n == 0)
            break;
        len += (size_t)n;
    }
    gzclose(gz);
    if (!buf)
        return scene__fail(err, SCENE_ERR_NOMEM, "%s: out of memory decompressing", path);
    if (rc != SCENE_OK) {
        free(buf);
        return rc;
    }
    *out = buf;
    *out_len = len;
    return SCENE_OK;
}

/* Checks what Assimp returns, whatever its own validation let through: every face has vertices, every
 * index lies within its mesh. */
static scene_result check_faces(const char *path, const struct aiScene *ai, scene_error *err)
{
    for (uint32_t i = 0; i < ai->mNumMeshes; i++) {
        const struct aiMesh *mesh = ai->mMeshes[i];
        if (!mesh || (mesh->mNumFaces > 0 && !mesh->mFaces) || (mesh->mNumVertices > 0 && !mesh->mVertices))
            return scene__fail(err, SCENE_ERR_FORMAT, "%s: mesh %u is incomplete", path, i);
        for (uint32_t f = 0; f < mesh->mNumFaces; f++) {
            const struct aiFace *face = &mesh->mFaces[f];
            if (face->mNumIndices == 0 || !face->mIndices)
                return scene__fail(err, SCENE_ERR_FORMAT, "%s: mesh %u face %u has no vertices", path, i, f);
            for (uint32_t k = 0; k < face->mNumIndices; k++)
                if (face->mIndices[k] >= mesh->mNumVertices)
                    return scene__fail(err, SCENE_ERR_FORMAT,
                                       "%s: mesh %u face %u uses vertex %u, but the mesh has %u vertices",
                                       path, i, f, face->mIndices[k], mesh->mNumVertices);
        }
    }
    return SCENE_OK;
}

/* Assimp's last error as one line: it can quote the file, line ends and all ("Unsupported x-file format
 * '4\nMe'"), so control characters become spaces. */
static const char *assimp_error(char *text, size_t cap)
{
    snprintf(text, cap, "%s", aiGetErrorString());
    for (char *p = text; *p; p++)
        if ((unsigned char)*p < 32 || *p == 127)
            *p = ' ';
    return text;
}

/* Assimp's log lines that mean it dropped or changed geometry while reading a file it still returns: its
 * glTF 2 reader drops faces with out-of-range indices and the vertices of an incomplete primitive, its PLY
 * reader skips an element it cannot parse (Assimp's own test models glTF2/IndexOutOfRange, .../
 * IncorrectVertexArrays and PLY/issue623.ply load that way). Found by reading every file of Debian's
 * assimp-testmodels, the shared scenes and the bunny through a log stream: none of these scenes logs one,
 * and Assimp's many other warnings (unknown chunks, Blender DNA fields) do not mean lost geometry. */
static const char *const assimp_dropped_markers[] = {
    "were dropped",          /* glTF 2: faces with out-of-range indices; vertices beyond a primitive */
    "out-of-range indices",  /* glTF 2 */
    "index is out of range", /* OFF (refused earlier by check_off) and others */
    "Skipping this element instance", /* PLY: an element whose properties do not parse */
};

/* What one import logged of those lines: their count and the first, cleaned to one line. */
typedef struct assimp_dropped_log {
    unsigned count;
    char first[200];
} assimp_dropped_log;

/* Assimp's log stream callback during an import (user: the assimp_dropped_log). Messages look like
 * "Warn,  T0: Some faces had out-of-range indices. Those faces were dropped.\n". */
static void assimp_log_line(const char *message, char *user)
{
    assimp_dropped_log *log = (assimp_dropped_log *)(void *)user;
    bool dropped = false;
    for (size_t i = 0; i < sizeof assimp_dropped_markers / sizeof assimp_dropped_markers[0]; i++)
        dropped |= strstr(message, assimp_dropped_markers[i]) != NULL;
    if (!dropped || (strncmp(message, "Warn", 4) != 0 && strncmp(message, "Error", 5) != 0))
        return;
    if (log->count++ == 0) {
        const char *text = strstr(message, ": ");
        snprintf(log->first, sizeof log->first, "%s", text ? text + 2 : message);
        for (char *p = log->first; *p; p++)
            if ((unsigned char)*p < 32 || *p == 127)
                *p = ' ';
        for (size_t n = strlen(log->first); n > 0 && log->first[n - 1] == ' ';)
            log->first[--n] = '\0';
    }
}

/* Assimp's logger is one for the process: imports that listen to it take turns. */
static pthread_mutex_t assimp_log_lock = PTHREAD_MUTEX_INITIALIZER;

/* How many meshes the node graph below node places (references), counting a mesh once per reference.
 * Assimp's validation has checked every index is below mNumMeshes and that the graph is a tree. */
static uint64_t placed_meshes(const struct aiNode *node, unsigned depth)
{
    if (!node || depth > 10000)
        return 0;
    uint64_t placed = node->mNumMeshes;
    for (uint32_t i = 0; i < node->mNumChildren; i++)
        placed += placed_meshes(node->mChildren[i], depth + 1);
    return placed;
}

/* Checks what Assimp's pre-transform step would fail on: it throws when no node places any mesh ("all
 * meshes are orphaned"), and aiApplyPostProcessing() then crashes releasing the scene (an AC3D object with
 * vertices but no surfaces gives one unplaced mesh of points). Says which case it is: no surfaces at all,
 * or surfaces no node places. */
static scene_result check_scene_graph(const char *path, const struct aiScene *ai, scene_error *err)
{
    if (placed_meshes(ai->mRootNode, 0) > 0)
        return SCENE_OK;
    uint64_t polygons = 0, points_lines = 0;
    for (uint32_t i = 0; i < ai->mNumMeshes; i++)
        for (uint32_t f = 0; f < ai->mMeshes[i]->mNumFaces; f++) {
            if (ai->mMeshes[i]->mFaces[f].mNumIndices >= 3)
                polygons++;
            else
                points_lines++;
        }
    if (ai->mNumMeshes == 0)
        return scene__fail(err, SCENE_ERR_EMPTY, "%s: no usable triangles in the file (it has no meshes)",
                           path);
    if (polygons == 0)
        return scene__fail(err, SCENE_ERR_EMPTY,
                           "%s: no usable triangles in the file (only %llu points and lines)", path,
                           (unsigned long long)points_lines);
    return scene__fail(
        err, SCENE_ERR_EMPTY,
        "%s: no usable triangles in the file (its %u meshes are not placed by any node of its scene "
        "graph)",
        path, ai->mNumMeshes);
}

/* The folder part of path (with a trailing slash), or "" for a bare file name. */
static void folder_of(const char *path, char *dir, size_t cap)
{
    const char *slash = strrchr(path, '/');
    size_t n = slash ? (size_t)(slash - path) + 1 : 0;
    if (n >= cap)
        n = cap - 1;
    memcpy(dir, path, n);
    dir[n] = 0;
}

/* Resolves a texture name from a model file: backslashes become slashes, the path is taken relative to
 * the model's folder, and when that file is absent a case-insensitive match of the file name in that
 * folder is used, then the name's last folder and file name beside the model's folder (a path from the
 * author's machine, "D:\\work\\models\\OBJ\\wood.jpg" read from models/FBX/ finds models/OBJ/wood.jpg: Assimp's
 * FBX spider). Returns false when nothing matches. */
static bool resolve_texture(const char *model_dir, const char *name, char *out, size_t cap)
{
    char clean[512];
    snprintf(clean, sizeof clean, "%s", name);
    for (char *p = clean; *p; p++)
        if (*p == '\\')
            *p = '/';
    if (clean[0] == '/')
        snprintf(out, cap, "%s", clean);
    else
        snprintf(out, cap, "%s%s", model_dir, clean);
    FILE *f = fopen(out, "rb");
    if (f) {
        fclose(f);
        return true;
    }
    const char *base = strrchr(clean, '/');
    base = base ? base + 1 : clean;
    DIR *dir = opendir(model_dir[0] ? model_dir : ".");
    if (!dir)
        return false;
    bool found = false;
    for (struct dirent *e; (e = readdir(dir)) != NULL;)
        if (strcasecmp(e->d_name, base) == 0) {
            snprintf(out, cap, "%s%s", model_dir, e->d_name);
            found = true;
            break;
        }
    closedir(dir);
    /* The last folder and file name, from the model's folder's parent. */
    char parent[512];
    snprintf(parent, sizeof parent, "%s", model_dir[0] ? model_dir : "./");
    size_t n = strlen(parent);
    while (n > 0 && parent[n - 1] == '/')
        parent[--n] = 0;
    const char *folder = base > clean + 1 ? base - 2 : NULL;
    while (folder && folder > clean && folder[-1] != '/')
        folder--;
    if (found || !folder || folder == base - 1 || !strrchr(parent, '/'))
        return found;
    *(strrchr(parent, '/') + 1) = 0;
    snprintf(out, cap, "%s%s", parent, folder);
    f = fopen(out, "rb");
    if (f)
        fclose(f);
    return f != NULL;
}

/* True when one of the file's materials before `index` names the same diffuse texture: its warning was
 * printed already (a model of many materials sharing one missing texture printed it once per material:
 * Assimp's MDC spider, 19 lines). */
static bool texture_warned(const struct aiScene *ai, uint32_t index, const struct aiString *texture)
{
    for (uint32_t j = 0; j < index; j++) {
        struct aiString other;
        if (aiGetMaterialTextureCount(ai->mMaterials[j], aiTextureType_DIFFUSE) > 0 &&
            aiGetMaterialTexture(ai->mMaterials[j], aiTextureType_DIFFUSE, 0, &other, NULL, NULL, NULL, NULL,
                                 NULL, NULL) == aiReturn_SUCCESS &&
            other.length == texture->length && memcmp(other.data, texture->data, other.length) == 0)
            return true;
    }
    return false;
}

/* The texture a material names that the file itself holds (a GLB's images, an FBX's embedded media), or
 * NULL: "*N" is the file's N-th texture (glTF), another name is looked up by its file name among the
 * embedded textures' names (FBX, which also names a file). */
static const struct aiTexture *embedded_texture(const struct aiScene *ai, const char *name)
{
    if (name[0] == '*') {
        char *end = NULL;
        unsigned long index = strtoul(name + 1, &end, 10);
        return end != name + 1 && *end == 0 && index < ai->mNumTextures ? ai->mTextures[index] : NULL;
    }
    const char *base = name;
    for (const char *p = name; *p; p++)
        if (*p == '/' || *p == '\\')
            base = p + 1;
    for (uint32_t i = 0; i < ai->mNumTextures; i++) {
        const char *file = ai->mTextures[i]->mFilename.data, *file_base = file;
        for (const char *p = file; *p; p++)
            if (*p == '/' || *p == '\\')
                file_base = p + 1;
        if (file_base[0] && strcasecmp(file_base, base) == 0)
            return ai->mTextures[i];
    }
    return NULL;
}

/* The sRGB transfer function, decoded to linear (8-bit texels are sRGB, as image files' are). */
static float srgb_to_linear(float c)
{
    return c <= 0.04045f ? c / 12.92f : powf((c + 0.055f) / 1.055f, 2.4f);
}

/* Adds a texture the file holds: encoded bytes (mHeight 0: PNG, JPEG, ..., named by Assimp's format hint)
 * through OpenImageIO, or Assimp's raw BGRA texels. Returns its index or -1 with err filled. */
static int32_t add_embedded_texture(scene *s, const char *path, const char *name, const struct aiTexture *tex,
                                    scene_error *err)
{
    char label[512];
    char hint[sizeof tex->achFormatHint + 1];
    snprintf(hint, sizeof hint, "%.*s", (int)sizeof tex->achFormatHint, tex->achFormatHint);
    snprintf(label, sizeof label, "%s[embedded %s].%s", path, name, hint[0] ? hint : "png");
    if (tex->mHeight == 0)
        return scene__add_texture_memory(s, label, tex->pcData, tex->mWidth, err);
    if (tex->mWidth > 65536 || tex->mHeight > 65536) {
        scene__fail(err, SCENE_ERR_RANGE, "%s: image size out of range (1..65536 per side)", label);
        return -1;
    }
    size_t texels = (size_t)tex->mWidth * tex->mHeight;
    double need = (double)texels * 3 * sizeof(float),
           memory = (double)sysconf(_SC_PHYS_PAGES) * sysconf(_SC_PAGESIZE);
    if (memory > 0 && need > memory) { /* as image files' headers are checked before anything is allocated */
        scene__fail(err, SCENE_ERR_RANGE,
                    "%s: %u x %u texels need %.3g GiB as floats, more than this machine has", label,
                    tex->mWidth, tex->mHeight, need / (1u << 30));
        return -1;
    }
    float *rgb = malloc(sizeof(float) * 3 * texels);
    if (!rgb) {
        scene__fail(err, SCENE_ERR_NOMEM, "%s: out of memory", label);
        return -1;
    }
    for (size_t i = 0; i < texels; i++) {
        rgb[3 * i] = srgb_to_linear(tex->pcData[i].r / 255.0f);
        rgb[3 * i + 1] = srgb_to_linear(tex->pcData[i].g / 255.0f);
        rgb[3 * i + 2] = srgb_to_linear(tex->pcData[i].b / 255.0f);
    }
    return scene__add_texture_rgb(s, label, tex->mWidth, tex->mHeight, rgb, err);
}

/* How a mesh reads its material's texture: which texture coordinate set, and per axis (u, v) whether the
 * coordinate is remapped to (c - offset) x scale: halved where the material's texture was mirrored into one
 * twice as wide or high (mirrored_texture()), moved and shrunk where it was clamped (clamped_texture()). */
typedef struct import_uv {
    uint8_t set;
    bool
        transform; /* glTF's KHR_texture_transform first: (u, v) -> (xf[0] u + xf[1] v + xf[2], xf[3] u + ...) */
    double xf[6];
    bool remap[2];
    float offset[2], scale[2];
} import_uv;

/* A coordinate pair as the material reads it: through its texture transform (the remap comes after). */
static void uv_transformed(const import_uv *m, float u, float v, float out[2])
{
    out[0] = u;
    out[1] = v;
    if (m->transform) {
        out[0] = (float)(m->xf[0] * u + m->xf[1] * v + m->xf[2]);
        out[1] = (float)(m->xf[3] * u + m->xf[4] * v + m->xf[5]);
    }
}

/* glTF's KHR_texture_transform of a material's base-colour texture, as Assimp 5.2.5 hands it over: an
 * aiUVTransform whose rotation is the glTF one negated and whose translation Assimp computed from the glTF
 * offset, scale and rotation for its own conventions (its glTF reader's formula, inverted here to recover
 * the offset). The glTF transform, uv' = offset + R(rotation) (scale x uv) with R = [cos sin; -sin cos] on
 * glTF's coordinates (v down from the top: the extension's GLSL matrix read by rows, which is what Khronos's
 * TextureTransformTest asset shows as right; by columns its arrow points at the "opposite direction" marker),
 * is written into m->xf on Assimp's (v = 1 - v_glTF). */
static void gltf_texture_transform(const struct aiMaterial *am, import_uv *m)
{
    struct aiUVTransform t;
    unsigned n = sizeof t / sizeof(ai_real);
    if (aiGetMaterialFloatArray(am, AI_MATKEY_UVTRANSFORM(aiTextureType_DIFFUSE, 0), (ai_real *)&t, &n) !=
            aiReturn_SUCCESS ||
        n != sizeof t / sizeof(ai_real))
        return;
    double sx = t.mScaling.x, sy = t.mScaling.y, rot = -(double)t.mRotation, c = cos(rot), sn = sin(rot);
    double o0 = t.mTranslation.x - 0.5 * sx * (-c + sn + 1);
    double o1 = 0.5 * sy * (sn + c - 1) + 1 - sy - t.mTranslation.y;
    const double xf[6] = {c * sx, -sn * sy, o0 + sn * sy, sn * sx, c * sy, 1 - o1 - c * sy};
    for (int k = 0; k < 6; k++)
        if (!isfinite(xf[k]))
            return;
    memcpy(m->xf, xf, sizeof xf);
    m->transform = true;
}

/* The largest side, in texels, of a clamped texture's padded copy (clamped_texture()). */
#define IMPORT_CLAMP_MAX_SIDE 16384

static int32_t replace_plain(scene *s, int32_t texture, int32_t added);

/* A mirrored repeat (glTF's MIRRORED_REPEAT) of texture index `texture` along u and/or v, as a plain repeat:
 * the texture followed by its mirror image, twice as wide (or high), read at half the coordinate. Bilinear
 * filtering and the mip chain see the same texels as mirrored addressing would (the seam's two texels are
 * the edge texel twice, as in a mirror), and texels per metre stay as they were. Returns the new texture's
 * index (it takes the plain one's place when nothing else uses that), or -1 with err filled. */
static int32_t mirrored_texture(scene *s, int32_t texture, bool mirror_u, bool mirror_v, scene_error *err)
{
    const scene_texture *src = &s->textures[texture];
    uint32_t w = src->width, h = src->height, mw = mirror_u ? 2 * w : w, mh = mirror_v ? 2 * h : h;
    if (mw > 65536 || mh > 65536) { /* a side the mip chain (SCENE_TEXTURE_MAX_LEVELS) cannot reach 1 from */
        scene__fail(err, SCENE_ERR_RANGE, "%s: mirrored, it would be %u x %u texels (at most 65536 a side)",
                    src->path, mw, mh);
        return -1;
    }
    float *rgb = malloc(sizeof(float) * 3 * (size_t)mw * mh);
    char name[300];
    snprintf(name, sizeof name, "%.250s (mirrored%s%s)", src->path, mirror_u ? " u" : "",
             mirror_v ? " v" : "");
    if (!rgb) {
        scene__fail(err, SCENE_ERR_NOMEM, "%s: out of memory", name);
        return -1;
    }
    for (uint32_t y = 0; y < mh; y++)
        for (uint32_t x = 0; x < mw; x++) {
            uint32_t sx = x < w ? x : 2 * w - 1 - x, sy = y < h ? y : 2 * h - 1 - y;
            memcpy(rgb + 3 * ((size_t)y * mw + x), src->rgb + 3 * ((size_t)sy * w + sx), sizeof(float) * 3);
        }
    return replace_plain(s, texture, scene__add_texture_rgb(s, name, mw, mh, rgb, err));
}

/* After a texture `added` was made from the plain one `texture` (mirrored_texture(), clamped_texture()): the
 * plain texture goes when it was loaded just now for this material and no other material uses it, the new
 * one taking its index. Returns the new texture's index, or -1 as added is. */
static int32_t replace_plain(scene *s, int32_t texture, int32_t added)
{
    bool used = (uint32_t)texture + 2 != s->texture_count;
    for (uint32_t i = 0; i < s->material_count && !used; i++)
        used = s->materials[i].texture == texture;
    if (added < 0 || used)
        return added;
    for (uint32_t l = 0; l < s->textures[texture].levels; l++)
        free(s->textures[texture].mip_rgb[l]);
    s->textures[texture] = s->textures[added];
    s->texture_count--;
    return texture;
}

/* A texture clamped to its edge (glTF's CLAMP_TO_EDGE, Assimp's clamp and decal modes) along the axes `axis`
 * says, read by coordinates that leave 0..1: as a plain repeat of a padded copy that covers the coordinates'
 * whole periods [lo, hi) (lo = floor of the least coordinate, hi = ceil of the greatest) plus one texel each
 * side, each texel the clamped lookup of the original's (its edge texel outside it). Read at
 * (c - lo + 1 / n) x n / (n (hi - lo) + 2) for a side of n texels, it gives the texels, the bilinear filter
 * and the texel density of clamped addressing; the margin keeps the copy's own wrap-around away from every
 * coordinate the meshes use. range[axis] holds the least and greatest coordinate. Returns the new texture's
 * index and fills uv's remap for the axes, or -1 with err filled (a copy wider than IMPORT_CLAMP_MAX_SIDE). */
static int32_t clamped_texture(scene *s, int32_t texture, const bool axis[2], const float range[2][2],
                               import_uv *uv, scene_error *err)
{
    const scene_texture *src = &s->textures[texture];
    uint32_t side[2] = {src->width, src->height}, out[2];
    int64_t first[2] = {0, 0};
    for (int k = 0; k < 2; k++) {
        out[k] = side[k];
        if (!axis[k])
            continue;
        double a = floor(range[k][0]), b = ceil(range[k][1]);
        double size = (b - a) * side[k] + 2;
        if (!(size <= IMPORT_CLAMP_MAX_SIDE)) {
            scene__fail(
                err, SCENE_ERR_RANGE,
                "%s: clamped over coordinates %g..%g, its copy would be %.0f texels wide (at most %d)",
                src->path, (double)range[k][0], (double)range[k][1], size, IMPORT_CLAMP_MAX_SIDE);
            return -1;
        }
        out[k] = (uint32_t)size;
        first[k] = (int64_t)a * side[k] - 1; /* the original texel (from the start) of the copy's first */
        uv->remap[k] = true;
        uv->offset[k] = (float)(a - 1.0 / side[k]);
        uv->scale[k] = (float)((double)side[k] / size);
    }
    float *rgb = malloc(sizeof(float) * 3 * (size_t)out[0] * out[1]);
    char name[300];
    snprintf(name, sizeof name, "%.250s (clamped%s%s)", src->path, axis[0] ? " u" : "", axis[1] ? " v" : "");
    if (!rgb) {
        scene__fail(err, SCENE_ERR_NOMEM, "%s: out of memory", name);
        return -1;
    }
    uint32_t w = side[0], h = side[1];
    for (uint32_t y = 0; y < out[1]; y++) {
        /* rows count from the top, coordinates v from the bottom: the copy's bottom row is row out[1] - 1 */
        int64_t r =
            axis[1] ? first[1] + (int64_t)(out[1] - 1 - y) : (int64_t)(h - 1 - y); /* from the bottom */
        r = r < 0 ? 0 : (r >= (int64_t)h ? (int64_t)h - 1 : r);
        size_t sy = (size_t)(h - 1 - (uint32_t)r);
        for (uint32_t x = 0; x < out[0]; x++) {
            int64_t c = axis[0] ? first[0] + (int64_t)x : (int64_t)x;
            c = c < 0 ? 0 : (c >= (int64_t)w ? (int64_t)w - 1 : c);
            memcpy(rgb + 3 * ((size_t)y * out[0] + x), src->rgb + 3 * (sy * w + (size_t)c),
                   sizeof(float) * 3);
        }
    }
    return replace_plain(s, texture, scene__add_texture_rgb(s, name, out[0], out[1], rgb, err));
}

/* The least and greatest finite coordinate (u, v) of set uv_set (set 0 where a mesh lacks it, as import_mesh
 * reads) over the meshes of material `material`; false when they have none. */
static bool material_uv_range(const struct aiScene *ai, uint32_t material, const import_uv *m,
                              float range[2][2])
{
    unsigned uv_set = m->set;
    range[0][0] = range[1][0] = INFINITY;
    range[0][1] = range[1][1] = -INFINITY;
    for (uint32_t i = 0; i < ai->mNumMeshes; i++) {
        const struct aiMesh *mesh = ai->mMeshes[i];
        const struct aiVector3D *uv =
            mesh->mTextureCoords[uv_set] ? mesh->mTextureCoords[uv_set] : mesh->mTextureCoords[0];
        for (uint32_t v = 0; mesh->mMaterialIndex == material && uv && v < mesh->mNumVertices; v++) {
            float c[2];
            uv_transformed(m, uv[v].x, uv[v].y, c);
            for (int k = 0; k < 2; k++)
                if (isfinite(c[k])) {
                    range[k][0] = fminf(range[k][0], c[k]);
                    range[k][1] = fmaxf(range[k][1], c[k]);
                }
        }
    }
    return range[0][0] <= range[0][1] || range[1][0] <= range[1][1];
}

/* An emitting material's emissive texture (glTF's emissiveTexture, times emissiveFactor): fxcache's emission
 * is one radiance per material, so the texture's mean colour over its texels multiplies it, which keeps the
 * material's emitted power (before, the texture was not read: a factor of 1 made every texel emit white). The
 * texture is read only for its mean and not kept (unless the material's diffuse texture is the same file);
 * one warning line says so. A texture that cannot be read leaves the emission as it is, with a warning. */
static void emissive_texture_mean(scene *s, const struct aiScene *ai, const struct aiMaterial *am,
                                  const char *path, const char *model_dir, scene_material *m)
{
    struct aiString tex;
    if (!scene_material_emits(m) || aiGetMaterialTextureCount(am, aiTextureType_EMISSIVE) == 0 ||
        aiGetMaterialTexture(am, aiTextureType_EMISSIVE, 0, &tex, NULL, NULL, NULL, NULL, NULL, NULL) !=
            aiReturn_SUCCESS ||
        tex.length == 0)
        return;
    char found[768];
    const struct aiTexture *held = embedded_texture(ai, tex.data);
    bool beside = tex.data[0] != '*' && resolve_texture(model_dir, tex.data, found, sizeof found);
    uint32_t before = s->texture_count;
    scene_error tex_err = {0};
    int32_t index = beside ? scene__add_texture(s, found, &tex_err)
                    : held ? add_embedded_texture(s, path, tex.data, held, &tex_err)
                           : -1;
    if (index < 0) {
        fprintf(stderr,
                "fxcache: warning: material '%s': emissive texture '%s' %s (its emission is uniform)\n",
                m->name, tex.data, beside || held ? "could not be read" : "not found beside the model");
        return;
    }
    scene_texture *t = &s->textures[index];
    double sum[3] = {0, 0, 0};
    size_t texels = (size_t)t->width * t->height;
    for (size_t i = 0; i < texels; i++)
        for (int k = 0; k < 3; k++)
            sum[k] += t->rgb[3 * i + k];
    for (int k = 0; k < 3; k++)
        m->emission[k] = (float)(m->emission[k] * (texels ? sum[k] / (double)texels : 0.0));
    fprintf(stderr,
            "fxcache: warning: material '%s': emissive texture '%s' is used as its mean colour (%.3g, %.3g, "
            "%.3g): fxcache's emission is uniform over a material\n",
            m->name, tex.data, sum[0] / (double)(texels ? texels : 1), sum[1] / (double)(texels ? texels : 1),
            sum[2] / (double)(texels ? texels : 1));
    if ((uint32_t)index == before && s->texture_count == before + 1) { /* read for its mean alone */
        free(t->rgb);
        for (uint32_t l = 1; l < t->levels; l++)
            free(t->mip_rgb[l]);
        memset(t, 0, sizeof *t);
        s->texture_count--;
    }
}

/* Converts one Assimp material into a scene material (its diffuse colour, emission and texture: a file
 * beside the model, or one the file holds). A texture that cannot be read is reported on stderr and counted;
 * the material keeps its colour. */
static scene_result import_material(scene *s, const struct aiScene *ai, uint32_t index, const char *path,
                                    const char *model_dir, bool gltf, uint32_t *out_index, import_uv *out_uv,
                                    scene_error *err)
{
    const struct aiMaterial *am = ai->mMaterials[index];
    *out_uv = (import_uv){0};
    scene_material m = {.diffuse = {0.7f, 0.7f, 0.7f}, .texture = -1};
    struct aiString name;
    if (aiGetMaterialString(am, AI_MATKEY_NAME, &name) == aiReturn_SUCCESS)
        snprintf(m.name, sizeof m.name, "%s", name.data);
    struct aiColor4D color;
    if (aiGetMaterialColor(am, AI_MATKEY_COLOR_DIFFUSE, &color) == aiReturn_SUCCESS) {
        float c[3] = {color.r, color.g, color.b};
        for (int k = 0; k < 3; k++)
            m.diffuse[k] = isfinite(c[k]) ? fminf(fmaxf(c[k], 0.0f), 1.0f) : 0.7f;
    }
    /* Emission: the emissive colour (OBJ's Ke, glTF's emissiveFactor, FBX's EmissiveColor) times the emissive
     * intensity when Assimp gives one (FBX's EmissiveFactor; glTF's KHR_materials_emissive_strength in Assimp
     * versions that read it, not 5.2.5). Radiance in the file's units; negative or non-finite counts as none. */
    if (aiGetMaterialColor(am, AI_MATKEY_COLOR_EMISSIVE, &color) == aiReturn_SUCCESS) {
        float strength = 1.0f;
        ai_real intensity = 1;
        if (aiGetMaterialFloat(am, AI_MATKEY_EMISSIVE_INTENSITY, &intensity) == aiReturn_SUCCESS &&
            isfinite(intensity) && intensity >= 0)
            strength = (float)intensity;
        float c[3] = {color.r, color.g, color.b};
        for (int k = 0; k < 3; k++) {
            float e = c[k] * strength;
            m.emission[k] = isfinite(e) && e > 0.0f ? e : 0.0f;
        }
        emissive_texture_mean(s, ai, am, path, model_dir, &m);
    }
    struct aiString tex;
    unsigned uv_set = 0; /* which of the mesh's texture coordinate sets the texture uses (glTF's texCoord) */
    enum aiTextureMapMode modes[2] = {aiTextureMapMode_Wrap, aiTextureMapMode_Wrap};
    if (aiGetMaterialTextureCount(am, aiTextureType_DIFFUSE) > 0 &&
        aiGetMaterialTexture(am, aiTextureType_DIFFUSE, 0, &tex, NULL, &uv_set, NULL, NULL, modes, NULL) ==
            aiReturn_SUCCESS &&
        tex.length > 0) {
        out_uv->set = uv_set < AI_MAX_NUMBER_OF_TEXTURECOORDS ? (uint8_t)uv_set : 0;
        if (gltf)
            gltf_texture_transform(am, out_uv);
        char found[768];
        double t0 = scene__now_ms();
        const struct aiTexture *held = embedded_texture(ai, tex.data);
        /* A file beside the model first (an FBX names both); what the file holds next (a GLB's "*0"). */
        bool beside = tex.data[0] != '*' && resolve_texture(model_dir, tex.data, found, sizeof found);
        if (beside || held) {
            scene_error tex_err = {0};
            m.texture = beside ? scene__add_texture(s, found, &tex_err)
                               : add_embedded_texture(s, path, tex.data, held, &tex_err);
            if (m.texture < 0) {
                if (!texture_warned(ai, index, &tex))
                    fprintf(stderr, "fxcache: warning: material '%s': %s (using its colour)\n", m.name,
                            tex_err.msg);
                s->repairs.textures_missing++;
            } else if (modes[0] == aiTextureMapMode_Mirror || modes[1] == aiTextureMapMode_Mirror) {
                int32_t mirrored = mirrored_texture(s, m.texture, modes[0] == aiTextureMapMode_Mirror,
                                                    modes[1] == aiTextureMapMode_Mirror, &tex_err);
                if (mirrored < 0) {
                    fprintf(stderr, "fxcache: warning: material '%s': %s (repeating it instead)\n", m.name,
                            tex_err.msg);
                } else {
                    m.texture = mirrored;
                    for (int k = 0; k < 2; k++)
                        if (modes[k] == aiTextureMapMode_Mirror) {
                            out_uv->remap[k] = true;
                            out_uv->offset[k] = 0.0f;
                            out_uv->scale[k] = 0.5f;
                        }
                }
            }
            /* Clamped (not repeated nor mirrored) where the meshes' coordinates leave 0..1: a padded copy.
             * Inside 0..1 clamping and repeating read the same texels but at the edges' outer half texel. */
            bool clamped[2] = {false, false}, outside = false;
            float range[2][2];
            if (m.texture >= 0 && material_uv_range(ai, index, out_uv, range))
                for (int k = 0; k < 2; k++) {
                    clamped[k] = modes[k] != aiTextureMapMode_Wrap && modes[k] != aiTextureMapMode_Mirror &&
                                 (range[k][0] < -1e-4f || range[k][1] > 1 + 1e-4f);
                    outside |= clamped[k];
                }
            if (outside) {
                int32_t copy = clamped_texture(s, m.texture, clamped, range, out_uv, &tex_err);
                if (copy < 0)
                    fprintf(stderr, "fxcache: warning: material '%s': %s (repeating it instead)\n", m.name,
                            tex_err.msg);
                else
                    m.texture = copy;
            }
            if (m.texture >= 0) {
                /* The texture carries the colour; Assimp's 3DS and OBJ readers give a tint we keep. */
                bool black = m.diffuse[0] == 0 && m.diffuse[1] == 0 && m.diffuse[2] == 0;
                if (black)
                    m.diffuse[0] = m.diffuse[1] = m.diffuse[2] = 1.0f;
            }
        } else {
            if (!texture_warned(ai, index, &tex))
                fprintf(stderr,
                        "fxcache: warning: material '%s': texture '%s' not found beside the model "
                        "(using its colour)\n",
                        m.name, tex.data);
            s->repairs.textures_missing++;
        }
        s->timings.textures_ms += scene__now_ms() - t0;
    }
    *out_index = scene__add_material(s, &m, err);
    return *out_index == UINT32_MAX ? SCENE_ERR_NOMEM : SCENE_OK;
}

/* How a file's vertex colours are read: not at all (a scene description's material replaces the file's),
 * as linear RGB (glTF's COLOR_0, by its specification), or as sRGB-encoded (every other format: PLY scans' and
 * DCC tools' byte colours are what a screen shows, as 8-bit images are). */
typedef enum import_colors { IMPORT_COLORS_NONE = 0, IMPORT_COLORS_LINEAR, IMPORT_COLORS_SRGB } import_colors;

/* Appends one Assimp mesh (triangulated) through scene__add_mesh_colored(), with its texture coordinates of
 * set uv_set (its material's texture's; set 0 when the mesh has no such set) and its first vertex colour set
 * (Assimp's mColors[0]; alpha is not used) read as `colors` says. */
static scene_result import_mesh(scene *s, const struct aiMesh *mesh, uint32_t mesh_number, uint32_t material,
                                import_uv uv_mode, import_colors colors, const double *xform,
                                const char *path, scene_error *err)
{
    unsigned uv_set = uv_mode.set;
    const struct aiVector3D *coords =
        mesh->mTextureCoords[uv_set] ? mesh->mTextureCoords[uv_set] : mesh->mTextureCoords[0];
    char name[160];
    if (mesh->mName.length > 0)
        snprintf(name, sizeof name, "%s", mesh->mName.data);
    else
        snprintf(name, sizeof name, "%s#%u", path, mesh_number);
    uint32_t nv = mesh->mNumVertices, nf = mesh->mNumFaces;
    float *positions = malloc(sizeof(float) * 3 * (size_t)(nv ? nv : 1));
    float *uv = coords ? malloc(sizeof(float) * 2 * (size_t)(nv ? nv : 1)) : NULL;
    uint32_t *indices = malloc(sizeof(uint32_t) * 3 * (size_t)(nf ? nf : 1));
    const struct aiColor4D *vertex_colors = colors != IMPORT_COLORS_NONE ? mesh->mColors[0] : NULL;
    float *color = vertex_colors ? malloc(sizeof(float) * 3 * (size_t)(nv ? nv : 1)) : NULL;
    scene_result rc = SCENE_ERR_NOMEM;
    if (!positions || !indices || (coords && !uv) || (vertex_colors && !color)) {
        rc = scene__fail(err, SCENE_ERR_NOMEM, "mesh '%s': out of memory", name);
        goto done;
    }
    for (uint32_t v = 0; v < nv; v++) {
        positions[3 * (size_t)v] = mesh->mVertices[v].x;
        positions[3 * (size_t)v + 1] = mesh->mVertices[v].y;
        positions[3 * (size_t)v + 2] = mesh->mVertices[v].z;
        if (uv) {
            float c[2];
            uv_transformed(&uv_mode, coords[v].x, coords[v].y, c);
            for (int k = 0; k < 2; k++)
                uv[2 * (size_t)v + k] =
                    uv_mode.remap[k] ? (c[k] - uv_mode.offset[k]) * uv_mode.scale[k] : c[k];
        }
        if (color) {
            const float c[3] = {vertex_colors[v].r, vertex_colors[v].g, vertex_colors[v].b};
            for (int k = 0; k < 3; k++) /* scene__add_mesh_colored clamps to 0..1 */
                color[3 * (size_t)v + k] =
                    colors == IMPORT_COLORS_SRGB ? srgb_to_linear(fminf(fmaxf(c[k], 0.0f), 1.0f)) : c[k];
        }
    }
    uint32_t nt = 0;
    for (uint32_t f = 0; f < nf; f++) {
        const struct aiFace *face = &mesh->mFaces[f];
        if (face->mNumIndices != 3) {
            s->repairs.non_triangles_dropped++;
            continue;
        }
        for (int c = 0; c < 3; c++)
            indices[3 * (size_t)nt + c] = face->mIndices[c];
        nt++;
    }
    rc = scene__add_mesh_colored(s, name, positions, nv, indices, nt, uv, color, material, xform, err);
done:
    free(positions);
    free(uv);
    free(color);
    free(indices);
    return rc;
}

/* Which scene material each Assimp mesh gets: the file's own through material_map, or one for all. */
typedef struct import_materials {
    const uint32_t *map;  /* per Assimp material, or NULL */
    const import_uv *uv;  /* per Assimp material: how its texture is read, or NULL */
    uint32_t count;       /* entries of map */
    uint32_t all;         /* UINT32_MAX, or the material every mesh gets */
    import_colors colors; /* how meshes' vertex colours are read */
} import_materials;

static uint32_t material_for(const import_materials *mats, const struct aiMesh *mesh)
{
    if (mats->all != UINT32_MAX)
        return mats->all;
    return mesh->mMaterialIndex < mats->count ? mats->map[mesh->mMaterialIndex] : mats->map[0]; /* first */
}

/* How a mesh reads its material's texture (set 0, as it is, with a material for all meshes). */
static import_uv uv_for(const import_materials *mats, const struct aiMesh *mesh)
{
    if (mats->all != UINT32_MAX || !mats->uv)
        return (import_uv){0};
    return mesh->mMaterialIndex < mats->count ? mats->uv[mesh->mMaterialIndex] : mats->uv[0];
}

/* Imports every mesh the nodes below node place, each through its node's transform times parent (the
 * ancestors' transforms times the caller's), so scene__add_mesh() sees a mirroring instance's transform and
 * keeps its triangles facing outwards. A mesh placed by two nodes is imported twice. */
static scene_result import_node(scene *s, const struct aiScene *ai, const struct aiNode *node,
                                const double parent[16], const import_materials *mats, const char *path,
                                unsigned depth, scene_error *err)
{
    if (!node || depth > 10000)
        return SCENE_OK;
    double local[16], world[16];
    scene__node_matrix(node, local);
    scene__matrix_multiply(parent, local, world);
    scene_result rc = SCENE_OK;
    for (uint32_t i = 0; rc == SCENE_OK && i < node->mNumMeshes; i++) {
        const struct aiMesh *mesh = ai->mMeshes[node->mMeshes[i]];
        if (!(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) {
            s->repairs.non_triangles_dropped += mesh->mNumFaces;
            continue;
        }
        rc = import_mesh(s, mesh, node->mMeshes[i], material_for(mats, mesh), uv_for(mats, mesh),
                         mats->colors, world, path, err);
    }
    for (uint32_t i = 0; rc == SCENE_OK && i < node->mNumChildren; i++)
        rc = import_node(s, ai, node->mChildren[i], world, mats, path, depth + 1, err);
    return rc;
}

/* scene__import_file, and with lights (non-NULL) also the file's lights and camera, which it then describes
 * (scene__import_file_lit). */
static scene_result import_file(scene *s, const char *path, const double *xform,
                                const scene_material *override, scene_file_lights *lights, scene_error *err)
{
    scene_result rc = scene__check_file(path, err);
    if (rc != SCENE_OK)
        return rc;

    /* Two phases, because Assimp 5.2.5 crashes on some damaged input (found by mutating files): its
     * triangulation asserts, aborting the process, on a face without vertices, which its own validation
     * lets through; and aiApplyPostProcessing() crashes releasing a scene when a step fails. So the
     * import runs only Assimp's validation, check_faces() and check_scene_graph() check what that let
     * through and what the steps would fail on, and only then do the post-processing steps run. */
    const unsigned flags = aiProcess_ValidateDataStructure;
    unsigned post = aiProcess_Triangulate | aiProcess_SortByPType;
    const struct aiScene *ai = NULL;
    size_t n = strlen(path);
    bool gz = n > 3 && strcasecmp(path + n - 3, ".gz") == 0;
    char inner[512];
    snprintf(inner, sizeof inner, "%.*s", (int)(gz ? n - 3 : n), path);
    const char *dot = strrchr(inner, '.');
    const char *hint = dot && !strchr(dot, '/') ? dot + 1 : "";
    const scene_import_format *format = scene__import_format_of(hint);
    char printed[200], why[400];
    if (format && format->refused)
        return scene__fail(err, SCENE_ERR_FORMAT, "%s: %s", path, format->refused);
    char *buf = NULL;
    size_t len = 0;
    if (gz || (format && format->check)) {
        /* The whole file in memory for the check (read_gz also reads plain files: zlib passes them
         * through); Assimp reads a .gz from this memory and a plain file from its path, where readers
         * that open files beside it (MD5's .md5anim) find them. */
        rc = read_gz(path, &buf, &len, err);
        if (rc != SCENE_OK)
            return rc;
        if (len == 0) {
            free(buf);
            return scene__fail(err, SCENE_ERR_FORMAT, "%s: %s", path,
                               gz ? "decompresses to nothing" : "empty file");
        }
        if (len > UINT32_MAX) {
            free(buf);
            return scene__fail(err, SCENE_ERR_RANGE, "%s: larger than 4 GiB", path);
        }
        if (format && format->check && (rc = format->check(path, buf, len, err)) != SCENE_OK) {
            free(buf);
            return rc;
        }
        if (!gz) {
            free(buf);
            buf = NULL;
        }
    }
    assimp_dropped_log dropped = {0};
    struct aiLogStream log_stream = {.callback = assimp_log_line, .user = (char *)(void *)&dropped};
    pthread_mutex_lock(&assimp_log_lock);
    aiAttachLogStream(&log_stream);
    scene_cerr_capture *capture = scene_cerr_capture_begin();
    ai = gz ? aiImportFileFromMemory(buf, (unsigned)len, flags, hint) : aiImportFile(path, flags);
    scene_cerr_capture_end(capture, printed, sizeof printed);
    aiDetachLogStream(&log_stream);
    pthread_mutex_unlock(&assimp_log_lock);
    free(buf);
    if (!ai) {
        assimp_error(why, sizeof why);
        /* Assimp's validation refuses a scene without meshes (an OBJ of comments only, Assimp's own M3D
         * cubes, which its reader here returns empty): the file holds nothing to render, as a scene with no
         * meshes that passes validation is refused below (SCENE_ERR_EMPTY). */
        if (strstr(why, "mNumMeshes is 0"))
            return scene__fail(err, SCENE_ERR_EMPTY,
                               "%s: no usable triangles in the file (Assimp read no meshes from it)", path);
        return scene__fail(err, SCENE_ERR_FORMAT, "%s: cannot import: %s%s%s%s", path, why,
                           printed[0] ? " (Assimp also printed: '" : "", printed, printed[0] ? "')" : "");
    }
    if (printed[0])
        fprintf(stderr, "fxcache: warning: %s: Assimp printed: '%s'\n", path, printed);
    if (dropped.count)
        fprintf(stderr, "fxcache: warning: %s: Assimp dropped geometry while reading it: '%s'%s\n", path,
                dropped.first, dropped.count > 1 ? " (and more such messages)" : "");
    scene_result checked = check_faces(path, ai, err);
    if (checked == SCENE_OK)
        checked = check_scene_graph(path, ai, err);
    if (checked != SCENE_OK) {
        aiReleaseImport(ai);
        return checked;
    }
    /* Lengths in metres: Assimp's global-scale step applies the file's unit where its reader leaves it to
     * that step (FBX's UnitScaleFactor, centimetres by default: an FBX cube of 21 cm was read as 21 m);
     * Collada's <unit> and up axis its reader applies itself, glTF is in metres. */
    const struct aiVector3D *sample = NULL; /* a vertex before and after: the scale applied */
    for (uint32_t i = 0; !sample && i < ai->mNumMeshes; i++)
        for (uint32_t v = 0; !sample && v < ai->mMeshes[i]->mNumVertices; v++)
            if (ai->mMeshes[i]->mVertices[v].x != 0)
                sample = &ai->mMeshes[i]->mVertices[v];
    double sample_before = sample ? sample->x : 0;
    ai = aiApplyPostProcessing(ai, aiProcess_GlobalScale);
    if (!ai)
        return scene__fail(err, SCENE_ERR_FORMAT, "%s: cannot import: %s", path,
                           assimp_error(why, sizeof why));
    double unit_scale = sample ? sample->x / sample_before : 1.0;
    /* The file's lights and camera, while the node graph that places them is whole (the global-scale step
     * ran alone for this). */
    if (lights) {
        rc = scene__import_lights(s, ai, path, unit_scale, lights, err);
        if (rc != SCENE_OK) {
            aiReleaseImport(ai);
            return rc;
        }
    }
    /* Assimp pre-transforms the meshes when no instance mirrors (every mesh in world space, merged by
     * material, as fxcache always read files); otherwise the meshes stay in their nodes' frames and
     * import_node() places each instance, so that a mirrored one keeps its triangles facing outwards. */
    bool mirrored = scene__places_mirrored(ai->mRootNode, scene__identity_matrix, 0);
    if (!mirrored)
        post |= aiProcess_PreTransformVertices;
    ai = aiApplyPostProcessing(ai, post);
    if (!ai)
        return scene__fail(err, SCENE_ERR_FORMAT, "%s: cannot import: %s", path,
                           assimp_error(why, sizeof why));

    char model_dir[512];
    folder_of(path, model_dir, sizeof model_dir);
    bool gltf = strcasecmp(hint, "gltf") == 0 || strcasecmp(hint, "glb") == 0;
    uint32_t *material_map = NULL;
    import_uv *uv_modes = NULL;
    uint32_t override_index = UINT32_MAX;
    if (override) {
        override_index = scene__add_material(s, override, err);
        if (override_index == UINT32_MAX)
            rc = SCENE_ERR_NOMEM;
    } else {
        material_map = malloc(sizeof(uint32_t) * (ai->mNumMaterials ? ai->mNumMaterials : 1));
        uv_modes = malloc(sizeof *uv_modes * (ai->mNumMaterials ? ai->mNumMaterials : 1));
        if (!material_map || !uv_modes)
            rc = scene__fail(err, SCENE_ERR_NOMEM, "%s: out of memory", path);
        for (uint32_t m = 0; rc == SCENE_OK && m < ai->mNumMaterials; m++)
            rc = import_material(s, ai, m, path, model_dir, gltf, &material_map[m], &uv_modes[m], err);
        if (rc == SCENE_OK && ai->mNumMaterials == 0) {
            scene_material grey = {.diffuse = {0.7f, 0.7f, 0.7f}, .texture = -1, .name = "default"};
            override_index = scene__add_material(s, &grey, err);
            if (override_index == UINT32_MAX)
                rc = SCENE_ERR_NOMEM;
        }
    }
    uint32_t before = s->triangle_count;
    scene_repairs repairs_before = s->repairs;
    import_materials mats = {.map = material_map,
                             .uv = uv_modes,
                             .count = ai->mNumMaterials,
                             .all = override_index,
                             .colors = override ? IMPORT_COLORS_NONE
                                                : (gltf ? IMPORT_COLORS_LINEAR : IMPORT_COLORS_SRGB)};
    if (mirrored && rc == SCENE_OK)
        rc = import_node(s, ai, ai->mRootNode, xform ? xform : scene__identity_matrix, &mats, path, 0, err);
    for (uint32_t i = 0; !mirrored && rc == SCENE_OK && i < ai->mNumMeshes; i++) {
        const struct aiMesh *mesh = ai->mMeshes[i];
        if (!(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) {
            s->repairs.non_triangles_dropped += mesh->mNumFaces;
            continue;
        }
        rc = import_mesh(s, mesh, i, material_for(&mats, mesh), uv_for(&mats, mesh), mats.colors, xform, path,
                         err);
    }
    if (rc == SCENE_OK && s->triangle_count == before) {
        char lost[160];
        scene__precision_lost(&s->repairs, repairs_before.precision_skipped, lost, sizeof lost);
        rc = scene__fail(
            err, SCENE_ERR_EMPTY,
            "%s: no usable triangles in the file (%llu points and lines dropped, %llu duplicate and %llu "
            "degenerate triangles skipped%s)",
            path,
            (unsigned long long)(s->repairs.non_triangles_dropped - repairs_before.non_triangles_dropped),
            (unsigned long long)(s->repairs.duplicate_skipped - repairs_before.duplicate_skipped),
            (unsigned long long)(s->repairs.degenerate_skipped - repairs_before.degenerate_skipped), lost);
    }
    free(material_map);
    free(uv_modes);
    aiReleaseImport(ai);
    return rc;
}

scene_result scene__import_file(scene *s, const char *path, const double *xform,
                                const scene_material *override, scene_error *err)
{
    return import_file(s, path, xform, override, NULL, err);
}

scene_result scene__import_file_lit(scene *s, const char *path, scene_file_lights *found, scene_error *err)
{
    return import_file(s, path, NULL, NULL, found, err);
}
