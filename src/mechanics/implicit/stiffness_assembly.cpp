// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"

#include <omp.h>

#include "physreg/core/error.hpp"
#include "mechanics/detail/corotational_tetra_kernel.hpp"

#include <algorithm>
#include <cmath>

namespace physreg {

StiffnessAssembler::StiffnessAssembler(const TledModel& model, const PenaltyCoupling* coupling,
                                       const std::vector<std::vector<std::int32_t>>& extra_stencils)
    : m_model(model), m_coupling(coupling && !coupling->empty() ? coupling : nullptr)
{
    if (model.options().averaged_nodal_pressure)
        fail("implicit solvers: the averaged-nodal-pressure tetrahedron has no assembled tangent; use hexahedra or "
             "plain tetrahedra (solver.averaged_nodal_pressure: false)");
    const std::size_t n = model.node_count();
    if (m_coupling && m_coupling->node_count() != n)
        fail("coupling built for {} nodes, the model has {}", m_coupling->node_count(), n);
    const int npe = model.nodes_per_element();
    const std::size_t e_count = model.element_count();
    const auto& conn = model.connectivity();
    if (npe == 4) {
        for (const auto& g : model.geometries()) {
            m_tetra_dn.insert(m_tetra_dn.end(), g.dn_dx.begin(), g.dn_dx.begin() + 12);
            m_tetra_volume.push_back(g.volume_mm3);
        }
        for (const auto& m : model.materials()) {
            m_tetra_mu.push_back(m.mu_mpa);
            m_tetra_lambda.push_back(m.lambda_mpa);
        }
    }

    // Node adjacency: nodes sharing an element or a coupling support (the point's two MLS domains).
    std::vector<std::vector<std::int32_t>> adjacency(n);
    for (std::size_t e = 0; e < e_count; ++e)
        for (int a = 0; a < npe; ++a)
            for (int b = 0; b < npe; ++b) adjacency[conn[npe * e + b]].push_back(conn[npe * e + a]);
    if (m_coupling)
        for (std::size_t i = 0; i < m_coupling->points().size(); ++i) {
            const auto entries = m_coupling->point_entries(i);
            for (const auto& p : entries)
                for (const auto& q : entries) adjacency[q.node].push_back(p.node);
        }
    for (const auto& group : extra_stencils)
        for (auto p : group) {
            if (p < 0 || static_cast<std::size_t>(p) >= n) fail("stiffness pattern: stencil node {} outside the model's {} nodes", p, n);
            for (auto q : group) adjacency[q].push_back(p);
        }
    m_node_begin.assign(n + 1, 0);
    for (std::size_t j = 0; j < n; ++j) {
        auto& list = adjacency[j];
        std::sort(list.begin(), list.end());
        list.erase(std::unique(list.begin(), list.end()), list.end());
        if (list.empty()) list.push_back(static_cast<std::int32_t>(j)); // a node of no element keeps its diagonal
        m_node_begin[j + 1] = m_node_begin[j] + static_cast<std::int32_t>(list.size());
    }
    m_neighbours.reserve(m_node_begin[n]);
    for (auto& list : adjacency) {
        m_neighbours.insert(m_neighbours.end(), list.begin(), list.end());
        std::vector<std::int32_t>().swap(list);
    }
    const std::int64_t nnz = 9 * static_cast<std::int64_t>(m_node_begin[n]);
    if (nnz > std::numeric_limits<int>::max()) fail("implicit solvers: the tangent would have {} entries, more than 2³¹", nnz);
    m_outer.resize(3 * n + 1);
    m_inner.resize(nnz);
    for (std::size_t j = 0; j < n; ++j) {
        const int degree = m_node_begin[j + 1] - m_node_begin[j];
        for (int c = 0; c < 3; ++c) {
            const int start = 9 * m_node_begin[j] + 3 * c * degree;
            m_outer[3 * j + c] = start;
            for (int p = 0; p < degree; ++p)
                for (int r = 0; r < 3; ++r) m_inner[start + 3 * p + r] = 3 * m_neighbours[m_node_begin[j] + p] + r;
        }
    }
    m_outer[3 * n] = static_cast<int>(nnz);

    const auto position = [&](std::int32_t i, std::int32_t j) {
        const auto begin = m_neighbours.begin() + m_node_begin[j], end = m_neighbours.begin() + m_node_begin[j + 1];
        return static_cast<std::int32_t>(std::lower_bound(begin, end, i) - begin);
    };
    m_block.resize(e_count * npe * npe);
    for (std::size_t e = 0; e < e_count; ++e)
        for (int a = 0; a < npe; ++a)
            for (int b = 0; b < npe; ++b) m_block[(e * npe + a) * npe + b] = position(conn[npe * e + a], conn[npe * e + b]);

    if (m_coupling) {
        // Entry (3 row + r, 3 col + r) of a coupling pair sits at value_index(row, col, 0, 0) + r (3 deg(col) + 1).
        m_coupling_begin.push_back(0);
        for (std::size_t p = 0; p < m_coupling->points().size(); ++p) {
            const auto entries = m_coupling->point_entries(p);
            for (const auto& col : entries)
                for (const auto& row : entries) m_coupling_index.push_back(value_index(row.node, col.node, 0, 0));
            m_coupling_begin.push_back(static_cast<std::int64_t>(m_coupling_index.size()));
        }
    }
    for (const auto& m : model.materials())
        m_hourglass_k.push_back(model.options().hourglass_kappa * hourglass_modulus_mpa(model.options(), m) / 8.0);
    if (npe == 8)
        for (const auto& g : model.geometries()) {
            std::vector<double> gram(64, 0.0);
            for (int a = 0; a < 8; ++a)
                for (int b = 0; b < 8; ++b)
                    for (int alpha = 0; alpha < 4; ++alpha) gram[8 * a + b] += g.gamma[4 * a + alpha] * g.gamma[4 * b + alpha];
            m_hourglass_gram.push_back(std::move(gram));
        }
}

SparseMatrix StiffnessAssembler::make_matrix() const
{
    std::vector<double> zeros(m_inner.size(), 0.0);
    const auto dofs = static_cast<int>(3 * m_model.node_count());
    return Eigen::Map<const SparseMatrix>(dofs, dofs, static_cast<int>(m_inner.size()), m_outer.data(), m_inner.data(), zeros.data());
}

std::int64_t StiffnessAssembler::value_index(std::int32_t i, std::int32_t j, int r, int c) const
{
    const auto begin = m_neighbours.begin() + m_node_begin[j], end = m_neighbours.begin() + m_node_begin[j + 1];
    const auto it = std::lower_bound(begin, end, i);
    if (it == end || *it != i) fail("stiffness pattern: nodes {} and {} are not coupled", i, j);
    return m_outer[3 * j + c] + 3 * (it - begin) + r;
}

namespace {

/// The coupling's constant Hessian k φφᵀ ⊗ I₃ per interface point, added at its precomputed value
/// offsets (`index` from `begin[p]`; a node's column holds 3 rows per neighbour, hence the stride).
void add_coupling_stiffness(const PenaltyCoupling& coupling, const std::vector<std::int64_t>& index_of, const std::vector<std::int64_t>& begin,
                            const std::vector<std::int32_t>& node_begin, double* values)
{
    for (std::size_t p = 0; p < coupling.points().size(); ++p) {
        const double k = coupling.point_stiffness_n_per_mm(p);
        const auto entries = coupling.point_entries(p);
        const std::int64_t* index = index_of.data() + begin[p];
        for (const auto& col : entries) {
            const std::int64_t stride = 3 * (node_begin[col.node + 1] - node_begin[col.node]) + 1;
            for (const auto& row : entries) {
                const double kv = k * row.phi * col.phi;
                const std::int64_t base = *index++;
                for (int r = 0; r < 3; ++r) values[base + r * stride] += kv;
            }
        }
    }
}

/// Adds one element's tangent into the assembled values: T_a[i][k][L] = Σ_J b_aJ A_iJ,kL and
/// K_ab[i][k] = V Σ_L T_a[i][k][L] b_bL + δ_ik k_hg G_ab (hexahedra's hourglass Gram matrix `gram`).
/// `block` gives each node pair's slot in the pattern, `outer` each column's start. False when a
/// value is not finite.
inline bool add_element_stiffness(int npe, const ElementGeometry& g, const double* A, double v, const double* gram, double khg,
                                  const std::int32_t* block, const int* outer, const std::int32_t* ids, double* values)
{
    bool finite = true;
    double t[8][27];
    for (int a = 0; a < npe; ++a)
        for (int i = 0; i < 3; ++i)
            for (int kl = 0; kl < 9; ++kl)
                t[a][9 * i + kl] = g.dn_dx[3 * a] * A[9 * (3 * i) + kl] + g.dn_dx[3 * a + 1] * A[9 * (3 * i + 1) + kl] + g.dn_dx[3 * a + 2] * A[9 * (3 * i + 2) + kl];
    for (int b = 0; b < npe; ++b) {
        const double b0 = v * g.dn_dx[3 * b], b1 = v * g.dn_dx[3 * b + 1], b2 = v * g.dn_dx[3 * b + 2];
        for (int a = 0; a < npe; ++a) {
            const double hg = gram ? khg * gram[8 * a + b] : 0.0;
            const int pos = block[a * npe + b];
            for (int k = 0; k < 3; ++k) {
                double* column = values + outer[3 * ids[b] + k] + 3 * pos;
                for (int i = 0; i < 3; ++i) {
                    const double* ta = t[a] + 9 * i + 3 * k;
                    const double kv = ta[0] * b0 + ta[1] * b1 + ta[2] * b2 + (i == k ? hg : 0.0);
                    finite = finite && std::isfinite(kv);
                    column[i] += kv;
                }
            }
        }
    }
    return finite;
}

} // namespace

Assembly StiffnessAssembler::assemble(const double* u, double* f, SparseMatrix* stiffness) const
{
    const std::size_t n = m_model.node_count(), e_count = m_model.element_count();
    const int npe = m_model.nodes_per_element();
    const MaterialLaw law = m_model.options().law;
    const auto& conn = m_model.connectivity();
    const auto& geometry_of = m_model.element_geometry();
    const auto& material_of = m_model.element_material();
    const auto& order = m_model.element_order();
    double* values = nullptr;
    if (stiffness) {
        if (stiffness->nonZeros() != static_cast<Eigen::Index>(m_inner.size()) || stiffness->rows() != static_cast<Eigen::Index>(3 * n))
            fail("stiffness assembly: the matrix does not have this model's pattern");
        values = stiffness->valuePtr();
    }
    std::vector<double> element_energy(e_count, 0.0);
    std::int64_t inverted = -1, non_finite = -1, inverted_count = 0;
    const std::int64_t nnz = static_cast<std::int64_t>(m_inner.size());
    // The governor picks the team size from the timings of earlier calls (one thread when the
    // machine is shared and the full team would wait at every colour's barrier).
    const int team = m_governor.threads();
    const double start = omp_get_wtime();
#pragma omp parallel num_threads(team)
    {
#pragma omp for schedule(static)
        for (std::int64_t k = 0; k < static_cast<std::int64_t>(3 * n); ++k) f[k] = 0.0;
        if (values) {
#pragma omp for schedule(static)
            for (std::int64_t k = 0; k < nnz; ++k) values[k] = 0.0;
        }
        std::int64_t my_inverted = -1, my_non_finite = -1, my_inverted_count = 0;
        // Forces only, co-rotational tetrahedra: SIMD batches (corotational_tetra_kernel.hpp).
        const bool tetra_batches = !values && npe == 4 && law == MaterialLaw::corotational;
        for (const auto& phase : m_model.phases()) {
            const long chunks = static_cast<long>(phase.size());
#pragma omp for schedule(dynamic, 4)
            for (long chunk = 0; chunk < chunks; ++chunk) {
                if (tetra_batches) {
                    constexpr int W = 8;
                    detail::TetraBatchResult batch;
                    const detail::TetraBatchInput input{conn.data(), geometry_of.data(), material_of.data(), m_tetra_dn.data(),
                                                        m_tetra_volume.data(), m_tetra_mu.data(), m_tetra_lambda.data()};
                    for (std::int64_t first = phase[chunk].begin; first < phase[chunk].end; first += W) {
                        const int count = static_cast<int>(std::min<std::int64_t>(W, phase[chunk].end - first));
                        detail::corotational_tetra_batch<W>(order.data() + first, count, input, u, f, element_energy.data(), batch);
                    }
                    my_inverted_count += batch.inverted;
                    if (batch.non_finite >= 0 && (my_non_finite < 0 || batch.non_finite < my_non_finite)) my_non_finite = batch.non_finite;
                    continue;
                }
                for (std::int64_t slot = phase[chunk].begin; slot < phase[chunk].end; ++slot) {
                    const std::size_t e = static_cast<std::size_t>(order[slot]);
                    const ElementGeometry& g = m_model.geometries()[geometry_of[e]];
                    const ElasticMaterial& mat = m_model.materials()[material_of[e]];
                    const std::int32_t* ids = conn.data() + npe * e;
                    double F[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
                    for (int a = 0; a < npe; ++a)
                        for (int i = 0; i < 3; ++i)
                            for (int J = 0; J < 3; ++J) F[3 * i + J] += u[3 * ids[a] + i] * g.dn_dx[3 * a + J];
                    double A[81], P[9];
                    const bool rotated = m_rotated_tangent && law == MaterialLaw::corotational;
                    const double j = values ? (rotated ? rotated_linear_tangent(mat, F, A) : first_piola_tangent(law, mat, F, A))
                                            : F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
                                                  F[2] * (F[3] * F[7] - F[4] * F[6]);
                    if (!(j > 0.0)) {
                        if (law == MaterialLaw::corotational) {
                            ++my_inverted_count; // the co-rotational law pushes inverted elements back (see corotation())
                        } else {
                            if (my_inverted < 0 || static_cast<std::int64_t>(e) < my_inverted) my_inverted = static_cast<std::int64_t>(e);
                            continue;
                        }
                    }
                    const double v = g.volume_mm3;
                    double energy = 0.0;
                    if (law == MaterialLaw::corotational) {
                        energy = v * corotational_stress(mat.mu_mpa, mat.lambda_mpa, F, P);
                    } else if (law == MaterialLaw::mooney_rivlin) {
                        energy = v * mooney_rivlin_stress<double>(0.5 * mat.mu_mpa - mat.c01_mpa, mat.c01_mpa, mat.kappa_mpa, F, P);
                    } else {
                        first_piola_kirchhoff<double>(law, mat.mu_mpa, mat.lambda_mpa, mat.kappa_mpa, F, P);
                        Mat3 fm;
                        for (int k = 0; k < 9; ++k) fm(k / 3, k % 3) = F[k];
                        energy = v * strain_energy_density(law, mat, fm);
                    }
                    double local_f[24];
                    for (int a = 0; a < npe; ++a)
                        for (int i = 0; i < 3; ++i)
                            local_f[3 * a + i] = v * (P[3 * i] * g.dn_dx[3 * a] + P[3 * i + 1] * g.dn_dx[3 * a + 1] + P[3 * i + 2] * g.dn_dx[3 * a + 2]);
                    double khg = 0.0;
                    const double* gram = nullptr;
                    if (npe == 8) {
                        khg = m_hourglass_k[material_of[e]] * g.volume_mm3 * g.b_squared;
                        gram = m_hourglass_gram[geometry_of[e]].data();
                        for (int alpha = 0; alpha < 4; ++alpha) {
                            double q[3] = {0, 0, 0};
                            for (int b = 0; b < 8; ++b)
                                for (int i = 0; i < 3; ++i) q[i] += g.gamma[4 * b + alpha] * u[3 * ids[b] + i];
                            energy += 0.5 * khg * (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
                            for (int a = 0; a < 8; ++a)
                                for (int i = 0; i < 3; ++i) local_f[3 * a + i] += khg * g.gamma[4 * a + alpha] * q[i];
                        }
                    }
                    bool finite = std::isfinite(energy);
                    for (int k = 0; k < 3 * npe; ++k) finite = finite && std::isfinite(local_f[k]);
                    element_energy[e] = energy;
                    for (int a = 0; a < npe; ++a)
                        for (int i = 0; i < 3; ++i) f[3 * ids[a] + i] += local_f[3 * a + i];
                    if (values)
                        finite = add_element_stiffness(npe, g, A, v, gram, khg, m_block.data() + e * npe * npe, m_outer.data(), ids, values) && finite;
                    if (!finite && (my_non_finite < 0 || static_cast<std::int64_t>(e) < my_non_finite))
                        my_non_finite = static_cast<std::int64_t>(e);
                }
            }
        }
#pragma omp critical(physreg_assembly_flags)
        {
            if (my_inverted >= 0 && (inverted < 0 || my_inverted < inverted)) inverted = my_inverted;
            if (my_non_finite >= 0 && (non_finite < 0 || my_non_finite < non_finite)) non_finite = my_non_finite;
            inverted_count += my_inverted_count;
        }
    }
    m_governor.record(omp_get_wtime() - start);
    Assembly result;
    result.inverted_element = inverted;
    result.non_finite_element = non_finite;
    result.inverted_tolerated = inverted_count;
    if (inverted >= 0) return result;
    for (double e : element_energy) result.energy_mj += e; // fixed order: the same sum for any thread count
    if (m_coupling) {
        m_coupling->add_forces(u, f);
        result.energy_mj += m_coupling->energy_mj(std::span<const double>(u, 3 * n));
        if (values) add_coupling_stiffness(*m_coupling, m_coupling_index, m_coupling_begin, m_node_begin, values);
    }
    return result;
}

Assembly StiffnessAssembler::energy(const double* u) const
{
    // The force pass is cheap next to the tangent; sharing the element code keeps energy and force consistent.
    std::vector<double> f(3 * m_model.node_count());
    return assemble(u, f.data(), nullptr);
}

} // namespace physreg
