// SPDX-License-Identifier: GPL-3.0-or-later
// Volume mesh readers: VTK XML unstructured grids (.vtu, with inline/appended, raw/base64 and
// zlib-compressed arrays) and Gmsh (.msh 2.2 and 4.1, ASCII and binary). The first byte picks the
// reader; a mesh that is accepted must pass VolumeMesh::validate.
#include "fuzz_support.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/vtu.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    if (size < 1) return 0;
    const char* extension = (data[0] & 1) ? ".msh" : ".vtu";
    const auto path = physreg::fuzz::write_input(data + 1, size - 1, extension);
    physreg::fuzz::expect_success_or_error([&] {
        physreg::MeshData mesh_data;
        const physreg::VolumeMesh mesh = physreg::read_volume_mesh(path, &mesh_data);
        mesh.validate("fuzzed mesh"); // must not throw: readers return valid meshes only
    });
    return 0;
}
