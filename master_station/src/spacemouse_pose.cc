// 3Dconnexion SpaceMouse, shaping and mapping: configuration checks, dead zone, staleness gain,
// and SpaceMousePoseMapper (rate and position control).

#include "master_station/spacemouse_pose.h"

#include <algorithm>
#include <cmath>
#include <glm/common.hpp>
#include <numbers>
#include <stdexcept>

#include "spacemouse_internal.h"

namespace ht {
namespace {

using detail::Format;
using detail::ValidateAxisMap;

}  // namespace

// ------------------------------------------------------------------------------------------------
// 4. Shaping and mapping
// ------------------------------------------------------------------------------------------------

void ValidateSpaceMouseConfig(const SpaceMouseConfig& c) {
  auto bad = [](const char* what, double v) {
    throw std::invalid_argument(Format("spacemouse: %s, got %g", what, v));
  };
  if (!(c.dead_zone >= 0.0 && c.dead_zone < 1.0)) bad("dead_zone must be in [0, 1)", c.dead_zone);
  if (!(c.hold_s >= 0.0 && std::isfinite(c.hold_s))) bad("hold_s must be >= 0", c.hold_s);
  if (!(c.decay_s >= 0.0 && std::isfinite(c.decay_s))) bad("decay_s must be >= 0", c.decay_s);
  if (!(c.v_max_m_per_s > 0.0 && std::isfinite(c.v_max_m_per_s))) {
    bad("v_max_m_per_s must be > 0", c.v_max_m_per_s);
  }
  if (!(c.w_max_rad_per_s > 0.0 && std::isfinite(c.w_max_rad_per_s))) {
    bad("w_max_rad_per_s must be > 0", c.w_max_rad_per_s);
  }
  if (!(c.max_rotation_rad > 0.0 && c.max_rotation_rad <= std::numbers::pi)) {
    bad("max_rotation_rad must be in (0, pi]", c.max_rotation_rad);
  }
  for (int i = 0; i < 3; ++i) {
    const double h = c.workspace_half_extents_m[i];
    if (!(h > 0.0 && std::isfinite(h))) bad("workspace_half_extents_m must be > 0", h);
  }
  if (!(c.max_step_s > 0.0 && std::isfinite(c.max_step_s))) {
    bad("max_step_s must be > 0", c.max_step_s);
  }
  if (!(c.read_timeout_ms > 0 && c.read_timeout_ms <= 1000)) {
    bad("read_timeout_ms must be in (0, 1000]", c.read_timeout_ms);
  }
  if (c.mode != SpaceMouseControlMode::kRate && c.mode != SpaceMouseControlMode::kPosition) {
    bad("mode must be kRate or kPosition", static_cast<int>(c.mode));
  }
  ValidateAxisMap(c.axis_map);
}

double ApplySpaceMouseDeadZone(double v, double dead_zone) noexcept {
  const double a = std::min(std::abs(v), 1.0);
  if (!(a > dead_zone)) return 0.0;  // NaN reads 0
  return std::copysign((a - dead_zone) / (1.0 - dead_zone), v);
}

double SpaceMouseStalenessGain(double age_s, double hold_s, double decay_s) noexcept {
  if (!(age_s > hold_s)) return 1.0;
  if (!(decay_s > 0.0)) return 0.0;
  return std::clamp(1.0 - (age_s - hold_s) / decay_s, 0.0, 1.0);
}

std::array<double, 6> ShapeSpaceMouseAxes(const SpaceMouseSample& sample, std::int64_t now_ns,
                                          const SpaceMouseConfig& config) noexcept {
  std::array<double, 6> d{};
  for (int i = 0; i < 6; ++i) {
    if (sample.axis_time_ns[i] == 0) continue;
    const double age_s =
        std::max<double>(0.0, static_cast<double>(now_ns - sample.axis_time_ns[i]) * 1e-9);
    d[i] = SpaceMouseStalenessGain(age_s, config.hold_s, config.decay_s) *
           ApplySpaceMouseDeadZone(sample.axes[i], config.dead_zone);
  }
  return d;
}

SpaceMousePoseMapper::SpaceMousePoseMapper(const SpaceMouseConfig& config) : config_(config) {
  ValidateSpaceMouseConfig(config);
}

void SpaceMousePoseMapper::Reset() noexcept {
  X_MH_ = RigidTransform::Identity();
  started_ = false;
  last_ns_ = 0;
}

void SpaceMousePoseMapper::Step(const SpaceMouseSample& sample, std::int64_t now_ns,
                                DeviceState& state) noexcept {
  if (!started_) {
    started_ = true;
    last_ns_ = now_ns;
  }
  double dt = 0.0;
  if (now_ns > last_ns_) {
    dt = std::min(static_cast<double>(now_ns - last_ns_) * 1e-9, config_.max_step_s);
    last_ns_ = now_ns;
  }
  const std::array<double, 6> d = ShapeSpaceMouseAxes(sample, now_ns, config_);
  const glm::dvec3 d_t{d[kTx], d[kTy], d[kTz]};
  glm::dvec3 d_r{d[kRx], d[kRy], d[kRz]};
  const glm::dvec3& h = config_.workspace_half_extents_m;
  const RigidTransform X_prev = X_MH_;
  if (config_.mode == SpaceMouseControlMode::kRate) {
    const Twist delta{(config_.v_max_m_per_s * dt) * d_t, (config_.w_max_rad_per_s * dt) * d_r};
    RigidTransform X = Displace(X_MH_, delta);
    X.translation = glm::clamp(X.translation, -h, h);
    X.rotation = glm::normalize(X.rotation);
    const glm::dvec3 theta = RotationVectorFromQuaternion(X.rotation);
    const double angle = glm::length(theta);
    if (angle > config_.max_rotation_rad) {
      X.rotation = QuaternionFromRotationVector(theta * (config_.max_rotation_rad / angle));
    }
    X_MH_ = X;
  } else {
    const double n = glm::length(d_r);
    if (n > 1.0) d_r /= n;
    X_MH_.translation = d_t * h;
    X_MH_.rotation = QuaternionFromRotationVector(config_.max_rotation_rad * d_r);
  }
  Twist V;
  if (dt > 0.0) {
    const Twist change = PoseDifference(X_MH_, X_prev);
    V = {change.linear / dt, change.angular / dt};
  }
  state.X_MH = X_MH_;
  state.V_MH_M = V;
  state.buttons = sample.buttons;
  state.timestamp_ns = now_ns;
}

}  // namespace ht
