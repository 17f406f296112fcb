#pragma once
// One run of the remote node (RunRemoteNode, remote_node.h), in the order RunRemoteNode calls
// its steps: the set-up (the penetration-depth backend and its warm-up, the pipeline, the socket
// and its port file, the link, the scene stream and the session), then the loop, one pass per
// Pass(): receive, switch to a rebuilt scene, say bad MACs, stream the scene, step and send the
// contact model, progress and pace; then the goodbye and the summary. Internal to slave_sim/src:
// remote_node.cc runs it, remote_node_summary.cc writes its summary.

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "haptic_core/remote_step.h"
#include "remote_session.h"
#include "remote_step_statistics.h"
#include "slave_sim/remote_node.h"
#include "transport/link.h"
#include "transport/scene_stream.h"

namespace ht::remote {

class RemoteNodeRun {
 public:
  /// The set-up. Throws std::invalid_argument for a configuration out of range, and
  /// std::runtime_error when the socket cannot be bound or the port file written.
  RemoteNodeRun(const RemoteNodeConfig& config, const HapticScene& scene);
  RemoteNodeRun(const RemoteNodeRun&) = delete;
  RemoteNodeRun& operator=(const RemoteNodeRun&) = delete;

  /// One pass of the loop; false once the node should stop (a Goodbye with exit_on_goodbye).
  bool Pass();
  /// Says goodbye to the operator (config.goodbye_on_stop) and writes the step trace.
  void Finish();
  /// The run's summary: remote_node_summary.cc.
  nlohmann::json Summary() const;

 private:
  // Receives at most kDrainPerPass datagrams, each handed to the session; false to stop.
  bool ReceiveDatagrams();
  // A rebuilt scene (config.take_reload): the pipeline switched to it between two steps, and the
  // objects whose bytes changed streamed as new versions.
  void SwitchToReloadedScene();
  // Datagrams that fail authentication, said at most every 5 s even with --quiet.
  void SayBadMacs(std::int64_t now_ns);
  // The remote step at the session's tool pose and its contact model to the operator; or, when
  // the step would see nothing new, a wait on the socket.
  void StepOrWait();
  // The speculative floor and the depth fields' margin by the operator's round trip.
  void FollowRoundTrip();
  void PrintProgress(const StepTimings& timings, int num_contacts);

  const RemoteNodeConfig& config_;
  std::string backend_message_;
  std::string gl_renderer_, gl_version_, gl_vendor_;
  bool gpu_instanced_draws_ = false;
  std::int64_t warm_up_missing_overlap_ = 0;
  std::unique_ptr<HapticTexturePipeline> pipeline_;
  std::string backend_at_start_;
  std::optional<UdpSocket> socket_;
  SocketAddress bound_;
  std::optional<SecureLink> link_;
  std::optional<SceneSender> scene_sender_;
  std::size_t scene_bytes_ = 0;
  RemoteCapabilities caps_;
  std::int64_t start_ns_ = 0;
  std::optional<RemoteSession> session_;
  RemoteStepStatistics statistics_;
  std::array<std::uint8_t, wire::kMaxDatagramBytes + 1> buffer_{};
  std::int64_t min_period_ns_ = 0;  // the pace (config.max_rate_hz)

  std::int64_t last_progress_ns_ = 0;
  std::uint64_t last_progress_steps_ = 0;
  std::uint64_t bad_mac_said_ = 0;  // bad-MAC datagrams already said
  std::int64_t bad_mac_said_ns_ = 0;
  bool reported_fallback_ = false;
  double largest_speculative_floor_m_ = 0.0;
  std::vector<StreamObject> reload_objects_;
  const HapticScene* current_scene_;  // the scene the pipeline steps (a reload moves it)
  std::uint64_t scene_reloads_ = 0;
  std::size_t reload_bytes_ = 0;
  std::int64_t first_step_ns_ = -1;  // the first step's time, and the process's CPU time then
  double first_step_cpu_s_ = 0.0;
};

/// The process's CPU time so far (s): user + system, every thread (getrusage).
double ProcessCpuSeconds() noexcept;

}  // namespace ht::remote
