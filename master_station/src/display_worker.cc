// The operator's display thread (display_worker.h).
#include "display_worker.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <thread>

#include "haptic_core/contact_linearization.h"
#include "haptic_core/statistics.h"
#include "haptic_core/steady_clock.h"
#include "master_station/display_window.h"
#include "master_station/frame_overlay.h"
#include "master_station/png_image.h"
#include "master_station/scene_renderer.h"

namespace ht::station {
namespace {

constexpr glm::vec4 kDefaultColour{0.70f, 0.70f, 0.72f, 1.0f};
constexpr glm::vec4 kHandleGhostColour{0.55f, 0.85f, 1.0f, 1.0f};
// A dark blue-grey (linear; about 0.1 once sRGB-encoded).
constexpr glm::vec4 kBackground{0.010f, 0.010f, 0.013f, 1.0f};
// Longest arrow drawn, in tool radii (longer ones are saturated).
constexpr double kArrowMaxRadii = 1.5;

RenderMesh ToRenderMesh(const ReceivedSceneContent::Mesh& m) {
  RenderMesh r;
  r.positions_N.reserve(m.mesh_N.vertices.size());
  for (const glm::dvec3& p : m.mesh_N.vertices) r.positions_N.emplace_back(p);
  r.triangles.reserve(m.mesh_N.triangles.size());
  for (const glm::ivec3& t : m.mesh_N.triangles) r.triangles.emplace_back(t);
  if (m.uv_N.size() == m.mesh_N.vertices.size()) {
    r.uv.reserve(m.uv_N.size());
    for (const glm::dvec2& uv : m.uv_N) r.uv.emplace_back(uv);
  }
  return r;
}

// Nodes that move with the tool: the tool node and its descendants (parents come first).
std::vector<bool> UnderTool(const SceneGraphDescription& g) {
  std::vector<bool> under(g.nodes.size(), false);
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    const SceneGraphNode& n = g.nodes[i];
    under[i] = (n.flags & kSceneNodeTool) != 0 ||
               (n.parent >= 0 && static_cast<std::size_t>(n.parent) < i &&
                under[static_cast<std::size_t>(n.parent)]);
  }
  return under;
}

}  // namespace

DisplayWorker::DisplayWorker(const DisplayConfig& config, const ReceivedScene& scene,
                             TripleBuffer<DisplayToolState>& tool, const glm::dvec3& up_W,
                             double max_contact_force_n, std::vector<std::string> phase_names)
    : config_(config),
      scene_(scene),
      tool_(tool),
      up_W_(up_W),
      max_contact_force_n_(max_contact_force_n > 0.0 ? max_contact_force_n
                                                     : std::numeric_limits<double>::infinity()),
      phase_names_(std::move(phase_names)) {}

