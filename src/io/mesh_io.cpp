// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/mesh_io.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/io/gmsh.hpp"

namespace physreg {
namespace fs = std::filesystem;

bool is_volume_mesh_file(const fs::path& path)
{
    const auto ext = full_extension(path);
    return ext == ".vtu" || ext == ".msh";
}

VolumeMesh read_volume_mesh(const fs::path& path, MeshData* data)
{
    if (!fs::exists(path)) fail_missing_file("mesh '{}': file does not exist", path.string());
    const auto ext = full_extension(path);
    if (ext == ".vtu") return read_vtu(path, data);
    if (ext == ".msh") {
        if (data) *data = {};
        return read_gmsh(path);
    }
    fail("mesh '{}': unknown extension '{}' (use .vtu or .msh)", path.string(), ext);
}

void write_volume_mesh(const fs::path& path, const VolumeMesh& mesh, const MeshData& data)
{
    const auto ext = full_extension(path);
    if (ext == ".vtu") return write_vtu(path, mesh, data);
    if (ext == ".msh") {
        const bool v2 = path.filename().string().ends_with(".v2.msh");
        return write_gmsh(path, mesh, v2 ? GmshVersion::v2_2 : GmshVersion::v4_1);
    }
    fail("mesh '{}': unknown extension '{}' (use .vtu or .msh)", path.string(), ext);
}

} // namespace physreg
