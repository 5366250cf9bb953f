/* A mesh file's node graph as Assimp gives it: node transforms in double, whether some instance mirrors (then
 * scene_import.c places meshes node by node instead of through Assimp's pre-transform step, which keeps a
 * mirrored mesh's corner order and so turns it inside out), and the lights and first camera the file carries,
 * placed by their nodes. Read after Assimp's global-scale step (FBX centimetres become metres) and before its
 * pre-transform step, which would flatten the graph (and, in Assimp 5.2.5, applies a glTF or 3DS camera's
 * translation twice: its readers put it both in the node and in the camera). */
#include "scene_import_nodes.h"

#include <assimp/camera.h>
#include <assimp/light.h>
#include <assimp/metadata.h>

#include <math.h>
#include <stdio.h>
#include <string.h>

const double scene__identity_matrix[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

void scene__node_matrix(const struct aiNode *node, double m[16])
{
    const struct aiMatrix4x4 *t = &node->mTransformation;
    const ai_real rows[16] = {t->a1, t->a2, t->a3, t->a4, t->b1, t->b2, t->b3, t->b4,
                              t->c1, t->c2, t->c3, t->c4, t->d1, t->d2, t->d3, t->d4};
    for (int i = 0; i < 16; i++)
        m[i] = (double)rows[i];
}

void scene__matrix_multiply(const double a[16], const double b[16], double out[16])
{
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++) {
            double sum = 0;
            for (int k = 0; k < 4; k++)
                sum += a[4 * r + k] * b[4 * k + c];
            out[4 * r + c] = sum;
        }
}

/* The determinant of the upper 3 x 3 (negative: the transform mirrors). */
static double determinant3(const double m[16])
{
    return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
           m[2] * (m[4] * m[9] - m[5] * m[8]);
}

bool scene__places_mirrored(const struct aiNode *node, const double parent[16], unsigned depth)
{
    if (!node || depth > 10000)
        return false;
    double local[16], world[16];
    scene__node_matrix(node, local);
    scene__matrix_multiply(parent, local, world);
    if (node->mNumMeshes > 0 && determinant3(world) < 0)
        return true;
    for (uint32_t i = 0; i < node->mNumChildren; i++)
        if (scene__places_mirrored(node->mChildren[i], world, depth + 1))
            return true;
    return false;
}

/* Grows lo/hi by the vertices of every mesh the nodes below node place, in world coordinates. */
static void grow_bounds(const struct aiScene *ai, const struct aiNode *node, const double parent[16],
                        unsigned depth, double lo[3], double hi[3])
{
    if (!node || depth > 10000)
        return;
    double local[16], world[16];
    scene__node_matrix(node, local);
    scene__matrix_multiply(parent, local, world);
    for (uint32_t i = 0; i < node->mNumMeshes; i++) {
        const struct aiMesh *mesh = ai->mMeshes[node->mMeshes[i]];
        for (uint32_t v = 0; v < mesh->mNumVertices; v++) {
            const struct aiVector3D *p = &mesh->mVertices[v];
            for (int r = 0; r < 3; r++) {
                double w = world[4 * r] * p->x + world[4 * r + 1] * p->y + world[4 * r + 2] * p->z +
                           world[4 * r + 3];
                lo[r] = fmin(lo[r], w);
                hi[r] = fmax(hi[r], w);
            }
        }
    }
    for (uint32_t i = 0; i < node->mNumChildren; i++)
        grow_bounds(ai, node->mChildren[i], world, depth + 1, lo, hi);
}

/* The node called name below node and its world transform (parent: the ancestors'); NULL when none. */
static const struct aiNode *find_node(const struct aiNode *node, const char *name, const double parent[16],
                                      unsigned depth, double world[16])
{
    if (!node || depth > 10000)
        return NULL;
    double local[16], here[16];
    scene__node_matrix(node, local);
    scene__matrix_multiply(parent, local, here);
    if (strcmp(node->mName.data, name) == 0) {
        memcpy(world, here, sizeof here);
        return node;
    }
    for (uint32_t i = 0; i < node->mNumChildren; i++) {
        const struct aiNode *found = find_node(node->mChildren[i], name, here, depth + 1, world);
        if (found)
            return found;
    }
    return NULL;
}

