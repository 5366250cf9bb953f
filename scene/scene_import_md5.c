/* The check of an MD5 mesh (.md5mesh) before Assimp reads it (scene__import_format_of, scene_import_check.c):
 * the indices Assimp uses without checking (a vertex's weights, a triangle's vertices, a weight's joint) must lie
 * within the lists it builds, and no declared count may exceed what the file can hold. The input is untrusted:
 * every check reads within [buf, buf + len) and refuses with one line naming the file and the line. */
#include "scene_import_check.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* One kind of indexed line in an MD5 mesh ("vert", "tri", "weight"): the list Assimp builds from it. */
typedef struct md5_list {
    uint64_t count; /* max(declared, largest index + 1): the length of Assimp's list */
    uint8_t *seen;  /* seen[i]: a line fills entry i (capacity entries, zero beyond what was set) */
    uint64_t capacity;
} md5_list;

/* Makes list->seen hold at least n entries (n is at most the file size plus one). */
static bool md5_reserve(md5_list *list, uint64_t n)
{
    if (n <= list->capacity)
        return true;
    uint64_t cap = list->capacity ? list->capacity : 64;
    while (cap < n)
        cap *= 2;
    uint8_t *bigger = realloc(list->seen, (size_t)cap);
    if (!bigger)
        return false;
    memset(bigger + list->capacity, 0, (size_t)(cap - list->capacity));
    list->seen = bigger;
    list->capacity = cap;
    return true;
}

/* Copies the line at p (up to its end or line_end) into a NUL-terminated buffer, for sscanf. */
static void md5_line_copy(const char *p, const char *line_end, char *out, size_t cap)
{
    size_t n = (size_t)(line_end - p);
    n = n < cap - 1 ? n : cap - 1;
    memcpy(out, p, n);
    out[n] = 0;
}

/* Strict readers for one field of an MD5 line: they advance *p past the field and return false when the text
 * is not that field. */
static void md5_blanks(const char **p)
{
    while (**p == ' ' || **p == '\t')
        (*p)++;
}

static bool md5_uint(const char **p, unsigned long long *out)
{
    md5_blanks(p);
    if (**p < '0' || **p > '9')
        return false;
    unsigned long long v = 0;
    for (; **p >= '0' && **p <= '9'; (*p)++)
        v = v > (ULLONG_MAX - 9) / 10 ? ULLONG_MAX : v * 10 + (unsigned long long)(**p - '0');
    *out = v;
    return true;
}

static bool md5_int(const char **p, long long *out)
{
    md5_blanks(p);
    bool negative = **p == '-';
    if (negative)
        (*p)++;
    unsigned long long v = 0;
    if (!md5_uint(p, &v) || v > LLONG_MAX)
        return false;
    *out = negative ? -(long long)v : (long long)v;
    return true;
}

/* Whether the line (n bytes, blanks before it skipped) starts with keyword as Assimp's TokenMatch() sees
 * it: followed by a blank or by the end of the line. */
static bool md5_keyword(const char *line, size_t n, const char *keyword)
{
    size_t kl = strlen(keyword);
    return n >= kl && memcmp(line, keyword, kl) == 0 && (n == kl || line[kl] == ' ' || line[kl] == '\t');
}

static bool md5_float(const char **p)
{
    md5_blanks(p);
    if (**p == '-')
        (*p)++;
    const char *digits = *p;
    while ((**p >= '0' && **p <= '9') || **p == '.')
        (*p)++;
    if (*p == digits)
        return false;
    if (**p == 'e' || **p == 'E') {
        (*p)++;
        if (**p == '-' || **p == '+')
            (*p)++;
        if (**p < '0' || **p > '9')
            return false;
        while (**p >= '0' && **p <= '9')
            (*p)++;
    }
    return true;
}

static bool md5_char(const char **p, char c)
{
    md5_blanks(p);
    if (**p != c)
        return false;
    (*p)++;
    return true;
}

/* The end of an MD5 line: blanks, then nothing or a // comment. */
static bool md5_line_end(const char *p)
{
    md5_blanks(&p);
    return *p == 0 || (p[0] == '/' && p[1] == '/');
}

