// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/explicit/tled_solver.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "mechanics/detail/hexahedron_kernel.hpp"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <omp.h>

namespace physreg {
namespace {

constexpr std::size_t BLOCK = 3 * 1024; // degrees of freedom per reduction block

template <typename Real>
inline void tetrahedron_deformation(const std::int32_t* ids, const Real* u, const Real* b, Real* F)
{
    for (int k = 0; k < 9; ++k) F[k] = (k % 4 == 0) ? Real(1) : Real(0);
    for (int a = 0; a < 4; ++a) {
        const Real* ua = u + 3 * static_cast<std::size_t>(ids[a]);
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) F[3 * r + c] += ua[r] * b[3 * a + c];
    }
}

template <typename Real>
inline Real tetrahedron_forces(const std::int32_t* ids, const Real* u, const Real* b, Real volume, MaterialLaw law,
                               Real mu, Real lambda, Real kappa, Real* f, Real volumetric_j = Real(0))
{
    Real F[9];
    tetrahedron_deformation(ids, u, b, F);
    Real P[9];
    const Real j = first_piola_kirchhoff(law, mu, lambda, kappa, F, P, volumetric_j);
    for (int a = 0; a < 4; ++a) {
        Real* fa = f + 3 * static_cast<std::size_t>(ids[a]);
        for (int r = 0; r < 3; ++r)
            fa[r] += volume * (P[3 * r] * b[3 * a] + P[3 * r + 1] * b[3 * a + 1] + P[3 * r + 2] * b[3 * a + 2]);
    }
    return j;
}

/// Contact nodes: only the tangential part of the residual s r − f counts (frictionless contact), N.
template <typename Real>
double tangential_contact_residual(const std::vector<std::int32_t>& nodes, const std::vector<Vec3>& normals, const std::vector<std::uint8_t>& constrained,
                                   const Real* r, const Real* fn, Real s)
{
    double residual = 0.0;
    for (std::size_t c = 0; c < nodes.size(); ++c) {
        const std::size_t node = static_cast<std::size_t>(nodes[c]);
        Vec3 res;
        for (int d = 0; d < 3; ++d) res[d] = constrained[3 * node + d] ? 0.0 : double(s * r[3 * node + d] - fn[3 * node + d]);
        res -= res.dot(normals[c]) * normals[c];
        residual = std::max(residual, res.cwiseAbs().maxCoeff());
    }
    return residual;
}

/// A node held by a tool keeps its sliding (tangential) momentum and loses the normal one: its
/// previous position is moved so that u − u_prev is the tangential part of its last increment.
template <typename Real>
void keep_tangential_momentum(const std::vector<std::int32_t>& nodes, const std::vector<Vec3>& normals, const std::vector<Real>& u, std::vector<Real>& u_prev)
{
    for (std::size_t c = 0; c < nodes.size(); ++c) {
        const std::size_t node = static_cast<std::size_t>(nodes[c]);
        const Vec3& n = normals[c];
        Vec3 v;
        for (int d = 0; d < 3; ++d) v[d] = double(u[3 * node + d]) - double(u_prev[3 * node + d]);
        const Vec3 tangential = v - v.dot(n) * n;
        for (int d = 0; d < 3; ++d) u_prev[3 * node + d] = static_cast<Real>(double(u[3 * node + d]) - tangential[d]);
    }
}

/// The distance still to go, mm, from the largest increments' contraction rate ρ over the last 20
/// iterations: ρ / (1 − ρ) × the last increment (a geometric series); infinite while not contracting.
double distance_to_equilibrium(const std::vector<double>& increment_history)
{
    const double increment = increment_history.back();
    double rho = 1.0;
    const std::size_t window = 20;
    if (increment_history.size() > window) {
        const double old = increment_history[increment_history.size() - 1 - window];
        if (old > 0) rho = std::pow(increment / old, 1.0 / double(window));
    }
    return rho < 1.0 ? rho / (1.0 - rho) * increment : std::numeric_limits<double>::infinity();
}

} // namespace

void EquilibriumOptions::validate() const
{
    if (max_iterations < 1) fail("max_iterations = {} must be ≥ 1", max_iterations);
    if (!(displacement_tolerance_mm > 0)) fail("displacement_tolerance_mm = {} must be > 0", displacement_tolerance_mm);
    if (!(residual_tolerance > 0)) fail("residual_tolerance = {} must be > 0", residual_tolerance);
    if (!(mass_safety >= 1.0)) fail("mass_safety = {} must be ≥ 1", mass_safety);
}

