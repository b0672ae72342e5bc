// SPDX-License-Identifier: GPL-3.0-or-later
// physreg info: what a file holds (image geometry and labels, mesh counts and quality, surfaces,
// landmarks, tissue tables).
#include "cli_support.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mesh/components.hpp"
#include "physreg/mesh/label_grid.hpp"

#include <iostream>

namespace physreg::cli {
namespace {

nlohmann::json image_info(const std::string& path)
{
    const ImageFileInfo info = read_image_info(path);
    nlohmann::json out = {{"kind", "image"},
                          {"format", info.format},
                          {"components", info.components},
                          {"component_type", info.component_type},
                          {"geometry", to_json(info.geometry)},
                          {"extent_mm", {info.geometry.size[0] * info.geometry.spacing[0],
                                         info.geometry.size[1] * info.geometry.spacing[1],
                                         info.geometry.size[2] * info.geometry.spacing[2]}}};
    const bool integral = info.component_type.find("float") == std::string::npos &&
                          info.component_type.find("double") == std::string::npos;
    if (info.components == 1 && integral) {
        const LabelVolume volume = read_label_volume(path);
        nlohmann::json labels = nlohmann::json::array();
        for (const auto& [label, count] : count_labels(volume))
            labels.push_back({{"label", label}, {"voxels", count}, {"volume_mm3", count * volume.geometry.voxel_volume_mm3()}});
        out["labels"] = labels;
    } else if (info.components == 1) {
        const ScalarImage image = read_scalar_image(path);
        float lo = std::numeric_limits<float>::infinity(), hi = -lo;
        std::size_t non_finite = 0;
        for (float v : image.values) {
            if (!std::isfinite(v)) {
                ++non_finite;
                continue;
            }
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        }
        out["intensity"] = {{"min", lo}, {"max", hi}, {"non_finite_voxels", non_finite}};
    } else if (info.components == 3) {
        const DisplacementField field = read_displacement_field(path);
        double max_norm = 0.0;
        for (std::size_t v = 0; v < field.components.size() / 3; ++v)
            max_norm = std::max(max_norm, Vec3(field.components[3 * v], field.components[3 * v + 1], field.components[3 * v + 2]).norm());
        out["kind"] = "displacement_field";
        out["max_displacement_mm"] = max_norm;
    }
    return out;
}

nlohmann::json mesh_info(const std::string& path)
{
    MeshData data;
    const VolumeMesh mesh = read_volume_mesh(path, &data);
    nlohmann::json out = mesh_summary(mesh);
    out["kind"] = "volume_mesh";
    out["face_connected_pieces"] = face_connected_pieces(mesh).pieces.size();
    nlohmann::json arrays = nlohmann::json::array();
    for (const auto& a : data.point_data) arrays.push_back({{"name", a.name}, {"association", "point"}, {"components", a.components}});
    for (const auto& a : data.cell_data) arrays.push_back({{"name", a.name}, {"association", "cell"}, {"components", a.components}});
    out["arrays"] = arrays;
    return out;
}

void print_human(const nlohmann::json& j, int indent = 0)
{
    for (const auto& [key, value] : j.items()) {
        std::cout << std::string(indent, ' ') << key << ":";
        if (value.is_object()) {
            std::cout << "\n";
            print_human(value, indent + 2);
        } else if (value.is_array() && !value.empty() && value.front().is_object()) {
            std::cout << "\n";
            for (const auto& item : value) std::cout << std::string(indent + 2, ' ') << "- " << item.dump() << "\n";
        } else {
            std::cout << " " << value.dump() << "\n";
        }
    }
}

} // namespace

void add_subcommand_info(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string file;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("info", "Describe a file: image, mesh, surface, landmarks or tissue table");
    sub->add_option("file", o->file, "Any file physreg reads (or a DICOM directory)")->required();
    sub->add_flag("--json", o->json, "Print JSON instead of text");
    sub->callback([o] {
        const std::string ext = full_extension(o->file);
        nlohmann::json out;
        if (ext == ".vtu" || ext == ".msh") {
            out = mesh_info(o->file);
        } else if (ext == ".stl" || ext == ".ply" || ext == ".obj") {
            const SurfaceMesh s = read_surface(o->file);
            out = {{"kind", "surface"}, {"vertices", s.vertices.size()}, {"triangles", s.triangles.size()}, {"labelled", !s.labels.empty()}};
        } else if (ext == ".csv" || ext == ".fcsv" || ext == ".mrk.json") {
            nlohmann::json points = nlohmann::json::array();
            for (const auto& l : read_landmarks(o->file))
                points.push_back({{"name", l.name}, {"type", to_string(l.type)}, {"position_mm_lps", {l.position[0], l.position[1], l.position[2]}}});
            out = {{"kind", "landmarks"}, {"count", points.size()}, {"landmarks", points}};
        } else if (ext == ".yaml" || ext == ".yml" || ext == ".json") {
            const TissueTable t = read_tissue_table(o->file);
            nlohmann::json tissues = nlohmann::json::array();
            for (const auto& x : t.tissues)
                tissues.push_back({{"label", x.label}, {"name", x.name}, {"young_modulus_pa", x.young_modulus_pa},
                                   {"poisson_ratio", x.poisson_ratio}, {"density_kg_m3", x.density_kg_m3}});
            out = {{"kind", "tissue_table"}, {"tissues", tissues}};
        } else {
            out = image_info(o->file);
        }
        out["file"] = o->file;
        if (o->json) std::cout << out.dump(2) << std::endl;
        else print_human(out);
    });
}

} // namespace physreg::cli
