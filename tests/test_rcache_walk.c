/* Tests of the client's render cache (viewer_client/rcache/rcache.h) over a moving sequence, against the
 * library itself run another way, and of what it links:
 *   - 1, 2 and 4 threads give bit-identical frames, requests and caches over a walk (the point passes split
 *     statically, the default, or handed out dynamically), and tiles of any size (or none) the same image;
 *   - equal depths keep the first slot on every path (tiles, the direct z-buffer, several threads);
 *   - the library needs nothing but libc, libm and pthreads (nm; the same check refuses fxc_proto).
 * The scene is tests/fxt_rcache.h's analytic one; test_rcache.c holds the closed-form checks. */
#include "test_util.h"

#include "fxt_rcache.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- threads ------------------------------------------------------------------------------------------- */

/* A walk: a first frame, then each client frame the camera turns and moves a little, the previous frame's
 * requests (both kinds) are answered by the ray caster with one frame of delay, and every few frames a whole
 * new frame arrives. Run with `threads`; every output of every frame is appended to a log for comparison. */
typedef struct walk_log {
    uint8_t *bytes;
    size_t used, cap;
} walk_log;

static void log_bytes(walk_log *log, const void *data, size_t n)
{
    if (log->used + n > log->cap) {
        log->cap = (log->used + n) * 2;
        log->bytes = realloc(log->bytes, log->cap);
    }
    memcpy(log->bytes + log->used, data, n);
    log->used += n;
}

static view_rc_camera walk_camera(int frame)
{
    double a = frame * 2.0 * FXT_RC_PI / 180, px = 0.05 * frame, pz = 1.0 - 0.04 * frame;
    return fxt_rc_look(px, 0.2, pz, px + sin(a), 0.1, pz - cos(a), 60);
}

static void answer(view_rc *rc, const view_rc_camera *cam, uint32_t w, uint32_t h, const view_rc_pixel *px,
                   uint32_t n)
{
    view_rc_sample *s = malloc(sizeof *s * (n + 1));
    for (uint32_t i = 0; i < n; i++) {
        double d[3];
        fxt_rc_pixel_ray(cam, w, h, px[i].x, px[i].y, d);
        fxt_rc_hit hit = fxt_rc_cast(cam->position, d, true, true);
        s[i] = (view_rc_sample){.x = px[i].x, .y = px[i].y, .depth = (float)hit.t};
        memcpy(s[i].rgb, hit.rgb, 3);
    }
    assert_int_equal(view_rc_insert_samples(rc, cam, w, h, s, n), FXC_OK);
    free(s);
}

static walk_log walk(uint32_t threads, uint32_t tile, bool dynamic, bool separate)
{
    const uint32_t w = 83, h = 57;
    walk_log log = {0};
    view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w,
                                              .height = h,
                                              .threads = threads,
                                              .tile_size = tile,
                                              .capacity = w * h * 3 / 2,
                                              .dynamic_points = dynamic,
                                              .dynamic_pixels = dynamic,
                                              .separate_pixel_passes = separate});
    uint8_t *rgb = malloc(w * h * 3);
    float *depth = malloc(w * h * sizeof(float));
    view_rc_pixel *req = malloc(sizeof *req * w * h), *pred = malloc(sizeof *pred * w * h);
    uint32_t nreq = 0, npred = 0;
    view_rc_camera prev = walk_camera(0), prev_pred = walk_camera(3);
    for (int frame = 0; frame < 24; frame++) {
        view_rc_camera cam = walk_camera(frame), predicted = walk_camera(frame + 3);
        if (frame % 8 == 0) {
            fxt_rc_render_scene(&cam, w, h, true, true, rgb, depth);
            assert_int_equal(view_rc_insert_frame(rc, &cam, w, h, rgb, depth), FXC_OK);
        }
        answer(rc, &prev, w, h, req, nreq);
        answer(rc, &prev_pred, w, h, pred, npred);
        view_rc_frame f;
        fxt_rc_render(rc, &cam, &predicted, &f);
        log_bytes(&log, f.rgb, (size_t)w * h * 3);
        log_bytes(&log, f.depth, (size_t)w * h * sizeof(float));
        log_bytes(&log, f.kind, (size_t)w * h);
        log_bytes(&log, f.priority, (size_t)w * h);
        log_bytes(&log, f.requests, f.request_count * sizeof(view_rc_pixel));
        log_bytes(&log, f.predicted_requests, f.predicted_count * sizeof(view_rc_pixel));
        uint32_t counts[] = {f.stats.points,  f.stats.projected, f.stats.migrated,  f.stats.culled,
                             f.stats.evicted, f.stats.dropped,   f.stats.superseded};
        log_bytes(&log, counts, sizeof counts);
        memcpy(req, f.requests, f.request_count * sizeof *req);
        memcpy(pred, f.predicted_requests, f.predicted_count * sizeof *pred);
        nreq = f.request_count;
        npred = f.predicted_count;
        prev = cam;
        prev_pred = predicted;
        if (frame > 0)
            assert_true(f.stats.migrated > 0 || tile >= 83);
    }
    uint32_t n = view_rc_point_count(rc);
    view_rc_point *pts = calloc(n + 1, sizeof *pts); /* zeroed: the struct's padding is compared too */
    uint32_t got = view_rc_points(rc, 0, n, pts);
    assert_int_equal(got, n);
    log_bytes(&log, pts, sizeof *pts * n);
    free(pts);
    view_rc_destroy(rc);
    free(rgb);
    free(depth);
    free(req);
    free(pred);
    return log;
}

