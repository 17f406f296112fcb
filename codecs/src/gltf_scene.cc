// The only translation unit that compiles tiny_gltf.h's implementation. It is built with
// tinygltf=proj_tinygltf (set on the codecs target) so that its symbols do not clash with the
// older tinygltf copy that libdraco.so exports (docs/DEPENDENCIES.md trap 1).
//
// TINYGLTF_ENABLE_DRACO is deliberately NOT defined: tinygltf 2.7's Draco path
// (ParseDracoExtension) indexes bufferViews, buffers and accessors without bounds checks and
// dereferences a null attribute when the stream lacks an id, so a malformed file could crash the
// process. Instead the KHR_draco_mesh_compression objects (and the Draco primitives' `indices`,
// whose accessors have no buffer view) are taken out of the JSON before tinygltf sees it, and the
// Draco streams are decoded here with every index and range checked.
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>
// tiny_gltf.h is included first so that its implementation sees only its own configuration.

#include <draco/compression/decode.h>
#include <draco/core/decoder_buffer.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "codecs/gltf_scene.h"
#include "codecs/json_nesting.h"

namespace ht {
namespace {

// Thrown inside this file; LoadGltfScene() prefixes the path.
struct LoadError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

constexpr std::uint32_t kGlbMagic = 0x46546C67;      // "glTF"
constexpr std::uint32_t kGlbChunkJson = 0x4E4F534A;  // "JSON"
constexpr std::uint32_t kGlbChunkBin = 0x004E4942;   // "BIN\0"

std::uint32_t ReadU32Le(const std::vector<unsigned char>& bytes, std::size_t at) {
  return static_cast<std::uint32_t>(bytes[at]) | (static_cast<std::uint32_t>(bytes[at + 1]) << 8) |
         (static_cast<std::uint32_t>(bytes[at + 2]) << 16) |
         (static_cast<std::uint32_t>(bytes[at + 3]) << 24);
}

void AppendU32Le(std::vector<unsigned char>& bytes, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<unsigned char>((v >> (8 * i)) & 0xFF));
}

std::vector<unsigned char> ReadWholeFile(const std::string& path) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) throw LoadError("cannot read the file: " + ec.message());
  if (size > static_cast<std::uintmax_t>(kGltfMaxFileBytes)) {
    throw LoadError("file of " + std::to_string(size) + " bytes exceeds the limit of " +
                    std::to_string(kGltfMaxFileBytes));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw LoadError("cannot open the file");
  std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
  if (size > 0 &&
      !in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size))) {
    throw LoadError("cannot read the file's " + std::to_string(size) + " bytes");
  }
  return bytes;
}

// A GLB container split into its chunks (offsets into the file bytes), after checking that the
// header and the chunk headers are consistent with the file's size.
struct GlbLayout {
  std::size_t json_offset = 0;
  std::size_t json_length = 0;
  std::optional<std::pair<std::size_t, std::size_t>> bin;  // offset, length
};

GlbLayout ParseGlbLayout(const std::vector<unsigned char>& bytes) {
  if (bytes.size() < 20) {
    throw LoadError("GLB truncated: " + std::to_string(bytes.size()) +
                    " bytes, less than the 12-byte header plus one 8-byte chunk header");
  }
  const std::uint32_t version = ReadU32Le(bytes, 4);
  if (version != 2) throw LoadError("GLB version " + std::to_string(version) + ", expected 2");
  const std::uint32_t length = ReadU32Le(bytes, 8);
  if (length > bytes.size()) {
    throw LoadError("GLB truncated: header declares " + std::to_string(length) +
                    " bytes, the file has " + std::to_string(bytes.size()));
  }
  if (length < 20)
    throw LoadError("GLB header declares an impossible length " + std::to_string(length));
  GlbLayout layout;
  const std::uint32_t json_length = ReadU32Le(bytes, 12);
  if (ReadU32Le(bytes, 16) != kGlbChunkJson) throw LoadError("GLB first chunk is not JSON");
  if (json_length > length - 20) {
    throw LoadError("GLB truncated: JSON chunk of " + std::to_string(json_length) +
                    " bytes runs past the declared length " + std::to_string(length));
  }
  layout.json_offset = 20;
  layout.json_length = json_length;
  std::size_t at = 20 + static_cast<std::size_t>(json_length);
  at = (at + 3) & ~std::size_t{3};  // chunks start 4-byte aligned
  if (at + 8 <= length) {
    const std::uint32_t bin_length = ReadU32Le(bytes, at);
    const std::uint32_t type = ReadU32Le(bytes, at + 4);
    if (type == kGlbChunkBin) {
      if (bin_length > length - (at + 8)) {
        throw LoadError("GLB truncated: BIN chunk of " + std::to_string(bin_length) +
                        " bytes runs past the declared length " + std::to_string(length));
      }
      layout.bin = std::make_pair(at + 8, static_cast<std::size_t>(bin_length));
    }
  }
  return layout;
}

// What was taken out of one Draco primitive's JSON.
struct DracoPrimitive {
  int buffer_view = -1;
  std::map<std::string, int> attributes;  // glTF attribute name -> Draco unique id
  int original_indices = -1;
};
using DracoKey = std::pair<int, int>;  // mesh index, primitive index

