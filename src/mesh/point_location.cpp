// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/point_location.hpp"

#include "physreg/core/error.hpp"

#include <Eigen/LU>
#include <cmath>
#include <limits>

namespace physreg {

std::vector<double> shape_weights(CellType type, const Vec3& xi)
{
    if (type == CellType::tetrahedron) return {1.0 - xi.sum(), xi[0], xi[1], xi[2]};
    const auto n = hex_shape_functions(xi);
    return {n.begin(), n.end()};
}

Vec3 natural_coordinates(const VolumeMesh& mesh, std::size_t c, const Vec3& point, bool& converged)
{
    const auto ids = mesh.cell(c);
    converged = true;
    if (mesh.cell_type == CellType::tetrahedron) {
        const Vec3& p0 = mesh.nodes[ids[0]];
        Mat3 m;
        m << mesh.nodes[ids[1]] - p0, mesh.nodes[ids[2]] - p0, mesh.nodes[ids[3]] - p0;
        return m.fullPivLu().solve(point - p0);
    }
    Vec3 xi = Vec3::Zero();
    for (int iteration = 0; iteration < 30; ++iteration) {
        Vec3 x = Vec3::Zero();
        Mat3 jacobian = Mat3::Zero();
        const auto n = hex_shape_functions(xi);
        for (int a = 0; a < 8; ++a) {
            const Vec3 corner = hex_corner_natural(a);
            const Vec3 dn(0.125 * corner[0] * (1 + corner[1] * xi[1]) * (1 + corner[2] * xi[2]),
                          0.125 * corner[1] * (1 + corner[0] * xi[0]) * (1 + corner[2] * xi[2]),
                          0.125 * corner[2] * (1 + corner[0] * xi[0]) * (1 + corner[1] * xi[1]));
            x += n[a] * mesh.nodes[ids[a]];
            jacobian += mesh.nodes[ids[a]] * dn.transpose();
        }
        const Vec3 step = jacobian.fullPivLu().solve(point - x);
        xi += step;
        if (!xi.allFinite()) break;
        if (step.norm() < 1e-12) return xi;
    }
    converged = false;
    return xi;
}

PointLocator::PointLocator(const VolumeMesh& mesh) : m_mesh(mesh)
{
    if (mesh.cell_count() == 0) fail("point location: the mesh has no cells");
    m_lower = Vec3::Constant(std::numeric_limits<double>::infinity());
    Vec3 upper = -m_lower;
    for (const auto& p : mesh.nodes) {
        m_lower = m_lower.cwiseMin(p);
        upper = upper.cwiseMax(p);
    }
    const Vec3 extent = (upper - m_lower).cwiseMax(1e-9);
    const double per_axis = std::cbrt(double(mesh.cell_count()) / (extent.prod() / std::pow(extent.maxCoeff(), 3)));
    for (int a = 0; a < 3; ++a)
        m_bins[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>(per_axis * extent[a] / extent.maxCoeff()), 1, 512);
    m_bin_size = extent.cwiseQuotient(Vec3(double(m_bins[0]), double(m_bins[1]), double(m_bins[2])));
    const std::size_t bin_count = static_cast<std::size_t>(m_bins[0] * m_bins[1] * m_bins[2]);
    auto bin_range = [&](std::size_t c, Index3& lo, Index3& hi) {
        Vec3 cmin = Vec3::Constant(std::numeric_limits<double>::infinity()), cmax = -cmin;
        for (auto n : mesh.cell(c)) {
            cmin = cmin.cwiseMin(mesh.nodes[n]);
            cmax = cmax.cwiseMax(mesh.nodes[n]);
        }
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>((cmin[a] - m_lower[a]) / m_bin_size[a]), 0, m_bins[a] - 1);
            hi[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>((cmax[a] - m_lower[a]) / m_bin_size[a]), 0, m_bins[a] - 1);
        }
    };
    std::vector<std::int32_t> count(bin_count + 1, 0);
    for (int pass = 0; pass < 2; ++pass) {
        std::vector<std::int32_t> fill;
        if (pass == 1) {
            m_bin_start.assign(bin_count + 1, 0);
            for (std::size_t b = 0; b < bin_count; ++b) m_bin_start[b + 1] = m_bin_start[b] + count[b];
            m_bin_cells.resize(static_cast<std::size_t>(m_bin_start.back()));
            fill.assign(m_bin_start.begin(), m_bin_start.end() - 1);
        }
        for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
            Index3 lo, hi;
            bin_range(c, lo, hi);
            for (auto k = lo[2]; k <= hi[2]; ++k)
                for (auto j = lo[1]; j <= hi[1]; ++j)
                    for (auto i = lo[0]; i <= hi[0]; ++i) {
                        const auto b = static_cast<std::size_t>(i + m_bins[0] * (j + m_bins[1] * k));
                        if (pass == 0) ++count[b];
                        else m_bin_cells[static_cast<std::size_t>(fill[b]++)] = static_cast<std::int32_t>(c);
                    }
        }
    }
}