static void test_threads_bit_identical(void **state)
{
    (void)state;
    const uint32_t tiles[] = {16, 13, 64};
    for (size_t t = 0; t < sizeof tiles / sizeof tiles[0]; t++) {
        walk_log one = walk(1, tiles[t], false, false);
        /* 2 and 4 threads, the point and pixel passes split statically (the default) and handed out
         * dynamically; then the cull, interpolation and prefilter as separate passes over the image instead
         * of fused by bands (whose halo rows are culled twice), on 1 and 2 threads. */
        const uint32_t threads[] = {2, 4, 2, 4, 1, 2};
        for (size_t k = 0; k < 6; k++) {
            walk_log many = walk(threads[k], tiles[t], k >= 2 && k < 4, k >= 4);
            assert_int_equal(many.used, one.used);
            assert_memory_equal(many.bytes, one.bytes, one.used);
            free(many.bytes);
        }
        free(one.bytes);
    }
}

/* The z-buffer's ties, by closed form, at w x h: two points at exactly the same depth in one pixel p (the same
 * sample inserted twice, w x h slots apart: different chunks), the pixel must show the first slot's colour; a
 * later point a little nearer (in pixel q) wins. Every z-buffer path: one thread straight into the image (the
 * default), one thread through the tile lists (tiled_one_thread), 2 threads, no_tiling, tiles in the tile's
 * buffers (64) and in the image (512), and the band lists (band_lists) on 1, 2 and 3 threads: at 128 x 64
 * one band of 64 rows, whose buffer (8,192 entries) the last chunk overflows, so the first point is flushed
 * into the z-buffer before the second arrives; at 1024 x 64 two bands of 32 rows, p in the first and q in
 * the second (on 2 threads each thread's band), each band's buffer (32,768 entries) overflowing too. */
