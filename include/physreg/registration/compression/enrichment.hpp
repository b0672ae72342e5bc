// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 000's detail enrichment (eqs. 9–10): the fine (high-resolution) model's nodes expressed
// from the 8 nodes of the coarse element they lie in, per deformation condition, so that a coarse
// simulation can synthesise the fine detail at run time.
//
// Eq. 9: for a condition t, Φ_{j,t} are moving-least-squares shape functions with a linear basis
// over the coarse element's 8 deformed nodes P_a^t, evaluated at the fine node's deformed position
// x_j^t (weights: the trilinear shape functions at the node's rest natural coordinates plus 0.05, so
// that all 8 nodes take part). Linear reproduction gives Σ_a Φ_a P_a^t = x_j^t: the training
// condition is reproduced exactly. Eq. 10 at run time: x_j = c + Σ_a Φ_a (P_a − c), c the coarse
// element's centroid (the local form keeps float32 weights accurate to ≈ 1e-7 mm).
//
// The database file: a versioned binary format with per-condition CRC-32 checksums (see
// docs/enrichment.md).
#include "physreg/core/types.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/registration/compression/liver_model.hpp"

#include <filesystem>
#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace physreg {

/// Eq. 9: 8 weights per fine node (node-major). `fine_nodes`: each fine node's coarse cell and rest
/// natural coordinates; `coarse_u`, `fine_u`: 3 displacements (mm) per node of each mesh.
std::vector<float> enrichment_weights(const VolumeMesh& coarse, const std::vector<double>& coarse_u, const std::vector<NodeEmbedding>& fine_nodes,
                                      const std::vector<Vec3>& fine_rest, const std::vector<double>& fine_u);

/// Eq. 10: fine displacements (3 per fine node, mm) from a coarse displacement and stored weights.
std::vector<double> synthesize_fine_displacement(const VolumeMesh& coarse, const std::vector<double>& coarse_u,
                                                 const std::vector<NodeEmbedding>& fine_nodes, const std::vector<Vec3>& fine_rest,
                                                 const std::vector<float>& phi);

struct EnrichmentDatabase;
struct EnrichmentMatch;
/// Eq. 10 for some fine nodes only (`subset`, fine node ids), with the blended weights of the
/// matched conditions: writes their displacements (mm) into `fine_u` (3 per fine node; the other
/// entries are left as they are). The real-time path synthesises only the nodes it shows.
void synthesize_fine_subset(const VolumeMesh& coarse, const std::vector<double>& coarse_u, const std::vector<NodeEmbedding>& fine_nodes,
                            const std::vector<Vec3>& fine_rest, const EnrichmentDatabase& db, const EnrichmentMatch& match,
                            const std::vector<std::int32_t>& subset, std::vector<double>& fine_u);

/// One deformation condition of the database: where the tool entered, which way it pressed, how deep.
struct EnrichmentCondition {
    std::string position;               ///< name of the entry position (e.g. "A")
    Vec3 contact_mm = Vec3::Zero();     ///< tool reference point at first contact
    Vec3 direction = Vec3::UnitY();     ///< unit pressing direction (its orientation)
    double depth_mm = 0.0;              ///< travel beyond first contact
};

struct EnrichmentDatabase {
    std::string fine_fingerprint, coarse_fingerprint; ///< the meshes it was built for
    std::string model_json;                           ///< the fine model's parameters (tissues, k, grids)
    std::uint64_t fine_nodes = 0, coarse_nodes = 0;
    std::vector<EnrichmentCondition> conditions;
    /// Per condition: the coarse model's displacement (3 per coarse node, mm; for matching by
    /// similarity) and the eq. 9 weights (8 per fine node).
    std::vector<std::vector<float>> coarse_displacement, weights;
    void validate(const std::string& what) const; ///< sizes consistent, values finite
    Index3 coarse_grid() const;                       ///< the coarse model's grid, from model_json
};

/// Which conditions a database holds: positions × orientations × depths (paper 000: 5 × 20 × 50).
struct EnrichmentPlan {
    struct Position {
        std::string name;
        Vec3 contact_mm;                    ///< where the tool first meets the organ
    };
    std::vector<Position> positions;
    Vec3 direction = Vec3::UnitY();         ///< nominal pressing direction (LPS; posterior)
    int orientations = 1;                   ///< 1: the nominal direction only; else also tilted ones
    double tilt_deg = 15.0;                 ///< tilt of the other orientations (on a cone, equal azimuths)
    std::vector<double> depths_mm;          ///< increasing, > 0
    void validate() const;
    std::size_t sequences() const { return positions.size() * static_cast<std::size_t>(orientations); }
    /// Unit pressing direction of orientation o (0: nominal).
    Vec3 orientation(int o) const;
    /// All conditions: position-major, then orientation, then depth (the database's order).
    std::vector<EnrichmentCondition> conditions() const;
};

