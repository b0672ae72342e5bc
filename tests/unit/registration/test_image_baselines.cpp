// SPDX-License-Identifier: GPL-3.0-or-later
// Paper 002's baselines (ITK rigid, Demons, B-spline) on synthetic pairs with a known motion, and
// the field tools the comparison rests on (sampling, inversion, resampling).
#include "test_support.hpp"

#include "physreg/core/error.hpp"
#include "physreg/field/field_mapping.hpp"
#include "physreg/registration/images/image_baselines.hpp"
#include "physreg/registration/images/image_registration.hpp"

#include <cmath>

namespace physreg {
namespace {

// An ellipsoid (label 1) holding a ball (label 2), 2 mm voxels, shifted by `shift` mm: the moving
// image of a pair whose true fixed→moving displacement is `shift` everywhere.
LabelVolume organ(const Vec3& shift)
{
    return test::make_volume({40, 36, 32}, [&](int i, int j, int k) -> std::uint16_t {
        const Vec3 x = Vec3(2.0 * i, 2.0 * j, 2.0 * k) - shift;
        const Vec3 c(40, 36, 32);
        if ((x - c - Vec3(6, 2, 0)).norm() < 7.0) return 2;
        const Vec3 e = (x - c).cwiseQuotient(Vec3(24, 18, 14));
        return e.squaredNorm() < 1.0 ? 1 : 0;
    }, Vec3(2, 2, 2));
}

Vec3 field_at(const DisplacementField& f, const Vec3& x) { return sample_field(f, x); }

TEST(ImageBaselines, RigidDemonsAndBSplineRecoverAKnownTranslation)
{
    const Vec3 shift(4.0, -2.0, 2.0); // whole voxels: the rasterised labels move by exactly this much
    const ScalarImage fixed = label_intensity_image(organ(Vec3::Zero()), {1, 2});
    const ScalarImage moving = label_intensity_image(organ(shift), {1, 2});
    BaselineOptions o;
    o.bspline_grid_mm = 40.0;
    const Vec3 centre(40, 36, 32);
    for (const BaselineMethod m : {BaselineMethod::rigid, BaselineMethod::demons, BaselineMethod::bspline}) {
        const BaselineResult r = register_baseline(fixed, moving, m, true, o);
        // Rigid and Demons (whose smoothing spreads the motion) recover the shift inside the organ;
        // the unregularised B-spline is pinned where the image has an edge only (inside a uniform
        // structure its control points see no data), so it is checked on the surface.
        const std::vector<Vec3> inside{centre, Vec3(centre + Vec3(10, 0, 0)), Vec3(centre + Vec3(-8, 6, 4))};
        const std::vector<Vec3> surface{Vec3(centre + Vec3(24, 0, 0)), Vec3(centre - Vec3(24, 0, 0)), Vec3(centre + Vec3(0, 18, 0)),
                                        Vec3(centre - Vec3(0, 18, 0)), Vec3(centre + Vec3(0, 0, 14)), Vec3(centre - Vec3(0, 0, 14))};
        for (const Vec3& x : m == BaselineMethod::bspline ? surface : inside) {
            const Vec3 d = field_at(r.fixed_to_moving, x);
            EXPECT_LT((d - shift).norm(), m == BaselineMethod::rigid ? 0.3 : 0.8) << to_string(m) << " at " << x.transpose() << ": " << d.transpose();
        }
    }
}

TEST(ImageBaselines, IdenticalImagesStayPut)
{
    // Regression: a B-spline on mutual information drifted by tens of mm on identical images.
    const ScalarImage image = label_intensity_image(organ(Vec3::Zero()), {1, 2});
    for (const BaselineMethod m : {BaselineMethod::demons, BaselineMethod::bspline}) {
        const BaselineResult r = register_baseline(image, image, m, true, BaselineOptions{});
        double largest = 0.0;
        for (float c : r.fixed_to_moving.components) largest = std::max(largest, std::abs(double(c)));
        EXPECT_LT(largest, 0.05) << to_string(m);
    }
}

TEST(ImageBaselines, ImagesWithoutOverlapAndBadOptionsAreRefused)
{
    ScalarImage fixed = label_intensity_image(organ(Vec3::Zero()), {1, 2});
    ScalarImage far = fixed;
    far.geometry.origin += Vec3(1000, 0, 0);
    EXPECT_NE(test::error_message([&] { register_baseline(fixed, far, BaselineMethod::rigid, true, BaselineOptions{}); }).find("do not overlap"), std::string::npos);
    BaselineOptions bad;
    bad.bspline_sampling = 0.0;
    EXPECT_NE(test::error_message([&] { register_baseline(fixed, fixed, BaselineMethod::bspline, true, bad); }).find("sampling"), std::string::npos);
    EXPECT_NE(test::error_message([] { parse_baseline_method("affine"); }).find("affine"), std::string::npos);
}

TEST(FieldMapping, InversionAndResamplingFollowTheField)
{
    // d(x) = 3 sin(x/20) e_x + 0.05 y e_z (smooth, invertible): the inverse point y of a target t
    // satisfies y + d(y) = t; resampling a labelled image moves its labels with the field.
    const LabelVolume labels = organ(Vec3::Zero());
    DisplacementField f = zero_field(labels.geometry);
    const auto& g = labels.geometry;
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const Vec3 x = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                const auto v = static_cast<std::size_t>(g.linear_index(i, j, k));
                f.components[3 * v] = static_cast<float>(3.0 * std::sin(x.x() / 20.0));
                f.components[3 * v + 2] = static_cast<float>(0.05 * x.y());
            }
    for (const Vec3& t : {Vec3(30, 30, 30), Vec3(52, 40, 20), Vec3(20, 50, 40)}) {
        Vec3 y;
        ASSERT_TRUE(invert_field_at(f, t, y));
        EXPECT_LT((y + sample_field(f, y) - t).norm(), 1e-3);
    }
    // A pure translation by 4 mm (2 voxels) along x: warped(x) = labels(x + 4 mm).
    DisplacementField shift = zero_field(g);
    for (std::size_t v = 0; v < shift.components.size() / 3; ++v) shift.components[3 * v] = 4.0f;
    const LabelVolume warped = resample_labels(labels, shift);
    for (std::int64_t i = 0; i + 2 < g.size[0]; ++i) EXPECT_EQ(warped.at(i, 18, 16), labels.at(i + 2, 18, 16));
}

} // namespace

