// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/tet_split.hpp"

#include "physreg/core/error.hpp"

#include <Eigen/LU>

namespace physreg {

VolumeMesh split_hexahedra_into_tetrahedra(const VolumeMesh& hex)
{
    if (hex.cell_type != CellType::hexahedron) fail("tetrahedral split: the mesh is already tetrahedral");
    // Local hexahedron corners by axis bits (x=1, y=2, z=4) in VTK order.
    static constexpr int local_of_bits[8] = {0, 1, 3, 2, 4, 5, 7, 6};
    // Kuhn: one tetrahedron per axis order (a, b, c): 000 → e_a → e_a+e_b → 111.
    static constexpr int axis_orders[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    VolumeMesh out;
    out.cell_type = CellType::tetrahedron;
    out.nodes = hex.nodes;
    out.cells.reserve(hex.cell_count() * 24);
    out.cell_labels.reserve(hex.cell_count() * 6);
    for (std::size_t c = 0; c < hex.cell_count(); ++c) {
        const auto ids = hex.cell(c);
        for (const auto& order : axis_orders) {
            const int b1 = 1 << order[0];
            const int b2 = b1 | (1 << order[1]);
            std::array<std::int32_t, 4> tet{ids[local_of_bits[0]], ids[local_of_bits[b1]], ids[local_of_bits[b2]],
                                            ids[local_of_bits[7]]};
            Mat3 m;
            const Vec3& p0 = out.nodes[tet[0]];
            m << out.nodes[tet[1]] - p0, out.nodes[tet[2]] - p0, out.nodes[tet[3]] - p0;
            const double det = m.determinant();
            if (det < 0) std::swap(tet[1], tet[2]);
            if (det == 0.0 || !std::isfinite(det))
                fail("tetrahedral split: hexahedron {} is degenerate (zero-volume tetrahedron)", c);
            out.cells.insert(out.cells.end(), tet.begin(), tet.end());
            out.cell_labels.push_back(hex.cell_labels[c]);
        }
    }
    return out;
}

} // namespace physreg
