/* What the viewer client measures, and how it reports it: per viewer the frames shown, the latency of each
 * camera to its first frame, the bytes received; the summary in words (stdout) and the JSON of --stats.
 * Pure bookkeeping, no network: tests/test_viewer.c checks the figures against closed forms. */
#ifndef FXC_VIEW_STATS_H
#define FXC_VIEW_STATS_H

#include "proto.h"
#include "rcache.h"

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

/* The display clock's figures (every display frame), and the render cache's with --reproject. Sums are over
 * display frames; the JSON gives their means. */
typedef struct view_display_stats {
    uint64_t frames;           /* display frames made */
    uint64_t skipped;          /* display frames not made because the clock fell behind */
    double fps;                /* the display clock's rate (--display-fps) */
    double empty_fraction_sum; /* pixels showing nothing (no frame yet; the cache's empty pixels) */
    bool reproject;            /* the render cache's figures below are valid */
    double kind_fraction_sum[VIEW_RC_PIXEL_KINDS]; /* pixels by view_rc_pixel_kind, fractions */
    uint64_t points_sum;                           /* the cache's live points after each frame */
    uint32_t points_last;
    uint64_t request_messages; /* sample-request messages sent */
    uint64_t request_pixels;   /* pixels in them */
    uint64_t requests_dropped; /* requested pixels not sent (no sample requests: the server side lacks
                                  them, or --sample-budget 0) */
    uint64_t answers;          /* samples messages inserted */
    uint64_t samples_received; /* samples in them */
    uint64_t frames_inserted;  /* frames inserted into the cache */
    uint64_t insert_errors; /* frames or answers the cache refused (no depth, too large, never asked for) */
    double stage_ms_sum[VIEW_RC_STAGE_COUNT]; /* view_rc_stats.stage_ms */
    double total_ms_sum;                      /* view_rc_stats.total_ms */
    double total_ms_max;
    double rtt_ms; /* the round trip the prediction used last (camera to frame shown) */
} view_display_stats;

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
    view_display_stats display;    /* the display clock's frames */
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
