// SPDX-License-Identifier: GPL-3.0-or-later
// physreg bench enrich: time per update (new tool position → every fine node at equilibrium) of the
// high-resolution model and of the coarse-to-fine scheme, for compressions followed as sequences
// of tool positions, each update warm-started from the previous one; TRE at the final depth.
#include "cli_support.hpp"
#include "progress.hpp"
#include "registration_cli.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/registration/enrichment.hpp"
#include "physreg/registration/estimation.hpp"

#include <omp.h>

#include <algorithm>
#include <set>
#include <chrono>
#include <fstream>
#include <iostream>
#include <numeric>

namespace physreg::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

double mean_of(const std::vector<double>& v)
{
    return std::accumulate(v.begin(), v.end(), 0.0) / double(v.size());
}

json timing_json(std::vector<double> ms, const std::vector<long>& iterations)
{
    const double mean = mean_of(ms);
    std::sort(ms.begin(), ms.end());
    const double mean_iterations = std::accumulate(iterations.begin(), iterations.end(), 0.0) / double(iterations.size());
    return {{"mean_ms", mean}, {"median_ms", ms[ms.size() / 2]}, {"max_ms", ms.back()}, {"min_ms", ms.front()},
            {"mean_iterations", mean_iterations}, {"ms_per_iteration", mean / mean_iterations}, {"updates", ms.size()}};
}

} // namespace

