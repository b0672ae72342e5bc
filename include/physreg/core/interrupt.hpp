// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Ctrl-C and `kill`: the first SIGINT/SIGTERM/SIGHUP only raises a flag (a watcher thread takes
// it); the running command sees it at its next progress update or output commit, throws
// Interrupted, and the staged outputs are removed on the way out, so an interrupted run leaves no
// partial output. A second signal ends the process at once (the default action).
#include "physreg/core/error.hpp"

namespace physreg {

class Interrupted : public Error {
public:
    Interrupted(int signal_number, const std::string& message) : Error(message), m_signal(signal_number) {}
    int signal_number() const { return m_signal; }
private:
    int m_signal;
};

/// Blocks the signals in every thread and starts the watcher thread (the program calls this once,
/// from its main thread, before any other thread starts). Also ignores
/// SIGXFSZ, so that a file-size limit makes writes fail with an error instead of killing the
/// process halfway through a file.
void install_interrupt_handlers();
/// The signal received, or 0.
int interrupt_signal();
/// Throws Interrupted when a signal has arrived; only on the thread that installed the handlers
/// and outside OpenMP parallel regions (an exception must not cross one), a no-op elsewhere.
void throw_if_interrupted();
/// "interrupted by SIGTERM (Terminated); no output was written".
std::string interruption_message(int signal_number);

} // namespace physreg
