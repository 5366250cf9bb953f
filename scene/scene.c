/* The scene builder: the functions every loader (mesh file, JSON description, embedded scene) shares, and
 * the finalisation that turns the appended meshes into a read-only scene with islands.
 *
 * scene__add_mesh() is where untrusted geometry is checked: every coordinate finite (naming mesh and
 * vertex), every index in range; it stages the mesh in double and has scene_weld.c weld and clean it
 * (equal positions welded, degenerate and duplicate triangles dropped and counted). */
#include "scene_internal.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

/* Auto texel density aims at this many level-0 texels over the whole surface (4096 x 4096). */
#define SCENE_AUTO_TEXELS (4096.0 * 4096.0)

double scene__now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

scene *scene__alloc(void)
{
    scene *s = calloc(1, sizeof *s);
    if (!s)
        return NULL;
    s->density_auto = true;
    s->fx_shadows = s->fx_ao = s->fx_indirect = SCENE_AUTO;
    snprintf(s->source, sizeof s->source, "(unnamed)");
    return s;
}

/* ---- the local frame and the loading state ------------------------------------------------------------ */

typedef struct scene__builder scene__builder;

/* What a scene holds while it is being loaded (scene.builder); scene__finalize() releases it. */
struct scene__builder {
    bool frame_chosen;
    double frame_origin[3]; /* the provisional frame the meshes are welded in: the first mesh's */
    scene__staged_mesh *meshes;
    uint32_t mesh_count;
    double *light_world; /* 3 per light slot: the world position of the light in that slot, in double */
    uint32_t light_slots;
    bool camera_set; /* camera_pos/target hold the scene's camera in double */
    double camera_pos[3], camera_target[3];
    char source[256];       /* the file the next meshes come from (scene__set_source) */
    double input_step;      /* the coarsest input spacing seen, metres (float spacing x transform stretch) */
    double input_magnitude; /* the largest input coordinate of that mesh */
    double input_stretch;   /* its transform's largest stretch */
    char input_source[256]; /* its file, or its mesh name */
};

/* The builder of s, allocated on first use; NULL when out of memory. */
static scene__builder *builder_of(scene *s)
{
    if (!s->builder)
        s->builder = calloc(1, sizeof *s->builder);
    return s->builder;
}

static void staged_mesh_release(scene__staged_mesh *m)
{
    free(m->world);
    free(m->indices);
    free(m->uv);
    free(m->color);
    memset(m, 0, sizeof *m);
}

/* Releases a scene's loading state. */
static void builder_free(scene *s)
{
    scene__builder *b = s->builder;
    if (!b)
        return;
    for (uint32_t i = 0; i < b->mesh_count; i++)
        staged_mesh_release(&b->meshes[i]);
    free(b->meshes);
    free(b->light_world);
    free(b);
    s->builder = NULL;
}

void scene__set_source(scene *s, const char *label)
{
    scene__builder *b = builder_of(s);
    if (b)
        snprintf(b->source, sizeof b->source, "%s", label ? label : "");
}

static void bounds_reset(double lo[3], double hi[3])
{
    for (int k = 0; k < 3; k++) {
        lo[k] = INFINITY;
        hi[k] = -INFINITY;
    }
}

/* Extends lo..hi by the vertices the mesh's triangles use (stray unused vertices do not move the frame). */
static void staged_bounds(const scene__staged_mesh *m, double lo[3], double hi[3])
{
    for (size_t i = 0; i < 3 * (size_t)m->triangle_count; i++) {
        const double *p = m->world + 3 * (size_t)m->indices[i];
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], p[k]);
            hi[k] = fmax(hi[k], p[k]);
        }
    }
}

/* The origin of the local frame for geometry spanning lo..hi (world, double): (0, 0, 0) when the centre of
 * the box lies within one extent (its longest side) of the world origin, where rebasing would gain at most
 * 1.6 bits and world coordinates stay as they are; else the centre rounded to a multiple of the smallest
 * power of two >= the extent, and of at least 1 m. The rounding keeps the origin a whole number of metres
 * and makes a scene moved by such multiples (1e6 is one for extents up to 64 m) bit-identical in its local
 * frame; either way every local coordinate lies within max(1.5 extents, 1 m) of the origin. The 1 m floor
 * costs nothing the texel grid sees: below 1 m floats are at most 6e-8 m apart, under 1/16 of the finest
 * texel allowed (1e6 texels per metre). */
