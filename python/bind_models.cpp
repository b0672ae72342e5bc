// SPDX-License-Identifier: GPL-3.0-or-later
// The Python module's models: paper 001's surface model and its registration to a cloud in numpy
// arrays, and the one Model of the three modes with its observations (Tool, Cloud, Segmentation)
// and physreg.register.
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

/// Tissues from {label: (young_modulus_pa, poisson_ratio)}; labels absent take paper 001's healthy liver (3.5 kPa, 0.45).
TissueTable tissues_from(const VolumeMesh& mesh, const std::optional<std::map<std::int32_t, std::pair<double, double>>>& given)
{
    TissueTable table;
    const std::set<std::int32_t> labels(mesh.cell_labels.begin(), mesh.cell_labels.end());
    for (const auto label : labels) {
        Tissue t;
        t.label = label;
        t.name = fmt::format("label {}", label);
        t.young_modulus_pa = 3500.0;
        t.poisson_ratio = 0.45;
        if (given && given->count(label)) std::tie(t.young_modulus_pa, t.poisson_ratio) = given->at(label);
        table.tissues.push_back(t);
    }
    if (given)
        for (const auto& [label, value] : *given)
            if (!labels.count(label)) throw py::value_error(fmt::format("tissues: label {} has no cell in the mesh", label));
    table.validate("tissues");
    return table;
}

/// A labelled surface's triangles as an (M, 3) int32 array of node ids (a copy).
py::array_t<std::int32_t> triangles_array(const LabelledTriangles& surface)
{
    py::array_t<std::int32_t> t({static_cast<py::ssize_t>(surface.triangles.size()), py::ssize_t{3}});
    for (std::size_t r = 0; r < surface.triangles.size(); ++r)
        for (int c = 0; c < 3; ++c) t.mutable_at(static_cast<py::ssize_t>(r), c) = surface.triangles[r][static_cast<std::size_t>(c)];
    return t;
}

struct SurfaceRegistration {
    VolumeMesh mesh;
    SurfaceRegistrationResult result;
};

// The dense field and the mapped points of any registration result (mesh at rest + nodal displacement).
py::tuple dense_field(const VolumeMesh& mesh, const std::vector<double>& u, std::optional<ImageGeometry> geometry, double spacing_mm)
{
    if (!(spacing_mm > 0) || !std::isfinite(spacing_mm)) throw py::value_error(fmt::format("spacing_mm: {} must be a positive number", spacing_mm));
    const ImageGeometry g = geometry ? *geometry : image_grid_over_mesh(mesh, spacing_mm, 2 * spacing_mm);
    DisplacementField f;
    {
        py::gil_scoped_release release;
        f = sample_displacement_field(mesh, u, g).field;
    }
    const ImageGeometry fg = f.geometry;
    return py::make_tuple(image_array(std::move(f), &DisplacementField::components, 3), fg);
}

py::array_t<double> mapped_points(const VolumeMesh& mesh, const std::vector<double>& u, const py::array& points, double max_distance_mm)
{
    const std::vector<Vec3> p = points_from(points, "points");
    LandmarkSet set(p.size());
    for (std::size_t n = 0; n < p.size(); ++n) set[n] = {std::to_string(n + 1), p[n], LandmarkType::unspecified};
    const auto where = embed_landmarks(mesh, set, max_distance_mm, "points");
    const LandmarkSet moved = displace_landmarks(mesh, where, set, u);
    py::array_t<double> out({static_cast<py::ssize_t>(moved.size()), py::ssize_t{3}});
    for (std::size_t n = 0; n < moved.size(); ++n)
        for (int a = 0; a < 3; ++a) out.mutable_at(static_cast<py::ssize_t>(n), a) = moved[n].position[a];
    return out;
}

