// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Hyperelastic material laws of the TLED solver, evaluated at one deformation gradient F.
//
// Units inside the solver: mm, N, MPa (= N/mm²), tonne/mm³, s. Tissue tables give E in Pa and
// density in kg/m³; material_from_tissue converts.
//
// Compressible Neo-Hookean (the decoupled form of TLED and NiftySim):
//   Ψ = μ/2 (Ī₁ − 3) + κ/2 (J − 1)²,  Ī₁ = J^(-2/3) tr C,
//   S = μ J^(-2/3) (I − (tr C / 3) C⁻¹) + κ J (J − 1) C⁻¹,
// with μ = E / (2(1 + ν)) and κ = E / (3(1 − 2ν)).
// St Venant–Kirchhoff: S = λ tr(E) I + 2 μ E, E = (C − I)/2.
// Small-strain linear elastic: P = σ = λ tr(ε) I + 2 μ ε, ε = sym(F) − I.
// Co-rotational linear (paper 001, Müller & Gross 2004 with the polar rotation): F = R U (polar
// decomposition), the linear law in the rotated frame, ε = U − I:
//   Ψ = μ |F − R|² + λ/2 (tr(RᵀF) − 3)²,  P = 2μ (F − R) + λ (tr(RᵀF) − 3) R.
// For a linear tetrahedron V P b_a is exactly the classical element force R K₀ (Rᵀx − X); unlike
// the small-strain law it gives zero force under any rigid rotation.
// Compressible Mooney–Rivlin (CalculiX's *HYPERELASTIC, MOONEY-RIVLIN with D1 = 2/κ), the law of the
// phantom's ground truth (implicit solvers only):
//   Ψ = C10 (Ī₁ − 3) + C01 (Ī₂ − 3) + κ/2 (J − 1)²,  Ī₂ = J^(-4/3) ½ (I₁² − tr C²),
// with C10 + C01 = μ/2 (the initial shear modulus is μ) and C01 = c01_fraction · μ/2.
#include "physreg/model/tissue_table.hpp"

#include <Eigen/Core>
#include <Eigen/SVD>

#include <cmath>
#include <limits>
#include <string>

namespace physreg {

enum class MaterialLaw { neo_hookean, st_venant_kirchhoff, linear_elastic, corotational, mooney_rivlin };
/// "neo-hookean", "svk", "linear", "corotational", "mooney-rivlin"
MaterialLaw parse_material_law(const std::string& text);
std::string to_string(MaterialLaw law);

struct ElasticMaterial {
    double mu_mpa = 0.0;      ///< shear modulus
    double lambda_mpa = 0.0;  ///< first Lamé parameter
    double kappa_mpa = 0.0;   ///< bulk modulus
    double density_t_mm3 = 0.0;
    double c01_mpa = 0.0;     ///< Mooney–Rivlin: the Ī₂ coefficient (C10 = μ/2 − C01)

