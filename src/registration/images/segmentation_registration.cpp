// SPDX-License-Identifier: GPL-3.0-or-later
// Paper 002's estimation of boundary forces and Young's moduli (adjoint gradients, L-BFGS).
#include "physreg/registration/images/segmentation_registration.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"

#include "physreg/mesh/tet_split.hpp"
#include "physreg/registration/images/segmentation_alignment.hpp"
#include "physreg/registration/images/segmentation_forms.hpp"

#include <fmt/format.h>
#include <lbfgs.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <set>

namespace physreg {
namespace {

using FaceKey = std::array<std::int32_t, 3>;

FaceKey face_key(std::int32_t a, std::int32_t b, std::int32_t c)
{
    FaceKey k{a, b, c};
    std::sort(k.begin(), k.end());
    return k;
}
constexpr int tet_faces[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};

/// Nodes of the faces that occur once among the cells accepted by `in_set`.
std::vector<std::int32_t> boundary_nodes_of(const VolumeMesh& mesh, const std::function<bool(std::size_t)>& in_set)
{
    std::map<FaceKey, int> count;
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        if (!in_set(c)) continue;
        const auto cell = mesh.cell(c);
        for (const auto& f : tet_faces) ++count[face_key(cell[static_cast<std::size_t>(f[0])], cell[static_cast<std::size_t>(f[1])], cell[static_cast<std::size_t>(f[2])])];
    }
    std::vector<std::uint8_t> on(mesh.node_count(), 0);
    for (const auto& [key, n] : count)
        if (n == 1)
            for (auto v : key) on[static_cast<std::size_t>(v)] = 1;
    std::vector<std::int32_t> nodes;
    for (std::size_t v = 0; v < on.size(); ++v)
        if (on[v]) nodes.push_back(static_cast<std::int32_t>(v));
    return nodes;
}

/// Outward unit normals (area-weighted over the faces around each node) of the boundary of the
/// cells accepted by `in_set`, at rest; zero for nodes off that boundary. `mean_edge_mm`: the
/// boundary faces' mean edge length.
std::vector<Vec3> boundary_normals_of(const VolumeMesh& mesh, const std::function<bool(std::size_t)>& in_set, double& mean_edge_mm)
{
    std::map<FaceKey, std::pair<int, std::array<std::int32_t, 4>>> faces; // count; the face's corners and the cell's other node
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        if (!in_set(c)) continue;
        const auto cell = mesh.cell(c);
        for (int f = 0; f < 4; ++f) {
            const auto a = cell[static_cast<std::size_t>(tet_faces[f][0])], b = cell[static_cast<std::size_t>(tet_faces[f][1])],
                       d = cell[static_cast<std::size_t>(tet_faces[f][2])];
            auto& entry = faces[face_key(a, b, d)];
            ++entry.first;
            entry.second = {a, b, d, cell[static_cast<std::size_t>(f)]};
        }
    }
    std::vector<Vec3> normal(mesh.node_count(), Vec3::Zero());
    double edges = 0.0;
    std::size_t count = 0;
    for (const auto& [key, entry] : faces) {
        if (entry.first != 1) continue;
        const auto& [a, b, d, other] = entry.second;
        const Vec3 &pa = mesh.nodes[static_cast<std::size_t>(a)], &pb = mesh.nodes[static_cast<std::size_t>(b)], &pd = mesh.nodes[static_cast<std::size_t>(d)];
        edges += (pb - pa).norm() + (pd - pb).norm() + (pa - pd).norm();
        count += 3;
        Vec3 n = (pb - pa).cross(pd - pa); // |n| = twice the area
        if (n.dot(mesh.nodes[static_cast<std::size_t>(other)] - pa) > 0) n = -n; // away from the cell
        for (const auto v : {a, b, d}) normal[static_cast<std::size_t>(v)] += n;
    }
    for (auto& n : normal)
        if (n.norm() > 0) n.normalize();
    mean_edge_mm = count ? edges / double(count) : 0.0;
    return normal;
}

double seconds_since(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

} // namespace

std::vector<std::int32_t> outer_boundary_nodes(const VolumeMesh& mesh)
{
    if (mesh.cell_type != CellType::tetrahedron) fail("outer boundary: the mesh is not tetrahedral");
    return boundary_nodes_of(mesh, [](std::size_t) { return true; });
}

SegmentationObjective::SegmentationObjective(const VolumeMesh& mesh, const std::vector<std::int32_t>& structure_labels,
                                             std::vector<const SignedDistanceMap*> maps, const std::string& what)
    : m_mesh(mesh), m_labels(structure_labels), m_maps(std::move(maps))
{
    if (m_maps.size() != structure_labels.size()) fail("{}: {} distance maps for {} structures", what, m_maps.size(), structure_labels.size());
    if (mesh.cell_type != CellType::tetrahedron) fail("{}: the mesh is not tetrahedral", what);
    for (std::size_t j = 0; j < structure_labels.size(); ++j) {
        if (!m_maps[j]) continue;
        const auto label = structure_labels[j];
        for (auto n : boundary_nodes_of(mesh, [&](std::size_t c) { return mesh.cell_labels[c] == label; })) {
            m_nodes.push_back(n);
            m_structures.push_back(static_cast<int>(j));
        }
    }
    if (m_nodes.empty()) fail("{}: no structure boundary to match (no distance map given)", what);
}

