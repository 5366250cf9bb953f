/* The probe effect (effects/fx_probes.c) against closed forms, through a small harness of its own: a grid of
 * probe payloads at one level, a world_taps over them (the engine's contract: the 8 corners of the cell
 * around a point that hold committed data, trilinear weights), and frames of "update every probe, then
 * commit every probe", as the engine runs them. Scenes are built in code (fxt_scene.h). */
#include "test_util.h"

#include "fxt_probes.h"
#include "fxt_scene.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- the octahedral map and the ray set ------------------------------------------------------------ */

/* A float in [0, 1] to a half, rounded to nearest: a second implementation, for writing test maps. */
static uint16_t test_half(float x)
{
    if (x == 0)
        return 0;
    int e;
    float m = frexpf(x, &e); /* x = m 2^e, m in [0.5, 1) */
    if (e - 1 < -14)
        return (uint16_t)lrintf(x * 16777216.0f);
    uint32_t mant = (uint32_t)lrintf((m * 2.0f - 1.0f) * 1024.0f);
    uint32_t exp = (uint32_t)(e - 1 + 15);
    if (mant == 1024)
        mant = 0, exp++;
    return (uint16_t)((exp << 10) | mant);
}

static void random_direction(uint64_t *state, float d[3])
{
    float z = 2.0f * fxt_random_unit(state) - 1.0f, phi = 2.0f * FXT_PI_F * fxt_random_unit(state);
    float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
    d[0] = r * cosf(phi), d[1] = r * sinf(phi), d[2] = z;
}

/* Encode then decode returns the direction; the map read bilinearly across its folded edges gives a smooth
 * function of direction back (a wrong wrap would mix opposite directions there, errors near 1). */
static void test_octahedral_map(void **state)
{
    (void)state;
    uint64_t rng = 1;
    for (int i = 0; i < 20000; i++) {
        float d[3], uv[2], back[3];
        random_direction(&rng, d);
        if (i < 6) { /* the axes, fold lines included */
            memset(d, 0, sizeof d);
            d[i / 2] = (i & 1) ? -1.0f : 1.0f;
        }
        fx_probe_oct_encode(d, uv);
        assert_true(uv[0] >= -1 && uv[0] <= 1 && uv[1] >= -1 && uv[1] <= 1);
        fx_probe_oct_decode(uv, back);
        for (int k = 0; k < 3; k++)
            assert_true(fabsf(back[k] - d[k]) < 2e-6f);
    }
    /* A payload whose texels hold f(d) = (1 + d.a) / 2 at their centre directions. */
    uint8_t payload[FX_PROBE_BYTES];
    memset(payload, 0, sizeof payload);
    const float a[3] = {0.48f, -0.6f, 0.64f};
    float one = 1.0f;
    uint32_t bits;
    memcpy(&bits, &one, sizeof bits);
    for (int k = 0; k < 4; k++)
        payload[24 + k] = (uint8_t)(bits >> (8 * k)); /* irradiance scale 1 */
    for (uint32_t t = 0; t < 64; t++) {
        float uv[2] = {((float)(t % 8) + 0.5f) / 4.0f - 1.0f, ((float)(t / 8) + 0.5f) / 4.0f - 1.0f}, d[3];
        fx_probe_oct_decode(uv, d);
        uint16_t h = test_half((1.0f + fx__dot(d, a)) * 0.5f);
        for (int k = 0; k < 3; k++)
            fx__put_u16(payload + 32 + 6 * t + 2 * k, h);
    }
    float worst = 0, mean = 0;
    for (int i = 0; i < 20000; i++) {
        float d[3], e[3];
        random_direction(&rng, d);
        fx_probe_irradiance(payload, d, e);
        float err = fabsf(e[0] - (1.0f + fx__dot(d, a)) * 0.5f);
        worst = fmaxf(worst, err);
        mean += err / 20000;
    }
    /* Bilinear over 8 x 8 texels of a unit-slope function: errors of a few hundredths at most. */
    printf("octahedral map: worst %.4f mean %.4f\n", (double)worst, (double)mean);
    assert_true(worst < 0.08f);
    assert_true(mean < 0.015f);
}

/* The spherical Fibonacci set is uniform: mean direction near 0, and the cosine-weighted integral of a
 * constant, (4 pi / n) sum max(0, n.d_i), is pi for any normal. */