static void frame_origin_for(const double lo[3], const double hi[3], double origin[3])
{
    double centre[3], extent = 0, distance = 0;
    for (int k = 0; k < 3; k++) {
        centre[k] = 0.5 * lo[k] + 0.5 * hi[k];
        extent = fmax(extent, hi[k] - lo[k]);
        distance = fmax(distance, fabs(centre[k]));
    }
    if (!(distance > extent)) { /* also for empty bounds (NaN) */
        origin[0] = origin[1] = origin[2] = 0;
        return;
    }
    if (!(extent > 0)) { /* a single point far out: its own position */
        memcpy(origin, centre, sizeof centre);
        return;
    }
    double quantum = ldexp(1.0, ilogb(extent));
    if (quantum < extent)
        quantum *= 2;
    quantum = fmax(quantum, 1.0);
    for (int k = 0; k < 3; k++)
        origin[k] = nearbyint(centre[k] / quantum) * quantum + 0.0; /* + 0.0: no -0 in messages */
}

void scene_world_to_local(const scene *s, const double world[3], float local[3])
{
    for (int k = 0; k < 3; k++)
        local[k] = (float)(world[k] - s->origin[k]);
}

void scene_local_to_world(const scene *s, const float local[3], double world[3])
{
    for (int k = 0; k < 3; k++)
        world[k] = (double)local[k] + s->origin[k];
}

void scene_free(scene *s)
{
    if (!s)
        return;
    free(s->positions);
    free(s->indices);
    free(s->corner_uv);
    free(s->corner_color);
    free(s->tri_mesh);
    free(s->tri_normal);
    free(s->meshes);
    free(s->materials);
    for (uint32_t i = 0; i < s->texture_count; i++) {
        free(s->textures[i].rgb); /* level 0 (mip_rgb[0], when the chain was built) */
        for (uint32_t l = 1; l < s->textures[i].levels; l++)
            free(s->textures[i].mip_rgb[l]);
    }
    free(s->tri_texture_lod);
    free(s->tri_texture_mean);
    free(s->textures);
    free(s->lights);
    free(s->islands);
    free(s->island_triangles);
    free(s->tri_island);
    free(s->tri_local);
    free(s->tri_island_uv);
    builder_free(s);
    free(s);
}

/* Grows *array to hold count elements of size bytes; false (array untouched) on overflow or no memory. */
bool scene__grow(void **array, size_t count, size_t size)
{
    if (count != 0 && size > SIZE_MAX / count)
        return false;
    void *p = realloc(*array, count * size);
    if (!p && count)
        return false;
    *array = p;
    return true;
}

scene_result scene__add_light_world(scene *s, const scene_light *l, const double world_position[3],
                                    const char *where, scene_error *err)
{
    scene_light light = *l;
    if (!scene__finite3(light.color) || !isfinite(light.intensity))
        return scene__fail(err, SCENE_ERR_INVALID, "%s: light colour and intensity must be finite", where);
    if (light.intensity < 0 || light.color[0] < 0 || light.color[1] < 0 || light.color[2] < 0)
        return scene__fail(err, SCENE_ERR_RANGE, "%s: light colour and intensity must be >= 0", where);
    /* Every consumer multiplies colour by intensity first: an infinite product turns a shadowed point's
     * 0 x inf into NaN (rendered black where the light is brightest). */
    double brightest = fmax(fmax(light.color[0], light.color[1]), light.color[2]) * (double)light.intensity;
    if (brightest > FLT_MAX)
        return scene__fail(err, SCENE_ERR_INVALID,
                           "%s: light colour x intensity must fit a float (it is %g, at most %g)", where,
                           brightest, (double)FLT_MAX);
    double world[3] = {light.position[0], light.position[1], light.position[2]};
    if (light.type == SCENE_LIGHT_DIRECTIONAL) {
        if (!scene__finite3(light.direction))
            return scene__fail(err, SCENE_ERR_INVALID, "%s: light direction must be finite", where);
        double len = sqrt((double)light.direction[0] * light.direction[0] +
                          (double)light.direction[1] * light.direction[1] +
                          (double)light.direction[2] * light.direction[2]);
        if (!(len > 1e-20))
            return scene__fail(err, SCENE_ERR_INVALID, "%s: light direction must not be zero", where);
        for (int k = 0; k < 3; k++)
            light.direction[k] = (float)(light.direction[k] / len);
    } else {
        if (world_position)
            memcpy(world, world_position, sizeof world);
        for (int k = 0; k < 3; k++)
            light.position[k] = (float)world[k];
        if (!isfinite(world[0]) || !isfinite(world[1]) || !isfinite(world[2]) ||
            !scene__finite3(light.position))
            return scene__fail(err, SCENE_ERR_INVALID, "%s: light position must be finite", where);
    }
    /* The slot's world position in double; scene__finalize() moves the light into the local frame. */
    scene__builder *b = builder_of(s);
    uint32_t slot = s->light_count;
    if (!b || (slot >= b->light_slots &&
               !scene__grow((void **)&b->light_world, 3 * ((size_t)slot + 1), sizeof(double))))
        return scene__fail(err, SCENE_ERR_NOMEM, "out of memory adding a light");
    if (slot >= b->light_slots)
        b->light_slots = slot + 1;
    memcpy(b->light_world + 3 * (size_t)slot, world, sizeof world);
    if (!scene__grow((void **)&s->lights, (size_t)s->light_count + 1, sizeof *s->lights))
        return scene__fail(err, SCENE_ERR_NOMEM, "out of memory adding a light");
    s->lights[s->light_count++] = light;
    return SCENE_OK;
}

