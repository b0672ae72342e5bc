// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/prepared_model.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/version.hpp"
#include "physreg/io/dataset.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/labelled_boundary.hpp"
#include "physreg/mesh/tetrahedral_meshing.hpp"

#include <chrono>
#include <fstream>
#include <map>
#include <set>

namespace physreg {
namespace {

constexpr const char* format_name = "physreg-prepared-model";
constexpr int format_version = 1;

double seconds_since(std::chrono::steady_clock::time_point t)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

std::set<std::int32_t> liver_labels(const LabelRoles& roles)
{
    std::set<std::int32_t> liver(roles.liver.begin(), roles.liver.end());
    liver.insert(roles.lesion.begin(), roles.lesion.end());
    liver.insert(roles.vessel.begin(), roles.vessel.end());
    return liver;
}

const char* shape_name(IndenterShape s)
{
    switch (s) {
    case IndenterShape::sphere: return "sphere";
    case IndenterShape::cylinder: return "cylinder";
    case IndenterShape::plane: return "plane";
    case IndenterShape::box: return "box";
    }
    return "sphere";
}

nlohmann::json vec_json(const Vec3& v) { return {v[0], v[1], v[2]}; }
Vec3 json_vec(const nlohmann::json& j) { return Vec3(j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()); }

nlohmann::json tool_json(const Indenter& t)
{
    nlohmann::json path = nlohmann::json::array();
    for (const auto& p : t.path) path.push_back(vec_json(p));
    nlohmann::json rotation = nlohmann::json::array();
    for (int r = 0; r < 3; ++r) rotation.push_back({t.rotation(r, 0), t.rotation(r, 1), t.rotation(r, 2)});
    return {{"name", t.name}, {"shape", shape_name(t.shape)}, {"radius_mm", t.radius_mm}, {"axis", vec_json(t.axis)},
            {"half_extents_mm", vec_json(t.half_extents_mm)}, {"rotation", rotation}, {"path_mm", path}};
}

Indenter json_tool(const nlohmann::json& j)
{
    Indenter t;
    t.name = j.at("name").get<std::string>();
    t.shape = parse_indenter_shape(j.at("shape").get<std::string>());
    t.radius_mm = j.at("radius_mm").get<double>();
    t.axis = json_vec(j.at("axis"));
    t.half_extents_mm = json_vec(j.at("half_extents_mm"));
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) t.rotation(r, c) = j.at("rotation").at(r).at(c).get<double>();
    for (const auto& p : j.at("path_mm")) t.path.push_back(json_vec(p));
    t.validate();
    return t;
}

nlohmann::json roles_json(const LabelRoles& r)
{
    return {{"body", r.body}, {"liver", r.liver}, {"lesion", r.lesion}, {"vessel", r.vessel}, {"bone", r.bone}, {"kidney", r.kidney}};
}

LabelRoles json_roles(const nlohmann::json& j)
{
    LabelRoles r;
    r.body = j.at("body").get<std::set<std::int32_t>>();
    r.liver = j.at("liver").get<std::set<std::int32_t>>();
    r.lesion = j.at("lesion").get<std::set<std::int32_t>>();
    r.vessel = j.at("vessel").get<std::set<std::int32_t>>();
    r.bone = j.at("bone").get<std::set<std::int32_t>>();
    r.kidney = j.at("kidney").get<std::set<std::int32_t>>();
    return r;
}

/// The query nodes: every organ surface's, and those the targets' interpolation reads.
std::vector<std::int32_t> query_nodes(const LiverModel& model, const std::vector<OrganSurface>& surfaces, const LandmarkSet& targets)
{
    std::set<std::int32_t> wanted;
    for (const auto& s : surfaces) wanted.insert(s.nodes.begin(), s.nodes.end());
    std::vector<Vec3> points;
    for (const auto& l : targets) points.push_back(l.position);
    for (const auto n : nodes_near(model.mesh, points, 2.0 * model.cell_size_mm.maxCoeff())) wanted.insert(n);
    return {wanted.begin(), wanted.end()};
}

} // namespace

std::vector<OrganSurface> organ_surfaces(const LiverModel& model, const LabelRoles& roles)
{
    std::vector<std::pair<std::string, std::set<std::int32_t>>> organs;
    organs.push_back({"liver", liver_labels(roles)});
    if (!roles.lesion.empty()) organs.push_back({"tumours", roles.lesion});
    if (!roles.vessel.empty()) organs.push_back({"vessels", roles.vessel});
    const auto faces = match_faces(model.mesh);
    std::vector<OrganSurface> out;
    for (const auto& [name, labels] : organs) {
        OrganSurface s{name, {}, {}};
        std::map<std::int32_t, std::uint32_t> index;
        for (const auto& f : faces) {
            const bool inside = labels.count(model.mesh.cell_labels[f.cell]) > 0;
            const bool other = f.neighbour < 0 || labels.count(model.mesh.cell_labels[f.neighbour]) == 0;
            if (!inside || !other) continue;
            std::vector<std::uint32_t> polygon;
            for (int k = 0; k < f.node_count(); ++k) {
                const auto [it, added] = index.emplace(f.nodes[k], static_cast<std::uint32_t>(s.nodes.size()));
                if (added) s.nodes.push_back(f.nodes[k]);
                polygon.push_back(it->second);
            }
            s.polygons.push_back(std::move(polygon));
        }
        if (!s.polygons.empty()) out.push_back(std::move(s));
    }
    return out;
}

