#pragma once
// The operator station: a 1 kHz haptic loop on the local contact model, a network thread that
// exchanges tool states and contact models with the remote node, and a recorder thread that
// writes the trace. The loop never allocates, locks, blocks or does I/O; it hands data to the
// other threads through TripleBuffer / SpscRing.

#include <atomic>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "haptic_core/tool_simulation.h"
#include "haptic_core/wrench_safety.h"
#include "master_station/experiment.h"
#include "master_station/haptic_device.h"
#include "master_station/operator_tick.h"
#include "master_station/station_config.h"
#include "transport/auth.h"
#include "transport/deadband.h"
#include "transport/messages.h"
#include "transport/udp_socket.h"

namespace ht {

/// The experiment's scene in the device base M from a Welcome's layout (X_WM: the workspace,
/// M in W): each target's bounds in W taken through its eight corners into an axis-aligned box
/// in M (m), its top and approach height in M, and the tool's extent below its centre (m). At
/// most layout.targets' capacity of targets; never throws but std::bad_alloc.
ExperimentScene ExperimentSceneInM(const wire::SceneLayout& layout, const RigidTransform& X_WM);

/// The operator tick's configuration the station runs with a device of capabilities `caps`, a
/// tool of `inertia` (kg, kg·m² along T's axes) and a tick of `h_s` (s, > 0): the configured
/// force and torque limits bounded by the device's (N, N·m; a device without force output gets
/// 1e-9), the passivity controller's damping capped at 4 × the device's rated damping (N·s/m),
/// passivity_release_ms in ticks (rounded), a contact-force bound of 0 read as none. Does not
/// validate (the tick's constructor throws std::invalid_argument for what it refuses).
OperatorTickConfig OperatorTickConfigFor(const StationConfig& config,
                                         const DeviceCapabilities& caps, const ToolInertia& inertia,
                                         double h_s);

/// Runs `experiment` with `device` against the remote node: opens an authenticated session
/// (Hello/Welcome; the Welcome's scene layout places the workspace and is given to the experiment
/// through Experiment::SetScene before the device is opened), runs the loop, keeps the session
/// alive (Ping/Pong; reconnects when the remote node is lost, while the loop goes on with the last
/// contact model), receives the scene, and says goodbye at the end. Returns the summary (the same
/// object written to summary.json), with per-stream statistics under "transport". Throws
/// std::runtime_error when the remote node never answers within connect_timeout_s, refuses the
/// session (with its reason), a stop is requested while waiting for it, or a socket cannot be
/// opened; the message says what to check. Where the session or its first model failed, the
/// summary.json written first has that message under "error".
nlohmann::json RunOperatorStation(const StationConfig& config, HapticDevice& device,
                                  Experiment& experiment);

}  // namespace ht
