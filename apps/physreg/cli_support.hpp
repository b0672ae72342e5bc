// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Shared pieces of the physreg subcommands: JSON summaries, option checks, output paths.
#include <CLI/CLI.hpp>

#include "physreg/evaluation/tre.hpp"
#include <filesystem>
#include <functional>
#include <utility>
#include <vector>
#include <nlohmann/json.hpp>
#include <string>

#include "physreg/image/image_geometry.hpp"
#include "physreg/io/geometry_json.hpp"
#include "physreg/mesh/components.hpp"
#include "physreg/mesh/quality.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/model/tissue_table.hpp"

namespace physreg::cli {

/// One line of TRE figures for the log: all (mean ± sd, max), surface, internal (tumour, vessel), mm.
std::string tre_line(const TreReport& r);

struct CommonOptions {
    bool json = false; ///< print a JSON summary on stdout (logs stay on stderr)
};

void add_subcommand_mesh(CLI::App& app);
void add_subcommand_coarsen(CLI::App& app);
void add_subcommand_info(CLI::App& app);
void add_subcommand_landmarks(CLI::App& app);
void add_subcommand_convert(CLI::App& app);
void add_subcommand_demo(CLI::App& app);
void add_subcommand_simulate(CLI::App& app);
void add_subcommand_phantom(CLI::App& app);
void add_subcommand_estimate(CLI::App& app);
void add_subcommand_register_compression(CLI::App& app);
void add_subcommand_register_surface(CLI::App& app);
void add_subcommand_register_images(CLI::App& app);
void add_subcommand_evaluate(CLI::App& app);
void add_subcommand_enrich(CLI::App& app);
void add_subcommand_bench(CLI::App& app);
void add_subcommand_settings(CLI::App& app);
void add_subcommand_serve(CLI::App& app);
void add_subcommand_prepare(CLI::App& app);
void add_subcommand_replay(CLI::App& app);

using physreg::to_json; ///< ImageGeometry (io/geometry_json.hpp)
nlohmann::json to_json(const HexGrid& grid);
nlohmann::json to_json(const MeshQuality& quality);
nlohmann::json to_json(const ComponentReport& report);
nlohmann::json mesh_summary(const VolumeMesh& mesh, const TissueTable* tissues = nullptr);

/// Prints `summary` as JSON on stdout when --json was given, else a short human line on stderr.
void report(const CommonOptions& options, const nlohmann::json& summary);

/// The tissue table from --tissues, or paper 000's default (labels 1, 2, 3) with a log line.
TissueTable load_tissues(const std::string& path);

/// report.html in `folder` (`shown_as`: the final folder when `folder` is a staging one; it holds the command's summary.json), drawn by the Python package's
/// physreg.report with matplotlib. A missing Python or matplotlib, or a failing script, is a
/// warning naming the reason: the registration's own outputs are complete without it.
void write_html_report(const std::filesystem::path& folder, const std::filesystem::path& shown_as = {});
/// --no-report: commands skip report.html.
void set_html_reports(bool enabled);

/// Fails unless the output's directory exists (checked before any work is done).
void check_output_path(const std::filesystem::path& path, const std::string& option);
/// Fails when two outputs name the same file, or an output names one of the inputs: `outputs` and
/// `inputs` are (option, path) pairs; empty paths are skipped.
void check_distinct_paths(const std::vector<std::pair<std::string, std::string>>& outputs,
                          const std::vector<std::pair<std::string, std::string>>& inputs = {});

/// The separate output files of one command: if the command fails after writing some of them (a
/// later write fails, the disk fills, Ctrl-C), those already written are removed, so the outputs
/// appear all together or not at all.
class OutputFiles {
public:
    OutputFiles() = default;
    OutputFiles(const OutputFiles&) = delete;
    OutputFiles& operator=(const OutputFiles&) = delete;
    ~OutputFiles();
    /// Calls write(path) (itself atomic) and remembers `path`.
    void write(const std::filesystem::path& path, const std::function<void(const std::filesystem::path&)>& write);
    void commit() { m_written.clear(); } ///< all written: keep them
private:
    std::vector<std::filesystem::path> m_written;
};

} // namespace physreg::cli

namespace physreg {
struct SimulationCase;
struct SimulationResult;
namespace cli {
/// Writes frames, the ParaView collection, final.vtu, the dense displacement field and mask and
/// summary.json into the case's output directory (staged: nothing appears if a write fails).
nlohmann::json write_simulation_outputs(const SimulationCase& c, const SimulationResult& result);
} // namespace cli
} // namespace physreg
