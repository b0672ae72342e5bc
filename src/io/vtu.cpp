// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/io/vtu.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "detail/base64.hpp"

#include <bit>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <pugixml.hpp>
#include <sstream>
#include <zlib.h>

namespace physreg {
namespace fs = std::filesystem;

const DataArray* MeshData::find_point(const std::string& name) const
{
    for (const auto& a : point_data)
        if (a.name == name) return &a;
    return nullptr;
}
const DataArray* MeshData::find_cell(const std::string& name) const
{
    for (const auto& a : cell_data)
        if (a.name == name) return &a;
    return nullptr;
}

namespace {

template <typename T>
std::string encode_block(const std::vector<T>& values)
{
    // Uncompressed inline binary: one base64 stream of [UInt64 byte count][data].
    const std::uint64_t bytes = values.size() * sizeof(T);
    std::string raw(sizeof(bytes) + bytes, '\0');
    std::memcpy(raw.data(), &bytes, sizeof(bytes));
    if (bytes) std::memcpy(raw.data() + sizeof(bytes), values.data(), bytes);
    return detail::base64_encode(raw);
}

template <typename T>
void write_array(std::ostream& out, const char* type, const std::string& name, int components,
                 const std::vector<T>& values)
{
    out << "<DataArray type=\"" << type << "\"";
    if (!name.empty()) out << " Name=\"" << name << "\"";
    out << " NumberOfComponents=\"" << components << "\" format=\"binary\">\n" << encode_block(values)
        << "\n</DataArray>\n";
}

std::string xml_escape(const std::string& s)
{
    std::string out;
    for (char c : s) {
        switch (c) {
        case '&': out += "&amp;"; break;
        case '<': out += "&lt;"; break;
        case '>': out += "&gt;"; break;
        case '"': out += "&quot;"; break;
        default: out += c;
        }
    }
    return out;
}

// ---- reading ---------------------------------------------------------------------------------

struct Decoder {
    std::string what;
    bool big_endian = false;
    bool header64 = false;
    bool zlib = false;
    std::string appended; // raw bytes after '_' (already base64-decoded if encoding="base64")
    bool appended_base64 = false;

    static int size_of(const std::string& type)
    {
        if (type == "Int8" || type == "UInt8") return 1;
        if (type == "Int16" || type == "UInt16") return 2;
        if (type == "Int32" || type == "UInt32" || type == "Float32") return 4;
        if (type == "Int64" || type == "UInt64" || type == "Float64") return 8;
        return 0;
    }

    static double value_at(const char* p, const std::string& type)
    {
        auto get = [p]<typename T>(T) {
            T v;
            std::memcpy(&v, p, sizeof(T));
            return static_cast<double>(v);
        };
        if (type == "Int8") return get(std::int8_t{});
        if (type == "UInt8") return get(std::uint8_t{});
        if (type == "Int16") return get(std::int16_t{});
        if (type == "UInt16") return get(std::uint16_t{});
        if (type == "Int32") return get(std::int32_t{});
        if (type == "UInt32") return get(std::uint32_t{});
        if (type == "Int64") return get(std::int64_t{});
        if (type == "UInt64") return get(std::uint64_t{});
        if (type == "Float32") return get(float{});
        return get(double{});
    }

    void swap_if_needed(std::string& bytes, int size) const
    {
        if (!big_endian || size == 1) return;
        for (std::size_t i = 0; i + size <= bytes.size(); i += size) std::reverse(bytes.begin() + i, bytes.begin() + i + size);
    }

    std::uint64_t header_value(const std::string& bytes, std::size_t index) const
    {
        const int h = header64 ? 8 : 4;
        if (bytes.size() < (index + 1) * h) fail("{}: truncated binary block header", what);
        std::string word = bytes.substr(index * h, h);
        swap_if_needed(word, h);
        std::uint64_t v = 0;
        if (h == 8) std::memcpy(&v, word.data(), 8);
        else {
            std::uint32_t v32;
            std::memcpy(&v32, word.data(), 4);
            v = v32;
        }
        return v;
    }

