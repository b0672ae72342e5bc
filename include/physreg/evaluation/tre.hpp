// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Target registration error: distances (mm) between predicted and ground-truth landmarks matched
// by name, summarised over all landmarks, surface ones and internal ones (tumour + vessel), and
// per type; CSV/JSON reports and a PNG chart.
#include "physreg/core/landmark.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace physreg {

struct TreEntry {
    std::string name;
    LandmarkType type = LandmarkType::unspecified;
    Vec3 truth = Vec3::Zero(), predicted = Vec3::Zero();
    double error_mm = 0.0;
};

struct TreStats {
    std::size_t count = 0;
    double mean_mm = 0.0, std_mm = 0.0, max_mm = 0.0; ///< std: population standard deviation
};
TreStats tre_stats(const std::vector<double>& errors_mm);

struct TreReport {
    std::vector<TreEntry> entries;
    TreStats all, surface, internal, tumour, vessel;
};

/// Every ground-truth landmark must have a prediction of the same name (Error naming the missing
/// ones and `what`); the truth's types are used. Non-finite positions are an Error.
TreReport compute_tre(const LandmarkSet& predicted, const LandmarkSet& truth, const std::string& what);
/// Pools several reports (e.g. the training compressions) into one.
TreReport pool_tre(const std::vector<TreReport>& reports);
/// The rigid baseline: the least-squares rigid motion (Umeyama, no scaling; Eigen::umeyama) taking
/// the `rest` landmarks of the given type to their `observed` positions (same names), applied to
/// every rest landmark. Throws Error naming `what` with fewer than 3 such landmarks or mismatched sets.
LandmarkSet rigid_landmark_registration(const LandmarkSet& rest, const LandmarkSet& observed, LandmarkType fitted_type, const std::string& what);

std::string tre_stats_json(const TreReport& report);               ///< {"all": {...}, "surface": …}
std::string tre_report_json(const TreReport& report);              ///< stats plus per-landmark rows
/// The registration summaries' TRE block: per group (all, surface, internal) count, mean, median,
/// max and std in mm (an empty group's median is null), and every landmark's error by name.
nlohmann::json tre_summary(const TreReport& report);
void write_tre_csv(const std::filesystem::path& path, const TreReport& report); ///< atomic

} // namespace physreg
