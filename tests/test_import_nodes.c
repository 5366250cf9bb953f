/* Mesh files as users bring them (scene/scene_import.c): node transforms (nested, non-uniform, mirrored
 * instances, one mesh placed twice), units, and the lights and cameras a file carries. Each expectation is
 * a closed form worked out by hand from the file written here, or a figure of a Debian test model (skipped
 * with a message when assimp-testmodels is absent). */
#include "test_util.h"

#include "fxt_scene.h"

#include "camera.h"
#include "engine.h"
#include "image.h"
#include "reference.h"
#include "scene_internal.h"

#include <assimp/cimport.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

/* Where Debian's assimp-testmodels puts Assimp's own test models. */
#define ASSIMP_MODELS "/usr/share/assimp/models"

/* A closed unit cube centred on its origin, faces counter-clockwise seen from outside, normals outward, as a
 * glTF 2 buffer "cube.bin" beside name; `nodes` and `extra` are JSON text for the "nodes" array (each node
 * with "mesh": 0 places the cube) and any further top-level members (lights, cameras), `scene_nodes` the
 * root nodes. Returns the .gltf path. */
static const char *write_cube_gltf(const char *name, const char *nodes, const char *scene_nodes,
                                   const char *extra)
{
    static const int faces[6][3][3] = {
        {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {{-1, 0, 0}, {0, 0, 1}, {0, 1, 0}},
        {{0, 1, 0}, {0, 0, 1}, {1, 0, 0}}, {{0, -1, 0}, {1, 0, 0}, {0, 0, 1}},
        {{0, 0, 1}, {1, 0, 0}, {0, 1, 0}}, {{0, 0, -1}, {0, 1, 0}, {1, 0, 0}},
    };
    static const int corners[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
    float positions[24][3], normals[24][3];
    uint16_t indices[36];
    for (int f = 0; f < 6; f++) {
        for (int c = 0; c < 4; c++)
            for (int k = 0; k < 3; k++) {
                positions[4 * f + c][k] = 0.5f * (float)(faces[f][0][k] + corners[c][0] * faces[f][1][k] +
                                                         corners[c][1] * faces[f][2][k]);
                normals[4 * f + c][k] = (float)faces[f][0][k];
            }
        const uint16_t quad[6] = {0, 1, 2, 0, 2, 3};
        for (int i = 0; i < 6; i++)
            indices[6 * f + i] = (uint16_t)(4 * f + quad[i]);
    }
    FILE *bin = fopen(fxt_tmp_path("cube.bin"), "wb");
    assert_non_null(bin);
    assert_int_equal(fwrite(positions, sizeof positions, 1, bin), 1);
    assert_int_equal(fwrite(normals, sizeof normals, 1, bin), 1);
    assert_int_equal(fwrite(indices, sizeof indices, 1, bin), 1);
    fclose(bin);
    static char text[8192];
    snprintf(text, sizeof text,
             "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":%s}],\"nodes\":%s,"
             "\"meshes\":[{\"name\":\"cube\",\"primitives\":[{\"attributes\":{\"POSITION\":0,\"NORMAL\":1},"
             "\"indices\":2,\"material\":0}]}],"
             "\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorFactor\":[0.5,0.5,0.5,1],"
             "\"metallicFactor\":0}}],"
             "\"buffers\":[{\"byteLength\":648,\"uri\":\"cube.bin\"}],"
             "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":288},"
             "{\"buffer\":0,\"byteOffset\":288,\"byteLength\":288},"
             "{\"buffer\":0,\"byteOffset\":576,\"byteLength\":72}],"
             "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":24,\"type\":\"VEC3\","
             "\"min\":[-0.5,-0.5,-0.5],\"max\":[0.5,0.5,0.5]},"
             "{\"bufferView\":1,\"componentType\":5126,\"count\":24,\"type\":\"VEC3\"},"
             "{\"bufferView\":2,\"componentType\":5123,\"count\":36,\"type\":\"SCALAR\"}]%s%s}",
             scene_nodes, nodes, extra ? "," : "", extra ? extra : "");
    return fxt_write_file(name, text);
}

/* The centroid of triangle t in world coordinates. */
static void centroid_world(const scene *s, uint32_t t, double out[3])
{
    for (int k = 0; k < 3; k++) {
        double sum = 0;
        for (int c = 0; c < 3; c++)
            sum += s->positions[3 * (size_t)s->indices[3 * (size_t)t + c] + k];
        out[k] = sum / 3 + s->origin[k];
    }
}

/* Three instances of one cube: as it is, mirrored by a node of scale [-1, 1, 1] (centre x = 3), and under a
 * parent of scale [2, 1, 1] with a child rotated 45 degrees about z (centre z = 3). Every triangle of every
 * instance must face away from its instance's centre (a closed cube's outside): before, Assimp's pre-transform
 * left the mirrored cube's 12 triangles facing inwards. The surface area and the sheared cube's normals are
 * computed by hand below. */
