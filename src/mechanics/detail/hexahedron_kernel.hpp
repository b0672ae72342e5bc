// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The hot loop of TLED: forces of a batch of W uniform-strain hexahedra with hourglass control.
// Elements of a batch sit in SIMD lanes: node values are gathered into lane-major stack arrays,
// all arithmetic runs over the lanes (the compiler vectorises the `omp simd` loops), and forces
// are scattered back node by node. Elements of one chunk of a phase share no node with another
// chunk of it, so the scatter is race free.
//
// A *run* is a batch of W elements along a grid row whose node numbers advance by one from lane
// to lane (node a of lane w is node base_a + w): its gather is then W consecutive nodes per local
// node, loaded as contiguous vectors, and its scatter adds W consecutive nodes, local node after
// local node (lanes share nodes across local nodes, never within one). On meshes from label
// volumes most batches are runs; this removes the scalar gather and scatter that dominated.
#include "physreg/mechanics/materials/material.hpp"

#include <cmath>
#include <cstdint>
#include <limits>

namespace physreg::detail {

struct HexBatchData {
    const std::int32_t* connectivity;
    const std::uint16_t* material;
    const std::int32_t* geometry;
};

// J^(-1/3) by Newton's iteration r ← r (4 − J r³)/3 from r = 1: quadratic convergence for
// J ∈ (0.3, 3) in 7 steps; lanes outside (rare, extreme deformation) are redone with std::cbrt.
template <typename Real, int W>
inline void inverse_cube_root(const Real* j, Real* r)
{
#pragma omp simd
    for (int w = 0; w < W; ++w) {
        Real x = 1;
        for (int it = 0; it < 7; ++it) x = x * (Real(4) - j[w] * x * x * x) * Real(1.0 / 3.0);
        r[w] = x;
    }
    for (int w = 0; w < W; ++w) {
        const Real t = j[w] * r[w] * r[w] * r[w];
        if (!(std::abs(t - Real(1)) < Real(64) * std::numeric_limits<Real>::epsilon()) && j[w] > Real(0))
            r[w] = Real(1) / std::cbrt(j[w]);
    }
}

/// Adds the forces of elements[0..count) (count ≤ W) into f. Returns the index (into elements)
/// of an element with det F ≤ 0, or -1. Run = true: the elements form a run (see above).
template <typename Real, int W, bool SharedGeometry, bool Run = false>
inline int hexahedron_batch(const std::int32_t* elements, int count, const HexBatchData& d, const Real* u,
                            const Real* dn_all, const Real* gamma_all, const Real* volume_all, const Real* vb2_all,
                            const Real* mu_all, const Real* lambda_all, const Real* kappa_all,
                            const Real* hourglass_all, MaterialLaw law, Real* f)
{
    alignas(64) Real ux[8][W], uy[8][W], uz[8][W];
    alignas(64) Real bl[SharedGeometry ? 1 : 24][W], gl[SharedGeometry ? 1 : 32][W];
    alignas(64) Real vol[W], khg[W], mu[W], lambda[W], kappa[W];
    std::int32_t ids[Run ? 1 : 8][W];
    std::int32_t base[8];
    if constexpr (Run) {
        const std::int32_t* c0 = d.connectivity + 8 * static_cast<std::size_t>(elements[0]);
        for (int a = 0; a < 8; ++a) {
            base[a] = c0[a];
            const Real* ua = u + 3 * static_cast<std::size_t>(c0[a]);
            if (count == W) {
#pragma omp simd
                for (int w = 0; w < W; ++w) {
                    ux[a][w] = ua[3 * w];
                    uy[a][w] = ua[3 * w + 1];
                    uz[a][w] = ua[3 * w + 2];
                }
            } else { // a row's last, shorter run: idle lanes repeat its first element
                for (int w = 0; w < W; ++w) {
                    const int live = w < count ? w : 0;
                    ux[a][w] = ua[3 * live];
                    uy[a][w] = ua[3 * live + 1];
                    uz[a][w] = ua[3 * live + 2];
                }
            }
        }
    }
    for (int w = 0; w < W; ++w) {
        // Idle lanes repeat an element of the batch (the last; a run's first, as gathered above).
        const std::int32_t e = elements[w < count ? w : (Run ? 0 : count - 1)];
        if constexpr (!Run) {
            const std::int32_t* c = d.connectivity + 8 * static_cast<std::size_t>(e);
            for (int a = 0; a < 8; ++a) {
                ids[a][w] = c[a];
                const Real* ua = u + 3 * static_cast<std::size_t>(c[a]);
                ux[a][w] = ua[0];
                uy[a][w] = ua[1];
                uz[a][w] = ua[2];
            }
        }
        const int g = SharedGeometry ? 0 : d.geometry[e];
        const int m = d.material[e];
        vol[w] = volume_all[g];
        khg[w] = hourglass_all[m] * vb2_all[g];
        mu[w] = mu_all[m];
        lambda[w] = lambda_all[m];
        kappa[w] = kappa_all[m];
        if constexpr (!SharedGeometry) {
            for (int k = 0; k < 24; ++k) bl[k][w] = dn_all[24 * g + k];
            for (int k = 0; k < 32; ++k) gl[k][w] = gamma_all[32 * g + k];
        }
    }
    auto b = [&](int k, int w) -> Real {
        if constexpr (SharedGeometry) return dn_all[k];
        else return bl[k][w];
    };
    auto gamma = [&](int k, int w) -> Real {
        if constexpr (SharedGeometry) return gamma_all[k];
        else return gl[k][w];
    };

    alignas(64) Real F[9][W];
#pragma omp simd
    for (int w = 0; w < W; ++w) {
        Real f0 = 1, f1 = 0, f2 = 0, f3 = 0, f4 = 1, f5 = 0, f6 = 0, f7 = 0, f8 = 1;
        for (int a = 0; a < 8; ++a) {
            const Real b0 = b(3 * a, w), b1 = b(3 * a + 1, w), b2 = b(3 * a + 2, w);
            f0 += ux[a][w] * b0;
            f1 += ux[a][w] * b1;
            f2 += ux[a][w] * b2;
            f3 += uy[a][w] * b0;
            f4 += uy[a][w] * b1;
            f5 += uy[a][w] * b2;
            f6 += uz[a][w] * b0;
            f7 += uz[a][w] * b1;
            f8 += uz[a][w] * b2;
        }
        F[0][w] = f0; F[1][w] = f1; F[2][w] = f2;
        F[3][w] = f3; F[4][w] = f4; F[5][w] = f5;
        F[6][w] = f6; F[7][w] = f7; F[8][w] = f8;
    }
    alignas(64) Real J[W];
#pragma omp simd
    for (int w = 0; w < W; ++w)
        J[w] = F[0][w] * (F[4][w] * F[8][w] - F[5][w] * F[7][w]) - F[1][w] * (F[3][w] * F[8][w] - F[5][w] * F[6][w]) +
               F[2][w] * (F[3][w] * F[7][w] - F[4][w] * F[6][w]);
    int inverted = -1;
    for (int w = 0; w < count; ++w)
        if (!(J[w] > Real(0))) inverted = w;
    if (inverted >= 0) return inverted;

    alignas(64) Real P[9][W];
    if (law == MaterialLaw::linear_elastic || law == MaterialLaw::corotational) {
        for (int w = 0; w < W; ++w) {
            Real fl[9], pl[9];
            for (int k = 0; k < 9; ++k) fl[k] = F[k][w];
            first_piola_kirchhoff(law, mu[w], lambda[w], kappa[w], fl, pl);
            for (int k = 0; k < 9; ++k) P[k][w] = pl[k] * vol[w];
        }
    } else {
        alignas(64) Real r[W];
        if (law == MaterialLaw::neo_hookean) inverse_cube_root<Real, W>(J, r);
#pragma omp simd
        for (int w = 0; w < W; ++w) {
            const Real c0 = F[0][w] * F[0][w] + F[3][w] * F[3][w] + F[6][w] * F[6][w];
            const Real c1 = F[1][w] * F[1][w] + F[4][w] * F[4][w] + F[7][w] * F[7][w];
            const Real c2 = F[2][w] * F[2][w] + F[5][w] * F[5][w] + F[8][w] * F[8][w];
            const Real c3 = F[0][w] * F[1][w] + F[3][w] * F[4][w] + F[6][w] * F[7][w];
            const Real c4 = F[1][w] * F[2][w] + F[4][w] * F[5][w] + F[7][w] * F[8][w];
            const Real c5 = F[0][w] * F[2][w] + F[3][w] * F[5][w] + F[6][w] * F[8][w];
            Real s0, s1, s2, s3, s4, s5;
            if (law == MaterialLaw::st_venant_kirchhoff) {
                const Real tr_e = Real(0.5) * (c0 + c1 + c2 - Real(3));
                s0 = lambda[w] * tr_e + mu[w] * (c0 - Real(1));
                s1 = lambda[w] * tr_e + mu[w] * (c1 - Real(1));
                s2 = lambda[w] * tr_e + mu[w] * (c2 - Real(1));
                s3 = mu[w] * c3;
                s4 = mu[w] * c4;
                s5 = mu[w] * c5;
            } else {
                const Real inv_j2 = Real(1) / (J[w] * J[w]);
                const Real mu_j = mu[w] * r[w] * r[w]; // μ J^(-2/3)
                const Real a = kappa[w] * J[w] * (J[w] - Real(1)) - mu_j * (c0 + c1 + c2) * Real(1.0 / 3.0);
                const Real ai = a * inv_j2; // C⁻¹ = adj(C) / J²
                s0 = mu_j + ai * (c1 * c2 - c4 * c4);
                s1 = mu_j + ai * (c0 * c2 - c5 * c5);
                s2 = mu_j + ai * (c0 * c1 - c3 * c3);
                s3 = ai * (c5 * c4 - c3 * c2);
                s4 = ai * (c3 * c5 - c0 * c4);
                s5 = ai * (c3 * c4 - c1 * c5);
            }
            const Real v = vol[w];
            for (int row = 0; row < 3; ++row) {
                const Real g0 = F[3 * row][w], g1 = F[3 * row + 1][w], g2 = F[3 * row + 2][w];
                P[3 * row][w] = v * (g0 * s0 + g1 * s3 + g2 * s5);
                P[3 * row + 1][w] = v * (g0 * s3 + g1 * s1 + g2 * s4);
                P[3 * row + 2][w] = v * (g0 * s5 + g1 * s4 + g2 * s2);
            }
        }
    }
    alignas(64) Real qx[4][W], qy[4][W], qz[4][W];
#pragma omp simd
    for (int w = 0; w < W; ++w)
        for (int m = 0; m < 4; ++m) {
            Real sx = 0, sy = 0, sz = 0;
            for (int a = 0; a < 8; ++a) {
                const Real g = gamma(4 * a + m, w);
                sx += g * ux[a][w];
                sy += g * uy[a][w];
                sz += g * uz[a][w];
            }
            qx[m][w] = khg[w] * sx;
            qy[m][w] = khg[w] * sy;
            qz[m][w] = khg[w] * sz;
        }
    alignas(64) Real fx[8][W], fy[8][W], fz[8][W];
#pragma omp simd
    for (int w = 0; w < W; ++w)
        for (int a = 0; a < 8; ++a) {
            const Real b0 = b(3 * a, w), b1 = b(3 * a + 1, w), b2 = b(3 * a + 2, w);
            Real x = P[0][w] * b0 + P[1][w] * b1 + P[2][w] * b2;
            Real y = P[3][w] * b0 + P[4][w] * b1 + P[5][w] * b2;
            Real z = P[6][w] * b0 + P[7][w] * b1 + P[8][w] * b2;
            for (int m = 0; m < 4; ++m) {
                const Real g = gamma(4 * a + m, w);
                x += g * qx[m][w];
                y += g * qy[m][w];
                z += g * qz[m][w];
            }
            fx[a][w] = x;
            fy[a][w] = y;
            fz[a][w] = z;
        }
    if constexpr (Run) {
        for (int a = 0; a < 8; ++a) {
            Real* fa = f + 3 * static_cast<std::size_t>(base[a]);
            if (count == W) {
#pragma omp simd
                for (int w = 0; w < W; ++w) {
                    fa[3 * w] += fx[a][w];
                    fa[3 * w + 1] += fy[a][w];
                    fa[3 * w + 2] += fz[a][w];
                }
            } else {
                for (int w = 0; w < count; ++w) {
                    fa[3 * w] += fx[a][w];
                    fa[3 * w + 1] += fy[a][w];
                    fa[3 * w + 2] += fz[a][w];
                }
            }
        }
    } else {
        for (int w = 0; w < count; ++w)
            for (int a = 0; a < 8; ++a) {
                Real* fa = f + 3 * static_cast<std::size_t>(ids[a][w]);
                fa[0] += fx[a][w];
                fa[1] += fy[a][w];
                fa[2] += fz[a][w];
            }
    }
    return -1;
}

} // namespace physreg::detail
