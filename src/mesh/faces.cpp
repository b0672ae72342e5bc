// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/faces.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>

namespace physreg {

std::vector<std::array<int, 4>> local_faces(CellType type)
{
    if (type == CellType::hexahedron)
        return {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
    return {{0, 2, 1, -1}, {0, 1, 3, -1}, {1, 2, 3, -1}, {0, 3, 2, -1}};
}

std::vector<CellFace> match_faces(const VolumeMesh& mesh)
{
    struct Record {
        std::array<std::int32_t, 4> key;
        std::int32_t cell;
        std::int8_t local;
    };
    const auto faces = local_faces(mesh.cell_type);
    std::vector<Record> records;
    records.reserve(mesh.cell_count() * faces.size());
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const auto ids = mesh.cell(c);
        for (std::size_t f = 0; f < faces.size(); ++f) {
            std::array<std::int32_t, 4> key{-1, -1, -1, -1};
            for (int v = 0; v < 4 && faces[f][v] >= 0; ++v) key[v] = ids[faces[f][v]];
            std::sort(key.begin(), key.end());
            records.push_back({key, static_cast<std::int32_t>(c), static_cast<std::int8_t>(f)});
        }
    }
    std::sort(records.begin(), records.end(), [](const Record& a, const Record& b) {
        return a.key != b.key ? a.key < b.key : a.cell < b.cell;
    });
    std::vector<CellFace> out;
    out.reserve(records.size() / 2 + 16);
    for (std::size_t r = 0; r < records.size();) {
        std::size_t end = r + 1;
        while (end < records.size() && records[end].key == records[r].key) ++end;
        if (end - r > 2)
            fail("mesh: face with nodes ({}, {}, {}, ...) is shared by {} cells (overlapping or non-manifold cells)",
                 records[r].key[0], records[r].key[1], records[r].key[2], end - r);
        CellFace face;
        face.cell = records[r].cell;
        const auto ids = mesh.cell(static_cast<std::size_t>(face.cell));
        for (int v = 0; v < 4; ++v) {
            const int local = faces[records[r].local][v];
            face.nodes[v] = local >= 0 ? ids[local] : -1;
        }
        if (end - r == 2) face.neighbour = records[r + 1].cell;
        out.push_back(face);
        r = end;
    }
    return out;
}

std::vector<BoundaryFace> boundary_faces(const VolumeMesh& mesh)
{
    std::vector<BoundaryFace> out;
    for (const auto& f : match_faces(mesh)) {
        if (f.neighbour >= 0) continue;
        BoundaryFace b{f.nodes, f.node_count(), Vec3::Zero(), Vec3::Zero(), 0.0};
        Vec3 cross;
        if (b.count == 4)
            cross = 0.5 * (mesh.nodes[f.nodes[2]] - mesh.nodes[f.nodes[0]]).cross(mesh.nodes[f.nodes[3]] - mesh.nodes[f.nodes[1]]);
        else
            cross = 0.5 * (mesh.nodes[f.nodes[1]] - mesh.nodes[f.nodes[0]]).cross(mesh.nodes[f.nodes[2]] - mesh.nodes[f.nodes[0]]);
        b.area = cross.norm();
        b.normal = cross / b.area;
        for (int a = 0; a < b.count; ++a) b.centroid += mesh.nodes[f.nodes[a]] / b.count;
        out.push_back(b);
    }
    return out;
}

} // namespace physreg
