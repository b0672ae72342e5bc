// SPDX-License-Identifier: GPL-3.0-or-later
// physreg serve (issue 44): the three papers live over OpenIGTLink. A TCP server that a tracker or a
// navigation display (3D Slicer's OpenIGTLinkIF, PLUS) connects to, or with --client a client of a
// PlusServer: each TRANSFORM named after the tool moves the body model by condensed contact (the
// latest pose wins, stale ones are dropped), and the answer goes back as POLYDATA per organ surface
// (fixed topology, point scalar displacement_mm) and POINT for the targets, stamped with the
// input's timestamp. A POLYDATA named after the cloud is registered by paper 001's pipeline, an
// IMAGE named after the segmentation (labels) by paper 002's, in the background while tool updates
// go on; their answers are POLYDATA liver_registered / <organ>_segmentation and POINT
// targets_registered / targets_segmentation. STRING CMD_<id> (PLUS's command form, XML body with
// Name="…") is answered ACK_<id>: status, reset. STATUS is ignored, unknown types are skipped by
// their body size. Headers of version 1 and 2 are read here (the 1.11 library cannot unpack
// version 2, which Slicer sends); answers use version 1, packed by Debian's libopenigtlink.
#include "cli_support.hpp"
#include "igtl_wire.hpp"
#include "physreg/field/field_mapping.hpp"
#include "physreg/registration/images/image_registration.hpp"
#include "settings_options.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/dataset.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/surface/partial_surface_registration.hpp"
#include "physreg/registration/surface/surface_model.hpp"

#include <igtlPointMessage.h>
#include <igtlPolyDataMessage.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <future>
#include <fstream>
#include <iostream>
#include <map>
#include <set>

