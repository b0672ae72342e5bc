// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// OpenIGTLink on the wire, as the live server (serve.hpp) and `physreg replay` read and write it: the 58-byte header of versions 1
// and 2 (big-endian; version 2 adds a 12-byte extended header and metadata to the body), the body's
// CRC-64 (the library's), and the socket helpers. Read by hand because the 1.11 library cannot
// unpack version 2, which 3D Slicer sends; answers are packed by the library.
#include "physreg/core/types.hpp"
#include "physreg/image/image_geometry.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace physreg::live {

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
/// The points of a POLYDATA message's content (its header: ten uint32 counts and sizes, then the
/// points as big-endian float32 triples), mm; `wire` −1 turns RAS into LPS. Error naming the device
/// for a short or non-finite content.
std::vector<Vec3> polydata_points(const IgtlMessage& m, double wire);
/// An IMAGE message of labels (one component; unsigned 8- or 16-bit, or signed ones with no
/// negative value) on its grid, in LPS mm whatever the message's coordinate frame (RAS or LPS). The
/// message's origin is the volume's centre (OpenIGTLink's convention); its matrix columns are the
/// axes scaled by the spacing. Error naming the device for other pixel types, a sub-volume, axes
/// that are not orthonormal, or a pixel block of the wrong size.
LabelVolume igtl_image_labels(const IgtlMessage& m);
/// A TRANSFORM message named `device` moving to `position_mm` (LPS; `wire` −1 writes RAS), identity
/// rotation, stamped `timestamp` (32.32 fixed point): header and body, packed by the library.
std::vector<std::uint8_t> transform_message(const std::string& device, const Vec3& position_mm, double wire, std::uint64_t timestamp);
/// True when more bytes wait on `fd`.
bool more_waiting(int fd, int timeout_ms = 0);
/// Sends all of `data`; false when the peer has gone.
bool send_all(int fd, const void* data, std::size_t n);

/// A TCP connection to `target` (HOST:PORT) with TCP_NODELAY; Error naming `option` when the
/// address is malformed or unknown or the connection is refused.
int connect_to(const std::string& target, const std::string& option);

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

} // namespace physreg::live
