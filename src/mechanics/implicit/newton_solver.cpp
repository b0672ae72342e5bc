// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/implicit/newton_solver.hpp"

#include "mechanics/detail/timing.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>

namespace physreg {
using detail::seconds_since;
namespace {

using Clock = std::chrono::steady_clock;

// ∇²g of the signed distance to a tool at x (sphere and cylinder; flat tools have none).
Mat3 distance_hessian(const Indenter& tool, const Vec3& x, double s, const Vec3& normal)
{
    if (tool.shape == IndenterShape::sphere) {
        const double r = (x - tool.position(s)).norm();
        return r > 0 ? Mat3((Mat3::Identity() - normal * normal.transpose()) / r) : Mat3::Zero();
    }
    if (tool.shape == IndenterShape::cylinder) {
        const Vec3 d = x - tool.position(s);
        const double r = (d - d.dot(tool.axis) * tool.axis).norm();
        return r > 0 ? Mat3((Mat3::Identity() - normal * normal.transpose() - tool.axis * tool.axis.transpose()) / r) : Mat3::Zero();
    }
    return Mat3::Zero();
}

std::string history_text(const std::vector<double>& history)
{
    std::string text;
    const std::size_t first = history.size() > 12 ? history.size() - 12 : 0;
    if (first > 0) text += "…, ";
    for (std::size_t k = first; k < history.size(); ++k) text += fmt::format("{}{:.3g}", k > first ? ", " : "", history[k]);
    return text;
}

} // namespace

ContactTerm contact_term(const Indenter& tool, const Vec3& x, double s, double lambda, double eps, bool curvature)
{
    ContactTerm t;
    Vec3 point, normal;
    tool.closest_surface_point(x, s, point, normal);
    t.gap_mm = (x - point).dot(normal);
    t.pressure_n = std::max(0.0, lambda - eps * t.gap_mm);
    t.energy_mj = (t.pressure_n * t.pressure_n - lambda * lambda) / (2.0 * eps);
    if (t.pressure_n > 0.0) {
        t.gradient = -t.pressure_n * normal;
        t.hessian = eps * normal * normal.transpose();
        if (curvature) t.hessian -= t.pressure_n * distance_hessian(tool, x, s, normal);
        else t.hessian -= std::min(t.pressure_n, lambda) * distance_hessian(tool, x, s, normal);
    }
    return t;
}

void NewtonOptions::validate() const
{
    if (max_iterations < 1) fail("newton: max_iterations = {} must be ≥ 1", max_iterations);
    if (!(residual_tolerance > 0 && residual_tolerance < 1)) fail("newton: tolerance = {} must be in (0, 1)", residual_tolerance);
    if (max_load_cuts < 0) fail("newton: max_load_cuts = {} must be ≥ 0", max_load_cuts);
    if (!(contact_penalty_scale > 0 && std::isfinite(contact_penalty_scale)))
        fail("newton: contact_penalty_scale = {} must be > 0", contact_penalty_scale);
    if (!(penetration_tolerance_mm > 0)) fail("newton: penetration_tolerance_mm = {} must be > 0", penetration_tolerance_mm);
    if (max_contact_updates < 1) fail("newton: max_contact_updates = {} must be ≥ 1", max_contact_updates);
    linear.validate();
}

NewtonSolver::NewtonSolver(const TledModel& model, const NewtonOptions& options)
    : m_model(model), m_options(options), m_linear(options.linear)
{
    m_linear.set_node_coordinates(model.rest_positions());
    options.validate();
    m_assembler = std::make_unique<StiffnessAssembler>(model, nullptr);
    m_k = m_assembler->make_matrix();
    const std::size_t dofs = 3 * model.node_count();
    m_u.assign(dofs, 0.0);
    m_external.assign(dofs, 0.0);
    m_prescribed.assign(dofs, 0.0);
    m_constrained.assign(dofs, 0);
    for (auto node : model.surface_nodes()) m_penalty.push_back(options.contact_penalty_scale * model.stiffness_bound()[node]);
}

NewtonSolver::~NewtonSolver() = default;

void NewtonSolver::set_coupling(const PenaltyCoupling* coupling)
{
    m_coupling = coupling && !coupling->empty() ? coupling : nullptr;
    m_assembler = std::make_unique<StiffnessAssembler>(m_model, m_coupling);
    m_k = m_assembler->make_matrix();
    m_linear.invalidate();
}

void NewtonSolver::set_loads(Loads loads)
{
    loads.validate(m_model.node_count());
    m_loads = std::move(loads);
    std::fill(m_constrained.begin(), m_constrained.end(), 0);
    std::fill(m_prescribed.begin(), m_prescribed.end(), 0.0);
    for (const auto& c : m_loads.constraints)
        for (auto node : c.nodes)
            for (int d = 0; d < 3; ++d)
                if (c.dofs[d]) {
                    m_constrained[3 * node + d] = 1;
                    m_prescribed[3 * node + d] = c.displacement_mm[d];
                }
    std::fill(m_external.begin(), m_external.end(), 0.0);
    std::copy(m_loads.external_forces_n.begin(), m_loads.external_forces_n.end(), m_external.begin());
    m_multiplier.assign(m_loads.indenters.size(), std::vector<double>(m_model.surface_nodes().size(), 0.0));
}

void NewtonSolver::reset()
{
    std::fill(m_u.begin(), m_u.end(), 0.0);
    for (auto& m : m_multiplier) std::fill(m.begin(), m.end(), 0.0);
    m_load_factor = 0.0;
}

void NewtonSolver::set_displacement(const std::vector<double>& u)
{
    if (u.size() != m_u.size()) fail("displacement: {} values for {} nodes", u.size(), m_model.node_count());
    for (std::size_t k = 0; k < u.size(); ++k)
        if (!std::isfinite(u[k])) fail("displacement: node {} is not finite", k / 3);
    m_u = u;
}

std::vector<double> NewtonSolver::internal_forces_n() const
{
    std::vector<double> f(m_u.size());
    const Assembly a = m_assembler->assemble(m_u.data(), f.data(), nullptr);
    if (a.inverted_element >= 0) fail("internal forces: element {} is inverted", a.inverted_element);
    return f;
}

// A static solve needs every rigid-body mode held by a Dirichlet condition or a tool. Count the
// modes (3 translations, 3 rotations about the centroid) that the prescribed dofs leave free.
void NewtonSolver::check_constrained() const
{
    const auto& x = m_model.rest_positions();
    const std::size_t n = m_model.node_count();
    Vec3 centre = Vec3::Zero();
    for (std::size_t i = 0; i < n; ++i) centre += Vec3(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
    centre /= double(n);
    const double scale = std::max(m_model.diagonal_mm(), 1e-9);
    Eigen::Matrix<double, 6, 6> gram = Eigen::Matrix<double, 6, 6>::Zero();
    for (std::size_t k = 0; k < m_constrained.size(); ++k) {
        if (!m_constrained[k]) continue;
        const std::size_t i = k / 3;
        const int d = static_cast<int>(k % 3);
        const Vec3 r = (Vec3(x[3 * i], x[3 * i + 1], x[3 * i + 2]) - centre) / scale;
        Eigen::Matrix<double, 6, 1> row = Eigen::Matrix<double, 6, 1>::Zero();
        row[d] = 1.0;
        // Rotation about axis a moves the point by e_a × r; its d component:
        for (int a = 0; a < 3; ++a) row[3 + a] = Vec3::Unit(a).cross(r)[d];
        gram += row * row.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(gram);
    const double largest = std::max(eig.eigenvalues().maxCoeff(), 0.0);
    int free_modes = 0;
    for (int k = 0; k < 6; ++k)
        if (!(eig.eigenvalues()[k] > 1e-10 * largest) || largest == 0.0) ++free_modes;
    if (free_modes > 0 && m_loads.indenters.empty())
        fail("static solve: the model is not constrained: {} rigid-body mode(s) are free (fix enough nodes, or press it with a tool "
             "against fixed nodes)",
             free_modes);
}

double NewtonSolver::contact_terms(const std::vector<double>& u, double s, std::vector<double>& gradient, SparseMatrix* k, bool count)
{
    double energy = 0.0;
    const auto& surface = m_model.surface_nodes();
    const auto& rest = m_model.rest_positions();
    if (count) m_contact_count = 0;
    for (std::size_t t = 0; t < m_loads.indenters.size(); ++t) {
        const Indenter& tool = m_loads.indenters[t];
        const auto& lambda = m_multiplier[t];
        for (std::size_t q = 0; q < surface.size(); ++q) {
            const std::int32_t node = surface[q];
            const Vec3 x(rest[3 * node] + u[3 * node], rest[3 * node + 1] + u[3 * node + 1], rest[3 * node + 2] + u[3 * node + 2]);
            const double eps = m_penalty[q];
            // Far nodes with no multiplier carry nothing: skip the closest-point search.
            if (lambda[q] == 0.0 && std::isfinite(tool.reach_mm()) && (x - tool.position(s)).norm() > tool.reach_mm()) continue;
            const ContactTerm term = contact_term(tool, x, s, lambda[q], eps, m_options.exact_contact_curvature);
            energy += term.energy_mj;
            if (term.pressure_n <= 0.0) continue;
            if (count) ++m_contact_count;
            for (int d = 0; d < 3; ++d) gradient[3 * node + d] += term.gradient[d];
            if (k) {
                double* values = k->valuePtr();
                for (int c = 0; c < 3; ++c)
                    for (int r = 0; r < 3; ++r) values[m_assembler->value_index(node, node, r, c)] += term.hessian(r, c);
            }
        }
    }
    return energy;
}

bool NewtonSolver::evaluate(const std::vector<double>& u, double s, Evaluation& out, SparseMatrix* k, NewtonSummary& summary)
{
    auto start = Clock::now();
    out.internal.resize(u.size());
    const Assembly a = m_assembler->assemble(u.data(), out.internal.data(), k);
    (k ? summary.assembly_s : summary.line_search_s) += seconds_since(start);
    out.inverted = a.inverted_element;
    if (a.inverted_element >= 0) return false;
    if (a.non_finite_element >= 0)
        fail("newton: the internal force or tangent of element {} is not finite (NaN or inf): check the material "
             "parameters and the mesh there",
             a.non_finite_element);
    out.energy = a.energy_mj;
    out.gradient = out.internal;
    for (std::size_t i = 0; i < u.size(); ++i) {
        out.gradient[i] -= s * m_external[i];
        out.energy -= s * m_external[i] * u[i];
    }
    start = Clock::now();
    out.energy += contact_terms(u, s, out.gradient, k, k != nullptr);
    summary.contact_s += seconds_since(start);
    return true;
}

double NewtonSolver::max_penetration(double s) const
{
    double worst = 0.0;
    const auto& rest = m_model.rest_positions();
    for (const auto& tool : m_loads.indenters)
        for (auto node : m_model.surface_nodes()) {
            const Vec3 x(rest[3 * node] + m_u[3 * node], rest[3 * node + 1] + m_u[3 * node + 1], rest[3 * node + 2] + m_u[3 * node + 2]);
            Vec3 point, normal;
            if (tool.push_out(x, s, point, normal)) worst = std::max(worst, (point - x).norm());
        }
    return worst;
}

NewtonSolver::Outcome NewtonSolver::newton(double s, NewtonSummary& summary, std::string& why, std::int64_t& inverted,
                                           const ProgressCallback& progress)
{
    const std::size_t dofs = m_u.size();
    Evaluation now, trial;
    if (!evaluate(m_u, s, now, nullptr, summary)) {
        inverted = now.inverted;
        why = fmt::format("element {} is inverted at the start of the increment", now.inverted);
        return Outcome::inverted;
    }
    Eigen::VectorXd rhs(dofs), step(dofs);
    std::vector<double> recent;
    for (int it = 0;; ++it) {
        // Residual on free dofs; the prescribed dofs still to move.
        double residual = 0.0, reference = 0.0, pending = 0.0;
        for (std::size_t i = 0; i < dofs; ++i) {
            if (!std::isfinite(now.gradient[i])) fail("newton: the residual at node {} is not finite", i / 3);
            if (m_constrained[i]) pending = std::max(pending, std::abs(s * m_prescribed[i] - m_u[i]));
            else residual = std::max(residual, std::abs(now.gradient[i]));
        }
        for (std::size_t node = 0; node < dofs / 3; ++node)
            reference = std::max(reference, Vec3(now.internal[3 * node], now.internal[3 * node + 1], now.internal[3 * node + 2]).norm());
        reference = std::max(reference, 1e-12);
        summary.residual_n = residual;
        summary.reference_force_n = reference;
        if (it > 0) summary.residual_history.push_back(residual);
        if (pending == 0.0 && residual <= m_options.residual_tolerance * reference) return Outcome::converged;
        // With the multipliers behind the pressures, the tangent's curvature term is inexact and
        // Newton only creeps (see contact_term): hand back for a multiplier update (inexact ALM).
        if (m_allow_stall && pending == 0.0 && !m_loads.indenters.empty() && recent.size() >= 3 && residual > 0.5 * recent[recent.size() - 3])
            return Outcome::stalled;
        recent.push_back(residual);
        if (it == m_options.max_iterations) {
            why = fmt::format("Newton did not converge in {} iterations (largest free residual {:.3g} N, tolerance {:.3g} N; residual "
                              "history {})",
                              it, residual, m_options.residual_tolerance * reference, history_text(summary.residual_history));
            return Outcome::not_converged;
        }
        ++summary.newton_iterations;
        if (progress) progress(-1.0, summary.newton_iterations);

        // Tangent, lifting of the prescribed increment, and the reduced system (identity rows for constrained dofs).
        if (!evaluate(m_u, s, now, &m_k, summary)) {
            inverted = now.inverted;
            why = fmt::format("element {} is inverted", now.inverted);
            return Outcome::inverted;
        }
        double* values = m_k.valuePtr();
        const int* outer = m_k.outerIndexPtr();
        const int* inner = m_k.innerIndexPtr();
        for (std::size_t i = 0; i < dofs; ++i) rhs[i] = m_constrained[i] ? s * m_prescribed[i] - m_u[i] : -now.gradient[i];
        for (std::size_t c = 0; c < dofs; ++c) {
            if (!m_constrained[c]) continue;
            const double du = rhs[c];
            for (int p = outer[c]; p < outer[c + 1]; ++p) {
                const int r = inner[p];
                if (!m_constrained[r] && du != 0.0) rhs[r] -= values[p] * du;
            }
        }
        for (std::size_t c = 0; c < dofs; ++c)
            for (int p = outer[c]; p < outer[c + 1]; ++p) {
                const std::size_t r = static_cast<std::size_t>(inner[p]);
                if (m_constrained[c] || m_constrained[r]) values[p] = r == c ? 1.0 : 0.0;
            }
        const LinearSolveStats ls = m_linear.solve(m_k, rhs, step);
        summary.linear_iterations += ls.iterations;
        summary.factorisations += ls.factorised ? 1 : 0;
        summary.shifted_factorisations += ls.shift > 0 ? 1 : 0;
        summary.factorisation_s += ls.factorisation_s;
        summary.solve_s += ls.solve_s;
        if (!step.allFinite()) fail("newton: the linear solve gave a non-finite correction (singular tangent)");

        // Backtracking line search on Π. A step that moves prescribed dofs changes the constraint
        // manifold, so only non-inversion is asked of it (and it is taken whole or not at all).
        double slope = 0.0;
        for (std::size_t i = 0; i < dofs; ++i)
            if (!m_constrained[i]) slope += now.gradient[i] * step[i];
        const double noise = 1e-12 * (std::abs(now.energy) + 1e-12);
        std::vector<double> u_trial(dofs);
        double alpha = 1.0;
        bool accepted = false;
        for (int cut = 0; cut <= 20; ++cut, alpha *= 0.5) {
            for (std::size_t i = 0; i < dofs; ++i) u_trial[i] = m_u[i] + alpha * step[i];
            if (!evaluate(u_trial, s, trial, nullptr, summary)) {
                inverted = trial.inverted;
                if (pending > 0.0) break; // a shorter step would leave the boundary behind: cut the load increment instead
                continue;
            }
            if (pending > 0.0 || trial.energy <= now.energy + 1e-4 * alpha * std::min(slope, 0.0) + noise) {
                accepted = true;
                break;
            }
        }
        if (!accepted) {
            why = inverted >= 0 ? fmt::format("every Newton step inverts element {}", inverted)
                                : fmt::format("the line search found no decrease of the energy (slope {:.3g} mJ)", slope);
            return inverted >= 0 ? Outcome::inverted : Outcome::not_converged;
        }
        inverted = -1;
        m_u.swap(u_trial);
        std::swap(now, trial);
    }
}

NewtonSolver::Outcome NewtonSolver::solve_increment(double s, NewtonSummary& summary, std::string& why, std::int64_t& inverted,
                                                    const ProgressCallback& progress)
{
    const auto& surface = m_model.surface_nodes();
    const auto& rest = m_model.rest_positions();
    // Updates after convergence and updates on a stall are budgeted apart (max_contact_updates each).
    int stall_updates = 0;
    for (int update = 0;;) {
        m_allow_stall = m_options.update_contact_on_stall && stall_updates < m_options.max_contact_updates;
        const Outcome o = newton(s, summary, why, inverted, progress);
        if (o != Outcome::converged && o != Outcome::stalled) return o;
        if (m_loads.indenters.empty()) return o;
        const auto start = Clock::now();
        summary.max_penetration_mm = max_penetration(s);
        summary.contact_nodes = m_contact_count;
        if (o == Outcome::converged && summary.max_penetration_mm <= m_options.penetration_tolerance_mm) {
            summary.contact_s += seconds_since(start);
            return o;
        }
        if (o == Outcome::stalled) ++stall_updates;
        else if (update++ == m_options.max_contact_updates) {
            why = fmt::format("contact: {} augmented Lagrangian updates left a penetration of {:.3g} mm (tolerance {:.3g} mm)", m_options.max_contact_updates,
                              summary.max_penetration_mm, m_options.penetration_tolerance_mm);
            return Outcome::not_converged;
        }
        // λ ← max(0, λ − ε g): the pressure the penalty carried becomes the multiplier.
        for (std::size_t t = 0; t < m_loads.indenters.size(); ++t)
            for (std::size_t q = 0; q < surface.size(); ++q) {
                const std::int32_t node = surface[q];
                const Vec3 x(rest[3 * node] + m_u[3 * node], rest[3 * node + 1] + m_u[3 * node + 1], rest[3 * node + 2] + m_u[3 * node + 2]);
                Vec3 point, normal;
                m_loads.indenters[t].closest_surface_point(x, s, point, normal);
                m_multiplier[t][q] = std::max(0.0, m_multiplier[t][q] - m_penalty[q] * (x - point).dot(normal));
            }
        ++summary.contact_updates;
        summary.contact_s += seconds_since(start);
    }
}

NewtonSummary NewtonSolver::solve_equilibrium(double load_factor, const ProgressCallback& progress)
{
    const auto start = Clock::now();
    if (!std::isfinite(load_factor)) fail("newton: load factor {} is not finite", load_factor);
    check_constrained();
    NewtonSummary summary;
    summary.linear_solver = to_string(m_linear.options().kind);
    double from = m_load_factor, increment = load_factor - from;
    int consecutive = 0;
    for (;;) {
        const double to = std::abs(load_factor - from) <= std::abs(increment) * (1 + 1e-12) ? load_factor : from + increment;
        const std::vector<double> saved_u = m_u;
        const auto saved_multipliers = m_multiplier;
        std::string why;
        std::int64_t inverted = -1;
        const Outcome o = solve_increment(to, summary, why, inverted, progress);
        if (o == Outcome::converged) {
            ++summary.increments;
            from = m_load_factor = to;
            if (to == load_factor) break;
            if (++consecutive >= 2 && std::abs(2 * increment) <= std::abs(load_factor - from)) increment *= 2;
            continue;
        }
        m_u = saved_u;
        m_multiplier = saved_multipliers;
        consecutive = 0;
        if (summary.load_cuts == m_options.max_load_cuts) {
            summary.seconds = seconds_since(start);
            if (o == Outcome::inverted)
                fail("newton: element {} inverts at load factor {:.6g} even after {} halvings of the load increment: the load is too "
                     "large for this mesh, or a tool pushes a node through the surface",
                     inverted, to, summary.load_cuts);
            summary.converged = false;
            summary.message = fmt::format("load factor {:.6g}: {} (after {} halvings of the increment)", to, why, summary.load_cuts);
            return summary;
        }
        ++summary.load_cuts;
        increment *= 0.5;
        logger()->debug("newton: increment to load factor {:.6g} failed ({}); halving", to, why);
    }
    summary.converged = true;
    summary.contact_nodes = m_contact_count;
    summary.seconds = seconds_since(start);
    summary.message = fmt::format("converged: {} increment(s), {} Newton iteration(s), residual {:.3g} N ({:.2g} of the largest "
                                  "internal force)",
                                  summary.increments, summary.newton_iterations, summary.residual_n,
                                  summary.residual_n / summary.reference_force_n);
    return summary;
}

} // namespace physreg
