// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// An experiment dataset as `physreg phantom` writes it (a folder with manifest.json): its states,
// their files, the tools of the compressions and the label roles. The reader belongs here, with the
// other file formats, so that the registration commands read a dataset without depending on the
// generator that made it (phantom/dataset.hpp).
#include "physreg/core/types.hpp"
#include "physreg/model/label_roles.hpp"
#include "physreg/model/loads.hpp"

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace physreg {

/// The manifest's format version this physreg writes and reads (2: the body ground truth).
constexpr int phantom_dataset_format_version = 2;

/// What `physreg phantom` wrote: every path relative to the dataset folder.
struct DatasetState {
    std::string name;                              ///< "rest", "A"…"E", "insufflation", "push"
    std::string kind;                              ///< rest, compression, insufflation, push
    std::map<std::string, std::string> files;      ///< role → relative path (labels, intensity, …)
    std::map<int, std::pair<std::string, std::string>> surfaces; ///< percentage → (PLY, CSV)
    double max_displacement_mm = 0.0;
    double depth_mm = 0.0;                         ///< compressions
    /// Compressions: the tool, its path from first contact (load factor 0) to the final position (1).
    std::optional<Indenter> tool;
};

struct PhantomDataset {
    std::filesystem::path directory;
    std::string generator_version;
    std::uint64_t seed = 0;
    std::string preset;
    std::string ground_truth_element;              ///< e.g. "linear tetrahedra (CGAL Mesh_3), Mooney-Rivlin"
    LabelRoles roles;
    std::string tissues_file;                      ///< relative: the ground-truth model's tissue table
    /// The literature material set the truth's moduli were drawn around (paper000, healthy,
    /// cirrhotic): registrations start from it, never from the truth's values.
    std::string material_set = "paper000";
    std::vector<DatasetState> states;              ///< rest first
    const DatasetState& state(const std::string& name) const; ///< throws Error if absent
    std::filesystem::path path(const std::string& relative) const { return directory / relative; }
};

/// Reads DIR/manifest.json; throws Error naming the file and key for a missing or malformed
/// manifest, an unknown format version, or a listed file that does not exist.
PhantomDataset read_phantom_dataset(const std::filesystem::path& directory);

} // namespace physreg
