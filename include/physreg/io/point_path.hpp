// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A tool's path written on a command line: "x,y,z;x,y,z;…" (mm, LPS), as `physreg prepare
// --tool-path` and `register-surface --tool-path` take it.
#include "physreg/core/types.hpp"

#include <string>
#include <vector>

namespace physreg {

/// The path's points; throws Error naming `what` (e.g. "--tool-path") for a word that is not a
/// number, a point without three coordinates, a coordinate that is not finite (NaN, inf) or no point.
std::vector<Vec3> parse_point_path(const std::string& text, const std::string& what);

/// The distance from `x` to the polyline through `path` (a single point: the distance to it).
double distance_to_path(const Vec3& x, const std::vector<Vec3>& path);

} // namespace physreg
