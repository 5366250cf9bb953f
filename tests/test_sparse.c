/* Sparse viewers (server/engine/engine.h, srv_viewer_set_pixels): the engine side of the render cache's
 * sample requests (issue 11). On the embedded default scene:
 *  - a sparse viewer's pixels equal the same pixels of a whole-frame viewer with the same camera rendered in
 *    the same frames (the same cache state at compose): colour, radiance and depth bit for bit, after ten
 *    frames of a static camera and on the first frame alike (shadow and AO); with the world-space probes on,
 *    depth is exact and colour within PROBE_TOLERANCE sRGB levels (probe shading groups a run's pixels), and
 *    within BLOCK_TOLERANCE where the whole frame evaluates indirect light per 4 x 4 block;
 *    the sinks never see the sparse viewer;
 *  - a list of every pixel (shuffled, each twice) in a fresh loop costs exactly what a whole frame costs in
 *    another fresh loop (primary rays, requested texels, effect rays per effect) and gives the same image;
 *  - a list of five pixels traces five primary rays, requests at most what five pixels' filters touch and
 *    traces a small fraction of a whole frame's effect rays;
 *  - refusals (count 0, above max_pixels, an entry outside the image, a whole-frame viewer, a stale id)
 * change nothing; duplicates are traced once; the list is spent by the frame that renders it; memory is
 *    max_pixels x (SRV_VIEWER_BYTES_PER_PIXEL + SRV_LIST_BYTES_PER_ENTRY). */
#include "test_util.h"

#include "camgen.h"
#include "engine.h"
#include "report.h"
#include "scene.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef fxt_scene_fixture fixture;

enum { W = 64, H = 36 };

static int compare_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* A list of n pixels of the W x H image: the four corners, then random ones (with repeats). */
static void make_list(uint32_t *list, uint32_t n, uint32_t seed)
{
    static const uint32_t corners[4][2] = {{0, 0}, {W - 1, 0}, {0, H - 1}, {W - 1, H - 1}};
    for (uint32_t i = 0; i < n; i++) {
        if (i < 4)
            list[i] = SRV_PIXEL_XY(corners[i][0], corners[i][1]);
        else
            list[i] = SRV_PIXEL_XY(fxt_random(&seed) % W, fxt_random(&seed) % H);
    }
}

typedef struct counting_sink {
    uint32_t viewer_frames;
    uint32_t last_width;
} counting_sink;

static int count_viewer_frame(void *user, const srv_viewer_frame *vf)
{
    counting_sink *c = user;
    c->viewer_frames++;
    c->last_width = vf->width;
    return 0;
}

/* Every listed pixel of the sparse viewer against the same pixel of the whole frame. */
static void assert_same_pixels(srv_loop *loop, srv_viewer_id full, srv_viewer_id sparse, const uint32_t *list,
                               uint32_t n)
{
    const uint8_t *image = srv_viewer_image(loop, full), *sparse_image = srv_viewer_image(loop, sparse);
    const float *radiance = srv_viewer_radiance(loop, full),
                *sparse_radiance = srv_viewer_radiance(loop, sparse);
    const float *depth = srv_viewer_depth(loop, full), *sparse_depth = srv_viewer_depth(loop, sparse);
    assert_non_null(sparse_image);
    assert_non_null(sparse_radiance);
    assert_non_null(sparse_depth);
    for (uint32_t i = 0; i < n; i++) {
        uint32_t x = list[i] & 0xFFFFu, y = list[i] >> 16;
        size_t p = (size_t)y * W + x;
        uint32_t at = srv_viewer_pixel_index(loop, sparse, x, y);
        assert_true(at != UINT32_MAX);
        if (memcmp(image + 3 * p, sparse_image + 3 * (size_t)at, 3) != 0 ||
            memcmp(radiance + 3 * p, sparse_radiance + 3 * (size_t)at, 3 * sizeof(float)) != 0 ||
            memcmp(depth + p, sparse_depth + at, sizeof(float)) != 0)
            fail_msg("pixel (%u, %u): sparse %u %u %u depth %g, whole frame %u %u %u depth %g", x, y,
                     sparse_image[3 * at], sparse_image[3 * at + 1], sparse_image[3 * at + 2],
                     (double)sparse_depth[at], image[3 * p], image[3 * p + 1], image[3 * p + 2],
                     (double)depth[p]);
    }
}

