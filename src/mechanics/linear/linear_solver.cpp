// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/linear/linear_solver.hpp"

#include "mechanics/detail/timing.hpp"
#include "mechanics/detail/amg_pcg.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"

#include <Eigen/CholmodSupport>
#include <chrono>
#include <cmath>
#include <exception>
#include <mutex>
#include <omp.h>

namespace physreg {
using detail::seconds_since;
namespace {

// OpenBLAS (OpenMP build) behind CHOLMOD runs its BLAS on the caller's OpenMP thread count. On
// this project's 2-core machines two BLAS threads made the supernodal factorisation 3.6× slower
// than one (4.5 s vs 1.24 s for 37 845 dofs, 21.9 GFlop: the threads spin-wait against each
// other), and passive waiting only brought it back to the 1-thread time. So CHOLMOD runs on one thread.
struct SingleThreadedBlas {
    int saved = omp_get_max_threads();
    SingleThreadedBlas() { omp_set_num_threads(1); }
    ~SingleThreadedBlas() { omp_set_num_threads(saved); }
};

// Runs a CHOLMOD call where the libraries' own OpenMP regions stay inactive. Outside any parallel
// region, CHOLMOD's supernodal factorisation opens a team of 4 for each large supernode, and with
// the one-thread setting above libgomp created and destroyed those threads every time (34 503
// thread creations in four factorisations of an 81 k-dof vector Laplacian); a factorisation of
// 192 k dofs took 1.5× the time (2.31 s against 1.51 s), the phantom's solves on OMP_NUM_THREADS=1
// 6× (small preset 165 s against 44 s in all). Inside an
// active region of two threads (one works, the other waits at the barrier and then sleeps) the
// nested regions run on the calling thread alone, as they do when the phantom solves two at once.
template <typename Work>
void on_one_thread(Work&& work)
{
    if (omp_in_parallel()) {
        const SingleThreadedBlas one_thread;
        work();
        return;
    }
    std::exception_ptr error;
#pragma omp parallel num_threads(2)
    {
#pragma omp single
        {
            try {
                const SingleThreadedBlas one_thread;
                work();
            } catch (...) {
                error = std::current_exception();
            }
        }
    }
    if (error) std::rethrow_exception(error);
}


const char* cholmod_ordering_name(int ordering)
{
    switch (ordering) {
    case CHOLMOD_NATURAL: return "natural";
    case CHOLMOD_GIVEN: return "given";
    case CHOLMOD_AMD: return "AMD";
    case CHOLMOD_METIS: return "METIS";
    case CHOLMOD_NESDIS: return "NESDIS";
    case CHOLMOD_COLAMD: return "COLAMD";
    default: return "other";
    }
}

} // namespace

LinearSolverKind parse_linear_solver(const std::string& text)
{
    if (text == "auto") return LinearSolverKind::automatic;
    if (text == "cholmod") return LinearSolverKind::cholmod;
    if (text == "pcg-factor") return LinearSolverKind::pcg_factor;
    if (text == "pcg-amg") return LinearSolverKind::pcg_amg;
    fail("linear solver '{}' is not one of auto, cholmod, pcg-factor, pcg-amg", text);
}

std::string to_string(LinearSolverKind kind)
{
    switch (kind) {
    case LinearSolverKind::automatic: return "auto";
    case LinearSolverKind::cholmod: return "cholmod";
    case LinearSolverKind::pcg_amg: return "pcg-amg";
    default: return "pcg-factor";
    }
}

void LinearSolverOptions::validate() const
{
    if (!(pcg_relative_tolerance > 0 && pcg_relative_tolerance < 1))
        fail("linear solver: pcg tolerance {} must be in (0, 1)", pcg_relative_tolerance);
    if (refactor_iterations < 1) fail("linear solver: refactor_iterations {} must be ≥ 1", refactor_iterations);
    if (amg_max_iterations < 1) fail("linear solver: amg_max_iterations {} must be ≥ 1", amg_max_iterations);
}

void symmetric_product(const SparseMatrix& k, const Eigen::VectorXd& x, Eigen::VectorXd& y)
{
    const Eigen::Index n = k.cols();
    y.resize(n);
    const int* outer = k.outerIndexPtr();
    const int* inner = k.innerIndexPtr();
    const double* values = k.valuePtr();
#pragma omp parallel for schedule(static)
    for (Eigen::Index c = 0; c < n; ++c) {
        double sum = 0.0;
        for (int p = outer[c]; p < outer[c + 1]; ++p) sum += values[p] * x[inner[p]];
        y[c] = sum;
    }
}

struct SymmetricSolver::Impl {
    Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower> factor;
    bool analysed = false, factored = false;
    double last_shift = 0.0;
    Eigen::Index pattern_nnz = -1, pattern_rows = -1;
    double factor_nonzeros = 0.0; ///< nnz(L) the analysis predicts
    std::vector<double> coordinates; ///< pcg-amg: node positions for the rigid rotations

