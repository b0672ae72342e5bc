// SPDX-License-Identifier: GPL-3.0-or-later
// Co-rotational tetrahedra and backward Euler dynamics: a cantilever under gravity against
// Euler–Bernoulli theory, the exact discrete rigid motion of a free body, energy decay under
// Rayleigh damping, mass matrices, and the errors of bad input.
#include "mechanics_fixtures.hpp"
#include "physreg/core/error.hpp"
#include "physreg/mechanics/implicit/backward_euler.hpp"
#include "physreg/mechanics/implicit/newton_solver.hpp"

#include <gtest/gtest.h>

#include <iostream>

namespace physreg {
using namespace test;

namespace {

TissueTable beam_tissue(double young_pa, double nu, double density_kg_m3)
{
    TissueTable t;
    t.tissues = {{1, "beam", young_pa, nu, density_kg_m3}};
    return t;
}

// A length × side × side beam along x, grid hexahedra nl × nt × nt.
VolumeMesh beam_mesh(int nl, int nt, double length, double side)
{
    const Vec3 spacing(length / nl, side / nt, side / nt);
    const auto volume = make_volume({nl, nt, nt}, [](int, int, int) { return std::uint16_t(1); }, spacing, spacing / 2);
    return mesh_label_volume(volume, beam_tissue(1e5, 0.3, 1000), {}, "beam").mesh;
}

// Gravity as nodal forces (lumped mass × g), for the static solver.
std::vector<double> gravity_forces(const TledModel& model, const Vec3& g)
{
    std::vector<double> f(3 * model.node_count());
    for (std::size_t i = 0; i < model.node_count(); ++i)
        for (int d = 0; d < 3; ++d) f[3 * i + d] = model.lumped_mass()[i] * g[d];
    return f;
}

// Mean z displacement of the nodes of the free end x = L.
double tip_deflection(const VolumeMesh& mesh, const std::vector<double>& u, double length)
{
    const auto tip = nodes_at(mesh, 0, length);
    double sum = 0;
    for (auto n : tip) sum += u[3 * n + 2];
    return sum / static_cast<double>(tip.size());
}

// A co-rotational beam of nx × 2 × 2 hexahedra of 5 mm split into tetrahedra, clamped at x = 0.
struct ClampedBeam {
    VolumeMesh mesh;
    TledModel model;
    Loads loads;
    ClampedBeam(int nx, double young_pa, double nu)
        : mesh(split_hexahedra_into_tetrahedra(block_mesh(nx, 2, 2, 5.0))), model(mesh, beam_tissue(young_pa, nu, 1000), [] {
              TledOptions options;
              options.law = MaterialLaw::corotational;
              return options;
          }())
    {
        loads.constraints.push_back({"clamp", nodes_at(mesh, 0, 0.0), {true, true, true}, Vec3::Zero()});
    }
};

} // namespace

TEST(CorotationalTetrahedra, CantileverUnderGravityMatchesEulerBernoulli)
{
    // A 100 × 10 × 10 mm cantilever (E = 100 MPa, ν = 0, ρ = 1000 kg/m³) clamped at x = 0, under
    // gravity −z: Euler–Bernoulli tip deflection q L⁴ / (8 E I), q = ρ g A. The deflection is
    // 0.15 % of the length (linear regime); Timoshenko's shear term adds 4EI/(κGAL²) = 0.8 %.
    const double length = 100, side = 10, e_pa = 1e8, rho = 1000, g = 9810;
    const double q = rho * 1e-12 * g * side * side;                 // N/mm
    const double ei = e_pa * 1e-6 * side * side * side * side / 12; // N·mm²
    const double euler_bernoulli = q * std::pow(length, 4) / (8 * ei);
    const double timoshenko = euler_bernoulli * (1 + 4 * ei / (5.0 / 6.0 * e_pa * 1e-6 / 2 * side * side * length * length));
    std::vector<double> errors;
    for (int refinement : {1, 2}) { // 10 × 1 × 1 mm, then 0.5 × 1 × 1 mm hexahedra, 6 tetrahedra each
        const VolumeMesh mesh = split_hexahedra_into_tetrahedra(beam_mesh(100 * refinement, 10, length, side));
        TledOptions options;
        options.law = MaterialLaw::corotational;
        const TledModel model(mesh, beam_tissue(e_pa, 0.0, rho), options);
        NewtonSolver solver(model);
        Loads loads;
        loads.constraints.push_back({"clamp", nodes_at(mesh, 0, 0.0), {true, true, true}, Vec3::Zero()});
        loads.external_forces_n = gravity_forces(model, Vec3(0, 0, -g));
        solver.set_loads(loads);
        const NewtonSummary summary = solver.solve_equilibrium(1.0);
        ASSERT_TRUE(summary.converged) << summary.message;
        const double deflection = -tip_deflection(mesh, solver.displacement_mm(), length);
        errors.push_back(deflection / euler_bernoulli - 1);
        std::cout << "cantilever: " << model.element_count() << " tetrahedra, tip deflection " << deflection << " mm; Euler-Bernoulli "
                  << euler_bernoulli << " mm (" << 100 * errors.back() << " %), Timoshenko " << timoshenko << " mm; "
                  << summary.newton_iterations << " Newton iterations\n";
    }
    // Linear tetrahedra are too stiff in bending; the error shrinks with the mesh size.
    EXPECT_LT(std::abs(errors[1]), 0.75 * std::abs(errors[0]));
    EXPECT_LT(std::abs(errors[1]), 0.02);
}

TEST(CorotationalTetrahedra, AnInvertedElementIsPushedBack)
{
    // One tetrahedron whose apex is pushed 2 mm through its base: the co-rotational law (rotation
    // from the SVD with the smallest singular value negated) keeps the element in the solve, with a
    // force that lifts the apex back, and a tangent that is still the derivative of the force.
    VolumeMesh mesh;
    mesh.cell_type = CellType::tetrahedron;
    mesh.nodes = {Vec3(0, 0, 0), Vec3(10, 0, 0), Vec3(0, 10, 0), Vec3(0, 0, 10)};
    mesh.cells = {0, 1, 2, 3};
    mesh.cell_labels = {1};
    TledOptions options;
    options.law = MaterialLaw::corotational;
    const TledModel model(mesh, beam_tissue(3500, 0.45, 1000), options);
    const StiffnessAssembler assembler(model);
    std::vector<double> u(12, 0.0), f(12), fp(12), fm(12);
    u[11] = -12.0;
    u[9] = 1.0; // and sideways, so the state has no symmetry
    SparseMatrix k = assembler.make_matrix();
    const Assembly a = assembler.assemble(u.data(), f.data(), &k);
    EXPECT_EQ(a.inverted_element, -1);
    EXPECT_EQ(a.inverted_tolerated, 1);
    EXPECT_TRUE(std::isfinite(a.energy_mj));
    EXPECT_LT(f[11], 0.0) << "internal force on the apex " << f[11] << " N: the restoring force −f must point up";
    const double h = 1e-6;
    double worst = 0, largest = 0;
    for (int c = 0; c < 12; ++c) {
        std::vector<double> up = u, um = u;
        up[c] += h;
        um[c] -= h;
        assembler.assemble(up.data(), fp.data(), nullptr);
        assembler.assemble(um.data(), fm.data(), nullptr);
        for (int r = 0; r < 12; ++r) {
            worst = std::max(worst, std::abs(k.coeff(r, c) - (fp[r] - fm[r]) / (2 * h)));
            largest = std::max(largest, std::abs(k.coeff(r, c)));
        }
    }
    EXPECT_LT(worst, 1e-6 * largest);
}

TEST(BackwardEuler, FreeBodyUnderGravityFallsWithTheExactDiscreteMotion)
{
    // No constraint (paper 001's registration has none): backward Euler gives v_n = n g Δt and
    // u_n = g Δt² n (n + 1) / 2 for every node, with no strain, for either mass matrix.
    const VolumeMesh mesh = split_hexahedra_into_tetrahedra(block_mesh(3, 3, 2, 5.0));
    TledOptions options;
    options.law = MaterialLaw::corotational;
    const TledModel model(mesh, beam_tissue(3500, 0.45, 1000), options);
    for (MassKind mass : {MassKind::lumped, MassKind::consistent}) {
        BackwardEulerOptions be;
        be.time_step_s = 0.01;
        be.mass = mass;
        be.residual_tolerance = 1e-10;
        BackwardEuler integrator(model, be);
        const Vec3 g(0, -9810, 0);
        integrator.set_body_acceleration(g);
        const int steps = 10;
        for (int s = 0; s < steps; ++s) integrator.step();
        const double expected = g[1] * be.time_step_s * be.time_step_s * steps * (steps + 1) / 2;
        double worst = 0;
        for (std::size_t i = 0; i < model.node_count(); ++i) {
            worst = std::max(worst, std::abs(integrator.displacement_mm()[3 * i + 1] - expected));
            worst = std::max(worst, std::abs(integrator.displacement_mm()[3 * i]) + std::abs(integrator.displacement_mm()[3 * i + 2]));
        }
        EXPECT_LT(worst, 1e-9 * std::abs(expected)) << to_string(mass);
        EXPECT_NEAR(integrator.velocity_mm_s()[1], g[1] * be.time_step_s * steps, 1e-9 * std::abs(g[1]));
        EXPECT_LT(integrator.strain_energy_mj(), 1e-12);
    }
}

TEST(BackwardEuler, MassMatricesCarryTheBodysMass)
{
    for (const VolumeMesh& mesh : {block_mesh(3, 2, 2, 2.0), split_hexahedra_into_tetrahedra(block_mesh(3, 2, 2, 2.0))}) {
        const TledModel model(mesh, beam_tissue(3500, 0.45, 1000), {});
        const StiffnessAssembler assembler(model);
        const double mass = 1e-12 * 1000 * 6 * 4 * 4; // tonne
        for (MassKind kind : {MassKind::lumped, MassKind::consistent}) {
            const SparseMatrix m = assemble_mass_matrix(assembler, kind);
            // Total mass along each axis: 1ᵀ M 1 restricted to one component.
            Eigen::VectorXd ones_x = Eigen::VectorXd::Zero(m.cols());
            for (Eigen::Index i = 0; i < m.cols(); i += 3) ones_x[i] = 1;
            EXPECT_NEAR(ones_x.dot(m * ones_x), mass, 1e-12 * mass) << to_string(kind);
            EXPECT_LT((m - SparseMatrix(m.transpose())).norm(), 1e-15 * m.norm());
        }
    }
}

TEST(BackwardEuler, RayleighDampingMakesTheEnergyDecay)
{
    // A cantilever released from its gravity-loaded equilibrium (gravity switched off) vibrates;
    // the total energy (kinetic + strain) never grows, and mass + stiffness damping take away
    // more than backward Euler's own numerical dissipation.
    const ClampedBeam beam(20, 1e6, 0.3);
    const VolumeMesh& mesh = beam.mesh;
    const TledModel& model = beam.model;
    const Loads& loads = beam.loads;
    NewtonSolver statics(model);
    Loads loaded = loads;
    loaded.external_forces_n = gravity_forces(model, Vec3(0, 0, -2000));
    statics.set_loads(loaded);
    ASSERT_TRUE(statics.solve_equilibrium(1.0).converged);
    const auto start = statics.displacement_mm();
    ASSERT_GT(-tip_deflection(mesh, start, 100), 1.0);

    std::vector<double> final_energy;
    for (double damping : {0.0, 1.0}) {
        BackwardEulerOptions be;
        be.time_step_s = 2e-3; // the first bending period is ≈ 0.1 s
        be.rayleigh_mass_per_s = 2.0 * damping;
        be.rayleigh_stiffness_s = 1e-3 * damping;
        BackwardEuler integrator(model, be);
        integrator.set_loads(loads);
        integrator.set_state(start, std::vector<double>(start.size(), 0.0));
        double energy = integrator.strain_energy_mj();
        const double initial = energy;
        bool monotone = true;
        for (int s = 0; s < 150; ++s) {
            integrator.step();
            const double now = integrator.kinetic_energy_mj() + integrator.strain_energy_mj();
            if (now > energy * (1 + 1e-9)) monotone = false;
            energy = now;
        }
        EXPECT_TRUE(monotone) << "damping " << damping;
        EXPECT_LT(energy, initial);
        final_energy.push_back(energy / initial);
    }
    std::cout << "energy left after 0.3 s: undamped " << final_energy[0] << ", Rayleigh " << final_energy[1] << "\n";
    EXPECT_LT(final_energy[1], 0.5 * final_energy[0]);
}

TEST(BackwardEuler, StaleTangentFollowsTheExactNewtonTrajectory)
{
    // A soft co-rotational block swinging under gravity with large rotation: the chord iterations
    // on an old factor and full Newton converge to the same steps.
    const ClampedBeam beam(8, 1e4, 0.45);
    const VolumeMesh& mesh = beam.mesh;
    const TledModel& model = beam.model;
    const Loads& loads = beam.loads;
    std::vector<std::vector<double>> finals;
    std::vector<int> factorisations;
    for (TangentUpdate update : {TangentUpdate::every_iteration, TangentUpdate::stale}) {
        BackwardEulerOptions be;
        be.time_step_s = 5e-3;
        be.tangent = update;
        be.rotated_corotational_tangent = false; // the exact tangent: every-iteration is then Newton's method
        be.residual_tolerance = 1e-9;
        BackwardEuler integrator(model, be);
        integrator.set_loads(loads);
        integrator.set_body_acceleration(Vec3(0, 0, -9810));
        for (int s = 0; s < 40; ++s) integrator.step();
        finals.push_back(integrator.displacement_mm());
        factorisations.push_back(integrator.total_factorisations());
    }
    const double tip = -tip_deflection(mesh, finals[0], 40);
    std::cout << "swinging block: tip " << tip << " mm; factorisations: exact Newton " << factorisations[0] << ", stale " << factorisations[1]
              << "\n";
    EXPECT_GT(tip, 5.0); // a large motion
    double diff = 0;
    for (std::size_t i = 0; i < finals[0].size(); ++i) diff = std::max(diff, std::abs(finals[0][i] - finals[1][i]));
    EXPECT_LT(diff, 1e-5 * tip);
    EXPECT_LT(factorisations[1], factorisations[0] / 2);
}

TEST(BackwardEuler, BadInputIsRefused)
{
    const VolumeMesh mesh = split_hexahedra_into_tetrahedra(block_mesh(2, 2, 2, 5.0));
    const TledModel model(mesh, beam_tissue(3500, 0.45, 1000), {});
    BackwardEulerOptions bad;
    bad.time_step_s = -1;
    EXPECT_THROW(BackwardEuler(model, bad), Error);
    bad = {};
    bad.rayleigh_mass_per_s = std::nan("");
    EXPECT_THROW(BackwardEuler(model, bad), Error);
    BackwardEuler integrator(model, {});
    Loads with_tool;
    Indenter tool;
    tool.name = "probe";
    tool.radius_mm = 1;
    tool.path = {Vec3::Zero()};
    with_tool.indenters.push_back(tool);
    EXPECT_NE(error_message([&] { integrator.set_loads(with_tool); }).find("indenters ('probe')"), std::string::npos);
    EXPECT_NE(error_message([&] { integrator.set_body_acceleration(Vec3(0, std::nan(""), 0)); }).find("not finite"), std::string::npos);
    TledOptions scaled;
    scaled.density_scale = 100;
    const TledModel scaled_model(mesh, beam_tissue(3500, 0.45, 1000), scaled);
    EXPECT_NE(error_message([&] { BackwardEuler(scaled_model, {}); }).find("density_scale"), std::string::npos);
    // A huge step under a huge load: an error (an inverted element or no convergence), not a NaN state.
    BackwardEulerOptions big;
    big.time_step_s = 10;
    BackwardEuler crushed(model, big);
    Loads clamp;
    clamp.constraints.push_back({"clamp", nodes_at(mesh, 2, 0.0), {true, true, true}, Vec3::Zero()});
    crushed.set_loads(clamp);
    crushed.set_body_acceleration(Vec3(0, 0, -1e9));
    EXPECT_THROW(crushed.step(), Error);
}

} // namespace physreg
