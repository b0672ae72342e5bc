// SPDX-License-Identifier: GPL-3.0-or-later
// physreg register-surface: paper 001 — a tetrahedral liver model registered to a partial
// intra-operative surface (labelled point cloud), with rigid and ICP baselines in the same report.
#include "cli_support.hpp"
#include "progress.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/evaluation/surface_distance.hpp"
#include "physreg/evaluation/tre.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/phantom/landmark_picking.hpp"
#include "physreg/mechanics/elements/embedded_beams.hpp"
#include "physreg/mechanics/elements/membrane.hpp"
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"
#include "physreg/registration/surface/surface_adjoint.hpp"
#include "physreg/registration/surface/surface_model.hpp"
#include "physreg/registration/surface/surface_registration.hpp"

#include <chrono>
#include <fstream>
#include <sstream>
#include <iostream>

namespace physreg::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct Options : CommonOptions {
    std::string dataset, state = "insufflation", labels, surface, region_seeds, model, regions, cloud, landmarks, landmarks_truth, truth_surface, output;
    std::string liver_labels, method = "biomechanical", material = "healthy", support = "posterior", model_kind = "homogeneous";
    std::string support_points, support_nodes, support_region;
    double support_radius = 10.0, support_stiffness = 0.0, support_tolerance = 3.0;
    double capsule_thickness = MembraneMaterial{}.thickness_mm, vessel_scale = 1.0, vessel_radius = 1.5, region_radius = 15.0, surface_scale = 1.0;
    std::string vessels;
    std::optional<int> visible;
    std::optional<double> notch_x, young_modulus;
    double poisson = 0.45, cell_size = 7.0, field_spacing = 2.0;
    double noise = 0.5;
    double d90 = 5.0, traction = 0.5, distance_fraction = 0.9, normal_agreement = 0.7, time_step = 0.1, plateau_tolerance = 0.01, plateau_rms_fraction = 0.5, max_pair = 40.0;
    int max_steps = 100, newton_per_step = 1;
    unsigned seed = 1;
    bool replace = false;
};

struct Inputs {
    VolumeMesh mesh;
    LabelledTriangles surface;
    std::optional<TetrahedronQuality> quality;
    LabelledPointCloud cloud;
    std::optional<LandmarkSet> landmarks, truth;
    std::optional<SurfaceMesh> truth_surface;
    std::optional<VolumeMesh> truth_mesh;   ///< dataset: the ground-truth state's mesh with its nodal displacement
    std::vector<double> truth_displacement;
    std::optional<ImageGeometry> field_geometry;
    std::vector<VesselBranch> vessels;      ///< centrelines for the heterogeneous model (may stay empty)
    json description;
};

std::set<std::int32_t> parse_label_set(const std::string& text, const std::string& option)
{
    std::set<std::int32_t> out;
    for (double v : parse_number_list(text, option)) {
        if (v != std::floor(v) || v <= 0) fail("{}: '{}' is not a positive integer label", option, v);
        out.insert(static_cast<std::int32_t>(v));
    }
    return out;
}

