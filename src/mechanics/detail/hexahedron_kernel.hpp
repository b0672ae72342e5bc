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
#include "mechanics/detail/hexahedron_stress.hpp"
#include "physreg/mechanics/materials/material.hpp"

#include <cmath>
#include <cstdint>
#include <limits>

namespace physreg::detail {

struct HexBatchData {
    const std::int32_t* connectivity;
    const std::uint16_t* material;
    const std::int32_t* geometry;
    const double* box_m = nullptr; ///< box elements: M of b_a = M s_a (row-major 3×3, 1/mm)
};

// J^(-1/3) by Newton's iteration r ← r (4 − J r³)/3 from r = 1: quadratic convergence, 5 steps
// reach double precision for J ∈ (0.8, 1.25) (tissue near incompressibility stays well inside);
// the check is vectorised too, and only a batch with a lane outside (large volume change) redoes
// those lanes with std::cbrt.
template <typename Real, int W>
inline void inverse_cube_root(const Real* j, Real* r)
{
    Real worst = 0;
#pragma omp simd reduction(max : worst)
    for (int w = 0; w < W; ++w) {
        Real x = 1;
        for (int it = 0; it < 5; ++it) x = x * (Real(4) - j[w] * x * x * x) * Real(1.0 / 3.0);
        r[w] = x;
        const Real t = std::abs(j[w] * x * x * x - Real(1));
        worst = std::max(worst, t == t ? t : Real(1)); // NaN: redo
    }
    if (worst < Real(64) * std::numeric_limits<Real>::epsilon()) return;
    for (int w = 0; w < W; ++w) {
        const Real t = j[w] * r[w] * r[w] * r[w];
        if (!(std::abs(t - Real(1)) < Real(64) * std::numeric_limits<Real>::epsilon()) && j[w] > Real(0))
            r[w] = Real(1) / std::cbrt(j[w]);
    }
}

// Box elements (every hexahedron of a uniform grid, turned or not): b_a = M s_a with s_a the
// corner's signs (±1 per axis) and the hourglass vectors Γ = ± the four sign products s_x s_y,
// s_y s_z, s_z s_x, s_x s_y s_z. An 8-point Walsh–Hadamard transform of the corner values then
// gives, in 24 additions per component, all of Σ_a s_a u_a (hence F = I + G Mᵀ) and the four
// hourglass amplitudes; its transpose maps the mode forces back to the corners. That replaces
// 8 × 3 × 3 + 8 × 4 × 3 multiply-adds by 24 + 24 additions each way (issue 45).
// Corners in the mesher's order (label_grid.cpp) → binary index (bit 0: +x, bit 1: +y, bit 2: +z).
inline constexpr int box_corner_bit[8] = {0, 1, 3, 2, 4, 5, 7, 6};

/// t[k] = Σ_a p_k(a) v[a], p_k(a) = Π over the set bits d of k of s_d(a) (s = +1 on the + side).
template <typename Real, int W>
inline void box_modes(const Real (&v)[8][W], Real (&t)[8][W])
{
#pragma omp simd
    for (int w = 0; w < W; ++w) {
        const Real a0 = v[0][w], a1 = v[1][w], a3 = v[2][w], a2 = v[3][w], a4 = v[4][w], a5 = v[5][w], a7 = v[6][w], a6 = v[7][w];
        const Real b0 = a0 + a1, b1 = a1 - a0, b2 = a2 + a3, b3 = a3 - a2, b4 = a4 + a5, b5 = a5 - a4, b6 = a6 + a7, b7 = a7 - a6;
        const Real c0 = b0 + b2, c1 = b1 + b3, c2 = b2 - b0, c3 = b3 - b1, c4 = b4 + b6, c5 = b5 + b7, c6 = b6 - b4, c7 = b7 - b5;
        t[0][w] = c0 + c4; t[1][w] = c1 + c5; t[2][w] = c2 + c6; t[3][w] = c3 + c7;
        t[4][w] = c4 - c0; t[5][w] = c5 - c1; t[6][w] = c6 - c2; t[7][w] = c7 - c3;
    }
}

/// The transpose: v[a] = Σ_k p_k(a) t[k] (mode forces back to the corners).
template <typename Real, int W>
inline void box_corners(const Real (&t)[8][W], Real (&v)[8][W])
{
#pragma omp simd
    for (int w = 0; w < W; ++w) {
        const Real a0 = t[0][w], a1 = t[1][w], a2 = t[2][w], a3 = t[3][w], a4 = t[4][w], a5 = t[5][w], a6 = t[6][w], a7 = t[7][w];
        const Real b0 = a0 - a1, b1 = a0 + a1, b2 = a2 - a3, b3 = a2 + a3, b4 = a4 - a5, b5 = a4 + a5, b6 = a6 - a7, b7 = a6 + a7;
        const Real c0 = b0 - b2, c1 = b1 - b3, c2 = b0 + b2, c3 = b1 + b3, c4 = b4 - b6, c5 = b5 - b7, c6 = b4 + b6, c7 = b5 + b7;
        v[0][w] = c0 - c4; v[1][w] = c1 - c5; v[3][w] = c2 - c6; v[2][w] = c3 - c7;
        v[4][w] = c0 + c4; v[5][w] = c1 + c5; v[7][w] = c2 + c6; v[6][w] = c3 + c7;
    }
}

/// The lanes of one batch: gathered node values and per-element data, then F, J, P and the
/// corner forces, each W wide (lane-major) so that every loop over the lanes vectorises.
template <typename Real, int W, bool SharedGeometry, bool Run, bool Box>
struct HexLanes {
    alignas(64) Real ux[8][W], uy[8][W], uz[8][W];
    alignas(64) Real bl[SharedGeometry ? 1 : 24][W], gl[SharedGeometry ? 1 : 32][W];
    alignas(64) Real vol[W], khg[W], mu[W], lambda[W], kappa[W];
    std::int32_t ids[Run ? 1 : 8][W];
    std::int32_t base[8];
    alignas(64) Real F[9][W], J[W], P[9][W];
    alignas(64) Real tx[Box ? 8 : 1][W], ty[Box ? 8 : 1][W], tz[Box ? 8 : 1][W];
    Real box_m[9] = {};
    alignas(64) Real fx[8][W], fy[8][W], fz[8][W];
    // The shape-function gradients and hourglass vectors of lane w (shared or per element).
    Real b(const Real* dn_all, int k, int w) const
    {
        if constexpr (SharedGeometry) return dn_all[k];
        else return bl[k][w];
    }
    Real gamma(const Real* gamma_all, int k, int w) const
    {
        if constexpr (SharedGeometry) return gamma_all[k];
        else return gl[k][w];
    }
};

/// Material data of every element type and material, indexed by geometry g and material m.
template <typename Real>
struct HexTables {
    const Real *dn_all, *gamma_all, *volume_all, *vb2_all, *mu_all, *lambda_all, *kappa_all, *hourglass_all;
};

/// Node displacements and per-element data into the lanes. Idle lanes (count < W) repeat an
/// element of the batch (the last; a run's first), so every lane computes finite values.
template <typename Real, int W, bool S, bool Run, bool Box>
[[gnu::always_inline]] inline void gather_lanes(HexLanes<Real, W, S, Run, Box>& l, const std::int32_t* elements, int count, const HexBatchData& d, const Real* u,
                         const HexTables<Real>& t)
{
    if constexpr (Run) {
        const std::int32_t* c0 = d.connectivity + 8 * static_cast<std::size_t>(elements[0]);
        for (int a = 0; a < 8; ++a) {
            l.base[a] = c0[a];
            const Real* ua = u + 3 * static_cast<std::size_t>(c0[a]);
            if (count == W) {
#pragma omp simd
                for (int w = 0; w < W; ++w) {
                    l.ux[a][w] = ua[3 * w];
                    l.uy[a][w] = ua[3 * w + 1];
                    l.uz[a][w] = ua[3 * w + 2];
                }
            } else { // a row's last, shorter run
                for (int w = 0; w < W; ++w) {
                    const int live = w < count ? w : 0;
                    l.ux[a][w] = ua[3 * live];
                    l.uy[a][w] = ua[3 * live + 1];
                    l.uz[a][w] = ua[3 * live + 2];
                }
            }
        }
    }
    for (int w = 0; w < W; ++w) {
        const std::int32_t e = elements[w < count ? w : (Run ? 0 : count - 1)];
        if constexpr (!Run) {
            const std::int32_t* c = d.connectivity + 8 * static_cast<std::size_t>(e);
            for (int a = 0; a < 8; ++a) {
                l.ids[a][w] = c[a];
                const Real* ua = u + 3 * static_cast<std::size_t>(c[a]);
                l.ux[a][w] = ua[0];
                l.uy[a][w] = ua[1];
                l.uz[a][w] = ua[2];
            }
        }
        const int g = S ? 0 : d.geometry[e];
        const int m = d.material[e];
        l.vol[w] = t.volume_all[g];
        l.khg[w] = t.hourglass_all[m] * t.vb2_all[g];
        l.mu[w] = t.mu_all[m];
        l.lambda[w] = t.lambda_all[m];
        l.kappa[w] = t.kappa_all[m];
        if constexpr (!S) {
            for (int k = 0; k < 24; ++k) l.bl[k][w] = t.dn_all[24 * g + k];
            for (int k = 0; k < 32; ++k) l.gl[k][w] = t.gamma_all[32 * g + k];
        }
    }
}

/// F = I + Σ_a u_a b_aᵀ per lane (box elements: through the Walsh–Hadamard modes), and J = det F.
template <typename Real, int W, bool S, bool Run, bool Box>
[[gnu::always_inline]] inline void deformation_gradient_lanes(HexLanes<Real, W, S, Run, Box>& l, const HexBatchData& d, const Real* dn_all)
{
    if constexpr (Box) {
        static_assert(S, "box elements share one geometry");
        for (int k = 0; k < 9; ++k) l.box_m[k] = static_cast<Real>(d.box_m[k]);
        box_modes<Real, W>(l.ux, l.tx);
        box_modes<Real, W>(l.uy, l.ty);
        box_modes<Real, W>(l.uz, l.tz);
        const Real* m = l.box_m;
#pragma omp simd
        for (int w = 0; w < W; ++w) {
            // F_ij = δ_ij + Σ_k M_jk G_ik, G_ik = t_i[2^k] = Σ_a s_k(a) u_ai.
            const Real g[3][3] = {{l.tx[1][w], l.tx[2][w], l.tx[4][w]}, {l.ty[1][w], l.ty[2][w], l.ty[4][w]}, {l.tz[1][w], l.tz[2][w], l.tz[4][w]}};
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j)
                    l.F[3 * i + j][w] = Real(i == j) + m[3 * j] * g[i][0] + m[3 * j + 1] * g[i][1] + m[3 * j + 2] * g[i][2];
        }
    } else {
#pragma omp simd
        for (int w = 0; w < W; ++w) {
            Real f0 = 1, f1 = 0, f2 = 0, f3 = 0, f4 = 1, f5 = 0, f6 = 0, f7 = 0, f8 = 1;
            for (int a = 0; a < 8; ++a) {
                const Real b0 = l.b(dn_all, 3 * a, w), b1 = l.b(dn_all, 3 * a + 1, w), b2 = l.b(dn_all, 3 * a + 2, w);
                f0 += l.ux[a][w] * b0;
                f1 += l.ux[a][w] * b1;
                f2 += l.ux[a][w] * b2;
                f3 += l.uy[a][w] * b0;
                f4 += l.uy[a][w] * b1;
                f5 += l.uy[a][w] * b2;
                f6 += l.uz[a][w] * b0;
                f7 += l.uz[a][w] * b1;
                f8 += l.uz[a][w] * b2;
            }
            l.F[0][w] = f0; l.F[1][w] = f1; l.F[2][w] = f2;
            l.F[3][w] = f3; l.F[4][w] = f4; l.F[5][w] = f5;
            l.F[6][w] = f6; l.F[7][w] = f7; l.F[8][w] = f8;
        }
    }
    const auto& F = l.F;
#pragma omp simd
    for (int w = 0; w < W; ++w)
        l.J[w] = F[0][w] * (F[4][w] * F[8][w] - F[5][w] * F[7][w]) - F[1][w] * (F[3][w] * F[8][w] - F[5][w] * F[6][w]) +
                 F[2][w] * (F[3][w] * F[7][w] - F[4][w] * F[6][w]);
}

