// glTF animations: reading and checking the translation/rotation/scale channels of every
// animation, and posing the scene's instances at a time by sampling them (glTF 2.0 Appendix C).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/gtc/quaternion.hpp>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "codecs/gltf_scene.h"
#include "gltf_internal.h"

namespace ht {
namespace gltf_internal {
namespace {

const char* PathName(GltfAnimationChannel::Path path) {
  switch (path) {
    case GltfAnimationChannel::Path::kTranslation:
      return "translation";
    case GltfAnimationChannel::Path::kRotation:
      return "rotation";
    case GltfAnimationChannel::Path::kScale:
      return "scale";
  }
  return "?";
}

}  // namespace

std::vector<GltfAnimation> ReadAnimations(const tinygltf::Model& model,
                                          const std::vector<int>& first_entry,
                                          const std::vector<GltfNode>& nodes,
                                          std::vector<std::string>* notes) {
  std::vector<GltfAnimation> out;
  std::int64_t keys = 0;  // output elements kept so far, against kGltfMaxAnimationKeys
  std::size_t weights = 0, unreached = 0, matrix = 0, kept = 0;
  for (std::size_t a = 0; a < model.animations.size(); ++a) {
    const tinygltf::Animation& src = model.animations[a];
    GltfAnimation anim;
    anim.name = src.name;
    // (node, path) -> channel index, to refuse a target animated twice.
    std::map<std::pair<int, int>, std::size_t> targets;
    for (std::size_t c = 0; c < src.channels.size(); ++c) {
      const tinygltf::AnimationChannel& ch = src.channels[c];
      const std::string what =
          "animation " + std::to_string(a) + " (\"" + src.name + "\") channel " + std::to_string(c);
      if (ch.sampler < 0 || static_cast<std::size_t>(ch.sampler) >= src.samplers.size()) {
        throw LoadError(what + ": sampler " + std::to_string(ch.sampler) + " out of range [0, " +
                        std::to_string(src.samplers.size()) + ")");
      }
      if (ch.target_node < 0 || static_cast<std::size_t>(ch.target_node) >= model.nodes.size()) {
        throw LoadError(what + ": target node " + std::to_string(ch.target_node) +
                        " out of range [0, " + std::to_string(model.nodes.size()) + ")");
      }
      GltfAnimationChannel out_ch;
      out_ch.node = ch.target_node;
      if (ch.target_path == "translation") {
        out_ch.path = GltfAnimationChannel::Path::kTranslation;
      } else if (ch.target_path == "rotation") {
        out_ch.path = GltfAnimationChannel::Path::kRotation;
      } else if (ch.target_path == "scale") {
        out_ch.path = GltfAnimationChannel::Path::kScale;
      } else if (ch.target_path == "weights") {
        ++weights;
        continue;
      } else {
        notes->push_back(what + ": target path \"" + ch.target_path + "\" not supported, ignored");
        continue;
      }
      const int entry = first_entry[static_cast<std::size_t>(ch.target_node)];
      if (entry < 0) {
        ++unreached;
        continue;
      }
      if (nodes[static_cast<std::size_t>(entry)].has_matrix) {
        ++matrix;
        continue;
      }
      out_ch.scene_node = entry;
      const auto [it, inserted] =
          targets.emplace(std::make_pair(ch.target_node, static_cast<int>(out_ch.path)), c);
      if (!inserted) {
        throw LoadError(what + ": node " + std::to_string(ch.target_node) + " " +
                        PathName(out_ch.path) + " is already animated by channel " +
                        std::to_string(it->second) + " (a target may appear once)");
      }

      const tinygltf::AnimationSampler& sampler =
          src.samplers[static_cast<std::size_t>(ch.sampler)];
      const std::string sw = what + " sampler " + std::to_string(ch.sampler);
      if (sampler.interpolation == "LINEAR") {
        out_ch.interpolation = GltfInterpolation::kLinear;
      } else if (sampler.interpolation == "STEP") {
        out_ch.interpolation = GltfInterpolation::kStep;
      } else if (sampler.interpolation == "CUBICSPLINE") {
        out_ch.interpolation = GltfInterpolation::kCubicSpline;
      } else {
        throw LoadError(sw + ": interpolation \"" + sampler.interpolation +
                        "\" is not LINEAR, STEP or CUBICSPLINE");
      }
      const bool cubic = out_ch.interpolation == GltfInterpolation::kCubicSpline;

      // Input: key times.
      if (sampler.input < 0 || static_cast<std::size_t>(sampler.input) >= model.accessors.size()) {
        throw LoadError(sw + ": input accessor " + std::to_string(sampler.input) + " out of range");
      }
      const tinygltf::Accessor& in = model.accessors[static_cast<std::size_t>(sampler.input)];
      if (in.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT || in.type != TINYGLTF_TYPE_SCALAR) {
        throw LoadError(sw + ": input accessor " + std::to_string(sampler.input) + " has " +
                        ComponentName(in.componentType) + " components of type code " +
                        std::to_string(in.type) + "; FLOAT SCALAR is required");
      }
      if (in.count == 0) throw LoadError(sw + ": input accessor has no keys");
      // Output: values (3 per key for a cubic spline).
      if (sampler.output < 0 ||
          static_cast<std::size_t>(sampler.output) >= model.accessors.size()) {
        throw LoadError(sw + ": output accessor " + std::to_string(sampler.output) +
                        " out of range");
      }
      const tinygltf::Accessor& outa = model.accessors[static_cast<std::size_t>(sampler.output)];
      const bool rotation = out_ch.path == GltfAnimationChannel::Path::kRotation;
      const int want_type = rotation ? TINYGLTF_TYPE_VEC4 : TINYGLTF_TYPE_VEC3;
      if (outa.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT || outa.type != want_type) {
        throw LoadError(sw + ": output accessor " + std::to_string(sampler.output) + " has " +
                        ComponentName(outa.componentType) + " components of type code " +
                        std::to_string(outa.type) + "; FLOAT " + (rotation ? "VEC4" : "VEC3") +
                        " is required for " + PathName(out_ch.path) +
                        " (normalized integers of KHR_mesh_quantization are not supported)");
      }
      const std::uint64_t want_count = std::uint64_t{in.count} * (cubic ? 3 : 1);
      if (outa.count != want_count) {
        throw LoadError(sw + ": output accessor has " + std::to_string(outa.count) +
                        " elements for " + std::to_string(in.count) + " key times, expected " +
                        std::to_string(want_count) + (cubic ? " (3 per key for CUBICSPLINE)" : ""));
      }
      keys += static_cast<std::int64_t>(want_count);
      if (keys > kGltfMaxAnimationKeys) {
        throw LoadError(sw + ": animations hold more than " +
                        std::to_string(kGltfMaxAnimationKeys) + " key values");
      }

      std::vector<glm::dvec4> times;
      ReadFloatElements(model, sampler.input, 1, sw + " input", &times);
      out_ch.times_s.resize(times.size());
      for (std::size_t k = 0; k < times.size(); ++k) {
        const double t = times[k].x;
        if (t < 0.0) {
          throw LoadError(sw + ": key time " + std::to_string(k) + " is negative (" +
                          std::to_string(t) + " s)");
        }
        if (k > 0 && t < out_ch.times_s[k - 1]) {
          throw LoadError(sw + ": key time " + std::to_string(k) + " (" + std::to_string(t) +
                          " s) is smaller than the one before (" +
                          std::to_string(out_ch.times_s[k - 1]) +
                          " s): times must be non-decreasing");
        }
        out_ch.times_s[k] = t;
      }
      ReadFloatElements(model, sampler.output, rotation ? 4 : 3, sw + " output", &out_ch.values);
      if (rotation) {
        for (std::size_t k = 0; k < in.count; ++k) {
          const glm::dvec4& q = out_ch.values[cubic ? 3 * k + 1 : k];
          if (!(glm::length(q) > 1e-12)) {
            throw LoadError(sw + ": rotation of key " + std::to_string(k) + " has zero length");
          }
        }
      }
      anim.duration_s = std::max(anim.duration_s, out_ch.times_s.back());
      anim.channels.push_back(std::move(out_ch));
      ++kept;
    }
    std::stable_sort(anim.channels.begin(), anim.channels.end(),
                     [](const GltfAnimationChannel& x, const GltfAnimationChannel& y) {
                       return x.node != y.node ? x.node < y.node : x.path < y.path;
                     });
    out.push_back(std::move(anim));
  }
  if (!out.empty()) {
    notes->push_back(std::to_string(out.size()) + " animation(s), " + std::to_string(kept) +
                     " translation/rotation/scale channel(s) kept");
  }
  if (weights > 0) {
    notes->push_back(std::to_string(weights) +
                     " animation channel(s) of weights (morph targets) ignored");
  }
  if (unreached > 0) {
    notes->push_back(std::to_string(unreached) +
                     " animation channel(s) ignored: their node is not reached from the scene");
  }
  if (matrix > 0) {
    notes->push_back(std::to_string(matrix) +
                     " animation channel(s) ignored: their node gives a matrix (glTF 2.0 allows "
                     "only translation/rotation/scale on animated nodes)");
  }
  return out;
}

}  // namespace gltf_internal

namespace {

// ---- Sampling (glTF 2.0 Appendix C). Nothing here allocates or throws.

// `q` / |q|, or `fallback` when q has no usable length.
glm::dvec4 NormalizedOr(const glm::dvec4& q, const glm::dvec4& fallback) noexcept {
  const double n = glm::length(q);
  return (n > 1e-300 && std::isfinite(n)) ? q / n : fallback;
}

// Spherical linear interpolation of unit quaternions (x, y, z, w) along the shorter arc.
glm::dvec4 Slerp(const glm::dvec4& a, glm::dvec4 b, double u) noexcept {
  double d = glm::dot(a, b);
  if (d < 0.0) {
    b = -b;
    d = -d;
  }
  if (d > 0.9995) return NormalizedOr(a + u * (b - a), a);  // nearly parallel: lerp is exact
  const double theta = std::acos(std::min(d, 1.0));
  const double s = std::sin(theta);
  return NormalizedOr((std::sin((1.0 - u) * theta) / s) * a + (std::sin(u * theta) / s) * b, a);
}

// True when the channel's arrays are consistent (always so for a loaded scene).
bool Usable(const GltfAnimationChannel& c) noexcept {
  const std::size_t n = c.times_s.size();
  const std::size_t per_key = c.interpolation == GltfInterpolation::kCubicSpline ? 3 : 1;
  return n > 0 && c.values.size() >= per_key * n;
}

// The channel's value at time t (not NaN; clamped to the keys); rotations normalized.
glm::dvec4 Sample(const GltfAnimationChannel& c, double t) noexcept {
  const std::vector<double>& k = c.times_s;
  const std::size_t n = k.size();
  const bool cubic = c.interpolation == GltfInterpolation::kCubicSpline;
  const bool rotation = c.path == GltfAnimationChannel::Path::kRotation;
  auto key = [&](std::size_t i) { return cubic ? c.values[3 * i + 1] : c.values[i]; };
  auto finish = [&](const glm::dvec4& v, std::size_t i) {
    if (!rotation) return v;
    return NormalizedOr(v, NormalizedOr(key(i), glm::dvec4(0.0, 0.0, 0.0, 1.0)));
  };
  if (!(t > k[0])) return finish(key(0), 0);
  if (t >= k[n - 1]) return finish(key(n - 1), n - 1);
  // k[0] < t < k[n - 1]: k[i] <= t < k[i + 1], so k[i + 1] > k[i].
  const std::size_t i =
      static_cast<std::size_t>(std::upper_bound(k.begin(), k.end(), t) - k.begin()) - 1;
  const double dt = k[i + 1] - k[i];
  const double u = (t - k[i]) / dt;
  switch (c.interpolation) {
    case GltfInterpolation::kStep:
      return finish(key(i), i);
    case GltfInterpolation::kLinear:
      if (rotation) {
        const glm::dvec4 fallback(0.0, 0.0, 0.0, 1.0);
        return Slerp(NormalizedOr(key(i), fallback), NormalizedOr(key(i + 1), fallback), u);
      }
      return key(i) + u * (key(i + 1) - key(i));
    case GltfInterpolation::kCubicSpline: {
      // Hermite: p(u) = h00 v_i + h10 dt b_i + h01 v_{i+1} + h11 dt a_{i+1}, with a the
      // in-tangent and b the out-tangent of a key.
      const double u2 = u * u;
      const double u3 = u2 * u;
      const glm::dvec4 v = (2.0 * u3 - 3.0 * u2 + 1.0) * c.values[3 * i + 1] +
                           ((u3 - 2.0 * u2 + u) * dt) * c.values[3 * i + 2] +
                           (-2.0 * u3 + 3.0 * u2) * c.values[3 * (i + 1) + 1] +
                           ((u3 - u2) * dt) * c.values[3 * (i + 1)];
      return finish(v, i);
    }
  }
  return finish(key(i), i);
}

// Calls fn(first entry, translation, rotation, scale) with the sampled local pose of every node
// that `anim` moves (t already wrapped), skipping nodes out of range or given by a matrix.
template <typename Fn>
void ForEachAnimatedNode(const GltfScene& scene, const GltfAnimation& anim, double t, Fn&& fn) {
  const std::size_t n_nodes = scene.nodes.size();
  const std::vector<GltfAnimationChannel>& channels = anim.channels;
  for (std::size_t c = 0; c < channels.size();) {
    std::size_t end = c + 1;
    while (end < channels.size() && channels[end].node == channels[c].node) ++end;
    const int first = channels[c].scene_node;
    if (first < 0 || static_cast<std::size_t>(first) >= n_nodes ||
        scene.nodes[static_cast<std::size_t>(first)].has_matrix) {
      c = end;
      continue;
    }
    const GltfNode& rest = scene.nodes[static_cast<std::size_t>(first)];
    glm::dvec3 translation = rest.translation;
    glm::dquat rotation = rest.rotation;
    glm::dvec3 scale = rest.scale;
    for (; c < end; ++c) {
      const GltfAnimationChannel& ch = channels[c];
      if (!Usable(ch)) continue;
      const glm::dvec4 v = Sample(ch, t);
      switch (ch.path) {
        case GltfAnimationChannel::Path::kTranslation:
          translation = glm::dvec3(v);
          break;
        case GltfAnimationChannel::Path::kRotation:
          rotation = glm::dquat(v.w, v.x, v.y, v.z);
          break;
        case GltfAnimationChannel::Path::kScale:
          scale = glm::dvec3(v);
          break;
      }
    }
    fn(first, translation, rotation, scale);
  }
}

// The animation's time: `time_s` wrapped into [0, duration) with `loop`.
double AnimationTime(const GltfAnimation& anim, double time_s, bool loop) noexcept {
  double t = time_s;
  const double duration = anim.duration_s;
  if (loop && std::isfinite(t) && duration > 0.0 && std::isfinite(duration)) {
    t = std::fmod(t, duration);
    if (t < 0.0) t += duration;
  }
  return t;
}

}  // namespace

void PoseInstancesAt(const GltfScene& scene, int animation, double time_s, bool loop,
                     std::vector<glm::dmat4>* X_WN) {
  std::vector<glm::dmat4>& X = *X_WN;
  const std::size_t n_inst = scene.instances.size();
  const std::size_t n_nodes = scene.nodes.size();
  const GltfAnimation* anim = nullptr;
  if (animation >= 0 && static_cast<std::size_t>(animation) < scene.animations.size() &&
      !std::isnan(time_s)) {
    anim = &scene.animations[static_cast<std::size_t>(animation)];
  }
  if (anim == nullptr || anim->channels.empty()) {
    X.resize(n_inst);
    for (std::size_t i = 0; i < n_inst; ++i) X[i] = scene.instances[i].X_WN;
    return;
  }
  // X first holds every entry's local pose X_PN, then its world pose X_WN (parents come first),
  // then the instances' poses are moved to the front.
  X.resize(std::max(n_nodes, n_inst));
  for (std::size_t v = 0; v < n_nodes; ++v) X[v] = scene.nodes[v].X_PN;

  const double t = AnimationTime(*anim, time_s, loop);
  ForEachAnimatedNode(scene, *anim, t,
                      [&](int first, const glm::dvec3& translation, const glm::dquat& rotation,
                          const glm::dvec3& scale) {
                        const glm::dmat4 X_PN =
                            gltf_internal::ComposeTrs(translation, rotation, scale);
                        // Every path to the node; next_same_node only grows, so this ends.
                        for (int v = first;;) {
                          X[static_cast<std::size_t>(v)] = X_PN;
                          const int next = scene.nodes[static_cast<std::size_t>(v)].next_same_node;
                          if (next <= v || static_cast<std::size_t>(next) >= n_nodes) break;
                          v = next;
                        }
                      });
  for (std::size_t v = 0; v < n_nodes; ++v) {
    const int p = scene.nodes[v].parent;
    if (p >= 0 && static_cast<std::size_t>(p) < v) X[v] = X[static_cast<std::size_t>(p)] * X[v];
  }
  // In a loaded scene the instances' entries grow strictly with the instance index, so entry >= i
  // and X[entry] is not yet overwritten (only X[0..i) is); anything else keeps the rest pose.
  int previous = -1;
  for (std::size_t i = 0; i < n_inst; ++i) {
    const int e = scene.instances[i].scene_node;
    if (e > previous && static_cast<std::size_t>(e) >= i && static_cast<std::size_t>(e) < n_nodes) {
      X[i] = X[static_cast<std::size_t>(e)];
      previous = e;
    } else {
      X[i] = scene.instances[i].X_WN;
    }
  }
  X.resize(n_inst);
}

void ScaleGltfScene(GltfScene& scene, double factor) {
  if (!(factor > 0.0) || !std::isfinite(factor)) {
    throw std::invalid_argument("scene scale must be a finite number > 0, got " +
                                std::to_string(factor));
  }
  if (factor == 1.0) return;
  const glm::dmat4 S = glm::dmat4(glm::dmat3(factor));
  std::vector<bool> root(scene.nodes.size(), false);
  for (std::size_t v = 0; v < scene.nodes.size(); ++v) {
    GltfNode& n = scene.nodes[v];
    if (n.parent >= 0) continue;
    root[v] = true;
    n.X_PN = S * n.X_PN;
    if (!n.has_matrix) {
      // S·T·R·Sc = T(f·t)·R·(f·Sc): a uniform scale commutes with the rotation.
      n.translation *= factor;
      n.scale *= factor;
    }
  }
  for (GltfMeshInstance& inst : scene.instances) inst.X_WN = S * inst.X_WN;
  for (GltfAnimation& a : scene.animations) {
    for (GltfAnimationChannel& c : a.channels) {
      const bool of_root = c.scene_node >= 0 &&
                           static_cast<std::size_t>(c.scene_node) < root.size() &&
                           root[static_cast<std::size_t>(c.scene_node)];
      if (!of_root || c.path == GltfAnimationChannel::Path::kRotation) continue;
      for (glm::dvec4& value : c.values) {
        value.x *= factor;
        value.y *= factor;
        value.z *= factor;
      }
    }
  }
  scene.camera.znear_m *= factor;
  scene.camera.zfar_m *= factor;
}

std::vector<glm::dmat4> PoseInstancesAt(const GltfScene& scene, int animation, double time_s,
                                        bool loop) {
  std::vector<glm::dmat4> X_WN;
  X_WN.reserve(std::max(scene.nodes.size(), scene.instances.size()));
  PoseInstancesAt(scene, animation, time_s, loop, &X_WN);
  return X_WN;
}

void AnimatedNodePosesAt(const GltfScene& scene, int animation, double time_s, bool loop,
                         std::vector<GltfNodePose>* poses) {
  poses->clear();
  if (animation < 0 || static_cast<std::size_t>(animation) >= scene.animations.size() ||
      std::isnan(time_s)) {
    return;
  }
  const GltfAnimation& anim = scene.animations[static_cast<std::size_t>(animation)];
  const std::size_t n_nodes = scene.nodes.size();
  ForEachAnimatedNode(scene, anim, AnimationTime(anim, time_s, loop),
                      [&](int first, const glm::dvec3& translation, const glm::dquat& rotation,
                          const glm::dvec3& scale) {
                        for (int v = first;;) {
                          poses->push_back({v, translation, glm::normalize(rotation), scale});
                          const int next = scene.nodes[static_cast<std::size_t>(v)].next_same_node;
                          if (next <= v || static_cast<std::size_t>(next) >= n_nodes) break;
                          v = next;
                        }
                      });
}

}  // namespace ht
