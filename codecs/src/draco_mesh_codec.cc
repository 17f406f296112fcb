#include "codecs/draco_mesh_codec.h"

#include <draco/attributes/geometry_attribute.h>
#include <draco/attributes/point_attribute.h>
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/encoder_buffer.h>
#include <draco/mesh/mesh.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <utility>

namespace ht {
namespace {

constexpr int kMinQuantizationBits = 1;   // Draco's AttributeQuantizationTransform limits.
constexpr int kMaxQuantizationBits = 24;  // 2^bits-entry histogram in the encoder: 67 MB at 24
constexpr int kMinSpeed = 0;
constexpr int kMaxSpeed = 10;
constexpr std::size_t kMaxVertices = static_cast<std::size_t>(std::numeric_limits<int>::max());

void CheckQuantizationBits(int bits, const char* name = "position_quantization_bits") {
  if (bits < kMinQuantizationBits || bits > kMaxQuantizationBits) {
    throw std::invalid_argument(std::string("Draco: ") + name + " = " + std::to_string(bits) +
                                " is outside [1, 24]");
  }
}

// Float32 copy of vertex `i`; throws std::invalid_argument when it is not finite as a float.
std::array<float, 3> ToFloat3(const glm::dvec3& v, std::size_t i) {
  const std::array<float, 3> f = {static_cast<float>(v.x), static_cast<float>(v.y),
                                  static_cast<float>(v.z)};
  if (!(std::isfinite(f[0]) && std::isfinite(f[1]) && std::isfinite(f[2]))) {
    throw std::invalid_argument("Draco: vertex " + std::to_string(i) + " (" + std::to_string(v.x) +
                                ", " + std::to_string(v.y) + ", " + std::to_string(v.z) +
                                ") is not finite as a float32");
  }
  return f;
}

void ValidateMesh(const TriangleMesh& mesh) {
  if (mesh.vertices.empty() || mesh.triangles.empty()) {
    throw std::invalid_argument("Draco: cannot encode an empty mesh (" +
                                std::to_string(mesh.vertices.size()) + " vertices, " +
                                std::to_string(mesh.triangles.size()) + " triangles)");
  }
  if (mesh.vertices.size() > kMaxVertices) {
    throw std::invalid_argument("Draco: " + std::to_string(mesh.vertices.size()) +
                                " vertices exceed 2^31-1");
  }
  const auto num_vertices = static_cast<long long>(mesh.vertices.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const glm::ivec3& t = mesh.triangles[f];
    for (int c = 0; c < 3; ++c) {
      if (t[c] < 0 || t[c] >= num_vertices) {
        throw std::invalid_argument("Draco: triangle " + std::to_string(f) + " corner " +
                                    std::to_string(c) + " has index " + std::to_string(t[c]) +
                                    ", outside [0, " + std::to_string(num_vertices) + ")");
      }
    }
  }
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) ToFloat3(mesh.vertices[i], i);
}

void ValidateUv(std::span<const glm::dvec2> uv, std::size_t num_vertices) {
  if (uv.size() != num_vertices) {
    throw std::invalid_argument("Draco: " + std::to_string(uv.size()) +
                                " texture coordinates for " + std::to_string(num_vertices) +
                                " vertices (need one per vertex, or none)");
  }
  for (std::size_t i = 0; i < uv.size(); ++i) {
    const float u = static_cast<float>(uv[i].x), v = static_cast<float>(uv[i].y);
    if (!(std::isfinite(u) && std::isfinite(v))) {
      throw std::invalid_argument("Draco: texture coordinate " + std::to_string(i) + " (" +
                                  std::to_string(uv[i].x) + ", " + std::to_string(uv[i].y) +
                                  ") is not finite as a float32");
    }
  }
}

[[noreturn]] void ThrowDecodeError(const std::string& what) {
  throw std::runtime_error("Draco decode: " + what);
}

// The mesh's position attribute, checked to exist with 3 components.
const draco::PointAttribute* PositionAttribute(const draco::Mesh& dmesh) {
  const draco::PointAttribute* const position =
      dmesh.GetNamedAttribute(draco::GeometryAttribute::POSITION);
  if (position == nullptr) ThrowDecodeError("the mesh has no position attribute");
  if (position->num_components() != 3) {
    ThrowDecodeError("the position attribute has " +
                     std::to_string(static_cast<int>(position->num_components())) +
                     " components, expected 3");
  }
  return position;
}

// The decoded mesh with one vertex per Draco point: its position and its value of `tex` (2
// components).
DracoMesh ToPointMesh(const draco::Mesh& dmesh, const draco::PointAttribute& tex) {
  const draco::PointAttribute* const position = PositionAttribute(dmesh);
  if (tex.num_components() != 2) {
    ThrowDecodeError("the texture coordinate attribute has " +
                     std::to_string(static_cast<int>(tex.num_components())) +
                     " components, expected 2");
  }
  if (dmesh.num_faces() == 0) ThrowDecodeError("the mesh has no triangles");
  const std::size_t num_points = dmesh.num_points();
  if (num_points == 0) ThrowDecodeError("the mesh has no points");
  if (num_points > kMaxVertices) {
    ThrowDecodeError(std::to_string(num_points) + " points exceed 2^31-1");
  }
  for (const draco::PointAttribute* a : {position, &tex}) {
    if (!a->is_mapping_identity() && a->indices_map_size() < num_points) {
      ThrowDecodeError(std::string("the ") + (a == position ? "position" : "texture coordinate") +
                       " attribute maps fewer points than the mesh has");
    }
  }
  DracoMesh out;
  out.mesh.vertices.resize(num_points);
  out.uv.resize(num_points);
  for (std::size_t i = 0; i < num_points; ++i) {
    const draco::PointIndex point(static_cast<std::uint32_t>(i));
    std::array<double, 3> p{};
    std::array<double, 2> st{};
    // ConvertValue checks the value index against the attribute's buffer.
    if (!position->ConvertValue<double>(position->mapped_index(point), 3, p.data())) {
      ThrowDecodeError("the position of point " + std::to_string(i) + " cannot be read");
    }
    if (!tex.ConvertValue<double>(tex.mapped_index(point), 2, st.data())) {
      ThrowDecodeError("the texture coordinate of point " + std::to_string(i) + " cannot be read");
    }
    if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))) {
      ThrowDecodeError("the position of point " + std::to_string(i) + " is not finite");
    }
    if (!(std::isfinite(st[0]) && std::isfinite(st[1]))) {
      ThrowDecodeError("the texture coordinate of point " + std::to_string(i) + " is not finite");
    }
    out.mesh.vertices[i] = glm::dvec3(p[0], p[1], p[2]);
    out.uv[i] = glm::dvec2(st[0], st[1]);
  }
  out.mesh.triangles.resize(dmesh.num_faces());
  for (draco::FaceIndex f(0); f < dmesh.num_faces(); ++f) {
    const draco::Mesh::Face& face = dmesh.face(f);
    glm::ivec3& t = out.mesh.triangles[f.value()];
    for (int c = 0; c < 3; ++c) {
      if (face[c].value() >= num_points) {
        ThrowDecodeError("triangle " + std::to_string(f.value()) + " refers to point " +
                         std::to_string(face[c].value()) + " of " + std::to_string(num_points));
      }
      t[c] = static_cast<int>(face[c].value());
    }
  }
  return out;
}

