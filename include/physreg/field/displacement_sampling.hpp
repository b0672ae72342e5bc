// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// From nodal displacements to a dense displacement-field image usable in ITK, 3D Slicer and ANTs.
#include "physreg/image/image_geometry.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <vector>

namespace physreg {

/// An axis-aligned (LPS) image grid covering the mesh's bounding box plus `margin_mm`, with
/// isotropic `spacing_mm`. Throws Error for non-positive spacing or an image over 512 M voxels.
ImageGeometry image_grid_over_mesh(const VolumeMesh& mesh, double spacing_mm, double margin_mm = 0.0);

struct SampledField {
    DisplacementField field;          ///< u(x) in mm at every voxel centre; 0 outside the mesh
    std::vector<std::uint8_t> inside; ///< 1 where the voxel centre lies in the mesh
};

/// Interpolates nodal displacements (3 per node, mm) with the elements' shape functions at every
/// voxel centre of `geometry`. The field lives in the reference (pre-operative) space: a point x
/// moves to x + u(x). Grid meshes are sampled by direct cell lookup, others through a point
/// locator. Voxels outside the mesh get u = 0 and inside = 0.
SampledField sample_displacement_field(const VolumeMesh& mesh, const std::vector<double>& displacement_mm,
                                       const ImageGeometry& geometry);

} // namespace physreg