/* m applied to the point p (w = 1) or, with w = 0, to the direction p. */
static void transform(const double m[16], const double p[3], double w, double out[3])
{
    for (int r = 0; r < 3; r++)
        out[r] = m[4 * r] * p[0] + m[4 * r + 1] * p[1] + m[4 * r + 2] * p[2] + m[4 * r + 3] * w;
}

static bool normalize(double v[3])
{
    double len = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (!(len > 0) || !isfinite(len))
        return false;
    for (int k = 0; k < 3; k++)
        v[k] /= len;
    return true;
}

/* Where an object with its own position `own` (aiLight/aiCamera mPosition, in its node's frame) stands in the
 * world. Assimp 5.2.5's glTF 2 and 3DS readers also copy the node's translation into mPosition (Assimp issue
 * 5054): when mPosition equals the node's own translation, it is that copy, and the node's origin is meant. */
static void place(const struct aiNode *node, const double world[16], const struct aiVector3D *own,
                  double out[3])
{
    double p[3] = {own->x, own->y, own->z};
    const struct aiMatrix4x4 *t = &node->mTransformation;
    if ((p[0] != 0 || p[1] != 0 || p[2] != 0) && own->x == t->a4 && own->y == t->b4 && own->z == t->c4)
        p[0] = p[1] = p[2] = 0;
    transform(world, p, 1, out);
}

/* The colour split into a colour with largest component 1 and an intensity (fxcache's lights multiply the
 * two). False when it has no energy or is not finite. */
static bool split_colour(const struct aiColor3D *c, float color[3], float *intensity)
{
    float rgb[3] = {c->r, c->g, c->b};
    float peak = fmaxf(rgb[0], fmaxf(rgb[1], rgb[2]));
    if (!(peak > 0) || !isfinite(peak) || !(fminf(rgb[0], fminf(rgb[1], rgb[2])) >= 0))
        return false;
    for (int k = 0; k < 3; k++)
        color[k] = rgb[k] / peak;
    *intensity = peak;
    return true;
}

static const char *light_type_name(enum aiLightSourceType type)
{
    switch (type) {
    case aiLightSource_DIRECTIONAL: return "directional";
    case aiLightSource_POINT: return "point";
    case aiLightSource_SPOT: return "spot";
    case aiLightSource_AMBIENT: return "ambient";
    case aiLightSource_AREA: return "area";
    default: return "unknown";
    }
}

/* The name of the Assimp reader that read the file ("glTF2 Importer", ...), or "". */
static const char *reader_of(const struct aiScene *ai)
{
    const struct aiMetadata *meta = ai->mMetaData;
    for (uint32_t i = 0; meta && i < meta->mNumProperties; i++)
        if (strcmp(meta->mKeys[i].data, "SourceAsset_Format") == 0 && meta->mValues[i].mType == AI_AISTRING &&
            meta->mValues[i].mData)
            return ((const struct aiString *)meta->mValues[i].mData)->data;
    return "";
}

