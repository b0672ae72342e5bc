// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Where the phantom's tools press: the default compressions (entry points over the liver that reach
// it without bone under the patch), the large local push, and a tool from a compression's path.
#include "phantom_states.hpp"

#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

namespace physreg::detail {

/// The label of the voxel nearest to `x`, or nothing outside the image.
std::optional<std::uint16_t> label_at(const LabelVolume& labels, const Vec3& x);
/// Length (mm) of the segment start + t·d, t ∈ [0, length], inside voxels satisfying `predicate`.
double length_inside(const LabelVolume& labels, const Vec3& start, const Vec3& d, double length,
                     const std::function<bool(std::int32_t)>& predicate);
/// Whether a voxel satisfying `predicate` lies on the segment start + t·d, t ∈ [0, length] (half-voxel steps).
bool line_hits(const LabelVolume& labels, const Vec3& start, const Vec3& d, double length,
               const std::function<bool(std::int32_t)>& predicate);

std::vector<CompressionSpec> default_compressions(const Prepared& p, const PhantomSpec& spec, const Vec3& lo, const Vec3& hi,
                                                  double image_length, bool through_gel);
Indenter make_indenter(const CompressionSpec& c, const Vec3& start, const Vec3& end);
CompressionSpec push_compression(const Prepared& p, const PhantomSpec& spec, const Vec3& lo, const Vec3& hi, double image_length);

} // namespace physreg::detail
