// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/label_grid.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <limits>

namespace physreg {

std::map<std::int32_t, std::int64_t> count_labels(const LabelVolume& volume)
{
    std::vector<std::int64_t> histogram(65536, 0);
    for (auto l : volume.labels) ++histogram[l];
    std::map<std::int32_t, std::int64_t> counts;
    for (std::size_t l = 0; l < histogram.size(); ++l)
        if (histogram[l]) counts[static_cast<std::int32_t>(l)] = histogram[l];
    return counts;
}

LabelGrid crop_to_tissues(const LabelVolume& volume, const TissueTable& tissues, const std::string& what)
{
    const ImageGeometry& g = volume.geometry;
    if (volume.labels.size() != static_cast<std::size_t>(g.voxel_count()))
        fail("{}: {} labels for {} voxels", what, volume.labels.size(), g.voxel_count());
    const auto counts = count_labels(volume);
    std::vector<std::uint16_t> map(65536, 0);
    std::string unknown;
    bool any_tissue = false;
    for (const auto& [label, count] : counts) {
        if (label == 0) continue;
        if (tissues.find(label)) {
            map[label] = static_cast<std::uint16_t>(label);
            any_tissue = true;
        } else if (!tissues.ignored_labels.count(label)) {
            unknown += fmt::format("{}{} ({} voxels)", unknown.empty() ? "" : ", ", label, count);
        }
    }
    if (!unknown.empty())
        fail("{}: labels {} are not in the tissue table; add them as tissues or list them under ignore_labels",
             what, unknown);
    if (!any_tissue) {
        std::string present;
        for (const auto& [label, count] : counts) present += fmt::format(" {}:{}", label, count);
        fail("{}: no voxel carries a tissue label (the label set is empty; label:voxels present:{})", what, present);
    }
    for (const auto& t : tissues.tissues)
        if (!counts.count(t.label))
            logger()->warn("{}: tissue '{}' (label {}) has no voxel", what, t.name, t.label);

    Index3 lo{g.size[0], g.size[1], g.size[2]}, hi{-1, -1, -1};
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j) {
            const std::uint16_t* row = volume.labels.data() + g.linear_index(0, j, k);
            for (std::int64_t i = 0; i < g.size[0]; ++i)
                if (map[row[i]]) {
                    lo = {std::min(lo[0], i), std::min(lo[1], j), std::min(lo[2], k)};
                    hi = {std::max(hi[0], i), std::max(hi[1], j), std::max(hi[2], k)};
                }
        }
    const bool flip = g.direction.determinant() < 0;
    LabelGrid out;
    out.geometry.dims = {hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1};
    out.geometry.cell_size = g.spacing;
    out.geometry.direction = g.direction;
    Vec3 corner(lo[0] - 0.5, lo[1] - 0.5, flip ? hi[2] + 0.5 : lo[2] - 0.5);
    out.geometry.origin = g.index_to_physical(corner);
    if (flip) out.geometry.direction.col(2) *= -1.0;
    const auto& d = out.geometry.dims;
    out.labels.resize(static_cast<std::size_t>(d[0] * d[1] * d[2]));
    for (std::int64_t k = 0; k < d[2]; ++k) {
        const std::int64_t source_k = flip ? hi[2] - k : lo[2] + k;
        for (std::int64_t j = 0; j < d[1]; ++j) {
            const std::uint16_t* row = volume.labels.data() + g.linear_index(lo[0], lo[1] + j, source_k);
            std::uint16_t* dst = out.labels.data() + d[0] * (j + d[1] * k);
            for (std::int64_t i = 0; i < d[0]; ++i) dst[i] = map[row[i]];
        }
    }
    return out;
}

LabelGrid resample_majority(const LabelGrid& source, const Index3& target, const std::string& what)
{
    const Index3& sd = source.geometry.dims;
    for (int a = 0; a < 3; ++a)
        if (target[a] < 1 || target[a] > sd[a])
            fail("{}: grid {}x{}x{} is larger than the {}x{}x{} cells it is built from along axis {} "
                 "(each target cell must hold at least one source cell)",
                 what, target[0], target[1], target[2], sd[0], sd[1], sd[2], a);
    // Compact label ids so that the vote table stays small.
    std::vector<std::int32_t> compact(65536, -1);
    std::vector<std::uint16_t> labels;
    for (auto l : source.labels)
        if (compact[l] < 0) {
            compact[l] = static_cast<std::int32_t>(labels.size());
            labels.push_back(l);
        }
    const std::size_t nl = labels.size();
    const std::int64_t target_cells = target[0] * target[1] * target[2];
    std::vector<std::int32_t> votes(static_cast<std::size_t>(target_cells) * nl, 0);
    std::array<std::vector<std::int64_t>, 3> bin;
    for (int a = 0; a < 3; ++a) {
        bin[a].resize(static_cast<std::size_t>(sd[a]));
        const double ratio = double(target[a]) / double(sd[a]);
        for (std::int64_t s = 0; s < sd[a]; ++s)
            bin[a][s] = std::min<std::int64_t>(target[a] - 1, static_cast<std::int64_t>((s + 0.5) * ratio));
    }
    for (std::int64_t k = 0; k < sd[2]; ++k)
        for (std::int64_t j = 0; j < sd[1]; ++j)
            for (std::int64_t i = 0; i < sd[0]; ++i) {
                const std::int64_t t = bin[0][i] + target[0] * (bin[1][j] + target[1] * bin[2][k]);
                ++votes[static_cast<std::size_t>(t) * nl + compact[source.at(i, j, k)]];
            }
    LabelGrid out;
    out.geometry = source.geometry;
    out.geometry.dims = target;
    for (int a = 0; a < 3; ++a) out.geometry.cell_size[a] = source.geometry.cell_size[a] * double(sd[a]) / double(target[a]);
    out.labels.resize(static_cast<std::size_t>(target_cells));
    for (std::int64_t t = 0; t < target_cells; ++t) {
        const std::int32_t* v = votes.data() + t * nl;
        std::size_t best = 0;
        for (std::size_t c = 1; c < nl; ++c) {
            const bool more = v[c] > v[best];
            const bool tie = v[c] == v[best];
            const bool better_tie = tie && (labels[best] == 0 || (labels[c] != 0 && labels[c] < labels[best]));
            if (more || better_tie) best = c;
        }
        out.labels[static_cast<std::size_t>(t)] = v[best] > 0 ? labels[best] : 0;
    }
    return out;
}

