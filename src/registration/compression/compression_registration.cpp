// SPDX-License-Identifier: GPL-3.0-or-later
// Paper 000's pipelines: the settings, the subject (body at rest and its model), a compression
// predicted, the parameters estimated, the coarse-to-fine scheme's plan and prediction.
#include "physreg/registration/compression/compression_registration.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/mesh/hex_meshing.hpp"

#include <chrono>
#include <cmath>
#include <limits>

namespace physreg {
using nlohmann::json;

namespace {

constexpr double infinity = std::numeric_limits<double>::infinity();

/// The model and solver entries every paper-000 mode shares (S derives from CompressionSettings).
template <typename S>
void add_model_entries(SettingsSpec<S>& s, std::vector<std::string> solvers)
{
    using C = CompressionSettings;
    std::string solver_help = "static solver: relaxation (dynamic relaxation, default: the faster on these models) or newton (Newton's method, "
                              "assembled tangent, stale-factor PCG)";
    if (solvers.size() > 2)
        solver_help += "; condensed: the model linearised at rest, contact condensed onto the skin nodes the tool reaches (milliseconds per update)";
    s.choice("variant", "--variant", &C::variant, {"homogeneous", "shared-nodes", "coupled"},
             "model: homogeneous (Han et al.), shared-nodes (per-element materials) or coupled (MLS penalty coupling, paper 000)")
        .choice("region", "--region", &C::region, {"body", "liver"},
                "what the model covers: body (the gel body with the organs inside, bone held, base on the table) or liver (the liver alone, "
                "posterior surface held)")
        .text("grid", "--grid", &C::grid,
              "cells over the region's bounding box per image axis, e.g. 54x40x26 (empty: body 54x40x26, liver 74x54x18, or one cell per voxel "
              "where the region spans fewer voxels)")
        .real("body_modulus", "--body-modulus", &C::body_modulus, "Pa", "Young's modulus of the gel body (region body), Pa", 0.0, infinity, true)
        .real("k_tumour", "--k-tumour", &C::k_tumour, "N/m", "parenchyma–tumour coupling stiffness k_c,s-t, N/m (paper 000: 600)", 0.0)
        .real("k_vessel", "--k-vessel", &C::k_vessel, "N/m", "parenchyma–vessel coupling stiffness k_c,s-v, N/m (paper 000: 500)", 0.0)
        .real("support_radius", "--support-radius", &C::support_radius, "cells", "MLS support radius, element sizes", 0.0, infinity, true)
        .choice("solver", "--solver", &C::solver, std::move(solvers), solver_help)
        .real("tool_speed", "--tool-speed", &C::tool_speed, "cells",
              "largest tool travel per relaxation iteration, in cell sizes (lower it if elements under the tool invert)", 0.0, 0.5, true)
        .real("tolerance", "--tolerance", &C::tolerance, "mm", "equilibrium: estimated distance to equilibrium, mm", 0.0, 1.0, true)
        .real("residual", "--residual", &C::residual, "", "equilibrium: largest free residual / largest internal force", 0.0, 1.0, true, true);
}

/// The checks every mode shares beyond the specification's ranges: the grid's form, the model.
void validate_model(const CompressionSettings& s, const std::function<std::string(const char*)>& name)
{
    if (!s.grid.empty()) parse_grid_dims(s.grid, name("grid"));
    try {
        s.model_parameters();
    } catch (const Error& e) {
        fail("model parameters: {}", e.what());
    }
}

/// The model is the subject's: settings that describe another one are an error, not ignored.
void require_subject_model(const CompressionSubject& subject, const CompressionSettings& settings)
{
    if (const auto keys = settings.model_keys_differing(subject.settings); !keys.empty())
        fail("settings {}: the model was built with other values (the subject's model is fixed when it is made); make the subject with "
             "these settings", fmt::join(keys, ", "));
}

TreReport at_rest_report(const LandmarkSet& rest, const LandmarkSet& truth, const std::string& what)
{
    return compute_tre(rest, truth, what + " (landmarks at rest)");
}

} // namespace

// ---- settings -------------------------------------------------------------------------------------

ModelParameters CompressionSettings::model_parameters(ModelParameters p) const
{
    p.variant = parse_model_variant(variant);
    p.region = parse_model_region(region);
    p.body_young_pa = body_modulus;
    if (!grid.empty()) p.grid = parse_grid_dims(grid, "grid");
    p.coupling.parenchyma_tumour_n_per_m = k_tumour;
    p.coupling.parenchyma_vessel_n_per_m = k_vessel;
    p.support_radius_cells = support_radius;
    p.validate();
    return p;
}

PredictionOptions CompressionSettings::prediction_options() const
{
    PredictionOptions p;
    p.method = parse_static_method(solver == "condensed" ? "relaxation" : solver);
    p.tool_speed_per_cell = tool_speed;
    p.equilibrium.displacement_tolerance_mm = tolerance;
    p.equilibrium.residual_tolerance = residual;
    return p;
}

std::vector<std::string> CompressionSettings::model_keys_differing(const CompressionSettings& d) const
{
    std::vector<std::string> keys;
    if (variant != d.variant) keys.push_back("variant");
    if (region != d.region) keys.push_back("region");
    if (grid != d.grid) keys.push_back("grid");
    if (body_modulus != d.body_modulus) keys.push_back("body_modulus");
    if (k_tumour != d.k_tumour) keys.push_back("k_tumour");
    if (k_vessel != d.k_vessel) keys.push_back("k_vessel");
    if (support_radius != d.support_radius) keys.push_back("support_radius");
    return keys;
}

std::size_t CompressionRegistrationSettings::memory_limit_bytes() const
{
    return parse_memory_size(memory_limit, "memory_limit");
}

const SettingsSpec<CompressionRegistrationSettings>& compression_spec()
{
    using S = CompressionRegistrationSettings;
    static const SettingsSpec<S> spec = [] {
        SettingsSpec<S> s("register-compression");
        add_model_entries(s, {"relaxation", "newton", "condensed"});
        s.integer("tool_updates", "--tool-updates", &S::tool_updates, "solver condensed: tool positions from first contact to the final one", 1, 1e6)
            .text("memory_limit", "--memory-limit",
                  &S::memory_limit, "solver condensed: memory the precomputation may take (factor, compliance), e.g. 8G; auto: 80 % of the "
                                    "physical memory. Over it: an error naming the size needed")
            .real("field_spacing", "--field-spacing", &S::field_spacing, "mm", "voxel size of the displacement field over the mesh, mm", 0.0, infinity, true);
        return s;
    }();
    return spec;
}

void validate(const CompressionRegistrationSettings& s, SettingNaming naming)
{
    const auto& spec = compression_spec();
    spec.validate(s, naming);
    const auto name = [&](const char* key) { return spec.name(key, naming); };
    validate_model(s, name);
    parse_memory_size(s.memory_limit, name("memory_limit"));
}

EstimationOptions EstimationSettings::estimation_options() const
{
    EstimationOptions options;
    options.fit_moduli = fit_moduli;
    options.fit_body_modulus = !fixed_body_modulus;
    options.k_min_n_per_m = k_min;
    options.k_max_n_per_m = k_max;
    options.algorithm = optimizer;
    options.max_evaluations = max_evaluations;
    options.prediction = prediction_options();
    return options;
}

const SettingsSpec<EstimationSettings>& estimation_spec()
{
    using S = EstimationSettings;
    static const SettingsSpec<S> spec = [] {
        SettingsSpec<S> s("estimate");
        add_model_entries(s, {"relaxation", "newton"});
        s.text("train", "--train", &S::train, "training compressions, e.g. A,B,C")
            .text("validate", "--validate", &S::validate, "held-out compressions, e.g. D,E (none: no validation)")
            .flag("fit_moduli", "--fit-moduli", &S::fit_moduli, "also fit the tumour and vessel Young's moduli (log-scaled, 1e4 … 1e8 Pa)")
            .flag("fixed_body_modulus", "--fixed-body-modulus", &S::fixed_body_modulus,
                  "region body: keep the gel's modulus (body_modulus) instead of fitting it (log-scaled, 2e3 … 2e6 Pa)")
            .real("k_min", "--k-min", &S::k_min, "N/m", "lower bound of the coupling stiffnesses, N/m", 0.0, infinity, true)
            .real("k_max", "--k-max", &S::k_max, "N/m", "upper bound of the coupling stiffnesses, N/m", 0.0, infinity, true)
            .choice("optimizer", "--optimizer", &S::optimizer, {"bobyqa", "neldermead"}, "NLopt's derivative-free optimiser: bobyqa or neldermead")
            .integer("max_evaluations", "--max-evaluations", &S::max_evaluations, "objective evaluations at most", 1, 1e6);
        return s;
    }();
    return spec;
}

void validate(const EstimationSettings& s, SettingNaming naming)
{
    const auto& spec = estimation_spec();
    spec.validate(s, naming);
    const auto name = [&](const char* key) { return spec.name(key, naming); };
    validate_model(s, name);
    split_names(s.train, name("train"));
    if (s.validate != "none") split_names(s.validate, name("validate"));
    if (!(s.k_max > s.k_min)) fail("{} {} N/m must exceed {} {} N/m", name("k_max"), s.k_max, name("k_min"), s.k_min);
}

const SettingsSpec<EnrichmentBuildSettings>& enrichment_build_spec()
{
    using S = EnrichmentBuildSettings;
    static const SettingsSpec<S> spec = [] {
        SettingsSpec<S> s("enrich-build");
        add_model_entries(s, {"relaxation", "newton"});
        s.text("coarse_grid", "--coarse-grid", &S::coarse_grid, "coarse model cells over the liver (paper 000: 24x18x18)")
            .text("positions", "--positions", &S::positions, "compressions of the dataset whose entry points are used (empty: all)")
            .text("positions_grid", "--positions-grid", &S::positions_grid,
                  "instead: CxR tool positions on a grid over the skin above the liver (central 70 %), each where the dataset's tool (a sphere) "
                  "first touches the body")
            .text("depths", "--depths", &S::depths, "tool depths beyond first contact, mm, increasing (empty: 2 mm steps to the deepest compression)")
            .integer("depth_count", "--depth-count", &S::depth_count, "instead of depths: this many depths evenly up to max_depth (0: off)", 0, 1e6)
            .real("max_depth", "--max-depth", &S::max_depth, "mm", "with depth_count: the deepest, mm", 0.0)
            .integer("orientations", "--orientations", &S::orientations, "pressing directions per position: the nominal one and N−1 tilted ones", 1, 1e4)
            .real("tilt", "--tilt", &S::tilt, "degrees", "tilt of the other directions, degrees", 0.0, 90.0);
        return s;
    }();
    return spec;
}

void validate(const EnrichmentBuildSettings& s, SettingNaming naming)
{
    const auto& spec = enrichment_build_spec();
    spec.validate(s, naming);
    const auto name = [&](const char* key) { return spec.name(key, naming); };
    validate_model(s, name);
    parse_grid_dims(s.coarse_grid, name("coarse_grid"));
    if (!s.positions.empty() && !s.positions_grid.empty()) fail("{} and {} exclude each other", name("positions"), name("positions_grid"));
    if (!s.depths.empty()) parse_number_list(s.depths, name("depths"));
    if (s.depth_count > 0 && !(s.max_depth > 0)) fail("{} needs {} > 0 mm", name("depth_count"), name("max_depth"));
}

const SettingsSpec<EnrichmentApplySettings>& enrichment_apply_spec()
{
    using S = EnrichmentApplySettings;
    static const SettingsSpec<S> spec = [] {
        SettingsSpec<S> s("enrich-apply");
        add_model_entries(s, {"relaxation", "newton"});
        s.choice("match", "--match", &S::match, {"parameters", "field"},
                 "parameters (tool position, direction, depth; paper 000) or field (coarse displacement similarity)")
            .text("blend", "--blend", &S::blend, "conditions blended: auto (leave-one-out best of 1…4) or a number")
            .text("detail_length", "--detail-length", &S::detail_length,
                  "share of the stored detail against the distance d to the nearest stored condition, 1/(1+(d/L)²), the rest the coarse field: "
                  "inf (paper 000: all detail at any distance), L in mm, or auto (the leave-one-position-out best around the rest landmarks; "
                  "measured unreliable, docs/enrichment.md)")
            .real("field_spacing", "--field-spacing", &S::field_spacing, "mm", "voxel size of the displacement field, mm", 0.0, infinity, true);
        return s;
    }();
    return spec;
}

void validate(const EnrichmentApplySettings& s, SettingNaming naming)
{
    const auto& spec = enrichment_apply_spec();
    spec.validate(s, naming);
    const auto name = [&](const char* key) { return spec.name(key, naming); };
    validate_model(s, name);
    if (s.blend != "auto") {
        const auto k = parse_number(s.blend);
        if (!k) fail("{}: '{}' is neither auto nor a number", name("blend"), s.blend);
        if (to_integer<int>(*k, name("blend"), "the number of blended database entries") < 1) fail("{} must be ≥ 1 (got {})", name("blend"), s.blend);
    }
    if (s.detail_length != "auto" && s.detail_length != "inf") {
        const auto l = parse_number(s.detail_length);
        if (!l || !(*l >= 0.0)) fail("{}: '{}' is not auto, inf or a length ≥ 0 mm", name("detail_length"), s.detail_length);
    }
}

// ---- 1. the subject ------------------------------------------------------------------------------

CompressionSubject make_compression_subject(LabelVolume labels, const LabelRoles& roles, LandmarkSet rest_landmarks,
                                            const CompressionSettings& settings, const std::string& parameters_file,
                                            const std::string& labels_source)
{
    CompressionSubject out;
    out.labels = std::move(labels);
    out.roles = roles;
    out.rest_landmarks = std::move(rest_landmarks);
    out.settings = settings;
    out.parameters_file = parameters_file;
    ModelParameters p;
    std::string fingerprint;
    if (!parameters_file.empty()) {
        p = read_model_parameters(parameters_file, &fingerprint);
        if (const auto set = settings.model_keys_set(); !set.empty())
            fail("--parameters '{}': the model comes from the parameter file; drop {} (variant, region, grid, body_modulus, k_tumour, "
                 "k_vessel and support_radius are fixed by the file)", parameters_file, fmt::join(set, ", "));
    } else {
        // Without a grid the grid comes from the labels (paper 000's, or one cell per voxel on a
        // coarse image such as the small preset's).
        if (settings.grid.empty()) p.grid = default_model_grid(out.labels, roles, parse_model_region(settings.region));
        try {
            p = settings.model_parameters(p);
        } catch (const Error& e) {
            fail("model parameters: {}", e.what());
        }
    }
    out.model = build_liver_model(out.labels, roles, p, labels_source);
    if (!fingerprint.empty() && fingerprint != out.model.fingerprint)
        fail("--parameters '{}': fitted on another mesh (fingerprint {}, this dataset's model {}); estimate again for this dataset",
             parameters_file, fingerprint, out.model.fingerprint);
    return out;
}

CompressionSubject read_dataset_compression_subject(const std::filesystem::path& dataset_directory, const CompressionSettings& settings,
                                                    const std::string& parameters_file)
{
    const PhantomDataset dataset = read_phantom_dataset(dataset_directory);
    const DatasetState& rest = dataset.state("rest");
    const auto labels_path = dataset.path(rest.files.at("labels"));
    CompressionSubject out = make_compression_subject(read_label_volume(labels_path), dataset.roles,
                                                      read_landmarks(dataset.path(rest.files.at("landmarks"))), settings, parameters_file,
                                                      labels_path.string());
    out.description = {{"dataset", std::filesystem::absolute(dataset_directory).string()}, {"parameters", parameters_file}};
    return out;
}

// ---- 2. a compression predicted ------------------------------------------------------------------

CompressionPrediction predict_compression_with_fallback(const LiverModel& model, const Indenter& tool, const LandmarkSet& rest_landmarks,
                                                        const PredictionOptions& options, const std::string& what, int tool_updates,
                                                        const CondensedContactOptions& condensed, std::string* fallback,
                                                        CondensedPrecomputation* precomputation, double* ms_per_update)
{
    try {
        return predict_compression(model, tool, rest_landmarks, options, what);
    } catch (const Interrupted&) {
        throw;
    } catch (const Error& e) {
        // A hard case is not bad input (issue 46 item 2): when the Neo-Hookean model folds an element
        // under the tool even at the slowest ramp, or its solve stalls, the model linearised at rest
        // with the contact condensed (which cannot fold) answers instead, and the caller says so.
        const std::string message = e.what();
        const bool folded = message.find("inverted") != std::string::npos, stalled = message.find("no equilibrium") != std::string::npos;
        if (!folded && !stalled) throw;
        const std::string why = folded ? "an element folded under the tool" : "the solve stalled short of equilibrium";
        logger()->warn("{}: the nonlinear model failed: {} ({}); answering with the model linearised at rest and condensed contact instead, "
                       "less accurate for deep pushes",
                       what, why, message);
        CompressionPrediction out = predict_compression_condensed(model, tool, rest_landmarks, tool_updates, what, condensed, precomputation, ms_per_update);
        if (fallback) *fallback = fmt::format("{} ({}); the answer is the linearised model's (condensed contact)", why, message);
        return out;
    }
}

CompressionRegistrationResult register_compression(const CompressionSubject& subject, const CompressionCase& observed,
                                                   const CompressionRegistrationSettings& settings, const std::function<void(double, const std::string&)>& progress)
{
    validate(settings, SettingNaming::option);
    require_subject_model(subject, settings);
    const auto report = [&](double f, const std::string& m) {
        if (progress) progress(f, m);
    };
    const LiverModel& model = subject.model;
    const ModelParameters& p = model.parameters;
    const std::string what = "compression " + observed.name;
    CompressionRegistrationResult r;
    r.settings = settings;
    r.state = observed.name;
    report(0.05, fmt::format("{} model: {} nodes, {} hexahedra, {} interface points", to_string(p.variant), model.mesh.node_count(),
                             model.mesh.cell_count(), model.coupling.points().size()));
    // condensed: the model linearised at rest and the contact condensed onto the skin nodes the
    // tool reaches; the other solvers reach the Neo-Hookean equilibrium.
    const bool condensed = settings.solver == "condensed";
    if (condensed) {
        CondensedContactOptions options;
        options.memory_limit_bytes = settings.memory_limit_bytes();
        r.prediction = predict_compression_condensed(model, observed.tool, subject.rest_landmarks, settings.tool_updates, what, options,
                                                     &r.condensed, &r.condensed_ms_per_update);
    } else {
        CondensedContactOptions options;
        options.memory_limit_bytes = settings.memory_limit_bytes();
        r.prediction = predict_compression_with_fallback(model, observed.tool, subject.rest_landmarks, settings.prediction_options(), what, settings.tool_updates,
                                                         options, &r.fallback, &r.condensed, &r.condensed_ms_per_update);
        if (!r.fallback.empty()) r.fallback = fmt::format("the {} solver: {}", settings.solver, r.fallback);
    }
    // A tool that never reaches the model leaves it at rest: say so instead of a silent zero.
    r.contact = r.prediction.max_displacement_mm > 1e-6;
    if (!r.contact)
        logger()->warn("{}: no contact: the tool never touches the model (largest displacement {:.2g} mm), so the prediction is the "
                       "landmarks at rest (with region liver: the tool presses the skin, not the liver)",
                       what, r.prediction.max_displacement_mm);
    report(0.7, "dense displacement field");
    const ImageGeometry geometry = image_grid_over_mesh(model.mesh, settings.field_spacing, 2.0 * model.cell_size_mm.maxCoeff());
    r.field = sample_displacement_field(model.mesh, r.prediction.displacement_mm, geometry);
    if (!observed.truth.empty()) {
        r.tre = compute_tre(r.prediction.landmarks, observed.truth, what);
        r.at_rest = at_rest_report(subject.rest_landmarks, observed.truth, what);
    }

    json& s = r.summary;
    s = {{"state", observed.name},
         {"model", to_json(p)},
         {"nodes", model.mesh.node_count()},
         {"hexahedra", model.mesh.cell_count()},
         {"interface_points", model.coupling.points().size()},
         {"method", settings.solver},
         {"iterations", r.prediction.iterations},
         {"seconds", r.prediction.seconds},
         {"max_displacement_mm", r.prediction.max_displacement_mm},
         {"tool_contact", r.contact ? "contact" : "no contact"},
         {"max_coupling_gap_mm", r.prediction.max_coupling_gap_mm},
         {"slower_tool_ramps", r.prediction.slower_ramps},
         {"files", {{"mesh", "mesh.vtu"}, {"landmarks", "landmarks.csv"}, {"displacement", "displacement.nii.gz"}}},
         {"units", "mm, LPS; displacement field in the rest (pre-operative) space: x → x + u(x)"},
         {"command", "register-compression"},
         {"settings", compression_spec().to_json(settings)}};
    if (r.tre) {
        s["tre_against_dataset"] = json::parse(tre_stats_json(*r.tre));
        s["tre_landmarks_at_rest"] = json::parse(tre_stats_json(*r.at_rest)); // the baseline: doing nothing
        s["tre_per_landmark"] = json::parse(tre_report_json(*r.tre))["landmarks"];
    }
    if (!r.fallback.empty()) {
        s["fallback"] = r.fallback;
        s["method"] = "condensed (fallback)";
        s["notes"] = json::array({r.fallback});
    }
    if (condensed || !r.fallback.empty())
        s["condensed"] = {{"law", "the model's Neo-Hookean tangent at rest (linear)"}, {"tool_updates", r.prediction.iterations},
                          {"ms_per_update", r.condensed_ms_per_update}, {"candidate_nodes", r.condensed.candidate_nodes},
                          {"precomputation_s", r.condensed.assembly_s + r.condensed.factorisation_s + r.condensed.compliance_s},
                          {"factor_nonzeros", r.condensed.factor_nonzeros}, {"memory_bytes", r.condensed.memory_bytes},
                          {"memory_limit_bytes", r.condensed.memory_limit_bytes}};
    s["inputs"] = subject.description;
    s["inputs"]["state"] = observed.name;
    report(1.0, "done");
    return r;
}

// ---- 3. parameters estimated ---------------------------------------------------------------------

CompressionEstimationRun estimate_compression(const CompressionSubject& subject, const PhantomDataset& dataset, const EstimationSettings& settings,
                                              const std::function<void(double, const std::string&)>& progress)
{
    validate(settings, SettingNaming::option);
    const auto train = compression_cases(dataset, split_names(settings.train, "--train"));
    const auto validation = settings.validate == "none" ? std::vector<CompressionCase>{} : compression_cases(dataset, split_names(settings.validate, "--validate"));
    CompressionEstimationRun run;
    run.result = estimate_parameters(subject.labels, subject.roles, subject.model.parameters, subject.rest_landmarks, train, validation,
                                     settings.estimation_options(), progress);
    const EstimationResult& r = run.result;
    const std::string source = dataset.directory.string();
    json& s = run.summary;
    s["dataset"] = source;
    s["optimiser"] = r.optimiser;
    s["stop_reason"] = r.stop_reason;
    s["evaluations"] = r.history.size();
    s["seconds"] = r.seconds;
    s["objective"] = "mean TRE over every landmark of the training compressions, mm";
    s["objective_mm"] = r.objective_mm;
    s["fitted"] = to_json(r.fitted);
    s["free_parameters"] = r.free_parameters;
    s["at_bound"] = r.at_bound; // fitted parameters that ended at a bound (the optimum may lie beyond)
    s["infeasible_evaluations"] = r.infeasible_evaluations;
    for (const auto& x : r.sensitivity)
        s["identifiability"][x.parameter] = {{"objective_change_mm_per_decade", x.mm_per_decade}, {"one_parameter_steps", x.evaluations},
                                             {"identifiable", x.identifiable}, {"threshold_mm_per_decade", EstimationResult::identifiable_mm_per_decade}};
    s["mesh_fingerprint"] = r.fingerprint;
    s["train"] = json::parse(tre_stats_json(r.train_pooled));
    if (!r.validation.empty()) s["validation"] = json::parse(tre_stats_json(r.validation_pooled));
    s["baseline_landmarks_at_rest"]["train"] = json::parse(tre_stats_json(r.train_at_rest));
    if (!r.validation.empty()) s["baseline_landmarks_at_rest"]["validation"] = json::parse(tre_stats_json(r.validation_at_rest));
    for (const auto& [name, rep] : r.train) s["per_compression"][name] = json::parse(tre_stats_json(rep));
    for (const auto& [name, rep] : r.validation) s["per_compression"][name] = json::parse(tre_stats_json(rep));
    run.fit = {{"objective_mm", r.objective_mm}, {"train", s["train"]}, {"validation", s.value("validation", json())},
               {"optimiser", r.optimiser}, {"evaluations", r.history.size()}, {"dataset", source}, {"at_bound", r.at_bound}};
    run.report = s;
    for (const auto& step : r.history)
        run.report["history"].push_back({{"parameters", to_json(step.parameters)}, {"objective_mm", step.objective_mm}});
    for (const auto& [name, rep] : r.train) run.report["landmarks"][name] = json::parse(tre_report_json(rep));
    for (const auto& [name, rep] : r.validation) run.report["landmarks"][name] = json::parse(tre_report_json(rep));
    return run;
}

// ---- 4. the coarse-to-fine scheme ----------------------------------------------------------------

EnrichmentBuildPlan enrichment_build_plan(const CompressionSubject& subject, const PhantomDataset& dataset, const EnrichmentBuildSettings& settings)
{
    validate(settings, SettingNaming::option);
    EnrichmentBuildPlan out;
    out.coarse_grid = parse_grid_dims(settings.coarse_grid, "--coarse-grid");
    // Entry points and tool of the dataset's compressions.
    std::vector<std::string> names;
    if (!settings.positions.empty()) names = split_names(settings.positions, "--positions");
    else
        for (const auto& s : dataset.states)
            if (s.tool && s.kind == "compression") names.push_back(s.name); // not the organs-only push
    if (names.empty()) fail("dataset '{}' has no tool compression to take positions from", dataset.directory.string());
    EnrichmentPlan& plan = out.plan;
    double deepest = 0.0;
    for (const auto& name : names) {
        const auto& state = dataset.state(name);
        if (!state.tool) fail("--positions: state '{}' is not a tool compression", name);
        plan.positions.push_back({name, state.tool->path.front()});
        plan.direction = (state.tool->path.back() - state.tool->path.front()).normalized();
        deepest = std::max(deepest, state.depth_mm);
    }
    out.shape = *dataset.state(names.front()).tool;
    if (!settings.positions_grid.empty()) {
        const auto x = settings.positions_grid.find('x');
        const auto columns = x == std::string::npos ? std::nullopt : parse_number(settings.positions_grid.substr(0, x));
        const auto rows = x == std::string::npos ? std::nullopt : parse_number(settings.positions_grid.substr(x + 1));
        if (!columns || !rows) fail("--positions-grid: '{}' is not CxR (e.g. 3x2)", settings.positions_grid);
        plan.positions = skin_grid_positions(subject.labels, subject.roles, out.shape, plan.direction,
                                             to_integer<int>(*columns, "--positions-grid", "columns"), to_integer<int>(*rows, "--positions-grid", "rows"));
    }
    if (!settings.depths.empty()) {
        plan.depths_mm = parse_number_list(settings.depths, "--depths");
    } else if (settings.depth_count > 0) {
        for (int i = 1; i <= settings.depth_count; ++i) plan.depths_mm.push_back(settings.max_depth * i / settings.depth_count);
    } else {
        for (double d = 2.0; d <= deepest + 1e-9; d += 2.0) plan.depths_mm.push_back(d);
    }
    plan.orientations = settings.orientations;
    plan.tilt_deg = settings.tilt;
    plan.validate();
    return out;
}

int enrichment_blend_size(const std::string& text, const EnrichmentDatabase& db, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                          const LiverModel& fine, std::vector<double>* loo_mm)
{
    if (text == "auto") return choose_blend_size(db, coarse.mesh, fine_nodes, fine.mesh.nodes, 4, loo_mm);
    const auto number = parse_number(text);
    if (!number) fail("--blend: '{}' is neither auto nor a number", text);
    const int k = to_integer<int>(*number, "--blend", "the number of blended database entries");
    if (k < 1) fail("--blend must be ≥ 1 (got {})", k);
    return k;
}

double enrichment_detail_length(const std::string& text, const EnrichmentDatabase& db, const LiverModel& coarse,
                                const std::vector<NodeEmbedding>& fine_nodes, const LiverModel& fine, EnrichmentMatching how, int k,
                                const LandmarkSet& rest_landmarks, std::vector<std::pair<double, double>>* loo_mm)
{
    if (text == "auto") {
        std::vector<Vec3> targets;
        for (const auto& l : rest_landmarks) targets.push_back(l.position);
        const auto scored = targets.empty() ? std::vector<std::int32_t>{} : nodes_near(fine.mesh, targets, 2.0 * fine.cell_size_mm.maxCoeff());
        return choose_detail_length(db, coarse.mesh, fine_nodes, fine.mesh.nodes, how, k, loo_mm, scored);
    }
    if (text == "inf") return infinity;
    const auto number = parse_number(text);
    if (!number || !(*number >= 0.0)) fail("--detail-length: '{}' is not auto, inf or a length ≥ 0 mm", text);
    return *number;
}

CoarseToFineResult predict_compression_coarse_to_fine(const CompressionSubject& subject, const EnrichmentDatabase& db,
                                                       const CompressionCase& observed, const EnrichmentApplySettings& settings,
                                                       const std::string& database_source, const std::function<void(double, const std::string&)>& progress)
{
    validate(settings, SettingNaming::option);
    require_subject_model(subject, settings);
    const auto report = [&](double f, const std::string& m) {
        if (progress) progress(f, m);
    };
    const EnrichmentMatching how = parse_enrichment_matching(settings.match);
    const LiverModel& fine = subject.model;
    CoarseToFineResult r;
    r.settings = settings;
    r.state = observed.name;
    std::vector<NodeEmbedding> embedding;
    r.coarse = coarsen_liver_model(fine, db.coarse_grid(), &embedding);
    check_database_fits(db, fine, r.coarse, database_source);
    report(0.1, "blend size and detail length");
    std::vector<double> loo;
    r.blend_size = enrichment_blend_size(settings.blend, db, r.coarse, embedding, fine, &loo);
    std::vector<std::pair<double, double>> detail_loo;
    r.detail_length_mm = enrichment_detail_length(settings.detail_length, db, r.coarse, embedding, fine, how, r.blend_size, subject.rest_landmarks, &detail_loo);
    report(0.3, "coarse simulation, matching, synthesis");
    const std::string what = "compression " + observed.name;
    r.prediction = predict_coarse_to_fine(fine, r.coarse, embedding, db, observed.tool, subject.rest_landmarks, how,
                                          EnrichmentBlend(r.blend_size, r.detail_length_mm), settings.prediction_options(), what);
    const auto& prediction = r.prediction;
    if (prediction.match.outside_range)
        logger()->warn("{} lies outside the database's range: {}; the result is extrapolated from the nearest stored conditions", what,
                       prediction.match.range_note);
    report(0.8, "dense displacement field");
    const ImageGeometry geometry = image_grid_over_mesh(fine.mesh, settings.field_spacing, 2.0 * fine.cell_size_mm.maxCoeff());
    r.field = sample_displacement_field(fine.mesh, prediction.fine_u, geometry);
    if (!observed.truth.empty()) r.tre = compute_tre(prediction.landmarks, observed.truth, what);

    json matched = json::array();
    for (std::size_t i = 0; i < prediction.match.conditions.size(); ++i) {
        const auto& c = db.conditions[prediction.match.conditions[i]];
        matched.push_back({{"condition", prediction.match.conditions[i]}, {"position", c.position}, {"depth_mm", c.depth_mm},
                           {"distance", prediction.match.distances[i]}, {"blend", prediction.match.blend[i]}});
    }
    json detail_rows = json::array();
    for (const auto& [length, error] : detail_loo) detail_rows.push_back({{"detail_length_mm", length_json(length)}, {"error_mm", error}});
    json& s = r.summary;
    s = {{"state", observed.name},
         {"match", settings.match},
         {"blend_size", r.blend_size},
         {"leave_one_out_error_mm_per_blend_size", loo},
         {"detail_length_mm", length_json(r.detail_length_mm)},
         {"detail_share", prediction.match.detail},
         {"leave_one_position_out_error_mm_per_detail_length", detail_rows},
         {"nearest_stored_position_mm", prediction.match.nearest_position_mm},
         {"matched", matched},
         {"outside_range", prediction.match.outside_range},
         {"range_note", prediction.match.range_note},
         {"coarse_iterations", prediction.iterations},
         {"coarse_seconds", prediction.coarse_seconds},
         {"synthesis_seconds", prediction.synthesis_seconds},
         {"files", {{"mesh", "mesh.vtu"}, {"coarse", "coarse.vtu"}, {"landmarks", "landmarks.csv"}, {"displacement", "displacement.nii.gz"}}},
         {"command", "enrich apply"},
         {"settings", enrichment_apply_spec().to_json(settings)}};
    if (r.tre) s["tre_against_dataset"] = json::parse(tre_stats_json(*r.tre));
    s["inputs"] = subject.description;
    s["inputs"].erase("parameters");
    s["inputs"]["database"] = database_source;
    s["inputs"]["state"] = observed.name;
    report(1.0, "done");
    return r;
}

// ---- shared forms --------------------------------------------------------------------------------

json to_json(const ModelParameters& p)
{
    return {{"variant", to_string(p.variant)},
            {"region", to_string(p.region)},
            {"k_c_s_t_n_per_m", p.coupling.parenchyma_tumour_n_per_m},
            {"k_c_s_v_n_per_m", p.coupling.parenchyma_vessel_n_per_m},
            {"young_modulus_pa", {{"parenchyma", p.parenchyma_young_pa}, {"tumour", p.tumour_young_pa}, {"vessel", p.vessel_young_pa}, {"body", p.body_young_pa}}},
            {"grid_cells", {p.grid[0], p.grid[1], p.grid[2]}}};
}

json length_json(double length_mm)
{
    return std::isinf(length_mm) ? json("inf") : json(length_mm);
}

std::vector<std::string> split_names(const std::string& text, const std::string& name)
{
    std::vector<std::string> names;
    std::size_t start = 0;
    while (start < text.size()) {
        const std::size_t end = std::min(text.find(',', start), text.size());
        if (end > start) names.push_back(text.substr(start, end - start));
        start = end + 1;
    }
    if (names.empty()) fail("{}: no state names in '{}'", name, text);
    return names;
}

std::size_t parse_memory_size(const std::string& text, const std::string& name)
{
    if (text == "auto") return 0;
    std::size_t used = 0;
    double value = 0.0;
    try {
        value = std::stod(text, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    const std::string suffix = text.substr(used);
    double unit = 0.0;
    if (suffix.empty()) unit = 1.0;
    else if (suffix == "K" || suffix == "k") unit = 1024.0;
    else if (suffix == "M") unit = 1024.0 * 1024.0;
    else if (suffix == "G") unit = 1024.0 * 1024.0 * 1024.0;
    else if (suffix == "T") unit = 1024.0 * 1024.0 * 1024.0 * 1024.0;
    if (used == 0 || unit == 0.0 || !std::isfinite(value) || !(value > 0) || value * unit < 1.0 || value * unit > 1e18)
        fail("{} must be auto or a positive size such as 8G, 512M or 1e9 (bytes; K, M, G, T are powers of 1024), got '{}'", name, text);
    return static_cast<std::size_t>(value * unit);
}

} // namespace physreg
