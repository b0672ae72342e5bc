// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/compression/enrichment.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"

#include <cerrno>
#include <Eigen/Dense>
#include <nlohmann/json.hpp>
#include <zlib.h>

#include <cmath>
#include <cstring>
#include <fstream>

namespace physreg {
namespace {

using json = nlohmann::json;
constexpr char magic[8] = {'P', 'H', 'Y', 'S', 'E', 'N', 'R', 'D'};
constexpr char end_magic[8] = {'E', 'N', 'D', 'E', 'N', 'R', 'D', '.'};
constexpr std::uint32_t format_version = 1;
constexpr double weight_floor = 0.05;

// The coarse element's deformed nodes and centroid.
void element_nodes(const VolumeMesh& coarse, const std::vector<double>& u, std::int32_t cell, std::array<Vec3, 8>& p, Vec3& centre)
{
    centre.setZero();
    const auto ids = coarse.cell(static_cast<std::size_t>(cell));
    for (int a = 0; a < 8; ++a) {
        const auto n = static_cast<std::size_t>(ids[a]);
        p[a] = coarse.nodes[n] + Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]);
        centre += p[a] / 8.0;
    }
}

std::uint32_t crc(const void* data, std::size_t bytes, std::uint32_t seed = 0)
{
    return static_cast<std::uint32_t>(crc32(seed, static_cast<const Bytef*>(data), static_cast<uInt>(bytes)));
}

} // namespace

std::vector<float> enrichment_weights(const VolumeMesh& coarse, const std::vector<double>& coarse_u, const std::vector<NodeEmbedding>& fine_nodes,
                                      const std::vector<Vec3>& fine_rest, const std::vector<double>& fine_u)
{
    if (coarse.cell_type != CellType::hexahedron) fail("enrichment: the coarse mesh must be hexahedral");
    if (coarse_u.size() != 3 * coarse.node_count() || fine_u.size() != 3 * fine_rest.size() || fine_nodes.size() != fine_rest.size())
        fail("enrichment: {} coarse / {} fine displacement values for {} coarse / {} fine nodes", coarse_u.size(), fine_u.size(),
             coarse.node_count(), fine_rest.size());
    std::vector<float> phi(8 * fine_rest.size());
    using Mat4 = Eigen::Matrix4d;
    using Vec4 = Eigen::Vector4d;
    for (std::size_t j = 0; j < fine_rest.size(); ++j) {
        std::array<Vec3, 8> p;
        Vec3 c;
        element_nodes(coarse, coarse_u, fine_nodes[j].cell, p, c);
        const Vec3 x = fine_rest[j] + Vec3(fine_u[3 * j], fine_u[3 * j + 1], fine_u[3 * j + 2]);
        double h = 0.0;
        for (const auto& q : p) h = std::max(h, (q - c).norm());
        const auto n = hex_shape_functions(fine_nodes[j].natural.cwiseMax(-1.0).cwiseMin(1.0));
        // Basis centred at x, scaled by the element size: Φ_a = w_a p_aᵀ A⁻¹ e₁.
        Mat4 a = Mat4::Zero();
        std::array<Vec4, 8> basis;
        std::array<double, 8> w;
        for (int k = 0; k < 8; ++k) {
            const Vec3 r = (p[k] - x) / h;
            basis[k] = Vec4(1.0, r.x(), r.y(), r.z());
            w[k] = n[k] + weight_floor;
            a += w[k] * basis[k] * basis[k].transpose();
        }
        const Vec4 row = a.ldlt().solve(Vec4::UnitX());
        if (!row.allFinite()) fail("enrichment: coarse element {} is degenerate (fine node {})", fine_nodes[j].cell, j);
        for (int k = 0; k < 8; ++k) phi[8 * j + k] = static_cast<float>(w[k] * row.dot(basis[k]));
    }
    return phi;
}

