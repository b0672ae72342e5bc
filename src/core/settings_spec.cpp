// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/settings_spec.hpp"

#include <algorithm>

namespace physreg {

std::string to_string(SettingKind kind)
{
    switch (kind) {
    case SettingKind::real: return "real";
    case SettingKind::integer: return "integer";
    case SettingKind::flag: return "flag";
    case SettingKind::choice: return "choice";
    case SettingKind::labels: return "labels";
    case SettingKind::text: return "text";
    }
    return "?";
}

std::vector<std::int32_t> parse_label_list(const std::string& text, const std::string& name)
{
    std::vector<std::int32_t> out;
    std::size_t start = 0;
    while (start <= text.size()) {
        const std::size_t end = std::min(text.find(',', start), text.size());
        std::string item = text.substr(start, end - start);
        item.erase(0, item.find_first_not_of(" \t"));
        item.erase(item.find_last_not_of(" \t") + 1);
        const auto v = parse_number(item);
        if (!v) fail("{}: '{}' is not a number (a comma-separated list of labels, e.g. 2,3,4)", name, item);
        if (*v != std::floor(*v) || *v <= 0 || *v > 65535) fail("{}: '{}' is not a label (1 … 65535)", name, item);
        out.push_back(static_cast<std::int32_t>(*v));
        start = end + 1;
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

} // namespace physreg
