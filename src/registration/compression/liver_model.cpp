// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/compression/liver_model.hpp"

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
#include <functional>
#include <algorithm>
#include <array>
#include <limits>
#include <set>

namespace physreg {
namespace {
using json = nlohmann::json;
constexpr const char* parameters_format = "physreg-model-parameters";
constexpr int parameters_version = 2; // 2: region and the body's modulus (version 1 files are liver models)
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

ModelRegion parse_model_region(const std::string& text)
{
    if (text == "body") return ModelRegion::body;
    if (text == "liver") return ModelRegion::liver;
    fail("model region '{}' is not one of body, liver", text);
}

std::string to_string(ModelRegion region)
{
    return region == ModelRegion::body ? "body" : "liver";
}

void ModelParameters::validate() const
{
    coupling.validate();
    const std::pair<const char*, double> moduli[] = {
        {"parenchyma Young's modulus", parenchyma_young_pa}, {"tumour Young's modulus", tumour_young_pa}, {"vessel Young's modulus", vessel_young_pa},
        {"body (gel) Young's modulus", body_young_pa}};
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
    j["region"] = to_string(p.region);
    j["coupling_stiffness_n_per_m"] = {{"parenchyma_tumour", p.coupling.parenchyma_tumour_n_per_m},
                                       {"parenchyma_vessel", p.coupling.parenchyma_vessel_n_per_m}};
    j["young_modulus_pa"] = {{"parenchyma", p.parenchyma_young_pa}, {"tumour", p.tumour_young_pa}, {"vessel", p.vessel_young_pa}, {"body", p.body_young_pa}};
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
                       {"format", "format_version", "variant", "region", "coupling_stiffness_n_per_m", "young_modulus_pa", "poisson_ratio", "grid_cells",
                        "mls_support_radius_cells", "mesh_fingerprint", "fit"},
                       what, "the file");
    if (j.contains("coupling_stiffness_n_per_m"))
        require_known_keys(keys_of(j["coupling_stiffness_n_per_m"]), {"parenchyma_tumour", "parenchyma_vessel"}, what, "coupling_stiffness_n_per_m");
    if (j.contains("young_modulus_pa")) require_known_keys(keys_of(j["young_modulus_pa"]), {"parenchyma", "tumour", "vessel", "body"}, what, "young_modulus_pa");
    try {
        if (j.at("format").get<std::string>() != parameters_format) fail("parameter file '{}': format is not {}", path.string(), parameters_format);
        const int version = j.at("format_version").get<int>();
        if (version < 1 || version > parameters_version)
            fail("parameter file '{}': format version {} (this physreg reads 1 to {})", path.string(), version, parameters_version);
        p.variant = parse_model_variant(j.at("variant").get<std::string>());
        // Version 1 files predate the body model: they describe the liver alone.
        p.region = version == 1 ? ModelRegion::liver : parse_model_region(j.at("region").get<std::string>());
        if (version >= 2) p.body_young_pa = j.at("young_modulus_pa").at("body").get<double>();
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

namespace {

// The voxel index box of the labels `member` accepts; hi[0] < 0 when there are none.
void voxel_extent(const LabelVolume& labels, const std::function<bool(std::int32_t)>& member, Index3& lo, Index3& hi)
{
    const auto& size = labels.geometry.size;
    lo = {size[0], size[1], size[2]};
    hi = {-1, -1, -1};
    for (std::int64_t k = 0; k < size[2]; ++k)
        for (std::int64_t j = 0; j < size[1]; ++j)
            for (std::int64_t i = 0; i < size[0]; ++i)
                if (member(labels.labels[static_cast<std::size_t>(i + size[0] * (j + size[1] * k))])) {
                    const Index3 at{i, j, k};
                    for (int a = 0; a < 3; ++a) {
                        lo[a] = std::min(lo[a], at[a]);
                        hi[a] = std::max(hi[a], at[a]);
                    }
                }
}

// `cap` cells, or one per voxel along an axis the extent spans fewer voxels than that.
Index3 grid_within(const Index3& lo, const Index3& hi, const Index3& cap)
{
    Index3 grid;
    for (int a = 0; a < 3; ++a) grid[a] = std::max<std::int64_t>(2, std::min<std::int64_t>(cap[a], hi[a] - lo[a] + 1));
    return grid;
}

} // namespace

Index3 default_liver_grid(const LabelVolume& rest_labels, const LabelRoles& roles, const Index3& cap)
{
    Index3 lo, hi;
    voxel_extent(rest_labels, [&](std::int32_t l) { return roles.is_liver_tissue(l); }, lo, hi);
    if (hi[0] < 0) fail("default model grid: no liver label ({}) in the label map", fmt::join(roles.liver, ","));
    return grid_within(lo, hi, cap);
}

namespace {

// Supports of a body model on its grid mesh: every node of a bone cell is held (the spine is
// fixed, as in the ground truth), and the flat base — boundary faces facing posterior (+y) within
// half a cell of the body's largest y — rests on a frictionless table (y held). Without bone the
// base is bonded instead (x, y, z held), else nothing would stop the body sliding on the table.
void set_body_supports(LiverModel& model, const std::set<std::int32_t>& bone_labels, const std::string& what)
{
    const VolumeMesh& mesh = model.mesh;
    std::vector<char> fixed(mesh.node_count(), 0), table(mesh.node_count(), 0);
    for (std::size_t c = 0; c < mesh.cell_count(); ++c)
        if (bone_labels.count(mesh.cell_labels[c]))
            for (const auto n : mesh.cell(c)) fixed[static_cast<std::size_t>(n)] = 1;
    double y_max = -std::numeric_limits<double>::infinity();
    for (const auto& x : mesh.nodes) y_max = std::max(y_max, x.y());
    const double tolerance = 0.5 * model.cell_size_mm.y();
    for (const auto& f : boundary_faces(mesh))
        if (f.normal.y() > 0.5)
            for (int a = 0; a < f.count; ++a) {
                const auto n = static_cast<std::size_t>(f.nodes[a]);
                if (mesh.nodes[n].y() >= y_max - tolerance) table[n] = 1;
            }
    const bool has_bone = std::find(fixed.begin(), fixed.end(), 1) != fixed.end();
    if (std::find(table.begin(), table.end(), 1) == table.end())
        fail("{}: the body has no flat posterior base to rest on (no boundary face facing +y within {:.2f} mm of its back)", what, tolerance);
    if (!has_bone)
        logger()->warn("{}: no bone label in the body model: its base is bonded to the table (x, y, z held) instead of sliding on it", what);
    for (std::size_t n = 0; n < mesh.node_count(); ++n) {
        if (fixed[n] || (table[n] && !has_bone)) model.fixed_nodes.push_back(static_cast<std::int32_t>(n));
        else if (table[n]) model.table_nodes.push_back(static_cast<std::int32_t>(n));
    }
}

void set_liver_supports(LiverModel& model, const std::vector<char>& fixed_vertex, const std::string& what)
{
    for (std::size_t n = 0; n < model.mesh.node_count(); ++n)
        if (fixed_vertex[static_cast<std::size_t>(model.original_vertex[n])]) model.fixed_nodes.push_back(static_cast<std::int32_t>(n));
    if (model.fixed_nodes.empty()) fail("{}: the liver has no posterior-facing surface to rest on", what);
}

// The body's labels: the named body role, or (none named) every label outside the other roles.
std::set<std::int32_t> body_labels(const std::set<std::int32_t>& present, const LabelRoles& roles)
{
    if (!roles.body.empty()) return roles.body;
    std::set<std::int32_t> body;
    for (const auto l : present)
        if (l != 0 && !roles.is_liver_tissue(l) && !roles.bone.count(l) && !roles.kidney.count(l)) body.insert(l);
    return body;
}

} // namespace

std::vector<NodeConstraint> LiverModel::supports() const
{
    std::vector<NodeConstraint> out;
    out.push_back({parameters.region == ModelRegion::body ? "bone_support" : "posterior_support", fixed_nodes, {true, true, true}, Vec3::Zero()});
    if (!table_nodes.empty()) out.push_back({"table", table_nodes, {false, true, false}, Vec3::Zero()});
    return out;
}

Index3 default_model_grid(const LabelVolume& rest_labels, const LabelRoles& roles, ModelRegion region)
{
    if (region == ModelRegion::liver) return default_liver_grid(rest_labels, roles);
    if (std::none_of(rest_labels.labels.begin(), rest_labels.labels.end(), [&](auto l) { return roles.is_liver_tissue(l); }))
        fail("default model grid: no liver label ({}) in the label map", fmt::join(roles.liver, ","));
    // The body is the non-background region (every tissue lies inside it).
    Index3 lo, hi;
    voxel_extent(rest_labels, [](std::int32_t l) { return l > 0; }, lo, hi);
    return grid_within(lo, hi, Index3{54, 40, 26});
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
            if (!present.count(l) || groups.count(l)) continue;
            model.tissues.tissues.push_back({l, fmt::format("{}_{}", name, l), young, parameters.poisson_ratio, 1000.0});
            groups[l] = group;
        }
    };
    // Homogeneous: the liver is one material (Han et al.); the gel around it keeps its own.
    const double parenchyma = parameters.parenchyma_young_pa;
    add(roles.liver, TissueGroup::parenchyma, "parenchyma", parenchyma);
    add(roles.lesion, TissueGroup::tumour, "tumour", homogeneous ? parenchyma : parameters.tumour_young_pa);
    add(roles.vessel, TissueGroup::vessel, "vessel", homogeneous ? parenchyma : parameters.vessel_young_pa);
    if (model.tissues.tissues.empty())
        fail("{}: no liver label ({}) in the label map", what, fmt::join(roles.liver, ","));
    const bool body = parameters.region == ModelRegion::body;
    if (body) {
        // The organs are cast into the gel and tied to it (shared nodes, as the phantom is made),
        // so body, kidney and bone join the parenchyma's coupling group.
        const auto gel = body_labels(present, roles);
        if (gel.empty() || std::none_of(gel.begin(), gel.end(), [&](std::int32_t l) { return present.count(l) > 0; }))
            fail("{}: region body: no body label in the label map (labels found: {}); name it with the label roles or use --region liver",
                 what, fmt::join(present, ","));
        add(gel, TissueGroup::parenchyma, "body", parameters.body_young_pa);
        add(roles.kidney, TissueGroup::parenchyma, "kidney", parenchyma);
        add(roles.bone, TissueGroup::parenchyma, "bone", parameters.body_young_pa); // held: its modulus never acts
    }
    for (const auto l : present)
        if (l != 0 && !groups.count(l)) model.tissues.ignored_labels.insert(l); // liver region: body, bone, kidneys are not meshed
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
    if (body) {
        std::set<std::int32_t> bone;
        for (const auto l : roles.bone)
            if (present.count(l)) bone.insert(l);
        model.bone_labels = bone;
        set_body_supports(model, bone, what);
    } else {
        set_liver_supports(model, fixed_vertex, what);
    }
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
    model.bone_labels = fine.bone_labels;
    model.mesh = std::move(coarse.mesh);
    model.fingerprint = mesh_fingerprint(model.mesh);
    model.cell_size_mm = model.mesh.grid->cell_size;
    model.original_vertex.resize(model.mesh.node_count());
    std::iota(model.original_vertex.begin(), model.original_vertex.end(), 0);
    if (model.parameters.region == ModelRegion::body) set_body_supports(model, model.bone_labels, "coarse model");
    else set_liver_supports(model, posterior_support(model.mesh), "coarse model");
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

std::vector<double> transfer_displacement(const LiverModel& from, const std::vector<double>& displacement_mm, const LiverModel& to)
{
    if (displacement_mm.size() != 3 * from.mesh.node_count())
        fail("transfer displacement: {} values for {} nodes", displacement_mm.size(), from.mesh.node_count());
    const auto where = embed_in_grid_mesh(from.mesh, to.mesh.nodes);
    const double reach = from.cell_size_mm.maxCoeff();
    std::vector<double> out(3 * to.mesh.node_count());
    for (std::size_t n = 0; n < where.size(); ++n) {
        NodeEmbedding e = where[n];
        if (!e.inside && e.distance_mm > reach)
            fail("transfer displacement: node {} lies {:.2f} mm outside the other model's mesh (more than one cell, {:.2f} mm)", n, e.distance_mm, reach);
        e.natural = e.natural.cwiseMax(-1.0).cwiseMin(1.0);
        const auto u = interpolate_nodal(from.mesh, e, displacement_mm, 3);
        for (int d = 0; d < 3; ++d) out[3 * n + d] = u[d];
    }
    return out;
}

ToolPassage tool_passage(const VolumeMesh& mesh, const std::vector<double>& u, const Indenter& tool)
{
    ToolPassage out;
    if (tool.shape != IndenterShape::sphere || tool.path.empty()) return out;
    if (u.size() != 3 * mesh.node_count()) fail("tool passage: {} displacement values for {} nodes", u.size(), mesh.node_count());
    VolumeMesh deformed = mesh;
    for (std::size_t n = 0; n < deformed.node_count(); ++n) deformed.nodes[n] += Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]);
    const PointLocator locator(deformed);
    const Vec3 centre = tool.position(1.0);
    std::vector<Vec3> directions{Vec3::Zero()};
    for (int a = 0; a < 3; ++a)
        for (const double sign : {-1.0, 1.0}) directions.push_back(sign * Vec3::Unit(a));
    for (const double x : {-1.0, 1.0})
        for (const double y : {-1.0, 1.0})
            for (const double z : {-1.0, 1.0}) directions.push_back(Vec3(x, y, z).normalized());
    for (const auto& d : directions) {
        const Vec3 p = centre + 0.25 * tool.radius_mm * d;
        ++out.samples;
        if (locator.locate(p)) {
            if (out.samples_inside == 0) out.first_inside = p;
            ++out.samples_inside;
        }
    }
    return out;
}

