/* The check of a PLY body against its header before Assimp reads it (check_ply in scene_import_check.c calls
 * it once the header has passed): Assimp 5.2.5 reads a vertex line with too few values as zeros, ignores
 * extra values and lines, loads a file with fewer faces than declared (the missing ones as copies), and
 * reports a truncated binary body or a face index out of range as "Validation failed: mIndices[2] is out of
 * range". Here every line of an ASCII body must hold exactly the values its element's properties declare,
 * each a number (list counts and face indices whole numbers), a binary body must hold every item the header
 * declares, and a face's vertex indices must lie within the vertex element. A header this check does not
 * model (an unknown format or type, a property before any element, too many elements) is left to Assimp.
 * The input is untrusted: every read stays within [buf, buf + len); refusals are one line naming the file
 * and, in ASCII, the line. */
#include "scene_import_check.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PLY_MAX_ELEMENTS   64
#define PLY_MAX_PROPERTIES 512
#define PLY_MAX_TOKEN      256 /* an ASCII value longer than this is refused as not a number */

/* A property's value type; 0 is unknown. */
enum { PLY_T_NONE, PLY_T_I8, PLY_T_U8, PLY_T_I16, PLY_T_U16, PLY_T_I32, PLY_T_U32, PLY_T_F32, PLY_T_F64 };

typedef struct ply_property {
    uint8_t type;       /* the value's type (a list's items) */
    uint8_t count_type; /* a list's count type, PLY_T_NONE for a scalar */
    bool face_index;    /* a face's vertex_indices (or vertex_index) list */
    char name[40];      /* for messages, cut short */
} ply_property;

typedef struct ply_element {
    char name[40];
    uint64_t count;
    uint32_t first, properties; /* its properties: [first, first + properties) */
} ply_element;

typedef struct ply_header {
    enum { PLY_ASCII, PLY_LITTLE, PLY_BIG } format;
    ply_element elements[PLY_MAX_ELEMENTS];
    ply_property properties[PLY_MAX_PROPERTIES];
    uint32_t element_count, property_count;
    uint64_t vertices; /* the vertex element's count */
} ply_header;

static uint8_t ply_type(const char *p, size_t n)
{
    static const struct {
        const char *name;
        uint8_t type;
    } types[] = {{"char", PLY_T_I8},   {"int8", PLY_T_I8},     {"uchar", PLY_T_U8},   {"uint8", PLY_T_U8},
                 {"short", PLY_T_I16}, {"int16", PLY_T_I16},   {"ushort", PLY_T_U16}, {"uint16", PLY_T_U16},
                 {"int", PLY_T_I32},   {"int32", PLY_T_I32},   {"uint", PLY_T_U32},   {"uint32", PLY_T_U32},
                 {"float", PLY_T_F32}, {"float32", PLY_T_F32}, {"double", PLY_T_F64}, {"float64", PLY_T_F64}};
    for (size_t k = 0; k < sizeof types / sizeof types[0]; k++)
        if (strlen(types[k].name) == n && memcmp(types[k].name, p, n) == 0)
            return types[k].type;
    return PLY_T_NONE;
}

static size_t ply_type_size(uint8_t type)
{
    static const size_t sizes[] = {0, 1, 1, 2, 2, 4, 4, 4, 8};
    return sizes[type];
}

/* The next blank-separated word of [*p, end): false when there is none. */
static bool next_word(const char **p, const char *end, const char **word, size_t *n)
{
    const char *q = *p;
    while (q < end && is_blank(*q))
        q++;
    if (q >= end)
        return false;
    *word = q;
    while (q < end && !is_blank(*q))
        q++;
    *n = (size_t)(q - *word);
    *p = q;
    return true;
}

static bool word_is(const char *word, size_t n, const char *what)
{
    return strlen(what) == n && memcmp(word, what, n) == 0;
}

/* Parses the header's format, element and property lines ([buf, body)). False when the header holds
 * something this check does not model: the body is then left to Assimp. */
