// SPDX-License-Identifier: GPL-3.0-or-later
// Backward Euler steps of the SOFA liver (ModelOrderReduction's liverFine.vtu: 4 293 nodes,
// 22 019 linear tetrahedra) with paper 001's mechanics: co-rotational linear tetrahedra, healthy
// liver E = 3.5 kPa, ν = 0.45, ρ = 1000 kg/m³, Rayleigh damping α = 0.1 /s, β = 0.1 s, lumped
// mass, hung from the nodes within 25 mm of its highest point under gravity (−y, SOFA's frame),
// Δt = 10 ms. The mesh is in SOFA's units; ×30 gives a 191 × 146 × 132 mm liver. (Resting on a
// small patch at the bottom it topples over; hung from a 12 mm patch, elements invert.)
// Per tangent policy: the first step (with the first factorisation) and the mean and percentiles
// of the later steps, split into force evaluation, assembly, factorisation and triangular solves.
// Run: OMP_NUM_THREADS=2 OMP_WAIT_POLICY=passive build/bin/bench_backward_euler bench/results/bench_backward_euler.json
//      [--mesh ../shared/data/sofa-mor-liverFine/liverFine.vtu] [--steps 100] [--young-pa 3500]
//      [--tolerance 1e-4 (Newton policies: ‖r‖∞ ≤ tol × largest force)] [--hold-radius-mm 25] [--policy N]
#include "physreg/core/atomic_file.hpp"
#include "physreg/core/blas_kernels.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/mechanics/implicit/backward_euler.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <omp.h>

using namespace physreg;

namespace {

struct Policy {
    std::string name;
    TangentUpdate tangent;
    int fixed_iterations;
    bool rotated_tangent;
};

double percentile(std::vector<double> v, double p)
{
    std::sort(v.begin(), v.end());
    return v[static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5)];
}

} // namespace

