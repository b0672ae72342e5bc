// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/surface_io.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"

#include <limits>
#include <cmath>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

namespace physreg {
namespace fs = std::filesystem;
namespace {

// STL stores unindexed triangles: identical coordinates become one vertex again.
struct Welder {
    SurfaceMesh& mesh;
    std::map<std::array<double, 3>, std::int32_t> index;
    std::int32_t add(const Vec3& p)
    {
        auto [it, inserted] = index.try_emplace({p[0], p[1], p[2]}, static_cast<std::int32_t>(mesh.vertices.size()));
        if (inserted) mesh.vertices.push_back(p);
        return it->second;
    }
};

SurfaceMesh read_stl(const fs::path& path, const std::string& what)
{
    std::ifstream in(path, std::ios::binary);
    std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    SurfaceMesh mesh;
    Welder welder{mesh, {}};
    std::uint32_t count = 0;
    if (content.size() >= 84) std::memcpy(&count, content.data() + 80, 4);
    const bool binary = content.size() >= 84 && content.size() == 84 + 50ull * count;
    if (binary) {
        for (std::uint32_t t = 0; t < count; ++t) {
            const char* p = content.data() + 84 + 50ull * t + 12;
            std::array<std::int32_t, 3> tri{};
            for (int v = 0; v < 3; ++v) {
                float xyz[3];
                std::memcpy(xyz, p + 12 * v, 12);
                tri[v] = welder.add(Vec3(xyz[0], xyz[1], xyz[2]));
            }
            mesh.triangles.push_back(tri);
        }
    } else {
        if (content.rfind("solid", 0) != 0)
            fail("{}: neither ascii STL (no 'solid') nor binary STL (size {} bytes does not match {} triangles)", what,
                 content.size(), count);
        std::istringstream s(content);
        std::string word;
        std::vector<std::int32_t> loop;
        while (s >> word) {
            if (word == "vertex") {
                Vec3 p;
                if (!(s >> p[0] >> p[1] >> p[2])) fail("{}: corrupt vertex line", what);
                loop.push_back(welder.add(p));
            } else if (word == "endloop") {
                if (loop.size() != 3) fail("{}: facet with {} vertices", what, loop.size());
                mesh.triangles.push_back({loop[0], loop[1], loop[2]});
                loop.clear();
            }
        }
        if (content.find("endsolid") == std::string::npos) fail("{}: truncated ascii STL (no 'endsolid')", what);
    }
    return mesh;
}

void write_stl(std::ofstream& out, const SurfaceMesh& mesh)
{
    char header[80] = "physreg surface, coordinates in mm (LPS)";
    out.write(header, 80);
    const auto count = static_cast<std::uint32_t>(mesh.triangles.size());
    out.write(reinterpret_cast<const char*>(&count), 4);
    for (const auto& t : mesh.triangles) {
        const Vec3 n = (mesh.vertices[t[1]] - mesh.vertices[t[0]]).cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]).normalized();
        float buffer[12] = {float(n[0]), float(n[1]), float(n[2])};
        for (int v = 0; v < 3; ++v)
            for (int a = 0; a < 3; ++a) buffer[3 + 3 * v + a] = static_cast<float>(mesh.vertices[t[v]][a]);
        out.write(reinterpret_cast<const char*>(buffer), 48);
        const std::uint16_t attribute = 0;
        out.write(reinterpret_cast<const char*>(&attribute), 2);
    }
}

struct PlyProperty {
    std::string name, type, list_count_type;
    bool list = false;
};
struct PlyElement {
    std::string name;
    std::size_t count = 0;
    std::vector<PlyProperty> properties;
};

int ply_size(const std::string& type)
{
    if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
    if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
    if (type == "int" || type == "uint" || type == "float" || type == "int32" || type == "uint32" || type == "float32") return 4;
    if (type == "double" || type == "float64") return 8;
    return 0;
}

