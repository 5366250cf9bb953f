/* Mesh files as users bring them (scene/scene_import.c): node transforms (nested, non-uniform, mirrored
 * instances, one mesh placed twice), units, and the lights and cameras a file carries. Each expectation is
 * a closed form worked out by hand from the file written here, or a figure of a Debian test model (skipped
 * with a message when assimp-testmodels is absent). */
#include "test_util.h"

#include "scene_internal.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

/* Where Debian's assimp-testmodels puts Assimp's own test models. */
#define ASSIMP_MODELS "/usr/share/assimp/models"

static scene *load_ok(const char *path)
{
    scene_error err = {0};
    scene *s = scene_load(path, NULL, &err);
    if (!s)
        fail_msg("%s: %s", path, err.msg);
    return s;
}

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
    scene *s = load_ok(path);
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

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mirrored_instance_faces_outwards),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
