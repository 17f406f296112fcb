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
    reject = MakeVersionReject(hello.client_nonce, hello.min_version, hello.max_version);
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
  const bool deadband_on = d.tool_state_deadband > 0.0f || d.model_deadband > 0.0f;
  const float a = hello.max_model_rate_hz, b = remote.max_model_rate_hz;
  const float model_rate_hz = a > 0 && b > 0 ? std::min(a, b) : std::max(a, b);
  if (deadband_on && model_rate_hz > 0.0f &&
      1000.0f / model_rate_hz > static_cast<float>(d.model_keepalive_ms)) {
    std::snprintf(text, sizeof(text),
                  "the operator asks a contact-model keep-alive of %u ms, but the session's model "
                  "rate is %.0f models/s (one per %.0f ms) (raise --deadband-keepalive, "
                  "--max-model-rate or slave_sim --max-rate)",
                  d.model_keepalive_ms, static_cast<double>(model_rate_hz), 1000.0 / model_rate_hz);
    reject.reason = wire::RejectReason::kCapabilities;
    reject.text_length = CopyText(reject.text, text);
    return false;
  }
  const std::uint16_t peer_timeout_ms = std::max(hello.peer_timeout_ms, remote.peer_timeout_ms);
  if (d.tool_state_deadband > 0.0f && d.tool_state_keepalive_ms >= peer_timeout_ms) {
    // The node extrapolates the last tool state for at most the keep-alive: never past the time
    // after which it would declare the operator lost.
    std::snprintf(text, sizeof(text),
                  "the operator asks a tool-state keep-alive of %u ms; it must be shorter than "
                  "the session's peer timeout, %u ms (lower --deadband-keepalive or raise "
                  "--peer-timeout)",
                  d.tool_state_keepalive_ms, peer_timeout_ms);
    reject.reason = wire::RejectReason::kCapabilities;
    reject.text_length = CopyText(reject.text, text);
    return false;
  }
  welcome = {};
  welcome.deadband = d;
  welcome.client_nonce = hello.client_nonce;
  welcome.version = high;
  welcome.tool_state_rate_hz = hello.tool_state_rate_hz;
  welcome.model_rate_hz = model_rate_hz;
  welcome.grid = remote.grid;
  welcome.window_m = remote.window_m;
  welcome.mtu = std::min(hello.mtu, remote.mtu);
  welcome.codecs = hello.codecs & remote.codecs;
  welcome.heartbeat_ms = hello.heartbeat_ms;
  welcome.peer_timeout_ms = peer_timeout_ms;
  welcome.scene_objects = (welcome.codecs & wire::kCodecDracoMesh) ? remote.scene_objects : 0;
  welcome.scene_name_length = CopyText(welcome.scene_name, remote.scene_name.c_str());
  welcome.layout = remote.layout;
  return true;
}

wire::RejectMessage MakeVersionReject(std::uint64_t client_nonce, std::uint16_t min_version,
                                      std::uint16_t max_version) noexcept {
  wire::RejectMessage reject;
  reject.client_nonce = client_nonce;
  reject.reason = wire::RejectReason::kVersion;
  char text[wire::kMaxRejectText + 1] = {};
  std::snprintf(text, sizeof(text),
                "no protocol version in common: operator speaks %u..%u, remote node %u..%u "
                "(run the same release on both sides)",
                min_version, max_version, wire::kMinProtocolVersion, wire::kProtocolVersion);
  reject.text_length = CopyText(reject.text, text);
  return reject;
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
