#pragma once
// The operator's display: renders the scene as the operator station received it, off
// the haptic loop, on its own thread: the decoded meshes with their materials' base colours at
// their received poses, the tool at its simulated pose, the device's handle as a ghost of the
// tool, and the contact points of the contact model in use with force arrows (m per N in the
// summary, saturated at 1.5 tool radii). Headless: PNG frames through EGL (Mesa llvmpipe without
// a GPU); window: the same frames shown through GLFW. Internal to master_station.

#include <atomic>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "haptic_core/contact_model.h"
#include "haptic_core/spatial.h"
#include "master_station/lock_free.h"
#include "master_station/received_scene.h"
#include "master_station/station_config.h"

namespace ht::station {

/// What the haptic loop hands the display (newest wins, TripleBuffer): W is the remote world.
struct DisplayToolState {
  double t_s = 0.0;         ///< run time of the tick (s)
  RigidTransform X_WT;      ///< the simulated tool's pose (frame T at its centre of mass)
  RigidTransform X_WH;      ///< the device handle's pose mapped into W
  bool have_model = false;  ///< a contact model has arrived
  ContactModel model;       ///< the newest contact model (contacts at its q0)
  int phase = -1;           ///< the experiment's phase (index into phase_names; −1 = none)
  double force_n = 0.0;     ///< |F| of the contact force on the tool the loop rendered (N)
  int contacts = 0;         ///< active contacts in that force
};

/// Renders frames at config.display.frame_rate_hz until stopped; kHeadless writes them as PNG
/// files, kWindow shows them in a window (and writes them too when frames_dir is given). Never
/// throws from Run: a display that cannot start (no EGL context, an unwritable folder) is said once
/// on stderr, recorded in Summary() and the run goes on without it.
class DisplayWorker {
 public:
  /// `up_W`: the scene's up direction (the Welcome's home pose +z); `max_contact_force_n`: the
  /// loop's bound on a contact's force (N; 0 = none), applied to the arrows as the loop applies it;
  /// `phase_names`: the experiment's phases, named in the frames' overlay; `scene` and `tool` must
  /// outlive the worker.
  DisplayWorker(const DisplayConfig& config, const ReceivedScene& scene,
                TripleBuffer<DisplayToolState>& tool, const glm::dvec3& up_W,
                double max_contact_force_n, std::vector<std::string> phase_names = {});
  void Run(const std::atomic<bool>& stop);
  /// The display's part of summary.json: mode, renderer, frames written, render and write times,
  /// the arrow scale, what went wrong.
  nlohmann::json Summary() const;

 private:
  const DisplayConfig& config_;
  const ReceivedScene& scene_;
  TripleBuffer<DisplayToolState>& tool_;
  glm::dvec3 up_W_;
  double max_contact_force_n_;
  std::vector<std::string> phase_names_;
  std::string renderer_, error_;
  std::uint64_t frames_ = 0, frames_without_scene_ = 0, scene_generations_ = 0;
  std::vector<double> render_ms_, write_ms_;
  double arrow_m_per_n_ = 0.0, arrow_max_m_ = 0.0;
  std::uint64_t arrows_ = 0, arrows_saturated_ = 0;
  bool window_closed_ = false;
  std::uint64_t textures_ = 0, textures_failed_ = 0;
  std::string texture_error_;
  std::vector<std::string> frame_files_;
};

}  // namespace ht::station
