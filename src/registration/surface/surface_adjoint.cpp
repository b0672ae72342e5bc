// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/surface/surface_adjoint.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/mechanics/linear/linear_solver.hpp"
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"
#include "physreg/mechanics/elements/tled_model.hpp"
#include "physreg/registration/surface/surface_model.hpp"

#include <lbfgs.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
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
    if (!(support_stiffness_n_per_mm >= 0) || !std::isfinite(support_stiffness_n_per_mm))
        fail("adjoint registration: support stiffness {} N/mm must be ≥ 0 (0: held)", support_stiffness_n_per_mm);
    if (!(spring_grading >= 0 && spring_grading <= 8))
        fail("adjoint registration: spring grading exponent {} must lie in [0, 8] (0: uniform springs)", spring_grading);
    if (!(spring_stiffness_n_per_mm >= 0) || !std::isfinite(spring_stiffness_n_per_mm))
        fail("adjoint registration: spring stiffness {} N/mm must be ≥ 0 (0: the soft spring fraction)", spring_stiffness_n_per_mm);
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
    std::unique_ptr<TledModel> model;            ///< co-rotational linear tetrahedra
    std::unique_ptr<StiffnessAssembler> assembler;
    SymmetricSolver solver{[] { LinearSolverOptions o; o.kind = LinearSolverKind::cholmod; return o; }()};
    SparseMatrix k;                              ///< K_R(u_k) with the held dofs as identity rows
    std::vector<std::uint8_t> fixed;             ///< per dof
    double anchor = 0.0;                         ///< soft spring per dof (no support), N/mm
    std::vector<double> spring;                  ///< per dof, N/mm: the anchor everywhere, or elastic supports at their nodes
    std::vector<std::int32_t> unknown_nodes;     ///< free surface nodes
    std::vector<FixedPair> pairs;
    double alpha = 0.0;
    double scale = 1.0;                          ///< f = scale · v (N per unit of v)
    int solves = 0;
    // The linearisation point: u = u_k + K_R⁻¹ (f − f_int(u_k)) (lagged co-rotational; never moved
    // for the small-strain model), W ≈ W_k + f_int_k·Δ + ½ Δ·K_R Δ.
    Eigen::VectorXd u_k, f_int_k, c_k;           ///< c_k = K_R⁻¹ f_int_k
    double w_k = 0.0;
    Eigen::VectorXd f, u, g, lambda, rhs;
    std::vector<double> history;                 ///< J per L-BFGS iteration of the current run

    explicit Problem(const VolumeMesh& m) : mesh(m) {}

    void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x)
    {
        rhs = b;
        for (Eigen::Index i = 0; i < rhs.size(); ++i)
            if (fixed[static_cast<std::size_t>(i)]) rhs[i] = 0.0;
        solver.solve_factored(rhs, x);
        ++solves;
    }

    /// Re-linearises at `at` (the co-rotational model) or at rest.
    void linearise(const Eigen::VectorXd& at)
    {
        const auto n = static_cast<Eigen::Index>(3 * mesh.node_count());
        u_k = at.size() ? at : Eigen::VectorXd::Zero(n);
        f_int_k.setZero(n);
        const Assembly a = assembler->assemble(u_k.data(), f_int_k.data(), &k);
        if (a.inverted_element >= 0) fail("adjoint registration: element {} inverted at the linearisation point", a.inverted_element);
        w_k = a.energy_mj;
        for (Eigen::Index i = 0; i < n; ++i) {
            const double k_i = spring[static_cast<std::size_t>(i)];
            f_int_k[i] += k_i * u_k[i];
            w_k += 0.5 * k_i * u_k[i] * u_k[i];
        }
        // Held dofs: identity rows and columns (u stays 0 there); the soft springs on the diagonal.
        for (int c = 0; c < k.outerSize(); ++c)
            for (SparseMatrix::InnerIterator it(k, c); it; ++it) {
                const bool held = fixed[static_cast<std::size_t>(it.row())] || fixed[static_cast<std::size_t>(it.col())];
                if (held) it.valueRef() = it.row() == it.col() ? 1.0 : 0.0;
                else if (it.row() == it.col()) it.valueRef() += spring[static_cast<std::size_t>(it.row())];
            }
        solver.factorise(k);
        solve(f_int_k, c_k);
    }

    /// J at unknowns v (scaled forces); gradient wrt v when `grad` is given.
    double evaluate(const double* v, double* grad)
    {
        const std::size_t n = 3 * mesh.node_count();
        f.setZero(static_cast<Eigen::Index>(n));
        for (std::size_t q = 0; q < unknown_nodes.size(); ++q)
            for (int d = 0; d < 3; ++d) f[3 * unknown_nodes[q] + d] = scale * v[3 * q + static_cast<std::size_t>(d)];
        Eigen::VectorXd delta;
        solve(f - f_int_k, delta);
        u = u_k + delta;
        g.setZero(static_cast<Eigen::Index>(n));
        double data = 0.0;
        const double inv = 1.0 / static_cast<double>(std::max<std::size_t>(1, pairs.size()));
        for (const auto& p : pairs) {
            Vec3 x = Vec3::Zero();
            for (int k3 = 0; k3 < 3; ++k3) {
                const auto node = static_cast<std::size_t>(p.nodes[static_cast<std::size_t>(k3)]);
                x += p.weights[static_cast<std::size_t>(k3)] * (mesh.nodes[node] + Vec3(u[3 * node], u[3 * node + 1], u[3 * node + 2]));
            }
            const double r = p.normal.dot(x - p.target);
            data += 0.5 * inv * r * r;
            for (int k3 = 0; k3 < 3; ++k3) {
                const auto node = static_cast<Eigen::Index>(p.nodes[static_cast<std::size_t>(k3)]);
                for (int d = 0; d < 3; ++d) g[3 * node + d] += inv * r * p.weights[static_cast<std::size_t>(k3)] * p.normal[d];
            }
        }
        // W ≈ W_k + f_int_k·Δ + ½ Δ·K_R Δ with K_R Δ = f − f_int_k at the free dofs (Δ = 0 at held ones).
        const double energy = w_k + f_int_k.dot(delta) + 0.5 * delta.dot(f - f_int_k);
        if (grad) {
            solve(g, lambda); // the adjoint: K_R symmetric; ∂W/∂f = K_R⁻¹ f = Δ + c_k
            for (std::size_t q = 0; q < unknown_nodes.size(); ++q)
                for (int d = 0; d < 3; ++d) {
                    const auto dof = static_cast<Eigen::Index>(3 * unknown_nodes[q] + d);
                    grad[3 * q + static_cast<std::size_t>(d)] = scale * (lambda[dof] + alpha * (delta[dof] + c_k[dof]));
                }
        }
        last_energy = energy;
        return data + alpha * energy;
    }
    double last_energy = 0.0;

    double rms_distance() const
    {
        double sum = 0.0;
        for (const auto& p : pairs) {
            Vec3 x = Vec3::Zero();
            for (int k3 = 0; k3 < 3; ++k3) {
                const auto node = static_cast<std::size_t>(p.nodes[static_cast<std::size_t>(k3)]);
                x += p.weights[static_cast<std::size_t>(k3)] * (mesh.nodes[node] + Vec3(u[3 * node], u[3 * node + 1], u[3 * node + 2]));
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

/// Weights of the springs to rest, mean 1: w_i ∝ (d_i / median d)^p with d_i the rest node's
/// distance to the nearest cloud point (floored at a tenth of the median). Where the surface was
/// seen to move the organ is tied loosely; far from it, where a pushed organ is held, firmly
/// (issue 56: 4 public frames, p 1–4 measured, docs/registration.md). Brute force over the cloud,
/// as cloud_noise.cpp: 10^3–10^4 nodes × 10^2–10^4 points, once per registration.
std::vector<double> spring_weights_by_cloud_distance(const VolumeMesh& mesh, const std::vector<Vec3>& cloud, double exponent)
{
    const std::size_t n = mesh.node_count();
    if (cloud.empty()) fail("adjoint registration: graded springs need a non-empty cloud");
    std::vector<double> d(n);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t ii = 0; ii < static_cast<std::ptrdiff_t>(n); ++ii) {
        const auto i = static_cast<std::size_t>(ii);
        double best = std::numeric_limits<double>::infinity();
        for (const auto& q : cloud) best = std::min(best, (mesh.nodes[i] - q).squaredNorm());
        d[i] = std::sqrt(best);
    }
    std::vector<double> sorted = d;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(n / 2), sorted.end());
    const double median = sorted[n / 2];
    std::vector<double> w(n, 1.0);
    if (!(median > 0.0)) return w; // every node on the cloud: nothing to grade by
    double mean = 0.0;
    for (std::size_t i = 0; i < n; ++i) mean += (w[i] = std::pow(std::max(d[i], 0.1 * median) / median, exponent));
    mean /= static_cast<double>(n);
    for (auto& x : w) x /= mean;
    return w;
}

std::unique_ptr<Problem> make_problem(const VolumeMesh& mesh, const SurfaceMatcher& matcher, const AdjointSurfaceOptions& options, const LabelledPointCloud& cloud)
{
    auto problem = std::make_unique<Problem>(mesh);
    TledOptions tled;
    tled.law = MaterialLaw::corotational;
    VolumeMesh one = mesh;
    std::fill(one.cell_labels.begin(), one.cell_labels.end(), 1);
    problem->model = std::make_unique<TledModel>(one, homogeneous_liver_tissues(options.young_modulus_pa, options.poisson_ratio), tled);
    problem->assembler = std::make_unique<StiffnessAssembler>(*problem->model);
    problem->assembler->set_rotated_corotational_tangent(true); // R K₀ Rᵀ: symmetric positive definite
    problem->k = problem->assembler->make_matrix();
    const std::size_t n = mesh.node_count();
    problem->fixed.assign(3 * n, 0);
    problem->spring.assign(3 * n, 0.0);
    for (const auto node : options.fixed_nodes) {
        if (node < 0 || static_cast<std::size_t>(node) >= n) fail("adjoint registration: support node {} is not a node of the model", node);
        for (int d = 0; d < 3; ++d) {
            const std::size_t dof = 3 * static_cast<std::size_t>(node) + static_cast<std::size_t>(d);
            if (options.support_stiffness_n_per_mm > 0)
                problem->spring[dof] = options.support_stiffness_n_per_mm; // ligaments stretch: springs to rest
            else
                problem->fixed[dof] = 1;
        }
    }
    if (options.fixed_nodes.empty()) {
        // No support: soft springs to rest at every node, so K is regular (BCF-FEM's idea).
        double edge = 0.0;
        std::size_t edges = 0;
        for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
            const auto cell = mesh.cell(c);
            for (std::size_t a = 0; a < cell.size(); ++a)
                for (std::size_t b = a + 1; b < cell.size(); ++b) edge += (mesh.nodes[static_cast<std::size_t>(cell[a])] - mesh.nodes[static_cast<std::size_t>(cell[b])]).norm(), ++edges;
        }
        problem->anchor = options.spring_stiffness_n_per_mm > 0
                              ? options.spring_stiffness_n_per_mm
                              : options.soft_spring_fraction * options.young_modulus_pa * 1e-6 * edge / static_cast<double>(std::max<std::size_t>(1, edges));
        std::fill(problem->spring.begin(), problem->spring.end(), problem->anchor);
        if (options.spring_grading > 0.0) {
            const auto w = spring_weights_by_cloud_distance(mesh, cloud.points, options.spring_grading);
            for (std::size_t i = 0; i < n; ++i)
                for (std::size_t d = 0; d < 3; ++d) problem->spring[3 * i + d] = problem->anchor * w[i];
        }
    }
    std::set<std::int32_t> surface;
    for (const auto& t : matcher.source().triangles) surface.insert(t.begin(), t.end());
    if (!options.load_nodes.empty()) {
        // The tool's contact region: forces act there only (the peer's force patch, issue 56).
        std::set<std::int32_t> load;
        for (const auto node : options.load_nodes) {
            if (node < 0 || static_cast<std::size_t>(node) >= n) fail("adjoint registration: load node {} is not a node of the model", node);
            load.insert(node);
        }
        surface = std::move(load);
    }
    for (const auto node : surface)
        if (!problem->fixed[3 * static_cast<std::size_t>(node)]) problem->unknown_nodes.push_back(node);
    if (problem->unknown_nodes.empty())
        fail("adjoint registration: every {} node is a support; no force is left to fit the cloud", options.load_nodes.empty() ? "surface" : "load");
    problem->linearise(Eigen::VectorXd());
    double diagonal = 0.0;
    std::size_t free = 0;
    for (Eigen::Index i = 0; i < problem->k.cols(); ++i)
        if (!problem->fixed[static_cast<std::size_t>(i)]) diagonal += problem->k.coeff(i, i), ++free;
    problem->scale = diagonal / static_cast<double>(std::max<std::size_t>(1, free)); // v ≈ mm of motion per unit
    return problem;
}

} // namespace

