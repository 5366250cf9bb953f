/* The engine's plug-in points and handles (server/engine/engine.h):
 *  - an effect defined only in this file (each texel stores its world position) is requested, queued,
 *    updated, resampled and shaded by the loop, with no file outside this one changed for it;
 *  - viewers as handles: add, remove, re-add in the same slot (the old id is refused), 64 viewers and no
 *    65th, a late viewer sees what an early one sees, memory back to its total after a remove;
 *  - sinks get every viewer's frame and the frame's statistics, and the run report sums them;
 *  - a replay of traces with different start times, lengths and resolutions through `fxcache sim` matches
 *    the same schedule driven frame by frame through the API;
 *  - every result code has a message; allocation failures inside a frame are counted, never silent. */
#include "test_util.h"

#include "cache.h"
#include "camgen.h"
#include "engine.h"
#include "engine_internal.h" /* white-box: the tone map */
#include "report.h"
#include "scene.h"
#include "trace.h"

#include <float.h>
#include <jansson.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef fxt_scene_fixture fixture;

/* ---- a test-only effect: the world position of every texel ------------------------------------------- */

static atomic_uint_fast64_t position_updates, position_resamples, position_shades;

static uint32_t position_texel_bytes(const scene *s)
{
    (void)s;
    return 3 * sizeof(float);
}

static bool position_needs(const scene *s, char *why, size_t cap)
{
    (void)s;
    snprintf(why, cap, "a test wants it");
    return true;
}

static uint64_t position_cost(const scene *s, uint32_t samples)
{
    (void)s, (void)samples;
    return 0;
}

/* Each texel's centre located through the triangle lookup (which the loop filled first, as a dependency). */
static uint64_t position_update(const fx_context *ctx, const fx_block_job *jobs, uint32_t count,
                                uint32_t samples)
{
    (void)samples;
    for (uint32_t j = 0; j < count; j++) {
        const fx_block_job *job = &jobs[j];
        assert_non_null(job->lookup);
        for (uint64_t m = job->mask; m; m &= m - 1) {
            uint32_t t = (uint32_t)__builtin_ctzll(m);
            float scale = (float)(1u << job->level);
            float u = ((float)(job->block_x * 8 + (t & 7)) + 0.5f) * scale;
            float v = ((float)(job->block_y * 8 + (t >> 3)) + 0.5f) * scale;
            float position[3], normal[3];
            fx_surface_point(ctx->s, job->island, job->lookup[t], u, v, position, normal);
            memcpy((uint8_t *)job->payload + (size_t)t * 12, position, sizeof position);
            atomic_fetch_add(&position_updates, 1);
        }
    }
    return 0;
}

static void position_resample(const fx_context *ctx, const void *const finer[4], void *texel)
{
    (void)ctx;
    float mean[3] = {0, 0, 0};
    for (int c = 0; c < 4; c++) {
        float p[3];
        memcpy(p, finer[c], sizeof p);
        for (int k = 0; k < 3; k++)
            mean[k] += 0.25f * p[k];
    }
    memcpy(texel, mean, sizeof mean);
    atomic_fetch_add(&position_resamples, 1);
}

/* The sky's visibility becomes the filtered height (y) of the point: the AO view shows it. */
static void position_shade(const fx_context *ctx, const fx_shade_run *run)
{
    (void)ctx;
    for (uint32_t i = 0; i < run->count; i++) {
        const fx_taps *taps = &run->taps[i];
        if (!taps->count)
            continue;
        float y = 0;
        for (uint32_t t = 0; t < taps->count; t++) {
            float p[3];
            memcpy(p, taps->texel[t], sizeof p);
            y += taps->weight[t] * p[1];
        }
        run->sky_visibility[i] *= y;
    }
    atomic_fetch_add(&position_shades, run->count);
}

static uint64_t position_eval(const fx_context *ctx, const fx_point *point, fx_shade_point *out)
{
    (void)ctx;
    *out->sky_visibility *= point->position[1];
    return 0;
}

static const fx_effect position_effect = {
    .name = "world_position",
    .cache = SCENE_CACHE_ON_SURFACE,
    .level_bias = 0,
    .filter = FX_FILTER_BILINEAR,
    .policy = FX_UPDATE_ONCE,
    .depends_on = "triangle_lookup",
    .texel_bytes = position_texel_bytes,
    .needs = position_needs,
    .cost = position_cost,
    .update = position_update,
    .resample = position_resample,
    .shade = position_shade,
    .eval = position_eval,
};

