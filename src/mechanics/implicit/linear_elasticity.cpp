// SPDX-License-Identifier: GPL-3.0-or-later
// Linear elasticity with per-structure moduli (paper 002's K(E) u = F).
#include "physreg/mechanics/implicit/linear_elasticity.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mechanics/materials/material.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

namespace physreg {
namespace {

std::int32_t find_root(std::vector<std::int32_t>& parent, std::int32_t i)
{
    while (parent[static_cast<std::size_t>(i)] != i) {
        parent[static_cast<std::size_t>(i)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(i)])];
        i = parent[static_cast<std::size_t>(i)];
    }
    return i;
}

double seconds_since(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

} // namespace

double tetrahedron_unit_stiffness(const Vec3* x, double nu, double* k)
{
    Mat3 j;
    j.col(0) = x[1] - x[0];
    j.col(1) = x[2] - x[0];
    j.col(2) = x[3] - x[0];
    const double det = j.determinant();
    const double volume = det / 6.0;
    if (!(volume > 0.0)) return volume;
    // Shape-function gradients: rows of J⁻¹ give ∇N_1..3; ∇N_0 = −Σ.
    const Mat3 inv = j.inverse();
    Eigen::Matrix<double, 4, 3> grad;
    grad.row(1) = inv.row(0);
    grad.row(2) = inv.row(1);
    grad.row(3) = inv.row(2);
    grad.row(0) = -(grad.row(1) + grad.row(2) + grad.row(3));
    const double lambda = nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    const double mu = 1.0 / (2.0 * (1.0 + nu));
    // K_ab,ik = V (λ ∂_i N_a ∂_k N_b + μ ∂_k N_a ∂_i N_b + μ δ_ik ∇N_a·∇N_b)
    for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b) {
            const double dot = grad.row(a).dot(grad.row(b));
            for (int i = 0; i < 3; ++i)
                for (int c = 0; c < 3; ++c) {
                    double v = lambda * grad(a, i) * grad(b, c) + mu * grad(a, c) * grad(b, i);
                    if (i == c) v += mu * dot;
                    k[(3 * a + i) * 12 + 3 * b + c] = volume * v;
                }
        }
    return volume;
}