void require_no_tool_passage(const VolumeMesh& mesh, const std::vector<double>& u, const Indenter& tool, const std::string& what)
{
    const ToolPassage p = tool_passage(mesh, u, tool);
    if (!p.passed()) return;
    const double depth = tool.path.size() > 1 ? (tool.path.back() - tool.path.front()).norm() : 0.0;
    fail("{}: the tool went through the model's surface instead of pressing it: {} of {} points of the {} mm sphere at its final position lie "
         "inside the deformed tissue (e.g. ({:.1f}, {:.1f}, {:.1f}) mm; the tool travelled {:.1f} mm from first contact, {:.2f}× its radius). The "
         "skin slid round the tool: its cells are too coarse for this depth (face contact holds up to about 1.5× the radius with cells under "
         "half the radius), or the condensed solver's linear kinematics cannot follow it. This is no prediction: use smaller cells under the "
         "tool, the relaxation solver or a shallower pose",
         what, p.samples_inside, p.samples, tool.radius_mm, p.first_inside.x(), p.first_inside.y(), p.first_inside.z(), depth,
         tool.radius_mm > 0 ? depth / tool.radius_mm : 0.0);
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
    const bool warm = !options.initial_displacement_mm.empty();
    if (warm) {
        if (options.initial_displacement_mm.size() != 3 * model.mesh.node_count())
            fail("{}: the initial displacement has {} values for {} nodes", what, options.initial_displacement_mm.size(), model.mesh.node_count());
        moving.path = {end}; // the tissue is already where this tool left it
    }
    Loads loads;
    loads.constraints = model.supports();
    loads.indenters.push_back(moving);
    const double travel = depth + back;
    CompressionPrediction out;
    const auto t0 = std::chrono::steady_clock::now();
    // A tool ramped too fast through the skin can fold an element before the tissue around it has
    // caught up (the static equilibrium does not depend on the ramp: frictionless contact and a
    // hyperelastic law). Relaxation then retries with a ramp three times slower (a warm start that
    // folds one restarts from rest first), four tries in all, and says so; a Newton solve or the
    // last try's inversion is the error.
    double speed = options.tool_speed_per_cell;
    bool warm_now = warm;
    for (int attempt = 0;; ++attempt) {
        EquilibriumOptions equilibrium = options.equilibrium;
        loads.indenters = {moving};
        if (!warm_now) loads.indenters.front().path = {contact - back * d, end};
        equilibrium.ramp_iterations = warm_now ? 1
                                               : std::max<long>(equilibrium.ramp_iterations,
                                                                std::lround(std::ceil(1.875 * travel / (speed * model.cell_size_mm.minCoeff()))));
        StaticSolver solver(*model.tled, {options.method, equilibrium, options.newton});
        solver.set_coupling(model.coupling.empty() ? nullptr : &model.coupling);
        solver.set_loads(loads);
        if (warm_now) solver.set_displacement(options.initial_displacement_mm);
        StaticSolveResult summary;
        try {
            summary = solver.solve(1.0);
        } catch (const Error& e) {
            const bool inverted = std::string(e.what()).find("inverted") != std::string::npos;
            if (!inverted || options.method != StaticMethod::relaxation || attempt == 3) fail("{}: {}", what, e.what());
            if (warm_now) {
                warm_now = false; // the warm start folded an element: start from rest
                continue;
            }
            logger()->warn("{}: an element folded under the tool at a ramp of {:.4g} cells per iteration; retrying at {:.4g}", what, speed,
                           speed / 3.0);
            speed /= 3.0;
            ++out.slower_ramps;
            continue;
        }
        if (!summary.converged) fail("{}: {}", what, summary.message);
        out.iterations = summary.iterations;
        out.displacement_mm = solver.displacement_mm();
        break;
    }
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (options.refuse_tool_passage)
        require_no_tool_passage(model.mesh, out.displacement_mm, tool, what);
    else
        out.tool_points_inside = tool_passage(model.mesh, out.displacement_mm, tool).samples_inside;
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
    loads.constraints = m_model.supports();
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
    const auto t0 = std::chrono::steady_clock::now();
    StaticSolveResult s;
    // An extrapolated guess or a fast ramp can fold an element under the tool: start again from
    // the last equilibrium, then with ramps three times slower (twice at most), as
    // predict_compression does.
    double speed = m_options.tool_speed_per_cell;
    for (int attempt = 0;; ++attempt) {
        const long ramp = std::max<long>(1, std::lround(std::ceil(1.875 * travel / (speed * m_model.cell_size_mm.minCoeff()))));
        try {
            s = m_solver.solve(1.0, ramp);
            break;
        } catch (const Error& e) {
            const bool inverted = std::string(e.what()).find("inverted") != std::string::npos;
            if (!inverted || m_options.method != StaticMethod::relaxation || attempt == 3) fail("{}: {}", what, e.what());
            if (attempt > 0 || m_previous.empty()) speed /= 3.0;
            logger()->debug("{}: an element folded; retrying from the last equilibrium at a ramp of {:.4g} cells per iteration", what, speed);
            m_solver.set_displacement(current);
            m_solver.reset_load_factor();
        }
    }
    if (!s.converged) fail("{}: {}", what, s.message);
    m_previous = current;
    m_previous_travel = travel;
    m_position = position;
    return {s.iterations, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()};
}

