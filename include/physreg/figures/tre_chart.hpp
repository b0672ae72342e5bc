// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The TRE bar chart (PNG through the raster canvas), for the commands' outputs; report.html draws
// the same data with matplotlib.
#include "physreg/evaluation/tre.hpp"
#include "physreg/io/png.hpp"

#include <string>
#include <vector>

namespace physreg {

/// Bar chart: per landmark the error (surface green, tumour red, vessel blue) and the means of
/// each group as lines; `series` lets several methods share one chart (grouped bars).
struct TreSeries {
    std::string label;
    TreReport report;
};
RgbImage render_tre_chart(const std::vector<TreSeries>& series, const std::string& title);

} // namespace physreg