/* Converts one light. Returns SCENE_OK with *added or *skipped set; an error only from scene__add_light. */
static scene_result import_light(scene *s, const struct aiScene *ai, const struct aiLight *light,
                                 const char *path, double unit_scale, scene_file_lights *out,
                                 scene_error *err)
{
    double world[16];
    const struct aiNode *node = find_node(ai->mRootNode, light->mName.data, scene__identity_matrix, 0, world);
    const char *why = NULL;
    char detail[160] = "";
    scene_light l = {0};
    double position[3] = {0, 0, 0};
    /* fxcache shades a surface of albedo a under a light of intensity I at angle t as a I cos t (I / d^2 for a
     * point light), as classic light colours mean (Collada, FBX, 3DS: a white light of 1 shows a surface's
     * albedo). glTF's lights are photometric: a sun of E lux gives radiance a E cos t / pi, a lamp of I cd
     * a I cos t / (pi d^2), so their intensities are divided by pi. */
    double photometric = strcmp(reader_of(ai), "glTF2 Importer") == 0 ? 1.0 / M_PI : 1.0;
    if (light->mType == aiLightSource_AMBIENT) {
        float color[3], intensity;
        if (!split_colour(&light->mColorAmbient, color, &intensity))
            why = "it has no intensity";
        else {
            memcpy(s->sky_color, color, sizeof color);
            s->sky_intensity = intensity;
            out->sky = true;
            return SCENE_OK;
        }
    } else if (light->mType == aiLightSource_SPOT || light->mType == aiLightSource_AREA) {
        /* A spot as a point light would send its light into the whole sphere: with glTF's usual outer cone of
         * 45 degrees, 7 times the power it has, onto walls it does not light. */
        why = "fxcache has no spot or area lights";
    } else if (light->mType != aiLightSource_DIRECTIONAL && light->mType != aiLightSource_POINT) {
        why = "fxcache has no lights of this type";
    } else if (!node) {
        why = "no node places it";
    } else if (!split_colour(&light->mColorDiffuse, l.color, &l.intensity)) {
        why = "it has no intensity";
    } else if (light->mType == aiLightSource_DIRECTIONAL) {
        l.intensity *= photometric;
        double d[3] = {light->mDirection.x, light->mDirection.y, light->mDirection.z}, dw[3];
        transform(world, d, 0, dw);
        if (!normalize(dw))
            why = "its direction is zero";
        l.type = SCENE_LIGHT_DIRECTIONAL;
        for (int k = 0; k < 3; k++)
            l.direction[k] = (float)dw[k];
    } else {
        /* Assimp's falloff is 1 / (constant + linear d + quadratic d^2), d in the file's units; fxcache's point
         * lights fall off as 1/d^2 in metres: exact when only the quadratic term is there (glTF's
         * KHR_lights_punctual: intensity in candela, quadratic 1). */
        double c = light->mAttenuationConstant, lin = light->mAttenuationLinear,
               q = light->mAttenuationQuadratic;
        if (!(c == 0 && lin == 0 && q > 0)) {
            why = "fxcache's point lights fall off as 1/d^2 only";
            snprintf(detail, sizeof detail, " (its falloff is 1 / (%g + %g d + %g d^2))", c, lin, q);
        } else {
            /* q is per squared length in the light's frame: a Collada file's unit is a scale in its root node
             * (0.01 for centimetres), so d there is d / scale in metres. glTF's lights ignore their nodes'
             * scale (KHR_lights_punctual: "all properties of the light ... are unaffected"). */
            double scale =
                strcmp(reader_of(ai), "glTF2 Importer") == 0 ? 1.0 : cbrt(fabs(determinant3(world)));
            double length = scale * unit_scale;
            double intensity = l.intensity * photometric * length * length / q;
            if (!(intensity <= 3.0e38))
                why = "its intensity is beyond a float";
            l.type = SCENE_LIGHT_POINT;
            l.intensity = (float)intensity;
            place(node, world, &light->mPosition, position);
        }
    }
    if (why) {
        fprintf(stderr, "fxcache: warning: %s: %s light '%s' ignored: %s%s\n", path,
                light_type_name(light->mType), light->mName.data, why, detail);
        out->skipped++;
        s->repairs.lights_unused++;
        return SCENE_OK;
    }
    char where[200];
    snprintf(where, sizeof where, "%s: light '%s'", path, light->mName.data);
    scene_result rc =
        scene__add_light_world(s, &l, l.type == SCENE_LIGHT_POINT ? position : NULL, where, err);
    if (rc == SCENE_OK)
        out->lights++;
    return rc;
}

