// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/implicit/backward_euler.hpp"

#include "mechanics/detail/timing.hpp"
#include "physreg/core/error.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace physreg {
using detail::seconds_since;
namespace {


double max_abs(const std::vector<double>& v)
{
    double m = 0.0;
    for (double x : v) m = std::max(m, std::abs(x));
    return m;
}

// ∫ N_a N_b dV of a trilinear hexahedron by 2×2×2 Gauss points (exact for the mass of a
// parallelepiped, and the usual rule otherwise).
std::array<double, 64> hexahedron_mass_integrals(const double* x) // x: 8 nodes × 3, mm
{
    std::array<double, 64> m{};
    const double g = 1.0 / std::sqrt(3.0);
    for (int q = 0; q < 8; ++q) {
        const Vec3 xi(q & 1 ? g : -g, q & 2 ? g : -g, q & 4 ? g : -g);
        const auto n = hex_shape_functions(xi);
        Mat3 jac = Mat3::Zero(); // ∂x/∂ξ
        for (int a = 0; a < 8; ++a) {
            const Vec3 c = hex_corner_natural(a);
            const Vec3 dn(c[0] * (1 + c[1] * xi[1]) * (1 + c[2] * xi[2]) / 8, c[1] * (1 + c[0] * xi[0]) * (1 + c[2] * xi[2]) / 8,
                          c[2] * (1 + c[0] * xi[0]) * (1 + c[1] * xi[1]) / 8);
            jac += Vec3(x[3 * a], x[3 * a + 1], x[3 * a + 2]) * dn.transpose();
        }
        const double w = jac.determinant(); // Gauss weights are 1
        for (int a = 0; a < 8; ++a)
            for (int b = 0; b < 8; ++b) m[8 * a + b] += w * n[a] * n[b];
    }
    return m;
}

} // namespace

MassKind parse_mass_kind(const std::string& text)
{
    if (text == "lumped") return MassKind::lumped;
    if (text == "consistent") return MassKind::consistent;
    fail("mass '{}' is not one of lumped, consistent", text);
}

std::string to_string(MassKind kind)
{
    return kind == MassKind::lumped ? "lumped" : "consistent";
}

TangentUpdate parse_tangent_update(const std::string& text)
{
    if (text == "every-iteration") return TangentUpdate::every_iteration;
    if (text == "every-step") return TangentUpdate::every_step;
    if (text == "stale") return TangentUpdate::stale;
    fail("tangent update '{}' is not one of every-iteration, every-step, stale", text);
}

std::string to_string(TangentUpdate update)
{
    switch (update) {
    case TangentUpdate::every_iteration: return "every-iteration";
    case TangentUpdate::every_step: return "every-step";
    default: return "stale";
    }
}

SparseMatrix assemble_mass_matrix(const StiffnessAssembler& assembler, MassKind kind)
{
    const TledModel& model = assembler.model();
    SparseMatrix mass = assembler.make_matrix();
    double* values = mass.valuePtr();
    if (kind == MassKind::lumped) {
        const auto& lumped = model.lumped_mass();
        for (std::size_t i = 0; i < model.node_count(); ++i)
            for (int d = 0; d < 3; ++d) values[assembler.value_index(static_cast<std::int32_t>(i), static_cast<std::int32_t>(i), d, d)] = lumped[i];
        return mass;
    }
    const int npe = model.nodes_per_element();
    const auto& connectivity = model.connectivity();
    const auto& rest = model.rest_positions();
    for (std::size_t e = 0; e < model.element_count(); ++e) {
        const std::int32_t* ids = connectivity.data() + npe * e;
        const double rho = model.materials()[model.element_material()[e]].density_t_mm3;
        std::array<double, 64> m{};
        if (npe == 4) {
            const double v = model.geometries()[model.element_geometry()[e]].volume_mm3;
            for (int a = 0; a < 4; ++a)
                for (int b = 0; b < 4; ++b) m[8 * a + b] = v / 20.0 * (a == b ? 2.0 : 1.0);
        } else {
            double x[24];
            for (int a = 0; a < 8; ++a)
                for (int d = 0; d < 3; ++d) x[3 * a + d] = rest[3 * ids[a] + d];
            m = hexahedron_mass_integrals(x);
        }
        for (int a = 0; a < npe; ++a)
            for (int b = 0; b < npe; ++b)
                for (int d = 0; d < 3; ++d) values[assembler.value_index(ids[a], ids[b], d, d)] += rho * m[8 * a + b];
    }
    return mass;
}