// Issue 57: label maps alone are a pair. The whole pipeline on a pair without intensities (the
// label maps stand in, as the command makes them): the label baselines run and the intensity ones
// do not, nothing is warped, the summary says so and compares each baseline with the answer; the
// lesion's centre, shifted by (4, −2, 2) mm, is found. Asking for intensity baselines is refused.
TEST(ImageRegistration, LabelMapsAloneAreAPair)
{
    const Vec3 shift(4.0, -2.0, 2.0);
    ImagePair pair;
    pair.fixed_labels = organ(shift);
    pair.moving_labels = organ(Vec3::Zero());
    pair.intensities = false;
    const auto as_image = [](const LabelVolume& l) { return ScalarImage{l.geometry, std::vector<float>(l.labels.begin(), l.labels.end())}; };
    pair.fixed = as_image(pair.fixed_labels);
    pair.moving = as_image(pair.moving_labels);
    const Vec3 lesion(46, 38, 32); // the ball's centre at rest, mm
    pair.landmarks_moving = LandmarkSet{{"lesion", lesion, LandmarkType::tumour}};
    pair.landmarks_fixed = LandmarkSet{{"lesion", lesion + shift, LandmarkType::tumour}};
    ImageRegistrationSettings s;
    s.baselines = "all"; // every baseline the pair can run: the label ones
    s.cell_size = 8.0;
    s.cycles = 4;
    const ImageRegistrationResult r = register_images(pair, s);
    std::vector<std::string> names;
    for (const auto& m : r.methods) names.push_back(m.name);
    for (const char* expected : {"biomechanical", "rigid_labels", "demons_labels", "bspline_labels"})
        EXPECT_NE(std::find(names.begin(), names.end(), expected), names.end()) << expected;
    for (const auto& n : names) EXPECT_EQ(n.find("_intensity"), std::string::npos) << n;
    EXPECT_TRUE(r.warped_moving.values.empty());
    EXPECT_FALSE(r.summary.at("intensities").get<bool>());
    const auto& against = r.summary.at("biomechanical_against_baselines");
    EXPECT_EQ(against.at("entries").size(), 3u);
    for (const auto& e : against.at("entries")) {
        EXPECT_GE(e.at("interior_apart_mean_mm").get<double>(), 0.0);
        EXPECT_GE(e.at("interior_apart_max_mm").get<double>(), e.at("interior_apart_mean_mm").get<double>());
    }
    EXPECT_FALSE(against.at("reading").get<std::string>().empty());
    EXPECT_LT(r.summary.at("methods").at("biomechanical").at("tre").at("all").at("mean_mm").get<double>(), 1.5)
        << "the lesion, shifted by 4.9 mm, is found to within a voxel or so";

    ImageRegistrationSettings intensity = s;
    intensity.baselines = "intensity";
    EXPECT_NE(test::error_message([&] { register_images(pair, intensity); }).find("--baselines intensity needs the --fixed and --moving images"),
              std::string::npos);
}

} // namespace physreg

