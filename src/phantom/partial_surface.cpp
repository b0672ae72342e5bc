// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/phantom/partial_surface.hpp"

#include "physreg/core/error.hpp"
#include "physreg/phantom/abdominal_phantom.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>

namespace physreg {

LabelledPointCloud visible_surface_patch(const VolumeMesh& mesh, const std::vector<double>& displacement_mm,
                                         const BoundarySurface& boundary, double fraction, const Vec3& view,
                                         double noise_mm, std::uint64_t seed)
{
    if (!(fraction > 0.0 && fraction <= 1.0)) fail("visible surface: fraction {} outside (0, 1]", fraction);
    if (!(noise_mm >= 0.0) || !std::isfinite(noise_mm)) fail("visible surface: noise {} mm must be ≥ 0", noise_mm);
    const Vec3 v = view.normalized();
    struct Facing { std::size_t triangle; double area; Vec3 centroid; };
    std::vector<Facing> facing;
    double total = 0.0;
    Vec3 weighted = Vec3::Zero();
    for (std::size_t t = 0; t < boundary.triangles.size(); ++t) {
        const auto& tri = boundary.triangles[t];
        const Vec3 a = displaced_position(mesh, displacement_mm, tri[0]), b = displaced_position(mesh, displacement_mm, tri[1]),
                   c = displaced_position(mesh, displacement_mm, tri[2]);
        const Vec3 cross = (b - a).cross(c - a);
        const double area = 0.5 * cross.norm();
        if (area <= 0.0 || cross.normalized().dot(v) >= -0.2) continue;
        const Vec3 centroid = (a + b + c) / 3.0;
        facing.push_back({t, area, centroid});
        total += area;
        weighted += area * centroid;
    }
    if (facing.empty()) fail("visible surface: no part of the surface faces the camera (view {}, {}, {})", v.x(), v.y(), v.z());
    const Vec3 centre = weighted / total;
    auto planar = [&](const Vec3& p) { const Vec3 d = p - centre; return (d - d.dot(v) * v).squaredNorm(); };
    std::stable_sort(facing.begin(), facing.end(), [&](const Facing& a, const Facing& b) { return planar(a.centroid) < planar(b.centroid); });
    std::vector<std::int32_t> kept;
    double area = 0.0;
    for (const auto& f : facing) {
        if (area >= fraction * total) break;
        area += f.area;
        const auto& tri = boundary.triangles[f.triangle];
        kept.insert(kept.end(), tri.begin(), tri.end());
    }
    std::sort(kept.begin(), kept.end());
    kept.erase(std::unique(kept.begin(), kept.end()), kept.end());
    // Deformed vertex normals for the kept nodes.
    std::vector<Vec3> normal(kept.size(), Vec3::Zero());
    auto kept_slot = [&](std::int32_t n) -> long {
        const auto it = std::lower_bound(kept.begin(), kept.end(), n);
        return it != kept.end() && *it == n ? it - kept.begin() : -1;
    };
    for (const auto& tri : boundary.triangles) {
        const Vec3 a = displaced_position(mesh, displacement_mm, tri[0]), b = displaced_position(mesh, displacement_mm, tri[1]),
                   c = displaced_position(mesh, displacement_mm, tri[2]);
        const Vec3 cross = 0.5 * (b - a).cross(c - a);
        for (const auto n : tri)
            if (const long s = kept_slot(n); s >= 0) normal[static_cast<std::size_t>(s)] += cross;
    }
    LabelledPointCloud cloud;
    SeededRandom random(seed);
    for (std::size_t q = 0; q < kept.size(); ++q) {
        const auto slot = static_cast<std::size_t>(std::lower_bound(boundary.nodes.begin(), boundary.nodes.end(), kept[q]) - boundary.nodes.begin());
        const Vec3 noise(random.normal(), random.normal(), random.normal());
        cloud.points.push_back(displaced_position(mesh, displacement_mm, kept[q]) + noise_mm * noise);
        cloud.normals.push_back(normal[q].normalized());
        cloud.labels.push_back(boundary.node_feature[slot]);
    }
    return cloud;
}

LabelledPointCloud sparse_surface_cloud(const VolumeMesh& mesh, const std::vector<double>& displacement_mm, const BoundarySurface& boundary,
                                        double coverage, int count, const std::function<bool(const Vec3&)>& hidden, double noise_mm,
                                        std::uint64_t seed, double* covered)
{
    if (!(coverage > 0.0 && coverage <= 1.0)) fail("sparse surface cloud: coverage {} outside (0, 1]", coverage);
    if (count < 3) fail("sparse surface cloud: {} points; at least 3 are needed", count);
    if (!(noise_mm >= 0.0) || !std::isfinite(noise_mm)) fail("sparse surface cloud: noise {} mm must be ≥ 0", noise_mm);
    struct Candidate { std::array<Vec3, 3> corners; Vec3 normal; double area; };
    std::vector<Candidate> candidates;
    double total = 0.0;
    for (const auto& tri : boundary.triangles) {
        const std::array<Vec3, 3> x{displaced_position(mesh, displacement_mm, tri[0]), displaced_position(mesh, displacement_mm, tri[1]),
                                    displaced_position(mesh, displacement_mm, tri[2])};
        const Vec3 cross = (x[1] - x[0]).cross(x[2] - x[0]);
        const double area = 0.5 * cross.norm();
        if (!(area > 0.0)) continue;
        total += area;
        if (hidden && hidden((x[0] + x[1] + x[2]) / 3.0)) continue;
        candidates.push_back({x, cross.normalized(), area});
    }
    if (candidates.empty()) fail("sparse surface cloud: the whole surface is hidden");
    // The back goes first: most posterior-facing triangles dropped until `coverage` of the area is left.
    std::stable_sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) { return a.normal.y() < b.normal.y(); });
    double kept_area = 0.0;
    std::size_t kept = 0;
    while (kept < candidates.size() && kept_area + candidates[kept].area <= coverage * total + 1e-9) kept_area += candidates[kept++].area;
    if (kept == 0) fail("sparse surface cloud: coverage {} keeps no triangle", coverage);
    candidates.resize(kept);
    std::vector<double> cumulative(kept);
    double sum = 0.0;
    for (std::size_t t = 0; t < kept; ++t) cumulative[t] = (sum += candidates[t].area);
    SeededRandom random(seed);
    LabelledPointCloud cloud;
    for (int q = 0; q < count; ++q) {
        const double pick = random.uniform() * sum;
        const auto t = static_cast<std::size_t>(std::min<std::ptrdiff_t>(
            std::upper_bound(cumulative.begin(), cumulative.end(), pick) - cumulative.begin(), static_cast<std::ptrdiff_t>(kept) - 1));
        double a = random.uniform(), b = random.uniform();
        if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b; // uniform over the triangle
        const auto& c = candidates[t].corners;
        const Vec3 noise(random.normal(), random.normal(), random.normal());
        cloud.points.push_back(c[0] + a * (c[1] - c[0]) + b * (c[2] - c[0]) + noise_mm * noise);
        cloud.normals.push_back(candidates[t].normal);
        cloud.labels.push_back(feature_none);
    }
    if (covered) *covered = total > 0 ? kept_area / total : 0.0;
    return cloud;
}

} // namespace physreg
