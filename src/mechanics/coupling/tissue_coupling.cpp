// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/coupling/tissue_coupling.hpp"

#include "physreg/core/error.hpp"

#include <cmath>
#include <unordered_map>

namespace physreg {

std::string to_string(TissueGroup group)
{
    switch (group) {
    case TissueGroup::parenchyma: return "parenchyma";
    case TissueGroup::tumour: return "tumour";
    case TissueGroup::vessel: return "vessel";
    }
    return "?";
}

void CouplingStiffness::validate() const
{
    const std::pair<const char*, double> values[] = {{"k_c,s-t (parenchyma–tumour coupling stiffness)", parenchyma_tumour_n_per_m},
                                                     {"k_c,s-v (parenchyma–vessel coupling stiffness)", parenchyma_vessel_n_per_m}};
    for (const auto& [name, value] : values)
        if (!std::isfinite(value) || value < 0.0) fail("{} must be a finite value ≥ 0 N/m (got {})", name, value);
}

double CouplingStiffness::n_per_mm(CouplingKind kind) const
{
    // N/m → N/mm.
    return (kind == CouplingKind::parenchyma_vessel ? parenchyma_vessel_n_per_m : parenchyma_tumour_n_per_m) * 1e-3;
}

PenaltyCoupling::PenaltyCoupling(std::vector<InterfacePoint> points, std::size_t node_count, const CouplingStiffness& stiffness)
    : m_points(std::move(points)), m_node_count(node_count)
{
    m_begin.reserve(m_points.size() + 1);
    m_begin.push_back(0);
    for (const auto& p : m_points) {
        for (std::size_t j = 0; j < p.first.nodes.size(); ++j) m_entries.push_back({p.first.nodes[j], p.first.phi[j]});
        for (std::size_t j = 0; j < p.second.nodes.size(); ++j) m_entries.push_back({p.second.nodes[j], -p.second.phi[j]});
        m_begin.push_back(static_cast<std::int64_t>(m_entries.size()));
    }
    for (const auto& e : m_entries)
        if (e.node < 0 || static_cast<std::size_t>(e.node) >= node_count) fail("coupling: support node {} out of range ({} nodes)", e.node, node_count);
    set_stiffness(stiffness);
}

void PenaltyCoupling::set_stiffness(const CouplingStiffness& stiffness)
{
    stiffness.validate();
    m_stiffness = stiffness;
    m_k.resize(m_points.size());
    for (std::size_t i = 0; i < m_points.size(); ++i) m_k[i] = stiffness.n_per_mm(m_points[i].kind);
}

std::vector<Vec3> PenaltyCoupling::gaps_mm(std::span<const double> u) const
{
    if (u.size() != 3 * m_node_count) fail("coupling: {} displacement values for {} nodes", u.size(), m_node_count);
    std::vector<Vec3> gaps(m_points.size(), Vec3::Zero());
    for (std::size_t i = 0; i < m_points.size(); ++i)
        for (std::int64_t q = m_begin[i]; q < m_begin[i + 1]; ++q) {
            const auto n = 3 * static_cast<std::size_t>(m_entries[q].node);
            gaps[i] += m_entries[q].phi * Vec3(u[n], u[n + 1], u[n + 2]);
        }
    return gaps;
}

double PenaltyCoupling::energy_mj(std::span<const double> u) const
{
    const auto gaps = gaps_mm(u);
    double e = 0.0;
    for (std::size_t i = 0; i < gaps.size(); ++i) e += 0.5 * m_k[i] * gaps[i].squaredNorm();
    return e;
}

template <typename Real>
void PenaltyCoupling::add_forces(const Real* u, Real* f) const
{
    // Serial: each point scatters into a few dozen nodes; a few thousand points cost far less than
    // the element loop, and a fixed order keeps results identical for any thread count.
    for (std::size_t i = 0; i < m_points.size(); ++i) {
        double d[3] = {0, 0, 0};
        for (std::int64_t q = m_begin[i]; q < m_begin[i + 1]; ++q) {
            const auto n = 3 * static_cast<std::size_t>(m_entries[q].node);
            for (int c = 0; c < 3; ++c) d[c] += m_entries[q].phi * double(u[n + c]);
        }
        for (int c = 0; c < 3; ++c) d[c] *= m_k[i];
        for (std::int64_t q = m_begin[i]; q < m_begin[i + 1]; ++q) {
            const auto n = 3 * static_cast<std::size_t>(m_entries[q].node);
            for (int c = 0; c < 3; ++c) f[n + c] += static_cast<Real>(m_entries[q].phi * d[c]);
        }
    }
}

template void PenaltyCoupling::add_forces<float>(const float*, float*) const;
template void PenaltyCoupling::add_forces<double>(const double*, double*) const;

std::vector<double> PenaltyCoupling::stiffness_bound() const
{
    // ∂²E/∂u_j∂u_l = k φ_j φ_l I per point: row sum of node j is k |φ_j| Σ_l |φ_l|.
    std::vector<double> bound(m_node_count, 0.0);
    for (std::size_t i = 0; i < m_points.size(); ++i) {
        double row = 0.0;
        for (std::int64_t q = m_begin[i]; q < m_begin[i + 1]; ++q) row += std::abs(m_entries[q].phi);
        for (std::int64_t q = m_begin[i]; q < m_begin[i + 1]; ++q)
            bound[static_cast<std::size_t>(m_entries[q].node)] += m_k[i] * std::abs(m_entries[q].phi) * row;
    }
    return bound;
}

void CouplingOptions::validate() const
{
    if (!(support_radius_cells >= 1.0) || !std::isfinite(support_radius_cells))
        fail("coupling support radius must be ≥ 1 element size (got {})", support_radius_cells);
}

namespace {

// Nodes of one tissue binned on a uniform grid for radius queries.
class NodeBins {
public:
    NodeBins(const std::vector<Vec3>& positions, const std::vector<std::int32_t>& nodes, const Vec3& bin_size)
        : m_positions(positions), m_bin(bin_size)
    {
        for (const auto n : nodes) m_bins[key(cell(positions[static_cast<std::size_t>(n)]))].push_back(n);
    }
    std::vector<std::int32_t> within(const Vec3& x, const Vec3& radius) const
    {
        std::vector<std::int32_t> out;
        const Index3 lo = cell(x - radius), hi = cell(x + radius);
        for (std::int64_t k = lo[2]; k <= hi[2]; ++k)
            for (std::int64_t j = lo[1]; j <= hi[1]; ++j)
                for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
                    const auto it = m_bins.find(key({i, j, k}));
                    if (it == m_bins.end()) continue;
                    for (const auto n : it->second)
                        if ((m_positions[static_cast<std::size_t>(n)] - x).cwiseQuotient(radius).norm() <= 1.0) out.push_back(n);
                }
        return out;
    }

private:
    Index3 cell(const Vec3& x) const
    {
        return {static_cast<std::int64_t>(std::floor(x.x() / m_bin.x())), static_cast<std::int64_t>(std::floor(x.y() / m_bin.y())),
                static_cast<std::int64_t>(std::floor(x.z() / m_bin.z()))};
    }
    static std::int64_t key(const Index3& c) { return (c[0] & 0x1FFFFF) | ((c[1] & 0x1FFFFF) << 21) | ((c[2] & 0x1FFFFF) << 42); }
    const std::vector<Vec3>& m_positions;
    Vec3 m_bin;
    std::unordered_map<std::int64_t, std::vector<std::int32_t>> m_bins;
};

// Element size along each LPS axis: grid meshes from their cells, others from the mean edge length.
Vec3 element_size(const VolumeMesh& mesh)
{
    if (mesh.grid) {
        Vec3 h = Vec3::Zero();
        for (int a = 0; a < 3; ++a) h += (mesh.grid->direction.col(a) * mesh.grid->cell_size[a]).cwiseAbs();
        return h;
    }
    double sum = 0.0;
    std::size_t count = 0;
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const auto cell = mesh.cell(c);
        for (std::size_t a = 1; a < cell.size(); ++a) {
            sum += (mesh.nodes[static_cast<std::size_t>(cell[a])] - mesh.nodes[static_cast<std::size_t>(cell[0])]).norm();
            ++count;
        }
    }
    return Vec3::Constant(count ? sum / double(count) : 1.0);
}

} // namespace