static void test_sparse_equals_whole_frame(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 11};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    srv_viewer_id full;
    srv_loop *loop = fxt_loop(&d, 1, W, H, &full);
    counting_sink sink_counts = {0};
    srv_sink sink = {.viewer_frame = count_viewer_frame, .user = &sink_counts};
    assert_int_equal(srv_loop_add_sink(loop, &sink), FXC_OK);
    srv_report *report = srv_report_create(loop);
    srv_sink rs = srv_report_sink(report);
    assert_int_equal(srv_loop_add_sink(loop, &rs), FXC_OK);
    srv_viewer_id sparse;
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.max_pixels = 600}, &sparse), FXC_OK);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    uint32_t list[600];
    srv_frame_stats st;
    uint64_t visible_listed = 0;
    for (int frame = 0; frame < 10; frame++) {
        make_list(list, 600, 0x1234u + (uint32_t)frame);
        uint32_t unique = 0;
        assert_int_equal(srv_viewer_set_pixels(loop, sparse, &cam, W, H, list, 600, &unique), FXC_OK);
        /* The distinct count, by a second method (sort and count). */
        uint32_t sorted[600];
        memcpy(sorted, list, sizeof sorted);
        qsort(sorted, 600, sizeof *sorted, compare_u32);
        uint32_t distinct = 1;
        for (uint32_t i = 1; i < 600; i++)
            distinct += sorted[i] != sorted[i - 1];
        assert_int_equal(unique, distinct);
        assert_true(unique < 600); /* the list has repeats */
        fxt_frame(loop, &full, 1, &cam, &st);
        assert_int_equal(st.viewer_count, 2);
        assert_int_equal(st.visibility_rays, (uint64_t)W * H + unique);
        /* The sparse viewer's list holds the distinct pixels, in a whole frame's compose order: 16 x 16
         * tiles in row order, then 4-row bands. */
        uint32_t count = 0;
        const uint32_t *rendered = srv_viewer_pixels(loop, sparse, &count);
        assert_int_equal(count, distinct);
        uint32_t by_value[600];
        memcpy(by_value, rendered, count * sizeof *rendered);
        qsort(by_value, count, sizeof *by_value, compare_u32);
        for (uint32_t i = 0, j = 0; i < 600; i++)
            if (i == 0 || sorted[i] != sorted[i - 1])
                assert_int_equal(by_value[j++], sorted[i]);
        for (uint32_t i = 1; i < count; i++) {
            uint32_t x0 = rendered[i - 1] & 0xFFFFu, y0 = rendered[i - 1] >> 16;
            uint32_t x1 = rendered[i] & 0xFFFFu, y1 = rendered[i] >> 16;
            uint32_t band0 = (y0 / 16 * 4 + x0 / 16) * 4 + y0 % 16 / 4,
                     band1 = (y1 / 16 * 4 + x1 / 16) * 4 + y1 % 16 / 4;
            assert_true(band0 <= band1); /* W = 64: four tiles per row */
        }
        /* Exact: the same camera, the same cache state at compose. */
        assert_same_pixels(loop, full, sparse, list, 600);
        const float *depth = srv_viewer_depth(loop, full);
        visible_listed = 0;
        for (uint32_t i = 0; i < count; i++)
            visible_listed += isfinite(depth[(rendered[i] >> 16) * W + (rendered[i] & 0xFFFFu)]);
        const srv_viewer_stats *vs = st.viewers[0].id.id == sparse.id ? &st.viewers[0] : &st.viewers[1];
        assert_int_equal(vs->pixels_visible, visible_listed);
        assert_int_equal(vs->pixels_rendered, distinct);
        assert_int_equal(vs->width, W);
        assert_int_equal(vs->height, H);
        assert_true(vs->sparse);
        assert_false((vs == &st.viewers[0] ? &st.viewers[1] : &st.viewers[0])->sparse);
    }
    assert_true(visible_listed > 100);               /* the camera sees the scene, not only sky */
    assert_int_equal(sink_counts.viewer_frames, 10); /* the whole-frame viewer only */
    assert_int_equal(sink_counts.last_width, W);
    /* The list is spent: the next frame renders the whole-frame viewer alone, and the results stay. */
    fxt_frame(loop, &full, 1, &cam, &st);
    assert_int_equal(st.viewer_count, 1);
    assert_int_equal(st.visibility_rays, (uint64_t)W * H);
    assert_non_null(srv_viewer_pixels(loop, sparse, NULL));
    /* The summary counts the sparse viewer apart from the whole-frame viewers (11 frames, 10 with a list). */
    const srv_report_totals *t = srv_report_get_totals(report);
    assert_int_equal(t->frames, 11);
    assert_int_equal(t->viewers_seen, 1);
    assert_int_equal(t->max_viewers, 1);
    assert_int_equal(t->viewer_frames, 11);
    assert_int_equal(t->sample_viewers_seen, 1);
    assert_int_equal(t->sample_viewer_frames, 10);
    srv_report_free(report);
    srv_loop_free(loop);
}