std::vector<double> synthesize_fine_displacement(const VolumeMesh& coarse, const std::vector<double>& coarse_u,
                                                 const std::vector<NodeEmbedding>& fine_nodes, const std::vector<Vec3>& fine_rest,
                                                 const std::vector<float>& phi)
{
    if (coarse_u.size() != 3 * coarse.node_count() || phi.size() != 8 * fine_rest.size() || fine_nodes.size() != fine_rest.size())
        fail("enrichment synthesis: {} coarse values for {} nodes, {} weights for {} fine nodes", coarse_u.size(), coarse.node_count(),
             phi.size(), fine_rest.size());
    std::vector<double> u(3 * fine_rest.size());
    for (std::size_t j = 0; j < fine_rest.size(); ++j) {
        std::array<Vec3, 8> p;
        Vec3 c;
        element_nodes(coarse, coarse_u, fine_nodes[j].cell, p, c);
        Vec3 x = c;
        for (int k = 0; k < 8; ++k) x += double(phi[8 * j + k]) * (p[k] - c);
        const Vec3 d = x - fine_rest[j];
        for (int k = 0; k < 3; ++k) u[3 * j + k] = d[k];
    }
    return u;
}

void synthesize_fine_subset(const VolumeMesh& coarse, const std::vector<double>& coarse_u, const std::vector<NodeEmbedding>& fine_nodes,
                            const std::vector<Vec3>& fine_rest, const EnrichmentDatabase& db, const EnrichmentMatch& match,
                            const std::vector<std::int32_t>& subset, std::vector<double>& fine_u)
{
    if (coarse_u.size() != 3 * coarse.node_count() || fine_u.size() != 3 * fine_rest.size() || fine_nodes.size() != fine_rest.size())
        fail("enrichment synthesis: {} coarse values for {} nodes, {} fine values for {} fine nodes", coarse_u.size(), coarse.node_count(),
             fine_u.size(), fine_rest.size());
    if (match.conditions.empty() || match.conditions.size() != match.blend.size()) fail("enrichment synthesis: empty match");
    for (const auto node : subset) {
        if (node < 0 || static_cast<std::size_t>(node) >= fine_rest.size()) fail("enrichment synthesis: fine node {} out of range", node);
        const auto j = static_cast<std::size_t>(node);
        std::array<Vec3, 8> p;
        Vec3 c;
        element_nodes(coarse, coarse_u, fine_nodes[j].cell, p, c);
        Vec3 x = c;
        const auto n = hex_shape_functions(fine_nodes[j].natural);
        for (int k = 0; k < 8; ++k) {
            double phi = 0.0; // the blend of the matched conditions' weights (blended_weights, for one node)
            for (std::size_t m = 0; m < match.conditions.size(); ++m) phi += match.blend[m] * double(db.weights[match.conditions[m]][8 * j + static_cast<std::size_t>(k)]);
            if (match.detail < 1.0) phi = match.detail * phi + (1.0 - match.detail) * n[static_cast<std::size_t>(k)];
            x += static_cast<double>(static_cast<float>(phi)) * (p[static_cast<std::size_t>(k)] - c);
        }
        const Vec3 d = x - fine_rest[j];
        for (int k = 0; k < 3; ++k) fine_u[3 * j + static_cast<std::size_t>(k)] = d[k];
    }
}

Index3 EnrichmentDatabase::coarse_grid() const
{
    try {
        const auto g = json::parse(model_json).at("coarse_grid").get<std::vector<std::int64_t>>();
        if (g.size() == 3) return {g[0], g[1], g[2]};
    } catch (const json::exception&) {
    }
    fail("enrichment database: its model parameters lack the coarse grid");
}

