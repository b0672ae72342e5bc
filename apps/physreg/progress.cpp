// SPDX-License-Identifier: GPL-3.0-or-later
#include "progress.hpp"

#include "physreg/core/interrupt.hpp"

#include "physreg/core/log.hpp"

#include <algorithm>
#include <cstdio>
#include <thread>
#include <unistd.h>

namespace physreg::cli {

namespace {
ProgressSink g_sink;
std::thread::id g_sink_thread;
bool g_quiet = false;
} // namespace

void set_progress_sink(ProgressSink sink)
{
    g_sink = std::move(sink);
    g_sink_thread = std::this_thread::get_id();
}

void set_progress_quiet(bool quiet) { g_quiet = quiet; }

ProgressDisplay::ProgressDisplay(std::string label)
    : m_label(std::move(label)), m_terminal(!g_quiet && !g_sink && isatty(fileno(stderr)) != 0), m_start(std::chrono::steady_clock::now()), m_last_draw(m_start)
{
}

ProgressDisplay::~ProgressDisplay()
{
    if (m_terminal && m_drawn && !m_finished) std::fputc('\n', stderr);
}

double ProgressDisplay::elapsed_since_start() const
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count();
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
    // Work that ends within a second shows no progress at all.
    if (!m_drawn && elapsed_since_start() < 1.0) return;
    m_drawn = true;
    const auto now = std::chrono::steady_clock::now();
    const double elapsed = std::chrono::duration<double>(now - m_start).count();
    const double eta = fraction > 0 ? elapsed * (1 - fraction) / fraction : 0.0;
    if (m_terminal) {
        if (now - m_last_draw < std::chrono::milliseconds(200) && fraction < 1.0) return;
        m_last_draw = now;
        const int width = 30, filled = static_cast<int>(fraction * width);
        std::fprintf(stderr, "\r%s [%s%s] %3.0f%%  %s  ETA %.0f s   ", m_label.c_str(), std::string(filled, '#').c_str(),
                     std::string(width - filled, ' ').c_str(), 100 * fraction, message.c_str(), eta);
        std::fflush(stderr);
        return;
    }
    const int decile = static_cast<int>(fraction * 10);
    if (decile == m_last_decile && now - m_last_draw < std::chrono::seconds(10)) return;
    m_last_decile = decile;
    m_last_draw = now;
    logger()->info("{}: {:3.0f}%  {}  (elapsed {:.1f} s, ETA {:.0f} s)", m_label, 100 * fraction, message, elapsed, eta);
}

void ProgressDisplay::finish()
{
    if (m_terminal && m_drawn && !m_finished) std::fputc('\n', stderr);
    m_finished = true;
}

} // namespace physreg::cli
