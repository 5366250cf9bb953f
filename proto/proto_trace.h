/* proto_trace: the viewer-trace text format (`fxcache-trace 1` and `2`, docs/TRACE_FORMAT.md) parsed from
 * bytes in memory. The second exchange format beside the wire format (proto.h): the server records and
 * replays traces (server/cameras/trace.c reads the file and calls this), the viewer client replays them, and
 * neither needs the other's code. No I/O and no scene: the cameras come out as written, in world coordinates
 * and double; moving them into a scene's local frame is the caller's business.
 *
 * The text is untrusted: the parser never reads outside [text, text + len) (the text need not end with a NUL
 * and may contain NUL bytes, which it refuses), never asserts on content, and stops at the first problem with
 * one line "FILE:LINE: what is wrong"; nothing partial is returned. */
#ifndef FXC_PROTO_TRACE_H
#define FXC_PROTO_TRACE_H

#include "fxc_result.h"

#include <stddef.h>
#include <stdint.h>

/* The header's magic word and the newest format version this build reads (and the server writes). */
#define PROTO_TRACE_MAGIC   "fxcache-trace"
#define PROTO_TRACE_VERSION 2
/* Largest side a version 2 'resolution' line may name. */
#define PROTO_TRACE_MAX_SIDE 8192
/* The longest line accepted, bytes, not counting its line end. */
#define PROTO_TRACE_MAX_LINE 4096
/* The largest trace file the readers load (server/cameras/trace.c, the viewer client), bytes: 256 MiB, some
 * five million cameras, 46 hours at 30 per second. */
#define PROTO_TRACE_MAX_FILE_BYTES (256u << 20)

/* One camera line as read: world coordinates, in double. */
typedef struct proto_trace_camera {
    double position[3];  /* metres, world coordinates */
    double direction[3]; /* non-zero; position + direction differs from position in double; up is +Y */
    float fov_deg;       /* vertical field of view, degrees, (0, 180) */
} proto_trace_camera;

/* A parsed trace. Owns cameras and times (malloc'd); release with proto_trace_release(). */
typedef struct proto_trace {
    uint32_t version;            /* the header's format version: 1 or 2 */
    uint32_t width, height;      /* the viewer's resolution from a version 2 'resolution' line; 0 when none */
    uint32_t count;              /* camera lines, >= 1 */
    double *times;               /* count times, seconds, finite, non-decreasing */
    proto_trace_camera *cameras; /* count cameras, in line order */
} proto_trace;

/* Parses len bytes of trace text. file_name is only used in messages (NULL reads "(trace)"). On FXC_OK *out
 * holds at least one camera and the caller owns it. Otherwise *out is empty (all zero) and err (cap bytes,
 * may be NULL) holds one line "FILE:LINE: what is wrong" with exactly the wording srv_trace_read() has always
 * given; the result is FXC_ERR_FORMAT for anything wrong with the text, FXC_ERR_NOMEM when memory ran out,
 * FXC_ERR_INVALID when out is NULL or text is NULL with len > 0. */
fxc_result proto_trace_parse(const char *text, size_t len, const char *file_name, proto_trace *out, char *err,
                             size_t cap);

/* Frees what a parse allocated and zeroes *t. NULL and an all-zero trace are allowed. */
void proto_trace_release(proto_trace *t);

/* Prints v with the fewest significant digits (9 to 17) that read back to exactly v: how the trace writer
 * prints times and positions, and how the parser quotes numbers in its messages. buf: cap bytes (32 hold any
 * double). */
void proto_trace_format_number(double v, char *buf, size_t cap);

#endif