/* The loop with the test effect beside the built-in lookup: every stage reaches it through its table. */
static void test_effect_plugin(void **state)
{
    fixture *f = *state;
    const fx_effect *effects[] = {&fx_effect_triangle_lookup, &position_effect};
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .effects = effects, .effect_count = 2, .keep_views = true};
    d.effect_on[1] = true;
    const uint32_t w = 96, h = 54;
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, w, h, &id);
    assert_true(srv_loop_effect_on(loop, 0)); /* the dependency runs with it */
    atomic_store(&position_updates, 0);
    atomic_store(&position_resamples, 0);
    atomic_store(&position_shades, 0);
    /* Looking down at the floor from 1 m, then backing away: coarser levels, whose texels can be resampled
     * from the finer ones already there. */
    srv_frame_stats st;
    uint64_t updated = 0, resampled = 0, requested = 0;
    const float heights[6] = {0.3f, 0.6f, 1.2f, 2.4f, 3.0f, 3.6f};
    for (int frame = 0; frame < 6; frame++) {
        float height = heights[frame];
        srv_camera cam = {
            .position = {0.5f, height, 0.3f}, .target = {0.5f, 0, 0.3f}, .up = {0, 0, -1}, .fov_deg = 50};
        fxt_frame(loop, &id, 1, &cam, &st);
        updated += st.texels_updated[1];
        resampled += st.texels_resampled[1];
        requested += st.requested_texels;
        assert_int_equal(st.rays[1], 0);
    }
    print_message("world_position: %llu requested, %llu updated, %llu resampled\n",
                  (unsigned long long)requested, (unsigned long long)updated, (unsigned long long)resampled);
    assert_true(requested > 0);
    assert_true(updated > 0);
    assert_true(resampled > 0);
    assert_int_equal(atomic_load(&position_updates) + resampled, updated);
    assert_int_equal(atomic_load(&position_resamples), resampled);
    assert_true(atomic_load(&position_shades) >= st.pixels_visible);

    /* Shaded: the AO view holds the filtered height, which must match the height of the surface each pixel
     * sees (from the depth buffer), within the texel size of the level read. Here the camera sees a wall and
     * the floor, so heights vary. */
    srv_camera side = {.position = {0, 1.5f, 3}, .target = {4.9f, 1.5f, -3}, .up = {0, 1, 0}, .fov_deg = 60};
    for (int frame = 0; frame < 2; frame++)
        fxt_frame(loop, &id, 1, &side, &st);
    assert_int_equal(st.pixels_missing, 0);
    const float *view = srv_viewer_view(loop, id, SRV_VIEW_AO), *depth = srv_viewer_depth(loop, id);
    assert_non_null(view);
    srv_camera_frame cf;
    assert_true(srv_camera_setup(&side, w, h, &cf));
    double texel = 1.0 / f->s->texel_density;
    uint32_t checked = 0, within = 0;
    double worst = 0;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t p = (size_t)y * w + x;
            if (!isfinite(depth[p]))
                continue;
            float dir[3];
            srv_camera_ray(&cf, (float)x + 0.5f, (float)y + 0.5f, dir);
            double expected = side.position[1] + depth[p] * dir[1];
            double err = fabs(view[p] - expected);
            worst = fmax(worst, err);
            checked++;
            within += err <= 2 * texel;
        }
    print_message(
        "height from the effect vs from the depth buffer: %u pixels, %u within 2 texels (%.4f m), worst "
        "%.4f m\n",
        checked, within, 2 * texel, worst);
    assert_true(checked > w * h / 2);
    assert_true(within >= checked * 0.95); /* the rest: coarse texels across a crease or an island border */

    /* The no-cache path calls the effect's eval: exact heights. */
    srv_loop_free(loop);
    d.no_cache = true;
    loop = fxt_loop(&d, 1, w, h, &id);
    fxt_frame(loop, &id, 1, &side, &st);
    view = srv_viewer_view(loop, id, SRV_VIEW_AO);
    depth = srv_viewer_depth(loop, id);
    for (size_t p = 0; p < (size_t)w * h; p++) {
        if (!isfinite(depth[p]))
            continue;
        float dir[3];
        srv_camera_ray(&cf, (float)(p % w) + 0.5f, (float)(p / w) + 0.5f, dir);
        assert_true(fabs(view[p] - (side.position[1] + depth[p] * dir[1])) < 1e-3);
    }
    srv_loop_free(loop);
}

/* An effect list whose dependency is missing is refused with a code. */
static void test_effect_list_refused(void **state)
{
    fixture *f = *state;
    const fx_effect *effects[] = {&position_effect};
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .effects = effects, .effect_count = 1};
    d.effect_on[0] = true;
    srv_loop *loop = NULL;
    char err[256];
    assert_int_equal(srv_loop_create(&d, &loop, err, sizeof err), FXC_ERR_EFFECTS);
    assert_null(loop);
    assert_non_null(strstr(err, "triangle_lookup"));
}

/* ---- viewers ------------------------------------------------------------------------------------------ */