static void test_mirrored_instance_faces_outwards(void **state)
{
    (void)state;
    const char *path = write_cube_gltf(
        "instances.gltf",
        "[{\"mesh\":0,\"name\":\"plain\"},"
        "{\"mesh\":0,\"name\":\"mirrored\",\"scale\":[-1,1,1],\"translation\":[3,0,0]},"
        "{\"name\":\"parent\",\"scale\":[2,1,1],\"children\":[3]},"
        "{\"mesh\":0,\"name\":\"child\",\"rotation\":[0,0,0.38268343,0.92387953],\"translation\":[0,0,3]}]",
        "[0,1,2]", NULL);
    scene *s = fxt_load_ok(path);
    assert_int_equal(s->triangle_count, 36); /* three instances of 12 */
    const double centres[3][3] = {{0, 0, 0}, {3, 0, 0}, {0, 0, 3}};
    uint32_t per_instance[3] = {0, 0, 0};
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        double c[3];
        centroid_world(s, t, c);
        int instance = c[0] > 1.5 ? 1 : (c[2] > 1.5 ? 2 : 0);
        per_instance[instance]++;
        double outward = 0;
        for (int k = 0; k < 3; k++)
            outward += (double)s->tri_normal[3 * (size_t)t + k] * (c[k] - centres[instance][k]);
        if (!(outward > 0))
            fail_msg("triangle %u of instance %d faces inwards (normal %g %g %g at %g %g %g)", t, instance,
                     (double)s->tri_normal[3 * t], (double)s->tri_normal[3 * t + 1],
                     (double)s->tri_normal[3 * t + 2], c[0], c[1], c[2]);
    }
    for (int i = 0; i < 3; i++)
        assert_int_equal(per_instance[i], 12);
    /* The sheared instance: M = S(2,1,1) R_z(45). Its x and y edges become (sqrt2, sqrt2/2, 0) and
     * (-sqrt2, sqrt2/2, 0) (length sqrt(2.5)), its z edge stays 1: two faces of |(a x b)| = 2 (the parallelogram
     * spanned by the x and y edges: |sqrt2 * sqrt2/2 + sqrt2 * sqrt2/2| = 2) and four of sqrt(2.5) by 1. */
    double expected = 6 + 6 + 2 * 2 + 4 * sqrt(2.5);
    assert_true(fabs(scene_surface_area(s) - expected) < 1e-5);
    /* Non-uniform scale: the +x face's normal is the inverse transpose's image of (1, 0, 0):
     * S^-1 R (1,0,0) = (0.5 cos45, sin45, 0), normalised (1/sqrt5, 2/sqrt5, 0). */
    bool found = false;
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        double c[3];
        centroid_world(s, t, c);
        const float *n = s->tri_normal + 3 * (size_t)t;
        if (c[2] > 1.5 && c[0] > 0.2 && c[1] > 0.2) {
            found = true;
            assert_true(fabs(n[0] - 1 / sqrt(5.0)) < 1e-5 && fabs(n[1] - 2 / sqrt(5.0)) < 1e-5);
        }
    }
    assert_true(found);
    /* Each instance has islands of its own, and the mirrored copy's add up to the plain one's texels. */
    uint64_t island_texels[3] = {0, 0, 0};
    for (uint32_t i = 0; i < s->island_count; i++) {
        const scene_island *island = &s->islands[i];
        int instance = -1;
        for (uint32_t k = 0; k < island->triangle_count; k++) {
            double c[3];
            centroid_world(s, s->island_triangles[island->first + k], c);
            int here = c[0] > 1.5 ? 1 : (c[2] > 1.5 ? 2 : 0);
            assert_true(instance < 0 || instance == here);
            instance = here;
        }
        island_texels[instance] += (uint64_t)island->width * island->height;
    }
    assert_true(island_texels[0] > 0);
    assert_true(island_texels[0] == island_texels[1]);
    scene_free(s);
}

/* The world bounds of a file's pre-transformed vertices as Assimp gives them without fxcache (its own units). */
static void assimp_raw_bounds(const char *path, double lo[3], double hi[3])
{
    const struct aiScene *ai =
        aiImportFile(path, aiProcess_Triangulate | aiProcess_PreTransformVertices | aiProcess_SortByPType);
    assert_non_null(ai);
    for (int k = 0; k < 3; k++) {
        lo[k] = INFINITY;
        hi[k] = -INFINITY;
    }
    for (uint32_t i = 0; i < ai->mNumMeshes; i++)
        for (uint32_t v = 0; v < ai->mMeshes[i]->mNumVertices; v++) {
            const double p[3] = {ai->mMeshes[i]->mVertices[v].x, ai->mMeshes[i]->mVertices[v].y,
                                 ai->mMeshes[i]->mVertices[v].z};
            for (int k = 0; k < 3; k++) {
                lo[k] = fmin(lo[k], p[k]);
                hi[k] = fmax(hi[k], p[k]);
            }
        }
    aiReleaseImport(ai);
}

/* An FBX file in centimetres (UnitScaleFactor 1, Assimp's cubes_with_names.fbx) loads in metres: its bounds
 * are the file's own coordinates times 0.01. Before, a 21 cm model was 21 m wide, so a glTF (metres) beside
 * it in a scene description was a hundred times too small, and its lights' falloff was off. */
static void test_fbx_centimetres_become_metres(void **state)
{
    (void)state;
    const char *path = ASSIMP_MODELS "/FBX/cubes_with_names.fbx";
    if (access(path, R_OK) != 0) {
        print_message("skipped: %s is absent (Debian's assimp-testmodels)\n", path);
        skip();
    }
    double lo[3], hi[3];
    assimp_raw_bounds(path, lo, hi);
    scene *s = fxt_load_ok(path);
    for (int k = 0; k < 3; k++) {
        double world_lo = s->bounds_min[k] + s->origin[k], world_hi = s->bounds_max[k] + s->origin[k];
        assert_true(fabs(world_lo - 0.01 * lo[k]) < 1e-6 && fabs(world_hi - 0.01 * hi[k]) < 1e-6);
    }
    assert_true(hi[0] - lo[0] > 20); /* the file's 21 units (centimetres) */
    scene_free(s);
}

/* A Collada file in centimetres with Z up: Assimp's Collada reader applies both itself (checked, already
 * right): a 100 x 100 cm quad at z = 200 cm is a 1 m quad 2 m up in fxcache's y-up world. */