LinearElasticModel::LinearElasticModel(const VolumeMesh& mesh, const LinearElasticOptions& options, const std::string& what)
    : m_node_count(mesh.node_count()), m_anchor(options.anchor_stiffness_n_mm), m_solver(LinearSolverOptions{options.reuse_factor ? LinearSolverKind::pcg_factor : LinearSolverKind::cholmod}), m_reuse_factor(options.reuse_factor)
{
    mesh.validate(what);
    if (mesh.cell_type != CellType::tetrahedron) fail("{}: linear elasticity needs a tetrahedral mesh", what);
    if (mesh.cell_count() == 0) fail("{}: the mesh has no cells", what);
    if (!(m_anchor >= 0.0) || !std::isfinite(m_anchor)) fail("{}: anchor stiffness {} N/mm must be ≥ 0 and finite", what, m_anchor);
    const std::size_t cells = mesh.cell_count();
    m_cells = mesh.cells;
    m_labels = mesh.cell_labels;
    std::sort(m_labels.begin(), m_labels.end());
    m_labels.erase(std::unique(m_labels.begin(), m_labels.end()), m_labels.end());
    for (const auto& [label, nu] : options.poisson_ratio)
        if (!(nu > -1.0 && nu < 0.5)) fail("{}: Poisson ratio {} of label {} must lie in (-1, 0.5)", what, nu, label);
    if (!(options.default_poisson_ratio > -1.0 && options.default_poisson_ratio < 0.5))
        fail("{}: Poisson ratio {} must lie in (-1, 0.5)", what, options.default_poisson_ratio);

    m_fixed.assign(m_node_count, 0);
    for (auto n : options.fixed_nodes) {
        if (n < 0 || static_cast<std::size_t>(n) >= m_node_count) fail("{}: fixed node {} is not a node of the mesh", what, n);
        m_fixed[static_cast<std::size_t>(n)] = 1;
    }
    m_dof_of.assign(3 * m_node_count, -1);
    std::int32_t free_dofs = 0;
    for (std::size_t n = 0; n < m_node_count; ++n)
        if (!m_fixed[n])
            for (int c = 0; c < 3; ++c) m_dof_of[3 * n + static_cast<std::size_t>(c)] = free_dofs++;
    if (free_dofs == 0) fail("{}: every node is fixed; nothing can move", what);

    // Element matrices at E = 1 MPa, structure index per cell, volumes.
    m_cell_structure.resize(cells);
    m_unit_stiffness.resize(144 * cells);
    m_volume.assign(m_labels.size(), 0.0);
    for (std::size_t c = 0; c < cells; ++c) {
        const auto s = static_cast<int>(std::lower_bound(m_labels.begin(), m_labels.end(), mesh.cell_labels[c]) - m_labels.begin());
        m_cell_structure[c] = s;
        const auto it = options.poisson_ratio.find(mesh.cell_labels[c]);
        const double nu = it == options.poisson_ratio.end() ? options.default_poisson_ratio : it->second;
        Vec3 x[4];
        for (int a = 0; a < 4; ++a) x[a] = mesh.nodes[static_cast<std::size_t>(m_cells[4 * c + static_cast<std::size_t>(a)])];
        for (int a = 0; a < 4; ++a)
            for (int i = 0; i < 3; ++i) m_rest_positions.push_back(x[a][i]);
        const double v = tetrahedron_unit_stiffness(x, nu, &m_unit_stiffness[144 * c]);
        if (!(v > 0.0)) fail("{}: tetrahedron {} is degenerate or inverted (volume {} mm³)", what, c, v);
        m_volume[static_cast<std::size_t>(s)] += v;
    }

    // Connected pieces: singularity check and the reference structure of each piece.
    std::vector<std::int32_t> parent(m_node_count);
    std::iota(parent.begin(), parent.end(), 0);
    for (std::size_t c = 0; c < cells; ++c)
        for (int a = 1; a < 4; ++a) {
            const auto r0 = find_root(parent, m_cells[4 * c]), r1 = find_root(parent, m_cells[4 * c + static_cast<std::size_t>(a)]);
            if (r0 != r1) parent[static_cast<std::size_t>(r1)] = r0;
        }
    std::map<std::int32_t, bool> piece_held;
    std::map<std::int32_t, std::map<int, double>> piece_volume;
    for (std::size_t c = 0; c < cells; ++c) piece_held.emplace(find_root(parent, m_cells[4 * c]), false);
    for (std::size_t n = 0; n < m_node_count; ++n)
        if (m_fixed[n]) piece_held[find_root(parent, static_cast<std::int32_t>(n))] = true;
    if (m_anchor == 0.0)
        for (const auto& [piece, held] : piece_held)
            if (!held)
                fail("{}: a mesh piece (around node {}) has no fixed node and there is no anchor stiffness: K is singular (give "
                     "Dirichlet nodes or a regularising anchor)", what, piece);
    for (std::size_t c = 0; c < cells; ++c) {
        Vec3 x[4];
        for (int a = 0; a < 4; ++a) x[a] = mesh.nodes[static_cast<std::size_t>(m_cells[4 * c + static_cast<std::size_t>(a)])];
        piece_volume[find_root(parent, m_cells[4 * c])][m_cell_structure[c]] += (x[1] - x[0]).cross(x[2] - x[0]).dot(x[3] - x[0]) / 6.0;
    }
    m_reference.assign(m_labels.size(), 0);
    for (const auto& [piece, volumes] : piece_volume) {
        const auto largest = std::max_element(volumes.begin(), volumes.end(), [](const auto& a, const auto& b) { return a.second < b.second; });
        m_reference[static_cast<std::size_t>(largest->first)] = 1;
    }

    // Pattern of the reduced K (both triangles), then each element entry's value index.
    std::vector<Eigen::Triplet<double, int>> triplets;
    triplets.reserve(144 * cells + static_cast<std::size_t>(free_dofs));
    // visit(c, entry, r, s): element c's 12×12 entry (row-major) and its reduced row/column (−1: held).
    const auto for_each_entry = [&](auto&& visit) {
        for (std::size_t c = 0; c < cells; ++c)
            for (int a = 0; a < 4; ++a)
                for (int b = 0; b < 4; ++b)
                    for (int i = 0; i < 3; ++i)
                        for (int k = 0; k < 3; ++k) {
                            const auto r = m_dof_of[3 * static_cast<std::size_t>(m_cells[4 * c + static_cast<std::size_t>(a)]) + static_cast<std::size_t>(i)];
                            const auto s = m_dof_of[3 * static_cast<std::size_t>(m_cells[4 * c + static_cast<std::size_t>(b)]) + static_cast<std::size_t>(k)];
                            visit(c, static_cast<std::size_t>((3 * a + i) * 12 + 3 * b + k), r, s);
                        }
    };
    for_each_entry([&](std::size_t, std::size_t, std::int32_t r, std::int32_t s) {
        if (r >= 0 && s >= 0) triplets.emplace_back(r, s, 1.0);
    });
    for (std::int32_t d = 0; d < free_dofs; ++d) triplets.emplace_back(d, d, 1.0);
    m_k.resize(free_dofs, free_dofs);
    m_k.setFromTriplets(triplets.begin(), triplets.end());
    m_k.makeCompressed();
    const auto value_index = [&](std::int32_t r, std::int32_t s) {
        const int* begin = m_k.innerIndexPtr() + m_k.outerIndexPtr()[s];
        const int* end = m_k.innerIndexPtr() + m_k.outerIndexPtr()[s + 1];
        return static_cast<std::int32_t>(std::lower_bound(begin, end, r) - m_k.innerIndexPtr());
    };
    m_entry.resize(144 * cells);
    for_each_entry([&](std::size_t c, std::size_t entry, std::int32_t r, std::int32_t s) {
        m_entry[144 * c + entry] = (r >= 0 && s >= 0) ? value_index(r, s) : -1;
    });
    m_diagonal_entry.resize(static_cast<std::size_t>(free_dofs));
    for (std::int32_t d = 0; d < free_dofs; ++d) m_diagonal_entry[static_cast<std::size_t>(d)] = value_index(d, d);
}

