// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Choosing the nodes a load or constraint acts on, in physical terms.
#include "physreg/mesh/volume_mesh.hpp"

#include <optional>
#include <string>
#include <vector>

namespace physreg {

struct NodeSelection {
    /// A face of the mesh's bounding box: axis 0/1/2 (x/y/z, LPS) and side "min" or "max";
    /// nodes within tolerance_mm of it.
    std::optional<int> axis;
    std::string side;
    double tolerance_mm = 1e-6;
    /// Or an axis-aligned box (mm).
    std::optional<Vec3> box_min, box_max;
    /// Or explicit node ids.
    std::vector<std::int32_t> nodes;
    /// Restrict to boundary (surface) nodes.
    bool surface_only = false;
};

/// Throws Error naming `what` when the selection is ill-formed, names nodes that do not exist,
/// or selects nothing.
std::vector<std::int32_t> select_nodes(const VolumeMesh& mesh, const NodeSelection& selection, const std::string& what);

} // namespace physreg