namespace physreg::cli {
namespace {

/// The surfaces a display shows: per organ the faces of its cells that border other tissue or
/// nothing, with their nodes.
struct OrganSurface {
    std::string name;
    std::vector<std::int32_t> nodes;                    ///< model node per surface point
    std::vector<std::vector<std::uint32_t>> polygons;   ///< surface point indices
};

std::vector<OrganSurface> organ_surfaces(const LiverModel& model, const LabelRoles& roles)
{
    std::vector<std::pair<std::string, std::set<std::int32_t>>> organs;
    std::set<std::int32_t> liver(roles.liver.begin(), roles.liver.end());
    liver.insert(roles.lesion.begin(), roles.lesion.end());
    liver.insert(roles.vessel.begin(), roles.vessel.end());
    organs.push_back({"liver", liver});
    if (!roles.lesion.empty()) organs.push_back({"tumours", roles.lesion});
    if (!roles.vessel.empty()) organs.push_back({"vessels", roles.vessel});
    const auto faces = match_faces(model.mesh);
    std::vector<OrganSurface> out;
    for (const auto& [name, labels] : organs) {
        OrganSurface s{name, {}, {}};
        std::map<std::int32_t, std::uint32_t> index;
        for (const auto& f : faces) {
            const bool inside = labels.count(model.mesh.cell_labels[f.cell]) > 0;
            const bool other = f.neighbour < 0 || labels.count(model.mesh.cell_labels[f.neighbour]) == 0;
            if (!inside || !other) continue;
            std::vector<std::uint32_t> polygon;
            for (int k = 0; k < f.node_count(); ++k) {
                const auto [it, added] = index.emplace(f.nodes[k], static_cast<std::uint32_t>(s.nodes.size()));
                if (added) s.nodes.push_back(f.nodes[k]);
                polygon.push_back(it->second);
            }
            s.polygons.push_back(std::move(polygon));
        }
        if (!s.polygons.empty()) out.push_back(std::move(s));
    }
    return out;
}

void send_message(int fd, igtl::MessageBase* m)
{
    m->Pack();
    if (!send_all(fd, m->GetPackPointer(), static_cast<std::size_t>(m->GetPackSize()))) fail("OpenIGTLink: the client went away while answering");
}

void stamp(igtl::MessageBase* m, std::uint64_t timestamp)
{
    m->SetTimeStamp(static_cast<unsigned int>(timestamp >> 32), static_cast<unsigned int>(timestamp & 0xffffffffu));
}

/// An organ's surface at displacement u (3 per node, mm) as POLYDATA: its nodes moved, its faces,
/// and the point scalar displacement_mm; `wire` −1 writes RAS.
igtl::PolyDataMessage::Pointer organ_surface_message(const OrganSurface& surface, const LiverModel& model, const std::vector<double>& u, double wire,
                                                     const std::string& name = "")
{
    auto points = igtl::PolyDataPointArray::New();
    auto polygons = igtl::PolyDataCellArray::New();
    auto magnitude = igtl::PolyDataAttribute::New();
    std::vector<igtlFloat32> values;
    for (const auto n : surface.nodes) {
        const Vec3 d(u[3 * n], u[3 * n + 1], u[3 * n + 2]);
        const Vec3 x = model.mesh.nodes[n] + d;
        points->AddPoint(static_cast<igtlFloat32>(wire * x[0]), static_cast<igtlFloat32>(wire * x[1]), static_cast<igtlFloat32>(x[2]));
        values.push_back(static_cast<igtlFloat32>(d.norm()));
    }
    for (auto polygon : surface.polygons) polygons->AddCell(static_cast<int>(polygon.size()), polygon.data());
    magnitude->SetType(igtl::PolyDataAttribute::POINT_SCALAR);
    magnitude->SetName("displacement_mm");
    magnitude->SetSize(static_cast<igtlUint32>(values.size()));
    magnitude->SetData(values.data());
    auto reply = igtl::PolyDataMessage::New();
    reply->SetDeviceName((name.empty() ? surface.name : name).c_str());
    reply->SetPoints(points);
    reply->SetPolygons(polygons);
    reply->AddAttribute(magnitude);
    return reply;
}

/// Paper 001's registered liver surface (the surface model's triangles at displacement u) as POLYDATA liver_registered.
igtl::PolyDataMessage::Pointer registered_surface_message(const SurfaceModel& surface_model, const std::vector<double>& u, double wire)
{
    auto points = igtl::PolyDataPointArray::New();
    auto polygons = igtl::PolyDataCellArray::New();
    std::map<std::int32_t, std::uint32_t> index;
    for (const auto& t : surface_model.surface.triangles) {
        igtlUint32 cell[3];
        for (int k = 0; k < 3; ++k) {
            const std::int32_t n = t[k];
            const auto [it, added] = index.emplace(n, static_cast<std::uint32_t>(index.size()));
            if (added) {
                const Vec3 x = surface_model.mesh.nodes[n] + Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]);
                points->AddPoint(static_cast<igtlFloat32>(wire * x[0]), static_cast<igtlFloat32>(wire * x[1]), static_cast<igtlFloat32>(x[2]));
            }
            cell[k] = it->second;
        }
        polygons->AddCell(3, cell);
    }
    auto message = igtl::PolyDataMessage::New();
    message->SetDeviceName("liver_registered");
    message->SetPoints(points);
    message->SetPolygons(polygons);
    return message;
}

/// Landmarks as a POINT message named `device` (with their types as group names when asked).
igtl::PointMessage::Pointer points_message(const std::string& device, const LandmarkSet& landmarks, double wire, bool with_groups)
{
    auto message = igtl::PointMessage::New();
    message->SetDeviceName(device.c_str());
    for (const auto& l : landmarks) {
        auto e = igtl::PointElement::New();
        e->SetName(l.name.c_str());
        if (with_groups) e->SetGroupName(to_string(l.type).c_str());
        e->SetPosition(static_cast<igtlFloat32>(wire * l.position[0]), static_cast<igtlFloat32>(wire * l.position[1]), static_cast<igtlFloat32>(l.position[2]));
        message->AddPointElement(e);
    }
    return message;
}

/// A refused input said on the wire: STATUS (configuration error) naming the device and the reason.
igtl::StatusMessage::Pointer error_status_message(const std::string& device, const std::string& reason)
{
    auto status = igtl::StatusMessage::New();
    status->SetDeviceName(device.c_str());
    status->SetCode(igtl::StatusMessage::STATUS_CONFIG_ERROR);
    status->SetErrorName("registration");
    status->SetStatusString(reason.c_str());
    return status;
}

