// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Total Lagrangian Explicit Dynamics: central differences with lumped mass and mass-proportional
// damping (paper 000 eq. 8), and dynamic relaxation to static equilibrium (adaptive damping from
// the Rayleigh quotient of the increment, per-node mass scaling and the convergence estimate of
// Joldes, Wittek & Miller's adaptive dynamic relaxation for TLED).
//
// Threads: elements are processed colour by colour; no two elements of a colour share a node, so
// each thread adds its forces straight into the nodal array. Every node receives its element
// contributions in the same order whatever the thread count, and reductions are summed in fixed
// blocks: results are bitwise identical for 1, 2 or more threads.
#include "physreg/core/thread_governor.hpp"
#include "physreg/model/loads.hpp"
#include "physreg/mechanics/elements/tled_model.hpp"
#include "physreg/mechanics/coupling/tissue_coupling.hpp"

#include <functional>
#include <string>
#include <vector>

namespace physreg {

struct EquilibriumOptions {
    long max_iterations = 100000;
    /// Converged when the estimated distance to equilibrium (ρ/(1−ρ)·|Δu|∞, ρ the observed
    /// contraction of increments) is below this, mm ...
    double displacement_tolerance_mm = 1e-3;
    /// ... and the largest residual force on a free degree of freedom is below this fraction of
    /// the largest internal nodal force (N/N).
    double residual_tolerance = 1e-4;
    /// Margin on the Gershgorin mass scaling (nonlinear stiffening); raise if DR diverges.
    double mass_safety = 2.0;
    /// Iterations over which constraints and tools move from the previous load level to the new.
    long ramp_iterations = 200;
    /// Tools press the surface's faces too, not only its nodes (FaceContactSamples): without it a
    /// sphere pressed deeper than about its radius can slip between the skin's nodes.
    bool face_contact = true;
    void validate() const;
};

enum class SolveStatus { converged, max_iterations };

struct SolveSummary {
    SolveStatus status = SolveStatus::max_iterations;
    long iterations = 0;
    double residual_n = 0.0;           ///< largest free residual force, N
    double reference_force_n = 0.0;    ///< largest internal nodal force, N
    double estimated_error_mm = 0.0;
    double seconds = 0.0;
    std::string message;
    bool converged() const { return status == SolveStatus::converged; }
};

struct Energies {
    double strain_mj = 0.0;    ///< Σ V Ψ(F), mJ (N·mm)
    double hourglass_mj = 0.0; ///< ½ Σ k Σ_α |Σ_b Γ_bα u_b|², mJ
    double kinetic_mj = 0.0;   ///< dynamic runs: ½ Σ m |v|², mJ
    double coupling_mj = 0.0;  ///< tissue–tissue penalty coupling: ½ Σ k_c |δ|², mJ
    double total_mj() const { return strain_mj + hourglass_mj + kinetic_mj + coupling_mj; }
};

/// Progress callback: fraction done in [0, 1] (dynamic runs) or -1 with the iteration (static).
using ProgressCallback = std::function<void(double fraction, long step)>;

template <typename Real>
class TledSolver {
public:
    explicit TledSolver(const TledModel& model);

    /// Replaces the loads (validated against the model). Keeps the displacement (warm start).
    void set_loads(Loads loads);
    const Loads& loads() const { return m_loads; }
    /// Adds tissue–tissue penalty coupling forces to every force evaluation (nullptr: none). The
    /// coupling must outlive the solver's use of it and match the model's nodes. Its stiffness
    /// enters the explicit time step and the dynamic-relaxation masses.
    void set_coupling(const PenaltyCoupling* coupling);
    /// Explicit step used by advance(): the model's stable step, reduced when a stiff coupling needs it.
    double time_step_s() const { return m_time_step; }

    /// Explicit dynamics from the current state for `duration_s`, at the model's stable step.
    /// Throws Error naming the step and element on inversion (J ≤ 0) or divergence.
    void advance(double duration_s, const ProgressCallback& progress = {});
    /// Static equilibrium under the loads at load factor `load_factor`, by dynamic relaxation
    /// from the current displacement. Non-convergence is reported in the summary; inversion or
    /// divergence throws Error.
    SolveSummary solve_equilibrium(const EquilibriumOptions& options, double load_factor = 1.0,
                                   const ProgressCallback& progress = {});

