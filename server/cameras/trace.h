/* Viewer traces: recorded viewer cameras as a versioned text file, one camera per line.
 *
 * Stage 1 of the frame ("cameras") takes every viewer's camera from a live connection, a generator
 * (camgen.h) or a trace. The server records live viewers with srv_trace_writer_*; `fxcache sim` replays
 * them with srv_trace_read() and srv_trace_camera(). The format is specified in docs/TRACE_FORMAT.md:
 *
 *     fxcache-trace 2
 *     # optional comment lines
 *     resolution W H            (version 2, optional, before the first camera)
 *     time px py pz dx dy dz fov_deg
 *
 * time in seconds (finite, non-decreasing), position in world coordinates (metres), view direction
 * (non-zero, need not be unit), vertical field of view in degrees, in (0, 180). Up is always +Y. A camera's
 * target is position + direction. Traces hold world coordinates; the frame loop works in the scene's local
 * frame (scene.h), so srv_trace_camera() converts on replay and the writer converts back.
 *
 * A trace file is untrusted input: the reader never asserts and never crashes on junk; every refusal is
 * one line "FILE:LINE: what is wrong". */
#ifndef FXC_SERVER_TRACE_H
#define FXC_SERVER_TRACE_H

#include "camera.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* The header's magic word and the newest format version this build reads and writes. */
#define SRV_TRACE_MAGIC   "fxcache-trace"
#define SRV_TRACE_VERSION 2
/* Largest resolution side a version 2 trace may name. */
#define SRV_TRACE_MAX_SIDE 8192
/* Replays compare frame times with trace times with this slack, seconds (times read back exactly anyway). */
#define SRV_TRACE_TIME_EPSILON 1e-9
/* The longest line the reader accepts, bytes, not counting the line end. */
#define SRV_TRACE_MAX_LINE 4096

typedef struct srv_trace srv_trace;               /* opaque: the cameras of one trace file */
typedef struct srv_trace_writer srv_trace_writer; /* opaque: a trace file being written */

/* Reads and validates a whole trace file. Returns NULL on failure with one line in err (cap bytes,
 * err may be NULL), naming the file, the line number and what is wrong; nothing partial is returned.
 * A trace holds at least one camera. The caller owns the result and frees it with srv_trace_free(). */
srv_trace *srv_trace_read(const char *path, char *err, size_t cap);

/* The number of cameras (camera lines) in a trace: at least 1. */
uint32_t srv_trace_count(const srv_trace *t);

/* The camera of frame `frame` in the local frame of scene s: frame i is the trace's i-th camera line (from
 * 0); past the end, the last camera holds. The position goes through scene_world_to_local() (in double);
 * the target is the rounded position + direction (a direction too short to move a float at that position is
 * stretched to the position's magnitude, same direction). up is (0, 1, 0). t must not be NULL; s NULL means
 * world coordinates as they are (a scene whose origin is 0). */
srv_camera srv_trace_camera(const srv_trace *t, const scene *s, uint32_t frame);

/* A camera given in world coordinates (a position, a direction, a field of view; up +Y), in the local frame
 * of scene s exactly as a trace line with these values replays: a live viewer's camera built this way and
 * recorded reads back as the same camera. s NULL: world coordinates as they are. */
srv_camera srv_trace_camera_world(const scene *s, const double position[3], const double direction[3],
                                  float fov_deg);

/* The time (seconds) of frame `frame`, with the same past-the-end rule as srv_trace_camera(). */
double srv_trace_time(const srv_trace *t, uint32_t frame);

/* The viewer's resolution recorded in a version 2 trace: true and the sides, or false when the file gives
 * none (version 1). */
bool srv_trace_resolution(const srv_trace *t, uint32_t *width, uint32_t *height);

/* The times of the first and the last camera (a replay's join and leave times). */
double srv_trace_first_time(const srv_trace *t);
double srv_trace_last_time(const srv_trace *t);

/* The camera at `time` seconds in the local frame of scene s (as srv_trace_camera): the last camera line
 * whose time is not after it (the first before the trace starts). */
srv_camera srv_trace_camera_at(const srv_trace *t, const scene *s, double time);

/* Releases a trace. NULL is allowed. */
void srv_trace_free(srv_trace *t);

/* Creates (truncates) a trace file at path and writes the header. Cameras added are in the local frame of
 * scene s and are written in world coordinates (the writer copies s->origin; s NULL: written as given).
 * Returns NULL with one line in err on failure. The caller owns the writer and must srv_trace_writer_close()
 * it. */
srv_trace_writer *srv_trace_writer_open(const char *path, const scene *s, char *err, size_t cap);

/* The same, recording the viewer's resolution: writes format version 2 with a 'resolution W H' line when
 * both sides are in 1..SRV_TRACE_MAX_SIDE (else version 1, as srv_trace_writer_open). */
srv_trace_writer *srv_trace_writer_open_sized(const char *path, const scene *s, uint32_t width,
                                              uint32_t height, char *err, size_t cap);

/* Appends one camera at `time` seconds: position = local position + origin in double, direction = target -
 * position, the time and position printed with as many digits as they need to read back exactly (at least
 * 9), the rest with %.9g, and the line is flushed at once so that a crash loses nothing already added.
 * Returns 0 on success; -1 when the camera or time is invalid (not finite, position equal to target,
 * fov_deg outside (0, 180), time before the previous one), and nothing is written; -2 on an I/O error.
 * srv_trace_writer_error() then says what went wrong. cam->up is not recorded (the format's up is +Y). */
int srv_trace_writer_add(srv_trace_writer *w, double time, const srv_camera *cam);

/* The last error of a writer as one line ("" when none). */
const char *srv_trace_writer_error(const srv_trace_writer *w);

/* The number of cameras written so far. */
uint32_t srv_trace_writer_count(const srv_trace_writer *w);

/* Flushes and closes the file and frees the writer. Returns 0, or -2 when an earlier write or the close
 * failed. NULL is allowed (returns 0). */
int srv_trace_writer_close(srv_trace_writer *w);

#endif
