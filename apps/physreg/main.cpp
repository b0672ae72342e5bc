// physreg: the command-line program. Thin: parse, validate, call the library.
#include "cli_support.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/version.hpp"

#include <iostream>

int main(int argc, char** argv)
{
    CLI::App app{"physreg — biomechanical volumetric registration for image-guided surgery.\n"
                 "Coordinates are physical mm in ITK's LPS space."};
    app.set_version_flag("--version", std::string("physreg ") + physreg::VERSION);
    std::string log_level = "info";
    app.add_option("--log-level", log_level, "trace, debug, info, warn, error or off (logs go to stderr)")
        ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}));
    app.require_subcommand(1);
    physreg::cli::add_subcommand_mesh(app);
    physreg::cli::add_subcommand_coarsen(app);
    physreg::cli::add_subcommand_info(app);
    physreg::cli::add_subcommand_landmarks(app);
    physreg::cli::add_subcommand_convert(app);
    physreg::cli::add_subcommand_simulate(app);
    physreg::cli::add_subcommand_phantom(app);
    physreg::cli::add_subcommand_estimate(app);
    physreg::cli::add_subcommand_register_compression(app);
    physreg::cli::add_subcommand_register_surface(app);
    physreg::cli::add_subcommand_register_images(app);
    physreg::cli::add_subcommand_evaluate(app);
    physreg::cli::add_subcommand_enrich(app);
    physreg::cli::add_subcommand_bench(app);
    physreg::cli::add_subcommand_demo(app);
    app.parse_complete_callback([&] { physreg::logger()->set_level(spdlog::level::from_str(log_level)); });
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    } catch (const physreg::Error& e) {
        std::cerr << "physreg: error: " << e.what() << std::endl;
        return 1;
    } catch (const std::exception& e) {
        std::cerr << "physreg: internal error: " << e.what() << std::endl;
        return 2;
    }
    return 0;
}