SplitMesh split_tissue_interfaces(const VolumeMesh& mesh, const std::map<std::int32_t, TissueGroup>& groups,
                                  const CouplingStiffness& stiffness, const CouplingOptions& options)
{
    options.validate();
    stiffness.validate();
    mesh.validate("coupling mesh");
    const std::size_t n0 = mesh.node_count();
    std::vector<TissueGroup> cell_group(mesh.cell_count());
    std::vector<std::uint8_t> present(n0, 0); // bit g: a cell of group g uses the vertex
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const auto it = groups.find(mesh.cell_labels[c]);
        if (it == groups.end()) fail("coupling: cell label {} has no tissue group (parenchyma, tumour or vessel)", mesh.cell_labels[c]);
        cell_group[c] = it->second;
        for (const auto n : mesh.cell(c)) present[static_cast<std::size_t>(n)] |= std::uint8_t(1u << static_cast<int>(it->second));
    }
    SplitMesh out;
    out.mesh = mesh;
    out.original_vertex.resize(n0);
    out.node_group.resize(n0);
    // copy[3 n + g]: node id of vertex n's copy in group g (the lowest group present keeps id n).
    std::vector<std::int32_t> copy(3 * n0, -1);
    for (std::size_t n = 0; n < n0; ++n) {
        out.original_vertex[n] = static_cast<std::int32_t>(n);
        bool first = true;
        for (int g = 0; g < 3; ++g) {
            if (!(present[n] & (1u << g))) continue;
            if (first) {
                copy[3 * n + g] = static_cast<std::int32_t>(n);
                out.node_group[n] = static_cast<TissueGroup>(g);
                first = false;
            } else {
                copy[3 * n + g] = static_cast<std::int32_t>(out.mesh.nodes.size());
                out.mesh.nodes.push_back(mesh.nodes[n]);
                out.original_vertex.push_back(static_cast<std::int32_t>(n));
                out.node_group.push_back(static_cast<TissueGroup>(g));
            }
        }
    }
    const int npc = mesh.cell_size();
    for (std::size_t c = 0; c < mesh.cell_count(); ++c)
        for (int a = 0; a < npc; ++a) {
            auto& id = out.mesh.cells[c * npc + a];
            id = copy[3 * static_cast<std::size_t>(id) + static_cast<int>(cell_group[c])];
        }
    // MLS support domains: nodes of each group, binned.
    const Vec3 h = element_size(mesh);
    MlsOptions mls = options.mls;
    mls.support_radius_mm = options.support_radius_cells * h;
    mls.validate();
    const Vec3 largest = mls.support_radius_mm * std::pow(mls.growth, mls.max_growths);
    std::vector<std::vector<std::int32_t>> members(3);
    for (std::size_t n = 0; n < out.mesh.node_count(); ++n) members[static_cast<int>(out.node_group[n])].push_back(static_cast<std::int32_t>(n));
    std::vector<NodeBins> bins;
    for (int g = 0; g < 3; ++g) bins.emplace_back(out.mesh.nodes, members[g], largest);
    std::vector<InterfacePoint> points;
    for (std::size_t n = 0; n < n0; ++n) {
        const std::uint8_t bits = present[n];
        if (bits == 1 || bits == 2 || bits == 4) continue;
        auto side = [&](int g) {
            const auto candidates = bins[g].within(mesh.nodes[n], largest);
            return mls_shape_functions(mesh.nodes[n], candidates, out.mesh.nodes, mls,
                                       fmt::format("coupling, {} side of interface vertex {}", to_string(TissueGroup(g)), n));
        };
        const std::pair<int, int> pairs[] = {{0, 1}, {0, 2}, {1, 2}};
        for (const auto& [a, b] : pairs) {
            if (!(bits & (1u << a)) || !(bits & (1u << b))) continue;
            InterfacePoint p;
            p.vertex = static_cast<std::int32_t>(n);
            p.rest_mm = mesh.nodes[n];
            p.kind = a == 0 ? (b == 1 ? CouplingKind::parenchyma_tumour : CouplingKind::parenchyma_vessel) : CouplingKind::tumour_vessel;
            p.first = side(a);
            p.second = side(b);
            points.push_back(std::move(p));
        }
    }
    out.coupling = PenaltyCoupling(std::move(points), out.mesh.node_count(), stiffness);
    return out;
}

} // namespace physreg
