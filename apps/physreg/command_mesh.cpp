// SPDX-License-Identifier: GPL-3.0-or-later
// physreg mesh: label volume → uniform hexahedral mesh (paper 000), plus optional surfaces and
// tetrahedra.
#include "cli_support.hpp"
#include "progress.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/surface_extraction.hpp"
#include "physreg/mesh/tet_split.hpp"

namespace physreg::cli {

void add_subcommand_mesh(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string labels, tissues, grid, output, surface, tetrahedra, components = "all";
        bool refuse_nonmanifold = false;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("mesh", "Build a uniform hexahedral mesh from a label volume");
    sub->add_option("labels", o->labels, "Label volume (.nii/.nii.gz/.nrrd/.mha/.mhd or a DICOM directory)")->required();
    sub->add_option("--tissues", o->tissues, "Label → tissue table (YAML/JSON); default: paper 000's 1/2/3");
    sub->add_option("--grid", o->grid, "Cells per axis over the tissues' bounding box, e.g. 74x18x54 "
                                       "(majority rule); default: one hexahedron per voxel");
    sub->add_option("-o,--output", o->output, "Output mesh (.vtu or .msh)")->required();
    sub->add_option("--surface", o->surface, "Also write boundary + tissue interfaces (.ply/.stl/.obj)");
    sub->add_option("--tetrahedra", o->tetrahedra, "Also write the conforming 6-tetrahedra split (.vtu/.msh)");
    sub->add_option("--components", o->components,
                    "Disconnected pieces: all (keep, warn), largest (keep the largest), refuse (error)")
        ->check(CLI::IsMember({"all", "largest", "refuse"}));
    sub->add_flag("--refuse-nonmanifold", o->refuse_nonmanifold,
                  "Refuse pieces joined only along an edge or at a vertex instead of splitting their nodes");
    sub->add_flag("--json", o->json, "Print a JSON summary on stdout");
    sub->callback([o] {
        check_output_path(o->output, "--output");
        if (!is_volume_mesh_file(o->output)) fail("--output '{}': use a .vtu or .msh file", o->output);
        if (!o->surface.empty()) check_output_path(o->surface, "--surface");
        if (!o->tetrahedra.empty()) check_output_path(o->tetrahedra, "--tetrahedra");
        check_distinct_paths({{"--output", o->output}, {"--surface", o->surface}, {"--tetrahedra", o->tetrahedra}},
                             {{"LABELS", o->labels}, {"--tissues", o->tissues}});
        MeshingOptions options;
        if (!o->grid.empty()) options.grid_dims = parse_grid_dims(o->grid, "--grid");
        options.components = parse_component_policy(o->components);
        options.split_nonmanifold = !o->refuse_nonmanifold;
        const TissueTable tissues = load_tissues(o->tissues);
        ProgressDisplay bar("mesh");
        bar.update(0.0, "reading the label volume");
        const LabelVolume volume = read_label_volume(o->labels);
        bar.update(0.15, "hexahedra");
        const auto result = mesh_label_volume(volume, tissues, options, "label volume '" + o->labels + "'");
        // Compute everything before writing anything, so that a failure leaves no outputs.
        SurfaceMesh surface;
        bar.update(0.5, "surfaces");
        if (!o->surface.empty()) surface = extract_surfaces(result.mesh);
        VolumeMesh tets;
        bar.update(0.6, "tetrahedra");
        if (!o->tetrahedra.empty()) tets = split_hexahedra_into_tetrahedra(result.mesh);
        bar.update(0.7, "writing");
        OutputFiles outputs; // all three or none
        outputs.write(o->output, [&](const auto& path) { write_volume_mesh(path, result.mesh); });
        if (!o->surface.empty()) outputs.write(o->surface, [&](const auto& path) { write_surface(path, surface); });
        if (!o->tetrahedra.empty()) outputs.write(o->tetrahedra, [&](const auto& path) { write_volume_mesh(path, tets); });
        bar.update(1.0, "done");
        outputs.commit();
        bar.finish();
        nlohmann::json summary = mesh_summary(result.mesh, &tissues);
        summary["input"] = {{"file", o->labels}, {"geometry", to_json(volume.geometry)}};
        nlohmann::json voxels = nlohmann::json::object();
        for (const auto& [label, count] : result.report.voxels_per_label) voxels[std::to_string(label)] = count;
        summary["input"]["voxels_per_label"] = voxels;
        summary["components"] = to_json(result.report.components);
        summary["output"] = o->output;
        logger()->info("meshed '{}': {} nodes, {} hexahedra on a {}x{}x{} grid of {:.3f}x{:.3f}x{:.3f} mm → '{}'",
                       o->labels, result.mesh.node_count(), result.mesh.cell_count(), result.report.grid.dims[0],
                       result.report.grid.dims[1], result.report.grid.dims[2], result.report.grid.cell_size[0],
                       result.report.grid.cell_size[1], result.report.grid.cell_size[2], o->output);
        report(*o, summary);
    });
}

} // namespace physreg::cli
