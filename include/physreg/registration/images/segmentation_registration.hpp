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
#include "physreg/registration/model.hpp"

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
    /// Root mean square of φ over the terms (mm) at u (less the rest offsets, when set).
    double rms_distance_mm(const Eigen::VectorXd& u) const;
    /// Per structure: mean and max |φ| (mm) at u (the plain distance, without the rest offsets).
    std::vector<std::pair<double, double>> per_structure_distance_mm(const Eigen::VectorXd& u) const;
    std::size_t term_count() const { return m_nodes.size(); }
    /// The boundary nodes whose terms belong to structure j (empty for a structure without a map).
    std::vector<std::int32_t> structure_term_nodes(std::size_t j) const;
    /// The finest voxel spacing of structure j's map, mm (0 without a map).
    double structure_voxel_mm(std::size_t j) const;
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

    /// Each boundary node keeps its rest distance to the *moving* segmentation's boundary (issue 28,
    /// the floor of the method): the mesh's boundary is not the voxel boundary (it lies within the
    /// facet distance of it and rounds its steps), so asking a node that sits δ inside the moving
    /// structure to land exactly on the fixed structure's boundary moves it, and the inside with it,
    /// by δ whatever the truth. The terms become ½ (φ_s(x + u) − φ'_s(x))², φ'_s the moving
    /// structure's signed distance map (`moving_maps`, the same order as the structures; nullptr for
    /// none). The reverse term, if any, is unchanged.
    void set_rest_offsets(const std::vector<const SignedDistanceMap*>& moving_maps);
    bool has_rest_offsets() const { return !m_offsets.empty(); }
    /// Per term offset φ'_s(x) at rest, mm (empty without rest offsets): mean and max |·|.
    std::pair<double, double> rest_offset_stats_mm() const;
    std::size_t reverse_point_count() const;

private:
    double reverse_term(const Eigen::VectorXd& u, Eigen::VectorXd* gradient) const;
    const VolumeMesh& m_mesh;
    std::vector<std::int32_t> m_labels;
    std::vector<std::int32_t> m_nodes;
    std::vector<int> m_structures;
    std::vector<const SignedDistanceMap*> m_maps;
    std::vector<double> m_offsets; ///< per term (empty: none)
    double offset(std::size_t t) const { return m_offsets.empty() ? 0.0 : m_offsets[t]; }
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
    /// Also stop when a cycle lowers the rms distance of the data term by less than this, mm (0:
    /// off): late cycles lower Φ by more than the relative tolerance while the boundary hardly moves.
    /// 0.001 mm: register-images' default (ImageRegistrationSettings), so that every route agrees.
    double rms_tolerance_mm = 0.001;
    bool estimate_moduli = true;
    /// Log-normal prior on the estimated moduli around their initial values (the tissue table), as
    /// issue 28 asks: Π = ½ N r² Σ_j (ln(E_j/E_j⁰) / ln f)², N the objective's terms. f (> 1; 0 =
    /// no prior, free ratios) is the factor one standard deviation away; r (mm) says what one σ
    /// costs — as much as an rms boundary distance of r over every term.
    double moduli_prior_factor = 0.0;
    double moduli_prior_rms_mm = 0.1;
    /// Large deformation (issue 28): the co-rotational law, its element rotations refreshed from the
    /// current state at the start of every cycle and frozen within it (LinearElasticModel::
    /// set_element_rotations). false: paper 002's small-strain law.
    bool corotational = false;
    /// Issue 30: solves by CG preconditioned by an earlier factor, refactorising only when it has
    /// gone stale (LinearElasticOptions::reuse_factor); false: a factorisation per set of moduli.
    bool reuse_factor = true;
    /// register_segmentation(Model, …) only: a model without supports is first moved rigidly onto
    /// the segmentation (its boundary nodes onto the distance maps' zero levels, Gauss–Newton) when
    /// that removes more than this fraction of their rms distance, as register-images'
    /// --initial-min-reduction: a segmentation fixes only the normal motion of a smooth boundary,
    /// so a slide along it is left to the rigid fit. ≥ 1: never.
    double rigid_min_reduction = 0.5;
    void validate() const;
};

struct SegmentationCycle {
    int cycle = 0;
    double objective_mm2 = 0.0, rms_distance_mm = 0.0; ///< the data term Φ alone (without the prior)
    double prior_mm2 = 0.0;                            ///< Π at the cycle's moduli
    std::vector<double> young_moduli_pa;
    int evaluations = 0;
};

/// Whether the data can tell a structure's modulus (issue 28): the estimated modulus doubled and
/// halved, the boundary load and the other moduli held, and what that does to the structure's own
/// boundary and to the data term. A modulus whose doubling moves its structure's boundary by less
/// than a tenth of a voxel (rms) is not determined by segmentations of that resolution.
struct ModulusSensitivity {
    std::size_t structure = 0;
    double boundary_change_doubled_mm = 0.0, boundary_change_halved_mm = 0.0; ///< rms over the structure's boundary nodes
    double objective_change_doubled_mm2 = 0.0, objective_change_halved_mm2 = 0.0; ///< Φ(×2) − Φ, Φ(×½) − Φ
    double voxel_mm = 0.0;
    bool determined = false; ///< max(boundary changes) ≥ 0.1 voxel
};

struct SegmentationRegistrationResult {
    Eigen::VectorXd displacement_mm, force_n;   ///< 3 per node
    std::vector<double> young_moduli_pa;        ///< per structure
    std::vector<std::uint8_t> estimated;        ///< per structure: 1 estimated, 0 held (reference)
    std::vector<SegmentationCycle> history;     ///< cycle 0 = the initial guess
    std::vector<ModulusSensitivity> sensitivity; ///< per estimated structure, at the result
    double initial_objective_mm2 = 0.0, objective_mm2 = 0.0, initial_rms_mm = 0.0, rms_distance_mm = 0.0;
    double prior_mm2 = 0.0; ///< Π at the final moduli (0 without a prior)
    double largest_rotation_deg = 0.0; ///< the co-rotational law's largest element rotation (0: linear law)
    std::size_t inverted_elements = 0; ///< tetrahedra with non-positive volume at the result
    int evaluations = 0, factorisations = 0, pcg_iterations = 0;
    std::string stop_reason;
    std::string rigid_prefit;                   ///< register_segmentation(Model, …): the rigid pre-fit, applied or not and why
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

/// Paper 002's method on any shared model (registration/model.hpp), issue 29: the model's mesh
/// (hexahedra split into six tetrahedra each, nodes unchanged, so the displacement is the model's),
/// one structure per cell label starting from its tissue's modulus and with its Poisson ratio, the
/// supports held, every other node of the outer boundary loaded; each structure's boundary is
/// drawn to the same label of `fixed_labels` (a label absent there takes part in the mechanics
/// only). A model without supports is first moved rigidly (options.rigid_min_reduction); the
/// displacement returned includes that motion. The law is paper 002's (linear, or options.corotational), whatever the model's. Throws
/// Error naming the problem for coupled tissues (split interfaces), auxiliary structures, supports
/// that hold single directions, and a fixed segmentation without any of the model's labels.
SegmentationRegistrationResult register_segmentation(const Model& model, const LabelVolume& fixed_labels, const SegmentationRegistrationOptions& options,
                                                     const std::function<void(double, const std::string&)>& progress = {});

} // namespace physreg
