/* scene: everything fxcache knows about the 3D world before any viewer looks at it.
 *
 * A scene is built once (from a mesh file, a JSON scene description, or the embedded default scene) and is
 * read-only afterwards. It holds welded triangles, per-corner mesh UVs for textures, materials, lights, the
 * sky, the texel density, the islands every triangle belongs to, and the per-effect overrides. The Embree
 * scene (scene_rt) and "what this scene needs" (scene_needs) are derived from it.
 *
 * Local frame: every position a scene holds (vertices, bounds, point lights, its camera) is a float in the
 * scene's local frame, world = local + origin, with the origin (double) near the scene's centre (DESIGN.md
 * "Numerical robustness"). The loaders apply mesh transforms and subtract the origin in double before
 * positions become floats, so a scene 1e6 from the world origin keeps the float precision it has at the
 * origin. Positions from outside (viewer traces, the command line) go through scene_world_to_local().
 *
 * Ownership: scene_free() releases every allocation a scene owns. Errors come back through scene_error, a
 * code plus one line naming the file, line, mesh or value at fault. */
#ifndef FXC_SCENE_H
#define FXC_SCENE_H

#include "fxc_result.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Result codes: the scene's names and texts, the shared values of common/fxc_result.h (name, value, text). */
#define SCENE_RESULTS(X)                                                                                     \
    X(SCENE_OK, FXC_OK, "ok")                                                                                \
    X(SCENE_ERR_IO, FXC_ERR_IO, "cannot read file")                                                          \
    X(SCENE_ERR_FORMAT, FXC_ERR_FORMAT, "unsupported or malformed file")                                     \
    X(SCENE_ERR_JSON, FXC_ERR_JSON, "malformed scene description")                                           \
    X(SCENE_ERR_INVALID, FXC_ERR_CONTENT, "invalid scene content")                                           \
    X(SCENE_ERR_RANGE, FXC_ERR_RANGE, "value out of range")                                                  \
    X(SCENE_ERR_EMPTY, FXC_ERR_EMPTY, "empty scene")                                                         \
    X(SCENE_ERR_NOMEM, FXC_ERR_NOMEM, "out of memory")                                                       \
    X(SCENE_ERR_EMBREE, FXC_ERR_EMBREE, "Embree error")

typedef enum scene_result {
#define FXC_X(name, value, str) name = value,
    SCENE_RESULTS(FXC_X)
#undef FXC_X
} scene_result;

/* The string of a result code. */
const char *scene_strerror(scene_result code);

/* A failure: the code and one line that names what and where. */
typedef struct scene_error {
    scene_result code;
    char msg[512];
} scene_error;

/* Effect overrides from the scene description. */
typedef enum scene_toggle { SCENE_AUTO = 0, SCENE_ON, SCENE_OFF } scene_toggle;

typedef enum scene_light_type { SCENE_LIGHT_DIRECTIONAL = 0, SCENE_LIGHT_POINT } scene_light_type;

typedef struct scene_light {
    scene_light_type type;
    float direction[3]; /* directional: unit vector the light travels along (from the light into the scene) */
    float position[3];  /* point: position in the local frame, metres (world until scene finalisation) */
    float color[3];     /* linear RGB, 0..1 typically */
    float intensity;    /* directional: irradiance scale; point: intensity (falls off with 1/d^2) */
} scene_light;

enum { SCENE_TEXTURE_MAX_LEVELS = 17 }; /* mip levels of a texture of at most 65536 texels a side */

typedef struct scene_texture {
    uint32_t width, height; /* texels */
    float *rgb;             /* linear RGB, width*height*3, row 0 at the top of the image */
    uint32_t levels;        /* mip levels, level 0 included (box-filtered halvings down to 1 x 1) */
    float *mip_rgb[SCENE_TEXTURE_MAX_LEVELS]; /* level l (mip_rgb[0] == rgb) */
    uint32_t mip_width[SCENE_TEXTURE_MAX_LEVELS], mip_height[SCENE_TEXTURE_MAX_LEVELS];
    char path[256]; /* where it came from, for messages */
} scene_texture;

typedef struct scene_material {
    float diffuse[3];  /* linear RGB albedo, 0..1 */
    int32_t texture;   /* index into scene.textures, or -1 */
    float emission[3]; /* linear RGB radiance the front face emits, W/(m^2 sr) in the scene's units (the sky's
                        * radiance and compose's radiance are in the same units); finite, >= 0; 0: none */
    char name[64];
} scene_material;

