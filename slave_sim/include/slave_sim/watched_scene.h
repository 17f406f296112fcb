#pragma once
// A scene from a file that the remote node watches: when the file (or the glTF a
// description names, or a buffer or image that glTF reads) changes on disk, a background thread
// rebuilds the haptic models through the model cache and the display stream; the node's loop
// adopts the new version between two steps (TakeReload), switches its pipeline to it and streams
// the objects whose bytes changed as new versions.

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "haptic_core/model_build/haptic_model_build.h"
#include "slave_sim/display_scene.h"
#include "slave_sim/scene_build.h"

namespace ht {

/// The scene of a file, rebuilt when the file changes. Construction, Animate, DisplayPoses and
/// TakeReload belong to one thread (the node's loop); the watcher runs on its own.
class WatchedScene {
 public:
  /// Builds the scene of `path` (LoadSceneInput(path, tool), BuildScene through `cache`,
  /// MakeDisplayStream), calling `progress` per model. Throws what those throw, and
  /// std::runtime_error naming `path` when the scene has no touchable object (nothing to touch).
  WatchedScene(std::string path, std::string tool, HapticModelCache cache,
               SceneBuildProgress progress = {});
  /// Stops the watcher (waits for a build in progress to finish).
  ~WatchedScene();
  WatchedScene(const WatchedScene&) = delete;
  WatchedScene& operator=(const WatchedScene&) = delete;

  /// The current version's built scene, haptic scene and display stream.
  const BuiltScene& built() const noexcept { return current_->built; }
  const HapticScene& haptic() const noexcept { return current_->built.haptic; }
  const DisplayStream& stream() const noexcept { return current_->stream; }
  /// Files the watcher looks at: the input, the glTF it names, and that glTF's relative buffer
  /// and image files.
  const std::vector<std::filesystem::path>& watched_files() const noexcept { return files_; }

  /// Moves the touchables to animation 0 at `time_s` (AnimateScene). Allocates nothing once
  /// warmed up.
  void Animate(double time_s);
  /// The moving nodes' local poses at `time_s` (DisplayNodePosesAt).
  void DisplayPoses(double time_s, std::vector<wire::NodePose>* poses);

  /// Starts the watcher thread: every `period_s` it compares each watched file's size and
  /// modification time with the last build's; a change that holds still for one more period
  /// (an editor's save in several writes) starts a rebuild on the watcher thread. A build that
  /// fails (a half-written or broken file) is counted with its message and the current version
  /// stays; the next change is tried again.
  void StartWatching(double period_s = 0.5);
  /// On the loop thread: adopts a rebuilt version when one is ready (never blocks). True when
  /// adopted: built(), haptic() and stream() are then the new version's; the previous version
  /// stays alive until the next adoption, so references the caller still holds stay valid while
  /// it switches over.
  bool TakeReload();

  /// {"watching", "files", "reloads", "builds_failed", "last_error", "last_build_s",
  ///  "last_change_to_ready_s"} for the run summary.
  nlohmann::json StatsJson() const;

 private:
  struct Version {
    BuiltScene built;
    DisplayStream stream;
    std::vector<glm::dmat4> animation_scratch;
    std::vector<GltfNodePose> pose_scratch;
  };
  struct FileStamp {
    std::uintmax_t size = 0;
    std::filesystem::file_time_type mtime{};
    bool exists = false;
    bool operator==(const FileStamp&) const = default;
  };
  std::unique_ptr<Version> Build() const;
  std::vector<FileStamp> Stamps() const;
  void Watch(double period_s);

  std::string path_, tool_;
  HapticModelCache cache_;
  SceneBuildProgress progress_;
  std::vector<std::filesystem::path> files_;
  std::unique_ptr<Version> current_, previous_;

  mutable std::mutex mutex_;  // guards pending_ and the counters below
  std::unique_ptr<Version> pending_;
  std::uint64_t reloads_ = 0, builds_failed_ = 0;
  std::string last_error_;
  double last_build_s_ = 0.0, last_change_to_ready_s_ = 0.0;

  std::atomic<bool> stop_{false};
  std::thread watcher_;
};

/// The files a scene input depends on: `path` itself; for a scene description, the glTF it names;
/// for a .gltf (not .glb), every buffer and image URI that is a relative file. Never throws: a
/// file that cannot be read or parsed contributes only itself.
std::vector<std::filesystem::path> SceneInputFiles(const std::string& path);

}  // namespace ht