template <typename Real>
TledSolver<Real>::TledSolver(const TledModel& model) : m_model(model), m_n(model.node_count())
{
    if (model.options().law == MaterialLaw::mooney_rivlin)
        fail("material law mooney-rivlin: only the implicit solvers (newton, backward-euler) implement it, not TLED explicit "
             "dynamics or dynamic relaxation");
    m_team = m_governor.threads();
    const int npe = model.nodes_per_element();
    for (const auto& g : model.geometries()) {
        for (int k = 0; k < 3 * npe; ++k) m_dn.push_back(static_cast<Real>(g.dn_dx[k]));
        for (int k = 0; k < 32; ++k) m_gamma.push_back(static_cast<Real>(g.gamma[k]));
        m_volume.push_back(static_cast<Real>(g.volume_mm3));
        m_vb2.push_back(static_cast<Real>(g.volume_mm3 * g.b_squared));
    }
    for (const auto& m : model.materials()) {
        m_mu.push_back(static_cast<Real>(m.mu_mpa));
        m_lambda.push_back(static_cast<Real>(m.lambda_mpa));
        m_kappa.push_back(static_cast<Real>(m.kappa_mpa));
        m_hourglass.push_back(static_cast<Real>(model.options().hourglass_kappa * hourglass_modulus_mpa(model.options(), m) / 8.0));
    }
    m_rest.assign(model.rest_positions().begin(), model.rest_positions().end());
    if (model.options().averaged_nodal_pressure) {
        m_nodal_j.assign(m_n, 1);
        m_inverse_nodal_volume.resize(m_n);
        for (std::size_t i = 0; i < m_n; ++i) m_inverse_nodal_volume[i] = static_cast<Real>(1.0 / model.nodal_volume()[i]);
    }
    const std::size_t dofs = 3 * m_n;
    m_u.assign(dofs, 0);
    m_u_prev.assign(dofs, 0);
    m_u_next.assign(dofs, 0);
    m_force.assign(dofs, 0);
    m_force_prev.assign(dofs, 0);
    m_external.assign(dofs, 0);
    m_constrained.assign(dofs, 0);
    m_prescribed.assign(dofs, 0);
    m_stiffness_bound = model.stiffness_bound();
    m_time_step = model.time_step_s();
    // Box elements (hexahedron_kernel.hpp): one shared geometry with b_a = M s_a, s_a the corner
    // signs of the mesher's corner order, and hourglass vectors ± the four sign products.
    if (npe == 8 && model.geometries().size() == 1 && model.options().box_elements) {
        const auto& g = model.geometries()[0];
        static constexpr int sign[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1}, {-1, -1, 1}, {1, -1, 1}, {1, 1, 1}, {-1, 1, 1}};
        double m[9] = {}, largest_b = 0.0;
        for (int a = 0; a < 8; ++a)
            for (int j = 0; j < 3; ++j) {
                largest_b = std::max(largest_b, std::abs(g.dn_dx[3 * a + j]));
                for (int k = 0; k < 3; ++k) m[3 * j + k] += g.dn_dx[3 * a + j] * sign[a][k] / 8.0; // Σ_a s_a s_aᵀ = 8 I
            }
        bool box = largest_b > 0;
        for (int a = 0; a < 8 && box; ++a)
            for (int j = 0; j < 3; ++j) {
                const double fitted = m[3 * j] * sign[a][0] + m[3 * j + 1] * sign[a][1] + m[3 * j + 2] * sign[a][2];
                box = box && std::abs(fitted - g.dn_dx[3 * a + j]) <= 1e-10 * largest_b;
            }
        // Each hourglass vector must be ± one of the sign products xy, yz, zx, xyz, each used once.
        int used = 0;
        for (int alpha = 0; alpha < 4 && box; ++alpha) {
            bool matched = false;
            for (int bits : {3, 5, 6, 7}) {
                double sigma = 0.0;
                bool same = true;
                for (int a = 0; a < 8; ++a) {
                    double p = 1.0;
                    for (int d = 0; d < 3; ++d)
                        if ((bits >> d) & 1) p *= sign[a][d];
                    if (a == 0) sigma = g.gamma[4 * a + alpha] * p;
                    same = same && std::abs(g.gamma[4 * a + alpha] - sigma * p) <= 1e-10;
                }
                if (same && std::abs(std::abs(sigma) - 1.0) <= 1e-10 && !(used & (1 << bits))) {
                    used |= 1 << bits;
                    matched = true;
                    break;
                }
            }
            box = matched;
        }
        if (box) {
            m_box = true;
            m_box_m.assign(m, m + 9);
        }
    }
    // Runs: positions in the element order from which the next elements' nodes all advance by one
    // (a grid row numbered along x). m_run_length[k] counts them, within k's chunk.
    if (npe == 8) {
        const auto& order = model.element_order();
        const auto& conn = model.connectivity();
        m_run_length.assign(order.size(), 1);
        for (const auto& phase : model.phases())
            for (const auto& chunk : phase)
                for (std::int64_t k = chunk.end - 2; k >= chunk.begin; --k) {
                    const std::int32_t* a = conn.data() + 8 * static_cast<std::size_t>(order[k]);
                    const std::int32_t* b = conn.data() + 8 * static_cast<std::size_t>(order[k + 1]);
                    bool shifted = true;
                    for (int n = 0; n < 8; ++n) shifted = shifted && b[n] == a[n] + 1;
                    if (shifted) m_run_length[k] = m_run_length[k + 1] + 1;
                }
        // The batches the force loop will form (see forces_in_parallel_region): count their elements.
        constexpr std::int32_t shortest_run = 8, width = 16;
        for (const auto& phase : model.phases())
            for (const auto& chunk : phase)
                for (std::int64_t k = chunk.begin; k < chunk.end;) {
                    if (m_run_length[k] >= shortest_run) {
                        const std::int64_t taken = std::min<std::int64_t>({width, m_run_length[k], chunk.end - k});
                        m_run_elements += static_cast<std::size_t>(taken);
                        k += taken;
                    } else {
                        ++k;
                    }
                }
    }
}

