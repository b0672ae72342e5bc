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

#include <cstddef>

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

/// Runs `task(i)` for every i in [0, n) on the machine's threads, for tasks whose own work is a
/// parallel solver: whole rounds of one task per thread (each task's parallel regions then run on
/// one thread, being nested), and the tasks left over after the last whole round one after another
/// with the full team each. Three solves on two threads then take ≈ 1.5 single-solve times instead
/// of 2 (measured in the demo's estimation and database builds, issue 31). `task` must not throw:
/// catch inside and report after the call.
template <typename Task>
void for_each_task_packed(std::size_t n, Task&& task)
{
    const std::size_t threads = static_cast<std::size_t>(omp_get_max_threads() > 0 ? omp_get_max_threads() : 1);
    const std::size_t whole = threads > 1 ? n / threads * threads : 0;
    if (whole > 0) {
#pragma omp parallel for num_threads(static_cast<int>(threads)) schedule(dynamic, 1)
        for (std::size_t i = 0; i < whole; ++i) task(i);
    }
    for (std::size_t i = whole; i < n; ++i) task(i);
}

} // namespace physreg
