// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// One model for the three registration modes (issue 29): what is simulated — a mesh, a material
// per element, the supports and the structures beside the volume elements — apart from what
// drives it (observation.hpp) and from the solver each mode needs:
//   tool poses     → compression/   TLED, dynamic relaxation or Newton   (paper 000)
//   a point cloud  → surface/       backward Euler under pair forces     (paper 001)
//   a segmentation → images/        linear elasticity, adjoint L-BFGS     (paper 002)
// Each mode's own model type (LiverModel, SurfaceModel) converts to and from it, so a paper 000
// body model can meet a paper 001 point cloud and paper 002's adjoint can fit a paper 001 liver.
#include "physreg/mechanics/coupling/tissue_coupling.hpp"
#include "physreg/mechanics/elements/auxiliary_elements.hpp"
#include "physreg/mechanics/materials/material.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/model/loads.hpp"
#include "physreg/model/tissue_table.hpp"
#include "physreg/mesh/labelled_boundary.hpp"

#include <functional>
#include <memory>
#include <set>
#include <string>
#include <vector>

namespace physreg {

struct Model {
    VolumeMesh mesh;                     ///< hexahedra or tetrahedra (mm, LPS); a cell's label names its tissue
    TissueTable tissues;                 ///< per label: Young's modulus (Pa), Poisson ratio, density
    MaterialLaw law = MaterialLaw::neo_hookean; ///< the constitutive law of every volume element
    /// Held degrees of freedom (zero displacement): whole nodes (bone, a posterior surface) or
    /// single directions (a frictionless table holds the normal one).
    std::vector<NodeConstraint> supports;
    /// The surface an intra-operative cloud sees, over the mesh's node ids, with regions (0 surface,
    /// 1 umbilical notch, 2 anterior margin): the outer boundary, or an organ's boundary inside a body.
    LabelledTriangles surface;
    /// Structures beside the volume elements (paper 001's capsule membrane, vessel beams).
    std::vector<std::shared_ptr<const AuxiliaryElements>> structures;
    /// Tissue–tissue penalty coupling over split interface nodes (paper 000's coupled variant); null: none.
    std::shared_ptr<const PenaltyCoupling> coupling;

    /// Throws Error naming `what`: an invalid mesh, a cell label without tissue, a support or surface
    /// node outside the mesh, a coupling over another node count.
    void validate(const std::string& what) const;
    /// Nodes whose three directions are all held, sorted.
    std::vector<std::int32_t> held_nodes() const;
    /// Supports that hold only some directions (empty when every support holds whole nodes).
    std::vector<NodeConstraint> partial_supports() const;
    /// The smallest Young's modulus of the tissues whose cells touch the surface, Pa: the material
    /// a cloud's pair forces press on.
    double surface_young_modulus_pa() const;
    std::vector<const AuxiliaryElements*> structure_pointers() const;
};

/// The boundary of the cells whose label satisfies `keep` as triangles over the mesh's node ids,
/// outward, every region 0 (hexahedra's quadrilaterals split in two). Throws Error naming `what`
/// when no cell is kept.
LabelledTriangles cell_group_boundary(const VolumeMesh& mesh, const std::function<bool(std::int32_t)>& keep, const std::string& what);

} // namespace physreg