static void test_collada_unit_and_up_axis(void **state)
{
    (void)state;
    const char *path = fxt_write_file(
        "zup_cm.dae",
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n"
        "<COLLADA xmlns=\"http://www.collada.org/2005/11/COLLADASchema\" version=\"1.4.1\">\n"
        "<asset><unit name=\"centimeter\" meter=\"0.01\"/><up_axis>Z_UP</up_axis></asset>\n"
        "<library_geometries><geometry id=\"quad\" name=\"quad\"><mesh>\n"
        "<source id=\"p\"><float_array id=\"pa\" count=\"12\">-50 -50 0 50 -50 0 50 50 0 -50 50 "
        "0</float_array>\n"
        "<technique_common><accessor source=\"#pa\" count=\"4\" stride=\"3\"><param name=\"X\" "
        "type=\"float\"/><param name=\"Y\" type=\"float\"/><param name=\"Z\" type=\"float\"/>"
        "</accessor></technique_common></source>\n"
        "<vertices id=\"v\"><input semantic=\"POSITION\" source=\"#p\"/></vertices>\n"
        "<triangles count=\"2\"><input semantic=\"VERTEX\" source=\"#v\" offset=\"0\"/><p>0 1 2 0 2 3</p>"
        "</triangles>\n</mesh></geometry></library_geometries>\n"
        "<library_visual_scenes><visual_scene id=\"S\" name=\"S\"><node id=\"q\" name=\"q\">"
        "<translate>0 0 200</translate><instance_geometry url=\"#quad\"/></node></visual_scene>"
        "</library_visual_scenes>\n<scene><instance_visual_scene url=\"#S\"/></scene>\n</COLLADA>\n");
    scene *s = fxt_load_ok(path);
    const double lo[3] = {-0.5, 2, -0.5}, hi[3] = {0.5, 2, 0.5};
    for (int k = 0; k < 3; k++) {
        assert_true(fabs(s->bounds_min[k] + s->origin[k] - lo[k]) < 1e-6);
        assert_true(fabs(s->bounds_max[k] + s->origin[k] - hi[k]) < 1e-6);
    }
    assert_true(fabs(scene_surface_area(s) - 1.0) < 1e-6);
    assert_true(s->tri_normal[1] > 0.999f); /* counter-clockwise seen from +z in the file: up */
    scene_free(s);
}

/* Loads a plain mesh file with its lights and camera through the loader's own steps, as scene_load does. */
static scene *load_lit(const char *path, scene_file_lights *found)
{
    scene_error err = {0};
    scene *s = scene__alloc();
    assert_non_null(s);
    if (scene__import_file_lit(s, path, found, &err) != SCENE_OK ||
        scene__finalize(s, NULL, &err) != SCENE_OK)
        fail_msg("%s: %s", path, err.msg);
    return s;
}

/* A model in millimetres or kilometres (the same cubes under a root node of scale 1e-3 or 1e3): the scene-scale
 * defaults follow its size (checked, already right): the ambient-occlusion radius is a tenth of the bounds'
 * diagonal, exactly a million times apart; the probes' finest cell, a power of two near a 64th of it, a
 * million times apart within the power of two (2^20 = 1.05e6); the default camera stands 1.1 diagonals from
 * the centre at both sizes. */
static void test_scene_scale_defaults_follow_units(void **state)
{
    (void)state;
    scene *s[2];
    const char *roots[2] = {"[{\"name\":\"mm\",\"scale\":[0.001,0.001,0.001],\"children\":[1,2]},"
                            "{\"mesh\":0},{\"mesh\":0,\"translation\":[3,0,0]}]",
                            "[{\"name\":\"km\",\"scale\":[1000,1000,1000],\"children\":[1,2]},"
                            "{\"mesh\":0},{\"mesh\":0,\"translation\":[3,0,0]}]"};
    for (int i = 0; i < 2; i++)
        s[i] = fxt_load_ok(write_cube_gltf(i ? "km.gltf" : "mm.gltf", roots[i], "[0]", NULL));
    assert_true(fabs(s[1]->ao_radius / s[0]->ao_radius / 1e6 - 1) < 1e-5);
    double cell_ratio = srv_probe_cell_default(s[1]) / srv_probe_cell_default(s[0]);
    assert_true(cell_ratio == 1048576.0 || cell_ratio == 524288.0);
    for (int i = 0; i < 2; i++) {
        srv_camera cam = srv_camera_default(s[i]);
        double diag = 0, dist = 0;
        for (int k = 0; k < 3; k++) {
            double e = (double)s[i]->bounds_max[k] - s[i]->bounds_min[k];
            double d = (double)cam.position[k] - cam.target[k];
            diag += e * e;
            dist += d * d;
        }
        assert_true(fabs(sqrt(dist) / sqrt(diag) - 1.1) < 1e-4);
    }
    scene_free(s[0]);
    scene_free(s[1]);
}

/* glTF's KHR_lights_punctual and a camera, against the file worked by hand: a directional light of colour
 * [1, 0.5, 0.25] x 2 on a node turned -45 degrees about x travels along R_x(-45) (0, 0, -1) = (0, -0.7071,
 * -0.7071) with intensity 2 / pi (a surface under E lux shows a E cos t / pi); a point light of 5 cd on a node at
 * (1, 2, 3) is a point light of intensity 5 / pi there; the spot light is left out (counted); the camera on a node at (0, 2, 8) turned -10 degrees about
 * x stands there (Assimp 5.2.5 also copies the translation into the camera, which its pre-transform step then
 * applied twice: (0, 5.36, 15.53)) and looks along (0, -sin 10, -cos 10) with glTF's yfov of 0.8 rad. */
