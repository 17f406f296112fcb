#include "transport/scene_graph.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <concepts>
#include <glm/gtc/matrix_transform.hpp>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string_view>

#include "haptic_core/byte_order.h"

namespace ht {
namespace {

// The rules a graph obeys, checked by the encoder (which throws) and the decoder (which returns
// false) alike, so that every graph one accepts the other accepts too.

/// True when `s` is well-formed UTF-8 (no overlong forms, surrogates or code points > U+10FFFF).
bool IsUtf8(std::string_view s) noexcept {
  std::size_t i = 0;
  while (i < s.size()) {
    const auto c = static_cast<unsigned char>(s[i]);
    std::size_t n = 0;
    std::uint32_t cp = 0;
    if (c < 0x80) {
      ++i;
      continue;
    } else if (c >= 0xC2 && c <= 0xDF) {
      n = 1;
      cp = c & 0x1Fu;
    } else if (c >= 0xE0 && c <= 0xEF) {
      n = 2;
      cp = c & 0x0Fu;
    } else if (c >= 0xF0 && c <= 0xF4) {
      n = 3;
      cp = c & 0x07u;
    } else {
      return false;
    }
    if (s.size() - i <= n) return false;
    for (std::size_t k = 1; k <= n; ++k) {
      const auto d = static_cast<unsigned char>(s[i + k]);
      if ((d & 0xC0u) != 0x80u) return false;
      cp = (cp << 6) | (d & 0x3Fu);
    }
    if ((n == 2 && cp < 0x800) || (n == 3 && cp < 0x10000) || cp > 0x10FFFF ||
        (cp >= 0xD800 && cp <= 0xDFFF)) {
      return false;
    }
    i += n + 1;
  }
  return true;
}

std::string Quoted(std::string_view s) {
  // Names in messages are cut, so that a hostile one cannot make the message huge.
  std::string q = "\"";
  q.append(s.substr(0, 40));
  if (s.size() > 40) q.append("...");
  q.push_back('"');
  return q;
}

std::string CheckName(std::string_view what, std::string_view s) {
  if (s.size() > kMaxSceneGraphNameBytes) {
    return std::string(what) + " has " + std::to_string(s.size()) + " bytes; the limit is " +
           std::to_string(kMaxSceneGraphNameBytes);
  }
  if (!IsUtf8(s)) return std::string(what) + " is not UTF-8";
  return {};
}

bool Finite(const glm::dvec3& v) noexcept {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

std::string NodeName(std::size_t i, const SceneGraphNode& n) {
  return "scene graph node " + std::to_string(i) + " (" + Quoted(n.name) + ")";
}

/// Empty when node i obeys the rules, else what is wrong with it.
std::string CheckNode(std::size_t i, const SceneGraphNode& n, std::size_t materials) {
  const std::string who = NodeName(i, n);
  if (std::string p = CheckName(who + ": the name", n.name); !p.empty()) return p;
  if (n.parent < -1 || (n.parent >= 0 && static_cast<std::size_t>(n.parent) >= i)) {
    return who + ": parent " + std::to_string(n.parent) + " is not -1 or below the node's index " +
           std::to_string(i) + " (parents come first)";
  }
  if (!Finite(n.translation)) return who + ": translation is not finite";
  const glm::dquat& q = n.rotation;
  if (!std::isfinite(q.w) || !std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z)) {
    return who + ": rotation is not finite";
  }
  const double norm2 = q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z;
  if (!(norm2 >= 1e-24) || !std::isfinite(norm2)) {
    return who + ": rotation has zero length (or one that cannot be normalized): w x y z = " +
           std::to_string(q.w) + " " + std::to_string(q.x) + " " + std::to_string(q.y) + " " +
           std::to_string(q.z);
  }
  if (!Finite(n.scale)) return who + ": scale is not finite";
  if (n.material < -1 || (n.material >= 0 && static_cast<std::size_t>(n.material) >= materials)) {
    return who + ": material " + std::to_string(n.material) + " is not -1 or below the " +
           std::to_string(materials) + " materials";
  }
  if ((n.flags & ~kSceneNodeAllFlags) != 0) {
    return who + ": flags " + std::to_string(n.flags) + " has bits other than SceneNodeFlags";
  }
  return {};
}

std::string CheckMaterial(std::size_t i, const SceneMaterial& m) {
  const std::string who = "scene material " + std::to_string(i) + " (" + Quoted(m.name) + ")";
  if (std::string p = CheckName(who + ": the name", m.name); !p.empty()) return p;
  if (std::string p = CheckName(who + ": texture_mime", m.texture_mime); !p.empty()) return p;
  const glm::vec4& c = m.base_colour_rgba;
  if (!std::isfinite(c.r) || !std::isfinite(c.g) || !std::isfinite(c.b) || !std::isfinite(c.a)) {
    return who + ": base_colour_rgba is not finite";
  }
  return {};
}

std::string CheckCamera(const SceneGraphCamera& c, std::size_t nodes) {
  if (c.node < -1 || (c.node >= 0 && static_cast<std::size_t>(c.node) >= nodes)) {
    return "scene graph camera: node " + std::to_string(c.node) + " is not -1 or below the " +
           std::to_string(nodes) + " nodes";
  }
  if (!std::isfinite(c.yfov_rad) || !std::isfinite(c.znear_m) || !std::isfinite(c.zfar_m)) {
    return "scene graph camera: yfov_rad, znear_m or zfar_m is not finite";
  }
  if (!(c.yfov_rad > 0.0 && c.yfov_rad < std::numbers::pi)) {
    return "scene graph camera: yfov_rad " + std::to_string(c.yfov_rad) + " is not in (0, pi)";
  }
  if (!(c.znear_m > 0.0)) {
    return "scene graph camera: znear_m " + std::to_string(c.znear_m) + " is not > 0";
  }
  if (c.zfar_m != 0.0 && !(c.zfar_m > c.znear_m)) {
    return "scene graph camera: zfar_m " + std::to_string(c.zfar_m) +
           " is neither 0 (infinite) nor > znear_m " + std::to_string(c.znear_m);
  }
  return {};
}

/// Empty when the graph obeys every rule, else the first problem.
std::string CheckGraph(const SceneGraphDescription& g) {
  if (std::string p = CheckName("the scene name", g.scene_name); !p.empty()) return p;
  if (g.nodes.size() > kMaxSceneGraphNodes) {
    return "the scene graph has " + std::to_string(g.nodes.size()) + " nodes; the limit is " +
           std::to_string(kMaxSceneGraphNodes);
  }
  if (g.materials.size() > kMaxSceneMaterials) {
    return "the scene graph has " + std::to_string(g.materials.size()) +
           " materials; the limit is " + std::to_string(kMaxSceneMaterials);
  }
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    if (std::string p = CheckNode(i, g.nodes[i], g.materials.size()); !p.empty()) return p;
  }
  for (std::size_t i = 0; i < g.materials.size(); ++i) {
    if (std::string p = CheckMaterial(i, g.materials[i]); !p.empty()) return p;
  }
  if (g.camera) return CheckCamera(*g.camera, g.nodes.size());
  return {};
}

// Encoding: field by field, little-endian (protocol.h has the layout).

void Put(std::vector<std::uint8_t>& out, std::uint8_t v) { out.push_back(v); }
void Put(std::vector<std::uint8_t>& out, std::uint16_t v) { AppendLe(out, v); }
void Put(std::vector<std::uint8_t>& out, std::uint32_t v) { AppendLe(out, v); }
void Put(std::vector<std::uint8_t>& out, std::int32_t v) {
  AppendLe(out, std::bit_cast<std::uint32_t>(v));
}
void Put(std::vector<std::uint8_t>& out, float v) { AppendLe(out, v); }
void Put(std::vector<std::uint8_t>& out, double v) { AppendLe(out, v); }
void Put(std::vector<std::uint8_t>& out, const glm::dvec3& v) {
  Put(out, v.x);
  Put(out, v.y);
  Put(out, v.z);
}
/// u8 length, then the bytes (the length was checked).
void PutText(std::vector<std::uint8_t>& out, std::string_view s) {
  Put(out, static_cast<std::uint8_t>(s.size()));
  out.insert(out.end(), s.begin(), s.end());
}

/// Reads the layout back; the first problem is kept and every later read does nothing.
class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> b) : b_(b) {}
  std::size_t remaining() const noexcept { return b_.size() - pos_; }
  bool ok() const noexcept { return error_.empty(); }
  const std::string& error() const noexcept { return error_; }
  void Fail(std::string message) {
    if (ok()) error_ = std::move(message);
  }

  template <std::unsigned_integral T>
  T Uint(const char* what) {
    if (!Need(sizeof(T), what)) return 0;
    const T v = LoadLe<T>(b_.data() + pos_);
    pos_ += sizeof(T);
    return v;
  }
  std::int32_t Int32(const char* what) {
    return std::bit_cast<std::int32_t>(Uint<std::uint32_t>(what));
  }
  float F32(const char* what) { return std::bit_cast<float>(Uint<std::uint32_t>(what)); }
  double F64(const char* what) { return std::bit_cast<double>(Uint<std::uint64_t>(what)); }
  glm::dvec3 Vec3(const char* what) {
    const double x = F64(what), y = F64(what), z = F64(what);
    return {x, y, z};
  }
  std::string Text(const char* what) {
    const std::uint8_t n = Uint<std::uint8_t>(what);
    if (!Need(n, what)) return {};
    std::string s(reinterpret_cast<const char*>(b_.data() + pos_), n);
    pos_ += n;
    return s;
  }

 private:
  bool Need(std::size_t n, const char* what) {
    if (ok() && remaining() < n) {
      Fail(std::string("truncated at byte ") + std::to_string(pos_) + " (" + what +
           "): " + std::to_string(n) + " bytes needed, " + std::to_string(remaining()) + " left");
    }
    return ok();
  }
  std::span<const std::uint8_t> b_;
  std::size_t pos_ = 0;
  std::string error_;
};

