// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/phantom/dataset.hpp"

#include "detail/phantom_states.hpp"
#include "detail/state_writing.hpp"
#include "detail/tool_placement.hpp"

#include <cerrno>
#include <cstring>
#include <omp.h>

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/version.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/field/image_warping.hpp"
#include "physreg/figures/slice_figure.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/png.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mechanics/simulation/calculix.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/phantom/landmark_picking.hpp"
#include "physreg/phantom/partial_surface.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <string_view>
#include <chrono>
#include <exception>
#include <cmath>
#include <fstream>
#include <numeric>

namespace physreg {
namespace fs = std::filesystem;
using nlohmann::json;

MaterialSet parse_material_set(const std::string& text)
{
    if (text == "paper000") return MaterialSet::paper000;
    if (text == "healthy") return MaterialSet::healthy;
    if (text == "cirrhotic") return MaterialSet::cirrhotic;
    fail("unknown material set '{}' (paper000, healthy, cirrhotic)", text);
}

std::string to_string(MaterialSet set)
{
    switch (set) {
    case MaterialSet::paper000: return "paper000";
    case MaterialSet::healthy: return "healthy";
    case MaterialSet::cirrhotic: return "cirrhotic";
    }
    return "?";
}

TissueTable phantom_tissue_table(MaterialSet set, const LabelRoles& roles, const std::set<std::int32_t>& present)
{
    double parenchyma = 2e5, nu = 0.49, vessel = 1e6, vessel_nu = 0.49, lesion = 5e6;
    if (set != MaterialSet::paper000) {
        parenchyma = set == MaterialSet::healthy ? 3.5e3 : 3.0e4;
        nu = 0.45;
        vessel = 6.2e5;
        vessel_nu = 0.4;
        lesion = 10 * parenchyma;
    }
    TissueTable table;
    auto add = [&](const std::set<std::int32_t>& labels, const std::string& name, double e, double v) {
        int n = 0;
        for (const auto label : labels) {
            if (!present.count(label)) continue;
            table.tissues.push_back({label, n++ == 0 ? name : fmt::format("{}_{}", name, label), e, v, 1000.0});
        }
    };
    add(roles.liver, "parenchyma", parenchyma, nu);
    add(roles.lesion, "lesion", lesion, nu);
    add(roles.vessel, "vessel", vessel, vessel_nu);
    add(roles.kidney, "kidney", 2.5 * parenchyma, nu);
    for (const auto label : present)
        if (label != 0 && !table.find(label)) table.ignored_labels.insert(label);
    table.validate("phantom materials");
    return table;
}

PhantomSpec PhantomSpec::preset_spec(const std::string& name)
{
    PhantomSpec spec;
    spec.preset = name;
    // A 60 mm ball (a fist-sized probe): pressed 25 mm into the gel, a 25 mm one would sink two
    // radii deep and fold the skin over itself, and a 40 mm one moved the landmarks 4.0 mm on average.
    spec.tool.radius_mm = 30.0;
    if (name == "cirs057a") return spec;
    if (name == "small") {
        spec.voxel_mm = 4.0;
        spec.ground_truth_mesh.organ_cell_mm = 7.0;
        spec.ground_truth_mesh.kidney_cell_mm = 10.0;
        spec.ground_truth_mesh.body_cell_mm = 18.0;
        spec.ground_truth_mesh.facet_mm = 5.0;
        spec.ground_truth_mesh.facet_distance_mm = 1.5;
        spec.load_step_mm = 6.0;
        spec.depths_mm = {12, 15, 12, 10, 12};
        spec.tool.radius_mm = 15.0;
        spec.surface_percentages = {50, 10};
        return spec;
    }
    fail("unknown preset '{}' (cirs057a, small, or give a label map with --from-labels)", name);
}

void PhantomSpec::validate() const
{
    if (preset == "from-labels" && labels_file.empty()) fail("phantom: from-labels needs a label map");
    if (preset != "from-labels" && preset != "cirs057a" && preset != "small") fail("phantom: unknown preset '{}'", preset);
    if (!(voxel_mm >= 0.5 && voxel_mm <= 6.0)) fail("phantom: --resolution {} mm outside 0.5 … 6 mm", voxel_mm);
    if (seed < 1 || seed > 4294967295ull) fail("phantom: --seed {} outside 1 … 4294967295", seed);
    ground_truth_mesh.validate();
    if (!(load_step_mm > 0.0 && load_step_mm <= 20.0)) fail("phantom: load step {} mm outside (0, 20]", load_step_mm);
    roles.validate("phantom label roles");
    for (const auto& c : compressions) {
        if (!(c.depth_mm > 0.0 && c.depth_mm <= 60.0)) fail("phantom: compression {}: depth {} mm outside (0, 60]", c.name, c.depth_mm);
        if (!std::isfinite(c.x_mm) || !std::isfinite(c.z_mm)) fail("phantom: compression {}: position is not finite", c.name);
        if (!(c.direction.norm() > 0.0) || !c.direction.allFinite()) fail("phantom: compression {}: direction must be a non-zero vector", c.name);
    }
    if (compressions.empty() && depths_mm.size() > 5)
        fail("phantom: {} depths given; the default compressions take 1 to 5 (A, B, … in order)", depths_mm.size());
    // No compression at all (--depths none) is for studies of the organs' own states: one of them must remain.
    if (compressions.empty() && depths_mm.empty() && !(push_depth_mm > 0) && insufflation_pa && !(*insufflation_pa > 0))
        fail("phantom: no compression (--depths none), no insufflation and no push: the dataset would have no deformed state");
    for (const double d : depths_mm)
        if (!(d > 0.0 && d <= 60.0)) fail("phantom: depth {} mm outside (0, 60]", d);
    if (!(tool.radius_mm > 0.0) || !std::isfinite(tool.radius_mm)) fail("phantom: tool radius {} mm must be > 0", tool.radius_mm);
    if (insufflation_pa && (!(*insufflation_pa >= 0.0) || !std::isfinite(*insufflation_pa)))
        fail("phantom: insufflation pressure {} Pa must be ≥ 0", *insufflation_pa);
    if (!(landmark_noise_mm >= 0.0 && landmark_noise_mm <= 10.0)) fail("phantom: landmark noise {} mm outside [0, 10]", landmark_noise_mm);
    if (!(surface_noise_mm >= 0.0 && surface_noise_mm <= 10.0)) fail("phantom: surface noise {} mm outside [0, 10]", surface_noise_mm);
    for (const int p : surface_percentages)
        if (p <= 0 || p > 100) fail("phantom: surface percentage {} outside 1 … 100", p);
    if (!(push_depth_mm >= 0.0 && push_depth_mm <= 80.0)) fail("phantom: --push-depth {} mm outside [0, 80]", push_depth_mm);
    if (!(push_tool_radius_mm >= 2.0 && push_tool_radius_mm <= 50.0)) fail("phantom: --push-tool-radius {} mm outside [2, 50]", push_tool_radius_mm);
    if (push_cloud_points < 3 || push_cloud_points > 1000000) fail("phantom: --push-points {} outside 3 … 1000000", push_cloud_points);
    if (!(push_cloud_coverage > 0.0 && push_cloud_coverage <= 1.0)) fail("phantom: push cloud coverage {} outside (0, 1]", push_cloud_coverage);
}


using namespace detail; // the generator's parts (src/phantom/detail)

namespace {

constexpr int format_version = phantom_dataset_format_version;
using Report = std::function<void(double, const std::string&)>;

double seconds_since(std::chrono::steady_clock::time_point t) { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count(); }

/// The ground truth's discretisation against CalculiX on a block of its gel with an inclusion
/// (when asked and ccx is installed): the manifest's "calculix_validation" entry.
json calculix_validation(const PhantomSpec& spec, const Prepared& p, const GroundTruth& gt, const fs::path& root, const Report& report, json& timings)
{
    json calculix = {{"run", false}};
    if (spec.calculix_validation && !calculix_available()) {
        calculix["reason"] = "ccx (Debian calculix-ccx) is not installed";
    } else if (spec.calculix_validation) {
        report(0.075, "CalculiX validation");
        const auto t = std::chrono::steady_clock::now();
        std::int32_t gel = -1, inclusion = -1;
        for (const auto& tissue : gt.tissues.tissues) {
            if (p.roles.body.count(tissue.label) && gel < 0) gel = tissue.label;
            if (p.roles.liver.count(tissue.label) && inclusion < 0) inclusion = tissue.label;
        }
        if (gel < 0) gel = inclusion; // organs only: a block of parenchyma
        for (const auto& tissue : gt.tissues.tissues)
            if (gel == inclusion && tissue.label != gel) inclusion = tissue.label;
        // Its files go to a scratch folder inside the staged dataset, removed before the dataset appears.
        const fs::path work = root / ".calculix";
        const CalculixValidation v = validate_ground_truth_against_calculix(gt.tissues, gel, inclusion, work);
        fs::remove_all(work);
        calculix = {{"run", true}, {"relative_rms", v.relative_rms}, {"calculix_peak_displacement_mm", v.peak_mm}, {"case", v.description}};
        logger()->info("ground truth vs CalculiX: RMS difference {:.3f} % of the peak displacement {:.2f} mm", 100 * v.relative_rms, v.peak_mm);
        timings["calculix_validation_s"] = seconds_since(t);
    }

    return calculix;
}

/// The manifest's description of the dataset: format, generator, units, frame, label roles, and the
/// ground truth (materials, mesh, law, contact, solver: for reports only), landmarks and surfaces.
json dataset_manifest(const PhantomSpec& spec, const Prepared& p, const GroundTruth& gt, const json& calculix, const LandmarkSet& rest_landmarks)
{
    json manifest;
    manifest["format"] = "physreg-phantom-dataset";
    manifest["format_version"] = format_version;
    manifest["generator"] = {{"name", "physreg"}, {"version", VERSION}, {"seed", spec.seed}, {"preset", spec.preset},
                             {"source", spec.preset == "from-labels" ? fs::absolute(spec.labels_file).lexically_normal().string() : p.source}};
    manifest["units"] = {{"length", "mm"}, {"displacement", "mm"}, {"young_modulus", "Pa"}, {"pressure", "Pa"},
                         {"force", "N"}, {"intensity", "arbitrary (MR-like)"}};
    manifest["coordinate_system"] = "LPS: ITK physical space (x to the patient's left, y posterior, z superior); 3D Slicer shows RAS";
    json roles;
    for (const auto& [name, set] : std::vector<std::pair<std::string, const std::set<std::int32_t>*>>{
             {"body", &p.roles.body}, {"liver", &p.roles.liver}, {"lesion", &p.roles.lesion},
             {"vessel", &p.roles.vessel}, {"bone", &p.roles.bone}, {"kidney", &p.roles.kidney}})
        roles[name] = *set;
    manifest["label_roles"] = roles;
    manifest["material_set"] = to_string(spec.materials);
    // The ground truth's materials: for reports only — no registration command reads them.
    json tissues = json::array();
    for (const auto& tissue : gt.tissues.tissues) {
        const ElasticMaterial m = material_from_tissue(tissue);
        tissues.push_back({{"label", tissue.label}, {"name", tissue.name}, {"young_modulus_pa", tissue.young_modulus_pa},
                           {"poisson_ratio", tissue.poisson_ratio}, {"density_kg_m3", tissue.density_kg_m3},
                           {"mooney_rivlin_c10_pa", (0.5 * m.mu_mpa - m.c01_mpa) * 1e6}, {"mooney_rivlin_c01_pa", m.c01_mpa * 1e6},
                           {"mooney_rivlin_d1_per_pa", 2.0 / (m.kappa_mpa * 1e6)}});
    }
    manifest["tissues_file"] = "ground_truth_tissues.yaml";
    const auto describe = [&](const GroundTruthModel& m) {
        const auto& q = m.quality;
        return json{{"nodes", m.mesh.node_count()}, {"elements", m.mesh.cell_count()}, {"support", m.support_description},
                    {"quality", {{"min_dihedral_deg", q.min_dihedral_deg}, {"max_dihedral_deg", q.max_dihedral_deg},
                                 {"cells_below_10_deg", q.below_10_deg}, {"min_radius_ratio", q.min_radius_ratio},
                                 {"mean_radius_ratio", q.mean_radius_ratio}, {"min_edge_mm", q.min_edge_mm},
                                 {"mean_edge_mm", q.mean_edge_mm}, {"max_edge_mm", q.max_edge_mm}}}};
    };
    const auto& gm = spec.ground_truth_mesh;
    std::vector<std::string> simulated;
    for (const auto& tissue : gt.tissues.tissues) simulated.push_back(p.roles.role_of(tissue.label));
    simulated.erase(std::unique(simulated.begin(), simulated.end()), simulated.end());
    manifest["ground_truth"] = {
        {"note", "a different model from every model physreg registers with (those: uniform one-point hexahedra, Neo-Hookean, "
                 "nu 0.49, liver only, literature moduli); registration commands never read this block"},
        {"simulated_tissues", simulated},
        {"tissues", tissues},
        {"material_ranges", gt.material_ranges},
        {"element", "linear tetrahedra (4 nodes, one Gauss point), conforming to every tissue interface, CGAL Mesh_3"},
        {"meshing", {{"organ_cell_mm", gm.organ_cell_mm}, {"kidney_cell_mm", gm.kidney_cell_mm}, {"body_cell_mm", gm.body_cell_mm},
                     {"facet_size_mm", gm.facet_mm}, {"facet_distance_mm", gm.facet_distance_mm}, {"seed", spec.seed}}},
        {"material_law", "compressible Mooney-Rivlin: C10 (I1bar - 3) + C01 (I2bar - 3) + (J - 1)^2 / D1"},
        {"contact", {{"tool", "rigid, frictionless; augmented Lagrangian on the smooth skin nodes, penetration tolerance " +
                                  fmt::format("{} mm", ground_truth_penetration_tolerance_mm)},
                     {"organs_gel", "tied (shared nodes): the phantom's organs are cast into the gel, which bonds to them"}}},
        {"solver", {{"method", "Newton (exact tangent by automatic differentiation, CHOLMOD), load steps with halving"},
                    {"residual_tolerance", ground_truth_residual_tolerance},
                    {"criterion", "largest free nodal residual / largest internal nodal force"},
                    {"load_step_mm", spec.load_step_mm}}},
        {"models", {{gt.body.name, describe(gt.body)}}},
        {"calculix_validation", calculix}};
    if (gt.organs) manifest["ground_truth"]["models"]["organs"] = describe(*gt.organs);
    manifest["landmarks"] = {{"count", rest_landmarks.size()},
                             {"surface", std::count_if(rest_landmarks.begin(), rest_landmarks.end(), [](const Landmark& l) { return l.type == LandmarkType::surface; })},
                             {"noise_sigma_mm", spec.landmark_noise_mm},
                             {"picking", "automatic from the rest labels (tips, ridges, notch; lesion poles; vessel bifurcations)"}};
    manifest["partial_surfaces"] = {{"percentages", spec.surface_percentages}, {"noise_sigma_mm", spec.surface_noise_mm},
                                    {"camera_view_direction", to_json(Vec3::UnitY())},
                                    {"labels", {{"0", "surface"}, {"1", "umbilical notch"}, {"2", "anterior margin"}}}};

    return manifest;
}

/// Every compression solved on the body model. `after_solve(index, state)` runs on the thread that
/// solved it, right after (the state's images: they then overlap the other solves instead of
/// waiting for the last one); `solved_one(count, name)` hears each one finish, one at a time.
std::vector<SolvedState> solve_compressions(const GroundTruth& gt, const PhantomSpec& spec, const Prepared& p, const std::vector<CompressionSpec>& compressions,
                                            const std::function<void(std::size_t, const SolvedState&)>& after_solve,
                                            const std::function<void(std::size_t, const std::string&)>& solved_one)
{
    // The compressions are independent: solved two at a time (each Newton solve is mostly a
    // single-threaded CHOLMOD factorisation and triangular solves, so two solves use the two cores
    // far better than one solve's threaded assembly). Each solve is deterministic, so the files do
    // not depend on the thread count.
    std::vector<SolvedState> solved_compressions(compressions.size());
    std::vector<std::exception_ptr> failures(compressions.size());
    const int solvers = std::max(1, std::min<int>(omp_get_max_threads(), static_cast<int>(compressions.size())));
    std::size_t finished = 0;
    // Deepest first (more load steps, more Newton iterations): the last solve to start is then a
    // short one and the two cores finish together (cirs057a: 600 s → ≈ 500 s for the five).
    std::vector<long> order(compressions.size());
    std::iota(order.begin(), order.end(), 0L);
    std::stable_sort(order.begin(), order.end(), [&](long a, long b) {
        return compressions[static_cast<std::size_t>(a)].depth_mm > compressions[static_cast<std::size_t>(b)].depth_mm;
    });
#pragma omp parallel for schedule(dynamic, 1) num_threads(solvers)
    for (long k = 0; k < static_cast<long>(compressions.size()); ++k) {
        const long c = order[static_cast<std::size_t>(k)];
        try {
            solved_compressions[static_cast<std::size_t>(c)] = solve_compression(gt.body, spec, p, compressions[static_cast<std::size_t>(c)]);
            after_solve(static_cast<std::size_t>(c), solved_compressions[static_cast<std::size_t>(c)]);
        } catch (...) {
            failures[static_cast<std::size_t>(c)] = std::current_exception();
        }
        // The bar moves as each compression is solved (it stood still for minutes before).
#pragma omp critical(phantom_progress)
        {
            ++finished;
            try { // an exception must not leave the critical section (or the loop's body)
                solved_one(finished, compressions[static_cast<std::size_t>(c)].name);
            } catch (...) {
                if (!failures[static_cast<std::size_t>(c)]) failures[static_cast<std::size_t>(c)] = std::current_exception();
            }
        }
    }
    for (const auto& failure : failures)
        if (failure) std::rethrow_exception(failure);
    return solved_compressions;
}

/// The manifest's segmentation pair: the rest labels against the insufflated ones, and which organs deform.
json insufflation_pairs(const Prepared& p, const GroundTruth& gt)
{
    std::vector<std::string> organs;
    for (const auto* set : {&p.roles.liver, &p.roles.kidney})
        for (const auto l : *set)
            if (gt.tissues.find(l)) organs.push_back(p.roles.role_of(l));
    organs.erase(std::unique(organs.begin(), organs.end()), organs.end());
    return json::array({{{"name", "insufflation"}, {"moving", "rest/labels.nii.gz"},
                                                   {"reference", "states/insufflation/labels.nii.gz"},
                                                   {"deforming_organs", organs},
                                                   {"note", "moving = pre-operative labels, reference = after the pressure load; each organ deforms with its own stiffness and support"}}});
}

} // namespace

DatasetReport generate_phantom_dataset(const PhantomSpec& spec, const fs::path& directory, bool replace,
                                       const std::function<void(double, const std::string&)>& progress)
{
    spec.validate();
    const auto clock0 = std::chrono::steady_clock::now();
    StagedDirectory staged(directory, replace);
    const fs::path root = staged.path();
    json timings = json::object();
    auto report = [&](double f, const std::string& m) {
        if (progress) progress(f, m);
    };

    report(0.0, "anatomy");
    Prepared p = prepare_labels(spec);
    // Each state's image: the noise-free image warped, then noise of its own (independent scans).
    const ScalarImage intensity = synthesize_clean_mr_intensity(p.labels, p.roles, mix_seed(spec.seed, "intensity"));
    Vec3 liver_lo, liver_hi;
    const Vec3 liver_centre = liver_centroid(p, liver_lo, liver_hi);
    timings["anatomy_s"] = seconds_since(clock0);

    report(0.01, "ground-truth mesh");
    auto t = std::chrono::steady_clock::now();
    GroundTruth gt = build_ground_truth(p, spec);
    const auto is_liver = [&](std::int32_t l) { return p.roles.is_liver_tissue(l); };
    timings["ground_truth_model_s"] = seconds_since(t);
    logger()->info("ground truth: {} model, {} nodes, {} tetrahedra (dihedral angles {:.1f}–{:.1f}°){}", gt.body.name, gt.body.mesh.node_count(),
                   gt.body.mesh.cell_count(), gt.body.quality.min_dihedral_deg, gt.body.quality.max_dihedral_deg,
                   gt.organs ? fmt::format("; organs alone {} tetrahedra", gt.organs->mesh.cell_count()) : std::string());

    report(0.07, "landmarks");
    t = std::chrono::steady_clock::now();
    const LandmarkSet rest_landmarks = pick_landmarks(p.labels, p.roles);
    const auto notch_x = find_margin_notch_x(p.labels, p.roles);
    // Per ground-truth model: where the landmarks sit, and the liver's labelled boundary.
    const auto view_of = [&](const GroundTruthModel& m) {
        return ModelView{&m, embed_landmarks(m.mesh, rest_landmarks, 1.5 * m.organ_cell_mm, "the ground-truth " + m.name + " mesh"), liver_boundary(m.mesh, is_liver, notch_x)};
    };
    const ModelView body_view = view_of(gt.body);
    const std::optional<ModelView> organ_view = gt.organs ? std::optional<ModelView>(view_of(*gt.organs)) : std::nullopt;
    const ModelView& insufflation_view = organ_view ? *organ_view : body_view;
    timings["landmarks_s"] = seconds_since(t);

    const json calculix = calculix_validation(spec, p, gt, root, report, timings);

    // The experiment's states.
    std::vector<CompressionSpec> compressions = spec.compressions;
    const auto& g = p.labels.geometry;
    const double image_length = g.spacing.cwiseProduct(Vec3(double(g.size[0]), double(g.size[1]), double(g.size[2]))).norm();
    if (compressions.empty()) compressions = default_compressions(p, spec, liver_lo, liver_hi, image_length, gt.body.name == "body");
    double parenchyma_e = 0.0;
    for (const auto& tissue : gt.tissues.tissues)
        if (p.roles.liver.count(tissue.label)) parenchyma_e = std::max(parenchyma_e, tissue.young_modulus_pa);
    const double pressure = spec.insufflation_pa.value_or(0.03 * parenchyma_e);

    write_tissue_table(root / "ground_truth_tissues.yaml", gt.tissues);
    json manifest = dataset_manifest(spec, p, gt, calculix, rest_landmarks);

    const StateWriter writer(root, spec, p, intensity, rest_landmarks, liver_centre);
    json states = json::array();
    // Progress weighted by measured cost (small preset, Release and ASan): preparation ≈ 10 %, the
    // compressions' Newton solves and their images ≈ 85 %, insufflation ≈ 5 %. During the solves
    // the load steps post their own notes (heartbeat lines every ≤ 30 s).
    constexpr double prepared = 0.10, written_all = 0.95;
    auto write_state = [&](const std::string& name, const std::string& kind, const SolvedState* solved, const ModelView& view) {
        states.push_back(writer.write(name, kind, solved, view, states.empty() ? prepared : written_all, report));
    };

    write_state("rest", "rest", nullptr, body_view);
    report(prepared + 0.01, fmt::format("solving {} compressions", compressions.size()));
    t = std::chrono::steady_clock::now();
    // Each compression's images are written by the thread that solved it, while the other thread
    // still solves (the writing took 80 s after the solves on cirs057a). The writer is const and
    // seeds each state's noise by its name, so the files do not depend on the order.
    std::vector<json> compression_states(compressions.size());
    std::vector<double> writing_s(compressions.size(), 0.0);
    double progress_now = prepared + 0.01;
    const auto report_in_turn = [&](double f, const std::string& m) {
        std::exception_ptr error; // (a Python callback's KeyboardInterrupt): never thrown out of the critical section
#pragma omp critical(phantom_progress)
        try {
            report(std::max(f, progress_now), m);
        } catch (...) {
            error = std::current_exception();
        }
        if (error) std::rethrow_exception(error);
    };
    const auto write_compression = [&](std::size_t k, const SolvedState& solved) {
        const auto start = std::chrono::steady_clock::now();
        double f0 = 0.0;
#pragma omp critical(phantom_progress)
        f0 = progress_now;
        compression_states[k] = writer.write(compressions[k].name, "compression", &solved, body_view, f0, report_in_turn);
        writing_s[k] = seconds_since(start);
    };
    const std::vector<SolvedState> solved_compressions = solve_compressions(gt, spec, p, compressions, write_compression,
                                                                            [&](std::size_t finished, const std::string& last) {
        progress_now = prepared + 0.01 + (written_all - prepared - 0.01) * double(finished) / double(compressions.size());
        report(progress_now, fmt::format("{} of {} compressions solved and written (last: {})", finished, compressions.size(), last));
    });
    timings["solve_and_write_compressions_s"] = seconds_since(t);
    for (std::size_t k = 0; k < compressions.size(); ++k) {
        const auto& c = compressions[k];
        const SolvedState& solved = solved_compressions[k];
        timings["solve_" + c.name + "_s"] = solved.solve.seconds;
        timings["state_" + c.name + "_s"] = writing_s[k];
        logger()->info("compression {}: depth {} mm on the {}, {} load steps, {} Newton iterations, {:.1f} s, max displacement {:.2f} mm; "
                       "images {:.1f} s", c.name, c.depth_mm, gt.body.name == "body" ? "skin" : "organ", solved.solve.load_steps,
                       solved.solve.newton_iterations, solved.solve.seconds, solved.solve.max_displacement_mm, writing_s[k]);
        states.push_back(compression_states[k]);
    }
    if (pressure > 0) {
        report(written_all, "insufflation: solving");
        t = std::chrono::steady_clock::now();
        const SolvedState solved = solve_insufflation(gt, pressure);
        timings["solve_insufflation_s"] = solved.solve.seconds;
        logger()->info("insufflation: {:.0f} Pa on the {} model, {} Newton iterations, {:.1f} s, max displacement {:.2f} mm", pressure,
                       gt.insufflation_model().name, solved.solve.newton_iterations, solved.solve.seconds, solved.solve.max_displacement_mm);
        write_state("insufflation", "insufflation", &solved, insufflation_view);
        timings["state_insufflation_s"] = seconds_since(t);
        manifest["segmentation_pairs"] = insufflation_pairs(p, gt);
    } else {
        manifest["segmentation_pairs"] = json::array();
    }
    if (spec.push_depth_mm > 0) {
        report(0.97, "large local push: solving");
        t = std::chrono::steady_clock::now();
        const CompressionSpec c = push_compression(p, spec, liver_lo, liver_hi, image_length);
        const SolvedState solved = solve_compression(gt.insufflation_model(), spec, p, c);
        timings["solve_push_s"] = solved.solve.seconds;
        logger()->info("push: {} mm by a {:.0f} mm tool on the {} model, {} Newton iterations, {:.1f} s, max displacement {:.2f} mm", c.depth_mm,
                       2 * solved.tool->radius_mm, gt.insufflation_model().name, solved.solve.newton_iterations, solved.solve.seconds,
                       solved.solve.max_displacement_mm);
        write_state("push", "push", &solved, insufflation_view);
        timings["state_push_s"] = seconds_since(t);
    }
    manifest["states"] = states;
    write_text(root / "manifest.json", manifest.dump(2) + "\n");
    report(1.0, "done");
    staged.commit();
    json summary = manifest;
    summary["output"] = directory.string();
    timings["total_s"] = seconds_since(clock0);
    summary["timings"] = timings;
    return {summary.dump(2)};
}

} // namespace physreg
