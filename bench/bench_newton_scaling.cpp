// SPDX-License-Identifier: GPL-3.0-or-later
// Cost of a static solve against mesh size, per solver: Newton with CHOLMOD, Newton with the
// stale-factor PCG, and dynamic relaxation, on blocks of about 10 k, 50 k, 200 k and 1 M hexahedra
// (and 20 k) (1 mm cells, E = 200 kPa, ν = 0.49, base fixed) pressed 1 mm by a sphere of radius width/6, then
// moved 0.5 mm further (a "tool update", warm-started). Writes a JSON table and a log-log PNG plot
// with the fitted slope α (time ∝ n^α).
// Run: OMP_NUM_THREADS=2 build/bin/bench_newton_scaling bench/results/bench_newton_scaling.json
//      [--max-elements N] [--budget-s S]   (a case predicted to take longer than S is skipped)
#include "physreg/core/atomic_file.hpp"
#include "physreg/core/blas_kernels.hpp"
#include "physreg/figures/canvas.hpp"
#include "physreg/io/png.hpp"
#include "physreg/mechanics/implicit/newton_solver.hpp"
#include "physreg/mesh/hex_meshing.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>

using namespace physreg;

namespace {

VolumeMesh block(int nx, int ny, int nz)
{
    LabelVolume v;
    v.geometry.size = {nx, ny, nz};
    v.geometry.spacing = Vec3::Ones();
    v.geometry.origin = Vec3::Constant(0.5);
    v.labels.assign(static_cast<std::size_t>(nx) * ny * nz, 1);
    TissueTable t;
    t.tissues = {{1, "parenchyma", 2e5, 0.49, 1000}};
    return mesh_label_volume(v, t, {}, "block").mesh;
}

struct Run {
    double first_s = 0, update_s = 0;
    long iterations_first = 0, iterations_update = 0;
    double peak_mm = 0;
    bool ok = true;
    std::string note;
};

Loads press(const VolumeMesh& mesh, int n, int nz)
{
    Loads loads;
    std::vector<std::int32_t> base;
    for (std::size_t i = 0; i < mesh.node_count(); ++i)
        if (mesh.nodes[i].z() < 1e-9) base.push_back(static_cast<std::int32_t>(i));
    loads.constraints.push_back({"base", base, {true, true, true}, Vec3::Zero()});
    Indenter sphere;
    sphere.name = "sphere";
    sphere.radius_mm = n / 6.0;
    const Vec3 c(n / 2.0, n / 2.0, nz + sphere.radius_mm);
    sphere.path = {c, c - Vec3(0, 0, 1.0), c - Vec3(0, 0, 1.5)};
    loads.indenters.push_back(sphere);
    return loads;
}

double seconds(std::chrono::steady_clock::time_point t)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

double peak(const std::vector<double>& u)
{
    double m = 0;
    for (std::size_t i = 0; i < u.size(); i += 3) m = std::max(m, std::hypot(u[i], u[i + 1], u[i + 2]));
    return m;
}

Run run_newton(const TledModel& model, const Loads& loads, LinearSolverKind kind)
{
    NewtonOptions o;
    o.linear.kind = kind;
    NewtonSolver solver(model, o);
    solver.set_loads(loads);
    Run r;
    auto t = std::chrono::steady_clock::now();
    NewtonSummary s = solver.solve_equilibrium(0.5);
    r.first_s = seconds(t);
    r.iterations_first = s.newton_iterations;
    if (!s.converged) return {0, 0, 0, 0, 0, false, s.message};
    t = std::chrono::steady_clock::now();
    s = solver.solve_equilibrium(1.0);
    r.update_s = seconds(t);
    r.iterations_update = s.newton_iterations;
    r.ok = s.converged;
    r.note = fmt::format("{} factorisations, {} PCG iterations in the update", s.factorisations, s.linear_iterations);
    r.peak_mm = peak(solver.displacement_mm());
    return r;
}

Run run_relaxation(const TledModel& model, const Loads& loads)
{
    TledSolver<double> solver(model);
    solver.set_loads(loads);
    EquilibriumOptions o; // defaults: 1e-3 mm, 1e-4 of the largest internal force
    Run r;
    auto t = std::chrono::steady_clock::now();
    SolveSummary s = solver.solve_equilibrium(o, 0.5);
    r.first_s = seconds(t);
    r.iterations_first = s.iterations;
    t = std::chrono::steady_clock::now();
    s = solver.solve_equilibrium(o, 1.0);
    r.update_s = seconds(t);
    r.iterations_update = s.iterations;
    r.ok = s.converged();
    r.peak_mm = peak(solver.displacement_mm());
    return r;
}

// Least-squares slope of log t against log n.
double slope(const std::vector<std::pair<double, double>>& points)
{
    if (points.size() < 2) return NAN;
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (auto [n, t] : points) {
        const double x = std::log(n), y = std::log(t);
        sx += x, sy += y, sxx += x * x, sxy += x * y;
    }
    const double k = double(points.size());
    return (k * sxy - sx * sy) / (k * sxx - sx * sx);
}

} // namespace

