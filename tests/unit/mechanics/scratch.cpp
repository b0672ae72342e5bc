#include "mechanics_fixtures.hpp"
#include <cstdio>
#include <gtest/gtest.h>
using namespace physreg; using namespace physreg::test;
TEST(Scratch, Run) {
    const VolumeMesh mesh = block_mesh(4, 2, 2, 2.5);
    for (double alpha : {200.0, 600.0, 2000.0}) for (double T : {0.5, 2.0}) {
    TledOptions options;
    options.damping_per_s = alpha;
    const TledModel model(mesh, one_tissue(3e3, 0.45), options);
    Loads loads = uniaxial_loads(mesh, 10, 5, 5, 0.9);
    loads.ramp_time_s = 0.05;
    TledSolver<double> dynamic(model);
    dynamic.set_loads(loads);
    dynamic.advance(T);
    TledSolver<double> relaxed(model);
    relaxed.set_loads(loads);
    EquilibriumOptions o; o.displacement_tolerance_mm = 1e-8; o.residual_tolerance = 1e-8;
    auto s = relaxed.solve_equilibrium(o);
    const auto a = dynamic.displacement_mm(), b = relaxed.displacement_mm();
    double worst = 0, scale = 0;
    for (std::size_t k = 0; k < a.size(); ++k) { worst = std::max(worst, std::abs(a[k] - b[k])); scale = std::max(scale, std::abs(b[k])); }
    printf("alpha=%g T=%g worst=%g scale=%g dt=%g steps=%ld dr_it=%ld ke=%g\n", alpha, T, worst, scale, model.time_step_s(), dynamic.steps(), s.iterations, dynamic.energies().kinetic_mj);
    }
}
