// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/compression/condensed_contact.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/mechanics/linear/linear_solver.hpp"
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <set>
#include <unistd.h>

namespace physreg {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

double distance_to_segment(const Vec3& x, const Vec3& a, const Vec3& b)
{
    const Vec3 ab = b - a;
    const double l2 = ab.squaredNorm();
    const double s = l2 > 0 ? std::clamp((x - a).dot(ab) / l2, 0.0, 1.0) : 0.0;
    return (x - (a + s * ab)).norm();
}

std::string memory_size(std::size_t bytes)
{
    const double mib = double(bytes) / 1048576.0;
    return mib >= 1024.0 ? fmt::format("{:.2f} GiB", mib / 1024.0) : fmt::format("{:.1f} MiB", mib);
}

void refuse_over_limit(std::size_t needed, std::size_t limit, double factor_nonzeros, std::size_t dofs, std::size_t candidates, std::size_t queries)
{
    if (needed <= limit) return;
    fail("condensed contact: the precomputation needs ≈ {} (Cholesky factor with {:.3g} non-zeros for {} dofs, compliance of {} "
         "candidate and {} query nodes, stiffness, work blocks), over the memory limit of {} (--memory-limit): fewer candidates "
         "(a smaller margin, fewer tool paths) or a coarser grid",
         memory_size(needed), factor_nonzeros, dofs, candidates, queries, memory_size(limit));
}

} // namespace

void CondensedContactOptions::validate() const
{
    if (!(candidate_margin_mm >= 0 && std::isfinite(candidate_margin_mm))) fail("condensed contact: candidate margin must be ≥ 0 mm (got {})", candidate_margin_mm);
    if (!(active_gap_mm > 0 && std::isfinite(active_gap_mm))) fail("condensed contact: active gap must be > 0 mm (got {})", active_gap_mm);
    if (lcp_max_sweeps < 1) fail("condensed contact: LCP sweeps must be ≥ 1 (got {})", lcp_max_sweeps);
    if (!(lcp_tolerance_mm > 0)) fail("condensed contact: LCP tolerance must be > 0 mm (got {})", lcp_tolerance_mm);
    if (normal_updates < 1) fail("condensed contact: normal updates must be ≥ 1 (got {})", normal_updates);
    if (!(penetration_tolerance_mm > 0)) fail("condensed contact: penetration tolerance must be > 0 mm (got {})", penetration_tolerance_mm);
}

struct CondensedContactModel::Factor {
    SparseMatrix k;
    SymmetricSolver solver{LinearSolverOptions{LinearSolverKind::cholmod}};
    std::vector<char> constrained; ///< per dof
    bool factorised = false;       ///< a model from stored compliance factorises when first needed
};

std::vector<std::int32_t> nodes_near(const VolumeMesh& mesh, const std::vector<Vec3>& points, double radius_mm)
{
    std::vector<std::int32_t> out;
    for (std::size_t n = 0; n < mesh.node_count(); ++n)
        for (const auto& p : points)
            if ((mesh.nodes[n] - p).norm() <= radius_mm) {
                out.push_back(static_cast<std::int32_t>(n));
                break;
            }
    return out;
}

std::size_t condensed_memory_bytes(std::size_t dofs, double factor_nonzeros, std::size_t stiffness_nonzeros, std::size_t candidate_nodes,
                                   std::size_t query_nodes)
{
    const double c3 = 3.0 * double(candidate_nodes), q3 = 3.0 * double(query_nodes);
    const double factor = 8.0 * factor_nonzeros;                        // L's values (supernodal; its indices are a few %)
    const double stiffness = 12.0 * double(stiffness_nonzeros) + 4.0 * double(dofs);
    const double compliance = 8.0 * c3 * (c3 + q3);
    const double work = 2.0 * 8.0 * 48.0 * double(dofs);                // one block of right-hand sides and its solution
    return static_cast<std::size_t>(factor + stiffness + compliance + work);
}

