// SPDX-License-Identifier: GPL-3.0-or-later
#include "progress.hpp"

#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/progress_note.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <unistd.h>

namespace physreg::cli {

namespace {
ProgressSink g_sink;
std::thread::id g_sink_thread;
bool g_quiet = false;

double seconds(std::chrono::steady_clock::duration d) { return std::chrono::duration<double>(d).count(); }
} // namespace

void set_progress_sink(ProgressSink sink)
{
    g_sink = std::move(sink);
    g_sink_thread = std::this_thread::get_id();
}

void set_progress_quiet(bool quiet) { g_quiet = quiet; }

double heartbeat_seconds()
{
    if (const char* text = std::getenv("PHYSREG_PROGRESS_HEARTBEAT_S")) {
        char* end = nullptr;
        const double value = std::strtod(text, &end);
        if (end != text && *end == '\0' && value > 0) return value;
    }
    return 25.0;
}

ProgressDisplay::ProgressDisplay(std::string label)
    : m_label(std::move(label)), m_terminal(!g_quiet && !g_sink && isatty(fileno(stderr)) != 0), m_active(!g_quiet && !g_sink),
      m_start(Clock::now()), m_last_draw(m_start), m_last_advance(m_start)
{
    if (m_active) m_heartbeat = std::thread([this] { heartbeat_loop(); });
}

ProgressDisplay::~ProgressDisplay()
{
    {
        const std::lock_guard<std::mutex> lock(m_mutex);
        m_stop = true;
    }
    m_wake.notify_all();
    if (m_heartbeat.joinable()) m_heartbeat.join();
    if (m_terminal && m_drawn && !m_finished) std::fputc('\n', stderr);
}

void ProgressDisplay::heartbeat_loop()
{
    const auto quiet_limit = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(m_terminal ? 1.0 : heartbeat_seconds()));
    std::unique_lock<std::mutex> lock(m_mutex);
    while (!m_stop) {
        m_wake.wait_for(lock, std::chrono::milliseconds(250));
        if (m_stop || m_finished) continue;
        const auto now = Clock::now();
        if (now - m_start < std::chrono::seconds(1) || now - m_last_draw < quiet_limit) continue;
        draw_locked(true);
    }
}

void ProgressDisplay::update(double fraction, const std::string& message)
{
    throw_if_interrupted(); // Ctrl-C / kill: stop here; staged outputs are removed on the way out
    fraction = std::clamp(fraction, 0.0, 1.0);
    if (g_sink) {
        if (std::this_thread::get_id() == g_sink_thread) g_sink(m_label, fraction, message);
        return;
    }
    if (g_quiet) return;
    const std::lock_guard<std::mutex> lock(m_mutex);
    const auto now = Clock::now();
    if (fraction > m_fraction) m_last_advance = now;
    m_fraction = fraction;
    if (message != m_message) clear_progress_notes(); // a new stage: the old stage's notes are stale
    m_message = message;
    // Work that ends within a second shows no progress at all.
    if (!m_drawn && now - m_start < std::chrono::seconds(1)) return;
    if (m_terminal) {
        if (now - m_last_draw < std::chrono::milliseconds(200) && fraction < 1.0) return;
    } else {
        const int decile = static_cast<int>(fraction * 10);
        if (decile == m_last_decile && now - m_last_draw < std::chrono::seconds(10)) return;
        m_last_decile = decile;
    }
    draw_locked(false);
}

void ProgressDisplay::draw_locked(bool heartbeat)
{
    m_drawn = true;
    const auto now = Clock::now();
    m_last_draw = now;
    const double elapsed = seconds(now - m_start);
    // An ETA by extrapolation is shown only when it means something: far enough in, and from a
    // fraction that is still moving (a stage that has gone quiet makes any extrapolation a guess).
    const bool trusted = m_fraction >= 0.15 && elapsed >= 5.0 && m_fraction < 1.0 && seconds(now - m_last_advance) < heartbeat_seconds();
    const std::string eta = trusted ? fmt::format("ETA {:.0f} s", elapsed * (1 - m_fraction) / m_fraction) : std::string("ETA –");
    const std::string note = heartbeat ? latest_progress_note() : std::string();
    const std::string what = note.empty() ? m_message : m_message + " — " + note;
    if (m_terminal) {
        const int width = 30, filled = static_cast<int>(m_fraction * width);
        std::fprintf(stderr, "\r\033[K%s [%s%s] %3.0f%%  %s  (%.0f s, %s)", m_label.c_str(), std::string(filled, '#').c_str(),
                     std::string(width - filled, ' ').c_str(), 100 * m_fraction, what.c_str(), elapsed, eta.c_str());
        std::fflush(stderr);
        return;
    }
    logger()->info("{}: {:3.0f}%  {}  (elapsed {:.1f} s, {})", m_label, 100 * m_fraction, what, elapsed, eta);
}

void ProgressDisplay::finish()
{
    const std::lock_guard<std::mutex> lock(m_mutex);
    if (m_terminal && m_drawn && !m_finished) std::fputc('\n', stderr);
    m_finished = true;
    clear_progress_notes();
}

} // namespace physreg::cli
