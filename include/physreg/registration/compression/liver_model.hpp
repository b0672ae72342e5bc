// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The evaluated model of paper 000 and its baselines: the liver (parenchyma, tumours, vessels) of
// a rest label map meshed on a uniform grid (74 × 54 × 18 cells over the liver by default), TLED
// Neo-Hookean, posterior-facing surface fixed (as in the phantom's ground truth), pressed by the
// tracked tool. Three variants:
//   homogeneous   one material (the parenchyma's) everywhere — Han et al.'s baseline;
//   shared-nodes  per-element materials, tissues sharing their interface vertices;
//   coupled       per-element materials, interface vertices split and joined by MLS penalty
//                 coupling (paper 000 eqs. 1–5; see mechanics/coupling/tissue_coupling.hpp).
#include "physreg/core/landmark.hpp"
#include "physreg/image/image_geometry.hpp"
#include "physreg/model/loads.hpp"
#include "physreg/mechanics/coupling/tissue_coupling.hpp"
#include "physreg/mechanics/implicit/static_solver.hpp"
#include "physreg/mechanics/explicit/tled_solver.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/model/label_roles.hpp"
#include "physreg/registration/model.hpp"

#include <filesystem>
#include <memory>
#include <set>
#include <string>

namespace physreg {

enum class ModelVariant { homogeneous, shared_nodes, coupled };
/// What the model covers. `body`: the whole phantom body the tool presses (gel with the organs
/// cast into it, tied to them; bone held; the flat base on a frictionless table), so that a tool
/// on the skin moves the liver through the gel. `liver`: the liver alone, its posterior surface
/// held (the model before the body; a tool that stays in the gel never touches it).
enum class ModelRegion { body, liver };
ModelRegion parse_model_region(const std::string& text); ///< body, liver
std::string to_string(ModelRegion region);
ModelVariant parse_model_variant(const std::string& text); ///< homogeneous, shared-nodes, coupled
std::string to_string(ModelVariant variant);

/// Everything that defines a model: what `physreg estimate` fits and the other commands read.
struct ModelParameters {
    ModelVariant variant = ModelVariant::coupled;
    ModelRegion region = ModelRegion::body;
    CouplingStiffness coupling;              ///< N/m (coupled variant only)
    double parenchyma_young_pa = 2e5;        ///< paper 000's phantom moduli
    double tumour_young_pa = 5e6;
    double vessel_young_pa = 1e6;
    /// The gel body (region body): 100 kPa. CIRS gels are quoted at 10–30 kPa (the 057A data sheet
    /// gives none), but with 5 mm uniform-strain hexahedra a gel under 40 kPa folds an element under
    /// the deepest training compression (B, 25 mm; measured at 20 and 40 kPa, not at 100 kPa): the
    /// grid cannot resolve the gel's flow around the tool. `estimate` fits it (start here).
    /// Kidneys take the parenchyma's modulus; bone is held, so its modulus never acts.
    double body_young_pa = 1e5;
    double poisson_ratio = 0.49;
    Index3 grid{74, 54, 18};                 ///< cells over the region's bounding box, per image axis
    double support_radius_cells = 1.25;      ///< MLS support radius, element sizes
    /// Throws Error naming the parameter: moduli ≤ 0 or NaN, ν ∉ (0, 0.5), grid < 2, stiffness < 0.
    void validate() const;
};

/// JSON parameter file. `fingerprint` (of the rest mesh the parameters were fitted on) is written
/// with them; reading returns it so that the caller can refuse a file from another mesh.
void write_model_parameters(const std::filesystem::path& path, const ModelParameters& parameters, const std::string& fingerprint,
                            const std::string& extra_json = "");
ModelParameters read_model_parameters(const std::filesystem::path& path, std::string* fingerprint = nullptr);

struct LiverModel {
    ModelParameters parameters;
    VolumeMesh mesh;                         ///< the solved mesh (split interfaces for `coupled`)
    std::vector<std::int32_t> original_vertex; ///< per node: vertex of the unsplit grid mesh
    TissueTable tissues;
    std::unique_ptr<TledModel> tled;
    PenaltyCoupling coupling;                ///< empty unless `coupled`
    std::vector<std::int32_t> fixed_nodes;   ///< held in x, y, z: bone cells' nodes (body) or the posterior surface (liver)
    std::vector<std::int32_t> table_nodes;   ///< held along y only (frictionless table under the base; body)
    /// The supports above as solver constraints.
    std::vector<NodeConstraint> supports() const;
 
