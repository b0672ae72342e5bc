// SPDX-License-Identifier: GPL-3.0-or-later
// The ground truth's law: compressible Mooney–Rivlin. Its stress is the derivative of its energy,
// its automatic-differentiation tangent the derivative of its stress (finite differences, as a Form), it
// reduces to our Neo-Hookean law for C01 = 0, and on a CGAL-meshed gel block with an inclusion
// physreg's Newton matches CalculiX's C3D4 MOONEY-RIVLIN (skips without ccx).
#include "form_cases.hpp"
#include "mechanics_fixtures.hpp"
#include "physreg/core/error.hpp"
#include "physreg/mechanics/forms/mechanics_forms.hpp"
#include "physreg/mechanics/simulation/calculix.hpp"
#include "physreg/mechanics/implicit/newton_solver.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/phantom/ground_truth.hpp"

#include <gtest/gtest.h>

#include <iostream>

namespace physreg {

namespace {

ElasticMaterial mooney(double c01_fraction)
{
    Tissue t{1, "gel", 2e4, 0.495, 1000.0};
    t.mooney_rivlin_c01_fraction = c01_fraction;
    return material_from_tissue(t);
}

const double kF[9] = {1.12, 0.07, -0.05, -0.03, 0.91, 0.11, 0.06, -0.08, 1.04}; // a finite, non-symmetric F

} // namespace

// Its stress is ∂Ψ/∂F and its automatic-differentiation tangent ∂P/∂F: a Form of F (test_forms.cpp).
const test::RegisterFormCase mooney_rivlin_law{"StrainEnergyDensityForm", "Mooney-Rivlin, C01 = 0.35 of mu/2", [] {
    const ElasticMaterial m = mooney(0.35);
    if (!(m.c01_mpa > 0.0)) fail("the Mooney-Rivlin material has no second-invariant term");
    FiniteDifferenceOptions o;
    o.random_directions = 3;
    return test::FormCheckResult{check_derivatives(StrainEnergyDensityForm(MaterialLaw::mooney_rivlin, m), std::vector<double>(kF, kF + 9), o), 1e-7, 1e-6};
}};

TEST(MooneyRivlin, UndeformedItHasNoStressAndTheSmallStrainTangent)
{
    const ElasticMaterial m = mooney(0.35);
    // Undeformed: no stress, and the small-strain tangent (λ + 2μ on the diagonal).
    const double identity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    double p0[9], a0[81];
    EXPECT_NEAR(mooney_rivlin_stress<double>(0.5 * m.mu_mpa - m.c01_mpa, m.c01_mpa, m.kappa_mpa, identity, p0), 0.0, 1e-15);
    for (double v : p0) EXPECT_NEAR(v, 0.0, 1e-15);
    first_piola_tangent(MaterialLaw::mooney_rivlin, m, identity, a0);
    EXPECT_NEAR(a0[0], m.kappa_mpa + 4.0 / 3.0 * m.mu_mpa, 1e-9 * m.kappa_mpa);
    EXPECT_NEAR(a0[1 * 9 + 1], m.mu_mpa, 1e-9 * m.kappa_mpa); // ∂P_01/∂F_01
}

TEST(MooneyRivlin, WithoutTheSecondInvariantItIsOurNeoHookeanLaw)
{
    const ElasticMaterial m = mooney(0.0);
    double p_mr[9], p_nh[9];
    mooney_rivlin_stress<double>(0.5 * m.mu_mpa, 0.0, m.kappa_mpa, kF, p_mr);
    first_piola_kirchhoff<double>(MaterialLaw::neo_hookean, m.mu_mpa, m.lambda_mpa, m.kappa_mpa, kF, p_nh);
    for (int k = 0; k < 9; ++k) EXPECT_NEAR(p_mr[k], p_nh[k], 1e-12 * m.kappa_mpa);
    // With C01 > 0 the stress differs (the test could fail).
    const ElasticMaterial other = mooney(0.4);
    double p_other[9];
    mooney_rivlin_stress<double>(0.5 * other.mu_mpa - other.c01_mpa, other.c01_mpa, other.kappa_mpa, kF, p_other);
    double difference = 0;
    for (int k = 0; k < 9; ++k) difference = std::max(difference, std::abs(p_other[k] - p_nh[k]));
    EXPECT_GT(difference, 1e-3 * m.mu_mpa);
}

TEST(MooneyRivlin, ExplicitSolversRefuseItAndBadFractionsAreRefused)
{
    const VolumeMesh mesh = split_hexahedra_into_tetrahedra(test::block_mesh(2, 2, 2, 1.0));
    TledOptions o;
    o.law = MaterialLaw::mooney_rivlin;
    const TledModel model(mesh, test::one_tissue(1e4, 0.45), o);
    EXPECT_NE(test::error_message([&] { TledSolver<double> solver(model); }).find("implicit solvers"), std::string::npos);
    TissueTable bad = test::one_tissue(1e4, 0.45);
    bad.tissues[0].mooney_rivlin_c01_fraction = 1.0;
    EXPECT_NE(test::error_message([&] { bad.validate("t"); }).find("mooney_rivlin_c01_fraction"), std::string::npos);
    EXPECT_EQ(parse_material_law("mooney-rivlin"), MaterialLaw::mooney_rivlin);
}

TEST(MooneyRivlin, GroundTruthDiscretisationMatchesCalculix)
{
    if (!calculix_available()) PHYSREG_MISSING_FIXTURE("ccx (Debian calculix-ccx) is not installed");
    nlohmann::json ranges;
    const TissueTable tissues = draw_ground_truth_tissues(MaterialSet::paper000, phantom_label_roles(), {0, 1, 2, 3, 4, 5, 6}, 7, ranges);
    test::TempDir dir;
    const CalculixValidation v = validate_ground_truth_against_calculix(tissues, 1, 2, dir.path());
    std::cout << v.description << ": " << 100 * v.relative_rms << " % (peak " << v.peak_mm << " mm)\n";
    EXPECT_GT(v.peak_mm, 2.0);      // the punch moved the block
    EXPECT_LT(v.relative_rms, 0.01); // issue 17: ≤ 1 % RMS
}

} // namespace physreg