template <typename Real>
void TledSolver<Real>::set_coupling(const PenaltyCoupling* coupling)
{
    if (coupling && coupling->node_count() != m_n)
        fail("coupling built for {} nodes, the model has {}", coupling->node_count(), m_n);
    m_coupling = coupling && !coupling->empty() ? coupling : nullptr;
    m_stiffness_bound = m_model.stiffness_bound();
    m_time_step = m_model.time_step_s();
    if (!m_coupling) return;
    // Stable step: ω_max² ≤ ω_elements² + max_j (coupling row bound / m_j) (the largest eigenvalue of
    // a sum of symmetric matrices is at most the sum of the largest ones).
    const auto bound = m_coupling->stiffness_bound();
    double omega2 = 0.0;
    for (std::size_t j = 0; j < m_n; ++j) {
        m_stiffness_bound[j] += bound[j];
        omega2 = std::max(omega2, bound[j] / m_model.lumped_mass()[j]);
    }
    const double omega_elements = 2.0 / m_model.critical_time_step_s();
    m_time_step = m_model.options().time_step_safety * 2.0 / std::sqrt(omega_elements * omega_elements + omega2);
}

template <typename Real>
void TledSolver<Real>::set_loads(Loads loads)
{
    loads.validate(m_n);
    m_loads = std::move(loads);
    std::fill(m_constrained.begin(), m_constrained.end(), 0);
    std::fill(m_prescribed.begin(), m_prescribed.end(), Real(0));
    for (const auto& c : m_loads.constraints)
        for (auto node : c.nodes)
            for (int d = 0; d < 3; ++d)
                if (c.dofs[d]) {
                    m_constrained[3 * node + d] = 1;
                    m_prescribed[3 * node + d] = static_cast<Real>(c.displacement_mm[d]);
                }
    m_constrained_dofs.clear();
    for (std::size_t k = 0; k < m_constrained.size(); ++k)
        if (m_constrained[k]) m_constrained_dofs.push_back(static_cast<std::int64_t>(k));
    std::fill(m_external.begin(), m_external.end(), Real(0));
    for (std::size_t k = 0; k < m_loads.external_forces_n.size(); ++k) m_external[k] = static_cast<Real>(m_loads.external_forces_n[k]);
}

template <typename Real>
void TledSolver<Real>::reset()
{
    std::fill(m_u.begin(), m_u.end(), Real(0));
    std::fill(m_u_prev.begin(), m_u_prev.end(), Real(0));
    m_load_factor = 0.0;
    m_time = 0.0;
    m_steps = 0;
}

template <typename Real>
void TledSolver<Real>::set_displacement(const std::vector<double>& u)
{
    if (u.size() != 3 * m_n) fail("displacement: {} values for {} nodes", u.size(), m_n);
    for (std::size_t k = 0; k < u.size(); ++k) {
        if (!std::isfinite(u[k])) fail("displacement: node {} is not finite", k / 3);
        m_u[k] = m_u_prev[k] = static_cast<Real>(u[k]);
    }
}

template <typename Real>
std::vector<double> TledSolver<Real>::displacement_mm() const
{
    return {m_u.begin(), m_u.end()};
}

template <typename Real>
std::vector<double> TledSolver<Real>::internal_forces_n()
{
    compute_internal_forces(m_u.data(), m_force.data());
    return {m_force.begin(), m_force.end()};
}

template <typename Real>
void TledSolver<Real>::compute_internal_forces(const Real* u, Real* f)
{
    m_inverted_element = LONG_MAX;
#pragma omp parallel num_threads(m_team)
    forces_in_parallel_region(u, f, true);
    if (m_inverted_element == LONG_MAX) m_inverted_element = -1;
}

