// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A label per cell of a uniform grid: the common currency of meshing and coarsening. A label
// volume is one (voxels are cells), a grid hexahedral mesh is one (its cells), and the majority
// rule turns one into another on a coarser grid.
#include "physreg/image/image_geometry.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/model/tissue_table.hpp"

#include <map>

namespace physreg {

struct LabelGrid {
    HexGrid geometry;                   ///< right-handed; cells = voxels or hexahedra
    std::vector<std::uint16_t> labels;  ///< per cell, x fastest; 0 = empty

    std::uint16_t at(std::int64_t i, std::int64_t j, std::int64_t k) const
    {
        return labels[static_cast<std::size_t>(i + geometry.dims[0] * (j + geometry.dims[1] * k))];
    }
};

/// Voxel count per label value (0 included) of a label volume.
std::map<std::int32_t, std::int64_t> count_labels(const LabelVolume& volume);

/// Crops the volume to the bounding box of its tissue voxels (labels of `tissues`, ignored labels
/// become background). Throws Error naming `what` if a label is in neither the table nor its
/// ignore list, or if no voxel carries a tissue label. A left-handed image direction is turned
/// into a right-handed grid by reversing the third axis, so hexahedra have positive Jacobians.
LabelGrid crop_to_tissues(const LabelVolume& volume, const TissueTable& tissues, const std::string& what);

/// Majority rule on a coarser grid over the same box: every source cell votes for its label
/// (background included) in the target cell holding its centre; the target cell takes the label
/// with most votes (ties: tissue over background, then the smaller label). Throws Error if a
/// target dimension exceeds the source's (a target cell would hold no source cell).
LabelGrid resample_majority(const LabelGrid& source, const Index3& target_dims, const std::string& what);

/// The grid cells of a grid mesh as a dense label grid, cropped to the occupied cells.
LabelGrid label_grid_of_mesh(const VolumeMesh& grid_mesh);

/// One hexahedron per occupied cell, nodes shared between neighbours, grid recorded on the mesh.
VolumeMesh hex_mesh_from_label_grid(const LabelGrid& grid);

} // namespace physreg
