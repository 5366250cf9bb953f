/* Scenes built by hand for the effect tests: see fxt_scene.h. */
#include "test_util.h"

#include "fxt_scene.h"
#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A new scene with one grey material. */
scene *fxt_new_scene(void)
{
    scene *s = scene__alloc();
    assert_non_null(s);
    scene_error err;
    scene_material material = {.diffuse = {0.5f, 0.5f, 0.5f}, .texture = -1, .name = "grey"};
    scene__add_material(s, &material, &err);
    return s;
}

/* Adds a parallelogram corner, corner + edge_a, corner + edge_a + edge_b, corner + edge_b as one mesh of
 * cells x cells quads (two triangles each); its normal is edge_a x edge_b. */
void fxt_add_quad(scene *s, const char *name, const double corner[3], const double edge_a[3],
                  const double edge_b[3], uint32_t cells)
{
    uint32_t side = cells + 1, vertex_count = side * side, triangle_count = 2 * cells * cells;
    float *positions = malloc(sizeof(float) * 3 * vertex_count);
    uint32_t *indices = malloc(sizeof(uint32_t) * 3 * triangle_count);
    assert_true(positions && indices);
    for (uint32_t j = 0; j < side; j++)
        for (uint32_t i = 0; i < side; i++)
            for (int k = 0; k < 3; k++)
                positions[3 * (j * side + i) + k] =
                    (float)(corner[k] + edge_a[k] * i / cells + edge_b[k] * j / cells);
    uint32_t t = 0;
    for (uint32_t j = 0; j < cells; j++)
        for (uint32_t i = 0; i < cells; i++) {
            uint32_t v00 = j * side + i, v10 = v00 + 1, v01 = v00 + side, v11 = v01 + 1;
            uint32_t quad[6] = {v00, v10, v11, v00, v11, v01};
            memcpy(indices + 3 * t, quad, sizeof quad);
            t += 2;
        }
    scene_error err;
    assert_int_equal(
        scene__add_mesh(s, name, positions, vertex_count, indices, triangle_count, NULL, 0, NULL, &err),
        SCENE_OK);
    free(positions);
    free(indices);
}

void fxt_add_box_face(scene *s, const char *name, const double lo[3], const double hi[3], int axis, int side,
                      bool inward, uint32_t cells)
{
    int a = (axis + 1) % 3, b = (axis + 2) % 3;
    double corner[3], ea[3] = {0, 0, 0}, eb[3] = {0, 0, 0};
    corner[axis] = side ? hi[axis] : lo[axis];
    corner[a] = lo[a];
    corner[b] = lo[b];
    ea[a] = hi[a] - lo[a];
    eb[b] = hi[b] - lo[b];
    /* ea x eb points along +axis: outward on the high side. */
    if ((side == 1) != inward)
        fxt_add_quad(s, name, corner, ea, eb, cells);
    else
        fxt_add_quad(s, name, corner, eb, ea, cells);
}

void fxt_add_box(scene *s, const char *name, const double lo[3], const double hi[3], bool inward,
                 uint32_t cells)
{
    for (int axis = 0; axis < 3; axis++)
        for (int side = 0; side < 2; side++) {
            char face[64];
            snprintf(face, sizeof face, "%s_%d%d", name, axis, side);
            fxt_add_box_face(s, face, lo, hi, axis, side, inward, cells);
        }
}

/* Adds a directional light travelling along direction. */
void fxt_add_sun(scene *s, float dx, float dy, float dz)
{
    scene_light light = {
        .type = SCENE_LIGHT_DIRECTIONAL, .direction = {dx, dy, dz}, .color = {1, 1, 1}, .intensity = 1};
    scene_error err;
    assert_int_equal(scene__add_light(s, &light, "test sun", &err), SCENE_OK);
}

