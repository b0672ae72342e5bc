// SPDX-License-Identifier: GPL-3.0-or-later
// The live link from Python (issue 59 item 6): physreg.serve, the library's session that `physreg
// serve` runs, and physreg.LiveClient, a tracker's and a display's side of it.
#include "bindings.hpp"

#include "physreg/live/client.hpp"
#include "physreg/live/serve.hpp"
#include "physreg/registration/compression/compression_registration.hpp"

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <atomic>
#include <filesystem>

namespace physreg::python {

void bind_live(py::module_& m)
{
    m.def("serve", [](std::optional<std::filesystem::path> model, std::optional<std::filesystem::path> dataset, int port, const std::string& client,
                      const std::string& bind, int max_clients, double send_queue_mib, const std::string& frame, const std::string& tool,
                      const std::string& cloud, const std::string& segmentation, std::optional<std::filesystem::path> record, double surface_cell_size,
                      bool once, std::optional<std::filesystem::path> parameters, std::optional<py::dict> settings, const py::kwargs& overrides) {
        live::ServeOptions o;
        if (model) o.model = model->string();
        if (dataset) o.dataset = dataset->string();
        if (parameters) o.parameters = parameters->string();
        if (record) o.record = record->string();
        o.port = port;
        o.client = client;
        o.host = bind;
        o.max_clients = max_clients;
        o.queue_mib = send_queue_mib;
        o.frame = frame;
        o.tool = tool;
        o.cloud = cloud;
        o.segmentation = segmentation;
        o.surface_cell_size = surface_cell_size;
        o.once = once;
        const auto s = settings_from(compression_spec(), settings, overrides, "serve", CompressionRegistrationSettings{});
        // Ctrl-C in Python: the session polls this about every 100 ms and ends cleanly; the
        // KeyboardInterrupt is raised once the GIL is back.
        std::atomic<bool> interrupted{false};
        o.stop_requested = [&interrupted] {
            py::gil_scoped_acquire gil;
            if (PyErr_CheckSignals() != 0) interrupted = true;
            return interrupted.load();
        };
        {
            py::gil_scoped_release release;
            live::serve(o, s);
        }
        if (interrupted) throw py::error_already_set();
    }, py::arg("model") = py::none(), py::arg("dataset") = py::none(), py::arg("port") = 0, py::arg("client") = "", py::arg("bind") = "127.0.0.1",
       py::arg("max_clients") = 4, py::arg("send_queue_mib") = 64.0, py::arg("frame") = "ras", py::arg("tool") = "tool", py::arg("cloud") = "cloud",
       py::arg("segmentation") = "segmentation", py::arg("record") = py::none(), py::arg("surface_cell_size") = live::ServeOptions{}.surface_cell_size,
       py::arg("once") = false, py::arg("parameters") = py::none(), py::arg("settings") = py::none(),
       "Serves a body model over OpenIGTLink as `physreg serve` does (the same library session): model, a folder made by `physreg prepare`, "
       "or dataset, a phantom dataset prepared at start; port (1-65535) to listen on bind (loopback by default), or client='HOST:PORT' to "
       "connect to a PlusServer. Each TRANSFORM named `tool` moves the model (answers: POLYDATA per organ surface, POINT 'targets'); "
       "POLYDATA `cloud` and IMAGE `segmentation` are registered in the background. frame: 'ras' (Slicer's) or 'lps' on the wire; "
       "record: a file of every message (physreg replay reads it); once: stop when the first client leaves. settings / keyword "
       "arguments: physreg.settings_spec('register-compression') keys. Blocks until the session ends; Ctrl-C stops it cleanly "
       "(KeyboardInterrupt). physreg.Error for impossible options or a model that cannot be read.");

    py::class_<live::LiveClient>(m, "LiveClient",
                                 "A client of physreg serve, as a tracker and a display are: tool poses out, the model's answers in. "
                                 "Positions are mm in LPS whatever the wire's frame.")
        .def(py::init<const std::string&, const std::string&>(), py::arg("address"), py::arg("frame") = "ras",
             "Connects to address 'HOST:PORT'; frame: the server's --frame (ras or lps). physreg.Error when it cannot connect.")
        .def("send_pose", [](live::LiveClient& c, const std::array<double, 3>& position, const std::string& device, std::uint64_t timestamp) {
            return c.send_pose(Vec3(position[0], position[1], position[2]), device, timestamp);
        }, py::arg("position_mm"), py::arg("device") = "tool", py::arg("timestamp") = 0,
             "Sends the tool's position (x, y, z) mm LPS as a TRANSFORM; timestamp 0: the next pose number in whole seconds (32.32 "
             "fixed point, as OpenIGTLink's). Returns the timestamp sent; the answers carry it.")
        .def("read", [](live::LiveClient& c, double timeout_s) -> py::object {
            std::optional<live::LiveMessage> message;
            {
                py::gil_scoped_release release;
                message = c.read(timeout_s);
            }
            if (!message) return py::none();
            py::dict d;
            d["type"] = message->type;
            d["device"] = message->device;
            d["timestamp"] = message->timestamp;
            py::array_t<double> points({static_cast<py::ssize_t>(message->points.size()), py::ssize_t{3}});
            auto p = points.mutable_unchecked<2>();
            for (std::size_t i = 0; i < message->points.size(); ++i)
                for (int k = 0; k < 3; ++k) p(static_cast<py::ssize_t>(i), k) = message->points[i][k];
            d["points"] = points;
            d["names"] = message->names;
            d["text"] = message->text;
            return d;
        }, py::arg("timeout_s") = 1.0,
             "The next message as a dict {type, device, timestamp, points: (N, 3) float64 mm LPS (POLYDATA vertices, POINT positions), "
             "names (POINT), text (STATUS, STRING)}, or None when none arrives within timeout_s. physreg.Error when the server has closed "
             "the connection.");
}

} // namespace physreg::python
