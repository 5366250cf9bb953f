/* The embedded default scene: built in code, needs no file ("fxcache ... --scene default").
 *
 * A room of 10 m x 4 m x 8 m (x from -5 to 5, y up from 0 to 4, z from -4 to 4, metres) whose ceiling has a
 * 3 m x 2 m opening (x from -1 to 2, z from -2 to 0). A sun (directional light) shines through the opening
 * and lays a patch of sunlight on the floor (about x 1..4, z -0.8..1.2); a red box and a green sphere
 * stand in that patch and cast shadows inside it. A tall blue box stands in the corner of two walls (inside
 * corners for ambient occlusion) and a low yellow box stands on the other side of the room, in shade. A
 * blue sky gives ambient light, so all three effects matter: hard shadows (sun), ambient occlusion (sky,
 * corners, contact with the floor) and indirect light (the sunlit patch lights the rest of the room).
 *
 * Every surface is made of quads of at most 1 m x 1 m (two triangles each) so that no triangle spans the
 * room; the sphere has 24 segments and 14 rings. About 1,250 triangles in all. Normals point into the room
 * for floor, walls and ceiling, and outward for the objects (counter-clockwise corners seen from the front,
 * as scene__finalize() computes normals). Box faces that lie against the floor or a wall are left out: they
 * would be invisible and coplanar with the surface they touch. */
#include "scene_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Room size, metres. */
#define DEFAULT_ROOM_HALF_X 5.0f
#define DEFAULT_ROOM_HEIGHT 4.0f
#define DEFAULT_ROOM_HALF_Z 4.0f

/* Geometry of one object, grown as quads and triangles are appended; failed is set when memory runs out. */
typedef struct default_builder {
    float *positions; /* vertex_count * 3 */
    uint32_t vertex_count, vertex_capacity;
    uint32_t *indices; /* triangle_count * 3 */
    uint32_t triangle_count, triangle_capacity;
    bool failed;
} default_builder;

/* Empties a builder for the next object, keeping its memory. */
static void builder_reset(default_builder *b)
{
    b->vertex_count = 0;
    b->triangle_count = 0;
}

/* Releases a builder's memory. */
static void builder_release(default_builder *b)
{
    free(b->positions);
    free(b->indices);
    memset(b, 0, sizeof *b);
}

/* Appends a vertex; returns its index (0 and failed set when out of memory). */
static uint32_t builder_vertex(default_builder *b, float x, float y, float z)
{
    if (b->failed)
        return 0;
    if (b->vertex_count == b->vertex_capacity) {
        uint32_t capacity = b->vertex_capacity ? b->vertex_capacity * 2 : 256;
        float *grown = realloc(b->positions, sizeof(float) * 3 * (size_t)capacity);
        if (!grown) {
            b->failed = true;
            return 0;
        }
        b->positions = grown;
        b->vertex_capacity = capacity;
    }
    float *p = b->positions + 3 * (size_t)b->vertex_count;
    p[0] = x;
    p[1] = y;
    p[2] = z;
    return b->vertex_count++;
}

/* Appends a triangle with corners a, c1, c2 (counter-clockwise seen from the side its normal points to). */
static void builder_triangle(default_builder *b, uint32_t a, uint32_t c1, uint32_t c2)
{
    if (b->failed)
        return;
    if (b->triangle_count == b->triangle_capacity) {
        uint32_t capacity = b->triangle_capacity ? b->triangle_capacity * 2 : 256;
        uint32_t *grown = realloc(b->indices, sizeof(uint32_t) * 3 * (size_t)capacity);
        if (!grown) {
            b->failed = true;
            return;
        }
        b->indices = grown;
        b->triangle_capacity = capacity;
    }
    uint32_t *t = b->indices + 3 * (size_t)b->triangle_count++;
    t[0] = a;
    t[1] = c1;
    t[2] = c2;
}

/* A rectangular hole in a grid, in cell coordinates: cells i in [i0, i1) and j in [j0, j1) are left out. */
typedef struct default_hole {
    uint32_t i0, i1, j0, j1;
} default_hole;

/* Appends the rectangle origin + [0,1] * edge_u + [0,1] * edge_v as cells_u x cells_v quads, facing
 * edge_u x edge_v, leaving out the cells of hole (may be NULL). Each quad has its own four corners; the
 * scene welds the shared ones (they are computed the same way, so they are bit-identical). */