    // Decompresses a zlib-compressed payload given its already-decoded header.
    std::string inflate_blocks(const std::string& header, const std::string& payload) const
    {
        const std::uint64_t blocks = header_value(header, 0);
        const std::uint64_t block_size = header_value(header, 1);
        const std::uint64_t last_size = header_value(header, 2);
        std::string out;
        std::size_t offset = 0;
        for (std::uint64_t b = 0; b < blocks; ++b) {
            const std::uint64_t compressed = header_value(header, 3 + b);
            const std::uint64_t expected = (b + 1 == blocks && last_size) ? last_size : block_size;
            if (offset + compressed > payload.size()) fail("{}: truncated compressed data block", what);
            std::string block(expected, '\0');
            uLongf produced = static_cast<uLongf>(expected);
            if (uncompress(reinterpret_cast<Bytef*>(block.data()), &produced,
                           reinterpret_cast<const Bytef*>(payload.data() + offset), static_cast<uLong>(compressed)) != Z_OK ||
                produced != expected)
                fail("{}: corrupt zlib data block", what);
            out += block;
            offset += compressed;
        }
        return out;
    }

    std::string decode_inline(const std::string& text) const
    {
        std::string compact;
        for (char c : text)
            if (!std::isspace(static_cast<unsigned char>(c))) compact += c;
        const int h = header64 ? 8 : 4;
        if (!zlib) {
            const std::string bytes = detail::base64_decode(compact, what);
            const std::uint64_t n = header_value(bytes, 0);
            if (bytes.size() < h + n) fail("{}: binary data array is truncated ({} of {} bytes)", what, bytes.size() - h, n);
            return bytes.substr(h, n);
        }
        // Compressed: the header is its own base64 stream; its length depends on the block count.
        const std::uint64_t blocks = header_value(detail::base64_decode(compact.substr(0, ((h + 2) / 3) * 4), what), 0);
        const std::size_t header_bytes = (3 + blocks) * h;
        const std::size_t header_chars = ((header_bytes + 2) / 3) * 4;
        if (compact.size() < header_chars) fail("{}: truncated compressed header", what);
        const std::string header = detail::base64_decode(compact.substr(0, header_chars), what);
        return inflate_blocks(header, detail::base64_decode(compact.substr(header_chars), what));
    }

    std::string decode_appended(std::uint64_t offset) const
    {
        const int h = header64 ? 8 : 4;
        if (appended_base64) fail("{}: base64-encoded appended data is not supported; re-save as raw or binary", what);
        if (offset + h > appended.size()) fail("{}: appended data offset {} beyond the end of the file", what, offset);
        if (!zlib) {
            const std::uint64_t n = header_value(appended.substr(offset, h), 0);
            if (offset + h + n > appended.size()) fail("{}: appended data array is truncated", what);
            return appended.substr(offset + h, n);
        }
        const std::uint64_t blocks = header_value(appended.substr(offset, h), 0);
        const std::size_t header_bytes = (3 + blocks) * h;
        if (offset + header_bytes > appended.size()) fail("{}: truncated compressed header", what);
        const std::string header = appended.substr(offset, header_bytes);
        std::uint64_t total = 0;
        for (std::uint64_t b = 0; b < blocks; ++b) total += header_value(header, 3 + b);
        if (offset + header_bytes + total > appended.size()) fail("{}: appended compressed data is truncated", what);
        return inflate_blocks(header, appended.substr(offset + header_bytes, total));
    }

