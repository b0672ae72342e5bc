// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Chooses the OpenMP team size of a repeated parallel workload by measuring it.
//
// On a machine shared with other processes, a team as large as the core count collapses: threads
// wait for a descheduled partner at every barrier (bench_tled fell from 40 M to 4.9–12.3 M element-
// steps/s beside a competing load), while one thread keeps its speed. The governor times the work
// with the full team and with one thread and keeps the faster. It re-tests the other choice in
// short trial windows, backing off exponentially while the choice keeps winning, so a wrong trial
// costs a few per cent at most and a change of load is noticed within a few hundred windows.
// PHYSREG_THREAD_GOVERNOR=off in the environment keeps the full team (for scaling measurements).
#include <omp.h>

namespace physreg {

class ThreadGovernor {
public:
    /// `max_threads` ≤ 0: omp_get_max_threads(). `window_s`: the measured time of one decision.
    explicit ThreadGovernor(int max_threads = 0, double window_s = 0.02);
    /// The team size to use for the next unit of work.
    int threads() const { return m_current; }
    /// Reports the wall time of a unit of work just run with threads() threads.
    void record(double seconds);
    /// Time per unit with one thread and with the full team (0: not measured yet).
    double seconds_per_unit(bool full_team) const { return m_per_unit[full_team ? 1 : 0]; }
    int max_threads() const { return m_max; }
    long switches() const { return m_switches; }

private:
    void finish_window();
    int m_max;
    bool m_enabled = true;
    double m_window_s;
    int m_current;
    bool m_trial = false;        ///< the current window measures the other choice
    int m_calibrating = 2;       ///< first windows: measure both choices before deciding
    double m_sum = 0.0;          ///< seconds in the current window
    long m_units = 0;            ///< units in the current window
    double m_per_unit[2] = {0.0, 0.0};
    long m_windows_until_trial = 1;
    long m_backoff = 1;
    long m_switches = 0;
};

/// Runs `work()` as one unit under the governor: `work` receives the team size to use.
template <typename Work>
void governed(ThreadGovernor& governor, Work&& work)
{
    const double start = omp_get_wtime();
    work(governor.threads());
    governor.record(omp_get_wtime() - start);
}

} // namespace physreg
