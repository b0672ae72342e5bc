// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Geometry of a 3-D image as ITK defines it: physical = origin + direction * diag(spacing) * index,
// in mm and LPS. Index (0,0,0) is the centre of the first voxel.
#include "physreg/core/types.hpp"

#include <cstdint>
#include <utility>
#include <vector>

namespace physreg {

struct ImageGeometry {
    Index3 size{0, 0, 0};          ///< voxels per axis
    Vec3 origin = Vec3::Zero();    ///< mm, centre of voxel (0,0,0)
    Vec3 spacing = Vec3::Ones();   ///< mm per voxel along each image axis
    Mat3 direction = Mat3::Identity(); ///< columns: image axes in LPS

    std::int64_t voxel_count() const { return size[0] * size[1] * size[2]; }
    std::int64_t linear_index(std::int64_t i, std::int64_t j, std::int64_t k) const
    {
        return i + size[0] * (j + size[1] * k);
    }
    /// Continuous index (voxel centres at integers) to physical mm.
    Vec3 index_to_physical(const Vec3& continuous_index) const
    {
        return origin + direction * spacing.cwiseProduct(continuous_index);
    }
    Vec3 physical_to_index(const Vec3& point) const;
    double voxel_volume_mm3() const { return spacing.prod(); }
    /// Throws Error naming `what` if spacing is not positive/finite or direction not orthonormal.
    void validate(const std::string& what) const;
    /// The axis-aligned physical box (mm, LPS) that the voxels cover (their outer faces), as {lo, hi}.
    std::pair<Vec3, Vec3> physical_box() const
    {
        Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
        for (int corner = 0; corner < 8; ++corner) {
            Vec3 index;
            for (int a = 0; a < 3; ++a) index[a] = ((corner >> a) & 1) ? double(size[a]) - 0.5 : -0.5;
            lo = lo.cwiseMin(index_to_physical(index));
            hi = hi.cwiseMax(index_to_physical(index));
        }
        return {lo, hi};
    }
};

/// A label volume: one integer label per voxel, 0 = background. Labels fit 16 bits.
struct LabelVolume {
    ImageGeometry geometry;
    std::vector<std::uint16_t> labels; ///< x fastest, then y, then z

    std::uint16_t at(std::int64_t i, std::int64_t j, std::int64_t k) const
    {
        return labels[static_cast<std::size_t>(geometry.linear_index(i, j, k))];
    }
};

/// A scalar image (intensities) with the same layout.
struct ScalarImage {
    ImageGeometry geometry;
    std::vector<float> values;
};

/// A dense displacement field u(x) in mm (LPS), sampled on an image grid; a point x of the
/// field's space maps to x + u(x), as an ITK DisplacementFieldTransform does.
struct DisplacementField {
    ImageGeometry geometry;
    std::vector<float> components; ///< 3 per voxel, interleaved (ux, uy, uz)
};

} // namespace physreg
