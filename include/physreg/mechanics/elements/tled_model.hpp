// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Everything TLED precomputes in the reference configuration (Miller, Joldes, Lance, Wittek 2007):
// shape-function derivatives, volumes, hourglass vectors, lumped masses, per-element materials,
// the critical time step, and a partition of the elements that lets threads scatter forces without
// races.
//
// Hexahedra are Flanagan–Belytschko uniform-strain elements (one-point integration with the mean
// derivative b_a = (1/V) ∫ ∂N_a/∂X dV, exact for any trilinear hexahedron) with the hourglass
// control of Joldes, Wittek & Miller (2009): f_a = k Σ_α Γ_aα (Σ_b Γ_bα u_b), with
// Γ_aα = h_aα − (Σ_b h_bα X_b) · b_a and k = κ_hg M V Σ_a |b_a|² / 8 (M: see TledOptions).
// Tetrahedra are linear (constant strain).
#include "physreg/mechanics/materials/material.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/model/tissue_table.hpp"

#include <array>
#include <vector>

namespace physreg {

struct TledOptions {
    MaterialLaw law = MaterialLaw::neo_hookean;
    /// Hourglass stiffness k = κ_hg · M · V Σ_a |b_a|² / 8 (hexahedra). Joldes, Wittek & Miller take
    /// M = λ + 2μ; near incompressibility (ν = 0.49: λ + 2μ = 51 μ) that makes bending of a coarse
    /// mesh far too stiff (a cantilever 4 elements thick deflects 53 % of Timoshenko's value), since
    /// hourglass modes are bending-like and carry little volume change. We take M = 2μ by default
    /// (κ_hg = 0.15: the same stiffness as M = λ + 2μ, κ_hg = 0.075 at ν = 1/3).
    enum class HourglassModulus { shear, dilatational };
    HourglassModulus hourglass_modulus = HourglassModulus::shear;
    double hourglass_kappa = 0.15;     ///< dimensionless hourglass stiffness κ_hg
    double time_step_safety = 0.8;     ///< Δt = safety × critical time step
    double damping_per_s = 0.0;        ///< mass-proportional damping α (1/s), paper 000 eq. 8
    double density_scale = 1.0;        ///< mass scaling factor (≥ 1) for explicit dynamics
    /// Tetrahedra: averaged nodal pressure (Joldes, Wittek & Miller 2009): the Neo-Hookean
    /// pressure uses J̄, the mean over the element's nodes of the volume-weighted J of the elements
    /// around each node — relieves volumetric locking of linear tetrahedra at ν → 0.5.
    bool averaged_nodal_pressure = false;
    /// How the force loop shares elements among threads (see TledModel::phases): `automatic` takes
    /// bands of node numbers when the numbering is narrow enough, else a colouring; `colouring`
    /// forces the colouring (benchmarks compare the two in one run).
    enum class WorkPartition { automatic, colouring };
    WorkPartition work_partition = WorkPartition::automatic;
    /// Uniform grids of box hexahedra take the kernel's corner-transform path (the same forces with
    /// fewer operations); false forces the general path (benchmarks compare the two).
    bool box_elements = true;
    void validate() const;
};

struct ElementGeometry {
    std::array<double, 24> dn_dx{}; ///< b_a (mean ∂N_a/∂X), node-major: [3a + i], 1/mm
    std::array<double, 32> gamma{}; ///< hourglass vectors Γ_aα: [4a + α] (hexahedra only)
    double volume_mm3 = 0.0;
    double b_squared = 0.0;         ///< Σ_a |b_a|², 1/mm²
    double length_mm = 0.0;         ///< characteristic length for the stable time step
};

class TledModel {
public:
    /// Throws Error for labels missing from `tissues`, impossible materials, degenerate or
    /// inverted elements.
    TledModel(const VolumeMesh& mesh, const TissueTable& tissues, const TledOptions& options);

    CellType cell_type() const { return m_cell_type; }
    int nodes_per_element() const { return m_nodes_per_element; }
    std::size_t node_count() const { return m_rest.size() / 3; }
    std::size_t element_count() const { return m_element_material.size(); }
    const TledOptions& options() const { return m_options; }

