// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/error.hpp"
#include "physreg/io/image_io.hpp"
#include "test_support.hpp"

#include <cstring>
#include <fstream>
#include <zlib.h>

namespace physreg {
namespace {

void expect_same_geometry(const ImageGeometry& a, const ImageGeometry& b, double tolerance)
{
    EXPECT_EQ(a.size, b.size);
    EXPECT_LT((a.origin - b.origin).cwiseAbs().maxCoeff(), tolerance);
    EXPECT_LT((a.spacing - b.spacing).cwiseAbs().maxCoeff(), tolerance);
    EXPECT_LT((a.direction - b.direction).cwiseAbs().maxCoeff(), tolerance);
}

std::string error_of(const std::function<void()>& f) { return test::error_message(f); }

LabelVolume oblique_volume()
{
    return test::make_volume({7, 5, 4}, [](int i, int j, int k) { return std::uint16_t((i + 2 * j + 3 * k) % 5); },
                             Vec3(0.8, 1.25, 2.5), Vec3(-12.5, 30.25, 7.0), test::oblique_rotation());
}

} // namespace

TEST(IoImage, LabelVolumeRoundTripKeepsGeometryInEveryFormat)
{
    test::TempDir dir;
    const LabelVolume volume = oblique_volume();
    // NIfTI stores the geometry as float32 (qform/sform): 1e-5 mm. NRRD and MetaImage print doubles.
    for (const auto& [name, tolerance] : {std::pair{"l.nii.gz", 1e-5}, {"l.nii", 1e-5}, {"l.nrrd", 1e-9}, {"l.mha", 1e-9}, {"l.mhd", 1e-9}}) {
        SCOPED_TRACE(name);
        write_label_volume(dir / name, volume);
        const LabelVolume back = read_label_volume(dir / name);
        expect_same_geometry(back.geometry, volume.geometry, tolerance);
        EXPECT_EQ(back.labels, volume.labels);
        const auto info = read_image_info(dir / name);
        expect_same_geometry(info.geometry, volume.geometry, tolerance);
        EXPECT_EQ(info.components, 1);
    }
}

TEST(IoImage, IndexToPhysicalFollowsItkConvention)
{
    const LabelVolume v = oblique_volume();
    const Vec3 index(2, 3, 1);
    const Vec3 expected = v.geometry.origin + v.geometry.direction * Vec3(2 * 0.8, 3 * 1.25, 1 * 2.5);
    EXPECT_LT((v.geometry.index_to_physical(index) - expected).norm(), 1e-12);
    EXPECT_LT((v.geometry.physical_to_index(expected) - index).norm(), 1e-12);
}

TEST(IoImage, ScalarImageAndDisplacementFieldRoundTrip)
{
    test::TempDir dir;
    ScalarImage image;
    image.geometry = oblique_volume().geometry;
    for (std::int64_t v = 0; v < image.geometry.voxel_count(); ++v) image.values.push_back(0.25f * float(v) - 3.0f);
    write_scalar_image(dir / "i.nrrd", image);
    const ScalarImage back = read_scalar_image(dir / "i.nrrd");
    EXPECT_EQ(back.values, image.values);

    DisplacementField field;
    field.geometry = image.geometry;
    for (std::int64_t v = 0; v < field.geometry.voxel_count(); ++v)
        for (int c = 0; c < 3; ++c) field.components.push_back(0.125f * float(v) * float(c + 1) - 1.0f);
    for (const char* name : {"u.nii.gz", "u.mha", "u.nrrd"}) {
        SCOPED_TRACE(name);
        write_displacement_field(dir / name, field);
        const auto info = read_image_info(dir / name);
        EXPECT_EQ(info.components, 3);
        const DisplacementField f = read_displacement_field(dir / name);
        expect_same_geometry(f.geometry, field.geometry, 1e-5);
        EXPECT_EQ(f.components, field.components);
    }
}

TEST(IoImage, DisplacementFieldNiftiHeaderIsWhatAntsAndSlicerRead)
{
    // A displacement-field transform in NIfTI: 5-D (x, y, z, t = 1, 3 components), intent 1007
    // (NIFTI_INTENT_VECTOR), float32.
    test::TempDir dir;
    DisplacementField field;
    field.geometry = oblique_volume().geometry;
    field.components.assign(3 * static_cast<std::size_t>(field.geometry.voxel_count()), 0.5f);
    write_displacement_field(dir / "u.nii.gz", field);
    gzFile file = gzopen((dir / "u.nii.gz").string().c_str(), "rb");
    ASSERT_NE(file, nullptr);
    char header[348];
    ASSERT_EQ(gzread(file, header, sizeof(header)), 348);
    gzclose(file);
    std::int16_t dim[8], intent, datatype;
    std::memcpy(dim, header + 40, sizeof(dim));
    std::memcpy(&intent, header + 68, 2);
    std::memcpy(&datatype, header + 70, 2);
    EXPECT_EQ(dim[0], 5);
    EXPECT_EQ(dim[1], 7);
    EXPECT_EQ(dim[4], 1);
    EXPECT_EQ(dim[5], 3);
    EXPECT_EQ(intent, 1007);
    EXPECT_EQ(datatype, 16);
}

TEST(IoImage, BadFilesGiveClearErrors)
{
    test::TempDir dir;
    EXPECT_NE(error_of([&] { read_label_volume(dir / "missing.nii.gz"); }).find("does not exist"), std::string::npos);

    std::ofstream(dir / "garbage.nii") << "this is not an image";
    EXPECT_NE(error_of([&] { read_label_volume(dir / "garbage.nii"); }).find("garbage.nii"), std::string::npos);

    // Truncated: a valid compressed NIfTI cut in half.
    write_label_volume(dir / "full.nii.gz", oblique_volume());
    std::ifstream in(dir / "full.nii.gz", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(dir / "cut.nii.gz", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
    EXPECT_NE(error_of([&] { read_label_volume(dir / "cut.nii.gz"); }).find("cut.nii.gz"), std::string::npos);

    // Truncated by a few bytes, uncompressed: ITK alone would pad with zeros; we refuse it.
    write_label_volume(dir / "full.nii", oblique_volume());
    std::ifstream raw(dir / "full.nii", std::ios::binary);
    std::string raw_bytes((std::istreambuf_iterator<char>(raw)), std::istreambuf_iterator<char>());
    std::ofstream(dir / "short.nii", std::ios::binary) << raw_bytes.substr(0, raw_bytes.size() - 10);
    EXPECT_NE(error_of([&] { read_label_volume(dir / "short.nii"); }).find("truncated"), std::string::npos);

    // Fractional and negative labels are refused, not rounded or wrapped.
    ScalarImage fractional;
    fractional.geometry.size = {2, 2, 2};
    fractional.values = {0, 1, 2, 1.5f, 0, 0, 0, 0};
    write_scalar_image(dir / "frac.nrrd", fractional);
    EXPECT_NE(error_of([&] { read_label_volume(dir / "frac.nrrd"); }).find("1.5"), std::string::npos);
    fractional.values[3] = -1;
    write_scalar_image(dir / "neg.nrrd", fractional);
    EXPECT_NE(error_of([&] { read_label_volume(dir / "neg.nrrd"); }).find("-1"), std::string::npos);

    // A 2-D image is not a volume.
    std::ofstream(dir / "flat.mha") << "ObjectType = Image\nNDims = 2\nDimSize = 2 2\nElementType = MET_UCHAR\n"
                                       "ElementDataFile = LOCAL\n"
                                    << std::string(4, '\1');
    EXPECT_NE(error_of([&] { read_label_volume(dir / "flat.mha"); }).find("3-D"), std::string::npos);
    // A vector image is not a label map.
    DisplacementField f;
    f.geometry.size = {2, 2, 2};
    f.components.assign(24, 0.5f);
    write_displacement_field(dir / "vec.mha", f);
    EXPECT_NE(error_of([&] { read_label_volume(dir / "vec.mha"); }).find("components"), std::string::npos);
}

TEST(IoImage, FailedWritesLeaveNoFile)
{
    test::TempDir dir;
    DisplacementField f;
    f.geometry.size = {2, 2, 2};
    f.components.assign(24, 0.0f);
    f.components[5] = std::numeric_limits<float>::quiet_NaN();
    EXPECT_NE(error_of([&] { write_displacement_field(dir / "u.nii.gz", f); }).find("not finite"), std::string::npos);
    LabelVolume v;
    v.geometry.size = {2, 2, 2};
    v.labels.assign(7, 0); // one short
    EXPECT_THROW(write_label_volume(dir / "l.nii.gz", v), Error);
    EXPECT_TRUE(dir.files().empty());
}

} // namespace physreg