/* sRGB differences between pixels of two images, accumulated: the worst channel, the sum over channels,
 * pixels differing and pixels compared. */
typedef struct srgb_difference {
    int worst;
    uint64_t total, differing, compared;
} srgb_difference;

static void srgb_difference_add(srgb_difference *d, const uint8_t a[3], const uint8_t b[3])
{
    bool differs = false;
    for (int k = 0; k < 3; k++) {
        int diff = abs((int)a[k] - (int)b[k]);
        d->worst = diff > d->worst ? diff : d->worst;
        d->total += (uint64_t)diff;
        differs |= diff != 0;
    }
    d->differing += differs;
    d->compared++;
}

/* With the world-space probes on, a pixel's indirect term is not a function of the pixel alone: probe shading
 * (effects/fx_probes_map.c) weighs the pixels of a run that share probes and normal at their mean position,
 * and a sparse list holds only some of a whole-frame run's pixels (a lone pixel is weighed at its own
 * position). Depth stays exact (and the whole run listed gives the whole frame's colour exactly:
 * test_every_pixel_costs_a_whole_frame); the colour differs by up to PROBE_TOLERANCE sRGB levels, and by
 * PROBE_MEAN_TOLERANCE on average. Measured on this scene and camera: at most 37 levels, 0.206 on average
 * per channel, 1626 of 6000 pixels differing (the test prints the figures). */
#define PROBE_TOLERANCE      48
#define PROBE_MEAN_TOLERANCE 0.5

static void test_probes_within_tolerance(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 11};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao", "probes"}, 3);
    srv_viewer_id full, sparse;
    srv_loop *loop = fxt_loop(&d, 1, W, H, &full);
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.max_pixels = 600}, &sparse), FXC_OK);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    uint32_t list[600];
    srv_frame_stats st;
    srgb_difference dif = {0};
    for (int frame = 0; frame < 10; frame++) {
        make_list(list, 600, 0x777u + (uint32_t)frame);
        assert_int_equal(srv_viewer_set_pixels(loop, sparse, &cam, W, H, list, 600, NULL), FXC_OK);
        fxt_frame(loop, &full, 1, &cam, &st);
        const uint8_t *image = srv_viewer_image(loop, full), *sparse_image = srv_viewer_image(loop, sparse);
        const float *depth = srv_viewer_depth(loop, full), *sparse_depth = srv_viewer_depth(loop, sparse);
        for (uint32_t i = 0; i < 600; i++) {
            uint32_t x = list[i] & 0xFFFFu, y = list[i] >> 16,
                     at = srv_viewer_pixel_index(loop, sparse, x, y);
            size_t p = (size_t)y * W + x;
            assert_memory_equal(depth + p, sparse_depth + at, sizeof(float));
            srgb_difference_add(&dif, image + 3 * p, sparse_image + 3 * (size_t)at);
        }
    }
    double mean = (double)dif.total / (3.0 * (double)dif.compared);
    print_message(
        "probes on: %llu of %llu listed pixels differ from the whole frame, by at most %d sRGB levels, "
        "%.3f on average per channel\n",
        (unsigned long long)dif.differing, (unsigned long long)dif.compared, dif.worst, mean);
    assert_true(dif.worst <= PROBE_TOLERANCE);
    assert_true(mean <= PROBE_MEAN_TOLERANCE);
    srv_loop_free(loop);
}

/* A whole frame whose indirect light is evaluated once per 4 x 4 block (srv_loop_desc.indirect_block: at
 * 160 x 96 and 20 degrees the narrowest probe cell spans 17 pixels, so the viewer uses 4) against a sparse
 * viewer's pixels, each evaluated itself (a list has no neighbours), same camera and cache. The colour
 * differs by the blocks' upsampling (joint bilateral, tests/test_world.c) on top of the run grouping above:
 * at most BLOCK_TOLERANCE sRGB levels and BLOCK_MEAN_TOLERANCE on average per channel, about twice what was
 * measured when the blocks came (at most 17 levels, 0.338 on average, 2279 of 4833 pixels differing; printed).
 * Since the frame-wide sample pass (one evaluation per sample, shade grouped by the frame's samples) it is
 * 0.395 on average, 17 at most, 2276 pixels; 8 x 8 blocks measured 0.756 (BENCHMARKS, probe-pix2). */
