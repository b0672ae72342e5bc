// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The assembled tangent stiffness of a TLED model, for implicit (Newton, backward Euler) solvers.
//
// The implicit solvers use exactly the TLED model's discretisation, so both solver families have
// the same equilibrium: uniform-strain hexahedra with the Joldes–Wittek–Miller hourglass control,
// linear tetrahedra, the three material laws, and paper 000's MLS penalty coupling. For an element,
//   f_a = V P(F) b_a + k_hg Σ_α Γ_aα (Σ_b Γ_bα u_b),            (the TLED internal force)
//   K_ab = V Σ_JL b_aJ (∂P_iJ/∂F_kL) b_bL + δ_ik k_hg Σ_α Γ_aα Γ_bα,
// the exact derivative of the force (the hourglass force is linear in u), and the energy is
// V Ψ(F) + ½ k_hg Σ_α |Σ_b Γ_bα u_b|² + the coupling's ½ Σ k_c |δ|².
//
// The sparsity pattern (every pair of nodes sharing an element or a coupling support) is built once;
// a column of node j holds 3 consecutive rows per neighbour node, so element blocks are written
// in place by precomputed offsets. Elements are assembled colour by colour on OpenMP threads (no
// two elements of a colour share a node: no races, the same sums in the same order for any thread count).
#include "physreg/core/thread_governor.hpp"
#include "physreg/mechanics/coupling/tissue_coupling.hpp"
#include "physreg/mechanics/elements/tled_model.hpp"

#include <Eigen/SparseCore>
#include <cstdint>
#include <vector>

namespace physreg {

using SparseMatrix = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

struct Assembly {
    double energy_mj = 0.0;          ///< strain + hourglass + coupling energy, mJ (N·mm)
    std::int64_t inverted_element = -1; ///< an element with det F ≤ 0 (then nothing else is valid)
    std::int64_t non_finite_element = -1; ///< an element whose force or tangent is NaN/inf
    /// Co-rotational law: elements with det F ≤ 0, kept in the solve (their rotation comes from
    /// the SVD and their force pushes them back); other laws stop at the first inverted element.
    std::int64_t inverted_tolerated = 0;
};

class StiffnessAssembler {
public:
    /// Throws Error for the averaged-nodal-pressure tetrahedron (it has no tangent here) and for a
    /// coupling built for another node count. `extra_stencils`: further node groups whose pairs
    /// need entries (auxiliary elements: membranes, embedded beams).
    StiffnessAssembler(const TledModel& model, const PenaltyCoupling* coupling = nullptr,
                       const std::vector<std::vector<std::int32_t>>& extra_stencils = {});

    /// Internal forces f (N, 3 per node, overwritten), the energy, and — when `stiffness` is given —
    /// the tangent (its values overwritten; it must come from make_matrix()). u: 3 per node, mm.
    Assembly assemble(const double* u, double* f, SparseMatrix* stiffness) const;
    /// Energy only (line searches). inverted_element ≥ 0 when some element is inverted.
    Assembly energy(const double* u) const;

    /// Co-rotational law only: assemble the rotated small-strain stiffness R K₀ Rᵀ (always positive
    /// semi-definite, not the exact derivative) instead of the exact tangent.
    void set_rotated_corotational_tangent(bool rotated) { m_rotated_tangent = rotated; }
    bool rotated_corotational_tangent() const { return m_rotated_tangent; }

    /// A matrix with the pattern, values zero.
    SparseMatrix make_matrix() const;
    /// Position in the value array of entry (3 i + r, 3 j + c) for nodes i, j sharing the pattern.
    std::int64_t value_index(std::int32_t i, std::int32_t j, int r, int c) const;
    std::size_t dofs() const { return 3 * m_model.node_count(); }
    const TledModel& model() const { return m_model; }
    const PenaltyCoupling* coupling() const { return m_coupling; }

private:
    const TledModel& m_model;
    const PenaltyCoupling* m_coupling;
    std::vector<int> m_outer, m_inner;         ///< CSC pattern (symmetric, both triangles)
    std::vector<std::int32_t> m_node_begin;    ///< node j's neighbours: m_neighbours[m_node_begin[j] …]
    std::vector<std::int32_t> m_neighbours;
    std::vector<std::int32_t> m_block;         ///< per element, per (a, b): position of node a in b's neighbours
    std::vector<std::int64_t> m_coupling_index, m_coupling_begin; ///< coupling pairs' value offsets, per point
    std::vector<std::vector<double>> m_hourglass_gram; ///< per geometry: Σ_α Γ_aα Γ_bα (8×8)
    bool m_rotated_tangent = false;
    mutable ThreadGovernor m_governor; ///< one assembly is one unit of work (not thread-safe: one caller at a time)
    std::vector<double> m_hourglass_k;         ///< per material: κ_hg M / 8 (times V Σ|b|² per geometry)
    /// Tetrahedra: b_a, volumes, μ and λ packed for the batched co-rotational force pass.
    std::vector<double> m_tetra_dn, m_tetra_volume, m_tetra_mu, m_tetra_lambda;
};

} // namespace physreg
