// SPDX-License-Identifier: GPL-3.0-or-later
// Configuration readers: tissue tables (YAML or JSON) and simulation cases (YAML). The first byte
// picks one. Unknown keys, wrong types and impossible values must all end in physreg::Error.
#include "fuzz_support.hpp"
#include "physreg/mechanics/simulation/simulation.hpp"
#include "physreg/model/tissue_table.hpp"

#include <cmath>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    if (size < 1) return 0;
    const int which = data[0] % 3;
    static const char* const extensions[] = {".yaml", ".json", ".yaml"};
    const auto path = physreg::fuzz::write_input(data + 1, size - 1, extensions[which]);
    physreg::fuzz::expect_success_or_error([&] {
        if (which < 2) {
            const physreg::TissueTable table = physreg::read_tissue_table(path);
            for (const auto& tissue : table.tissues) {
                physreg::fuzz::check(tissue.young_modulus_pa > 0 && std::isfinite(tissue.young_modulus_pa), "E > 0, finite");
                physreg::fuzz::check(tissue.poisson_ratio > -1 && tissue.poisson_ratio < 0.5, "-1 < nu < 0.5");
            }
        } else {
            const physreg::SimulationCase simulation_case = physreg::read_simulation_case(path);
            physreg::fuzz::check(simulation_case.frames >= 1, "frames >= 1");
            physreg::fuzz::check(simulation_case.load_steps >= 1, "load steps >= 1");
        }
    });
    return 0;
}
