// SPDX-License-Identifier: GPL-3.0-or-later
// Glisson's capsule membrane (paper 001): constant-strain triangles, co-rotational, plane stress —
// checked against the energy, rigid motions, finite differences, and the axial stiffness a skin of
// membrane adds to a block in uniaxial tension.
#include "form_cases.hpp"
#include "mechanics_fixtures.hpp"
#include "physreg/mechanics/forms/mechanics_forms.hpp"
#include "physreg/mechanics/implicit/backward_euler.hpp"
#include "physreg/mechanics/elements/membrane.hpp"
#include "physreg/registration/surface/surface_model.hpp"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace physreg {

namespace {
const std::vector<double> triangle_rest = {0, 0, 0, 10, 0, 0, 2, 8, 0};

Membrane one_triangle(const MembraneMaterial& m = {}) { return Membrane({{0, 1, 2}}, triangle_rest, m, "triangle"); }

std::vector<double> forces(const Membrane& membrane, const std::vector<double>& u)
{
    std::vector<double> f(u.size(), 0.0);
    membrane.add_forces(u.data(), f.data());
    return f;
}

// u of the affine motion x ↦ A x + c on the triangle's nodes.
std::vector<double> affine(const Mat3& a, const Vec3& c)
{
    std::vector<double> u(9);
    for (int n = 0; n < 3; ++n) {
        const Vec3 x(triangle_rest[3 * n], triangle_rest[3 * n + 1], triangle_rest[3 * n + 2]);
        const Vec3 d = a * x + c - x;
        for (int k = 0; k < 3; ++k) u[3 * n + k] = d[k];
    }
    return u;
}
} // namespace

TEST(Membrane, UniformStretchGivesThePlaneStressResultantsAndEnergy)
{
    MembraneMaterial m;
    m.young_modulus_pa = 8e6;
    m.poisson_ratio = 0.45;
    m.thickness_mm = 0.1;
    const Membrane membrane = one_triangle(m);
    const double eps = 0.01;
    Mat3 a = Mat3::Identity();
    a(0, 0) += eps; // ε_xx = 0.01, ε_yy = 0
    std::vector<double> u = affine(a, Vec3::Zero());
    std::vector<double> f(9, 0.0);
    const double energy = membrane.add_forces(u.data(), f.data());
    const double e = 8.0, nu = 0.45, t = 0.1, area = 40.0;
    const double nxx = e * t / (1 - nu * nu) * eps; // N/mm
    EXPECT_NEAR(energy, 0.5 * area * nxx * eps, 1e-9 * energy);
    // Nodal forces are A N ∇N_a; their sum vanishes and their moment about x gives N_xx back:
    // Σ_a f_a x_aᵀ = A N (the virial of a uniform stress state).
    Vec3 total = Vec3::Zero();
    double virial_xx = 0.0, virial_yy = 0.0;
    for (int n = 0; n < 3; ++n) {
        total += Vec3(f[3 * n], f[3 * n + 1], f[3 * n + 2]);
        virial_xx += f[3 * n] * triangle_rest[3 * n];
        virial_yy += f[3 * n + 1] * triangle_rest[3 * n + 1];
    }
    EXPECT_LT(total.norm(), 1e-12);
    EXPECT_NEAR(virial_xx, area * nxx, 1e-9);
    EXPECT_NEAR(virial_yy, area * nu * nxx, 1e-9);
}

TEST(Membrane, RigidMotionsCarryNoForceAndRotateTheForcesOfAStretch)
{
    const Membrane membrane = one_triangle();
    const Mat3 r = Eigen::AngleAxisd(0.7, Vec3(1, 2, -1).normalized()).toRotationMatrix();
    for (double v : forces(membrane, affine(r, Vec3(3, -2, 5)))) EXPECT_NEAR(v, 0.0, 1e-12);
    Mat3 stretch = Mat3::Identity();
    stretch(0, 0) = 1.02;
    stretch(1, 1) = 0.99;
    stretch(0, 1) = 0.005;
    stretch(1, 0) = 0.005;
    const auto f0 = forces(membrane, affine(stretch, Vec3::Zero()));
    const auto f1 = forces(membrane, affine(r * stretch, Vec3(1, 1, 1)));
    for (int n = 0; n < 3; ++n) {
        const Vec3 expected = r * Vec3(f0[3 * n], f0[3 * n + 1], f0[3 * n + 2]);
        EXPECT_LT((Vec3(f1[3 * n], f1[3 * n + 1], f1[3 * n + 2]) - expected).norm(), 1e-10);
    }
}

