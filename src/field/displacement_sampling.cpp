// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/field/displacement_sampling.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/point_location.hpp"

#include <cmath>
#include <limits>
#include <optional>

namespace physreg {

ImageGeometry image_grid_over_mesh(const VolumeMesh& mesh, double spacing_mm, double margin_mm)
{
    if (!(spacing_mm > 0 && std::isfinite(spacing_mm))) fail("displacement field spacing {} mm must be positive", spacing_mm);
    if (!(margin_mm >= 0 && std::isfinite(margin_mm))) fail("displacement field margin {} mm must be ≥ 0", margin_mm);
    if (mesh.node_count() == 0) fail("displacement field: the mesh has no nodes");
    Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (const auto& p : mesh.nodes) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    lo -= Vec3::Constant(margin_mm);
    hi += Vec3::Constant(margin_mm);
    ImageGeometry g;
    g.spacing = Vec3::Constant(spacing_mm);
    for (int a = 0; a < 3; ++a) g.size[a] = static_cast<std::int64_t>(std::floor((hi[a] - lo[a]) / spacing_mm)) + 1;
    if (double(g.size[0]) * double(g.size[1]) * double(g.size[2]) > 512e6)
        fail("displacement field: {}x{}x{} voxels at {} mm is too large; use a coarser spacing", g.size[0], g.size[1], g.size[2], spacing_mm);
    g.origin = lo;
    return g;
}

SampledField sample_displacement_field(const VolumeMesh& mesh, const std::vector<double>& u, const ImageGeometry& geometry)
{
    geometry.validate("displacement field grid");
    if (u.size() != 3 * mesh.node_count()) fail("displacement field: {} values for {} nodes", u.size(), mesh.node_count());
    SampledField out;
    out.field.geometry = geometry;
    const auto voxels = static_cast<std::size_t>(geometry.voxel_count());
    out.field.components.assign(3 * voxels, 0.0f);
    out.inside.assign(voxels, 0);
    const bool grid = mesh.grid && mesh.cell_type == CellType::hexahedron && mesh.cell_grid_index.size() == mesh.cell_count();
    std::vector<std::int32_t> cell_at;
    if (grid) {
        const Index3& d = mesh.grid->dims;
        cell_at.assign(static_cast<std::size_t>(d[0] * d[1] * d[2]), -1);
        for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
            const auto& ijk = mesh.cell_grid_index[c];
            cell_at[static_cast<std::size_t>(ijk[0] + d[0] * (ijk[1] + d[1] * ijk[2]))] = static_cast<std::int32_t>(c);
        }
    }
    const PointLocator* locator = nullptr;
    std::optional<PointLocator> owned;
    if (!grid) {
        owned.emplace(mesh);
        locator = &*owned;
    }
    const int per = mesh.cell_size();
#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t k = 0; k < geometry.size[2]; ++k)
        for (std::int64_t j = 0; j < geometry.size[1]; ++j)
            for (std::int64_t i = 0; i < geometry.size[0]; ++i) {
                const Vec3 x = geometry.index_to_physical(Vec3(double(i), double(j), double(k)));
                std::int32_t cell = -1;
                Vec3 xi;
                if (grid) {
                    const Vec3 g = mesh.grid->to_grid(x);
                    Index3 c;
                    bool in = true;
                    for (int a = 0; a < 3; ++a) {
                        c[a] = static_cast<std::int64_t>(std::floor(g[a]));
                        if (c[a] == mesh.grid->dims[a] && g[a] <= double(c[a]) + 1e-9) --c[a]; // the far face
                        in = in && c[a] >= 0 && c[a] < mesh.grid->dims[a];
                    }
                    if (in) {
                        cell = cell_at[static_cast<std::size_t>(c[0] + mesh.grid->dims[0] * (c[1] + mesh.grid->dims[1] * c[2]))];
                        xi = 2.0 * (g - Vec3(double(c[0]), double(c[1]), double(c[2]))) - Vec3::Ones();
                    }
                } else if (const auto e = locator->locate(x)) {
                    cell = e->cell;
                    xi = e->natural;
                }
                if (cell < 0) continue;
                const auto weights = shape_weights(mesh.cell_type, xi);
                const auto ids = mesh.cell(static_cast<std::size_t>(cell));
                Vec3 value = Vec3::Zero();
                for (int a = 0; a < per; ++a) value += weights[a] * Vec3(u[3 * ids[a]], u[3 * ids[a] + 1], u[3 * ids[a] + 2]);
                const auto v = static_cast<std::size_t>(geometry.linear_index(i, j, k));
                for (int c = 0; c < 3; ++c) out.field.components[3 * v + c] = static_cast<float>(value[c]);
                out.inside[v] = 1;
            }
    return out;
}

} // namespace physreg