namespace {

using Cell3 = Eigen::Matrix<long, 3, 1>;

// Nearest point of a set by a uniform bucket grid (rebuilt for each evaluation: the deformed nodes
// move). A few thousand points per structure; written here rather than pulling in a k-d tree.
class NearestPoint {
public:
    NearestPoint(const std::vector<Vec3>& points, double cell) : m_points(points), m_cell(cell)
    {
        m_lo = Vec3::Constant(1e300);
        Vec3 hi = Vec3::Constant(-1e300);
        for (const auto& p : points) m_lo = m_lo.cwiseMin(p), hi = hi.cwiseMax(p);
        for (int d = 0; d < 3; ++d) m_dims[d] = std::max<long>(1, static_cast<long>((hi[d] - m_lo[d]) / m_cell) + 1);
        m_start.assign(static_cast<std::size_t>(m_dims[0] * m_dims[1] * m_dims[2]) + 1, 0);
        for (const auto& p : points) ++m_start[bucket(index(p)) + 1];
        for (std::size_t b = 1; b < m_start.size(); ++b) m_start[b] += m_start[b - 1];
        m_order.resize(points.size());
        std::vector<std::size_t> fill(m_start.begin(), m_start.end() - 1);
        for (std::size_t i = 0; i < points.size(); ++i) m_order[fill[bucket(index(points[i]))]++] = static_cast<std::int32_t>(i);
    }
    /// Index (into the points) of the nearest to q within `reach` mm, or points.size() for none.
    std::size_t nearest(const Vec3& q, double reach) const
    {
        const Cell3 c = index(q);
        double best = reach * reach;
        std::size_t which = m_points.size();
        const long rings = static_cast<long>(std::ceil(reach / m_cell)) + 1;
        for (long r = 0; r <= rings; ++r) {
            for (long i = c[0] - r; i <= c[0] + r; ++i)
                for (long j = c[1] - r; j <= c[1] + r; ++j)
                    for (long k = c[2] - r; k <= c[2] + r; ++k) {
                        if (std::max({std::abs(i - c[0]), std::abs(j - c[1]), std::abs(k - c[2])}) != r) continue; // the ring only
                        if (i < 0 || j < 0 || k < 0 || i >= m_dims[0] || j >= m_dims[1] || k >= m_dims[2]) continue;
                        const std::size_t b = bucket({i, j, k});
                        for (std::size_t t = m_start[b]; t < m_start[b + 1]; ++t) {
                            const auto p = static_cast<std::size_t>(m_order[t]);
                            const double d = (m_points[p] - q).squaredNorm();
                            if (d < best || (d == best && p < which)) best = d, which = p;
                        }
                    }
            // Every point beyond ring r lies farther than r cells from q's cell.
            const bool outside_all = c[0] - r <= 0 && c[1] - r <= 0 && c[2] - r <= 0 && c[0] + r >= m_dims[0] - 1 && c[1] + r >= m_dims[1] - 1 &&
                                     c[2] + r >= m_dims[2] - 1;
            if (static_cast<double>(r) * m_cell >= std::sqrt(best) || outside_all) return which;
        }
        return which;
    }

private:
    Cell3 index(const Vec3& p) const
    {
        Cell3 i;
        for (int d = 0; d < 3; ++d) i[d] = static_cast<long>(std::floor((p[d] - m_lo[d]) / m_cell));
        return i;
    }
    std::size_t bucket(const Cell3& i) const
    {
        Cell3 c;
        for (int d = 0; d < 3; ++d) c[d] = std::clamp<long>(i[d], 0, m_dims[d] - 1);
        return static_cast<std::size_t>((c[2] * m_dims[1] + c[1]) * m_dims[0] + c[0]);
    }
    const std::vector<Vec3>& m_points;
    double m_cell;
    Vec3 m_lo;
    long m_dims[3] = {1, 1, 1};
    std::vector<std::size_t> m_start;
    std::vector<std::int32_t> m_order;
};

} // namespace

