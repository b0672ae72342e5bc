// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/quality.hpp"
#include "test_support.hpp"

namespace physreg {
namespace {

MeshingResult fine_mesh(const std::function<std::uint16_t(int, int, int)>& label, Index3 size, std::optional<Index3> grid)
{
    const auto volume = test::make_volume(size, label, Vec3(1.0, 0.5, 2.0), Vec3(-7, 3, 11), test::oblique_rotation());
    MeshingOptions options;
    options.grid_dims = grid;
    return mesh_label_volume(volume, default_tissue_table(), options, "fine");
}

} // namespace

TEST(MeshCoarsen, AlignedGridKeepsVolumeAndMajorityLabels)
{
    // 12×12×12 voxels → fine 12³ grid (one voxel per cell) → coarse 4×3×6 (3×4×2 fine cells each).
    // Labels are constant on coarse cells except for a minority of tumour cells in two of them.
    auto label = [](int i, int j, int k) -> std::uint16_t {
        const int ci = i / 3, cj = j / 4, ck = k / 2;
        if ((ci == 1 && cj == 1 && ck == 2) && i % 3 == 0 && j % 4 == 0) return 3; // 2 of 24 cells
        return std::uint16_t((ci + cj + ck) % 2 + 1);
    };
    const auto fine = fine_mesh(label, {12, 12, 12}, Index3{12, 12, 12});
    const auto result = coarsen(fine.mesh, {4, 3, 6}, ComponentPolicy::keep_all);
    const VolumeMesh& coarse = result.mesh;
    EXPECT_EQ(coarse.cell_count(), 72u);
    EXPECT_NEAR(measure_quality(coarse).volume_mm3, measure_quality(fine.mesh).volume_mm3, 1e-8);
    for (std::size_t c = 0; c < coarse.cell_count(); ++c) {
        const auto& ijk = coarse.cell_grid_index[c];
        EXPECT_EQ(coarse.cell_labels[c], (ijk[0] + ijk[1] + ijk[2]) % 2 + 1) << "coarse cell " << c;
    }
}

TEST(MeshCoarsen, EveryFineNodeIsEmbeddedAndReproduced)
{
    auto label = [](int i, int j, int k) -> std::uint16_t {
        const double x = i - 19.5, y = j - 15.5, z = k - 13.5;
        return x * x / 361 + y * y / 225 + z * z / 169 <= 1 ? (x > 6 ? 3 : 1) : 0;
    };
    const auto fine = fine_mesh(label, {40, 32, 28}, std::nullopt); // one hexahedron per voxel
    const auto result = coarsen(fine.mesh, {10, 8, 7}, ComponentPolicy::keep_all); // ≈ 4³ voxels per cell
    ASSERT_EQ(result.fine_nodes.size(), fine.mesh.node_count());
    std::size_t inside = 0;
    for (std::size_t n = 0; n < fine.mesh.node_count(); ++n) {
        const NodeEmbedding& e = result.fine_nodes[n];
        ASSERT_GE(e.cell, 0);
        // Trilinear interpolation of the coarse cell's nodes at ξ gives back the fine node, inside or
        // (extrapolated) outside: the coarse cells are exact boxes.
        const auto weights = hex_shape_functions(e.natural);
        Vec3 x = Vec3::Zero();
        const auto ids = result.mesh.cell(static_cast<std::size_t>(e.cell));
        for (int a = 0; a < 8; ++a) x += weights[a] * result.mesh.nodes[ids[a]];
        EXPECT_LT((x - fine.mesh.nodes[n]).norm(), 1e-9) << "fine node " << n;
        if (e.inside) {
            ++inside;
            EXPECT_LE(e.natural.cwiseAbs().maxCoeff(), 1.0);
            EXPECT_EQ(e.distance_mm, 0.0);
        } else {
            EXPECT_GT(e.distance_mm, 0.0);
        }
    }
    EXPECT_GT(inside, fine.mesh.node_count() * 3 / 4);
    // The majority rule keeps the volume approximately (unaligned cells): within 10 %.
    const double v_fine = measure_quality(fine.mesh).volume_mm3, v_coarse = measure_quality(result.mesh).volume_mm3;
    EXPECT_NEAR(v_coarse / v_fine, 1.0, 0.10);
}

} // namespace physreg
