// SPDX-License-Identifier: GPL-3.0-or-later
#include "igtl_wire.hpp"

#include "physreg/core/error.hpp"

#include <igtl_util.h>

#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstring>

namespace physreg::cli {

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
    if (body_size > (std::uint64_t(1) << 31)) fail("OpenIGTLink: {} message '{}' announces {} bytes", m.type, m.device, body_size);
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

} // namespace physreg::cli