std::size_t effective_memory_limit(std::size_t memory_limit_bytes)
{
    if (memory_limit_bytes > 0) return memory_limit_bytes;
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || page <= 0) return std::numeric_limits<std::size_t>::max();
    return static_cast<std::size_t>(0.8 * double(pages) * double(page));
}

CondensedContactModel::CondensedContactModel(const LiverModel& model, const std::vector<Indenter>& session_tools,
                                             std::vector<std::int32_t> query_nodes, const CondensedContactOptions& options)
    : m_model(model), m_options(options), m_factor(std::make_unique<Factor>()), m_query(std::move(query_nodes))
{
    options.validate();
    if (session_tools.empty()) fail("condensed contact: no tool path given (the candidates lie near the session's tools)");
    assemble_at_rest();
    const auto& constrained = m_factor->constrained;

    // Candidates: free surface nodes within the tool's reach + the margin of a session path.
    for (const auto& t : session_tools) {
        t.validate();
        if (!std::isfinite(t.reach_mm())) fail("condensed contact: tool '{}' has no finite reach (sphere or box tools only)", t.name);
    }
    for (const auto n : model.tled->surface_nodes()) {
        const auto i = static_cast<std::size_t>(n);
        if (constrained[3 * i] && constrained[3 * i + 1] && constrained[3 * i + 2]) continue;
        const Vec3& x = model.mesh.nodes[i];
        for (const auto& t : session_tools) {
            bool near = false;
            for (std::size_t s = 0; s < t.path.size() && !near; ++s)
                near = distance_to_segment(x, t.path[s], t.path[std::min(s + 1, t.path.size() - 1)]) <= t.reach_mm() + options.candidate_margin_mm;
            if (near) {
                m_candidates.push_back(n);
                break;
            }
        }
        if (m_candidates.empty() || m_candidates.back() != n) m_outside.push_back(n);
    }
    if (m_candidates.empty()) fail("condensed contact: no surface node lies within the tools' reach (+{} mm) of their paths", options.candidate_margin_mm);

    std::vector<std::int32_t> candidates;
    candidates.swap(m_candidates);
    factorise(candidates.size());
    // Compliance columns of the candidate dofs.
    const auto t0 = std::chrono::steady_clock::now();
    m_query_u.assign(3 * m_query.size(), 0.0);
    add_candidates(candidates);
    m_pre.compliance_s = seconds_since(t0);
    m_pre.query_nodes = m_query.size();
}

CondensedContactModel::CondensedContactModel(const LiverModel& model, CondensedCompliance stored, const CondensedContactOptions& options)
    : m_model(model), m_options(options), m_factor(std::make_unique<Factor>()), m_candidates(std::move(stored.candidates)),
      m_query(std::move(stored.query)), m_outside(std::move(stored.outside)), m_wcc(std::move(stored.wcc)), m_wqc(std::move(stored.wqc)),
      m_pre(stored.precomputation)
{
    options.validate();
    assemble_at_rest();
    const std::size_t nodes = model.mesh.node_count();
    const auto c3 = static_cast<Eigen::Index>(3 * m_candidates.size()), q3 = static_cast<Eigen::Index>(3 * m_query.size());
    if (stored.dofs != 3 * nodes)
        fail("condensed contact: the stored compliance was computed for {} unknowns, the model has {} (another model)", stored.dofs, 3 * nodes);
    for (const auto* list : {&m_candidates, &m_query, &m_outside})
        for (const auto n : *list)
            if (n < 0 || static_cast<std::size_t>(n) >= nodes) fail("condensed contact: stored node {} out of range (0 … {})", n, nodes - 1);
    if (m_candidates.empty() || m_wcc.rows() != c3 || m_wcc.cols() != c3 || m_wqc.rows() != q3 || m_wqc.cols() != c3)
        fail("condensed contact: the stored compliance blocks ({}×{}, {}×{}) do not match {} candidates and {} query nodes", m_wcc.rows(), m_wcc.cols(),
             m_wqc.rows(), m_wqc.cols(), m_candidates.size(), m_query.size());
    std::size_t held = 0;
    for (const char c : m_factor->constrained) held += c ? 1 : 0;
    const double probe = stiffness_probe();
    if (held != stored.constrained_dofs || !(std::abs(probe - stored.stiffness_probe) <= 1e-9 * std::max(std::abs(probe), std::abs(stored.stiffness_probe))))
        fail("condensed contact: the stored compliance belongs to another stiffness (held unknowns {} vs {}, stiffness probe {:.12g} vs {:.12g}): "
             "prepare the model again with this version of physreg",
             stored.constrained_dofs, held, stored.stiffness_probe, probe);
    for (Eigen::Index i = 0; i < m_wcc.size(); ++i)
        if (!std::isfinite(m_wcc.data()[i])) fail("condensed contact: the stored compliance holds a non-finite value");
    for (Eigen::Index i = 0; i < m_wqc.size(); ++i)
        if (!std::isfinite(m_wqc.data()[i])) fail("condensed contact: the stored compliance holds a non-finite value");
    m_least_compliance = 1e-12 * m_wcc.diagonal().maxCoeff();
    m_force = Eigen::VectorXd::Zero(c3);
    m_lambda.assign(m_candidates.size(), 0.0);
    m_query_u.assign(3 * m_query.size(), 0.0);
    m_pre.factorisation_s = 0.0; // not factorised (yet): the factor is made when first needed
    m_pre.compliance_s = 0.0;
}

