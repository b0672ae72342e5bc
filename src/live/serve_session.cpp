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
// Name="…") is answered ACK_<id>: status, reset, and field (the dense displacement field as IMAGE). STATUS is ignored, unknown types are skipped by
// their body size. Headers of version 1 and 2 are read here (the 1.11 library cannot unpack
// version 2, which Slicer sends); answers use version 1, packed by Debian's libopenigtlink.
#include "physreg/live/serve.hpp"
#include "physreg/live/igtl_wire.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/field/field_mapping.hpp"
#include "physreg/registration/images/image_registration.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/dataset.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/prepared_model.hpp"
#include "physreg/registration/surface/partial_surface_registration.hpp"
#include "physreg/registration/surface/surface_model.hpp"

#include <igtlImageMessage.h>
#include <igtlPointMessage.h>
#include <igtlPolyDataMessage.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtl_util.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <deque>
#include <cmath>
#include <cstring>
#include <future>
#include <fstream>
#include <iostream>
#include <map>
#include <set>

namespace physreg::live {
namespace {

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
    pair.auto_hold = "none"; // as for datasets: no support assumed (docs/registration.md, paper 002's holds)
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

/// The displacement field of every node `u` (3 per node, mm) sampled on a grid over the mesh
/// (`spacing_mm`, `margin_mm` beyond it: register-compression's grid) as IMAGE "displacement": float32, 3 components (the displacement in the wire's
/// frame, mm; 0 outside the model), the wire's coordinate system, origin at the volume's centre.
igtl::ImageMessage::Pointer displacement_image_message(const VolumeMesh& mesh, const std::vector<double>& u, double spacing_mm, double margin_mm,
                                                       double wire)
{
    const ImageGeometry g = image_grid_over_mesh(mesh, spacing_mm, margin_mm);
    const SampledField f = sample_displacement_field(mesh, u, g);
    auto m = igtl::ImageMessage::New();
    m->SetDeviceName("displacement");
    m->SetDimensions(static_cast<int>(g.size[0]), static_cast<int>(g.size[1]), static_cast<int>(g.size[2]));
    m->SetSpacing(static_cast<float>(g.spacing[0]), static_cast<float>(g.spacing[1]), static_cast<float>(g.spacing[2]));
    m->SetScalarType(igtl::ImageMessage::TYPE_FLOAT32);
    m->SetNumComponents(3);
    m->SetEndian(igtl_is_little_endian() ? igtl::ImageMessage::ENDIAN_LITTLE : igtl::ImageMessage::ENDIAN_BIG); // the scalars go as they are in memory
    m->SetCoordinateSystem(wire < 0 ? igtl::ImageMessage::COORDINATE_RAS : igtl::ImageMessage::COORDINATE_LPS);
    Vec3 centre = g.origin;
    for (int a = 0; a < 3; ++a) centre += g.direction.col(a) * (g.spacing[a] * 0.5 * static_cast<double>(g.size[a] - 1));
    igtl::Matrix4x4 matrix;
    igtl::IdentityMatrix(matrix);
    for (int row = 0; row < 3; ++row) {
        const double flip = row < 2 ? wire : 1.0;
        for (int col = 0; col < 3; ++col) matrix[row][col] = static_cast<float>(flip * g.direction(row, col));
        matrix[row][3] = static_cast<float>(flip * centre[row]);
    }
    m->SetMatrix(matrix);
    m->AllocateScalars();
    // The scalars follow a 72-byte header in the message's buffer: not 4-byte aligned, so copied
    // byte-wise (a float store there is undefined behaviour; UBSan stops on it).
    auto* out = static_cast<unsigned char*>(m->GetScalarPointer());
    const auto& c = f.field.components;
    for (std::size_t v = 0; v < c.size() / 3; ++v) {
        const float xyz[3] = {static_cast<float>(wire * c[3 * v]), static_cast<float>(wire * c[3 * v + 1]), static_cast<float>(c[3 * v + 2])};
        std::memcpy(out + 12 * v, xyz, sizeof xyz);
    }
    return m;
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

namespace {


/// One connection: a tracker, a display (3D Slicer), a script, or the PlusServer in client mode.
/// What goes out waits in a bounded queue sent without blocking, so that a client that never reads
/// cannot hold up the others: a message that would overflow its queue is dropped and counted.
struct ServeClient {
    int id = 0;
    Descriptor fd;
    std::deque<std::vector<std::uint8_t>> outgoing;
    std::size_t queued_bytes = 0, front_sent = 0;
    std::uint64_t dropped_messages = 0;
    int warned_rotation = 0; ///< poses whose rotation was not rigid (said once)
    bool gone = false;
    explicit ServeClient(int i, int descriptor) : id(i), fd(descriptor) {}
};

/// One served model and the sessions on it: the body model with its condensed contact (paper 000),
/// the liver model for clouds (paper 001, stored by prepare or meshed at the first cloud) and the
/// registrations of clouds and segmentations (paper 002) that run in the background, one at a time
/// (the latest input waiting replaces older ones). Up to --max-clients connections at once: model
/// updates go to every client, answers to commands and refusals to the client that asked.
class ServeSession {
public:
    ServeSession(const ServeOptions& o, const CompressionRegistrationSettings& s);
    /// Listens (or connects, in client mode) and serves until the session ends (--once: the last
    /// client left; client mode: the server closed) or SIGINT/SIGTERM (then Interrupted).
    void run();

private:
    struct Job {
        std::function<BackgroundAnswer()> run;
        std::string device;
        std::uint64_t timestamp = 0;
        int client = 0; ///< who sent the input (its refusal goes there)
    };
    struct Pose {
        IgtlMessage message;
        int client = 0;
    };
    /// Reads what `c` has sent: poses into `latest` (an older one there is dropped), other messages
    /// handled in order (a pose waiting is answered first). A malformed stream: a STATUS to that
    /// client, its connection closed.
    void read_from(ServeClient& c, std::optional<Pose>& latest, int& dropped);
    void handle(ServeClient& c, const IgtlMessage& message);
    void answer_pose(const Pose& pose, int dropped);
    void answer_command(ServeClient& c, const IgtlMessage& message);
    /// Stamps, packs and queues `m` for one client (or every client), recorded once.
    void send_to(ServeClient& c, igtl::MessageBase* m, std::uint64_t timestamp);
    void broadcast(igtl::MessageBase* m, std::uint64_t timestamp);
    /// Model updates (`droppable`) are dropped past the queue's bound; answers to the client's own requests never are.
    void enqueue(ServeClient& c, const std::uint8_t* bytes, std::size_t n, bool droppable);
    /// Sends what the socket takes now, without blocking.
    void flush(ServeClient& c);
    ServeClient* client(int id);
    /// One JSON line per message in --record; what came in with its bytes (hex), so that `physreg
    /// replay` can send the session again at its own pace.
    void record(const char* direction, const std::string& type, const std::string& device, std::uint64_t timestamp,
                const std::vector<std::uint8_t>* raw = nullptr);
    void queue(Job job);
    /// A finished background registration's answer sent (or its refusal as a STATUS), the next one started.
    void deliver_background();
    BackgroundAnswer register_cloud(const LabelledPointCloud& cloud);
    BackgroundAnswer register_segmentation(const LabelVolume& labels);

    const ServeOptions& m_o;
    const bool m_client_mode;
    const double m_wire; ///< −1: RAS on the wire (x and y change sign), 1: LPS
    std::chrono::steady_clock::time_point m_t0;
    std::unique_ptr<PreparedBodyModel> m_prepared; // a prepared model read, or one made from --dataset at start
    const CompressionSubject& m_subject;
    const std::vector<OrganSurface>& m_surfaces;
    Indenter m_tool_shape;
    CondensedContactModel* m_condensed = nullptr;
    double m_ready_s = 0.0;
    std::ofstream m_record;
    int m_updates = 0;
    double m_field_spacing = 1.0; ///< --field-spacing, mm: the field sent on request
    PartialSurfaceSettings m_surface_settings;
    std::optional<SurfaceModel>& m_surface_model; // stored by prepare, or meshed at the first cloud
    std::future<BackgroundAnswer> m_running;
    Job m_running_job;
    std::optional<Job> m_waiting;
    std::vector<std::unique_ptr<ServeClient>> m_clients;
    int m_next_client = 1;
    std::uint64_t m_dropped_messages = 0, m_dropped_poses = 0;
};

/// The served model: read from a prepared folder, or prepared now from a phantom dataset.
std::unique_ptr<PreparedBodyModel> served_model(const ServeOptions& o, const CompressionRegistrationSettings& s)
{
    CondensedContactOptions condensed_options;
    condensed_options.memory_limit_bytes = s.memory_limit_bytes();
    if (!o.model.empty()) {
        if (const auto set = s.model_keys_set(); !set.empty() || !o.parameters.empty())
            fail("serve: the prepared model '{}' fixes the model; drop {} (prepare it again to change them)", o.model,
                 o.parameters.empty() ? fmt::format("{}", fmt::join(set, ", ")) : std::string("--parameters"));
        return read_prepared_model(o.model, condensed_options);
    }
    std::vector<Indenter> session_tools = dataset_session_tools(o.dataset);
    PreparedModelOptions options;
    options.condensed = condensed_options;
    options.surface_cell_size_mm = 0.0; // meshed at the first cloud
    return prepare_body_model(read_dataset_compression_subject(o.dataset, s, o.parameters), std::move(session_tools), options);
}

ServeSession::ServeSession(const ServeOptions& o, const CompressionRegistrationSettings& s)
    : m_o(o), m_client_mode(!o.client.empty()), m_wire(o.frame == "ras" ? -1.0 : 1.0), m_t0(std::chrono::steady_clock::now()),
      m_prepared(served_model(o, s)), m_subject(m_prepared->subject), m_surfaces(m_prepared->surfaces), m_tool_shape(m_prepared->session_tools.front()),
      m_condensed(m_prepared->condensed.get()), m_surface_model(m_prepared->surface_model)
{
    m_ready_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - m_t0).count();
    if (!o.record.empty()) {
        m_record.open(o.record);
        if (!m_record) fail("--record '{}': cannot write", o.record);
    }
    m_surface_settings.cell_size = o.surface_cell_size;
    validate(m_surface_settings, SettingNaming::option);
    m_field_spacing = s.field_spacing;
}

void ServeSession::run()
{
    const int yes = 1;
    Descriptor listener(m_client_mode ? -1 : ::socket(AF_INET, SOCK_STREAM, 0));
    if (!m_client_mode) {
        if (listener.get() < 0) fail("serve: cannot open a socket: {}", std::strerror(errno));
        ::setsockopt(listener.get(), SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
        sockaddr_in address{};
        address.sin_family = AF_INET;
        address.sin_port = htons(static_cast<std::uint16_t>(m_o.port));
        if (::inet_pton(AF_INET, m_o.host.c_str(), &address.sin_addr) != 1) fail("--bind '{}' is not an IPv4 address", m_o.host);
        if (::bind(listener.get(), reinterpret_cast<sockaddr*>(&address), sizeof address) != 0)
            fail("--port {}: cannot listen on {}:{}: {}", m_o.port, m_o.host, m_o.port, std::strerror(errno));
        ::listen(listener.get(), 8);
    }
    const bool loopback = m_o.host.rfind("127.", 0) == 0;
    const std::string where = m_client_mode ? fmt::format("connecting to {}", m_o.client) : fmt::format("listening on {}:{}", m_o.host, m_o.port);
    logger()->info("serve: model {} nodes, {} candidate skin nodes, {} surface and target nodes; ready in {:.1f} s, {} ({} frame, up to {} clients)",
                   m_subject.model.mesh.node_count(), m_condensed->precomputation().candidate_nodes, m_condensed->query_nodes().size(), m_ready_s, where,
                   m_o.frame, m_o.max_clients);
    if (!m_client_mode && loopback)
        logger()->info("serve: bound to the loopback address {}: only programs on this machine can connect (OpenIGTLink has no authentication)", m_o.host);
    else if (!m_client_mode)
        logger()->warn("serve: bound to {}: anyone who reaches this port can send poses and read the model (OpenIGTLink has no authentication or "
                       "encryption)", m_o.host);
    std::cerr << fmt::format("serve: {}\n", where) << std::flush;
    if (m_client_mode) {
        const int fd = connect_to(m_o.client, "--client");
        m_clients.push_back(std::make_unique<ServeClient>(m_next_client++, fd));
        logger()->info("serve: connected to the server");
    }
    bool had_client = m_client_mode;
    while (true) {
        if (const int signal = interrupt_signal(); signal != 0) {
            // Stop accepting, finish what is in flight (the update in flight already finished: updates run on this thread), close cleanly.
            logger()->info("serve: stopping on signal {} after {} updates; {} client(s) closed", signal, m_updates, m_clients.size());
            if (m_running.valid()) m_running.wait();
            for (auto& c : m_clients) flush(*c);
            m_clients.clear();
            throw_if_interrupted();
        }
        if (m_o.stop_requested && m_o.stop_requested()) {
            logger()->info("serve: stopping as asked after {} updates; {} client(s) closed", m_updates, m_clients.size());
            if (m_running.valid()) m_running.wait();
            for (auto& c : m_clients) flush(*c);
            m_clients.clear();
            return;
        }
        if (m_running.valid() && m_running.wait_for(std::chrono::seconds(0)) == std::future_status::ready) deliver_background();
        std::vector<pollfd> fds;
        if (!m_client_mode) fds.push_back({listener.get(), POLLIN, 0});
        for (const auto& c : m_clients) fds.push_back({c->fd.get(), static_cast<short>(POLLIN | (c->outgoing.empty() ? 0 : POLLOUT)), 0});
        if (::poll(fds.data(), fds.size(), m_running.valid() ? 20 : 100) < 0 && errno != EINTR) fail("serve: poll failed: {}", std::strerror(errno));
        std::size_t at = 0;
        if (!m_client_mode && (fds[at++].revents & POLLIN)) {
            const int fd = ::accept(listener.get(), nullptr, nullptr);
            if (fd >= 0) {
                ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
                timeval stall{5, 0}; // a message started and not finished within 5 s ends that connection
                ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &stall, sizeof stall);
                auto c = std::make_unique<ServeClient>(m_next_client++, fd);
                if (static_cast<int>(m_clients.size()) >= m_o.max_clients) {
                    auto status = error_status_message("serve", fmt::format("too many clients: {} connected (--max-clients {})", m_clients.size(), m_o.max_clients));
                    send_to(*c, status, 0);
                    flush(*c);
                    logger()->warn("serve: a client was refused: {} connected already (--max-clients {})", m_clients.size(), m_o.max_clients);
                } else {
                    logger()->info("serve: client {} connected ({} in all)", c->id, m_clients.size() + 1);
                    m_clients.push_back(std::move(c));
                    had_client = true;
                }
            }
        }
        std::optional<Pose> latest;
        int dropped = 0;
        const std::size_t polled = m_clients.size() < fds.size() - at ? m_clients.size() : fds.size() - at;
        for (std::size_t i = 0; i < polled; ++i) {
            ServeClient& c = *m_clients[i];
            if (fds[at + i].revents & POLLOUT) flush(c);
            if (!c.gone && (fds[at + i].revents & (POLLIN | POLLHUP | POLLERR))) read_from(c, latest, dropped);
        }
        if (latest) answer_pose(*latest, dropped);
        for (auto& c : m_clients) flush(*c);
        std::erase_if(m_clients, [&](const std::unique_ptr<ServeClient>& c) {
            if (!c->gone) return false;
            logger()->info("serve: client {} disconnected after {} updates ({} messages dropped for it)", c->id, m_updates, c->dropped_messages);
            return true;
        });
        if ((m_o.once || m_client_mode) && had_client && m_clients.empty()) break; // a client session ends with its server's connection
    }
    if (m_running.valid()) m_running.wait(); // a registration still running finishes before the session ends
    logger()->info("serve: session ended: {} updates, {} stale poses dropped, {} messages dropped for clients that did not read", m_updates,
                   m_dropped_poses, m_dropped_messages);
}

void ServeSession::read_from(ServeClient& c, std::optional<Pose>& latest, int& dropped)
{
    do {
        std::optional<IgtlMessage> message;
        try {
            message = read_igtl_message(c.fd.get());
        } catch (const Error& e) {
            // A malformed stream: said to that client, its connection closed; the others go on.
            send_to(c, error_status_message("serve", e.what()), 0);
            flush(c);
            logger()->warn("serve: client {}: {}; its connection is closed", c.id, e.what());
            c.gone = true;
            return;
        }
        if (!message) {
            c.gone = true;
            return;
        }
        record("in", message->type, message->device, message->timestamp, &message->raw);
        if (message->type == "TRANSFORM" && message->device == m_o.tool) {
            if (latest) ++dropped; // the latest pose wins: an older one waiting is dropped unanswered
            latest = Pose{std::move(*message), c.id};
            continue;
        }
        if (latest) { // answered in order: the pose that came first
            answer_pose(*latest, dropped);
            latest.reset();
            dropped = 0;
        }
        handle(c, *message);
    } while (!c.gone && more_waiting(c.fd.get()));
}

void ServeSession::handle(ServeClient& c, const IgtlMessage& message)
{
    try {
        if (message.type == "STRING" && message.device.rfind("CMD_", 0) == 0) {
            answer_command(c, message);
        } else if (message.type == "GET_POLYDATA") {
            // OpenIGTLink's query: the current surface of the organ it names (the liver for any other name).
            const OrganSurface* surface = &m_surfaces.front();
            for (const auto& o : m_surfaces)
                if (o.name == message.device) surface = &o;
            send_to(c, organ_surface_message(*surface, m_subject.model, m_condensed->query_field_mm(), m_wire), message.timestamp);
        } else if (message.type == "POLYDATA" && message.device == m_o.cloud) {
            LabelledPointCloud cloud;
            cloud.points = polydata_points(message, m_wire);
            cloud.labels.assign(cloud.points.size(), 0);
            queue({[this, cloud = std::move(cloud)] { return register_cloud(cloud); }, m_o.cloud, message.timestamp, c.id});
        } else if (message.type == "IMAGE" && message.device == m_o.segmentation) {
            LabelVolume labels = igtl_image_labels(message);
            queue({[this, labels = std::move(labels)] { return register_segmentation(labels); }, m_o.segmentation, message.timestamp, c.id});
        }
        // STATUS (Slicer sends one on connecting), other devices and unknown types: skipped.
    } catch (const Error& e) {
        // A well-formed message whose content is refused (a grey-level IMAGE, a cloud of NaN): said on
        // the wire to its sender, and the session goes on.
        send_to(c, error_status_message(message.device, e.what()), message.timestamp);
        logger()->warn("serve: client {}: {}", c.id, e.what());
    }
}

ServeClient* ServeSession::client(int id)
{
    for (auto& c : m_clients)
        if (c->id == id && !c->gone) return c.get();
    return nullptr;
}

void ServeSession::send_to(ServeClient& c, igtl::MessageBase* m, std::uint64_t timestamp)
{
    stamp(m, timestamp);
    m->Pack();
    enqueue(c, static_cast<const std::uint8_t*>(m->GetPackPointer()), static_cast<std::size_t>(m->GetPackSize()), false);
    record("out", m->GetDeviceType(), m->GetDeviceName(), timestamp);
}

void ServeSession::broadcast(igtl::MessageBase* m, std::uint64_t timestamp)
{
    stamp(m, timestamp);
    m->Pack();
    for (auto& c : m_clients)
        if (!c->gone) enqueue(*c, static_cast<const std::uint8_t*>(m->GetPackPointer()), static_cast<std::size_t>(m->GetPackSize()), true);
    record("out", m->GetDeviceType(), m->GetDeviceName(), timestamp);
}

void ServeSession::enqueue(ServeClient& c, const std::uint8_t* bytes, std::size_t n, bool droppable)
{
    const auto limit = static_cast<std::size_t>(m_o.queue_mib * 1024.0 * 1024.0);
    if (droppable && c.queued_bytes + n > limit && !c.outgoing.empty()) {
        if (c.dropped_messages++ == 0) logger()->warn("serve: client {} does not read what it is sent: messages are dropped for it (--send-queue {} MiB)", c.id, m_o.queue_mib);
        ++m_dropped_messages;
        return;
    }
    c.outgoing.emplace_back(bytes, bytes + n);
    c.queued_bytes += n;
}

void ServeSession::flush(ServeClient& c)
{
    while (!c.gone && !c.outgoing.empty()) {
        const auto& front = c.outgoing.front();
        const ssize_t sent = ::send(c.fd.get(), front.data() + c.front_sent, front.size() - c.front_sent, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (sent < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) return; // the socket is full: later
        if (sent <= 0) {
            c.gone = true;
            return;
        }
        c.front_sent += static_cast<std::size_t>(sent);
        if (c.front_sent == front.size()) {
            c.queued_bytes -= front.size();
            c.outgoing.pop_front();
            c.front_sent = 0;
        }
    }
}

void ServeSession::record(const char* direction, const std::string& type, const std::string& device, std::uint64_t timestamp,
                          const std::vector<std::uint8_t>* raw)
{
    if (!m_record) return;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - m_t0).count();
    nlohmann::json line{{"direction", direction}, {"type", type}, {"device", device}, {"timestamp", timestamp}, {"wall_s", wall}};
    if (raw) line["bytes_hex"] = to_hex(*raw);
    m_record << line.dump() << "\n";
    m_record.flush();
}

void ServeSession::answer_pose(const Pose& pose, int dropped)
{
    m_dropped_poses += static_cast<std::uint64_t>(dropped);
    const IgtlMessage& message = pose.message;
    ServeClient* sender = client(pose.client);
    // A pose must be a rigid motion with finite numbers (Slicer sends float32: orthonormal to 1e-3).
    std::string refused;
    if (message.content.size() < 48) refused = fmt::format("TRANSFORM '{}' holds {} bytes, not 48", message.device, message.content.size());
    Mat3 r = Mat3::Zero();
    Vec3 position = Vec3::Zero();
    if (refused.empty()) {
        for (int k = 0; k < 12; ++k) {
            const double v = read_float_be(message.content.data() + 4 * k);
            if (!std::isfinite(v)) refused = fmt::format("TRANSFORM '{}': element {} is not finite", message.device, k + 1);
            if (k < 9) r(k % 3, k / 3) = v; // columns first, as OpenIGTLink packs them
        }
        position = Vec3(m_wire * read_float_be(message.content.data() + 36), m_wire * read_float_be(message.content.data() + 40),
                        read_float_be(message.content.data() + 44));
        if (refused.empty() && ((r.transpose() * r - Mat3::Identity()).cwiseAbs().maxCoeff() > 1e-3 || r.determinant() < 0)) {
            const std::string why =
                fmt::format("TRANSFORM '{}' is not a rigid motion (its rotation part is not orthonormal and right-handed to 1e-3)", message.device);
            if (m_tool_shape.shape != IndenterShape::sphere) {
                refused = why;
            } else if (sender && sender->warned_rotation++ == 0) {
                // A sphere has no orientation: its centre is used, and the sender is told once.
                send_to(*sender, error_status_message(message.device, why + "; the sphere's centre is used, its rotation ignored"), message.timestamp);
                logger()->warn("serve: client {}: {}; the sphere's centre is used, its rotation ignored (said once)", pose.client, why);
            }
        }
    }
    if (!refused.empty()) {
        if (sender) send_to(*sender, error_status_message(message.device, refused), message.timestamp);
        logger()->warn("serve: client {}: {}; the pose is ignored", pose.client, refused);
        return;
    }
    const auto started = std::chrono::steady_clock::now();
    const LiverModel& model = m_subject.model;
    CondensedContactModel::Update update;
    try {
        update = m_condensed->move_to(m_tool_shape, position);
    } catch (const Error& e) {
        // A pose the contact cannot solve (an LCP that does not converge): the model stays where it was.
        if (sender) send_to(*sender, error_status_message(message.device, e.what()), message.timestamp);
        logger()->warn("serve: pose at ({:.1f}, {:.1f}, {:.1f}) mm LPS not solved: {}", position[0], position[1], position[2], e.what());
        return;
    }
    const std::vector<double> u = m_condensed->query_field_mm();
    for (const auto& surface : m_surfaces) broadcast(organ_surface_message(surface, model, u, m_wire), message.timestamp);
    broadcast(points_message("targets", move_landmarks(model, u, m_subject.rest_landmarks), m_wire, true), message.timestamp);
    ++m_updates;
    logger()->debug("serve: update {} at ({:.1f}, {:.1f}, {:.1f}) mm LPS: {} nodes in contact, {:.2f} ms ({} stale poses dropped)", m_updates, position[0],
                    position[1], position[2], update.active_nodes,
                    std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - started).count(), dropped);
}

void ServeSession::answer_command(ServeClient& c, const IgtlMessage& message)
{
    const std::string xml = message.content.size() > 4 ? std::string(message.content.begin() + 4, message.content.end()) : "";
    const std::string command = xml_attribute(xml, "Name");
    std::string answer;
    if (command == "reset") {
        m_condensed->reset();
        answer = "<Command Status=\"SUCCESS\" Message=\"the model is at rest\"/>";
    } else if (command == "field") {
        // The dense field of the current state, on request only (one solve with the factor for every
        // node; a prepared model makes the factor at the first request: seconds, the updates wait).
        const LiverModel& model = m_subject.model;
        send_to(c, displacement_image_message(model.mesh, m_condensed->full_displacement_mm(), m_field_spacing, 2.0 * model.cell_size_mm.maxCoeff(), m_wire),
                message.timestamp);
        answer = fmt::format("<Command Status=\"SUCCESS\" Message=\"IMAGE displacement sent ({} mm voxels)\"/>", m_field_spacing);
    } else if (command == "status") {
        answer = fmt::format("<Command Status=\"SUCCESS\" Updates=\"{}\" Nodes=\"{}\" Frame=\"{}\" Clients=\"{}\" DroppedPoses=\"{}\" DroppedMessages=\"{}\" "
                             "Factorised=\"{}\"/>",
                             m_updates, m_subject.model.mesh.node_count(), m_o.frame, m_clients.size(), m_dropped_poses, m_dropped_messages,
                             m_condensed->factorised() ? "yes" : "no");
    } else {
        answer = fmt::format("<Command Status=\"FAIL\" Message=\"unknown command '{}' (reset, status, field)\"/>", command);
    }
    auto ack = igtl::StringMessage::New();
    ack->SetDeviceName(("ACK_" + message.device.substr(4)).c_str());
    ack->SetString(answer.c_str());
    send_to(c, ack, message.timestamp);
}

void ServeSession::queue(Job job)
{
    if (m_running.valid()) {
        m_waiting = std::move(job); // the latest waiting input wins
        return;
    }
    m_running_job = std::move(job);
    m_running = std::async(std::launch::async, m_running_job.run);
}

void ServeSession::deliver_background()
{
    // A registration is done: its answer goes to every client with its input's timestamp.
    try {
        const BackgroundAnswer answer = m_running.get();
        for (const auto& m : answer.messages) broadcast(m, m_running_job.timestamp);
        logger()->info("serve: {}", answer.note);
    } catch (const Error& e) {
        // An input the pipeline refuses is the client's bad input: said to it on the wire, the session goes on.
        if (ServeClient* c = client(m_running_job.client)) send_to(*c, error_status_message(m_running_job.device, e.what()), m_running_job.timestamp);
        logger()->warn("serve: {} refused: {}", m_running_job.device, e.what());
    }
    if (m_waiting) {
        Job next = std::move(*m_waiting);
        m_waiting.reset();
        queue(std::move(next));
    }
}

BackgroundAnswer ServeSession::register_cloud(const LabelledPointCloud& cloud)
{
    if (!m_surface_model) {
        std::set<std::int32_t> liver(m_subject.roles.liver.begin(), m_subject.roles.liver.end());
        liver.insert(m_subject.roles.lesion.begin(), m_subject.roles.lesion.end());
        liver.insert(m_subject.roles.vessel.begin(), m_subject.roles.vessel.end());
        // No notch region: the wire's clouds are unlabelled, and every triangle is "surface" to them.
        m_surface_model = surface_model_from_labels(m_subject.labels, liver, m_surface_settings.cell_size, std::nullopt,
                                                    static_cast<unsigned>(m_surface_settings.seed), "serve: the liver model for clouds");
    }
    PartialSurfaceCase c;
    c.mesh = m_surface_model->mesh;
    c.surface = m_surface_model->surface;
    c.quality = m_surface_model->quality;
    c.cloud = cloud;
    c.patient_frame = true; // meshed from the subject's label volume
    c.landmarks = m_subject.rest_landmarks;
    const PartialSurfaceResult r = register_partial_surface(c, m_surface_settings);
    BackgroundAnswer answer;
    answer.messages.push_back(registered_surface_message(*m_surface_model, r.chosen_method().displacement_mm, m_wire).GetPointer());
    answer.messages.push_back(points_message("targets_registered", *r.landmarks, m_wire, false).GetPointer());
    answer.note = fmt::format("cloud registered ({}; {})", r.chosen_method().name, r.safeguard.statement);
    return answer;
}

BackgroundAnswer ServeSession::register_segmentation(const LabelVolume& labels)
{
    const ImageRegistrationResult r = register_segmentation_pair(m_subject, labels, m_o.segmentation);
    const DisplacementField& field = r.chosen_method().field; // intra-operative → pre-operative (the subject's rest)
    const LiverModel& model = m_subject.model;
    BackgroundAnswer answer;
    for (const auto& surface : m_surfaces)
        answer.messages.push_back(
            organ_surface_message(surface, model, displacement_through_inverse(field, model.mesh.nodes, surface.nodes), m_wire, surface.name + "_segmentation")
                .GetPointer());
    LandmarkSet targets = m_subject.rest_landmarks;
    for (auto& l : targets) invert_field_at(field, Vec3(l.position), l.position);
    answer.messages.push_back(points_message("targets_segmentation", targets, m_wire, true).GetPointer());
    answer.note = fmt::format("segmentation registered ({}; mean Dice {})", r.chosen_method().name, mean_dice(r, r.chosen_method().name));
    return answer;
}

} // namespace

void validate(const ServeOptions& o)
{
    if (o.model.empty() == o.dataset.empty()) fail("serve: give a prepared MODEL (physreg prepare) or --dataset DIR, not both");
    if (o.client.empty() == (o.port == 0)) fail("serve: give --port (listen) or --client HOST:PORT (connect to a PlusServer), not both");
    if (!o.client.empty() && o.client.rfind(':') == std::string::npos) fail("--client '{}': give HOST:PORT", o.client);
    if (o.client.empty() && (o.port < 1 || o.port > 65535)) fail("--port {} must lie in 1 … 65535", o.port);
    if (o.max_clients < 1) fail("--max-clients {} must be ≥ 1", o.max_clients);
    if (!(o.queue_mib > 0) || !std::isfinite(o.queue_mib)) fail("--send-queue {} must be > 0 MiB", o.queue_mib);
    if (o.frame != "ras" && o.frame != "lps") fail("--frame '{}': use ras or lps", o.frame);
}

void serve(const ServeOptions& options, const CompressionRegistrationSettings& settings)
{
    validate(options);
    validate(settings, SettingNaming::option);
    ServeSession session(options, settings);
    session.run();
}

} // namespace physreg::live
