// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Orthogonal slices of an image with tissue contours and landmarks overlaid (true: green crosses,
// predicted: red circles joined to their true position), so a person can check a state at a glance.
#include "physreg/core/landmark.hpp"
#include "physreg/figures/canvas.hpp"
#include "physreg/image/image_geometry.hpp"
#include "physreg/model/label_roles.hpp"

#include <string>

namespace physreg {

struct SliceFigureOptions {
    Vec3 centre = Vec3::Zero();     ///< mm, LPS: the three planes pass through it
    double pixels_per_mm = 2.0;
    double landmark_slab_mm = 8.0;  ///< landmarks within this distance of a plane are drawn on it
    std::string title;
    /// Optional scalar map on the intensity's grid (e.g. a displacement difference, mm), drawn in
    /// colour (dark blue → red → yellow, 0 … heat_max) where finite, with a colour bar; NaN voxels
    /// show the grey intensity.
    const ScalarImage* heat = nullptr;
    double heat_max = 1.0;
    std::string heat_label = "MM";
};

/// Three panels: axial (z = const; x right, anterior up), coronal (y = const; x right, superior
/// up), sagittal (x = const; anterior left, superior up). Intensities in grey (0 … 99.5th
/// percentile), contours coloured by role: body orange, liver magenta, lesion red, vessel cyan,
/// bone yellow, kidney green. `predicted` may be empty; else matched to `truth` by name.
Canvas render_orthogonal_slices(const ScalarImage& intensity, const LabelVolume& labels, const LabelRoles& roles,
                                const LandmarkSet& truth, const LandmarkSet& predicted, const SliceFigureOptions& options);

} // namespace physreg
