// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/model/label_roles.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <sstream>

namespace physreg {

std::string LabelRoles::role_of(std::int32_t label) const
{
    if (liver.count(label)) return "liver";
    if (lesion.count(label)) return "lesion";
    if (vessel.count(label)) return "vessel";
    if (body.count(label)) return "body";
    if (bone.count(label)) return "bone";
    if (kidney.count(label)) return "kidney";
    return "";
}

void LabelRoles::validate(const std::string& what) const
{
    if (liver.empty()) fail("{}: no liver (parenchyma) label given", what);
    std::set<std::int32_t> seen;
    for (const auto* set : {&body, &liver, &lesion, &vessel, &bone, &kidney})
        for (const auto label : *set) {
            if (label <= 0 || label > 65535) fail("{}: label {} is not a tissue label (1 … 65535)", what, label);
            if (!seen.insert(label).second) fail("{}: label {} is given two roles", what, label);
        }
}

LabelRoles phantom_label_roles()
{
    LabelRoles r;
    r.body = {phantom_label::body};
    r.liver = {phantom_label::liver};
    r.lesion = {phantom_label::lesion};
    r.vessel = {phantom_label::vessel};
    r.bone = {phantom_label::bone};
    r.kidney = {phantom_label::kidney};
    return r;
}

LabelRoles parse_label_roles(const std::string& text, const std::string& option)
{
    LabelRoles roles;
    std::stringstream parts(text);
    std::string part;
    while (std::getline(parts, part, ';')) {
        if (part.empty()) continue;
        const auto eq = part.find('=');
        if (eq == std::string::npos) fail("{}: '{}' is not ROLE=LABEL[,LABEL…]", option, part);
        const std::string role = part.substr(0, eq);
        std::set<std::int32_t>* target = role == "body" ? &roles.body : role == "liver" ? &roles.liver
                                       : role == "lesion" ? &roles.lesion : role == "vessel" ? &roles.vessel
                                       : role == "bone" ? &roles.bone : role == "kidney" ? &roles.kidney : nullptr;
        if (!target) fail("{}: unknown role '{}' (body, liver, lesion, vessel, bone, kidney)", option, role);
        std::stringstream labels(part.substr(eq + 1));
        std::string label;
        while (std::getline(labels, label, ',')) {
            try {
                std::size_t used = 0;
                const long value = std::stol(label, &used);
                if (used != label.size()) throw std::invalid_argument(label);
                target->insert(static_cast<std::int32_t>(value));
            } catch (const std::logic_error&) {
                fail("{}: '{}' is not an integer label", option, label);
            }
        }
    }
    roles.validate(option);
    return roles;
}

} // namespace physreg
