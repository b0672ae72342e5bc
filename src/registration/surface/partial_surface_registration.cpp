// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/surface/partial_surface_registration.hpp"
#include "physreg/registration/surface/cloud_noise.hpp"
#include "registration/surface/detail/partial_surface_steps.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/evaluation/predicted_error.hpp"
#include "physreg/evaluation/surface_distance.hpp"
#include "physreg/evaluation/tre.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/point_path.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mechanics/elements/embedded_beams.hpp"
#include "physreg/mechanics/elements/membrane.hpp"
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/registration/surface/surface_adjoint.hpp"
#include "physreg/registration/surface/surface_model.hpp"
#include "physreg/registration/surface/surface_registration.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>
#include <random>
#include <array>
#include <exception>
#include <set>
#include <sstream>

namespace physreg {
using nlohmann::json;
using namespace surface_detail;

namespace {

constexpr double unbounded = std::numeric_limits<double>::infinity();

// ---- the methods ---------------------------------------------------------------------------------

/// Labelled rigid ICP ("rigid") and plain ICP ("icp"), each from several starts; the supports
/// judge which poses are plausible. `pose_determined` is cleared when far-apart poses fit alike.
void run_rigid_methods(const PartialSurfaceCase& c, const TledModel& model, const SurfaceMatcher& matcher, const SurfaceRegistrationOptions& options,
                       const PartialSurfaceSettings& s, std::vector<PartialSurfaceMethod>& methods, bool& pose_determined, std::vector<std::string>& notes)
{
    // An unlabelled cloud on an unlabelled surface pairs alike with and without labels: plain ICP is
    // then the labelled fit itself, reported as such instead of being computed twice.
    const bool all_zero = std::all_of(c.cloud.labels.begin(), c.cloud.labels.end(), [](std::int32_t l) { return l == 0; }) &&
                          std::all_of(c.surface.labels.begin(), c.surface.labels.end(), [](std::int32_t l) { return l == 0; });
    for (const bool labelled : {true, false}) {
        if (!labelled && all_zero) {
            if (methods.back().name != "rigid") break;
            PartialSurfaceMethod icp = methods.back();
            icp.name = "icp";
            icp.details["same_as"] = "rigid: an unlabelled cloud on an unlabelled surface pairs alike with and without labels";
            methods.push_back(std::move(icp));
            continue;
        }
        RobustRigidOptions robust;
        robust.supports = options.fixed_nodes;
        robust.support_tolerance_mm = s.support_tolerance;
        const auto t0 = std::chrono::steady_clock::now();
        RobustRigidResult rr;
        try {
            rr = register_surface_rigid_robust(model.rest_positions(), matcher, c.cloud, options.matching, labelled, robust);
        } catch (const Error& e) {
            // A baseline that cannot be fitted is reported, never the end of the registration.
            notes.push_back(fmt::format("{}: no rigid fit ({}); the baseline is left out", labelled ? "rigid" : "icp", e.what()));
            logger()->warn("register-surface: {}", notes.back());
            if (all_zero) break;
            continue;
        }
        const RigidSurfaceResult& r = rr.chosen;
        json alternatives = json::array();
        for (const auto& candidate : rr.candidates)
            alternatives.push_back({{"start", candidate.start}, {"rotation_deg", Eigen::AngleAxisd(candidate.result.rotation).angle() * 180.0 / M_PI},
                                    {"cloud_to_model_mean_mm", candidate.cloud_mean_mm}, {"support_motion_mm", candidate.support_motion_mm},
                                    {"plausible", candidate.plausible}, {"chosen", candidate.start == rr.chosen_start}});
        json d = {{"iterations", r.iterations}, {"converged", r.converged}, {"pairs", r.matching.kept},
                  {"rotation_deg", Eigen::AngleAxisd(r.rotation).angle() * 180.0 / M_PI}, {"translation_mm", {r.translation[0], r.translation[1], r.translation[2]}},
                  {"start", rr.chosen_start}, {"decision", rr.decision}, {"pose_determined", rr.pose_determined}, {"alternatives", alternatives}};
        pose_determined = pose_determined && rr.pose_determined;
        methods.push_back({labelled ? "rigid" : "icp", r.displacement_mm, seconds_since(t0), d});
    }
}

json biomechanical_details(const SurfaceRegistrationResult& b)
{
    json plateaus = json::array();
    for (const auto& p : b.plateaus) {
        json k;
        for (const auto& [label, v] : p.stiffness_n) k[std::to_string(label)] = v;
        plateaus.push_back({{"plateau", p.plateau}, {"stiffness_n", k}, {"steps", p.steps}, {"settled", p.reached}, {"last_step_mm", p.last_step_mm},
                            {"last_step_rms_mm", p.last_step_rms_mm}, {"pairs", p.matching.kept}, {"pruned_far", p.matching.pruned_far},
                            {"pruned_distance", p.matching.pruned_distance}, {"pruned_normal", p.matching.pruned_normal},
                            {"mean_pair_distance_mm", p.matching.mean_distance_mm}, {"factorisations", p.factorisations}, {"seconds", p.seconds}});
    }
    return {{"time_steps", b.steps}, {"factorisations", b.factorisations}, {"newton_iterations", b.newton_iterations},
            {"time_split_s", {{"matching", b.matching_s}, {"forces", b.force_s}, {"assembly", b.assembly_s}, {"factorisation", b.factorisation_s}, {"solves", b.solve_s}}},
            {"plateaus", plateaus}, {"completed", b.stopped.empty()}, {"stopped", b.stopped.empty() ? json(nullptr) : json(b.stopped)},
            {"inverted_elements", b.inverted_elements}, {"backoffs", b.backoffs}, {"final_softening", b.final_softening}};
}

PartialSurfaceMethod run_adjoint(const PartialSurfaceCase& c, const SurfaceMatcher& matcher, const SurfaceRegistrationOptions& options, double E,
                                 const PartialSurfaceSettings& s, double springs_n_per_mm, const std::function<void(double, const std::string&)>& progress)
{
    AdjointSurfaceOptions a;
    a.matching = options.matching;
    a.young_modulus_pa = E;
    a.poisson_ratio = s.poisson;
    a.fixed_nodes = options.fixed_nodes;
    a.load_nodes = options.load_nodes;
    a.spring_stiffness_n_per_mm = springs_n_per_mm;
    a.spring_grading = s.spring_grading;
    a.support_stiffness_n_per_mm = options.support_stiffness_n_per_mm;
    a.noise_mm = s.noise;
    const AdjointSurfaceResult r = register_surface_adjoint(c.mesh, matcher, c.cloud, a, progress);
    json rungs = json::array();
    for (const auto& g : r.rungs)
        rungs.push_back({{"alpha_mm2_per_mj", std::isfinite(g.alpha) ? json(g.alpha) : json(nullptr)}, {"rms_distance_mm", g.rms_distance_mm},
                         {"strain_energy_mj", g.strain_energy_mj},
                         {"lbfgs_iterations", g.lbfgs_iterations}, {"pairs", g.pairs}});
    if (!r.discrepancy_reached)
        logger()->warn("register-surface: the adjoint method never brought the cloud within {:.2f} mm (RMS); the smallest alpha is kept", a.discrepancy_factor * a.noise_mm);
    return {"adjoint", r.displacement_mm, r.seconds,
            {{"model", "static co-rotational linear tetrahedra, re-linearised (R K0 R^T, CHOLMOD) at every re-pairing; unknown surface forces"},
             {"regularisation", "alpha x strain energy"},
             {"alpha_rule", fmt::format("discrepancy principle: the largest alpha whose RMS point-to-plane distance is <= {} x the noise {} mm", a.discrepancy_factor, a.noise_mm)},
             {"chosen_alpha_mm2_per_mj", r.at_rest_meets_noise ? json(nullptr) : json(r.rungs[r.chosen].alpha)},
             {"discrepancy_reached", r.discrepancy_reached}, {"at_rest_meets_noise", r.at_rest_meets_noise},
             {"rungs", rungs}, {"solves", r.solves}, {"warnings", r.warnings},
             {"supports", a.fixed_nodes.empty() ? r.spring_grading > 0 ? fmt::format("none: springs to rest at every node (mean {} N/mm), graded by the distance to the cloud (exponent {})", r.spring_stiffness_n_per_mm, r.spring_grading) : fmt::format("none: springs to rest at every node ({} N/mm)", r.spring_stiffness_n_per_mm) : std::string("held")}}};
}

json model_json(const PartialSurfaceCase& c, const PartialSurfaceSettings& s, double E, const std::optional<Membrane>& capsule, const std::optional<EmbeddedBeams>& beams)
{
    json model = {{"kind", s.model_kind}, {"element", "linear tetrahedra (CGAL Mesh_3), co-rotational"}, {"nodes", c.mesh.node_count()},
                  {"tetrahedra", c.mesh.cell_count()}, {"surface_triangles", c.surface.triangles.size()}, {"young_modulus_pa", E}, {"poisson_ratio", s.poisson}};
    if (capsule)
        model["capsule"] = {{"element", "co-rotational constant-strain triangles (plane stress)"}, {"triangles", capsule->size()},
                            {"young_modulus_pa", MembraneMaterial{}.young_modulus_pa}, {"poisson_ratio", MembraneMaterial{}.poisson_ratio},
                            {"thickness_mm", s.capsule_thickness}, {"area_mm2", capsule->total_area_mm2()}};
    if (beams)
        model["vessels"] = {{"element", "co-rotational Timoshenko beams embedded in the tetrahedra"}, {"elements", beams->size()},
                            {"length_mm", beams->total_length_mm()}, {"segments_outside_model", beams->dropped_elements()},
                            {"young_modulus_pa", BeamMaterial{}.young_modulus_pa}, {"poisson_ratio", BeamMaterial{}.poisson_ratio}};
    if (c.quality)
        model["quality"] = {{"min_dihedral_deg", c.quality->min_dihedral_deg}, {"max_dihedral_deg", c.quality->max_dihedral_deg},
                            {"min_radius_ratio", c.quality->min_radius_ratio}, {"mean_edge_mm", c.quality->mean_edge_mm}};
    std::map<std::string, int> region_triangles;
    for (auto l : c.surface.labels) ++region_triangles[l == 1 ? "umbilical_notch" : l == 2 ? "anterior_margin" : "surface"];
    model["region_triangles"] = region_triangles;
    return model;
}

} // namespace

double PartialSurfaceSettings::young_modulus_pa() const
{
    if (young_modulus > 0) return young_modulus;
    return material == "cirrhotic" ? 30000.0 : 3500.0;
}

const SettingsSpec<PartialSurfaceSettings>& partial_surface_spec()
{
    using S = PartialSurfaceSettings;
    static const SettingsSpec<S> spec = [] {
        SettingsSpec<S> s("register-surface");
        s.choice("method", "--method", &S::method, {"adjoint", "biomechanical", "rigid", "icp"},
                 "adjoint (default: optimal control — a static co-rotational model under the chosen supports, unknown surface forces found by "
                 "adjoint gradients; it follows a large local push where closest-point pairing locks onto the nearest surface), biomechanical "
                 "(paper 001: annealed arctan pair forces, backward Euler; it also picks the supports), rigid (labelled rigid ICP) or icp "
                 "(plain ICP); the others are reported beside it")
            .choice("safeguard", "--safeguard", &S::safeguard, {"conservative", "keep"},
                    "when the deformable result fits the cloud worse than the rigid fit or than the model at rest, or the methods that fit the "
                    "data place the model apart (the data do not determine it), or the model at rest already meets the cloud to the noise: "
                    "conservative writes the model at rest (the rigid fit when it removes more than half of the distance at rest, its "
                    "starts agree on the pose, and it turns the model by at most 15° and shifts it by at most a quarter of its size unless it "
                    "meets the cloud to the noise) and says why; keep writes the deformable result anyway, flagged; the summary names the "
                    "runner-up and the margin")
            .choice("model_kind", "--model-kind", &S::model_kind, {"homogeneous", "heterogeneous"},
                    "homogeneous (parenchyma only) or heterogeneous (plus Glisson's capsule: a membrane of 8 000 kPa on the surface, and the vessels, paper 001)")
            .real("capsule_thickness", "--capsule-thickness", &S::capsule_thickness, "mm", "heterogeneous model: capsule thickness, mm", 0.0, unbounded, true)
            .choice("material", "--material", &S::material, {"healthy", "cirrhotic"}, "healthy (E 3.5 kPa) or cirrhotic (30 kPa), paper 001")
            .real("young_modulus", "--young-modulus", &S::young_modulus, "Pa", "parenchyma Young's modulus, Pa (0: from --material)", 0.0)
            .real("poisson", "--poisson", &S::poisson, "", "Poisson's ratio of the parenchyma (default 0.48: tissue is nearly incompressible; paper 001 used 0.45)", 0.0, 0.5, false, true)
            .real("cell_size", "--cell-size", &S::cell_size, "mm", "tetrahedron size (largest circumradius), mm", 0.0, unbounded, true)
            .real("d90", "--d90", &S::d90, "mm", "distance at which a pair force reaches 90 % of its maximum, mm", 0.0, unbounded, true)
            .real("traction", "--traction", &S::traction, "", "largest pair traction as a fraction of E (sets k_max)", 0.0, unbounded, true)
            .real("distance_fraction", "--distance-fraction", &S::distance_fraction, "", "pruning d_t: keep pairs closer than d_t × the largest", 0.0, 1.0, true)
            .real("max_pair_distance", "--max-pair-distance", &S::max_pair_distance, "mm",
                  "pairs longer than this are dropped (a cloud that does not belong to the model), mm", 0.0, unbounded, true)
            .real("normal_agreement", "--normal-agreement", &S::normal_agreement, "", "pruning n_t: keep pairs whose normals agree ≥ n_t", -1.0, 1.0)
            .choice("support", "--support", &S::support, {"auto", "posterior", "springs", "none"},
                    "auto (default: the supports are hypotheses — the named supports, the surface the cloud shows unmoved ('still'), the "
                    "posterior surface when the model is in a patient frame, springs at every node — tried from the most constrained; named or "
                    "still supports that fit to the noise end the search and win; of the others within 0.1 mm or 10 % of the best fit, the most "
                    "constrained wins unless a looser one needs ≤ 0.9× its strain energy), posterior "
                    "(surface nodes facing posterior, normal · +y > 0.5, where the vena cava and ligaments hold a liver), springs (soft springs to "
                    "rest at every node, BCF-FEM) or none (paper 001's free model)")
            .real("support_radius", "--support-radius", &S::support_radius, "mm", "--support-points: radius, mm", 0.0, unbounded, true)
            .labels("support_region", "--support-region", &S::support_region,
                    "further support: surface triangles of these region labels (e.g. 3; from --regions, whose labels other than 0, 1, 2 are never paired with the cloud)")
            .real("support_stiffness", "--support-stiffness", &S::support_stiffness, "N/mm",
                  "0: supports held; > 0: springs of this stiffness, N/mm per node and direction, to the rest position (ligaments stretch)", 0.0)
            .real("spring_stiffness", "--spring-stiffness", &S::spring_stiffness, "N/mm",
                  "the springs hypothesis: N/mm per node and direction (0: 0.01 × E × the mean edge)", 0.0)
            .real("spring_grading", "--spring-grading", &S::spring_grading, "",
                  "the adjoint method under the springs hypothesis: each node's spring ∝ (its distance to the cloud / the median)^this, their "
                  "mean kept, so the organ is tied loosely where the surface was seen and firmly far from it (a push is held away from the "
                  "tool); 0: uniform springs", 0.0, 8.0)
            .real("support_tolerance", "--support-tolerance", &S::support_tolerance, "mm",
                  "rigid baselines: a pose that moves a support node farther than this is implausible, mm", 0.0, unbounded, true)
            .text("load_nodes", "--load-nodes", &S::load_nodes,
                  "where forces may act (the tool's contact region): a file of surface node ids, one or more per line, '#' comments; the "
                  "biomechanical pair forces and the adjoint method's controls act there only (default: anywhere on the surface)")
            .text("load_points", "--load-points", &S::load_points,
                  "where forces may act: surface nodes within --load-radius of these points (landmark file: CSV, .fcsv, .mrk.json; mm, LPS)")
            .real("load_radius", "--load-radius", &S::load_radius, "mm", "--load-points: radius, mm", 0.0, unbounded, true)
            .text("tool_path", "--tool-path", &S::tool_path,
                  "where forces may act: a tracked tool's sphere centres since first contact, \"x,y,z;x,y,z;…\" (mm, LPS); the surface nodes "
                  "within --tool-radius of that path")
            .real("tool_radius", "--tool-radius", &S::tool_radius, "mm", "--tool-path: the tool sphere's radius, mm (required with it)", 0.0)
            .real("noise", "--noise", &S::noise, "mm", "the cloud's noise σ, mm, for the discrepancy principle that picks the supports (--support auto) "
                  "and the adjoint method's regularisation weight; 0 (default): estimated from the cloud (quadric fits to each point's 16 nearest, "
                  "a robust median), at least 0.5 mm", 0.0, unbounded)
            .choice("uncertainty", "--uncertainty", &S::uncertainty, {"halves", "none"},
                    "halves (default): the cloud is split at random into two halves, each registered by the biomechanical method under the chosen "
                    "supports; how far apart they place the model is the answer's precision (summary: uncertainty), and a motion smaller than 4/3 "
                    "of that spread is flagged as not resolved by the data (the safeguard); none: skip it (two registrations faster)")
            .real("time_step", "--time-step", &S::time_step, "s", "backward Euler time step, s", 0.0, unbounded, true)
            .real("plateau_tolerance", "--plateau-tolerance", &S::plateau_tolerance, "mm", "a plateau ends when no node moves more than this in a step, mm…", 0.0,
                  unbounded, true)
            .real("plateau_rms_fraction", "--plateau-rms-fraction", &S::plateau_rms_fraction, "",
                  "…or when the nodes' rms motion in a step is below this fraction of the plateau tolerance (0: off, paper 001's rule)", 0.0, 1.0)
            .integer("newton_per_step", "--newton-per-step", &S::newton_per_step, "Newton iterations per time step (1: linearised backward Euler; 0: to convergence)", 0, 1000)
            .integer("max_steps_per_plateau", "--max-steps-per-plateau", &S::max_steps_per_plateau, "time steps per plateau at most", 1, 1e6)
            .real("field_spacing", "--field-spacing", &S::field_spacing, "mm", "voxel size of displacement.nii.gz when no label volume gives the grid, mm", 0.0,
                  unbounded, true)
            .real("region_radius", "--region-radius", &S::region_radius, "mm", "--region-seeds: geodesic radius of each region, mm", 0.0, unbounded, true)
            .real("surface_scale", "--surface-scale", &S::surface_scale, "", "--surface: factor to mm (e.g. 1000 for SOFA meshes in metres)", 0.0, unbounded, true)
            .real("vessel_scale", "--vessel-scale", &S::vessel_scale, "", "--vessels: factor to mm (e.g. 1000 for metres)", 0.0, unbounded, true)
            .real("vessel_radius", "--vessel-radius", &S::vessel_radius, "mm", "--vessels: radius of files without radii, mm", 0.0, unbounded, true)
            .integer("seed", "--seed", &S::seed, "seed of the CGAL mesher and of the cloud's random halves (--uncertainty)", 0, 2147483647);
        return s;
    }();
    return spec;
}

void validate(const PartialSurfaceSettings& s, SettingNaming naming)
{
    const auto& spec = partial_surface_spec();
    spec.validate(s, naming);
    const auto n = [&](const char* key) { return spec.name(key, naming); };
    if (!s.tool_path.empty()) {
        parse_point_path(s.tool_path, n("tool_path")); // NaN, missing coordinates: said before any work
        if (!(s.tool_radius > 0)) fail("{} needs {} > 0 (the tool sphere's radius, mm)", n("tool_path"), n("tool_radius"));
    } else if (s.tool_radius > 0) {
        fail("{} {} mm: no {} to go with it", n("tool_radius"), s.tool_radius, n("tool_path"));
    }
}

namespace {

/// Leaves out the points given more than once (the same x, y, z; the first is kept, with its label
/// and normal) and returns how many: a repeated point would weigh twice in the fit and shrink the
/// mean spacing that sets the pair stiffness (issue 46's bad input).
std::size_t drop_duplicate_points(LabelledPointCloud& cloud)
{
    const std::size_t n = cloud.points.size();
    std::vector<std::size_t> order(n);
    std::iota(order.begin(), order.end(), std::size_t{0});
    const auto key = [&](std::size_t i) { return std::array<double, 3>{cloud.points[i][0], cloud.points[i][1], cloud.points[i][2]}; };
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return key(a) < key(b); });
    std::vector<std::uint8_t> keep(n, 1);
    for (std::size_t k = 1; k < n; ++k)
        if (key(order[k]) == key(order[k - 1])) keep[order[k]] = 0;
    const auto dropped = static_cast<std::size_t>(std::count(keep.begin(), keep.end(), 0));
    if (dropped == 0) return 0;
    LabelledPointCloud out;
    for (std::size_t i = 0; i < n; ++i) {
        if (!keep[i]) continue;
        out.points.push_back(cloud.points[i]);
        if (i < cloud.labels.size()) out.labels.push_back(cloud.labels[i]);
        if (i < cloud.normals.size()) out.normals.push_back(cloud.normals[i]);
    }
    cloud = std::move(out);
    return dropped;
}

