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

/// Node n's position displaced by u (3 per node, mm; empty: at rest).
inline Vec3 displaced_position(const VolumeMesh& mesh, const std::vector<double>& u, std::int32_t n)
{
    const auto q = static_cast<std::size_t>(n);
    return mesh.nodes[q] + (u.empty() ? Vec3::Zero() : Vec3(u[3 * q], u[3 * q + 1], u[3 * q + 2]));
}

} // namespace physreg