void CondensedContactModel::assemble_at_rest()
{
    if (!m_model.tled) fail("condensed contact: the model has no mechanics");
    const std::size_t nodes = m_model.mesh.node_count(), dofs = 3 * nodes;
    for (const auto q : m_query)
        if (q < 0 || static_cast<std::size_t>(q) >= nodes) fail("condensed contact: query node {} out of range (0 … {})", q, nodes - 1);
    // Supports: held dofs get an identity row and column (their displacement stays 0).
    auto& constrained = m_factor->constrained;
    constrained.assign(dofs, 0);
    for (const auto& c : m_model.supports())
        for (const auto n : c.nodes)
            for (int d = 0; d < 3; ++d)
                if (c.dofs[static_cast<std::size_t>(d)]) constrained[3 * static_cast<std::size_t>(n) + static_cast<std::size_t>(d)] = 1;
    // The tangent at rest (the model's law linearised), supports eliminated.
    const auto t0 = std::chrono::steady_clock::now();
    const PenaltyCoupling* coupling = m_model.coupling.points().empty() ? nullptr : &m_model.coupling;
    StiffnessAssembler assembler(*m_model.tled, coupling);
    SparseMatrix& k = m_factor->k;
    k = assembler.make_matrix();
    std::vector<double> zero(dofs, 0.0), force(dofs, 0.0);
    const Assembly a = assembler.assemble(zero.data(), force.data(), &k);
    if (a.non_finite_element >= 0) fail("condensed contact: element {} has a non-finite stiffness at rest", a.non_finite_element);
    for (int j = 0; j < k.outerSize(); ++j)
        for (SparseMatrix::InnerIterator it(k, j); it; ++it)
            if (constrained[static_cast<std::size_t>(it.row())] || constrained[static_cast<std::size_t>(j)]) it.valueRef() = it.row() == j ? 1.0 : 0.0;
    m_pre.assembly_s = seconds_since(t0);
    m_pre.dofs = dofs;
}

void CondensedContactModel::factorise(std::size_t candidates) const
{
    // The memory the precomputation will take, from CHOLMOD's analysis, before anything large is made.
    const SparseMatrix& k = m_factor->k;
    const double analysed_nonzeros = m_factor->solver.analyse(k);
    const std::size_t limit = effective_memory_limit(m_options.memory_limit_bytes);
    const std::size_t needed = condensed_memory_bytes(m_pre.dofs, analysed_nonzeros, static_cast<std::size_t>(k.nonZeros()), candidates, m_query.size());
    refuse_over_limit(needed, limit, analysed_nonzeros, m_pre.dofs, candidates, m_query.size());
    const auto t0 = std::chrono::steady_clock::now();
    if (m_factor->solver.factorise(k).shift > 0)
        fail("condensed contact: the stiffness at rest is not positive definite (CHOLMOD needed a shift): is the model held against rigid motion?");
    m_pre.factorisation_s = seconds_since(t0);
    m_pre.factor_nonzeros = analysed_nonzeros;
    m_pre.memory_limit_bytes = limit;
    m_pre.memory_bytes = needed;
    m_factor->factorised = true;
}