/// What a background registration sends back (its input's timestamp is stamped on when sent).
struct BackgroundAnswer {
    std::vector<igtl::MessageBase::Pointer> messages;
    std::string note; ///< for the log
};

/// Paper 002 for a segmentation that came over the wire: the subject's rest labels (moving) against
/// it (fixed), the organs as structures, the labels standing in for the intensities (the wire
/// carries none), register-images' defaults (posterior held: the subject is in a patient frame)
/// without baselines.
ImageRegistrationResult register_segmentation_pair(const CompressionSubject& subject, const LabelVolume& labels, const std::string& device)
{
    const auto as_image = [](const LabelVolume& v) { return ScalarImage{v.geometry, std::vector<float>(v.labels.begin(), v.labels.end())}; };
    ImagePair pair;
    pair.moving_labels = subject.labels;
    pair.fixed_labels = labels;
    pair.moving = as_image(subject.labels);
    pair.fixed = as_image(labels);
    std::set<std::int32_t> present;
    for (const auto l : subject.labels.labels) present.insert(l);
    for (const auto* role : {&subject.roles.liver, &subject.roles.lesion, &subject.roles.vessel, &subject.roles.kidney})
        for (const auto l : *role)
            if (present.count(l)) pair.default_structures.push_back(l);
    std::sort(pair.default_structures.begin(), pair.default_structures.end());
    pair.auto_hold = "posterior";
    pair.description = {{"moving", "the served subject's rest labels"}, {"fixed", "OpenIGTLink IMAGE '" + device + "'"}};
    ImageRegistrationSettings settings;
    settings.baselines = "none";
    return register_images(pair, settings);
}

/// Each listed node's displacement from its rest position (pre-operative) to the intra-operative
/// image, through the inverse of `field` (intra-operative → pre-operative), 3 per model node (zero elsewhere).
std::vector<double> displacement_through_inverse(const DisplacementField& field, const std::vector<Vec3>& rest, const std::vector<std::int32_t>& nodes)
{
    std::vector<double> u(3 * rest.size(), 0.0);
    for (const auto n : nodes) {
        Vec3 y;
        invert_field_at(field, rest[static_cast<std::size_t>(n)], y);
        for (int a = 0; a < 3; ++a) u[3 * static_cast<std::size_t>(n) + a] = y[a] - rest[static_cast<std::size_t>(n)][a];
    }
    return u;
}

/// The mean Dice of a method over the structures, as its summary reports them.
std::string mean_dice(const ImageRegistrationResult& r, const std::string& method)
{
    const auto& dice = r.summary.at("methods").at(method).at("dice");
    double sum = 0.0;
    for (const auto& [label, value] : dice.items()) sum += value.get<double>();
    return dice.empty() ? std::string("-") : fmt::format("{:.3f}", sum / static_cast<double>(dice.size()));
}

/// The attribute value Name="…" of a PLUS command's XML body ("" when absent).
std::string xml_attribute(const std::string& xml, const std::string& attribute)
{
    const auto at = xml.find(attribute + "=\"");
    if (at == std::string::npos) return "";
    const auto begin = at + attribute.size() + 2, end = xml.find('"', begin);
    return end == std::string::npos ? "" : xml.substr(begin, end - begin);
}

} // namespace