static void test_viewer_handles(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = {.s = f->s, .rt = f->rt};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    srv_loop *loop = fxt_loop(&d, 0, 0, 0, NULL);
    srv_memory before, after;
    srv_loop_memory(loop, &before);

    srv_viewer_id a, b;
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.width = 32, .height = 16}, &a), FXC_OK);
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.width = 40, .height = 20}, &b), FXC_OK);
    assert_true(a.id != 0 && b.id != 0 && a.id != b.id);
    srv_loop_memory(loop, &after);
    /* triangle, barycentrics, footprint, depth (4 each), side (1), radiance (12), sRGB (3) */
    assert_int_equal(after.viewers - before.viewers, (uint64_t)(32 * 16 + 40 * 20) * (5 * 4 + 1 + 12 + 3));
    assert_int_equal(SRV_VIEWER_BYTES_PER_PIXEL,
                     5 * 4 + 1 + 12 + 3); /* what the command line checks against */
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    srv_frame_stats st;
    fxt_frame(loop, (srv_viewer_id[]){a, b}, 2, (srv_camera[]){cam, cam}, &st);
    assert_int_equal(st.viewer_count, 2);
    assert_int_equal(st.viewers[1].width, 40);
    assert_int_equal(st.visibility_rays, 32 * 16 + 40 * 20);

    /* Remove a: its id is refused everywhere; b goes on alone. */
    assert_int_equal(srv_viewer_remove(loop, a), FXC_OK);
    assert_int_equal(srv_viewer_remove(loop, a), FXC_ERR_STALE_ID);
    assert_int_equal(srv_viewer_set_camera(loop, a, &cam), FXC_ERR_STALE_ID);
    assert_null(srv_viewer_image(loop, a));
    assert_int_equal(srv_viewer_check(loop, a), FXC_ERR_STALE_ID);
    assert_int_equal(srv_loop_frame(loop, &st), FXC_OK);
    assert_int_equal(st.viewer_count, 1);
    assert_int_equal(st.viewers[0].id.id, b.id);
    /* Re-added in a's slot with a new generation: the old id stays refused. */
    srv_viewer_id c;
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.width = 32, .height = 16}, &c), FXC_OK);
    assert_int_equal(c.id & 0xFFu, a.id & 0xFFu);
    assert_true(c.id != a.id);
    assert_int_equal(srv_viewer_check(loop, a), FXC_ERR_STALE_ID);
    assert_int_equal(srv_viewer_check(loop, c), FXC_OK);
    assert_null(srv_viewer_image(loop, c)); /* no frame yet */
    assert_int_equal(srv_viewer_check(loop, (srv_viewer_id){0}), FXC_ERR_STALE_ID);
    assert_int_equal(srv_viewer_check(loop, (srv_viewer_id){0xFFFFFFFFu}), FXC_ERR_STALE_ID);
    /* Bad shapes and cameras are refused with their codes. */
    srv_viewer_id bad;
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.width = 0, .height = 5}, &bad),
                     FXC_ERR_INVALID);
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.width = 9000, .height = 5}, &bad),
                     FXC_ERR_INVALID);
    srv_camera degenerate = cam;
    memcpy(degenerate.target, degenerate.position, sizeof degenerate.target);
    assert_int_equal(srv_viewer_set_camera(loop, c, &degenerate), FXC_ERR_CAMERA);

    /* Memory: removing every viewer brings the viewers' bytes back to where they started. */
    assert_int_equal(srv_viewer_remove(loop, b), FXC_OK);
    assert_int_equal(srv_viewer_remove(loop, c), FXC_OK);
    srv_loop_memory(loop, &after);
    assert_int_equal(after.viewers, before.viewers);
    assert_int_equal(srv_loop_viewers(loop, NULL, 0), 0);
    srv_loop_free(loop);
}

/* 64 viewers fit, a 65th does not; all 64 render. */
static void test_sixty_four_viewers(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = {.s = f->s, .rt = f->rt};
    fxt_effects_on(&d, (const char *const[]){"ao"}, 1);
    srv_viewer_id ids[SRV_MAX_VIEWERS];
    srv_loop *loop = fxt_loop(&d, SRV_MAX_VIEWERS, 8, 8, ids);
    srv_viewer_id extra;
    assert_int_equal(srv_viewer_add(loop, NULL, &extra), FXC_ERR_NO_SLOT);
    srv_camera cams[SRV_MAX_VIEWERS];
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        cams[v] = srv_camgen_camera(SRV_CAMGEN_ORBIT, f->s, v, SRV_MAX_VIEWERS, 0, 1);
    srv_frame_stats st;
    fxt_frame(loop, ids, SRV_MAX_VIEWERS, cams, &st);
    assert_int_equal(st.viewer_count, SRV_MAX_VIEWERS);
    assert_int_equal(st.visibility_rays, SRV_MAX_VIEWERS * 64);
    uint64_t sum = 0;
    for (uint32_t v = 0; v < SRV_MAX_VIEWERS; v++)
        sum += st.viewers[v].requested_texels;
    assert_int_equal(sum, st.requested_texels);
    srv_loop_free(loop);
}

/* A viewer added at frame 10 with the same camera as one present from frame 0 gets the same pixels once the
 * cache has converged. */
static void test_late_viewer_same_pixels(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 5};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    srv_viewer_id early;
    srv_loop *loop = fxt_loop(&d, 1, 64, 36, &early);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    srv_frame_stats st;
    for (int frame = 0; frame < 10; frame++)
        fxt_frame(loop, &early, 1, &cam, &st);
    srv_viewer_id late;
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.width = 64, .height = 36}, &late), FXC_OK);
    for (int frame = 10; frame < 16; frame++)
        fxt_frame(loop, (srv_viewer_id[]){early, late}, 2, (srv_camera[]){cam, cam}, &st);
    assert_int_equal(st.rays[1] + st.rays[2], 0); /* converged: nothing left to trace */
    assert_memory_equal(srv_viewer_image(loop, early), srv_viewer_image(loop, late), 64 * 36 * 3);
    assert_memory_equal(srv_viewer_radiance(loop, early), srv_viewer_radiance(loop, late),
                        64 * 36 * 3 * sizeof(float));
    srv_loop_free(loop);
}