void SegmentationObjective::add_reverse_term()
{
    m_targets.assign(m_maps.size(), {});
    for (std::size_t s = 0; s < m_maps.size(); ++s) {
        if (!m_maps[s]) continue;
        auto& target = m_targets[s];
        for (std::size_t t = 0; t < m_nodes.size(); ++t)
            if (m_structures[t] == static_cast<int>(s)) target.nodes.push_back(m_nodes[t]);
        if (target.nodes.empty()) continue;
        const auto label = m_labels[s];
        const auto normals = boundary_normals_of(m_mesh, [&](std::size_t c) { return m_mesh.cell_labels[c] == label; }, target.spacing_mm);
        for (const auto n : target.nodes) target.normals.push_back(normals[static_cast<std::size_t>(n)]);
        // The voxels on either side of the zero level (|φ| ≤ half a voxel: the boundary voxels'
        // centres), projected onto it along ∇φ.
        const SignedDistanceMap& map = *m_maps[s];
        const ImageGeometry& g = map.geometry();
        const double half = 0.5 * g.spacing.maxCoeff() * 1.01;
        std::vector<Vec3> points;
        for (std::int64_t k = 0; k < g.size[2]; ++k)
            for (std::int64_t j = 0; j < g.size[1]; ++j)
                for (std::int64_t i = 0; i < g.size[0]; ++i) {
                    const float v = map.values()[static_cast<std::size_t>((k * g.size[1] + j) * g.size[0] + i)];
                    if (std::abs(v) > half) continue;
                    const Vec3 p = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                    Vec3 gradient;
                    const double phi = map.value_and_gradient(p, gradient);
                    const double norm2 = gradient.squaredNorm();
                    if (!(norm2 > 1e-12)) continue;
                    points.push_back(p - phi * gradient / norm2);
                }
        // At most 4 points per model term: the fine voxel surface adds cost, not information.
        const std::size_t cap = 4 * target.nodes.size();
        const std::size_t stride = std::max<std::size_t>(1, (points.size() + cap - 1) / cap);
        for (std::size_t q = 0; q < points.size(); q += stride) target.points.push_back(points[q]);
        if (target.points.empty()) fail("symmetric objective: structure {} has no boundary voxel in its distance map", s);
        target.weight = double(target.nodes.size()) / double(target.points.size());
    }
}

std::size_t SegmentationObjective::reverse_point_count() const
{
    std::size_t n = 0;
    for (const auto& t : m_targets) n += t.points.size();
    return n;
}

double SegmentationObjective::reverse_term(const Eigen::VectorXd& u, Eigen::VectorXd* gradient) const
{
    double sum = 0.0;
    for (const auto& target : m_targets) {
        if (target.nodes.empty()) continue;
        std::vector<Vec3> x(target.nodes.size());
        for (std::size_t i = 0; i < x.size(); ++i) {
            const auto n = static_cast<Eigen::Index>(target.nodes[i]);
            x[i] = m_mesh.nodes[static_cast<std::size_t>(n)] + Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]);
        }
        // Buckets of the boundary's node spacing (its mean edge at rest).
        const double cell = std::max(1e-3, target.spacing_mm);
        const NearestPoint nearest(x, cell);
        // Fixed boundary farther than a few node spacings from the whole model is what the model
        // cannot represent (a vessel branch thinner than its cells): left out, as ICP trims.
        const double reach = 3.0 * cell;
        for (const auto& y : target.points) {
            // Point to plane (the node's rest normal): the pull is across the model's surface; along
            // it the nodes stay free (a point-to-node pull drags them sideways, measured worse).
            const std::size_t i = nearest.nearest(y, reach);
            if (i == x.size()) continue;
            const double r = (x[i] - y).dot(target.normals[i]);
            sum += 0.5 * target.weight * r * r;
            if (gradient) {
                const auto n = static_cast<Eigen::Index>(target.nodes[i]);
                for (int c = 0; c < 3; ++c) (*gradient)[3 * n + c] += target.weight * r * target.normals[i][c];
            }
        }
    }
    return sum;
}

double SegmentationObjective::evaluate(const Eigen::VectorXd& u, Eigen::VectorXd* gradient) const
{
    if (gradient) gradient->setZero(u.size());
    double phi_sum = m_targets.empty() ? 0.0 : reverse_term(u, gradient);
    for (std::size_t t = 0; t < m_nodes.size(); ++t) {
        const auto n = static_cast<std::size_t>(m_nodes[t]);
        const Vec3 x = m_mesh.nodes[n] + Vec3(u[static_cast<Eigen::Index>(3 * n)], u[static_cast<Eigen::Index>(3 * n + 1)], u[static_cast<Eigen::Index>(3 * n + 2)]);
        Vec3 g;
        const double phi = m_maps[static_cast<std::size_t>(m_structures[t])]->value_and_gradient(x, g) - offset(t);
        phi_sum += 0.5 * phi * phi;
        if (gradient)
            for (int c = 0; c < 3; ++c) (*gradient)[static_cast<Eigen::Index>(3 * n + static_cast<std::size_t>(c))] += phi * g[c];
    }
    return phi_sum;
}

double SegmentationObjective::rms_distance_mm(const Eigen::VectorXd& u) const
{
    // The forward direction only (the model's boundary nodes to the fixed segmentation): the same
    // measure with or without the reverse term.
    double sum = 0.0;
    for (std::size_t t = 0; t < m_nodes.size(); ++t) {
        const auto n = static_cast<std::size_t>(m_nodes[t]);
        const Vec3 x = m_mesh.nodes[n] + Vec3(u[static_cast<Eigen::Index>(3 * n)], u[static_cast<Eigen::Index>(3 * n + 1)], u[static_cast<Eigen::Index>(3 * n + 2)]);
        const double phi = m_maps[static_cast<std::size_t>(m_structures[t])]->value(x) - offset(t);
        sum += phi * phi;
    }
    return std::sqrt(sum / static_cast<double>(m_nodes.size()));
}

