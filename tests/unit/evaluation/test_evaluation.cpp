// SPDX-License-Identifier: GPL-3.0-or-later
// evaluation/ against hand-computed values (issue 43 item 5): TRE statistics and groups, Dice and
// surface distances of label volumes, point-to-surface and Hausdorff distances, and the error
// predicted from strain energy.
#include "physreg/evaluation/predicted_error.hpp"
#include "physreg/evaluation/segmentation_overlap.hpp"
#include "physreg/evaluation/surface_distance.hpp"
#include "physreg/evaluation/tre.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace physreg {

TEST(Evaluation, TreStatisticsAndGroupsAreTheHandComputedOnes)
{
    // Errors 3, 4 (surface), 0 (tumour), 12 (vessel): mean 4.75, population sd √(Σ(e−4.75)²/4).
    const LandmarkSet truth{{"s1", Vec3(0, 0, 0), LandmarkType::surface},
                            {"s2", Vec3(10, 0, 0), LandmarkType::surface},
                            {"t", Vec3(0, 10, 0), LandmarkType::tumour},
                            {"v", Vec3(0, 0, 10), LandmarkType::vessel}};
    const LandmarkSet predicted{{"v", Vec3(0, 0, 22), LandmarkType::vessel}, // order differs: matched by name
                                {"s1", Vec3(3, 0, 0), LandmarkType::surface},
                                {"s2", Vec3(10, 4, 0), LandmarkType::surface},
                                {"t", Vec3(0, 10, 0), LandmarkType::tumour}};
    const TreReport r = compute_tre(predicted, truth, "hand");
    EXPECT_EQ(r.all.count, 4u);
    EXPECT_DOUBLE_EQ(r.all.mean_mm, 4.75);
    const double sd = std::sqrt((std::pow(3 - 4.75, 2) + std::pow(4 - 4.75, 2) + std::pow(0 - 4.75, 2) + std::pow(12 - 4.75, 2)) / 4);
    EXPECT_NEAR(r.all.std_mm, sd, 1e-12);
    EXPECT_DOUBLE_EQ(r.all.max_mm, 12.0);
    EXPECT_DOUBLE_EQ(r.surface.mean_mm, 3.5);
    EXPECT_EQ(r.internal.count, 2u); // tumour and vessel
    EXPECT_DOUBLE_EQ(r.internal.mean_mm, 6.0);
    EXPECT_DOUBLE_EQ(r.tumour.mean_mm, 0.0);
    EXPECT_DOUBLE_EQ(r.vessel.max_mm, 12.0);
    // Pooling two reports is the statistics over all their landmarks.
    const TreReport pooled = pool_tre({r, r});
    EXPECT_EQ(pooled.all.count, 8u);
    EXPECT_DOUBLE_EQ(pooled.all.mean_mm, 4.75);
    // A truth landmark without a prediction is an error naming it.
    LandmarkSet fewer = predicted;
    fewer.pop_back();
    EXPECT_NE(test::error_message([&] { compute_tre(fewer, truth, "hand"); }).find("hand"), std::string::npos);
}

TEST(Evaluation, DiceAndSurfaceDistanceOfTwoBoxes)
{
    // Reference: an 8×8×8 box; warped: the same box shifted one voxel along x (1 mm voxels).
    // Overlap 7×8×8 = 448 of 512 each: Dice = 2·448 / 1024 = 0.875.
    const auto box = [](int shift) {
        return test::make_volume({20, 20, 20}, [shift](int i, int j, int k) {
            return std::uint16_t(i >= 6 + shift && i < 14 + shift && j >= 6 && j < 14 && k >= 6 && k < 14 ? 1 : 0);
        });
    };
    const auto o = compare_segmentations(box(0), box(1), {1});
    ASSERT_EQ(o.size(), 1u);
    EXPECT_DOUBLE_EQ(o[0].dice, 0.875);
    EXPECT_EQ(o[0].reference_voxels, 512);
    EXPECT_EQ(o[0].warped_voxels, 512);
    // The boundaries: the two x faces move by 1 mm, the others stay: max 1 mm, mean below it.
    EXPECT_NEAR(o[0].max_surface_mm, 1.0, 1e-6);
    EXPECT_GT(o[0].mean_surface_mm, 0.0);
    EXPECT_LT(o[0].mean_surface_mm, 1.0);
    // The same box: Dice 1, no distance.
    const auto same = compare_segmentations(box(0), box(0), {1});
    EXPECT_DOUBLE_EQ(same[0].dice, 1.0);
    EXPECT_NEAR(same[0].max_surface_mm, 0.0, 1e-9);
}

