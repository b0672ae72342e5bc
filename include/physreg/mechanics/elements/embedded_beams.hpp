// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 001's vascular tree: Timoshenko beams along the vessel centrelines, embedded in the
// tetrahedra. Each beam node lies in a tetrahedron; its displacement is the barycentric mix of
// the tetrahedron's nodes and its rotation the tetrahedron's rotation ½ curl u — so the beams add
// no unknowns, only stiffness that couples the tetrahedra around them (paper 001 couples its beams
// to the tetrahedra by barycentric mapping too).
//
// Co-rotational: an element's frame R is the polar rotation of the mean deformation gradient of
// its two tetrahedra; the tetrahedra's nodes are unrotated by Rᵀ, the linear Timoshenko element
// acts on the unrotated displacements w (energy ½ wᵀ M w, M = Tᵀ K T precomputed: T maps the 24
// tetrahedron displacements to the 12 beam unknowns), and forces rotate back: f = R M w. Rigid
// motions give w = a translation, which the element does not resist. Tangent: R M Rᵀ (rotated).
#include "physreg/core/types.hpp"
#include "physreg/mechanics/elements/auxiliary_elements.hpp"
#include "physreg/io/vessel_centrelines.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace physreg {

struct BeamMaterial {
    double young_modulus_pa = 620e3; ///< paper 001's vessels
    double poisson_ratio = 0.4;
    double shear_correction = 0.9;   ///< κ of a solid circular section (≈ 6(1+ν)/(7+6ν))
    void validate(const std::string& what) const;
};

class EmbeddedBeams : public AuxiliaryElements {
public:
    /// Resamples every branch into elements of at most `element_mm` and embeds their nodes in the
    /// tetrahedral `mesh`. Segments with a node outside the mesh are left out (counted in
    /// dropped_elements()). Throws Error naming `what` for non-tetrahedral meshes, bad materials or
    /// when no element lies inside.
    EmbeddedBeams(const VolumeMesh& mesh, const std::vector<VesselBranch>& branches, const BeamMaterial& material, double element_mm,
                  const std::string& what);

    std::vector<std::vector<std::int32_t>> stencils() const override;
    double add_forces(const double* u, double* f) const override;
    void add_stiffness(const double* u, const StiffnessAssembler& assembler, double* values) const override;

    std::size_t size() const { return m_elements.size(); }
    std::size_t dropped_elements() const { return m_dropped; }
    double total_length_mm() const;

    /// The 12×12 Timoshenko stiffness in the element's axes (dofs u, v, w, θx, θy, θz per node),
    /// N/mm, N, N·mm: exposed for tests.
    static Eigen::Matrix<double, 12, 12> timoshenko_stiffness(double length_mm, double radius_mm, const BeamMaterial& material);

private:
    struct Element {
        std::array<std::int32_t, 8> nodes;          ///< the two tetrahedra's nodes (may repeat)
        std::array<Vec3, 8> rest;                   ///< their rest positions
        std::array<Vec3, 8> gradient;               ///< ∇N of each node in its tetrahedron, 1/mm
        Eigen::Matrix<double, 24, 24> stiffness;    ///< M = Tᵀ K T in global axes
        double length_mm;
    };
    /// The element frame R and the unrotated displacements w (24) at displacement u.
    void unrotate(const Element& e, const double* u, Mat3& r, Eigen::Matrix<double, 24, 1>& w) const;

    std::vector<Element> m_elements;
    std::size_t m_dropped = 0;
};

} // namespace physreg