std::vector<std::pair<double, double>> SegmentationObjective::per_structure_distance_mm(const Eigen::VectorXd& u) const
{
    std::vector<std::pair<double, double>> out(m_maps.size(), {0.0, 0.0});
    std::vector<std::size_t> count(m_maps.size(), 0);
    for (std::size_t t = 0; t < m_nodes.size(); ++t) {
        const auto n = static_cast<std::size_t>(m_nodes[t]);
        const auto s = static_cast<std::size_t>(m_structures[t]);
        const Vec3 x = m_mesh.nodes[n] + Vec3(u[static_cast<Eigen::Index>(3 * n)], u[static_cast<Eigen::Index>(3 * n + 1)], u[static_cast<Eigen::Index>(3 * n + 2)]);
        const double d = std::abs(m_maps[s]->value(x));
        out[s].first += d;
        out[s].second = std::max(out[s].second, d);
        ++count[s];
    }
    for (std::size_t s = 0; s < out.size(); ++s)
        if (count[s]) out[s].first /= static_cast<double>(count[s]);
    return out;
}

std::vector<std::int32_t> SegmentationObjective::structure_term_nodes(std::size_t j) const
{
    std::vector<std::int32_t> nodes;
    for (std::size_t t = 0; t < m_nodes.size(); ++t)
        if (static_cast<std::size_t>(m_structures[t]) == j) nodes.push_back(m_nodes[t]);
    return nodes;
}

double SegmentationObjective::structure_voxel_mm(std::size_t j) const
{
    return j < m_maps.size() && m_maps[j] ? m_maps[j]->geometry().spacing.minCoeff() : 0.0;
}

void SegmentationObjective::set_rest_offsets(const std::vector<const SignedDistanceMap*>& moving_maps)
{
    if (moving_maps.size() != m_maps.size()) fail("rest offsets: {} moving distance maps for {} structures", moving_maps.size(), m_maps.size());
    std::vector<double> offsets(m_nodes.size(), 0.0);
    for (std::size_t t = 0; t < m_nodes.size(); ++t) {
        const auto* map = moving_maps[static_cast<std::size_t>(m_structures[t])];
        if (!map) continue;
        const double o = map->value(m_mesh.nodes[static_cast<std::size_t>(m_nodes[t])]);
        if (!std::isfinite(o)) fail("rest offsets: structure {}'s moving distance map is not finite at node {}", m_labels[static_cast<std::size_t>(m_structures[t])], m_nodes[t]);
        offsets[t] = o;
    }
    m_offsets = std::move(offsets);
}

std::pair<double, double> SegmentationObjective::rest_offset_stats_mm() const
{
    double sum = 0.0, most = 0.0;
    for (double o : m_offsets) sum += std::abs(o), most = std::max(most, std::abs(o));
    return {m_offsets.empty() ? 0.0 : sum / static_cast<double>(m_offsets.size()), most};
}

std::vector<Vec3> SegmentationObjective::distance_vectors() const
{
    std::vector<Vec3> sum(m_mesh.node_count(), Vec3::Zero());
    std::vector<int> count(m_mesh.node_count(), 0);
    for (std::size_t t = 0; t < m_nodes.size(); ++t) {
        const auto n = static_cast<std::size_t>(m_nodes[t]);
        Vec3 g;
        const double phi = m_maps[static_cast<std::size_t>(m_structures[t])]->value_and_gradient(m_mesh.nodes[n], g) - offset(t);
        const double norm = g.norm();
        if (norm > 1e-9) sum[n] -= phi * g / norm;
        ++count[n];
    }
    for (std::size_t n = 0; n < sum.size(); ++n)
        if (count[n]) sum[n] /= count[n];
    return sum;
}

void SegmentationRegistrationOptions::validate() const
{
    if (alternation_iterations < 1) fail("segmentation registration: alternation iterations {} must be ≥ 1", alternation_iterations);
    if (max_cycles < 1) fail("segmentation registration: max cycles {} must be ≥ 1", max_cycles);
    if (!(relative_tolerance >= 0.0) || !std::isfinite(relative_tolerance)) fail("segmentation registration: relative tolerance {} must be ≥ 0", relative_tolerance);
    if (!(rms_tolerance_mm >= 0.0) || !std::isfinite(rms_tolerance_mm)) fail("segmentation registration: rms tolerance {} mm must be ≥ 0", rms_tolerance_mm);
    if (!(moduli_prior_factor == 0.0 || (moduli_prior_factor > 1.0 && std::isfinite(moduli_prior_factor))))
        fail("segmentation registration: moduli prior factor {} must be > 1 (one standard deviation of the log-normal prior), or 0 for none", moduli_prior_factor);
    if (!(moduli_prior_rms_mm > 0.0) || !std::isfinite(moduli_prior_rms_mm))
        fail("segmentation registration: moduli prior weight {} mm (the rms distance one standard deviation costs) must be positive", moduli_prior_rms_mm);
    if (!(rigid_min_reduction >= 0.0) || !std::isfinite(rigid_min_reduction))
        fail("segmentation registration: rigid pre-fit threshold {} must be ≥ 0 (a fraction of the rms distance; ≥ 1: never)", rigid_min_reduction);
}

BoundaryParametrisation parse_boundary_parametrisation(const std::string& text)
{
    if (text == "nodal-forces") return BoundaryParametrisation::nodal_forces;
    if (text == "surface-displacement") return BoundaryParametrisation::surface_displacement;
    fail("boundary parametrisation '{}': use nodal-forces or surface-displacement", text);
}

