// SPDX-License-Identifier: GPL-3.0-or-later
// CGAL's AABB tree over triangles (header-only, GPL-3.0-or-later), compiled in the CGAL object library.
#include "physreg/mesh/triangle_search.hpp"

#include "physreg/core/error.hpp"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <cmath>

namespace physreg {

namespace {
using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Triangle = Kernel::Triangle_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, Iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;

Point to_point(const Vec3& v) { return {v[0], v[1], v[2]}; }
} // namespace

Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, std::array<double, 3>& w)
{
    // Ericson, Real-Time Collision Detection, 5.1.5.
    const Vec3 ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) {
        w = {1, 0, 0};
        return a;
    }
    const Vec3 bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) {
        w = {0, 1, 0};
        return b;
    }
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const double t = d1 - d3 != 0 ? d1 / (d1 - d3) : 0.0;
        w = {1 - t, t, 0};
        return a + t * ab;
    }
    const Vec3 cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) {
        w = {0, 0, 1};
        return c;
    }
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        const double t = d2 - d6 != 0 ? d2 / (d2 - d6) : 0.0;
        w = {1 - t, 0, t};
        return a + t * ac;
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
        const double denominator = (d4 - d3) + (d5 - d6);
        const double t = denominator != 0 ? (d4 - d3) / denominator : 0.0;
        w = {0, 1 - t, t};
        return b + t * (c - b);
    }
    const double sum = va + vb + vc;
    if (!(sum > 0)) { // degenerate (zero area) triangle that reached here: fall back to corner a
        w = {1, 0, 0};
        return a;
    }
    const double v = vb / sum, u = vc / sum;
    w = {1 - v - u, v, u};
    return a + v * ab + u * ac;
}

struct TriangleSearch::Impl {
    std::vector<Vec3> vertices;
    std::vector<std::array<std::int32_t, 3>> corners; ///< per indexed triangle
    std::vector<std::int32_t> ids;                    ///< per indexed triangle: its caller index
    std::vector<Triangle> triangles;
    Tree tree;
};

TriangleSearch::TriangleSearch(const std::vector<Vec3>& vertices, const std::vector<std::array<std::int32_t, 3>>& triangles,
                               const std::vector<std::int32_t>& subset)
    : m_impl(std::make_unique<Impl>())
{
    m_impl->vertices = vertices;
    const auto add = [&](std::int32_t t) {
        if (t < 0 || static_cast<std::size_t>(t) >= triangles.size()) fail("triangle search: triangle {} out of range", t);
        const auto& tri = triangles[static_cast<std::size_t>(t)];
        for (auto v : tri)
            if (v < 0 || static_cast<std::size_t>(v) >= vertices.size()) fail("triangle search: triangle {} has vertex {} out of range", t, v);
        const Vec3 &a = vertices[tri[0]], &b = vertices[tri[1]], &c = vertices[tri[2]];
        // Zero-area triangles are left out: their points lie on their neighbours' edges.
        if (!((b - a).cross(c - a).norm() > 0)) return;
        m_impl->corners.push_back(tri);
        m_impl->ids.push_back(t);
        m_impl->triangles.emplace_back(to_point(a), to_point(b), to_point(c));
    };
    if (subset.empty())
        for (std::size_t t = 0; t < triangles.size(); ++t) add(static_cast<std::int32_t>(t));
    else
        for (auto t : subset) add(t);
    if (!m_impl->triangles.empty()) {
        m_impl->tree.insert(m_impl->triangles.cbegin(), m_impl->triangles.cend());
        m_impl->tree.accelerate_distance_queries();
    }
}

TriangleSearch::~TriangleSearch() = default;
TriangleSearch::TriangleSearch(TriangleSearch&&) noexcept = default;
TriangleSearch& TriangleSearch::operator=(TriangleSearch&&) noexcept = default;

bool TriangleSearch::empty() const { return m_impl->triangles.empty(); }
std::size_t TriangleSearch::size() const { return m_impl->triangles.size(); }

ClosestTriangle TriangleSearch::closest(const Vec3& p) const
{
    ClosestTriangle result;
    if (empty()) return result;
    const auto hit = m_impl->tree.closest_point_and_primitive(to_point(p));
    const auto local = static_cast<std::size_t>(hit.second - m_impl->triangles.cbegin());
    const auto& tri = m_impl->corners[local];
    result.triangle = m_impl->ids[local];
    result.point = closest_point_on_triangle(p, m_impl->vertices[tri[0]], m_impl->vertices[tri[1]], m_impl->vertices[tri[2]], result.weights);
    result.distance_mm = (result.point - p).norm();
    return result;
}

} // namespace physreg
