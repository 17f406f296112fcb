// The model cache (haptic_model_build.h): the cache key, the file layout (little-endian, field by
// field, STYLE.md 7) and its loader's checks, and the cached build.
#include <sodium.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <concepts>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <glm/glm.hpp>
#include <limits>
#include <random>
#include <stdexcept>

#include "haptic_core/byte_order.h"
#include "haptic_core/model_build/haptic_model_build.h"
#include "model_build_helpers.h"

namespace ht {
namespace {

using model_build::Bounds;
using model_build::BoundsOf;
using model_build::IsSizingSize;
using model_build::MeasuredSurface;
using model_build::Seconds;

// Bump when the build's output or the file layout changes: old entries then miss.
constexpr std::uint32_t kBuildFormatVersion = 4;  // 4: outward reach percentile
constexpr char kCacheMagic[8] = {'H', 'T', 'M', 'O', 'D', 'E', 'L', '1'};
// Bounds on what a cache file may claim (the loader never allocates beyond them).
constexpr std::uint64_t kMaxCacheCount = 64ULL << 20;

// Field-by-field little-endian serialization (STYLE.md 7).
class ByteWriter {
 public:
  void U8(std::uint8_t v) { AppendLe(bytes_, v); }
  void U32(std::uint32_t v) { AppendLe(bytes_, v); }
  void U64(std::uint64_t v) { AppendLe(bytes_, v); }
  void I64(std::int64_t v) { U64(static_cast<std::uint64_t>(v)); }
  void I32(std::int32_t v) { U32(static_cast<std::uint32_t>(v)); }
  void F64(double v) { AppendLe(bytes_, v); }
  void F32(float v) { AppendLe(bytes_, v); }
  void Vec3(const glm::dvec3& v) {
    F64(v.x);
    F64(v.y);
    F64(v.z);
  }
  void Str(const std::string& s) {
    U64(s.size());
    bytes_.insert(bytes_.end(), s.begin(), s.end());
  }
  void Raw(const void* data, std::size_t n) {
    const auto* p = static_cast<const std::uint8_t*>(data);
    bytes_.insert(bytes_.end(), p, p + n);
  }
  const std::vector<std::uint8_t>& bytes() const noexcept { return bytes_; }

 private:
  std::vector<std::uint8_t> bytes_;
};

struct CacheFormatError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class ByteReader {
 public:
  explicit ByteReader(const std::vector<std::uint8_t>& bytes) : bytes_(bytes) {}
  std::uint8_t U8() { return Load<std::uint8_t>(); }
  std::uint32_t U32() { return Load<std::uint32_t>(); }
  std::uint64_t U64() { return Load<std::uint64_t>(); }
  std::int64_t I64() { return static_cast<std::int64_t>(U64()); }
  std::int32_t I32() { return static_cast<std::int32_t>(U32()); }
  double F64() {
    const auto v = std::bit_cast<double>(U64());
    if (!std::isfinite(v)) throw CacheFormatError("non-finite number");
    return v;
  }
  float F32() {
    const auto v = std::bit_cast<float>(U32());
    if (!std::isfinite(v)) throw CacheFormatError("non-finite number");
    return v;
  }
  glm::dvec3 Vec3() {
    const double x = F64(), y = F64(), z = F64();
    return {x, y, z};
  }
  std::string Str() {
    const std::uint64_t n = Count(1);
    std::string s(reinterpret_cast<const char*>(bytes_.data() + pos_), n);
    pos_ += n;
    return s;
  }
  /// A count of items of `item_bytes` each that must fit in what is left of the file.
  std::uint64_t Count(std::uint64_t item_bytes) {
    const std::uint64_t n = U64();
    if (n > kMaxCacheCount || n * item_bytes > bytes_.size() - pos_) {
      throw CacheFormatError("count " + std::to_string(n) + " exceeds the file");
    }
    return n;
  }
  bool AtEnd() const noexcept { return pos_ == bytes_.size(); }