/// The first Piola–Kirchhoff stress times the element volume, P V, per lane.
template <typename Real, int W, bool S, bool Run, bool Box>
[[gnu::always_inline]] inline void stress_lanes(HexLanes<Real, W, S, Run, Box>& l, MaterialLaw law)
{
    const auto& F = l.F;
    const auto& J = l.J;
    auto& P = l.P;
    if (law == MaterialLaw::linear_elastic || law == MaterialLaw::corotational) {
        for (int w = 0; w < W; ++w) {
            Real fl[9], pl[9];
            for (int k = 0; k < 9; ++k) fl[k] = F[k][w];
            first_piola_kirchhoff(law, l.mu[w], l.lambda[w], l.kappa[w], fl, pl);
            for (int k = 0; k < 9; ++k) P[k][w] = pl[k] * l.vol[w];
        }
        return;
    }
    // The remaining laws' stress is hexahedron_stress.hpp's, shared with the GPU step; one lane
    // loop per law, so that each vectorises without a branch.
    if (law == MaterialLaw::st_venant_kirchhoff) {
#pragma omp simd
        for (int w = 0; w < W; ++w) {
            const auto f = [&](int k) { return F[k][w]; };
            const Sym3<Real> s = st_venant_kirchhoff_stress(right_cauchy_green<Real>(f), l.mu[w], l.lambda[w]);
            volume_first_piola(f, s, l.vol[w], [&](int k, Real value) { P[k][w] = value; });
        }
        return;
    }
    alignas(64) Real r[W];
    inverse_cube_root<Real, W>(J, r);
#pragma omp simd
    for (int w = 0; w < W; ++w) {
        const auto f = [&](int k) { return F[k][w]; };
        const Sym3<Real> s = neo_hookean_stress(right_cauchy_green<Real>(f), l.mu[w], l.kappa[w], J[w], r[w]);
        volume_first_piola(f, s, l.vol[w], [&](int k, Real value) { P[k][w] = value; });
    }
}

