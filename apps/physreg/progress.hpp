// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Progress on long work: a bar with percentage and ETA on a terminal, a log line every 10 %
// otherwise (CI logs, pipes); nothing for work that ends within a second.
#include <chrono>
#include <functional>
#include <string>

namespace physreg::cli {

/// Where progress goes instead of the terminal (the Python module's callbacks): label, fraction
/// in [0, 1], message. Called only on the thread that installed it.
using ProgressSink = std::function<void(const std::string& label, double fraction, const std::string& message)>;
void set_progress_sink(ProgressSink sink); ///< empty: back to the terminal
/// --quiet: no bar and no progress lines (errors and warnings still go to stderr).
void set_progress_quiet(bool quiet);

class ProgressDisplay {
public:
    explicit ProgressDisplay(std::string label);
    ~ProgressDisplay();
    void update(double fraction, const std::string& message);
    void finish();

private:
    double elapsed_since_start() const;
    std::string m_label;
    bool m_terminal;
    bool m_finished = false;
    bool m_drawn = false; ///< something was shown (work past its first second)
    int m_last_decile = -1;
    std::chrono::steady_clock::time_point m_start, m_last_draw;
};

} // namespace physreg::cli
