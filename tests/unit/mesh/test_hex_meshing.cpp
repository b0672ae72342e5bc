// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/error.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/quality.hpp"
#include "test_support.hpp"

namespace physreg {
namespace {

TissueTable two_tissues()
{
    TissueTable t;
    t.tissues = {{1, "parenchyma", 2e5, 0.49, 1000}, {3, "tumour", 5e6, 0.49, 1000}};
    return t;
}

double label_volume(const VolumeMesh& mesh, std::int32_t label)
{
    for (const auto& [l, v] : volume_per_label(mesh))
        if (l == label) return v;
    return 0.0;
}

std::string error_of(const std::function<void()>& f) { return test::error_message(f); }

} // namespace

TEST(MeshHexMeshing, VoxelBlockGivesExactCountsAndVolumes)
{
    // A 4×3×2 block: 3 voxels of tumour (label 3), the rest parenchyma, in a 10³ volume.
    const Vec3 spacing(0.5, 1.5, 2.0);
    const auto volume = test::make_volume({10, 10, 10}, [](int i, int j, int k) -> std::uint16_t {
        if (i < 2 || i > 5 || j < 4 || j > 6 || k < 1 || k > 2) return 0;
        return (j == 4 && k == 1 && i < 5) ? 3 : 1;
    }, spacing, Vec3(10, 20, 30), test::oblique_rotation());
    const auto result = mesh_label_volume(volume, two_tissues(), {}, "block");
    const VolumeMesh& mesh = result.mesh;
    EXPECT_EQ(mesh.cell_count(), 24u);
    EXPECT_EQ(mesh.node_count(), 5u * 4u * 3u);
    const double voxel = spacing.prod();
    EXPECT_NEAR(label_volume(mesh, 3), 3 * voxel, 1e-9);
    EXPECT_NEAR(label_volume(mesh, 1), 21 * voxel, 1e-9);
    const MeshQuality q = measure_quality(mesh);
    EXPECT_EQ(q.inverted_cells, 0u);
    EXPECT_NEAR(q.min_scaled_jacobian, 1.0, 1e-12);
    // The hexahedra sit exactly on the voxels: corner node of voxel (2,4,1) is at index (1.5,3.5,0.5).
    const Vec3 corner = volume.geometry.index_to_physical(Vec3(1.5, 3.5, 0.5));
    double nearest = 1e9;
    for (const auto& p : mesh.nodes) nearest = std::min(nearest, (p - corner).norm());
    EXPECT_LT(nearest, 1e-9);
    EXPECT_EQ(result.report.components.pieces.size(), 1u);
}

TEST(MeshHexMeshing, LeftHandedImagesGivePositiveHexahedra)
{
    Mat3 flip = Mat3::Identity();
    flip(0, 0) = -1; // e.g. an RAS-stored volume read into LPS
    const auto volume = test::make_volume({4, 3, 2}, [](int, int, int) { return std::uint16_t(1); }, Vec3(1, 2, 3), Vec3::Zero(), flip);
    const auto mesh = mesh_label_volume(volume, two_tissues(), {}, "flipped").mesh;
    const MeshQuality q = measure_quality(mesh);
    EXPECT_EQ(q.inverted_cells, 0u);
    EXPECT_NEAR(q.volume_mm3, 24 * 6.0, 1e-9);
}

TEST(MeshHexMeshing, TargetGridUsesTheMajorityRule)
{
    // 8×6×4 voxels in the tissue box, grid 4×3×2 → each cell holds 2×2×2 voxels.
    // Cell (0,0,0): 5 of 8 voxels tissue → kept; cell (1,0,0): 3 of 8 → background, dropped;
    // cell (2,0,0): 4 parenchyma + 3 tumour + 1 empty → parenchyma.
    const auto volume = test::make_volume({10, 8, 6}, [](int i, int j, int k) -> std::uint16_t {
        if (i < 1 || i > 8 || j < 1 || j > 6 || k < 1 || k > 4) return 0;
        const int a = i - 1, b = j - 1, c = k - 1;
        const int cx = a / 2, local = (a % 2) + 2 * (b % 2) + 4 * (c % 2);
        if (b < 2 && c < 2) {
            if (cx == 0) return local < 5 ? 1 : 0;
            if (cx == 1) return local < 3 ? 1 : 0;
            if (cx == 2) return local < 4 ? 1 : (local < 7 ? 3 : 0);
        }
        // keep the box corners so that the bounding box is the whole 8×6×4 block
        return 1;
    });
    MeshingOptions options;
    options.grid_dims = Index3{4, 3, 2};
    const auto result = mesh_label_volume(volume, two_tissues(), options, "majority");
    EXPECT_EQ(result.report.grid.dims, (Index3{4, 3, 2}));
    EXPECT_EQ(result.report.grid.cell_size, Vec3(2, 2, 2));
    EXPECT_EQ(result.mesh.cell_count(), 23u); // 24 cells, one mostly empty
    for (std::size_t c = 0; c < result.mesh.cell_count(); ++c) {
        const auto& ijk = result.mesh.cell_grid_index[c];
        EXPECT_FALSE(ijk == (Index3{1, 0, 0}));
        EXPECT_EQ(result.mesh.cell_labels[c], 1);
    }
    // Voxel-aligned grid: the volume is the kept cells' voxels.
    EXPECT_NEAR(measure_quality(result.mesh).volume_mm3, 23 * 8.0, 1e-9);
}

TEST(MeshHexMeshing, TiesPreferTissueOverBackgroundThenTheSmallerLabel)
{
    const auto volume = test::make_volume({2, 1, 1}, [](int i, int, int) -> std::uint16_t { return i == 0 ? 3 : 1; });
    MeshingOptions options;
    options.grid_dims = Index3{1, 1, 1};
    EXPECT_EQ(mesh_label_volume(volume, two_tissues(), options, "tie").mesh.cell_labels[0], 1);
    // 3 | 0 | 0 | 1 on a 2-cell grid: tumour ties with background (tissue wins), then 0 ties with 1.
    const auto padded = test::make_volume({4, 1, 1}, [](int i, int, int) -> std::uint16_t { return i == 0 ? 3 : (i == 3 ? 1 : 0); });
    options.grid_dims = Index3{2, 1, 1};
    const auto m = mesh_label_volume(padded, two_tissues(), options, "tie").mesh;
    ASSERT_EQ(m.cell_count(), 2u);
    EXPECT_EQ(m.cell_labels[0], 3);
    EXPECT_EQ(m.cell_labels[1], 1);
}

TEST(MeshHexMeshing, EdgeAndVertexContactsAreSplitOrRefused)
{
    // Two voxels touching along an edge, two more touching at a vertex.
    const auto edge = test::make_volume({3, 3, 3}, [](int i, int j, int k) -> std::uint16_t {
        return (i == 0 && j == 0 && k == 0) || (i == 1 && j == 1 && k == 0) ? 1 : 0;
    });
    auto r = mesh_label_volume(edge, two_tissues(), {}, "edge");
    EXPECT_EQ(r.report.components.pieces.size(), 2u);
    EXPECT_EQ(r.report.components.nonmanifold_nodes, 2);
    EXPECT_EQ(r.mesh.node_count(), 16u);
    const auto vertex = test::make_volume({3, 3, 3}, [](int i, int j, int k) -> std::uint16_t {
        return (i == 0 && j == 0 && k == 0) || (i == 1 && j == 1 && k == 1) ? 1 : 0;
    });
    r = mesh_label_volume(vertex, two_tissues(), {}, "vertex");
    EXPECT_EQ(r.report.components.nonmanifold_nodes, 1);
    EXPECT_EQ(r.mesh.node_count(), 16u);

    MeshingOptions refuse;
    refuse.split_nonmanifold = false;
    EXPECT_NE(error_of([&] { mesh_label_volume(edge, two_tissues(), refuse, "edge"); }).find("edge or at a vertex"), std::string::npos);
    refuse.split_nonmanifold = true;
    refuse.components = ComponentPolicy::refuse;
    EXPECT_NE(error_of([&] { mesh_label_volume(edge, two_tissues(), refuse, "edge"); }).find("2 disconnected pieces"), std::string::npos);

    // keep_largest drops the smaller piece and reports it.
    const auto two = test::make_volume({6, 2, 2}, [](int i, int, int) -> std::uint16_t { return i < 3 ? 1 : (i == 5 ? 1 : 0); });
    MeshingOptions largest;
    largest.components = ComponentPolicy::keep_largest;
    r = mesh_label_volume(two, two_tissues(), largest, "two");
    EXPECT_EQ(r.mesh.cell_count(), 12u);
    EXPECT_EQ(r.report.components.dropped_cells, 4);
    EXPECT_NEAR(r.report.components.dropped_volume_mm3, 4.0, 1e-12);
}

TEST(MeshHexMeshing, BadInputIsRefusedWithReasons)
{
    const auto volume = test::make_volume({4, 4, 4}, [](int i, int, int) -> std::uint16_t { return i == 0 ? 5 : 1; });
    EXPECT_NE(error_of([&] { mesh_label_volume(volume, two_tissues(), {}, "v.nii"); }).find("labels 5 (16 voxels)"), std::string::npos);
    TissueTable ignoring = two_tissues();
    ignoring.ignored_labels = {5};
    EXPECT_EQ(mesh_label_volume(volume, ignoring, {}, "v.nii").mesh.cell_count(), 48u);

    const auto empty = test::make_volume({4, 4, 4}, [](int, int, int) -> std::uint16_t { return 0; });
    EXPECT_NE(error_of([&] { mesh_label_volume(empty, two_tissues(), {}, "e.nii"); }).find("empty"), std::string::npos);

    MeshingOptions big;
    big.grid_dims = Index3{5, 2, 2};
    EXPECT_NE(error_of([&] { mesh_label_volume(volume, ignoring, big, "v.nii"); }).find("larger"), std::string::npos);

    EXPECT_NE(error_of([] { parse_grid_dims("74x18", "--grid"); }).find("--grid"), std::string::npos);
    EXPECT_NE(error_of([] { parse_grid_dims("74x0x5", "--grid"); }).find("--grid"), std::string::npos);
    EXPECT_EQ(parse_grid_dims("74x18x54", "--grid"), (Index3{74, 18, 54}));

    LabelVolume bad_spacing = volume;
    bad_spacing.geometry.spacing[1] = 0;
    EXPECT_NE(error_of([&] { mesh_label_volume(bad_spacing, ignoring, {}, "s.nii"); }).find("spacing"), std::string::npos);
}

} // namespace physreg
