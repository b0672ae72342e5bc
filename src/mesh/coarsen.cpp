// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/coarsen.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/label_grid.hpp"

#include <cmath>
#include <limits>

namespace physreg {

CoarseningResult coarsen(const VolumeMesh& fine, const Index3& dims, ComponentPolicy policy)
{
    const LabelGrid fine_grid = label_grid_of_mesh(fine);
    const LabelGrid coarse_grid = resample_majority(fine_grid, dims, "coarsen --grid");
    CoarseningResult result;
    result.mesh = hex_mesh_from_label_grid(coarse_grid);
    if (result.mesh.cell_count() == 0) fail("coarsen: every coarse cell is mostly empty; use a finer grid");
    result.components = repair_components(result.mesh, policy, true, "coarse mesh");
    result.fine_nodes = embed_in_grid_mesh(result.mesh, fine.nodes);
    return result;
}

std::vector<NodeEmbedding> embed_in_grid_mesh(const VolumeMesh& mesh, const std::vector<Vec3>& points)
{
    if (!mesh.grid || mesh.cell_grid_index.size() != mesh.cell_count())
        fail("embedding: the mesh is not a grid mesh");
    const HexGrid& grid = *mesh.grid;
    const Index3& d = grid.dims;
    std::vector<std::int32_t> cell_at(static_cast<std::size_t>(d[0] * d[1] * d[2]), -1);
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const auto& ijk = mesh.cell_grid_index[c];
        cell_at[static_cast<std::size_t>(ijk[0] + d[0] * (ijk[1] + d[1] * ijk[2]))] = static_cast<std::int32_t>(c);
    }
    constexpr double tolerance = 1e-9; // in cell units: points on a shared face belong to either cell
    std::vector<NodeEmbedding> out(points.size());
    for (std::size_t p = 0; p < points.size(); ++p) {
        const Vec3 g = grid.to_grid(points[p]);
        NodeEmbedding& e = out[p];
        // Candidate cells: those whose closed box holds g (up to 8 at a shared corner).
        Index3 lo, hi;
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor(g[a] - tolerance)));
            hi[a] = std::min<std::int64_t>(d[a] - 1, static_cast<std::int64_t>(std::floor(g[a] + tolerance)));
        }
        for (std::int64_t k = lo[2]; k <= hi[2] && !e.inside; ++k)
            for (std::int64_t j = lo[1]; j <= hi[1] && !e.inside; ++j)
                for (std::int64_t i = lo[0]; i <= hi[0] && !e.inside; ++i) {
                    const std::int32_t c = cell_at[static_cast<std::size_t>(i + d[0] * (j + d[1] * k))];
                    if (c < 0) continue;
                    const Vec3 xi = 2.0 * (g - Vec3(double(i), double(j), double(k))) - Vec3::Ones();
                    if (xi.cwiseAbs().maxCoeff() <= 1.0 + 2 * tolerance) e = {c, xi.cwiseMax(-1.0).cwiseMin(1.0), true, 0.0};
                }
        if (e.inside) continue;
        // Outside every cell: the nearest cell, with ξ extrapolated.
        double best = std::numeric_limits<double>::infinity();
        for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
            const auto& ijk = mesh.cell_grid_index[c];
            Vec3 gap;
            for (int a = 0; a < 3; ++a)
                gap[a] = std::max({0.0, double(ijk[a]) - g[a], g[a] - double(ijk[a] + 1)}) * grid.cell_size[a];
            const double distance = gap.norm();
            if (distance < best) {
                best = distance;
                e.cell = static_cast<std::int32_t>(c);
                e.natural = 2.0 * (g - Vec3(double(ijk[0]), double(ijk[1]), double(ijk[2]))) - Vec3::Ones();
                e.distance_mm = distance;
            }
        }
    }
    return out;
}

} // namespace physreg
