// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
#include "physreg/mesh/volume_mesh.hpp"

namespace physreg {

struct MeshQuality {
    std::size_t nodes = 0, cells = 0;
    double volume_mm3 = 0.0;
    double min_cell_volume_mm3 = 0.0, max_cell_volume_mm3 = 0.0;
    /// Scaled Jacobian: 1 for a cube / regular tetrahedron, ≤ 0 for inverted cells.
    double min_scaled_jacobian = 0.0, mean_scaled_jacobian = 0.0;
    double max_edge_ratio = 0.0;   ///< longest / shortest edge of a cell, worst cell
    double min_edge_mm = 0.0, max_edge_mm = 0.0;
    std::size_t inverted_cells = 0; ///< scaled Jacobian ≤ 0
};

MeshQuality measure_quality(const VolumeMesh& mesh);

} // namespace physreg
