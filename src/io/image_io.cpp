// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/image_io.hpp"

#include "detail/itk_bridge.hpp"
#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <zlib.h>

namespace physreg {
namespace fs = std::filesystem;
namespace {

ImageGeometry from_plain(const detail::PlainGeometry& p)
{
    ImageGeometry g;
    for (int a = 0; a < 3; ++a) {
        g.size[a] = p.size[a];
        g.origin[a] = p.origin[a];
        g.spacing[a] = p.spacing[a];
        for (int b = 0; b < 3; ++b) g.direction(a, b) = p.direction[3 * a + b];
    }
    return g;
}

detail::PlainGeometry to_plain(const ImageGeometry& g)
{
    detail::PlainGeometry p;
    for (int a = 0; a < 3; ++a) {
        p.size[a] = g.size[a];
        p.origin[a] = g.origin[a];
        p.spacing[a] = g.spacing[a];
        for (int b = 0; b < 3; ++b) p.direction[3 * a + b] = g.direction(a, b);
    }
    return p;
}

void check_size(const ImageGeometry& g, std::size_t values, std::size_t per_voxel, const fs::path& path)
{
    g.validate("image for '" + path.string() + "'");
    if (values != per_voxel * static_cast<std::size_t>(g.voxel_count()))
        fail("image for '{}': {} values for {} voxels", path.string(), values, g.voxel_count());
}

// ITK's NIfTI reader accepts a truncated .nii/.nii.gz and fills the missing voxels with zeros.
// We check that the file holds as many bytes as its header promises.
void verify_nifti_complete(const fs::path& path)
{
    const std::string ext = full_extension(path);
    if (ext != ".nii" && ext != ".nii.gz") return;
    const std::string what = "image '" + path.string() + "'";
    gzFile file = gzopen(path.string().c_str(), "rb"); // reads uncompressed files too
    if (!file) fail("{}: cannot open file", what);
    unsigned char header[540];
    const int got = gzread(file, header, sizeof(header));
    auto get = [&](int offset, int size, bool swap) {
        unsigned char b[8];
        std::memcpy(b, header + offset, size);
        if (swap) std::reverse(b, b + size);
        std::int64_t v = 0;
        if (size == 2) { std::int16_t x; std::memcpy(&x, b, 2); v = x; }
        if (size == 4) { std::int32_t x; std::memcpy(&x, b, 4); v = x; }
        if (size == 8) { std::int64_t x; std::memcpy(&x, b, 8); v = x; }
        return v;
    };
    std::int64_t expected = -1;
    if (got >= 348) {
        for (bool swap : {false, true}) {
            const auto sizeof_hdr = get(0, 4, swap);
            if (sizeof_hdr == 348) {
                std::int64_t voxels = 1;
                const auto dims = get(40, 2, swap);
                for (int d = 1; d <= std::min<std::int64_t>(dims, 7); ++d) voxels *= std::max<std::int64_t>(1, get(40 + 2 * d, 2, swap));
                float offset;
                std::int32_t raw = static_cast<std::int32_t>(get(108, 4, swap));
                std::memcpy(&offset, &raw, 4);
                expected = static_cast<std::int64_t>(offset) + voxels * (get(72, 2, swap) / 8);
            } else if (sizeof_hdr == 540 && got >= 540) {
                std::int64_t voxels = 1;
                const auto dims = get(16, 8, swap);
                for (int d = 1; d <= std::min<std::int64_t>(dims, 7); ++d) voxels *= std::max<std::int64_t>(1, get(16 + 8 * d, 8, swap));
                expected = get(168, 8, swap) + voxels * (get(12, 2, swap) / 8);
            }
            if (expected >= 0) break;
        }
    }
    std::int64_t total = got > 0 ? got : 0;
    std::vector<char> buffer(1 << 20);
    int n;
    while ((n = gzread(file, buffer.data(), static_cast<unsigned>(buffer.size()))) > 0) total += n;
    int error = Z_OK;
    const char* message = gzerror(file, &error);
    const std::string zlib_message = message ? message : "";
    gzclose(file);
    if (n < 0 || (error != Z_OK && error != Z_STREAM_END))
        fail("{}: corrupt or truncated compressed data ({})", what, zlib_message);
    if (expected >= 0 && total < expected)
        fail("{}: truncated: holds {} bytes, its header promises {}", what, total, expected);
}

} // namespace

ImageFileInfo read_image_info(const fs::path& path)
{
    const auto h = detail::itk_read_header(path.string());
    ImageFileInfo info;
    info.geometry = from_plain(h.geometry);
    info.dimensions = h.dimensions;
    info.components = h.components;
    info.component_type = h.component_type;
    info.format = h.format;
    return info;
}

LabelVolume read_label_volume(const fs::path& path)
{
    const ImageFileInfo info = read_image_info(path);
    verify_nifti_complete(path);
    const std::string what = "label volume '" + path.string() + "'";
    if (info.components != 1)
        fail("{}: has {} components per voxel; a label map has one", what, info.components);
    // Read integer types that fit int32 as int32; everything else as double, then check.
    const bool narrow = info.component_type == "char" || info.component_type == "unsigned_char" ||
                        info.component_type == "short" || info.component_type == "unsigned_short" ||
                        info.component_type == "int";
    LabelVolume volume;
    detail::PlainGeometry plain;
    auto convert = [&](const auto& values) {
        volume.geometry = from_plain(plain);
        volume.geometry.validate(what);
        volume.labels.resize(values.size());
        for (std::size_t v = 0; v < values.size(); ++v) {
            const double value = static_cast<double>(values[v]);
            if (!(value >= 0.0 && value <= 65535.0) || value != std::floor(value))
                fail("{}: voxel {} holds {} (labels must be integers in 0..65535)", what, v, value);
            volume.labels[v] = static_cast<std::uint16_t>(value);
        }
    };
    if (narrow) {
        std::vector<std::int32_t> values;
        detail::itk_read(path.string(), plain, values);
        convert(values);
    } else {
        std::vector<double> values;
        detail::itk_read(path.string(), plain, values);
        convert(values);
    }
    return volume;
}

ScalarImage read_scalar_image(const fs::path& path)
{
    const ImageFileInfo info = read_image_info(path);
    verify_nifti_complete(path);
    if (info.components != 1)
        fail("image '{}': has {} components per voxel; expected a scalar image", path.string(), info.components);
    ScalarImage out;
    detail::PlainGeometry plain;
    detail::itk_read(path.string(), plain, out.values);
    out.geometry = from_plain(plain);
    out.geometry.validate("image '" + path.string() + "'");
    return out;
}

DisplacementField read_displacement_field(const fs::path& path)
{
    const ImageFileInfo info = read_image_info(path);
    verify_nifti_complete(path);
    const std::string what = "displacement field '" + path.string() + "'";
    if (info.components != 3) fail("{}: has {} components per voxel; expected 3", what, info.components);
    DisplacementField out;
    detail::PlainGeometry plain;
    detail::itk_read_vectors(path.string(), plain, out.components);
    out.geometry = from_plain(plain);
    out.geometry.validate(what);
    for (std::size_t i = 0; i < out.components.size(); ++i)
        if (!std::isfinite(out.components[i])) fail("{}: voxel {} is not finite", what, i / 3);
    return out;
}

void write_label_volume(const fs::path& path, const LabelVolume& volume)
{
    check_size(volume.geometry, volume.labels.size(), 1, path);
    write_atomically(path, [&](const fs::path& tmp) {
        detail::itk_write(tmp.string(), path.string(), to_plain(volume.geometry), volume.labels.data());
    });
}

void write_scalar_image(const fs::path& path, const ScalarImage& image)
{
    check_size(image.geometry, image.values.size(), 1, path);
    write_atomically(path, [&](const fs::path& tmp) {
        detail::itk_write(tmp.string(), path.string(), to_plain(image.geometry), image.values.data());
    });
}

void write_displacement_field(const fs::path& path, const DisplacementField& field)
{
    check_size(field.geometry, field.components.size(), 3, path);
    for (std::size_t i = 0; i < field.components.size(); ++i)
        if (!std::isfinite(field.components[i]))
            fail("displacement field for '{}': voxel {} is not finite", path.string(), i / 3);
    write_atomically(path, [&](const fs::path& tmp) {
        detail::itk_write_vectors(tmp.string(), path.string(), to_plain(field.geometry), field.components.data());
    });
}

} // namespace physreg
