/* Stability suite, caches (docs/ERROR.md "Stability suite"): a pool far smaller than the working set
 * (thrashing: slower, never wrong), the table at the highest load the engine gives it, the largest level
 * biases, and world positions at and beyond the world-space range. Every frame is checked by
 * stab_check_loop; the on-surface texels a thrashing cache holds are recomputed from scratch (white-box). */
#include "stab_util.h"

#include "camgen.h"
#include "engine_internal.h"
#include "fx_internal.h"
#include "scene_internal.h"
#include "wsc.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- recomputing resident texels ---------------------------------------------------------------------------- */

/* Every texel with data of every resident block of the on-surface effects is what the effect computes for its
 * key from nothing (the second method: the effect's own update on a fresh buffer, with the loop's context):
 * lookup texels with fx_lookup_update, shadow masks with fx_shadow_update, AO with fx_ao_update of the texel's
 * own sample count (samples k of a texel are a function of (seed, key, texel, k), so any split of them over
 * frames gives the same bytes). Random numbers hash the key, so a block evicted and mapped again elsewhere
 * must hold exactly the same bytes. Returns the texels compared. */
static uint64_t recompute_resident(srv_loop *loop)
{
    const scene *s = loop->s;
    const srv_cache_kind *kind = loop->kinds[SCENE_CACHE_ON_SURFACE];
    void *cache = loop->caches[SCENE_CACHE_ON_SURFACE];
    uint64_t compared = 0;
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        if (!loop->effect_cached[e] || loop->effect_kind[e] != SCENE_CACHE_ON_SURFACE)
            continue;
        const char *name = loop->effects[e]->name;
        uint32_t bytes = loop->effects[e]->texel_bytes(s);
        for (uint32_t b = 0; b < kind->pool_capacity(cache, e); b++) {
            uint64_t key = kind->block_key(cache, e, b), valid = kind->block_valid(cache, e, b);
            if (key == UINT64_MAX || !valid)
                continue;
            fx_block_job job;
            memset(&job, 0, sizeof job);
            kind->job_location(cache, e, key, &job);
            uint32_t lookup[64];
            fx_lookup_update(s, job.island, job.level, job.block_x, job.block_y, valid, lookup);
            const uint8_t *held = kind->block_payload(cache, e, b);
            uint32_t fresh_words[64 * 2]; /* 64 texels of at most 8 bytes */
            uint8_t *fresh = (uint8_t *)fresh_words;
            assert_true(bytes <= 8);
            for (uint64_t m = valid; m; m &= m - 1) {
                uint32_t t = (uint32_t)__builtin_ctzll(m);
                memset(fresh_words, 0, sizeof fresh_words);
                job.mask = 1ull << t;
                job.lookup = lookup;
                job.payload = fresh;
                if (strcmp(name, "triangle_lookup") == 0) {
                    fx_lookup_update(s, job.island, job.level, job.block_x, job.block_y, job.mask,
                                     fresh_words);
                } else if (strcmp(name, "shadow") == 0) {
                    fx_shadow_update(&loop->fx, &job, 1);
                } else if (strcmp(name, "ao") == 0) {
                    fx_ao_update(&loop->fx, &job, 1, fx_ao_count(held, t));
                } else {
                    continue;
                }
                if (memcmp(fresh + (size_t)t * bytes, held + (size_t)t * bytes, bytes) != 0)
                    fail_msg("effect %s, block %016llx texel %u: the cache holds bytes its effect does not "
                             "compute "
                             "for that key",
                             name, (unsigned long long)key, t);
                compared++;
            }
        }
    }
    return compared;
}

/* The effect list of the thrashing cases: the built-in lookup, shadow, AO and probes, shadow and AO without
 * resampling (a resampled texel is the mean of finer ones no longer resident, which recompute_resident could
 * not rebuild; test_frame.c covers resampling). */
static fx_effect shadow_plain, ao_plain;
static const fx_effect *thrash_effects[4];

