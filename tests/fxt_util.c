/* Shared test helpers (named fxt_util.c so the test_*.c glob does not take it for a test): see test_util.h. */
#include "test_util.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

const char *fxt_shared_scene(const char *rel)
{
    static char path[1024];
    snprintf(path, sizeof path, "%s/../shared/scenes/%s", FXC_SOURCE_DIR, rel);
    if (access(path, R_OK) != 0) {
        printf("SKIP: %s is absent (the shared scenes are not beside this clone)\n", path);
        return NULL;
    }
    return path;
}

const char *fxt_tmp_path(const char *name)
{
    static char path[1024];
    mkdir(FXC_TEST_TMP, 0755);
    snprintf(path, sizeof path, "%s/%s", FXC_TEST_TMP, name);
    return path;
}

const char *fxt_write_file(const char *name, const char *text)
{
    const char *path = fxt_tmp_path(name);
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    fputs(text, f);
    fclose(f);
    return path;
}

static void slurp(const char *path, char *buf, size_t cap)
{
    if (!buf || cap == 0)
        return;
    buf[0] = 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        return;
    size_t n = fread(buf, 1, cap - 1, f);
    buf[n] = 0;
    fclose(f);
}

int fxt_run_cli(const char *args, char *out, size_t out_cap, char *err, size_t err_cap)
{
    char out_path[1100], err_path[1100], cmd[4096];
    snprintf(out_path, sizeof out_path, "%s", fxt_tmp_path("cli_stdout.txt"));
    snprintf(err_path, sizeof err_path, "%s", fxt_tmp_path("cli_stderr.txt"));
    snprintf(cmd, sizeof cmd, "'%s' %s >'%s' 2>'%s' </dev/null", FXC_BIN, args, out_path, err_path);
    int status = system(cmd);
    slurp(out_path, out, out_cap);
    slurp(err_path, err, err_cap);
    if (status == -1 || !WIFEXITED(status))
        return -1;
    return WEXITSTATUS(status);
}