// Removes KHR_draco_mesh_compression (and the primitive's `indices`) from every primitive of
// `doc` and returns what was removed. Leaves anything it does not understand for tinygltf.
std::map<DracoKey, DracoPrimitive> ExtractDraco(nlohmann::json& doc) {
  std::map<DracoKey, DracoPrimitive> out;
  if (!doc.is_object()) return out;
  auto meshes = doc.find("meshes");
  if (meshes == doc.end() || !meshes->is_array()) return out;
  for (std::size_t m = 0; m < meshes->size(); ++m) {
    nlohmann::json& mesh = (*meshes)[m];
    if (!mesh.is_object()) continue;
    auto prims = mesh.find("primitives");
    if (prims == mesh.end()) continue;
    if (!prims->is_array())
      throw LoadError("mesh " + std::to_string(m) + ": primitives is not an array");
    for (std::size_t p = 0; p < prims->size(); ++p) {
      nlohmann::json& prim = (*prims)[p];
      if (!prim.is_object()) continue;
      auto ext = prim.find("extensions");
      if (ext == prim.end() || !ext->is_object()) continue;
      auto draco = ext->find("KHR_draco_mesh_compression");
      if (draco == ext->end()) continue;
      const std::string where =
          "mesh " + std::to_string(m) + " primitive " + std::to_string(p) + ": ";
      DracoPrimitive d;
      if (!draco->is_object())
        throw LoadError(where + "KHR_draco_mesh_compression is not an object");
      auto bv = draco->find("bufferView");
      if (bv == draco->end() || !bv->is_number_integer() || bv->get<std::int64_t>() < 0 ||
          bv->get<std::int64_t>() > std::numeric_limits<int>::max()) {
        throw LoadError(where +
                        "KHR_draco_mesh_compression.bufferView missing or not a valid index");
      }
      d.buffer_view = static_cast<int>(bv->get<std::int64_t>());
      auto attrs = draco->find("attributes");
      if (attrs == draco->end() || !attrs->is_object()) {
        throw LoadError(where + "KHR_draco_mesh_compression.attributes missing or not an object");
      }
      for (auto it = attrs->begin(); it != attrs->end(); ++it) {
        if (!it->is_number_integer() || it->get<std::int64_t>() < 0 ||
            it->get<std::int64_t>() > std::numeric_limits<int>::max()) {
          throw LoadError(where + "KHR_draco_mesh_compression.attributes." + it.key() +
                          " is not a valid Draco attribute id");
        }
        d.attributes[it.key()] = static_cast<int>(it->get<std::int64_t>());
      }
      auto indices = prim.find("indices");
      if (indices != prim.end()) {
        if (indices->is_number_integer() && indices->get<std::int64_t>() >= 0 &&
            indices->get<std::int64_t>() <= std::numeric_limits<int>::max()) {
          d.original_indices = static_cast<int>(indices->get<std::int64_t>());
        }
        prim.erase(indices);
      }
      ext->erase(draco);
      out[{static_cast<int>(m), static_cast<int>(p)}] = d;
    }
  }
  return out;
}

bool IgnoreImage(tinygltf::Image*, const int, std::string*, std::string*, int, int,
                 const unsigned char*, int, void*) {
  return true;  // images are not needed for geometry
}

std::string Trimmed(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s;
}

// Runs tinygltf on the file's bytes, after taking Draco out of the JSON.
tinygltf::Model ParseWithTinyGltf(const std::string& path,
                                  std::map<DracoKey, DracoPrimitive>* draco,
                                  std::vector<std::string>* notes) {
  std::vector<unsigned char> bytes = ReadWholeFile(path);
  const bool is_glb = bytes.size() >= 4 && ReadU32Le(bytes, 0) == kGlbMagic;
  std::optional<GlbLayout> glb;
  std::string json_text;
  if (is_glb) {
    glb = ParseGlbLayout(bytes);
    json_text.assign(reinterpret_cast<const char*>(bytes.data() + glb->json_offset),
                     glb->json_length);
  } else {
    json_text.assign(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  }

  // Both parsers recurse per nesting level: a deep file must not reach them (stack overflow).
  if (const std::size_t depth = JsonNestingDepth(json_text); depth > kMaxJsonNesting) {
    throw LoadError("the JSON nests " + std::to_string(depth) + " levels deep (at most " +
                    std::to_string(kMaxJsonNesting) + " are accepted)");
  }
  nlohmann::json doc = nlohmann::json::parse(json_text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded()) throw LoadError("the JSON does not parse");
  *draco = ExtractDraco(doc);
  bool edited = !draco->empty();
  // Skins are ignored; taking them out spares tinygltf 2.7's refusal of a skin without
  // inverseBindMatrices (valid glTF: tinygltf issue 492).
  if (doc.is_object() && doc.contains("skins")) {
    const std::size_t n = doc["skins"].is_array() ? doc["skins"].size() : 1;
    notes->push_back(std::to_string(n) + " skin(s) ignored (bind pose used)");
    doc.erase("skins");
    if (doc.contains("nodes") && doc["nodes"].is_array()) {
      for (nlohmann::json& node : doc["nodes"]) {
        if (node.is_object()) node.erase("skin");
      }
    }
    edited = true;
  }
  if (edited) {
    json_text = doc.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    if (is_glb) {
      // Rebuild the GLB with the edited JSON chunk and the original BIN chunk.
      while (json_text.size() % 4 != 0) json_text.push_back(' ');
      std::vector<unsigned char> rebuilt;
      const std::size_t bin_size = glb->bin ? glb->bin->second : 0;
      const std::size_t bin_padded = (bin_size + 3) & ~std::size_t{3};
      const std::size_t total = 12 + 8 + json_text.size() + (glb->bin ? 8 + bin_padded : 0);
      if (total > std::numeric_limits<std::uint32_t>::max()) throw LoadError("GLB too large");
      rebuilt.reserve(total);
      AppendU32Le(rebuilt, kGlbMagic);
      AppendU32Le(rebuilt, 2);
      AppendU32Le(rebuilt, static_cast<std::uint32_t>(total));
      AppendU32Le(rebuilt, static_cast<std::uint32_t>(json_text.size()));
      AppendU32Le(rebuilt, kGlbChunkJson);
      rebuilt.insert(rebuilt.end(), json_text.begin(), json_text.end());
      if (glb->bin) {
        AppendU32Le(rebuilt, static_cast<std::uint32_t>(bin_padded));
        AppendU32Le(rebuilt, kGlbChunkBin);
        rebuilt.insert(rebuilt.end(), bytes.begin() + static_cast<std::ptrdiff_t>(glb->bin->first),
                       bytes.begin() + static_cast<std::ptrdiff_t>(glb->bin->first + bin_size));
        rebuilt.resize(total, 0);
      }
      bytes = std::move(rebuilt);
    }
  }

  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&IgnoreImage, nullptr);
  tinygltf::Model model;
  std::string err;
  std::string warn;
  const std::string base_dir = std::filesystem::path(path).parent_path().string();
  bool ok = false;
  if (is_glb) {
    ok = loader.LoadBinaryFromMemory(&model, &err, &warn, bytes.data(),
                                     static_cast<unsigned int>(bytes.size()), base_dir);
  } else {
    if (json_text.size() > std::numeric_limits<unsigned int>::max())
      throw LoadError("JSON too large");
    ok = loader.LoadASCIIFromString(&model, &err, &warn, json_text.data(),
                                    static_cast<unsigned int>(json_text.size()), base_dir);
  }
  if (!ok || !err.empty()) {
    std::string message =
        "tinygltf refuses the file: " + (err.empty() ? "(no error text)" : Trimmed(err));
    if (!warn.empty()) message += "; warnings: " + Trimmed(warn);
    throw LoadError(message);
  }
  if (!warn.empty()) notes->push_back("tinygltf warning: " + Trimmed(warn));
  return model;
}