 private:
  template <std::unsigned_integral T>
  T Load() {
    if (bytes_.size() - pos_ < sizeof(T)) throw CacheFormatError("truncated");
    const T v = LoadLe<T>(bytes_.data() + pos_);
    pos_ += sizeof(T);
    return v;
  }
  const std::vector<std::uint8_t>& bytes_;
  std::size_t pos_ = 0;
};

void WriteParams(ByteWriter& w, const HapticModelBuildParams& p) {
  w.I32(p.coarse_triangles);
  // With texture sizing the bake's own size is not used: it does not split the cache.
  w.I32(p.texture_sizing.from_detail ? 0 : p.texture.texture_size);
  w.I32(p.texture.gutter_texels);
  w.F64(p.texture.crease_angle_deg);
  w.F64(p.texture.max_ray_distance_m);
  w.I32(p.texture.validation_samples);
  w.U64(p.texture.seed);
  w.F64(p.hulls.convexity_tolerance_m);
  w.I32(p.hulls.max_leaf_triangles);
  w.F64(p.hulls.max_normal_deviation_deg);
  w.F64(p.hulls.max_shadow_gap_m);
  w.F64(p.hulls.leaf_thickness_m);
  w.F64(p.density_kg_per_m3);
  if (p.texture_sizing.from_detail) {  // fixed-size keys stay those of older builds
    w.U8(1);
    w.F64(p.texture_sizing.surface_budget_m);
    w.F64(p.texture_sizing.min_improvement);
    w.I32(p.texture_sizing.min_size);
    w.I32(p.texture_sizing.max_size);
  }
}

void WriteHull(ByteWriter& w, const ConvexHull& hull) {
  w.U64(hull.vertices_O.size());
  for (const auto& p : hull.vertices_O) w.Vec3(p);
  w.U64(hull.planes_O.size());
  for (const auto& pl : hull.planes_O) {
    w.F64(pl.x);
    w.F64(pl.y);
    w.F64(pl.z);
    w.F64(pl.w);
  }
  w.Vec3(hull.center_O);
}

ConvexHull ReadHull(ByteReader& r) {
  ConvexHull hull;
  hull.vertices_O.resize(r.Count(24));
  for (auto& p : hull.vertices_O) p = r.Vec3();
  hull.planes_O.resize(r.Count(32));
  for (auto& pl : hull.planes_O) {
    const double x = r.F64(), y = r.F64(), z = r.F64(), d = r.F64();
    pl = glm::dvec4(x, y, z, d);
  }
  hull.center_O = r.Vec3();
  return hull;
}

void WriteBuild(ByteWriter& w, const std::string& key, const HapticModelBuild& build) {
  const HapticModel& m = *build.model;
  const HapticModelBuildReport& rep = build.report;
  w.Raw(kCacheMagic, sizeof kCacheMagic);
  w.U32(kBuildFormatVersion);
  w.Str(key);
  w.Str(m.name);
  w.U64(m.vertices_O.size());
  for (const auto& p : m.vertices_O) w.Vec3(p);
  w.U64(m.triangles.size());
  for (const auto& t : m.triangles) {
    w.I32(t.x);
    w.I32(t.y);
    w.I32(t.z);
  }
  for (const auto& n : m.corner_normals_O) w.Vec3(n);
  for (const auto& uv : m.corner_uvs) {
    w.F32(uv.x);
    w.F32(uv.y);
  }
  for (const auto t : m.textured) w.U8(t);
  for (const auto s : m.texel_size_m) w.F64(s);
  // Texture: level 0 only; the mip chain is rebuilt by the HeightField constructor.
  const bool has_texture = !m.texture.empty();
  w.U8(has_texture ? 1 : 0);
  if (has_texture) {
    const HeightFieldLevel& l0 = m.texture.level(0);
    w.I32(l0.width);
    w.I32(l0.height);
    w.U8(m.texture.wrap_u() ? 1 : 0);
    w.U8(m.texture.wrap_v() ? 1 : 0);
    w.U64(l0.texels.size());
    for (const float h : l0.texels) w.F32(h);
  }
  w.U64(m.hull_vertices_O.size());
  for (const auto& p : m.hull_vertices_O) w.Vec3(p);
  w.U64(m.hull_hierarchy.nodes.size());
  for (const HullNode& node : m.hull_hierarchy.nodes) {
    WriteHull(w, node.hull);
    w.I32(node.children[0]);
    w.I32(node.children[1]);
    w.U64(node.triangles.size());
    for (const int t : node.triangles) w.I32(t);
  }
  w.F64(m.outward_reach_m < 0.0 ? -1.0 : m.outward_reach_m);
  w.Vec3(m.center_of_mass_O);
  w.F64(m.mass_kg);
  w.Vec3(m.inertia_diagonal_O);
  w.I64(m.full_resolution_triangles);
  // Report figures that describe the model (not the times of this start).
  w.I64(rep.full_triangles);
  w.I64(rep.welded_vertices);
  w.I64(rep.dropped_non_manifold_triangles);
  w.I64(rep.input_boundary_edges);
  w.I64(rep.coarse_boundary_edges);
  w.I64(rep.bake.texels_baked);
  w.I64(rep.bake.rays);
  w.I64(rep.bake.misses);
  w.I64(rep.bake.clamped);
  w.F64(rep.bake.max_abs_height_m);
  w.F64(rep.bake.max_bake_error_m);
  w.F64(rep.bake.rms_bake_error_m);
  w.I64(rep.bake.validation_misses);
  w.F64(rep.bake.seconds);
  w.F64(rep.decimate_s);
  w.F64(rep.bake_s);
  w.F64(rep.hulls_s);
  w.F64(rep.total_s);
  // Optional tail (a file of format 4 may end before it): the texture-size trials of a build
  // with TextureSizingParams::from_detail.
  if (!rep.texture_trials.empty()) {
    w.U64(rep.texture_trials.size());
    for (const TextureSizeTrial& t : rep.texture_trials) {
      w.I32(t.size);
      w.F64(t.surface_p99_m);
      w.F64(t.surface_outside_p99_m);
      w.F64(t.seconds);
    }
    w.Str(rep.texture_size_reason);
  }
}

HapticModelBuild ReadBuild(ByteReader& r, const std::string& key) {
  char magic[sizeof kCacheMagic];
  for (char& c : magic) c = static_cast<char>(r.U8());
  if (std::memcmp(magic, kCacheMagic, sizeof magic) != 0) throw CacheFormatError("not a model");
  const std::uint32_t version = r.U32();
  if (version != kBuildFormatVersion) {
    throw CacheFormatError("format version " + std::to_string(version) + ", this build reads " +
                           std::to_string(kBuildFormatVersion));
  }
  if (r.Str() != key) throw CacheFormatError("entry is for another key");
  auto model = std::make_shared<HapticModel>();
  HapticModel& m = *model;
  m.name = r.Str();
  m.vertices_O.resize(r.Count(24));
  for (auto& p : m.vertices_O) p = r.Vec3();
  const std::uint64_t nf = r.Count(12 + 3 * 24 + 3 * 8 + 1 + 8);
  m.triangles.resize(nf);
  for (auto& t : m.triangles) {
    const int a = r.I32(), b = r.I32(), c = r.I32();
    t = glm::ivec3(a, b, c);
  }
  m.corner_normals_O.resize(3 * nf);
  for (auto& n : m.corner_normals_O) n = r.Vec3();
  m.corner_uvs.resize(3 * nf);
  for (auto& uv : m.corner_uvs) {
    const float u = r.F32(), v = r.F32();
    uv = glm::vec2(u, v);
  }
  m.textured.resize(nf);
  for (auto& t : m.textured) t = r.U8();
  m.texel_size_m.resize(nf);
  for (auto& s : m.texel_size_m) s = r.F64();
  if (r.U8() != 0) {
    const int width = r.I32(), height = r.I32();
    const bool wrap_u = r.U8() != 0, wrap_v = r.U8() != 0;
    std::vector<float> texels(r.Count(4));
    for (float& h : texels) h = r.F32();
    try {
      m.texture = HeightField(width, height, std::move(texels), wrap_u, wrap_v);
    } catch (const std::invalid_argument& e) {
      throw CacheFormatError(std::string("texture: ") + e.what());
    }
  }
  m.hull_vertices_O.resize(r.Count(24));
  for (auto& p : m.hull_vertices_O) p = r.Vec3();
  // A node takes at least 8+8+24 (hull counts, centre) + 8 (children) + 8 (triangle count) bytes.
  m.hull_hierarchy.nodes.resize(r.Count(56));
  for (HullNode& node : m.hull_hierarchy.nodes) {
    node.hull = ReadHull(r);
    node.children[0] = r.I32();
    node.children[1] = r.I32();
    node.triangles.resize(r.Count(4));
    for (int& t : node.triangles) t = r.I32();
  }
  m.outward_reach_m = r.F64();
  m.center_of_mass_O = r.Vec3();
  m.mass_kg = r.F64();
  m.inertia_diagonal_O = r.Vec3();
  m.full_resolution_triangles = r.I64();
  HapticModelBuild build;
  HapticModelBuildReport& rep = build.report;
  rep.name = m.name;
  rep.full_triangles = r.I64();
  rep.welded_vertices = r.I64();
  rep.dropped_non_manifold_triangles = r.I64();
  rep.input_boundary_edges = r.I64();
  rep.coarse_boundary_edges = r.I64();
  rep.bake.texels_baked = r.I64();
  rep.bake.rays = r.I64();
  rep.bake.misses = r.I64();
  rep.bake.clamped = r.I64();
  rep.bake.max_abs_height_m = r.F64();
  rep.bake.max_bake_error_m = r.F64();
  rep.bake.rms_bake_error_m = r.F64();
  rep.bake.validation_misses = r.I64();
  rep.bake.seconds = r.F64();
  rep.decimate_s = r.F64();
  rep.bake_s = r.F64();
  rep.hulls_s = r.F64();
  rep.total_s = r.F64();
  if (!r.AtEnd()) {
    // The trials of a from_detail build: at least one, powers of two in [16, 8192] doubling
    // from one to the next, the model's own size among them.
    rep.texture_trials.resize(r.Count(4 + 3 * 8));
    if (rep.texture_trials.empty()) throw CacheFormatError("texture trials: none");
    bool has_own_size = false;
    const int own_size = m.texture.empty() ? 0 : m.texture.level(0).width;
    for (std::size_t i = 0; i < rep.texture_trials.size(); ++i) {
      TextureSizeTrial& t = rep.texture_trials[i];
      t.size = r.I32();
      t.surface_p99_m = r.F64();
      t.surface_outside_p99_m = r.F64();
      t.seconds = r.F64();
      if (!IsSizingSize(t.size) || (i > 0 && t.size != 2 * rep.texture_trials[i - 1].size)) {
        throw CacheFormatError("texture trials: bad size " + std::to_string(t.size));
      }
      has_own_size |= t.size == own_size;
    }
    if (!has_own_size) throw CacheFormatError("texture trials: the model's size is not among them");
    rep.texture_size_reason = r.Str();
  }
  if (!r.AtEnd()) throw CacheFormatError("trailing bytes");
  try {
    m.Validate();
    // The builder's hulls contain their vertices to ~1e-9 of the diagonal; the file holds the
    // same doubles, so a loose bound only catches damage.
    const Bounds bounds = BoundsOf(m.vertices_O);
    if (!m.hull_hierarchy.nodes.empty()) {
      m.hull_hierarchy.Validate(m.vertices_O, m.triangles,
                                1e-6 * glm::length(bounds.hi - bounds.lo) + 1e-12);
    }
  } catch (const std::invalid_argument& e) {
    throw CacheFormatError(std::string("invalid model: ") + e.what());
  }
  rep.coarse_triangles = static_cast<std::int64_t>(m.triangles.size());
  rep.hull_nodes = static_cast<int>(m.hull_hierarchy.nodes.size());
  rep.hull_leaves = m.hull_hierarchy.LeafCount();
  rep.hull_depth = m.hull_hierarchy.Depth();
  rep.texture_size = m.texture.empty() ? 0 : m.texture.level(0).width;
  rep.outward_reach_m = m.OutwardReach();
  build.model = std::move(model);
  return build;
}

}  // namespace

std::string HapticModelCacheKey(const TriangleMesh& full_O, const HapticModelBuildParams& params) {
  if (sodium_init() < 0) throw std::runtime_error("libsodium failed to initialise");
  crypto_generichash_state state;
  crypto_generichash_init(&state, nullptr, 0, 32);
  ByteWriter header;
  header.U32(kBuildFormatVersion);
  WriteParams(header, params);
  header.U64(full_O.vertices.size());
  header.U64(full_O.triangles.size());
  crypto_generichash_update(&state, header.bytes().data(), header.bytes().size());
  // Mesh arrays in chunks, field by field (bit-exact doubles, little-endian).
  ByteWriter chunk;
  const auto flush = [&] {
    crypto_generichash_update(&state, chunk.bytes().data(), chunk.bytes().size());
    chunk = ByteWriter();
  };
  for (std::size_t i = 0; i < full_O.vertices.size(); ++i) {
    chunk.Vec3(full_O.vertices[i]);
    if (chunk.bytes().size() >= (1 << 16)) flush();
  }
  for (std::size_t i = 0; i < full_O.triangles.size(); ++i) {
    chunk.I32(full_O.triangles[i].x);
    chunk.I32(full_O.triangles[i].y);
    chunk.I32(full_O.triangles[i].z);
    if (chunk.bytes().size() >= (1 << 16)) flush();
  }
  flush();
  unsigned char digest[32];
  crypto_generichash_final(&state, digest, sizeof digest);
  char hex[2 * sizeof digest + 1];
  sodium_bin2hex(hex, sizeof hex, digest, sizeof digest);
  return hex;
}

std::string HapticModelCache::DefaultDir() {
  if (const char* d = std::getenv("HT_CACHE_DIR"); d != nullptr && *d != '\0') return d;
  if (const char* d = std::getenv("XDG_CACHE_HOME"); d != nullptr && *d != '\0') {
    return std::string(d) + "/haptic_teleop";
  }
  if (const char* d = std::getenv("HOME"); d != nullptr && *d != '\0') {
    return std::string(d) + "/.cache/haptic_teleop";
  }
  return "";
}

std::optional<HapticModelBuild> HapticModelCache::Load(const std::string& key,
                                                       std::string* why) const {
  if (dir_.empty()) return std::nullopt;
  const std::string path = dir_ + "/" + key + ".htmodel";
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return std::nullopt;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec || size > (std::uint64_t{4} << 30)) {
    if (why) *why = path + ": unreadable or larger than 4 GiB";
    return std::nullopt;
  }
  std::ifstream in(path, std::ios::binary);
  std::vector<std::uint8_t> bytes(size);
  if (!in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size))) {
    if (why) *why = path + ": read failed";
    return std::nullopt;
  }
  try {
    ByteReader reader(bytes);
    HapticModelBuild build = ReadBuild(reader, key);
    build.report.cache_key = key;
    return build;
  } catch (const std::exception& e) {  // CacheFormatError, or what a damaged file provokes
    if (why) *why = path + ": " + e.what();
    return std::nullopt;
  }
}