/// Paper 001 in memory: SurfaceModel, register_surface_cloud and its result.
void bind_surface_model(py::module_& m)
{
    // ---- in memory (issue 29): paper 001's registration of a model to a cloud held in numpy arrays ----
    py::class_<SurfaceModel>(m, "SurfaceModel",
                             "Paper 001's liver model: tetrahedra (every cell label 1) and its outer surface, whose triangles carry "
                             "feature labels (0 surface, 1 umbilical notch, 2 anterior margin) that a cloud's labels are matched to.")
        .def_static("from_labels", [](const py::array& labels, const ImageGeometry& geometry, std::optional<std::vector<std::int32_t>> liver_labels,
                                      double cell_size_mm, std::optional<double> notch_x_mm, unsigned seed) {
            if (!(cell_size_mm > 0) || !std::isfinite(cell_size_mm)) throw py::value_error(fmt::format("cell_size_mm: {} must be a positive number", cell_size_mm));
            const LabelVolume v = label_volume_from(labels, geometry);
            std::set<std::int32_t> liver;
            if (liver_labels)
                liver.insert(liver_labels->begin(), liver_labels->end());
            else
                for (auto l : v.labels)
                    if (l != 0) liver.insert(l);
            py::gil_scoped_release release;
            return surface_model_from_labels(v, liver, cell_size_mm, notch_x_mm, seed, "labels");
        }, py::arg("labels"), py::arg("geometry"), py::arg("liver_labels") = py::none(), py::arg("cell_size_mm") = 7.0, py::arg("notch_x_mm") = py::none(),
           py::arg("seed") = 1u,
           "Meshes the union of liver_labels (default: every non-zero label) of a uint16 label array [z, y, x] as register-surface --labels "
           "does (largest circumradius cell_size_mm); regions by the anatomical rule, the umbilical notch at x = notch_x_mm when given.")
        .def_static("from_mesh", [](const VolumeMesh& mesh) {
            if (mesh.cell_type != CellType::tetrahedron) throw py::value_error("mesh: paper 001's model must hold tetrahedra");
            SurfaceModel model;
            model.mesh = mesh;
            std::fill(model.mesh.cell_labels.begin(), model.mesh.cell_labels.end(), 1);
            model.surface = unlabelled_boundary(model.mesh);
            model.quality = measure_tetrahedra(model.mesh);
            return model;
        }, py::arg("mesh"), "A tetrahedral mesh as register-surface --model takes it: one material, its whole boundary 'surface' (label 0).")
        .def_property_readonly("mesh", [](const SurfaceModel& model) { return model.mesh; }, "The tetrahedra (a copy).")
        .def_property_readonly("surface_triangles", [](const SurfaceModel& model) {
            return triangles_array(model.surface);
        }, "(M, 3) int32 mesh node ids of the outer surface's triangles.")
        .def_property_readonly("surface_labels", [](const SurfaceModel& model) {
            return py::array_t<std::int32_t>(static_cast<py::ssize_t>(model.surface.labels.size()), model.surface.labels.data());
        }, "(M,) int32 feature label per surface triangle.")
        .def("to_model", [](const SurfaceModel& model, double young_modulus_pa, double poisson_ratio) {
            return to_model(model, homogeneous_liver_tissues(young_modulus_pa, poisson_ratio));
        }, py::arg("young_modulus_pa") = 3500.0, py::arg("poisson_ratio") = 0.45,
           "The shared physreg.Model of this liver (its regions kept, the co-rotational law, no support), for physreg.register.")
        .def("__repr__", [](const SurfaceModel& model) {
            return fmt::format("SurfaceModel({} nodes, {} tetrahedra, {} surface triangles)", model.mesh.node_count(), model.mesh.cell_count(), model.surface.triangles.size());
        });

    py::class_<SurfaceRegistration>(m, "SurfaceRegistration", "The result of register_surface_cloud: the model's nodal displacement and its dense field.")
        .def_property_readonly("displacement", [](py::object self) {
            auto& r = self.cast<SurfaceRegistration&>().result;
            return py::array_t<double>({static_cast<py::ssize_t>(r.displacement_mm.size() / 3), py::ssize_t{3}}, r.displacement_mm.data(), self);
        }, "(N, 3) float64 nodal displacement, mm (a view)")
        .def_property_readonly("mesh", [](const SurfaceRegistration& r) { return r.mesh; }, "The model's tetrahedra at rest (a copy).")
        .def_property_readonly("steps", [](const SurfaceRegistration& r) { return r.result.steps; })
        .def_property_readonly("factorisations", [](const SurfaceRegistration& r) { return r.result.factorisations; })
        .def_property_readonly("seconds", [](const SurfaceRegistration& r) { return r.result.seconds; })
        .def_property_readonly("plateaus", [](const SurfaceRegistration& r) {
            py::list out;
            for (const auto& p : r.result.plateaus) {
                py::dict d;
                d["plateau"] = p.plateau;
                d["steps"] = p.steps;
                d["settled"] = p.reached;
                d["pairs"] = p.matching.kept;
                d["mean_pair_distance_mm"] = p.matching.mean_distance_mm;
                d["stiffness_n"] = p.stiffness_n;
                out.append(d);
            }
            return out;
        }, "Per annealing plateau: steps, whether it settled, pairs kept, their mean distance (mm), stiffness per label (N).")
        .def("field", [](const SurfaceRegistration& r, std::optional<ImageGeometry> geometry, double spacing_mm) {
            return dense_field(r.mesh, r.result.displacement_mm, geometry, spacing_mm);
        }, py::arg("geometry") = py::none(), py::arg("spacing_mm") = 2.0,
           "The dense field (float32 [z, y, x, 3], mm, LPS; 0 outside the model) on `geometry`, or on a grid of spacing_mm over the model "
           "with a 2-voxel margin (as register-surface writes displacement.nii.gz) → (array, ImageGeometry).")
        .def("map_points", [](const SurfaceRegistration& r, const py::array& points, double max_distance_mm) {
            return mapped_points(r.mesh, r.result.displacement_mm, points, max_distance_mm);
        }, py::arg("points"), py::arg("max_distance_mm") = 10.5,
           "Rest positions (N, 3) mm (targets, landmarks) carried by the model's displacement; a point farther than max_distance_mm "
           "from the model is an error.");

    m.def("register_surface_cloud", [](const SurfaceModel& model, const py::array& points, std::optional<py::array> labels, std::optional<py::array> normals,
                                       double young_modulus_pa, double poisson_ratio, double traction_ratio, const std::string& support,
                                       std::optional<std::vector<std::int32_t>> support_nodes, std::optional<py::function> progress) {
        const LabelledPointCloud cloud = cloud_from(points, labels, normals);
        SurfaceCloudProblem problem;
        problem.young_modulus_pa = young_modulus_pa;
        problem.poisson_ratio = poisson_ratio;
        problem.traction_ratio = traction_ratio;
        if (support != "posterior" && support != "none") throw py::value_error(fmt::format("support: '{}' is not one of 'posterior', 'none'", support));
        problem.posterior_support = support == "posterior";
        if (support_nodes) problem.support_nodes = *support_nodes;
        const auto report = progress_from(progress);
        SurfaceRegistration out{model.mesh, {}};
        {
            py::gil_scoped_release release;
            out.result = register_surface_cloud(model.mesh, model.surface, cloud, problem, report);
        }
        return out;
    }, py::arg("model"), py::arg("points"), py::arg("labels") = py::none(), py::arg("normals") = py::none(), py::arg("young_modulus_pa") = 3500.0,
          py::arg("poisson_ratio") = 0.45, py::arg("traction_ratio") = 0.5, py::arg("support") = "posterior", py::arg("support_nodes") = py::none(),
          py::arg("progress") = py::none(),
          "Paper 001's biomechanical registration of `model` to a cloud held in memory — points (N, 3) mm LPS, optional int32 feature "
          "labels (N,) (default: all 0, surface) and outward normals (N, 3) — by the biomechanical method alone (co-rotational tetrahedra, "
          "backward Euler, arctan pair forces annealed over paper 001's schedules) with the supports given here: support 'posterior' "
          "(default: the posterior surface held) or 'none', plus support_nodes. No support hypotheses, rigid baselines, cloud-halves "
          "check or safeguard: register_partial_surface runs register-surface's whole pipeline (its default support is 'auto'). "
          "progress(fraction, message) after every plateau. Returns a SurfaceRegistration.");

}

