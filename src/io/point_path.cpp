// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/point_path.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace physreg {

std::vector<Vec3> parse_point_path(const std::string& text, const std::string& what)
{
    std::vector<Vec3> path;
    std::stringstream points(text);
    std::string point;
    while (std::getline(points, point, ';')) {
        std::stringstream values(point);
        std::string v;
        std::vector<double> xyz;
        while (std::getline(values, v, ',')) {
            double value = 0.0;
            try {
                std::size_t used = 0;
                value = std::stod(v, &used);
                while (used < v.size() && std::isspace(static_cast<unsigned char>(v[used]))) ++used;
                if (used != v.size()) throw std::invalid_argument(v);
            } catch (const std::exception&) {
                fail("{} '{}': '{}' is not a number", what, text, v);
            }
            xyz.push_back(value);
        }
        if (xyz.size() != 3) fail("{} '{}': each point is x,y,z in mm (got '{}')", what, text, point);
        const Vec3 p(xyz[0], xyz[1], xyz[2]);
        if (!p.allFinite()) fail("{} '{}': a coordinate is not finite", what, text);
        path.push_back(p);
    }
    if (path.empty()) fail("{} '{}': no point", what, text);
    return path;
}

double distance_to_path(const Vec3& x, const std::vector<Vec3>& path)
{
    if (path.empty()) return std::numeric_limits<double>::infinity();
    double best = (x - path.front()).norm();
    for (std::size_t k = 1; k < path.size(); ++k) {
        const Vec3 a = path[k - 1], ab = path[k] - a;
        const double len2 = ab.squaredNorm();
        const double t = len2 > 0 ? std::clamp((x - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
        best = std::min(best, (x - (a + t * ab)).norm());
    }
    return best;
}

} // namespace physreg