    Impl()
    {
        factor.cholmod().print = 0; // failures are reported by us, not on stderr
    }

    // Numeric factorisation, shifted when K is not positive definite. Returns the shift used.
    double factorise(const SparseMatrix& k)
    {
        double shift = 0.0;
        on_one_thread([&] { shift = factorise_here(k); });
        return shift;
    }

    // Symbolic analysis (ordering, supernodes), once per sparsity pattern.
    void analyse_here(const SparseMatrix& k)
    {
        if (!analysed || k.nonZeros() != pattern_nnz || k.rows() != pattern_rows) {
            {
                // One symbolic analysis at a time in the process: CHOLMOD's METIS ordering draws
                // from GKlib's global random state, so two solvers analysing at once (the phantom
                // solves its compressions two at a time) got orderings that depended on timing,
                // and the ground truth differed from run to run by up to 6e-6 mm.
                static std::mutex analysis;
                const std::lock_guard<std::mutex> lock(analysis);
                factor.analyzePattern(k);
            }
            analysed = true;
            const cholmod_common& c = factor.cholmod();
            const auto& method = c.method[c.selected];
            logger()->debug("linear solver: {} dofs, ordering {}, nnz(L) {:.3g}, {:.3g} GFlop per factorisation", k.rows(),
                            cholmod_ordering_name(method.ordering), method.lnz, method.fl * 1e-9);
            pattern_nnz = k.nonZeros();
            pattern_rows = k.rows();
            factor_nonzeros = method.lnz;
        }
    }

