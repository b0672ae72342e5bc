#pragma once
// Progress on long work: a bar with percentage and ETA on a terminal, a log line every 10 %
// otherwise (CI logs, pipes).
#include <chrono>
#include <string>

namespace physreg::cli {

class ProgressDisplay {
public:
    explicit ProgressDisplay(std::string label);
    ~ProgressDisplay();
    void update(double fraction, const std::string& message);
    void finish();

private:
    std::string m_label;
    bool m_terminal;
    bool m_finished = false;
    int m_last_decile = -1;
    std::chrono::steady_clock::time_point m_start, m_last_draw;
};

} // namespace physreg::cli
