/* Mesh-file import through Assimp's C API: OBJ, 3DS, PLY, glTF 2 and whatever else Assimp reads.
 * A ".gz" file is decompressed with zlib first and handed to Assimp from memory with the inner extension
 * as the format hint. Meshes are triangulated by Assimp and pre-transformed to world space; points and
 * lines are dropped and counted; every mesh then goes through scene__add_mesh(), which checks, welds and
 * cleans it. Diffuse colours and diffuse textures (read with OpenImageIO, relative to the model file, with
 * a case-insensitive fallback since many old models name "KAMEN.JPG" for kamen.jpg) become materials. */
#include "scene_internal.h"
#include "cerr_capture.h"

#include <assimp/cimport.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
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

/* A whole number as Assimp's strtoul10() reads it: the leading decimal digits, wrapping modulo 2^32 as its
 * unsigned int does. *digits_out (may be NULL) is the same number without wrapping, saturated at UINT64_MAX,
 * so a count that wrapped to something small is still seen for what the file declares. */
static uint32_t assimp_strtoul10(const char *p, const char *end, uint64_t *digits_out)
{
    uint32_t wrapped = 0;
    uint64_t digits = 0;
    for (; p < end && *p >= '0' && *p <= '9'; p++) {
        wrapped = wrapped * 10u + (uint32_t)(*p - '0');
        digits = digits > (UINT64_MAX - 9) / 10 ? UINT64_MAX : digits * 10 + (uint64_t)(*p - '0');
    }
    if (digits_out)
        *digits_out = digits;
    return wrapped;
}

/* Refuses a declared count larger than the file could hold: every item of a declared element, vertex or
 * face takes at least one byte of the file, so a count above the file's size is a lie that would only make
 * Assimp allocate for it (its OFF reader allocates from the header alone: Assimp's own test file
 * invalid/OutOfMemory.off, 309 bytes, declares 353535235358 vertices and grew past 8 GB). */
static scene_result check_count(const char *path, unsigned line, const char *what, uint64_t count, size_t len,
                                scene_error *err)
{
    if (count <= len)
        return SCENE_OK;
    return scene__fail(err, SCENE_ERR_FORMAT,
                       "%s:%u: declares %llu %s, more than the file's %zu bytes can hold", path, line,
                       (unsigned long long)count, what, len);
}

/* Counts in a PLY "comment" line that Assimp takes as an element count are refused only above this many:
 * below it Assimp's allocation for them is small whatever the file's size (about 24 bytes each). */
#define PLY_COMMENT_COUNT_HARMLESS (1u << 20)

/* Checks a PLY header before Assimp reads it. Assimp 5.2.5's PLY reader loops forever on a header whose
 * end_header line is damaged (found by mutating files), so the header must end with an end_header line;
 * and no element may declare more items than the file has bytes. Header lines PLY does not define
 * (Blender 2.47 writes a bare "Created by Blender3D ..." line) are accepted: Assimp skips them. Assimp also
 * parses every "comment" line as an element (its comment skipping works on a copy of the line), so a
 * comment starting with a number, or with "vertex"/"face" and a number, declares a count as well. */