/* The on-surface kind's taps of a run of pixels equal each pixel's taps found alone, bit for bit: a pixel
 * that reuses the previous pixel's four texels (same island, level and corner texel) gets what the full
 * lookup gives. Pixels from a converged frame of the fixture, every row in runs of up to 64 and in reverse
 * order too (other neighbours), for each effect at its own level bias and one finer, the two effects' taps
 * in one call (each effect first once); every other row through lanes only (the pixels garbage). */
static void test_osc_taps_run_equals_single(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 5};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    enum { W = 96, H = 54 };
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, W, H, &id);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    srv_frame_stats st;
    for (int frame = 0; frame < 8; frame++)
        fxt_frame(loop, &id, 1, &cam, &st);
    const srv_viewer *view = &loop->viewers[0];
    srv_pixel pixels[SRV_RUN];
    static fx_taps run_taps[SRV_MAX_EFFECTS][SRV_RUN];
    fx_taps one;
    uint32_t run_blocks[SRV_MAX_EFFECTS][SRV_RUN], one_block;
    uint64_t compared = 0, four = 0, empty_total = 0;
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        if (!loop->effect_shading[e] || loop->effect_kind[e] != SCENE_CACHE_ON_SURFACE)
            continue;
        /* Effect e first, then every other on-surface effect, in one call (the several-effect interface):
         * each one's taps equal a call for it alone. */
        uint32_t group[SRV_MAX_EFFECTS] = {e}, n_group = 1;
        for (uint32_t g = 0; g < loop->effect_count; g++)
            if (g != e && loop->effect_shading[g] && loop->effect_kind[g] == SCENE_CACHE_ON_SURFACE)
                group[n_group++] = g;
        assert_int_equal(n_group, 2); /* shadow and AO */
        fx_taps *group_taps[SRV_MAX_EFFECTS];
        uint32_t *group_blocks[SRV_MAX_EFFECTS];
        for (uint32_t j = 0; j < n_group; j++)
            group_taps[j] = run_taps[j], group_blocks[j] = run_blocks[j];
        const srv_cache_kind *kind = loop->kinds[SCENE_CACHE_ON_SURFACE];
        void *cache = loop->caches[SCENE_CACHE_ON_SURFACE];
        for (int32_t bias = loop->bias[e] - 1; bias <= loop->bias[e]; bias++)
            for (int reverse = 0; reverse < 2; reverse++)
                for (uint32_t y = 0; y < H; y++) {
                    uint32_t n = 0;
                    for (uint32_t k = 0; k < W && n < SRV_RUN; k++) {
                        uint32_t x = reverse ? W - 1 - k : k;
                        size_t p = (size_t)y * W + x;
                        uint32_t tri = view->tri[p];
                        if (tri == SRV_MISS)
                            continue;
                        srv_pixel *px = &pixels[n++];
                        memset(px, 0, sizeof *px);
                        px->triangle = tri;
                        px->island = f->s->tri_island[tri];
                        px->footprint = view->footprint[p];
                        srv__island_uv(f->s, tri, view->bary_u[p], view->bary_v[p], &px->island_u,
                                       &px->island_v);
                    }
                    /* Every other row, the run's call with the pixels also as lanes (what compose's gather
                     * hands it); the single calls below always without. */
                    srv_pixel_lanes lanes;
                    memset(&lanes, 0, sizeof lanes);
                    for (uint32_t i = 0; i < n; i++) {
                        lanes.island_u[i] = pixels[i].island_u;
                        lanes.island_v[i] = pixels[i].island_v;
                        lanes.footprint[i] = pixels[i].footprint;
                        lanes.island[i] = pixels[i].island;
                        lanes.width0[i] = f->s->islands[pixels[i].island].width;
                        lanes.height0[i] = f->s->islands[pixels[i].island].height;
                    }
                    /* With lanes, the kind reads only them (lanes_suffice: compose's tile gather then leaves
                     * its pixels unset): the pixels handed along are garbage, an island far past the scene's
                     * and NaN values, which would show in the taps (or crash) if they were read. */
                    static srv_pixel garbage[SRV_RUN];
                    memset(garbage, 0xFF, sizeof garbage);
                    assert_true(kind->lanes_suffice);
                    uint32_t empty =
                        kind->pixel_taps(cache, 0, 0, (y & 1) ? garbage : pixels, (y & 1) ? &lanes : NULL, n,
                                         n_group, group, bias, group_taps, group_blocks);
                    uint32_t empty_found = 0; /* the taps with count 0 the call says it gave */
                    for (uint32_t i = 0; i < n * n_group; i++) {
                        uint32_t j = i / n, at = i % n;
                        fx_taps *one_taps = &one;
                        uint32_t *one_blocks = &one_block;
                        kind->pixel_taps(cache, 0, 0, &pixels[at], NULL, 1, 1, &group[j], bias, &one_taps,
                                         &one_blocks);
                        const fx_taps *a = &run_taps[j][at];
                        assert_int_equal(a->count, one.count);
                        empty_found += a->count == 0;
                        assert_int_equal(run_blocks[j][at], one_block);
                        assert_memory_equal(&a->footprint_log2, &one.footprint_log2, sizeof(float));
                        assert_memory_equal(a->texel, one.texel, one.count * sizeof one.texel[0]);
                        assert_memory_equal(a->weight, one.weight, one.count * sizeof(float));
                        assert_memory_equal(a->at_x, one.at_x, one.count * sizeof(float));
                        assert_memory_equal(a->at_y, one.at_y, one.count * sizeof(float));
                        compared += j == 0; /* effect e at its own levels (the other one may have no data) */
                        four += j == 0 && one.count == 4;
                    }
                    assert_int_equal(empty, empty_found);
                    empty_total += empty;
                }
    }
    assert_true(compared > 4 * W * H / 2 && four > compared / 2); /* most pixels, most of them four taps */
    assert_true(empty_total > 0); /* some pixel without data, so the count was checked where it is not 0 */
    srv_loop_free(loop);
}

