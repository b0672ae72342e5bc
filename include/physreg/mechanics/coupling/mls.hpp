// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Moving-least-squares (MLS) shape functions with a linear basis (Lancaster & Salkauskas 1981;
// paper 000 eq. 1): a point x is expressed from the nodes of its support domain as
// x = Σ_j Φ_j x_j, Φ_j = p(x)ᵀ A(x)⁻¹ w_j p(x_j), A(x) = Σ_j w_j p(x_j) p(x_j)ᵀ, p = (1, x, y, z).
// Partition of unity and exact reproduction of linear fields hold by construction.
#include "physreg/core/types.hpp"

#include <span>
#include <string>
#include <vector>

namespace physreg {

struct MlsOptions {
    /// Support domain: the ellipsoid |(x_j − x) ./ radius| ≤ 1, radius per LPS axis in mm (tie it to
    /// the element size: e.g. 1.5 cells per axis).
    Vec3 support_radius_mm = Vec3::Ones();
    int min_nodes = 4;                       ///< a linear basis in 3-D needs ≥ 4 non-coplanar nodes
    /// Ill-conditioning guard: the reciprocal condition number of the scaled moment matrix must
    /// exceed this; otherwise the support grows by `growth` (at most `max_growths` times), then Error.
    double min_reciprocal_condition = 1e-6;
    double growth = 1.25;
    int max_growths = 3;
    void validate() const;
};

/// The compactly supported weight: quartic spline 1 − 6s² + 8s³ − 3s⁴ for s ∈ [0, 1], 0 beyond
/// (C² at s = 1, smooth inside).
double mls_weight(double s);

struct MlsShapeFunctions {
    std::vector<std::int32_t> nodes; ///< the support domain actually used
    std::vector<double> phi;         ///< Φ_j, same order; Σ Φ_j = 1
    double reciprocal_condition = 0.0;
    double radius_scale = 1.0;       ///< support growth applied (1: none)
};

/// Shape functions at `x` from the candidate nodes (positions indexed by node id). Throws Error
/// naming `what` when fewer than min_nodes candidates fall inside the largest allowed support, or the
/// moment matrix stays ill-conditioned (e.g. all support nodes on one plane).
MlsShapeFunctions mls_shape_functions(const Vec3& x, std::span<const std::int32_t> candidates, std::span<const Vec3> positions,
                                      const MlsOptions& options, const std::string& what);

} // namespace physreg
