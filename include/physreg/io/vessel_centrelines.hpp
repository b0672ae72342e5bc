// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Vessel centrelines: polylines with a radius per point (mm, LPS), as paper 001's vessel beams
// (mechanics/elements/embedded_beams.hpp) and the phantom's vascular tree use them.
#include "physreg/core/types.hpp"

#include <filesystem>
#include <vector>

namespace physreg {

/// One branch of a vessel tree: a polyline with a radius per point (mm, LPS).
struct VesselBranch {
    std::vector<Vec3> points;
    std::vector<double> radii_mm;
};

/// Reads centrelines: CSV "branch,x,y,z,radius" (mm; rows of a branch consecutive), or the
/// DigitalTwin text format (one "x y z" per line, branches separated by blank lines; every radius
/// `default_radius_mm`). Coordinates are multiplied by `scale` (e.g. 1000 for metres). Throws
/// Error naming the file for unreadable or non-finite values and branches of fewer than two points.
std::vector<VesselBranch> read_vessel_centrelines(const std::filesystem::path& path, double scale, double default_radius_mm);
/// Writes the CSV form (atomic).
void write_vessel_centrelines(const std::filesystem::path& path, const std::vector<VesselBranch>& branches);

} // namespace physreg
