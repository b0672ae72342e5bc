// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// OpenIGTLink on the wire, as serve and replay read and write it: the 58-byte header of versions 1
// and 2 (big-endian; version 2 adds a 12-byte extended header and metadata to the body), the body's
// CRC-64 (the library's), and the socket helpers. Read by hand because the 1.11 library cannot
// unpack version 2, which 3D Slicer sends; answers are packed by the library.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace physreg::cli {

constexpr std::size_t igtl_header_size = 58;

struct IgtlMessage {
    int version = 1;
    std::string type, device;
    std::uint64_t timestamp = 0;        ///< OpenIGTLink's 32.32 fixed-point seconds
    std::vector<std::uint8_t> content;  ///< the body without version 2's extended header and metadata
    std::vector<std::uint8_t> raw;      ///< header and body as received
};

std::uint64_t read_be(const std::uint8_t* p, int bytes);
float read_float_be(const std::uint8_t* p);

/// One message from `fd`, its CRC checked; nothing when the peer has gone (end of stream). Error
/// naming the type and device for a corrupt message.
std::optional<IgtlMessage> read_igtl_message(int fd);
/// The message `raw` (header and body) parsed the same way; Error when it is not one whole message.
IgtlMessage parse_igtl_message(const std::vector<std::uint8_t>& raw);
/// True when more bytes wait on `fd`.
bool more_waiting(int fd, int timeout_ms = 0);
/// Sends all of `data`; false when the peer has gone.
bool send_all(int fd, const void* data, std::size_t n);

std::string to_hex(const std::vector<std::uint8_t>& bytes);
/// Error naming `what` for text that is not hex digits in pairs.
std::vector<std::uint8_t> from_hex(const std::string& text, const std::string& what);

/// Closes the descriptor when it goes.
class Descriptor {
public:
    explicit Descriptor(int fd = -1) : m_fd(fd) {}
    ~Descriptor();
    Descriptor(const Descriptor&) = delete;
    Descriptor& operator=(const Descriptor&) = delete;
    int get() const { return m_fd; }

private:
    int m_fd;
};

} // namespace physreg::cli