/// The heterogeneous model's parts and the options every biomechanical run shares; `options` points
/// at `capsule` and `beams` (hence held by pointer, never moved).
struct SurfaceMechanics {
    TledModel model;
    std::optional<Membrane> capsule;
    std::optional<EmbeddedBeams> beams;
    SurfaceRegistrationOptions options;
    SurfaceMechanics(const VolumeMesh& mesh, double E, double poisson, const TledOptions& tled)
        : model(mesh, homogeneous_liver_tissues(E, poisson), tled)
    {
    }
};

std::unique_ptr<SurfaceMechanics> surface_mechanics(const PartialSurfaceCase& c, const PartialSurfaceSettings& s, double E, const LoadRegion& load)
{
    TledOptions tled;
    tled.law = MaterialLaw::corotational;
    auto m = std::make_unique<SurfaceMechanics>(c.mesh, E, s.poisson, tled);
    if (s.model_kind == "heterogeneous") {
        MembraneMaterial membrane;
        membrane.thickness_mm = s.capsule_thickness;
        m->capsule.emplace(c.surface.triangles, m->model.rest_positions(), membrane, "--model-kind heterogeneous: the capsule");
        if (c.vessels.empty())
            logger()->warn("register-surface: no vessel centrelines (--vessels): the heterogeneous model has the capsule only");
        else
            m->beams.emplace(c.mesh, c.vessels, BeamMaterial{}, s.cell_size, "--model-kind heterogeneous: the vessel beams");
    } // the homogeneous model leaves the case's vessels out
    SurfaceRegistrationOptions& options = m->options;
    options.matching.distance_fraction = s.distance_fraction;
    options.matching.normal_agreement = s.normal_agreement;
    options.matching.max_distance_mm = s.max_pair_distance;
    options.force.d90_mm = s.d90;
    options.dynamics.time_step_s = s.time_step;
    options.plateau_tolerance_mm = s.plateau_tolerance;
    options.plateau_rms_fraction = s.plateau_rms_fraction;
    options.max_steps_per_plateau = s.max_steps_per_plateau;
    options.newton_iterations_per_step = s.newton_per_step;
    options.load_nodes = load.nodes;
    if (m->capsule) options.structures.push_back(&*m->capsule);
    if (m->beams) options.structures.push_back(&*m->beams);
    return m;
}

