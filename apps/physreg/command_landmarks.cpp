// SPDX-License-Identifier: GPL-3.0-or-later
// physreg landmarks locate: where each landmark sits in a mesh, and a nodal field interpolated there.
#include "cli_support.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/mesh/point_location.hpp"

#include <fstream>
#include <iostream>

namespace physreg::cli {

void add_subcommand_landmarks(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string mesh, landmarks, output, field;
    };
    auto o = std::make_shared<Options>();
    auto* group = app.add_subcommand("landmarks", "Landmark tools");
    group->require_subcommand(1);
    auto* sub = group->add_subcommand("locate", "Locate landmarks in a mesh (cell + natural coordinates) and "
                                                "interpolate a nodal field there");
    sub->add_option("mesh", o->mesh, "Volume mesh (.vtu or .msh)")->required();
    sub->add_option("landmarks", o->landmarks, "Landmarks (.csv, .fcsv, .mrk.json)")->required();
    sub->add_option("-o,--output", o->output, "CSV with name, cell, natural coordinates and interpolated values");
    sub->add_option("--field", o->field, "Point-data array of the mesh to interpolate (e.g. displacement)");
    sub->add_flag("--json", o->json, "Print a JSON summary on stdout");
    sub->callback([o] {
        if (!o->output.empty()) check_output_path(o->output, "--output");
        MeshData data;
        const VolumeMesh mesh = read_volume_mesh(o->mesh, &data);
        const LandmarkSet landmarks = read_landmarks(o->landmarks);
        if (landmarks.empty()) fail("landmarks '{}': holds no landmark", o->landmarks);
        const DataArray* field = nullptr;
        if (!o->field.empty()) {
            field = data.find_point(o->field);
            if (!field) fail("--field: mesh '{}' has no point-data array '{}'", o->mesh, o->field);
        }
        const PointLocator locator(mesh);
        std::vector<NodeEmbedding> where;
        for (const auto& l : landmarks) where.push_back(locator.locate_or_throw(l.position, "landmark '" + l.name + "'"));
        nlohmann::json rows = nlohmann::json::array();
        for (std::size_t i = 0; i < landmarks.size(); ++i) {
            nlohmann::json row = {{"name", landmarks[i].name}, {"cell", where[i].cell},
                                  {"natural", {where[i].natural[0], where[i].natural[1], where[i].natural[2]}}};
            if (field) row["value"] = interpolate_nodal(mesh, where[i], field->values, field->components);
            rows.push_back(row);
        }
        if (!o->output.empty())
            write_atomically(o->output, [&](const std::filesystem::path& tmp) {
                std::ofstream out(tmp);
                out.precision(17);
                out << "name,cell,xi,eta,zeta";
                if (field)
                    for (int c = 0; c < field->components; ++c) out << ',' << field->name << '_' << c;
                out << "\n";
                for (const auto& row : rows) {
                    out << row["name"].get<std::string>() << ',' << row["cell"].get<int>();
                    for (double x : row["natural"]) out << ',' << x;
                    if (field)
                        for (double x : row["value"]) out << ',' << x;
                    out << "\n";
                }
                out.close();
                if (!out) fail("--output '{}': write failed", o->output);
            });
        if (o->json) std::cout << nlohmann::json{{"landmarks", rows}}.dump(2) << std::endl;
    });
}

} // namespace physreg::cli
