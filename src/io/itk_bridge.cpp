// SPDX-License-Identifier: GPL-3.0-or-later
#include "detail/itk_bridge.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"

#include <itkGDCMImageIO.h>
#include <itkGDCMImageIOFactory.h>
#include <itkGDCMSeriesFileNames.h>
#include <itkImage.h>
#include <itkImageFileReader.h>
#include <itkImageFileWriter.h>
#include <itkImageIOFactory.h>
#include <itkImageSeriesReader.h>
#include <itkMetaImageIO.h>
#include <itkMetaImageIOFactory.h>
#include <itkNiftiImageIO.h>
#include <itkNiftiImageIOFactory.h>
#include <itkNrrdImageIO.h>
#include <itkNrrdImageIOFactory.h>
#include <itkPNGImageIO.h>
#include <itkRGBPixel.h>
#include <itkVector.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>

namespace physreg::detail {
namespace fs = std::filesystem;
namespace {

// The formats physreg promises, registered once (ITK_USE_FILE would do this globally).
void register_image_formats()
{
    static const bool registered = [] {
        itk::NiftiImageIOFactory::RegisterOneFactory();
        itk::NrrdImageIOFactory::RegisterOneFactory();
        itk::MetaImageIOFactory::RegisterOneFactory();
        itk::GDCMImageIOFactory::RegisterOneFactory();
        return true;
    }();
    (void)registered;
}

void require_exists(const std::string& path)
{
    register_image_formats();
    std::error_code ec;
    if (!fs::exists(path, ec)) fail_missing_file("image '{}': file does not exist", path);
}

std::string lower(std::string text)
{
    std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return text;
}

bool ends_with(const std::string& text, const std::string& suffix)
{
    return text.size() >= suffix.size() && text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

/// The reader for a file, chosen by its extension. Letting ITK probe every format instead lets a
/// corrupt .mha be parsed as DICOM, whose reader allocates whatever a damaged length field says
/// (4 GiB for a 150-byte file, found by fuzzing). Unknown extensions (e.g. DICOM files without
/// one) are still probed.
itk::ImageIOBase::Pointer image_io_for(const std::string& path)
{
    const std::string name = lower(fs::path(path).filename().string());
    itk::ImageIOBase::Pointer io;
    std::string format;
    if (ends_with(name, ".nii") || ends_with(name, ".nii.gz") || ends_with(name, ".hdr") || ends_with(name, ".img")) {
        io = itk::NiftiImageIO::New();
        format = "NIfTI";
    } else if (ends_with(name, ".nrrd") || ends_with(name, ".nhdr")) {
        io = itk::NrrdImageIO::New();
        format = "NRRD";
    } else if (ends_with(name, ".mha") || ends_with(name, ".mhd")) {
        io = itk::MetaImageIO::New();
        format = "MetaImage";
    } else {
        io = itk::ImageIOFactory::CreateImageIO(path.c_str(), itk::ImageIOFactory::FileModeEnum::ReadMode);
        if (!io) fail("image '{}': not a readable image (unknown format, corrupt or truncated header)", path);
        return io;
    }
    if (!io->CanReadFile(path.c_str())) fail("image '{}': not a valid {} file (corrupt or truncated header)", path, format);
    return io;
}

/// Refuses a header that declares more pixel data than its file can hold: zlib/gzip compress at
/// most about 1032:1, so a single-file image (NIfTI, NRRD or MetaImage with its data inside)
/// declaring more than 1100 × its file size is corrupt. Checked before ITK allocates the buffer.
void check_declared_size(const std::string& path, const itk::ImageIOBase& io)
{
    const std::string name = lower(fs::path(path).filename().string());
    const bool single_file = ends_with(name, ".nii") || ends_with(name, ".nii.gz") || ends_with(name, ".nrrd") || ends_with(name, ".mha");
    if (!single_file) return;
    if (ends_with(name, ".nrrd") || ends_with(name, ".mha")) {
        // A detached data file ("data file:" in NRRD, ElementDataFile other than LOCAL in MetaImage).
        std::ifstream in(path, std::ios::binary);
        std::string head(4096, '\0');
        in.read(head.data(), static_cast<std::streamsize>(head.size()));
        head.resize(static_cast<std::size_t>(in.gcount()));
        const std::string text = lower(head);
        if (text.find("data file:") != std::string::npos || text.find("datafile:") != std::string::npos) return;
        const auto element = text.find("elementdatafile");
        if (element != std::string::npos) {
            const std::string line = text.substr(element, text.find('\n', element) - element);
            if (line.find("local") == std::string::npos) return;
        }
    }
    std::error_code ec;
    const auto file_bytes = fs::file_size(path, ec);
    if (ec) return;
    if (io.GetComponentType() == itk::IOComponentEnum::UNKNOWNCOMPONENTTYPE)
        fail("image '{}': unknown or unsupported pixel type (corrupt header?)", path);
    long double declared = static_cast<long double>(io.GetComponentSize()) * io.GetNumberOfComponents();
    for (unsigned a = 0; a < io.GetNumberOfDimensions(); ++a) declared *= static_cast<long double>(io.GetDimensions(a));
    if (declared > 1100.0L * static_cast<long double>(file_bytes) + 4096.0L)
        fail("image '{}': the header declares {:.0f} bytes of pixel data, more than a {}-byte file can hold even compressed "
             "(corrupt header or truncated file)",
             path, static_cast<double>(declared), file_bytes);
}

template <typename ImageType>
PlainGeometry geometry_of(const ImageType* image)
{
    PlainGeometry g;
    const auto region = image->GetLargestPossibleRegion();
    for (unsigned a = 0; a < 3; ++a) {
        g.size[a] = static_cast<std::int64_t>(region.GetSize()[a]);
        g.origin[a] = image->GetOrigin()[a];
        g.spacing[a] = image->GetSpacing()[a];
        for (unsigned b = 0; b < 3; ++b) g.direction[3 * a + b] = image->GetDirection()[a][b];
    }
    return g;
}

template <typename ImageType>
typename ImageType::Pointer make_image(const PlainGeometry& g)
{
    auto image = ImageType::New();
    typename ImageType::RegionType region;
    typename ImageType::PointType origin;
    typename ImageType::SpacingType spacing;
    typename ImageType::DirectionType direction;
    for (unsigned a = 0; a < 3; ++a) {
        region.SetSize(a, static_cast<itk::SizeValueType>(g.size[a]));
        origin[a] = g.origin[a];
        spacing[a] = g.spacing[a];
        for (unsigned b = 0; b < 3; ++b) direction[a][b] = g.direction[3 * a + b];
    }
    image->SetRegions(region);
    image->SetOrigin(origin);
    image->SetSpacing(spacing);
    image->SetDirection(direction);
    image->Allocate();
    return image;
}

std::vector<std::string> dicom_series_files(const std::string& dir)
{
    auto names = itk::GDCMSeriesFileNames::New();
    names->SetUseSeriesDetails(true);
    names->SetDirectory(dir);
    const auto& series = names->GetSeriesUIDs();
    if (series.empty()) fail("image '{}': directory holds no DICOM series", dir);
    if (series.size() > 1)
        logger()->warn("image '{}': {} DICOM series found; reading the first ({})", dir, series.size(), series.front());
    return names->GetFileNames(series.front());
}

template <typename ImageType>
typename ImageType::Pointer read_itk(const std::string& path)
{
    require_exists(path);
    try {
        if (fs::is_directory(path)) {
            auto reader = itk::ImageSeriesReader<ImageType>::New();
            reader->SetImageIO(itk::GDCMImageIO::New());
            reader->SetFileNames(dicom_series_files(path));
            reader->Update();
            return reader->GetOutput();
        }
        auto io = image_io_for(path);
        io->SetFileName(path);
        io->ReadImageInformation();
        check_declared_size(path, *io);
        auto reader = itk::ImageFileReader<ImageType>::New();
        reader->SetImageIO(io);
        reader->SetFileName(path);
        reader->Update();
        return reader->GetOutput();
    } catch (const itk::ExceptionObject& e) {
        fail("image '{}': cannot be read (corrupt or truncated?): {}", path, e.GetDescription());
    } catch (const std::bad_alloc&) {
        fail("image '{}': cannot be read: not enough memory for the image its header declares", path);
    }
}

template <typename ImageType, typename T>
void read_scalars(const std::string& path, PlainGeometry& geometry, std::vector<T>& values)
{
    auto image = read_itk<ImageType>(path);
    geometry = geometry_of(image.GetPointer());
    const auto* data = image->GetBufferPointer();
    values.assign(data, data + geometry.size[0] * geometry.size[1] * geometry.size[2]);
}

template <typename ImageType>
void write_itk(const std::string& path, const std::string& final_name, const ImageType* image)
{
    register_image_formats();
    try {
        auto writer = itk::ImageFileWriter<ImageType>::New();
        writer->SetFileName(path);
        writer->SetInput(image);
        writer->SetUseCompression(true);
        writer->Update();
    } catch (const itk::ExceptionObject& e) {
        fail("image '{}': cannot be written: {}", final_name, e.GetDescription());
    }
}

} // namespace

namespace {

PlainHeader read_header(const std::string& path)
{
    require_exists(path);
    const bool directory = fs::is_directory(path);
    const std::string probe = directory ? dicom_series_files(path).front() : path;
    auto io = directory ? itk::ImageIOBase::Pointer(itk::GDCMImageIO::New()) : image_io_for(probe);
    try {
        io->SetFileName(probe);
        io->ReadImageInformation();
    } catch (const itk::ExceptionObject& e) {
        fail("image '{}': cannot read header: {}", path, e.GetDescription());
    }
    if (!directory) check_declared_size(path, *io);
    PlainHeader h;
    unsigned dims = io->GetNumberOfDimensions();
    // A trailing axis of length 1 (e.g. a 4-D NIfTI with one time point) is still a 3-D image.
    while (dims > 3 && io->GetDimensions(dims - 1) == 1) --dims;
    if (!(dims == 3 || (directory && dims == 2)))
        fail("image '{}': has {} dimensions; physreg needs a 3-D image", path, dims);
    h.dimensions = 3;
    h.components = static_cast<int>(io->GetNumberOfComponents());
    h.component_type = itk::ImageIOBase::GetComponentTypeAsString(io->GetComponentType());
    h.format = io->GetNameOfClass();
    if (directory) {
        // The series geometry (slice count, spacing along z) needs the whole series.
        auto image = read_itk<itk::Image<float, 3>>(path);
        h.geometry = geometry_of(image.GetPointer());
        return h;
    }
    for (unsigned a = 0; a < 3; ++a) {
        h.geometry.size[a] = static_cast<std::int64_t>(io->GetDimensions(a));
        h.geometry.origin[a] = io->GetOrigin(a);
        h.geometry.spacing[a] = io->GetSpacing(a);
        const auto column = io->GetDirection(a);
        for (unsigned b = 0; b < 3; ++b) h.geometry.direction[3 * b + a] = column[b];
    }
    return h;
}

} // namespace

PlainHeader itk_read_header(const std::string& path)
{
    try {
        return read_header(path);
    } catch (const itk::ExceptionObject& e) {
        // ITK's accessors throw on what a damaged header leaves behind (e.g. an unknown pixel type).
        fail("image '{}': cannot read header: {}", path, e.GetDescription());
    }
}

void itk_read(const std::string& path, PlainGeometry& g, std::vector<std::int32_t>& v)
{
    read_scalars<itk::Image<std::int32_t, 3>>(path, g, v);
}
void itk_read(const std::string& path, PlainGeometry& g, std::vector<double>& v)
{
    read_scalars<itk::Image<double, 3>>(path, g, v);
}
void itk_read(const std::string& path, PlainGeometry& g, std::vector<float>& v)
{
    read_scalars<itk::Image<float, 3>>(path, g, v);
}

void itk_read_vectors(const std::string& path, PlainGeometry& g, std::vector<float>& v)
{
    using FieldImage = itk::Image<itk::Vector<float, 3>, 3>;
    auto image = read_itk<FieldImage>(path);
    g = geometry_of(image.GetPointer());
    const auto n = static_cast<std::size_t>(g.size[0] * g.size[1] * g.size[2]);
    v.resize(3 * n);
    const auto* data = image->GetBufferPointer();
    for (std::size_t i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) v[3 * i + c] = data[i][c];
}

void itk_write(const std::string& path, const std::string& final_name, const PlainGeometry& g, const std::uint16_t* values)
{
    auto image = make_image<itk::Image<std::uint16_t, 3>>(g);
    std::copy(values, values + g.size[0] * g.size[1] * g.size[2], image->GetBufferPointer());
    write_itk(path, final_name, image.GetPointer());
}

void itk_write(const std::string& path, const std::string& final_name, const PlainGeometry& g, const float* values)
{
    auto image = make_image<itk::Image<float, 3>>(g);
    std::copy(values, values + g.size[0] * g.size[1] * g.size[2], image->GetBufferPointer());
    write_itk(path, final_name, image.GetPointer());
}

void itk_write_vectors(const std::string& path, const std::string& final_name, const PlainGeometry& g, const float* values)
{
    using FieldImage = itk::Image<itk::Vector<float, 3>, 3>;
    auto image = make_image<FieldImage>(g);
    const auto n = static_cast<std::size_t>(g.size[0] * g.size[1] * g.size[2]);
    auto* data = image->GetBufferPointer();
    for (std::size_t i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) data[i][c] = values[3 * i + c];
    write_itk(path, final_name, image.GetPointer());
}

using RgbImage2 = itk::Image<itk::RGBPixel<unsigned char>, 2>;

void itk_write_rgb_png(const std::string& path, const std::string& final_name, int width, int height,
                       const std::uint8_t* rgb)
{
    auto image = RgbImage2::New();
    RgbImage2::RegionType region;
    region.SetSize(0, static_cast<itk::SizeValueType>(width));
    region.SetSize(1, static_cast<itk::SizeValueType>(height));
    image->SetRegions(region);
    image->Allocate();
    std::copy(rgb, rgb + 3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height),
              reinterpret_cast<unsigned char*>(image->GetBufferPointer()));
    try {
        auto writer = itk::ImageFileWriter<RgbImage2>::New();
        writer->SetImageIO(itk::PNGImageIO::New());
        writer->SetFileName(path);
        writer->SetInput(image);
        writer->Update();
    } catch (const itk::ExceptionObject& e) {
        fail("PNG '{}': cannot be written: {}", final_name, e.GetDescription());
    }
}

void itk_read_rgb_png(const std::string& path, int& width, int& height, std::vector<std::uint8_t>& rgb)
{
    if (!fs::exists(path)) fail_missing_file("PNG '{}': file does not exist", path);
    try {
        auto reader = itk::ImageFileReader<RgbImage2>::New();
        reader->SetImageIO(itk::PNGImageIO::New());
        reader->SetFileName(path);
        reader->Update();
        const auto size = reader->GetOutput()->GetLargestPossibleRegion().GetSize();
        width = static_cast<int>(size[0]);
        height = static_cast<int>(size[1]);
        const auto* data = reinterpret_cast<const std::uint8_t*>(reader->GetOutput()->GetBufferPointer());
        rgb.assign(data, data + 3 * size[0] * size[1]);
    } catch (const itk::ExceptionObject& e) {
        fail("PNG '{}': cannot be read (corrupt or truncated?): {}", path, e.GetDescription());
    }
}

} // namespace physreg::detail
