// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Conjugate gradients preconditioned by hypre's BoomerAMG, set up for 3D elasticity (the solver
// behind LinearSolverKind::pcg_amg). Each call is independent: hypre runs on MPI_COMM_SELF, so
// every MPI rank of a distributed run solves its own systems.
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"

#include <Eigen/Core>
#include <vector>

namespace physreg::detail {

struct AmgPcgResult {
    int iterations = 0;
    double relative_residual = 0.0;
    bool converged = false;
    double setup_s = 0.0, solve_s = 0.0;
};

/// Solves K x = b (K symmetric, both triangles stored, 3 interleaved unknowns per node) to
/// ‖r‖ ≤ tolerance ‖b‖. `coordinates` (3 per node, mm) add the rigid rotations to the
/// interpolation; empty: the systems approach alone.
AmgPcgResult solve_amg_pcg(const SparseMatrix& k, const Eigen::VectorXd& b, Eigen::VectorXd& x, const std::vector<double>& coordinates,
                           double tolerance, int max_iterations);

} // namespace physreg::detail
