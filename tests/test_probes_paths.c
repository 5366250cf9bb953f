/* The probe effect (effects/fx_probes.c, fx_probes_hits.c) against itself run another way, through the
 * harness of fxt_probes.h: threads splitting the probes any way give the same bytes; the shading lanes match
 * the per-point filter; cell reads match the taps; the per-thread memos give the same results across loops;
 * the batched bounce at hits matches one hit at a time; half reads with denormals-are-zero keep their values.
 * The closed-form checks are in test_probes.c. */
#include "test_util.h"

#include "fxt_probes.h"
#include "fxt_scene.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- 5. determinism
 * ---------------------------------------------------------------------------------------- */

typedef struct split_task {
    const fx_context *ctx;
    fx_block_job *jobs;
    const uint32_t *order;
    uint32_t count, chunk, thread, threads;
    bool commit;
} split_task;

/* Runs chunks thread, thread + threads, ... of the permuted job list (each chunk copied in `order`). */
/* A level-1 grid (cell `cell`, 3 x 1 x 3 probes from (-cell, cell, -cell), anchored at the origin) whose probes
 * are committed over 3 frames: what a level-0 grid's hits with no probe of their own read
 * (hit_bounce_coarser). */
static void coarse_grid_commit(fxt_grid *coarse, const scene *s, scene_rt *rt, float cell)
{
    fxt_grid_init(coarse, s, (float[3]){-cell, cell, -cell}, cell, 3, 1, 3);
    coarse->level = 1;
    for (uint32_t i = 0; i < coarse->count; i++)
        coarse->jobs[i].level = 1;
    fx_context ctx = fxt_grid_context(s, rt, coarse, 0.9f);
    for (int f = 0; f < 3; f++)
        fxt_grid_frame(coarse, &ctx);
}

static void *split_worker(void *arg)
{
    split_task *t = arg;
    scene_tracing_thread_init();
    fx_block_job chunk[16];
    for (uint32_t first = t->thread * t->chunk; first < t->count; first += t->threads * t->chunk) {
        uint32_t n = t->count - first < t->chunk ? t->count - first : t->chunk;
        for (uint32_t i = 0; i < n; i++)
            chunk[i] = t->jobs[t->order[first + i]];
        if (t->commit)
            fx_effect_probes.commit(t->ctx, chunk, n);
        else
            fx_effect_probes.update(t->ctx, chunk, n, 0);
    }
    return NULL;
}

static void split_frame(fxt_grid *g, const fx_context *ctx, const uint32_t *order, uint32_t chunk,
                        uint32_t threads)
{
    for (int phase = 0; phase < 2; phase++) {
        pthread_t tid[4];
        split_task tasks[4];
        for (uint32_t t = 0; t < threads; t++) {
            tasks[t] = (split_task){.ctx = ctx,
                                    .jobs = g->jobs,
                                    .order = order,
                                    .count = g->count,
                                    .chunk = chunk,
                                    .thread = t,
                                    .threads = threads,
                                    .commit = phase == 1};
            assert_int_equal(pthread_create(&tid[t], NULL, split_worker, &tasks[t]), 0);
        }
        for (uint32_t t = 0; t < threads; t++)
            pthread_join(tid[t], NULL);
    }
}

/* The payload bytes after 4 frames are identical for one call in order, chunks of 7 in reverse order on 2
 * threads, and chunks of 3 in a shuffled order on 3 threads (the thin-wall scene: hits, shadow rays,
 * relocation and bounces through world_taps all run). */