static void test_gltf_lights_and_camera(void **state)
{
    (void)state;
    const char *path = write_cube_gltf(
        "lights.gltf",
        "[{\"mesh\":0,\"name\":\"floor\",\"scale\":[10,1,10]},"
        "{\"name\":\"sunnode\",\"rotation\":[-0.38268343,0,0,0.92387953],"
        "\"extensions\":{\"KHR_lights_punctual\":{\"light\":0}}},"
        "{\"name\":\"lampnode\",\"translation\":[1,2,3],\"extensions\":{\"KHR_lights_punctual\":{\"light\":1}"
        "}},"
        "{\"name\":\"spotnode\",\"translation\":[0,3,0],\"rotation\":[-0.70710678,0,0,0.70710678],"
        "\"extensions\":{\"KHR_lights_punctual\":{\"light\":2}}},"
        "{\"name\":\"camnode\",\"translation\":[0,2,8],\"rotation\":[-0.0871557,0,0,0.9961947],\"camera\":0}"
        "]",
        "[0,1,2,3,4]",
        "\"extensionsUsed\":[\"KHR_lights_punctual\"],\"extensions\":{\"KHR_lights_punctual\":{\"lights\":["
        "{\"type\":\"directional\",\"color\":[1,0.5,0.25],\"intensity\":2.0,\"name\":\"sun\"},"
        "{\"type\":\"point\",\"color\":[1,1,1],\"intensity\":5.0,\"name\":\"lamp\"},"
        "{\"type\":\"spot\",\"intensity\":3.0,\"spot\":{\"innerConeAngle\":0.3,\"outerConeAngle\":0.6}}]}},"
        "\"cameras\":[{\"type\":\"perspective\",\"perspective\":{\"yfov\":0.8,\"aspectRatio\":1.5,"
        "\"znear\":0.1}}]");
    scene_file_lights found;
    scene *s = load_lit(path, &found);
    assert_int_equal(found.lights, 2);
    assert_int_equal(found.skipped, 1);
    assert_false(found.sky);
    assert_true(found.camera);
    assert_int_equal(s->light_count, 2);
    const scene_light *sun = &s->lights[0], *lamp = &s->lights[1];
    assert_int_equal(sun->type, SCENE_LIGHT_DIRECTIONAL);
    /* glTF's lux and candela are photometric: fxcache's intensity is E / pi (radiance a E cos t / pi). */
    const float pi = (float)M_PI;
    const float sun_dir[3] = {0, -0.70710678f, -0.70710678f}, sun_rgb[3] = {2 / pi, 1 / pi, 0.5f / pi};
    for (int k = 0; k < 3; k++) {
        assert_true(fabsf(sun->direction[k] - sun_dir[k]) < 1e-5f);
        assert_true(fabsf(sun->color[k] * sun->intensity - sun_rgb[k]) < 1e-5f);
    }
    assert_int_equal(lamp->type, SCENE_LIGHT_POINT);
    const double lamp_at[3] = {1, 2, 3};
    for (int k = 0; k < 3; k++) {
        assert_true(fabs(lamp->position[k] + s->origin[k] - lamp_at[k]) < 1e-5);
        assert_true(fabsf(lamp->color[k] * lamp->intensity - 5.0f / pi) < 1e-5f);
    }
    const double cam_at[3] = {0, 2, 8}, cam_dir[3] = {0, -sin(10 * M_PI / 180), -cos(10 * M_PI / 180)};
    double len = 0, to[3];
    for (int k = 0; k < 3; k++) {
        assert_true(fabs(s->camera_pos[k] + s->origin[k] - cam_at[k]) < 1e-5);
        to[k] = (double)s->camera_target[k] - s->camera_pos[k];
        len += to[k] * to[k];
    }
    len = sqrt(len);
    for (int k = 0; k < 3; k++)
        assert_true(fabs(to[k] / len - cam_dir[k]) < 1e-5);
    assert_true(fabs(s->camera_fov_deg - 0.8 * 180 / M_PI) < 1e-3);
    scene_free(s);
    /* scene_load, as every command loads a mesh file: the file's lights replace the default sun and sky (a
     * glTF has no sky), and its camera is the default camera. Before: one default sun, a sky of 0.6, no
     * camera. */
    s = fxt_load_ok(path);
    assert_int_equal(s->light_count, 2);
    assert_false(s->default_lighting);
    assert_true(s->sky_intensity == 0);
    assert_true(s->has_camera);
    scene_free(s);
}

/* The closed form through the reference renderer: a glTF sun of E = 3 lux whose light travels along
 * R_x(-60) (0, 0, -1) = (0, -0.866, -0.5), on the top of a slab of base colour a = 0.5 (no sky: glTF has
 * none), shows radiance a E cos t / pi = 0.5 x 3 x 0.866 / pi = 0.4135 at every pixel (each shadow ray reaches
 * the sun; nothing else is there to bounce light back). Before the light was read, the file got fxcache's
 * default sun and sky. */
static void test_gltf_sun_closed_form(void **state)
{
    (void)state;
    const char *path = write_cube_gltf(
        "sun.gltf",
        "[{\"mesh\":0,\"name\":\"slab\",\"scale\":[40,1,40],\"translation\":[0,-0.5,0]},"
        "{\"name\":\"sunnode\",\"rotation\":[-0.5,0,0,0.8660254],"
        "\"extensions\":{\"KHR_lights_punctual\":{\"light\":0}}}]",
        "[0,1]",
        "\"extensionsUsed\":[\"KHR_lights_punctual\"],\"extensions\":{\"KHR_lights_punctual\":{\"lights\":["
        "{\"type\":\"directional\",\"intensity\":3.0}]}}");
    scene_file_lights found;
    scene *s = load_lit(path, &found);
    assert_int_equal(found.lights, 1);
    assert_true(s->sky_intensity == 0);
    scene_error err = {0};
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    assert_non_null(rt);
    srv_ref_desc d = {.s = s, .rt = rt, .seed = 5, .threads = 2};
    uint32_t n = 0;
    const fx_effect *const *registry = fx_registry(&n);
    bool needed[SRV_MAX_EFFECTS] = {false};
    char why[SRV_MAX_EFFECTS][200];
    fx_needs(registry, n, s, needed, why);
    for (uint32_t e = 0; e < n; e++)
        d.effect_on[e] = needed[e] && registry[e]->shade;
    srv_ref *ref = NULL;
    char msg[256];
    if (srv_ref_create(&d, &ref, msg, sizeof msg) != FXC_OK)
        fail_msg("srv_ref_create: %s", msg);
    enum { W = 16, H = 9 };
    static float radiance[W * H * 3], half0[W * H * 3], half1[W * H * 3], ao[W * H], shadow[W * H];
    static uint8_t srgb[W * H * 3];
    srv_ref_image out = {
        .radiance = radiance, .half = {half0, half1}, .ao = ao, .shadow = shadow, .srgb = srgb};
    srv_ref_stats stats;
    srv_camera cam = {.position = {0, 3, 2.5f}, .target = {0, 0, 0}, .fov_deg = 60};
    for (int k = 0; k < 3; k++) { /* the camera in the local frame */
        cam.position[k] -= (float)s->origin[k];
        cam.target[k] -= (float)s->origin[k];
    }
    assert_int_equal(srv_ref_render(ref, &cam, W, H, 0, &out, &stats, NULL, NULL), FXC_OK);
    double expected = 0.5 * 3.0 * cos(30 * M_PI / 180) / M_PI, worst = 0;
    for (size_t i = 0; i < (size_t)W * H * 3; i++)
        worst = fmax(worst, fabs(radiance[i] - expected) / expected);
    if (worst > 1e-4)
        fail_msg("worst relative error %.3g against a E cos t / pi = %.6f (pixel 0: %.6f)", worst, expected,
                 (double)radiance[0]);
    srv_ref_free(ref);
    scene_rt_free(rt);
    scene_free(s);
}

