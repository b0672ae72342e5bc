// SPDX-License-Identifier: GPL-3.0-or-later
#include "state_writing.hpp"

#include <cerrno>
#include <cstring>
#include <omp.h>

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/version.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/field/image_warping.hpp"
#include "physreg/figures/slice_figure.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/png.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mechanics/simulation/calculix.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/phantom/landmark_picking.hpp"
#include "physreg/phantom/partial_surface.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <string_view>
#include <chrono>
#include <exception>
#include <cmath>
#include <fstream>
#include <numeric>

namespace physreg::detail {
namespace fs = std::filesystem;
using nlohmann::json;

json to_json(const Vec3& v) { return json::array({v.x(), v.y(), v.z()}); }

std::string shape_name(IndenterShape s)
{
    switch (s) {
    case IndenterShape::sphere: return "sphere";
    case IndenterShape::cylinder: return "cylinder";
    case IndenterShape::plane: return "plane";
    case IndenterShape::box: return "box";
    }
    return "?";
}

LandmarkSet move_landmarks(const LandmarkSet& rest, const std::vector<NodeEmbedding>& where, const VolumeMesh& mesh,
                           const std::vector<double>& u)
{
    LandmarkSet out = rest;
    for (std::size_t l = 0; l < rest.size(); ++l) {
        const auto d = interpolate_nodal(mesh, where[l], u, 3);
        out[l].position += Vec3(d[0], d[1], d[2]);
    }
    return out;
}

LandmarkSet with_noise(const LandmarkSet& set, double sigma, std::uint64_t seed)
{
    SeededRandom random(seed);
    LandmarkSet out = set;
    for (auto& l : out) l.position += sigma * Vec3(random.normal(), random.normal(), random.normal());
    return out;
}

// Paints the tool and its shaft (the tool swept back along the pressing direction) as air.
void paint_tool(LabelVolume& labels, ScalarImage& intensity, const Indenter& tool, const Vec3& direction,
                const std::function<bool(std::int32_t)>& deforming)
{
    const auto& g = labels.geometry;
    const Vec3 tip = tool.position(1.0);
    const double reach = tool.shape == IndenterShape::box ? tool.half_extents_mm.norm() : tool.radius_mm;
    const double step = 0.5 * g.spacing.minCoeff();
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const Vec3 x = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                const Vec3 r = x - tip;
                const double along = r.dot(direction);
                if (along > reach) continue;                       // beyond the tool's tip
                if (tool.shape != IndenterShape::cylinder && (r - along * direction).norm() > reach) continue;
                const auto v = static_cast<std::size_t>(g.linear_index(i, j, k));
                if (deforming(labels.labels[v]) || labels.labels[v] == 0) continue;
                // Inside the tool moved back by some travel t ≥ 0?
                bool inside = false;
                Vec3 surface, normal;
                for (double t = 0; t <= std::max(0.0, reach - along) + 2 * reach && !inside; t += step)
                    inside = tool.push_out(x + t * direction, 1.0, surface, normal);
                if (!inside) continue;
                labels.labels[v] = 0;
                intensity.values[v] = 0.f;
            }
}


void write_text(const fs::path& path, const std::string& text)
{
    write_atomically(path, [&](const fs::path& tmp) {
        std::ofstream out(tmp);
        out << text;
        if (!out) fail("cannot write '{}': {}", path.string(), std::strerror(errno));
    });
}

StateWriter::StateWriter(const fs::path& root, const PhantomSpec& spec, const Prepared& p, const ScalarImage& intensity, const LandmarkSet& rest_landmarks,
                         const Vec3& liver_centre)
    : m_root(root), m_spec(spec), m_p(p), m_intensity(intensity), m_rest_landmarks(rest_landmarks), m_liver_centre(liver_centre)
{
    m_fill_intensity = [&] {
        double sum = 0;
        std::int64_t n = 0;
        for (std::size_t v = 0; v < p.labels.labels.size(); ++v)
            if (p.roles.body.count(p.labels.labels[v])) sum += intensity.values[v], ++n;
        return n ? sum / static_cast<double>(n) : 0.0;
    }();
    m_air_intensity = [&] {
        double sum = 0;
        std::int64_t n = 0;
        for (std::size_t v = 0; v < p.labels.labels.size(); ++v)
            if (p.labels.labels[v] == 0) sum += intensity.values[v], ++n;
        return n ? sum / static_cast<double>(n) : 0.0;
    }();
    m_body_label = p.roles.body.empty() ? 0 : static_cast<std::uint16_t>(*p.roles.body.begin());
    m_extension_mm = 1.5 * spec.ground_truth_mesh.facet_mm;
}

