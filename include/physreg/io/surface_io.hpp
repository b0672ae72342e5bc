// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Triangulated surfaces: STL (binary written; ascii or binary read), PLY (binary little-endian
// written with per-face labels "inside_label"/"outside_label"; ascii or binary read) and
// Wavefront OBJ (labels as groups "g label_<inside>_<outside>") and legacy VTK POLYDATA (ASCII;
// cell scalars inside_label/outside_label or label/region/feature, point scalars label/feature,
// point NORMALS). Format by extension.
#include "physreg/mesh/surface_mesh.hpp"

#include <filesystem>

namespace physreg {

SurfaceMesh read_surface(const std::filesystem::path& path);
/// The vertices of a PLY or legacy VTK file (with its optional normals and vertex labels); triangles are read
/// but not required (point clouds).
SurfaceMesh read_point_set(const std::filesystem::path& path);
void write_surface(const std::filesystem::path& path, const SurfaceMesh& surface);

} // namespace physreg
