#pragma once
// A device that plays a recorded handle trajectory from a CSV file at the file's own timestamps:
// for repeating a human operator's motion, or a motion recorded by this station, exactly.

#include <string>
#include <vector>

#include "master_station/haptic_device.h"

namespace ht {

/// One recorded handle pose: time (s from the start of the file), p_MH (m) and R_MH.
struct ReplaySample {
  double t_s = 0.0;
  RigidTransform X_MH;
};

/// Reads a replay trace. The CSV has a header line naming its columns; recognised are `t_s`
/// (seconds, strictly increasing; or `t`), the position `x,y,z` (m, in the device base M) and
/// optionally the rotation vector `rx,ry,rz` (rad). A station trace.csv also works: its
/// `hand_x,hand_y,hand_z` are in the remote world W, so `origin_W` (the workspace centre in W,
/// as given by --workspace-origin) is subtracted to bring them into M. Throws
/// std::runtime_error naming the file, the line and the problem (missing column, bad number,
/// non-finite value, time not increasing, fewer than 2 rows).
std::vector<ReplaySample> LoadReplayTrace(const std::string& path, const glm::dvec3& origin_W);

/// Plays samples at their timestamps from the first ReadState on: the pose is interpolated
/// linearly (position) and by slerp (rotation) between samples, the twist is the slope of the
/// interval, and after the last sample the handle holds still. Wrenches are accepted and counted,
/// not rendered (a recording cannot react).
class ReplayDevice final : public HapticDevice {
 public:
  /// Throws std::invalid_argument when fewer than 2 samples are given.
  explicit ReplayDevice(std::vector<ReplaySample> samples, std::string source = "replay");

  DeviceCapabilities capabilities() const override;
  void Open() override;
  void Close() noexcept override;
  bool ReadState(std::int64_t now_ns, DeviceState& state) noexcept override;
  bool WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept override;

  /// Seconds of motion in the file.
  double duration_s() const noexcept { return samples_.back().t_s - samples_.front().t_s; }
  /// Wrenches written so far.
  std::int64_t wrenches_written() const noexcept { return wrenches_; }

 private:
  std::vector<ReplaySample> samples_;
  std::string source_;
  bool open_ = false, started_ = false;
  std::int64_t t0_ns_ = 0;
  std::size_t cursor_ = 0;
  std::int64_t wrenches_ = 0;
};

}  // namespace ht
