// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mesh/tetrahedral_meshing.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Labeled_mesh_domain_3.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/Polygon_mesh_processing/orientation.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Polyhedral_mesh_domain_3.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/boost/graph/helpers.h>
#include <CGAL/make_mesh_3.h>
#include <CGAL/refine_mesh_3.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <unordered_map>

namespace physreg {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Domain = CGAL::Labeled_mesh_domain_3<Kernel>;
using Triangulation = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, CGAL::Sequential_tag>::type;
using Complex = CGAL::Mesh_complex_3_in_triangulation_3<Triangulation>;
using Criteria = CGAL::Mesh_criteria_3<Triangulation>;
using Point = Kernel::Point_3;

// The label at a physical point: of the 8 voxel centres around it, the label with the largest sum
// of trilinear weights (CGAL's labellized trilinear interpolation); outside the image: 0.
struct LabelAt {
    const LabelVolume* volume;
    const std::vector<char>* selected; // per label value: meshed
    int operator()(const Point& p) const
    {
        const auto& g = volume->geometry;
        const Vec3 c = g.physical_to_index(Vec3(p.x(), p.y(), p.z()));
        std::int64_t base[3];
        double t[3];
        for (int a = 0; a < 3; ++a) {
            const double f = std::floor(c[a]);
            base[a] = static_cast<std::int64_t>(f);
            t[a] = c[a] - f;
        }
        std::int32_t best_label = 0, labels[8];
        double weights[8];
        int count = 0;
        for (int corner = 0; corner < 8; ++corner) {
            std::int64_t ijk[3];
            double w = 1.0;
            for (int a = 0; a < 3; ++a) {
                const int bit = (corner >> a) & 1;
                ijk[a] = base[a] + bit;
                w *= bit ? t[a] : 1.0 - t[a];
            }
            std::int32_t label = 0;
            if (ijk[0] >= 0 && ijk[1] >= 0 && ijk[2] >= 0 && ijk[0] < g.size[0] && ijk[1] < g.size[1] && ijk[2] < g.size[2]) {
                label = volume->at(ijk[0], ijk[1], ijk[2]);
                if (!(*selected)[static_cast<std::size_t>(label)]) label = 0;
            }
            int k = 0;
            while (k < count && labels[k] != label) ++k;
            if (k == count) labels[count] = label, weights[count++] = 0.0;
            weights[k] += w;
        }
        double best = -1.0;
        for (int k = 0; k < count; ++k)
            if (weights[k] > best || (weights[k] == best && labels[k] < best_label)) best = weights[k], best_label = labels[k];
        return best_label;
    }
};

// Cell size by subdomain (the label of the cell's circumcentre's subdomain).
struct CellSize {
    const TetMeshingOptions* options;
    double operator()(const Point&, int, const Domain::Index& index) const
    {
        if (const auto* sub = boost::get<int>(&index)) {
            const auto it = options->cell_size_mm.find(*sub);
            if (it != options->cell_size_mm.end()) return it->second;
        }
        return options->default_cell_size_mm;
    }
};

double dihedral_deg(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d)
{
    // Angle at edge ab between faces abc and abd.
    const Vec3 e = (b - a).normalized();
    Vec3 u = c - a, v = d - a;
    u -= u.dot(e) * e;
    v -= v.dot(e) * e;
    const double cosine = std::clamp(u.normalized().dot(v.normalized()), -1.0, 1.0);
    return std::acos(cosine) * 180.0 / M_PI;
}

// The cells of a CGAL complex as a VolumeMesh (positive volumes, subdomain index as the label).
template <class ComplexType>
VolumeMesh export_complex(const ComplexType& complex, const std::string& what)
{
    using VertexHandle = typename ComplexType::Triangulation::Vertex_handle;
    VolumeMesh mesh;
    mesh.cell_type = CellType::tetrahedron;
    std::unordered_map<const void*, std::int32_t> id_of;
    const auto node = [&](VertexHandle v) {
        const void* key = &*v;
        const auto it = id_of.find(key);
        if (it != id_of.end()) return it->second;
        const auto& p = v->point().point();
        const auto id = static_cast<std::int32_t>(mesh.nodes.size());
        mesh.nodes.emplace_back(p.x(), p.y(), p.z());
        id_of.emplace(key, id);
        return id;
    };
    for (auto c = complex.cells_in_complex_begin(); c != complex.cells_in_complex_end(); ++c) {
        std::array<std::int32_t, 4> ids{node(c->vertex(0)), node(c->vertex(1)), node(c->vertex(2)), node(c->vertex(3))};
        const Vec3 &a = mesh.nodes[ids[0]], &b = mesh.nodes[ids[1]], &cc = mesh.nodes[ids[2]], &d = mesh.nodes[ids[3]];
        if ((b - a).cross(cc - a).dot(d - a) < 0) std::swap(ids[2], ids[3]); // positive volume
        mesh.cells.insert(mesh.cells.end(), ids.begin(), ids.end());
        mesh.cell_labels.push_back(static_cast<std::int32_t>(complex.subdomain_index(c)));
    }
    if (mesh.cell_count() == 0) fail("{}: CGAL made no tetrahedra (are the features smaller than the sizes?)", what);
    mesh.validate(what);
    return mesh;
}

// One surface point per axis direction from a voxel of every connected component of every label:
// CGAL's default initialisation shoots random rays and can miss a small or distant component (one of
// the two kidneys of the small phantom was lost), which refinement never recovers. This follows
// CGAL's initialize_triangulation_from_labeled_image, for our function-based domain.
void seed_every_component(Complex& complex, const Domain& domain, const LabelVolume& labels, const std::vector<char>& selected)
{
    const auto& g = labels.geometry;
    const std::int64_t n = g.voxel_count();
    std::vector<char> visited(static_cast<std::size_t>(n), 0);
    auto& tr = complex.triangulation();
    const auto cwp = tr.geom_traits().construct_weighted_point_3_object();
    const auto intersect = domain.construct_intersection_object();
    const std::int64_t size[3] = {g.size[0], g.size[1], g.size[2]};
    const auto label_of = [&](std::int64_t i, std::int64_t j, std::int64_t k) -> std::int32_t {
        if (i < 0 || j < 0 || k < 0 || i >= size[0] || j >= size[1] || k >= size[2]) return 0;
        const auto l = labels.at(i, j, k);
        return selected[static_cast<std::size_t>(l)] ? l : 0;
    };
    std::vector<std::int64_t> queue;
    for (std::int64_t k = 0; k < size[2]; ++k)
        for (std::int64_t j = 0; j < size[1]; ++j)
            for (std::int64_t i = 0; i < size[0]; ++i) {
                const std::int32_t l = label_of(i, j, k);
                const auto v0 = g.linear_index(i, j, k);
                if (l == 0 || visited[static_cast<std::size_t>(v0)]) continue;
                // Flood the component (6-connected, same label) so that it is seeded once.
                queue.assign(1, v0);
                visited[static_cast<std::size_t>(v0)] = 1;
                for (std::size_t q = 0; q < queue.size(); ++q) {
                    const std::int64_t v = queue[q];
                    const std::int64_t ci = v % size[0], cj = (v / size[0]) % size[1], ck = v / (size[0] * size[1]);
                    for (int d = 0; d < 6; ++d) {
                        const std::int64_t ni = ci + (d == 0) - (d == 1), nj = cj + (d == 2) - (d == 3), nk = ck + (d == 4) - (d == 5);
                        if (label_of(ni, nj, nk) != l) continue;
                        const auto nv = g.linear_index(ni, nj, nk);
                        if (visited[static_cast<std::size_t>(nv)]) continue;
                        visited[static_cast<std::size_t>(nv)] = 1;
                        queue.push_back(nv);
                    }
                }
                // From the component's middle voxel (in flood order), march each axis to the first voxel of
                // another label; the segment between the two centres crosses the component's surface.
                const std::int64_t seed = queue[queue.size() / 2];
                const std::int64_t si = seed % size[0], sj = (seed / size[0]) % size[1], sk = seed / (size[0] * size[1]);
                const Vec3 from = g.index_to_physical(Vec3(double(si), double(sj), double(sk)));
                for (int d = 0; d < 6; ++d) {
                    std::int64_t step = 1;
                    while (label_of(si + step * ((d == 0) - (d == 1)), sj + step * ((d == 2) - (d == 3)), sk + step * ((d == 4) - (d == 5))) == l) ++step;
                    const Vec3 to = g.index_to_physical(Vec3(double(si + step * ((d == 0) - (d == 1))), double(sj + step * ((d == 2) - (d == 3))),
                                                             double(sk + step * ((d == 4) - (d == 5)))));
                    const auto hit = intersect(Kernel::Segment_3(Point(from.x(), from.y(), from.z()), Point(to.x(), to.y(), to.z())));
                    if (std::get<2>(hit) == 0) continue;
                    const auto wp = cwp(std::get<0>(hit));
                    typename Triangulation::Locate_type lt;
                    int li = 0, lj = 0;
                    const auto cell = tr.locate(wp, lt, li, lj);
                    if (lt != Triangulation::OUTSIDE_AFFINE_HULL) {
                        // Skip a point the triangulation would hide (CGAL's own check).
                        if (tr.dimension() == 1 && tr.side_of_power_segment(cell, wp, true) != CGAL::ON_BOUNDED_SIDE) continue;
                        if (tr.dimension() == 2 && tr.side_of_power_circle(cell, 3, wp, true) != CGAL::ON_BOUNDED_SIDE) continue;
                        if (tr.dimension() == 3 && tr.side_of_power_sphere(cell, wp, true) != CGAL::ON_BOUNDED_SIDE) continue;
                    }
                    const auto vertex = tr.insert(wp);
                    if (vertex == typename Triangulation::Vertex_handle()) continue;
                    complex.set_dimension(vertex, 2);
                    complex.set_index(vertex, std::get<1>(hit));
                }
            }
    if (tr.dimension() != 3) CGAL::Mesh_3::internal::init_c3t3(complex, domain, Criteria(CGAL::parameters::facet_angle = 25), 20);
}
} // namespace