bool Failed(std::string* error, std::string message) {
  if (error != nullptr) *error = "scene graph: " + std::move(message);
  return false;
}

glm::dmat4 LocalMatrix(const SceneNodeTransform& t) {
  const glm::dquat& q = t.rotation;
  const double norm = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  const glm::dquat unit = norm > 0.0 ? q / norm : glm::dquat(1.0, 0.0, 0.0, 0.0);
  return glm::translate(glm::dmat4(1.0), t.translation) * glm::mat4_cast(unit) *
         glm::scale(glm::dmat4(1.0), t.scale);
}

}  // namespace

std::string SceneGraphName(std::string_view name) {
  if (!IsUtf8(name)) return "";
  std::size_t end = std::min(name.size(), kMaxSceneGraphNameBytes);
  // Back off continuation bytes (10xxxxxx) so that the cut falls between two characters.
  while (end < name.size() && end > 0 && (static_cast<unsigned char>(name[end]) & 0xC0u) == 0x80u) {
    --end;
  }
  return std::string(name.substr(0, end));
}

std::vector<std::uint8_t> EncodeSceneGraph(const SceneGraphDescription& g) {
  if (std::string problem = CheckGraph(g); !problem.empty()) throw std::invalid_argument(problem);
  std::vector<std::uint8_t> out;
  out.reserve(16 + g.scene_name.size() + g.nodes.size() * (wire::kSceneGraphNodeMinBytes + 16) +
              g.materials.size() * (wire::kSceneMaterialMinBytes + 16) +
              wire::kSceneGraphCameraBytes);
  Put(out, wire::kSceneGraphMagic);
  Put(out, wire::kSceneGraphFormatVersion);
  PutText(out, g.scene_name);
  Put(out, static_cast<std::uint16_t>(g.nodes.size()));
  Put(out, static_cast<std::uint16_t>(g.materials.size()));
  for (const SceneGraphNode& n : g.nodes) {
    PutText(out, n.name);
    Put(out, n.parent);
    Put(out, n.translation);
    Put(out, n.rotation.w);
    Put(out, n.rotation.x);
    Put(out, n.rotation.y);
    Put(out, n.rotation.z);
    Put(out, n.scale);
    Put(out, n.mesh_object);
    Put(out, n.material);
    Put(out, n.flags);
  }
  for (const SceneMaterial& m : g.materials) {
    PutText(out, m.name);
    Put(out, m.base_colour_rgba.r);
    Put(out, m.base_colour_rgba.g);
    Put(out, m.base_colour_rgba.b);
    Put(out, m.base_colour_rgba.a);
    Put(out, m.base_colour_texture_object);
    PutText(out, m.texture_mime);
  }
  Put(out, static_cast<std::uint8_t>(g.camera ? 1 : 0));
  if (g.camera) {
    Put(out, g.camera->node);
    Put(out, g.camera->yfov_rad);
    Put(out, g.camera->znear_m);
    Put(out, g.camera->zfar_m);
  }
  return out;
}

