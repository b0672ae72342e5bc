// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/dataset.hpp"

#include "physreg/core/error.hpp"

#include <nlohmann/json.hpp>
#include <fstream>

namespace physreg {

namespace fs = std::filesystem;
using json = nlohmann::json;

const DatasetState& PhantomDataset::state(const std::string& name) const
{
    for (const auto& s : states)
        if (s.name == name) return s;
    fail("dataset '{}': no state '{}'", directory.string(), name);
}

PhantomDataset read_phantom_dataset(const fs::path& directory)
{
    const fs::path path = directory / "manifest.json";
    std::ifstream in(path);
    if (!in) fail("dataset '{}': no manifest.json (not a physreg phantom dataset?)", directory.string());
    json m;
    try {
        in >> m;
    } catch (const json::exception& e) {
        fail("dataset manifest '{}': not valid JSON: {}", path.string(), e.what());
    }
    PhantomDataset d;
    d.directory = directory;
    try {
        if (m.at("format").get<std::string>() != "physreg-phantom-dataset") fail("dataset manifest '{}': format is not physreg-phantom-dataset", path.string());
        const int version = m.at("format_version").get<int>();
        if (version != phantom_dataset_format_version) fail("dataset manifest '{}': format version {} (this physreg reads {})", path.string(), version, phantom_dataset_format_version);
        d.generator_version = m.at("generator").at("version").get<std::string>();
        d.seed = m.at("generator").at("seed").get<std::uint64_t>();
        d.preset = m.at("generator").at("preset").get<std::string>();
        d.ground_truth_element = m.at("ground_truth").at("element").get<std::string>();
        const auto& r = m.at("label_roles");
        d.roles.body = r.at("body").get<std::set<std::int32_t>>();
        d.roles.liver = r.at("liver").get<std::set<std::int32_t>>();
        d.roles.lesion = r.at("lesion").get<std::set<std::int32_t>>();
        d.roles.vessel = r.at("vessel").get<std::set<std::int32_t>>();
        d.roles.bone = r.at("bone").get<std::set<std::int32_t>>();
        d.roles.kidney = r.at("kidney").get<std::set<std::int32_t>>();
        d.tissues_file = m.at("tissues_file").get<std::string>();
        d.material_set = m.value("material_set", std::string("paper000"));
        for (const auto& s : m.at("states")) {
            DatasetState state;
            state.name = s.at("name").get<std::string>();
            state.kind = s.at("kind").get<std::string>();
            state.files = s.at("files").get<std::map<std::string, std::string>>();
            for (const auto& [percent, entry] : s.at("partial_surfaces").items()) {
                const auto number = parse_number(percent);
                if (!number) fail("dataset manifest '{}': state {}: partial surface key '{}' is not a percentage", path.string(), state.name, percent);
                state.surfaces[to_integer<int>(*number, "dataset manifest '" + path.string() + "'", "a partial surface's percentage")] = {
                    entry.at("ply").get<std::string>(), entry.at("csv").get<std::string>()};
            }
            state.max_displacement_mm = s.value("max_displacement_mm", 0.0);
            state.depth_mm = s.value("depth_mm", 0.0);
            if (s.contains("tool")) {
                const auto& t = s.at("tool");
                auto vec = [](const json& v) { return Vec3(v.at(0).get<double>(), v.at(1).get<double>(), v.at(2).get<double>()); };
                Indenter tool;
                tool.name = "tool_" + state.name;
                tool.shape = parse_indenter_shape(t.at("shape").get<std::string>());
                tool.radius_mm = t.at("radius_mm").get<double>();
                tool.axis = vec(t.at("axis"));
                tool.half_extents_mm = vec(t.at("half_extents_mm"));
                tool.path = {vec(t.at("contact_position_mm")), vec(t.at("final_position_mm"))};
                try {
                    tool.validate();
                } catch (const Error& e) {
                    fail("dataset manifest '{}': state {}: tool: {}", path.string(), state.name, e.what());
                }
                state.tool = tool;
            }
            d.states.push_back(state);
        }
    } catch (const json::exception& e) {
        fail("dataset manifest '{}': missing or malformed entry: {}", path.string(), e.what());
    }
    if (d.states.empty() || d.states.front().name != "rest") fail("dataset manifest '{}': the first state must be 'rest'", path.string());
    auto check = [&](const std::string& relative) {
        if (!fs::exists(directory / relative)) fail_missing_file("dataset '{}': listed file '{}' does not exist", directory.string(), relative);
    };
    check(d.tissues_file);
    for (const auto& s : d.states) {
        for (const auto& [role, file] : s.files) check(file);
        for (const auto& [percent, files] : s.surfaces) check(files.first), check(files.second);
    }
    return d;
}

} // namespace physreg
