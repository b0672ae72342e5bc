// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The built-in CIRS-057A-like abdominal phantom (paper 000's test object), and what turns any
// label map into an experiment: which labels are which organ, and an MR-like intensity image.
//
// Labels follow the segmented CT of the real phantom in ../shared/data/cirs057a-ct: 0 air,
// 1 body (gel, skin), 2 liver parenchyma, 3 lesions, 4 vessels, 5 bone, 6 kidneys.
// Coordinates are physical mm in LPS: x towards the patient's left, y posterior, z superior; the
// phantom lies supine with its flat base at the posterior side, so tools press along +y.
#include "physreg/image/image_geometry.hpp"
#include "physreg/mechanics/elements/embedded_beams.hpp"
#include "physreg/model/label_roles.hpp"

#include <cstdint>
#include <set>
#include <string>

namespace physreg {

/// Measured facts of the CIRS 057A phantom: body ≈ 270 × 200 mm in cross-section, 130 mm long,
/// on a flat base; liver ≈ 184 × 142 × 89 mm (LR × AP × SI) of three smooth lobes with an
/// umbilical-notch-like cleft; lesions of 14, 14, 9, 8, 5 and 5 mm; a branching vessel tree with
/// radii decreasing from 4.5 to 1.2 mm (longest tube path ≈ 135 mm); spine and two kidneys.
/// Deterministic. `voxel_mm`: isotropic voxel size, 0.5 … 6 mm.
LabelVolume make_cirs057a_phantom(double voxel_mm);
/// The centrelines of its vessel tree (the tubes' axes, radii at both ends), mm, LPS — the
/// pre-operative vessel model paper 001's heterogeneous liver needs.
std::vector<VesselBranch> cirs057a_vessel_centrelines();

/// MR-like (T2-weighted look) intensities: per-role means (vessels dark, lesions bright), a
/// smooth multiplicative bias field (±15 %) and Rician noise (σ = 2 % of the liver's mean), all
/// drawn from `seed`. Arbitrary units.
ScalarImage synthesize_mr_intensity(const LabelVolume& labels, const LabelRoles& roles, std::uint64_t seed);

/// The same without the noise: what the deformed states warp, so that each scan gets noise of its
/// own (a noise pattern carried along with the tissue would hand intensity-based registration
/// landmarks no real pair of scans has).
ScalarImage synthesize_clean_mr_intensity(const LabelVolume& labels, const LabelRoles& roles, std::uint64_t seed);

/// Rician magnitude noise of σ = 2 % of the liver's mean intensity, drawn from `seed`.
void add_mr_noise(ScalarImage& image, std::uint64_t seed);

/// A portable seeded random stream (SplitMix64 + Box–Muller): identical on every platform.
class SeededRandom {
public:
    explicit SeededRandom(std::uint64_t seed) : m_state(seed) {}
    std::uint64_t next();
    double uniform();  ///< [0, 1)
    double normal();   ///< N(0, 1)
private:
    std::uint64_t m_state;
    double m_spare = 0.0;
    bool m_has_spare = false;
};

} // namespace physreg
