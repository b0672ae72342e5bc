// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Small-strain linear elasticity on linear tetrahedra with one Young's modulus per structure
// (label): K(E) u = F, K(E) = Σ_j E_j K̂_j + k_a I, where K̂_j is the stiffness of structure j's
// tetrahedra at E = 1 and its own Poisson ratio — paper 002's model. Because K is linear in each
// E_j, ∂K/∂E_j = K̂_j exactly, which the adjoint gradients of parameter estimation use.
//
// Dirichlet nodes (u = 0: bones, a held back) are eliminated; k_a (an optional spring to the rest
// position at every node, N/mm) regularises free-floating structures. A system with neither is
// singular and refused. The factorisation (CHOLMOD, analysis reused) is made once per set of moduli
// and serves every solve with it: the state solve and the adjoint solve of an evaluation.
//
// Large deformation (issue 28): the co-rotational law with *frozen* rotations. Given a displacement
// ū, each tetrahedron's rotation R_e (polar decomposition of its deformation gradient) is fixed, and
// the element force R_e K_e (R_eᵀ x − X) becomes affine in u: K_R u − b, K_R = Σ R K Rᵀ, b = Σ R K
// (X − Rᵀ X). Both stay linear in each E_j, so the adjoint gradients keep their form (with b's
// derivative); refreshing the rotations between solves gives the co-rotational equilibrium.
#include "physreg/mechanics/linear/linear_solver.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

namespace physreg {

struct LinearElasticOptions {
    std::map<std::int32_t, double> poisson_ratio; ///< per label; labels absent take default_poisson_ratio
    double default_poisson_ratio = 0.45;
    std::vector<std::int32_t> fixed_nodes;        ///< u = 0
    double anchor_stiffness_n_mm = 0.0;           ///< spring to rest at every node (0: none)
    /// Issue 30: solve K(E) u = f by CG preconditioned by the factor of an earlier K (pcg-factor,
    /// renewed when CG needs more than 25 iterations) instead of factorising K for every set of
    /// moduli: the modulus phase of paper 002's alternation changes E a little per evaluation.
    /// Solutions agree with the direct ones to the CG tolerance (1e-10 relative residual).
    bool reuse_factor = false;
};

class LinearElasticModel {
public:
    /// Throws Error naming `what` for a mesh that is not tetrahedral, degenerate or inverted cells,
    /// ν outside (−1, 0.5), a negative anchor, or a mesh piece with no fixed node and no anchor
    /// (its K would be singular).
    LinearElasticModel(const VolumeMesh& mesh, const LinearElasticOptions& options, const std::string& what);
    ~LinearElasticModel();

    const std::vector<std::int32_t>& structure_labels() const { return m_labels; } ///< sorted
    std::size_t structure_count() const { return m_labels.size(); }
    std::size_t node_count() const { return m_node_count; }
    const std::vector<std::uint8_t>& fixed() const { return m_fixed; } ///< per node
    /// Per structure: 1 when it is the largest structure (by volume) of some connected mesh piece.
    /// Forces and moduli of a piece scale together (u depends on F/E only), so estimation holds
    /// these moduli and estimates the others relative to them.
    const std::vector<std::uint8_t>& reference_structures() const { return m_reference; }
    /// Volume per structure, mm³.
    const std::vector<double>& structure_volume_mm3() const { return m_volume; }

    /// Sets the moduli (Pa, one per structure, in structure_labels() order) and factorises K (with
    /// reuse_factor: assembles K; the next solve decides whether to factorise).
    /// Throws Error for a non-positive or non-finite modulus (naming its label), or a K that is
    /// not positive definite.
    void set_young_moduli(const std::vector<double>& young_modulus_pa);
    const std::vector<double>& young_moduli_pa() const { return m_young_pa; }