typedef struct scene_mesh {
    char name[128];
    uint32_t first_triangle, triangle_count; /* range in the scene's triangle arrays */
    uint32_t material;                       /* index into scene.materials */
} scene_mesh;

/* One island: a connected group of at most SCENE_ISLAND_MAX_TRIANGLES triangles with its own texture space. */
typedef struct scene_island {
    uint32_t first;          /* first entry in scene.island_triangles */
    uint32_t triangle_count; /* 1..256 */
    uint32_t width, height;  /* size in texels at level 0, including the one-texel border */
    uint32_t mesh;           /* the mesh it belongs to */
} scene_island;

/* The side bit of an island id where it names a side of a surface (on-surface cache keys, srv_pixel.island):
 * set for the side the triangles' winding makes the back (DESIGN.md "On-surface cache": the back is a twin
 * island). An island's own index never has it: a scene holds at most UINT32_MAX / 8 triangles
 * (scene__add_mesh) and islands are fewer than triangles. */
#define SCENE_ISLAND_BACK  0x80000000u
#define SCENE_ISLAND_INDEX 0x7FFFFFFFu /* the island's own index in an id with a side bit */

enum {
    SCENE_ISLAND_MAX_TRIANGLES = 256,
    SCENE_BLOCK_TEXELS = 8,             /* a block is 8 x 8 texels */
    SCENE_MAX_BLOCKS = 4096,            /* 12-bit block coordinates */
    SCENE_MAX_ISLAND_TEXELS = 4096 * 8, /* level-0 island side, border included */
};

/* Counts of input the importer repaired or skipped, never silently. */
typedef struct scene_repairs {
    uint64_t degenerate_skipped; /* zero-area or repeated-vertex triangles dropped */
    uint64_t precision_skipped;  /* of those, triangles with an area in double that collapsed in float in the
                                      local frame (too far from the scene's centre for their size) */
    double precision_reach;      /* the farthest such triangle's corner from the local origin, metres */
    uint64_t duplicate_skipped;  /* triangles with the same three welded vertices as an earlier one */
    uint64_t nonmanifold_split;  /* triangles split off from the half-edge mesh (non-manifold edges) */
    uint64_t vertices_welded;    /* vertices merged into an earlier one with the same position */
    uint64_t non_triangles_dropped; /* points and lines in the input */
    uint64_t textures_missing;      /* texture files named by a material that could not be read */
    uint64_t lights_unused;         /* a mesh file's lights fxcache does not use (spot, area, other falloffs,
                                       formats whose lights Assimp does not give as meant: SCENE_FORMAT.md) */
    uint64_t cameras_unused;        /* a mesh file's cameras not used (all but the first; other formats') */
} scene_repairs;

/* Wall-clock time of each build stage, milliseconds. */
typedef struct scene_timings {
    double load_ms;    /* reading and parsing files, triangulation */
    double weld_ms;    /* welding and validation */
    double islands_ms; /* topology, chart growing, projection */
    double textures_ms;
} scene_timings;

struct scene__builder; /* private to the scene module: loading state, gone once the scene is finalised */

