// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/forms/mechanics_forms.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mechanics/elements/tled_model.hpp"
#include "physreg/mechanics/implicit/newton_solver.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace physreg {
namespace {

void multiply(const SparseMatrix& k, std::span<const double> v, std::span<double> product)
{
    Eigen::Map<Eigen::VectorXd>(product.data(), static_cast<Eigen::Index>(product.size())) =
        k * Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

} // namespace

// ---- elastic energy ----------------------------------------------------------------------------

std::string ElasticForm::name() const
{
    return fmt::format("elastic energy ({}{})", to_string(m_assembler.model().options().law), m_assembler.coupling() ? " + tissue coupling" : "");
}

double ElasticForm::value(std::span<const double> u) const
{
    const Assembly a = m_assembler.energy(u.data());
    if (a.inverted_element >= 0) fail("{}: element {} is inverted at this displacement", name(), a.inverted_element);
    return a.energy_mj;
}

void ElasticForm::gradient(std::span<const double> u, std::span<double> g) const
{
    const Assembly a = m_assembler.assemble(u.data(), g.data(), nullptr);
    if (a.inverted_element >= 0) fail("{}: element {} is inverted at this displacement", name(), a.inverted_element);
}

bool ElasticForm::hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const
{
    SparseMatrix k = m_assembler.make_matrix();
    std::vector<double> f(u.size());
    const Assembly a = m_assembler.assemble(u.data(), f.data(), &k);
    if (a.inverted_element >= 0) fail("{}: element {} is inverted at this displacement", name(), a.inverted_element);
    multiply(k, v, product);
    return true;
}

// ---- tissue coupling ---------------------------------------------------------------------------

void CouplingForm::gradient(std::span<const double> u, std::span<double> g) const
{
    std::fill(g.begin(), g.end(), 0.0);
    m_coupling.add_forces(u.data(), g.data());
}

bool CouplingForm::hessian_product(std::span<const double>, std::span<const double> v, std::span<double> product) const
{
    // Point i's energy ½ k_i |Σ φ u|² has the Hessian k_i φ φᵀ ⊗ I₃.
    std::fill(product.begin(), product.end(), 0.0);
    for (std::size_t i = 0; i < m_coupling.points().size(); ++i) {
        Vec3 gap = Vec3::Zero();
        const auto entries = m_coupling.point_entries(i);
        for (const auto& e : entries) gap += e.phi * Vec3(v[3 * e.node], v[3 * e.node + 1], v[3 * e.node + 2]);
        gap *= m_coupling.point_stiffness_n_per_mm(i);
        for (const auto& e : entries)
            for (int d = 0; d < 3; ++d) product[3 * static_cast<std::size_t>(e.node) + d] += e.phi * gap[d];
    }
    return true;
}

// ---- springs -----------------------------------------------------------------------------------

SpringForm::SpringForm(std::size_t node_count, std::vector<std::int32_t> nodes, double stiffness_n_per_mm)
    : m_node_count(node_count), m_nodes(std::move(nodes)), m_k(stiffness_n_per_mm)
{
    if (!(m_k >= 0) || !std::isfinite(m_k)) fail("springs to rest: stiffness {} N/mm must be ≥ 0 and finite", m_k);
    for (auto n : m_nodes)
        if (n < 0 || static_cast<std::size_t>(n) >= m_node_count) fail("springs to rest: node {} is not among the model's {}", n, m_node_count);
}

double SpringForm::value(std::span<const double> u) const
{
    double e = 0.0;
    for (auto n : m_nodes)
        for (int d = 0; d < 3; ++d) e += u[3 * static_cast<std::size_t>(n) + d] * u[3 * static_cast<std::size_t>(n) + d];
    return 0.5 * m_k * e;
}

void SpringForm::gradient(std::span<const double> u, std::span<double> g) const
{
    std::fill(g.begin(), g.end(), 0.0);
    for (auto n : m_nodes)
        for (int d = 0; d < 3; ++d) g[3 * static_cast<std::size_t>(n) + d] += m_k * u[3 * static_cast<std::size_t>(n) + d];
}

bool SpringForm::hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const
{
    gradient(v, product); // linear in u: H v = ∂E/∂u at v
    (void)u;
    return true;
}

void SpringForm::add_restoring(std::span<const double> u, std::span<double> forces, std::span<double> stiffness) const
{
    for (auto n : m_nodes)
        for (int d = 0; d < 3; ++d) {
            const auto q = 3 * static_cast<std::size_t>(n) + static_cast<std::size_t>(d);
            forces[q] -= m_k * u[q];
            stiffness[q] += m_k;
        }
}

// ---- membrane and beams ------------------------------------------------------------------------

AuxiliaryElementsForm::AuxiliaryElementsForm(const AuxiliaryElements& elements, std::size_t node_count, std::string name,
                                             const StiffnessAssembler* for_hessian)
    : m_elements(elements), m_node_count(node_count), m_name(std::move(name)), m_assembler(for_hessian)
{
    if (m_assembler && m_assembler->dofs() != 3 * node_count)
        fail("{}: the assembler has {} unknowns, the elements' model {}", m_name, m_assembler->dofs(), 3 * node_count);
}

double AuxiliaryElementsForm::value(std::span<const double> u) const
{
    std::vector<double> scratch(u.size(), 0.0);
    return m_elements.add_forces(u.data(), scratch.data());
}

void AuxiliaryElementsForm::gradient(std::span<const double> u, std::span<double> g) const
{
    std::fill(g.begin(), g.end(), 0.0);
    m_elements.add_forces(u.data(), g.data());
}

bool AuxiliaryElementsForm::hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const
{
    if (!m_assembler) return false;
    SparseMatrix k = m_assembler->make_matrix();
    m_elements.add_stiffness(u.data(), *m_assembler, k.valuePtr());
    multiply(k, v, product);
    return true;
}

// ---- tool contact ------------------------------------------------------------------------------

ContactForm::ContactForm(const Indenter& tool, std::vector<double> rest_mm, std::vector<std::int32_t> nodes, std::vector<double> multipliers_n,
                         double load_factor, double penalty_n_per_mm)
    : m_tool(tool), m_rest(std::move(rest_mm)), m_nodes(std::move(nodes)), m_lambda(std::move(multipliers_n)), m_s(load_factor), m_eps(penalty_n_per_mm)
{
    if (m_lambda.size() != m_nodes.size()) fail("tool contact: {} multipliers for {} nodes", m_lambda.size(), m_nodes.size());
    for (auto n : m_nodes)
        if (n < 0 || 3 * static_cast<std::size_t>(n) >= m_rest.size()) fail("tool contact: node {} is not a model node", n);
    if (!(m_eps > 0) || !std::isfinite(m_eps)) fail("tool contact: penalty {} N/mm must be positive", m_eps);
}

Vec3 ContactForm::position(std::span<const double> u, std::int32_t node) const
{
    const auto q = 3 * static_cast<std::size_t>(node);
    return Vec3(m_rest[q] + u[q], m_rest[q + 1] + u[q + 1], m_rest[q + 2] + u[q + 2]);
}

double ContactForm::value(std::span<const double> u) const
{
    double e = 0.0;
    for (std::size_t i = 0; i < m_nodes.size(); ++i) e += contact_term(m_tool, position(u, m_nodes[i]), m_s, m_lambda[i], m_eps).energy_mj;
    return e;
}

void ContactForm::gradient(std::span<const double> u, std::span<double> g) const
{
    std::fill(g.begin(), g.end(), 0.0);
    for (std::size_t i = 0; i < m_nodes.size(); ++i) {
        const ContactTerm t = contact_term(m_tool, position(u, m_nodes[i]), m_s, m_lambda[i], m_eps);
        for (int d = 0; d < 3; ++d) g[3 * static_cast<std::size_t>(m_nodes[i]) + d] += t.gradient[d];
    }
}

bool ContactForm::hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const
{
    std::fill(product.begin(), product.end(), 0.0);
    for (std::size_t i = 0; i < m_nodes.size(); ++i) {
        const ContactTerm t = contact_term(m_tool, position(u, m_nodes[i]), m_s, m_lambda[i], m_eps);
        const auto q = 3 * static_cast<std::size_t>(m_nodes[i]);
        const Vec3 hv = t.hessian * Vec3(v[q], v[q + 1], v[q + 2]);
        for (int d = 0; d < 3; ++d) product[q + d] += hv[d];
    }
    return true;
}

// ---- material laws -----------------------------------------------------------------------------

std::string StrainEnergyDensityForm::name() const { return fmt::format("strain energy density ({})", to_string(m_law)); }

double StrainEnergyDensityForm::value(std::span<const double> f) const
{
    Mat3 m;
    for (int k = 0; k < 9; ++k) m(k / 3, k % 3) = f[k];
    return strain_energy_density(m_law, m_material, m);
}

void StrainEnergyDensityForm::gradient(std::span<const double> f, std::span<double> p) const
{
    const ElasticMaterial& m = m_material;
    if (m_law == MaterialLaw::mooney_rivlin)
        mooney_rivlin_stress<double>(0.5 * m.mu_mpa - m.c01_mpa, m.c01_mpa, m.kappa_mpa, f.data(), p.data());
    else
        first_piola_kirchhoff<double>(m_law, m.mu_mpa, m.lambda_mpa, m.kappa_mpa, f.data(), p.data());
}

bool StrainEnergyDensityForm::hessian_product(std::span<const double> f, std::span<const double> v, std::span<double> product) const
{
    double a[81];
    first_piola_tangent(m_law, m_material, f.data(), a);
    for (int ij = 0; ij < 9; ++ij) {
        double s = 0.0;
        for (int kl = 0; kl < 9; ++kl) s += a[9 * ij + kl] * v[kl];
        product[ij] = s;
    }
    return true;
}

} // namespace physreg