/// Corner forces: P V b_a plus the hourglass forces k_hg Γ (Γᵀ u).
template <typename Real, int W, bool S, bool Run, bool Box>
[[gnu::always_inline]] inline void corner_forces_lanes(HexLanes<Real, W, S, Run, Box>& l, const Real* dn_all, const Real* gamma_all)
{
    const auto& P = l.P;
    if constexpr (Box) {
        // Mode forces: gradient modes (PM)_ik at 2^k, hourglass modes k_hg t_i at 3, 5, 6, 7 (Γ =
        // ±p: the sign squares away), none at 0; then back to the corners.
        alignas(64) Real ox[8][W], oy[8][W], oz[8][W];
        const Real* m = l.box_m;
#pragma omp simd
        for (int w = 0; w < W; ++w) {
            Real (*o[3])[W] = {ox, oy, oz};
            const Real (*t[3])[W] = {l.tx, l.ty, l.tz};
            for (int i = 0; i < 3; ++i) {
                o[i][0][w] = 0;
                o[i][1][w] = P[3 * i][w] * m[0] + P[3 * i + 1][w] * m[3] + P[3 * i + 2][w] * m[6];
                o[i][2][w] = P[3 * i][w] * m[1] + P[3 * i + 1][w] * m[4] + P[3 * i + 2][w] * m[7];
                o[i][4][w] = P[3 * i][w] * m[2] + P[3 * i + 1][w] * m[5] + P[3 * i + 2][w] * m[8];
                o[i][3][w] = l.khg[w] * t[i][3][w];
                o[i][5][w] = l.khg[w] * t[i][5][w];
                o[i][6][w] = l.khg[w] * t[i][6][w];
                o[i][7][w] = l.khg[w] * t[i][7][w];
            }
        }
        box_corners<Real, W>(ox, l.fx);
        box_corners<Real, W>(oy, l.fy);
        box_corners<Real, W>(oz, l.fz);
    } else {
        alignas(64) Real qx[4][W], qy[4][W], qz[4][W];
#pragma omp simd
        for (int w = 0; w < W; ++w)
            for (int m = 0; m < 4; ++m) {
                Real sx = 0, sy = 0, sz = 0;
                for (int a = 0; a < 8; ++a) {
                    const Real g = l.gamma(gamma_all, 4 * a + m, w);
                    sx += g * l.ux[a][w];
                    sy += g * l.uy[a][w];
                    sz += g * l.uz[a][w];
                }
                qx[m][w] = l.khg[w] * sx;
                qy[m][w] = l.khg[w] * sy;
                qz[m][w] = l.khg[w] * sz;
            }
#pragma omp simd
        for (int w = 0; w < W; ++w)
            for (int a = 0; a < 8; ++a) {
                const Real b0 = l.b(dn_all, 3 * a, w), b1 = l.b(dn_all, 3 * a + 1, w), b2 = l.b(dn_all, 3 * a + 2, w);
                Real x = P[0][w] * b0 + P[1][w] * b1 + P[2][w] * b2;
                Real y = P[3][w] * b0 + P[4][w] * b1 + P[5][w] * b2;
                Real z = P[6][w] * b0 + P[7][w] * b1 + P[8][w] * b2;
                for (int m = 0; m < 4; ++m) {
                    const Real g = l.gamma(gamma_all, 4 * a + m, w);
                    x += g * qx[m][w];
                    y += g * qy[m][w];
                    z += g * qz[m][w];
                }
                l.fx[a][w] = x;
                l.fy[a][w] = y;
                l.fz[a][w] = z;
            }
    }
}