int main(int argc, char** argv)
{
    physreg::restart_with_fast_blas_kernels(argv); // the program's own choice of BLAS kernels (core/blas_kernels.hpp)
    if (argc < 2) {
        std::cerr << "usage: bench_newton_scaling OUT.json [--max-elements N] [--budget-s S] [--methods a,b,...]\n";
        return 1;
    }
    const std::string out = argv[1];
    long max_elements = 1100000;
    double budget_s = 300;
    for (int i = 2; i < argc; ++i) {
        const std::string a = argv[i];
        if (i + 1 >= argc) {
            std::cerr << "bench_newton_scaling: " << a << " needs a value\n";
            return 1;
        }
        if (a == "--max-elements") max_elements = std::stol(argv[++i]);
        else if (a == "--budget-s") budget_s = std::stod(argv[++i]);
        else if (a == "--methods") ++i;
        else {
            std::cerr << "bench_newton_scaling: unknown option " << a << "\n";
            return 1;
        }
    }
    const std::vector<int> sizes = {28, 34, 46, 74, 126}; // n × n × n/2 cells: 11 k, 20 k, 49 k, 203 k, 1.0 M
    std::vector<std::string> methods = {"newton-cholmod", "newton-pcg-factor", "newton-pcg-amg", "relaxation"};
    for (int i = 2; i < argc; ++i)
        if (std::string(argv[i]) == "--methods" && i + 1 < argc) { // comma-separated subset
            methods.clear();
            std::stringstream list(argv[++i]);
            for (std::string m; std::getline(list, m, ',');) methods.push_back(m);
        }
    nlohmann::json rows = nlohmann::json::array();
    std::map<std::string, std::vector<std::pair<double, double>>> measured;
    for (int n : sizes) {
        const int nz = n / 2;
        const long elements = long(n) * n * nz;
        if (elements > max_elements) break;
        const VolumeMesh mesh = block(n, n, nz);
        const TledModel model(mesh, [] {
            TissueTable t;
            t.tissues = {{1, "parenchyma", 2e5, 0.49, 1000}};
            return t;
        }(), {});
        const Loads loads = press(mesh, n, nz);
        for (const auto& method : methods) {
            auto& points = measured[method];
            if (!points.empty()) { // predict from the last two sizes (one size: assume α = 2, a 3D direct solver's flops)
                const double a = points.size() >= 2 ? slope({points[points.size() - 2], points.back()}) : 2.0;
                const double predicted = points.back().second * std::pow(double(elements) / points.back().first, a);
                if (predicted > budget_s) {
                    rows.push_back({{"elements", elements}, {"method", method}, {"skipped", true},
                                    {"predicted_update_s", predicted}});
                    std::cout << method << " " << elements << ": skipped (predicted " << predicted << " s)\n";
                    continue;
                }
            }
            Run r;
            try {
                r = method == "relaxation" ? run_relaxation(model, loads)
                                           : run_newton(model, loads,
                                                        method == "newton-cholmod"  ? LinearSolverKind::cholmod
                                                        : method == "newton-pcg-amg" ? LinearSolverKind::pcg_amg
                                                                                     : LinearSolverKind::pcg_factor);
            } catch (const std::exception& e) {
                r.ok = false;
                r.note = e.what();
            }
            std::cout << method << " " << elements << " elements: first " << r.first_s << " s (" << r.iterations_first
                      << " it), update " << r.update_s << " s (" << r.iterations_update << " it), peak " << r.peak_mm << " mm "
                      << r.note << std::endl;
            rows.push_back({{"elements", elements}, {"dofs", 3 * model.node_count()}, {"method", method}, {"converged", r.ok},
                            {"first_solve_s", r.first_s}, {"update_s", r.update_s}, {"iterations_first", r.iterations_first},
                            {"iterations_update", r.iterations_update}, {"peak_displacement_mm", r.peak_mm}, {"note", r.note}});
            if (r.ok) points.push_back({double(elements), r.update_s});
        }
    }
    nlohmann::json slopes;
    for (const auto& [method, points] : measured) slopes[method] = slope(points);

    // Log-log plot of the update time.
    Canvas canvas(640, 420);
    const double x0 = 70, x1 = 610, y0 = 370, y1 = 30, lx0 = std::log10(5e3), lx1 = std::log10(2e6), ly0 = -3, ly1 = 3;
    const auto px = [&](double n) { return x0 + (std::log10(n) - lx0) / (lx1 - lx0) * (x1 - x0); };
    const auto py = [&](double t) { return y0 + (std::log10(std::max(t, 1e-3)) - ly0) / (ly1 - ly0) * (y1 - y0); };
    canvas.line(x0, y0, x1, y0, {0, 0, 0});
    canvas.line(x0, y0, x0, y1, {0, 0, 0});
    for (int e = -3; e <= 3; ++e) {
        canvas.line(x0 - 4, py(std::pow(10.0, e)), x0, py(std::pow(10.0, e)), {0, 0, 0});
        canvas.text(8, static_cast<int>(py(std::pow(10.0, e))) - 3, fmt::format("1E{}S", e), {0, 0, 0});
    }
    for (double n : {1e4, 1e5, 1e6}) {
        canvas.line(px(n), y0, px(n), y0 + 4, {0, 0, 0});
        canvas.text(static_cast<int>(px(n)) - 12, static_cast<int>(y0) + 10, fmt::format("1E{}", int(std::log10(n))), {0, 0, 0});
    }
    canvas.text(250, 400, "ELEMENTS (LOG)", {0, 0, 0});
    canvas.text(80, 8, "TIME PER TOOL UPDATE, 2 THREADS", {0, 0, 0});
    const std::map<std::string, Rgb> colours = {{"newton-cholmod", {200, 30, 30}}, {"newton-pcg-factor", {30, 120, 200}}, {"newton-pcg-amg", {200, 120, 20}}, {"relaxation", {40, 150, 40}}};
    int legend = 0;
    for (const auto& [method, points] : measured) {
        const Rgb c = colours.at(method);
        for (std::size_t k = 0; k < points.size(); ++k) {
            canvas.circle(px(points[k].first), py(points[k].second), 4, c);
            if (k > 0) canvas.line(px(points[k - 1].first), py(points[k - 1].second), px(points[k].first), py(points[k].second), c, 2);
        }
        std::string label = method;
        for (auto& ch : label) ch = static_cast<char>(std::toupper(ch));
        canvas.text(90, 40 + 14 * legend++, fmt::format("{} ALPHA = {:.2f}", label, slopes[method].get<double>()), c);
    }
    const std::string png = out.substr(0, out.rfind('.')) + ".png";
    write_png(png, canvas.image());

    const nlohmann::json result = {{"benchmark", "newton_scaling"},
                                   {"threads", std::getenv("OMP_NUM_THREADS") ? std::getenv("OMP_NUM_THREADS") : "default"},
                                   {"case", "n×n×n/2 block of 1 mm hexahedra, E 200 kPa, ν 0.49, base fixed; sphere radius n/6 pressed 1 mm "
                                            "(first solve), then 0.5 mm more (update, warm start)"},
                                   {"rows", rows},
                                   {"slope_alpha_update_time", slopes},
                                   {"plot", png}};
    write_atomically(out, [&](const std::filesystem::path& tmp) { std::ofstream(tmp) << result.dump(2) << "\n"; });
    return 0;
}
