// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Sampled surface distances (paper 001's Hausdorff distance): from every sample of one surface —
// its vertices and triangle centroids — to the closest point of the other surface (exact
// point-triangle distance), summarised as mean and max, in both directions.
#include "physreg/mesh/surface_mesh.hpp"

#include <string>
#include <vector>

namespace physreg {

struct SurfaceDistance {
    std::size_t samples = 0;
    double mean_mm = 0.0, max_mm = 0.0;
};

struct HausdorffReport {
    SurfaceDistance forward;  ///< from the first surface's samples to the second surface
    SurfaceDistance backward; ///< from the second's to the first
    double max_mm() const { return std::max(forward.max_mm, backward.max_mm); } ///< the (sampled) Hausdorff distance
    double mean_mm() const { return 0.5 * (forward.mean_mm + backward.mean_mm); }
};

/// Distances from `points` to `surface`. Throws Error naming `what` when the surface has no triangle.
SurfaceDistance points_to_surface(const std::vector<Vec3>& points, const SurfaceMesh& surface, const std::string& what);
/// The samples of a surface: vertices, then triangle centroids.
std::vector<Vec3> surface_samples(const SurfaceMesh& surface);
HausdorffReport hausdorff_distance(const SurfaceMesh& first, const SurfaceMesh& second, const std::string& what);

} // namespace physreg