/// Adds the live lanes' corner forces into f (a run: W consecutive nodes per corner).
template <typename Real, int W, bool S, bool Run, bool Box>
[[gnu::always_inline]] inline void scatter_lanes(const HexLanes<Real, W, S, Run, Box>& l, int count, Real* f)
{
    if constexpr (Run) {
        for (int a = 0; a < 8; ++a) {
            Real* fa = f + 3 * static_cast<std::size_t>(l.base[a]);
            if (count == W) {
#pragma omp simd
                for (int w = 0; w < W; ++w) {
                    fa[3 * w] += l.fx[a][w];
                    fa[3 * w + 1] += l.fy[a][w];
                    fa[3 * w + 2] += l.fz[a][w];
                }
            } else {
                for (int w = 0; w < count; ++w) {
                    fa[3 * w] += l.fx[a][w];
                    fa[3 * w + 1] += l.fy[a][w];
                    fa[3 * w + 2] += l.fz[a][w];
                }
            }
        }
    } else {
        for (int w = 0; w < count; ++w)
            for (int a = 0; a < 8; ++a) {
                Real* fa = f + 3 * static_cast<std::size_t>(l.ids[a][w]);
                fa[0] += l.fx[a][w];
                fa[1] += l.fy[a][w];
                fa[2] += l.fz[a][w];
            }
    }
}

