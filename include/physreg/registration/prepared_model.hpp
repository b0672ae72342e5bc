// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A body model prepared once for live use (physreg prepare, then physreg serve MODEL; issue 44):
// paper 000's model with its condensed contact precomputed, the organ surfaces a display shows,
// and paper 001's tetrahedral liver model for intra-operative clouds. Stored as a folder:
//   prepared.json        what it is, from what, the settings, the session's tool paths, timings
//   labels.nii.gz        the rest label volume; landmarks.csv the targets; parameters.json (if any)
//   condensed.bin        the compliance blocks (write_condensed_compliance)
//   surface_model.vtu    the liver's tetrahedra for clouds (its boundary is derived again)
//   body_model.vtu       the hexahedral body model with its tissues and held nodes (for viewing)
// Reading rebuilds the hexahedral model from the labels and settings (deterministic, seconds) and
// checks it against the stored fingerprint and stiffness probe; the Cholesky factor is not
// stored (hundreds of MB to GB) and is made only when something needs it.
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/compression/condensed_contact.hpp"
#include "physreg/registration/surface/surface_model.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace physreg {

/// An organ's surface as a display shows it: the faces of its cells that border other tissue or
/// nothing, over its own points (each a model node).
struct OrganSurface {
    std::string name;                                   ///< liver, tumours, vessels
    std::vector<std::int32_t> nodes;                    ///< model node per surface point
    std::vector<std::vector<std::uint32_t>> polygons;   ///< surface point indices
};
/// The liver (with its lesions and vessels), the tumours and the vessels, where the roles name them.
std::vector<OrganSurface> organ_surfaces(const LiverModel& model, const LabelRoles& roles);

struct PreparedModelOptions {
    CondensedContactOptions condensed;
    double surface_cell_size_mm = 7.0; ///< paper 001's liver model for clouds (largest circumradius); 0: none
    unsigned surface_seed = 1;
};

struct PreparedBodyModel {
    CompressionSubject subject;
    std::vector<Indenter> session_tools;          ///< the tool's shape and the paths the candidates lie near
    std::vector<OrganSurface> surfaces;
    std::unique_ptr<CondensedContactModel> condensed; // refers to subject.model: the struct is not moved
    std::optional<SurfaceModel> surface_model;    ///< paper 001's liver model for clouds
    nlohmann::json description = nlohmann::json::object(); ///< inputs, timings (s) of each stage
    PreparedBodyModel() = default;
    PreparedBodyModel(const PreparedBodyModel&) = delete;
    PreparedBodyModel& operator=(const PreparedBodyModel&) = delete;
};

/// Precomputes everything: the condensed contact for the session's tools (candidates near their
/// paths; query nodes: the organ surfaces and the nodes around the targets) and the liver model.
/// Throws Error as CondensedContactModel does, or for no tool.
std::unique_ptr<PreparedBodyModel> prepare_body_model(CompressionSubject subject, std::vector<Indenter> session_tools,
                                                      const PreparedModelOptions& options);
/// Writes the folder (staged, then renamed: no partial folder). An existing non-empty folder is
/// refused unless `replace`.
void write_prepared_model(const PreparedBodyModel& model, const std::filesystem::path& directory, bool replace);
/// Reads a folder written by write_prepared_model. Throws Error naming the file for a missing or
/// corrupt part, another format version, or a model that no longer matches its stored compliance.
std::unique_ptr<PreparedBodyModel> read_prepared_model(const std::filesystem::path& directory, const CondensedContactOptions& options = {});

/// A phantom dataset's tool compressions (the tool's shape and the session's paths); throws Error
/// naming `directory` when it has none.
std::vector<Indenter> dataset_session_tools(const std::filesystem::path& directory);

/// Whether `directory` holds a prepared model (its prepared.json).
bool is_prepared_model(const std::filesystem::path& directory);

} // namespace physreg
