// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/elements/membrane.hpp"

#include "physreg/core/error.hpp"

#include <Eigen/SVD>
#include <cmath>

namespace physreg {

void MembraneMaterial::validate(const std::string& what) const
{
    if (!(young_modulus_pa > 0 && std::isfinite(young_modulus_pa))) fail("{}: membrane Young's modulus {} Pa must be > 0", what, young_modulus_pa);
    if (!(poisson_ratio > -1 && poisson_ratio < 0.5)) fail("{}: membrane Poisson's ratio {} must be in (-1, 0.5)", what, poisson_ratio);
    if (!(thickness_mm > 0 && std::isfinite(thickness_mm))) fail("{}: membrane thickness {} mm must be > 0", what, thickness_mm);
}

namespace {
Vec3 node(const std::vector<double>& x, std::int32_t n) { return {x[3 * n], x[3 * n + 1], x[3 * n + 2]}; }
} // namespace

Membrane::Membrane(const std::vector<std::array<std::int32_t, 3>>& triangles, const std::vector<double>& rest, const MembraneMaterial& material,
                   const std::string& what)
    : m_rest(rest)
{
    material.validate(what);
    const double e = material.young_modulus_pa * 1e-6, nu = material.poisson_ratio; // MPa
    m_d << 1, nu, 0, nu, 1, 0, 0, 0, (1 - nu) / 2;
    m_d *= e / (1 - nu * nu) * material.thickness_mm;
    const auto nodes = static_cast<std::int32_t>(rest.size() / 3);
    for (std::size_t t = 0; t < triangles.size(); ++t) {
        const auto& tri = triangles[t];
        for (auto n : tri)
            if (n < 0 || n >= nodes) fail("{}: membrane triangle {} has node {} outside the model's {} nodes", what, t, n, nodes);
        const Vec3 a = node(rest, tri[0]), b = node(rest, tri[1]), c = node(rest, tri[2]);
        const Vec3 normal = (b - a).cross(c - a);
        const double area = 0.5 * normal.norm();
        if (!(area > 1e-12)) fail("{}: membrane triangle {} (nodes {}, {}, {}) is degenerate", what, t, tri[0], tri[1], tri[2]);
        // The rest triangle's 2-D frame: e1 along a→b, e2 in the plane.
        const Vec3 e1 = (b - a).normalized(), e2 = normal.normalized().cross(e1);
        Eigen::Matrix2d x;
        x << (b - a).dot(e1), (c - a).dot(e1), (b - a).dot(e2), (c - a).dot(e2);
        Element el;
        el.nodes = tri;
        el.area_mm2 = area;
        el.rest_inverse = x.inverse();
        // ∇N_1 and ∇N_2 are the rows of X⁻¹; ∇N_0 = −(∇N_1 + ∇N_2).
        for (int k = 0; k < 2; ++k) {
            el.gradient[2 + k] = el.rest_inverse(0, k);
            el.gradient[4 + k] = el.rest_inverse(1, k);
            el.gradient[k] = -el.rest_inverse(0, k) - el.rest_inverse(1, k);
        }
        m_triangles.push_back(el);
    }
}

std::vector<std::vector<std::int32_t>> Membrane::stencils() const
{
    std::vector<std::vector<std::int32_t>> out;
    for (const auto& e : m_triangles) out.push_back({e.nodes[0], e.nodes[1], e.nodes[2]});
    return out;
}

double Membrane::total_area_mm2() const
{
    double sum = 0.0;
    for (const auto& e : m_triangles) sum += e.area_mm2;
    return sum;
}

void Membrane::rotation_and_strain(const Element& e, const double* u, Eigen::Matrix<double, 3, 2>& q, Eigen::Vector3d& strain) const
{
    Vec3 x[3];
    for (int a = 0; a < 3; ++a) {
        const auto n = e.nodes[a];
        x[a] = node(m_rest, n) + Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]);
    }
    Eigen::Matrix<double, 3, 2> dx;
    dx.col(0) = x[1] - x[0];
    dx.col(1) = x[2] - x[0];
    const Eigen::Matrix<double, 3, 2> f = dx * e.rest_inverse;
    const Eigen::JacobiSVD<Eigen::Matrix<double, 3, 2>> svd(f, Eigen::ComputeFullU | Eigen::ComputeFullV);
    q = svd.matrixU().leftCols<2>() * svd.matrixV().transpose();
    const Eigen::Matrix2d s = svd.matrixV() * svd.singularValues().asDiagonal() * svd.matrixV().transpose();
    strain << s(0, 0) - 1, s(1, 1) - 1, 2 * s(0, 1);
}

double Membrane::add_forces(const double* u, double* f) const
{
    double energy = 0.0;
    Eigen::Matrix<double, 3, 2> q;
    Eigen::Vector3d strain;
    for (const auto& e : m_triangles) {
        rotation_and_strain(e, u, q, strain);
        const Eigen::Vector3d stress = m_d * strain; // N/mm (membrane resultants)
        energy += 0.5 * e.area_mm2 * strain.dot(stress);
        Eigen::Matrix2d sigma;
        sigma << stress[0], stress[2], stress[2], stress[1];
        for (int a = 0; a < 3; ++a) {
            const Eigen::Vector2d g(e.gradient[2 * a], e.gradient[2 * a + 1]);
            const Vec3 fa = e.area_mm2 * q * (sigma * g);
            for (int d = 0; d < 3; ++d) f[3 * e.nodes[a] + d] += fa[d];
        }
    }
    return energy;
}

void Membrane::add_stiffness(const double* u, const StiffnessAssembler& assembler, double* values) const
{
    Eigen::Matrix<double, 3, 2> q;
    Eigen::Vector3d strain;
    for (const auto& e : m_triangles) {
        rotation_and_strain(e, u, q, strain);
        // B_a (3×2, Voigt) maps an in-plane corner displacement to the strain.
        Eigen::Matrix<double, 3, 2> b[3];
        for (int a = 0; a < 3; ++a) {
            const double gx = e.gradient[2 * a], gy = e.gradient[2 * a + 1];
            b[a] << gx, 0, 0, gy, gy, gx;
        }
        for (int a = 0; a < 3; ++a)
            for (int c = 0; c < 3; ++c) {
                const Eigen::Matrix3d k = e.area_mm2 * q * (b[a].transpose() * m_d * b[c]) * q.transpose();
                for (int r = 0; r < 3; ++r)
                    for (int s = 0; s < 3; ++s) values[assembler.value_index(e.nodes[a], e.nodes[c], r, s)] += k(r, s);
            }
    }
}

} // namespace physreg
