// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Landmark files, chosen by extension:
//  .csv      name,x,y,z[,type] in mm LPS. An optional "# coordinate_system = RAS" comment line
//            flips to RAS; "# units = mm" is checked (other units are refused).
//  .fcsv     3D Slicer markups fiducial CSV ("# CoordinateSystem = LPS|RAS|0|1"; none = RAS).
//  .mrk.json 3D Slicer markups JSON (coordinateSystem LPS or RAS, coordinateUnits mm).
// RAS is converted to LPS on reading (x and y negated); files are written in LPS.
#include "physreg/core/landmark.hpp"

#include <filesystem>

namespace physreg {

LandmarkSet read_landmarks(const std::filesystem::path& path);
void write_landmarks(const std::filesystem::path& path, const LandmarkSet& landmarks);

} // namespace physreg
