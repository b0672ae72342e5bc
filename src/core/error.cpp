// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/error.hpp"

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

} // namespace physreg
