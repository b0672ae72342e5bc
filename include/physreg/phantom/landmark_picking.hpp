// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 000's 25 landmarks, picked automatically from a label map so that any segmentation gets
// them: 11 on the liver surface at recognisable points (tips, ridges and a notch, found as
// extreme points of the surface in fixed anatomical directions) and 14 internal ones (on lesion
// boundaries and at vessel bifurcations).
#include "physreg/core/landmark.hpp"
#include "physreg/phantom/abdominal_phantom.hpp"

namespace physreg {

struct LandmarkPickingOptions {
    int surface_count = 11;
    int internal_count = 14;
    double surface_separation_mm = 15.0;  ///< no two surface landmarks closer than this
    double internal_separation_mm = 5.0;
};

/// Surface landmarks sit on a face between a liver voxel and a non-liver voxel (type surface);
/// lesion landmarks on a face between a lesion voxel and a non-lesion one (type tumour, at the
/// lesion's anterior then posterior pole, largest lesions first); bifurcations at the centre of
/// the vessel cross-section where a geodesic front through the vessel splits (type vessel).
/// When the labels hold fewer features, further points along the vessels (type vessel) and then
/// deep parenchyma points (type unspecified) complete the set; names say which kind each is.
/// Throws Error if the volume has no liver voxel.
LandmarkSet pick_landmarks(const LabelVolume& labels, const LabelRoles& roles, const LandmarkPickingOptions& options = {});

/// The x coordinate (mm) of the umbilical-notch-like cleft on the anterior-inferior margin: the
/// deepest local dip of that margin between its two highest points; nullopt when there is none
/// deeper than 2 mm.
std::optional<double> find_margin_notch_x(const LabelVolume& labels, const LabelRoles& roles);

} // namespace physreg
