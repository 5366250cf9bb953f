/* Private to the scene module: the builder functions the loaders (mesh files, JSON, embedded scene) share,
 * and the stages scene finalisation runs. */
#ifndef FXC_SCENE_INTERNAL_H
#define FXC_SCENE_INTERNAL_H

#include "scene.h"

#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>

/* One mesh as a loader handed it over, in double precision after its transform: kept until the scene's
 * origin is settled, so that the mesh can be welded and cleaned again in the final frame. */
typedef struct scene__staged_mesh {
    char name[128];
    double *world;     /* vertex_count * 3: positions after the mesh transform, world frame */
    uint32_t *indices; /* triangle_count * 3 */
    float *uv;         /* vertex_count * 2, or NULL */
    float *color;      /* vertex_count * 3: vertex colours, linear RGB in 0..1, or NULL */
    uint32_t vertex_count, triangle_count, material;
    bool mirrored; /* the transform mirrors: corners are swapped to keep the winding */
    uint32_t mesh; /* its entry in scene.meshes, UINT32_MAX when nothing of it was left */
} scene__staged_mesh;

/* Welds and cleans the staged mesh m into the scene in the local frame at origin (scene_weld.c): appends its
 * vertices and triangles, sets *mesh to its entry in s->meshes (UINT32_MAX when nothing of it was left). */
scene_result scene__commit_mesh(scene *s, const scene__staged_mesh *m, const double origin[3],
                                const char *name, uint32_t *mesh_index, scene_error *err);

/* The spacing of floats at magnitude x (the unit in the last place), in double. */
double scene__float_spacing(double x);