/* ---- sinks and the report ----------------------------------------------------------------------------- */

typedef struct counting_sink {
    uint32_t viewer_frames, frames;
    uint64_t pixels;
    uint32_t last_width;
} counting_sink;

static int count_viewer_frame(void *user, const srv_viewer_frame *vf)
{
    counting_sink *c = user;
    c->viewer_frames++;
    c->pixels += (uint64_t)vf->width * vf->height;
    c->last_width = vf->width;
    assert_non_null(vf->srgb);
    assert_non_null(vf->radiance);
    assert_non_null(vf->depth);
    assert_non_null(vf->stats);
    assert_true(vf->camera.fov_deg > 0);
    return 0;
}

static int count_frame_done(void *user, const srv_frame_stats *st)
{
    counting_sink *c = user;
    c->frames++;
    assert_int_equal(st->frame + 1, c->frames);
    return 0;
}

static void test_sinks_and_report(void **state)
{
    fixture *f = *state;
    srv_loop_desc d = {.s = f->s, .rt = f->rt};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    srv_viewer_id ids[2];
    srv_loop *loop = fxt_loop(&d, 1, 24, 12, ids);
    counting_sink counter = {0};
    assert_int_equal(srv_loop_add_sink(loop, &(srv_sink){count_viewer_frame, count_frame_done, &counter}),
                     FXC_OK);
    srv_report *report = srv_report_create(loop);
    srv_sink rs = srv_report_sink(report);
    assert_int_equal(srv_loop_add_sink(loop, &rs), FXC_OK);
    srv_camera cam = srv_camgen_camera(SRV_CAMGEN_STATIC, f->s, 0, 1, 0, 1);
    srv_frame_stats st;
    uint64_t requested = 0;
    fxt_frame(loop, ids, 1, &cam, &st);
    requested += st.requested_texels;
    assert_int_equal(srv_viewer_add(loop, &(srv_viewer_desc){.width = 16, .height = 8}, &ids[1]), FXC_OK);
    fxt_frame(loop, ids, 2, (srv_camera[]){cam, cam}, &st);
    requested += st.requested_texels;
    assert_int_equal(counter.frames, 2);
    assert_int_equal(counter.viewer_frames, 3);
    assert_int_equal(counter.pixels, 24 * 12 * 2 + 16 * 8);
    const srv_report_totals *t = srv_report_get_totals(report);
    assert_int_equal(t->frames, 2);
    assert_int_equal(t->viewer_frames, 3);
    assert_int_equal(t->viewers_seen, 2);
    assert_int_equal(t->max_viewers, 2);
    assert_int_equal(t->requested, requested);
    assert_int_equal(t->visibility_rays, 24 * 12 * 2 + 16 * 8);
    srv_memory mem;
    srv_loop_memory(loop, &mem);
    assert_int_equal(t->final.total, mem.total);
    json_t *j = srv_report_json(report);
    assert_int_equal(json_integer_value(json_object_get(j, "viewer_frames")), 3);
    assert_non_null(json_object_get(json_object_get(j, "rays"), "shadow"));
    json_decref(j);
    srv_report_free(report);
    srv_loop_free(loop);
}

/* ---- a replay through the command line against the same schedule through the API ---------------------- */

typedef struct trace_plan {
    double start;     /* seconds */
    uint32_t cameras; /* lines, 1/30 s apart */
    uint32_t width, height;
} trace_plan;

