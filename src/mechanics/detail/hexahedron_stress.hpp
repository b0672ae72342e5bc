// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The uniform-strain hexahedron's stress, written once for the CPU kernel (hexahedron_kernel.hpp,
// one SIMD lane at a time) and for the GPU step (gpu/tled_step_kernels.hpp, one thread per element;
// nvcc compiles it for the device, g++ for the host emulation): the right Cauchy–Green tensor, the
// second Piola–Kirchhoff stress of the two laws, and V F S. Scalars and accessors rather than
// arrays, so that the CPU's `omp simd` lane loop still vectorises once they are inlined.

#if defined(__CUDACC__)
#define PHYSREG_STRESS_INLINE __host__ __device__ __forceinline__
#else
#define PHYSREG_STRESS_INLINE [[gnu::always_inline]] inline
#endif

namespace physreg::detail {

/// A symmetric 3×3 tensor: its diagonal, then the 01, 12 and 02 entries.
template <typename Real>
struct Sym3 {
    Real xx, yy, zz, xy, yz, xz;
};

/// A row-major 3×3 array read as F(k), k = 3 row + column.
template <typename Real>
struct RowMajor3 {
    const Real* a;
    PHYSREG_STRESS_INLINE Real operator()(int k) const { return a[k]; }
};

/// C = Fᵀ F; `F(k)` reads the row-major entry k.
template <typename Real, typename Matrix>
PHYSREG_STRESS_INLINE Sym3<Real> right_cauchy_green(const Matrix& F)
{
    return {F(0) * F(0) + F(3) * F(3) + F(6) * F(6), F(1) * F(1) + F(4) * F(4) + F(7) * F(7), F(2) * F(2) + F(5) * F(5) + F(8) * F(8),
            F(0) * F(1) + F(3) * F(4) + F(6) * F(7), F(1) * F(2) + F(4) * F(5) + F(7) * F(8), F(0) * F(2) + F(3) * F(5) + F(6) * F(8)};
}

/// S from C for St Venant–Kirchhoff: λ tr E I + 2 μ E.
template <typename Real>
PHYSREG_STRESS_INLINE Sym3<Real> st_venant_kirchhoff_stress(const Sym3<Real>& c, Real mu, Real lambda)
{
    const Real tr_e = Real(0.5) * (c.xx + c.yy + c.zz - Real(3));
    return {lambda * tr_e + mu * (c.xx - Real(1)), lambda * tr_e + mu * (c.yy - Real(1)), lambda * tr_e + mu * (c.zz - Real(1)),
            mu * c.xy, mu * c.yz, mu * c.xz};
}

/// S from C for the decoupled Neo-Hookean law: μ J^(-2/3) (I − tr C C⁻¹ / 3) + κ J (J − 1) C⁻¹,
/// given r = J^(-1/3).
template <typename Real>
PHYSREG_STRESS_INLINE Sym3<Real> neo_hookean_stress(const Sym3<Real>& c, Real mu, Real kappa, Real J, Real r)
{
    const Real inv_j2 = Real(1) / (J * J);
    const Real mu_j = mu * r * r; // μ J^(-2/3)
    const Real a = kappa * J * (J - Real(1)) - mu_j * (c.xx + c.yy + c.zz) * Real(1.0 / 3.0);
    const Real ai = a * inv_j2; // C⁻¹ = adj(C) / J²
    return {mu_j + ai * (c.yy * c.zz - c.yz * c.yz), mu_j + ai * (c.xx * c.zz - c.xz * c.xz), mu_j + ai * (c.xx * c.yy - c.xy * c.xy),
            ai * (c.xz * c.yz - c.xy * c.zz), ai * (c.xy * c.xz - c.xx * c.yz), ai * (c.xy * c.yz - c.yy * c.xz)};
}

/// P = V F S, the element's first Piola–Kirchhoff stress times its volume; `P(k, value)` writes the
/// row-major entry k.
template <typename Real, typename Matrix, typename Out>
PHYSREG_STRESS_INLINE void volume_first_piola(const Matrix& F, const Sym3<Real>& s, Real v, const Out& P)
{
    for (int row = 0; row < 3; ++row) {
        const Real g0 = F(3 * row), g1 = F(3 * row + 1), g2 = F(3 * row + 2);
        P(3 * row, v * (g0 * s.xx + g1 * s.xy + g2 * s.xz));
        P(3 * row + 1, v * (g0 * s.xy + g1 * s.yy + g2 * s.yz));
        P(3 * row + 2, v * (g0 * s.xz + g1 * s.yz + g2 * s.zz));
    }
}

} // namespace physreg::detail
