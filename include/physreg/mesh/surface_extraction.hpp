// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
#include "physreg/mesh/surface_mesh.hpp"
#include "physreg/mesh/volume_mesh.hpp"

namespace physreg {

/// The outer boundary (label {tissue, 0}, normals outward) and every interface between two
/// tissues (label {lower, higher}, normal pointing from the lower label's tissue into the higher).
/// Quadrilateral faces are split into two triangles. Vertices are renumbered compactly.
SurfaceMesh extract_surfaces(const VolumeMesh& mesh);

/// Only the outer boundary.
SurfaceMesh extract_boundary(const VolumeMesh& mesh);

} // namespace physreg
