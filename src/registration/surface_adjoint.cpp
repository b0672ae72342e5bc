// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/surface_adjoint.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/mechanics/linear_elasticity.hpp"

#include <lbfgs.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fmt/format.h>
#include <memory>
#include <set>

namespace physreg {

void AdjointSurfaceOptions::validate() const
{
    matching.validate();
    if (!(young_modulus_pa > 0) || !std::isfinite(young_modulus_pa)) fail("adjoint registration: Young's modulus {} Pa must be > 0", young_modulus_pa);
    if (!(poisson_ratio > -1 && poisson_ratio < 0.5)) fail("adjoint registration: Poisson's ratio {} outside (−1, 0.5)", poisson_ratio);
    if (!(noise_mm > 0) || !std::isfinite(noise_mm)) fail("adjoint registration: --noise {} mm must be > 0", noise_mm);
    if (!(discrepancy_factor >= 1) || !std::isfinite(discrepancy_factor)) fail("adjoint registration: discrepancy factor {} must be ≥ 1", discrepancy_factor);
    if (!(soft_spring_fraction > 0)) fail("adjoint registration: soft spring fraction {} must be > 0", soft_spring_fraction);
    if (alpha_steps < 1 || outer_iterations < 1 || lbfgs_iterations < 1)
        fail("adjoint registration: α steps {}, re-pairings {} and L-BFGS iterations {} must be ≥ 1", alpha_steps, outer_iterations, lbfgs_iterations);
}

namespace {

struct FixedPair {
    std::array<std::int32_t, 3> nodes{};
    std::array<double, 3> weights{};
    Vec3 normal = Vec3::Zero();
    Vec3 target = Vec3::Zero();
};

struct Problem {
    const VolumeMesh& mesh;
    std::unique_ptr<LinearElasticModel> model;
    std::vector<std::int32_t> unknown_nodes;     ///< free surface nodes
    std::vector<FixedPair> pairs;
    double alpha = 0.0;
    double scale = 1.0;                          ///< f = scale · v (N per unit of v)
    int solves = 0;
    Eigen::VectorXd f, u, g, lambda;
    std::vector<double> history;                 ///< J per L-BFGS iteration of the current run

    explicit Problem(const VolumeMesh& m) : mesh(m) {}

    /// J at unknowns v (scaled forces); gradient wrt v when `grad` is given.
    double evaluate(const double* v, double* grad)
    {
        const std::size_t n = 3 * mesh.node_count();
        f.setZero(static_cast<Eigen::Index>(n));
        for (std::size_t q = 0; q < unknown_nodes.size(); ++q)
            for (int d = 0; d < 3; ++d) f[3 * unknown_nodes[q] + d] = scale * v[3 * q + static_cast<std::size_t>(d)];
        model->solve(f, u);
        ++solves;
        g.setZero(static_cast<Eigen::Index>(n));
        double data = 0.0;
        const double inv = 1.0 / static_cast<double>(std::max<std::size_t>(1, pairs.size()));
        for (const auto& p : pairs) {
            Vec3 x = Vec3::Zero();
            for (int k = 0; k < 3; ++k) {
                const auto node = static_cast<std::size_t>(p.nodes[static_cast<std::size_t>(k)]);
                x += p.weights[static_cast<std::size_t>(k)] * (mesh.nodes[node] + Vec3(u[3 * node], u[3 * node + 1], u[3 * node + 2]));
            }
            const double r = p.normal.dot(x - p.target);
            data += 0.5 * inv * r * r;
            for (int k = 0; k < 3; ++k) {
                const auto node = static_cast<Eigen::Index>(p.nodes[static_cast<std::size_t>(k)]);
                for (int d = 0; d < 3; ++d) g[3 * node + d] += inv * r * p.weights[static_cast<std::size_t>(k)] * p.normal[d];
            }
        }
        const double energy = 0.5 * f.dot(u); // ½ uᵀ K u with K u = f at the free dofs, u = 0 at the held ones
        if (grad) {
            model->solve(g, lambda); // the adjoint: K symmetric
            ++solves;
            for (std::size_t q = 0; q < unknown_nodes.size(); ++q)
                for (int d = 0; d < 3; ++d) {
                    const auto dof = static_cast<Eigen::Index>(3 * unknown_nodes[q] + d);
                    grad[3 * q + static_cast<std::size_t>(d)] = scale * (lambda[dof] + alpha * u[dof]);
                }
        }
        return data + alpha * energy;
    }