void add_subcommand_bench(CLI::App& app)
{
    auto* group = app.add_subcommand("bench", "Benchmarks of the registration pipeline (JSON)");
    group->require_subcommand(1);
    struct Options : CommonOptions {
        std::string dataset, parameters, database, states = "A,B,C,D,E", held_out = "D,E", output, match = "parameters", blend = "auto";
        ModelOptions model;
        int steps = 20;
    };
    auto o = std::make_shared<Options>();
    auto* sub = group->add_subcommand("enrich", "Time per update of the high-resolution model and of coarse-to-fine along compressions "
                                                "(warm-started tool sequences); speed-up and final TRE");
    sub->add_option("--dataset", o->dataset, "Phantom dataset")->required();
    sub->add_option("--parameters", o->parameters, "Parameter file (physreg estimate) the database was built with");
    add_model_options(sub, o->model);
    sub->add_option("--database", o->database, "Enrichment database (physreg enrich build)")->required();
    sub->add_option("--states", o->states, "Compressions to follow (default A,B,C,D,E)");
    sub->add_option("--held-out", o->held_out, "Which of them are held out (never in the database or the estimation; default D,E): "
                                               "their TRE is reported apart from the training ones'");
    sub->add_option("--steps", o->steps, "Tool positions from first contact to the final depth (default 20)");
    sub->add_option("--match", o->match, "parameters or field");
    sub->add_option("--blend", o->blend, "auto or a number of blended conditions");
    sub->add_option("-o,--output", o->output, "JSON report (also printed with --json)");
    sub->add_flag("--json", o->json, "Print the report on stdout");
    sub->callback([o] {
        if (o->steps < 1) fail("--steps must be ≥ 1 (got {})", o->steps);
        if (!o->output.empty()) check_output_path(o->output, "--output");
        const EnrichmentMatching how = parse_enrichment_matching(o->match);
        const EnrichmentDatabase db = read_enrichment_database(o->database);
        const LoadedModel loaded = load_model(o->dataset, o->parameters, o->model);
        std::vector<NodeEmbedding> embedding;
        const LiverModel coarse = coarsen_liver_model(loaded.model, db.coarse_grid(), &embedding);
        check_database_fits(db, loaded.model, coarse, "--database '" + o->database + "'");
        const int k = blend_size(o->blend, db, coarse, embedding, loaded.model);
        const auto cases = compression_cases(loaded.dataset, split_names(o->states, "--states"));
        const PredictionOptions options = prediction_options(o->model);
        json report;
        report["what"] = "time per update: new tool position → every fine node at equilibrium, warm-started from the previous position";
        report["threads"] = omp_get_max_threads();
        report["convergence"] = {{"displacement_tolerance_mm", options.equilibrium.displacement_tolerance_mm},
                                 {"residual_tolerance", options.equilibrium.residual_tolerance},
                                 {"tool_speed_cells_per_iteration", options.tool_speed_per_cell}};
        report["fine_model"] = {{"nodes", loaded.model.mesh.node_count()}, {"hexahedra", loaded.model.mesh.cell_count()},
                                {"variant", to_string(loaded.model.parameters.variant)}};
        report["coarse_model"] = {{"nodes", coarse.mesh.node_count()}, {"hexahedra", coarse.mesh.cell_count()}};
        report["database"] = {{"file", o->database}, {"conditions", db.conditions.size()}, {"match", o->match}, {"blend", k}};
        report["targets"] = {{"coarse_to_fine_ms", 10.0}, {"high_resolution_ms", 100.0}, {"tre_gap_mm", 0.5}};
        ProgressDisplay bar("bench enrich");
        std::vector<double> all_hr, all_c2f, all_coarse, all_synthesis;
        std::vector<TreReport> tre_hr, tre_c2f, tre_hr_held, tre_c2f_held, tre_hr_train, tre_c2f_train;
        const auto held_names = split_names(o->held_out, "--held-out");
        const std::set<std::string> held(held_names.begin(), held_names.end());
        for (std::size_t c = 0; c < cases.size(); ++c) {
            const double depth = (cases[c].tool.path.back() - cases[c].tool.path.front()).norm();
            const TrackingRun run = track_compression(loaded.model, coarse, embedding, db, cases[c].tool, loaded.rest_landmarks, o->steps, how, k,
                                                      options, cases[c].name, [&](int s) {
                                                          bar.update(double(c * o->steps + s) / double(cases.size() * o->steps),
                                                                     fmt::format("{} step {}", cases[c].name, s));
                                                      });
            if (run.last_match.outside_range) logger()->warn("{}: outside the database's range: {}", cases[c].name, run.last_match.range_note);
            tre_hr.push_back(compute_tre(run.high_resolution_landmarks, cases[c].truth, cases[c].name));
            tre_c2f.push_back(compute_tre(run.coarse_to_fine_landmarks, cases[c].truth, cases[c].name));
            (held.count(cases[c].name) ? tre_hr_held : tre_hr_train).push_back(tre_hr.back());
            (held.count(cases[c].name) ? tre_c2f_held : tre_c2f_train).push_back(tre_c2f.back());
            const auto& ms_hr = run.high_resolution_ms;
            const auto& ms_c2f = run.coarse_to_fine_ms;
            const auto& it_hr = run.high_resolution_iterations;
            const auto& it_c2f = run.coarse_iterations;
            all_hr.insert(all_hr.end(), ms_hr.begin(), ms_hr.end());
            all_c2f.insert(all_c2f.end(), ms_c2f.begin(), ms_c2f.end());
            all_coarse.insert(all_coarse.end(), run.coarse_solve_ms.begin(), run.coarse_solve_ms.end());
            all_synthesis.insert(all_synthesis.end(), run.synthesis_ms.begin(), run.synthesis_ms.end());
            report["compressions"][cases[c].name] = {{"depth_mm", depth},
                                                     {"held_out", held.count(cases[c].name) > 0},
                                                     {"high_resolution", timing_json(ms_hr, it_hr)},
                                                     {"coarse_to_fine", timing_json(ms_c2f, it_c2f)},
                                                     {"coarse_to_fine_split_ms", {{"coarse_equilibrium", mean_of(run.coarse_solve_ms)},
                                                                                  {"match_synthesis_landmarks", mean_of(run.synthesis_ms)}}},
                                                     {"tre_high_resolution", json::parse(tre_stats_json(tre_hr.back()))},
                                                     {"tre_coarse_to_fine", json::parse(tre_stats_json(tre_c2f.back()))}};
        }
        bar.finish();
        const TreReport hr = pool_tre(tre_hr), c2f = pool_tre(tre_c2f);
        const double mean_hr = mean_of(all_hr), mean_c2f = mean_of(all_c2f);
        report["summary"] = {{"method", o->model.solver},
                             {"high_resolution_ms_per_update", mean_hr},
                             {"coarse_to_fine_ms_per_update", mean_c2f},
                             {"coarse_to_fine_split_ms", {{"coarse_equilibrium", mean_of(all_coarse)},
                                                          {"match_synthesis_landmarks", mean_of(all_synthesis)}}},
                             {"speed_up", mean_hr / mean_c2f},
                             {"tre_high_resolution", json::parse(tre_stats_json(hr))},
                             {"tre_coarse_to_fine", json::parse(tre_stats_json(c2f))},
                             {"tre_gap_mm", c2f.all.mean_mm - hr.all.mean_mm},
                             {"training", {{"states", tre_hr_train.size()},
                                           {"tre_high_resolution", json::parse(tre_stats_json(pool_tre(tre_hr_train)))},
                                           {"tre_coarse_to_fine", json::parse(tre_stats_json(pool_tre(tre_c2f_train)))}}},
                             {"held_out", {{"states", tre_hr_held.size()},
                                           {"tre_high_resolution", json::parse(tre_stats_json(pool_tre(tre_hr_held)))},
                                           {"tre_coarse_to_fine", json::parse(tre_stats_json(pool_tre(tre_c2f_held)))}}},
                             {"meets_coarse_to_fine_target", mean_c2f <= 10.0},
                             {"meets_high_resolution_target", mean_hr <= 100.0},
                             {"meets_tre_target", c2f.all.mean_mm - hr.all.mean_mm <= 0.5}};
        std::cerr << fmt::format("bench enrich ({}, {} threads): high resolution {:.1f} ms/update, coarse-to-fine {:.1f} ms/update, speed-up "
                                 "{:.1f}×; TRE at the final depth (high resolution vs coarse-to-fine): training {:.3f} vs {:.3f} mm, "
                                 "held-out {:.3f} vs {:.3f} mm\n",
                                 o->model.solver, omp_get_max_threads(), mean_hr, mean_c2f, mean_hr / mean_c2f,
                                 pool_tre(tre_hr_train).all.mean_mm, pool_tre(tre_c2f_train).all.mean_mm, pool_tre(tre_hr_held).all.mean_mm,
                                 pool_tre(tre_c2f_held).all.mean_mm);
        if (!o->output.empty())
            write_atomically(o->output, [&](const fs::path& tmp) { std::ofstream(tmp) << report.dump(2) << "\n"; });
        if (o->json) std::cout << report.dump(2) << std::endl;
    });
}

} // namespace physreg::cli
