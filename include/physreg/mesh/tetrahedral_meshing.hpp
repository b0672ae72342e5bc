// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Conforming tetrahedral meshes of label volumes with CGAL's Mesh_3 (Delaunay refinement): every
// boundary between two labels is a set of mesh faces, approximating the smooth interface rather
// than the voxel staircase. The labelling function is CGAL's "labellized trilinear" rule (the label
// whose trilinear indicator weight is largest at the point), so interfaces are located to sub-voxel
// accuracy. Sizes per label (e.g. fine in the liver, coarse in the surrounding gel).
//
// Why CGAL Mesh_3 (and not TetGen or Gmsh): it meshes a labelled domain directly (no surface
// extraction and repair first), guarantees conformity of every interface, has size and quality
// criteria with sliver exudation, is in Debian (libcgal-dev, GPL-3.0-or-later like physreg), and is
// deterministic for a fixed random seed.
#include "physreg/image/image_geometry.hpp"
#include "physreg/mesh/surface_mesh.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <map>
#include <set>
#include <string>

namespace physreg {

struct TetMeshingOptions {
    std::set<std::int32_t> labels;                 ///< labels meshed (others are outside); empty: every nonzero label
    std::map<std::int32_t, double> cell_size_mm;   ///< largest circumradius per label
    double default_cell_size_mm = 8.0;             ///< labels not in cell_size_mm
    double facet_size_mm = 4.0;                    ///< largest surface Delaunay ball radius
    double facet_distance_mm = 0.6;                ///< largest distance of a facet to the true interface
    double facet_angle_deg = 25.0;                 ///< smallest facet angle
    double radius_edge_ratio = 2.5;                ///< largest circumradius / shortest edge of a cell
    bool exude = true;                             ///< sliver exudation (to its end: no time limit, so reproducible)
    unsigned seed = 1;                             ///< CGAL's random generator (the same seed, the same mesh)
    /// Seed CGAL's surface with points on every connected component of every label. CGAL's default
    /// random rays can miss a small or distant component (one kidney of the small phantom); off by
    /// default for now because it changes every existing mesh (the phantom's ground truth included).
    bool seed_every_component = false;
    void validate() const;
};

/// Meshes the selected labels of `labels`; cells carry their label. Throws Error naming `what` for
/// bad options, no selected voxel, or an empty result (features smaller than the sizes).
VolumeMesh mesh_labels_tetrahedral(const LabelVolume& labels, const TetMeshingOptions& options, const std::string& what);

/// Meshes the inside of a closed surface (CGAL's polyhedral domain; cells labelled 1) with the
/// sizes of `options` (default_cell_size_mm for the cells; labels and per-label sizes unused).
/// Throws Error naming `what` for a surface that is empty, non-manifold, not closed or
/// self-intersecting. An inward-oriented surface is turned outward.
VolumeMesh mesh_surface_tetrahedral(const SurfaceMesh& surface, const TetMeshingOptions& options, const std::string& what);

/// Shape measures of a tetrahedral mesh, for the quality report.
struct TetrahedronQuality {
    std::size_t cells = 0, nodes = 0;
    double min_dihedral_deg = 0.0, max_dihedral_deg = 0.0;
    double min_radius_ratio = 0.0;      ///< 3 r_inscribed / R_circumscribed: 1 regular, → 0 degenerate
    double mean_radius_ratio = 0.0;
    std::size_t below_10_deg = 0;       ///< cells with a dihedral angle < 10°
    double min_edge_mm = 0.0, mean_edge_mm = 0.0, max_edge_mm = 0.0;
};
TetrahedronQuality measure_tetrahedra(const VolumeMesh& mesh);

} // namespace physreg
