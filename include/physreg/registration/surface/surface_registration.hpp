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
#include "physreg/mechanics/implicit/backward_euler.hpp"
#include "physreg/mechanics/elements/tled_model.hpp"
#include "physreg/registration/model.hpp"
#include "physreg/registration/surface/surface_matching.hpp"

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
    /// A plateau is reached when no node moves more than this in one time step…
    double plateau_tolerance_mm = 0.01;
    /// …or when the nodes' root-mean-square motion in one step is below this fraction of
    /// plateau_tolerance_mm (0: off). Issue 30: under strong pair forces a plateau ends in a limit
    /// cycle — a few pairs switch partners every step and move their nodes by 0.1–0.5 mm back and
    /// forth while the rest stands still — which the largest motion never reports as settled (100
    /// steps per plateau on the push case). A motion spread over the model (a slow slide) has its
    /// rms near its largest value, so for it the rule is stricter than the first one, never looser.
    double plateau_rms_fraction = 0.5;
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
    /// 0: `fixed_nodes` held (Dirichlet); > 0: each tied to its rest position by a spring of this
    /// stiffness per direction (N/mm), because ligaments stretch.
    double support_stiffness_n_per_mm = 0.0;
    /// Where the pair forces may act (issue 56: the tool's contact region); empty: at every node.
    /// Pair forces and their stiffness at other nodes are dropped.
    std::vector<std::int32_t> load_nodes;
    /// Supports that hold only some directions (a table's normal), always held; node ids checked.
    std::vector<NodeConstraint> partial_supports;
    /// Tissue–tissue penalty coupling of a model with split interfaces (paper 000's coupled body
    /// model); null: none. It must outlive the call.
    const PenaltyCoupling* coupling = nullptr;
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
    double last_step_rms_mm = 0.0; ///< root mean square of the nodal motion in that step
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
    /// Empty when every plateau ran; else why the annealing stopped early (elements inverted by a
    /// plateau's forces) and which plateau's result is kept.
    std::string stopped;
    std::size_t inverted_elements = 0; ///< in the step that stopped it
    /// Steps undone and retried with the pairs softened by half because an element inverted or the
    /// step could not be solved (issue 56 item 5), and the softening at the end (1: none).
    int backoffs = 0;
    double final_softening = 1.0;
};

/// `progress(fraction, message)` after every plateau. Throws Error for bad options, a cloud label
/// without schedule or model region and a cloud with no pair left after pruning. A step whose
/// forces invert elements or cannot be solved is numerical trouble, not bad input: it is undone
/// and retried with softened pairs (issue 56); when that fails six times in a plateau the annealing
/// stops, the last completed plateau's state is returned and `stopped` says why (issue 46).
SurfaceRegistrationResult register_surface_biomechanical(const TledModel& model, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                                         const SurfaceRegistrationOptions& options,
                                                         const std::function<void(double, const std::string&)>& progress = {});

/// The register-surface command's biomechanical method on a model and a cloud held in memory (the
/// Python API's entry, issue 29): one homogeneous co-rotational material, paper 001's schedules with
/// k_max = pair_stiffness_n(traction ratio, E, the cloud's mean spacing), the posterior surface held
/// as the command's default support, and the options' matching, force law and dynamics.
struct SurfaceCloudProblem {
    double young_modulus_pa = 3500.0;        ///< paper 001's healthy liver
    double poisson_ratio = 0.45;
    double traction_ratio = 0.5;             ///< the largest pair traction as a fraction of E
    bool posterior_support = true;           ///< hold the surface nodes facing +y (normal · +y > 0.5)
    std::vector<std::int32_t> support_nodes; ///< held as well (node ids)
    SurfaceRegistrationOptions options;      ///< its schedules and fixed nodes are set from the above
};
/// Throws Error as register_surface_biomechanical does, and for supports that take every surface node.
SurfaceRegistrationResult register_surface_cloud(const VolumeMesh& mesh, const LabelledTriangles& surface, const LabelledPointCloud& cloud,
                                                 const SurfaceCloudProblem& problem,
                                                 const std::function<void(double, const std::string&)>& progress = {});

