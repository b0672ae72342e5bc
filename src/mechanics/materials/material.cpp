// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/materials/material.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/types.hpp"

#include <unsupported/Eigen/AutoDiff>

namespace physreg {

MaterialLaw parse_material_law(const std::string& text)
{
    if (text == "neo-hookean" || text == "neo_hookean") return MaterialLaw::neo_hookean;
    if (text == "svk" || text == "st-venant-kirchhoff") return MaterialLaw::st_venant_kirchhoff;
    if (text == "linear" || text == "linear-elastic") return MaterialLaw::linear_elastic;
    if (text == "corotational" || text == "co-rotational") return MaterialLaw::corotational;
    if (text == "mooney-rivlin" || text == "mooney_rivlin") return MaterialLaw::mooney_rivlin;
    fail("material law '{}' is not one of neo-hookean, svk, linear, corotational, mooney-rivlin", text);
}

std::string to_string(MaterialLaw law)
{
    switch (law) {
    case MaterialLaw::neo_hookean: return "neo-hookean";
    case MaterialLaw::st_venant_kirchhoff: return "svk";
    case MaterialLaw::corotational: return "corotational";
    case MaterialLaw::mooney_rivlin: return "mooney-rivlin";
    default: return "linear";
    }
}

ElasticMaterial material_from_tissue(const Tissue& t)
{
    TissueTable single;
    single.tissues = {t};
    single.validate("material");
    const double e = t.young_modulus_pa * 1e-6; // Pa → MPa
    const double nu = t.poisson_ratio;
    ElasticMaterial m;
    m.mu_mpa = e / (2.0 * (1.0 + nu));
    m.lambda_mpa = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    m.kappa_mpa = e / (3.0 * (1.0 - 2.0 * nu));
    m.density_t_mm3 = t.density_kg_m3 * 1e-12; // kg/m³ → t/mm³
    m.c01_mpa = t.mooney_rivlin_c01_fraction * 0.5 * m.mu_mpa;
    return m;
}

} // namespace physreg

