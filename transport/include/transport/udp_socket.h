#pragma once
// A thin RAII wrapper over a non-blocking IPv4/IPv6 UDP socket.

#include <sys/socket.h>

#include <cstdint>
#include <optional>
#include <span>
#include <string>

namespace ht {

/// A socket address (IPv4 or IPv6) with a printable form.
struct SocketAddress {
  sockaddr_storage storage{};
  socklen_t length = 0;

  /// Parses "HOST:PORT" where HOST is a numeric IPv4 address, "[IPv6]", "localhost" (127.0.0.1)
  /// or a host name, resolved by the system (getaddrinfo: its first IPv4 address, else its first
  /// IPv6 one). Throws std::invalid_argument with the offending text when it cannot be parsed or
  /// resolved, or the port is outside 0..65535; a HOST with ':' outside brackets ("::1:47000")
  /// is refused with how to write an IPv6 address.
  static SocketAddress Parse(const std::string& text);
  /// "a.b.c.d:port" or "[v6]:port".
  std::string ToString() const;
  /// Port number (host order).
  std::uint16_t port() const noexcept;
  bool operator==(const SocketAddress& other) const noexcept;
};

/// Non-blocking UDP socket. Send and receive never block; Wait blocks up to a timeout.
class UdpSocket {
 public:
  /// Opens a socket bound to `local` (port 0 picks a free port), asking for a 4 MiB receive buffer
  /// and a send buffer of `send_buffer_bytes` (best effort: the kernel caps them at
  /// net.core.rmem_max / wmem_max). Throws std::runtime_error with the system's reason (e.g.
  /// "Address already in use") and the address on failure.
  explicit UdpSocket(const SocketAddress& local, int send_buffer_bytes = 1 << 20);
  ~UdpSocket();
  UdpSocket(const UdpSocket&) = delete;
  UdpSocket& operator=(const UdpSocket&) = delete;

  /// The bound address (with the port the system chose).
  SocketAddress local_address() const;

  /// Sends one datagram. Returns false (and the caller counts it) when the system refuses it or
  /// would block; never throws.
  bool SendTo(std::span<const std::uint8_t> bytes, const SocketAddress& to) noexcept;

  /// Receives one datagram into `buffer` if one is waiting. Returns its size (datagrams longer
  /// than the buffer are reported with their full length via MSG_TRUNC so they can be rejected),
  /// or std::nullopt when none is waiting.
  std::optional<std::size_t> ReceiveFrom(std::span<std::uint8_t> buffer,
                                         SocketAddress& from) noexcept;

  /// Waits until a datagram is readable or `timeout_ms` passes. Returns true when readable.
  bool WaitReadable(int timeout_ms) noexcept;
  /// The same to the nanosecond (ppoll): for deadlines shorter than a millisecond. A timeout ≤ 0
  /// only checks.
  bool WaitReadableNs(std::int64_t timeout_ns) noexcept;

  /// The socket's file descriptor, to wait on it together with other descriptors (poll, ppoll).
  /// The socket keeps owning it: the caller must not close it, and it is invalid once the socket
  /// is destroyed.
  int native_handle() const noexcept { return fd_; }

 private:
  int fd_ = -1;
};

}  // namespace ht
