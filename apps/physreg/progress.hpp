// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Progress on long work: a bar with percentage on a terminal, a log line every 10 % otherwise (CI
// logs, pipes); nothing for work that ends within a second. When the work goes quiet (a long solve
// inside one stage), a heartbeat shows what it is doing (physreg::latest_progress_note()) at
// least every `heartbeat_seconds` on a log and every second on a terminal. The ETA is shown only
// once it can be trusted (15 % done and 5 s in, from a fraction that moved within the last
// heartbeat interval); otherwise it is absent, never a guess.
#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

namespace physreg::cli {

/// Where progress goes instead of the terminal (the Python module's callbacks): label, fraction
/// in [0, 1], message. Called only on the thread that installed it.
using ProgressSink = std::function<void(const std::string& label, double fraction, const std::string& message)>;
void set_progress_sink(ProgressSink sink); ///< empty: back to the terminal
/// --quiet: no bar and no progress lines (errors and warnings still go to stderr).
void set_progress_quiet(bool quiet);
/// Longest silence between two progress lines on a log (not a terminal), in seconds: 25 by
/// default (a line at least every 30 s); PHYSREG_PROGRESS_HEARTBEAT_S overrides it (tests).
double heartbeat_seconds();

class ProgressDisplay {
public:
    explicit ProgressDisplay(std::string label);
    ~ProgressDisplay();
    ProgressDisplay(const ProgressDisplay&) = delete;
    ProgressDisplay& operator=(const ProgressDisplay&) = delete;
    void update(double fraction, const std::string& message);
    void finish();

private:
    using Clock = std::chrono::steady_clock;
    void draw_locked(bool heartbeat); ///< m_mutex held
    void heartbeat_loop();
    std::string m_label;
    bool m_terminal;
    bool m_active;                    ///< neither quiet nor a sink: this display draws
    bool m_finished = false;
    bool m_drawn = false;             ///< something was shown (work past its first second)
    int m_last_decile = -1;
    double m_fraction = 0.0;
    std::string m_message;
    Clock::time_point m_start, m_last_draw, m_last_advance;
    std::mutex m_mutex;
    std::condition_variable m_wake;
    bool m_stop = false;
    std::thread m_heartbeat;
};

} // namespace physreg::cli
