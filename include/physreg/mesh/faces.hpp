// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Cell faces of a volume mesh matched across neighbours (by sorted node ids): the basis of
// surface extraction, connectivity analysis and conformity checks on unstructured meshes.
#include "physreg/mesh/volume_mesh.hpp"

#include <array>
#include <vector>

namespace physreg {

struct CellFace {
    std::array<std::int32_t, 4> nodes{-1, -1, -1, -1}; ///< oriented outward from `cell`; 3 used for triangles
    std::int32_t cell = -1;
    std::int32_t neighbour = -1; ///< cell on the other side, -1 on the boundary
    int node_count() const { return nodes[3] < 0 ? 3 : 4; }
};

/// Local faces of a cell type, outward oriented (right-hand rule) for a positively oriented cell.
std::vector<std::array<int, 4>> local_faces(CellType type);

/// Every face once: interior faces carry both cells (cell < neighbour), boundary faces one.
/// Throws Error if a face is shared by more than two cells (non-manifold, overlapping cells).
std::vector<CellFace> match_faces(const VolumeMesh& mesh);

/// A boundary face with its outward unit normal, centroid (mm) and area (mm²) in the mesh's
/// reference configuration.
struct BoundaryFace {
    std::array<std::int32_t, 4> nodes;
    int count;
    Vec3 normal, centroid;
    double area;
};
std::vector<BoundaryFace> boundary_faces(const VolumeMesh& mesh);
} // namespace physreg
