/* The probe tests' harness (fxt_probes.h). */
#include "fxt_probes.h"

#include "fxt_scene.h"
#include "test_util.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void fxt_grid_init(fxt_grid *g, const scene *s, const float origin[3], float cell, uint32_t nx, uint32_t ny,
                   uint32_t nz)
{
    memset(g, 0, sizeof *g);
    memcpy(g->origin, origin, sizeof g->origin);
    g->cell = cell;
    g->n[0] = nx, g->n[1] = ny, g->n[2] = nz;
    g->count = nx * ny * nz;
    assert_int_equal(fx_effect_probes.texel_bytes(s), FX_PROBE_BYTES);
    g->scratch_bytes = fx_effect_probes.scratch_bytes(s);
    g->payload = calloc(g->count, FX_PROBE_BYTES);
    g->scratch = calloc(g->count, g->scratch_bytes);
    g->jobs = calloc(g->count, sizeof *g->jobs);
    assert_true(g->payload && g->scratch && g->jobs);
    for (uint32_t z = 0; z < nz; z++)
        for (uint32_t y = 0; y < ny; y++)
            for (uint32_t x = 0; x < nx; x++) {
                uint32_t i = (z * ny + y) * nx + x;
                fx_block_job *job = &g->jobs[i];
                job->key = 0x7000000000000000ull | ((uint64_t)z << 40) | ((uint64_t)y << 20) | x;
                job->mask = 1;
                job->effect = FX_PROBES; /* the registry's index, as the engine's loop gives it */
                job->payload = g->payload + (size_t)i * FX_PROBE_BYTES;
                job->scratch = g->scratch + (size_t)i * g->scratch_bytes;
                job->cell = cell;
                job->origin[0] = origin[0] + cell * (float)x;
                job->origin[1] = origin[1] + cell * (float)y;
                job->origin[2] = origin[2] + cell * (float)z;
            }
}

void fxt_grid_free(fxt_grid *g)
{
    free(g->payload);
    free(g->scratch);
    free(g->jobs);
}

/* The payload of the grid probe at corner c (bit k: + 1 cell along axis k) of the cell whose lowest grid
 * point is base, if it is inside the grid and holds committed data; else NULL. */
static const uint8_t *grid_corner(const fxt_grid *g, const int base[3], int c)
{
    int at[3];
    for (int k = 0; k < 3; k++) {
        at[k] = base[k] + ((c >> k) & 1);
        if (at[k] < 0 || at[k] >= (int)g->n[k])
            return NULL;
    }
    const uint8_t *p =
        g->payload +
        (size_t)(((uint32_t)at[2] * g->n[1] + (uint32_t)at[1]) * g->n[0] + (uint32_t)at[0]) * FX_PROBE_BYTES;
    fx_probe_info info;
    fx_probe_info_read(p, &info);
    return (info.flags & FX_PROBE_HAS_DATA) ? p : NULL;
}

/* The grid of `level`: g or one of its coarser grids, NULL when none has it. */
static const fxt_grid *grid_of_level(const fxt_grid *g, uint32_t level)
{
    while (g && g->level != level)
        g = g->coarser;
    return g;
}

/* world_taps over the grid: corners of the cell around pos with committed data, trilinear weights. */
static uint32_t grid_taps(const void *user, uint32_t effect, const float pos[3], uint32_t level,
                          fx_taps *taps)
{
    const fxt_grid *g = grid_of_level(user, level);
    assert_int_equal(effect, FX_PROBES);
    taps->count = 0;
    if (!g)
        return 0;
    int base[3];
    float frac[3];
    for (int k = 0; k < 3; k++) {
        float f = (pos[k] - g->origin[k]) / g->cell;
        base[k] = (int)floorf(f);
        frac[k] = f - (float)base[k];
    }
    for (int c = 0; c < 8; c++) {
        const uint8_t *p = grid_corner(g, base, c);
        if (!p)
            continue;
        float w = 1;
        for (int k = 0; k < 3; k++)
            w *= ((c >> k) & 1) ? frac[k] : 1.0f - frac[k];
        taps->texel[taps->count] = p;
        taps->weight[taps->count] = w;
        taps->count++;
    }
    return taps->count;
}

/* world_cell over the grid: the 8 corners of the cell around centre that hold committed data, NULL elsewhere
 * (corner c at the cell's lowest grid point + (c & 1, c >> 1 & 1, c >> 2 & 1) cells). */
