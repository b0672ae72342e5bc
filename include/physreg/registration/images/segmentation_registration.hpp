// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 002: segmentation-driven registration whose deformation is always a linear-elastic
// simulation. The moving image's structures are meshed together (conforming tetrahedra, one
// structure per label); unknown boundary forces F on the outer surface nodes and unknown Young's
// moduli E move them so that every structure's boundary lands on the same structure in the
// reference segmentation:
//   Φ(F, E) = ½ Σ_(i, s) φ_s(v_i + u_i)²,  K(E) u = F,
// over the boundary nodes i of each structure s, φ_s the reference's signed distance map of s.
// Exact gradients by the adjoint: K λ = ∂Φ/∂u (one more solve with the same factor), then
// ∂Φ/∂F = λ and ∂Φ/∂E_j = −λᵀ K̂_j u. L-BFGS (liblbfgs, Moré–Thuente line search) alternates, as
// the paper does, n iterations on F with E fixed, then n on log E with F fixed (log E keeps E > 0).
//
// Two parametrisations of the boundary load, with the same minimisers (for any E the map from
// the surface forces F to the surface displacements w is a bijection, w = C(E) F):
// - nodal-forces (paper 002): per-node forces, scaled to millimetres (F = k̄ x, k̄ the mean
//   diagonal stiffness); initial guess α d, the distance vectors d = −φ∇φ/|∇φ| scaled by the best
//   α of a short search. Φ's Hessian in F is C² — badly conditioned (soft global modes), so
//   L-BFGS restarted every n iterations needs many cycles.
// - surface-displacement (ours, the default): per-node displacements w of the same nodes; F is
//   their reaction K u. The Hessian is then close to the data term's own (well conditioned), and
//   d is directly the initial guess. The modulus phase holds w (not F) fixed: it moves what the
//   surface does not fix — the internal structures, where moduli are identifiable.
// Adjoint for surface-displacement: u_c = w, K_ff u_f = −K_fc w; K_ff μ = g_f;
// ∂Φ/∂w = g_c − (K [μ; 0])_c, ∂Φ/∂E_j = −[μ; 0]ᵀ K̂_j u.
// Because a free piece's u depends only on F/E (and with w prescribed not on a common scale of E
// at all), the largest structure of each mesh piece keeps its given modulus and the others are
// estimated relative to it.
#include "physreg/image/distance_map.hpp"
#include "physreg/mechanics/implicit/linear_elasticity.hpp"

#include <Eigen/Core>
#include <functional>
#include <string>
#include <vector>

namespace physreg {

/// The data term: (node, structure) pairs on each structure's boundary and the reference maps.
class SegmentationObjective {
public:
    /// `maps[j]`: the reference distance map of structure j (model.structure_labels() order);
    /// nullptr leaves that structure out of Φ. Throws Error naming `what` when no term is left.
    SegmentationObjective(const VolumeMesh& mesh, const std::vector<std::int32_t>& structure_labels,
                          std::vector<const SignedDistanceMap*> maps, const std::string& what);
    /// Φ (mm²) at displacement u (mm, 3 per node); gradient ∂Φ/∂u (mm) when asked.
    double evaluate(const Eigen::VectorXd& u, Eigen::VectorXd* gradient) const;
    /// Root mean square of φ over the terms (mm) at u.
    double rms_distance_mm(const Eigen::VectorXd& u) const;
    /// Per structure: mean and max |φ| (mm) at u.
    std::vector<std::pair<double, double>> per_structure_distance_mm(const Eigen::VectorXd& u) const;
    std::size_t term_count() const { return m_nodes.size(); }
    /// −φ ∇φ/|∇φ| at the rest position, averaged over a node's terms (zero for nodes without one).
    std::vector<Vec3> distance_vectors() const;

