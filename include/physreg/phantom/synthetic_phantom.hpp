// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A built-in synthetic liver label volume, so the main job needs no download: smooth lobed
// parenchyma (label 1) ≈ 184 × 142 × 89 mm, a branching vessel tree (label 2) and four spherical
// tumours (label 3) of 14, 14, 9 and 8 mm diameter. Deterministic.
#include "physreg/core/landmark.hpp"
#include "physreg/image/image_geometry.hpp"

namespace physreg {

struct SyntheticPhantom {
    LabelVolume labels;
    LandmarkSet landmarks; ///< tumour centres, vessel bifurcations and surface points, mm LPS
};

/// `voxel_mm`: isotropic voxel size (mm), 0.5 … 10.
SyntheticPhantom make_synthetic_liver(double voxel_mm = 2.0);

} // namespace physreg