// A checked view of an accessor's elements.
struct AccessorView {
  const unsigned char* data = nullptr;  // null when the accessor has no buffer view (all zeros)
  std::size_t stride = 0;
  std::size_t count = 0;
};

constexpr std::int64_t kMaxNodeVisits = 1'000'000;
constexpr std::size_t kMaxAccessorCount = std::size_t{1} << 31;

AccessorView ViewAccessor(const tinygltf::Model& model, int index, std::size_t element_size,
                          const std::string& what) {
  if (index < 0 || static_cast<std::size_t>(index) >= model.accessors.size()) {
    throw LoadError(what + ": accessor " + std::to_string(index) + " out of range [0, " +
                    std::to_string(model.accessors.size()) + ")");
  }
  const tinygltf::Accessor& a = model.accessors[static_cast<std::size_t>(index)];
  const std::string name = what + " (accessor " + std::to_string(index) + ")";
  if (a.sparse.isSparse) throw LoadError(name + ": sparse accessors are not supported");
  if (a.count > kMaxAccessorCount) {
    throw LoadError(name + ": count " + std::to_string(a.count) + " is absurd");
  }
  AccessorView v;
  v.count = a.count;
  v.stride = element_size;
  if (a.bufferView < 0) return v;  // glTF: all zeros
  if (static_cast<std::size_t>(a.bufferView) >= model.bufferViews.size()) {
    throw LoadError(name + ": buffer view " + std::to_string(a.bufferView) + " out of range");
  }
  const tinygltf::BufferView& bv = model.bufferViews[static_cast<std::size_t>(a.bufferView)];
  if (bv.buffer < 0 || static_cast<std::size_t>(bv.buffer) >= model.buffers.size()) {
    throw LoadError(name + ": buffer " + std::to_string(bv.buffer) + " of buffer view " +
                    std::to_string(a.bufferView) + " out of range");
  }
  const tinygltf::Buffer& buffer = model.buffers[static_cast<std::size_t>(bv.buffer)];
  // All sizes below are < 2^32 (tinygltf's lengths) or < 2^31 (count), so 64-bit sums are exact.
  const std::uint64_t view_end = std::uint64_t{bv.byteOffset} + bv.byteLength;
  if (view_end > buffer.data.size()) {
    throw LoadError(name + ": buffer view " + std::to_string(a.bufferView) + " [" +
                    std::to_string(bv.byteOffset) + ", " + std::to_string(view_end) +
                    ") runs past buffer " + std::to_string(bv.buffer) + " of " +
                    std::to_string(buffer.data.size()) + " bytes");
  }
  if (bv.byteStride != 0) {
    if (bv.byteStride < element_size) {
      throw LoadError(name + ": byteStride " + std::to_string(bv.byteStride) +
                      " is smaller than the element size " + std::to_string(element_size));
    }
    v.stride = bv.byteStride;
  }
  if (v.count > 0) {
    const std::uint64_t end =
        std::uint64_t{a.byteOffset} + std::uint64_t{v.stride} * (v.count - 1) + element_size;
    if (end > bv.byteLength) {
      throw LoadError(name + ": " + std::to_string(v.count) + " elements from byte " +
                      std::to_string(a.byteOffset) + " need " + std::to_string(end) +
                      " bytes, buffer view " + std::to_string(a.bufferView) + " has " +
                      std::to_string(bv.byteLength) + " (accessor out of buffer range)");
    }
  }
  v.data = buffer.data.data() + bv.byteOffset + a.byteOffset;
  return v;
}

const char* ComponentName(int type) {
  switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
      return "BYTE";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return "UNSIGNED_BYTE";
    case TINYGLTF_COMPONENT_TYPE_SHORT:
      return "SHORT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      return "UNSIGNED_SHORT";
    case TINYGLTF_COMPONENT_TYPE_INT:
      return "INT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
      return "UNSIGNED_INT";
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      return "FLOAT";
    case TINYGLTF_COMPONENT_TYPE_DOUBLE:
      return "DOUBLE";
    default:
      return "unknown";
  }
}

// Vertex positions and the corner list (before strip/fan conversion) of one primitive.
struct PrimitiveData {
  std::vector<glm::dvec3> positions;
  std::vector<std::uint32_t> corners;  // indices, or 0..#V-1 for a non-indexed primitive
};