/// summary.json's load_region: where forces acted, and how much of it the chosen supports hold.
json load_region_json(const LoadRegion& load, const SupportHypothesis& held)
{
    if (load.nodes.empty())
        return {{"nodes", json::array()}, {"statement", "forces may act anywhere on the surface (no --load-nodes, --load-points or --tool-path)"}};
    std::size_t held_load = 0;
    if (held.stiffness == 0 && held.name != "springs")
        for (const auto n : load.nodes) held_load += std::binary_search(held.supports.nodes.begin(), held.supports.nodes.end(), n);
    return {{"nodes", load.nodes}, {"sources", load.sources}, {"nearest_cloud_point_mm", load.nearest_cloud_mm}, {"held_by_supports", held_load},
            {"statement", held_load == 0 ? fmt::format("forces act on {} surface node(s) only; none of them is held by the supports '{}'",
                                                       load.nodes.size(), held.name)
                                         : fmt::format("forces act on {} surface node(s) only; {} of them are held by the supports '{}' "
                                                       "and carry none", load.nodes.size(), held_load, held.name)}};
}

/// What judges a result: the targets' cells, the truth at the nodes, and the strain energy of a
/// displacement (the model's and its capsule's and vessels').
Judges make_judges(const PartialSurfaceCase& c, const PartialSurfaceSettings& s, const StiffnessAssembler& energy_assembler,
                   const std::vector<const AuxiliaryElements*>& structures)
{
    Judges judges;
    judges.landmark_cells = c.landmarks ? embed_landmarks(c.mesh, *c.landmarks, 1.5 * s.cell_size, "the liver model") : std::vector<NodeEmbedding>{};
    judges.truth_at_nodes = truth_at_nodes(c);
    judges.strain_energy_mj = [&energy_assembler, structures](const std::vector<double>& u) {
        double e = energy_assembler.energy(u.data()).energy_mj;
        std::vector<double> scratch(u.size(), 0.0);
        for (const auto* structure : structures) e += structure->add_forces(u.data(), scratch.data());
        return e;
    };
    return judges;
}