    double rms_distance() const
    {
        double sum = 0.0;
        for (const auto& p : pairs) {
            Vec3 x = Vec3::Zero();
            for (int k = 0; k < 3; ++k) {
                const auto node = static_cast<std::size_t>(p.nodes[static_cast<std::size_t>(k)]);
                x += p.weights[static_cast<std::size_t>(k)] * (mesh.nodes[node] + Vec3(u[3 * node], u[3 * node + 1], u[3 * node + 2]));
            }
            sum += std::pow(p.normal.dot(x - p.target), 2);
        }
        return std::sqrt(sum / static_cast<double>(std::max<std::size_t>(1, pairs.size())));
    }
};

lbfgsfloatval_t evaluate_lbfgs(void* instance, const lbfgsfloatval_t* v, lbfgsfloatval_t* g, const int, const lbfgsfloatval_t)
{
    return static_cast<Problem*>(instance)->evaluate(v, g);
}

int record_progress(void* instance, const lbfgsfloatval_t*, const lbfgsfloatval_t*, const lbfgsfloatval_t fx, const lbfgsfloatval_t,
                    const lbfgsfloatval_t, const lbfgsfloatval_t, int, int, int)
{
    static_cast<Problem*>(instance)->history.push_back(fx);
    return 0;
}

void pair_at(Problem& problem, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud, const MatchingOptions& matching, const Eigen::VectorXd& u)
{
    const std::size_t n = problem.mesh.node_count();
    std::vector<double> x(3 * n);
    for (std::size_t i = 0; i < n; ++i)
        for (int d = 0; d < 3; ++d) x[3 * i + static_cast<std::size_t>(d)] = problem.mesh.nodes[i][d] + (u.size() ? u[static_cast<Eigen::Index>(3 * i + static_cast<std::size_t>(d))] : 0.0);
    MatchStatistics stats;
    const auto pairs = matcher.match(x, cloud, matching, &stats);
    if (pairs.empty())
        fail("adjoint registration: no pair left after pruning: {} of {} cloud points lie farther than {} mm from the model's surface", stats.pruned_far,
             stats.points, matching.max_distance_mm);
    problem.pairs.clear();
    for (const auto& p : pairs) {
        const auto& tri = matcher.source().triangles[static_cast<std::size_t>(p.triangle)];
        FixedPair q;
        q.nodes = tri;
        q.weights = p.weights;
        q.target = p.target;
        const auto at = [&](int k) { const auto i = 3 * static_cast<std::size_t>(tri[static_cast<std::size_t>(k)]); return Vec3(x[i], x[i + 1], x[i + 2]); };
        Vec3 normal = (at(1) - at(0)).cross(at(2) - at(0));
        q.normal = normal.norm() > 0 ? Vec3(normal.normalized()) : Vec3::UnitX();
        problem.pairs.push_back(q);
    }
}

std::unique_ptr<Problem> make_problem(const VolumeMesh& mesh, const SurfaceMatcher& matcher, const AdjointSurfaceOptions& options)
{
    auto problem = std::make_unique<Problem>(mesh);
    LinearElasticOptions elastic;
    elastic.default_poisson_ratio = options.poisson_ratio;
    elastic.fixed_nodes = options.fixed_nodes;
    if (options.fixed_nodes.empty()) {
        // No support: soft springs to rest at every node, so K is regular (BCF-FEM's idea).
        double edge = 0.0;
        std::size_t edges = 0;
        for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
            const auto cell = mesh.cell(c);
            for (std::size_t a = 0; a < cell.size(); ++a)
                for (std::size_t b = a + 1; b < cell.size(); ++b) edge += (mesh.nodes[static_cast<std::size_t>(cell[a])] - mesh.nodes[static_cast<std::size_t>(cell[b])]).norm(), ++edges;
        }
        elastic.anchor_stiffness_n_mm = options.soft_spring_fraction * options.young_modulus_pa * 1e-6 * edge / static_cast<double>(std::max<std::size_t>(1, edges));
    }
    problem->model = std::make_unique<LinearElasticModel>(mesh, elastic, "the adjoint registration's model");
    std::vector<double> moduli(problem->model->structure_count(), options.young_modulus_pa);
    problem->model->set_young_moduli(moduli);
    std::set<std::int32_t> surface;
    for (const auto& t : matcher.source().triangles) surface.insert(t.begin(), t.end());
    for (const auto node : surface)
        if (!problem->model->fixed()[static_cast<std::size_t>(node)]) problem->unknown_nodes.push_back(node);
    if (problem->unknown_nodes.empty()) fail("adjoint registration: every surface node is a support; no force is left to fit the cloud");
    problem->scale = problem->model->mean_diagonal_n_mm(); // v ≈ mm of motion per unit
    return problem;
}

} // namespace

