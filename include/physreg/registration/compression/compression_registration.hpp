// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 000's pipelines, whole (issue 43): the functions that `physreg register-compression`,
// `estimate`, `enrich build|apply`, Python's physreg.register_compression / estimate_compression /
// predict_coarse_to_fine and `serve` call. Read top to bottom in compression_registration.cpp:
//   1. the subject: the body at rest (labels, roles, landmarks) and the model built on it, from the
//      settings or a parameter file fitted on the same mesh;
//   2. register_compression: the tool's path through the model (dynamic relaxation or Newton to the
//      Neo-Hookean equilibrium, or condensed contact on the model linearised at rest), the tool
//      passage check, the dense field, TRE against the truth and against doing nothing;
//   3. estimate_compression: coupling stiffnesses (and moduli) fitted to training compressions,
//      validated on held-out ones, with identifiability;
//   4. the coarse-to-fine scheme: the database's plan, and a prediction by coarse simulation,
//      matching and synthesis of the fine mesh.
// Settings: CompressionSettings (the model and its solver) and the modes' extensions, each
// specified once (compression_spec(), estimation_spec(), enrichment_build_spec(), enrichment_apply_spec()).
#include "physreg/core/settings_spec.hpp"
#include "physreg/evaluation/tre.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/io/dataset.hpp"
#include "physreg/registration/compression/condensed_contact.hpp"
#include "physreg/registration/compression/enrichment.hpp"
#include "physreg/registration/compression/estimation.hpp"
#include "physreg/registration/compression/liver_model.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace physreg {

/// The model and its solver, as every paper-000 mode takes them. Defaults are ModelParameters'
/// and PredictionOptions'; grid "" takes the dataset's (default_model_grid).
struct CompressionSettings {
    std::string variant = "coupled";          ///< homogeneous, shared-nodes, coupled
    std::string region = "body";              ///< body, liver
    std::string grid;                         ///< "54x40x26"; "": from the labels
    double body_modulus = ModelParameters{}.body_young_pa;                       ///< Pa
    double k_tumour = ModelParameters{}.coupling.parenchyma_tumour_n_per_m;      ///< N/m
    double k_vessel = ModelParameters{}.coupling.parenchyma_vessel_n_per_m;      ///< N/m
    double support_radius = ModelParameters{}.support_radius_cells;              ///< cells
    std::string solver = "relaxation";        ///< relaxation, newton, condensed (register-compression)
    double tool_speed = PredictionOptions{}.tool_speed_per_cell;                 ///< cells per iteration
    double tolerance = 1e-3;                  ///< mm
    double residual = 1e-3;

    /// The model these settings describe, starting from `start` (its grid when grid is "").
    ModelParameters model_parameters(ModelParameters start = {}) const;
    PredictionOptions prediction_options() const;
    /// The keys of the model (variant … support_radius) whose values differ from `other`'s.
    std::vector<std::string> model_keys_differing(const CompressionSettings& other) const;
    /// Those that differ from their defaults: a parameter file fixes them, so none may be given beside one.
    std::vector<std::string> model_keys_set() const { return model_keys_differing(CompressionSettings{}); }
};

/// register-compression: the model, its solver, the condensed contact's updates and memory, the field.
struct CompressionRegistrationSettings : CompressionSettings {
    int tool_updates = 20;                    ///< condensed: tool positions from first contact to the end
    std::string memory_limit = "auto";        ///< condensed: "auto" (80 % of the memory) or a size, e.g. 8G
    double field_spacing = 1.0;               ///< mm
    std::size_t memory_limit_bytes() const;   ///< 0 for auto
};
const SettingsSpec<CompressionRegistrationSettings>& compression_spec();
void validate(const CompressionRegistrationSettings& settings, SettingNaming naming);

