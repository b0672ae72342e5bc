// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/liver_model.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/config_keys.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/point_location.hpp"

#include <cerrno>
#include <cstring>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <fstream>
#include <set>

namespace physreg {
namespace {
using json = nlohmann::json;
constexpr const char* parameters_format = "physreg-model-parameters";
constexpr int parameters_version = 1;
} // namespace

ModelVariant parse_model_variant(const std::string& text)
{
    if (text == "homogeneous") return ModelVariant::homogeneous;
    if (text == "shared-nodes") return ModelVariant::shared_nodes;
    if (text == "coupled") return ModelVariant::coupled;
    fail("model variant '{}' is not one of homogeneous, shared-nodes, coupled", text);
}

std::string to_string(ModelVariant variant)
{
    switch (variant) {
    case ModelVariant::homogeneous: return "homogeneous";
    case ModelVariant::shared_nodes: return "shared-nodes";
    case ModelVariant::coupled: return "coupled";
    }
    return "?";
}

void ModelParameters::validate() const
{
    coupling.validate();
    const std::pair<const char*, double> moduli[] = {
        {"parenchyma Young's modulus", parenchyma_young_pa}, {"tumour Young's modulus", tumour_young_pa}, {"vessel Young's modulus", vessel_young_pa}};
    for (const auto& [name, value] : moduli)
        if (!(value > 0) || !std::isfinite(value)) fail("{} must be a positive finite value in Pa (got {})", name, value);
    if (!(poisson_ratio > 0 && poisson_ratio < 0.5)) fail("Poisson's ratio must lie in (0, 0.5) (got {})", poisson_ratio);
    for (int a = 0; a < 3; ++a)
        if (grid[a] < 2 || grid[a] > 2000) fail("model grid: {} cells along axis {} (need 2 … 2000)", grid[a], a);
    if (!(support_radius_cells >= 1.0) || !std::isfinite(support_radius_cells))
        fail("MLS support radius must be ≥ 1 element size (got {})", support_radius_cells);
}

void write_model_parameters(const std::filesystem::path& path, const ModelParameters& p, const std::string& fingerprint,
                            const std::string& extra_json)
{
    p.validate();
    json j;
    j["format"] = parameters_format;
    j["format_version"] = parameters_version;
    j["variant"] = to_string(p.variant);
    j["coupling_stiffness_n_per_m"] = {{"parenchyma_tumour", p.coupling.parenchyma_tumour_n_per_m},
                                       {"parenchyma_vessel", p.coupling.parenchyma_vessel_n_per_m}};
    j["young_modulus_pa"] = {{"parenchyma", p.parenchyma_young_pa}, {"tumour", p.tumour_young_pa}, {"vessel", p.vessel_young_pa}};
    j["poisson_ratio"] = p.poisson_ratio;
    j["grid_cells"] = {p.grid[0], p.grid[1], p.grid[2]};
    j["mls_support_radius_cells"] = p.support_radius_cells;
    j["mesh_fingerprint"] = fingerprint;
    if (!extra_json.empty()) j["fit"] = json::parse(extra_json);
    write_atomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp);
        out << j.dump(2) << "\n";
        if (!out) fail("cannot write parameter file '{}': {}", path.string(), std::strerror(errno));
    });
}