void CondensedContactModel::ensure_factor() const
{
    if (m_factor->factorised) return;
    logger()->info("condensed contact: factorising the stiffness ({} unknowns; the stored compliance needed none until now)", m_pre.dofs);
    factorise(m_candidates.size());
}

bool CondensedContactModel::factorised() const { return m_factor->factorised; }

double CondensedContactModel::stiffness_probe() const
{
    // vᵀ K w for two fixed vectors: equal for equal stiffnesses, and a change of any entry shows
    // (K's nonzeros are assembled in a fixed order, so this is reproducible to rounding).
    const SparseMatrix& k = m_factor->k;
    double sum = 0.0;
    for (int j = 0; j < k.outerSize(); ++j)
        for (SparseMatrix::InnerIterator it(k, j); it; ++it)
            sum += std::sin(0.7 * double(it.row()) + 0.3) * it.value() * std::cos(1.3 * double(j) + 0.1);
    return sum;
}

CondensedCompliance CondensedContactModel::compliance() const
{
    CondensedCompliance c;
    c.candidates = m_candidates;
    c.query = m_query;
    c.outside = m_outside;
    c.wcc = m_wcc;
    c.wqc = m_wqc;
    c.dofs = m_pre.dofs;
    for (const char h : m_factor->constrained) c.constrained_dofs += h ? 1 : 0;
    c.stiffness_probe = stiffness_probe();
    c.precomputation = m_pre;
    return c;
}

void CondensedContactModel::add_candidates(const std::vector<std::int32_t>& added)
{
    ensure_factor();
    const std::size_t dofs = m_factor->constrained.size();
    const auto& constrained = m_factor->constrained;
    const auto old3 = static_cast<Eigen::Index>(3 * m_candidates.size());
    const std::size_t needed = condensed_memory_bytes(dofs, m_pre.factor_nonzeros, static_cast<std::size_t>(m_factor->k.nonZeros()),
                                                      m_candidates.size() + added.size(), m_query.size());
    refuse_over_limit(needed, m_pre.memory_limit_bytes, m_pre.factor_nonzeros, dofs, m_candidates.size() + added.size(), m_query.size());
    m_pre.memory_bytes = needed;
    m_candidates.insert(m_candidates.end(), added.begin(), added.end());
    const auto c3 = static_cast<Eigen::Index>(3 * m_candidates.size()), q3 = static_cast<Eigen::Index>(3 * m_query.size());
    m_wcc.conservativeResize(c3, c3);
    m_wqc.conservativeResize(q3, c3);
    auto dof_of = [](const std::vector<std::int32_t>& nodes, Eigen::Index i) {
        return 3 * static_cast<std::size_t>(nodes[static_cast<std::size_t>(i / 3)]) + static_cast<std::size_t>(i % 3);
    };
    // The new columns, a block of right-hand sides at a time (BLAS-3 solves).
    constexpr Eigen::Index block = 48;
    for (Eigen::Index b0 = old3; b0 < c3; b0 += block) {
        throw_if_interrupted();
        const Eigen::Index bs = std::min(block, c3 - b0);
        Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(dofs), bs);
        for (Eigen::Index j = 0; j < bs; ++j) {
            const auto dof = dof_of(m_candidates, b0 + j);
            if (!constrained[dof]) rhs(static_cast<Eigen::Index>(dof), j) = 1.0;
        }
        Eigen::MatrixXd x;
        m_factor->solver.solve_factored(rhs, x);
        for (Eigen::Index j = 0; j < bs; ++j) {
            for (Eigen::Index i = 0; i < c3; ++i) {
                const auto dof = dof_of(m_candidates, i);
                m_wcc(i, b0 + j) = constrained[dof] ? 0.0 : x(static_cast<Eigen::Index>(dof), j);
            }
            for (Eigen::Index i = 0; i < q3; ++i) {
                const auto dof = dof_of(m_query, i);
                m_wqc(i, b0 + j) = constrained[dof] ? 0.0 : x(static_cast<Eigen::Index>(dof), j);
            }
        }
    }
    // The old candidates' rows of the new columns, by the symmetry of K⁻¹.
    if (old3 > 0 && c3 > old3) m_wcc.block(old3, 0, c3 - old3, old3) = m_wcc.block(0, old3, old3, c3 - old3).transpose();
    m_least_compliance = 1e-12 * m_wcc.diagonal().maxCoeff();
    m_pre.candidate_nodes = m_candidates.size();
    m_pre.compliance_bytes = static_cast<std::size_t>(m_wcc.size() + m_wqc.size()) * sizeof(double);
    m_force.conservativeResize(c3);
    m_force.tail(c3 - old3).setZero();
    m_lambda.resize(m_candidates.size(), 0.0);
    const std::set<std::int32_t> now(added.begin(), added.end());
    std::erase_if(m_outside, [&](std::int32_t n) { return now.count(n) > 0; });
}