json StateWriter::write(const std::string& name, const std::string& kind, const SolvedState* solved, const ModelView& view, double f0,
                        const std::function<void(double, const std::string&)>& report) const
{
    // The names the dataset generator used when this was a lambda of it.
    const fs::path& root = m_root;
    const PhantomSpec& spec = m_spec;
    const Prepared& p = m_p;
    const ScalarImage& intensity = m_intensity;
    const LandmarkSet& rest_landmarks = m_rest_landmarks;
    const Vec3& liver_centre = m_liver_centre;
    const auto& g = p.labels.geometry;
    const double fill_intensity = m_fill_intensity, air_intensity = m_air_intensity, extension_mm = m_extension_mm;
    const std::uint16_t body_label = m_body_label;
    const VolumeMesh& mesh = view.model->mesh;
    const auto deforming = [&](std::int32_t l) { return view.model->labels.count(l) > 0; };
    // Voxels a deforming tissue leaves: gel when the gel stays, air when the gel moves too.
    const bool gel_moves = deforming(body_label);
    const std::uint16_t fill_label = gel_moves ? 0 : body_label;
    const std::string dir = name == "rest" ? "rest" : "states/" + name;
    fs::create_directories(root / dir);
    json s;
    s["name"] = name;
    s["kind"] = kind;
    json files;
    const std::vector<double> zero(3 * mesh.node_count(), 0.0);
    const std::vector<double>& u = solved ? solved->u : zero;
    LabelVolume labels = p.labels;
    ScalarImage image = intensity;
    if (solved) {
        report(f0, name + ": images");
        const InverseMap map = rasterize_inverse_map(mesh, u, g, extension_mm);
        labels = warp_labels(p.labels, map, deforming, fill_label);
        image = warp_intensity(intensity, p.labels, labels, map, deforming, static_cast<float>(gel_moves ? air_intensity : fill_intensity));
        if (solved->tool) paint_tool(labels, image, *solved->tool, solved->compression.direction.normalized(), deforming);
        files["inverse_displacement"] = write_file(root, dir + "/inverse_displacement.nii.gz",
                                                   [&](const fs::path& f) { write_displacement_field(f, map.field); });
        const SampledField forward = sample_displacement_field(mesh, u, g);
        files["displacement"] = write_file(root, dir + "/displacement.nii.gz",
                                           [&](const fs::path& f) { write_displacement_field(f, forward.field); });
    }
    files["labels"] = write_file(root, dir + "/labels.nii.gz", [&](const fs::path& f) { write_label_volume(f, labels); });
    add_mr_noise(image, mix_seed(spec.seed, "intensity/" + name));
    files["intensity"] = write_file(root, dir + "/intensity.nii.gz", [&](const fs::path& f) { write_scalar_image(f, image); });
    MeshData data;
    data.point_data.push_back({"displacement", 3, u});
    files["mesh"] = write_file(root, dir + "/mesh.vtu", [&](const fs::path& f) { write_vtu(f, mesh, data); });
    const LandmarkSet landmarks = solved ? move_landmarks(rest_landmarks, view.landmark_cells, mesh, u) : rest_landmarks;
    files["landmarks"] = write_file(root, dir + "/landmarks.csv", [&](const fs::path& f) { write_landmarks(f, landmarks); });
    files["landmarks_noisy"] = write_file(root, dir + "/landmarks_noisy.csv", [&](const fs::path& f) {
        write_landmarks(f, with_noise(landmarks, spec.landmark_noise_mm, mix_seed(spec.seed, "landmarks/" + name)));
    });
    files["liver_surface"] = write_file(root, dir + "/liver_surface.ply", [&](const fs::path& f) { write_boundary_ply(f, mesh, u, view.liver_surface); });
    if (name == "rest" && spec.preset != "from-labels")
        files["vessel_centrelines"] = write_file(root, dir + "/vessel_centrelines.csv", [&](const fs::path& f) {
            write_vessel_centrelines(f, cirs057a_vessel_centrelines());
        });
    json surfaces = json::object();
    if (solved && kind == "push") {
        // Sparse, unlabelled, over nearly the whole surface: all but the back and what the tool covers.
        const Indenter& tool = *solved->tool;
        double covered = 0.0;
        const auto cloud = sparse_surface_cloud(mesh, u, view.liver_surface, spec.push_cloud_coverage, spec.push_cloud_points,
                                                [&](const Vec3& x) { Vec3 s, n; return tool.push_out(x, 1.0, s, n); }, spec.surface_noise_mm,
                                                mix_seed(spec.seed, "surface/" + name), &covered);
        const int percent = static_cast<int>(std::lround(100 * covered));
        const std::string stem = fmt::format("{}/sparse_cloud_{:03d}", dir, percent);
        surfaces[std::to_string(percent)] = {
            {"ply", write_file(root, stem + ".ply", [&](const fs::path& f) { write_point_cloud_ply(f, cloud); })},
            {"csv", write_file(root, stem + ".csv", [&](const fs::path& f) { write_point_cloud_csv(f, cloud); })},
            {"points", cloud.points.size()},
            {"kind", "sparse unlabelled cloud over the surface but its back and the tool's footprint"}};
    } else if (solved) {
        for (const int percent : spec.surface_percentages) {
            const auto cloud = visible_surface_patch(mesh, u, view.liver_surface, percent / 100.0, Vec3::UnitY(), spec.surface_noise_mm,
                                                     mix_seed(spec.seed, fmt::format("surface/{}/{}", name, percent)));
            const std::string stem = fmt::format("{}/partial_surface_{:03d}", dir, percent);
            surfaces[std::to_string(percent)] = {
                {"ply", write_file(root, stem + ".ply", [&](const fs::path& f) { write_point_cloud_ply(f, cloud); })},
                {"csv", write_file(root, stem + ".csv", [&](const fs::path& f) { write_point_cloud_csv(f, cloud); })},
                {"points", cloud.points.size()}};
        }
    }
    s["partial_surfaces"] = surfaces;
    // Picture: through the tool's final position for compressions, the liver's centre otherwise.
    SliceFigureOptions figure;
    figure.centre = liver_centre;
    std::string title = "PHYSREG PHANTOM " + name;
    if (solved && solved->tool) {
        const Vec3 tip = solved->tool->position(1.0);
        figure.centre = Vec3(tip.x(), liver_centre.y(), tip.z());
        title += fmt::format(": {} R {:.1f} MM, DEPTH {:.1f} MM", shape_name(solved->tool->shape), solved->tool->radius_mm, solved->compression.depth_mm);
    } else if (solved) {
        title += fmt::format(": PRESSURE {:.0f} PA", solved->pressure_pa);
    }
    if (solved) title += fmt::format(", MAX DISPL. {:.1f} MM", solved->solve.max_displacement_mm);
    figure.title = title;
    figure.pixels_per_mm = std::clamp(600.0 / (g.spacing.x() * g.size[0]), 0.5, 4.0);
    const Canvas canvas = render_orthogonal_slices(image, labels, p.roles, landmarks, {}, figure);
    files["picture"] = write_file(root, dir + "/slices.png", [&](const fs::path& f) { write_png(f, canvas.image()); });
    s["files"] = files;
    if (solved) {
        s["max_displacement_mm"] = solved->solve.max_displacement_mm;
        s["ground_truth_model"] = view.model->name;
        s["load_steps"] = solved->solve.load_steps;
        s["newton_iterations"] = solved->solve.newton_iterations;
        s["contact_updates"] = solved->solve.contact_updates;
        s["worst_residual_ratio"] = solved->solve.worst_residual_ratio;
        s["max_node_penetration_mm"] = solved->solve.max_penetration_mm;
        if (solved->tool) {
            const auto& c = solved->compression;
            s["tool"] = {{"shape", shape_name(solved->tool->shape)}, {"radius_mm", solved->tool->radius_mm},
                         {"axis", to_json(solved->tool->axis)}, {"half_extents_mm", to_json(solved->tool->half_extents_mm)},
                         {"entry_x_mm", c.x_mm}, {"entry_z_mm", c.z_mm}, {"direction", to_json(c.direction.normalized())},
                         {"contact_position_mm", to_json(solved->tool->path.front())},
                         {"final_position_mm", to_json(solved->tool->path.back())}};
            s["depth_mm"] = c.depth_mm;
            if (!solved->adaptation.empty())
                s["tool_adapted"] = {{"scale", solved->requested_tool_scale}, {"requested_radius_mm", solved->tool->radius_mm / solved->requested_tool_scale},
                                     {"reason", solved->adaptation}};
        } else {
            s["pressure_pa"] = solved->pressure_pa;
            s["pressure_faces"] = "organ surface faces facing anterior (outward normal y < -0.2), dead load";
        }
    }
    return s;
}

} // namespace physreg::detail
