// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/error.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/tet_split.hpp"
#include "test_support.hpp"

namespace physreg {

TEST(FieldSampling, LinearNodalFieldsAreReproducedAtVoxelCentres)
{
    const auto volume = test::make_volume({6, 5, 4}, [](int i, int j, int k) -> std::uint16_t {
        return (i + j + k) % 7 == 0 ? 0 : 1; // a few holes: voxels there are outside the mesh
    }, Vec3(2.0, 1.5, 3.0), Vec3(-4, 5, 1), test::oblique_rotation());
    const VolumeMesh hex = mesh_label_volume(volume, default_tissue_table(), {}, "v").mesh;
    const VolumeMesh tets = split_hexahedra_into_tetrahedra(hex);
    Mat3 g;
    g << 0.1, -0.02, 0.03, 0.0, 0.05, 0.01, -0.04, 0.02, 0.0;
    const Vec3 t(0.5, -1.0, 2.0);
    for (const VolumeMesh* mesh : {&hex, &tets}) {
        std::vector<double> u;
        for (const auto& p : mesh->nodes) {
            const Vec3 v = g * p + t;
            u.insert(u.end(), {v[0], v[1], v[2]});
        }
        // Sample on the label volume's own grid: voxel centres of tissue voxels are inside.
        const SampledField s = sample_displacement_field(*mesh, u, volume.geometry);
        std::size_t inside = 0;
        for (std::int64_t k = 0; k < 4; ++k)
            for (std::int64_t j = 0; j < 5; ++j)
                for (std::int64_t i = 0; i < 6; ++i) {
                    const auto v = static_cast<std::size_t>(volume.geometry.linear_index(i, j, k));
                    const bool tissue = volume.labels[v] != 0;
                    EXPECT_EQ(s.inside[v] != 0, tissue) << i << "," << j << "," << k;
                    const Vec3 x = volume.geometry.index_to_physical(Vec3(double(i), double(j), double(k)));
                    const Vec3 expected = tissue ? Vec3(g * x + t) : Vec3::Zero();
                    for (int c = 0; c < 3; ++c) EXPECT_NEAR(s.field.components[3 * v + c], expected[c], 1e-5);
                    inside += tissue;
                }
        EXPECT_GT(inside, 80u);
    }
}

TEST(FieldSampling, GridOverMeshAndBadInput)
{
    const auto volume = test::make_volume({3, 3, 3}, [](int, int, int) { return std::uint16_t(1); });
    const VolumeMesh mesh = mesh_label_volume(volume, default_tissue_table(), {}, "v").mesh;
    const ImageGeometry g = image_grid_over_mesh(mesh, 0.5, 1.0);
    EXPECT_EQ(g.size, (Index3{11, 11, 11}));
    EXPECT_LT((g.origin - Vec3::Constant(-1.5)).norm(), 1e-12);
    EXPECT_THROW(image_grid_over_mesh(mesh, 0.0), Error);
    EXPECT_THROW(sample_displacement_field(mesh, std::vector<double>(5, 0.0), g), Error);
}

} // namespace physreg
