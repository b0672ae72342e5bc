// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 001's pipeline, whole (issue 43): the one function that `physreg register-surface` and
// Python's physreg.register_partial_surface call. Read top to bottom in partial_surface_registration.cpp:
//   1. the model: co-rotational tetrahedra, and for the heterogeneous kind Glisson's capsule
//      (membrane) and the vessels (embedded beams);
//   2. the supports, as hypotheses (named, posterior in a patient frame, springs, none) chosen by the data;
//   3. the methods: labelled rigid and plain ICP (multi-start, supports judge plausibility), the
//      biomechanical registration (arctan pair forces annealed, backward Euler), and the adjoint
//      method when asked;
//   4. evaluation: fit to the cloud, strain energy, implied rigid motion, Hausdorff distance, TRE
//      and nodal error when a truth is given, and whether the data determine the pose.
// The settings are PartialSurfaceSettings, specified once by partial_surface_spec().
#include "physreg/core/settings_spec.hpp"
#include "physreg/core/landmark.hpp"
#include "physreg/image/image_geometry.hpp"
#include "physreg/io/point_cloud.hpp"
#include "physreg/mesh/surface_mesh.hpp"
#include "physreg/io/vessel_centrelines.hpp"
#include "physreg/mesh/tetrahedral_meshing.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/registration/surface/surface_matching.hpp"

#include <nlohmann/json.hpp>

#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace physreg {

/// Every setting of paper 001's pipeline; defaults are the command's (partial_surface_spec() holds
/// their ranges and help). The meshing ones (cell_size, seed, surface_scale, region_radius,
/// vessel_scale, vessel_radius) are read where a case is made from files.
struct PartialSurfaceSettings {
    std::string method = "adjoint";           ///< the result written: adjoint, biomechanical, rigid, icp
    std::string safeguard = "conservative";   ///< conservative: a flagged deformable result gives way to rest (or rigid when it explains the cloud); keep
    std::string model_kind = "homogeneous";   ///< homogeneous, heterogeneous (capsule and vessels)
    double capsule_thickness = 0.1;           ///< mm
    std::string material = "healthy";         ///< healthy (3.5 kPa), cirrhotic (30 kPa)
    double young_modulus = 0.0;               ///< Pa; 0: from the material
    double poisson = 0.48;                    ///< nearly incompressible tissue (0.45 until issue 56: paper 001's value)
    double cell_size = 7.0;                   ///< mm
    double d90 = 5.0;                         ///< mm
    double traction = 0.5;                    ///< fraction of E
    double distance_fraction = 0.9;
    double max_pair_distance = 40.0;          ///< mm
    double normal_agreement = 0.7;
    std::string support = "auto";             ///< auto (hypotheses chosen by the data), posterior, springs, none
    double support_radius = 10.0;             ///< mm, around support points
    std::vector<std::int32_t> support_region; ///< surface region labels held
    double support_stiffness = 0.0;           ///< N/mm; 0: held
    double spring_stiffness = 0.0;            ///< N/mm, the springs hypothesis; 0: 0.01 × E × mean edge
    double spring_grading = 2.0;              ///< the adjoint's springs ∝ (distance to the cloud / median)^this, mean kept; 0: uniform
    double support_tolerance = 3.0;           ///< mm
    /// Where forces may act (issue 56 item 2; empty: anywhere on the surface): node ids (a file),
    /// surface nodes within load_radius of picked points (a landmark file), or of a tracked tool's
    /// path (its sphere centres, "x,y,z;…" mm LPS) within tool_radius.
    std::string load_nodes;
    std::string load_points;
    double load_radius = 10.0;                ///< mm, around load points
    std::string tool_path;
    double tool_radius = 0.0;                 ///< mm; required with tool_path
    double noise = 0.0;                       ///< mm, the discrepancy principle's σ; 0: estimated from the cloud (at least default_noise_floor_mm)
    std::string uncertainty = "halves";       ///< halves: the cloud's two random halves registered apart (precision, resolved motion); none
    double time_step = 0.1;                   ///< s
    double plateau_tolerance = 0.01;          ///< mm
    double plateau_rms_fraction = 0.5;
    int newton_per_step = 1;
    int max_steps_per_plateau = 100;
    double field_spacing = 2.0;               ///< mm
    double region_radius = 15.0;              ///< mm
    double surface_scale = 1.0;
    double vessel_scale = 1.0;
    double vessel_radius = 1.5;               ///< mm
    int seed = 1;

