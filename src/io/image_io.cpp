// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/image_io.hpp"

#include "detail/itk_bridge.hpp"
#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"

#include <algorithm>
#include <bit>
#include <cctype>
#include <sstream>
#include <iterator>
#include <fstream>
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

// MetaImage headers are checked before ITK's MetaIO parses them: on malformed headers MetaIO
// overflows a fixed buffer (strcpy of a long field), divides by zero (a file-pattern
// ElementDataFile with step 0) or loops without end (all found by fuzzing). Accepted: lines
// "Key = Value" with a plain key and a value of at most 255 characters, NDims 1-4, DimSize of NDims
// positive integers, a known ElementType, 1-64 channels, and ElementDataFile last: LOCAL or one
// file name (slice lists and file patterns are not supported).
void verify_metaimage(const fs::path& path)
{
    const std::string ext = full_extension(path);
    if (ext != ".mha" && ext != ".mhd") return;
    const std::string what = "image '" + path.string() + "'";
    std::ifstream in(path, std::ios::binary);
    if (!in) fail("{}: cannot open file", what);
    std::string line;
    int number = 0, dimensions = 0;
    std::vector<std::string> sizes;
    bool element_type = false, data_file = false;
    std::size_t read = 0;
    const auto positive_integer = [](const std::string& t) {
        return !t.empty() && t.size() <= 9 && std::all_of(t.begin(), t.end(), [](unsigned char c) { return std::isdigit(c); }) && std::stol(t) > 0;
    };
    while (!data_file && std::getline(in, line)) {
        ++number;
        read += line.size() + 1;
        if (read > 65536) fail("{}: MetaImage header longer than 64 KB (corrupt?)", what);
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.find_first_not_of(" \t") == std::string::npos) continue;
        const auto equals = line.find('=');
        const auto trim = [](std::string t) {
            const auto a = t.find_first_not_of(" \t"), b = t.find_last_not_of(" \t");
            return a == std::string::npos ? std::string() : t.substr(a, b - a + 1);
        };
        const std::string key = equals == std::string::npos ? "" : trim(line.substr(0, equals));
        const std::string value = equals == std::string::npos ? "" : trim(line.substr(equals + 1));
        const bool plain_key = !key.empty() && key.size() <= 64 &&
                               std::all_of(key.begin(), key.end(), [](unsigned char c) { return std::isalnum(c) || c == '_'; });
        if (!plain_key || value.size() > 255 ||
            !std::all_of(value.begin(), value.end(), [](unsigned char c) { return c >= 32 && c < 127; }))
            fail("{}: MetaImage header line {} is not 'Key = Value' (plain key, printable value of at most 255 characters)", what, number);
        std::istringstream words(value);
        std::vector<std::string> tokens{std::istream_iterator<std::string>(words), std::istream_iterator<std::string>()};
        if (key == "NDims") {
            if (tokens.size() != 1 || !positive_integer(tokens[0]) || std::stol(tokens[0]) > 4) fail("{}: MetaImage NDims '{}' (1 to 4)", what, value);
            dimensions = static_cast<int>(std::stol(tokens[0]));
        } else if (key == "DimSize") {
            sizes = tokens;
        } else if (key == "ElementType") {
            static const char* const types[] = {"MET_UCHAR", "MET_CHAR", "MET_USHORT", "MET_SHORT", "MET_UINT", "MET_INT", "MET_ULONG", "MET_LONG",
                                                "MET_ULONG_LONG", "MET_LONG_LONG", "MET_FLOAT", "MET_DOUBLE"};
            element_type = tokens.size() == 1 && std::any_of(std::begin(types), std::end(types), [&](const char* t) { return tokens[0] == t; });
            if (!element_type) fail("{}: MetaImage ElementType '{}' is not a scalar MET_ type", what, value);
        } else if (key == "ElementNumberOfChannels") {
            if (tokens.size() != 1 || !positive_integer(tokens[0]) || std::stol(tokens[0]) > 64)
                fail("{}: MetaImage ElementNumberOfChannels '{}' (1 to 64)", what, value);
        } else if (key == "ElementDataFile") {
            if (tokens.size() != 1 || tokens[0] == "LIST")
                fail("{}: MetaImage ElementDataFile '{}': physreg reads LOCAL data or one data file (no slice lists or file patterns)", what, value);
            data_file = true;
        }
    }
    if (!data_file) fail("{}: MetaImage header without ElementDataFile (truncated?)", what);
    if (dimensions == 0 || sizes.size() != static_cast<std::size_t>(dimensions) ||
        !std::all_of(sizes.begin(), sizes.end(), positive_integer))
        fail("{}: MetaImage header needs NDims and DimSize with NDims positive sizes", what);
    if (!element_type) fail("{}: MetaImage header without ElementType", what);
}

