// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Child programs (CalculiX, the Python report) run through here, not std::system(): the program
// blocks SIGINT/SIGTERM/SIGHUP in all its threads for its watcher (core/interrupt.hpp), and a
// child must not inherit that mask, or `kill` and Ctrl-C could not stop it.
#include <string>

namespace physreg {

/// Runs `/bin/sh -c command` and waits for it, like std::system(), and returns the same wait
/// status. The child starts with no signal blocked and the default actions, in a process group of
/// its own; a SIGINT/SIGTERM/SIGHUP that the watcher takes meanwhile is passed on to that group.
/// Throws Error when the shell cannot be started.
int run_shell_command(const std::string& command);

} // namespace physreg
