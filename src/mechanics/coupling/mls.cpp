// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/coupling/mls.hpp"

#include "physreg/core/error.hpp"

#include <Eigen/Eigenvalues>
#include <cmath>

namespace physreg {

void MlsOptions::validate() const
{
    for (int a = 0; a < 3; ++a)
        if (!(support_radius_mm[a] > 0) || !std::isfinite(support_radius_mm[a]))
            fail("MLS support radius must be positive and finite (got {} mm along axis {})", support_radius_mm[a], a);
    if (min_nodes < 4) fail("MLS: a linear basis needs at least 4 support nodes (min_nodes = {})", min_nodes);
    if (!(min_reciprocal_condition > 0 && min_reciprocal_condition < 1)) fail("MLS: min_reciprocal_condition must lie in (0, 1)");
    if (!(growth > 1) || max_growths < 0) fail("MLS: support growth must exceed 1 and max_growths be ≥ 0");
}

double mls_weight(double s)
{
    if (s >= 1.0) return 0.0;
    const double s2 = s * s;
    return 1.0 - 6.0 * s2 + 8.0 * s2 * s - 3.0 * s2 * s2;
}

MlsShapeFunctions mls_shape_functions(const Vec3& x, std::span<const std::int32_t> candidates, std::span<const Vec3> positions,
                                      const MlsOptions& options, const std::string& what)
{
    options.validate();
    using Mat4 = Eigen::Matrix4d;
    using Vec4 = Eigen::Vector4d;
    double scale = 1.0;
    std::size_t best_count = 0;
    double best_rcond = 0.0;
    for (int attempt = 0; attempt <= options.max_growths; ++attempt, scale *= options.growth) {
        const Vec3 radius = scale * options.support_radius_mm;
        // The basis is centred at x and scaled by the radius, so A is O(1) whatever the units.
        MlsShapeFunctions out;
        std::vector<Vec4> basis;
        std::vector<double> weight;
        Mat4 moment = Mat4::Zero();
        for (const auto node : candidates) {
            const Vec3 r = (positions[static_cast<std::size_t>(node)] - x).cwiseQuotient(radius);
            const double w = mls_weight(r.norm());
            if (w <= 0.0) continue;
            const Vec4 p(1.0, r.x(), r.y(), r.z());
            out.nodes.push_back(node);
            basis.push_back(p);
            weight.push_back(w);
            moment += w * p * p.transpose();
        }
        best_count = std::max(best_count, out.nodes.size());
        if (static_cast<int>(out.nodes.size()) < options.min_nodes) continue;
        const Eigen::SelfAdjointEigenSolver<Mat4> eigen(moment, Eigen::EigenvaluesOnly);
        const double largest = eigen.eigenvalues().maxCoeff(), smallest = eigen.eigenvalues().minCoeff();
        const double rcond = largest > 0 ? smallest / largest : 0.0;
        best_rcond = std::max(best_rcond, rcond);
        if (!(rcond >= options.min_reciprocal_condition)) continue;
        // Φ_j = p(x)ᵀ A⁻¹ w_j p_j with p(x) = e₁ in the centred basis.
        const Vec4 row = moment.ldlt().solve(Vec4::UnitX());
        out.phi.resize(out.nodes.size());
        for (std::size_t j = 0; j < out.nodes.size(); ++j) out.phi[j] = weight[j] * row.dot(basis[j]);
        out.reciprocal_condition = rcond;
        out.radius_scale = scale;
        return out;
    }
    if (static_cast<int>(best_count) < options.min_nodes)
        fail("{}: support domain at ({:.2f}, {:.2f}, {:.2f}) mm has {} vertices of its tissue within {:.2f}× the support radius "
             "(need ≥ {}); the tissue is too thin for the MLS support, or the support radius is too small",
             what, x.x(), x.y(), x.z(), best_count, scale / options.growth, options.min_nodes);
    fail("{}: MLS moment matrix at ({:.2f}, {:.2f}, {:.2f}) mm is ill-conditioned (reciprocal condition {:.2g} < {:.2g}; support "
         "vertices nearly coplanar) even with the support grown {:.2f}×", what, x.x(), x.y(), x.z(), best_rcond,
         options.min_reciprocal_condition, scale / options.growth);
}

} // namespace physreg
