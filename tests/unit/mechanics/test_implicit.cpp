// SPDX-License-Identifier: GPL-3.0-or-later
// Implicit mechanics: material tangents, the assembled stiffness, contact terms and the Newton
// solver, checked against finite differences (as Forms, run by test_forms.cpp), analytical
// solutions and dynamic relaxation.
#include "form_cases.hpp"
#include "mechanics_fixtures.hpp"
#include "physreg/mechanics/forms/mechanics_forms.hpp"
#include "physreg/core/error.hpp"
#include "physreg/mechanics/implicit/newton_solver.hpp"
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"
#include "physreg/mechanics/coupling/tissue_coupling.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <chrono>
#include <tuple>
#include <cstring>
#include <omp.h>
#include <iostream>
#include <random>

namespace physreg {
using namespace test;

namespace {

// A deformation gradient with no symmetry and J ≈ 1.05.
const double kF[9] = {1.1, 0.2, -0.05, 0.03, 0.93, 0.12, -0.07, 0.04, 1.05};

std::vector<double> random_vector(std::size_t n, double scale, std::uint32_t seed)
{
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> d(-scale, scale);
    std::vector<double> v(n);
    for (auto& x : v) x = d(random);
    return v;
}

double max_abs(const std::vector<double>& v)
{
    double m = 0;
    for (double x : v) m = std::max(m, std::abs(x));
    return m;
}

VolumeMesh distorted(VolumeMesh mesh, double amplitude_mm)
{
    mesh.grid.reset();
    mesh.cell_grid_index.clear();
    const auto shift = random_vector(3 * mesh.node_count(), amplitude_mm, 3);
    for (std::size_t i = 0; i < mesh.node_count(); ++i)
        for (int d = 0; d < 3; ++d) mesh.nodes[i][d] += shift[3 * i + d];
    return mesh;
}

NewtonOptions tight_newton()
{
    NewtonOptions o;
    o.residual_tolerance = 1e-9;
    o.penetration_tolerance_mm = 1e-6;
    return o;
}

} // namespace

// Each law as a Form of F: P = ∂Ψ/∂F and the material tangent ∂P/∂F (test_forms.cpp runs the checker).
FormCheckResult material_law_case(MaterialLaw law)
{
    const ElasticMaterial m = material_from_tissue({1, "t", 2e5, 0.49, 1000});
    FiniteDifferenceOptions o;
    o.random_directions = 3;
    return {check_derivatives(StrainEnergyDensityForm(law, m), std::vector<double>(kF, kF + 9), o), 1e-7, 1e-7};
}
const RegisterFormCase neo_hookean_law{"StrainEnergyDensityForm", "neo-Hookean", [] { return material_law_case(MaterialLaw::neo_hookean); }};
const RegisterFormCase svk_law{"StrainEnergyDensityForm", "St Venant-Kirchhoff", [] { return material_law_case(MaterialLaw::st_venant_kirchhoff); }};
const RegisterFormCase linear_law{"StrainEnergyDensityForm", "linear elastic", [] { return material_law_case(MaterialLaw::linear_elastic); }};
const RegisterFormCase corotational_law{"StrainEnergyDensityForm", "co-rotational", [] { return material_law_case(MaterialLaw::corotational); }};

// The assembled energy, internal forces and tangent of each element and law at strains of ≈ 10 %,
// with no symmetry (distorted meshes).
FormCheckResult elastic_case(const VolumeMesh& mesh, MaterialLaw law)
{
    TledOptions options;
    options.law = law;
    const TledModel model(mesh, one_tissue(2e5, 0.49), options);
    const StiffnessAssembler assembler(model);
    FiniteDifferenceOptions o;
    o.random_directions = 3;
    return {check_derivatives(ElasticForm(assembler), random_vector(3 * model.node_count(), 0.08, 11), o), 1e-6, 1e-6};
}
const VolumeMesh& small_grid()
{
    static const VolumeMesh grid = block_mesh(4, 3, 3, 1.5);
    return grid;
}
const RegisterFormCase elastic_grid{"ElasticForm", "grid hexahedra, neo-Hookean", [] { return elastic_case(small_grid(), MaterialLaw::neo_hookean); }};
const RegisterFormCase elastic_hex_nh{"ElasticForm", "distorted hexahedra, neo-Hookean",
                                      [] { return elastic_case(distorted(small_grid(), 0.2), MaterialLaw::neo_hookean); }};
const RegisterFormCase elastic_hex_svk{"ElasticForm", "distorted hexahedra, SVK",
                                       [] { return elastic_case(distorted(small_grid(), 0.2), MaterialLaw::st_venant_kirchhoff); }};
const RegisterFormCase elastic_tet_nh{"ElasticForm", "tetrahedra, neo-Hookean",
                                      [] { return elastic_case(split_hexahedra_into_tetrahedra(distorted(small_grid(), 0.2)), MaterialLaw::neo_hookean); }};
const RegisterFormCase elastic_tet_linear{"ElasticForm", "tetrahedra, linear",
                                          [] { return elastic_case(split_hexahedra_into_tetrahedra(small_grid()), MaterialLaw::linear_elastic); }};
const RegisterFormCase elastic_tet_corot{"ElasticForm", "tetrahedra, co-rotational",
                                         [] { return elastic_case(split_hexahedra_into_tetrahedra(distorted(small_grid(), 0.2)), MaterialLaw::corotational); }};
const RegisterFormCase elastic_hex_corot{"ElasticForm", "distorted hexahedra, co-rotational",
                                         [] { return elastic_case(distorted(small_grid(), 0.2), MaterialLaw::corotational); }};

TEST(MechanicsImplicit, AssembledTangentIsSymmetric)
{
    // Its agreement with the forces' derivative is the ElasticForm cases of test_forms.cpp.
    for (const auto& [name, mesh, law] : {std::tuple{"tetrahedra, neo-Hookean", split_hexahedra_into_tetrahedra(distorted(small_grid(), 0.2)), MaterialLaw::neo_hookean},
                                          std::tuple{"distorted hexahedra, co-rotational", distorted(small_grid(), 0.2), MaterialLaw::corotational}}) {
        TledOptions options;
        options.law = law;
        const TledModel model(mesh, one_tissue(2e5, 0.49), options);
        const StiffnessAssembler assembler(model);
        const auto u = random_vector(3 * model.node_count(), 0.08, 11);
        SparseMatrix k = assembler.make_matrix();
        std::vector<double> f(u.size());
        EXPECT_LT(assembler.assemble(u.data(), f.data(), &k).inverted_element, 0) << name;
        const SparseMatrix kt = k.transpose();
        EXPECT_LT((k - kt).norm(), 1e-10 * k.norm()) << name << ": the tangent is not symmetric";
    }
}

TEST(MechanicsImplicit, CorotationalLawIsRotationInvariantAndLinearForSmallStrains)
{
    const ElasticMaterial m = material_from_tissue({1, "t", 3500, 0.45, 1000});
    // The polar rotation is a rotation and F = R U with U symmetric positive definite.
    double r[9];
    polar_rotation(kF, r);
    const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> f_map(kF), r_map(r);
    EXPECT_LT((r_map.transpose() * r_map - Mat3::Identity()).norm(), 1e-13);
    EXPECT_NEAR(r_map.determinant(), 1.0, 1e-13);
    const Mat3 u_stretch = r_map.transpose() * f_map;
    EXPECT_LT((u_stretch - u_stretch.transpose()).norm(), 1e-13);
    EXPECT_GT(Eigen::SelfAdjointEigenSolver<Mat3>(u_stretch).eigenvalues().minCoeff(), 0.0);
    // Small strain, no rotation: the linear law to first order.
    const double h = 1e-5;
    double f[9], p_corot[9], p_linear[9];
    for (int k = 0; k < 9; ++k) f[k] = (k % 4 == 0 ? 1.0 : 0.0) + h * (kF[k] - (k % 4 == 0 ? 1.0 : 0.0));
    first_piola_kirchhoff<double>(MaterialLaw::corotational, m.mu_mpa, m.lambda_mpa, m.kappa_mpa, f, p_corot);
    first_piola_kirchhoff<double>(MaterialLaw::linear_elastic, m.mu_mpa, m.lambda_mpa, m.kappa_mpa, f, p_linear);
    double diff = 0, size = 0;
    for (int k = 0; k < 9; ++k) diff = std::max(diff, std::abs(p_corot[k] - p_linear[k])), size = std::max(size, std::abs(p_linear[k]));
    EXPECT_LT(diff, 1e-3 * size); // the difference is O(h²) against O(h)

    // A rigid rotation by 90° (about an oblique axis) of a whole mesh: no elastic force and no
    // energy, for tetrahedra and hexahedra — where the small-strain law gives forces of the order of E.
    const Mat3 q = Eigen::AngleAxisd(M_PI / 2, Vec3(1, 2, 3).normalized()).toRotationMatrix();
    for (const VolumeMesh& mesh : {split_hexahedra_into_tetrahedra(distorted(block_mesh(4, 3, 3, 1.5), 0.2)),
                                   distorted(block_mesh(4, 3, 3, 1.5), 0.2)}) {
        double corotational_force = 0, linear_force = 0;
        for (MaterialLaw law : {MaterialLaw::corotational, MaterialLaw::linear_elastic}) {
            TledOptions options;
            options.law = law;
            const TledModel model(mesh, one_tissue(3500, 0.45), options);
            const StiffnessAssembler assembler(model);
            std::vector<double> u(3 * model.node_count()), force(u.size());
            for (std::size_t i = 0; i < model.node_count(); ++i) {
                const Vec3 x = q * mesh.nodes[i] - mesh.nodes[i];
                for (int d = 0; d < 3; ++d) u[3 * i + d] = x[d];
            }
            const Assembly a = assembler.assemble(u.data(), force.data(), nullptr);
            (law == MaterialLaw::corotational ? corotational_force : linear_force) = max_abs(force);
            if (law == MaterialLaw::corotational) {
                EXPECT_LT(std::abs(a.energy_mj), 1e-16);
            }
        }
        EXPECT_GT(linear_force, 1e-4);
        EXPECT_LT(corotational_force, 1e-12 * linear_force) << "co-rotational force " << corotational_force;
    }
}

// Parenchyma with a stiff cubic inclusion, split and coupled by MLS penalties (paper 000): the
// elastic energy with the coupling's, and the coupling alone.
struct CoupledInclusion {
    TissueTable tissues;
    SplitMesh split;
    CoupledInclusion()
    {
        const auto volume = make_volume({6, 6, 6}, [](int i, int j, int k) -> std::uint16_t {
            return (i >= 2 && i < 4 && j >= 2 && j < 4 && k >= 2 && k < 4) ? 2 : 1;
        });
        tissues.tissues = {{1, "parenchyma", 2e5, 0.49, 1000}, {2, "tumour", 5e6, 0.49, 1000}};
        const VolumeMesh mesh = mesh_label_volume(volume, tissues, {}, "inclusion").mesh;
        split = split_tissue_interfaces(mesh, {{1, TissueGroup::parenchyma}, {2, TissueGroup::tumour}}, CouplingStiffness{5e4, 5e4}, {});
        if (split.coupling.empty()) fail("the inclusion has no coupling");
    }
};
const RegisterFormCase elastic_coupled{"ElasticForm", "hexahedra with a coupled stiff inclusion", [] {
    const CoupledInclusion c;
    const TledModel model(c.split.mesh, c.tissues, {});
    const StiffnessAssembler assembler(model, &c.split.coupling);
    FiniteDifferenceOptions o;
    o.random_directions = 3;
    return FormCheckResult{check_derivatives(ElasticForm(assembler), random_vector(3 * model.node_count(), 0.05, 5), o), 1e-6, 1e-6};
}};
const RegisterFormCase coupling_alone{"CouplingForm", "MLS penalty coupling of a stiff inclusion", [] {
    const CoupledInclusion c;
    FiniteDifferenceOptions o;
    o.step = 1e-4; // quadratic: central differences are exact up to round-off
    return FormCheckResult{check_derivatives(CouplingForm(c.split.coupling), random_vector(3 * c.split.mesh.node_count(), 0.1, 3), o), 1e-8, 1e-8};
}};

// The augmented-Lagrangian contact of nodes inside a sphere, a cylinder and a plane (with curvature).
FormCheckResult contact_case(IndenterShape shape)
{
    Indenter tool;
    tool.radius_mm = 2.0;
    tool.path = {Vec3(0, 0, 0)};
    tool.shape = shape;
    if (shape == IndenterShape::cylinder) tool.axis = Vec3(1, 1, 0).normalized();
    if (shape == IndenterShape::plane) tool.axis = Vec3(0, 0.6, 0.8);
    // Three nodes inside all three tools, one outside with a multiplier (its pressure still acts), one away.
    const std::vector<double> rest{0.4, 0.7, -1.5, -0.3, 0.2, -0.9, 0.5, -0.4, -1.2, 0.1, 0.1, -0.05, 0.0, 0.0, 5.0};
    const ContactForm form(tool, rest, {0, 1, 2, 3, 4}, {0.3, 0.0, 0.1, 0.2, 0.0}, 1.0, 50.0);
    const std::vector<double> u{0.01, -0.02, 0.03, 0.0, 0.01, 0.0, -0.01, 0.0, 0.02, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    FiniteDifferenceOptions o;
    o.piecewise_smooth = true; // a node on the contact's switch
    return {check_derivatives(form, u, o), 1e-6, 1e-6, true, 10};
}
const RegisterFormCase contact_sphere{"ContactForm", "sphere", [] { return contact_case(IndenterShape::sphere); }};
const RegisterFormCase contact_cylinder{"ContactForm", "cylinder", [] { return contact_case(IndenterShape::cylinder); }};
const RegisterFormCase contact_plane{"ContactForm", "plane", [] { return contact_case(IndenterShape::plane); }};

TEST(MechanicsImplicit, ContactTermActsInsideTheToolAndNowhereElse)
{
    // Its derivatives are the ContactForm cases of test_forms.cpp.
    Indenter sphere;
    sphere.radius_mm = 2.0;
    sphere.path = {Vec3(0, 0, 0)};
    const ContactTerm inside = contact_term(sphere, Vec3(0.4, 0.7, -1.5), 1.0, 0.3, 50.0);
    EXPECT_GT(inside.pressure_n, 0.0);
    EXPECT_LT(inside.gap_mm, 0.0);
    // Outside the tool with no multiplier: nothing.
    const ContactTerm away = contact_term(sphere, Vec3(0, 0, 5), 1.0, 0.0, 50.0);
    EXPECT_EQ(away.pressure_n, 0.0);
    EXPECT_EQ(away.energy_mj, 0.0);
}

TEST(MechanicsImplicit, NewtonReproducesTheAnalyticalUniaxialStretch)
{
    // 20 % stretch of a 4 × 2 × 2 mm bar, ν = 0.49: hexahedra and tetrahedra within 0.5 % of the
    // analytical Neo-Hookean stress, in one Newton solve (homogeneous states are exact for both).
    const double length = 4, width = 2, height = 2, stretch = 1.2;
    for (bool tets : {false, true}) {
        VolumeMesh mesh = block_mesh(4, 2, 2, 1.0);
        if (tets) mesh = split_hexahedra_into_tetrahedra(mesh);
        const TledModel model(mesh, one_tissue(2e5, 0.49), {});
        NewtonSolver solver(model, tight_newton());
        solver.set_loads(uniaxial_loads(mesh, length, width, height, stretch));
        const NewtonSummary s = solver.solve_equilibrium(1.0);
        ASSERT_TRUE(s.converged) << s.message;
        EXPECT_LT(s.newton_iterations, 30);
        const auto [lateral, p11] = neo_hookean_uniaxial(stretch, model.materials()[0]);
        const double force = force_x(solver.internal_forces_n(), nodes_at(mesh, 0, length));
        EXPECT_NEAR(force / (width * height), p11, 0.005 * p11) << (tets ? "tetrahedra" : "hexahedra");
        const auto u = solver.displacement_mm();
        const auto corner = node_at(mesh, Vec3(length, width, height));
        EXPECT_NEAR(u[3 * corner + 1], (lateral - 1) * width, 1e-3 * width);
    }
}

TEST(MechanicsImplicit, NewtonAndDynamicRelaxationAgreeUnderASphere)
{
    // A 24 × 24 × 12 mm block (1 mm hexahedra, ν = 0.45) on a fixed base, a 2 mm sphere pressed
    // 1.5 mm into the top, in three tool positions (warm start as along a trajectory).
    const VolumeMesh mesh = block_mesh(24, 24, 12, 1.0);
    const TledModel model(mesh, one_tissue(3e3, 0.45), {});
    const Loads loads = base_held_sphere_press(mesh, 2.0, {Vec3(12, 12, 14), Vec3(12, 12, 12.5)});
    NewtonSolver newton(model, tight_newton());
    newton.set_loads(loads);
    TledSolver<double> relaxation(model);
    relaxation.set_loads(loads);
    EquilibriumOptions dr;
    dr.displacement_tolerance_mm = 1e-6;
    dr.residual_tolerance = 1e-7;
    dr.max_iterations = 400000;
    for (double s : {0.5, 1.0}) {
        const NewtonSummary ns = newton.solve_equilibrium(s);
        ASSERT_TRUE(ns.converged) << ns.message;
        EXPECT_LE(ns.max_penetration_mm, 1e-6);
    }
    const auto start = std::chrono::steady_clock::now();
    const SolveSummary ds = relaxation.solve_equilibrium(dr, 1.0);
    ASSERT_TRUE(ds.converged()) << ds.message;
    std::cout << "dynamic relaxation: " << ds.iterations << " iterations, "
              << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() << " s\n";
    const auto un = newton.displacement_mm(), ud = relaxation.displacement_mm();
    double peak = 0, diff = 0;
    for (std::size_t i = 0; i < un.size(); ++i) {
        peak = std::max(peak, std::abs(ud[i]));
        diff = std::max(diff, std::abs(un[i] - ud[i]));
    }
    EXPECT_GT(peak, 1.4);
    EXPECT_LT(diff, 1e-4 * peak) << "Newton and relaxation differ by " << diff << " mm of a peak " << peak << " mm";
}

TEST(MechanicsImplicit, IterativeSolversMatchTheDirectSolverAlongAToolPath)
{
    const VolumeMesh mesh = block_mesh(12, 12, 6, 1.0);
    const TledModel model(mesh, one_tissue(3e3, 0.45), {});
    const Loads loads = base_held_sphere_press(mesh, 2.0, {Vec3(6, 6, 8), Vec3(6, 6, 7), Vec3(8, 6, 7)});
    std::vector<std::vector<double>> results;
    std::vector<NewtonSummary> summaries;
    for (LinearSolverKind kind : {LinearSolverKind::cholmod, LinearSolverKind::pcg_factor, LinearSolverKind::pcg_amg}) {
        NewtonOptions o = tight_newton();
        o.linear.kind = kind;
        NewtonSolver solver(model, o);
        solver.set_loads(loads);
        NewtonSummary total;
        for (double s : {0.25, 0.5, 0.75, 1.0}) {
            const NewtonSummary ns = solver.solve_equilibrium(s);
            ASSERT_TRUE(ns.converged) << to_string(kind) << ": " << ns.message;
            total.newton_iterations += ns.newton_iterations;
            total.factorisations += ns.factorisations;
            total.linear_iterations += ns.linear_iterations;
            EXPECT_EQ(ns.linear_solver, to_string(kind));
        }
        results.push_back(solver.displacement_mm());
        summaries.push_back(total);
    }
    for (int other : {1, 2}) {
        double diff = 0;
        for (std::size_t i = 0; i < results[0].size(); ++i) diff = std::max(diff, std::abs(results[0][i] - results[other][i]));
        EXPECT_LT(diff, 1e-6) << "solver " << other;
    }
    EXPECT_EQ(summaries[0].factorisations, summaries[0].newton_iterations); // direct: one per iteration
    std::cout << "pcg-amg: " << summaries[2].linear_iterations << " CG iterations over " << summaries[2].newton_iterations
              << " Newton iterations\n";
    EXPECT_GT(summaries[2].linear_iterations, summaries[2].newton_iterations);
    EXPECT_LT(summaries[1].factorisations, summaries[1].newton_iterations / 2) << "the stale factor was renewed too often";
    EXPECT_GT(summaries[1].linear_iterations, 0);
}

namespace {
// The tangent at rest of a block held at its base (identity rows there) and a downward load on
// the free nodes: a symmetric positive definite system for the linear solvers.
std::pair<SparseMatrix, Eigen::VectorXd> held_block_system(const TledModel& model, const VolumeMesh& mesh)
{
    const StiffnessAssembler assembler(model);
    SparseMatrix k = assembler.make_matrix();
    std::vector<double> u(3 * model.node_count(), 0.0), f(u.size());
    assembler.assemble(u.data(), f.data(), &k);
    std::vector<char> fixed(k.cols(), 0);
    for (auto n : nodes_at(mesh, 2, 0.0))
        for (int d = 0; d < 3; ++d) fixed[3 * n + d] = 1;
    for (Eigen::Index c = 0; c < k.cols(); ++c)
        for (SparseMatrix::InnerIterator it(k, c); it; ++it)
            if (fixed[c] || fixed[it.row()]) it.valueRef() = it.row() == c ? 1.0 : 0.0;
    Eigen::VectorXd b = Eigen::VectorXd::Zero(k.cols());
    for (Eigen::Index i = 2; i < k.cols(); i += 3)
        if (!fixed[i]) b[i] = -1e-4;
    return {std::move(k), std::move(b)};
}
} // namespace

TEST(MechanicsImplicit, AlgebraicMultigridSolvesLikeCholesky)
{
    // One tangent of a base-held block, solved by CHOLMOD and by CG + BoomerAMG with and without
    // the rigid rotations in the interpolation; and an unconverged AMG solve is an error.
    const VolumeMesh mesh = block_mesh(8, 8, 4, 1.0);
    const TledModel model(mesh, one_tissue(3e3, 0.45), {});
    const auto [k, b] = held_block_system(model, mesh);
    Eigen::VectorXd reference, x;
    SymmetricSolver direct({LinearSolverKind::cholmod});
    direct.solve(k, b, reference);
    for (bool rigid_modes : {false, true}) {
        LinearSolverOptions o;
        o.kind = LinearSolverKind::pcg_amg;
        o.amg_rigid_modes = rigid_modes;
        SymmetricSolver amg(o);
        amg.set_node_coordinates(model.rest_positions());
        const LinearSolveStats st = amg.solve(k, b, x);
        EXPECT_GT(st.iterations, 0);
        EXPECT_LT((x - reference).norm(), 1e-7 * reference.norm()) << "rigid modes " << rigid_modes;
    }
    LinearSolverOptions starved;
    starved.kind = LinearSolverKind::pcg_amg;
    starved.amg_max_iterations = 2;
    SymmetricSolver amg(starved);
    EXPECT_NE(error_message([&] { amg.solve(k, b, x); }).find("pcg-amg"), std::string::npos);
}

TEST(MechanicsImplicit, CholeskyGivesTheSameBitsOnAnyThreadAndConcurrently)
{
    // The factor and its solution do not depend on where the factorisation runs: outside any
    // parallel region, inside one, or two solvers analysing and factorising at the same time
    // (METIS's ordering draws from a global random state; the analyses take turns).
    const VolumeMesh mesh = block_mesh(10, 10, 8, 1.0);
    const TledModel model(mesh, one_tissue(3e3, 0.45), {});
    const auto [k, b] = held_block_system(model, mesh);
    const auto solve = [&] {
        SymmetricSolver s({LinearSolverKind::cholmod});
        Eigen::VectorXd x;
        s.solve(k, b, x);
        return x;
    };
    const Eigen::VectorXd outside = solve();
    ASSERT_GT(outside.norm(), 0.0);
    Eigen::VectorXd concurrent[2];
#pragma omp parallel num_threads(2)
    concurrent[omp_get_thread_num()] = solve();
    for (const auto& x : concurrent) {
        ASSERT_EQ(x.size(), outside.size());
        EXPECT_EQ(std::memcmp(x.data(), outside.data(), sizeof(double) * static_cast<std::size_t>(x.size())), 0);
    }
}

TEST(MechanicsImplicit, BadInputAndFailuresAreReported)
{
    const VolumeMesh mesh = block_mesh(4, 4, 2, 1.0);
    const TledModel model(mesh, one_tissue(3e3, 0.45), {});
    // Nothing fixed: six free rigid-body modes.
    {
        NewtonSolver solver(model);
        Loads loads;
        loads.external_forces_n.assign(3 * model.node_count(), 0.0);
        loads.external_forces_n[2] = 1e-3;
        solver.set_loads(loads);
        EXPECT_NE(error_message([&] { solver.solve_equilibrium(1.0); }).find("not constrained: 6 rigid-body mode"), std::string::npos);
    }
    // One node held: three rotations free.
    {
        NewtonSolver solver(model);
        Loads loads;
        loads.constraints.push_back({"pin", {0}, {true, true, true}, Vec3::Zero()});
        solver.set_loads(loads);
        EXPECT_NE(error_message([&] { solver.solve_equilibrium(1.0); }).find("3 rigid-body mode"), std::string::npos);
    }
    // Too few iterations and no load cuts: not converged, with the residual history.
    {
        NewtonOptions o;
        o.max_iterations = 1;
        o.max_load_cuts = 0;
        NewtonSolver solver(model, o);
        Loads loads;
        loads.constraints.push_back({"base", nodes_at(mesh, 2, 0.0), {true, true, true}, Vec3::Zero()});
        loads.constraints.push_back({"top", nodes_at(mesh, 2, 2.0), {true, true, true}, Vec3(0.3, 0, -0.5)});
        solver.set_loads(loads);
        const NewtonSummary s = solver.solve_equilibrium(1.0);
        EXPECT_FALSE(s.converged);
        EXPECT_NE(s.message.find("residual history"), std::string::npos) << s.message;
        EXPECT_EQ(max_abs(solver.displacement_mm()), 0.0) << "the state must stay at the last equilibrium";
    }
    // Crushing a block through itself inverts elements: an Error naming the element.
    {
        NewtonOptions o;
        o.max_load_cuts = 2;
        NewtonSolver solver(model, o);
        Loads loads;
        loads.constraints.push_back({"base", nodes_at(mesh, 2, 0.0), {true, true, true}, Vec3::Zero()});
        loads.constraints.push_back({"top", nodes_at(mesh, 2, 2.0), {true, true, true}, Vec3(0, 0, -2.5)});
        solver.set_loads(loads);
        EXPECT_NE(error_message([&] { solver.solve_equilibrium(1.0); }).find("element"), std::string::npos);
    }
    // The averaged-nodal-pressure tetrahedron has no tangent.
    {
        TledOptions anp;
        anp.averaged_nodal_pressure = true;
        const TledModel tets(split_hexahedra_into_tetrahedra(mesh), one_tissue(3e3, 0.45), anp);
        EXPECT_NE(error_message([&] { NewtonSolver solver(tets); }).find("averaged-nodal-pressure"), std::string::npos);
    }
}

} // namespace physreg
