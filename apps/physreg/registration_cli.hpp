// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Options and helpers shared by the commands that build the liver model (estimate,
// register-compression, enrich).
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "physreg/evaluation/tre.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/registration/compression/enrichment.hpp"
#include "physreg/registration/compression/liver_model.hpp"

#include <optional>
#include <string>
#include <vector>

namespace physreg::cli {

/// "A,B,C" → {"A", "B", "C"}; Error naming `option` when empty.
std::vector<std::string> split_names(const std::string& text, const std::string& option);
/// --memory-limit: "auto" (0: 80 % of the physical memory) or a size in bytes with an optional
/// binary suffix K, M, G or T (e.g. 8G = 8 GiB); Error naming `option` otherwise.
std::size_t parse_memory_limit(const std::string& text, const std::string& option);

struct ModelOptions {
    std::string variant = "coupled", region = "body", grid;
    std::optional<double> k_tumour, k_vessel, support_radius, body_modulus;
    double tool_speed = PredictionOptions{}.tool_speed_per_cell;
    double tolerance_mm = PredictionOptions{}.equilibrium.displacement_tolerance_mm;
    double residual = PredictionOptions{}.equilibrium.residual_tolerance;
    std::string solver = "relaxation";
};
void add_model_options(CLI::App* sub, ModelOptions& m);
ModelParameters model_parameters(const ModelOptions& m, ModelParameters p);
PredictionOptions prediction_options(const ModelOptions& m);
nlohmann::json parameters_json(const ModelParameters& p);
std::string tre_line(const TreReport& r);

/// --blend: "auto" (leave-one-out best of 1…4 over the database; errors per size in `loo_mm`) or a
/// number ≥ 1; Error otherwise.
int blend_size(const std::string& text, const EnrichmentDatabase& db, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
               const LiverModel& fine, std::vector<double>* loo_mm = nullptr);
/// --detail-length: "auto" (leave-one-sequence-out best over the database, choose_detail_length;
/// errors per length in `loo_mm`), "inf" (paper 000: the stored detail at any distance) or a
/// number ≥ 0 mm; Error otherwise.
/// `rest_landmarks`: the targets whose neighbourhood (fine nodes within two cells) the error is
/// taken over; empty: every fine node.
double detail_length(const std::string& text, const EnrichmentDatabase& db, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                     const LiverModel& fine, EnrichmentMatching how, int k, const LandmarkSet& rest_landmarks,
                     std::vector<std::pair<double, double>>* loo_mm = nullptr);
/// A length for JSON: the number, or "inf".
nlohmann::json length_json(double length_mm);

/// The dataset's rest state and the model: from `parameters_file` (checked against the mesh it
/// builds: "fitted on another mesh") or from the model options.
struct LoadedModel {
    PhantomDataset dataset;
    LabelVolume labels;
    LandmarkSet rest_landmarks;
    LiverModel model;
};
LoadedModel load_model(const std::string& dataset, const std::string& parameters_file, const ModelOptions& options);

} // namespace physreg::cli
