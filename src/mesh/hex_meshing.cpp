// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/hex_meshing.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/label_grid.hpp"

#include <charconv>

namespace physreg {

Index3 parse_grid_dims(const std::string& text, const std::string& option)
{
    Index3 dims{0, 0, 0};
    const char* p = text.data();
    const char* end = text.data() + text.size();
    for (int a = 0; a < 3; ++a) {
        auto [next, ec] = std::from_chars(p, end, dims[a]);
        if (ec != std::errc() || dims[a] < 1)
            fail("{}: '{}' is not a grid like 74x18x54 (three positive integers)", option, text);
        p = next;
        if (a < 2) {
            if (p == end || (*p != 'x' && *p != 'X'))
                fail("{}: '{}' is not a grid like 74x18x54 (three positive integers)", option, text);
            ++p;
        }
    }
    if (p != end) fail("{}: '{}' is not a grid like 74x18x54 (three positive integers)", option, text);
    return dims;
}

MeshingResult mesh_label_volume(const LabelVolume& volume, const TissueTable& tissues,
                                const MeshingOptions& options, const std::string& what)
{
    volume.geometry.validate(what);
    tissues.validate(what + " tissue table");
    MeshingResult result;
    result.report.voxels_per_label = count_labels(volume);
    LabelGrid grid = crop_to_tissues(volume, tissues, what);
    if (options.grid_dims) grid = resample_majority(grid, *options.grid_dims, what + " --grid");
    result.mesh = hex_mesh_from_label_grid(grid);
    if (result.mesh.cell_count() == 0)
        fail("{}: every cell of the {}x{}x{} grid is mostly background; use a finer grid", what,
             grid.geometry.dims[0], grid.geometry.dims[1], grid.geometry.dims[2]);
    result.report.grid = grid.geometry;
    result.report.components =
        repair_components(result.mesh, options.components, options.split_nonmanifold, what);
    return result;
}

} // namespace physreg