/// The one model of the three modes and its observations: Model, Tool, Cloud, Segmentation.
void bind_model_and_observations(py::module_& m)
{
    // ---- one model for the three modes (issue 29): Model, observations, register --------------------
    py::class_<Model>(m, "Model",
                      "One model for the three registration modes: a mesh (tetrahedra or hexahedra), a tissue per cell label (Young's "
                      "modulus Pa, Poisson ratio), the law, supports, and the surface a cloud is matched to. A tool (physreg.Tool) drives "
                      "it with paper 000's TLED solver (grid hexahedra only), a cloud (physreg.Cloud) with paper 001's co-rotational "
                      "backward Euler, a segmentation (physreg.Segmentation) with paper 002's linear elasticity and adjoint L-BFGS.")
        .def_static("from_mesh", [](const VolumeMesh& mesh, std::optional<std::map<std::int32_t, std::pair<double, double>>> tissues, const std::string& law,
                                    std::optional<std::vector<std::int32_t>> surface_labels) {
            Model model;
            model.mesh = mesh;
            model.tissues = tissues_from(mesh, tissues);
            model.law = parse_material_law(law);
            const std::set<std::int32_t> keep = surface_labels ? std::set<std::int32_t>(surface_labels->begin(), surface_labels->end()) : std::set<std::int32_t>{};
            model.surface = cell_group_boundary(mesh, [&](std::int32_t l) { return keep.empty() || keep.count(l) > 0; }, "surface_labels");
            model.validate("mesh");
            return model;
        }, py::arg("mesh"), py::arg("tissues") = py::none(), py::arg("law") = "neo-hookean", py::arg("surface_labels") = py::none(),
           "A model of `mesh` (physreg.mesh_from_labels, read_mesh): tissues {label: (young_modulus_pa, poisson_ratio)} (labels left out: "
           "3.5 kPa, 0.45), the law (neo-hookean, corotational, svk, linear, mooney-rivlin), and its surface: the boundary of the cells "
           "of surface_labels (default: the whole outer boundary), every region 0.")
        .def_static("from_labels", [](const py::array& labels, const ImageGeometry& geometry, const std::string& kind, std::optional<std::array<int, 3>> grid,
                                      double cell_size_mm, std::optional<std::map<std::int32_t, std::pair<double, double>>> tissues, const std::string& law,
                                      std::optional<std::vector<std::int32_t>> surface_labels, unsigned seed, std::optional<std::vector<std::int32_t>> ignore_labels) {
            Model model;
            model.mesh = mesh_labels(labels, geometry, kind, grid, cell_size_mm, 0.75, std::nullopt, seed, ignore_labels ? *ignore_labels : std::vector<std::int32_t>{}, tissues);
            model.tissues = tissues_from(model.mesh, tissues);
            model.law = parse_material_law(law);
            const std::set<std::int32_t> keep = surface_labels ? std::set<std::int32_t>(surface_labels->begin(), surface_labels->end()) : std::set<std::int32_t>{};
            model.surface = cell_group_boundary(model.mesh, [&](std::int32_t l) { return keep.empty() || keep.count(l) > 0; }, "surface_labels");
            model.validate("labels");
            return model;
        }, py::arg("labels"), py::arg("geometry"), py::arg("kind") = "hex", py::arg("grid") = py::none(), py::arg("cell_size_mm") = 6.0,
           py::arg("tissues") = py::none(), py::arg("law") = "neo-hookean", py::arg("surface_labels") = py::none(), py::arg("seed") = 1u,
           py::arg("ignore_labels") = py::none(),
           "A model meshed from a uint16 label array [z, y, x] as mesh_from_labels does (kind 'hex': grid hexahedra, which a Tool can "
           "drive; 'tet': CGAL tetrahedra of cell_size_mm), then as from_mesh. Labels in ignore_labels are left out (background); "
           "every other label needs no entry in physreg's tissue table: tissues gives its modulus, else 3.5 kPa.")
        .def("hold", [](Model& model, const std::vector<std::int32_t>& nodes, const std::string& directions, const std::string& name) {
            std::array<bool, 3> dofs{false, false, false};
            for (const char c : directions) {
                if (c < 'x' || c > 'z') throw py::value_error(fmt::format("directions: '{}' is not made of x, y, z", directions));
                dofs[static_cast<std::size_t>(c - 'x')] = true;
            }
            if (directions.empty()) throw py::value_error("directions: empty");
            Model changed = model;
            changed.supports.push_back({name, nodes, dofs, Vec3::Zero()});
            changed.validate("hold");
            model = std::move(changed);
        }, py::arg("nodes"), py::arg("directions") = "xyz", py::arg("name") = "support",
           "Holds `nodes` (ids) in the given directions (e.g. 'xyz', or 'y' for a table under the model).")
        .def("surface_nodes_facing", [](const Model& model, std::array<double, 3> direction, double cosine) {
            const Vec3 d(direction[0], direction[1], direction[2]);
            if (!(d.norm() > 0) || !d.allFinite()) throw py::value_error("direction: must be a non-zero finite vector");
            return surface_nodes_facing(model.mesh, model.surface, d.normalized(), cosine);
        }, py::arg("direction"), py::arg("cosine") = 0.5,
           "Surface nodes whose outward normal points along `direction` (cosine above `cosine`): e.g. (0, 1, 0), the posterior side, to hold.")
        .def_property_readonly("mesh", [](const Model& model) { return model.mesh; }, "The mesh (a copy).")
        .def_property_readonly("law", [](const Model& model) { return to_string(model.law); })
        .def_property_readonly("tissues", [](const Model& model) {
            py::dict d;
            for (const auto& t : model.tissues.tissues) d[py::int_(t.label)] = py::make_tuple(t.young_modulus_pa, t.poisson_ratio);
            return d;
        }, "{label: (young_modulus_pa, poisson_ratio)}")
        .def_property_readonly("supports", [](const Model& model) {
            py::list out;
            for (const auto& c : model.supports) {
                std::string directions;
                for (int a = 0; a < 3; ++a)
                    if (c.dofs[static_cast<std::size_t>(a)]) directions += static_cast<char>('x' + a);
                out.append(py::make_tuple(c.name, py::array_t<std::int32_t>(static_cast<py::ssize_t>(c.nodes.size()), c.nodes.data()), directions));
            }
            return out;
        }, "[(name, node ids, directions held)]")
        .def_property_readonly("surface_triangles", [](const Model& model) {
            return triangles_array(model.surface);
        }, "(M, 3) int32 node ids of the surface's triangles.")
        .def_property_readonly("surface_labels", [](const Model& model) {
            return py::array_t<std::int32_t>(static_cast<py::ssize_t>(model.surface.labels.size()), model.surface.labels.data());
        }, "(M,) int32 region per surface triangle (0 surface, 1 umbilical notch, 2 anterior margin).")
        .def("__repr__", [](const Model& model) {
            return fmt::format("Model({} nodes, {} {}, {} tissues, law {}, {} supports, {} surface triangles)", model.mesh.node_count(), model.mesh.cell_count(),
                               model.mesh.cell_type == CellType::hexahedron ? "hexahedra" : "tetrahedra", model.tissues.tissues.size(), to_string(model.law),
                               model.supports.size(), model.surface.triangles.size());
        });

    py::class_<ToolObservation>(m, "Tool", "A tracked tool's poses: the path of its reference point (sphere centre, box centre) from first contact to its "
                                          "last pose, or a single pose (the approach then runs along the skin's normal).")
        .def(py::init([](const py::array& path, double radius_mm, const std::string& shape) {
                 ToolObservation o;
                 o.tool.name = "tool";
                 o.tool.path = points_from(path, "path");
                 if (o.tool.path.empty()) throw py::value_error("path: needs at least one pose");
                 // One pose (a single tracked position): register() finds the approach along the skin's normal.
                 o.tool.shape = parse_indenter_shape(shape);
                 if (o.tool.shape != IndenterShape::sphere) throw py::value_error(fmt::format("shape: '{}': only 'sphere' is taken from Python yet", shape));
                 if (!(radius_mm > 0) || !std::isfinite(radius_mm)) throw py::value_error(fmt::format("radius_mm: {} must be a positive number", radius_mm));
                 o.tool.radius_mm = radius_mm;
                 return o;
             }), py::arg("path"), py::arg("radius_mm"), py::arg("shape") = "sphere");
    py::class_<CloudObservation>(m, "Cloud", "A surface seen during the operation: points (N, 3) mm LPS, optional int32 region labels (N,), outward normals (N, 3).")
        .def(py::init([](const py::array& points, std::optional<py::array> labels, std::optional<py::array> normals) {
                 return CloudObservation{cloud_from(points, labels, normals)};
             }), py::arg("points"), py::arg("labels") = py::none(), py::arg("normals") = py::none());
    py::class_<SegmentationObservation>(m, "Segmentation", "A new segmentation: a uint16 label array [z, y, x] and its geometry, labels as the model's cells.")
        .def(py::init([](const py::array& labels, const ImageGeometry& geometry) { return SegmentationObservation{label_volume_from(labels, geometry)}; }),
             py::arg("labels"), py::arg("geometry"));

}

