// SPDX-License-Identifier: GPL-3.0-or-later
// physreg register-surface: paper 001 — a tetrahedral liver model registered to a partial
// intra-operative surface (labelled point cloud), with rigid and ICP baselines in the same report.
// The pipeline is the library's register_partial_surface
// (registration/surface/partial_surface_registration.hpp); this command reads the case, resolves
// the settings (partial_surface_spec: options, --settings FILE) and writes the files.
#include "cli_support.hpp"
#include "progress.hpp"
#include "settings_options.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/phantom/registration_cases.hpp"
#include "physreg/registration/surface/partial_surface_registration.hpp"
#include "physreg/registration/surface/surface_model.hpp"

#include <chrono>
#include <fstream>
#include <iostream>

namespace physreg::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct Sources : CommonOptions {
    std::string dataset, state = "insufflation", output;
    std::optional<int> visible;
    PartialSurfaceFiles files;
    bool replace = false;
};

PartialSurfaceCase load_case(const Sources& o, const PartialSurfaceSettings& s)
{
    const auto& f = o.files;
    if (o.dataset.empty()) return read_partial_surface_case(f, s);
    if (!f.labels.empty() || !f.model.empty() || !f.surface.empty()) fail("register-surface: give exactly one of --dataset, --labels, --surface and --model");
    if (!f.cloud.empty() || !f.landmarks.empty() || !f.landmarks_truth.empty() || !f.truth_surface.empty() || !f.regions.empty() || !f.region_seeds.empty())
        fail("register-surface: --dataset provides the cloud, landmarks, regions and truth; leave out --cloud, --landmarks, --landmarks-truth, --truth-surface and "
             "--regions");
    PartialSurfaceCase c = read_dataset_surface_case(o.dataset, o.state, o.visible, s, f.vessels);
    read_support_files(c, f.support_points, f.support_nodes);
    return c;
}

void write_outputs(const fs::path& folder, const PartialSurfaceCase& c, const PartialSurfaceResult& r)
{
    const auto& u = r.chosen_method().displacement_mm;
    MeshData data;
    data.point_data.push_back({"displacement", 3, u});
    write_vtu(folder / "mesh.vtu", c.mesh, data);
    write_surface(folder / "regions.ply", regions_surface(c.mesh, c.surface));
    write_surface(folder / "regions.vtk", regions_surface(c.mesh, c.surface));
    write_surface(folder / "registered_surface.ply", regions_surface(c.mesh, c.surface, &u));
    write_displacement_field(folder / "displacement.nii.gz", sample_displacement_field(c.mesh, u, r.field_geometry).field);
    if (r.landmarks) write_landmarks(folder / "landmarks.csv", *r.landmarks);
}

/// One line per method on stderr: TRE, nodal error, Hausdorff distance, fit to the cloud, seconds.
void print_methods(const json& methods)
{
    const auto mm = [](const json& v) { return v.is_number() ? fmt::format("{:.2f}", v.get<double>()) : std::string("–"); };
    for (const char* name : {"at_rest", "icp", "rigid", "biomechanical", "adjoint"}) {
        if (!methods.contains(name)) continue;
        const json& m = methods[name];
        std::string s = fmt::format("{:<14}", name);
        if (m.contains("tre")) s += fmt::format(" TRE {} mm (internal {})", mm(m["tre"]["all"]["mean_mm"]), mm(m["tre"]["internal"]["mean_mm"]));
        if (m.contains("node_tre_mm")) s += fmt::format(", nodes {:.2f} mm", m["node_tre_mm"]["mean"].get<double>());
        if (m.contains("hausdorff_mm")) s += fmt::format(", Hausdorff mean {:.2f} / max {:.2f} mm", m["hausdorff_mm"]["mean"].get<double>(), m["hausdorff_mm"]["max"].get<double>());
        s += fmt::format(", cloud→model {:.2f} mm, {:.2f} s", m["cloud_to_model_mm"]["mean"].get<double>(), m["seconds"].get<double>());
        std::cerr << s << "\n";
    }
}

} // namespace