TriangleMesh ToTriangleMesh(const draco::Mesh& dmesh) {
  const draco::PointAttribute* const position = PositionAttribute(dmesh);
  if (dmesh.num_faces() == 0) ThrowDecodeError("the mesh has no triangles");
  const std::size_t num_values = position->size();
  if (num_values == 0) ThrowDecodeError("the position attribute is empty");
  if (num_values > kMaxVertices) {
    ThrowDecodeError(std::to_string(num_values) + " positions exceed 2^31-1");
  }
  const std::size_t num_points = dmesh.num_points();
  if (!position->is_mapping_identity() && position->indices_map_size() < num_points) {
    ThrowDecodeError("the position attribute maps fewer points than the mesh has");
  }

  TriangleMesh mesh;
  mesh.vertices.resize(num_values);
  for (std::size_t i = 0; i < num_values; ++i) {
    std::array<double, 3> p{};
    const draco::AttributeValueIndex value(static_cast<std::uint32_t>(i));
    if (!position->ConvertValue<double>(value, 3, p.data())) {
      ThrowDecodeError("position " + std::to_string(i) + " cannot be read");
    }
    if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))) {
      ThrowDecodeError("position " + std::to_string(i) + " is not finite");
    }
    mesh.vertices[i] = glm::dvec3(p[0], p[1], p[2]);
  }

  mesh.triangles.resize(dmesh.num_faces());
  for (draco::FaceIndex f(0); f < dmesh.num_faces(); ++f) {
    const draco::Mesh::Face& face = dmesh.face(f);
    glm::ivec3& t = mesh.triangles[f.value()];
    for (int c = 0; c < 3; ++c) {
      if (face[c].value() >= num_points) {
        ThrowDecodeError("triangle " + std::to_string(f.value()) + " refers to point " +
                         std::to_string(face[c].value()) + " of " + std::to_string(num_points));
      }
      const std::uint32_t v = position->mapped_index(face[c]).value();
      if (v >= num_values) {
        ThrowDecodeError("triangle " + std::to_string(f.value()) + " refers to position " +
                         std::to_string(v) + " of " + std::to_string(num_values));
      }
      t[c] = static_cast<int>(v);
    }
  }
  return mesh;
}

}  // namespace