static inline bool scene__finite3(const float v[3])
{
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

/* "; N of the degenerate ones have an area but collapse at float precision D m from the local origin, ..." for the
 * triangles of r->precision_skipped beyond `before`, or "" when there are none; for messages about dropped
 * triangles. */
void scene__precision_lost(const scene_repairs *r, uint64_t before, char *out, size_t cap);

/* The longest triangle edge of the scene, metres (local frame); 0 without triangles. */
double scene__longest_edge(const scene *s);

/* Fills err with code and a printf-style message; returns code so callers can `return scene__fail(...)`. */
scene_result scene__fail(scene_error *err, scene_result code, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/* A new empty scene with defaults: no meshes, no lights, no sky, density auto, overrides auto. */
scene *scene__alloc(void);

/* Monotonic clock, milliseconds. */
double scene__now_ms(void);

/* Appends a material; returns its index. */
uint32_t scene__add_material(scene *s, const scene_material *m, scene_error *err);

/* Loads a texture (through OpenImageIO) or returns the index of one already loaded from the same path.
 * Returns -1 and fills err when it cannot be read. */
int32_t scene__add_texture(scene *s, const char *path, scene_error *err);

/* The same from len encoded bytes in memory (a texture embedded in a GLB or FBX file), named name (its
 * extension picks the image reader; a second texture of the same name is the first). */
int32_t scene__add_texture_memory(scene *s, const char *name, const void *data, size_t len, scene_error *err);

/* Adds a texture of linear RGB texels (width * height * 3, malloc'd; the scene owns them from here on, also
 * on failure), named path in messages: texels clamped to 0..1, mip chain built. */
int32_t scene__add_texture_rgb(scene *s, const char *path, uint32_t width, uint32_t height, float *rgb,
                               scene_error *err);

/* Appends a light after checking it (finite values, non-negative intensity, non-zero direction). A point
 * light's position is in world coordinates until scene__finalize() moves it into the local frame. */
scene_result scene__add_light(scene *s, const scene_light *l, const char *where, scene_error *err);

/* The same with the point light's world position in double (l->position is then ignored): for positions
 * from a scene description, which may lie far from the world origin. */
scene_result scene__add_light_world(scene *s, const scene_light *l, const double world_position[3],
                                    const char *where, scene_error *err);

/* Sets the scene's default camera from world positions in double (has_camera, camera_* fields; the float
 * fields receive the world position rounded, the local frame's value at finalisation). False when the
 * builder state cannot be allocated. */
bool scene__set_camera_world(scene *s, const double position[3], const double target[3], float fov_deg);

/* Names the file (or other source) the meshes appended next come from, for the precision warning: "" or
 * NULL clears it. */
void scene__set_source(scene *s, const char *label);

/* Appends a mesh. positions: vertex_count*3; indices: triangle_count*3; uv: vertex_count*2 or NULL.
 * xform: a row-major 4x4 affine transform (double) applied to positions in double, or NULL. Checks every
 * coordinate is finite (naming the mesh and vertex), every index in range; moves the positions into the
 * scene's local frame in double before they become floats; welds vertices with equal (float) positions;
 * drops degenerate and duplicate triangles (counted in s->repairs). A mesh left with no triangle is not
 * added (counted) but is not an error.
 *
 * The local frame's origin is the whole scene's, known only once every mesh is in: until then meshes are
 * welded and cleaned in a provisional frame centred on the first mesh, and scene__finalize() repeats the
 * welding and cleaning from the double positions (kept until then) if the scene's origin differs, so the
 * result is that of one pass in the final frame. */
scene_result scene__add_mesh(scene *s, const char *name, const float *positions, uint32_t vertex_count,
                             const uint32_t *indices, uint32_t triangle_count, const float *uv,
                             uint32_t material, const double *xform, scene_error *err);

/* The same with vertex colours: color is vertex_count * 3 linear RGB (clamped to 0..1 here, a value that is
 * not finite read as 0), or NULL (none). The scene gets corner_color once some mesh has colours; meshes
 * without them are white (1, 1, 1) there. */
scene_result scene__add_mesh_colored(scene *s, const char *name, const float *positions,
                                     uint32_t vertex_count, const uint32_t *indices, uint32_t triangle_count,
                                     const float *uv, const float *color, uint32_t material,
                                     const double *xform, scene_error *err);

/* Appends a sun (directional light) and a sky: the defaults of a plain mesh file or a scene without lights
 * and sky. */
void scene__add_default_lighting(scene *s);

/* Final stage: settles the local frame (the origin; meshes rebuilt in it if the provisional frame differed;
 * point lights and the camera moved into it), checks the scene is not empty, computes normals, bounds, the
 * texel density (auto: from the surface area), the precision warning, the islands. desc may be NULL. */
scene_result scene__finalize(scene *s, const scene_load_desc *desc, scene_error *err);

/* Builds the islands of a scene whose triangles, normals and texel density are set (scene_islands.c).
 * Fills s->islands, island_triangles, tri_island, tri_local, tri_island_uv and s->repairs.nonmanifold_split.
 * Fails with SCENE_ERR_RANGE when the texel density makes one triangle wider than an island may be. */
scene_result scene__build_islands(scene *s, scene_error *err);

/* Grows *array to hold count elements of size bytes; false (array untouched) on overflow or no memory. */
bool scene__grow(void **array, size_t count, size_t size);

/* The log2 of texture texels per metre of every textured triangle (scene_material.c), for mip selection. */
scene_result scene__compute_texture_lods(scene *s, scene_error *err);

/* Every triangle's texture mean over it (scene_material.c; scene_albedo_mean), after the texture levels. */
scene_result scene__compute_texture_means(scene *s, scene_error *err);

/* Checks that path names a regular file that can be opened for reading, before any reader opens it: a
 * directory named like a model ("x.obj"), a FIFO or a device is refused with a message saying what it is. */
scene_result scene__check_file(const char *path, scene_error *err);

/* What fxcache knows about a mesh format before Assimp reads it (scene_import_check.c), by the file's (inner,
 * for .gz) extension: a check of the whole file that runs before Assimp, or the reason the format is refused
 * outright. */
typedef scene_result (*scene_import_check_fn)(const char *path, const char *buf, size_t len,
                                              scene_error *err);
typedef struct scene_import_format {
    const char *ext;             /* lower case, without the dot */
    scene_import_check_fn check; /* NULL: none */
    const char *refused;         /* non-NULL: the file is refused with this reason */
} scene_import_format;

/* The entry for extension ext (compared without case), or NULL when fxcache knows nothing of the format. */
const scene_import_format *scene__import_format_of(const char *ext);

/* Mesh-file import through Assimp (scene_import.c): appends the file's meshes and materials to s.
 * xform (row-major affine, double) may be NULL; override (may be NULL) replaces every material of the file. */
scene_result scene__import_file(scene *s, const char *path, const double *xform,
                                const scene_material *override, scene_error *err);

/* What a mesh file's own lights and camera gave the scene (scene__import_file_lit). */
typedef struct scene_file_lights {
    uint32_t lights;  /* directional and point lights added */
    uint32_t skipped; /* lights fxcache cannot represent (spot, area, other falloffs): a warning line each */
    bool sky;         /* an ambient light became the sky */
    bool camera;      /* the file's first camera became the scene's default camera */
} scene_file_lights;

/* A plain mesh file: scene__import_file without transform or material, plus the file's lights (directional,
 * point with an inverse-square falloff, ambient as the sky) and its first camera (scene_import_nodes.c);
 * *found says what they gave. */
scene_result scene__import_file_lit(scene *s, const char *path, scene_file_lights *found, scene_error *err);

/* Reads a JSON scene description into s (scene_json.c). */
scene_result scene__load_json(scene *s, const char *path, scene_error *err);

/* Fills s with the embedded default scene (scene_default.c). */
scene_result scene__build_default(scene *s, scene_error *err);

/* The same with its meshes moved by xform (row-major affine, double; NULL for none); its lights and camera
 * are not moved (a JSON scene that places it brings its own). */
scene_result scene__build_default_xform(scene *s, const double *xform, scene_error *err);

#endif
