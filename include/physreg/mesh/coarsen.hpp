// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 000's coarse model: a grid mesh re-gridded with the majority rule (e.g. 74×18×54 →
// 24×18×18), and every fine node embedded in the coarse element that contains it.
#include "physreg/mesh/components.hpp"
#include "physreg/mesh/volume_mesh.hpp"

namespace physreg {

/// Where a point sits in a mesh: cell and natural coordinates ξ (hexahedra: ξ ∈ [-1,1]³ inside;
/// tetrahedra: barycentric λ1..λ3, λ0 = 1 − Σ).
struct NodeEmbedding {
    std::int32_t cell = -1;
    Vec3 natural = Vec3::Zero();
    bool inside = false;       ///< false: the nearest cell, ξ extrapolated beyond [-1,1]
    double distance_mm = 0.0;  ///< distance to that cell (0 inside)
};

struct CoarseningResult {
    VolumeMesh mesh;
    ComponentReport components;
    std::vector<NodeEmbedding> fine_nodes; ///< one per node of the fine mesh
};

CoarseningResult coarsen(const VolumeMesh& fine, const Index3& dims, ComponentPolicy policy);

/// Embeds points in a grid hexahedral mesh (exact: cells are boxes of the grid).
std::vector<NodeEmbedding> embed_in_grid_mesh(const VolumeMesh& grid_mesh, const std::vector<Vec3>& points);

} // namespace physreg
