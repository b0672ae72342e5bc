// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 001's intra-operative data: the part of the deformed liver surface a laparoscopic camera
// sees, as a noisy point cloud whose points carry anatomical feature labels (an umbilical-notch-
// like cleft and the anterior margin, the two features paper 001 matches separately).
#include "physreg/core/types.hpp"
#include "physreg/io/point_cloud.hpp"
#include "physreg/mesh/labelled_boundary.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <functional>
#include <vector>

namespace physreg {

/// The visible patch: of the triangles facing the camera (deformed normal · view < −0.2, `view`
/// the camera's viewing direction, e.g. +y for a camera above an anterior surface), those whose
/// centroids are nearest, in the image plane, to the centroid of that anterior surface, until
/// `fraction` of its area is kept. Their nodes, displaced by isotropic Gaussian noise of
/// `noise_mm` (seeded), form the cloud.
LabelledPointCloud visible_surface_patch(const VolumeMesh& mesh, const std::vector<double>& displacement_mm,
                                         const BoundarySurface& boundary, double fraction, const Vec3& view,
                                         double noise_mm, std::uint64_t seed);

/// A sparse cloud over most of the surface (issue 32's large-push case): the deformed boundary
/// without the triangles whose centroid `hidden` (e.g. under the tool) and without the most
/// posterior-facing ones (deformed normal · +y largest: the back, against the supports) until
/// `coverage` of the area is left; `count` points drawn area-weighted on what is left, with
/// Gaussian noise `noise_mm`, unlabelled (0), normals of their triangles. `covered` (optional)
/// gets the fraction of the area the cloud spans. Throws Error for coverage outside (0, 1] or
/// count < 3.
LabelledPointCloud sparse_surface_cloud(const VolumeMesh& mesh, const std::vector<double>& displacement_mm, const BoundarySurface& boundary,
                                        double coverage, int count, const std::function<bool(const Vec3&)>& hidden, double noise_mm,
                                        std::uint64_t seed, double* covered = nullptr);

} // namespace physreg
