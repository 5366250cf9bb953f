/* A mesh file's node graph as Assimp gives it: node transforms in double and whether some instance mirrors
 * (then scene_import.c places meshes node by node instead of through Assimp's pre-transform step, which keeps
 * a mirrored mesh's corner order and so turns it inside out). */
#include "scene_import_nodes.h"

#include <math.h>
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