/// Tool positions over the skin that a session's tool can reach, independent of any recorded
/// compression: `columns` × `rows` entry lines along `direction`, evenly over the central 70 % of
/// the liver's extent across that direction (the tool presses over the liver), each at the
/// position where the sphere `tool` first touches the body (non-background voxels) of
/// `rest_labels`. Names G, then the column, then the row. Throws Error for a tool that is not a sphere, a grid
/// under 1 × 1, a label map without liver, or a line that misses the body.
std::vector<EnrichmentPlan::Position> skin_grid_positions(const LabelVolume& rest_labels, const LabelRoles& roles, const Indenter& tool,
                                                          const Vec3& direction, int columns, int rows);

/// The tool path of a condition: from two coarse cells back along the direction to the depth.
Indenter condition_tool(const Indenter& shape, const EnrichmentCondition& condition, double back_mm);

struct EnrichmentBuildOptions {
    PredictionOptions prediction;
    /// Finished sequences (one position and orientation through all depths) are saved here and
    /// reused when the build is run again (resume). Empty: no checkpoints.
    std::filesystem::path checkpoint_directory;
    int rank = 0, ranks = 1;                ///< MPI: this process does sequences s with s % ranks == rank
    std::function<void(double, const std::string&)> progress;
};

/// Deforms the fine and the coarse model under every condition of `plan` (sequences in parallel on
/// threads; depths of a sequence warm-started from each other) and stores the eq. 9 weights. With
/// ranks > 1 it returns only this rank's sequences (conditions of the others are left out); merge
/// with merge_enrichment_parts. Deterministic: the same database whatever the thread or rank count.
EnrichmentDatabase build_enrichment_database(const LiverModel& fine, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                                             const Indenter& tool_shape, const EnrichmentPlan& plan, const EnrichmentBuildOptions& options);

/// Puts the parts built by several ranks together in the plan's order. Throws Error for a missing
/// or duplicated condition, or parts built for other meshes.
EnrichmentDatabase merge_enrichment_parts(const std::vector<EnrichmentDatabase>& parts, const EnrichmentPlan& plan);

/// The file format in memory (for MPI messages): what write/read put in and take from the file.
std::string serialize_enrichment_database(const EnrichmentDatabase& database);
EnrichmentDatabase deserialize_enrichment_database(const std::string& bytes, const std::string& what);

/// Choosing stored conditions for a new deformation (paper 000: by compression parameters).
enum class EnrichmentMatching {
    parameters, ///< tool entry point, direction and depth (needs the tool's parameters)
    field       ///< similarity of the coarse displacement field (works without the tool's parameters)
};
EnrichmentMatching parse_enrichment_matching(const std::string& text);

/// How matched conditions make the fine detail. The `conditions` nearest are blended by inverse
/// distance. The stored detail's share falls with the nearest match's distance d as
/// 1 / (1 + (d / detail_length_mm)²); the rest is the coarse field interpolated trilinearly (no
/// detail), so that detail made under a tool far from this one cannot hurt more than it may help.
/// detail_length_mm = ∞: the stored detail whatever the distance (paper 000); 0: only on an exact hit.
struct EnrichmentBlend {
    int conditions = 1;
    double detail_length_mm = std::numeric_limits<double>::infinity();
    EnrichmentBlend(int k = 1, double length_mm = std::numeric_limits<double>::infinity()) : conditions(k), detail_length_mm(length_mm) {}
    /// Throws Error naming `what` for fewer than 1 condition or a length < 0 or NaN.
    void validate(const std::string& what) const;
    double detail_share(double nearest_distance) const;
};

struct EnrichmentMatch {
    std::vector<std::size_t> conditions; ///< the k nearest, nearest first
    std::vector<double> distances;       ///< parameters: mm (|Δ contact| + |Δ depth| + 10 mm/rad × angle); field: RMS mm
    std::vector<double> blend;           ///< inverse-distance weights, Σ = 1
    double detail = 1.0;                 ///< share of the stored detail (EnrichmentBlend); the rest: trilinear coarse field
    bool outside_range = false;          ///< the query lies beyond the database's conditions: extrapolated
    std::string range_note;              ///< how far outside, for the warning
    double nearest_position_mm = 0.0;    ///< parameters: entry point to the nearest stored one
};

/// Parameter distance between conditions, mm (10 mm per radian of direction change).
double condition_distance(const EnrichmentCondition& a, const EnrichmentCondition& b);
/// The nearest conditions. `query` is needed for parameter matching (and checks the range);
/// `coarse_u` (3 per coarse node) for field matching. The range: a query is inside when its entry
/// point lies within the stored entry points' convex hull (seen along the pressing direction)
/// grown by 5 mm, its depth within the stored depths there, and its direction within 5° (or the
/// stored tilt) of a stored one; anything else is extrapolated and says how far out it lies.
EnrichmentMatch match_enrichment(const EnrichmentDatabase& db, EnrichmentMatching how, const EnrichmentBlend& blend, const EnrichmentCondition* query,
                                 const std::vector<double>& coarse_u);