scene_result scene__add_light(scene *s, const scene_light *l, const char *where, scene_error *err)
{
    return scene__add_light_world(s, l, NULL, where, err);
}

bool scene__set_camera_world(scene *s, const double position[3], const double target[3], float fov_deg)
{
    scene__builder *b = builder_of(s);
    if (!b)
        return false;
    b->camera_set = true;
    memcpy(b->camera_pos, position, sizeof b->camera_pos);
    memcpy(b->camera_target, target, sizeof b->camera_target);
    s->has_camera = true;
    for (int k = 0; k < 3; k++) {
        s->camera_pos[k] = (float)position[k];
        s->camera_target[k] = (float)target[k];
    }
    s->camera_fov_deg = fov_deg;
    return true;
}

void scene__add_default_lighting(scene *s)
{
    scene_light sun = {.type = SCENE_LIGHT_DIRECTIONAL,
                       .direction = {-0.35f, -0.85f, -0.4f},
                       .color = {1.0f, 0.95f, 0.85f},
                       .intensity = 3.0f};
    scene__add_light(s, &sun, "default sun", NULL);
    s->sky_color[0] = 0.55f;
    s->sky_color[1] = 0.7f;
    s->sky_color[2] = 1.0f;
    s->sky_intensity = 0.6f;
}

/* ---- welding and cleaning ----------------------------------------------------------------------------- */

scene_result scene__add_mesh(scene *s, const char *name, const float *positions, uint32_t vertex_count,
                             const uint32_t *indices, uint32_t triangle_count, const float *uv,
                             uint32_t material, const double *xform, scene_error *err)
{
    return scene__add_mesh_colored(s, name, positions, vertex_count, indices, triangle_count, uv, NULL,
                                   material, xform, err);
}