    std::set<std::int32_t> bone_labels;      ///< held cells' labels (body region)
    Vec3 cell_size_mm = Vec3::Zero();
    std::string fingerprint;                 ///< hash of the unsplit mesh (positions, cells, labels)
    /// Same mesh and tissues with new coupling stiffnesses (no re-meshing, no MLS rebuild).
    void set_coupling_stiffness(const CouplingStiffness& stiffness);
};

/// The model as the three registration modes share it (registration/model.hpp): mesh, tissues,
/// Neo-Hookean law, supports, the tissue coupling. Its surface is the boundary of the cells whose
/// label is in `surface_labels` — e.g. the liver's, the organ an intra-operative cloud sees inside
/// the body — or, with none given, the mesh's outer boundary.
Model to_model(const LiverModel& model, const std::set<std::int32_t>& surface_labels = {});

/// The compression mode's model (TLED, the tool's contact) of a shared model, so a tool can drive
/// any model on a grid of hexahedra (landmarks and the tool's reach use the grid's cells).
/// Supports holding whole nodes become fixed nodes, supports holding y alone table nodes (region
/// body); the coupling, if any, is kept (variant coupled). Throws Error naming `what` for
/// tetrahedra or a mesh without its grid, other partial supports, and auxiliary structures
/// (the explicit solver has none).
LiverModel compression_model(const Model& model, const std::string& what);

/// The grid a dataset's model gets when none is asked for: paper 000's 74 × 54 × 18 cells (`cap`)
/// over the liver's bounding box, or one cell per voxel along an axis where the liver (with its
/// lesions and vessels) spans fewer voxels than that (the small preset's 4 mm images). Throws
/// Error when `rest_labels` holds no liver-role label.
Index3 default_liver_grid(const LabelVolume& rest_labels, const LabelRoles& roles, const Index3& cap = Index3{74, 54, 18});
/// The same for a region: `liver` as above; `body` caps at 54 × 40 × 26 cells over the body's
/// bounding box (5 mm cells on the CIRS 057A body), one cell per voxel where the body spans fewer.
Index3 default_model_grid(const LabelVolume& rest_labels, const LabelRoles& roles, ModelRegion region);

/// Meshes the region's labels of `rest_labels` (liver roles; for `body` also the body, kidney and
/// bone roles, or every non-background label when no body label is named); `what` names the
/// input in messages. A body model without bone or without a flat base is an Error.
LiverModel build_liver_model(const LabelVolume& rest_labels, const LabelRoles& roles, const ModelParameters& parameters,
                             const std::string& what);

/// Paper 000's low-resolution model: `fine`'s mesh coarsened to `grid` cells (e.g. 24 × 18 × 18) by
/// the majority rule over fine cells, tissues directly connected (shared nodes, no coupling),
/// per-tissue moduli as in `fine`, the same posterior support. `fine_nodes` receives every fine
/// node's coarse cell and natural coordinates (rest).
LiverModel coarsen_liver_model(const LiverModel& fine, const Index3& grid, std::vector<NodeEmbedding>* fine_nodes = nullptr);

struct PredictionOptions {
    /// Static solver: dynamic relaxation (default: measured faster on these models, see
    /// bench/README.md) or Newton's method; both reach the same equilibrium.
    StaticMethod method = StaticMethod::relaxation;
    NewtonOptions newton;
    EquilibriumOptions equilibrium = default_equilibrium();
    /// Largest tool travel per relaxation iteration, in smallest-cell sizes (sets the tool ramp).
    double tool_speed_per_cell = 0.01;
    static EquilibriumOptions default_equilibrium(); ///< 1e-3 mm and residual 1e-3 of the largest force
    /// Optional start (3 per node): an equilibrium of the same mesh with the tool at its final
    /// position, e.g. from other parameters during estimation. The tool then starts there.
    std::vector<double> initial_displacement_mm;
    /// A tool that ends inside the model is an Error (require_no_tool_passage). false: recorded in
    /// CompressionPrediction::tool_passage only — the coarse-to-fine scheme's coarse model, whose
    /// cells are too coarse to hold the skin under the tool by design, and whose missing detail the
    /// enrichment database supplies.
    bool refuse_tool_passage = true;
};

struct CompressionPrediction {
    std::vector<double> displacement_mm;     ///< 3 per node of LiverModel::mesh
    LandmarkSet landmarks;                   ///< the rest landmarks moved by the model
    long iterations = 0;
    double seconds = 0.0;
    double max_displacement_mm = 0.0;
    double max_coupling_gap_mm = 0.0;        ///< largest |δ| over interface points (coupled)
    int slower_ramps = 0;                    ///< retries with a 3× slower tool ramp after a folded element
    int tool_points_inside = 0;              ///< tool_passage's samples inside the deformed model (0: the tool only pressed)
};

/// Where a tool went through the model's surface instead of pressing it (issue 46): points of the
/// tool at its final pose — the reference point and points a quarter radius from it in 14
/// directions — that lie inside the deformed model. Node-to-surface contact keeps nodes out of the
/// tool but not the faces between them: a tool pushed deep (or smaller than the cells) can slide the
/// skin nodes round it and end inside the tissue. A sphere that only presses bulges into a face
/// between nodes by less than three quarters of its radius unless the face's diagonal exceeds about
/// twice the radius (a tool the model's cells cannot resolve), so a pressing tool does not count.
struct ToolPassage {
    int samples = 0, samples_inside = 0;
    Vec3 first_inside = Vec3::Zero();  ///< mm, LPS: a tool point inside the deformed model
    bool passed() const { return samples_inside > 0; }
};
/// `u`: 3 per node of `mesh` (mm). Spheres only (other shapes: nothing sampled).
ToolPassage tool_passage(const VolumeMesh& mesh, const std::vector<double>& u, const Indenter& tool);
/// Throws Error naming `what` when tool_passage finds the tool inside the model: a result whose
/// tissue the tool has gone through is no prediction.
void require_no_tool_passage(const VolumeMesh& mesh, const std::vector<double>& u, const Indenter& tool, const std::string& what);

/// Static equilibrium with the tool moved from `tool.path.front()` (first contact) to
/// `tool.path.back()`; it starts two cells back so that the model's own surface is met. Landmarks
/// outside the mesh by more than one cell are an Error naming them; closer ones take the nearest
/// cell's interpolation. Throws Error on inversion or non-convergence, and when the tool ends inside
/// the model (require_no_tool_passage), naming `what`.
CompressionPrediction predict_compression(const LiverModel& model, const Indenter& tool, const LandmarkSet& rest_landmarks,
                                          const PredictionOptions& options, const std::string& what);

/// Follows a tool through a sequence of positions, each equilibrium warm-started from the previous
/// one (the run-time use: a new tracked tool position → the organ at equilibrium).
class CompressionTracker {
public:
    /// `tool`: shape and first-contact position (path.front()); it starts two cells back.
    CompressionTracker(const LiverModel& model, const Indenter& tool, const PredictionOptions& options);
    struct Update {
        long iterations = 0;
        double seconds = 0.0;
    };
    /// Moves the tool's reference point to `position_mm` and relaxes to equilibrium, starting from
    /// the last equilibrium extrapolated linearly along the tool's motion (the previous update's
    /// increment, scaled by the travel), which tracking a steadily moving tool makes a close guess.
    Update move_to(const Vec3& position_mm, const std::string& what);
    std::vector<double> displacement_mm() const { return m_solver.displacement_mm(); }

private:
    const LiverModel& m_model;
    Indenter m_tool;
    PredictionOptions m_options;
    StaticSolver m_solver;
    Vec3 m_position;
    std::vector<double> m_previous; ///< the equilibrium before the current one (extrapolation)
    double m_previous_travel = 0.0;
};

/// Moves landmarks with nodal displacements of the model (the interpolation predict_compression uses).
LandmarkSet move_landmarks(const LiverModel& model, const std::vector<double>& displacement_mm, const LandmarkSet& rest_landmarks);

/// A displacement of `from` carried to the nodes of `to` (the same region as another variant or
/// grid): `from`'s field interpolated at `to`'s rest nodes, e.g. a warm start for `to`. Throws Error
/// for a node of `to` more than one cell of `from` outside its mesh.
std::vector<double> transfer_displacement(const LiverModel& from, const std::vector<double>& displacement_mm, const LiverModel& to);

} // namespace physreg
