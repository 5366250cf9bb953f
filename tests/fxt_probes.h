/* The probe tests' harness (tests/test_probes*.c): a grid of probe payloads at one level and the engine's
 * contract over it (world_taps: the 8 corners of the cell around a point that hold committed data, trilinear
 * weights; world_cell: a whole cell for the update's hits), frames of "update every probe, then commit every
 * probe" as the engine runs them, and the scenes built in code the tests share (fxt_scene.h). */
#ifndef FXT_PROBES_H
#define FXT_PROBES_H

#include "fx_internal.h"
#include "fx_probes_internal.h"
#include "scene_internal.h"

#include <stdbool.h>
#include <stdint.h>

#define FXT_PI_F 3.14159265358979f

/* A grid of nx x ny x nz probes at origin + cell * (x, y, z), one level: each probe's payload, scratch and
 * block job (keyed by its grid position). `coarser` (NULL unless a test sets it): a grid of another level
 * that world_cell and world_taps also answer for (its level in its `level`, its origin a multiple of its cell:
 * the update reads coarser levels on the world cache's grid, anchored at the origin); other levels hold no
 * probes. */
typedef struct fxt_grid {
    float origin[3], cell;
    uint32_t n[3], count, level, scratch_bytes;
    uint8_t *payload, *scratch;
    fx_block_job *jobs;
    const struct fxt_grid *coarser;
} fxt_grid;

void fxt_grid_init(fxt_grid *g, const scene *s, const float origin[3], float cell, uint32_t nx, uint32_t ny,
                   uint32_t nz);

/* Frees what fxt_grid_init allocated. */
void fxt_grid_free(fxt_grid *g);

/* The engine's context over the grid: update hits read whole cells (world_cell), compose reads taps. */
fx_context fxt_grid_context(const scene *s, scene_rt *rt, const fxt_grid *g, float hysteresis);

/* One frame: every probe updated (one call), then committed. Returns the rays traced. */
uint64_t fxt_grid_frame(fxt_grid *g, const fx_context *ctx);

/* The indirect term shade adds at a point (E / pi) and what it leaves of sky visibility (sky may be NULL),
 * with the context ctx (NULL: none). */
void fxt_grid_shade_ctx(const fx_context *ctx, const fxt_grid *g, const float pos[3], const float normal[3],
                        float indirect[3], float *sky);

/* fxt_grid_shade_ctx with no context. */
void fxt_grid_shade_at(const fxt_grid *g, const float pos[3], const float normal[3], float indirect[3],
                       float *sky);

/* A white point light of the given intensity. */
void fxt_add_point_light(scene *s, float x, float y, float z, float intensity);

/* fxt_add_sphere (an icosphere, normals inward): fxt_scene.h, shared with test_world.c. */

/* A uniform float in [0, 1) from a splitmix step of *state. */
float fxt_random_unit(uint64_t *state);

/* The thin-wall scene: a lit room x in [-2, w] with a point light at (-1.2, 1, 0), a wall 0.1 thick, and a
 * dark room beyond it to x = 2.1 (both rooms 2 high, z in [-1, 1], 4 x 4 quads a face). */
scene_rt *fxt_thin_wall_scene(double w, scene **out);

#endif
