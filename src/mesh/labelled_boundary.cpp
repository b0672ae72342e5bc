// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/labelled_boundary.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/faces.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace physreg {

BoundarySurface liver_boundary(const VolumeMesh& mesh, const std::function<bool(std::int32_t)>& keep,
                               std::optional<double> notch_x_mm)
{
    BoundarySurface s;
    const auto faces = match_faces(mesh);
    for (const auto& face : faces) {
        const bool inside_keep = keep(mesh.cell_labels[static_cast<std::size_t>(face.cell)]);
        const bool other_keep = face.neighbour >= 0 && keep(mesh.cell_labels[static_cast<std::size_t>(face.neighbour)]);
        if (!inside_keep || other_keep) continue;
        if (face.node_count() == 3) {
            s.triangles.push_back({face.nodes[0], face.nodes[1], face.nodes[2]});
        } else {
            s.triangles.push_back({face.nodes[0], face.nodes[1], face.nodes[2]});
            s.triangles.push_back({face.nodes[0], face.nodes[2], face.nodes[3]});
        }
    }
    // A face between a kept cell and a non-kept one is oriented from `cell`; when the kept cell is
    // the neighbour, match_faces oriented it the other way: the loop above only keeps faces whose
    // `cell` is kept, so the neighbour case needs its own pass.
    for (const auto& face : faces) {
        if (face.neighbour < 0) continue;
        const bool cell_keep = keep(mesh.cell_labels[static_cast<std::size_t>(face.cell)]);
        const bool neighbour_keep = keep(mesh.cell_labels[static_cast<std::size_t>(face.neighbour)]);
        if (cell_keep || !neighbour_keep) continue;
        if (face.node_count() == 3) {
            s.triangles.push_back({face.nodes[0], face.nodes[2], face.nodes[1]});
        } else {
            s.triangles.push_back({face.nodes[0], face.nodes[2], face.nodes[1]});
            s.triangles.push_back({face.nodes[0], face.nodes[3], face.nodes[2]});
        }
    }
    for (const auto& t : s.triangles) s.nodes.insert(s.nodes.end(), t.begin(), t.end());
    std::sort(s.nodes.begin(), s.nodes.end());
    s.nodes.erase(std::unique(s.nodes.begin(), s.nodes.end()), s.nodes.end());
    // Area-weighted vertex normals of the rest shape.
    std::vector<Vec3> normal(s.nodes.size(), Vec3::Zero());
    auto slot = [&](std::int32_t n) { return static_cast<std::size_t>(std::lower_bound(s.nodes.begin(), s.nodes.end(), n) - s.nodes.begin()); };
    for (const auto& t : s.triangles) {
        const Vec3 a = mesh.nodes[t[0]], b = mesh.nodes[t[1]], c = mesh.nodes[t[2]];
        const Vec3 area = 0.5 * (b - a).cross(c - a);
        for (const auto n : t) normal[slot(n)] += area;
    }
    const Vec3 margin_direction = Vec3(0, -1, -1).normalized();
    s.node_feature.assign(s.nodes.size(), feature_none);
    for (std::size_t q = 0; q < s.nodes.size(); ++q) {
        const Vec3 n = normal[q].normalized();
        const Vec3& p = mesh.nodes[static_cast<std::size_t>(s.nodes[q])];
        const bool margin = n.dot(margin_direction) > std::cos(35.0 * M_PI / 180.0);
        const bool inferior_or_margin = margin || n.dot(Vec3(0, 0, -1)) > 0.7 || n.dot(Vec3(0, -1, 0)) > 0.7;
        if (notch_x_mm && std::abs(p.x() - *notch_x_mm) <= 10.0 && inferior_or_margin && n.dot(margin_direction) > 0.3)
            s.node_feature[q] = feature_umbilical_notch;
        else if (margin)
            s.node_feature[q] = feature_anterior_margin;
    }
    return s;
}

void LabelledTriangles::validate(std::size_t node_count, const std::string& what) const
{
    if (triangles.size() != labels.size()) fail("{}: {} triangles but {} labels", what, triangles.size(), labels.size());
    if (triangles.empty()) fail("{}: no surface triangles", what);
    for (std::size_t t = 0; t < triangles.size(); ++t) {
        for (auto v : triangles[t])
            if (v < 0 || static_cast<std::size_t>(v) >= node_count)
                fail("{}: triangle {} has node {} outside the model's {} nodes", what, t, v, node_count);
        if (labels[t] < 0) fail("{}: triangle {} has negative label {}", what, t, labels[t]);
    }
}

LabelledTriangles labelled_triangles(const VolumeMesh& mesh, std::optional<double> notch_x_mm)
{
    const BoundarySurface b = liver_boundary(mesh, [](std::int32_t) { return true; }, notch_x_mm);
    LabelledTriangles out;
    out.triangles = b.triangles;
    out.labels.reserve(b.triangles.size());
    const auto feature = [&](std::int32_t node) {
        const auto q = std::lower_bound(b.nodes.begin(), b.nodes.end(), node) - b.nodes.begin();
        return b.node_feature[static_cast<std::size_t>(q)];
    };
    // A triangle takes a feature carried by at least two of its corners (the notch first).
    for (const auto& t : b.triangles) {
        int notch = 0, margin = 0;
        for (auto n : t) {
            const auto f = feature(n);
            notch += f == feature_umbilical_notch;
            margin += f == feature_anterior_margin || f == feature_umbilical_notch;
        }
        out.labels.push_back(notch >= 2 ? feature_umbilical_notch : margin >= 2 ? feature_anterior_margin : feature_none);
    }
    return out;
}

std::vector<std::int32_t> surface_nodes_facing(const VolumeMesh& mesh, const LabelledTriangles& surface, const Vec3& direction, double cosine)
{
    std::vector<Vec3> normal(mesh.node_count(), Vec3::Zero());
    for (const auto& t : surface.triangles) {
        const Vec3 area = 0.5 * (mesh.nodes[t[1]] - mesh.nodes[t[0]]).cross(mesh.nodes[t[2]] - mesh.nodes[t[0]]);
        for (auto n : t) normal[static_cast<std::size_t>(n)] += area;
    }
    std::vector<std::int32_t> out;
    for (std::size_t n = 0; n < normal.size(); ++n)
        if (normal[n].norm() > 0 && normal[n].normalized().dot(direction) > cosine) out.push_back(static_cast<std::int32_t>(n));
    return out;
}

std::vector<std::int32_t> surface_nodes_near(const VolumeMesh& mesh, const LabelledTriangles& surface, const std::vector<Vec3>& points, double radius_mm)
{
    if (!(radius_mm > 0) || !std::isfinite(radius_mm)) fail("support radius {} mm must be > 0", radius_mm);
    std::vector<std::uint8_t> on(mesh.node_count(), 0);
    for (const auto& t : surface.triangles)
        for (auto n : t) on[static_cast<std::size_t>(n)] = 1;
    std::vector<std::int32_t> out;
    for (std::size_t n = 0; n < on.size(); ++n) {
        if (!on[n]) continue;
        for (const auto& p : points)
            if ((mesh.nodes[n] - p).norm() <= radius_mm) {
                out.push_back(static_cast<std::int32_t>(n));
                break;
            }
    }
    return out;
}

LabelledTriangles unlabelled_boundary(const VolumeMesh& mesh)
{
    LabelledTriangles out = labelled_triangles(mesh, std::nullopt);
    std::fill(out.labels.begin(), out.labels.end(), feature_none);
    return out;
}

} // namespace physreg