void DisplayWorker::Run(const std::atomic<bool>& stop) {
  std::unique_ptr<SceneRenderer> renderer;
  std::unique_ptr<DisplayWindow> window;
  const bool write_frames = !config_.frames_dir.empty();
  try {
    if (write_frames) std::filesystem::create_directories(config_.frames_dir);
    // Base colours are linear (glTF); the frames are sRGB images, like the textures.
    renderer = SceneRenderer::Create(config_.width, config_.height, ColourEncoding::kSrgb);
    renderer_ = renderer->gpu().renderer;
    if (config_.mode == DisplayConfig::Mode::kWindow) {
      window = DisplayWindow::Open(config_.width, config_.height, "master_station: remote scene");
    }
  } catch (const std::exception& e) {
    error_ = std::string("the display could not start: ") + e.what();
    std::fprintf(stderr, "[master] %s; the run goes on without it\n", error_.c_str());
    return;
  }
  std::printf("[master] display: %s, %dx%d at %.1f frames/s%s%s (%s)\n",
              window ? "window" : "headless", config_.width, config_.height, config_.frame_rate_hz,
              write_frames ? " into " : "", config_.frames_dir.c_str(), renderer_.c_str());
  std::fflush(stdout);

  std::uint64_t generation = 0;
  std::shared_ptr<const ReceivedSceneContent> content;
  std::map<std::uint32_t, int> mesh_index;  // object id → renderer mesh
  std::map<std::uint32_t, double> mesh_radius;
  std::map<std::uint32_t, bool> mesh_has_uv;
  std::map<std::uint32_t, int> texture_index;  // image object id → renderer texture (−1 failed)
  std::map<std::uint32_t, std::uint32_t> texture_version;  // image object id → version uploaded
  std::vector<bool> under_tool;
  double tool_radius_m = 0.02;
  std::vector<SceneNodeTransform> local;
  DisplayToolState tool{};
  bool have_tool = false;
  RenderFrame frame;
  std::vector<std::uint8_t> rgba;
  const std::int64_t period_ns = static_cast<std::int64_t>(1e9 / config_.frame_rate_hz);
  std::int64_t next = SteadyNowNs();
  while (!stop.load(std::memory_order_acquire)) {
    const std::int64_t now = SteadyNowNs();
    if (now < next) {
      std::this_thread::sleep_for(std::chrono::nanoseconds(std::min<std::int64_t>(
          next - now, 20'000'000)));  // wakes at least every 20 ms to see a stop
      continue;
    }
    next += period_ns;
    if (next < now) next = now + period_ns;  // fell behind: no burst of frames
    if (tool_.Read(tool)) have_tool = true;
    std::uint64_t g = 0;
    std::shared_ptr<const ReceivedSceneContent> c = scene_.Content(&g);
    if (!c || !have_tool) {
      ++frames_without_scene_;
      continue;
    }
    try {
      if (g != generation) {
        // A new scene version: upload new or changed meshes.
        content = std::move(c);
        generation = g;
        ++scene_generations_;
        for (const ReceivedSceneContent::Mesh& m : content->meshes) {
          if (m.mesh_N.triangles.empty()) continue;
          const RenderMesh r = ToRenderMesh(m);
          if (auto it = mesh_index.find(m.object_id); it != mesh_index.end()) {
            renderer->ReplaceMesh(it->second, r);
          } else {
            mesh_index[m.object_id] = renderer->AddMesh(r);
          }
          mesh_has_uv[m.object_id] = m.uv_N.size() == m.mesh_N.vertices.size();
          double radius = 0.0;
          for (const glm::dvec3& p : m.mesh_N.vertices) radius = std::max(radius, glm::length(p));
          mesh_radius[m.object_id] = radius;
        }
        // Base-colour textures, decoded once per object (PNG or JPEG as the file had them).
        // A new version of an image is uploaded as a new texture (the old one stays allocated:
        // the renderer has no release; edits of a texture are rare).
        for (const ReceivedSceneContent::Image& image : content->images) {
          if (const auto v = texture_version.find(image.object_id);
              v != texture_version.end() && v->second == image.version) {
            continue;
          }
          texture_version[image.object_id] = image.version;
          int w = 0, h = 0;
          try {
            const std::vector<std::uint8_t> pixels = DecodeImage(image.bytes, &w, &h);
            texture_index[image.object_id] = renderer->AddTexture(pixels, w, h);
            ++textures_;
          } catch (const std::exception& e) {
            texture_index[image.object_id] = -1;  // drawn in its base colour
            ++textures_failed_;
            texture_error_ = e.what();
          }
        }
        under_tool = UnderTool(content->graph);
        tool_radius_m = 0.0;
        for (std::size_t i = 0; i < content->graph.nodes.size(); ++i) {
          const SceneGraphNode& n = content->graph.nodes[i];
          if ((n.flags & kSceneNodeTool) == 0 || mesh_radius.count(n.mesh_object) == 0) continue;
          const double s =
              std::max({std::abs(n.scale.x), std::abs(n.scale.y), std::abs(n.scale.z)});
          tool_radius_m =
              std::max(tool_radius_m, glm::length(n.translation) + s * mesh_radius[n.mesh_object]);
        }
        if (!(tool_radius_m > 1e-4)) tool_radius_m = 0.02;
        // Arrows: half the tool's radius per newton, so that a 2 N contact spans the tool.
        arrow_m_per_n_ = 0.5 * tool_radius_m;
        arrow_max_m_ = kArrowMaxRadii * tool_radius_m;
      }
      const SceneGraphDescription& graph = content->graph;
      scene_.CopyPoses(&local);
      const std::vector<glm::dmat4> X_WN = local.size() == graph.nodes.size()
                                               ? ComposeWorldPoses(graph, local)
                                               : ComposeWorldPoses(graph);
      const glm::dmat4 X_WT = tool.X_WT.Matrix();
      const glm::dmat4 X_WH = tool.X_WH.Matrix();
      frame.items.clear();
      frame.arrows.clear();
      for (std::size_t i = 0; i < graph.nodes.size(); ++i) {
        const SceneGraphNode& n = graph.nodes[i];
        const auto m = mesh_index.find(n.mesh_object);
        if (n.mesh_object == 0 || m == mesh_index.end()) continue;
        glm::vec4 colour = kDefaultColour;
        int texture = -1;
        if (n.material >= 0 && static_cast<std::size_t>(n.material) < graph.materials.size()) {
          const SceneMaterial& material = graph.materials[static_cast<std::size_t>(n.material)];
          colour = material.base_colour_rgba;
          const auto t = texture_index.find(material.base_colour_texture_object);
          if (t != texture_index.end() && mesh_has_uv[n.mesh_object]) texture = t->second;
        }
        if (under_tool[i]) {
          // Tool nodes are posed in T: at the simulated tool, and as a ghost at the handle.
          frame.items.push_back({m->second, X_WT * X_WN[i], colour, false, texture});
          frame.items.push_back({m->second, X_WH * X_WN[i], kHandleGhostColour, true});
        } else {
          frame.items.push_back({m->second, X_WN[i], colour, false, texture});
        }
      }
      if (tool.have_model) {
        // Each contact's force on the tool at the tool's pose now, as the loop renders it:
        // −k·max(δ(q), 0)·J with δ(q) the contact's linearization (ContactDepthAt, DESIGN.md §5),
        // drawn at the contact point moved with the tool since q0.
        const Twist dq = PoseDifference(tool.X_WT, tool.model.X_WT0);
        // X_WT · X_WT0⁻¹: carries a point fixed to the tool from where it was at q0 to where it is
        // now, both in W.
        const RigidTransform X_displacement_W = tool.X_WT * tool.model.X_WT0.Inverse();
        for (int k = 0; k < tool.model.num_contacts; ++k) {
          const ContactLinearization& cl = tool.model.contacts[static_cast<std::size_t>(k)];
          PenetrationGradient J;
          const double depth = ContactDepthAt(cl, dq, &J);
          glm::dvec3 force = PenaltyWrench(depth, J, cl.stiffness_n_per_m).force;
          // As the loop renders it: held at the bound on a contact's force (EvaluateContactModel).
          if (const double f = glm::length(force); f > max_contact_force_n_) {
            force *= max_contact_force_n_ / f;
          }
          // An arrow longer than kArrowMaxRadii tool radii is drawn at that length (saturated:
          // counted), so that a grazing contact's large force does not hide the scene.
          const double length = glm::length(force) * arrow_m_per_n_;
          if (length > kArrowMaxRadii * tool_radius_m) {
            force *= kArrowMaxRadii * tool_radius_m / length;
            ++arrows_saturated_;
          }
          ++arrows_;
          frame.arrows.push_back({X_displacement_W * cl.point_W, force});
        }
      }
      frame.arrow_m_per_n = arrow_m_per_n_;
      frame.background_rgba = kBackground;
      if (config_.file_camera && graph.camera && graph.camera->node >= 0 &&
          static_cast<std::size_t>(graph.camera->node) < X_WN.size()) {
        // The scene file's camera: looks along −z of its node, +y up.
        const glm::dmat4& X_WC = X_WN[static_cast<std::size_t>(graph.camera->node)];
        frame.camera.eye_W = glm::dvec3(X_WC[3]);
        frame.camera.target_W = frame.camera.eye_W - glm::normalize(glm::dvec3(X_WC[2]));
        frame.camera.up_W = glm::dvec3(X_WC[1]);
        frame.camera.yfov_rad = graph.camera->yfov_rad;
        frame.camera.near_m = graph.camera->znear_m;
        frame.camera.far_m = graph.camera->zfar_m > 0.0 ? graph.camera->zfar_m : 1000.0;
      } else {
        // Follows the tool, from above and behind, far enough to see it and what it touches.
        frame.camera = FollowCamera(
            tool.X_WT.translation, up_W_,
            config_.camera_distance_m > 0.0 ? config_.camera_distance_m : 5.0 * tool_radius_m);
      }
      const std::int64_t t0 = SteadyNowNs();
      renderer->Render(frame, &rgba);
      if (config_.overlay) {
        // White on a black box: readable over any scene, and told apart from the tool's blue and
        // the arrows' orange (tests/png_checks.py).
        static constexpr std::uint8_t kText[4] = {255, 255, 255, 255};
        static constexpr std::uint8_t kBox[4] = {0, 0, 0, 255};
        FrameOverlayText text;
        text.t_s = tool.t_s;
        if (tool.phase >= 0 && static_cast<std::size_t>(tool.phase) < phase_names_.size()) {
          text.phase = phase_names_[static_cast<std::size_t>(tool.phase)];
        }
        text.force_n = tool.force_n;
        text.contacts = tool.contacts;
        // Two pixels per font unit up to 800 pixels wide, three above (glyphs ~14 / 21 px high).
        const int scale = renderer->width() > 800 ? 3 : 2;
        DrawTextBox(rgba, renderer->width(), renderer->height(), 4, 4, FormatFrameOverlay(text),
                    scale, kText, kBox);
      }
      const std::int64_t t1 = SteadyNowNs();
      if (write_frames) {
        char name[32];
        std::snprintf(name, sizeof(name), "frame_%05llu.png",
                      static_cast<unsigned long long>(frames_));
        WritePng(config_.frames_dir + "/" + name, renderer->width(), renderer->height(), rgba);
        if (frame_files_.size() < 100000) frame_files_.push_back(name);
      }
      if (window && !window->Show(rgba, renderer->width(), renderer->height())) {
        window_closed_ = true;
        std::printf("[master] display: the window was closed; the run goes on\n");
        std::fflush(stdout);
        return;
      }
      const std::int64_t t2 = SteadyNowNs();
      render_ms_.push_back(static_cast<double>(t1 - t0) * 1e-6);
      write_ms_.push_back(static_cast<double>(t2 - t1) * 1e-6);
      ++frames_;
      if (config_.max_frames > 0 && frames_ >= static_cast<std::uint64_t>(config_.max_frames)) {
        break;
      }
    } catch (const std::exception& e) {
      error_ = std::string("the display stopped: ") + e.what();
      std::fprintf(stderr, "[master] %s; the run goes on without it\n", error_.c_str());
      return;
    }
  }
}

