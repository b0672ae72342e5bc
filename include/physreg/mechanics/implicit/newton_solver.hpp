// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Static equilibrium by Newton's method on the assembled tangent: the implicit counterpart of
// dynamic relaxation (tled_solver.hpp), for the same model, loads and coupling, with the same
// equilibrium.
//
// - Line search on the total energy Π(u) = W_int(u) + W_contact(u) − s f_ext·u (Armijo
//   backtracking): a Newton step that would invert an element or raise the energy is shortened.
// - Load stepping: the load factor goes from the last equilibrium to the target in increments; an
//   increment that fails (no convergence, an element that cannot be kept from inverting) is halved,
//   up to max_load_cuts times, then the solve reports failure (or throws, for inversion).
// - Prescribed displacements enter the first Newton step of an increment by lifting
//   (K_ff Δu_f = −r_f − K_fc Δu_c), so the boundary does not jump ahead of the interior.
// - Rigid tools: frictionless contact by the augmented Lagrangian method on the tools' signed
//   distance g (outside > 0): a node's pressure is p = max(0, λ − ε g), energy (p² − λ²)/(2ε);
//   Newton converges for fixed multipliers λ, then λ ← p, until no node penetrates more than
//   penetration_tolerance_mm. ε is contact_penalty_scale times the node's stiffness bound. The
//   tangent includes the curvature of spheres and cylinders (−p ∇²g).
#include "physreg/mechanics/linear/linear_solver.hpp"
#include "physreg/model/loads.hpp"
#include "physreg/mechanics/explicit/tled_solver.hpp"

#include <string>
#include <vector>

namespace physreg {

/// One node against one tool in the augmented Lagrangian: signed distance g (outside > 0),
/// pressure p = max(0, λ − ε g) (N), energy (p² − λ²)/(2ε) (mJ), its gradient −p n (N) and Hessian
/// ε n nᵀ − p ∇²g (N/mm; ∇²g from the curvature of spheres and cylinders). With `exact_curvature`
/// false the curvature term uses min(p, λ) instead of p: the same at a converged multiplier (p = λ),
/// but free of the large negative tangential stiffness of a deep first penetration (λ = 0).
struct ContactTerm {
    double gap_mm = 0.0, pressure_n = 0.0, energy_mj = 0.0;
    Vec3 gradient = Vec3::Zero();
    Mat3 hessian = Mat3::Zero();
};
ContactTerm contact_term(const Indenter& tool, const Vec3& x, double load_factor, double lambda_n, double penalty_n_per_mm,
                         bool exact_curvature = true);

struct NewtonOptions {
    int max_iterations = 40;                  ///< Newton iterations per load increment and contact update
    double residual_tolerance = 1e-7;         ///< converged: largest free residual ≤ this × largest internal nodal force
    int max_load_cuts = 12;                   ///< halvings of a failing load increment before giving up
    double contact_penalty_scale = 10.0;      ///< ε = scale × the node's stiffness bound (N/mm)
    double penetration_tolerance_mm = 1e-3;   ///< augmented Lagrangian updates until no node penetrates more
    int max_contact_updates = 30;
    /// The tools' curvature term −p ∇²g of the tangent is negative in the tangential directions; with
    /// the exact p, a deep first penetration (pure penalty, λ = 0) makes the tangent strongly
    /// indefinite. By default the term uses min(p, λ) (exact once the multipliers have converged:
    /// quadratic convergence near the solution, a positive definite tangent on first contact).
    bool exact_contact_curvature = false;
    /// Update the multipliers as soon as Newton stalls (the residual falls less than 2× in two
    /// iterations) instead of only after convergence: with λ near the pressures the curvature
    /// term becomes exact and Newton fast again. Off by default (the classical ALM).
    bool update_contact_on_stall = false;
    LinearSolverOptions linear;
    void validate() const;
};

struct NewtonSummary {
    bool converged = false;
    std::string message;
    std::string linear_solver;                ///< the method actually used
    int increments = 0;                       ///< load increments solved
    int load_cuts = 0;                        ///< increments halved after a failure
    int newton_iterations = 0;
    int contact_updates = 0;                  ///< augmented Lagrangian multiplier updates
    long linear_iterations = 0;               ///< PCG iterations (pcg-factor)
    int factorisations = 0;
    int shifted_factorisations = 0;           ///< tangents that needed a diagonal shift to factor
    std::vector<double> residual_history;     ///< largest free residual (N) after every Newton iteration
    double residual_n = 0.0;                  ///< final largest free residual, N
    double reference_force_n = 0.0;           ///< largest internal nodal force, N
    double max_penetration_mm = 0.0;
    std::size_t contact_nodes = 0;
    double assembly_s = 0.0, factorisation_s = 0.0, solve_s = 0.0, contact_s = 0.0, line_search_s = 0.0, seconds = 0.0;
};

class NewtonSolver {
public:
    explicit NewtonSolver(const TledModel& model, const NewtonOptions& options = {});
    ~NewtonSolver();

