// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Point clouds as intra-operative data arrives (paper 001): points with outward normals and
// feature labels, read from CSV or PLY and written for ParaView and 3D Slicer.
#include "physreg/core/types.hpp"
#include "physreg/mesh/labelled_boundary.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <cstdint>
#include <filesystem>
#include <vector>

namespace physreg {

struct LabelledPointCloud {
    std::vector<Vec3> points;          ///< mm, LPS
    std::vector<Vec3> normals;         ///< unit, outward (from the deformed surface, before noise)
    std::vector<std::int32_t> labels;  ///< SurfaceFeature
};

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