std::vector<std::uint8_t> EncodeMeshDraco(const TriangleMesh& mesh,
                                          const DracoEncodeOptions& options) {
  return EncodeMeshDracoWithUv(mesh, {}, options);
}

std::vector<std::uint8_t> EncodeMeshDracoWithUv(const TriangleMesh& mesh,
                                                std::span<const glm::dvec2> uv,
                                                const DracoEncodeOptions& options) {
  CheckQuantizationBits(options.position_quantization_bits);
  if (!uv.empty()) CheckQuantizationBits(options.uv_quantization_bits, "uv_quantization_bits");
  if (options.speed < kMinSpeed || options.speed > kMaxSpeed) {
    throw std::invalid_argument("Draco: speed = " + std::to_string(options.speed) +
                                " is outside [0, 10]");
  }
  ValidateMesh(mesh);
  if (!uv.empty()) ValidateUv(uv, mesh.vertices.size());

  // One Draco point per vertex, one position value (and one texture coordinate value) per point
  // (identity mapping): a point carries its position and its (u, v) together through Draco's
  // reordering.
  const auto num_vertices = static_cast<std::uint32_t>(mesh.vertices.size());
  draco::Mesh dmesh;
  dmesh.set_num_points(num_vertices);
  draco::GeometryAttribute geometry_attribute;
  geometry_attribute.Init(draco::GeometryAttribute::POSITION, nullptr, 3, draco::DT_FLOAT32,
                          /*normalized=*/false, sizeof(float) * 3, 0);
  const int attribute_id =
      dmesh.AddAttribute(geometry_attribute, /*identity_mapping=*/true, num_vertices);
  draco::PointAttribute* const position = dmesh.attribute(attribute_id);
  for (std::uint32_t i = 0; i < num_vertices; ++i) {
    const std::array<float, 3> p = ToFloat3(mesh.vertices[i], i);
    position->SetAttributeValue(draco::AttributeValueIndex(i), p.data());
  }
  if (!uv.empty()) {
    draco::GeometryAttribute tex_attribute;
    tex_attribute.Init(draco::GeometryAttribute::TEX_COORD, nullptr, 2, draco::DT_FLOAT32,
                       /*normalized=*/false, sizeof(float) * 2, 0);
    const int tex_id = dmesh.AddAttribute(tex_attribute, /*identity_mapping=*/true, num_vertices);
    draco::PointAttribute* const tex = dmesh.attribute(tex_id);
    for (std::uint32_t i = 0; i < num_vertices; ++i) {
      const std::array<float, 2> st = {static_cast<float>(uv[i].x), static_cast<float>(uv[i].y)};
      tex->SetAttributeValue(draco::AttributeValueIndex(i), st.data());
    }
  }
  dmesh.SetNumFaces(mesh.triangles.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const glm::ivec3& t = mesh.triangles[f];
    dmesh.SetFace(draco::FaceIndex(static_cast<std::uint32_t>(f)),
                  {draco::PointIndex(static_cast<std::uint32_t>(t.x)),
                   draco::PointIndex(static_cast<std::uint32_t>(t.y)),
                   draco::PointIndex(static_cast<std::uint32_t>(t.z))});
  }

  draco::Encoder encoder;
  encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION,
                                   options.position_quantization_bits);
  if (!uv.empty()) {
    encoder.SetAttributeQuantization(draco::GeometryAttribute::TEX_COORD,
                                     options.uv_quantization_bits);
  }
  encoder.SetSpeedOptions(options.speed, options.speed);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeMeshToBuffer(dmesh, &buffer);
  if (!status.ok()) {
    throw std::runtime_error("Draco encode failed: " + status.error_msg_string());
  }
  const auto* const data = reinterpret_cast<const std::uint8_t*>(buffer.data());
  return std::vector<std::uint8_t>(data, data + buffer.size());
}