double ply_value(std::istream& in, const std::string& type, bool binary, const std::string& what)
{
    if (!binary) {
        double v;
        if (!(in >> v)) fail("{}: truncated or corrupt ascii PLY data", what);
        return v;
    }
    char b[8];
    const int size = ply_size(type);
    if (!in.read(b, size)) fail("{}: truncated binary PLY data", what);
    auto get = [&b]<typename T>(T) {
        T v;
        std::memcpy(&v, b, sizeof(T));
        return static_cast<double>(v);
    };
    if (type == "char" || type == "int8") return get(std::int8_t{});
    if (type == "uchar" || type == "uint8") return get(std::uint8_t{});
    if (type == "short" || type == "int16") return get(std::int16_t{});
    if (type == "ushort" || type == "uint16") return get(std::uint16_t{});
    if (type == "int" || type == "int32") return get(std::int32_t{});
    if (type == "uint" || type == "uint32") return get(std::uint32_t{});
    if (type == "float" || type == "float32") return get(float{});
    return get(double{});
}

SurfaceMesh read_ply(const fs::path& path, const std::string& what)
{
    const auto file_bytes = static_cast<std::uint64_t>(fs::file_size(path));
    std::ifstream in(path, std::ios::binary);
    std::string line;
    std::getline(in, line);
    if (line.rfind("ply", 0) != 0) fail("{}: not a PLY file", what);
    bool binary = false;
    std::vector<PlyElement> elements;
    while (std::getline(in, line)) {
        if (!line.empty() && line.back() == '\r') line.pop_back();
        std::istringstream s(line);
        std::string key;
        s >> key;
        if (key == "format") {
            std::string format;
            s >> format;
            if (format == "binary_little_endian") binary = true;
            else if (format != "ascii") fail("{}: PLY format '{}' is not supported", what, format);
        } else if (key == "element") {
            PlyElement e;
            std::string count_text;
            s >> e.name >> count_text;
            std::size_t used = 0;
            try {
                e.count = std::stoull(count_text, &used);
            } catch (const std::logic_error&) {
                used = 0;
            }
            // Each element takes at least one byte of the file: a larger count is corrupt (and
            // would loop for hours over elements without properties).
            if (used == 0 || used != count_text.size() || count_text[0] == '-' || e.count > file_bytes)
                fail("{}: element '{}' has a bad count '{}' for a {}-byte file", what, e.name, count_text, file_bytes);
            elements.push_back(e);
        } else if (key == "property") {
            if (elements.empty()) fail("{}: property before element", what);
            PlyProperty p;
            std::string type;
            s >> type;
            if (type == "list") {
                p.list = true;
                s >> p.list_count_type >> p.type >> p.name;
            } else {
                p.type = type;
                s >> p.name;
            }
            if (!ply_size(p.type)) fail("{}: unknown PLY type '{}'", what, p.type);
            if (p.list && !ply_size(p.list_count_type)) fail("{}: unknown PLY list count type '{}'", what, p.list_count_type);
            elements.back().properties.push_back(p);
        } else if (key == "end_header") {
            break;
        }
    }
    if (!in) fail("{}: truncated PLY header", what);
    SurfaceMesh mesh;
    bool has_vertex_normals = false, has_vertex_labels = false;
    for (const auto& e : elements)
        if (e.name == "vertex")
            for (const auto& prop : e.properties) {
                has_vertex_normals = has_vertex_normals || prop.name == "nx";
                has_vertex_labels = has_vertex_labels || prop.name == "label" || prop.name == "feature";
            }
    for (const auto& e : elements) {
        for (std::size_t i = 0; i < e.count; ++i) {
            Vec3 p = Vec3::Zero(), normal = Vec3::Zero();
            std::int32_t vertex_label = 0;
            std::array<std::int32_t, 2> label{0, 0};
            bool has_label = false;
            std::vector<std::int32_t> polygon;
            for (const auto& prop : e.properties) {
                if (prop.list) {
                    const auto n = to_integer<std::uint32_t>(ply_value(in, prop.list_count_type, binary, what), what, "a list length");
                    if (n > file_bytes) fail("{}: a list of {} values in a {}-byte file (corrupt)", what, n, file_bytes);
                    for (std::size_t k = 0; k < n; ++k) polygon.push_back(to_integer<std::int32_t>(ply_value(in, prop.type, binary, what), what, "a vertex index"));
                    continue;
                }
                const double v = ply_value(in, prop.type, binary, what);
                if (e.name == "vertex") {
                    if (prop.name == "x") p[0] = v;
                    if (prop.name == "y") p[1] = v;
                    if (prop.name == "z") p[2] = v;
                    if (prop.name == "nx") normal[0] = v;
                    if (prop.name == "ny") normal[1] = v;
                    if (prop.name == "nz") normal[2] = v;
                    if (prop.name == "label" || prop.name == "feature") vertex_label = to_integer<std::int32_t>(v, what, "a vertex label");
                } else if (prop.name == "inside_label") {
                    label[0] = to_integer<std::int32_t>(v, what, "a face label");
                    has_label = true;
                } else if (prop.name == "outside_label") {
                    label[1] = to_integer<std::int32_t>(v, what, "a face label");
                    has_label = true;
                }
            }
            if (e.name == "vertex") {
                mesh.vertices.push_back(p);
                if (has_vertex_normals) mesh.vertex_normals.push_back(normal);
                if (has_vertex_labels) mesh.vertex_labels.push_back(vertex_label);
            }
            if (e.name == "face") {
                if (polygon.size() < 3) fail("{}: face {} has {} vertices", what, i, polygon.size());
                for (std::size_t k = 1; k + 1 < polygon.size(); ++k) {
                    mesh.triangles.push_back({polygon[0], polygon[k], polygon[k + 1]});
                    if (has_label) mesh.labels.push_back(label);
                }
            }
        }
    }
    return mesh;
}