static bool parse_header(const char *buf, const char *body, ply_header *h)
{
    memset(h, 0, sizeof *h);
    bool format = false;
    for (const char *line = buf; line < body;) {
        const char *newline = memchr(line, '\n', (size_t)(body - line));
        const char *end = newline ? newline : body, *p = line, *word;
        size_t n;
        line = newline ? newline + 1 : body;
        if (!next_word(&p, end, &word, &n))
            continue;
        if (word_is(word, n, "format")) {
            if (!next_word(&p, end, &word, &n))
                return false;
            if (word_is(word, n, "ascii"))
                h->format = PLY_ASCII;
            else if (word_is(word, n, "binary_little_endian"))
                h->format = PLY_LITTLE;
            else if (word_is(word, n, "binary_big_endian"))
                h->format = PLY_BIG;
            else
                return false;
            format = true;
        } else if (word_is(word, n, "element")) {
            if (h->element_count == PLY_MAX_ELEMENTS || !next_word(&p, end, &word, &n))
                return false;
            ply_element *e = &h->elements[h->element_count++];
            snprintf(e->name, sizeof e->name, "%.*s", (int)(n < 39 ? n : 39), word);
            const char *count;
            size_t count_len;
            if (!next_word(&p, end, &count, &count_len))
                return false;
            assimp_strtoul10(count, count + count_len, &e->count);
            e->first = h->property_count;
            if (strcmp(e->name, "vertex") == 0)
                h->vertices = e->count;
        } else if (word_is(word, n, "property")) {
            if (h->element_count == 0 || h->property_count == PLY_MAX_PROPERTIES ||
                !next_word(&p, end, &word, &n))
                return false;
            ply_property *prop = &h->properties[h->property_count];
            if (word_is(word, n, "list")) {
                if (!next_word(&p, end, &word, &n))
                    return false;
                prop->count_type = ply_type(word, n);
                if (prop->count_type == PLY_T_NONE || prop->count_type >= PLY_T_F32 ||
                    !next_word(&p, end, &word, &n))
                    return false;
            }
            prop->type = ply_type(word, n);
            if (prop->type == PLY_T_NONE || !next_word(&p, end, &word, &n))
                return false;
            snprintf(prop->name, sizeof prop->name, "%.*s", (int)(n < 39 ? n : 39), word);
            ply_element *e = &h->elements[h->element_count - 1];
            prop->face_index = prop->count_type != PLY_T_NONE && strcmp(e->name, "face") == 0 &&
                               (word_is(word, n, "vertex_indices") || word_is(word, n, "vertex_index"));
            h->property_count++;
            e->properties++;
        }
    }
    return format;
}

/* ---- ASCII ---------------------------------------------------------------------------------------- */

static bool ply_line_end(char c)
{
    return c == '\r' || c == '\n' || c == '\0' || c == '\f';
}

/* The next line as Assimp 5.2.5's IOStreamBuffer::getNextLine() splits an ASCII body: false at its end. A
 * line end where a line should start is skipped through the next '\n' (one blank line, or the '\n' of a
 * CRLF); the line is [*start, *stop), and *p moves one byte past its end. So a second blank line in a row,
 * or one of blanks, is a line of its own: an item with no values. */
static bool ply_next_line(const char **p, const char *end, const char **start, const char **stop)
{
    const char *q = *p;
    if (q < end && ply_line_end(*q)) {
        while (q < end && *q != '\n')
            q++;
        q = q < end ? q + 1 : end;
    }
    if (q >= end)
        return false;
    *start = q;
    while (q < end && !ply_line_end(*q))
        q++;
    *stop = q;
    *p = q < end ? q + 1 : end;
    return true;
}

/* One ASCII value: a number strtod reads whole (a whole number, optionally signed, when `whole`). */
static bool ascii_number(const char *word, size_t n, bool whole, double *value)
{
    char copy[PLY_MAX_TOKEN + 1];
    if (n > PLY_MAX_TOKEN)
        return false;
    memcpy(copy, word, n);
    copy[n] = 0;
    if (whole) {
        size_t k = copy[0] == '-' || copy[0] == '+';
        if (k == n)
            return false;
        for (; k < n; k++)
            if (copy[k] < '0' || copy[k] > '9')
                return false;
    }
    char *stop;
    *value = strtod(copy, &stop);
    return stop == copy + n;
}