scene_result scene__add_mesh_colored(scene *s, const char *name, const float *positions,
                                     uint32_t vertex_count, const uint32_t *indices, uint32_t triangle_count,
                                     const float *uv, const float *color, uint32_t material,
                                     const double *xform, scene_error *err)
{
    if (material >= s->material_count)
        return scene__fail(err, SCENE_ERR_INVALID, "mesh '%s': material %u out of range (%u materials)", name,
                           material, s->material_count);
    for (uint32_t v = 0; v < vertex_count; v++) {
        const float *p = positions + 3 * (size_t)v;
        if (!scene__finite3(p))
            return scene__fail(err, SCENE_ERR_INVALID,
                               "mesh '%s': vertex %u has a non-finite coordinate (%g, %g, %g)", name, v,
                               (double)p[0], (double)p[1], (double)p[2]);
    }
    for (size_t i = 0; i < 3 * (size_t)triangle_count; i++)
        if (indices[i] >= vertex_count)
            return scene__fail(err, SCENE_ERR_INVALID,
                               "mesh '%s': triangle %zu uses vertex %u, but the mesh has %u vertices", name,
                               i / 3, indices[i], vertex_count);
    if (triangle_count == 0)
        return SCENE_OK;

    scene__builder *b = builder_of(s);
    if (!b || !scene__grow((void **)&b->meshes, (size_t)b->mesh_count + 1, sizeof *b->meshes))
        return scene__fail(err, SCENE_ERR_NOMEM, "mesh '%s': out of memory", name);
    scene__staged_mesh *m = &b->meshes[b->mesh_count];
    memset(m, 0, sizeof *m);
    snprintf(m->name, sizeof m->name, "%s", name);
    m->vertex_count = vertex_count;
    m->triangle_count = triangle_count;
    m->material = material;
    m->mesh = UINT32_MAX;
    m->world = malloc(sizeof(double) * 3 * (size_t)vertex_count);
    m->indices = malloc(sizeof(uint32_t) * 3 * (size_t)triangle_count);
    m->uv = uv ? malloc(sizeof(float) * 2 * (size_t)vertex_count) : NULL;
    m->color = color ? malloc(sizeof(float) * 3 * (size_t)vertex_count) : NULL;
    if (!m->world || !m->indices || (uv && !m->uv) || (color && !m->color)) {
        staged_mesh_release(m);
        return scene__fail(err, SCENE_ERR_NOMEM, "mesh '%s': out of memory", name);
    }
    memcpy(m->indices, indices, sizeof(uint32_t) * 3 * (size_t)triangle_count);
    if (uv)
        memcpy(m->uv, uv, sizeof(float) * 2 * (size_t)vertex_count);
    for (size_t i = 0; color && i < 3 * (size_t)vertex_count; i++) /* an albedo factor: 0..1, NaN as 0 */
        m->color[i] = color[i] > 0.0f ? fminf(color[i], 1.0f) : 0.0f;

    /* The transform, in double. The input's own float spacing, times the transform's largest stretch, is the
     * finest the mesh can be, wherever it ends up. */
    double input_magnitude = 0, stretch = 1;
    for (uint32_t v = 0; v < vertex_count; v++) {
        const float *p = positions + 3 * (size_t)v;
        double *w = m->world + 3 * (size_t)v;
        for (int r = 0; r < 3; r++) {
            w[r] = xform ? xform[4 * r] * p[0] + xform[4 * r + 1] * p[1] + xform[4 * r + 2] * p[2] +
                               xform[4 * r + 3]
                         : (double)p[r];
            input_magnitude = fmax(input_magnitude, fabs((double)p[r]));
        }
        if (!(fabs(w[0]) <= FLT_MAX && fabs(w[1]) <= FLT_MAX && fabs(w[2]) <= FLT_MAX)) { /* and NaN */
            staged_mesh_release(m);
            return scene__fail(err, SCENE_ERR_INVALID,
                               "mesh '%s': vertex %u is not finite (as a float) after the mesh transform",
                               name, v);
        }
    }
    b->mesh_count++; /* owned by the builder from here on */
    if (xform) {
        stretch = 0;
        for (int col = 0; col < 3; col++)
            stretch = fmax(stretch, sqrt(xform[col] * xform[col] + xform[4 + col] * xform[4 + col] +
                                         xform[8 + col] * xform[8 + col]));
        double det = xform[0] * (xform[5] * xform[10] - xform[6] * xform[9]) -
                     xform[1] * (xform[4] * xform[10] - xform[6] * xform[8]) +
                     xform[2] * (xform[4] * xform[9] - xform[5] * xform[8]);
        m->mirrored = det < 0;
    }
    double input_step = scene__float_spacing(input_magnitude) * stretch;
    if (input_step > b->input_step) {
        b->input_step = input_step;
        b->input_magnitude = input_magnitude;
        b->input_stretch = stretch;
        snprintf(b->input_source, sizeof b->input_source, "%s", b->source[0] ? b->source : name);
    }

    if (!b->frame_chosen) {
        double lo[3], hi[3];
        bounds_reset(lo, hi);
        staged_bounds(m, lo, hi);
        frame_origin_for(lo, hi, b->frame_origin);
        b->frame_chosen = true;
    }
    return scene__commit_mesh(s, m, b->frame_origin, name, &m->mesh, err);
}

/* ---- finalisation ------------------------------------------------------------------------------------- */

double scene__longest_edge(const scene *s)
{
    double longest = 0;
    for (size_t t = 0; t < s->triangle_count; t++)
        for (int e = 0; e < 3; e++) {
            const float *a = s->positions + 3 * (size_t)s->indices[3 * t + (size_t)e];
            const float *b = s->positions + 3 * (size_t)s->indices[3 * t + (size_t)(e + 1) % 3];
            double dx = (double)b[0] - a[0], dy = (double)b[1] - a[1], dz = (double)b[2] - a[2];
            longest = fmax(longest, sqrt(dx * dx + dy * dy + dz * dz));
        }
    return longest;
}

double scene_triangle_area(const scene *s, uint32_t t)
{
    const float *a = s->positions + 3 * (size_t)s->indices[3 * (size_t)t];
    const float *b = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 1];
    const float *c = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 2];
    double e1[3], e2[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = (double)b[k] - a[k];
        e2[k] = (double)c[k] - a[k];
    }
    double cx = e1[1] * e2[2] - e1[2] * e2[1];
    double cy = e1[2] * e2[0] - e1[0] * e2[2];
    double cz = e1[0] * e2[1] - e1[1] * e2[0];
    return 0.5 * sqrt(cx * cx + cy * cy + cz * cz);
}

double scene_surface_area(const scene *s)
{
    double area = 0;
    for (uint32_t t = 0; t < s->triangle_count; t++)
        area += scene_triangle_area(s, t);
    return area;
}

