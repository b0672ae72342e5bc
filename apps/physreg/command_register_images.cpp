// SPDX-License-Identifier: GPL-3.0-or-later
// physreg register-images: paper 002 — a moving image registered to a fixed (reference) image by a
// linear-elastic simulation whose boundary load and Young's moduli are estimated from the two
// segmentations, with ITK's rigid, Demons and B-spline registrations (on intensities and on
// labels) in the same report.
#include "cli_support.hpp"
#include "progress.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/evaluation/segmentation_overlap.hpp"
#include "physreg/evaluation/tre.hpp"
#include "physreg/field/field_mapping.hpp"
#include "physreg/field/image_warping.hpp"
#include "physreg/image/distance_map.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/mesh/tetrahedral_meshing.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/registration/images/image_baselines.hpp"
#include "physreg/registration/images/segmentation_alignment.hpp"
#include "physreg/registration/images/segmentation_registration.hpp"
#include "physreg/registration/surface/surface_model.hpp"

#include <chrono>
#include <fstream>
#include <functional>
#include <iostream>

namespace physreg::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct Options : CommonOptions {
    std::string dataset, state = "insufflation", fixed, fixed_labels, moving, moving_labels, landmarks_fixed, landmarks_moving, tissues, output;
    std::string structures, method = "biomechanical", hold = "auto", hold_labels, parametrisation = "surface-displacement", baselines = "all";
    std::string initial = "rigid";
    double cell_size = 6.0, facet_distance = 0.75, margin = 15.0, anchor = 0.0, tolerance = 1e-3, bspline_grid = 50.0, demons_sigma = 1.5;
    int iterations = 5, cycles = 40;
    bool no_moduli = false, replace = false, symmetric = false;
    double moduli_prior = 0.0, moduli_prior_rms = 0.1;
    bool rest_offsets = true;
    std::string law = "linear";
    bool no_factor_reuse = false;
    double rms_tolerance = 0.001;
    double initial_min_reduction = 0.5; ///< the fraction of the boundary RMS distance the alignment must remove
    unsigned seed = 1;
};

struct Inputs {
    ScalarImage fixed, moving;
    LabelVolume fixed_labels, moving_labels;
    std::optional<LandmarkSet> landmarks_fixed, landmarks_moving;
    std::vector<std::int32_t> structures;
    TissueTable tissues;
    std::string hold;
    json description;
};