int main(int argc, char** argv)
{
    physreg::restart_with_fast_blas_kernels(argv); // the program's own choice of BLAS kernels (core/blas_kernels.hpp)
    try {
        std::filesystem::path output = "bench_backward_euler.json";
        std::filesystem::path mesh_path = "../shared/data/sofa-mor-liverFine/liverFine.vtu";
        int steps = 100;
        double young_pa = 3500, tolerance = 1e-4, radius = 25.0;
        int only_policy = -1; // --policy N: run only the N-th policy (0: SOFA's linearised scheme)
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            if (a == "--mesh" && i + 1 < argc)
                mesh_path = argv[++i];
            else if (a == "--steps" && i + 1 < argc)
                steps = std::stoi(argv[++i]);
            else if (a == "--young-pa" && i + 1 < argc)
                young_pa = std::stod(argv[++i]);
            else if (a == "--tolerance" && i + 1 < argc)
                tolerance = std::stod(argv[++i]);
            else if (a == "--hold-radius-mm" && i + 1 < argc)
                radius = std::stod(argv[++i]);
            else if (a == "--policy" && i + 1 < argc)
                only_policy = std::stoi(argv[++i]);
            else
                output = a;
        }
        if (!std::filesystem::exists(mesh_path)) {
            std::cerr << "bench_backward_euler: mesh " << mesh_path << " not found (pass --mesh)\n";
            return 2;
        }
        VolumeMesh mesh = read_volume_mesh(mesh_path);
        const double scale_mm = 30.0;
        for (auto& p : mesh.nodes) p *= scale_mm;
        for (auto& label : mesh.cell_labels) label = 1;
        TissueTable tissues;
        tissues.tissues = {{1, "liver", young_pa, 0.45, 1000}};
        TledOptions options;
        options.law = MaterialLaw::corotational;
        const TledModel model(mesh, tissues, options);

        // Hung from its top: every node within `radius` of the highest one (in y) is held.
        std::size_t top = 0;
        for (std::size_t i = 0; i < mesh.node_count(); ++i)
            if (mesh.nodes[i].y() > mesh.nodes[top].y()) top = i;
        NodeConstraint hold{"held", {}, {true, true, true}, Vec3::Zero()};
        for (std::size_t i = 0; i < mesh.node_count(); ++i)
            if ((mesh.nodes[i] - mesh.nodes[top]).norm() <= radius) hold.nodes.push_back(static_cast<std::int32_t>(i));
        Loads loads;
        loads.constraints.push_back(hold);

        const std::vector<Policy> policies = {
            {"stale R K0 R^T factor, 1 iteration (linearised, as SOFA)", TangentUpdate::stale, 1, true},
            {"new R K0 R^T factor every step, 1 iteration", TangentUpdate::every_step, 1, true},
            {"stale exact-tangent factor, Newton to tolerance", TangentUpdate::stale, 0, false},
            {"exact tangent every iteration, Newton to tolerance", TangentUpdate::every_iteration, 0, false}};
        nlohmann::json cases = nlohmann::json::array();
        for (std::size_t p = 0; p < policies.size(); ++p) {
            if (only_policy >= 0 && static_cast<std::size_t>(only_policy) != p) continue;
            const Policy& policy = policies[p];
            BackwardEulerOptions be;
            be.time_step_s = 0.01;
            be.rayleigh_mass_per_s = 0.1;
            be.rayleigh_stiffness_s = 0.1;
            be.tangent = policy.tangent;
            be.fixed_newton_iterations = policy.fixed_iterations;
            be.rotated_corotational_tangent = policy.rotated_tangent;
            be.residual_tolerance = tolerance;
            be.max_newton_iterations = 50;
            BackwardEuler integrator(model, be);
            integrator.set_loads(loads);
            integrator.set_body_acceleration(Vec3(0, -9810, 0));
            const int n_steps = policy.tangent == TangentUpdate::stale ? steps : std::min(steps, 20);
            std::vector<double> ms, force_ms, solve_ms, iterations;
            double first_ms = 0, factorisation_s = 0, assembly_s = 0, worst_residual = 0;
            std::int64_t inverted = 0;
            std::string failure;
            for (int s = 0; s < n_steps; ++s) {
                BackwardEulerStep st;
                try {
                    st = integrator.step();
                } catch (const std::exception& e) {
                    failure = e.what();
                    std::cout << policy.name << ": " << failure << "\n";
                    break;
                }
                inverted = std::max(inverted, st.inverted_elements);
                worst_residual = std::max(worst_residual, st.residual_n / st.reference_force_n);
                if (s == 0) {
                    first_ms = 1e3 * st.seconds;
                    continue;
                }
                ms.push_back(1e3 * st.seconds);
                force_ms.push_back(1e3 * st.force_s);
                solve_ms.push_back(1e3 * st.solve_s);
                iterations.push_back(st.newton_iterations);
                factorisation_s += st.factorisation_s;
                assembly_s += st.assembly_s;
            }
            double lowest = 0;
            for (std::size_t i = 0; i < model.node_count(); ++i) lowest = std::min(lowest, integrator.displacement_mm()[3 * i + 1]);
            const auto mean = [](const std::vector<double>& v) {
                double sum = 0;
                for (double x : v) sum += x;
                return sum / static_cast<double>(v.size());
            };
            nlohmann::json c = {{"policy", policy.name},
                                {"tangent", to_string(policy.tangent)},
                                {"jacobian_stiffness", policy.rotated_tangent ? "rotated R K0 R^T" : "exact"},
                                {"fixed_newton_iterations", policy.fixed_iterations},
                                {"steps", n_steps},
                                {"first_step_ms", first_ms},
                                {"mean_step_ms", mean(ms)},
                                {"median_step_ms", percentile(ms, 0.5)},
                                {"p90_step_ms", percentile(ms, 0.9)},
                                {"mean_force_ms", mean(force_ms)},
                                {"mean_solve_ms", mean(solve_ms)},
                                {"mean_newton_iterations", mean(iterations)},
                                {"factorisations", integrator.total_factorisations()},
                                {"factorisation_s_after_first_step", factorisation_s},
                                {"assembly_s_after_first_step", assembly_s},
                                {"simulated_s", integrator.time_s()},
                                {"failure", failure},
                                {"most_inverted_elements", inverted},
                                {"worst_relative_residual", worst_residual},
                                {"residual_tolerance", be.residual_tolerance},
                                {"largest_sag_mm", -lowest}};
            std::cout << fmt::format("{:<42} first {:7.1f} ms  later: mean {:6.2f} ms, median {:6.2f}, p90 {:6.2f} (forces {:.2f}, "
                                     "solves {:.2f}), {:.2f} it/step, {} factorisations, sag {:.1f} mm, worst residual {:.2g}, inverted {}\n",
                                     policy.name, first_ms, mean(ms), percentile(ms, 0.5), percentile(ms, 0.9), mean(force_ms),
                                     mean(solve_ms), mean(iterations), integrator.total_factorisations(), -lowest, worst_residual, inverted);
            cases.push_back(c);
        }
        const nlohmann::json doc = {{"benchmark", "bench_backward_euler"},
                                    {"mesh", mesh_path.filename().string()},
                                    {"nodes", model.node_count()},
                                    {"tetrahedra", model.element_count()},
                                    {"scale_mm_per_unit", scale_mm},
                                    {"held_nodes", hold.nodes.size()},
                                    {"threads", omp_get_max_threads()},
                                    {"openblas_kernels", physreg::openblas_kernels()},
                                    {"law", "corotational"},
                                    {"young_pa", young_pa},
                                    {"hold_radius_mm", radius},
                                    {"poisson", 0.45},
                                    {"time_step_s", 0.01},
                                    {"rayleigh", {{"mass_per_s", 0.1}, {"stiffness_s", 0.1}}},
                                    {"cases", cases}};
        write_atomically(output, [&](const std::filesystem::path& tmp) { std::ofstream(tmp) << doc.dump(2) << "\n"; });
        std::cout << "wrote " << output << "\n";
        return 0;
    } catch (const std::exception& e) {
        std::cerr << "bench_backward_euler: " << e.what() << "\n";
        return 1;
    }
}
