// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/figures/tre_chart.hpp"

#include "physreg/core/error.hpp"
#include "physreg/figures/canvas.hpp"

#include <algorithm>
#include <cmath>
#include <map>

namespace physreg {

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
            c.fill_rect(bx, static_cast<int>(std::lround(y_of(e.error_mm))), bx + bar - 2, head + plot_h, colour(e.type, s)); // rounded, not truncated: y is computed with a fused multiply-add, 113.99… for 4 mm
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

} // namespace physreg
