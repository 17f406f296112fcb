// A scene from a file, rebuilt when the file changes (slave_sim/watched_scene.h).
#include "slave_sim/watched_scene.h"

#include <chrono>
#include <cstdio>
#include <fstream>
#include <set>

namespace ht {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

std::vector<std::filesystem::path> SceneInputFiles(const std::string& path) {
  std::vector<std::filesystem::path> files{path};
  try {
    std::string gltf = path;
    if (std::filesystem::path(path).extension() == ".json") {
      gltf = LoadSceneInput(path).gltf_path;
      files.emplace_back(gltf);
    }
    if (std::filesystem::path(gltf).extension() == ".gltf") {
      std::ifstream in(gltf);
      const nlohmann::json doc = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
      if (doc.is_object()) {
        for (const char* key : {"buffers", "images"}) {
          if (!doc.contains(key) || !doc[key].is_array()) continue;
          for (const nlohmann::json& e : doc[key]) {
            if (!e.is_object() || !e.contains("uri") || !e["uri"].is_string()) continue;
            if (auto file = GltfLocalFile(gltf, e["uri"].get<std::string>())) {
              files.push_back(std::move(*file));
            }
          }
        }
      }
    }
  } catch (const std::exception&) {
    // The build reports what is wrong with the file; the watcher keeps what it has.
  }
  std::set<std::filesystem::path> seen;
  std::vector<std::filesystem::path> unique;
  for (const auto& f : files) {
    if (seen.insert(f.lexically_normal()).second) unique.push_back(f);
  }
  return unique;
}

WatchedScene::WatchedScene(std::string path, std::string tool, HapticModelCache cache,
                           SceneBuildProgress progress)
    : path_(std::move(path)),
      tool_(std::move(tool)),
      cache_(std::move(cache)),
      progress_(std::move(progress)) {
  files_ = SceneInputFiles(path_);
  current_ = Build();
}

WatchedScene::~WatchedScene() {
  stop_.store(true, std::memory_order_release);
  if (watcher_.joinable()) watcher_.join();
}

std::unique_ptr<WatchedScene::Version> WatchedScene::Build() const {
  auto v = std::make_unique<Version>();
  v->built = BuildScene(LoadSceneInput(path_, tool_), cache_, progress_);
  if (v->built.haptic.touchables.empty()) {
    int tools = 0, display = 0;
    for (const SceneNode& obj : v->built.objects) {
      tools += obj.spec.role == NodeRole::kTool;
      display += obj.spec.role == NodeRole::kDisplay;
    }
    throw std::runtime_error(
        path_ + ": nothing to touch: the scene has " + std::to_string(v->built.objects.size()) +
        " mesh node(s) (" + std::to_string(tools) + " tool, " + std::to_string(display) +
        " display); give a glTF with a mesh node, or a scene description that leaves one "
        "touchable");
  }
  v->stream = MakeDisplayStream(v->built);
  return v;
}

std::vector<WatchedScene::FileStamp> WatchedScene::Stamps() const {
  std::vector<FileStamp> out;
  for (const auto& f : files_) {
    FileStamp s;
    std::error_code ec;
    s.size = std::filesystem::file_size(f, ec);
    if (!ec) s.mtime = std::filesystem::last_write_time(f, ec);
    s.exists = !ec;
    if (ec) s.size = 0;
    out.push_back(s);
  }
  return out;
}

void WatchedScene::Animate(double time_s) {
  AnimateScene(current_->built, 0, time_s, &current_->animation_scratch);
}

void WatchedScene::DisplayPoses(double time_s, std::vector<wire::NodePose>* poses) {
  DisplayNodePosesAt(current_->built, current_->stream, time_s, &current_->pose_scratch, poses);
}

void WatchedScene::StartWatching(double period_s) {
  if (watcher_.joinable()) return;
  watcher_ = std::thread([this, period_s] { Watch(period_s); });
}

void WatchedScene::Watch(double period_s) {
  const auto period = std::chrono::duration<double>(period_s);
  std::vector<FileStamp> built = Stamps();
  std::vector<FileStamp> seen = built;
  std::chrono::steady_clock::time_point changed_at{};
  while (!stop_.load(std::memory_order_acquire)) {
    // Sleep a period in short steps, so that a stop is seen at once.
    const auto wake = std::chrono::steady_clock::now() + period;
    while (std::chrono::steady_clock::now() < wake && !stop_.load(std::memory_order_acquire)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    if (stop_.load(std::memory_order_acquire)) return;
    const std::vector<FileStamp> now = Stamps();
    if (now != seen) {  // still changing (or just changed): wait until it holds still
      if (seen == built) changed_at = std::chrono::steady_clock::now();
      seen = now;
      continue;
    }
    if (now == built) continue;
    bool all_there = true;
    for (const FileStamp& s : now) all_there = all_there && s.exists;
    if (!all_there) continue;  // a file is away (an editor's rename): wait for it
    std::printf("[slave] scene file changed: rebuilding %s\n", path_.c_str());
    std::fflush(stdout);
    const auto t0 = std::chrono::steady_clock::now();
    try {
      std::unique_ptr<Version> v = Build();
      const double build_s = SecondsSince(t0);
      std::lock_guard<std::mutex> lock(mutex_);
      pending_ = std::move(v);
      last_build_s_ = build_s;
      last_change_to_ready_s_ = SecondsSince(changed_at);
      std::printf("[slave] scene rebuilt in %.2f s; the pipeline switches at the next step\n",
                  build_s);
    } catch (const std::exception& e) {
      std::lock_guard<std::mutex> lock(mutex_);
      ++builds_failed_;
      last_error_ = e.what();
      std::printf(
          "[slave] scene file changed but does not build (%s); the current version "
          "stays\n",
          e.what());
    }
    std::fflush(stdout);
    built = now;
    // The files a description or glTF reads may have changed with it.
    const std::vector<std::filesystem::path> files = SceneInputFiles(path_);
    if (files != files_) {
      std::lock_guard<std::mutex> lock(mutex_);
      files_ = files;
      built = seen = Stamps();
    }
  }
}

bool WatchedScene::TakeReload() {
  std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock() || !pending_) return false;
  previous_ = std::move(current_);
  current_ = std::move(pending_);
  ++reloads_;
  return true;
}

nlohmann::json WatchedScene::StatsJson() const {
  std::lock_guard<std::mutex> lock(mutex_);
  nlohmann::json files = nlohmann::json::array();
  for (const auto& f : files_) files.push_back(f.string());
  return {{"watching", watcher_.joinable()},
          {"files", files},
          {"reloads", reloads_},
          {"builds_failed", builds_failed_},
          {"last_error", last_error_},
          {"last_build_s", last_build_s_},
          {"last_change_to_ready_s", last_change_to_ready_s_}};
}

}  // namespace ht
