// SPDX-License-Identifier: GPL-3.0-or-later
// MLS shape functions and tissue–tissue penalty coupling (paper 000 eqs. 1–5).
#include "test_support.hpp"

#include "physreg/mechanics/coupling/mls.hpp"
#include "physreg/mechanics/coupling/tissue_coupling.hpp"
#include "physreg/mechanics/explicit/tled_solver.hpp"
#include "physreg/mesh/hex_meshing.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace physreg {
namespace {

std::vector<Vec3> scattered_points(int count, std::uint32_t seed)
{
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> u(-2.0, 2.0);
    std::vector<Vec3> p;
    for (int i = 0; i < count; ++i) p.emplace_back(u(random), u(random), 0.5 * u(random));
    return p;
}

TEST(Mls, PartitionOfUnityAndExactLinearFields)
{
    const auto points = scattered_points(200, 7);
    std::vector<std::int32_t> all(points.size());
    std::iota(all.begin(), all.end(), 0);
    MlsOptions options;
    options.support_radius_mm = Vec3(1.5, 1.5, 0.8);
    const Mat3 a = (Mat3() << 0.3, -1.2, 0.7, 2.0, 0.1, -0.4, 0.5, 0.9, 1.1).finished();
    const Vec3 b(3.0, -1.0, 2.5);
    for (const Vec3& x : {Vec3(0, 0, 0), Vec3(0.7, -0.3, 0.2), Vec3(-1.1, 1.2, -0.4)}) {
        const auto s = mls_shape_functions(x, all, points, options, "test");
        ASSERT_GE(s.nodes.size(), 4u);
        double sum = 0.0;
        Vec3 position = Vec3::Zero(), field = Vec3::Zero();
        for (std::size_t j = 0; j < s.nodes.size(); ++j) {
            const Vec3& xj = points[static_cast<std::size_t>(s.nodes[j])];
            EXPECT_LE((xj - x).cwiseQuotient(options.support_radius_mm * s.radius_scale).norm(), 1.0);
            sum += s.phi[j];
            position += s.phi[j] * xj;
            field += s.phi[j] * (a * xj + b);
        }
        EXPECT_NEAR(sum, 1.0, 1e-12);
        EXPECT_LT((position - x).norm(), 1e-11);
        EXPECT_LT((field - (a * x + b)).norm(), 1e-10);
        // A quadratic field is not reproduced exactly (the test could fail): MLS with a linear basis.
        double quadratic = 0.0;
        for (std::size_t j = 0; j < s.nodes.size(); ++j) quadratic += s.phi[j] * points[static_cast<std::size_t>(s.nodes[j])].squaredNorm();
        EXPECT_GT(std::abs(quadratic - x.squaredNorm()), 1e-4);
    }
    EXPECT_EQ(mls_weight(0.0), 1.0);
    EXPECT_EQ(mls_weight(1.0), 0.0);
    EXPECT_NEAR(mls_weight(0.5), 1 - 6 * 0.25 + 8 * 0.125 - 3 * 0.0625, 1e-15);
}

TEST(Mls, RefusesTooFewOrCoplanarSupportVertices)
{
    const std::vector<Vec3> points{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0.5, 0.5, 0}, {5, 5, 5}};
    const std::vector<std::int32_t> all{0, 1, 2, 3, 4, 5};
    MlsOptions options;
    options.support_radius_mm = Vec3::Constant(1.6);
    const auto coplanar = test::error_message([&] { mls_shape_functions(Vec3(0.5, 0.5, 0), all, points, options, "plate"); });
    EXPECT_NE(coplanar.find("ill-conditioned"), std::string::npos) << coplanar;
    EXPECT_NE(coplanar.find("plate"), std::string::npos);
    const std::vector<std::int32_t> three{0, 1, 2};
    const auto few = test::error_message([&] { mls_shape_functions(Vec3(0.2, 0.2, 0.2), three, points, options, "corner"); });
    EXPECT_NE(few.find("support domain"), std::string::npos) << few;
    EXPECT_NE(few.find("3 vertices"), std::string::npos) << few;
}

