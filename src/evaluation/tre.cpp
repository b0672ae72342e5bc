// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/evaluation/tre.hpp"

#include <Eigen/Geometry>

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>

namespace physreg {
namespace {
using json = nlohmann::json;

bool is_internal(LandmarkType t) { return t == LandmarkType::tumour || t == LandmarkType::vessel; }

json stats_json(const TreStats& s) { return {{"count", s.count}, {"mean_mm", s.mean_mm}, {"std_mm", s.std_mm}, {"max_mm", s.max_mm}}; }

json report_stats(const TreReport& r)
{
    return {{"all", stats_json(r.all)},       {"surface", stats_json(r.surface)}, {"internal", stats_json(r.internal)},
            {"tumour", stats_json(r.tumour)}, {"vessel", stats_json(r.vessel)}};
}

void summarise(TreReport& r)
{
    std::vector<double> all, surface, internal, tumour, vessel;
    for (const auto& e : r.entries) {
        all.push_back(e.error_mm);
        if (e.type == LandmarkType::surface) surface.push_back(e.error_mm);
        if (is_internal(e.type)) internal.push_back(e.error_mm);
        if (e.type == LandmarkType::tumour) tumour.push_back(e.error_mm);
        if (e.type == LandmarkType::vessel) vessel.push_back(e.error_mm);
    }
    r.all = tre_stats(all);
    r.surface = tre_stats(surface);
    r.internal = tre_stats(internal);
    r.tumour = tre_stats(tumour);
    r.vessel = tre_stats(vessel);
}

} // namespace

TreStats tre_stats(const std::vector<double>& errors)
{
    TreStats s;
    s.count = errors.size();
    if (errors.empty()) return s;
    double sum = 0.0;
    for (const double e : errors) sum += e, s.max_mm = std::max(s.max_mm, e);
    s.mean_mm = sum / double(errors.size());
    double var = 0.0;
    for (const double e : errors) var += (e - s.mean_mm) * (e - s.mean_mm);
    s.std_mm = std::sqrt(var / double(errors.size()));
    return s;
}

TreReport compute_tre(const LandmarkSet& predicted, const LandmarkSet& truth, const std::string& what)
{
    if (truth.empty()) fail("{}: no ground-truth landmarks", what);
    std::map<std::string, const Landmark*> by_name;
    for (const auto& p : predicted) by_name[p.name] = &p;
    std::vector<std::string> missing;
    TreReport r;
    for (const auto& t : truth) {
        const auto it = by_name.find(t.name);
        if (it == by_name.end()) {
            missing.push_back(t.name);
            continue;
        }
        if (!t.position.allFinite() || !it->second->position.allFinite()) fail("{}: landmark '{}' has a non-finite position", what, t.name);
        r.entries.push_back({t.name, t.type, t.position, it->second->position, (it->second->position - t.position).norm()});
    }
    if (!missing.empty()) fail("{}: {} ground-truth landmark(s) have no prediction: {}", what, missing.size(), fmt::join(missing, ", "));
    summarise(r);
    return r;
}

TreReport pool_tre(const std::vector<TreReport>& reports)
{
    TreReport r;
    for (const auto& q : reports) r.entries.insert(r.entries.end(), q.entries.begin(), q.entries.end());
    summarise(r);
    return r;
}

std::string tre_stats_json(const TreReport& report) { return report_stats(report).dump(); }

json tre_summary(const TreReport& report)
{
    // The median over exactly the landmarks the group's statistics count (compute_tre's grouping:
    // internal = tumour and vessel; untyped landmarks count in "all" only). An empty group has no
    // median: null, never a number copied from another group.
    const auto group = [&](const TreStats& s, bool (*member)(LandmarkType)) {
        std::vector<double> e;
        for (const auto& entry : report.entries)
            if (member(entry.type)) e.push_back(entry.error_mm);
        if (e.size() != s.count) fail("TRE summary: {} landmarks in a group whose statistics count {}", e.size(), s.count);
        std::sort(e.begin(), e.end());
        json median = nullptr;
        if (!e.empty()) median = e.size() % 2 ? e[e.size() / 2] : 0.5 * (e[e.size() / 2 - 1] + e[e.size() / 2]);
        return json{{"count", s.count}, {"mean_mm", s.mean_mm}, {"median_mm", median}, {"max_mm", s.max_mm}, {"std_mm", s.std_mm}};
    };
    json per = json::object();
    for (const auto& e : report.entries) per[e.name] = e.error_mm;
    return {{"all", group(report.all, [](LandmarkType) { return true; })},
            {"surface", group(report.surface, [](LandmarkType t) { return t == LandmarkType::surface; })},
            {"internal", group(report.internal, [](LandmarkType t) { return is_internal(t); })},
            {"per_landmark_mm", per}};
}

std::string tre_report_json(const TreReport& report)
{
    json j = report_stats(report);
    j["units"] = "mm";
    json rows = json::array();
    for (const auto& e : report.entries)
        rows.push_back({{"name", e.name},
                        {"type", to_string(e.type)},
                        {"truth_mm", {e.truth.x(), e.truth.y(), e.truth.z()}},
                        {"predicted_mm", {e.predicted.x(), e.predicted.y(), e.predicted.z()}},
                        {"error_mm", e.error_mm}});
    j["landmarks"] = rows;
    return j.dump(2);
}

void write_tre_csv(const std::filesystem::path& path, const TreReport& report)
{
    write_atomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp);
        out << "name,type,truth_x_mm,truth_y_mm,truth_z_mm,predicted_x_mm,predicted_y_mm,predicted_z_mm,error_mm\n";
        for (const auto& e : report.entries)
            out << fmt::format("{},{},{:.6f},{:.6f},{:.6f},{:.6f},{:.6f},{:.6f},{:.6f}\n", e.name, to_string(e.type), e.truth.x(), e.truth.y(),
                               e.truth.z(), e.predicted.x(), e.predicted.y(), e.predicted.z(), e.error_mm);
        if (!out) fail("cannot write TRE table '{}'", path.string());
    });
}

LandmarkSet rigid_landmark_registration(const LandmarkSet& rest, const LandmarkSet& observed, LandmarkType fitted_type, const std::string& what)
{
    if (rest.size() != observed.size()) fail("{}: {} rest landmarks but {} observed", what, rest.size(), observed.size());
    std::vector<std::size_t> used;
    for (std::size_t l = 0; l < rest.size(); ++l) {
        if (rest[l].name != observed[l].name) fail("{}: landmark {} is '{}' at rest but '{}' observed", what, l, rest[l].name, observed[l].name);
        if (!observed[l].position.allFinite()) fail("{}: landmark '{}' is not finite", what, observed[l].name);
        if (rest[l].type == fitted_type) used.push_back(l);
    }
    if (used.size() < 3) fail("{}: {} landmarks to fit a rigid motion to (at least 3 needed)", what, used.size());
    Eigen::Matrix3Xd from(3, static_cast<Eigen::Index>(used.size())), to(3, static_cast<Eigen::Index>(used.size()));
    for (std::size_t k = 0; k < used.size(); ++k) {
        from.col(static_cast<Eigen::Index>(k)) = rest[used[k]].position;
        to.col(static_cast<Eigen::Index>(k)) = observed[used[k]].position;
    }
    const Eigen::Matrix4d t = Eigen::umeyama(from, to, false);
    LandmarkSet out = rest;
    for (auto& l : out) l.position = t.topLeftCorner<3, 3>() * l.position + t.topRightCorner<3, 1>();
    return out;
}

} // namespace physreg
