// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/evaluation/tre.hpp"

#include <Eigen/Geometry>

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/figures/canvas.hpp"

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

RgbImage render_tre_chart(const std::vector<TreSeries>& series, const std::string& title)
{
    if (series.empty()) fail("TRE chart: nothing to draw");
    const std::size_t n = series.front().report.entries.size();
    for (const auto& s : series)
        if (s.report.entries.size() != n) fail("TRE chart: series '{}' has {} landmarks, the first has {}", s.label, s.report.entries.size(), n);
    double top = 1.0;
    for (const auto& s : series)
        for (const auto& e : s.report.entries) top = std::max(top, e.error_mm);
    top = std::ceil(top * 1.1);
    const int left = 60, right = 20, head = 50, foot = 70 + 16 * static_cast<int>(series.size());
    const int min_group = std::max<int>(12, 6 * static_cast<int>(series.size()) + 4);
    const int width = std::max(640, left + right + min_group * static_cast<int>(n)), plot_h = 320, height = head + plot_h + foot;
    const int group = std::max(min_group, (width - left - right) / std::max<int>(1, static_cast<int>(n))); // fill the plot
    Canvas c(width, height);
    const Rgb black{0, 0, 0}, grey{200, 200, 200};
    auto y_of = [&](double mm) { return head + plot_h - mm / top * plot_h; };
    c.text(left, 12, title, black, 2);
    // Axis with mm ticks.
    const double tick = top <= 5 ? 0.5 : top <= 10 ? 1.0 : top <= 25 ? 2.5 : 5.0;
    for (double v = 0; v <= top + 1e-9; v += tick) {
        c.line(left, y_of(v), width - right, y_of(v), grey);
        c.text(4, static_cast<int>(y_of(v)) - 3, fmt::format("{:.1f}", v), black);
    }
    c.text(4, head - 14, "TRE MM", black);
    c.line(left, head, left, head + plot_h, black);
    // Bars: one group per landmark, one bar per series; colour by landmark type, shade by series.
    auto colour = [](LandmarkType t, std::size_t s) -> Rgb {
        Rgb base = t == LandmarkType::surface ? Rgb{40, 160, 60} : t == LandmarkType::tumour ? Rgb{210, 50, 40} : Rgb{40, 90, 200};
        for (auto& v : base) v = static_cast<std::uint8_t>(std::min(255.0, v + 70.0 * double(s)));
        return base;
    };
    const int bar = std::max(3, (group - 4) / static_cast<int>(series.size()));
    for (std::size_t i = 0; i < n; ++i) {
        const int x0 = left + 2 + group * static_cast<int>(i);
        for (std::size_t s = 0; s < series.size(); ++s) {
            const auto& e = series[s].report.entries[i];
            const int bx = x0 + bar * static_cast<int>(s);
            c.fill_rect(bx, static_cast<int>(y_of(e.error_mm)), bx + bar - 2, head + plot_h, colour(e.type, s));
        }
        if (n <= 40) c.text(x0, head + plot_h + 4 + 8 * static_cast<int>(i % 2), series.front().report.entries[i].name.substr(0, 3), black);
    }
    // Legend: the series with their means (surface / internal / all).
    int y = head + plot_h + 26;
    c.text(left, y, "GREEN SURFACE  RED TUMOUR  BLUE VESSEL  (LIGHTER: LATER SERIES)", black);
    for (const auto& s : series) {
        y += 16;
        c.text(left, y,
               fmt::format("{}: SURFACE {:.2f}  INTERNAL {:.2f}  ALL {:.2f} MM (MAX {:.2f})", s.label, s.report.surface.mean_mm,
                           s.report.internal.mean_mm, s.report.all.mean_mm, s.report.all.max_mm),
               black);
    }
    return c.image();
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
