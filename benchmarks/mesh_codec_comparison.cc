// Draco (the scene stream's codec, codecs/draco_mesh_codec.h) beside meshoptimizer (Debian's
// libmeshoptimizer-dev: its index and vertex codecs after its vertex-cache and vertex-fetch
// reordering, alone and followed by zlib as its documentation recommends) on the seed models,
// the procedural ridged block and gear, and the real glTF models of ../shared/data when present
// (issue 18). Both quantize positions to the same uniform grid (DracoQuantizationStep: the
// bounding box's largest extent over 2^bits − 1). Per mesh and bit count: compressed bytes
// (and bits per triangle), encode and decode time (median of --repeats), and the geometric error
// relative to the bounding-box diagonal: the largest distance from a decoded vertex to the
// nearest original one (order-free, so the two codecs' reordering does not matter), measured on
// a uniform hash grid. A program, not a test: nothing here is asserted.
//
// Usage: mesh_codec_comparison [--bits 11,14] [--repeats 5] [--csv FILE] [--shared-data DIR]

#include <meshoptimizer.h>
#include <zlib.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "codecs/draco_mesh_codec.h"
#include "codecs/gltf_scene.h"
#include "haptic_core/demo/procedural_models.h"
#include "haptic_core/demo/seed_models.h"
#include "haptic_core/statistics.h"