/// Adds the forces of elements[0..count) (count ≤ W) into f. Returns the index (into elements)
/// of an element with det F ≤ 0, or -1. Run = true: the elements form a run (see above). Box =
/// true (needs SharedGeometry): the shared geometry is a box with b_a = M s_a, M = d.box_m
/// (row-major), and the transform above replaces the gradient and hourglass sums.
template <typename Real, int W, bool SharedGeometry, bool Run = false, bool Box = false>
inline int hexahedron_batch(const std::int32_t* elements, int count, const HexBatchData& d, const Real* u,
                            const Real* dn_all, const Real* gamma_all, const Real* volume_all, const Real* vb2_all,
                            const Real* mu_all, const Real* lambda_all, const Real* kappa_all,
                            const Real* hourglass_all, MaterialLaw law, Real* f)
{
    HexLanes<Real, W, SharedGeometry, Run, Box> lanes;
    const HexTables<Real> tables{dn_all, gamma_all, volume_all, vb2_all, mu_all, lambda_all, kappa_all, hourglass_all};
    gather_lanes(lanes, elements, count, d, u, tables);
    deformation_gradient_lanes(lanes, d, dn_all);
    int inverted = -1;
    for (int w = 0; w < count; ++w)
        if (!(lanes.J[w] > Real(0))) inverted = w;
    if (inverted >= 0) return inverted;
    stress_lanes(lanes, law);
    corner_forces_lanes(lanes, dn_all, gamma_all);
    scatter_lanes(lanes, count, f);
    return -1;
}

} // namespace physreg::detail
