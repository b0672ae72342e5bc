// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/model/loads.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace physreg {

double smooth_step(double tau)
{
    tau = std::clamp(tau, 0.0, 1.0);
    return tau * tau * tau * (10.0 - 15.0 * tau + 6.0 * tau * tau);
}

IndenterShape parse_indenter_shape(const std::string& text)
{
    if (text == "sphere") return IndenterShape::sphere;
    if (text == "cylinder") return IndenterShape::cylinder;
    if (text == "plane") return IndenterShape::plane;
    if (text == "box") return IndenterShape::box;
    fail("indenter shape '{}' is not one of sphere, cylinder, plane, box", text);
}

Vec3 Indenter::position(double s) const
{
    if (path.size() == 1) return path.front();
    s = std::clamp(s, 0.0, 1.0) * double(path.size() - 1);
    const std::size_t i = std::min(path.size() - 2, static_cast<std::size_t>(s));
    const double t = s - double(i);
    return (1.0 - t) * path[i] + t * path[i + 1];
}

bool Indenter::push_out(const Vec3& x, double s, Vec3& surface_point, Vec3& normal) const
{
    const Vec3 c = position(s);
    switch (shape) {
    case IndenterShape::sphere: {
        const Vec3 d = x - c;
        const double r = d.norm();
        if (r >= radius_mm) return false;
        normal = r > 0 ? Vec3(d / r) : Vec3::UnitZ();
        surface_point = c + radius_mm * normal;
        return true;
    }
    case IndenterShape::cylinder: {
        const Vec3 d = x - c;
        const Vec3 radial = d - d.dot(axis) * axis;
        const double r = radial.norm();
        if (r >= radius_mm) return false;
        normal = r > 0 ? Vec3(radial / r) : axis.unitOrthogonal();
        surface_point = x + (radius_mm - r) * normal;
        return true;
    }
    case IndenterShape::plane: {
        const double depth = (x - c).dot(axis);
        if (depth >= 0) return false;
        normal = axis;
        surface_point = x - depth * axis;
        return true;
    }
    case IndenterShape::box: {
        const Vec3 local = rotation.transpose() * (x - c);
        int best = -1;
        double least = 0.0;
        for (int a = 0; a < 3; ++a) {
            const double gap = half_extents_mm[a] - std::abs(local[a]);
            if (gap <= 0) return false;
            if (best < 0 || gap < least) {
                least = gap;
                best = a;
            }
        }
        Vec3 n = Vec3::Zero();
        n[best] = local[best] >= 0 ? 1.0 : -1.0;
        normal = rotation * n;
        surface_point = x + least * normal;
        return true;
    }
    }
    return false;
}

void Indenter::closest_surface_point(const Vec3& x, double s, Vec3& surface_point, Vec3& normal) const
{
    if (push_out(x, s, surface_point, normal)) return;
    const Vec3 c = position(s);
    switch (shape) {
    case IndenterShape::sphere: {
        const Vec3 d = x - c;
        normal = d.norm() > 0 ? Vec3(d.normalized()) : Vec3::UnitZ();
        surface_point = c + radius_mm * normal;
        return;
    }
    case IndenterShape::cylinder: {
        const Vec3 d = x - c;
        const Vec3 radial = d - d.dot(axis) * axis;
        normal = radial.norm() > 0 ? Vec3(radial.normalized()) : axis.unitOrthogonal();
        surface_point = x + (radius_mm - radial.norm()) * normal;
        return;
    }
    case IndenterShape::plane:
        normal = axis;
        surface_point = x - (x - c).dot(axis) * axis;
        return;
    case IndenterShape::box: {
        const Vec3 local = rotation.transpose() * (x - c);
        const Vec3 clamped = local.cwiseMax(-half_extents_mm).cwiseMin(half_extents_mm);
        surface_point = c + rotation * clamped;
        const Vec3 d = local - clamped;
        normal = d.norm() > 0 ? Vec3(rotation * d.normalized()) : Vec3(rotation.col(0));
        return;
    }
    }
}

