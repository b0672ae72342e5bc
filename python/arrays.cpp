// SPDX-License-Identifier: GPL-3.0-or-later
#include "bindings.hpp"

#include <fmt/format.h>

#include <pybind11/stl.h>

namespace physreg::python {

// ---- argument checks: TypeError for the wrong kind of object/dtype, ValueError for shapes --------

void require_dtype(const py::array& a, const py::dtype& expected, const char* argument)
{
    if (!a.dtype().is(expected))
        throw py::type_error(fmt::format("{}: expected dtype {}, got {}", argument, std::string(py::str(py::object(expected))), std::string(py::str(py::object(a.dtype())))));
}

void require_c_contiguous(const py::array& a, const char* argument)
{
    if (!(a.flags() & py::array::c_style))
        throw py::value_error(fmt::format("{}: the array must be C-contiguous (use numpy.ascontiguousarray)", argument));
}

/// An (N, 3) float64 array of points, copied into Vec3s; ValueError naming `argument`.
std::vector<Vec3> points_from(const py::array& a, const char* argument)
{
    require_dtype(a, py::dtype::of<double>(), argument);
    if (a.ndim() != 2 || a.shape(1) != 3)
        throw py::value_error(fmt::format("{}: expected shape (N, 3), got {}", argument, std::string(py::str(py::tuple(py::cast(std::vector<py::ssize_t>(a.shape(), a.shape() + a.ndim())))))));
    const auto view = a.cast<CArray<double>>().unchecked<2>();
    std::vector<Vec3> out(static_cast<std::size_t>(a.shape(0)));
    for (py::ssize_t n = 0; n < a.shape(0); ++n) {
        out[static_cast<std::size_t>(n)] = Vec3(view(n, 0), view(n, 1), view(n, 2));
        if (!out[static_cast<std::size_t>(n)].allFinite()) throw py::value_error(fmt::format("{}: row {} is not finite", argument, n));
    }
    return out;
}

/// A view of a std::vector<Vec3> (N, 3) float64 owned by `owner`.
py::array points_view(std::vector<Vec3>& points, py::handle owner)
{
    return py::array_t<double>({static_cast<py::ssize_t>(points.size()), py::ssize_t{3}}, {sizeof(Vec3), sizeof(double)},
                               points.empty() ? nullptr : points.front().data(), owner);
}

// ---- images ---------------------------------------------------------------------------------------

py::array volume_shape_check(const py::array& a, const char* argument)
{
    if (a.ndim() != 3) throw py::value_error(fmt::format("{}: expected a 3-D array indexed [z, y, x], got {} dimensions", argument, a.ndim()));
    require_c_contiguous(a, argument);
    return a;
}

ImageGeometry geometry_for(const py::array& a, const ImageGeometry& given, const char* argument)
{
    ImageGeometry g = given;
    g.size = Index3{a.shape(2), a.shape(1), a.shape(0)};
    g.validate(argument);
    return g;
}

/// A uint16 array [z, y, x] and its geometry → a LabelVolume (copied).
LabelVolume label_volume_from(const py::array& labels, const ImageGeometry& geometry)
{
    volume_shape_check(labels, "labels");
    require_dtype(labels, py::dtype::of<std::uint16_t>(), "labels");
    LabelVolume v;
    v.geometry = geometry_for(labels, geometry, "geometry");
    const auto* data = static_cast<const std::uint16_t*>(labels.data());
    v.labels.assign(data, data + labels.size());
    return v;
}

/// A progress(fraction, message) callback for the library, called with the GIL held; Ctrl-C stops it.
std::function<void(double, const std::string&)> progress_from(const std::optional<py::function>& progress)
{
    if (!progress) return {};
    py::function callback = *progress;
    return [callback](double fraction, const std::string& message) {
        py::gil_scoped_acquire acquire;
        callback(fraction, message);
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    };
}

/// A cloud from numpy: points (N, 3) float64 mm, optional int32 labels (N,) (default 0) and normals (N, 3).
LabelledPointCloud cloud_from(const py::array& points, const std::optional<py::array>& labels, const std::optional<py::array>& normals)
{
    LabelledPointCloud cloud;
    cloud.points = points_from(points, "points");
    if (cloud.points.empty()) throw py::value_error("points: the cloud has no point");
    if (labels) {
        require_dtype(*labels, py::dtype::of<std::int32_t>(), "labels");
        if (labels->ndim() != 1 || static_cast<std::size_t>(labels->shape(0)) != cloud.points.size())
            throw py::value_error(fmt::format("labels: expected shape ({},)", cloud.points.size()));
        const auto* l = static_cast<const std::int32_t*>(labels->cast<CArray<std::int32_t>>().data());
        cloud.labels.assign(l, l + cloud.points.size());
    } else {
        cloud.labels.assign(cloud.points.size(), 0);
    }
    if (normals) {
        cloud.normals = points_from(*normals, "normals");
        if (cloud.normals.size() != cloud.points.size()) throw py::value_error(fmt::format("normals: {} rows for {} points", cloud.normals.size(), cloud.points.size()));
    }
    return cloud;
}

ScalarImage scalar_image_from(const py::array& image, const ImageGeometry& geometry, const char* argument)
{
    volume_shape_check(image, argument);
    require_dtype(image, py::dtype::of<float>(), argument);
    ScalarImage v;
    v.geometry = geometry_for(image, geometry, "geometry");
    const auto* data = static_cast<const float*>(image.data());
    v.values.assign(data, data + image.size());
    return v;
}

py::object to_python(const nlohmann::json& value) { return py::module_::import("json").attr("loads")(value.dump()); }

nlohmann::json from_python(const py::handle& value)
{
    const std::string text = py::str(py::module_::import("json").attr("dumps")(value));
    return nlohmann::json::parse(text);
}

/// {name: (x, y, z)} mm LPS → landmarks (untyped: they count in the TRE's "all" group).
LandmarkSet landmarks_from_dict(const std::map<std::string, std::array<double, 3>>& given, const char* argument)
{
    LandmarkSet set;
    for (const auto& [name, p] : given) {
        const Vec3 x(p[0], p[1], p[2]);
        if (!x.allFinite()) throw py::value_error(fmt::format("{}: landmark '{}' is not finite", argument, name));
        set.push_back({name, x, LandmarkType::unspecified});
    }
    return set;
}

py::dict landmarks_dict(const LandmarkSet& set)
{
    py::dict d;
    for (const auto& l : set) d[py::str(l.name)] = py::make_tuple(l.position[0], l.position[1], l.position[2]);
    return d;
}

py::tuple field_tuple(const DisplacementField& field)
{
    DisplacementField copy = field;
    const ImageGeometry g = copy.geometry;
    return py::make_tuple(image_array(std::move(copy), &DisplacementField::components, 3), g);
}

} // namespace physreg::python