namespace {

struct LcpSolution {
    int sweeps = 0;            ///< pivots and Gauss–Seidel sweeps
    bool converged = true;
    double violation_mm = 0.0; ///< complementarity violation left (Gauss–Seidel only)
};

/// The contact LCP w = q + D λ ≥ 0, λ ≥ 0, wᵀλ = 0 (D = Nᵀ W N, mm/N; q, mm): block principal
/// pivoting (an active-set method) from the warm start λ, then projected Gauss–Seidel if it cycles.
LcpSolution solve_contact_lcp(const Eigen::MatrixXd& dm, const Eigen::VectorXd& q, Eigen::VectorXd& lambda, double tolerance_mm, int max_sweeps)
{
    LcpSolution out;
    const Eigen::Index m = q.size();
    std::vector<char> active(static_cast<std::size_t>(m), 0);
    for (Eigen::Index a = 0; a < m; ++a) active[static_cast<std::size_t>(a)] = lambda(a) > 0 || q(a) < 0;
    bool solved = false;
    for (int pivot = 0; pivot < 30 && !solved; ++pivot) {
        std::vector<Eigen::Index> idx;
        for (Eigen::Index a = 0; a < m; ++a)
            if (active[static_cast<std::size_t>(a)]) idx.push_back(a);
        lambda.setZero();
        if (!idx.empty()) {
            const auto na = static_cast<Eigen::Index>(idx.size());
            Eigen::MatrixXd daa(na, na);
            Eigen::VectorXd rhs(na);
            for (Eigen::Index a = 0; a < na; ++a) {
                rhs(a) = -q(idx[static_cast<std::size_t>(a)]);
                for (Eigen::Index b = 0; b < na; ++b) daa(a, b) = dm(idx[static_cast<std::size_t>(a)], idx[static_cast<std::size_t>(b)]);
            }
            const Eigen::VectorXd la = daa.ldlt().solve(rhs);
            for (Eigen::Index a = 0; a < na; ++a) lambda(idx[static_cast<std::size_t>(a)]) = la(a);
        }
        const Eigen::VectorXd w = q + dm * lambda;
        bool changed = false;
        for (Eigen::Index a = 0; a < m; ++a) {
            const double scale = dm(a, a);
            if (active[static_cast<std::size_t>(a)] && lambda(a) < -tolerance_mm / scale) active[static_cast<std::size_t>(a)] = 0, changed = true;
            else if (!active[static_cast<std::size_t>(a)] && w(a) < -tolerance_mm) active[static_cast<std::size_t>(a)] = 1, changed = true;
        }
        ++out.sweeps;
        solved = !changed;
    }
    if (!solved) {
        lambda = lambda.cwiseMax(0.0);
        double violation = 1e300;
        for (int sweep = 0; sweep < max_sweeps && violation > tolerance_mm; ++sweep, ++out.sweeps) {
            violation = 0.0;
            for (Eigen::Index a = 0; a < m; ++a) {
                const double w = q(a) + dm.row(a).dot(lambda);
                const double next = std::max(0.0, lambda(a) - w / dm(a, a));
                violation = std::max(violation, std::abs(std::min(w, next * dm(a, a))));
                lambda(a) = next;
            }
        }
        out.violation_mm = violation;
        out.converged = violation <= tolerance_mm;
    }
    return out;
}

} // namespace

