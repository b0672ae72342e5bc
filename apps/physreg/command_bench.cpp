// SPDX-License-Identifier: GPL-3.0-or-later
// physreg bench enrich: time per update (new tool position → every fine node at equilibrium) of the
// high-resolution model and of the coarse-to-fine scheme, for compressions followed as sequences
// of tool positions, each update warm-started from the previous one; TRE at the final depth.
// physreg bench condensed: the same tool sequences with condensed contact (issue 30): the stiffness
// factorised once at rest, the candidate skin nodes' compliance precomputed, an LCP per update.
#include "cli_support.hpp"
#include "progress.hpp"
#include "settings_options.hpp"

#include "physreg/registration/compression/compression_registration.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/registration/compression/condensed_coarse_to_fine.hpp"
#include "physreg/registration/compression/condensed_contact.hpp"
#include "physreg/registration/compression/enrichment.hpp"
#include "physreg/registration/compression/estimation.hpp"

#include <omp.h>
#include <sys/resource.h>

#include <algorithm>
#include <set>
#include <chrono>
#include <optional>
#include <fstream>
#include <iostream>
#include <numeric>

namespace physreg::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

/// The process's high-water mark of resident memory, MB (getrusage).
double peak_rss_mb()
{
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return double(usage.ru_maxrss) * 1024.0 / 1e6; // ru_maxrss is in KiB on Linux
}

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