void ReadPositions(const tinygltf::Model& model, int accessor_index, const std::string& what,
                   std::vector<glm::dvec3>* out) {
  if (accessor_index >= 0 && static_cast<std::size_t>(accessor_index) < model.accessors.size()) {
    const tinygltf::Accessor& a = model.accessors[static_cast<std::size_t>(accessor_index)];
    if (a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT || a.type != TINYGLTF_TYPE_VEC3) {
      throw LoadError(what + ": POSITION accessor " + std::to_string(accessor_index) + " has " +
                      ComponentName(a.componentType) + " components of type code " +
                      std::to_string(a.type) + "; FLOAT VEC3 is required (wrong component type)");
    }
  }
  const AccessorView v = ViewAccessor(model, accessor_index, 12, what + " POSITION");
  if (static_cast<std::int64_t>(v.count) > kGltfMaxVertices) {
    throw LoadError(what + ": " + std::to_string(v.count) + " vertices exceed the limit of " +
                    std::to_string(kGltfMaxVertices));
  }
  out->assign(v.count, glm::dvec3(0.0));
  if (v.data == nullptr) return;
  for (std::size_t i = 0; i < v.count; ++i) {
    float xyz[3];
    std::memcpy(xyz, v.data + i * v.stride, sizeof xyz);
    for (int k = 0; k < 3; ++k) {
      if (!std::isfinite(xyz[k])) {
        throw LoadError(what + ": POSITION of vertex " + std::to_string(i) +
                        " is not finite (NaN or infinite)");
      }
    }
    (*out)[i] = glm::dvec3(xyz[0], xyz[1], xyz[2]);
  }
}

void ReadIndices(const tinygltf::Model& model, int accessor_index, const std::string& what,
                 std::vector<std::uint32_t>* out) {
  if (accessor_index < 0 || static_cast<std::size_t>(accessor_index) >= model.accessors.size()) {
    throw LoadError(what + ": indices accessor " + std::to_string(accessor_index) +
                    " out of range");
  }
  const tinygltf::Accessor& a = model.accessors[static_cast<std::size_t>(accessor_index)];
  std::size_t size = 0;
  switch (a.componentType) {
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      size = 1;
      break;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      size = 2;
      break;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
      size = 4;
      break;
    default:
      throw LoadError(what + ": indices accessor " + std::to_string(accessor_index) + " has " +
                      ComponentName(a.componentType) +
                      " components; UNSIGNED_BYTE/SHORT/INT is required (wrong component type)");
  }
  if (a.type != TINYGLTF_TYPE_SCALAR) {
    throw LoadError(what + ": indices accessor " + std::to_string(accessor_index) +
                    " is not SCALAR (wrong type)");
  }
  const AccessorView v = ViewAccessor(model, accessor_index, size, what + " indices");
  if (static_cast<std::int64_t>(v.count) > 3 * kGltfMaxTriangles + 2) {
    throw LoadError(what + ": " + std::to_string(v.count) +
                    " indices exceed the triangle limit of " + std::to_string(kGltfMaxTriangles));
  }
  out->assign(v.count, 0);
  if (v.data == nullptr) return;
  for (std::size_t i = 0; i < v.count; ++i) {
    const unsigned char* p = v.data + i * v.stride;
    std::uint32_t value = 0;
    if (size == 1) {
      value = p[0];
    } else if (size == 2) {
      std::uint16_t s;
      std::memcpy(&s, p, 2);
      value = s;
    } else {
      std::memcpy(&value, p, 4);
    }
    (*out)[i] = value;
  }
}

PrimitiveData DecodeDracoPrimitive(const tinygltf::Model& model, const DracoPrimitive& d,
                                   const std::string& what) {
  if (static_cast<std::size_t>(d.buffer_view) >= model.bufferViews.size()) {
    throw LoadError(what + ": Draco buffer view " + std::to_string(d.buffer_view) +
                    " out of range");
  }
  const tinygltf::BufferView& bv = model.bufferViews[static_cast<std::size_t>(d.buffer_view)];
  if (bv.buffer < 0 || static_cast<std::size_t>(bv.buffer) >= model.buffers.size()) {
    throw LoadError(what + ": buffer " + std::to_string(bv.buffer) +
                    " of the Draco buffer view out of range");
  }
  const tinygltf::Buffer& buffer = model.buffers[static_cast<std::size_t>(bv.buffer)];
  if (std::uint64_t{bv.byteOffset} + bv.byteLength > buffer.data.size()) {
    throw LoadError(what + ": Draco buffer view " + std::to_string(d.buffer_view) +
                    " runs past its buffer of " + std::to_string(buffer.data.size()) + " bytes");
  }
  auto pos = d.attributes.find("POSITION");
  if (pos == d.attributes.end()) {
    throw LoadError(what + ": KHR_draco_mesh_compression has no POSITION attribute");
  }
  draco::DecoderBuffer in;
  in.Init(reinterpret_cast<const char*>(buffer.data.data() + bv.byteOffset), bv.byteLength);
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&in);
  if (!decoded.ok()) {
    throw LoadError(what +
                    ": Draco stream does not decode: " + decoded.status().error_msg_string());
  }
  const std::unique_ptr<draco::Mesh>& mesh = decoded.value();
  if (mesh == nullptr) throw LoadError(what + ": Draco stream decoded to nothing");
  const draco::PointAttribute* attr =
      mesh->GetAttributeByUniqueId(static_cast<std::uint32_t>(pos->second));
  if (attr == nullptr) {
    throw LoadError(what + ": Draco stream has no attribute with id " +
                    std::to_string(pos->second));
  }
  if (attr->num_components() != 3) {
    throw LoadError(what + ": Draco POSITION has " + std::to_string(attr->num_components()) +
                    " components, expected 3");
  }
  if (static_cast<std::int64_t>(mesh->num_points()) > kGltfMaxVertices ||
      static_cast<std::int64_t>(mesh->num_faces()) > kGltfMaxTriangles) {
    throw LoadError(what + ": Draco mesh of " + std::to_string(mesh->num_points()) +
                    " points and " + std::to_string(mesh->num_faces()) +
                    " faces exceeds the limits");
  }
  PrimitiveData out;
  out.positions.resize(mesh->num_points());
  for (draco::PointIndex i(0); i < mesh->num_points(); ++i) {
    float xyz[3] = {0.0f, 0.0f, 0.0f};
    if (!attr->ConvertValue<float>(attr->mapped_index(i), 3, xyz)) {
      throw LoadError(what + ": Draco POSITION of point " + std::to_string(i.value()) +
                      " cannot be read");
    }
    for (int k = 0; k < 3; ++k) {
      if (!std::isfinite(xyz[k])) {
        throw LoadError(what + ": Draco POSITION of point " + std::to_string(i.value()) +
                        " is not finite (NaN or infinite)");
      }
    }
    out.positions[i.value()] = glm::dvec3(xyz[0], xyz[1], xyz[2]);
  }
  out.corners.reserve(static_cast<std::size_t>(mesh->num_faces()) * 3);
  for (draco::FaceIndex f(0); f < mesh->num_faces(); ++f) {
    const draco::Mesh::Face& face = mesh->face(f);
    for (int k = 0; k < 3; ++k) out.corners.push_back(face[k].value());
  }
  return out;
}