    const std::vector<double>& rest_positions() const { return m_rest; } ///< 3 per node, mm
    const std::vector<std::int32_t>& connectivity() const { return m_connectivity; }
    const std::vector<std::uint16_t>& element_material() const { return m_element_material; }
    const std::vector<std::int32_t>& element_geometry() const { return m_element_geometry; }
    const std::vector<ElementGeometry>& geometries() const { return m_geometries; }
    const std::vector<ElasticMaterial>& materials() const { return m_materials; }
    const std::vector<std::int32_t>& material_labels() const { return m_material_labels; }
    /// Lumped masses, tonne (ρ V / nodes per element, summed).
    const std::vector<double>& lumped_mass() const { return m_mass; }
    /// Per node: a Gershgorin bound of the row of the linearised stiffness, N/mm. Dynamic
    /// relaxation scales masses with it so that every node has the same stable step.
    const std::vector<double>& stiffness_bound() const { return m_stiffness_bound; }
    /// The force loop's work: phases run one after another; the chunks of a phase run in parallel,
    /// each chunk's elements in order on one thread. Chunks of one phase share no node, so threads
    /// add forces into nodes without races, and every node receives its contributions in the same
    /// order whatever the thread count. Chunks index element_order().
    struct Chunk {
        std::int64_t begin, end;
    };
    const std::vector<std::vector<Chunk>>& phases() const { return m_phases; }
    const std::vector<std::int32_t>& element_order() const { return m_element_order; }
    /// True when the chunks are bands of node numbers (two phases, a chunk about one layer of a
    /// grid mesh; chunks differ in size), false for a colouring (chunks of 16 elements).
    bool band_partition() const { return m_band_partition; }
    /// Σ of V_e / 4 over the tetrahedra around each node (averaged nodal pressure), mm³.
    const std::vector<double>& nodal_volume() const { return m_nodal_volume; }
    /// Nodes on the mesh boundary (candidates for contact).
    const std::vector<std::int32_t>& surface_nodes() const { return m_surface_nodes; }
    /// Boundary faces (quads, or triangles with nodes[3] = -1), in cyclic node order: contact
    /// samples their interiors, so that a tool cannot pass between surface nodes.
    const std::vector<std::array<std::int32_t, 4>>& surface_faces() const { return m_surface_faces; }

    /// Critical time step (s) of central differences: min over elements of L_e / c_e.
    double critical_time_step_s() const { return m_critical_dt; }
    std::int32_t critical_element() const { return m_critical_element; }
    /// The stable step actually used: safety × critical.
    double time_step_s() const { return m_options.time_step_safety * m_critical_dt; }
    /// Model size (bounding-box diagonal, mm): divergence is declared when |u| exceeds 10×.
    double diagonal_mm() const { return m_diagonal; }

private:
    TledOptions m_options;
    CellType m_cell_type;
    int m_nodes_per_element;
    std::vector<double> m_rest;
    std::vector<std::int32_t> m_connectivity;
    std::vector<std::uint16_t> m_element_material;
    std::vector<std::int32_t> m_element_geometry;
    std::vector<ElementGeometry> m_geometries;
    std::vector<ElasticMaterial> m_materials;
    std::vector<std::int32_t> m_material_labels;
    std::vector<double> m_mass, m_stiffness_bound, m_nodal_volume;
    std::vector<std::vector<Chunk>> m_phases;
    std::vector<std::int32_t> m_element_order;
    void build_work_partition(const VolumeMesh& mesh);
    bool build_band_partition(const VolumeMesh& mesh);
    bool m_band_partition = false;
    std::vector<std::int32_t> m_surface_nodes;
    std::vector<std::array<std::int32_t, 4>> m_surface_faces;
    double m_critical_dt = 0.0, m_diagonal = 0.0;
    std::int32_t m_critical_element = -1;
};

/// M of the hourglass stiffness (MPa) for a material under the options.
double hourglass_modulus_mpa(const TledOptions& options, const ElasticMaterial& material);

/// Strain energy density Ψ(F) (MJ/m³ = N·mm/mm³) of a law; used for energy checks, not in the hot loop.
double strain_energy_density(MaterialLaw law, const ElasticMaterial& m, const Mat3& f);

} // namespace physreg