ModelParameters read_model_parameters(const std::filesystem::path& path, std::string* fingerprint)
{
    require_existing_file(path, "parameter file '" + path.string() + "'");
    std::ifstream in(path);
    if (!in) fail("parameter file '{}': cannot open", path.string());
    json j;
    try {
        in >> j;
    } catch (const json::exception& e) {
        fail("parameter file '{}': not valid JSON: {}", path.string(), e.what());
    }
    ModelParameters p;
    const std::string what = "parameter file '" + path.string() + "'";
    if (!j.is_object()) fail("{}: expected a JSON object", what);
    const auto keys_of = [](const json& object) {
        std::vector<std::string> keys;
        if (object.is_object())
            for (const auto& item : object.items()) keys.push_back(item.key());
        return keys;
    };
    require_known_keys(keys_of(j),
                       {"format", "format_version", "variant", "coupling_stiffness_n_per_m", "young_modulus_pa", "poisson_ratio", "grid_cells",
                        "mls_support_radius_cells", "mesh_fingerprint", "fit"},
                       what, "the file");
    if (j.contains("coupling_stiffness_n_per_m"))
        require_known_keys(keys_of(j["coupling_stiffness_n_per_m"]), {"parenchyma_tumour", "parenchyma_vessel"}, what, "coupling_stiffness_n_per_m");
    if (j.contains("young_modulus_pa")) require_known_keys(keys_of(j["young_modulus_pa"]), {"parenchyma", "tumour", "vessel"}, what, "young_modulus_pa");
    try {
        if (j.at("format").get<std::string>() != parameters_format) fail("parameter file '{}': format is not {}", path.string(), parameters_format);
        if (j.at("format_version").get<int>() != parameters_version)
            fail("parameter file '{}': format version {} (this physreg reads {})", path.string(), j.at("format_version").get<int>(), parameters_version);
        p.variant = parse_model_variant(j.at("variant").get<std::string>());
        p.coupling.parenchyma_tumour_n_per_m = j.at("coupling_stiffness_n_per_m").at("parenchyma_tumour").get<double>();
        p.coupling.parenchyma_vessel_n_per_m = j.at("coupling_stiffness_n_per_m").at("parenchyma_vessel").get<double>();
        p.parenchyma_young_pa = j.at("young_modulus_pa").at("parenchyma").get<double>();
        p.tumour_young_pa = j.at("young_modulus_pa").at("tumour").get<double>();
        p.vessel_young_pa = j.at("young_modulus_pa").at("vessel").get<double>();
        p.poisson_ratio = j.at("poisson_ratio").get<double>();
        const auto g = j.at("grid_cells").get<std::vector<std::int64_t>>();
        if (g.size() != 3) fail("parameter file '{}': grid_cells needs 3 values", path.string());
        p.grid = {g[0], g[1], g[2]};
        p.support_radius_cells = j.at("mls_support_radius_cells").get<double>();
        if (fingerprint) *fingerprint = j.at("mesh_fingerprint").get<std::string>();
    } catch (const json::exception& e) {
        fail("parameter file '{}': missing or malformed entry: {}", path.string(), e.what());
    }
    try {
        p.validate();
    } catch (const Error& e) {
        fail("parameter file '{}': {}", path.string(), e.what());
    }
    return p;
}

namespace {

// The posterior-facing organ surface rests on the phantom's base (as in the ground truth).
std::vector<char> posterior_support(const VolumeMesh& mesh)
{
    std::vector<char> fixed(mesh.node_count(), 0);
    for (const auto& f : boundary_faces(mesh))
        if (f.normal.y() > 0.5)
            for (int a = 0; a < f.count; ++a) fixed[static_cast<std::size_t>(f.nodes[a])] = 1;
    return fixed;
}

std::string mesh_fingerprint(const VolumeMesh& mesh)
{
    // FNV-1a over node positions (to 1e-6 mm), connectivity and labels.
    std::uint64_t h = 0xcbf29ce484222325ull;
    auto mix = [&](std::int64_t v) {
        for (int b = 0; b < 8; ++b) h = (h ^ static_cast<std::uint64_t>((v >> (8 * b)) & 0xff)) * 0x100000001b3ull;
    };
    mix(static_cast<std::int64_t>(mesh.node_count()));
    mix(static_cast<std::int64_t>(mesh.cell_count()));
    for (const auto& x : mesh.nodes)
        for (int a = 0; a < 3; ++a) mix(std::llround(x[a] * 1e6));
    for (const auto c : mesh.cells) mix(c);
    for (const auto l : mesh.cell_labels) mix(l);
    return fmt::format("{:016x}-{}n-{}e", h, mesh.node_count(), mesh.cell_count());
}

} // namespace

void LiverModel::set_coupling_stiffness(const CouplingStiffness& stiffness)
{
    parameters.coupling = stiffness;
    coupling.set_stiffness(stiffness);
}

