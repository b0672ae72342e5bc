// SPDX-License-Identifier: GPL-3.0-or-later
// physreg phantom: the experiment dataset (built-in CIRS-057A-like phantom or any label map) that
// every registration command reads.
#include "cli_support.hpp"
#include "progress.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/phantom/dataset.hpp"

#include <iostream>
#include <sstream>

namespace physreg::cli {
namespace {

Vec3 parse_vector(const std::string& text, const std::string& option)
{
    const auto v = parse_number_list(text, option);
    if (v.size() != 3) fail("{}: '{}' is not three comma-separated numbers", option, text);
    const Vec3 out(v[0], v[1], v[2]);
    if (!out.allFinite()) fail("{}: '{}' is not finite", option, text);
    return out;
}

} // namespace

void add_subcommand_phantom(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string preset = "cirs057a", from_labels, label_roles, vessel_mask, output, grid, materials = "paper000";
        std::string organ_support = "posterior";
        std::string depths, tool = "sphere", tool_direction = "0,1,0", tool_axis = "1,0,0", tool_half_extents;
        std::vector<std::string> compressions;
        std::optional<double> resolution, tool_radius, insufflation_pa, landmark_noise, surface_noise;
        std::uint64_t seed = 1;
        bool replace = false, no_calculix = false, organs_only = false;
        std::optional<double> load_step;
        double push_depth = 0.0, push_tool_radius = 12.5;
        int push_points = 500;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("phantom", "Make a phantom experiment dataset: images, ground-truth compressions, landmarks, "
                                              "partial surfaces, pictures (see docs/phantom.md)");
    auto* preset = sub->add_option("--preset", o->preset, "Built-in anatomy: cirs057a (default) or small (fast, for tests)");
    sub->add_option("--from-labels", o->from_labels, "Use this label map instead of a preset (NIfTI/NRRD/MHA/DICOM)")->excludes(preset);
    sub->add_option("--label-roles", o->label_roles,
                    "Which labels are which organ, e.g. \"liver=1\" or \"body=1;liver=2;lesion=3;vessel=4;bone=5;kidney=6\" (the default)");
    sub->add_option("--vessel-mask", o->vessel_mask, "Label map on the same grid whose nonzero voxels inside the liver are vessels");
    sub->add_option("--seed", o->seed, "Seed (1 … 4294967295) of the ground-truth materials and mesh, noise, bias field and annotation "
                                       "noise (same seed → identical files)");
    sub->add_option("--resolution", o->resolution, "Preset image voxel size, mm (default 1.25; small: 4)");
    sub->add_option("--ground-truth-size", o->grid, "Ground-truth tetrahedron sizes ORGAN,BODY (largest circumradius, mm; default 3,12; "
                                                    "small: 7,18)");
    sub->add_option("--materials", o->materials, "Literature values the ground-truth moduli are drawn around: paper000 (default), "
                                                 "healthy or cirrhotic (paper 001)");
    sub->add_option("--depths", o->depths, "Tool travel on the skin from first contact of the default compressions A, B, … (one "
                                           "per depth, 1 to 5), mm (default 20,25,20,15,22; small: 12,15,12,10,12); none: no compression "
                                           "(the insufflation and the push only)");
    sub->add_option("--load-step", o->load_step, "Largest tool travel per Newton load step of the ground truth, mm (default 5; small: 4)");
    sub->add_flag("--organs-only", o->organs_only, "Simulate the organs alone, posterior faces fixed, the tool pressing them directly "
                                                   "(no gel: for studies of the liver models' own mechanics)");
    sub->add_option("--organ-support", o->organ_support,
                    "Where the organs alone are held (insufflation, push, --organs-only): surface faces facing posterior (default), anterior, "
                    "superior, inferior, left, right or x,y,z (LPS; outward normal · direction > 0.5)");
    sub->add_flag("--no-calculix", o->no_calculix, "Skip the CalculiX validation of the ground truth (the manifest says so)");
    sub->add_option("--compression", o->compressions, "NAME:X:Z:DEPTH (mm, LPS) instead of the default five; repeatable");
    sub->add_option("--tool", o->tool, "Indenter shape: sphere (default), cylinder (a rod pressed sideways) or box");
    sub->add_option("--tool-radius", o->tool_radius, "Sphere/cylinder radius, mm (default 30; small: 15)");
    sub->add_option("--tool-direction", o->tool_direction, "Pressing direction x,y,z (LPS; default 0,1,0 = posterior)");
    sub->add_option("--tool-axis", o->tool_axis, "Cylinder axis x,y,z (default 1,0,0)");
    sub->add_option("--tool-half-extents", o->tool_half_extents, "Box half extents x,y,z, mm (default 12,6,12)");
    sub->add_option("--insufflation-pa", o->insufflation_pa, "Pressure on the anterior organ surfaces, Pa (default 3 % of the parenchyma's E; 0: none)");
    sub->add_option("--push-depth", o->push_depth, "Add the large local push: a sphere pressed this far (mm, posterior) into the "
                                                   "right lobe of the organs alone, seen as a sparse cloud over 90 % of the surface (default 0: none)");
    sub->add_option("--push-tool-radius", o->push_tool_radius, "--push-depth: the sphere's radius, mm (default 12.5)");
    sub->add_option("--push-points", o->push_points, "--push-depth: points in its sparse cloud (default 500)");
    sub->add_option("--landmark-noise", o->landmark_noise, "Annotation noise σ of landmarks_noisy.csv, mm (default 0.5)");
    sub->add_option("--surface-noise", o->surface_noise, "Noise σ of the partial surfaces, mm (default 0.5)");
    sub->add_option("-o,--output", o->output, "Dataset directory (created; must not exist or be empty unless --force)")->required();
    sub->add_flag("--force", o->replace, "Replace an existing dataset directory (only once the new one is complete)");
    sub->add_flag("--json", o->json, "Print the manifest and run times as JSON on stdout");
    sub->callback([o] {
        PhantomSpec spec;
        if (!o->from_labels.empty()) {
            spec = PhantomSpec::preset_spec("cirs057a");
            spec.preset = "from-labels";
            spec.labels_file = o->from_labels;
        } else {
            spec = PhantomSpec::preset_spec(o->preset);
        }
        if (!o->label_roles.empty()) spec.roles = parse_label_roles(o->label_roles, "--label-roles");
        spec.vessel_mask = o->vessel_mask;
        spec.seed = o->seed;
        if (o->resolution) {
            if (!o->from_labels.empty()) fail("--resolution applies to the presets; a label map keeps its own grid");
            spec.voxel_mm = *o->resolution;
        }
        if (!o->grid.empty()) {
            const auto sizes = parse_number_list(o->grid, "--ground-truth-size");
            if (sizes.size() != 2) fail("--ground-truth-size: '{}' is not ORGAN,BODY (two sizes in mm)", o->grid);
            spec.ground_truth_mesh.organ_cell_mm = sizes[0];
            spec.ground_truth_mesh.kidney_cell_mm = 2.0 * sizes[0];
            spec.ground_truth_mesh.body_cell_mm = sizes[1];
        }
        if (o->load_step) spec.load_step_mm = *o->load_step;
        spec.calculix_validation = !o->no_calculix;
        spec.simulate_body = !o->organs_only;
        spec.organ_support = parse_organ_support(o->organ_support, "--organ-support");
        spec.materials = parse_material_set(o->materials);
        if (o->depths == "none")
            spec.depths_mm.clear(); // the insufflation and the push only (studies of the organs' own states)
        else if (!o->depths.empty())
            spec.depths_mm = parse_number_list(o->depths, "--depths");
        spec.tool.shape = parse_indenter_shape(o->tool);
        if (spec.tool.shape == IndenterShape::plane) fail("--tool: a plane has no position over the liver; use sphere, cylinder or box");
        if (o->tool_radius) spec.tool.radius_mm = *o->tool_radius;
        spec.tool.axis = parse_vector(o->tool_axis, "--tool-axis");
        if (!o->tool_half_extents.empty()) spec.tool.half_extents_mm = parse_vector(o->tool_half_extents, "--tool-half-extents");
        const Vec3 direction = parse_vector(o->tool_direction, "--tool-direction");
        if (direction.norm() == 0.0) fail("--tool-direction: must be a non-zero vector");
        if (direction.normalized().y() <= 0.0) fail("--tool-direction: the tool must press towards posterior (y > 0), got {}", o->tool_direction);
        for (const auto& text : o->compressions) {
            std::stringstream in(text);
            std::string item;
            std::vector<std::string> parts;
            while (std::getline(in, item, ':')) parts.push_back(item);
            if (parts.size() != 4 || parts[0].empty()) fail("--compression: '{}' is not NAME:X:Z:DEPTH", text);
            const auto numbers = parse_number_list(parts[1] + "," + parts[2] + "," + parts[3], "--compression " + parts[0]);
            CompressionSpec c;
            c.name = parts[0];
            c.x_mm = numbers[0];
            c.z_mm = numbers[1];
            c.depth_mm = numbers[2];
            c.tool = spec.tool;
            c.direction = direction;
            spec.compressions.push_back(c);
        }
        if (o->compressions.empty() && direction.normalized() != Vec3::UnitY())
            logger()->info("--tool-direction applies to --compression entries; the default five press along +y");
        spec.insufflation_pa = o->insufflation_pa;
        spec.push_depth_mm = o->push_depth;
        spec.push_tool_radius_mm = o->push_tool_radius;
        spec.push_cloud_points = o->push_points;
        if (o->landmark_noise) spec.landmark_noise_mm = *o->landmark_noise;
        if (o->surface_noise) spec.surface_noise_mm = *o->surface_noise;
        spec.validate();

        ProgressDisplay bar("phantom");
        const DatasetReport result = generate_phantom_dataset(spec, o->output, o->replace, [&](double f, const std::string& m) { bar.update(f, m); });
        bar.finish();
        const auto summary = nlohmann::json::parse(result.summary_json);
        const auto& models = summary["ground_truth"]["models"];
        const auto& main_model = models.contains("body") ? models["body"] : models["organs"];
        logger()->info("phantom dataset '{}': {} states, ground truth {} nodes / {} tetrahedra, {:.1f} s", o->output,
                       summary["states"].size(), main_model["nodes"].get<long>(), main_model["elements"].get<long>(),
                       summary["timings"]["total_s"].get<double>());
        report(*o, summary);
    });
}

} // namespace physreg::cli
