#include "transport/session.h"

#include <sodium.h>

#include <algorithm>
#include <cstdio>
#include <cstring>

namespace ht {
namespace {

template <std::size_t N>
std::uint8_t CopyText(std::array<char, N>& out, const char* text) noexcept {
  const std::size_t n = std::min(N, std::strlen(text));
  std::memcpy(out.data(), text, n);
  return static_cast<std::uint8_t>(n);
}

}  // namespace

bool NegotiateSession(const wire::HelloMessage& hello, const RemoteCapabilities& remote,
                      wire::WelcomeMessage& welcome, wire::RejectMessage& reject) noexcept {
  reject.client_nonce = hello.client_nonce;
  const std::uint16_t low = std::max(hello.min_version, wire::kMinProtocolVersion);
  const std::uint16_t high = std::min(hello.max_version, wire::kProtocolVersion);
  char text[wire::kMaxRejectText + 1] = {};
  if (low > high) {
    std::snprintf(text, sizeof(text),
                  "no protocol version in common: operator speaks %u..%u, remote node %u..%u",
                  hello.min_version, hello.max_version, wire::kMinProtocolVersion,
                  wire::kProtocolVersion);
    reject.reason = wire::RejectReason::kVersion;
    reject.text_length = CopyText(reject.text, text);
    return false;
  }
  if (hello.max_grid != 0 && remote.grid > hello.max_grid) {
    std::snprintf(text, sizeof(text),
                  "the remote node's penetration-depth grid is %u x %u; the operator accepts at "
                  "most %u (raise --max-grid or lower slave_sim --grid)",
                  remote.grid, remote.grid, hello.max_grid);
    reject.reason = wire::RejectReason::kCapabilities;
    reject.text_length = CopyText(reject.text, text);
    return false;
  }
  const wire::DeadbandTerms& d = hello.deadband;
  const float over = std::max(d.tool_state_deadband, d.model_deadband);
  if (over > remote.max_deadband) {
    std::snprintf(text, sizeof(text),
                  "the operator asks a %s deadband of %.1f %%; this remote node accepts at most "
                  "%.1f %% (lower master_station --deadband or raise slave_sim --max-deadband)",
                  d.tool_state_deadband >= d.model_deadband ? "tool-state" : "contact-model",
                  100.0 * over, 100.0 * remote.max_deadband);
    reject.reason = wire::RejectReason::kCapabilities;
    reject.text_length = CopyText(reject.text, text);
    return false;
  }
  if (d.model_deadband > 0.0f && remote.max_model_rate_hz > 0.0f &&
      1000.0f / remote.max_model_rate_hz > static_cast<float>(d.model_keepalive_ms)) {
    std::snprintf(text, sizeof(text),
                  "the operator asks a contact-model keep-alive of %u ms; this remote node sends "
                  "at most %.0f models/s (one per %.0f ms) (raise --deadband-keepalive or slave_sim "
                  "--max-rate)",
                  d.model_keepalive_ms, static_cast<double>(remote.max_model_rate_hz),
                  1000.0 / remote.max_model_rate_hz);
    reject.reason = wire::RejectReason::kCapabilities;
    reject.text_length = CopyText(reject.text, text);
    return false;
  }
  welcome = {};
  welcome.deadband = d;
  welcome.client_nonce = hello.client_nonce;
  welcome.version = high;
  welcome.tool_state_rate_hz = hello.tool_state_rate_hz;
  const float a = hello.max_model_rate_hz, b = remote.max_model_rate_hz;
  welcome.model_rate_hz = a > 0 && b > 0 ? std::min(a, b) : std::max(a, b);
  welcome.grid = remote.grid;
  welcome.window_m = remote.window_m;
  welcome.mtu = std::min(hello.mtu, remote.mtu);
  welcome.codecs = hello.codecs & remote.codecs;
  welcome.heartbeat_ms = hello.heartbeat_ms;
  welcome.peer_timeout_ms = std::max(hello.peer_timeout_ms, remote.peer_timeout_ms);
  welcome.scene_objects = (welcome.codecs & wire::kCodecDracoMesh) ? remote.scene_objects : 0;
  welcome.scene_name_length = CopyText(welcome.scene_name, remote.scene_name.c_str());
  welcome.layout = remote.layout;
  return true;
}

bool NonceHistory::Insert(std::uint64_t nonce) noexcept {
  for (std::size_t i = 0; i < count_; ++i) {
    if (ring_[i] == nonce) return false;
  }
  ring_[next_] = nonce;
  next_ = (next_ + 1) % kSize;
  count_ = std::min(count_ + 1, kSize);
  return true;
}

std::uint32_t RandomSessionId() noexcept {
  if (sodium_init() < 0) return 1;
  std::uint32_t v = 0;
  while (v == 0) v = randombytes_random();
  return v;
}

std::uint64_t RandomNonce() noexcept {
  if (sodium_init() < 0) return 1;
  std::uint64_t v = 0;
  randombytes_buf(&v, sizeof(v));
  return v;
}

}  // namespace ht
