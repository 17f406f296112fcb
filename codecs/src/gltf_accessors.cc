// glTF accessors: typed element data read out of buffer views with every offset, stride and
// count checked against the buffer (positions, texture coordinates, indices, and the float
// elements of animations).

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "codecs/gltf_scene.h"
#include "gltf_internal.h"

namespace ht::gltf_internal {
namespace {

constexpr std::size_t kMaxAccessorCount = std::size_t{1} << 31;

}  // namespace

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

void ReadTexCoords(const tinygltf::Model& model, int accessor_index, const std::string& what,
                   std::vector<glm::dvec2>* out) {
  if (accessor_index < 0 || static_cast<std::size_t>(accessor_index) >= model.accessors.size()) {
    throw LoadError(what + ": TEXCOORD_0 accessor " + std::to_string(accessor_index) +
                    " out of range");
  }
  const tinygltf::Accessor& a = model.accessors[static_cast<std::size_t>(accessor_index)];
  const std::string name = what + ": TEXCOORD_0 accessor " + std::to_string(accessor_index);
  if (a.type != TINYGLTF_TYPE_VEC2) {
    throw LoadError(name + " has type code " + std::to_string(a.type) +
                    "; VEC2 is required (wrong type)");
  }
  std::size_t component_size = 0;
  switch (a.componentType) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      component_size = 4;
      break;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      component_size = 1;
      break;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      component_size = 2;
      break;
    default:
      throw LoadError(name + " has " + ComponentName(a.componentType) +
                      " components; FLOAT or normalized UNSIGNED_BYTE/SHORT is required (wrong "
                      "component type)");
  }
  if (component_size != 4 && !a.normalized) {
    throw LoadError(name + " has " + ComponentName(a.componentType) +
                    " components that are not normalized (KHR_mesh_quantization's texture "
                    "coordinates are not supported; wrong component type)");
  }
  const AccessorView v =
      ViewAccessor(model, accessor_index, 2 * component_size, what + " TEXCOORD_0");
  if (static_cast<std::int64_t>(v.count) > kGltfMaxVertices) {
    throw LoadError(name + ": " + std::to_string(v.count) + " elements exceed the limit of " +
                    std::to_string(kGltfMaxVertices));
  }
  out->assign(v.count, glm::dvec2(0.0));
  if (v.data == nullptr) return;
  for (std::size_t i = 0; i < v.count; ++i) {
    const unsigned char* p = v.data + i * v.stride;
    if (component_size == 4) {
      float uv[2];
      std::memcpy(uv, p, sizeof uv);
      if (!std::isfinite(uv[0]) || !std::isfinite(uv[1])) {
        throw LoadError(name + ": TEXCOORD_0 of vertex " + std::to_string(i) +
                        " is not finite (NaN or infinite)");
      }
      (*out)[i] = glm::dvec2(uv[0], uv[1]);
    } else if (component_size == 2) {
      std::uint16_t uv[2];
      std::memcpy(uv, p, sizeof uv);
      (*out)[i] = glm::dvec2(uv[0], uv[1]) / 65535.0;
    } else {
      (*out)[i] = glm::dvec2(p[0], p[1]) / 255.0;
    }
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

}  // namespace ht::gltf_internal
