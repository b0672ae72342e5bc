// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/vessel_centrelines.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

namespace physreg {

namespace {

double finite_number(const std::string& text, const std::string& what, int line)
{
    const auto v = parse_number(text);
    if (!v || !std::isfinite(*v)) fail("{}: line {}: '{}' is not a finite number", what, line, text);
    return *v;
}

} // namespace

std::vector<VesselBranch> read_vessel_centrelines(const std::filesystem::path& path, double scale, double default_radius_mm)
{
    const std::string what = "vessel centrelines '" + path.string() + "'";
    if (!(scale > 0 && std::isfinite(scale))) fail("{}: scale {} must be > 0", what, scale);
    if (!(default_radius_mm > 0)) fail("{}: default radius {} mm must be > 0", what, default_radius_mm);
    require_existing_file(path, what);
    std::ifstream in(path);
    if (!in) fail("{}: cannot open file", what);
    std::vector<VesselBranch> branches;
    const bool csv = path.extension() == ".csv";
    std::string line, current_id;
    bool header = false;
    int number = 0;
    VesselBranch branch;
    const auto close = [&] {
        if (branch.points.empty()) return;
        if (branch.points.size() < 2) fail("{}: a branch ending at line {} has a single point", what, number);
        branches.push_back(branch);
        branch = {};
    };
    while (std::getline(in, line)) {
        ++number;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (!line.empty() && line[0] == '#') continue;
        if (csv) {
            if (line.empty()) continue;
            if (!header) {
                if (line != "branch,x,y,z,radius") fail("{}: line {}: expected the header 'branch,x,y,z,radius'", what, number);
                header = true;
                continue;
            }
            std::vector<std::string> items;
            std::stringstream s(line);
            for (std::string item; std::getline(s, item, ',');) items.push_back(item);
            if (items.size() != 5) fail("{}: line {}: expected 5 values branch,x,y,z,radius", what, number);
            if (items[0] != current_id) close(), current_id = items[0];
            branch.points.emplace_back(scale * finite_number(items[1], what, number), scale * finite_number(items[2], what, number),
                                       scale * finite_number(items[3], what, number));
            const double r = scale * finite_number(items[4], what, number);
            if (!(r > 0)) fail("{}: line {}: radius {} must be > 0", what, number, r);
            branch.radii_mm.push_back(r);
        } else {
            std::stringstream s(line);
            std::vector<std::string> items;
            for (std::string item; s >> item;) items.push_back(item);
            if (items.empty()) {
                close();
                continue;
            }
            if (items.size() != 3) fail("{}: line {}: expected 'x y z'", what, number);
            branch.points.emplace_back(scale * finite_number(items[0], what, number), scale * finite_number(items[1], what, number),
                                       scale * finite_number(items[2], what, number));
            branch.radii_mm.push_back(default_radius_mm);
        }
    }
    close();
    if (branches.empty()) fail("{}: no branch", what);
    return branches;
}

void write_vessel_centrelines(const std::filesystem::path& path, const std::vector<VesselBranch>& branches)
{
    write_atomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp);
        out << "# physreg vessel centrelines; coordinate_system = LPS; units = mm\nbranch,x,y,z,radius\n";
        for (std::size_t b = 0; b < branches.size(); ++b)
            for (std::size_t i = 0; i < branches[b].points.size(); ++i) {
                const Vec3& p = branches[b].points[i];
                out << b << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << branches[b].radii_mm[i] << '\n';
            }
        out.close();
        if (!out) fail("vessel centrelines '{}': write failed", path.string());
    });
}

} // namespace physreg
