/* The pinhole basis is one computation for the server and the client's render cache (common/fxc_camera.h):
 * the client projects the points the server's rays produced back to their pixels, so the two must build the
 * same forward, right and up from the same pose, bit for bit, for every pose the server accepts. Checked:
 *   - random directions, and directions within 1e-9 to 1e-3 rad of straight up and straight down at many
 *     azimuths (a top-down camera: before the shared header the client crossed with +Y in float and the
 *     server switched to another perpendicular within 1e-6 rad, so a client turned the image by up to 90
 *     degrees there), and directions of length 1e-30 to 1e12 (the server refuses targets beyond SCENE_MAX_CAMERA_REACH): srv_camera_setup (position 0, target the
 *     direction) against view_rc__view_setup, identical floats;
 *   - the basis is orthonormal within 1e-6 for all of them (a second check that needs no second copy). */
#include "test_util.h"

#include "camera.h"
#include "rc_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static uint64_t rng_state = 0x9e3779b97f4a7c15ull;

static double uniform(void)
{
    rng_state ^= rng_state << 13, rng_state ^= rng_state >> 7, rng_state ^= rng_state << 17;
    return (double)(rng_state >> 11) / 9007199254740992.0;
}

static double dot3(const float a[3], const float b[3])
{
    return (double)a[0] * b[0] + (double)a[1] * b[1] + (double)a[2] * b[2];
}

/* One direction through both setups; returns the number of disagreeing bases (0 or 1). */
static int check_direction(const float dir[3])
{
    srv_camera cam = {
        .position = {0, 0, 0}, .target = {dir[0], dir[1], dir[2]}, .up = {0, 1, 0}, .fov_deg = 60};
    srv_camera_frame server;
    view_rc_camera pose = {.position = {0, 0, 0}, .direction = {dir[0], dir[1], dir[2]}, .fov_deg = 60};
    const double origin[3] = {0, 0, 0};
    rc_view client;
    bool s_ok = srv_camera_setup(&cam, 64, 36, &server);
    bool c_ok = view_rc__view_setup(&pose, 64, 36, origin, &client);
    assert_int_equal(s_ok, c_ok);
    if (!s_ok)
        return 0;
    /* Orthonormal: unit lengths, right angles. */
    const float *axes[3] = {server.forward, server.right, server.up};
    for (int a = 0; a < 3; a++) {
        assert_true(fabs(dot3(axes[a], axes[a]) - 1.0) < 1e-6);
        for (int b = a + 1; b < 3; b++)
            assert_true(fabs(dot3(axes[a], axes[b])) < 1e-6);
    }
    return memcmp(server.forward, client.forward, sizeof server.forward) != 0 ||
           memcmp(server.right, client.right, sizeof server.right) != 0 ||
           memcmp(server.up, client.up, sizeof server.up) != 0;
}

static void test_random_directions(void **state)
{
    (void)state;
    int differ = 0;
    for (int i = 0; i < 20000; i++) {
        float dir[3];
        for (int k = 0; k < 3; k++)
            dir[k] = (float)(2 * uniform() - 1);
        differ += check_direction(dir);
    }
    assert_int_equal(differ, 0);
}

static void test_near_vertical_directions(void **state)
{
    (void)state;
    int differ = 0, checked = 0;
    for (int sign = -1; sign <= 1; sign += 2)
        for (int e = 3; e <= 9; e++)
            for (int a = 0; a < 64; a++) {
                double tilt = pow(10.0, -e) * (0.5 + uniform()), azimuth = 2 * M_PI * a / 64.0;
                float dir[3] = {(float)(sin(tilt) * cos(azimuth)), (float)(sign * cos(tilt)),
                                (float)(sin(tilt) * sin(azimuth))};
                differ += check_direction(dir);
                checked++;
            }
    float straight[2][3] = {{0, 1, 0}, {0, -1, 0}};
    for (int i = 0; i < 2; i++)
        differ += check_direction(straight[i]);
    assert_int_equal(checked, 2 * 7 * 64);
    assert_int_equal(differ, 0);
}

static void test_extreme_lengths(void **state)
{
    (void)state;
    int differ = 0;
    const float scales[] = {1e-30f, 1e-20f, 1e-10f, 1e5f, 1e12f}; /* the server refuses beyond 1e13 m */
    for (size_t s = 0; s < sizeof scales / sizeof scales[0]; s++)
        for (int i = 0; i < 200; i++) {
            float dir[3];
            for (int k = 0; k < 3; k++)
                dir[k] = (float)(2 * uniform() - 1) * scales[s];
            differ += check_direction(dir);
        }
    assert_int_equal(differ, 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_random_directions),
        cmocka_unit_test(test_near_vertical_directions),
        cmocka_unit_test(test_extreme_lengths),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
