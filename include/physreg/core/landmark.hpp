// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
#include "physreg/core/types.hpp"

#include <optional>
#include <string>
#include <vector>

namespace physreg {

enum class LandmarkType { unspecified, surface, tumour, vessel };
std::string to_string(LandmarkType type);
std::optional<LandmarkType> parse_landmark_type(const std::string& text); ///< "" → unspecified

/// A named point in physical mm, LPS (ITK's convention; 3D Slicer shows RAS).
struct Landmark {
    std::string name;
    Vec3 position = Vec3::Zero();
    LandmarkType type = LandmarkType::unspecified;
};

using LandmarkSet = std::vector<Landmark>;

} // namespace physreg
