// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/live/igtl_wire.hpp"

#include "physreg/core/error.hpp"

#include <igtlTransformMessage.h>
#include <igtl_util.h>

#include <poll.h>
#include <netinet/tcp.h>
#include <netinet/in.h>
#include <netdb.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cmath>
#include <cstring>

namespace physreg::live {

std::uint64_t read_be(const std::uint8_t* p, int bytes)
{
    std::uint64_t v = 0;
    for (int i = 0; i < bytes; ++i) v = (v << 8) | p[i];
    return v;
}

float read_float_be(const std::uint8_t* p)
{
    const auto bits = static_cast<std::uint32_t>(read_be(p, 4));
    float f;
    std::memcpy(&f, &bits, 4);
    return f;
}

namespace {

std::string fixed_string(const std::uint8_t* p, std::size_t n)
{
    std::size_t len = 0;
    while (len < n && p[len] != 0) ++len;
    return std::string(reinterpret_cast<const char*>(p), len);
}

bool read_exact(int fd, std::uint8_t* out, std::size_t n)
{
    while (n > 0) {
        const ssize_t got = ::recv(fd, out, n, 0);
        if (got <= 0) return false;
        out += got;
        n -= static_cast<std::size_t>(got);
    }
    return true;
}

/// The header's fields into `m`; the body size.
std::uint64_t parse_header(const std::uint8_t* h, IgtlMessage& m)
{
    m.version = static_cast<int>(read_be(h, 2));
    m.type = fixed_string(h + 2, 12);
    m.device = fixed_string(h + 14, 20);
    m.timestamp = read_be(h + 34, 8);
    const std::uint64_t body_size = read_be(h + 42, 8);
    if (m.version < 1 || m.version > 2) fail("OpenIGTLink: header version {} (read: 1 and 2)", m.version);
    if (body_size > (std::uint64_t(256) << 20))
        fail("OpenIGTLink: {} message '{}' announces a body of {} bytes, over the 256 MiB limit", m.type, m.device, body_size);
    return body_size;
}

/// The CRC and version 2's layout checked; the content cut out of the body (raw's tail).
void finish(IgtlMessage& m)
{
    const std::uint8_t* body = m.raw.data() + igtl_header_size;
    const std::uint64_t body_size = m.raw.size() - igtl_header_size;
    if (::crc64(const_cast<std::uint8_t*>(body), body_size, 0) != read_be(m.raw.data() + 50, 8))
        fail("OpenIGTLink: {} message '{}': CRC mismatch", m.type, m.device);
    std::size_t begin = 0, end = body_size;
    if (m.version == 2) {
        if (body_size < 12) fail("OpenIGTLink: version 2 {} message '{}' shorter than its extended header", m.type, m.device);
        const std::size_t extended = read_be(body, 2), meta_header = read_be(body + 2, 2), meta = read_be(body + 4, 4);
        if (extended < 12 || extended + meta_header + meta > body_size)
            fail("OpenIGTLink: version 2 {} message '{}': extended header and metadata larger than the body", m.type, m.device);
        begin = extended;
        end = body_size - meta_header - meta;
    }
    m.content.assign(body + begin, body + end);
}

} // namespace

std::optional<IgtlMessage> read_igtl_message(int fd)
{
    IgtlMessage m;
    m.raw.resize(igtl_header_size);
    if (!read_exact(fd, m.raw.data(), igtl_header_size)) return std::nullopt;
    const std::uint64_t body_size = parse_header(m.raw.data(), m);
    m.raw.resize(igtl_header_size + body_size);
    if (body_size > 0 && !read_exact(fd, m.raw.data() + igtl_header_size, body_size)) return std::nullopt;
    finish(m);
    return m;
}

IgtlMessage parse_igtl_message(const std::vector<std::uint8_t>& raw)
{
    IgtlMessage m;
    if (raw.size() < igtl_header_size) fail("OpenIGTLink: {} bytes are not a message (the header alone is {})", raw.size(), igtl_header_size);
    const std::uint64_t body_size = parse_header(raw.data(), m);
    if (raw.size() != igtl_header_size + body_size)
        fail("OpenIGTLink: {} message '{}' of {} bytes announces a body of {}", m.type, m.device, raw.size(), body_size);
    m.raw = raw;
    finish(m);
    return m;
}

bool more_waiting(int fd, int timeout_ms)
{
    pollfd p{fd, POLLIN, 0};
    return ::poll(&p, 1, timeout_ms) > 0 && (p.revents & POLLIN);
}

bool send_all(int fd, const void* data, std::size_t n)
{
    const auto* p = static_cast<const std::uint8_t*>(data);
    while (n > 0) {
        const ssize_t sent = ::send(fd, p, n, MSG_NOSIGNAL);
        if (sent <= 0) return false;
        p += sent;
        n -= static_cast<std::size_t>(sent);
    }
    return true;
}

std::string to_hex(const std::vector<std::uint8_t>& bytes)
{
    static const char* digits = "0123456789abcdef";
    std::string out;
    out.reserve(2 * bytes.size());
    for (const auto b : bytes) out += digits[b >> 4], out += digits[b & 15];
    return out;
}

std::vector<std::uint8_t> from_hex(const std::string& text, const std::string& what)
{
    const auto value = [&](char c) -> int {
        if (c >= '0' && c <= '9') return c - '0';
        if (c >= 'a' && c <= 'f') return c - 'a' + 10;
        if (c >= 'A' && c <= 'F') return c - 'A' + 10;
        fail("{}: '{}' is not a hex digit", what, c);
    };
    if (text.size() % 2 != 0) fail("{}: an odd number of hex digits", what);
    std::vector<std::uint8_t> out(text.size() / 2);
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = static_cast<std::uint8_t>(16 * value(text[2 * i]) + value(text[2 * i + 1]));
    return out;
}

Descriptor::~Descriptor()
{
    if (m_fd >= 0) ::close(m_fd);
}

int connect_to(const std::string& target, const std::string& option)
{
    const auto colon = target.rfind(':');
    if (colon == std::string::npos) fail("{} '{}': give HOST:PORT", option, target);
    const std::string host = target.substr(0, colon), port = target.substr(colon + 1);
    addrinfo hints{};
    hints.ai_family = AF_INET;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* found = nullptr;
    if (::getaddrinfo(host.c_str(), port.c_str(), &hints, &found) != 0 || !found) fail("{} '{}': host or port unknown", option, target);
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    const int ok = fd >= 0 ? ::connect(fd, found->ai_addr, found->ai_addrlen) : -1;
    ::freeaddrinfo(found);
    if (ok != 0) {
        if (fd >= 0) ::close(fd);
        fail("{} '{}': cannot connect: {}", option, target, std::strerror(errno));
    }
    const int yes = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
    return fd;
}


/// The points of a POLYDATA message's content (its header: ten uint32 counts and sizes, then the
/// points as big-endian float32 triples); `wire` −1 turns RAS into LPS. Error naming the device.
std::vector<Vec3> polydata_points(const IgtlMessage& m, double wire)
{
    if (m.content.size() < 40) fail("OpenIGTLink: POLYDATA '{}' shorter than its header", m.device);
    const std::uint64_t n = read_be(m.content.data(), 4);
    if (40 + 12 * n > m.content.size()) fail("OpenIGTLink: POLYDATA '{}' announces {} points in {} bytes", m.device, n, m.content.size());
    std::vector<Vec3> points(n);
    for (std::uint64_t i = 0; i < n; ++i) {
        const std::uint8_t* p = m.content.data() + 40 + 12 * i;
        points[i] = Vec3(wire * read_float_be(p), wire * read_float_be(p + 4), read_float_be(p + 8));
        if (!points[i].allFinite()) fail("OpenIGTLink: POLYDATA '{}': point {} is not finite", m.device, i);
    }
    return points;
}

LabelVolume igtl_image_labels(const IgtlMessage& m)
{
    const auto& c = m.content;
    if (c.size() < 72) fail("OpenIGTLink: IMAGE '{}' shorter than its 72-byte header", m.device);
    const int components = c[2], scalar = c[3], endian = c[4], frame = c[5];
    if (components != 1) fail("OpenIGTLink: IMAGE '{}' has {} components per voxel; labels have one", m.device, components);
    if (scalar != 2 && scalar != 3 && scalar != 4 && scalar != 5)
        fail("OpenIGTLink: IMAGE '{}': scalar type {} is not a label type (8- or 16-bit integers)", m.device, scalar);
    if (endian != 1 && endian != 2) fail("OpenIGTLink: IMAGE '{}': endianness {} (1 big, 2 little)", m.device, endian);
    if (frame != 1 && frame != 2) fail("OpenIGTLink: IMAGE '{}': coordinate frame {} (1 RAS, 2 LPS)", m.device, frame);
    LabelVolume v;
    auto& g = v.geometry;
    for (int a = 0; a < 3; ++a) {
        g.size[a] = static_cast<std::int64_t>(read_be(c.data() + 6 + 2 * a, 2));
        if (g.size[a] == 0) fail("OpenIGTLink: IMAGE '{}' has no voxel along axis {}", m.device, a);
        if (read_be(c.data() + 60 + 2 * a, 2) != 0 || static_cast<std::int64_t>(read_be(c.data() + 66 + 2 * a, 2)) != g.size[a])
            fail("OpenIGTLink: IMAGE '{}' is a sub-volume; send the whole segmentation", m.device);
    }
    // Columns t, s, n (the axes times the spacing) and the centre p, RAS or LPS; to LPS.
    const double flip = frame == 1 ? -1.0 : 1.0;
    Mat3 axes;
    Vec3 centre;
    for (int col = 0; col < 4; ++col)
        for (int row = 0; row < 3; ++row) {
            const double value = (row < 2 ? flip : 1.0) * read_float_be(c.data() + 12 + 4 * (3 * col + row));
            if (!std::isfinite(value)) fail("OpenIGTLink: IMAGE '{}': its matrix is not finite", m.device);
            if (col < 3) axes(row, col) = value;
            else centre[row] = value;
        }
    for (int a = 0; a < 3; ++a) {
        g.spacing[a] = axes.col(a).norm();
        if (!(g.spacing[a] > 0)) fail("OpenIGTLink: IMAGE '{}': axis {} has zero length", m.device, a);
        g.direction.col(a) = axes.col(a) / g.spacing[a];
    }
    if ((g.direction.transpose() * g.direction - Mat3::Identity()).cwiseAbs().maxCoeff() > 1e-3)
        fail("OpenIGTLink: IMAGE '{}': its axes are not orthonormal", m.device);
    g.origin = centre;
    for (int a = 0; a < 3; ++a) g.origin -= g.direction.col(a) * (g.spacing[a] * 0.5 * static_cast<double>(g.size[a] - 1));
    const std::size_t bytes = scalar <= 3 ? 1 : 2;
    const std::size_t voxels = static_cast<std::size_t>(g.size[0] * g.size[1] * g.size[2]);
    if (c.size() != 72 + voxels * bytes)
        fail("OpenIGTLink: IMAGE '{}' of {}×{}×{} voxels holds {} bytes of pixels, not {}", m.device, g.size[0], g.size[1], g.size[2], c.size() - 72, voxels * bytes);
    v.labels.resize(voxels);
    const std::uint8_t* p = c.data() + 72;
    for (std::size_t i = 0; i < voxels; ++i) {
        std::uint32_t value = bytes == 1 ? p[i] : endian == 1 ? (std::uint32_t(p[2 * i]) << 8 | p[2 * i + 1]) : (std::uint32_t(p[2 * i + 1]) << 8 | p[2 * i]);
        const bool negative = (scalar == 2 && value >= 0x80) || (scalar == 4 && value >= 0x8000);
        if (negative) fail("OpenIGTLink: IMAGE '{}': voxel {} holds a negative label", m.device, i);
        v.labels[i] = static_cast<std::uint16_t>(value);
    }
    return v;
}

std::vector<std::uint8_t> transform_message(const std::string& device, const Vec3& position_mm, double wire, std::uint64_t timestamp)
{
    auto m = igtl::TransformMessage::New();
    m->SetDeviceName(device.c_str());
    igtl::Matrix4x4 matrix;
    igtl::IdentityMatrix(matrix);
    matrix[0][3] = static_cast<float>(wire * position_mm[0]);
    matrix[1][3] = static_cast<float>(wire * position_mm[1]);
    matrix[2][3] = static_cast<float>(position_mm[2]);
    m->SetMatrix(matrix);
    m->SetTimeStamp(static_cast<unsigned int>(timestamp >> 32), static_cast<unsigned int>(timestamp & 0xffffffffu));
    m->Pack();
    const auto* p = static_cast<const std::uint8_t*>(m->GetPackPointer());
    return {p, p + m->GetPackSize()};
}

} // namespace physreg::live
