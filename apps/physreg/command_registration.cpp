// SPDX-License-Identifier: GPL-3.0-or-later
// physreg estimate / register-compression / evaluate: paper 000's heterogeneous model — fit its
// parameters on training compressions, predict a compression, and measure TRE.
#include "cli_support.hpp"
#include "progress.hpp"
#include "settings_options.hpp"

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
#include "physreg/registration/compression/compression_registration.hpp"
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
        std::string dataset, parameters, output, report_file;
        std::vector<double> k_bounds;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("estimate", "Fit the model's coupling stiffnesses (and optionally tumour/vessel moduli) to the "
                                               "landmarks of training compressions (paper 000 eqs. 6–7); report TRE");
    sub->add_option("--dataset", o->dataset, "Phantom dataset directory (physreg phantom)")->required();
    auto settings = std::make_shared<SettingsOptions<EstimationSettings>>(sub, estimation_spec());
    sub->add_option("--k-bounds", o->k_bounds, "Bounds of the coupling stiffnesses, N/m (the same as --k-min LOW --k-max HIGH)")->expected(2);
    sub->add_option("-o,--output", o->output, "Parameter file to write (JSON; read by register-compression)")->required();
    sub->add_option("--report", o->report_file, "Also write the full report (TRE per compression and landmark, history) as JSON");
    sub->add_flag("--json", o->json, "Print the report as JSON on stdout");
    sub->callback([o, settings] {
        check_output_path(o->output, "--output");
        if (!o->report_file.empty()) check_output_path(o->report_file, "--report");
        EstimationSettings s = settings->resolve();
        if (!o->k_bounds.empty()) s.k_min = o->k_bounds[0], s.k_max = o->k_bounds[1];
        validate(s, SettingNaming::option);
        const PhantomDataset dataset = read_phantom_dataset(o->dataset);
        const CompressionSubject subject = read_dataset_compression_subject(o->dataset, s);
        ProgressDisplay bar("estimate");
        const CompressionEstimationRun run = estimate_compression(subject, dataset, s, [&](double f, const std::string& m) { bar.update(f, m); });
        bar.finish();
        const EstimationResult& r = run.result;
        write_model_parameters(o->output, r.fitted, r.fingerprint, run.fit.dump());
        if (!o->report_file.empty())
            write_atomically(o->report_file, [&](const fs::path& tmp) { std::ofstream(tmp) << run.report.dump(2) << "\n"; });
        std::cerr << fmt::format("estimate ({}, {} evaluations, {:.1f} s; {}): k_c,s-t = {:.4g} N/m, k_c,s-v = {:.4g} N/m, "
                                 "E tumour {:.4g} Pa, E vessel {:.4g} Pa, E body {:.4g} Pa ({} model)\n",
                                 r.optimiser, r.history.size(), r.seconds, r.stop_reason, r.fitted.coupling.parenchyma_tumour_n_per_m,
                                 r.fitted.coupling.parenchyma_vessel_n_per_m, r.fitted.tumour_young_pa, r.fitted.vessel_young_pa,
                                 r.fitted.body_young_pa, to_string(r.fitted.region));
        if (!r.at_bound.empty())
            std::cerr << fmt::format("  WARNING: {} ended at a bound; the optimum may lie beyond it\n", fmt::join(r.at_bound, ", "));
        for (const auto& x : r.sensitivity)
            std::cerr << fmt::format("  {:<16} {:.4f} mm per decade over {} one-parameter steps: {}\n", x.parameter, x.mm_per_decade, x.evaluations,
                                     x.evaluations == 0 ? "not measured" : x.identifiable ? "identifiable" : "NOT identifiable from these landmarks");
        for (const auto& [name, rep] : r.train) std::cerr << fmt::format("  train {:<6} {}\n", name, tre_line(rep));
        std::cerr << fmt::format("  TRAIN        {}\n", tre_line(r.train_pooled));
        for (const auto& [name, rep] : r.validation) std::cerr << fmt::format("  validate {:<3} {}\n", name, tre_line(rep));
        if (!r.validation.empty()) std::cerr << fmt::format("  VALIDATION   {}\n", tre_line(r.validation_pooled));
        std::cerr << fmt::format("  baseline, landmarks left at rest: train {:.3f} (internal {:.3f}), validation {:.3f} (internal {:.3f}) mm\n",
                                 r.train_at_rest.all.mean_mm, r.train_at_rest.internal.mean_mm, r.validation_at_rest.all.mean_mm,
                                 r.validation_at_rest.internal.mean_mm);
        std::cerr << fmt::format("  parameters written to {}\n", o->output);
        if (o->json) std::cout << run.summary.dump(2) << std::endl;
    });
}

void add_subcommand_register_compression(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string dataset, state, parameters, output;
        bool replace = false;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("register-compression", "Predict a tool compression with the model: deformed mesh (VTU), landmark "
                                                           "positions (CSV) and dense displacement field (ITK image)");
    sub->add_option("--dataset", o->dataset, "Phantom dataset directory (rest labels and landmarks, the tool's path)")->required();
    sub->add_option("--state", o->state, "The compression to predict (e.g. D)")->required();
    sub->add_option("--parameters", o->parameters, "Parameter file from physreg estimate (else the model settings)");
    auto settings = std::make_shared<SettingsOptions<CompressionRegistrationSettings>>(sub, compression_spec());
    sub->add_option("-o,--output", o->output, "Output directory (created)")->required();
    sub->add_flag("--force", o->replace, "Replace an existing output directory (only once the new one is complete)");
    sub->add_flag("--json", o->json, "Print a JSON summary on stdout");
    sub->callback([o, settings] {
        const CompressionRegistrationSettings s = settings->resolve();
        validate(s, SettingNaming::option);
        const CompressionSubject subject = read_dataset_compression_subject(o->dataset, s, o->parameters);
        const auto cases = compression_cases(read_phantom_dataset(o->dataset), {o->state});
        StagedDirectory staging(o->output, o->replace);
        ProgressDisplay bar("register-compression");
        CompressionRegistrationResult r = register_compression(subject, cases[0], s, [&](double f, const std::string& m) { bar.update(0.8 * f, m); });
        bar.update(0.8, "writing outputs");
        MeshData data;
        data.point_data.push_back({"displacement", 3, r.prediction.displacement_mm});
        write_vtu(staging.path() / "mesh.vtu", subject.model.mesh, data);
        write_landmarks(staging.path() / "landmarks.csv", r.prediction.landmarks);
        write_displacement_field(staging.path() / "displacement.nii.gz", r.field.field);
        if (!settings->file().empty()) r.summary["settings_file"] = fs::absolute(settings->file()).string();
        write_atomically(staging.path() / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << r.summary.dump(2) << "\n"; });
        bar.update(0.95, "report.html");
        write_html_report(staging.path(), o->output);
        staging.commit();
        bar.finish();
        const ModelParameters& p = subject.model.parameters;
        std::cerr << fmt::format("register-compression {} ({} {}): {} iterations, {:.2f} s, max displacement {:.2f} mm{}; TRE {}; landmarks at "
                                 "rest {:.3f} mm\n", o->state, to_string(p.region), to_string(p.variant), r.prediction.iterations, r.prediction.seconds,
                                 r.prediction.max_displacement_mm, r.contact ? "" : " (no contact)", tre_line(*r.tre), r.at_rest->all.mean_mm);
        if (o->json) std::cout << r.summary.dump(2) << std::endl;
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