namespace {

// Decodes `bytes` into positions and triangles, and with `with_uv` the first texture coordinate
// attribute too (one vertex per point then).
DracoMesh Decode(std::span<const std::uint8_t> bytes, bool with_uv) {
  // Draco sizes its allocations from counts in the stream: a corrupt count can ask for more
  // memory than there is, which surfaces as std::bad_alloc / std::length_error.
  try {
    draco::DecoderBuffer buffer;
    buffer.Init(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    auto geometry_type = draco::Decoder::GetEncodedGeometryType(&buffer);
    if (!geometry_type.ok()) {
      ThrowDecodeError("not a Draco stream (" + std::to_string(bytes.size()) +
                       " bytes): " + geometry_type.status().error_msg_string());
    }
    switch (geometry_type.value()) {
      case draco::TRIANGULAR_MESH:
        break;
      case draco::POINT_CLOUD:
        ThrowDecodeError("the stream holds a point cloud, not a triangle mesh");
      default:
        ThrowDecodeError("the stream holds an unknown geometry type " +
                         std::to_string(static_cast<int>(geometry_type.value())));
    }

    // GetEncodedGeometryType() only peeks at the header; decode from the start again.
    buffer.Init(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    draco::Decoder decoder;
    auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
    if (!decoded.ok()) {
      ThrowDecodeError("corrupt or truncated mesh stream (" + std::to_string(bytes.size()) +
                       " bytes): " + decoded.status().error_msg_string());
    }
    const std::unique_ptr<draco::Mesh> dmesh = std::move(decoded).value();
    if (dmesh == nullptr) ThrowDecodeError("Draco returned no mesh");
    const draco::PointAttribute* const tex =
        with_uv ? dmesh->GetNamedAttribute(draco::GeometryAttribute::TEX_COORD) : nullptr;
    if (tex != nullptr) return ToPointMesh(*dmesh, *tex);
    return {ToTriangleMesh(*dmesh), {}};
  } catch (const std::bad_alloc&) {
    ThrowDecodeError("corrupt stream: its sizes ask for more memory than is available");
  } catch (const std::length_error& e) {
    ThrowDecodeError(std::string("corrupt stream: impossible size (") + e.what() + ")");
  }
}

}  // namespace

TriangleMesh DecodeMeshDraco(std::span<const std::uint8_t> bytes) {
  return Decode(bytes, /*with_uv=*/false).mesh;
}

DracoMesh DecodeMeshDracoWithUv(std::span<const std::uint8_t> bytes) {
  return Decode(bytes, /*with_uv=*/true);
}

double DracoQuantizationStep(const TriangleMesh& mesh, int bits) {
  CheckQuantizationBits(bits);
  if (mesh.vertices.empty()) {
    throw std::invalid_argument("Draco: quantization step of a mesh with no vertex");
  }
  // Mirrors draco::AttributeQuantizationTransform::ComputeParameters: float32 min/max per axis,
  // range = the largest max - min (1 when that is 0), step = range / (2^bits - 1).
  std::array<float, 3> lo = ToFloat3(mesh.vertices[0], 0);
  std::array<float, 3> hi = lo;
  for (std::size_t i = 1; i < mesh.vertices.size(); ++i) {
    const std::array<float, 3> p = ToFloat3(mesh.vertices[i], i);
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], p[c]);
      hi[c] = std::max(hi[c], p[c]);
    }
  }
  float range = 0.0f;
  for (int c = 0; c < 3; ++c) range = std::max(range, hi[c] - lo[c]);
  if (range == 0.0f) range = 1.0f;
  const auto max_quantized_value = static_cast<double>((1u << static_cast<unsigned>(bits)) - 1u);
  return static_cast<double>(range) / max_quantized_value;
}

}  // namespace ht