/// Paper 001's method on any shared model (registration/model.hpp), issue 29: the model's mesh
/// (tetrahedra or hexahedra), its per-element moduli under the co-rotational law (paper 001's), its
/// supports, structures and coupling, its surface matched to the cloud; paper 001's schedules with
/// k_max = pair_stiffness_n(traction ratio, E, the cloud's mean spacing). So a paper 000 body model
/// can follow a partial liver surface seen inside it.
struct CloudRegistrationSettings {
    double traction_ratio = 0.5;             ///< the largest pair traction as a fraction of E
    double young_modulus_pa = 0.0;           ///< E of the pair stiffness; 0: Model::surface_young_modulus_pa()
    SurfaceRegistrationOptions options;      ///< its schedules, supports, structures and coupling are set from the model
};
/// Throws Error as register_surface_biomechanical does, for a model without surface, and for
/// supports that take every surface node.
SurfaceRegistrationResult register_cloud(const Model& model, const LabelledPointCloud& cloud, const CloudRegistrationSettings& settings,
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

/// Where an ICP run starts and what else it must honour.
struct RigidIcpSettings {
    int max_iterations = 200;
    double tolerance_mm = 1e-4;
    Mat3 initial_rotation = Mat3::Identity(); ///< start x ↦ R₀ x + t₀
    Vec3 initial_translation = Vec3::Zero();
    /// Nodes pulled towards their rest positions (point-to-point, total weight `anchor_weight` × the
    /// number of cloud pairs): the supports, so the pose stays one the anatomy allows.
    std::vector<std::int32_t> anchors;
    double anchor_weight = 0.0;
};

/// Iterative closest point (point-to-plane): labelled pairs (`use_labels`, the rigid counterpart of the biomechanical
/// method) or pairs with any triangle (plain ICP); stops when no node moves more than `tolerance_mm`
/// between iterations or after `max_iterations`.
RigidSurfaceResult register_surface_rigid(const std::vector<double>& rest_positions_mm, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                          const MatchingOptions& matching, bool use_labels, const RigidIcpSettings& settings = {});

/// The rigid motion nearest (least squares over the nodes, Umeyama) to a displacement field: the pose
/// a registration implies, whatever it did besides.
struct RigidMotion {
    Mat3 rotation = Mat3::Identity();
    Vec3 translation = Vec3::Zero();
    double angle_deg = 0.0;
    double residual_rms_mm = 0.0; ///< the non-rigid rest
};
RigidMotion implied_rigid_motion(const std::vector<double>& rest_positions_mm, const std::vector<double>& displacement_mm);

/// Issue 32: rigid registration that does not trust one fit. ICP runs from several starts — the
/// identity, the principal axes of the cloud matched to those of the model's surface (all four
/// right-handed sign choices), and ±`start_angle_deg` about each axis — and a pose is kept only
/// when it is plausible (no support node moves farther than `support_tolerance_mm`) and fits the
/// cloud better than the identity start's by more than `improvement` (relative mean cloud-to-model
/// distance). When no start is plausible, the fit is redone with the supports as anchors.
struct RobustRigidOptions {
    std::vector<std::int32_t> supports;
    double support_tolerance_mm = 10.0;
    double improvement = 0.1;
    double start_angle_deg = 30.0;
    double anchor_weight = 1.0;
    /// Two plausible poses whose fits differ by less than this (relative) while they rotate more
    /// than `ambiguous_angle_deg` apart: the data do not determine the pose.
    double ambiguous_fit = 0.1;
    double ambiguous_angle_deg = 10.0;
};
struct RigidCandidate {
    std::string start;
    RigidSurfaceResult result;
    double cloud_mean_mm = 0.0;     ///< mean distance of every cloud point to the posed surface
    double support_motion_mm = 0.0; ///< largest motion of a support node
    bool plausible = true;
};
struct RobustRigidResult {
    RigidSurfaceResult chosen;
    std::string chosen_start;       ///< a candidate's start, or "anchored to the supports"
    std::vector<RigidCandidate> candidates;
    bool pose_determined = true;
    std::string decision;           ///< why this pose, in words
};
RobustRigidResult register_surface_rigid_robust(const std::vector<double>& rest_positions_mm, const SurfaceMatcher& matcher,
                                                const LabelledPointCloud& cloud, const MatchingOptions& matching, bool use_labels,
                                                const RobustRigidOptions& options);

} // namespace physreg
