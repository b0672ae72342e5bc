// SPDX-License-Identifier: GPL-3.0-or-later
// physreg: the command-line program. Thin: parse, validate, call the library.
#include "app.hpp"

#include "physreg/core/blas_kernels.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/openmp_wait.hpp"

#include <filesystem>
#include <iostream>
#include <string>

// Idle OpenMP threads spin briefly, then give the core back (core/openmp_wait.hpp; issue 30 item 5).
PHYSREG_OPENMP_SHORT_SPIN();

int main(int argc, char** argv)
{
    // OpenBLAS's generic kernels on a CPU it does not know: start again with ones the CPU runs
    // (the supernodal factorisations ≈ 3× faster; core/blas_kernels.hpp).
    physreg::restart_with_fast_blas_kernels(argv);
    CLI::App app{"physreg — biomechanical volumetric registration for image-guided surgery.\n"
                 "Coordinates are physical mm in ITK's LPS space."};
    physreg::cli::build_app(app);
    physreg::install_interrupt_handlers();
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    } catch (const physreg::Interrupted& e) {
        std::cerr << "physreg: " << e.what() << std::endl;
        return 128 + e.signal_number(); // the shell's convention for "ended by signal N"
    } catch (const std::filesystem::filesystem_error& e) {
        // Disk full, permission denied, … in a file operation without its own message.
        std::cerr << "physreg: error: " << e.what() << std::endl;
        return 1;
    } catch (const physreg::Error& e) {
        if (const int s = physreg::interrupt_signal(); s != 0) { // the error came from the interruption (a child program stopped by it)
            // An Interrupted rethrown as an Error with context already carries the message: say it once.
            const std::string message = physreg::interruption_message(s), what = e.what();
            std::cerr << "physreg: " << message;
            if (what.find(message) == std::string::npos) std::cerr << " (" << what << ")";
            std::cerr << std::endl;
            return 128 + s;
        }
        std::cerr << "physreg: error: " << e.what() << std::endl;
        return 1;
    } catch (const std::exception& e) {
        std::cerr << "physreg: internal error: " << e.what() << std::endl;
        return 2;
    }
    return 0;
}
