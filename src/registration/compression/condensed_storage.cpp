// SPDX-License-Identifier: GPL-3.0-or-later
// The condensed contact's compliance on disk (physreg prepare → serve). Layout, little-endian:
//   "PHYSREG-CONDENSED\n" | u32 version | u64 dofs, constrained dofs, candidates c, query q, outside o
//   | f64 stiffness probe | i32 × (c + q + o) | f64 × 3c·3c (W_cc) | f64 × 3q·3c (W_qc), column-major
//   | f64 assembly, factorisation, compliance seconds, factor nonzeros | u32 CRC-32 of everything before
// The sizes are checked against the file's length before anything is allocated.
#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/registration/compression/condensed_contact.hpp"

#include <zlib.h>

#include <cstring>
#include <fstream>
#include <iterator>

namespace physreg {
namespace {

constexpr char magic[] = "PHYSREG-CONDENSED\n";
constexpr std::uint32_t format_version = 1;

class Writer {
public:
    template <class T>
    void put(const T* data, std::size_t count)
    {
        const std::size_t at = m_bytes.size(), n = count * sizeof(T);
        m_bytes.resize(at + n);
        if (n > 0) std::memcpy(m_bytes.data() + at, data, n);
    }
    template <class T>
    void put(T value) { put(&value, 1); }
    std::vector<char>& bytes() { return m_bytes; }

private:
    std::vector<char> m_bytes;
};

class Reader {
public:
    Reader(const std::vector<char>& bytes, std::string name) : m_bytes(bytes), m_name(std::move(name)) {}
    template <class T>
    void get(T* data, std::size_t count, const char* what)
    {
        if (count > (m_bytes.size() - m_at) / sizeof(T)) fail("condensed compliance '{}': truncated in {}", m_name, what);
        std::memcpy(data, m_bytes.data() + m_at, count * sizeof(T));
        m_at += count * sizeof(T);
    }
    template <class T>
    T get(const char* what)
    {
        T v{};
        get(&v, 1, what);
        return v;
    }
    std::size_t left() const { return m_bytes.size() - m_at; }

private:
    const std::vector<char>& m_bytes;
    std::string m_name;
    std::size_t m_at = 0;
};

std::uint32_t crc_of(const char* data, std::size_t bytes)
{
    std::uint32_t c = 0;
    while (bytes > 0) { // zlib takes 32-bit lengths
        const std::size_t n = std::min<std::size_t>(bytes, 1u << 30);
        c = static_cast<std::uint32_t>(crc32(c, reinterpret_cast<const Bytef*>(data), static_cast<uInt>(n)));
        data += n;
        bytes -= n;
    }
    return c;
}

} // namespace

void write_condensed_compliance(const std::filesystem::path& path, const CondensedCompliance& c)
{
    Writer w;
    w.put(magic, sizeof magic - 1);
    w.put(format_version);
    for (const std::size_t v : {c.dofs, c.constrained_dofs, c.candidates.size(), c.query.size(), c.outside.size()}) w.put(static_cast<std::uint64_t>(v));
    w.put(c.stiffness_probe);
    for (const auto* list : {&c.candidates, &c.query, &c.outside}) w.put(list->data(), list->size());
    w.put(c.wcc.data(), static_cast<std::size_t>(c.wcc.size()));
    w.put(c.wqc.data(), static_cast<std::size_t>(c.wqc.size()));
    const auto& p = c.precomputation;
    for (const double v : {p.assembly_s, p.factorisation_s, p.compliance_s, p.factor_nonzeros}) w.put(v);
    w.put(crc_of(w.bytes().data(), w.bytes().size()));
    write_atomically(path, [&](const std::filesystem::path& temporary) {
        std::ofstream out(temporary, std::ios::binary);
        out.write(w.bytes().data(), static_cast<std::streamsize>(w.bytes().size()));
        if (!out.flush()) fail("condensed compliance '{}': cannot write the file", path.string());
    });
}

CondensedCompliance read_condensed_compliance(const std::filesystem::path& path)
{
    const std::string name = path.string();
    std::ifstream in(path, std::ios::binary);
    if (!in) fail("condensed compliance '{}': cannot read the file", name);
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (bytes.size() < sizeof magic - 1 + 4 || std::memcmp(bytes.data(), magic, sizeof magic - 1) != 0)
        fail("condensed compliance '{}': not a physreg condensed-compliance file (wrong magic)", name);
    std::uint32_t stored_crc = 0;
    std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
    if (crc_of(bytes.data(), bytes.size() - 4) != stored_crc) fail("condensed compliance '{}': checksum mismatch: the file is corrupt or truncated", name);
    Reader r(bytes, name);
    std::vector<char> skip(sizeof magic - 1);
    r.get(skip.data(), skip.size(), "the magic");
    const auto version = r.get<std::uint32_t>("the version");
    if (version != format_version) fail("condensed compliance '{}': format version {} (this physreg reads {})", name, version, format_version);
    CondensedCompliance c;
    std::uint64_t sizes[5];
    r.get(sizes, 5, "the sizes");
    c.dofs = sizes[0];
    c.constrained_dofs = sizes[1];
    const std::uint64_t nc = sizes[2], nq = sizes[3], no = sizes[4];
    c.stiffness_probe = r.get<double>("the stiffness probe");
    // Everything that follows, from the sizes alone: it must be what is left (before allocating).
    const long double expected = 4.0L * (nc + nq + no) + 8.0L * (9.0L * nc * nc + 9.0L * nq * nc) + 8.0L * 4 + 4;
    if (expected != static_cast<long double>(r.left()))
        fail("condensed compliance '{}': the sizes ({} candidates, {} query, {} outside nodes) do not match the file's length", name, nc, nq, no);
    for (auto [list, n] : {std::pair{&c.candidates, nc}, std::pair{&c.query, nq}, std::pair{&c.outside, no}}) {
        list->resize(n);
        r.get(list->data(), n, "the node lists");
    }
    c.wcc.resize(static_cast<Eigen::Index>(3 * nc), static_cast<Eigen::Index>(3 * nc));
    c.wqc.resize(static_cast<Eigen::Index>(3 * nq), static_cast<Eigen::Index>(3 * nc));
    r.get(c.wcc.data(), static_cast<std::size_t>(c.wcc.size()), "the candidates' compliance");
    r.get(c.wqc.data(), static_cast<std::size_t>(c.wqc.size()), "the query nodes' compliance");
    auto& p = c.precomputation;
    p.assembly_s = r.get<double>("the timings");
    p.factorisation_s = r.get<double>("the timings");
    p.compliance_s = r.get<double>("the timings");
    p.factor_nonzeros = r.get<double>("the timings");
    p.dofs = c.dofs;
    p.candidate_nodes = c.candidates.size();
    p.query_nodes = c.query.size();
    p.compliance_bytes = static_cast<std::size_t>(c.wcc.size() + c.wqc.size()) * sizeof(double);
    return c;
}

} // namespace physreg
