// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/images/image_registration.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/evaluation/segmentation_overlap.hpp"
#include "physreg/evaluation/tre.hpp"
#include "physreg/field/field_mapping.hpp"
#include "physreg/field/image_warping.hpp"
#include "physreg/image/distance_map.hpp"
#include "physreg/io/geometry_json.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/labelled_boundary.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/mesh/tetrahedral_meshing.hpp"
#include "physreg/registration/images/image_baselines.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <set>

namespace physreg {
using nlohmann::json;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); }

// ---- 1. structures -------------------------------------------------------------------------------

/// The structures to mesh and match: given, the pair's default, or every label of the moving
/// segmentation; each must be in both segmentations. A fixed segmentation with labels the moving
/// one lacks has another organ set (unless the structures were named).
std::vector<std::int32_t> resolve_structures(const ImagePair& pair, const std::vector<std::int32_t>& requested)
{
    std::map<std::int32_t, std::int64_t> fixed_count = count_labels(pair.fixed_labels), moving_count = count_labels(pair.moving_labels);
    std::vector<std::int32_t> structures = !requested.empty() ? requested : pair.default_structures;
    if (structures.empty())
        for (const auto& [label, n] : moving_count)
            if (label != 0) structures.push_back(label);
    if (structures.empty()) fail("register-images: the moving segmentation '{}' has no structure (every voxel is 0)", pair.description.value("moving_labels", std::string("of the pair")));
    for (auto label : structures) {
        const bool in_moving = moving_count.count(label) && moving_count[label] > 0, in_fixed = fixed_count.count(label) && fixed_count[label] > 0;
        if (!in_moving && !in_fixed) fail("register-images: structure {} is empty in both segmentations", label);
        if (!in_moving) fail("register-images: structure {} is in the fixed segmentation only (the moving labels have none)", label);
        if (!in_fixed) fail("register-images: structure {} is in the moving segmentation only (the fixed labels have none)", label);
    }
    if (requested.empty() && pair.default_structures.empty())
        for (const auto& [label, n] : fixed_count)
            if (label != 0 && !std::count(structures.begin(), structures.end(), label))
                fail("register-images: label {} is in the fixed segmentation only; the organ sets differ (choose with --structures)", label);
    return structures;
}

/// The pair's table, or 3 kPa and ν 0.45 for every structure when none was given; every structure
/// must have a tissue.
TissueTable resolve_tissues(const ImagePair& pair, const std::vector<std::int32_t>& structures)
{
    TissueTable tissues = pair.tissues;
    const std::string source = pair.tissues_source.empty() ? "the given tissue table" : pair.tissues_source;
    if (!tissues.tissues.empty()) tissues.validate(source);
    else
        for (auto label : structures) tissues.tissues.push_back({label, "label " + std::to_string(label), 3000.0, 0.45, 1000.0, 0.0});
    for (auto label : structures)
        if (!tissues.find(label)) fail("register-images: structure {} has no tissue in {}", label, source);
    return tissues;
}

// ---- 2. initial alignment ------------------------------------------------------------------------

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
DisplacementField rigid_inverse_field(const SegmentationAlignment& a, const ImageGeometry& geometry) { return compose_with_alignment(zero_field(geometry), a); }

/// The moving side seen through the alignment T (x_fixed = T x_moving): image and labels resampled
/// onto the fixed grid at T⁻¹(y), landmarks moved by T. Everything after it runs in the fixed frame
/// and explains only the non-rigid rest.
ImagePair aligned_pair(const ImagePair& in, const SegmentationAlignment& a)
{
    ImagePair out = in;
    const DisplacementField to_moving = rigid_inverse_field(a, in.fixed.geometry);
    out.moving = resample_image(in.moving, to_moving, 0.0f);
    out.moving_labels = resample_labels(in.moving_labels, to_moving);
    if (in.landmarks_moving)
        for (auto& l : *out.landmarks_moving) l.position = a.apply(l.position);
    return out;
}

/// Whether the alignment is applied, and why. Frames that already agree (a dataset's states, two
/// scans of one session) keep them: a rigid fit of deformed organs would move the held support with
/// it (on the phantom pair: 2.3°, and the biomechanical TRE 0.62 instead of 0.33 mm). A pair whose
/// frames differ has most of its boundary distance removed by the rigid motion (the 9 unaligned
/// pairs: 82–99 %), a pair that shares one frame little of it (the phantom pairs: 30 % and 6 %).
std::pair<bool, std::string> alignment_decision(const SegmentationAlignment& alignment, const ImageRegistrationSettings& s)
{
    const double before = alignment.rms_boundary_distance_before_mm, after = alignment.rms_boundary_distance_mm;
    const double gain = before - after;
    if (s.initial == "identity") return {false, "identity asked (--initial identity)"};
    if (gain > s.initial_min_reduction * before)
        return {true, fmt::format("applied: it removes {:.0f} % of the boundary RMS distance ({:.2f} → {:.2f} mm)", 100 * gain / before, before, after)};
    return {false, fmt::format("not applied: it removes only {:.0f} % of the boundary RMS distance ({:.2f} → {:.2f} mm; --initial-min-reduction {}): the frames "
                               "already agree, the rest is deformation", 100 * gain / std::max(before, 1e-12), before, after, s.initial_min_reduction)};
}

/// Frames that do not overlap at all cannot be related by any method here without an alignment.
void require_overlap(const ImagePair& in)
{
    const auto [flo, fhi] = in.fixed.geometry.physical_box();
    const auto [mlo, mhi] = in.moving.geometry.physical_box();
    if ((flo.array() > mhi.array()).any() || (mlo.array() > fhi.array()).any())
        fail("register-images: the fixed and moving images do not overlap in physical space (fixed [{:.1f} {:.1f} {:.1f}]–[{:.1f} {:.1f} {:.1f}] mm, moving "
             "[{:.1f} {:.1f} {:.1f}]–[{:.1f} {:.1f} {:.1f}] mm); bring them into one frame first or use --initial centroid|rigid",
             flo[0], flo[1], flo[2], fhi[0], fhi[1], fhi[2], mlo[0], mlo[1], mlo[2], mhi[0], mhi[1], mhi[2]);
}