#define BLOCK_TOLERANCE      32
#define BLOCK_MEAN_TOLERANCE 0.7

static void test_probe_blocks_within_tolerance(void **state)
{
    enum { BW = 160, BH = 96, LISTED = 1000 };
    fixture *f = *state;
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 11};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao", "probes"}, 3);
    srv_viewer_id full, sparse;
    srv_loop *loop = fxt_loop(&d, 1, BW, BH, &full);
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.max_pixels = LISTED}, &sparse), FXC_OK);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    cam.fov_deg = 20.0f;
    static uint32_t list[LISTED];
    srv_frame_stats st;
    srgb_difference dif = {0};
    for (int frame = 0; frame < 10; frame++) {
        uint32_t seed = 0x999u + (uint32_t)frame;
        for (uint32_t i = 0; i < LISTED; i++)
            list[i] = SRV_PIXEL_XY(fxt_random(&seed) % BW, fxt_random(&seed) % BH);
        assert_int_equal(srv_viewer_set_pixels(loop, sparse, &cam, BW, BH, list, LISTED, NULL), FXC_OK);
        fxt_frame(loop, &full, 1, &cam, &st);
        if (frame < 5) /* the probes settle first: compare the same converged cache */
            continue;
        const uint8_t *image = srv_viewer_image(loop, full), *sparse_image = srv_viewer_image(loop, sparse);
        uint32_t count = 0;
        const uint32_t *pixels = srv_viewer_pixels(loop, sparse, &count);
        for (uint32_t i = 0; i < count; i++) {
            size_t p = (size_t)(pixels[i] >> 16) * BW + (pixels[i] & 0xFFFFu);
            srgb_difference_add(&dif, image + 3 * p, sparse_image + 3 * (size_t)i);
        }
    }
    double mean = (double)dif.total / (3.0 * (double)dif.compared);
    print_message(
        "4x4 blocks: %llu of %llu listed pixels differ from the whole frame, by at most %d sRGB levels, "
        "%.3f on average per channel\n",
        (unsigned long long)dif.differing, (unsigned long long)dif.compared, dif.worst, mean);
    assert_true(dif.compared > 2000);
    assert_true(dif.worst <= BLOCK_TOLERANCE);
    assert_true(mean <= BLOCK_MEAN_TOLERANCE);
    srv_loop_free(loop);
}

/* Runs frames of one viewer in a fresh loop: a whole-frame viewer, or a sparse one listing every pixel twice
 * in a shuffled order. Fills the last frame's stats and a copy of the image in row order. */
static void run_alone(fixture *f, bool sparse, int frames, srv_frame_stats *st, uint8_t *image)
{
    /* Every pixel's own indirect light (indirect_block 1), as a sparse viewer always has it: the whole frame's
     * 4 x 4 blocks against a list are test_probes_within_tolerance's. */
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 3, .threads = 2, .indirect_block = 1};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao", "probes"}, 3);
    char err[256];
    srv_loop *loop = NULL;
    assert_int_equal(srv_loop_create(&d, &loop, err, sizeof err), FXC_OK);
    srv_viewer_id id;
    srv_viewer_desc vd =
        sparse ? (srv_viewer_desc){.max_pixels = 2 * W * H} : (srv_viewer_desc){.width = W, .height = H};
    assert_int_equal(srv_viewer_add(loop, &vd, &id), FXC_OK);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    static uint32_t list[2 * W * H];
    uint32_t rng = 99;
    for (int frame = 0; frame < frames; frame++) {
        if (sparse) {
            for (uint32_t i = 0; i < 2 * W * H; i++)
                list[i] = SRV_PIXEL_XY(i % W, (i / W) % H);
            for (uint32_t i = 2 * W * H - 1; i > 0; i--) {
                uint32_t j = fxt_random(&rng) % (i + 1), t = list[i];
                list[i] = list[j];
                list[j] = t;
            }
            uint32_t unique = 0;
            assert_int_equal(srv_viewer_set_pixels(loop, id, &cam, W, H, list, 2 * W * H, &unique), FXC_OK);
            assert_int_equal(unique, W * H);
        } else {
            assert_int_equal(srv_viewer_set_camera(loop, id, &cam), FXC_OK);
        }
        assert_int_equal(srv_loop_frame(loop, st), FXC_OK);
    }
    /* In the whole frame's layout: a sparse viewer's entry i is pixel list[i]. */
    const uint8_t *rendered = srv_viewer_image(loop, id);
    if (sparse) {
        uint32_t count = 0;
        const uint32_t *pixels = srv_viewer_pixels(loop, id, &count);
        assert_int_equal(count, W * H);
        for (uint32_t i = 0; i < count; i++)
            memcpy(image + 3 * (size_t)((pixels[i] >> 16) * W + (pixels[i] & 0xFFFFu)),
                   rendered + 3 * (size_t)i, 3);
    } else {
        memcpy(image, rendered, (size_t)W * H * 3);
    }
    srv_loop_free(loop);
}

