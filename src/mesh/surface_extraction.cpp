// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/surface_extraction.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/faces.hpp"

#include <cmath>

namespace physreg {

void SurfaceMesh::validate(const std::string& what) const
{
    for (std::size_t t = 0; t < triangles.size(); ++t)
        for (auto v : triangles[t])
            if (v < 0 || static_cast<std::size_t>(v) >= vertices.size())
                fail("{}: triangle {} refers to vertex {} of {}", what, t, v, vertices.size());
    for (std::size_t v = 0; v < vertices.size(); ++v)
        if (!vertices[v].allFinite()) fail("{}: vertex {} is not finite", what, v);
    if (!labels.empty() && labels.size() != triangles.size())
        fail("{}: {} labels for {} triangles", what, labels.size(), triangles.size());
    if (!vertex_normals.empty() && vertex_normals.size() != vertices.size())
        fail("{}: {} vertex normals for {} vertices", what, vertex_normals.size(), vertices.size());
    if (!vertex_labels.empty() && vertex_labels.size() != vertices.size())
        fail("{}: {} vertex labels for {} vertices", what, vertex_labels.size(), vertices.size());
}

namespace {

SurfaceMesh extract(const VolumeMesh& mesh, bool interfaces)
{
    SurfaceMesh out;
    std::vector<std::int32_t> vertex_of(mesh.node_count(), -1);
    auto vertex = [&](std::int32_t n) {
        if (vertex_of[n] < 0) {
            vertex_of[n] = static_cast<std::int32_t>(out.vertices.size());
            out.vertices.push_back(mesh.nodes[n]);
        }
        return vertex_of[n];
    };
    for (const auto& face : match_faces(mesh)) {
        const std::int32_t inside = mesh.cell_labels[face.cell];
        std::int32_t outside = 0;
        bool flip = false;
        if (face.neighbour >= 0) {
            outside = mesh.cell_labels[face.neighbour];
            if (!interfaces || outside == inside) continue;
            // Orient from the lower label into the higher: the face is outward from `cell`.
            if (inside > outside) flip = true;
        }
        std::array<std::int32_t, 4> v{};
        const int count = face.node_count();
        for (int i = 0; i < count; ++i) v[i] = vertex(face.nodes[i]);
        std::array<std::int32_t, 2> label = flip ? std::array<std::int32_t, 2>{outside, inside}
                                                 : std::array<std::int32_t, 2>{inside, outside};
        auto add = [&](std::int32_t a, std::int32_t b, std::int32_t c) {
            out.triangles.push_back(flip ? std::array<std::int32_t, 3>{a, c, b} : std::array<std::int32_t, 3>{a, b, c});
            out.labels.push_back(label);
        };
        add(v[0], v[1], v[2]);
        if (count == 4) add(v[0], v[2], v[3]);
    }
    return out;
}

} // namespace

SurfaceMesh extract_surfaces(const VolumeMesh& mesh) { return extract(mesh, true); }
SurfaceMesh extract_boundary(const VolumeMesh& mesh) { return extract(mesh, false); }

} // namespace physreg
