// SPDX-License-Identifier: GPL-3.0-or-later
// Dice and boundary distances of warped segmentations.
#include "physreg/evaluation/segmentation_overlap.hpp"

#include "physreg/core/error.hpp"
#include "physreg/image/distance_map.hpp"

#include <cmath>
#include <limits>
#include <optional>

namespace physreg {
namespace {

bool same_grid(const ImageGeometry& a, const ImageGeometry& b)
{
    return a.size == b.size && (a.origin - b.origin).norm() < 1e-6 && (a.spacing - b.spacing).norm() < 1e-9 &&
           (a.direction - b.direction).norm() < 1e-9;
}

/// Boundary-voxel distances of `own` measured against `other` (maps of the same structure).
void boundary_distances(const LabelVolume& v, std::int32_t label, const SignedDistanceMap& own, const SignedDistanceMap& other, double& sum,
                        double& max, std::int64_t& count)
{
    const ImageGeometry& g = v.geometry;
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                if (v.at(i, j, k) != label) continue;
                bool boundary = false;
                const std::int64_t n[6][3] = {{i - 1, j, k}, {i + 1, j, k}, {i, j - 1, k}, {i, j + 1, k}, {i, j, k - 1}, {i, j, k + 1}};
                for (const auto& q : n)
                    if (q[0] < 0 || q[1] < 0 || q[2] < 0 || q[0] >= g.size[0] || q[1] >= g.size[1] || q[2] >= g.size[2] || v.at(q[0], q[1], q[2]) != label)
                        boundary = true;
                if (!boundary) continue;
                const auto index = static_cast<std::size_t>(g.linear_index(i, j, k));
                const double d = std::abs(other.values()[index] - own.values()[index]);
                sum += d;
                max = std::max(max, d);
                ++count;
            }
}

} // namespace

std::vector<StructureOverlap> compare_segmentations(const LabelVolume& reference, const LabelVolume& warped, const std::vector<std::int32_t>& structures)
{
    if (!same_grid(reference.geometry, warped.geometry)) fail("segmentation overlap: the warped and reference label maps are on different grids");
    std::vector<StructureOverlap> out;
    for (const auto label : structures) {
        StructureOverlap s;
        s.label = label;
        std::int64_t both = 0;
        for (std::size_t v = 0; v < reference.labels.size(); ++v) {
            const bool r = reference.labels[v] == label, w = warped.labels[v] == label;
            s.reference_voxels += r;
            s.warped_voxels += w;
            both += r && w;
        }
        s.dice = (s.reference_voxels + s.warped_voxels) ? 2.0 * static_cast<double>(both) / static_cast<double>(s.reference_voxels + s.warped_voxels) : 0.0;
        s.mean_surface_mm = s.max_surface_mm = std::numeric_limits<double>::quiet_NaN();
        const auto voxels = static_cast<std::int64_t>(reference.labels.size());
        if (s.reference_voxels > 0 && s.warped_voxels > 0 && s.reference_voxels < voxels && s.warped_voxels < voxels) {
            const SignedDistanceMap ref(reference, {label}, "reference label " + std::to_string(label));
            const SignedDistanceMap war(warped, {label}, "warped label " + std::to_string(label));
            double sum = 0.0, max = 0.0;
            std::int64_t count = 0;
            boundary_distances(warped, label, war, ref, sum, max, count);
            boundary_distances(reference, label, ref, war, sum, max, count);
            s.mean_surface_mm = count ? sum / static_cast<double>(count) : 0.0;
            s.max_surface_mm = max;
        }
        out.push_back(s);
    }
    return out;
}

} // namespace physreg