static void test_every_pixel_costs_a_whole_frame(void **state)
{
    fixture *f = *state;
    static uint8_t image_full[W * H * 3], image_sparse[W * H * 3];
    for (int frames = 1; frames <= 3; frames += 2) {
        srv_frame_stats full, sparse;
        run_alone(f, false, frames, &full, image_full);
        run_alone(f, true, frames, &sparse, image_sparse);
        assert_int_equal(sparse.visibility_rays, full.visibility_rays);
        assert_int_equal(sparse.requested_texels, full.requested_texels);
        assert_int_equal(sparse.unique_texels, full.unique_texels);
        assert_int_equal(sparse.world.requested_cells, full.world.requested_cells);
        uint64_t rays = 0;
        for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++) {
            assert_int_equal(sparse.rays[e], full.rays[e]);
            rays += full.rays[e];
        }
        assert_true(rays > 0);
        assert_int_equal(sparse.pixels_missing, full.pixels_missing);
        assert_memory_equal(image_sparse, image_full, sizeof image_full);
    }
}

static void test_few_pixels_cost_few_rays(void **state)
{
    fixture *f = *state;
    srv_frame_stats full;
    static uint8_t image[W * H * 3];
    run_alone(f, false, 1, &full, image);
    uint64_t full_rays = 0;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++)
        full_rays += full.rays[e];

    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 3, .threads = 2};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    char err[256];
    srv_loop *loop = NULL;
    assert_int_equal(srv_loop_create(&d, &loop, err, sizeof err), FXC_OK);
    srv_viewer_id id;
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.max_pixels = 16}, &id), FXC_OK);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    /* Five pixels around the image's centre, where the default camera sees the scene. */
    const uint32_t list[5] = {SRV_PIXEL_XY(32, 18), SRV_PIXEL_XY(10, 30), SRV_PIXEL_XY(50, 25),
                              SRV_PIXEL_XY(20, 20), SRV_PIXEL_XY(40, 30)};
    assert_int_equal(srv_viewer_set_pixels(loop, id, &cam, W, H, list, 5, NULL), FXC_OK);
    srv_frame_stats st;
    assert_int_equal(srv_loop_frame(loop, &st), FXC_OK);
    assert_int_equal(st.visibility_rays, 5);
    assert_int_equal(st.viewers[0].pixels_rendered, 5);
    uint64_t rays = 0;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++)
        rays += st.rays[e];
    /* At most the texels five pixels' filters touch, per shading effect: SRV_KEYS_PER_PIXEL blocks of 64. */
    assert_true(st.requested_texels > 0);
    assert_true(st.requested_texels <= 5ull * 2 * FX_MAX_TAPS * 64);
    assert_true(rays > 0);
    assert_true(rays * 20 < full_rays); /* under 5 % of a whole frame's (which has 2304 pixels) */
    print_message(
        "5 pixels: %llu effect rays, %llu requested texels; the whole 64x36 frame: %llu effect rays, "
        "%llu requested texels\n",
        (unsigned long long)rays, (unsigned long long)st.requested_texels, (unsigned long long)full_rays,
        (unsigned long long)full.requested_texels);
    srv_loop_free(loop);
}

