// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The centroid and principal axes of a point set: the starting poses both rigid alignments try
// (partial-surface ICP and segmentation alignment).
#include "physreg/core/types.hpp"

#include <Eigen/Eigenvalues>
#include <vector>

namespace physreg::detail {

struct PrincipalFrame {
    Vec3 centre = Vec3::Zero();
    Mat3 axes = Mat3::Identity(); ///< columns: principal directions, largest spread first, right-handed
};

inline PrincipalFrame principal_frame(const std::vector<Vec3>& points)
{
    PrincipalFrame f;
    for (const auto& p : points) f.centre += p / static_cast<double>(points.size());
    Mat3 c = Mat3::Zero();
    for (const auto& p : points) c += (p - f.centre) * (p - f.centre).transpose();
    Eigen::SelfAdjointEigenSolver<Mat3> eigen(c);
    for (int k = 0; k < 3; ++k) f.axes.col(k) = eigen.eigenvectors().col(2 - k);
    if (f.axes.determinant() < 0) f.axes.col(2) *= -1.0;
    return f;
}

/// The four right-handed sign choices of matching one frame's axes to another's.
inline Mat3 axis_flip(int signs)
{
    Mat3 flip = Mat3::Identity();
    if (signs & 1) flip(0, 0) = -1, flip(2, 2) *= -1;
    if (signs & 2) flip(1, 1) = -1, flip(2, 2) *= -1;
    return flip;
}

} // namespace physreg::detail
