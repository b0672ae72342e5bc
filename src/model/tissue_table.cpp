// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/model/tissue_table.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/config_keys.hpp"
#include "physreg/core/error.hpp"

#include <cmath>
#include <fstream>
#include <yaml-cpp/yaml.h>

namespace physreg {

const Tissue* TissueTable::find(std::int32_t label) const
{
    for (const auto& t : tissues)
        if (t.label == label) return &t;
    return nullptr;
}

void TissueTable::validate(const std::string& what) const
{
    if (tissues.empty()) fail("{}: the tissue table lists no tissues", what);
    std::set<std::int32_t> labels;
    std::set<std::string> names;
    for (const auto& t : tissues) {
        const std::string who = fmt::format("{}: tissue '{}' (label {})", what, t.name, t.label);
        if (t.label <= 0 || t.label > 65535) fail("{}: label must be in 1..65535 (0 is background)", who);
        if (t.name.empty()) fail("{}: tissue name is empty", who);
        if (!labels.insert(t.label).second) fail("{}: label {} appears twice", what, t.label);
        if (!names.insert(t.name).second) fail("{}: tissue name '{}' appears twice", what, t.name);
        if (!(std::isfinite(t.young_modulus_pa) && t.young_modulus_pa > 0))
            fail("{}: young_modulus_pa = {} Pa is impossible (must be finite and > 0)", who, t.young_modulus_pa);
        if (!(std::isfinite(t.poisson_ratio) && t.poisson_ratio > -1.0 && t.poisson_ratio < 0.5))
            fail("{}: poisson_ratio = {} is impossible (must lie in (-1, 0.5))", who, t.poisson_ratio);
        if (!(std::isfinite(t.density_kg_m3) && t.density_kg_m3 > 0))
            fail("{}: density_kg_m3 = {} is impossible (must be finite and > 0)", who, t.density_kg_m3);
        if (!(std::isfinite(t.mooney_rivlin_c01_fraction) && t.mooney_rivlin_c01_fraction >= 0.0 && t.mooney_rivlin_c01_fraction < 1.0))
            fail("{}: mooney_rivlin_c01_fraction = {} is impossible (must lie in [0, 1): C10 = (1 − fraction) μ/2 must stay > 0)", who,
                 t.mooney_rivlin_c01_fraction);
        if (ignored_labels.count(t.label)) fail("{}: label {} is both a tissue and ignored", what, t.label);
    }
}

TissueTable read_tissue_table(const std::filesystem::path& path)
{
    const std::string what = "tissue table '" + path.string() + "'";
    if (!std::filesystem::exists(path)) fail_missing_file("{}: file does not exist", what);
    YAML::Node root;
    try {
        root = YAML::LoadFile(path.string());
    } catch (const YAML::Exception& e) {
        fail("{}: not valid YAML/JSON: {}", what, e.what());
    }
    try {
        if (!root.IsMap() || !root["tissues"] || !root["tissues"].IsSequence())
            fail("{}: expected a map with a 'tissues' list", what);
        const auto keys_of = [&what](const YAML::Node& map) {
            std::vector<std::string> keys;
            for (const auto& entry : map) {
                // A list or map used as a key (`? [a, b]`) is valid YAML but never one of ours.
                if (!entry.first.IsScalar()) fail("{}: line {}: a key must be a plain name", what, entry.first.Mark().line + 1);
                keys.push_back(entry.first.Scalar());
            }
            return keys;
        };
        require_known_keys(keys_of(root), {"tissues", "ignore_labels"}, what, "the table");
        TissueTable table;
        std::size_t index = 0;
        for (const auto& node : root["tissues"]) {
            const std::string where = fmt::format("{}: tissues[{}]", what, index);
            if (!node.IsMap()) fail("{}: expected a map (label, name, young_modulus_pa, poisson_ratio, …)", where);
            auto number = [&](const char* key, std::optional<double> fallback) -> double {
                if (!node[key]) {
                    if (fallback) return *fallback;
                    fail("{}: missing '{}'", where, key);
                }
                try {
                    return node[key].as<double>();
                } catch (const YAML::Exception&) {
                    fail("{}: '{}' is not a number", where, key);
                }
            };
            Tissue t;
            try {
                t.label = node["label"].as<std::int32_t>();
                t.name = node["name"].as<std::string>();
            } catch (const YAML::Exception&) {
                fail("{}: needs an integer 'label' and a 'name'", where);
            }
            for (const char* legacy : {"E", "young_modulus", "nu", "density"})
                if (node[legacy])
                    fail("{}: key '{}' is ambiguous about units; use young_modulus_pa, poisson_ratio, density_kg_m3",
                         where, legacy);
            require_known_keys(keys_of(node), {"label", "name", "young_modulus_pa", "poisson_ratio", "density_kg_m3", "mooney_rivlin_c01_fraction"}, what,
                               fmt::format("tissues[{}]", index));
            ++index;
            t.young_modulus_pa = number("young_modulus_pa", std::nullopt);
            t.poisson_ratio = number("poisson_ratio", std::nullopt);
            t.density_kg_m3 = number("density_kg_m3", 1000.0);
            t.mooney_rivlin_c01_fraction = number("mooney_rivlin_c01_fraction", 0.0);
            table.tissues.push_back(t);
        }
        if (root["ignore_labels"] && !root["ignore_labels"].IsSequence()) fail("{}: 'ignore_labels' must be a list of integers", what);
        if (root["ignore_labels"]) {
            try {
                for (const auto& l : root["ignore_labels"]) table.ignored_labels.insert(l.as<std::int32_t>());
            } catch (const YAML::Exception&) {
                fail("{}: 'ignore_labels' must be a list of integers", what);
            }
        }
        table.validate(what);
        return table;
    } catch (const YAML::Exception& e) {
        // A structure the checks above did not foresee (e.g. a scalar where a list belongs).
        fail("{}: line {}: unexpected structure: {}", what, e.mark.line + 1, e.msg);
    }
}

void write_tissue_table(const std::filesystem::path& path, const TissueTable& table)
{
    table.validate("tissue table for '" + path.string() + "'");
    YAML::Emitter out;
    out << YAML::BeginMap << YAML::Key << "tissues" << YAML::Value << YAML::BeginSeq;
    for (const auto& t : table.tissues) {
        out << YAML::Flow << YAML::BeginMap << YAML::Key << "label" << YAML::Value << t.label << YAML::Key
            << "name" << YAML::Value << t.name << YAML::Key << "young_modulus_pa" << YAML::Value
            << t.young_modulus_pa << YAML::Key << "poisson_ratio" << YAML::Value << t.poisson_ratio << YAML::Key
            << "density_kg_m3" << YAML::Value << t.density_kg_m3;
        if (t.mooney_rivlin_c01_fraction != 0.0) out << YAML::Key << "mooney_rivlin_c01_fraction" << YAML::Value << t.mooney_rivlin_c01_fraction;
        out << YAML::EndMap;
    }
    out << YAML::EndSeq;
    if (!table.ignored_labels.empty()) {
        out << YAML::Key << "ignore_labels" << YAML::Value << YAML::Flow << YAML::BeginSeq;
        for (auto l : table.ignored_labels) out << l;
        out << YAML::EndSeq;
    }
    out << YAML::EndMap;
    write_atomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream f(tmp);
        f << "# physreg tissue table: young_modulus_pa [Pa], poisson_ratio [-], density_kg_m3 [kg/m^3]\n"
          << out.c_str() << "\n";
        if (!f) fail("tissue table '{}': write failed", path.string());
    });
}

TissueTable default_tissue_table()
{
    TissueTable t;
    t.tissues = {{1, "parenchyma", 2.0e5, 0.49, 1000.0},
                 {2, "vessel", 1.0e6, 0.49, 1000.0},
                 {3, "tumour", 5.0e6, 0.49, 1000.0}};
    return t;
}

} // namespace physreg
