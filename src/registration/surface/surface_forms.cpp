// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/surface/surface_forms.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>

namespace physreg {

PairPotentialForm::PairPotentialForm(std::vector<SurfacePair> pairs, const LabelledTriangles& source, std::map<std::int32_t, double> stiffness_n,
                                     ArctanForceLaw law, const std::vector<double>& rest_mm)
    : m_pairs(std::move(pairs)), m_source(source), m_k(std::move(stiffness_n)), m_law(law), m_rest(rest_mm)
{
    m_law.validate();
    for (const auto& p : m_pairs) {
        if (!m_k.count(p.label)) fail("pair potential: no stiffness for label {}", p.label);
        if (p.triangle < 0 || static_cast<std::size_t>(p.triangle) >= m_source.triangles.size())
            fail("pair potential: pair of cloud point {} names triangle {}, not one of the surface's {}", p.point, p.triangle, m_source.triangles.size());
    }
}

Vec3 PairPotentialForm::gap(const SurfacePair& p, std::span<const double> u) const
{
    Vec3 source = Vec3::Zero();
    const auto& tri = m_source.triangles[static_cast<std::size_t>(p.triangle)];
    for (int c = 0; c < 3; ++c) {
        const auto q = 3 * static_cast<std::size_t>(tri[c]);
        source += p.weights[c] * Vec3(m_rest[q] + u[q], m_rest[q + 1] + u[q + 1], m_rest[q + 2] + u[q + 2]);
    }
    return p.target - source;
}

double PairPotentialForm::value(std::span<const double> u) const
{
    double e = 0.0;
    for (const auto& p : m_pairs) e += m_law.potential(m_k.at(p.label), gap(p, u).norm());
    return e;
}

void PairPotentialForm::gradient(std::span<const double> u, std::span<double> g) const
{
    // ∂ψ/∂source = −ψ'(d) p̂, spread on the corners by the weights: minus the pair force of
    // accumulate_pair_forces, which uses the same law.magnitude.
    std::fill(g.begin(), g.end(), 0.0);
    for (const auto& p : m_pairs) {
        const Vec3 gap_mm = gap(p, u);
        const double d = gap_mm.norm();
        if (d == 0) continue;
        const Vec3 force = m_law.magnitude(m_k.at(p.label), d) / d * gap_mm;
        const auto& tri = m_source.triangles[static_cast<std::size_t>(p.triangle)];
        for (int c = 0; c < 3; ++c)
            for (int i = 0; i < 3; ++i) g[3 * static_cast<std::size_t>(tri[c]) + i] -= p.weights[c] * force[i];
    }
}

bool PairPotentialForm::hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const
{
    // ∂²ψ/∂source² = ψ''(d) p̂p̂ᵀ + ψ'(d)/d (I − p̂p̂ᵀ).
    std::fill(product.begin(), product.end(), 0.0);
    for (const auto& p : m_pairs) {
        const Vec3 gap_mm = gap(p, u);
        const double d = gap_mm.norm();
        const double k = m_k.at(p.label);
        const auto& tri = m_source.triangles[static_cast<std::size_t>(p.triangle)];
        Vec3 moved = Vec3::Zero();
        for (int c = 0; c < 3; ++c) {
            const auto q = 3 * static_cast<std::size_t>(tri[c]);
            moved += p.weights[c] * Vec3(v[q], v[q + 1], v[q + 2]);
        }
        Vec3 hv;
        if (d > 0) {
            const Vec3 n = gap_mm / d;
            const double along = n.dot(moved);
            hv = m_law.radial_stiffness(k, d) * along * n + m_law.magnitude(k, d) / d * (moved - along * n);
        } else {
            hv = m_law.radial_stiffness(k, 0.0) * moved; // isotropic at d = 0
        }
        for (int c = 0; c < 3; ++c)
            for (int i = 0; i < 3; ++i) product[3 * static_cast<std::size_t>(tri[c]) + i] += p.weights[c] * hv[i];
    }
    return true;
}

double SurfaceAdjointForm::value(std::span<const double> f) const
{
    std::vector<double> unused;
    return adjoint_surface_objective(m_mesh, m_matcher, m_cloud, m_options, m_alpha, std::vector<double>(f.begin(), f.end()), unused, m_linearisation);
}

void SurfaceAdjointForm::gradient(std::span<const double> f, std::span<double> g) const
{
    std::vector<double> gradient;
    adjoint_surface_objective(m_mesh, m_matcher, m_cloud, m_options, m_alpha, std::vector<double>(f.begin(), f.end()), gradient, m_linearisation);
    if (gradient.size() != g.size()) fail("{}: the objective gave {} gradient entries for {} unknowns", name(), gradient.size(), g.size());
    std::copy(gradient.begin(), gradient.end(), g.begin());
}

} // namespace physreg
