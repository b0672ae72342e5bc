// SPDX-License-Identifier: GPL-3.0-or-later
// Dense displacement fields applied to points and images.
#include "physreg/field/field_mapping.hpp"

#include <algorithm>
#include <cmath>

namespace physreg {
namespace {

/// Trilinear weights of a continuous index; false outside the grid (beyond half a voxel clamped).
template <typename Visit>
bool trilinear(const ImageGeometry& g, const Vec3& index, Visit&& visit)
{
    std::int64_t base[3];
    double t[3];
    for (int a = 0; a < 3; ++a) {
        if (!(index[a] >= -0.5 && index[a] <= static_cast<double>(g.size[a]) - 0.5)) return false;
        const double c = std::clamp(index[a], 0.0, static_cast<double>(g.size[a] - 1));
        base[a] = std::min<std::int64_t>(static_cast<std::int64_t>(std::floor(c)), std::max<std::int64_t>(g.size[a] - 2, 0));
        t[a] = std::clamp(c - static_cast<double>(base[a]), 0.0, 1.0);
    }
    for (int corner = 0; corner < 8; ++corner) {
        const int c[3] = {corner & 1, (corner >> 1) & 1, (corner >> 2) & 1};
        double w = 1.0;
        std::int64_t ijk[3];
        for (int a = 0; a < 3; ++a) {
            ijk[a] = std::min<std::int64_t>(base[a] + c[a], g.size[a] - 1);
            w *= c[a] ? t[a] : 1.0 - t[a];
        }
        if (w != 0.0) visit(static_cast<std::size_t>(g.linear_index(ijk[0], ijk[1], ijk[2])), w);
    }
    return true;
}

} // namespace

Vec3 sample_field(const DisplacementField& field, const Vec3& x)
{
    Vec3 d = Vec3::Zero();
    trilinear(field.geometry, field.geometry.physical_to_index(x), [&](std::size_t v, double w) {
        for (int c = 0; c < 3; ++c) d[c] += w * field.components[3 * v + static_cast<std::size_t>(c)];
    });
    return d;
}

bool invert_field_at(const DisplacementField& field, const Vec3& target, Vec3& y)
{
    y = target;
    for (int k = 0; k < 100; ++k) {
        const Vec3 next = target - sample_field(field, y);
        const double change = (next - y).norm();
        y = next;
        if (change < 1e-4) return true;
    }
    return false;
}

namespace {
// Calls visit(v, p) for every voxel v of the field's grid with p = x_v + u(x_v), in parallel.
template <typename Visit>
void for_each_mapped_voxel(const DisplacementField& field, Visit&& visit)
{
    const ImageGeometry& g = field.geometry;
#pragma omp parallel for schedule(static)
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const auto v = static_cast<std::size_t>(g.linear_index(i, j, k));
                const Vec3 x = g.index_to_physical(Vec3(i, j, k));
                visit(v, Vec3(x + Vec3(field.components[3 * v], field.components[3 * v + 1], field.components[3 * v + 2])));
            }
}
} // namespace

LabelVolume resample_labels(const LabelVolume& moving, const DisplacementField& field)
{
    LabelVolume out;
    out.geometry = field.geometry;
    out.labels.assign(static_cast<std::size_t>(field.geometry.voxel_count()), 0);
    for_each_mapped_voxel(field, [&](std::size_t v, const Vec3& p) {
        const Vec3 index = moving.geometry.physical_to_index(p);
        std::int64_t n[3];
        bool inside = true;
        for (int a = 0; a < 3; ++a) {
            n[a] = static_cast<std::int64_t>(std::llround(index[a]));
            inside = inside && n[a] >= 0 && n[a] < moving.geometry.size[a];
        }
        if (inside) out.labels[v] = moving.at(n[0], n[1], n[2]);
    });
    return out;
}

ScalarImage resample_image(const ScalarImage& moving, const DisplacementField& field, float outside)
{
    ScalarImage out;
    out.geometry = field.geometry;
    out.values.assign(static_cast<std::size_t>(field.geometry.voxel_count()), outside);
    for_each_mapped_voxel(field, [&](std::size_t v, const Vec3& p) {
        double value = 0.0;
        if (trilinear(moving.geometry, moving.geometry.physical_to_index(p), [&](std::size_t m, double w) { value += w * moving.values[m]; }))
            out.values[v] = static_cast<float>(value);
    });
    return out;
}

DisplacementField zero_field(const ImageGeometry& geometry)
{
    DisplacementField f;
    f.geometry = geometry;
    f.components.assign(3 * static_cast<std::size_t>(geometry.voxel_count()), 0.0f);
    return f;
}

} // namespace physreg