void write_ply(std::ofstream& out, const SurfaceMesh& mesh)
{
    const bool labelled = !mesh.labels.empty();
    out << "ply\nformat binary_little_endian 1.0\ncomment physreg surface, coordinates in mm (LPS)\n"
        << "element vertex " << mesh.vertices.size() << "\nproperty double x\nproperty double y\nproperty double z\n"
        << "element face " << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\n";
    if (labelled) out << "property int inside_label\nproperty int outside_label\n";
    out << "end_header\n";
    for (const auto& p : mesh.vertices) out.write(reinterpret_cast<const char*>(p.data()), 24);
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
        const std::uint8_t three = 3;
        out.write(reinterpret_cast<const char*>(&three), 1);
        out.write(reinterpret_cast<const char*>(mesh.triangles[t].data()), 12);
        if (labelled) out.write(reinterpret_cast<const char*>(mesh.labels[t].data()), 8);
    }
}

SurfaceMesh read_obj(const fs::path& path, const std::string& what)
{
    std::ifstream in(path);
    SurfaceMesh mesh;
    std::array<std::int32_t, 2> label{0, 0};
    bool labelled = false;
    std::string line;
    std::size_t line_number = 0;
    while (std::getline(in, line)) {
        ++line_number;
        std::istringstream s(line);
        std::string key;
        s >> key;
        if (key == "v") {
            Vec3 p;
            if (!(s >> p[0] >> p[1] >> p[2])) fail("{}: line {}: corrupt vertex", what, line_number);
            mesh.vertices.push_back(p);
        } else if (key == "g" || key == "o") {
            std::string name;
            s >> name;
            int a = 0, b = 0;
            if (std::sscanf(name.c_str(), "label_%d_%d", &a, &b) == 2) {
                label = {a, b};
                labelled = true;
            }
        } else if (key == "f") {
            std::vector<std::int32_t> polygon;
            std::string token;
            while (s >> token) {
                const long v = std::strtol(token.c_str(), nullptr, 10); // "v/vt/vn": the vertex index
                if (v == 0) fail("{}: line {}: bad face index '{}'", what, line_number, token);
                const long index = v > 0 ? v - 1 : static_cast<long>(mesh.vertices.size()) + v;
                if (index < 0 || index > std::numeric_limits<std::int32_t>::max())
                    fail("{}: line {}: face index '{}' is out of range", what, line_number, token);
                polygon.push_back(static_cast<std::int32_t>(index));
            }
            if (polygon.size() < 3) fail("{}: line {}: face with {} vertices", what, line_number, polygon.size());
            for (std::size_t k = 1; k + 1 < polygon.size(); ++k) {
                mesh.triangles.push_back({polygon[0], polygon[k], polygon[k + 1]});
                mesh.labels.push_back(label);
            }
        }
    }
    if (!labelled) mesh.labels.clear();
    return mesh;
}