// Called by every thread of a parallel region (orphaned work-sharing). Records the smallest
// inverted element in m_inverted_element (LONG_MAX: none).
template <typename Real>
void TledSolver<Real>::forces_in_parallel_region(const Real* u, Real* f, bool zero_first)
{
    const std::size_t dofs = 3 * m_n;
    const int npe = m_model.nodes_per_element();
    const std::int32_t* connectivity = m_model.connectivity().data();
    const std::uint16_t* material = m_model.element_material().data();
    const std::int32_t* geometry = m_model.element_geometry().data();
    const MaterialLaw law = m_model.options().law;
    const bool shared_geometry = m_model.geometries().size() == 1;
    const detail::HexBatchData data{connectivity, material, geometry, m_box ? m_box_m.data() : nullptr};
    long inverted = LONG_MAX;
    if (zero_first) {
#pragma omp for schedule(static)
        for (std::size_t k = 0; k < dofs; ++k) f[k] = 0;
    }
    const std::int32_t* order = m_model.element_order().data();
    const bool anp = npe == 4 && m_model.options().averaged_nodal_pressure;
    if (anp) {
        // Averaged nodal pressure, pass 1: J̄ at the nodes = Σ V_e J_e / 4 / Σ V_e / 4.
        Real* nodal = m_nodal_j.data();
#pragma omp for schedule(static)
        for (std::size_t i = 0; i < m_n; ++i) nodal[i] = 0;
        for (const auto& phase : m_model.phases()) {
            const long chunks = static_cast<long>(phase.size());
#pragma omp for schedule(static)
            for (long chunk = 0; chunk < chunks; ++chunk)
                for (std::int64_t k = phase[chunk].begin; k < phase[chunk].end; ++k) {
                    const std::int32_t e = order[k];
                    const std::int32_t g = geometry[e];
                    const std::int32_t* ids = connectivity + 4 * static_cast<std::size_t>(e);
                    Real F[9];
                    tetrahedron_deformation(ids, u, m_dn.data() + 12 * g, F);
                    const Real j = F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
                                   F[2] * (F[3] * F[7] - F[4] * F[6]);
                    for (int a = 0; a < 4; ++a) nodal[ids[a]] += m_volume[g] * j / Real(4);
                }
        }
#pragma omp for schedule(static)
        for (std::size_t i = 0; i < m_n; ++i) nodal[i] *= m_inverse_nodal_volume[i];
    }
    auto run_chunk = [&](const TledModel::Chunk& chunk) {
        const std::int64_t begin = chunk.begin, end = chunk.end;
        if (npe == 8) {
            constexpr int W = 16; // elements per SIMD batch: two AVX-512 registers of doubles (measured best of 8, 16, 32)
            for (std::int64_t first = begin; first < end;) {
                // A run of at least W/2 elements (see hexahedron_kernel.hpp) takes the contiguous
                // path; other batches stop where such a run begins.
                constexpr int shortest_run = W / 2;
                const bool run = m_run_length[first] >= shortest_run;
                int in_batch = static_cast<int>(std::min<std::int64_t>(W, end - first));
                if (run)
                    in_batch = std::min(in_batch, m_run_length[first]);
                else
                    for (int k = 1; k < in_batch; ++k)
                        if (m_run_length[first + k] >= shortest_run) {
                            in_batch = k;
                            break;
                        }
                const std::int32_t* elements = order + first;
                const Real* args[] = {m_dn.data(), m_gamma.data(), m_volume.data(), m_vb2.data(), m_mu.data(), m_lambda.data(), m_kappa.data(), m_hourglass.data()};
                int bad;
                if (m_box)
                    bad = run ? detail::hexahedron_batch<Real, W, true, true, true>(elements, in_batch, data, u, args[0], args[1], args[2], args[3], args[4], args[5], args[6], args[7], law, f)
                              : detail::hexahedron_batch<Real, W, true, false, true>(elements, in_batch, data, u, args[0], args[1], args[2], args[3], args[4], args[5], args[6], args[7], law, f);
                else if (shared_geometry)
                    bad = run ? detail::hexahedron_batch<Real, W, true, true>(elements, in_batch, data, u, args[0], args[1], args[2], args[3], args[4], args[5], args[6], args[7], law, f)
                              : detail::hexahedron_batch<Real, W, true, false>(elements, in_batch, data, u, args[0], args[1], args[2], args[3], args[4], args[5], args[6], args[7], law, f);
                else
                    bad = run ? detail::hexahedron_batch<Real, W, false, true>(elements, in_batch, data, u, args[0], args[1], args[2], args[3], args[4], args[5], args[6], args[7], law, f)
                              : detail::hexahedron_batch<Real, W, false, false>(elements, in_batch, data, u, args[0], args[1], args[2], args[3], args[4], args[5], args[6], args[7], law, f);
                if (bad >= 0) inverted = std::min<long>(inverted, elements[bad]);
                first += in_batch;
            }
        } else {
            for (std::int64_t k = begin; k < end; ++k) {
                const std::int32_t e = order[k];
                const std::int32_t g = geometry[e];
                const std::uint16_t m = material[e];
                const std::int32_t* ids = connectivity + 4 * static_cast<std::size_t>(e);
                Real jbar = 0;
                if (anp) jbar = (m_nodal_j[ids[0]] + m_nodal_j[ids[1]] + m_nodal_j[ids[2]] + m_nodal_j[ids[3]]) / Real(4);
                const Real j = tetrahedron_forces<Real>(ids, u, m_dn.data() + 12 * g, m_volume[g], law, m_mu[m], m_lambda[m],
                                                        m_kappa[m], f, jbar);
                if (!(j > Real(0))) inverted = std::min<long>(inverted, e);
            }
        }
    };
    // Band chunks (about a layer of a grid mesh each) differ in size: dealt out one at a time.
    // Colour chunks are many and equal: dealt out statically.
    const bool dynamic = m_model.band_partition();
    for (const auto& phase : m_model.phases()) {
        const long chunks = static_cast<long>(phase.size());
#pragma omp for schedule(dynamic) nowait
        for (long chunk = 0; chunk < (dynamic ? chunks : 0); ++chunk)
            run_chunk(phase[chunk]);
#pragma omp for schedule(static)
        for (long chunk = 0; chunk < (dynamic ? 0 : chunks); ++chunk)
            run_chunk(phase[chunk]);
    }
    if (m_coupling) {
        // Element loops end with a barrier; the coupling scatters serially (fixed order).
#pragma omp single
        m_coupling->add_forces(u, f);
    }
    if (inverted != LONG_MAX) {
#pragma omp critical(physreg_inverted)
        m_inverted_element = std::min(m_inverted_element, inverted);
    }
}

