// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Blocks and node selections for the mechanics verification tests.
#include "physreg/mechanics/explicit/tled_solver.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/tet_split.hpp"
#include "test_support.hpp"

#include <cmath>

namespace physreg::test {

/// A block [0, nx·h] × [0, ny·h] × [0, nz·h] mm of one tissue (label 1), grid hexahedra.
inline VolumeMesh block_mesh(int nx, int ny, int nz, double h)
{
    const auto volume = make_volume({nx, ny, nz}, [](int, int, int) { return std::uint16_t(1); }, Vec3::Constant(h),
                                    Vec3::Constant(h / 2));
    TissueTable t;
    t.tissues = {{1, "tissue", 1e5, 0.3, 1000}};
    return mesh_label_volume(volume, t, {}, "block").mesh;
}

inline TissueTable one_tissue(double young_pa, double nu)
{
    TissueTable t;
    t.tissues = {{1, "tissue", young_pa, nu, 1000}};
    return t;
}

/// Nodes whose coordinate `axis` equals `value` (within 1e-9 mm).
inline std::vector<std::int32_t> nodes_at(const VolumeMesh& mesh, int axis, double value)
{
    std::vector<std::int32_t> out;
    for (std::size_t n = 0; n < mesh.node_count(); ++n)
        if (std::abs(mesh.nodes[n][axis] - value) < 1e-9) out.push_back(static_cast<std::int32_t>(n));
    return out;
}

inline std::int32_t node_at(const VolumeMesh& mesh, const Vec3& p)
{
    for (std::size_t n = 0; n < mesh.node_count(); ++n)
        if ((mesh.nodes[n] - p).norm() < 1e-9) return static_cast<std::int32_t>(n);
    return -1;
}

/// Uniaxial stretch along x of the block [0,L]×[0,W]×[0,H]: x = 0 held in x, x = L moved by
/// (stretch − 1)·L, three corner nodes remove rigid motion without restraining lateral contraction.
inline Loads uniaxial_loads(const VolumeMesh& mesh, double length, double width, double height, double stretch)
{
    Loads loads;
    loads.constraints.push_back({"x0", nodes_at(mesh, 0, 0.0), {true, false, false}, Vec3::Zero()});
    loads.constraints.push_back({"xL", nodes_at(mesh, 0, length), {true, false, false}, Vec3((stretch - 1) * length, 0, 0)});
    loads.constraints.push_back({"origin", {node_at(mesh, Vec3::Zero())}, {false, true, true}, Vec3::Zero()});
    loads.constraints.push_back({"y-edge", {node_at(mesh, Vec3(0, width, 0))}, {false, false, true}, Vec3::Zero()});
    loads.constraints.push_back({"z-edge", {node_at(mesh, Vec3(0, 0, height))}, {false, true, false}, Vec3::Zero()});
    return loads;
}

/// Analytical uniaxial response of the decoupled Neo-Hookean law (traction-free lateral faces):
/// returns {lateral stretch, nominal stress P11 in MPa}.
inline std::pair<double, double> neo_hookean_uniaxial(double stretch, const ElasticMaterial& m)
{
    auto sigma = [&](double l1, double l2, int component) {
        const double j = l1 * l2 * l2;
        const double i1 = l1 * l1 + 2 * l2 * l2;
        const double b = component == 0 ? l1 * l1 : l2 * l2;
        return m.mu_mpa * std::pow(j, -5.0 / 3.0) * (b - i1 / 3.0) + m.kappa_mpa * (j - 1.0);
    };
    double l2 = 1.0;
    for (int it = 0; it < 100; ++it) { // Newton on σ22(λ2) = 0 with a numerical derivative
        const double s = sigma(stretch, l2, 1);
        const double ds = (sigma(stretch, l2 + 1e-7, 1) - sigma(stretch, l2 - 1e-7, 1)) / 2e-7;
        l2 -= s / ds;
        if (std::abs(s) < 1e-14) break;
    }
    const double p11 = sigma(stretch, l2, 0) * l2 * l2; // P = J σ F⁻ᵀ → P11 = λ2² σ11
    return {l2, p11};
}

/// Sum of the x-components of the internal forces on `nodes`, N.
inline double force_x(const std::vector<double>& forces, const std::vector<std::int32_t>& nodes)
{
    double sum = 0;
    for (auto n : nodes) sum += forces[3 * n];
    return sum;
}

// A block held at its base (z = 0) and pressed by a sphere of `radius_mm` moving along `path`.
inline Loads base_held_sphere_press(const VolumeMesh& mesh, double radius_mm, std::vector<Vec3> path)
{
    Loads loads;
    loads.constraints.push_back({"base", nodes_at(mesh, 2, 0.0), {true, true, true}, Vec3::Zero()});
    Indenter sphere;
    sphere.name = "sphere";
    sphere.radius_mm = radius_mm;
    sphere.path = std::move(path);
    loads.indenters.push_back(sphere);
    return loads;
}

} // namespace physreg::test
