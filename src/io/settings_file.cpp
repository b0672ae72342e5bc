// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/settings_file.hpp"

#include "physreg/core/error.hpp"

#include <yaml-cpp/yaml.h>

namespace physreg {
namespace {

/// YAML → JSON: a plain scalar that reads as true/false or a number becomes one (YAML 1.2's core
/// schema); a quoted scalar stays a string.
nlohmann::json to_json(const YAML::Node& node, const std::string& what)
{
    switch (node.Type()) {
    case YAML::NodeType::Null:
    case YAML::NodeType::Undefined: return nullptr;
    case YAML::NodeType::Sequence: {
        nlohmann::json out = nlohmann::json::array();
        for (const auto& item : node) out.push_back(to_json(item, what));
        return out;
    }
    case YAML::NodeType::Map: {
        nlohmann::json out = nlohmann::json::object();
        for (const auto& item : node) {
            if (!item.first.IsScalar()) fail("{}: a key that is not a name", what);
            out[item.first.Scalar()] = to_json(item.second, what);
        }
        return out;
    }
    case YAML::NodeType::Scalar: {
        const std::string& text = node.Scalar();
        if (node.Tag() == "!") return text; // quoted
        if (text == "true" || text == "True" || text == "TRUE") return true;
        if (text == "false" || text == "False" || text == "FALSE") return false;
        if (const auto number = parse_number(text); number && std::isfinite(*number)) {
            if (text.find_first_of(".eE") == std::string::npos && std::abs(*number) < 9e15) return static_cast<std::int64_t>(*number);
            return *number;
        }
        return text;
    }
    }
    return nullptr;
}

} // namespace

nlohmann::json read_settings_file(const std::filesystem::path& path)
{
    const std::string what = path.string();
    require_existing_file(path, what);
    YAML::Node root;
    try {
        root = YAML::LoadFile(path.string());
    } catch (const YAML::Exception& e) {
        fail("{}: not valid YAML/JSON: {}", what, e.what());
    }
    if (!root.IsMap()) fail("{}: expected a mapping of settings (key: value) at the top level", what);
    return to_json(root, what);
}

} // namespace physreg