// T·R·S as a matrix (glTF 2.0 §3.5.3), the same operations for rest and animated poses.
glm::dmat4 ComposeTrs(const glm::dvec3& t, const glm::dquat& r, const glm::dvec3& s) noexcept {
  glm::dmat4 X = glm::translate(glm::dmat4(1.0), t);
  X = X * glm::mat4_cast(r);
  return glm::scale(X, s);
}

// The rest transform of file node `index` (checked), without its place in the tree.
GltfNode RestNode(const tinygltf::Node& node, int index) {
  const std::string what = "node " + std::to_string(index);
  auto check = [&](const std::vector<double>& v, std::size_t n, const char* field) {
    if (!v.empty() && v.size() != n) {
      throw LoadError(what + ": " + field + " has " + std::to_string(v.size()) +
                      " numbers, expected " + std::to_string(n));
    }
    for (double x : v) {
      if (!std::isfinite(x)) throw LoadError(what + ": " + field + " is not finite");
    }
  };
  check(node.matrix, 16, "matrix");
  check(node.translation, 3, "translation");
  check(node.rotation, 4, "rotation");
  check(node.scale, 3, "scale");
  GltfNode out;
  out.node_index = index;
  if (!node.matrix.empty()) {
    out.has_matrix = true;
    glm::dmat4& X = out.X_PN;
    for (int c = 0; c < 4; ++c) {
      for (int r = 0; r < 4; ++r) X[c][r] = node.matrix[static_cast<std::size_t>(4 * c + r)];
    }
    if (X[0][3] != 0.0 || X[1][3] != 0.0 || X[2][3] != 0.0 || X[3][3] != 1.0) {
      throw LoadError(what + ": matrix's bottom row is not (0, 0, 0, 1)");
    }
    return out;
  }
  if (!node.translation.empty())
    out.translation = glm::dvec3(node.translation[0], node.translation[1], node.translation[2]);
  if (!node.rotation.empty()) {
    // glTF quaternions are (x, y, z, w); glm::dquat's constructor takes (w, x, y, z).
    glm::dquat q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
    const double norm = glm::length(q);
    if (!(norm > 1e-12)) throw LoadError(what + ": rotation quaternion has zero length");
    out.rotation = q / norm;
  }
  if (!node.scale.empty()) out.scale = glm::dvec3(node.scale[0], node.scale[1], node.scale[2]);
  out.X_PN = ComposeTrs(out.translation, out.rotation, out.scale);
  return out;
}