// ---- 3. region and model -------------------------------------------------------------------------

/// The fixed grid cropped to the structures of both segmentations plus `margin_mm`.
ImageGeometry region_of_interest(const ImagePair& in, const std::vector<std::int32_t>& structures, double margin_mm)
{
    const ImageGeometry& g = in.fixed.geometry;
    Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
    for (const LabelVolume* v : {&in.fixed_labels, &in.moving_labels})
        for (std::int64_t k = 0; k < v->geometry.size[2]; ++k)
            for (std::int64_t j = 0; j < v->geometry.size[1]; ++j)
                for (std::int64_t i = 0; i < v->geometry.size[0]; ++i)
                    if (std::count(structures.begin(), structures.end(), v->at(i, j, k))) {
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

/// The supports: nodes of held labels, and (hold posterior) the surface nodes facing +y.
std::vector<std::uint8_t> held_nodes(const VolumeMesh& mesh, const std::vector<std::int32_t>& hold_labels, const std::string& hold)
{
    std::vector<std::uint8_t> held(mesh.node_count(), 0);
    for (std::size_t c = 0; c < mesh.cell_count(); ++c)
        if (std::count(hold_labels.begin(), hold_labels.end(), mesh.cell_labels[c]))
            for (auto n : mesh.cell(c)) held[static_cast<std::size_t>(n)] = 1;
    if (hold == "posterior")
        for (auto n : surface_nodes_facing(mesh, unlabelled_boundary(mesh), Vec3::UnitY(), 0.5)) held[static_cast<std::size_t>(n)] = 1;
    return held;
}

// ---- 4. the biomechanical method -----------------------------------------------------------------

json history_json(const SegmentationRegistrationResult& b, const std::vector<std::int32_t>& model_labels)
{
    json history = json::array();
    for (const auto& h : b.history) {
        json e;
        for (std::size_t j = 0; j < model_labels.size(); ++j) e[std::to_string(model_labels[j])] = h.young_moduli_pa[j];
        history.push_back({{"cycle", h.cycle}, {"objective_mm2", h.objective_mm2}, {"prior_mm2", h.prior_mm2}, {"rms_distance_mm", h.rms_distance_mm},
                           {"evaluations", h.evaluations}, {"young_moduli_pa", e}});
    }
    return history;
}

// ---- 5. baselines ----------------------------------------------------------------------------------

/// ITK's rigid, Demons and B-spline on intensities and/or labels. A baseline that fails is a finding
/// of the report, not the end of the command (issue 28: B-spline found no fixed sample in an
/// unaligned pair).
void run_baselines(const ImagePair& in, const ScalarImage& fixed, const LabelVolume& fixed_labels, const ImageGeometry& roi,
                   const std::vector<std::int32_t>& structures, const ImageRegistrationSettings& s, ImageRegistrationResult& result,
                   const std::function<void(double, const std::string&)>& progress)
{
    BaselineOptions baseline;
    baseline.bspline_grid_mm = s.bspline_grid;
    baseline.demons_field_sigma_voxels = s.demons_sigma;
    baseline.seed = static_cast<unsigned>(s.seed);
    std::vector<std::pair<std::string, bool>> inputs;
    // A label-to-label pair has no intensities: "all" is then every baseline it can run (summary
    // "baselines_run"); "intensity" alone was refused before any work.
    if ((s.baselines == "all" && in.intensities) || s.baselines == "intensity") inputs.emplace_back("intensity", false);
    if (s.baselines == "all" || s.baselines == "labels") inputs.emplace_back("labels", true);
    const int total = 3 * static_cast<int>(inputs.size());
    int done = 0;
    for (const auto& [input, labels_mode] : inputs) {
        // Rigid and B-spline see the whole moving image, so that a sample pushed out of the region
        // still finds intensities (otherwise mutual information gains by pushing hard samples out);
        // Demons needs both images on one grid: its moving image is resampled onto the region.
        const ScalarImage f = labels_mode ? label_intensity_image(fixed_labels, structures) : fixed;
        const ScalarImage m_whole = labels_mode ? label_intensity_image(in.moving_labels, structures) : in.moving;
        const ScalarImage m_region = labels_mode ? label_intensity_image(resample_labels(in.moving_labels, zero_field(roi)), structures)
                                                 : resample_image(in.moving, zero_field(roi), 0.0f);
        for (const BaselineMethod method : {BaselineMethod::rigid, BaselineMethod::demons, BaselineMethod::bspline}) {
            if (progress) progress(0.5 + 0.4 * done / std::max(1, total), fmt::format("{} ({})", to_string(method), input));
            const std::string name = to_string(method) + "_" + input;
            ++done;
            BaselineResult r;
            try {
                r = register_baseline(f, method == BaselineMethod::demons ? m_region : m_whole, method, labels_mode, baseline);
            } catch (const Interrupted&) {
                throw;
            } catch (const Error& e) {
                logger()->warn("register-images: baseline {} failed: {}", name, e.what());
                result.failed_baselines[name] = e.what();
                continue;
            }
            ImageMethodOutcome out{name, std::move(r.fixed_to_moving), std::nullopt, {}, r.seconds, json(r.figures)};
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
            result.methods.push_back(std::move(out));
        }
    }
}

// ---- 6. evaluation -------------------------------------------------------------------------------

json evaluate_method(const ImageMethodOutcome& m, const LabelVolume& fixed_labels, const std::vector<std::int32_t>& structures,
                     const std::optional<LandmarkSet>& landmarks_fixed)
{
    json r = m.details;
    r["seconds"] = m.seconds;
    json dice, surface;
    for (const auto& s : compare_segmentations(fixed_labels, m.warped_labels, structures)) {
        dice[std::to_string(s.label)] = s.dice;
        surface[std::to_string(s.label)] = {{"mean_mm", std::isnan(s.mean_surface_mm) ? json(nullptr) : json(s.mean_surface_mm)},
                                            {"max_mm", std::isnan(s.max_surface_mm) ? json(nullptr) : json(s.max_surface_mm)}};
    }
    r["dice"] = dice;
    r["surface_distance"] = surface;
    if (m.landmarks && landmarks_fixed) r["tre"] = tre_summary(compute_tre(*m.landmarks, *landmarks_fixed, m.name + " landmarks"));
    r["status"] = "ok";
    return r;
}

bool names_method(const std::string& name, const std::string& method) { return name == method || name == method + "_intensity" || name == method + "_labels"; }

/// Issue 57 item 4: per baseline, whether it fits the boundaries better than the biomechanical
/// answer (mean Dice higher by more than half a percent) and moves the interior differently (the
/// two fields more than a voxel apart on average inside the fixed structures). Where both hold, the
/// segmentations cannot say which interior is right: the summary says so rather than choosing.
json against_baselines(const ImageRegistrationResult& result, const LabelVolume& fixed_labels, const std::vector<std::int32_t>& structures, const json& methods_json)
{
    const auto mean_dice = [&](const std::string& name) {
        double sum = 0.0;
        std::size_t n = 0;
        for (const auto& [label, d] : methods_json.at(name).at("dice").items()) sum += d.get<double>(), ++n;
        return n ? sum / static_cast<double>(n) : 0.0;
    };
    const ImageMethodOutcome* bio = nullptr;
    for (const auto& m : result.methods)
        if (m.name == "biomechanical") bio = &m;
    json out = {{"entries", json::array()}};
    if (!bio) return out;
    const double voxel_mm = fixed_labels.geometry.spacing.maxCoeff();
    const double bio_dice = mean_dice("biomechanical");
    std::vector<std::string> conflicts;
    for (const auto& m : result.methods) {
        const bool baseline = m.name.size() > 7 && (m.name.rfind("_labels") == m.name.size() - 7 || m.name.rfind("_intensity") == m.name.size() - 10);
        if (!baseline || m.field.components.size() != bio->field.components.size()) continue;
        double sum = 0.0, largest = 0.0;
        std::size_t n = 0;
        for (std::size_t v = 0; v < fixed_labels.labels.size(); ++v) {
            if (!std::count(structures.begin(), structures.end(), static_cast<std::int32_t>(fixed_labels.labels[v]))) continue;
            const Eigen::Vector3f d(bio->field.components[3 * v] - m.field.components[3 * v], bio->field.components[3 * v + 1] - m.field.components[3 * v + 1],
                                    bio->field.components[3 * v + 2] - m.field.components[3 * v + 2]);
            sum += d.norm();
            largest = std::max(largest, static_cast<double>(d.norm()));
            ++n;
        }
        const double apart = n ? sum / static_cast<double>(n) : 0.0;
        const double dice = mean_dice(m.name);
        const bool fits_better = dice > bio_dice + 0.005, moves_differently = apart > voxel_mm;
        out["entries"].push_back({{"method", m.name}, {"mean_dice", dice}, {"biomechanical_mean_dice", bio_dice}, {"interior_apart_mean_mm", apart},
                                  {"interior_apart_max_mm", largest}, {"fits_the_boundaries_better", fits_better}, {"moves_the_interior_differently", moves_differently}});
        if (fits_better && moves_differently) conflicts.push_back(fmt::format("{} (Dice {:.3f} against {:.3f}; {:.1f} mm apart inside)", m.name, dice, bio_dice, apart));
    }
    out["reading"] = conflicts.empty()
                         ? std::string("no baseline both fits the boundaries better (Dice + 0.005) and moves the interior differently (more than a voxel apart on average)")
                         : fmt::format("{} fit{} the boundaries better than the biomechanical answer and move{} the interior differently: the segmentations "
                                       "alone cannot say which interior is right (the biomechanical one is the elastic extension of its boundary fit)",
                                       fmt::join(conflicts, ", "), conflicts.size() == 1 ? "s" : "", conflicts.size() == 1 ? "s" : "");
    return out;
}

} // namespace

SegmentationRegistrationOptions ImageRegistrationSettings::solver_options() const
{
    SegmentationRegistrationOptions reg;
    reg.parametrisation = parse_boundary_parametrisation(parametrisation);
    reg.alternation_iterations = iterations;
    reg.max_cycles = cycles;
    reg.relative_tolerance = tolerance;
    reg.rms_tolerance_mm = rms_tolerance;
    reg.estimate_moduli = estimate_moduli;
    reg.moduli_prior_factor = moduli_prior;
    reg.moduli_prior_rms_mm = moduli_prior_rms;
    reg.corotational = law == "corotational";
    reg.reuse_factor = factor_reuse;
    return reg;
}

const SettingsSpec<ImageRegistrationSettings>& image_registration_spec()
{
    using S = ImageRegistrationSettings;
    static const SettingsSpec<S> spec = [] {
        SettingsSpec<S> s("register-images");
        s.choice("method", "--method", &S::method, {"biomechanical", "rigid", "demons", "bspline"}, "the method whose result is written: biomechanical, rigid, demons or bspline")
            .choice("initial", "--initial", &S::initial, {"identity", "centroid", "translation", "rigid"},
                    "initial alignment of the segmentations before every method: identity, centroid, translation (centroids, then the translation that fits the fixed structures' distance maps) or rigid (centroids, then rigid on the distance maps)")
            .real("initial_min_reduction", "--initial-min-reduction", &S::initial_min_reduction, "",
                  "apply the initial alignment only when it removes more than this fraction of the structures' boundary RMS distance (0: always)", 0.0, 1.0)
            .real("initial_max_rotation", "--initial-max-rotation", &S::initial_max_rotation, "degrees",
                  "rigid alignment: the largest plausible rotation between the frames; a pose turned farther wins only when it fits the "
                  "boundaries at most half as far as the best pose within it and closer by more than a voxel (180: the best fit alone)",
                  0.0, 180.0, true)
            .choice("baselines", "--baselines", &S::baselines, {"all", "intensity", "labels", "none"}, "baselines in the report: all, intensity, labels or none")
            .choice("hold", "--hold", &S::hold, {"auto", "posterior", "none"},
                    "Dirichlet support: posterior (surface nodes facing +y), none, or auto (the pair's own recommendation: none for datasets and "
                    "served segmentations since issue 46 — the segmentation drives the whole boundary, and a held face keeps the initial alignment's error)")
            .labels("structures", "--structures", &S::structures, "labels to mesh and match, e.g. 2,3,4,6 (default: every label of the moving segmentation)")
            .labels("hold_labels", "--hold-labels", &S::hold_labels, "labels (meshed with the structures) whose nodes are held, e.g. bone")
            .real("anchor", "--anchor", &S::anchor, "N/mm", "regularising spring to rest at every node, N/mm (0: none)", 0.0)
            .choice("parametrisation", "--parametrisation", &S::parametrisation, {"surface-displacement", "nodal-forces"},
                    "boundary unknowns: surface-displacement or nodal-forces (paper 002)")
            .integer("iterations", "--iterations", &S::iterations, "L-BFGS iterations per phase of the alternation (paper: 5)", 1, 1e6)
            .integer("cycles", "--cycles", &S::cycles, "most alternation cycles", 1, 1e6)
            .real("tolerance", "--tolerance", &S::tolerance, "", "stop when a cycle lowers the objective by less than this fraction", 0.0)
            .real("rms_tolerance", "--rms-tolerance", &S::rms_tolerance, "mm", "also stop when a cycle lowers the rms boundary distance by less than this, mm (0: off)", 0.0)
            .flag("estimate_moduli", "!--no-moduli", &S::estimate_moduli, "estimate the structures' Young's moduli (--no-moduli: keep the initial values, boundary load only)")
            .real("moduli_prior", "--moduli-prior", &S::moduli_prior, "",
                  "log-normal prior on the estimated moduli around the tissue table's: the factor one standard deviation away (e.g. 2), 0 for free ratios")
            .real("moduli_prior_rms", "--moduli-prior-rms", &S::moduli_prior_rms, "mm",
                  "the prior's weight: one standard deviation costs as much as this rms boundary distance over every objective term, mm", 0.0, std::numeric_limits<double>::infinity(), true)
            .choice("law", "--law", &S::law, {"linear", "corotational"},
                    "the registering model's law: linear (small strain, paper 002) or corotational (large rotations: the element rotations refreshed every cycle)")
            .flag("factor_reuse", "!--no-factor-reuse", &S::factor_reuse,
                  "solve by CG preconditioned by an earlier factor (--no-factor-reuse: factorise K for every set of moduli; the same result to 1e-10, for benchmarks)")
            .flag("rest_offsets", "--rest-offsets,!--no-rest-offsets", &S::rest_offsets,
                  "each model boundary node keeps its rest distance to the moving segmentation's boundary (the mesh is not the voxel boundary) instead of landing exactly "
                  "on the fixed one (--no-rest-offsets: paper 002's objective)")
            .flag("symmetric", "--symmetric", &S::symmetric,
                  "symmetric objective: also pull the model toward the fixed structures' boundary points that no model node reaches")
            .real("cell_size", "--cell-size", &S::cell_size, "mm", "largest tetrahedron circumradius, mm", 0.0, std::numeric_limits<double>::infinity(), true)
            .real("facet_distance", "--facet-distance", &S::facet_distance, "mm", "largest distance of a mesh facet to the label interface, mm", 0.0,
                  std::numeric_limits<double>::infinity(), true)
            .real("margin", "--margin", &S::margin, "mm", "the registration region: the structures' bounding box plus this margin, mm", 0.0)
            .real("bspline_grid", "--bspline-grid", &S::bspline_grid, "mm", "B-spline control spacing at the coarsest level, mm (halved twice)", 0.0,
                  std::numeric_limits<double>::infinity(), true)
            .real("demons_sigma", "--demons-sigma", &S::demons_sigma, "voxels", "Demons field smoothing σ, voxels", 0.0, std::numeric_limits<double>::infinity(), true)
            .integer("seed", "--seed", &S::seed, "meshing and metric-sampling seed", 0, 2147483647);
        return s;
    }();
    return spec;
}

void validate(const ImageRegistrationSettings& s, SettingNaming naming)
{
    const auto& spec = image_registration_spec();
    spec.validate(s, naming);
    const auto n = [&](const char* key) { return spec.name(key, naming); };
    if (s.method != "biomechanical" && s.baselines == "none") fail("{} {} needs the baselines ({} is none)", n("method"), s.method, n("baselines"));
    if (!s.estimate_moduli && s.moduli_prior != 0.0)
        fail("{} {} needs estimated moduli ({})", n("moduli_prior"), s.moduli_prior, naming == SettingNaming::option ? n("estimate_moduli") + " is given" : "estimate_moduli is false");
    try {
        s.solver_options().validate();
    } catch (const Error& e) {
        fail("{} {} / {} {} mm: {}", n("moduli_prior"), s.moduli_prior, n("moduli_prior_rms"), s.moduli_prior_rms, e.what());
    }
}


namespace {

/// The moving structures' model: the mesh (kept in result.mesh) with its held nodes (result.held),
/// the loaded surface nodes, each structure's reference map and initial modulus, and the objective.
struct ImageModel {
    TetrahedronQuality quality;
    double meshing_s = 0.0;
    LinearElasticOptions elastic;
    std::vector<std::int32_t> force_nodes;
    std::vector<std::int32_t> labels; ///< the model's structures, sorted; held labels take part in the mechanics only
    std::vector<std::unique_ptr<SignedDistanceMap>> maps, moving_maps;
    std::vector<const SignedDistanceMap*> map_of; ///< per label: its reference map, null for held labels
    std::vector<double> initial_e;
    std::unique_ptr<SegmentationObjective> objective;
};

ImageModel build_image_model(const ImagePair& in, const LabelVolume& fixed_labels, const std::vector<std::int32_t>& structures, const TissueTable& tissues,
                             const ImageRegistrationSettings& s, ImageRegistrationResult& result)
{
    ImageModel m;
    const auto t_mesh = std::chrono::steady_clock::now();
    TetMeshingOptions meshing;
    meshing.labels.insert(structures.begin(), structures.end());
    meshing.labels.insert(s.hold_labels.begin(), s.hold_labels.end());
    meshing.default_cell_size_mm = s.cell_size;
    meshing.facet_size_mm = s.cell_size;
    meshing.facet_distance_mm = s.facet_distance;
    meshing.seed = static_cast<unsigned>(s.seed);
    meshing.seed_every_component = true; // every organ piece must be meshed, or its Dice collapses
    result.mesh = mesh_labels_tetrahedral(in.moving_labels, meshing, "the moving segmentation");
    const VolumeMesh& mesh = result.mesh;
    m.quality = measure_tetrahedra(mesh);
    m.meshing_s = seconds_since(t_mesh);
    LinearElasticOptions& elastic = m.elastic;
    for (const auto& t : tissues.tissues) elastic.poisson_ratio[t.label] = t.poisson_ratio;
    elastic.anchor_stiffness_n_mm = s.anchor;
    result.held = held_nodes(mesh, s.hold_labels, s.hold);
    for (std::size_t n = 0; n < result.held.size(); ++n)
        if (result.held[n]) elastic.fixed_nodes.push_back(static_cast<std::int32_t>(n));
    std::vector<std::int32_t>& force_nodes = m.force_nodes;
    for (auto n : outer_boundary_nodes(mesh))
        if (!result.held[static_cast<std::size_t>(n)]) force_nodes.push_back(n);
    // Structures of the model (sorted labels), their maps and initial moduli; held labels take part
    // in the mechanics but not in the objective.
    m.labels.assign(meshing.labels.begin(), meshing.labels.end());
    const std::vector<std::int32_t>& model_labels = m.labels;
    auto& maps = m.maps;
    auto& map_of = m.map_of;
    auto& initial_e = m.initial_e;
    for (auto label : model_labels) {
        const bool structure = std::count(structures.begin(), structures.end(), label) > 0;
        maps.push_back(structure ? std::make_unique<SignedDistanceMap>(fixed_labels, std::set<std::int32_t>{label}, "fixed label " + std::to_string(label)) : nullptr);
        map_of.push_back(maps.back().get());
        const Tissue* t = tissues.find(label);
        if (!t) fail("register-images: held label {} has no tissue (give --tissues)", label);
        initial_e.push_back(t->young_modulus_pa);
    }
    {   // A structure the mesher lost (thinner than the cells) would shift the order: refuse.
        const std::set<std::int32_t> meshed(mesh.cell_labels.begin(), mesh.cell_labels.end());
        for (auto label : model_labels)
            if (!meshed.count(label)) fail("register-images: structure {} got no tetrahedron (thinner than --cell-size {} mm?)", label, s.cell_size);
    }
    m.objective = std::make_unique<SegmentationObjective>(mesh, model_labels, map_of, "the fixed segmentation");
    SegmentationObjective& objective = *m.objective;
    if (s.symmetric) objective.add_reverse_term();
    auto& moving_maps = m.moving_maps;
    if (s.rest_offsets) {
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

    return m;
}

/// The biomechanical result as a method: its dense inverse field on the region, the moving labels
/// warped (voxels the structures left are background), landmarks carried, the solver's figures.
ImageMethodOutcome biomechanical_outcome(const ImagePair& in, const VolumeMesh& mesh, const std::vector<std::int32_t>& model_labels,
                                         const SegmentationRegistrationResult& b, const SegmentationRegistrationOptions& reg, const ImageGeometry& roi,
                                         const ImageRegistrationSettings& s)
{
    const std::vector<double> u(b.displacement_mm.data(), b.displacement_mm.data() + b.displacement_mm.size());
    {
        const auto t0 = std::chrono::steady_clock::now();
        const InverseMap inverse = rasterize_inverse_map(mesh, u, roi, 2.0 * s.cell_size);
        ImageMethodOutcome m{"biomechanical", inverse.field, std::nullopt, {}, b.seconds, json::object()};
        m.warped_labels = resample_labels(in.moving_labels, m.field);
        // Voxels the deformed structures left (not covered by the deformed mesh) are background.
        for (std::size_t v = 0; v < m.warped_labels.labels.size(); ++v)
            if (!inverse.coverage[v] && std::count(model_labels.begin(), model_labels.end(), m.warped_labels.labels[v])) m.warped_labels.labels[v] = 0;
        if (in.landmarks_moving) {
            // A landmark a little outside the segmented structures (partial volume, an unsegmented
            // neighbour) is carried by the nearest element; the allowance must not shrink with a
            // finer mesh (3 mm cells refused a public pair's landmark 4.8 mm outside its gland), so
            // it is 1.5 cells or 5 voxels of the moving image, whichever is larger.
            const double allowance = std::max(1.5 * s.cell_size, 5.0 * in.moving_labels.geometry.spacing.maxCoeff());
            const auto where = embed_landmarks(mesh, *in.landmarks_moving, allowance, "the moving structures' mesh (landmarks)");
            m.landmarks = displace_landmarks(mesh, where, *in.landmarks_moving, u);
        }
        m.details = {{"initial_rms_distance_mm", b.initial_rms_mm}, {"rms_distance_mm", b.rms_distance_mm}, {"moduli_prior_mm2", b.prior_mm2}, {"evaluations", b.evaluations},
                     {"factorisations", b.factorisations}, {"pcg_iterations", b.pcg_iterations}, {"factor_reuse", reg.reuse_factor},
                     {"cycles", static_cast<int>(b.history.size()) - 1}, {"stop_reason", b.stop_reason},
                     {"time_split_s", {{"factorisation", b.factorisation_s}, {"solves", b.solve_s}, {"field", seconds_since(t0)}}},
                     {"history", history_json(b, model_labels)}};
        return m;
    }

}

/// Every method brought through the initial alignment (when applied; the alignment alone becomes a
/// method too) and evaluated; a failed baseline is listed, and the run fails only if it was the chosen method.
json evaluate_methods(const ImagePair& original, const ImagePair& in, const LabelVolume& fixed_labels, const std::vector<std::int32_t>& structures,
                      const ImageRegistrationSettings& s, ImageRegistrationResult& result)
{
    const SegmentationAlignment& alignment = result.alignment;
    const ImageGeometry& roi = result.region;
    auto& methods = result.methods;
    methods.front().warped_labels = resample_labels(original.moving_labels, methods.front().field);
    if (original.landmarks_moving) methods.front().landmarks = *original.landmarks_moving;
    if (result.aligned) {
        // Every method ran after the alignment: its field is composed with T⁻¹ and the original moving
        // labels are warped through the whole map. The alignment alone is a method too.
        for (std::size_t k = 1; k < methods.size(); ++k) {
            auto& m = methods[k];
            m.field = compose_with_alignment(std::move(m.field), alignment);
            LabelVolume warped = resample_labels(original.moving_labels, m.field);
            if (m.name == "biomechanical") // voxels the deformed structures left stay background
                for (std::size_t v = 0; v < warped.labels.size(); ++v)
                    if (m.warped_labels.labels[v] == 0 && std::count(structures.begin(), structures.end(), warped.labels[v])) warped.labels[v] = 0;
            m.warped_labels = std::move(warped);
        }
        ImageMethodOutcome rigid_part{"initial_alignment", rigid_inverse_field(alignment, roi), std::nullopt, {}, 0.0, json{{"mode", s.initial}, {"start", alignment.start}}};
        rigid_part.warped_labels = resample_labels(original.moving_labels, rigid_part.field);
        if (in.landmarks_moving) rigid_part.landmarks = *in.landmarks_moving;
        methods.insert(methods.begin() + 1, std::move(rigid_part));
    }
    json methods_json;
    for (const auto& m : methods) methods_json[m.name] = evaluate_method(m, fixed_labels, structures, in.landmarks_fixed);
    for (const auto& [name, reason] : result.failed_baselines) {
        methods_json[name] = {{"status", "failed"}, {"reason", reason}};
        if (names_method(name, s.method) && std::none_of(methods.begin(), methods.end(), [&](const ImageMethodOutcome& m) { return m.name.rfind(s.method + "_", 0) == 0; }))
            fail("register-images: the chosen --method {} failed: {}", s.method, reason);
    }
    return methods_json;
}

/// parameters.json: the estimated moduli with their sensitivity, the boundary load.
json parameters_json(const ImageModel& model, const TissueTable& tissues, const SegmentationRegistrationResult& b, const SegmentationRegistrationOptions& reg)
{
    const std::vector<std::int32_t>& model_labels = model.labels;
    const auto& initial_e = model.initial_e;
    const auto& map_of = model.map_of;
    const auto& force_nodes = model.force_nodes;
    json parameters;
    parameters["units"] = {{"young_modulus", "Pa"}, {"force", "N"}, {"length", "mm"}};
    parameters["parametrisation"] = to_string(reg.parametrisation);
    json structures_json = json::array();
    for (std::size_t j = 0; j < model_labels.size(); ++j) {
        const Tissue* t = tissues.find(model_labels[j]);
        structures_json.push_back({{"label", model_labels[j]}, {"name", t ? t->name : ""}, {"initial_young_modulus_pa", initial_e[j]},
                                   {"young_modulus_pa", b.young_moduli_pa[j]}, {"estimated", static_cast<bool>(b.estimated[j])},
                                   {"poisson_ratio", t ? t->poisson_ratio : 0.0}, {"matched", map_of[j] != nullptr},
                                   {"note", b.estimated[j] ? "estimated relative to its piece's reference structure" : "held: the largest structure of its mesh piece, or estimation off"}});
        for (const auto& m : b.sensitivity)
            if (m.structure == j)
                structures_json.back()["sensitivity"] = {
                    {"boundary_change_mm", {{"modulus_doubled", m.boundary_change_doubled_mm}, {"modulus_halved", m.boundary_change_halved_mm}}},
                    {"objective_change_mm2", {{"modulus_doubled", m.objective_change_doubled_mm2}, {"modulus_halved", m.objective_change_halved_mm2}}},
                    {"voxel_mm", m.voxel_mm}, {"determined_by_the_data", m.determined},
                    {"reading", m.determined ? "doubling or halving this modulus moves the structure's boundary by at least a tenth of a voxel (rms)"
                                             : "not determined by the data: doubling or halving this modulus moves the structure's boundary by less than a tenth of a "
                                               "voxel (rms), below what the segmentations resolve; the estimate is not a measurement"}};
    }
    parameters["structures"] = structures_json;
    double total_force = 0.0, max_force = 0.0;
    for (auto n : force_nodes) {
        const double f = b.force_n.segment<3>(3 * n).norm();
        total_force += f;
        max_force = std::max(max_force, f);
    }
    parameters["boundary_load"] = {{"nodes", force_nodes.size()}, {"sum_of_magnitudes_n", total_force}, {"max_nodal_n", max_force}, {"per_node", "mesh.vtu point data 'force'"}};

    return parameters;
}

/// summary.json: inputs, the settings used, the model, every method (its seconds added by the caller).
json summary_json(const ImagePair& original, const ImageRegistrationSettings& s, const ImageRegistrationResult& result, const ImageModel& model,
                  const json& methods_json, const SegmentationRegistrationOptions& reg)
{
    const auto& structures = result.structures;
    const ImageGeometry& roi = result.region;
    const VolumeMesh& mesh = result.mesh;
    const SegmentationAlignment& alignment = result.alignment;
    const SegmentationRegistrationResult& b = result.biomechanical;
    const std::vector<std::int32_t>& model_labels = model.labels;
    const LinearElasticOptions& elastic = model.elastic;
    const auto& force_nodes = model.force_nodes;
    const SegmentationObjective& objective = *model.objective;
    const TetrahedronQuality& quality = model.quality;
    const double mesh_s = model.meshing_s;
    json summary;
    summary["command"] = "register-images";
    summary["units"] = {{"length", "mm"}, {"force", "N"}, {"time", "s"}, {"young_modulus", "Pa"}};
    summary["inputs"] = original.description;
    summary["intensities"] = original.intensities;
    summary["method"] = s.method;
    summary["settings"] = image_registration_spec().to_json(s);
    summary["structures"] = structures;
    summary["region"] = to_json(roi);
    std::vector<std::int32_t> held_labels = s.hold_labels;
    summary["model"] = {{"element", reg.corotational ? "linear tetrahedra (CGAL Mesh_3, conforming to every structure), co-rotational linear elasticity "
                                                       "(rotations refreshed every cycle)"
                                                     : "linear tetrahedra (CGAL Mesh_3, conforming to every structure), small-strain linear elasticity"},
                        {"law", s.law}, {"largest_element_rotation_deg", b.largest_rotation_deg}, {"inverted_elements", b.inverted_elements},
                        {"tetrahedra", mesh.cell_count()}, {"nodes", mesh.node_count()}, {"held_nodes", elastic.fixed_nodes.size()}, {"hold", s.hold},
                        {"held_labels", held_labels}, {"anchor_n_mm", s.anchor}, {"loaded_nodes", force_nodes.size()}, {"objective_terms", objective.term_count()},
                        {"objective", objective.symmetric() ? "symmetric (model → fixed and fixed → model)" : "model → fixed"},
                        {"reverse_points", objective.reverse_point_count()},
                        {"rest_offsets_mm", objective.has_rest_offsets() ? json{{"mean", objective.rest_offset_stats_mm().first}, {"max", objective.rest_offset_stats_mm().second}}
                                                                         : json(nullptr)},
                        {"meshing_s", mesh_s},
                        {"quality", {{"min_dihedral_deg", quality.min_dihedral_deg}, {"max_dihedral_deg", quality.max_dihedral_deg},
                                     {"min_radius_ratio", quality.min_radius_ratio}, {"mean_edge_mm", quality.mean_edge_mm}, {"below_10_deg", quality.below_10_deg}}}};
    summary["parameters"] = {{"cell_size_mm", s.cell_size}, {"facet_distance_mm", s.facet_distance}, {"margin_mm", s.margin}, {"parametrisation", to_string(reg.parametrisation)},
                             {"iterations_per_phase", s.iterations}, {"max_cycles", s.cycles}, {"tolerance", s.tolerance}, {"rms_tolerance_mm", s.rms_tolerance},
                             {"estimate_moduli", s.estimate_moduli},
                             {"moduli_prior", s.moduli_prior == 0.0 ? json(nullptr) : json{{"factor", s.moduli_prior}, {"rms_mm", s.moduli_prior_rms},
                                                                                           {"form", "½ N r² Σ (ln(E/E_table) / ln factor)² over the estimated structures"}}},
                             {"bspline_grid_mm", s.bspline_grid}, {"demons_sigma_voxels", s.demons_sigma}};
    summary["estimated_moduli_pa"] = json::object();
    for (std::size_t j = 0; j < model_labels.size(); ++j) summary["estimated_moduli_pa"][std::to_string(model_labels[j])] = b.young_moduli_pa[j];
    summary["moduli_determined_by_the_data"] = json::object(); // per estimated structure (parameters.json: the sensitivity behind it)
    for (const auto& m : b.sensitivity) summary["moduli_determined_by_the_data"][std::to_string(model_labels[m.structure])] = m.determined;
    summary["initial_alignment"] = {{"mode", s.initial}, {"applied", result.aligned}, {"decision", result.alignment_decision}, {"min_reduction", s.initial_min_reduction},
                                    {"start", alignment.start}, {"rotation_deg", alignment.rotation_deg},
                                    {"translation_mm", {alignment.translation[0], alignment.translation[1], alignment.translation[2]}},
                                    {"rotation_matrix", {{alignment.rotation(0, 0), alignment.rotation(0, 1), alignment.rotation(0, 2)},
                                                         {alignment.rotation(1, 0), alignment.rotation(1, 1), alignment.rotation(1, 2)},
                                                         {alignment.rotation(2, 0), alignment.rotation(2, 1), alignment.rotation(2, 2)}}},
                                    {"convention", "x_fixed = R x_moving + t; every method's field includes it"},
                                    {"centroid_distance_before_mm", alignment.centroid_distance_mm},
                                    {"max_plausible_rotation_deg", s.initial_max_rotation},
                                    {"boundary_rms_distance_mm", {{"before", alignment.rms_boundary_distance_before_mm}, {"after", alignment.rms_boundary_distance_mm}}},
                                    {"mesh_frame", !result.aligned ? "moving" : "fixed, after the initial alignment (mesh.vtu displacement: the non-rigid part)"}};
    if (!alignment.hypotheses.empty()) {
        json& a = summary["initial_alignment"];
        a["pose_decision"] = alignment.decision;
        for (const auto& h : alignment.hypotheses)
            a["hypotheses"].push_back({{"start", h.start}, {"rms_boundary_distance_mm", h.rms_boundary_distance_mm}, {"rotation_deg", h.rotation_deg},
                                       {"plausible", h.plausible}, {"chosen", h.start == alignment.start}});
        if (!alignment.runner_up.empty())
            a["runner_up"] = {{"start", alignment.runner_up}, {"rotation_from_winner_deg", alignment.runner_up_rotation_deg},
                              {"rms_margin_mm", alignment.runner_up_margin_mm}};
    }
    summary["methods"] = methods_json;
    return summary;
}

} // namespace

ImageRegistrationResult register_images(const ImagePair& original, const ImageRegistrationSettings& settings,
                                        const std::function<void(double, const std::string&)>& progress)
{
    const auto start = std::chrono::steady_clock::now();
    const auto report = [&](double f, const std::string& m) {
        if (progress) progress(f, m);
    };
    validate(settings, SettingNaming::option);
    const auto same = [](const ImageGeometry& a, const ImageGeometry& b) { return a.size == b.size && (a.origin - b.origin).norm() < 1e-6 && (a.spacing - b.spacing).norm() < 1e-9; };
    if (!same(original.fixed.geometry, original.fixed_labels.geometry)) fail("register-images: the fixed image and --fixed-labels are on different grids");
    if (!same(original.moving.geometry, original.moving_labels.geometry)) fail("register-images: the moving image and --moving-labels are on different grids");
    if (!original.intensities && settings.baselines == "intensity")
        fail("register-images: --baselines intensity needs the --fixed and --moving images (only label maps were given: use --baselines labels)");
    if (original.landmarks_fixed.has_value() != original.landmarks_moving.has_value())
        fail("register-images: give both --landmarks-fixed and --landmarks-moving, or neither");

    ImageRegistrationResult result;
    result.settings = settings;
    result.settings.hold = settings.hold == "auto" ? original.auto_hold : settings.hold;
    const ImageRegistrationSettings& s = result.settings;
    if (s.hold != "posterior" && s.hold != "none") fail("--hold '{}': use posterior, none or auto", s.hold);

    // 1. Structures and tissues.
    result.structures = resolve_structures(original, settings.structures);
    const std::vector<std::int32_t>& structures = result.structures;
    const TissueTable tissues = resolve_tissues(original, structures);

    // 2. Initial alignment.
    report(0.01, "initial alignment");
    const InitialAlignment initial_mode = parse_initial_alignment(s.initial);
    result.alignment = align_segmentations(original.fixed_labels, original.moving_labels, structures, initial_mode, s.initial_max_rotation);
    const SegmentationAlignment& alignment = result.alignment;
    if (initial_mode != InitialAlignment::identity)
        logger()->info("register-images: initial alignment ({}, start {}): rotation {:.2f}°, translation ({:.1f}, {:.1f}, {:.1f}) mm; structures' boundary RMS "
                       "distance {:.2f} → {:.2f} mm", s.initial, alignment.start, alignment.rotation_deg, alignment.translation[0], alignment.translation[1],
                       alignment.translation[2], alignment.rms_boundary_distance_before_mm, alignment.rms_boundary_distance_mm);
    if (initial_mode == InitialAlignment::rigid) {
        logger()->info("register-images: initial alignment: {}", alignment.decision);
        if (!alignment.runner_up.empty())
            logger()->info("register-images: initial alignment: runner-up {} ({:.1f}° from the winner), {:+.2f} mm RMS boundary distance",
                           alignment.runner_up, alignment.runner_up_rotation_deg, alignment.runner_up_margin_mm);
    }
    std::tie(result.aligned, result.alignment_decision) = alignment_decision(alignment, s);
    if (initial_mode != InitialAlignment::identity) logger()->info("register-images: initial alignment {}", result.alignment_decision);
    const ImagePair in = result.aligned ? aligned_pair(original, alignment) : original;
    if (!result.aligned) require_overlap(in);

    // 3. Region, mesh, supports.
    result.region = region_of_interest(in, structures, s.margin);
    const ImageGeometry& roi = result.region;
    const ScalarImage fixed = crop<ScalarImage>(in.fixed, roi, in.fixed.values);
    const LabelVolume fixed_labels = crop<LabelVolume>(in.fixed_labels, roi, in.fixed_labels.labels);
    logger()->info("register-images: structures {}, region {}×{}×{} voxels", fmt::join(structures, ","), roi.size[0], roi.size[1], roi.size[2]);
    report(0.02, "meshing");
    const ImageModel model = build_image_model(in, fixed_labels, structures, tissues, s, result);
    const VolumeMesh& mesh = result.mesh;
    const std::vector<std::int32_t>& model_labels = model.labels;

    // 4. The biomechanical registration and its dense inverse field.
    result.methods.push_back({"at_rest", zero_field(roi), std::nullopt, {}, 0.0, json::object()});
    report(0.05, "biomechanical registration");
    const SegmentationRegistrationOptions reg = s.solver_options();
    result.biomechanical = register_segmentation(mesh, model.elastic, *model.objective, model.force_nodes, model.initial_e, reg, [&](double f, const std::string& m) { report(0.05 + 0.45 * f, m); });
    const SegmentationRegistrationResult& b = result.biomechanical;
    if (b.inverted_elements > 0)
        logger()->warn("register-images: {} of {} tetrahedra are inverted in the biomechanical result (summary.json: model.inverted_elements); the dense field is "
                       "still written", b.inverted_elements, mesh.cell_count());
    result.methods.push_back(biomechanical_outcome(in, mesh, model_labels, b, reg, roi, s));

    // 5. Baselines.
    run_baselines(in, fixed, fixed_labels, roi, structures, s, result, report);

    // 6. Every method through the alignment, evaluated.
    report(0.92, "evaluation");
    auto& methods = result.methods;
    const json methods_json = evaluate_methods(original, in, fixed_labels, structures, s, result);

    // The written result: the chosen method (baselines: on intensities when run, else labels).
    std::optional<std::size_t> chosen;
    for (std::size_t k = 0; k < methods.size(); ++k)
        if (methods[k].name == s.method || methods[k].name == s.method + "_intensity" || (!chosen && methods[k].name == s.method + "_labels")) chosen = k;
    if (!chosen) fail("register-images: method {} was not run", s.method);
    result.chosen = *chosen;
    if (original.intensities) result.warped_moving = resample_image(original.moving, result.chosen_method().field, 0.0f);

    // 7. parameters.json and summary.json.
    result.parameters = parameters_json(model, tissues, b, reg);
    result.summary = summary_json(original, s, result, model, methods_json, reg);
    result.summary["biomechanical_against_baselines"] = against_baselines(result, fixed_labels, structures, methods_json);
    if (const auto& r = result.summary["biomechanical_against_baselines"]; r.contains("reading") && r["reading"].get<std::string>().rfind("no baseline", 0) != 0)
        logger()->warn("register-images: {}", r["reading"].get<std::string>());
    result.summary["seconds"] = seconds_since(start);
    return result;
}

} // namespace physreg