namespace {

using Clock = std::chrono::steady_clock;

template <class F>
double MedianMs(int repeats, F&& f) {
  std::vector<double> t;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = Clock::now();
    f();
    t.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  return ht::Percentile(std::move(t), 0.5);
}

struct Box {
  glm::dvec3 lo{1e300}, hi{-1e300};
};
Box Bounds(const ht::TriangleMesh& m) {
  Box b;
  for (const glm::dvec3& v : m.vertices) {
    b.lo = glm::min(b.lo, v);
    b.hi = glm::max(b.hi, v);
  }
  return b;
}

// Largest distance from a vertex of `decoded` to the nearest vertex of `original`, on a hash
// grid of cell `cell` (≥ the largest expected error, so a 3×3×3 search suffices; a miss widens).
double MaxNearestDistance(const ht::TriangleMesh& original, const ht::TriangleMesh& decoded,
                          double cell) {
  struct Hash {
    std::size_t operator()(const glm::ivec3& k) const noexcept {
      return (static_cast<std::size_t>(k.x) * 73856093u) ^
             (static_cast<std::size_t>(k.y) * 19349663u) ^
             (static_cast<std::size_t>(k.z) * 83492791u);
    }
  };
  std::unordered_map<glm::ivec3, std::vector<int>, Hash> grid;
  const auto key = [&](const glm::dvec3& p) { return glm::ivec3(glm::floor(p / cell)); };
  for (int i = 0; i < static_cast<int>(original.vertices.size()); ++i) {
    grid[key(original.vertices[i])].push_back(i);
  }
  double worst = 0.0;
  for (const glm::dvec3& p : decoded.vertices) {
    double best = 1e300;
    for (int reach = 1; reach <= 4 && best > reach * cell; ++reach) {
      const glm::ivec3 k = key(p);
      for (int dz = -reach; dz <= reach; ++dz) {
        for (int dy = -reach; dy <= reach; ++dy) {
          for (int dx = -reach; dx <= reach; ++dx) {
            const auto it = grid.find(k + glm::ivec3(dx, dy, dz));
            if (it == grid.end()) continue;
            for (const int i : it->second) {
              best = std::min(best, glm::length(original.vertices[i] - p));
            }
          }
        }
      }
    }
    worst = std::max(worst, best);
  }
  return worst;
}

struct Row {
  std::string mesh, codec;
  int bits = 0;
  std::size_t triangles = 0, bytes = 0;
  double encode_ms = 0.0, decode_ms = 0.0, error_rel = 0.0;
};

// A quantized position as meshoptimizer's vertex codec takes it: uint16 x, y, z on Draco's grid,
// padded to the codec's 4-byte vertex multiple.
struct QuantizedVertex {
  std::uint16_t x, y, z, pad;
};

// meshoptimizer at `bits`: positions quantized, reordered for the vertex cache and fetch, then
// encoded.
struct Meshopt {
  std::vector<unsigned char> vertex_bytes, index_bytes;
  std::size_t vertex_count = 0, index_count = 0;
};

Meshopt EncodeMeshopt(const ht::TriangleMesh& mesh, const Box& box, double step) {
  std::vector<QuantizedVertex> q(mesh.vertices.size());
  for (std::size_t i = 0; i < q.size(); ++i) {
    const glm::dvec3 t = (mesh.vertices[i] - box.lo) / step + 0.5;
    q[i] = {static_cast<std::uint16_t>(t.x), static_cast<std::uint16_t>(t.y),
            static_cast<std::uint16_t>(t.z), 0};
  }
  std::vector<unsigned int> indices;
  indices.reserve(mesh.triangles.size() * 3);
  for (const glm::ivec3& t : mesh.triangles) {
    for (int c = 0; c < 3; ++c) indices.push_back(static_cast<unsigned int>(t[c]));
  }
  meshopt_optimizeVertexCache(indices.data(), indices.data(), indices.size(), q.size());
  std::vector<QuantizedVertex> fetched(q.size());
  const std::size_t used = meshopt_optimizeVertexFetch(
      fetched.data(), indices.data(), indices.size(), q.data(), q.size(), sizeof(QuantizedVertex));
  fetched.resize(used);
  Meshopt out;
  out.vertex_count = used;
  out.index_count = indices.size();
  out.vertex_bytes.resize(meshopt_encodeVertexBufferBound(used, sizeof(QuantizedVertex)));
  out.vertex_bytes.resize(meshopt_encodeVertexBuffer(out.vertex_bytes.data(),
                                                     out.vertex_bytes.size(), fetched.data(), used,
                                                     sizeof(QuantizedVertex)));
  out.index_bytes.resize(meshopt_encodeIndexBufferBound(indices.size(), used));
  out.index_bytes.resize(meshopt_encodeIndexBuffer(out.index_bytes.data(), out.index_bytes.size(),
                                                   indices.data(), indices.size()));
  return out;
}

ht::TriangleMesh DecodeMeshopt(const Meshopt& m, const Box& box, double step) {
  std::vector<QuantizedVertex> q(m.vertex_count);
  std::vector<unsigned int> indices(m.index_count);
  if (meshopt_decodeVertexBuffer(q.data(), q.size(), sizeof(QuantizedVertex), m.vertex_bytes.data(),
                                 m.vertex_bytes.size()) != 0 ||
      meshopt_decodeIndexBuffer(indices.data(), indices.size(), sizeof(unsigned int),
                                m.index_bytes.data(), m.index_bytes.size()) != 0) {
    throw std::runtime_error("meshoptimizer could not decode its own stream");
  }
  ht::TriangleMesh mesh;
  mesh.vertices.reserve(q.size());
  for (const QuantizedVertex& v : q)
    mesh.vertices.push_back(box.lo + glm::dvec3(v.x, v.y, v.z) * step);
  for (std::size_t i = 0; i + 2 < indices.size(); i += 3) {
    mesh.triangles.emplace_back(indices[i], indices[i + 1], indices[i + 2]);
  }
  return mesh;
}

std::vector<unsigned char> Deflate(const std::vector<unsigned char>& in) {
  uLongf n = compressBound(static_cast<uLong>(in.size()));
  std::vector<unsigned char> out(n);
  if (compress2(out.data(), &n, in.data(), static_cast<uLong>(in.size()), 6) != Z_OK) {
    throw std::runtime_error("zlib failed");
  }
  out.resize(n);
  return out;
}
std::vector<unsigned char> Inflate(const std::vector<unsigned char>& in, std::size_t size) {
  std::vector<unsigned char> out(size);
  uLongf n = static_cast<uLongf>(size);
  if (uncompress(out.data(), &n, in.data(), static_cast<uLong>(in.size())) != Z_OK) {
    throw std::runtime_error("zlib failed");
  }
  return out;
}

std::vector<Row> Compare(const std::string& name, const ht::TriangleMesh& mesh, int bits,
                         int repeats) {
  const Box box = Bounds(mesh);
  const double diagonal = glm::length(box.hi - box.lo);
  const double step = ht::DracoQuantizationStep(mesh, bits);
  std::vector<Row> rows;
  {  // Draco
    ht::DracoEncodeOptions o;
    o.position_quantization_bits = bits;
    std::vector<std::uint8_t> bytes;
    Row r{name, "draco", bits, mesh.triangles.size()};
    r.encode_ms = MedianMs(repeats, [&] { bytes = ht::EncodeMeshDraco(mesh, o); });
    ht::TriangleMesh decoded;
    r.decode_ms = MedianMs(repeats, [&] { decoded = ht::DecodeMeshDraco(bytes); });
    r.bytes = bytes.size();
    r.error_rel = MaxNearestDistance(mesh, decoded, 2.0 * step) / diagonal;
    rows.push_back(r);
  }
  {  // meshoptimizer, then meshoptimizer + zlib
    Meshopt m;
    Row r{name, "meshopt", bits, mesh.triangles.size()};
    r.encode_ms = MedianMs(repeats, [&] { m = EncodeMeshopt(mesh, box, step); });
    ht::TriangleMesh decoded;
    r.decode_ms = MedianMs(repeats, [&] { decoded = DecodeMeshopt(m, box, step); });
    r.bytes = m.vertex_bytes.size() + m.index_bytes.size();
    r.error_rel = MaxNearestDistance(mesh, decoded, 2.0 * step) / diagonal;
    rows.push_back(r);
    Row z = r;
    z.codec = "meshopt+zlib";
    std::vector<unsigned char> zv, zi;
    z.encode_ms = r.encode_ms + MedianMs(repeats, [&] {
                    zv = Deflate(m.vertex_bytes);
                    zi = Deflate(m.index_bytes);
                  });
    z.decode_ms = r.decode_ms + MedianMs(repeats, [&] {
                    Inflate(zv, m.vertex_bytes.size());
                    Inflate(zi, m.index_bytes.size());
                  });
    z.bytes = zv.size() + zi.size();
    rows.push_back(z);
  }
  return rows;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Draco beside meshoptimizer on the seed models and real glTF models"};
  std::vector<int> bits = {11, 14};
  std::string csv_path, shared = "../shared/data";
  int repeats = 5;
  app.add_option("--bits", bits, "position quantization bits (comma-separated, 4 to 16)")
      ->delimiter(',')
      ->check(CLI::Range(4, 16))
      ->capture_default_str();
  app.add_option("--repeats", repeats, "timed repeats per codec (median)")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  app.add_option("--csv", csv_path, "write every row here");
  app.add_option("--shared-data", shared, "the team's data folder (glTF models)")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  std::vector<std::pair<std::string, ht::TriangleMesh>> meshes;
  meshes.emplace_back("ridged_block", ht::MakeRidgedBlockFullResolution());
  meshes.emplace_back("ridged_gear", ht::MakeRidgedGearFullResolution());
  for (const ht::SeedModel m : {ht::SeedModel::kHammer, ht::SeedModel::kCadPart,
                                ht::SeedModel::kFile, ht::SeedModel::kTorus}) {
    std::fprintf(stderr, "mesh_codec_comparison: making %s...\n", ht::SeedModelName(m));
    meshes.emplace_back(ht::SeedModelName(m), ht::MakeSeedModelFullResolution(m));
  }
  for (const char* rel : {"gltf/draco_testdata_gltf/glTF_Binary/Duck.glb",
                          "gltf/assimp_gltf2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb",
                          "gltf/draco_testdata_gltf/CesiumMilkTruck/glTF/CesiumMilkTruck.gltf"}) {
    const std::filesystem::path path = std::filesystem::path(shared) / rel;
    if (!std::filesystem::exists(path)) {
      std::fprintf(stderr, "mesh_codec_comparison: %s not found (skipped)\n", path.c_str());
      continue;
    }
    const ht::GltfScene scene = ht::LoadGltfScene(path.string());
    for (const ht::GltfMesh& m : scene.meshes) {
      if (m.mesh_N.triangles.size() < 100) continue;
      meshes.emplace_back(path.stem().string() + "/" + (m.name.empty() ? "mesh" : m.name),
                          m.mesh_N);
    }
  }
  std::vector<Row> rows;
  std::printf(
      "| mesh | triangles | bits | codec | bytes | bits/tri | encode ms | decode ms | "
      "error / diagonal |\n|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& [name, mesh] : meshes) {
    for (const int b : bits) {
      for (const Row& r : Compare(name, mesh, b, repeats)) {
        std::printf("| %s | %zu | %d | %s | %zu | %.2f | %.2f | %.2f | %.2e |\n", r.mesh.c_str(),
                    r.triangles, r.bits, r.codec.c_str(), r.bytes,
                    8.0 * static_cast<double>(r.bytes) / static_cast<double>(r.triangles),
                    r.encode_ms, r.decode_ms, r.error_rel);
        std::fflush(stdout);
        rows.push_back(r);
      }
    }
  }
  if (!csv_path.empty()) {
    std::ofstream csv(csv_path);
    csv << "mesh,triangles,bits,codec,bytes,encode_ms,decode_ms,error_rel\n";
    for (const Row& r : rows) {
      csv << r.mesh << ',' << r.triangles << ',' << r.bits << ',' << r.codec << ',' << r.bytes
          << ',' << r.encode_ms << ',' << r.decode_ms << ',' << r.error_rel << '\n';
    }
  }
  return 0;
}
