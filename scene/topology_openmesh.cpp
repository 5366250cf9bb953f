// topology_openmesh.cpp: the OpenMesh shim behind topology.h (the only C++ of the island builder).
//
// Builds an OpenMesh TriMesh from the welded scene triangles, one face per scene triangle in scene order,
// so face index == triangle index. A triangle OpenMesh refuses (complex edge, complex vertex, failed patch
// re-linking, repeated corner) is added again with three fresh copies of its vertices: it keeps its face
// index but has no neighbour, so the island builder makes it an island of its own. Then every half-edge of
// every face is read back as "triangle across edge k". Exceptions never leave this file: they become
// scene_topo_result codes with a message.
#include "topology.h"

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>

#include <climits>
#include <cstdio>
#include <exception>
#include <new>
#include <vector>

namespace
{

typedef OpenMesh::TriMesh_ArrayKernelT<> TopoMesh;

// Writes a one-line message if the caller gave a buffer.
void topo_message(char *msg, size_t msg_cap, const char *text, unsigned long long value)
{
    if (msg && msg_cap > 0)
        std::snprintf(msg, msg_cap, text, value);
}

// Silences OpenMesh's "complex edge" chatter on omerr for the lifetime of the guard: refusals are expected
// here and counted instead of printed.
struct OmerrSilencer {
    bool was_enabled;
    OmerrSilencer() : was_enabled(::omerr().is_enabled())
    {
        ::omerr().disable();
    }
    ~OmerrSilencer()
    {
        if (was_enabled)
            ::omerr().enable();
    }
};

// Adds triangle t with fresh copies of its three vertices; returns false if OpenMesh still refuses.
bool add_isolated_face(TopoMesh &mesh, const float *positions, const uint32_t *corner,
                       TopoMesh::VertexHandle handles[3])
{
    for (int k = 0; k < 3; k++) {
        const float *p = positions + 3 * (size_t)corner[k];
        handles[k] = mesh.add_vertex(TopoMesh::Point(p[0], p[1], p[2]));
    }
    return mesh.add_face(handles[0], handles[1], handles[2]).is_valid();
}

// The body of scene_topo_edge_neighbors, free to throw.
scene_topo_result build_neighbors(const float *positions, uint32_t vertex_count, const uint32_t *indices,
                                  uint32_t triangle_count, uint32_t *edge_neighbor, uint32_t *split_count,
                                  char *msg, size_t msg_cap)
{
    // OpenMesh indexes with int; every split-off triangle may add three vertices.
    if ((uint64_t)triangle_count * 3 + vertex_count > (uint64_t)INT_MAX / 2) {
        topo_message(msg, msg_cap, "topology: %llu triangles are more than OpenMesh can index",
                     (unsigned long long)triangle_count);
        return SCENE_TOPO_ERR_INVALID;
    }
    for (size_t i = 0; i < (size_t)triangle_count * 3; i++)
        if (indices[i] >= vertex_count) {
            topo_message(msg, msg_cap, "topology: vertex index out of range in triangle %llu",
                         (unsigned long long)(i / 3));
            return SCENE_TOPO_ERR_INVALID;
        }

    OmerrSilencer silencer;
    TopoMesh mesh;
    mesh.reserve(vertex_count, (size_t)triangle_count * 3 / 2 + 16, triangle_count);
    std::vector<TopoMesh::VertexHandle> shared(vertex_count);
    for (uint32_t v = 0; v < vertex_count; v++) {
        const float *p = positions + 3 * (size_t)v;
        shared[v] = mesh.add_vertex(TopoMesh::Point(p[0], p[1], p[2]));
    }

    // The vertex handles each face was built from, to find edge k among the face's half-edges.
    std::vector<TopoMesh::VertexHandle> face_corner((size_t)triangle_count * 3);
    uint32_t refused = 0;
    for (uint32_t t = 0; t < triangle_count; t++) {
        const uint32_t *corner = indices + 3 * (size_t)t;
        TopoMesh::VertexHandle *handles = &face_corner[3 * (size_t)t];
        bool repeated = corner[0] == corner[1] || corner[1] == corner[2] || corner[0] == corner[2];
        TopoMesh::FaceHandle face;
        if (!repeated) {
            for (int k = 0; k < 3; k++)
                handles[k] = shared[corner[k]];
            face = mesh.add_face(handles[0], handles[1], handles[2]);
        }
        if (!face.is_valid()) {
            refused++;
            if (!add_isolated_face(mesh, positions, corner, handles)) {
                topo_message(msg, msg_cap, "topology: OpenMesh refused isolated triangle %llu",
                             (unsigned long long)t);
                return SCENE_TOPO_ERR_INTERNAL;
            }
        }
        if ((size_t)mesh.n_faces() != (size_t)t + 1) {
            topo_message(msg, msg_cap, "topology: face index out of step at triangle %llu",
                         (unsigned long long)t);
            return SCENE_TOPO_ERR_INTERNAL;
        }
    }

    for (uint32_t t = 0; t < triangle_count; t++) {
        const TopoMesh::VertexHandle *handles = &face_corner[3 * (size_t)t];
        uint32_t *out = edge_neighbor + 3 * (size_t)t;
        out[0] = out[1] = out[2] = SCENE_TOPO_NO_NEIGHBOR;
        TopoMesh::FaceHandle face((int)t);
        TopoMesh::HalfedgeHandle first = mesh.halfedge_handle(face), he = first;
        for (int step = 0; step < 3; step++, he = mesh.next_halfedge_handle(he)) {
            TopoMesh::VertexHandle from = mesh.from_vertex_handle(he);
            int k = from == handles[0] ? 0 : from == handles[1] ? 1 : from == handles[2] ? 2 : -1;
            if (k < 0) {
                topo_message(msg, msg_cap, "topology: face %llu lost a corner", (unsigned long long)t);
                return SCENE_TOPO_ERR_INTERNAL;
            }
            TopoMesh::FaceHandle across = mesh.face_handle(mesh.opposite_halfedge_handle(he));
            if (across.is_valid())
                out[k] = (uint32_t)across.idx();
        }
    }
    *split_count = refused;
    return SCENE_TOPO_OK;
}

} // namespace

extern "C" scene_topo_result scene_topo_edge_neighbors(const float *positions, uint32_t vertex_count,
                                                       const uint32_t *indices, uint32_t triangle_count,
                                                       uint32_t *edge_neighbor, uint32_t *split_count,
                                                       char *msg, size_t msg_cap)
{
    if (msg && msg_cap > 0)
        msg[0] = 0;
    *split_count = 0;
    try {
        return build_neighbors(positions, vertex_count, indices, triangle_count, edge_neighbor, split_count,
                               msg, msg_cap);
    } catch (const std::bad_alloc &) {
        topo_message(msg, msg_cap, "topology: out of memory building the half-edge mesh (%llu triangles)",
                     (unsigned long long)triangle_count);
        return SCENE_TOPO_ERR_NOMEM;
    } catch (const std::exception &e) {
        if (msg && msg_cap > 0)
            std::snprintf(msg, msg_cap, "topology: OpenMesh failed: %s", e.what());
        return SCENE_TOPO_ERR_INTERNAL;
    } catch (...) {
        topo_message(msg, msg_cap, "topology: unknown exception from OpenMesh (%llu triangles)",
                     (unsigned long long)triangle_count);
        return SCENE_TOPO_ERR_INTERNAL;
    }
}
