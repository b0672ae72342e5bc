// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Tissue–tissue penalty coupling through moving least squares (paper 000 eqs. 1–5).
//
// Every mesh vertex shared by parenchyma and a lesion (tumour or vessel) is split: the lesion's
// elements get their own copy, so the tissues are separate TLED bodies. For each split vertex i two
// virtual boundary vertices bp_i (parenchyma side) and bq_i (lesion side) sit at its rest position;
// they are not degrees of freedom but MLS interpolants of the vertices of their own tissue around
// them (eq. 1, Φ fixed in the reference configuration as everything else in total-Lagrangian TLED).
// The gap δ_i = bp_i − bq_i draws a penalty force −k_c δ_i on bp_i and +k_c δ_i on bq_i (eq. 2),
// spread back onto each support domain through Φ (eq. 3) inside every TLED step; the copies follow
// their tissues (eq. 4). The coupling is the gradient of the energy E = ½ Σ_i k_c |δ_i|², so it is
// conservative, its forces sum to zero, and it adds stiffness k_c Φ_j Σ|Φ| to the vertices it
// touches (the explicit time step and dynamic relaxation account for it).
//
// Units: k_c is given in N/m, as in paper 000 (k_{c,s-t} = 600 N/m, k_{c,s-v} = 500 N/m), and
// used in N/mm internally (÷ 1000): a force in N per mm of gap between the two interpolated copies.
#include "physreg/mechanics/coupling/mls.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <map>
#include <span>
#include <vector>

namespace physreg {

enum class TissueGroup : std::uint8_t { parenchyma = 0, tumour = 1, vessel = 2 };
std::string to_string(TissueGroup group);

/// Which pair of tissues an interface joins. A vertex touching tumour and vessel but no parenchyma
/// couples them with k_{c,s-t} (our choice; paper 000 has no such interface).
enum class CouplingKind : std::uint8_t { parenchyma_tumour, parenchyma_vessel, tumour_vessel };

struct CouplingStiffness {
    double parenchyma_tumour_n_per_m = 600.0; ///< k_{c,s-t}, N/m
    double parenchyma_vessel_n_per_m = 500.0; ///< k_{c,s-v}, N/m
    /// Throws Error naming the parameter for a negative, NaN or infinite stiffness.
    void validate() const;
    double n_per_mm(CouplingKind kind) const;
};

struct InterfacePoint {
    std::int32_t vertex = -1;     ///< the split vertex (its first-side copy keeps this id)
    Vec3 rest_mm = Vec3::Zero();
    CouplingKind kind = CouplingKind::parenchyma_tumour;
    MlsShapeFunctions first;      ///< parenchyma side (tumour side for tumour–vessel)
    MlsShapeFunctions second;     ///< lesion side
};

class PenaltyCoupling {
public:
    PenaltyCoupling() = default;
    PenaltyCoupling(std::vector<InterfacePoint> points, std::size_t node_count, const CouplingStiffness& stiffness);

    void set_stiffness(const CouplingStiffness& stiffness);
    const CouplingStiffness& stiffness() const { return m_stiffness; }
    const std::vector<InterfacePoint>& points() const { return m_points; }
    std::size_t node_count() const { return m_node_count; }
    bool empty() const { return m_points.empty(); }

    /// Gap δ_i = bp_i − bq_i of every interface point for nodal displacements u (3 per node), mm.
    std::vector<Vec3> gaps_mm(std::span<const double> u) const;
    /// E = ½ Σ k_c |δ|², mJ (N·mm).
    double energy_mj(std::span<const double> u) const;
    /// Adds the coupling's internal forces ∂E/∂u (N, 3 per node) to f.
    template <typename Real>
    void add_forces(const Real* u, Real* f) const;
    /// Per node: Σ over rows of |∂²E/∂u_j∂u_l| (Gershgorin bound of the coupling stiffness), N/mm.
    std::vector<double> stiffness_bound() const;

    struct Entry {
        std::int32_t node;
        double phi; ///< +Φ on the first side, −Φ on the second: δ = Σ entry.phi u_node
    };
    /// Point i's gap as δ_i = Σ entry.phi u_node: its energy's Hessian is k_i φ φᵀ ⊗ I₃ (implicit solvers).
    std::span<const Entry> point_entries(std::size_t i) const
    {
        return {m_entries.data() + m_begin[i], static_cast<std::size_t>(m_begin[i + 1] - m_begin[i])};
    }
    double point_stiffness_n_per_mm(std::size_t i) const { return m_k[i]; }

private:
    std::vector<InterfacePoint> m_points;
    std::vector<std::int64_t> m_begin; ///< entries of point i: [m_begin[i], m_begin[i+1])
    std::vector<Entry> m_entries;
    std::vector<double> m_k;           ///< per point, N/mm
    std::size_t m_node_count = 0;
    CouplingStiffness m_stiffness;
};

struct CouplingOptions {
    /// Support radius of the MLS domains in element sizes (per grid axis for grid meshes). 1.25
    /// takes a vertex's own copy and its edge neighbours in its tissue (weight 0.03 at 0.8 of the
    /// radius): the coupling then ties nearly the copies themselves, so a stiff coupling approaches
    /// shared nodes (2 % on the unit test's inclusion); larger supports smooth more (1.6: 5 %).
    double support_radius_cells = 1.25;
    MlsOptions mls; ///< support_radius_mm is set from support_radius_cells
    void validate() const;
};

struct SplitMesh {
    VolumeMesh mesh;                           ///< cells as before; interface vertices duplicated
    std::vector<std::int32_t> original_vertex; ///< per node of `mesh`: its vertex in the input mesh
    std::vector<TissueGroup> node_group;       ///< per node: the tissue it belongs to
    PenaltyCoupling coupling;
};

/// Splits the vertices where tissue groups meet and builds the MLS coupling between the copies.
/// `groups` gives every cell label's group; a label missing from it is an Error. Throws Error
/// (naming the interface position) when a support domain has too few vertices or is ill-conditioned.
SplitMesh split_tissue_interfaces(const VolumeMesh& mesh, const std::map<std::int32_t, TissueGroup>& groups,
                                  const CouplingStiffness& stiffness, const CouplingOptions& options);

} // namespace physreg