/* Finalizes s at texel density (texels per metre) with the AO radius and builds its Embree scene. */
scene_rt *fxt_finish_scene(scene *s, float density, float ao_radius)
{
    scene_error err;
    s->ao_radius = ao_radius;
    scene_load_desc desc = {.texel_density = density};
    scene_result rc = scene__finalize(s, &desc, &err);
    if (rc != SCENE_OK)
        fprintf(stderr, "finalize: %s\n", err.msg);
    assert_int_equal(rc, SCENE_OK);
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    assert_non_null(rt);
    scene_tracing_thread_init();
    return rt;
}

/* The single island of mesh (the test meshes are planar and small, so each is one island). */
uint32_t fxt_island_of_mesh(const scene *s, uint32_t mesh)
{
    uint32_t found = UINT32_MAX, islands = 0;
    for (uint32_t i = 0; i < s->island_count; i++)
        if (s->islands[i].mesh == mesh) {
            found = i;
            islands++;
        }
    assert_int_equal(islands, 1);
    return found;
}

/* The cache key of a block (DESIGN.md: effect:4 | island:32 | level:4 | block_y:12 | block_x:12). */
uint64_t fxt_block_key(uint32_t effect, uint32_t island, uint32_t level, uint32_t bx, uint32_t by)
{
    return ((uint64_t)effect << 60) | ((uint64_t)island << 28) | ((uint64_t)level << 24) |
           ((uint64_t)by << 12) | bx;
}

/* Prepares every block of island at level for effect: masks cover the island's texels, lookups are filled. */
void fxt_island_run_init(fxt_island_run *run, const scene *s, uint32_t island, uint32_t level,
                         uint32_t effect)
{
    memset(run, 0, sizeof *run);
    run->island = island;
    run->level = level;
    uint32_t count = 0;
    const fx_effect *const *registry = fx_registry(&count);
    assert_true(effect < count);
    run->texel_bytes = registry[effect]->texel_bytes(s);
    uint32_t width = (s->islands[island].width + (1u << level) - 1) >> level;
    uint32_t height = (s->islands[island].height + (1u << level) - 1) >> level;
    run->blocks_x = (width + 7) / 8;
    run->blocks_y = (height + 7) / 8;
    run->block_count = run->blocks_x * run->blocks_y;
    run->lookup = calloc((size_t)run->block_count * 64, sizeof(uint32_t));
    run->payload = calloc((size_t)run->block_count * 64, run->texel_bytes);
    run->jobs = calloc(run->block_count, sizeof(fx_block_job));
    assert_true(run->lookup && run->payload && run->jobs);
    for (uint32_t by = 0; by < run->blocks_y; by++)
        for (uint32_t bx = 0; bx < run->blocks_x; bx++) {
            uint32_t b = by * run->blocks_x + bx;
            uint64_t mask = 0;
            for (uint32_t t = 0; t < 64; t++)
                if (bx * 8 + (t & 7) < width && by * 8 + (t >> 3) < height)
                    mask |= 1ull << t;
            fx_lookup_update(s, island, level, bx, by, mask, run->lookup + 64 * b);
            run->jobs[b] = (fx_block_job){.key = fxt_block_key(effect, island, level, bx, by),
                                          .island = island,
                                          .level = level,
                                          .block_x = bx,
                                          .block_y = by,
                                          .mask = mask,
                                          .lookup = run->lookup + 64 * b,
                                          .payload = run->payload + (size_t)64 * run->texel_bytes * b};
            run->texels += (uint64_t)__builtin_popcountll(mask);
        }
}

/* Releases a run's storage. */
void fxt_island_run_free(fxt_island_run *run)
{
    free(run->lookup);
    free(run->payload);
    free(run->jobs);
}

/* The embedded scene scaled by `scale` and moved by `offset` (every axis), with its sun, sky, AO radius and
 * camera transformed alike (the camera in double, as a scene description gives it); light intensities and
 * the sky multiplied by `intensity_scale`. Finalised at the automatic texel density, which follows the
 * scale, so the islands are the same in texels at every scale. */