// A 10 × 10 × 10 mm block of parenchyma (label 1, 1 mm cells) with a 4 mm cubic tumour (label 2).
struct Inclusion {
    VolumeMesh mesh;
    TissueTable tissues;
    std::map<std::int32_t, TissueGroup> groups{{1, TissueGroup::parenchyma}, {2, TissueGroup::tumour}};
    Inclusion()
    {
        const auto volume = test::make_volume({10, 10, 10}, [](int i, int j, int k) -> std::uint16_t {
            return (i >= 3 && i < 7 && j >= 3 && j < 7 && k >= 3 && k < 7) ? 2 : 1;
        });
        tissues.tissues = {{1, "parenchyma", 2e5, 0.49, 1000}, {2, "tumour", 5e6, 0.49, 1000}};
        mesh = mesh_label_volume(volume, tissues, {}, "inclusion").mesh;
    }
    // Bottom face fixed, top face pressed down by `depth` mm (parenchyma only: the tumour is inside).
    Loads loads(const VolumeMesh& m, double depth) const
    {
        Loads l;
        NodeConstraint bottom{"bottom", {}, {true, true, true}, Vec3::Zero()}, top{"top", {}, {true, true, true}, Vec3(0, 0, -depth)};
        double zmin = 1e300, zmax = -1e300;
        for (const auto& x : m.nodes) zmin = std::min(zmin, x.z()), zmax = std::max(zmax, x.z());
        for (std::size_t n = 0; n < m.node_count(); ++n) {
            if (m.nodes[n].z() < zmin + 1e-9) bottom.nodes.push_back(static_cast<std::int32_t>(n));
            if (m.nodes[n].z() > zmax - 1e-9) top.nodes.push_back(static_cast<std::int32_t>(n));
        }
        l.constraints = {bottom, top};
        return l;
    }
};

TEST(TissueCoupling, SplitsInterfaceVerticesAndCouplesThem)
{
    const Inclusion block;
    const SplitMesh split = split_tissue_interfaces(block.mesh, block.groups, {}, {});
    // The tumour's 5×5×5 vertices, of which the 3×3×3 inside are its own: 98 shared with parenchyma.
    EXPECT_EQ(split.mesh.node_count(), block.mesh.node_count() + 98);
    EXPECT_EQ(split.coupling.points().size(), 98u);
    for (const auto& p : split.coupling.points()) {
        EXPECT_EQ(p.kind, CouplingKind::parenchyma_tumour);
        for (const auto n : p.first.nodes) EXPECT_EQ(split.node_group[static_cast<std::size_t>(n)], TissueGroup::parenchyma);
        for (const auto n : p.second.nodes) EXPECT_EQ(split.node_group[static_cast<std::size_t>(n)], TissueGroup::tumour);
    }
    // No cell of the tumour shares a node with a parenchyma cell any more.
    std::vector<int> owner(split.mesh.node_count(), 0);
    for (std::size_t c = 0; c < split.mesh.cell_count(); ++c)
        for (const auto n : split.mesh.cell(c)) owner[static_cast<std::size_t>(n)] |= split.mesh.cell_labels[c];
    for (const int o : owner) EXPECT_NE(o, 3);
    // Rest gap zero; an affine motion (rigid or not) opens no gap: linear reproduction on both sides.
    std::vector<double> u(3 * split.mesh.node_count());
    const Mat3 a = (Mat3() << 0.01, -0.05, 0.02, 0.05, 0.0, -0.03, -0.02, 0.03, 0.015).finished();
    for (std::size_t n = 0; n < split.mesh.node_count(); ++n) {
        const Vec3 d = a * split.mesh.nodes[n] + Vec3(0.4, -0.2, 0.1);
        for (int k = 0; k < 3; ++k) u[3 * n + k] = d[k];
    }
    for (const auto& g : split.coupling.gaps_mm(u)) EXPECT_LT(g.norm(), 1e-12);
    EXPECT_LT(split.coupling.energy_mj(u), 1e-20);
}

TEST(TissueCoupling, ForcesSumToZero)
{
    const Inclusion block;
    CouplingStiffness k;
    k.parenchyma_tumour_n_per_m = 2500.0;
    const SplitMesh split = split_tissue_interfaces(block.mesh, block.groups, k, {});
    std::mt19937 random(3);
    std::normal_distribution<double> noise(0.0, 0.1);
    std::vector<double> u(3 * split.mesh.node_count());
    for (auto& v : u) v = noise(random);
    std::vector<double> f(u.size(), 0.0);
    split.coupling.add_forces(u.data(), f.data());
    Vec3 total = Vec3::Zero();
    double largest = 0.0;
    for (std::size_t n = 0; n < split.mesh.node_count(); ++n) {
        total += Vec3(f[3 * n], f[3 * n + 1], f[3 * n + 2]);
        largest = std::max(largest, Vec3(f[3 * n], f[3 * n + 1], f[3 * n + 2]).norm());
    }
    ASSERT_GT(largest, 1e-3);
    EXPECT_LT(total.norm(), 1e-12 * largest * double(split.mesh.node_count()));
    // f = ∂E/∂u and the Hessian: the CouplingForm case of test_implicit.cpp, run by test_forms.cpp.
    // Stiffness in N/mm: 2500 N/m is 2.5 N/mm.
    EXPECT_DOUBLE_EQ(k.n_per_mm(CouplingKind::parenchyma_tumour), 2.5);
}

