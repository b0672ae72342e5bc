// SPDX-License-Identifier: GPL-3.0-or-later
#include "cli_support.hpp"

#include <sstream>

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/subprocess.hpp"

#include <cstdlib>
#include <optional>
#include <iostream>
#include <sys/wait.h>

namespace physreg::cli {

nlohmann::json to_json(const HexGrid& g)
{
    return {{"dims", {g.dims[0], g.dims[1], g.dims[2]}},
            {"cell_size_mm", {g.cell_size[0], g.cell_size[1], g.cell_size[2]}},
            {"origin_mm_lps", {g.origin[0], g.origin[1], g.origin[2]}}};
}

nlohmann::json to_json(const MeshQuality& q)
{
    return {{"volume_mm3", q.volume_mm3},
            {"min_cell_volume_mm3", q.min_cell_volume_mm3},
            {"max_cell_volume_mm3", q.max_cell_volume_mm3},
            {"min_scaled_jacobian", q.min_scaled_jacobian},
            {"mean_scaled_jacobian", q.mean_scaled_jacobian},
            {"max_edge_ratio", q.max_edge_ratio},
            {"min_edge_mm", q.min_edge_mm},
            {"max_edge_mm", q.max_edge_mm},
            {"inverted_cells", q.inverted_cells}};
}

nlohmann::json to_json(const ComponentReport& r)
{
    nlohmann::json pieces = nlohmann::json::array();
    for (const auto& p : r.pieces) pieces.push_back({{"cells", p.cells}, {"volume_mm3", p.volume_mm3}});
    return {{"pieces", pieces},
            {"nonmanifold_nodes_split", r.nonmanifold_nodes},
            {"dropped_cells", r.dropped_cells},
            {"dropped_volume_mm3", r.dropped_volume_mm3}};
}

nlohmann::json mesh_summary(const VolumeMesh& mesh, const TissueTable* tissues)
{
    nlohmann::json labels = nlohmann::json::array();
    std::map<std::int32_t, std::size_t> cells;
    for (auto l : mesh.cell_labels) ++cells[l];
    for (const auto& [label, volume] : volume_per_label(mesh)) {
        nlohmann::json entry = {{"label", label}, {"cells", cells[label]}, {"volume_mm3", volume}};
        if (tissues)
            if (const Tissue* t = tissues->find(label)) entry["tissue"] = t->name;
        labels.push_back(entry);
    }
    nlohmann::json out = {{"cell_type", to_string(mesh.cell_type)},
                          {"nodes", mesh.node_count()},
                          {"cells", mesh.cell_count()},
                          {"labels", labels},
                          {"quality", to_json(measure_quality(mesh))}};
    if (mesh.grid) out["grid"] = to_json(*mesh.grid);
    return out;
}

void report(const CommonOptions& options, const nlohmann::json& summary)
{
    if (options.json) std::cout << summary.dump(2) << std::endl;
}

TissueTable load_tissues(const std::string& path)
{
    if (!path.empty()) return read_tissue_table(path);
    logger()->info("no --tissues given: using paper 000's table (1 parenchyma 2e5 Pa, 2 vessel 1e6 Pa, "
                   "3 tumour 5e6 Pa; ν = 0.49)");
    return default_tissue_table();
}

void check_output_path(const std::filesystem::path& path, const std::string& option)
{
    const auto dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
    if (!std::filesystem::is_directory(dir))
        fail("{} '{}': directory '{}' does not exist", option, path.string(), dir.string());
}

void check_distinct_paths(const std::vector<std::pair<std::string, std::string>>& outputs,
                          const std::vector<std::pair<std::string, std::string>>& inputs)
{
    namespace fs = std::filesystem;
    const auto same = [](const std::string& a, const std::string& b) {
        return fs::weakly_canonical(fs::absolute(a)) == fs::weakly_canonical(fs::absolute(b));
    };
    for (std::size_t i = 0; i < outputs.size(); ++i) {
        if (outputs[i].second.empty()) continue;
        for (std::size_t j = i + 1; j < outputs.size(); ++j)
            if (!outputs[j].second.empty() && same(outputs[i].second, outputs[j].second))
                fail("{} and {} name the same file '{}': give each output its own path", outputs[i].first, outputs[j].first, outputs[i].second);
        for (const auto& [option, path] : inputs)
            if (!path.empty() && same(outputs[i].second, path))
                fail("{} '{}' is the same file as the input {}: it would be overwritten", outputs[i].first, outputs[i].second, option);
    }
}

OutputFiles::~OutputFiles()
{
    for (const auto& path : m_written) {
        std::error_code ignored;
        std::filesystem::remove(path, ignored);
    }
}

void OutputFiles::write(const std::filesystem::path& path, const std::function<void(const std::filesystem::path&)>& write)
{
    write(path);
    m_written.push_back(path);
}

std::string tre_line(const TreReport& r)
{
    return fmt::format("all {:.3f} ± {:.3f} (max {:.3f}) | surface {:.3f} | internal {:.3f} (tumour {:.3f}, vessel {:.3f}) mm", r.all.mean_mm,
                       r.all.std_mm, r.all.max_mm, r.surface.mean_mm, r.internal.mean_mm, r.tumour.mean_mm, r.vessel.mean_mm);
}

namespace {

bool g_reports = true;

std::string shell_quote(const std::string& text)
{
    std::string out = "'";
    for (char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
}

/// Where the Python package lives: $PHYSREG_PYTHONPATH (the package sets it when it runs a command
/// in-process), else next to the program — the build tree (bin/../python) or an install
/// (bin/../lib/python3/dist-packages).
std::optional<std::filesystem::path> python_package_root()
{
    namespace fs = std::filesystem;
    std::vector<fs::path> candidates;
    if (const char* env = std::getenv("PHYSREG_PYTHONPATH"); env && *env) candidates.emplace_back(env);
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) {
        candidates.push_back(exe.parent_path().parent_path() / "python");
        candidates.push_back(exe.parent_path().parent_path() / "lib" / "python3" / "dist-packages");
    }
    for (const auto& c : candidates)
        if (fs::exists(c / "physreg" / "report.py", ec)) return c;
    return std::nullopt;
}

} // namespace

void set_html_reports(bool enabled) { g_reports = enabled; }

void write_html_report(const std::filesystem::path& folder, const std::filesystem::path& shown_as)
{
    if (!g_reports) return;
    const auto root = python_package_root();
    if (!root) {
        logger()->warn("report.html not written: the physreg Python package (physreg/report.py) was not found next to the program "
                       "(build with -DPHYSREG_BUILD_PYTHON=ON, or set PHYSREG_PYTHONPATH); --no-report silences this");
        return;
    }
    const std::string python = std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
    const std::string command = "PYTHONPATH=" + shell_quote(root->string()) + " OMP_NUM_THREADS=1 " + python + " -m physreg.report " +
                                shell_quote(folder.string()) +
                                (shown_as.empty() ? std::string() : " --shown-as " + shell_quote(std::filesystem::absolute(shown_as).string())) + " >/dev/null";
    const int status = run_shell_command(command);
    if (status != 0) {
        const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        logger()->warn("report.html not written: '{} -m physreg.report' failed (exit status {}; its message is above; is python3-matplotlib "
                       "installed?); the other outputs are complete", python, code);
    }
}

} // namespace physreg::cli