static void test_fibonacci_uniform(void **state)
{
    (void)state;
    const uint32_t n = FX_PROBE_RAYS;
    float mean[3] = {0, 0, 0};
    for (uint32_t i = 0; i < n; i++) {
        float d[3];
        fx_probe_fibonacci(i, n, d);
        assert_true(fabsf(fx__dot(d, d) - 1.0f) < 1e-5f);
        for (int k = 0; k < 3; k++)
            mean[k] += d[k] / (float)n;
    }
    assert_true(sqrtf(fx__dot(mean, mean)) < 0.01f);
    uint64_t rng = 7;
    for (int j = 0; j < 200; j++) {
        float normal[3], sum = 0;
        random_direction(&rng, normal);
        for (uint32_t i = 0; i < n; i++) {
            float d[3];
            fx_probe_fibonacci(i, n, d);
            sum += fmaxf(0.0f, fx__dot(normal, d));
        }
        /* 144 points: the quadrature of a cosine lobe is within 1.5 % (3 % for a random set). */
        assert_true(fabsf(4.0f * FXT_PI_F / (float)n * sum - FXT_PI_F) < 0.015f * FXT_PI_F);
    }
}

/* ---- 1. open sky ------------------------------------------------------------------------------------- */

/* Under an open uniform sky of radiance L with nothing around, shade gives irradiance pi L whatever the
 * normal (it adds E / pi = L, what compose's sky term would give) and takes the sky term out; the no-cache
 * estimate agrees. */
static void open_sky_at(float intensity)
{
    scene *s = fxt_new_scene();
    /* A quad of 1 mm at the origin (the scene needs geometry; at the origin the local frame is the world's),
     * the probes 80 m away: it subtends 1e-10 sr from them. */
    fxt_add_quad(s, "speck", (double[3]){-0.0005, 0, -0.0005}, (double[3]){0, 0, 0.001},
                 (double[3]){0.001, 0, 0}, 1);
    s->sky_color[0] = 0.2f, s->sky_color[1] = 0.4f, s->sky_color[2] = 0.8f;
    s->sky_intensity = intensity;
    scene_rt *rt = fxt_finish_scene(s, 4.0f, 1.0f);
    fxt_grid g;
    assert_true(s->origin[0] == 0 && s->origin[1] == 0 && s->origin[2] == 0);
    fxt_grid_init(&g, s, (float[3]){79, 79, 79}, 2.0f, 2, 2, 2);
    fx_context ctx = fxt_grid_context(s, rt, &g, 0.0f);
    assert_int_equal(fxt_grid_frame(&g, &ctx), 8 * FX_PROBE_RAYS); /* no hit, no shadow ray */
    for (uint32_t i = 0; i < g.count; i++) {
        fx_probe_info info;
        fx_probe_info_read(g.jobs[i].payload, &info);
        assert_int_equal(info.flags, FX_PROBE_HAS_DATA);
        assert_int_equal(info.updates, 1);
    }
    uint64_t rng = 3;
    for (int j = 0; j < 40; j++) {
        float normal[3], pos[3], indirect[3], sky;
        random_direction(&rng, normal);
        if (j < 6) {
            memset(normal, 0, sizeof normal);
            normal[j / 2] = (j & 1) ? -1.0f : 1.0f;
        }
        for (int k = 0; k < 3; k++)
            pos[k] = 79.0f + 2.0f * fxt_random_unit(&rng);
        fxt_grid_shade_at(&g, pos, normal, indirect, &sky);
        for (int k = 0; k < 3; k++) {
            float L = s->sky_color[k] * s->sky_intensity;
            if (!(fabsf(FXT_PI_F * indirect[k] - FXT_PI_F * L) < 2e-3f * FXT_PI_F * L))
                printf("open sky: normal %g %g %g channel %d: %g vs %g\n", (double)normal[0],
                       (double)normal[1], (double)normal[2], k, (double)indirect[k], (double)L);
            /* pi x indirect is the irradiance; half rounding (stochastic: under 2 units of 2^-11) only. */
            assert_true(fabsf(FXT_PI_F * indirect[k] - FXT_PI_F * L) < 2e-3f * FXT_PI_F * L);
        }
        assert_true(sky == 0.0f);
    }
    /* The no-cache estimate from a point on the speck, facing up: every ray escapes. */
    float e[3];
    uint64_t rays = 0;
    fx_probe_eval_point(&ctx, (float[3]){0, 0, 0}, (float[3]){0, 1, 0}, 99, e, &rays);
    assert_int_equal(rays, FX_PROBE_RAYS);
    for (int k = 0; k < 3; k++)
        assert_true(fabsf(e[k] - FXT_PI_F * s->sky_color[k] * s->sky_intensity) < 1e-4f);
    fxt_grid_free(&g);
    scene_rt_free(rt);
    scene_free(s);
}

