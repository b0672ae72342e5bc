// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/node_selection.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/faces.hpp"

#include <algorithm>
#include <limits>

namespace physreg {

std::vector<std::int32_t> select_nodes(const VolumeMesh& mesh, const NodeSelection& s, const std::string& what)
{
    const int ways = (s.axis ? 1 : 0) + (s.box_min || s.box_max ? 1 : 0) + (s.nodes.empty() ? 0 : 1);
    if (ways != 1) fail("{}: give exactly one of 'face', 'box' or 'nodes'", what);
    std::vector<bool> on_surface;
    if (s.surface_only) {
        on_surface.assign(mesh.node_count(), false);
        for (const auto& f : match_faces(mesh))
            if (f.neighbour < 0)
                for (int v = 0; v < f.node_count(); ++v) on_surface[f.nodes[v]] = true;
    }
    std::vector<std::int32_t> out;
    if (!s.nodes.empty()) {
        for (auto n : s.nodes)
            if (n < 0 || static_cast<std::size_t>(n) >= mesh.node_count())
                fail("{}: node {} does not exist (the mesh has {} nodes)", what, n, mesh.node_count());
        out = s.nodes;
    } else if (s.axis) {
        if (*s.axis < 0 || *s.axis > 2) fail("{}: axis must be x, y or z", what);
        if (s.side != "min" && s.side != "max") fail("{}: side '{}' must be min or max", what, s.side);
        if (!(s.tolerance_mm >= 0)) fail("{}: tolerance_mm must be ≥ 0", what);
        double extreme = s.side == "min" ? std::numeric_limits<double>::infinity() : -std::numeric_limits<double>::infinity();
        for (const auto& p : mesh.nodes) extreme = s.side == "min" ? std::min(extreme, p[*s.axis]) : std::max(extreme, p[*s.axis]);
        for (std::size_t n = 0; n < mesh.node_count(); ++n)
            if (std::abs(mesh.nodes[n][*s.axis] - extreme) <= s.tolerance_mm + 1e-9 * std::abs(extreme))
                out.push_back(static_cast<std::int32_t>(n));
    } else {
        if (!s.box_min || !s.box_max) fail("{}: a box needs min and max", what);
        if ((s.box_max.value() - s.box_min.value()).minCoeff() < 0) fail("{}: box max is below box min", what);
        for (std::size_t n = 0; n < mesh.node_count(); ++n) {
            const Vec3& p = mesh.nodes[n];
            if ((p - *s.box_min).minCoeff() >= 0 && (*s.box_max - p).minCoeff() >= 0) out.push_back(static_cast<std::int32_t>(n));
        }
    }
    if (s.surface_only) std::erase_if(out, [&](std::int32_t n) { return !on_surface[n]; });
    if (out.empty()) fail("{}: selects no node", what);
    return out;
}

} // namespace physreg