scene *fxt_transformed_default(double scale, double offset, float intensity_scale)
{
    scene_error err = {0};
    scene *base = scene_create_default(NULL, &err);
    assert_non_null(base);
    scene *s = scene__alloc();
    assert_non_null(s);
    for (uint32_t m = 0; m < base->material_count; m++)
        assert_int_not_equal(scene__add_material(s, &base->materials[m], &err), UINT32_MAX);
    const double xform[16] = {scale, 0, 0, offset, 0, scale, 0, offset, 0, 0, scale, offset, 0, 0, 0, 1};
    for (uint32_t m = 0; m < base->mesh_count; m++) {
        const scene_mesh *mesh = &base->meshes[m];
        assert_int_equal(scene__add_mesh(s, mesh->name, base->positions, base->vertex_count,
                                         base->indices + 3 * (size_t)mesh->first_triangle,
                                         mesh->triangle_count, NULL, mesh->material, xform, &err),
                         SCENE_OK);
    }
    for (uint32_t l = 0; l < base->light_count; l++) {
        scene_light light = base->lights[l];
        light.intensity *= intensity_scale;
        assert_int_equal(scene__add_light(s, &light, "test light", &err), SCENE_OK);
    }
    memcpy(s->sky_color, base->sky_color, sizeof s->sky_color);
    s->sky_intensity = base->sky_intensity * intensity_scale;
    s->ao_radius = (float)(base->ao_radius * scale);
    if (base->has_camera) {
        double position[3], target[3];
        for (int k = 0; k < 3; k++) {
            position[k] = base->camera_pos[k] * scale + offset;
            target[k] = base->camera_target[k] * scale + offset;
        }
        assert_true(scene__set_camera_world(s, position, target, base->camera_fov_deg));
    }
    scene_free(base);
    assert_int_equal(scene__finalize(s, NULL, &err), SCENE_OK);
    return s;
}

