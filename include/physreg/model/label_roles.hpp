// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Which label values of a segmentation are which organ: what turns any label map into a model's
// tissues, supports and targets. The phantom's convention (labels 1…6) follows the segmented CT of
// the real CIRS 057A phantom in ../shared/data/cirs057a-ct.
#include <cstdint>
#include <set>
#include <string>

namespace physreg {

namespace phantom_label {
constexpr std::uint16_t body = 1, liver = 2, lesion = 3, vessel = 4, bone = 5, kidney = 6;
} // namespace phantom_label

/// Which label values of a label map play which anatomical role. The liver is parenchyma +
/// lesions + vessels; at least one parenchyma label must be present.
struct LabelRoles {
    std::set<std::int32_t> body, liver, lesion, vessel, bone, kidney;
    bool is_liver_tissue(std::int32_t label) const { return liver.count(label) || lesion.count(label) || vessel.count(label); }
    std::string role_of(std::int32_t label) const; ///< "liver", …, or "" for none
    void validate(const std::string& what) const;  ///< a label in two roles, label 0, no liver label
};

/// The phantom's convention (labels 1…6 above).
LabelRoles phantom_label_roles();
/// "liver=2;lesion=3;vessel=4,7" → roles (unnamed roles stay empty); throws Error naming `option`.
LabelRoles parse_label_roles(const std::string& text, const std::string& option);

} // namespace physreg
