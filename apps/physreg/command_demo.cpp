// SPDX-License-Identifier: GPL-3.0-or-later
// physreg demo: the main job. On the built-in CIRS-057A-like phantom it runs paper 000 end to end:
// phantom dataset (the body ground truth) → coupling estimation (train A, B, C) → detail enrichment
// database (training positions only) → registration of the training and the held-out compressions
// (D, E) with the homogeneous, the high-resolution heterogeneous and the coarse-to-fine model and a
// rigid baseline → TRE (training and held-out apart) and time per update beside paper 000's
// figures, VTU files and PNG figures. --quick does the same on the small preset (tests).
#include "cli_support.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/mesh/surface_extraction.hpp"
#include "physreg/mesh/tet_split.hpp"
#include "physreg/mechanics/simulation/simulation.hpp"
#include "physreg/phantom/synthetic_phantom.hpp"
#include "progress.hpp"

#include "physreg/phantom/dataset.hpp"
#include "physreg/evaluation/tre.hpp"
#include "physreg/figures/tre_chart.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/figures/slice_figure.hpp"
#include "physreg/io/png.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/registration/compression/condensed_coarse_to_fine.hpp"
#include "physreg/registration/compression/condensed_contact.hpp"
#include "physreg/registration/compression/enrichment.hpp"
#include "physreg/registration/compression/estimation.hpp"

#include <numeric>
#include <omp.h>
#include "physreg/core/version.hpp"

#include <chrono>
#include <fstream>
#include <iostream>