    double young_modulus_pa() const;          ///< young_modulus, or the material's
};

const SettingsSpec<PartialSurfaceSettings>& partial_surface_spec();
/// The specification's ranges and the settings' own rules; Error naming the setting as `naming` says.
void validate(const PartialSurfaceSettings& settings, SettingNaming naming);

/// What paper 001 registers: a tetrahedral liver model with a labelled surface, a cloud, and what
/// judges the result when known.
struct PartialSurfaceCase {
    VolumeMesh mesh;                          ///< tetrahedra, one material
    LabelledTriangles surface;                ///< regions: 0 surface, 1 umbilical notch, 2 anterior margin, others never paired
    std::optional<TetrahedronQuality> quality;
    LabelledPointCloud cloud;
    std::vector<VesselBranch> vessels;        ///< the heterogeneous model's centrelines (may be empty)
    std::vector<Vec3> support_points;         ///< further supports: surface nodes within support_radius
    std::string support_points_source;        ///< names them in errors and the summary
    std::vector<std::int32_t> support_nodes;  ///< further supports: node ids
    std::string support_nodes_source;
    std::vector<std::int32_t> load_nodes;     ///< where forces may act besides the settings' load region: node ids
    std::string load_nodes_source;
    std::optional<LandmarkSet> landmarks, truth; ///< targets at rest, and their true deformed positions
    std::optional<SurfaceMesh> truth_surface;
    std::optional<VolumeMesh> truth_mesh;     ///< a truth's mesh with its nodal displacement (nodal error)
    std::vector<double> truth_displacement;
    std::optional<ImageGeometry> field_geometry; ///< the dense field's grid (else one over the mesh)
    /// The model's coordinates are a patient frame (LPS): a label volume's physical space. Only then
    /// does the posterior surface mean anything, and --support auto offers it.
    bool patient_frame = false;
    nlohmann::json description = nlohmann::json::object();
};

struct PartialSurfaceMethod {
    std::string name;                          ///< at_rest, rigid, icp, biomechanical, adjoint
    std::vector<double> displacement_mm;       ///< 3 per model node
    double seconds = 0.0;
    nlohmann::json details = nlohmann::json::object();
};

/// What the safeguard found (issue 46): reasons to distrust the deformable answer, judged without
/// the truth, and what was written instead.
struct PartialSurfaceSafeguard {
    std::vector<std::string> flags;            ///< empty: nothing found
    std::string requested;                     ///< settings.method
    std::string answer;                        ///< the method whose result is written
    std::string statement;                     ///< one sentence for the log and the report
    std::vector<std::string> notes;            ///< what was weighed and set aside (a rigid pose too large to trust)
    std::string runner_up;                     ///< the best-fitting other candidate (the method asked for, a trusted rigid fit, at rest)
    double margin_mm = 0.0;                    ///< its mean cloud distance minus the answer's (negative: the runner-up fits better)
};

/// The least noise σ the discrepancy principle works to, mm: below it the model would chase its own
/// facets (the default before the estimate, tuned on the public optimal-control liver).
inline constexpr double default_noise_floor_mm = 0.5;

/// A rigid fit turning the model by more than this is no fallback unless it explains the cloud to
/// the noise (issue 56 item 4).
inline constexpr double max_plausible_rigid_angle_deg = 15.0;

struct PartialSurfaceResult {
    PartialSurfaceSettings settings;
    std::vector<PartialSurfaceMethod> methods;
    std::size_t chosen = 0;                    ///< the answer: settings.method, or what the safeguard put in its place
    PartialSurfaceSafeguard safeguard;
    std::vector<std::int32_t> support_nodes;
    std::optional<LandmarkSet> landmarks;      ///< the targets through the chosen result
    ImageGeometry field_geometry;              ///< where displacement.nii.gz is sampled
    nlohmann::json summary;                    ///< summary.json, as written
    const PartialSurfaceMethod& chosen_method() const { return methods.at(chosen); }
};

