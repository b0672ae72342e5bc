// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/config_keys.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <cctype>

namespace physreg {
namespace {

/// Levenshtein distance, case-insensitive (keys are short: the O(n·m) table is nothing).
std::size_t edit_distance(std::string_view a, std::string_view b)
{
    std::vector<std::size_t> row(b.size() + 1);
    for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (std::size_t i = 1; i <= a.size(); ++i) {
        std::size_t diagonal = row[0];
        row[0] = i;
        for (std::size_t j = 1; j <= b.size(); ++j) {
            const std::size_t above = row[j];
            const bool same = std::tolower(static_cast<unsigned char>(a[i - 1])) == std::tolower(static_cast<unsigned char>(b[j - 1]));
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (same ? 0 : 1)});
            diagonal = above;
        }
    }
    return row[b.size()];
}

} // namespace

std::string closest_key(std::string_view key, const std::vector<std::string_view>& accepted)
{
    std::string best;
    std::size_t best_distance = std::max<std::size_t>(1, key.size() / 3) + 1;
    for (const auto candidate : accepted) {
        const std::size_t d = edit_distance(key, candidate);
        if (d < best_distance) {
            best_distance = d;
            best = std::string(candidate);
        }
    }
    return best;
}

void require_known_keys(const std::vector<std::string>& keys, const std::vector<std::string_view>& accepted, const std::string& file,
                        const std::string& place)
{
    for (const auto& key : keys) {
        if (std::find(accepted.begin(), accepted.end(), key) != accepted.end()) continue;
        std::string list;
        for (const auto a : accepted) list += (list.empty() ? "" : ", ") + std::string(a);
        const std::string suggestion = closest_key(key, accepted);
        fail("{}: unknown key '{}' in {} (accepted there: {}{})", file, key, place, list,
             suggestion.empty() ? "" : "; did you mean '" + suggestion + "'?");
    }
}

} // namespace physreg