static scene_result check_ascii(const char *path, const char *buf, const char *body, const char *end,
                                const ply_header *h, scene_error *err)
{
    const char *p = body;
    for (uint32_t ei = 0; ei < h->element_count; ei++) {
        const ply_element *e = &h->elements[ei];
        for (uint64_t item = 0; item < e->count; item++) {
            /* the item's line, as Assimp splits the body */
            const char *line, *stop, *word;
            size_t n;
            if (!ply_next_line(&p, end, &line, &stop))
                return scene__fail(
                    err, SCENE_ERR_FORMAT,
                    "%s: the body ends before item %llu of the %llu of element '%s' the header "
                    "declares",
                    path, (unsigned long long)item, (unsigned long long)e->count, e->name);
            const char *first = line;
            if (e->properties && !next_word(&first, stop, &word, &n))
                return scene__fail(
                    err, SCENE_ERR_FORMAT,
                    "%s:%u: a blank line where item %llu of element '%s' should be (Assimp's PLY "
                    "reader takes it for that item and misreads the rest)",
                    path, line_of(buf, line), (unsigned long long)item, e->name);
            const char *q = line;
            uint64_t values = 0;                   /* the values read on the line */
            uint64_t expected = 0;                 /* the values the properties read so far declare */
            uint32_t short_at = 0;                 /* the property the line ran out in */
            bool short_line = false, exact = true; /* exact: expected is the line's whole count */
            for (uint32_t pi = e->first; pi < e->first + e->properties && !short_line; pi++) {
                const ply_property *prop = &h->properties[pi];
                uint64_t items = 1;
                double value;
                if (prop->count_type != PLY_T_NONE) {
                    expected++;
                    if (!next_word(&q, stop, &word, &n)) {
                        exact = false; /* the list's length is not on the line */
                        short_line = true;
                        short_at = pi;
                        break;
                    }
                    values++;
                    if (!ascii_number(word, n, true, &value) || value < 0 || value > 1e9)
                        return scene__fail(err, SCENE_ERR_FORMAT,
                                           "%s:%u: '%.*s' is not a list length (element '%s' item %llu, "
                                           "property '%s')",
                                           path, line_of(buf, word), (int)(n < 40 ? n : 40), word, e->name,
                                           (unsigned long long)item, prop->name);
                    items = (uint64_t)value;
                }
                expected += items;
                for (uint64_t k = 0; k < items; k++) {
                    if (!next_word(&q, stop, &word, &n)) {
                        short_line = true;
                        short_at = pi;
                        break;
                    }
                    values++;
                    bool whole = prop->type < PLY_T_F32;
                    if (!ascii_number(word, n, whole, &value))
                        return scene__fail(err, SCENE_ERR_FORMAT,
                                           "%s:%u: '%.*s' is not %s (element '%s' item %llu, property '%s')",
                                           path, line_of(buf, word), (int)(n < 40 ? n : 40), word,
                                           whole ? "a whole number" : "a number", e->name,
                                           (unsigned long long)item, prop->name);
                    if (prop->face_index && !(value >= 0 && value < (double)h->vertices))
                        return scene__fail(err, SCENE_ERR_FORMAT,
                                           "%s:%u: face %llu uses vertex %.*s, but the file declares %llu "
                                           "vertices",
                                           path, line_of(buf, word), (unsigned long long)item,
                                           (int)(n < 40 ? n : 40), word, (unsigned long long)h->vertices);
                }
            }
            if (short_line)
                for (uint32_t pi = short_at + 1; pi < e->first + e->properties; pi++) {
                    expected++;
                    exact = exact && h->properties[pi].count_type == PLY_T_NONE;
                }
            uint64_t extra = 0;
            while (next_word(&q, stop, &word, &n))
                extra++;
            if (short_line || extra)
                return scene__fail(
                    err, SCENE_ERR_FORMAT,
                    "%s:%u: element '%s' item %llu has %llu values, the header declares %s%llu", path,
                    line_of(buf, line), e->name, (unsigned long long)item,
                    (unsigned long long)(values + extra), exact ? "" : "at least ",
                    (unsigned long long)expected);
        }
    }
    const char *word = p;
    while (word < end && (is_blank(*word) || *word == '\0' || *word == '\f'))
        word++;
    size_t n = 0;
    while (word + n < end && !is_blank(word[n]))
        n++;
    if (word < end)
        return scene__fail(err, SCENE_ERR_FORMAT,
                           "%s:%u: data after the last item the header declares: '%.*s'", path,
                           line_of(buf, word), (int)(n < 40 ? n : 40), word);
    return SCENE_OK;
}

