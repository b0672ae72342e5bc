// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The physreg command line as a library: main() and the Python module build the same CLI11 app,
// so a script gets the commands, validations and messages of the program.
#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace physreg::cli {

/// Adds every subcommand and the global options (--log-level, --quiet) to `app`.
void build_app(CLI::App& app);

/// Runs `physreg args...` in this process. Help/version text goes to stdout; a bad command line
/// throws physreg::Error with CLI11's message; bad input throws what the command throws.
void run_in_process(const std::vector<std::string>& args);

} // namespace physreg::cli
