/* What the checks on mesh files before Assimp reads them share (scene_import_check.c, and the MD5 check in
 * scene_import_md5.c): Assimp's reading of whole numbers, line numbers for messages, and the refusal of a
 * declared count larger than the file could hold. Private to the scene module. */
#ifndef FXC_SCENE_IMPORT_CHECK_H
#define FXC_SCENE_IMPORT_CHECK_H

#include "scene_internal.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* A whole number as Assimp's strtoul10() reads it: the leading decimal digits, wrapping modulo 2^32 as its
 * unsigned int does. *digits_out (may be NULL) is the same number without wrapping, saturated at UINT64_MAX,
 * so a count that wrapped to something small is still seen for what the file declares. */
static inline uint32_t assimp_strtoul10(const char *p, const char *end, uint64_t *digits_out)
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

/* The number of the line pos is on (1-based). */
static inline unsigned line_of(const char *buf, const char *pos)
{
    unsigned line = 1;
    for (const char *q = buf; q < pos; q++)
        line += *q == '\n';
    return line;
}

static inline bool is_blank(char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\n';
}

/* Refuses a declared count larger than the file could hold: every item of a declared element, vertex or
 * face takes at least one byte of the file, so a count above the file's size is a lie that would only make
 * Assimp allocate for it (its OFF reader allocates from the header alone: Assimp's own test file
 * invalid/OutOfMemory.off, 309 bytes, declares 353535235358 vertices and grew past 8 GB). */
static inline scene_result check_count(const char *path, unsigned line, const char *what, uint64_t count,
                                       size_t len, scene_error *err)
{
    if (count <= len)
        return SCENE_OK;
    return scene__fail(err, SCENE_ERR_FORMAT,
                       "%s:%u: declares %llu %s, more than the file's %zu bytes can hold", path, line,
                       (unsigned long long)count, what, len);
}

/* check_count() for a count at `at` in buf: the line number is counted only when the check fails. */
static inline scene_result check_count_at(const char *path, const char *buf, const char *at, const char *what,
                                          uint64_t count, size_t len, scene_error *err)
{
    return count <= len ? SCENE_OK : check_count(path, line_of(buf, at), what, count, len, err);
}

/* The check of a PLY body against its header (scene_import_ply.c): body is the offset of the byte after the
 * end_header line. */
scene_result scene__check_ply_body(const char *path, const char *buf, size_t len, size_t body,
                                   scene_error *err);

/* The MD5 mesh check (scene_import_md5.c). */
scene_result scene__check_md5(const char *path, const char *buf, size_t len, scene_error *err);

#endif