std::unique_ptr<PreparedBodyModel> prepare_body_model(CompressionSubject subject, std::vector<Indenter> session_tools,
                                                      const PreparedModelOptions& options)
{
    if (session_tools.empty()) fail("prepare: no tool path (the condensed contact's candidates lie near the session's tool paths)");
    if (!(options.surface_cell_size_mm >= 0)) fail("prepare: the liver model's cell size must be ≥ 0 mm (got {})", options.surface_cell_size_mm);
    auto out = std::make_unique<PreparedBodyModel>();
    out->subject = std::move(subject);
    out->session_tools = std::move(session_tools);
    const LiverModel& model = out->subject.model;
    out->surfaces = organ_surfaces(model, out->subject.roles);
    auto t0 = std::chrono::steady_clock::now();
    out->condensed = std::make_unique<CondensedContactModel>(model, out->session_tools, query_nodes(model, out->surfaces, out->subject.rest_landmarks),
                                                             options.condensed);
    out->description["timings_s"]["condensed_contact"] = seconds_since(t0);
    if (options.surface_cell_size_mm > 0) {
        t0 = std::chrono::steady_clock::now();
        // No notch region: clouds on the wire are unlabelled, and every triangle is "surface" to them.
        out->surface_model = surface_model_from_labels(out->subject.labels, liver_labels(out->subject.roles), options.surface_cell_size_mm, std::nullopt,
                                                       options.surface_seed, "prepare: the liver model for clouds");
        out->description["timings_s"]["surface_model"] = seconds_since(t0);
    }
    out->description["surface_cell_size_mm"] = options.surface_cell_size_mm;
    out->description["surface_seed"] = options.surface_seed;
    return out;
}

std::vector<Indenter> dataset_session_tools(const std::filesystem::path& directory)
{
    std::vector<Indenter> tools;
    for (const auto& st : read_phantom_dataset(directory).states)
        if (st.tool && st.kind == "compression") tools.push_back(*st.tool);
    if (tools.empty()) fail("dataset '{}' has no tool compression (the tool's shape and the session's paths)", directory.string());
    return tools;
}

bool is_prepared_model(const std::filesystem::path& directory)
{
    return std::filesystem::is_regular_file(directory / "prepared.json");
}

void write_prepared_model(const PreparedBodyModel& m, const std::filesystem::path& directory, bool replace)
{
    StagedDirectory staged(directory, replace);
    const auto& dir = staged.path();
    const CompressionSubject& s = m.subject;
    write_label_volume(dir / "labels.nii.gz", s.labels);
    write_landmarks(dir / "landmarks.csv", s.rest_landmarks);
    if (!s.parameters_file.empty()) std::filesystem::copy_file(s.parameters_file, dir / "parameters.json");
    const CondensedCompliance compliance = m.condensed->compliance();
    write_condensed_compliance(dir / "condensed.bin", compliance);
    // The body model for viewing: its tissues (cell data "tissue") and held nodes.
    MeshData data;
    DataArray held{"held", 1, std::vector<double>(s.model.mesh.node_count(), 0.0)};
    for (const auto& c : s.model.supports())
        for (const auto n : c.nodes) held.values[static_cast<std::size_t>(n)] = 1.0;
    data.point_data.push_back(std::move(held));
    write_vtu(dir / "body_model.vtu", s.model.mesh, data);
    if (m.surface_model) write_vtu(dir / "surface_model.vtu", m.surface_model->mesh);

    CompressionRegistrationSettings settings;
    static_cast<CompressionSettings&>(settings) = s.settings;
    nlohmann::json tools = nlohmann::json::array();
    for (const auto& t : m.session_tools) tools.push_back(tool_json(t));
    const auto& pre = compliance.precomputation;
    nlohmann::json manifest{
        {"format", format_name},
        {"format_version", format_version},
        {"physreg_version", VERSION},
        {"description", m.description},
        {"inputs", s.description},
        {"settings", compression_spec().to_json(settings)},
        {"parameters_file", s.parameters_file.empty() ? "" : "parameters.json"},
        {"label_roles", roles_json(s.roles)},
        {"session_tools", tools},
        {"body_model", {{"fingerprint", s.model.fingerprint}, {"nodes", s.model.mesh.node_count()}, {"hexahedra", s.model.mesh.cell_count()}}},
        {"condensed",
         {{"dofs", pre.dofs}, {"candidate_nodes", pre.candidate_nodes}, {"query_nodes", pre.query_nodes}, {"factor_nonzeros", pre.factor_nonzeros},
          {"assembly_s", pre.assembly_s}, {"factorisation_s", pre.factorisation_s}, {"compliance_s", pre.compliance_s},
          {"compliance_bytes", pre.compliance_bytes}}},
        {"surface_model", m.surface_model ? nlohmann::json{{"file", "surface_model.vtu"}, {"nodes", m.surface_model->mesh.node_count()},
                                                           {"tetrahedra", m.surface_model->mesh.cell_count()}}
                                          : nlohmann::json(nullptr)},
        {"stored", "rest labels, targets, settings (and parameter file), label roles, the session's tool paths, the condensed contact's compliance "
                   "blocks (candidates × candidates, query × candidates), the liver's tetrahedra for clouds, the body model (for viewing)"},
        {"recomputed_at_start", "the hexahedral body model from the labels and settings (checked against the fingerprint), its stiffness at rest "
                                "(checked against the stored probe), the liver model's boundary; the Cholesky factor only when first needed "
                                "(the displacement field on request, a tool off the session's paths)"},
        {"units", "mm, N, Pa; LPS"},
    };
    std::ofstream(dir / "prepared.json") << manifest.dump(1) << "\n";
    staged.commit();
}

