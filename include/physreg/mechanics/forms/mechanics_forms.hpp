// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The mechanical energies as Forms of the nodal displacements u (mm, 3 per node): value in mJ
// (N·mm), gradient in N (the internal force), Hessian in N/mm — and one of the material laws as a
// Form of the deformation gradient F (9 entries, row-major; Ψ in MJ/m³ = N·mm/mm³, P = ∂Ψ/∂F in MPa,
// ∂P/∂F the material tangent). Each wraps the code the solvers run, so the finite-difference
// checker tests what is used.
#include "physreg/mechanics/coupling/tissue_coupling.hpp"
#include "physreg/mechanics/elements/auxiliary_elements.hpp"
#include "physreg/mechanics/forms/form.hpp"
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"
#include "physreg/mechanics/materials/material.hpp"
#include "physreg/model/loads.hpp"

#include <cstdint>
#include <vector>

namespace physreg {

/// The volume elements' strain and hourglass energy (plus the coupling's when the assembler has
/// one): W(u), the internal forces and the assembled tangent. An inverted element is an Error.
class ElasticForm : public Form {
public:
    explicit ElasticForm(const StiffnessAssembler& assembler) : m_assembler(assembler) {}
    std::string name() const override;
    std::size_t size() const override { return m_assembler.dofs(); }
    double value(std::span<const double> u) const override;
    void gradient(std::span<const double> u, std::span<double> g) const override;
    bool hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const override;

private:
    const StiffnessAssembler& m_assembler;
};

/// Paper 000's MLS penalty coupling, E = ½ Σ k_c |δ|² (quadratic: its Hessian is constant).
class CouplingForm : public Form {
public:
    explicit CouplingForm(const PenaltyCoupling& coupling) : m_coupling(coupling) {}
    std::string name() const override { return "tissue coupling"; }
    std::size_t size() const override { return 3 * m_coupling.node_count(); }
    double value(std::span<const double> u) const override { return m_coupling.energy_mj(u); }
    void gradient(std::span<const double> u, std::span<double> g) const override;
    bool hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const override;

private:
    const PenaltyCoupling& m_coupling;
};

/// Springs to rest of stiffness k (N/mm per node and direction) at the given nodes: elastic
/// supports, and BCF-FEM's soft springs at every node. E = ½ k Σ |u_i|².
class SpringForm : public Form {
public:
    /// Throws Error for a negative or non-finite k or a node out of range.
    SpringForm(std::size_t node_count, std::vector<std::int32_t> nodes, double stiffness_n_per_mm);
    std::string name() const override { return "springs to rest"; }
    std::size_t size() const override { return 3 * m_node_count; }
    double value(std::span<const double> u) const override;
    void gradient(std::span<const double> u, std::span<double> g) const override;
    bool hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const override;
    /// What an explicit or implicit step adds: the restoring force −∂E/∂u into `forces` and the
    /// diagonal stiffness k into `stiffness` (both 3 per node).
    void add_restoring(std::span<const double> u, std::span<double> forces, std::span<double> stiffness) const;

private:
    std::size_t m_node_count;
    std::vector<std::int32_t> m_nodes;
    double m_k;
};

/// Auxiliary elements (paper 001's capsule membrane, embedded vessel beams). Their tangent is
/// assembled in a StiffnessAssembler's pattern: give one built with their stencils for the Hessian.
class AuxiliaryElementsForm : public Form {
public:
    AuxiliaryElementsForm(const AuxiliaryElements& elements, std::size_t node_count, std::string name,
                          const StiffnessAssembler* for_hessian = nullptr);
    std::string name() const override { return m_name; }
    std::size_t size() const override { return 3 * m_node_count; }
    double value(std::span<const double> u) const override;
    void gradient(std::span<const double> u, std::span<double> g) const override;
    bool hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const override;

private:
    const AuxiliaryElements& m_elements;
    std::size_t m_node_count;
    std::string m_name;
    const StiffnessAssembler* m_assembler;
};

/// The Newton solver's augmented-Lagrangian tool contact (contact_term) summed over `nodes` at rest
/// positions `rest_mm` (3 per node), at load factor s with multipliers λ (N, one per listed node).
class ContactForm : public Form {
public:
    ContactForm(const Indenter& tool, std::vector<double> rest_mm, std::vector<std::int32_t> nodes, std::vector<double> multipliers_n, double load_factor,
                double penalty_n_per_mm);
    std::string name() const override { return "tool contact (augmented Lagrangian)"; }
    std::size_t size() const override { return m_rest.size(); }
    double value(std::span<const double> u) const override;
    void gradient(std::span<const double> u, std::span<double> g) const override;
    bool hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const override;

private:
    Vec3 position(std::span<const double> u, std::int32_t node) const;
    Indenter m_tool;
    std::vector<double> m_rest;
    std::vector<std::int32_t> m_nodes;
    std::vector<double> m_lambda;
    double m_s, m_eps;
};

/// A material law as a Form of F (9, row-major): Ψ(F), P(F) (the stress the elements use) and the
/// material tangent ∂P/∂F (first_piola_tangent).
class StrainEnergyDensityForm : public Form {
public:
    StrainEnergyDensityForm(MaterialLaw law, const ElasticMaterial& material) : m_law(law), m_material(material) {}
    std::string name() const override;
    std::size_t size() const override { return 9; }
    double value(std::span<const double> f) const override;
    void gradient(std::span<const double> f, std::span<double> p) const override;
    bool hessian_product(std::span<const double> f, std::span<const double> v, std::span<double> product) const override;

private:
    MaterialLaw m_law;
    ElasticMaterial m_material;
};

} // namespace physreg