// Reads all triangle primitives of mesh `m` into one GltfMesh.
GltfMesh BuildMesh(const tinygltf::Model& model, int m,
                   const std::map<DracoKey, DracoPrimitive>& draco,
                   std::vector<std::string>* notes) {
  const tinygltf::Mesh& src = model.meshes[static_cast<std::size_t>(m)];
  GltfMesh out;
  out.name = src.name;
  out.gltf_mesh_index = m;
  for (std::size_t p = 0; p < src.primitives.size(); ++p) {
    const tinygltf::Primitive& prim = src.primitives[p];
    const std::string what =
        "mesh " + std::to_string(m) + " (\"" + src.name + "\") primitive " + std::to_string(p);
    if (prim.mode == TINYGLTF_MODE_POINTS || prim.mode == TINYGLTF_MODE_LINE ||
        prim.mode == TINYGLTF_MODE_LINE_LOOP || prim.mode == TINYGLTF_MODE_LINE_STRIP) {
      notes->push_back(what + ": mode " + std::to_string(prim.mode) +
                       " (points or lines) skipped: no surface");
      continue;
    }
    if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
        prim.mode != TINYGLTF_MODE_TRIANGLE_FAN) {
      throw LoadError(what + ": unknown mode " + std::to_string(prim.mode));
    }
    PrimitiveData data;
    int mode = prim.mode;
    auto d = draco.find({m, static_cast<int>(p)});
    if (d != draco.end()) {
      data = DecodeDracoPrimitive(model, d->second, what);
      mode = TINYGLTF_MODE_TRIANGLES;  // the decoded faces are a triangle list
      ++out.draco_primitive_count;
    } else {
      auto pos = prim.attributes.find("POSITION");
      if (pos == prim.attributes.end()) {
        notes->push_back(what + ": no POSITION attribute, skipped");
        continue;
      }
      ReadPositions(model, pos->second, what, &data.positions);
      for (const auto& [attribute, accessor] : prim.attributes) {
        if (accessor < 0 || static_cast<std::size_t>(accessor) >= model.accessors.size()) {
          throw LoadError(what + ": attribute " + attribute + " refers to accessor " +
                          std::to_string(accessor) + " out of range");
        }
        const std::size_t count = model.accessors[static_cast<std::size_t>(accessor)].count;
        if (count != data.positions.size()) {
          throw LoadError(what + ": attribute " + attribute + " has " + std::to_string(count) +
                          " elements, POSITION has " + std::to_string(data.positions.size()) +
                          " (vertex arrays of different lengths)");
        }
      }
      if (prim.indices >= 0) {
        ReadIndices(model, prim.indices, what, &data.corners);
      } else {
        data.corners.resize(data.positions.size());
        for (std::size_t i = 0; i < data.corners.size(); ++i)
          data.corners[i] = static_cast<std::uint32_t>(i);
      }
    }
    const std::size_t nv = data.positions.size();
    for (std::size_t i = 0; i < data.corners.size(); ++i) {
      if (data.corners[i] >= nv) {
        throw LoadError(what + ": index " + std::to_string(data.corners[i]) + " at position " +
                        std::to_string(i) + " out of range [0, " + std::to_string(nv) +
                        ") (index out of range)");
      }
    }
    const std::size_t base = out.mesh_N.vertices.size();
    if (static_cast<std::int64_t>(base + nv) > kGltfMaxVertices) {
      throw LoadError(what + ": more than " + std::to_string(kGltfMaxVertices) +
                      " vertices in the mesh");
    }
    out.mesh_N.vertices.insert(out.mesh_N.vertices.end(), data.positions.begin(),
                               data.positions.end());
    auto add = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
      if (a == b || b == c || c == a) {
        ++out.dropped_degenerate_triangles;
        return;
      }
      out.mesh_N.triangles.emplace_back(static_cast<int>(base + a), static_cast<int>(base + b),
                                        static_cast<int>(base + c));
    };
    const std::vector<std::uint32_t>& k = data.corners;
    const std::size_t n = k.size();
    if (mode == TINYGLTF_MODE_TRIANGLES) {
      if (n % 3 != 0) {
        throw LoadError(what + ": TRIANGLES with " + std::to_string(n) +
                        " corners, not a multiple of 3 (incorrect vertex array length)");
      }
      for (std::size_t i = 0; i + 2 < n; i += 3) add(k[i], k[i + 1], k[i + 2]);
    } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
      // glTF 2.0 §3.7.2.1: triangle i = (v_i, v_{i+1+i%2}, v_{i+2-i%2}).
      for (std::size_t i = 0; i + 2 < n; ++i) {
        if (i % 2 == 0) {
          add(k[i], k[i + 1], k[i + 2]);
        } else {
          add(k[i], k[i + 2], k[i + 1]);
        }
      }
    } else {
      // Fan: triangle i = (v_{i+1}, v_{i+2}, v_0).
      for (std::size_t i = 0; i + 2 < n; ++i) add(k[i + 1], k[i + 2], k[0]);
    }
    if (static_cast<std::int64_t>(out.mesh_N.triangles.size()) > kGltfMaxTriangles) {
      throw LoadError(what + ": more than " + std::to_string(kGltfMaxTriangles) +
                      " triangles in the mesh");
    }
    ++out.primitive_count;
  }
  return out;
}