LinearElasticModel::~LinearElasticModel() = default;

void LinearElasticModel::set_young_moduli(const std::vector<double>& young_modulus_pa)
{
    if (young_modulus_pa.size() != m_labels.size()) fail("linear elasticity: {} Young's moduli given for {} structures", young_modulus_pa.size(), m_labels.size());
    for (std::size_t j = 0; j < m_labels.size(); ++j)
        if (!(young_modulus_pa[j] > 0.0) || !std::isfinite(young_modulus_pa[j]))
            fail("linear elasticity: Young's modulus {} Pa of label {} must be positive and finite", young_modulus_pa[j], m_labels[j]);
    const auto t0 = std::chrono::steady_clock::now();
    m_young_pa = young_modulus_pa;
    double* values = m_k.valuePtr();
    std::fill(values, values + m_k.nonZeros(), 0.0);
    for (std::size_t c = 0; c < m_cell_structure.size(); ++c) {
        const double e_mpa = 1e-6 * m_young_pa[static_cast<std::size_t>(m_cell_structure[c])];
        const double* k = &m_unit_stiffness[144 * c];
        const std::int32_t* entry = &m_entry[144 * c];
        for (int q = 0; q < 144; ++q)
            if (entry[q] >= 0) values[entry[q]] += e_mpa * k[q];
    }
    for (auto d : m_diagonal_entry) values[d] += m_anchor;
    if (m_reuse_factor) { // the next solve factorises when the earlier factor no longer preconditions well
        m_factor_current = false;
        m_pcg_iterations_since_change = 0;
        m_factorisation_s += seconds_since(t0);
        return;
    }
    const LinearSolveStats stats = m_solver.factorise(m_k);
    ++m_factorisations;
    if (stats.shift > 0.0) fail("linear elasticity: K is not positive definite (a diagonal shift of {} was needed)", stats.shift);
    m_factorisation_s += seconds_since(t0);
}

