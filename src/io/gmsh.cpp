// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/gmsh.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <unordered_map>

namespace physreg {
namespace fs = std::filesystem;
namespace {

// Reads numbers either as ascii tokens or as native binary values, so one parser serves both.
struct Tokens {
    std::istream& in;
    std::string what;
    std::uint64_t file_bytes = 0;
    bool binary = false;

    template <typename T>
    T get(const char* item)
    {
        T v{};
        if (binary) {
            in.read(reinterpret_cast<char*>(&v), sizeof(T));
        } else if constexpr (sizeof(T) == 1) {
            int wide;
            in >> wide;
            v = static_cast<T>(wide);
        } else {
            in >> v;
        }
        if (!in) fail("{}: truncated or corrupt file while reading {}", what, item);
        return v;
    }
    // Counts in version 1/2 files are ascii even in binary files.
    std::int64_t ascii_count(const char* item)
    {
        std::int64_t n = -1;
        if (!(in >> n) || n < 0) fail("{}: corrupt {}", what, item);
        return n;
    }
    void expect_end(const std::string& section)
    {
        std::string w;
        while (in >> w)
            if (w == "$End" + section || w == "$END" + section) return;
        fail("{}: section {} is not closed (truncated file)", what, section);
    }
    /// A count read from the file, refused when the file is too short to hold that many entries
    /// (each takes at least one byte): a corrupt count must not size an allocation.
    template <typename T>
    T count(const char* item)
    {
        const T n = get<T>(item);
        if (static_cast<std::uint64_t>(n) > file_bytes) fail("{}: {} {} is larger than the file (corrupt file)", what, item, n);
        return n;
    }
    void skip_line()
    {
        std::string rest;
        std::getline(in, rest);
    }
};

struct RawCell {
    int type;
    std::int32_t label;
    std::vector<std::int64_t> nodes;
    std::int64_t tag = 0;
};

int gmsh_node_count(int type)
{
    switch (type) {
    case 15: return 1;
    case 1: return 2;
    case 2: return 3;
    case 3: return 4;
    case 4: return 4;
    case 5: return 8;
    case 6: return 6;
    case 7: return 5;
    case 8: return 3;
    case 9: return 6;
    case 10: return 9;
    case 11: return 10;
    case 12: return 27;
    case 16: return 8;
    case 17: return 20;
    default: return -1;
    }
}

bool is_volume(int type) { return type == 4 || type == 5 || type == 6 || type == 7 || type == 11 || type == 12 || type == 17; }

VolumeMesh assemble(const std::string& what, const std::unordered_map<std::int64_t, Vec3>& nodes_by_tag,
                    const std::vector<std::int64_t>& node_order, const std::vector<RawCell>& raw)
{
    VolumeMesh mesh;
    int type = 0;
    for (const auto& c : raw) {
        if (!is_volume(c.type)) continue;
        if (c.type != 4 && c.type != 5)
            fail("{}: element type {} is not supported (linear tetrahedra 4 and hexahedra 5 only)", what, c.type);
        if (type && type != c.type) fail("{}: mixes tetrahedra and hexahedra (one cell type per mesh)", what);
        type = c.type;
    }
    if (!type) fail("{}: holds no tetrahedra or hexahedra", what);
    mesh.cell_type = type == 5 ? CellType::hexahedron : CellType::tetrahedron;
    std::unordered_map<std::int64_t, std::int32_t> index;
    for (auto tag : node_order) {
        index.emplace(tag, static_cast<std::int32_t>(mesh.nodes.size()));
        mesh.nodes.push_back(nodes_by_tag.at(tag));
    }
    for (const auto& c : raw) {
        if (c.type != type) continue;
        for (auto tag : c.nodes) {
            const auto it = index.find(tag);
            if (it == index.end()) fail("{}: an element refers to node {}, which is not defined", what, tag);
            mesh.cells.push_back(it->second);
        }
        mesh.cell_labels.push_back(c.label);
    }
    mesh.validate(what);
    return mesh;
}

void read_nodes_v1v2(Tokens& t, std::unordered_map<std::int64_t, Vec3>& nodes, std::vector<std::int64_t>& order)
{
    const auto n = t.ascii_count("node count");
    if (t.binary) t.skip_line();
    for (std::int64_t i = 0; i < n; ++i) {
        const auto tag = static_cast<std::int64_t>(t.binary ? t.get<std::int32_t>("node tag") : t.get<std::int64_t>("node tag"));
        Vec3 p;
        for (int a = 0; a < 3; ++a) p[a] = t.get<double>("node coordinate");
        if (!nodes.emplace(tag, p).second) fail("{}: node {} defined twice", t.what, tag);
        order.push_back(tag);
    }
}

void read_elements_v1v2(Tokens& t, int major, std::vector<RawCell>& cells)
{
    const auto m = t.ascii_count("element count");
    if (t.binary) {
        t.skip_line();
        std::int64_t done = 0;
        while (done < m) {
            const int type = t.get<std::int32_t>("element type");
            const int count = t.get<std::int32_t>("element block size");
            const int tags = t.get<std::int32_t>("tag count");
            const int nn = gmsh_node_count(type);
            if (nn < 0 || count < 0 || tags < 0) fail("{}: unknown element type {} in binary block", t.what, type);
            for (int e = 0; e < count; ++e) {
                RawCell c{type, 0, {}};
                c.tag = t.get<std::int32_t>("element tag");
                for (int k = 0; k < tags; ++k) {
                    const int v = t.get<std::int32_t>("element tag");
                    if (k == 0) c.label = v;
                }
                for (int k = 0; k < nn; ++k) c.nodes.push_back(t.get<std::int32_t>("element node"));
                cells.push_back(std::move(c));
            }
            done += count;
        }
        return;
    }
    for (std::int64_t e = 0; e < m; ++e) {
        const auto tag = t.get<std::int64_t>("element tag");
        RawCell c{t.get<int>("element type"), 0, {}};
        c.tag = tag;
        int nn = gmsh_node_count(c.type);
        if (nn < 0) fail("{}: unknown element type {}", t.what, c.type);
        if (major == 1) {
            c.label = t.get<int>("physical region");
            t.get<int>("elementary region");
            const int listed = t.get<int>("node count");
            if (listed != nn) fail("{}: element {} of type {} lists {} nodes", t.what, e, c.type, listed);
        } else {
            const int tags = t.get<int>("tag count");
            for (int k = 0; k < tags; ++k) {
                const int v = t.get<int>("element tag");
                if (k == 0) c.label = v;
            }
        }
        for (int k = 0; k < nn; ++k) c.nodes.push_back(t.get<std::int64_t>("element node"));
        cells.push_back(std::move(c));
    }
}

// Version 4.1: entities carry the physical tags; nodes and elements come in entity blocks.
void read_v4(Tokens& t, std::unordered_map<std::int64_t, Vec3>& nodes, std::vector<std::int64_t>& order,
             std::vector<RawCell>& cells, std::map<int, int>& volume_physical, const std::string& section)
{
    using Size = std::uint64_t;
    if (section == "$Entities") {
        Size counts[4];
        for (auto& c : counts) c = t.get<Size>("entity count");
        for (int dim = 0; dim < 4; ++dim)
            for (Size e = 0; e < counts[dim]; ++e) {
                const int tag = t.get<std::int32_t>("entity tag");
                for (int k = 0; k < (dim == 0 ? 3 : 6); ++k) t.get<double>("entity box");
                const Size physical = t.get<Size>("physical tag count");
                for (Size k = 0; k < physical; ++k) {
                    const int p = t.get<std::int32_t>("physical tag");
                    if (dim == 3 && k == 0) volume_physical[tag] = p;
                }
                if (dim > 0) {
                    const Size bounding = t.get<Size>("bounding entity count");
                    for (Size k = 0; k < bounding; ++k) t.get<std::int32_t>("bounding entity");
                }
            }
        t.expect_end("Entities");
    } else if (section == "$Nodes") {
        const Size blocks = t.get<Size>("node block count");
        t.get<Size>("node count");
        t.get<Size>("min node tag");
        t.get<Size>("max node tag");
        for (Size b = 0; b < blocks; ++b) {
            t.get<std::int32_t>("entity dim");
            t.get<std::int32_t>("entity tag");
            const int parametric = t.get<std::int32_t>("parametric flag");
            if (parametric) fail("{}: parametric node coordinates are not supported", t.what);
            const Size count = t.count<Size>("block node count");
            std::vector<std::int64_t> tags(count);
            for (auto& tag : tags) tag = static_cast<std::int64_t>(t.get<Size>("node tag"));
            for (auto tag : tags) {
                Vec3 p;
                for (int a = 0; a < 3; ++a) p[a] = t.get<double>("node coordinate");
                if (!nodes.emplace(tag, p).second) fail("{}: node {} defined twice", t.what, tag);
                order.push_back(tag);
            }
        }
        t.expect_end("Nodes");
    } else if (section == "$Elements") {
        const Size blocks = t.get<Size>("element block count");
        t.get<Size>("element count");
        t.get<Size>("min element tag");
        t.get<Size>("max element tag");
        for (Size b = 0; b < blocks; ++b) {
            const int dim = t.get<std::int32_t>("entity dim");
            const int entity = t.get<std::int32_t>("entity tag");
            const int type = t.get<std::int32_t>("element type");
            const Size count = t.count<Size>("block element count");
            const int nn = gmsh_node_count(type);
            if (nn < 0) fail("{}: unknown element type {}", t.what, type);
            const auto it = volume_physical.find(entity);
            const int label = dim == 3 && it != volume_physical.end() ? it->second : entity;
            for (Size e = 0; e < count; ++e) {
                RawCell c{type, label, {}};
                c.tag = static_cast<std::int64_t>(t.get<Size>("element tag"));
                for (int k = 0; k < nn; ++k) c.nodes.push_back(static_cast<std::int64_t>(t.get<Size>("element node")));
                cells.push_back(std::move(c));
            }
        }
        t.expect_end("Elements");
    }
}

} // namespace

VolumeMesh read_gmsh(const fs::path& path)
{
    const std::string what = "Gmsh '" + path.string() + "'";
    require_existing_file(path, what);
    std::ifstream in(path, std::ios::binary);
    if (!in) fail("{}: cannot open file", what);
    Tokens t{in, what, static_cast<std::uint64_t>(fs::file_size(path))};
    std::unordered_map<std::int64_t, Vec3> nodes;
    std::vector<std::int64_t> order;
    std::vector<RawCell> cells;
    std::map<int, int> volume_physical;
    int major = 0;
    bool saw_nodes = false, saw_elements = false;
    std::string word;
    while (in >> word) {
        if (word == "$NOD") {
            major = 1;
            read_nodes_v1v2(t, nodes, order);
            t.expect_end("NOD");
            saw_nodes = true;
        } else if (word == "$ELM") {
            read_elements_v1v2(t, 1, cells);
            t.expect_end("ELM");
            saw_elements = true;
        } else if (word == "$MeshFormat") {
            double version = 0;
            int file_type = 0, data_size = 0;
            in >> version >> file_type >> data_size;
            if (!in) fail("{}: corrupt $MeshFormat", what);
            if (!(version >= 0 && version < 100)) fail("{}: Gmsh format {} is not supported (1, 2.x and 4.1 are)", what, version);
            major = static_cast<int>(version);
            if (major != 2 && !(major == 4 && version >= 4.1 - 1e-9))
                fail("{}: Gmsh format {} is not supported (1, 2.x and 4.1 are)", what, version);
            t.binary = file_type == 1;
            if (t.binary) {
                if (data_size != 8) fail("{}: binary data size {} (only 8-byte doubles supported)", what, data_size);
                in.get(); // newline before the endianness marker
                const int one = t.get<std::int32_t>("endianness marker");
                if (one != 1) fail("{}: binary file written with another byte order", what);
            }
            t.expect_end("MeshFormat");
        } else if (word == "$Nodes" && major == 2) {
            read_nodes_v1v2(t, nodes, order);
            t.expect_end("Nodes");
            saw_nodes = true;
        } else if (word == "$Elements" && major == 2) {
            read_elements_v1v2(t, 2, cells);
            t.expect_end("Elements");
            saw_elements = true;
        } else if ((word == "$Entities" || word == "$Nodes" || word == "$Elements") && major == 4) {
            if (t.binary) in.get();
            read_v4(t, nodes, order, cells, volume_physical, word);
            saw_nodes = saw_nodes || word == "$Nodes";
            saw_elements = saw_elements || word == "$Elements";
        } else if (word.starts_with("$") && !word.starts_with("$End") && !word.starts_with("$END")) {
            t.expect_end(word.substr(1)); // sections we do not need ($PhysicalNames, $Periodic, ...)
        } else if (!word.starts_with("$")) {
            if (!major) fail("{}: not a Gmsh mesh file", what);
        }
    }
    if (!saw_nodes || !saw_elements) fail("{}: missing node or element section (not a Gmsh mesh, or truncated)", what);
    // Element tags give the order (version 4 groups elements by entity).
    std::stable_sort(cells.begin(), cells.end(), [](const RawCell& a, const RawCell& b) { return a.tag < b.tag; });
    return assemble(what, nodes, order, cells);
}

void write_gmsh(const fs::path& path, const VolumeMesh& mesh, GmshVersion version)
{
    mesh.validate("mesh for '" + path.string() + "'");
    const int type = mesh.cell_type == CellType::hexahedron ? 5 : 4;
    write_atomically(path, [&](const fs::path& tmp) {
        std::ofstream out(tmp);
        out.precision(17);
        if (version == GmshVersion::v2_2) {
            out << "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n" << mesh.node_count() << "\n";
            for (std::size_t n = 0; n < mesh.node_count(); ++n)
                out << n + 1 << ' ' << mesh.nodes[n][0] << ' ' << mesh.nodes[n][1] << ' ' << mesh.nodes[n][2] << "\n";
            out << "$EndNodes\n$Elements\n" << mesh.cell_count() << "\n";
            for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
                out << c + 1 << ' ' << type << " 2 " << mesh.cell_labels[c] << ' ' << mesh.cell_labels[c];
                for (auto v : mesh.cell(c)) out << ' ' << v + 1;
                out << "\n";
            }
            out << "$EndElements\n";
        } else {
            // One volume entity per label, with the label as its tag and physical tag.
            std::map<std::int32_t, std::vector<std::size_t>> by_label;
            for (std::size_t c = 0; c < mesh.cell_count(); ++c) by_label[mesh.cell_labels[c]].push_back(c);
            Vec3 lo = Vec3::Constant(1e300), hi = -lo;
            for (const auto& p : mesh.nodes) {
                lo = lo.cwiseMin(p);
                hi = hi.cwiseMax(p);
            }
            out << "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n0 0 0 " << by_label.size() << "\n";
            for (const auto& [label, cells] : by_label)
                out << label << ' ' << lo[0] << ' ' << lo[1] << ' ' << lo[2] << ' ' << hi[0] << ' ' << hi[1] << ' '
                    << hi[2] << " 1 " << label << " 0\n";
            out << "$EndEntities\n$Nodes\n1 " << mesh.node_count() << " 1 " << mesh.node_count() << "\n";
            out << "3 " << by_label.begin()->first << " 0 " << mesh.node_count() << "\n";
            for (std::size_t n = 0; n < mesh.node_count(); ++n) out << n + 1 << "\n";
            for (const auto& p : mesh.nodes) out << p[0] << ' ' << p[1] << ' ' << p[2] << "\n";
            out << "$EndNodes\n$Elements\n" << by_label.size() << ' ' << mesh.cell_count() << " 1 " << mesh.cell_count() << "\n";
            for (const auto& [label, cells] : by_label) {
                out << "3 " << label << ' ' << type << ' ' << cells.size() << "\n";
                for (auto c : cells) {
                    out << c + 1;
                    for (auto v : mesh.cell(c)) out << ' ' << v + 1;
                    out << "\n";
                }
            }
            out << "$EndElements\n";
        }
        out.close();
        if (!out) fail("'{}': write failed: {}", path.string(), std::strerror(errno));
    });
}

} // namespace physreg
