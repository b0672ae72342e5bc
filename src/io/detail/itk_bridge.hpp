// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The narrow door to ITK. This header (and itk_bridge.cpp) use no Eigen: ITK 5.2 bundles its own
// Eigen 3.3, which must not meet Debian's Eigen 3.4 in one translation unit.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace physreg::detail {

struct PlainGeometry {
    std::array<std::int64_t, 3> size{};
    std::array<double, 3> origin{}, spacing{};
    std::array<double, 9> direction{}; ///< row-major
};

struct PlainHeader {
    PlainGeometry geometry;
    int dimensions = 0;
    int components = 0;
    std::string component_type, format;
};

PlainHeader itk_read_header(const std::string& path);
void itk_read(const std::string& path, PlainGeometry& geometry, std::vector<std::int32_t>& values);
void itk_read(const std::string& path, PlainGeometry& geometry, std::vector<double>& values);
void itk_read(const std::string& path, PlainGeometry& geometry, std::vector<float>& values);
/// 3-component vectors, interleaved.
void itk_read_vectors(const std::string& path, PlainGeometry& geometry, std::vector<float>& values);
void itk_write(const std::string& path, const std::string& final_name, const PlainGeometry& geometry,
               const std::uint16_t* values);
void itk_write(const std::string& path, const std::string& final_name, const PlainGeometry& geometry,
               const float* values);
void itk_write_vectors(const std::string& path, const std::string& final_name, const PlainGeometry& geometry,
                       const float* values);

/// 8-bit RGB PNG, rows top to bottom, 3 bytes per pixel.
void itk_write_rgb_png(const std::string& path, const std::string& final_name, int width, int height,
                       const std::uint8_t* rgb);
void itk_read_rgb_png(const std::string& path, int& width, int& height, std::vector<std::uint8_t>& rgb);

} // namespace physreg::detail
