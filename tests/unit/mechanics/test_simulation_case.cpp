// SPDX-License-Identifier: GPL-3.0-or-later
#include "mechanics_fixtures.hpp"
#include "physreg/core/error.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/mechanics/simulation/simulation.hpp"

#include <fstream>

namespace physreg {
namespace {

std::string error_of(const std::function<void()>& f) { return test::error_message(f); }

const char* kCase = R"(mesh: block.vtu
tissues: tissues.yaml
solver: {mode: static, load_steps: 2}
constraints:
  - name: base
    select: {face: z_min}
    fixed: [x, y, z]
  - name: top
    select: {face: z_max}
    displacement_mm: [0, 0, -1]
output: {directory: out, frames: 2}
)";

} // namespace

TEST(MechanicsSimulationCase, ReadsAndRunsACase)
{
    test::TempDir dir;
    write_volume_mesh(dir / "block.vtu", test::block_mesh(4, 4, 4, 2.0));
    std::ofstream(dir / "tissues.yaml") << "tissues: [{label: 1, name: t, young_modulus_pa: 3000, poisson_ratio: 0.45}]\n";
    std::ofstream(dir / "case.yaml") << kCase;
    const SimulationCase c = read_simulation_case(dir / "case.yaml");
    EXPECT_EQ(c.mesh_file, dir / "block.vtu");
    EXPECT_EQ(c.load_steps, 2);
    ASSERT_EQ(c.constraints.size(), 2u);
    EXPECT_EQ(c.constraints[1].displacement_mm, Vec3(0, 0, -1));
    const SimulationResult r = run_simulation(c, {});
    ASSERT_EQ(r.frames.size(), 2u);
    ASSERT_EQ(r.equilibria.size(), 2u);
    EXPECT_TRUE(r.equilibria[1].converged());
    // The top face moved by the prescribed −1 mm.
    const auto top = test::nodes_at(r.mesh, 2, 8.0);
    for (auto n : top) EXPECT_NEAR(r.frames.back().displacement_mm[3 * n + 2], -1.0, 1e-12);
}

TEST(MechanicsSimulationCase, BackwardEulerSettlesOnTheStaticEquilibriumUnderGravity)
{
    // A co-rotational block on a fixed base under gravity: backward Euler with Rayleigh damping,
    // run long enough, comes to rest on the equilibrium that Newton finds directly.
    test::TempDir dir;
    write_volume_mesh(dir / "block.vtu", split_hexahedra_into_tetrahedra(test::block_mesh(4, 4, 4, 2.0)));
    std::ofstream(dir / "tissues.yaml") << "tissues: [{label: 1, name: t, young_modulus_pa: 3000, poisson_ratio: 0.45}]\n";
    const std::string common = R"(mesh: block.vtu
tissues: tissues.yaml
material_law: corotational
gravity_mm_s2: [0, -9810, 0]
constraints:
  - {name: base, select: {face: z_min}, fixed: [x, y, z]}
)";
    std::ofstream(dir / "static.yaml") << common << "solver: {method: newton}\noutput: {directory: static}\n";
    std::ofstream(dir / "dynamic.yaml") << common
                                        << "solver: {method: backward-euler, time_step_s: 0.01, duration_s: 1.5, rayleigh_mass_per_s: 20,\n"
                                           "         rayleigh_stiffness_s: 0.001, mass: consistent}\noutput: {directory: dynamic, frames: 3}\n";
    const SimulationCase dynamic_case = read_simulation_case(dir / "dynamic.yaml");
    EXPECT_TRUE(dynamic_case.dynamic);
    EXPECT_EQ(to_string(dynamic_case.method), "backward-euler");
    const auto statics = run_simulation(read_simulation_case(dir / "static.yaml"), {});
    const auto dynamics = run_simulation(dynamic_case, {});
    ASSERT_EQ(dynamics.frames.size(), 3u);
    EXPECT_NEAR(dynamics.frames.back().time_s, 1.5, 1e-9);
    ASSERT_TRUE(dynamics.backward_euler.has_value());
    EXPECT_EQ(dynamics.steps, 150);
    const auto& a = statics.frames.back().displacement_mm;
    const auto& b = dynamics.frames.back().displacement_mm;
    double peak = 0, diff = 0;
    for (std::size_t i = 0; i < a.size(); ++i) peak = std::max(peak, std::abs(a[i])), diff = std::max(diff, std::abs(a[i] - b[i]));
    EXPECT_GT(peak, 0.05); // it does sag (mm)
    EXPECT_LT(diff, 1e-3 * peak) << "static peak " << peak << " mm";
    // An indenter is refused by the implicit dynamics, with its name.
    std::ofstream(dir / "tool.yaml") << common
                                     << "solver: {method: backward-euler, time_step_s: 0.01, duration_s: 0.1}\n"
                                        "indenters: [{name: probe, shape: sphere, radius_mm: 1, path_mm: [[4, 4, 9]]}]\n"
                                        "output: {directory: tool}\n";
    EXPECT_NE(error_of([&] { run_simulation(read_simulation_case(dir / "tool.yaml"), {}); }).find("'probe'"), std::string::npos);
}