typedef struct scene {
    /* Geometry, local frame (world = local + origin), welded. */
    uint32_t vertex_count;
    float *positions; /* vertex_count * 3 */
    uint32_t triangle_count;
    uint32_t *indices;       /* triangle_count * 3, into positions */
    float *corner_uv;        /* triangle_count * 6: the mesh's own UVs per corner (for textures), 0 if none */
    float *corner_color;     /* triangle_count * 9: per corner, the vertex colour (linear RGB, 0..1) that
                              * multiplies the material's albedo, interpolated over the triangle (glTF's
                              * COLOR_0, a PLY scan's colours); NULL when no mesh has vertex colours (then
                              * 1, 1, 1 everywhere), so a scene without them holds nothing for them */
    uint32_t *tri_mesh;      /* triangle_count: mesh index */
    float *tri_normal;       /* triangle_count * 3: unit geometric normal */
    float *tri_texture_lod;  /* triangle_count: log2 of its texture's texels per metre on it (-1000: none) */
    float *tri_texture_mean; /* triangle_count * 3: its texture's mean over it (1, 1, 1: none); see
                              * scene_albedo_mean */

    uint32_t mesh_count;
    scene_mesh *meshes;
    uint32_t material_count;
    scene_material *materials;
    uint32_t texture_count;
    scene_texture *textures;
    uint32_t light_count;
    scene_light *lights;

    float sky_color[3]; /* linear RGB */
    float sky_intensity;

    float texel_density; /* level-0 texels per metre */
    bool density_auto;   /* chosen by scene_finalize() from the surface area */
    float ao_radius;     /* metres; 0 = auto (a tenth of the bounding-box diagonal) */

    scene_toggle fx_shadows, fx_ao, fx_indirect;

    /* Some material with a mesh emits (emission > 0): set by scene_finalize(), and by scene_emission_refresh()
     * after a material's emission changes. Compose and the probes add emission only when it is set, so a
     * scene without emitters pays one test per run of pixels or chunk of rays. */
    bool emissive;
    /* A plain mesh file got the default sun and sky (scene__add_default_lighting): it has no lights fxcache
     * reads (glTF, Collada: docs/SCENE_FORMAT.md) and no emitters, or its emitters cover more than
     * SCENE_LAMP_AREA_FRACTION of its surface (a glow, not a lamp). */
    bool default_lighting;

    bool has_camera;                                       /* a default camera from the scene description */
    float camera_pos[3], camera_target[3], camera_fov_deg; /* local frame, like every position here */

    /* The local frame: world = local + origin, metres. The centre of the geometry's bounding box rounded to a
     * multiple of the smallest power of two >= the scene's extent and >= 1 m (so a whole number of metres),
     * or (0, 0, 0) when that centre lies within one extent of the world origin (rebasing would gain at most
     * 1.6 bits there). Either way every local coordinate is within max(1.5 extents, 1 m) of the origin. */
    double origin[3];
    /* The spacing of stored positions, metres: the coarser of the float spacing at the largest local
     * coordinate and the spacing the input had (a mesh file whose own coordinates are far from its origin
     * arrives as floats, already quantized, times the mesh transform's scale). */
    double position_step;
    /* "" or one line: positions are quantized to more than SCENE_PRECISION_TEXEL_FRACTION of a texel at the
     * texel density, naming the file or the extent at fault and the figure. The scene still loads. */
    char precision_warning[512];

    float bounds_min[3], bounds_max[3];
    float ray_offset_scale; /* min(1, bounding-box diagonal in metres): scales scene_offset_ray_origin() */

    /* Islands (filled by scene_finalize()). */
    uint32_t island_count;
    scene_island *islands;
    uint32_t *island_triangles; /* triangle_count entries: scene triangle of each island slot */
    uint32_t *tri_island;       /* triangle_count: island of each triangle */
    uint8_t *tri_local;         /* triangle_count: index of the triangle inside its island (0..255) */
    float *tri_island_uv;       /* triangle_count * 6: island-local UV per corner, level-0 texel units */

    scene_repairs repairs;
    scene_timings timings;
    char source[256]; /* file it came from, or "(embedded default scene)" */

    struct scene__builder *builder; /* loading state (private); NULL once finalised */
} scene;

/* Positions quantized more coarsely than this fraction of a level-0 texel get a precision_warning. */
#define SCENE_PRECISION_TEXEL_FRACTION (1.0 / 16.0)

/* How far from the local origin geometry, point lights and the scene's camera may lie, metres. The per-pixel
 * and effect code works in float and squares distances (dot products, Chebyshev moments, 1/d^2): at 1e12 m a
 * squared distance across the scene is about 1e25, far inside float's range (3.4e38), while at 1e19 m it
 * overflows to infinity. The local frame is centred on a scene far from the world origin, so this limits the
 * scene's extent, not where it lies in the world. */
#define SCENE_MAX_REACH 1e12
/* How far cameras may stand from the local origin, metres: ten times SCENE_MAX_REACH, so that the camera
 * generators' viewers around the largest scene (an orbit at 1.5 times its half diagonal) are within it; squared
 * distances from there (about 1e26) still fit a float. */
#define SCENE_MAX_CAMERA_REACH 1e13
/* The smallest scene, metres: the longest side of the geometry's bounding box. Below it products of lengths
 * (areas, squared distances, their squares in the probes' moments) leave float's normal range: measured with the
 * embedded scene scaled down, shadows, AO and probes match scale 1 down to a 1e-10 m room and break at 1e-11 m
 * (dark blotches, holes); Sponza breaks ten times larger, and at 1e-19 m sim refused its cameras. A
 * micrometre leaves a thousandfold margin; a smaller model loads scaled up by a transform. */
#define SCENE_MIN_EXTENT 1e-6

