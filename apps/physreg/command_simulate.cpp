// SPDX-License-Identifier: GPL-3.0-or-later
// physreg simulate CASE.yaml: TLED simulation of a mesh or label volume under constraints,
// forces and indenters; writes VTU frames, a ParaView collection, the final displacement field
// (VTU and ITK image) and a JSON summary. Outputs appear only when the run succeeds.
#include "cli_support.hpp"
#include "progress.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/mechanics/explicit/gpu_tled.hpp"
#include "physreg/mechanics/simulation/simulation.hpp"

#include <fstream>
#include <iostream>
#include <unistd.h>

namespace physreg::cli {
namespace fs = std::filesystem;
namespace {

// A folder beside the outputs that is moved into place file by file on success, removed on failure.
class StagingDirectory {
public:
    explicit StagingDirectory(const fs::path& target) : m_target(target)
    {
        fs::create_directories(target);
        m_path = target / fmt::format(".partial-{}", ::getpid());
        fs::remove_all(m_path);
        fs::create_directories(m_path);
    }
    ~StagingDirectory()
    {
        std::error_code ec;
        fs::remove_all(m_path, ec);
    }
    const fs::path& path() const { return m_path; }
    void commit()
    {
        for (const auto& entry : fs::directory_iterator(m_path)) fs::rename(entry.path(), m_target / entry.path().filename());
    }

private:
    fs::path m_target, m_path;
};

} // namespace

nlohmann::json write_simulation_outputs(const SimulationCase& c, const SimulationResult& result)
{
    StagingDirectory staging(c.output_directory);
    std::string pvd = "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n";
    double largest = 0.0;
    for (std::size_t k = 0; k < result.frames.size(); ++k) {
        const auto& frame = result.frames[k];
        MeshData frame_data;
        frame_data.point_data.push_back({"displacement", 3, frame.displacement_mm});
        const std::string name = fmt::format("frame_{:04d}.vtu", k + 1);
        write_vtu(staging.path() / name, result.mesh, frame_data);
        const double stamp = c.dynamic ? frame.time_s : frame.load_factor;
        pvd += fmt::format("<DataSet timestep=\"{}\" file=\"{}\"/>\n", stamp, name);
    }
    pvd += "</Collection>\n</VTKFile>\n";
    write_atomically(staging.path() / "frames.pvd", [&](const fs::path& tmp) { std::ofstream(tmp) << pvd; });
    const auto& final_u = result.frames.back().displacement_mm;
    for (std::size_t n = 0; n < result.mesh.node_count(); ++n)
        largest = std::max(largest, Vec3(final_u[3 * n], final_u[3 * n + 1], final_u[3 * n + 2]).norm());
    MeshData final_data;
    final_data.point_data.push_back({"displacement", 3, final_u});
    write_vtu(staging.path() / "final.vtu", result.mesh, final_data);
    // The dense field on the label volume's grid (or a grid over the mesh).
    ImageGeometry geometry = (result.label_geometry && c.field_spacing_mm == 0.0)
                                 ? *result.label_geometry
                                 : image_grid_over_mesh(result.mesh, c.field_spacing_mm > 0 ? c.field_spacing_mm : 2.0);
    const SampledField field = sample_displacement_field(result.mesh, final_u, geometry);
    write_displacement_field(staging.path() / "displacement_field.nii.gz", field.field);
    LabelVolume mask{geometry, {field.inside.begin(), field.inside.end()}};
    write_label_volume(staging.path() / "displacement_mask.nii.gz", mask);

    nlohmann::json equilibria = nlohmann::json::array();
    for (const auto& s : result.equilibria)
        equilibria.push_back({{"iterations", s.iterations}, {"residual_n", s.residual_n}, {"reference_force_n", s.reference_force_n},
                              {"estimated_error_mm", s.estimated_error_mm}, {"seconds", s.seconds}});
    nlohmann::json newton = nlohmann::json::array();
    for (const auto& s : result.newton_solves)
        newton.push_back({{"converged", s.converged},
                          {"linear_solver", s.linear_solver},
                          {"increments", s.increments},
                          {"load_cuts", s.load_cuts},
                          {"newton_iterations", s.newton_iterations},
                          {"residual_history_n", s.residual_history},
                          {"residual_n", s.residual_n},
                          {"reference_force_n", s.reference_force_n},
                          {"linear_iterations", s.linear_iterations},
                          {"factorisations", s.factorisations},
                          {"shifted_factorisations", s.shifted_factorisations},
                          {"contact_updates", s.contact_updates},
                          {"contact_nodes", s.contact_nodes},
                          {"max_penetration_mm", s.max_penetration_mm},
                          {"time_s", {{"assembly", s.assembly_s}, {"factorisation", s.factorisation_s}, {"solve", s.solve_s},
                                      {"contact", s.contact_s}, {"line_search", s.line_search_s}, {"total", s.seconds}}}});
    nlohmann::json backward_euler = nullptr;
    if (result.backward_euler) {
        const auto& t = *result.backward_euler;
        backward_euler = {{"time_step_s", c.backward_euler.time_step_s},
                          {"rayleigh_mass_per_s", c.backward_euler.rayleigh_mass_per_s},
                          {"rayleigh_stiffness_s", c.backward_euler.rayleigh_stiffness_s},
                          {"mass", to_string(c.backward_euler.mass)},
                          {"tangent", to_string(c.backward_euler.tangent)},
                          {"newton_iterations_per_step", c.backward_euler.fixed_newton_iterations > 0
                                                             ? nlohmann::json(c.backward_euler.fixed_newton_iterations)
                                                             : nlohmann::json("to tolerance")},
                          {"tolerance", c.backward_euler.residual_tolerance},
                          {"newton_iterations", t.newton_iterations},
                          {"factorisations", t.factorisations},
                          {"shifted_factorisations", t.shifted_factorisations},
                          {"worst_relative_residual", t.worst_relative_residual},
                          {"most_inverted_elements", t.most_inverted_elements},
                          {"time_s", {{"forces", t.force_s}, {"assembly", t.assembly_s}, {"factorisation", t.factorisation_s}, {"solve", t.solve_s}}}};
    }
    nlohmann::json summary = {{"case", c.source.string()},
                              {"method", to_string(c.method)},
                              {"mode", c.dynamic ? "dynamic" : "static"},
                              {"precision", c.single_precision ? "single" : "double"},
                              {"device", to_string(c.device)},
                              {"material_law", to_string(c.tled.law)},
                              {"mesh", mesh_summary(result.mesh)},
                              {"critical_time_step_s", result.critical_time_step_s},
                              {"time_step_s", result.time_step_s},
                              {"steps", result.steps},
                              {"equilibria", equilibria},
                              {"newton", newton},
                              {"backward_euler", backward_euler},
                              {"max_displacement_mm", largest},
                              {"seconds", result.seconds},
                              {"outputs", {"frames.pvd", "final.vtu", "displacement_field.nii.gz", "displacement_mask.nii.gz"}}};
    write_atomically(staging.path() / "summary.json", [&](const fs::path& tmp) { std::ofstream(tmp) << summary.dump(2) << "\n"; });
    staging.commit();
    return summary;
}

void add_subcommand_simulate(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string case_file, output, device;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("simulate", "Run a TLED simulation described by a case file (YAML)");
    sub->add_option("case", o->case_file, "Case file (see docs/simulate.md)")->required();
    sub->add_option("-o,--output", o->output, "Output directory (instead of the case file's `output`)");
    sub->add_flag("--json", o->json, "Print the JSON summary on stdout");
    sub->add_option("--device", o->device,
                    "Where explicit dynamics runs: cpu, gpu (CUDA; refused with the reason when this build or machine has none) or "
                    "gpu-emulation (the GPU algorithm on the host, for checking); default: the case's solver.device, else cpu");
    sub->callback([o] {
        SimulationCase c = read_simulation_case(o->case_file);
        if (!o->output.empty()) c.output_directory = o->output;
        if (!o->device.empty()) {
            c.device = parse_device(o->device);
            check_device(c, "--device " + o->device);
            if (c.device == Device::gpu) {
                const GpuStatus status = gpu_status();
                if (!status.usable()) fail("--device gpu: {}", status.reason);
            }
        }
        ProgressDisplay bar("simulate");
        const SimulationResult result = run_simulation(c, [&](double f, const std::string& m) { bar.update(f, m); });
        bar.finish();

        const nlohmann::json summary = write_simulation_outputs(c, result);
        logger()->info("simulated {} steps in {:.2f} s; max displacement {:.3f} mm → '{}'", result.steps, result.seconds,
                       summary["max_displacement_mm"].get<double>(), c.output_directory.string());
        report(*o, summary);
    });
}

} // namespace physreg::cli