namespace physreg::cli {

namespace {

// The building blocks on the small synthetic liver (labels 1–3, paper 000's default tissues):
// meshes (voxel, grid, coarse), surfaces, tetrahedra, located landmarks, a TLED indentation.
// Quick; its files are the inputs of the command-line tests and show each format.
nlohmann::json run_meshing_blocks(const std::filesystem::path& dir)
{
    namespace fs = std::filesystem;
    using clock = std::chrono::steady_clock;
    auto ms_since = [](clock::time_point t0) {
        return std::chrono::duration<double, std::milli>(clock::now() - t0).count();
    };
    const Index3 grid{72, 56, 36};
    const Index3 coarse_grid{24, 18, 18};
    const double voxel_mm = 2.0;
    fs::create_directories(dir);
    auto step = [](int n, const std::string& text) { logger()->debug("meshing blocks [{}/7] {}", n, text); };

    step(1, "synthetic liver label volume");
    auto t0 = clock::now();
    const SyntheticPhantom phantom = make_synthetic_liver(voxel_mm);
    const TissueTable tissues = default_tissue_table();
    write_label_volume(dir / "labels.nii.gz", phantom.labels);
    write_tissue_table(dir / "tissues.yaml", tissues);
    for (const char* name : {"landmarks.csv", "landmarks.mrk.json", "landmarks.fcsv"})
        write_landmarks(dir / name, phantom.landmarks);
    const double phantom_ms = ms_since(t0);

    step(2, "hexahedral mesh, one hexahedron per voxel");
    t0 = clock::now();
    MeshingOptions voxel_options;
    const auto voxel = mesh_label_volume(phantom.labels, tissues, voxel_options, "synthetic liver");
    const double voxel_ms = ms_since(t0);
    write_volume_mesh(dir / "mesh_voxels.vtu", voxel.mesh);

    step(3, "hexahedral mesh on the 72x56x36 grid (majority rule)");
    t0 = clock::now();
    MeshingOptions grid_options;
    grid_options.grid_dims = grid;
    const auto fine = mesh_label_volume(phantom.labels, tissues, grid_options, "synthetic liver");
    const double grid_ms = ms_since(t0);
    write_volume_mesh(dir / "mesh_fine.vtu", fine.mesh);

    step(4, "coarse mesh on the 24x18x18 grid, fine nodes embedded");
    t0 = clock::now();
    const auto coarse = coarsen(fine.mesh, coarse_grid, ComponentPolicy::keep_all);
    const double coarse_ms = ms_since(t0);
    write_volume_mesh(dir / "mesh_coarse.vtu", coarse.mesh);
    std::size_t outside = 0;
    for (const auto& e : coarse.fine_nodes) outside += !e.inside;

    step(5, "surfaces (boundary + tissue interfaces) and conforming tetrahedra");
    t0 = clock::now();
    const SurfaceMesh surfaces = extract_surfaces(fine.mesh);
    const VolumeMesh tets = split_hexahedra_into_tetrahedra(fine.mesh);
    const double surface_ms = ms_since(t0);
    write_surface(dir / "surfaces_fine.ply", surfaces);
    write_surface(dir / "boundary_fine.stl", extract_boundary(fine.mesh));
    write_volume_mesh(dir / "tetrahedra_fine.vtu", tets);

    step(6, "landmarks located in the fine mesh");
    const PointLocator locator(fine.mesh);
    nlohmann::json located = nlohmann::json::array();
    for (const auto& l : phantom.landmarks) {
        const auto e = locator.locate(l.position);
        located.push_back({{"name", l.name}, {"type", to_string(l.type)}, {"inside_mesh", e.has_value()},
                           {"cell", e ? e->cell : -1}});
    }

    step(7, "TLED: a 30 mm sphere pressed 10 mm into the anterior surface of the coarse model");
    SimulationCase indentation;
    indentation.source = dir / "summary.json";
    indentation.mesh_file = dir / "mesh_coarse.vtu";
    indentation.tissues_file = dir / "tissues.yaml";
    indentation.load_steps = 4;
    SimulationCase::Constraint back;
    back.name = "posterior face";
    back.select.axis = 1;
    back.select.side = "max";
    back.select.tolerance_mm = 3.0;
    indentation.constraints.push_back(back);
    Indenter tool;
    tool.name = "sphere";
    tool.radius_mm = 15.0;
    tool.path = {Vec3(-30, -78, 0), Vec3(-30, -68, 0)};
    indentation.indenters.push_back(tool);
    indentation.output_directory = dir / "indentation";
    indentation.frames = 4;
    indentation.field_spacing_mm = 2.0;
    const SimulationResult simulated = run_simulation(indentation, {});
    const nlohmann::json simulation = write_simulation_outputs(indentation, simulated);
    long iterations = 0;
    for (const auto& e : simulated.equilibria) iterations += e.iterations;

    return {
        {"label_volume", to_json(phantom.labels.geometry)},
        {"voxel_mesh", mesh_summary(voxel.mesh, &tissues)},
        {"fine_mesh", mesh_summary(fine.mesh, &tissues)},
        {"coarse_mesh", mesh_summary(coarse.mesh, &tissues)},
        {"fine_nodes_outside_coarse_mesh", outside},
        {"surface_triangles", surfaces.triangles.size()},
        {"tetrahedra", tets.cell_count()},
        {"landmarks", located},
        {"indentation", simulation},
        {"timings_ms", {{"phantom", phantom_ms}, {"voxel_mesh", voxel_ms}, {"grid_mesh", grid_ms},
                        {"coarsen_and_embed", coarse_ms}, {"surfaces_and_tetrahedra", surface_ms}}}};
}

/// A method of the demo's table: its TRE on the held-out (D, E) and training (A, B, C) states, its
/// times per update, and paper 000's figures where the paper has them.
struct DemoMethod {
    std::string name, paper;
    double paper_all, paper_surface, paper_internal, paper_ms;
    std::vector<TreReport> tre, tre_train; ///< held-out (D, E); training (A, B, C)
    std::vector<double> ms;
};

struct DemoPhantom {
    bool reused = false;
    double seconds = 0.0;
};

/// The demo's phantom dataset in phantom_dir: hard links to an earlier run's (earlier_phantom) when
/// it was made by this version with the same preset and seed, else generated.
DemoPhantom demo_phantom(const PhantomSpec& spec, const std::filesystem::path& earlier_phantom, const std::filesystem::path& phantom_dir, bool rebuild)
{
    namespace fs = std::filesystem;
    bool reuse = false;
    if (!rebuild && fs::exists(earlier_phantom / "manifest.json")) {
        try {
            const PhantomDataset old = read_phantom_dataset(earlier_phantom);
            reuse = old.preset == spec.preset && old.seed == spec.seed && old.generator_version == VERSION;
        } catch (const Error&) {
            reuse = false;
        }
        if (reuse) {
            // Hard links: no copy, and the earlier OUTPUT stays whole if this run fails.
            fs::copy(earlier_phantom, phantom_dir, fs::copy_options::recursive | fs::copy_options::create_hard_links);
            logger()->info("reusing the phantom dataset of an earlier run in '{}' (--rebuild-phantom makes it anew)", earlier_phantom.string());
        }
    }
    double phantom_s = 0.0;
    if (!reuse) {
        const auto t = std::chrono::steady_clock::now();
        ProgressDisplay bar("phantom");
        generate_phantom_dataset(spec, phantom_dir, true, [&](double f, const std::string& m) { bar.update(f, m); });
        bar.finish();
        phantom_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    }
    return {reuse, phantom_s};
}

/// A held-out state's outputs: the fine mesh with both solutions and their difference and the
/// homogeneous one (VTU, ParaView), the predicted landmarks (CSV), slices through the tool's dent with
/// true and predicted landmarks (paper 000 figs. 8/9) and the map of |coarse-to-fine − high-resolution|
/// (fig. 11); returns the state's summary entry.
nlohmann::json write_held_out_outputs(const std::filesystem::path& dir, const PhantomDataset& dataset, const CompressionCase& vc, const LiverModel& fine,
                                      const LiverModel& homogeneous, const TrackingRun& run, const std::vector<double>& homogeneous_u,
                                      const LandmarkSet& homogeneous_landmarks, const LabelVolume& rest_labels, double pixels_per_mm)
{
    const Vec3 a = vc.tool.path.front(), b = vc.tool.path.back();
    // VTU for ParaView: the fine mesh with both solutions and their difference; the homogeneous one.
    std::vector<double> difference(run.high_resolution_u.size()), magnitude(fine.mesh.node_count());
    double largest = 0.0;
    for (std::size_t k = 0; k < difference.size(); ++k) difference[k] = run.coarse_to_fine_u[k] - run.high_resolution_u[k];
    for (std::size_t n = 0; n < magnitude.size(); ++n) {
        magnitude[n] = Vec3(difference[3 * n], difference[3 * n + 1], difference[3 * n + 2]).norm();
        largest = std::max(largest, magnitude[n]);
    }
    MeshData data;
    data.point_data = {{"displacement_high_resolution", 3, run.high_resolution_u},
                       {"displacement_coarse_to_fine", 3, run.coarse_to_fine_u},
                       {"difference_mm", 3, difference},
                       {"difference_magnitude_mm", 1, magnitude}};
    write_vtu(dir / "registration" / (vc.name + "_fine.vtu"), fine.mesh, data);
    MeshData plain_data;
    plain_data.point_data = {{"displacement", 3, homogeneous_u}};
    write_vtu(dir / "registration" / (vc.name + "_homogeneous.vtu"), homogeneous.mesh, plain_data);
    write_landmarks(dir / "registration" / (vc.name + "_landmarks_high_resolution.csv"), run.high_resolution_landmarks);
    write_landmarks(dir / "registration" / (vc.name + "_landmarks_coarse_to_fine.csv"), run.coarse_to_fine_landmarks);
    write_landmarks(dir / "registration" / (vc.name + "_landmarks_homogeneous.csv"), homogeneous_landmarks);
    // Figures: slices through the tool's dent with true (green) and predicted (red) landmarks
    // (paper 000 figs. 8/9), and the map of |coarse-to-fine − high-resolution| (fig. 11).
    const DatasetState& state = dataset.state(vc.name);
    const ScalarImage intensity = read_scalar_image(dataset.path(state.files.at("intensity")));
    const LabelVolume labels = read_label_volume(dataset.path(state.files.at("labels")));
    SliceFigureOptions figure;
    figure.centre = b + vc.tool.radius_mm * (b - a).normalized();
    figure.pixels_per_mm = pixels_per_mm;
    figure.title = fmt::format("{}: TRUE (GREEN) AND COARSE-TO-FINE (RED) LANDMARKS", vc.name);
    write_png(dir / "figures" / ("slices_" + vc.name + "_coarse_to_fine.png"),
              render_orthogonal_slices(intensity, labels, dataset.roles, vc.truth, run.coarse_to_fine_landmarks, figure).image());
    figure.title = fmt::format("{}: TRUE (GREEN) AND HIGH-RESOLUTION (RED) LANDMARKS", vc.name);
    write_png(dir / "figures" / ("slices_" + vc.name + "_high_resolution.png"),
              render_orthogonal_slices(intensity, labels, dataset.roles, vc.truth, run.high_resolution_landmarks, figure).image());
    const ImageGeometry& g = rest_labels.geometry;
    const SampledField field = sample_displacement_field(fine.mesh, difference, g);
    ScalarImage heat{g, std::vector<float>(field.inside.size(), std::numeric_limits<float>::quiet_NaN())};
    for (std::size_t v = 0; v < field.inside.size(); ++v)
        if (field.inside[v]) heat.values[v] = static_cast<float>(Vec3(field.field.components[3 * v], field.field.components[3 * v + 1], field.field.components[3 * v + 2]).norm());
    const ScalarImage rest_intensity = read_scalar_image(dataset.path(dataset.state("rest").files.at("intensity")));
    const LabelVolume rest_label_image = rest_labels;
    figure.heat = &heat;
    figure.heat_max = std::max(0.05, std::ceil(largest * 20.0) / 20.0);
    figure.heat_label = "DIFFERENCE, MM";
    figure.title = fmt::format("{}: DISPLACEMENT DIFFERENCE, REST CONFIGURATION (MAX {:.2f} MM)", vc.name, largest);
    write_png(dir / "figures" / ("difference_" + vc.name + ".png"),
              render_orthogonal_slices(rest_intensity, rest_label_image, dataset.roles, {}, {}, figure).image());
    return {{"max_difference_high_resolution_vs_coarse_to_fine_mm", largest},
                          {"matched_conditions", run.last_match.conditions.size()},
                          {"outside_database_range", run.last_match.outside_range},
                          {"nearest_stored_position_mm", run.last_match.nearest_position_mm},
                          {"detail_share", run.last_match.detail}};
}

/// The demo's table of methods: TRE on the training and held-out states, time per update and
/// paper 000's figures, as text (returned) and as the summary's rows (`table`).
std::string demo_table(const std::vector<DemoMethod>& methods, const std::string& preset, std::size_t landmarks, nlohmann::json& table)
{
    using json = nlohmann::json;
    table = json::array();
    std::string text = fmt::format("\nphysreg demo — {} phantom (body ground truth: gel, tetrahedra, Mooney-Rivlin, unknown moduli), "
                                   "{} landmarks per compression, {} threads\n\n", preset, landmarks, omp_get_max_threads());
    text += fmt::format("{:<34}{:>28}{:>28}{:>10}   {}\n", "method", "training A,B,C: all/surf/int", "held-out D,E: all/surf/int", "ms/update",
                        "paper 000 (all/surface/internal, time)");
    for (const auto& m : methods) {
        const TreReport r = pool_tre(m.tre), rt = pool_tre(m.tre_train);
        const double ms = m.ms.empty() ? 0.0 : std::accumulate(m.ms.begin(), m.ms.end(), 0.0) / double(m.ms.size());
        text += fmt::format("{:<34}{:>9.2f} /{:>6.2f} /{:>6.2f} mm{:>9.2f} /{:>6.2f} /{:>6.2f} mm{:>10}   {}\n", m.name, rt.all.mean_mm,
                            rt.surface.mean_mm, rt.internal.mean_mm, r.all.mean_mm, r.surface.mean_mm, r.internal.mean_mm,
                            m.ms.empty() ? std::string("-") : (ms < 10 ? fmt::format("{:.2f}", ms) : fmt::format("{:.1f}", ms)), m.paper);
        json row = {{"method", m.name}, {"tre_held_out", json::parse(tre_stats_json(r))}, {"tre_training", json::parse(tre_stats_json(rt))}};
        if (!m.ms.empty()) row["ms_per_update"] = ms;
        if (m.paper_all > 0)
            row["paper_000"] = {{"tre_all_mm", m.paper_all}, {"tre_surface_mm", m.paper_surface}, {"tre_internal_mm", m.paper_internal}, {"ms_per_frame", m.paper_ms}};
        table.push_back(row);
    }
    text += "(rigid: fitted to the 11 noisy surface landmarks of each state, so its surface TRE is a fit residual)\n";
    return text;
}

/// The tool followed by condensed contact (or its coarse-to-fine variant) in `steps` positions from
/// first contact to the last pose; each update's milliseconds into `ms` when given. Returns the field
/// at the query nodes (fine model).
std::vector<double> follow_condensed(CondensedContactModel& model, const Indenter& tool, int steps, std::vector<double>* ms)
{
    const Vec3 a = tool.path.front(), b = tool.path.back();
    model.reset();
    for (int s = 1; s <= steps; ++s) {
        const auto up = model.move_to(tool, a + (b - a) * double(s) / double(steps));
        if (ms) ms->push_back(up.contact_ms + up.recovery_ms);
    }
    return model.query_field_mm();
}

std::vector<double> follow_condensed(CondensedCoarseToFine& model, const Indenter& tool, int steps, std::vector<double>* ms)
{
    const Vec3 a = tool.path.front(), b = tool.path.back();
    model.reset();
    for (int s = 1; s <= steps; ++s) {
        const Vec3 at = a + (b - a) * double(s) / double(steps);
        const auto up = model.move_to(tool, at, {"", a, (b - a).normalized(), (at - a).norm()});
        if (ms) ms->push_back(up.total_ms());
    }
    return model.fine_field_mm();
}

/// summary.json of the demo: the table, the fit (start, bounds, identifiability), the database, per state and timings.
nlohmann::json demo_summary(const std::string& preset, std::uint64_t seed, const nlohmann::json& table, const EstimationResult& fit,
                            const std::vector<DemoMethod>& methods, const EnrichmentDatabase& db, std::uintmax_t database_bytes, int blend,
                            double detail_length, const nlohmann::json& per_state, const nlohmann::json& blocks, const nlohmann::json& seconds)
{
    using json = nlohmann::json;
    return {{"preset", preset},
                    {"seed", seed},
                    {"methods", table},
                    {"fitted", to_json(fit.fitted)},
                    // The optimiser's start: a fitted value equal to it was not moved by the data.
                    {"fit_start", fit.history.empty() ? json(nullptr) : to_json(fit.history.front().parameters)},
                    {"fit_at_bound", fit.at_bound},
                    {"fit_identifiability", [&] {
                         json j = json::object();
                         for (const auto& s : fit.sensitivity)
                             j[s.parameter] = {{"objective_change_mm_per_decade", s.mm_per_decade}, {"identifiable", s.identifiable}};
                         return j;
                     }()},
                    {"train_tre", json::parse(tre_stats_json(fit.train_pooled))},
                    {"validation_tre", json::parse(tre_stats_json(pool_tre(methods[1].tre)))},
                    {"validation_landmarks_at_rest", json::parse(tre_stats_json(pool_tre(methods[4].tre)))},
                    {"database", {{"conditions", db.conditions.size()}, {"bytes", database_bytes}, {"blend", blend},
                                  {"detail_length_mm", std::isinf(detail_length) ? json("inf") : json(detail_length)}}},
                    {"per_state", per_state},
                    {"meshing_blocks", blocks},
                    {"seconds", seconds}};
}

/// The demo's models and the detail enrichment database of step 4.
struct DemoModels {
    LiverModel fine, coarse;
    EnrichmentDatabase db;
    std::vector<NodeEmbedding> embedding;
    int blend = 0;
    double detail_length = 0.0;
};

/// Step 4: the fitted fine model, its coarse companion and the enrichment database over the
/// training positions A, B, C × depths (written to dir/enrichment.phe).
DemoModels build_demo_models(const std::filesystem::path& dir, const PhantomDataset& dataset, const LabelVolume& rest_labels,
                             const EstimationResult& fit, const std::vector<CompressionCase>& train_cases, const Index3& coarse_grid,
                             const std::vector<double>& depths)
{
    namespace fs = std::filesystem;
    DemoModels m;
    m.fine = build_liver_model(rest_labels, dataset.roles, fit.fitted, "phantom rest labels");
    m.coarse = coarsen_liver_model(m.fine, coarse_grid, &m.embedding);
    EnrichmentPlan plan;
    // Held-out evaluation: only the training compressions' tool positions go into the database.
    // A grid over the skin (`enrich build --positions-grid`) was measured here and made
    // coarse-to-fine worse (docs/enrichment.md): the detail of a position 10 mm away hurts.
    for (const auto& c : train_cases)
        plan.positions.push_back({c.name, c.tool.path.front()}), plan.direction = (c.tool.path.back() - c.tool.path.front()).normalized();
    plan.depths_mm = depths;
    {
        ProgressDisplay bar("enrich build");
        EnrichmentBuildOptions options;
        options.checkpoint_directory = dir / "enrichment.phe.partial";
        options.progress = [&](double f, const std::string& m) { bar.update(f, m); };
        m.db = build_enrichment_database(m.fine, m.coarse, m.embedding, train_cases.front().tool, plan, options);
        bar.finish();
    }
    write_enrichment_database(dir / "enrichment.phe", m.db);
    fs::remove_all(dir / "enrichment.phe.partial");
    m.blend = choose_blend_size(m.db, m.coarse.mesh, m.embedding, m.fine.mesh.nodes, 4);
    // Paper 000's synthesis: the stored detail at any distance. A detail share chosen by leave
    // one position out was measured here and picked the wrong way on both presets
    // (docs/enrichment.md), so the demo keeps the paper's.
    m.detail_length = std::numeric_limits<double>::infinity();
    return m;
}

/// The demo's table rows and the held-out states' summaries (step 5).
struct DemoRegistration {
    std::vector<DemoMethod> methods;
    nlohmann::json per_state;
};

/// Step 5: the training (A, B, C) and held-out (D, E) compressions followed in track_steps tool
/// positions with every model of the table; the held-out states' outputs written under dir.
DemoRegistration register_demo_compressions(const std::filesystem::path& dir, const PhantomDataset& dataset, const LabelVolume& rest_labels,
                                            const LandmarkSet& rest_landmarks, const EstimationResult& fit, const DemoModels& models,
                                            const std::vector<CompressionCase>& train_cases,
                                            const std::vector<CompressionCase>& validation_cases, int track_steps, bool quick)
{
    using json = nlohmann::json;
    const LiverModel& fine = models.fine;
    const LiverModel& coarse = models.coarse;
    const auto& embedding = models.embedding;
    const EnrichmentDatabase& db = models.db;
    const int blend = models.blend;
    const double detail_length = models.detail_length;
    ModelParameters homogeneous_parameters = fit.fitted;
    homogeneous_parameters.variant = ModelVariant::homogeneous;
    const LiverModel homogeneous = build_liver_model(rest_labels, dataset.roles, homogeneous_parameters, "phantom rest labels");
    const PredictionOptions prediction;
    std::vector<DemoMethod> methods{{"homogeneous (Han et al.)", "7.74 / 6.39 / 8.81 mm, 344.83 ms", 7.74, 6.39, 8.81, 344.83, {}, {}, {}},
                                {"high-resolution heterogeneous", "2.22 / 2.45 / 2.04 mm, 344.83 ms", 2.22, 2.45, 2.04, 344.83, {}, {}, {}},
                                {"coarse-to-fine", "3.42 / 3.46 / 3.38 mm, 36.76 ms", 3.42, 3.46, 3.38, 36.76, {}, {}, {}},
                                {"rigid (noisy surface landmarks)", "-", 0, 0, 0, 0, {}, {}, {}},
                                {"landmarks left at rest", "-", 0, 0, 0, 0, {}, {}, {}},
                                {"condensed contact", "-", 0, 0, 0, 0, {}, {}, {}},
                                {"condensed coarse-to-fine", "-", 0, 0, 0, 0, {}, {}, {}}};
    json per_state;
    std::vector<CompressionCase> all_cases = train_cases;
    all_cases.insert(all_cases.end(), validation_cases.begin(), validation_cases.end());
    // Condensed contact (issue 30): the high-resolution model linearised and factorised once,
    // the compliance of the skin nodes the five tools reach and of the landmarks' nodes kept.
    std::vector<Indenter> session_tools;
    for (const auto& c : all_cases) session_tools.push_back(c.tool);
    std::vector<Vec3> landmark_points;
    for (const auto& l : rest_landmarks) landmark_points.push_back(l.position);
    const auto query = nodes_near(fine.mesh, landmark_points, 2.0 * fine.cell_size_mm.maxCoeff());
    CondensedContactModel condensed(fine, session_tools, query);
    logger()->info("condensed contact: {} candidate nodes, precomputed in {:.1f} s", condensed.precomputation().candidate_nodes,
                   condensed.precomputation().assembly_s + condensed.precomputation().factorisation_s + condensed.precomputation().compliance_s);
    // Coarse-to-fine on top: the coarse model condensed the same way, the landmarks' fine nodes synthesised.
    CondensedCoarseToFine condensed_c2f(fine, coarse, embedding, db, session_tools, query, EnrichmentMatching::parameters,
                                        EnrichmentBlend(blend, detail_length));
    ProgressDisplay bar("registration");
    // Training states need TRE only: the high-resolution equilibria are the estimation's own at
    // the fitted parameters (same model, tool and tolerance), the homogeneous model is solved at
    // the final depth (three solves packed on the threads); coarse-to-fine is tracked as for
    // D, E. Held-out states are tracked with every model for the time per update. Progress
    // weights: measured shares of this stage on cirs057a.
    const double homogeneous_share = 0.25, training_share = 0.03, held_out_share = (1.0 - homogeneous_share - 3 * training_share) / 2.0;
    bar.update(0.0, "homogeneous model on the training compressions");
    // Warm-started from the heterogeneous model's equilibria (the materials differ little, so
    // each solve needs a fraction of the iterations from rest; same tolerance). The coupled mesh
    // doubles the interface nodes: its field is interpolated onto the homogeneous mesh.
    std::vector<std::vector<double>> homogeneous_warm;
    for (const auto& u : fit.train_displacement_mm) homogeneous_warm.push_back(transfer_displacement(fine, u, homogeneous));
    const auto homogeneous_train = evaluate_cases(homogeneous, homogeneous_parameters, rest_landmarks, train_cases, prediction,
                                                  homogeneous_warm.size() == train_cases.size() ? &homogeneous_warm : nullptr);
    double done_share = homogeneous_share;
    for (std::size_t c = 0; c < all_cases.size(); ++c) {
        const auto& vc = all_cases[c];
        const bool held_out = c >= train_cases.size();
        const double share = held_out ? held_out_share : training_share;
        const TrackingRun run = track_compression(fine, coarse, embedding, db, vc.tool, rest_landmarks, track_steps, EnrichmentMatching::parameters,
                                                  EnrichmentBlend(blend, detail_length), prediction, vc.name, [&](int s) {
                                                      bar.update(done_share + share * 0.5 * double(s) / double(track_steps),
                                                                 fmt::format("{} step {}", vc.name, s));
                                                  }, /*high_resolution=*/held_out);
        if (run.last_match.outside_range) logger()->warn("{}: outside the database's range ({}); extrapolated", vc.name, run.last_match.range_note);
        const Vec3 a = vc.tool.path.front(), b = vc.tool.path.back();
        // Homogeneous model: the same tracking on the held-out states.
        std::vector<double> homogeneous_u;
        LandmarkSet homogeneous_landmarks;
        if (held_out) {
            CompressionTracker plain(homogeneous, vc.tool, prediction);
            for (int s = 1; s <= track_steps; ++s) {
                methods[0].ms.push_back(1e3 * plain.move_to(a + (b - a) * double(s) / double(track_steps), vc.name + " (homogeneous)").seconds);
                bar.update(done_share + share * (0.5 + 0.5 * double(s) / double(track_steps)), fmt::format("{} step {} (homogeneous)", vc.name, s));
            }
            homogeneous_u = plain.displacement_mm();
            homogeneous_landmarks = move_landmarks(homogeneous, homogeneous_u, rest_landmarks);
        }
        done_share += share;
        // Rigid baseline: the rigid motion that best maps the rest surface landmarks onto their noisy
        // observed positions in this state (what a tracked pointer would give), applied to all.
        const DatasetState& observed_state = dataset.state(vc.name);
        const LandmarkSet observed = read_landmarks(dataset.path(observed_state.files.at("landmarks_noisy")));
        const LandmarkSet rigid_landmarks = rigid_landmark_registration(rest_landmarks, observed, LandmarkType::surface, vc.name + " (rigid)");
        const auto record_report = [&](DemoMethod& m, const TreReport& r) { (held_out ? m.tre : m.tre_train).push_back(r); };
        const auto record = [&](DemoMethod& m, const LandmarkSet& predicted) { record_report(m, compute_tre(predicted, vc.truth, vc.name)); };
        if (held_out) {
            record(methods[0], homogeneous_landmarks);
            record(methods[1], run.high_resolution_landmarks);
        } else {
            record_report(methods[0], homogeneous_train.at(c).second);
            record_report(methods[1], fit.train.at(c).second);
            if (fit.train.at(c).first != vc.name) fail("demo: the estimation's training reports are out of order ({} for {})", fit.train.at(c).first, vc.name);
        }
        record(methods[2], run.coarse_to_fine_landmarks);
        record(methods[3], rigid_landmarks);
        record(methods[4], rest_landmarks);
        // Condensed contact along the same tool positions.
        record(methods[5], move_landmarks(fine, follow_condensed(condensed, vc.tool, track_steps, held_out ? &methods[5].ms : nullptr), rest_landmarks));
        record(methods[6], move_landmarks(fine, follow_condensed(condensed_c2f, vc.tool, track_steps, held_out ? &methods[6].ms : nullptr), rest_landmarks));
        if (!held_out) continue; // timings, outputs and figures: the held-out compressions
        methods[1].ms.insert(methods[1].ms.end(), run.high_resolution_ms.begin(), run.high_resolution_ms.end());
        methods[2].ms.insert(methods[2].ms.end(), run.coarse_to_fine_ms.begin(), run.coarse_to_fine_ms.end());
        per_state[vc.name] = write_held_out_outputs(dir, dataset, vc, fine, homogeneous, run, homogeneous_u, homogeneous_landmarks, rest_labels,
                                                    quick ? 1.0 : 2.0);
    }
    bar.finish();
    return {std::move(methods), std::move(per_state)};
}

} // namespace

void add_subcommand_demo(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string output = "demo-out";
        bool quick = false, rebuild = false;
        int evaluations = 0;
        std::uint64_t seed = 1;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("demo", "The main job: phantom → estimation → enrichment database → registration of the validation "
                                           "compressions (homogeneous, high-resolution, coarse-to-fine) with TRE, timings and figures");
    sub->add_option("-o,--output", o->output, "Output directory (created)")->capture_default_str();
    sub->add_flag("--quick", o->quick, "Small preset and grids (≈ 1 min; for tests)");
    sub->add_flag("--rebuild-phantom", o->rebuild, "Rebuild the phantom dataset even if OUTPUT/phantom holds one from an earlier run");
    sub->add_option("--max-evaluations", o->evaluations, "Estimation budget (default 8; quick 4)");
    sub->add_option("--seed", o->seed, "Seed of the phantom (its ground-truth materials, mesh and noise; default 1)");
    sub->add_flag("--json", o->json, "Print the JSON summary on stdout");
    sub->callback([o] {
        namespace fs = std::filesystem;
        using json = nlohmann::json;
        using clock = std::chrono::steady_clock;
        const auto start = clock::now();
        auto seconds_since = [](clock::time_point t) { return std::chrono::duration<double>(clock::now() - t).count(); };
        // Everything is written into a staging folder beside OUTPUT that replaces it only when the
        // demo has finished: an interrupted or failed demo leaves the earlier OUTPUT (or none).
        const fs::path target(o->output);
        StagedDirectory staging(target, /*replace=*/true);
        const fs::path dir = staging.path();
        fs::create_directories(dir / "figures");
        fs::create_directories(dir / "registration");
        const int steps_total = 7;
        auto step = [&](int n, const std::string& text) { logger()->info("[{}/{}] {} ({:.0f} s so far)", n, steps_total, text, seconds_since(start)); };
        // Settings: paper 000's grids on the full phantom; small ones for --quick.
        const std::string preset = o->quick ? "small" : "cirs057a";
        // The body model (gel with the organs inside, bone held, base on the table): 5 mm cells on the
        // CIRS body, 10 mm coarse; about half that resolution for --quick.
        const Index3 grid = o->quick ? Index3{27, 20, 13} : Index3{54, 40, 26};
        const Index3 coarse_grid = o->quick ? Index3{20, 15, 10} : Index3{27, 20, 13};
        // Tool travel on the skin from first contact, as in the phantom's compressions (up to 25 mm).
        const std::vector<double> depths = o->quick ? std::vector<double>{4, 8, 12, 15} : std::vector<double>{5, 10, 15, 20, 25};
        const int evaluations = o->evaluations > 0 ? o->evaluations : (o->quick ? 4 : 8);
        const int track_steps = o->quick ? 5 : 4;
        const std::vector<std::string> train{"A", "B", "C"}, validation{"D", "E"};

        step(1, "building blocks on the synthetic liver: meshes, surfaces, tetrahedra, a TLED indentation → meshing/");
        const json blocks = run_meshing_blocks(dir / "meshing");

        step(2, "phantom dataset (" + preset + " preset) → phantom/");
        const fs::path phantom_dir = dir / "phantom";
        // The demo's phantom is `physreg phantom`'s default: the body ground truth (docs/phantom.md).
        PhantomSpec phantom_spec = PhantomSpec::preset_spec(preset);
        phantom_spec.seed = o->seed;
        phantom_spec.validate();
        const DemoPhantom phantom = demo_phantom(phantom_spec, target / "phantom", phantom_dir, o->rebuild);
        const bool reuse = phantom.reused;
        const double phantom_s = phantom.seconds;
        const PhantomDataset dataset = read_phantom_dataset(phantom_dir);
        const LabelVolume rest_labels = read_label_volume(dataset.path(dataset.state("rest").files.at("labels")));
        const LandmarkSet rest_landmarks = read_landmarks(dataset.path(dataset.state("rest").files.at("landmarks")));
        const auto train_cases = compression_cases(dataset, train), validation_cases = compression_cases(dataset, validation);

        step(3, "coupling stiffnesses and the gel's modulus estimated on A, B, C (NLopt BOBYQA) → params.json");
        auto t = clock::now();
        ModelParameters initial;
        initial.grid = grid;
        EstimationOptions estimation;
        estimation.max_evaluations = evaluations;
        EstimationResult fit;
        {
            ProgressDisplay bar("estimate");
            // Held-out D, E are registered in step 5 with the fitted model: not solved here twice.
            fit = estimate_parameters(rest_labels, dataset.roles, initial, rest_landmarks, train_cases, {}, estimation,
                                      [&](double f, const std::string& m) { bar.update(f, m); });
            bar.finish();
        }
        write_model_parameters(dir / "params.json", fit.fitted, fit.fingerprint,
                               json({{"objective_mm", fit.objective_mm}, {"evaluations", fit.history.size()}}).dump());
        const double estimate_s = seconds_since(t);

        step(4, "detail enrichment database: training positions A, B, C × depths, fine and coarse models → enrichment.phe");
        t = clock::now();
        const DemoModels models = build_demo_models(dir, dataset, rest_labels, fit, train_cases, coarse_grid, depths);
        const EnrichmentDatabase& db = models.db;
        const double database_s = seconds_since(t);
        const auto database_bytes = fs::file_size(dir / "enrichment.phe");

        step(5, "training (A, B, C) and held-out (D, E) compressions followed in " + std::to_string(track_steps) +
                    " tool positions: homogeneous, high-resolution heterogeneous, coarse-to-fine; rigid baseline");
        t = clock::now();
        auto [methods, per_state] = register_demo_compressions(dir, dataset, rest_labels, rest_landmarks, fit, models, train_cases,
                                                               validation_cases, track_steps, o->quick);
        const double registration_s = seconds_since(t);

        step(6, "TRE chart → figures/tre.png");
        std::vector<TreSeries> series;
        for (const auto& m : methods) {
            const std::string first = m.name.substr(0, m.name.find(' '));
            series.push_back({first == "high-resolution" ? "HIGH-RES" : m.name == "condensed coarse-to-fine" ? "COND-C2F" : first, pool_tre(m.tre)});
        }
        write_png(dir / "figures" / "tre.png", render_tre_chart(series, "TRE ON HELD-OUT COMPRESSIONS D, E"));

        step(7, "summary");
        json table;
        std::string text = demo_table(methods, preset, rest_landmarks.size(), table);
        const double total_s = seconds_since(start);
        text += fmt::format("\n{} model, {}x{}x{} cells (coarse {}x{}x{}); fitted k_c,s-t = {:.4g} N/m, k_c,s-v = {:.4g} N/m (paper 000: 600, 500), "
                            "gel E {:.4g} Pa (start 1e5){}; training TRE {:.3f} mm (paper 2.00), validation {:.3f} mm (paper 2.55)\n",
                            to_string(fit.fitted.region), grid[0], grid[1], grid[2], coarse_grid[0], coarse_grid[1], coarse_grid[2],
                            fit.fitted.coupling.parenchyma_tumour_n_per_m, fit.fitted.coupling.parenchyma_vessel_n_per_m, fit.fitted.body_young_pa,
                            fit.at_bound.empty() ? "" : fmt::format(" (AT A BOUND: {})", fmt::join(fit.at_bound, ", ")), fit.train_pooled.all.mean_mm,
                            pool_tre(methods[1].tre).all.mean_mm);
        text += fmt::format("landmarks left at rest (how far D, E moved them): {:.3f} mm; enrichment database {} conditions, {:.1f} MB, blend {}, "
                            "detail length {} mm\n",
                            pool_tre(methods[4].tre).all.mean_mm, db.conditions.size(), double(database_bytes) / 1e6, models.blend, models.detail_length);
        text += fmt::format("time: phantom {:.0f} s{}, estimation {:.0f} s, database {:.0f} s, registration {:.0f} s; total {:.0f} s\n", phantom_s,
                            reuse ? " (reused)" : "", estimate_s, database_s, registration_s, total_s);
        text += fmt::format("outputs in '{}': registration/*.vtu (ParaView), figures/*.png, params.json, enrichment.phe, phantom/ (3D Slicer: "
                            "images, fields, landmarks)\n", target.string());
        const json summary = demo_summary(preset, o->seed, table, fit, methods, db, database_bytes, models.blend, models.detail_length, per_state, blocks,
                                          {{"phantom", phantom_s}, {"phantom_reused", reuse}, {"estimation", estimate_s}, {"database", database_s},
                                           {"registration", registration_s}, {"total", total_s}});
        write_atomically(dir / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << summary.dump(2) << "\n"; });
        write_html_report(dir, target);
        staging.commit();
        if (o->json) std::cout << summary.dump(2) << std::endl;
        else std::cout << text;
    });
}

} // namespace physreg::cli
