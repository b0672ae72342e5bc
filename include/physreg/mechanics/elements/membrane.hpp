// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Glisson's capsule (paper 001's heterogeneous liver): a membrane of constant-strain triangles on
// the model's surface nodes, plane stress, co-rotational. Per triangle, the in-plane deformation
// gradient F (3×2, from the rest triangle's own 2-D frame) is split by its polar decomposition
// F = Q S (Q: 3×2 with orthonormal columns, S: 2×2 symmetric); the small strain ε = S − I gives
// the stress σ = D ε, and the corner forces f_a = A t Q σ ∇N_a are the derivative of the energy
// ½ A t εᵀ D ε. The tangent is the rotated small-strain stiffness A t Q Bᵀ D B Qᵀ (positive
// semi-definite, as the co-rotational tetrahedra's), not the exact derivative.
//
// The membrane adds into a StiffnessAssembler's pattern: every pair of corners must share a model
// element, which holds for triangles that are faces of the volume mesh (its boundary).
#include "physreg/mechanics/elements/auxiliary_elements.hpp"
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"

#include <array>
#include <string>
#include <vector>

namespace physreg {

struct MembraneMaterial {
    double young_modulus_pa = 8.0e6; ///< paper 001's capsule: 8 000 kPa
    double poisson_ratio = 0.45;
    double thickness_mm = 0.1;       ///< our assumption (paper 001 gives none): Glisson's capsule is ≈ 0.1 mm thick
    void validate(const std::string& what) const;
};

class Membrane : public AuxiliaryElements {
public:
    /// Triangles over model node ids at their rest positions (3 per node, mm). Throws Error naming
    /// `what` for bad materials, node ids out of range or degenerate triangles.
    Membrane(const std::vector<std::array<std::int32_t, 3>>& triangles, const std::vector<double>& rest_mm, const MembraneMaterial& material,
             const std::string& what);

    /// Adds the internal forces (N) at displacement u (mm) into f and returns the energy (mJ).
    double add_forces(const double* u, double* f) const override;
    /// Adds the rotated stiffness (N/mm) into `values` of a matrix in `assembler`'s pattern.
    void add_stiffness(const double* u, const StiffnessAssembler& assembler, double* values) const override;
    std::vector<std::vector<std::int32_t>> stencils() const override;
    std::size_t size() const { return m_triangles.size(); }
    double total_area_mm2() const;

private:
    struct Element {
        std::array<std::int32_t, 3> nodes;
        std::array<double, 6> gradient; ///< ∇N_a in the rest triangle's 2-D frame: [2a + k], 1/mm
        Eigen::Matrix2d rest_inverse;   ///< inverse of [X1 − X0, X2 − X0] in that frame
        double area_mm2;
    };
    /// Q (3×2) and the strain ε (Voigt: xx, yy, 2xy) of element e at displacement u.
    void rotation_and_strain(const Element& e, const double* u, Eigen::Matrix<double, 3, 2>& q, Eigen::Vector3d& strain) const;

    std::vector<Element> m_triangles;
    const std::vector<double>& m_rest;
    Eigen::Matrix3d m_d;   ///< plane-stress elasticity × thickness, N/mm (MPa · mm)
};

} // namespace physreg