TEST(TissueCoupling, BadStiffnessIsRefusedNamingTheParameter)
{
    CouplingStiffness k;
    k.parenchyma_vessel_n_per_m = -1.0;
    EXPECT_NE(test::error_message([&] { k.validate(); }).find("k_c,s-v"), std::string::npos);
    k.parenchyma_vessel_n_per_m = 500.0;
    k.parenchyma_tumour_n_per_m = std::nan("");
    EXPECT_NE(test::error_message([&] { k.validate(); }).find("k_c,s-t"), std::string::npos);
    const Inclusion block;
    std::map<std::int32_t, TissueGroup> missing{{1, TissueGroup::parenchyma}};
    EXPECT_NE(test::error_message([&] { split_tissue_interfaces(block.mesh, missing, {}, {}); }).find("label 2"), std::string::npos);
}

EquilibriumOptions tight()
{
    EquilibriumOptions o;
    o.displacement_tolerance_mm = 1e-7;
    o.residual_tolerance = 1e-7;
    o.max_iterations = 400000;
    return o;
}

// Largest distance between the coupled model's parenchyma copies and the shared-node model's nodes.
double difference_to_shared(const Inclusion& block, const std::vector<double>& shared_u, double k_n_per_m, double& largest,
                            double radius = CouplingOptions{}.support_radius_cells)
{
    CouplingStiffness k{k_n_per_m, k_n_per_m};
    CouplingOptions options;
    options.support_radius_cells = radius;
    const SplitMesh split = split_tissue_interfaces(block.mesh, block.groups, k, options);
    const TledModel model(split.mesh, block.tissues, {});
    TledSolver<double> solver(model);
    solver.set_coupling(&split.coupling);
    solver.set_loads(block.loads(split.mesh, 0.5));
    const auto summary = solver.solve_equilibrium(tight());
    EXPECT_TRUE(summary.converged()) << summary.message;
    const auto u = solver.displacement_mm();
    double diff = 0.0;
    largest = 0.0;
    for (std::size_t n = 0; n < split.mesh.node_count(); ++n) {
        const std::size_t v = static_cast<std::size_t>(split.original_vertex[n]);
        const Vec3 a(u[3 * n], u[3 * n + 1], u[3 * n + 2]), b(shared_u[3 * v], shared_u[3 * v + 1], shared_u[3 * v + 2]);
        diff = std::max(diff, (a - b).norm());
        largest = std::max(largest, b.norm());
    }
    return diff;
}

TEST(TissueCoupling, StiffCouplingApproachesTheSharedNodeModel)
{
    const Inclusion block;
    const TledModel shared_model(block.mesh, block.tissues, {});
    TledSolver<double> shared(shared_model);
    shared.set_loads(block.loads(block.mesh, 0.5));
    ASSERT_TRUE(shared.solve_equilibrium(tight()).converged());
    const auto shared_u = shared.displacement_mm();
    double largest = 0.0;
    // k = 1e6 N/m (1000 N/mm, ≈ 5000× a 1 mm parenchyma element's stiffness E·h = 0.2 N/mm), default
    // support (1.25 cells): every copy within 2 % of the largest displacement (≈ 0.5 mm) of the
    // shared-node solution. The coupling ties MLS averages, not the copies themselves, so what is
    // left shrinks with the support: 0.2 % at 1.05 cells. A soft coupling (10 N/m) lets the tissues
    // slide apart by far more.
    const double stiff = difference_to_shared(block, shared_u, 1e6, largest);
    const double tight = difference_to_shared(block, shared_u, 1e6, largest, 1.05);
    const double soft = difference_to_shared(block, shared_u, 10.0, largest);
    EXPECT_GE(largest, 0.5);
    EXPECT_LT(largest, 0.55);
    EXPECT_LT(stiff, 0.02 * largest) << "stiff coupling differs by " << stiff << " mm";
    EXPECT_LT(tight, 0.002 * largest) << "tight support differs by " << tight << " mm";
    EXPECT_GT(soft, 5.0 * stiff) << "soft " << soft << " stiff " << stiff;
}