void LinearElasticModel::set_element_rotations(const Eigen::VectorXd& u)
{
    if (!u.allFinite()) fail("linear elasticity: the displacement the rotations are taken from is not finite");
    if (static_cast<std::size_t>(u.size()) != 3 * m_node_count) fail("linear elasticity: rotation displacement of size {} for {} nodes", u.size(), m_node_count);
    if (m_rest_unit_stiffness.empty()) m_rest_unit_stiffness = m_unit_stiffness;
    const std::size_t cells = m_cell_structure.size();
    m_unit_rotation_load.assign(12 * cells, 0.0);
    double largest = 0.0;
    std::size_t inverted = 0;
    for (std::size_t c = 0; c < cells; ++c) {
        const double* rest = &m_rest_positions[12 * c];
        Eigen::Matrix3d dx, dr;
        for (int a = 1; a < 4; ++a)
            for (int i = 0; i < 3; ++i) {
                const auto n0 = static_cast<Eigen::Index>(3 * m_cells[4 * c]), na = static_cast<Eigen::Index>(3 * m_cells[4 * c + static_cast<std::size_t>(a)]);
                dr(i, a - 1) = rest[3 * a + i] - rest[i];
                dx(i, a - 1) = dr(i, a - 1) + u[na + i] - u[n0 + i];
            }
        const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> f = dx * dr.inverse();
        Eigen::Matrix<double, 3, 3, Eigen::RowMajor> r;
        // An element inverted at u gets the rotation of Irving et al. (corotation()), which pushes it back out.
        if (!(corotation(f.data(), r.data()) > 0.0)) ++inverted;
        largest = std::max(largest, std::acos(std::clamp(0.5 * (r.trace() - 1.0), -1.0, 1.0)));
        // K_R = Rb K Rbᵀ (Rb = diag(R, R, R, R)), block by block; b̂ = Rb K (X − Rbᵀ X). Plain
        // loops over 3×3 blocks (Eigen's 12×12 products trip GCC 12's AVX-512 header warnings).
        const double* k = &m_rest_unit_stiffness[144 * c];
        double* rotated = &m_unit_stiffness[144 * c];
        double y[12], z[12];
        for (int a = 0; a < 4; ++a)
            for (int i = 0; i < 3; ++i) {
                double rt_x = 0.0; // (Rᵀ X_a)_i
                for (int m = 0; m < 3; ++m) rt_x += r(m, i) * rest[3 * a + m];
                y[3 * a + i] = rest[3 * a + i] - rt_x;
            }
        for (int p = 0; p < 12; ++p) {
            z[p] = 0.0;
            for (int q = 0; q < 12; ++q) z[p] += k[12 * p + q] * y[q];
        }
        for (int a = 0; a < 4; ++a)
            for (int i = 0; i < 3; ++i) {
                double v = 0.0;
                for (int m = 0; m < 3; ++m) v += r(i, m) * z[3 * a + m];
                m_unit_rotation_load[12 * c + static_cast<std::size_t>(3 * a + i)] = v;
            }
        for (int a = 0; a < 4; ++a)
            for (int b = 0; b < 4; ++b) {
                Eigen::Matrix3d block;
                for (int i = 0; i < 3; ++i)
                    for (int m = 0; m < 3; ++m) block(i, m) = k[(3 * a + i) * 12 + 3 * b + m];
                const Eigen::Matrix3d turned = r * block * r.transpose();
                for (int i = 0; i < 3; ++i)
                    for (int m = 0; m < 3; ++m) rotated[(3 * a + i) * 12 + 3 * b + m] = turned(i, m);
            }
    }
    m_largest_rotation_deg = largest * 180.0 / 3.14159265358979323846;
    m_inverted_at_rotations = inverted;
    if (!m_young_pa.empty()) set_young_moduli(m_young_pa);
}