/* Checks the lists of one MD5 mesh once its block has ended (lines from mesh_start to mesh_end). Every vert,
 * tri and weight line must have the exact form Assimp reads field by field (on anything else it reads other
 * fields than the ones meant); every list entry must be filled by a line; a vertex's weights must lie within
 * the weights, a weight's joint within the joints, a triangle's corners within the vertices; and a mesh with
 * triangles must use every vertex: Assimp's reader makes a copy of each vertex for every further triangle
 * corner that uses it into a list of 3 x triangles entries, and writes past that list when a vertex is
 * unused (heap corruption, found by mutating files). */
static scene_result md5_check_mesh(const char *path, const char *buf, const char *mesh_start,
                                   const char *mesh_end, unsigned mesh_number, const md5_list lists[3],
                                   uint64_t joints, scene_error *err)
{
    static const char *const kinds[3] = {"vert", "tri", "weight"};
    for (int k = 0; k < 3; k++)
        for (uint64_t i = 0; i < lists[k].count; i++)
            if (!lists[k].seen[i])
                return scene__fail(
                    err, SCENE_ERR_FORMAT,
                    "%s:%u: mesh %u has no %s line for index %llu of its %llu (Assimp would read "
                    "an uninitialised entry)",
                    path, line_of(buf, mesh_start), mesh_number, kinds[k], (unsigned long long)i,
                    (unsigned long long)lists[k].count);
    uint64_t verts = lists[0].count, tris = lists[1].count, weights = lists[2].count;
    uint8_t *used = calloc((size_t)verts + 1, 1);
    if (!used)
        return scene__fail(err, SCENE_ERR_NOMEM, "%s: out of memory checking the MD5 mesh", path);
    scene_result rc = SCENE_OK;
    for (const char *q = mesh_start; q < mesh_end && rc == SCENE_OK;) {
        const char *qe = memchr(q, '\n', (size_t)(mesh_end - q));
        qe = qe ? qe : mesh_end;
        char text[256];
        md5_line_copy(q, qe, text, sizeof text);
        const char *line_at = q;
        q = qe + 1;
        const char *t = text;
        md5_blanks(&t);
        /* the other keywords Assimp reads in a mesh: "shader" with a quoted name, the three counts */
        static const char *const others[4] = {"shader", "numverts", "numtris", "numweights"};
        int other = -1;
        for (int k = 0; k < 4 && other < 0; k++)
            if (md5_keyword(t, strlen(t), others[k]))
                other = k;
        if (other >= 0) {
            const char *f = t + strlen(others[other]);
            unsigned long long value = 0;
            const char *close = NULL;
            bool ok = other > 0 ? md5_uint(&f, &value)
                                : (md5_char(&f, '"') && (close = strchr(f, '"')) != NULL && (f = close + 1));
            if (!ok || !md5_line_end(f))
                rc = scene__fail(err, SCENE_ERR_FORMAT, "%s:%u: malformed %s line: '%.60s'", path,
                                 line_of(buf, line_at), others[other], t);
            continue;
        }
        int kind = -1;
        for (int k = 0; k < 3 && kind < 0; k++)
            if (md5_keyword(t, strlen(t), kinds[k]))
                kind = k;
        if (kind < 0)
            continue;
        const char *f = t + strlen(kinds[kind]);
        unsigned long long index = 0, first = 0, count = 0, corner[3] = {0}, joint = 0;
        bool ok = md5_uint(&f, &index);
        if (kind == 0)
            ok = ok && md5_char(&f, '(') && md5_float(&f) && md5_float(&f) && md5_char(&f, ')') &&
                 md5_uint(&f, &first) && md5_uint(&f, &count);
        else if (kind == 1)
            ok = ok && md5_uint(&f, &corner[0]) && md5_uint(&f, &corner[1]) && md5_uint(&f, &corner[2]);
        else
            ok = ok && md5_uint(&f, &joint) && md5_float(&f) && md5_char(&f, '(') && md5_float(&f) &&
                 md5_float(&f) && md5_float(&f) && md5_char(&f, ')');
        if (!ok || !md5_line_end(f))
            rc = scene__fail(err, SCENE_ERR_FORMAT, "%s:%u: malformed %s line: '%.60s'", path,
                             line_of(buf, line_at), kinds[kind], t);
        else if (kind == 0 && (first > weights || count > weights - first))
            rc = scene__fail(
                err, SCENE_ERR_FORMAT,
                "%s:%u: vert %llu uses %llu weights from weight %llu, but mesh %u has %llu weights", path,
                line_of(buf, line_at), index, count, first, mesh_number, (unsigned long long)weights);
        else if (kind == 1 && (corner[0] >= verts || corner[1] >= verts || corner[2] >= verts))
            rc = scene__fail(err, SCENE_ERR_FORMAT,
                             "%s:%u: tri %llu uses a vertex beyond mesh %u's %llu vertices", path,
                             line_of(buf, line_at), index, mesh_number, (unsigned long long)verts);
        else if (kind == 2 && joint >= joints)
            rc = scene__fail(err, SCENE_ERR_FORMAT,
                             "%s:%u: weight %llu uses joint %llu, but Assimp finds %llu joints in the file",
                             path, line_of(buf, line_at), index, joint, (unsigned long long)joints);
        else if (kind == 1)
            used[corner[0]] = used[corner[1]] = used[corner[2]] = 1;
    }
    for (uint64_t v = 0; rc == SCENE_OK && tris > 0 && v < verts; v++)
        if (!used[v])
            rc = scene__fail(
                err, SCENE_ERR_FORMAT,
                "%s:%u: mesh %u: vert %llu is used by no triangle (Assimp's MD5 reader then writes past "
                "its vertex list)",
                path, line_of(buf, mesh_start), mesh_number, (unsigned long long)v);
    free(used);
    return rc;
}

