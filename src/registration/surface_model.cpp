#include "physreg/registration/surface_model.hpp"

#include "physreg/core/error.hpp"
#include "physreg/phantom/partial_surface.hpp"

#include <algorithm>

namespace physreg {

namespace {
LabelledTriangles labelled_boundary(const VolumeMesh& mesh, std::optional<double> notch_x_mm)
{
    const BoundarySurface b = liver_boundary(mesh, [](std::int32_t) { return true; }, notch_x_mm);
    LabelledTriangles out;
    out.triangles = b.triangles;
    out.labels.reserve(b.triangles.size());
    const auto feature = [&](std::int32_t node) {
        const auto q = std::lower_bound(b.nodes.begin(), b.nodes.end(), node) - b.nodes.begin();
        return b.node_feature[static_cast<std::size_t>(q)];
    };
    // A triangle takes a feature carried by at least two of its corners (the notch first).
    for (const auto& t : b.triangles) {
        int notch = 0, margin = 0;
        for (auto n : t) {
            const auto f = feature(n);
            notch += f == feature_umbilical_notch;
            margin += f == feature_anterior_margin || f == feature_umbilical_notch;
        }
        out.labels.push_back(notch >= 2 ? feature_umbilical_notch : margin >= 2 ? feature_anterior_margin : feature_none);
    }
    return out;
}
} // namespace

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
    model.surface = labelled_boundary(model.mesh, notch_x_mm);
    return model;
}

LabelledTriangles unlabelled_boundary(const VolumeMesh& mesh)
{
    LabelledTriangles out = labelled_boundary(mesh, std::nullopt);
    std::fill(out.labels.begin(), out.labels.end(), feature_none);
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

} // namespace physreg
