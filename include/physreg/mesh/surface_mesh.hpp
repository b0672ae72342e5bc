// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Triangulated surfaces: the outer boundary and tissue interfaces of a volume mesh, or a surface
// read from STL/PLY/OBJ. Each triangle carries the label of the tissue on each side.
#include "physreg/core/types.hpp"

#include <array>
#include <vector>

namespace physreg {

struct SurfaceMesh {
    std::vector<Vec3> vertices;                        ///< mm, LPS
    std::vector<std::array<std::int32_t, 3>> triangles; ///< counter-clockwise seen from outside
    /// Per triangle: {label inside, label outside}; outside 0 = exterior. Empty if unlabelled.
    std::vector<std::array<std::int32_t, 2>> labels;
    /// Optional per-vertex data read from PLY files (empty when absent): normals (nx, ny, nz) and an
    /// integer vertex label ("label" or "feature", e.g. paper 001's surface regions).
    std::vector<Vec3> vertex_normals;
    std::vector<std::int32_t> vertex_labels;

    void validate(const std::string& what) const;
};

} // namespace physreg