std::string to_string(BoundaryParametrisation p)
{
    return p == BoundaryParametrisation::nodal_forces ? "nodal-forces" : "surface-displacement";
}

SegmentationGradient evaluate_segmentation_gradient(const LinearElasticModel& model, const SegmentationObjective& objective,
                                                    const std::vector<std::int32_t>& force_nodes, BoundaryParametrisation parametrisation,
                                                    double force_scale_n_mm, const Eigen::VectorXd& x)
{
    const auto dofs = static_cast<Eigen::Index>(3 * model.node_count());
    Eigen::VectorXd boundary = Eigen::VectorXd::Zero(dofs);
    const bool forces = parametrisation == BoundaryParametrisation::nodal_forces;
    for (std::size_t i = 0; i < force_nodes.size(); ++i)
        for (int c = 0; c < 3; ++c)
            boundary[3 * force_nodes[i] + c] = (forces ? force_scale_n_mm : 1.0) * x[static_cast<Eigen::Index>(3 * i) + c];
    SegmentationGradient out;
    Eigen::VectorXd load; // the co-rotational law's load at frozen rotations (zero for the linear law)
    model.rotation_load(load);
    if (forces)
        model.solve(boundary + load, out.displacement_mm);
    else
        model.solve_prescribed(load, boundary, out.displacement_mm);
    Eigen::VectorXd g_u;
    out.objective_mm2 = objective.evaluate(out.displacement_mm, &g_u);
    model.solve(g_u, out.lambda); // zero at fixed dofs
    out.d_force.resize(x.size());
    if (forces) {
        for (std::size_t i = 0; i < force_nodes.size(); ++i)
            for (int c = 0; c < 3; ++c) out.d_force[static_cast<Eigen::Index>(3 * i) + c] = force_scale_n_mm * out.lambda[3 * force_nodes[i] + c];
    } else {
        Eigen::VectorXd k_lambda;
        model.multiply(out.lambda, k_lambda);
        for (std::size_t i = 0; i < force_nodes.size(); ++i)
            for (int c = 0; c < 3; ++c) {
                const auto d = 3 * force_nodes[i] + c;
                out.d_force[static_cast<Eigen::Index>(3 * i) + c] = g_u[d] - k_lambda[d];
            }
    }
    out.d_log_modulus.resize(model.structure_count());
    for (std::size_t j = 0; j < model.structure_count(); ++j)
        out.d_log_modulus[j] = -1e-6 * model.young_moduli_pa()[j] * (model.structure_form(j, out.lambda, out.displacement_mm) - model.structure_rotation_load(j, out.lambda));
    return out;
}