std::vector<std::int32_t> parse_labels(const std::string& text, const std::string& option)
{
    std::vector<std::int32_t> out;
    for (double v : parse_number_list(text, option)) {
        if (v != std::floor(v) || v <= 0 || v > 65535) fail("{}: '{}' is not a label (1 … 65535)", option, v);
        out.push_back(static_cast<std::int32_t>(v));
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

Inputs load_inputs(const Options& o)
{
    Inputs in;
    const bool files = !o.fixed.empty() || !o.fixed_labels.empty() || !o.moving.empty() || !o.moving_labels.empty();
    if (o.dataset.empty() == !files || (files && (o.fixed.empty() || o.fixed_labels.empty() || o.moving.empty() || o.moving_labels.empty())))
        fail("register-images: give --dataset DIR, or all four of --fixed, --fixed-labels, --moving and --moving-labels");
    if (!o.dataset.empty()) {
        if (!o.landmarks_fixed.empty() || !o.landmarks_moving.empty()) fail("register-images: --dataset provides the landmarks; leave out --landmarks-fixed/--landmarks-moving");
        const PhantomDataset dataset = read_phantom_dataset(o.dataset);
        const DatasetState& rest = dataset.state("rest");
        const DatasetState& state = dataset.state(o.state);
        if (state.kind == "rest") fail("register-images: --state {} is the rest state; choose a deformed one", o.state);
        in.moving = read_scalar_image(dataset.path(rest.files.at("intensity")));
        in.moving_labels = read_label_volume(dataset.path(rest.files.at("labels")));
        in.fixed = read_scalar_image(dataset.path(state.files.at("intensity")));
        in.fixed_labels = read_label_volume(dataset.path(state.files.at("labels")));
        in.landmarks_moving = read_landmarks(dataset.path(rest.files.at("landmarks")));
        in.landmarks_fixed = read_landmarks(dataset.path(state.files.at("landmarks")));
        std::set<std::int32_t> organs;
        for (const auto* role : {&dataset.roles.liver, &dataset.roles.lesion, &dataset.roles.vessel, &dataset.roles.kidney}) organs.insert(role->begin(), role->end());
        in.structures.assign(organs.begin(), organs.end());
        // Initial moduli: the literature values of the dataset's material set (the truth's moduli
        // are drawn around them and never read).
        std::ifstream manifest_file(fs::path(o.dataset) / "manifest.json");
        const json manifest = json::parse(manifest_file);
        const MaterialSet set = parse_material_set(manifest.value("material_set", std::string("paper000")));
        std::set<std::int32_t> present;
        for (const auto& [label, n] : count_labels(in.moving_labels)) present.insert(label);
        in.tissues = phantom_tissue_table(set, dataset.roles, present);
        in.hold = o.hold == "auto" ? "posterior" : o.hold;
        in.description = {{"dataset", o.dataset}, {"state", o.state}, {"moving", rest.files.at("intensity")}, {"fixed", state.files.at("intensity")},
                          {"initial_moduli", "literature values of material set " + to_string(set)}};
    } else {
        in.fixed = read_scalar_image(o.fixed);
        in.fixed_labels = read_label_volume(o.fixed_labels);
        in.moving = read_scalar_image(o.moving);
        in.moving_labels = read_label_volume(o.moving_labels);
        if (o.landmarks_fixed.empty() != o.landmarks_moving.empty()) fail("register-images: give both --landmarks-fixed and --landmarks-moving, or neither");
        if (!o.landmarks_fixed.empty()) {
            in.landmarks_fixed = read_landmarks(o.landmarks_fixed);
            in.landmarks_moving = read_landmarks(o.landmarks_moving);
        }
        in.hold = o.hold == "auto" ? "none" : o.hold;
        in.description = {{"fixed", o.fixed}, {"fixed_labels", o.fixed_labels}, {"moving", o.moving}, {"moving_labels", o.moving_labels}};
    }
    const auto same = [](const ImageGeometry& a, const ImageGeometry& b) { return a.size == b.size && (a.origin - b.origin).norm() < 1e-6 && (a.spacing - b.spacing).norm() < 1e-9; };
    if (!same(in.fixed.geometry, in.fixed_labels.geometry)) fail("register-images: the fixed image and --fixed-labels are on different grids");
    if (!same(in.moving.geometry, in.moving_labels.geometry)) fail("register-images: the moving image and --moving-labels are on different grids");
    // Structures: given, or every label of the moving segmentation; each must be in both.
    std::map<std::int32_t, std::int64_t> fixed_count = count_labels(in.fixed_labels), moving_count = count_labels(in.moving_labels);
    if (!o.structures.empty()) in.structures = parse_labels(o.structures, "--structures");
    if (in.structures.empty())
        for (const auto& [label, n] : moving_count)
            if (label != 0) in.structures.push_back(label);
    if (in.structures.empty()) fail("register-images: the moving segmentation '{}' has no structure (every voxel is 0)", o.moving_labels.empty() ? o.dataset : o.moving_labels);
    for (auto label : in.structures) {
        const bool in_moving = moving_count.count(label) && moving_count[label] > 0, in_fixed = fixed_count.count(label) && fixed_count[label] > 0;
        if (!in_moving && !in_fixed) fail("register-images: structure {} is empty in both segmentations", label);
        if (!in_moving) fail("register-images: structure {} is in the fixed segmentation only (the moving labels have none)", label);
        if (!in_fixed) fail("register-images: structure {} is in the moving segmentation only (the fixed labels have none)", label);
    }
    if (o.structures.empty())
        for (const auto& [label, n] : fixed_count)
            if (label != 0 && !std::count(in.structures.begin(), in.structures.end(), label) && o.dataset.empty())
                fail("register-images: label {} is in the fixed segmentation only; the organ sets differ (choose with --structures)", label);
    if (!o.tissues.empty()) in.tissues = read_tissue_table(o.tissues);
    if (!o.tissues.empty() || !o.dataset.empty()) in.tissues.validate(o.tissues.empty() ? "the dataset's tissues" : o.tissues);
    if (o.tissues.empty() && o.dataset.empty()) {
        // No table: one soft-tissue modulus for every structure (3 kPa, ν 0.45; only ratios are estimated).
        for (auto label : in.structures) in.tissues.tissues.push_back({label, "label " + std::to_string(label), 3000.0, 0.45, 1000.0, 0.0});
    }
    for (auto label : in.structures)
        if (!in.tissues.find(label)) fail("register-images: structure {} has no tissue in {}", label, o.tissues.empty() ? "the dataset's table" : o.tissues);
    return in;
}

/// The fixed grid cropped to the structures of both segmentations plus `margin_mm`.
/// A fixed → aligned-moving field d_a composed with T⁻¹: y ↦ T⁻¹(y + d_a(y)) − y.
DisplacementField compose_with_alignment(DisplacementField field, const SegmentationAlignment& a)
{
    const auto& g = field.geometry;
    std::size_t v = 0;
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i, ++v) {
                const Vec3 y = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                const Vec3 d(field.components[3 * v], field.components[3 * v + 1], field.components[3 * v + 2]);
                const Vec3 x = a.rotation.transpose() * (y + d - a.translation) - y;
                for (int c = 0; c < 3; ++c) field.components[3 * v + static_cast<std::size_t>(c)] = static_cast<float>(x[c]);
            }
    return field;
}

/// d(y) = T⁻¹(y) − y on `geometry`: the fixed → moving map of the rigid part alone.
DisplacementField rigid_inverse_field(const SegmentationAlignment& a, const ImageGeometry& geometry)
{
    DisplacementField f = zero_field(geometry);
    return compose_with_alignment(f, a);
}

/// The moving side seen through the initial alignment T (x_fixed = T x_moving): image and labels
/// resampled onto the fixed grid at T⁻¹(y), landmarks moved by T. Everything after it runs in the
/// fixed frame and explains only the non-rigid rest.
Inputs aligned_inputs(const Inputs& in, const SegmentationAlignment& a)
{
    Inputs out = in;
    const DisplacementField to_moving = rigid_inverse_field(a, in.fixed.geometry);
    out.moving = resample_image(in.moving, to_moving, 0.0f);
    out.moving_labels = resample_labels(in.moving_labels, to_moving);
    if (in.landmarks_moving)
        for (auto& l : *out.landmarks_moving) l.position = a.apply(l.position);
    return out;
}

ImageGeometry region_of_interest(const Inputs& in, double margin_mm)
{
    const ImageGeometry& g = in.fixed.geometry;
    Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
    for (const LabelVolume* v : {&in.fixed_labels, &in.moving_labels})
        for (std::int64_t k = 0; k < v->geometry.size[2]; ++k)
            for (std::int64_t j = 0; j < v->geometry.size[1]; ++j)
                for (std::int64_t i = 0; i < v->geometry.size[0]; ++i)
                    if (std::count(in.structures.begin(), in.structures.end(), v->at(i, j, k))) {
                        const Vec3 index = g.physical_to_index(v->geometry.index_to_physical(Vec3(i, j, k)));
                        lo = lo.cwiseMin(index);
                        hi = hi.cwiseMax(index);
                    }
    ImageGeometry roi = g;
    Index3 first;
    for (int a = 0; a < 3; ++a) {
        const double m = margin_mm / g.spacing[a];
        first[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>(std::floor(lo[a] - m)), 0, g.size[a] - 1);
        const std::int64_t last = std::clamp<std::int64_t>(static_cast<std::int64_t>(std::ceil(hi[a] + m)), 0, g.size[a] - 1);
        if (last < first[a]) fail("register-images: the structures lie outside the fixed image (no overlap of the two images)");
        roi.size[a] = last - first[a] + 1;
    }
    roi.origin = g.index_to_physical(Vec3(first[0], first[1], first[2]));
    return roi;
}

template <typename Image, typename Value>
Image crop(const Image& in, const ImageGeometry& roi, const std::vector<Value>& values)
{
    Image out;
    out.geometry = roi;
    const Vec3 offset = in.geometry.physical_to_index(roi.origin);
    const Index3 o{static_cast<std::int64_t>(std::llround(offset[0])), static_cast<std::int64_t>(std::llround(offset[1])), static_cast<std::int64_t>(std::llround(offset[2]))};
    std::vector<Value> v(static_cast<std::size_t>(roi.voxel_count()));
    for (std::int64_t k = 0; k < roi.size[2]; ++k)
        for (std::int64_t j = 0; j < roi.size[1]; ++j)
            for (std::int64_t i = 0; i < roi.size[0]; ++i)
                v[static_cast<std::size_t>(roi.linear_index(i, j, k))] = values[static_cast<std::size_t>(in.geometry.linear_index(i + o[0], j + o[1], k + o[2]))];
    if constexpr (std::is_same_v<Image, LabelVolume>)
        out.labels = std::move(v);
    else
        out.values = std::move(v);
    return out;
}

struct MethodOutcome {
    std::string name;
    DisplacementField field;   ///< fixed → moving on the ROI
    std::optional<LandmarkSet> landmarks;
    double seconds = 0.0;
    json details;
    LabelVolume warped_labels;
};

json tre_json(const TreReport& report)
{
    // The median over exactly the landmarks the group's statistics count (compute_tre's grouping:
    // internal = tumour and vessel; untyped landmarks count in "all" only). An empty group has no
    // median: null, never a number copied from another group.
    const auto group = [&](const TreStats& s, const std::function<bool(LandmarkType)>& member) {
        std::vector<double> e;
        for (const auto& entry : report.entries)
            if (member(entry.type)) e.push_back(entry.error_mm);
        if (e.size() != s.count) fail("TRE summary: {} landmarks in a group whose statistics count {}", e.size(), s.count);
        std::sort(e.begin(), e.end());
        json median = nullptr;
        if (!e.empty()) median = e.size() % 2 ? e[e.size() / 2] : 0.5 * (e[e.size() / 2 - 1] + e[e.size() / 2]);
        return json{{"count", s.count}, {"mean_mm", s.mean_mm}, {"median_mm", median}, {"max_mm", s.max_mm}, {"std_mm", s.std_mm}};
    };
    json per = json::object();
    for (const auto& e : report.entries) per[e.name] = e.error_mm;
    return {{"all", group(report.all, [](LandmarkType) { return true; })},
            {"surface", group(report.surface, [](LandmarkType t) { return t == LandmarkType::surface; })},
            {"internal", group(report.internal, [](LandmarkType t) { return t == LandmarkType::tumour || t == LandmarkType::vessel; })},
            {"per_landmark_mm", per}};
}

void add_subcommand_register_images_impl(CLI::App& app)
{
    auto o = std::make_shared<Options>();
    auto* cmd = app.add_subcommand("register-images",
                                   "Paper 002: register a moving image to a fixed one with a linear-elastic simulation whose boundary load and "
                                   "per-structure Young's moduli are estimated from the segmentations; rigid, Demons and B-spline baselines");
    cmd->add_option("--dataset", o->dataset, "a phantom dataset: its rest → state segmentation pair, images and landmarks");
    cmd->add_option("--state", o->state, "the dataset's deformed state (the fixed image)")->capture_default_str();
    cmd->add_option("--fixed", o->fixed, "the fixed (reference, e.g. intra-operative) image");
    cmd->add_option("--fixed-labels", o->fixed_labels, "its segmentation");
    cmd->add_option("--moving", o->moving, "the moving (pre-operative) image");
    cmd->add_option("--moving-labels", o->moving_labels, "its segmentation (meshed)");
    cmd->add_option("--landmarks-fixed", o->landmarks_fixed, "landmarks in the fixed image (CSV/FCSV/.mrk.json; TRE)");
    cmd->add_option("--landmarks-moving", o->landmarks_moving, "the same landmarks in the moving image");
    cmd->add_option("--structures", o->structures, "labels to mesh and match, e.g. 2,3,4,6 (default: every label of the moving segmentation)");
    cmd->add_option("--tissues", o->tissues, "tissue table (YAML/JSON): initial E (Pa) and ν per label (default: 3 kPa, ν 0.45)");
    cmd->add_option("--method", o->method, "the method whose result is written: biomechanical, rigid, demons or bspline")->capture_default_str();
    cmd->add_option("--initial", o->initial, "initial alignment of the segmentations before every method: identity, centroid or rigid "
                                             "(centroids, then rigid on the fixed structures' distance maps)")->capture_default_str();
    cmd->add_option("--initial-min-reduction", o->initial_min_reduction, "apply the initial alignment only when it removes more than this "
                                                                         "fraction of the structures' boundary RMS distance (0: always)")->capture_default_str();
    cmd->add_option("--baselines", o->baselines, "baselines in the report: all, intensity, labels or none")->capture_default_str();
    cmd->add_option("--hold", o->hold, "Dirichlet support: posterior (surface nodes facing +y), none, or auto (posterior for datasets, else none)")->capture_default_str();
    cmd->add_option("--hold-labels", o->hold_labels, "labels (meshed with the structures) whose nodes are held, e.g. bone");
    cmd->add_option("--anchor", o->anchor, "regularising spring to rest at every node, N/mm (0: none)")->capture_default_str();
    cmd->add_option("--parametrisation", o->parametrisation, "boundary unknowns: surface-displacement or nodal-forces (paper 002)")->capture_default_str();
    cmd->add_option("--iterations", o->iterations, "L-BFGS iterations per phase of the alternation (paper: 5)")->capture_default_str();
    cmd->add_option("--cycles", o->cycles, "most alternation cycles")->capture_default_str();
    cmd->add_option("--tolerance", o->tolerance, "stop when a cycle lowers the objective by less than this fraction")->capture_default_str();
    cmd->add_option("--rms-tolerance", o->rms_tolerance, "also stop when a cycle lowers the rms boundary distance by less than this, mm (0: off; before "
                                                         "2026-11-27 the runs went on to --cycles)")
        ->capture_default_str();
    cmd->add_flag("--no-moduli", o->no_moduli, "keep the moduli at their initial values (boundary load only)");
    cmd->add_option("--moduli-prior", o->moduli_prior, "log-normal prior on the estimated moduli around the tissue table's: the factor one standard "
                                                       "deviation away (e.g. 2), 0 for free ratios")->capture_default_str();
    cmd->add_option("--moduli-prior-rms", o->moduli_prior_rms, "the prior's weight: one standard deviation costs as much as this rms boundary "
                                                               "distance over every objective term, mm")->capture_default_str();
    cmd->add_option("--law", o->law, "the registering model's law: linear (small strain, paper 002) or corotational (large rotations: the "
                                     "element rotations refreshed every cycle)")->capture_default_str();
    cmd->add_flag("--no-factor-reuse", o->no_factor_reuse, "factorise K for every set of moduli instead of solving by CG preconditioned by an "
                                                            "earlier factor (the same result to 1e-10; for benchmarks)");
    cmd->add_flag("--rest-offsets,!--no-rest-offsets", o->rest_offsets, "each model boundary node keeps its rest distance to the moving segmentation's "
                                                      "boundary (the mesh is not the voxel boundary) instead of landing exactly on the fixed one (default; "
                                                      "--no-rest-offsets: paper 002's objective)")->capture_default_str();
    cmd->add_flag("--symmetric", o->symmetric, "symmetric objective: also pull the model toward the fixed structures' boundary points "
                                                "that no model node reaches (fixed → model distances as well as model → fixed)");
    cmd->add_option("--cell-size", o->cell_size, "largest tetrahedron circumradius, mm")->capture_default_str();
    cmd->add_option("--facet-distance", o->facet_distance, "largest distance of a mesh facet to the label interface, mm")->capture_default_str();
    cmd->add_option("--margin", o->margin, "the registration region: the structures' bounding box plus this margin, mm")->capture_default_str();
    cmd->add_option("--bspline-grid", o->bspline_grid, "B-spline control spacing at the coarsest level, mm (halved twice)")->capture_default_str();
    cmd->add_option("--demons-sigma", o->demons_sigma, "Demons field smoothing σ, voxels")->capture_default_str();
    cmd->add_option("--seed", o->seed, "meshing and metric-sampling seed")->capture_default_str();
    cmd->add_option("-o,--output", o->output, "output folder (staged: appears only when complete)")->required();
    cmd->add_flag("--force,--replace", o->replace, "replace an existing output folder (only once the new one is complete; --replace: the older name)");
    cmd->add_flag("--json", o->json, "print the summary as JSON on stdout");
    cmd->callback([o] {
        const auto start = std::chrono::steady_clock::now();
        for (const auto& [name, value] : {std::pair{"--cell-size", o->cell_size}, {"--facet-distance", o->facet_distance}, {"--bspline-grid", o->bspline_grid}, {"--demons-sigma", o->demons_sigma}})
            if (!(value > 0.0) || !std::isfinite(value)) fail("{} {} must be positive", name, value);
        if (!(o->margin >= 0.0)) fail("--margin {} must be ≥ 0", o->margin);
        if (!(o->anchor >= 0.0) || !std::isfinite(o->anchor)) fail("--anchor {} N/mm must be ≥ 0", o->anchor);
        if (!(o->initial_min_reduction >= 0.0 && o->initial_min_reduction <= 1.0))
            fail("--initial-min-reduction {} must lie in [0, 1] (a fraction of the boundary RMS distance)", o->initial_min_reduction);
        if (o->method != "biomechanical" && o->method != "rigid" && o->method != "demons" && o->method != "bspline")
            fail("--method '{}': use biomechanical, rigid, demons or bspline", o->method);
        if (o->baselines != "all" && o->baselines != "intensity" && o->baselines != "labels" && o->baselines != "none")
            fail("--baselines '{}': use all, intensity, labels or none", o->baselines);
        if (o->method != "biomechanical" && o->baselines == "none") fail("--method {} needs the baselines (--baselines is none)", o->method);
        SegmentationRegistrationOptions reg;
        reg.parametrisation = parse_boundary_parametrisation(o->parametrisation);
        reg.alternation_iterations = o->iterations;
        reg.max_cycles = o->cycles;
        reg.relative_tolerance = o->tolerance;
        if (!(o->rms_tolerance >= 0.0) || !std::isfinite(o->rms_tolerance)) fail("--rms-tolerance {} mm must be ≥ 0 (0: off)", o->rms_tolerance);
        reg.rms_tolerance_mm = o->rms_tolerance;
        reg.estimate_moduli = !o->no_moduli;
        reg.moduli_prior_factor = o->moduli_prior;
        reg.moduli_prior_rms_mm = o->moduli_prior_rms;
        if (o->law != "linear" && o->law != "corotational") fail("--law '{}': use linear or corotational", o->law);
        reg.corotational = o->law == "corotational";
        reg.reuse_factor = !o->no_factor_reuse;
        if (o->no_moduli && o->moduli_prior != 0.0) fail("--moduli-prior {} needs estimated moduli (--no-moduli is given)", o->moduli_prior);
        try {
            reg.validate();
        } catch (const Error& e) {
            fail("--moduli-prior {} / --moduli-prior-rms {} mm: {}", o->moduli_prior, o->moduli_prior_rms, e.what());
        }
        check_output_path(o->output, "--output");
        StagedDirectory staging(o->output, o->replace);
        ProgressDisplay bar("register-images");
        bar.update(0.0, "inputs");
        const Inputs original = load_inputs(*o);
        const InitialAlignment initial_mode = parse_initial_alignment(o->initial);
        bar.update(0.01, "initial alignment");
        const SegmentationAlignment alignment = align_segmentations(original.fixed_labels, original.moving_labels, original.structures, initial_mode);
        if (initial_mode != InitialAlignment::identity)
            logger()->info("register-images: initial alignment ({}, start {}): rotation {:.2f}°, translation ({:.1f}, {:.1f}, {:.1f}) mm; structures' "
                           "boundary RMS distance {:.2f} → {:.2f} mm", o->initial, alignment.start, alignment.rotation_deg, alignment.translation[0],
                           alignment.translation[1], alignment.translation[2], alignment.rms_boundary_distance_before_mm, alignment.rms_boundary_distance_mm);
        // Frames that already agree (a dataset's states, two scans of one session) keep them: a rigid
        // fit of deformed organs would move the held support with it (on the phantom pair: 2.3°, and
        // the biomechanical TRE 0.62 instead of 0.33 mm). A pair whose frames differ has most of its
        // boundary distance removed by the rigid motion (the 9 unaligned pairs: 82–99 %), a pair that
        // shares one frame little of it (the phantom pairs: 30 % and 6 %): the rest is deformation.
        const double before = alignment.rms_boundary_distance_before_mm;
        const double gain = before - alignment.rms_boundary_distance_mm;
        const bool aligned = initial_mode != InitialAlignment::identity && gain > o->initial_min_reduction * before;
        const std::string decision =
            initial_mode == InitialAlignment::identity ? "identity asked (--initial identity)"
            : aligned ? fmt::format("applied: it removes {:.0f} % of the boundary RMS distance ({:.2f} → {:.2f} mm)", 100 * gain / before, before,
                                    alignment.rms_boundary_distance_mm)
                      : fmt::format("not applied: it removes only {:.0f} % of the boundary RMS distance ({:.2f} → {:.2f} mm; --initial-min-reduction "
                                    "{}): the frames already agree, the rest is deformation", 100 * gain / std::max(before, 1e-12), before,
                                    alignment.rms_boundary_distance_mm, o->initial_min_reduction);
        if (initial_mode != InitialAlignment::identity) logger()->info("register-images: initial alignment {}", decision);
        const Inputs in = aligned ? aligned_inputs(original, alignment) : original;
        if (!aligned) {
            // Frames that do not overlap at all: no method here can relate them (there is no initial
            // alignment yet), so say so before any work instead of returning an unrelated result.
            const auto [flo, fhi] = in.fixed.geometry.physical_box();
            const auto [mlo, mhi] = in.moving.geometry.physical_box();
            if ((flo.array() > mhi.array()).any() || (mlo.array() > fhi.array()).any())
                fail("register-images: the fixed and moving images do not overlap in physical space (fixed [{:.1f} {:.1f} {:.1f}]–[{:.1f} {:.1f} {:.1f}] "
                     "mm, moving [{:.1f} {:.1f} {:.1f}]–[{:.1f} {:.1f} {:.1f}] mm); bring them into one frame first or use --initial centroid|rigid",
                     flo[0], flo[1], flo[2], fhi[0], fhi[1], fhi[2], mlo[0], mlo[1], mlo[2], mhi[0], mhi[1], mhi[2]);
        }
        const ImageGeometry roi = region_of_interest(in, o->margin);
        const ScalarImage fixed = crop<ScalarImage>(in.fixed, roi, in.fixed.values);
        const LabelVolume fixed_labels = crop<LabelVolume>(in.fixed_labels, roi, in.fixed_labels.labels);
        logger()->info("register-images: structures {}, region {}×{}×{} voxels", fmt::join(in.structures, ","), roi.size[0], roi.size[1], roi.size[2]);

        // The model: conforming tetrahedra of the moving structures (and held labels).
        bar.update(0.02, "meshing");
        const auto t_mesh = std::chrono::steady_clock::now();
        std::vector<std::int32_t> held_labels = o->hold_labels.empty() ? std::vector<std::int32_t>{} : parse_labels(o->hold_labels, "--hold-labels");
        TetMeshingOptions meshing;
        meshing.labels.insert(in.structures.begin(), in.structures.end());
        meshing.labels.insert(held_labels.begin(), held_labels.end());
        meshing.default_cell_size_mm = o->cell_size;
        meshing.facet_size_mm = o->cell_size;
        meshing.facet_distance_mm = o->facet_distance;
        meshing.seed = o->seed;
        meshing.seed_every_component = true; // every organ piece must be meshed, or its Dice collapses
        const VolumeMesh mesh = mesh_labels_tetrahedral(in.moving_labels, meshing, "the moving segmentation");
        const TetrahedronQuality quality = measure_tetrahedra(mesh);
        const double mesh_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_mesh).count();
        LinearElasticOptions elastic;
        for (const auto& t : in.tissues.tissues) elastic.poisson_ratio[t.label] = t.poisson_ratio;
        elastic.anchor_stiffness_n_mm = o->anchor;
        std::vector<std::uint8_t> fixed_node(mesh.node_count(), 0);
        for (std::size_t c = 0; c < mesh.cell_count(); ++c)
            if (std::count(held_labels.begin(), held_labels.end(), mesh.cell_labels[c]))
                for (auto n : mesh.cell(c)) fixed_node[static_cast<std::size_t>(n)] = 1;
        if (in.hold == "posterior") {
            for (auto n : surface_nodes_facing(mesh, unlabelled_boundary(mesh), Vec3::UnitY(), 0.5)) fixed_node[static_cast<std::size_t>(n)] = 1;
        } else if (in.hold != "none") {
            fail("--hold '{}': use posterior, none or auto", in.hold);
        }
        for (std::size_t n = 0; n < fixed_node.size(); ++n)
            if (fixed_node[n]) elastic.fixed_nodes.push_back(static_cast<std::int32_t>(n));
        std::vector<std::int32_t> force_nodes;
        for (auto n : outer_boundary_nodes(mesh))
            if (!fixed_node[static_cast<std::size_t>(n)]) force_nodes.push_back(n);
        // Structures of the model (sorted labels), their maps and initial moduli; held labels
        // take part in the mechanics but not in the objective.
        std::vector<std::int32_t> model_labels(meshing.labels.begin(), meshing.labels.end());
        std::vector<std::unique_ptr<SignedDistanceMap>> maps;
        std::vector<const SignedDistanceMap*> map_of;
        std::vector<double> initial_e;
        for (auto label : model_labels) {
            const bool structure = std::count(in.structures.begin(), in.structures.end(), label) > 0;
            maps.push_back(structure ? std::make_unique<SignedDistanceMap>(fixed_labels, std::set<std::int32_t>{label}, "fixed label " + std::to_string(label)) : nullptr);
            map_of.push_back(maps.back().get());
            const Tissue* t = in.tissues.find(label);
            if (!t) fail("register-images: held label {} has no tissue (give --tissues)", label);
            initial_e.push_back(t->young_modulus_pa);
        }
        // A structure the mesher lost (thinner than the cells) would shift the order: refuse.
        {
            std::set<std::int32_t> meshed(mesh.cell_labels.begin(), mesh.cell_labels.end());
            for (auto label : model_labels)
                if (!meshed.count(label)) fail("register-images: structure {} got no tetrahedron (thinner than --cell-size {} mm?)", label, o->cell_size);
        }
        SegmentationObjective objective(mesh, model_labels, map_of, "the fixed segmentation");
        if (o->symmetric) objective.add_reverse_term();
        std::vector<std::unique_ptr<SignedDistanceMap>> moving_maps;
        if (o->rest_offsets) {
            std::vector<const SignedDistanceMap*> moving_of;
            for (std::size_t j = 0; j < model_labels.size(); ++j) {
                moving_maps.push_back(map_of[j] ? std::make_unique<SignedDistanceMap>(in.moving_labels, std::set<std::int32_t>{model_labels[j]},
                                                                                      "moving label " + std::to_string(model_labels[j]))
                                                : nullptr);
                moving_of.push_back(moving_maps.back().get());
            }
            objective.set_rest_offsets(moving_of);
            const auto [mean, most] = objective.rest_offset_stats_mm();
            logger()->info("register-images: rest offsets of the boundary nodes to the moving segmentation: mean {:.3f} mm, max {:.3f} mm", mean, most);
        }
        logger()->info("register-images: {} tetrahedra, {} nodes, {} held, {} loaded surface nodes, {} objective terms", mesh.cell_count(), mesh.node_count(),
                       elastic.fixed_nodes.size(), force_nodes.size(), objective.term_count());

        std::vector<MethodOutcome> outcomes;
        outcomes.push_back({"at_rest", zero_field(roi), std::nullopt, 0.0, json::object(), {}});
        bar.update(0.05, "biomechanical registration");
        const SegmentationRegistrationResult b = register_segmentation(mesh, elastic, objective, force_nodes, initial_e, reg, [&](double f, const std::string& m) {
            bar.update(0.05 + 0.45 * f, m);
        });
        if (b.inverted_elements > 0)
            logger()->warn("register-images: {} of {} tetrahedra are inverted in the biomechanical result (summary.json: model.inverted_elements); "
                           "the dense field is still written", b.inverted_elements, mesh.cell_count());
        const std::vector<double> u(b.displacement_mm.data(), b.displacement_mm.data() + b.displacement_mm.size());
        {
            const auto t0 = std::chrono::steady_clock::now();
            const InverseMap inverse = rasterize_inverse_map(mesh, u, roi, 2.0 * o->cell_size);
            MethodOutcome m{"biomechanical", inverse.field, std::nullopt, b.seconds, json::object(), {}};
            m.warped_labels = resample_labels(in.moving_labels, m.field);
            // Voxels the deformed structures left (not covered by the deformed mesh) are background.
            for (std::size_t v = 0; v < m.warped_labels.labels.size(); ++v)
                if (!inverse.coverage[v] && std::count(model_labels.begin(), model_labels.end(), m.warped_labels.labels[v])) m.warped_labels.labels[v] = 0;
            if (in.landmarks_moving) {
                const auto where = embed_landmarks(mesh, *in.landmarks_moving, 1.5 * o->cell_size, "the moving structures' mesh (landmarks)");
                m.landmarks = displace_landmarks(mesh, where, *in.landmarks_moving, u);
            }
            json history = json::array();
            for (const auto& h : b.history) {
                json e;
                for (std::size_t j = 0; j < model_labels.size(); ++j) e[std::to_string(model_labels[j])] = h.young_moduli_pa[j];
                history.push_back({{"cycle", h.cycle}, {"objective_mm2", h.objective_mm2}, {"prior_mm2", h.prior_mm2}, {"rms_distance_mm", h.rms_distance_mm}, {"evaluations", h.evaluations}, {"young_moduli_pa", e}});
            }
            m.details = {{"initial_rms_distance_mm", b.initial_rms_mm}, {"rms_distance_mm", b.rms_distance_mm}, {"moduli_prior_mm2", b.prior_mm2}, {"evaluations", b.evaluations},
                         {"factorisations", b.factorisations}, {"pcg_iterations", b.pcg_iterations}, {"factor_reuse", reg.reuse_factor}, {"cycles", static_cast<int>(b.history.size()) - 1}, {"stop_reason", b.stop_reason},
                         {"time_split_s", {{"factorisation", b.factorisation_s}, {"solves", b.solve_s}, {"field", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()}}},
                         {"history", history}};
            outcomes.push_back(std::move(m));
        }
        // Baselines on intensities and on labels.
        BaselineOptions baseline;
        baseline.bspline_grid_mm = o->bspline_grid;
        baseline.demons_field_sigma_voxels = o->demons_sigma;
        baseline.seed = o->seed;
        std::vector<std::pair<std::string, bool>> inputs;
        if (o->baselines == "all" || o->baselines == "intensity") inputs.emplace_back("intensity", false);
        if (o->baselines == "all" || o->baselines == "labels") inputs.emplace_back("labels", true);
        const int total = 3 * static_cast<int>(inputs.size());
        std::map<std::string, std::string> failed_baselines; ///< name → reason
        int done = 0;
        for (const auto& [input, labels_mode] : inputs) {
            // Rigid and B-spline see the whole moving image, so that a sample pushed out of the region
            // still finds intensities (otherwise mutual information gains by pushing hard samples out);
            // Demons needs both images on one grid: its moving image is resampled onto the region.
            const ScalarImage f = labels_mode ? label_intensity_image(fixed_labels, in.structures) : fixed;
            const ScalarImage m_whole = labels_mode ? label_intensity_image(in.moving_labels, in.structures) : in.moving;
            const ScalarImage m_region = labels_mode ? label_intensity_image(resample_labels(in.moving_labels, zero_field(roi)), in.structures)
                                                     : resample_image(in.moving, zero_field(roi), 0.0f);
            for (const BaselineMethod method : {BaselineMethod::rigid, BaselineMethod::demons, BaselineMethod::bspline}) {
                bar.update(0.5 + 0.4 * done / std::max(1, total), fmt::format("{} ({})", to_string(method), input));
                BaselineResult r;
                try {
                    r = register_baseline(f, method == BaselineMethod::demons ? m_region : m_whole, method, labels_mode, baseline);
                } catch (const Interrupted&) {
                    throw;
                } catch (const Error& e) {
                    // A baseline that fails is a finding of the report, not the end of the command
                    // (issue 28: B-spline found no fixed sample in an unaligned pair).
                    const std::string name = to_string(method) + "_" + input;
                    logger()->warn("register-images: baseline {} failed: {}", name, e.what());
                    failed_baselines[name] = e.what();
                    ++done;
                    continue;
                }
                MethodOutcome out{to_string(method) + "_" + input, std::move(r.fixed_to_moving), std::nullopt, r.seconds, json(r.figures), {}};
                if (in.landmarks_moving) {
                    LandmarkSet mapped = *in.landmarks_moving;
                    int unsettled = 0;
                    for (auto& l : mapped) {
                        Vec3 y;
                        if (!invert_field_at(out.field, l.position, y)) ++unsettled;
                        l.position = y;
                    }
                    out.details["landmark_inversions_unsettled"] = unsettled;
                    out.landmarks = mapped;
                }
                out.warped_labels = resample_labels(in.moving_labels, out.field);
                outcomes.push_back(std::move(out));
                ++done;
            }
        }
        bar.update(0.92, "evaluation and outputs");
        outcomes.front().warped_labels = resample_labels(original.moving_labels, outcomes.front().field);
        if (original.landmarks_moving) outcomes.front().landmarks = *original.landmarks_moving;
        if (aligned) {
            // Every method ran after the alignment: its field is composed with T⁻¹ and the original
            // moving labels are warped through the whole map. The alignment alone is a method too.
            for (std::size_t k = 1; k < outcomes.size(); ++k) {
                auto& m = outcomes[k];
                m.field = compose_with_alignment(std::move(m.field), alignment);
                LabelVolume warped = resample_labels(original.moving_labels, m.field);
                if (m.name == "biomechanical") // voxels the deformed structures left stay background
                    for (std::size_t v = 0; v < warped.labels.size(); ++v)
                        if (m.warped_labels.labels[v] == 0 && std::count(in.structures.begin(), in.structures.end(), warped.labels[v])) warped.labels[v] = 0;
                m.warped_labels = std::move(warped);
            }
            MethodOutcome rigid_part{"initial_alignment", rigid_inverse_field(alignment, roi), std::nullopt, 0.0,
                                     json{{"mode", o->initial}, {"start", alignment.start}}, {}};
            rigid_part.warped_labels = resample_labels(original.moving_labels, rigid_part.field);
            if (in.landmarks_moving) rigid_part.landmarks = *in.landmarks_moving;
            outcomes.insert(outcomes.begin() + 1, std::move(rigid_part));
        }
        json methods;
        for (const auto& m : outcomes) {
            json r = m.details;
            r["seconds"] = m.seconds;
            json dice, surface;
            for (const auto& s : compare_segmentations(fixed_labels, m.warped_labels, in.structures)) {
                dice[std::to_string(s.label)] = s.dice;
                surface[std::to_string(s.label)] = {{"mean_mm", std::isnan(s.mean_surface_mm) ? json(nullptr) : json(s.mean_surface_mm)},
                                                    {"max_mm", std::isnan(s.max_surface_mm) ? json(nullptr) : json(s.max_surface_mm)}};
            }
            r["dice"] = dice;
            r["surface_distance"] = surface;
            if (m.landmarks && in.landmarks_fixed) r["tre"] = tre_json(compute_tre(*m.landmarks, *in.landmarks_fixed, m.name + " landmarks"));
            r["status"] = "ok";
            methods[m.name] = r;
        }
        for (const auto& [name, reason] : failed_baselines) {
            methods[name] = {{"status", "failed"}, {"reason", reason}};
            if (name == o->method || name == o->method + "_intensity" || name == o->method + "_labels")
                if (std::none_of(outcomes.begin(), outcomes.end(), [&](const MethodOutcome& m) { return m.name.rfind(o->method + "_", 0) == 0; }))
                    fail("register-images: the chosen --method {} failed: {}", o->method, reason);
        }
        // The written result: the chosen method (baselines: on intensities when run, else labels).
        const MethodOutcome* chosen = nullptr;
        for (const auto& m : outcomes)
            if (m.name == o->method || m.name == o->method + "_intensity" || (!chosen && m.name == o->method + "_labels")) chosen = &m;
        if (!chosen) fail("register-images: method {} was not run", o->method);
        write_label_volume(staging.path() / "warped_labels.nii.gz", chosen->warped_labels);
        write_scalar_image(staging.path() / "warped_moving.nii.gz", resample_image(original.moving, chosen->field, 0.0f));
        write_displacement_field(staging.path() / "displacement.nii.gz", chosen->field);
        if (chosen->landmarks) write_landmarks(staging.path() / "landmarks.csv", *chosen->landmarks);
        MeshData data;
        data.point_data.push_back({"displacement", 3, u});
        data.point_data.push_back({"force", 3, std::vector<double>(b.force_n.data(), b.force_n.data() + b.force_n.size())});
        std::vector<double> held(fixed_node.begin(), fixed_node.end());
        data.point_data.push_back({"held", 1, held});
        write_vtu(staging.path() / "mesh.vtu", mesh, data);
        json parameters;
        parameters["units"] = {{"young_modulus", "Pa"}, {"force", "N"}, {"length", "mm"}};
        parameters["parametrisation"] = to_string(reg.parametrisation);
        json structures = json::array();
        for (std::size_t j = 0; j < model_labels.size(); ++j) {
            const Tissue* t = in.tissues.find(model_labels[j]);
            structures.push_back({{"label", model_labels[j]}, {"name", t ? t->name : ""}, {"initial_young_modulus_pa", initial_e[j]},
                                  {"young_modulus_pa", b.young_moduli_pa[j]}, {"estimated", static_cast<bool>(b.estimated[j])},
                                  {"poisson_ratio", t ? t->poisson_ratio : 0.0}, {"matched", map_of[j] != nullptr},
                                  {"note", b.estimated[j] ? "estimated relative to its piece's reference structure" : "held: the largest structure of its mesh piece, or estimation off"}});
            for (const auto& m : b.sensitivity)
                if (m.structure == j)
                    structures.back()["sensitivity"] = {
                        {"boundary_change_mm", {{"modulus_doubled", m.boundary_change_doubled_mm}, {"modulus_halved", m.boundary_change_halved_mm}}},
                        {"objective_change_mm2", {{"modulus_doubled", m.objective_change_doubled_mm2}, {"modulus_halved", m.objective_change_halved_mm2}}},
                        {"voxel_mm", m.voxel_mm}, {"determined_by_the_data", m.determined},
                        {"reading", m.determined ? "doubling or halving this modulus moves the structure's boundary by at least a tenth of a voxel (rms)"
                                                 : "not determined by the data: doubling or halving this modulus moves the structure's boundary by less than a "
                                                   "tenth of a voxel (rms), below what the segmentations resolve; the estimate is not a measurement"}};
        }
        parameters["structures"] = structures;
        double total_force = 0.0, max_force = 0.0;
        for (auto n : force_nodes) {
            const double f = b.force_n.segment<3>(3 * n).norm();
            total_force += f;
            max_force = std::max(max_force, f);
        }
        parameters["boundary_load"] = {{"nodes", force_nodes.size()}, {"sum_of_magnitudes_n", total_force}, {"max_nodal_n", max_force},
                                       {"per_node", "mesh.vtu point data 'force'"}};
        write_atomically(staging.path() / "parameters.json", [&](const fs::path& tmp) { std::ofstream(tmp) << parameters.dump(2) << "\n"; });

        json summary;
        summary["command"] = "register-images";
        summary["units"] = {{"length", "mm"}, {"force", "N"}, {"time", "s"}, {"young_modulus", "Pa"}};
        summary["inputs"] = in.description;
        summary["method"] = o->method;
        summary["structures"] = in.structures;
        summary["region"] = to_json(roi);
        summary["model"] = {{"element", reg.corotational ? "linear tetrahedra (CGAL Mesh_3, conforming to every structure), co-rotational linear elasticity "
                                                           "(rotations refreshed every cycle)"
                                                         : "linear tetrahedra (CGAL Mesh_3, conforming to every structure), small-strain linear elasticity"},
                            {"law", o->law}, {"largest_element_rotation_deg", b.largest_rotation_deg}, {"inverted_elements", b.inverted_elements},
                            {"tetrahedra", mesh.cell_count()}, {"nodes", mesh.node_count()}, {"held_nodes", elastic.fixed_nodes.size()}, {"hold", in.hold},
                            {"held_labels", held_labels}, {"anchor_n_mm", o->anchor}, {"loaded_nodes", force_nodes.size()}, {"objective_terms", objective.term_count()},
                            {"objective", objective.symmetric() ? "symmetric (model → fixed and fixed → model)" : "model → fixed"},
                            {"reverse_points", objective.reverse_point_count()},
                            {"rest_offsets_mm", objective.has_rest_offsets() ? json{{"mean", objective.rest_offset_stats_mm().first}, {"max", objective.rest_offset_stats_mm().second}} : json(nullptr)},
                            {"meshing_s", mesh_s},
                            {"quality", {{"min_dihedral_deg", quality.min_dihedral_deg}, {"max_dihedral_deg", quality.max_dihedral_deg},
                                         {"min_radius_ratio", quality.min_radius_ratio}, {"mean_edge_mm", quality.mean_edge_mm}, {"below_10_deg", quality.below_10_deg}}}};
        summary["parameters"] = {{"cell_size_mm", o->cell_size}, {"facet_distance_mm", o->facet_distance}, {"margin_mm", o->margin}, {"parametrisation", to_string(reg.parametrisation)},
                                 {"iterations_per_phase", o->iterations}, {"max_cycles", o->cycles}, {"tolerance", o->tolerance}, {"rms_tolerance_mm", o->rms_tolerance}, {"estimate_moduli", !o->no_moduli},
                                 {"moduli_prior", o->moduli_prior == 0.0 ? json(nullptr) : json{{"factor", o->moduli_prior}, {"rms_mm", o->moduli_prior_rms},
                                                                                               {"form", "½ N r² Σ (ln(E/E_table) / ln factor)² over the estimated structures"}}},
                                 {"bspline_grid_mm", o->bspline_grid}, {"demons_sigma_voxels", o->demons_sigma}};
        summary["estimated_moduli_pa"] = json::object();
        for (std::size_t j = 0; j < model_labels.size(); ++j) summary["estimated_moduli_pa"][std::to_string(model_labels[j])] = b.young_moduli_pa[j];
        summary["moduli_determined_by_the_data"] = json::object(); // per estimated structure (parameters.json: the sensitivity behind it)
        for (const auto& m : b.sensitivity) summary["moduli_determined_by_the_data"][std::to_string(model_labels[m.structure])] = m.determined;
        summary["initial_alignment"] = {{"mode", o->initial}, {"applied", aligned}, {"decision", decision}, {"min_reduction", o->initial_min_reduction}, {"start", alignment.start}, {"rotation_deg", alignment.rotation_deg},
                                        {"translation_mm", {alignment.translation[0], alignment.translation[1], alignment.translation[2]}},
                                        {"rotation_matrix", {{alignment.rotation(0, 0), alignment.rotation(0, 1), alignment.rotation(0, 2)},
                                                             {alignment.rotation(1, 0), alignment.rotation(1, 1), alignment.rotation(1, 2)},
                                                             {alignment.rotation(2, 0), alignment.rotation(2, 1), alignment.rotation(2, 2)}}},
                                        {"convention", "x_fixed = R x_moving + t; every method's field includes it"},
                                        {"centroid_distance_before_mm", alignment.centroid_distance_mm},
                                        {"boundary_rms_distance_mm", {{"before", alignment.rms_boundary_distance_before_mm}, {"after", alignment.rms_boundary_distance_mm}}},
                                        {"mesh_frame", !aligned ? "moving" : "fixed, after the initial alignment (mesh.vtu displacement: the non-rigid part)"}};
        summary["methods"] = methods;
        summary["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        write_atomically(staging.path() / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << summary.dump(2) << "\n"; });
        bar.update(0.99, "report.html");
        write_html_report(staging.path(), o->output);
        staging.commit();
        bar.finish();
        if (o->json) {
            std::cout << summary.dump(2) << "\n";
            return;
        }
        for (const auto& m : outcomes) {
            const json& r = methods[m.name];
            std::string line = fmt::format("{:<20}", m.name);
            if (r.contains("tre")) {
                // A group without landmarks has null statistics (issue 28 item 6).
                const auto mm = [](const json& v) { return v.is_number() ? fmt::format("{:.2f}", v.get<double>()) : std::string("–"); };
                line += fmt::format(" TRE {} mm (internal {})", mm(r["tre"]["all"]["mean_mm"]), mm(r["tre"]["internal"]["mean_mm"]));
            }
            double dice = 0.0;
            for (const auto& [k, v] : r["dice"].items()) dice += v.get<double>();
            line += fmt::format(", mean Dice {:.3f}, {:.1f} s", dice / std::max<std::size_t>(1, r["dice"].size()), m.seconds);
            std::cerr << line << "\n";
        }
        for (const auto& [name, reason] : failed_baselines) std::cerr << fmt::format("{:<20} failed: {}\n", name, reason);
    });
}

} // namespace

void add_subcommand_register_images(CLI::App& app)
{
    add_subcommand_register_images_impl(app);
}

} // namespace physreg::cli
