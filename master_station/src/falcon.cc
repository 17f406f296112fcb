// Novint Falcon, the device: FalconDevice (configuration checks, Open with the firmware load,
// the I/O thread that exchanges one frame per period, and the wait-free hand-offs with the
// haptic loop).

#include "master_station/falcon.h"

#include <chrono>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <thread>
#include <vector>

#include "falcon_internal.h"
#include "haptic_core/steady_clock.h"

namespace ht::falcon {
namespace {

using detail::Clock;

}  // namespace

// ---------------------------------------------------------------------------------------------
// Device
// ---------------------------------------------------------------------------------------------

FalconDevice::FalconDevice(FalconConfig config, FalconTransportFactory factory)
    : config_(std::move(config)), factory_(std::move(factory)) {
  if (config_.max_motor_command < 1 || config_.max_motor_command > 32767) {
    throw std::invalid_argument("Novint Falcon: max_motor_command " +
                                std::to_string(config_.max_motor_command) + " outside 1..32767");
  }
  if (!(config_.exchange_period_s > 0.0) || !(config_.exchange_period_s <= 0.1)) {
    throw std::invalid_argument("Novint Falcon: exchange period " +
                                std::to_string(config_.exchange_period_s) + " s outside (0, 0.1]");
  }
  if (config_.exchange_timeout_ms < 1 || config_.start_timeout_ms < 1 ||
      !(config_.wrench_timeout_s > 0.0) || !(config_.stale_after_s > 0.0) ||
      !(config_.velocity_cutoff_hz > 0.0)) {
    throw std::invalid_argument(
        "Novint Falcon: timeouts, staleness and velocity cut-off must be positive");
  }
  if (!factory_) {
    factory_ = [bus = config_.usb_bus, address = config_.usb_address] {
      return std::unique_ptr<FalconTransport>(new LibusbFalconTransport(bus, address));
    };
  }
}

FalconDevice::~FalconDevice() { Close(); }

DeviceCapabilities FalconDevice::capabilities() const {
  DeviceCapabilities c;
  c.name = "Novint Falcon (libusb)";
  c.max_force_n = 8.9;  // Novint: "force capabilities > 8.9 N" (H3DAPI wiki, Novint Falcon)
  c.max_torque_nm = 0.0;
  c.max_stiffness_n_per_m = 3000.0;  // CHAI3D cFalconDevice m_maxForceStiffness
  c.max_rotational_stiffness_nm_per_rad = 0.0;
  c.max_damping_ns_per_m = 20.0;  // CHAI3D cFalconDevice m_maxLinearDamping
  c.rated_loop_rate_hz = 1.0 / config_.exchange_period_s;
  // Novint: 4" x 4" x 4" 3D touch workspace (H3DAPI wiki): ±2" = ±0.0508 m about M's origin (a
  // cube: the same in D and M).
  c.workspace_half_extents_m = {0.0508, 0.0508, 0.0508};
  c.dof_in = 3;
  c.dof_out = 3;
  return c;
}

void FalconDevice::Open() {
  if (open_.load()) return;
  std::vector<std::uint8_t> image = ReadFirmwareFile(config_.firmware_path);
  try {
    transport_ = factory_();
    if (!transport_) throw std::runtime_error("Novint Falcon: no transport was made");
    protocol_ = std::make_unique<FalconProtocol>(*transport_);
    protocol_->LoadFirmware(image);
    // The firmware answers every request once it runs (libnifalcon isFirmwareLoaded).
    FalconRequest hello;
    hello.homing_mode = true;
    hello.leds = kLedRed;
    FalconResponse first;
    bool answered = false;
    const auto deadline = Clock::now() + std::chrono::milliseconds(config_.start_timeout_ms);
    while (!answered && Clock::now() < deadline) {
      answered =
          protocol_->Exchange(hello, first, config_.exchange_timeout_ms) == ExchangeResult::kOk;
      if (!answered) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    if (!answered) {
      throw std::runtime_error(
          "Novint Falcon: the firmware was loaded but the Falcon does not answer; is its power "
          "supply plugged in? Power-cycle it and retry");
    }
  } catch (...) {
    protocol_.reset();
    transport_.reset();
    throw;
  }
  Sample drained;
  while (samples_.Read(drained)) {
  }
  have_sample_ = false;
  homed_ = false;
  homed_mask_ = 0;
  exchanges_ = 0;
  malformed_ = 0;
  io_errors_ = 0;
  timeouts_ = 0;
  kinematics_faults_ = 0;
  saturated_ = 0;
  commands_.Write(ForceCommand{});
  stop_ = false;
  io_thread_ = std::thread([this] { IoLoop(); });
  open_ = true;
}

void FalconDevice::Close() noexcept {
  open_ = false;
  stop_ = true;
  if (io_thread_.joinable()) io_thread_.join();  // the loop's last request commands zero
  protocol_.reset();
  transport_.reset();
}

void FalconDevice::IoLoop() noexcept {
  const auto period = std::chrono::nanoseconds(
      static_cast<std::int64_t>(std::llround(config_.exchange_period_s * 1e9)));
  const auto wrench_timeout_ns = static_cast<std::int64_t>(config_.wrench_timeout_s * 1e9);
  const double tau_filter_s = 1.0 / (2.0 * std::numbers::pi * config_.velocity_cutoff_hz);
  ForceCommand force;
  glm::dvec3 p_DH{0.0};
  glm::dvec3 v_DH_D{0.0};
  bool have_position = false;
  std::int64_t t_position_ns = 0;
  bool homed = false;
  auto next = Clock::now();
  // The clock is passed in (FalconConfig::clock_ns): readings and freshness use it.
  const auto clock_ns = [this]() noexcept {
    return config_.clock_ns ? config_.clock_ns() : SteadyNowNs();
  };

  while (!stop_.load(std::memory_order_relaxed)) {
    ForceCommand newest;
    if (commands_.Read(newest)) force = newest;
    const std::int64_t now_ns = clock_ns();

    FalconRequest request;
    request.homing_mode = !homed;
    request.leds = homed ? kLedGreen : kLedRed;
    const bool fresh = force.valid && std::abs(now_ns - force.t_ns) <= wrench_timeout_ns;
    if (homed && have_position && fresh) {
      glm::dmat3 J;
      if (HandleJacobian(p_DH, J)) {
        const MotorCommands mc =
            TorquesToMotorCommands(TorquesForForce(J, force.F_H_D), config_.max_motor_command);
        request.motor_command = mc.command;
        if (mc.saturated) saturated_.fetch_add(1, std::memory_order_relaxed);
      } else {
        kinematics_faults_.fetch_add(1, std::memory_order_relaxed);
      }
    }

    FalconResponse response;
    const ExchangeResult result =
        protocol_->Exchange(request, response, config_.exchange_timeout_ms);
    malformed_.store(protocol_->malformed_frames(), std::memory_order_relaxed);
    if (result == ExchangeResult::kOk) {
      const std::int64_t t_ns = clock_ns();
      exchanges_.fetch_add(1, std::memory_order_relaxed);
      homed_mask_.store(response.homed_mask, std::memory_order_relaxed);
      homed = (response.homed_mask & kAllAxesHomed) == kAllAxesHomed;
      homed_.store(homed, std::memory_order_relaxed);
      Sample sample;
      sample.homed = homed;
      sample.buttons = response.buttons;
      sample.t_ns = t_ns;
      if (homed) {
        const MotorAngles theta = {EncoderToMotorAngle(response.encoder[0]),
                                   EncoderToMotorAngle(response.encoder[1]),
                                   EncoderToMotorAngle(response.encoder[2])};
        glm::dvec3 p = have_position ? p_DH : glm::dvec3(0.0);
        if (ForwardKinematics(theta, p)) {
          if (have_position) {
            const double dt = static_cast<double>(t_ns - t_position_ns) * 1e-9;
            if (dt > 0.0) {
              const double alpha = dt / (dt + tau_filter_s);
              v_DH_D += alpha * ((p - p_DH) / dt - v_DH_D);
            }
          } else {
            v_DH_D = glm::dvec3(0.0);
          }
          p_DH = p;
          t_position_ns = t_ns;
          have_position = true;
        } else {
          kinematics_faults_.fetch_add(1, std::memory_order_relaxed);
        }
      } else {
        have_position = false;
      }
      sample.p_DH = p_DH;
      sample.v_DH_D = v_DH_D;
      // A reading whose kinematics failed is not published as new.
      if (!homed || t_position_ns == t_ns) samples_.Write(sample);
    } else if (result == ExchangeResult::kTimeout) {
      timeouts_.fetch_add(1, std::memory_order_relaxed);
    } else {
      io_errors_.fetch_add(1, std::memory_order_relaxed);
    }

    next += period;
    const auto now = Clock::now();
    if (next < now) next = now;
    std::this_thread::sleep_until(next);
  }

  // Leave the motors unpowered and the LEDs off.
  FalconRequest zero;
  FalconResponse ignored;
  protocol_->Exchange(zero, ignored, config_.exchange_timeout_ms);
}

bool FalconDevice::ReadState(std::int64_t now_ns, DeviceState& state) noexcept {
  if (!open_.load(std::memory_order_acquire)) return false;
  Sample s;
  if (samples_.Read(s)) {
    last_sample_ = s;
    have_sample_ = true;
  }
  if (!have_sample_ || !last_sample_.homed) return false;
  if (now_ns - last_sample_.t_ns > static_cast<std::int64_t>(config_.stale_after_s * 1e9)) {
    return false;
  }
  state.X_MH = RigidTransform{kR_MD * last_sample_.p_DH, glm::dquat(1.0, 0.0, 0.0, 0.0)};
  state.V_MH_M = Twist{kR_MD * last_sample_.v_DH_D, glm::dvec3(0.0)};
  state.buttons = last_sample_.buttons;
  state.timestamp_ns = last_sample_.t_ns;
  return true;
}

bool FalconDevice::WriteWrench(const Wrench& F_H_M, std::int64_t now_ns) noexcept {
  if (!open_.load(std::memory_order_acquire)) return false;
  ForceCommand command;
  command.t_ns = now_ns;
  if (!IsFinite(F_H_M)) {
    command.valid = true;  // render zero
    commands_.Write(command);
    return false;
  }
  command.F_H_D = glm::transpose(kR_MD) * F_H_M.force;
  command.valid = true;
  commands_.Write(command);
  return true;
}

FalconStatus FalconDevice::status() const noexcept {
  FalconStatus s;
  s.running = open_.load();
  s.homed = homed_.load();
  s.homed_mask = homed_mask_.load();
  s.exchanges = exchanges_.load();
  s.malformed_frames = malformed_.load();
  s.io_errors = io_errors_.load();
  s.read_timeouts = timeouts_.load();
  s.kinematics_faults = kinematics_faults_.load();
  s.saturated_commands = saturated_.load();
  return s;
}

}  // namespace ht::falcon
