// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A settings file (--settings FILE): a JSON or YAML mapping of setting keys to values, read as JSON
// so that a mode's SettingsSpec checks it (unknown keys, types, ranges).
#include <nlohmann/json.hpp>

#include <filesystem>

namespace physreg {

/// The file's top-level mapping. Throws MissingFileError for a missing file, Error naming the file
/// for one that is not valid YAML/JSON or whose top level is not a mapping.
nlohmann::json read_settings_file(const std::filesystem::path& path);

} // namespace physreg
