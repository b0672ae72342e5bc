// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The model paper 001 registers: a smooth tetrahedral liver (CGAL Mesh_3) whose boundary triangles
// carry surface regions — umbilical notch (UN, 1), anterior margin (AM, 2), the rest (0) — from a
// label volume, a labelled surface, or none (everything "surface").
#include "physreg/image/image_geometry.hpp"
#include "physreg/mesh/surface_mesh.hpp"
#include "physreg/mesh/tetrahedral_meshing.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/model/tissue_table.hpp"
#include "physreg/registration/model.hpp"
#include "physreg/registration/surface/surface_matching.hpp"

#include <optional>
#include <set>
#include <string>

namespace physreg {

struct SurfaceModel {
    VolumeMesh mesh;              ///< tetrahedra, every cell label 1
    LabelledTriangles surface;    ///< outward boundary triangles over mesh node ids, with regions
    TetrahedronQuality quality;
};

/// Meshes the union of `liver_labels` of `labels` (largest circumradius `cell_size_mm`, surface facets
/// within a voxel of the smooth boundary) and labels the boundary by the phantom's anatomical rule
/// (partial_surface.hpp: anterior-inferior band = AM, the part of it within 10 mm of `notch_x_mm` = UN;
/// no notch: no UN region). Throws Error naming `what` for an empty selection.
SurfaceModel surface_model_from_labels(const LabelVolume& labels, const std::set<std::int32_t>& liver_labels, double cell_size_mm,
                                       std::optional<double> notch_x_mm, unsigned seed, const std::string& what);

/// Meshes the inside of a closed liver surface (STL/PLY/OBJ) the same way; regions by the anatomical
/// rule when `notch_x_mm` is given, else every triangle "surface". Throws Error for open,
/// non-manifold or self-intersecting surfaces.
SurfaceModel surface_model_from_surface(const SurfaceMesh& surface, double cell_size_mm, std::optional<double> notch_x_mm, unsigned seed,
                                        const std::string& what);

/// A point the user picked on the surface and the region it seeds (1 UN, 2 AM).
struct RegionSeed {
    std::int32_t label = 0;
    Vec3 point = Vec3::Zero();
};
/// Regions grown from picked points: a triangle takes a seed's label when its centroid lies within
/// `radius_mm` of the seed along the surface (Dijkstra over the surface edges from the vertex
/// nearest the seed); the notch wins over the margin where both reach. Throws Error naming `what`
/// for a seed farther than `max_snap_mm` from the surface or a radius ≤ 0.
LabelledTriangles regions_from_seeds(const VolumeMesh& mesh, const LabelledTriangles& boundary, const std::vector<RegionSeed>& seeds, double radius_mm,
                                     double max_snap_mm, const std::string& what);

/// Regions from a labelled surface in the same space (a PLY with per-vertex "label"/"feature", or
/// per-face labels: the inside label): each boundary triangle takes the label at the closest point of
/// `regions` to its centroid (vertex labels: of the closest corner). Throws Error naming `what` when
/// the surface has no labels or lies farther than `max_distance_mm` from a triangle.
LabelledTriangles regions_from_surface(const VolumeMesh& mesh, const LabelledTriangles& boundary, const SurfaceMesh& regions,
                                       double max_distance_mm, const std::string& what);

/// The boundary (displaced when `displacement_mm` is given) as a surface whose triangles carry their
/// region as the inside label — written as PLY it opens in ParaView (face data) and reads back with
/// regions_from_surface.
SurfaceMesh regions_surface(const VolumeMesh& mesh, const LabelledTriangles& boundary, const std::vector<double>* displacement_mm = nullptr);

/// The shared model (registration/model.hpp) of a paper 001 liver: its tetrahedra and labelled
/// surface, `tissues` for its cell label(s), the co-rotational law, and `supports` (none: paper 001).
/// Throws Error naming the problem, as Model::validate.
Model to_model(const SurfaceModel& model, const TissueTable& tissues, std::vector<NodeConstraint> supports = {});

/// One homogeneous parenchyma (label 1): paper 001's healthy (3.5 kPa) or cirrhotic (30 kPa) liver, ν 0.45.
TissueTable homogeneous_liver_tissues(double young_modulus_pa, double poisson_ratio = 0.45);

} // namespace physreg