void BackwardEulerOptions::validate() const
{
    if (!(time_step_s > 0 && std::isfinite(time_step_s))) fail("backward Euler: time_step_s = {} must be > 0", time_step_s);
    if (!(rayleigh_mass_per_s >= 0 && std::isfinite(rayleigh_mass_per_s)))
        fail("backward Euler: rayleigh mass coefficient {} 1/s must be ≥ 0", rayleigh_mass_per_s);
    if (!(rayleigh_stiffness_s >= 0 && std::isfinite(rayleigh_stiffness_s)))
        fail("backward Euler: rayleigh stiffness coefficient {} s must be ≥ 0", rayleigh_stiffness_s);
    if (max_newton_iterations < 1) fail("backward Euler: max_newton_iterations = {} must be ≥ 1", max_newton_iterations);
    if (fixed_newton_iterations < 0) fail("backward Euler: newton_iterations = {} must be ≥ 0", fixed_newton_iterations);
    if (!(residual_tolerance > 0 && residual_tolerance < 1)) fail("backward Euler: tolerance = {} must be in (0, 1)", residual_tolerance);
    if (!(stale_contraction > 0 && stale_contraction < 1))
        fail("backward Euler: stale_contraction = {} must be in (0, 1)", stale_contraction);
}

namespace {
std::vector<std::vector<std::int32_t>> stencils_of(const std::vector<const AuxiliaryElements*>& auxiliary)
{
    std::vector<std::vector<std::int32_t>> all;
    for (const auto* a : auxiliary) {
        if (!a) fail("backward Euler: null auxiliary elements");
        auto s = a->stencils();
        all.insert(all.end(), std::make_move_iterator(s.begin()), std::make_move_iterator(s.end()));
    }
    return all;
}
} // namespace

BackwardEuler::BackwardEuler(const TledModel& model, const BackwardEulerOptions& options, const PenaltyCoupling* coupling,
                             std::vector<const AuxiliaryElements*> auxiliary)
    : m_model(model), m_options(options), m_auxiliary(std::move(auxiliary)), m_assembler(model, coupling, stencils_of(m_auxiliary)), m_linear([] {
          LinearSolverOptions linear;
          linear.kind = LinearSolverKind::cholmod;
          return linear;
      }())
{
    options.validate();
    m_assembler.set_rotated_corotational_tangent(options.rotated_corotational_tangent);
    if (model.options().density_scale != 1.0)
        fail("backward Euler: density_scale = {} is mass scaling for explicit dynamics; the implicit integrator needs the "
             "physical mass (density_scale 1)",
             model.options().density_scale);
    m_mass = assemble_mass_matrix(m_assembler, options.mass);
    if (options.mass == MassKind::lumped) {
        m_mass_diagonal.resize(m_assembler.dofs());
        for (std::size_t k = 0; k < m_mass_diagonal.size(); ++k) m_mass_diagonal[k] = model.lumped_mass()[k / 3];
    }
    m_k = m_assembler.make_matrix();
    m_jacobian = m_assembler.make_matrix();
    const std::size_t n = m_assembler.dofs();
    m_u.assign(n, 0.0);
    m_v.assign(n, 0.0);
    m_force.assign(n, 0.0);
    m_constrained.assign(n, 0);
    m_assembler.assemble(m_u.data(), m_force.data(), nullptr);
    for (const auto* a : m_auxiliary) a->add_forces(m_u.data(), m_force.data());
}

BackwardEuler::~BackwardEuler() = default;

void BackwardEuler::set_loads(Loads loads)
{
    loads.validate(m_model.node_count());
    if (!loads.indenters.empty())
        fail("backward Euler: rigid indenters ('{}') are not supported by the implicit dynamics yet; use the newton or "
             "explicit method",
             loads.indenters.front().name);
    std::vector<std::uint8_t> constrained(m_constrained.size(), 0);
    for (const auto& c : loads.constraints)
        for (auto node : c.nodes)
            for (int d = 0; d < 3; ++d)
                if (c.dofs[d]) constrained[3 * node + d] = 1;
    m_loads = std::move(loads);
    // New forces alone keep the factor (paper 001's registration changes them every step).
    if (constrained != m_constrained) {
        m_constrained.swap(constrained);
        m_have_factor = false;
    }
}