bool DecodeSceneGraph(std::span<const std::uint8_t> bytes, SceneGraphDescription* out,
                      std::string* error) {
  if (out == nullptr) return Failed(error, "no output given");
  Reader r(bytes);
  const auto magic = r.Uint<std::uint32_t>("magic");
  if (r.ok() && magic != wire::kSceneGraphMagic) {
    return Failed(error, "bad magic (not a scene-graph object)");
  }
  const auto version = r.Uint<std::uint16_t>("format version");
  if (r.ok() && version != wire::kSceneGraphFormatVersion) {
    return Failed(error, "format version " + std::to_string(version) + ", this build reads " +
                             std::to_string(wire::kSceneGraphFormatVersion));
  }
  SceneGraphDescription g;
  g.scene_name = r.Text("scene name");
  const auto node_count = r.Uint<std::uint16_t>("node count");
  const auto material_count = r.Uint<std::uint16_t>("material count");
  if (!r.ok()) return Failed(error, r.error());
  if (material_count > kMaxSceneMaterials) {
    return Failed(error, std::to_string(material_count) + " materials; the limit is " +
                             std::to_string(kMaxSceneMaterials));
  }
  // Before allocating: the counts must fit the bytes left, at the smallest size of each element.
  const std::size_t least = node_count * wire::kSceneGraphNodeMinBytes +
                            material_count * wire::kSceneMaterialMinBytes + 1;
  if (least > r.remaining()) {
    return Failed(error, std::to_string(node_count) + " nodes and " +
                             std::to_string(material_count) + " materials need at least " +
                             std::to_string(least) + " bytes; " + std::to_string(r.remaining()) +
                             " are left");
  }
  g.nodes.resize(node_count);
  g.materials.resize(material_count);
  for (SceneGraphNode& n : g.nodes) {
    n.name = r.Text("node name");
    n.parent = r.Int32("node parent");
    n.translation = r.Vec3("node translation");
    const double w = r.F64("node rotation"), x = r.F64("node rotation"), y = r.F64("node rotation"),
                 z = r.F64("node rotation");
    n.rotation = glm::dquat(w, x, y, z);
    n.scale = r.Vec3("node scale");
    n.mesh_object = r.Uint<std::uint32_t>("node mesh_object");
    n.material = r.Int32("node material");
    n.flags = r.Uint<std::uint8_t>("node flags");
    if (!r.ok()) return Failed(error, r.error());
  }
  for (SceneMaterial& m : g.materials) {
    m.name = r.Text("material name");
    const float red = r.F32("material base_colour_rgba"),
                green = r.F32("material base_colour_rgba"),
                blue = r.F32("material base_colour_rgba"),
                alpha = r.F32("material base_colour_rgba");
    m.base_colour_rgba = glm::vec4(red, green, blue, alpha);
    m.base_colour_texture_object = r.Uint<std::uint32_t>("material texture object");
    m.texture_mime = r.Text("material texture_mime");
    if (!r.ok()) return Failed(error, r.error());
  }
  const auto has_camera = r.Uint<std::uint8_t>("has_camera");
  if (!r.ok()) return Failed(error, r.error());
  if (has_camera > 1) {
    return Failed(error, "has_camera is " + std::to_string(has_camera) + ", not 0 or 1");
  }
  if (has_camera == 1) {
    SceneGraphCamera c;
    c.node = r.Int32("camera node");
    c.yfov_rad = r.F64("camera yfov_rad");
    c.znear_m = r.F64("camera znear_m");
    c.zfar_m = r.F64("camera zfar_m");
    if (!r.ok()) return Failed(error, r.error());
    g.camera = c;
  }
  if (r.remaining() > 0) {
    return Failed(error, std::to_string(r.remaining()) + " bytes after the end of the graph");
  }
  if (std::string problem = CheckGraph(g); !problem.empty()) {
    return Failed(error, std::move(problem));
  }
  *out = std::move(g);
  return true;
}

