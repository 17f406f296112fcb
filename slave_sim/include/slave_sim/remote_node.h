#pragma once
// The remote simulation node: receives tool states, runs the haptic texture pipeline at the
// latest one as fast as it can (independent of the network rate), and streams contact models.

#include <atomic>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "haptic_core/gpu_penetration_depth.h"
#include "haptic_core/haptic_scene.h"
#include "haptic_core/remote_step.h"
#include "slave_sim/display_scene.h"
#include "slave_sim/remote_node_config.h"
#include "transport/auth.h"
#include "transport/deadband.h"
#include "transport/messages.h"
#include "transport/udp_socket.h"

namespace ht {

/// The built-in block-on-gear scene (or the stiff wall, `scene`) as a display stream: the ridged
/// block's and the ridged gear's full-resolution meshes (the wall's coarse mesh), Draco-compressed
/// (14-bit positions, speed 5), with their scene graph.
DisplayStream BlockOnGearDisplayStream(const HapticScene& scene);

/// The scene's layout that every Welcome carries (wire::SceneLayout): the tool's home pose (whose
/// +z is the scene's up), the tool's mass and principal moments, and, for the touchable objects
/// (the kMaxWelcomeTargets largest by bounding-box diagonal, largest first), their bounds in W at
/// their current poses, widened by the texture's outward reach (HapticModel::OutwardReach()),
/// their highest coarse vertex along up, and the hand height above it where the tool touches
/// nothing (checked with HullProximityQuery against every touchable). Never throws except
/// std::bad_alloc.
wire::SceneLayout MakeSceneLayout(const HapticScene& scene);

/// The speculative floor (m) the node sets for a round trip (ns; ≤ 0: none measured yet):
/// config.speculative_speed_m_per_s × the round trip, at most config.max_speculative_floor_m; 0
/// when the speed is 0 or no round trip is known. noexcept.
double SpeculativeFloorForRoundTrip(const RemoteNodeConfig& config,
                                    std::int64_t operator_rtt_ns) noexcept;

/// Runs the node on `scene` until `stop` becomes true (or a goodbye arrives when
/// exit_on_goodbye). Sessions: a Hello (authenticated, fresh nonce) opens one, replacing any
/// other; the node steps only while a session is open, and closes it on Goodbye or when the
/// operator is silent for the peer timeout, then waits for the next Hello. Returns the run's
/// summary (rates, step-time percentiles, per-stream statistics, sessions). Throws
/// std::runtime_error if the socket cannot be bound or the port file cannot be written, and
/// std::invalid_argument for a bad MTU, pipeline option or deadband setting.
nlohmann::json RunRemoteNode(const RemoteNodeConfig& config, const HapticScene& scene,
                             const std::atomic<bool>& stop);

}  // namespace ht
