#pragma once
// The remote node's configuration (RunRemoteNode, remote_node.h), in a header of its own so that
// the session code below the node (remote_session.h) can take it without the node.

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "haptic_core/gpu_penetration_depth.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/remote_step.h"
#include "slave_sim/display_scene.h"
#include "transport/auth.h"
#include "transport/deadband.h"
#include "transport/messages.h"
#include "transport/udp_socket.h"

namespace ht {

/// Configuration of the remote node.
struct RemoteNodeConfig {
  SocketAddress listen_address = SocketAddress::Parse("127.0.0.1:47000");
  PipelineOptions pipeline;
  /// Where the texture penetration depth runs: cpu, gpu (headless EGL), or auto (a hardware GPU
  /// when one starts, else the CPU backend). A GPU that cannot start means the CPU, with a
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
  /// Say goodbye to the operator when stopped (false simulates a crash, for tests).
  bool goodbye_on_stop = true;
  /// Each session's streams start after this sequence number (0: at 1), for tests of what happens
  /// near the end of the header's u32 sequence (wire::kSequenceRenewAt: Goodbye, a new session).
  std::uint64_t start_sequences_at = 0;
  /// Pre-shared key: every datagram is authenticated with it (see transport/protocol.h).
  MacKey key;
  /// Largest datagram for scene fragments (bytes, kMinMtuBytes..kMaxDatagramBytes); a session uses
  /// the smaller of this and the operator's.
  std::size_t mtu = 1472;
  /// An operator that has sent nothing authenticated for this long is declared lost (ms); the
  /// session uses the larger of this and the operator's.
  int peer_timeout_ms = 500;
  /// Largest perceptual deadband (Weber fraction, [0, 1)) accepted from an operator on either
  /// stream; a Hello asking more is refused with a Reject that says so.
  double max_deadband = 0.5;
  /// The speculative floor by the round trip (PipelineOptions::speculative_floor_m): before each
  /// step the node sets the floor to this hand speed (m/s) times
  /// the round trip the operator's newest Ping reports, at most max_speculative_floor_m. A model
  /// answers a tool pose a round trip old; a hand at this speed can meanwhile have covered that
  /// much towards a surface the pose was clear of (lifted and pressed again, turned towards it),
  /// and the model then holds that surface already (δ0 < 0, no force until the tool reaches it
  /// on the operator's local model). At a loopback's or a LAN's round trip (≤ 1 ms) the floor is
  /// a few micrometres and changes nothing; at 150 ms one way with the defaults, 6 mm. 0 turns
  /// it off (the pipeline's own floor stays). RunRemoteNode throws std::invalid_argument for a
  /// negative or non-finite value. The default, 25 mm/s, covers the seed's scripted press (about
  /// 22 mm/s at its fastest) and the recorded human motion (14 mm/s); its measurements are in
  /// docs/measurements.md (PipelineOptions::speculative_floor_m).
  double speculative_speed_m_per_s = 0.025;
  /// The largest floor set by the round trip (m, ≥ 0).
  double max_speculative_floor_m = 6e-3;
  /// Offer depth fields (protocol.h kCodecDepthFields): for a session whose operator takes them,
  /// stage 5d renders each contact's depth field (PipelineOptions::depth_fields) and the node
  /// sends each field's DepthFieldFragments before the first model that names it; the
  /// operator's loop evaluates the fields at its own tool pose.
  bool depth_fields = true;
  /// A field's travel margin for a session: this hand speed (m/s) times the round trip the
  /// operator's newest Ping reports, at least depth_field_min_margin_m (m); the margin is cut to
  /// what fits kMaxDepthFieldSide nodes a side (PipelineOptions::depth_field_margin_m).
  double depth_field_speed_m_per_s = 0.05;
  double depth_field_min_margin_m = 2e-3;
  /// Floors and keep-alive of the contact-model deadband; its Weber fraction and keep-alive come
  /// from the session (the operator asks them in its Hello).
  ContactModelDeadbandConfig model_deadband;
  /// Pace of scene fragments (bytes per second), so that they never crowd out contact models.
  double scene_rate_bytes_per_s = 4e6;
  /// Scene objects streamed to the operator at join (DisplayStream::objects: the scene graph,
  /// Draco meshes in their own frames, base-colour images), by object id.
  std::vector<StreamObject> scene_objects;
  /// Local poses of the scene graph's moving nodes at `elapsed_s` (seconds since the node
  /// started, the clock `animate` is called with), written into `poses` (cleared first; its
  /// capacity is kept, so that it allocates only when it grows). Called at display_rate_hz while
  /// a session with the scene is open, on the node's loop thread; must not throw. Empty = nothing
  /// moves.
  std::function<void(double elapsed_s, std::vector<wire::NodePose>* poses)> display_poses;
  /// Rate of NodePoses frames (Hz, 1..1000).
  double display_rate_hz = 60.0;
  /// Called on the node's loop thread before each pass: returns a new version of the scene when
  /// one is ready (its scene file changed and was rebuilt, e.g. WatchedScene::TakeReload), with
  /// its display stream's objects in `objects`; null otherwise. The node then switches its
  /// pipeline to the returned scene (which must outlive the node or the next switch) between two
  /// steps and streams the objects whose bytes changed as new versions. Must not block. Empty =
  /// the scene never changes.
  std::function<const HapticScene*(std::vector<StreamObject>* objects)> take_reload;
  /// Called before each step with the seconds since the node started, to move animated objects
  /// of the scene (e.g. AnimateScene() on a scene from a file); empty = a static scene. It runs on
  /// the stepping thread and must not throw.
  std::function<void(double elapsed_s)> animate;
  /// Where to write one CSV row per remote step once the node stops ("" = don't): `step, t_s,
  /// leaf_pairs, clusters, contacts, broad_phase_culled, collision_us, texture_us, total_us,
  /// budget_exhausted, tool_state_seq, cause, free_space_clearance_mm` (the split of seed
  /// Fig. 77; the newest tool state answered, why the node stepped, the free space it found). The
  /// first 2^20 steps are kept, in memory reserved at start, so the step loop never writes a file.
  std::string step_trace_path;
};

}  // namespace ht
