/* The command-line tests' helpers (fxt_cli.h). */
#include "fxt_cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

char out_buf[1 << 16], err_buf[1 << 14];

void write_file(char *dst, size_t cap, const char *name, const char *text)
{
    int n = snprintf(dst, cap, "%s", fxt_write_file(name, text));
    assert_true(n > 0 && (size_t)n < cap);
}

/* err_buf holds exactly one non-empty line (ending in one newline). */
void assert_one_line_error(void)
{
    size_t len = strlen(err_buf);
    if (len == 0 || err_buf[len - 1] != '\n' || memchr(err_buf, '\n', len - 1) != NULL) {
        print_error("stderr is not exactly one line: '%s'\n", err_buf);
        fail();
    }
    assert_true(len > 1);
}

void assert_contains(const char *haystack, const char *needle)
{
    if (!strstr(haystack, needle)) {
        print_error("expected '%s' in: '%s'\n", needle, haystack);
        fail();
    }
}

/* Runs a command that must fail with exit code rc and one line on stderr containing every needle (NULL
 * terminated). */
void expect_error(int rc, const char *args, ...)
{
    int got = fxt_run_cli(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf);
    if (got != rc) {
        print_error("fxcache %s: exit %d, expected %d; stderr: %s\n", args, got, rc, err_buf);
        fail();
    }
    assert_one_line_error();
    va_list ap;
    va_start(ap, args);
    for (const char *needle = va_arg(ap, const char *); needle; needle = va_arg(ap, const char *))
        assert_contains(err_buf, needle);
    va_end(ap);
}

json_t *parse_json_text(const char *text)
{
    json_error_t error;
    json_t *root = json_loads(text, 0, &error);
    if (!root) {
        print_error("invalid JSON (%d:%d: %s): %.400s\n", error.line, error.column, error.text, text);
        fail();
    }
    assert_true(json_is_object(root));
    return root;
}

json_t *load_json_file(const char *path)
{
    json_error_t error;
    json_t *root = json_load_file(path, 0, &error);
    if (!root) {
        print_error("%s: invalid JSON (%d:%d: %s)\n", path, error.line, error.column, error.text);
        fail();
    }
    assert_true(json_is_object(root));
    return root;
}

/* The node at a dotted path ("rays.ao"); fails when absent. */
const json_t *jget(const json_t *root, const char *path)
{
    char buf[256];
    snprintf(buf, sizeof buf, "%s", path);
    const json_t *node = root;
    for (char *save = NULL, *key = strtok_r(buf, ".", &save); key; key = strtok_r(NULL, ".", &save)) {
        node = json_object_get(node, key);
        if (!node) {
            print_error("missing field '%s'\n", path);
            fail();
        }
    }
    return node;
}

/* The integer at a dotted path; fails when absent or not an integer. */
long long jint(const json_t *root, const char *path)
{
    const json_t *node = jget(root, path);
    if (!json_is_integer(node)) {
        print_error("field '%s' is not an integer\n", path);
        fail();
    }
    return json_integer_value(node);
}
