#include "transport/auth.h"

#include <fcntl.h>
#include <sodium.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace ht {
namespace {

void EnsureSodium() {
  static const int init = sodium_init();  // thread-safe once; 1 = already initialised
  if (init < 0) throw std::runtime_error("libsodium failed to initialise (sodium_init)");
}

static_assert(wire::kFullMacBytes == crypto_auth_BYTES);
static_assert(wire::kMacBytes * 2 == crypto_auth_hmacsha256_BYTES,
              "the wire MAC is HMAC-SHA-256 truncated to half its output (RFC 4868)");
static_assert(wire::kMacKeyBytes == crypto_auth_hmacsha256_KEYBYTES);
static_assert(wire::kMacKeyBytes == crypto_auth_KEYBYTES);

}  // namespace

MacKey MacKey::Generate() {
  EnsureSodium();
  MacKey k;
  randombytes_buf(k.bytes.data(), k.bytes.size());
  return k;
}

MacKey MacKey::FromHex(const std::string& text) {
  const auto first = text.find_first_not_of(" \t\r\n");
  const auto last = text.find_last_not_of(" \t\r\n");
  const std::string hex = first == std::string::npos ? "" : text.substr(first, last - first + 1);
  if (hex.size() != 2 * wire::kMacKeyBytes) {
    throw std::invalid_argument("a key is " + std::to_string(2 * wire::kMacKeyBytes) +
                                " hexadecimal characters, found " + std::to_string(hex.size()) +
                                " characters");
  }
  MacKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i) {
    unsigned v = 0;
    for (int j = 0; j < 2; ++j) {
      const char c = hex[2 * i + static_cast<std::size_t>(j)];
      int d = -1;
      if (c >= '0' && c <= '9') d = c - '0';
      if (c >= 'a' && c <= 'f') d = c - 'a' + 10;
      if (c >= 'A' && c <= 'F') d = c - 'A' + 10;
      if (d < 0) {
        throw std::invalid_argument(std::string("a key is hexadecimal; found '") + c +
                                    "' at position " + std::to_string(2 * i + j));
      }
      v = v * 16 + static_cast<unsigned>(d);
    }
    k.bytes[i] = static_cast<std::uint8_t>(v);
  }
  return k;
}

std::string MacKey::ToHex() const {
  static const char* digits = "0123456789abcdef";
  std::string s;
  for (std::uint8_t b : bytes) {
    s += digits[b >> 4];
    s += digits[b & 15];
  }
  return s;
}

MacKey LoadKeyFile(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    throw std::runtime_error("cannot read key file " + path + ": " + std::strerror(errno) +
                             " (create one with: slave_sim keygen " + path + ")");
  }
  if (!S_ISREG(st.st_mode)) throw std::runtime_error("key file " + path + " is not a regular file");
  if ((st.st_mode & 077) != 0) {
    throw std::runtime_error("key file " + path +
                             " may be read or written by group or others; run: chmod 600 " + path);
  }
  std::ifstream f(path);
  if (!f) throw std::runtime_error("cannot open key file " + path);
  std::stringstream ss;
  ss << f.rdbuf();
  try {
    return MacKey::FromHex(ss.str());
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error("key file " + path + " is not a key: " + e.what());
  }
}

void WriteKeyFile(const std::string& path, const MacKey& key, bool overwrite) {
  const int flags = O_WRONLY | O_CREAT | O_CLOEXEC | (overwrite ? O_TRUNC : O_EXCL);
  const int fd = ::open(path.c_str(), flags, 0600);
  if (fd < 0) {
    const int e = errno;
    if (e == EEXIST) {
      throw std::runtime_error("key file " + path + " exists; refusing to overwrite (use --force)");
    }
    throw std::runtime_error("cannot create key file " + path + ": " + std::strerror(e));
  }
  ::fchmod(fd, 0600);  // also when overwriting a file that had looser permissions
  const std::string text = key.ToHex() + "\n";
  const bool ok = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
  ::close(fd);
  if (!ok) throw std::runtime_error("cannot write key file " + path);
}

void ComputeFullMac(std::span<const std::uint8_t> message, const MacKey& key,
                    std::span<std::uint8_t, wire::kFullMacBytes> mac) noexcept {
  crypto_auth(mac.data(), message.data(), message.size(), key.bytes.data());
}

void ComputeMac(std::span<const std::uint8_t> message, const MacKey& key,
                std::span<std::uint8_t, wire::kMacBytes> mac) noexcept {
  std::array<std::uint8_t, crypto_auth_hmacsha256_BYTES> full;
  crypto_auth_hmacsha256(full.data(), message.data(), message.size(), key.bytes.data());
  std::memcpy(mac.data(), full.data(), wire::kMacBytes);
}

bool VerifyMac(std::span<const std::uint8_t> datagram, const MacKey& key) noexcept {
  if (datagram.size() < wire::kMacBytes) return false;
  const std::size_t n = datagram.size() - wire::kMacBytes;
  std::array<std::uint8_t, wire::kMacBytes> expected;
  ComputeMac(datagram.first(n), key, expected);
  // sodium_memcmp runs in time independent of where the bytes differ.
  return sodium_memcmp(expected.data(), datagram.data() + n, wire::kMacBytes) == 0;
}

bool VerifyFullMac(std::span<const std::uint8_t> datagram, const MacKey& key) noexcept {
  if (datagram.size() < wire::kFullMacBytes) return false;
  const std::size_t n = datagram.size() - wire::kFullMacBytes;
  return crypto_auth_verify(datagram.data() + n, datagram.data(), n, key.bytes.data()) == 0;
}

std::array<std::uint8_t, wire::kSceneDigestBytes> ContentDigest(
    std::span<const std::uint8_t> bytes) noexcept {
  std::array<std::uint8_t, wire::kSceneDigestBytes> d{};
  crypto_generichash(d.data(), d.size(), bytes.data(), bytes.size(), nullptr, 0);
  return d;
}

ReplayWindow::Verdict ReplayWindow::Check(std::uint64_t s) const noexcept {
  if (s == 0) return Verdict::kZero;
  if (s > highest_) return Verdict::kNewest;
  if (highest_ - s >= kBits) return Verdict::kTooOld;
  const std::uint64_t bit = s % kBits;
  return (bitmap_[bit / 64] >> (bit % 64)) & 1u ? Verdict::kDuplicate : Verdict::kLate;
}

ReplayWindow::Verdict ReplayWindow::Accept(std::uint64_t s) noexcept {
  const Verdict v = Check(s);
  if (v == Verdict::kNewest) {
    // Clear the bits of the numbers skipped between the old highest and s (they leave or enter
    // the window unseen).
    const std::uint64_t gap = s - highest_;
    if (gap >= kBits || highest_ == 0) {
      bitmap_.fill(0);
    } else {
      for (std::uint64_t q = highest_ + 1; q < s; ++q) {
        const std::uint64_t bit = q % kBits;
        bitmap_[bit / 64] &= ~(std::uint64_t{1} << (bit % 64));
      }
    }
    highest_ = s;
  }
  if (v == Verdict::kNewest || v == Verdict::kLate) {
    const std::uint64_t bit = s % kBits;
    bitmap_[bit / 64] |= std::uint64_t{1} << (bit % 64);
  }
  return v;
}

void ReplayWindow::Reset() noexcept {
  bitmap_.fill(0);
  highest_ = 0;
}

}  // namespace ht
