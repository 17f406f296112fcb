// The remote scene as the operator station has received it (master_station/received_scene.h).
#include "master_station/received_scene.h"

namespace ht {

void ReceivedScene::Set(std::shared_ptr<const ReceivedSceneContent> content) {
  std::lock_guard<std::mutex> lock(mutex_);
  const bool same_graph = content_ && content && content_->graph_version != 0 &&
                          content->graph_version == content_->graph_version &&
                          content->graph.nodes.size() == content_->graph.nodes.size();
  content_ = std::move(content);
  ++generation_;
  if (same_graph) return;  // only a mesh or an image changed: the poses received still hold
  poses_.reset();
  tracks_.clear();
  if (content_) poses_.emplace(content_->graph, content_->graph_version);
}

std::size_t ReceivedScene::ApplyPoses(const wire::NodePosesMessage& message) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.messages;
  if (!poses_) {
    ++stats_.messages_before_scene;
    stats_.entries_dropped += message.count;
    return 0;
  }
  const std::size_t applied = poses_->Apply(message);
  stats_.entries_applied += applied;
  for (std::size_t i = 0; i < message.count && i < message.poses.size(); ++i) {
    const std::uint16_t node = message.poses[i].node;
    if (node >= poses_->local().size() || poses_->node_time_s(node) != message.scene_time_s) {
      continue;  // not applied (stale, or not a node of this graph)
    }
    auto it = tracks_.find(node);
    if (it == tracks_.end()) {
      if (tracks_.size() >= kMaxTrackedNodes) continue;
      ReceivedNodeTrack t;
      t.node = node;
      t.name = content_->graph.nodes[node].name;
      t.first_time_s = message.scene_time_s;
      t.first = poses_->local()[node];
      it = tracks_.emplace(node, t).first;
    }
    ++it->second.updates;
    it->second.last_time_s = message.scene_time_s;
    it->second.last = poses_->local()[node];
  }
  stats_.entries_dropped += message.count - applied;
  return applied;
}

std::shared_ptr<const ReceivedSceneContent> ReceivedScene::Content(
    std::uint64_t* generation) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (generation != nullptr) *generation = generation_;
  return content_;
}

void ReceivedScene::CopyPoses(std::vector<SceneNodeTransform>* local) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!poses_) {
    local->clear();
    return;
  }
  local->assign(poses_->local().begin(), poses_->local().end());
}

std::vector<ReceivedNodeTrack> ReceivedScene::node_tracks() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<ReceivedNodeTrack> out;
  for (const auto& [node, track] : tracks_) out.push_back(track);
  return out;
}

ReceivedPoseStats ReceivedScene::pose_stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

}  // namespace ht