/// estimate: the model's start, and what the optimiser fits and how.
struct EstimationSettings : CompressionSettings {
    std::string train = "A,B,C";              ///< training compressions
    std::string validate = "D,E";             ///< held-out compressions; "none"
    bool fit_moduli = false;                  ///< tumour and vessel E besides the couplings
    bool fixed_body_modulus = false;          ///< region body: keep the gel's E
    double k_min = 1.0, k_max = 1e5;          ///< N/m
    std::string optimizer = "bobyqa";         ///< bobyqa, neldermead
    int max_evaluations = 30;
    EstimationOptions estimation_options() const;
};
const SettingsSpec<EstimationSettings>& estimation_spec();
void validate(const EstimationSettings& settings, SettingNaming naming);

/// enrich build: the coarse model and the conditions stored.
struct EnrichmentBuildSettings : CompressionSettings {
    std::string coarse_grid = "24x18x18";     ///< paper 000
    std::string positions;                    ///< compressions whose entry points are used; "": all
    std::string positions_grid;               ///< "CxR" over the skin instead
    std::string depths;                       ///< mm, "2,4,6"; "": 2 mm steps to the deepest compression
    int depth_count = 0;                      ///< instead of depths: this many up to max_depth
    double max_depth = 0.0;                   ///< mm
    int orientations = 1;
    double tilt = 15.0;                       ///< degrees
};
const SettingsSpec<EnrichmentBuildSettings>& enrichment_build_spec();
void validate(const EnrichmentBuildSettings& settings, SettingNaming naming);

/// enrich apply: how stored conditions are matched and blended.
struct EnrichmentApplySettings : CompressionSettings {
    std::string match = "parameters";         ///< parameters, field
    std::string blend = "auto";               ///< auto or a count ≥ 1
    std::string detail_length = "inf";        ///< inf, auto or mm ≥ 0
    double field_spacing = 1.0;               ///< mm
};
const SettingsSpec<EnrichmentApplySettings>& enrichment_apply_spec();
void validate(const EnrichmentApplySettings& settings, SettingNaming naming);

/// The body at rest and the model built on it.
struct CompressionSubject {
    LabelVolume labels;
    LabelRoles roles;
    LandmarkSet rest_landmarks;
    LiverModel model;
    CompressionSettings settings;             ///< the settings it was built with (the model keys are defaults beside a parameter file)
    std::string parameters_file;              ///< "" : the model came from the settings
    nlohmann::json description = nlohmann::json::object(); ///< where it came from (summary "inputs")
};

/// Builds the model of `labels` from `settings`, or from `parameters_file` (estimate's output; then
/// no model key may differ from its default, and the file must have been fitted on this mesh).
/// Throws Error naming the file or the setting.
CompressionSubject make_compression_subject(LabelVolume labels, const LabelRoles& roles, LandmarkSet rest_landmarks,
                                            const CompressionSettings& settings, const std::string& parameters_file = "",
                                            const std::string& labels_source = "rest labels");
/// A phantom dataset's rest state (physreg phantom) as the subject.
CompressionSubject read_dataset_compression_subject(const std::filesystem::path& dataset, const CompressionSettings& settings,
                                                    const std::string& parameters_file = "");

/// predict_compression, and where the Neo-Hookean model folds an element under the tool even at its
/// slowest ramp or its solve stalls short of equilibrium, the model linearised at rest with condensed contact (`tool_updates` positions)
/// instead: `fallback` then says why (else it is left empty). Other errors (bad input, a tool that
/// passes through the skin) are thrown as they are.
CompressionPrediction predict_compression_with_fallback(const LiverModel& model, const Indenter& tool, const LandmarkSet& rest_landmarks,
                                                        const PredictionOptions& options, const std::string& what, int tool_updates,
                                                        const CondensedContactOptions& condensed, std::string* fallback,
                                                        CondensedPrecomputation* precomputation = nullptr, double* ms_per_update = nullptr);