std::vector<SceneNodeTransform> RestTransforms(const SceneGraphDescription& graph) {
  std::vector<SceneNodeTransform> out(graph.nodes.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    const SceneGraphNode& n = graph.nodes[i];
    out[i] = {n.translation, n.rotation, n.scale};
  }
  return out;
}

std::vector<glm::dmat4> ComposeWorldPoses(const SceneGraphDescription& graph) {
  return ComposeWorldPoses(graph, {});
}

std::vector<glm::dmat4> ComposeWorldPoses(const SceneGraphDescription& graph,
                                          std::span<const SceneNodeTransform> local) {
  const std::size_t n = graph.nodes.size();
  if (!local.empty() && local.size() != n) {
    throw std::invalid_argument("ComposeWorldPoses: " + std::to_string(local.size()) +
                                " local transforms for " + std::to_string(n) + " nodes");
  }
  std::vector<glm::dmat4> X_WN(n);
  for (std::size_t i = 0; i < n; ++i) {
    const SceneGraphNode& node = graph.nodes[i];
    const std::int32_t p = node.parent;
    if (p < -1 || (p >= 0 && static_cast<std::size_t>(p) >= i)) {
      throw std::invalid_argument("ComposeWorldPoses: " + NodeName(i, node) + " has parent " +
                                  std::to_string(p) + ", not -1 or below its index");
    }
    const glm::dmat4 X_PN = LocalMatrix(
        local.empty() ? SceneNodeTransform{node.translation, node.rotation, node.scale} : local[i]);
    X_WN[i] = p < 0 ? X_PN : X_WN[static_cast<std::size_t>(p)] * X_PN;
  }
  return X_WN;
}

