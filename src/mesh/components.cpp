// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/components.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/mesh/faces.hpp"

#include <algorithm>
#include <map>
#include <numeric>

namespace physreg {
namespace {

struct UnionFind {
    std::vector<std::int32_t> parent;
    explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
    std::int32_t find(std::int32_t x)
    {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
    }
    void unite(std::int32_t a, std::int32_t b)
    {
        a = find(a);
        b = find(b);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
};

// Grid meshes: neighbours through the dense cell index (fast, no face sort).
void unite_grid_neighbours(const VolumeMesh& mesh, UnionFind& uf)
{
    const Index3& d = mesh.grid->dims;
    std::vector<std::int32_t> cell_at(static_cast<std::size_t>(d[0] * d[1] * d[2]), -1);
    auto linear = [&](const Index3& ijk) { return static_cast<std::size_t>(ijk[0] + d[0] * (ijk[1] + d[1] * ijk[2])); };
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) cell_at[linear(mesh.cell_grid_index[c])] = static_cast<std::int32_t>(c);
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const Index3& ijk = mesh.cell_grid_index[c];
        for (int a = 0; a < 3; ++a) {
            if (ijk[a] == 0) continue;
            Index3 n = ijk;
            --n[a];
            const std::int32_t other = cell_at[linear(n)];
            if (other < 0) continue;
            // Only cells that really share the face's nodes are connected (not after a split).
            const auto ca = mesh.cell(c), cb = mesh.cell(static_cast<std::size_t>(other));
            static constexpr int lo_face[3][4] = {{0, 3, 4, 7}, {0, 1, 4, 5}, {0, 1, 2, 3}};
            static constexpr int hi_face[3][4] = {{1, 2, 5, 6}, {3, 2, 7, 6}, {4, 5, 6, 7}};
            bool shared = true;
            for (int v = 0; v < 4; ++v) shared = shared && ca[lo_face[a][v]] == cb[hi_face[a][v]];
            if (shared) uf.unite(static_cast<std::int32_t>(c), other);
        }
    }
}

} // namespace

ComponentPolicy parse_component_policy(const std::string& text)
{
    if (text == "all") return ComponentPolicy::keep_all;
    if (text == "largest") return ComponentPolicy::keep_largest;
    if (text == "refuse") return ComponentPolicy::refuse;
    fail("--components: '{}' is not one of all, largest, refuse", text);
}

FaceConnectedPieces face_connected_pieces(const VolumeMesh& mesh)
{
    UnionFind uf(mesh.cell_count());
    const bool grid = mesh.grid && mesh.cell_type == CellType::hexahedron &&
                      mesh.cell_grid_index.size() == mesh.cell_count();
    if (grid) {
        unite_grid_neighbours(mesh, uf);
    } else {
        for (const auto& face : match_faces(mesh))
            if (face.neighbour >= 0) uf.unite(face.cell, face.neighbour);
    }
    // Per root: cells and volume (grid cells are all the same box).
    std::vector<std::int32_t> root(mesh.cell_count());
    std::vector<ComponentReport::Piece> by_root(mesh.cell_count());
    const double grid_cell_volume = grid ? mesh.grid->cell_volume_mm3() : 0.0;
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        root[c] = uf.find(static_cast<std::int32_t>(c));
        ++by_root[root[c]].cells;
        by_root[root[c]].volume_mm3 += grid ? grid_cell_volume : cell_volume(mesh, c);
    }
    std::vector<std::int32_t> order;
    for (std::size_t r = 0; r < by_root.size(); ++r)
        if (by_root[r].cells) order.push_back(static_cast<std::int32_t>(r));
    std::stable_sort(order.begin(), order.end(), [&](std::int32_t a, std::int32_t b) {
        return by_root[a].volume_mm3 > by_root[b].volume_mm3;
    });
    std::vector<std::int32_t> rank(mesh.cell_count(), -1);
    FaceConnectedPieces out;
    for (std::size_t p = 0; p < order.size(); ++p) {
        rank[order[p]] = static_cast<std::int32_t>(p);
        out.pieces.push_back(by_root[order[p]]);
    }
    out.piece_of_cell.resize(mesh.cell_count());
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) out.piece_of_cell[c] = rank[root[c]];
    return out;
}

