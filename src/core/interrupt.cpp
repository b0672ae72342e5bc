// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/interrupt.hpp"

#include <atomic>
#include <csignal>
#include <cstring>
#include <omp.h>
#include <thread>

namespace physreg {
namespace {

volatile std::sig_atomic_t g_signal = 0;
std::atomic<bool> g_installed{false};
std::thread::id g_main_thread;

extern "C" void on_signal(int signal_number)
{
    g_signal = signal_number;
    std::signal(signal_number, SIG_DFL); // a second one ends the process at once
}

} // namespace

void install_interrupt_handlers()
{
    g_main_thread = std::this_thread::get_id();
    for (int s : {SIGINT, SIGTERM, SIGHUP})
        if (std::signal(s, on_signal) == SIG_IGN) std::signal(s, SIG_IGN); // ignored by our parent (nohup, `&`): keep it so
    std::signal(SIGXFSZ, SIG_IGN);
    g_installed = true;
}

int interrupt_signal() { return g_signal; }

void throw_if_interrupted()
{
    const int s = g_signal;
    // Never inside an OpenMP parallel region (progress is reported from some of them, on the master
    // thread): an exception leaving a region terminates the process. The next serial progress
    // update or output commit stops the command instead.
    if (s == 0 || !g_installed || std::this_thread::get_id() != g_main_thread || omp_in_parallel()) return;
    throw Interrupted(s, fmt::format("interrupted by {} ({}); no output was written", sigabbrev_np(s) ? std::string("SIG") + sigabbrev_np(s) : "a signal",
                                     strsignal(s)));
}

} // namespace physreg
