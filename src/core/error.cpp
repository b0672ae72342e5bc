// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/error.hpp"

#include <algorithm>

namespace physreg {

std::optional<double> parse_number(const std::string& text)
{
    try {
        std::size_t used = 0;
        const double value = std::stod(text, &used);
        if (used == text.size()) return value;
    } catch (const std::logic_error&) { // invalid_argument, out_of_range
    }
    return std::nullopt;
}

void require_existing_file(const std::filesystem::path& path, const std::string& what)
{
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) fail_missing_file("{}: file does not exist", what);
}

std::vector<double> parse_number_list(const std::string& text, const std::string& name)
{
    std::vector<double> v;
    std::size_t start = 0;
    while (start < text.size()) {
        const std::size_t end = std::min(text.find(',', start), text.size());
        const std::string item = text.substr(start, end - start);
        const auto value = parse_number(item);
        if (!value) fail("{}: '{}' is not a number", name, item);
        v.push_back(*value);
        start = end + 1;
    }
    if (v.empty()) fail("{}: empty list", name);
    return v;
}

} // namespace physreg