struct CompressionRegistrationResult {
    CompressionRegistrationSettings settings;
    std::string state;
    CompressionPrediction prediction;
    bool contact = false;                     ///< the tool moved the model at all
    CondensedPrecomputation condensed;        ///< solver condensed only (or its fallback)
    std::string fallback;                     ///< why the nonlinear solver's answer was replaced by the condensed one ("" : it was not)
    double condensed_ms_per_update = 0.0;
    std::optional<TreReport> tre, at_rest;    ///< when the case has a truth
    SampledField field;                       ///< on a grid over the mesh, settings.field_spacing
    nlohmann::json summary;                   ///< summary.json as register-compression writes it
};

/// Predicts the compression `observed` (its truth, when not empty, measures the TRE). The model keys
/// of `settings` must be the subject's (the model is built already). Throws Error for a tool that
/// passes through the skin (require_no_tool_passage) or a solver that fails.
CompressionRegistrationResult register_compression(const CompressionSubject& subject, const CompressionCase& observed,
                                                   const CompressionRegistrationSettings& settings, const std::function<void(double, const std::string&)>& progress = {});

struct CompressionEstimationRun {
    EstimationResult result;
    nlohmann::json summary;                   ///< estimate --json
    nlohmann::json report;                    ///< estimate --report: the summary, the history and every landmark
    nlohmann::json fit;                       ///< what the parameter file records about the fit
};
/// Fits on the dataset's training compressions and validates on its held-out ones.
CompressionEstimationRun estimate_compression(const CompressionSubject& subject, const PhantomDataset& dataset, const EstimationSettings& settings,
                                              const std::function<void(double, const std::string&)>& progress = {});

/// The database's plan from the dataset's compressions (or a grid over the skin) and the tool shape
/// it is built with.
struct EnrichmentBuildPlan {
    EnrichmentPlan plan;
    Indenter shape;
    Index3 coarse_grid;
};
EnrichmentBuildPlan enrichment_build_plan(const CompressionSubject& subject, const PhantomDataset& dataset, const EnrichmentBuildSettings& settings);

struct CoarseToFineResult {
    EnrichmentApplySettings settings;
    std::string state;
    LiverModel coarse;
    CoarseToFinePrediction prediction;
    int blend_size = 1;
    double detail_length_mm = 0.0;
    std::optional<TreReport> tre;
    SampledField field;
    nlohmann::json summary;                   ///< summary.json as enrich apply writes it
};
/// Coarse-to-fine prediction of `observed` with `database` (built for this subject's model).
CoarseToFineResult predict_compression_coarse_to_fine(const CompressionSubject& subject, const EnrichmentDatabase& database,
                                                       const CompressionCase& observed, const EnrichmentApplySettings& settings,
                                                       const std::string& database_source = "database", const std::function<void(double, const std::string&)>& progress = {});

/// blend "auto" (leave-one-out best of 1…4; errors per size in `loo_mm`) or a count ≥ 1.
int enrichment_blend_size(const std::string& text, const EnrichmentDatabase& db, const LiverModel& coarse,
                          const std::vector<NodeEmbedding>& fine_nodes, const LiverModel& fine, std::vector<double>* loo_mm = nullptr);
/// detail_length "auto" (leave-one-sequence-out best around the rest landmarks), "inf" or mm ≥ 0.
double enrichment_detail_length(const std::string& text, const EnrichmentDatabase& db, const LiverModel& coarse,
                                const std::vector<NodeEmbedding>& fine_nodes, const LiverModel& fine, EnrichmentMatching how, int k,
                                const LandmarkSet& rest_landmarks, std::vector<std::pair<double, double>>* loo_mm = nullptr);

/// JSON forms shared by the modes' summaries.
nlohmann::json to_json(const ModelParameters& parameters);
nlohmann::json length_json(double length_mm);  ///< the number, or "inf"
/// "A,B,C" → {"A", "B", "C"}; Error naming `name` when empty.
std::vector<std::string> split_names(const std::string& text, const std::string& name);
/// "auto" (0) or a size with an optional binary suffix K, M, G, T; Error naming `name`.
std::size_t parse_memory_size(const std::string& text, const std::string& name);

} // namespace physreg
