// SPDX-License-Identifier: GPL-3.0-or-later
// physreg enrich build / apply: paper 000's coarse-to-fine scheme — the detail enrichment
// database (threads and MPI ranks), and coarse simulation + synthesis of the fine mesh.
#include "cli_support.hpp"
#include "progress.hpp"
#include "settings_options.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
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
        std::string dataset, parameters, output;
        bool replace = false, no_resume = false;
    };
    auto b = std::make_shared<BuildOptions>();
    auto* build = group->add_subcommand("build", "Build the database: deform the fine and the coarse model under positions × orientations × "
                                                 "depths (threads; MPI ranks under mpirun) and store eq. 9's weights");
    build->add_option("--dataset", b->dataset, "Phantom dataset (rest labels; tool shape and entry positions of its compressions)")->required();
    build->add_option("--parameters", b->parameters, "Parameter file from physreg estimate (else the model settings)");
    auto build_settings = std::make_shared<SettingsOptions<EnrichmentBuildSettings>>(build, enrichment_build_spec());
    build->add_option("-o,--output", b->output, "Database file (e.g. liver.phe)")->required();
    build->add_flag("--force", b->replace, "Replace an existing database");
    build->add_flag("--no-resume", b->no_resume, "Ignore checkpoints of an interrupted build (OUTPUT.partial/)");
    build->add_flag("--json", b->json, "Print a JSON summary on stdout");
    build->callback([b, build_settings] {
        MpiSession mpi;
        const bool root = mpi.rank() == 0;
        if (!root) logger()->set_level(spdlog::level::warn);
        if (fs::exists(b->output) && !b->replace) fail("--output '{}' exists; use --force to replace it", b->output);
        check_output_path(b->output, "--output");
        const auto t0 = std::chrono::steady_clock::now();
        const EnrichmentBuildSettings settings = build_settings->resolve();
        validate(settings, SettingNaming::option);
        const PhantomDataset dataset = read_phantom_dataset(b->dataset);
        const CompressionSubject subject = read_dataset_compression_subject(b->dataset, settings, b->parameters);
        const EnrichmentBuildPlan built = enrichment_build_plan(subject, dataset, settings);
        const EnrichmentPlan& plan = built.plan;
        std::vector<NodeEmbedding> embedding;
        const LiverModel coarse = coarsen_liver_model(subject.model, built.coarse_grid, &embedding);
        EnrichmentBuildOptions options;
        options.prediction = settings.prediction_options();
        options.checkpoint_directory = fs::path(b->output).string() + ".partial";
        if (b->no_resume && root && fs::exists(options.checkpoint_directory)) fs::remove_all(options.checkpoint_directory);
        options.rank = mpi.rank();
        options.ranks = mpi.size();
        const std::size_t total = plan.sequences() * plan.depths_mm.size();
        if (root)
            logger()->info("enrich build: {} positions × {} orientations × {} depths = {} conditions; fine {} nodes / {} hexahedra, coarse {} "
                           "nodes / {} hexahedra; {} process(es)",
                           plan.positions.size(), plan.orientations, plan.depths_mm.size(), total, subject.model.mesh.node_count(),
                           subject.model.mesh.cell_count(), coarse.mesh.node_count(), coarse.mesh.cell_count(), mpi.size());
        std::unique_ptr<ProgressDisplay> bar;
        if (root) {
            bar = std::make_unique<ProgressDisplay>("enrich build");
            options.progress = [&](double f, const std::string& m) { bar->update(f, m); };
        }
        EnrichmentDatabase mine;
        std::string failure;
        try {
            mine = build_enrichment_database(subject.model, coarse, embedding, built.shape, plan, options);
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
        std::vector<std::string> stored;
        for (const auto& position : plan.positions) stored.push_back(position.name);
        json summary = {{"database", b->output},
                        {"conditions", db.conditions.size()},
                        {"positions", stored},
                        {"orientations", plan.orientations},
                        {"depths_mm", plan.depths_mm},
                        {"fine_nodes", db.fine_nodes},
                        {"coarse_nodes", db.coarse_nodes},
                        {"coarse_hexahedra", coarse.mesh.cell_count()},
                        {"processes", mpi.size()},
                        {"seconds", seconds},
                        {"file_bytes", bytes},
                        {"bytes_per_condition", db.conditions.empty() ? 0.0 : double(bytes) / double(db.conditions.size())},
                        {"storage", "float32 eq. 9 weights (8 per fine node) + float32 coarse displacement per condition; no lossy reduction"},
                        {"settings", enrichment_build_spec().to_json(settings)}};
        logger()->info("enrich build: {} conditions in {:.1f} s; '{}' {:.1f} MB ({:.0f} kB per condition)", db.conditions.size(), seconds,
                       b->output, double(bytes) / 1e6, double(bytes) / 1e3 / double(std::max<std::size_t>(1, db.conditions.size())));
        if (b->json) std::cout << summary.dump(2) << std::endl;
    });

    struct ApplyOptions : CommonOptions {
        std::string database, dataset, state, parameters, output;
        bool replace = false;
    };
    auto a = std::make_shared<ApplyOptions>();
    auto* apply = group->add_subcommand("apply", "Predict a compression coarse-to-fine: simulate the coarse model, match stored conditions, "
                                                 "synthesise the fine mesh and the landmarks");
    apply->add_option("--database", a->database, "Database from physreg enrich build")->required();
    apply->add_option("--dataset", a->dataset, "Phantom dataset (rest labels and landmarks, the tool's path)")->required();
    apply->add_option("--state", a->state, "The compression to predict (e.g. D)")->required();
    apply->add_option("--parameters", a->parameters, "Parameter file the database was built with (else the model settings)");
    auto apply_settings = std::make_shared<SettingsOptions<EnrichmentApplySettings>>(apply, enrichment_apply_spec());
    apply->add_option("-o,--output", a->output, "Output directory (created)")->required();
    apply->add_flag("--force", a->replace, "Replace an existing output directory (only once the new one is complete)");
    apply->add_flag("--json", a->json, "Print a JSON summary on stdout");
    apply->callback([a, apply_settings] {
        const EnrichmentApplySettings settings = apply_settings->resolve();
        validate(settings, SettingNaming::option);
        const EnrichmentDatabase db = read_enrichment_database(a->database);
        const CompressionSubject subject = read_dataset_compression_subject(a->dataset, settings, a->parameters);
        const auto cases = compression_cases(read_phantom_dataset(a->dataset), {a->state});
        StagedDirectory staging(a->output, a->replace);
        CoarseToFineResult r = predict_compression_coarse_to_fine(subject, db, cases[0], settings, "--database '" + a->database + "'");
        r.summary["inputs"]["database"] = fs::absolute(a->database).string();
        if (!apply_settings->file().empty()) r.summary["settings_file"] = fs::absolute(apply_settings->file()).string();
        MeshData fine_data, coarse_data;
        fine_data.point_data.push_back({"displacement", 3, r.prediction.fine_u});
        coarse_data.point_data.push_back({"displacement", 3, r.prediction.coarse_u});
        write_vtu(staging.path() / "mesh.vtu", subject.model.mesh, fine_data);
        write_vtu(staging.path() / "coarse.vtu", r.coarse.mesh, coarse_data);
        write_landmarks(staging.path() / "landmarks.csv", r.prediction.landmarks);
        write_displacement_field(staging.path() / "displacement.nii.gz", r.field.field);
        write_atomically(staging.path() / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << r.summary.dump(2) << "\n"; });
        write_html_report(staging.path(), a->output);
        staging.commit();
        std::cerr << fmt::format("enrich apply {} (match {}, {} blended; coarse {:.3f} s, synthesis {:.3f} s): TRE {}\n", a->state, settings.match,
                                 r.blend_size, r.prediction.coarse_seconds, r.prediction.synthesis_seconds, tre_line(*r.tre));
        if (a->json) std::cout << r.summary.dump(2) << std::endl;
    });
}

} // namespace physreg::cli