CondensedContactModel::~CondensedContactModel() = default;
CondensedContactModel::CondensedContactModel(CondensedContactModel&&) noexcept = default;

CondensedContactModel::Update CondensedContactModel::move_to(const Indenter& tool, const Vec3& position_mm)
{
    Indenter t = tool;
    t.path = {position_mm};
    Update up;

    const auto contact_start = std::chrono::steady_clock::now();
    std::size_t c = m_candidates.size(); // grows when the tool leaves the candidate region

    // Candidate displacements from the current forces (only the loaded columns contribute).
    std::vector<std::size_t> loaded;
    auto candidate_displacement = [&](Eigen::VectorXd& u) {
        u.setZero(static_cast<Eigen::Index>(3 * c));
        for (const auto j : loaded)
            for (int d = 0; d < 3; ++d) {
                const double f = m_force(static_cast<Eigen::Index>(3 * j + static_cast<std::size_t>(d)));
                if (f != 0.0) u.noalias() += m_wcc.col(static_cast<Eigen::Index>(3 * j + static_cast<std::size_t>(d))) * f;
            }
    };
    for (std::size_t j = 0; j < c; ++j)
        if (m_lambda[j] > 0) loaded.push_back(j);

    Eigen::VectorXd u;
    std::vector<Vec3> normal;
    std::vector<double> gap;
    auto gaps_at = [&](const Eigen::VectorXd& uc) {
        for (std::size_t i = 0; i < c; ++i) {
            const Vec3 x = m_model.mesh.nodes[static_cast<std::size_t>(m_candidates[i])] + uc.segment<3>(static_cast<Eigen::Index>(3 * i));
            Vec3 s, n;
            t.closest_surface_point(x, 0.0, s, n);
            normal[i] = n;
            gap[i] = (x - s).dot(n); // signed: < 0 inside the tool
        }
    };
    // A tool outside the precomputed region: surface nodes that are not candidates lie within its
    // reach + the LCP's gap at rest. (Along a session path that never happens: the margin exceeds
    // the gap. Nodes move with the tissue, but those beyond the margin move less than the tool.)
    // Their compliance is solved now (the full solve), never skipped.
    auto extend_region = [&]() {
        if (m_outside.empty()) return;
        const double reach = t.reach_mm();
        std::size_t reached = 0;
        std::vector<std::int32_t> added;
        for (const auto n : m_outside) {
            const double d = (m_model.mesh.nodes[static_cast<std::size_t>(n)] - position_mm).norm();
            if (d <= reach + m_options.active_gap_mm) ++reached;
            if (d <= reach + m_options.candidate_margin_mm) added.push_back(n);
        }
        if (reached == 0) return;
        const auto t0 = std::chrono::steady_clock::now();
        add_candidates(added);
        up.added_candidates = static_cast<int>(added.size());
        up.extension_ms = 1e3 * seconds_since(t0);
        ++m_pre.region_extensions;
        m_pre.added_candidates += added.size();
        m_pre.extension_s += 1e-3 * up.extension_ms;
        logger()->warn("condensed contact: the tool at ({:.1f}, {:.1f}, {:.1f}) mm left the precomputed candidate region ({} surface "
                       "nodes within its reach were no candidates): {} nodes added by solves with the factor in {:.2f} s",
                       position_mm.x(), position_mm.y(), position_mm.z(), reached, added.size(), 1e-3 * up.extension_ms);
    };
    extend_region(); // first: the displacements and gaps below cover the added candidates too
    c = m_candidates.size();
    candidate_displacement(u);
    normal.resize(c);
    gap.resize(c);
    gaps_at(u);

    std::vector<std::size_t> set; // the LCP's candidates
    for (int linearisation = 0; linearisation < m_options.normal_updates; ++linearisation) {
        // A node that cannot move along the tool's normal (a support holds that direction) has no
        // compliance there and stays out of the LCP; if the tool reaches it, the penetration check
        // below says so.
        std::set<std::size_t> chosen;
        for (std::size_t i = 0; i < c; ++i) {
            const double own = normal[i].dot(m_wcc.block<3, 3>(static_cast<Eigen::Index>(3 * i), static_cast<Eigen::Index>(3 * i)) * normal[i]);
            if ((gap[i] < m_options.active_gap_mm || m_lambda[i] > 0) && own > m_least_compliance) chosen.insert(i);
        }
        set.assign(chosen.begin(), chosen.end());
        const auto m = static_cast<Eigen::Index>(set.size());
        // D = Nᵀ W N and q on the set, linearised at the current displacement.
        Eigen::MatrixXd dm(m, m);
        Eigen::VectorXd q(m), lambda(m);
        for (Eigen::Index a = 0; a < m; ++a) {
            const std::size_t i = set[static_cast<std::size_t>(a)];
            q(a) = gap[i] - normal[i].dot(u.segment<3>(static_cast<Eigen::Index>(3 * i)));
            lambda(a) = m_lambda[i];
            for (Eigen::Index b = 0; b < m; ++b) {
                const std::size_t j = set[static_cast<std::size_t>(b)];
                dm(a, b) = normal[i].dot(m_wcc.block<3, 3>(static_cast<Eigen::Index>(3 * i), static_cast<Eigen::Index>(3 * j)) * normal[j]);
            }
        }
        // The LCP: w = q + D λ ≥ 0, λ ≥ 0, wᵀλ = 0, from the warm start.
        const LcpSolution lcp = solve_contact_lcp(dm, q, lambda, m_options.lcp_tolerance_mm, m_options.lcp_max_sweeps);
        up.sweeps += lcp.sweeps;
        if (!lcp.converged)
            fail("condensed contact: the contact problem at the tool position ({:.2f}, {:.2f}, {:.2f}) mm did not converge "
                 "({} nodes, complementarity violation {:.3g} mm after {} sweeps)",
                 position_mm.x(), position_mm.y(), position_mm.z(), m, lcp.violation_mm, m_options.lcp_max_sweeps);
        // New forces along the new normals; re-linearise at the displacement they give.
        std::fill(m_lambda.begin(), m_lambda.end(), 0.0);
        m_force.setZero();
        loaded.clear();
        for (Eigen::Index a = 0; a < m; ++a) {
            const std::size_t i = set[static_cast<std::size_t>(a)];
            if (lambda(a) <= 0) continue;
            m_lambda[i] = lambda(a);
            m_force.segment<3>(static_cast<Eigen::Index>(3 * i)) = lambda(a) * normal[i];
            loaded.push_back(i);
        }
        candidate_displacement(u);
        gaps_at(u);
        up.lcp_nodes = static_cast<int>(m);
    }
    up.max_penetration_mm = 0.0;
    for (std::size_t i = 0; i < c; ++i) up.max_penetration_mm = std::max(up.max_penetration_mm, -gap[i]);
    if (up.max_penetration_mm > m_options.penetration_tolerance_mm)
        fail("condensed contact: {:.3g} mm of penetration remain at the tool position ({:.2f}, {:.2f}, {:.2f}) mm after {} linearisations "
             "(tolerance {:.3g} mm)",
             up.max_penetration_mm, position_mm.x(), position_mm.y(), position_mm.z(), m_options.normal_updates, m_options.penetration_tolerance_mm);
    Vec3 total = Vec3::Zero();
    for (const auto j : loaded) total += m_force.segment<3>(static_cast<Eigen::Index>(3 * j));
    up.total_force_n = total.norm();
    up.active_nodes = static_cast<int>(loaded.size());
    const auto contact_done = std::chrono::steady_clock::now();
    up.contact_ms = 1e3 * std::chrono::duration<double>(contact_done - contact_start).count() - up.extension_ms;

    // The query nodes from the loaded columns.
    Eigen::VectorXd uq = Eigen::VectorXd::Zero(m_wqc.rows());
    for (const auto j : loaded) uq.noalias() += m_wqc.middleCols<3>(static_cast<Eigen::Index>(3 * j)) * m_force.segment<3>(static_cast<Eigen::Index>(3 * j));
    m_query_u.assign(uq.data(), uq.data() + uq.size());
    up.recovery_ms = 1e3 * seconds_since(contact_done);
    return up;
}

