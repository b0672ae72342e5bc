// physreg demo: the main job on the built-in synthetic liver. Until the solver and registration
// issues land it runs the front half of the pipeline: label volume → hexahedral meshes (voxel,
// paper-like grid, coarse) → surfaces, tetrahedra, landmarks located in the mesh.
#include "cli_support.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/mesh/surface_extraction.hpp"
#include "physreg/mesh/tet_split.hpp"
#include "physreg/mechanics/simulation.hpp"
#include "physreg/phantom/synthetic_phantom.hpp"
#include "progress.hpp"

#include "physreg/phantom/dataset.hpp"

#include <chrono>
#include <fstream>
#include <iostream>

namespace physreg::cli {

void add_subcommand_demo(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string output = "demo-out";
        std::string grid = "72x56x36";
        std::string coarse = "24x18x18";
        double voxel_mm = 2.0;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("demo", "Run the main job on the built-in synthetic liver phantom");
    sub->add_option("-o,--output", o->output, "Output directory (created)")->capture_default_str();
    sub->add_option("--grid", o->grid, "High-resolution grid over the liver")->capture_default_str();
    sub->add_option("--coarse-grid", o->coarse, "Coarse grid")->capture_default_str();
    sub->add_option("--voxel-mm", o->voxel_mm, "Voxel size of the synthetic label volume, mm")->capture_default_str();
    sub->add_flag("--json", o->json, "Print the JSON summary on stdout");
    sub->callback([o] {
        namespace fs = std::filesystem;
        using clock = std::chrono::steady_clock;
        auto ms_since = [](clock::time_point t0) {
            return std::chrono::duration<double, std::milli>(clock::now() - t0).count();
        };
        const Index3 grid = parse_grid_dims(o->grid, "--grid");
        const Index3 coarse_grid = parse_grid_dims(o->coarse, "--coarse-grid");
        fs::create_directories(o->output);
        const fs::path dir(o->output);
        auto step = [](int n, const std::string& text) { logger()->info("[{}/8] {}", n, text); };

        step(1, "synthetic liver label volume");
        auto t0 = clock::now();
        const SyntheticPhantom phantom = make_synthetic_liver(o->voxel_mm);
        const TissueTable tissues = default_tissue_table();
        write_label_volume(dir / "labels.nii.gz", phantom.labels);
        write_tissue_table(dir / "tissues.yaml", tissues);
        for (const char* name : {"landmarks.csv", "landmarks.mrk.json", "landmarks.fcsv"})
            write_landmarks(dir / name, phantom.landmarks);
        const double phantom_ms = ms_since(t0);

        step(2, "hexahedral mesh, one hexahedron per voxel");
        t0 = clock::now();
        MeshingOptions voxel_options;
        const auto voxel = mesh_label_volume(phantom.labels, tissues, voxel_options, "synthetic liver");
        const double voxel_ms = ms_since(t0);
        write_volume_mesh(dir / "mesh_voxels.vtu", voxel.mesh);

        step(3, "hexahedral mesh on the " + o->grid + " grid (majority rule)");
        t0 = clock::now();
        MeshingOptions grid_options;
        grid_options.grid_dims = grid;
        const auto fine = mesh_label_volume(phantom.labels, tissues, grid_options, "synthetic liver");
        const double grid_ms = ms_since(t0);
        write_volume_mesh(dir / "mesh_fine.vtu", fine.mesh);

        step(4, "coarse mesh on the " + o->coarse + " grid, fine nodes embedded");
        t0 = clock::now();
        const auto coarse = coarsen(fine.mesh, coarse_grid, ComponentPolicy::keep_all);
        const double coarse_ms = ms_since(t0);
        write_volume_mesh(dir / "mesh_coarse.vtu", coarse.mesh);
        std::size_t outside = 0;
        for (const auto& e : coarse.fine_nodes) outside += !e.inside;

        step(5, "surfaces (boundary + tissue interfaces) and conforming tetrahedra");
        t0 = clock::now();
        const SurfaceMesh surfaces = extract_surfaces(fine.mesh);
        const VolumeMesh tets = split_hexahedra_into_tetrahedra(fine.mesh);
        const double surface_ms = ms_since(t0);
        write_surface(dir / "surfaces_fine.ply", surfaces);
        write_surface(dir / "boundary_fine.stl", extract_boundary(fine.mesh));
        write_volume_mesh(dir / "tetrahedra_fine.vtu", tets);

        step(6, "landmarks located in the fine mesh");
        const PointLocator locator(fine.mesh);
        nlohmann::json located = nlohmann::json::array();
        for (const auto& l : phantom.landmarks) {
            const auto e = locator.locate(l.position);
            located.push_back({{"name", l.name}, {"type", to_string(l.type)}, {"inside_mesh", e.has_value()},
                               {"cell", e ? e->cell : -1}});
        }

        step(7, "TLED: a 30 mm sphere pressed 10 mm into the anterior surface of the coarse model");
        SimulationCase indentation;
        indentation.source = dir / "summary.json";
        indentation.mesh_file = dir / "mesh_coarse.vtu";
        indentation.tissues_file = dir / "tissues.yaml";
        indentation.load_steps = 4;
        SimulationCase::Constraint back;
        back.name = "posterior face";
        back.select.axis = 1;
        back.select.side = "max";
        back.select.tolerance_mm = 3.0;
        indentation.constraints.push_back(back);
        Indenter tool;
        tool.name = "sphere";
        tool.radius_mm = 15.0;
        tool.path = {Vec3(-30, -78, 0), Vec3(-30, -68, 0)};
        indentation.indenters.push_back(tool);
        indentation.output_directory = dir / "indentation";
        indentation.frames = 4;
        indentation.field_spacing_mm = 2.0;
        ProgressDisplay bar("indentation");
        const SimulationResult simulated = run_simulation(indentation, [&](double f, const std::string& m) { bar.update(f, m); });
        bar.finish();
        const nlohmann::json simulation = write_simulation_outputs(indentation, simulated);
        long iterations = 0;
        for (const auto& e : simulated.equilibria) iterations += e.iterations;

        step(8, "phantom experiment dataset (CIRS-057A-like anatomy, small preset; `physreg phantom` makes the full one)");
        ProgressDisplay phantom_bar("phantom");
        const auto dataset = nlohmann::json::parse(
            generate_phantom_dataset(PhantomSpec::preset_spec("small"), dir / "phantom", true,
                                     [&](double f, const std::string& m) { phantom_bar.update(f, m); })
                .summary_json);
        phantom_bar.finish();

        nlohmann::json summary = {
            {"output_directory", dir.string()},
            {"label_volume", to_json(phantom.labels.geometry)},
            {"voxel_mesh", mesh_summary(voxel.mesh, &tissues)},
            {"fine_mesh", mesh_summary(fine.mesh, &tissues)},
            {"coarse_mesh", mesh_summary(coarse.mesh, &tissues)},
            {"fine_nodes_outside_coarse_mesh", outside},
            {"surface_triangles", surfaces.triangles.size()},
            {"tetrahedra", tets.cell_count()},
            {"landmarks", located},
            {"indentation", simulation},
            {"phantom_dataset", {{"directory", (dir / "phantom").string()}, {"states", dataset["states"].size()},
                                 {"ground_truth_nodes", dataset["ground_truth"]["nodes"]},
                                 {"ground_truth_elements", dataset["ground_truth"]["elements"]},
                                 {"seconds", dataset["timings"]["total_s"]}}},
            {"timings_ms", {{"phantom", phantom_ms}, {"voxel_mesh", voxel_ms}, {"grid_mesh", grid_ms},
                            {"coarsen_and_embed", coarse_ms}, {"surfaces_and_tetrahedra", surface_ms}}}};
        write_atomically(dir / "summary.json", [&](const fs::path& tmp) {
            std::ofstream(tmp) << summary.dump(2) << "\n";
        });
        if (o->json) {
            std::cout << summary.dump(2) << std::endl;
            return;
        }
        auto volume = [](const VolumeMesh& m) { return measure_quality(m).volume_mm3 / 1000.0; };
        std::cout << fmt::format("\nphysreg demo — synthetic liver ({} × {} × {} voxels of {} mm)\n\n",
                                 phantom.labels.geometry.size[0], phantom.labels.geometry.size[1],
                                 phantom.labels.geometry.size[2], o->voxel_mm)
                  << fmt::format("{:<28}{:>10}{:>12}{:>14}{:>12}\n", "mesh", "nodes", "hexahedra", "volume (ml)", "time (ms)")
                  << fmt::format("{:<28}{:>10}{:>12}{:>14.1f}{:>12.1f}\n", "one per voxel", voxel.mesh.node_count(),
                                 voxel.mesh.cell_count(), volume(voxel.mesh), voxel_ms)
                  << fmt::format("{:<28}{:>10}{:>12}{:>14.1f}{:>12.1f}\n", "grid " + o->grid, fine.mesh.node_count(),
                                 fine.mesh.cell_count(), volume(fine.mesh), grid_ms)
                  << fmt::format("{:<28}{:>10}{:>12}{:>14.1f}{:>12.1f}\n", "coarse " + o->coarse, coarse.mesh.node_count(),
                                 coarse.mesh.cell_count(), volume(coarse.mesh), coarse_ms)
                  << fmt::format("\n{} surface triangles, {} tetrahedra, {} of {} fine nodes outside the coarse mesh\n",
                                 surfaces.triangles.size(), tets.cell_count(), outside, coarse.fine_nodes.size())
                  << fmt::format("TLED indentation (coarse model, Neo-Hookean, 10 mm sphere travel): {} iterations of dynamic "
                                 "relaxation over 4 tool positions, {:.1f} s, max displacement {:.2f} mm\n",
                                 iterations, simulated.seconds, simulation["max_displacement_mm"].get<double>())
                  << fmt::format("phantom dataset (small preset): {} states with ground truth, landmarks, partial surfaces and "
                                 "pictures in '{}', {:.1f} s\n",
                                 dataset["states"].size(), (dir / "phantom").string(), dataset["timings"]["total_s"].get<double>())
                  << fmt::format("outputs in '{}' (open the .vtu files and indentation/frames.pvd in ParaView, labels.nii.gz, "
                                 "landmarks.mrk.json and indentation/displacement_field.nii.gz in 3D Slicer)\n",
                                 dir.string());
    });
}

} // namespace physreg::cli
