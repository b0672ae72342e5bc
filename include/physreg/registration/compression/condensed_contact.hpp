// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Condensed contact for tool updates (issue 30; Bro-Nielsen & Cotin 1996, Cotin et al. 1999):
// paper 000's model linearised at rest, its stiffness K factorised once (CHOLMOD), and the
// compliance W = K⁻¹ kept only where it is needed — at the candidate contact nodes (the skin nodes
// any tool position of the session can reach) and at the query nodes (around the landmarks). Each
// update then solves the frictionless contact on that block alone, as a linear complementarity
// problem by projected Gauss–Seidel warm-started from the previous update:
//   w = q + D λ ≥ 0, λ ≥ 0, wᵀλ = 0,  D_ij = n_iᵀ W_ij n_j,  q_i = g_i(u) − n_iᵀ u_i,
// λ_i the contact force (N) on node i along the tool's outward normal n_i, g_i its gap (mm). The
// normals and gaps are re-linearised at the solution a few times (the tool is curved). The query
// displacements are W_qc F; the whole field, when asked for, is one back-substitution.
//
// The law is small-strain linear elasticity (the tangent of the model's Neo-Hookean law at rest,
// with its hourglass control and MLS coupling): exact for small tool travels, an approximation for
// deep ones — bench condensed measures how far it lands from the nonlinear solution.
#include "physreg/model/loads.hpp"
#include "physreg/registration/compression/liver_model.hpp"

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace physreg {

struct CondensedContactOptions {
    double candidate_margin_mm = 10.0; ///< candidates: surface nodes within the tool's reach + this of a session path
    double active_gap_mm = 5.0;        ///< a candidate enters an update's LCP when its gap is below this (mm)
    int lcp_max_sweeps = 2000;         ///< projected Gauss–Seidel sweeps per linearisation
    double lcp_tolerance_mm = 1e-5;    ///< largest complementarity violation |min(w, λ D_ii)|, mm
    int normal_updates = 4;            ///< re-linearisations of the normals and gaps per update
    double penetration_tolerance_mm = 1e-3; ///< accepted penetration after the last linearisation
    /// Memory the precomputation may take, bytes: the Cholesky factor, the compliance blocks, the
    /// stiffness, the solve's work blocks; estimated from CHOLMOD's analysis before anything is
    /// factorised. 0: 80 % of the machine's physical memory. Over it: an Error naming both sizes.
    std::size_t memory_limit_bytes = 0;
    void validate() const;
};

/// The memory a condensed model of this size needs (bytes, the estimate the limit is checked
/// against): `factor_nonzeros` = nnz(L), `stiffness_nonzeros` = nnz(K).
std::size_t condensed_memory_bytes(std::size_t dofs, double factor_nonzeros, std::size_t stiffness_nonzeros, std::size_t candidate_nodes,
                                   std::size_t query_nodes);
/// `memory_limit_bytes` as applied: itself, or 80 % of the physical memory when 0.
std::size_t effective_memory_limit(std::size_t memory_limit_bytes);

struct CondensedPrecomputation {
    std::size_t dofs = 0, candidate_nodes = 0, query_nodes = 0;
    double assembly_s = 0.0, factorisation_s = 0.0, compliance_s = 0.0;
    std::size_t compliance_bytes = 0;
    double factor_nonzeros = 0.0;  ///< nnz(L)
    std::size_t memory_bytes = 0;  ///< the estimate checked against the limit (factor, compliance, stiffness, work)
    std::size_t memory_limit_bytes = 0;
    /// Tool positions that left the candidate region: the surface nodes they reached were added
    /// as candidates by solves with the factor (a fallback, with a warning).
    int region_extensions = 0;
    std::size_t added_candidates = 0;
    double extension_s = 0.0;
};

/// What a condensed model keeps after its precomputation: enough to answer tool updates with no
/// factor (physreg prepare stores it, serve starts from it). The stiffness probe (vᵀ K w for fixed
/// vectors) and the held unknowns tie it to the stiffness it came from.
struct CondensedCompliance {
    std::vector<std::int32_t> candidates, query, outside;
    Eigen::MatrixXd wcc, wqc; ///< mm/N
    std::size_t dofs = 0, constrained_dofs = 0;
    double stiffness_probe = 0.0;
    CondensedPrecomputation precomputation;
};
/// A binary file of its own (magic, version, sizes, arrays, a checksum). Reading checks sizes
/// against the file's length before allocating, and the checksum; throws Error naming the file.
void write_condensed_compliance(const std::filesystem::path& path, const CondensedCompliance& compliance);
CondensedCompliance read_condensed_compliance(const std::filesystem::path& path);

class CondensedContactModel {
public:
    /// `session_tools`: every tool path of the session (candidates lie near them); `query_nodes`:
    /// nodes whose displacement each update returns. Throws Error when no surface node is near the
    /// tools, when the stiffness cannot be factored, or for shapes without a finite reach.
    CondensedContactModel(const LiverModel& model, const std::vector<Indenter>& session_tools, std::vector<std::int32_t> query_nodes,
                          const CondensedContactOptions& options = {});
    /// From stored compliance (physreg prepare): the stiffness is assembled (fractions of a second)
    /// and checked against the one the blocks came from, and not factorised until something needs
    /// the factor (the whole field, candidates added for a tool off the session's paths). Throws
    /// Error for blocks of another model or of another size.
    CondensedContactModel(const LiverModel& model, CondensedCompliance stored, const CondensedContactOptions& options = {});
    ~CondensedContactModel();
    CondensedContactModel(CondensedContactModel&&) noexcept;
    /// The blocks and node lists this model answers from (what prepare stores).
    CondensedCompliance compliance() const;
    /// Whether the stiffness has been factorised (a model from stored compliance: only once needed).
    bool factorised() const;

    struct Update {
        int active_nodes = 0;        ///< candidates in contact (λ > 0)
        int lcp_nodes = 0;           ///< candidates in the LCP
        int sweeps = 0;              ///< Gauss–Seidel sweeps, all linearisations
        double max_penetration_mm = 0.0;
        double total_force_n = 0.0;  ///< |Σ λ n|
        double contact_ms = 0.0, recovery_ms = 0.0;
        /// Surface nodes within the tool's reach that were not candidates: added by solves with
        /// the factor before the contact (the fallback for a tool outside the precomputed region).
        int added_candidates = 0;
        double extension_ms = 0.0;
    };
    /// The tool (its shape, at its reference position `position_mm`) → contact forces and the
    /// query nodes' displacements. A tool that reaches surface nodes outside the precomputed
    /// candidates (it left the session's paths) is not answered from the stale block: the nodes
    /// within its reach + the margin become candidates first, their compliance solved with the
    /// factor (seconds, not milliseconds), with a warning naming the position. Throws Error when
    /// the LCP does not converge, a penetration beyond the tolerance remains (naming the update's
    /// position), or the added candidates would exceed the memory limit.
    Update move_to(const Indenter& tool, const Vec3& position_mm);
    /// Forget the contact forces (a new tool sequence starts from rest).
    void reset();
    /// 3 per query node (the order given), mm, after the last update.
    const std::vector<double>& query_displacement_mm() const { return m_query_u; }
    /// Every node's displacement (3 per node, mm) with only the query nodes filled (zero elsewhere):
    /// enough for anything that reads the query nodes alone, such as the landmarks' interpolation.
    std::vector<double> query_field_mm() const;
    /// Every node's displacement (3 per node, mm): one solve with the factor.
    std::vector<double> full_displacement_mm() const;

    const CondensedPrecomputation& precomputation() const { return m_pre; }
    const std::vector<std::int32_t>& candidate_nodes() const { return m_candidates; }
    const std::vector<std::int32_t>& query_nodes() const { return m_query; }

private:
    /// Appends `added` to the candidates: their compliance columns by solves with the factor, the
    /// old candidates' rows of them by symmetry. Checks the memory limit first.
    void add_candidates(const std::vector<std::int32_t>& added);
    /// The supports and the tangent stiffness at rest (supports eliminated).
    void assemble_at_rest();
    /// CHOLMOD's analysis (the memory limit checked for `candidates`) and factorisation.
    void factorise(std::size_t candidates) const;
    void ensure_factor() const;
    double stiffness_probe() const;

    struct Factor;
    const LiverModel& m_model;
    CondensedContactOptions m_options;
    std::unique_ptr<Factor> m_factor;
    std::vector<std::int32_t> m_candidates, m_query;
    std::vector<std::int32_t> m_outside; ///< free surface nodes that are not candidates (yet)
    Eigen::MatrixXd m_wcc; ///< compliance at candidate dofs (3c × 3c), mm/N
    Eigen::MatrixXd m_wqc; ///< query dofs × candidate dofs (3q × 3c), mm/N
    Eigen::VectorXd m_force; ///< 3c: the last contact forces (N)
    double m_least_compliance = 0.0; ///< below this a candidate cannot move along a normal (held), mm/N
    std::vector<double> m_lambda; ///< per candidate: last λ (warm start)
    std::vector<double> m_query_u;
    mutable CondensedPrecomputation m_pre; // the factor's figures are filled in when it is made
};

/// A compression predicted by condensed contact (`register-compression --solver condensed`): the
/// model linearised and factorised, the tool moved from first contact to its final position in
/// `steps` updates, then the whole field by one back-substitution and the landmarks moved with it.
/// `iterations` is the number of updates; `seconds` includes the precomputation. Throws Error as
/// CondensedContactModel does (naming `what`) and for steps < 1.
CompressionPrediction predict_compression_condensed(const LiverModel& model, const Indenter& tool, const LandmarkSet& rest_landmarks, int steps,
                                                    const std::string& what, const CondensedContactOptions& options = {},
                                                    CondensedPrecomputation* precomputation = nullptr, double* ms_per_update = nullptr);

/// Nodes within `radius_mm` of any of `points` (rest positions), sorted.
std::vector<std::int32_t> nodes_near(const VolumeMesh& mesh, const std::vector<Vec3>& points, double radius_mm);

} // namespace physreg
