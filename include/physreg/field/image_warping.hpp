// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// From a deformed mesh to deformed images: the inverse map x ↦ X(x) (deformed → rest) sampled on
// an image grid, and label / intensity images resampled through it — what an image of the
// deformed organ would show.
#include "physreg/image/image_geometry.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <functional>

namespace physreg {

struct InverseMap {
    /// On the deformed-space grid: d(x) = X(x) − x in mm, so that the rest point of x is x + d(x),
    /// exactly what an ITK DisplacementFieldTransform used to resample the rest image needs.
    DisplacementField field;
    /// Per voxel: 1 inside the deformed mesh, 2 within the extension band around it (d copied
    /// from the nearest covered voxels), 0 elsewhere (d = 0).
    std::vector<std::uint8_t> coverage;
};

/// Rasterises the deformed cells (nodes + displacement_mm) on `geometry`, inverting each cell's
/// map by Newton's method at every voxel centre it covers, then extends d(x) outward by
/// `extension_mm` (layer by layer, mean of the already-covered face neighbours) so that voxels
/// where the label map and the mesh boundary disagree by up to a cell still resample consistently.
InverseMap rasterize_inverse_map(const VolumeMesh& mesh, const std::vector<double>& displacement_mm,
                                 const ImageGeometry& geometry, double extension_mm);

/// Deformed labels on the map's grid (which must equal `rest`'s geometry): voxels whose rest point
/// carries a deforming label take it (nearest voxel); voxels a deforming tissue left are filled with
/// `fill_label`; everything else keeps its rest label.
LabelVolume warp_labels(const LabelVolume& rest, const InverseMap& map,
                        const std::function<bool(std::int32_t)>& deforming, std::uint16_t fill_label);
/// Deformed intensities, trilinear at the rest points; vacated voxels take `fill_value`.
/// `rest_labels` tells which voxels belong to deforming tissues.
ScalarImage warp_intensity(const ScalarImage& rest, const LabelVolume& rest_labels, const LabelVolume& deformed_labels,
                           const InverseMap& map, const std::function<bool(std::int32_t)>& deforming, float fill_value);

} // namespace physreg