static void test_open_sky(void **state)
{
    (void)state;
    const float intensities[] = {1.5f, 1e5f, 1e-6f, 1e30f, 1e-30f};
    for (size_t i = 0; i < sizeof intensities / sizeof intensities[0]; i++) {
        printf("open sky at intensity %g\n", (double)intensities[i]);
        open_sky_at(intensities[i]);
    }
}

/* ---- 2. inside a sphere ---------------------------------------------------------------------------------
 */

/* The mean and worst relative error of shade's indirect term against `expected` at 24 wall points. */
static void sphere_wall_error(const fxt_grid *g, float expected, float *mean_error, float *worst_error,
                              float *mean)
{
    uint64_t rng = 11;
    *mean_error = *worst_error = *mean = 0;
    for (int j = 0; j < 24; j++) {
        float d[3], pos[3], normal[3], indirect[3];
        random_direction(&rng, d);
        for (int k = 0; k < 3; k++)
            pos[k] = 0.999f * d[k], normal[k] = -d[k];
        fxt_grid_shade_at(g, pos, normal, indirect, NULL);
        float error = (indirect[0] - expected) / expected;
        *mean_error += error / 24;
        *mean += indirect[0] / 24;
        *worst_error = fmaxf(*worst_error, fabsf(error));
    }
}

/* Inside a closed diffuse sphere of albedo 0.5 lit by a point light at its centre (E0 = I / R^2 on the wall,
 * in compose's units), wall radiance is uniform and E = E0 + rho E: the indirect term at the wall goes to
 * E0 rho / (1 - rho) = E0. With hysteresis h, the probes' indirect I follows I_k+1 = h I_k + (1 - h) rho (E0
 * + I_k): the error shrinks by h + (1 - h) rho per frame.
 *   - h = 0.5: 0.75 per frame, 30 frames leave 1e-4: the fixed point itself is checked, within 2 % at every
 *     wall point (mean 1 %): the facets sag 0.05 % from the sphere, 144 rays quadrature a nearly uniform
 *     field almost exactly; what is left is the Chebyshev and wrap weighting of probes outside the sphere
 *     (switched off) and the probes' half rounding.
 *   - h = 0.97 (the default), from probes holding 0 when the light goes on: I_k = E0 (1 - 0.985^k), 0.596 E0
 *     after 60 frames; checked within 1.5 % (the same errors, plus the noise of the blend's stochastic
 *     rounding and the ray set's rotation, which no longer average out over 30 frames of fast blending).
 * Both with plain hysteresis (fx_context.probe_plain_blend), whose closed form this is; the change-aware
 * blend (the default) reaches the fixed point within 1 % in 11 frames here: tests/test_probes_converge.c. */
