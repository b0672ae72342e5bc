// SPDX-License-Identifier: GPL-3.0-or-later
// Options and helpers shared by the commands that build the liver model.
#include "registration_cli.hpp"


#include "physreg/core/error.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/registration/compression/condensed_contact.hpp"

#include <cmath>
#include <sstream>

namespace physreg::cli {
using nlohmann::json;

std::vector<std::string> split_names(const std::string& text, const std::string& option)
{
    std::vector<std::string> names;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ','))
        if (!item.empty()) names.push_back(item);
    if (names.empty()) fail("{}: no state names in '{}'", option, text);
    return names;
}

std::size_t parse_memory_limit(const std::string& text, const std::string& option)
{
    if (text == "auto") return 0;
    std::size_t used = 0;
    double value = 0.0;
    try {
        value = std::stod(text, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    const std::string suffix = text.substr(used);
    double unit = 0.0;
    if (suffix.empty()) unit = 1.0;
    else if (suffix == "K" || suffix == "k") unit = 1024.0;
    else if (suffix == "M") unit = 1024.0 * 1024.0;
    else if (suffix == "G") unit = 1024.0 * 1024.0 * 1024.0;
    else if (suffix == "T") unit = 1024.0 * 1024.0 * 1024.0 * 1024.0;
    if (used == 0 || unit == 0.0 || !std::isfinite(value) || !(value > 0) || value * unit < 1.0 || value * unit > 1e18)
        fail("{} must be auto or a positive size such as 8G, 512M or 1e9 (bytes; K, M, G, T are powers of 1024), got '{}'", option, text);
    return static_cast<std::size_t>(value * unit);
}

void add_model_options(CLI::App* sub, ModelOptions& m)
{
    sub->add_option("--variant", m.variant, "Model: homogeneous (Han et al.), shared-nodes (per-element materials) or coupled (MLS "
                                            "penalty coupling, paper 000; default)");
    sub->add_option("--region", m.region, "What the model covers: body (the gel body with the organs inside, bone held, base on the table; "
                                          "default) or liver (the liver alone, posterior surface held)");
    sub->add_option("--grid", m.grid, "Cells over the region's bounding box per image axis (default: body 54x40x26, liver 74x54x18, or one "
                                      "cell per voxel where the region spans fewer voxels)");
    sub->add_option("--body-modulus", m.body_modulus, "Young's modulus of the gel body, Pa (region body; default 1e5)");
    sub->add_option("--k-tumour", m.k_tumour, "Parenchyma–tumour coupling stiffness k_c,s-t, N/m (default 600, paper 000)");
    sub->add_option("--k-vessel", m.k_vessel, "Parenchyma–vessel coupling stiffness k_c,s-v, N/m (default 500, paper 000)");
    sub->add_option("--support-radius", m.support_radius, "MLS support radius, element sizes (default 1.25)");
    sub->add_option("--tool-speed", m.tool_speed, "Largest tool travel per relaxation iteration, in cell sizes (default 0.01; lower "
                                                  "it if elements under the tool invert)");
    sub->add_option("--tolerance", m.tolerance_mm, "Equilibrium: estimated distance to equilibrium, mm (default 1e-3)");
    sub->add_option("--residual", m.residual, "Equilibrium: largest free residual / largest internal force (default 1e-3)");
    sub->add_option("--solver", m.solver, "Static solver: relaxation (dynamic relaxation, default: the faster on these models) or newton "
                                          "(Newton's method, assembled tangent, stale-factor PCG; residual 1e-7 of the largest force); "
                                          "register-compression also takes condensed (the model linearised at rest, contact condensed "
                                          "onto the skin nodes the tool reaches, 20 tool updates: milliseconds per update)");
}

PredictionOptions prediction_options(const ModelOptions& m)
{
    if (!(m.tool_speed > 0 && m.tool_speed <= 0.5)) fail("--tool-speed must lie in (0, 0.5] cell sizes per iteration (got {})", m.tool_speed);
    if (!(m.tolerance_mm > 0 && m.tolerance_mm <= 1.0)) fail("--tolerance must lie in (0, 1] mm (got {})", m.tolerance_mm);
    if (!(m.residual > 0 && m.residual < 1.0)) fail("--residual must lie in (0, 1) (got {})", m.residual);
    PredictionOptions p;
    p.method = parse_static_method(m.solver);
    p.tool_speed_per_cell = m.tool_speed;
    p.equilibrium.displacement_tolerance_mm = m.tolerance_mm;
    p.equilibrium.residual_tolerance = m.residual;
    return p;
}

ModelParameters model_parameters(const ModelOptions& m, ModelParameters p)
{
    p.variant = parse_model_variant(m.variant);
    p.region = parse_model_region(m.region);
    if (m.body_modulus) p.body_young_pa = *m.body_modulus;
    if (!m.grid.empty()) p.grid = parse_grid_dims(m.grid, "--grid");
    if (m.k_tumour) p.coupling.parenchyma_tumour_n_per_m = *m.k_tumour;
    if (m.k_vessel) p.coupling.parenchyma_vessel_n_per_m = *m.k_vessel;
    if (m.support_radius) p.support_radius_cells = *m.support_radius;
    try {
        p.validate();
    } catch (const Error& e) {
        fail("model parameters: {}", e.what());
    }
    return p;
}

json parameters_json(const ModelParameters& p)
{
    return {{"variant", to_string(p.variant)},
            {"region", to_string(p.region)},
            {"k_c_s_t_n_per_m", p.coupling.parenchyma_tumour_n_per_m},
            {"k_c_s_v_n_per_m", p.coupling.parenchyma_vessel_n_per_m},
            {"young_modulus_pa", {{"parenchyma", p.parenchyma_young_pa}, {"tumour", p.tumour_young_pa}, {"vessel", p.vessel_young_pa}, {"body", p.body_young_pa}}},
            {"grid_cells", {p.grid[0], p.grid[1], p.grid[2]}}};
}

std::string tre_line(const TreReport& r)
{
    return fmt::format("all {:.3f} ± {:.3f} (max {:.3f}) | surface {:.3f} | internal {:.3f} (tumour {:.3f}, vessel {:.3f}) mm", r.all.mean_mm,
                       r.all.std_mm, r.all.max_mm, r.surface.mean_mm, r.internal.mean_mm, r.tumour.mean_mm, r.vessel.mean_mm);
}


LoadedModel load_model(const std::string& dataset, const std::string& parameters_file, const ModelOptions& options)
{
    LoadedModel out;
    out.dataset = read_phantom_dataset(dataset);
    const DatasetState& rest = out.dataset.state("rest");
    out.labels = read_label_volume(out.dataset.path(rest.files.at("labels")));
    out.rest_landmarks = read_landmarks(out.dataset.path(rest.files.at("landmarks")));
    ModelParameters p;
    std::string fingerprint;
    if (!parameters_file.empty()) {
        p = read_model_parameters(parameters_file, &fingerprint);
        if (options.variant != "coupled" || options.region != "body" || !options.grid.empty() || options.k_tumour || options.k_vessel ||
            options.body_modulus)
            fail("--parameters: the model comes from the parameter file; drop --variant/--region/--grid/--k-tumour/--k-vessel/--body-modulus");
    } else {
        // Without --grid the grid comes from the dataset (paper 000's, or one cell per voxel on a
        // coarse image such as the small preset's).
        if (options.grid.empty()) p.grid = default_model_grid(out.labels, out.dataset.roles, parse_model_region(options.region));
        p = model_parameters(options, p);
    }
    out.model = build_liver_model(out.labels, out.dataset.roles, p, out.dataset.path(rest.files.at("labels")).string());
    if (!fingerprint.empty() && fingerprint != out.model.fingerprint)
        fail("--parameters '{}': fitted on another mesh (fingerprint {}, this dataset's model {}); estimate again for this dataset",
             parameters_file, fingerprint, out.model.fingerprint);
    return out;
}

int blend_size(const std::string& text, const EnrichmentDatabase& db, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
               const LiverModel& fine, std::vector<double>* loo_mm)
{
    if (text == "auto") return choose_blend_size(db, coarse.mesh, fine_nodes, fine.mesh.nodes, 4, loo_mm);
    const auto number = parse_number(text);
    if (!number) fail("--blend: '{}' is neither auto nor a number", text);
    const int k = to_integer<int>(*number, "--blend", "the number of blended database entries");
    if (k < 1) fail("--blend must be ≥ 1 (got {})", k);
    return k;
}

double detail_length(const std::string& text, const EnrichmentDatabase& db, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                     const LiverModel& fine, EnrichmentMatching how, int k, const LandmarkSet& rest_landmarks,
                     std::vector<std::pair<double, double>>* loo_mm)
{
    if (text == "auto") {
        std::vector<Vec3> targets;
        for (const auto& l : rest_landmarks) targets.push_back(l.position);
        const auto scored = targets.empty() ? std::vector<std::int32_t>{} : nodes_near(fine.mesh, targets, 2.0 * fine.cell_size_mm.maxCoeff());
        return choose_detail_length(db, coarse.mesh, fine_nodes, fine.mesh.nodes, how, k, loo_mm, scored);
    }
    if (text == "inf") return std::numeric_limits<double>::infinity();
    const auto number = parse_number(text);
    if (!number || !(*number >= 0.0)) fail("--detail-length: '{}' is not auto, inf or a length ≥ 0 mm", text);
    return *number;
}

nlohmann::json length_json(double length_mm)
{
    return std::isinf(length_mm) ? nlohmann::json("inf") : nlohmann::json(length_mm);
}

} // namespace physreg::cli