/* Unit geometric normals (counter-clockwise corners seen from the front) and the bounding box. */
static scene_result compute_normals_and_bounds(scene *s, scene_error *err)
{
    free(s->tri_normal);
    s->tri_normal = malloc(sizeof(float) * 3 * (size_t)s->triangle_count);
    if (!s->tri_normal)
        return scene__fail(err, SCENE_ERR_NOMEM, "out of memory computing normals");
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        const float *a = s->positions + 3 * (size_t)s->indices[3 * (size_t)t];
        const float *b = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 1];
        const float *c = s->positions + 3 * (size_t)s->indices[3 * (size_t)t + 2];
        double e1[3], e2[3], n[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = (double)b[k] - a[k];
            e2[k] = (double)c[k] - a[k];
        }
        n[0] = e1[1] * e2[2] - e1[2] * e2[1];
        n[1] = e1[2] * e2[0] - e1[0] * e2[2];
        n[2] = e1[0] * e2[1] - e1[1] * e2[0];
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int k = 0; k < 3; k++)
            s->tri_normal[3 * (size_t)t + k] = len > 0 ? (float)(n[k] / len) : (k == 2 ? 1.0f : 0.0f);
    }
    for (int k = 0; k < 3; k++) {
        s->bounds_min[k] = INFINITY;
        s->bounds_max[k] = -INFINITY;
    }
    for (uint32_t v = 0; v < s->vertex_count; v++)
        for (int k = 0; k < 3; k++) {
            float x = s->positions[3 * (size_t)v + k];
            s->bounds_min[k] = fminf(s->bounds_min[k], x);
            s->bounds_max[k] = fmaxf(s->bounds_max[k], x);
        }
    double diag2 = 0;
    for (int k = 0; k < 3; k++)
        diag2 +=
            ((double)s->bounds_max[k] - s->bounds_min[k]) * ((double)s->bounds_max[k] - s->bounds_min[k]);
    s->ray_offset_scale = (float)fmin(1.0, fmax(sqrt(diag2), 1e-30));
    return SCENE_OK;
}

static scene_result settle_frame(scene *s, scene_error *err)
{
    scene__builder *b = s->builder;
    if (!b)
        return SCENE_OK; /* built by hand: positions are already where they stay */
    double lo[3], hi[3], origin[3] = {0, 0, 0};
    bounds_reset(lo, hi);
    for (uint32_t i = 0; i < b->mesh_count; i++)
        staged_bounds(&b->meshes[i], lo, hi);
    if (b->mesh_count)
        frame_origin_for(lo, hi, origin);

    if (b->frame_chosen && memcmp(origin, b->frame_origin, sizeof origin) != 0) {
        scene_mesh *old_meshes = s->meshes;
        uint32_t old_mesh_count = s->mesh_count;
        free(s->positions);
        free(s->indices);
        free(s->corner_uv);
        free(s->corner_color);
        free(s->tri_mesh);
        s->positions = NULL;
        s->indices = NULL;
        s->corner_uv = NULL;
        s->corner_color = NULL;
        s->tri_mesh = NULL;
        s->meshes = NULL;
        s->vertex_count = s->triangle_count = s->mesh_count = 0;
        s->repairs.vertices_welded = s->repairs.degenerate_skipped = s->repairs.duplicate_skipped = 0;
        s->repairs.precision_skipped = 0;
        s->repairs.precision_reach = 0;
        scene_result rc = SCENE_OK;
        for (uint32_t i = 0; i < b->mesh_count && rc == SCENE_OK; i++) {
            scene__staged_mesh *m = &b->meshes[i];
            /* The name as the loader left it (a JSON scene renames meshes after import). */
            const char *name = m->mesh < old_mesh_count ? old_meshes[m->mesh].name : m->name;
            char kept_name[sizeof m->name];
            snprintf(kept_name, sizeof kept_name, "%s", name);
            rc = scene__commit_mesh(s, m, origin, kept_name, &m->mesh, err);
        }
        free(old_meshes);
        if (rc != SCENE_OK)
            return rc;
    }
    memcpy(s->origin, origin, sizeof origin);

    /* A slot's double position applies while the float there is still its rounding (nobody replaced it). */
    for (uint32_t i = 0; i < s->light_count; i++) {
        scene_light *l = &s->lights[i];
        if (l->type != SCENE_LIGHT_POINT)
            continue;
        double world[3] = {l->position[0], l->position[1], l->position[2]};
        const double *slot = i < b->light_slots ? b->light_world + 3 * (size_t)i : NULL;
        if (slot && (float)slot[0] == l->position[0] && (float)slot[1] == l->position[1] &&
            (float)slot[2] == l->position[2])
            memcpy(world, slot, sizeof world);
        scene_world_to_local(s, world, l->position);
    }
    if (s->has_camera) {
        double pos[3], target[3];
        bool precise = b->camera_set;
        for (int k = 0; k < 3; k++) {
            precise = precise && (float)b->camera_pos[k] == s->camera_pos[k] &&
                      (float)b->camera_target[k] == s->camera_target[k];
            pos[k] = s->camera_pos[k];
            target[k] = s->camera_target[k];
        }
        if (precise) {
            memcpy(pos, b->camera_pos, sizeof pos);
            memcpy(target, b->camera_target, sizeof target);
        }
        scene_world_to_local(s, pos, s->camera_pos);
        scene_world_to_local(s, target, s->camera_target);
    }
    return SCENE_OK;
}

