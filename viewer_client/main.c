/* fxcache-viewer: the lightweight client of fxcache (see viewer_client/README.md and --help). Parses the
 * options, reads the traces, runs the session (view_client.c), prints the summary and writes --stats.
 * Exit status: 0 every viewer ended well, 1 a viewer failed, 2 a bad option or trace file. */
#include "proto_trace.h"
#include "view_client.h"
#include "view_options.h"
#include "view_stats.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* Reads a whole trace file (at most PROTO_TRACE_MAX_FILE_BYTES) and parses it. Returns false with one line in
 * err: the file unreadable, too large, or the parser's "FILE:LINE: what is wrong". */
static bool load_trace(const char *path, proto_trace *out, char *err, size_t cap)
{
    FILE *file = fopen(path, "rb");
    if (!file) {
        snprintf(err, cap, "%s: cannot open: %s", path, strerror(errno));
        return false;
    }
    size_t size = 0, capacity = 0;
    char *text = NULL;
    bool ok = true;
    for (;;) {
        if (size == capacity) {
            if (capacity > PROTO_TRACE_MAX_FILE_BYTES) {
                snprintf(err, cap, "%s: larger than %u MiB: too large for a trace file", path,
                         PROTO_TRACE_MAX_FILE_BYTES >> 20);
                ok = false;
                break;
            }
            size_t grown = capacity ? capacity * 2 : 65536;
            if (grown > (size_t)PROTO_TRACE_MAX_FILE_BYTES + 1)
                grown = (size_t)PROTO_TRACE_MAX_FILE_BYTES + 1; /* one byte over tells "too large" */
            char *bigger = realloc(text, grown);
            if (!bigger) {
                snprintf(err, cap, "%s: out of memory", path);
                ok = false;
                break;
            }
            text = bigger;
            capacity = grown;
        }
        size += fread(text + size, 1, capacity - size, file);
        if (size < capacity) { /* a short read: the end of the file, or an error */
            if (ferror(file)) {
                snprintf(err, cap, "%s: read error: %s", path, strerror(errno));
                ok = false;
            }
            break;
        }
    }
    fclose(file);
    if (ok)
        ok = proto_trace_parse(text, size, path, out, err, cap) == FXC_OK;
    free(text);
    return ok;
}

/* Creates a folder and its parents (as mkdir -p). Returns false with errno set. */
static bool make_folder(const char *path)
{
    char partial[4096];
    if (strlen(path) >= sizeof partial) {
        errno = ENAMETOOLONG;
        return false;
    }
    snprintf(partial, sizeof partial, "%s", path);
    for (char *slash = partial + 1; *slash; slash++)
        if (*slash == '/') {
            *slash = 0;
            if (mkdir(partial, 0777) != 0 && errno != EEXIST)
                return false;
            *slash = '/';
        }
    if (mkdir(partial, 0777) != 0 && errno != EEXIST)
        return false;
    struct stat info;
    if (stat(partial, &info) != 0)
        return false;
    if (!S_ISDIR(info.st_mode)) {
        errno = ENOTDIR;
        return false;
    }
    return true;
}

int main(int argc, char **argv)
{
    view_options options;
    char err[1024];
    switch (view_options_parse(argc, argv, getenv("FXCACHE_TOKEN"), &options, err, sizeof err)) {
    case VIEW_PARSE_HELP: fputs(view_options_help(), stdout); return 0;
    case VIEW_PARSE_ERROR: fprintf(stderr, "fxcache-viewer: %s\n", err); return 2;
    case VIEW_PARSE_RUN: break;
    }

    /* Everything an option names is checked before any connection: traces, the output folder, the stats
     * file. */
    proto_trace traces[VIEW_MAX_VIEWERS];
    memset(traces, 0, sizeof traces);
    int status = 0;
    for (uint32_t i = 0; i < options.trace_count && status == 0; i++)
        if (!load_trace(options.traces[i], &traces[i], err, sizeof err)) {
            fprintf(stderr, "fxcache-viewer: --trace: %s\n", err);
            status = 2;
        }
    if (status == 0 && options.out_dir && !make_folder(options.out_dir)) {
        fprintf(stderr, "fxcache-viewer: --out %s: cannot create the folder: %s\n", options.out_dir,
                strerror(errno));
        status = 2;
    }
    if (status == 0 && options.display_out && !make_folder(options.display_out)) {
        fprintf(stderr, "fxcache-viewer: --display-out %s: cannot create the folder: %s\n",
                options.display_out, strerror(errno));
        status = 2;
    }
    if (status == 0 && options.stats_path) {
        FILE *probe = fopen(options.stats_path, "ab");
        if (!probe) {
            fprintf(stderr, "fxcache-viewer: --stats %s: cannot write: %s\n", options.stats_path,
                    strerror(errno));
            status = 2;
        } else {
            fclose(probe);
        }
    }

    view_viewer_stats *stats = status == 0 ? calloc(options.viewers, sizeof *stats) : NULL;
    if (status == 0 && !stats) {
        fprintf(stderr, "fxcache-viewer: out of memory\n");
        status = 1;
    }
    double seconds = 0;
    if (status == 0 && view_client_run(&options, traces, stats, &seconds, err, sizeof err) != 0) {
        fprintf(stderr, "fxcache-viewer: %s\n", err);
        status = 1;
    }
    if (status == 0) {
        for (uint32_t i = 0; i < options.viewers; i++)
            if (stats[i].failed)
                status = 1;
        if (!options.quiet)
            view_stats_print_summary(stdout, stats, options.viewers, options.url, seconds);
        if (options.stats_path && view_stats_write_json(options.stats_path, stats, options.viewers,
                                                        options.url, seconds, err, sizeof err) != 0) {
            fprintf(stderr, "fxcache-viewer: --stats %s\n", err);
            status = 1;
        }
    }
    if (stats)
        for (uint32_t i = 0; i < options.viewers; i++)
            view_latency_free(&stats[i].latency);
    free(stats);
    for (uint32_t i = 0; i < options.trace_count; i++)
        proto_trace_release(&traces[i]);
    return status;
}