double Indenter::reach_mm() const
{
    switch (shape) {
    case IndenterShape::sphere: return radius_mm;
    case IndenterShape::box: return half_extents_mm.norm();
    case IndenterShape::cylinder:
    case IndenterShape::plane: return std::numeric_limits<double>::infinity();
    }
    return std::numeric_limits<double>::infinity();
}

void Indenter::validate() const
{
    const std::string who = "indenter '" + name + "'";
    if (path.empty()) fail("{}: needs at least one position", who);
    for (const auto& p : path)
        if (!p.allFinite()) fail("{}: a path position is not finite", who);
    if ((shape == IndenterShape::sphere || shape == IndenterShape::cylinder) && !(radius_mm > 0 && std::isfinite(radius_mm)))
        fail("{}: radius_mm = {} must be positive", who, radius_mm);
    if ((shape == IndenterShape::cylinder || shape == IndenterShape::plane) && std::abs(axis.norm() - 1.0) > 1e-9)
        fail("{}: axis/normal must be a unit vector", who);
    if (shape == IndenterShape::box && !(half_extents_mm.minCoeff() > 0 && half_extents_mm.allFinite()))
        fail("{}: half_extents_mm must be positive", who);
}

double face_span_mm(const std::array<Vec3, 4>& x, int count)
{
    return count == 4 ? std::max((x[0] - x[2]).norm(), (x[1] - x[3]).norm())
                      : std::max({(x[0] - x[1]).norm(), (x[1] - x[2]).norm(), (x[2] - x[0]).norm()});
}

FaceContactSamples face_contact_samples(const Indenter& tool, const std::array<Vec3, 4>& corners, int count)
{
    FaceContactSamples out;
    if (tool.shape == IndenterShape::plane) return out;
    const double radius = tool.shape == IndenterShape::box ? tool.half_extents_mm.minCoeff() : tool.radius_mm;
    const double span = face_span_mm(corners, count), half = 0.5 * span;
    const double sag = half < radius ? radius - std::sqrt(radius * radius - half * half) : radius;
    out.allowance_mm = std::min(sag, 0.2 * radius);
    const int n = std::clamp(static_cast<int>(std::ceil(span / (0.25 * radius))), 2, 8);
    if (count == 4) {
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) {
                const double xi = (i + 0.5) / n, eta = (j + 0.5) / n;
                out.weights.push_back({(1 - xi) * (1 - eta), xi * (1 - eta), xi * eta, (1 - xi) * eta});
            }
    } else {
        // Centroids of the n² sub-triangles: n(n+1)/2 upright, n(n−1)/2 inverted.
        for (int i = 0; i < n; ++i)
            for (int j = 0; i + j < n; ++j) {
                const double b1 = (i + 1.0 / 3.0) / n, b2 = (j + 1.0 / 3.0) / n;
                out.weights.push_back({1 - b1 - b2, b1, b2, 0.0});
                if (i + j < n - 1) {
                    const double c1 = (i + 2.0 / 3.0) / n, c2 = (j + 2.0 / 3.0) / n;
                    out.weights.push_back({1 - c1 - c2, c1, c2, 0.0});
                }
            }
    }
    return out;
}

void Loads::validate(std::size_t node_count) const
{
    for (const auto& c : constraints) {
        if (c.nodes.empty()) fail("constraint '{}': selects no node", c.name);
        for (auto n : c.nodes)
            if (n < 0 || static_cast<std::size_t>(n) >= node_count)
                fail("constraint '{}': node {} does not exist (the mesh has {} nodes)", c.name, n, node_count);
        if (!c.displacement_mm.allFinite()) fail("constraint '{}': displacement is not finite", c.name);
    }
    for (const auto& i : indenters) i.validate();
    if (!external_forces_n.empty()) {
        if (external_forces_n.size() != 3 * node_count)
            fail("external forces: {} values for {} nodes (3 per node expected)", external_forces_n.size(), node_count);
        for (std::size_t k = 0; k < external_forces_n.size(); ++k)
            if (!std::isfinite(external_forces_n[k])) fail("external forces: node {} has a non-finite force", k / 3);
    }
    if (!(ramp_time_s >= 0 && std::isfinite(ramp_time_s))) fail("ramp_time_s = {} must be ≥ 0", ramp_time_s);
}

} // namespace physreg
