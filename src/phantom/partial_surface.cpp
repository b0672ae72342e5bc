// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/phantom/partial_surface.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/phantom/abdominal_phantom.hpp"

#include <cerrno>
#include <cstring>
#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <fstream>
#include <functional>
#include <sstream>

namespace physreg {
namespace {

Vec3 displaced(const VolumeMesh& mesh, const std::vector<double>& u, std::int32_t n)
{
    const auto q = static_cast<std::size_t>(n);
    return mesh.nodes[q] + (u.empty() ? Vec3::Zero() : Vec3(u[3 * q], u[3 * q + 1], u[3 * q + 2]));
}

} // namespace

BoundarySurface liver_boundary(const VolumeMesh& mesh, const std::function<bool(std::int32_t)>& keep,
                               std::optional<double> notch_x_mm)
{
    BoundarySurface s;
    const auto faces = match_faces(mesh);
    for (const auto& face : faces) {
        const bool inside_keep = keep(mesh.cell_labels[static_cast<std::size_t>(face.cell)]);
        const bool other_keep = face.neighbour >= 0 && keep(mesh.cell_labels[static_cast<std::size_t>(face.neighbour)]);
        if (!inside_keep || other_keep) continue;
        if (face.node_count() == 3) {
            s.triangles.push_back({face.nodes[0], face.nodes[1], face.nodes[2]});
        } else {
            s.triangles.push_back({face.nodes[0], face.nodes[1], face.nodes[2]});
            s.triangles.push_back({face.nodes[0], face.nodes[2], face.nodes[3]});
        }
    }
    // A face between a kept cell and a non-kept one is oriented from `cell`; when the kept cell is
    // the neighbour, match_faces oriented it the other way: the loop above only keeps faces whose
    // `cell` is kept, so the neighbour case needs its own pass.
    for (const auto& face : faces) {
        if (face.neighbour < 0) continue;
        const bool cell_keep = keep(mesh.cell_labels[static_cast<std::size_t>(face.cell)]);
        const bool neighbour_keep = keep(mesh.cell_labels[static_cast<std::size_t>(face.neighbour)]);
        if (cell_keep || !neighbour_keep) continue;
        if (face.node_count() == 3) {
            s.triangles.push_back({face.nodes[0], face.nodes[2], face.nodes[1]});
        } else {
            s.triangles.push_back({face.nodes[0], face.nodes[2], face.nodes[1]});
            s.triangles.push_back({face.nodes[0], face.nodes[3], face.nodes[2]});
        }
    }
    for (const auto& t : s.triangles) s.nodes.insert(s.nodes.end(), t.begin(), t.end());
    std::sort(s.nodes.begin(), s.nodes.end());
    s.nodes.erase(std::unique(s.nodes.begin(), s.nodes.end()), s.nodes.end());
    // Area-weighted vertex normals of the rest shape.
    std::vector<Vec3> normal(s.nodes.size(), Vec3::Zero());
    auto slot = [&](std::int32_t n) { return static_cast<std::size_t>(std::lower_bound(s.nodes.begin(), s.nodes.end(), n) - s.nodes.begin()); };
    for (const auto& t : s.triangles) {
        const Vec3 a = mesh.nodes[t[0]], b = mesh.nodes[t[1]], c = mesh.nodes[t[2]];
        const Vec3 area = 0.5 * (b - a).cross(c - a);
        for (const auto n : t) normal[slot(n)] += area;
    }
    const Vec3 margin_direction = Vec3(0, -1, -1).normalized();
    s.node_feature.assign(s.nodes.size(), feature_none);
    for (std::size_t q = 0; q < s.nodes.size(); ++q) {
        const Vec3 n = normal[q].normalized();
        const Vec3& p = mesh.nodes[static_cast<std::size_t>(s.nodes[q])];
        const bool margin = n.dot(margin_direction) > std::cos(35.0 * M_PI / 180.0);
        const bool inferior_or_margin = margin || n.dot(Vec3(0, 0, -1)) > 0.7 || n.dot(Vec3(0, -1, 0)) > 0.7;
        if (notch_x_mm && std::abs(p.x() - *notch_x_mm) <= 10.0 && inferior_or_margin && n.dot(margin_direction) > 0.3)
            s.node_feature[q] = feature_umbilical_notch;
        else if (margin)
            s.node_feature[q] = feature_anterior_margin;
    }
    return s;
}

LabelledPointCloud visible_surface_patch(const VolumeMesh& mesh, const std::vector<double>& displacement_mm,
                                         const BoundarySurface& boundary, double fraction, const Vec3& view,
                                         double noise_mm, std::uint64_t seed)
{
    if (!(fraction > 0.0 && fraction <= 1.0)) fail("visible surface: fraction {} outside (0, 1]", fraction);
    if (!(noise_mm >= 0.0) || !std::isfinite(noise_mm)) fail("visible surface: noise {} mm must be ≥ 0", noise_mm);
    const Vec3 v = view.normalized();
    struct Facing { std::size_t triangle; double area; Vec3 centroid; };
    std::vector<Facing> facing;
    double total = 0.0;
    Vec3 weighted = Vec3::Zero();
    for (std::size_t t = 0; t < boundary.triangles.size(); ++t) {
        const auto& tri = boundary.triangles[t];
        const Vec3 a = displaced(mesh, displacement_mm, tri[0]), b = displaced(mesh, displacement_mm, tri[1]),
                   c = displaced(mesh, displacement_mm, tri[2]);
        const Vec3 cross = (b - a).cross(c - a);
        const double area = 0.5 * cross.norm();
        if (area <= 0.0 || cross.normalized().dot(v) >= -0.2) continue;
        const Vec3 centroid = (a + b + c) / 3.0;
        facing.push_back({t, area, centroid});
        total += area;
        weighted += area * centroid;
    }
    if (facing.empty()) fail("visible surface: no part of the surface faces the camera (view {}, {}, {})", v.x(), v.y(), v.z());
    const Vec3 centre = weighted / total;
    auto planar = [&](const Vec3& p) { const Vec3 d = p - centre; return (d - d.dot(v) * v).squaredNorm(); };
    std::stable_sort(facing.begin(), facing.end(), [&](const Facing& a, const Facing& b) { return planar(a.centroid) < planar(b.centroid); });
    std::vector<std::int32_t> kept;
    double area = 0.0;
    for (const auto& f : facing) {
        if (area >= fraction * total) break;
        area += f.area;
        const auto& tri = boundary.triangles[f.triangle];
        kept.insert(kept.end(), tri.begin(), tri.end());
    }
    std::sort(kept.begin(), kept.end());
    kept.erase(std::unique(kept.begin(), kept.end()), kept.end());
    // Deformed vertex normals for the kept nodes.
    std::vector<Vec3> normal(kept.size(), Vec3::Zero());
    auto kept_slot = [&](std::int32_t n) -> long {
        const auto it = std::lower_bound(kept.begin(), kept.end(), n);
        return it != kept.end() && *it == n ? it - kept.begin() : -1;
    };
    for (const auto& tri : boundary.triangles) {
        const Vec3 a = displaced(mesh, displacement_mm, tri[0]), b = displaced(mesh, displacement_mm, tri[1]),
                   c = displaced(mesh, displacement_mm, tri[2]);
        const Vec3 cross = 0.5 * (b - a).cross(c - a);
        for (const auto n : tri)
            if (const long s = kept_slot(n); s >= 0) normal[static_cast<std::size_t>(s)] += cross;
    }
    LabelledPointCloud cloud;
    SeededRandom random(seed);
    for (std::size_t q = 0; q < kept.size(); ++q) {
        const auto slot = static_cast<std::size_t>(std::lower_bound(boundary.nodes.begin(), boundary.nodes.end(), kept[q]) - boundary.nodes.begin());
        const Vec3 noise(random.normal(), random.normal(), random.normal());
        cloud.points.push_back(displaced(mesh, displacement_mm, kept[q]) + noise_mm * noise);
        cloud.normals.push_back(normal[q].normalized());
        cloud.labels.push_back(boundary.node_feature[slot]);
    }
    return cloud;
}

LabelledPointCloud sparse_surface_cloud(const VolumeMesh& mesh, const std::vector<double>& displacement_mm, const BoundarySurface& boundary,
                                        double coverage, int count, const std::function<bool(const Vec3&)>& hidden, double noise_mm,
                                        std::uint64_t seed, double* covered)
{
    if (!(coverage > 0.0 && coverage <= 1.0)) fail("sparse surface cloud: coverage {} outside (0, 1]", coverage);
    if (count < 3) fail("sparse surface cloud: {} points; at least 3 are needed", count);
    if (!(noise_mm >= 0.0) || !std::isfinite(noise_mm)) fail("sparse surface cloud: noise {} mm must be ≥ 0", noise_mm);
    struct Candidate { std::array<Vec3, 3> corners; Vec3 normal; double area; };
    std::vector<Candidate> candidates;
    double total = 0.0;
    for (const auto& tri : boundary.triangles) {
        const std::array<Vec3, 3> x{displaced(mesh, displacement_mm, tri[0]), displaced(mesh, displacement_mm, tri[1]),
                                    displaced(mesh, displacement_mm, tri[2])};
        const Vec3 cross = (x[1] - x[0]).cross(x[2] - x[0]);
        const double area = 0.5 * cross.norm();
        if (!(area > 0.0)) continue;
        total += area;
        if (hidden && hidden((x[0] + x[1] + x[2]) / 3.0)) continue;
        candidates.push_back({x, cross.normalized(), area});
    }
    if (candidates.empty()) fail("sparse surface cloud: the whole surface is hidden");
    // The back goes first: most posterior-facing triangles dropped until `coverage` of the area is left.
    std::stable_sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) { return a.normal.y() < b.normal.y(); });
    double kept_area = 0.0;
    std::size_t kept = 0;
    while (kept < candidates.size() && kept_area + candidates[kept].area <= coverage * total + 1e-9) kept_area += candidates[kept++].area;
    if (kept == 0) fail("sparse surface cloud: coverage {} keeps no triangle", coverage);
    candidates.resize(kept);
    std::vector<double> cumulative(kept);
    double sum = 0.0;
    for (std::size_t t = 0; t < kept; ++t) cumulative[t] = (sum += candidates[t].area);
    SeededRandom random(seed);
    LabelledPointCloud cloud;
    for (int q = 0; q < count; ++q) {
        const double pick = random.uniform() * sum;
        const auto t = static_cast<std::size_t>(std::min<std::ptrdiff_t>(
            std::upper_bound(cumulative.begin(), cumulative.end(), pick) - cumulative.begin(), static_cast<std::ptrdiff_t>(kept) - 1));
        double a = random.uniform(), b = random.uniform();
        if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b; // uniform over the triangle
        const auto& c = candidates[t].corners;
        const Vec3 noise(random.normal(), random.normal(), random.normal());
        cloud.points.push_back(c[0] + a * (c[1] - c[0]) + b * (c[2] - c[0]) + noise_mm * noise);
        cloud.normals.push_back(candidates[t].normal);
        cloud.labels.push_back(feature_none);
    }
    if (covered) *covered = total > 0 ? kept_area / total : 0.0;
    return cloud;
}

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
            const Vec3 p = displaced(mesh, displacement_mm, boundary.nodes[q]);
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