void TetMeshingOptions::validate() const
{
    const auto positive = [](double v, const char* name) {
        if (!(std::isfinite(v) && v > 0)) fail("tetrahedral meshing: {} = {} must be finite and > 0", name, v);
    };
    positive(default_cell_size_mm, "default_cell_size_mm");
    positive(facet_size_mm, "facet_size_mm");
    positive(facet_distance_mm, "facet_distance_mm");
    for (const auto& [label, size] : cell_size_mm) positive(size, fmt::format("cell_size_mm[{}]", label).c_str());
    if (!(facet_angle_deg > 0 && facet_angle_deg <= 30))
        fail("tetrahedral meshing: facet_angle_deg = {} must lie in (0, 30] (CGAL's refinement terminates up to 30°)", facet_angle_deg);
    if (!(radius_edge_ratio >= 2.0))
        fail("tetrahedral meshing: radius_edge_ratio = {} must be ≥ 2 (Delaunay refinement cannot guarantee less)", radius_edge_ratio);
}

namespace {
VolumeMesh mesh_axis_aligned_labels(const LabelVolume& labels, const TetMeshingOptions& options, const std::string& what);
} // namespace

// CGAL meshes the labels in the grid's own axes: a volume whose direction cosines are turned (a
// segmentation resampled onto a turned fixed grid, register-images' initial alignment) is meshed
// with the identity direction and its nodes turned back about the origin. Meshed in the turned frame,
// CGAL 5.5's refinement dereferenced an uninitialised cell and crashed (SIGSEGV; the small preset
// aligned onto a grid turned 10°, seeds 2 and 3 alike); CGAL's own tests mesh axis-aligned images.
VolumeMesh mesh_labels_tetrahedral(const LabelVolume& labels, const TetMeshingOptions& options, const std::string& what)
{
    options.validate();
    labels.geometry.validate(what);
    const Mat3& direction = labels.geometry.direction;
    if ((direction - Mat3::Identity()).cwiseAbs().maxCoeff() < 1e-12) return mesh_axis_aligned_labels(labels, options, what);
    LabelVolume axis_aligned = labels;
    axis_aligned.geometry.direction = Mat3::Identity();
    VolumeMesh mesh = mesh_axis_aligned_labels(axis_aligned, options, what);
    const Vec3 origin = labels.geometry.origin;
    for (auto& x : mesh.nodes) x = origin + direction * (x - origin);
    if (direction.determinant() < 0) // a reflection turns every tetrahedron inside out: reorder its nodes
        for (std::size_t c = 0; c < mesh.cell_count(); ++c) std::swap(mesh.cells[4 * c + 1], mesh.cells[4 * c + 2]);
    mesh.validate(what);
    return mesh;
}