template <typename Real>
void TledSolver<Real>::check_state(const Real* u, const char* phase) const
{
    if (m_inverted_element >= 0) {
        // Where: the element's centre in the reference configuration, mm.
        Vec3 centre = Vec3::Zero();
        const int per = m_model.nodes_per_element();
        const auto& rest = m_model.rest_positions();
        for (int a = 0; a < per; ++a) {
            const auto n = static_cast<std::size_t>(m_model.connectivity()[static_cast<std::size_t>(m_inverted_element) * per + a]);
            centre += Vec3(rest[3 * n], rest[3 * n + 1], rest[3 * n + 2]) / per;
        }
        fail("{} step {}: element {} (at {:.1f}, {:.1f}, {:.1f} mm) is inverted (det F ≤ 0); the load is too large for "
             "this mesh, or the run is unstable (reduce the time step or the load)",
             phase, m_steps, m_inverted_element, centre.x(), centre.y(), centre.z());
    }
    const double limit = 10.0 * m_model.diagonal_mm();
    for (std::size_t k = 0; k < 3 * m_n; ++k)
        if (!std::isfinite(double(u[k])) || std::abs(double(u[k])) > limit)
            fail("{} step {}: the solution diverged at node {} (|u| = {:.3g} mm, model size {:.3g} mm)", phase, m_steps,
                 k / 3, std::abs(double(u[k])), m_model.diagonal_mm());
}