    /// Makes Φ symmetric (issue 28): adds the reverse direction, from the fixed segmentation's
    /// boundary to the model. Points y on each structure's zero level (the voxels beside it
    /// projected onto it) pull the nearest deformed boundary node n(y) of the same structure across
    /// its surface, point to plane along its rest normal ν: Ψ = ½ Σ_s w_s Σ_y ((x_n(y) − y)·ν_n)²,
    /// w_s = (the structure's terms / its points) so that both directions weigh the same. It sees
    /// what the forward term cannot: parts of the fixed structure that no model node reaches.
    /// Points farther than 3 boundary edges from every node are left out (what the model cannot
    /// represent, e.g. a vessel branch thinner than its cells).
    void add_reverse_term();
    bool symmetric() const { return !m_targets.empty(); }
    std::size_t reverse_point_count() const;

private:
    double reverse_term(const Eigen::VectorXd& u, Eigen::VectorXd* gradient) const;
    const VolumeMesh& m_mesh;
    std::vector<std::int32_t> m_labels;
    std::vector<std::int32_t> m_nodes;
    std::vector<int> m_structures;
    std::vector<const SignedDistanceMap*> m_maps;
    struct ReverseTargets {
        std::vector<Vec3> points;           ///< on the structure's zero level, mm
        std::vector<std::int32_t> nodes;    ///< the structure's boundary nodes
        std::vector<Vec3> normals;          ///< their outward unit normals at rest
        double weight = 1.0;
        double spacing_mm = 1.0;            ///< mean boundary edge at rest
    };
    std::vector<ReverseTargets> m_targets; ///< per structure with a map (empty: forward only)
};

/// Nodes on faces of the meshed domain's outer boundary (a face of exactly one cell).
std::vector<std::int32_t> outer_boundary_nodes(const VolumeMesh& mesh);

enum class BoundaryParametrisation { nodal_forces, surface_displacement };
BoundaryParametrisation parse_boundary_parametrisation(const std::string& text); ///< nodal-forces | surface-displacement
std::string to_string(BoundaryParametrisation p);

struct SegmentationRegistrationOptions {
    BoundaryParametrisation parametrisation = BoundaryParametrisation::surface_displacement;
    int alternation_iterations = 5; ///< paper 002: n L-BFGS iterations per phase
    int max_cycles = 40;            ///< F phase + E phase = one cycle
    /// Stop when a cycle lowers Φ by less than this fraction of Φ.
    double relative_tolerance = 1e-3;
    bool estimate_moduli = true;
    void validate() const;
};

struct SegmentationCycle {
    int cycle = 0;
    double objective_mm2 = 0.0, rms_distance_mm = 0.0;
    std::vector<double> young_moduli_pa;
    int evaluations = 0;
};

struct SegmentationRegistrationResult {
    Eigen::VectorXd displacement_mm, force_n;   ///< 3 per node
    std::vector<double> young_moduli_pa;        ///< per structure
    std::vector<std::uint8_t> estimated;        ///< per structure: 1 estimated, 0 held (reference)
    std::vector<SegmentationCycle> history;     ///< cycle 0 = the initial guess
    double initial_objective_mm2 = 0.0, objective_mm2 = 0.0, initial_rms_mm = 0.0, rms_distance_mm = 0.0;
    int evaluations = 0, factorisations = 0;
    std::string stop_reason;
    double seconds = 0.0, factorisation_s = 0.0, solve_s = 0.0;
};

/// Φ and its exact gradient with respect to the boundary unknowns x (per force node: scaled
/// forces, F = k̄ x, or displacements w = x) and to log E_j (all structures). `model`'s moduli
/// must already be set; for surface-displacement the force nodes must be fixed nodes of `model`.
struct SegmentationGradient {
    double objective_mm2 = 0.0;
    Eigen::VectorXd displacement_mm, d_force;   ///< d_force: ∂Φ/∂x (3 per force node)
    Eigen::VectorXd lambda;                     ///< the adjoint (3 per node)
    std::vector<double> d_log_modulus;          ///< ∂Φ/∂ log E_j
};
SegmentationGradient evaluate_segmentation_gradient(const LinearElasticModel& model, const SegmentationObjective& objective,
                                                    const std::vector<std::int32_t>& force_nodes, BoundaryParametrisation parametrisation,
                                                    double force_scale_n_mm, const Eigen::VectorXd& x);

/// Runs the alternation from the given moduli (Pa; positive; mesh.structure order of a
/// LinearElasticModel) on a model built from `mesh` and `elastic` (plus, for surface-displacement,
/// the force nodes held). `force_nodes`: the loaded surface nodes (none of them fixed in `elastic`).
/// `progress(fraction, message)`.
SegmentationRegistrationResult register_segmentation(const VolumeMesh& mesh, const LinearElasticOptions& elastic,
                                                     const SegmentationObjective& objective,
                                                     const std::vector<std::int32_t>& force_nodes, const std::vector<double>& initial_moduli_pa,
                                                     const SegmentationRegistrationOptions& options,
                                                     const std::function<void(double, const std::string&)>& progress = {});

} // namespace physreg
