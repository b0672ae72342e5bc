// SPDX-License-Identifier: GPL-3.0-or-later
// The cloud's noise estimated from the cloud alone (registration/surface/cloud_noise.hpp), against
// clouds whose noise is known: a curved smooth surface sampled with Gaussian noise of a given σ,
// with and without outliers, and without noise.
#include "physreg/registration/surface/cloud_noise.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace physreg {
namespace {

/// Points on a sphere cap (radius 80 mm, 5 mm spacing over ±60 mm), moved along the normal by
/// N(0, σ); `outliers` of them moved 5-20 mm instead.
std::vector<Vec3> sphere_cap(double sigma, double outlier_share, unsigned seed)
{
    std::mt19937 rng(seed);
    std::normal_distribution<double> noise(0.0, 1.0);
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    std::vector<Vec3> out;
    const double R = 80.0;
    for (double x = -60; x <= 60; x += 5)
        for (double y = -60; y <= 60; y += 5) {
            if (x * x + y * y > 60.0 * 60.0) continue; // a round cap: the sphere spans it everywhere
            const Vec3 p(x, y, std::sqrt(R * R - x * x - y * y));
            const Vec3 n = p.normalized();
            const double off = uniform(rng) < outlier_share ? (uniform(rng) < 0.5 ? -1 : 1) * (5.0 + 15.0 * uniform(rng)) : sigma * noise(rng);
            out.push_back(p + off * n);
        }
    return out;
}

TEST(CloudNoise, ASmoothSurfaceWithoutNoiseGivesNearlyNone)
{
    EXPECT_LT(estimate_cloud_noise(sphere_cap(0.0, 0.0, 1)).sigma_mm, 0.02);
}

TEST(CloudNoise, TheNoiseOfACurvedSurfaceIsFoundWithinTwentyPercent)
{
    // One cloud's estimate scatters by about 8 % (simulated over seeds): 20 % is 2.5 of those.
    for (const double sigma : {0.3, 1.0, 2.0}) {
        const CloudNoise n = estimate_cloud_noise(sphere_cap(sigma, 0.0, 2));
        EXPECT_NEAR(n.sigma_mm, sigma, 0.2 * sigma) << sigma;
        EXPECT_LT(n.outlier_share, 0.02) << sigma;
    }
}

TEST(CloudNoise, FivePercentOutliersNeitherInflateTheNoiseNorGoUnseen)
{
    const CloudNoise n = estimate_cloud_noise(sphere_cap(1.0, 0.05, 3));
    const CloudNoise clean = estimate_cloud_noise(sphere_cap(1.0, 0.0, 3));
    // The estimate of one cloud of ~450 points scatters by about 8 % (simulated); the outliers move it
    // by less than that against the same cloud without them.
    EXPECT_NEAR(n.sigma_mm, clean.sigma_mm, 0.08 * clean.sigma_mm);
    EXPECT_NEAR(n.sigma_mm, 1.0, 0.25);
    EXPECT_GT(n.outlier_share, 0.03);
    EXPECT_LT(n.outlier_share, 0.10);
}

TEST(CloudNoise, TooFewPointsOrNeighboursAreRefused)
{
    EXPECT_NE(test::error_message([] { estimate_cloud_noise(std::vector<Vec3>(10, Vec3::Zero())); }).find("at least 20"), std::string::npos);
    EXPECT_NE(test::error_message([] { estimate_cloud_noise(sphere_cap(0.0, 0.0, 1), 4); }).find("neighbours"), std::string::npos);
    // Every point on one line: no neighbourhood spans a surface.
    std::vector<Vec3> line;
    for (int i = 0; i < 50; ++i) line.emplace_back(i, 0, 0);
    EXPECT_NE(test::error_message([&] { estimate_cloud_noise(line); }).find("usable neighbourhood"), std::string::npos);
}

} // namespace
} // namespace physreg
