// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/model.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/labelled_boundary.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace physreg {

void Model::validate(const std::string& what) const
{
    mesh.validate(what);
    if (mesh.cell_count() == 0) fail("{}: the model's mesh has no cell", what);
    tissues.validate(what);
    std::set<std::int32_t> labels(mesh.cell_labels.begin(), mesh.cell_labels.end());
    for (const auto label : labels)
        if (!tissues.find(label)) fail("{}: cell label {} has no tissue in the model's tissue table", what, label);
    const auto n = mesh.node_count();
    for (const auto& s : supports) {
        if (s.displacement_mm != Vec3::Zero()) fail("{}: support '{}' prescribes a displacement; a model's supports hold (zero)", what, s.name);
        for (const auto node : s.nodes)
            if (node < 0 || static_cast<std::size_t>(node) >= n) fail("{}: support '{}' names node {}, not a node of the model ({} nodes)", what, s.name, node, n);
    }
    surface.validate(n, what + ": surface");
    for (const auto& s : structures)
        if (!s) fail("{}: a null auxiliary structure", what);
    if (coupling && coupling->node_count() != n)
        fail("{}: the tissue coupling is over {} nodes, the mesh has {}", what, coupling->node_count(), n);
}

std::vector<std::int32_t> Model::held_nodes() const
{
    std::vector<std::int32_t> out;
    for (const auto& s : supports)
        if (s.dofs[0] && s.dofs[1] && s.dofs[2]) out.insert(out.end(), s.nodes.begin(), s.nodes.end());
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

std::vector<NodeConstraint> Model::partial_supports() const
{
    std::vector<NodeConstraint> out;
    for (const auto& s : supports)
        if (!(s.dofs[0] && s.dofs[1] && s.dofs[2]) && (s.dofs[0] || s.dofs[1] || s.dofs[2]) && !s.nodes.empty()) out.push_back(s);
    return out;
}

double Model::surface_young_modulus_pa() const
{
    std::vector<std::uint8_t> on_surface(mesh.node_count(), 0);
    for (const auto& t : surface.triangles)
        for (const auto node : t) on_surface[static_cast<std::size_t>(node)] = 1;
    double softest = std::numeric_limits<double>::infinity();
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const auto cell = mesh.cell(c);
        if (std::none_of(cell.begin(), cell.end(), [&](std::int32_t node) { return on_surface[static_cast<std::size_t>(node)] != 0; })) continue;
        if (const Tissue* t = tissues.find(mesh.cell_labels[c])) softest = std::min(softest, t->young_modulus_pa);
    }
    if (!std::isfinite(softest)) fail("model: no cell touches the model's surface (is the surface empty?)");
    return softest;
}

std::vector<const AuxiliaryElements*> Model::structure_pointers() const
{
    std::vector<const AuxiliaryElements*> out;
    for (const auto& s : structures) out.push_back(s.get());
    return out;
}

LabelledTriangles cell_group_boundary(const VolumeMesh& mesh, const std::function<bool(std::int32_t)>& keep, const std::string& what)
{
    if (std::none_of(mesh.cell_labels.begin(), mesh.cell_labels.end(), keep)) fail("{}: no cell of the mesh belongs to the surface's labels", what);
    const BoundarySurface b = liver_boundary(mesh, keep, std::nullopt);
    LabelledTriangles out;
    out.triangles = b.triangles;
    out.labels.assign(out.triangles.size(), feature_none);
    return out;
}

} // namespace physreg