SceneNodePoses::SceneNodePoses(const SceneGraphDescription& graph, std::uint32_t graph_version)
    : graph_version_(graph_version),
      local_(RestTransforms(graph)),
      time_s_(graph.nodes.size(), -std::numeric_limits<double>::infinity()),
      newest_time_s_(-std::numeric_limits<double>::infinity()) {}

std::size_t SceneNodePoses::Apply(const wire::NodePosesMessage& m) noexcept {
  if (m.graph_version != graph_version_) {
    ++stats_.messages_other_graph;
    return 0;
  }
  std::size_t applied = 0;
  const int count = std::min<int>(m.count, wire::kMaxNodePosesPerDatagram);
  for (int i = 0; i < count; ++i) {
    const wire::NodePose& p = m.poses[static_cast<std::size_t>(i)];
    if (p.node >= local_.size()) {
      ++stats_.entries_bad_node;
      continue;
    }
    if (!(m.scene_time_s >= time_s_[p.node])) {  // older (or NaN, which the decoder refuses)
      ++stats_.entries_stale;
      continue;
    }
    time_s_[p.node] = m.scene_time_s;
    local_[p.node] = {glm::dvec3(p.translation),
                      glm::dquat(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z),
                      glm::dvec3(p.scale)};
    ++applied;
  }
  stats_.entries_applied += applied;
  if (applied > 0 && m.scene_time_s > newest_time_s_) newest_time_s_ = m.scene_time_s;
  return applied;
}

double SceneNodePoses::node_time_s(std::size_t node) const noexcept {
  return node < time_s_.size() ? time_s_[node] : -std::numeric_limits<double>::infinity();
}

}  // namespace ht