static void test_replay_matches_api(void **state)
{
    fixture *f = *state;
    const trace_plan plans[3] = {{0.0, 12, 48, 27}, {0.1, 4, 32, 32}, {0.2, 9, 40, 20}};
    const double fps = 30;
    char paths[3][1100];
    srv_trace *traces[3];
    char err[512];
    for (int i = 0; i < 3; i++) {
        char name[32];
        snprintf(name, sizeof name, "replay_%d.trace", i);
        snprintf(paths[i], sizeof paths[i], "%s", fxt_tmp_path(name));
        srv_trace_writer *w =
            srv_trace_writer_open_sized(paths[i], f->s, plans[i].width, plans[i].height, err, sizeof err);
        assert_non_null(w);
        for (uint32_t k = 0; k < plans[i].cameras; k++) {
            srv_camera cam = srv_camgen_camera(SRV_CAMGEN_WALK, f->s, (uint32_t)i, 3, k, 2);
            assert_int_equal(srv_trace_writer_add(w, plans[i].start + k / fps, &cam), 0);
        }
        assert_int_equal(srv_trace_writer_close(w), 0);
        traces[i] = srv_trace_read(paths[i], err, sizeof err);
        assert_non_null(traces[i]);
    }
    /* Through the command line. */
    char summary[1100], stats[1100], args[4096];
    snprintf(summary, sizeof summary, "%s", fxt_tmp_path("replay_summary.json"));
    snprintf(stats, sizeof stats, "%s", fxt_tmp_path("replay_stats.jsonl"));
    snprintf(args, sizeof args,
             "sim --trace '%s' --trace '%s' --trace '%s' --summary '%s' --stats '%s' --quiet", paths[0],
             paths[1], paths[2], summary, stats);
    char out[4096], errs[4096];
    int rc = fxt_run_cli(args, out, sizeof out, errs, sizeof errs);
    if (rc != 0)
        fail_msg("fxcache %s: exit %d: %s", args, rc, errs);
    json_error_t jerr;
    json_t *sum = json_load_file(summary, 0, &jerr);
    assert_non_null(sum);

    /* Through the API: join at the first time, leave after the last, cameras by time. */
    srv_loop_desc d = {.s = f->s, .rt = f->rt, .seed = 1, .pool_bytes = 64u << 20};
    fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
    srv_loop *loop = fxt_loop(&d, 0, 0, 0, NULL);
    srv_viewer_id ids[3] = {{0}};
    bool joined[3] = {false}, left[3] = {false};
    uint64_t requested = 0, viewer_frames = 0;
    uint32_t frames = (uint32_t)floor((0.2 + 8 / fps) * fps + 1e-6) + 1; /* until the last trace ends */
    FILE *lines = fopen(stats, "rb");
    assert_non_null(lines);
    char line[1 << 15];
    for (uint32_t frame = 0; frame < frames; frame++) {
        double now = frame / fps;
        for (int i = 0; i < 3; i++) {
            bool present =
                srv_trace_first_time(traces[i]) <= now + 1e-9 && now <= srv_trace_last_time(traces[i]) + 1e-9;
            if (!present && joined[i] && !left[i]) {
                assert_int_equal(srv_viewer_remove(loop, ids[i]), FXC_OK);
                left[i] = true;
            }
            if (!present || left[i])
                continue;
            if (!joined[i]) {
                srv_viewer_desc vd = {.width = plans[i].width, .height = plans[i].height};
                assert_int_equal(srv_viewer_add(loop, &vd, &ids[i]), FXC_OK);
                joined[i] = true;
            }
            srv_camera cam = srv_trace_camera_at(traces[i], f->s, now);
            assert_int_equal(srv_viewer_set_camera(loop, ids[i], &cam), FXC_OK);
        }
        srv_frame_stats st;
        assert_int_equal(srv_loop_frame(loop, &st), FXC_OK);
        requested += st.requested_texels;
        viewer_frames += st.viewer_count;
        /* The same viewers with the same image sizes in the same frame of the stats file. */
        assert_non_null(fgets(line, sizeof line, lines));
        json_t *jl = json_loads(line, 0, &jerr);
        assert_non_null(jl);
        json_t *viewers = json_object_get(jl, "viewers");
        assert_int_equal(json_array_size(viewers), st.viewer_count);
        for (uint32_t v = 0; v < st.viewer_count; v++) {
            json_t *jv = json_array_get(viewers, v);
            assert_int_equal(json_integer_value(json_object_get(jv, "width")), st.viewers[v].width);
            assert_int_equal(json_integer_value(json_object_get(jv, "height")), st.viewers[v].height);
            assert_int_equal(json_integer_value(json_object_get(jv, "requested_texels")),
                             st.viewers[v].requested_texels);
        }
        assert_int_equal(json_integer_value(json_object_get(jl, "requested_texels")), st.requested_texels);
        json_decref(jl);
    }
    assert_null(fgets(line, sizeof line, lines)); /* no more frames than the schedule */
    fclose(lines);
    assert_int_equal(viewer_frames, 12 + 4 + 9);
    assert_int_equal(json_integer_value(json_object_get(sum, "frames")), frames);
    assert_int_equal(json_integer_value(json_object_get(sum, "viewer_frames")), viewer_frames);
    assert_int_equal(json_integer_value(json_object_get(sum, "viewers_seen")), 3);
    assert_int_equal(json_integer_value(json_object_get(sum, "requested_texels")), requested);
    json_decref(sum);
    srv_loop_free(loop);
    for (int i = 0; i < 3; i++)
        srv_trace_free(traces[i]);
}

/* ---- results and drops --------------------------------------------------------------------------------- */