template <typename Real>
void TledSolver<Real>::advance(double duration_s, const ProgressCallback& progress)
{
    if (!(duration_s >= 0 && std::isfinite(duration_s))) fail("simulation duration {} s must be ≥ 0", duration_s);
    const double dt = m_time_step;
    const long steps = static_cast<long>(std::ceil(duration_s / dt - 1e-9));
    const double alpha = m_model.options().damping_per_s;
    // u⁺ = A (R − F) + B u − C u⁻ per node (central differences with mass-proportional damping).
    std::vector<Real> a(m_n), b(m_n), c(m_n);
    for (std::size_t i = 0; i < m_n; ++i) {
        const double m = m_model.lumped_mass()[i];
        const double denominator = m / (dt * dt) + alpha * m / (2 * dt);
        a[i] = static_cast<Real>(1.0 / denominator);
        b[i] = static_cast<Real>(2.0 * m / (dt * dt) / denominator);
        c[i] = static_cast<Real>((m / (dt * dt) - alpha * m / (2 * dt)) / denominator);
    }
    const long report_every = std::max<long>(1, steps / 100);
    const double limit = 10.0 * m_model.diagonal_mm();
    const auto& surface = m_model.surface_nodes();
    const long surface_count = static_cast<long>(surface.size());
    const bool has_external = !m_loads.external_forces_n.empty();
    Real* buffers[3] = {m_u_prev.data(), m_u.data(), m_u_next.data()};
    int previous = 0, current = 1, next = 2;
    bool failed = false;
    long failed_step = 0;
    double largest = 0.0, step_largest = 0.0; // shared: reduced into by every thread each step
    m_inverted_element = LONG_MAX;
    // One parallel region per chunk of steps: no fork/join per step, the serial bookkeeping is a
    // `single` section between barriers; between chunks the governor may change the team size.
    const long chunk = 4;
    for (long begin = 0; begin < steps && !failed; begin += chunk) {
    const long end = std::min(steps, begin + chunk);
    m_team = m_governor.threads();
    const double chunk_start = omp_get_wtime();
#pragma omp parallel num_threads(m_team)
    for (long step = begin; step < end; ++step) {
        const Real* u = buffers[current];
        const Real* up = buffers[previous];
        Real* un = buffers[next];
        const Real s = static_cast<Real>(m_loads.load_factor(m_time));
        // Forces accumulate into an array the update loop below has already zeroed.
        forces_in_parallel_region(u, m_force.data(), step == 0);
        Real* f = m_force.data();
        const Real* r = m_external.data();
        // Node by node in blocks (vectorised over nodes); each thread keeps its largest |u⁺| and
        // counts NaNs (+∞ then).
        constexpr long nodes_per_block = static_cast<long>(BLOCK / 3);
        const long nodes = static_cast<long>(m_n);
        const long blocks = (nodes + nodes_per_block - 1) / nodes_per_block;
        Real node_largest = 0;
        int not_finite = 0;
#pragma omp for schedule(static)
        for (long block = 0; block < blocks; ++block) {
            const long first = block * nodes_per_block, last = std::min(nodes, first + nodes_per_block);
            Real block_largest = 0;
            int block_nan = 0;
#pragma omp simd reduction(max : block_largest) reduction(+ : block_nan)
            for (long i = first; i < last; ++i) {
                for (int d = 0; d < 3; ++d) {
                    const long k = 3 * i + d;
                    const Real load = has_external ? s * r[k] : Real(0);
                    un[k] = a[i] * (load - f[k]) + b[i] * u[k] - c[i] * up[k];
                    f[k] = 0;
                    const Real magnitude = std::abs(un[k]);
                    block_nan += magnitude != magnitude;
                    block_largest = std::max(block_largest, magnitude);
                }
            }
            node_largest = std::max(node_largest, block_largest);
            not_finite += block_nan;
        }
#pragma omp critical(physreg_step_largest)
        step_largest = std::max(step_largest, not_finite ? std::numeric_limits<double>::infinity() : double(node_largest));
        const double s_next = m_loads.load_factor(m_time + dt);
        const Real sn = static_cast<Real>(s_next);
        const long constrained = static_cast<long>(m_constrained_dofs.size());
#pragma omp for schedule(static)
        for (long k = 0; k < constrained; ++k) un[m_constrained_dofs[k]] = sn * m_prescribed[m_constrained_dofs[k]];
        for (const auto& indenter : m_loads.indenters) {
#pragma omp for schedule(static)
            for (long k = 0; k < surface_count; ++k) {
                Vec3 normal;
                push_node_out(indenter, un, surface[k], s_next, normal);
            }
        }
#pragma omp single
        {
            largest = step_largest;
            step_largest = 0.0;
            m_time += dt;
            ++m_steps;
            if (m_inverted_element != LONG_MAX || !(largest <= limit)) {
                failed = true;
                failed_step = m_steps;
            }
            previous = current;
            current = next;
            next = 3 - previous - current;
            if (progress && (step % report_every == 0 || step + 1 == steps)) progress(double(step + 1) / double(steps), m_steps);
        }
        if (failed) break;
    }
    m_governor.record(omp_get_wtime() - chunk_start);
    if (begin % 256 == 0) throw_if_interrupted(); // between chunks, outside the parallel region
    }
    // Put the buffers back in place: m_u now, m_u_prev one step before.
    std::vector<Real>* vectors[3] = {&m_u_prev, &m_u, &m_u_next};
    std::vector<Real> now = std::move(*vectors[current]), before = std::move(*vectors[previous]), spare = std::move(*vectors[next]);
    m_u = std::move(now);
    m_u_prev = std::move(before);
    m_u_next = std::move(spare);
    if (failed) {
        if (m_inverted_element != LONG_MAX) {
            const long element = m_inverted_element;
            m_inverted_element = -1;
            fail("dynamics step {}: element {} is inverted (det F ≤ 0); the load is too large for this mesh, or "
                 "the run is unstable (reduce the time step or the load)",
                 failed_step, element);
        }
        m_inverted_element = -1;
        check_state(m_u.data(), "dynamics");
        fail("dynamics step {}: the solution diverged (|u| = {:.3g} mm, model size {:.3g} mm)", failed_step, largest,
             m_model.diagonal_mm());
    }
    m_inverted_element = -1;
    compute_internal_forces(m_u.data(), m_force.data());
    check_state(m_u.data(), "dynamics");
}

