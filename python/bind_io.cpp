// SPDX-License-Identifier: GPL-3.0-or-later
// The Python module's files and geometry: images, label maps and displacement fields, volume meshes
// (and meshing label arrays), surfaces, landmarks, TRE and the Hausdorff distance.
#include "bindings.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/landmark.hpp"
#include "physreg/evaluation/surface_distance.hpp"
#include "physreg/evaluation/tre.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/surface_extraction.hpp"
#include "physreg/mesh/tetrahedral_meshing.hpp"
#include "physreg/model/tissue_table.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/registration/observation.hpp"
#include "physreg/registration/surface/surface_model.hpp"
#include "physreg/registration/surface/surface_registration.hpp"

#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>
#include <map>
#include <set>
#include <tuple>

namespace physreg::python {
namespace {

py::array_t<std::int32_t> cells_view(VolumeMesh& mesh, py::handle owner)
{
    const py::ssize_t k = mesh.cell_size();
    return py::array_t<std::int32_t>({static_cast<py::ssize_t>(mesh.cell_count()), k}, mesh.cells.data(), owner);
}

LandmarkSet landmarks_from(const std::vector<std::string>& names, const py::array& positions, const char* argument)
{
    const std::vector<Vec3> p = points_from(positions, argument);
    if (p.size() != names.size())
        throw py::value_error(fmt::format("{}: {} positions for {} names", argument, p.size(), names.size()));
    LandmarkSet set(p.size());
    for (std::size_t n = 0; n < p.size(); ++n) set[n] = {names[n], p[n], LandmarkType::unspecified};
    return set;
}

py::dict stats_dict(const TreStats& s)
{
    py::dict d;
    d["count"] = s.count;
    d["mean_mm"] = s.mean_mm;
    d["std_mm"] = s.std_mm;
    d["max_mm"] = s.max_mm;
    return d;
}

} // namespace

/// mesh_from_labels' work: hexahedra from the voxels or a grid, or CGAL tetrahedra.
VolumeMesh mesh_labels(const py::array& labels, const ImageGeometry& geometry, const std::string& kind, std::optional<std::array<int, 3>> grid,
                       double cell_size_mm, double facet_distance_mm, std::optional<std::vector<std::int32_t>> only, unsigned seed,
                       const std::vector<std::int32_t>& ignore, const std::optional<std::map<std::int32_t, std::pair<double, double>>>& tissues)
{
    LabelVolume v = label_volume_from(labels, geometry);
    if (!ignore.empty())
        for (auto& l : v.labels)
            if (std::count(ignore.begin(), ignore.end(), static_cast<std::int32_t>(l))) l = 0; // ignored labels are background
    if (kind == "hex") {
        MeshingOptions o;
        if (grid) o.grid_dims = Index3{(*grid)[0], (*grid)[1], (*grid)[2]};
        // The hexahedral mesher reads each label's tissue: the default table's, else the tissues
        // given, else paper 001's healthy liver (Model.from_labels sets the moduli afterwards).
        // Only the labels present, so that the mesher warns of no absent tissue.
        const TissueTable defaults = default_tissue_table();
        TissueTable table;
        for (const auto label : std::set<std::uint16_t>(v.labels.begin(), v.labels.end())) {
            if (label == 0) continue;
            if (const Tissue* t = defaults.find(label); t && !(tissues && tissues->count(label))) {
                table.tissues.push_back(*t);
                continue;
            }
            const auto given = tissues && tissues->count(label) ? tissues->at(label) : std::pair<double, double>{3500.0, 0.45};
            table.tissues.push_back({label, fmt::format("label {}", label), given.first, given.second, 1000.0, 0.0});
        }
        if (table.tissues.empty()) table = defaults; // no label at all: the mesher says so
        py::gil_scoped_release release;
        return mesh_label_volume(v, table, o, "labels").mesh;
    }
    if (kind == "tet") {
        if (!(cell_size_mm > 0) || !std::isfinite(cell_size_mm)) throw py::value_error(fmt::format("cell_size_mm: {} must be a positive number", cell_size_mm));
        if (!(facet_distance_mm > 0) || !std::isfinite(facet_distance_mm)) throw py::value_error(fmt::format("facet_distance_mm: {} must be a positive number", facet_distance_mm));
        TetMeshingOptions o;
        o.default_cell_size_mm = cell_size_mm;
        o.facet_size_mm = cell_size_mm;
        o.facet_distance_mm = facet_distance_mm;
        o.seed = seed;
        o.seed_every_component = true;
        if (only) o.labels.insert(only->begin(), only->end());
        py::gil_scoped_release release;
        return mesh_labels_tetrahedral(v, o, "labels");
    }
    throw py::value_error(fmt::format("kind: '{}' is not one of 'hex', 'tet'", kind));
}

/// Images and displacement fields: numpy arrays [z, y, x] with their geometry.
void bind_images(py::module_& m)
{
    m.def("read_labels", [](const std::filesystem::path& path) {
        LabelVolume v = read_label_volume(path);
        const ImageGeometry g = v.geometry;
        return py::make_tuple(image_array(std::move(v), &LabelVolume::labels, 1), g);
    }, py::arg("path"),
          "Reads a label volume (NIfTI, NRRD, MetaImage, DICOM directory) → (uint16 array [z, y, x], ImageGeometry). "
          "Raises FileNotFoundError for a missing file and physreg.Error for a corrupt one or non-integral labels.");
    m.def("read_image", [](const std::filesystem::path& path) {
        ScalarImage v = read_scalar_image(path);
        const ImageGeometry g = v.geometry;
        return py::make_tuple(image_array(std::move(v), &ScalarImage::values, 1), g);
    }, py::arg("path"), "Reads a scalar image → (float32 array [z, y, x], ImageGeometry).");
    m.def("read_displacement_field", [](const std::filesystem::path& path) {
        DisplacementField f = read_displacement_field(path);
        const ImageGeometry g = f.geometry;
        return py::make_tuple(image_array(std::move(f), &DisplacementField::components, 3), g);
    }, py::arg("path"), "Reads an ITK displacement field → (float32 array [z, y, x, 3] of (ux, uy, uz) in mm, LPS; ImageGeometry).");
    m.def("write_labels", [](const std::filesystem::path& path, const py::array& labels, const ImageGeometry& geometry) {
        const LabelVolume v = label_volume_from(labels, geometry);
        write_label_volume(path, v);
    }, py::arg("path"), py::arg("labels"), py::arg("geometry"), "Writes a uint16 label array [z, y, x] (atomically: temporary file, then rename).");
    m.def("write_image", [](const std::filesystem::path& path, const py::array& image, const ImageGeometry& geometry) {
        volume_shape_check(image, "image");
        require_dtype(image, py::dtype::of<float>(), "image");
        ScalarImage v;
        v.geometry = geometry_for(image, geometry, "geometry");
        const auto* data = static_cast<const float*>(image.data());
        v.values.assign(data, data + image.size());
        write_scalar_image(path, v);
    }, py::arg("path"), py::arg("image"), py::arg("geometry"), "Writes a float32 image [z, y, x] (atomically).");
    m.def("write_displacement_field", [](const std::filesystem::path& path, const py::array& field, const ImageGeometry& geometry) {
        if (field.ndim() != 4 || field.shape(3) != 3) throw py::value_error("field: expected shape (nz, ny, nx, 3)");
        require_c_contiguous(field, "field");
        require_dtype(field, py::dtype::of<float>(), "field");
        DisplacementField f;
        f.geometry = geometry;
        f.geometry.size = Index3{field.shape(2), field.shape(1), field.shape(0)};
        f.geometry.validate("geometry");
        const auto* data = static_cast<const float*>(field.data());
        f.components.assign(data, data + field.size());
        write_displacement_field(path, f);
    }, py::arg("path"), py::arg("field"), py::arg("geometry"),
          "Writes a displacement field (float32 [z, y, x, 3], mm, LPS) that ITK, ANTs and 3D Slicer read as a transform.");

}

/// Meshes, surfaces, landmarks and the distances between them.
void bind_geometry(py::module_& m)
{
    py::class_<VolumeMesh>(m, "Mesh", "A volume mesh: nodes (N, 3) mm LPS, cells (M, 4 or 8) node ids, one tissue label per cell.")
        .def_property_readonly("nodes", [](py::object self) { return points_view(self.cast<VolumeMesh&>().nodes, self); },
                               "(N, 3) float64 node positions, mm (a view: writes change the mesh)")
        .def_property_readonly("cells", [](py::object self) { return cells_view(self.cast<VolumeMesh&>(), self); }, "(M, k) int32 node ids (view)")
        .def_property_readonly("cell_labels", [](py::object self) {
            auto& mesh = self.cast<VolumeMesh&>();
            return py::array_t<std::int32_t>({static_cast<py::ssize_t>(mesh.cell_labels.size())}, mesh.cell_labels.data(), self);
        }, "(M,) int32 tissue label per cell (view)")
        .def_property_readonly("cell_type", [](const VolumeMesh& mesh) { return to_string(mesh.cell_type); })
        .def_property_readonly("node_count", &VolumeMesh::node_count)
        .def_property_readonly("cell_count", &VolumeMesh::cell_count)
        .def("volume_per_label", [](const VolumeMesh& mesh) {
            std::map<std::int32_t, double> out;
            for (const auto& [label, volume] : volume_per_label(mesh)) out[label] = volume;
            return out;
        }, "{label: volume in mm³}")
        .def("__repr__", [](const VolumeMesh& mesh) {
            return fmt::format("Mesh({} nodes, {} {} cells)", mesh.node_count(), mesh.cell_count(), to_string(mesh.cell_type));
        });

    m.def("read_mesh", [](const std::filesystem::path& path) { return read_volume_mesh(path); }, py::arg("path"),
          "Reads a volume mesh (VTK XML .vtu or Gmsh .msh).");
    m.def("write_mesh", [](const std::filesystem::path& path, const VolumeMesh& mesh) { write_volume_mesh(path, mesh); }, py::arg("path"), py::arg("mesh"),
          "Writes a volume mesh (.vtu; .msh for Gmsh 4.1, .v2.msh for 2.2; atomically).");
    m.def("mesh_from_labels", [](const py::array& labels, const ImageGeometry& geometry, const std::string& kind, std::optional<std::array<int, 3>> grid,
                                 double cell_size_mm, double facet_distance_mm, std::optional<std::vector<std::int32_t>> only, unsigned seed) {
        return mesh_labels(labels, geometry, kind, grid, cell_size_mm, facet_distance_mm, only, seed);
    }, py::arg("labels"), py::arg("geometry"), py::arg("kind") = "hex", py::arg("grid") = py::none(), py::arg("cell_size_mm") = 6.0,
          py::arg("facet_distance_mm") = 0.75, py::arg("labels_meshed") = py::none(), py::arg("seed") = 1u,
          "Meshes a label volume. kind='hex': uniform hexahedra straight from the voxels (paper 000), optionally "
          "coarsened to `grid` cells (i, j, k) over the labels' bounding box; kind='tet': conforming tetrahedra (CGAL Mesh_3), "
          "largest circumradius cell_size_mm (mm), facets within facet_distance_mm (mm) of the label interfaces.");

    py::class_<SurfaceMesh>(m, "Surface", "A triangle surface: vertices (N, 3) mm LPS, triangles (M, 3) vertex ids.")
        .def(py::init([](const py::array& vertices, const py::array& triangles) {
                 SurfaceMesh s;
                 s.vertices = points_from(vertices, "vertices");
                 require_dtype(triangles, py::dtype::of<std::int32_t>(), "triangles");
                 if (triangles.ndim() != 2 || triangles.shape(1) != 3) throw py::value_error("triangles: expected shape (M, 3)");
                 const auto t = triangles.cast<CArray<std::int32_t>>().unchecked<2>();
                 for (py::ssize_t r = 0; r < triangles.shape(0); ++r) {
                     std::array<std::int32_t, 3> tri{t(r, 0), t(r, 1), t(r, 2)};
                     for (auto v : tri)
                         if (v < 0 || static_cast<std::size_t>(v) >= s.vertices.size())
                             throw py::value_error(fmt::format("triangles: row {} names vertex {} (there are {})", r, v, s.vertices.size()));
                     s.triangles.push_back(tri);
                 }
                 return s;
             }),
             py::arg("vertices"), py::arg("triangles"))
        .def_property_readonly("vertices", [](py::object self) { return points_view(self.cast<SurfaceMesh&>().vertices, self); })
        .def_property_readonly("triangles", [](py::object self) {
            auto& s = self.cast<SurfaceMesh&>();
            return py::array_t<std::int32_t>({static_cast<py::ssize_t>(s.triangles.size()), py::ssize_t{3}}, s.triangles.empty() ? nullptr : s.triangles.front().data(), self);
        })
        .def("__repr__", [](const SurfaceMesh& s) { return fmt::format("Surface({} vertices, {} triangles)", s.vertices.size(), s.triangles.size()); });
    m.def("read_surface", [](const std::filesystem::path& path) { return read_surface(path); }, py::arg("path"), "Reads an STL/PLY/OBJ/VTK surface (mm).");
    m.def("write_surface", [](const std::filesystem::path& path, const SurfaceMesh& s) { write_surface(path, s); }, py::arg("path"), py::arg("surface"),
          "Writes a surface by extension: .stl (binary), .ply (binary, per-face inside/outside labels) or .obj (groups per label pair); "
          "positions mm, LPS; written to a temporary name and renamed when complete; physreg.Error names the file.");
    m.def("boundary_surface", [](const VolumeMesh& mesh) { return extract_boundary(mesh); }, py::arg("mesh"),
          "The outer boundary of a volume mesh as a triangle surface.");

    m.def("read_landmarks", [](const std::filesystem::path& path) {
        const LandmarkSet set = read_landmarks(path);
        py::array_t<double> positions({static_cast<py::ssize_t>(set.size()), py::ssize_t{3}});
        std::vector<std::string> names, types;
        for (std::size_t n = 0; n < set.size(); ++n) {
            names.push_back(set[n].name);
            types.push_back(to_string(set[n].type));
            for (int a = 0; a < 3; ++a) positions.mutable_at(static_cast<py::ssize_t>(n), a) = set[n].position[a];
        }
        return py::make_tuple(names, positions, types);
    }, py::arg("path"), "Reads landmarks (CSV, Slicer .fcsv or .mrk.json) → (names, (N, 3) positions mm LPS, types).");
    m.def("write_landmarks", [](const std::filesystem::path& path, const std::vector<std::string>& names, const py::array& positions) {
        write_landmarks(path, landmarks_from(names, positions, "positions"));
    }, py::arg("path"), py::arg("names"), py::arg("positions"), "Writes landmarks (.csv, .fcsv or .mrk.json for 3D Slicer's Markups; atomically).");

    m.def("tre", [](const py::array& predicted, const py::array& truth) {
        const std::vector<Vec3> p = points_from(predicted, "predicted"), t = points_from(truth, "truth");
        if (p.size() != t.size()) throw py::value_error(fmt::format("predicted: {} points but truth has {}", p.size(), t.size()));
        if (p.empty()) throw py::value_error("truth: no landmark");
        py::array_t<double> errors(static_cast<py::ssize_t>(p.size()));
        std::vector<double> e(p.size());
        for (std::size_t n = 0; n < p.size(); ++n) errors.mutable_at(static_cast<py::ssize_t>(n)) = e[n] = (p[n] - t[n]).norm();
        py::dict d = stats_dict(tre_stats(e));
        d["errors_mm"] = errors;
        return d;
    }, py::arg("predicted"), py::arg("truth"),
          "Target registration error between matched rows of two (N, 3) arrays (mm): {'errors_mm', 'count', 'mean_mm', 'std_mm', 'max_mm'}.");
    m.def("hausdorff", [](const SurfaceMesh& first, const SurfaceMesh& second) {
        HausdorffReport r;
        {
            py::gil_scoped_release release;
            r = hausdorff_distance(first, second, "hausdorff");
        }
        py::dict d;
        d["max_mm"] = r.max_mm();
        d["mean_mm"] = r.mean_mm();
        d["forward_max_mm"] = r.forward.max_mm;
        d["backward_max_mm"] = r.backward.max_mm;
        d["forward_mean_mm"] = r.forward.mean_mm;
        d["backward_mean_mm"] = r.backward.mean_mm;
        return d;
    }, py::arg("first"), py::arg("second"),
          "Sampled symmetric Hausdorff distance between two surfaces (vertices and triangle centroids to the exact closest point), mm.");
}

void bind_io(py::module_& m)
{
    bind_images(m);
    bind_geometry(m);
}

} // namespace physreg::python