/* The spacing of the stored positions against the texel size: fills position_step and, when positions are
 * more than SCENE_PRECISION_TEXEL_FRACTION of a texel apart, precision_warning (naming the file whose float
 * input limits them, or the extent of the local frame). */
static void assess_precision(scene *s)
{
    double reach = 0;
    for (int k = 0; k < 3; k++)
        reach = fmax(reach, fmax(fabs((double)s->bounds_min[k]), fabs((double)s->bounds_max[k])));
    double local_step = scene__float_spacing(reach);
    const scene__builder *b = s->builder;
    double input_step = b ? b->input_step : 0;
    s->position_step = fmax(local_step, input_step);
    s->precision_warning[0] = 0;
    if (s->repairs.precision_skipped) {
        snprintf(
            s->precision_warning, sizeof s->precision_warning,
            "%s: %llu triangle(s) with an area dropped as degenerate: they collapse at float precision up "
            "to %.4g m from the local origin, where floats are %.3g m apart; keep distant parts in a scene "
            "of their own, or scale the scene down",
            s->source, (unsigned long long)s->repairs.precision_skipped, s->repairs.precision_reach,
            scene__float_spacing(s->repairs.precision_reach));
        return;
    }
    double texel = 1.0 / (double)s->texel_density;
    if (!(s->position_step > SCENE_PRECISION_TEXEL_FRACTION * texel))
        return;
    if (input_step > local_step) {
        char stretch[64] = "";
        if (b->input_stretch != 1.0)
            snprintf(stretch, sizeof stretch, ", stretched %.4g times by the mesh transform",
                     b->input_stretch);
        snprintf(
            s->precision_warning, sizeof s->precision_warning,
            "%s: its coordinates (up to %.7g%s) arrive as 32-bit floats, so positions are %.3g m apart: "
            "%.3g texels at %.4g texels per metre (more than 1/%.0f texel); keep a model near the origin "
            "in its own file and place it with a scene transform",
            b->input_source, b->input_magnitude, stretch, input_step, input_step / texel,
            (double)s->texel_density, 1.0 / SCENE_PRECISION_TEXEL_FRACTION);
    } else {
        snprintf(s->precision_warning, sizeof s->precision_warning,
                 "%s: the scene reaches %.4g m from its local origin, where floats are %.3g m apart: %.3g "
                 "texels at %.4g texels per metre (more than 1/%.0f texel); lower the texel density or split "
                 "the scene",
                 s->source, reach, local_step, local_step / texel, (double)s->texel_density,
                 1.0 / SCENE_PRECISION_TEXEL_FRACTION);
    }
}

/* Largest |coordinate| of a point. */
static double reach_of(const float p[3])
{
    return fmax(fabs((double)p[0]), fmax(fabs((double)p[1]), fabs((double)p[2])));
}

/* Refuses geometry or point lights farther than SCENE_MAX_REACH from the local origin, or the scene's camera
 * farther than SCENE_MAX_CAMERA_REACH (after the frame is settled and the bounds are known). */
static scene_result check_reach(const scene *s, scene_error *err)
{
    double reach = fmax(reach_of(s->bounds_min), reach_of(s->bounds_max)), extent = 0;
    for (int k = 0; k < 3; k++)
        extent = fmax(extent, (double)s->bounds_max[k] - (double)s->bounds_min[k]);
    if (!(extent >=
          SCENE_MIN_EXTENT * (1 - 1e-6))) /* the bound itself loads, within the bounds' float rounding */
        return scene__fail(
            err, SCENE_ERR_RANGE,
            "%s: the geometry spans only %.4g m; fxcache handles scenes at least %.0e m across "
            "(below, float products of its lengths leave the normal range and shadows, AO and "
            "probes come out wrong): scale the scene up with a transform",
            s->source, extent, SCENE_MIN_EXTENT);
    if (!(reach <= SCENE_MAX_REACH))
        return scene__fail(
            err, SCENE_ERR_RANGE,
            "%s: the geometry spans %.4g m from its centre; fxcache handles at most %.0e m (squared "
            "distances must fit a float): scale the scene down or split it",
            s->source, reach, SCENE_MAX_REACH);
    for (uint32_t i = 0; i < s->light_count; i++)
        if (s->lights[i].type == SCENE_LIGHT_POINT && !(reach_of(s->lights[i].position) <= SCENE_MAX_REACH))
            return scene__fail(
                err, SCENE_ERR_RANGE,
                "%s: lights[%u] (point) lies %.4g m from the scene's centre; at most %.0e m (squared "
                "distances must fit a float): use a directional light for a far source",
                s->source, i, reach_of(s->lights[i].position), SCENE_MAX_REACH);
    if (s->has_camera &&
        !(fmax(reach_of(s->camera_pos), reach_of(s->camera_target)) <= SCENE_MAX_CAMERA_REACH))
        return scene__fail(err, SCENE_ERR_RANGE,
                           "%s: the camera lies %.4g m from the scene's centre; at most %.0e m", s->source,
                           fmax(reach_of(s->camera_pos), reach_of(s->camera_target)), SCENE_MAX_CAMERA_REACH);
    return SCENE_OK;
}