    /// u = K⁻¹ f (f: N, 3 per node; u: mm, 3 per node, 0 at fixed nodes). Also the adjoint solve
    /// (K is symmetric).
    void solve(const Eigen::VectorXd& f, Eigen::VectorXd& u) const;
    /// u with u = `prescribed` at the fixed nodes (non-homogeneous Dirichlet) and K u = f at the
    /// others: K_ff u_f = f_f − K_fc u_c. Entries of `prescribed` at free nodes are ignored.
    void solve_prescribed(const Eigen::VectorXd& f, const Eigen::VectorXd& prescribed, Eigen::VectorXd& u) const;
    /// aᵀ K̂_j b, in N·mm per MPa (the derivative of aᵀ K b with respect to E_j in MPa).
    double structure_form(std::size_t j, const Eigen::VectorXd& a, const Eigen::VectorXd& b) const;
    /// y = K x (all nodes; rows of fixed nodes are the reaction forces).
    void multiply(const Eigen::VectorXd& x, Eigen::VectorXd& y) const;
    /// Freezes each tetrahedron's co-rotational rotation at displacement u (mm, 3 per node) and
    /// refactorises K = K_R; solves then include the rotation load b (see rotation_load). An
    /// element inverted at u gets the rotation that pushes it back out (corotation()); they are
    /// counted (inverted_at_rotations).
    void set_element_rotations(const Eigen::VectorXd& u);
    bool rotated() const { return !m_rest_unit_stiffness.empty(); }
    /// b(E) (N, 3 per node, zero without rotations): the co-rotational law's load at frozen rotations.
    void rotation_load(Eigen::VectorXd& b) const;
    /// aᵀ b̂_j, N·mm per MPa (the derivative of aᵀ b with respect to E_j in MPa; 0 without rotations).
    double structure_rotation_load(std::size_t j, const Eigen::VectorXd& a) const;
    /// The largest element rotation angle of the frozen rotations, degrees (0 without).
    double largest_rotation_deg() const { return m_largest_rotation_deg; }
    std::size_t inverted_at_rotations() const { return m_inverted_at_rotations; }
    /// Tetrahedra with non-positive volume at displacement u.
    std::size_t inverted_elements(const Eigen::VectorXd& u) const;
    /// Mean diagonal entry of K per free degree of freedom, N/mm (a typical nodal stiffness).
    double mean_diagonal_n_mm() const;
    int factorisations() const { return m_factorisations; }
    int pcg_iterations() const { return m_pcg_iterations; } ///< with reuse_factor: CG iterations over all solves
    double factorisation_seconds() const { return m_factorisation_s; }
    double solve_seconds() const { return m_solve_s; }

private:
    std::size_t m_node_count = 0;
    std::vector<std::int32_t> m_cells;           ///< 4 per cell
    std::vector<int> m_cell_structure;
    std::vector<double> m_unit_stiffness;        ///< 144 per cell (E = 1 MPa; rotated when rotations are frozen)
    std::vector<double> m_rest_unit_stiffness;   ///< the unrotated copy (empty: no rotations)
    std::vector<double> m_unit_rotation_load;    ///< 12 per cell: R K̂ (X − Rᵀ X) (empty: none)
    std::vector<double> m_rest_positions;        ///< 12 per cell, mm
    double m_largest_rotation_deg = 0.0;
    std::size_t m_inverted_at_rotations = 0;
    std::vector<std::int32_t> m_entry;           ///< 144 per cell: value index in K (−1: a fixed dof)
    std::vector<std::int32_t> m_labels;
    std::vector<std::uint8_t> m_reference;
    std::vector<double> m_volume;
    std::vector<std::uint8_t> m_fixed;
    std::vector<std::int32_t> m_dof_of;          ///< global dof → reduced dof (−1 fixed)
    std::vector<std::int32_t> m_diagonal_entry;  ///< per reduced dof
    double m_anchor = 0.0;
    std::vector<double> m_young_pa;
    SparseMatrix m_k;
    mutable SymmetricSolver m_solver;
    mutable int m_factorisations = 0;
    mutable int m_pcg_iterations = 0;
    mutable double m_factorisation_s = 0.0;
    bool m_reuse_factor = false;
    mutable bool m_factor_current = false; ///< reuse_factor: the factor is of K as it stands (solve directly)
    mutable int m_pcg_iterations_since_change = 0;
    mutable double m_solve_s = 0.0;
};

/// The element stiffness of a linear tetrahedron (12×12, row-major, node-major dofs) for E = 1 MPa
/// and Poisson ratio ν, nodes in mm: V Bᵀ D B. Returns the signed volume (mm³; ≤ 0: degenerate or
/// inverted, and k is left unset).
double tetrahedron_unit_stiffness(const Vec3* nodes, double poisson_ratio, double* k);

} // namespace physreg
