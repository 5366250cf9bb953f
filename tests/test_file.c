/* Checked whole-file writes (common/fxc_file.h): what a failed write leaves behind.
 *   - fxc_remove_partial removes a regular file and a link (not what the link points to), and leaves a pipe
 *     and a folder alone;
 *   - a write straight to /dev/full (not through a link) fails with ENOSPC naming the path, and /dev/full is
 *     still a character device afterwards; so after `fxcache sim --summary /dev/full`. Run as root, both used
 *     to remove the device node (the next write then made /dev/full a regular file, and every later full-disk
 *     test on the machine passed its writes). */
#include "test_util.h"

#include "fxc_file.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static bool is_device(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISCHR(st.st_mode);
}

static void test_remove_partial_kinds(void **state)
{
    (void)state;
    char file[1024], link[1024], target[1024], fifo[1024], dir[1024];
    snprintf(file, sizeof file, "%s", fxt_tmp_path("partial_file"));
    snprintf(link, sizeof link, "%s", fxt_tmp_path("partial_link"));
    snprintf(target, sizeof target, "%s", fxt_tmp_path("partial_target"));
    snprintf(fifo, sizeof fifo, "%s", fxt_tmp_path("partial_fifo"));
    snprintf(dir, sizeof dir, "%s", fxt_tmp_path("partial_dir"));
    remove(file), remove(link), remove(target), remove(fifo), rmdir(dir);
    FILE *f = fopen(file, "w");
    assert_non_null(f);
    fclose(f);
    f = fopen(target, "w");
    assert_non_null(f);
    fclose(f);
    assert_int_equal(symlink(target, link), 0);
    assert_int_equal(mkfifo(fifo, 0600), 0);
    assert_int_equal(mkdir(dir, 0755), 0);
    fxc_remove_partial(file);
    fxc_remove_partial(link);
    fxc_remove_partial(fifo);
    fxc_remove_partial(dir);
    struct stat st;
    assert_int_equal(lstat(file, &st), -1);
    assert_int_equal(lstat(link, &st), -1);
    assert_int_equal(lstat(target, &st), 0);
    assert_int_equal(lstat(fifo, &st), 0);
    assert_true(S_ISFIFO(st.st_mode));
    assert_int_equal(lstat(dir, &st), 0);
    assert_true(S_ISDIR(st.st_mode));
    remove(target), remove(fifo), rmdir(dir);
}

static void test_dev_full_survives(void **state)
{
    (void)state;
    if (!is_device("/dev/full") || access("/dev/full", W_OK) != 0) {
        print_message("SKIP: /dev/full is absent or not a device\n");
        skip();
    }
    char msg[256];
    static const char bytes[8192];
    assert_false(fxc_write_whole_file("/dev/full", bytes, sizeof bytes, msg, sizeof msg));
    assert_non_null(strstr(msg, "/dev/full: cannot write: No space left on device"));
    assert_true(is_device("/dev/full"));
    char cmd[2048];
    snprintf(cmd, sizeof cmd,
             "%s sim --frames 1 --viewers 1 --res 16x9 --threads 1 --quiet --summary /dev/full 2>/dev/null",
             FXC_BIN);
    int rc = system(cmd);
    assert_true(WIFEXITED(rc) && WEXITSTATUS(rc) == 1);
    assert_true(is_device("/dev/full"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_remove_partial_kinds),
        cmocka_unit_test(test_dev_full_survives),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
