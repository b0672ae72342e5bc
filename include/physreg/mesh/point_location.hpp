// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Locating points (landmarks) in a volume mesh and interpolating nodal fields there.
#include "physreg/core/landmark.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <optional>

namespace physreg {

class PointLocator {
public:
    /// Bins cells by bounding box on a uniform grid (about one cell per bin). The mesh must
    /// outlive the locator.
    explicit PointLocator(const VolumeMesh& mesh);

    /// The cell containing `point` (boundary included, tolerance 1e-6 in natural coordinates),
    /// or nothing when the point lies outside the mesh.
    std::optional<NodeEmbedding> locate(const Vec3& point) const;

    /// Like locate(), but throws Error naming `name` with the distance to the nearest node when
    /// the point is outside.
    NodeEmbedding locate_or_throw(const Vec3& point, const std::string& name) const;

private:
    const VolumeMesh& m_mesh;
    Vec3 m_lower, m_bin_size;
    Index3 m_bins{1, 1, 1};
    std::vector<std::int32_t> m_bin_start, m_bin_cells;
};

/// Natural coordinates of `point` in cell `cell` (Newton iteration for hexahedra, exact for
/// tetrahedra); `converged` false if Newton failed (a badly distorted cell).
Vec3 natural_coordinates(const VolumeMesh& mesh, std::size_t cell, const Vec3& point, bool& converged);

/// Shape-function weights of the cell's nodes at natural coordinates ξ.
std::vector<double> shape_weights(CellType type, const Vec3& natural);

/// Interpolates a nodal field (`components` values per node, node-major) at an embedding.
std::vector<double> interpolate_nodal(const VolumeMesh& mesh, const NodeEmbedding& where,
                                      const std::vector<double>& field, int components);

/// Landmarks in a tetrahedral mesh: the containing cell, else the nearest cell within
/// `max_distance_mm` with barycentric weights clamped to it (a surface landmark just outside a
/// smooth mesh); farther points are an Error naming the landmark and `what`.
std::vector<NodeEmbedding> embed_landmarks(const VolumeMesh& mesh, const LandmarkSet& points, double max_distance_mm, const std::string& what);
/// The landmarks moved by the nodal displacement u (mm, 3 per node) at their embeddings.
LandmarkSet displace_landmarks(const VolumeMesh& mesh, const std::vector<NodeEmbedding>& where, const LandmarkSet& rest, const std::vector<double>& u);

} // namespace physreg
