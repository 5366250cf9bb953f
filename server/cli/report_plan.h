/* `fxcache report`'s options and plan (cmd_report.c runs it): the options with their usage text and checks,
 * and the sweep's configurations, each the base settings with one change, in the order they run. */
#ifndef FXC_REPORT_PLAN_H
#define FXC_REPORT_PLAN_H

#include "cli_cameras.h"
#include "cli_engine.h"
#include "report_out.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

enum { REPORT_MAX_CONFIGS = 96 };

/* The sweep families, in the order they run (--only picks some): report_plan.c names them. */
enum { REPORT_FAMILIES = 9 };

typedef struct report_options {
    srv_cli_engine engine;     /* the base settings every configuration starts from */
    srv_cli_view_options view; /* --viewers, --frames, --res, --camera, --trace, --fps */
    uint32_t warmup, every;
    bool warmup_set, every_set;
    const char *out_dir;
    bool quick, quiet;
    double ref_samples; /* scale of the reference's default samples (0: 1, or 1/4 with --quick) */
    bool only[REPORT_FAMILIES];
    bool only_set;
    double heatmap_max;
    bool time_cpu; /* plots, front and comparison on process CPU time instead of the elapsed frame time */
} report_options;

/* One configuration: its row and the engine settings it runs with. */
typedef struct report_config {
    srv_rep_row row;
    srv_cli_engine engine;
    char key[1400]; /* everything that decides its results: a marker with another key is redone */
} report_config;

typedef struct report_plan {
    report_config configs[REPORT_MAX_CONFIGS];
    size_t count;
} report_plan;

typedef struct report_context {
    const report_options *o;
    const scene *s;
    int32_t shadow_index, ao_index; /* in the registry, -1 when absent or not running */
    bool probes_on;
    double default_cell;
    char run_key[900]; /* what every configuration shares */
} report_context;

/* Parses report's command line into o. Returns -1 to go on, or the exit code (0 after --help, 2 for a bad
 * option, with its one-line message printed). */
int srv_report_parse_options(int argc, char **argv, report_options *o);

/* Builds the plan: every sweep the options ask for, in family order, each configuration's row and key filled. */
void srv_report_build_plan(report_plan *plan, const report_context *ctx);

#endif
