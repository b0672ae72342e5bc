// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Gmsh .msh meshes made elsewhere (e.g. SOFA's liver): versions 1, 2.x (ascii and binary) and
// 4.1 (ascii and binary). Tetrahedra (type 4) and hexahedra (type 5) are kept; points, lines and
// surface elements are skipped. A cell's label is its physical tag (version 4: the first physical
// tag of its volume entity, else the entity tag).
#include "physreg/mesh/volume_mesh.hpp"

#include <filesystem>

namespace physreg {

VolumeMesh read_gmsh(const std::filesystem::path& path);

enum class GmshVersion { v2_2, v4_1 };
/// ASCII; labels written as physical (and elementary/entity) tags. Atomic write.
void write_gmsh(const std::filesystem::path& path, const VolumeMesh& mesh, GmshVersion version = GmshVersion::v4_1);

} // namespace physreg
