// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// What the Python module's bound areas share: numpy ↔ physreg conversions with their argument
// checks (TypeError for the wrong kind or dtype, ValueError for shapes), progress callbacks, and
// JSON ↔ Python objects for settings and summaries.
#include "physreg/core/landmark.hpp"
#include "physreg/core/settings_spec.hpp"
#include "physreg/core/types.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/image/image_geometry.hpp"
#include "physreg/io/point_cloud.hpp"

#include <nlohmann/json.hpp>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <array>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace physreg::python {
namespace py = pybind11;

template <typename T>
using CArray = py::array_t<T, py::array::c_style>;

void require_dtype(const py::array& a, const py::dtype& expected, const char* argument);
void require_c_contiguous(const py::array& a, const char* argument);
/// An (N, 3) float64 array of points, copied into Vec3s; ValueError naming `argument`.
std::vector<Vec3> points_from(const py::array& a, const char* argument);
/// A view of a std::vector<Vec3> (N, 3) float64 owned by `owner`.
py::array points_view(std::vector<Vec3>& points, py::handle owner);
py::array volume_shape_check(const py::array& a, const char* argument);
ImageGeometry geometry_for(const py::array& a, const ImageGeometry& given, const char* argument);
/// A uint16 array [z, y, x] and its geometry → a LabelVolume (copied).
LabelVolume label_volume_from(const py::array& labels, const ImageGeometry& geometry);
/// A float32 array [z, y, x] and its geometry → a ScalarImage (copied).
ScalarImage scalar_image_from(const py::array& image, const ImageGeometry& geometry, const char* argument);
/// A cloud from numpy: points (N, 3) float64 mm, optional int32 labels (N,) (default 0) and normals (N, 3).
LabelledPointCloud cloud_from(const py::array& points, const std::optional<py::array>& labels, const std::optional<py::array>& normals);
/// A progress(fraction, message) callback for the library, called with the GIL held; Ctrl-C stops it.
std::function<void(double, const std::string&)> progress_from(const std::optional<py::function>& progress);
/// JSON → Python (dict, list, str, float, int, bool, None) and back (through Python's json module).
py::object to_python(const nlohmann::json& value);
nlohmann::json from_python(const py::handle& value);

/// {name: (x, y, z)} mm LPS → landmarks (untyped: they count in the TRE's "all" group); ValueError naming `argument`.
LandmarkSet landmarks_from_dict(const std::map<std::string, std::array<double, 3>>& given, const char* argument);
/// A displacement field → (float32 array [z, y, x, 3] mm, ImageGeometry).
py::tuple field_tuple(const DisplacementField& field);
/// Landmarks → {name: (x, y, z)}.
py::dict landmarks_dict(const LandmarkSet& set);

/// A mode's settings from Python: `s` (the specification's defaults unless given), then `settings` (a dict), then
/// keyword overrides; checked with the keys as Python names them.
template <typename Settings>
Settings settings_from(const SettingsSpec<Settings>& spec, const std::optional<py::dict>& settings, const py::kwargs& overrides, const char* function,
                       Settings s = {})
{
    if (settings) spec.apply(s, from_python(*settings), "settings");
    if (overrides.size() > 0) spec.apply(s, from_python(overrides), function);
    validate(s, SettingNaming::key);
    return s;
}

/// A label array meshed as Model.from_labels and mesh_from_labels do: kind "hex" (a grid, or one cell
/// per voxel) or "tet" (CGAL); `ignore`: labels taken as background; `tissues`: {label: (E Pa, ν)}.
VolumeMesh mesh_labels(const py::array& labels, const ImageGeometry& geometry, const std::string& kind, std::optional<std::array<int, 3>> grid,
                       double cell_size_mm, double facet_distance_mm, std::optional<std::vector<std::int32_t>> only, unsigned seed,
                       const std::vector<std::int32_t>& ignore = {}, const std::optional<std::map<std::int32_t, std::pair<double, double>>>& tissues = std::nullopt);

/// The bound areas beside module.cpp's.
void bind_io(py::module_& m);          ///< bind_io.cpp: images, meshes, surfaces, landmarks, TRE
void bind_models(py::module_& m);      ///< bind_models.cpp: SurfaceModel, Model, observations, register
void bind_pipelines(py::module_& m);   ///< bind_pipelines.cpp: papers 001 and 002 as the commands run them
void bind_compression(py::module_& m); ///< bind_compression.cpp: paper 000 as the commands run it
void bind_live(py::module_& m);        ///< bind_live.cpp: serve and its client (the live layer)

/// An image's values as a numpy array [z, y, x] (or [z, y, x, c]) that owns the image.
template <typename Image, typename Value>
py::array image_array(Image&& image, std::vector<Value> Image::*values, int components)
{
    auto* owned = new Image(std::move(image));
    py::capsule owner(owned, [](void* p) { delete static_cast<Image*>(p); });
    const auto& g = owned->geometry;
    std::vector<py::ssize_t> shape{g.size[2], g.size[1], g.size[0]};
    if (components > 1) shape.push_back(components);
    return py::array_t<Value>(shape, ((*owned).*values).data(), owner);
}



} // namespace physreg::python
