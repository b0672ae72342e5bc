// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/png.hpp"

#include "detail/itk_bridge.hpp"
#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"

namespace physreg {

void write_png(const std::filesystem::path& path, const RgbImage& image)
{
    if (image.width <= 0 || image.height <= 0 ||
        image.rgb.size() != 3 * static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height))
        fail("PNG '{}': image of {}×{} pixels with {} bytes", path.string(), image.width, image.height, image.rgb.size());
    write_atomically(path, [&](const std::filesystem::path& tmp) {
        detail::itk_write_rgb_png(tmp.string(), path.string(), image.width, image.height, image.rgb.data());
    });
}

RgbImage read_png(const std::filesystem::path& path)
{
    RgbImage image;
    detail::itk_read_rgb_png(path.string(), image.width, image.height, image.rgb);
    return image;
}

} // namespace physreg
