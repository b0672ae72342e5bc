// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/simulation/calculix.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/subprocess.hpp"

#include <cerrno>
#include <cstring>
#include <fmt/format.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace physreg {

bool calculix_available()
{
    return run_shell_command("command -v ccx > /dev/null 2>&1") == 0;
}

namespace {

// The displacements of the last increment in ccx's .dat file (*NODE PRINT U), 3 per node.
std::vector<double> read_ccx_displacements(const std::filesystem::path& dat, std::size_t nodes)
{
    std::ifstream in(dat);
    std::vector<std::string> lines;
    for (std::string line; std::getline(in, line);) lines.push_back(line);
    std::size_t last = lines.size();
    for (std::size_t k = 0; k < lines.size(); ++k)
        if (lines[k].find("displacements (vx,vy,vz)") != std::string::npos) last = k;
    if (last == lines.size()) return {};
    std::vector<double> u(3 * nodes, std::nan(""));
    for (std::size_t k = last + 1; k < lines.size(); ++k) {
        std::istringstream row(lines[k]);
        std::size_t id;
        double x, y, z;
        if (!(row >> id >> x >> y >> z)) continue; // blank lines around the table
        if (id >= 1 && id <= nodes) u[3 * (id - 1)] = x, u[3 * (id - 1) + 1] = y, u[3 * (id - 1) + 2] = z;
    }
    return u;
}

} // namespace

std::vector<double> solve_with_calculix(const VolumeMesh& mesh, const TissueTable& tissues, MaterialLaw law, const Loads& loads,
                                        const std::filesystem::path& directory, const std::string& job, const CalculixRun& run)
{
    if (law != MaterialLaw::neo_hookean && law != MaterialLaw::mooney_rivlin)
        fail("CalculiX job '{}': law {} has no CalculiX counterpart here (neo-hookean, mooney-rivlin)", job, to_string(law));
    if (!loads.indenters.empty() || !loads.external_forces_n.empty())
        fail("CalculiX job '{}': only prescribed displacements are translated (no tools, no forces)", job);
    mesh.validate("CalculiX job '" + job + "'");
    tissues.validate("CalculiX job '" + job + "'");
    const std::string element = !run.element.empty() ? run.element : mesh.cell_type == CellType::tetrahedron ? "C3D4" : "C3D8I";
    const std::filesystem::path inp_path = directory / (job + ".inp");
    {
        std::ofstream inp(inp_path);
        inp << "*NODE, NSET=Nall\n";
        for (std::size_t i = 0; i < mesh.node_count(); ++i)
            // CalculiX reads fields of at most 20 characters: 13 significant digits fit.
            inp << fmt::format("{}, {:.13g}, {:.13g}, {:.13g}\n", i + 1, mesh.nodes[i].x(), mesh.nodes[i].y(), mesh.nodes[i].z());
        for (const auto& tissue : tissues.tissues) {
            bool any = false;
            for (std::size_t e = 0; e < mesh.cell_count(); ++e) {
                if (mesh.cell_labels[e] != tissue.label) continue;
                if (!any) inp << "*ELEMENT, TYPE=" << element << ", ELSET=T" << tissue.label << "\n";
                any = true;
                inp << e + 1;
                for (auto id : mesh.cell(e)) inp << ", " << id + 1;
                inp << "\n";
            }
            if (!any) continue;
            const ElasticMaterial m = material_from_tissue(tissue);
            inp << "*MATERIAL, NAME=M" << tissue.label << "\n";
            if (law == MaterialLaw::neo_hookean)
                inp << fmt::format("*HYPERELASTIC, NEO HOOKE\n{:.13g}, {:.13g}\n", m.mu_mpa / 2, 2 / m.kappa_mpa);
            else
                inp << fmt::format("*HYPERELASTIC, MOONEY-RIVLIN\n{:.13g}, {:.13g}, {:.13g}\n", m.mu_mpa / 2 - m.c01_mpa, m.c01_mpa, 2 / m.kappa_mpa);
            inp << "*SOLID SECTION, ELSET=T" << tissue.label << ", MATERIAL=M" << tissue.label << "\n";
        }
        for (std::size_t e = 0; e < mesh.cell_count(); ++e)
            if (!tissues.find(mesh.cell_labels[e])) fail("CalculiX job '{}': element {} has label {} with no tissue", job, e, mesh.cell_labels[e]);
        for (std::size_t c = 0; c < loads.constraints.size(); ++c) {
            inp << "*NSET, NSET=C" << c << "\n";
            for (auto id : loads.constraints[c].nodes) inp << id + 1 << "\n";
        }
        inp << "*STEP, NLGEOM, INC=1000\n*STATIC\n" << run.initial_increment << ", 1.0\n*BOUNDARY\n";
        for (std::size_t c = 0; c < loads.constraints.size(); ++c)
            for (int k = 0; k < 3; ++k)
                if (loads.constraints[c].dofs[static_cast<std::size_t>(k)])
                    inp << fmt::format("C{}, {}, {}, {:.13g}\n", c, k + 1, k + 1, loads.constraints[c].displacement_mm[k]);
        inp << "*NODE PRINT, NSET=Nall\nU\n*END STEP\n";
        if (!inp) fail("CalculiX job '{}': cannot write {}: {}", job, inp_path.string(), std::strerror(errno));
    }
    const std::filesystem::path log = directory / (job + ".log");
    const std::string command = fmt::format("cd '{}' && OMP_NUM_THREADS={} ccx -i {} > {} 2>&1", directory.string(), run.threads, job,
                                            log.filename().string());
    if (run_shell_command(command) != 0) {
        // The log's last lines say why (the folder may be a scratch one that disappears).
        std::ifstream in(log);
        std::vector<std::string> lines;
        for (std::string line; std::getline(in, line);)
            if (!line.empty()) lines.push_back(line);
        const std::size_t from = lines.size() > 6 ? lines.size() - 6 : 0;
        std::string tail;
        for (std::size_t k = from; k < lines.size(); ++k) tail += "\n  " + lines[k];
        fail("CalculiX job '{}' failed ({}); its log ends:{}", job, log.string(), tail);
    }
    auto u = read_ccx_displacements(directory / (job + ".dat"), mesh.node_count());
    if (u.size() != 3 * mesh.node_count()) fail("CalculiX job '{}': no displacement table in its .dat file; see {}", job, log.string());
    for (std::size_t i = 0; i < u.size(); ++i)
        if (!std::isfinite(u[i])) fail("CalculiX job '{}': node {} missing from its output", job, i / 3 + 1);
    return u;
}

double relative_rms_difference(const std::vector<double>& a, const std::vector<double>& b)
{
    if (a.size() != b.size() || a.empty()) fail("relative RMS difference: fields of {} and {} values", a.size(), b.size());
    double peak = 0, sum = 0;
    const std::size_t nodes = a.size() / 3;
    for (std::size_t i = 0; i < nodes; ++i) {
        double d2 = 0, b2 = 0;
        for (int k = 0; k < 3; ++k) d2 += (a[3 * i + k] - b[3 * i + k]) * (a[3 * i + k] - b[3 * i + k]), b2 += b[3 * i + k] * b[3 * i + k];
        sum += d2;
        peak = std::max(peak, std::sqrt(b2));
    }
    if (!(peak > 0)) fail("relative RMS difference: the reference field is zero");
    return std::sqrt(sum / static_cast<double>(nodes)) / peak;
}

} // namespace physreg
