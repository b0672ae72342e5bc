// SPDX-License-Identifier: GPL-3.0-or-later
// Newton on the TLED discretisation against an independent solver: CalculiX (ccx, Debian
// calculix-ccx), same mesh, C3D8I (incompatible modes) and C3D8R (reduced integration with
// CalculiX's own hourglass control) elements, NLGEOM, its Neo-Hookean law (C10 = μ/2, D1 = 2/κ:
// the same decoupled energy as ours).
// A block on a fixed base is indented by a frictionless flat punch (the top nodes of a central
// patch pushed down, free to slide). Skips when ccx is not installed.
#include "mechanics_fixtures.hpp"
#include "physreg/mechanics/simulation/calculix.hpp"
#include "physreg/mechanics/implicit/newton_solver.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>

namespace physreg {
using namespace test;

TEST(MechanicsCalculix, IndentedBlockMatchesCalculix)
{
    if (!calculix_available()) PHYSREG_MISSING_FIXTURE("ccx (Debian calculix-ccx) is not installed");
    const int n = 12, nz = 6;
    const double depth = 0.6; // mm, 10 % of the thickness
    const VolumeMesh mesh = block_mesh(n, n, nz, 1.0);
    const TissueTable tissues = one_tissue(1e5, 0.45);
    std::vector<std::int32_t> base, punch;
    for (std::size_t i = 0; i < mesh.node_count(); ++i) {
        const Vec3& p = mesh.nodes[i];
        if (p.z() < 1e-9) base.push_back(static_cast<std::int32_t>(i));
        if (std::abs(p.z() - 6.0) < 1e-9 && std::abs(p.x() - 6.0) <= 2.0 + 1e-9 && std::abs(p.y() - 6.0) <= 2.0 + 1e-9)
            punch.push_back(static_cast<std::int32_t>(i));
    }
    ASSERT_EQ(punch.size(), 25u);

    // physreg: Newton on the TLED model (uniform-strain hexahedra with hourglass control).
    const TledModel model(mesh, tissues, {});
    NewtonOptions options;
    options.residual_tolerance = 1e-9;
    NewtonSolver solver(model, options);
    Loads loads;
    loads.constraints.push_back({"base", base, {true, true, true}, Vec3::Zero()});
    loads.constraints.push_back({"punch", punch, {false, false, true}, Vec3(0, 0, -depth)});
    solver.set_loads(loads);
    ASSERT_TRUE(solver.solve_equilibrium(1.0).converged);
    const auto ours = solver.displacement_mm();

    // CalculiX on the same nodes and elements (VTK's hexahedron order is Abaqus's C3D8 order).
    TempDir dir;
    // RMS over the nodes of the difference, as a fraction of ccx's peak displacement.
    const auto compare = [&](const std::string& element) {
        CalculixRun run;
        run.element = element;
        const auto theirs = solve_with_calculix(mesh, tissues, MaterialLaw::neo_hookean, loads, dir.path(), "block_" + element, run);
        const double relative = relative_rms_difference(ours, theirs);
        std::cout << "physreg Newton vs CalculiX " << element << " (NLGEOM, Neo-Hookean), " << mesh.cell_count() << " hexahedra, punch "
                  << depth << " mm: RMS difference " << 100 * relative << " % of ccx's peak displacement\n";
        return relative;
    };
    // Incompatible-mode hexahedra (no hourglass modes, no locking): the closest reference.
    EXPECT_LT(compare("C3D8I"), 0.01);
    // C3D8R: reduced integration as ours but with CalculiX's own, softer hourglass control (its
    // punch-edge nodes overshoot the punch depth by 5 %): 3.1 % here, 1.2 % on the mesh refined 2×.
    EXPECT_LT(compare("C3D8R"), 0.04);
}

} // namespace physreg
