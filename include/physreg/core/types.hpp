// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Shared numeric types. Positions are physical coordinates in mm, ITK's LPS space.
#include <Eigen/Core>
#include <Eigen/Geometry> // cross products
#include <array>
#include <cstdint>

namespace physreg {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Index3 = std::array<std::int64_t, 3>;

} // namespace physreg
