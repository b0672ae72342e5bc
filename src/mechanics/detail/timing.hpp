// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Wall-clock seconds for the time splits that the solvers report.
#include <chrono>

namespace physreg::detail {

inline double seconds_since(std::chrono::steady_clock::time_point start)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

} // namespace physreg::detail
