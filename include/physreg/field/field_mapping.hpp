// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Using a dense displacement field d on a fixed grid (x ↦ x + d(x), ITK's convention for
// resampling): trilinear sampling, point inversion, resampling label maps and images through it.
#include "physreg/image/image_geometry.hpp"

namespace physreg {

/// d(x) by trilinear interpolation; zero outside the field's grid.
Vec3 sample_field(const DisplacementField& field, const Vec3& x);
/// The fixed point y with y + d(y) = target, by the fixed-point iteration y ← target − d(y)
/// (converges where |∇d| < 1); returns false when it did not settle to 1e-4 mm in 100 steps.
bool invert_field_at(const DisplacementField& field, const Vec3& target, Vec3& y);
/// The moving labels seen on the field's grid (nearest voxel at x + d(x); 0 outside the moving image).
LabelVolume resample_labels(const LabelVolume& moving, const DisplacementField& fixed_to_moving);
/// The moving image seen on the field's grid (trilinear at x + d(x); `outside` beyond it).
ScalarImage resample_image(const ScalarImage& moving, const DisplacementField& fixed_to_moving, float outside);
/// A zero field on `geometry`.
DisplacementField zero_field(const ImageGeometry& geometry);

} // namespace physreg
