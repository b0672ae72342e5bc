// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/progress_note.hpp"

#include <map>
#include <mutex>

namespace physreg {
namespace {
std::mutex g_mutex;
std::map<std::string, std::string> g_notes;
} // namespace

void post_progress_note(const std::string& key, std::string text) noexcept
{
    try {
        const std::lock_guard<std::mutex> lock(g_mutex);
        if (text.empty())
            g_notes.erase(key);
        else
            g_notes[key] = std::move(text);
    } catch (...) { // a note is a courtesy: out of memory here must not stop a solve
    }
}

void clear_progress_notes() noexcept
{
    const std::lock_guard<std::mutex> lock(g_mutex);
    g_notes.clear();
}

std::string latest_progress_note()
{
    const std::lock_guard<std::mutex> lock(g_mutex);
    std::string text;
    for (const auto& [key, note] : g_notes) text += (text.empty() ? "" : "; ") + key + ": " + note;
    return text;
}

} // namespace physreg