static void test_thread_split_determinism(void **state)
{
    (void)state;
    scene *s;
    scene_rt *rt = fxt_thin_wall_scene(0.35, &s);
    uint8_t *reference = NULL;
    for (int variant = 0; variant < 3; variant++) {
        fxt_grid g;
        fxt_grid_init(&g, s, (float[3]){-1.5f, 0.5f, -0.5f}, 1.0f, 4, 2, 2);
        fx_context ctx = fxt_grid_context(s, rt, &g, 0.0f);
        uint32_t order[16];
        for (uint32_t i = 0; i < g.count; i++)
            order[i] = variant == 1 ? g.count - 1 - i : (variant == 2 ? (i * 5 + 3) % g.count : i);
        for (int f = 0; f < 4; f++) {
            if (variant == 0)
                fxt_grid_frame(&g, &ctx);
            else
                split_frame(&g, &ctx, order, variant == 1 ? 7 : 3, variant == 1 ? 2 : 3);
        }
        if (variant == 0) {
            reference = malloc((size_t)g.count * FX_PROBE_BYTES);
            memcpy(reference, g.payload, (size_t)g.count * FX_PROBE_BYTES);
        } else {
            assert_memory_equal(reference, g.payload, (size_t)g.count * FX_PROBE_BYTES);
        }
        fxt_grid_free(&g);
    }
    free(reference);
    scene_rt_free(rt);
    scene_free(s);
}

/* compose's shade against the filter read the plain way (fx__probe_filter_memo without a context:
 * probe_weight and fx_probe_irradiance per probe, no lanes): random payloads (positions around the point,
 * data or not, off or not, random halves for irradiance and moments, so the Chebyshev bound, the octahedral
 * wrap at every edge and the crush of small weights all occur), random points, normals and tap counts (1 to
 * 16: a partial group of lanes and two levels' taps), one pixel a run, so the group's weights are taken at
 * the pixel itself. The two sum in different orders (the filter renormalises, shade divides once by the
 * total), hence a relative tolerance of 1e-5 (a few float roundings); a wrong texel, weight or lane would be
 * off by far more. */
static uint16_t random_half(uint64_t *rng, uint32_t exponent_lo, uint32_t exponent_hi)
{
    *rng = fx__mix64(*rng + 0x9e3779b97f4a7c15ull);
    uint32_t exponent = exponent_lo + (uint32_t)(*rng >> 32) % (exponent_hi - exponent_lo + 1);
    return (uint16_t)(exponent << 10 | (uint32_t)(*rng & 0x3ffu));
}

