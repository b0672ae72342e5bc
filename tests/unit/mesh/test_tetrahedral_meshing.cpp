// SPDX-License-Identifier: GPL-3.0-or-later
// CGAL Mesh_3 meshes of label volumes: conforming interfaces, label volumes close to the true
// shapes (not the voxel staircase), quality figures, determinism per seed, bad input.
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/tetrahedral_meshing.hpp"
#include "test_support.hpp"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <cmath>
#include <map>

namespace physreg {

namespace {

// A 40 mm cube of label 1 (0.5 mm voxels) holding a sphere of radius 10 mm, label 2.
LabelVolume sphere_in_cube()
{
    return test::make_volume({80, 80, 80}, [](int i, int j, int k) {
        const Vec3 x = 0.5 * Vec3(i + 0.5, j + 0.5, k + 0.5) - Vec3(20, 20, 20);
        return std::uint16_t(x.norm() < 10.0 ? 2 : 1);
    }, Vec3::Constant(0.5), Vec3::Constant(0.25));
}

TetMeshingOptions options()
{
    TetMeshingOptions o;
    o.cell_size_mm = {{2, 2.0}};
    o.default_cell_size_mm = 4.0;
    o.facet_size_mm = 2.0;
    o.facet_distance_mm = 0.2;
    o.seed = 3;
    return o;
}

} // namespace

TEST(TetrahedralMeshing, SphereInCubeIsConformingAndCloseToTheTrueVolumes)
{
    const VolumeMesh mesh = mesh_labels_tetrahedral(sphere_in_cube(), options(), "sphere in cube");
    ASSERT_EQ(mesh.cell_type, CellType::tetrahedron);
    std::map<std::int32_t, double> volume;
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const auto n = mesh.cell(c);
        const Vec3 a = mesh.nodes[n[1]] - mesh.nodes[n[0]], b = mesh.nodes[n[2]] - mesh.nodes[n[0]], d = mesh.nodes[n[3]] - mesh.nodes[n[0]];
        const double v = a.cross(b).dot(d) / 6.0;
        ASSERT_GT(v, 0.0) << "cell " << c << " is not positively oriented";
        volume[mesh.cell_labels[c]] += v;
    }
    const double sphere = 4.0 / 3.0 * M_PI * 1000.0, cube = 64000.0;
    EXPECT_NEAR(volume[2], sphere, 0.02 * sphere);
    EXPECT_NEAR(volume[1] + volume[2], cube, 0.01 * cube);
    // Conformity: every face is shared by two cells or lies on the outer boundary (the cube's
    // faces), none hangs inside; interface faces sit on the sphere to within the facet distance.
    std::size_t interface_faces = 0;
    double worst = 0.0;
    for (const auto& f : match_faces(mesh)) {
        if (f.neighbour < 0) {
            const Vec3 centre = (mesh.nodes[f.nodes[0]] + mesh.nodes[f.nodes[1]] + mesh.nodes[f.nodes[2]]) / 3.0;
            const double to_box = std::min((centre.array() - 0.0).abs().minCoeff(), (centre.array() - 40.0).abs().minCoeff());
            // On the cube's faces; near its edges and corners CGAL rounds them (no feature protection).
            EXPECT_LT(to_box, 1.0) << "a boundary face inside the cube: the mesh is not conforming";
            continue;
        }
        if (mesh.cell_labels[f.cell] == mesh.cell_labels[f.neighbour]) continue;
        ++interface_faces;
        for (int a = 0; a < 3; ++a) worst = std::max(worst, std::abs((mesh.nodes[f.nodes[a]] - Vec3(20, 20, 20)).norm() - 10.0));
    }
    EXPECT_GT(interface_faces, 200u);
    EXPECT_LT(worst, 0.35); // interface vertices lie on the true sphere (the voxel staircase is 0.25–0.43 mm off)
    const TetrahedronQuality q = measure_tetrahedra(mesh);
    EXPECT_EQ(q.cells, mesh.cell_count());
    EXPECT_GT(q.min_dihedral_deg, 1.0);
    EXPECT_GT(q.mean_radius_ratio, 0.6);
    EXPECT_LE(q.max_edge_mm, 4.0 * 2.0 + 1e-9); // circumradius 4 mm bounds the edge by 8 mm
}