std::size_t LinearElasticModel::inverted_elements(const Eigen::VectorXd& u) const
{
    std::size_t count = 0;
    for (std::size_t c = 0; c < m_cell_structure.size(); ++c) {
        Vec3 x[4];
        for (int a = 0; a < 4; ++a) {
            const auto n = static_cast<Eigen::Index>(3 * m_cells[4 * c + static_cast<std::size_t>(a)]);
            for (int i = 0; i < 3; ++i) x[a][i] = m_rest_positions[12 * c + static_cast<std::size_t>(3 * a + i)] + u[n + i];
        }
        if (!((x[1] - x[0]).cross(x[2] - x[0]).dot(x[3] - x[0]) > 0.0)) ++count;
    }
    return count;
}

void LinearElasticModel::rotation_load(Eigen::VectorXd& b) const
{
    b.setZero(static_cast<Eigen::Index>(3 * m_node_count));
    if (m_unit_rotation_load.empty()) return;
    for (std::size_t c = 0; c < m_cell_structure.size(); ++c) {
        const double e_mpa = 1e-6 * m_young_pa.at(static_cast<std::size_t>(m_cell_structure[c]));
        for (int q = 0; q < 12; ++q) b[3 * m_cells[4 * c + static_cast<std::size_t>(q / 3)] + q % 3] += e_mpa * m_unit_rotation_load[12 * c + static_cast<std::size_t>(q)];
    }
}

double LinearElasticModel::structure_rotation_load(std::size_t j, const Eigen::VectorXd& a) const
{
    if (m_unit_rotation_load.empty()) return 0.0;
    double sum = 0.0;
    for (std::size_t c = 0; c < m_cell_structure.size(); ++c) {
        if (static_cast<std::size_t>(m_cell_structure[c]) != j) continue;
        for (int q = 0; q < 12; ++q) sum += a[3 * m_cells[4 * c + static_cast<std::size_t>(q / 3)] + q % 3] * m_unit_rotation_load[12 * c + static_cast<std::size_t>(q)];
    }
    return sum;
}

void LinearElasticModel::solve(const Eigen::VectorXd& f, Eigen::VectorXd& u) const
{
    if (m_young_pa.empty()) fail("linear elasticity: solve before the moduli were set");
    if (static_cast<std::size_t>(f.size()) != 3 * m_node_count) fail("linear elasticity: force vector of size {} for {} nodes", f.size(), m_node_count);
    const auto t0 = std::chrono::steady_clock::now();
    Eigen::VectorXd b(m_k.rows()), x(m_k.rows());
    for (std::size_t d = 0; d < m_dof_of.size(); ++d)
        if (m_dof_of[d] >= 0) b[m_dof_of[d]] = f[static_cast<Eigen::Index>(d)];
    double factorising_s = 0.0;
    if (m_reuse_factor && !m_factor_current) {
        // CG on a K solved several times (the load phase holds E) costs more, summed, than one
        // factorisation: factorise once the CG iterations spent on this K pass a budget. Counted in
        // iterations, not seconds, so that the result does not depend on the machine's speed or
        // load (cli.determinism: the same bits on 1 and 2 threads). One iteration costs 1/35–1/16
        // of a factorisation from 15 k to 38 k tetrahedra (bench_register_images).
        constexpr int iterations_per_factorisation = 20;
        LinearSolveStats stats;
        if (m_solver.has_factor() && m_pcg_iterations_since_change > iterations_per_factorisation) {
            stats = m_solver.factorise(m_k);
            m_solver.solve_factored(b, x);
        } else {
            stats = m_solver.solve(m_k, b, x);
            m_pcg_iterations_since_change += stats.iterations;
        }
        m_pcg_iterations += stats.iterations;
        if (stats.factorised) {
            m_factor_current = true;
            ++m_factorisations;
            m_factorisation_s += stats.factorisation_s;
            factorising_s = stats.factorisation_s;
            if (stats.shift > 0.0) fail("linear elasticity: K is not positive definite (a diagonal shift of {} was needed)", stats.shift);
        }
    } else {
        m_solver.solve_factored(b, x);
    }
    u.setZero(static_cast<Eigen::Index>(3 * m_node_count));
    for (std::size_t d = 0; d < m_dof_of.size(); ++d)
        if (m_dof_of[d] >= 0) u[static_cast<Eigen::Index>(d)] = x[m_dof_of[d]];
    m_solve_s += seconds_since(t0) - factorising_s;
}

