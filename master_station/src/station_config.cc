// The operator station's configuration (station_config.h): its checks, and the operator tick's
// configuration it gives (operator_station.h).
#include "master_station/station_config.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>

#include "master_station/operator_station.h"

namespace ht {

void StationConfig::Validate() const {
  if (!(max_contact_force_n >= 0.0)) {
    throw std::invalid_argument("the bound on a contact's force must be >= 0 N (0 = none)");
  }
  if (display.mode != DisplayConfig::Mode::kNone) {
    if (!(display.frame_rate_hz >= 0.1 && display.frame_rate_hz <= 120.0)) {
      throw std::invalid_argument("display frame rate must be within 0.1..120 frames/s, got " +
                                  std::to_string(display.frame_rate_hz));
    }
    if (display.width < 16 || display.width > 4096 || display.height < 16 ||
        display.height > 4096) {
      throw std::invalid_argument("display size must be within 16..4096 pixels each, got " +
                                  std::to_string(display.width) + "x" +
                                  std::to_string(display.height));
    }
    if (display.max_frames < 0) throw std::invalid_argument("display max frames must be >= 0");
    if (!(display.camera_distance_m >= 0.0 && display.camera_distance_m <= 1e4)) {
      throw std::invalid_argument("camera distance must be within 0..10000 m (0 = automatic)");
    }
  }
  if (display.mode == DisplayConfig::Mode::kHeadless && display.frames_dir.empty() &&
      out_dir.empty()) {
    throw std::invalid_argument(
        "--display headless writes PNG frames: give --frames-dir DIR (or --out DIR, whose "
        "frames/ folder is then used)");
  }
  if (display.mode == DisplayConfig::Mode::kWindow) {
    const char* x11 = std::getenv("DISPLAY");
    const char* wayland = std::getenv("WAYLAND_DISPLAY");
    if ((x11 == nullptr || *x11 == '\0') && (wayland == nullptr || *wayland == '\0')) {
      throw std::invalid_argument(
          "--display window needs a display server, but DISPLAY and WAYLAND_DISPLAY are unset "
          "(on a machine without one, use --display headless --frames-dir DIR)");
    }
  }
  if (!(loop_rate_hz >= 100.0 && loop_rate_hz <= 4000.0)) {
    throw std::invalid_argument("loop rate must be within 100..4000 Hz, got " +
                                std::to_string(loop_rate_hz));
  }
  if (!IsFiniteRigidTransform(X_WM)) throw std::invalid_argument("X_WM must be finite");
  if (!(connect_timeout_s > 0.0)) throw std::invalid_argument("connect timeout must be positive");
  if (mtu < static_cast<int>(wire::kMinMtuBytes) ||
      mtu > static_cast<int>(wire::kMaxDatagramBytes)) {
    throw std::invalid_argument("MTU must be within 548..1472 bytes, got " + std::to_string(mtu));
  }
  if (heartbeat_ms < 10 || heartbeat_ms > 10000) {
    throw std::invalid_argument("heartbeat must be within 10..10000 ms");
  }
  if (peer_timeout_ms <= heartbeat_ms || peer_timeout_ms > 60000) {
    throw std::invalid_argument("peer timeout must be above the heartbeat (" +
                                std::to_string(heartbeat_ms) + " ms) and at most 60000 ms, got " +
                                std::to_string(peer_timeout_ms));
  }
  if (model_blend_ticks < 1 || model_blend_ticks > 100) {
    throw std::invalid_argument("model blend ticks must be within 1..100");
  }
  if (reconnect_period_ms < 10) throw std::invalid_argument("reconnect period must be >= 10 ms");
  if (!(passivity_reserve_j >= 0.0 && passivity_reserve_j <= 1.0)) {
    throw std::invalid_argument("passivity reserve must be within 0..1 J, got " +
                                std::to_string(passivity_reserve_j));
  }
  if (!(passivity_refill_fraction >= 0.0 && passivity_refill_fraction < 1.0)) {
    throw std::invalid_argument("passivity refill fraction must be within [0, 1), got " +
                                std::to_string(passivity_refill_fraction));
  }
  if (!(passivity_release_ms >= 0.0 && passivity_release_ms <= 10000.0)) {
    throw std::invalid_argument("passivity release must be within 0..10000 ms, got " +
                                std::to_string(passivity_release_ms));
  }
  if (!(switch_offset_release_ms > 0.0)) {  // +∞ allowed; NaN refused
    throw std::invalid_argument("switch offset release must be > 0 ms, got " +
                                std::to_string(switch_offset_release_ms));
  }
  if (max_grid < 0 || max_grid > 65535) throw std::invalid_argument("max grid must be 0..65535");
  coupling.Validate();
  safety.Validate();
  if (!(stop_ramp_s >= 0.0 && stop_ramp_s <= 10.0)) {
    throw std::invalid_argument("stop ramp must be within 0..10 s, got " +
                                std::to_string(stop_ramp_s));
  }
  if (run_until_stopped && stop_requested == nullptr) {
    throw std::invalid_argument(
        "run_until_stopped needs stop_requested (a flag a signal handler sets), or the run "
        "would never end");
  }
  tool_state_deadband.Validate();
  if (!(tool_state_deadband.keepalive_s >= 1e-3 && tool_state_deadband.keepalive_s <= 60.0)) {
    throw std::invalid_argument("tool-state keep-alive must be within 1 ms..60 s");
  }
  if (!(model_deadband >= 0.0 && model_deadband < 1.0)) {
    throw std::invalid_argument("contact-model deadband must be in [0, 1), got " +
                                std::to_string(model_deadband));
  }
  if (!(model_keepalive_s >= 1e-3 && model_keepalive_s < safety.model_timeout_s)) {
    throw std::invalid_argument(
        "contact-model keep-alive must be at least 1 ms and below the model timeout (" +
        std::to_string(safety.model_timeout_s) +
        " s), or the force would fade between models; "
        "got " +
        std::to_string(model_keepalive_s) + " s");
  }
}

OperatorTickConfig OperatorTickConfigFor(const StationConfig& config,
                                         const DeviceCapabilities& caps, const ToolInertia& inertia,
                                         double h_s) {
  OperatorTickConfig tick_config;
  tick_config.inertia = inertia;
  tick_config.coupling = config.coupling;
  // The device's own limits bound the configured ones (a device without force output gets a
  // vanishing limit: it renders nothing).
  tick_config.safety = config.safety;
  tick_config.safety.max_force_n =
      std::max(1e-9, std::min(config.safety.max_force_n, caps.max_force_n));
  tick_config.safety.max_torque_nm =
      std::max(1e-9, std::min(config.safety.max_torque_nm, caps.max_torque_nm));
  tick_config.model_blend_ticks = config.model_blend_ticks;
  tick_config.passivity = config.passivity;
  // The added damping is capped (4 x the device's rated damping: the controller acts for single
  // ticks, well inside what a 1 kHz device renders); energy it cannot dissipate in one tick stays
  // in the observer (E < 0) and is dissipated on the next ones.
  tick_config.passivity_max_damping_ns_per_m = 4.0 * caps.max_damping_ns_per_m;
  tick_config.passivity_reserve_j = config.passivity_reserve_j;
  tick_config.passivity_refill_fraction = config.passivity_refill_fraction;
  tick_config.passivity_release_ticks =
      static_cast<int>(std::lround(config.passivity_release_ms * 1e-3 / h_s));
  tick_config.energy_bounded_switch = config.energy_bounded_switch;
  tick_config.switch_offset_release_ms = config.switch_offset_release_ms;
  tick_config.h_s = h_s;
  tick_config.max_contact_force_n = config.max_contact_force_n > 0.0
                                        ? config.max_contact_force_n
                                        : std::numeric_limits<double>::infinity();
  tick_config.hunt_crossley_s_per_m = config.hunt_crossley_s_per_m;
  return tick_config;
}

}  // namespace ht