void write_obj(std::ofstream& out, const SurfaceMesh& mesh)
{
    out.precision(17);
    out << "# physreg surface, coordinates in mm (LPS)\n";
    for (const auto& p : mesh.vertices) out << "v " << p[0] << ' ' << p[1] << ' ' << p[2] << "\n";
    std::array<std::int32_t, 2> current{-1, -1};
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
        if (!mesh.labels.empty() && mesh.labels[t] != current) {
            current = mesh.labels[t];
            out << "g label_" << current[0] << '_' << current[1] << "\n";
        }
        const auto& tri = mesh.triangles[t];
        out << "f " << tri[0] + 1 << ' ' << tri[1] + 1 << ' ' << tri[2] + 1 << "\n";
    }
}

// Legacy VTK POLYDATA, ASCII: POINTS, POLYGONS (fans of polygons become triangles), VERTICES and
// LINES skipped, CELL_DATA / POINT_DATA scalars (labels) and point NORMALS.
SurfaceMesh read_vtk_polydata(const fs::path& path, const std::string& what)
{
    require_existing_file(path, what);
    const auto file_bytes = static_cast<std::uint64_t>(fs::file_size(path));
    std::ifstream in(path);
    if (!in) fail("{}: cannot open file", what);
    std::string line;
    std::getline(in, line);
    if (line.rfind("# vtk DataFile", 0) != 0) fail("{}: not a legacy VTK file (first line '{}')", what, line.substr(0, 40));
    std::getline(in, line); // title
    std::string format;
    in >> format;
    if (format == "BINARY") fail("{}: binary legacy VTK is not supported; save it as ASCII (or use PLY/STL/OBJ)", what);
    if (format != "ASCII") fail("{}: expected ASCII or BINARY, found '{}'", what, format);
    std::string keyword, kind;
    in >> keyword >> kind;
    if (keyword != "DATASET" || kind != "POLYDATA") fail("{}: only DATASET POLYDATA is read as a surface (found '{} {}')", what, keyword, kind);
    SurfaceMesh mesh;
    std::vector<std::int32_t> face_label;
    std::string attribute_of; // "CELL_DATA" or "POINT_DATA": where the next attributes belong
    std::size_t polygons = 0;
    const auto number = [&]() {
        std::string token;
        if (!(in >> token)) fail("{}: truncated file", what);
        const auto v = parse_number(token);
        if (!v) fail("{}: '{}' is not a number", what, token);
        return *v;
    };
    const auto count = [&]() {
        const double v = number();
        // Each entry takes at least one byte of the file: a larger count is corrupt and must not
        // size an allocation.
        if (!(v >= 0 && v == std::floor(v) && v <= static_cast<double>(file_bytes))) fail("{}: bad count {} for a {}-byte file", what, v, file_bytes);
        return static_cast<std::size_t>(v);
    };
    while (in >> keyword) {
        if (keyword == "POINTS") {
            const std::size_t n = count();
            in >> kind;
            mesh.vertices.resize(n);
            for (auto& v : mesh.vertices)
                for (int d = 0; d < 3; ++d) v[d] = number(); // one at a time: argument order is unspecified
        } else if (keyword == "POLYGONS" || keyword == "VERTICES" || keyword == "LINES") {
            const std::size_t n = count();
            count(); // total size
            for (std::size_t c = 0; c < n; ++c) {
                const std::size_t k = count();
                std::vector<std::int32_t> ids(k);
                for (auto& id : ids) id = to_integer<std::int32_t>(number(), what, "a point id");
                if (keyword != "POLYGONS") continue;
                if (k < 3) fail("{}: polygon {} has {} points", what, c, k);
                for (std::size_t j = 1; j + 1 < k; ++j) {
                    mesh.triangles.push_back({ids[0], ids[j], ids[j + 1]});
                    face_label.push_back(static_cast<std::int32_t>(polygons));
                }
                ++polygons;
            }
        } else if (keyword == "TRIANGLE_STRIPS") {
            fail("{}: TRIANGLE_STRIPS are not supported", what);
        } else if (keyword == "CELL_DATA" || keyword == "POINT_DATA") {
            attribute_of = keyword;
            count();
        } else if (keyword == "SCALARS") {
            std::string name, type;
            in >> name >> type;
            std::getline(in, line); // optional component count
            int components = 1;
            if (line.find_first_not_of(" \t\r") != std::string::npos) {
                std::istringstream count_text(line);
                if (!(count_text >> components) || components < 1 || components > 4)
                    fail("{}: SCALARS {}: the component count must be 1 to 4 (got '{}')", what, name, line);
            }
            in >> keyword;
            if (keyword == "LOOKUP_TABLE") in >> keyword; else fail("{}: SCALARS {} without LOOKUP_TABLE", what, name);
            const bool cells = attribute_of == "CELL_DATA";
            const std::size_t n = (cells ? polygons : mesh.vertices.size()) * static_cast<std::size_t>(components);
            std::vector<double> values(n);
            for (auto& v : values) v = number();
            const bool label = name == "label" || name == "feature" || name == "region" || name == "inside_label";
            if (name == "outside_label" && cells && components == 1) {
                if (mesh.labels.size() != face_label.size()) mesh.labels.assign(face_label.size(), {0, 0});
                for (std::size_t t = 0; t < face_label.size(); ++t) mesh.labels[t][1] = to_integer<std::int32_t>(values[static_cast<std::size_t>(face_label[t])], what, "a cell label");
            } else if (label && components == 1) {
                if (cells) {
                    if (mesh.labels.size() != face_label.size()) mesh.labels.assign(face_label.size(), {0, 0});
                    for (std::size_t t = 0; t < face_label.size(); ++t) mesh.labels[t][0] = to_integer<std::int32_t>(values[static_cast<std::size_t>(face_label[t])], what, "a cell label");
                } else {
                    mesh.vertex_labels.resize(values.size());
                    for (std::size_t i = 0; i < values.size(); ++i) mesh.vertex_labels[i] = to_integer<std::int32_t>(values[i], what, "a point label");
                }
            }
        } else if (keyword == "NORMALS" || keyword == "VECTORS") {
            std::string name, type;
            in >> name >> type;
            const bool cells = attribute_of == "CELL_DATA";
            std::vector<Vec3> values(cells ? polygons : mesh.vertices.size());
            for (auto& v : values)
                for (int d = 0; d < 3; ++d) v[d] = number();
            if (keyword == "NORMALS" && !cells) mesh.vertex_normals = values;
        } else if (keyword == "METADATA") {
            while (std::getline(in, line) && !line.empty()) {
            }
        } else {
            fail("{}: unsupported legacy VTK section '{}'", what, keyword);
        }
    }
    return mesh;
}