    double dilatational_modulus_mpa() const { return lambda_mpa + 2.0 * mu_mpa; }
    /// Dilatational wave speed, mm/s.
    double wave_speed_mm_s() const { return std::sqrt(dilatational_modulus_mpa() / density_t_mm3); }
};

/// Throws Error naming the tissue for impossible parameters.
ElasticMaterial material_from_tissue(const Tissue& tissue);

/// The rotation R of the polar decomposition F = R U (row-major 3×3), for det F > 0, by Higham's
/// scaled Newton iteration X ← ½ (ζ X + X⁻ᵀ / ζ), ζ = (‖X⁻¹‖_F / ‖X‖_F)^½: quadratically
/// convergent, a proper rotation for det F > 0, and cheaper than an SVD. Returns det F.
template <typename Real>
inline Real polar_rotation(const Real* f, Real* r)
{
    const auto det = [](const Real* x) {
        return x[0] * (x[4] * x[8] - x[5] * x[7]) - x[1] * (x[3] * x[8] - x[5] * x[6]) + x[2] * (x[3] * x[7] - x[4] * x[6]);
    };
    const Real j = det(f);
    for (int k = 0; k < 9; ++k) r[k] = f[k];
    if (!(j > Real(0))) return j;
    // Quadratic convergence: once an update changes X by less than δ, the error left is O(δ²), so
    // δ ≤ 4 √ε is enough.
    const Real tolerance = Real(4) * std::sqrt(std::numeric_limits<Real>::epsilon());
    for (int iteration = 0; iteration < 40; ++iteration) {
        const Real d = det(r);
        // X⁻ᵀ = cofactor(X) / det X
        Real c[9];
        c[0] = r[4] * r[8] - r[5] * r[7];
        c[1] = r[5] * r[6] - r[3] * r[8];
        c[2] = r[3] * r[7] - r[4] * r[6];
        c[3] = r[2] * r[7] - r[1] * r[8];
        c[4] = r[0] * r[8] - r[2] * r[6];
        c[5] = r[1] * r[6] - r[0] * r[7];
        c[6] = r[1] * r[5] - r[2] * r[4];
        c[7] = r[2] * r[3] - r[0] * r[5];
        c[8] = r[0] * r[4] - r[1] * r[3];
        Real x_norm = 0, c_norm = 0;
        for (int k = 0; k < 9; ++k) {
            c[k] /= d;
            x_norm += r[k] * r[k];
            c_norm += c[k] * c[k];
        }
        const Real zeta = std::sqrt(std::sqrt(c_norm / x_norm));
        Real change = 0;
        for (int k = 0; k < 9; ++k) {
            const Real next = Real(0.5) * (zeta * r[k] + c[k] / zeta);
            change += (next - r[k]) * (next - r[k]);
            r[k] = next;
        }
        if (change <= tolerance * tolerance) break;
    }
    return j;
}

/// The rotation of the co-rotational law: the polar rotation for det F > 0; for an inverted or
/// flat element (det F ≤ 0) the rotation of the SVD F = W Σ Vᵀ with W and V made proper by
/// negating the smallest singular value (Irving, Teran & Fedkiw 2004), so that the linear law in
/// the rotated frame pushes the element back out of inversion. Returns det F.
template <typename Real>
inline Real corotation(const Real* f, Real* r)
{
    const Real j = polar_rotation(f, r);
    if (j > Real(0)) return j;
    using Matrix = Eigen::Matrix<Real, 3, 3, Eigen::RowMajor>;
    const Eigen::JacobiSVD<Matrix> svd(Eigen::Map<const Matrix>(f), Eigen::ComputeFullU | Eigen::ComputeFullV);
    Matrix w = svd.matrixU(), v = svd.matrixV();
    if (w.determinant() < Real(0)) w.col(2) *= Real(-1);
    if (v.determinant() < Real(0)) v.col(2) *= Real(-1);
    Eigen::Map<Matrix> rotation(r);
    rotation = w * v.transpose();
    return j;
}

/// The co-rotational law's P (MPa, written to `p`) at F; returns the energy density Ψ (MPa), both
/// from one rotation.
template <typename Real>
inline Real corotational_stress(Real mu, Real lambda, const Real* f, Real* p)
{
    Real r[9];
    corotation(f, r);
    Real excess = -Real(3), distance = 0; // tr(RᵀF) − 3 = tr(U − I), |F − R|²
    for (int k = 0; k < 9; ++k) {
        excess += r[k] * f[k];
        distance += (f[k] - r[k]) * (f[k] - r[k]);
    }
    for (int k = 0; k < 9; ++k) p[k] = Real(2) * mu * (f[k] - r[k]) + lambda * excess * r[k];
    return mu * distance + Real(0.5) * lambda * excess * excess;
}

/// The Mooney–Rivlin P (MPa, written to `p`) at F; returns the energy density Ψ (MPa). Templated on
/// the scalar so that automatic differentiation gives the exact tangent. det F ≤ 0: returns NaN.
template <typename Real>
inline Real mooney_rivlin_stress(double c10, double c01, double kappa, const Real* f, Real* p)
{
    using std::pow;
    const Real j = f[0] * (f[4] * f[8] - f[5] * f[7]) - f[1] * (f[3] * f[8] - f[5] * f[6]) + f[2] * (f[3] * f[7] - f[4] * f[6]);
    if (!(j > 0.0)) {
        for (int k = 0; k < 9; ++k) p[k] = Real(std::numeric_limits<double>::quiet_NaN());
        return Real(std::numeric_limits<double>::quiet_NaN());
    }
    // C = Fᵀ F as C00 C11 C22 C01 C12 C02
    Real cm[6];
    cm[0] = f[0] * f[0] + f[3] * f[3] + f[6] * f[6];
    cm[1] = f[1] * f[1] + f[4] * f[4] + f[7] * f[7];
    cm[2] = f[2] * f[2] + f[5] * f[5] + f[8] * f[8];
    cm[3] = f[0] * f[1] + f[3] * f[4] + f[6] * f[7];
    cm[4] = f[1] * f[2] + f[4] * f[5] + f[7] * f[8];
    cm[5] = f[0] * f[2] + f[3] * f[5] + f[6] * f[8];
    const Real i1 = cm[0] + cm[1] + cm[2];
    const Real tr_c2 = cm[0] * cm[0] + cm[1] * cm[1] + cm[2] * cm[2] + Real(2.0) * (cm[3] * cm[3] + cm[4] * cm[4] + cm[5] * cm[5]);
    const Real i2 = Real(0.5) * (i1 * i1 - tr_c2);
    const Real inv_j2 = Real(1.0) / (j * j);
    const Real ci[6] = {(cm[1] * cm[2] - cm[4] * cm[4]) * inv_j2, (cm[0] * cm[2] - cm[5] * cm[5]) * inv_j2,
                        (cm[0] * cm[1] - cm[3] * cm[3]) * inv_j2, (cm[5] * cm[4] - cm[3] * cm[2]) * inv_j2,
                        (cm[3] * cm[5] - cm[0] * cm[4]) * inv_j2, (cm[3] * cm[4] - cm[1] * cm[5]) * inv_j2};
    const Real j23 = pow(j, -2.0 / 3.0), j43 = j23 * j23;
    // S = 2C10 J^(-2/3) (I − I₁/3 C⁻¹) + 2C01 J^(-4/3) (I₁ I − C − ⅔ I₂ C⁻¹) + κ J (J − 1) C⁻¹
    const Real a1 = Real(2.0 * c10) * j23, a2 = Real(2.0 * c01) * j43;
    const Real inverse_coefficient = -a1 * i1 / Real(3.0) - a2 * Real(2.0 / 3.0) * i2 + Real(kappa) * j * (j - Real(1.0));
    Real s[6];
    for (int k = 0; k < 6; ++k) s[k] = inverse_coefficient * ci[k] - a2 * cm[k];
    for (int k = 0; k < 3; ++k) s[k] += a1 + a2 * i1;
    for (int r = 0; r < 3; ++r) {
        const Real f0 = f[3 * r], f1 = f[3 * r + 1], f2 = f[3 * r + 2];
        p[3 * r + 0] = f0 * s[0] + f1 * s[3] + f2 * s[5];
        p[3 * r + 1] = f0 * s[3] + f1 * s[1] + f2 * s[4];
        p[3 * r + 2] = f0 * s[5] + f1 * s[4] + f2 * s[2];
    }
    return Real(c10) * (j23 * i1 - Real(3.0)) + Real(c01) * (j43 * i2 - Real(3.0)) + Real(0.5 * kappa) * (j - Real(1.0)) * (j - Real(1.0));
}

/// First Piola–Kirchhoff stress P (MPa) for F (row-major 3×3), written to `p`. Returns J = det F.
/// `volumetric_j` > 0 (Neo-Hookean only) replaces J in the pressure κ(J − 1): the averaged-nodal-
/// pressure tetrahedron passes the volume change averaged over the element's nodes.
/// Templated on the scalar so single and double precision kernels share it.
template <typename Real>
inline Real first_piola_kirchhoff(MaterialLaw law, Real mu, Real lambda, Real kappa, const Real* f, Real* p,
                                  Real volumetric_j = Real(0))
{
    const Real j = f[0] * (f[4] * f[8] - f[5] * f[7]) - f[1] * (f[3] * f[8] - f[5] * f[6]) +
                   f[2] * (f[3] * f[7] - f[4] * f[6]);
    if (law == MaterialLaw::corotational) {
        corotational_stress(mu, lambda, f, p);
        return j;
    }
    if (law == MaterialLaw::linear_elastic) {
        const Real trace = f[0] + f[4] + f[8] - Real(3);
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) {
                const Real eps = Real(0.5) * (f[3 * r + c] + f[3 * c + r]) - (r == c ? Real(1) : Real(0));
                p[3 * r + c] = Real(2) * mu * eps + (r == c ? lambda * trace : Real(0));
            }
        return j;
    }
    // C = Fᵀ F (symmetric)
    Real cm[6];
    cm[0] = f[0] * f[0] + f[3] * f[3] + f[6] * f[6];
    cm[1] = f[1] * f[1] + f[4] * f[4] + f[7] * f[7];
    cm[2] = f[2] * f[2] + f[5] * f[5] + f[8] * f[8];
    cm[3] = f[0] * f[1] + f[3] * f[4] + f[6] * f[7]; // C01
    cm[4] = f[1] * f[2] + f[4] * f[5] + f[7] * f[8]; // C12
    cm[5] = f[0] * f[2] + f[3] * f[5] + f[6] * f[8]; // C02
    Real s[6];
    if (law == MaterialLaw::st_venant_kirchhoff) {
        const Real tr_e = Real(0.5) * (cm[0] + cm[1] + cm[2] - Real(3));
        s[0] = lambda * tr_e + mu * (cm[0] - Real(1));
        s[1] = lambda * tr_e + mu * (cm[1] - Real(1));
        s[2] = lambda * tr_e + mu * (cm[2] - Real(1));
        s[3] = mu * cm[3];
        s[4] = mu * cm[4];
        s[5] = mu * cm[5];
    } else {
        // C⁻¹ = adj(C) / J²
        const Real inv_j2 = Real(1) / (j * j);
        const Real ci0 = (cm[1] * cm[2] - cm[4] * cm[4]) * inv_j2;
        const Real ci1 = (cm[0] * cm[2] - cm[5] * cm[5]) * inv_j2;
        const Real ci2 = (cm[0] * cm[1] - cm[3] * cm[3]) * inv_j2;
        const Real ci3 = (cm[5] * cm[4] - cm[3] * cm[2]) * inv_j2;
        const Real ci4 = (cm[3] * cm[5] - cm[0] * cm[4]) * inv_j2;
        const Real ci5 = (cm[3] * cm[4] - cm[1] * cm[5]) * inv_j2;
        const Real cbrt_j = std::cbrt(j);
        const Real mu_j = mu / (cbrt_j * cbrt_j); // μ J^(-2/3)
        const Real third_trace = (cm[0] + cm[1] + cm[2]) / Real(3);
        // Averaged nodal pressure: the pressure κ(J̄ − 1) from a smoothed J̄ when one is given.
        const Real jp = volumetric_j > Real(0) ? volumetric_j : j;
        const Real vol = kappa * j * (jp - Real(1));
        const Real a = vol - mu_j * third_trace; // coefficient of C⁻¹
        s[0] = mu_j + a * ci0;
        s[1] = mu_j + a * ci1;
        s[2] = mu_j + a * ci2;
        s[3] = a * ci3;
        s[4] = a * ci4;
        s[5] = a * ci5;
    }
    // P = F S
    for (int r = 0; r < 3; ++r) {
        const Real f0 = f[3 * r], f1 = f[3 * r + 1], f2 = f[3 * r + 2];
        p[3 * r + 0] = f0 * s[0] + f1 * s[3] + f2 * s[5];
        p[3 * r + 1] = f0 * s[3] + f1 * s[1] + f2 * s[4];
        p[3 * r + 2] = f0 * s[5] + f1 * s[4] + f2 * s[2];
    }
    return j;
}

} // namespace physreg

