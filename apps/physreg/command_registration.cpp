// SPDX-License-Identifier: GPL-3.0-or-later
// physreg estimate / register-compression / evaluate: paper 000's heterogeneous model — fit its
// parameters on training compressions, predict a compression, and measure TRE.
#include "cli_support.hpp"
#include "progress.hpp"
#include "registration_cli.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/evaluation/tre.hpp"
#include "physreg/registration/compression/condensed_contact.hpp"
#include "physreg/figures/tre_chart.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/png.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/registration/compression/estimation.hpp"

#include <fstream>
#include <iostream>
#include <sstream>

namespace physreg::cli {
namespace fs = std::filesystem;
using nlohmann::json;


void add_subcommand_estimate(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string dataset, train = "A,B,C", validate = "D,E", output, report_file, algorithm = "bobyqa";
        ModelOptions model;
        bool fit_moduli = false, fixed_body = false;
        int max_evaluations = 30;
        double k_min = 1.0, k_max = 1e5;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("estimate", "Fit the model's coupling stiffnesses (and optionally tumour/vessel moduli) to the "
                                               "landmarks of training compressions (paper 000 eqs. 6–7); report TRE");
    sub->add_option("--dataset", o->dataset, "Phantom dataset directory (physreg phantom)")->required();
    sub->add_option("--train", o->train, "Training compressions (default A,B,C)");
    sub->add_option("--validate", o->validate, "Validation compressions (default D,E; \"none\" for none)");
    add_model_options(sub, o->model);
    sub->add_flag("--fit-moduli", o->fit_moduli, "Also fit the tumour and vessel Young's moduli (log-scaled, 1e4 … 1e8 Pa)");
    sub->add_flag("--fixed-body-modulus", o->fixed_body, "Region body: keep the gel's modulus (--body-modulus) instead of fitting it "
                                                        "(log-scaled, 2e3 … 2e6 Pa; fitted by default)");
    sub->add_option("--k-bounds", [o](const std::vector<std::string>& v) {
        if (v.size() != 2) return false;
        const auto low = parse_number(v[0]), high = parse_number(v[1]);
        if (!low || !high) return false; // CLI11 then reports "Could not convert: --k-bounds = …" (exit 104)
        o->k_min = *low, o->k_max = *high;
        return true;
    }, "Bounds of the coupling stiffnesses, N/m (default 1 1e5)")->expected(2);
    sub->add_option("--optimizer", o->algorithm, "bobyqa (default) or neldermead (NLopt)");
    sub->add_option("--max-evaluations", o->max_evaluations, "Objective evaluations at most (default 30)");
    sub->add_option("-o,--output", o->output, "Parameter file to write (JSON; read by register-compression)")->required();
    sub->add_option("--report", o->report_file, "Also write the full report (TRE per compression and landmark, history) as JSON");
    sub->add_flag("--json", o->json, "Print the report as JSON on stdout");
    sub->callback([o] {
        check_output_path(o->output, "--output");
        if (!o->report_file.empty()) check_output_path(o->report_file, "--report");
        const PhantomDataset dataset = read_phantom_dataset(o->dataset);
        const DatasetState& rest = dataset.state("rest");
        const LabelVolume labels = read_label_volume(dataset.path(rest.files.at("labels")));
        ModelParameters defaults;
        if (o->model.grid.empty()) defaults.grid = default_model_grid(labels, dataset.roles, parse_model_region(o->model.region)); // from the dataset
        const ModelParameters initial = model_parameters(o->model, defaults);
        const auto train = compression_cases(dataset, split_names(o->train, "--train"));
        const auto validation = o->validate == "none" ? std::vector<CompressionCase>{} : compression_cases(dataset, split_names(o->validate, "--validate"));
        const LandmarkSet rest_landmarks = read_landmarks(dataset.path(rest.files.at("landmarks")));
        EstimationOptions options;
        options.fit_moduli = o->fit_moduli;
        options.fit_body_modulus = !o->fixed_body;
        options.k_min_n_per_m = o->k_min;
        options.k_max_n_per_m = o->k_max;
        options.algorithm = o->algorithm;
        options.max_evaluations = o->max_evaluations;
        options.prediction = prediction_options(o->model);
        ProgressDisplay bar("estimate");
        const EstimationResult r = estimate_parameters(labels, dataset.roles, initial, rest_landmarks, train, validation, options,
                                                       [&](double f, const std::string& m) { bar.update(f, m); });
        bar.finish();
        json summary;
        summary["dataset"] = o->dataset;
        summary["optimiser"] = r.optimiser;
        summary["stop_reason"] = r.stop_reason;
        summary["evaluations"] = r.history.size();
        summary["seconds"] = r.seconds;
        summary["objective"] = "mean TRE over every landmark of the training compressions, mm";
        summary["objective_mm"] = r.objective_mm;
        summary["fitted"] = parameters_json(r.fitted);
        summary["free_parameters"] = r.free_parameters;
        summary["at_bound"] = r.at_bound; // fitted parameters that ended at a bound (the optimum may lie beyond)
        summary["infeasible_evaluations"] = r.infeasible_evaluations;
        for (const auto& s : r.sensitivity)
            summary["identifiability"][s.parameter] = {{"objective_change_mm_per_decade", s.mm_per_decade}, {"one_parameter_steps", s.evaluations},
                                                       {"identifiable", s.identifiable},
                                                       {"threshold_mm_per_decade", EstimationResult::identifiable_mm_per_decade}};
        summary["mesh_fingerprint"] = r.fingerprint;
        summary["train"] = json::parse(tre_stats_json(r.train_pooled));
        if (!r.validation.empty()) summary["validation"] = json::parse(tre_stats_json(r.validation_pooled));
        summary["baseline_landmarks_at_rest"]["train"] = json::parse(tre_stats_json(r.train_at_rest));
        if (!r.validation.empty()) summary["baseline_landmarks_at_rest"]["validation"] = json::parse(tre_stats_json(r.validation_at_rest));
        for (const auto& [name, rep] : r.train) summary["per_compression"][name] = json::parse(tre_stats_json(rep));
        for (const auto& [name, rep] : r.validation) summary["per_compression"][name] = json::parse(tre_stats_json(rep));
        const json fit = {{"objective_mm", r.objective_mm}, {"train", summary["train"]}, {"validation", summary.value("validation", json())},
                          {"optimiser", r.optimiser}, {"evaluations", r.history.size()}, {"dataset", o->dataset},
                          {"at_bound", r.at_bound}};
        write_model_parameters(o->output, r.fitted, r.fingerprint, fit.dump());
        if (!o->report_file.empty()) {
            json full = summary;
            for (const auto& step : r.history) full["history"].push_back({{"parameters", parameters_json(step.parameters)}, {"objective_mm", step.objective_mm}});
            for (const auto& [name, rep] : r.train) full["landmarks"][name] = json::parse(tre_report_json(rep));
            for (const auto& [name, rep] : r.validation) full["landmarks"][name] = json::parse(tre_report_json(rep));
            write_atomically(o->report_file, [&](const fs::path& tmp) { std::ofstream(tmp) << full.dump(2) << "\n"; });
        }
        std::cerr << fmt::format("estimate ({}, {} evaluations, {:.1f} s; {}): k_c,s-t = {:.4g} N/m, k_c,s-v = {:.4g} N/m, "
                                 "E tumour {:.4g} Pa, E vessel {:.4g} Pa, E body {:.4g} Pa ({} model)\n",
                                 r.optimiser, r.history.size(), r.seconds, r.stop_reason, r.fitted.coupling.parenchyma_tumour_n_per_m,
                                 r.fitted.coupling.parenchyma_vessel_n_per_m, r.fitted.tumour_young_pa, r.fitted.vessel_young_pa,
                                 r.fitted.body_young_pa, to_string(r.fitted.region));
        if (!r.at_bound.empty())
            std::cerr << fmt::format("  WARNING: {} ended at a bound; the optimum may lie beyond it\n", fmt::join(r.at_bound, ", "));
        for (const auto& s : r.sensitivity)
            std::cerr << fmt::format("  {:<16} {:.4f} mm per decade over {} one-parameter steps: {}\n", s.parameter, s.mm_per_decade, s.evaluations,
                                     s.evaluations == 0 ? "not measured" : s.identifiable ? "identifiable" : "NOT identifiable from these landmarks");
        for (const auto& [name, rep] : r.train) std::cerr << fmt::format("  train {:<6} {}\n", name, tre_line(rep));
        std::cerr << fmt::format("  TRAIN        {}\n", tre_line(r.train_pooled));
        for (const auto& [name, rep] : r.validation) std::cerr << fmt::format("  validate {:<3} {}\n", name, tre_line(rep));
        if (!r.validation.empty()) std::cerr << fmt::format("  VALIDATION   {}\n", tre_line(r.validation_pooled));
        std::cerr << fmt::format("  baseline, landmarks left at rest: train {:.3f} (internal {:.3f}), validation {:.3f} (internal {:.3f}) mm\n",
                                 r.train_at_rest.all.mean_mm, r.train_at_rest.internal.mean_mm, r.validation_at_rest.all.mean_mm,
                                 r.validation_at_rest.internal.mean_mm);
        std::cerr << fmt::format("  parameters written to {}\n", o->output);
        if (o->json) std::cout << summary.dump(2) << std::endl;
    });
}

void add_subcommand_register_compression(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string dataset, state, parameters, output;
        ModelOptions model;
        double field_spacing = 1.0;
        bool replace = false;
        std::string memory_limit = "auto";
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("register-compression", "Predict a tool compression with the model: deformed mesh (VTU), landmark "
                                                           "positions (CSV) and dense displacement field (ITK image)");
    sub->add_option("--dataset", o->dataset, "Phantom dataset directory (rest labels and landmarks, the tool's path)")->required();
    sub->add_option("--state", o->state, "The compression to predict (e.g. D)")->required();
    auto* params = sub->add_option("--parameters", o->parameters, "Parameter file from physreg estimate (else --variant/--k-* or defaults)");
    add_model_options(sub, o->model);
    sub->add_option("--field-spacing", o->field_spacing, "Voxel size of the displacement field over the mesh, mm (default 1)");
    sub->add_option("--memory-limit", o->memory_limit, "With --solver condensed: memory the precomputation may take (factor, compliance), "
                                                      "e.g. 8G; auto (default): 80 % of the physical memory. Over it: an error naming the size needed");
    sub->add_option("-o,--output", o->output, "Output directory (created)")->required();
    sub->add_flag("--force", o->replace, "Replace an existing output directory (only once the new one is complete)");
    sub->add_flag("--json", o->json, "Print a JSON summary on stdout");
    (void)params;
    sub->callback([o] {
        if (!(o->field_spacing > 0)) fail("--field-spacing must be > 0 mm (got {})", o->field_spacing);
        CondensedContactOptions condensed_options;
        condensed_options.memory_limit_bytes = parse_memory_limit(o->memory_limit, "--memory-limit");
        const LoadedModel loaded = load_model(o->dataset, o->parameters, o->model);
        const auto cases = compression_cases(loaded.dataset, {o->state});
        const LiverModel& model = loaded.model;
        const ModelParameters& p = model.parameters;
        const LandmarkSet& rest_landmarks = loaded.rest_landmarks;
        StagedDirectory staging(o->output, o->replace);
        ProgressDisplay bar("register-compression");
        bar.update(0.05, fmt::format("{} model: {} nodes, {} hexahedra, {} interface points", to_string(p.variant), model.mesh.node_count(),
                                     model.mesh.cell_count(), model.coupling.points().size()));
        // --solver condensed (issue 30): the model linearised at rest and the contact condensed onto
        // the skin nodes the tool reaches; the other solvers reach the Neo-Hookean equilibrium.
        const bool condensed = o->model.solver == "condensed";
        CondensedPrecomputation condensed_pre;
        double condensed_ms = 0.0;
        const auto prediction = condensed ? predict_compression_condensed(model, cases[0].tool, rest_landmarks, 20, "compression " + o->state,
                                                                          condensed_options, &condensed_pre, &condensed_ms)
                                          : predict_compression(model, cases[0].tool, rest_landmarks, prediction_options(o->model),
                                                                "compression " + o->state);
        // A tool that never reaches the model leaves it at rest: say so instead of a silent zero.
        const bool contact = prediction.max_displacement_mm > 1e-6;
        if (!contact)
            logger()->warn("compression {}: no contact: the tool never touches the model (largest displacement {:.2g} mm), so the "
                           "prediction is the landmarks at rest (with --region liver: the tool presses the skin, not the liver)",
                           o->state, prediction.max_displacement_mm);
        bar.update(0.8, "writing outputs");
        MeshData data;
        data.point_data.push_back({"displacement", 3, prediction.displacement_mm});
        write_vtu(staging.path() / "mesh.vtu", model.mesh, data);
        write_landmarks(staging.path() / "landmarks.csv", prediction.landmarks);
        const ImageGeometry geometry = image_grid_over_mesh(model.mesh, o->field_spacing, 2.0 * model.cell_size_mm.maxCoeff());
        const SampledField field = sample_displacement_field(model.mesh, prediction.displacement_mm, geometry);
        write_displacement_field(staging.path() / "displacement.nii.gz", field.field);
        const TreReport tre = compute_tre(prediction.landmarks, cases[0].truth, "compression " + o->state);
        const TreReport at_rest = compute_tre(rest_landmarks, cases[0].truth, "compression " + o->state + " (landmarks at rest)");
        json summary = {{"state", o->state},
                        {"model", parameters_json(p)},
                        {"nodes", model.mesh.node_count()},
                        {"hexahedra", model.mesh.cell_count()},
                        {"interface_points", model.coupling.points().size()},
                        {"method", o->model.solver},
                        {"iterations", prediction.iterations},
                        {"seconds", prediction.seconds},
                        {"max_displacement_mm", prediction.max_displacement_mm},
                        {"tool_contact", contact ? "contact" : "no contact"},
                        {"max_coupling_gap_mm", prediction.max_coupling_gap_mm},
                        {"tre_against_dataset", json::parse(tre_stats_json(tre))},
                        {"tre_landmarks_at_rest", json::parse(tre_stats_json(at_rest))}, // the baseline: doing nothing
                        {"slower_tool_ramps", prediction.slower_ramps},
                        {"files", {{"mesh", "mesh.vtu"}, {"landmarks", "landmarks.csv"}, {"displacement", "displacement.nii.gz"}}},
                        {"units", "mm, LPS; displacement field in the rest (pre-operative) space: x → x + u(x)"}};
        if (condensed)
            summary["condensed"] = {{"law", "the model's Neo-Hookean tangent at rest (linear)"}, {"tool_updates", prediction.iterations},
                                    {"ms_per_update", condensed_ms}, {"candidate_nodes", condensed_pre.candidate_nodes},
                                    {"precomputation_s", condensed_pre.assembly_s + condensed_pre.factorisation_s + condensed_pre.compliance_s},
                                    {"factor_nonzeros", condensed_pre.factor_nonzeros},
                                    {"memory_bytes", condensed_pre.memory_bytes}, {"memory_limit_bytes", condensed_pre.memory_limit_bytes}};
        summary["command"] = "register-compression";
        summary["inputs"] = {{"dataset", fs::absolute(o->dataset).string()}, {"state", o->state}, {"parameters", o->parameters}};
        summary["tre_per_landmark"] = json::parse(tre_report_json(tre))["landmarks"];
        write_atomically(staging.path() / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << summary.dump(2) << "\n"; });
        bar.update(0.95, "report.html");
        write_html_report(staging.path(), o->output);
        staging.commit();
        bar.finish();
        std::cerr << fmt::format("register-compression {} ({} {}): {} iterations, {:.2f} s, max displacement {:.2f} mm{}; TRE {}; landmarks at "
                                 "rest {:.3f} mm\n", o->state, to_string(p.region), to_string(p.variant), prediction.iterations, prediction.seconds,
                                 prediction.max_displacement_mm, contact ? "" : " (no contact)", tre_line(tre), at_rest.all.mean_mm);
        if (o->json) std::cout << summary.dump(2) << std::endl;
    });
}