Inputs load_inputs(const Options& o)
{
    Inputs in;
    const int sources = !o.dataset.empty() + !o.labels.empty() + !o.model.empty() + !o.surface.empty();
    if (sources != 1) fail("register-surface: give exactly one of --dataset, --labels, --surface and --model");
    if (!o.regions.empty() && !o.region_seeds.empty()) fail("register-surface: give --regions or --region-seeds, not both");
    if (!o.dataset.empty()) {
        if (!o.cloud.empty() || !o.landmarks.empty() || !o.landmarks_truth.empty() || !o.truth_surface.empty() || !o.regions.empty() ||
            !o.region_seeds.empty())
            fail("register-surface: --dataset provides the cloud, landmarks, regions and truth; leave out --cloud, --landmarks, "
                 "--landmarks-truth, --truth-surface and --regions");
        const PhantomDataset dataset = read_phantom_dataset(o.dataset);
        const DatasetState& rest = dataset.state("rest");
        const DatasetState& state = dataset.state(o.state);
        if (state.kind == "rest") fail("register-surface: --state {} is the rest state; choose a deformed one", o.state);
        // --visible: as asked; else the state's only cloud (the push's sparse one), else 30 %.
        const int visible = o.visible ? *o.visible : state.surfaces.size() == 1 ? state.surfaces.begin()->first : 30;
        const auto surface = state.surfaces.find(visible);
        if (surface == state.surfaces.end()) {
            std::string available;
            for (const auto& [p, f] : state.surfaces) available += (available.empty() ? "" : ", ") + std::to_string(p);
            fail("register-surface: state {} has no partial surface with {} % visible (available: {})", o.state, visible, available);
        }
        const LabelVolume labels = read_label_volume(dataset.path(rest.files.at("labels")));
        std::set<std::int32_t> liver;
        for (const auto* role : {&dataset.roles.liver, &dataset.roles.lesion, &dataset.roles.vessel}) liver.insert(role->begin(), role->end());
        SurfaceModel model = surface_model_from_labels(labels, liver, o.cell_size, find_margin_notch_x(labels, dataset.roles), o.seed,
                                                       "liver model of '" + o.dataset + "'");
        in.mesh = std::move(model.mesh);
        in.surface = std::move(model.surface);
        in.quality = model.quality;
        in.cloud = read_point_cloud(dataset.path(surface->second.first));
        in.landmarks = read_landmarks(dataset.path(rest.files.at("landmarks")));
        in.truth = read_landmarks(dataset.path(state.files.at("landmarks")));
        in.truth_surface = read_surface(dataset.path(state.files.at("liver_surface")));
        MeshData data;
        in.truth_mesh = read_vtu(dataset.path(state.files.at("mesh")), &data);
        const DataArray* u = data.find_point("displacement");
        if (!u || u->components != 3) fail("register-surface: the ground-truth mesh of state {} has no 3-component 'displacement'", o.state);
        in.truth_displacement = u->values;
        in.field_geometry = labels.geometry;
        if (!o.vessels.empty())
            in.vessels = read_vessel_centrelines(o.vessels, o.vessel_scale, o.vessel_radius);
        else if (rest.files.count("vessel_centrelines"))
            in.vessels = read_vessel_centrelines(dataset.path(rest.files.at("vessel_centrelines")), 1.0, 1.0);
        in.description = {{"dataset", o.dataset}, {"state", o.state}, {"visible_percent", visible}, {"cloud", surface->second.first},
                          {"regions", "from the rest label map (anatomical rule; notch from the label map)"}};
        return in;
    }
    if (o.cloud.empty()) fail("register-surface: --cloud is required with --labels, --surface or --model");
    if (!o.labels.empty()) {
        const LabelVolume labels = read_label_volume(o.labels);
        std::set<std::int32_t> liver;
        if (o.liver_labels.empty())
            for (const auto& [label, count] : count_labels(labels)) {
                if (label != 0) liver.insert(label);
            }
        else
            liver = parse_label_set(o.liver_labels, "--liver-labels");
        SurfaceModel model = surface_model_from_labels(labels, liver, o.cell_size, o.notch_x, o.seed, "liver model of '" + o.labels + "'");
        in.mesh = std::move(model.mesh);
        in.surface = std::move(model.surface);
        in.quality = model.quality;
        in.field_geometry = labels.geometry;
        in.description = {{"labels", o.labels}};
    } else if (!o.surface.empty()) {
        SurfaceMesh liver = read_surface(o.surface);
        if (!(o.surface_scale > 0)) fail("--surface-scale {} must be > 0", o.surface_scale);
        for (auto& v : liver.vertices) v *= o.surface_scale;
        SurfaceModel model = surface_model_from_surface(liver, o.cell_size, o.notch_x, o.seed, "--surface '" + o.surface + "'");
        in.mesh = std::move(model.mesh);
        in.surface = std::move(model.surface);
        in.quality = model.quality;
        in.description = {{"surface", o.surface}};
    } else {
        in.mesh = read_volume_mesh(o.model);
        if (in.mesh.cell_type != CellType::tetrahedron) fail("register-surface: --model '{}' must hold tetrahedra (paper 001's model)", o.model);
        std::fill(in.mesh.cell_labels.begin(), in.mesh.cell_labels.end(), 1);
        in.surface = unlabelled_boundary(in.mesh);
        in.quality = measure_tetrahedra(in.mesh);
        in.description = {{"model", o.model}};
    }
    if (!o.regions.empty()) {
        in.surface = regions_from_surface(in.mesh, in.surface, read_surface(o.regions), 5.0, "--regions '" + o.regions + "'");
        in.description["regions"] = o.regions;
    } else if (!o.region_seeds.empty()) {
        std::vector<RegionSeed> seeds;
        for (const auto& l : read_landmarks(o.region_seeds)) {
            const std::string prefix = l.name.substr(0, 2);
            if (prefix != "UN" && prefix != "AM")
                fail("--region-seeds '{}': landmark '{}' must be named UN… (umbilical notch) or AM… (anterior margin)", o.region_seeds, l.name);
            seeds.push_back({prefix == "UN" ? feature_umbilical_notch : feature_anterior_margin, l.position});
        }
        in.surface = regions_from_seeds(in.mesh, in.surface, seeds, o.region_radius, 10.0, "--region-seeds '" + o.region_seeds + "'");
        in.description["regions"] = fmt::format("grown {} mm along the surface from the points of {}", o.region_radius, o.region_seeds);
    } else if ((o.labels.empty() && o.surface.empty()) || !o.notch_x) {
        in.description["regions"] = o.labels.empty() && o.surface.empty() ? "none (all surface)" : "anatomical rule, no umbilical notch (no --notch-x)";
    } else {
        in.description["regions"] = fmt::format("anatomical rule, notch at x = {} mm", *o.notch_x);
    }
    in.cloud = read_point_cloud(o.cloud);
    in.description["cloud"] = o.cloud;
    if (!o.vessels.empty()) {
        in.vessels = read_vessel_centrelines(o.vessels, o.vessel_scale, o.vessel_radius);
        in.description["vessels"] = o.vessels;
    }
    if (!o.landmarks.empty()) in.landmarks = read_landmarks(o.landmarks);
    if (!o.landmarks_truth.empty()) {
        if (!in.landmarks) fail("register-surface: --landmarks-truth needs --landmarks (their rest positions)");
        in.truth = read_landmarks(o.landmarks_truth);
    }
    if (!o.truth_surface.empty()) in.truth_surface = read_surface(o.truth_surface);
    return in;
}

struct Supports {
    std::vector<std::int32_t> nodes; ///< sorted, unique
    json sources = json::array();
};

std::vector<std::int32_t> read_node_ids(const std::string& path, std::size_t node_count)
{
    const std::string what = "--support-nodes '" + path + "'";
    require_existing_file(path, what);
    std::ifstream in(path);
    std::vector<std::int32_t> ids;
    std::string line;
    int number = 0;
    while (std::getline(in, line)) {
        ++number;
        const auto hash = line.find('#');
        if (hash != std::string::npos) line.resize(hash);
        for (auto& c : line)
            if (c == ',' || c == ';' || c == '\t' || c == '\r') c = ' ';
        std::istringstream words(line);
        std::string word;
        while (words >> word) {
            const auto v = parse_number(word);
            if (!v) {
                if (ids.empty() && number == 1 && (word == "node" || word == "id" || word == "node_id")) continue; // a header
                fail("{}: line {}: '{}' is not a node id", what, number, word);
            }
            const auto id = to_integer<std::int32_t>(*v, what, "a node id");
            if (id < 0 || static_cast<std::size_t>(id) >= node_count) fail("{}: line {}: node {} is not a node of the model (0 … {})", what, number, id, node_count - 1);
            ids.push_back(id);
        }
    }
    if (ids.empty()) fail("{}: no node id", what);
    return ids;
}

