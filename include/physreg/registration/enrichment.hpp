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

#include <filesystem>
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
};

/// Atomic write (temporary name, then rename).
void write_enrichment_database(const std::filesystem::path& path, const EnrichmentDatabase& database);
/// Throws Error naming the file for a wrong magic or version, a truncated file, a checksum
/// mismatch (naming the condition block), or inconsistent sizes.
EnrichmentDatabase read_enrichment_database(const std::filesystem::path& path);

} // namespace physreg