/// physreg.register and its Registration result.
void bind_register(py::module_& m)
{
    struct Registration {
        VolumeMesh mesh;
        ModelRegistration result;
    };
    py::class_<Registration>(m, "Registration", "The result of physreg.register: the mode and solver used, the nodal displacement and its dense field.")
        .def_property_readonly("mode", [](const Registration& r) { return r.result.mode; }, "compression, surface or images")
        .def_property_readonly("solver", [](const Registration& r) { return r.result.solver; })
        .def_property_readonly("seconds", [](const Registration& r) { return r.result.seconds; })
        .def_property_readonly("notes", [](const Registration& r) { return r.result.notes; }, "What the mode decided on the way (a segmentation: the rigid pre-fit)")
        .def_property_readonly("displacement", [](py::object self) {
            auto& u = self.cast<Registration&>().result.displacement_mm;
            return py::array_t<double>({static_cast<py::ssize_t>(u.size() / 3), py::ssize_t{3}}, u.data(), self);
        }, "(N, 3) float64 nodal displacement, mm (a view)")
        .def_property_readonly("mesh", [](const Registration& r) { return r.mesh; }, "The model's mesh at rest (a copy).")
        .def("field", [](const Registration& r, std::optional<ImageGeometry> geometry, double spacing_mm) {
            return dense_field(r.mesh, r.result.displacement_mm, geometry, spacing_mm);
        }, py::arg("geometry") = py::none(), py::arg("spacing_mm") = 2.0,
           "The dense field (float32 [z, y, x, 3], mm, LPS; 0 outside the model) on `geometry`, or on a grid of spacing_mm over the model → (array, ImageGeometry).")
        .def("map_points", [](const Registration& r, const py::array& points, double max_distance_mm) {
            // displace_points locates points in tetrahedra and in grid hexahedra (the tool mode's models).
            Model located;
            located.mesh = r.mesh;
            const std::vector<Vec3> moved = displace_points(located, r.result.displacement_mm, points_from(points, "points"), max_distance_mm, "points");
            py::array_t<double> out({static_cast<py::ssize_t>(moved.size()), py::ssize_t{3}});
            for (std::size_t n = 0; n < moved.size(); ++n)
                for (int a = 0; a < 3; ++a) out.mutable_at(static_cast<py::ssize_t>(n), a) = moved[n][a];
            return out;
        }, py::arg("points"), py::arg("max_distance_mm") = 10.5,
           "Rest positions (N, 3) mm (landmarks, targets) carried by the displacement; tetrahedral and grid-hexahedral models alike.");

    m.def("register", [](const Model& model, const py::object& observation, double traction_ratio, double young_modulus_pa, int max_cycles,
                         std::optional<py::function> progress, double tool_speed) {
        Observation seen;
        if (py::isinstance<ToolObservation>(observation)) seen = observation.cast<ToolObservation>();
        else if (py::isinstance<CloudObservation>(observation)) seen = observation.cast<CloudObservation>();
        else if (py::isinstance<SegmentationObservation>(observation)) seen = observation.cast<SegmentationObservation>();
        else throw py::type_error("observation: expected a physreg.Tool, physreg.Cloud or physreg.Segmentation");
        ModelRegistrationSettings settings;
        settings.cloud.traction_ratio = traction_ratio;
        settings.cloud.young_modulus_pa = young_modulus_pa;
        settings.segmentation.max_cycles = max_cycles;
        // The command's --tool-speed check, named as Python names it.
        if (!(tool_speed > 0 && tool_speed <= 0.5)) throw py::value_error(fmt::format("tool_speed: must lie in (0, 0.5] cell sizes per iteration (got {})", tool_speed));
        settings.compression.tool_speed_per_cell = tool_speed;
        const auto report = progress_from(progress);
        Registration out{model.mesh, {}};
        py::gil_scoped_release release;
        out.result = register_model(model, seen, settings, report);
        return out;
    }, py::arg("model"), py::arg("observation"), py::arg("traction_ratio") = 0.5, py::arg("young_modulus_pa") = 0.0, py::arg("max_cycles") = 40,
          py::arg("progress") = py::none(), py::arg("tool_speed") = PredictionOptions{}.tool_speed_per_cell,
          "Registers `model` to what was seen, with the solver that observation needs: a Tool → equilibrium under the tool (paper 000, "
          "TLED); a Cloud → paper 001's annealed pair forces (traction_ratio × E, E = young_modulus_pa or the surface's softest tissue); "
          "a Segmentation → paper 002's boundary-driven linear elasticity (max_cycles alternations). tool_speed: the tool's largest travel per "
          "relaxation iteration in cell sizes, as register-compression --tool-speed. Returns a Registration.");

    bind_pipelines(m);
    bind_compression(m);
    bind_live(m);
}

} // namespace

void bind_models(py::module_& m)
{
    bind_surface_model(m);
    bind_model_and_observations(m);
    bind_register(m);
}

} // namespace physreg::python
