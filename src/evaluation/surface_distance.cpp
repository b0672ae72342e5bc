// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/evaluation/surface_distance.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/triangle_search.hpp"

namespace physreg {

SurfaceDistance points_to_surface(const std::vector<Vec3>& points, const SurfaceMesh& surface, const std::string& what)
{
    const TriangleSearch search(surface.vertices, surface.triangles);
    if (search.empty()) fail("{}: the surface has no (non-degenerate) triangle", what);
    SurfaceDistance d;
    d.samples = points.size();
    for (const auto& p : points) {
        const double distance = search.closest(p).distance_mm;
        d.mean_mm += distance;
        d.max_mm = std::max(d.max_mm, distance);
    }
    if (!points.empty()) d.mean_mm /= static_cast<double>(points.size());
    return d;
}

std::vector<Vec3> surface_samples(const SurfaceMesh& surface)
{
    std::vector<Vec3> samples = surface.vertices;
    for (const auto& t : surface.triangles) samples.push_back((surface.vertices[t[0]] + surface.vertices[t[1]] + surface.vertices[t[2]]) / 3.0);
    return samples;
}

HausdorffReport hausdorff_distance(const SurfaceMesh& first, const SurfaceMesh& second, const std::string& what)
{
    HausdorffReport r;
    r.forward = points_to_surface(surface_samples(first), second, what);
    r.backward = points_to_surface(surface_samples(second), first, what);
    return r;
}

} // namespace physreg
