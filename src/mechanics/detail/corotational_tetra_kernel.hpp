// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Forces of a batch of W linear tetrahedra under the co-rotational law (the force pass of the
// implicit solvers: backward Euler's step, Newton's residual). Elements sit in SIMD lanes, as in
// hexahedron_kernel.hpp; the polar rotation runs Higham's scaled Newton iteration (the one of
// polar_rotation()) on all lanes at once until every lane has converged — a lane that converged
// early iterates on at its fixed point. Inverted or flat lanes (det F ≤ 0) take the scalar
// corotation() (its SVD), as the element-by-element code does. Issue 45: the 22 019 polar
// decompositions of the SOFA liver were half of a backward-Euler step.
#include "physreg/mechanics/materials/material.hpp"

#include <cmath>
#include <cstdint>
#include <limits>

namespace physreg::detail {

struct TetraBatchInput {
    const std::int32_t* connectivity; ///< 4 per element
    const std::int32_t* geometry;     ///< per element: index into dn / volume
    const std::uint16_t* material;    ///< per element: index into mu / lambda
    const double* dn;                 ///< 12 per geometry (b_a, node-major), 1/mm
    const double* volume;             ///< per geometry, mm³
    const double* mu;                 ///< per material, MPa
    const double* lambda;             ///< per material, MPa
};

struct TetraBatchResult {
    std::int64_t inverted = 0;     ///< lanes with det F ≤ 0 (pushed back by the law)
    std::int64_t non_finite = -1;  ///< smallest element whose force or energy is not finite, -1 none
};

/// Adds the forces of elements[0..count) (count ≤ W) into f and writes their energies (mJ) into
/// energy[element].
template <int W>
inline void corotational_tetra_batch(const std::int32_t* elements, int count, const TetraBatchInput& in, const double* u, double* f,
                                     double* energy, TetraBatchResult& result)
{
    alignas(64) double F[9][W], X[9][W], b[12][W], v[W], mu[W], lambda[W], J[W];
    std::int32_t ids[4][W];
    for (int w = 0; w < W; ++w) {
        const std::int32_t e = elements[w < count ? w : count - 1]; // idle lanes repeat the last element
        const std::int32_t* c = in.connectivity + 4 * static_cast<std::size_t>(e);
        const double* bg = in.dn + 12 * static_cast<std::size_t>(in.geometry[e]);
        for (int k = 0; k < 12; ++k) b[k][w] = bg[k];
        v[w] = in.volume[in.geometry[e]];
        mu[w] = in.mu[in.material[e]];
        lambda[w] = in.lambda[in.material[e]];
        for (int k = 0; k < 9; ++k) F[k][w] = (k % 4 == 0) ? 1.0 : 0.0;
        for (int a = 0; a < 4; ++a) {
            ids[a][w] = c[a];
            const double* ua = u + 3 * static_cast<std::size_t>(c[a]);
            for (int r = 0; r < 3; ++r)
                for (int col = 0; col < 3; ++col) F[3 * r + col][w] += ua[r] * bg[3 * a + col];
        }
    }
    const auto det = [](const double (&x)[9][W], int w) {
        return x[0][w] * (x[4][w] * x[8][w] - x[5][w] * x[7][w]) - x[1][w] * (x[3][w] * x[8][w] - x[5][w] * x[6][w]) +
               x[2][w] * (x[3][w] * x[7][w] - x[4][w] * x[6][w]);
    };
    bool any_inverted = false;
    for (int w = 0; w < W; ++w) {
        J[w] = det(F, w);
        const bool sound = J[w] > 0.0;
        any_inverted = any_inverted || (w < count && !sound);
        for (int k = 0; k < 9; ++k) X[k][w] = sound ? F[k][w] : ((k % 4 == 0) ? 1.0 : 0.0); // inverted lanes: redone below
    }
    const double tolerance = 4.0 * std::sqrt(std::numeric_limits<double>::epsilon());
    for (int iteration = 0; iteration < 40; ++iteration) {
        double largest_change = 0.0;
#pragma omp simd reduction(max : largest_change)
        for (int w = 0; w < W; ++w) {
            const double x0 = X[0][w], x1 = X[1][w], x2 = X[2][w], x3 = X[3][w], x4 = X[4][w], x5 = X[5][w], x6 = X[6][w], x7 = X[7][w],
                         x8 = X[8][w];
            // X⁻ᵀ = cofactor(X) / det X, written out so that the lanes vectorise.
            const double c0 = x4 * x8 - x5 * x7, c1 = x5 * x6 - x3 * x8, c2 = x3 * x7 - x4 * x6;
            const double c3 = x2 * x7 - x1 * x8, c4 = x0 * x8 - x2 * x6, c5 = x1 * x6 - x0 * x7;
            const double c6 = x1 * x5 - x2 * x4, c7 = x2 * x3 - x0 * x5, c8 = x0 * x4 - x1 * x3;
            const double inverse_d = 1.0 / (x0 * c0 + x1 * c1 + x2 * c2);
            const double x_norm = x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3 + x4 * x4 + x5 * x5 + x6 * x6 + x7 * x7 + x8 * x8;
            const double c_norm = (c0 * c0 + c1 * c1 + c2 * c2 + c3 * c3 + c4 * c4 + c5 * c5 + c6 * c6 + c7 * c7 + c8 * c8) * inverse_d * inverse_d;
            const double zeta = std::sqrt(std::sqrt(c_norm / x_norm));
            const double a = 0.5 * zeta, bq = 0.5 * inverse_d / zeta; // X⁺ = a X + bq cofactor(X)
            const double n0 = a * x0 + bq * c0, n1 = a * x1 + bq * c1, n2 = a * x2 + bq * c2;
            const double n3 = a * x3 + bq * c3, n4 = a * x4 + bq * c4, n5 = a * x5 + bq * c5;
            const double n6 = a * x6 + bq * c6, n7 = a * x7 + bq * c7, n8 = a * x8 + bq * c8;
            const double change = (n0 - x0) * (n0 - x0) + (n1 - x1) * (n1 - x1) + (n2 - x2) * (n2 - x2) + (n3 - x3) * (n3 - x3) +
                                  (n4 - x4) * (n4 - x4) + (n5 - x5) * (n5 - x5) + (n6 - x6) * (n6 - x6) + (n7 - x7) * (n7 - x7) +
                                  (n8 - x8) * (n8 - x8);
            X[0][w] = n0; X[1][w] = n1; X[2][w] = n2;
            X[3][w] = n3; X[4][w] = n4; X[5][w] = n5;
            X[6][w] = n6; X[7][w] = n7; X[8][w] = n8;
            largest_change = std::max(largest_change, change);
        }
        if (largest_change <= tolerance * tolerance) break;
    }
    if (any_inverted)
        for (int w = 0; w < count; ++w)
            if (!(J[w] > 0.0)) {
                double fl[9], rl[9];
                for (int k = 0; k < 9; ++k) fl[k] = F[k][w];
                corotation(fl, rl); // the SVD's proper rotation (Irving, Teran & Fedkiw)
                for (int k = 0; k < 9; ++k) X[k][w] = rl[k];
                ++result.inverted;
            }
    alignas(64) double fx[4][W], fy[4][W], fz[4][W], psi[W];
#pragma omp simd
    for (int w = 0; w < W; ++w) {
        double excess = -3.0, distance = 0.0; // tr(RᵀF) − 3, |F − R|²
        for (int k = 0; k < 9; ++k) {
            excess += X[k][w] * F[k][w];
            distance += (F[k][w] - X[k][w]) * (F[k][w] - X[k][w]);
        }
        double P[9];
        for (int k = 0; k < 9; ++k) P[k] = 2.0 * mu[w] * (F[k][w] - X[k][w]) + lambda[w] * excess * X[k][w];
        psi[w] = v[w] * (mu[w] * distance + 0.5 * lambda[w] * excess * excess);
        for (int a = 0; a < 4; ++a) {
            const double b0 = b[3 * a][w], b1 = b[3 * a + 1][w], b2 = b[3 * a + 2][w];
            fx[a][w] = v[w] * (P[0] * b0 + P[1] * b1 + P[2] * b2);
            fy[a][w] = v[w] * (P[3] * b0 + P[4] * b1 + P[5] * b2);
            fz[a][w] = v[w] * (P[6] * b0 + P[7] * b1 + P[8] * b2);
        }
    }
    for (int w = 0; w < count; ++w) {
        const std::int32_t e = elements[w];
        bool finite = std::isfinite(psi[w]);
        for (int a = 0; a < 4; ++a) {
            finite = finite && std::isfinite(fx[a][w]) && std::isfinite(fy[a][w]) && std::isfinite(fz[a][w]);
            double* fa = f + 3 * static_cast<std::size_t>(ids[a][w]);
            fa[0] += fx[a][w];
            fa[1] += fy[a][w];
            fa[2] += fz[a][w];
        }
        energy[e] = psi[w];
        if (!finite && (result.non_finite < 0 || e < result.non_finite)) result.non_finite = e;
    }
}

} // namespace physreg::detail