void EnrichmentDatabase::validate(const std::string& what) const
{
    if (coarse_displacement.size() != conditions.size() || weights.size() != conditions.size())
        fail("{}: {} conditions but {} coarse fields and {} weight sets", what, conditions.size(), coarse_displacement.size(), weights.size());
    for (std::size_t t = 0; t < conditions.size(); ++t) {
        if (coarse_displacement[t].size() != 3 * coarse_nodes || weights[t].size() != 8 * fine_nodes)
            fail("{}: condition {} holds {} coarse values and {} weights (expected {} and {})", what, t, coarse_displacement[t].size(),
                 weights[t].size(), 3 * coarse_nodes, 8 * fine_nodes);
        for (const float v : coarse_displacement[t])
            if (!std::isfinite(v)) fail("{}: condition {} has a non-finite coarse displacement", what, t);
        for (const float v : weights[t])
            if (!std::isfinite(v)) fail("{}: condition {} has a non-finite weight", what, t);
        if (!conditions[t].contact_mm.allFinite() || !conditions[t].direction.allFinite() || !std::isfinite(conditions[t].depth_mm))
            fail("{}: condition {} has non-finite tool parameters", what, t);
    }
}

std::string serialize_enrichment_database(const EnrichmentDatabase& db)
{
    db.validate("enrichment database");
    json header;
    header["fine_fingerprint"] = db.fine_fingerprint;
    header["coarse_fingerprint"] = db.coarse_fingerprint;
    header["model"] = db.model_json.empty() ? json::object() : json::parse(db.model_json);
    header["fine_nodes"] = db.fine_nodes;
    header["coarse_nodes"] = db.coarse_nodes;
    header["units"] = "mm; weights dimensionless (float32); coarse displacement float32 mm";
    header["conditions"] = json::array();
    for (const auto& c : db.conditions)
        header["conditions"].push_back({{"position", c.position},
                                        {"contact_mm", {c.contact_mm.x(), c.contact_mm.y(), c.contact_mm.z()}},
                                        {"direction", {c.direction.x(), c.direction.y(), c.direction.z()}},
                                        {"depth_mm", c.depth_mm}});
    const std::string text = header.dump();
    std::string out;
    std::uint32_t whole = 0;
    auto put = [&](const void* data, std::size_t bytes) {
        out.append(static_cast<const char*>(data), bytes);
        whole = crc(data, bytes, whole);
    };
    put(magic, sizeof magic);
    put(&format_version, sizeof format_version);
    const std::uint64_t header_bytes = text.size();
    put(&header_bytes, sizeof header_bytes);
    put(text.data(), text.size());
    for (std::size_t t = 0; t < db.conditions.size(); ++t) {
        const auto& u = db.coarse_displacement[t];
        const auto& w = db.weights[t];
        const std::uint32_t block = crc(w.data(), w.size() * sizeof(float), crc(u.data(), u.size() * sizeof(float)));
        put(u.data(), u.size() * sizeof(float));
        put(w.data(), w.size() * sizeof(float));
        put(&block, sizeof block);
    }
    put(end_magic, sizeof end_magic);
    out.append(reinterpret_cast<const char*>(&whole), sizeof whole);
    return out;
}

void write_enrichment_database(const std::filesystem::path& path, const EnrichmentDatabase& db)
{
    db.validate("enrichment database '" + path.string() + "'");
    const std::string bytes = serialize_enrichment_database(db);
    write_atomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp, std::ios::binary);
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
        if (!out) fail("cannot write enrichment database '{}': {}", path.string(), std::strerror(errno));
    });
}

EnrichmentDatabase read_enrichment_database(const std::filesystem::path& path)
{
    require_existing_file(path, "enrichment database '" + path.string() + "'");
    std::ifstream in(path, std::ios::binary);
    if (!in) fail("enrichment database '{}': cannot open", path.string());
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return deserialize_enrichment_database(bytes, "enrichment database '" + path.string() + "'");
}