/* Every code in the one table has its own non-empty message; the modules' codes are its values. */
static void test_result_codes(void **state)
{
    (void)state;
    int n = fxc_result_count();
    assert_true(n >= 10);
    for (int i = 0; i < n; i++) {
        int code = fxc_result_code(i);
        const char *text = fxc_strerror(code);
        assert_true(text && text[0]);
        assert_string_not_equal(text, "unknown result");
        assert_true(code == 0 ? i == 0 : code < 0);
        for (int j = 0; j < i; j++) {
            assert_int_not_equal(fxc_result_code(j), code);
            assert_string_not_equal(fxc_strerror(fxc_result_code(j)), text);
        }
    }
    assert_string_equal(fxc_strerror(12345), "unknown result");
    /* The cache's and the scene's codes are values of the same table. */
    const int module_codes[] = {OSC_ERR_INVALID_DESC, OSC_ERR_OUT_OF_MEMORY, OSC_ERR_POOL_EXHAUSTED,
                                OSC_ERR_TABLE_FULL,   OSC_ERR_NOT_FOUND,     SCENE_ERR_IO,
                                SCENE_ERR_FORMAT,     SCENE_ERR_JSON,        SCENE_ERR_INVALID,
                                SCENE_ERR_NOMEM,      SCENE_ERR_EMBREE};
    for (size_t i = 0; i < sizeof module_codes / sizeof module_codes[0]; i++)
        assert_string_not_equal(fxc_strerror(module_codes[i]), "unknown result");
    assert_int_equal(SCENE_ERR_NOMEM, OSC_ERR_OUT_OF_MEMORY);
    for (int d = 0; d < SRV_DROP_COUNT; d++)
        assert_string_not_equal(srv_drop_name((srv_drop)d), "?");
}

/* An allocator that refuses the n-th allocation after being armed (thread-safe: pool threads allocate). */
typedef struct failing_allocator {
    atomic_int armed;
    atomic_long countdown; /* allocations left before one fails */
    atomic_long failures;
} failing_allocator;

static void *failing_realloc(void *pointer, size_t old_size, size_t new_size, void *user)
{
    (void)old_size;
    failing_allocator *a = user;
    if (atomic_load(&a->armed) && atomic_fetch_sub(&a->countdown, 1) == 1) {
        atomic_fetch_add(&a->failures, 1);
        return NULL;
    }
    return realloc(pointer, new_size);
}

static void failing_free(void *pointer, size_t size, void *user)
{
    (void)size, (void)user;
    free(pointer);
}

/* For every k, failing the k-th allocation of a first frame is counted as a drop, the frame still completes,
 * and a later frame recovers. Both the request and the update stages are hit. */
static void test_allocation_failures_counted(void **state)
{
    fixture *f = *state;
    bool hit_requests = false, hit_updates = false;
    for (long k = 1; k < 200; k++) {
        failing_allocator fa;
        atomic_init(&fa.armed, 0);
        atomic_init(&fa.countdown, k);
        atomic_init(&fa.failures, 0);
        srv_loop_desc d = {.s = f->s,
                           .rt = f->rt,
                           .threads = 1,
                           .allocator = {.realloc = failing_realloc, .free = failing_free, .user = &fa}};
        fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
        srv_viewer_id ids[2];
        srv_loop *loop = fxt_loop(&d, 2, 48, 27, ids);
        atomic_store(&fa.armed, 1);
        srv_camera cams[2] = {srv_camgen_camera(SRV_CAMGEN_ORBIT, f->s, 0, 2, 0, 1),
                              srv_camgen_camera(SRV_CAMGEN_ORBIT, f->s, 1, 2, 0, 1)};
        srv_frame_stats st;
        fxt_frame(loop, ids, 2, cams, &st);
        long failures = atomic_load(&fa.failures);
        uint64_t drops = 0;
        for (int dr = 0; dr < SRV_DROP_COUNT; dr++)
            drops += st.drops[dr];
        if (failures > 0) {
            if (drops == 0)
                fail_msg("allocation %ld failed inside the frame but nothing was counted as dropped", k);
            hit_requests |= st.drops[SRV_DROP_NOMEM_REQUESTS] > 0;
            hit_updates |= st.drops[SRV_DROP_NOMEM_UPDATES] > 0;
        }
        atomic_store(&fa.armed, 0);
        fxt_frame(loop, ids, 2, cams, &st);
        assert_int_equal(st.drops[SRV_DROP_NOMEM_REQUESTS] + st.drops[SRV_DROP_NOMEM_UPDATES], 0);
        srv_loop_free(loop);
        if (failures == 0)
            break; /* k is past the frame's allocations: every one has been failed once */
    }
    assert_true(hit_requests);
    assert_true(hit_updates);
}

/* Compose's tone map by thresholds equals its definition with expf: over every 997th bit pattern from 0 to
 * +infinity (both signs), over every bit pattern of each interval where the byte changes (the thresholds), and
 * at NaN and the infinities. */
