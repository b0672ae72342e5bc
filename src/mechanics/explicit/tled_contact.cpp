// SPDX-License-Identifier: GPL-3.0-or-later
// The TLED solver's contact (paper 000's tool on the skin): nodes the tool reaches are projected out
// of it, with an active set during equilibrium solves, face contact between organs, and the
// candidates a tool path can reach chosen once per load range. Members of TledSolver
// (tled_solver.hpp); the time stepping and the forces are in tled_solver.cpp.
#include "physreg/mechanics/explicit/tled_solver.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <omp.h>

namespace physreg {

template <typename Real>
void TledSolver<Real>::constrain(Real* u, double load_factor, bool record_contacts)
{
    const Real s = static_cast<Real>(load_factor);
    for (auto k : m_constrained_dofs) u[k] = s * m_prescribed[k];
    if (record_contacts) {
        m_contact_normal_node.clear();
        m_contact_normal.clear();
    }
    m_contact_count = 0;
    for (const auto& indenter : m_loads.indenters)
        for (auto node : m_model.surface_nodes()) {
            Vec3 normal;
            if (!push_node_out(indenter, u, node, load_factor, normal)) continue;
            ++m_contact_count;
            if (record_contacts) {
                m_contact_normal_node.push_back(node);
                m_contact_normal.push_back(normal);
            }
        }
}

// Dynamic relaxation: a node that touched a tool stays on its surface (sliding freely) until the
// residual force pulls it away from the tool; projecting only penetrating nodes makes the contact
// set chatter and slows convergence several-fold.
template <typename Real>
void TledSolver<Real>::constrain_with_active_set(Real* u, double load_factor, const Real* forces, Real s)
{
    for (auto k : m_constrained_dofs) u[k] = static_cast<Real>(load_factor) * m_prescribed[k];
    if (m_active_tool.size() != m_n) m_active_tool.assign(m_n, -1);
    m_contact_normal_node.clear();
    m_contact_normal.clear();
    m_contact_count = 0;
    for (std::size_t t = 0; t < m_loads.indenters.size(); ++t) {
        const Indenter& tool = m_loads.indenters[t];
        for (auto node : m_contact_candidates[t]) {
            Real* un = u + 3 * static_cast<std::size_t>(node);
            const Real* xn = m_rest.data() + 3 * static_cast<std::size_t>(node);
            const Vec3 x = current_position(u, node);
            Vec3 surface, normal;
            if (m_active_tool[node] == static_cast<int>(t)) {
                tool.closest_surface_point(x, load_factor, surface, normal);
                Vec3 residual;
                for (int d = 0; d < 3; ++d)
                    residual[d] = double(s * m_external[3 * node + d] - forces[3 * node + d]);
                const bool inside = tool.push_out(x, load_factor, surface, normal);
                if (!inside && residual.dot(normal) > 0) { // pulled away: release
                    m_active_tool[node] = -1;
                    continue;
                }
                if (!inside) tool.closest_surface_point(x, load_factor, surface, normal);
            } else if (m_active_tool[node] < 0 && tool.push_out(x, load_factor, surface, normal)) {
                m_active_tool[node] = static_cast<int>(t);
            } else {
                continue;
            }
            for (int d = 0; d < 3; ++d)
                if (!m_constrained[3 * node + d]) un[d] = static_cast<Real>(surface[d] - double(xn[d]));
            ++m_contact_count;
            m_contact_normal_node.push_back(node);
            m_contact_normal.push_back(normal);
        }
    }
}

// Surface nodes within the tool's reach (plus a margin) of the segment its reference point sweeps
// between the two load factors; the margin is spent as nodes move (see solve_equilibrium).
template <typename Real>
void TledSolver<Real>::select_contact_candidates(const Real* u, double from_factor, double to_factor)
{
    const auto& surface = m_model.surface_nodes();
    const auto& faces = m_model.surface_faces();
    m_contact_candidates.assign(m_loads.indenters.size(), {});
    m_contact_faces.assign(m_loads.indenters.size(), {});
    double margin = std::numeric_limits<double>::infinity();
    std::vector<double> distance(m_n, std::numeric_limits<double>::infinity());
    for (std::size_t t = 0; t < m_loads.indenters.size(); ++t) {
        const Indenter& tool = m_loads.indenters[t];
        const bool faces_too = tool.shape != IndenterShape::plane; // a face between nodes outside a half-space is outside it
        const double reach = tool.reach_mm();
        if (!std::isfinite(reach)) {
            m_contact_candidates[t] = surface;
            if (faces_too)
                for (std::size_t f = 0; f < faces.size(); ++f) m_contact_faces[t].push_back(static_cast<std::int32_t>(f));
            continue;
        }
        const double tool_margin = std::max(1.0, 0.25 * reach);
        margin = std::min(margin, tool_margin);
        // The reference point's path between the two factors: a polyline through the path vertices.
        const double lo = std::min(from_factor, to_factor), hi = std::max(from_factor, to_factor);
        std::vector<Vec3> polyline{tool.position(lo)};
        const std::size_t segments = tool.path.size() > 1 ? tool.path.size() - 1 : 1;
        for (std::size_t i = 1; i < segments; ++i) {
            const double si = double(i) / double(segments);
            if (si > lo && si < hi) polyline.push_back(tool.path[i]);
        }
        polyline.push_back(tool.position(hi));
        const double limit = reach + tool_margin;
        for (auto node : surface) {
            const Vec3 x = current_position(u, node);
            double d = std::numeric_limits<double>::infinity();
            for (std::size_t i = 0; i + 1 < polyline.size(); ++i) {
                const Vec3 a = polyline[i], ab = polyline[i + 1] - a;
                const double length2 = ab.squaredNorm();
                const double along = length2 > 0 ? std::clamp((x - a).dot(ab) / length2, 0.0, 1.0) : 0.0;
                d = std::min(d, (x - a - along * ab).norm());
            }
            distance[static_cast<std::size_t>(node)] = d;
            if (d <= limit) m_contact_candidates[t].push_back(node);
        }
        // A face is reached through its interior before its nodes: a face whose nearest node is
        // within the limit plus the face's size.
        if (!faces_too) continue;
        for (std::size_t f = 0; f < faces.size(); ++f) {
            const int count = faces[f][3] < 0 ? 3 : 4;
            std::array<Vec3, 4> x;
            double nearest = std::numeric_limits<double>::infinity();
            for (int a = 0; a < count; ++a) {
                x[a] = current_position(u, faces[f][a]);
                nearest = std::min(nearest, distance[static_cast<std::size_t>(faces[f][a])]);
            }
            if (nearest <= limit + face_span_mm(x, count)) m_contact_faces[t].push_back(static_cast<std::int32_t>(f));
        }
    }
    m_candidate_slack = margin;
}

// Face contact (see FaceContactSamples): a face sample inside a tool deeper than its allowance is
// pushed out by a penalty force spread over its face's nodes by their shape functions: per face
// 0.4 × the smallest Gershgorin stiffness bound of its nodes (at the default mass safety of 2).
// Relaxation's pseudo-masses leave room for 2 × the bound; four faces pressed in full could take a
// node past it, but only part of a face's samples press and the bound overestimates the stiffness.
// An instability would show as an inverted element or a divergence, both errors. (Tried and dropped: moving the nodes onto the tool as node contact
// does — samples of one face undo each other and the relaxation chatters; an augmented Lagrangian
// multiplier — it held the face exactly but kept a coarse block from converging.)
template <typename Real>
void TledSolver<Real>::subtract_face_contact_forces(const Real* u, double load_factor, Real* f)
{
    m_pressed_face_samples = 0;
    if (!m_face_contact) return;
    const auto& faces = m_model.surface_faces();
    const auto& bound = m_stiffness_bound;
    for (std::size_t t = 0; t < m_contact_faces.size(); ++t) {
        const Indenter& tool = m_loads.indenters[t];
        const double reach = tool.reach_mm();
        const Vec3 centre = tool.position(load_factor);
        for (const auto index : m_contact_faces[t]) {
            const auto& face = faces[static_cast<std::size_t>(index)];
            const int count = face[3] < 0 ? 3 : 4;
            std::array<Vec3, 4> x;
            Vec3 mid = Vec3::Zero();
            for (int a = 0; a < count; ++a) {
                x[a] = current_position(u, face[a]);
                mid += x[a] / double(count);
            }
            if (std::isfinite(reach) && (mid - centre).norm() > reach + face_span_mm(x, count)) continue;
            const FaceContactSamples samples = face_contact_samples(tool, x, count);
            if (samples.weights.empty()) continue;
            double penalty = std::numeric_limits<double>::infinity();
            for (int a = 0; a < count; ++a) penalty = std::min(penalty, bound[static_cast<std::size_t>(face[a])]);
            penalty *= m_face_penalty_scale * double(count) / double(samples.weights.size());
            for (const auto& w : samples.weights) {
                Vec3 p = Vec3::Zero();
                for (int a = 0; a < count; ++a) p += w[a] * x[a];
                Vec3 surface, normal;
                if (!tool.push_out(p, load_factor, surface, normal)) continue;
                const double excess = (surface - p).norm() - samples.allowance_mm;
                if (excess <= 0) continue;
                ++m_pressed_face_samples;
                const Vec3 force = penalty * excess * normal;
                for (int a = 0; a < count; ++a)
                    for (int d = 0; d < 3; ++d) f[3 * static_cast<std::size_t>(face[a]) + d] -= static_cast<Real>(w[a] * force[d]);
            }
        }
    }
}

template <typename Real>
bool TledSolver<Real>::push_node_out(const Indenter& indenter, Real* u, std::int32_t node, double load_factor, Vec3& normal) const
{
    Real* un = u + 3 * static_cast<std::size_t>(node);
    const Real* xn = m_rest.data() + 3 * static_cast<std::size_t>(node);
    const Vec3 x = current_position(u, node);
    Vec3 surface;
    if (!indenter.push_out(x, load_factor, surface, normal)) return false;
    for (int d = 0; d < 3; ++d)
        if (!m_constrained[3 * node + d]) un[d] = static_cast<Real>(surface[d] - double(xn[d]));
    return true;
}

template <typename Real>
Vec3 TledSolver<Real>::current_position(const Real* u, std::int32_t node) const
{
    const std::size_t k = 3 * static_cast<std::size_t>(node);
    return {double(m_rest[k] + u[k]), double(m_rest[k + 1] + u[k + 1]), double(m_rest[k + 2] + u[k + 2])};
}


// The members above, for the two precisions (the class itself is instantiated in tled_solver.cpp).
#define PHYSREG_TLED_CONTACT_MEMBERS(Real)                                                                                  \
    template void TledSolver<Real>::constrain(Real*, double, bool);                                                        \
    template void TledSolver<Real>::constrain_with_active_set(Real*, double, const Real*, Real);                           \
    template void TledSolver<Real>::select_contact_candidates(const Real*, double, double);                                \
    template void TledSolver<Real>::subtract_face_contact_forces(const Real*, double, Real*);                              \
    template bool TledSolver<Real>::push_node_out(const Indenter&, Real*, std::int32_t, double, Vec3&) const;               \
    template Vec3 TledSolver<Real>::current_position(const Real*, std::int32_t) const;
PHYSREG_TLED_CONTACT_MEMBERS(float)
PHYSREG_TLED_CONTACT_MEMBERS(double)
#undef PHYSREG_TLED_CONTACT_MEMBERS

} // namespace physreg
