/* Helpers of the command-line tests (tests/test_cli*.c): one buffer each for what the last command printed
 * on stdout and stderr, one-line error checks, and reading the JSON the commands write. */
#ifndef FXC_FXT_CLI_H
#define FXC_FXT_CLI_H

#include "test_util.h"

#include <jansson.h>

#define BUNNY "/usr/share/glmark2/models/bunny.obj"

extern char out_buf[1 << 16], err_buf[1 << 14];

/* Runs `fxcache <args...>` (printf-style) and returns the exit code; stdout and stderr land in out_buf and
 * err_buf. */
#define run(...) fxt_run_clif(out_buf, sizeof out_buf, err_buf, sizeof err_buf, __VA_ARGS__)
#define tmp_path fxt_tmp_path_copy

/* Writes text to the scratch file `name` and copies its path into dst (cap bytes). */
void write_file(char *dst, size_t cap, const char *name, const char *text);

/* err_buf holds exactly one non-empty line (ending in one newline). */
void assert_one_line_error(void);

void assert_contains(const char *haystack, const char *needle);

/* Runs a command that must fail with exit code rc and one line on stderr containing every needle (NULL
 * terminated). */
void expect_error(int rc, const char *args, ...);

/* The JSON object in text or in the file at path; fails the test when it is not one. */
json_t *parse_json_text(const char *text);
json_t *load_json_file(const char *path);

/* The integer at a dotted path ("rays.ao"); fails when absent or not an integer. */
long long jint(const json_t *root, const char *path);

/* The node at a dotted path; fails when absent. */
const json_t *jget(const json_t *root, const char *path);

#endif
