// SPDX-License-Identifier: GPL-3.0-or-later
// The registration pipelines from Python (issue 43), calling the same library functions as the
// commands, with the same settings specifications: paper 002 (physreg.ImagePair,
// register_image_pair; register-images) and paper 001 (physreg.PartialSurfaceCase,
// register_partial_surface; register-surface).
#include "bindings.hpp"

#include "physreg/core/error.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/phantom/registration_cases.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/images/image_registration.hpp"
#include "physreg/registration/surface/partial_surface_registration.hpp"
#include "physreg/registration/surface/surface_model.hpp"

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <map>

namespace physreg::python {

namespace {

/// Paper 002's pipeline: ImagePair, register_image_pair and its result.
void bind_image_pipeline(py::module_& m)
{
    py::class_<ImagePair>(m, "ImagePair",
                          "Paper 002's input: a fixed (intra-operative) image and segmentation, a moving (pre-operative) image and "
                          "segmentation to be meshed, optional landmarks for the TRE and initial tissues.")
        .def(py::init([](const std::optional<py::array>& fixed, const py::array& fixed_labels, const ImageGeometry& fixed_geometry, const std::optional<py::array>& moving,
                         const py::array& moving_labels, const ImageGeometry& moving_geometry,
                         std::optional<std::map<std::string, std::array<double, 3>>> landmarks_fixed,
                         std::optional<std::map<std::string, std::array<double, 3>>> landmarks_moving,
                         std::optional<std::map<std::int32_t, std::pair<double, double>>> tissues, const std::string& auto_hold) {
                 ImagePair p;
                 if (fixed.has_value() != moving.has_value()) throw py::value_error("fixed, moving: give both images or neither (None: a label-to-label pair)");
                 p.fixed_labels = label_volume_from(fixed_labels, fixed_geometry);
                 p.moving_labels = label_volume_from(moving_labels, moving_geometry);
                 p.intensities = fixed.has_value();
                 // Without images the label maps stand in (the label baselines only; see ImagePair::intensities).
                 p.fixed = fixed ? scalar_image_from(*fixed, fixed_geometry, "fixed") : ScalarImage{p.fixed_labels.geometry, {p.fixed_labels.labels.begin(), p.fixed_labels.labels.end()}};
                 p.moving = moving ? scalar_image_from(*moving, moving_geometry, "moving") : ScalarImage{p.moving_labels.geometry, {p.moving_labels.labels.begin(), p.moving_labels.labels.end()}};
                 if (landmarks_fixed.has_value() != landmarks_moving.has_value())
                     throw py::value_error("landmarks_fixed, landmarks_moving: give both or neither");
                 if (landmarks_fixed) {
                     p.landmarks_fixed = landmarks_from_dict(*landmarks_fixed, "landmarks_fixed");
                     p.landmarks_moving = landmarks_from_dict(*landmarks_moving, "landmarks_moving");
                 }
                 if (tissues) {
                     for (const auto& [label, value] : *tissues)
                         p.tissues.tissues.push_back({label, fmt::format("label {}", label), value.first, value.second, 1000.0, 0.0});
                     p.tissues_source = "tissues";
                 }
                 if (auto_hold != "none" && auto_hold != "posterior") throw py::value_error(fmt::format("auto_hold: '{}' is not 'none' or 'posterior'", auto_hold));
                 p.auto_hold = auto_hold;
                 p.description = {{"source", "Python arrays"}};
                 return p;
             }),
             py::arg("fixed"), py::arg("fixed_labels"), py::arg("fixed_geometry"), py::arg("moving"), py::arg("moving_labels"), py::arg("moving_geometry"),
             py::arg("landmarks_fixed") = py::none(), py::arg("landmarks_moving") = py::none(), py::arg("tissues") = py::none(), py::arg("auto_hold") = "none",
             "Images are float32 and labels uint16 arrays [z, y, x] on their geometry (fixed = moving = None: a label-to-label pair, label baselines only); landmarks {name: (x, y, z)} mm LPS; tissues "
             "{label: (young_modulus_pa, poisson_ratio)} (default: 3 kPa, 0.45 for every structure); auto_hold: what the setting hold='auto' means.")
        .def_static("from_dataset", [](const std::filesystem::path& dataset, const std::string& state) {
            py::gil_scoped_release release;
            return read_dataset_image_pair(dataset, state);
        }, py::arg("dataset"), py::arg("state") = "insufflation",
           "A phantom dataset's rest → state pair, as register-images --dataset reads it (its organs, its material set's moduli, hold auto = posterior).")
        .def_property_readonly("has_landmarks", [](const ImagePair& p) { return p.landmarks_fixed.has_value(); })
        .def("__repr__", [](const ImagePair& p) {
            return fmt::format("ImagePair(fixed {}×{}×{}, moving {}×{}×{}, {} landmarks)", p.fixed.geometry.size[0], p.fixed.geometry.size[1], p.fixed.geometry.size[2],
                               p.moving.geometry.size[0], p.moving.geometry.size[1], p.moving.geometry.size[2], p.landmarks_fixed ? p.landmarks_fixed->size() : 0);
        });

    py::class_<ImageRegistrationResult>(m, "ImageRegistration", "The result of physreg.register_image_pair: every method's field, the summary and parameters.")
        .def_property_readonly("method", [](const ImageRegistrationResult& r) { return r.chosen_method().name; }, "the method whose result is the answer")
        .def_property_readonly("methods", [](const ImageRegistrationResult& r) {
            std::vector<std::string> names;
            for (const auto& m : r.methods) names.push_back(m.name);
            return names;
        })
        .def_property_readonly("summary", [](const ImageRegistrationResult& r) { return to_python(r.summary); }, "what register-images writes to summary.json")
        .def_property_readonly("parameters", [](const ImageRegistrationResult& r) { return to_python(r.parameters); }, "parameters.json: moduli, sensitivity, load")
        .def_property_readonly("settings", [](const ImageRegistrationResult& r) { return to_python(image_registration_spec().to_json(r.settings)); })
        .def("field", [](const ImageRegistrationResult& r, std::optional<std::string> method) {
            if (!method) return field_tuple(r.chosen_method().field);
            for (const auto& m : r.methods)
                if (m.name == *method) return field_tuple(m.field);
            throw py::value_error(fmt::format("method: '{}' was not run", *method));
        }, py::arg("method") = py::none(),
           "The fixed → moving displacement field (float32 [z, y, x, 3] mm, LPS) of `method` (default: the answer) on the region → (array, ImageGeometry); "
           "the same field register-images writes to displacement.nii.gz.")
        .def_property_readonly("warped_labels", [](const ImageRegistrationResult& r) {
            LabelVolume copy = r.chosen_method().warped_labels;
            const ImageGeometry g = copy.geometry;
            return py::make_tuple(image_array(std::move(copy), &LabelVolume::labels, 1), g);
        }, "The moving labels through the answer's field → (uint16 array, ImageGeometry).")
        .def_property_readonly("landmarks", [](const ImageRegistrationResult& r) -> py::object {
            if (!r.chosen_method().landmarks) return py::none();
            return landmarks_dict(*r.chosen_method().landmarks);
        }, "The moving landmarks carried onto the fixed image {name: (x, y, z)}, or None.");

    m.def("register_image_pair", [](const ImagePair& pair, std::optional<py::dict> settings, std::optional<py::function> progress, const py::kwargs& overrides) {
        const auto s = settings_from(image_registration_spec(), settings, overrides, "register_image_pair");
        const auto report = progress_from(progress);
        py::gil_scoped_release release;
        return register_images(pair, s, report);
    }, py::arg("pair"), py::arg("settings") = py::none(), py::arg("progress") = py::none(),
          "Paper 002's pipeline, as `physreg register-images`: initial alignment, conforming tetrahedra, linear elasticity with boundary "
          "load and moduli by L-BFGS with adjoint gradients, ITK baselines, evaluation. settings: a dict of physreg.settings_spec('register-images') "
          "keys; keyword arguments override it (e.g. cycles=4). Returns an ImageRegistration.");

}

/// Paper 001's pipeline: PartialSurfaceCase, register_partial_surface and its result.
void bind_surface_pipeline(py::module_& m)
{
    // ---- paper 001 ---------------------------------------------------------------------------------
    py::class_<PartialSurfaceCase>(m, "PartialSurfaceCase",
                                   "Paper 001's input: a tetrahedral liver model with a labelled surface, an intra-operative cloud, and "
                                   "optionally targets with their truth.")
        .def(py::init([](const SurfaceModel& model, const py::array& points, std::optional<py::array> labels, std::optional<py::array> normals,
                         std::optional<std::map<std::string, std::array<double, 3>>> landmarks, std::optional<std::map<std::string, std::array<double, 3>>> truth,
                         std::optional<std::vector<std::int32_t>> support_nodes, bool patient_frame,
                         std::optional<std::vector<std::int32_t>> load_nodes) {
                 PartialSurfaceCase c;
                 c.patient_frame = patient_frame;
                 c.mesh = model.mesh;
                 c.surface = model.surface;
                 c.quality = model.quality;
                 c.cloud = cloud_from(points, labels, normals);
                 if (truth && !landmarks) throw py::value_error("truth: needs landmarks (their rest positions)");
                 if (landmarks) c.landmarks = landmarks_from_dict(*landmarks, "landmarks");
                 if (truth) c.truth = landmarks_from_dict(*truth, "truth");
                 if (support_nodes) {
                     c.support_nodes = *support_nodes;
                     c.support_nodes_source = "support_nodes";
                 }
                 if (load_nodes) {
                     c.load_nodes = *load_nodes;
                     c.load_nodes_source = "load_nodes";
                 }
                 c.description = {{"source", "Python arrays"}};
                 return c;
             }),
             py::arg("model"), py::arg("points"), py::arg("labels") = py::none(), py::arg("normals") = py::none(), py::arg("landmarks") = py::none(),
             py::arg("truth") = py::none(), py::arg("support_nodes") = py::none(), py::arg("patient_frame") = false, py::arg("load_nodes") = py::none(),
             "A SurfaceModel and a cloud (points (N, 3) mm LPS, int32 region labels (N,), normals (N, 3)); landmarks {name: (x, y, z)} at rest "
             "and their truth; support_nodes: node ids held besides the settings' support; patient_frame: the coordinates are a patient's "
             "LPS frame (then support 'auto' offers the posterior surface); load_nodes: surface node ids where forces may act (the tool's contact "
             "region; the settings' load_nodes, load_points and tool_path add to it).")
        .def_static("from_dataset", [](const std::filesystem::path& dataset, const std::string& state, std::optional<int> visible,
                                       std::optional<py::dict> settings, const py::kwargs& overrides) {
            const auto s = settings_from(partial_surface_spec(), settings, overrides, "PartialSurfaceCase.from_dataset");
            py::gil_scoped_release release;
            return read_dataset_surface_case(dataset, state, visible, s);
        }, py::arg("dataset"), py::arg("state") = "insufflation", py::arg("visible") = py::none(), py::arg("settings") = py::none(),
           "A phantom dataset's state as register-surface --dataset reads it (the rest liver meshed with the settings' cell_size and seed).")
        .def_property_readonly("node_count", [](const PartialSurfaceCase& c) { return c.mesh.node_count(); })
        .def_property_readonly("cloud_points", [](const PartialSurfaceCase& c) { return c.cloud.points.size(); });

    py::class_<PartialSurfaceResult>(m, "PartialSurfaceRegistration", "The result of physreg.register_partial_surface: every method's displacement and the summary.")
        .def_property_readonly("method", [](const PartialSurfaceResult& r) { return r.chosen_method().name; })
        .def_property_readonly("methods", [](const PartialSurfaceResult& r) {
            std::vector<std::string> names;
            for (const auto& m : r.methods) names.push_back(m.name);
            return names;
        })
        .def_property_readonly("summary", [](const PartialSurfaceResult& r) { return to_python(r.summary); }, "what register-surface writes to summary.json")
        .def_property_readonly("settings", [](const PartialSurfaceResult& r) { return to_python(partial_surface_spec().to_json(r.settings)); })
        .def("displacement", [](const PartialSurfaceResult& r, std::optional<std::string> method) {
            const PartialSurfaceMethod* chosen = &r.chosen_method();
            if (method) {
                chosen = nullptr;
                for (const auto& m : r.methods)
                    if (m.name == *method) chosen = &m;
                if (!chosen) throw py::value_error(fmt::format("method: '{}' was not run", *method));
            }
            const auto& u = chosen->displacement_mm;
            py::array_t<double> out({static_cast<py::ssize_t>(u.size() / 3), py::ssize_t{3}});
            std::copy(u.begin(), u.end(), out.mutable_data());
            return out;
        }, py::arg("method") = py::none(), "(nodes, 3) float64 nodal displacement, mm, of `method` (default: the answer)")
        .def_property_readonly("landmarks", [](const PartialSurfaceResult& r) -> py::object {
            if (!r.landmarks) return py::none();
            return landmarks_dict(*r.landmarks);
        }, "The targets carried by the answer {name: (x, y, z)}, or None.")
        .def("field", [](const PartialSurfaceResult& r, const PartialSurfaceCase& c) {
            DisplacementField f;
            {
                py::gil_scoped_release release;
                f = sample_displacement_field(c.mesh, r.chosen_method().displacement_mm, r.field_geometry).field;
            }
            const ImageGeometry g = f.geometry;
            return py::make_tuple(image_array(std::move(f), &DisplacementField::components, 3), g);
        }, py::arg("case"), "The answer's dense field on register-surface's grid → (float32 [z, y, x, 3] mm, ImageGeometry): its displacement.nii.gz.");

    m.def("register_partial_surface", [](const PartialSurfaceCase& c, std::optional<py::dict> settings, std::optional<py::function> progress, const py::kwargs& overrides) {
        const auto s = settings_from(partial_surface_spec(), settings, overrides, "register_partial_surface");
        const auto report = progress_from(progress);
        py::gil_scoped_release release;
        return register_partial_surface(c, s, report);
    }, py::arg("case"), py::arg("settings") = py::none(), py::arg("progress") = py::none(),
          "Paper 001's pipeline, as `physreg register-surface`: supports, labelled rigid and ICP baselines, the biomechanical registration "
          "(annealed arctan pair forces, co-rotational backward Euler), the adjoint method when asked, evaluation and the determinacy check. "
          "settings: a dict of physreg.settings_spec('register-surface') keys; keyword arguments override it. Returns a PartialSurfaceRegistration.");

}

} // namespace

void bind_pipelines(py::module_& m)
{
    bind_image_pipeline(m);
    bind_surface_pipeline(m);
    m.def("settings_spec", [](const std::string& mode) {
        if (mode == "register-images") return to_python(image_registration_spec().describe());
        if (mode == "register-surface") return to_python(partial_surface_spec().describe());
        if (mode == "register-compression") return to_python(compression_spec().describe());
        if (mode == "estimate") return to_python(estimation_spec().describe());
        if (mode == "enrich-build") return to_python(enrichment_build_spec().describe());
        if (mode == "enrich-apply") return to_python(enrichment_apply_spec().describe());
        throw py::value_error(fmt::format("mode: '{}' has no settings specification (register-images, register-surface, register-compression, "
                                          "estimate, enrich-build, enrich-apply)", mode));
    }, py::arg("mode"), "A mode's settings: {key: {option, kind, default, unit, range or choices, help}}.");
}

} // namespace physreg::python
