// SPDX-License-Identifier: GPL-3.0-or-later
// Reading and validating simulation case files (YAML/JSON): its own translation unit so the
// parser can be fuzzed without the solvers.
#include "physreg/mechanics/simulation/simulation.hpp"

#include "physreg/core/config_keys.hpp"
#include "physreg/core/error.hpp"
#include "physreg/mesh/hex_meshing.hpp"

#include <algorithm>
#include <cmath>
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
        for (const auto& entry : node) {
            // A list or map used as a key (`? [a, b]`) is valid YAML but never one of ours.
            if (!entry.first.IsScalar()) fail("{}: line {}: a key in {} must be a plain name", what, entry.first.Mark().line + 1, where);
            keys.push_back(entry.first.Scalar());
        }
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
    /// A whole number in [minimum, maximum] (counts and iteration limits; 2.5 or 1e300 are errors,
    /// not silently truncated).
    long integer(const YAML::Node& parent, const std::string& key, const std::string& where, long fallback,
                 long minimum = 0, long maximum = 2'000'000'000) const
    {
        const double v = number(parent, key, where, static_cast<double>(fallback));
        if (v != std::floor(v) || v < static_cast<double>(minimum) || v > static_cast<double>(maximum))
            fail("{}: '{}' in {} must be a whole number in [{}, {}] (got {})", what, key, where, minimum, maximum, v);
        return static_cast<long>(v);
    }
    /// A section that must be a map when present (`solver: fast` is refused, not indexed).
    YAML::Node section(const YAML::Node& parent, const std::string& key, const std::string& where) const
    {
        const YAML::Node node = parent[key];
        if (node && !node.IsNull() && !node.IsMap()) fail("{}: '{}' in {} must be a map of settings", what, key, where);
        return node;
    }
    /// A section that must be a list when present.
    YAML::Node list(const YAML::Node& parent, const std::string& key, const std::string& where) const
    {
        const YAML::Node node = parent[key];
        if (node && !node.IsNull() && !node.IsSequence()) fail("{}: '{}' in {} must be a list", what, key, where);
        return node;
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
        if (node["box"] && !node["box"].IsMap()) fail("{}: {}.select.box must be a map with 'min' and 'max'", what, where);
        if (node["box"]) check_keys(node["box"], {"min", "max"}, where + ".select.box");
        if (node["nodes"] && !node["nodes"].IsSequence()) fail("{}: {}.select.nodes must be a list of node ids", what, where);
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

namespace {

/// The case's solver section: the method and its options (each applies to the methods named).
void read_solver(SimulationCase& c, const YAML::Node& solver, const Reader& r)
{
    const std::string where = "solver";
    r.check_keys(solver,
                 {"method", "mode", "precision", "device", "duration_s", "ramp_time_s", "damping_per_s", "hourglass_kappa", "hourglass_modulus",
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
        be.fixed_newton_iterations = static_cast<int>(r.integer(solver, "newton_iterations", where, 0.0));
        be.residual_tolerance = r.number(solver, "tolerance", where, be.residual_tolerance);
        be.max_newton_iterations = static_cast<int>(r.integer(solver, "max_iterations", where, be.max_newton_iterations));
        be.validate();
    }
    for (const char* key : {"displacement_tolerance_mm", "residual_tolerance"})
        if (solver[key] && newton) fail("{}: solver.{} applies to method: relaxation (newton takes 'tolerance')", r.what, key);
    if (newton) {
        if (solver["linear"]) c.newton.linear.kind = parse_linear_solver(r.get<std::string>(solver["linear"], "linear", where));
        c.newton.residual_tolerance = r.number(solver, "tolerance", where, c.newton.residual_tolerance);
        c.newton.penetration_tolerance_mm = r.number(solver, "penetration_tolerance_mm", where, c.newton.penetration_tolerance_mm);
        c.newton.max_load_cuts = static_cast<int>(r.integer(solver, "max_load_cuts", where, c.newton.max_load_cuts));
        c.newton.max_iterations = static_cast<int>(r.integer(solver, "max_iterations", where, c.newton.max_iterations));
        c.newton.validate();
    }
    if (solver["precision"]) {
        const auto p = r.get<std::string>(solver["precision"], "precision", where);
        if (p != "single" && p != "double") fail("{}: solver.precision '{}' must be single or double", r.what, p);
        c.single_precision = p == "single";
    }
    if (solver["device"]) c.device = parse_device(r.get<std::string>(solver["device"], "device", where));
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
    c.load_steps = static_cast<int>(r.integer(solver, "load_steps", where, 1));
    c.equilibrium.displacement_tolerance_mm = r.number(solver, "displacement_tolerance_mm", where, c.equilibrium.displacement_tolerance_mm);
    c.equilibrium.residual_tolerance = r.number(solver, "residual_tolerance", where, c.equilibrium.residual_tolerance);
    if (!newton && !implicit_dynamics)
        c.equilibrium.max_iterations = r.integer(solver, "max_iterations", where, c.equilibrium.max_iterations, 1, 1'000'000'000'000);
}

/// The case's constraints, forces and indenters.
void read_loads(SimulationCase& c, const YAML::Node& root, const Reader& r)
{
    std::size_t index = 0;
    for (const auto& node : r.list(root, "constraints", "the case")) {
        SimulationCase::Constraint k;
        const std::string where = fmt::format("constraints[{}]", index++);
        r.check_keys(node, {"name", "select", "fixed", "displacement_mm"}, where);
        k.name = node["name"] ? r.get<std::string>(node["name"], "name", where) : where;
        k.select = r.selection(node["select"], where);
        if (node["fixed"] && !node["fixed"].IsSequence()) fail("{}: {}.fixed must be a list of axes (x, y, z)", r.what, where);
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
    for (const auto& node : r.list(root, "forces", "the case")) {
        SimulationCase::Force f;
        const std::string where = fmt::format("forces[{}]", index++);
        r.check_keys(node, {"name", "select", "total_force_n"}, where);
        f.name = node["name"] ? r.get<std::string>(node["name"], "name", where) : where;
        f.select = r.selection(node["select"], where);
        f.total_force_n = r.vec3(node["total_force_n"], "total_force_n", where);
        c.forces.push_back(f);
    }
    index = 0;
    for (const auto& node : r.list(root, "indenters", "the case")) {
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
}

SimulationCase read_case(const fs::path& path, const Reader& r)
{
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

    if (const YAML::Node solver = r.section(root, "solver", "the case")) read_solver(c, solver, r);
    if (c.method == SimulationCase::Method::newton && c.single_precision)
        fail("{}: solver.precision single applies to relaxation and explicit; newton runs in double precision", r.what);
    check_device(c, r.what);
    c.tled.validate();
    c.equilibrium.validate();
    if (c.dynamic && !(c.duration_s > 0)) fail("{}: a dynamic run needs solver.duration_s > 0", r.what);
    if (c.load_steps < 1) fail("{}: solver.load_steps must be ≥ 1", r.what);
    if (c.time_step_s && !(*c.time_step_s > 0)) fail("{}: solver.time_step_s must be > 0", r.what);
    if (c.method == SimulationCase::Method::backward_euler) c.time_step_s.reset(); // not the explicit step
    if (!c.gravity_mm_s2.allFinite()) fail("{}: gravity_mm_s2 is not finite", r.what);

    read_loads(c, root, r);
    if (c.constraints.empty() && c.indenters.empty() && c.forces.empty() && c.gravity_mm_s2.isZero()) fail("{}: no constraints, forces or indenters: nothing to simulate", r.what);

    const YAML::Node output = r.section(root, "output", "the case");
    if (!output || !output["directory"]) fail("{}: needs output.directory", r.what);
    r.check_keys(output, {"directory", "frames", "field_spacing_mm"}, "output");
    c.output_directory = resolve(path, r.get<std::string>(output["directory"], "directory", "output"));
    c.frames = static_cast<int>(r.integer(output, "frames", "output", 1));
    if (c.frames < 1) fail("{}: output.frames must be ≥ 1", r.what);
    c.field_spacing_mm = r.number(output, "field_spacing_mm", "output", 0.0);
    if (c.field_spacing_mm < 0) fail("{}: output.field_spacing_mm must be ≥ 0", r.what);
    return c;
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

void check_device(const SimulationCase& c, const std::string& what)
{
    if (c.device == Device::cpu) return;
    const std::string device = to_string(c.device);
    if (c.method != SimulationCase::Method::explicit_dynamics)
        fail("{}: device {} runs explicit dynamics only (solver.method: explicit), not {}", what, device, to_string(c.method));
    if (c.single_precision) fail("{}: device {} runs in double precision (solver.precision: double)", what, device);
    if (!c.indenters.empty()) fail("{}: device {} does not run tools (indenters); run this case on the cpu", what, device);
    if (c.tetrahedra) fail("{}: device {} runs hexahedral meshes only (tetrahedra: false)", what, device);
}

SimulationCase read_simulation_case(const fs::path& path)
{
    const Reader r{"case '" + path.string() + "'"};
    try {
        return read_case(path, r);
    } catch (const YAML::Exception& e) {
        // A structure the checks above did not foresee (e.g. a scalar where a map belongs).
        fail("{}: line {}: unexpected structure: {}", r.what, e.mark.line + 1, e.msg);
    }
}

} // namespace physreg