/* Assimp's Collada lights.dae (Blender's five lamp types): the sun is used; the lamp and the area light fall
 * off as 1 / (1 + q d^2), which fxcache's 1/d^2 point lights cannot give, and the spot is not a point: all
 * three are left out with a warning each; the hemisphere light is Collada's ambient light: the sky. */
static void test_collada_lights_kept_and_refused(void **state)
{
    (void)state;
    const char *path = ASSIMP_MODELS "/Collada/lights.dae";
    if (access(path, R_OK) != 0) {
        print_message("skipped: %s is absent (Debian's assimp-testmodels)\n", path);
        skip();
    }
    scene_file_lights found;
    scene *s = load_lit(path, &found);
    assert_int_equal(found.lights, 1);
    assert_int_equal(found.skipped, 3);
    assert_int_equal(s->repairs.lights_unused, 3);
    assert_true(
        found.sky); /* <ambient><color>1 1 1</color>: a sky of radiance 1 (a surface of albedo a under it
                             * shows a x 1, as under an ambient light of 1) */
    assert_true(s->sky_intensity == 1.0f && s->sky_color[0] == 1.0f && s->sky_color[2] == 1.0f);
    assert_int_equal(s->light_count, 1);
    assert_int_equal(s->lights[0].type, SCENE_LIGHT_DIRECTIONAL);
    assert_true(s->lights[0].direction[1] <
                -0.999f); /* Blender's sun points down its -z: down once y is up */
    scene_free(s);
}

/* A Collada point light in a centimetre file, falling off as 1 / (q d^2) with q = 1e-4 per square centimetre:
 * in metres 1 / (1e-4 x 1e4 d^2) = 1 / d^2, a point light of intensity 1 (Collada's colour, no pi: classic light
 * colours shade a I cos t / d^2), at z = 300 cm with Z up: 3 m above the origin. */
static void test_collada_point_light_in_centimetres(void **state)
{
    (void)state;
    const char *path = fxt_write_file(
        "lamp_cm.dae",
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n"
        "<COLLADA xmlns=\"http://www.collada.org/2005/11/COLLADASchema\" version=\"1.4.1\">\n"
        "<asset><unit name=\"centimeter\" meter=\"0.01\"/><up_axis>Z_UP</up_axis></asset>\n"
        "<library_lights><light id=\"lamp\" name=\"lamp\"><technique_common><point><color>1 1 1</color>"
        "<constant_attenuation>0</constant_attenuation><linear_attenuation>0</linear_attenuation>"
        "<quadratic_attenuation>0.0001</quadratic_attenuation></point></technique_common></light>"
        "</library_lights>\n"
        "<library_geometries><geometry id=\"quad\" name=\"quad\"><mesh>\n"
        "<source id=\"p\"><float_array id=\"pa\" count=\"12\">-500 -500 0 500 -500 0 500 500 0 -500 500 0"
        "</float_array>\n<technique_common><accessor source=\"#pa\" count=\"4\" stride=\"3\"><param "
        "name=\"X\" type=\"float\"/><param name=\"Y\" type=\"float\"/><param name=\"Z\" type=\"float\"/>"
        "</accessor></technique_common></source>\n"
        "<vertices id=\"v\"><input semantic=\"POSITION\" source=\"#p\"/></vertices>\n"
        "<triangles count=\"2\"><input semantic=\"VERTEX\" source=\"#v\" offset=\"0\"/><p>0 1 2 0 2 3</p>"
        "</triangles>\n</mesh></geometry></library_geometries>\n"
        "<library_visual_scenes><visual_scene id=\"S\" name=\"S\">"
        "<node id=\"q\" name=\"q\"><instance_geometry url=\"#quad\"/></node>"
        "<node id=\"lampnode\" name=\"lamp\"><translate>0 0 300</translate><instance_light "
        "url=\"#lamp\"/></node>"
        "</visual_scene></library_visual_scenes>\n<scene><instance_visual_scene url=\"#S\"/></scene>\n"
        "</COLLADA>\n");
    scene_file_lights found;
    scene *s = load_lit(path, &found);
    assert_int_equal(found.lights, 1);
    assert_int_equal(s->light_count, 1);
    const scene_light *lamp = &s->lights[0];
    assert_int_equal(lamp->type, SCENE_LIGHT_POINT);
    const double at[3] = {0, 3, 0};
    for (int k = 0; k < 3; k++) {
        assert_true(fabs(lamp->position[k] + s->origin[k] - at[k]) < 1e-5);
        assert_true(fabs(lamp->color[k] * lamp->intensity - 1.0) < 1e-4);
    }
    scene_free(s);
}

/* Assimp's FBX global_settings.fbx (Blender: two lamps, two cameras, UnitScaleFactor 500): its camera is used,
 * its lights are not (Assimp turns FBX's decay into 2 / DecayStart^2): counted in the repairs scene-info
 * prints; with no light left the loader keeps the default sun and sky (scene_load). */
static void test_fbx_camera_used_lights_not(void **state)
{
    (void)state;
    const char *path = ASSIMP_MODELS "/FBX/global_settings.fbx";
    if (access(path, R_OK) != 0) {
        print_message("skipped: %s is absent (Debian's assimp-testmodels)\n", path);
        skip();
    }
    scene_file_lights found;
    scene *s = load_lit(path, &found);
    assert_int_equal(found.lights, 0);
    assert_int_equal(s->light_count, 0);
    assert_int_equal(s->repairs.lights_unused, 2);  /* counted for scene-info */
    assert_int_equal(s->repairs.cameras_unused, 1); /* the second camera */
    assert_true(found.camera && s->has_camera);
    /* Blender's 35 mm lens on a 32 mm sensor: 49.13 degrees across, 16:9: 2 atan(tan(24.57 deg) / 1.7778)
     * = 28.84 degrees vertically. */
    assert_true(fabs(s->camera_fov_deg - 28.84) < 0.05);
    scene_free(s);
    s = fxt_load_ok(
        path); /* through scene_load: no light read, so the default sun and sky; the file's camera */
    assert_true(s->default_lighting && s->light_count == 1 && s->sky_intensity > 0 && s->has_camera);
    scene_free(s);
}