static void test_sphere_converges(void **state)
{
    (void)state;
    scene *s = fxt_new_scene(); /* albedo 0.5 */
    fxt_add_sphere(s, 1.0f, 4); /* 5,120 facets */
    fxt_add_point_light(s, 0, 0, 0, 1.0f);
    scene_rt *rt = fxt_finish_scene(s, 4.0f, 1.0f);
    const float expected = 1.0f; /* E0 rho / (1 - rho) with E0 = 1, rho = 0.5 */
    for (int run = 0; run < 2; run++) {
        float h = run == 0 ? 0.5f : 0.97f;
        int frames = run == 0 ? 30 : 60;
        fxt_grid g;
        fxt_grid_init(&g, s, (float[3]){-1.1f, -1.1f, -1.1f}, 0.55f, 5, 5, 5);
        fx_context ctx = fxt_grid_context(s, rt, &g, h);
        ctx.probe_plain_blend = true;
        /* h = 0.97: three dark frames first, so every probe has settled (switched off, relocated, on again)
         * and holds 0; then the light goes on and every probe blends from there. */
        if (run == 1) {
            s->lights[0].intensity = 0.0f;
            for (int f = 0; f < 3; f++)
                fxt_grid_frame(&g, &ctx);
            s->lights[0].intensity = 1.0f;
        }
        for (int f = 0; f < frames; f++)
            fxt_grid_frame(&g, &ctx);
        uint32_t off = 0, on_outside = 0;
        for (uint32_t i = 0; i < g.count; i++) {
            fx_probe_info info;
            fx_probe_info_read(g.jobs[i].payload, &info);
            bool inside = sqrtf(fx__dot(g.jobs[i].origin, g.jobs[i].origin)) < 1.0f;
            if (info.flags & FX_PROBE_OFF) {
                off++;
                assert_false(inside);
            } else if (!inside) {
                on_outside++;
            }
        }
        float mean_error, worst_error, mean;
        sphere_wall_error(&g, expected, &mean_error, &worst_error, &mean);
        float target = run == 0 ? expected : expected * (1.0f - powf(0.985f, (float)frames));
        printf(
            "sphere h=%.2f: %u probes off, %u outside on; indirect mean %.4f (closed form %.4f), worst error "
            "vs the fixed point %.4f\n",
            (double)h, off, on_outside, (double)mean, (double)target, (double)worst_error);
        assert_true(off > 0);
        if (run == 0) {
            assert_true(fabsf(mean_error) < 0.01f);
            assert_true(worst_error < 0.02f);
        } else {
            assert_true(fabsf(mean - target) < 0.015f * target);
        }
        fxt_grid_free(&g);
    }
    scene_rt_free(rt);
    scene_free(s);
}

/* The stiff sphere: albedo 0.99, E0 = 1 (a 1,280-facet sphere: its facets sag 0.2 %, so E0 is 0.4 % more on
 * average). The indirect term at the wall goes to E0 rho / (1 - rho) = 99 E0, 99 times the direct light, and
 * with hysteresis h follows I_k = 99 E0 (1 - r^k), r = h + (1 - h) rho, one bounce more each frame. With h
 * near 0, r = rho = 0.99: 69.4 % of the fixed point after 120 frames, 99 % after 459 (measured over 1,000
 * frames: within 0.5 % of 99 from frame 500 on, no overshoot beyond it, every value finite). With the default
 * h = 0.97, r = 0.9997: 1 % of the way per 33 frames, so 15,000 frames to 99 % (docs/ARCHITECTURE.md, probes).
 * Checked: the curve at frames 30, 60, 120 within 1.5 % (the facets' 0.4 %, the ray set's quadrature, the
 * halves' rounding), and finite, for a probe grid of 3 x 3 x 3 (the centre probe inside). */