void HapticModelCache::Store(const std::string& key, const HapticModelBuild& build) const {
  if (dir_.empty()) return;
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  if (ec) throw std::runtime_error(dir_ + ": cannot create the cache folder: " + ec.message());
  ByteWriter w;
  WriteBuild(w, key, build);
  const std::string path = dir_ + "/" + key + ".htmodel";
  const std::string tmp =
      path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(std::random_device{}());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(w.bytes().data()),
              static_cast<std::streamsize>(w.bytes().size()));
    if (!out.flush()) {
      std::filesystem::remove(tmp, ec);
      throw std::runtime_error(tmp + ": cannot write the cache entry");
    }
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw std::runtime_error(path + ": cannot rename the cache entry into place");
  }
}

HapticModelBuild BuildHapticModelCached(const std::string& name, const TriangleMesh& full_O,
                                        const HapticModelBuildParams& params,
                                        const HapticModelCache& cache) {
  if (cache.dir().empty()) return BuildHapticModel(name, full_O, params);
  const auto start = std::chrono::steady_clock::now();
  const std::string key = HapticModelCacheKey(full_O, params);
  std::string why;
  if (auto hit = cache.Load(key, &why)) {
    hit->report.from_cache = true;
    hit->report.cache_load_s = Seconds(start);
    hit->report.surface = MeasuredSurface(*hit->model, full_O);
    if (hit->model->name != name) {
      // Same geometry and parameters under another name: share the build, keep this name.
      auto renamed = std::make_shared<HapticModel>(*hit->model);
      renamed->name = name;
      hit->model = std::move(renamed);
      hit->report.name = name;
    }
    return *std::move(hit);
  }
  HapticModelBuild build = BuildHapticModel(name, full_O, params);
  build.report.cache_key = key;
  build.report.cache_note = why;
  try {
    cache.Store(key, build);
  } catch (const std::runtime_error& e) {
    build.report.cache_note +=
        (build.report.cache_note.empty() ? "" : "; ") + std::string("not cached: ") + e.what();
  }
  return build;
}

}  // namespace ht
