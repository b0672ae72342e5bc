// SPDX-License-Identifier: GPL-3.0-or-later
// Image readers (ITK behind physreg's bridge): NIfTI, NRRD and MetaImage, read as a label volume,
// a scalar image or a displacement field. The first byte picks the format and the reader. ITK
// itself is not instrumented: this target checks physreg's side (header checks, sizes, labels).
#include "fuzz_support.hpp"
#include "physreg/io/image_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    using namespace physreg;
    if (size < 1) return 0;
    static const char* const extensions[] = {".nii", ".nrrd", ".mha", ".nii"};
    const auto path = fuzz::write_input(data + 1, size - 1, extensions[data[0] & 3]);
    const int reader = (data[0] >> 2) % 3;
    fuzz::expect_success_or_error([&] {
        if (reader == 0) {
            const LabelVolume volume = read_label_volume(path);
            fuzz::check(volume.labels.size() == static_cast<std::size_t>(volume.geometry.voxel_count()), "label count");
        } else if (reader == 1) {
            const ScalarImage image = read_scalar_image(path);
            fuzz::check(image.values.size() == static_cast<std::size_t>(image.geometry.voxel_count()), "value count");
        } else {
            const DisplacementField field = read_displacement_field(path);
            fuzz::check(field.components.size() == 3 * static_cast<std::size_t>(field.geometry.voxel_count()), "vector count");
        }
    });
    return 0;
}