Index3 default_liver_grid(const LabelVolume& rest_labels, const LabelRoles& roles, const Index3& cap)
{
    std::vector<char> model_label(65536, 0);
    for (const auto* set : {&roles.liver, &roles.lesion, &roles.vessel})
        for (const auto l : *set)
            if (l >= 0 && l < 65536) model_label[static_cast<std::size_t>(l)] = 1;
    const auto& size = rest_labels.geometry.size;
    Index3 lo{size[0], size[1], size[2]}, hi{-1, -1, -1};
    for (std::int64_t k = 0; k < size[2]; ++k)
        for (std::int64_t j = 0; j < size[1]; ++j)
            for (std::int64_t i = 0; i < size[0]; ++i)
                if (model_label[rest_labels.labels[static_cast<std::size_t>(i + size[0] * (j + size[1] * k))]]) {
                    const Index3 at{i, j, k};
                    for (int a = 0; a < 3; ++a) {
                        lo[a] = std::min(lo[a], at[a]);
                        hi[a] = std::max(hi[a], at[a]);
                    }
                }
    if (hi[0] < 0) fail("default model grid: no liver label ({}) in the label map", fmt::join(roles.liver, ","));
    Index3 grid;
    for (int a = 0; a < 3; ++a) grid[a] = std::max<std::int64_t>(2, std::min<std::int64_t>(cap[a], hi[a] - lo[a] + 1));
    return grid;
}

LiverModel build_liver_model(const LabelVolume& rest_labels, const LabelRoles& roles, const ModelParameters& parameters,
                             const std::string& what)
{
    parameters.validate();
    LiverModel model;
    model.parameters = parameters;
    std::set<std::int32_t> present;
    for (const auto l : rest_labels.labels) present.insert(l);
    std::map<std::int32_t, TissueGroup> groups;
    const bool homogeneous = parameters.variant == ModelVariant::homogeneous;
    auto add = [&](const std::set<std::int32_t>& labels, TissueGroup group, const char* name, double young) {
        for (const auto l : labels) {
            if (!present.count(l)) continue;
            const double e = homogeneous ? parameters.parenchyma_young_pa : young;
            model.tissues.tissues.push_back({l, fmt::format("{}_{}", name, l), e, parameters.poisson_ratio, 1000.0});
            groups[l] = group;
        }
    };
    add(roles.liver, TissueGroup::parenchyma, "parenchyma", parameters.parenchyma_young_pa);
    add(roles.lesion, TissueGroup::tumour, "tumour", parameters.tumour_young_pa);
    add(roles.vessel, TissueGroup::vessel, "vessel", parameters.vessel_young_pa);
    if (model.tissues.tissues.empty())
        fail("{}: no liver label ({}) in the label map", what, fmt::join(roles.liver, ","));
    for (const auto l : present)
        if (l != 0 && !groups.count(l)) model.tissues.ignored_labels.insert(l); // body, bone, kidneys: not the liver
    model.tissues.validate(what);
    MeshingOptions meshing;
    meshing.grid_dims = parameters.grid;
    meshing.components = ComponentPolicy::keep_all;
    VolumeMesh grid_mesh = mesh_label_volume(rest_labels, model.tissues, meshing, what).mesh;
    model.fingerprint = mesh_fingerprint(grid_mesh);
    model.cell_size_mm = grid_mesh.grid->cell_size;
    const std::vector<char> fixed_vertex = posterior_support(grid_mesh);
    if (parameters.variant == ModelVariant::coupled) {
        CouplingOptions options;
        options.support_radius_cells = parameters.support_radius_cells;
        SplitMesh split = split_tissue_interfaces(grid_mesh, groups, parameters.coupling, options);
        model.mesh = std::move(split.mesh);
        model.original_vertex = std::move(split.original_vertex);
        model.coupling = std::move(split.coupling);
    } else {
        model.mesh = std::move(grid_mesh);
        model.original_vertex.resize(model.mesh.node_count());
        std::iota(model.original_vertex.begin(), model.original_vertex.end(), 0);
    }
    for (std::size_t n = 0; n < model.mesh.node_count(); ++n)
        if (fixed_vertex[static_cast<std::size_t>(model.original_vertex[n])]) model.fixed_nodes.push_back(static_cast<std::int32_t>(n));
    if (model.fixed_nodes.empty()) fail("{}: the liver has no posterior-facing surface to rest on", what);
    model.tled = std::make_unique<TledModel>(model.mesh, model.tissues, TledOptions{});
    return model;
}