// Checks of a NIfTI file before ITK reads it. The header's geometry (pixdim, quaternion, offsets,
// sform rows) must be finite: ITK's reader aborts the whole process (vnl assert_finite) on NaN or
// Inf there (found by fuzzing). With `whole_file`, also that the file holds as many bytes as its
// header promises: ITK accepts a truncated .nii/.nii.gz and fills the missing voxels with zeros.
void verify_nifti(const fs::path& path, bool whole_file)
{
    const std::string ext = full_extension(path);
    if (ext != ".nii" && ext != ".nii.gz") return;
    const std::string what = "image '" + path.string() + "'";
    gzFile file = gzopen(path.string().c_str(), "rb"); // reads uncompressed files too
    if (!file) fail("{}: cannot open file", what);
    unsigned char header[540];
    const int got = gzread(file, header, sizeof(header));
    // A signed integer of `size` bytes at `offset`, in the host's (little-endian) order or swapped.
    // Assembled byte by byte: GCC 12 took the former memcpy + std::reverse into an 8-byte buffer
    // for a 32-byte write (-Wstringop-overflow, a false positive).
    static_assert(std::endian::native == std::endian::little, "the NIfTI header check assumes a little-endian host");
    auto get = [&](int offset, int size, bool swap) -> std::int64_t {
        std::uint64_t raw = 0;
        for (int i = 0; i < size; ++i)
            raw |= std::uint64_t(header[offset + (swap ? size - 1 - i : i)]) << (8 * i);
        if (size == 2) return static_cast<std::int16_t>(raw);
        if (size == 4) return static_cast<std::int32_t>(raw);
        return static_cast<std::int64_t>(raw);
    };
    // Sizes from a header that may be corrupt: long double, so that a product of seven damaged
    // dimensions or a huge vox_offset cannot overflow (found by fuzzing).
    long double expected = -1;
    if (got >= 348) {
        for (bool swap : {false, true}) {
            const auto sizeof_hdr = get(0, 4, swap);
            if (sizeof_hdr == 348) {
                long double voxels = 1;
                const auto dims = get(40, 2, swap);
                for (int d = 1; d <= std::min<std::int64_t>(dims, 7); ++d) voxels *= std::max<std::int64_t>(1, get(40 + 2 * d, 2, swap));
                float offset;
                std::int32_t raw = static_cast<std::int32_t>(get(108, 4, swap));
                std::memcpy(&offset, &raw, 4);
                if (std::isfinite(offset) && offset >= 0) expected = static_cast<long double>(offset) + voxels * static_cast<long double>(get(72, 2, swap) / 8);
            } else if (sizeof_hdr == 540 && got >= 540) {
                long double voxels = 1;
                const auto dims = get(16, 8, swap);
                for (int d = 1; d <= std::min<std::int64_t>(dims, 7); ++d) voxels *= std::max<std::int64_t>(1, get(16 + 8 * d, 8, swap));
                expected = static_cast<long double>(get(168, 8, swap)) + voxels * static_cast<long double>(get(14, 2, swap) / 8); // vox_offset, bitpix
            }
            if (expected >= 0) break;
        }
    }
    if (got >= 348) {
        for (bool swap : {false, true}) {
            const auto sizeof_hdr = get(0, 4, swap);
            // NIfTI readers take the byte order of the data from dim[0] (valid: 1 to 7), not from
            // sizeof_hdr: check the floats in the order the reader will use.
            bool data_swap = swap;
            if (sizeof_hdr == 348 || (sizeof_hdr == 540 && got >= 540)) {
                const int dim0_offset = sizeof_hdr == 348 ? 40 : 16, dim0_size = sizeof_hdr == 348 ? 2 : 8;
                const auto dim0 = get(dim0_offset, dim0_size, swap), dim0_swapped = get(dim0_offset, dim0_size, !swap);
                if (dim0 >= 1 && dim0 <= 7) data_swap = swap;
                else if (dim0_swapped >= 1 && dim0_swapped <= 7) data_swap = !swap;
                else {
                    gzclose(file);
                    fail("{}: the NIfTI header's dim[0] is {} (must be 1 to 7): corrupt header", what, dim0);
                }
            }
            const auto finite_floats = [&](int offset, int count, int size) {
                for (int k = 0; k < count; ++k) {
                    unsigned char b[8];
                    std::memcpy(b, header + offset + size * k, static_cast<std::size_t>(size));
                    if (data_swap) std::reverse(b, b + size);
                    double v;
                    if (size == 4) {
                        float f;
                        std::memcpy(&f, b, 4);
                        v = f;
                    } else {
                        std::memcpy(&v, b, 8);
                    }
                    if (!std::isfinite(v) || std::abs(v) > 1e10) return false; // mm; beyond that ITK's float maths overflows
                }
                return true;
            };
            bool finite = true;
            std::int64_t qform_code = 0, sform_code = 0;
            if (sizeof_hdr == 348) {
                finite = finite_floats(76, 8, 4) && finite_floats(256, 18, 4); // pixdim; quatern, qoffset, srow
                qform_code = get(252, 2, data_swap);
                sform_code = get(254, 2, data_swap);
            } else if (sizeof_hdr == 540 && got >= 540) {
                finite = finite_floats(104, 8, 8) && finite_floats(352, 18, 8);
                qform_code = get(344, 4, data_swap);
                sform_code = get(348, 4, data_swap);
            } else {
                if (swap) {
                    gzclose(file);
                    fail("{}: not a NIfTI-1/2 header (sizeof_hdr is {}, must be 348 or 540): corrupt file", what, get(0, 4, false));
                }
                continue;
            }
            if (!finite || qform_code < 0 || qform_code > 5 || sform_code < 0 || sform_code > 5) {
                gzclose(file);
                fail("{}: the NIfTI header's geometry is corrupt (pixdim, qform or sform NaN, Inf or beyond 1e10 mm, or a "
                     "qform/sform code outside 0–5)",
                     what);
            }
            break;
        }
    } else if (got >= 0) {
        gzclose(file);
        fail("{}: {} bytes: too short for a NIfTI header of 348 bytes (truncated, or not NIfTI)", what, got);
    }
    if (!whole_file) {
        gzclose(file);
        return;
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
    if (expected >= 0 && static_cast<long double>(total) < expected)
        fail("{}: truncated: holds {} bytes, its header promises {:.0f}", what, total, static_cast<double>(expected));
}

} // namespace

ImageFileInfo read_image_info(const fs::path& path)
{
    if (fs::is_regular_file(path)) { // before ITK sees the header
        verify_nifti(path, false);
        verify_metaimage(path);
    }
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
    verify_nifti(path, true);
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
    verify_nifti(path, true);
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
    verify_nifti(path, true);
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
