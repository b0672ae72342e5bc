// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 002's missing first step (issue 28): a rigid alignment of two segmentations whose frames
// differ (pre-operative MR and intra-operative ultrasound, two CT scans), so the mechanics only has
// the non-rigid part to explain. Centroids of the structures, then (mode rigid) Gauss–Newton on
// the fixed structures' signed distance maps: Σ_structures Σ_boundary points φ_s(R x + t)², started
// from the centroid alignment and from the four right-handed matches of the principal axes. Each
// start's pose is a hypothesis (issue 46): frames of one patient rarely differ by more than a few
// tens of degrees, and a near-symmetric organ (prostate, kidney) fits its half-turned self almost
// as well as itself. So the best pose within `max_plausible_rotation_deg` of the identity wins
// unless a pose farther out fits the boundaries at most half as far and closer by more than a
// voxel of the fixed image (a margin the data resolve); every hypothesis, the runner-up and the
// margin are reported. The translation alone (from the centroids, no rotation) is a hypothesis
// too (issue 57). With a single structure, whose deformed outline can look turned, it is the one
// the winning rotated pose must beat: it must leave at most half the translation's distance, or the
// translation is kept (180°: the best fit alone). Two or more structures resolve the turn by their
// layout: there the rotated pose wins as before. Written here rather than with ITK's rigid registration of
// label images because the distance-map cost needs no overlap to start from and gives each
// structure its own term.
#include "physreg/core/types.hpp"
#include "physreg/image/image_geometry.hpp"

#include <string>
#include <vector>

namespace physreg {

enum class InitialAlignment { identity, centroid, rigid, translation };
InitialAlignment parse_initial_alignment(const std::string& text); ///< identity | centroid | translation | rigid
std::string to_string(InitialAlignment mode);

/// One start's refined pose.
struct AlignmentHypothesis {
    std::string start;                   ///< centroids, principal axes 0 … 3, translation
    double rms_boundary_distance_mm = 0.0;
    double rotation_deg = 0.0;           ///< of the refined pose from the identity
    bool plausible = true;               ///< rotation within max_plausible_rotation_deg
};

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
    std::vector<AlignmentHypothesis> hypotheses; ///< rigid: every start's pose
    std::string decision;                ///< rigid: why the winner won
    std::string runner_up;               ///< rigid: the best other pose (a start ending more than 5° away)
    double runner_up_margin_mm = 0.0;    ///< its RMS boundary distance minus the winner's (< 0: it fits better)
    double runner_up_rotation_deg = 0.0; ///< between the winner and the runner-up
    Vec3 apply(const Vec3& x) const { return rotation * x + translation; }
};

/// Aligns the `structures` of `moving` to those of `fixed`. Throws Error naming the structure when a
/// structure is empty in either segmentation (nothing to match).
/// `max_plausible_rotation_deg`: see above (> 0; 180 trusts the best fit alone).
SegmentationAlignment align_segmentations(const LabelVolume& fixed, const LabelVolume& moving, const std::vector<std::int32_t>& structures,
                                          InitialAlignment mode, double max_plausible_rotation_deg = 60.0);

class SignedDistanceMap;
/// The rigid motion that brings each structure's `points` (e.g. a model's boundary nodes) nearest
/// the zero level of its fixed distance map (`maps[s]`, nullptr: left out): the same Gauss–Newton,
/// started from the identity. Throws Error when no structure has both a map and points.
SegmentationAlignment align_points_to_maps(const std::vector<const SignedDistanceMap*>& maps, const std::vector<std::vector<Vec3>>& points);

} // namespace physreg