static void thrash_effects_init(void)
{
    shadow_plain = fx_effect_shadow;
    shadow_plain.resample = NULL;
    ao_plain = fx_effect_ao;
    ao_plain.resample = NULL;
    thrash_effects[0] = &fx_effect_triangle_lookup;
    thrash_effects[1] = &shadow_plain;
    thrash_effects[2] = &ao_plain;
    thrash_effects[3] = &fx_effect_probes;
}

typedef struct thrash_result {
    uint64_t rays, evictions, exhausted, missing, compared, dropped;
    uint32_t table_count, table_capacity, blocks;
} thrash_result;

/* Three viewers orbiting the embedded scene for 6 frames with a pool of pool_bytes; every frame checked and
 * every resident texel recomputed. */
static thrash_result thrash(uint64_t pool_bytes, bool probes)
{
    thrash_effects_init();
    scene_error err = {0};
    scene *s = scene_create_default(NULL, &err);
    assert_non_null(s);
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    assert_non_null(rt);
    srv_loop_desc d = {.s = s,
                       .rt = rt,
                       .seed = 13,
                       .pool_bytes = pool_bytes,
                       .effects = thrash_effects,
                       .effect_count = 4,
                       .threads = 2,
                       .probe_rays = 32,
                       .keep_views = true};
    d.effect_on[1] = d.effect_on[2] = true;
    d.effect_on[3] = probes;
    srv_viewer_id ids[3];
    srv_loop *loop = fxt_loop(&d, 3, 64, 36, ids);
    thrash_result r;
    memset(&r, 0, sizeof r);
    for (uint32_t frame = 0; frame < 6; frame++) {
        srv_camera cams[3];
        for (uint32_t v = 0; v < 3; v++)
            cams[v] = srv_camgen_camera(SRV_CAMGEN_ORBIT, s, v, 3, frame * 7, 13);
        srv_frame_stats st;
        stab_frames(loop, ids, 3, cams, false, 1, &st);
        r.compared += recompute_resident(loop);
        for (uint32_t e = 0; e < 4; e++)
            r.rays += st.rays[e];
        r.missing += st.pixels_missing;
        r.dropped += st.drops[SRV_DROP_POOL_EXHAUSTED];
        r.evictions = st.evictions;
        r.exhausted = st.exhausted;
        r.table_count = st.table_count;
        r.table_capacity = st.table_capacity;
        r.blocks = 0;
        for (uint32_t e = 0; e < 3; e++)
            r.blocks += (uint32_t)st.blocks_resident[e];
    }
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
    return r;
}

/* One viewer (32 x 18) orbiting the embedded scene through six views twice, with pools of 64 blocks per
 * effect (the smallest the engine makes) against 64 MiB, in lockstep, every texel converged in its first update (64 AO
 * samples): the six views need more blocks than the pools hold, so blocks are evicted and traced again when
 * their view comes back. Slower: more effect rays for the same frames. Never wrong: a frame whose blocks all
 * found room (no drop) is bit for bit the 64 MiB run's frame (every texel is a function of its key, so a block
 * traced again holds the same bytes), and every texel the small pools hold recomputes exactly. Then pools
 * far smaller than even one frame's blocks (three viewers): every frame drops blocks and leaves pixels
 * without data (counted, never silent), and what the pools do hold still recomputes exactly. */
