/* The fxcache command line against what it promises about its outputs and options: --help states the ranges
 * the options enforce, and frames that cannot be written end a run with one line (also the frame an
 * interrupted run saves at its end). Runs the fxcache program of this build through fxt_run_cli(), as
 * test_cli.c does (which had grown past 1,000 lines). */
#include "fxt_cli.h"

#include <fcntl.h>
#include <signal.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

/* --help states each option's range as the option's refusal does: the value just outside is refused naming
 * that range, and the help has the same range. --fps said (0, 1000] where 0.0005 is refused ([0.001, 1000]);
 * --save-every, --threads, --ray-budget, ref's --every and report's --heatmap-max gave none. */
static void test_help_ranges_match_refusals(void **state)
{
    (void)state;
    static const struct {
        const char *command, *option, *outside, *refusal, *help;
    } cases[] = {
        {"sim", "--fps", "0.0005", "in [0.001, 1000]", "[0.001, 1000]"},
        {"serve", "--fps", "0.0005", "in [0.001, 1000]", "[0.001, 1000]"},
        {"ref --out x", "--fps", "0.0005", "in [0.001, 1000]", "[0.001, 1000]"},
        {"report --out x", "--fps", "0.0005", "in [0.001, 1000]", "[0.001, 1000]"},
        {"sim", "--save-every", "1000001", "in [0, 1000000]", "0..1000000"},
        {"ref --out x", "--every", "1000001", "in [0, 1000000]", "0..1000000"},
        {"sim", "--threads", "257", "in [0, 256]", "0..256"},
        {"serve", "--threads", "257", "in [0, 256]", "0..256"},
        {"ref --out x", "--threads", "257", "in [0, 256]", "0..256"},
        {"sim", "--ray-budget", "2e12", "in [0, 1e+12]", "0..1e12"},
        {"report --out x", "--heatmap-max", "2e6", "in [1e-06, 1e+06]", "[1e-6, 1e6]"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int rc = run("%s %s %s", cases[i].command, cases[i].option, cases[i].outside);
        if (rc != 2 || !strstr(err_buf, cases[i].refusal))
            fail_msg("%s %s %s: exit %d, '%s'", cases[i].command, cases[i].option, cases[i].outside, rc,
                     err_buf);
        char command[64];
        snprintf(command, sizeof command, "%s", cases[i].command);
        command[strcspn(command, " ")] = 0;
        assert_int_equal(run("%s --help", command), 0);
        /* the option's entry: from its name to the next option's */
        char key[64];
        snprintf(key, sizeof key, "  %s ", cases[i].option);
        const char *entry = strstr(out_buf, key);
        assert_non_null(entry);
        const char *next = strstr(entry + 3, "\n  --");
        size_t len = next ? (size_t)(next - entry) : strlen(entry);
        char text[1024];
        snprintf(text, sizeof text, "%.*s", (int)(len < sizeof text ? len : sizeof text - 1), entry);
        if (!strstr(text, cases[i].help))
            fail_msg("%s --help: %s lacks '%s': %s", command, cases[i].option, cases[i].help, text);
    }
}

/* Frames sim cannot write (file names linked to /dev/full, where every write fails with ENOSPC): one line
 * naming the file and exit 1, also when the frame is the one an interrupted run saves at its end. Both
 * viewers' failures were printed (two lines), and the interrupted run's was ignored (exit 0). */
static void test_sim_frames_unwritable(void **state)
{
    (void)state;
    if (access("/dev/full", W_OK) != 0) {
        print_message("SKIP: /dev/full is absent\n");
        skip();
    }
    char out[1024], link[1200], summary[1024], stats[1024];
    tmp_path(out, sizeof out, "full_out");
    tmp_path(summary, sizeof summary, "full_summary.json");
    tmp_path(stats, sizeof stats, "full_stats.jsonl");
    mkdir(out, 0755);
    for (int frame = 0; frame < 600; frame++)
        for (int v = 0; v < 2; v++) {
            snprintf(link, sizeof link, "%s/frame_%04d_viewer_%02d.png", out, frame, v);
            remove(link);
            assert_int_equal(symlink("/dev/full", link), 0);
        }
    /* A summary that cannot be written: one line, exit 1, and no partial file left (an empty one was). */
    char full_summary[1024];
    tmp_path(full_summary, sizeof full_summary, "full_summary_link.json");
    remove(full_summary);
    assert_int_equal(symlink("/dev/full", full_summary), 0);
    int rc = run("sim --frames 1 --viewers 1 --res 16x9 --threads 1 --quiet --summary %s", full_summary);
    assert_int_equal(rc, 1);
    assert_one_line_error();
    assert_contains(err_buf, "full_summary_link.json: No space left on device");
    struct stat st;
    assert_int_equal(lstat(full_summary, &st), -1);

    rc = run("sim --frames 1 --viewers 2 --res 16x9 --threads 1 --quiet --out %s", out);
    assert_int_equal(rc, 1);
    assert_one_line_error();
    assert_contains(err_buf, "frame_0000_viewer_00.png: cannot write: No space left on device");

    /* Interrupted: frame 0 is written normally (saved every 600th frame, and frame 0 is a plain file now);
     * the last frame, saved after the signal, is not. */
    snprintf(link, sizeof link, "%s/frame_0000_viewer_00.png", out);
    remove(link);
    snprintf(link, sizeof link, "%s/frame_0000_viewer_01.png", out);
    remove(link);
    remove(stats);
    remove(summary);
    char err_path[1024];
    tmp_path(err_path, sizeof err_path, "full_stderr.txt");
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        int devnull = open("/dev/null", O_WRONLY),
            err_fd = open(err_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        dup2(devnull, STDOUT_FILENO);
        dup2(err_fd, STDERR_FILENO);
        execl(FXC_BIN, FXC_BIN, "sim", "--frames", "100000", "--res", "16x9", "--viewers", "2", "--stats",
              stats, "--summary", summary, "--out", out, "--save-every", "600", "--threads", "1", "--quiet",
              (char *)NULL);
        _exit(127);
    }
    fxt_wait_for_lines(stats, 2, 60.0); /* two frames on record */
    assert_int_equal(kill(pid, SIGINT), 0);
    int status = 0;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFEXITED(status));
    json_t *sum = load_json_file(summary);
    assert_true(json_is_true(json_object_get(sum, "interrupted")));
    json_int_t frames = json_integer_value(json_object_get(sum, "frames"));
    json_decref(sum);
    FILE *f = fopen(err_path, "r");
    assert_non_null(f);
    size_t n = fread(err_buf, 1, sizeof err_buf - 1, f);
    err_buf[n] = 0;
    fclose(f);
    print_message("interrupted after %d frames: exit %d, '%s'\n", (int)frames, WEXITSTATUS(status), err_buf);
    if (frames >= 2 && frames <= 600) { /* its last frame is one of the links */
        assert_int_equal(WEXITSTATUS(status), 1);
        assert_one_line_error();
        assert_contains(err_buf, "No space left on device");
    }
}