/* A GLB holds its texture ("*0"): the texels must be those of the same texture read from its PNG file beside
 * the .gltf twin of the model (Assimp's BoxTextured). Before, "*0" was skipped without a word: the box came
 * out white. */
static void test_glb_embedded_texture(void **state)
{
    (void)state;
    const char *glb = ASSIMP_MODELS "/glTF2/BoxTextured-glTF-Binary/BoxTextured.glb";
    const char *gltf = ASSIMP_MODELS "/glTF2/BoxTextured-glTF/BoxTextured.gltf";
    if (access(glb, R_OK) != 0 || access(gltf, R_OK) != 0) {
        print_message("skipped: %s or %s is absent (Debian's assimp-testmodels)\n", glb, gltf);
        skip();
    }
    scene *a = fxt_load_ok(glb), *b = fxt_load_ok(gltf);
    assert_int_equal(a->texture_count, 1);
    assert_int_equal(b->texture_count, 1);
    assert_int_equal(a->repairs.textures_missing, 0);
    /* The twin's sampler mirrors u (MIRRORED_REPEAT), so its texture is the PNG followed by its mirror
     * image: its left half row by row is the PNG. */
    const scene_texture *ta = &a->textures[0], *tb = &b->textures[0];
    assert_int_equal(2 * ta->width, tb->width);
    assert_int_equal(ta->height, tb->height);
    for (uint32_t y = 0; y < ta->height; y++)
        assert_memory_equal(ta->rgb + 3 * (size_t)y * ta->width, tb->rgb + 3 * (size_t)y * tb->width,
                            sizeof(float) * 3 * ta->width);
    assert_int_equal(a->materials[a->meshes[0].material].texture, 0);
    scene_free(a);
    scene_free(b);
}

/* A unit quad whose base-colour texture is 2 x 1 texels, red then green (red_green.png beside it), read from
 * texture coordinate set `texcoord` with the sampler's wrapS `wrap_s` (10497 repeat, 33648 mirrored repeat,
 * 33071 clamp); its corners' coordinates in sets 0 and 1 are uv0 and uv1; placed by the glTF `nodes` (JSON
 * text) whose roots are `scene_nodes`. Returns the .gltf path. */
static const char *write_quad_gltf_nodes(const char *name, const float uv0[4][2], const float uv1[4][2],
                                         int texcoord, int wrap_s, const char *nodes, const char *scene_nodes)
{
    const uint8_t texels[6] = {255, 0, 0, 0, 255, 0};
    char msg[256];
    assert_int_equal(scene_image_write_u8(fxt_tmp_path("red_green.png"), 2, 1, 3, texels, msg, sizeof msg),
                     0);
    const float positions[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 0, -1}, {0, 0, -1}};
    const uint16_t indices[6] = {0, 1, 2, 0, 2, 3};
    FILE *bin = fopen(fxt_tmp_path("quad_uv.bin"), "wb");
    assert_non_null(bin);
    assert_int_equal(fwrite(positions, sizeof positions, 1, bin), 1);
    assert_int_equal(fwrite(uv0, sizeof(float) * 8, 1, bin), 1);
    assert_int_equal(fwrite(uv1, sizeof(float) * 8, 1, bin), 1);
    assert_int_equal(fwrite(indices, sizeof indices, 1, bin), 1);
    fclose(bin);
    static char text[4096];
    snprintf(
        text, sizeof text,
        "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":%s}],\"nodes\":%s,"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1,\"TEXCOORD_1\":2},"
        "\"indices\":3,\"material\":0}]}],"
        "\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorTexture\":{\"index\":0,\"texCoord\":%d},"
        "\"metallicFactor\":0}}],"
        "\"samplers\":[{\"wrapS\":%d,\"wrapT\":10497}],"
        "\"textures\":[{\"source\":0,\"sampler\":0}],\"images\":[{\"uri\":\"red_green.png\"}],"
        "\"buffers\":[{\"byteLength\":124,\"uri\":\"quad_uv.bin\"}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":48},"
        "{\"buffer\":0,\"byteOffset\":48,\"byteLength\":32},{\"buffer\":0,\"byteOffset\":80,"
        "\"byteLength\":32},{\"buffer\":0,\"byteOffset\":112,\"byteLength\":12}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\","
        "\"min\":[0,0,-1],\"max\":[1,0,0]},{\"bufferView\":1,\"componentType\":5126,\"count\":4,"
        "\"type\":\"VEC2\"},{\"bufferView\":2,\"componentType\":5126,\"count\":4,\"type\":\"VEC2\"},"
        "{\"bufferView\":3,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]}",
        scene_nodes, nodes, texcoord, wrap_s);
    return fxt_write_file(name, text);
}

/* The quad placed once as it is, every corner at u = u0 in set 0 and u = u1 in set 1 (v = 0.5). */
static const char *write_quad_gltf(const char *name, float u0, float u1, int texcoord, int wrap_s)
{
    const float uv0[4][2] = {{u0, 0.5f}, {u0, 0.5f}, {u0, 0.5f}, {u0, 0.5f}};
    const float uv1[4][2] = {{u1, 0.5f}, {u1, 0.5f}, {u1, 0.5f}, {u1, 0.5f}};
    return write_quad_gltf_nodes(name, uv0, uv1, texcoord, wrap_s, "[{\"mesh\":0}]", "[0]");
}