void fxt_add_sphere(scene *s, float r, int levels)
{
    const float t = 1.6180339887f;
    float v0[12][3] = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                       {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
    uint32_t f0[20][3] = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                          {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                          {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
    uint32_t tri_count = 20;
    float(*tris)[3][3] = malloc(sizeof *tris * 20);
    for (uint32_t f = 0; f < 20; f++)
        for (int c = 0; c < 3; c++)
            memcpy(tris[f][c], v0[f0[f][c]], sizeof tris[f][c]);
    for (int l = 0; l < levels; l++) {
        float(*next)[3][3] = malloc(sizeof *next * tri_count * 4);
        for (uint32_t f = 0; f < tri_count; f++) {
            float m[3][3];
            for (int e = 0; e < 3; e++)
                for (int k = 0; k < 3; k++)
                    m[e][k] = 0.5f * (tris[f][e][k] + tris[f][(e + 1) % 3][k]);
            float(*o)[3][3] = next + 4 * f;
            memcpy(o[0][0], tris[f][0], 12), memcpy(o[0][1], m[0], 12), memcpy(o[0][2], m[2], 12);
            memcpy(o[1][0], tris[f][1], 12), memcpy(o[1][1], m[1], 12), memcpy(o[1][2], m[0], 12);
            memcpy(o[2][0], tris[f][2], 12), memcpy(o[2][1], m[2], 12), memcpy(o[2][2], m[1], 12);
            memcpy(o[3][0], m[0], 12), memcpy(o[3][1], m[1], 12), memcpy(o[3][2], m[2], 12);
        }
        free(tris);
        tris = next;
        tri_count *= 4;
    }
    float *positions = malloc(sizeof(float) * 9 * tri_count);
    uint32_t *indices = malloc(sizeof(uint32_t) * 3 * tri_count);
    for (uint32_t f = 0; f < tri_count; f++) {
        float p[3][3];
        for (int c = 0; c < 3; c++) {
            float len = sqrtf(tris[f][c][0] * tris[f][c][0] + tris[f][c][1] * tris[f][c][1] +
                              tris[f][c][2] * tris[f][c][2]);
            for (int k = 0; k < 3; k++)
                p[c][k] = tris[f][c][k] / len * r;
        }
        /* Inward: (p1 - p0) x (p2 - p0) must point towards the centre. */
        float e1[3], e2[3], n[3];
        for (int k = 0; k < 3; k++)
            e1[k] = p[1][k] - p[0][k], e2[k] = p[2][k] - p[0][k];
        n[0] = e1[1] * e2[2] - e1[2] * e2[1], n[1] = e1[2] * e2[0] - e1[0] * e2[2],
        n[2] = e1[0] * e2[1] - e1[1] * e2[0];
        bool outward = n[0] * p[0][0] + n[1] * p[0][1] + n[2] * p[0][2] > 0;
        for (int c = 0; c < 3; c++) {
            int src = outward && c > 0 ? 3 - c : c;
            memcpy(positions + 9 * f + 3 * c, p[src], 12);
            indices[3 * f + c] = 3 * f + (uint32_t)c;
        }
    }
    scene_error err;
    assert_int_equal(
        scene__add_mesh(s, "sphere", positions, 3 * tri_count, indices, tri_count, NULL, 0, NULL, &err),
        SCENE_OK);
    free(positions);
    free(indices);
    free(tris);
}

/* ---- the closed form of AO in a corner (test_crease.c, the stability suite) ---------------------------- */

/* Antiderivative of sqrt(1 - x^2) on [-1, 1]. */
static double half_disk_primitive(double x)
{
    x = fmin(fmax(x, -1.0), 1.0);
    return 0.5 * (x * sqrt(1 - x * x) + asin(x));
}

/* Area of the unit disk with x > -a and z > -b (a, b >= 0; INFINITY for no bound). */
static double disk_area_beyond(double a, double b)
{
    double lo = -fmin(a, 1.0);
    /* Integrate sqrt(1 - x^2) + min(sqrt(1 - x^2), b) over x in [lo, 1]. */
    double area = 2 * (half_disk_primitive(1) - half_disk_primitive(lo));
    if (b < 1) {
        double c = sqrt(1 - b * b), from = fmax(lo, -c);
        if (from < c)
            area -= half_disk_primitive(c) - half_disk_primitive(from) - b * (c - from);
    }
    return area;
}

double fxt_disk_open(double d1, double d2, double h, double radius)
{
    const double pi = 3.14159265358979323846;
    double a = d1 / radius, b = d2 / radius, open = disk_area_beyond(a, b);
    if (h < radius) {
        double rho = sqrt(1 - (h / radius) * (h / radius)); /* rays inside this disk reach the ceiling */
        open -= rho * rho * disk_area_beyond(a / rho, b / rho);
    }
    return open / pi;
}

/* A unit quad in the XZ plane facing up (+y), two triangles. */
const char fxt_quad_obj[] = "o quad\n"
                            "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\n"
                            "f 1 3 2\nf 1 4 3\n";

/* Writes quad.obj into the scratch folder, where the JSON files of these tests refer to it. */
const char *fxt_write_quad(void)
{
    return fxt_write_file("quad.obj", fxt_quad_obj);
}

/* Writes text as a JSON file name next to quad.obj, loads it into a fresh scene and finalises it; returns
 * the scene on success (caller frees) or NULL with err filled. */
scene *fxt_load_json_text(const char *name, const char *text, scene_error *err)
{
    fxt_write_quad();
    const char *path = fxt_write_file(name, text);
    char path_copy[1024];
    snprintf(path_copy, sizeof path_copy, "%s", path);
    scene *s = scene__alloc();
    assert_non_null(s);
    snprintf(s->source, sizeof s->source, "%s", path_copy); /* as scene_load() names it */
    memset(err, 0, sizeof *err);
    scene_result r = scene__load_json(s, path_copy, err);
    if (r == SCENE_OK) /* settles the local frame: positions, lights and camera relative to s->origin */
        r = scene__finalize(s, NULL, err);
    if (r != SCENE_OK) {
        assert_int_equal(err->code, r);
        scene_free(s);
        return NULL;
    }
    return s;
}

scene *fxt_load_ok(const char *path)
{
    scene_error err = {0};
    scene *s = scene_load(path, NULL, &err);
    if (!s)
        fail_msg("%s: %s", path, err.msg);
    return s;
}