double adjoint_surface_objective(const VolumeMesh& mesh, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                 const AdjointSurfaceOptions& options, double alpha, const std::vector<double>& f, std::vector<double>& gradient)
{
    options.validate();
    auto problem = make_problem(mesh, matcher, options);
    pair_at(*problem, matcher, cloud, options.matching, Eigen::VectorXd());
    problem->alpha = alpha;
    std::vector<double> v(3 * problem->unknown_nodes.size()), g(v.size());
    for (std::size_t q = 0; q < problem->unknown_nodes.size(); ++q)
        for (int d = 0; d < 3; ++d) v[3 * q + static_cast<std::size_t>(d)] = f[3 * static_cast<std::size_t>(problem->unknown_nodes[q]) + static_cast<std::size_t>(d)] / problem->scale;
    const double j = problem->evaluate(v.data(), g.data());
    gradient.assign(f.size(), 0.0);
    for (std::size_t q = 0; q < problem->unknown_nodes.size(); ++q)
        for (int d = 0; d < 3; ++d)
            gradient[3 * static_cast<std::size_t>(problem->unknown_nodes[q]) + static_cast<std::size_t>(d)] = g[3 * q + static_cast<std::size_t>(d)] / problem->scale;
    return j;
}

AdjointSurfaceResult register_surface_adjoint(const VolumeMesh& mesh, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                              const AdjointSurfaceOptions& options, const std::function<void(double, const std::string&)>& progress)
{
    const auto start = std::chrono::steady_clock::now();
    options.validate();
    auto problem = make_problem(mesh, matcher, options);
    AdjointSurfaceResult result;
    std::vector<double> v(3 * problem->unknown_nodes.size(), 0.0), best_v = v;
    pair_at(*problem, matcher, cloud, options.matching, Eigen::VectorXd());
    // α_0: the balance ½ mean r² against α ½ k u² for one dof of stiffness k (the mean diagonal)
    // gives u = d / (1 + α k P); start 10⁴ times stiffer than even.
    const double k = problem->model->mean_diagonal_n_mm();
    const double alpha0 = 1e4 / (k * static_cast<double>(problem->pairs.size()));
    const double target = options.discrepancy_factor * options.noise_mm;
    lbfgs_parameter_t parameters;
    lbfgs_parameter_init(&parameters);
    parameters.max_iterations = options.lbfgs_iterations;
    parameters.epsilon = 1e-6;
    parameters.max_linesearch = 20;
    for (int step = 0; step < options.alpha_steps; ++step) {
        problem->alpha = alpha0 * std::pow(10.0, -0.5 * step);
        AdjointRung rung;
        rung.alpha = problem->alpha;
        for (int outer = 0; outer < options.outer_iterations; ++outer) {
            if (outer > 0 || step > 0) pair_at(*problem, matcher, cloud, options.matching, problem->u);
            problem->history.clear();
            double fx = 0.0;
            const int status = lbfgs(static_cast<int>(v.size()), v.data(), &fx, evaluate_lbfgs, record_progress, problem.get(), &parameters);
            rung.lbfgs_iterations += static_cast<int>(problem->history.size());
            if (status < 0 && status != LBFGSERR_MAXIMUMITERATION && status != LBFGSERR_ROUNDING_ERROR) {
                std::string history;
                for (std::size_t h = problem->history.size() > 5 ? problem->history.size() - 5 : 0; h < problem->history.size(); ++h)
                    history += fmt::format("{}{:.6g}", history.empty() ? "" : ", ", problem->history[h]);
                result.warnings.push_back(fmt::format("α {:.3g}, re-pairing {}: L-BFGS stopped with code {} (last objective values: {})", problem->alpha,
                                                      outer, status, history.empty() ? "none" : history));
                logger()->warn("adjoint registration: {}", result.warnings.back());
            }
            problem->evaluate(v.data(), nullptr); // u at the final v
        }
        rung.rms_distance_mm = problem->rms_distance();
        rung.strain_energy_mj = 0.5 * problem->f.dot(problem->u);
        rung.pairs = static_cast<int>(problem->pairs.size());
        result.rungs.push_back(rung);
        logger()->debug("adjoint registration: α {:.3g}: RMS distance {:.3f} mm, strain energy {:.4g} mJ, {} L-BFGS iterations", rung.alpha,
                        rung.rms_distance_mm, rung.strain_energy_mj, rung.lbfgs_iterations);
        if (progress)
            progress(static_cast<double>(step + 1) / options.alpha_steps, fmt::format("α {:.3g}: RMS distance {:.2f} mm", rung.alpha, rung.rms_distance_mm));
        best_v = v;
        result.chosen = result.rungs.size() - 1;
        if (rung.rms_distance_mm <= target) {
            result.discrepancy_reached = true;
            break;
        }
    }
    problem->evaluate(best_v.data(), nullptr);
    result.displacement_mm.assign(problem->u.data(), problem->u.data() + problem->u.size());
    result.force_n.assign(problem->f.data(), problem->f.data() + problem->f.size());
    result.solves = problem->solves;
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
}

} // namespace physreg