LiverModel coarsen_liver_model(const LiverModel& fine, const Index3& grid, std::vector<NodeEmbedding>* fine_nodes)
{
    CoarseningResult coarse = coarsen(fine.mesh, grid, ComponentPolicy::keep_all);
    LiverModel model;
    model.parameters = fine.parameters;
    model.parameters.variant = ModelVariant::shared_nodes;
    model.parameters.grid = grid;
    model.tissues = fine.tissues;
    model.mesh = std::move(coarse.mesh);
    model.fingerprint = mesh_fingerprint(model.mesh);
    model.cell_size_mm = model.mesh.grid->cell_size;
    model.original_vertex.resize(model.mesh.node_count());
    std::iota(model.original_vertex.begin(), model.original_vertex.end(), 0);
    const std::vector<char> fixed = posterior_support(model.mesh);
    for (std::size_t n = 0; n < fixed.size(); ++n)
        if (fixed[n]) model.fixed_nodes.push_back(static_cast<std::int32_t>(n));
    if (model.fixed_nodes.empty()) fail("coarse model: the liver has no posterior-facing surface to rest on");
    model.tled = std::make_unique<TledModel>(model.mesh, model.tissues, TledOptions{});
    if (fine_nodes) *fine_nodes = std::move(coarse.fine_nodes);
    return model;
}

EquilibriumOptions PredictionOptions::default_equilibrium()
{
    EquilibriumOptions o;
    o.displacement_tolerance_mm = 1e-3;
    o.residual_tolerance = 1e-3;
    o.max_iterations = 200000;
    return o;
}

LandmarkSet move_landmarks(const LiverModel& model, const std::vector<double>& displacement_mm, const LandmarkSet& rest)
{
    std::vector<Vec3> points;
    for (const auto& l : rest) points.push_back(l.position);
    const auto where = embed_in_grid_mesh(model.mesh, points);
    const double reach = model.cell_size_mm.maxCoeff();
    LandmarkSet moved = rest;
    for (std::size_t i = 0; i < rest.size(); ++i) {
        NodeEmbedding e = where[i];
        if (!e.inside && e.distance_mm > reach)
            fail("landmark '{}' at ({:.2f}, {:.2f}, {:.2f}) mm lies {:.2f} mm outside the model's mesh (more than one cell, {:.2f} mm)",
                 rest[i].name, rest[i].position.x(), rest[i].position.y(), rest[i].position.z(), e.distance_mm, reach);
        // Just outside the voxelised surface: the nearest cell's field, clamped to it (no extrapolation).
        e.natural = e.natural.cwiseMax(-1.0).cwiseMin(1.0);
        const auto u = interpolate_nodal(model.mesh, e, displacement_mm, 3);
        moved[i].position += Vec3(u[0], u[1], u[2]);
    }
    return moved;
}