nlohmann::json DisplayWorker::Summary() const {
  nlohmann::json j;
  j["mode"] = config_.mode == DisplayConfig::Mode::kWindow ? "window" : "headless";
  j["window_closed"] = window_closed_;
  j["textures"] = textures_;
  j["textures_failed"] = textures_failed_;
  j["texture_error"] = texture_error_;
  j["arrows"] = arrows_;
  j["arrows_saturated"] = arrows_saturated_;
  j["arrow_max_m"] = arrow_max_m_;
  j["frames_dir"] = config_.frames_dir;
  j["size"] = {config_.width, config_.height};
  j["frame_rate_hz"] = config_.frame_rate_hz;
  j["camera"] = config_.file_camera ? "file" : "follow";
  j["overlay"] = config_.overlay;
  j["renderer"] = renderer_;
  j["frames"] = frames_;
  j["frames_without_scene"] = frames_without_scene_;
  j["scene_versions_shown"] = scene_generations_;
  j["render_ms_p50"] = Percentile(render_ms_, 0.5);
  j["render_ms_p99"] = Percentile(render_ms_, 0.99);
  j["present_ms_p50"] = Percentile(write_ms_, 0.5);  // PNG write and/or window
  j["arrow_m_per_n"] = arrow_m_per_n_;
  j["error"] = error_;
  j["first_frame"] = frame_files_.empty() ? "" : frame_files_.front();
  j["last_frame"] = frame_files_.empty() ? "" : frame_files_.back();
  return j;
}

}  // namespace ht::station