/// The anatomical supports: the posterior surface, picked points (with a radius) and node ids, together.
Supports select_supports(const Options& o, const Inputs& in)
{
    Supports s;
    if (!(o.support_stiffness >= 0) || !std::isfinite(o.support_stiffness))
        fail("--support-stiffness {} N/mm must be ≥ 0 (0: held)", o.support_stiffness);
    if (!(o.support_tolerance > 0) || !std::isfinite(o.support_tolerance)) fail("--support-tolerance {} mm must be > 0", o.support_tolerance);
    if (o.support == "posterior") {
        const auto nodes = surface_nodes_facing(in.mesh, in.surface, Vec3::UnitY(), 0.5);
        if (nodes.empty()) fail("--support posterior: no surface node faces posterior (+y) in the model");
        s.nodes.insert(s.nodes.end(), nodes.begin(), nodes.end());
        s.sources.push_back({{"source", "posterior"}, {"rule", "surface nodes whose normal · +y > 0.5"}, {"nodes", nodes.size()}});
    } else if (o.support != "none") {
        fail("--support '{}': use posterior (default) or none (paper 001's free model)", o.support);
    }
    if (!o.support_points.empty()) {
        std::vector<Vec3> points;
        for (const auto& l : read_landmarks(o.support_points)) points.push_back(l.position);
        const auto nodes = surface_nodes_near(in.mesh, in.surface, points, o.support_radius);
        if (nodes.empty())
            fail("--support-points '{}': no surface node within --support-radius {} mm of its {} point(s) (are they on the model's surface, mm, LPS?)",
                 o.support_points, o.support_radius, points.size());
        s.nodes.insert(s.nodes.end(), nodes.begin(), nodes.end());
        s.sources.push_back({{"source", o.support_points}, {"points", points.size()}, {"radius_mm", o.support_radius}, {"nodes", nodes.size()}});
    }
    if (!o.support_region.empty()) {
        // A labelled surface region (from --regions or --region-seeds): e.g. 3 = the bare area.
        std::set<std::int32_t> wanted;
        for (const double v : parse_number_list(o.support_region, "--support-region")) wanted.insert(to_integer<std::int32_t>(v, "--support-region", "a region label"));
        std::set<std::int32_t> nodes;
        for (std::size_t t = 0; t < in.surface.triangles.size(); ++t)
            if (wanted.count(in.surface.labels[t])) nodes.insert(in.surface.triangles[t].begin(), in.surface.triangles[t].end());
        if (nodes.empty()) fail("--support-region {}: no surface triangle of the model carries that region label (give them with --regions)", o.support_region);
        s.nodes.insert(s.nodes.end(), nodes.begin(), nodes.end());
        s.sources.push_back({{"source", "region " + o.support_region}, {"nodes", nodes.size()}});
    }
    if (!o.support_nodes.empty()) {
        const auto nodes = read_node_ids(o.support_nodes, in.mesh.node_count());
        s.nodes.insert(s.nodes.end(), nodes.begin(), nodes.end());
        s.sources.push_back({{"source", o.support_nodes}, {"nodes", nodes.size()}});
    }
    std::sort(s.nodes.begin(), s.nodes.end());
    s.nodes.erase(std::unique(s.nodes.begin(), s.nodes.end()), s.nodes.end());
    std::set<std::int32_t> surface_nodes;
    for (const auto& t : in.surface.triangles) surface_nodes.insert(t.begin(), t.end());
    std::size_t on_surface = 0;
    for (const auto n : s.nodes) on_surface += surface_nodes.count(n);
    if (!s.nodes.empty() && on_surface >= surface_nodes.size())
        fail("--support {}{}: the supports take every one of the {} surface nodes; nothing is left free to meet the cloud", o.support,
             o.support_points.empty() && o.support_nodes.empty() && o.support_region.empty() ? "" : " with --support-points/--support-nodes/--support-region",
             surface_nodes.size());
    if (!s.nodes.empty())
        logger()->info("register-surface: {} support nodes {}", s.nodes.size(),
                       o.support_stiffness > 0 ? fmt::format("on springs of {} N/mm", o.support_stiffness) : std::string("held at rest"));
    return s;
}

double young_modulus(const Options& o)
{
    if (o.young_modulus) return *o.young_modulus;
    if (o.material == "healthy") return 3500.0;
    if (o.material == "cirrhotic") return 30000.0;
    fail("--material '{}': use healthy (3.5 kPa) or cirrhotic (30 kPa), or give --young-modulus", o.material);
}

struct MethodOutcome {
    std::string name;
    std::vector<double> u;
    double seconds = 0.0;
    json details;
};