TEST(TissueCoupling, WithoutCouplingTheLesionIsNotDeformed)
{
    const Inclusion block;
    const SplitMesh split = split_tissue_interfaces(block.mesh, block.groups, CouplingStiffness{0.0, 0.0}, {});
    const TledModel model(split.mesh, block.tissues, {});
    TledSolver<double> solver(model);
    solver.set_coupling(&split.coupling);
    solver.set_loads(block.loads(split.mesh, 0.5));
    ASSERT_TRUE(solver.solve_equilibrium({}).converged());
    const auto u = solver.displacement_mm();
    double tumour = 0.0, parenchyma = 0.0;
    for (std::size_t n = 0; n < split.mesh.node_count(); ++n) {
        const double d = Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]).norm();
        (split.node_group[n] == TissueGroup::tumour ? tumour : parenchyma) = std::max(d, split.node_group[n] == TissueGroup::tumour ? tumour : parenchyma);
    }
    EXPECT_GT(parenchyma, 0.49);
    EXPECT_LT(tumour, 1e-12); // k_c = 0: no force reaches the lesion (round-off of F = I only)
    // A weak coupling (1 N/m) moves the lesion but hardly strains it: its strain energy is a tiny
    // fraction of the parenchyma's. Explicit dynamics, damped, for a short time.
    const SplitMesh weak = split_tissue_interfaces(block.mesh, block.groups, CouplingStiffness{1.0, 1.0}, {});
    const TledModel weak_model(weak.mesh, block.tissues, {});
    TledSolver<double> dynamic(weak_model);
    dynamic.set_coupling(&weak.coupling);
    Loads loads = block.loads(weak.mesh, 0.5);
    loads.ramp_time_s = 0.02;
    dynamic.set_loads(loads);
    dynamic.advance(0.05);
    // Strain energy per tissue from a model restricted to each tissue's elements.
    auto strain = [&](std::int32_t label) {
        VolumeMesh part = weak.mesh;
        part.cells.clear();
        part.cell_labels.clear();
        part.cell_grid_index.clear();
        part.grid.reset();
        for (std::size_t c = 0; c < weak.mesh.cell_count(); ++c)
            if (weak.mesh.cell_labels[c] == label) {
                for (const auto n : weak.mesh.cell(c)) part.cells.push_back(n);
                part.cell_labels.push_back(label);
            }
        TissueTable t = block.tissues;
        const TledModel m(part, t, {});
        TledSolver<double> s(m);
        s.set_displacement(dynamic.displacement_mm());
        return s.energies().strain_mj;
    };
    EXPECT_LT(strain(2), 1e-4 * strain(1));
}

TEST(TissueCoupling, UndampedDynamicsDoesNotGainEnergy)
{
    const Inclusion block;
    const SplitMesh split = split_tissue_interfaces(block.mesh, block.groups, CouplingStiffness{2e4, 2e4}, {});
    // A step well below the stability limit: the kinetic energy measured from a backward difference
    // then differs from the conserved (shadow) energy of central differences by ≤ (ω Δt / 2)² ≈ 1 %.
    TledOptions small_step;
    small_step.time_step_safety = 0.1;
    const TledModel model(split.mesh, block.tissues, small_step);
    TledSolver<double> solver(model);
    solver.set_coupling(&split.coupling);
    EXPECT_LT(solver.time_step_s(), model.time_step_s()); // the stiff coupling shortens the stable step
    // Start from a state with the tumour displaced against the parenchyma (open gaps, zero velocity).
    std::vector<double> u(3 * split.mesh.node_count(), 0.0);
    for (std::size_t n = 0; n < split.mesh.node_count(); ++n)
        if (split.node_group[n] == TissueGroup::tumour) u[3 * n] = 0.05;
    solver.set_displacement(u);
    const double initial = solver.energies().total_mj();
    ASSERT_GT(solver.energies().coupling_mj, 0.0);
    double highest = initial;
    for (int chunk = 0; chunk < 40; ++chunk) {
        solver.advance(200 * solver.time_step_s());
        highest = std::max(highest, solver.energies().total_mj());
    }
    EXPECT_LT(highest, 1.03 * initial) << "initial " << initial << " mJ, highest " << highest << " mJ";
    EXPECT_GT(solver.energies().total_mj(), 0.5 * initial); // undamped: energy is not lost either
}

} // namespace
} // namespace physreg
