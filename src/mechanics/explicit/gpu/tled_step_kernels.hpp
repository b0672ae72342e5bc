// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The GPU path's TLED step, written once for the CUDA device and for the host emulation that tests
// it on machines without a GPU. One explicit central-difference step is two kernels:
//  1. per element: the forces on its 8 nodes (uniform-strain hexahedron with hourglass control,
//     the same formulas as the CPU kernel hexahedron_kernel.hpp), stored per element — no node is
//     written by two threads, so there is no colouring and no atomic add;
//  2. per node: the sum of its elements' stored forces in a fixed order (deterministic), then the
//     update u⁺ = A (s R − F) + B u − C u⁻ and the prescribed degrees of freedom.
// Plain C++ with PHYSREG_HD on every function: nvcc compiles it for the device, g++ for the host.
// The stress is hexahedron_stress.hpp's, the very formulas the CPU kernel runs.
#include "mechanics/detail/hexahedron_stress.hpp"

#include <cmath>
#include <cstdint>

#if defined(__CUDACC__)
#define PHYSREG_HD __host__ __device__
#else
#define PHYSREG_HD
#endif

namespace physreg::gpu {

enum StepLaw : int { step_neo_hookean = 0, step_st_venant_kirchhoff = 1 };

/// Model arrays the step reads (device or host pointers). Element-force storage is component
/// major: value k (= 3 a + d, node a, direction d) of element e at element_force[k × elements + e].
struct StepModel {
    std::int64_t elements = 0, nodes = 0;
    int law = step_neo_hookean;
    const std::int32_t* connectivity = nullptr; ///< 8 per element
    const std::uint16_t* material = nullptr;
    const std::int32_t* geometry = nullptr;
    const double* dn = nullptr;        ///< 24 per geometry
    const double* gamma = nullptr;     ///< 32 per geometry
    const double* volume = nullptr;    ///< per geometry, mm³
    const double* vb2 = nullptr;       ///< per geometry: V Σ|b|²
    const double* mu = nullptr;        ///< per material, MPa
    const double* lambda = nullptr;
    const double* kappa = nullptr;
    const double* hourglass = nullptr; ///< per material: κ_hg M / 8
    // Per node: the element-force slots to sum (CSR), and the update's coefficients.
    const std::int64_t* incidence_offset = nullptr; ///< nodes + 1
    const std::int64_t* incidence = nullptr;        ///< slot 3a × elements + e
    const double* coefficient_a = nullptr;
    const double* coefficient_b = nullptr;
    const double* coefficient_c = nullptr;
    const std::uint8_t* constrained = nullptr; ///< 3 per node
    const double* prescribed = nullptr;        ///< 3 per node at load factor 1, mm
    const double* external = nullptr;          ///< 3 per node at load factor 1, N; null: none
};

/// Writes P(k, value) into a row-major array (volume_first_piola's output).
struct StoreRowMajor {
    double* a;
    PHYSREG_HD void operator()(int k, double value) const { a[k] = value; }
};

/// Kernel 1 for element e. Returns false when det F ≤ 0 (inverted element).
PHYSREG_HD inline bool element_forces(const StepModel& m, std::int64_t e, const double* u, double* element_force)
{
    const std::int32_t* c = m.connectivity + 8 * e;
    const int g = m.geometry[e];
    const int mat = m.material[e];
    const double* b = m.dn + 24 * g;
    const double* gamma = m.gamma + 32 * g;
    double ua[8][3];
    for (int a = 0; a < 8; ++a)
        for (int d = 0; d < 3; ++d) ua[a][d] = u[3 * static_cast<std::int64_t>(c[a]) + d];
    double F[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    for (int a = 0; a < 8; ++a)
        for (int r = 0; r < 3; ++r)
            for (int k = 0; k < 3; ++k) F[3 * r + k] += ua[a][r] * b[3 * a + k];
    const double J = F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) + F[2] * (F[3] * F[7] - F[4] * F[6]);
    const bool sound = J > 0.0;
    // C = Fᵀ F, the second Piola–Kirchhoff stress S and V F S: hexahedron_stress.hpp, as the CPU kernel.
    const physreg::detail::RowMajor3<double> f{F};
    const auto cg = physreg::detail::right_cauchy_green<double>(f);
    const double jj = sound ? J : 1.0; // an inverted element is reported; keep the arithmetic finite
    const auto s = m.law == step_st_venant_kirchhoff ? physreg::detail::st_venant_kirchhoff_stress(cg, m.mu[mat], m.lambda[mat])
                                                     : physreg::detail::neo_hookean_stress(cg, m.mu[mat], m.kappa[mat], jj, 1.0 / cbrt(jj));
    double P[9];
    physreg::detail::volume_first_piola(f, s, m.volume[g], StoreRowMajor{P});
    const double khg = m.hourglass[mat] * m.vb2[g];
    double q[4][3];
    for (int mode = 0; mode < 4; ++mode)
        for (int d = 0; d < 3; ++d) {
            double sum = 0.0;
            for (int a = 0; a < 8; ++a) sum += gamma[4 * a + mode] * ua[a][d];
            q[mode][d] = khg * sum;
        }
    for (int a = 0; a < 8; ++a) {
        const double b0 = b[3 * a], b1 = b[3 * a + 1], b2 = b[3 * a + 2];
        for (int d = 0; d < 3; ++d) {
            double value = P[3 * d] * b0 + P[3 * d + 1] * b1 + P[3 * d + 2] * b2;
            for (int mode = 0; mode < 4; ++mode) value += gamma[4 * a + mode] * q[mode][d];
            element_force[(3 * a + d) * m.elements + e] = value;
        }
    }
    return sound;
}

/// Kernel 2 for node i: gathers its force and writes u⁺ at load factors s (now) and sn (next).
/// Returns |u⁺|∞ of the node (infinite when not finite).
PHYSREG_HD inline double node_update(const StepModel& m, std::int64_t i, const double* element_force, const double* u, const double* u_prev,
                                     double* u_next, double s, double sn)
{
    double f[3] = {0.0, 0.0, 0.0};
    for (std::int64_t k = m.incidence_offset[i]; k < m.incidence_offset[i + 1]; ++k) {
        const std::int64_t slot = m.incidence[k];
        for (int d = 0; d < 3; ++d) f[d] += element_force[slot + d * m.elements];
    }
    double largest = 0.0;
    for (int d = 0; d < 3; ++d) {
        const std::int64_t k = 3 * i + d;
        double value;
        if (m.constrained[k]) {
            value = sn * m.prescribed[k];
        } else {
            const double load = m.external ? s * m.external[k] : 0.0;
            value = m.coefficient_a[i] * (load - f[d]) + m.coefficient_b[i] * u[k] - m.coefficient_c[i] * u_prev[k];
        }
        u_next[k] = value;
        const double magnitude = fabs(value);
        largest = magnitude == magnitude ? (magnitude > largest ? magnitude : largest) : INFINITY;
    }
    return largest;
}

} // namespace physreg::gpu
