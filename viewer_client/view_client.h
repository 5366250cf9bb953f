/* The viewer client's session: N simulated viewers on one libwebsockets context, served by one thread.
 *
 * Each viewer connects, says hello, waits for the welcome, then sends cameras (from its trace, or from the
 * generator at --fps) and takes the frames that come back: decodes the colour and depth payloads, writes a
 * PNG with --out, and times each camera to the first frame that shows it. --latency holds cameras before they
 * are sent and frames before they count as shown. One timer per viewer (lws_sul) wakes it for its next
 * camera or held frame; one housekeeping timer a tenth of a second checks timeouts and prints progress.
 * Writes happen only in the writeable callback, with LWS_PRE bytes of headroom (DEPENDENCIES.md).
 *
 * A viewer ends when it has shown --frames frames, when its trace ended (a frame for its last camera
 * showed), when the program is interrupted (SIGINT, SIGTERM), or on a failure of its own (refused, closed,
 * garbage, timed out), which is printed as one line and leaves the other viewers going. */
#ifndef FXC_VIEW_CLIENT_H
#define FXC_VIEW_CLIENT_H

#include "proto_trace.h"
#include "view_options.h"
#include "view_stats.h"

#include <stddef.h>

/* Runs the session until every viewer has ended. traces: o->trace_count parsed traces (viewer i uses trace
 * i, or trace 0 for all when there is one). stats: o->viewers entries, filled (and their latency lists owned
 * by the caller afterwards: view_latency_free each). *seconds: how long the session ran. Returns 0 when the
 * session ran (viewers may have failed: stats say), -1 with one line in err when it could not start at all
 * (no libwebsockets context, out of memory). Installs SIGINT and SIGTERM handlers for its duration. */
int view_client_run(const view_options *o, const proto_trace *traces, view_viewer_stats *stats,
                    double *seconds, char *err, size_t cap);

#endif
