// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// How well a warped segmentation matches the reference, per structure: Dice and the symmetric
// surface distance between the two boundaries (mm).
#include "physreg/image/image_geometry.hpp"

#include <vector>

namespace physreg {

struct StructureOverlap {
    std::int32_t label = 0;
    double dice = 0.0;
    double mean_surface_mm = 0.0, max_surface_mm = 0.0; ///< over both sets' boundary voxels
    std::int64_t reference_voxels = 0, warped_voxels = 0;
};

/// `warped` and `reference` must share the grid (Error otherwise). The boundary of a structure
/// is its voxels with a face neighbour outside it; the distance of a boundary voxel of one set
/// is |φ_other − φ_own| at its centre (both signed distance maps, so that coinciding interfaces
/// give 0 rather than half a voxel). A structure empty in either image gets Dice 0 and no
/// surface distance (NaN).
std::vector<StructureOverlap> compare_segmentations(const LabelVolume& reference, const LabelVolume& warped,
                                                    const std::vector<std::int32_t>& structures);

} // namespace physreg