/* Why every triangle came out degenerate when the transforms, not the file, did it: the meshes placed
 * (in double) so far from the world origin that doubles there are coarser than the smallest scene (a
 * translate of 1e38 m), or stretched beyond SCENE_MAX_REACH (a scale of [1e20, 1e-20, 1]); "" otherwise. */
static void empty_scene_cause(const scene *s, char *out, size_t cap)
{
    const scene__builder *b = s->builder;
    out[0] = 0;
    if (!b || !b->mesh_count || !s->repairs.degenerate_skipped)
        return;
    double lo[3], hi[3], far = 0, extent = 0;
    bounds_reset(lo, hi);
    for (uint32_t i = 0; i < b->mesh_count; i++)
        staged_bounds(&b->meshes[i], lo, hi);
    for (int k = 0; k < 3; k++) {
        far = fmax(far, fmax(fabs(lo[k]), fabs(hi[k])));
        extent = fmax(extent, hi[k] - lo[k]);
    }
    if (extent > 2 * SCENE_MAX_REACH)
        snprintf(out, cap,
                 ": the meshes span %.4g m, and fxcache handles at most %.0e m from the scene's centre (a "
                 "transform's scale?)",
                 extent, SCENE_MAX_REACH);
    else if (far * DBL_EPSILON > SCENE_MIN_EXTENT)
        snprintf(out, cap,
                 ": the meshes lie %.4g m from the world origin, where even doubles are about %.3g m apart; "
                 "place them nearer to it",
                 far, far * DBL_EPSILON);
}

scene_result scene__finalize(scene *s, const scene_load_desc *desc, scene_error *err)
{
    scene_result settled = settle_frame(s, err);
    if (settled != SCENE_OK)
        return settled;
    if (s->triangle_count == 0) {
        char lost[160], where[240] = "";
        scene__precision_lost(&s->repairs, 0, lost, sizeof lost);
        empty_scene_cause(s, where, sizeof where);
        return scene__fail(err, SCENE_ERR_EMPTY,
                           "%s: the scene has no triangles (%llu duplicate and %llu "
                           "degenerate skipped%s)%s",
                           s->source, (unsigned long long)s->repairs.duplicate_skipped,
                           (unsigned long long)s->repairs.degenerate_skipped, lost, where);
    }
    double t0 = scene__now_ms();
    scene_result rc = compute_normals_and_bounds(s, err);
    if (rc == SCENE_OK)
        rc = check_reach(s, err);
    if (rc != SCENE_OK)
        return rc;
    if (desc && desc->texel_density != 0) {
        if (!(desc->texel_density >= 1e-6f) || !(desc->texel_density <= 1e6f))
            return scene__fail(err, SCENE_ERR_RANGE,
                               "texel density %g is outside [1e-6, 1e6] texels per metre",
                               (double)desc->texel_density);
        s->texel_density = desc->texel_density;
        s->density_auto = false;
    }
    if (s->density_auto || !(s->texel_density > 0)) {
        double area = scene_surface_area(s);
        s->texel_density = area > 0 ? (float)sqrt(SCENE_AUTO_TEXELS / area) : 1.0f;
        s->density_auto = true;
        /* A triangle spans at most its longest edge in any direction, so its island needs at most that times
         * the density plus a border of texels a side: the auto density stays low enough for every triangle
         * to fit. A sliver 1000 m by 1 mm (0.5 m^2 of surface) was refused at its own auto density with
         * "lower the texel density", which the user never set. An explicit density is kept and refused. */
        double longest = scene__longest_edge(s);
        double fits = (SCENE_MAX_ISLAND_TEXELS - 4) / longest;
        if (longest > 0 && s->texel_density > fits)
            s->texel_density = (float)(0.999 * fits);
    }
    if (!(s->ao_radius > 0)) {
        double dx = s->bounds_max[0] - s->bounds_min[0], dy = s->bounds_max[1] - s->bounds_min[1],
               dz = s->bounds_max[2] - s->bounds_min[2];
        s->ao_radius = (float)(0.1 * sqrt(dx * dx + dy * dy + dz * dz));
        if (!(s->ao_radius > 0))
            s->ao_radius = 1.0f;
    }
    rc = scene__compute_texture_lods(s, err);
    if (rc != SCENE_OK)
        return rc;
    rc = scene__compute_texture_means(s, err);
    if (rc != SCENE_OK)
        return rc;
    assess_precision(s);
    builder_free(s); /* the scene is read-only from here on */
    s->timings.weld_ms += scene__now_ms() - t0;
    t0 = scene__now_ms();
    rc = scene__build_islands(s, err);
    s->timings.islands_ms = scene__now_ms() - t0;
    scene_emission_refresh(s);
    return rc;
}