    /// Replaces the loads (validated against the model). Keeps the displacement (warm start).
    void set_loads(Loads loads);
    const Loads& loads() const { return m_loads; }
    /// Tissue–tissue penalty coupling (nullptr: none); must outlive the solver's use of it.
    void set_coupling(const PenaltyCoupling* coupling);

    /// Static equilibrium at `load_factor`, stepping from the last equilibrium's load factor.
    /// Non-convergence is reported in the summary (state back at the last converged increment);
    /// an element that inverts at every step size, a non-finite tangent or residual, and a model
    /// with free rigid-body modes throw Error.
    NewtonSummary solve_equilibrium(double load_factor = 1.0, const ProgressCallback& progress = {});

    void reset();
    void reset_load_factor() { m_load_factor = 0.0; }
    double load_factor() const { return m_load_factor; }
    void set_displacement(const std::vector<double>& u_mm);
    std::vector<double> displacement_mm() const { return m_u; }
    /// Internal nodal forces at the current displacement, N (3 per node).
    std::vector<double> internal_forces_n() const;
    std::size_t contact_nodes() const { return m_contact_count; }
    const NewtonOptions& options() const { return m_options; }

private:
    struct Evaluation {
        double energy = 0.0;        ///< Π, mJ
        std::int64_t inverted = -1;
        std::vector<double> gradient; ///< ∂Π/∂u (N), constrained entries included
        std::vector<double> internal; ///< internal forces alone
    };
    bool evaluate(const std::vector<double>& u, double s, Evaluation& out, SparseMatrix* k, NewtonSummary& summary);
    double contact_terms(const std::vector<double>& u, double s, std::vector<double>& gradient, SparseMatrix* k, bool count);
    enum class Outcome { converged, not_converged, inverted, stalled };
    bool m_allow_stall = false;
    Outcome newton(double s, NewtonSummary& summary, std::string& why, std::int64_t& inverted, const ProgressCallback& progress);
    Outcome solve_increment(double s, NewtonSummary& summary, std::string& why, std::int64_t& inverted, const ProgressCallback& progress);
    double max_penetration(double s) const;
    void check_constrained() const;

    const TledModel& m_model;
    NewtonOptions m_options;
    Loads m_loads;
    const PenaltyCoupling* m_coupling = nullptr;
    std::unique_ptr<StiffnessAssembler> m_assembler;
    SparseMatrix m_k;
    SymmetricSolver m_linear;
    std::vector<double> m_u, m_external, m_prescribed;
    std::vector<std::uint8_t> m_constrained;
    std::vector<std::vector<double>> m_multiplier; ///< per tool, per surface node: λ (N)
    std::vector<double> m_penalty;                 ///< per surface node: ε (N/mm)
    std::size_t m_contact_count = 0;
    double m_load_factor = 0.0;
};

} // namespace physreg