namespace {

// The boundary of the cells whose label is kept, found on the unsplit grid (a coupled model's split
// interfaces are no boundary of the organ), each face over its own cell's (split) nodes, outward.
LabelledTriangles kept_cells_boundary(const LiverModel& model, const std::set<std::int32_t>& labels)
{
    const auto keep = [&](std::size_t cell) { return labels.empty() || labels.count(model.mesh.cell_labels[cell]) > 0; };
    VolumeMesh unsplit = model.mesh;
    for (auto& node : unsplit.cells) node = model.original_vertex[static_cast<std::size_t>(node)];
    LabelledTriangles out;
    bool any = false;
    for (const auto& face : match_faces(unsplit)) {
        const bool cell_kept = keep(static_cast<std::size_t>(face.cell));
        const bool neighbour_kept = face.neighbour >= 0 && keep(static_cast<std::size_t>(face.neighbour));
        any = any || cell_kept || neighbour_kept;
        if (cell_kept == neighbour_kept) continue;
        // Oriented outward from `cell`; from the neighbour's side it is turned round.
        const auto owner = static_cast<std::size_t>(cell_kept ? face.cell : face.neighbour);
        std::array<std::int32_t, 4> nodes = face.nodes;
        const int count = face.node_count();
        if (!cell_kept) std::reverse(nodes.begin(), nodes.begin() + count);
        const auto own = model.mesh.cell(owner);
        for (int a = 0; a < count; ++a)
            for (const auto n : own)
                if (model.original_vertex[static_cast<std::size_t>(n)] == nodes[static_cast<std::size_t>(a)]) {
                    nodes[static_cast<std::size_t>(a)] = n;
                    break;
                }
        out.triangles.push_back({nodes[0], nodes[1], nodes[2]});
        if (count == 4) out.triangles.push_back({nodes[0], nodes[2], nodes[3]});
    }
    if (!any) fail("compression model surface: no cell of the mesh belongs to the surface's labels");
    out.labels.assign(out.triangles.size(), 0);
    return out;
}

} // namespace

