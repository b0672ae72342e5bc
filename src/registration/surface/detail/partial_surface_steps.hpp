// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The steps of register_partial_surface (partial_surface_registration.cpp), shared by its three
// files: the supports and where forces act (partial_surface_supports.cpp), the methods and the
// pipeline (partial_surface_registration.cpp), and what judges a result (partial_surface_judges.cpp).
#include "physreg/mesh/coarsen.hpp"
#include "physreg/registration/surface/partial_surface_registration.hpp"
#include "physreg/registration/surface/surface_registration.hpp"

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace physreg::surface_detail {

using nlohmann::json;

inline double seconds_since(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// ---- supports and loads (partial_surface_supports.cpp) -------------------------------------------

struct Supports {
    std::vector<std::int32_t> nodes; ///< sorted, unique
    json sources = json::array();
};

/// One way the organ may be held (issue 46 item 3): tried, judged by the data, reported.
struct SupportHypothesis {
    std::string name;      ///< named, posterior, springs, none (or their union for an explicit --support)
    Supports supports;
    double stiffness = 0.0; ///< N/mm per node and direction; 0: held
    std::string why;       ///< why it is offered
};

/// The region where the tool may press (issue 56 item 2): the union of the settings' node file,
/// load points and tool path and the case's node ids; empty: anywhere on the surface.
struct LoadRegion {
    std::vector<std::int32_t> nodes; ///< sorted, unique surface nodes
    json sources = json::array();
    double nearest_cloud_mm = 0.0;   ///< from the region to the nearest cloud point
};

/// Node ids from a file: one or more per line (commas, semicolons or blanks between), '#' comments,
/// an optional header word; Error naming `option` and the file for anything else.
std::vector<std::int32_t> read_node_ids(const std::string& path, std::size_t node_count, const std::string& option);
/// The soft springs' stiffness of the springs hypothesis, N/mm per node and direction.
double spring_stiffness_n_per_mm(const PartialSurfaceCase& c, const PartialSurfaceSettings& s);
/// The hypotheses to try, the most constrained first.
std::vector<SupportHypothesis> support_hypotheses(const PartialSurfaceCase& c, const PartialSurfaceSettings& s, const LoadRegion& load);
/// Where forces may act; Error naming the source for nodes off the surface or far from the cloud.
LoadRegion load_region(const PartialSurfaceCase& c, const PartialSurfaceSettings& s);

// ---- what judges a result (partial_surface_judges.cpp) -------------------------------------------

struct Judges {
    std::vector<NodeEmbedding> landmark_cells;
    std::vector<std::uint8_t> node_used;
    std::vector<std::optional<Vec3>> truth_at_nodes;
    std::function<double(const std::vector<double>&)> strain_energy_mj;
};

/// A method's figures without the truth (fit, energy, implied pose) and with it (TRE, Hausdorff).
json evaluate(const PartialSurfaceMethod& m, const PartialSurfaceCase& c, const Judges& judges);
/// Whether the data decide between the methods.
json determinacy(const std::vector<PartialSurfaceMethod>& methods, const json& evaluated, bool rigid_pose_determined);
/// The truth's displacement at each model node (empty without a truth mesh).
std::vector<std::optional<Vec3>> truth_at_nodes(const PartialSurfaceCase& c);
/// The mean cloud-to-model distance a model that explains the cloud reaches (1.2 sigma).
double discrepancy_level_mm(const PartialSurfaceSettings& s);
/// The diagonal of the model's bounding box, mm.
double model_size_mm(const VolumeMesh& mesh);
/// The error the answer's strain energy predicts (adjoint method only).
json predicted_error_json(const json& evaluated, const std::string& requested, const std::string& answer, const std::string& support,
                          const VolumeMesh& mesh, double young_modulus_pa);
/// The RMS over the nodes of the distance between two nodal displacements, mm.
double nodal_rms_mm(const std::vector<double>& a, const std::vector<double>& b);
/// The cloud-halves check: the cloud's two random halves registered apart.
json cloud_halves_check(const PartialSurfaceCase& c, const PartialSurfaceSettings& s, const TledModel& model, const SurfaceMatcher& matcher,
                        SurfaceRegistrationOptions options, const std::vector<double>& answer, const Judges& judges,
                        const std::function<void(double, const std::string&)>& report);

// ---- the supports chosen by the data (partial_surface_supports.cpp) ------------------------------

struct SupportDecision {
    std::size_t chosen = 0;
    std::vector<SurfaceRegistrationResult> runs; ///< one per hypothesis tried, in order
    json report;                                 ///< summary.json's support_hypotheses
    std::vector<std::string> notes;              ///< supports the data contradict, looser ones that fit alike elsewhere
};

/// The hypotheses registered in order (named supports that explain the data to the noise end the
/// search); of those the data do not tell apart from the best fit, the named supports win, else the
/// most constrained unless a looser one needs clearly less strain energy (≤ 0.9×).
SupportDecision choose_support(const PartialSurfaceCase& c, const PartialSurfaceSettings& s, const std::vector<SupportHypothesis>& hypotheses,
                               const TledModel& model, const SurfaceMatcher& matcher, SurfaceRegistrationOptions options, Judges& judges,
                               const std::function<void(double, const std::string&)>& report);

} // namespace physreg::surface_detail