static scene_result check_ply(const char *path, const char *buf, size_t len, scene_error *err)
{
    /* the element semantics after which Assimp reads a count ("TextureFile" takes a name, no count) */
    static const char *const semantics[] = {"vertex", "face", "tristrips", "edge", "material"};
    size_t pos = 0;
    for (unsigned line = 1; pos < len && line <= 100000; line++) {
        const char *start = buf + pos;
        const char *newline = memchr(start, '\n', len - pos);
        size_t n = newline ? (size_t)(newline - start) : len - pos;
        size_t m = n > 0 && start[n - 1] == '\r' ? n - 1 : n;
        const char *end = start + m;
        if (line == 1) {
            if (!(m == 3 && memcmp(start, "ply", 3) == 0))
                return scene__fail(err, SCENE_ERR_FORMAT, "%s: not a PLY file (the first line is not 'ply')", path);
        } else if (m >= 10 && memcmp(start, "end_header", 10) == 0 &&
                   (m == 10 || start[10] == ' ' || start[10] == '\t')) {
            return SCENE_OK;
        } else if (m >= 8 && memcmp(start, "element ", 8) == 0) {
            /* "element NAME COUNT", nothing after the count */
            const char *p = start + 8, *name = NULL, *digits = NULL;
            while (p < end && (*p == ' ' || *p == '\t'))
                p++;
            for (name = p; p < end && *p != ' ' && *p != '\t';)
                p++;
            size_t name_len = (size_t)(p - name);
            while (p < end && (*p == ' ' || *p == '\t'))
                p++;
            for (digits = p; p < end && *p >= '0' && *p <= '9';)
                p++;
            bool has_digits = p > digits;
            while (p < end && (*p == ' ' || *p == '\t'))
                p++;
            if (name_len == 0 || !has_digits || p != end)
                return scene__fail(err, SCENE_ERR_FORMAT, "%s:%u: malformed element line: '%.*s'", path, line,
                                   (int)(m < 60 ? m : 60), start);
            uint64_t declared = 0;
            assimp_strtoul10(digits, end, &declared);
            char what[96];
            snprintf(what, sizeof what, "items of element '%.*s'", (int)(name_len < 40 ? name_len : 40),
                     name);
            scene_result rc = check_count(path, line, what, declared, len, err);
            if (rc != SCENE_OK)
                return rc;
        } else if (m >= 8 && memcmp(start, "comment", 7) == 0 && (start[7] == ' ' || start[7] == '\t')) {
            const char *p = start + 8;
            while (p < end && (*p == ' ' || *p == '\t'))
                p++;
            for (size_t k = 0; k < sizeof semantics / sizeof semantics[0]; k++) {
                size_t sl = strlen(semantics[k]);
                if ((size_t)(end - p) > sl && memcmp(p, semantics[k], sl) == 0 &&
                    (p[sl] == ' ' || p[sl] == '\t')) {
                    for (p += sl; p < end && (*p == ' ' || *p == '\t');)
                        p++;
                    break;
                }
            }
            uint64_t declared = 0;
            assimp_strtoul10(p, end, &declared);
            if (declared > len && declared > PLY_COMMENT_COUNT_HARMLESS)
                return scene__fail(
                    err, SCENE_ERR_FORMAT,
                    "%s:%u: Assimp reads this comment as declaring %llu items, more than the file's "
                    "%zu bytes can hold: '%.*s'",
                    path, line, (unsigned long long)declared, len, (int)(m < 60 ? m : 60), start);
        }
        if (!newline)
            break;
        pos += n + 1;
    }
    return scene__fail(err, SCENE_ERR_FORMAT, "%s: the PLY header has no end_header line", path);
}