void BackwardEuler::set_body_acceleration(const Vec3& g)
{
    if (!g.allFinite()) fail("backward Euler: the body acceleration is not finite");
    m_gravity = g;
}

void BackwardEuler::set_external_stiffness(std::vector<double> diagonal)
{
    if (!diagonal.empty() && diagonal.size() != m_u.size())
        fail("backward Euler: external stiffness of {} values for {} dofs", diagonal.size(), m_u.size());
    for (std::size_t i = 0; i < diagonal.size(); ++i)
        if (!(diagonal[i] >= 0 && std::isfinite(diagonal[i]))) fail("backward Euler: external stiffness {} N/mm at dof {} must be finite and ≥ 0", diagonal[i], i);
    m_external_stiffness = std::move(diagonal);
}

void BackwardEuler::set_state(const std::vector<double>& u, const std::vector<double>& v, double time_s)
{
    if (u.size() != m_u.size() || v.size() != m_v.size())
        fail("backward Euler: state of {}/{} values for {} dofs", u.size(), v.size(), m_u.size());
    for (std::size_t i = 0; i < u.size(); ++i)
        if (!std::isfinite(u[i]) || !std::isfinite(v[i])) fail("backward Euler: state value {} is not finite", i);
    m_u = u;
    m_v = v;
    m_time = time_s;
    BackwardEulerStep scratch;
    if (!forces_if_valid(m_u, m_force, scratch))
        fail("backward Euler: the given state has an inverted element ({})", m_assembler.energy(m_u.data()).inverted_element);
}

double BackwardEuler::kinetic_energy_mj() const
{
    const Eigen::Map<const Eigen::VectorXd> v(m_v.data(), static_cast<Eigen::Index>(m_v.size()));
    return 0.5 * v.dot(m_mass * v); // tonne·mm²/s² = N·mm = mJ
}

double BackwardEuler::strain_energy_mj() const
{
    double energy = m_assembler.energy(m_u.data()).energy_mj;
    std::vector<double> scratch(m_u.size(), 0.0);
    for (const auto* a : m_auxiliary) energy += a->add_forces(m_u.data(), scratch.data());
    return energy;
}

void BackwardEuler::mass_times(const Eigen::VectorXd& v, Eigen::VectorXd& out) const
{
    if (m_mass_diagonal.empty()) {
        symmetric_product(m_mass, v, out);
        return;
    }
    out.resize(v.size());
    for (Eigen::Index k = 0; k < v.size(); ++k) out[k] = m_mass_diagonal[static_cast<std::size_t>(k)] * v[k];
}

bool BackwardEuler::forces_if_valid(const std::vector<double>& u, std::vector<double>& f, BackwardEulerStep& stats) const
{
    const auto start = std::chrono::steady_clock::now();
    const Assembly a = m_assembler.assemble(u.data(), f.data(), nullptr);
    if (a.inverted_element < 0)
        for (const auto* x : m_auxiliary) x->add_forces(u.data(), f.data());
    stats.force_s += seconds_since(start);
    if (a.inverted_element >= 0) return false;
    if (a.non_finite_element >= 0)
        fail("backward Euler: element {} has a non-finite force at t = {:.6g} s", a.non_finite_element, m_time + m_options.time_step_s);
    stats.inverted_elements = a.inverted_tolerated;
    return true;
}

