#include "cli_support.hpp"

#include <sstream>

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"

#include <iostream>

namespace physreg::cli {

nlohmann::json to_json(const ImageGeometry& g)
{
    nlohmann::json direction = nlohmann::json::array();
    for (int r = 0; r < 3; ++r) direction.push_back({g.direction(r, 0), g.direction(r, 1), g.direction(r, 2)});
    return {{"size", {g.size[0], g.size[1], g.size[2]}},
            {"spacing_mm", {g.spacing[0], g.spacing[1], g.spacing[2]}},
            {"origin_mm_lps", {g.origin[0], g.origin[1], g.origin[2]}},
            {"direction", direction}};
}

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

std::vector<double> parse_number_list(const std::string& text, const std::string& option)
{
    std::stringstream in(text);
    std::string item;
    std::vector<double> v;
    while (std::getline(in, item, ',')) {
        try {
            std::size_t used = 0;
            v.push_back(std::stod(item, &used));
            if (used != item.size()) throw std::invalid_argument(item);
        } catch (const std::logic_error&) {
            fail("{}: '{}' is not a number", option, item);
        }
    }
    if (v.empty()) fail("{}: empty list", option);
    return v;
}

} // namespace physreg::cli
