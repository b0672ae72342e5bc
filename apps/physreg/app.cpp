// SPDX-License-Identifier: GPL-3.0-or-later
#include "app.hpp"

#include "cli_support.hpp"
#include "progress.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/version.hpp"

#include <iostream>
#include <memory>

namespace physreg::cli {

void build_app(CLI::App& app)
{
    app.set_version_flag("--version", std::string("physreg ") + physreg::VERSION);
    // Global options are taken after the subcommand too (`physreg register-surface … --no-report`):
    // every subcommand made below inherits this and passes what it does not know to its parent.
    app.fallthrough();
    auto log_level = std::make_shared<std::string>("info");
    auto quiet = std::make_shared<bool>(false);
    auto no_report = std::make_shared<bool>(false);
    app.add_option("--log-level", *log_level, "trace, debug, info, warn, error or off (logs go to stderr)")
        ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}));
    app.add_flag("-q,--quiet", *quiet, "No progress bar or progress lines, and only warnings and errors in the log");
    app.add_flag("--no-report", *no_report, "Commands that write an output folder skip report.html (the HTML report drawn with matplotlib)");
    app.require_subcommand(1);
    add_subcommand_mesh(app);
    add_subcommand_coarsen(app);
    add_subcommand_info(app);
    add_subcommand_landmarks(app);
    add_subcommand_convert(app);
    add_subcommand_simulate(app);
    add_subcommand_phantom(app);
    add_subcommand_estimate(app);
    add_subcommand_register_compression(app);
    add_subcommand_register_surface(app);
    add_subcommand_register_images(app);
    add_subcommand_evaluate(app);
    add_subcommand_enrich(app);
    add_subcommand_bench(app);
    add_subcommand_demo(app);
    add_subcommand_settings(app);
    add_subcommand_prepare(app);
    add_subcommand_serve(app);
    add_subcommand_replay(app);
    app.parse_complete_callback([log_level, quiet, no_report] {
        set_html_reports(!*no_report);
        auto level = spdlog::level::from_str(*log_level);
        if (*quiet && level < spdlog::level::warn) level = spdlog::level::warn;
        physreg::logger()->set_level(level);
        set_progress_quiet(*quiet);
    });
}

void run_in_process(const std::vector<std::string>& args)
{
    CLI::App app{"physreg"};
    build_app(app);
    std::vector<std::string> reversed(args.rbegin(), args.rend()); // CLI11 takes the arguments reversed
    try {
        app.parse(reversed);
    } catch (const CLI::CallForHelp&) {
        std::cout << app.help();
    } catch (const CLI::CallForAllHelp&) {
        std::cout << app.help("", CLI::AppFormatMode::All);
    } catch (const CLI::CallForVersion&) {
        std::cout << "physreg " << physreg::VERSION << '\n';
    } catch (const CLI::ParseError& e) {
        throw Error(std::string("command line: ") + e.what());
    }
}

} // namespace physreg::cli
