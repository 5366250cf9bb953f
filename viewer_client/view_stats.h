/* What the viewer client measures, and how it reports it: per viewer the frames shown, the latency of each
 * camera to its first frame, the bytes received; the summary in words (stdout) and the JSON of --stats.
 * Pure bookkeeping, no network: tests/test_viewer.c checks the figures against closed forms. */
#ifndef FXC_VIEW_STATS_H
#define FXC_VIEW_STATS_H

#include "proto.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

/* A growing list of latency samples, milliseconds. Grows by doubling (one allocation per doubling, never
 * per frame once grown). */
typedef struct view_latency {
    double *samples_ms;
    size_t count, capacity;
} view_latency;

/* Appends a sample; false when memory ran out (the sample is then not kept). */
bool view_latency_add(view_latency *l, double ms);
void view_latency_free(view_latency *l);

/* The median (the mean of the two middle values when n is even) and the nearest-rank percentile p in (0, 100]
 * (the smallest value with at least p % of the values at or below it) of n values, which must be sorted
 * ascending; 0 when n is 0. */
double view_median(const double *sorted, size_t n);
double view_percentile(const double *sorted, size_t n, double p);

/* Sorts n values ascending. */
void view_sort(double *values, size_t n);

/* One viewer's figures, kept by the client while it runs. */
typedef struct view_viewer_stats {
    uint32_t index;                /* the viewer's number in this run, from 0 */
    char name[PROTO_NAME_MAX + 1]; /* the name the server gave it ("" before a welcome) */
    bool failed;                   /* it ended with an error (error says which) */
    char error[320];               /* one line, "" when none */
    uint64_t frames;               /* frames shown (received, then held for --latency) */
    uint64_t decode_errors;        /* frames shown whose colour or depth payload did not decode */
    uint64_t bytes_received;       /* every message from the server, headers included */
    uint64_t frame_bytes;          /* the frame messages among them that were shown */
    uint64_t cameras_sent;         /* camera messages sent */
    uint64_t cameras_skipped;      /* cameras not sent because a newer one was due (a stalled loop) */
    double seconds;                /* from the welcome to the last frame shown (0 without frames) */
    view_latency latency;          /* per camera, the first frame that showed it or a newer one */
} view_viewer_stats;

/* The figures of one line of the summary: a viewer's, or the total over several (frames, bytes and fps
 * added up; latency over all samples together). */
typedef struct view_figures {
    uint64_t frames, decode_errors, bytes_received, frame_bytes, latency_samples;
    double fps;             /* frames per second: a viewer's own, summed over viewers for a total */
    double latency_median;  /* ms, 0 without samples */
    double latency_p95;     /* ms, 0 without samples */
    double bytes_per_frame; /* frame bytes / frames, 0 without frames */
} view_figures;

/* The figures of viewers[0..n) together (n = 1: one viewer's). Returns false when memory for sorting ran
 * out. */
bool view_figures_of(const view_viewer_stats *viewers, uint32_t n, view_figures *out);

/* Prints the summary in words: one line per viewer, then the total. */
void view_stats_print_summary(FILE *out, const view_viewer_stats *viewers, uint32_t n, const char *url,
                              double seconds);

/* Writes the --stats JSON (see viewer_client/README.md) to path. Returns 0, or -1 with one line in err. */
int view_stats_write_json(const char *path, const view_viewer_stats *viewers, uint32_t n, const char *url,
                          double seconds, char *err, size_t cap);

#endif
