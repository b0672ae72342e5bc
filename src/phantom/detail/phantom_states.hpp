// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The phantom's states, solved by the ground truth (ground_truth.hpp): the prepared label map, the
// ground-truth models and materials drawn from the seed, and the solves of each compression (with
// the tool enlarged when it would slip between the surface nodes) and of the insufflation.
#include "physreg/phantom/dataset.hpp"
#include "physreg/phantom/ground_truth.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace physreg::detail {

/// A seed of its own for each random draw named `what` (materials, noise of one state, …).
std::uint64_t mix_seed(std::uint64_t seed, const std::string& what);

struct Prepared {
    LabelVolume labels;
    LabelRoles roles;
    std::string source;
};

/// The label map (a preset, or a file with its vessel mask painted in), checked to have a liver.
Prepared prepare_labels(const PhantomSpec& spec);

// The ground truth: materials drawn from the seed, the body model for the compressions, the organs
// alone for the insufflation (ground_truth.hpp).
struct GroundTruth {
    TissueTable tissues;
    nlohmann::json material_ranges;
    GroundTruthModel body;
    std::optional<GroundTruthModel> organs; ///< absent when the body model is the organs already
    const GroundTruthModel& insufflation_model() const { return organs ? *organs : body; }
};
GroundTruth build_ground_truth(const Prepared& p, const PhantomSpec& spec);

/// The liver's centroid, and its bounding box in lo, hi (mm, LPS).
Vec3 liver_centroid(const Prepared& p, Vec3& lo, Vec3& hi);

struct SolvedState {
    std::vector<double> u;
    GroundTruthSolve solve;
    std::optional<Indenter> tool;
    CompressionSpec compression;
    double pressure_pa = 0.0;
    double requested_tool_scale = 1.0; ///< the tool actually used ÷ the one asked for (> 1: adapted)
    std::string adaptation;            ///< why the tool was enlarged, or ""
};

/// A compression solved on model m; a tool that slips between the surface nodes is enlarged and
/// the solve retried (the adaptation is reported in the state).
SolvedState solve_compression(const GroundTruthModel& m, const PhantomSpec& spec, const Prepared& p, const CompressionSpec& c);
/// The insufflation: a pressure on the organs' anterior faces, solved on the organs alone.
SolvedState solve_insufflation(const GroundTruth& gt, double pressure_pa);

} // namespace physreg::detail
