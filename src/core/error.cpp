// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/error.hpp"

namespace physreg {

void require_existing_file(const std::filesystem::path& path, const std::string& what)
{
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) fail_missing_file("{}: file does not exist", what);
}

} // namespace physreg