/* Options for loading. All-zero means defaults. */
typedef struct scene_load_desc {
    float texel_density; /* level-0 texels per metre; 0 = from the file, else auto */
} scene_load_desc;

/* Loads a scene: a JSON scene description (*.json), or any mesh file Assimp reads (optionally .gz), which
 * then becomes a scene lit by its own lights and seen from its own camera where it has them (glTF, Collada;
 * FBX cameras), else with defaults (one sun, a sky) unless some material of it emits and the emitting
 * triangles cover at most SCENE_LAMP_AREA_FRACTION of its surface (lamps: then its emitters alone light
 * it). The path "default" (or NULL) is the embedded scene.
 * Returns NULL and fills err on failure; nothing partial is returned. */
scene *scene_load(const char *path, const scene_load_desc *desc, scene_error *err);

/* The embedded default scene: a room with an opening towards a sun, boxes and a curved object. */
scene *scene_create_default(const scene_load_desc *desc, scene_error *err);

/* Releases a scene and everything it owns. NULL is allowed. */
void scene_free(scene *s);

/* Converts a world-space position (a camera position or target, a light position) into the scene's local
 * frame: (float)(world - origin), subtracted in double. Use it for every position that comes from outside
 * the scene (traces, the command line). */
void scene_world_to_local(const scene *s, const double world[3], float local[3]);

/* The inverse: local + origin, added in double (for writing positions back out, e.g. recorded traces). */
void scene_local_to_world(const scene *s, const float local[3], double world[3]);

/* The area of triangle t, square metres (its corners' floats, in double). */
double scene_triangle_area(const scene *s, uint32_t t);

/* Total surface area of the scene's triangles, square metres. */
double scene_surface_area(const scene *s);

/* Samples a material's albedo (linear RGB) at triangle tri with barycentrics (u, v) of corners 1 and 2, from
 * the texture's finest level (bilinear), times the vertex colour interpolated there (corner_color, when the
 * scene has vertex colours: (1 - u - v) c0 + u c1 + v c2). */
void scene_albedo(const scene *s, uint32_t tri, float u, float v, float out_rgb[3]);

/* The same, filtered for a pixel whose footprint on the surface is 2^footprint_log2 metres: the texture's
 * mip level whose texels are that size (bilinear within it), so textures do not alias and far surfaces
 * read small, cache-friendly levels. */
void scene_albedo_filtered(const scene *s, uint32_t tri, float u, float v, float footprint_log2,
                           float out_rgb[3]);

/* What albedo sampling needs of one triangle, looked up once for the many pixels that see it. */
typedef struct scene_albedo_triangle {
    const scene_texture *texture; /* NULL: untextured, the diffuse colour alone */
    float diffuse[3];
    float uv[6];        /* mesh UVs of the three corners */
    float lod;          /* log2 of texture texels per metre on the triangle */
    const float *color; /* its three corners' vertex colours (scene.corner_color), or NULL: none */
} scene_albedo_triangle;

/* Prepares albedo sampling of triangle tri; scene_albedo_sample() then gives what scene_albedo_filtered()
 * gives for the same arguments. */
void scene_albedo_prepare(const scene *s, uint32_t tri, scene_albedo_triangle *out);
void scene_albedo_sample(const scene_albedo_triangle *t, float u, float v, float footprint_log2,
                         float out_rgb[3]);

/* The albedo of a run of `count` hits: out_rgb[i] is what scene_albedo_filtered(s, tri[i], u[i], v[i],
 * footprint_log2[i]) gives. Neighbouring hits on the same triangle share one lookup of its material, and
 * the caller keeps its registers across the run (one call, not one per pixel). */
void scene_albedo_run(const scene *s, const uint32_t *tri, const float *u, const float *v,
                      const float *footprint_log2, uint32_t count, float (*out_rgb)[3]);

/* The albedo of triangle tri averaged over the triangle: its material's diffuse colour times its texture's
 * mean over it, the texture read once when the scene was finalised, bilinearly at the triangle's UV centroid
 * in the mip level whose texels are as large as the triangle (the square root of its UV area in texels; the
 * coarsest level, the texture's mean, for triangles over a whole repeat). One load per call, no filtering:
 * for estimators of low-frequency light (the probe update's hits), not for pixels. The diffuse colour is read
 * at the call (a material changed after finalisation counts); a scene without the table (never finalised)
 * gives the same value, computed at the call. */
void scene_albedo_mean(const scene *s, uint32_t tri, float out_rgb[3]);