void keep_cells(VolumeMesh& mesh, const std::vector<bool>& keep)
{
    std::vector<std::int32_t> new_id(mesh.node_count(), -1);
    VolumeMesh out;
    out.cell_type = mesh.cell_type;
    out.grid = mesh.grid;
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        if (!keep[c]) continue;
        for (auto n : mesh.cell(c)) {
            if (new_id[n] < 0) {
                new_id[n] = static_cast<std::int32_t>(out.nodes.size());
                out.nodes.push_back(mesh.nodes[n]);
            }
            out.cells.push_back(new_id[n]);
        }
        out.cell_labels.push_back(mesh.cell_labels[c]);
        if (!mesh.cell_grid_index.empty()) out.cell_grid_index.push_back(mesh.cell_grid_index[c]);
    }
    mesh = std::move(out);
}

ComponentReport repair_components(VolumeMesh& mesh, ComponentPolicy policy, bool split_nonmanifold,
                                  const std::string& what)
{
    ComponentReport report;
    const auto found = face_connected_pieces(mesh);
    const auto& piece = found.piece_of_cell;
    report.pieces = found.pieces;
    const auto count = static_cast<std::int32_t>(report.pieces.size());
    // A node used by cells of two pieces joins them only along an edge or at a vertex.
    std::vector<std::int32_t> owner(mesh.node_count(), -1);
    std::map<std::pair<std::int32_t, std::int32_t>, std::int32_t> copies;
    std::vector<bool> is_shared(mesh.node_count(), false);
    for (std::size_t c = 0; c < mesh.cell_count(); ++c)
        for (auto n : mesh.cell(c)) {
            if (owner[n] < 0) owner[n] = piece[c];
            else if (owner[n] != piece[c]) is_shared[n] = true;
        }
    report.nonmanifold_nodes = std::count(is_shared.begin(), is_shared.end(), true);
    if (report.nonmanifold_nodes > 0) {
        if (!split_nonmanifold)
            fail("{}: {} nodes join pieces only along an edge or at a vertex (a hinge in the FE model); "
                 "refusing (allow node splitting to repair)",
                 what, report.nonmanifold_nodes);
        const int per = mesh.cell_size();
        for (std::size_t c = 0; c < mesh.cell_count(); ++c)
            for (int v = 0; v < per; ++v) {
                auto& n = mesh.cells[c * per + v];
                if (!is_shared[n] || owner[n] == piece[c]) continue;
                auto [it, inserted] = copies.try_emplace({n, piece[c]}, static_cast<std::int32_t>(mesh.nodes.size()));
                if (inserted) mesh.nodes.push_back(mesh.nodes[n]);
                n = it->second;
            }
        logger()->warn("{}: split {} nodes where pieces touched only along an edge or at a vertex", what,
                       report.nonmanifold_nodes);
    }
    if (count > 1) {
        if (policy == ComponentPolicy::refuse)
            fail("{}: the mesh has {} disconnected pieces (largest {:.1f} mm³, next {:.1f} mm³); "
                 "use --components largest or all",
                 what, count, report.pieces[0].volume_mm3, report.pieces[1].volume_mm3);
        if (policy == ComponentPolicy::keep_largest) {
            std::vector<bool> keep(mesh.cell_count());
            for (std::size_t c = 0; c < mesh.cell_count(); ++c) keep[c] = piece[c] == 0;
            for (std::size_t p = 1; p < report.pieces.size(); ++p) {
                report.dropped_cells += report.pieces[p].cells;
                report.dropped_volume_mm3 += report.pieces[p].volume_mm3;
            }
            keep_cells(mesh, keep);
            logger()->warn("{}: kept the largest of {} pieces; dropped {} cells ({:.1f} mm³)", what, count,
                           report.dropped_cells, report.dropped_volume_mm3);
        } else {
            logger()->warn("{}: the mesh has {} disconnected pieces (kept all; largest {:.1f} mm³)", what, count,
                           report.pieces[0].volume_mm3);
        }
    }
    return report;
}

} // namespace physreg
