// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/field/image_warping.hpp"

#include "physreg/core/error.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace physreg {
namespace {

bool same_grid(const ImageGeometry& a, const ImageGeometry& b)
{
    return a.size == b.size && (a.origin - b.origin).norm() < 1e-6 && (a.spacing - b.spacing).norm() < 1e-9 &&
           (a.direction - b.direction).norm() < 1e-9;
}

// Newton inversion of a trilinear hexahedron: ξ with Σ N_a(ξ) x_a = p.
bool invert_hexahedron(const std::array<Vec3, 8>& x, const Vec3& p, Vec3& xi)
{
    xi.setZero();
    for (int it = 0; it < 25; ++it) {
        Vec3 r = -p;
        Mat3 jacobian = Mat3::Zero();
        for (int a = 0; a < 8; ++a) {
            const Vec3 c = hex_corner_natural(a);
            const double n0 = 1 + c[0] * xi[0], n1 = 1 + c[1] * xi[1], n2 = 1 + c[2] * xi[2];
            r += 0.125 * n0 * n1 * n2 * x[a];
            jacobian.col(0) += 0.125 * c[0] * n1 * n2 * x[a];
            jacobian.col(1) += 0.125 * n0 * c[1] * n2 * x[a];
            jacobian.col(2) += 0.125 * n0 * n1 * c[2] * x[a];
        }
        const Vec3 step = jacobian.partialPivLu().solve(r);
        if (!step.allFinite()) return false;
        xi -= step;
        if (xi.cwiseAbs().maxCoeff() > 3.0) return false;
        if (step.cwiseAbs().maxCoeff() < 1e-10) return true;
    }
    return false;
}

// Barycentric coordinates of p in a tetrahedron, as ξ = (λ1, λ2, λ3).
bool invert_tetrahedron(const std::array<Vec3, 8>& x, const Vec3& p, Vec3& xi)
{
    Mat3 m;
    m << x[1] - x[0], x[2] - x[0], x[3] - x[0];
    xi = m.partialPivLu().solve(p - x[0]);
    return xi.allFinite();
}

} // namespace

InverseMap rasterize_inverse_map(const VolumeMesh& mesh, const std::vector<double>& displacement_mm,
                                 const ImageGeometry& geometry, double extension_mm)
{
    if (displacement_mm.size() != 3 * mesh.node_count())
        fail("inverse map: {} displacement values for {} nodes", displacement_mm.size(), mesh.node_count());
    if (!(extension_mm >= 0.0) || !std::isfinite(extension_mm)) fail("inverse map: extension {} mm must be ≥ 0", extension_mm);
    geometry.validate("inverse map grid");
    InverseMap map;
    map.field.geometry = geometry;
    const auto voxels = static_cast<std::size_t>(geometry.voxel_count());
    map.field.components.assign(3 * voxels, 0.f);
    map.coverage.assign(voxels, 0);
    const bool hexahedra = mesh.cell_type == CellType::hexahedron;
    const int per_cell = mesh.cell_size();
    const double tolerance = 1e-6;
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const auto cell = mesh.cell(c);
        std::array<Vec3, 8> rest{}, deformed{};
        Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
        for (int a = 0; a < per_cell; ++a) {
            const auto n = static_cast<std::size_t>(cell[a]);
            rest[a] = mesh.nodes[n];
            deformed[a] = rest[a] + Vec3(displacement_mm[3 * n], displacement_mm[3 * n + 1], displacement_mm[3 * n + 2]);
            const Vec3 index = geometry.physical_to_index(deformed[a]);
            lo = lo.cwiseMin(index);
            hi = hi.cwiseMax(index);
        }
        std::array<std::int64_t, 3> first{}, last{};
        bool empty = false;
        for (int a = 0; a < 3; ++a) {
            first[a] = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil(lo[a] - 1e-9)));
            last[a] = std::min<std::int64_t>(geometry.size[a] - 1, static_cast<std::int64_t>(std::floor(hi[a] + 1e-9)));
            empty |= first[a] > last[a];
        }
        if (empty) continue;
        Vec3 xi = Vec3::Zero();
        for (std::int64_t k = first[2]; k <= last[2]; ++k)
            for (std::int64_t j = first[1]; j <= last[1]; ++j)
                for (std::int64_t i = first[0]; i <= last[0]; ++i) {
                    const auto v = static_cast<std::size_t>(geometry.linear_index(i, j, k));
                    if (map.coverage[v] == 1) continue;
                    const Vec3 p = geometry.index_to_physical(Vec3(double(i), double(j), double(k)));
                    Vec3 restpoint;
                    if (hexahedra) {
                        if (!invert_hexahedron(deformed, p, xi) || xi.cwiseAbs().maxCoeff() > 1 + tolerance) continue;
                        const auto n = hex_shape_functions(xi);
                        restpoint.setZero();
                        for (int a = 0; a < 8; ++a) restpoint += n[a] * rest[a];
                    } else {
                        if (!invert_tetrahedron(deformed, p, xi) || xi.minCoeff() < -tolerance || xi.sum() > 1 + tolerance) continue;
                        restpoint = rest[0] + xi[0] * (rest[1] - rest[0]) + xi[1] * (rest[2] - rest[0]) + xi[2] * (rest[3] - rest[0]);
                    }
                    const Vec3 d = restpoint - p;
                    for (int a = 0; a < 3; ++a) map.field.components[3 * v + a] = static_cast<float>(d[a]);
                    map.coverage[v] = 1;
                }
    }
    // Extension band, one layer of face neighbours at a time.
    const int layers = static_cast<int>(std::ceil(extension_mm / geometry.spacing.minCoeff()));
    std::vector<std::size_t> layer;
    const std::int64_t nx = geometry.size[0], ny = geometry.size[1], nz = geometry.size[2];
    for (int l = 0; l < layers; ++l) {
        layer.clear();
        for (std::int64_t k = 0; k < nz; ++k)
            for (std::int64_t j = 0; j < ny; ++j)
                for (std::int64_t i = 0; i < nx; ++i) {
                    const auto v = static_cast<std::size_t>(geometry.linear_index(i, j, k));
                    if (map.coverage[v]) continue;
                    const bool near = (i > 0 && map.coverage[v - 1]) || (i + 1 < nx && map.coverage[v + 1]) ||
                                      (j > 0 && map.coverage[v - nx]) || (j + 1 < ny && map.coverage[v + nx]) ||
                                      (k > 0 && map.coverage[v - nx * ny]) || (k + 1 < nz && map.coverage[v + nx * ny]);
                    if (near) layer.push_back(v);
                }
        if (layer.empty()) break;
        std::vector<float> values(3 * layer.size(), 0.f);
        for (std::size_t q = 0; q < layer.size(); ++q) {
            const std::size_t v = layer[q];
            const std::int64_t i = static_cast<std::int64_t>(v) % nx, j = (static_cast<std::int64_t>(v) / nx) % ny,
                               k = static_cast<std::int64_t>(v) / (nx * ny);
            int count = 0;
            auto add = [&](bool valid, std::size_t w) {
                if (!valid || !map.coverage[w]) return;
                for (int a = 0; a < 3; ++a) values[3 * q + a] += map.field.components[3 * w + a];
                ++count;
            };
            add(i > 0, v - 1);
            add(i + 1 < nx, v + 1);
            add(j > 0, v - nx);
            add(j + 1 < ny, v + nx);
            add(k > 0, v - nx * ny);
            add(k + 1 < nz, v + nx * ny);
            for (int a = 0; a < 3; ++a) values[3 * q + a] /= static_cast<float>(count);
        }
        for (std::size_t q = 0; q < layer.size(); ++q) {
            for (int a = 0; a < 3; ++a) map.field.components[3 * layer[q] + a] = values[3 * q + a];
            map.coverage[layer[q]] = 2;
        }
    }
    return map;
}