template <typename Real>
SolveSummary TledSolver<Real>::solve_equilibrium(const EquilibriumOptions& options, double load_factor,
                                                 const ProgressCallback& progress)
{
    options.validate();
    if (std::none_of(m_constrained.begin(), m_constrained.end(), [](std::uint8_t c) { return c != 0; }))
        fail("equilibrium: the model is unconstrained (no fixed or prescribed node): static equilibrium is "
             "undetermined; fix some nodes");
    const auto start = std::chrono::steady_clock::now();
    const std::size_t dofs = 3 * m_n;
    // Pseudo-time step h = 1 and masses from the stiffness bound: every node is stable at h = 1.
    std::vector<Real> inverse_mass(m_n);
    std::vector<double> mass(m_n);
    for (std::size_t i = 0; i < m_n; ++i) {
        mass[i] = options.mass_safety * m_stiffness_bound[i] / 4.0;
        if (!(mass[i] > 0)) fail("node {} belongs to no element with stiffness", i);
        inverse_mass[i] = static_cast<Real>(1.0 / mass[i]);
    }
    // Prescribed displacements and tools move from the last equilibrium's load level to the new one
    // over the first iterations (a smooth ramp), so that a large step does not invert elements.
    const double start_factor = m_load_factor;
    const long ramp = start_factor == load_factor ? 0 : options.ramp_iterations;
    auto factor_at = [&](long iteration) {
        return ramp == 0 ? load_factor : start_factor + (load_factor - start_factor) * smooth_step(double(iteration) / double(ramp));
    };
    constrain(m_u.data(), factor_at(0), true);
    select_contact_candidates(m_u.data(), start_factor, load_factor);
    m_active_tool.assign(m_n, -1);
    for (auto node : m_contact_normal_node) m_active_tool[node] = 0;
    if (m_loads.indenters.size() != 1) std::fill(m_active_tool.begin(), m_active_tool.end(), -1);
    m_u_prev = m_u; // start at rest
    m_face_contact = options.face_contact;
    m_face_penalty_scale = 0.2 * options.mass_safety;
    compute_internal_forces(m_u.data(), m_force.data());
    subtract_face_contact_forces(m_u.data(), factor_at(0), m_force.data());
    check_state(m_u.data(), "equilibrium");
    double damping = 0.0; // c; estimated after the first iteration
    SolveSummary summary;
    std::vector<double> increment_history;
    const std::size_t blocks = (dofs + BLOCK - 1) / BLOCK;
    std::vector<double> num(blocks), den(blocks);
    // Contact dofs: the normal component of the residual is the contact reaction.
    std::vector<std::uint8_t> in_contact(m_n, 0);
    std::vector<std::int32_t> flagged; // the nodes in_contact marks: cleared one by one, not the whole array
    auto refresh_contact = [&] {
        for (auto node : flagged) in_contact[node] = 0;
        flagged = m_contact_normal_node;
        for (auto node : flagged) in_contact[node] = 1;
    };
    refresh_contact();
    for (long iteration = 1; iteration <= options.max_iterations; ++iteration) {
        // One iteration is one unit of work for the governor (timed to the end of the loop body).
        const double iteration_start = omp_get_wtime();
        m_team = m_governor.threads();
        const double factor = factor_at(iteration);
        const Real s = static_cast<Real>(factor);
        const Real beta = static_cast<Real>((2.0 - damping) / (2.0 + damping));
        const Real gain = static_cast<Real>(2.0 / (2.0 + damping));
        Real* un = m_u_next.data();
        const Real *u = m_u.data(), *up = m_u_prev.data(), *f = m_force.data(), *r = m_external.data();
#pragma omp parallel for schedule(static) num_threads(m_team)
        for (std::size_t k = 0; k < dofs; ++k)
            un[k] = u[k] + beta * (u[k] - up[k]) + gain * inverse_mass[k / 3] * (s * r[k] - f[k]);
        constrain_with_active_set(un, factor, f, s);
        refresh_contact();
        std::swap(m_force_prev, m_force);
        compute_internal_forces(un, m_force.data());
        subtract_face_contact_forces(un, factor, m_force.data());
        ++m_steps;
        if (m_inverted_element >= 0) check_state(un, "equilibrium"); // throws, naming the element
        // Adaptive damping: the Rayleigh quotient of the increment, ω² ≈ Δuᵀ ΔF / Δuᵀ M Δu. Fast modes
        // are damped out first, so the increment tends to the slowest mode and ω² to λ_min; the
        // critical damping of that mode is c = 2ω. (Underwood's local estimate with the total
        // displacement converged 1.6× slower on our indentation tests.)
        double increment = 0.0, residual = 0.0, reference = 0.0, largest = 0.0;
        const Real* fn = m_force.data();
        const Real* fp = m_force_prev.data();
#pragma omp parallel for schedule(static) reduction(max : increment, residual, reference, largest) num_threads(m_team)
        for (std::size_t blk = 0; blk < blocks; ++blk) {
            double nb = 0, db = 0;
            const std::size_t end = std::min(dofs, (blk + 1) * BLOCK);
            for (std::size_t k = blk * BLOCK; k < end; ++k) {
                const double du = double(un[k]) - double(u[k]);
                const double magnitude = std::abs(double(un[k]));
                largest = std::max(largest, magnitude != magnitude ? std::numeric_limits<double>::infinity() : magnitude);
                increment = std::max(increment, std::abs(du));
                reference = std::max(reference, std::abs(double(fn[k])));
                if (m_constrained[k]) continue;
                if (!in_contact[k / 3]) { // tool projections are not elastic motion
                    nb += du * (double(fn[k]) - double(fp[k]));
                    db += mass[k / 3] * du * du;
                }
                if (!in_contact[k / 3]) residual = std::max(residual, std::abs(double(s * r[k] - fn[k])));
            }
            num[blk] = nb;
            den[blk] = db;
        }
        residual = std::max(residual, tangential_contact_residual(m_contact_normal_node, m_contact_normal, m_constrained, r, fn, s));
        if (!(largest <= 10.0 * m_model.diagonal_mm())) check_state(un, "equilibrium"); // throws, naming the node
        double sum_num = 0, sum_den = 0;
        for (std::size_t blk = 0; blk < blocks; ++blk) {
            sum_num += num[blk];
            sum_den += den[blk];
        }
        if (sum_den > 0 && sum_num > 0) damping = 2.0 * std::sqrt(std::min(sum_num / sum_den, 4.0));
        damping = std::min(damping, 1.9);
        std::swap(m_u_prev, m_u);
        std::swap(m_u, m_u_next);
        keep_tangential_momentum(m_contact_normal_node, m_contact_normal, m_u, m_u_prev);

        // No node has moved farther than √3 × the largest component increment: once the candidates'
        // margin is used up, select them again around the current shape.
        m_candidate_slack -= std::sqrt(3.0) * increment;
        if (m_candidate_slack < 0) select_contact_candidates(m_u.data(), start_factor, load_factor);
        increment_history.push_back(increment);
        const double estimate = distance_to_equilibrium(increment_history);
        summary.iterations = iteration;
        summary.residual_n = residual;
        summary.reference_force_n = reference;
        summary.estimated_error_mm = increment == 0.0 ? 0.0 : estimate;
        // Floors at round-off level: an unloaded model (all forces ~1e-15 N) is at equilibrium.
        const bool still = increment <= 1e-9 || estimate <= options.displacement_tolerance_mm;
        const bool balanced = residual <= std::max(options.residual_tolerance * reference, 1e-10);
        if (progress && iteration % 200 == 0) progress(-1.0, iteration);
        // Ctrl-C / kill between iterations (a no-op inside an enclosing parallel region, where the
        // caller's next serial point stops instead): a relaxation can run for minutes.
        if (iteration % 64 == 0) throw_if_interrupted();
        m_governor.record(omp_get_wtime() - iteration_start);
        if (still && balanced && iteration > ramp) {
            summary.status = SolveStatus::converged;
            break;
        }
    }
    summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    summary.message = summary.converged()
                          ? fmt::format("equilibrium after {} iterations (residual {:.3g} N of {:.3g} N, distance {:.3g} mm)",
                                        summary.iterations, summary.residual_n, summary.reference_force_n, summary.estimated_error_mm)
                          : fmt::format("no equilibrium after {} iterations (residual {:.3g} N of {:.3g} N, distance {:.3g} mm)",
                                        summary.iterations, summary.residual_n, summary.reference_force_n, summary.estimated_error_mm);
    m_u_prev = m_u;
    m_load_factor = load_factor;
    return summary;
}

