#pragma once
// Writing triangle meshes as a binary glTF 2.0 file (.glb), so that generated models (the seed
// benchmark models) are ordinary scene files that LoadGltfScene() and any glTF viewer read.

#include <glm/mat4x4.hpp>
#include <string>
#include <vector>

#include "haptic_core/mesh.h"

namespace ht {

/// One node of a written scene: a mesh shown at a pose.
struct GlbNode {
  /// Node and mesh name in the file.
  std::string name;
  /// Geometry in the node frame N (metres); #V ≤ 2^32−1 vertices, #F triangles.
  TriangleMesh mesh_N;
  /// Pose of N in the scene frame, X_WN (rigid, column-major like glTF); written as the node's
  /// `matrix` unless it is the identity.
  glm::dmat4 X_WN{1.0};
  /// Free-form JSON text written as the node's `extras` (e.g. a role), "" for none.
  std::string extras_json;
};

/// Writes `nodes` as one scene of a .glb file at `path` (one mesh, one TRIANGLES primitive with
/// FLOAT VEC3 POSITION and UNSIGNED_INT indices per node; positions rounded to float32 with
/// their min/max as the specification requires). Throws std::invalid_argument for a non-finite
/// vertex, an index out of range or an empty mesh, naming the node; std::runtime_error naming
/// `path` when the file cannot be written (written to a temporary name first, then renamed).
void WriteGlb(const std::string& path, const std::vector<GlbNode>& nodes);

}  // namespace ht
