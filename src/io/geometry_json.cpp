// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/geometry_json.hpp"

namespace physreg {

nlohmann::json to_json(const ImageGeometry& g)
{
    nlohmann::json direction = nlohmann::json::array();
    for (int r = 0; r < 3; ++r) direction.push_back({g.direction(r, 0), g.direction(r, 1), g.direction(r, 2)});
    return {{"size", {g.size[0], g.size[1], g.size[2]}},
            {"spacing_mm", {g.spacing[0], g.spacing[1], g.spacing[2]}},
            {"origin_mm_lps", {g.origin[0], g.origin[1], g.origin[2]}},
            {"direction", direction}};
}

} // namespace physreg
