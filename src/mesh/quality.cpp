// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/quality.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

namespace physreg {
namespace {

// Corner a of a cell and its three edge neighbours, ordered so that a positive cell gives det > 0.
constexpr int hex_corner_edges[8][3] = {{1, 3, 4}, {2, 0, 5}, {3, 1, 6}, {0, 2, 7},
                                        {7, 5, 0}, {4, 6, 1}, {5, 7, 2}, {6, 4, 3}};
constexpr int tet_corner_edges[4][3] = {{1, 2, 3}, {2, 0, 3}, {0, 1, 3}, {1, 0, 2}};

} // namespace

MeshQuality measure_quality(const VolumeMesh& mesh)
{
    MeshQuality q;
    q.nodes = mesh.node_count();
    q.cells = mesh.cell_count();
    if (q.cells == 0) return q;
    q.min_cell_volume_mm3 = q.min_scaled_jacobian = q.min_edge_mm = std::numeric_limits<double>::infinity();
    q.max_cell_volume_mm3 = -q.min_cell_volume_mm3;
    const bool hex = mesh.cell_type == CellType::hexahedron;
    const int corners = hex ? 8 : 4;
    double sum_sj = 0.0;
    for (std::size_t c = 0; c < q.cells; ++c) {
        const auto ids = mesh.cell(c);
        const double volume = cell_volume(mesh, c);
        q.volume_mm3 += volume;
        q.min_cell_volume_mm3 = std::min(q.min_cell_volume_mm3, volume);
        q.max_cell_volume_mm3 = std::max(q.max_cell_volume_mm3, volume);
        double cell_sj = std::numeric_limits<double>::infinity();
        double shortest = std::numeric_limits<double>::infinity(), longest = 0.0;
        for (int a = 0; a < corners; ++a) {
            Mat3 m;
            for (int e = 0; e < 3; ++e) {
                const int b = hex ? hex_corner_edges[a][e] : tet_corner_edges[a][e];
                const Vec3 edge = mesh.nodes[ids[b]] - mesh.nodes[ids[a]];
                const double length = edge.norm();
                shortest = std::min(shortest, length);
                longest = std::max(longest, length);
                m.col(e) = length > 0 ? Vec3(edge / length) : Vec3::Zero();
            }
            double sj = m.determinant();
            if (!hex) sj *= std::sqrt(2.0); // regular tetrahedron → 1
            cell_sj = std::min(cell_sj, sj);
        }
        q.min_scaled_jacobian = std::min(q.min_scaled_jacobian, cell_sj);
        sum_sj += cell_sj;
        q.inverted_cells += cell_sj <= 0.0;
        q.min_edge_mm = std::min(q.min_edge_mm, shortest);
        q.max_edge_mm = std::max(q.max_edge_mm, longest);
        q.max_edge_ratio = std::max(q.max_edge_ratio, shortest > 0 ? longest / shortest : std::numeric_limits<double>::infinity());
    }
    q.mean_scaled_jacobian = sum_sj / double(q.cells);
    return q;
}

} // namespace physreg