void write_vtk_polydata(std::ofstream& out, const SurfaceMesh& mesh)
{
    out << "# vtk DataFile Version 3.0\nphysreg surface (mm, LPS)\nASCII\nDATASET POLYDATA\nPOINTS " << mesh.vertices.size() << " double\n";
    out.precision(10);
    for (const auto& v : mesh.vertices) out << v.x() << ' ' << v.y() << ' ' << v.z() << '\n';
    out << "POLYGONS " << mesh.triangles.size() << ' ' << 4 * mesh.triangles.size() << '\n';
    for (const auto& t : mesh.triangles) out << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
    if (!mesh.labels.empty()) {
        out << "CELL_DATA " << mesh.triangles.size() << "\nSCALARS inside_label int 1\nLOOKUP_TABLE default\n";
        for (const auto& l : mesh.labels) out << l[0] << '\n';
        out << "SCALARS outside_label int 1\nLOOKUP_TABLE default\n";
        for (const auto& l : mesh.labels) out << l[1] << '\n';
    }
    if (!mesh.vertex_labels.empty() || !mesh.vertex_normals.empty()) {
        out << "POINT_DATA " << mesh.vertices.size() << '\n';
        if (!mesh.vertex_labels.empty()) {
            out << "SCALARS label int 1\nLOOKUP_TABLE default\n";
            for (auto l : mesh.vertex_labels) out << l << '\n';
        }
        if (!mesh.vertex_normals.empty()) {
            out << "NORMALS normals double\n";
            for (const auto& n : mesh.vertex_normals) out << n.x() << ' ' << n.y() << ' ' << n.z() << '\n';
        }
    }
}

} // namespace