static void test_sphere_stiff(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    for (int k = 0; k < 3; k++)
        s->materials[0].diffuse[k] = 0.99f;
    fxt_add_sphere(s, 1.0f, 3);
    fxt_add_point_light(s, 0, 0, 0, 1.0f);
    scene_rt *rt = fxt_finish_scene(s, 4.0f, 1.0f);
    fxt_grid g;
    fxt_grid_init(&g, s, (float[3]){-1.1f, -1.1f, -1.1f}, 1.1f, 3, 3, 3);
    fx_context ctx = fxt_grid_context(s, rt, &g, 1e-6f);
    for (int f = 1; f <= 120; f++) {
        fxt_grid_frame(&g, &ctx);
        if (f % 30 != 0 || f == 90)
            continue;
        float expected = 99.0f * (1.0f - powf(0.99f, (float)f));
        float mean_error, worst_error, mean;
        sphere_wall_error(&g, expected, &mean_error, &worst_error, &mean);
        printf("stiff sphere frame %d: indirect mean %.4f (closed form %.4f), worst error %.4f\n", f,
               (double)mean, (double)expected, (double)worst_error);
        assert_true(isfinite(mean) && isfinite(worst_error));
        assert_true(fabsf(mean_error) < 0.015f);
        assert_true(worst_error < 0.03f);
    }
    fxt_grid_free(&g);
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- 3. hysteresis step response ------------------------------------------------------------------------
 */

/* A large floor (albedo 0.5) under a sun straight down of intensity 2: floor radiance L = 1 in compose's
 * units, a black sky. A point between the probes with a normal at angle theta from straight down sees the
 * lit half-space: E / pi = L (1 + cos theta) / 2; the normal is a texel centre of the map, so no bilinear
 * mixing of directions blurs it. The probes first hold 0 (dark frames), then the sun goes on: with plain
 * hysteresis h = 0.97 and a stationary estimate the value is V (1 - h^k) after k frames, within 5 % of V
 * after ceil(ln 0.05 / ln 0.97) = 99 frames; then the sun goes off and it decays as V h^k, under 5 % after 99
 * frames. Checked every frame against the closed form within 1.5 % of V (quadrature of the horizon by 144
 * rotated rays, half rounding, the floor's own up-facing probes giving it 1 % more light than a true floor
 * would get), and no overshoot beyond 1.5 % of V. Plain hysteresis (fx_context.probe_plain_blend), whose
 * closed form this is; the change-aware blend's step response: tests/test_probes_converge.c. */
static void test_step_response(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "floor", (double[3]){-100, 0, -100}, (double[3]){0, 0, 200}, (double[3]){200, 0, 0}, 4);
    fxt_add_sun(s, 0, -1, 0);
    scene_rt *rt = fxt_finish_scene(s, 0.05f, 1.0f);
    assert_true(s->origin[1] == 0);
    s->lights[0].intensity = 0.0f;
    fxt_grid g;
    fxt_grid_init(&g, s, (float[3]){-1, 0.5f, -1}, 1.0f, 3, 2, 3);
    fx_context ctx = fxt_grid_context(s, rt, &g, 0.0f); /* 0: the default, 0.97 */
    ctx.probe_plain_blend = true;
    /* Texel (3, 0)'s centre, uv (-0.125, -0.875), on the fold line z = 0: almost straight down. */
    float uv[2] = {3.5f / 4.0f - 1.0f, 0.5f / 4.0f - 1.0f}, normal[3];
    fx_probe_oct_decode(uv, normal);
    assert_true(normal[1] < -0.98f);
    const float point[3] = {0.2f, 1.0f, -0.3f};
    float V = 1.0f * (1.0f - normal[1]) * 0.5f; /* L (1 + cos theta), cos theta = -n.y */
    for (int f = 0; f < 3; f++)
        fxt_grid_frame(&g, &ctx);
    float indirect[3];
    fxt_grid_shade_at(&g, point, normal, indirect, NULL);
    assert_true(indirect[0] == 0.0f);
    s->lights[0].intensity = 2.0f;
    const float h = FX_PROBE_HYSTERESIS;
    int settle = (int)ceilf(logf(0.05f) / logf(h));
    assert_int_equal(settle, 99);
    float worst = 0, peak = 0, end = 0;
    for (int k = 1; k <= 130; k++) {
        fxt_grid_frame(&g, &ctx);
        fxt_grid_shade_at(&g, point, normal, indirect, NULL);
        float expected = V * (1.0f - powf(h, (float)k));
        worst = fmaxf(worst, fabsf(indirect[0] - expected) / V);
        peak = fmaxf(peak, indirect[0] / V);
        if (k == settle)
            assert_true(indirect[0] > 0.95f * V * (1.0f - 0.015f));
        end = indirect[0];
    }
    printf("step on: V %.4f, worst deviation %.4f V, peak %.4f V\n", (double)V, (double)worst, (double)peak);
    assert_true(worst < 0.015f);
    assert_true(peak < 1.015f);
    s->lights[0].intensity = 0.0f;
    worst = 0;
    for (int k = 1; k <= settle; k++) {
        fxt_grid_frame(&g, &ctx);
        fxt_grid_shade_at(&g, point, normal, indirect, NULL);
        worst = fmaxf(worst, fabsf(indirect[0] - end * powf(h, (float)k)) / V);
        assert_true(indirect[0] >= 0.0f);
    }
    printf("step off: worst deviation %.4f V, after %d frames %.4f V\n", (double)worst, settle,
           (double)(indirect[0] / V));
    assert_true(worst < 0.015f);
    assert_true(indirect[0] < 0.05f * V + 0.015f * V);
    fxt_grid_free(&g);
    scene_rt_free(rt);
    scene_free(s);
}

/* ---- 4. leaks
 * ---------------------------------------------------------------------------------------------- */

/* A probe inside a closed box is switched off and stays off (the box reaches 0.6 cell from it, beyond the
 * 0.45 cell relocation); a probe 0.1 cell inside a small box walks out through the nearest face and is on
 * again; probes outside are on and not moved beyond their 45 %. */
