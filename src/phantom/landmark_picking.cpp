// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/phantom/landmark_picking.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <map>
#include <optional>

namespace physreg {
namespace {

// A face between a voxel inside a region and one outside: its centre and outward direction.
struct BoundaryFace {
    Vec3 centre, normal;
};

template <typename Inside>
std::vector<BoundaryFace> boundary_faces(const LabelVolume& v, Inside inside)
{
    const auto& g = v.geometry;
    std::vector<BoundaryFace> faces;
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                if (!inside(v.at(i, j, k))) continue;
                const std::int64_t ijk[3] = {i, j, k};
                for (int a = 0; a < 3; ++a)
                    for (int s : {-1, 1}) {
                        std::int64_t n[3] = {i, j, k};
                        n[a] += s;
                        const bool outside = n[a] < 0 || n[a] >= g.size[a] || !inside(v.at(n[0], n[1], n[2]));
                        if (!outside) continue;
                        Vec3 index = Vec3(double(ijk[0]), double(ijk[1]), double(ijk[2]));
                        index[a] += 0.5 * s;
                        Vec3 step = Vec3::Zero();
                        step[a] = s;
                        faces.push_back({g.index_to_physical(index), (g.direction * step).normalized()});
                    }
            }
    return faces;
}

bool far_from(const Vec3& p, const LandmarkSet& set, double separation)
{
    for (const auto& l : set)
        if ((l.position - p).norm() < separation) return false;
    return true;
}

// The extreme boundary face in direction `d` that keeps its distance from the picked ones.
std::optional<Vec3> extreme_point(const std::vector<BoundaryFace>& faces, const Vec3& d, const LandmarkSet& picked, double separation)
{
    std::vector<std::pair<double, std::size_t>> order;
    order.reserve(faces.size());
    for (std::size_t f = 0; f < faces.size(); ++f)
        if (faces[f].normal.dot(d) > 0.0) order.emplace_back(-faces[f].centre.dot(d), f);
    std::sort(order.begin(), order.end());
    for (const auto& [score, f] : order)
        if (far_from(faces[f].centre, picked, separation)) return faces[f].centre;
    return std::nullopt;
}

struct Components {
    std::vector<std::int32_t> id; // per voxel, -1 outside
    std::vector<std::vector<std::size_t>> voxels;
};

template <typename Inside>
Components connected_components(const LabelVolume& v, Inside inside)
{
    const auto& g = v.geometry;
    Components c;
    c.id.assign(v.labels.size(), -1);
    const std::int64_t nx = g.size[0], ny = g.size[1], nz = g.size[2];
    for (std::size_t seed = 0; seed < v.labels.size(); ++seed) {
        if (c.id[seed] >= 0 || !inside(v.labels[seed])) continue;
        const auto id = static_cast<std::int32_t>(c.voxels.size());
        c.voxels.emplace_back();
        std::deque<std::size_t> queue{seed};
        c.id[seed] = id;
        while (!queue.empty()) {
            const std::size_t w = queue.front();
            queue.pop_front();
            c.voxels.back().push_back(w);
            const std::int64_t i = static_cast<std::int64_t>(w) % nx, j = (static_cast<std::int64_t>(w) / nx) % ny,
                               k = static_cast<std::int64_t>(w) / (nx * ny);
            for (std::int64_t dk = -1; dk <= 1; ++dk)
                for (std::int64_t dj = -1; dj <= 1; ++dj)
                    for (std::int64_t di = -1; di <= 1; ++di) {
                        const std::int64_t a = i + di, b = j + dj, e = k + dk;
                        if (a < 0 || b < 0 || e < 0 || a >= nx || b >= ny || e >= nz) continue;
                        const auto n = static_cast<std::size_t>(g.linear_index(a, b, e));
                        if (c.id[n] >= 0 || !inside(v.labels[n])) continue;
                        c.id[n] = id;
                        queue.push_back(n);
                    }
        }
    }
    return c;
}

Vec3 centroid(const LabelVolume& v, const std::vector<std::size_t>& voxels)
{
    const auto& g = v.geometry;
    Vec3 sum = Vec3::Zero();
    for (const auto w : voxels) {
        const std::int64_t nx = g.size[0], ny = g.size[1];
        const auto s = static_cast<std::int64_t>(w);
        sum += g.index_to_physical(Vec3(double(s % nx), double((s / nx) % ny), double(s / (nx * ny))));
    }
    return sum / static_cast<double>(voxels.size());
}

// Vessel bifurcations of one tree-like component: fronts of a breadth-first search from one of
// its extremities, cut in bands of geodesic distance; where a band's piece touches two or more
// pieces of the next band, the front has split. Also returns points every `spacing` along.
void vessel_features(const LabelVolume& v, const std::vector<std::size_t>& voxels, double band_mm,
                     std::vector<Vec3>& bifurcations, std::vector<Vec3>& along)
{
    const auto& g = v.geometry;
    const std::int64_t nx = g.size[0], ny = g.size[1], nz = g.size[2];
    std::map<std::size_t, std::size_t> local;
    for (std::size_t q = 0; q < voxels.size(); ++q) local[voxels[q]] = q;
    // Calls visit(neighbour, axis) for each face neighbour of component voxel q inside the component.
    auto for_each_neighbour = [&](std::size_t q, const auto& visit) {
        const auto s = static_cast<std::int64_t>(voxels[q]);
        const std::int64_t i = s % nx, j = (s / nx) % ny, k = s / (nx * ny);
        for (int a = 0; a < 3; ++a)
            for (int d : {-1, 1}) {
                std::int64_t n[3] = {i, j, k};
                n[a] += d;
                if (n[a] < 0 || n[a] >= (a == 0 ? nx : a == 1 ? ny : nz)) continue;
                const auto it = local.find(static_cast<std::size_t>(g.linear_index(n[0], n[1], n[2])));
                if (it != local.end()) visit(it->second, a);
            }
    };
    auto bfs = [&](std::size_t start, std::vector<double>& distance) {
        distance.assign(voxels.size(), -1.0);
        std::deque<std::size_t> queue{start};
        distance[start] = 0;
        while (!queue.empty()) {
            const std::size_t q = queue.front();
            queue.pop_front();
            for_each_neighbour(q, [&](std::size_t n, int axis) {
                if (distance[n] >= 0) return;
                distance[n] = distance[q] + g.spacing[axis];
                queue.push_back(n);
            });
        }
    };
    std::vector<double> distance;
    bfs(0, distance);
    std::size_t extremity = 0;
    for (std::size_t q = 0; q < voxels.size(); ++q)
        if (distance[q] > distance[extremity]) extremity = q;
    bfs(extremity, distance);
    // Pieces of each band: union-find over face neighbours in the same band.
    std::vector<std::size_t> parent(voxels.size());
    for (std::size_t q = 0; q < parent.size(); ++q) parent[q] = q;
    std::function<std::size_t(std::size_t)> root = [&](std::size_t q) { return parent[q] == q ? q : parent[q] = root(parent[q]); };
    auto band = [&](std::size_t q) { return distance[q] < 0 ? -1L : static_cast<long>(distance[q] / band_mm); };
    for (std::size_t q = 0; q < voxels.size(); ++q)
        if (distance[q] >= 0)
            for_each_neighbour(q, [&](std::size_t n, int) {
                if (distance[n] >= 0 && band(n) == band(q)) parent[root(q)] = root(n);
            });
    std::vector<std::pair<std::size_t, std::size_t>> cross; // (piece in band b, piece in band b+1)
    for (std::size_t q = 0; q < voxels.size(); ++q)
        if (distance[q] >= 0)
            for_each_neighbour(q, [&](std::size_t n, int) {
                if (distance[n] >= 0 && band(n) == band(q) + 1) cross.emplace_back(root(q), root(n));
            });
    std::map<std::size_t, std::vector<std::size_t>> children;
    for (const auto& [piece, next] : cross) children[piece].push_back(next);
    std::map<std::size_t, std::vector<std::size_t>> members;
    for (std::size_t q = 0; q < voxels.size(); ++q)
        if (distance[q] >= 0) members[root(q)].push_back(voxels[q]);
    for (auto& [piece, next] : children) {
        std::sort(next.begin(), next.end());
        next.erase(std::unique(next.begin(), next.end()), next.end());
        // A split counts when at least two child pieces have ≥ 4 voxels (not a one-voxel bump of the wall).
        int substantial = 0;
        for (const auto n : next) substantial += members[n].size() >= 4 ? 1 : 0;
        if (substantial >= 2) bifurcations.push_back(centroid(v, members[piece]));
    }
    // Points along: centroids of pieces every third band.
    for (const auto& [piece, m] : members) {
        const long b = band(local[m.front()]);
        if (b % 3 == 1 && m.size() >= 4) along.push_back(centroid(v, m));
    }
}

} // namespace

