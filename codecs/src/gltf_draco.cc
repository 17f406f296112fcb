// KHR_draco_mesh_compression primitives of a glTF scene: taking the extension objects out of the
// JSON before tinygltf sees it (see gltf_container.cc for why), and decoding each primitive's
// Draco stream (positions, TEXCOORD_0, faces) with libdraco, every index and range checked.

#include <draco/compression/decode.h>
#include <draco/core/decoder_buffer.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "codecs/gltf_scene.h"
#include "gltf_internal.h"

namespace ht::gltf_internal {

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
  auto tex = d.attributes.find("TEXCOORD_0");
  if (tex != d.attributes.end()) {
    const draco::PointAttribute* uv =
        mesh->GetAttributeByUniqueId(static_cast<std::uint32_t>(tex->second));
    if (uv == nullptr) {
      throw LoadError(what + ": Draco stream has no attribute with id " +
                      std::to_string(tex->second) + " (TEXCOORD_0)");
    }
    if (uv->num_components() != 2) {
      throw LoadError(what + ": Draco TEXCOORD_0 has " + std::to_string(uv->num_components()) +
                      " components, expected 2");
    }
    // Dequantized by the decoder; normalized integer values are divided by their maximum.
    out.uv.resize(mesh->num_points());
    for (draco::PointIndex i(0); i < mesh->num_points(); ++i) {
      float st[2] = {0.0f, 0.0f};
      if (!uv->ConvertValue<float>(uv->mapped_index(i), 2, st)) {
        throw LoadError(what + ": Draco TEXCOORD_0 of point " + std::to_string(i.value()) +
                        " cannot be read");
      }
      if (!std::isfinite(st[0]) || !std::isfinite(st[1])) {
        throw LoadError(what + ": Draco TEXCOORD_0 of point " + std::to_string(i.value()) +
                        " is not finite (NaN or infinite)");
      }
      out.uv[i.value()] = glm::dvec2(st[0], st[1]);
    }
  }
  out.corners.reserve(static_cast<std::size_t>(mesh->num_faces()) * 3);
  for (draco::FaceIndex f(0); f < mesh->num_faces(); ++f) {
    const draco::Mesh::Face& face = mesh->face(f);
    for (int k = 0; k < 3; ++k) out.corners.push_back(face[k].value());
  }
  return out;
}

}  // namespace ht::gltf_internal
