// SPDX-License-Identifier: GPL-3.0-or-later
// The OpenIGTLink reader of physreg serve (src/live/igtl_wire.cpp): the 58-byte header of versions
// 1 and 2, the body's CRC-64, version 2's extended header and metadata, the POLYDATA points a
// cloud arrives as and the IMAGE a segmentation arrives as. The first input byte's low bit says whether the CRC is written in before
// parsing (so that mutations reach the layout checks behind it) or left as the input has it.
#include "fuzz_support.hpp"
#include "physreg/live/igtl_wire.hpp"

#include <igtl_util.h>

#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    if (size < 1) return 0;
    std::vector<std::uint8_t> raw(data + 1, data + size);
    if ((data[0] & 1) && raw.size() >= physreg::live::igtl_header_size) {
        const std::uint64_t crc = ::crc64(raw.data() + physreg::live::igtl_header_size, raw.size() - physreg::live::igtl_header_size, 0);
        for (int i = 0; i < 8; ++i) raw[50 + i] = static_cast<std::uint8_t>(crc >> (56 - 8 * i));
    }
    physreg::fuzz::expect_success_or_error([&] {
        const physreg::live::IgtlMessage m = physreg::live::parse_igtl_message(raw);
        physreg::fuzz::check(m.content.size() <= raw.size() - physreg::live::igtl_header_size, "the content lies inside the body");
        if (m.type == "POLYDATA") {
            const auto points = physreg::live::polydata_points(m, -1.0);
            for (const auto& p : points) physreg::fuzz::check(p.allFinite(), "finite cloud points");
        }
        if (m.type == "IMAGE") {
            const physreg::LabelVolume v = physreg::live::igtl_image_labels(m);
            physreg::fuzz::check(static_cast<std::int64_t>(v.labels.size()) == v.geometry.voxel_count(), "one label per voxel");
            physreg::fuzz::check(v.geometry.origin.allFinite() && v.geometry.spacing.minCoeff() > 0, "a finite grid");
        }
    });
    return 0;
}