std::optional<double> find_margin_notch_x(const LabelVolume& labels, const LabelRoles& roles)
{
    auto liver = [&](std::int32_t l) { return roles.is_liver_tissue(l); };
    const auto faces = boundary_faces(labels, liver);
    if (faces.empty()) return std::nullopt;
    const Vec3 d = Vec3(0, -1, -1).normalized(); // anterior-inferior
    double xmin = 1e300, xmax = -1e300;
    for (const auto& f : faces) {
        xmin = std::min(xmin, f.centre.x());
        xmax = std::max(xmax, f.centre.x());
    }
    const double bin = 4.0;
    const int bins = std::max(1, static_cast<int>((xmax - xmin) / bin) + 1);
    std::vector<double> support(bins, -1e300);
    for (const auto& f : faces) {
        const int b = std::min(bins - 1, static_cast<int>((f.centre.x() - xmin) / bin));
        support[b] = std::max(support[b], f.centre.dot(d));
    }
    // Deepest dip below the lower of the highest points on its left and right.
    std::optional<double> best;
    double best_depth = 2.0;
    for (int b = bins / 6; b < bins - bins / 6; ++b) {
        double left = -1e300, right = -1e300;
        for (int q = 0; q < b; ++q) left = std::max(left, support[q]);
        for (int q = b + 1; q < bins; ++q) right = std::max(right, support[q]);
        const double depth = std::min(left, right) - support[b];
        if (depth > best_depth) {
            best_depth = depth;
            best = xmin + (b + 0.5) * bin;
        }
    }
    return best;
}

