// SPDX-License-Identifier: GPL-3.0-or-later
// Landmark readers: CSV, Slicer FCSV and Slicer markups JSON (.mrk.json). The first byte picks one.
#include "fuzz_support.hpp"
#include "physreg/io/landmarks_io.hpp"

#include <cmath>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    if (size < 1) return 0;
    static const char* const extensions[] = {".csv", ".fcsv", ".mrk.json", ".csv"};
    const auto path = physreg::fuzz::write_input(data + 1, size - 1, extensions[data[0] & 3]);
    physreg::fuzz::expect_success_or_error([&] {
        const physreg::LandmarkSet landmarks = physreg::read_landmarks(path);
        for (const auto& landmark : landmarks)
            physreg::fuzz::check(landmark.position.allFinite(), "finite landmark positions");
    });
    return 0;
}