void add_subcommand_evaluate(CLI::App& app)
{
    struct Options : CommonOptions {
        std::vector<std::string> predicted;
        std::string truth, output, title = "TARGET REGISTRATION ERROR";
        bool replace = false;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("evaluate", "TRE of predicted landmarks against ground truth: CSV, JSON and a PNG chart");
    sub->add_option("--predicted", o->predicted, "Predicted landmarks (CSV/FCSV/Slicer JSON); LABEL=FILE to name a series; repeatable")
        ->required();
    sub->add_option("--truth", o->truth, "Ground-truth landmarks (matched by name)")->required();
    sub->add_option("--title", o->title, "Chart title");
    sub->add_option("-o,--output", o->output, "Output directory (created): tre.csv, tre.json, tre.png")->required();
    sub->add_flag("--force", o->replace, "Replace an existing output directory (only once the new one is complete)");
    sub->add_flag("--json", o->json, "Print the statistics as JSON on stdout");
    sub->callback([o] {
        const LandmarkSet truth = read_landmarks(o->truth);
        std::vector<TreSeries> series;
        for (const auto& item : o->predicted) {
            const auto eq = item.find('=');
            const std::string label = eq == std::string::npos ? fs::path(item).stem().string() : item.substr(0, eq);
            const std::string file = eq == std::string::npos ? item : item.substr(eq + 1);
            series.push_back({label, compute_tre(read_landmarks(file), truth, "'" + file + "' against '" + o->truth + "'")});
        }
        StagedDirectory staging(o->output, o->replace);
        json summary;
        for (std::size_t s = 0; s < series.size(); ++s) {
            const std::string suffix = series.size() == 1 ? "" : "_" + series[s].label;
            write_tre_csv(staging.path() / ("tre" + suffix + ".csv"), series[s].report);
            write_atomically(staging.path() / ("tre" + suffix + ".json"),
                             [&](const fs::path& tmp) { std::ofstream(tmp) << tre_report_json(series[s].report) << "\n"; });
            summary[series[s].label] = json::parse(tre_stats_json(series[s].report));
            std::cerr << fmt::format("{}: {}\n", series[s].label, tre_line(series[s].report));
        }
        write_png(staging.path() / "tre.png", render_tre_chart(series, o->title));
        staging.commit();
        if (o->json) std::cout << summary.dump(2) << std::endl;
    });
}

} // namespace physreg::cli