/// How well the cloud determines the answer (issue 46 item 5): its two halves registered apart,
/// held exactly as the answer was (the springs hypothesis ties every node; `options` has by now
/// only what the rigid fits' plausibility needs).
json uncertainty_of(const PartialSurfaceCase& c, const PartialSurfaceSettings& s, const TledModel& model, const SurfaceMatcher& matcher,
                    const SurfaceRegistrationOptions& options, const SupportHypothesis& held, const std::vector<double>& answer, const Judges& judges,
                    const std::function<void(double, const std::string&)>& report)
{
    if (s.uncertainty != "halves") return {{"method", s.uncertainty}, {"run", false}, {"statement", "not run (--uncertainty none)"}};
    SurfaceRegistrationOptions held_as_answer = options;
    held_as_answer.fixed_nodes = held.supports.nodes;
    held_as_answer.support_stiffness_n_per_mm = held.stiffness;
    json out = cloud_halves_check(c, s, model, matcher, held_as_answer, answer, judges, report);
    out["supports"] = held.name;
    out["support_nodes"] = held.supports.nodes.size();
    out["support_stiffness_n_per_mm"] = held.stiffness;
    return out;
}

/// The settings with the cloud's noise σ in place (noise 0: estimated from the cloud, at least
/// default_noise_floor_mm), and what was decided in `report` (summary.json's "noise").
PartialSurfaceSettings with_noise(const PartialSurfaceSettings& given, const LabelledPointCloud& cloud, json& report)
{
    PartialSurfaceSettings s = given;
    if (given.noise > 0) {
        report = {{"used_mm", given.noise}, {"source", "given (--noise)"}};
        return s;
    }
    if (cloud.points.size() < 20) {
        s.noise = default_noise_floor_mm;
        report = {{"used_mm", s.noise}, {"source", fmt::format("the floor: {} points are too few to estimate it", cloud.points.size())}};
        return s;
    }
    const CloudNoise estimate = estimate_cloud_noise(cloud.points);
    s.noise = std::max(default_noise_floor_mm, estimate.sigma_mm);
    report = {{"used_mm", s.noise}, {"estimated_mm", estimate.sigma_mm}, {"outlier_share", estimate.outlier_share},
              {"source", estimate.sigma_mm > default_noise_floor_mm ? "estimated from the cloud (quadric fits to each point's 16 nearest)"
                                                                    : fmt::format("the floor {} mm (the cloud's own estimate is below it)", default_noise_floor_mm)}};
    logger()->info("register-surface: cloud noise estimated at {:.2f} mm ({:.0f} % outliers); the discrepancy principle works to {:.2f} mm",
                   estimate.sigma_mm, 100.0 * estimate.outlier_share, s.noise);
    return s;
}

