// SPDX-License-Identifier: GPL-3.0-or-later
// The spectrum that sets dynamic relaxation's speed: Lanczos on the mass-scaled tangent stiffness
// M^{-1/2} K M^{-1/2} (M the relaxation's masses, K by central differences of the TLED forces) of
// the high-resolution and coarse liver models, at rest and at the final depth of compressions
// followed as 20-position tool sequences (as `physreg bench enrich` does).
//
// Relaxation is stable while λ_max < 4 (pseudo-time step 1) and, critically damped, a mode of
// eigenvalue λ decays by about √λ per iteration: λ_max tells how much margin the mass scaling
// keeps, the lowest eigenvalues how many iterations an update needs. Ritz values at the low end
// are upper bounds of the true eigenvalues (they converge slowly; λ_max converges fast).
//
// Usage: bench_dr_spectrum DATASET PARAMETERS.json OUTPUT.json [--states D,E] [--steps-coarse N] [--steps-fine N]
// Hand-written Lanczos (full reorthogonalisation, Eigen): no sparse eigensolver is among our
// dependencies, and the operator is only available matrix-free.
#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/registration/compression/liver_model.hpp"

#include <Eigen/Dense>
#include <nlohmann/json.hpp>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>

using namespace physreg;
using nlohmann::json;

namespace {

struct Spectrum {
    double largest = 0.0;
    std::vector<double> lowest; ///< smallest Ritz values, ascending
    int steps = 0;
    double seconds = 0.0;
};

// Lanczos on A = D K D with D = M^{-1/2} on free dofs, 0 on fixed ones; K v by central differences
// of the internal forces about u0 (the operator is the tangent stiffness at u0, N/mm).
Spectrum mass_scaled_spectrum(const LiverModel& model, const std::vector<double>& u0, double mass_safety, int steps, int lowest)
{
    const auto t0 = std::chrono::steady_clock::now();
    TledSolver<double> solver(*model.tled);
    solver.set_coupling(model.coupling.empty() ? nullptr : &model.coupling);
    const std::size_t n = 3 * model.mesh.node_count();
    std::vector<double> bound = model.tled->stiffness_bound();
    if (!model.coupling.empty()) {
        const auto coupling = model.coupling.stiffness_bound();
        for (std::size_t i = 0; i < coupling.size(); ++i) bound[i] += coupling[i];
    }
    Eigen::VectorXd scale = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(n));
    for (std::size_t k = 0; k < n; ++k) scale[k] = 1.0 / std::sqrt(mass_safety * bound[k / 3] / 4.0); // as solve_equilibrium
    for (auto node : model.fixed_nodes)
        for (int d = 0; d < 3; ++d) scale[3 * node + d] = 0.0;
    const double step_mm = 1e-5;
    std::vector<double> plus(n), minus(n);
    auto apply = [&](const Eigen::VectorXd& x) {
        const Eigen::VectorXd v = scale.cwiseProduct(x);
        const double h = step_mm / std::max(v.cwiseAbs().maxCoeff(), 1e-300);
        for (std::size_t k = 0; k < n; ++k) {
            plus[k] = u0[k] + h * v[k];
            minus[k] = u0[k] - h * v[k];
        }
        solver.set_displacement(plus);
        const auto f_plus = solver.internal_forces_n();
        solver.set_displacement(minus);
        const auto f_minus = solver.internal_forces_n();
        Eigen::VectorXd y(static_cast<Eigen::Index>(n));
        for (std::size_t k = 0; k < n; ++k) y[k] = scale[k] * (f_plus[k] - f_minus[k]) / (2.0 * h);
        return y;
    };
    Eigen::MatrixXd q(static_cast<Eigen::Index>(n), steps + 1);
    std::vector<double> alpha, beta;
    Eigen::VectorXd start = Eigen::VectorXd::Random(static_cast<Eigen::Index>(n)).cwiseProduct(scale.cwiseSign());
    q.col(0) = start.normalized();
    for (int j = 0; j < steps; ++j) {
        Eigen::VectorXd w = apply(q.col(j));
        alpha.push_back(q.col(j).dot(w));
        for (int pass = 0; pass < 2; ++pass) w -= q.leftCols(j + 1) * (q.leftCols(j + 1).transpose() * w);
        const double b = w.norm();
        if (b < 1e-12 * std::abs(alpha.back())) break;
        beta.push_back(b);
        q.col(j + 1) = w / b;
    }
    const int m = static_cast<int>(alpha.size());
    Eigen::MatrixXd t = Eigen::MatrixXd::Zero(m, m);
    for (int j = 0; j < m; ++j) {
        t(j, j) = alpha[j];
        if (j + 1 < m) t(j, j + 1) = t(j + 1, j) = beta[j];
    }
    const Eigen::VectorXd ritz = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(t, Eigen::EigenvaluesOnly).eigenvalues();
    Spectrum out;
    out.steps = m;
    out.largest = ritz[m - 1];
    for (int i = 0; i < std::min(lowest, m); ++i) out.lowest.push_back(ritz[i]);
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return out;
}

