// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 000, "Hexahedral mesh construction": a uniform hexahedral mesh straight from a label
// volume, one hexahedron per voxel or on a target grid over the tissues' bounding box.
#include "physreg/image/image_geometry.hpp"
#include "physreg/mesh/components.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/model/tissue_table.hpp"

#include <map>
#include <optional>

namespace physreg {

struct MeshingOptions {
    /// Cells per axis over the tissues' bounding box (majority rule); none = one per voxel.
    std::optional<Index3> grid_dims;
    ComponentPolicy components = ComponentPolicy::keep_all;
    bool split_nonmanifold = true;
};

struct MeshingReport {
    std::map<std::int32_t, std::int64_t> voxels_per_label; ///< of the input volume, 0 included
    HexGrid grid;                                          ///< the grid the cells sit on
    ComponentReport components;
};

struct MeshingResult {
    VolumeMesh mesh;
    MeshingReport report;
};

/// `what` names the input in error messages (e.g. the file name).
MeshingResult mesh_label_volume(const LabelVolume& volume, const TissueTable& tissues,
                                const MeshingOptions& options, const std::string& what);

/// "74x18x54" → {74, 18, 54}; throws Error naming `option` otherwise.
Index3 parse_grid_dims(const std::string& text, const std::string& option);

} // namespace physreg
