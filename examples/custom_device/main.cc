// A custom device backend: a class that implements ht::HapticDevice
// (master_station/include/master_station/haptic_device.h) and runs in the operator station
// against a remote node, as the Falcon, SpaceMouse and replay backends do. Copy it and replace
// the bodies of Open, Close, ReadState and WriteWrench with your device's driver calls.
//
// This one has no hardware: a "probe rig" whose handle is held by a stiff hand that follows a
// fixed path in the device base M (+z up): down from 2 mm above the workspace centre to 2 mm
// below it in the first second, then side to side along x (±6 mm, 2 s period). The wrench the
// station commands pushes the handle off that path (the hand's stiffness, 1,000 N/m, with a
// 20 ms lag), so the loop closes as with a person.
//
// Usage: custom_device HOST:PORT KEY_FILE [SECONDS] [OUT_DIR]
//   against a running `slave_sim --listen HOST:PORT --key KEY_FILE` (block-on-gear: the workspace
//   centre is the block's home, 0.5 mm above the gear); OUT_DIR gets trace.csv and summary.json.
// Prints the loop's rate (Hz), the largest contact count, the wrenches written, the largest
// force commanded to the handle |F_H_M| (N) and the handle's lowest z in M (mm). Exits 0 when
// the device felt a contact (|F| > 0.5 N), 1 when not, 2 on an error.
//
// Built in the tree (the operator station's library, master_station_lib, is not installed):
// HT_BUILD_EXAMPLES, on by default, makes build/examples/custom_device/custom_device; ctest
// runs it against a slave_sim (example_custom_device, tests/example_custom_device_test.sh).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <numbers>

#include "master_station/experiment.h"
#include "master_station/haptic_device.h"
#include "master_station/operator_station.h"
#include "transport/auth.h"

namespace {

class ProbeRigDevice final : public ht::HapticDevice {
 public:
  ht::DeviceCapabilities capabilities() const override {
    ht::DeviceCapabilities caps;
    caps.name = "example probe rig";
    caps.max_force_n = 8.0;
    caps.max_torque_nm = 0.5;
    caps.max_stiffness_n_per_m = 2000.0;
    caps.max_rotational_stiffness_nm_per_rad = 2.0;
    caps.max_damping_ns_per_m = 10.0;
    caps.workspace_half_extents_m = glm::dvec3(0.05);
    return caps;  // 6 DoF in and out, rated at 1 kHz, moved by a person (not scripted)
  }
  // A real backend opens its port here and throws std::runtime_error saying what to do.
  void Open() override {
    open_ = true;
    started_ = false;
    F_H_M_ = {};
  }
  // A real backend commands zero wrench, then releases the device.
  void Close() noexcept override {
    F_H_M_ = {};
    open_ = false;
  }

  // Called every tick (1 kHz): noexcept, no allocation, no lock, no I/O beyond the device's.
  bool ReadState(std::int64_t now_ns, ht::DeviceState& state) noexcept override {
    if (!open_) return false;
    if (!started_) {
      t0_ns_ = last_ns_ = now_ns;
      p_MH_ = Path(0.0);
      started_ = true;
    }
    const double t = static_cast<double>(now_ns - t0_ns_) * 1e-9;
    const double dt = static_cast<double>(now_ns - last_ns_) * 1e-9;
    const glm::dvec3 target = Path(t) + F_H_M_.force / kHandStiffness;  // the hand yields
    const glm::dvec3 p_before = p_MH_;
    p_MH_ += (target - p_MH_) * std::min(1.0, dt / kHandLag_s);
    state.X_MH = {p_MH_, glm::dquat(1.0, 0.0, 0.0, 0.0)};
    state.V_MH_M = {dt > 0.0 ? (p_MH_ - p_before) / dt : glm::dvec3(0.0), glm::dvec3(0.0)};
    state.timestamp_ns = now_ns;
    last_ns_ = now_ns;
    lowest_z_m = std::min(lowest_z_m, p_MH_.z);
    return true;
  }
  bool WriteWrench(const ht::Wrench& F_H_M, std::int64_t) noexcept override {
    if (!open_) return false;
    F_H_M_ = F_H_M;
    ++wrenches_written;
    largest_force_n = std::max(largest_force_n, glm::length(F_H_M.force));
    return true;
  }

  std::int64_t wrenches_written = 0;
  double largest_force_n = 0.0, lowest_z_m = 0.0;

 private:
  static constexpr double kHandStiffness = 1000.0;  // N/m
  static constexpr double kHandLag_s = 0.02;
  // The hand's path in M (m) at t seconds.
  static glm::dvec3 Path(double t) {
    const double down = std::min(t, 1.0);
    const double z = 2e-3 - 4e-3 * (0.5 - 0.5 * std::cos(std::numbers::pi * down));
    const double x = t > 1.0 ? 6e-3 * std::sin(std::numbers::pi * (t - 1.0)) : 0.0;
    return {x, 0.0, z};
  }
  bool open_ = false, started_ = false;
  std::int64_t t0_ns_ = 0, last_ns_ = 0;
  glm::dvec3 p_MH_{0.0};
  ht::Wrench F_H_M_;
};

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: custom_device HOST:PORT KEY_FILE [SECONDS] [OUT_DIR]\n");
    return 2;
  }
  try {
    ht::StationConfig config;
    config.remote_address = ht::SocketAddress::Parse(argv[1]);
    config.key = ht::LoadKeyFile(argv[2]);
    config.out_dir = argc > 4 ? argv[4] : "";
    config.progress_period_s = 0.0;
    // The experiment gives the run's length and the trace's phase names; this device is not
    // scripted, so its hand does not follow the experiment's path.
    const auto experiment = ht::MakeExperiment("fig75", argc > 3 ? std::stod(argv[3]) : 4.0);
    ProbeRigDevice device;
    const nlohmann::json summary = ht::RunOperatorStation(config, device, *experiment);
    std::printf(
        "custom_device: loop %.0f Hz, contacts max %d, %lld wrenches written, largest "
        "|F_H_M| %.2f N, lowest handle z %.2f mm (in M)\n",
        summary["operator_rate_hz"].get<double>(), summary["contacts_max"].get<int>(),
        static_cast<long long>(device.wrenches_written), device.largest_force_n,
        device.lowest_z_m * 1e3);
    return device.largest_force_n > 0.5 ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "custom_device: error: %s\n", e.what());
    return 2;
  }
}