/// A load region every hypothesis holds entirely would carry no force anywhere: Error naming it.
void require_a_free_load_node(const LoadRegion& load, const std::vector<SupportHypothesis>& hypotheses)
{
    if (load.nodes.empty()) return;
    for (const auto& h : hypotheses) {
        if (h.stiffness > 0 || h.name == "springs") return;
        for (const auto n : load.nodes)
            if (!std::binary_search(h.supports.nodes.begin(), h.supports.nodes.end(), n)) return;
    }
    fail("the load region ({} node(s), {}) lies entirely within the held supports: no node is left where a force may act", load.nodes.size(),
         load.sources.dump());
}

struct MethodRuns {
    json uncertainty;
    bool rigid_pose_determined = true;
    std::vector<std::string> rigid_notes;
};

/// 3b. How well the cloud determines the answer (issue 46 item 5): its two halves registered apart;
/// and 4. every method, the chosen one the answer, the others the report's baselines (appended to
/// `methods`: at rest, rigid, ICP, biomechanical, adjoint).
MethodRuns run_methods(const PartialSurfaceCase& c, const PartialSurfaceSettings& s, const TledModel& model, const SurfaceMatcher& matcher,
                       const SurfaceRegistrationOptions& options, const SupportHypothesis& held, const SurfaceRegistrationResult& b, double E,
                       const Judges& judges, const std::function<void(double, const std::string&)>& report, std::vector<PartialSurfaceMethod>& methods)
{
    MethodRuns runs;
    methods.push_back({"at_rest", std::vector<double>(3 * c.mesh.node_count(), 0.0), 0.0, json::object()});
    const auto halves_and_rigid = [&] {
        runs.uncertainty = uncertainty_of(c, s, model, matcher, options, held, b.displacement_mm, judges, report);
        report(0.8, "rigid baselines");
        run_rigid_methods(c, model, matcher, options, s, methods, runs.rigid_pose_determined, runs.rigid_notes);
    };
    std::optional<PartialSurfaceMethod> adjoint;
    if (s.method == "adjoint") {
        // The adjoint answer shares nothing with the halves and the rigid starts, and its solves run
        // on one core: the two run side by side (issue 56's time: on the public liver 7.9 s of
        // adjoint followed 2.5 s of halves and rigid starts). Nested regions inside run on their
        // section's thread alone; only the baselines' side reports progress.
        report(0.75, "adjoint registration, beside the cloud halves and the rigid baselines");
        std::exception_ptr adjoint_error, baselines_error;
#pragma omp parallel sections num_threads(2)
        {
#pragma omp section
            {
                try {
                    adjoint = run_adjoint(c, matcher, options, E, s, held.name == "springs" ? held.stiffness : 0.0, {});
                } catch (...) {
                    adjoint_error = std::current_exception();
                }
            }
#pragma omp section
            {
                try {
                    halves_and_rigid();
                } catch (...) {
                    baselines_error = std::current_exception();
                }
            }
        }
        if (baselines_error) std::rethrow_exception(baselines_error);
        if (adjoint_error) std::rethrow_exception(adjoint_error);
    } else {
        halves_and_rigid();
    }
    methods.push_back({"biomechanical", b.displacement_mm, b.seconds, biomechanical_details(b)});
    methods.back().details["support"] = held.name;
    if (adjoint) methods.push_back(std::move(*adjoint));
    return runs;
}

} // namespace