/* ---- binary --------------------------------------------------------------------------------------- */

/* A binary value at p (ply_type_size(type) bytes in the file's byte order), as a double. */
static double binary_value(const unsigned char *p, uint8_t type, bool big)
{
    size_t size = ply_type_size(type);
    uint64_t bits = 0;
    for (size_t k = 0; k < size; k++)
        bits |= (uint64_t)p[big ? size - 1 - k : k] << (8 * k);
    switch (type) {
    case PLY_T_I8: return (double)(int8_t)(uint8_t)bits;
    case PLY_T_I16: return (double)(int16_t)(uint16_t)bits;
    case PLY_T_I32: return (double)(int32_t)(uint32_t)bits;
    case PLY_T_F32: {
        uint32_t b32 = (uint32_t)bits;
        float f;
        memcpy(&f, &b32, sizeof f);
        return f;
    }
    case PLY_T_F64: {
        double d;
        memcpy(&d, &bits, sizeof d);
        return d;
    }
    default: return (double)bits;
    }
}

static scene_result check_binary(const char *path, const char *body, const char *end, const ply_header *h,
                                 scene_error *err)
{
    const unsigned char *p = (const unsigned char *)body, *stop = (const unsigned char *)end;
    bool big = h->format == PLY_BIG;
    for (uint32_t ei = 0; ei < h->element_count; ei++) {
        const ply_element *e = &h->elements[ei];
        for (uint64_t item = 0; item < e->count; item++)
            for (uint32_t pi = e->first; pi < e->first + e->properties; pi++) {
                const ply_property *prop = &h->properties[pi];
                uint64_t items = 1;
                size_t size = ply_type_size(prop->type);
                if (prop->count_type != PLY_T_NONE) {
                    size_t count_size = ply_type_size(prop->count_type);
                    if ((size_t)(stop - p) < count_size)
                        goto truncated;
                    double count = binary_value(p, prop->count_type, big);
                    p += count_size;
                    if (count < 0)
                        return scene__fail(err, SCENE_ERR_FORMAT,
                                           "%s: element '%s' item %llu: property '%s' has a list of length "
                                           "%.0f",
                                           path, e->name, (unsigned long long)item, prop->name, count);
                    items = (uint64_t)count;
                }
                if ((uint64_t)(stop - p) / size < items)
                    goto truncated;
                if (prop->face_index)
                    for (uint64_t k = 0; k < items; k++) {
                        double index = binary_value(p + k * size, prop->type, big);
                        if (!(index >= 0 && index < (double)h->vertices))
                            return scene__fail(err, SCENE_ERR_FORMAT,
                                               "%s: face %llu uses vertex %.0f, but the file declares %llu "
                                               "vertices",
                                               path, (unsigned long long)item, index,
                                               (unsigned long long)h->vertices);
                    }
                p += items * size;
                continue;
            truncated:
                return scene__fail(
                    err, SCENE_ERR_FORMAT,
                    "%s: truncated: the binary body ends (after %zu bytes) inside item %llu of "
                    "the %llu of element '%s' the header declares",
                    path, (size_t)(end - body), (unsigned long long)item, (unsigned long long)e->count,
                    e->name);
            }
    }
    return SCENE_OK; /* bytes after the last item are ignored, as Assimp does */
}

scene_result scene__check_ply_body(const char *path, const char *buf, size_t len, size_t body,
                                   scene_error *err)
{
    ply_header *h = malloc(sizeof *h);
    if (!h)
        return SCENE_OK; /* the check is skipped; Assimp still reads the file */
    scene_result rc = SCENE_OK;
    if (body <= len && parse_header(buf, buf + body, h))
        /* Assimp's ASCII body starts one byte after "end_header" (at the '\n' of a CRLF) */
        rc = h->format == PLY_ASCII
                 ? check_ascii(path, buf,
                               buf + body - (body >= 2 && buf[body - 1] == '\n' && buf[body - 2] == '\r'),
                               buf + len, h, err)
                 : check_binary(path, buf + body, buf + len, h, err);
    free(h);
    return rc;
}
