// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/elements/tled_model.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/faces.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

namespace physreg {

void TledOptions::validate() const
{
    if (!(hourglass_kappa >= 0.0 && hourglass_kappa < 1.0))
        fail("hourglass_kappa = {} is outside [0, 1)", hourglass_kappa);
    if (!(time_step_safety > 0.0 && time_step_safety <= 1.0))
        fail("time_step_safety = {} is outside (0, 1]: a larger step than the critical one is unstable", time_step_safety);
    if (!(damping_per_s >= 0.0 && std::isfinite(damping_per_s))) fail("damping_per_s = {} must be ≥ 0", damping_per_s);
    if (!(density_scale >= 1.0 && std::isfinite(density_scale))) fail("density_scale = {} must be ≥ 1", density_scale);
}

namespace {

// Signs of the hexahedron corners in natural coordinates (VTK order).
constexpr int sign_x[8] = {-1, 1, 1, -1, -1, 1, 1, -1};
constexpr int sign_y[8] = {-1, -1, 1, 1, -1, -1, 1, 1};
constexpr int sign_z[8] = {-1, -1, -1, -1, 1, 1, 1, 1};

ElementGeometry hexahedron_geometry(const std::array<Vec3, 8>& x, std::size_t element)
{
    ElementGeometry g;
    // Mean derivatives by exact 2×2×2 Gauss integration of ∂N/∂X det J.
    const double q = 1.0 / std::sqrt(3.0);
    std::array<Vec3, 8> b;
    b.fill(Vec3::Zero());
    double volume = 0.0;
    for (int p = 0; p < 8; ++p) {
        const Vec3 xi(q * sign_x[p], q * sign_y[p], q * sign_z[p]);
        std::array<Vec3, 8> dn_dxi;
        Mat3 jac = Mat3::Zero();
        for (int a = 0; a < 8; ++a) {
            dn_dxi[a] = Vec3(0.125 * sign_x[a] * (1 + sign_y[a] * xi[1]) * (1 + sign_z[a] * xi[2]),
                             0.125 * sign_y[a] * (1 + sign_x[a] * xi[0]) * (1 + sign_z[a] * xi[2]),
                             0.125 * sign_z[a] * (1 + sign_x[a] * xi[0]) * (1 + sign_y[a] * xi[1]));
            jac += x[a] * dn_dxi[a].transpose();
        }
        const double det = jac.determinant();
        if (!(det > 0.0)) fail("mesh: hexahedron {} is inverted or degenerate (det J = {:.3g} at a Gauss point)", element, det);
        const Mat3 inv_t = jac.inverse().transpose();
        for (int a = 0; a < 8; ++a) b[a] += det * (inv_t * dn_dxi[a]);
        volume += det;
    }
    g.volume_mm3 = volume;
    for (int a = 0; a < 8; ++a) {
        b[a] /= volume;
        for (int i = 0; i < 3; ++i) g.dn_dx[3 * a + i] = b[a][i];
        g.b_squared += b[a].squaredNorm();
    }
    // Hourglass base vectors ξη, ηζ, ζξ, ξηζ and their Γ.
    for (int alpha = 0; alpha < 4; ++alpha) {
        double h[8];
        for (int a = 0; a < 8; ++a) {
            const int hv[4] = {sign_x[a] * sign_y[a], sign_y[a] * sign_z[a], sign_z[a] * sign_x[a], sign_x[a] * sign_y[a] * sign_z[a]};
            h[a] = hv[alpha];
        }
        Vec3 hx = Vec3::Zero();
        for (int a = 0; a < 8; ++a) hx += h[a] * x[a];
        for (int a = 0; a < 8; ++a) g.gamma[4 * a + alpha] = h[a] - hx.dot(b[a]);
    }
    // Characteristic length: volume over the largest face area.
    static const int faces[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
    double largest = 0.0;
    for (const auto& f : faces)
        largest = std::max(largest, 0.5 * (x[f[2]] - x[f[0]]).cross(x[f[3]] - x[f[1]]).norm());
    g.length_mm = volume / largest;
    return g;
}

ElementGeometry tetrahedron_geometry(const std::array<Vec3, 8>& x, std::size_t element)
{
    ElementGeometry g;
    Mat3 m;
    m << x[1] - x[0], x[2] - x[0], x[3] - x[0];
    const double det = m.determinant();
    if (!(det > 0.0)) fail("mesh: tetrahedron {} is inverted or degenerate (6V = {:.3g} mm³)", element, det);
    g.volume_mm3 = det / 6.0;
    // ∇N_1..3 are the rows of m⁻¹; ∇N_0 = −Σ.
    const Mat3 inv = m.inverse();
    Vec3 grads[4];
    grads[1] = inv.row(0).transpose();
    grads[2] = inv.row(1).transpose();
    grads[3] = inv.row(2).transpose();
    grads[0] = -(grads[1] + grads[2] + grads[3]);
    double largest = 0.0;
    for (int a = 0; a < 4; ++a) {
        for (int i = 0; i < 3; ++i) g.dn_dx[3 * a + i] = grads[a][i];
        g.b_squared += grads[a].squaredNorm();
        largest = std::max(largest, 1.0 / grads[a].norm()); // altitude from node a
    }
    double shortest = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 4; ++a) shortest = std::min(shortest, 1.0 / grads[a].norm());
    g.length_mm = shortest; // the smallest altitude
    (void)largest;
    return g;
}

} // namespace

bool TledModel::build_band_partition(const VolumeMesh& mesh)
{
    // Elements sorted by their smallest node number, cut into chunks that each cover a band of
    // at least B node numbers, B the widest element's span (largest − smallest node number + 1).
    // An element of chunk k touches nodes in [lo_k, lo_{k+1} + B); chunk k + 2 starts at
    // lo_{k+2} ≥ lo_{k+1} + B, so even chunks share no node, nor odd ones: two phases. On a grid
    // mesh numbered plane by plane a chunk is about one layer of elements, swept in the order of
    // the nodes' memory: each node's 8 contributions arrive while it is in cache (one pass over
    // the arrays per step instead of one per colour). The order is fixed by the mesh alone, so
    // every node receives its contributions in the same order whatever the thread count.
    const std::size_t e_count = mesh.cell_count();
    if (e_count == 0) return false;
    std::vector<std::int32_t> lowest(e_count);
    std::int64_t band = 1;
    for (std::size_t e = 0; e < e_count; ++e) {
        const auto cell = mesh.cell(e);
        const auto [lo, hi] = std::minmax_element(cell.begin(), cell.end());
        lowest[e] = *lo;
        band = std::max<std::int64_t>(band, std::int64_t(*hi) - std::int64_t(*lo) + 1);
    }
    // Two phases of at least 8 chunks each keep two to eight threads busy; narrower meshes (or a
    // numbering with a wide band) are coloured instead.
    const std::int64_t nodes = static_cast<std::int64_t>(mesh.node_count());
    if (nodes / band < 16) return false;
    std::vector<std::int32_t> order(e_count);
    for (std::size_t e = 0; e < e_count; ++e) order[e] = static_cast<std::int32_t>(e);
    std::stable_sort(order.begin(), order.end(), [&](std::int32_t a, std::int32_t b) { return lowest[a] < lowest[b]; });
    std::vector<std::vector<Chunk>> phases(2);
    std::size_t k = 0;
    int parity = 0;
    for (std::int64_t lo = 0; lo < nodes && k < e_count; lo += band, parity ^= 1) {
        const auto begin = static_cast<std::int64_t>(k);
        while (k < e_count && lowest[order[k]] < lo + band) ++k;
        if (static_cast<std::int64_t>(k) > begin) phases[parity].push_back({begin, static_cast<std::int64_t>(k)});
    }
    m_element_order = std::move(order);
    for (auto& phase : phases)
        if (!phase.empty()) m_phases.push_back(std::move(phase));
    m_band_partition = true;
    return true;
}

void TledModel::build_work_partition(const VolumeMesh& mesh)
{
    const std::size_t n = mesh.node_count(), e_count = mesh.cell_count();
    m_element_order.clear();
    m_phases.clear();
    m_band_partition = false;
    if (m_options.work_partition == TledOptions::WorkPartition::automatic && build_band_partition(mesh)) return;
    // Meshes whose node numbering has too wide a band (unstructured tetrahedra): a greedy
    // colouring in element order (no two elements of a colour share a node; a grid mesh gets 8
    // colours), each colour cut into chunks of 16 elements (one SIMD batch: balances two threads
    // on small meshes). Every colour visits the whole node array, so on large meshes the band
    // partition above is faster (fewer passes over memory).
    // 256 colours: grid meshes need 8, unstructured tetrahedra up to about the largest number of
    // elements around a node (≈ 20–100).
    constexpr int words = 4, max_colours = 64 * words;
    std::vector<std::array<std::uint64_t, words>> node_colours(n, std::array<std::uint64_t, words>{});
    std::vector<std::vector<std::int32_t>> colours;
    for (std::size_t e = 0; e < e_count; ++e) {
        std::array<std::uint64_t, words> used{};
        for (auto id : mesh.cell(e))
            for (int w = 0; w < words; ++w) used[w] |= node_colours[id][w];
        int c = 0;
        while (c < max_colours && (used[c / 64] >> (c % 64)) & 1u) ++c;
        if (c == max_colours) fail("mesh: element {} needs more than {} colours (a node with too many elements)", e, max_colours);
        for (auto id : mesh.cell(e)) node_colours[id][c / 64] |= (std::uint64_t(1) << (c % 64));
        if (static_cast<std::size_t>(c) >= colours.size()) colours.resize(c + 1);
        colours[c].push_back(static_cast<std::int32_t>(e));
    }
    constexpr std::size_t chunk = 16;
    for (const auto& colour : colours) {
        m_phases.emplace_back();
        for (std::size_t k = 0; k < colour.size(); k += chunk) {
            const auto begin = static_cast<std::int64_t>(m_element_order.size());
            m_element_order.insert(m_element_order.end(), colour.begin() + k, colour.begin() + std::min(colour.size(), k + chunk));
            m_phases.back().push_back({begin, static_cast<std::int64_t>(m_element_order.size())});
        }
    }
}

double hourglass_modulus_mpa(const TledOptions& options, const ElasticMaterial& material)
{
    return options.hourglass_modulus == TledOptions::HourglassModulus::shear ? 2.0 * material.mu_mpa
                                                                              : material.dilatational_modulus_mpa();
}

double strain_energy_density(MaterialLaw law, const ElasticMaterial& m, const Mat3& f)
{
    const double j = f.determinant();
    if (law == MaterialLaw::corotational) {
        Mat3 r;
        // Column-major storage reads as Fᵀ = Rᵀ (R U Rᵀ), whose rotation Rᵀ comes back stored as R.
        corotation(f.data(), r.data());
        const double excess = (r.transpose() * f).trace() - 3.0;
        return m.mu_mpa * (f - r).squaredNorm() + 0.5 * m.lambda_mpa * excess * excess;
    }
    if (law == MaterialLaw::linear_elastic) {
        const Mat3 eps = 0.5 * (f + f.transpose()) - Mat3::Identity();
        return 0.5 * m.lambda_mpa * eps.trace() * eps.trace() + m.mu_mpa * eps.squaredNorm();
    }
    if (law == MaterialLaw::mooney_rivlin) {
        double fr[9], p[9];
        for (int k = 0; k < 9; ++k) fr[k] = f(k / 3, k % 3);
        return mooney_rivlin_stress<double>(0.5 * m.mu_mpa - m.c01_mpa, m.c01_mpa, m.kappa_mpa, fr, p);
    }
    const Mat3 c = f.transpose() * f;
    if (law == MaterialLaw::st_venant_kirchhoff) {
        const Mat3 e = 0.5 * (c - Mat3::Identity());
        return 0.5 * m.lambda_mpa * e.trace() * e.trace() + m.mu_mpa * e.squaredNorm();
    }
    return 0.5 * m.mu_mpa * (std::pow(j, -2.0 / 3.0) * c.trace() - 3.0) + 0.5 * m.kappa_mpa * (j - 1.0) * (j - 1.0);
}

TledModel::TledModel(const VolumeMesh& mesh, const TissueTable& tissues, const TledOptions& options)
    : m_options(options), m_cell_type(mesh.cell_type), m_nodes_per_element(mesh.cell_size())
{
    options.validate();
    mesh.validate("mesh");
    if (mesh.cell_count() == 0) fail("mesh: has no elements");
    const std::size_t n = mesh.node_count(), e_count = mesh.cell_count();
    const int npe = m_nodes_per_element;
    m_rest.resize(3 * n);
    Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (std::size_t i = 0; i < n; ++i) {
        for (int c = 0; c < 3; ++c) m_rest[3 * i + c] = mesh.nodes[i][c];
        lo = lo.cwiseMin(mesh.nodes[i]);
        hi = hi.cwiseMax(mesh.nodes[i]);
    }
    m_diagonal = (hi - lo).norm();
    m_connectivity = mesh.cells;

    // Materials: one entry per label used by the mesh.
    std::map<std::int32_t, std::uint16_t> material_of_label;
    for (auto label : mesh.cell_labels) {
        if (material_of_label.count(label)) continue;
        const Tissue* t = tissues.find(label);
        if (!t) fail("mesh: label {} has no tissue in the tissue table", label);
        material_of_label[label] = static_cast<std::uint16_t>(m_materials.size());
        ElasticMaterial m = material_from_tissue(*t);
        m.density_t_mm3 *= options.density_scale;
        m_materials.push_back(m);
        m_material_labels.push_back(label);
    }
    m_element_material.resize(e_count);
    for (std::size_t e = 0; e < e_count; ++e) m_element_material[e] = material_of_label[mesh.cell_labels[e]];

    // Geometry: all cells of a grid mesh are the same box, so they share one entry.
    m_element_geometry.resize(e_count);
    const bool shared = mesh.grid && mesh.cell_type == CellType::hexahedron;
    std::array<Vec3, 8> x;
    if (shared) {
        const HexGrid& g = *mesh.grid;
        static constexpr int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
        for (int a = 0; a < 8; ++a) x[a] = g.node_position(corner[a][0], corner[a][1], corner[a][2]) - g.origin;
        m_geometries.push_back(hexahedron_geometry(x, 0));
        // Guard: the mesh's own cells must be these boxes.
        for (std::size_t e = 0; e < e_count; ++e) {
            const auto ids = mesh.cell(e);
            for (int a = 1; a < 8; ++a) {
                const Vec3 edge = mesh.nodes[ids[a]] - mesh.nodes[ids[0]];
                if ((edge - (x[a] - x[0])).norm() > 1e-6 * (1.0 + x[6].norm()))
                    fail("mesh: cell {} does not match its grid (the grid metadata is inconsistent)", e);
            }
        }
    } else {
        m_geometries.reserve(e_count);
        for (std::size_t e = 0; e < e_count; ++e) {
            const auto ids = mesh.cell(e);
            for (int a = 0; a < npe; ++a) x[a] = mesh.nodes[ids[a]];
            m_geometries.push_back(npe == 8 ? hexahedron_geometry(x, e) : tetrahedron_geometry(x, e));
            m_element_geometry[e] = static_cast<std::int32_t>(e);
        }
    }

    // Masses, stiffness bounds, critical time step.
    m_mass.assign(n, 0.0);
    m_stiffness_bound.assign(n, 0.0);
    m_critical_dt = std::numeric_limits<double>::infinity();
    for (std::size_t e = 0; e < e_count; ++e) {
        const ElementGeometry& g = m_geometries[m_element_geometry[e]];
        const ElasticMaterial& m = m_materials[m_element_material[e]];
        const double dt = g.length_mm / m.wave_speed_mm_s();
        if (dt < m_critical_dt) {
            m_critical_dt = dt;
            m_critical_element = static_cast<std::int32_t>(e);
        }
        const double node_mass = m.density_t_mm3 * g.volume_mm3 / npe;
        const double modulus = m.dilatational_modulus_mpa();
        double sum_b = 0.0;
        for (int a = 0; a < npe; ++a) sum_b += Vec3(g.dn_dx[3 * a], g.dn_dx[3 * a + 1], g.dn_dx[3 * a + 2]).norm();
        const double hourglass = npe == 8 ? options.hourglass_kappa * hourglass_modulus_mpa(options, m) * g.volume_mm3 * g.b_squared / 8.0 : 0.0;
        const auto ids = mesh.cell(e);
        for (int a = 0; a < npe; ++a) {
            m_mass[ids[a]] += node_mass;
            const double ba = Vec3(g.dn_dx[3 * a], g.dn_dx[3 * a + 1], g.dn_dx[3 * a + 2]).norm();
            double gamma_row = 0.0;
            if (npe == 8)
                for (int alpha = 0; alpha < 4; ++alpha) {
                    double col = 0.0;
                    for (int b = 0; b < 8; ++b) col += std::abs(g.gamma[4 * b + alpha]);
                    gamma_row += std::abs(g.gamma[4 * a + alpha]) * col;
                }
            // Row sum of |K_ab| ≤ (λ + 2μ) V |b_a| Σ_b |b_b| (+ hourglass part).
            m_stiffness_bound[ids[a]] += modulus * g.volume_mm3 * ba * sum_b + hourglass * gamma_row;
        }
    }

    if (options.averaged_nodal_pressure) {
        if (m_cell_type != CellType::tetrahedron) fail("averaged_nodal_pressure applies to tetrahedra only");
        if (options.law != MaterialLaw::neo_hookean) fail("averaged_nodal_pressure needs the Neo-Hookean law");
        m_nodal_volume.assign(n, 0.0);
        for (std::size_t e = 0; e < e_count; ++e)
            for (auto id : mesh.cell(e)) m_nodal_volume[id] += m_geometries[m_element_geometry[e]].volume_mm3 / 4.0;
    }
    build_work_partition(mesh);
    for (const auto& face : match_faces(mesh))
        if (face.neighbour < 0) {
            m_surface_faces.push_back(face.nodes);
            for (int v = 0; v < face.node_count(); ++v) m_surface_nodes.push_back(face.nodes[v]);
        }
    std::sort(m_surface_nodes.begin(), m_surface_nodes.end());
    m_surface_nodes.erase(std::unique(m_surface_nodes.begin(), m_surface_nodes.end()), m_surface_nodes.end());
}

} // namespace physreg
