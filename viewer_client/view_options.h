/* The command line of fxcache-viewer: every option, its default, its range, and the one-line refusal of a bad
 * value ("fxcache-viewer: --viewers 0: ..." naming the option and the value; the program exits 2). The text
 * of --help is here too, beside the parser it describes. */
#ifndef FXC_VIEW_OPTIONS_H
#define FXC_VIEW_OPTIONS_H

#include "proto.h"
#include "view_camera.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

enum {
    VIEW_MAX_VIEWERS = 64,       /* --viewers upper bound */
    VIEW_MAX_LATENCY_MS = 10000, /* --latency upper bound */
    VIEW_MAX_RC_THREADS = 64,    /* --rc-threads upper bound (rcache.h's VIEW_RC_MAX_THREADS) */
};

#define VIEW_DEFAULT_URL "ws://127.0.0.1:7681"

typedef struct view_options {
    /* --connect ws://HOST:PORT[/PATH] */
    char url[300];    /* as given (default VIEW_DEFAULT_URL) */
    char host[256];   /* a name, an IPv4 address, or an IPv6 address without its brackets */
    uint16_t port;    /* 1..65535 */
    char path[256];   /* "/" unless the URL names one */
    uint32_t viewers; /* 1..64 (default 1, or the number of traces) */
    uint32_t frames;  /* frames each viewer shows before it says bye (0 = no limit) */
    const char *traces[VIEW_MAX_VIEWERS]; /* --trace files, in order (point into argv) */
    uint32_t trace_count;
    view_camera_kind camera; /* --camera (default orbit) when there is no trace */
    bool camera_given;
    double fps;             /* cameras per second (0 = the welcome's fps) */
    uint32_t width, height; /* --res (default 640x360, or a version 2 trace's resolution) */
    bool res_given;
    float fov_deg;   /* (0, 180); 0 = the welcome camera's (the trace's with --trace) */
    uint8_t codec;   /* proto_codec (default zstd) */
    uint8_t quality; /* JPEG quality 1..100 (default 85), sent only with jpeg */
    bool quality_given;
    uint8_t depth;                        /* proto_depth (default none) */
    char token[PROTO_TOKEN_MAX + 1];      /* --token, else $FXCACHE_TOKEN, else "" */
    char name_prefix[PROTO_NAME_MAX + 1]; /* "" = the server names the viewers */
    const char *out_dir;                  /* --out (NULL = write no frames) */
    uint32_t latency_ms;                  /* simulated delay each way, 0..10000 */
    const char *stats_path;               /* --stats (NULL = none) */
    double timeout_s;                     /* (0, 86400], default 10 */
    bool quiet;
    /* The display clock and the render cache (--reproject): */
    double display_fps;      /* display frames per second per viewer, (0, 1000] (default 30) */
    const char *display_out; /* --display-out DIR: every display frame as PNG, its camera as a trace */
    bool reproject;          /* the display shows the render cache's frame (else the last frame received) */
    bool depth_given;
    bool no_prediction, no_prefilter, no_eviction, no_tiling; /* view_rc_desc's stage switches */
    uint32_t rc_threads;    /* the render cache's threads, 1..64 (default 1) */
    uint32_t sample_budget; /* pixels requested per display frame (0: the render cache's default, width *
                               height / 32); 0 with --sample-budget 0: no sample requests */
    bool sample_budget_given;
    uint8_t strategy;  /* proto_strategy sent in hello (default basic) */
    double time_scale; /* --time-scale: the session's durations run this many times slower, [1, 1000] (1) */
} view_options;

typedef enum view_parse_result {
    VIEW_PARSE_RUN,  /* options are valid: run */
    VIEW_PARSE_HELP, /* --help: print view_options_help() and exit 0 */
    VIEW_PARSE_ERROR /* err holds one line (without the program name): exit 2 */
} view_parse_result;

/* Parses argv[1..argc) into *o (defaults first). env_token is $FXCACHE_TOKEN (NULL when unset); --token wins.
 * Only checks what can be checked without files or the network (trace files are read later). */
view_parse_result view_options_parse(int argc, char *const argv[], const char *env_token, view_options *o,
                                     char *err, size_t cap);

/* Parses "ws://HOST:PORT" with an optional path into o->host, o->port, o->path. false with one line in err
 * (naming --connect and the value) otherwise. */
bool view_options_parse_url(const char *url, view_options *o, char *err, size_t cap);

/* The text of --help. */
const char *view_options_help(void);

#endif
