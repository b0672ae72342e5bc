// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Shared by the fuzz targets: physreg's readers take paths, so each input is written to a file with
// the extension under test first. Bad input must end in physreg::Error; anything else (another
// exception, a crash, a sanitizer report, a violated invariant) is a finding.
#include "physreg/core/error.hpp"

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

namespace physreg::fuzz {

/// One scratch directory per process (libFuzzer's -jobs/-workers run several processes).
inline const std::filesystem::path& scratch_directory()
{
    static const std::filesystem::path directory = [] {
        auto dir = std::filesystem::temp_directory_path() / ("physreg-fuzz-" + std::to_string(::getpid()));
        std::filesystem::create_directories(dir);
        return dir;
    }();
    return directory;
}

/// Writes `size` bytes to scratch/input<extension> and returns the path.
inline std::filesystem::path write_input(const std::uint8_t* data, std::size_t size, const std::string& extension)
{
    const auto path = scratch_directory() / ("input" + extension);
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    out.close();
    if (!out) {
        std::fprintf(stderr, "fuzz: cannot write %s\n", path.c_str());
        std::abort();
    }
    return path;
}

/// Runs `read`; a physreg::Error (a clear refusal) is an accepted outcome, and its message must
/// not be empty.
template <typename Read>
void expect_success_or_error(Read&& read)
{
    try {
        read();
    } catch (const physreg::Error& error) {
        if (std::string(error.what()).empty()) {
            std::fprintf(stderr, "fuzz: physreg::Error with an empty message\n");
            std::abort();
        }
    }
}

/// Aborts (a finding) when an invariant the reader promises does not hold.
inline void check(bool condition, const char* what)
{
    if (!condition) {
        std::fprintf(stderr, "fuzz: invariant violated: %s\n", what);
        std::abort();
    }
}

} // namespace physreg::fuzz
