// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/phantom/synthetic_phantom.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <cmath>

namespace physreg {
namespace {

struct Ellipsoid {
    Vec3 centre, radii;
    double value(const Vec3& p) const { return (p - centre).cwiseQuotient(radii).squaredNorm(); }
};

struct Segment {
    Vec3 a, b;
    double ra, rb; // radius at a and b, mm
    double distance_minus_radius(const Vec3& p) const
    {
        const Vec3 ab = b - a;
        const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
        return (p - (a + t * ab)).norm() - (ra + t * (rb - ra));
    }
};

} // namespace

SyntheticPhantom make_synthetic_liver(double voxel_mm)
{
    if (!(voxel_mm >= 0.5 && voxel_mm <= 10.0)) fail("synthetic phantom: voxel size {} mm outside 0.5 … 10 mm", voxel_mm);
    // Lobes in mm, liver-centred frame (x: patient left, y: posterior, z: superior).
    const Ellipsoid lobes[] = {{{-30, 0, 0}, {62, 62, 42}},    // right lobe
                               {{38, -8, 6}, {54, 42, 28}},    // left lobe
                               {{-5, 18, -18}, {45, 40, 26}}}; // caudate / posterior part
    const Vec3 hilum(-10, 10, -20);
    const Segment vessels[] = {{hilum, {-45, 5, -5}, 4.5, 3.0},  {{-45, 5, -5}, {-75, 0, 10}, 3.0, 2.0},
                               {{-45, 5, -5}, {-50, -25, 15}, 3.0, 2.0}, {hilum, {30, -5, 0}, 4.0, 2.5},
                               {{30, -5, 0}, {65, -10, 8}, 2.5, 1.8},    {{30, -5, 0}, {35, -25, 15}, 2.5, 1.8}};
    const Ellipsoid tumours[] = {{{-55, 20, 10}, Vec3::Constant(7.0)},
                                 {{-20, -30, 15}, Vec3::Constant(7.0)},
                                 {{50, 10, 0}, Vec3::Constant(4.5)},
                                 {{5, 30, -25}, Vec3::Constant(4.0)}};
    auto inside_liver = [&](const Vec3& p) {
        // Smooth union of the lobes (soft minimum of the ellipsoid functions).
        double sum = 0.0;
        for (const auto& e : lobes) sum += std::exp(-6.0 * (e.value(p) - 1.0));
        return sum > 1.0;
    };
    SyntheticPhantom out;
    ImageGeometry& g = out.labels.geometry;
    const Vec3 extent(220, 170, 110);
    for (int a = 0; a < 3; ++a) g.size[a] = static_cast<std::int64_t>(std::ceil(extent[a] / voxel_mm));
    g.spacing = Vec3::Constant(voxel_mm);
    g.origin = -0.5 * Vec3(double(g.size[0] - 1), double(g.size[1] - 1), double(g.size[2] - 1)) * voxel_mm;
    out.labels.labels.assign(static_cast<std::size_t>(g.voxel_count()), 0);
#pragma omp parallel for schedule(static)
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const Vec3 p = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                if (!inside_liver(p)) continue;
                std::uint16_t label = 1;
                for (const auto& s : vessels)
                    if (s.distance_minus_radius(p) <= 0) label = 2;
                for (const auto& t : tumours)
                    if (t.value(p) <= 1.0) label = 3;
                out.labels.labels[static_cast<std::size_t>(g.linear_index(i, j, k))] = label;
            }
    int n = 0;
    for (const auto& t : tumours) out.landmarks.push_back({"tumour_" + std::to_string(++n), t.centre, LandmarkType::tumour});
    out.landmarks.push_back({"bifurcation_right", {-45, 5, -5}, LandmarkType::vessel});
    out.landmarks.push_back({"bifurcation_left", {30, -5, 0}, LandmarkType::vessel});
    // Surface points: walk from the centre of each lobe outwards until the liver ends.
    const Vec3 directions[] = {{-1, 0, 0}, {1, 0, 0}, {0, 0, 1}, {0, -1, 0}, {0, 0, -1}};
    const char* names[] = {"right_tip", "left_tip", "dome", "anterior_margin", "inferior_edge"};
    for (int d = 0; d < 5; ++d) {
        const Vec3 start = d == 1 ? lobes[1].centre : lobes[0].centre;
        double t = 0;
        while (inside_liver(start + (t + 0.1) * directions[d])) t += 0.1;
        out.landmarks.push_back({names[d], start + (t - 0.5 * voxel_mm) * directions[d], LandmarkType::surface});
    }
    return out;
}

} // namespace physreg
