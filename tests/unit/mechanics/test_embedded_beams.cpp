// SPDX-License-Identifier: GPL-3.0-or-later
// Paper 001's vessel beams: Timoshenko elements embedded in tetrahedra — the element matrix, rigid
// motions, a cantilever against Timoshenko's deflection, and the centreline files.
// GCC 12's own AVX-512 header (avx512fintrin.h, _mm512_extractf64x4_pd) warns "__Y is used
// uninitialized" when Eigen's 12 × 12 norm below is inlined into this test: the header's code, not ours.
#pragma GCC diagnostic ignored "-Wuninitialized"
#include "form_cases.hpp"
#include "mechanics_fixtures.hpp"
#include "physreg/mechanics/forms/mechanics_forms.hpp"
#include "physreg/mechanics/implicit/backward_euler.hpp"
#include "physreg/mechanics/elements/embedded_beams.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <fstream>
#include <iostream>
#include <gtest/gtest.h>
#include <numbers>

namespace physreg {

TEST(EmbeddedBeams, TimoshenkoElementHasSixRigidModesAndTheCantileverCompliance)
{
    const BeamMaterial m{620e3, 0.4, 0.9};
    const double l = 10.0, r = 1.0;
    const auto k = EmbeddedBeams::timoshenko_stiffness(l, r, m);
    EXPECT_LT((k - k.transpose()).norm(), 1e-12 * k.norm());
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 12, 12>> eig(k);
    int zero = 0;
    for (int i = 0; i < 12; ++i) {
        EXPECT_GT(eig.eigenvalues()[i], -1e-10 * eig.eigenvalues().maxCoeff());
        zero += eig.eigenvalues()[i] < 1e-10 * eig.eigenvalues().maxCoeff();
    }
    EXPECT_EQ(zero, 6);
    // Node 0 clamped, a transverse tip load P along y: δ = P l³/(3EI) + P l/(κGA), both planes.
    const Eigen::Matrix<double, 6, 6> free = k.bottomRightCorner<6, 6>();
    Eigen::Matrix<double, 6, 1> load = Eigen::Matrix<double, 6, 1>::Zero();
    load[1] = 1e-3;
    load[2] = 1e-3;
    const Eigen::Matrix<double, 6, 1> d = free.ldlt().solve(load);
    const double e = 0.62, g = e / 2.8, inertia = std::numbers::pi / 4, area = std::numbers::pi;
    const double expected = 1e-3 * l * l * l / (3 * e * inertia) + 1e-3 * l / (0.9 * g * area);
    EXPECT_NEAR(d[1], expected, 1e-9 * expected);
    EXPECT_NEAR(d[2], expected, 1e-9 * expected);
    EXPECT_NEAR(d[5], 1e-3 * l * l / (2 * e * inertia), 1e-9);  // tip rotation θz = P l²/(2EI)
    EXPECT_NEAR(d[4], -1e-3 * l * l / (2 * e * inertia), 1e-9); // θy turns the other way for +z
}

namespace {
// A bar 100 × 12 × 12 mm of soft tetrahedra with a vessel along its axis (off the grid planes).
struct Bar {
    VolumeMesh mesh = split_hexahedra_into_tetrahedra(test::block_mesh(50, 6, 6, 2.0));
    std::vector<VesselBranch> vessel{{{Vec3(0.01, 5.9, 6.1), Vec3(99.99, 5.9, 6.1)}, {1.0, 1.0}}};
};
} // namespace

// The beams' forces are ∂E/∂u of their co-rotational energy (to the co-rotational approximation:
// the frame's derivative is left out) on a bent, twisted bar, and their tangent at rest is exact:
// Forms run by test_forms.cpp.
const test::RegisterFormCase beams_bent{"EmbeddedBeams", "a vessel in a bent bar", [] {
    const Bar bar;
    const EmbeddedBeams beams(bar.mesh, bar.vessel, BeamMaterial{}, 2.0, "bar vessel");
    std::vector<double> u(3 * bar.mesh.node_count());
    for (std::size_t n = 0; n < bar.mesh.node_count(); ++n) {
        const Vec3& x = bar.mesh.nodes[n];
        const double s = x.x() / 100.0;
        u[3 * n + 1] = 0.8 * s * s + 0.01 * std::sin(1.7 * static_cast<double>(n)); // bending, and a rough part
        u[3 * n + 2] = 0.05 * s * (x.y() - 6.0);                                   // a twist
    }
    test::FormCheckResult out{check_derivatives(AuxiliaryElementsForm(beams, bar.mesh.node_count(), "vessel beams"), u), 5e-4}; // measured 7e-5
    out.expect_hessian = false; // no assembler given: the tangent is checked at rest below
    return out;
}};
const test::RegisterFormCase beams_at_rest{"EmbeddedBeams", "tangent at rest", [] {
    const Bar bar;
    const EmbeddedBeams beams(bar.mesh, bar.vessel, BeamMaterial{}, 2.0, "bar vessel");
    TledOptions options;
    options.law = MaterialLaw::corotational;
    const TledModel model(bar.mesh, test::one_tissue(6.2, 0.3), options);
    const StiffnessAssembler assembler(model, nullptr, beams.stencils());
    test::FormCheckResult out{check_derivatives(AuxiliaryElementsForm(beams, bar.mesh.node_count(), "vessel beams", &assembler),
                                                std::vector<double>(3 * bar.mesh.node_count(), 0.0)),
                              1e-6, 1e-5}; // measured 2.6e-7 (round-off of 7 500 unknowns)
    out.expect_gradient = false; // at rest the force vanishes
    return out;
}};

TEST(EmbeddedBeams, RigidMotionsOfTheHostCarryNoBeamForce)
{
    const Bar bar;
    const EmbeddedBeams beams(bar.mesh, bar.vessel, BeamMaterial{}, 2.0, "bar vessel");
    EXPECT_EQ(beams.dropped_elements(), 0u);
    EXPECT_NEAR(beams.total_length_mm(), 99.98, 1e-9);
    const Mat3 r = Eigen::AngleAxisd(0.9, Vec3(1, -2, 0.5).normalized()).toRotationMatrix();
    std::vector<double> u(3 * bar.mesh.node_count()), f(u.size(), 0.0);
    for (std::size_t n = 0; n < bar.mesh.node_count(); ++n) {
        const Vec3 d = r * bar.mesh.nodes[n] + Vec3(4, -3, 7) - bar.mesh.nodes[n];
        for (int k = 0; k < 3; ++k) u[3 * n + k] = d[k];
    }
    EXPECT_NEAR(beams.add_forces(u.data(), f.data()), 0.0, 1e-12); // mJ (round-off of w = Rᵀ x − X)
    for (double v : f) EXPECT_NEAR(v, 0.0, 1e-12);
}

TEST(EmbeddedBeams, AVesselInASoftBarBendsLikeATimoshenkoCantilever)
{
    // The bar (E 6.2 Pa: its own bending stiffness E I = 0.0107 N·mm² is 2 % of the vessel's 0.487)
    // is clamped on its first
    // 4 mm and carries a transverse load P at its free end; the embedded vessel (E 620 kPa, r 1 mm)
    // takes it. A beam node's rotation is that of its tetrahedron, so a clamp holds the vessel only
    // where whole tetrahedra are held: the root is at x = 4 mm, the free length 96 mm.
    const Bar bar;
    const BeamMaterial vessel{620e3, 0.4, 0.9};
    const EmbeddedBeams beams(bar.mesh, bar.vessel, vessel, 2.0, "bar vessel");
    TledOptions options;
    options.law = MaterialLaw::corotational;
    const TledModel model(bar.mesh, test::one_tissue(6.2, 0.3), options);
    BackwardEulerOptions quasi_static;
    quasi_static.time_step_s = 1e4;
    quasi_static.tangent = TangentUpdate::every_iteration;
    quasi_static.residual_tolerance = 1e-7;
    quasi_static.rotated_corotational_tangent = false; // the exact tangent of the tetrahedra: quadratic convergence
    quasi_static.max_newton_iterations = 30;
    BackwardEuler integrator(model, quasi_static, nullptr, {&beams});
    Loads loads;
    std::vector<std::int32_t> clamp;
    for (double x : {0.0, 2.0, 4.0})
        for (auto n : test::nodes_at(bar.mesh, 0, x)) clamp.push_back(n);
    loads.constraints.push_back({"clamp", clamp, {true, true, true}, Vec3::Zero()});
    const double p = 2e-6; // N, a small deflection (linear range)
    const auto end = test::nodes_at(bar.mesh, 0, 100.0);
    loads.external_forces_n.assign(3 * bar.mesh.node_count(), 0.0);
    for (auto n : end) loads.external_forces_n[3 * n + 1] = p / static_cast<double>(end.size());
    integrator.set_loads(loads);
    integrator.step();
    double deflection = 0.0;
    for (auto n : end) deflection += integrator.displacement_mm()[3 * n + 1] / static_cast<double>(end.size());
    const double e = 0.62, g = e / 2.8, inertia = std::numbers::pi / 4, area = std::numbers::pi, l = 96.0;
    const double bar_ei = 6.2e-6 * std::pow(12.0, 4) / 12;
    const double timoshenko = p * l * l * l / (3 * (e * inertia + bar_ei)) + p * l / (0.9 * g * area);
    EXPECT_NEAR(deflection, timoshenko, 0.08 * timoshenko) << "mm; Timoshenko " << timoshenko;
    std::cout << "embedded cantilever: tip deflection " << deflection << " mm, Timoshenko " << timoshenko << " mm\n";
    // Without the vessel the bar alone is ~45× softer: a thousandth of the load bends it by more than a 30th.
    BackwardEuler alone(model, quasi_static);
    for (double& v : loads.external_forces_n) v *= 1e-3;
    alone.set_loads(loads);
    alone.step();
    EXPECT_GT(alone.displacement_mm()[3 * end[0] + 1], deflection / 30);
}

TEST(EmbeddedBeams, CentrelineFilesReadBackAndBadOnesAreRefused)
{
    const test::TempDir dir;
    const std::vector<VesselBranch> tree{{{Vec3(0, 0, 0), Vec3(10, 0, 0), Vec3(20, 5, 0)}, {3, 2.5, 2}}, {{Vec3(10, 0, 0), Vec3(10, 10, 0)}, {1.5, 1}}};
    write_vessel_centrelines(dir / "tree.csv", tree);
    const auto back = read_vessel_centrelines(dir / "tree.csv", 1.0, 1.0);
    ASSERT_EQ(back.size(), 2u);
    EXPECT_EQ(back[0].points.size(), 3u);
    EXPECT_NEAR(back[1].radii_mm[1], 1.0, 1e-12);
    std::ofstream(dir / "skeleton.txt") << "0.01 0.02 0.03\n0.02 0.02 0.03\n\n0.05 0 0\n0.06 0 0\n0.07 0 0\n";
    const auto skeleton = read_vessel_centrelines(dir / "skeleton.txt", 1000.0, 1.5);
    ASSERT_EQ(skeleton.size(), 2u);
    EXPECT_NEAR(skeleton[0].points[1].x(), 20.0, 1e-9);
    EXPECT_NEAR(skeleton[1].radii_mm[2], 1.5, 1e-12);
    std::ofstream(dir / "bad.txt") << "0 0 0\n1 1 nan\n";
    EXPECT_NE(test::error_message([&] { read_vessel_centrelines(dir / "bad.txt", 1.0, 1.0); }).find("not a finite number"), std::string::npos);
    std::ofstream(dir / "single.txt") << "0 0 0\n\n1 1 1\n2 2 2\n";
    EXPECT_NE(test::error_message([&] { read_vessel_centrelines(dir / "single.txt", 1.0, 1.0); }).find("single point"), std::string::npos);
    const Bar bar;
    const std::vector<VesselBranch> outside{{{Vec3(200, 0, 0), Vec3(300, 0, 0)}, {1, 1}}};
    EXPECT_NE(test::error_message([&] { EmbeddedBeams(bar.mesh, outside, BeamMaterial{}, 2.0, "far vessel"); }).find("no vessel segment lies inside"),
              std::string::npos);
}

} // namespace physreg
