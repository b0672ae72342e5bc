// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/simulation.hpp"

#include "physreg/core/config_keys.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/tet_split.hpp"

#include <algorithm>
#include <chrono>
#include <yaml-cpp/yaml.h>

namespace physreg {
namespace fs = std::filesystem;
namespace {

struct Reader {
    std::string what;

    /// Unknown keys are errors (a misspelt or misplaced key would otherwise be ignored silently).
    void check_keys(const YAML::Node& node, std::initializer_list<const char*> allowed, const std::string& where) const
    {
        if (!node || !node.IsMap()) return;
        std::vector<std::string> keys;
        for (const auto& entry : node) keys.push_back(entry.first.as<std::string>());
        require_known_keys(keys, std::vector<std::string_view>(allowed.begin(), allowed.end()), what, where);
    }

    template <typename T>
    T get(const YAML::Node& node, const std::string& key, const std::string& where) const
    {
        try {
            return node.as<T>();
        } catch (const YAML::Exception&) {
            fail("{}: '{}' in {} has the wrong type", what, key, where);
        }
    }
    double number(const YAML::Node& parent, const std::string& key, const std::string& where, std::optional<double> fallback = {}) const
    {
        if (!parent[key]) {
            if (fallback) return *fallback;
            fail("{}: {} needs '{}'", what, where, key);
        }
        const double v = get<double>(parent[key], key, where);
        if (!std::isfinite(v)) fail("{}: '{}' in {} is not finite", what, key, where);
        return v;
    }
    Vec3 vec3(const YAML::Node& node, const std::string& key, const std::string& where) const
    {
        if (!node || !node.IsSequence() || node.size() != 3) fail("{}: '{}' in {} must be a list of 3 numbers", what, key, where);
        Vec3 v;
        for (int a = 0; a < 3; ++a) v[a] = get<double>(node[a], key, where);
        if (!v.allFinite()) fail("{}: '{}' in {} is not finite", what, key, where);
        return v;
    }
    NodeSelection selection(const YAML::Node& node, const std::string& where) const
    {
        if (!node || !node.IsMap()) fail("{}: {} needs a 'select' map (face, box or nodes)", what, where);
        check_keys(node, {"face", "tolerance_mm", "box", "nodes", "surface_only"}, where + ".select");
        if (node["box"]) check_keys(node["box"], {"min", "max"}, where + ".select.box");
        NodeSelection s;
        if (node["face"]) {
            const std::string face = get<std::string>(node["face"], "face", where); // e.g. "y_min"
            const auto underscore = face.find('_');
            const std::string axis = face.substr(0, underscore);
            if (underscore == std::string::npos || (axis != "x" && axis != "y" && axis != "z"))
                fail("{}: face '{}' in {} must look like x_min, y_max, …", what, face, where);
            s.axis = axis[0] - 'x';
            s.side = face.substr(underscore + 1);
            s.tolerance_mm = number(node, "tolerance_mm", where, 1e-6);
        }
        if (node["box"]) {
            s.box_min = vec3(node["box"]["min"], "box.min", where);
            s.box_max = vec3(node["box"]["max"], "box.max", where);
        }
        if (node["nodes"])
            for (const auto& n : node["nodes"]) s.nodes.push_back(get<std::int32_t>(n, "nodes", where));
        if (node["surface_only"]) s.surface_only = get<bool>(node["surface_only"], "surface_only", where);
        return s;
    }
};

fs::path resolve(const fs::path& base, const std::string& file)
{
    const fs::path p(file);
    return p.is_absolute() ? p : base.parent_path() / p;
}

} // namespace

SimulationCase read_simulation_case(const fs::path& path)
{
    const Reader r{"case '" + path.string() + "'"};
    if (!fs::exists(path)) fail_missing_file("{}: file does not exist", r.what);
    YAML::Node root;
    try {
        root = YAML::LoadFile(path.string());
    } catch (const YAML::Exception& e) {
        fail("{}: not valid YAML: {}", r.what, e.what());
    }
    if (!root.IsMap()) fail("{}: expected a map", r.what);
    r.check_keys(root,
                 {"mesh", "labels", "grid", "tissues", "element", "material_law", "solver", "constraints", "forces", "indenters",
                  "gravity_mm_s2", "output"},
                 "the case");
    SimulationCase c;
    c.source = path;
    if (root["mesh"]) c.mesh_file = resolve(path, r.get<std::string>(root["mesh"], "mesh", "the case"));
    if (root["labels"]) c.labels_file = resolve(path, r.get<std::string>(root["labels"], "labels", "the case"));
    if (c.mesh_file.empty() == c.labels_file.empty()) fail("{}: give exactly one of 'mesh' or 'labels'", r.what);
    if (root["grid"]) c.grid = parse_grid_dims(r.get<std::string>(root["grid"], "grid", "the case"), r.what + ": grid");
    if (root["tissues"]) c.tissues_file = resolve(path, r.get<std::string>(root["tissues"], "tissues", "the case"));
    if (root["element"]) {
        const auto e = r.get<std::string>(root["element"], "element", "the case");
        if (e != "hexahedron" && e != "tetrahedron") fail("{}: element '{}' must be hexahedron or tetrahedron", r.what, e);
        c.tetrahedra = e == "tetrahedron";
    }
    if (root["material_law"]) c.tled.law = parse_material_law(r.get<std::string>(root["material_law"], "material_law", "the case"));
    if (root["gravity_mm_s2"]) c.gravity_mm_s2 = r.vec3(root["gravity_mm_s2"], "gravity_mm_s2", "the case");

    const YAML::Node solver = root["solver"];
    if (solver) {
        const std::string where = "solver";
        r.check_keys(solver,
                     {"method", "mode", "precision", "duration_s", "ramp_time_s", "damping_per_s", "hourglass_kappa", "hourglass_modulus",
                      "averaged_nodal_pressure", "time_step_safety", "density_scale", "time_step_s", "load_steps",
                      "displacement_tolerance_mm", "residual_tolerance", "max_iterations", "linear", "tolerance",
                      "penetration_tolerance_mm", "max_load_cuts", "rayleigh_mass_per_s", "rayleigh_stiffness_s", "mass", "tangent",
                      "newton_iterations", "corotational_tangent"},
                     where);
        if (solver["mode"]) {
            const auto mode = r.get<std::string>(solver["mode"], "mode", where);
            if (mode != "static" && mode != "dynamic") fail("{}: solver.mode '{}' must be static or dynamic", r.what, mode);
            c.method = mode == "dynamic" ? SimulationCase::Method::explicit_dynamics : SimulationCase::Method::relaxation;
        }
        if (solver["method"]) {
            const auto method = r.get<std::string>(solver["method"], "method", where);
            SimulationCase::Method m;
            if (method == "relaxation") m = SimulationCase::Method::relaxation;
            else if (method == "newton") m = SimulationCase::Method::newton;
            else if (method == "explicit") m = SimulationCase::Method::explicit_dynamics;
            else if (method == "backward-euler") m = SimulationCase::Method::backward_euler;
            else fail("{}: solver.method '{}' must be relaxation, newton, explicit or backward-euler", r.what, method);
            if (solver["mode"] && m != c.method) fail("{}: solver.mode and solver.method disagree", r.what);
            c.method = m;
        }
        const bool implicit_dynamics = c.method == SimulationCase::Method::backward_euler;
        c.dynamic = c.method == SimulationCase::Method::explicit_dynamics || implicit_dynamics;
        const bool newton = c.method == SimulationCase::Method::newton;
        for (const char* key : {"linear", "penetration_tolerance_mm", "max_load_cuts"})
            if (solver[key] && !newton) fail("{}: solver.{} applies to method: newton only", r.what, key);
        if (solver["tolerance"] && !newton && !implicit_dynamics)
            fail("{}: solver.tolerance applies to methods newton and backward-euler", r.what);
        for (const char* key : {"rayleigh_mass_per_s", "rayleigh_stiffness_s", "mass", "tangent", "newton_iterations", "corotational_tangent"})
            if (solver[key] && !implicit_dynamics) fail("{}: solver.{} applies to method: backward-euler only", r.what, key);
        for (const char* key : {"damping_per_s", "density_scale", "time_step_safety", "precision", "load_steps"})
            if (solver[key] && implicit_dynamics)
                fail("{}: solver.{} does not apply to method: backward-euler (it takes time_step_s, rayleigh_mass_per_s, "
                     "rayleigh_stiffness_s)",
                     r.what, key);
        if (implicit_dynamics) {
            BackwardEulerOptions& be = c.backward_euler;
            if (!solver["time_step_s"]) fail("{}: method backward-euler needs solver.time_step_s", r.what);
            be.time_step_s = r.number(solver, "time_step_s", where);
            be.rayleigh_mass_per_s = r.number(solver, "rayleigh_mass_per_s", where, 0.0);
            be.rayleigh_stiffness_s = r.number(solver, "rayleigh_stiffness_s", where, 0.0);
            if (solver["mass"]) be.mass = parse_mass_kind(r.get<std::string>(solver["mass"], "mass", where));
            if (solver["tangent"]) be.tangent = parse_tangent_update(r.get<std::string>(solver["tangent"], "tangent", where));
            if (solver["corotational_tangent"]) {
                const auto t = r.get<std::string>(solver["corotational_tangent"], "corotational_tangent", where);
                if (t != "rotated" && t != "exact") fail("{}: solver.corotational_tangent '{}' must be rotated or exact", r.what, t);
                be.rotated_corotational_tangent = t == "rotated";
            }
            be.fixed_newton_iterations = static_cast<int>(r.number(solver, "newton_iterations", where, 0.0));
            be.residual_tolerance = r.number(solver, "tolerance", where, be.residual_tolerance);
            be.max_newton_iterations = static_cast<int>(r.number(solver, "max_iterations", where, be.max_newton_iterations));
            be.validate();
        }
        for (const char* key : {"displacement_tolerance_mm", "residual_tolerance"})
            if (solver[key] && newton) fail("{}: solver.{} applies to method: relaxation (newton takes 'tolerance')", r.what, key);
        if (newton) {
            if (solver["linear"]) c.newton.linear.kind = parse_linear_solver(r.get<std::string>(solver["linear"], "linear", where));
            c.newton.residual_tolerance = r.number(solver, "tolerance", where, c.newton.residual_tolerance);
            c.newton.penetration_tolerance_mm = r.number(solver, "penetration_tolerance_mm", where, c.newton.penetration_tolerance_mm);
            c.newton.max_load_cuts = static_cast<int>(r.number(solver, "max_load_cuts", where, c.newton.max_load_cuts));
            c.newton.max_iterations = static_cast<int>(r.number(solver, "max_iterations", where, c.newton.max_iterations));
            c.newton.validate();
        }
        if (solver["precision"]) {
            const auto p = r.get<std::string>(solver["precision"], "precision", where);
            if (p != "single" && p != "double") fail("{}: solver.precision '{}' must be single or double", r.what, p);
            c.single_precision = p == "single";
        }
        c.duration_s = r.number(solver, "duration_s", where, 0.0);
        c.ramp_time_s = r.number(solver, "ramp_time_s", where, 0.0);
        c.tled.damping_per_s = r.number(solver, "damping_per_s", where, c.tled.damping_per_s);
        c.tled.hourglass_kappa = r.number(solver, "hourglass_kappa", where, c.tled.hourglass_kappa);
        if (solver["hourglass_modulus"]) {
            const auto m = r.get<std::string>(solver["hourglass_modulus"], "hourglass_modulus", where);
            if (m != "shear" && m != "dilatational") fail("{}: solver.hourglass_modulus '{}' must be shear or dilatational", r.what, m);
            c.tled.hourglass_modulus = m == "shear" ? TledOptions::HourglassModulus::shear : TledOptions::HourglassModulus::dilatational;
        }
        if (solver["averaged_nodal_pressure"])
            c.tled.averaged_nodal_pressure = r.get<bool>(solver["averaged_nodal_pressure"], "averaged_nodal_pressure", where);
        c.tled.time_step_safety = r.number(solver, "time_step_safety", where, c.tled.time_step_safety);
        c.tled.density_scale = r.number(solver, "density_scale", where, c.tled.density_scale);
        if (solver["time_step_s"]) c.time_step_s = r.number(solver, "time_step_s", where);
        c.load_steps = static_cast<int>(r.number(solver, "load_steps", where, 1));
        c.equilibrium.displacement_tolerance_mm = r.number(solver, "displacement_tolerance_mm", where, c.equilibrium.displacement_tolerance_mm);
        c.equilibrium.residual_tolerance = r.number(solver, "residual_tolerance", where, c.equilibrium.residual_tolerance);
        if (!newton && !implicit_dynamics)
            c.equilibrium.max_iterations = static_cast<long>(r.number(solver, "max_iterations", where, double(c.equilibrium.max_iterations)));
    }
    if (c.method == SimulationCase::Method::newton && c.single_precision)
        fail("{}: solver.precision single applies to relaxation and explicit; newton runs in double precision", r.what);
    c.tled.validate();
    c.equilibrium.validate();
    if (c.dynamic && !(c.duration_s > 0)) fail("{}: a dynamic run needs solver.duration_s > 0", r.what);
    if (c.load_steps < 1) fail("{}: solver.load_steps must be ≥ 1", r.what);
    if (c.time_step_s && !(*c.time_step_s > 0)) fail("{}: solver.time_step_s must be > 0", r.what);
    if (c.method == SimulationCase::Method::backward_euler) c.time_step_s.reset(); // not the explicit step
    if (!c.gravity_mm_s2.allFinite()) fail("{}: gravity_mm_s2 is not finite", r.what);

    std::size_t index = 0;
    for (const auto& node : root["constraints"]) {
        SimulationCase::Constraint k;
        const std::string where = fmt::format("constraints[{}]", index++);
        r.check_keys(node, {"name", "select", "fixed", "displacement_mm"}, where);
        k.name = node["name"] ? r.get<std::string>(node["name"], "name", where) : where;
        k.select = r.selection(node["select"], where);
        if (node["fixed"]) {
            k.dofs = {false, false, false};
            for (const auto& d : node["fixed"]) {
                const auto axis = r.get<std::string>(d, "fixed", where);
                if (axis != "x" && axis != "y" && axis != "z") fail("{}: {}.fixed lists '{}' (x, y or z)", r.what, where, axis);
                k.dofs[axis[0] - 'x'] = true;
            }
        }
        if (node["displacement_mm"]) {
            k.displacement_mm = r.vec3(node["displacement_mm"], "displacement_mm", where);
            if (!node["fixed"]) k.dofs = {true, true, true};
        }
        c.constraints.push_back(k);
    }
    index = 0;
    for (const auto& node : root["forces"]) {
        SimulationCase::Force f;
        const std::string where = fmt::format("forces[{}]", index++);
        r.check_keys(node, {"name", "select", "total_force_n"}, where);
        f.name = node["name"] ? r.get<std::string>(node["name"], "name", where) : where;
        f.select = r.selection(node["select"], where);
        f.total_force_n = r.vec3(node["total_force_n"], "total_force_n", where);
        c.forces.push_back(f);
    }
    index = 0;
    for (const auto& node : root["indenters"]) {
        Indenter i;
        const std::string where = fmt::format("indenters[{}]", index++);
        r.check_keys(node, {"name", "shape", "radius_mm", "axis", "normal", "half_extents_mm", "path_mm"}, where);
        i.name = node["name"] ? r.get<std::string>(node["name"], "name", where) : where;
        i.shape = parse_indenter_shape(node["shape"] ? r.get<std::string>(node["shape"], "shape", where) : "");
        i.radius_mm = r.number(node, "radius_mm", where, 0.0);
        if (node["axis"]) i.axis = r.vec3(node["axis"], "axis", where).normalized();
        if (node["normal"]) i.axis = r.vec3(node["normal"], "normal", where).normalized();
        if (node["half_extents_mm"]) i.half_extents_mm = r.vec3(node["half_extents_mm"], "half_extents_mm", where);
        if (!node["path_mm"] || !node["path_mm"].IsSequence()) fail("{}: {} needs 'path_mm', a list of positions", r.what, where);
        for (const auto& p : node["path_mm"]) i.path.push_back(r.vec3(p, "path_mm", where));
        i.validate();
        c.indenters.push_back(i);
    }
    if (c.constraints.empty() && c.indenters.empty() && c.forces.empty() && c.gravity_mm_s2.isZero()) fail("{}: no constraints, forces or indenters: nothing to simulate", r.what);

    const YAML::Node output = root["output"];
    if (!output || !output["directory"]) fail("{}: needs output.directory", r.what);
    r.check_keys(output, {"directory", "frames", "field_spacing_mm"}, "output");
    c.output_directory = resolve(path, r.get<std::string>(output["directory"], "directory", "output"));
    c.frames = static_cast<int>(r.number(output, "frames", "output", 1));
    if (c.frames < 1) fail("{}: output.frames must be ≥ 1", r.what);
    c.field_spacing_mm = r.number(output, "field_spacing_mm", "output", 0.0);
    if (c.field_spacing_mm < 0) fail("{}: output.field_spacing_mm must be ≥ 0", r.what);
    return c;
}

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

std::string to_string(SimulationCase::Method method)
{
    switch (method) {
    case SimulationCase::Method::newton: return "newton";
    case SimulationCase::Method::explicit_dynamics: return "explicit";
    case SimulationCase::Method::backward_euler: return "backward-euler";
    default: return "relaxation";
    }
}

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