LandmarkSet pick_landmarks(const LabelVolume& labels, const LabelRoles& roles, const LandmarkPickingOptions& options)
{
    auto liver = [&](std::int32_t l) { return roles.is_liver_tissue(l); };
    const auto faces = boundary_faces(labels, liver);
    if (faces.empty()) fail("landmarks: the label map has no liver voxel (liver labels given: {})", fmt::join(roles.liver, ","));
    LandmarkSet surface;
    // Tips and ridges: extreme points in anatomical directions (LPS: +x left, +y posterior, +z superior).
    const std::pair<const char*, Vec3> directions[] = {
        {"right_tip", {-1, 0, 0}},         {"left_tip", {1, 0, 0}},
        {"dome", {0, 0, 1}},               {"inferior_tip", {0, 0, -1}},
        {"anterior_point", {0, -1, 0}},    {"right_anterior_ridge", {-1, -1, 0}},
        {"left_anterior_ridge", {1, -1, 0}}, {"anterior_inferior_margin", {0, -1, -1}},
        {"right_inferior_ridge", {-1, 0, -1}}, {"left_superior_ridge", {1, 0, 1}},
        {"posterior_superior_ridge", {0, 1, 1}}, {"left_inferior_ridge", {1, 0, -1}},
        {"right_superior_ridge", {-1, 0, 1}}, {"posterior_point", {0, 1, 0}}};
    // The notch first: the extreme anterior-inferior point within the cleft's x band.
    if (const auto notch_x = find_margin_notch_x(labels, roles)) {
        std::vector<BoundaryFace> band;
        for (const auto& f : faces)
            if (std::abs(f.centre.x() - *notch_x) <= 2.0) band.push_back(f);
        if (auto p = extreme_point(band, Vec3(0, -1, -1).normalized(), surface, options.surface_separation_mm))
            surface.push_back({"umbilical_notch", *p, LandmarkType::surface});
    }
    for (const auto& [name, d] : directions) {
        if (static_cast<int>(surface.size()) >= options.surface_count) break;
        if (auto p = extreme_point(faces, d.normalized(), surface, options.surface_separation_mm))
            surface.push_back({name, *p, LandmarkType::surface});
    }
    if (static_cast<int>(surface.size()) < options.surface_count)
        fail("landmarks: only {} of {} surface landmarks fit {} mm apart (liver too small for this resolution?)",
             surface.size(), options.surface_count, options.surface_separation_mm);

    LandmarkSet internal;
    // Lesions, largest first: anterior pole, then (second pass) posterior pole.
    auto lesion = [&](std::int32_t l) { return roles.lesion.count(l) > 0; };
    const auto lesions = connected_components(labels, lesion);
    std::vector<std::size_t> order(lesions.voxels.size());
    for (std::size_t q = 0; q < order.size(); ++q) order[q] = q;
    std::stable_sort(order.begin(), order.end(), [&](auto a, auto b) { return lesions.voxels[a].size() > lesions.voxels[b].size(); });
    std::vector<std::vector<BoundaryFace>> lesion_faces(lesions.voxels.size());
    for (const auto& f : boundary_faces(labels, lesion)) {
        // The face's voxel: half a voxel inwards.
        const Vec3 inside = labels.geometry.physical_to_index(f.centre - 0.25 * labels.geometry.spacing.minCoeff() * f.normal);
        const std::int64_t i = std::lround(inside[0]), j = std::lround(inside[1]), k = std::lround(inside[2]);
        const auto id = lesions.id[static_cast<std::size_t>(labels.geometry.linear_index(i, j, k))];
        if (id >= 0) lesion_faces[static_cast<std::size_t>(id)].push_back(f);
    }
    const int wanted = options.internal_count;
    auto add_internal = [&](const std::string& name, const Vec3& p, LandmarkType type) {
        if (static_cast<int>(internal.size()) < wanted && far_from(p, internal, options.internal_separation_mm)) {
            internal.push_back({name, p, type});
            return true;
        }
        return false;
    };
    int lesion_number = 0;
    for (const auto q : order) {
        ++lesion_number;
        if (auto p = extreme_point(lesion_faces[q], Vec3(0, -1, 0), {}, 0.0))
            add_internal(fmt::format("lesion{}_anterior_boundary", lesion_number), *p, LandmarkType::tumour);
    }
    // Vessel bifurcations.
    auto vessel = [&](std::int32_t l) { return roles.vessel.count(l) > 0; };
    const auto trees = connected_components(labels, vessel);
    std::vector<Vec3> bifurcations, along;
    const double band = std::max(3.0, 2.0 * labels.geometry.spacing.maxCoeff());
    for (const auto& tree : trees.voxels)
        if (tree.size() >= 8) vessel_features(labels, tree, band, bifurcations, along);
    int bifurcation_number = 0;
    for (const auto& p : bifurcations) {
        if (add_internal(fmt::format("vessel_bifurcation{}", bifurcation_number + 1), p, LandmarkType::vessel)) ++bifurcation_number;
    }
    lesion_number = 0;
    for (const auto q : order) {
        ++lesion_number;
        if (auto p = extreme_point(lesion_faces[q], Vec3(0, 1, 0), {}, 0.0))
            add_internal(fmt::format("lesion{}_posterior_boundary", lesion_number), *p, LandmarkType::tumour);
    }
    int along_number = 0;
    for (const auto& p : along)
        if (add_internal(fmt::format("vessel_point{}", along_number + 1), p, LandmarkType::vessel)) ++along_number;
    if (static_cast<int>(internal.size()) < wanted) {
        // Deep parenchyma: liver voxels far from the surface, on a coarse lattice.
        auto parenchyma = [&](std::int32_t l) { return roles.liver.count(l) > 0; };
        const auto& g = labels.geometry;
        std::vector<std::pair<double, Vec3>> candidates;
        const std::int64_t stride = std::max<std::int64_t>(1, static_cast<std::int64_t>(8.0 / g.spacing.minCoeff()));
        for (std::int64_t k = 0; k < g.size[2]; k += stride)
            for (std::int64_t j = 0; j < g.size[1]; j += stride)
                for (std::int64_t i = 0; i < g.size[0]; i += stride) {
                    if (!parenchyma(labels.at(i, j, k))) continue;
                    const Vec3 p = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                    double depth = 1e300;
                    for (std::size_t f = 0; f < faces.size(); f += 7) depth = std::min(depth, (faces[f].centre - p).norm());
                    candidates.emplace_back(-depth, p);
                }
        std::stable_sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
        // 15 mm apart; in a small organ (a prostate-sized gland) closer, down to 6 mm, rather than fail.
        int deep = 0;
        for (const double separation : {15.0, 10.0, 6.0})
            for (const auto& [score, p] : candidates)
                if (static_cast<int>(internal.size()) < wanted && far_from(p, internal, separation)) {
                    internal.push_back({fmt::format("parenchyma_point{}", ++deep), p, LandmarkType::unspecified});
                }
    }
    if (static_cast<int>(internal.size()) < wanted)
        fail("landmarks: only {} of {} internal landmarks found", internal.size(), wanted);
    LandmarkSet all;
    int n = 0;
    for (const auto& l : surface) all.push_back({fmt::format("S{:02d}_{}", ++n, l.name), l.position, l.type});
    n = 0;
    for (const auto& l : internal) all.push_back({fmt::format("I{:02d}_{}", ++n, l.name), l.position, l.type});
    return all;
}

} // namespace physreg