PartialSurfaceResult register_partial_surface(const PartialSurfaceCase& given, const PartialSurfaceSettings& settings,
                                              const std::function<void(double, const std::string&)>& progress)
{
    const auto start = std::chrono::steady_clock::now();
    // The case as registered: the cloud without repeated points (reported in the notes).
    PartialSurfaceCase cleaned;
    std::size_t duplicates = 0;
    {
        LabelledPointCloud cloud = given.cloud;
        duplicates = drop_duplicate_points(cloud);
        if (duplicates > 0) {
            cleaned = given;
            cleaned.cloud = std::move(cloud);
            logger()->warn("register-surface: {} cloud point(s) given more than once were left out ({} kept)", duplicates, cleaned.cloud.points.size());
        }
    }
    const PartialSurfaceCase& c = duplicates > 0 ? cleaned : given;
    const auto report = [&](double f, const std::string& m) {
        if (progress) progress(f, m);
    };
    validate(settings, SettingNaming::option);
    if (c.mesh.cell_type != CellType::tetrahedron) fail("register-surface: the model must hold tetrahedra (paper 001's model)");
    PartialSurfaceResult result;
    // The noise the discrepancy principle works to: as given, or estimated from the cloud.
    json noise;
    const PartialSurfaceSettings s = with_noise(settings, c.cloud, noise);
    result.settings = s;
    const double E = s.young_modulus_pa();
    logger()->info("register-surface: model {} nodes, {} tetrahedra, {} surface triangles; cloud {} points", c.mesh.node_count(), c.mesh.cell_count(),
                   c.surface.triangles.size(), c.cloud.points.size());
    // Where the tool may press (issue 56 item 2): read and checked before any work.
    const LoadRegion load = load_region(c, s);
    if (!load.nodes.empty())
        logger()->info("register-surface: forces act on {} surface node(s) only ({})", load.nodes.size(), load.sources.dump());

    // 1. The model: co-rotational tetrahedra, and the heterogeneous model's capsule and vessels.
    const SurfaceMatcher matcher(c.surface, c.mesh.node_count(), "the model's surface");
    const auto mechanics = surface_mechanics(c, s, E, load);
    const TledModel& model = mechanics->model;
    SurfaceRegistrationOptions options = mechanics->options;

    // 2. Paper 001's annealing schedules, and what judges a result without the truth (and with it).
    const double spacing = mean_point_spacing_mm(c.cloud.points);
    const double k_max = pair_stiffness_n(s.traction, E, spacing);
    options.schedules = paper001_schedules(k_max);
    const StiffnessAssembler energy_assembler(model, nullptr, {});
    Judges judges = make_judges(c, s, energy_assembler, options.structures);

    // 3. The supports are hypotheses (issue 46 item 3): each is registered, the most constrained one
    //    the data accept wins.
    const auto hypotheses = support_hypotheses(c, s, load);
    require_a_free_load_node(load, hypotheses);
    const SupportDecision decision = choose_support(c, s, hypotheses, model, matcher, options, judges, report);
    const SupportHypothesis& held = hypotheses[decision.chosen];
    const SurfaceRegistrationResult& b = decision.runs[decision.chosen];
    const bool springs_everywhere = held.name == "springs";
    options.fixed_nodes = springs_everywhere ? std::vector<std::int32_t>{} : held.supports.nodes; // the rigid fits' plausibility, the adjoint's supports
    options.support_stiffness_n_per_mm = springs_everywhere ? 0.0 : held.stiffness;
    result.support_nodes = held.supports.nodes;
    if (!options.fixed_nodes.empty())
        logger()->info("register-surface: {} support nodes ({}) {}", options.fixed_nodes.size(), held.name,
                       held.stiffness > 0 ? fmt::format("on springs of {} N/mm", held.stiffness) : std::string("held at rest"));

    // 3b. How well the cloud determines that answer, and 4. every method.
    auto& methods = result.methods;
    const MethodRuns runs = run_methods(c, s, model, matcher, options, held, b, E, judges, report, methods);
    const json& uncertainty = runs.uncertainty;
    const bool rigid_pose_determined = runs.rigid_pose_determined;
    const std::vector<std::string>& rigid_notes = runs.rigid_notes;

    // 5. Evaluation.
    report(0.92, "evaluation");
    judges.node_used = b.node_used;
    json evaluated;
    for (const auto& m : methods) evaluated[m.name] = evaluate(m, c, judges);
    const json determined = determinacy(methods, evaluated, rigid_pose_determined);
    // The safeguard's yardstick is the noise the user stated, or the floor: an estimate raised by a
    // rough surface (the phantom's voxel-built livers, 1.1-1.4 mm on noise-free patches) would call
    // every small motion unresolved and write the model at rest.
    PartialSurfaceSettings stated = s;
    stated.noise = settings.noise > 0 ? settings.noise : default_noise_floor_mm;
    result.safeguard = judge_deformable_answer(evaluated, determined, rigid_pose_determined, s.method, s.safeguard, discrepancy_level_mm(stated), uncertainty,
                                               model_size_mm(c.mesh));
    for (const auto& n : result.safeguard.notes) logger()->warn("register-surface: {}", n);
    if (!result.safeguard.flags.empty()) logger()->warn("register-surface: {}", result.safeguard.statement);
    for (std::size_t k = 0; k < methods.size(); ++k)
        if (methods[k].name == result.safeguard.answer) result.chosen = k;
    const auto& chosen = result.chosen_method();
    if (c.landmarks) result.landmarks = displace_landmarks(c.mesh, judges.landmark_cells, *c.landmarks, chosen.displacement_mm);
    result.field_geometry = c.field_geometry ? *c.field_geometry : image_grid_over_mesh(c.mesh, s.field_spacing, 2 * s.field_spacing);

    json& summary = result.summary;
    summary["command"] = "register-surface";
    summary["units"] = {{"length", "mm"}, {"force", "N"}, {"time", "s"}, {"young_modulus", "Pa"}};
    summary["inputs"] = c.description;
    summary["method"] = s.method;
    summary["settings"] = partial_surface_spec().to_json(s);
    summary["support"] = held.name;
    summary["support_nodes"] = held.supports.nodes.size();
    summary["supports"] = {{"hypothesis", held.name}, {"sources", held.supports.sources}, {"kind", held.stiffness > 0 ? "elastic" : "held"},
                           {"stiffness_n_per_mm", held.stiffness}, {"nodes", held.supports.nodes}, {"rigid_plausibility_tolerance_mm", s.support_tolerance}};
    summary["support_hypotheses"] = decision.report;
    summary["load_region"] = load_region_json(load, held);
    summary["determinacy"] = determined;
    summary["uncertainty"] = uncertainty;
    summary["noise"] = noise;
    summary["predicted_error"] = predicted_error_json(evaluated, s.method, result.safeguard.answer, held.name, c.mesh, E);
    logger()->info("register-surface: {}", summary["predicted_error"]["statement"].get<std::string>());
    summary["safeguard"] = {{"flags", result.safeguard.flags}, {"notes", result.safeguard.notes}, {"requested", result.safeguard.requested},
                            {"answer", result.safeguard.answer}, {"runner_up", result.safeguard.runner_up},
                            {"margin_mm", result.safeguard.margin_mm}, {"setting", s.safeguard}, {"statement", result.safeguard.statement}};
    if (c.truth_mesh) {
        // The pose the ground truth implies, to judge the baselines' rotations by (reports only).
        std::vector<double> truth_rest;
        for (const auto& x : c.truth_mesh->nodes) truth_rest.insert(truth_rest.end(), {x[0], x[1], x[2]});
        const RigidMotion pose = implied_rigid_motion(truth_rest, c.truth_displacement);
        summary["truth"] = {{"implied_rigid_motion", {{"rotation_deg", pose.angle_deg},
                                                      {"translation_mm", {pose.translation[0], pose.translation[1], pose.translation[2]}},
                                                      {"non_rigid_rms_mm", pose.residual_rms_mm}}}};
    }
    summary["model"] = model_json(c, s, E, mechanics->capsule, mechanics->beams);
    summary["cloud"] = {{"points", c.cloud.points.size()}, {"mean_spacing_mm", spacing}, {"normals", !c.cloud.normals.empty()}};
    summary["parameters"] = {{"cell_size_mm", s.cell_size}, {"d90_mm", s.d90}, {"traction_ratio", s.traction}, {"k_max_n", k_max}, {"distance_fraction", s.distance_fraction},
                             {"normal_agreement", s.normal_agreement}, {"time_step_s", s.time_step}, {"rayleigh_mass_per_s", options.dynamics.rayleigh_mass_per_s},
                             {"rayleigh_stiffness_s", options.dynamics.rayleigh_stiffness_s}, {"plateau_tolerance_mm", s.plateau_tolerance},
                             {"plateau_rms_fraction", s.plateau_rms_fraction}, {"exponent", 3}, {"r", {{"umbilical_notch", 2}, {"anterior_margin", 4}, {"surface", 10}}}};
    summary["methods"] = evaluated;
    // What went wrong on the way without ending the run (issue 46: numerical trouble backs a method off).
    summary["notes"] = json::array();
    if (duplicates > 0)
        summary["notes"].push_back(fmt::format("{} cloud point(s) given more than once were left out (the first of each kept; {} points registered)", duplicates,
                                               c.cloud.points.size()));
    if (!b.stopped.empty()) summary["notes"].push_back("biomechanical: " + b.stopped);
    for (const auto& n : rigid_notes) summary["notes"].push_back(n);
    for (const auto& n : decision.notes) summary["notes"].push_back(n);
    summary["seconds"] = seconds_since(start);
    return result;
}

