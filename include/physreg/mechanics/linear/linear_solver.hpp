// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Linear solvers for the symmetric positive definite systems of implicit mechanics (K Δu = −r).
//
// - cholmod: supernodal Cholesky (SuiteSparse CHOLMOD, through Eigen). The symbolic analysis (fill-
//   reducing ordering, supernodes) is done once per sparsity pattern and reused for every Newton
//   step and tool position; each solve refactors numerically.
// - pcg-amg: conjugate gradients preconditioned by one V-cycle of hypre's BoomerAMG for systems
//   (3 unknowns per node, nodal coarsening; optionally the rigid rotations as interpolation
//   vectors, which needs set_node_coordinates). Memory and cost O(n) per iteration, but the setup
//   is redone for every tangent and the iteration count grows as ν → 0.5.
// - pcg-factor: conjugate gradients preconditioned by the Cholesky factor of an *earlier* tangent.
//   Along a tool trajectory the tangent changes slowly, so a stale factor keeps PCG to a few
//   iterations; the factor is renewed when PCG needs more than `refactor_iterations`.
// A tangent that is not positive definite (buckling, an unconstrained mode) is factored again with
// a diagonal shift σ I, growing 10× per try from 1e-6 × the largest diagonal entry; the shift is reported (a shifted tangent still gives a
// descent direction for the energy line search; convergence is always judged on the true residual).
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

namespace physreg {

enum class LinearSolverKind { automatic, cholmod, pcg_factor, pcg_amg };
LinearSolverKind parse_linear_solver(const std::string& text); ///< auto | cholmod | pcg-factor | pcg-amg
std::string to_string(LinearSolverKind kind);

struct LinearSolveStats {
    int iterations = 0;      ///< PCG iterations (0 for a direct solve)
    bool factorised = false; ///< a numeric factorisation was made
    double shift = 0.0;      ///< diagonal shift needed to factor (0: positive definite)
    double factorisation_s = 0.0, solve_s = 0.0;
};

struct LinearSolverOptions {
    LinearSolverKind kind = LinearSolverKind::automatic;
    double pcg_relative_tolerance = 1e-10; ///< ‖r‖ ≤ tol ‖b‖
    int amg_max_iterations = 1000;         ///< pcg-amg: an error beyond this many iterations
    /// pcg-amg: add the rigid rotations to BoomerAMG's interpolation (hypre's GM-2 elasticity
    /// variant). Off by default: on a 28×28×14 block at ν = 0.49 it took 106 CG iterations and
    /// 4.0 s against 87 and 2.0 s without (the setup and the V-cycles cost twice as much).
    bool amg_rigid_modes = false;
    int refactor_iterations = 25;          ///< pcg-factor: renew the factor beyond this many iterations
    void validate() const;
};

class SymmetricSolver {
public:
    explicit SymmetricSolver(const LinearSolverOptions& options);
    ~SymmetricSolver();
    SymmetricSolver(SymmetricSolver&&) noexcept;
    SymmetricSolver& operator=(SymmetricSolver&&) noexcept;

    /// Solves K x = b. K (both triangles stored) keeps its sparsity pattern between calls. Throws
    /// Error when K cannot be factored even with a shift of 1e3 × its largest diagonal entry.
    LinearSolveStats solve(const SparseMatrix& k, const Eigen::VectorXd& b, Eigen::VectorXd& x);
    /// Reference node positions (mm, 3 per node): pcg-amg builds the rigid rotations from them.
    void set_node_coordinates(std::vector<double> xyz);

    /// The symbolic analysis of K's pattern alone (CHOLMOD's ordering; kept for the factorisation):
    /// the non-zeros the Cholesky factor L will have, to size memory before factorising.
    double analyse(const SparseMatrix& k);
    /// Factors K now (shifted if it is not positive definite), for later solve_factored calls.
    LinearSolveStats factorise(const SparseMatrix& k);
    /// Solves with the factor of the last factorised matrix (modified Newton: a stale tangent).
    /// Throws Error when there is none.
    LinearSolveStats solve_factored(const Eigen::VectorXd& b, Eigen::VectorXd& x);
    /// The same for several right-hand sides at once (the columns of b; BLAS-3 in CHOLMOD).
    LinearSolveStats solve_factored(const Eigen::MatrixXd& b, Eigen::MatrixXd& x);
    bool has_factor() const;
    /// Forget the factor (the next pcg-factor solve refactors).
    void invalidate();
    const LinearSolverOptions& options() const { return m_options; }

private:
    struct Impl;
    LinearSolverOptions m_options;
    std::unique_ptr<Impl> m_impl;
};

/// y = K x for a symmetric K stored in both triangles (column j is row j), on OpenMP threads.
void symmetric_product(const SparseMatrix& k, const Eigen::VectorXd& x, Eigen::VectorXd& y);

} // namespace physreg