// Reads `count`-checked FLOAT elements of `components` numbers (1, 3 or 4) from an accessor into
// dvec4s (unused components 0), refusing NaN and infinities.
void ReadFloatElements(const tinygltf::Model& model, int accessor_index, int components,
                       const std::string& what, std::vector<glm::dvec4>* out) {
  const AccessorView v =
      ViewAccessor(model, accessor_index, static_cast<std::size_t>(components) * 4, what);
  out->assign(v.count, glm::dvec4(0.0));
  if (v.data == nullptr) return;
  for (std::size_t i = 0; i < v.count; ++i) {
    float xyzw[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    std::memcpy(xyzw, v.data + i * v.stride, sizeof(float) * static_cast<std::size_t>(components));
    for (int k = 0; k < components; ++k) {
      if (!std::isfinite(xyzw[k])) {
        throw LoadError(what + ": element " + std::to_string(i) +
                        " is not finite (NaN or infinite)");
      }
    }
    (*out)[i] = glm::dvec4(xyzw[0], xyzw[1], xyzw[2], xyzw[3]);
  }
}

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

// Reads and checks the translation/rotation/scale channels of every animation. `first_entry`
// maps a file node to its first entry in `nodes` (-1 when the scene does not reach it).
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

GltfScene BuildScene(const std::string& path) {
  GltfScene scene;
  scene.path = path;
  std::map<DracoKey, DracoPrimitive> draco;
  const tinygltf::Model model = ParseWithTinyGltf(path, &draco, &scene.notes);

  for (const std::string& ext : model.extensionsRequired) {
    if (ext == "KHR_draco_mesh_compression") continue;
    if (ext == "EXT_meshopt_compression" || ext == "KHR_meshopt_compression" ||
        ext == "KHR_mesh_quantization" || ext == "EXT_mesh_gpu_instancing") {
      throw LoadError("requires extension " + ext +
                      ", which changes geometry and is not supported");
    }
    scene.notes.push_back("required extension " + ext + " ignored (does not change geometry)");
  }
  if (!model.cameras.empty())
    scene.notes.push_back(std::to_string(model.cameras.size()) + " camera(s) ignored");
  if (!model.skins.empty())
    scene.notes.push_back(std::to_string(model.skins.size()) + " skin(s) ignored (bind pose used)");
  if (!model.materials.empty())
    scene.notes.push_back(std::to_string(model.materials.size()) + " material(s) ignored");

  // The node graph must be acyclic, with children in range. glTF 2.0 asks for disjoint trees,
  // but some files (Draco's CubeScaledInstances) instance a node under several parents: such a
  // node is shown once per path from the root, with a note.
  const std::size_t node_count = model.nodes.size();
  std::vector<int> parents(node_count, 0);
  for (std::size_t n = 0; n < node_count; ++n) {
    for (int c : model.nodes[n].children) {
      if (c < 0 || static_cast<std::size_t>(c) >= node_count) {
        throw LoadError("node " + std::to_string(n) + " has child " + std::to_string(c) +
                        " out of range [0, " + std::to_string(node_count) + ")");
      }
      ++parents[static_cast<std::size_t>(c)];
    }
  }
  {
    // Iterative three-colour depth-first search: reaching a node that is still open is a cycle.
    enum : char { kNew, kOpen, kDone };
    std::vector<char> colour(node_count, kNew);
    std::vector<std::pair<int, std::size_t>> stack;  // node, next child to look at
    for (std::size_t start = 0; start < node_count; ++start) {
      if (colour[start] != kNew) continue;
      stack.emplace_back(static_cast<int>(start), 0);
      colour[start] = kOpen;
      while (!stack.empty()) {
        auto& [n, next] = stack.back();
        const std::vector<int>& children = model.nodes[static_cast<std::size_t>(n)].children;
        if (next == children.size()) {
          colour[static_cast<std::size_t>(n)] = kDone;
          stack.pop_back();
          continue;
        }
        const int c = children[next++];
        if (colour[static_cast<std::size_t>(c)] == kOpen) {
          throw LoadError("node " + std::to_string(n) + " has child " + std::to_string(c) +
                          ", which is one of its ancestors (node cycle)");
        }
        if (colour[static_cast<std::size_t>(c)] == kNew) {
          colour[static_cast<std::size_t>(c)] = kOpen;
          stack.emplace_back(c, 0);
        }
      }
    }
  }
  const std::size_t shared = static_cast<std::size_t>(
      std::count_if(parents.begin(), parents.end(), [](int p) { return p > 1; }));
  if (shared > 0) {
    scene.notes.push_back(std::to_string(shared) +
                          " node(s) have several parents (glTF 2.0 asks for trees): shown once "
                          "per path from the root");
  }

  std::vector<int> roots;
  if (!model.scenes.empty()) {
    int s = model.defaultScene;
    if (s < 0) {
      s = 0;
      scene.notes.push_back("no default scene: scene 0 of " + std::to_string(model.scenes.size()) +
                            " used");
    } else if (static_cast<std::size_t>(s) >= model.scenes.size()) {
      throw LoadError("default scene " + std::to_string(s) + " out of range [0, " +
                      std::to_string(model.scenes.size()) + ")");
    } else {
      scene.notes.push_back("scene " + std::to_string(s) + " (default) used");
    }
    for (int n : model.scenes[static_cast<std::size_t>(s)].nodes) {
      if (n < 0 || static_cast<std::size_t>(n) >= node_count) {
        throw LoadError("scene " + std::to_string(s) + " lists node " + std::to_string(n) +
                        " out of range");
      }
      if (parents[static_cast<std::size_t>(n)] > 0) {
        scene.notes.push_back("scene " + std::to_string(s) + " lists node " + std::to_string(n) +
                              ", which is also a child of another node");
      }
      roots.push_back(n);
    }
    if (roots.empty())
      scene.notes.push_back("scene " + std::to_string(s) + " has no nodes: nothing to show");
  } else {
    for (std::size_t n = 0; n < node_count; ++n) {
      if (parents[n] == 0) roots.push_back(static_cast<int>(n));
    }
    scene.notes.push_back("no scene in the file: all " + std::to_string(roots.size()) +
                          " root nodes used");
  }

  // Depth-first from the roots. The graph is acyclic (checked above), so this ends; shared
  // children can still multiply the paths, hence the cap on visits.
  std::int64_t visits = 0;
  std::vector<int> mesh_slot(model.meshes.size(), -1);
  std::int64_t total_triangles = 0;
  std::int64_t total_vertices = 0;
  // Entries of scene.nodes per file node: the first, and the last (to chain next_same_node).
  std::vector<int> first_entry(node_count, -1);
  std::vector<int> last_entry(node_count, -1);
  struct Pending {
    int node;
    int parent_entry;
    glm::dmat4 X_WP;
  };
  std::vector<Pending> stack;
  for (auto it = roots.rbegin(); it != roots.rend(); ++it)
    stack.push_back({*it, -1, glm::dmat4(1.0)});
  while (!stack.empty()) {
    const Pending top = stack.back();
    const int n = top.node;
    stack.pop_back();
    if (++visits > kMaxNodeVisits) {
      throw LoadError("more than " + std::to_string(kMaxNodeVisits) +
                      " node visits (shared children multiply the paths)");
    }
    const tinygltf::Node& node = model.nodes[static_cast<std::size_t>(n)];
    GltfNode entry = RestNode(node, n);
    entry.parent = top.parent_entry;
    const int e = static_cast<int>(scene.nodes.size());
    const std::size_t un = static_cast<std::size_t>(n);
    if (first_entry[un] < 0) {
      first_entry[un] = e;
    } else {
      scene.nodes[static_cast<std::size_t>(last_entry[un])].next_same_node = e;
    }
    last_entry[un] = e;
    const glm::dmat4 X_WN = top.X_WP * entry.X_PN;
    scene.nodes.push_back(entry);
    if (node.mesh >= 0) {
      if (static_cast<std::size_t>(node.mesh) >= model.meshes.size()) {
        throw LoadError("node " + std::to_string(n) + " refers to mesh " +
                        std::to_string(node.mesh) + " out of range [0, " +
                        std::to_string(model.meshes.size()) + ")");
      }
      int& slot = mesh_slot[static_cast<std::size_t>(node.mesh)];
      if (slot < 0) {
        GltfMesh mesh = BuildMesh(model, node.mesh, draco, &scene.notes);
        total_triangles += static_cast<std::int64_t>(mesh.mesh_N.triangles.size());
        total_vertices += static_cast<std::int64_t>(mesh.mesh_N.vertices.size());
        if (total_triangles > kGltfMaxTriangles || total_vertices > kGltfMaxVertices) {
          throw LoadError("scene exceeds the limit of " + std::to_string(kGltfMaxTriangles) +
                          " triangles / " + std::to_string(kGltfMaxVertices) + " vertices");
        }
        slot = static_cast<int>(scene.meshes.size());
        scene.meshes.push_back(std::move(mesh));
      }
      scene.instances.push_back({node.name, n, slot, X_WN, e});
    }
    for (auto c = node.children.rbegin(); c != node.children.rend(); ++c)
      stack.push_back({*c, e, X_WN});
  }
  scene.animations = ReadAnimations(model, first_entry, scene.nodes, &scene.notes);
  const std::size_t unused =
      static_cast<std::size_t>(std::count(mesh_slot.begin(), mesh_slot.end(), -1));
  if (unused > 0)
    scene.notes.push_back(std::to_string(unused) + " mesh(es) not shown by the scene, not loaded");
  return scene;
}

nlohmann::json Vec3Json(const glm::dvec3& v) { return nlohmann::json::array({v.x, v.y, v.z}); }

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

}  // namespace