namespace {
VolumeMesh mesh_axis_aligned_labels(const LabelVolume& labels, const TetMeshingOptions& options, const std::string& what)
{
    options.validate();
    labels.geometry.validate(what);
    std::vector<char> selected(65536, 0);
    std::vector<std::int64_t> voxels_of(65536, 0);
    std::int64_t voxels = 0;
    Vec3 lo = Vec3::Constant(1e300), hi = -lo;
    const auto& g = labels.geometry;
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const auto l = labels.at(i, j, k);
                if (l == 0 || (!options.labels.empty() && !options.labels.count(l))) continue;
                selected[l] = 1;
                ++voxels_of[l];
                ++voxels;
                const Vec3 x = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                lo = lo.cwiseMin(x);
                hi = hi.cwiseMax(x);
            }
    if (voxels == 0) fail("{}: no voxel carries a label to mesh", what);
    const Vec3 margin = 2.0 * g.spacing.cwiseAbs().maxCoeff() * Vec3::Ones();
    lo -= margin;
    hi += margin;

    CGAL::Random random(options.seed);
    const std::function<int(const Point&)> label_at = LabelAt{&labels, &selected};
    const double error_bound = 1e-6;
    Domain domain(label_at, CGAL::Bbox_3(lo.x(), lo.y(), lo.z(), hi.x(), hi.y(), hi.z()), error_bound, CGAL::Null_subdomain_index(), &random);
    namespace params = CGAL::parameters;
    Criteria criteria(params::facet_angle = options.facet_angle_deg, params::facet_size = options.facet_size_mm,
                      params::facet_distance = options.facet_distance_mm, params::cell_radius_edge_ratio = options.radius_edge_ratio,
                      params::cell_size = CellSize{&options});
    const auto mesh_once = [&](bool seed_all) {
        CGAL::get_default_random() = CGAL::Random(options.seed);
        Complex complex;
        try {
            if (seed_all) {
                seed_every_component(complex, domain, labels, selected);
                CGAL::refine_mesh_3(complex, domain, criteria, params::no_perturb(), params::no_exude());
            } else {
                complex = CGAL::make_mesh_3<Complex>(domain, criteria, params::no_perturb(), params::no_exude());
            }
            if (options.exude) CGAL::exude_mesh_3(complex, params::sliver_bound = 12.0);
        } catch (const std::exception& e) {
            fail("{}: CGAL Mesh_3 failed: {}", what, e.what());
        }
        return export_complex(complex, what);
    };
    VolumeMesh mesh = mesh_once(options.seed_every_component);
    if (!options.seed_every_component) {
        // CGAL's initial points come from random rays, which can miss a whole organ (the small
        // phantom's organs with seed 9: 505 tetrahedra of one structure were all it found). When
        // less than half of the selected voxels' volume is meshed, the labels are meshed again with
        // every component seeded; other meshes are kept as they are (seeding changes every mesh),
        // and labels meshed below half their volume are said (small lesions and thin vessels).
        std::vector<double> meshed(65536, 0.0);
        double meshed_total = 0.0;
        for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
            const auto cell = mesh.cell(c);
            const Vec3 a = mesh.nodes[cell[1]] - mesh.nodes[cell[0]], b = mesh.nodes[cell[2]] - mesh.nodes[cell[0]],
                       d = mesh.nodes[cell[3]] - mesh.nodes[cell[0]];
            const double volume = std::abs(a.dot(b.cross(d))) / 6.0;
            const auto l = mesh.cell_labels[c];
            if (l >= 0 && l < 65536) meshed[static_cast<std::size_t>(l)] += volume;
            meshed_total += volume;
        }
        const double voxel_mm3 = std::abs(g.spacing.prod());
        std::vector<std::string> short_labels;
        for (std::int32_t l = 1; l < 65536; ++l) {
            const double expected = static_cast<double>(voxels_of[static_cast<std::size_t>(l)]) * voxel_mm3;
            if (selected[static_cast<std::size_t>(l)] && meshed[static_cast<std::size_t>(l)] < 0.5 * expected)
                short_labels.push_back(fmt::format("{} ({:.0f} %)", l, 100.0 * meshed[static_cast<std::size_t>(l)] / expected));
        }
        if (meshed_total < 0.5 * static_cast<double>(voxels) * voxel_mm3) {
            logger()->warn("{}: CGAL's random start found {:.0f} % of the labels' volume: meshed again with every component seeded", what,
                           100.0 * meshed_total / (static_cast<double>(voxels) * voxel_mm3));
            mesh = mesh_once(true);
        } else if (!short_labels.empty()) {
            logger()->info("{}: label(s) meshed below half their voxels' volume: {}", what, fmt::join(short_labels, ", "));
        }
    }
    return mesh;
}
} // namespace

