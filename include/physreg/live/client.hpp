// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A client of the live link, as a tracker and a display are: tool poses out, the model's answers in
// (organ surfaces as POLYDATA, targets as POINT, refusals as STATUS). For scripts, tests and a
// navigation system that embeds the library; Python's physreg.LiveClient.
#include "physreg/core/types.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace physreg::live {

struct LiveMessage {
    std::string type, device;            ///< e.g. POLYDATA "liver", POINT "targets", STATUS "tool"
    std::uint64_t timestamp = 0;         ///< OpenIGTLink's 32.32 fixed-point seconds, as the pose that caused it
    std::vector<Vec3> points;            ///< POLYDATA vertices or POINT positions, mm, LPS
    std::vector<std::string> names;      ///< POINT: one name per point
    std::string text;                    ///< STATUS: its message; STRING: its text
};

class LiveClient {
public:
    /// Connects to `address` (HOST:PORT). `frame`: the server's --frame (ras or lps); positions are
    /// given and returned in LPS whatever it is. Error naming the address when it cannot connect.
    LiveClient(const std::string& address, const std::string& frame = "ras");
    ~LiveClient();
    LiveClient(const LiveClient&) = delete;
    LiveClient& operator=(const LiveClient&) = delete;

    /// Sends the tool's position (mm, LPS) as a TRANSFORM named `device`; `timestamp` 0: the next
    /// pose number (1, 2, …) in whole seconds, so that answers can be matched to their pose.
    /// Returns the timestamp sent. Error naming the value for a non-finite position.
    std::uint64_t send_pose(const Vec3& position_mm, const std::string& device = "tool", std::uint64_t timestamp = 0);
    /// The next message, or nothing when none arrives within `timeout_s`. Error when the server has
    /// closed the connection or sends a corrupt message.
    std::optional<LiveMessage> read(double timeout_s);

private:
    int m_fd = -1;
    double m_wire = -1.0;
    std::uint32_t m_poses = 0;
};

} // namespace physreg::live
