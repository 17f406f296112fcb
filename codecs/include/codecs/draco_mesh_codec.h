#pragma once
// Draco compression of a full-resolution triangle mesh, for streaming scene geometry from the
// remote simulation node to the operator station (display only: the haptic loop never reads a
// decoded mesh). Uses Draco's public mesh API (https://google.github.io/draco/).

#include <cstdint>
#include <glm/vec2.hpp>
#include <span>
#include <vector>

#include "haptic_core/mesh.h"

namespace ht {

/// Options of EncodeMeshDraco().
struct DracoEncodeOptions {
  /// Bits per position coordinate, in [1, 24]. Positions are quantized on a uniform grid whose
  /// step is DracoQuantizationStep(mesh, position_quantization_bits) in every axis; 14 bits on a
  /// 6 cm object gives a step of 3.7 µm. Cost: libdraco 1.5.5's encoder builds a histogram of
  /// 2^bits entries (draco/core/shannon_entropy.cc), so whatever the mesh, encoding takes about
  /// 4·2^bits bytes and time to match: 4 MB at 20 bits, 67 MB / 0.05 s at 24 (hence the cap; 4.3 GB
  /// / 3 s at 30).
  int position_quantization_bits = 14;
  /// Draco speed, in [0, 10], used for both encoding and decoding: 0 gives the smallest stream and
  /// the slowest codec, 10 the fastest and largest (10 switches Edgebreaker connectivity coding
  /// off in favour of sequential coding).
  int speed = 5;
  /// Bits per texture coordinate, in [1, 24], for EncodeMeshDracoWithUv() (unused without
  /// coordinates; declared last so that {bits, speed} initializers keep their meaning). Draco
  /// quantizes (u, v) on a uniform grid whose step is the larger extent of their bounding box
  /// divided by 2^bits - 1: 12 bits on [0, 1] gives a step of 2.4e-4, a quarter texel of a
  /// 1024-pixel texture. 12 is glTF-Transform's default for Draco texture coordinates (libdraco
  /// itself quantizes nothing unless asked; its draco_encoder tool defaults to 10).
  int uv_quantization_bits = 12;
};

/// Compresses `mesh` (frame O, metres) into a self-contained Draco byte stream (format of the
/// installed libdraco, 2.2 for Debian 12's 1.5.5) that DecodeMeshDraco() or any Draco decoder
/// reads back. Only positions are stored; they are converted to float32 and quantized (see
/// DracoEncodeOptions).
///
/// What may not survive the round trip: vertex and triangle order; with speed < 10 (Edgebreaker),
/// vertices used by no triangle and triangles that repeat an index (they carry no area) are
/// dropped, and a vertex where the surface is non-manifold comes back as several copies (speed 10
/// keeps all of these). Vertices at the same position are not merged. Each decoded coordinate
/// lies within half a quantization step (plus float32 rounding, about 6e-8 of the coordinate's
/// magnitude) of the original; the step counts dropped vertices too.
///
/// Throws std::invalid_argument when the mesh has no vertex or no triangle, a triangle index is
/// outside [0, #V), a vertex coordinate is not finite or does not fit in a float, more than 2^31-1
/// vertices are given, or an option is outside its range; std::runtime_error with Draco's status
/// message when Draco fails.
std::vector<std::uint8_t> EncodeMeshDraco(const TriangleMesh& mesh,
                                          const DracoEncodeOptions& options = {});

/// EncodeMeshDraco() with texture coordinates: `uv` holds one (u, v) per vertex of `mesh` (#V
/// entries, uv[i] belonging to mesh.vertices[i], any convention: they are stored as given,
/// float32, quantized with options.uv_quantization_bits), stored as a TEX_COORD attribute of
/// the same Draco points as the positions; empty `uv` stores none (the same stream as
/// EncodeMeshDraco()). DecodeMeshDracoWithUv() returns them attached to their vertices whatever
/// order Draco gives the vertices. Each decoded coordinate lies within half a uv quantization step
/// (plus float32 rounding) of the original.
///
/// Throws what EncodeMeshDraco() throws, and std::invalid_argument when `uv` is neither empty nor
/// #V long, a coordinate is not finite as a float32, or uv_quantization_bits is outside [1, 24].
std::vector<std::uint8_t> EncodeMeshDracoWithUv(const TriangleMesh& mesh,
                                                std::span<const glm::dvec2> uv,
                                                const DracoEncodeOptions& options = {});

/// A decoded Draco mesh with its texture coordinates.
struct DracoMesh {
  /// Positions (the stream's units: metres for EncodeMeshDraco streams) and triangles.
  TriangleMesh mesh;
  /// (u, v) of each vertex of `mesh` (#V entries, uv[i] belonging to mesh.vertices[i]), as they
  /// were encoded (no flip); empty when the stream has no texture coordinate attribute.
  std::vector<glm::dvec2> uv;
};

/// Decodes a Draco mesh stream (any version libdraco reads) into a triangle mesh whose positions
/// are the stream's position attribute, in the stream's units (metres for EncodeMeshDraco()
/// streams). Triangles keep the stream's corner order. Other attributes (normals, texture
/// coordinates, colours) are ignored; vertices split by them in the stream stay separate.
///
/// Throws std::runtime_error, never crashes, on malformed input; the message says which check
/// failed: not a Draco stream, a point cloud rather than a mesh, truncated or corrupt data (with
/// Draco's status message), no 3-component position attribute, no triangles, or a non-finite
/// decoded coordinate.
TriangleMesh DecodeMeshDraco(std::span<const std::uint8_t> bytes);

/// Decodes a Draco mesh stream with its first texture coordinate attribute (TEX_COORD). With one,
/// the vertices are the stream's points: each point's position and (u, v) (2 components read as
/// float, normalized integers divided by their maximum), so that a vertex where the coordinates
/// have a seam comes back once per side; triangles keep the stream's corner order. Without one,
/// the result is DecodeMeshDraco()'s with an empty uv.
///
/// Throws what DecodeMeshDraco() throws, and std::runtime_error when the texture coordinate
/// attribute has other than 2 components or a non-finite value.
DracoMesh DecodeMeshDracoWithUv(std::span<const std::uint8_t> bytes);

/// Position quantization step (m) that EncodeMeshDraco() uses for `mesh` at `bits` bits: the
/// largest extent of the axis-aligned bounding box of the vertices (computed in float32, as Draco
/// does) divided by 2^bits - 1. When all vertices coincide Draco takes an extent of 1 (m), and so
/// does this function. The bounding box covers all vertices, used by a triangle or not.
///
/// Throws std::invalid_argument when the mesh has no vertex, a vertex is not finite, or `bits` is
/// outside [1, 24].
double DracoQuantizationStep(const TriangleMesh& mesh, int bits);

}  // namespace ht
