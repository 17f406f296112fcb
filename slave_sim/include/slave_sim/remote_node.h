#pragma once
// The remote simulation node: receives tool states, runs the haptic texture pipeline at the
// latest one as fast as it can (independent of the network rate), and streams contact models.

#include <atomic>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "haptic_core/gpu_penetration_depth.h"
#include "haptic_core/haptic_scene.h"
#include "transport/udp_socket.h"

namespace ht {

/// Configuration of the remote node.
struct RemoteNodeConfig {
  SocketAddress listen_address = SocketAddress::Parse("127.0.0.1:47000");
  PipelineOptions pipeline;
  /// Where the texture penetration depth runs: cpu, gpu (headless EGL), or auto (a hardware GPU
  /// when one starts, else the CPU reference). A GPU that cannot start means the CPU, with a
  /// message; so does a GPU that fails mid-run.
  PdBackendChoice pd_backend = PdBackendChoice::kAuto;
  /// GPU options (depth precision, batch size).
  GpuPenetrationDepthOptions gpu;
  /// Upper bound on the step rate (Hz); 0 = as fast as the pipeline runs.
  double max_rate_hz = 0.0;
  /// Stop when the operator side says goodbye.
  bool exit_on_goodbye = true;
  /// Write the bound address's port here once listening ("" = don't).
  std::string port_file;
  /// Print a progress line every this many seconds (0 = never).
  double progress_period_s = 1.0;
};

/// Runs the node on `scene` until `stop` becomes true (or a goodbye arrives when
/// exit_on_goodbye). Returns the run's summary (rates, step-time percentiles, datagram counters).
/// Throws std::runtime_error if the socket cannot be bound or the port file cannot be written.
nlohmann::json RunRemoteNode(const RemoteNodeConfig& config, const HapticScene& scene,
                             const std::atomic<bool>& stop);

}  // namespace ht