    /// Resets displacement, velocity and time to zero.
    void reset();
    /// Keeps the displacement but makes the next solve_equilibrium ramp its loads from load factor 0
    /// (e.g. after set_loads with a tool path that starts where the previous one ended).
    void reset_load_factor() { m_load_factor = 0.0; }
    void set_displacement(const std::vector<double>& u_mm);
    std::vector<double> displacement_mm() const;
    /// Internal nodal forces F(u) at the current displacement, N (3 per node).
    std::vector<double> internal_forces_n();
    Energies energies() const;
    double time_s() const { return m_time; }
    long steps() const { return m_steps; }
    /// Hexahedra: elements the force kernel takes as contiguous runs (grid rows numbered along x),
    /// per force evaluation; the others are gathered node by node.
    std::size_t run_elements() const { return m_run_elements; }
    /// Hexahedra of one shared box geometry: forces by the corner transform (hexahedron_kernel.hpp).
    bool box_elements() const { return m_box; }
    /// Nodes currently pushed out by an indenter.
    std::size_t contact_nodes() const { return m_contact_count; }
    /// Dynamic relaxation: surface-face samples that pressed into a tool at the last iteration
    /// (beyond a chord's sag) and were pushed back by the face contact's penalty.
    std::size_t pressed_face_samples() const { return m_pressed_face_samples; }

private:
    void compute_internal_forces(const Real* u, Real* f);
    void forces_in_parallel_region(const Real* u, Real* f, bool zero_first);
    bool push_node_out(const Indenter& indenter, Real* u, std::int32_t node, double load_factor, Vec3& normal) const;
    void constrain(Real* u, double load_factor, bool record_contacts);
    void constrain_with_active_set(Real* u, double load_factor, const Real* forces, Real s);
    void select_contact_candidates(const Real* u, double from_factor, double to_factor);
    void subtract_face_contact_forces(const Real* u, double load_factor, Real* f);
    Vec3 current_position(const Real* u, std::int32_t node) const; ///< rest + u, mm
    void check_state(const Real* u, const char* phase) const;
    std::vector<double> block_sums(const std::function<void(std::size_t, std::size_t, double*)>& partial, int values) const;

    const TledModel& m_model;
    Loads m_loads;
    const PenaltyCoupling* m_coupling = nullptr;
    ThreadGovernor m_governor; ///< team size of the step and iteration loops, chosen by timing
    int m_team = 1;            ///< the team size of the current step or iteration
    std::vector<double> m_stiffness_bound; ///< the model's plus the coupling's, N/mm
    double m_time_step = 0.0;
    std::size_t m_n = 0;
    // Model data in the solver's precision.
    std::vector<Real> m_dn, m_gamma, m_volume, m_vb2, m_mu, m_lambda, m_kappa, m_hourglass;
    std::vector<Real> m_rest;
    std::vector<Real> m_nodal_j, m_inverse_nodal_volume; ///< averaged nodal pressure (tetrahedra)
    /// Hexahedra: per position of the element order, the length of the run of elements from it
    /// whose node numbers advance by one (the force kernel's contiguous path), within its chunk.
    std::vector<std::int32_t> m_run_length;
    std::size_t m_run_elements = 0;
    /// Box elements (one shared geometry b_a = M s_a): the kernel's Walsh–Hadamard path.
    bool m_box = false;
    std::vector<double> m_box_m;
    // State: displacement now and one step before, forces, scratch.
    std::vector<Real> m_u, m_u_prev, m_u_next, m_force, m_force_prev, m_external;
    std::vector<std::uint8_t> m_constrained; ///< 3 per node: 1 if the dof is prescribed
    std::vector<Real> m_prescribed;          ///< 3 per node at load factor 1
    std::vector<std::int64_t> m_constrained_dofs;
    std::vector<std::int32_t> m_contact_normal_node;
    std::vector<Vec3> m_contact_normal;
    std::size_t m_contact_count = 0;
    std::vector<int> m_active_tool; ///< dynamic relaxation: the tool a node is held against, -1 none
    /// Dynamic relaxation: per tool, the surface nodes that may touch it before the nodes have moved
    /// m_candidate_slack mm more (checking only them is the same as checking every surface node).
    std::vector<std::vector<std::int32_t>> m_contact_candidates;
    double m_candidate_slack = -1.0;
    /// Per tool: the surface faces (indices of TledModel::surface_faces) with a candidate node.
    std::vector<std::vector<std::int32_t>> m_contact_faces;
    bool m_face_contact = true;
    double m_face_penalty_scale = 0.0; ///< per face: this × the smallest stiffness bound of its nodes, N/mm
    std::size_t m_pressed_face_samples = 0;
    double m_time = 0.0;
    double m_load_factor = 0.0; ///< load level of the last equilibrium (warm start)
    long m_steps = 0;
    mutable long m_inverted_element = -1;
};

extern template class TledSolver<float>;
extern template class TledSolver<double>;

} // namespace physreg
