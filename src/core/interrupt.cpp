// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/interrupt.hpp"

#include <atomic>
#include <csignal>
#include <cstring>
#include <omp.h>
#include <pthread.h>
#include <thread>

namespace physreg {
namespace {

std::atomic<int> g_signal{0};
std::atomic<bool> g_installed{false};
std::thread::id g_main_thread;

} // namespace

// The signals are blocked in every thread and taken by one watcher thread with sigwait(), not by a
// handler: libraries install handlers of their own (METIS/GKlib sets a SIGTERM handler that
// longjmps, and leaves it behind when called from several threads; a SIGTERM then crashed the
// process), and a blocked signal never reaches them.
void install_interrupt_handlers()
{
    g_main_thread = std::this_thread::get_id();
    std::signal(SIGXFSZ, SIG_IGN);
    sigset_t watched;
    sigemptyset(&watched);
    for (int s : {SIGINT, SIGTERM, SIGHUP}) {
        struct sigaction current {};
        sigaction(s, nullptr, &current);
        if (current.sa_handler != SIG_IGN) sigaddset(&watched, s); // ignored by our parent (nohup, `&`): keep it so
    }
    // Before any other thread exists, so that every thread (OpenMP, ITK, MPI) inherits the mask.
    pthread_sigmask(SIG_BLOCK, &watched, nullptr);
    std::thread([watched] {
        for (;;) {
            int s = 0;
            if (sigwait(&watched, &s) != 0) continue;
            if (g_signal.exchange(s) != 0) {
                // A second signal: end the process now, as the signal's default action would.
                std::signal(s, SIG_DFL);
                sigset_t one;
                sigemptyset(&one);
                sigaddset(&one, s);
                pthread_sigmask(SIG_UNBLOCK, &one, nullptr);
                raise(s);
            }
        }
    }).detach();
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
    throw Interrupted(s, interruption_message(s));
}

std::string interruption_message(int signal_number)
{
    const char* name = sigabbrev_np(signal_number);
    return fmt::format("interrupted by {} ({}); no output was written", name ? std::string("SIG") + name : "a signal", strsignal(signal_number));
}

} // namespace physreg