static void check_ties_first_slot(uint32_t w, uint32_t h, uint32_t p, uint32_t q)
{
    view_rc_camera cam = fxt_rc_look(0, 0, 0, 0, 0, -1, 60);
    view_rc_sample *s = malloc(sizeof *s * (w * h + 4));
    uint32_t n = 0;
    const uint8_t red[3] = {200, 0, 0}, green[3] = {0, 200, 0}, grey[3] = {90, 90, 90};
    s[n] = (view_rc_sample){.x = (uint16_t)(p % w), .y = (uint16_t)(p / w), .depth = 5.0f};
    memcpy(s[n++].rgb, red, 3);
    s[n] = (view_rc_sample){.x = (uint16_t)(q % w), .y = (uint16_t)(q / w), .depth = 5.0f};
    memcpy(s[n++].rgb, red, 3);
    for (uint32_t k = 0; k < w * h; k++) {
        if (k == p || k == q)
            continue;
        s[n] = (view_rc_sample){.x = (uint16_t)(k % w), .y = (uint16_t)(k / w), .depth = 5.0f};
        memcpy(s[n++].rgb, grey, 3);
    }
    s[n] = (view_rc_sample){.x = (uint16_t)(p % w), .y = (uint16_t)(p / w), .depth = 5.0f};
    memcpy(s[n++].rgb, green, 3);
    s[n] = (view_rc_sample){.x = (uint16_t)(q % w), .y = (uint16_t)(q / w), .depth = 4.99f};
    memcpy(s[n++].rgb, green, 3);
    const struct {
        uint32_t threads, tile;
        bool tiled, no_tiling;
        bool bands;
    } ways[] = {{1, 64, false, false, false}, {1, 512, false, false, false}, {1, 64, true, false, false},
                {1, 512, true, false, false}, {2, 64, false, false, false},  {2, 512, false, false, false},
                {1, 64, false, true, false},  {1, 64, false, false, true},   {2, 64, false, false, true},
                {3, 64, false, false, true},  {1, 16, false, false, true}};
    for (size_t k = 0; k < sizeof ways / sizeof ways[0]; k++) {
        view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w,
                                                  .height = h,
                                                  .threads = ways[k].threads,
                                                  .tile_size = ways[k].tile,
                                                  .capacity = w * h + 8,
                                                  .tiled_one_thread = ways[k].tiled,
                                                  .no_tiling = ways[k].no_tiling,
                                                  .band_lists = ways[k].bands});
        assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, s, n), FXC_OK);
        view_rc_frame f;
        fxt_rc_render(rc, &cam, NULL, &f);
        assert_int_equal(f.stats.projected, n);
        assert_int_equal(f.kind[p], VIEW_RC_POINT);
        assert_memory_equal(f.rgb + 3 * p, red, 3);
        assert_int_equal(f.kind[q], VIEW_RC_POINT);
        assert_memory_equal(f.rgb + 3 * q, green, 3);
        assert_int_equal(f.kind[p + 1], VIEW_RC_POINT);
        assert_memory_equal(f.rgb + 3 * (p + 1), grey, 3);
        view_rc_destroy(rc);
    }
    free(s);
}

static void test_zbuffer_ties_first_slot(void **state)
{
    (void)state;
    check_ties_first_slot(128, 64, 20 * 128 + 30, 40 * 128 + 90);
    check_ties_first_slot(1024, 64, 20 * 1024 + 300, 40 * 1024 + 900);
}

/* The z-buffer's order within and across the one-thread path's blocks (rc_project.c, zbuffer_span: depths read
 * for a block of points before any of them is tested), by closed form: at each of four pixels a run of points
 * in consecutive slots, the pixel must show the first point of the least depth in slot order. At p 5, 3, 4, 3
 * (the 4 and the second 3 were nearer than what the z-buffer held when the block began) and, in the last
 * slots, after the other pixels' points (another block), 3 again and 6; at q 4, 3, 2, 1 (each wins in turn);
 * at r 1, 2, 3, 4; at s 5, then 2 in the last slot. The direct path, the tile lists on one thread and 2
 * threads must agree. */
static void test_zbuffer_order_in_blocks(void **state)
{
    (void)state;
    const uint32_t w = 64, h = 32;
    const uint32_t px[4] = {10 * 64 + 20, 20 * 64 + 40, 5 * 64 + 50, 25 * 64 + 8};
    view_rc_camera cam = fxt_rc_look(0, 0, 0, 0, 0, -1, 60);
    view_rc_sample *s = malloc(sizeof *s * (w * h + 16));
    uint32_t n = 0;
#define RC_T_ADD(pix, d, c)                                                                                  \
    do {                                                                                                     \
        s[n] = (view_rc_sample){.x = (uint16_t)((pix) % w), .y = (uint16_t)((pix) / w), .depth = (d)};       \
        s[n].rgb[0] = (uint8_t)(c);                                                                          \
        s[n].rgb[1] = s[n].rgb[2] = 0;                                                                       \
        n++;                                                                                                 \
    } while (0)
    RC_T_ADD(px[0], 5.0f, 10);
    RC_T_ADD(px[0], 3.0f, 11); /* p's winner */
    RC_T_ADD(px[0], 4.0f, 12);
    RC_T_ADD(px[0], 3.0f, 13);
    const float up[4] = {4.0f, 3.0f, 2.0f, 1.0f};
    for (int k = 0; k < 4; k++)
        RC_T_ADD(px[1], up[k], 20 + k); /* q's winner: the last, 23 */
    for (int k = 0; k < 4; k++)
        RC_T_ADD(px[2], up[3 - k], 30 + k); /* r's winner: the first, 30 */
    RC_T_ADD(px[3], 5.0f, 40);
    for (uint32_t k = 0; k < w * h; k++)
        if (k != px[0] && k != px[1] && k != px[2] && k != px[3])
            RC_T_ADD(k, 5.0f, 90);
    RC_T_ADD(px[0], 3.0f, 14);
    RC_T_ADD(px[0], 6.0f, 15);
    RC_T_ADD(px[3], 2.0f, 41); /* s's winner */
#undef RC_T_ADD
    const uint8_t want[4] = {11, 23, 30, 41};
    const struct {
        uint32_t threads;
        bool tiled;
    } ways[] = {{1, false}, {1, true}, {2, false}};
    for (size_t k = 0; k < sizeof ways / sizeof ways[0]; k++) {
        view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w,
                                                  .height = h,
                                                  .threads = ways[k].threads,
                                                  .tile_size = 16,
                                                  .capacity = w * h + 16,
                                                  .tiled_one_thread = ways[k].tiled});
        assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, s, n), FXC_OK);
        view_rc_frame f;
        fxt_rc_render(rc, &cam, NULL, &f);
        assert_int_equal(f.stats.projected, n);
        for (int j = 0; j < 4; j++) {
            assert_int_equal(f.kind[px[j]], VIEW_RC_POINT);
            assert_int_equal(f.rgb[3 * px[j]], want[j]);
        }
        view_rc_destroy(rc);
    }
    free(s);
}

