#pragma once
// The operator station's configuration (RunOperatorStation, operator_station.h) and its
// display's, in a header of their own so that the station's worker threads (network_worker.h,
// display_worker.h) can take them without the station.

#include <atomic>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>

#include "haptic_core/tool_simulation.h"
#include "haptic_core/wrench_safety.h"
#include "master_station/operator_tick.h"
#include "transport/auth.h"
#include "transport/deadband.h"
#include "transport/messages.h"
#include "transport/udp_socket.h"

namespace ht {

/// The operator's display of the remote scene as received (off the haptic loop, its own thread).
struct DisplayConfig {
  /// kNone renders nothing; kHeadless writes PNG frames through a headless EGL context (Mesa
  /// llvmpipe without a GPU); kWindow shows a window on a display server.
  enum class Mode { kNone, kHeadless, kWindow };
  Mode mode = Mode::kNone;
  /// Where kHeadless writes frame_00000.png, ... ("" = <out_dir>/frames).
  std::string frames_dir;
  /// Frames per second (0.1..120).
  double frame_rate_hz = 10.0;
  /// Image size (pixels, 16..4096 each).
  int width = 640;
  int height = 480;
  /// Stop rendering after this many frames (0 = none).
  int max_frames = 0;
  /// Distance of the camera that follows the tool (m; 0 = five times the tool's radius).
  double camera_distance_m = 0.0;
  /// Use the scene file's own camera (its first perspective camera) instead of following the
  /// tool. Off by default: a file's camera frames the whole scene, and the tool, its ghost and
  /// its force arrows were a few pixels in it (the Duck, 2CylinderEngine). Without a
  /// camera in the file the camera follows the tool either way.
  bool file_camera = false;
  /// Print the run time, the experiment's phase and the contact force |F| in each frame's
  /// top-left corner (frame_overlay.h).
  bool overlay = true;
};

/// Configuration of one run of the station.
struct StationConfig {
  /// When this becomes true (a signal handler sets it), the loop ramps the device's wrench to
  /// zero over `stop_ramp_s`, commands zero, closes the device and the run ends normally (the
  /// summary is written). Null: only the experiment's duration ends the run.
  const std::atomic<bool>* stop_requested = nullptr;
  double stop_ramp_s = 0.2;
  /// Run until `stop_requested` (a person at a real device), not for the experiment's duration.
  bool run_until_stopped = false;
  /// Largest trace.csv (bytes; 0 = no cap): rows beyond it are counted, not written.
  std::uint64_t trace_max_bytes = 0;
  SocketAddress remote_address = SocketAddress::Parse("127.0.0.1:47000");
  SocketAddress local_address = SocketAddress::Parse("127.0.0.1:0");
  double loop_rate_hz = 1000.0;
  /// Maps the device base M into the remote world W (X_WM): the workspace centre lands on the
  /// tool's home pose, and M's +z is the scene's up. With `workspace_from_remote` (the default)
  /// it is the home pose the remote node's Welcome gives, its translation replaced by
  /// `workspace_origin_W` when that is set; otherwise this value as given.
  RigidTransform X_WM;
  bool workspace_from_remote = true;
  std::optional<glm::dvec3> workspace_origin_W;
  /// The tool's mass properties when the remote node's Welcome gives none.
  ToolInertia tool_inertia;
  VirtualCoupling coupling;
  /// How long to wait for the first contact model before giving up (s).
  double connect_timeout_s = 10.0;
  /// Each session's streams start after this sequence number (0: at 1), for tests of what happens
  /// near the end of the header's u32 sequence (wire::kSequenceRenewAt: Goodbye, a new session).
  std::uint64_t start_sequences_at = 0;
  /// Directory for trace.csv and summary.json ("" = write nothing).
  std::string out_dir;
  /// Print progress lines to stdout every `progress_period_s` (0 = never).
  double progress_period_s = 0.5;
  /// Pre-shared key: every datagram is authenticated with it (see transport/protocol.h).
  MacKey key;
  /// Largest datagram for scene fragments (bytes); the session uses the smaller of both sides'.
  int mtu = 1472;
  /// Ping period (ms): heartbeat, round-trip time and clock offset.
  int heartbeat_ms = 100;
  /// The remote node is declared lost after this long without an authenticated datagram (ms).
  int peer_timeout_ms = 500;
  /// While no session is open, a new Hello every this many milliseconds.
  int reconnect_period_ms = 250;
  /// Most contact models per second asked of the remote node (0 = as fast as it steps); the
  /// default, 0 here, is replaced by the loop rate: more models than ticks are never used.
  double max_model_rate_hz = 0.0;
  /// A newly received contact model is blended in over this many ticks (1 = switched at once).
  int model_blend_ticks = 4;
  /// Time-domain passivity controller on the hand–device port (Ryu, Kwon & Hannaford 2004).
  bool passivity = true;
  /// Bound on each contact's force on the simulated tool (N; 0 = none): DESIGN.md §5's bounded
  /// delivered stiffness. A contact beyond it pushes with the bound and adds no stiffness
  /// (EvaluateContactModel): a guard against a contact whose depth is not a height field's
  /// (docs/hard-cases.md). The default is twice what the simulated operator and a Falcon render
  /// (about 10 N), so that an ordinary press never meets it; each engagement is a step in the force
  /// the operator feels (docs/hard-cases.md has the runs that chose it).
  double max_contact_force_n = 20.0;
  /// Hunt–Crossley contact damping α (s/m) of the simulated tool: each contact's force
  /// −kδ(1 + α·dδ/dt)∇δ (ToolSimulator::set_contact_damping_hunt_crossley; 0 = none). 20 s/m
  /// damps a 0.1 mm press as β = 2 ms would (ζ ≈ 0.3 for the 0.1 kg tool on 10⁴ N/m); measured:
  /// docs/measurements.md.
  double hunt_crossley_s_per_m = 20.0;
  /// The passivity controller's energy reserve (J, in [0, 1]; 0 = none): the store a slow hand
  /// draws on instead of the guard's cut (PassivityController::set_energy_reserve); measured:
  /// docs/measurements.md.
  double passivity_reserve_j = 1e-4;
  /// The largest change of the wrench the reserve's refill may make, a fraction of the wrench
  /// (in [0, 1)).
  double passivity_refill_fraction = 0.05;
  /// The passivity stage's release (ms, ≥ 0; 0 = off): a force the stage cut comes back over
  /// this long instead of on the next tick (OperatorTickConfig::passivity_release_ticks).
  /// Energy-bounded onsets (OperatorTickConfig::energy_bounded_switch) and the longest their
  /// depth offset is held (ms, > 0; +∞ = as the energy budget allows). On by default together:
  /// without them a late model's stored energy is cut by the guard in one-tick pulses of the
  /// whole force, a pulse train under delay. Measured: docs/measurements.md.
  double passivity_release_ms = 20.0;
  bool energy_bounded_switch = true;
  double switch_offset_release_ms = 200.0;
  /// The safety stage before the device (force/torque caps are further bounded by the device's
  /// capabilities; the contact model's age is measured on the local clock from its send time).
  SafetyLimits safety{.max_force_n = 1e9, .max_torque_nm = 1e9, .model_timeout_s = 0.5};
  /// Largest penetration-depth grid accepted from the remote node (0 = any).
  int max_grid = 0;
  /// Perceptual deadband of the tool states this station sends (transport/deadband.h): its
  /// Weber fraction (0 = every tick), floors, keep-alive and velocity-adaptive option.
  ToolStateDeadbandConfig tool_state_deadband;
  /// Weber fraction asked of the remote node for its contact models (0 = every model), and the
  /// keep-alive of that stream (s; must be below safety.model_timeout_s, or the safety stage
  /// would fade the force between two models the deadband held back).
  double model_deadband = 0.0;
  double model_keepalive_s = 0.1;
  /// Ask for contact models in the compact quantized encoding (transport/protocol.h) when the
  /// remote node has it; false keeps the float encoding.
  bool compact_models = true;
  /// Ask to send tool states as CompactToolState (66 bytes a datagram instead of 138;
  /// transport/protocol.h states its error bounds) rather than ToolState; used when the remote
  /// node agrees (Welcome's codecs).
  bool compact_tool_states = true;
  /// Ask for each contact's depth field (transport/protocol.h kCodecDepthFields): the loop then
  /// evaluates the two surfaces at its own tool pose every tick, and each contact's
  /// linearization only where its field is missing or the tool has left the field's margin.
  bool depth_fields = true;

  /// The display of the remote scene (none by default).
  DisplayConfig display;

  /// Throws std::invalid_argument naming the first bad value (rate outside 100..4000 Hz, MTU
  /// outside 548..1472, peer timeout not above the heartbeat, stop ramp outside 0..10 s,
  /// run_until_stopped without stop_requested, a deadband outside [0, 1), a headless display
  /// without a frames folder or out_dir, a window display without a display server, ...).
  void Validate() const;
};

}  // namespace ht