namespace {

struct PhaseContext {
    LinearElasticModel* model;
    const SegmentationObjective* objective;
    const std::vector<std::int32_t>* force_nodes;
    BoundaryParametrisation parametrisation;
    double scale;
    Eigen::VectorXd* x;                 ///< force unknowns (fixed during the modulus phase)
    std::vector<double> base_moduli;    ///< E = base · exp(y) in the modulus phase
    std::vector<std::size_t> estimated; ///< structures of the modulus phase
    int evaluations = 0;
    bool modulus_phase = false;
    ModuliPriorForm prior;              ///< weight N r² / (ln f)², mm² (0: no prior), around ln E⁰ per structure
};

/// Π = ½ w Σ_(j estimated) (ln E_j − ln E_j⁰)² (the prior form of the log-moduli); its gradient in ln E_j when asked.
double moduli_prior(const PhaseContext& p, const std::vector<double>& e, std::vector<double>* d_log = nullptr)
{
    if (d_log) d_log->assign(e.size(), 0.0);
    if (p.prior.weight_mm2() == 0.0) return 0.0;
    std::vector<double> log_moduli(e.size());
    for (std::size_t j = 0; j < e.size(); ++j) log_moduli[j] = std::log(e[j]);
    if (d_log) p.prior.gradient(log_moduli, *d_log);
    return p.prior.value(log_moduli);
}

lbfgsfloatval_t evaluate_phase(void* instance, const lbfgsfloatval_t* v, lbfgsfloatval_t* g, const int n, const lbfgsfloatval_t)
{
    auto& p = *static_cast<PhaseContext*>(instance);
    ++p.evaluations;
    if (!p.modulus_phase) {
        const Eigen::Map<const Eigen::VectorXd> x(v, n);
        const SegmentationGradient r = evaluate_segmentation_gradient(*p.model, *p.objective, *p.force_nodes, p.parametrisation, p.scale, x);
        for (int i = 0; i < n; ++i) g[i] = r.d_force[i];
        return r.objective_mm2;
    }
    std::vector<double> e = p.model->young_moduli_pa();
    for (int i = 0; i < n; ++i) {
        if (!std::isfinite(v[i]) || std::abs(v[i]) > 20.0) return std::numeric_limits<double>::infinity(); // E beyond e^±20: reject the trial
        e[p.estimated[static_cast<std::size_t>(i)]] = p.base_moduli[p.estimated[static_cast<std::size_t>(i)]] * std::exp(v[i]);
    }
    p.model->set_young_moduli(e);
    const SegmentationGradient r = evaluate_segmentation_gradient(*p.model, *p.objective, *p.force_nodes, p.parametrisation, p.scale, *p.x);
    std::vector<double> d_prior;
    const double prior = moduli_prior(p, e, &d_prior);
    for (int i = 0; i < n; ++i) {
        const auto j = p.estimated[static_cast<std::size_t>(i)];
        g[i] = r.d_log_modulus[j] + d_prior[j];
    }
    return r.objective_mm2 + prior;
}

int run_lbfgs(PhaseContext& context, Eigen::VectorXd& v, int iterations, double& fx)
{
    lbfgs_parameter_t parameters;
    lbfgs_parameter_init(&parameters);
    parameters.max_iterations = iterations;
    parameters.epsilon = 1e-8;
    parameters.past = 0;
    parameters.max_linesearch = 20;
    return lbfgs(static_cast<int>(v.size()), v.data(), &fx, evaluate_phase, nullptr, &context, &parameters);
}

/// How much the boundary and the objective move when each estimated modulus is doubled or halved:
/// a modulus that moves the boundary by less than a tenth of a voxel is not determined by the data.
std::vector<ModulusSensitivity> moduli_sensitivity(LinearElasticModel& model, const SegmentationObjective& objective,
                                                   const std::function<SegmentationGradient(const Eigen::VectorXd&)>& evaluate,
                                                   const std::vector<std::size_t>& estimated, const Eigen::VectorXd& x,
                                                   const std::vector<double>& moduli_pa, const Eigen::VectorXd& displacement_mm, double objective_mm2)
{
    std::vector<ModulusSensitivity> out;
    for (auto j : estimated) {
        ModulusSensitivity m;
        m.structure = j;
        m.voxel_mm = objective.structure_voxel_mm(j);
        const std::vector<std::int32_t> nodes = objective.structure_term_nodes(j);
        for (double factor : {2.0, 0.5}) {
            std::vector<double> e = moduli_pa;
            e[j] *= factor;
            model.set_young_moduli(e);
            const SegmentationGradient changed = evaluate(x);
            double sum = 0.0;
            for (auto n : nodes)
                for (int c = 0; c < 3; ++c) {
                    const double d = changed.displacement_mm[3 * n + c] - displacement_mm[3 * n + c];
                    sum += d * d;
                }
            const double rms = nodes.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(nodes.size()));
            (factor > 1 ? m.boundary_change_doubled_mm : m.boundary_change_halved_mm) = rms;
            (factor > 1 ? m.objective_change_doubled_mm2 : m.objective_change_halved_mm2) = changed.objective_mm2 - objective_mm2;
        }
        m.determined = std::max(m.boundary_change_doubled_mm, m.boundary_change_halved_mm) >= 0.1 * m.voxel_mm;
        out.push_back(m);
    }
    return out;
}

} // namespace