TEST(Evaluation, PointToSurfaceAndHausdorffDistances)
{
    // A 10 × 10 mm square in the plane z = 0 (two triangles), and the same square at z = 2.5.
    const auto square = [](double z) {
        SurfaceMesh s;
        s.vertices = {Vec3(0, 0, z), Vec3(10, 0, z), Vec3(10, 10, z), Vec3(0, 10, z)};
        s.triangles = {{0, 1, 2}, {0, 2, 3}};
        return s;
    };
    // Points above the square at heights 1 and 3, and one 4 mm beside its edge (closest: the edge).
    const SurfaceDistance d = points_to_surface({Vec3(5, 5, 1), Vec3(2, 8, -3), Vec3(14, 5, 0)}, square(0), "square");
    EXPECT_EQ(d.samples, 3u);
    EXPECT_NEAR(d.mean_mm, (1.0 + 3.0 + 4.0) / 3.0, 1e-12);
    EXPECT_NEAR(d.max_mm, 4.0, 1e-12);
    const HausdorffReport h = hausdorff_distance(square(0), square(2.5), "squares");
    EXPECT_NEAR(h.max_mm(), 2.5, 1e-12);
    EXPECT_NEAR(h.mean_mm(), 2.5, 1e-12);
    EXPECT_EQ(h.forward.samples, 6u); // 4 vertices and 2 centroids
    EXPECT_NE(test::error_message([&] { points_to_surface({Vec3::Zero()}, SurfaceMesh{}, "nothing"); }).find("nothing"), std::string::npos);
}

TEST(Evaluation, PredictedErrorScalesWithTheStrainTheEnergyImplies)
{
    // A 100 mm cube of a linear material (nu = 0) stretched uniformly by 2 %: U = E eps^2 V / 2, so
    // the energy's displacement scale L sqrt(2U/(EV)) is exactly L eps = 2 mm, whatever E.
    const double V = 1e6, eps = 0.02;
    for (const double E : {1000.0, 3500.0, 20000.0}) {
        const double U_mj = 0.5 * E * eps * eps * V * 1e-9 * 1e3; // Pa x m^3 = J, in mJ
        const PredictedError p = predict_error_from_strain_energy(U_mj, E, V, SupportRegime::springs);
        EXPECT_NEAR(p.energy_scale_mm, 2.0, 1e-9) << E;
        EXPECT_GT(p.mean_mm, 0.0);
        EXPECT_LT(p.low_mm, p.mean_mm);
        EXPECT_GT(p.high_mm, p.mean_mm);
        EXPECT_DOUBLE_EQ(p.interval_coverage, 0.8);
    }
    // Twice the strain, twice the predicted error; held supports predict less for the same energy
    // (the springs let the organ drift, which costs little energy and much error).
    const auto at = [&](double e, SupportRegime r) { return predict_error_from_strain_energy(0.5 * 3500 * e * e * V * 1e-6, 3500, V, r); };
    EXPECT_NEAR(at(0.04, SupportRegime::springs).mean_mm, 2.0 * at(0.02, SupportRegime::springs).mean_mm, 1e-12);
    EXPECT_LT(at(0.02, SupportRegime::held).mean_mm, at(0.02, SupportRegime::springs).mean_mm);
    EXPECT_EQ(predict_error_from_strain_energy(0.0, 3500, V, SupportRegime::held).mean_mm, 0.0);
    const nlohmann::json j = to_json(at(0.02, SupportRegime::held));
    EXPECT_EQ(j["regime"], "held");
    EXPECT_EQ(j["interval_mm"].size(), 2u);
    // Impossible inputs name the parameter.
    EXPECT_NE(test::error_message([&] { predict_error_from_strain_energy(-1.0, 3500, V, SupportRegime::held); }).find("strain energy"), std::string::npos);
    EXPECT_NE(test::error_message([&] { predict_error_from_strain_energy(NAN, 3500, V, SupportRegime::held); }).find("strain energy"), std::string::npos);
    EXPECT_NE(test::error_message([&] { predict_error_from_strain_energy(1.0, 0.0, V, SupportRegime::held); }).find("Young"), std::string::npos);
    EXPECT_NE(test::error_message([&] { predict_error_from_strain_energy(1.0, 3500, -V, SupportRegime::held); }).find("volume"), std::string::npos);
}

} // namespace physreg