CompressionPrediction predict_compression(const LiverModel& model, const Indenter& tool, const LandmarkSet& rest_landmarks,
                                          const PredictionOptions& options, const std::string& what)
{
    if (tool.path.size() < 2) fail("{}: the tool needs a path from first contact to the final position", what);
    const Vec3 contact = tool.path.front(), end = tool.path.back();
    const double depth = (end - contact).norm();
    if (!(depth > 0)) fail("{}: the tool does not move (contact and final positions coincide)", what);
    const Vec3 d = (end - contact) / depth;
    // The model's voxelised surface may stand proud of the true one: start two cells back.
    const double back = 2.0 * model.cell_size_mm.maxCoeff();
    Indenter moving = tool;
    moving.path = {contact - back * d, end};
    Loads loads;
    loads.constraints.push_back({"posterior_support", model.fixed_nodes, {true, true, true}, Vec3::Zero()});
    loads.indenters.push_back(moving);
    EquilibriumOptions equilibrium = options.equilibrium;
    const double travel = depth + back;
    equilibrium.ramp_iterations = std::max<long>(equilibrium.ramp_iterations,
                                                 std::lround(std::ceil(1.875 * travel / (options.tool_speed_per_cell * model.cell_size_mm.minCoeff()))));
    StaticSolver solver(*model.tled, {options.method, equilibrium, options.newton});
    solver.set_coupling(model.coupling.empty() ? nullptr : &model.coupling);
    solver.set_loads(loads);
    CompressionPrediction out;
    const auto t0 = std::chrono::steady_clock::now();
    StaticSolveResult summary;
    try {
        summary = solver.solve(1.0);
    } catch (const Error& e) {
        fail("{}: {}", what, e.what());
    }
    if (!summary.converged) fail("{}: {}", what, summary.message);
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    out.iterations = summary.iterations;
    out.displacement_mm = solver.displacement_mm();
    for (std::size_t n = 0; n < model.mesh.node_count(); ++n)
        out.max_displacement_mm = std::max(out.max_displacement_mm, Vec3(out.displacement_mm[3 * n], out.displacement_mm[3 * n + 1],
                                                                         out.displacement_mm[3 * n + 2]).norm());
    if (!model.coupling.empty())
        for (const auto& g : model.coupling.gaps_mm(out.displacement_mm)) out.max_coupling_gap_mm = std::max(out.max_coupling_gap_mm, g.norm());
    out.landmarks = move_landmarks(model, out.displacement_mm, rest_landmarks);
    return out;
}

CompressionTracker::CompressionTracker(const LiverModel& model, const Indenter& tool, const PredictionOptions& options)
    : m_model(model), m_tool(tool), m_options(options), m_solver(*model.tled, {options.method, options.equilibrium, options.newton})
{
    if (tool.path.size() < 2) fail("tracker: the tool needs a path from first contact onwards");
    const Vec3 d = (tool.path.back() - tool.path.front()).normalized();
    m_position = tool.path.front() - 2.0 * model.cell_size_mm.maxCoeff() * d;
    m_tool.path = {m_position};
    m_solver.set_coupling(model.coupling.empty() ? nullptr : &model.coupling);
}

CompressionTracker::Update CompressionTracker::move_to(const Vec3& position, const std::string& what)
{
    // The tool moves from where it was (load factor 0) to the new position (1); the solver's state
    // is the previous equilibrium.
    Indenter tool = m_tool;
    tool.path = {m_position, position};
    Loads loads;
    loads.constraints.push_back({"posterior_support", m_model.fixed_nodes, {true, true, true}, Vec3::Zero()});
    loads.indenters.push_back(tool);
    m_solver.set_loads(loads);
    m_solver.reset_load_factor();
    const double travel = (position - m_position).norm();
    const std::vector<double> current = m_solver.displacement_mm();
    if (!m_previous.empty() && m_previous_travel > 0) {
        std::vector<double> guess(current.size());
        const double ratio = travel / m_previous_travel;
        for (std::size_t k = 0; k < guess.size(); ++k) guess[k] = current[k] + ratio * (current[k] - m_previous[k]);
        m_solver.set_displacement(guess);
    }
    const long ramp = std::max<long>(1, std::lround(std::ceil(1.875 * travel / (m_options.tool_speed_per_cell * m_model.cell_size_mm.minCoeff()))));
    const auto t0 = std::chrono::steady_clock::now();
    StaticSolveResult s;
    try {
        s = m_solver.solve(1.0, ramp);
    } catch (const Error& e) {
        if (m_previous.empty()) fail("{}: {}", what, e.what());
        // The extrapolated guess folded an element: start from the last equilibrium instead.
        m_solver.set_displacement(current);
        m_solver.reset_load_factor();
        try {
            s = m_solver.solve(1.0, ramp);
        } catch (const Error& again) {
            fail("{}: {}", what, again.what());
        }
    }
    if (!s.converged) fail("{}: {}", what, s.message);
    m_previous = current;
    m_previous_travel = travel;
    m_position = position;
    return {s.iterations, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()};
}

} // namespace physreg
