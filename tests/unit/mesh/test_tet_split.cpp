// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/quality.hpp"
#include "physreg/mesh/tet_split.hpp"
#include "test_support.hpp"

#include <map>

namespace physreg {

TEST(MeshTetSplit, TetrahedraArePositiveConformingAndFillTheHexahedra)
{
    Mat3 left = test::oblique_rotation();
    left.col(1) *= -1; // left-handed image axes as well
    for (const Mat3& direction : {Mat3(Mat3::Identity()), test::oblique_rotation(), left}) {
        const auto volume = test::make_volume({7, 6, 5}, [](int i, int j, int k) -> std::uint16_t {
            const double x = i - 3, y = j - 2.5, z = k - 2;
            return x * x / 9 + y * y / 6.25 + z * z / 4 <= 1.2 ? (i > 4 ? 3 : 1) : 0;
        }, Vec3(1.2, 0.9, 1.7), Vec3(5, 6, 7), direction);
        const VolumeMesh hex = mesh_label_volume(volume, default_tissue_table(), {}, "ellipsoid").mesh;
        const VolumeMesh tets = split_hexahedra_into_tetrahedra(hex);
        ASSERT_EQ(tets.cell_count(), 6 * hex.cell_count());
        double total = 0.0;
        for (std::size_t t = 0; t < tets.cell_count(); ++t) {
            const double v = cell_volume(tets, t);
            EXPECT_GT(v, 0.0) << "tetrahedron " << t;
            total += v;
            EXPECT_EQ(tets.cell_labels[t], hex.cell_labels[t / 6]);
        }
        EXPECT_NEAR(total, measure_quality(hex).volume_mm3, 1e-9 * total);
        // Conforming: every triangle is shared by two tetrahedra or lies on the hexahedral boundary;
        // boundary triangles are exactly two per boundary quadrilateral.
        std::size_t hex_boundary = 0, tet_boundary = 0;
        for (const auto& f : match_faces(hex)) hex_boundary += f.neighbour < 0;
        for (const auto& f : match_faces(tets)) tet_boundary += f.neighbour < 0;
        EXPECT_EQ(tet_boundary, 2 * hex_boundary);
        EXPECT_EQ(measure_quality(tets).inverted_cells, 0u);
    }
}

} // namespace physreg
