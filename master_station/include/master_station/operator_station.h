#pragma once
// The operator station: a 1 kHz haptic loop on the local contact model, a network thread that
// exchanges tool states and contact models with the remote node, and a recorder thread that
// writes the trace. The loop never allocates, locks, blocks or does I/O; it hands data to the
// other threads through TripleBuffer / SpscRing.

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "haptic_core/tool_simulation.h"
#include "master_station/experiment.h"
#include "master_station/haptic_device.h"
#include "transport/udp_socket.h"

namespace ht {

/// Configuration of one run of the station.
struct StationConfig {
  SocketAddress remote_address = SocketAddress::Parse("127.0.0.1:47000");
  SocketAddress local_address = SocketAddress::Parse("127.0.0.1:0");
  double loop_rate_hz = 1000.0;
  /// Maps the device base M into the remote world W (X_WM): the workspace centre lands on the
  /// tool's home pose.
  RigidTransform X_WM;
  ToolInertia tool_inertia;
  VirtualCoupling coupling;
  /// How long to wait for the first contact model before giving up (s).
  double connect_timeout_s = 10.0;
  /// Directory for trace.csv and summary.json ("" = write nothing).
  std::string out_dir;
  /// Print progress lines to stdout every `progress_period_s` (0 = never).
  double progress_period_s = 0.5;
  std::uint32_t session_id = 1;

  /// Throws std::invalid_argument naming the first bad value (rate outside 100..4000 Hz, ...).
  void Validate() const;
};

/// Runs `experiment` with `device` against the remote node. Returns the summary (the same object
/// written to summary.json). Throws std::runtime_error when the remote node never answers within
/// connect_timeout_s or a socket cannot be opened; the message says what to check.
nlohmann::json RunOperatorStation(const StationConfig& config, HapticDevice& device,
                                  const Experiment& experiment);

}  // namespace ht
