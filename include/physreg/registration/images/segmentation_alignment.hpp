// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 002's missing first step (issue 28): a rigid alignment of two segmentations whose frames
// differ (pre-operative MR and intra-operative ultrasound, two CT scans), so the mechanics only has
// the non-rigid part to explain. Centroids of the structures, then (mode rigid) Gauss–Newton on
// the fixed structures' signed distance maps: Σ_structures Σ_boundary points φ_s(R x + t)², started
// from the centroid alignment and from the four right-handed matches of the principal axes; the
// start with the lowest final cost wins. Written here rather than with ITK's rigid registration of
// label images because the distance-map cost needs no overlap to start from and gives each
// structure its own term.
#include "physreg/core/types.hpp"
#include "physreg/image/image_geometry.hpp"

#include <string>
#include <vector>

namespace physreg {

enum class InitialAlignment { identity, centroid, rigid };
InitialAlignment parse_initial_alignment(const std::string& text); ///< identity | centroid | rigid
std::string to_string(InitialAlignment mode);

/// x_fixed = rotation · x_moving + translation (mm, LPS).
struct SegmentationAlignment {
    InitialAlignment mode = InitialAlignment::identity;
    Mat3 rotation = Mat3::Identity();
    Vec3 translation = Vec3::Zero();
    double rotation_deg = 0.0;
    double centroid_distance_mm = 0.0;   ///< between the structures' centroids before alignment
    double rms_boundary_distance_mm = 0.0; ///< moving boundary points to the fixed boundaries, after
    double rms_boundary_distance_before_mm = 0.0;
    std::string start;                   ///< the winning start (rigid)
    int iterations = 0;
    Vec3 apply(const Vec3& x) const { return rotation * x + translation; }
};

/// Aligns the `structures` of `moving` to those of `fixed`. Throws Error naming the structure when a
/// structure is empty in either segmentation (nothing to match).
SegmentationAlignment align_segmentations(const LabelVolume& fixed, const LabelVolume& moving, const std::vector<std::int32_t>& structures,
                                          InitialAlignment mode);

class SignedDistanceMap;
/// The rigid motion that brings each structure's `points` (e.g. a model's boundary nodes) nearest
/// the zero level of its fixed distance map (`maps[s]`, nullptr: left out): the same Gauss–Newton,
/// started from the identity. Throws Error when no structure has both a map and points.
SegmentationAlignment align_points_to_maps(const std::vector<const SignedDistanceMap*>& maps, const std::vector<std::vector<Vec3>>& points);

} // namespace physreg