namespace physreg {

double first_piola_tangent(MaterialLaw law, const ElasticMaterial& m, const double* f, double* a)
{
    const double mu = m.mu_mpa, lambda = m.lambda_mpa, kappa = m.kappa_mpa;
    const auto d = [](int i, int j) { return i == j ? 1.0 : 0.0; };
    const double j = f[0] * (f[4] * f[8] - f[5] * f[7]) - f[1] * (f[3] * f[8] - f[5] * f[6]) + f[2] * (f[3] * f[7] - f[4] * f[6]);
    if (law == MaterialLaw::mooney_rivlin) {
        // Exact tangent by forward-mode automatic differentiation of P(F) (Eigen's AutoDiffScalar):
        // no hand-derived fourth-order tensor to get wrong, machine-precision derivatives.
        using Dual = Eigen::AutoDiffScalar<Eigen::Matrix<double, 9, 1>>;
        Dual fd[9], pd[9];
        for (int k = 0; k < 9; ++k) fd[k] = Dual(f[k], 9, k);
        mooney_rivlin_stress<Dual>(0.5 * mu - m.c01_mpa, m.c01_mpa, kappa, fd, pd);
        for (int r = 0; r < 9; ++r)
            for (int c = 0; c < 9; ++c) a[9 * r + c] = pd[r].derivatives()[c];
        return j;
    }
    if (law == MaterialLaw::corotational) {
        double r[9];
        corotation(f, r);
        double u[3][3]; // U = Rᵀ F (symmetric up to round-off)
        for (int I = 0; I < 3; ++I)
            for (int J = 0; J < 3; ++J) u[I][J] = r[I] * f[J] + r[3 + I] * f[3 + J] + r[6 + I] * f[6 + J];
        const double trace = u[0][0] + u[1][1] + u[2][2];
        Mat3 g;
        for (int I = 0; I < 3; ++I)
            for (int J = 0; J < 3; ++J) g(I, J) = trace * d(I, J) - 0.5 * (u[I][J] + u[J][I]);
        const Mat3 g_inverse = g.inverse(); // tr U I − U is positive definite for det F > 0
        const double rotation_coefficient = lambda * (trace - 3.0) - 2.0 * mu;
        for (int k = 0; k < 3; ++k)
            for (int L = 0; L < 3; ++L) {
                // Y = Rᵀ dF − dFᵀ R for dF = e_k e_Lᵀ: Y_IJ = R_kI δ_JL − δ_IL R_kJ.
                double y[3][3];
                for (int I = 0; I < 3; ++I)
                    for (int J = 0; J < 3; ++J) y[I][J] = r[3 * k + I] * d(J, L) - d(I, L) * r[3 * k + J];
                const Vec3 axial(y[2][1], y[0][2], y[1][0]);
                const Vec3 w = g_inverse * axial;
                const double omega[3][3] = {{0.0, -w[2], w[1]}, {w[2], 0.0, -w[0]}, {-w[1], w[0], 0.0}};
                for (int i = 0; i < 3; ++i)
                    for (int J = 0; J < 3; ++J) {
                        const double dr = r[3 * i] * omega[0][J] + r[3 * i + 1] * omega[1][J] + r[3 * i + 2] * omega[2][J];
                        a[9 * (3 * i + J) + 3 * k + L] =
                            2.0 * mu * d(i, k) * d(J, L) + lambda * r[3 * i + J] * r[3 * k + L] + rotation_coefficient * dr;
                    }
            }
        return f[0] * (f[4] * f[8] - f[5] * f[7]) - f[1] * (f[3] * f[8] - f[5] * f[6]) + f[2] * (f[3] * f[7] - f[4] * f[6]);
    }
    if (law == MaterialLaw::linear_elastic) {
        // P = λ tr(ε) I + 2μ ε, ε = sym(F) − I.
        for (int i = 0; i < 3; ++i)
            for (int J = 0; J < 3; ++J)
                for (int k = 0; k < 3; ++k)
                    for (int L = 0; L < 3; ++L)
                        a[9 * (3 * i + J) + 3 * k + L] = lambda * d(i, J) * d(k, L) + mu * (d(i, k) * d(J, L) + d(i, L) * d(J, k));
        return j;
    }
    double c[3][3];
    for (int I = 0; I < 3; ++I)
        for (int J = 0; J < 3; ++J) c[I][J] = f[I] * f[J] + f[3 + I] * f[3 + J] + f[6 + I] * f[6 + J];
    double s[3][3], cc[3][3][3][3]; // S and ℂ = 2 ∂S/∂C
    if (law == MaterialLaw::st_venant_kirchhoff) {
        const double tr_e = 0.5 * (c[0][0] + c[1][1] + c[2][2] - 3.0);
        for (int I = 0; I < 3; ++I)
            for (int J = 0; J < 3; ++J) {
                s[I][J] = lambda * tr_e * d(I, J) + mu * (c[I][J] - d(I, J));
                for (int K = 0; K < 3; ++K)
                    for (int L = 0; L < 3; ++L)
                        cc[I][J][K][L] = lambda * d(I, J) * d(K, L) + mu * (d(I, K) * d(J, L) + d(I, L) * d(J, K));
            }
    } else {
        // Ψ = μ/2 (J^(-2/3) I₁ − 3) + κ/2 (J − 1)²:
        // ℂ = −⅔ μ J^(-2/3) (I⊗C⁻¹ + C⁻¹⊗I) + (2/9) μ J^(-2/3) I₁ C⁻¹⊗C⁻¹ + ⅔ μ J^(-2/3) I₁ 𝕀_C⁻¹
        //     + κ (2J² − J) C⁻¹⊗C⁻¹ − 2κ (J² − J) 𝕀_C⁻¹,  𝕀_C⁻¹ = ½ (C⁻¹_IK C⁻¹_JL + C⁻¹_IL C⁻¹_JK).
        const double inv_j2 = 1.0 / (j * j);
        double ci[3][3];
        ci[0][0] = (c[1][1] * c[2][2] - c[1][2] * c[1][2]) * inv_j2;
        ci[1][1] = (c[0][0] * c[2][2] - c[0][2] * c[0][2]) * inv_j2;
        ci[2][2] = (c[0][0] * c[1][1] - c[0][1] * c[0][1]) * inv_j2;
        ci[0][1] = ci[1][0] = (c[0][2] * c[1][2] - c[0][1] * c[2][2]) * inv_j2;
        ci[1][2] = ci[2][1] = (c[0][1] * c[0][2] - c[0][0] * c[1][2]) * inv_j2;
        ci[0][2] = ci[2][0] = (c[0][1] * c[1][2] - c[1][1] * c[0][2]) * inv_j2;
        const double cbrt_j = std::cbrt(j);
        const double mu_a = mu / (cbrt_j * cbrt_j);
        const double i1 = c[0][0] + c[1][1] + c[2][2];
        const double vol = kappa * j * (j - 1.0);
        for (int I = 0; I < 3; ++I)
            for (int J = 0; J < 3; ++J) {
                s[I][J] = mu_a * (d(I, J) - i1 / 3.0 * ci[I][J]) + vol * ci[I][J];
                for (int K = 0; K < 3; ++K)
                    for (int L = 0; L < 3; ++L) {
                        const double sym = 0.5 * (ci[I][K] * ci[J][L] + ci[I][L] * ci[J][K]);
                        cc[I][J][K][L] = -2.0 / 3.0 * mu_a * (d(I, J) * ci[K][L] + ci[I][J] * d(K, L)) +
                                         2.0 / 9.0 * mu_a * i1 * ci[I][J] * ci[K][L] + 2.0 / 3.0 * mu_a * i1 * sym +
                                         kappa * (2.0 * j * j - j) * ci[I][J] * ci[K][L] - 2.0 * vol * sym;
                    }
            }
    }
    // G_iJ,kL = Σ_IK F_iI ℂ_IJKL F_kK: first contract ℂ with F over I, then over K.
    double t[3][3][3][3]; // t[i][J][K][L] = Σ_I F_iI ℂ_IJKL
    for (int i = 0; i < 3; ++i)
        for (int J = 0; J < 3; ++J)
            for (int K = 0; K < 3; ++K)
                for (int L = 0; L < 3; ++L)
                    t[i][J][K][L] = f[3 * i] * cc[0][J][K][L] + f[3 * i + 1] * cc[1][J][K][L] + f[3 * i + 2] * cc[2][J][K][L];
    for (int i = 0; i < 3; ++i)
        for (int J = 0; J < 3; ++J)
            for (int k = 0; k < 3; ++k)
                for (int L = 0; L < 3; ++L)
                    a[9 * (3 * i + J) + 3 * k + L] = d(i, k) * s[J][L] + f[3 * k] * t[i][J][0][L] + f[3 * k + 1] * t[i][J][1][L] +
                                                     f[3 * k + 2] * t[i][J][2][L];
    return j;
}

double rotated_linear_tangent(const ElasticMaterial& m, const double* f, double* a)
{
    double r[9];
    const double j = corotation(f, r);
    for (int i = 0; i < 3; ++i)
        for (int J = 0; J < 3; ++J)
            for (int k = 0; k < 3; ++k)
                for (int L = 0; L < 3; ++L)
                    a[9 * (3 * i + J) + 3 * k + L] = m.lambda_mpa * r[3 * i + J] * r[3 * k + L] +
                                                     m.mu_mpa * ((i == k && J == L ? 1.0 : 0.0) + r[3 * i + L] * r[3 * k + J]);
    return j;
}

} // namespace physreg
