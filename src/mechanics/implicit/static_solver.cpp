// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/implicit/static_solver.hpp"

#include "physreg/core/error.hpp"

namespace physreg {

StaticMethod parse_static_method(const std::string& text)
{
    if (text == "relaxation") return StaticMethod::relaxation;
    if (text == "newton") return StaticMethod::newton;
    fail("solver '{}' is not one of relaxation, newton", text);
}

std::string to_string(StaticMethod method)
{
    return method == StaticMethod::newton ? "newton" : "relaxation";
}

StaticSolver::StaticSolver(const TledModel& model, const StaticSolverOptions& options) : m_options(options)
{
    if (options.method == StaticMethod::newton) m_newton = std::make_unique<NewtonSolver>(model, options.newton);
    else m_relaxation = std::make_unique<TledSolver<double>>(model);
}

StaticSolver::~StaticSolver() = default;

void StaticSolver::set_loads(Loads loads)
{
    if (m_newton) m_newton->set_loads(std::move(loads));
    else m_relaxation->set_loads(std::move(loads));
}

void StaticSolver::set_coupling(const PenaltyCoupling* coupling)
{
    if (m_newton) m_newton->set_coupling(coupling);
    else m_relaxation->set_coupling(coupling);
}

StaticSolveResult StaticSolver::solve(double load_factor, long ramp_iterations)
{
    StaticSolveResult r;
    if (m_newton) {
        const NewtonSummary s = m_newton->solve_equilibrium(load_factor);
        r.converged = s.converged;
        r.iterations = s.newton_iterations;
        r.message = s.message;
        return r;
    }
    EquilibriumOptions o = m_options.relaxation;
    if (ramp_iterations > 0) o.ramp_iterations = ramp_iterations;
    const SolveSummary s = m_relaxation->solve_equilibrium(o, load_factor);
    r.converged = s.converged();
    r.iterations = s.iterations;
    r.message = s.message;
    return r;
}

void StaticSolver::reset_load_factor()
{
    if (m_newton) m_newton->reset_load_factor();
    else m_relaxation->reset_load_factor();
}

void StaticSolver::set_displacement(const std::vector<double>& u)
{
    if (m_newton) m_newton->set_displacement(u);
    else m_relaxation->set_displacement(u);
}

std::vector<double> StaticSolver::displacement_mm() const
{
    return m_newton ? m_newton->displacement_mm() : m_relaxation->displacement_mm();
}

} // namespace physreg