SegmentationRegistrationResult register_segmentation(const VolumeMesh& mesh, const LinearElasticOptions& elastic,
                                                     const SegmentationObjective& objective,
                                                     const std::vector<std::int32_t>& force_nodes, const std::vector<double>& initial_moduli_pa,
                                                     const SegmentationRegistrationOptions& options,
                                                     const std::function<void(double, const std::string&)>& progress)
{
    options.validate();
    if (force_nodes.empty()) fail("segmentation registration: no force node (every outer surface node is fixed)");
    const auto t0 = std::chrono::steady_clock::now();
    const BoundaryParametrisation mode = options.parametrisation;
    LinearElasticOptions model_options = elastic;
    model_options.reuse_factor = options.reuse_factor;
    if (mode == BoundaryParametrisation::surface_displacement) {
        model_options.fixed_nodes.insert(model_options.fixed_nodes.end(), force_nodes.begin(), force_nodes.end());
        std::sort(model_options.fixed_nodes.begin(), model_options.fixed_nodes.end());
        model_options.fixed_nodes.erase(std::unique(model_options.fixed_nodes.begin(), model_options.fixed_nodes.end()), model_options.fixed_nodes.end());
    }
    LinearElasticModel model(mesh, model_options, "segmentation registration model");
    model.set_young_moduli(initial_moduli_pa);
    const double scale = model.mean_diagonal_n_mm();
    const auto evaluate = [&](const Eigen::VectorXd& x) { return evaluate_segmentation_gradient(model, objective, force_nodes, mode, scale, x); };

    SegmentationRegistrationResult result;
    result.estimated.assign(model.structure_count(), 0);
    std::vector<std::size_t> estimated;
    if (options.estimate_moduli)
        for (std::size_t j = 0; j < model.structure_count(); ++j)
            if (!model.reference_structures()[j]) {
                result.estimated[j] = 1;
                estimated.push_back(j);
            }

    // Initial guess from the distance vectors of the force nodes.
    const std::vector<Vec3> d = objective.distance_vectors();
    Eigen::VectorXd x(static_cast<Eigen::Index>(3 * force_nodes.size()));
    for (std::size_t i = 0; i < force_nodes.size(); ++i)
        for (int c = 0; c < 3; ++c) x[static_cast<Eigen::Index>(3 * i) + c] = d[static_cast<std::size_t>(force_nodes[i])][c];
    Eigen::VectorXd zero = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(3 * mesh.node_count()));
    result.initial_objective_mm2 = objective.evaluate(zero, nullptr);
    result.initial_rms_mm = objective.rms_distance_mm(zero);
    int evaluations = 0;
    if (mode == BoundaryParametrisation::nodal_forces) {
        // F = k̄ d overshoots (every node pushes the whole body): the best of α = 1, ½, ¼, … 2⁻¹², or 0.
        double best_alpha = 0.0, best = result.initial_objective_mm2;
        for (int k = 0; k <= 12; ++k) {
            const double alpha = std::ldexp(1.0, -k);
            const double phi = evaluate(alpha * x).objective_mm2;
            ++evaluations;
            if (phi < best) {
                best = phi;
                best_alpha = alpha;
            }
        }
        x *= best_alpha;
    }

    PhaseContext context{&model, &objective, &force_nodes, mode, scale, &x, model.young_moduli_pa(), estimated, evaluations, false, {}};
    if (options.moduli_prior_factor > 0.0) {
        const double log_factor = std::log(options.moduli_prior_factor);
        std::vector<double> mean;
        for (double e : initial_moduli_pa) mean.push_back(std::log(e));
        context.prior = ModuliPriorForm(static_cast<double>(objective.term_count()) * options.moduli_prior_rms_mm * options.moduli_prior_rms_mm /
                                            (log_factor * log_factor),
                                        std::move(mean), estimated);
    }
    const auto rms_of = [&](double data) { return std::sqrt(2.0 * data / static_cast<double>(objective.term_count())); };
    double phi = evaluate(x).objective_mm2;
    double prior = moduli_prior(context, model.young_moduli_pa());
    result.history.push_back({0, phi, rms_of(phi), prior, model.young_moduli_pa(), ++context.evaluations});
    result.stop_reason = "cycle budget used";
    for (int cycle = 1; cycle <= options.max_cycles; ++cycle) {
        if (options.corotational) {
            // Large deformation: the rotations frozen at the current state for this cycle.
            model.set_element_rotations(evaluate(x).displacement_mm);
            phi = evaluate(x).objective_mm2;
            context.evaluations += 2;
            result.largest_rotation_deg = std::max(result.largest_rotation_deg, model.largest_rotation_deg());
        }
        const double before = phi + prior; // the objective minimised: data term + prior
        context.modulus_phase = false;
        run_lbfgs(context, x, options.alternation_iterations, phi);
        if (!estimated.empty()) {
            context.modulus_phase = true;
            context.base_moduli = model.young_moduli_pa();
            Eigen::VectorXd y = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(estimated.size()));
            run_lbfgs(context, y, options.alternation_iterations, phi);
            std::vector<double> e = context.base_moduli;
            for (std::size_t i = 0; i < estimated.size(); ++i) e[estimated[i]] *= std::exp(y[static_cast<Eigen::Index>(i)]);
            model.set_young_moduli(e); // the line search may have left the factor at a trial point
        }
        phi = evaluate(x).objective_mm2;
        prior = moduli_prior(context, model.young_moduli_pa());
        ++context.evaluations;
        result.history.push_back({cycle, phi, rms_of(phi), prior, model.young_moduli_pa(), context.evaluations});
        if (progress)
            progress(static_cast<double>(cycle) / options.max_cycles,
                     fmt::format("cycle {}: rms distance {:.3f} mm", cycle, result.history.back().rms_distance_mm));
        if (before - (phi + prior) < options.relative_tolerance * before) {
            result.stop_reason = fmt::format("a cycle lowered the objective by less than {} of it", options.relative_tolerance);
            break;
        }
        const auto& h = result.history;
        if (options.rms_tolerance_mm > 0.0 && h[h.size() - 2].rms_distance_mm - h.back().rms_distance_mm < options.rms_tolerance_mm) {
            result.stop_reason = fmt::format("a cycle lowered the rms distance by less than {} mm", options.rms_tolerance_mm);
            break;
        }
    }
    const SegmentationGradient final_state = evaluate(x);
    result.displacement_mm = final_state.displacement_mm;
    // The boundary load: the nodal forces, or the reactions K u at the prescribed nodes.
    Eigen::VectorXd k_u, rotation_load;
    model.multiply(result.displacement_mm, k_u);
    model.rotation_load(rotation_load);
    k_u -= rotation_load; // the co-rotational element forces R K (Rᵀ x − X)
    result.force_n = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(3 * mesh.node_count()));
    for (auto n : force_nodes)
        for (int c = 0; c < 3; ++c) result.force_n[3 * n + c] = k_u[3 * n + c];
    result.young_moduli_pa = model.young_moduli_pa();
    result.objective_mm2 = final_state.objective_mm2;
    result.inverted_elements = model.inverted_elements(result.displacement_mm);
    // Sensitivity of the result to each estimated modulus (two more factorisations each).
    result.sensitivity = moduli_sensitivity(model, objective, evaluate, estimated, x, result.young_moduli_pa, result.displacement_mm, final_state.objective_mm2);
    model.set_young_moduli(result.young_moduli_pa);
    result.prior_mm2 = moduli_prior(context, result.young_moduli_pa);
    result.rms_distance_mm = objective.rms_distance_mm(result.displacement_mm);
    result.evaluations = context.evaluations;
    result.factorisations = model.factorisations();
    result.pcg_iterations = model.pcg_iterations();
    result.factorisation_s = model.factorisation_seconds();
    result.solve_s = model.solve_seconds();
    result.seconds = seconds_since(t0);
    return result;
}