json spectrum_json(const Spectrum& s)
{
    return {{"lambda_max", s.largest},
            {"stability_margin", 4.0 / s.largest},
            {"lowest_ritz_values", s.lowest},
            {"decay_per_iteration_of_lowest", s.lowest.empty() ? 0.0 : std::sqrt(std::max(s.lowest.front(), 0.0))},
            {"lanczos_steps", s.steps},
            {"seconds", s.seconds}};
}

} // namespace

int main(int argc, char** argv)
{
    try {
        if (argc < 4) fail("usage: bench_dr_spectrum DATASET PARAMETERS.json OUTPUT.json [--states D,E] [--steps-coarse N] [--steps-fine N]");
        std::string states = "D,E";
        int steps_coarse = 800, steps_fine = 800;
        if ((argc - 4) % 2 != 0) fail("option '{}' needs a value", argv[argc - 1]);
        for (int a = 4; a + 1 < argc; a += 2) {
            const std::string key = argv[a];
            if (key == "--states") states = argv[a + 1];
            else if (key == "--steps-coarse") steps_coarse = std::stoi(argv[a + 1]);
            else if (key == "--steps-fine") steps_fine = std::stoi(argv[a + 1]);
            else fail("unknown option '{}'", key);
        }
        if (steps_coarse < 10 || steps_fine < 10) fail("--steps-coarse and --steps-fine must be ≥ 10");
        const auto dataset = read_phantom_dataset(argv[1]);
        const auto labels = read_label_volume(dataset.path(dataset.state("rest").files.at("labels")));
        const ModelParameters parameters = read_model_parameters(argv[2]);
        const LiverModel fine = build_liver_model(labels, dataset.roles, parameters, "rest");
        const LiverModel coarse = coarsen_liver_model(fine, {24, 18, 18});
        const PredictionOptions options;
        json report;
        report["what"] = "Lanczos Ritz values of M^-1/2 K M^-1/2 (relaxation masses M, tangent stiffness K); stable while lambda_max < 4";
        report["mass_safety"] = options.equilibrium.mass_safety;
        report["threads"] = omp_get_max_threads();
        std::vector<std::string> names;
        for (std::size_t at = 0; at <= states.size();) {
            const std::size_t comma = std::min(states.find(',', at), states.size());
            if (comma > at) names.push_back(states.substr(at, comma - at));
            at = comma + 1;
        }
        for (const auto& [label, model, steps] : {std::tuple{"coarse", &coarse, steps_coarse}, std::tuple{"high_resolution", &fine, steps_fine}}) {
            json& entry = report["models"][label];
            entry["dofs"] = 3 * model->mesh.node_count();
            std::cerr << label << ": rest\n";
            entry["rest"] = spectrum_json(mass_scaled_spectrum(*model, std::vector<double>(3 * model->mesh.node_count(), 0.0),
                                                               options.equilibrium.mass_safety, steps, 16));
            for (const auto& state : names) {
                std::cerr << label << ": " << state << " (tracking 20 tool positions, then Lanczos)\n";
                const Indenter& tool = *dataset.state(state).tool;
                CompressionTracker tracker(*model, tool, options);
                const Vec3 first = tool.path.front(), last = tool.path.back();
                for (int s = 1; s <= 20; ++s) tracker.move_to(first + (last - first) * double(s) / 20.0, state);
                entry[state] = spectrum_json(mass_scaled_spectrum(*model, tracker.displacement_mm(), options.equilibrium.mass_safety, steps, 16));
            }
        }
        write_atomically(argv[3], [&](const std::filesystem::path& tmp) { std::ofstream(tmp) << report.dump(2) << "\n"; });
        std::cout << report.dump(2) << std::endl;
        return 0;
    } catch (const std::exception& e) {
        std::cerr << "bench_dr_spectrum: " << e.what() << "\n";
        return 1;
    }
}
