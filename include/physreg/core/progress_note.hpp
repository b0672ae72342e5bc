// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// What long work is doing right now, for progress displays: short lines such as "compression B:
// load step 2/3, Newton iteration 5" that any thread may post (solvers inside parallel regions
// included, where no progress callback may run), one per key, and that the display shows when it
// has had nothing new to show for a while. Thread-safe; posting never throws.
#include <string>

namespace physreg {

/// Sets the note under `key` ("compression B"); an empty text removes it.
void post_progress_note(const std::string& key, std::string text) noexcept;
/// Removes every note (a new stage begins).
void clear_progress_notes() noexcept;
/// The notes in key order, "key: text; key: text", or "".
std::string latest_progress_note();

} // namespace physreg
