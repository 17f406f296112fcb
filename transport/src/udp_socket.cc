#include "transport/udp_socket.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace ht {

SocketAddress SocketAddress::Parse(const std::string& text) {
  const auto colon = text.rfind(':');
  if (colon == std::string::npos || colon + 1 >= text.size()) {
    throw std::invalid_argument("address '" + text + "' must be HOST:PORT");
  }
  std::string host = text.substr(0, colon);
  const std::string port_text = text.substr(colon + 1);
  char* end = nullptr;
  errno = 0;
  const long port = std::strtol(port_text.c_str(), &end, 10);
  if (errno != 0 || end == port_text.c_str() || *end != '\0' || port < 0 || port > 65535) {
    throw std::invalid_argument("address '" + text + "': port must be 0..65535");
  }
  if (host == "localhost") host = "127.0.0.1";
  SocketAddress a;
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
    sockaddr_in6 s6{};
    s6.sin6_family = AF_INET6;
    s6.sin6_port = htons(static_cast<std::uint16_t>(port));
    if (inet_pton(AF_INET6, host.substr(1, host.size() - 2).c_str(), &s6.sin6_addr) != 1) {
      throw std::invalid_argument("address '" + text + "': bad IPv6 host");
    }
    std::memcpy(&a.storage, &s6, sizeof(s6));
    a.length = sizeof(s6);
    return a;
  }
  // An IPv6 address without its brackets: its last ':' was taken for the port's.
  if (host.find(':') != std::string::npos) {
    throw std::invalid_argument("address '" + text +
                                "': write an IPv6 address as [ADDR]:PORT, e.g. [::1]:47000");
  }
  sockaddr_in s4{};
  s4.sin_family = AF_INET;
  s4.sin_port = htons(static_cast<std::uint16_t>(port));
  if (inet_pton(AF_INET, host.c_str(), &s4.sin_addr) == 1) {
    std::memcpy(&a.storage, &s4, sizeof(s4));
    a.length = sizeof(s4);
    return a;
  }
  // Digits and dots that are no dotted quad ("1.2.3") are a mistyped address, not a name (the
  // resolver would read them as inet_aton does: 1.2.0.3).
  if (host.empty() || host.find_first_not_of("0123456789.") == std::string::npos) {
    throw std::invalid_argument("address '" + text +
                                "': host must be a numeric IPv4 address, [IPv6] or a host name");
  }
  // A host name, through the system's resolver (/etc/hosts, DNS): its first IPv4 address, else
  // its first IPv6 one.
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* found = nullptr;
  if (const int rc = getaddrinfo(host.c_str(), nullptr, &hints, &found); rc != 0) {
    throw std::invalid_argument("address '" + text + "': cannot resolve host '" + host + "' (" +
                                gai_strerror(rc) +
                                "): give a name this machine resolves, a numeric IPv4 address "
                                "or [IPv6]");
  }
  const addrinfo* chosen = found;
  for (const addrinfo* i = found; i != nullptr; i = i->ai_next) {
    if (i->ai_family == AF_INET) {
      chosen = i;
      break;
    }
  }
  if (chosen->ai_family != AF_INET && chosen->ai_family != AF_INET6) {
    freeaddrinfo(found);
    throw std::invalid_argument("address '" + text + "': host '" + host +
                                "' has no IPv4 or IPv6 address");
  }
  std::memcpy(&a.storage, chosen->ai_addr, chosen->ai_addrlen);
  a.length = static_cast<socklen_t>(chosen->ai_addrlen);
  freeaddrinfo(found);
  const auto port_n = htons(static_cast<std::uint16_t>(port));
  if (a.storage.ss_family == AF_INET) {
    reinterpret_cast<sockaddr_in*>(&a.storage)->sin_port = port_n;
  } else {
    reinterpret_cast<sockaddr_in6*>(&a.storage)->sin6_port = port_n;
  }
  return a;
}

std::string SocketAddress::ToString() const {
  char buf[INET6_ADDRSTRLEN] = {};
  if (storage.ss_family == AF_INET6) {
    const auto* s6 = reinterpret_cast<const sockaddr_in6*>(&storage);
    inet_ntop(AF_INET6, &s6->sin6_addr, buf, sizeof(buf));
    return "[" + std::string(buf) + "]:" + std::to_string(ntohs(s6->sin6_port));
  }
  const auto* s4 = reinterpret_cast<const sockaddr_in*>(&storage);
  inet_ntop(AF_INET, &s4->sin_addr, buf, sizeof(buf));
  return std::string(buf) + ":" + std::to_string(ntohs(s4->sin_port));
}

std::uint16_t SocketAddress::port() const noexcept {
  if (storage.ss_family == AF_INET6) {
    return ntohs(reinterpret_cast<const sockaddr_in6*>(&storage)->sin6_port);
  }
  return ntohs(reinterpret_cast<const sockaddr_in*>(&storage)->sin_port);
}

bool SocketAddress::operator==(const SocketAddress& o) const noexcept {
  return length == o.length && std::memcmp(&storage, &o.storage, length) == 0;
}

UdpSocket::UdpSocket(const SocketAddress& local, int send_buffer_bytes) {
  fd_ = ::socket(local.storage.ss_family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw std::runtime_error(std::string("socket(): ") + std::strerror(errno));
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&local.storage), local.length) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd_);
    fd_ = -1;
    throw std::runtime_error("cannot bind UDP " + local.ToString() + ": " + why);
  }
  // Room for bursts while a thread is descheduled (best effort: the kernel caps it at
  // net.core.rmem_max / wmem_max).
  const int receive_bytes = 4 << 20;
  ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &receive_bytes, sizeof(receive_bytes));
  ::setsockopt(fd_, SOL_SOCKET, SO_SNDBUF, &send_buffer_bytes, sizeof(send_buffer_bytes));
}

UdpSocket::~UdpSocket() {
  if (fd_ >= 0) ::close(fd_);
}

SocketAddress UdpSocket::local_address() const {
  SocketAddress a;
  a.length = sizeof(a.storage);
  ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a.storage), &a.length);
  return a;
}

bool UdpSocket::SendTo(std::span<const std::uint8_t> bytes, const SocketAddress& to) noexcept {
  const ssize_t n = ::sendto(fd_, bytes.data(), bytes.size(), MSG_DONTWAIT,
                             reinterpret_cast<const sockaddr*>(&to.storage), to.length);
  return n == static_cast<ssize_t>(bytes.size());
}

std::optional<std::size_t> UdpSocket::ReceiveFrom(std::span<std::uint8_t> buffer,
                                                  SocketAddress& from) noexcept {
  from.length = sizeof(from.storage);
  const ssize_t n = ::recvfrom(fd_, buffer.data(), buffer.size(), MSG_DONTWAIT | MSG_TRUNC,
                               reinterpret_cast<sockaddr*>(&from.storage), &from.length);
  if (n < 0) return std::nullopt;
  return static_cast<std::size_t>(n);
}

bool UdpSocket::WaitReadable(int timeout_ms) noexcept {
  pollfd p{fd_, POLLIN, 0};
  return ::poll(&p, 1, timeout_ms) > 0 && (p.revents & POLLIN);
}

bool UdpSocket::WaitReadableNs(std::int64_t timeout_ns) noexcept {
  pollfd p{fd_, POLLIN, 0};
  const std::int64_t ns = timeout_ns > 0 ? timeout_ns : 0;
  const timespec t{static_cast<time_t>(ns / 1000000000), static_cast<long>(ns % 1000000000)};
  return ::ppoll(&p, 1, &t, nullptr) > 0 && (p.revents & POLLIN);
}

}  // namespace ht
