/* The checks fxcache runs on a mesh file before Assimp reads it, by format (scene_import.c calls them
 * through scene__import_format_of()): declared counts against the file's size (PLY, OFF, STL, ASE, .x) and
 * the indices Assimp uses without checking (ASE, .x, MD5), each found crashing or exhausting memory on
 * damaged files; the OFF faces Assimp would drop or change silently; and the formats refused outright, with the reason. The input is untrusted: every check
 * reads within [buf, buf + len) and refuses with one line naming the file and, where known, the line. */
#include "scene_import_check.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

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
                return scene__fail(err, SCENE_ERR_FORMAT, "%s: not a PLY file (the first line is not 'ply')",
                                   path);
        } else if (m >= 10 && memcmp(start, "end_header", 10) == 0 &&
                   (m == 10 || start[10] == ' ' || start[10] == '\t')) {
            return scene__check_ply_body(path, buf, len, newline ? pos + n + 1 : len, err);
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

/* Skips blanks, line ends and '#' comment lines the way Assimp's OFF reader does (its SkipLine() ends a
 * comment at '\r' as well as '\n'). */
static const char *off_next_token(const char *p, const char *end)
{
    for (;;) {
        while (p < end && (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n'))
            p++;
        if (p >= end || *p != '#')
            return p;
        while (p < end && *p != '\n' && *p != '\r' && *p != '\0')
            p++;
    }
}

/* Assimp's line buffer (ParsingUtils.h BufferSize): GetNextLine() copies up to this many bytes of a line and
 * then writes its terminating zero one byte past the buffer; the rest of a longer line becomes the next. */
#define OFF_ASSIMP_LINE_BUFFER 4096

static bool off_line_end(char c)
{
    return c == '\r' || c == '\n' || c == '\0' || c == '\f';
}

/* The next line as Assimp's GetNextLine() splits the OFF body: false at the end of the data (Assimp's buffer
 * ends at the first zero byte); otherwise the line is [*start, *stop) and *p moves past it and every line
 * end after it, so blank lines are skipped. */
static bool off_next_line(const char **p, const char *end, const char **start, const char **stop)
{
    const char *q = *p;
    if (q >= end || *q == '\0')
        return false;
    *start = q;
    while (q < end && !off_line_end(*q))
        q++;
    *stop = q;
    while (q < end && off_line_end(*q) && *q != '\0')
        q++;
    *p = q;
    return true;
}

/* Checks the vertex and face lines of an OFF body the way Assimp 5.2.5's reader walks them, for what it
 * would otherwise do silently: it drops a face of more than 9 corners (or of 0, or whose count is not a
 * number), clamps a vertex index beyond the list to the last vertex, reads a missing or non-numeric index
 * (a negative one, say) as vertex 0, and overruns its line buffer by one byte on a line of 4096 bytes or
 * more. p is where Assimp starts reading vertex lines. Fewer lines than declared are left to Assimp,
 * which refuses the file. */
static scene_result off_check_body(const char *path, const char *buf, const char *p, const char *end,
                                   uint64_t vertices, uint64_t faces, scene_error *err)
{
    const char *start, *stop;
    for (uint64_t v = 0; v < vertices; v++) {
        if (!off_next_line(&p, end, &start, &stop))
            return SCENE_OK;
        if (stop - start >= OFF_ASSIMP_LINE_BUFFER)
            goto too_long;
    }
    for (uint64_t f = 0; f < faces; f++) {
        if (!off_next_line(&p, end, &start, &stop))
            return SCENE_OK;
        if (stop - start >= OFF_ASSIMP_LINE_BUFFER)
            goto too_long;
        const char *q = start;
        while (q < stop && (*q == ' ' || *q == '\t'))
            q++;
        uint64_t corners = 0;
        bool number = q < stop && *q >= '0' && *q <= '9';
        assimp_strtoul10(q, stop, &corners);
        if (!number)
            return scene__fail(err, SCENE_ERR_FORMAT,
                               "%s:%u: face %llu does not start with its corner count (Assimp's OFF reader "
                               "would drop it silently)",
                               path, line_of(buf, start), (unsigned long long)f);
        if (corners == 0 || corners > 9)
            return scene__fail(err, SCENE_ERR_FORMAT,
                               "%s:%u: face %llu has %llu corners; Assimp's OFF reader reads faces of 1 to 9 "
                               "corners and would drop it silently",
                               path, line_of(buf, start), (unsigned long long)f, (unsigned long long)corners);
        while (q < stop && *q >= '0' && *q <= '9')
            q++;
        for (uint64_t c = 0; c < corners; c++) {
            while (q < stop && (*q == ' ' || *q == '\t'))
                q++;
            uint64_t index = 0;
            if (q >= stop || *q < '0' || *q > '9')
                return scene__fail(err, SCENE_ERR_FORMAT,
                                   "%s:%u: face %llu: corner %llu of %llu is missing or not a vertex index",
                                   path, line_of(buf, start), (unsigned long long)f, (unsigned long long)c,
                                   (unsigned long long)corners);
            assimp_strtoul10(q, stop, &index);
            if (index >= vertices)
                return scene__fail(err, SCENE_ERR_FORMAT,
                                   "%s:%u: face %llu uses vertex %llu, but the file declares %llu vertices",
                                   path, line_of(buf, start), (unsigned long long)f,
                                   (unsigned long long)index, (unsigned long long)vertices);
            while (q < stop && *q >= '0' && *q <= '9')
                q++;
        }
    }
    return SCENE_OK;
too_long:
    return scene__fail(err, SCENE_ERR_FORMAT,
                       "%s:%u: a line of %lld bytes; Assimp's OFF reader reads lines of at most %d bytes",
                       path, line_of(buf, start), (long long)(stop - start), OFF_ASSIMP_LINE_BUFFER - 1);
}

/* Checks an OFF header's vertex and face counts against the file size before Assimp reads it: Assimp
 * allocates both arrays from the header alone. The header is parsed as Assimp parses it: optional "ST",
 * "C", "N", "4" and "n" prefixes, "OFF" (which may be absent), a dimension after "n", then the counts.
 * Then the body's lines and face indices (off_check_body()). */
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
    uint64_t declared[2] = {0, 0};
    for (int k = 0; k < 2; k++) {
        /* Assimp reads the counts as unsigned int: a count that wraps to a smaller one is refused here by
         * its unwrapped value, so the body below is walked with the counts Assimp uses */
        assimp_strtoul10(p, end, &declared[k]);
        scene_result rc = check_count_at(path, buf, p, what[k], declared[k], len, err);
        if (rc != SCENE_OK)
            return rc;
        while (p < end && *p >= '0' && *p <= '9')
            p++;
        p = off_next_token(p, end);
    }
    /* the edge count, which Assimp skips; the vertex lines start at the next token */
    while (p < end && *p >= '0' && *p <= '9')
        p++;
    p = off_next_token(p, end);
    return off_check_body(path, buf, p, end, declared[0], declared[1], err);
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

/* One *MESH block of an ASE file as Assimp's reader will use it. Assimp sizes a list when it meets the
 * list's block (*MESH_VERTEX_LIST, *MESH_FACE_LIST, *MESH_TVERTLIST, *MESH_CVERTLIST) to the count declared
 * before it (*MESH_NUMVERTEX, ...), and the list stays empty without its block. Per face: which of the
 * *MESH_FACE, *MESH_CFACE and *MESH_TFACE lines (per texture channel) filled it. */
enum { ASE_CHANNELS = 8, ASE_FACE = 1, ASE_CFACE = 2, ASE_TFACE0 = 4 };
typedef struct ase_mesh {
    uint64_t declared_faces, declared_vertices, declared_cvertices, declared_tvertices[ASE_CHANNELS];
    uint64_t faces, vertices, cvertices, tvertices[ASE_CHANNELS]; /* the lists' sizes */
    uint16_t *filled; /* per face: ASE_FACE | ASE_CFACE | ASE_TFACE0 << channel */
    uint64_t largest_corner, largest_ccorner, largest_tcorner[ASE_CHANNELS]; /* +1, 0: none */
    const char *start; /* where the block starts, for the message (line numbers only on failure: counting
                          them per block would make the check quadratic) */
} ase_mesh;

/* At the end of a *MESH block: a mesh with faces must have vertices, and every face Assimp allocated must be
 * filled by a *MESH_FACE line, and by a *MESH_CFACE / *MESH_TFACE line when the mesh has vertex colours /
 * texture vertices in that channel (Assimp reads those indices for every face; each of these segfaulted). */
static scene_result ase_check_mesh(const char *path, const char *buf, const ase_mesh *m, unsigned mesh_number,
                                   scene_error *err)
{
    if (m->faces > 0 && m->vertices == 0) /* Assimp clamps a vertex index to vertices - 1 */
        return scene__fail(err, SCENE_ERR_FORMAT, "%s:%u: mesh %u has %llu faces but no vertices", path,
                           line_of(buf, m->start), mesh_number, (unsigned long long)m->faces);
    /* Assimp does not check the corners against the lists (a corner of 159999999 segfaulted) */
    const char *beyond = m->largest_corner > m->vertices                         ? "*MESH_FACE"
                         : m->cvertices > 0 && m->largest_ccorner > m->cvertices ? "*MESH_CFACE"
                                                                                 : NULL;
    for (int c = 0; !beyond && c < ASE_CHANNELS; c++)
        if (m->tvertices[c] > 0 && m->largest_tcorner[c] > m->tvertices[c])
            beyond = "*MESH_TFACE";
    if (beyond)
        return scene__fail(err, SCENE_ERR_FORMAT, "%s:%u: mesh %u: a %s line uses a vertex beyond its list",
                           path, line_of(buf, m->start), mesh_number, beyond);
    for (uint64_t f = 0; f < m->faces; f++) {
        const char *missing = NULL;
        int channel = -1;
        if (!(m->filled[f] & ASE_FACE))
            missing = "*MESH_FACE";
        else if (m->cvertices > 0 && !(m->filled[f] & ASE_CFACE))
            missing = "*MESH_CFACE";
        for (int c = 0; !missing && c < ASE_CHANNELS; c++)
            if (m->tvertices[c] > 0 && !(m->filled[f] & (ASE_TFACE0 << c))) {
                missing = "*MESH_TFACE";
                channel = c;
            }
        if (missing)
            return scene__fail(
                err, SCENE_ERR_FORMAT,
                "%s:%u: mesh %u has no %s line for face %llu of its %llu%s (Assimp would read an "
                "uninitialised face)",
                path, line_of(buf, m->start), mesh_number, missing, (unsigned long long)f,
                (unsigned long long)m->faces, channel > 0 ? " in a mapping channel" : "");
    }
    return SCENE_OK;
}

/* Whether the text after a *MESH_FACE keyword is what Assimp's reader needs to set all three corners of the
 * face, on the keyword's line: an index, ':', then A:, B: and C: (in any order, each once) with a number. On
 * anything else it stops reading the line but keeps the face, with the corners it had not read
 * uninitialised (a "C:" with its number missing segfaulted). *largest gets the largest corner. */
static bool ase_face_line_complete(const char *p, const char *end, uint64_t *largest)
{
    *largest = 0;
    const char *newline = memchr(p, '\n', (size_t)(end - p));
    end = newline ? newline : end;
    while (p < end && (*p == ' ' || *p == '\t'))
        p++;
    if (p >= end || *p < '0' || *p > '9')
        return false;
    while (p < end && *p >= '0' && *p <= '9')
        p++;
    while (p < end && (*p == ' ' || *p == '\t'))
        p++;
    if (p >= end || *p != ':')
        return false;
    p++;
    unsigned corners = 0;
    for (int i = 0; i < 3; i++) {
        while (p < end && (*p == ' ' || *p == '\t'))
            p++;
        if (end - p < 2 || p[1] != ':')
            return false;
        int corner = *p == 'A' || *p == 'a'   ? 0
                     : *p == 'B' || *p == 'b' ? 1
                     : *p == 'C' || *p == 'c' ? 2
                                              : -1;
        if (corner < 0)
            return false;
        corners |= 1u << corner;
        for (p += 2; p < end && (*p == ' ' || *p == '\t');)
            p++;
        if (p >= end || *p < '0' || *p > '9')
            return false;
        uint64_t index = 0;
        assimp_strtoul10(p, end, &index);
        *largest = index > *largest ? index : *largest;
        while (p < end && *p >= '0' && *p <= '9')
            p++;
    }
    return corners == 7;
}

/* Reading an ASE file the way Assimp's reader walks it: each block (the file, a *MESH, a list in it) is its
 * own loop over every character, counting braces and ending when its depth returns to zero, and reacting
 * only to its own keywords (a keyword followed by a blank); a keyword of another block is ignored. */
enum ase_block_kind {
    ASE_FILE,
    ASE_MESH,
    ASE_CHANNEL,
    ASE_VERTEX_LIST,
    ASE_FACE_LIST,
    ASE_TVERT_LIST,
    ASE_TFACE_LIST,
    ASE_CVERT_LIST,
    ASE_CFACE_LIST,
    ASE_SKIP
};

typedef struct ase_reader {
    const char *path, *buf, *p, *end;
    scene_error *err;
    scene_result rc;
    unsigned mesh_number;
} ase_reader;

/* Whether the keyword at r->p is `keyword` followed by a blank or the end (Assimp's TokenMatch()); if so,
 * moves past it and reads the number after it (Assimp's ParseLV4MeshLong(): 0 without digits). */
static bool ase_keyword(ase_reader *r, const char *keyword, uint64_t *value)
{
    size_t n = strlen(keyword);
    if ((size_t)(r->end - r->p) < n || memcmp(r->p, keyword, n) != 0 ||
        (r->p + n < r->end && !is_blank(r->p[n])))
        return false;
    r->p += n;
    const char *q = r->p;
    while (q < r->end && (*q == ' ' || *q == '\t'))
        q++;
    assimp_strtoul10(q, r->end, value);
    return true;
}

/* Reads one block of kind `kind` from r->p (just after its keyword) to where Assimp's loop for it ends;
 * m is the mesh it belongs to (NULL at file level), channel its texture channel. */
static void ase_block(ase_reader *r, enum ase_block_kind kind, ase_mesh *m, int channel)
{
    int depth = 0;
    while (r->p < r->end && r->rc == SCENE_OK) {
        char c = *r->p;
        if (c == '{' || c == '}') {
            r->p++;
            if (c == '{')
                depth++;
            else if (--depth == 0 && kind != ASE_FILE)
                return;
            continue;
        }
        if (c != '*') {
            r->p++;
            continue;
        }
        const char *word = r->p;
        uint64_t value = 0, largest = 0;
        if (kind == ASE_FILE && ase_keyword(r, "*MESH", &value)) {
            ase_mesh mesh = {.start = word};
            ase_block(r, ASE_MESH, &mesh, 0);
            if (r->rc == SCENE_OK)
                r->rc = ase_check_mesh(r->path, r->buf, &mesh, r->mesh_number++, r->err);
            free(mesh.filled);
        } else if (kind == ASE_MESH && ase_keyword(r, "*MESH_NUMVERTEX", &value)) {
            m->declared_vertices = value;
        } else if (kind == ASE_MESH && ase_keyword(r, "*MESH_NUMFACES", &value)) {
            m->declared_faces = value;
        } else if (kind == ASE_MESH && ase_keyword(r, "*MESH_NUMCVERTEX", &value)) {
            m->declared_cvertices = value;
        } else if ((kind == ASE_MESH || kind == ASE_CHANNEL) && ase_keyword(r, "*MESH_NUMTVERTEX", &value)) {
            m->declared_tvertices[channel] = value;
        } else if (kind == ASE_MESH && ase_keyword(r, "*MESH_VERTEX_LIST", &value)) {
            m->vertices = m->declared_vertices; /* Assimp sizes each list as its block starts */
            ase_block(r, ASE_VERTEX_LIST, m, channel);
        } else if (kind == ASE_MESH && ase_keyword(r, "*MESH_FACE_LIST", &value)) {
            free(m->filled);
            m->faces = m->declared_faces;
            if (!(m->filled = calloc((size_t)m->faces + 1, sizeof *m->filled)))
                r->rc =
                    scene__fail(r->err, SCENE_ERR_NOMEM, "%s: out of memory checking the ASE file", r->path);
            else
                ase_block(r, ASE_FACE_LIST, m, channel);
        } else if (kind == ASE_MESH && ase_keyword(r, "*MESH_CVERTLIST", &value)) {
            m->cvertices = m->declared_cvertices;
            ase_block(r, ASE_CVERT_LIST, m, channel);
        } else if (kind == ASE_MESH && ase_keyword(r, "*MESH_CFACELIST", &value)) {
            ase_block(r, ASE_CFACE_LIST, m, channel);
        } else if ((kind == ASE_MESH || kind == ASE_CHANNEL) && ase_keyword(r, "*MESH_TVERTLIST", &value)) {
            m->tvertices[channel] = m->declared_tvertices[channel];
            ase_block(r, ASE_TVERT_LIST, m, channel);
        } else if ((kind == ASE_MESH || kind == ASE_CHANNEL) && ase_keyword(r, "*MESH_TFACELIST", &value)) {
            ase_block(r, ASE_TFACE_LIST, m, channel);
        } else if (kind == ASE_MESH && ase_keyword(r, "*MESH_MAPPINGCHANNEL", &value)) {
            /* Assimp reads channel N (2..8) into texture channel N - 1 and skips the others */
            bool valid = value >= 2 && value <= ASE_CHANNELS;
            ase_block(r, valid ? ASE_CHANNEL : ASE_SKIP, m, valid ? (int)value - 1 : 0);
        } else if (kind == ASE_FACE_LIST && ase_keyword(r, "*MESH_FACE", &value)) {
            if (!ase_face_line_complete(r->p, r->end, &largest))
                r->rc =
                    scene__fail(r->err, SCENE_ERR_FORMAT,
                                "%s:%u: a *MESH_FACE line that is not 'N: A: a B: b C: c' (Assimp would keep "
                                "the face with uninitialised corners)",
                                r->path, line_of(r->buf, word));
            else if (value < m->faces) {
                m->filled[value] |= ASE_FACE;
                m->largest_corner = largest + 1 > m->largest_corner ? largest + 1 : m->largest_corner;
            }
        } else if ((kind == ASE_TFACE_LIST && ase_keyword(r, "*MESH_TFACE", &value)) ||
                   (kind == ASE_CFACE_LIST && ase_keyword(r, "*MESH_CFACE", &value))) {
            /* "face a b c": the largest of a, b, c as Assimp reads them (no digits: 0) */
            const char *q = r->p;
            for (int i = 0; i < 4; i++) {
                while (q < r->end && (*q == ' ' || *q == '\t'))
                    q++;
                uint64_t index = 0;
                assimp_strtoul10(q, r->end, &index);
                if (i > 0)
                    largest = index > largest ? index : largest;
                while (q < r->end && *q >= '0' && *q <= '9')
                    q++;
            }
            if (value < m->faces) {
                bool colour = kind == ASE_CFACE_LIST;
                uint64_t *corner = colour ? &m->largest_ccorner : &m->largest_tcorner[channel];
                m->filled[value] |= colour ? ASE_CFACE : (uint16_t)(ASE_TFACE0 << channel);
                *corner = largest + 1 > *corner ? largest + 1 : *corner;
            }
        } else {
            r->p++; /* not a keyword of this block: Assimp moves on by one character */
        }
    }
}

/* Checks an ASE file before Assimp reads it. Every count it declares (*MESH_NUMVERTEX, *MESH_NUMFACES,
 * *MESH_NUMTVERTEX, ...: every "*...NUM..." or "*...COUNT..." keyword followed by a number) must be at most
 * the file size, as Assimp resizes its arrays to them (a 300000000 there made it touch 3.6 GB before reading
 * a vertex); and every *MESH must pass ase_check_mesh() as Assimp's reader will have filled it. */
static scene_result check_ase(const char *path, const char *buf, size_t len, scene_error *err)
{
    const char *end = buf + len;
    for (const char *p = buf; p < end; p++) {
        if (*p != '*')
            continue;
        const char *word = p;
        while (p + 1 < end && !is_blank(p[1]))
            p++;
        size_t n = (size_t)(p + 1 - word);
        bool counts = false;
        for (size_t k = 1; k + 3 <= n && !counts; k++)
            counts = memcmp(word + k, "NUM", 3) == 0 || (k + 5 <= n && memcmp(word + k, "COUNT", 5) == 0);
        if (!counts)
            continue;
        const char *q = p + 1;
        while (q < end && (*q == ' ' || *q == '\t'))
            q++;
        uint64_t value = 0;
        assimp_strtoul10(q, end, &value);
        char what[64];
        snprintf(what, sizeof what, "items (%.*s)", (int)(n < 40 ? n : 40), word);
        scene_result rc = check_count_at(path, buf, word, what, value, len, err);
        if (rc != SCENE_OK)
            return rc;
    }
    ase_reader r = {.path = path, .buf = buf, .p = buf, .end = end, .err = err, .rc = SCENE_OK};
    ase_block(&r, ASE_FILE, NULL, 0);
    return r.rc;
}

/* Skips one number of a text .x file and the separators after it; returns NULL when there is no number.
 * Besides digits it takes what Assimp's float reader takes: "nan" and "inf", and the "1.#IND" / "1.#QNAN"
 * forms some exporters write (missing one would put the next count where Assimp reads a coordinate). */
static const char *x_skip_number(const char *p, const char *end)
{
    const char *start = p;
    if (p < end && (*p == '-' || *p == '+'))
        p++;
    if (end - p >= 3 && (strncasecmp(p, "nan", 3) == 0 || strncasecmp(p, "inf", 3) == 0)) {
        p += 3;
        while (p < end && ((*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z')))
            p++;
    } else {
        while (p < end &&
               ((*p >= '0' && *p <= '9') || *p == '.' || *p == 'e' || *p == 'E' || *p == '-' || *p == '+'))
            p++;
        if (p < end && *p == '#')
            while (p < end && (*p == '#' || (*p >= 'A' && *p <= 'Z')))
                p++;
    }
    if (p == start || (p == start + 1 && (*start == '-' || *start == '+')))
        return NULL;
    while (p < end && (is_blank(*p) || *p == ';' || *p == ','))
        p++;
    return p;
}

/* Reads one integer of a text .x file as Assimp's reader does (an optional '-', digits) and skips the
 * separators after it; returns NULL when there is none. */
static const char *x_read_int(const char *p, const char *end, long long *out)
{
    if (!p || p >= end)
        return NULL;
    const char *q = p;
    bool negative = *q == '-';
    if (negative)
        q++;
    if (q >= end || *q < '0' || *q > '9')
        return NULL;
    long long v = 0;
    for (; q < end && *q >= '0' && *q <= '9'; q++)
        v = v > (LLONG_MAX - 9) / 10 ? LLONG_MAX : v * 10 + (*q - '0');
    *out = negative ? -v : v;
    return x_skip_number(p, end);
}

/* Checks a text DirectX .x file before Assimp reads it: the counts its Mesh, MeshNormals,
 * MeshTextureCoords, MeshVertexColors and MeshMaterialList objects declare must be at most the file size
 * (Assimp's X reader resizes its arrays to them: a vertex count of 300000000 made it touch 3.6 GB; the face
 * count of a Mesh comes after its vertices), and the faces of MeshNormals must use normals that exist (Assimp
 * does not check them: a normal index of -10 segfaulted). Binary and compressed .x files are not checked. */
static scene_result check_x(const char *path, const char *buf, size_t len, scene_error *err)
{
    if (len < 16 || memcmp(buf, "xof ", 4) != 0 || memcmp(buf + 8, "txt ", 4) != 0)
        return SCENE_OK;
    static const struct {
        const char *name;
        const char *what[2];      /* the first count, and the second (NULL: none) */
        unsigned numbers_between; /* numbers per item of the first list, before the second count */
    } objects[] = {
        {"Mesh", {"vertices (Mesh)", "faces (Mesh)"}, 3},
        {"MeshNormals", {"normals (MeshNormals)", "face normals (MeshNormals)"}, 3},
        {"MeshTextureCoords", {"texture coordinates (MeshTextureCoords)", NULL}, 0},
        {"MeshVertexColors", {"vertex colours (MeshVertexColors)", NULL}, 0},
        {"MeshMaterialList", {"materials (MeshMaterialList)", "face indexes (MeshMaterialList)"}, 0},
    };
    const char *end = buf + len;
    for (const char *p = buf + 16; p < end; p++) {
        if (p[-1] == '_' || (p[-1] >= 'A' && p[-1] <= 'Z') || (p[-1] >= 'a' && p[-1] <= 'z') ||
            (p[-1] >= '0' && p[-1] <= '9'))
            continue;
        for (size_t k = 0; k < sizeof objects / sizeof objects[0]; k++) {
            size_t n = strlen(objects[k].name);
            if ((size_t)(end - p) <= n || memcmp(p, objects[k].name, n) != 0 ||
                !(is_blank(p[n]) || p[n] == '{'))
                continue;
            /* NAME [identifier] { count; ... */
            const char *q = p + n;
            while (q < end && is_blank(*q))
                q++;
            while (q < end && !is_blank(*q) && *q != '{')
                q++;
            while (q < end && is_blank(*q))
                q++;
            if (q >= end || *q != '{')
                break;
            for (q++; q < end && is_blank(*q);)
                q++;
            uint64_t first_count = 0;
            for (int c = 0; c < 2 && objects[k].what[c] && q < end && ((*q >= '0' && *q <= '9') || *q == '-');
                 c++) {
                long long signed_count = 0;
                const char *count_at = q;
                if (!(q = x_read_int(q, end, &signed_count)))
                    break;
                /* Assimp reads a negative count as unsigned: -12 faces are 4294967284 */
                uint64_t declared = signed_count < 0 ? UINT64_MAX : (uint64_t)signed_count;
                scene_result rc = check_count_at(path, buf, count_at, objects[k].what[c], declared, len, err);
                if (rc != SCENE_OK)
                    return signed_count < 0
                               ? scene__fail(err, SCENE_ERR_FORMAT, "%s:%u: declares %lld %s", path,
                                             line_of(buf, count_at), signed_count, objects[k].what[c])
                               : rc;
                for (uint64_t skip = c == 0 ? declared * objects[k].numbers_between : 0; q && skip > 0;
                     skip--)
                    q = x_skip_number(q, end);
                if (!q)
                    break;
                if (c == 0)
                    first_count = declared;
                else if (k == 1) /* the faces of MeshNormals: count, then that many normal indices */
                    for (uint64_t f = 0; q && f < declared; f++) {
                        long long corners = 0, normal = 0;
                        q = x_read_int(q, end, &corners);
                        for (long long i = 0; q && i < corners; i++) {
                            const char *at = q;
                            q = x_read_int(q, end, &normal);
                            if (q && (normal < 0 || (uint64_t)normal >= first_count))
                                return scene__fail(
                                    err, SCENE_ERR_FORMAT,
                                    "%s:%u: a face of MeshNormals uses normal %lld, but it has %llu "
                                    "normals",
                                    path, line_of(buf, at), normal, (unsigned long long)first_count);
                        }
                    }
            }
            break;
        }
    }
    return SCENE_OK;
}

static const scene_import_format import_formats[] = {
    {"ply", check_ply, NULL},
    {"off", check_off, NULL},
    {"stl", check_stl, NULL},
    {"ase", check_ase, NULL},
    {"ask", check_ase, NULL},
    {"x", check_x, NULL},
    {"md5mesh", scene__check_md5, NULL},
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

const scene_import_format *scene__import_format_of(const char *ext)
{
    for (size_t i = 0; i < sizeof import_formats / sizeof import_formats[0]; i++)
        if (strcasecmp(ext, import_formats[i].ext) == 0)
            return &import_formats[i];
    return NULL;
}