SurfaceMesh read_point_set(const fs::path& path)
{
    const std::string what = "point set '" + path.string() + "'";
    if (!fs::exists(path)) fail_missing_file("{}: file does not exist", what);
    const std::string ext = full_extension(path);
    if (ext != ".ply" && ext != ".vtk") fail("{}: point sets are read from PLY or legacy VTK files", what);
    SurfaceMesh mesh = ext == ".ply" ? read_ply(path, what) : read_vtk_polydata(path, what);
    mesh.validate(what);
    if (mesh.vertices.empty()) fail("{}: holds no vertices", what);
    return mesh;
}

SurfaceMesh read_surface(const fs::path& path)
{
    const std::string what = "surface '" + path.string() + "'";
    if (!fs::exists(path)) fail_missing_file("{}: file does not exist", what);
    const std::string ext = full_extension(path);
    SurfaceMesh mesh;
    if (ext == ".stl") mesh = read_stl(path, what);
    else if (ext == ".ply") mesh = read_ply(path, what);
    else if (ext == ".obj") mesh = read_obj(path, what);
    else if (ext == ".vtk") mesh = read_vtk_polydata(path, what);
    else fail("{}: unknown surface extension '{}' (use .stl, .ply, .obj or .vtk)", what, ext);
    mesh.validate(what);
    if (mesh.triangles.empty()) fail("{}: holds no triangles", what);
    return mesh;
}

void write_surface(const fs::path& path, const SurfaceMesh& mesh)
{
    mesh.validate("surface for '" + path.string() + "'");
    const std::string ext = full_extension(path);
    if (ext != ".stl" && ext != ".ply" && ext != ".obj" && ext != ".vtk")
        fail("surface '{}': unknown extension '{}' (use .stl, .ply, .obj or .vtk)", path.string(), ext);
    write_atomically(path, [&](const fs::path& tmp) {
        std::ofstream out(tmp, std::ios::binary);
        if (ext == ".stl") write_stl(out, mesh);
        else if (ext == ".ply") write_ply(out, mesh);
        else if (ext == ".vtk") write_vtk_polydata(out, mesh);
        else write_obj(out, mesh);
        out.close();
        if (!out) fail("surface '{}': write failed: {}", path.string(), std::strerror(errno));
    });
}

} // namespace physreg
