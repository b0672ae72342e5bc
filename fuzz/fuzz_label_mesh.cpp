// SPDX-License-Identifier: GPL-3.0-or-later
// Label volume → hexahedral mesh (paper 000's meshing) on tiny random volumes, then the surfaces
// and the tetrahedral split that the solvers use. Input bytes: sizes (3), spacing and direction,
// options, then one label per voxel (0-4; 4 is not in the tissue table). An accepted volume must
// give a valid mesh of positive, uninverted cells with the volume's labels.
#include "fuzz_support.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/quality.hpp"
#include "physreg/mesh/surface_extraction.hpp"
#include "physreg/mesh/tet_split.hpp"

#include <cmath>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    using namespace physreg;
    if (size < 6) return 0;
    LabelVolume volume;
    volume.geometry.size = {1 + data[0] % 7, 1 + data[1] % 7, 1 + data[2] % 7};
    const double spacings[] = {1.0, 0.5, 2.5, 0.1, 3.0, 1e-3, 1e3, 0.0};
    volume.geometry.spacing = Vec3(spacings[data[3] & 7], spacings[(data[3] >> 3) & 7], 1.0);
    if (data[3] & 0x40) volume.geometry.direction = Eigen::AngleAxisd(0.3, Vec3(1, 2, 3).normalized()).toRotationMatrix();
    if (data[3] & 0x80) volume.geometry.direction.col(2) *= -1.0; // left-handed image axes
    volume.geometry.origin = Vec3(-12.5, 40.0, 3.25);
    const std::uint8_t flags = data[4];
    MeshingOptions options;
    if (flags & 1) options.grid_dims = Index3{1 + (flags >> 1) % 4, 1 + (flags >> 3) % 4, 1 + (flags >> 5) % 4};
    options.components = static_cast<ComponentPolicy>(data[5] % 3);
    options.split_nonmanifold = (data[5] & 4) != 0;

    const std::size_t voxels = static_cast<std::size_t>(volume.geometry.voxel_count());
    volume.labels.assign(voxels, 0);
    for (std::size_t v = 0; v < voxels && 6 + v < size; ++v) volume.labels[v] = static_cast<std::uint16_t>(data[6 + v] % 5);

    const TissueTable tissues = default_tissue_table();
    fuzz::expect_success_or_error([&] {
        const MeshingResult result = mesh_label_volume(volume, tissues, options, "fuzzed volume");
        const VolumeMesh& mesh = result.mesh;
        mesh.validate("fuzzed mesh");
        fuzz::check(mesh.cell_count() > 0, "a mesh that is returned has cells");
        for (const auto label : mesh.cell_labels) fuzz::check(tissues.find(label) != nullptr, "cell labels are tissues");
        const MeshQuality quality = measure_quality(mesh);
        fuzz::check(quality.inverted_cells == 0 && quality.min_cell_volume_mm3 > 0, "no inverted or empty cells");
        const SurfaceMesh surface = extract_boundary(mesh);
        for (const auto& triangle : surface.triangles)
            for (const auto v : triangle) fuzz::check(v >= 0 && v < static_cast<std::int32_t>(surface.vertices.size()), "surface ids");
        const VolumeMesh tets = split_hexahedra_into_tetrahedra(mesh);
        tets.validate("fuzzed tetrahedra");
        // Relative 1e-6: round-off on cells of aspect ratio 1e6 (spacing 1e3 × 1e-3 mm) reaches 1e-8;
        // a lost or doubled tetrahedron changes the volume by ≥ 1 / (6 · 343 cells) = 5e-4.
        fuzz::check(std::abs(measure_quality(tets).volume_mm3 - quality.volume_mm3) <= 1e-6 * quality.volume_mm3,
                    "the tetrahedral split keeps the volume");
    });
    return 0;
}