LabelGrid label_grid_of_mesh(const VolumeMesh& mesh)
{
    if (!mesh.grid || mesh.cell_type != CellType::hexahedron)
        fail("mesh: coarsening needs a hexahedral mesh built on a uniform grid (from a label volume)");
    Index3 lo{std::numeric_limits<std::int64_t>::max(), std::numeric_limits<std::int64_t>::max(),
              std::numeric_limits<std::int64_t>::max()};
    Index3 hi{-1, -1, -1};
    for (const auto& ijk : mesh.cell_grid_index)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], ijk[a]);
            hi[a] = std::max(hi[a], ijk[a]);
        }
    if (mesh.cell_count() == 0) fail("mesh: has no cells");
    LabelGrid out;
    out.geometry = *mesh.grid;
    out.geometry.dims = {hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1};
    out.geometry.origin = mesh.grid->node_position(lo[0], lo[1], lo[2]);
    const auto& d = out.geometry.dims;
    out.labels.assign(static_cast<std::size_t>(d[0] * d[1] * d[2]), 0);
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const auto& ijk = mesh.cell_grid_index[c];
        const auto label = mesh.cell_labels[c];
        if (label <= 0 || label > 65535) fail("mesh: cell {} has label {} (must be 1..65535)", c, label);
        out.labels[static_cast<std::size_t>((ijk[0] - lo[0]) + d[0] * ((ijk[1] - lo[1]) + d[1] * (ijk[2] - lo[2])))] =
            static_cast<std::uint16_t>(label);
    }
    return out;
}

VolumeMesh hex_mesh_from_label_grid(const LabelGrid& grid)
{
    const Index3& d = grid.geometry.dims;
    const Index3 nd{d[0] + 1, d[1] + 1, d[2] + 1};
    std::vector<std::int32_t> node_id(static_cast<std::size_t>(nd[0] * nd[1] * nd[2]), -1);
    VolumeMesh mesh;
    mesh.cell_type = CellType::hexahedron;
    mesh.grid = grid.geometry;
    std::size_t occupied = 0;
    for (auto l : grid.labels) occupied += l != 0;
    if (occupied > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max() / 8))
        fail("mesh: {} cells exceed the 32-bit index range", occupied);
    mesh.cells.reserve(8 * occupied);
    mesh.cell_labels.reserve(occupied);
    mesh.cell_grid_index.reserve(occupied);
    static constexpr int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                         {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
    // Nodes are numbered in the scan order of the node grid (x fastest), not in order of first
    // use: neighbours along x get consecutive numbers, so the elements of a row have node numbers
    // that advance by one from element to element, which the TLED force kernel loads and stores
    // as contiguous vectors (hexahedron_kernel.hpp), and a layer of elements touches two planes of
    // consecutive nodes.
    for (std::int64_t k = 0; k < d[2]; ++k)
        for (std::int64_t j = 0; j < d[1]; ++j)
            for (std::int64_t i = 0; i < d[0]; ++i) {
                if (!grid.at(i, j, k)) continue;
                for (const auto& c : corner) node_id[static_cast<std::size_t>(i + c[0] + nd[0] * (j + c[1] + nd[1] * (k + c[2])))] = 0;
            }
    for (std::int64_t nk = 0; nk < nd[2]; ++nk)
        for (std::int64_t nj = 0; nj < nd[1]; ++nj)
            for (std::int64_t ni = 0; ni < nd[0]; ++ni) {
                auto& id = node_id[static_cast<std::size_t>(ni + nd[0] * (nj + nd[1] * nk))];
                if (id < 0) continue;
                id = static_cast<std::int32_t>(mesh.nodes.size());
                mesh.nodes.push_back(grid.geometry.node_position(ni, nj, nk));
            }
    for (std::int64_t k = 0; k < d[2]; ++k)
        for (std::int64_t j = 0; j < d[1]; ++j)
            for (std::int64_t i = 0; i < d[0]; ++i) {
                const auto label = grid.at(i, j, k);
                if (!label) continue;
                for (const auto& c : corner)
                    mesh.cells.push_back(node_id[static_cast<std::size_t>(i + c[0] + nd[0] * (j + c[1] + nd[1] * (k + c[2])))]);
                mesh.cell_labels.push_back(label);
                mesh.cell_grid_index.push_back({i, j, k});
            }
    return mesh;
}

} // namespace physreg
