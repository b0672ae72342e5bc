// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Strict configuration files: a key that is misspelt or misplaced is an error naming the key, the
// file and place, the keys accepted there, and the nearest accepted key ("did you mean").
#include <string>
#include <string_view>
#include <vector>

namespace physreg {

/// The accepted key closest to `key` by edit distance (case-insensitive), if it is close enough
/// to be a plausible typo (at most a third of the key's length, at least 1); else "".
std::string closest_key(std::string_view key, const std::vector<std::string_view>& accepted);

/// Throws Error "<file>: unknown key '<key>' in <place> (accepted there: a, b, c; did you mean
/// 'b'?)" for the first key of `keys` that `accepted` lacks.
void require_known_keys(const std::vector<std::string>& keys, const std::vector<std::string_view>& accepted, const std::string& file,
                        const std::string& place);

} // namespace physreg
