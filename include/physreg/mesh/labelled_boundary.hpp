// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A volume mesh's outer boundary as triangles over the mesh's own node ids, with feature labels
// from the rest shape (paper 001 matches an umbilical-notch-like cleft and the anterior margin
// separately).
#include "physreg/core/types.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace physreg {

enum SurfaceFeature : std::int32_t { feature_none = 0, feature_umbilical_notch = 1, feature_anterior_margin = 2 };

/// The outer boundary of a volume mesh as triangles over the mesh's own node ids (so any nodal
/// displacement deforms it), with outward orientation.
struct BoundarySurface {
    std::vector<std::array<std::int32_t, 3>> triangles; ///< volume-mesh node ids
    std::vector<std::int32_t> nodes;                    ///< the boundary's node ids, sorted
    std::vector<std::int32_t> node_feature;             ///< per entry of `nodes`: SurfaceFeature
};

/// Boundary triangles of `mesh` restricted to cells whose label satisfies `keep` (e.g. the liver,
/// not the kidneys), and feature labels from the rest shape: the anterior margin is where the
/// outward normal lies within 35° of anterior-inferior (0, −1, −1)/√2; the notch is the part of
/// that band and of the inferior surface within 10 mm (in x) of `notch_x_mm`.
BoundarySurface liver_boundary(const VolumeMesh& mesh, const std::function<bool(std::int32_t)>& keep,
                               std::optional<double> notch_x_mm);

/// A surface over a mesh's node ids with a region label per triangle: paper 001's matching source
/// (SurfaceFeature: 0 surface, 1 umbilical notch, 2 anterior margin; other labels are never paired),
/// the surface every registration mode's Model carries.
struct LabelledTriangles {
    std::vector<std::array<std::int32_t, 3>> triangles;
    std::vector<std::int32_t> labels;
    /// Throws Error naming `what` for mismatched sizes, node ids outside [0, node_count) or negative labels.
    void validate(std::size_t node_count, const std::string& what) const;
};

/// The whole outer boundary of `mesh` as LabelledTriangles: a triangle takes a feature carried by at
/// least two of its corners (liver_boundary's rule; no notch without `notch_x_mm`).
LabelledTriangles labelled_triangles(const VolumeMesh& mesh, std::optional<double> notch_x_mm);

/// The boundary of a volume mesh, every triangle "surface" (0).
LabelledTriangles unlabelled_boundary(const VolumeMesh& mesh);

/// Boundary nodes whose area-weighted rest normal points along `direction` (cosine > `cosine`):
/// e.g. the posterior face a support holds.
std::vector<std::int32_t> surface_nodes_facing(const VolumeMesh& mesh, const LabelledTriangles& surface, const Vec3& direction, double cosine);

/// Boundary nodes within `radius_mm` of any of `points` (a support picked as points: ligaments, the
/// vena cava). Throws Error for a radius ≤ 0.
std::vector<std::int32_t> surface_nodes_near(const VolumeMesh& mesh, const LabelledTriangles& surface, const std::vector<Vec3>& points, double radius_mm);

/// Node n's position displaced by u (3 per node, mm; empty: at rest).
inline Vec3 displaced_position(const VolumeMesh& mesh, const std::vector<double>& u, std::int32_t n)
{
    const auto q = static_cast<std::size_t>(n);
    return mesh.nodes[q] + (u.empty() ? Vec3::Zero() : Vec3(u[3 * q], u[3 * q + 1], u[3 * q + 2]));
}

} // namespace physreg
