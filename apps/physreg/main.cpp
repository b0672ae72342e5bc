// SPDX-License-Identifier: GPL-3.0-or-later
// physreg: the command-line program. Thin: parse, validate, call the library.
#include "app.hpp"

#include "physreg/core/error.hpp"

#include <iostream>

int main(int argc, char** argv)
{
    CLI::App app{"physreg — biomechanical volumetric registration for image-guided surgery.\n"
                 "Coordinates are physical mm in ITK's LPS space."};
    physreg::cli::build_app(app);
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