static void test_tone_map_thresholds(void **state)
{
    (void)state;
    uint64_t checked = 0, changes = 0;
    uint8_t previous = 0;
    for (uint64_t bits = 0; bits <= 0x7f800000u; bits += 997) {
        for (int sign = 0; sign < 2; sign++) {
            uint32_t b = (uint32_t)bits | (sign ? 0x80000000u : 0);
            float c;
            memcpy(&c, &b, sizeof c);
            uint8_t got = srv__tone_map(c), want = srv__tone_map_reference(c);
            if (got != want)
                fail_msg("tone map of %.9g (0x%08x): %u, definition %u", (double)c, b, got, want);
            checked++;
            if (sign || got == previous)
                continue;
            changes++;
            for (uint32_t d = (uint32_t)bits - 997; d <= bits; d++) { /* the interval where it changed */
                memcpy(&c, &d, sizeof c);
                if (srv__tone_map(c) != srv__tone_map_reference(c))
                    fail_msg("tone map of %.9g (0x%08x): %u, definition %u", (double)c, d, srv__tone_map(c),
                             srv__tone_map_reference(c));
            }
            previous = got;
        }
    }
    assert_true(checked > 4000000);
    assert_true(changes > 200); /* nearly every byte value is reached */
    assert_int_equal(srv__tone_map(NAN), 0);
    assert_int_equal(srv__tone_map(INFINITY), 255);
    assert_int_equal(srv__tone_map(-INFINITY), 0);
}

/* The tone map over lanes (compose's rows, 48 channels at most, vectorised) equals the definition with expf:
 * over every 9973rd bit pattern of all 2^32 (both signs, NaNs and infinities) and every 61st from 2^-9 to 1
 * (where most bytes change), in calls of 1 to 48 floats so the vector body and its remainder both run. */
static void test_tone_map_lanes(void **state)
{
    (void)state;
    enum { N = 48 };
    const struct {
        uint64_t first, end, step;
    } spans[] = {{0, 0x100000000ull, 9973}, {0x3b000000u, 0x3f800000u, 61}};
    uint64_t checked = 0;
    for (size_t r = 0; r < sizeof spans / sizeof spans[0]; r++) {
        uint32_t n = 1;
        for (uint64_t bits = spans[r].first; bits < spans[r].end; n = n % N + 1) {
            float c[N];
            uint8_t got[N];
            uint32_t count = 0;
            for (; count < n && bits < spans[r].end; count++, bits += spans[r].step) {
                uint32_t b = (uint32_t)bits;
                memcpy(&c[count], &b, sizeof b);
            }
            srv__tone_map_lanes(c, got, count);
            for (uint32_t j = 0; j < count; j++) {
                uint8_t want = srv__tone_map_reference(c[j]);
                if (got[j] != want) {
                    uint32_t b;
                    memcpy(&b, &c[j], sizeof b);
                    fail_msg("tone map lanes of %.9g (0x%08x): %u, definition %u", (double)c[j], b, got[j],
                             want);
                }
            }
            checked += count;
        }
    }
    assert_true(checked > 1500000);
    /* Every bit pattern of each interval of 61 where the byte changes: the thresholds themselves. */
    uint32_t changes = 0;
    for (uint32_t bits = 0x3b000000u; bits + 61 <= 0x3f800000u; bits += 61) {
        float lo, hi;
        uint32_t end = bits + 61;
        memcpy(&lo, &bits, sizeof lo);
        memcpy(&hi, &end, sizeof hi);
        if (srv__tone_map_reference(lo) == srv__tone_map_reference(hi))
            continue;
        changes++;
        for (uint32_t first = bits; first <= end; first += N) {
            float c[N];
            uint8_t got[N];
            uint32_t count = 0;
            for (; count < N && first + count <= end; count++) {
                uint32_t b = first + count;
                memcpy(&c[count], &b, sizeof b);
            }
            srv__tone_map_lanes(c, got, count);
            for (uint32_t j = 0; j < count; j++)
                if (got[j] != srv__tone_map_reference(c[j]))
                    fail_msg("tone map lanes at a threshold, %.9g: %u, definition %u", (double)c[j], got[j],
                             srv__tone_map_reference(c[j]));
        }
    }
    assert_true(changes > 200);
    const float special[] = {NAN, INFINITY, -INFINITY, 0.0f, -0.0f, 20.0f, 0x1p-20f, FLT_MAX, -FLT_MAX};
    uint8_t got[9];
    srv__tone_map_lanes(special, got, 9);
    const uint8_t want[] = {0, 255, 0, 0, 0, 255, srv__tone_map_reference(0x1p-20f), 255, 0};
    assert_memory_equal(got, want, sizeof want);
}

/* A test run with the embedded default scene as its state. */
#define SCENE_TEST(test)                                                                                     \
    cmocka_unit_test_setup_teardown(test, fxt_default_scene_setup, fxt_default_scene_teardown)

int main(void)
{
    const struct CMUnitTest tests[] = {
        SCENE_TEST(test_effect_plugin),           SCENE_TEST(test_effect_list_refused),
        SCENE_TEST(test_viewer_handles),          SCENE_TEST(test_sixty_four_viewers),
        SCENE_TEST(test_late_viewer_same_pixels), SCENE_TEST(test_osc_taps_run_equals_single),
        SCENE_TEST(test_sinks_and_report),        SCENE_TEST(test_replay_matches_api),
        cmocka_unit_test(test_result_codes),      cmocka_unit_test(test_tone_map_thresholds),
        cmocka_unit_test(test_tone_map_lanes),    SCENE_TEST(test_allocation_failures_counted),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