template <typename Real>
Energies TledSolver<Real>::energies() const
{
    Energies out;
    const int npe = m_model.nodes_per_element();
    const auto& conn = m_model.connectivity();
    for (std::size_t e = 0; e < m_model.element_count(); ++e) {
        const ElementGeometry& g = m_model.geometries()[m_model.element_geometry()[e]];
        const ElasticMaterial& mat = m_model.materials()[m_model.element_material()[e]];
        Mat3 f = Mat3::Identity();
        for (int a = 0; a < npe; ++a) {
            const std::size_t node = static_cast<std::size_t>(conn[npe * e + a]);
            const Vec3 ua(static_cast<double>(m_u[3 * node]), static_cast<double>(m_u[3 * node + 1]), static_cast<double>(m_u[3 * node + 2]));
            f += ua * Vec3(g.dn_dx[3 * a], g.dn_dx[3 * a + 1], g.dn_dx[3 * a + 2]).transpose();
        }
        out.strain_mj += g.volume_mm3 * strain_energy_density(m_model.options().law, mat, f);
        if (npe == 8) {
            const double k = m_model.options().hourglass_kappa * hourglass_modulus_mpa(m_model.options(), mat) * g.volume_mm3 * g.b_squared / 8.0;
            for (int m = 0; m < 4; ++m) {
                Vec3 q = Vec3::Zero();
                for (int a = 0; a < 8; ++a) {
                    const std::size_t node = static_cast<std::size_t>(conn[8 * e + a]);
                    q += g.gamma[4 * a + m] * Vec3(double(m_u[3 * node]), double(m_u[3 * node + 1]), double(m_u[3 * node + 2]));
                }
                out.hourglass_mj += 0.5 * k * q.squaredNorm();
            }
        }
    }
    if (m_coupling) {
        const std::vector<double> u(m_u.begin(), m_u.end());
        out.coupling_mj = m_coupling->energy_mj(u);
    }
    const double dt = m_time_step;
    for (std::size_t i = 0; i < m_n; ++i) {
        Vec3 v;
        for (int d = 0; d < 3; ++d) v[d] = (double(m_u[3 * i + d]) - double(m_u_prev[3 * i + d])) / dt;
        out.kinetic_mj += 0.5 * m_model.lumped_mass()[i] * v.squaredNorm(); // t·mm²/s² = mJ
    }
    return out;
}

template class TledSolver<float>;
template class TledSolver<double>;

} // namespace physreg
