// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// An image grid as the summaries (summary.json) write it: size, spacing (mm), origin (mm, LPS) and
// direction cosines.
#include "physreg/image/image_geometry.hpp"

#include <nlohmann/json.hpp>

namespace physreg {

nlohmann::json to_json(const ImageGeometry& geometry);

} // namespace physreg
