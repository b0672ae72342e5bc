// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Signed distance maps of label regions (mm; negative inside, positive outside), with the
// trilinear interpolant and its exact gradient at any physical point — the data term of
// segmentation-driven registration (paper 002: d(v + u, S_ref)) and of surface-distance metrics.
//
// ITK's SignedMaurerDistanceMapImageFilter (exact Euclidean distance transform, in mm through the
// image spacing) measures distances to the centres of the region's boundary voxels; the interface
// itself lies half a voxel further out, so half the smallest spacing is subtracted (the zero level
// then sits on the voxel faces, to ≤ half a voxel on oblique interfaces).
#include "physreg/image/image_geometry.hpp"

#include <set>
#include <string>

namespace physreg {

class SignedDistanceMap {
public:
    /// The map of the voxels of `labels` whose label is in `region`. Throws Error naming `what`
    /// for an empty region or a region filling the whole image (no interface).
    SignedDistanceMap(const LabelVolume& labels, const std::set<std::int32_t>& region, const std::string& what);

    /// φ(x) in mm: trilinear inside the image; beyond its edge the edge value plus the distance to
    /// the image box (so that leaving the image is never cheaper than staying).
    double value(const Vec3& x) const;
    /// φ(x) and ∇φ(x) (the exact derivative of the same interpolant, per mm).
    double value_and_gradient(const Vec3& x, Vec3& gradient) const;
    const ImageGeometry& geometry() const { return m_geometry; }
    const std::vector<float>& values() const { return m_values; }

private:
    ImageGeometry m_geometry;
    std::vector<float> m_values;
    Mat3 m_index_to_physical_gradient; ///< D S⁻¹: ∇ₓφ = D S⁻¹ ∇ᵢφ
};

} // namespace physreg
