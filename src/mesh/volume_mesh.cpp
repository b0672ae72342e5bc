// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/volume_mesh.hpp"

#include "physreg/core/error.hpp"

#include <Eigen/LU>
#include <cmath>
#include <map>

namespace physreg {

std::string to_string(CellType type) { return type == CellType::hexahedron ? "hexahedron" : "tetrahedron"; }

Vec3 hex_corner_natural(int a)
{
    static constexpr int sx[8] = {-1, 1, 1, -1, -1, 1, 1, -1};
    static constexpr int sy[8] = {-1, -1, 1, 1, -1, -1, 1, 1};
    static constexpr int sz[8] = {-1, -1, -1, -1, 1, 1, 1, 1};
    return {double(sx[a]), double(sy[a]), double(sz[a])};
}

std::array<double, 8> hex_shape_functions(const Vec3& xi)
{
    std::array<double, 8> n{};
    for (int a = 0; a < 8; ++a) {
        const Vec3 c = hex_corner_natural(a);
        n[a] = 0.125 * (1 + c[0] * xi[0]) * (1 + c[1] * xi[1]) * (1 + c[2] * xi[2]);
    }
    return n;
}

void VolumeMesh::validate(const std::string& what) const
{
    const std::size_t per = static_cast<std::size_t>(cell_size());
    if (cells.size() != per * cell_labels.size())
        fail("{}: {} connectivity entries for {} cells of {} nodes", what, cells.size(), cell_labels.size(), per);
    for (std::size_t i = 0; i < cells.size(); ++i)
        if (cells[i] < 0 || static_cast<std::size_t>(cells[i]) >= nodes.size())
            fail("{}: cell {} refers to node {} but the mesh has {} nodes", what, i / per, cells[i], nodes.size());
    for (std::size_t n = 0; n < nodes.size(); ++n)
        if (!nodes[n].allFinite()) fail("{}: node {} has a non-finite coordinate", what, n);
    if (grid && cell_grid_index.size() != cell_labels.size())
        fail("{}: grid mesh has {} grid indices for {} cells", what, cell_grid_index.size(), cell_labels.size());
}

double cell_volume(const VolumeMesh& mesh, std::size_t c)
{
    const auto ids = mesh.cell(c);
    if (mesh.cell_type == CellType::tetrahedron) {
        const Vec3& p0 = mesh.nodes[ids[0]];
        Mat3 m;
        m << mesh.nodes[ids[1]] - p0, mesh.nodes[ids[2]] - p0, mesh.nodes[ids[3]] - p0;
        return m.determinant() / 6.0;
    }
    const double g = 1.0 / std::sqrt(3.0);
    double volume = 0.0;
    for (int q = 0; q < 8; ++q) {
        const Vec3 xi = hex_corner_natural(q) * g;
        Mat3 jacobian = Mat3::Zero();
        for (int a = 0; a < 8; ++a) {
            const Vec3 c = hex_corner_natural(a);
            const Vec3 dn(0.125 * c[0] * (1 + c[1] * xi[1]) * (1 + c[2] * xi[2]),
                          0.125 * c[1] * (1 + c[0] * xi[0]) * (1 + c[2] * xi[2]),
                          0.125 * c[2] * (1 + c[0] * xi[0]) * (1 + c[1] * xi[1]));
            jacobian += mesh.nodes[ids[a]] * dn.transpose();
        }
        volume += jacobian.determinant();
    }
    return volume;
}

std::vector<std::pair<std::int32_t, double>> volume_per_label(const VolumeMesh& mesh)
{
    std::map<std::int32_t, double> sums;
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) sums[mesh.cell_labels[c]] += cell_volume(mesh, c);
    return {sums.begin(), sums.end()};
}

} // namespace physreg