static void test_pool_far_smaller_than_working_set(void **state)
{
    (void)state;
    scene_error err = {0};
    scene *s = scene_create_default(NULL, &err);
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    srv_loop *loops[2];
    srv_viewer_id ids[2];
    thrash_effects_init();
    for (int i = 0; i < 2; i++) {
        srv_loop_desc d = {.s = s,
                           .rt = rt,
                           .seed = 13,
                           .pool_bytes = i ? 1 : 64u << 20,
                           .threads = 2,
                           .samples_per_update = 64,
                           .effects = thrash_effects,
                           .effect_count = 3};
        d.effect_on[1] = d.effect_on[2] = true;
        loops[i] = fxt_loop(&d, 1, 32, 18, &ids[i]);
    }
    uint64_t rays[2] = {0, 0}, compared = 0;
    uint32_t same = 0, dropped_frames = 0;
    srv_frame_stats st[2];
    for (uint32_t frame = 0; frame < 12; frame++) {
        srv_camera cam = srv_camgen_camera(SRV_CAMGEN_ORBIT, s, 0, 1, (frame % 6) * 30, 13);
        for (int i = 0; i < 2; i++) {
            stab_frames(loops[i], &ids[i], 1, &cam, true, 1, &st[i]);
            for (uint32_t e = 0; e < 3; e++)
                rays[i] += st[i].rays[e];
        }
        compared += recompute_resident(loops[1]);
        if (st[1].drops[SRV_DROP_POOL_EXHAUSTED] == 0) {
            assert_memory_equal(srv_viewer_radiance(loops[0], ids[0]), srv_viewer_radiance(loops[1], ids[1]),
                                32 * 18 * 3 * sizeof(float));
            same++;
        } else {
            dropped_frames++;
        }
    }
    print_message(
        "six views twice, pools of 64 blocks: %llu effect rays (64 MiB: %llu), %llu evictions; %u frames "
        "without a drop, each bit for bit the 64 MiB frame, %u with drops; %llu resident texels "
        "recomputed, all identical\n",
        (unsigned long long)rays[1], (unsigned long long)rays[0], (unsigned long long)st[1].evictions, same,
        dropped_frames, (unsigned long long)compared);
    assert_true(rays[1] > rays[0]);
    assert_true(st[1].evictions > 0 && st[0].evictions == 0);
    assert_true(same >= 6);
    assert_true(compared > 500);
    for (int i = 0; i < 2; i++)
        srv_loop_free(loops[i]);
    scene_rt_free(rt);
    scene_free(s);

    thrash_result small = thrash(1, true), large = thrash(64u << 20, true);
    print_message(
        "three viewers, pools of 64 blocks: %llu evictions, %llu exhausted requests, %llu blocks dropped, "
        "%llu missing pixels (64 MiB: %llu); %llu resident texels recomputed (64 MiB: %llu), all "
        "identical\n",
        (unsigned long long)small.evictions, (unsigned long long)small.exhausted,
        (unsigned long long)small.dropped, (unsigned long long)small.missing,
        (unsigned long long)large.missing, (unsigned long long)small.compared,
        (unsigned long long)large.compared);
    assert_true(small.exhausted > 0 && small.evictions > 0 && small.dropped > 0 &&
                small.missing > large.missing);
    assert_int_equal(large.exhausted, 0);
    assert_true(small.compared > 1000 && large.compared > small.compared);
    assert_true(small.blocks <= 3 * 64);
}

/* The table at the highest load the engine gives it. The on-surface table has 150 % of all pools' blocks,
 * rounded up to a power of two (osc.h), so its load cannot pass 2/3 through the engine: the cache's refusals at
 * its 75 % maximum are reachable only through its own API, where tests/test_osc.c drives them against a
 * reference model. Pools of 113 blocks for lookup, shadow and AO put 339 blocks in a table of 512 slots; three
 * viewers thrashing them keep it between 55 and 66 % (housekeeping evicts ahead of the next frame), inserting
 * and deleting (backward shift) every frame. Every frame: every resident key is found at its own block (so no
 * key twice), the statistics' count is the resident blocks', the load is above half and at most 2/3, and
 * every texel recomputes exactly. */