namespace {

/// bench enrich: time per update of the high-resolution model and of coarse-to-fine along compressions.
void add_bench_enrich(CLI::App* group)
{
    struct Options : CommonOptions {
        std::string dataset, parameters, database, states = "A,B,C,D,E", held_out = "D,E", output;
        int steps = 20;
    };
    auto o = std::make_shared<Options>();
    auto* sub = group->add_subcommand("enrich", "Time per update of the high-resolution model and of coarse-to-fine along compressions "
                                                "(warm-started tool sequences); speed-up and final TRE");
    sub->add_option("--dataset", o->dataset, "Phantom dataset")->required();
    sub->add_option("--parameters", o->parameters, "Parameter file (physreg estimate) the database was built with");
    auto settings = std::make_shared<SettingsOptions<EnrichmentApplySettings>>(sub, enrichment_apply_spec());
    sub->add_option("--database", o->database, "Enrichment database (physreg enrich build)")->required();
    sub->add_option("--states", o->states, "Compressions to follow (default A,B,C,D,E)");
    sub->add_option("--held-out", o->held_out, "Which of them are held out (never in the database or the estimation; default D,E): "
                                               "their TRE is reported apart from the training ones'");
    sub->add_option("--steps", o->steps, "Tool positions from first contact to the final depth (default 20)");
    sub->add_option("-o,--output", o->output, "JSON report (also printed with --json)");
    sub->add_flag("--json", o->json, "Print the report on stdout");
    sub->callback([o, settings] {
        if (o->steps < 1) fail("--steps must be ≥ 1 (got {})", o->steps);
        if (!o->output.empty()) check_output_path(o->output, "--output");
        const EnrichmentApplySettings s = settings->resolve();
        validate(s, SettingNaming::option);
        const EnrichmentMatching how = parse_enrichment_matching(s.match);
        const EnrichmentDatabase db = read_enrichment_database(o->database);
        const CompressionSubject loaded = read_dataset_compression_subject(o->dataset, s, o->parameters);
        std::vector<NodeEmbedding> embedding;
        const LiverModel coarse = coarsen_liver_model(loaded.model, db.coarse_grid(), &embedding);
        check_database_fits(db, loaded.model, coarse, "--database '" + o->database + "'");
        const int k = enrichment_blend_size(s.blend, db, coarse, embedding, loaded.model);
        const double detail = enrichment_detail_length(s.detail_length, db, coarse, embedding, loaded.model, how, k, loaded.rest_landmarks);
        const auto cases = compression_cases(read_phantom_dataset(o->dataset), split_names(o->states, "--states"));
        const PredictionOptions options = s.prediction_options();
        json report;
        report["what"] = "time per update: new tool position → every fine node at equilibrium, warm-started from the previous position";
        report["threads"] = omp_get_max_threads();
        report["convergence"] = {{"displacement_tolerance_mm", options.equilibrium.displacement_tolerance_mm},
                                 {"residual_tolerance", options.equilibrium.residual_tolerance},
                                 {"tool_speed_cells_per_iteration", options.tool_speed_per_cell}};
        report["fine_model"] = {{"nodes", loaded.model.mesh.node_count()}, {"hexahedra", loaded.model.mesh.cell_count()},
                                {"variant", to_string(loaded.model.parameters.variant)}};
        report["coarse_model"] = {{"nodes", coarse.mesh.node_count()}, {"hexahedra", coarse.mesh.cell_count()}};
        report["database"] = {{"file", o->database}, {"conditions", db.conditions.size()}, {"match", s.match}, {"blend", k},
                              {"detail_length_mm", length_json(detail)}};
        report["targets"] = {{"coarse_to_fine_ms", 10.0}, {"high_resolution_ms", 100.0}, {"tre_gap_mm", 0.5}};
        ProgressDisplay bar("bench enrich");
        std::vector<double> all_hr, all_c2f, all_coarse, all_synthesis;
        std::vector<TreReport> tre_hr, tre_c2f, tre_hr_held, tre_c2f_held, tre_hr_train, tre_c2f_train;
        const auto held_names = split_names(o->held_out, "--held-out");
        const std::set<std::string> held(held_names.begin(), held_names.end());
        for (std::size_t c = 0; c < cases.size(); ++c) {
            const double depth = (cases[c].tool.path.back() - cases[c].tool.path.front()).norm();
            const TrackingRun run = track_compression(loaded.model, coarse, embedding, db, cases[c].tool, loaded.rest_landmarks, o->steps, how,
                                                      EnrichmentBlend(k, detail), options, cases[c].name, [&](int s) {
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
        report["summary"] = {{"method", s.solver},
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
                                 s.solver, omp_get_max_threads(), mean_hr, mean_c2f, mean_hr / mean_c2f,
                                 pool_tre(tre_hr_train).all.mean_mm, pool_tre(tre_c2f_train).all.mean_mm, pool_tre(tre_hr_held).all.mean_mm,
                                 pool_tre(tre_c2f_held).all.mean_mm);
        if (!o->output.empty())
            write_atomically(o->output, [&](const fs::path& tmp) { std::ofstream(tmp) << report.dump(2) << "\n"; });
        if (o->json) std::cout << report.dump(2) << std::endl;
    });

    // bench condensed (issue 30).
}

/// bench condensed's coarse-to-fine part of the report (and its line on stderr).
json coarse_to_fine_report(const CondensedCoarseToFine& c2f, const EnrichmentDatabase& db, const LiverModel& coarse, const std::string& database_file,
                           const std::string& match, int blend, double detail, std::size_t fine_nodes, const std::vector<double>& c2f_ms,
                           const std::vector<double>& c2f_contact, const std::vector<double>& c2f_recovery, const std::vector<double>& c2f_synthesis,
                           const std::vector<TreReport>& c2f_train, const std::vector<TreReport>& c2f_held)
{
    const auto& cp = c2f.coarse_model().precomputation();
    json out = {
        {"database", {{"file", database_file}, {"conditions", db.conditions.size()}, {"match", match}, {"blend", blend},
                      {"detail_length_mm", length_json(detail)}}},
        {"coarse_model", {{"nodes", coarse.mesh.node_count()}, {"hexahedra", coarse.mesh.cell_count()}}},
        {"precomputation", {{"candidate_nodes", cp.candidate_nodes}, {"coarse_query_nodes", cp.query_nodes}, {"factorisation_s", cp.factorisation_s},
                            {"compliance_s", cp.compliance_s}, {"assembly_s", cp.assembly_s}}},
        {"fine_nodes_synthesised", fine_nodes},
        {"ms_per_update", {{"mean", mean_of(c2f_ms)}, {"max", *std::max_element(c2f_ms.begin(), c2f_ms.end())},
                           {"contact", mean_of(c2f_contact)}, {"recovery", mean_of(c2f_recovery)}, {"synthesis", mean_of(c2f_synthesis)}}},
        {"training", json::parse(tre_stats_json(pool_tre(c2f_train)))},
        {"held_out", json::parse(tre_stats_json(pool_tre(c2f_held)))}};
    std::cerr << fmt::format("bench condensed, coarse-to-fine: precomputation {:.1f} s ({} coarse candidates); {:.3f} ms/update (contact {:.3f}, "
                             "recovery {:.3f}, synthesis {:.3f}); TRE training {:.3f} mm, held-out {:.3f} mm\n",
                             cp.assembly_s + cp.factorisation_s + cp.compliance_s, cp.candidate_nodes, mean_of(c2f_ms), mean_of(c2f_contact),
                             mean_of(c2f_recovery), mean_of(c2f_synthesis), pool_tre(c2f_train).all.mean_mm, pool_tre(c2f_held).all.mean_mm);
    return out;
}

/// The model and its precomputation, as bench condensed reports them.
void add_model_report(json& report, const LiverModel& model, const CondensedPrecomputation& pre)
{
    report["model"] = {{"nodes", model.mesh.node_count()}, {"hexahedra", model.mesh.cell_count()},
                       {"variant", to_string(model.parameters.variant)}, {"region", to_string(model.parameters.region)},
                       {"law", "the model's Neo-Hookean tangent at rest (small-strain linear elasticity)"}};
    report["precomputation"] = {{"dofs", pre.dofs}, {"candidate_nodes", pre.candidate_nodes}, {"query_nodes", pre.query_nodes},
                                {"assembly_s", pre.assembly_s}, {"factorisation_s", pre.factorisation_s},
                                {"compliance_s", pre.compliance_s}, {"compliance_mb", double(pre.compliance_bytes) / 1e6},
                                {"factor_nonzeros", pre.factor_nonzeros}, {"memory_estimate_mb", double(pre.memory_bytes) / 1e6},
                                {"memory_limit_mb", double(pre.memory_limit_bytes) / 1e6}};
}

struct CondensedOptions : CommonOptions {
    std::string dataset, parameters, states = "A,B,C,D,E", held_out = "D,E", output, nonlinear = "never", database;
    int steps = 20;
    double margin_mm = 10.0;
    std::string memory_limit = "auto";
};

/// bench condensed, once its options are read and checked.
void run_bench_condensed(const CondensedOptions& co, const EnrichmentApplySettings& s)
{
    validate(s, SettingNaming::option);
    if (co.steps < 1) fail("--steps must be ≥ 1 (got {})", co.steps);
    if (!(co.margin_mm >= 0)) fail("--candidate-margin must be ≥ 0 mm (got {})", co.margin_mm);
    if (co.nonlinear != "never" && co.nonlinear != "relaxation") fail("--nonlinear must be never or relaxation (got '{}')", co.nonlinear);
    const std::size_t memory_limit = parse_memory_size(co.memory_limit, "--memory-limit");
    if (!co.output.empty()) check_output_path(co.output, "--output");
    const CompressionSubject loaded = read_dataset_compression_subject(co.dataset, s, co.parameters);
    const auto cases = compression_cases(read_phantom_dataset(co.dataset), split_names(co.states, "--states"));
    const auto held_names = split_names(co.held_out, "--held-out");
    const std::set<std::string> held(held_names.begin(), held_names.end());
    std::vector<Indenter> tools;
    for (const auto& c : cases) tools.push_back(c.tool);
    std::vector<Vec3> around;
    for (const auto& l : loaded.rest_landmarks) around.push_back(l.position);
    // Every node within two cells of a landmark: a superset of the nodes its interpolation reads.
    const auto query = nodes_near(loaded.model.mesh, around, 2.0 * loaded.model.cell_size_mm.maxCoeff());
    CondensedContactOptions options;
    options.candidate_margin_mm = co.margin_mm;
    options.memory_limit_bytes = memory_limit;
    logger()->info("bench condensed: factorising the stiffness at rest and the candidates' compliance");
    CondensedContactModel condensed(loaded.model, tools, query, options);
    // Coarse-to-fine on top (issue 30 item 3): the database's coarse model, condensed too.
    std::optional<EnrichmentDatabase> db;
    std::optional<LiverModel> coarse;
    std::vector<NodeEmbedding> embedding;
    std::optional<CondensedCoarseToFine> c2f;
    int blend = 0;
    double detail = std::numeric_limits<double>::infinity();
    const EnrichmentMatching how = parse_enrichment_matching(s.match);
    if (!co.database.empty()) {
        db = read_enrichment_database(co.database);
        coarse = coarsen_liver_model(loaded.model, db->coarse_grid(), &embedding);
        check_database_fits(*db, loaded.model, *coarse, "--database '" + co.database + "'");
        blend = enrichment_blend_size(s.blend, *db, *coarse, embedding, loaded.model);
        detail = enrichment_detail_length(s.detail_length, *db, *coarse, embedding, loaded.model, how, blend, loaded.rest_landmarks);
        logger()->info("bench condensed: the coarse model ({} nodes) condensed for coarse-to-fine", coarse->mesh.node_count());
        c2f.emplace(loaded.model, *coarse, embedding, *db, tools, query, how, EnrichmentBlend(blend, detail), options);
    }
    const auto& pre = condensed.precomputation();
    json report;
    report["what"] = "time per update with condensed contact: new tool position → contact forces → the landmarks' nodes";
    report["threads"] = omp_get_max_threads();
    add_model_report(report, loaded.model, pre);
    report["targets"] = {{"high_resolution_ms", 100.0}, {"coarse_to_fine_ms", 10.0}};
    ProgressDisplay bar("bench condensed");
    std::vector<double> all_ms, all_contact, all_recovery, relax_ms;
    std::vector<TreReport> tre_all, tre_held, tre_train, linear_all, linear_held, linear_train, c2f_held, c2f_train;
    std::vector<double> c2f_ms, c2f_contact, c2f_recovery, c2f_synthesis;
    for (std::size_t c = 0; c < cases.size(); ++c) {
        condensed.reset();
        if (c2f) c2f->reset();
        CondensedCoarseToFine::Update c2f_up;
        const Vec3 a = cases[c].tool.path.front(), b = cases[c].tool.path.back();
        std::vector<double> ms, contact, recovery;
        CondensedContactModel::Update up;
        std::vector<double> state_relax_ms;
        LandmarkSet linear_moved;
        for (int s = 1; s <= co.steps; ++s) {
            const Vec3 at = a + (double(s) / co.steps) * (b - a);
            up = condensed.move_to(cases[c].tool, at);
            ms.push_back(up.contact_ms + up.recovery_ms);
            contact.push_back(up.contact_ms);
            recovery.push_back(up.recovery_ms);
            if (s == co.steps) linear_moved = move_landmarks(loaded.model, condensed.query_field_mm(), loaded.rest_landmarks);
            if (c2f) {
                const EnrichmentCondition condition{"", a, (b - a).normalized(), (at - a).norm()};
                c2f_up = c2f->move_to(cases[c].tool, at, condition);
                c2f_ms.push_back(c2f_up.total_ms());
                c2f_contact.push_back(c2f_up.contact.contact_ms);
                c2f_recovery.push_back(c2f_up.contact.recovery_ms);
                c2f_synthesis.push_back(c2f_up.synthesis_ms);
            }
            bar.update(double(c * co.steps + s) / double(cases.size() * co.steps), fmt::format("{} step {}", cases[c].name, s));
        }
        LandmarkSet moved = move_landmarks(loaded.model, condensed.query_field_mm(), loaded.rest_landmarks);
        json relaxation;
        if (co.nonlinear == "relaxation") {
            // The model's own law by dynamic relaxation, started from the condensed field, and
            // (for the ratio, in the same run) from rest.
            PredictionOptions warm;
            warm.initial_displacement_mm = condensed.full_displacement_mm();
            const auto t0 = std::chrono::steady_clock::now();
            const CompressionPrediction from_condensed = predict_compression(loaded.model, cases[c].tool, loaded.rest_landmarks, warm, cases[c].name);
            const double warm_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            const CompressionPrediction from_rest = predict_compression(loaded.model, cases[c].tool, loaded.rest_landmarks, {}, cases[c].name);
            moved = from_condensed.landmarks;
            state_relax_ms.push_back(1e3 * warm_s);
            relaxation = {{"from_condensed", {{"iterations", from_condensed.iterations}, {"s", warm_s}}},
                          {"from_rest", {{"iterations", from_rest.iterations}, {"s", from_rest.seconds},
                                         {"tre", json::parse(tre_stats_json(compute_tre(from_rest.landmarks, cases[c].truth, cases[c].name)))}}}};
        }
        tre_all.push_back(compute_tre(moved, cases[c].truth, cases[c].name));
        (held.count(cases[c].name) ? tre_held : tre_train).push_back(tre_all.back());
        linear_all.push_back(compute_tre(linear_moved, cases[c].truth, cases[c].name));
        (held.count(cases[c].name) ? linear_held : linear_train).push_back(linear_all.back());
        relax_ms.insert(relax_ms.end(), state_relax_ms.begin(), state_relax_ms.end());
        const TreReport at_rest = compute_tre(loaded.rest_landmarks, cases[c].truth, cases[c].name + " at rest");
        all_ms.insert(all_ms.end(), ms.begin(), ms.end());
        all_contact.insert(all_contact.end(), contact.begin(), contact.end());
        all_recovery.insert(all_recovery.end(), recovery.begin(), recovery.end());
        report["compressions"][cases[c].name] = {
            {"depth_mm", (b - a).norm()}, {"held_out", held.count(cases[c].name) > 0},
            {"ms_per_update", {{"mean", mean_of(ms)}, {"max", *std::max_element(ms.begin(), ms.end())},
                               {"contact", mean_of(contact)}, {"recovery", mean_of(recovery)}}},
            {"final", {{"nodes_in_contact", up.active_nodes}, {"lcp_nodes", up.lcp_nodes}, {"max_penetration_mm", up.max_penetration_mm},
                       {"tool_force_n", up.total_force_n}}},
            {"tre", json::parse(tre_stats_json(tre_all.back()))},
            {"tre_linear_update", json::parse(tre_stats_json(linear_all.back()))},
            {"tre_landmarks_at_rest", json::parse(tre_stats_json(at_rest))}};
        if (!relaxation.is_null()) report["compressions"][cases[c].name]["relaxation"] = relaxation;
        if (c2f) {
            const TreReport t = compute_tre(move_landmarks(loaded.model, c2f->fine_field_mm(), loaded.rest_landmarks), cases[c].truth, cases[c].name);
            (held.count(cases[c].name) ? c2f_held : c2f_train).push_back(t);
            if (c2f_up.match.outside_range) logger()->warn("{}: outside the database's range: {}", cases[c].name, c2f_up.match.range_note);
            report["compressions"][cases[c].name]["coarse_to_fine"] = {
                {"tre", json::parse(tre_stats_json(t))}, {"outside_database_range", c2f_up.match.outside_range},
                {"range_note", c2f_up.match.range_note}, {"final_nodes_in_contact", c2f_up.contact.active_nodes}};
        }
    }
    bar.finish();
    report["summary"] = {{"ms_per_update", mean_of(all_ms)}, {"contact_ms", mean_of(all_contact)}, {"recovery_ms", mean_of(all_recovery)},
                         {"tre", json::parse(tre_stats_json(pool_tre(tre_all)))},
                         {"training", {{"states", tre_train.size()}, {"tre", json::parse(tre_stats_json(pool_tre(tre_train)))}}},
                         {"held_out", {{"states", tre_held.size()}, {"tre", json::parse(tre_stats_json(pool_tre(tre_held)))}}},
                         {"nonlinear", co.nonlinear},
                         {"linear_update_tre", {{"training", json::parse(tre_stats_json(pool_tre(linear_train)))},
                                                {"held_out", json::parse(tre_stats_json(pool_tre(linear_held)))}}},
                         {"relaxation_from_condensed_ms", relax_ms.empty() ? json(nullptr) : json(mean_of(relax_ms))}};
    if (c2f) report["coarse_to_fine"] = coarse_to_fine_report(*c2f, *db, *coarse, co.database, s.match, blend, detail, query.size(), c2f_ms, c2f_contact,
                                                         c2f_recovery, c2f_synthesis, c2f_train, c2f_held);
    std::cerr << fmt::format("bench condensed ({} threads): precomputation {:.1f} s (factor {:.1f} s, {} candidate nodes {:.1f} s); "
                             "{:.2f} ms/update (contact {:.2f}, recovery {:.3f}); TRE at the final depth: training {:.3f} mm, held-out {:.3f} mm "
                             "(linear update alone: {:.3f}, {:.3f} mm; nonlinear {}: {:.0f} ms per final state)\n",
                             omp_get_max_threads(), pre.assembly_s + pre.factorisation_s + pre.compliance_s, pre.factorisation_s,
                             pre.candidate_nodes, pre.compliance_s, mean_of(all_ms), mean_of(all_contact), mean_of(all_recovery),
                             pool_tre(tre_train).all.mean_mm, pool_tre(tre_held).all.mean_mm, pool_tre(linear_train).all.mean_mm,
                             pool_tre(linear_held).all.mean_mm, co.nonlinear, relax_ms.empty() ? 0.0 : mean_of(relax_ms));
    // Tool positions off the session's paths (none here: the candidates come from these paths).
    report["precomputation"]["region_extensions"] = {{"updates", pre.region_extensions}, {"added_candidates", pre.added_candidates},
                                                     {"s", pre.extension_s}};
    report["peak_rss_mb"] = peak_rss_mb();
    if (!co.output.empty())
        write_atomically(co.output, [&](const fs::path& tmp) { std::ofstream(tmp) << report.dump(2) << "\n"; });
    if (co.json) std::cout << report.dump(2) << std::endl;
}

/// bench condensed: time per update with condensed contact (and coarse-to-fine on top with a database).
void add_bench_condensed(CLI::App* group)
{
    auto co = std::make_shared<CondensedOptions>();
    auto* cond = group->add_subcommand("condensed", "Time per update with condensed contact: the model linearised and factorised "
                                                    "once at rest, the compliance of the skin nodes the tools can reach precomputed, a "
                                                    "contact problem on those nodes alone per update; TRE at the final depth");
    cond->add_option("--dataset", co->dataset, "Phantom dataset")->required();
    cond->add_option("--parameters", co->parameters, "Parameter file (physreg estimate)");
    auto cond_settings = std::make_shared<SettingsOptions<EnrichmentApplySettings>>(cond, enrichment_apply_spec());
    cond->add_option("--states", co->states, "Compressions to follow (default A,B,C,D,E); all their tool paths define the candidate nodes");
    cond->add_option("--held-out", co->held_out, "Which of them are held out (default D,E): their TRE is reported apart");
    cond->add_option("--steps", co->steps, "Tool positions from first contact to the final depth (default 20)");
    cond->add_option("--nonlinear", co->nonlinear,
                     "The model's own Neo-Hookean law at each compression's final depth: never (default: the linear law alone) or "
                     "relaxation (dynamic relaxation started from the condensed field, and from rest for comparison; the TRE is then "
                     "the nonlinear one)");
    cond->add_option("--database", co->database,
                     "Enrichment database (physreg enrich build): also coarse-to-fine on top of condensed contact — the coarse model "
                     "condensed, the database matched, the landmarks' fine nodes synthesised — timed per stage");
    cond->add_option("--candidate-margin", co->margin_mm, "Candidates: surface nodes within the tool's reach + this of a path, mm (default 10)");
    cond->add_option("--memory-limit", co->memory_limit, "Memory the precomputation may take (factor, compliance), e.g. 8G; auto (default): "
                                                         "80 % of the physical memory. Over it: an error naming the size needed");
    cond->add_option("-o,--output", co->output, "JSON report (also printed with --json)");
    cond->add_flag("--json", co->json, "Print the report on stdout");
    cond->callback([co, cond_settings] { run_bench_condensed(*co, cond_settings->resolve()); });
}

} // namespace

void add_subcommand_bench(CLI::App& app)
{
    auto* group = app.add_subcommand("bench", "Benchmarks of the registration pipeline (JSON)");
    group->require_subcommand(1);
    add_bench_enrich(group);
    add_bench_condensed(group);
}

} // namespace physreg::cli
