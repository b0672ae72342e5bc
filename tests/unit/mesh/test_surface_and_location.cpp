// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/error.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/mesh/quality.hpp"
#include "physreg/mesh/surface_extraction.hpp"
#include "physreg/mesh/tet_split.hpp"
#include "test_support.hpp"

#include <map>
#include <random>

namespace physreg {
namespace {

VolumeMesh two_tissue_block()
{
    // 4×3×3 block, the last column (i = 3) is tumour.
    const auto volume = test::make_volume({6, 5, 5}, [](int i, int j, int k) -> std::uint16_t {
        if (i < 1 || i > 4 || j < 1 || j > 3 || k < 1 || k > 3) return 0;
        return i == 4 ? 3 : 1;
    }, Vec3(1.0, 2.0, 0.5), Vec3(1, 2, 3), test::oblique_rotation());
    return mesh_label_volume(volume, default_tissue_table(), {}, "block").mesh;
}

// Volume enclosed by a closed, outward-oriented triangulated surface (divergence theorem).
double enclosed_volume(const SurfaceMesh& s, std::array<std::int32_t, 2> label_filter, bool interfaces_count_inside)
{
    double v = 0.0;
    for (std::size_t t = 0; t < s.triangles.size(); ++t) {
        const auto& l = s.labels[t];
        double sign = 0;
        if (l[1] == 0 && l[0] == label_filter[0]) sign = 1;
        if (interfaces_count_inside && l[0] == label_filter[0] && l[1] == label_filter[1]) sign = 1;
        if (interfaces_count_inside && l[1] == label_filter[0] && l[0] == label_filter[1]) sign = -1;
        if (sign == 0) continue;
        const auto& tri = s.triangles[t];
        v += sign * s.vertices[tri[0]].dot(s.vertices[tri[1]].cross(s.vertices[tri[2]])) / 6.0;
    }
    return v;
}

} // namespace

TEST(MeshSurface, BoundaryAndInterfaceAreClosedAndOriented)
{
    const VolumeMesh mesh = two_tissue_block();
    const SurfaceMesh all = extract_surfaces(mesh);
    const SurfaceMesh boundary = extract_boundary(mesh);
    // Boundary quads of a 4×3×3 block: 2·(4·3 + 4·3 + 3·3) = 66 → 132 triangles; interface 3·3 → 18.
    EXPECT_EQ(boundary.triangles.size(), 132u);
    EXPECT_EQ(all.triangles.size(), 150u);
    std::size_t interface = 0;
    for (const auto& l : all.labels) interface += l == std::array<std::int32_t, 2>{1, 3};
    EXPECT_EQ(interface, 18u);
    // Closed: every edge of the boundary is used twice, in opposite directions.
    std::map<std::pair<int, int>, int> edges;
    for (const auto& t : boundary.triangles)
        for (int e = 0; e < 3; ++e) ++edges[{t[e], t[(e + 1) % 3]}];
    for (const auto& [e, count] : edges) {
        EXPECT_EQ(count, 1);
        EXPECT_EQ(edges.count({e.second, e.first}), 1u);
    }
    // Outward orientation: the enclosed volume equals the mesh volume; parenchyma (label 1) is
    // enclosed by its boundary faces plus the interface, oriented from 1 into 3.
    const auto vols = volume_per_label(mesh);
    EXPECT_NEAR(enclosed_volume(boundary, {1, 0}, false) + enclosed_volume(boundary, {3, 0}, false),
                measure_quality(mesh).volume_mm3, 1e-9);
    EXPECT_NEAR(enclosed_volume(all, {1, 3}, true), vols[0].second, 1e-9);
}

TEST(MeshPointLocation, LocatesInterpolatesAndRefusesOutsidePoints)
{
    const VolumeMesh hex = two_tissue_block();
    const VolumeMesh tets = split_hexahedra_into_tetrahedra(hex);
    // A linear field is reproduced exactly by both element types.
    auto linear = [](const Vec3& p) { return 2.0 * p[0] - 0.5 * p[1] + 3.0 * p[2] + 7.0; };
    std::mt19937 rng(42);
    for (const VolumeMesh* mesh : {&hex, &tets}) {
        std::vector<double> field;
        for (const auto& p : mesh->nodes) field.push_back(linear(p));
        const PointLocator locator(*mesh);
        std::uniform_int_distribution<std::size_t> pick(0, mesh->cell_count() - 1);
        std::uniform_real_distribution<double> w(0.05, 1.0);
        for (int trial = 0; trial < 200; ++trial) {
            // A random convex combination of a cell's nodes lies inside that cell.
            const std::size_t c = pick(rng);
            Vec3 p = Vec3::Zero();
            double total = 0;
            for (auto n : mesh->cell(c)) {
                const double weight = w(rng);
                p += weight * mesh->nodes[n];
                total += weight;
            }
            p /= total;
            const NodeEmbedding e = locator.locate_or_throw(p, "sample");
            EXPECT_NEAR(interpolate_nodal(*mesh, e, field, 1)[0], linear(p), 1e-9);
        }
        // Outside: a point beyond the box.
        const Vec3 far = mesh->nodes[0] + Vec3(100, 0, 0);
        EXPECT_FALSE(locator.locate(far).has_value());
        try {
            locator.locate_or_throw(far, "landmark 'tip'");
            FAIL() << "expected an error";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("landmark 'tip'"), std::string::npos);
            EXPECT_NE(std::string(e.what()).find("outside the mesh"), std::string::npos);
        }
        EXPECT_FALSE(locator.locate(Vec3(std::nan(""), 0, 0)).has_value());
    }
}

} // namespace physreg