    std::vector<double> read(const pugi::xml_node& node, std::size_t expected_tuples, int& components) const
    {
        const std::string type = node.attribute("type").as_string();
        const std::string name = node.attribute("Name").as_string();
        const std::string format = node.attribute("format").as_string("ascii");
        components = node.attribute("NumberOfComponents").as_int(1);
        const int size = size_of(type);
        const std::string where = fmt::format("{}: data array '{}'", what, name);
        if (!size) fail("{}: unsupported type '{}'", where, type);
        if (components < 1) fail("{}: NumberOfComponents = {}", where, components);
        std::vector<double> values;
        const std::size_t expected = expected_tuples * static_cast<std::size_t>(components);
        if (format == "ascii") {
            std::istringstream in(node.child_value());
            values.reserve(expected);
            double v;
            while (in >> v) values.push_back(v);
            if (!in.eof()) fail("{}: non-numeric ascii value", where);
        } else {
            std::string bytes = format == "binary" ? decode_inline(node.child_value())
                                                   : decode_appended(node.attribute("offset").as_ullong());
            if (format != "binary" && format != "appended") fail("{}: unknown format '{}'", where, format);
            swap_if_needed(bytes, size);
            values.resize(bytes.size() / size);
            for (std::size_t i = 0; i < values.size(); ++i) values[i] = value_at(bytes.data() + i * size, type);
        }
        if (expected_tuples != std::size_t(-1) && values.size() != expected)
            fail("{}: holds {} values, expected {} (truncated or inconsistent file)", where, values.size(), expected);
        return values;
    }
};

} // namespace

void write_vtu(const fs::path& path, const VolumeMesh& mesh, const MeshData& data)
{
    mesh.validate("mesh for '" + path.string() + "'");
    const std::size_t n = mesh.node_count(), m = mesh.cell_count();
    for (const auto& a : data.point_data)
        if (a.values.size() != n * a.components) fail("'{}': point data '{}' has {} values for {} nodes", path.string(), a.name, a.values.size(), n);
    for (const auto& a : data.cell_data)
        if (a.values.size() != m * a.components) fail("'{}': cell data '{}' has {} values for {} cells", path.string(), a.name, a.values.size(), m);
    write_atomically(path, [&](const fs::path& tmp) {
        std::ofstream out(tmp, std::ios::binary);
        out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" "
               "byte_order=\"LittleEndian\" header_type=\"UInt64\">\n<UnstructuredGrid>\n";
        if (mesh.grid) {
            const HexGrid& g = *mesh.grid;
            std::vector<double> v{g.origin[0], g.origin[1], g.origin[2], g.cell_size[0], g.cell_size[1], g.cell_size[2]};
            for (int c = 0; c < 3; ++c)
                for (int r = 0; r < 3; ++r) v.push_back(g.direction(r, c));
            for (int a = 0; a < 3; ++a) v.push_back(double(g.dims[a]));
            out << "<FieldData>\n";
            out << "<DataArray type=\"Float64\" Name=\"physreg_grid\" NumberOfTuples=\"1\" NumberOfComponents=\"18\" "
                   "format=\"binary\">\n"
                << encode_block(v) << "\n</DataArray>\n</FieldData>\n";
        }
        out << "<Piece NumberOfPoints=\"" << n << "\" NumberOfCells=\"" << m << "\">\n<PointData>\n";
        for (const auto& a : data.point_data) write_array(out, "Float64", xml_escape(a.name), a.components, a.values);
        out << "</PointData>\n<CellData>\n";
        write_array(out, "Int32", "tissue", 1, mesh.cell_labels);
        if (mesh.grid) {
            std::vector<std::int32_t> ijk;
            ijk.reserve(3 * m);
            for (const auto& g : mesh.cell_grid_index)
                for (int a = 0; a < 3; ++a) ijk.push_back(static_cast<std::int32_t>(g[a]));
            write_array(out, "Int32", "grid_index", 3, ijk);
        }
        for (const auto& a : data.cell_data) write_array(out, "Float64", xml_escape(a.name), a.components, a.values);
        out << "</CellData>\n<Points>\n";
        std::vector<double> xyz;
        xyz.reserve(3 * n);
        for (const auto& p : mesh.nodes) xyz.insert(xyz.end(), {p[0], p[1], p[2]});
        write_array(out, "Float64", "Points", 3, xyz);
        out << "</Points>\n<Cells>\n";
        const int per = mesh.cell_size();
        std::vector<std::int64_t> connectivity(mesh.cells.begin(), mesh.cells.end()), offsets(m);
        for (std::size_t c = 0; c < m; ++c) offsets[c] = static_cast<std::int64_t>((c + 1) * per);
        std::vector<std::uint8_t> types(m, mesh.cell_type == CellType::hexahedron ? 12 : 10);
        write_array(out, "Int64", "connectivity", 1, connectivity);
        write_array(out, "Int64", "offsets", 1, offsets);
        write_array(out, "UInt8", "types", 1, types);
        out << "</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
        out.close();
        if (!out) fail("'{}': write failed: {}", path.string(), std::strerror(errno));
    });
}

VolumeMesh read_vtu(const fs::path& path, MeshData* data)
{
    const std::string what = "VTU '" + path.string() + "'";
    require_existing_file(path, what);
    std::ifstream in(path, std::ios::binary);
    if (!in) fail("{}: cannot open file", what);
    std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    Decoder decoder;
    decoder.what = what;
    // Raw appended data is not XML: cut it out before parsing.
    const auto appended_at = content.find("<AppendedData");
    if (appended_at != std::string::npos) {
        const auto underscore = content.find('_', content.find('>', appended_at));
        const auto end = content.rfind("</AppendedData>");
        if (underscore == std::string::npos || end == std::string::npos || end < underscore)
            fail("{}: truncated appended data section", what);
        decoder.appended = content.substr(underscore + 1, end - underscore - 1);
        decoder.appended_base64 = content.substr(appended_at, underscore - appended_at).find("base64") != std::string::npos;
        content = content.substr(0, appended_at) + "</UnstructuredGrid></VTKFile>";
    }
    pugi::xml_document doc;
    const auto parsed = doc.load_string(content.c_str());
    if (!parsed) fail("{}: not valid XML ({} at byte {}): corrupt or truncated", what, parsed.description(), parsed.offset);
    const auto root = doc.child("VTKFile");
    if (!root || std::string(root.attribute("type").as_string()) != "UnstructuredGrid")
        fail("{}: not a VTK UnstructuredGrid file", what);
    decoder.big_endian = std::string(root.attribute("byte_order").as_string("LittleEndian")) == "BigEndian";
    decoder.header64 = std::string(root.attribute("header_type").as_string("UInt32")) == "UInt64";
    const std::string compressor = root.attribute("compressor").as_string();
    if (!compressor.empty() && compressor != "vtkZLibDataCompressor")
        fail("{}: compressor '{}' is not supported (zlib only)", what, compressor);
    decoder.zlib = !compressor.empty();
    const auto grid_node = root.child("UnstructuredGrid");
    const auto piece = grid_node.child("Piece");
    if (!piece) fail("{}: no Piece element", what);
    if (piece.next_sibling("Piece")) fail("{}: several pieces are not supported", what);
    const std::size_t n = piece.attribute("NumberOfPoints").as_ullong();
    const std::size_t m = piece.attribute("NumberOfCells").as_ullong();
    int components = 0;
    const auto points = decoder.read(piece.child("Points").child("DataArray"), n, components);
    if (components != 3) fail("{}: points have {} components", what, components);
    auto cell_array = [&](const char* name, std::size_t expected) {
        for (auto a : piece.child("Cells").children("DataArray"))
            if (std::string(a.attribute("Name").as_string()) == name) return decoder.read(a, expected, components);
        fail("{}: missing cell array '{}'", what, name);
    };
    const auto offsets = cell_array("offsets", m);
    const auto types = cell_array("types", m);
    const auto connectivity = cell_array("connectivity", m ? to_integer<std::uint32_t>(offsets.back(), what, "the last cell offset") : 0);

    VolumeMesh mesh;
    mesh.nodes.resize(n);
    for (std::size_t i = 0; i < n; ++i) mesh.nodes[i] = Vec3(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
    int volume_type = 0;
    std::vector<std::size_t> kept;
    for (std::size_t c = 0; c < m; ++c) {
        const int t = to_integer<std::uint8_t>(types[c], what, "a cell type");
        if (t == 10 || t == 12) {
            if (volume_type && volume_type != t) fail("{}: mixes tetrahedra and hexahedra (one cell type per mesh)", what);
            volume_type = t;
            kept.push_back(c);
        } else if (t == 13 || t == 14 || t == 24 || t == 25 || t == 42) {
            fail("{}: cell {} has VTK type {}; only tetrahedra (10) and hexahedra (12) are supported", what, c, t);
        }
    }
    if (kept.size() != m) logger()->info("{}: skipped {} surface/line/vertex cells", what, m - kept.size());
    if (kept.empty()) fail("{}: holds no tetrahedra or hexahedra", what);
    mesh.cell_type = volume_type == 12 ? CellType::hexahedron : CellType::tetrahedron;
    const int per = mesh.cell_size();
    for (auto c : kept) {
        const std::size_t begin = c ? to_integer<std::uint32_t>(offsets[c - 1], what, "a cell offset") : 0;
        const std::size_t end = to_integer<std::uint32_t>(offsets[c], what, "a cell offset");
        if (end < begin || end - begin != static_cast<std::size_t>(per))
            fail("{}: cell {} has {} nodes, expected {}", what, c, offsets[c] - double(begin), per);
        if (end > connectivity.size()) fail("{}: cell {} reaches past the connectivity array", what, c);
        for (int v = 0; v < per; ++v) mesh.cells.push_back(to_integer<std::int32_t>(connectivity[begin + v], what, "a node id"));
    }
    MeshData local;
    for (auto a : piece.child("PointData").children("DataArray")) {
        DataArray d;
        d.name = a.attribute("Name").as_string();
        d.values = decoder.read(a, n, d.components);
        local.point_data.push_back(std::move(d));
    }
    for (auto a : piece.child("CellData").children("DataArray")) {
        DataArray d;
        d.name = a.attribute("Name").as_string();
        d.values = decoder.read(a, m, d.components);
        // Keep only the volume cells' values.
        std::vector<double> picked;
        for (auto c : kept)
            for (int k = 0; k < d.components; ++k) picked.push_back(d.values[c * d.components + k]);
        d.values = std::move(picked);
        local.cell_data.push_back(std::move(d));
    }
    const DataArray* labels = nullptr;
    for (const char* name : {"tissue", "gmsh:physical", "CellEntityIds", "MaterialIds"})
        if (!labels) labels = local.find_cell(name);
    mesh.cell_labels.assign(kept.size(), 1);
    if (labels) {
        if (labels->components != 1) fail("{}: cell labels '{}' have {} components", what, labels->name, labels->components);
        for (std::size_t c = 0; c < kept.size(); ++c) mesh.cell_labels[c] = to_integer<std::int32_t>(labels->values[c], what, "a cell label");
    }
    // The grid a physreg mesh was built on.
    const DataArray* grid_index = local.find_cell("grid_index");
    for (auto a : grid_node.child("FieldData").children("DataArray")) {
        if (std::string(a.attribute("Name").as_string()) != "physreg_grid" || !grid_index) continue;
        const auto v = decoder.read(a, 1, components);
        if (components != 18) fail("{}: field data physreg_grid has {} values, expected 18", what, components);
        HexGrid g;
        g.origin = Vec3(v[0], v[1], v[2]);
        g.cell_size = Vec3(v[3], v[4], v[5]);
        for (int c = 0; c < 3; ++c)
            for (int r = 0; r < 3; ++r) g.direction(r, c) = v[6 + 3 * c + r];
        g.dims = {to_integer<std::int32_t>(v[15], what, "physreg_grid dims"), to_integer<std::int32_t>(v[16], what, "physreg_grid dims"),
                  to_integer<std::int32_t>(v[17], what, "physreg_grid dims")};
        mesh.grid = g;
        for (std::size_t c = 0; c < kept.size(); ++c) {
            Index3 ijk{to_integer<std::int32_t>(grid_index->values[3 * c], what, "grid_index"),
                       to_integer<std::int32_t>(grid_index->values[3 * c + 1], what, "grid_index"),
                       to_integer<std::int32_t>(grid_index->values[3 * c + 2], what, "grid_index")};
            for (int k = 0; k < 3; ++k)
                if (ijk[k] < 0 || ijk[k] >= g.dims[k]) fail("{}: cell {} grid index out of the grid", what, c);
            mesh.cell_grid_index.push_back(ijk);
        }
    }
    mesh.validate(what);
    if (data) {
        std::erase_if(local.cell_data, [](const DataArray& a) { return a.name == "tissue" || a.name == "grid_index"; });
        *data = std::move(local);
    }
    return mesh;
}

} // namespace physreg
