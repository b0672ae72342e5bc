// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/live/client.hpp"

#include "physreg/core/error.hpp"
#include "physreg/live/igtl_wire.hpp"

#include <unistd.h>

#include <cmath>
#include <cstring>

namespace physreg::live {

LiveClient::LiveClient(const std::string& address, const std::string& frame)
{
    if (frame != "ras" && frame != "lps") fail("live client: frame '{}': use ras or lps", frame);
    m_wire = frame == "ras" ? -1.0 : 1.0;
    m_fd = connect_to(address, "live client address");
}

LiveClient::~LiveClient()
{
    if (m_fd >= 0) ::close(m_fd);
}

std::uint64_t LiveClient::send_pose(const Vec3& position_mm, const std::string& device, std::uint64_t timestamp)
{
    for (int d = 0; d < 3; ++d)
        if (!std::isfinite(position_mm[d])) fail("live client: the pose's coordinate {} is {} (not finite)", "xyz"[d], position_mm[d]);
    if (timestamp == 0) timestamp = std::uint64_t(++m_poses) << 32;
    const auto bytes = transform_message(device, position_mm, m_wire, timestamp);
    if (!send_all(m_fd, bytes.data(), bytes.size())) fail("live client: the server closed the connection");
    return timestamp;
}

std::optional<LiveMessage> LiveClient::read(double timeout_s)
{
    if (!(timeout_s >= 0) || !std::isfinite(timeout_s)) fail("live client: timeout {} s must be finite and >= 0", timeout_s);
    if (!more_waiting(m_fd, static_cast<int>(timeout_s * 1000.0))) return std::nullopt;
    const auto m = read_igtl_message(m_fd);
    if (!m) fail("live client: the server closed the connection");
    LiveMessage out;
    out.type = m->type;
    out.device = m->device;
    out.timestamp = m->timestamp;
    if (m->type == "POLYDATA") {
        out.points = polydata_points(*m, m_wire);
    } else if (m->type == "POINT") {
        // Elements of 136 bytes: name 64, group 32, RGBA 4, position 3 x float32, radius, owner 20.
        if (m->content.size() % 136 != 0) fail("live client: POINT '{}' of {} bytes is not whole elements of 136", m->device, m->content.size());
        for (std::size_t at = 0; at < m->content.size(); at += 136) {
            const char* name = reinterpret_cast<const char*>(m->content.data() + at);
            out.names.emplace_back(name, strnlen(name, 64));
            const std::uint8_t* p = m->content.data() + at + 100;
            out.points.emplace_back(m_wire * read_float_be(p), m_wire * read_float_be(p + 4), read_float_be(p + 8));
        }
    } else if (m->type == "STATUS" && m->content.size() > 30) {
        // code 2, subcode 8, error name 20, then the message (NUL-terminated).
        const char* text = reinterpret_cast<const char*>(m->content.data() + 30);
        out.text.assign(text, strnlen(text, m->content.size() - 30));
    } else if (m->type == "STRING" && m->content.size() > 4) {
        out.text.assign(m->content.begin() + 4, m->content.end());
    }
    return out;
}

} // namespace physreg::live