std::unique_ptr<PreparedBodyModel> read_prepared_model(const std::filesystem::path& directory, const CondensedContactOptions& options)
{
    const auto t0 = std::chrono::steady_clock::now();
    const auto manifest_path = directory / "prepared.json";
    if (!is_prepared_model(directory)) fail("prepared model '{}': no prepared.json (make one with physreg prepare)", directory.string());
    nlohmann::json manifest;
    try {
        manifest = nlohmann::json::parse(std::ifstream(manifest_path));
    } catch (const nlohmann::json::exception& e) {
        fail("prepared model '{}': prepared.json is not valid JSON: {}", directory.string(), e.what());
    }
    auto out = std::make_unique<PreparedBodyModel>();
    try {
        if (manifest.at("format").get<std::string>() != format_name) fail("not a prepared model (format '{}')", manifest.at("format").get<std::string>());
        if (manifest.at("format_version").get<int>() != format_version)
            fail("format version {} (this physreg reads {})", manifest.at("format_version").get<int>(), format_version);
        CompressionRegistrationSettings settings;
        compression_spec().apply(settings, manifest.at("settings"), (directory / "prepared.json").string());
        const LabelRoles roles = json_roles(manifest.at("label_roles"));
        const std::string parameters = manifest.at("parameters_file").get<std::string>();
        out->subject = make_compression_subject(read_label_volume(directory / "labels.nii.gz"), roles, read_landmarks(directory / "landmarks.csv"),
                                                settings, parameters.empty() ? "" : (directory / parameters).string(), "prepared model's rest labels");
        out->subject.description = manifest.at("inputs");
        const std::string fingerprint = manifest.at("body_model").at("fingerprint").get<std::string>();
        if (out->subject.model.fingerprint != fingerprint)
            fail("the body model built again differs from the stored one (fingerprint {} vs {}): prepare it again with this version of physreg",
                 out->subject.model.fingerprint, fingerprint);
        for (const auto& t : manifest.at("session_tools")) out->session_tools.push_back(json_tool(t));
        out->description = manifest.at("description");
    } catch (const nlohmann::json::exception& e) {
        fail("prepared model '{}': prepared.json: {}", directory.string(), e.what());
    } catch (const Error& e) {
        fail("prepared model '{}': {}", directory.string(), e.what());
    }
    out->surfaces = organ_surfaces(out->subject.model, out->subject.roles);
    out->condensed = std::make_unique<CondensedContactModel>(out->subject.model, read_condensed_compliance(directory / "condensed.bin"), options);
    if (!manifest.at("surface_model").is_null()) {
        SurfaceModel s;
        s.mesh = read_vtu(directory / "surface_model.vtu");
        if (s.mesh.cell_type != CellType::tetrahedron) fail("prepared model '{}': surface_model.vtu must hold tetrahedra", directory.string());
        std::fill(s.mesh.cell_labels.begin(), s.mesh.cell_labels.end(), 1);
        s.quality = measure_tetrahedra(s.mesh);
        s.surface = labelled_triangles(s.mesh, std::nullopt);
        out->surface_model = std::move(s);
    }
    out->description["read_s"] = seconds_since(t0);
    return out;
}

} // namespace physreg