double adjoint_surface_objective(const VolumeMesh& mesh, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                 const AdjointSurfaceOptions& options, double alpha, const std::vector<double>& f, std::vector<double>& gradient,
                                 const std::vector<double>* linearisation_mm)
{
    options.validate();
    auto problem = make_problem(mesh, matcher, options, cloud);
    if (linearisation_mm) {
        if (linearisation_mm->size() != 3 * mesh.node_count()) fail("adjoint objective: linearisation point of {} values", linearisation_mm->size());
        problem->linearise(Eigen::Map<const Eigen::VectorXd>(linearisation_mm->data(), static_cast<Eigen::Index>(linearisation_mm->size())));
    }
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
    auto problem = make_problem(mesh, matcher, options, cloud);
    AdjointSurfaceResult result;
    std::vector<double> v(3 * problem->unknown_nodes.size(), 0.0), best_v = v;
    pair_at(*problem, matcher, cloud, options.matching, Eigen::VectorXd());
    // α_0: the balance ½ mean r² against α ½ k u² for one dof of stiffness k (the mean diagonal)
    // gives u = d / (1 + α k P); start 10⁴ times stiffer than even.
    const double k = problem->scale; // the mean diagonal of K, N/mm
    const double alpha0 = 1e4 / (k * static_cast<double>(problem->pairs.size()));
    const double target = options.discrepancy_factor * options.noise_mm;
    lbfgs_parameter_t parameters;
    lbfgs_parameter_init(&parameters);
    parameters.max_iterations = options.lbfgs_iterations;
    parameters.epsilon = 1e-6;
    parameters.max_linesearch = 20;
    // Stop a re-pairing's L-BFGS once 5 iterations gained less than 1e-5 of the objective: every
    // run used to reach its 60 iterations (360 per α on the public liver, 10 of its 19 s) while the
    // pairs, about to be recomputed, bound the accuracy anyway (issue 56's time target).
    parameters.past = 5;
    parameters.delta = 1e-5;
    // The answer at the state in problem->u and problem->f.
    const auto finish = [&]() {
        result.displacement_mm.assign(problem->u.data(), problem->u.data() + problem->u.size());
        result.force_n.assign(problem->f.data(), problem->f.data() + problem->f.size());
        result.solves = problem->solves;
        result.spring_stiffness_n_per_mm = problem->anchor;
        result.spring_grading = options.fixed_nodes.empty() ? options.spring_grading : 0.0;
        result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        return result;
    };
    // α → ∞ first: where the model at rest already meets the cloud to the noise, no force is
    // warranted (the discrepancy principle's largest α is infinite). Without this the first rung's
    // stiff but finite α moved the organ by hundredths of a millimetre the data do not resolve.
    problem->u = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(3 * mesh.node_count()));
    problem->f = problem->u;
    if (const double rest_rms = problem->rms_distance(); rest_rms <= target) {
        AdjointRung rung;
        rung.alpha = std::numeric_limits<double>::infinity();
        rung.rms_distance_mm = rest_rms;
        rung.pairs = static_cast<int>(problem->pairs.size());
        result.rungs.push_back(rung);
        result.discrepancy_reached = result.at_rest_meets_noise = true;
        logger()->debug("adjoint registration: the model at rest meets the cloud to the noise (RMS {:.3f} ≤ {:.3f} mm): no force", rest_rms, target);
        if (progress) progress(1.0, fmt::format("at rest: RMS distance {:.2f} mm, within the noise", rest_rms));
        return finish();
    }
    for (int step = 0; step < options.alpha_steps; ++step) {
        problem->alpha = alpha0 * std::pow(10.0, -0.5 * step);
        AdjointRung rung;
        rung.alpha = problem->alpha;
        for (int outer = 0; outer < options.outer_iterations; ++outer) {
            if (outer > 0 || step > 0) {
                pair_at(*problem, matcher, cloud, options.matching, problem->u);
                if (options.corotational) {
                    // Lagged co-rotational: re-linearise at the current state, keep the forces.
                    problem->linearise(problem->u);
                }
            }
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
        rung.strain_energy_mj = problem->last_energy;
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
    for (std::size_t i = 0; i < problem->fixed.size(); ++i)
        if (problem->fixed[i]) problem->u[static_cast<Eigen::Index>(i)] = 0.0;
    return finish();
}

} // namespace physreg