static void builder_grid(default_builder *b, const float origin[3], const float edge_u[3],
                         const float edge_v[3], uint32_t cells_u, uint32_t cells_v, const default_hole *hole)
{
    for (uint32_t i = 0; i < cells_u; i++) {
        for (uint32_t j = 0; j < cells_v; j++) {
            if (hole && i >= hole->i0 && i < hole->i1 && j >= hole->j0 && j < hole->j1)
                continue;
            uint32_t corner[4];
            for (int c = 0; c < 4; c++) {
                uint32_t ci = i + (c == 1 || c == 2), cj = j + (c >= 2);
                float fu = (float)ci / (float)cells_u, fv = (float)cj / (float)cells_v;
                corner[c] = builder_vertex(b, origin[0] + fu * edge_u[0] + fv * edge_v[0],
                                           origin[1] + fu * edge_u[1] + fv * edge_v[1],
                                           origin[2] + fu * edge_u[2] + fv * edge_v[2]);
            }
            builder_triangle(b, corner[0], corner[1], corner[2]);
            builder_triangle(b, corner[0], corner[2], corner[3]);
        }
    }
}

/* Faces of a box, to leave out the ones that lie against a wall or the floor. */
enum {
    BOX_NEG_X = 1 << 0,
    BOX_POS_X = 1 << 1,
    BOX_NEG_Y = 1 << 2,
    BOX_POS_Y = 1 << 3,
    BOX_NEG_Z = 1 << 4,
    BOX_POS_Z = 1 << 5,
    BOX_ALL_BUT_BOTTOM = BOX_NEG_X | BOX_POS_X | BOX_POS_Y | BOX_NEG_Z | BOX_POS_Z,
};