namespace physreg {

/// Material tangent A = ∂P/∂F (MPa) at F (row-major 3×3), for implicit solvers (double precision):
/// a[9 (3i + J) + (3k + L)] = ∂P_iJ/∂F_kL. With P = F S and ℂ = 2 ∂S/∂C,
/// A_iJkL = δ_ik S_JL + Σ_IK F_iI ℂ_IJKL F_kK (Neo-Hookean and St Venant–Kirchhoff); the linear
/// law's A is constant. Co-rotational: A = 2μ 𝕀 + λ R⊗R + (λ (tr(RᵀF) − 3) − 2μ) ∂R/∂F, with
/// ∂R = R Ω, Ω = [ω]×, ω = (tr U I − U)⁻¹ axial(Rᵀ∂F − ∂FᵀR). Returns J = det F. The averaged-nodal-pressure variant has no tangent here.
double first_piola_tangent(MaterialLaw law, const ElasticMaterial& m, const double* f, double* a);

/// The classical co-rotational stiffness (SOFA, Müller & Gross): the small-strain tangent rotated,
/// A_iJkL = λ R_iJ R_kL + μ (δ_ik δ_JL + R_iL R_kJ), i.e. K_e = R K₀ Rᵀ. It drops ∂R/∂F, so it is not
/// the exact derivative of the force, but it is positive semi-definite for every F (inverted
/// elements included): Newton becomes a quasi-Newton method that cannot be thrown off by the
/// indefinite exact tangent of a crushed element. Returns J = det F.
double rotated_linear_tangent(const ElasticMaterial& m, const double* f, double* a);

} // namespace physreg