json evaluate(const MethodOutcome& m, const Inputs& in, const std::vector<NodeEmbedding>& landmark_cells, const std::vector<std::uint8_t>& node_used,
              const std::vector<std::optional<Vec3>>& truth_at_nodes, const std::function<double(const std::vector<double>&)>& strain_energy_mj)
{
    json r = m.details;
    r["seconds"] = m.seconds;
    // What a user can judge a result by without the truth (issue 32's safeguard).
    std::vector<double> rest(3 * in.mesh.node_count());
    for (std::size_t n = 0; n < in.mesh.node_count(); ++n)
        for (int d = 0; d < 3; ++d) rest[3 * n + static_cast<std::size_t>(d)] = in.mesh.nodes[n][d];
    const RigidMotion pose = implied_rigid_motion(rest, m.u);
    double largest = 0.0;
    for (std::size_t i = 0; i < m.u.size(); i += 3) largest = std::max(largest, std::hypot(m.u[i], m.u[i + 1], m.u[i + 2]));
    r["largest_displacement_mm"] = largest;
    r["strain_energy_mj"] = strain_energy_mj(m.u);
    r["implied_rigid_motion"] = {{"rotation_deg", pose.angle_deg}, {"translation_mm", {pose.translation[0], pose.translation[1], pose.translation[2]}},
                                 {"non_rigid_rms_mm", pose.residual_rms_mm}};
    const SurfaceMesh deformed = regions_surface(in.mesh, in.surface, &m.u);
    const SurfaceDistance fit = points_to_surface(in.cloud.points, deformed, "cloud to model");
    r["cloud_to_model_mm"] = {{"mean", fit.mean_mm}, {"max", fit.max_mm}};
    if (in.truth_surface) {
        const HausdorffReport h = hausdorff_distance(deformed, *in.truth_surface, "model vs truth surface");
        r["hausdorff_mm"] = {{"model_to_truth", {{"mean", h.forward.mean_mm}, {"max", h.forward.max_mm}}},
                             {"truth_to_model", {{"mean", h.backward.mean_mm}, {"max", h.backward.max_mm}}},
                             {"mean", h.mean_mm()}, {"max", h.max_mm()}};
    }
    if (in.landmarks && in.truth) {
        const TreReport tre = compute_tre(displace_landmarks(in.mesh, landmark_cells, *in.landmarks, m.u), *in.truth, m.name + " landmarks");
        r["tre"] = json::parse(tre_stats_json(tre));
        r["tre_per_landmark"] = json::array();
        for (const auto& e : tre.entries) r["tre_per_landmark"].push_back({{"name", e.name}, {"type", to_string(e.type)}, {"error_mm", e.error_mm}});
    }
    if (!truth_at_nodes.empty()) {
        std::vector<double> errors;
        for (std::size_t i = 0; i < truth_at_nodes.size(); ++i)
            if (!node_used[i] && truth_at_nodes[i])
                errors.push_back((Vec3(m.u[3 * i], m.u[3 * i + 1], m.u[3 * i + 2]) - *truth_at_nodes[i]).norm());
        const TreStats s = tre_stats(errors);
        r["node_tre_mm"] = {{"nodes", s.count}, {"mean", s.mean_mm}, {"max", s.max_mm}, {"std", s.std_mm}};
    }
    return r;
}

/// Whether the data decide between the methods (issue 32): two methods that fit the cloud about
/// equally well (mean distances within 0.5 mm or 25 %) but place the model differently (nodal RMS
/// difference over 2 mm and over 3× their fit) are two answers the cloud cannot tell apart; so is a
/// rigid fit whose starts found far-apart poses of equal fit.
json determinacy(const std::vector<MethodOutcome>& outcomes, const json& methods, bool rigid_pose_determined)
{
    json notes = json::array();
    bool determined = rigid_pose_determined;
    if (!rigid_pose_determined) notes.push_back("rigid starts found poses rotated more than 10° apart that fit the cloud within 10 % of each other");
    for (std::size_t a = 0; a < outcomes.size(); ++a)
        for (std::size_t b = a + 1; b < outcomes.size(); ++b) {
            const auto& ma = outcomes[a];
            const auto& mb = outcomes[b];
            if (ma.name == "at_rest" || mb.name == "at_rest") continue;
            const double fa = methods[ma.name]["cloud_to_model_mm"]["mean"].get<double>(), fb = methods[mb.name]["cloud_to_model_mm"]["mean"].get<double>();
            double sum = 0.0;
            for (std::size_t i = 0; i < ma.u.size(); ++i) sum += (ma.u[i] - mb.u[i]) * (ma.u[i] - mb.u[i]);
            const double rms = std::sqrt(3.0 * sum / static_cast<double>(ma.u.size()));
            const bool alike = std::abs(fa - fb) <= std::max(0.5, 0.25 * std::min(fa, fb));
            if (alike && rms > std::max(2.0, 3.0 * std::max(fa, fb))) {
                determined = false;
                notes.push_back(fmt::format("{} and {} fit the cloud alike ({:.2f} and {:.2f} mm) but place the model {:.1f} mm apart (nodal RMS)", ma.name,
                                            mb.name, fa, fb, rms));
            }
        }
    json out = {{"pose_determined", determined}, {"notes", notes}};
    out["statement"] = determined ? "the methods that fit the data agree within what the data resolve"
                                  : "the data do not determine the pose: the results below are alternatives the cloud cannot tell apart";
    return out;
}

} // namespace

