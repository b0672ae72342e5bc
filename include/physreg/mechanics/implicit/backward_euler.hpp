// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Implicit (backward Euler) dynamics of a TLED model, for paper 001's registration and for
// simulations whose time steps are far above the explicit critical step.
//
// The unknown of a step is the end velocity v (x_{n+1} = x_n + Δt v). The residual
//   r(v) = M (v − v_n)/Δt + α M v + (1 + β/Δt) f(x_n + Δt v) − (β/Δt) f(x_n) − f_ext(t_{n+1})
// is backward Euler with Rayleigh damping D = α M + β K, the stiffness-proportional part taken as
// β (f(x_{n+1}) − f(x_n))/Δt (= β K v exactly for a linear model, and needing no tangent for the
// nonlinear ones). Its Jacobian J = (1/Δt + α) M + (Δt + β) K(x) is symmetric positive definite
// for a small enough Δt even without Dirichlet conditions (paper 001's registration has none).
//
// Each step takes Newton iterations on r, starting from v = 0 (whose residual reuses the force
// of the previous step): by default until ‖r‖∞ ≤ tolerance × the largest force, or a fixed count
// (one iteration is the linearised backward Euler of SOFA's EulerImplicit solver). The tangent is
// assembled and factorised (CHOLMOD) every iteration, once per step, or only when a stale factor
// stops converging: a stale factor turns Newton into the chord method, which along a smooth motion
// needs one force evaluation and one pair of triangular solves per iteration.
#include "physreg/mechanics/linear/linear_solver.hpp"
#include "physreg/model/loads.hpp"
#include "physreg/mechanics/elements/auxiliary_elements.hpp"
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"

#include <memory>
#include <string>
#include <vector>

namespace physreg {

enum class MassKind { lumped, consistent };
MassKind parse_mass_kind(const std::string& text); ///< lumped | consistent
std::string to_string(MassKind kind);

/// The mass matrix (tonne) in the assembler's pattern: lumped (ρV/nodes per element, diagonal) or
/// consistent (ρ ∫ N_a N_b dV: ρV/20 (1 + δ_ab) for linear tetrahedra, 2×2×2 Gauss for hexahedra).
SparseMatrix assemble_mass_matrix(const StiffnessAssembler& assembler, MassKind kind);

enum class TangentUpdate { every_iteration, every_step, stale };
TangentUpdate parse_tangent_update(const std::string& text); ///< every-iteration | every-step | stale
std::string to_string(TangentUpdate update);

struct BackwardEulerOptions {
    double time_step_s = 0.01;
    double rayleigh_mass_per_s = 0.0;   ///< α of D = α M + β K, 1/s
    double rayleigh_stiffness_s = 0.0;  ///< β, s
    MassKind mass = MassKind::lumped;
    TangentUpdate tangent = TangentUpdate::stale;
    /// Co-rotational law: the Jacobian's stiffness is the rotated R K₀ Rᵀ (true, as SOFA: positive
    /// definite even with crushed or inverted elements) or the exact tangent (false: quadratic
    /// convergence while every element is well shaped).
    bool rotated_corotational_tangent = true;
    int max_newton_iterations = 10;     ///< per step (tolerance mode)
    /// > 0: exactly this many Newton iterations per step, no convergence test (1: linearised
    /// backward Euler). 0: iterate to residual_tolerance, an error when it is not reached.
    int fixed_newton_iterations = 0;
    double residual_tolerance = 1e-6;   ///< ‖r_free‖∞ ≤ this × the largest internal, external or inertial nodal force
    double stale_contraction = 0.5;     ///< stale: refactor when an iteration reduces ‖r‖ by less than this factor
    void validate() const;
};

struct BackwardEulerStep {
    bool converged = true;        ///< fixed-iteration steps: always true (the residual is reported)
    int newton_iterations = 0;
    int factorisations = 0;
    int shifted_factorisations = 0; ///< Jacobians that were not positive definite (factored with a diagonal shift)
    double residual_n = 0.0;      ///< largest free residual at the end of the step, N
    double reference_force_n = 0.0;
    std::vector<double> residual_history; ///< N, after each force evaluation
    std::int64_t inverted_elements = 0;   ///< co-rotational law: elements with det F ≤ 0 at the end of the step
    double force_s = 0.0, assembly_s = 0.0, factorisation_s = 0.0, solve_s = 0.0, seconds = 0.0;
};

class BackwardEuler {
public:
    /// The coupling (may be null) must outlive the integrator. Throws Error for bad options and for
    /// the averaged-nodal-pressure tetrahedron (no tangent).
    /// `auxiliary` (paper 001's capsule membrane, vessel beams) must outlive the integrator too;
    /// their forces and stiffness join the model's.
    BackwardEuler(const TledModel& model, const BackwardEulerOptions& options, const PenaltyCoupling* coupling = nullptr,
                  std::vector<const AuxiliaryElements*> auxiliary = {});
    ~BackwardEuler();

