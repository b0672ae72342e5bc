// SPDX-License-Identifier: GPL-3.0-or-later
// Meshes a 4×3×2-voxel label block with the installed library and checks the hexahedral mesh.
#include <physreg/core/version.hpp>
#include <physreg/mesh/hex_meshing.hpp>
#include <physreg/model/tissue_table.hpp>

#include <cstdio>

int main()
{
    physreg::LabelVolume volume;
    volume.geometry.size = physreg::Index3{4, 3, 2};
    volume.geometry.spacing = physreg::Vec3(2.0, 2.0, 2.0);
    volume.labels.assign(24, 1);
    const auto result = physreg::mesh_label_volume(volume, physreg::default_tissue_table(), {}, "consumer block");
    std::printf("physreg %s: %zu nodes, %zu cells\n", physreg::VERSION, result.mesh.node_count(), result.mesh.cell_count());
    return result.mesh.cell_count() == 24 && result.mesh.node_count() == 60 ? 0 : 1;
}
