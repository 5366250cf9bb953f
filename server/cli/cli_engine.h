/* What `fxcache sim` and `fxcache serve` share (cli_engine.c): the engine's options, opening a run, the
 * per-frame statistics file, and the summary. */
#ifndef FXC_SERVER_CLI_ENGINE_H
#define FXC_SERVER_CLI_ENGINE_H

#include "cli_cameras.h"
#include "engine.h"
#include "report.h"

#include <getopt.h>
#include <jansson.h>
#include <signal.h>
#include <stdbool.h>
#include <stdio.h>

/* The options that shape the engine; zero fields take the loop's defaults. */
typedef struct srv_cli_engine {
    const char *scene_path; /* NULL: the embedded default scene */
    const char *effects;    /* NULL or "auto": what the scene needs */
    int32_t bias[SRV_MAX_EFFECTS];
    bool bias_set[SRV_MAX_EFFECTS];
    double pool_mb, ray_budget, density, probe_cell, probe_hysteresis;
    uint32_t seed, threads, ao_step, probe_rays, probe_budget;
    uint32_t indirect_block;          /* srv_loop_desc.indirect_block: 1, 2 or 4 (0: the loop's default, 4) */
    uint32_t ao_samples, shadow_rays; /* converged sample counts (0: the loop's defaults, 64 and 16) */
    double no_cache_samples;          /* --no-cache: the baseline's counts as a multiple of those (0: 1) */
    bool no_cache, no_local_table;
    bool probe_plain_blend; /* --probe-blend plain: srv_loop_desc.probe_plain_blend */
} srv_cli_engine;

/* getopt_long codes of the engine options (a command's own codes start at SRV_CLI_O_COMMAND). */
enum {
    SRV_CLI_O_SCENE = 256,
    SRV_CLI_O_EFFECTS,
    SRV_CLI_O_BIAS,
    SRV_CLI_O_POOL,
    SRV_CLI_O_BUDGET,
    SRV_CLI_O_AOSTEP,
    SRV_CLI_O_PCELL,
    SRV_CLI_O_PRAYS,
    SRV_CLI_O_PHYST,
    SRV_CLI_O_PBUDGET,
    SRV_CLI_O_NOLOCAL,
    SRV_CLI_O_NOCACHE,
    SRV_CLI_O_SEED,
    SRV_CLI_O_THREADS,
    SRV_CLI_O_DENSITY,
    SRV_CLI_O_AOSAMPLES,
    SRV_CLI_O_SHADOWRAYS,
    SRV_CLI_O_NCSAMPLES,
    SRV_CLI_O_IBLOCK,
    SRV_CLI_O_PBLEND,
    SRV_CLI_O_COMMAND = 320
};

/* The engine options' getopt_long entries (no terminator) and their --help lines (one %s: the effect names). */
extern const struct option srv_cli_engine_options[];
extern const size_t srv_cli_engine_option_count;
extern const char srv_cli_engine_usage[];

void srv_cli_engine_defaults(srv_cli_engine *e);

/* A command's own getopt_long entries (n_own, no terminator) followed by the engine's and a terminator, in
 * out (cap entries, enough for all); the loop's state (optind, opterr) reset for a new parse. */
void srv_cli_merge_options(const struct option *own, size_t n_own, struct option *out, size_t cap);

/* The effects a user can choose (those that shade), comma-separated. */
void srv_cli_effect_names(char *out, size_t cap);

/* Handles one getopt_long result: 1 when it was an engine option and valid, 0 when it was one and invalid
 * (a one-line error "fxcache CMD: OPTION: ..." was printed), -1 when it is not an engine option. */
int srv_cli_engine_option(const char *cmd, int code, const char *arg, srv_cli_engine *e);

/* The same for the commands that take both the engine's and the camera options (sim, ref, report): 1 when
 * code was one of them and valid, 0 when it was one and invalid (its one-line error printed), -1 otherwise. */
int srv_cli_run_option(const char *cmd, int code, const char *arg, srv_cli_engine *e,
                       srv_cli_view_options *v);

/* Decides which effects run on scene s: the registry's needs, narrowed by --effects `list` (NULL or "auto":
 * all that are needed); effect_on by registry index, a reason for each (why it runs or is left out), and in
 * left_out_extra (a JSON object) the needs of the scene no registered effect serves. False (and an error line)
 * for an unknown effect. `sim`, `serve` and `ref` decide the same way, so a reference has the terms the
 * cached frames it is compared with have. */
bool srv_cli_choose_effects(const char *cmd, const scene *s, const char *list,
                            bool effect_on[SRV_MAX_EFFECTS], char reasons[SRV_MAX_EFFECTS][200],
                            json_t *left_out_extra);

/* A run: the scene, its Embree scene, the loop with the chosen effects, the report (its sink registered). */
typedef struct srv_cli_run {
    const char *cmd;
    scene *s;
    scene_rt *rt;
    srv_loop *loop;
    srv_report *report;
    srv_sink report_sink;
    char reasons[SRV_MAX_EFFECTS][200]; /* why each effect runs or is left out */
    json_t *left_out_extra;             /* what the scene needs that no registered effect serves */
    double bvh_ms;
} srv_cli_run;

/* Checks the engine options against each other (--no-cache-samples needs --no-cache): true, or false with a
 * one-line error. srv_cli_run_open calls it first. */
bool srv_cli_engine_check(const char *cmd, const srv_cli_engine *e);

/* The frame loop's description from the engine options (effects left off: the caller chooses them). */
srv_loop_desc srv_cli_loop_desc(const srv_cli_engine *e, const scene *s, scene_rt *rt, bool keep_views);

/* Opens a run. Returns -1 on success, else the exit code (an error line was printed; srv_cli_run_close
 * still frees what was made). A signal flagged in *stop during the scene load ends it (128 + signal). */
int srv_cli_run_open(const char *cmd, const srv_cli_engine *e, bool keep_views, srv_cli_run *run,
                     volatile sig_atomic_t *stop);
void srv_cli_run_close(srv_cli_run *run);

/* --stats FILE: one JSON line per frame, flushed at once (a crash loses no finished frame). */
typedef struct srv_cli_stats {
    FILE *file;
    srv_cli_run *run;
    const char *path;
} srv_cli_stats;

bool srv_cli_stats_open(srv_cli_stats *stats, srv_cli_run *run, const char *path);
bool srv_cli_stats_close(srv_cli_stats *stats); /* false (and an error line) when the close failed */

/* The summary's common part: scene, options, effects and why, the report's totals. Caller owns it. */
json_t *srv_cli_summary_json(const srv_cli_run *run, const srv_cli_engine *e);
/* Writes JSON to path (indented); false with an error line on failure, and no partial file left. */
bool srv_cli_write_json(const char *cmd, const char *path, const json_t *value);
/* The summary in words on stdout. */
void srv_cli_print_summary(const srv_cli_run *run, bool no_cache, bool interrupted);

/* After a run whose block pools were too small for a frame's requests (the report's exhausted count): one
 * warning line on stderr with the count, the pixels composed without cached data, --pool-mb and, when the
 * probes' world-space pool was among them, the finest probe cell against the scene's default (a tiny
 * --probe-cell multiplies the cells near every viewer). Nothing when no request was refused. */
void srv_cli_warn_exhausted(const srv_cli_run *run, const srv_cli_engine *e);

#endif
