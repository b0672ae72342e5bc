// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/image/image_geometry.hpp"

#include "physreg/core/error.hpp"

#include <Eigen/LU>
#include <cmath>

namespace physreg {

Vec3 ImageGeometry::physical_to_index(const Vec3& point) const
{
    return (direction.transpose() * (point - origin)).cwiseQuotient(spacing);
}

void ImageGeometry::validate(const std::string& what) const
{
    for (int a = 0; a < 3; ++a) {
        if (size[a] <= 0) fail("{}: image size along axis {} is {} (must be positive)", what, a, size[a]);
        if (!std::isfinite(spacing[a]) || spacing[a] <= 0.0)
            fail("{}: spacing along axis {} is {} mm (must be positive and finite)", what, a, spacing[a]);
        if (!std::isfinite(origin[a])) fail("{}: origin is not finite", what);
    }
    const double orthogonality = (direction.transpose() * direction - Mat3::Identity()).cwiseAbs().maxCoeff();
    if (!std::isfinite(orthogonality) || orthogonality > 1e-4)
        fail("{}: direction matrix is not orthonormal (|DᵀD − I| = {:.3g})", what, orthogonality);
}

} // namespace physreg
