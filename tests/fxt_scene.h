/* Scenes built by hand for the effect tests (test_effects.c, test_crease.c): quads, suns, islands, and every
 * block of an island run through an effect. White-box: uses the scene builder's internals. */
#ifndef FXC_FXT_SCENE_H
#define FXC_FXT_SCENE_H

#include "effects.h"
#include "scene.h"

#include <stdint.h>

/* Every block of one island at one level, with its lookup and payload storage and one job per block. */
typedef struct fxt_island_run {
    uint32_t island, level, blocks_x, blocks_y, block_count, texel_bytes;
    uint32_t *lookup;   /* block_count * 64 */
    uint8_t *payload;   /* block_count * 64 * texel_bytes */
    fx_block_job *jobs; /* block_count */
    uint64_t texels;    /* texels in all masks */
} fxt_island_run;

/* A new scene with one grey material. */
scene *fxt_new_scene(void);

/* Adds a parallelogram corner, corner + edge_a, corner + edge_a + edge_b, corner + edge_b as one mesh of
 * cells x cells quads (two triangles each); its normal is edge_a x edge_b. */
void fxt_add_quad(scene *s, const char *name, const double corner[3], const double edge_a[3],
                  const double edge_b[3], uint32_t cells);

/* Adds face (axis, side) of the axis-aligned box [lo, hi] (side 0 at lo[axis], 1 at hi[axis]) as a quad of
 * cells x cells named name, facing out of the box, or into it when inward. */
void fxt_add_box_face(scene *s, const char *name, const double lo[3], const double hi[3], int axis, int side,
                      bool inward, uint32_t cells);

/* Adds the closed box [lo, hi]: its 6 faces named name_AS (axis, side), facing out (a solid) or, when inward,
 * in (a room seen from inside). */
void fxt_add_box(scene *s, const char *name, const double lo[3], const double hi[3], bool inward,
                 uint32_t cells);

/* Adds a directional light travelling along direction. */
void fxt_add_sun(scene *s, float dx, float dy, float dz);

/* Adds an icosphere of radius r about the origin, 20 x 4^levels facets, normals inward (test_probes.c,
 * test_world.c: a closed sphere lit from its centre). */
void fxt_add_sphere(scene *s, float r, int levels);

/* Finalizes s at texel density (texels per metre) with the AO radius and builds its Embree scene. */
scene_rt *fxt_finish_scene(scene *s, float density, float ao_radius);

/* The single island of mesh (the test meshes are planar and small, so each is one island). */
uint32_t fxt_island_of_mesh(const scene *s, uint32_t mesh);

/* The cache key of a block (DESIGN.md: effect:4 | island:32 | level:4 | block_y:12 | block_x:12). */
uint64_t fxt_block_key(uint32_t effect, uint32_t island, uint32_t level, uint32_t bx, uint32_t by);

/* Prepares every block of island at level for effect: masks cover the island's texels, lookups are filled. */
void fxt_island_run_init(fxt_island_run *run, const scene *s, uint32_t island, uint32_t level,
                         uint32_t effect);

/* Releases a run's storage. */
void fxt_island_run_free(fxt_island_run *run);

/* The embedded default scene scaled by `scale` about the world origin, then moved by `offset` on every axis,
 * with its sun, sky, AO radius and camera transformed alike; lights and sky times `intensity_scale`;
 * finalised at the automatic density (which follows the scale). */
scene *fxt_transformed_default(double scale, double offset, float intensity_scale);

/* The unoccluded fraction of cosine-weighted rays of length radius from a floor point at distances d1, d2 from
 * two perpendicular walls (INFINITY: no wall) under a ceiling at height h (INFINITY: none), in closed form: a
 * cosine-weighted direction projects to a uniform point of the unit disk (Malley), and a ray meets a wall at
 * distance d iff its component towards it exceeds d / radius (test_crease.c checks it by counting). */
double fxt_disk_open(double d1, double d2, double h, double radius);

/* A unit quad in the XZ plane facing up (+y), two triangles, as an OBJ file's text. */
extern const char fxt_quad_obj[];

/* Writes quad.obj (a unit quad in the XZ plane facing up, two triangles) into the scratch folder, where the
 * JSON scene tests' files refer to it; returns its path. */
const char *fxt_write_quad(void);

/* Writes text as a JSON file `name` next to quad.obj, loads it into a fresh scene and finalises it; returns
 * the scene on success (caller frees) or NULL with err filled. */
scene *fxt_load_json_text(const char *name, const char *text, scene_error *err);

/* scene_load(path) with default options; fails the test with the loader's message when it refuses. */
scene *fxt_load_ok(const char *path);

#endif