/// Σ_m blend_m Φ_m over the matched conditions, mixed with the trilinear weights of `fine_nodes`
/// by the match's detail share (partition of unity kept). `fine_nodes` may be null when the
/// detail share is 1.
std::vector<float> blended_weights(const EnrichmentDatabase& db, const EnrichmentMatch& match,
                                   const std::vector<NodeEmbedding>* fine_nodes = nullptr);
/// The detail length (EnrichmentBlend) with the lowest leave-one-sequence-out error: each stored
/// condition predicted from the conditions of the other positions and orientations (matched as
/// `how`, `k` blended), its own fine nodes as the truth; among 0, 1, 2, 4, …, 64 mm and ∞.
/// The error is the mean over `scored` fine nodes (e.g. those around the targets the user looks
/// at: the rest landmarks), or over every fine node when `scored` is empty. Returns ∞ (paper 000)
/// for a database of one sequence. `errors_mm`: (length, mean error) per candidate.
double choose_detail_length(const EnrichmentDatabase& db, const VolumeMesh& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                            const std::vector<Vec3>& fine_rest, EnrichmentMatching how, int k,
                            std::vector<std::pair<double, double>>* errors_mm = nullptr, const std::vector<std::int32_t>& scored = {});
/// The blend size with the lowest leave-one-out error over the database (each stored condition
/// predicted from the others by field matching, its own fine nodes as the truth), among 1…max_k.
/// Returns k and the error per k (mean fine-node error, mm) in `errors_mm`.
int choose_blend_size(const EnrichmentDatabase& db, const VolumeMesh& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                      const std::vector<Vec3>& fine_rest, int max_k, std::vector<double>* errors_mm = nullptr);

/// Throws Error naming `what` when the database was built for another fine or coarse mesh, or for
/// other model parameters (tissue moduli, coupling).
void check_database_fits(const EnrichmentDatabase& db, const LiverModel& fine, const LiverModel& coarse, const std::string& what);
/// The fine model's parameters as the database records them.
std::string enrichment_model_json(const LiverModel& fine, const LiverModel& coarse);

/// Coarse-to-fine prediction of a compression: the coarse model solved for the tool, the stored
/// conditions matched, every fine node synthesised (eq. 10), landmarks moved in the fine mesh.
struct CoarseToFinePrediction {
    std::vector<double> coarse_u, fine_u;   ///< mm
    LandmarkSet landmarks;
    EnrichmentMatch match;
    long iterations = 0;                    ///< coarse relaxation
    double coarse_seconds = 0.0, synthesis_seconds = 0.0;
};
CoarseToFinePrediction predict_coarse_to_fine(const LiverModel& fine, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                                              const EnrichmentDatabase& db, const Indenter& tool, const LandmarkSet& rest_landmarks,
                                              EnrichmentMatching how, const EnrichmentBlend& blend, const PredictionOptions& options,
                                              const std::string& what);

/// A compression followed as `steps` tool positions from first contact to the final depth, each
/// update warm-started from the previous one, with the high-resolution model and coarse-to-fine
/// (coarse equilibrium + matching + synthesis of every fine node and landmark): wall time per update
/// and the landmarks at the final depth. With `high_resolution` false only coarse-to-fine runs (its
/// high-resolution fields stay empty): for states whose high-resolution equilibrium is known already.
struct TrackingRun {
    std::vector<double> high_resolution_ms, coarse_to_fine_ms;
    /// coarse_to_fine_ms split: coarse equilibrium, and matching + synthesis + landmarks.
    std::vector<double> coarse_solve_ms, synthesis_ms;
    std::vector<long> high_resolution_iterations, coarse_iterations;
    LandmarkSet high_resolution_landmarks, coarse_to_fine_landmarks; ///< at the final depth
    std::vector<double> high_resolution_u, coarse_to_fine_u;         ///< fine displacements at the final depth, mm
    EnrichmentMatch last_match;
};
TrackingRun track_compression(const LiverModel& fine, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                              const EnrichmentDatabase& db, const Indenter& tool, const LandmarkSet& rest_landmarks, int steps,
                              EnrichmentMatching how, const EnrichmentBlend& blend, const PredictionOptions& options, const std::string& what,
                              const std::function<void(int)>& on_step = {}, bool high_resolution = true);

/// Atomic write (temporary name, then rename).
void write_enrichment_database(const std::filesystem::path& path, const EnrichmentDatabase& database);
/// Throws Error naming the file for a wrong magic or version, a truncated file, a checksum
/// mismatch (naming the condition block), or inconsistent sizes.
EnrichmentDatabase read_enrichment_database(const std::filesystem::path& path);

} // namespace physreg
