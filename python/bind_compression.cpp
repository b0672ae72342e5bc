// SPDX-License-Identifier: GPL-3.0-or-later
// Paper 000 from Python (issue 43), calling the same library functions as the commands with the
// same settings specifications: the subject (physreg.CompressionSubject), a compression predicted
// (predict_compression; register-compression), the parameters estimated (estimate_compression;
// estimate) and the coarse-to-fine scheme (predict_coarse_to_fine; enrich apply).
#include "bindings.hpp"

#include "physreg/core/error.hpp"
#include "physreg/io/dataset.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/observation.hpp"

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

namespace physreg::python {
namespace {

py::array nodal_array(const std::vector<double>& u)
{
    py::array_t<double> out({static_cast<py::ssize_t>(u.size() / 3), py::ssize_t{3}});
    std::copy(u.begin(), u.end(), out.mutable_data());
    return out;
}

/// A mode's settings starting from the subject's model keys (the model is built already).
template <typename Settings>
Settings with_model(Settings s, const CompressionSubject& subject)
{
    static_cast<CompressionSettings&>(s) = subject.settings;
    return s;
}

/// A one-pose tool gets its approach along the skin's normal, as physreg.register does.
CompressionCase complete_case(const CompressionSubject& subject, CompressionCase c)
{
    if (c.tool.path.size() == 1) c.tool = with_approach_path(to_model(subject.model), c.tool);
    return c;
}

} // namespace

void bind_compression(py::module_& m)
{
    py::class_<CompressionSubject>(m, "CompressionSubject",
                                   "Paper 000's subject: the body at rest (labels, roles, landmarks) and the heterogeneous hexahedral model "
                                   "built on it, from the settings or from a parameter file (physreg estimate).")
        .def_static("from_dataset", [](const std::filesystem::path& dataset, std::optional<std::string> parameters, std::optional<py::dict> settings,
                                       const py::kwargs& overrides) {
            const auto s = settings_from(compression_spec(), settings, overrides, "CompressionSubject.from_dataset");
            py::gil_scoped_release release;
            return read_dataset_compression_subject(dataset, s, parameters.value_or(""));
        }, py::arg("dataset"), py::arg("parameters") = py::none(), py::arg("settings") = py::none(),
           "A phantom dataset's rest state, as register-compression --dataset reads it; settings: the model keys of "
           "physreg.settings_spec('register-compression') (variant, region, grid, …), none of them beside a parameter file.")
        .def_property_readonly("node_count", [](const CompressionSubject& s) { return s.model.mesh.node_count(); })
        .def_property_readonly("hexahedra", [](const CompressionSubject& s) { return s.model.mesh.cell_count(); })
        .def_property_readonly("parameters", [](const CompressionSubject& s) { return to_python(to_json(s.model.parameters)); },
                               "the model's parameters as summary.json writes them")
        .def_property_readonly("rest_landmarks", [](const CompressionSubject& s) { return landmarks_dict(s.rest_landmarks); })
        .def("__repr__", [](const CompressionSubject& s) {
            return fmt::format("CompressionSubject({} {} model: {} nodes, {} hexahedra)", to_string(s.model.parameters.region),
                               to_string(s.model.parameters.variant), s.model.mesh.node_count(), s.model.mesh.cell_count());
        });

    py::class_<CompressionCase>(m, "CompressionCase", "A tool compression: the tool's path and, when known, the landmarks it produced (the truth).")
        .def(py::init([](const ToolObservation& tool, std::optional<std::map<std::string, std::array<double, 3>>> truth, const std::string& name) {
                 CompressionCase c{name, tool.tool, {}};
                 if (truth) c.truth = landmarks_from_dict(*truth, "truth");
                 return c;
             }),
             py::arg("tool"), py::arg("truth") = py::none(), py::arg("name") = "tool",
             "tool: a physreg.Tool (one pose: the approach runs along the skin's normal); truth {name: (x, y, z)} mm LPS of the rest landmarks.")
        .def_static("from_dataset", [](const std::filesystem::path& dataset, const std::string& state) {
            py::gil_scoped_release release;
            return compression_cases(read_phantom_dataset(dataset), {state}).front();
        }, py::arg("dataset"), py::arg("state"), "A phantom dataset's compression with its ground-truth landmarks.")
        .def_readonly("name", &CompressionCase::name)
        .def_property_readonly("has_truth", [](const CompressionCase& c) { return !c.truth.empty(); });

    py::class_<CompressionRegistrationResult>(m, "CompressionRegistration", "The result of physreg.predict_compression.")
        .def_property_readonly("summary", [](const CompressionRegistrationResult& r) { return to_python(r.summary); }, "what register-compression writes to summary.json")
        .def_property_readonly("settings", [](const CompressionRegistrationResult& r) { return to_python(compression_spec().to_json(r.settings)); })
        .def_property_readonly("displacement", [](const CompressionRegistrationResult& r) { return nodal_array(r.prediction.displacement_mm); },
                               "(nodes, 3) float64 nodal displacement of the model, mm")
        .def_property_readonly("landmarks", [](const CompressionRegistrationResult& r) { return landmarks_dict(r.prediction.landmarks); },
                               "the rest landmarks moved by the model {name: (x, y, z)}")
        .def_property_readonly("field", [](const CompressionRegistrationResult& r) { return field_tuple(r.field.field); },
                               "the dense field register-compression writes to displacement.nii.gz → (float32 [z, y, x, 3] mm, ImageGeometry)");

    m.def("predict_compression", [](const CompressionSubject& subject, const CompressionCase& observed, std::optional<py::dict> settings,
                                     std::optional<py::function> progress, const py::kwargs& overrides) {
        const auto s = settings_from(compression_spec(), settings, overrides, "predict_compression", with_model(CompressionRegistrationSettings{}, subject));
        const auto report = progress_from(progress);
        py::gil_scoped_release release;
        return register_compression(subject, complete_case(subject, observed), s, report);
    }, py::arg("subject"), py::arg("case"), py::arg("settings") = py::none(), py::arg("progress") = py::none(),
          "Paper 000's prediction of a compression, as `physreg register-compression`: the tool's path through the model (relaxation or "
          "Newton to the Neo-Hookean equilibrium, or condensed contact), the tool-passage check, the dense field, TRE against the truth "
          "and against the landmarks at rest. settings: physreg.settings_spec('register-compression') keys (the solver's; the model's are "
          "the subject's); keyword arguments override them. Returns a CompressionRegistration.");

    py::class_<CompressionEstimationRun>(m, "CompressionEstimation", "The result of physreg.estimate_compression.")
        .def_property_readonly("summary", [](const CompressionEstimationRun& r) { return to_python(r.summary); }, "estimate --json")
        .def_property_readonly("report", [](const CompressionEstimationRun& r) { return to_python(r.report); }, "estimate --report: history and landmarks")
        .def_property_readonly("fitted", [](const CompressionEstimationRun& r) { return to_python(to_json(r.result.fitted)); })
        .def("write_parameters", [](const CompressionEstimationRun& r, const std::filesystem::path& path) {
            write_model_parameters(path, r.result.fitted, r.result.fingerprint, r.fit.dump());
        }, py::arg("path"), "The parameter file estimate -o writes (read by CompressionSubject.from_dataset(parameters=…)).");

    m.def("estimate_compression", [](const std::filesystem::path& dataset, std::optional<py::dict> settings, std::optional<py::function> progress,
                                     const py::kwargs& overrides) {
        const auto s = settings_from(estimation_spec(), settings, overrides, "estimate_compression");
        const auto report = progress_from(progress);
        py::gil_scoped_release release;
        const PhantomDataset d = read_phantom_dataset(dataset);
        return estimate_compression(read_dataset_compression_subject(dataset, s), d, s, report);
    }, py::arg("dataset"), py::arg("settings") = py::none(), py::arg("progress") = py::none(),
          "Paper 000 eqs. 6–7, as `physreg estimate`: the coupling stiffnesses (and optionally moduli) fitted to the training compressions' "
          "landmarks, validated on the held-out ones. settings: physreg.settings_spec('estimate') keys. Returns a CompressionEstimation.");

    py::class_<CoarseToFineResult>(m, "CoarseToFine", "The result of physreg.predict_coarse_to_fine.")
        .def_property_readonly("summary", [](const CoarseToFineResult& r) { return to_python(r.summary); }, "what enrich apply writes to summary.json")
        .def_property_readonly("displacement", [](const CoarseToFineResult& r) { return nodal_array(r.prediction.fine_u); }, "(fine nodes, 3) mm")
        .def_property_readonly("landmarks", [](const CoarseToFineResult& r) { return landmarks_dict(r.prediction.landmarks); })
        .def_property_readonly("field", [](const CoarseToFineResult& r) { return field_tuple(r.field.field); });

    m.def("predict_coarse_to_fine", [](const CompressionSubject& subject, const std::filesystem::path& database, const CompressionCase& observed,
                                       std::optional<py::dict> settings, std::optional<py::function> progress, const py::kwargs& overrides) {
        const auto s = settings_from(enrichment_apply_spec(), settings, overrides, "predict_coarse_to_fine", with_model(EnrichmentApplySettings{}, subject));
        const auto report = progress_from(progress);
        py::gil_scoped_release release;
        const EnrichmentDatabase db = read_enrichment_database(database);
        return predict_compression_coarse_to_fine(subject, db, complete_case(subject, observed), s, "database '" + database.string() + "'", report);
    }, py::arg("subject"), py::arg("database"), py::arg("case"), py::arg("settings") = py::none(), py::arg("progress") = py::none(),
          "Paper 000's coarse-to-fine scheme, as `physreg enrich apply`: the coarse model simulated, the database's conditions matched, the "
          "fine mesh synthesised. settings: physreg.settings_spec('enrich-apply') keys. Returns a CoarseToFine.");
}

} // namespace physreg::python