EnrichmentDatabase deserialize_enrichment_database(const std::string& bytes, const std::string& name)
{
    const std::uint64_t file_bytes = bytes.size();
    std::uint32_t whole = 0;
    std::uint64_t consumed = 0;
    auto get = [&](void* data, std::size_t n, const char* what) {
        if (consumed + n > file_bytes) fail("{}: truncated ({} bytes; ended inside the {})", name, file_bytes, what);
        std::memcpy(data, bytes.data() + consumed, n);
        consumed += n;
        whole = crc(data, n, whole);
    };
    char m[8];
    get(m, sizeof m, "magic");
    if (std::memcmp(m, magic, sizeof m) != 0) fail("{}: not a physreg enrichment database (bad magic)", name);
    std::uint32_t version = 0;
    get(&version, sizeof version, "version");
    if (version != format_version) fail("{}: format version {} (this physreg reads {})", name, version, format_version);
    std::uint64_t header_bytes = 0;
    get(&header_bytes, sizeof header_bytes, "header size");
    if (header_bytes > file_bytes) fail("{}: truncated or corrupt header size ({} bytes)", name, header_bytes);
    std::string text(header_bytes, '\0');
    get(text.data(), text.size(), "header");
    EnrichmentDatabase db;
    try {
        const json h = json::parse(text);
        db.fine_fingerprint = h.at("fine_fingerprint").get<std::string>();
        db.coarse_fingerprint = h.at("coarse_fingerprint").get<std::string>();
        db.model_json = h.at("model").dump();
        db.fine_nodes = h.at("fine_nodes").get<std::uint64_t>();
        db.coarse_nodes = h.at("coarse_nodes").get<std::uint64_t>();
        for (const auto& c : h.at("conditions")) {
            const auto p = c.at("contact_mm").get<std::vector<double>>(), d = c.at("direction").get<std::vector<double>>();
            if (p.size() != 3 || d.size() != 3) fail("{}: a condition's vectors need 3 values", name);
            db.conditions.push_back({c.at("position").get<std::string>(), Vec3(p[0], p[1], p[2]), Vec3(d[0], d[1], d[2]), c.at("depth_mm").get<double>()});
        }
    } catch (const json::exception& e) {
        fail("{}: corrupt header: {}", name, e.what());
    }
    const std::uint64_t block_bytes = (3 * db.coarse_nodes + 8 * db.fine_nodes) * sizeof(float) + sizeof(std::uint32_t);
    const std::uint64_t expected = consumed + block_bytes * db.conditions.size() + sizeof end_magic + sizeof(std::uint32_t);
    if (file_bytes != expected)
        fail("{}: {} bytes, expected {} for {} conditions ({})", name, file_bytes, expected, db.conditions.size(),
             file_bytes < expected ? "truncated" : "trailing data");
    for (std::size_t t = 0; t < db.conditions.size(); ++t) {
        std::vector<float> u(3 * db.coarse_nodes), w(8 * db.fine_nodes);
        get(u.data(), u.size() * sizeof(float), "coarse displacements");
        get(w.data(), w.size() * sizeof(float), "weights");
        std::uint32_t stored = 0;
        get(&stored, sizeof stored, "block checksum");
        const std::uint32_t actual = crc(w.data(), w.size() * sizeof(float), crc(u.data(), u.size() * sizeof(float)));
        if (stored != actual)
            fail("{}: checksum mismatch in condition {} ({} {:.2f} mm): the file is corrupt", name, t, db.conditions[t].position,
                 db.conditions[t].depth_mm);
        db.coarse_displacement.push_back(std::move(u));
        db.weights.push_back(std::move(w));
    }
    char e[8];
    get(e, sizeof e, "end marker");
    std::uint32_t stored_whole = 0;
    std::memcpy(&stored_whole, bytes.data() + consumed, sizeof stored_whole);
    if (std::memcmp(e, end_magic, sizeof e) != 0 || stored_whole != whole)
        fail("{}: checksum mismatch in the header or end marker: the file is corrupt", name);
    db.validate(name);
    return db;
}

} // namespace physreg
