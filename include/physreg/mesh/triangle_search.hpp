// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Closest points on a set of triangles (CGAL's AABB tree): paper 001's matching of a point cloud
// to the model's surface, transfer of surface labels, and sampled surface distances (Hausdorff).
#include "physreg/core/types.hpp"

#include <array>
#include <memory>
#include <vector>

namespace physreg {

struct ClosestTriangle {
    std::int32_t triangle = -1;            ///< index into the triangle list given to the search
    Vec3 point = Vec3::Zero();             ///< mm
    std::array<double, 3> weights{};       ///< barycentric weights of `point` on the triangle's corners
    double distance_mm = 0.0;
};

/// The point of triangle (a, b, c) closest to p and its barycentric weights (Ericson's Voronoi
/// region test: exact on edges and corners, no iteration). Degenerate triangles give a point of an edge.
Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, std::array<double, 3>& weights);

class TriangleSearch {
public:
    /// Indexes `triangles` (corner ids into `vertices`), or only those listed in `subset` when it is
    /// given. The arrays are copied: the search stays valid when the caller's vertices move.
    TriangleSearch(const std::vector<Vec3>& vertices, const std::vector<std::array<std::int32_t, 3>>& triangles,
                   const std::vector<std::int32_t>& subset = {});
    ~TriangleSearch();
    TriangleSearch(TriangleSearch&&) noexcept;
    TriangleSearch& operator=(TriangleSearch&&) noexcept;

    bool empty() const;
    std::size_t size() const;
    /// The closest indexed triangle to p (triangle −1 when the search is empty).
    ClosestTriangle closest(const Vec3& p) const;

private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
};

} // namespace physreg