/* ---- tiles --------------------------------------------------------------------------------------------- */

/* Tiles organise the work; they must not change the picture: the same sparse points (a pattern dense here,
 * sparse there, so that both ways of the prefilter run) through tiles of 8, 16, 64 and 256 pixels (the
 * z-buffer in buffers of the tile's own), of 512 (above 256: straight into the image), through the one-pass
 * z-buffer of no_tiling, and on one thread through the tile lists (tiled_one_thread; by default one thread
 * projects chunks straight into the image's z-buffer), and through the band lists (band_lists) on 1, 2 and 3
 * threads, give the same image, depths, kinds and priorities. */
static void test_tiles_do_not_change_the_image(void **state)
{
    (void)state;
    const uint32_t w = 150, h = 90;
    view_rc_camera cam = fxt_rc_look(0, 0.5, 0, 0, 0, -5, 60);
    view_rc_sample *s = malloc(sizeof *s * w * h);
    uint32_t n = 0;
    uint64_t seed = 12345;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            seed = seed * 6364136223846793005u + 1442695040888963407u;
            uint32_t r = (uint32_t)(seed >> 33);
            /* Dense on the left third, one in 12 in the middle, one in 60 on the right. */
            uint32_t keep = x < w / 3 ? 2 : x < 2 * w / 3 ? 12 : 60;
            if (r % keep != 0)
                continue;
            double d[3];
            fxt_rc_pixel_ray(&cam, w, h, x, y, d);
            fxt_rc_hit hit = fxt_rc_cast(cam.position, d, true, true);
            s[n] = (view_rc_sample){.x = (uint16_t)x, .y = (uint16_t)y, .depth = (float)hit.t};
            memcpy(s[n++].rgb, hit.rgb, 3);
        }
    view_rc_camera moved = fxt_rc_look(0.2, 0.6, -0.3, 0.1, 0, -5, 60);
    walk_log reference = {0};
    const uint32_t tiles[] = {64, 8, 16, 256, 512, 64, 64, 512, 16, 64, 64, 16};
    for (size_t t = 0; t < sizeof tiles / sizeof tiles[0]; t++) {
        bool direct = t == 5,
             tiled = t >= 6 && t <= 8; /* one thread: the tile lists too (tiled_one_thread) */
        bool bands = t >= 9;           /* the band lists on 1, 2 and 3 threads */
        view_rc *rc = fxt_rc_make(&(view_rc_desc){.width = w,
                                                  .height = h,
                                                  .tile_size = tiles[t],
                                                  .threads = bands ? (uint32_t)(t - 8) : 0,
                                                  .no_tiling = direct,
                                                  .tiled_one_thread = tiled,
                                                  .band_lists = bands});
        assert_int_equal(view_rc_insert_samples(rc, &cam, w, h, s, n), FXC_OK);
        view_rc_frame f;
        fxt_rc_render(rc, &moved, NULL, &f);
        assert_true(f.stats.pixels[VIEW_RC_PREFILTER] > 100 && f.stats.pixels[VIEW_RC_INTERP] > 100);
        walk_log log = {0};
        log_bytes(&log, f.rgb, (size_t)w * h * 3);
        log_bytes(&log, f.depth, (size_t)w * h * sizeof(float));
        log_bytes(&log, f.kind, (size_t)w * h);
        log_bytes(&log, f.priority, (size_t)w * h);
        if (t == 0) {
            reference = log;
        } else {
            assert_int_equal(log.used, reference.used);
            assert_memory_equal(log.bytes, reference.bytes, reference.used);
            free(log.bytes);
        }
        view_rc_destroy(rc);
    }
    free(reference.bytes);
    free(s);
}

