// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A bridge to CalculiX (ccx, Debian calculix-ccx), the independent nonlinear FE solver physreg checks
// its own implicit solver against: the same nodes, elements, tissues and law, prescribed nodal
// displacements, a static NLGEOM step. Used by the tests and by `physreg phantom`, which validates
// its ground-truth discretisation on a small case and writes the figure into the manifest.
#include "physreg/model/loads.hpp"
#include "physreg/mechanics/materials/material.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/model/tissue_table.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace physreg {

/// True when `ccx` is on the PATH.
bool calculix_available();

struct CalculixRun {
    /// Element type: "" picks C3D4 for tetrahedra, C3D8I for hexahedra; C3D8R, C3D8 are accepted.
    std::string element;
    double initial_increment = 0.25; ///< fraction of the step
    int threads = 1;
};

/// Writes `directory`/`job`.inp, runs ccx there and returns its nodal displacements (mm, 3 per node)
/// of the last increment. Laws: neo-hookean (*HYPERELASTIC, NEO HOOKE: C10 = μ/2, D1 = 2/κ) and
/// mooney-rivlin (C10, C01, D1), one material per tissue. Only constraints (no tools, no forces).
/// Throws Error naming the job and its log for a ccx failure or a missing displacement table.
std::vector<double> solve_with_calculix(const VolumeMesh& mesh, const TissueTable& tissues, MaterialLaw law, const Loads& loads,
                                        const std::filesystem::path& directory, const std::string& job, const CalculixRun& run = {});

/// RMS over the nodes of |a − b|, divided by the largest |b| (the reference's peak displacement).
double relative_rms_difference(const std::vector<double>& a, const std::vector<double>& b);

} // namespace physreg