static void test_refusals_and_memory(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 3, .threads = 1};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    srv_viewer_id full;
    srv_loop *loop = fxt_loop(&d, 1, W, H, &full);
    srv_memory before, after;
    srv_loop_memory(loop, &before);
    srv_viewer_id sparse;
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.max_pixels = SRV_MAX_PIXEL_LIST + 1}, &sparse),
                     FXC_ERR_INVALID);
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.max_pixels = 100}, &sparse), FXC_OK);
    srv_loop_memory(loop, &after);
    assert_int_equal(after.viewers - before.viewers,
                     100 * (SRV_VIEWER_BYTES_PER_PIXEL + SRV_LIST_BYTES_PER_ENTRY));
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    assert_int_equal(srv_viewer_set_camera(loop, sparse, &cam), FXC_ERR_INVALID);
    uint32_t list[101];
    make_list(list, 101, 7);
    static const struct {
        const char *what;
        uint32_t width, height, count, bad_entry; /* bad_entry: replaces list[3] when nonzero */
        fxc_result expect;
    } cases[] = {
        {"count 0", W, H, 0, 0, FXC_ERR_RANGE},
        {"count above max_pixels", W, H, 101, 0, FXC_ERR_RANGE},
        {"x = width", W, H, 10, SRV_PIXEL_XY(W, 0), FXC_ERR_RANGE},
        {"y = height", W, H, 10, SRV_PIXEL_XY(0, H), FXC_ERR_RANGE},
        {"x 0xffff", W, H, 10, SRV_PIXEL_XY(0xFFFF, 1), FXC_ERR_RANGE},
        {"width 0", 0, H, 10, 0, FXC_ERR_INVALID},
        {"height above the maximum", W, SRV_MAX_SIDE + 1, 10, 0, FXC_ERR_INVALID},
        {"control: 100 pixels", W, H, 100, 0, FXC_OK},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        uint32_t saved = list[3];
        if (cases[c].bad_entry)
            list[3] = cases[c].bad_entry;
        fxc_result r = srv_viewer_set_pixels(loop, sparse, &cam, cases[c].width, cases[c].height, list,
                                             cases[c].count, NULL);
        list[3] = saved;
        if (r != cases[c].expect)
            fail_msg("%s: %s, expected %s", cases[c].what, fxc_strerror(r), fxc_strerror(cases[c].expect));
        if (r != FXC_OK) { /* nothing changed: no list is pending */
            srv_frame_stats st;
            fxt_frame(loop, &full, 1, &cam, &st);
            assert_int_equal(st.viewer_count, 1);
        }
    }
    assert_int_equal(srv_viewer_set_pixels(loop, full, &cam, W, H, list, 10, NULL), FXC_ERR_INVALID);
    assert_int_equal(srv_viewer_set_pixels(loop, sparse, &cam, W, H, NULL, 10, NULL), FXC_ERR_INVALID);
    srv_camera bad = cam;
    bad.fov_deg = 0;
    assert_int_equal(srv_viewer_set_pixels(loop, sparse, &bad, W, H, list, 10, NULL), FXC_ERR_CAMERA);
    /* The control case's list is pending: one frame renders it, then it is spent. */
    srv_frame_stats st;
    fxt_frame(loop, &full, 1, &cam, &st);
    assert_int_equal(st.viewer_count, 2);
    uint32_t count = 0;
    assert_non_null(srv_viewer_pixels(loop, sparse, &count));
    assert_true(count > 50 && count <= 100);
    assert_int_equal(srv_viewer_pixel_index(loop, sparse, W, 0), UINT32_MAX);
    assert_null(srv_viewer_pixels(loop, full, NULL));
    srv_viewer_id stale = sparse;
    srv_memory mid;
    srv_loop_memory(loop, &mid);
    assert_int_equal(srv_viewer_remove(loop, sparse), FXC_OK);
    assert_int_equal(srv_viewer_set_pixels(loop, stale, &cam, W, H, list, 10, NULL), FXC_ERR_STALE_ID);
    srv_loop_memory(loop, &after);
    /* Its buffers and its request list are freed (the whole-frame viewer's request list grew meanwhile). */
    assert_true(after.viewers + 100 * (SRV_VIEWER_BYTES_PER_PIXEL + SRV_LIST_BYTES_PER_ENTRY) < mid.viewers);
    srv_loop_free(loop);
}

#define SCENE_TEST(test)                                                                                     \
    cmocka_unit_test_setup_teardown(test, fxt_default_scene_setup, fxt_default_scene_teardown)

int main(void)
{
    const struct CMUnitTest tests[] = {
        SCENE_TEST(test_sparse_equals_whole_frame),     SCENE_TEST(test_probes_within_tolerance),
        SCENE_TEST(test_probe_blocks_within_tolerance), SCENE_TEST(test_every_pixel_costs_a_whole_frame),
        SCENE_TEST(test_few_pixels_cost_few_rays),      SCENE_TEST(test_refusals_and_memory),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
