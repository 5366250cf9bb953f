/* Runs the block pools cannot hold are degraded, never silently: a finest probe cell of 1e-6 m on the embedded
 * scene (4 million times finer than its default 0.25 m) exhausts the probes' world-space pool. `sim` said so
 * blaming --pool-mb only; `serve` said nothing. Both now print one warning line with the count, naming the
 * probe cell and the scene's default, and the summary counts pool_exhausted. */
#include "fxt_serve.h"
#include "test_util.h"

#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static size_t count_lines(const char *text)
{
    size_t n = 0;
    for (; *text; text++)
        n += *text == '\n';
    return n;
}

static void test_sim_tiny_probe_cell(void **state)
{
    (void)state;
    char err[4096];
    assert_int_equal(
        fxt_run_cli("sim --scene default --effects probes --probe-cell 1e-6 --frames 2 --res 160x90 "
                    "--viewers 2 --threads 1 --quiet",
                    NULL, 0, err, sizeof err),
        0);
    assert_int_equal(count_lines(err), 1);
    assert_non_null(strstr(err, "warning"));
    assert_non_null(strstr(err, "finest cell of 1e-06 m"));
    assert_non_null(strstr(err, "default 0.25 m"));
}

static void test_serve_tiny_probe_cell(void **state)
{
    (void)state;
    char summary[1100];
    fxt_tmp_path_copy(summary, sizeof summary, "degraded_summary.json");
    unlink(summary);
    fxt_server sv;
    const char *args[] = {"--effects", "probes", "--probe-cell", "1e-6",  "--threads", "1",
                          "--fps",     "20",     "--summary",    summary, NULL};
    fxt_server_start(&sv, "degraded", args);
    int fd = fxt_ws_connect(sv.port);
    assert_true(fd >= 0);
    proto_msg hello = fxt_hello_msg(160, 90, PROTO_CODEC_RAW);
    assert_true(fxt_ws_send_msg(fd, &hello));
    proto_welcome w;
    assert_true(fxt_read_welcome(fd, &w));
    proto_msg cam = {.type = PROTO_CAMERA};
    cam.u.camera.pose = w.camera;
    assert_true(fxt_ws_send_msg(fd, &cam));
    usleep(3000000); /* a few frames */
    assert_int_equal(fxt_server_stop(&sv), 0);
    close(fd);
    assert_true(fxt_file_contains(sv.err, "finest cell of 1e-06 m"));
    size_t size = 0;
    char *text = fxt_read_file(summary, &size);
    json_error_t error;
    json_t *sum = json_loadb(text, size, 0, &error);
    free(text);
    assert_non_null(sum);
    assert_true(json_integer_value(json_object_get(sum, "pool_exhausted")) > 0);
    json_decref(sum);
}

int main(void)
{
    mkdir(FXC_TEST_TMP, 0755);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sim_tiny_probe_cell),
        cmocka_unit_test(test_serve_tiny_probe_cell),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
