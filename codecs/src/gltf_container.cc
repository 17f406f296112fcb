// The glTF container: reading the file (within kGltfMaxFileBytes), telling a GLB (header and
// chunks, checked against the file's size) from a JSON glTF, taking Draco and skins out of the
// JSON and running tinygltf on the result (buffers and their URIs).
//
// The only translation unit that compiles tiny_gltf.h's implementation. It is built with
// tinygltf=proj_tinygltf (set on the codecs target) so that its symbols do not clash with the
// older tinygltf copy that libdraco.so exports (docs/DEPENDENCIES.md trap 1).
//
// TINYGLTF_ENABLE_DRACO is deliberately NOT defined: tinygltf 2.7's Draco path
// (ParseDracoExtension) indexes bufferViews, buffers and accessors without bounds checks and
// dereferences a null attribute when the stream lacks an id, so a malformed file could crash the
// process. Instead the KHR_draco_mesh_compression objects (and the Draco primitives' `indices`,
// whose accessors have no buffer view) are taken out of the JSON before tinygltf sees it, and the
// Draco streams are decoded in gltf_draco.cc with every index and range checked.
#define TINYGLTF_IMPLEMENTATION
#include "gltf_internal.h"
// gltf_internal.h is included first: it includes tiny_gltf.h, whose implementation must see only
// its own configuration.

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "codecs/gltf_scene.h"
#include "codecs/json_nesting.h"
#include "haptic_core/byte_order.h"

namespace ht::gltf_internal {
namespace {

constexpr std::uint32_t kGlbMagic = 0x46546C67;      // "glTF"
constexpr std::uint32_t kGlbChunkJson = 0x4E4F534A;  // "JSON"
constexpr std::uint32_t kGlbChunkBin = 0x004E4942;   // "BIN\0"

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
  const std::uint32_t version = LoadLe<std::uint32_t>(bytes.data() + 4);
  if (version != 2) throw LoadError("GLB version " + std::to_string(version) + ", expected 2");
  const std::uint32_t length = LoadLe<std::uint32_t>(bytes.data() + 8);
  if (length > bytes.size()) {
    throw LoadError("GLB truncated: header declares " + std::to_string(length) +
                    " bytes, the file has " + std::to_string(bytes.size()));
  }
  if (length < 20)
    throw LoadError("GLB header declares an impossible length " + std::to_string(length));
  GlbLayout layout;
  const std::uint32_t json_length = LoadLe<std::uint32_t>(bytes.data() + 12);
  if (LoadLe<std::uint32_t>(bytes.data() + 16) != kGlbChunkJson)
    throw LoadError("GLB first chunk is not JSON");
  if (json_length > length - 20) {
    throw LoadError("GLB truncated: JSON chunk of " + std::to_string(json_length) +
                    " bytes runs past the declared length " + std::to_string(length));
  }
  layout.json_offset = 20;
  layout.json_length = json_length;
  std::size_t at = 20 + static_cast<std::size_t>(json_length);
  at = (at + 3) & ~std::size_t{3};  // chunks start 4-byte aligned
  if (at + 8 <= length) {
    const std::uint32_t bin_length = LoadLe<std::uint32_t>(bytes.data() + at);
    const std::uint32_t type = LoadLe<std::uint32_t>(bytes.data() + at + 4);
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

// Keeps an image's bytes as the file has them (PNG, JPEG): the display streams them undecoded.
// `user_data` is the model being loaded. tinygltf hands an image stored in a buffer view over as
// &buffer.data[byteOffset] and byteLength without checking them against the buffer's size (a
// fuzzed file read past it), so such an image is refused here unless its view lies inside its
// buffer; the buffers and views are parsed before the images.
bool KeepImageBytes(tinygltf::Image* image, const int index, std::string* err, std::string*, int,
                    int, const unsigned char* bytes, int size, void* user_data) {
  const auto* model = static_cast<const tinygltf::Model*>(user_data);
  if (model != nullptr && image->bufferView >= 0) {
    const auto view_index = static_cast<std::size_t>(image->bufferView);
    const bool view_ok = view_index < model->bufferViews.size();
    const tinygltf::BufferView* view = view_ok ? &model->bufferViews[view_index] : nullptr;
    const bool buffer_ok = view != nullptr && view->buffer >= 0 &&
                           static_cast<std::size_t>(view->buffer) < model->buffers.size();
    const std::size_t buffer_size =
        buffer_ok ? model->buffers[static_cast<std::size_t>(view->buffer)].data.size() : 0;
    if (!buffer_ok || view->byteOffset > buffer_size ||
        view->byteLength > buffer_size - view->byteOffset ||
        view->byteLength != static_cast<std::size_t>(std::max(size, 0))) {
      if (err != nullptr) {
        *err += "image[" + std::to_string(index) + "] bufferView " +
                std::to_string(image->bufferView) +
                (buffer_ok ? " (bytes " + std::to_string(view->byteOffset) + " + " +
                                 std::to_string(view->byteLength) + ") runs past its buffer of " +
                                 std::to_string(buffer_size) + " bytes"
                           : " names no buffer") +
                "\n";
      }
      return false;
    }
  }
  if (bytes != nullptr && size > 0) image->image.assign(bytes, bytes + size);
  image->as_is = true;
  return true;
}

std::string Trimmed(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s;
}

}  // namespace

// Runs tinygltf on the file's bytes, after taking Draco out of the JSON.
tinygltf::Model ParseWithTinyGltf(const std::string& path,
                                  std::map<DracoKey, DracoPrimitive>* draco,
                                  std::vector<std::string>* notes) {
  std::vector<unsigned char> bytes = ReadWholeFile(path);
  const bool is_glb = bytes.size() >= 4 && LoadLe<std::uint32_t>(bytes.data() + 0) == kGlbMagic;
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
      AppendLe(rebuilt, kGlbMagic);
      AppendLe(rebuilt, std::uint32_t{2});
      AppendLe(rebuilt, static_cast<std::uint32_t>(total));
      AppendLe(rebuilt, static_cast<std::uint32_t>(json_text.size()));
      AppendLe(rebuilt, kGlbChunkJson);
      rebuilt.insert(rebuilt.end(), json_text.begin(), json_text.end());
      if (glb->bin) {
        AppendLe(rebuilt, static_cast<std::uint32_t>(bin_padded));
        AppendLe(rebuilt, kGlbChunkBin);
        rebuilt.insert(rebuilt.end(), bytes.begin() + static_cast<std::ptrdiff_t>(glb->bin->first),
                       bytes.begin() + static_cast<std::ptrdiff_t>(glb->bin->first + bin_size));
        rebuilt.resize(total, 0);
      }
      bytes = std::move(rebuilt);
    }
  }

  tinygltf::TinyGLTF loader;
  tinygltf::Model model;
  loader.SetImageLoader(&KeepImageBytes, &model);
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

}  // namespace ht::gltf_internal