static void test_shade_lanes_match_filter(void **state)
{
    (void)state;
    enum { PROBES = 16, TRIALS = 4000 };
    static uint8_t payload[PROBES][FX_PROBE_BYTES];
    uint64_t rng = 0x5eed1e55u;
    uint32_t compared = 0, lit = 0;
    double worst = 0;
    for (uint32_t trial = 0; trial < TRIALS; trial++) {
        float point[3], normal[3];
        for (int k = 0; k < 3; k++)
            point[k] = (float)fxt_random_unit(&rng) * 2.0f - 1.0f;
        do {
            for (int k = 0; k < 3; k++)
                normal[k] = (float)fxt_random_unit(&rng) * 2.0f - 1.0f;
        } while (fx__dot(normal, normal) < 0.01f);
        float len = sqrtf(fx__dot(normal, normal));
        for (int k = 0; k < 3; k++)
            normal[k] /= len;
        if (trial % 7 == 0) /* axis normals: the octahedron's corners and edges */
            for (int k = 0; k < 3; k++)
                normal[k] = k == (int)(trial / 7 % 3) ? (trial % 2 ? -1.0f : 1.0f) : 0.0f;
        fx_taps taps;
        memset(&taps, 0, sizeof taps);
        taps.count = 1 + (uint32_t)(fxt_random_unit(&rng) * PROBES) % PROBES;
        for (uint32_t t = 0; t < taps.count; t++) {
            uint8_t *p = payload[t];
            memset(p, 0, FX_PROBE_BYTES);
            float cell = trial % 3 == 0 ? 0.25f : 1.0f;
            for (int k = 0; k < 3; k++) {
                float at = point[k] + ((float)fxt_random_unit(&rng) * 2.0f - 1.0f) * cell;
                memcpy(p + 4 * k, &at, 4);
            }
            uint32_t roll = (uint32_t)(fxt_random_unit(&rng) * 10) % 10;
            uint32_t flags =
                roll == 0 ? 0u : (roll == 1 ? FX_PROBE_HAS_DATA | FX_PROBE_OFF : FX_PROBE_HAS_DATA);
            float scale = (float)fxt_random_unit(&rng) * 4.0f;
            memcpy(p + 12, &cell, 4);
            memcpy(p + 16, &flags, 4); /* little-endian hosts only, as the rest of this file */
            memcpy(p + 24, &scale, 4);
            for (uint32_t i = 0; i < FX_PROBE_TEXELS * 3; i++)
                fx__put_u16(p + PROBE_IRRADIANCE + 2 * i, random_half(&rng, 1, 15)); /* 2^-14 .. 2 */
            for (uint32_t i = 0; i < FX_PROBE_TEXELS; i++) {
                fx__put_u16(p + PROBE_MOMENTS + 4 * i, random_half(&rng, 11, 16)); /* mean: 1/16 .. 4 cells */
                fx__put_u16(p + PROBE_MOMENTS + 4 * i + 2, random_half(&rng, 8, 18)); /* mean squared */
            }
            taps.texel[t] = p;
            taps.weight[t] = (float)fxt_random_unit(&rng) + 1e-3f;
        }
        float expected[3];
        bool any = fx__probe_filter_memo(NULL, true, &taps, point, normal, expected);
        fx_point pt;
        memset(&pt, 0, sizeof pt);
        memcpy(pt.position, point, sizeof pt.position);
        memcpy(pt.normal, normal, sizeof pt.normal);
        memcpy(pt.view_normal, normal, sizeof pt.view_normal);
        float indirect[3] = {0, 0, 0}, visibility = 1, sky = 1;
        fx_shade_run run = {.count = 1,
                            .taps = &taps,
                            .points = &pt,
                            .light_visibility = &visibility,
                            .sky_visibility = &sky,
                            .indirect = indirect};
        fx_effect_probes.shade(NULL, &run);
        if (!any) { /* no probe with data: shade adds nothing and leaves the sky */
            assert_true(indirect[0] == 0 && indirect[1] == 0 && indirect[2] == 0);
            assert_true(sky == 1.0f);
            continue;
        }
        compared++;
        for (int k = 0; k < 3; k++) {
            double want = (double)expected[k] / (double)FXT_PI_F, got = indirect[k];
            double error = fabs(got - want) / fmax(fabs(want), 1e-30);
            if (want > 0)
                lit++;
            if (error > worst)
                worst = error;
            if (!(error <= 1e-5))
                printf("trial %u channel %d: shade %.9g, filter %.9g\n", trial, k, got, want);
            assert_true(error <= 1e-5);
        }
    }
    printf("shade against the filter: %u points compared (%u channels lit), worst relative error %.3g\n",
           compared, lit, worst);
    assert_true(compared > TRIALS / 2);
}

/* Update hits read the probes around them through world_cell (a cell's corners kept per thread) or, without
 * it, through world_taps per hit: the same filter, so after 6 frames of the thin-wall scene (bounces between
 * the probes of both rooms, a wall between them, probes switched off inside the wall) the maps agree. The
 * trilinear weights differ in rounding only (the harness's taps are computed in float, world_cell's in
 * double) and stochastic rounding to half may then round a texel the other way: within 3 units in the last
 * place of a half (2^-11 relative each) of the probe's brightest texel, per texel. A grid of level 1 is
 * resident, read at hits whose cell of level 0 holds no probe, through either path. */
