/* topology: edge adjacency of the welded scene triangles, computed through OpenMesh's half-edge mesh.
 *
 * The island builder (scene_islands.c) grows charts across triangle edges; it needs, for every triangle
 * edge, the triangle on the other side. This header is the C face of a small C++ shim
 * (topology_openmesh.cpp) that feeds the triangles to an OpenMesh TriMesh in scene order. Triangles
 * OpenMesh refuses (an edge already used by two faces, a vertex it cannot link, inconsistent winding) are
 * split off: added as isolated faces with their own copies of the vertices, so they have no neighbour and
 * become islands of their own. No C++ exception crosses this boundary. */
#ifndef FXC_TOPOLOGY_H
#define FXC_TOPOLOGY_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Result codes of the shim. */
typedef enum scene_topo_result {
    SCENE_TOPO_OK = 0,
    SCENE_TOPO_ERR_NOMEM = -1,    /* std::bad_alloc inside OpenMesh */
    SCENE_TOPO_ERR_INVALID = -2,  /* an index out of range, or more triangles than OpenMesh can index */
    SCENE_TOPO_ERR_INTERNAL = -3, /* any other exception, or OpenMesh did something unexpected */
} scene_topo_result;

/* Marks an edge with no triangle on the other side (boundary, or a split-off triangle). */
#define SCENE_TOPO_NO_NEIGHBOR UINT32_MAX

/* Computes edge neighbours. positions: vertex_count * 3 floats; indices: triangle_count * 3, each below
 * vertex_count. edge_neighbor (caller-allocated, triangle_count * 3 entries) receives for edge k of
 * triangle t (corner k -> corner (k+1) % 3) the triangle across that edge, or SCENE_TOPO_NO_NEIGHBOR.
 * Across a returned edge the two triangles have opposite (consistent) winding. split_count receives how
 * many triangles were split off. On failure returns a negative code and writes one line into msg (may be
 * NULL). */
scene_topo_result scene_topo_edge_neighbors(const float *positions, uint32_t vertex_count,
                                            const uint32_t *indices, uint32_t triangle_count,
                                            uint32_t *edge_neighbor, uint32_t *split_count, char *msg,
                                            size_t msg_cap);

#ifdef __cplusplus
}
#endif
#endif
