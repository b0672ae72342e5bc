// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A simulation case (what `physreg simulate CASE.yaml` runs): the model, loads, solver settings
// and outputs, read from YAML; and the run itself.
#include "physreg/image/image_geometry.hpp"
#include "physreg/mechanics/implicit/backward_euler.hpp"
#include "physreg/mechanics/implicit/newton_solver.hpp"
#include "physreg/mechanics/node_selection.hpp"
#include "physreg/mechanics/explicit/device.hpp"
#include "physreg/mechanics/explicit/tled_solver.hpp"
#include "physreg/mesh/volume_mesh.hpp"

#include <filesystem>
#include <optional>

namespace physreg {

struct SimulationCase {
    std::filesystem::path source;        ///< the case file (relative paths are resolved against it)
    std::filesystem::path mesh_file;     ///< a .vtu/.msh mesh, or ...
    std::filesystem::path labels_file;   ///< ... a label volume meshed on `grid` (or per voxel)
    std::optional<Index3> grid;
    std::filesystem::path tissues_file;  ///< empty: paper 000's default table
    bool tetrahedra = false;             ///< split hexahedra into tetrahedra

    TledOptions tled;
    std::optional<double> time_step_s;   ///< explicit step; refused above the critical step
    bool single_precision = false;
    /// Where explicit dynamics runs (`solver.device`, or `simulate --device`): the GPU path runs
    /// explicit dynamics of hexahedra in double precision without tools (gpu_tled.hpp).
    Device device = Device::cpu;
    /// How the case is solved: static equilibrium by dynamic relaxation or by Newton's method, or
    /// dynamics for duration_s, explicit (central differences) or implicit (backward Euler)
    /// (`solver.method`; the older `solver.mode` static/dynamic means relaxation/explicit).
    enum class Method { relaxation, newton, explicit_dynamics, backward_euler };
    Method method = Method::relaxation;
    bool dynamic = false;                ///< explicit_dynamics or backward_euler
    NewtonOptions newton;
    BackwardEulerOptions backward_euler; ///< its time_step_s is solver.time_step_s
    Vec3 gravity_mm_s2 = Vec3::Zero();   ///< body acceleration: nodal forces lumped mass × g (× load factor)
    double duration_s = 0.0;
    int load_steps = 1;                  ///< static: equilibria at 1/n, 2/n, …, 1 of the load
    EquilibriumOptions equilibrium;

    struct Constraint {
        std::string name;
        NodeSelection select;
        std::array<bool, 3> dofs{true, true, true};
        Vec3 displacement_mm = Vec3::Zero();
    };
    struct Force {
        std::string name;
        NodeSelection select;
        Vec3 total_force_n = Vec3::Zero(); ///< shared equally by the selected nodes
    };
    std::vector<Constraint> constraints;
    std::vector<Force> forces;
    std::vector<Indenter> indenters;
    double ramp_time_s = 0.0;

    std::filesystem::path output_directory;
    int frames = 1;                        ///< VTU frames written (dynamic: evenly in time)
    double field_spacing_mm = 0.0;         ///< dense field spacing; 0: the label volume's grid, else 2 mm
};

/// Reads and validates a case file. Throws Error naming the key and the reason.
SimulationCase read_simulation_case(const std::filesystem::path& path);
/// Throws Error (naming `what`) when the case asks a device for what it cannot run.
void check_device(const SimulationCase& c, const std::string& what);
std::string to_string(SimulationCase::Method method); ///< relaxation | newton | explicit

struct SimulationFrame {
    double time_s = 0.0;       ///< dynamic runs
    double load_factor = 0.0;
    std::vector<double> displacement_mm;
};

struct SimulationResult {
    VolumeMesh mesh;
    std::vector<SimulationFrame> frames;   ///< the last is the final state
    std::vector<SolveSummary> equilibria;  ///< relaxation: one per load step
    std::vector<NewtonSummary> newton_solves; ///< newton: one per load step
    struct BackwardEulerTotals {
        long newton_iterations = 0, factorisations = 0, shifted_factorisations = 0, unconverged_fixed_steps = 0;
        double worst_relative_residual = 0.0;  ///< largest ‖r‖∞ / reference force at the end of a step
        std::int64_t most_inverted_elements = 0; ///< co-rotational law: elements with det F ≤ 0 in one step
        double force_s = 0, assembly_s = 0, factorisation_s = 0, solve_s = 0;
    };
    std::optional<BackwardEulerTotals> backward_euler;
    double critical_time_step_s = 0.0;
    double time_step_s = 0.0;
    long steps = 0;
    double seconds = 0.0;
    std::optional<ImageGeometry> label_geometry; ///< when the case meshed a label volume
};

/// Runs the case. `progress(fraction, message)` is called along the way. Throws Error for bad
/// input, inverted elements or divergence; a static load step that does not converge is an Error.
SimulationResult run_simulation(const SimulationCase& c, const std::function<void(double, const std::string&)>& progress);

} // namespace physreg