void LinearElasticModel::solve_prescribed(const Eigen::VectorXd& f, const Eigen::VectorXd& prescribed, Eigen::VectorXd& u) const
{
    if (static_cast<std::size_t>(prescribed.size()) != 3 * m_node_count) fail("linear elasticity: prescribed vector of size {} for {} nodes", prescribed.size(), m_node_count);
    Eigen::VectorXd constrained = Eigen::VectorXd::Zero(prescribed.size()), k_c;
    for (std::size_t d = 0; d < m_dof_of.size(); ++d)
        if (m_dof_of[d] < 0) constrained[static_cast<Eigen::Index>(d)] = prescribed[static_cast<Eigen::Index>(d)];
    multiply(constrained, k_c);
    solve(f - k_c, u); // rows of fixed dofs are dropped by the reduced solve
    u += constrained;
}

double LinearElasticModel::structure_form(std::size_t j, const Eigen::VectorXd& a, const Eigen::VectorXd& b) const
{
    double sum = 0.0;
    for (std::size_t c = 0; c < m_cell_structure.size(); ++c) {
        if (static_cast<std::size_t>(m_cell_structure[c]) != j) continue;
        double ae[12], be[12];
        for (int n = 0; n < 4; ++n)
            for (int i = 0; i < 3; ++i) {
                const auto d = static_cast<Eigen::Index>(3 * m_cells[4 * c + static_cast<std::size_t>(n)] + i);
                ae[3 * n + i] = a[d];
                be[3 * n + i] = b[d];
            }
        const double* k = &m_unit_stiffness[144 * c];
        for (int p = 0; p < 12; ++p) {
            double row = 0.0;
            for (int q = 0; q < 12; ++q) row += k[12 * p + q] * be[q];
            sum += ae[p] * row;
        }
    }
    return sum;
}

void LinearElasticModel::multiply(const Eigen::VectorXd& x, Eigen::VectorXd& y) const
{
    y = m_anchor * x;
    for (std::size_t c = 0; c < m_cell_structure.size(); ++c) {
        const double e_mpa = 1e-6 * m_young_pa.at(static_cast<std::size_t>(m_cell_structure[c]));
        const double* k = &m_unit_stiffness[144 * c];
        for (int p = 0; p < 12; ++p) {
            double row = 0.0;
            for (int q = 0; q < 12; ++q) row += k[12 * p + q] * x[3 * m_cells[4 * c + static_cast<std::size_t>(q / 3)] + q % 3];
            y[3 * m_cells[4 * c + static_cast<std::size_t>(p / 3)] + p % 3] += e_mpa * row;
        }
    }
}

double LinearElasticModel::mean_diagonal_n_mm() const
{
    double sum = 0.0;
    for (auto d : m_diagonal_entry) sum += m_k.valuePtr()[d];
    return sum / static_cast<double>(m_diagonal_entry.size());
}

} // namespace physreg