std::optional<NodeEmbedding> PointLocator::locate(const Vec3& point) const
{
    constexpr double tolerance = 1e-6;
    if (!point.allFinite()) return std::nullopt;
    Index3 b;
    for (int a = 0; a < 3; ++a) {
        const double t = (point[a] - m_lower[a]) / m_bin_size[a];
        if (t < -tolerance || t > double(m_bins[a]) + tolerance) return std::nullopt;
        b[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>(t), 0, m_bins[a] - 1);
    }
    const auto bin = static_cast<std::size_t>(b[0] + m_bins[0] * (b[1] + m_bins[1] * b[2]));
    for (auto s = m_bin_start[bin]; s < m_bin_start[bin + 1]; ++s) {
        const auto c = static_cast<std::size_t>(m_bin_cells[static_cast<std::size_t>(s)]);
        bool converged = false;
        const Vec3 xi = natural_coordinates(m_mesh, c, point, converged);
        if (!converged) continue;
        const bool inside = m_mesh.cell_type == CellType::hexahedron
                                ? xi.cwiseAbs().maxCoeff() <= 1.0 + tolerance
                                : xi.minCoeff() >= -tolerance && xi.sum() <= 1.0 + tolerance;
        if (inside) return NodeEmbedding{static_cast<std::int32_t>(c), xi, true, 0.0};
    }
    return std::nullopt;
}

NodeEmbedding PointLocator::locate_or_throw(const Vec3& point, const std::string& name) const
{
    if (!point.allFinite()) fail("{}: position is not finite", name);
    if (auto e = locate(point)) return *e;
    double nearest = std::numeric_limits<double>::infinity();
    for (const auto& p : m_mesh.nodes) nearest = std::min(nearest, (p - point).norm());
    fail("{} at ({:.3f}, {:.3f}, {:.3f}) mm LPS lies outside the mesh (nearest mesh node {:.3f} mm away)", name,
         point[0], point[1], point[2], nearest);
}

std::vector<double> interpolate_nodal(const VolumeMesh& mesh, const NodeEmbedding& where,
                                      const std::vector<double>& field, int components)
{
    if (field.size() != mesh.node_count() * static_cast<std::size_t>(components))
        fail("interpolation: field has {} values, expected {} ({} per node)", field.size(),
             mesh.node_count() * components, components);
    const auto weights = shape_weights(mesh.cell_type, where.natural);
    const auto ids = mesh.cell(static_cast<std::size_t>(where.cell));
    std::vector<double> out(static_cast<std::size_t>(components), 0.0);
    for (std::size_t a = 0; a < weights.size(); ++a)
        for (int c = 0; c < components; ++c) out[c] += weights[a] * field[ids[a] * components + c];
    return out;
}

std::vector<NodeEmbedding> embed_landmarks(const VolumeMesh& mesh, const LandmarkSet& points, double max_distance_mm, const std::string& what)
{
    if (mesh.cell_type != CellType::tetrahedron) fail("embedding landmarks in {}: tetrahedral meshes only", what);
    const PointLocator locator(mesh);
    std::vector<NodeEmbedding> out;
    for (const auto& l : points) {
        if (auto e = locator.locate(l.position)) {
            out.push_back(*e);
            continue;
        }
        NodeEmbedding best;
        best.distance_mm = std::numeric_limits<double>::infinity();
        for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
            const auto ids = mesh.cell(c);
            if ((mesh.nodes[ids[0]] - l.position).norm() > best.distance_mm + 50.0) continue;
            bool ok = true;
            Vec3 xi = natural_coordinates(mesh, c, l.position, ok);
            if (!ok) continue;
            // Clamp to the simplex: negative barycentric weights to zero, renormalised.
            double w[4] = {1.0 - xi.sum(), xi[0], xi[1], xi[2]}, sum = 0;
            for (double& v : w) sum += (v = std::max(0.0, v));
            for (double& v : w) v /= sum;
            const Vec3 q = w[0] * mesh.nodes[ids[0]] + w[1] * mesh.nodes[ids[1]] + w[2] * mesh.nodes[ids[2]] + w[3] * mesh.nodes[ids[3]];
            const double d = (q - l.position).norm();
            if (d < best.distance_mm) best = {static_cast<std::int32_t>(c), Vec3(w[1], w[2], w[3]), false, d};
        }
        if (!(best.distance_mm <= max_distance_mm))
            fail("landmark {} lies {:.2f} mm outside {} (at most {:.1f} mm allowed)", l.name, best.distance_mm, what,
                 max_distance_mm);
        out.push_back(best);
    }
    return out;
}

LandmarkSet displace_landmarks(const VolumeMesh& mesh, const std::vector<NodeEmbedding>& where, const LandmarkSet& rest, const std::vector<double>& u)
{
    if (where.size() != rest.size()) fail("displace_landmarks: {} embeddings for {} landmarks", where.size(), rest.size());
    LandmarkSet out = rest;
    for (std::size_t i = 0; i < rest.size(); ++i) {
        const auto d = interpolate_nodal(mesh, where[i], u, 3);
        out[i].position += Vec3(d[0], d[1], d[2]);
    }
    return out;
}

} // namespace physreg
