// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 001: registration of a volumetric liver model to a partial intra-operative surface (a
// labelled point cloud). The model — co-rotational linear tetrahedra, no Dirichlet condition — is
// integrated in time by backward Euler with Rayleigh damping under the pair forces of
// surface_matching.hpp; the pairs are recomputed after every time step; when the motion stops (an
// equilibrium plateau) the feature stiffnesses step up along their annealing schedules; the run
// ends once all are at their maximum (n = max r_j + 1). The pair forces are linearised in each step
// (BackwardEuler::set_external_stiffness), so large time steps stay stable.
//
// Rigid baselines under the same matching: labelled rigid ICP and plain (unlabelled) ICP, both
// point-to-plane (a 6×6 least-squares step per iteration).
#include "physreg/mechanics/backward_euler.hpp"
#include "physreg/mechanics/tled_model.hpp"
#include "physreg/registration/surface_matching.hpp"

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace physreg {

struct SurfaceRegistrationOptions {
    MatchingOptions matching;
    ArctanForceLaw force;
    /// Per feature label; every label of the cloud needs one. paper001_schedules() gives the paper's.
    std::map<std::int32_t, AnnealingSchedule> schedules;
    BackwardEulerOptions dynamics = paper001_dynamics();
    /// A plateau is reached when no node moves more than this in one time step.
    double plateau_tolerance_mm = 0.01;
    int max_steps_per_plateau = 100; ///< then the next plateau starts anyway (reported as not reached)
    /// > 0: this many Newton iterations per time step on a Jacobian refreshed at each plateau's
    /// start (linearised backward Euler, as SOFA's EulerImplicit: the equilibrium is the same, only
    /// the path differs); 0: each step solved to the dynamics' residual tolerance.
    int newton_iterations_per_step = 1;
    /// Paper 001's heterogeneous model: Glisson's capsule on the surface and the vessel beams
    /// (empty: homogeneous). They must outlive the call.
    std::vector<const AuxiliaryElements*> structures;
    /// Nodes held at rest (anatomical support, e.g. the posterior surface); empty: none, as paper 001.
    std::vector<std::int32_t> fixed_nodes;
    void validate() const;
    /// Δt 0.1 s, Rayleigh mass and stiffness coefficients 0.1 (paper 001), lumped mass, stale tangent.
    static BackwardEulerOptions paper001_dynamics();
};

/// Paper 001's schedules: umbilical notch r = 2, anterior margin r = 4, rest of the surface r = 10,
/// exponent 3; k_max for all, k_min = k_max/10 for the two features and 0 for the surface.
std::map<std::int32_t, AnnealingSchedule> paper001_schedules(double k_max_n);

/// The pair stiffness whose largest traction is `traction_ratio` × E: each cloud point stands for
/// an area of about spacing² (√3/2) (a triangulated sampling), so k = ratio × E × that area.
/// E in Pa, spacing in mm → N.
double pair_stiffness_n(double traction_ratio, double young_modulus_pa, double point_spacing_mm);

struct PlateauReport {
    int plateau = 0;
    std::map<std::int32_t, double> stiffness_n; ///< per label
    int steps = 0;
    bool reached = false;       ///< false: max_steps_per_plateau ran out first
    double last_step_mm = 0.0;  ///< largest nodal motion in the plateau's last step
    MatchStatistics matching;   ///< the plateau's last match
    int factorisations = 0;
    double seconds = 0.0;
};

struct SurfaceRegistrationResult {
    std::vector<double> displacement_mm;     ///< 3 per model node
    std::vector<PlateauReport> plateaus;
    std::vector<std::uint8_t> node_used;     ///< 1 for nodes of triangles paired in the final match
    std::size_t steps = 0;
    int factorisations = 0;
    int newton_iterations = 0;
    double seconds = 0.0;
    double matching_s = 0.0, force_s = 0.0, assembly_s = 0.0, factorisation_s = 0.0, solve_s = 0.0; ///< where the time went
};

/// `progress(fraction, message)` after every plateau. Throws Error for bad options, a cloud label
/// without schedule or model region, a cloud with no pair left after pruning, a non-converging time
/// step, and a model that inverts elements (naming the plateau).
SurfaceRegistrationResult register_surface_biomechanical(const TledModel& model, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                                         const SurfaceRegistrationOptions& options,
                                                         const std::function<void(double, const std::string&)>& progress = {});

struct RigidSurfaceResult {
    Mat3 rotation = Mat3::Identity();
    Vec3 translation = Vec3::Zero();          ///< x ↦ R x + t, mm
    std::vector<double> displacement_mm;      ///< of every model node
    int iterations = 0;
    bool converged = false;
    MatchStatistics matching;                 ///< final match
    std::vector<std::uint8_t> node_used;
    double seconds = 0.0;
};

/// Iterative closest point (point-to-plane): labelled pairs (`use_labels`, the rigid counterpart of the biomechanical
/// method) or pairs with any triangle (plain ICP); stops when no node moves more than `tolerance_mm`
/// between iterations or after `max_iterations`.
RigidSurfaceResult register_surface_rigid(const std::vector<double>& rest_positions_mm, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                          const MatchingOptions& matching, bool use_labels, int max_iterations = 200, double tolerance_mm = 1e-4);

} // namespace physreg
