#include "codecs/glb_writer.h"

#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <stdexcept>

#include "haptic_core/byte_order.h"

namespace ht {
namespace {

void PadTo4(std::vector<std::uint8_t>& out, std::uint8_t fill) {
  while (out.size() % 4 != 0) out.push_back(fill);
}

}  // namespace

void WriteGlb(const std::string& path, const std::vector<GlbNode>& nodes) {
  using nlohmann::json;
  if (nodes.empty()) throw std::invalid_argument("WriteGlb: no node to write to " + path);
  json doc;
  doc["asset"] = {{"version", "2.0"}, {"generator", "haptic_teleop WriteGlb"}};
  doc["scene"] = 0;
  json scene_nodes = json::array(), jnodes = json::array(), meshes = json::array(),
       accessors = json::array(), views = json::array();
  std::vector<std::uint8_t> bin;
  for (std::size_t n = 0; n < nodes.size(); ++n) {
    const GlbNode& node = nodes[n];
    const TriangleMesh& m = node.mesh_N;
    if (m.vertices.empty() || m.triangles.empty()) {
      throw std::invalid_argument("WriteGlb: node '" + node.name + "' has an empty mesh");
    }
    if (m.vertices.size() > std::numeric_limits<std::uint32_t>::max()) {
      throw std::invalid_argument("WriteGlb: node '" + node.name + "' has too many vertices");
    }
    glm::dvec3 lo{std::numeric_limits<double>::max()}, hi{-std::numeric_limits<double>::max()};
    const std::size_t position_offset = bin.size();
    for (std::size_t i = 0; i < m.vertices.size(); ++i) {
      const glm::dvec3& p = m.vertices[i];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
        throw std::invalid_argument("WriteGlb: node '" + node.name + "' vertex " +
                                    std::to_string(i) + " is not finite");
      }
      for (int c = 0; c < 3; ++c) {
        const float f = static_cast<float>(p[c]);
        AppendLe(bin, f);
        lo[c] = std::min(lo[c], static_cast<double>(f));
        hi[c] = std::max(hi[c], static_cast<double>(f));
      }
    }
    const std::size_t position_bytes = bin.size() - position_offset;
    const std::size_t index_offset = bin.size();
    const auto nv = static_cast<std::int64_t>(m.vertices.size());
    for (std::size_t f = 0; f < m.triangles.size(); ++f) {
      for (int c = 0; c < 3; ++c) {
        const int i = m.triangles[f][c];
        if (i < 0 || i >= nv) {
          throw std::invalid_argument("WriteGlb: node '" + node.name + "' triangle " +
                                      std::to_string(f) + " indexes vertex " + std::to_string(i) +
                                      " of " + std::to_string(nv));
        }
        AppendLe(bin, static_cast<std::uint32_t>(i));
      }
    }
    const std::size_t index_bytes = bin.size() - index_offset;
    const auto view_base = static_cast<int>(views.size());
    views.push_back({{"buffer", 0},
                     {"byteOffset", position_offset},
                     {"byteLength", position_bytes},
                     {"target", 34962}});
    views.push_back({{"buffer", 0},
                     {"byteOffset", index_offset},
                     {"byteLength", index_bytes},
                     {"target", 34963}});
    const auto accessor_base = static_cast<int>(accessors.size());
    accessors.push_back({{"bufferView", view_base},
                         {"componentType", 5126},
                         {"count", m.vertices.size()},
                         {"type", "VEC3"},
                         {"min", {lo.x, lo.y, lo.z}},
                         {"max", {hi.x, hi.y, hi.z}}});
    accessors.push_back({{"bufferView", view_base + 1},
                         {"componentType", 5125},
                         {"count", 3 * m.triangles.size()},
                         {"type", "SCALAR"}});
    meshes.push_back({{"name", node.name},
                      {"primitives",
                       {{{"attributes", {{"POSITION", accessor_base}}},
                         {"indices", accessor_base + 1},
                         {"mode", 4}}}}});
    json jnode = {{"name", node.name}, {"mesh", static_cast<int>(n)}};
    if (node.X_WN != glm::dmat4(1.0)) {
      json matrix = json::array();
      for (int c = 0; c < 4; ++c) {
        for (int r = 0; r < 4; ++r) matrix.push_back(node.X_WN[c][r]);
      }
      jnode["matrix"] = matrix;
    }
    if (!node.extras_json.empty()) jnode["extras"] = json::parse(node.extras_json);
    jnodes.push_back(jnode);
    scene_nodes.push_back(static_cast<int>(n));
  }
  doc["scenes"] = {{{"nodes", scene_nodes}}};
  doc["nodes"] = jnodes;
  doc["meshes"] = meshes;
  doc["accessors"] = accessors;
  doc["bufferViews"] = views;
  doc["buffers"] = {{{"byteLength", bin.size()}}};

  std::string text = doc.dump();
  std::vector<std::uint8_t> json_chunk(text.begin(), text.end());
  PadTo4(json_chunk, ' ');
  PadTo4(bin, 0);
  const std::uint64_t total = 12 + 8 + json_chunk.size() + 8 + bin.size();
  if (total > std::numeric_limits<std::uint32_t>::max()) {
    throw std::invalid_argument("WriteGlb: " + path + " would exceed the 4 GiB a .glb can hold");
  }
  std::vector<std::uint8_t> out;
  out.reserve(28 + json_chunk.size() + bin.size());
  AppendLe(out, std::uint32_t{0x46546C67});  // "glTF"
  AppendLe(out, std::uint32_t{2});
  AppendLe(out, static_cast<std::uint32_t>(12 + 8 + json_chunk.size() + 8 + bin.size()));
  AppendLe(out, static_cast<std::uint32_t>(json_chunk.size()));
  AppendLe(out, std::uint32_t{0x4E4F534A});  // "JSON"
  out.insert(out.end(), json_chunk.begin(), json_chunk.end());
  AppendLe(out, static_cast<std::uint32_t>(bin.size()));
  AppendLe(out, std::uint32_t{0x004E4942});  // "BIN\0"
  out.insert(out.end(), bin.begin(), bin.end());

  const std::string tmp =
      path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(std::random_device{}());
  {
    std::ofstream file(tmp, std::ios::binary | std::ios::trunc);
    file.write(reinterpret_cast<const char*>(out.data()), static_cast<std::streamsize>(out.size()));
    if (!file.flush()) {
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      throw std::runtime_error(path + ": cannot write the file");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw std::runtime_error(path + ": cannot rename into place: " + ec.message());
}

}  // namespace ht