static void test_table_at_load_limit(void **state)
{
    (void)state;
    const uint64_t blocks = 113, pool = blocks * 64 * (4 + 2 + 4);
    thrash_effects_init();
    scene_error err = {0};
    scene *s = scene_create_default(NULL, &err);
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    srv_loop_desc d = {.s = s,
                       .rt = rt,
                       .seed = 13,
                       .pool_bytes = pool,
                       .effects = thrash_effects,
                       .effect_count = 3,
                       .threads = 2};
    d.effect_on[1] = d.effect_on[2] = true;
    srv_viewer_id ids[3];
    srv_loop *loop = fxt_loop(&d, 3, 64, 36, ids);
    const srv_cache_kind *kind = loop->kinds[SCENE_CACHE_ON_SURFACE];
    void *cache = loop->caches[SCENE_CACHE_ON_SURFACE];
    uint64_t compared = 0;
    double peak = 0;
    for (uint32_t frame = 0; frame < 6; frame++) {
        srv_camera cams[3];
        for (uint32_t v = 0; v < 3; v++)
            cams[v] = srv_camgen_camera(SRV_CAMGEN_ORBIT, s, v, 3, frame * 7, 13);
        srv_frame_stats st;
        stab_frames(loop, ids, 3, cams, false, 1, &st);
        assert_int_equal(st.table_capacity, 512);
        uint32_t resident = 0;
        for (uint32_t e = 0; e < 3; e++) {
            assert_int_equal(kind->pool_capacity(cache, e), blocks);
            for (uint32_t b = 0; b < blocks; b++) {
                uint64_t key = kind->block_key(cache, e, b);
                if (key == UINT64_MAX)
                    continue;
                resident++;
                if (kind->find(cache, e, key) != b)
                    fail_msg("frame %u: key %016llx of block %u is found at block %u", frame,
                             (unsigned long long)key, b, kind->find(cache, e, key));
            }
        }
        assert_int_equal(resident, st.table_count);
        double load = (double)st.table_count / st.table_capacity;
        assert_true(load > 0.5 && load <= 2.0 / 3.0);
        peak = fmax(peak, load);
        compared += recompute_resident(loop);
        print_message("frame %u: table %u of %u slots (%.1f %%), %llu evictions so far\n", frame,
                      st.table_count, st.table_capacity, 100.0 * st.table_count / st.table_capacity,
                      (unsigned long long)st.evictions);
    }
    print_message("table: peak load %.1f %% of 512 slots (every pool full: %.1f %%)\n", 100 * peak,
                  100.0 * 3 * blocks / 512);
    assert_true(compared > 1000);
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- level bias -------------------------------------------------------------------------------------------- */

/* The largest biases: +15, INT32_MAX (every read at level 15, where an island is one texel), -15 and INT32_MIN
 * (level 0), for shadows, AO and probes (whose levels end at 14 and 0). On the open plane
 * every pixel is the closed form at every bias (one texel whose samples all meet the sky and the sun is exactly
 * 1); on the embedded scene every frame is checked and every resident block lies at the level the bias forces
 * (white-box), and no-cache gives the same image at any bias (it reads no cache). */
static void test_largest_level_bias(void **state)
{
    (void)state;
    const int32_t biases[] = {15, INT32_MAX, -15, INT32_MIN};
    scene_rt *rt;
    scene *plane = stab_open_plane((const float[3]){0.4f, -0.8f, 0.3f}, 2.0f, 1.0f, &rt);
    srv_camera cam = {
        .position = {0.2f, 3.3f, 1.9f}, .target = {0.2f, 0.3f, -3.3f}, .up = {0, 1, 0}, .fov_deg = 70};
    for (size_t i = 0; i < sizeof biases / sizeof biases[0]; i++) {
        srv_loop_desc d = {
            .s = plane, .rt = rt, .seed = 2, .keep_views = true, .samples_per_update = 64, .threads = 2};
        fxt_effects_on(&d, (const char *const[]){"shadow", "ao"}, 2);
        d.bias[SCENE_FX_SHADOW] = d.bias[SCENE_FX_AO] = biases[i];
        d.bias_set[SCENE_FX_SHADOW] = d.bias_set[SCENE_FX_AO] = true;
        srv_viewer_id id;
        srv_loop *loop = fxt_loop(&d, 1, 64, 36, &id);
        srv_frame_stats st;
        stab_frames(loop, &id, 1, &cam, true, 2, &st);
        stab_plane_result r = stab_check_open_plane(loop, id, &cam, (double)0.3f, 0.7, -0.4, 20.0, 20.0);
        print_message("open plane, bias %d: %llu pixels the closed form\n", biases[i],
                      (unsigned long long)r.plane_pixels);
        assert_true(r.plane_pixels > 1000);
        srv_loop_free(loop);
    }
    scene_rt_free(rt);
    scene_free(plane);

    scene_error err = {0};
    scene *s = scene_create_default(NULL, &err);
    rt = scene_rt_create(s, NULL, &err);
    cam = srv_camera_default(s);
    float *reference = NULL;
    for (size_t i = 0; i < sizeof biases / sizeof biases[0]; i++)
        for (int no_cache = 0; no_cache < 2; no_cache++) {
            int32_t probe_bias = biases[i]; /* the world-space levels end at 14 and 0 */
            srv_loop_desc d = {
                .s = s, .rt = rt, .seed = 2, .no_cache = no_cache, .threads = 2, .probe_rays = 32};
            fxt_effects_on(&d, (const char *const[]){"shadow", "ao", "probes"}, 3);
            d.bias[SCENE_FX_SHADOW] = d.bias[SCENE_FX_AO] = biases[i];
            d.bias[SCENE_FX_PROBES] = probe_bias;
            d.bias_set[SCENE_FX_SHADOW] = d.bias_set[SCENE_FX_AO] = d.bias_set[SCENE_FX_PROBES] = true;
            srv_viewer_id id;
            srv_loop *loop = fxt_loop(&d, 1, 48, 27, &id);
            srv_frame_stats st;
            stab_checked c = stab_frames(loop, &id, 1, &cam, true, no_cache ? 1 : 3, &st);
            if (no_cache) {
                float *rad = stab_copy_radiance(loop, id);
                if (!reference)
                    reference = rad;
                else {
                    assert_memory_equal(reference, rad, 48 * 27 * 3 * sizeof(float));
                    free(rad);
                }
                srv_loop_free(loop);
                continue;
            }
            uint32_t expected_level = biases[i] > 0 ? 15 : 0, wrong = 0, blocks = 0;
            for (uint32_t k = 0; k < SCENE_CACHE_COUNT; k++) {
                const srv_cache_kind *kind = loop->kinds[k];
                for (uint32_t e = 0; kind && e < loop->effect_count; e++) {
                    if (!loop->effect_cached[e] || loop->effect_kind[e] != k || e == SCENE_FX_TRIANGLE_LOOKUP)
                        continue;
                    for (uint32_t b = 0; b < kind->pool_capacity(loop->caches[k], e); b++) {
                        uint64_t key = kind->block_key(loop->caches[k], e, b);
                        if (key == UINT64_MAX)
                            continue;
                        fx_block_job job;
                        memset(&job, 0, sizeof job);
                        kind->job_location(loop->caches[k], e, key, &job);
                        uint32_t want = k == SCENE_CACHE_WORLD_SPACE ? (probe_bias > 0 ? WSC_MAX_LEVEL : 0)
                                                                     : expected_level;
                        wrong += job.level != want;
                        blocks++;
                    }
                }
            }
            print_message(
                "embedded scene, bias %d (probes %d): %llu AO and %llu shadow texels, %llu probes, %u "
                "blocks, %u at another level, %llu refused\n",
                biases[i], probe_bias, (unsigned long long)c.texels[SCENE_FX_AO],
                (unsigned long long)c.texels[SCENE_FX_SHADOW], (unsigned long long)c.texels[SCENE_FX_PROBES],
                blocks, wrong, (unsigned long long)st.world.refusals);
            assert_int_equal(wrong, 0);
            assert_true(c.texels[SCENE_FX_AO] > 0 && c.texels[SCENE_FX_PROBES] > 0);
            assert_int_equal(st.world.refusals, 0);
            srv_loop_free(loop);
        }
    free(reference);
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- world positions at and beyond the range ------------------------------------------------------------------ */

/* A wall facing +z whose height runs across the world-space grid's vertical limit, seen from 2.2 m (every
 * pixel 2 to 2.9 m away: at a finest cell of 1/16 m that is level 2, cells of 0.25 m, and no blending, which
 * starts at 3 m): the grid's y coordinate g must satisfy g + 1 <= 2^17 - 1 for a cell's upper corners (wsc.h),
 * so the last cell ends at (2^17 - 1) x 0.25 = 32767.75 m. A speck at the origin keeps the scene's frame at the
 * world origin (the grid is anchored there). Per pixel (the sharing view is 0 exactly where a pixel has no
 * probe taps): every pixel below 32767.75 m, up to the last representable cell, has its probes; every pixel
 * above has none, refused and counted (never wrapped onto cells at the other end, which would give it taps);
 * within 1 mm of the limit (float positions there are 4 mm apart) either. */
static void test_world_positions_at_and_beyond_range(void **state)
{
    (void)state;
    const double limit = (double)((1 << 17) - 1) * 0.25;
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "speck", (const double[3]){0, 0, 0}, (const double[3]){0, 0, 0.1},
                 (const double[3]){0.1, 0, 0}, 1);
    /* edge_a along +x, edge_b along +y: x cross y = +z */
    fxt_add_quad(s, "wall", (const double[3]){-1.5, limit - 1.25, 0}, (const double[3]){3, 0, 0},
                 (const double[3]){0, 2.5, 0}, 2);
    fxt_add_sun(s, 0.2f, -0.5f, -1.0f);
    s->sky_intensity = 1.0f;
    s->sky_color[0] = s->sky_color[1] = s->sky_color[2] = 1.0f;
    scene_rt *rt = fxt_finish_scene(s, 8.0f, 0.5f);
    assert_true(s->origin[1] == 0);
    assert_string_equal(s->precision_warning, "");
    srv_loop_desc d = {.s = s,
                       .rt = rt,
                       .seed = 3,
                       .threads = 2,
                       .probe_rays = 32,
                       .probe_cell = 1.0f / 16,
                       .keep_views = true};
    fxt_effects_on(&d, (const char *const[]){"probes"}, 1);
    srv_viewer_id id;
    srv_loop *loop = fxt_loop(&d, 1, 48, 48, &id);
    srv_camera cam = {
        .position = {0, (float)limit, 2.2f}, .target = {0, (float)limit, 0}, .up = {0, 1, 0}, .fov_deg = 60};
    srv_frame_stats st;
    stab_frames(loop, &id, 1, &cam, true, 2, &st);
    srv_camera_frame f;
    assert_true(srv_camera_setup(&cam, 48, 48, &f));
    const float *depth = srv_viewer_depth(loop, id), *share = srv_viewer_view(loop, id, SRV_VIEW_SHARING);
    uint32_t inside = 0, beyond = 0, either = 0;
    for (uint32_t y = 0; y < 48; y++)
        for (uint32_t x = 0; x < 48; x++) {
            size_t p = (size_t)y * 48 + x;
            assert_true(isfinite(depth[p]));
            assert_true(depth[p] > 2.0f && depth[p] < 3.0f);
            double q[3];
            stab_pixel_point(&f, x, y, depth[p], q);
            if (fabs(q[1] - limit) < 1e-3) {
                either++;
            } else if (q[1] < limit) {
                inside++;
                if (!(share[p] > 0))
                    fail_msg("pixel (%u, %u) at y %.6f, below the limit %.2f: no probe taps", x, y, q[1],
                             limit);
            } else {
                beyond++;
                if (share[p] != 0)
                    fail_msg("pixel (%u, %u) at y %.6f, beyond the limit %.2f: it has probe taps", x, y, q[1],
                             limit);
            }
        }
    print_message(
        "world-space range: %u pixels below the limit with their probes, %u beyond without, %u within "
        "1 mm; %llu points refused, %llu cells\n",
        inside, beyond, either, (unsigned long long)st.world.refusals,
        (unsigned long long)st.world.unique_cells);
    assert_true(inside > 500 && beyond > 500);
    assert_true(st.world.refusals > 0);
    srv_loop_free(loop);
    scene_rt_free(rt);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pool_far_smaller_than_working_set),
        cmocka_unit_test(test_table_at_load_limit),
        cmocka_unit_test(test_largest_level_bias),
        cmocka_unit_test(test_world_positions_at_and_beyond_range),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