/* Skips blanks, line ends and '#' comment lines the way Assimp's OFF reader does. */
static const char *off_next_token(const char *p, const char *end)
{
    for (;;) {
        while (p < end && (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n'))
            p++;
        if (p >= end || *p != '#')
            return p;
        while (p < end && *p != '\n')
            p++;
    }
}

/* Checks an OFF header's vertex and face counts against the file size before Assimp reads it: Assimp
 * allocates both arrays from the header alone. The header is parsed as Assimp parses it: optional "ST",
 * "C", "N", "4" and "n" prefixes, "OFF" (which may be absent), a dimension after "n", then the counts. */
static scene_result check_off(const char *path, const char *buf, size_t len, scene_error *err)
{
    const char *p = off_next_token(buf, buf + len), *end = buf + len;
    bool dimension = false;
    if (end - p > 2 && p[0] == 'S' && p[1] == 'T')
        p += 2;
    if (end - p > 1 && p[0] == 'C')
        p++;
    if (end - p > 1 && p[0] == 'N')
        p++;
    if (end - p > 1 && p[0] == '4')
        p++;
    if (end - p > 1 && p[0] == 'n') {
        dimension = true;
        p++;
    }
    if (end - p > 3 && memcmp(p, "OFF", 3) == 0)
        p += 3;
    else
        dimension = false; /* Assimp reads the counts from here on */
    p = off_next_token(p, end);
    if (dimension) {
        assimp_strtoul10(p, end, NULL);
        while (p < end && *p >= '0' && *p <= '9')
            p++;
        p = off_next_token(p, end);
    }
    static const char *const what[2] = {"vertices", "faces"};
    for (int k = 0; k < 2; k++) {
        uint64_t declared = 0;
        assimp_strtoul10(p, end, &declared);
        unsigned line = 1;
        for (const char *q = buf; q < p; q++)
            line += *q == '\n';
        scene_result rc = check_count(path, line, what[k], declared, len, err);
        if (rc != SCENE_OK)
            return rc;
        while (p < end && *p >= '0' && *p <= '9')
            p++;
        p = off_next_token(p, end);
    }
    return SCENE_OK;
}

/* Checks a binary STL's facet count against the file size. Assimp takes a file for binary STL when
 * 84 + 50 * count equals its size in 32-bit arithmetic, which a huge count can wrap to; ASCII STL declares
 * no counts. */
static scene_result check_stl(const char *path, const char *buf, size_t len, scene_error *err)
{
    if (len < 84)
        return SCENE_OK;
    const unsigned char *c = (const unsigned char *)buf + 80;
    uint32_t count = (uint32_t)c[0] | (uint32_t)c[1] << 8 | (uint32_t)c[2] << 16 | (uint32_t)c[3] << 24;
    bool binary = (uint32_t)(count * 50u + 84u) == (uint32_t)len;
    if (binary && 84 + 50 * (uint64_t)count != (uint64_t)len)
        return scene__fail(err, SCENE_ERR_FORMAT,
                           "%s: declares %u facets (%llu bytes), but the file has %zu bytes", path, count,
                           84 + 50 * (unsigned long long)count, len);
    return SCENE_OK;
}

/* What fxcache knows about a format before Assimp reads it, by the file's (inner, for .gz) extension: a
 * check of the whole file (declared counts against its size) that runs before Assimp, or the reason the
 * format is refused outright. */
typedef scene_result (*import_check_fn)(const char *path, const char *buf, size_t len, scene_error *err);
typedef struct import_format {
    const char *ext;       /* lower case, without the dot */
    import_check_fn check; /* NULL: none */
    const char *refused;   /* non-NULL: the file is refused with this reason */
} import_format;

static const import_format import_formats[] = {
    {"ply", check_ply, NULL},
    {"off", check_off, NULL},
    {"stl", check_stl, NULL},
    /* Assimp's Q3BSP importer opens its file as a zip archive (ZipArchiveIOSystem) and looks for
     * maps/NAME.bsp inside, so a bare .bsp always fails with "Failed to open file"; inside a .pk3 it
     * leaves the triangles' vertex indices unset (5.2.5: every face reads "0 0 0" or "N 0 0"). */
    {"bsp", NULL,
     "a bare Quake 3 .bsp map: Assimp reads these only from inside a .pk3 (zip) archive, and its Quake 3 "
     "importer (5.2.5) leaves the triangles' vertex indices unset; convert the map (e.g. to OBJ) first"},
    {"pk3", NULL,
     "a Quake 3 .pk3 archive: Assimp's Quake 3 importer (5.2.5) leaves the triangles' vertex indices unset; "
     "convert the map (e.g. to OBJ) first"},
};

static const import_format *import_format_of(const char *ext)
{
    for (size_t i = 0; i < sizeof import_formats / sizeof import_formats[0]; i++)
        if (strcasecmp(ext, import_formats[i].ext) == 0)
            return &import_formats[i];
    return NULL;
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
                                       "%s: mesh %u face %u uses vertex %u, but the mesh has %u vertices", path, i,
                                       f, face->mIndices[k], mesh->mNumVertices);
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
 * folder is used. Returns false when nothing matches. */
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
    return found;
}

/* Converts one Assimp material into a scene material (its diffuse colour and texture). A texture that
 * cannot be read is reported on stderr and counted; the material keeps its colour. */
static scene_result import_material(scene *s, const struct aiMaterial *am, const char *model_dir,
                                    uint32_t *out_index, scene_error *err)
{
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
    struct aiString tex;
    if (aiGetMaterialTextureCount(am, aiTextureType_DIFFUSE) > 0 &&
        aiGetMaterialTexture(am, aiTextureType_DIFFUSE, 0, &tex, NULL, NULL, NULL, NULL, NULL, NULL) ==
            aiReturn_SUCCESS &&
        tex.length > 0 && tex.data[0] != '*') {
        char path[768];
        double t0 = scene__now_ms();
        if (resolve_texture(model_dir, tex.data, path, sizeof path)) {
            scene_error tex_err = {0};
            m.texture = scene__add_texture(s, path, &tex_err);
            if (m.texture < 0) {
                fprintf(stderr, "fxcache: warning: material '%s': %s (using its colour)\n", m.name, tex_err.msg);
                s->repairs.textures_missing++;
            } else {
                /* The texture carries the colour; Assimp's 3DS and OBJ readers give a tint we keep. */
                bool black = m.diffuse[0] == 0 && m.diffuse[1] == 0 && m.diffuse[2] == 0;
                if (black)
                    m.diffuse[0] = m.diffuse[1] = m.diffuse[2] = 1.0f;
            }
        } else {
            fprintf(stderr, "fxcache: warning: material '%s': texture '%s' not found beside the model "
                            "(using its colour)\n",
                    m.name, tex.data);
            s->repairs.textures_missing++;
        }
        s->timings.textures_ms += scene__now_ms() - t0;
    }
    *out_index = scene__add_material(s, &m, err);
    return *out_index == UINT32_MAX ? SCENE_ERR_NOMEM : SCENE_OK;
}

/* Appends one Assimp mesh (already triangulated and in world space) through scene__add_mesh(). */
static scene_result import_mesh(scene *s, const struct aiMesh *mesh, uint32_t mesh_number, uint32_t material,
                                const double *xform, const char *path, scene_error *err)
{
    char name[160];
    if (mesh->mName.length > 0)
        snprintf(name, sizeof name, "%s", mesh->mName.data);
    else
        snprintf(name, sizeof name, "%s#%u", path, mesh_number);
    uint32_t nv = mesh->mNumVertices, nf = mesh->mNumFaces;
    float *positions = malloc(sizeof(float) * 3 * (size_t)(nv ? nv : 1));
    float *uv = mesh->mTextureCoords[0] ? malloc(sizeof(float) * 2 * (size_t)(nv ? nv : 1)) : NULL;
    uint32_t *indices = malloc(sizeof(uint32_t) * 3 * (size_t)(nf ? nf : 1));
    scene_result rc = SCENE_ERR_NOMEM;
    if (!positions || !indices || (mesh->mTextureCoords[0] && !uv)) {
        rc = scene__fail(err, SCENE_ERR_NOMEM, "mesh '%s': out of memory", name);
        goto done;
    }
    for (uint32_t v = 0; v < nv; v++) {
        positions[3 * (size_t)v] = mesh->mVertices[v].x;
        positions[3 * (size_t)v + 1] = mesh->mVertices[v].y;
        positions[3 * (size_t)v + 2] = mesh->mVertices[v].z;
        if (uv) {
            uv[2 * (size_t)v] = mesh->mTextureCoords[0][v].x;
            uv[2 * (size_t)v + 1] = mesh->mTextureCoords[0][v].y;
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
    rc = scene__add_mesh(s, name, positions, nv, indices, nt, uv, material, xform, err);
done:
    free(positions);
    free(uv);
    free(indices);
    return rc;
}

scene_result scene__import_file(scene *s, const char *path, const double *xform,
                                const scene_material *override, scene_error *err)
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
    const unsigned post = aiProcess_Triangulate | aiProcess_PreTransformVertices | aiProcess_SortByPType;
    const struct aiScene *ai = NULL;
    size_t n = strlen(path);
    bool gz = n > 3 && strcasecmp(path + n - 3, ".gz") == 0;
    char inner[512];
    snprintf(inner, sizeof inner, "%.*s", (int)(gz ? n - 3 : n), path);
    const char *dot = strrchr(inner, '.');
    const char *hint = dot && !strchr(dot, '/') ? dot + 1 : "";
    const import_format *format = import_format_of(hint);
    char printed[200], why[400];
    if (format && format->refused)
        return scene__fail(err, SCENE_ERR_FORMAT, "%s: %s", path, format->refused);
    if (gz || (format && format->check)) {
        /* The whole file in memory, so the check sees the bytes Assimp reads (read_gz also reads plain
         * files: zlib passes them through). */
        char *buf = NULL;
        size_t len = 0;
        rc = read_gz(path, &buf, &len, err);
        if (rc != SCENE_OK)
            return rc;
        if (len == 0) {
            free(buf);
            return scene__fail(err, SCENE_ERR_FORMAT, "%s: %s", path, gz ? "decompresses to nothing" : "empty file");
        }
        if (len > UINT32_MAX) {
            free(buf);
            return scene__fail(err, SCENE_ERR_RANGE, "%s: larger than 4 GiB", path);
        }
        if (format && format->check && (rc = format->check(path, buf, len, err)) != SCENE_OK) {
            free(buf);
            return rc;
        }
        scene_cerr_capture *capture = scene_cerr_capture_begin();
        ai = aiImportFileFromMemory(buf, (unsigned)len, flags, hint);
        scene_cerr_capture_end(capture, printed, sizeof printed);
        free(buf);
    } else {
        scene_cerr_capture *capture = scene_cerr_capture_begin();
        ai = aiImportFile(path, flags);
        scene_cerr_capture_end(capture, printed, sizeof printed);
    }
    if (!ai)
        return scene__fail(err, SCENE_ERR_FORMAT, "%s: cannot import: %s%s%s%s", path,
                           assimp_error(why, sizeof why), printed[0] ? " (Assimp also printed: '" : "",
                           printed, printed[0] ? "')" : "");
    if (printed[0])
        fprintf(stderr, "fxcache: warning: %s: Assimp printed: '%s'\n", path, printed);
    scene_result checked = check_faces(path, ai, err);
    if (checked == SCENE_OK)
        checked = check_scene_graph(path, ai, err);
    if (checked != SCENE_OK) {
        aiReleaseImport(ai);
        return checked;
    }
    ai = aiApplyPostProcessing(ai, post);
    if (!ai)
        return scene__fail(err, SCENE_ERR_FORMAT, "%s: cannot import: %s", path,
                           assimp_error(why, sizeof why));

    char model_dir[512];
    folder_of(path, model_dir, sizeof model_dir);
    uint32_t *material_map = NULL;
    uint32_t override_index = UINT32_MAX;
    if (override) {
        override_index = scene__add_material(s, override, err);
        if (override_index == UINT32_MAX)
            rc = SCENE_ERR_NOMEM;
    } else {
        material_map = malloc(sizeof(uint32_t) * (ai->mNumMaterials ? ai->mNumMaterials : 1));
        if (!material_map)
            rc = scene__fail(err, SCENE_ERR_NOMEM, "%s: out of memory", path);
        for (uint32_t m = 0; rc == SCENE_OK && m < ai->mNumMaterials; m++)
            rc = import_material(s, ai->mMaterials[m], model_dir, &material_map[m], err);
        if (rc == SCENE_OK && ai->mNumMaterials == 0) {
            scene_material grey = {.diffuse = {0.7f, 0.7f, 0.7f}, .texture = -1, .name = "default"};
            override_index = scene__add_material(s, &grey, err);
            if (override_index == UINT32_MAX)
                rc = SCENE_ERR_NOMEM;
        }
    }
    uint32_t before = s->triangle_count;
    scene_repairs repairs_before = s->repairs;
    for (uint32_t i = 0; rc == SCENE_OK && i < ai->mNumMeshes; i++) {
        const struct aiMesh *mesh = ai->mMeshes[i];
        if (!(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) {
            s->repairs.non_triangles_dropped += mesh->mNumFaces;
            continue;
        }
        uint32_t material = override_index;
        if (material == UINT32_MAX)
            material = mesh->mMaterialIndex < ai->mNumMaterials ? material_map[mesh->mMaterialIndex]
                                                                : material_map[0]; /* this file's first */
        rc = import_mesh(s, mesh, i, material, xform, path, err);
    }
    if (rc == SCENE_OK && s->triangle_count == before)
        rc = scene__fail(
            err, SCENE_ERR_EMPTY,
            "%s: no usable triangles in the file (%llu points and lines dropped, %llu degenerate and "
            "%llu duplicate triangles skipped)",
            path,
            (unsigned long long)(s->repairs.non_triangles_dropped - repairs_before.non_triangles_dropped),
            (unsigned long long)(s->repairs.degenerate_skipped - repairs_before.degenerate_skipped),
            (unsigned long long)(s->repairs.duplicate_skipped - repairs_before.duplicate_skipped));
    free(material_map);
    aiReleaseImport(ai);
    return rc;
}