/* Fails unless every triangle's albedo is the given texel colour (red: 1 0 0, green: 0 1 0). */
static void assert_albedo_everywhere(const scene *s, const float expected[3], const char *why)
{
    for (uint32_t t = 0; t < s->triangle_count; t++)
        for (int corner = 0; corner < 3; corner++) {
            float rgb[3];
            scene_albedo(s, t, corner == 1 ? 0.8f : 0.1f, corner == 2 ? 0.8f : 0.1f, rgb);
            for (int k = 0; k < 3; k++)
                if (!(fabsf(rgb[k] - expected[k]) < 0.01f))
                    fail_msg("%s: triangle %u albedo (%g, %g, %g), expected (%g, %g, %g)", why, t,
                             (double)rgb[0], (double)rgb[1], (double)rgb[2], (double)expected[0],
                             (double)expected[1], (double)expected[2]);
        }
}

/* glTF's texCoord and wrap modes against the texel each must read, in a red | green texture (texel centres
 * at u = 0.25 and 0.75). texCoord 1 reads TEXCOORD_1: u0 = 0.25 (red) in set 0, u1 = 0.75 (green) in set 1
 * gives green (before, set 0 was always read: red). MIRRORED_REPEAT at u = 1.25 reads 2 - 1.25 = 0.75: green
 * (a repeat reads 0.25: red, which is what fxcache did before), and a plain repeat there still reads red. */
static void test_gltf_texcoord_and_mirror(void **state)
{
    (void)state;
    const float red[3] = {1, 0, 0}, green[3] = {0, 1, 0};
    scene *s = fxt_load_ok(write_quad_gltf("set1.gltf", 0.25f, 0.75f, 1, 10497));
    assert_int_equal(s->texture_count, 1);
    assert_albedo_everywhere(s, green, "texCoord 1");
    scene_free(s);
    s = fxt_load_ok(write_quad_gltf("mirror.gltf", 1.25f, 0, 0, 33648));
    assert_int_equal(s->texture_count, 1); /* the mirrored texture replaced the plain one */
    assert_int_equal(s->textures[0].width, 4);
    assert_albedo_everywhere(s, green, "MIRRORED_REPEAT at u = 1.25");
    scene_free(s);
    s = fxt_load_ok(write_quad_gltf("repeat.gltf", 1.25f, 0, 0, 10497));
    assert_albedo_everywhere(s, red, "REPEAT at u = 1.25");
    scene_free(s);
}

/* One textured quad placed by two nodes, as it is and scaled by 2 (no mirror: Assimp's pre-transform path):
 * both appear (1 + 4 square metres), with islands of their own, and the texture on the scaled copy has half
 * the texels per metre: its log2 is exactly one lower (the same UVs over twice the length). */
static void test_instanced_texture_density(void **state)
{
    (void)state;
    const float uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    const char *path = write_quad_gltf_nodes(
        "twice.gltf", uv, uv, 0, 10497,
        "[{\"mesh\":0},{\"mesh\":0,\"scale\":[2,2,2],\"translation\":[3,0,0]}]", "[0,1]");
    scene *s = fxt_load_ok(path);
    assert_int_equal(s->triangle_count, 4);
    assert_true(fabs(scene_surface_area(s) - 5.0) < 1e-6);
    float lod[2] = {NAN, NAN};
    for (uint32_t t = 0; t < s->triangle_count; t++) {
        double c[3];
        centroid_world(s, t, c);
        int copy = c[0] > 2 ? 1 : 0;
        if (isnan(lod[copy]))
            lod[copy] = s->tri_texture_lod[t];
        assert_true(s->tri_texture_lod[t] == lod[copy]);
    }
    /* a 2 x 1 texture over 1 m^2: log2 sqrt(2 texels / 1 m^2) = 0.5; over 4 m^2: -0.5 */
    assert_true(fabsf(lod[0] - 0.5f) < 1e-5f && fabsf(lod[1] + 0.5f) < 1e-5f);
    for (uint32_t i = 0; i < s->island_count; i++) {
        const scene_island *island = &s->islands[i];
        double first[3];
        centroid_world(s, s->island_triangles[island->first], first);
        for (uint32_t k = 1; k < island->triangle_count; k++) {
            double c[3];
            centroid_world(s, s->island_triangles[island->first + k], c);
            assert_true((c[0] > 2) == (first[0] > 2)); /* no island spans both copies */
        }
    }
    scene_free(s);
}

/* glTF's CLAMP_TO_EDGE where the coordinates leave 0..1: the quad's u runs from -1 (x = 0) to 2 (x = 1), so at
 * x the red | green texture (texel centres u = 0.25, 0.75) clamped gives green g(u) = clamp((u - 0.25) / 0.5,
 * 0, 1), red 1 - g: red up to u = 0.25, green from 0.75, a blend between; near both ends too (the copy's own
 * wrap-around stays outside). Before, the texture repeated (with one warning line): at u = -0.5 it read the
 * green texel. A mirrored repeat there is not clamped, and Assimp's vertex-coloured Collada model loads its
 * colours without a warning (tests/test_import_colors.c). */