// A volume whose direction cosines are turned (a segmentation resampled onto a turned grid) or
// mirrored is meshed in its grid's own axes: the mesh is the axis-aligned volume's mesh turned about
// the origin, node for node, its tetrahedra positively oriented, and the sphere where the turned
// geometry puts it.
TEST(TetrahedralMeshing, ATurnedOrMirroredGridIsMeshedInItsOwnAxes)
{
    const LabelVolume straight = sphere_in_cube();
    const VolumeMesh reference = mesh_labels_tetrahedral(straight, options(), "straight");
    for (const bool mirrored : {false, true}) {
        LabelVolume turned = straight;
        Mat3 d = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
        if (mirrored) d.col(2) *= -1.0;
        turned.geometry.direction = d;
        const VolumeMesh mesh = mesh_labels_tetrahedral(turned, options(), "turned");
        ASSERT_EQ(mesh.node_count(), reference.node_count());
        ASSERT_EQ(mesh.cell_count(), reference.cell_count());
        const Vec3 o = straight.geometry.origin;
        for (std::size_t n = 0; n < mesh.node_count(); ++n)
            ASSERT_LT((mesh.nodes[n] - (o + d * (reference.nodes[n] - o))).norm(), 1e-9) << "node " << n;
        double sphere = 0.0;
        for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
            const auto n = mesh.cell(c);
            const Vec3 a = mesh.nodes[n[1]] - mesh.nodes[n[0]], b = mesh.nodes[n[2]] - mesh.nodes[n[0]], e = mesh.nodes[n[3]] - mesh.nodes[n[0]];
            const double v = a.cross(b).dot(e) / 6.0;
            ASSERT_GT(v, 0.0) << "cell " << c << (mirrored ? " (mirrored grid)" : " (turned grid)");
            if (mesh.cell_labels[c] == 2) sphere += v;
        }
        EXPECT_NEAR(sphere, 4.0 / 3.0 * M_PI * 1000.0, 0.02 * 4.0 / 3.0 * M_PI * 1000.0);
        // The sphere's centre (index 39.5 in each axis) is where the turned geometry maps it.
        const Vec3 centre = turned.geometry.index_to_physical(Vec3::Constant(39.5));
        double worst = 0.0;
        for (std::size_t c = 0; c < mesh.cell_count(); ++c)
            if (mesh.cell_labels[c] == 2)
                for (const auto node : mesh.cell(c)) worst = std::max(worst, (mesh.nodes[static_cast<std::size_t>(node)] - centre).norm());
        EXPECT_LT(worst, 10.4);
    }
}

TEST(TetrahedralMeshing, SameSeedSameMeshAndBadInputIsRefused)
{
    const LabelVolume volume = sphere_in_cube();
    TetMeshingOptions o = options();
    const VolumeMesh a = mesh_labels_tetrahedral(volume, o, "a"), b = mesh_labels_tetrahedral(volume, o, "b");
    ASSERT_EQ(a.node_count(), b.node_count());
    EXPECT_EQ(a.cells, b.cells);
    for (std::size_t n = 0; n < a.node_count(); ++n) EXPECT_EQ(a.nodes[n], b.nodes[n]);
    TetMeshingOptions only_sphere = o;
    only_sphere.labels = {2};
    const VolumeMesh sphere = mesh_labels_tetrahedral(volume, only_sphere, "sphere");
    for (const auto l : sphere.cell_labels) EXPECT_EQ(l, 2);

    TetMeshingOptions missing = o;
    missing.labels = {7};
    EXPECT_NE(test::error_message([&] { mesh_labels_tetrahedral(volume, missing, "volume 'v'"); }).find("no voxel"), std::string::npos);
    TetMeshingOptions bad = o;
    bad.facet_size_mm = 0.0;
    EXPECT_NE(test::error_message([&] { mesh_labels_tetrahedral(volume, bad, "v"); }).find("facet_size_mm"), std::string::npos);
    bad = o;
    bad.radius_edge_ratio = 1.0;
    EXPECT_NE(test::error_message([&] { mesh_labels_tetrahedral(volume, bad, "v"); }).find("radius_edge_ratio"), std::string::npos);
    bad = o;
    bad.cell_size_mm[2] = std::nan("");
    EXPECT_NE(test::error_message([&] { mesh_labels_tetrahedral(volume, bad, "v"); }).find("cell_size_mm[2]"), std::string::npos);
}

} // namespace physreg