static void test_cell_reads_match_taps(void **state)
{
    (void)state;
    scene *s;
    scene_rt *rt = fxt_thin_wall_scene(0.35, &s);
    fxt_grid a, b;
    fxt_grid_init(&a, s, (float[3]){-1.5f, 0.5f, -0.5f}, 1.0f, 4, 2, 2);
    fxt_grid_init(&b, s, (float[3]){-1.5f, 0.5f, -0.5f}, 1.0f, 4, 2, 2);
    fxt_grid coarse; /* level 1, read by both at hits with no probe of level 0 (hit_bounce_coarser) */
    coarse_grid_commit(&coarse, s, rt, 2.0f);
    a.coarser = b.coarser = &coarse;
    fx_context cells = fxt_grid_context(s, rt, &a, 0.9f), taps = fxt_grid_context(s, rt, &b, 0.9f);
    taps.world_cell = NULL;
    for (int f = 0; f < 6; f++) {
        fxt_grid_frame(&a, &cells);
        fxt_grid_frame(&b, &taps);
    }
    uint32_t lit = 0;
    for (uint32_t i = 0; i < a.count; i++) {
        const uint8_t *pa = a.payload + (size_t)i * FX_PROBE_BYTES,
                      *pb = b.payload + (size_t)i * FX_PROBE_BYTES;
        fx_probe_info ia, ib;
        fx_probe_info_read(pa, &ia);
        fx_probe_info_read(pb, &ib);
        assert_int_equal(ia.flags, ib.flags);
        assert_memory_equal(ia.position, ib.position, sizeof ia.position);
        if (ia.flags & FX_PROBE_OFF)
            continue;
        float scale_a, scale_b, brightest = 0, worst = 0;
        memcpy(&scale_a, pa + 24, sizeof scale_a);
        memcpy(&scale_b, pb + 24, sizeof scale_b);
        for (uint32_t t = 0; t < FX_PROBE_TEXELS; t++) {
            float dir[3], ea[3], eb[3];
            float uv[2] = {((float)(t % 8) + 0.5f) * 0.25f - 1.0f, ((float)(t / 8) + 0.5f) * 0.25f - 1.0f};
            fx_probe_oct_decode(uv, dir);
            fx_probe_irradiance(pa, dir, ea);
            fx_probe_irradiance(pb, dir, eb);
            for (int k = 0; k < 3; k++) {
                brightest = fmaxf(brightest, eb[k]);
                worst = fmaxf(worst, fabsf(ea[k] - eb[k]));
            }
        }
        lit += brightest > 0;
        assert_true(fabsf(scale_a - scale_b) <= 4.0f / 2048.0f * scale_b);
        assert_true(worst <= 3.0f / 2048.0f * brightest);
    }
    assert_true(lit >= 8); /* the comparison saw light: most of the 16 probes are on and lit */
    fxt_grid_free(&coarse);
    fxt_grid_free(&a);
    fxt_grid_free(&b);
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- 6. per-thread memos across loops
 * ---------------------------------------------------------------------- The per-thread memos (the irradiance
 * memo of fx_probes_map.c, the update's cell memo) keep pointers into payloads. A loop freed and a new one
 * whose payloads sit at the same addresses, run for the same frame numbers, must not read the first loop's
 * values (BENCHMARKS, "a latent bug the memo exposed": stab_light's 2^k linearity failed in 6 of 10 runs).
 * Deterministic here: both loops use one payload buffer (the same addresses by construction), the thin-wall
 * scene with a light 1 then 3 times as bright, 4 frames each with frame numbers 1..4, hits read through
 * world_taps (the irradiance memo) or world_cell, compose's shade read with the context after the last frame
 * (the memo again). The second loop's payload bytes and shaded values must equal those of the same loop run
 * alone in a fresh thread (fresh memos: what a fresh process computes), bit for bit; with epochs 0 (a harness
 * that gives none) and with unique epochs. */
typedef struct memo_sequence {
    fxt_grid *g;
    scene *s;
    scene_rt *rt;
    const float *intensity; /* per loop */
    const uint64_t *epoch;  /* per loop */
    uint32_t loops;
    bool cells;         /* hits through world_cell (else world_taps) */
    uint8_t *payload;   /* out: the last loop's payload bytes */
    float shaded[4][3]; /* out: the last loop's shade at 4 points */
} memo_sequence;

static void *memo_sequence_run(void *arg)
{
    memo_sequence *m = arg;
    scene_tracing_thread_init();
    static const float points[4][3] = {
        {0.35f, 1.0f, 0.1f}, {-1.0f, 0.0f, 0.2f}, {1.0f, 2.0f, -0.3f}, {-0.5f, 1.0f, -1.0f}};
    /* Tilted normals (no wall's): the updates' hits never ask for them, so only shade writes their memo
     * entries, once per loop, at the last frame: the second loop's read finds what the first loop left. */
    static const float normals[4][3] = {{-0.8f, 0.6f, 0}, {0, 0.6f, 0.8f}, {0.6f, -0.8f, 0}, {0.8f, 0, 0.6f}};
    for (uint32_t l = 0; l < m->loops; l++) {
        m->s->lights[0].intensity = m->intensity[l];
        memset(m->g->payload, 0, (size_t)m->g->count * FX_PROBE_BYTES);
        memset(m->g->scratch, 0, (size_t)m->g->count * m->g->scratch_bytes);
        fx_context ctx = fxt_grid_context(m->s, m->rt, m->g, 0.9f);
        if (!m->cells)
            ctx.world_cell = NULL;
        ctx.epoch = m->epoch[l];
        for (uint32_t f = 1; f <= 4; f++) {
            ctx.frame = f;
            fxt_grid_frame(m->g, &ctx);
        }
        for (int p = 0; p < 4; p++)
            fxt_grid_shade_ctx(&ctx, m->g, points[p], normals[p], m->shaded[p], NULL);
    }
    memcpy(m->payload, m->g->payload, (size_t)m->g->count * FX_PROBE_BYTES);
    return NULL;
}

static void test_memo_across_loops(void **state)
{
    (void)state;
    scene *s;
    scene_rt *rt = fxt_thin_wall_scene(0.35, &s);
    fxt_grid g;
    fxt_grid_init(&g, s, (float[3]){-1.5f, 0.5f, -0.5f}, 1.0f, 4, 2, 2);
    size_t bytes = (size_t)g.count * FX_PROBE_BYTES;
    static const float one[1] = {3.0f}, two[2] = {1.0f, 3.0f};
    static const uint64_t no_epoch[2] = {0, 0}, epochs[2] = {101, 102};
    for (int variant = 0; variant < 4; variant++) {
        bool cells = variant & 1;
        const uint64_t *epoch = variant & 2 ? epochs : no_epoch;
        memo_sequence fresh = {.g = &g,
                               .s = s,
                               .rt = rt,
                               .intensity = one,
                               .epoch = epoch + 1,
                               .loops = 1,
                               .cells = cells,
                               .payload = malloc(bytes)};
        memo_sequence again = {.g = &g,
                               .s = s,
                               .rt = rt,
                               .intensity = two,
                               .epoch = epoch,
                               .loops = 2,
                               .cells = cells,
                               .payload = malloc(bytes)};
        assert_true(fresh.payload && again.payload);
        pthread_t tid;
        assert_int_equal(pthread_create(&tid, NULL, memo_sequence_run, &fresh), 0);
        pthread_join(tid, NULL);
        assert_int_equal(pthread_create(&tid, NULL, memo_sequence_run, &again), 0);
        pthread_join(tid, NULL);
        uint32_t differ = 0;
        for (size_t i = 0; i < bytes; i++)
            differ += fresh.payload[i] != again.payload[i];
        printf("memo across loops (%s, %s): %u payload bytes differ, shade %.6g against %.6g\n",
               cells ? "world_cell" : "world_taps", epoch[0] ? "unique epochs" : "epoch 0", differ,
               (double)again.shaded[0][0], (double)fresh.shaded[0][0]);
        assert_true(fresh.shaded[0][0] > 0); /* the lit wall sees light */
        assert_int_equal(differ, 0);
        assert_memory_equal(fresh.shaded, again.shaded, sizeof fresh.shaded);
        free(fresh.payload);
        free(again.payload);
    }
    fxt_grid_free(&g);
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- 7. the batched bounce at hits against one hit at a time ---------------------------------------------
 * The update shades a chunk's front-face hits in passes (fx_probes_hits.c, hit_batch) or, with
 * fx__probe_hits_batched false, one at a time (hit_bounce): the same operations moved in time, so the
 * payloads must agree bit for bit after frames of bounces (every float of the irradiance and moments, the
 * positions, flags). With the memo's 2048 entries, and with 2 and 8 (fx__probe_memo_log2, fresh threads: the
 * memo is allocated at a thread's first update), where a later hit's fill replaces entries that hits waiting
 * for the last pass read (the pass must run first); the room corners' cells see three normals (a slot
 * replaced while read); 144 rays and 200 (a chunk of 128 and one of 72). Two scenes: the thin-wall rooms (a
 * point light) and an open court under a sky with a sun and a point light (the directional light's direction
 * taken once per update against fx__light_arriving per hit); the rooms also with a cell of 0.7 (no exact
 * inverse: hit_locate divides). A grid of level 1 is resident too, which the hits in cells with no probe of
 * the update's level read. */
typedef struct batch_run {
    fxt_grid *g;
    scene *s;
    scene_rt *rt;
    uint32_t rays;
    uint8_t *payload; /* out */
} batch_run;

static void *batch_run_thread(void *arg)
{
    batch_run *b = arg;
    scene_tracing_thread_init();
    memset(b->g->payload, 0, (size_t)b->g->count * FX_PROBE_BYTES);
    memset(b->g->scratch, 0, (size_t)b->g->count * b->g->scratch_bytes);
    fx_context ctx = fxt_grid_context(b->s, b->rt, b->g, 0.9f);
    ctx.probe_rays = b->rays;
    ctx.epoch = 7;
    for (uint32_t f = 1; f <= 5; f++) {
        ctx.frame = f;
        fxt_grid_frame(b->g, &ctx);
    }
    memcpy(b->payload, b->g->payload, (size_t)b->g->count * FX_PROBE_BYTES);
    return NULL;
}

/* A floor (y = 0, x and z in [-2, 2.5]) and two walls (x = -2, z = -1), open above: a sky, a sun, a lamp. */
static scene_rt *open_court_scene(scene **out)
{
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "floor", (double[3]){-2, 0, -2}, (double[3]){0, 0, 4.5}, (double[3]){4.5, 0, 0}, 4);
    fxt_add_quad(s, "wall_x", (double[3]){-2, 0, -2}, (double[3]){0, 2, 0}, (double[3]){0, 0, 4.5}, 4);
    fxt_add_quad(s, "wall_z", (double[3]){-2, 0, -1}, (double[3]){4.5, 0, 0}, (double[3]){0, 2, 0}, 4);
    fxt_add_sun(s, 0.3f, -1.0f, 0.4f);
    fxt_add_point_light(s, 0.5f, 1.2f, 0.3f, 0.5f);
    s->sky_color[0] = 0.2f, s->sky_color[1] = 0.4f, s->sky_color[2] = 0.8f;
    s->sky_intensity = 0.5f;
    *out = s;
    return fxt_finish_scene(s, 4.0f, 1.0f);
}

static void test_batched_hits_match_single(void **state)
{
    (void)state;
    for (int setup = 0; setup < 3; setup++) {
        const int court = setup == 1;
        const float cell = setup == 2 ? 0.7f : 1.0f;
        scene *s;
        scene_rt *rt = court ? open_court_scene(&s) : fxt_thin_wall_scene(0.35, &s);
        fxt_grid g, coarse;
        fxt_grid_init(&g, s, (float[3]){-1.5f, 0.5f, -0.5f}, cell, 4, 2, 2);
        /* Probes of level 1 (cell x 2, on the grid anchored at the origin), committed first and then kept:
         * the hits in g's cells with no probe read them (hit_bounce_coarser; in the batched path after
         * pass 3, through the same memo) */
        coarse_grid_commit(&coarse, s, rt, 2 * cell);
        size_t bytes = (size_t)g.count * FX_PROBE_BYTES;
        static const uint32_t memo_log2[3] = {11, 3, 1}, rays[2] = {FX_PROBE_RAYS, 200};
        uint8_t *single = malloc(bytes), *batched = malloc(bytes);
        assert_true(single && batched);
        batch_run alone = {.g = &g, .s = s, .rt = rt, .rays = FX_PROBE_RAYS, .payload = malloc(bytes)};
        assert_non_null(alone.payload);
        pthread_t alone_tid; /* without the coarse probes: the payloads differ (they are read) */
        assert_int_equal(pthread_create(&alone_tid, NULL, batch_run_thread, &alone), 0);
        pthread_join(alone_tid, NULL);
        g.coarser = &coarse;
        for (int v = 0; v < 6; v++) {
            batch_run run = {.g = &g, .s = s, .rt = rt, .rays = rays[v % 2]};
            fx__probe_memo_log2 = memo_log2[v / 2];
            pthread_t tid;
            fx__probe_hits_batched = false;
            run.payload = single;
            assert_int_equal(pthread_create(&tid, NULL, batch_run_thread, &run), 0);
            pthread_join(tid, NULL);
            fx__probe_hits_batched = true;
            run.payload = batched;
            assert_int_equal(pthread_create(&tid, NULL, batch_run_thread, &run), 0);
            pthread_join(tid, NULL);
            uint32_t differ = 0, lit = 0;
            for (size_t i = 0; i < bytes; i++)
                differ += single[i] != batched[i];
            for (uint32_t i = 0; i < g.count; i++) {
                float scale;
                memcpy(&scale, single + (size_t)i * FX_PROBE_BYTES + 24, sizeof scale);
                lit += scale > 0;
            }
            printf("batched hits, %s, cell %.1f, memo 2^%u, %u rays: %u payload bytes differ, %u of %u "
                   "probes lit\n",
                   court ? "open court" : "thin wall", (double)cell, memo_log2[v / 2], rays[v % 2], differ,
                   lit, g.count);
            assert_int_equal(differ, 0);
            assert_true(lit >= 8);
            if (v == 0) {
                uint32_t coarse_read = 0;
                for (size_t i = 0; i < bytes; i++)
                    coarse_read += alone.payload[i] != batched[i];
                printf("  without the coarse probes: %u payload bytes differ\n", coarse_read);
                assert_true(coarse_read > 0);
            }
        }
        free(alone.payload);
        fxt_grid_free(&coarse);
        fx__probe_memo_log2 = 11;
        free(single);
        free(batched);
        fxt_grid_free(&g);
        scene_rt_free(rt);
        scene_free(s);
    }
}

/* half_bits_to_float, the vectorisable reader of the stored halves, against half_to_float for every finite
 * half >= 0, on a thread set up as the pool's are (denormals-are-zero, flush-to-zero): the subnormal halves
 * (texels below 2^-14 of their probe's scale) must keep their value, not read as 0. */
static void test_half_bits_daz(void **state)
{
    (void)state;
    scene_tracing_thread_init();
    uint32_t subnormal_nonzero = 0;
    for (uint32_t h = 0; h <= 0x7bffu; h++) {
        float a = half_bits_to_float(h), b = half_to_float((uint16_t)h);
        uint32_t abits, bbits;
        memcpy(&abits, &a, sizeof abits);
        memcpy(&bbits, &b, sizeof bbits);
        if (abits != bbits)
            fail_msg("half 0x%04x: %a against half_to_float's %a", h, (double)a, (double)b);
        subnormal_nonzero += h > 0 && h < 0x400u && a > 0;
    }
    assert_int_equal(subnormal_nonzero, 0x3ffu);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_thread_split_determinism),
        cmocka_unit_test(test_cell_reads_match_taps),
        cmocka_unit_test(test_shade_lanes_match_filter),
        cmocka_unit_test(test_memo_across_loops),
        cmocka_unit_test(test_half_bits_daz),
        cmocka_unit_test(test_batched_hits_match_single),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
