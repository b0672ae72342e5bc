// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/surface/cloud_noise.hpp"

#include "physreg/core/error.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <numeric>

namespace physreg {

namespace {

/// The point's distance to the quadric through its neighbours (in their principal frame: the
/// normal is the smallest-variance axis); NaN when the neighbourhood is degenerate.
double quadric_residual(const Vec3& p, const std::vector<Vec3>& points, const std::vector<std::size_t>& near)
{
    Vec3 centre = Vec3::Zero();
    for (const auto i : near) centre += points[i];
    centre /= static_cast<double>(near.size());
    Mat3 covariance = Mat3::Zero();
    for (const auto i : near) covariance += (points[i] - centre) * (points[i] - centre).transpose();
    const Eigen::SelfAdjointEigenSolver<Mat3> eigen(covariance);
    const Vec3 normal = eigen.eigenvectors().col(0), u = eigen.eigenvectors().col(2), v = eigen.eigenvectors().col(1);
    if (!(eigen.eigenvalues()[1] > 0)) return std::nan("");
    // Least squares for h = a + b x + c y + d x² + e x y + f y² over the neighbours (local
    // coordinates), then once more without the neighbours far off that fit (an outlier among them
    // would tilt it for every point it is near).
    std::vector<double> x(near.size()), y(near.size()), h(near.size());
    for (std::size_t k = 0; k < near.size(); ++k) {
        const Vec3 d = points[near[k]] - centre;
        x[k] = d.dot(u), y[k] = d.dot(v), h[k] = d.dot(normal);
    }
    std::vector<std::uint8_t> keep(near.size(), 1);
    Eigen::VectorXd c;
    for (int pass = 0; pass < 2; ++pass) {
        const auto rows = static_cast<Eigen::Index>(std::count(keep.begin(), keep.end(), 1));
        Eigen::MatrixXd A(rows, 6);
        Eigen::VectorXd b(rows);
        Eigen::Index row = 0;
        for (std::size_t k = 0; k < near.size(); ++k)
            if (keep[k]) {
                A.row(row) << 1.0, x[k], y[k], x[k] * x[k], x[k] * y[k], y[k] * y[k];
                b[row++] = h[k];
            }
        c = A.colPivHouseholderQr().solve(b);
        if (pass == 1) break;
        std::vector<double> r(near.size());
        for (std::size_t k = 0; k < near.size(); ++k)
            r[k] = std::abs(h[k] - (c[0] + c[1] * x[k] + c[2] * y[k] + c[3] * x[k] * x[k] + c[4] * x[k] * y[k] + c[5] * y[k] * y[k]));
        std::vector<double> sorted = r;
        std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
        const double limit = 3.0 * 1.4826 * sorted[sorted.size() / 2];
        std::size_t kept = 0;
        for (std::size_t k = 0; k < near.size(); ++k) kept += keep[k] = r[k] <= limit ? 1 : 0;
        if (kept < 10) break; // too few left for six coefficients: the first fit stands
    }
    const Vec3 d = p - centre;
    const double px = d.dot(u), py = d.dot(v);
    const double fitted = c[0] + c[1] * px + c[2] * py + c[3] * px * px + c[4] * px * py + c[5] * py * py;
    return std::abs(d.dot(normal) - fitted);
}

} // namespace

CloudNoise estimate_cloud_noise(const std::vector<Vec3>& points, int neighbours)
{
    if (neighbours < 8 || neighbours > 64) fail("cloud noise: {} neighbours (use 8 to 64)", neighbours);
    if (points.size() < 20) fail("cloud noise: {} points; at least 20 are needed to estimate the noise", points.size());
    const std::size_t n = points.size();
    for (std::size_t i = 0; i < n; ++i)
        if (!points[i].allFinite()) fail("cloud noise: point {} is not finite", i);
    const auto k = std::min<std::size_t>(static_cast<std::size_t>(neighbours), n - 1);
    std::vector<double> residuals(n, std::nan(""));
    // Brute-force neighbours: clouds are 10^2-10^4 points, and this runs once per registration.
#pragma omp parallel for schedule(dynamic, 16)
    for (std::ptrdiff_t ii = 0; ii < static_cast<std::ptrdiff_t>(n); ++ii) {
        const auto i = static_cast<std::size_t>(ii);
        std::vector<std::pair<double, std::size_t>> by_distance;
        by_distance.reserve(n - 1);
        for (std::size_t j = 0; j < n; ++j)
            if (j != i) by_distance.emplace_back((points[j] - points[i]).squaredNorm(), j);
        std::partial_sort(by_distance.begin(), by_distance.begin() + static_cast<std::ptrdiff_t>(k), by_distance.end());
        std::vector<std::size_t> near(k);
        for (std::size_t m = 0; m < k; ++m) near[m] = by_distance[m].second;
        residuals[i] = quadric_residual(points[i], points, near);
    }
    std::vector<double> finite;
    for (const double r : residuals)
        if (std::isfinite(r)) finite.push_back(r);
    CloudNoise out;
    out.points_used = finite.size();
    if (finite.size() < 20) fail("cloud noise: only {} of {} points have a usable neighbourhood (a cloud on a line?)", finite.size(), n);
    std::nth_element(finite.begin(), finite.begin() + static_cast<std::ptrdiff_t>(finite.size() / 2), finite.end());
    const double median = finite[finite.size() / 2];
    out.sigma_mm = 1.4826 * median / std::sqrt(1.0 + 6.0 / static_cast<double>(k));
    const auto outliers = std::count_if(finite.begin(), finite.end(), [&](double r) { return r > std::max(0.05, 3.5 * out.sigma_mm * std::sqrt(1.0 + 6.0 / static_cast<double>(k))); });
    out.outlier_share = static_cast<double>(outliers) / static_cast<double>(finite.size());
    return out;
}

} // namespace physreg