Model to_model(const LiverModel& model, const std::set<std::int32_t>& surface_labels)
{
    Model out;
    out.mesh = model.mesh;
    out.tissues = model.tissues;
    out.law = model.tled ? model.tled->options().law : MaterialLaw::neo_hookean;
    out.supports = model.supports();
    out.surface = kept_cells_boundary(model, surface_labels);
    if (!model.coupling.empty()) out.coupling = std::make_shared<const PenaltyCoupling>(model.coupling);
    return out;
}

LiverModel compression_model(const Model& model, const std::string& what)
{
    model.validate(what);
    if (model.mesh.cell_type != CellType::hexahedron || !model.mesh.grid)
        fail("{}: a tool drives models on a grid of hexahedra (paper 000's TLED model); this one holds {} without a grid", what,
             to_string(model.mesh.cell_type));
    if (!model.structures.empty())
        fail("{}: {} auxiliary structure(s) (membrane, beams): the explicit TLED solver has none; drive this model with a cloud instead", what,
             model.structures.size());
    LiverModel out;
    out.mesh = model.mesh;
    out.tissues = model.tissues;
    out.cell_size_mm = model.mesh.grid->cell_size;
    out.fingerprint = mesh_fingerprint(model.mesh);
    out.original_vertex.resize(model.mesh.node_count());
    std::iota(out.original_vertex.begin(), out.original_vertex.end(), 0);
    out.fixed_nodes = model.held_nodes();
    for (const auto& s : model.partial_supports()) {
        if (s.dofs != std::array<bool, 3>{false, true, false})
            fail("{}: support '{}' holds directions ({}, {}, {}); the compression mode takes whole nodes or a table's y", what, s.name, s.dofs[0], s.dofs[1],
                 s.dofs[2]);
        out.table_nodes.insert(out.table_nodes.end(), s.nodes.begin(), s.nodes.end());
    }
    std::sort(out.table_nodes.begin(), out.table_nodes.end());
    out.table_nodes.erase(std::unique(out.table_nodes.begin(), out.table_nodes.end()), out.table_nodes.end());
    out.parameters.region = out.table_nodes.empty() ? ModelRegion::liver : ModelRegion::body;
    out.parameters.variant = model.coupling ? ModelVariant::coupled : ModelVariant::shared_nodes;
    out.parameters.grid = model.mesh.grid->dims;
    if (model.coupling) {
        out.coupling = *model.coupling;
        out.parameters.coupling = model.coupling->stiffness();
    }
    TledOptions tled;
    tled.law = model.law;
    out.tled = std::make_unique<TledModel>(out.mesh, out.tissues, tled);
    return out;
}

} // namespace physreg