    /// Constraints (displacement × load factor at the step's end time), nodal forces × load factor.
    /// Rigid indenters are refused: contact is not part of this integrator yet.
    void set_loads(Loads loads);
    /// A uniform body acceleration (gravity), mm/s²: nodal force = lumped mass × g × load factor.
    void set_body_acceleration(const Vec3& g_mm_s2);
    /// Position-dependent external forces (paper 001's pair forces) linearised about the state at
    /// the start of each step: f_ext(u) ≈ f_ext − K_e (u − u_n), K_e diagonal (N/mm per dof, ≥ 0,
    /// empty: none). Makes the forces implicit in the step (stable for any Δt) without their exact
    /// derivative; K_e enters the Jacobian at its next factorisation.
    void set_external_stiffness(std::vector<double> diagonal_n_per_mm);
    /// The next step factorises a fresh Jacobian (fixed-iteration runs with a stale tangent never
    /// decide that themselves).
    void refresh_tangent() { m_have_factor = false; }

    /// Advances by one time step. Throws Error for an inverted element (naming it and the time), a
    /// non-finite force, or a step that does not converge even with a fresh tangent every iteration.
    BackwardEulerStep step();

    double time_s() const { return m_time; }
    const std::vector<double>& displacement_mm() const { return m_u; }
    const std::vector<double>& velocity_mm_s() const { return m_v; }
    /// Sets the state (and time); velocities of constrained dofs are kept as given.
    void set_state(const std::vector<double>& u_mm, const std::vector<double>& v_mm_s, double time_s = 0.0);
    double kinetic_energy_mj() const;  ///< ½ vᵀ M v
    double strain_energy_mj() const;   ///< elastic + hourglass + coupling energy at the current state
    const SparseMatrix& mass_matrix() const { return m_mass; }
    const BackwardEulerOptions& options() const { return m_options; }
    int total_factorisations() const { return m_total_factorisations; }

private:
    bool forces_if_valid(const std::vector<double>& u, std::vector<double>& f, BackwardEulerStep& stats) const;
    void factorise_jacobian(const std::vector<double>& u, BackwardEulerStep& stats);
    bool attempt(BackwardEulerStep& stats, bool fresh_tangent_every_iteration);

    const TledModel& m_model;
    BackwardEulerOptions m_options;
    std::vector<const AuxiliaryElements*> m_auxiliary;
    StiffnessAssembler m_assembler;
    SparseMatrix m_mass, m_k, m_jacobian;
    /// Lumped mass: the diagonal (3 per node), so that M v is a scaling, not a sparse product
    /// over the stiffness pattern; empty for the consistent mass.
    std::vector<double> m_mass_diagonal;
    void mass_times(const Eigen::VectorXd& v, Eigen::VectorXd& out) const;
    SymmetricSolver m_linear;
    Loads m_loads;
    Vec3 m_gravity = Vec3::Zero();
    std::vector<double> m_external_stiffness; ///< empty or 3 per node, N/mm
    std::vector<std::uint8_t> m_constrained;
    std::vector<double> m_u, m_v, m_force; ///< m_force = f(m_u)
    double m_time = 0.0;
    double m_jacobian_time_step = 0.0;     ///< Δt the factor was made for
    bool m_have_factor = false;
    int m_total_factorisations = 0;
};

} // namespace physreg