// ---- a case from files ---------------------------------------------------------------------------

PartialSurfaceCase read_partial_surface_case(const PartialSurfaceFiles& f, const PartialSurfaceSettings& s)
{
    PartialSurfaceCase c;
    const int sources = !f.labels.empty() + !f.model.empty() + !f.surface.empty();
    if (sources != 1) fail("register-surface: give exactly one of --dataset, --labels, --surface and --model");
    if (!f.regions.empty() && !f.region_seeds.empty()) fail("register-surface: give --regions or --region-seeds, not both");
    if (f.cloud.empty()) fail("register-surface: --cloud is required with --labels, --surface or --model");
    if (!f.labels.empty()) {
        const LabelVolume labels = read_label_volume(f.labels);
        std::set<std::int32_t> liver;
        if (f.liver_labels.empty()) {
            for (const auto& [label, count] : count_labels(labels))
                if (label != 0) liver.insert(label);
        } else {
            for (const auto l : parse_label_list(f.liver_labels, "--liver-labels")) liver.insert(l);
        }
        SurfaceModel model = surface_model_from_labels(labels, liver, s.cell_size, f.notch_x_mm, static_cast<unsigned>(s.seed), "liver model of '" + f.labels + "'");
        c.mesh = std::move(model.mesh);
        c.surface = std::move(model.surface);
        c.quality = model.quality;
        c.field_geometry = labels.geometry;
        c.patient_frame = true;
        c.description = {{"labels", f.labels}};
    } else if (!f.surface.empty()) {
        SurfaceMesh liver = read_surface(f.surface);
        for (auto& v : liver.vertices) v *= s.surface_scale;
        SurfaceModel model = surface_model_from_surface(liver, s.cell_size, f.notch_x_mm, static_cast<unsigned>(s.seed), "--surface '" + f.surface + "'");
        c.mesh = std::move(model.mesh);
        c.surface = std::move(model.surface);
        c.quality = model.quality;
        c.description = {{"surface", f.surface}};
    } else {
        c.mesh = read_volume_mesh(f.model);
        if (c.mesh.cell_type != CellType::tetrahedron) fail("register-surface: --model '{}' must hold tetrahedra (paper 001's model)", f.model);
        std::fill(c.mesh.cell_labels.begin(), c.mesh.cell_labels.end(), 1);
        c.surface = unlabelled_boundary(c.mesh);
        c.quality = measure_tetrahedra(c.mesh);
        c.description = {{"model", f.model}};
    }
    if (!f.regions.empty()) {
        c.surface = regions_from_surface(c.mesh, c.surface, read_surface(f.regions), 5.0, "--regions '" + f.regions + "'");
        c.description["regions"] = f.regions;
    } else if (!f.region_seeds.empty()) {
        std::vector<RegionSeed> seeds;
        for (const auto& l : read_landmarks(f.region_seeds)) {
            const std::string prefix = l.name.substr(0, 2);
            if (prefix != "UN" && prefix != "AM")
                fail("--region-seeds '{}': landmark '{}' must be named UN… (umbilical notch) or AM… (anterior margin)", f.region_seeds, l.name);
            seeds.push_back({prefix == "UN" ? feature_umbilical_notch : feature_anterior_margin, l.position});
        }
        c.surface = regions_from_seeds(c.mesh, c.surface, seeds, s.region_radius, 10.0, "--region-seeds '" + f.region_seeds + "'");
        c.description["regions"] = fmt::format("grown {} mm along the surface from the points of {}", s.region_radius, f.region_seeds);
    } else if ((f.labels.empty() && f.surface.empty()) || !f.notch_x_mm) {
        c.description["regions"] = f.labels.empty() && f.surface.empty() ? "none (all surface)" : "anatomical rule, no umbilical notch (no --notch-x)";
    } else {
        c.description["regions"] = fmt::format("anatomical rule, notch at x = {} mm", *f.notch_x_mm);
    }
    c.cloud = read_point_cloud(f.cloud);
    c.description["cloud"] = f.cloud;
    if (!f.vessels.empty()) {
        c.vessels = read_vessel_centrelines(f.vessels, s.vessel_scale, s.vessel_radius);
        c.description["vessels"] = f.vessels;
    }
    if (!f.landmarks.empty()) c.landmarks = read_landmarks(f.landmarks);
    if (!f.landmarks_truth.empty()) {
        if (!c.landmarks) fail("register-surface: --landmarks-truth needs --landmarks (their rest positions)");
        c.truth = read_landmarks(f.landmarks_truth);
    }
    if (!f.truth_surface.empty()) c.truth_surface = read_surface(f.truth_surface);
    read_support_files(c, f.support_points, f.support_nodes);
    return c;
}

void read_support_files(PartialSurfaceCase& c, const std::string& support_points, const std::string& support_nodes)
{
    if (!support_points.empty()) {
        for (const auto& l : read_landmarks(support_points)) c.support_points.push_back(l.position);
        c.support_points_source = support_points;
    }
    if (!support_nodes.empty()) {
        c.support_nodes = read_node_ids(support_nodes, c.mesh.node_count(), "--support-nodes");
        c.support_nodes_source = support_nodes;
    }
}

} // namespace physreg