/* Reads the first-pass facts of one element (line) of an MD5 mesh block into the lists: a declared count or
 * the index of a vert, tri or weight line (at most the file size, so the lists stay small). */
static scene_result md5_mesh_element(const char *path, const char *buf, size_t len, const char *line,
                                     const char *line_end, md5_list lists[3], scene_error *err)
{
    static const char *const kinds[3] = {"vert", "tri", "weight"};
    static const char *const numbers[3] = {"numverts", "numtris", "numweights"};
    size_t n = (size_t)(line_end - line);
    for (int k = 0; k < 3; k++) {
        bool number_line = md5_keyword(line, n, numbers[k]), item_line = md5_keyword(line, n, kinds[k]);
        if (!number_line && !item_line)
            continue;
        const char *q = line + strlen(number_line ? numbers[k] : kinds[k]);
        while (q < line_end && (*q == ' ' || *q == '\t'))
            q++;
        uint64_t value = 0;
        assimp_strtoul10(q, line_end, &value);
        md5_list *list = &lists[k];
        if (value > len)
            return scene__fail(
                err, SCENE_ERR_FORMAT, "%s:%u: %s %llu, more than the file's %zu bytes can hold", path,
                line_of(buf, line), number_line ? numbers[k] : kinds[k], (unsigned long long)value, len);
        if (!md5_reserve(list, value + 1))
            return scene__fail(err, SCENE_ERR_NOMEM, "%s: out of memory checking the MD5 mesh", path);
        if (!number_line)
            list->seen[value] = 1;
        uint64_t count = number_line ? value : value + 1;
        list->count = count > list->count ? count : list->count;
        return SCENE_OK;
    }
    return SCENE_OK;
}

/* Checks one element of a joints block: "name" parent ( x y z ) ( qx qy qz ). Assimp takes every element of
 * the block for a joint and looks for the name's quotation marks past the end of the line. */
static scene_result md5_joint_element(const char *path, const char *buf, const char *line,
                                      const char *line_end, scene_error *err)
{
    char text[256];
    md5_line_copy(line, line_end, text, sizeof text);
    const char *f = text;
    long long parent = 0;
    const char *close = text[0] == '"' ? strchr(text + 1, '"') : NULL;
    bool ok = close && (f = close + 1, md5_int(&f, &parent)) && md5_char(&f, '(') && md5_float(&f) &&
              md5_float(&f) && md5_float(&f) && md5_char(&f, ')') && md5_char(&f, '(') && md5_float(&f) &&
              md5_float(&f) && md5_float(&f) && md5_char(&f, ')') && md5_line_end(f);
    if (!ok)
        return scene__fail(err, SCENE_ERR_FORMAT, "%s:%u: malformed joint line: '%.60s'", path,
                           line_of(buf, line), text);
    return SCENE_OK;
}