void BackwardEuler::factorise_jacobian(const std::vector<double>& u, BackwardEulerStep& stats)
{
    auto start = std::chrono::steady_clock::now();
    std::vector<double> scratch(u.size());
    const Assembly a = m_assembler.assemble(u.data(), scratch.data(), &m_k);
    if (a.inverted_element < 0)
        for (const auto* x : m_auxiliary) x->add_stiffness(u.data(), m_assembler, m_k.valuePtr());
    if (a.inverted_element >= 0)
        fail("backward Euler: element {} inverted at t = {:.6g} s", a.inverted_element, m_time + m_options.time_step_s);
    if (a.non_finite_element >= 0)
        fail("backward Euler: element {} has a non-finite tangent at t = {:.6g} s", a.non_finite_element, m_time + m_options.time_step_s);
    const double dt = m_options.time_step_s;
    const double cm = 1.0 / dt + m_options.rayleigh_mass_per_s, ck = dt + m_options.rayleigh_stiffness_s;
    const Eigen::Index nnz = m_jacobian.nonZeros();
    double* j = m_jacobian.valuePtr();
    const double* k = m_k.valuePtr();
    const double* m = m_mass.valuePtr();
    for (Eigen::Index p = 0; p < nnz; ++p) j[p] = cm * m[p] + ck * k[p];
    if (!m_external_stiffness.empty())
        for (std::size_t i = 0; i < m_external_stiffness.size(); ++i) {
            const auto node = static_cast<std::int32_t>(i / 3);
            const int d = static_cast<int>(i % 3);
            j[m_assembler.value_index(node, node, d, d)] += dt * m_external_stiffness[i];
        }
    // Constrained dofs: identity rows and columns, scaled like the rest of the diagonal.
    double diagonal = 0.0;
    for (Eigen::Index c = 0; c < m_jacobian.cols(); ++c) diagonal += m_jacobian.coeff(c, c);
    diagonal /= static_cast<double>(m_jacobian.cols());
    for (Eigen::Index c = 0; c < m_jacobian.outerSize(); ++c)
        for (SparseMatrix::InnerIterator it(m_jacobian, c); it; ++it)
            if (m_constrained[c] || m_constrained[it.row()]) it.valueRef() = it.row() == c ? diagonal : 0.0;
    stats.assembly_s += seconds_since(start);
    // An indefinite Jacobian (the exact tangent of a strongly compressed or inverted co-rotational
    // element, buckling) is factored with a diagonal shift: the iterations then still converge on the
    // true residual, only more slowly; the shifted factorisations are counted.
    const LinearSolveStats s = m_linear.factorise(m_jacobian);
    if (s.shift > 0) ++stats.shifted_factorisations;
    stats.factorisation_s += s.factorisation_s;
    ++stats.factorisations;
    ++m_total_factorisations;
    m_have_factor = true;
    m_jacobian_time_step = dt;
}