/* Ctrl-C twice during a long frame (2048 x 2048 on one thread: seconds): the first asks for the end (the
 * frame is abandoned within a tile since robust-six: the run may be over, exit 0, before the second comes),
 * the second ends the run at once, by the signal. Before, sim caught every signal alike and a user could not
 * stop a frame that takes minutes short of SIGKILL. */
static void test_sim_second_signal_ends_at_once(void **state)
{
    (void)state;
    const char *argv[] = {FXC_BIN, "sim",       "--frames",  "3", "--viewers", "1",
                          "--res", "2048x2048", "--threads", "1", "--quiet",   NULL};
    pid_t pid = fxt_spawn_quiet(argv, SIGINT, NULL);
    struct timespec tenth = {0, 100 * 1000 * 1000};
    for (int tries = 0; tries < 300 && !fxt_catches_signal(pid, SIGINT); tries++)
        nanosleep(&tenth, NULL);
    assert_true(fxt_catches_signal(pid, SIGINT));
    for (int k = 0; k < 10; k++) /* a second into the load and the first frame */
        nanosleep(&tenth, NULL);
    assert_int_equal(kill(pid, SIGINT), 0);
    for (int tries = 0; tries < 50 && fxt_catches_signal(pid, SIGINT); tries++)
        nanosleep(&tenth, NULL); /* the handler has given SIGINT back to its default action */
    assert_int_equal(kill(pid, SIGINT), 0);
    int status = 0;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    if (WIFEXITED(status) && WEXITSTATUS(status) == 0)
        return; /* the first signal ended the run (its frame abandoned) before the second arrived */
    if (!WIFSIGNALED(status) || WTERMSIG(status) != SIGINT)
        fail_msg("after two SIGINTs: %s %d", WIFSIGNALED(status) ? "signal" : "exit",
                 WIFSIGNALED(status) ? WTERMSIG(status) : WEXITSTATUS(status));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_help_ranges_match_refusals),
        cmocka_unit_test(test_sim_frames_unwritable),
        cmocka_unit_test(test_sim_second_signal_ends_at_once),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
