// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The noise of an intra-operative cloud, from the cloud alone: the discrepancy principle (the
// adjoint's regularisation, the supports chosen by the data) needs σ, and a user rarely states it.
// A registration told 0.5 mm on a cloud with 1 mm noise and outliers fits the noise (the project's
// robustness study: 30 of 60 answers worse than at rest, 2.71 against 1.37 mm at worst).
#include "physreg/core/types.hpp"

#include <vector>

namespace physreg {

struct CloudNoise {
    double sigma_mm = 0.0;       ///< robust estimate of the noise normal to the surface, mm
    double outlier_share = 0.0;  ///< points whose residual exceeds 3.5 σ
    std::size_t points_used = 0; ///< points with a full neighbourhood (at least 12 points)
};

/// For each point, a quadric z = f(x, y) is fitted to its `neighbours` nearest other points in
/// their principal frame and the point's distance to it taken; σ = 1.4826 × the median of those
/// distances (robust to outliers), divided by √(1 + 6/neighbours) for the fit's own error. The
/// quadric takes out the surface's curvature, so a smooth noise-free cloud gives nearly 0. Error
/// for fewer than 20 points or neighbours outside [8, 64].
CloudNoise estimate_cloud_noise(const std::vector<Vec3>& points, int neighbours = 16);

} // namespace physreg