bool BackwardEuler::attempt(BackwardEulerStep& stats, bool fresh_every_iteration)
{
    const double dt = m_options.time_step_s;
    const double t1 = m_time + dt, s1 = m_loads.load_factor(t1);
    const std::size_t n = m_u.size();
    const double alpha = m_options.rayleigh_mass_per_s, beta_dt = m_options.rayleigh_stiffness_s / dt;

    std::vector<double> f_ext(n, 0.0);
    const auto& lumped = m_model.lumped_mass();
    for (std::size_t i = 0; i < n; ++i)
        f_ext[i] = s1 * ((m_loads.external_forces_n.empty() ? 0.0 : m_loads.external_forces_n[i]) + lumped[i / 3] * m_gravity[i % 3]);

    // Start from v = 0 on free dofs; constrained dofs move to their prescribed position at t1.
    std::vector<double> v(n, 0.0), u(n), f(n), r(n);
    for (const auto& c : m_loads.constraints)
        for (auto node : c.nodes)
            for (int d = 0; d < 3; ++d)
                if (c.dofs[d]) v[3 * node + d] = (s1 * c.displacement_mm[d] - m_u[3 * node + d]) / dt;
    const bool starts_at_rest = max_abs(v) == 0.0;

    const Eigen::Map<const Eigen::VectorXd> v_old(m_v.data(), static_cast<Eigen::Index>(n));
    Eigen::VectorXd mass_v_old;
    mass_times(v_old, mass_v_old);
    double reference = max_abs(f_ext);
    for (Eigen::Index i = 0; i < mass_v_old.size(); ++i) reference = std::max(reference, std::abs(mass_v_old[i]) / dt);
    reference = std::max(reference, max_abs(m_force));

    const int fixed = m_options.fixed_newton_iterations;
    const int limit = fixed > 0 ? fixed : m_options.max_newton_iterations;
    Eigen::VectorXd vv, mass_v, rhs, dv;
    double previous = -1.0;
    bool refactored_last = false;
    stats.residual_history.clear();
    for (std::size_t i = 0; i < n; ++i) u[i] = m_u[i] + dt * v[i];
    if (starts_at_rest)
        f = m_force;
    else if (!forces_if_valid(u, f, stats))
        fail("backward Euler: the prescribed motion inverts element(s) at t = {:.6g} s", t1);
    std::vector<double> v_try(n), u_try(n), f_try(n);
    for (int k = 0;; ++k) {
        vv = Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(n));
        mass_times(vv, mass_v);
        double norm = 0.0;
        for (std::size_t i = 0; i < n; ++i) {
            r[i] = m_constrained[i] ? 0.0
                                    : (mass_v[i] - mass_v_old[i]) / dt + alpha * mass_v[i] + (1.0 + beta_dt) * f[i] -
                                          beta_dt * m_force[i] - f_ext[i] +
                                          (m_external_stiffness.empty() ? 0.0 : m_external_stiffness[i] * dt * v[i]);
            if (!std::isfinite(r[i])) fail("backward Euler: non-finite residual at dof {} (node {}) at t = {:.6g} s", i, i / 3, t1);
            norm = std::max(norm, std::abs(r[i]));
        }
        reference = std::max(reference, max_abs(f));
        stats.residual_history.push_back(norm);
        stats.residual_n = norm;
        stats.reference_force_n = reference;
        const bool converged = fixed > 0 ? k == fixed : norm <= m_options.residual_tolerance * reference;
        if (converged || norm == 0.0) {
            stats.converged = true;
            break;
        }
        if (k == limit) {
            stats.converged = false;
            return false;
        }
        // A factor made in the last iteration that still converges slowly is not improved by another.
        const bool stale_and_slow = m_options.tangent == TangentUpdate::stale && previous > 0 && !refactored_last &&
                                    norm > m_options.stale_contraction * previous;
        const bool refresh = fresh_every_iteration || !m_have_factor || m_jacobian_time_step != dt ||
                             m_options.tangent == TangentUpdate::every_iteration ||
                             (m_options.tangent == TangentUpdate::every_step && k == 0) || stale_and_slow;
        if (refresh) factorise_jacobian(u, stats);
        refactored_last = refresh;
        previous = norm;
        rhs = -Eigen::Map<const Eigen::VectorXd>(r.data(), static_cast<Eigen::Index>(n));
        const LinearSolveStats s = m_linear.solve_factored(rhs, dv);
        stats.solve_s += s.solve_s;
        ++stats.newton_iterations;
        // A full step that would invert an element (an overshooting sliver) is halved, up to 10 times.
        bool accepted = false;
        for (double step = 1.0; !accepted && step > 1e-3; step *= 0.5) {
            for (std::size_t i = 0; i < n; ++i) {
                v_try[i] = m_constrained[i] ? v[i] : v[i] + step * dv[static_cast<Eigen::Index>(i)];
                u_try[i] = m_u[i] + dt * v_try[i];
            }
            accepted = forces_if_valid(u_try, f_try, stats);
        }
        if (!accepted) {
            std::int64_t element = m_assembler.energy(u_try.data()).inverted_element;
            fail("backward Euler: element {} inverts at t = {:.6g} s whatever the length of the Newton step; reduce the time "
                 "step or the load, or add damping",
                 element, t1);
        }
        v.swap(v_try);
        u.swap(u_try);
        f.swap(f_try);
    }
    m_u = u;
    m_v = v;
    m_force = f;
    m_time = t1;
    return true;
}

BackwardEulerStep BackwardEuler::step()
{
    const auto start = std::chrono::steady_clock::now();
    BackwardEulerStep stats;
    if (!attempt(stats, false)) {
        if (m_options.tangent == TangentUpdate::every_iteration || !attempt(stats, true)) {
            std::string history;
            for (double r : stats.residual_history) history += fmt::format(" {:.3g}", r);
            fail("backward Euler: step to t = {:.6g} s did not converge in {} Newton iterations (largest residual{} N; "
                 "tolerance {:.3g} N); reduce the time step",
                 m_time + m_options.time_step_s, m_options.max_newton_iterations, history,
                 m_options.residual_tolerance * stats.reference_force_n);
        }
    }
    stats.seconds = seconds_since(start);
    return stats;
}

} // namespace physreg
