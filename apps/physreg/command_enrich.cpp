// SPDX-License-Identifier: GPL-3.0-or-later
// physreg enrich build / apply: paper 000's coarse-to-fine scheme — the detail enrichment
// database (threads and MPI ranks), and coarse simulation + synthesis of the fine mesh.
#include "cli_support.hpp"
#include "progress.hpp"
#include "registration_cli.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/registration/compression/enrichment.hpp"
#include "physreg/registration/compression/estimation.hpp"

#include <mpi.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>

namespace physreg::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// MPI only when launched by mpirun (OpenMPI or PMI environment); a plain run stays one process.
class MpiSession {
public:
    MpiSession()
    {
        if (!std::getenv("OMPI_COMM_WORLD_SIZE") && !std::getenv("PMI_SIZE")) return;
        int provided = 0, initialised = 0;
        MPI_Initialized(&initialised);
        if (initialised) fail("MPI was started before the enrichment session");
        MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
        m_active = true;
        MPI_Comm_rank(MPI_COMM_WORLD, &m_rank);
        MPI_Comm_size(MPI_COMM_WORLD, &m_size);
    }
    ~MpiSession()
    {
        if (m_active) MPI_Finalize();
    }
    int rank() const { return m_rank; }
    int size() const { return m_size; }
    /// True on every rank when any rank reports failure.
    bool any(bool mine) const
    {
        if (!m_active) return mine;
        int local = mine ? 1 : 0, global = 0;
        MPI_Allreduce(&local, &global, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
        return global != 0;
    }
    void send(const std::string& bytes, int to) const
    {
        const std::uint64_t n = bytes.size();
        MPI_Send(&n, 1, MPI_UINT64_T, to, 1, MPI_COMM_WORLD);
        for (std::uint64_t at = 0; at < n; at += chunk)
            MPI_Send(bytes.data() + at, static_cast<int>(std::min<std::uint64_t>(chunk, n - at)), MPI_BYTE, to, 2, MPI_COMM_WORLD);
    }
    std::string receive(int from) const
    {
        std::uint64_t n = 0;
        MPI_Recv(&n, 1, MPI_UINT64_T, from, 1, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        std::string bytes(n, '\0');
        for (std::uint64_t at = 0; at < n; at += chunk)
            MPI_Recv(bytes.data() + at, static_cast<int>(std::min<std::uint64_t>(chunk, n - at)), MPI_BYTE, from, 2, MPI_COMM_WORLD,
                     MPI_STATUS_IGNORE);
        return bytes;
    }

private:
    static constexpr std::uint64_t chunk = 1u << 30;
    bool m_active = false;
    int m_rank = 0, m_size = 1;
};

} // namespace

void add_subcommand_enrich(CLI::App& app)
{
    auto* group = app.add_subcommand("enrich", "Coarse-to-fine scheme with a detail enrichment database (paper 000 eqs. 9–10)");
    group->require_subcommand(1);

    struct BuildOptions : CommonOptions {
        std::string dataset, parameters, output, positions, positions_grid, depths, coarse_grid = "24x18x18";
        ModelOptions model;
        int depth_count = 0, orientations = 1;
        double max_depth = 0.0, tilt = 15.0;
        bool replace = false, no_resume = false;
    };
    auto b = std::make_shared<BuildOptions>();
    auto* build = group->add_subcommand("build", "Build the database: deform the fine and the coarse model under positions × orientations × "
                                                 "depths (threads; MPI ranks under mpirun) and store eq. 9's weights");
    build->add_option("--dataset", b->dataset, "Phantom dataset (rest labels; tool shape and entry positions of its compressions)")->required();
    build->add_option("--parameters", b->parameters, "Parameter file from physreg estimate (else the model options)");
    add_model_options(build, b->model);
    build->add_option("--coarse-grid", b->coarse_grid, "Coarse model cells over the liver (default 24x18x18, paper 000)");
    build->add_option("--positions", b->positions, "Compressions of the dataset whose entry points are used (default: all)");
    build->add_option("--positions-grid", b->positions_grid, "Instead: CxR tool positions on a grid over the skin above the liver (central "
                                                             "70 %), each where the dataset's tool (a sphere) first touches the body");
    build->add_option("--depths", b->depths, "Tool depths beyond first contact, mm, increasing (default: 2 mm steps to the deepest compression)");
    build->add_option("--depth-count", b->depth_count, "Instead of --depths: this many depths evenly up to --max-depth");
    build->add_option("--max-depth", b->max_depth, "With --depth-count: the deepest, mm");
    build->add_option("--orientations", b->orientations, "Pressing directions per position: the nominal one and N−1 tilted ones (default 1)");
    build->add_option("--tilt", b->tilt, "Tilt of the other directions, degrees (default 15)");
    build->add_option("-o,--output", b->output, "Database file (e.g. liver.phe)")->required();
    build->add_flag("--force", b->replace, "Replace an existing database");
    build->add_flag("--no-resume", b->no_resume, "Ignore checkpoints of an interrupted build (OUTPUT.partial/)");
    build->add_flag("--json", b->json, "Print a JSON summary on stdout");
    build->callback([b] {
        MpiSession mpi;
        const bool root = mpi.rank() == 0;
        if (!root) logger()->set_level(spdlog::level::warn);
        if (fs::exists(b->output) && !b->replace) fail("--output '{}' exists; use --force to replace it", b->output);
        check_output_path(b->output, "--output");
        const auto t0 = std::chrono::steady_clock::now();
        const LoadedModel loaded = load_model(b->dataset, b->parameters, b->model);
        std::vector<NodeEmbedding> embedding;
        const LiverModel coarse = coarsen_liver_model(loaded.model, parse_grid_dims(b->coarse_grid, "--coarse-grid"), &embedding);
        // Plan: entry points and tool of the dataset's compressions.
        std::vector<std::string> names;
        if (!b->positions.empty()) names = split_names(b->positions, "--positions");
        else
            for (const auto& s : loaded.dataset.states)
                if (s.tool && s.kind == "compression") names.push_back(s.name); // not the organs-only push
        if (names.empty()) fail("dataset '{}' has no tool compression to take positions from", b->dataset);
        EnrichmentPlan plan;
        double deepest = 0.0;
        for (const auto& name : names) {
            const auto& state = loaded.dataset.state(name);
            if (!state.tool) fail("--positions: state '{}' is not a tool compression", name);
            plan.positions.push_back({name, state.tool->path.front()});
            plan.direction = (state.tool->path.back() - state.tool->path.front()).normalized();
            deepest = std::max(deepest, state.depth_mm);
        }
        const Indenter shape = *loaded.dataset.state(names.front()).tool;
        if (!b->positions_grid.empty()) {
            if (!b->positions.empty()) fail("--positions and --positions-grid exclude each other");
            const auto x = b->positions_grid.find('x');
            const auto columns = x == std::string::npos ? std::nullopt : parse_number(b->positions_grid.substr(0, x));
            const auto rows = x == std::string::npos ? std::nullopt : parse_number(b->positions_grid.substr(x + 1));
            if (!columns || !rows) fail("--positions-grid: '{}' is not CxR (e.g. 3x2)", b->positions_grid);
            plan.positions = skin_grid_positions(loaded.labels, loaded.dataset.roles, shape, plan.direction,
                                                 to_integer<int>(*columns, "--positions-grid", "columns"), to_integer<int>(*rows, "--positions-grid", "rows"));
        }
        if (!b->depths.empty()) {
            plan.depths_mm = parse_number_list(b->depths, "--depths");
        } else if (b->depth_count > 0) {
            if (!(b->max_depth > 0)) fail("--depth-count needs --max-depth > 0 mm");
            for (int i = 1; i <= b->depth_count; ++i) plan.depths_mm.push_back(b->max_depth * i / b->depth_count);
        } else {
            for (double d = 2.0; d <= deepest + 1e-9; d += 2.0) plan.depths_mm.push_back(d);
        }
        plan.orientations = b->orientations;
        plan.tilt_deg = b->tilt;
        plan.validate();
        EnrichmentBuildOptions options;
        options.prediction = prediction_options(b->model);
        options.checkpoint_directory = fs::path(b->output).string() + ".partial";
        if (b->no_resume && root && fs::exists(options.checkpoint_directory)) fs::remove_all(options.checkpoint_directory);
        options.rank = mpi.rank();
        options.ranks = mpi.size();
        const std::size_t total = plan.sequences() * plan.depths_mm.size();
        if (root)
            logger()->info("enrich build: {} positions × {} orientations × {} depths = {} conditions; fine {} nodes / {} hexahedra, coarse {} "
                           "nodes / {} hexahedra; {} process(es)",
                           plan.positions.size(), plan.orientations, plan.depths_mm.size(), total, loaded.model.mesh.node_count(),
                           loaded.model.mesh.cell_count(), coarse.mesh.node_count(), coarse.mesh.cell_count(), mpi.size());
        std::unique_ptr<ProgressDisplay> bar;
        if (root) {
            bar = std::make_unique<ProgressDisplay>("enrich build");
            options.progress = [&](double f, const std::string& m) { bar->update(f, m); };
        }
        EnrichmentDatabase mine;
        std::string failure;
        try {
            mine = build_enrichment_database(loaded.model, coarse, embedding, shape, plan, options);
        } catch (const std::exception& e) {
            failure = e.what();
        }
        if (mpi.any(!failure.empty())) {
            if (!failure.empty()) fail("{}", failure);
            fail("enrich build: another MPI rank failed (see its message)");
        }
        EnrichmentDatabase db;
        if (mpi.size() > 1) {
            if (!root) {
                mpi.send(serialize_enrichment_database(mine), 0);
                return;
            }
            std::vector<EnrichmentDatabase> parts{std::move(mine)};
            for (int r = 1; r < mpi.size(); ++r) parts.push_back(deserialize_enrichment_database(mpi.receive(r), fmt::format("part from rank {}", r)));
            db = merge_enrichment_parts(parts, plan);
        } else {
            db = std::move(mine);
        }
        if (bar) bar->finish();
        write_enrichment_database(b->output, db);
        fs::remove_all(options.checkpoint_directory);
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        const auto bytes = fs::file_size(b->output);
        json summary = {{"database", b->output},
                        {"conditions", db.conditions.size()},
                        {"positions", [&] {
                             std::vector<std::string> stored;
                             for (const auto& position : plan.positions) stored.push_back(position.name);
                             return stored;
                         }()},
                        {"orientations", plan.orientations},
                        {"depths_mm", plan.depths_mm},
                        {"fine_nodes", db.fine_nodes},
                        {"coarse_nodes", db.coarse_nodes},
                        {"coarse_hexahedra", coarse.mesh.cell_count()},
                        {"processes", mpi.size()},
                        {"seconds", seconds},
                        {"file_bytes", bytes},
                        {"bytes_per_condition", db.conditions.empty() ? 0.0 : double(bytes) / double(db.conditions.size())},
                        {"storage", "float32 eq. 9 weights (8 per fine node) + float32 coarse displacement per condition; no lossy reduction"}};
        logger()->info("enrich build: {} conditions in {:.1f} s; '{}' {:.1f} MB ({:.0f} kB per condition)", db.conditions.size(), seconds,
                       b->output, double(bytes) / 1e6, double(bytes) / 1e3 / double(std::max<std::size_t>(1, db.conditions.size())));
        if (b->json) std::cout << summary.dump(2) << std::endl;
    });

    struct ApplyOptions : CommonOptions {
        std::string database, dataset, state, parameters, output, match = "parameters", blend = "auto", detail = "inf";
        ModelOptions model;
        double field_spacing = 1.0;
        bool replace = false;
    };
    auto a = std::make_shared<ApplyOptions>();
    auto* apply = group->add_subcommand("apply", "Predict a compression coarse-to-fine: simulate the coarse model, match stored conditions, "
                                                 "synthesise the fine mesh and the landmarks");
    apply->add_option("--database", a->database, "Database from physreg enrich build")->required();
    apply->add_option("--dataset", a->dataset, "Phantom dataset (rest labels and landmarks, the tool's path)")->required();
    apply->add_option("--state", a->state, "The compression to predict (e.g. D)")->required();
    apply->add_option("--parameters", a->parameters, "Parameter file the database was built with (else the model options)");
    add_model_options(apply, a->model);
    apply->add_option("--match", a->match, "parameters (tool position, direction, depth; paper 000) or field (coarse displacement similarity)");
    apply->add_option("--blend", a->blend, "Conditions blended: auto (leave-one-out best of 1…4) or a number");
    apply->add_option("--detail-length", a->detail, "Share of the stored detail against the distance d to the nearest stored condition, 1/(1+(d/L)²), the rest the coarse field: inf (paper 000: all detail at any distance; default), L in mm, or auto (the leave-one-position-out best around the rest landmarks; measured unreliable, docs/enrichment.md)");
    apply->add_option("--field-spacing", a->field_spacing, "Voxel size of the displacement field, mm (default 1)");
    apply->add_option("-o,--output", a->output, "Output directory (created)")->required();
    apply->add_flag("--force", a->replace, "Replace an existing output directory (only once the new one is complete)");
    apply->add_flag("--json", a->json, "Print a JSON summary on stdout");
    apply->callback([a] {
        const EnrichmentMatching how = parse_enrichment_matching(a->match);
        if (!(a->field_spacing > 0)) fail("--field-spacing must be > 0 mm (got {})", a->field_spacing);
        const EnrichmentDatabase db = read_enrichment_database(a->database);
        const LoadedModel loaded = load_model(a->dataset, a->parameters, a->model);
        std::vector<NodeEmbedding> embedding;
        const LiverModel coarse = coarsen_liver_model(loaded.model, db.coarse_grid(), &embedding);
        check_database_fits(db, loaded.model, coarse, "--database '" + a->database + "'");
        const auto cases = compression_cases(loaded.dataset, {a->state});
        std::vector<double> loo;
        const int k = blend_size(a->blend, db, coarse, embedding, loaded.model, &loo);
        std::vector<std::pair<double, double>> detail_loo;
        const double detail = detail_length(a->detail, db, coarse, embedding, loaded.model, how, k, loaded.rest_landmarks, &detail_loo);
        StagedDirectory staging(a->output, a->replace);
        const auto prediction = predict_coarse_to_fine(loaded.model, coarse, embedding, db, cases[0].tool, loaded.rest_landmarks, how,
                                                       EnrichmentBlend(k, detail), prediction_options(a->model), "compression " + a->state);
        if (prediction.match.outside_range)
            logger()->warn("compression {} lies outside the database's range: {}; the result is extrapolated from the nearest stored "
                           "conditions", a->state, prediction.match.range_note);
        MeshData fine_data, coarse_data;
        fine_data.point_data.push_back({"displacement", 3, prediction.fine_u});
        coarse_data.point_data.push_back({"displacement", 3, prediction.coarse_u});
        write_vtu(staging.path() / "mesh.vtu", loaded.model.mesh, fine_data);
        write_vtu(staging.path() / "coarse.vtu", coarse.mesh, coarse_data);
        write_landmarks(staging.path() / "landmarks.csv", prediction.landmarks);
        const ImageGeometry geometry = image_grid_over_mesh(loaded.model.mesh, a->field_spacing, 2.0 * loaded.model.cell_size_mm.maxCoeff());
        write_displacement_field(staging.path() / "displacement.nii.gz", sample_displacement_field(loaded.model.mesh, prediction.fine_u, geometry).field);
        const TreReport tre = compute_tre(prediction.landmarks, cases[0].truth, "compression " + a->state);
        json matched = json::array();
        for (std::size_t i = 0; i < prediction.match.conditions.size(); ++i) {
            const auto& c = db.conditions[prediction.match.conditions[i]];
            matched.push_back({{"condition", prediction.match.conditions[i]}, {"position", c.position}, {"depth_mm", c.depth_mm},
                               {"distance", prediction.match.distances[i]}, {"blend", prediction.match.blend[i]}});
        }
        json summary = {{"state", a->state},
                        {"match", a->match},
                        {"blend_size", k},
                        {"leave_one_out_error_mm_per_blend_size", loo},
                        {"detail_length_mm", length_json(detail)},
                        {"detail_share", prediction.match.detail},
                        {"leave_one_position_out_error_mm_per_detail_length", [&] {
                             json rows = json::array();
                             for (const auto& [length, error] : detail_loo) rows.push_back({{"detail_length_mm", length_json(length)}, {"error_mm", error}});
                             return rows;
                         }()},
                        {"nearest_stored_position_mm", prediction.match.nearest_position_mm},
                        {"matched", matched},
                        {"outside_range", prediction.match.outside_range},
                        {"range_note", prediction.match.range_note},
                        {"coarse_iterations", prediction.iterations},
                        {"coarse_seconds", prediction.coarse_seconds},
                        {"synthesis_seconds", prediction.synthesis_seconds},
                        {"tre_against_dataset", json::parse(tre_stats_json(tre))},
                        {"files", {{"mesh", "mesh.vtu"}, {"coarse", "coarse.vtu"}, {"landmarks", "landmarks.csv"}, {"displacement", "displacement.nii.gz"}}}};
        summary["command"] = "enrich apply";
        summary["inputs"] = {{"database", fs::absolute(a->database).string()}, {"dataset", fs::absolute(a->dataset).string()}, {"state", a->state}};
        write_atomically(staging.path() / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << summary.dump(2) << "\n"; });
        write_html_report(staging.path(), a->output);
        staging.commit();
        std::cerr << fmt::format("enrich apply {} (match {}, {} blended; coarse {:.3f} s, synthesis {:.3f} s): TRE {}\n", a->state, a->match, k,
                                 prediction.coarse_seconds, prediction.synthesis_seconds, tre_line(tre));
        if (a->json) std::cout << summary.dump(2) << std::endl;
    });
}

} // namespace physreg::cli
