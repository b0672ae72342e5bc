// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A phantom dataset's states as the registration pipelines take them, with the dataset's
// conventions stated where they become defaults:
// - paper 002: the rest → state segmentation pair (the moving image is the rest state, the fixed
//   one the deformed state); its organs are the structures, its frames hold the posterior face
//   (hold auto), and the initial moduli are the literature values of its material set (the
//   truth's are never read);
// - paper 001: the liver of the rest labels meshed, the state's partial surface as the cloud, its
//   landmarks, surface and mesh as the truth, the phantom's vessel centrelines.
#include "physreg/registration/images/image_registration.hpp"
#include "physreg/registration/surface/partial_surface_registration.hpp"

#include <filesystem>
#include <optional>
#include <string>

namespace physreg {

/// Throws Error naming the dataset for a missing state or the rest state asked as the fixed one.
ImagePair read_dataset_image_pair(const std::filesystem::path& dataset, const std::string& state);

/// `visible`: the state's partial surface with this percentage seen (default: its only one, else
/// 30 %); `vessels`: centrelines to use instead of the phantom's own (empty: the phantom's). The
/// meshing follows `settings` (cell_size, seed, vessel_scale/radius for `vessels`). Throws Error
/// naming the state and the percentages it has.
PartialSurfaceCase read_dataset_surface_case(const std::filesystem::path& dataset, const std::string& state, std::optional<int> visible,
                                             const PartialSurfaceSettings& settings, const std::string& vessels = "");

} // namespace physreg
