#pragma once
// One run of the operator station (RunOperatorStation, operator_station.h), in the order
// RunOperatorStation calls its steps: the worker threads (network, trace recorder; the display
// once the loop starts), the wait for the session and the workspace it places, the wait for the
// first contact model, the haptic loop on its own thread with progress printed beside it, and the
// summary. Internal to master_station/src: operator_station.cc runs it, station_summary.cc writes
// its summary.

#include <array>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>

#include "display_worker.h"
#include "haptic_core/statistics.h"
#include "master_station/experiment.h"
#include "master_station/haptic_device.h"
#include "master_station/lock_free.h"
#include "master_station/operator_tick.h"
#include "master_station/station_config.h"
#include "network_worker.h"
#include "trace_recorder.h"

namespace ht::station {

/// What the haptic loop measures. The atomics are read while it runs (progress); the rest once
/// its thread has joined.
struct LoopRecord {
  /// Samples of at most `sample_capacity` ticks each (a uniform sample over longer runs).
  explicit LoopRecord(std::size_t sample_capacity)
      : compute_us(sample_capacity), period_us(sample_capacity), model_age_ms(sample_capacity) {}
  ReservoirSamples compute_us;    ///< the tick's own time (µs)
  ReservoirSamples period_us;     ///< the time between two ticks' starts (µs)
  ReservoirSamples model_age_ms;  ///< the age of the contact model in use (ms), where there is one
  std::atomic<std::int64_t> ticks_done{0};
  std::atomic<bool> done{false};
  // The last tick's figures, for the progress line.
  std::atomic<int> contacts{0}, phase{0};
  std::atomic<double> force_n{0.0}, age_ms{-1.0};
  bool stopped_by_request = false;  ///< the run ended on Ctrl-C or SIGTERM, after the ramp
  std::int64_t overruns = 0;        ///< ticks that fell more than a period behind
  std::int64_t device_write_faults = 0;
  int contacts_max = 0;
  double contact_force_max_n = 0.0;
  std::string realtime_note = "SCHED_FIFO priority 80";
  /// The ends of phases that should end free (Experiment::EndsFree) where the contact force on the
  /// tool was still above kWedgedForceN: a wedged tool. The first kWedgedKept are kept.
  static constexpr double kWedgedForceN = 1.0;
  static constexpr std::size_t kWedgedKept = 32;
  struct WedgedPhaseEnd {
    int phase = 0;
    double t_s = 0.0;      ///< the phase's last tick (s of the run)
    double force_n = 0.0;  ///< |contact force on the tool| then (N)
  };
  std::array<WedgedPhaseEnd, kWedgedKept> wedged{};
  std::int64_t wedged_count = 0;    ///< all of them (beyond kWedgedKept too)
  std::int64_t free_ends_seen = 0;  ///< the ends of phases that should end free, wedged or not
};

/// One run. The constructor opens the trace, the device and starts the network and recorder
/// threads (throws std::runtime_error when the trace cannot be written, and what the device's
/// Open throws); the destructor stops every thread it started and closes the device.
class OperatorStationRun {
 public:
  OperatorStationRun(const StationConfig& config, HapticDevice& device, Experiment& experiment);
  ~OperatorStationRun();
  OperatorStationRun(const OperatorStationRun&) = delete;
  OperatorStationRun& operator=(const OperatorStationRun&) = delete;

  /// Waits for the session (its Welcome places the workspace M, gives the tool's inertia and the
  /// touchable objects' targets), hands the experiment its scene, and sends the tool's first
  /// state. Throws std::runtime_error when a stop is requested meanwhile.
  void WaitForSession();
  /// Waits for the remote node's first contact model. Throws std::runtime_error (what to check)
  /// when none comes within connect_timeout_s, the session is refused, or a stop is requested.
  void WaitForFirstModel();
  /// Starts the display, runs the haptic loop on its own thread (real-time priority where
  /// permitted) until the experiment ends or a stop has ramped the force down, printing progress
  /// meanwhile; then stops the worker threads.
  void RunHapticLoop();
  /// The run's summary (summary.json): station_summary.cc. After RunHapticLoop.
  nlohmann::json Summary() const;
  /// The summary of a run that ended before its loop ran (no session, no first model, a stop
  /// while waiting): `error` (why, as thrown), the experiment, the device, the session's state
  /// and the transport's counts. Stops the worker threads first.
  nlohmann::json FailureSummary(const std::string& error);

 private:
  // The loop thread's body: one tick per period on the device's clock.
  void LoopThread();
  // The recorder thread's body: trace rows to trace.csv as the run goes.
  void RecorderThread();
  // Prints a progress line every progress_period_s until the loop is done.
  void PrintProgressUntilDone();
  // Stops and joins every worker thread, closes the trace and the device (once).
  void StopWorkers();
  bool StopRequested() const;
  // Throws (after stopping the workers) when a stop was requested while waiting for `what`.
  void ThrowIfStopped(const char* what);

  const StationConfig& config_;
  HapticDevice& device_;
  Experiment& experiment_;
  DeviceCapabilities caps_;       // read again after Open: some devices learn their limits there
  const std::int64_t ticks_;      // the loop's ticks (the maximum when run until stopped)
  const std::int64_t period_ns_;  // the loop's period
  std::FILE* trace_ = nullptr;

  TripleBuffer<OutgoingToolState> outgoing_;
  TripleBuffer<IncomingModel> incoming_;
  /// Depth fields from the network worker to the loop (and their buffers back).
  FieldHandoff field_handoff_;
  SpscRing<TraceRow> rows_{16384};
  Counters counters_;
  ReceivedScene received_scene_;
  std::optional<NetworkWorker> network_;  // made once the trace is open (it binds the socket)
  DisplayConfig display_config_;
  bool display_on_ = false;
  TripleBuffer<DisplayToolState> display_tool_;
  std::optional<DisplayWorker> display_;
  std::atomic<bool> stop_display_{false}, stop_network_{false}, stop_recorder_{false};
  std::thread display_thread_, network_thread_, recorder_thread_;
  bool workers_stopped_ = false;
  std::atomic<std::uint64_t> rows_dropped_{0};
  std::uint64_t rows_over_cap_ = 0;

  // The session's workspace and scene (WaitForSession), and the deadline of both waits.
  std::int64_t connect_deadline_ns_ = 0;
  RigidTransform X_WM_;
  RigidTransform X_WM_start_;
  ToolInertia tool_inertia_;
  ExperimentScene scene_M_;
  ToolState tool_start_;
  std::uint64_t tool_seq_ = 1;

  // The loop (RunHapticLoop).
  std::optional<OperatorTick> tick_;
  std::optional<LoopRecord> record_;
  double elapsed_s_ = 0.0;
};

}  // namespace ht::station