static void test_probe_inside_box(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    fxt_add_box(s, "solid", (double[3]){-0.6, -0.6, -0.6}, (double[3]){0.6, 0.6, 0.6}, false, 2);
    fxt_add_box(s, "small", (double[3]){9.6, -0.3, -0.3}, (double[3]){10.1, 0.3, 0.3}, false, 2);
    scene_rt *rt = fxt_finish_scene(s, 4.0f, 1.0f);
    assert_true(s->origin[0] == 0 && s->origin[1] == 0 && s->origin[2] == 0);
    s->sky_color[0] = s->sky_color[1] = s->sky_color[2] = 1.0f;
    s->sky_intensity = 1.0f;
    for (int which = 0; which < 2; which++) {
        fxt_grid g;
        fxt_grid_init(&g, s, (float[3]){which ? 9.0f : -1.0f, -1, -1}, 1.0f, 3, 3, 3);
        fx_context ctx = fxt_grid_context(s, rt, &g, 0.0f);
        for (int f = 0; f < 4; f++)
            fxt_grid_frame(&g, &ctx);
        for (uint32_t i = 0; i < g.count; i++) {
            fx_probe_info info;
            fx_probe_info_read(g.jobs[i].payload, &info);
            for (int k = 0; k < 3; k++)
                assert_true(fabsf(info.position[k] - g.jobs[i].origin[k]) <= 0.45f * g.cell * 1.0001f);
            if (i == 13) { /* the centre */
                if (which == 0) {
                    assert_true(info.flags & FX_PROBE_OFF);
                    assert_true(info.backface_fraction > 0.99f);
                } else {
                    assert_false(info.flags & FX_PROBE_OFF);
                    assert_true(info.position[0] > 10.1f + 0.1f); /* out through x = 10.1 */
                }
            } else {
                assert_false(info.flags & FX_PROBE_OFF);
            }
        }
        fxt_grid_free(&g);
    }
    scene_rt_free(rt);
    scene_free(s);
}

/* Two closed rooms sharing a wall a tenth of a cell thick; a point light in one. The dark room gets no light
 * at all, so whatever shade gives a point in it is leaked. Points on the wall's dark face and on the dark
 * floor beside it, against the mirrored points in the lit room, for walls at three places between the probe
 * planes (mid-way, and 0.05 cell from either probe plane: probes there are relocated). DDGI's Chebyshev
 * test with its cubed weight and crushing keeps the leak under 2 % of the lit side (measured: at most 0.8 %,
 * on the floor beside a wall 0.05 cell from the lit probes' plane; 0.05 % on the wall itself). With the
 * update's own filter at hits (fx_probes.c, "The bounce at hits": the moments' nearest texel, the plane test)
 * 0.86 % and 0.05 % (0.77 % and 0.04 % with shade's filter at hits too; without Chebyshev at hits 2.3 %, and
 * with the plane test alone 3.4 %, both failing this bound). */

static void test_thin_wall_leak(void **state)
{
    (void)state;
    const float offsets[3] = {-0.05f, 0.35f,
                              -0.45f}; /* the wall is [w, w + 0.1], probe planes at -0.5, 0.5 */
    for (int c = 0; c < 3; c++) {
        double w = offsets[c];
        scene *s;
        scene_rt *rt = fxt_thin_wall_scene(w, &s);
        fxt_grid g;
        fxt_grid_init(&g, s, (float[3]){-1.5f, 0.5f, -0.5f}, 1.0f, 4, 2, 2);
        fx_context ctx = fxt_grid_context(s, rt, &g, 0.0f);
        for (int f = 0; f < 24; f++)
            fxt_grid_frame(&g, &ctx);
        float wf = (float)w, lit_wall[3], dark_wall[3], lit_floor[3], dark_floor[3];
        fxt_grid_shade_at(&g, (float[3]){wf, 1.0f, 0.1f}, (float[3]){-1, 0, 0}, lit_wall, NULL);
        fxt_grid_shade_at(&g, (float[3]){wf + 0.1f, 1.0f, 0.1f}, (float[3]){1, 0, 0}, dark_wall, NULL);
        fxt_grid_shade_at(&g, (float[3]){wf - 0.1f, 0.0f, 0.1f}, (float[3]){0, 1, 0}, lit_floor, NULL);
        fxt_grid_shade_at(&g, (float[3]){wf + 0.2f, 0.0f, 0.1f}, (float[3]){0, 1, 0}, dark_floor, NULL);
        printf("thin wall at %.2f: wall lit %.4f dark %.5f, floor lit %.4f dark %.5f\n", w,
               (double)lit_wall[0], (double)dark_wall[0], (double)lit_floor[0], (double)dark_floor[0]);
        assert_true(lit_wall[0] > 0.01f && lit_floor[0] > 0.01f);
        assert_true(dark_wall[0] < 0.02f * lit_wall[0]);
        assert_true(dark_floor[0] < 0.02f * lit_floor[0]);
        fxt_grid_free(&g);
        scene_rt_free(rt);
        scene_free(s);
    }
}