SegmentationRegistrationResult register_segmentation(const Model& model, const LabelVolume& fixed_labels, const SegmentationRegistrationOptions& options,
                                                     const std::function<void(double, const std::string&)>& progress)
{
    const std::string what = "segmentation registration";
    options.validate();
    model.validate(what + ": the model");
    if (model.coupling)
        fail("{}: the model's tissues are coupled by penalty over split interfaces; paper 002's linear model joins them by shared nodes "
             "(build the model with shared nodes)", what);
    if (!model.structures.empty())
        fail("{}: the model has {} auxiliary structure(s) (membrane, beams), which paper 002's linear model does not hold", what, model.structures.size());
    if (const auto partial = model.partial_supports(); !partial.empty())
        fail("{}: support '{}' holds only some directions; paper 002's linear model holds whole nodes", what, partial.front().name);
    VolumeMesh mesh = model.mesh.cell_type == CellType::hexahedron ? split_hexahedra_into_tetrahedra(model.mesh) : model.mesh;
    const std::set<std::int32_t> present(mesh.cell_labels.begin(), mesh.cell_labels.end());
    const std::set<std::int32_t> observed(fixed_labels.labels.begin(), fixed_labels.labels.end());
    const std::vector<std::int32_t> labels(present.begin(), present.end());
    LinearElasticOptions elastic;
    elastic.fixed_nodes = model.held_nodes();
    elastic.reuse_factor = options.reuse_factor;
    std::vector<std::unique_ptr<SignedDistanceMap>> maps;
    std::vector<const SignedDistanceMap*> map_of;
    std::vector<double> initial;
    for (const auto label : labels) {
        const Tissue* t = model.tissues.find(label);
        elastic.poisson_ratio[label] = t->poisson_ratio;
        initial.push_back(t->young_modulus_pa);
        maps.push_back(observed.count(label) ? std::make_unique<SignedDistanceMap>(fixed_labels, std::set<std::int32_t>{label},
                                                                                   fmt::format("fixed label {}", label))
                                             : nullptr);
        map_of.push_back(maps.back().get());
    }
    if (std::all_of(map_of.begin(), map_of.end(), [](const SignedDistanceMap* m) { return m == nullptr; }))
        fail("{}: none of the model's labels ({}) is in the fixed segmentation", what, fmt::join(labels, ","));
    // A free model slides rigidly first (what the segmentation's normal distances cannot tell the
    // elastic registration); a held one cannot move rigidly at all.
    Mat3 rotation = Mat3::Identity();
    Vec3 translation = Vec3::Zero();
    std::string prefit = elastic.fixed_nodes.empty() ? "not tried (rigid_min_reduction ≥ 1)" : "not tried: the model is held (supports)";
    if (elastic.fixed_nodes.empty() && options.rigid_min_reduction < 1.0) {
        const SegmentationObjective rest_terms(mesh, labels, map_of, "the fixed segmentation");
        std::vector<std::vector<Vec3>> points(labels.size());
        for (std::size_t j = 0; j < labels.size(); ++j)
            for (const auto n : rest_terms.structure_term_nodes(j)) points[j].push_back(mesh.nodes[static_cast<std::size_t>(n)]);
        const SegmentationAlignment fit = align_points_to_maps(map_of, points);
        const double before = fit.rms_boundary_distance_before_mm, after = fit.rms_boundary_distance_mm;
        const bool apply = before - after > options.rigid_min_reduction * before;
        prefit = fmt::format("{}: {:.1f}° and {:.2f} mm move the boundary's rms distance {:.3f} → {:.3f} mm ({:.0f} % removed, {:.0f} % needed)",
                             apply ? "applied" : "not applied", fit.rotation_deg, fit.translation.norm(), before, after,
                             100 * (before - after) / std::max(before, 1e-12), 100 * options.rigid_min_reduction);
        if (apply) {
            rotation = fit.rotation;
            translation = fit.translation;
            for (auto& x : mesh.nodes) x = rotation * x + translation;
        }
    }
    const SegmentationObjective objective(mesh, labels, map_of, "the fixed segmentation");
    std::vector<std::int32_t> force_nodes;
    for (const auto n : outer_boundary_nodes(mesh))
        if (!std::binary_search(elastic.fixed_nodes.begin(), elastic.fixed_nodes.end(), n)) force_nodes.push_back(n);
    if (force_nodes.empty()) fail("{}: the supports hold every node of the outer boundary; nothing is left to load", what);
    SegmentationRegistrationResult result = register_segmentation(mesh, elastic, objective, force_nodes, initial, options, progress);
    for (std::size_t i = 0; i < model.mesh.node_count(); ++i) {
        const Vec3& x = model.mesh.nodes[i];
        const Vec3 rigid = rotation * x + translation - x;
        for (int c = 0; c < 3; ++c) result.displacement_mm[static_cast<Eigen::Index>(3 * i + static_cast<std::size_t>(c))] += rigid[c];
    }
    result.rigid_prefit = prefit;
    return result;
}

} // namespace physreg
