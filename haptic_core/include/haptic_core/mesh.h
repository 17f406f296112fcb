#pragma once
// A plain triangle mesh: what the codecs read and write and the model build starts from, in a
// header of its own so that codecs and transport need none of the haptic model.

#include <glm/vec3.hpp>
#include <vector>

namespace ht {

/// A full-resolution triangle mesh (for display, baking and reports), frame O, metres.
struct TriangleMesh {
  /// Vertices, #V.
  std::vector<glm::dvec3> vertices;
  /// Triangles, #F, counter-clockwise seen from outside.
  std::vector<glm::ivec3> triangles;
};

}  // namespace ht
