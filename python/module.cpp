// SPDX-License-Identifier: GPL-3.0-or-later
// physreg's Python module (_physreg; the package `physreg` wraps it): the errors, ImageGeometry and
// `run` here; the bound areas in bind_io, bind_models, bind_pipelines and bind_compression. Arrays
// follow SimpleITK's convention: a volume is a C-contiguous numpy array indexed [k, j, i] (z, y, x),
// sharing physreg's memory layout (x fastest), so images and mesh nodes pass without copies where
// the layout allows. Positions are mm in ITK's LPS space.
#include "app.hpp"
#include "bindings.hpp"
#include "progress.hpp"

#include "physreg/core/blas_kernels.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/version.hpp"

#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <array>

namespace py = pybind11;
using namespace physreg;
using namespace physreg::python;

PYBIND11_MODULE(_physreg, m)
{
    m.doc() = "physreg: biomechanical volumetric registration (C++ core). Units: mm, Pa, N; LPS space.";
    m.attr("__version__") = physreg::VERSION;
    m.def("openblas_kernels", &openblas_kernels,
          "OpenBLAS's kernel set in this process ('SkylakeX', 'Haswell', 'Prescott', ...); '' when the BLAS is not OpenBLAS");
    m.def("openblas_better_kernels", &openblas_better_kernels,
          "The OPENBLAS_CORETYPE to start Python with when OpenBLAS fell back to its generic kernels on a CPU that runs "
          "better ones (AVX-512: 'SkylakeX', AVX2: 'Haswell'); '' otherwise");

    static py::exception<Error> error(m, "Error", PyExc_RuntimeError);
    error.attr("__doc__") = "Bad input (a corrupt file, wrong dimensions, an impossible parameter) or a failed solve: the message names the "
                            "file or parameter and the reason, as the physreg program prints it. A RuntimeError.";
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const MissingFileError& e) {
            PyErr_SetString(PyExc_FileNotFoundError, e.what());
        } catch (const Error& e) {
            error(e.what());
        }
    });

    py::class_<ImageGeometry>(m, "ImageGeometry",
                              "Where an image lies: origin (mm, centre of voxel 0,0,0), spacing (mm per voxel along i, j, k), "
                              "direction (3×3, columns = image axes in LPS) and size (voxels along i, j, k).")
        .def(py::init([](std::array<double, 3> origin, std::array<double, 3> spacing, std::optional<py::array> direction) {
                 ImageGeometry g;
                 g.origin = Vec3(origin[0], origin[1], origin[2]);
                 g.spacing = Vec3(spacing[0], spacing[1], spacing[2]);
                 if (direction) {
                     const auto d = direction->cast<CArray<double>>();
                     if (d.ndim() != 2 || d.shape(0) != 3 || d.shape(1) != 3) throw py::value_error("direction: expected shape (3, 3)");
                     for (int r = 0; r < 3; ++r)
                         for (int c = 0; c < 3; ++c) g.direction(r, c) = d.at(r, c);
                 }
                 g.size = Index3{1, 1, 1};
                 g.validate("ImageGeometry");
                 return g;
             }),
             py::arg("origin") = std::array<double, 3>{0, 0, 0}, py::arg("spacing") = std::array<double, 3>{1, 1, 1}, py::arg("direction") = py::none())
        .def_property_readonly("origin", [](const ImageGeometry& g) { return std::array<double, 3>{g.origin[0], g.origin[1], g.origin[2]}; })
        .def_property_readonly("spacing", [](const ImageGeometry& g) { return std::array<double, 3>{g.spacing[0], g.spacing[1], g.spacing[2]}; })
        .def_property_readonly("size", [](const ImageGeometry& g) { return std::array<std::int64_t, 3>{g.size[0], g.size[1], g.size[2]}; })
        .def_property_readonly("direction", [](const ImageGeometry& g) {
            py::array_t<double> d({3, 3});
            for (int r = 0; r < 3; ++r)
                for (int c = 0; c < 3; ++c) d.mutable_at(r, c) = g.direction(r, c);
            return d;
        })
        .def("index_to_physical", [](const ImageGeometry& g, std::array<double, 3> ijk) {
            const Vec3 x = g.index_to_physical(Vec3(ijk[0], ijk[1], ijk[2]));
            return std::array<double, 3>{x[0], x[1], x[2]};
        }, py::arg("ijk"), "Continuous index (i, j, k) → physical point (mm, LPS).")
        .def("__repr__", [](const ImageGeometry& g) {
            return fmt::format("ImageGeometry(size=({}, {}, {}), spacing=({:g}, {:g}, {:g}) mm, origin=({:g}, {:g}, {:g}) mm)", g.size[0], g.size[1], g.size[2],
                               g.spacing[0], g.spacing[1], g.spacing[2], g.origin[0], g.origin[1], g.origin[2]);
        });


    bind_io(m);
    bind_models(m);

    m.def("run", [](const std::vector<std::string>& args, std::optional<py::function> progress) {
        struct Restore {
            ~Restore() { cli::set_progress_sink({}); }
        } restore;
        if (progress) {
            py::function callback = *progress;
            cli::set_progress_sink([callback](const std::string& label, double fraction, const std::string& message) {
                callback(label, fraction, message);
                if (PyErr_CheckSignals() != 0) throw py::error_already_set();
            });
        }
        cli::run_in_process(args);
    }, py::arg("args"), py::arg("progress") = py::none(),
          "Runs `physreg ARGS...` in this process (the same commands, checks and messages as the program). "
          "progress(label, fraction 0–1, message) is called on long work instead of the terminal bar.");
}