TEST(MechanicsSimulationCase, BadCasesNameTheKeyAndReason)
{
    test::TempDir dir;
    write_volume_mesh(dir / "block.vtu", test::block_mesh(2, 2, 2, 2.0));
    std::ofstream(dir / "tissues.yaml") << "tissues: [{label: 1, name: t, young_modulus_pa: 3000, poisson_ratio: 0.45}]\n";
    auto with = [&](const std::string& from, const std::string& to) {
        std::string text = kCase;
        text.replace(text.find(from), from.size(), to);
        std::ofstream(dir / "bad.yaml") << text;
        return dir / "bad.yaml";
    };
    EXPECT_NE(error_of([&] { read_simulation_case(with("output: {directory: out, frames: 2}", "")); }).find("output.directory"),
              std::string::npos);
    EXPECT_NE(error_of([&] { read_simulation_case(with("face: z_min", "face: w_min")); }).find("w_min"), std::string::npos);
    EXPECT_NE(error_of([&] { read_simulation_case(with("mode: static", "mode: sideways")); }).find("sideways"), std::string::npos);
    EXPECT_NE(error_of([&] { read_simulation_case(with("mode: static", "mode: dynamic")); }).find("duration_s"), std::string::npos);
    EXPECT_NE(error_of([&] { run_simulation(read_simulation_case(with("face: z_min", "nodes: [0, 4000]")), {}); }).find("node 4000 does not exist"),
              std::string::npos);
    EXPECT_NE(error_of([&] { run_simulation(read_simulation_case(with("load_steps: 2", "load_steps: 2, time_step_s: 1.0")), {}); })
                  .find("above the critical time step"),
              std::string::npos);
    // Unknown and misplaced keys name the key, where it is, and what is accepted there.
    const std::string bogus = error_of([&] { read_simulation_case(with("load_steps: 2", "load_steps: 2, bogus_key: 1")); });
    EXPECT_NE(bogus.find("unknown key 'bogus_key' in solver"), std::string::npos) << bogus;
    EXPECT_NE(bogus.find("accepted there: method"), std::string::npos) << bogus;
    EXPECT_NE(error_of([&] { read_simulation_case(with("fixed: [x, y, z]", "fixed: [x, y, z]\n    fix: [x]")); }).find("unknown key 'fix'"),
              std::string::npos);
    // A typo gets the nearest accepted key.
    const std::string typo = error_of([&] { read_simulation_case(with("load_steps: 2", "load_step: 2")); });
    EXPECT_NE(typo.find("unknown key 'load_step' in solver"), std::string::npos) << typo;
    EXPECT_NE(typo.find("did you mean 'load_steps'?"), std::string::npos) << typo;
    EXPECT_NE(error_of([&] { read_simulation_case(with("mesh: block.vtu", "mesh: block.vtu\nmethod: newton")); }).find("unknown key 'method' in the case"),
              std::string::npos);
    EXPECT_NE(error_of([&] { read_simulation_case(with("mode: static, load_steps: 2", "method: backward-euler, duration_s: 1")); })
                  .find("needs solver.time_step_s"),
              std::string::npos);
    EXPECT_NE(error_of([&] { read_simulation_case(with("mode: static", "method: newton, rayleigh_mass_per_s: 1")); })
                  .find("applies to method: backward-euler only"),
              std::string::npos);
    EXPECT_NE(error_of([&] {
                  read_simulation_case(with("mode: static, load_steps: 2", "method: backward-euler, duration_s: 1, time_step_s: 0.01, tangent: sometimes"));
              }).find("sometimes"),
              std::string::npos);
    EXPECT_NE(error_of([&] { read_simulation_case(with("mode: static", "mode: dynamic, method: newton")); }).find("disagree"), std::string::npos);
    // Newton runs the same case to the same answer as relaxation.
    {
        std::ofstream(dir / "relax.yaml") << kCase;
        std::string text = kCase;
        text.replace(text.find("mode: static"), 12, "method: newton, linear: cholmod");
        std::ofstream(dir / "newton.yaml") << text;
        const auto a = run_simulation(read_simulation_case(dir / "relax.yaml"), {});
        const auto b = run_simulation(read_simulation_case(dir / "newton.yaml"), {});
        ASSERT_EQ(b.newton_solves.size(), 2u);
        EXPECT_TRUE(b.newton_solves.back().converged);
        EXPECT_TRUE(b.equilibria.empty());
        double diff = 0;
        for (std::size_t i = 0; i < a.frames.back().displacement_mm.size(); ++i)
            diff = std::max(diff, std::abs(a.frames.back().displacement_mm[i] - b.frames.back().displacement_mm[i]));
        EXPECT_LT(diff, 1e-2); // relaxation's default criterion is 1e-3 mm
    }
    std::ofstream(dir / "tissues.yaml") << "tissues: [{label: 1, name: t, young_modulus_pa: 3000, poisson_ratio: 0.5}]\n";
    with("load_steps: 2", "load_steps: 2"); // the valid case again, with the impossible tissue
    EXPECT_NE(error_of([&] { run_simulation(read_simulation_case(dir / "bad.yaml"), {}); }).find("poisson_ratio"), std::string::npos);
}

} // namespace physreg