/* Appends the faces (BOX_* mask) of the axis-aligned box [lo, hi], facing outward, one quad per face. */
static void builder_box(default_builder *b, const float lo[3], const float hi[3], unsigned faces)
{
    const float size[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
    const float ex[3] = {size[0], 0, 0}, ey[3] = {0, size[1], 0}, ez[3] = {0, 0, size[2]};
    const float at_hi_x[3] = {hi[0], lo[1], lo[2]}, at_hi_y[3] = {lo[0], hi[1], lo[2]},
                at_hi_z[3] = {lo[0], lo[1], hi[2]};
    /* Each pair of edges is ordered so that edge_u x edge_v points out of the box. */
    if (faces & BOX_NEG_X)
        builder_grid(b, lo, ez, ey, 1, 1, NULL); /* z x y = -x */
    if (faces & BOX_POS_X)
        builder_grid(b, at_hi_x, ey, ez, 1, 1, NULL); /* y x z = +x */
    if (faces & BOX_NEG_Y)
        builder_grid(b, lo, ex, ez, 1, 1, NULL); /* x x z = -y */
    if (faces & BOX_POS_Y)
        builder_grid(b, at_hi_y, ez, ex, 1, 1, NULL); /* z x x = +y */
    if (faces & BOX_NEG_Z)
        builder_grid(b, lo, ey, ex, 1, 1, NULL); /* y x x = -z */
    if (faces & BOX_POS_Z)
        builder_grid(b, at_hi_z, ex, ey, 1, 1, NULL); /* x x y = +z */
}

/* Appends a UV sphere (segments around, rings from pole to pole) facing outward. */
static void builder_sphere(default_builder *b, const float center[3], float radius, uint32_t segments,
                           uint32_t rings)
{
    const double pi = 3.14159265358979323846;
    uint32_t south = builder_vertex(b, center[0], center[1] - radius, center[2]);
    for (uint32_t r = 1; r < rings; r++) {
        double polar = pi * (double)r / (double)rings; /* from the south pole up */
        double y = -cos(polar), ring_radius = sin(polar);
        for (uint32_t k = 0; k < segments; k++) {
            double azimuth = 2.0 * pi * (double)k / (double)segments;
            builder_vertex(b, center[0] + radius * (float)(ring_radius * cos(azimuth)),
                           center[1] + radius * (float)y,
                           center[2] + radius * (float)(ring_radius * sin(azimuth)));
        }
    }
    uint32_t north = builder_vertex(b, center[0], center[1] + radius, center[2]);
    /* Vertex of ring r (1..rings-1), segment k. */
#define RING_VERTEX(r, k) (south + 1 + ((r)-1) * segments + ((k) % segments))
    for (uint32_t k = 0; k < segments; k++) {
        /* Outward = up x around (at +x: y x z = +x), so each triangle lists an "up" edge before an
         * "around" edge. */
        builder_triangle(b, south, RING_VERTEX(1, k), RING_VERTEX(1, k + 1));
        for (uint32_t r = 1; r + 1 < rings; r++) {
            builder_triangle(b, RING_VERTEX(r, k), RING_VERTEX(r + 1, k), RING_VERTEX(r + 1, k + 1));
            builder_triangle(b, RING_VERTEX(r, k), RING_VERTEX(r + 1, k + 1), RING_VERTEX(r, k + 1));
        }
        builder_triangle(b, RING_VERTEX(rings - 1, k), north, RING_VERTEX(rings - 1, k + 1));
    }
#undef RING_VERTEX
}

/* Hands the builder's object to the scene as one mesh with the given material, then empties the builder. */
static scene_result builder_commit(default_builder *b, scene *s, const char *name, uint32_t material,
                                   const double *xform, scene_error *err)
{
    if (b->failed)
        return scene__fail(err, SCENE_ERR_NOMEM, "(embedded default scene): out of memory building '%s'",
                           name);
    scene_result r = scene__add_mesh(s, name, b->positions, b->vertex_count, b->indices, b->triangle_count,
                                     NULL, material, xform, err);
    builder_reset(b);
    return r;
}

/* Appends a material with the given name and linear albedo; UINT32_MAX (err filled) when out of memory. */
static uint32_t default_material(scene *s, const char *name, float r, float g, float b, scene_error *err)
{
    scene_material m;
    memset(&m, 0, sizeof m);
    m.diffuse[0] = r;
    m.diffuse[1] = g;
    m.diffuse[2] = b;
    m.texture = -1;
    strncpy(m.name, name, sizeof m.name - 1);
    return scene__add_material(s, &m, err);
}

/* Fills s with the embedded default scene: its meshes and materials, the sun, the sky, the ambient-occlusion
 * radius and the default camera. xform (may be NULL) moves the meshes only. s comes from scene__alloc(); on
 * failure err says why and the caller frees s. */
scene_result scene__build_default_xform(scene *s, const double *xform, scene_error *err)
{
    enum { MAT_FLOOR, MAT_WALLS, MAT_RED, MAT_BLUE, MAT_YELLOW, MAT_GREEN, MAT_COUNT };
    static const struct {
        const char *name;
        float rgb[3];
    } materials[MAT_COUNT] = {
        {"default floor (oak)", {0.55f, 0.40f, 0.26f}}, {"default walls (plaster)", {0.80f, 0.78f, 0.74f}},
        {"default red", {0.70f, 0.12f, 0.08f}},         {"default blue", {0.12f, 0.22f, 0.65f}},
        {"default yellow", {0.75f, 0.62f, 0.15f}},      {"default green", {0.15f, 0.55f, 0.22f}},
    };
    uint32_t material_index[MAT_COUNT];
    for (int m = 0; m < MAT_COUNT; m++) {
        material_index[m] = default_material(s, materials[m].name, materials[m].rgb[0], materials[m].rgb[1],
                                             materials[m].rgb[2], err);
        if (material_index[m] == UINT32_MAX)
            return err ? err->code : SCENE_ERR_NOMEM;
    }

    scene__set_source(s, "(embedded default scene)");
    const float hx = DEFAULT_ROOM_HALF_X, h = DEFAULT_ROOM_HEIGHT, hz = DEFAULT_ROOM_HALF_Z;
    const float along_x[3] = {2 * hx, 0, 0}, along_y[3] = {0, h, 0}, along_z[3] = {0, 0, 2 * hz};
    const uint32_t cells_x = 10, cells_y = 4, cells_z = 8; /* 1 m cells */
    default_builder b;
    memset(&b, 0, sizeof b);
    scene_result r;

    /* Floor, facing up: z x x = +y. */
    const float floor_origin[3] = {-hx, 0, -hz};
    builder_grid(&b, floor_origin, along_z, along_x, cells_z, cells_x, NULL);
    if ((r = builder_commit(&b, s, "floor", material_index[MAT_FLOOR], xform, err)) != SCENE_OK)
        goto done;

    /* Ceiling, facing down (x x z = -y), with the opening: cells x -1..2, z -2..0. */
    const float ceiling_origin[3] = {-hx, h, -hz};
    const default_hole opening = {.i0 = 4, .i1 = 7, .j0 = 2, .j1 = 4};
    builder_grid(&b, ceiling_origin, along_x, along_z, cells_x, cells_z, &opening);
    if ((r = builder_commit(&b, s, "ceiling with opening", material_index[MAT_WALLS], xform, err)) !=
        SCENE_OK)
        goto done;

    /* Four walls facing into the room. */
    const float west_origin[3] = {-hx, 0, -hz}, east_origin[3] = {hx, 0, -hz};
    const float north_origin[3] = {-hx, 0, -hz}, south_origin[3] = {-hx, 0, hz};
    builder_grid(&b, west_origin, along_y, along_z, cells_y, cells_z, NULL);  /* y x z = +x */
    builder_grid(&b, east_origin, along_z, along_y, cells_z, cells_y, NULL);  /* z x y = -x */
    builder_grid(&b, north_origin, along_x, along_y, cells_x, cells_y, NULL); /* x x y = +z */
    builder_grid(&b, south_origin, along_y, along_x, cells_y, cells_x, NULL); /* y x x = -z */
    if ((r = builder_commit(&b, s, "walls", material_index[MAT_WALLS], xform, err)) != SCENE_OK)
        goto done;

    /* A red cube in the sunlit patch. */
    const float red_lo[3] = {1.5f, 0, -0.5f}, red_hi[3] = {2.5f, 1.0f, 0.5f};
    builder_box(&b, red_lo, red_hi, BOX_ALL_BUT_BOTTOM);
    if ((r = builder_commit(&b, s, "red box", material_index[MAT_RED], xform, err)) != SCENE_OK)
        goto done;

    /* A tall blue box in the corner of the west and north walls: only its three free faces. */
    const float blue_lo[3] = {-hx, 0, -hz}, blue_hi[3] = {-hx + 1.2f, 2.2f, -hz + 1.0f};
    builder_box(&b, blue_lo, blue_hi, BOX_POS_X | BOX_POS_Y | BOX_POS_Z);
    if ((r = builder_commit(&b, s, "blue box in the corner", material_index[MAT_BLUE], xform, err)) !=
        SCENE_OK)
        goto done;

    /* A low, wide yellow box in the shade. */
    const float yellow_lo[3] = {-2.5f, 0, 1.5f}, yellow_hi[3] = {-0.5f, 0.6f, 3.0f};
    builder_box(&b, yellow_lo, yellow_hi, BOX_ALL_BUT_BOTTOM);
    if ((r = builder_commit(&b, s, "yellow box", material_index[MAT_YELLOW], xform, err)) != SCENE_OK)
        goto done;

    /* A green sphere resting on the floor in the sunlit patch. */
    const float sphere_center[3] = {3.3f, 0.6f, 0.6f};
    builder_sphere(&b, sphere_center, 0.6f, 24, 14);
    if ((r = builder_commit(&b, s, "green sphere", material_index[MAT_GREEN], xform, err)) != SCENE_OK)
        goto done;

    /* The sun travels down and towards +x, +z: through the opening onto the floor around x 1..4, z -0.8..1.2. */
    scene_light sun;
    memset(&sun, 0, sizeof sun);
    sun.type = SCENE_LIGHT_DIRECTIONAL;
    sun.direction[0] = 0.5f;
    sun.direction[1] = -1.0f;
    sun.direction[2] = 0.3f;
    sun.color[0] = 1.0f;
    sun.color[1] = 0.95f;
    sun.color[2] = 0.85f;
    sun.intensity = 3.0f;
    if ((r = scene__add_light(s, &sun, "(embedded default scene): sun", err)) != SCENE_OK)
        goto done;

    s->sky_color[0] = 0.55f;
    s->sky_color[1] = 0.70f;
    s->sky_color[2] = 1.00f;
    s->sky_intensity = 0.6f;
    s->ao_radius = 1.0f; /* metres: about a box's size, so corners and contacts darken */

    /* From the corner at +x, +z, above eye height, looking across the sunlit patch (red box, sphere) to the
     * blue box in the far corner; the yellow box is on the left and the ceiling opening at the top. */
    s->has_camera = true;
    s->camera_pos[0] = 4.3f;
    s->camera_pos[1] = 2.2f;
    s->camera_pos[2] = 3.5f;
    s->camera_target[0] = -1.0f;
    s->camera_target[1] = 0.5f;
    s->camera_target[2] = -1.5f;
    s->camera_fov_deg = 60.0f;
    r = SCENE_OK;
done:
    builder_release(&b);
    return r;
}

scene_result scene__build_default(scene *s, scene_error *err)
{
    return scene__build_default_xform(s, NULL, err);
}