/* The first camera as the scene's default camera, looking at a target as far as the geometry's centre. */
static void import_camera(scene *s, const struct aiScene *ai, const char *path, const double lo[3],
                          const double hi[3], scene_file_lights *out)
{
    const struct aiCamera *cam = ai->mCameras[0];
    double world[16];
    const struct aiNode *node = find_node(ai->mRootNode, cam->mName.data, scene__identity_matrix, 0, world);
    double position[3], look[3] = {cam->mLookAt.x, cam->mLookAt.y, cam->mLookAt.z}, dir[3];
    if (!node || cam->mOrthographicWidth > 0) {
        fprintf(stderr, "fxcache: warning: %s: camera '%s' ignored: %s\n", path, cam->mName.data,
                node ? "fxcache's cameras are perspective" : "no node places it");
        return;
    }
    place(node, world, &cam->mPosition, position);
    transform(world, look, 0, dir);
    if (!normalize(dir)) {
        fprintf(stderr, "fxcache: warning: %s: camera '%s' ignored: it looks nowhere\n", path,
                cam->mName.data);
        return;
    }
    /* Assimp's readers give the whole horizontal angle (FBX and Collada: Blender's default 35 mm lens reads
     * 0.8576 rad = 49.1 degrees), its glTF 2 reader yfov x aspect; fxcache keeps the vertical angle. Without
     * an aspect ratio in the file (3DS) the horizontal angle is taken as 16:9 frames'. */
    double aspect = cam->mAspect > 0 && isfinite(cam->mAspect) ? cam->mAspect : 16.0 / 9.0;
    double horizontal = cam->mHorizontalFOV;
    double vertical = strcmp(reader_of(ai), "glTF2 Importer") == 0 ? horizontal / aspect
                                                                   : 2 * atan(tan(0.5 * horizontal) / aspect);
    double fov_deg = vertical * 180.0 / M_PI;
    if (!(fov_deg > 0 && fov_deg < 180))
        fov_deg = 60;
    double distance = 0;
    for (int k = 0; k < 3; k++) {
        double d = 0.5 * (lo[k] + hi[k]) - position[k];
        distance += d * d;
    }
    distance = sqrt(distance);
    if (!(distance > 0) || !isfinite(distance))
        distance = 1;
    double target[3];
    for (int k = 0; k < 3; k++)
        target[k] = position[k] + distance * dir[k];
    if (!(isfinite(position[0]) && isfinite(position[1]) && isfinite(position[2]) && isfinite(target[0]) &&
          isfinite(target[1]) && isfinite(target[2]))) {
        fprintf(stderr, "fxcache: warning: %s: camera '%s' ignored: its position is not finite\n", path,
                cam->mName.data);
        return;
    }
    if (scene__set_camera_world(s, position, target, (float)fov_deg))
        out->camera = true;
}

/* Which readers give lights and cameras as their files mean them, checked against Assimp 5.2.5's output:
 * glTF 2 (KHR_lights_punctual; yfov) and Collada (its spec's colour and 1 / (c + l d + q d^2) falloff, passed
 * as they are; whole horizontal angle) for both, FBX for cameras (whole horizontal angle: Blender's default
 * 35 mm lens reads 49.1 degrees). Not the others: Assimp's 3DS reader reads a camera's lens (millimetres) as
 * an angle in degrees and leaves every light aiLight's default falloff 1/d; its FBX reader turns a light's
 * decay into 2 / DecayStart^2, which is not FBX's falloff. */
static const struct {
    const char *reader;
    bool lights, cameras;
} trusted_readers[] = {
    {"glTF2 Importer", true, true},
    {"Collada Importer", true, true},
    {"Autodesk FBX Importer", false, true},
};

scene_result scene__import_lights(scene *s, const struct aiScene *ai, const char *path, double unit_scale,
                                  scene_file_lights *out, scene_error *err)
{
    memset(out, 0, sizeof *out);
    const char *reader = reader_of(ai);
    bool lights = false, cameras = false;
    for (size_t i = 0; i < sizeof trusted_readers / sizeof trusted_readers[0]; i++)
        if (strcmp(reader, trusted_readers[i].reader) == 0) {
            lights = trusted_readers[i].lights;
            cameras = trusted_readers[i].cameras;
        }
    /* Counted, not printed: Sponza's 3DS file carries an omni light and a camera, and every command that
     * loads it would repeat the line; scene-info reports the counts. */
    s->repairs.lights_unused += lights ? 0 : ai->mNumLights;
    s->repairs.cameras_unused += cameras ? 0 : ai->mNumCameras;
    if (cameras && ai->mNumCameras > 1)
        s->repairs.cameras_unused += ai->mNumCameras - 1;
    double bounds_lo[3] = {INFINITY, INFINITY, INFINITY}, bounds_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    if (cameras && ai->mNumCameras > 0)
        grow_bounds(ai, ai->mRootNode, scene__identity_matrix, 0, bounds_lo, bounds_hi);
    for (uint32_t i = 0; lights && i < ai->mNumLights; i++) {
        scene_result rc = import_light(s, ai, ai->mLights[i], path, unit_scale, out, err);
        if (rc != SCENE_OK)
            return rc;
    }
    if (cameras && ai->mNumCameras > 0)
        import_camera(s, ai, path, bounds_lo, bounds_hi, out);
    return SCENE_OK;
}
