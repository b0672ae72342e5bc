// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Issue 32 item 2: registration to a partial surface as an optimal-control problem (after Mestdagh
// & Cotin, MICCAI 2022). The unknowns are nodal forces f on the free surface nodes; the model is
// static co-rotational linear tetrahedra (the law paper 001's model uses), held at the supports, or
// — with no support — tied to rest by soft springs (BCF-FEM's way of needing no boundary
// condition). It is solved lagged: about a linearisation point u_k (the rest shape first, then the
// state at every re-pairing) u = u_k + K_R⁻¹ (f − f_int(u_k)), K_R = R K₀ Rᵀ (one CHOLMOD factor per
// re-pairing). With the pairs and u_k fixed,
//   J(f) = ½ mean_p (n_p · (x_p(u) − q_p))² + α W(u),  W ≈ W_k + f_int_k·Δ + ½ Δ·K_R Δ,
// point-to-plane distances of the cloud points q_p to their closest triangles (n_p the triangle's
// normal at pairing) plus α × the strain energy. Its gradient needs one adjoint solve:
//   ∂J/∂f = K_R⁻¹ g_u + α K_R⁻¹ f,  g_u = ∂(data)/∂u  (K_R⁻¹ f = Δ + K_R⁻¹ f_int_k).
// L-BFGS (liblbfgs) minimises J; the pairs are then recomputed and the model re-linearised (an
// ICP-like outer loop). α runs down a half-decade ladder from a stiff start, each warm-started from
// the last; the discrepancy principle keeps the first (largest) α whose RMS cloud distance falls to
// τ × the noise σ. Every rung is reported (an L-curve: distance against energy).
// `corotational = false` keeps the rest linearisation: small-strain linear elasticity.
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/registration/surface/surface_matching.hpp"

#include <functional>
#include <string>
#include <vector>

namespace physreg {

struct AdjointSurfaceOptions {
    MatchingOptions matching;
    double young_modulus_pa = 3500.0;
    double poisson_ratio = 0.48;                 ///< as register-surface's default (docs/registration.md, issue 56)
    std::vector<std::int32_t> fixed_nodes;       ///< held supports; empty: soft springs everywhere
    double support_stiffness_n_per_mm = 0.0;     ///< 0: fixed_nodes held; > 0: each tied to rest by springs of this stiffness
    /// The controls: nodes where forces may act (issue 56: the tool's contact region); empty:
    /// every free surface node. Held nodes among them carry none.
    std::vector<std::int32_t> load_nodes;
    double soft_spring_fraction = 1e-4;          ///< no support: spring = this × the mean diagonal of K…
    double spring_stiffness_n_per_mm = 0.0;      ///< …or this, N/mm per node and direction, when > 0
    /// No support: the springs graded by each node's distance d to the cloud, k_i = k (d_i / median
    /// d)^p / mean, so their mean stays k (loose where the surface was seen, firm far from it);
    /// 0: uniform.
    double spring_grading = 0.0;
    double noise_mm = 0.5;                       ///< σ of the cloud, for the discrepancy principle
    double discrepancy_factor = 1.5;             ///< τ: stop at RMS distance ≤ τ σ (the model's own discretisation error adds to σ)
    int alpha_steps = 13;                        ///< α_k = α_0 · 10^(−k/2), k = 0 … steps−1
    int outer_iterations = 6;                    ///< re-pairings per α
    int lbfgs_iterations = 60;                   ///< per re-pairing
    /// true: co-rotational linear tetrahedra, re-linearised (R K₀ Rᵀ and the co-rotational internal
    /// force) at every re-pairing, the forces kept (lagged: exact gradients of each linearised
    /// problem); false: small-strain linear elasticity about the rest shape.
    bool corotational = true;
    void validate() const;
};

struct AdjointRung {
    double alpha = 0.0;              ///< mm²/mJ
    double rms_distance_mm = 0.0;    ///< point-to-plane, over the final pairs
    double strain_energy_mj = 0.0;
    int lbfgs_iterations = 0;
    int pairs = 0;
};

struct AdjointSurfaceResult {
    std::vector<double> displacement_mm;   ///< 3 per node
    std::vector<double> force_n;           ///< 3 per node
    std::vector<AdjointRung> rungs;        ///< in the order tried
    std::size_t chosen = 0;                ///< index into rungs
    bool discrepancy_reached = false;      ///< false: the smallest α was kept (noise level never reached)
    /// The model at rest already lies within τ σ of the cloud (RMS): the discrepancy principle's α
    /// is infinite, no force is applied and the displacement is zero; rungs holds that one state.
    bool at_rest_meets_noise = false;
    std::vector<std::string> warnings;     ///< L-BFGS stops other than convergence, with their history
    int solves = 0;
    double spring_stiffness_n_per_mm = 0.0; ///< the springs to rest at every node (no support), N/mm: their mean
    double spring_grading = 0.0;            ///< their grading exponent (0: uniform, or held supports)
    double seconds = 0.0;
};

/// Throws Error for bad options, a cloud with no pair left, or a singular model.
AdjointSurfaceResult register_surface_adjoint(const VolumeMesh& mesh, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                              const AdjointSurfaceOptions& options,
                                              const std::function<void(double, const std::string&)>& progress = {});

/// For the gradient test: J and ∂J/∂f (free surface dofs only; others zero) at forces `f` (3 per
/// node) for the pairs of the rest shape, with weight `alpha`, linearised at rest or at
/// `linearisation_mm` (3 per node; the co-rotational model's re-linearisation).
double adjoint_surface_objective(const VolumeMesh& mesh, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                 const AdjointSurfaceOptions& options, double alpha, const std::vector<double>& f, std::vector<double>& gradient,
                                 const std::vector<double>* linearisation_mm = nullptr);

} // namespace physreg