/* ---- emission ------------------------------------------------------------------------------------------ */

/* True when a material emits (some emission component > 0). */
bool scene_material_emits(const scene_material *m);

/* Recomputes s->emissive from the materials of its meshes (after a material's emission changed). */
void scene_emission_refresh(scene *s);

/* What the emitting materials give out, for messages: how many materials with a mesh emit, and the total
 * emitted power pi x Le x area summed over their triangles (one side), W in the scene's units, per channel. */
void scene_emission_power(const scene *s, uint32_t *emitting_materials, double power_rgb[3]);

/* The share of the scene's surface area whose material emits, 0..1 (0 without triangles). */
double scene_emission_area_fraction(const scene *s);

/* Emitters of a plain mesh file replace the default sun and sky only when they are lamps: their triangles
 * cover at most this share of the surface. Formats whose materials carry an "emissive" colour for a whole
 * object (MS3D, FBX's Phong, Blender's emit) glow everywhere; they keep the defaults, the emission adds. */
#define SCENE_LAMP_AREA_FRACTION 0.1

/* Adds the emission of triangle tri's material to radiance out_rgb when view_normal (the normal turned to the
 * side the viewer or ray comes from) is on its front: dot(view_normal, geometric normal) > 0. Emission is
 * one-sided, as the probes see it (a back face is the inside of a closed mesh). Saturates at FLT_MAX, never
 * infinite. One material lookup: callers test s->emissive first. */
void scene_emission_add(const scene *s, uint32_t tri, const float view_normal[3], float out_rgb[3]);

/* ---- what the scene needs ---------------------------------------------------------------------------- */

typedef enum scene_effect {
    SCENE_FX_TRIANGLE_LOOKUP = 0,
    SCENE_FX_SHADOW,
    SCENE_FX_AO,
    SCENE_FX_PROBES,
    SCENE_FX_COUNT
} scene_effect;

typedef enum scene_cache_kind {
    SCENE_CACHE_ON_SURFACE = 0,
    SCENE_CACHE_WORLD_SPACE,
    SCENE_CACHE_COUNT
} scene_cache_kind;

typedef struct scene_needs_result {
    bool effect[SCENE_FX_COUNT];
    char effect_reason[SCENE_FX_COUNT][160]; /* why it runs, or why it is left out */
    bool cache[SCENE_CACHE_COUNT];
    char cache_reason[SCENE_CACHE_COUNT][160];
} scene_needs_result;

/* Decides from the scene content and its overrides which effects and caches run, with a reason for each. */
void scene_needs(const scene *s, scene_needs_result *out);

/* Short names: "triangle_lookup", "shadow", "ao", "probes"; "on_surface", "world_space". */
const char *scene_effect_name(scene_effect fx);
const char *scene_cache_name(scene_cache_kind c);

/* ---- Embree ------------------------------------------------------------------------------------------ */

typedef struct scene_rt scene_rt; /* opaque: an Embree device and scene built from scene triangles */

/* Builds the Embree scene from the same triangles (geometry 0, primID = scene triangle index).
 * Returns NULL and fills err when Embree reports an error. build_ms (may be NULL) receives the build time. */
scene_rt *scene_rt_create(const scene *s, double *build_ms, scene_error *err);
void scene_rt_free(scene_rt *rt);

/* The RTCScene handle, as void * so that this header needs no Embree include. */
void *scene_rt_handle(scene_rt *rt);

/* Sets flush-to-zero and denormals-are-zero for the calling thread: call once in every tracing thread. */
void scene_tracing_thread_init(void);

/* A robust origin for a ray leaving a surface at p with geometric normal n (pointing to the side the ray
 * leaves towards): offsets p along n by a scale-aware amount in integer ULPs (Waechter and Binder, Ray
 * Tracing Gems ch. 6). Their fixed offset for coordinates near zero assumes a scene of unit size; `scale`
 * (the scene's ray_offset_scale) shrinks that threshold and offset for smaller scenes. Every ray in fxcache
 * that starts on a surface uses this. */
void scene_offset_ray_origin(const float p[3], const float n[3], float scale, float out[3]);

/* One closest-hit query (for tools and tests; passes use packets). Returns true on a hit. */
bool scene_rt_intersect1(scene_rt *rt, const float org[3], const float dir[3], float tfar, uint32_t *tri,
                         float *u, float *v, float *t);

#ifdef __cplusplus
}
#endif
#endif