TetrahedronQuality measure_tetrahedra(const VolumeMesh& mesh)
{
    if (mesh.cell_type != CellType::tetrahedron) fail("tetrahedron quality: the mesh has {} cells", to_string(mesh.cell_type));
    TetrahedronQuality q;
    q.cells = mesh.cell_count();
    q.nodes = mesh.node_count();
    q.min_dihedral_deg = 180;
    q.min_radius_ratio = 1e300;
    q.min_edge_mm = 1e300;
    double ratio_sum = 0, edge_sum = 0;
    std::size_t edges = 0;
    static constexpr int pairs[6][4] = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 3, 1, 2}, {1, 2, 0, 3}, {1, 3, 0, 2}, {2, 3, 0, 1}};
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        const auto cell = mesh.cell(c);
        const Vec3 x[4] = {mesh.nodes[cell[0]], mesh.nodes[cell[1]], mesh.nodes[cell[2]], mesh.nodes[cell[3]]};
        double smallest = 180;
        for (const auto& p : pairs) {
            const double angle = dihedral_deg(x[p[0]], x[p[1]], x[p[2]], x[p[3]]);
            smallest = std::min(smallest, angle);
            q.max_dihedral_deg = std::max(q.max_dihedral_deg, angle);
            const double edge = (x[p[0]] - x[p[1]]).norm();
            q.min_edge_mm = std::min(q.min_edge_mm, edge);
            q.max_edge_mm = std::max(q.max_edge_mm, edge);
            edge_sum += edge;
            ++edges;
        }
        q.min_dihedral_deg = std::min(q.min_dihedral_deg, smallest);
        if (smallest < 10) ++q.below_10_deg;
        // r_in = 3V / area; R from the circumcentre formula.
        const Vec3 a = x[1] - x[0], b = x[2] - x[0], d = x[3] - x[0];
        const double volume = std::abs(a.dot(b.cross(d))) / 6.0;
        const double area = 0.5 * ((x[1] - x[0]).cross(x[2] - x[0]).norm() + (x[1] - x[0]).cross(x[3] - x[0]).norm() +
                                   (x[2] - x[0]).cross(x[3] - x[0]).norm() + (x[2] - x[1]).cross(x[3] - x[1]).norm());
        const double r_in = 3.0 * volume / area;
        const Vec3 centre_offset = (a.squaredNorm() * b.cross(d) + b.squaredNorm() * d.cross(a) + d.squaredNorm() * a.cross(b)) /
                                   (2.0 * a.dot(b.cross(d)));
        const double ratio = 3.0 * r_in / centre_offset.norm();
        q.min_radius_ratio = std::min(q.min_radius_ratio, ratio);
        ratio_sum += ratio;
    }
    q.mean_radius_ratio = ratio_sum / static_cast<double>(std::max<std::size_t>(1, q.cells));
    q.mean_edge_mm = edge_sum / static_cast<double>(std::max<std::size_t>(1, edges));
    return q;
}