static void test_gltf_clamp_to_edge(void **state)
{
    (void)state;
    static char out[8192], err[8192];
    const float uv[4][2] = {{-1, 0.5f}, {2, 0.5f}, {2, 0.5f}, {-1, 0.5f}};
    char path[1024]; /* fxt_run_clif reuses the scratch path's buffer */
    snprintf(path, sizeof path, "%s",
             write_quad_gltf_nodes("clamp.gltf", uv, uv, 0, 33071, "[{\"mesh\":0}]", "[0]"));
    assert_int_equal(fxt_run_clif(out, sizeof out, err, sizeof err, "scene-info '%s'", path), 0);
    assert_null(strstr(err, "clamp"));
    scene *s = fxt_load_ok(path);
    assert_int_equal(s->texture_count, 1); /* the padded copy took the plain texture's place */
    const float bary[6][2] = {{0.001f, 0.001f}, {0.2f, 0.1f},     {0.4f, 0.3f},
                              {0.1f, 0.6f},     {0.998f, 0.001f}, {0.5f, 0.25f}};
    for (uint32_t t = 0; t < s->triangle_count; t++)
        for (int i = 0; i < 6; i++) {
            double x = 0;
            for (int c = 0; c < 3; c++) {
                double w = c == 0 ? 1.0 - bary[i][0] - bary[i][1] : bary[i][c - 1];
                x +=
                    w * s->positions[3 * (size_t)s->indices[3 * (size_t)t + c]] + (c == 0 ? s->origin[0] : 0);
            }
            double u = -1 + 3 * x, g = fmin(fmax((u - 0.25) / 0.5, 0), 1);
            float rgb[3];
            scene_albedo(s, t, bary[i][0], bary[i][1], rgb);
            if (!(fabs(rgb[0] - (1 - g)) < 1e-4 && fabs(rgb[1] - g) < 1e-4 && fabs(rgb[2]) < 1e-6))
                fail_msg("triangle %u at u = %.4f: (%g, %g, %g), expected (%g, %g, 0)", t, u, (double)rgb[0],
                         (double)rgb[1], (double)rgb[2], 1 - g, g);
        }
    scene_free(s);
    const char *mirrored = write_quad_gltf("mirror.gltf", 1.25f, 0, 0, 33648);
    assert_int_equal(fxt_run_clif(out, sizeof out, err, sizeof err, "scene-info '%s'", mirrored), 0);
    assert_null(strstr(err, "clamp"));
    const char *colours = ASSIMP_MODELS "/Collada/kwxport_test_vcolors.dae";
    if (access(colours, R_OK) != 0) {
        print_message("skipped: %s is absent (Debian's assimp-testmodels)\n", colours);
        skip();
    }
    assert_int_equal(fxt_run_clif(out, sizeof out, err, sizeof err, "scene-info '%s'", colours), 0);
    assert_null(strstr(err, "vertex colours"));
    s = fxt_load_ok(colours);
    assert_non_null(s->corner_color);
    scene_free(s);
}

/* Appends a 3DS chunk header (id, length including the six header bytes) at buf + *at. */
static void chunk_3ds(uint8_t *buf, size_t *at, uint16_t id, uint32_t length)
{
    memcpy(buf + *at, &id, 2);
    memcpy(buf + *at + 2, &length, 4);
    *at += 6;
}

/* A hand-written 3DS file: one triangle and a camera with a 35 mm lens. Assimp 5.2.5 reads the lens as an
 * angle (35 degrees across), while a 35 mm lens on 3D Studio's 36 mm film frame sees 2 atan(18 / 35) = 54.4
 * degrees: the camera is left out (counted in cameras_unused) and the scene keeps fxcache's default camera,
 * as Sponza's 3DS file does. The decision stands on what this checks of Assimp's reading. */
static void test_3ds_camera_lens_misread(void **state)
{
    (void)state;
    static uint8_t buf[512];
    size_t at = 0;
    const float corners[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const uint16_t face[4] = {0, 1, 2, 0};
    const float camera[8] = {0, 0.3f, 5, 0, 0.3f, 0, 0, 35}; /* position, target, bank, lens (mm) */
    uint32_t mesh_len = 6 + 4 + 6 + (6 + 2 + 36) + (6 + 2 + 8),
             cam_len = 6 + 4 + 6 + 32;                       /* names of 4 bytes */
    chunk_3ds(buf, &at, 0x4D4D, 6 + 6 + mesh_len + cam_len); /* main */
    chunk_3ds(buf, &at, 0x3D3D, 6 + mesh_len + cam_len);     /* editor */
    chunk_3ds(buf, &at, 0x4000, mesh_len);                   /* object "tri" */
    memcpy(buf + at, "tri", 4), at += 4;
    chunk_3ds(buf, &at, 0x4100, 6 + (6 + 2 + 36) + (6 + 2 + 8)); /* triangle mesh */
    chunk_3ds(buf, &at, 0x4110, 6 + 2 + 36);
    uint16_t three = 3, one = 1;
    memcpy(buf + at, &three, 2), at += 2;
    memcpy(buf + at, corners, 36), at += 36;
    chunk_3ds(buf, &at, 0x4120, 6 + 2 + 8);
    memcpy(buf + at, &one, 2), at += 2;
    memcpy(buf + at, face, 8), at += 8;
    chunk_3ds(buf, &at, 0x4000, cam_len); /* object "cam" */
    memcpy(buf + at, "cam", 4), at += 4;
    chunk_3ds(buf, &at, 0x4700, 6 + 32);
    memcpy(buf + at, camera, 32), at += 32;
    FILE *f = fopen(fxt_tmp_path("lens.3ds"), "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(buf, at, 1, f), 1);
    fclose(f);
    char path[1024];
    snprintf(path, sizeof path, "%s", fxt_tmp_path("lens.3ds"));
    const struct aiScene *ai = aiImportFile(path, 0);
    if (!ai)
        fail_msg("Assimp: %s", aiGetErrorString());
    assert_int_equal(ai->mNumCameras, 1);
    double across_deg = ai->mCameras[0]->mHorizontalFOV * 180 / M_PI;
    aiReleaseImport(ai);
    assert_true(fabs(across_deg - 35) < 1e-3); /* the lens's millimetres as degrees, not 54.4 */
    scene *s = fxt_load_ok(path);
    assert_false(s->has_camera);
    assert_int_equal(s->repairs.cameras_unused, 1);
    scene_free(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mirrored_instance_faces_outwards),
        cmocka_unit_test(test_fbx_centimetres_become_metres),
        cmocka_unit_test(test_collada_unit_and_up_axis),
        cmocka_unit_test(test_scene_scale_defaults_follow_units),
        cmocka_unit_test(test_gltf_lights_and_camera),
        cmocka_unit_test(test_gltf_sun_closed_form),
        cmocka_unit_test(test_collada_lights_kept_and_refused),
        cmocka_unit_test(test_collada_point_light_in_centimetres),
        cmocka_unit_test(test_fbx_camera_used_lights_not),
        cmocka_unit_test(test_glb_embedded_texture),
        cmocka_unit_test(test_gltf_texcoord_and_mirror),
        cmocka_unit_test(test_instanced_texture_density),
        cmocka_unit_test(test_gltf_clamp_to_edge),
        cmocka_unit_test(test_3ds_camera_lens_misread),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
