// SPDX-License-Identifier: GPL-3.0-or-later
// Surface and point-set readers: STL (ASCII/binary), PLY (ASCII/binary), OBJ and legacy VTK
// POLYDATA. The first byte picks the format and whether the file is read as a point set.
#include "fuzz_support.hpp"
#include "physreg/io/surface_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    if (size < 1) return 0;
    static const char* const extensions[] = {".stl", ".ply", ".obj", ".vtk"};
    const char* extension = extensions[data[0] & 3];
    const bool point_set = (data[0] & 4) && (data[0] & 1); // .ply and .vtk only
    const auto path = physreg::fuzz::write_input(data + 1, size - 1, extension);
    physreg::fuzz::expect_success_or_error([&] {
        const physreg::SurfaceMesh surface = point_set ? physreg::read_point_set(path) : physreg::read_surface(path);
        const auto vertices = static_cast<std::int64_t>(surface.vertices.size());
        for (const auto& triangle : surface.triangles)
            for (const auto v : triangle) physreg::fuzz::check(v >= 0 && v < vertices, "triangle vertex id in range");
        for (const auto& p : surface.vertices) physreg::fuzz::check(p.allFinite(), "finite vertices");
        physreg::fuzz::check(surface.labels.empty() || surface.labels.size() == surface.triangles.size(), "one label pair per triangle");
        physreg::fuzz::check(surface.vertex_normals.empty() || surface.vertex_normals.size() == surface.vertices.size(),
                             "one normal per vertex");
        physreg::fuzz::check(surface.vertex_labels.empty() || surface.vertex_labels.size() == surface.vertices.size(),
                             "one label per vertex");
    });
    return 0;
}