void add_subcommand_serve(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string dataset, parameters, host = "127.0.0.1", frame = "ras", tool = "tool", record, cloud = "cloud", client, segmentation = "segmentation";
        int port = 0;
        double surface_cell_size = PartialSurfaceSettings{}.cell_size;
        bool once = false;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("serve", "Paper 000 live over OpenIGTLink: tool poses (TRANSFORM) in, the body model's organ surfaces "
                                            "(POLYDATA) and targets (POINT) out, by condensed contact");
    sub->add_option("--dataset", o->dataset, "Phantom dataset: the body at rest, its landmarks, the tool and the session's paths")->required();
    sub->add_option("--parameters", o->parameters, "Parameter file from physreg estimate (else the model settings)");
    auto settings = std::make_shared<SettingsOptions<CompressionRegistrationSettings>>(sub, compression_spec());
    sub->add_option("--port", o->port, "TCP port to listen on (Slicer and PLUS default to 18944; give it only when asked)");
    sub->add_option("--client", o->client, "Client mode: connect to HOST:PORT (a PlusServer streaming the tracker's poses) instead of listening; "
                                           "the session ends when that server closes the connection");
    sub->add_option("--host", o->host, "Address to listen on (default 127.0.0.1; 0.0.0.0 for every interface)");
    sub->add_option("--frame", o->frame, "Coordinates on the wire: ras (3D Slicer's, default) or lps (the images')");
    sub->add_option("--tool", o->tool, "Device name of the tool's TRANSFORM (default 'tool'); other transforms are ignored");
    sub->add_option("--record", o->record, "Write every message in and out (type, device, timestamp, wall time; the bytes of those in) as JSON "
                                           "lines: physreg replay sends such a session again");
    sub->add_option("--cloud", o->cloud, "Device name of the intra-operative clouds (POLYDATA points; default 'cloud'): each one is registered by "
                                         "paper 001's pipeline in the background while tool updates go on, the latest cloud winning");
    sub->add_option("--segmentation", o->segmentation, "Device name of intra-operative segmentations (IMAGE, 8- or 16-bit labels as the "
                                                       "dataset's): each is registered by paper 002's pipeline in the background (default 'segmentation'); "
                                                       "the organ surfaces and targets come back as <organ>_segmentation and targets_segmentation");
    sub->add_option("--surface-cell-size", o->surface_cell_size, "Paper 001's tetrahedral liver model for clouds: largest circumradius, mm (default 7)");
    sub->add_flag("--once", o->once, "Stop when the first client disconnects (tests, scripts)");
    sub->callback([o, settings] {
        if (o->client.empty() == (o->port == 0)) fail("serve: give --port (listen) or --client HOST:PORT (connect to a PlusServer), not both");
        const bool client_mode = !o->client.empty();
        if (client_mode && o->client.rfind(':') == std::string::npos) fail("--client '{}': give HOST:PORT", o->client);
        if (!client_mode && (o->port < 1 || o->port > 65535)) fail("--port {} must lie in 1 … 65535", o->port);
        if (o->frame != "ras" && o->frame != "lps") fail("--frame '{}': use ras or lps", o->frame);
        const CompressionRegistrationSettings s = settings->resolve();
        validate(s, SettingNaming::option);
        const auto t0 = std::chrono::steady_clock::now();
        const PhantomDataset dataset = read_phantom_dataset(o->dataset);
        const CompressionSubject subject = read_dataset_compression_subject(o->dataset, s, o->parameters);
        const LiverModel& model = subject.model;
        std::vector<Indenter> session_tools;
        for (const auto& st : dataset.states)
            if (st.tool && st.kind == "compression") session_tools.push_back(*st.tool);
        if (session_tools.empty()) fail("serve: dataset '{}' has no tool compression (the tool's shape and the session's paths)", o->dataset);
        const Indenter tool_shape = session_tools.front();
        // The nodes each update returns: every organ surface's, and those the targets read.
        const auto surfaces = organ_surfaces(model, subject.roles);
        std::set<std::int32_t> wanted;
        for (const auto& surface : surfaces) wanted.insert(surface.nodes.begin(), surface.nodes.end());
        std::vector<Vec3> targets;
        for (const auto& l : subject.rest_landmarks) targets.push_back(l.position);
        for (const auto n : nodes_near(model.mesh, targets, 2.0 * model.cell_size_mm.maxCoeff())) wanted.insert(n);
        CondensedContactOptions condensed_options;
        condensed_options.memory_limit_bytes = s.memory_limit_bytes();
        CondensedContactModel condensed(model, session_tools, std::vector<std::int32_t>(wanted.begin(), wanted.end()), condensed_options);
        std::vector<std::int64_t> query_index(model.mesh.node_count(), -1);
        for (std::size_t i = 0; i < condensed.query_nodes().size(); ++i) query_index[condensed.query_nodes()[i]] = static_cast<std::int64_t>(i);
        const double ready_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        const double wire = o->frame == "ras" ? -1.0 : 1.0; // RAS ↔ LPS: x and y change sign

        const int yes = 1;
        Descriptor listener(client_mode ? -1 : ::socket(AF_INET, SOCK_STREAM, 0));
        if (!client_mode) {
            if (listener.get() < 0) fail("serve: cannot open a socket: {}", std::strerror(errno));
            ::setsockopt(listener.get(), SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
            sockaddr_in address{};
            address.sin_family = AF_INET;
            address.sin_port = htons(static_cast<std::uint16_t>(o->port));
            if (::inet_pton(AF_INET, o->host.c_str(), &address.sin_addr) != 1) fail("--host '{}' is not an IPv4 address", o->host);
            if (::bind(listener.get(), reinterpret_cast<sockaddr*>(&address), sizeof address) != 0)
                fail("--port {}: cannot listen on {}:{}: {}", o->port, o->host, o->port, std::strerror(errno));
            ::listen(listener.get(), 1);
        }
        std::ofstream record;
        if (!o->record.empty()) {
            record.open(o->record);
            if (!record) fail("--record '{}': cannot write", o->record);
        }
        // One JSON line per message; what came in with its bytes (hex), so that `physreg replay` can
        // send the session again at its own pace.
        const auto log_message = [&](const char* direction, const std::string& type, const std::string& device, std::uint64_t timestamp,
                                     const std::vector<std::uint8_t>* raw = nullptr) {
            if (!record) return;
            const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            nlohmann::json line{{"direction", direction}, {"type", type}, {"device", device}, {"timestamp", timestamp}, {"wall_s", wall}};
            if (raw) line["bytes_hex"] = to_hex(*raw);
            record << line.dump() << "\n";
            record.flush();
        };
        const std::string where = client_mode ? fmt::format("connecting to {}", o->client) : fmt::format("listening on {}:{}", o->host, o->port);
        logger()->info("serve: model {} nodes, {} candidate skin nodes, {} surface and target nodes; ready in {:.1f} s, {} ({} frame)",
                       model.mesh.node_count(), condensed.precomputation().candidate_nodes, condensed.query_nodes().size(), ready_s, where, o->frame);
        std::cerr << fmt::format("serve: {}\n", where) << std::flush;
        int updates = 0;
        // Clouds (paper 001) and segmentations (paper 002) are registered in the background, one at a
        // time, while tool updates go on; the latest input waiting replaces older ones. A job returns
        // the messages to send (stamped with its input's timestamp when done).
        PartialSurfaceSettings surface_settings;
        surface_settings.cell_size = o->surface_cell_size;
        validate(surface_settings, SettingNaming::option);
        std::optional<SurfaceModel> surface_model; // meshed at the first cloud
        struct Job {
            std::function<BackgroundAnswer()> run;
            std::string device;
            std::uint64_t timestamp = 0;
        };
        std::future<BackgroundAnswer> running;
        Job running_job;
        std::optional<Job> waiting;
        const auto start_job = [&](Job job) {
            running_job = std::move(job);
            running = std::async(std::launch::async, running_job.run);
        };
        const auto cloud_job = [&](LabelledPointCloud cloud) {
            return [&, cloud = std::move(cloud)]() {
                if (!surface_model) {
                    std::set<std::int32_t> liver(subject.roles.liver.begin(), subject.roles.liver.end());
                    liver.insert(subject.roles.lesion.begin(), subject.roles.lesion.end());
                    liver.insert(subject.roles.vessel.begin(), subject.roles.vessel.end());
                    // No notch region: the wire's clouds are unlabelled, and every triangle is "surface" to them.
                    surface_model = surface_model_from_labels(subject.labels, liver, surface_settings.cell_size, std::nullopt,
                                                              static_cast<unsigned>(surface_settings.seed), "serve: the liver model for clouds");
                }
                PartialSurfaceCase c;
                c.mesh = surface_model->mesh;
                c.surface = surface_model->surface;
                c.quality = surface_model->quality;
                c.cloud = cloud;
                c.patient_frame = true; // meshed from the subject's label volume
                c.landmarks = subject.rest_landmarks;
                const PartialSurfaceResult r = register_partial_surface(c, surface_settings);
                BackgroundAnswer answer;
                answer.messages.push_back(registered_surface_message(*surface_model, r.chosen_method().displacement_mm, wire).GetPointer());
                answer.messages.push_back(points_message("targets_registered", *r.landmarks, wire, false).GetPointer());
                answer.note = fmt::format("cloud registered ({}; {})", r.chosen_method().name, r.safeguard.statement);
                return answer;
            };
        };
        const auto segmentation_job = [&](LabelVolume labels) {
            return [&, labels = std::move(labels)]() {
                const ImageRegistrationResult r = register_segmentation_pair(subject, labels, o->segmentation);
                const DisplacementField& field = r.chosen_method().field; // intra-operative → pre-operative (the subject's rest)
                BackgroundAnswer answer;
                for (const auto& surface : surfaces)
                    answer.messages.push_back(organ_surface_message(surface, model, displacement_through_inverse(field, model.mesh.nodes, surface.nodes), wire,
                                                                    surface.name + "_segmentation").GetPointer());
                LandmarkSet targets = subject.rest_landmarks;
                for (auto& l : targets) invert_field_at(field, Vec3(l.position), l.position);
                answer.messages.push_back(points_message("targets_segmentation", targets, wire, true).GetPointer());
                answer.note = fmt::format("segmentation registered ({}; mean Dice {})", r.chosen_method().name, mean_dice(r, r.chosen_method().name));
                return answer;
            };
        };
        do {
            Descriptor client(client_mode ? connect_to(o->client, "--client") : ::accept(listener.get(), nullptr, nullptr));
            if (client.get() < 0) fail("serve: accept failed: {}", std::strerror(errno));
            ::setsockopt(client.get(), IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
            logger()->info(client_mode ? "serve: connected to the server" : "serve: a client connected");
            std::optional<IgtlMessage> pending; // read while dropping stale poses, not answered yet
            while (true) {
                if (running.valid() && running.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
                    // A registration is done: its answer goes out with its input's timestamp.
                    try {
                        const BackgroundAnswer answer = running.get();
                        for (const auto& m : answer.messages) {
                            stamp(m, running_job.timestamp);
                            send_message(client.get(), m);
                            log_message("out", m->GetDeviceType(), m->GetDeviceName(), running_job.timestamp);
                        }
                        logger()->info("serve: {}", answer.note);
                    } catch (const Error& e) {
                        // An input the pipeline refuses is the client's bad input: said on the wire, the session goes on.
                        auto status = error_status_message(running_job.device, e.what());
                        stamp(status, running_job.timestamp);
                        send_message(client.get(), status);
                        log_message("out", "STATUS", running_job.device, running_job.timestamp);
                        logger()->warn("serve: {} refused: {}", running_job.device, e.what());
                    }
                    if (waiting) {
                        start_job(std::move(*waiting));
                        waiting.reset();
                    }
                }
                if (!pending && !more_waiting(client.get(), running.valid() ? 50 : -1)) continue;
                auto message = pending ? std::move(pending) : read_igtl_message(client.get());
                pending.reset();
                if (!message) break;
                log_message("in", message->type, message->device, message->timestamp, &message->raw);
                if (message->type == "TRANSFORM" && message->device == o->tool) {
                    // The latest pose wins: poses queued behind this one replace it unanswered.
                    int dropped = 0;
                    while (more_waiting(client.get())) {
                        auto next = read_igtl_message(client.get());
                        if (!next) break;
                        if (next->type != "TRANSFORM" || next->device != o->tool) {
                            pending = std::move(next); // answered after this pose, in order
                            break;
                        }
                        log_message("in", next->type, next->device, next->timestamp, &next->raw);
                        message = std::move(next);
                        ++dropped;
                    }
                    if (message->content.size() < 48) fail("OpenIGTLink: TRANSFORM '{}' holds {} bytes, not 48", message->device, message->content.size());
                    const Vec3 position(wire * read_float_be(message->content.data() + 36), wire * read_float_be(message->content.data() + 40),
                                        read_float_be(message->content.data() + 44));
                    const auto started = std::chrono::steady_clock::now();
                    const auto update = condensed.move_to(tool_shape, position);
                    const std::vector<double> u = condensed.query_field_mm();
                    const LandmarkSet moved = move_landmarks(model, u, subject.rest_landmarks);
                    for (const auto& surface : surfaces) {
                        auto reply = organ_surface_message(surface, model, u, wire);
                        stamp(reply, message->timestamp);
                        send_message(client.get(), reply);
                        log_message("out", "POLYDATA", surface.name, message->timestamp);
                    }
                    auto targets_message = points_message("targets", moved, wire, true);
                    stamp(targets_message, message->timestamp);
                    send_message(client.get(), targets_message);
                    log_message("out", "POINT", "targets", message->timestamp);
                    ++updates;
                    logger()->debug("serve: update {} at ({:.1f}, {:.1f}, {:.1f}) mm LPS: {} nodes in contact, {:.2f} ms ({} stale poses dropped)", updates,
                                    position[0], position[1], position[2], update.active_nodes,
                                    std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - started).count(), dropped);
                } else if (message->type == "STRING" && message->device.rfind("CMD_", 0) == 0) {
                    const std::string xml = message->content.size() > 4 ? std::string(message->content.begin() + 4, message->content.end()) : "";
                    const std::string command = xml_attribute(xml, "Name");
                    std::string answer;
                    if (command == "reset") {
                        condensed.reset();
                        answer = "<Command Status=\"SUCCESS\" Message=\"the model is at rest\"/>";
                    } else if (command == "status") {
                        answer = fmt::format("<Command Status=\"SUCCESS\" Updates=\"{}\" Nodes=\"{}\" Frame=\"{}\"/>", updates, model.mesh.node_count(), o->frame);
                    } else {
                        answer = fmt::format("<Command Status=\"FAIL\" Message=\"unknown command '{}' (reset, status)\"/>", command);
                    }
                    auto ack = igtl::StringMessage::New();
                    ack->SetDeviceName(("ACK_" + message->device.substr(4)).c_str());
                    ack->SetString(answer.c_str());
                    stamp(ack, message->timestamp);
                    send_message(client.get(), ack);
                    log_message("out", "STRING", "ACK_" + message->device.substr(4), message->timestamp);
                } else if (message->type == "POLYDATA" && message->device == o->cloud) {
                    LabelledPointCloud cloud;
                    cloud.points = polydata_points(*message, wire);
                    cloud.labels.assign(cloud.points.size(), 0);
                    Job job{cloud_job(std::move(cloud)), o->cloud, message->timestamp};
                    if (running.valid()) waiting = std::move(job); // the latest waiting input wins
                    else start_job(std::move(job));
                } else if (message->type == "IMAGE" && message->device == o->segmentation) {
                    std::optional<LabelVolume> labels;
                    try {
                        labels = igtl_image_labels(*message);
                    } catch (const Error& e) {
                        // An image that is no segmentation (a grey-level frame sent under its name): said on the wire, the session goes on.
                        auto status = error_status_message(o->segmentation, e.what());
                        stamp(status, message->timestamp);
                        send_message(client.get(), status);
                        log_message("out", "STATUS", o->segmentation, message->timestamp);
                        logger()->warn("serve: {}", e.what());
                    }
                    if (labels) {
                        Job job{segmentation_job(std::move(*labels)), o->segmentation, message->timestamp};
                        if (running.valid()) waiting = std::move(job);
                        else start_job(std::move(job));
                    }
                }
                // STATUS (Slicer sends one on connecting), other devices and unknown types: skipped.
            }
            if (running.valid()) running.wait(); // a registration still running finishes before the next client
            running = {};
            waiting.reset();
            logger()->info("serve: the {} disconnected after {} updates", client_mode ? "server" : "client", updates);
        } while (!o->once && !client_mode); // a client session ends with its server's connection
    });
}

} // namespace physreg::cli