/* A single-sided wall (1 m high, facing +x, a floor in front only) and probes behind and above its top edge,
 * one by one at 0.1 m steps, for three seeds. A probe behind the wall is off (it sees the wall's back within
 * its reach and no front face), moves out through the wall if the 0.45-cell clamp lets it get clear, and
 * must then stay where it settles: after 8 updates none switches on or off again. Before the relocation's
 * two departures (fx_probes.c, "Relocation") probes here walked back round the edge towards their grid
 * point and were off again (a restart from one update's rays every few updates), or stopped on the wall's
 * plane and were on or off with the rays' rotation (39 changes of state after update 8 in these 150 runs,
 * none moved out for good). A probe that once saw a front face within reach from where it stands stays on
 * (FX_PROBE_SEEN_FRONT): whether one of its rotated rays finds a sliver of floor over the wall's top was
 * the rest of the flicker. Measured: 87 runs moved out, 36 off at the end, no change after update 8. */
static void test_wall_edge_stable(void **state)
{
    (void)state;
    scene *s = fxt_new_scene();
    fxt_add_quad(s, "wall", (double[3]){0, 0, -2}, (double[3]){0, 1, 0}, (double[3]){0, 0, 4}, 4);
    fxt_add_quad(s, "floor", (double[3]){0, 0, -2}, (double[3]){0, 0, 4}, (double[3]){3, 0, 0}, 4);
    scene_rt *rt = fxt_finish_scene(s, 4.0f, 1.0f);
    s->sky_color[0] = s->sky_color[1] = s->sky_color[2] = 1.0f;
    s->sky_intensity = 1.0f;
    uint32_t changes = 0, moved_out = 0, off = 0;
    for (uint64_t seed = 1; seed <= 3; seed++)
        for (int yi = 0; yi < 10; yi++)
            for (int xi = 0; xi < 5; xi++) {
                float x = -0.05f - 0.1f * (float)xi, y = 0.55f + 0.1f * (float)yi;
                fxt_grid g;
                fxt_grid_init(&g, s, (float[3]){x, y, 0.0f}, 1.0f, 1, 1, 1);
                fx_context ctx = fxt_grid_context(s, rt, &g, 0.0f);
                ctx.seed = seed;
                uint32_t last = 0;
                fx_probe_info info;
                for (int f = 0; f < 24; f++) {
                    fxt_grid_frame(&g, &ctx);
                    fx_probe_info_read(g.jobs[0].payload, &info);
                    uint32_t now = info.flags & FX_PROBE_OFF;
                    if (f > 8 && now != last) {
                        printf("probe at (%.2f, %.2f), seed %u: %s at update %d\n", (double)x, (double)y,
                               (unsigned)seed, now ? "off" : "on", f);
                        changes++;
                    }
                    last = now;
                }
                moved_out += (info.flags & FX_PROBE_MOVED_OUT) != 0;
                off += (info.flags & FX_PROBE_OFF) != 0;
                if (info.flags & FX_PROBE_MOVED_OUT) /* out in front of the wall, clear of it */
                    assert_true(info.position[0] > 0.05f);
                fxt_grid_free(&g);
            }
    printf("wall edge: %u probe runs moved out, %u off at the end, %u changes after update 8\n", moved_out,
           off, changes);
    assert_int_equal(changes, 0);
    assert_true(moved_out >= 70 && off >= 25); /* both outcomes occur */
    scene_rt_free(rt);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_octahedral_map),   cmocka_unit_test(test_fibonacci_uniform),
        cmocka_unit_test(test_open_sky),         cmocka_unit_test(test_sphere_converges),
        cmocka_unit_test(test_sphere_stiff),     cmocka_unit_test(test_step_response),
        cmocka_unit_test(test_probe_inside_box), cmocka_unit_test(test_thin_wall_leak),
        cmocka_unit_test(test_wall_edge_stable),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
