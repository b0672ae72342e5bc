// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/elements/embedded_beams.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"
#include "physreg/mesh/point_location.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>

namespace physreg {

namespace {

Mat3 cross_matrix(const Vec3& a)
{
    Mat3 m;
    m << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
    return m;
}

} // namespace

void BeamMaterial::validate(const std::string& what) const
{
    if (!(young_modulus_pa > 0 && std::isfinite(young_modulus_pa))) fail("{}: beam Young's modulus {} Pa must be > 0", what, young_modulus_pa);
    if (!(poisson_ratio > -1 && poisson_ratio < 0.5)) fail("{}: beam Poisson's ratio {} must be in (-1, 0.5)", what, poisson_ratio);
    if (!(shear_correction > 0 && shear_correction <= 1)) fail("{}: shear correction {} must be in (0, 1]", what, shear_correction);
}

Eigen::Matrix<double, 12, 12> EmbeddedBeams::timoshenko_stiffness(double l, double radius, const BeamMaterial& m)
{
    const double e = m.young_modulus_pa * 1e-6, g = e / (2 * (1 + m.poisson_ratio));
    const double area = std::numbers::pi * radius * radius, inertia = std::numbers::pi * std::pow(radius, 4) / 4, polar = 2 * inertia;
    const double phi = 12 * e * inertia / (m.shear_correction * g * area * l * l);
    Eigen::Matrix<double, 12, 12> k = Eigen::Matrix<double, 12, 12>::Zero();
    const auto put = [&](int i, int j, double v) {
        k(i, j) += v;
        if (i != j) k(j, i) += v;
    };
    // Axial (u) and torsion (θx).
    put(0, 0, e * area / l), put(6, 6, e * area / l), put(0, 6, -e * area / l);
    put(3, 3, g * polar / l), put(9, 9, g * polar / l), put(3, 9, -g * polar / l);
    const double a = e * inertia / ((1 + phi) * l * l * l);
    // Bending in the x–y plane: v (1, 7), θz (5, 11).
    put(1, 1, 12 * a), put(7, 7, 12 * a), put(1, 7, -12 * a);
    put(1, 5, 6 * l * a), put(1, 11, 6 * l * a), put(5, 7, -6 * l * a), put(7, 11, -6 * l * a);
    put(5, 5, (4 + phi) * l * l * a), put(11, 11, (4 + phi) * l * l * a), put(5, 11, (2 - phi) * l * l * a);
    // Bending in the x–z plane: w (2, 8), θy (4, 10) — the coupling signs flip.
    put(2, 2, 12 * a), put(8, 8, 12 * a), put(2, 8, -12 * a);
    put(2, 4, -6 * l * a), put(2, 10, -6 * l * a), put(4, 8, 6 * l * a), put(8, 10, 6 * l * a);
    put(4, 4, (4 + phi) * l * l * a), put(10, 10, (4 + phi) * l * l * a), put(4, 10, (2 - phi) * l * l * a);
    return k;
}

EmbeddedBeams::EmbeddedBeams(const VolumeMesh& mesh, const std::vector<VesselBranch>& branches, const BeamMaterial& material, double element_mm,
                             const std::string& what)
{
    material.validate(what);
    if (mesh.cell_type != CellType::tetrahedron) fail("{}: vessel beams embed in tetrahedra only", what);
    if (!(element_mm > 0)) fail("{}: beam element length {} mm must be > 0", what, element_mm);
    const PointLocator locator(mesh);
    struct Embedded {
        std::int32_t cell;
        std::array<double, 4> weights;
    };
    const auto embed = [&](const Vec3& p) -> std::optional<Embedded> {
        const auto e = locator.locate(p);
        if (!e) return std::nullopt;
        return Embedded{e->cell, {1 - e->natural.sum(), e->natural[0], e->natural[1], e->natural[2]}};
    };
    for (std::size_t b = 0; b < branches.size(); ++b) {
        const auto& branch = branches[b];
        if (branch.points.size() != branch.radii_mm.size()) fail("{}: branch {} has {} points but {} radii", what, b, branch.points.size(), branch.radii_mm.size());
        for (std::size_t s = 0; s + 1 < branch.points.size(); ++s) {
            const Vec3 p0 = branch.points[s], p1 = branch.points[s + 1];
            const double length = (p1 - p0).norm();
            if (!(length > 0)) continue; // repeated point
            const int pieces = std::max(1, static_cast<int>(std::ceil(length / element_mm)));
            for (int k = 0; k < pieces; ++k) {
                const double t0 = double(k) / pieces, t1 = double(k + 1) / pieces;
                const Vec3 a = p0 + t0 * (p1 - p0), c = p0 + t1 * (p1 - p0);
                const double radius = branch.radii_mm[s] + 0.5 * (t0 + t1) * (branch.radii_mm[s + 1] - branch.radii_mm[s]);
                const auto ea = embed(a), ec = embed(c);
                if (!ea || !ec) {
                    ++m_dropped;
                    continue;
                }
                Element el;
                el.length_mm = (c - a).norm();
                const Embedded ends[2] = {*ea, *ec};
                // T (12×24): beam node displacement = Σ w_k w_k', rotation = ½ Σ ∇N_k × w_k.
                Eigen::Matrix<double, 12, 24> t = Eigen::Matrix<double, 12, 24>::Zero();
                for (int end = 0; end < 2; ++end) {
                    const auto ids = mesh.cell(static_cast<std::size_t>(ends[end].cell));
                    Mat3 j;
                    for (int d = 0; d < 3; ++d) j.col(d) = mesh.nodes[ids[d + 1]] - mesh.nodes[ids[0]];
                    const Mat3 inverse = j.inverse();
                    for (int k2 = 0; k2 < 4; ++k2) {
                        const int slot = 4 * end + k2;
                        el.nodes[slot] = ids[k2];
                        el.rest[slot] = mesh.nodes[ids[k2]];
                        el.gradient[slot] = k2 == 0 ? Vec3(-(inverse.row(0) + inverse.row(1) + inverse.row(2)).transpose()) : Vec3(inverse.row(k2 - 1).transpose());
                        t.block<3, 3>(6 * end, 3 * slot) = ends[end].weights[k2] * Mat3::Identity();
                        t.block<3, 3>(6 * end + 3, 3 * slot) = 0.5 * cross_matrix(el.gradient[slot]);
                    }
                }
                // The element's axes: e1 along the beam, e2 and e3 across (any pair, the section is round).
                const Vec3 e1 = (c - a).normalized();
                const Vec3 e2 = (std::abs(e1.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(e1).normalized(), e3 = e1.cross(e2);
                Mat3 axes;
                axes << e1, e2, e3; // columns: local → global
                Eigen::Matrix<double, 12, 12> to_local = Eigen::Matrix<double, 12, 12>::Zero();
                for (int q = 0; q < 4; ++q) to_local.block<3, 3>(3 * q, 3 * q) = axes.transpose();
                const Eigen::Matrix<double, 12, 12> k_local = timoshenko_stiffness(el.length_mm, radius, material);
                el.stiffness = t.transpose() * to_local.transpose() * k_local * to_local * t;
                m_elements.push_back(el);
            }
        }
    }
    if (m_elements.empty()) fail("{}: no vessel segment lies inside the model ({} segment(s) outside)", what, m_dropped);
}

std::vector<std::vector<std::int32_t>> EmbeddedBeams::stencils() const
{
    std::vector<std::vector<std::int32_t>> out;
    for (const auto& e : m_elements) out.emplace_back(e.nodes.begin(), e.nodes.end());
    return out;
}

double EmbeddedBeams::total_length_mm() const
{
    double sum = 0.0;
    for (const auto& e : m_elements) sum += e.length_mm;
    return sum;
}

void EmbeddedBeams::unrotate(const Element& e, const double* u, Mat3& r, Eigen::Matrix<double, 24, 1>& w) const
{
    Mat3 f = Mat3::Zero();
    for (int k = 0; k < 8; ++k) {
        const Vec3 uk(u[3 * e.nodes[k]], u[3 * e.nodes[k] + 1], u[3 * e.nodes[k] + 2]);
        f += 0.5 * uk * e.gradient[k].transpose();
    }
    f += Mat3::Identity();
    const Eigen::JacobiSVD<Mat3> svd(f, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Mat3 v = svd.matrixV();
    if ((svd.matrixU() * v.transpose()).determinant() < 0) v.col(2) *= -1; // a proper rotation even if the mean F is inverted
    r = svd.matrixU() * v.transpose();
    for (int k = 0; k < 8; ++k) {
        const Vec3 x = e.rest[k] + Vec3(u[3 * e.nodes[k]], u[3 * e.nodes[k] + 1], u[3 * e.nodes[k] + 2]);
        w.segment<3>(3 * k) = r.transpose() * x - e.rest[k];
    }
}

double EmbeddedBeams::add_forces(const double* u, double* f) const
{
    double energy = 0.0;
    Mat3 r;
    Eigen::Matrix<double, 24, 1> w;
    for (const auto& e : m_elements) {
        unrotate(e, u, r, w);
        const Eigen::Matrix<double, 24, 1> g = e.stiffness * w;
        energy += 0.5 * w.dot(g);
        for (int k = 0; k < 8; ++k) {
            const Vec3 fk = r * g.segment<3>(3 * k);
            for (int d = 0; d < 3; ++d) f[3 * e.nodes[k] + d] += fk[d];
        }
    }
    return energy;
}

void EmbeddedBeams::add_stiffness(const double* u, const StiffnessAssembler& assembler, double* values) const
{
    Mat3 r;
    Eigen::Matrix<double, 24, 1> w;
    for (const auto& e : m_elements) {
        unrotate(e, u, r, w);
        for (int a = 0; a < 8; ++a)
            for (int b = 0; b < 8; ++b) {
                const Mat3 k = r * e.stiffness.block<3, 3>(3 * a, 3 * b) * r.transpose();
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j) values[assembler.value_index(e.nodes[a], e.nodes[b], i, j)] += k(i, j);
            }
    }
}

} // namespace physreg