/// The safeguard's judgement, as register_partial_surface makes it: `evaluated` holds per method
/// name {"cloud_to_model_mm": {"mean": …}} (at_rest, and rigid when run); `determinacy` is
/// {"pose_determined": bool, "notes": [...]}. A deformable `requested` answer (biomechanical,
/// adjoint) is flagged when it fits the cloud worse than the rigid fit or than at rest (by more than
/// 5 % and 0.1 mm), when the data do not determine it, or when the model left at rest already meets
/// the cloud to `noise_level_mm` (mean distance; 1.2 × the noise σ) and the answer removes less than
/// half of that residual: the data show no motion.
/// `setting` conservative then answers the model at rest, or the rigid fit when it removes more than
/// half of the cloud-to-model distance at rest and the rigid starts agree on the pose (and at rest
/// does not already meet the noise); keep keeps it.
/// `halves` (optional) is the cloud-halves check: {"resolved": false, "statement": …} flags an
/// answer whose motion the two halves of the cloud do not agree on (summary.json's "uncertainty").
/// Issue 56: a rigid fit ("rigid": {"rotation_deg", "translation_mm"}) that turns the model by more
/// than max_plausible_rigid_angle_deg or moves it by more than a quarter of `model_size_mm` (the
/// model's bounding-box diagonal; 0: not judged) neither flags nor replaces the deformable answer
/// unless it meets the cloud to `noise_level_mm`; it is named in the notes instead.
PartialSurfaceSafeguard judge_deformable_answer(const nlohmann::json& evaluated, const nlohmann::json& determinacy, bool rigid_pose_determined,
                                                const std::string& requested, const std::string& setting, double noise_level_mm,
                                                const nlohmann::json& halves = nlohmann::json::object(), double model_size_mm = 0.0);

/// The cloud-halves check's decision (issue 46 item 5), apart from the registrations that feed it:
/// `spread_mm` is the mean distance between the two halves' answers, `motion_mm` the mean motion of
/// the answer (both over the same points: model nodes or targets). The motion is resolved when it
/// exceeds 4/3 of the spread (the halves' difference has twice the standard error of the answer,
/// so the motion then stands at least 2.7 standard errors clear of none).
bool motion_resolved_by_halves(double spread_mm, double motion_mm);

/// Runs the pipeline. `progress(fraction, message)`. Throws Error for bad input (supports off the
/// model, a cloud far from it) and when the chosen method fails.
PartialSurfaceResult register_partial_surface(const PartialSurfaceCase& c, const PartialSurfaceSettings& settings,
                                              const std::function<void(double, const std::string&)>& progress = {});

/// The mode's entry point under the command's name (register-surface), as register_images and
/// register_compression are named: the same pipeline as register_partial_surface.
inline PartialSurfaceResult register_surface(const PartialSurfaceCase& c, const PartialSurfaceSettings& settings,
                                             const std::function<void(double, const std::string&)>& progress = {})
{
    return register_partial_surface(c, settings, progress);
}

/// A case from files as register-surface takes them: exactly one model source (a label volume, a
/// closed surface or a tetrahedral mesh), its regions (a labelled surface or picked seeds), the
/// cloud, targets, truth, vessels and supports. Empty paths are left out; `notch_x_mm` places the
/// anatomical rule's umbilical notch.
struct PartialSurfaceFiles {
    std::string labels, liver_labels, surface, model, regions, region_seeds, cloud, landmarks, landmarks_truth, truth_surface, vessels;
    std::string support_points, support_nodes;
    std::optional<double> notch_x_mm;
};
PartialSurfaceCase read_partial_surface_case(const PartialSurfaceFiles& files, const PartialSurfaceSettings& settings);
/// Further supports from files: picked points (a landmark file) and node ids (one or more per
/// line, '#' comments); empty paths are left out. Throws Error naming the file.
void read_support_files(PartialSurfaceCase& c, const std::string& support_points, const std::string& support_nodes);

} // namespace physreg