VolumeMesh mesh_surface_tetrahedral(const SurfaceMesh& surface, const TetMeshingOptions& options, const std::string& what)
{
    using SurfacePolyhedron = CGAL::Surface_mesh<Point>;
    using PolyDomain = CGAL::Polyhedral_mesh_domain_3<SurfacePolyhedron, Kernel>;
    using PolyTriangulation = CGAL::Mesh_triangulation_3<PolyDomain, CGAL::Default, CGAL::Sequential_tag>::type;
    using PolyComplex = CGAL::Mesh_complex_3_in_triangulation_3<PolyTriangulation>;
    using PolyCriteria = CGAL::Mesh_criteria_3<PolyTriangulation>;
    namespace pmp = CGAL::Polygon_mesh_processing;
    options.validate();
    surface.validate(what);
    if (surface.triangles.empty()) fail("{}: the surface has no triangles", what);
    SurfacePolyhedron sm;
    std::vector<SurfacePolyhedron::Vertex_index> vertex;
    for (const auto& v : surface.vertices) vertex.push_back(sm.add_vertex(Point(v.x(), v.y(), v.z())));
    for (std::size_t t = 0; t < surface.triangles.size(); ++t) {
        const auto& tri = surface.triangles[t];
        if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) fail("{}: triangle {} repeats a vertex", what, t);
        if (sm.add_face(vertex[tri[0]], vertex[tri[1]], vertex[tri[2]]) == SurfacePolyhedron::null_face())
            fail("{}: triangle {} makes the surface non-manifold (an edge shared by more than two triangles, or inconsistent orientation)", what, t);
    }
    if (!CGAL::is_closed(sm)) fail("{}: the surface is not closed (it has border edges): a volume needs a watertight surface", what);
    if (pmp::does_self_intersect(sm)) fail("{}: the surface intersects itself", what);
    if (!pmp::is_outward_oriented(sm)) pmp::reverse_face_orientations(sm);
    CGAL::Random random(options.seed);
    CGAL::get_default_random() = CGAL::Random(options.seed);
    PolyDomain domain(sm, &random);
    namespace params = CGAL::parameters;
    PolyCriteria criteria(params::facet_angle = options.facet_angle_deg, params::facet_size = options.facet_size_mm,
                          params::facet_distance = options.facet_distance_mm, params::cell_radius_edge_ratio = options.radius_edge_ratio,
                          params::cell_size = options.default_cell_size_mm);
    PolyComplex complex;
    try {
        complex = CGAL::make_mesh_3<PolyComplex>(domain, criteria, params::no_perturb(), params::no_exude());
        if (options.exude) CGAL::exude_mesh_3(complex, params::sliver_bound = 12.0);
    } catch (const std::exception& e) {
        fail("{}: CGAL Mesh_3 failed: {}", what, e.what());
    }
    VolumeMesh mesh = export_complex(complex, what);
    std::fill(mesh.cell_labels.begin(), mesh.cell_labels.end(), 1);
    return mesh;
}

} // namespace physreg