GltfScene LoadGltfScene(const std::string& path) {
  try {
    return BuildScene(path);
  } catch (const LoadError& e) {
    throw std::runtime_error(path + ": " + e.what());
  } catch (const std::bad_alloc&) {
    throw std::runtime_error(path + ": out of memory while loading");
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

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

  double t = time_s;
  const double duration = anim->duration_s;
  if (loop && std::isfinite(t) && duration > 0.0 && std::isfinite(duration)) {
    t = std::fmod(t, duration);
    if (t < 0.0) t += duration;
  }
  const std::vector<GltfAnimationChannel>& channels = anim->channels;
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
    const glm::dmat4 X_PN = ComposeTrs(translation, rotation, scale);
    // Every path to the node; next_same_node only grows, so this ends.
    for (int v = first;;) {
      X[static_cast<std::size_t>(v)] = X_PN;
      const int next = scene.nodes[static_cast<std::size_t>(v)].next_same_node;
      if (next <= v || static_cast<std::size_t>(next) >= n_nodes) break;
      v = next;
    }
  }
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

std::vector<glm::dmat4> PoseInstancesAt(const GltfScene& scene, int animation, double time_s,
                                        bool loop) {
  std::vector<glm::dmat4> X_WN;
  X_WN.reserve(std::max(scene.nodes.size(), scene.instances.size()));
  PoseInstancesAt(scene, animation, time_s, loop, &X_WN);
  return X_WN;
}

nlohmann::json SceneSummaryJson(const GltfScene& scene) {
  nlohmann::json j;
  j["path"] = scene.path;
  j["notes"] = scene.notes;
  j["meshes"] = nlohmann::json::array();
  std::int64_t mesh_triangles = 0;
  std::int64_t vertices = 0;
  for (const GltfMesh& m : scene.meshes) {
    j["meshes"].push_back({{"name", m.name},
                           {"gltf_mesh_index", m.gltf_mesh_index},
                           {"triangles", m.mesh_N.triangles.size()},
                           {"vertices", m.mesh_N.vertices.size()},
                           {"primitives", m.primitive_count},
                           {"draco_primitives", m.draco_primitive_count},
                           {"dropped_degenerate_triangles", m.dropped_degenerate_triangles}});
    mesh_triangles += static_cast<std::int64_t>(m.mesh_N.triangles.size());
    vertices += static_cast<std::int64_t>(m.mesh_N.vertices.size());
  }
  j["instances"] = nlohmann::json::array();
  std::int64_t triangles = 0;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  glm::dvec3 lo_all(kInf);
  glm::dvec3 hi_all(-kInf);
  for (const GltfMeshInstance& inst : scene.instances) {
    nlohmann::json e = {
        {"node", inst.node_name}, {"node_index", inst.node_index}, {"mesh", inst.mesh}};
    if (inst.mesh >= 0 && static_cast<std::size_t>(inst.mesh) < scene.meshes.size()) {
      const GltfMesh& m = scene.meshes[static_cast<std::size_t>(inst.mesh)];
      e["mesh_name"] = m.name;
      e["triangles"] = m.mesh_N.triangles.size();
      e["vertices"] = m.mesh_N.vertices.size();
      triangles += static_cast<std::int64_t>(m.mesh_N.triangles.size());
      if (!m.mesh_N.vertices.empty()) {
        glm::dvec3 lo(kInf);
        glm::dvec3 hi(-kInf);
        for (const glm::dvec3& p_N : m.mesh_N.vertices) {
          const glm::dvec3 p_W = glm::dvec3(inst.X_WN * glm::dvec4(p_N, 1.0));
          lo = glm::min(lo, p_W);
          hi = glm::max(hi, p_W);
        }
        e["bbox_min_W"] = Vec3Json(lo);
        e["bbox_max_W"] = Vec3Json(hi);
        lo_all = glm::min(lo_all, lo);
        hi_all = glm::max(hi_all, hi);
      }
    }
    j["instances"].push_back(std::move(e));
  }
  nlohmann::json totals = {{"instances", scene.instances.size()},
                           {"meshes", scene.meshes.size()},
                           {"triangles", triangles},
                           {"mesh_triangles", mesh_triangles},
                           {"vertices", vertices}};
  if (lo_all.x <= hi_all.x) {
    totals["bbox_min_W"] = Vec3Json(lo_all);
    totals["bbox_max_W"] = Vec3Json(hi_all);
  }
  j["totals"] = std::move(totals);
  j["animations"] = nlohmann::json::array();
  for (const GltfAnimation& a : scene.animations) {
    j["animations"].push_back(
        {{"name", a.name}, {"channels", a.channels.size()}, {"duration_s", a.duration_s}});
  }
  return j;
}

}  // namespace ht