static bool grid_cell(const void *user, uint32_t effect, uint32_t level, const float centre[3],
                      const void *texel[8])
{
    const fxt_grid *g = grid_of_level(user, level);
    assert_int_equal(effect, FX_PROBES);
    for (int c = 0; c < 8; c++)
        texel[c] = NULL;
    if (!g)
        return true;
    int base[3];
    for (int k = 0; k < 3; k++)
        base[k] = (int)floorf((centre[k] - g->origin[k]) / g->cell);
    for (int c = 0; c < 8; c++)
        texel[c] = grid_corner(g, base, c);
    return true;
}

/* The engine's context over the grid: update hits read whole cells (world_cell), compose reads taps. */
fx_context fxt_grid_context(const scene *s, scene_rt *rt, const fxt_grid *g, float hysteresis)
{
    return (fx_context){.s = s,
                        .rt = rt,
                        .seed = 1234,
                        .ao_radius = 1,
                        .world_taps = grid_taps,
                        .world_cell = grid_cell,
                        .world_user = g,
                        .probe_rays = FX_PROBE_RAYS,
                        .probe_hysteresis = hysteresis};
}

/* One frame: every probe updated (one call), then committed. Returns the rays traced. */
uint64_t fxt_grid_frame(fxt_grid *g, const fx_context *ctx)
{
    uint64_t rays = fx_effect_probes.update(ctx, g->jobs, g->count, 0);
    fx_effect_probes.commit(ctx, g->jobs, g->count);
    return rays;
}

/* The indirect term shade adds at a point (E / pi) and what it leaves of sky visibility (sky may be NULL),
 * with the context ctx (NULL: none). */
void fxt_grid_shade_ctx(const fx_context *ctx, const fxt_grid *g, const float pos[3], const float normal[3],
                        float indirect[3], float *sky)
{
    fx_taps taps;
    memset(&taps, 0, sizeof taps);
    grid_taps(g, FX_PROBES, pos, g->level, &taps);
    fx_point point;
    memset(&point, 0, sizeof point);
    memcpy(point.position, pos, sizeof point.position);
    float len = sqrtf(fx__dot(normal, normal));
    for (int k = 0; k < 3; k++)
        point.normal[k] = point.view_normal[k] = normal[k] / len;
    float visibility = 1, sky_visibility = 1;
    indirect[0] = indirect[1] = indirect[2] = 0;
    fx_shade_run run = {.count = 1,
                        .light_count = 0,
                        .taps = &taps,
                        .points = &point,
                        .light_visibility = &visibility,
                        .sky_visibility = &sky_visibility,
                        .indirect = indirect};
    fx_effect_probes.shade(ctx, &run);
    if (sky)
        *sky = sky_visibility;
}

void fxt_grid_shade_at(const fxt_grid *g, const float pos[3], const float normal[3], float indirect[3],
                       float *sky)
{
    fxt_grid_shade_ctx(NULL, g, pos, normal, indirect, sky);
}

void fxt_add_point_light(scene *s, float x, float y, float z, float intensity)
{
    scene_light light = {
        .type = SCENE_LIGHT_POINT, .position = {x, y, z}, .color = {1, 1, 1}, .intensity = intensity};
    scene_error err;
    assert_int_equal(scene__add_light(s, &light, "test lamp", &err), SCENE_OK);
}

float fxt_random_unit(uint64_t *state)
{
    *state = fx__mix64(*state + 0x9e3779b97f4a7c15ull);
    return (float)(*state >> 40) / 16777216.0f;
}

/* The thin-wall scene: a lit room x in [-2, w] with a point light at (-1.2, 1, 0), a wall 0.1 thick, and a
 * dark room beyond it to x = 2.1 (both rooms 2 high, z in [-1, 1], 4 x 4 quads a face). */
scene_rt *fxt_thin_wall_scene(double w, scene **out)
{
    scene *s = fxt_new_scene();
    fxt_add_box(s, "lit", (double[3]){-2, 0, -1}, (double[3]){w, 2, 1}, true, 4);
    fxt_add_box(s, "dark", (double[3]){w + 0.1, 0, -1}, (double[3]){2.1, 2, 1}, true, 4);
    fxt_add_point_light(s, -1.2f, 1.0f, 0.0f, 1.0f);
    *out = s;
    return fxt_finish_scene(s, 4.0f, 1.0f);
}
