// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The phantom's ground-truth model: deliberately *not* the family of models physreg registers with
// (uniform one-point hexahedra, Neo-Hookean, ν 0.49, liver only, TLED relaxation), so that
// registration errors measured on the phantom are not an inverse crime:
// - the whole CIRS-057A-like body: the gel block with the organs embedded in it (tied: the organs
//   are cast into the gel), the bone removed and its surface fixed, the flat base on a frictionless
//   table; the tool presses the skin of the gel, and the liver deforms through the gel;
// - conforming linear tetrahedra from CGAL Mesh_3 (smooth interfaces, sizes per tissue);
// - compressible Mooney–Rivlin, ν 0.495–0.497, moduli drawn per seed from stated ranges;
// - static equilibrium by Newton's method (load steps, augmented-Lagrangian frictionless contact
//   with the rigid tool on the smooth skin), validated against CalculiX on a small case.
#include "physreg/model/loads.hpp"
#include "physreg/mechanics/implicit/newton_solver.hpp"
#include "physreg/mechanics/elements/tled_model.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/tetrahedral_meshing.hpp"
#include "physreg/phantom/abdominal_phantom.hpp"

#include <nlohmann/json.hpp>

#include <memory>
#include <set>
#include <string>
#include <vector>

namespace physreg {

enum class MaterialSet;

/// Sizes of the ground-truth mesh, mm (CGAL criteria: largest circumradius per region, surface
/// Delaunay ball radius).
struct GroundTruthMeshing {
    double organ_cell_mm = 3.0;   ///< parenchyma, lesions, vessels
    double kidney_cell_mm = 6.0;
    double body_cell_mm = 12.0;   ///< gel
    double facet_mm = 4.0;        ///< every surface and interface (the skin the tool presses included)
    double facet_distance_mm = 0.6;
    void validate() const;
};

/// The tissues of the ground truth with moduli drawn from the seed; `ranges` gets the ranges
/// (JSON, for the manifest). Labels of role bone are not tissues (removed, their surface fixed);
/// body (gel) is a tissue when present.
TissueTable draw_ground_truth_tissues(MaterialSet set, const LabelRoles& roles, const std::set<std::int32_t>& present,
                                      std::uint64_t seed, nlohmann::json& ranges);

/// One discretisation of the ground truth: the body (compressions) or the organs alone (the
/// insufflation state, where the gas frees the liver's anterior surface).
struct GroundTruthModel {
    std::string name;                        ///< "body" or "organs"
    VolumeMesh mesh;
    std::unique_ptr<TledModel> model;        ///< Mooney–Rivlin linear tetrahedra (implicit solvers only)
    std::vector<BoundaryFace> faces;         ///< outer boundary
    Loads supports;                          ///< fixed bone surface, table, or posterior organ faces
    std::string support_description;
    std::set<std::int32_t> labels;           ///< tissues in the mesh (their voxels move in warped images)
    TetrahedronQuality quality;
    double organ_cell_mm = 0.0;
};

/// Where the organs alone are held (issue 46 item 6: a truth whose supports the registration is
/// not told): the surface faces whose outward normal · `direction` > 0.5. `name` labels it in the
/// manifest (posterior, the default, as the vena cava and ligaments hold a liver lying supine).
struct OrganSupport {
    std::string name = "posterior";
    Vec3 direction = Vec3::UnitY();
};
/// An anatomical name (posterior, anterior, inferior, superior, left, right; LPS) or x,y,z.
/// Throws Error naming `what`.
OrganSupport parse_organ_support(const std::string& text, const std::string& what);

/// The body model (the organs and the gel, bone removed) when the label map has a body label;
/// otherwise the organs alone, held at `organ_support`.
GroundTruthModel build_body_model(const LabelVolume& labels, const LabelRoles& roles, const TissueTable& tissues,
                                  const GroundTruthMeshing& meshing, unsigned seed, const OrganSupport& organ_support = {});
/// The organs (every liver-role and kidney tissue) cut out of `body`, held at `organ_support`.
GroundTruthModel build_organ_model(const GroundTruthModel& body, const LabelRoles& roles, const TissueTable& tissues,
                                   const OrganSupport& organ_support = {});

struct GroundTruthSolve {
    std::vector<double> displacement_mm;
    int load_steps = 0, newton_iterations = 0, contact_updates = 0, factorisations = 0, load_cuts = 0;
    double seconds = 0.0, max_displacement_mm = 0.0, max_penetration_mm = 0.0;
    double worst_residual_ratio = 0.0;       ///< largest free residual / largest internal force, worst step
};

/// Newton tolerance of the ground truth (largest free residual / largest internal nodal force).
constexpr double ground_truth_residual_tolerance = 1e-3;
constexpr double ground_truth_penetration_tolerance_mm = 0.1; // about the chord sag between skin nodes

/// Static equilibrium under `loads` (the model's supports are added) in `load_steps` equal steps.
/// Throws Error naming `what` for an element the load folds or no convergence.
GroundTruthSolve solve_ground_truth_state(const GroundTruthModel& model, Loads loads, int load_steps, const std::string& what);

/// Builds a small version of the ground truth (a gel block with a stiffer inclusion, the same
/// mesher, law and ν), indents it by prescribed nodal displacements, solves it with physreg's
/// Newton and with CalculiX (C3D4, MOONEY-RIVLIN, NLGEOM) and returns the RMS nodal difference as
/// a fraction of CalculiX's peak displacement, and a description. Throws when ccx is missing.
struct CalculixValidation {
    double relative_rms = 0.0, peak_mm = 0.0;
    std::size_t nodes = 0, cells = 0;
    std::string description;
};
CalculixValidation validate_ground_truth_against_calculix(const TissueTable& tissues, std::int32_t gel_label, std::int32_t inclusion_label,
                                                          const std::filesystem::path& work_directory);

} // namespace physreg