void CondensedContactModel::reset()
{
    m_force.setZero();
    std::fill(m_lambda.begin(), m_lambda.end(), 0.0);
    std::fill(m_query_u.begin(), m_query_u.end(), 0.0);
}

std::vector<double> CondensedContactModel::query_field_mm() const
{
    std::vector<double> u(3 * m_model.mesh.node_count(), 0.0);
    for (std::size_t i = 0; i < m_query.size(); ++i)
        for (std::size_t d = 0; d < 3; ++d) u[3 * static_cast<std::size_t>(m_query[i]) + d] = m_query_u[3 * i + d];
    return u;
}

std::vector<double> CondensedContactModel::full_displacement_mm() const
{
    ensure_factor();
    const std::size_t dofs = m_factor->constrained.size();
    Eigen::VectorXd f = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(dofs));
    for (std::size_t j = 0; j < m_candidates.size(); ++j)
        for (int d = 0; d < 3; ++d) {
            const auto dof = 3 * static_cast<std::size_t>(m_candidates[j]) + static_cast<std::size_t>(d);
            if (!m_factor->constrained[dof]) f(static_cast<Eigen::Index>(dof)) = m_force(static_cast<Eigen::Index>(3 * j + static_cast<std::size_t>(d)));
        }
    Eigen::VectorXd u;
    m_factor->solver.solve_factored(f, u);
    std::vector<double> out(u.data(), u.data() + u.size());
    for (std::size_t d = 0; d < dofs; ++d)
        if (m_factor->constrained[d]) out[d] = 0.0;
    return out;
}

