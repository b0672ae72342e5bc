// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Volume meshes by extension: .vtu (VTK XML) and .msh (Gmsh; written as 4.1, or 2.2 for
// "*.v2.msh").
#include "physreg/io/vtu.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <filesystem>

namespace physreg {

VolumeMesh read_volume_mesh(const std::filesystem::path& path, MeshData* data = nullptr);
void write_volume_mesh(const std::filesystem::path& path, const VolumeMesh& mesh, const MeshData& data = {});
/// True for the extensions read_volume_mesh understands.
bool is_volume_mesh_file(const std::filesystem::path& path);

} // namespace physreg