void add_subcommand_register_surface(CLI::App& app)
{
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("register-surface", "Register a tetrahedral liver model to a partial intra-operative surface (paper 001): "
                                                       "labelled matching, arctan forces with annealing, co-rotational backward Euler");
    sub->add_option("--dataset", o->dataset, "Phantom dataset (physreg phantom): model from its rest labels, cloud, landmarks and truth from --state");
    sub->add_option("--state", o->state, "Dataset state to register to (default insufflation)");
    sub->add_option("--visible", o->visible, "Dataset: visible percentage of the surface (one the dataset has: 50, 40, 30, 20, 10; default 30)");
    sub->add_option("--labels", o->labels, "Liver label volume (NIfTI/NRRD/MHA/DICOM): meshed with CGAL");
    sub->add_option("--liver-labels", o->liver_labels, "--labels: which labels form the liver (default every nonzero label)");
    sub->add_option("--notch-x", o->notch_x, "--labels/--surface: x (LPS, mm) of the umbilical notch for the anatomical region rule (else: --labels "
                                             "has no UN region, --surface no region at all)");
    sub->add_option("--surface", o->surface, "Closed liver surface (STL/PLY/OBJ, mm, LPS): meshed with CGAL");
    sub->add_option("--surface-scale", o->surface_scale, "--surface: factor to mm (e.g. 1000 for SOFA meshes in metres; default 1)");
    sub->add_option("--model", o->model, "Tetrahedral liver mesh (.vtu, .vtk, .msh) instead of --labels");
    sub->add_option("--regions", o->regions, "Labelled surface (PLY with vertex 'label'/'feature' or face labels; 0 surface, 1 UN, 2 AM) giving the model's regions");
    sub->add_option("--region-seeds", o->region_seeds, "Points picked on the surface (CSV/FCSV/.mrk.json) named UN… or AM…: regions grown "
                                                     "along the surface from them");
    sub->add_option("--region-radius", o->region_radius, "--region-seeds: geodesic radius of each region, mm (default 15)");
    sub->add_option("--cloud", o->cloud, "Intra-operative point cloud (.ply with optional normals and 'label', or .csv x,y,z[,label] with or without a header), mm, LPS");
    sub->add_option("--landmarks", o->landmarks, "Targets at rest (CSV/FCSV/.mrk.json) to map through the registration");
    sub->add_option("--landmarks-truth", o->landmarks_truth, "Their true deformed positions (same names): TRE in the summary");
    sub->add_option("--truth-surface", o->truth_surface, "The true deformed liver surface (STL/PLY/OBJ): Hausdorff distance in the summary");
    sub->add_option("--method", o->method, "biomechanical (default), adjoint (optimal control: static elastic model, unknown surface forces, "
                                           "issue 32), rigid (labelled rigid ICP) or icp (plain ICP); the others are reported beside it");
    sub->add_option("--model-kind", o->model_kind, "homogeneous (default: parenchyma only) or heterogeneous (plus Glisson's capsule: a membrane "
                                                  "of 8 000 kPa on the surface, paper 001)");
    sub->add_option("--capsule-thickness", o->capsule_thickness, "Heterogeneous model: capsule thickness, mm (default 0.1)");
    sub->add_option("--vessels", o->vessels, "Heterogeneous model: vessel centrelines (CSV branch,x,y,z,radius, or text 'x y z' lines with "
                                             "blank lines between branches); --dataset brings the phantom's own");
    sub->add_option("--vessel-scale", o->vessel_scale, "--vessels: factor to mm (e.g. 1000 for metres; default 1)");
    sub->add_option("--vessel-radius", o->vessel_radius, "--vessels: radius of files without radii, mm (default 1.5)");
    sub->add_option("--material", o->material, "healthy (E 3.5 kPa, default) or cirrhotic (30 kPa), paper 001");
    sub->add_option("--young-modulus", o->young_modulus, "Parenchyma Young's modulus, Pa (instead of --material)");
    sub->add_option("--poisson", o->poisson, "Poisson's ratio (default 0.45)");
    sub->add_option("--cell-size", o->cell_size, "Tetrahedron size (largest circumradius), mm (default 7)");
    sub->add_option("--d90", o->d90, "Distance at which a pair force reaches 90 % of its maximum, mm (default 5)");
    sub->add_option("--traction", o->traction, "Largest pair traction as a fraction of E (sets k_max; default 0.5)");
    sub->add_option("--distance-fraction", o->distance_fraction, "Pruning d_t: keep pairs closer than d_t × the largest (default 0.9)");
    sub->add_option("--max-pair-distance", o->max_pair, "Pairs longer than this are dropped (a cloud that does not belong to the model), mm (default 40)");
    sub->add_option("--normal-agreement", o->normal_agreement, "Pruning n_t: keep pairs whose normals agree ≥ n_t (default 0.7)");
    sub->add_option("--support", o->support, "posterior (default: surface nodes facing posterior, normal · +y > 0.5, where the vena cava and "
                                             "ligaments hold a liver) or none (paper 001's free model)");
    sub->add_option("--support-points", o->support_points, "Further support: surface nodes within --support-radius of these points (landmark "
                                                           "file: CSV, .fcsv, .mrk.json; e.g. ligaments, vena cava)");
    sub->add_option("--support-radius", o->support_radius, "--support-points: radius, mm (default 10)");
    sub->add_option("--support-region", o->support_region, "Further support: surface triangles of these region labels (e.g. 3; from "
                                                           "--regions, whose labels other than 0, 1, 2 are never paired with the cloud)");
    sub->add_option("--support-nodes", o->support_nodes, "Further support: a file of model node ids (one or more per line, '#' comments)");
    sub->add_option("--support-stiffness", o->support_stiffness, "0 (default): supports held; > 0: springs of this stiffness, N/mm per node "
                                                                 "and direction, to the rest position (ligaments stretch)");
    sub->add_option("--noise", o->noise, "--method adjoint: the cloud's noise σ, mm, for the discrepancy principle that picks the "
                                         "regularisation weight (default 0.5)");
    sub->add_option("--support-tolerance", o->support_tolerance, "Rigid baselines: a pose that moves a support node farther than this is "
                                                                 "implausible, mm (default 3)");
    sub->add_option("--time-step", o->time_step, "Backward Euler time step, s (default 0.1)");
    sub->add_option("--plateau-tolerance", o->plateau_tolerance, "A plateau ends when no node moves more than this in a step, mm (default 0.01)…");
    sub->add_option("--plateau-rms-fraction", o->plateau_rms_fraction, "…or when the nodes' rms motion in a step is below this fraction of "
                                                                     "the plateau tolerance (default 0.5; 0: off, paper 001's rule)");
    sub->add_option("--newton-per-step", o->newton_per_step, "Newton iterations per time step (default 1: linearised backward Euler; 0: to convergence)");
    sub->add_option("--max-steps-per-plateau", o->max_steps, "Time steps per plateau at most (default 100)");
    sub->add_option("--field-spacing", o->field_spacing, "Voxel size of displacement.nii.gz when no label volume gives the grid, mm (default 2)");
    sub->add_option("--seed", o->seed, "Seed of the CGAL mesher (default 1)");
    sub->add_option("-o,--output", o->output, "Output folder (mesh.vtu, displacement.nii.gz, landmarks.csv, regions.ply, summary.json)")->required();
    sub->add_flag("--force", o->replace, "Replace an existing output folder");
    sub->add_flag("--json", o->json, "Print the summary as JSON on stdout");
    sub->callback([o] {
        const auto start = std::chrono::steady_clock::now();
        if (o->method != "biomechanical" && o->method != "rigid" && o->method != "icp" && o->method != "adjoint")
            fail("--method '{}': use biomechanical, adjoint, rigid or icp", o->method);
        if (o->method == "adjoint" && o->support_stiffness > 0)
            fail("--method adjoint: --support-stiffness {} N/mm: the adjoint method holds its supports (or, with --support none, ties every node by "
                 "soft springs); elastic supports are for the biomechanical method", o->support_stiffness);
        if (!(o->noise > 0) || !std::isfinite(o->noise)) fail("--noise {} mm must be > 0", o->noise);
        const double E = young_modulus(*o);
        StagedDirectory staging(o->output, o->replace); // refuses an existing output before any work
        ProgressDisplay bar("register-surface");
        bar.update(0.0, "model and inputs");
        const Inputs in = load_inputs(*o);
        logger()->info("register-surface: model {} nodes, {} tetrahedra, {} surface triangles; cloud {} points", in.mesh.node_count(), in.mesh.cell_count(),
                       in.surface.triangles.size(), in.cloud.points.size());
        const SurfaceMatcher matcher(in.surface, in.mesh.node_count(), "the model's surface");
        TledOptions tled;
        tled.law = MaterialLaw::corotational;
        const TissueTable tissues = homogeneous_liver_tissues(E, o->poisson);
        const TledModel model(in.mesh, tissues, tled);
        std::optional<Membrane> capsule;
        std::optional<EmbeddedBeams> beams;
        if (o->model_kind == "heterogeneous") {
            MembraneMaterial m;
            m.thickness_mm = o->capsule_thickness;
            capsule.emplace(in.surface.triangles, model.rest_positions(), m, "--model-kind heterogeneous: the capsule");
            if (in.vessels.empty())
                logger()->warn("register-surface: no vessel centrelines (--vessels): the heterogeneous model has the capsule only");
            else
                beams.emplace(in.mesh, in.vessels, BeamMaterial{}, o->cell_size, "--model-kind heterogeneous: the vessel beams");
        } else if (o->model_kind != "homogeneous") {
            fail("--model-kind '{}': use homogeneous or heterogeneous", o->model_kind);
        } else if (!o->vessels.empty()) {
            fail("--vessels: only the heterogeneous model has vessels (add --model-kind heterogeneous)");
        }

        SurfaceRegistrationOptions options;
        options.matching.distance_fraction = o->distance_fraction;
        options.matching.normal_agreement = o->normal_agreement;
        options.matching.max_distance_mm = o->max_pair;
        options.force.d90_mm = o->d90;
        options.dynamics.time_step_s = o->time_step;
        options.plateau_tolerance_mm = o->plateau_tolerance;
        options.plateau_rms_fraction = o->plateau_rms_fraction;
        options.max_steps_per_plateau = o->max_steps;
        options.newton_iterations_per_step = o->newton_per_step;
        if (capsule) options.structures.push_back(&*capsule);
        if (beams) options.structures.push_back(&*beams);
        const Supports supports = select_supports(*o, in);
        options.fixed_nodes = supports.nodes;
        options.support_stiffness_n_per_mm = o->support_stiffness;
        const double spacing = mean_point_spacing_mm(in.cloud.points);
        const double k_max = pair_stiffness_n(o->traction, E, spacing);
        options.schedules = paper001_schedules(k_max);

        // All three methods, the chosen one written out; the others are the report's baselines.
        std::vector<MethodOutcome> outcomes;
        std::vector<std::uint8_t> used(in.mesh.node_count(), 0);
        {
            MethodOutcome at_rest{"at_rest", std::vector<double>(3 * in.mesh.node_count(), 0.0), 0.0, json::object()};
            outcomes.push_back(at_rest);
        }
        bool rigid_pose_determined = true;
        for (const bool labelled : {true, false}) {
            RobustRigidOptions robust;
            robust.supports = options.fixed_nodes;
            robust.support_tolerance_mm = o->support_tolerance;
            const auto start_rigid = std::chrono::steady_clock::now();
            const RobustRigidResult rr = register_surface_rigid_robust(model.rest_positions(), matcher, in.cloud, options.matching, labelled, robust);
            const RigidSurfaceResult& r = rr.chosen;
            json alternatives = json::array();
            for (const auto& c : rr.candidates)
                alternatives.push_back({{"start", c.start}, {"rotation_deg", Eigen::AngleAxisd(c.result.rotation).angle() * 180.0 / M_PI},
                                        {"cloud_to_model_mean_mm", c.cloud_mean_mm}, {"support_motion_mm", c.support_motion_mm},
                                        {"plausible", c.plausible}, {"chosen", c.start == rr.chosen_start}});
            json d = {{"iterations", r.iterations}, {"converged", r.converged}, {"pairs", r.matching.kept},
                      {"rotation_deg", Eigen::AngleAxisd(r.rotation).angle() * 180.0 / M_PI}, {"translation_mm", {r.translation[0], r.translation[1], r.translation[2]}},
                      {"start", rr.chosen_start}, {"decision", rr.decision}, {"pose_determined", rr.pose_determined}, {"alternatives", alternatives}};
            rigid_pose_determined = rigid_pose_determined && rr.pose_determined;
            outcomes.push_back({labelled ? "rigid" : "icp", r.displacement_mm,
                                std::chrono::duration<double>(std::chrono::steady_clock::now() - start_rigid).count(), d});
        }
        bar.update(0.05, "biomechanical registration");
        const SurfaceRegistrationResult b = register_surface_biomechanical(model, matcher, in.cloud, options, [&](double f, const std::string& m) {
            bar.update(0.05 + 0.85 * f, m);
        });
        used = b.node_used;
        {
            json plateaus = json::array();
            for (const auto& p : b.plateaus) {
                json k;
                for (const auto& [label, v] : p.stiffness_n) k[std::to_string(label)] = v;
                plateaus.push_back({{"plateau", p.plateau}, {"stiffness_n", k}, {"steps", p.steps}, {"settled", p.reached}, {"last_step_mm", p.last_step_mm}, {"last_step_rms_mm", p.last_step_rms_mm},
                                    {"pairs", p.matching.kept}, {"pruned_far", p.matching.pruned_far}, {"pruned_distance", p.matching.pruned_distance}, {"pruned_normal", p.matching.pruned_normal},
                                    {"mean_pair_distance_mm", p.matching.mean_distance_mm}, {"factorisations", p.factorisations}, {"seconds", p.seconds}});
            }
            outcomes.push_back({"biomechanical", b.displacement_mm, b.seconds,
                                {{"time_steps", b.steps}, {"factorisations", b.factorisations}, {"newton_iterations", b.newton_iterations},
                                 {"time_split_s", {{"matching", b.matching_s}, {"forces", b.force_s}, {"assembly", b.assembly_s},
                                                   {"factorisation", b.factorisation_s}, {"solves", b.solve_s}}},
                                 {"plateaus", plateaus}}});
        }
        if (o->method == "adjoint") {
            bar.update(0.6, "adjoint registration");
            AdjointSurfaceOptions a;
            a.matching = options.matching;
            a.young_modulus_pa = E;
            a.poisson_ratio = o->poisson;
            a.fixed_nodes = options.fixed_nodes;
            a.noise_mm = o->noise;
            const AdjointSurfaceResult r = register_surface_adjoint(in.mesh, matcher, in.cloud, a, [&](double f, const std::string& m) {
                bar.update(0.6 + 0.3 * f, m);
            });
            json rungs = json::array();
            for (const auto& g : r.rungs)
                rungs.push_back({{"alpha_mm2_per_mj", g.alpha}, {"rms_distance_mm", g.rms_distance_mm}, {"strain_energy_mj", g.strain_energy_mj},
                                 {"lbfgs_iterations", g.lbfgs_iterations}, {"pairs", g.pairs}});
            outcomes.push_back({"adjoint", r.displacement_mm, r.seconds,
                                {{"model", "static co-rotational linear tetrahedra, re-linearised (R K0 R^T, CHOLMOD) at every re-pairing; unknown surface forces"},
                                 {"regularisation", "alpha x strain energy"},
                                 {"alpha_rule", fmt::format("discrepancy principle: the largest alpha whose RMS point-to-plane distance is <= {} x the noise {} mm",
                                                            a.discrepancy_factor, a.noise_mm)},
                                 {"chosen_alpha_mm2_per_mj", r.rungs[r.chosen].alpha}, {"discrepancy_reached", r.discrepancy_reached},
                                 {"rungs", rungs}, {"solves", r.solves}, {"warnings", r.warnings},
                                 {"supports", a.fixed_nodes.empty() ? "none: soft springs to rest at every node" : "held"}}});
            if (!r.discrepancy_reached)
                logger()->warn("register-surface: the adjoint method never brought the cloud within {:.2f} mm (RMS); the smallest alpha is kept",
                               a.discrepancy_factor * a.noise_mm);
        }
        bar.update(0.92, "evaluation and outputs");
        const std::vector<NodeEmbedding> landmark_cells =
            in.landmarks ? embed_landmarks(in.mesh, *in.landmarks, 1.5 * o->cell_size, "the liver model") : std::vector<NodeEmbedding>{};
        std::vector<std::optional<Vec3>> truth_at_nodes;
        if (in.truth_mesh) {
            const PointLocator locator(*in.truth_mesh);
            for (const auto& x : in.mesh.nodes) {
                const auto e = locator.locate(x);
                if (!e) {
                    truth_at_nodes.emplace_back();
                    continue;
                }
                const auto d = interpolate_nodal(*in.truth_mesh, *e, in.truth_displacement, 3);
                truth_at_nodes.emplace_back(Vec3(d[0], d[1], d[2]));
            }
        }
        const StiffnessAssembler energy_assembler(model, nullptr, {});
        const auto strain_energy = [&](const std::vector<double>& u) {
            double e = energy_assembler.energy(u.data()).energy_mj;
            std::vector<double> scratch(u.size(), 0.0);
            for (const auto* s : options.structures) e += s->add_forces(u.data(), scratch.data());
            return e;
        };
        json methods;
        for (const auto& m : outcomes) methods[m.name] = evaluate(m, in, landmark_cells, used, truth_at_nodes, strain_energy);
        const MethodOutcome& chosen = *std::find_if(outcomes.begin(), outcomes.end(), [&](const MethodOutcome& m) { return m.name == o->method; });

        MeshData data;
        data.point_data.push_back({"displacement", 3, chosen.u});
        write_vtu(staging.path() / "mesh.vtu", in.mesh, data);
        write_surface(staging.path() / "regions.ply", regions_surface(in.mesh, in.surface));
        write_surface(staging.path() / "regions.vtk", regions_surface(in.mesh, in.surface));
        write_surface(staging.path() / "registered_surface.ply", regions_surface(in.mesh, in.surface, &chosen.u));
        const ImageGeometry geometry = in.field_geometry ? *in.field_geometry : image_grid_over_mesh(in.mesh, o->field_spacing, 2 * o->field_spacing);
        write_displacement_field(staging.path() / "displacement.nii.gz", sample_displacement_field(in.mesh, chosen.u, geometry).field);
        if (in.landmarks) write_landmarks(staging.path() / "landmarks.csv", displace_landmarks(in.mesh, landmark_cells, *in.landmarks, chosen.u));

        json summary;
        summary["command"] = "register-surface";
        summary["units"] = {{"length", "mm"}, {"force", "N"}, {"time", "s"}, {"young_modulus", "Pa"}};
        summary["inputs"] = in.description;
        summary["method"] = o->method;
        summary["support"] = o->support;
        summary["support_nodes"] = options.fixed_nodes.size();
        summary["supports"] = {{"sources", supports.sources}, {"kind", o->support_stiffness > 0 ? "elastic" : "held"},
                               {"stiffness_n_per_mm", o->support_stiffness}, {"nodes", options.fixed_nodes},
                               {"rigid_plausibility_tolerance_mm", o->support_tolerance}};
        summary["determinacy"] = determinacy(outcomes, methods, rigid_pose_determined);
        if (in.truth_mesh) {
            // The pose the ground truth implies, to judge the baselines' rotations by (reports only).
            std::vector<double> truth_rest;
            for (const auto& x : in.truth_mesh->nodes) truth_rest.insert(truth_rest.end(), {x[0], x[1], x[2]});
            const RigidMotion pose = implied_rigid_motion(truth_rest, in.truth_displacement);
            summary["truth"] = {{"implied_rigid_motion", {{"rotation_deg", pose.angle_deg},
                                                          {"translation_mm", {pose.translation[0], pose.translation[1], pose.translation[2]}},
                                                          {"non_rigid_rms_mm", pose.residual_rms_mm}}}};
        }
        summary["model"] = {{"kind", o->model_kind}, {"element", "linear tetrahedra (CGAL Mesh_3), co-rotational"}, {"nodes", in.mesh.node_count()},
                            {"tetrahedra", in.mesh.cell_count()}, {"surface_triangles", in.surface.triangles.size()},
                            {"young_modulus_pa", E}, {"poisson_ratio", o->poisson}};
        if (capsule)
            summary["model"]["capsule"] = {{"element", "co-rotational constant-strain triangles (plane stress)"}, {"triangles", capsule->size()},
                                           {"young_modulus_pa", MembraneMaterial{}.young_modulus_pa}, {"poisson_ratio", MembraneMaterial{}.poisson_ratio},
                                           {"thickness_mm", o->capsule_thickness}, {"area_mm2", capsule->total_area_mm2()}};
        if (beams)
            summary["model"]["vessels"] = {{"element", "co-rotational Timoshenko beams embedded in the tetrahedra"}, {"elements", beams->size()},
                                           {"length_mm", beams->total_length_mm()}, {"segments_outside_model", beams->dropped_elements()},
                                           {"young_modulus_pa", BeamMaterial{}.young_modulus_pa}, {"poisson_ratio", BeamMaterial{}.poisson_ratio}};
        if (in.quality)
            summary["model"]["quality"] = {{"min_dihedral_deg", in.quality->min_dihedral_deg}, {"max_dihedral_deg", in.quality->max_dihedral_deg},
                                           {"min_radius_ratio", in.quality->min_radius_ratio}, {"mean_edge_mm", in.quality->mean_edge_mm}};
        std::map<std::string, int> region_triangles;
        for (auto l : in.surface.labels) ++region_triangles[l == 1 ? "umbilical_notch" : l == 2 ? "anterior_margin" : "surface"];
        summary["model"]["region_triangles"] = region_triangles;
        summary["cloud"] = {{"points", in.cloud.points.size()}, {"mean_spacing_mm", spacing}, {"normals", !in.cloud.normals.empty()}};
        summary["parameters"] = {{"cell_size_mm", o->cell_size}, {"d90_mm", o->d90}, {"traction_ratio", o->traction}, {"k_max_n", k_max}, {"distance_fraction", o->distance_fraction},
                                 {"normal_agreement", o->normal_agreement}, {"time_step_s", o->time_step}, {"rayleigh_mass_per_s", 0.1},
                                 {"rayleigh_stiffness_s", 0.1}, {"plateau_tolerance_mm", o->plateau_tolerance}, {"plateau_rms_fraction", o->plateau_rms_fraction}, {"exponent", 3},
                                 {"r", {{"umbilical_notch", 2}, {"anterior_margin", 4}, {"surface", 10}}}};
        summary["methods"] = methods;
        summary["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        write_atomically(staging.path() / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << summary.dump(2) << "\n"; });
        bar.update(0.99, "report.html");
        write_html_report(staging.path(), o->output);
        staging.commit();
        bar.finish();
        const auto line = [&](const std::string& name) {
            const json& m = methods[name];
            std::string s = fmt::format("{:<14}", name);
            if (m.contains("tre")) {
                const auto mm = [](const json& v) { return v.is_number() ? fmt::format("{:.2f}", v.get<double>()) : std::string("–"); };
                s += fmt::format(" TRE {} mm (internal {})", mm(m["tre"]["all"]["mean_mm"]), mm(m["tre"]["internal"]["mean_mm"]));
            }
            if (m.contains("node_tre_mm")) s += fmt::format(", nodes {:.2f} mm", m["node_tre_mm"]["mean"].get<double>());
            if (m.contains("hausdorff_mm")) s += fmt::format(", Hausdorff mean {:.2f} / max {:.2f} mm", m["hausdorff_mm"]["mean"].get<double>(), m["hausdorff_mm"]["max"].get<double>());
            s += fmt::format(", cloud→model {:.2f} mm, {:.2f} s", m["cloud_to_model_mm"]["mean"].get<double>(), m["seconds"].get<double>());
            return s;
        };
        if (o->json)
            std::cout << summary.dump(2) << "\n";
        else
            for (const char* name : {"at_rest", "icp", "rigid", "biomechanical", "adjoint"})
                if (methods.contains(name)) std::cerr << line(name) << "\n";
        if (!summary["determinacy"]["pose_determined"].get<bool>()) {
            logger()->warn("register-surface: {}", summary["determinacy"]["statement"].get<std::string>());
            for (const auto& note : summary["determinacy"]["notes"]) logger()->warn("  {}", note.get<std::string>());
        }
    });
}

} // namespace physreg::cli
