// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/thread_governor.hpp"

#include "physreg/core/log.hpp"

#include <algorithm>
#include <cstdlib>
#include <cstring>

namespace physreg {

ThreadGovernor::ThreadGovernor(int max_threads, double window_s)
    : m_max(max_threads > 0 ? max_threads : omp_get_max_threads()), m_window_s(window_s), m_current(m_max)
{
    const char* setting = std::getenv("PHYSREG_THREAD_GOVERNOR");
    m_enabled = !(setting && std::strcmp(setting, "off") == 0);
}

void ThreadGovernor::record(double seconds)
{
    if (m_max <= 1 || !m_enabled) return;
    m_sum += seconds;
    ++m_units;
    // Trial and calibration windows are a quarter of a normal one: the losing choice costs little.
    if (m_sum >= (m_trial || m_calibrating > 0 ? 0.25 : 1.0) * m_window_s) finish_window();
}

void ThreadGovernor::finish_window()
{
    const int index = m_current == m_max ? 1 : 0;
    m_per_unit[index] = m_sum / static_cast<double>(m_units);
    m_sum = 0.0;
    m_units = 0;
    if (m_calibrating > 0) { // the first two short windows: the full team, then one thread
        if (--m_calibrating > 0) {
            m_current = 1;
            return;
        }
        m_current = m_per_unit[1] <= 1.1 * m_per_unit[0] ? m_max : 1;
        m_windows_until_trial = m_backoff = 2;
        return;
    }
    if (m_trial) {
        m_trial = false;
        const int other = 1 - index;
        // Keep the faster; the full team wins ties within 10 %.
        const bool full_faster = m_per_unit[1] <= 1.1 * m_per_unit[0];
        const int choice = full_faster ? m_max : 1;
        const bool trial_won = choice == m_current;
        if (!trial_won) {
            m_current = other == 1 ? m_max : 1;
            m_backoff = std::min<long>(2 * m_backoff, 64); // the incumbent won again: test it less often
        } else {
            ++m_switches;
            m_backoff = 1;
        }
        m_windows_until_trial = m_backoff;
        logger()->trace("thread governor: {:.3g} ms per unit on 1 thread, {:.3g} ms on {}: {} thread(s), next trial in {} window(s)",
                        1e3 * m_per_unit[0], 1e3 * m_per_unit[1], m_max, m_current, m_windows_until_trial);
        return;
    }
    if (--m_windows_until_trial <= 0) {
        m_trial = true;
        m_current = m_current == m_max ? 1 : m_max;
    }
}

} // namespace physreg
