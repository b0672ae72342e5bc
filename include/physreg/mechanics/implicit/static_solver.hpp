// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// One interface over the two static solvers, so that pipelines (compression prediction, tracking,
// the enrichment database) choose by option: dynamic relaxation (explicit TLED iterations) or
// Newton's method on the assembled tangent. Both solve the same discrete equilibrium.
#include "physreg/mechanics/implicit/newton_solver.hpp"
#include "physreg/mechanics/explicit/tled_solver.hpp"

#include <memory>
#include <string>

namespace physreg {

enum class StaticMethod { relaxation, newton };
StaticMethod parse_static_method(const std::string& text); ///< relaxation | newton
std::string to_string(StaticMethod method);

struct StaticSolverOptions {
    StaticMethod method = StaticMethod::relaxation;
    EquilibriumOptions relaxation;
    NewtonOptions newton;
};

struct StaticSolveResult {
    bool converged = false;
    long iterations = 0;       ///< relaxation iterations, or Newton iterations
    std::string message;
};

class StaticSolver {
public:
    StaticSolver(const TledModel& model, const StaticSolverOptions& options);
    ~StaticSolver();
    void set_loads(Loads loads);
    void set_coupling(const PenaltyCoupling* coupling);
    /// Equilibrium at `load_factor`; `ramp_iterations` (relaxation only) overrides the options' ramp.
    /// Inversion and divergence throw Error, non-convergence is reported.
    StaticSolveResult solve(double load_factor, long ramp_iterations = 0);
    void reset_load_factor();
    void set_displacement(const std::vector<double>& u_mm);
    std::vector<double> displacement_mm() const;
    StaticMethod method() const { return m_options.method; }

private:
    StaticSolverOptions m_options;
    std::unique_ptr<TledSolver<double>> m_relaxation;
    std::unique_ptr<NewtonSolver> m_newton;
};

} // namespace physreg