// Force = ∂E/∂x at a rotated, stretched state (measured 6e-9 relative; the rotation's derivative
// drops out of a constant-strain triangle's energy), as a Form run by test_forms.cpp.
const test::RegisterFormCase membrane_stretched{"Membrane", "one triangle rotated and stretched", [] {
    const Membrane membrane = one_triangle();
    const Mat3 r = Eigen::AngleAxisd(0.4, Vec3(0, 1, 1).normalized()).toRotationMatrix();
    Mat3 stretch = Mat3::Identity();
    stretch(0, 0) = 1.01;
    stretch(1, 1) = 1.004;
    std::vector<double> u = affine(r * stretch, Vec3::Zero());
    u[7] += 0.02; // a non-affine bit
    test::FormCheckResult out{check_derivatives(AuxiliaryElementsForm(membrane, 3, "capsule membrane"), u), 1e-6};
    out.expect_hessian = false; // no assembler given: its tangent is checked at rest below
    return out;
}};

// The assembled tangent at rest is the exact derivative of the force there (the force is zero).
const test::RegisterFormCase membrane_at_rest{"Membrane", "tangent at rest on a tetrahedron's face", [] {
    const VolumeMesh tet{CellType::tetrahedron, {Vec3(0, 0, 0), Vec3(10, 0, 0), Vec3(2, 8, 0), Vec3(3, 3, 6)}, {0, 1, 2, 3}, {1}, {}, {}};
    TledOptions options;
    options.law = MaterialLaw::corotational;
    const TledModel model(tet, test::one_tissue(1.0, 0.3), options);
    const std::vector<double> rest = model.rest_positions();
    const Membrane on_tet({{0, 1, 2}}, rest, MembraneMaterial{}, "face");
    const StiffnessAssembler assembler(model, nullptr, on_tet.stencils());
    FiniteDifferenceOptions o;
    o.step = 1e-7;
    test::FormCheckResult out{check_derivatives(AuxiliaryElementsForm(on_tet, 4, "capsule membrane", &assembler), std::vector<double>(12, 0.0), o)};
    out.expect_gradient = false; // at rest the force vanishes
    return out;
}};

TEST(Membrane, ASkinOnALongBlockAddsItsAxialStiffnessInTension)
{
    // Block 40 × 10 × 10 mm (2.5 mm cells split into tetrahedra), soft tissue E = 3.5 kPa, ν = 0.45;
    // the four lateral faces carry a membrane E = 8 MPa, ν = 0.45, t = 0.1 mm. Uniaxial stretch
    // 0.5 % along x, lateral faces free: the axial force is E_t A ε + E_m t P ε (the membrane in
    // uniaxial stress along the block, contracting freely around it), P = 40 mm.
    const double length = 40, width = 10, height = 10, eps = 0.005;
    const VolumeMesh mesh = split_hexahedra_into_tetrahedra(test::block_mesh(16, 4, 4, 2.5));
    TledOptions options;
    options.law = MaterialLaw::corotational;
    const TledModel model(mesh, test::one_tissue(3500.0, 0.45), options);
    std::vector<std::array<std::int32_t, 3>> lateral;
    for (const auto& t : unlabelled_boundary(mesh).triangles) {
        const Vec3 n = (mesh.nodes[t[1]] - mesh.nodes[t[0]]).cross(mesh.nodes[t[2]] - mesh.nodes[t[0]]).normalized();
        if (std::abs(n.x()) < 0.5) lateral.push_back(t);
    }
    ASSERT_EQ(lateral.size(), 4u * 16 * 4 * 2);
    const MembraneMaterial skin{8e6, 0.45, 0.1};
    const Membrane membrane(lateral, model.rest_positions(), skin, "skin");
    EXPECT_NEAR(membrane.total_area_mm2(), 4 * length * width, 1e-9);
    BackwardEulerOptions quasi_static;
    quasi_static.time_step_s = 1e4; // M/Δt negligible: one step is a static solve
    quasi_static.tangent = TangentUpdate::every_iteration;
    quasi_static.residual_tolerance = 1e-9;
    quasi_static.max_newton_iterations = 30;
    const auto axial_force = [&](bool with_skin) {
        BackwardEuler integrator(model, quasi_static, nullptr,
                                 with_skin ? std::vector<const AuxiliaryElements*>{&membrane} : std::vector<const AuxiliaryElements*>{});
        integrator.set_loads(test::uniaxial_loads(mesh, length, width, height, 1 + eps));
        integrator.step();
        const StiffnessAssembler assembler(model);
        std::vector<double> f(3 * mesh.node_count(), 0.0);
        assembler.assemble(integrator.displacement_mm().data(), f.data(), nullptr);
        if (with_skin) membrane.add_forces(integrator.displacement_mm().data(), f.data());
        double sum = 0.0;
        for (auto n : test::nodes_at(mesh, 0, length)) sum += f[3 * n];
        return sum;
    };
    const double tissue = axial_force(false), both = axial_force(true);
    EXPECT_NEAR(tissue, 3.5e-3 * width * height * eps, 0.02 * 3.5e-3 * width * height * eps);
    const double skin_expected = 8.0 * 0.1 * 2 * (width + height) * eps;
    EXPECT_NEAR(both - tissue, skin_expected, 0.03 * skin_expected) << "N";
}

} // namespace physreg