    double factorise_here(const SparseMatrix& k)
    {
        analyse_here(k);
        factor.setShift(0.0);
        factor.factorize(k);
        if (factor.info() == Eigen::Success) {
            factored = true;
            return 0.0;
        }
        double largest = 0.0;
        for (Eigen::Index j = 0; j < k.cols(); ++j) largest = std::max(largest, std::abs(k.coeff(j, j)));
        // Away from equilibrium a compressed near-incompressible material can have a strongly
        // indefinite tangent (large compressive pressure in the geometric stiffness): the shift
        // grows until the factor exists, which turns the step towards steepest descent.
        // Each failed attempt costs a factorisation: start from a tenth of the last shift that worked
        // (successive tangents of one solve need similar shifts) instead of from 1e-6.
        const double first = last_shift > 0.0 ? std::max(1e-6 * largest, 0.1 * last_shift) : 1e-6 * largest;
        for (double shift = first; shift <= 1.001e3 * largest; shift *= 10.0) {
            factor.setShift(shift);
            factor.factorize(k);
            if (factor.info() == Eigen::Success) {
                factored = true;
                last_shift = shift;
                logger()->debug("linear solver: tangent not positive definite, factored with shift {:.3g}", shift);
                return shift;
            }
        }
        factored = false;
        fail("linear solver: the tangent stiffness is not positive definite even with a diagonal shift of 1e3 × its "
             "largest entry ({:.3g}): it has NaN entries, or the model is not constrained",
             largest);
    }
};

SymmetricSolver::SymmetricSolver(const LinearSolverOptions& options) : m_options(options), m_impl(std::make_unique<Impl>())
{
    options.validate();
    if (m_options.kind == LinearSolverKind::automatic) m_options.kind = LinearSolverKind::pcg_factor;
}
SymmetricSolver::~SymmetricSolver() = default;
SymmetricSolver::SymmetricSolver(SymmetricSolver&&) noexcept = default;
SymmetricSolver& SymmetricSolver::operator=(SymmetricSolver&&) noexcept = default;

LinearSolveStats SymmetricSolver::factorise(const SparseMatrix& k)
{
    LinearSolveStats stats;
    const auto start = std::chrono::steady_clock::now();
    stats.shift = m_impl->factorise(k);
    stats.factorised = true;
    stats.factorisation_s = seconds_since(start);
    return stats;
}

namespace {
// One or several right-hand sides with the kept factor (on one BLAS thread, as the factorisation).
template <class Rhs, class Solution>
LinearSolveStats solve_with_factor(const Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower>& factor, bool factored, Eigen::Index rows,
                                   const Rhs& b, Solution& x)
{
    if (!factored) fail("linear solver: no factorisation to solve with");
    if (b.rows() != rows) fail("linear solver: right-hand side of {} rows for a factor of {}", b.rows(), rows);
    LinearSolveStats stats;
    const auto start = std::chrono::steady_clock::now();
    {
        const SingleThreadedBlas one_thread;
        x = factor.solve(b);
    }
    stats.solve_s = seconds_since(start);
    return stats;
}
} // namespace

LinearSolveStats SymmetricSolver::solve_factored(const Eigen::VectorXd& b, Eigen::VectorXd& x)
{
    return solve_with_factor(m_impl->factor, m_impl->factored, m_impl->pattern_rows, b, x);
}

LinearSolveStats SymmetricSolver::solve_factored(const Eigen::MatrixXd& b, Eigen::MatrixXd& x)
{
    return solve_with_factor(m_impl->factor, m_impl->factored, m_impl->pattern_rows, b, x);
}

double SymmetricSolver::analyse(const SparseMatrix& k)
{
    on_one_thread([&] { m_impl->analyse_here(k); });
    return m_impl->factor_nonzeros;
}

bool SymmetricSolver::has_factor() const
{
    return m_impl->factored;
}

void SymmetricSolver::set_node_coordinates(std::vector<double> xyz)
{
    m_impl->coordinates = std::move(xyz);
}

void SymmetricSolver::invalidate()
{
    m_impl->factored = false;
}

LinearSolveStats SymmetricSolver::solve(const SparseMatrix& k, const Eigen::VectorXd& b, Eigen::VectorXd& x)
{
    LinearSolveStats stats;
    Impl& s = *m_impl;
    const auto direct = [&] {
        auto start = std::chrono::steady_clock::now();
        stats.shift = s.factorise(k);
        stats.factorised = true;
        stats.factorisation_s += seconds_since(start);
        start = std::chrono::steady_clock::now();
        {
            const SingleThreadedBlas one_thread;
            x = s.factor.solve(b);
        }
        stats.solve_s += seconds_since(start);
    };
    if (m_options.kind == LinearSolverKind::pcg_amg) {
        const detail::AmgPcgResult amg =
            detail::solve_amg_pcg(k, b, x, m_options.amg_rigid_modes ? s.coordinates : std::vector<double>{},
                                  m_options.pcg_relative_tolerance, m_options.amg_max_iterations);
        stats.iterations = amg.iterations;
        stats.factorised = true; // the AMG setup plays the factorisation's part
        stats.factorisation_s = amg.setup_s;
        stats.solve_s = amg.solve_s;
        if (!amg.converged)
            fail("linear solver pcg-amg: CG with BoomerAMG reached a relative residual of {:.3g} after {} iterations (tolerance "
                 "{:.3g}); the tangent may be indefinite or too ill-conditioned (ν → 0.5): use cholmod or pcg-factor",
                 amg.relative_residual, amg.iterations, m_options.pcg_relative_tolerance);
        return stats;
    }
    if (m_options.kind == LinearSolverKind::cholmod || !s.factored || k.rows() != s.pattern_rows) {
        direct();
        return stats;
    }
    // PCG with the stale factor as preconditioner.
    const auto start = std::chrono::steady_clock::now();
    const double b_norm = b.norm();
    x.setZero(b.size());
    if (b_norm == 0.0) return stats;
    const auto precondition = [&](const Eigen::VectorXd& v) {
        const SingleThreadedBlas one_thread;
        return Eigen::VectorXd(s.factor.solve(v));
    };
    Eigen::VectorXd r = b, z = precondition(r), p = z, q;
    double rz = r.dot(z);
    bool converged = false;
    for (int it = 1; it <= m_options.refactor_iterations; ++it) {
        symmetric_product(k, p, q);
        const double pq = p.dot(q);
        if (!(pq > 0.0)) break; // K not positive definite along p: refactor with a shift
        const double alpha = rz / pq;
        x += alpha * p;
        r -= alpha * q;
        stats.iterations = it;
        const double relative = r.norm() / b_norm;
        if (relative <= m_options.pcg_relative_tolerance) {
            converged = true;
            break;
        }
        // A factor gone stale shows in the first iterations' rate: when that rate would need more
        // iterations than the budget allows, renew the factor now instead of after the budget.
        if (it >= 4 && (relative >= 1.0 || std::log(m_options.pcg_relative_tolerance) / std::log(relative) * it >
                                                  1.5 * m_options.refactor_iterations))
            break;
        z = precondition(r);
        const double rz_new = r.dot(z);
        p = z + (rz_new / rz) * p;
        rz = rz_new;
    }
    stats.solve_s += seconds_since(start);
    if (!converged) direct(); // the factor has gone stale: renew it
    return stats;
}

} // namespace physreg