/* Walks the sections of an MD5 file as Assimp's parser splits them, and checks them (pass 0: the joints
 * blocks, counting the joints into *joints; pass 1: the mesh blocks, against that count). A section is a
 * name, then values and at most one { } block of lines; after a value Assimp consumes one more character, so
 * a value at the end of a line continues the section on the next line unless that line is blank or indented:
 * "numMeshes 1" directly above "joints {" makes that block part of the numMeshes section, no joints at all.
 */
static scene_result md5_sections(const char *path, const char *buf, size_t len, int pass, uint64_t *joints,
                                 scene_error *err)
{
    const char *end = buf + len;
    unsigned mesh_number = 0;
    scene_result rc = SCENE_OK;
    for (const char *p = buf; p < end && rc == SCENE_OK;) {
        while (p < end && is_blank(*p))
            p++;
        if (p >= end)
            break;
        const char *name = p;
        while (p < end && !is_blank(*p))
            p++;
        size_t name_len = (size_t)(p - name);
        while (p < end && (*p == ' ' || *p == '\t'))
            p++;
        const char *value = NULL;                       /* Assimp keeps the last value of a section */
        while (p < end && *p != '{' && !is_blank(*p)) { /* values, each with the character after it */
            value = p;
            while (p < end && !is_blank(*p))
                p++;
            if (p < end)
                p++;
        }
        bool reserves = (name_len == 9 && memcmp(name, "numJoints", 9) == 0) ||
                        (name_len == 9 && memcmp(name, "numMeshes", 9) == 0);
        if (value && reserves && pass == 0) { /* Assimp reserves that many joints or meshes */
            uint64_t count = 0;
            assimp_strtoul10(value, end, &count);
            char what[32];
            snprintf(what, sizeof what, "items (%.*s)", (int)name_len, name);
            if ((rc = check_count_at(path, buf, value, what, count, len, err)) != SCENE_OK)
                break;
        }
        if (p >= end || *p != '{')
            continue;
        bool joints_block = name_len == 6 && memcmp(name, "joints", 6) == 0;
        bool mesh_block = name_len == 4 && memcmp(name, "mesh", 4) == 0;
        const char *block_start = ++p;
        md5_list lists[3] = {{0}};
        while (rc == SCENE_OK) { /* one element per line, to a line starting with '}' */
            while (p < end && is_blank(*p))
                p++;
            if (p >= end || *p == '}')
                break;
            const char *line = p, *eol = memchr(p, '\n', (size_t)(end - p));
            const char *line_end = eol ? eol : end;
            p = eol ? eol + 1 : end;
            unsigned quotes = 0;
            for (const char *q = line; q < line_end; q++)
                quotes += *q == '"';
            if (quotes % 2) /* Assimp looks for the closing quotation mark past the end of the line */
                rc = scene__fail(err, SCENE_ERR_FORMAT, "%s:%u: a quotation mark not closed on its line",
                                 path, line_of(buf, line));
            else if (joints_block && pass == 0 &&
                     (rc = md5_joint_element(path, buf, line, line_end, err)) == SCENE_OK)
                (*joints)++;
            else if (mesh_block && pass == 1)
                rc = md5_mesh_element(path, buf, len, line, line_end, lists, err);
        }
        if (rc == SCENE_OK && mesh_block && pass == 1)
            rc = md5_check_mesh(path, buf, block_start, p, mesh_number++, lists, *joints, err);
        for (int k = 0; k < 3; k++)
            free(lists[k].seen);
        if (p < end)
            p++; /* the '}' */
    }
    return rc;
}

/* Checks an MD5 mesh the way Assimp's reader will use it (md5_sections(), md5_check_mesh()): every quoted
 * string must close on its line (a shader name without its closing quotation mark made Assimp read past its
 * buffer); every count and index must be at most the file size; and the lists of each mesh must be complete
 * and refer to each other within range. */
scene_result scene__check_md5(const char *path, const char *buf, size_t len, scene_error *err)
{
    uint64_t joints = 0;
    scene_result rc = md5_sections(path, buf, len, 0, &joints, err);
    return rc == SCENE_OK ? md5_sections(path, buf, len, 1, &joints, err) : rc;
}
