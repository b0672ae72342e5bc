// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 001's intra-operative data: the part of the deformed liver surface a laparoscopic camera
// sees, as a noisy point cloud whose points carry anatomical feature labels (an umbilical-notch-
// like cleft and the anterior margin, the two features paper 001 matches separately).
#include "physreg/core/types.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <filesystem>
#include <functional>
#include <optional>
#include <vector>

namespace physreg {

enum SurfaceFeature : std::int32_t { feature_none = 0, feature_umbilical_notch = 1, feature_anterior_margin = 2 };

/// The outer boundary of a volume mesh as triangles over the mesh's own node ids (so any nodal
/// displacement deforms it), with outward orientation.
struct BoundarySurface {
    std::vector<std::array<std::int32_t, 3>> triangles; ///< volume-mesh node ids
    std::vector<std::int32_t> nodes;                    ///< the boundary's node ids, sorted
    std::vector<std::int32_t> node_feature;             ///< per entry of `nodes`: SurfaceFeature
};

/// Boundary triangles of `mesh` restricted to cells whose label satisfies `keep` (e.g. the liver,
/// not the kidneys), and feature labels from the rest shape: the anterior margin is where the
/// outward normal lies within 35° of anterior-inferior (0, −1, −1)/√2; the notch is the part of
/// that band and of the inferior surface within 10 mm (in x) of `notch_x_mm`.
BoundarySurface liver_boundary(const VolumeMesh& mesh, const std::function<bool(std::int32_t)>& keep,
                               std::optional<double> notch_x_mm);

struct LabelledPointCloud {
    std::vector<Vec3> points;          ///< mm, LPS
    std::vector<Vec3> normals;         ///< unit, outward (from the deformed surface, before noise)
    std::vector<std::int32_t> labels;  ///< SurfaceFeature
};

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

/// PLY (ascii: x y z nx ny nz label) and CSV (x_mm,y_mm,z_mm,label) writers, atomic.
void write_point_cloud_ply(const std::filesystem::path& path, const LabelledPointCloud& cloud);
void write_point_cloud_csv(const std::filesystem::path& path, const LabelledPointCloud& cloud);
/// CSV: a header x,y,z,label or x,y,z (any case, spaces allowed) or none (3 or 4 numbers per row
/// from the first line); '#' lines are comments; without a label column every point is surface (0).
LabelledPointCloud read_point_cloud_csv(const std::filesystem::path& path);
/// A cloud by extension: .csv (x,y,z[,label]) or .ply (vertices; optional nx ny nz and an integer
/// "label"/"feature" property; unlabelled points are surface, 0). Throws Error naming the file for
/// no points and non-finite coordinates or normals.
LabelledPointCloud read_point_cloud(const std::filesystem::path& path);
/// The labelled boundary as a PLY mesh (vertices with a "feature" property), atomic.
void write_boundary_ply(const std::filesystem::path& path, const VolumeMesh& mesh, const std::vector<double>& displacement_mm,
                        const BoundarySurface& boundary);

} // namespace physreg
