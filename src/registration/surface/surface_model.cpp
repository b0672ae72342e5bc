// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/surface/surface_model.hpp"

#include "physreg/core/error.hpp"
#include "physreg/mesh/labelled_boundary.hpp"

#include <algorithm>
#include <limits>
#include <map>

namespace physreg {


SurfaceModel surface_model_from_labels(const LabelVolume& labels, const std::set<std::int32_t>& liver_labels, double cell_size_mm,
                                       std::optional<double> notch_x_mm, unsigned seed, const std::string& what)
{
    if (liver_labels.empty()) fail("{}: no liver label selected", what);
    TetMeshingOptions options;
    options.labels = liver_labels;
    options.default_cell_size_mm = cell_size_mm;
    const double voxel = labels.geometry.spacing.minCoeff();
    options.facet_size_mm = std::max(0.6 * cell_size_mm, voxel);
    options.facet_distance_mm = voxel;
    options.seed = seed;
    SurfaceModel model;
    model.mesh = mesh_labels_tetrahedral(labels, options, what);
    std::fill(model.mesh.cell_labels.begin(), model.mesh.cell_labels.end(), 1);
    model.quality = measure_tetrahedra(model.mesh);
    model.surface = labelled_triangles(model.mesh, notch_x_mm);
    return model;
}

SurfaceModel surface_model_from_surface(const SurfaceMesh& surface, double cell_size_mm, std::optional<double> notch_x_mm, unsigned seed,
                                        const std::string& what)
{
    TetMeshingOptions options;
    options.default_cell_size_mm = cell_size_mm;
    // The surface's own resolution bounds how closely the facets need to follow it.
    double edge = 0.0;
    for (const auto& t : surface.triangles) edge += (surface.vertices[t[1]] - surface.vertices[t[0]]).norm();
    edge /= std::max<std::size_t>(1, surface.triangles.size());
    options.facet_size_mm = std::max(0.6 * cell_size_mm, 0.5 * edge);
    options.facet_distance_mm = std::max(0.5, 0.1 * edge);
    options.seed = seed;
    SurfaceModel model;
    model.mesh = mesh_surface_tetrahedral(surface, options, what);
    model.quality = measure_tetrahedra(model.mesh);
    model.surface = labelled_triangles(model.mesh, notch_x_mm);
    if (!notch_x_mm) std::fill(model.surface.labels.begin(), model.surface.labels.end(), feature_none);
    return model;
}

LabelledTriangles regions_from_seeds(const VolumeMesh& mesh, const LabelledTriangles& boundary, const std::vector<RegionSeed>& seeds, double radius_mm,
                                     double max_snap_mm, const std::string& what)
{
    if (!(radius_mm > 0)) fail("{}: region radius {} mm must be > 0", what, radius_mm);
    // Surface graph: boundary vertices, edges weighted by length.
    std::map<std::int32_t, std::vector<std::pair<std::int32_t, double>>> edges;
    for (const auto& t : boundary.triangles)
        for (int c = 0; c < 3; ++c) {
            const auto a = t[c], b = t[(c + 1) % 3];
            const double l = (mesh.nodes[a] - mesh.nodes[b]).norm();
            edges[a].push_back({b, l});
            edges[b].push_back({a, l});
        }
    LabelledTriangles out = boundary;
    std::fill(out.labels.begin(), out.labels.end(), feature_none);
    // Margin first, then the notch over it.
    for (const std::int32_t label : {std::int32_t(feature_anterior_margin), std::int32_t(feature_umbilical_notch)}) {
        std::map<std::int32_t, double> distance;
        std::vector<std::pair<double, std::int32_t>> heap;
        for (const auto& s : seeds) {
            if (s.label != feature_anterior_margin && s.label != feature_umbilical_notch) fail("{}: seed label {} is neither 1 (UN) nor 2 (AM)", what, s.label);
            if (s.label != label) continue;
            std::int32_t nearest = -1;
            double best = std::numeric_limits<double>::infinity();
            for (const auto& [v, list] : edges) {
                const double d = (mesh.nodes[v] - s.point).norm();
                if (d < best) best = d, nearest = v;
            }
            if (!(best <= max_snap_mm)) fail("{}: a seed lies {:.1f} mm from the model's surface (at most {:.1f} mm)", what, best, max_snap_mm);
            distance[nearest] = 0.0;
            heap.push_back({0.0, nearest});
        }
        std::make_heap(heap.begin(), heap.end(), std::greater<>());
        while (!heap.empty()) {
            std::pop_heap(heap.begin(), heap.end(), std::greater<>());
            const auto [d, v] = heap.back();
            heap.pop_back();
            if (d > distance[v] || d > radius_mm) continue;
            for (const auto& [w, l] : edges[v]) {
                const auto it = distance.find(w);
                if (it == distance.end() || d + l < it->second) {
                    distance[w] = d + l;
                    heap.push_back({d + l, w});
                    std::push_heap(heap.begin(), heap.end(), std::greater<>());
                }
            }
        }
        for (std::size_t t = 0; t < boundary.triangles.size(); ++t) {
            double mean = 0.0;
            bool reached = true;
            for (auto v : boundary.triangles[t]) {
                const auto it = distance.find(v);
                if (it == distance.end()) reached = false;
                else mean += it->second / 3.0;
            }
            if (reached && mean <= radius_mm) out.labels[t] = label;
        }
    }
    return out;
}

LabelledTriangles regions_from_surface(const VolumeMesh& mesh, const LabelledTriangles& boundary, const SurfaceMesh& regions, double max_distance_mm,
                                       const std::string& what)
{
    const bool by_vertex = !regions.vertex_labels.empty();
    if (!by_vertex && regions.labels.empty()) fail("{}: the regions surface has no labels (per-vertex 'label'/'feature' or per-face labels)", what);
    if (regions.triangles.empty()) fail("{}: the regions surface has no triangles", what);
    const TriangleSearch search(regions.vertices, regions.triangles);
    LabelledTriangles out = boundary;
    for (std::size_t t = 0; t < boundary.triangles.size(); ++t) {
        const auto& tri = boundary.triangles[t];
        const Vec3 centroid = (mesh.nodes[tri[0]] + mesh.nodes[tri[1]] + mesh.nodes[tri[2]]) / 3.0;
        const ClosestTriangle hit = search.closest(centroid);
        if (hit.triangle < 0 || hit.distance_mm > max_distance_mm)
            fail("{}: model surface triangle {} lies {:.2f} mm from the regions surface (at most {:.1f} mm allowed): is it in the model's space?", what,
                 t, hit.distance_mm, max_distance_mm);
        const auto& r = regions.triangles[static_cast<std::size_t>(hit.triangle)];
        if (by_vertex) {
            const int corner = static_cast<int>(std::max_element(hit.weights.begin(), hit.weights.end()) - hit.weights.begin());
            out.labels[t] = regions.vertex_labels[static_cast<std::size_t>(r[corner])];
        } else {
            out.labels[t] = regions.labels[static_cast<std::size_t>(hit.triangle)][0];
        }
        if (out.labels[t] < 0) fail("{}: negative region label {}", what, out.labels[t]);
    }
    return out;
}

SurfaceMesh regions_surface(const VolumeMesh& mesh, const LabelledTriangles& boundary, const std::vector<double>* u)
{
    SurfaceMesh s;
    std::vector<std::int32_t> vertex_of(mesh.node_count(), -1);
    for (std::size_t t = 0; t < boundary.triangles.size(); ++t) {
        std::array<std::int32_t, 3> tri{};
        for (int c = 0; c < 3; ++c) {
            const auto n = static_cast<std::size_t>(boundary.triangles[t][c]);
            if (vertex_of[n] < 0) {
                vertex_of[n] = static_cast<std::int32_t>(s.vertices.size());
                s.vertices.push_back(mesh.nodes[n] + (u ? Vec3((*u)[3 * n], (*u)[3 * n + 1], (*u)[3 * n + 2]) : Vec3::Zero()));
            }
            tri[c] = vertex_of[n];
        }
        s.triangles.push_back(tri);
        s.labels.push_back({boundary.labels[t], 0});
    }
    return s;
}

TissueTable homogeneous_liver_tissues(double young_modulus_pa, double poisson_ratio)
{
    TissueTable table;
    table.tissues.push_back(Tissue{1, "parenchyma", young_modulus_pa, poisson_ratio, 1000.0, 0.0});
    table.validate("homogeneous liver model");
    return table;
}

Model to_model(const SurfaceModel& model, const TissueTable& tissues, std::vector<NodeConstraint> supports)
{
    Model out;
    out.mesh = model.mesh;
    out.tissues = tissues;
    out.law = MaterialLaw::corotational;
    out.surface = model.surface;
    out.supports = std::move(supports);
    out.validate("surface model");
    return out;
}

} // namespace physreg
