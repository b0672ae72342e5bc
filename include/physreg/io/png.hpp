// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// 8-bit RGB PNG pictures (through ITK's PNG IO): the figures people look at.
#include <cstdint>
#include <filesystem>
#include <vector>

namespace physreg {

struct RgbImage {
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgb; ///< 3 bytes per pixel, rows top to bottom
};

/// Atomic (temporary file + rename). Throws Error for an empty or inconsistent image.
void write_png(const std::filesystem::path& path, const RgbImage& image);
/// Throws Error naming the file if it is missing or not a readable PNG.
RgbImage read_png(const std::filesystem::path& path);

} // namespace physreg