void add_subcommand_register_surface(CLI::App& app)
{
    auto o = std::make_shared<Sources>();
    auto& f = o->files;
    auto* sub = app.add_subcommand("register-surface", "Register a tetrahedral liver model to a partial intra-operative surface (paper 001): "
                                                       "labelled matching, arctan forces with annealing, co-rotational backward Euler");
    sub->add_option("--dataset", o->dataset, "Phantom dataset (physreg phantom): model from its rest labels, cloud, landmarks and truth from --state");
    sub->add_option("--state", o->state, "Dataset state to register to (default insufflation)");
    sub->add_option("--visible", o->visible, "Dataset: visible percentage of the surface (one the dataset has: 50, 40, 30, 20, 10; default 30)");
    sub->add_option("--labels", f.labels, "Liver label volume (NIfTI/NRRD/MHA/DICOM): meshed with CGAL");
    sub->add_option("--liver-labels", f.liver_labels, "--labels: which labels form the liver (default every nonzero label)");
    sub->add_option("--notch-x", f.notch_x_mm, "--labels/--surface: x (LPS, mm) of the umbilical notch for the anatomical region rule (else: --labels "
                                               "has no UN region, --surface no region at all)");
    sub->add_option("--surface", f.surface, "Closed liver surface (STL/PLY/OBJ, mm, LPS): meshed with CGAL");
    sub->add_option("--model", f.model, "Tetrahedral liver mesh (.vtu, .vtk, .msh) instead of --labels");
    sub->add_option("--regions", f.regions, "Labelled surface (PLY with vertex 'label'/'feature' or face labels; 0 surface, 1 UN, 2 AM) giving the model's regions");
    sub->add_option("--region-seeds", f.region_seeds, "Points picked on the surface (CSV/FCSV/.mrk.json) named UN… or AM…: regions grown along the surface from them");
    sub->add_option("--cloud", f.cloud, "Intra-operative point cloud (.ply with optional normals and 'label', or .csv x,y,z[,label] with or without a header), mm, LPS");
    sub->add_option("--landmarks", f.landmarks, "Targets at rest (CSV/FCSV/.mrk.json) to map through the registration");
    sub->add_option("--landmarks-truth", f.landmarks_truth, "Their true deformed positions (same names): TRE in the summary");
    sub->add_option("--truth-surface", f.truth_surface, "The true deformed liver surface (STL/PLY/OBJ): Hausdorff distance in the summary");
    sub->add_option("--vessels", f.vessels, "Heterogeneous model: vessel centrelines (CSV branch,x,y,z,radius, or text 'x y z' lines with blank lines between "
                                            "branches); --dataset brings the phantom's own");
    sub->add_option("--support-points", f.support_points, "Further support: surface nodes within --support-radius of these points (landmark file: CSV, .fcsv, "
                                                          ".mrk.json; e.g. ligaments, vena cava)");
    sub->add_option("--support-nodes", f.support_nodes, "Further support: a file of model node ids (one or more per line, '#' comments)");
    auto settings = std::make_shared<SettingsOptions<PartialSurfaceSettings>>(sub, partial_surface_spec());
    sub->add_option("-o,--output", o->output, "Output folder (mesh.vtu, displacement.nii.gz, landmarks.csv, regions.ply, summary.json)")->required();
    sub->add_flag("--force", o->replace, "Replace an existing output folder");
    sub->add_flag("--json", o->json, "Print the summary as JSON on stdout");
    sub->callback([o, settings] {
        const auto start = std::chrono::steady_clock::now();
        const PartialSurfaceSettings s = settings->resolve();
        validate(s, SettingNaming::option);
        if (!o->files.vessels.empty() && s.model_kind != "heterogeneous") fail("--vessels: only the heterogeneous model has vessels (add --model-kind heterogeneous)");
        StagedDirectory staging(o->output, o->replace); // refuses an existing output before any work
        ProgressDisplay bar("register-surface");
        bar.update(0.0, "model and inputs");
        const PartialSurfaceCase c = load_case(*o, s);
        PartialSurfaceResult r = register_partial_surface(c, s, [&](double fraction, const std::string& m) { bar.update(fraction, m); });
        bar.update(0.95, "outputs");
        write_outputs(staging.path(), c, r);
        if (!settings->file().empty()) r.summary["settings_file"] = settings->file();
        r.summary["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        write_atomically(staging.path() / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << r.summary.dump(2) << "\n"; });
        bar.update(0.99, "report.html");
        write_html_report(staging.path(), o->output);
        staging.commit();
        bar.finish();
        if (o->json)
            std::cout << r.summary.dump(2) << "\n";
        else
            print_methods(r.summary["methods"]);
        if (!r.summary["determinacy"]["pose_determined"].get<bool>()) {
            logger()->warn("register-surface: {}", r.summary["determinacy"]["statement"].get<std::string>());
            for (const auto& note : r.summary["determinacy"]["notes"]) logger()->warn("  {}", note.get<std::string>());
        }
    });
}

} // namespace physreg::cli
