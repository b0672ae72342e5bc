// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Shared numeric types. Positions are physical coordinates in mm, ITK's LPS space.
// GCC 12's own AVX-512 intrinsics header (avx512fintrin.h, reached through Eigen with -march=native)
// declares `__m512d __Y = __Y;` in _mm512_undefined_pd(), which -Wmaybe-uninitialized reports in
// every file that inlines Eigen's AVX-512 packets (GCC bug 105593, fixed in GCC 13). Likewise
// -Warray-bounds on Eigen's 8-wide unaligned load in umeyama() of a 3-vector column, a path Eigen
// guards at run time. Both warnings are placed in these third-party headers, so they are silenced
// for the headers included here only, not for our code.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Warray-bounds"
#endif
#include <Eigen/Core>
#include <Eigen/Geometry> // cross products
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#include <array>
#include <cstdint>

namespace physreg {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Index3 = std::array<std::int64_t, 3>;

} // namespace physreg