/* ---- the client stays light ---------------------------------------------------------------------------- */

/* The symbols an archive leaves undefined that are not its own (view_rc_), libc's, libm's, pthreads' or the
 * compiler runtime's (function multi-versioning, sanitizers), through `nm -u`; their count, the first few in
 * `names`. -1 when nm cannot run. */
static int foreign_symbols(const char *archive, char *names, size_t cap)
{
    static const char *const allowed[] = {
        "aligned_alloc", "madvise", "calloc", "malloc", "realloc", "free",
        "memcpy",        "memmove", "memset", "memcmp", "abs",     "clock_gettime",
        "sqrtf",         "tanf",    "floor",  "floorf", "sysconf", "_GLOBAL_OFFSET_TABLE_"};
    char command[1200];
    snprintf(command, sizeof command, "nm -u '%s' 2>/dev/null", archive);
    FILE *pipe = popen(command, "r");
    if (!pipe)
        return -1;
    int foreign = 0, lines = 0;
    names[0] = 0;
    char line[512];
    while (fgets(line, sizeof line, pipe)) {
        char kind[8], symbol[400];
        if (sscanf(line, " %7s %399s", kind, symbol) != 2 || strlen(kind) != 1)
            continue;
        lines++;
        if (!strncmp(symbol, "view_rc_", 8) || !strncmp(symbol, "fxc_pool_", 9) ||
            !strncmp(symbol, "pthread_", 8) || !strncmp(symbol, "__", 2))
            continue;
        bool ok = false;
        for (size_t i = 0; i < sizeof allowed / sizeof allowed[0]; i++)
            ok |= !strcmp(symbol, allowed[i]);
        if (!ok) {
            if (strlen(names) + strlen(symbol) + 2 < cap) {
                strcat(names, symbol);
                strcat(names, " ");
            }
            foreign++;
        }
    }
    return pclose(pipe) == 0 && lines > 0 ? foreign : -1;
}

/* libfxc_rcache.a needs nothing but libc, libm, pthreads and the shared thread pool (libfxc_pool.a, itself
 * libc and pthreads only); the check refuses fxc_proto (zstd, libturbojpeg). The archives are found from this
 * test's scratch folder, <build>/tests/tmp_test_rcache. */
static void test_links_only_libc_libm_pthreads(void **state)
{
    (void)state;
    char build[1024], archive[1200], names[600];
    snprintf(build, sizeof build, "%s", FXC_TEST_TMP);
    for (int up = 0; up < 2; up++) {
        char *slash = strrchr(build, '/');
        assert_non_null(slash);
        *slash = 0;
    }
    snprintf(archive, sizeof archive, "%s/viewer_client/rcache/libfxc_rcache.a", build);
    int foreign = foreign_symbols(archive, names, sizeof names);
    if (foreign < 0)
        skip(); /* no nm */
    if (foreign != 0)
        fail_msg("%s needs %d symbols from outside libc, libm and pthreads: %s", archive, foreign, names);
    snprintf(archive, sizeof archive, "%s/libfxc_pool.a", build);
    foreign = foreign_symbols(archive, names, sizeof names);
    if (foreign != 0)
        fail_msg("%s needs %d symbols from outside libc and pthreads: %s", archive, foreign, names);
    snprintf(archive, sizeof archive, "%s/proto/libfxc_proto.a", build);
    foreign = foreign_symbols(archive, names, sizeof names);
    assert_true(foreign > 0);
    assert_non_null(strstr(names, "ZSTD_"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_threads_bit_identical),
        cmocka_unit_test(test_zbuffer_ties_first_slot),
        cmocka_unit_test(test_zbuffer_order_in_blocks),
        cmocka_unit_test(test_tiles_do_not_change_the_image),
        cmocka_unit_test(test_links_only_libc_libm_pthreads),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