namespace {

std::int64_t nearest_voxel(const ImageGeometry& g, const Vec3& p)
{
    const Vec3 index = g.physical_to_index(p);
    std::int64_t ijk[3];
    for (int a = 0; a < 3; ++a) {
        ijk[a] = static_cast<std::int64_t>(std::lround(index[a]));
        if (ijk[a] < 0 || ijk[a] >= g.size[a]) return -1;
    }
    return g.linear_index(ijk[0], ijk[1], ijk[2]);
}

Vec3 rest_point(const InverseMap& map, std::size_t v, const Vec3& x)
{
    return x + Vec3(map.field.components[3 * v], map.field.components[3 * v + 1], map.field.components[3 * v + 2]);
}

} // namespace

LabelVolume warp_labels(const LabelVolume& rest, const InverseMap& map,
                        const std::function<bool(std::int32_t)>& deforming, std::uint16_t fill_label)
{
    const auto& g = rest.geometry;
    if (!same_grid(g, map.field.geometry)) fail("warp labels: the inverse map's grid differs from the label volume's");
    LabelVolume out = rest;
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const auto v = static_cast<std::size_t>(g.linear_index(i, j, k));
                std::uint16_t label = rest.labels[v];
                const bool was_deforming = deforming(label);
                bool placed = false;
                if (map.coverage[v]) {
                    const auto w = nearest_voxel(g, rest_point(map, v, g.index_to_physical(Vec3(double(i), double(j), double(k)))));
                    if (w >= 0) {
                        const auto source = rest.labels[static_cast<std::size_t>(w)];
                        if (map.coverage[v] == 1 || deforming(source)) {
                            label = source;
                            placed = deforming(source);
                        }
                    }
                }
                if (!placed && was_deforming && label == rest.labels[v]) label = fill_label;
                out.labels[v] = label;
            }
    return out;
}

ScalarImage warp_intensity(const ScalarImage& rest, const LabelVolume& rest_labels, const LabelVolume& deformed_labels,
                           const InverseMap& map, const std::function<bool(std::int32_t)>& deforming, float fill_value)
{
    const auto& g = rest.geometry;
    if (!same_grid(g, map.field.geometry) || !same_grid(g, rest_labels.geometry) || !same_grid(g, deformed_labels.geometry))
        fail("warp intensity: the images' grids differ");
    ScalarImage out = rest;
    auto sample = [&](const Vec3& p) -> float {
        const Vec3 index = g.physical_to_index(p);
        double value = 0.0;
        for (int corner = 0; corner < 8; ++corner) {
            double weight = 1.0;
            std::int64_t ijk[3];
            for (int a = 0; a < 3; ++a) {
                const double f = std::floor(index[a]);
                const double t = index[a] - f;
                const int bit = (corner >> a) & 1;
                ijk[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>(f) + bit, 0, g.size[a] - 1);
                weight *= bit ? t : 1 - t;
            }
            value += weight * rest.values[static_cast<std::size_t>(g.linear_index(ijk[0], ijk[1], ijk[2]))];
        }
        return static_cast<float>(value);
    };
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const auto v = static_cast<std::size_t>(g.linear_index(i, j, k));
                const bool now_deforming = deforming(deformed_labels.labels[v]);
                if (now_deforming && map.coverage[v])
                    out.values[v] = sample(rest_point(map, v, g.index_to_physical(Vec3(double(i), double(j), double(k)))));
                else if (deforming(rest_labels.labels[v]) && !now_deforming)
                    out.values[v] = fill_value;
            }
    return out;
}

} // namespace physreg
