/* Private to the scene module: a mesh file's node graph as Assimp gives it (scene_import_nodes.c): node
 * transforms in double, whether some instance mirrors, and the lights and camera the file carries. */
#ifndef FXC_SCENE_IMPORT_NODES_H
#define FXC_SCENE_IMPORT_NODES_H

#include "scene_internal.h"

#include <assimp/scene.h>

/* The identity as a row-major 4 x 4. */
extern const double scene__identity_matrix[16];

/* The transform of node relative to its parent as a row-major 4 x 4 in double (Assimp's aiMatrix4x4 is
 * row-major and applies to column vectors, as scene__add_mesh's transforms do). */
void scene__node_matrix(const struct aiNode *node, double m[16]);

/* out = a * b (row-major 4 x 4); out may not alias a or b. */
void scene__matrix_multiply(const double a[16], const double b[16], double out[16]);

/* True when some node below node places a mesh through a mirroring transform (a negative determinant of its
 * own transform times its ancestors'; parent is the ancestors'). */
bool scene__places_mirrored(const struct aiNode *node, const double parent[16], unsigned depth);

/* Adds the file's lights (directional, point with an inverse-square falloff, ambient as the sky) and its
 * first camera (looking as far as the centre of the file's geometry) to s, placed by their nodes' world
 * transforms: call it while the node graph is whole (before Assimp's pre-transform step). unit_scale is the
 * scale Assimp applied to the file's lengths (FBX centimetres to metres), for point lights' falloff. Lights
 * it cannot represent are skipped with one warning line each on stderr. */
scene_result scene__import_lights(scene *s, const struct aiScene *ai, const char *path, double unit_scale,
                                  scene_file_lights *out, scene_error *err);

#endif
