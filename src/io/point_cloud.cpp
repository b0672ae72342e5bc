// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/point_cloud.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/io/surface_io.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

namespace physreg {

void write_point_cloud_ply(const std::filesystem::path& path, const LabelledPointCloud& cloud)
{
    write_atomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp);
        out << "ply\nformat ascii 1.0\ncomment physreg intra-operative point cloud, mm, LPS; label 0 surface, "
               "1 umbilical notch, 2 anterior margin\n";
        out << "element vertex " << cloud.points.size()
            << "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
               "property int label\nend_header\n";
        for (std::size_t q = 0; q < cloud.points.size(); ++q)
            out << fmt::format("{:.4f} {:.4f} {:.4f} {:.5f} {:.5f} {:.5f} {}\n", cloud.points[q].x(), cloud.points[q].y(),
                               cloud.points[q].z(), cloud.normals[q].x(), cloud.normals[q].y(), cloud.normals[q].z(), cloud.labels[q]);
        if (!out) fail("cannot write '{}': {}", path.string(), std::strerror(errno));
    });
}

void write_point_cloud_csv(const std::filesystem::path& path, const LabelledPointCloud& cloud)
{
    write_atomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp);
        out << "# physreg intra-operative point cloud; coordinate_system = LPS; units = mm\n"
               "# label: 0 surface, 1 umbilical notch, 2 anterior margin\nx,y,z,label\n";
        for (std::size_t q = 0; q < cloud.points.size(); ++q)
            out << fmt::format("{:.4f},{:.4f},{:.4f},{}\n", cloud.points[q].x(), cloud.points[q].y(), cloud.points[q].z(), cloud.labels[q]);
        if (!out) fail("cannot write '{}': {}", path.string(), std::strerror(errno));
    });
}

LabelledPointCloud read_point_cloud_csv(const std::filesystem::path& path)
{
    const std::string what = "point cloud '" + path.string() + "'";
    require_existing_file(path, what);
    std::ifstream in(path);
    if (!in) fail("{}: cannot open file", what);
    LabelledPointCloud cloud;
    std::string line;
    int line_number = 0;
    bool first = true;
    std::size_t columns = 0; // 3: x,y,z (every point a plain surface point, label 0); 4: x,y,z,label
    auto split = [](const std::string& text) {
        std::vector<std::string> items;
        std::stringstream fields(text);
        std::string item;
        while (std::getline(fields, item, ',')) {
            const auto b = item.find_first_not_of(" \t\r"), e = item.find_last_not_of(" \t\r");
            items.push_back(b == std::string::npos ? "" : item.substr(b, e - b + 1));
        }
        return items;
    };
    while (std::getline(in, line)) {
        ++line_number;
        if (line.empty() || line[0] == '#' || line.find_first_not_of(" \t\r") == std::string::npos) continue;
        auto items = split(line);
        if (first) {
            first = false;
            // A header as users write it (x,y,z or x,y,z,label, any case), or none: numbers from the start.
            std::string lower = line;
            for (auto& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
            const auto names = split(lower);
            if (names == std::vector<std::string>{"x", "y", "z"} || names == std::vector<std::string>{"x", "y", "z", "label"}) {
                columns = names.size();
                continue;
            }
            if (!parse_number(items.front()))
                fail("{}: line {}: the header must name the columns x,y,z or x,y,z,label (got '{}')", what, line_number, line);
            columns = items.size();
            if (columns != 3 && columns != 4) fail("{}: line {}: {} values; expected x,y,z or x,y,z,label", what, line_number, columns);
        }
        std::vector<double> values;
        for (const auto& item : items) {
            const auto value = parse_number(item);
            if (!value) fail("{}: line {}: '{}' is not a number", what, line_number, item);
            values.push_back(*value);
        }
        if (values.size() != columns || !std::isfinite(values[0]) || !std::isfinite(values[1]) || !std::isfinite(values[2]))
            fail("{}: line {}: expected {} finite values ({})", what, line_number, columns, columns == 3 ? "x,y,z" : "x,y,z,label");
        cloud.points.emplace_back(values[0], values[1], values[2]);
        cloud.normals.push_back(Vec3::Zero());
        cloud.labels.push_back(columns == 4 ? to_integer<std::int32_t>(values[3], what, "a point label") : 0);
    }
    if (cloud.points.empty()) fail("{}: no points (empty or truncated file)", what);
    return cloud;
}

void write_boundary_ply(const std::filesystem::path& path, const VolumeMesh& mesh, const std::vector<double>& displacement_mm,
                        const BoundarySurface& boundary)
{
    write_atomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp);
        out << "ply\nformat ascii 1.0\ncomment physreg liver boundary, mm, LPS; feature 0 surface, 1 umbilical notch, "
               "2 anterior margin\n";
        out << "element vertex " << boundary.nodes.size()
            << "\nproperty float x\nproperty float y\nproperty float z\nproperty int feature\n";
        out << "element face " << boundary.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
        for (std::size_t q = 0; q < boundary.nodes.size(); ++q) {
            const Vec3 p = displaced_position(mesh, displacement_mm, boundary.nodes[q]);
            out << fmt::format("{:.4f} {:.4f} {:.4f} {}\n", p.x(), p.y(), p.z(), boundary.node_feature[q]);
        }
        auto slot = [&](std::int32_t n) { return std::lower_bound(boundary.nodes.begin(), boundary.nodes.end(), n) - boundary.nodes.begin(); };
        for (const auto& t : boundary.triangles) out << "3 " << slot(t[0]) << ' ' << slot(t[1]) << ' ' << slot(t[2]) << '\n';
        if (!out) fail("cannot write '{}': {}", path.string(), std::strerror(errno));
    });
}

LabelledPointCloud read_point_cloud(const std::filesystem::path& path)
{
    const std::string ext = path.extension().string();
    LabelledPointCloud cloud;
    if (ext == ".csv") {
        cloud = read_point_cloud_csv(path);
    } else if (ext == ".ply" || ext == ".vtk") {
        const SurfaceMesh points = read_point_set(path);
        cloud.points = points.vertices;
        cloud.normals = points.vertex_normals;
        for (const auto& n : cloud.normals)
            if (!n.allFinite()) fail("point cloud '{}': a normal is not finite", path.string());
        cloud.labels = points.vertex_labels.empty() ? std::vector<std::int32_t>(points.vertices.size(), feature_none) : points.vertex_labels;
    } else {
        fail("point cloud '{}': unknown extension '{}' (use .ply, .vtk or .csv)", path.string(), ext);
    }
    if (cloud.points.empty()) fail("point cloud '{}': no points", path.string());
    return cloud;
}

} // namespace physreg