/* ---- loading ------------------------------------------------------------------------------------------ */

static bool ends_with(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    if (m > n)
        return false;
    for (size_t i = 0; i < m; i++) {
        char a = s[n - m + i], b = suffix[i];
        if (a >= 'A' && a <= 'Z')
            a = (char)(a - 'A' + 'a');
        if (a != b)
            return false;
    }
    return true;
}

scene_result scene__check_file(const char *path, scene_error *err)
{
    struct stat st;
    if (stat(path, &st) != 0)
        return scene__fail(err, SCENE_ERR_IO, "%s: cannot read: %s", path, strerror(errno));
    if (S_ISDIR(st.st_mode))
        return scene__fail(err, SCENE_ERR_IO, "%s: is a directory, not a file", path);
    if (!S_ISREG(st.st_mode))
        return scene__fail(err, SCENE_ERR_IO, "%s: not a regular file (a %s)", path,
                           S_ISFIFO(st.st_mode)   ? "FIFO"
                           : S_ISSOCK(st.st_mode) ? "socket"
                                                  : "device");
    FILE *probe = fopen(path, "rb");
    if (!probe)
        return scene__fail(err, SCENE_ERR_IO, "%s: cannot read: %s", path, strerror(errno));
    fclose(probe);
    return SCENE_OK;
}

scene *scene_create_default(const scene_load_desc *desc, scene_error *err)
{
    return scene_load(NULL, desc, err);
}

scene *scene_load(const char *path, const scene_load_desc *desc, scene_error *err)
{
    scene *s = scene__alloc();
    if (!s) {
        scene__fail(err, SCENE_ERR_NOMEM, "out of memory");
        return NULL;
    }
    double t0 = scene__now_ms();
    scene_result rc;
    if (!path || strcmp(path, "default") == 0) {
        snprintf(s->source, sizeof s->source, "(embedded default scene)");
        rc = scene__build_default(s, err);
    } else if (ends_with(path, ".json")) {
        snprintf(s->source, sizeof s->source, "%s", path);
        rc = scene__check_file(path, err);
        if (rc == SCENE_OK)
            rc = scene__load_json(s, path, err);
    } else {
        snprintf(s->source, sizeof s->source, "%s", path);
        scene__set_source(s, path);
        scene_file_lights file = {0};
        rc = scene__import_file_lit(s, path, &file, err);
        /* The file's own lights (and its ambient light, as the sky) replace the default sun and sky, as a
         * scene description's do. A file whose lamps emit is lit by them (a Cornell box's light): no sun and
         * sky. Emitters that cover most of the surface are a glow (an MS3D or FBX "emissive" colour): the
         * defaults stay. */
        scene_emission_refresh(s);
        bool lit_by_file = file.lights > 0 || file.sky;
        if (rc == SCENE_OK && !lit_by_file &&
            (!s->emissive || scene_emission_area_fraction(s) > SCENE_LAMP_AREA_FRACTION)) {
            scene__add_default_lighting(s);
            s->default_lighting = true;
        }
    }
    s->timings.load_ms = scene__now_ms() - t0 - s->timings.weld_ms - s->timings.textures_ms;
    if (rc == SCENE_OK)
        rc = scene__finalize(s, desc, err);
    if (rc != SCENE_OK && path && strcmp(path, "default") != 0 && err && !strstr(err->msg, path)) {
        /* name the file when the message does not (a mesh's vertex, a triangle too wide for an island) */
        char inner[sizeof err->msg];
        snprintf(inner, sizeof inner, "%s", err->msg);
        scene__fail(err, rc, "%s: %s", path, inner);
    }
    if (rc != SCENE_OK) {
        scene_free(s);
        return NULL;
    }
    return s;
}

/* ---- materials ---------------------------------------------------------------------------------------- */
