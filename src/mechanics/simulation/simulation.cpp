// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/simulation/simulation.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/mechanics/explicit/gpu_tled.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/tet_split.hpp"

#include <algorithm>
#include <chrono>

namespace physreg {
namespace {

template <typename Real>
void run(const SimulationCase& c, const TledModel& model, const Loads& loads, SimulationResult& result,
         const std::function<void(double, const std::string&)>& progress)
{
    if (c.method == SimulationCase::Method::backward_euler) {
        BackwardEuler integrator(model, c.backward_euler);
        integrator.set_loads(loads);
        SimulationResult::BackwardEulerTotals totals;
        const double dt = c.backward_euler.time_step_s;
        const long steps = std::lround(std::ceil(c.duration_s / dt - 1e-9));
        long frame = 1;
        for (long step = 1; step <= steps; ++step) {
            const BackwardEulerStep s = integrator.step();
            totals.newton_iterations += s.newton_iterations;
            totals.factorisations += s.factorisations;
            totals.shifted_factorisations += s.shifted_factorisations;
            totals.worst_relative_residual = std::max(totals.worst_relative_residual, s.residual_n / std::max(s.reference_force_n, 1e-300));
            totals.most_inverted_elements = std::max(totals.most_inverted_elements, s.inverted_elements);
            totals.force_s += s.force_s;
            totals.assembly_s += s.assembly_s;
            totals.factorisation_s += s.factorisation_s;
            totals.solve_s += s.solve_s;
            if (progress && (step % 10 == 0 || step == steps))
                progress(double(step) / steps, fmt::format("step {}/{}, t = {:.4g} s, {} Newton iteration(s)", step, steps, integrator.time_s(),
                                                           s.newton_iterations));
            // Frames evenly in time: frame k at the first step reaching k/frames of the duration.
            while (frame <= c.frames && step * c.frames >= frame * steps) {
                result.frames.push_back({integrator.time_s(), loads.load_factor(integrator.time_s()), integrator.displacement_mm()});
                ++frame;
            }
        }
        if (totals.most_inverted_elements > 0)
            logger()->warn("backward Euler: up to {} co-rotational element(s) were inverted during the run (kept, pushed back by "
                           "the law)",
                           totals.most_inverted_elements);
        result.backward_euler = totals;
        result.steps = steps;
        result.time_step_s = dt;
        return;
    }
    if (c.device != Device::cpu) {
        check_device(c, "simulate");
        GpuTledSolver solver(model, c.device);
        solver.set_loads(loads);
        for (int frame = 1; frame <= c.frames; ++frame) {
            const double until = c.duration_s * frame / c.frames;
            solver.advance(until - solver.time_s(), [&](double, long step) {
                if (progress) progress(solver.time_s() / c.duration_s, fmt::format("step {} ({}), t = {:.4g} s", step, to_string(c.device), solver.time_s()));
            });
            result.frames.push_back({solver.time_s(), loads.load_factor(solver.time_s()), solver.displacement_mm()});
        }
        result.steps = solver.steps();
        return;
    }
    TledSolver<Real> solver(model);
    solver.set_loads(loads);
    if (c.dynamic) {
        for (int frame = 1; frame <= c.frames; ++frame) {
            const double until = c.duration_s * frame / c.frames;
            solver.advance(until - solver.time_s(), [&](double, long step) {
                if (progress) progress(solver.time_s() / c.duration_s, fmt::format("step {}, t = {:.4g} s", step, solver.time_s()));
            });
            result.frames.push_back({solver.time_s(), loads.load_factor(solver.time_s()), solver.displacement_mm()});
        }
        result.steps = solver.steps();
        return;
    }
    if (c.method == SimulationCase::Method::newton) {
        NewtonSolver newton(model, c.newton);
        newton.set_loads(loads);
        for (int step = 1; step <= c.load_steps; ++step) {
            const double factor = double(step) / c.load_steps;
            const NewtonSummary s = newton.solve_equilibrium(factor, [&](double, long iteration) {
                if (progress) progress((step - 1 + 0.5) / c.load_steps, fmt::format("load step {}/{}, Newton iteration {}", step, c.load_steps, iteration));
            });
            result.newton_solves.push_back(s);
            if (!s.converged) fail("load step {}/{}: {}", step, c.load_steps, s.message);
            logger()->info("load step {}/{}: {}", step, c.load_steps, s.message);
            if (progress) progress(double(step) / c.load_steps, fmt::format("load step {}/{} done", step, c.load_steps));
            result.frames.push_back({0.0, factor, newton.displacement_mm()});
        }
        return;
    }
    for (int step = 1; step <= c.load_steps; ++step) {
        const double factor = double(step) / c.load_steps;
        const SolveSummary s = solver.solve_equilibrium(c.equilibrium, factor, [&](double, long iteration) {
            if (progress) progress((step - 1 + 0.5) / c.load_steps, fmt::format("load step {}/{}, iteration {}", step, c.load_steps, iteration));
        });
        result.equilibria.push_back(s);
        if (!s.converged()) fail("load step {}/{}: {}", step, c.load_steps, s.message);
        logger()->info("load step {}/{}: {}", step, c.load_steps, s.message);
        if (progress) progress(double(step) / c.load_steps, fmt::format("load step {}/{} done", step, c.load_steps));
        result.frames.push_back({0.0, factor, solver.displacement_mm()});
    }
    result.steps = solver.steps();
}

} // namespace

SimulationResult run_simulation(const SimulationCase& c, const std::function<void(double, const std::string&)>& progress)
{
    const auto start = std::chrono::steady_clock::now();
    SimulationResult result;
    TissueTable tissues = c.tissues_file.empty() ? default_tissue_table() : read_tissue_table(c.tissues_file);
    if (!c.mesh_file.empty()) {
        result.mesh = read_volume_mesh(c.mesh_file);
    } else {
        const LabelVolume volume = read_label_volume(c.labels_file);
        MeshingOptions options;
        options.grid_dims = c.grid;
        result.mesh = mesh_label_volume(volume, tissues, options, "labels '" + c.labels_file.string() + "'").mesh;
        result.label_geometry = volume.geometry;
    }
    if (c.tetrahedra) result.mesh = split_hexahedra_into_tetrahedra(result.mesh);
    TledOptions options = c.tled;
    {
        const TledModel probe(result.mesh, tissues, options);
        result.critical_time_step_s = probe.critical_time_step_s();
        if (c.time_step_s) {
            if (*c.time_step_s > probe.critical_time_step_s())
                fail("solver.time_step_s = {:.4g} s is above the critical time step {:.4g} s (element {}): the run would "
                     "be unstable",
                     *c.time_step_s, probe.critical_time_step_s(), probe.critical_element());
            options.time_step_safety = *c.time_step_s / probe.critical_time_step_s();
        }
    }
    const TledModel model(result.mesh, tissues, options);
    result.time_step_s = model.time_step_s();
    if (c.method == SimulationCase::Method::backward_euler) result.time_step_s = c.backward_euler.time_step_s;
    Loads loads;
    loads.ramp_time_s = c.ramp_time_s;
    for (const auto& k : c.constraints)
        loads.constraints.push_back({k.name, select_nodes(result.mesh, k.select, "constraint '" + k.name + "'"), k.dofs, k.displacement_mm});
    if (!c.forces.empty()) loads.external_forces_n.assign(3 * result.mesh.node_count(), 0.0);
    for (const auto& f : c.forces) {
        const auto nodes = select_nodes(result.mesh, f.select, "force '" + f.name + "'");
        for (auto n : nodes)
            for (int d = 0; d < 3; ++d) loads.external_forces_n[3 * n + d] += f.total_force_n[d] / double(nodes.size());
    }
    if (!c.gravity_mm_s2.isZero()) {
        // Weight from the physical mass (the lumped mass divided by any explicit mass scaling).
        if (loads.external_forces_n.empty()) loads.external_forces_n.assign(3 * result.mesh.node_count(), 0.0);
        for (std::size_t n = 0; n < result.mesh.node_count(); ++n)
            for (int d = 0; d < 3; ++d)
                loads.external_forces_n[3 * n + d] += model.lumped_mass()[n] / options.density_scale * c.gravity_mm_s2[d];
    }
    loads.indenters = c.indenters;
    logger()->info("model: {} nodes, {} {}, {} material(s); critical time step {:.4g} s", model.node_count(),
                   model.element_count(), to_string(result.mesh.cell_type), model.materials().size(), model.critical_time_step_s());
    if (c.single_precision) run<float>(c, model, loads, result, progress);
    else run<double>(c, model, loads, result, progress);
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
}

} // namespace physreg
