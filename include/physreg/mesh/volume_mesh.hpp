// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The volumetric mesh every solver consumes: nodes in physical mm (LPS), one cell type per mesh,
// one tissue label per cell. Hexahedra follow VTK's node order (0-3 bottom face counter-clockwise
// seen from inside +ξ3, 4-7 the top face), which is also Gmsh's.
#include "physreg/core/types.hpp"

#include <optional>
#include <span>
#include <string>
#include <vector>

namespace physreg {

enum class CellType { tetrahedron, hexahedron };

constexpr int nodes_per_cell(CellType type) { return type == CellType::hexahedron ? 8 : 4; }
std::string to_string(CellType type);

/// A uniform, right-handed grid of hexahedral cells: node (i,j,k) sits at
/// origin + direction * (i·h0, j·h1, k·h2).
struct HexGrid {
    Vec3 origin = Vec3::Zero();       ///< mm, corner node (0,0,0)
    Vec3 cell_size = Vec3::Ones();    ///< mm along each grid axis
    Mat3 direction = Mat3::Identity(); ///< columns: grid axes in LPS, det = +1
    Index3 dims{0, 0, 0};             ///< cells per axis

    Vec3 node_position(std::int64_t i, std::int64_t j, std::int64_t k) const
    {
        return origin + direction * Vec3(i * cell_size[0], j * cell_size[1], k * cell_size[2]);
    }
    /// Physical point to continuous grid-node coordinates (node (i,j,k) ↦ (i,j,k)).
    Vec3 to_grid(const Vec3& point) const
    {
        return (direction.transpose() * (point - origin)).cwiseQuotient(cell_size);
    }
    std::int64_t cell_count() const { return dims[0] * dims[1] * dims[2]; }
    double cell_volume_mm3() const { return cell_size.prod(); }
};

struct VolumeMesh {
    CellType cell_type = CellType::hexahedron;
    std::vector<Vec3> nodes;              ///< mm, LPS
    std::vector<std::int32_t> cells;      ///< nodes_per_cell() node ids per cell
    std::vector<std::int32_t> cell_labels; ///< tissue label per cell (label-volume value)
    /// Present for meshes built on a uniform grid: its geometry and each cell's (i,j,k).
    std::optional<HexGrid> grid;
    std::vector<Index3> cell_grid_index;

    std::size_t node_count() const { return nodes.size(); }
    std::size_t cell_count() const { return cell_labels.size(); }
    int cell_size() const { return nodes_per_cell(cell_type); }
    std::span<const std::int32_t> cell(std::size_t c) const
    {
        return {cells.data() + c * static_cast<std::size_t>(cell_size()), static_cast<std::size_t>(cell_size())};
    }
    /// Throws Error naming `what` on inconsistent sizes, out-of-range node ids or non-finite nodes.
    void validate(const std::string& what) const;
};

/// Volume of a cell in mm³ (hexahedra: exact 2×2×2 Gauss integral of det J; tetrahedra: exact).
double cell_volume(const VolumeMesh& mesh, std::size_t cell);
/// Sum of cell volumes per label, mm³.
std::vector<std::pair<std::int32_t, double>> volume_per_label(const VolumeMesh& mesh);

/// Trilinear hexahedron shape functions N_a(ξ), ξ ∈ [-1,1]³, in VTK node order.
std::array<double, 8> hex_shape_functions(const Vec3& xi);
/// Corner a's natural coordinates (±1, ±1, ±1).
Vec3 hex_corner_natural(int a);

} // namespace physreg
