// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The model and loads packed for the GPU step's kernels, in host memory (standard C++ only: the
// CUDA back end includes it).
#include "tled_step_kernels.hpp"

#include <cstdint>
#include <vector>

namespace physreg::gpu {

/// The model and loads packed for the kernels, in host memory.
struct HostModel {
    std::int64_t elements = 0, nodes = 0;
    int law = step_neo_hookean;
    std::vector<std::int32_t> connectivity, geometry;
    std::vector<std::uint16_t> material;
    std::vector<double> dn, gamma, volume, vb2, mu, lambda, kappa, hourglass;
    std::vector<std::int64_t> incidence_offset, incidence;
    std::vector<double> coefficient_a, coefficient_b, coefficient_c;
    std::vector<std::uint8_t> constrained;
    std::vector<double> prescribed, external; ///< external empty: no external forces
    StepModel view() const; ///< pointers into these vectors
};

struct ChunkReport {
    std::int64_t inverted_element = -1; ///< smallest element with det F ≤ 0 in the chunk, -1 none
    long inverted_step = -1;            ///< the chunk's first step (0-based) that found one
    double largest_mm = 0.0;            ///< largest |u| over the chunk (infinite if not finite)
};

} // namespace physreg::gpu