CompressionPrediction predict_compression_condensed(const LiverModel& model, const Indenter& tool, const LandmarkSet& rest_landmarks, int steps,
                                                    const std::string& what, const CondensedContactOptions& options,
                                                    CondensedPrecomputation* precomputation, double* ms_per_update)
{
    if (steps < 1) fail("{}: condensed contact needs ≥ 1 tool update (got {})", what, steps);
    if (tool.path.size() < 2) fail("{}: the tool needs a path from first contact to the final position", what);
    const auto start = std::chrono::steady_clock::now();
    CompressionPrediction out;
    try {
        CondensedContactModel condensed(model, {tool}, {}, options);
        const Vec3 a = tool.path.front(), b = tool.path.back();
        double update_ms = 0.0;
        for (int s = 1; s <= steps; ++s) {
            const auto up = condensed.move_to(tool, a + (double(s) / double(steps)) * (b - a));
            update_ms += up.contact_ms + up.recovery_ms;
        }
        out.displacement_mm = condensed.full_displacement_mm();
        if (precomputation) *precomputation = condensed.precomputation();
        if (ms_per_update) *ms_per_update = update_ms / double(steps);
    } catch (const Interrupted&) {
        throw;
    } catch (const Error& e) {
        fail("{}: {}", what, e.what());
    }
    require_no_tool_passage(model.mesh, out.displacement_mm, tool, what);
    out.landmarks = move_landmarks(model, out.displacement_mm, rest_landmarks);
    out.iterations = steps;
    for (std::size_t n = 0; 3 * n + 2 < out.displacement_mm.size(); ++n)
        out.max_displacement_mm = std::max(out.max_displacement_mm, Vec3(out.displacement_mm[3 * n], out.displacement_mm[3 * n + 1],
                                                                          out.displacement_mm[3 * n + 2]).norm());
    out.seconds = seconds_since(start);
    return out;
}

} // namespace physreg
